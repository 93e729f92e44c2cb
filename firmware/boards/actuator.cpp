/* Actuator board (AXIS_ACTUATOR, seed 004 section 2.1): one linear actuator with PWM
 * speed control moves the lines' lever arms; an analogue inclinometer on a line is the
 * position measurement. docs/protocol.md "Actuator board behaviour", docs/firmware.md.
 * The same models as the Python simulator (sslfr_common/drives.py, sim/actuator.py):
 *
 * - every 10 ms: the inclinometer's mean ADC reading (free-running conversions,
 *   ~96 per period, averaged: the electrical noise averages out below one LSB), its
 *   calibrated offset removed -> measured angle; the loop (ActuatorLoop): drive when
 *   |error| > deadband, rest when |error| <= deadband / 2, angular speed
 *   min(move speed, gain |error|) but at least gain * deadband / 2, converted through
 *   the lever (law of cosines, dL/dtheta) to an actuator speed and a PWM duty
 *   (0 or >= min_duty);
 * - stall / time-out (MotionWatch): driving for the stall window with the mean of the
 *   last quarter of the window's readings within stall_min of the first quarter's
 *   (means over 100 ms blocks), or one move driving longer than the time-out: PWM off,
 *   fault STALL;
 * - STOP and the 1 s host-silence watchdog switch the PWM off at once.
 *
 * Pins (Arduino Pro Mini): D9 PWM (OC1A, 20 kHz) -> speed controller, D8 DIR (high:
 * lengthen the actuator = increase the angle), A0 <- inclinometer output (0.5-4.5 V).
 * Parameters: actuator_params.h (the collector description's, compile time).
 */
#include "board.h"
#include "actuator_params.h"
#include "actuator_state.h"

#include <math.h>
#include <util/atomic.h>

#define PWM_TOP 799u            /* 16 MHz / 800 = 20 kHz */
#define PWM_START_COUNT ((uint16_t)(ACT_MIN_DUTY * (float)(PWM_TOP + 1u)))   /* the motor does not start at or below */
#define DIR_BIT _BV(0)          /* PB0 = D8 */
#define PWM_BIT _BV(1)          /* PB1 = D9 = OC1A */
#define CONTROL_MS 10u
#define BLOCK_MS 100u
#define NBLOCKS (ACT_STALL_WINDOW_MS / BLOCK_MS)
#define QUARTER (NBLOCKS / 4 ? NBLOCKS / 4 : 1)

static volatile uint32_t g_adc_sum;
static volatile uint16_t g_adc_n;

/* the board's state (read by the harness by symbol: `act`, actuator_state.h) */
volatile act_state_t act __attribute__((used));
static volatile uint8_t g_retarget;   /* MOVE_TO gave a new target while driving */
static float act_blocks[NBLOCKS];   /* the motion watch's 100 ms block means */

ISR(ADC_vect)
{
    g_adc_sum += ADC;
    g_adc_n++;
    ADCSRA |= _BV(ADSC);
}

static float geo_length(float th)
{
    const float d = ACT_MOUNT_M, r = ACT_LEVER_M;
    return sqrtf(d * d + r * r - 2.0f * d * r * cosf(ACT_MOUNT_ANGLE + th));
}

/* dL/dtheta [m/rad] */
static float geo_rate(float th)
{
    return ACT_MOUNT_M * ACT_LEVER_M * sinf(ACT_MOUNT_ANGLE + th) / geo_length(th);
}

static float duty_for_speed(float v)
{
    if (v == 0.0f) return 0.0f;
    float a = fabsf(v) / ACT_MAX_SPEED;
    if (a > 1.0f) a = 1.0f;
    return copysignf(ACT_MIN_DUTY + (1.0f - ACT_MIN_DUTY) * a, v);
}

static float speed_for_duty(float duty)
{
    float a = fabsf(duty);
    if (a > 1.0f) a = 1.0f;
    if (a < ACT_MIN_DUTY) return 0.0f;
    return copysignf(ACT_MAX_SPEED * (a - ACT_MIN_DUTY) / (1.0f - ACT_MIN_DUTY), duty);
}

