/* State of the axis board's motion control, shared by the step interrupt, the 1 kHz
 * profile interrupt and the request handler. Packed with a fixed layout so the simavr
 * harness (sim/fwsim.c) can read it from the firmware's RAM by the symbol `ax`. */
#ifndef SSLFR_AXIS_STATE_H
#define SSLFR_AXIS_STATE_H

#include <stdint.h>

typedef struct __attribute__((packed)) {
    int32_t pos;            /* step counter [steps] (step ISR) */
    int32_t goal;           /* the step ISR steps toward this [steps] */
    int32_t target;         /* target of the move [steps] */
    int32_t pf_int;         /* profile position, integer part [steps] */
    float pf_frac;          /* profile position, fraction [0, 1) */
    float v;                /* profile speed [steps/s], signed */
    float cmd_speed;        /* speed limit of the current move [steps/s] */
    uint16_t interval;      /* [0.5 us timer ticks] between steps */
    uint8_t stepping;       /* step ISR armed */
    uint8_t homed, homing, home_switch;
    int32_t home_position;  /* [steps] counter value at the home switch */
    uint16_t faults;        /* FAULT_* bits */
    uint8_t events;         /* AX_EV_* raised by the step ISR, consumed by the profile */
    uint8_t limit_bits;     /* LIM_* closed switches (last sample) */
    uint32_t steps_total;   /* step pulses since boot */
    float decel;            /* deceleration of the current stop [steps/s^2] (0: accel) */
    uint8_t seek_switch;    /* host-loss stow toward a switch: its index (0xFF none) */
    uint8_t hl_stowing;     /* driving to the host-loss stow by itself */
} axis_state_t;

/* The host-silence watchdog stops within this time [s], decelerating faster than the
 * configured acceleration when needed: 1 s of silence + this <= 1.2 s to standstill. */
#define AXIS_WATCHDOG_STOP_S 0.15f

#define AX_EV_LIMIT 0x01    /* a switch in the direction of travel stopped the motor */
#define AX_EV_HOME 0x02     /* the home switch closed: counter set, homed */
#define AX_EV_SEEK 0x04     /* the switch a host-loss stow drives to closed */

#endif
