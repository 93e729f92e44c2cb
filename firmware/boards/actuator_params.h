/* The actuator board's drive (seed 004 section 2.1), as the shipped collector description
 * src/sslfr_bringup/config/collectors/florianopolis_lepten.yaml gives it (movement
 * `mirrors`: actuator, inclinometer, range, deadband); tests/test_fw_drives.py fails when
 * they differ. Override at build time with -D for another collector. SI units, radians. */
#ifndef SSLFR_ACTUATOR_PARAMS_H
#define SSLFR_ACTUATOR_PARAMS_H

#define DEG (3.14159265358979f / 180.0f)
#ifndef ACT_LEVER_M
#define ACT_LEVER_M 0.15f            /* lever_m */
#define ACT_MOUNT_M 0.40f            /* mount_distance_m */
#define ACT_MOUNT_ANGLE (90.0f * DEG) /* mount_angle_deg */
#define ACT_STROKE_MIN 0.30f         /* stroke_m */
#define ACT_STROKE_MAX 0.53f
#define ACT_RANGE_LO (-40.0f * DEG)  /* range_deg */
#define ACT_RANGE_HI (40.0f * DEG)
#define ACT_DEADBAND (0.05f * DEG)   /* deadband_deg */
#define ACT_MAX_SPEED 0.005f         /* max_speed_m_s [m/s] at duty 1 */
#define ACT_MIN_DUTY 0.2f            /* min_duty */
#define ACT_STALL_WINDOW_MS 2000u    /* stall_window_s */
#define ACT_STALL_MIN (0.03f * DEG)  /* stall_min_deg */
#define ACT_TIMEOUT_MS 60000ul       /* move_timeout_s */
#define ACT_OFFSET_CAL (0.0f * DEG)  /* inclinometer offset_deg (calibration) */
#endif
#define ACT_GAIN 2.0f                /* [1/s] ActuatorLoop.gain */
#define ACT_STEP_RAD (0.006f * DEG)  /* messages.DEFAULT_STEP_RAD */

/* The inclinometer: an analogue (SCA-style) sensor with a linear voltage output,
 * ACT_INC_V0 at 0 deg, ACT_INC_MV_PER_DEG (0.5-4.5 V over +/-45 deg), on A0 against AVcc. */
#define ACT_INC_V0_MV 2500.0f
#define ACT_INC_MV_PER_DEG (4000.0f / 90.0f)
#define ACT_VREF_MV 5000.0f

#endif