static void pwm_set(float duty)
{
    act.duty = duty;
    if (duty == 0.0f) {
        OCR1A = 0;
        TCCR1A &= (uint8_t)~_BV(COM1A1);     /* pin low, no glitch at 0 */
        PORTB &= (uint8_t)~PWM_BIT;
        return;
    }
    if (duty > 0) PORTB |= DIR_BIT; else PORTB &= (uint8_t)~DIR_BIT;
    float a = fabsf(duty);
    uint16_t count = (uint16_t)(a * (float)(PWM_TOP + 1) + 0.5f);
    /* a drive is at least the first count above the start duty: rounded down to the
     * start duty itself, a slow approach (a speed under half a count: 0.15 mm/s with a
     * 0.2 m/s actuator) would leave the motor standing while the loop drives, and the
     * motion watch would latch STALL */
    if (count <= PWM_START_COUNT) count = PWM_START_COUNT + 1u;
    if (count > PWM_TOP + 1u) count = PWM_TOP + 1u;
    OCR1A = count;
    TCCR1A |= _BV(COM1A1);
}

static void watch_reset(void)
{
    act.watching = 0;
    act.nblocks = 0;
    act.block_n = 0;
    act.block_sum = 0.0f;
}

static void drive_stop(void)
{
    pwm_set(0.0f);
    act.has_target = 0;
    act.driving = 0;
    watch_reset();
}

/* MotionWatch.update: 1 = stall or time-out */
static uint8_t watch_update(uint32_t now, uint8_t driving, float angle)
{
    if (!driving) {
        watch_reset();
        return 0;
    }
    if (!act.watching) {
        act.watching = 1;
        act.since = now;
        act.block_start = now;
    }
    if (g_retarget) {           /* at the loop's own `now`: a time read later would be ahead of it */
        g_retarget = 0;
        act.since = now;
    }
    if ((uint32_t)(now - act.since) > ACT_TIMEOUT_MS)
        return 1;
    act.block_sum += angle;
    act.block_n++;
    if ((uint32_t)(now - act.block_start) + CONTROL_MS >= BLOCK_MS) {
        float mean = act.block_sum / act.block_n;
        if (act.nblocks == NBLOCKS) {
            for (uint8_t i = 1; i < NBLOCKS; i++) act_blocks[i - 1] = act_blocks[i];
            act.nblocks--;
        }
        act_blocks[act.nblocks++] = mean;
        act.block_sum = 0.0f;
        act.block_n = 0;
        act.block_start = now + CONTROL_MS;
        if (act.nblocks == NBLOCKS) {
            float a = 0.0f, b = 0.0f;
            for (uint8_t i = 0; i < QUARTER; i++) {
                a += act_blocks[i];
                b += act_blocks[NBLOCKS - 1 - i];
            }
            if (fabsf(b - a) / QUARTER < ACT_STALL_MIN)
                return 1;
        }
    }
    return 0;
}

/* ActuatorLoop.duty */
static float loop_duty(void)
{
    float err = act.target - act.measured;
    float e = fabsf(err);
    if (act.driving && e <= ACT_DEADBAND / 2) act.driving = 0;
    else if (!act.driving && e > ACT_DEADBAND) act.driving = 1;
    if (!act.driving) return 0.0f;
    float omega = ACT_GAIN * e;
    if (act.speed < omega) omega = act.speed;
    if (omega < ACT_GAIN * ACT_DEADBAND / 2) omega = ACT_GAIN * ACT_DEADBAND / 2;
    float d = fabsf(duty_for_speed(omega * geo_rate(act.measured)));
    return err < 0 ? -d : d;
}

static uint8_t read_inclinometer(void)
{
    uint32_t s;
    uint16_t n;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
        s = g_adc_sum; n = g_adc_n;
        g_adc_sum = 0; g_adc_n = 0;
    }
    if (!n) return 0;
    /* ADC = floor(Vin 1024 / Vref): the mean of dithered readings is 0.5 LSB low */
    float mv = ((float)s / (float)n + 0.5f) * (ACT_VREF_MV / 1024.0f);
    act.measured = (mv - ACT_INC_V0_MV) / ACT_INC_MV_PER_DEG * DEG - ACT_OFFSET_CAL;
    return 1;
}

static void act_setup(void)
{
    act.faults = FAULT_RESET;
    DDRB |= DIR_BIT | PWM_BIT;
    PORTB &= (uint8_t)~(DIR_BIT | PWM_BIT);
    /* Timer1: fast PWM, TOP = ICR1 (mode 14), no prescaler: 20 kHz on OC1A */
    ICR1 = PWM_TOP;
    OCR1A = 0;
    TCCR1A = _BV(WGM11);
    TCCR1B = _BV(WGM13) | _BV(WGM12) | _BV(CS10);
    /* ADC: A0 against AVcc, clk/128, conversions chained in the interrupt */
    ADMUX = _BV(REFS0);
    ADCSRA = _BV(ADEN) | _BV(ADIE) | _BV(ADSC) | _BV(ADPS2) | _BV(ADPS1) | _BV(ADPS0);
    uint32_t t0 = millis();
    while (!g_adc_n && (uint32_t)(millis() - t0) < 5) {}
    read_inclinometer();
}

