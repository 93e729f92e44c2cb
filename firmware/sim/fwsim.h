/* fwsim: the SSLFR boards' exact firmware (.elf) on libsimavr, with models of what each
 * board is wired to. See fwsim.c (harness: UART bridge, pacing, faults, control) and
 * models.c (stepper + mechanism, AS5048A, MAX6675, VEML7700, NEO-6, switches). */
#ifndef FWSIM_H
#define FWSIM_H

#include <stdint.h>
#include <stdio.h>
#include "sim_avr.h"

#define F_CPU_HZ 16000000u

enum board_kind { B_AXIS, B_ABSORBER, B_IRRADIANCE, B_GPS, B_BOOTLOADER, B_ACTUATOR };

/* mechanism of an axis (SI units, radians), as sim/axis.py AxisConfig */
typedef struct {
    double lo, hi, sleep, step_rad, switch_width, overtravel;
    double angle;              /* the joint angle (truth) */
    int stalled;
    int has_sensor;            /* AS5048A on the joint */
    uint16_t sensor_zero;      /* encoder count at joint angle 0 */
    int64_t steps;             /* STEP pulses seen by the model (signed) */
    uint64_t last_step_cycle;  /* total cycles at the last pulse */
    uint64_t first_step_after_rx; /* set by the harness: cycle of the first step after a mark */
    /* actuator + lever + inclinometer (sslfr_common/drives.py LeverGeometry, sim/actuator.py):
     * lever, mount distance [m], mount angle [rad], stroke [m], speed at duty 1 [m/s],
     * start duty, inclinometer mounting offset [rad], electrical noise [mV rms] */
    double lever, mount, mount_angle, stroke_lo, stroke_hi, max_speed, min_duty, inc_offset, noise_mv;
    double length, duty;       /* actuator length [m] (truth), last PWM duty seen (signed) */
} mech_t;

typedef struct model model_t;

/* models.c */
model_t *model_create(avr_t *avr, enum board_kind kind, mech_t *mech);
void model_after_reset(model_t *m);              /* re-apply pin levels, timers */
int model_command(model_t *m, const char *cmd, char *reply, size_t n);  /* 0 = handled */
void model_status_json(model_t *m, FILE *out);   /* ,"key":value... */
/* RAM address of the firmware's pulse-input pin (absorber g_pulse_pin; 0: unknown): a
 * "pulses HZ" command without PIN drives the pin the firmware counts on */
void model_set_pulse_pin_addr(model_t *m, uint32_t addr);
uint64_t model_total_cycles(avr_t *avr);         /* cycles since the harness started */

#endif
