/* State of the actuator board's control loop (boards/actuator.cpp). Packed with a fixed
 * layout so the simavr harness (sim/fwsim.c) can read it from the firmware's RAM by the
 * symbol `act`, as it reads the stepper's `ax` (axis_state.h). */
#ifndef SSLFR_ACTUATOR_STATE_H
#define SSLFR_ACTUATOR_STATE_H

#include <stdint.h>

typedef struct __attribute__((packed)) {
    float measured;     /* [rad] line angle, offset removed */
    float target;       /* [rad] */
    float speed;        /* [rad/s] the move's limit */
    float duty;         /* signed [-1, 1] */
    int32_t zero;       /* [steps] counter - measured / step */
    uint16_t faults;    /* FAULT_* bits */
    uint8_t has_target, homed, driving;
    /* motion watch (the 100 ms block means are in act_blocks[]) */
    uint32_t since;     /* [ms] start of the move (driving without a pause) */
    uint8_t watching, nblocks;
    float block_sum;
    uint8_t block_n;
    uint32_t block_start;
} act_state_t;

#endif