static void act_poll(uint32_t now)
{
    static uint32_t last;
    if ((uint32_t)(now - last) < CONTROL_MS)
        return;
    last = now;
    read_inclinometer();
    if (act.has_target) {
        float duty = loop_duty();
        if (watch_update(now, duty != 0.0f, act.measured)) {
            act.faults |= FAULT_STALL;
            drive_stop();
            return;
        }
        pwm_set(duty);
    }
}

static int32_t to_steps(float angle)
{
    return (int32_t)lroundf(angle / ACT_STEP_RAD) + act.zero;
}

static uint8_t handle_status(const proto_frame_t *req, proto_frame_t *ans)
{
    if (req->len != 0)
        return session_nack(req, ans, ERR_BAD_PAYLOAD);
    msg_status_t s;
    s.position = to_steps(act.measured);
    s.target = act.has_target ? to_steps(act.target) : s.position;
    s.speed = speed_for_duty(act.duty) / geo_rate(act.measured) / ACT_STEP_RAD;
    s.flags = ST_HAS_SENSOR;
    if (act.duty != 0.0f) s.flags |= ST_MOVING;
    if (act.homed) s.flags |= ST_HOMED;
    s.limit_bits = 0;
    s.fault_bits = act.faults;
    s.sensor_angle = act.measured;
    s.uptime_ms = millis();
    ans->type = MSG_STATUS;
    ans->len = msg_status(ans->payload, &s);
    return 1;
}

static uint8_t handle_move(const proto_frame_t *req, proto_frame_t *ans)
{
    msg_move_to_t m;
    if (msg_parse_move_to(req, &m))
        return session_nack(req, ans, ERR_BAD_PAYLOAD);
    if (!act.homed)
        return session_nack(req, ans, ERR_NOT_HOMED);
    float target = (float)(m.steps - act.zero) * ACT_STEP_RAD;
    if (!(m.speed > 0.0f) || target < ACT_RANGE_LO || target > ACT_RANGE_HI)
        return session_nack(req, ans, ERR_OUT_OF_RANGE);
    if (!act.has_target || act.duty == 0.0f)
        watch_reset();
    else if (target != act.target)
        g_retarget = 1;         /* a new target is a new move: its time-out starts again
                                   (the stall window keeps its blocks: a tracking loop
                                   gets a new target every control period) */
    act.target = target;
    act.speed = m.speed * ACT_STEP_RAD;
    act.has_target = 1;
    act.faults &= (uint16_t)~(FAULT_WATCHDOG | FAULT_LIMIT | FAULT_STALL);
    return session_ack(req, ans);
}

static uint8_t act_handle(const proto_frame_t *req, proto_frame_t *ans)
{
    switch (req->type) {
    case MSG_GET_STATUS:
        return handle_status(req, ans);
    case MSG_MOVE_TO:
        return handle_move(req, ans);
    case MSG_STOP:
        if (req->len != 0)
            return session_nack(req, ans, ERR_BAD_PAYLOAD);
        drive_stop();
        return session_ack(req, ans);
    case MSG_SET_ZERO: {
        int32_t p;
        if (msg_parse_i32(req, &p))
            return session_nack(req, ans, ERR_BAD_PAYLOAD);
        drive_stop();
        act.zero = p - (int32_t)lroundf(act.measured / ACT_STEP_RAD);
        act.homed = 1;
        act.faults &= (uint16_t)~FAULT_RESET;
        return session_ack(req, ans);
    }
    default:
        return 0;
    }
}

static void act_host_silent(void)
{
    if (act.duty != 0.0f || act.has_target)
        act.faults |= FAULT_WATCHDOG;
    drive_stop();
}

static uint8_t act_busy(void) { return act.duty != 0.0f; }
static uint8_t act_may_sleep(void) { return 1; }

const BoardDef BOARD = {
    KIND_AXIS_ACTUATOR, "sslfr-actuator", act_setup, act_poll, act_handle,
    act_host_silent, act_busy, act_may_sleep,
};
