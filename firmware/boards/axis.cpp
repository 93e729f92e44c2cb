/* Axis board: one stepper axis of the SSLFR (mirrors, mobile structure or secondary
 * reflector; which one, the step limits and the motion limits live in the EEPROM
 * configuration record). docs/protocol.md "Axis board behaviour", docs/firmware.md.
 *
 * Motion. A 1 kHz profile interrupt (Timer2) integrates a trapezoidal speed profile
 * (speed min(MOVE_TO speed, max speed), acceleration `accel`, braking distance
 * v^2 / 2a, no overshoot: the same law as the simulator sim/axis.py) into a continuous
 * position; the step interrupt (Timer1, 0.5 us ticks) emits the steps from the counter
 * to that position, spread over the next millisecond (up to AXIS_MAX_STEP_RATE).
 * Limit switches are sampled in the step interrupt before and after every step: a
 * switch closed in the direction of travel stops the motor there, whatever the host
 * says (fault LIMIT), except the switch a HOME is looking for, whose closing sets the
 * counter. Host silence for 1 s decelerates to a stop within AXIS_WATCHDOG_STOP_S (fault
 * WATCHDOG), faster than `accel` when needed.
 *
 * Built with -DAXIS_NO_SWITCHES (build/axis_noswitch.elf, seed 003's rig: no switch
 * wired): the switch inputs are never read (limit bits 0), HOME is not implemented
 * (UNKNOWN_TYPE) and SET_ZERO is the only reference (docs/collectors.md "Drives"); a
 * host-loss stow toward a switch is refused (OUT_OF_RANGE), a step target is allowed.
 *
 * Host-loss stow (SET_HOST_LOSS_STOW, kept in EEPROM at HL_EEPROM_ADDR): when the host
 * stays silent for `delay_ms` after that stop, the board drives by itself to the stow
 * target (a step position, only when HOMED; or toward a switch until it closes), with the
 * same switch and step-range checks as any move, and latches fault HOST_LOSS (STATUS flag
 * HOST_LOSS_STOWING while it drives). A host that comes back sees it in STATUS; the
 * board goes on to the stow until the host commands (MOVE_TO, HOME or STOP).
 *
 * Pins (Arduino Pro Mini): D3 STEP, D4 DIR, D5 /ENABLE, D6 /DRIVER_FAULT (input,
 * pull-up), D7 LOW switch, D8 HIGH switch, D9 SLEEP switch (inputs, pull-ups, switch to
 * GND), D10 /CS, D11 MOSI, D12 MISO, D13 SCK of the optional AS5048A absolute encoder.
 */
#include "board.h"
#include "axis_state.h"

#include <SPI.h>
#include <avr/eeprom.h>
#include <math.h>
#include <string.h>
#include <util/atomic.h>

volatile axis_state_t ax __attribute__((used));

#define STEP_BIT _BV(3)   /* PD3 */
#define DIR_BIT _BV(4)    /* PD4 */
#define EN_BIT _BV(5)     /* PD5 */
#define FAULT_BIT _BV(6)  /* PD6 */
#define LOW_BIT _BV(7)    /* PD7 */
#define HIGH_BIT _BV(0)   /* PB0 */
#define SLEEP_BIT _BV(1)  /* PB1 */
#define SENSOR_CS 10
#define TICKS_PER_MS 2000u
#define MIN_INTERVAL 40u  /* [ticks] 20 us: 50 kHz ceiling of the step ISR */

static float g_accel;
static uint8_t g_switch_nc;
static uint8_t g_dir_invert;
static volatile uint8_t g_profile_busy;
static uint16_t g_sensor_raw;      /* last AS5048A angle, 14 bits */
static msg_host_loss_t g_hl;       /* the host-loss stow in force (EEPROM) */
static uint8_t g_hl_armed;         /* the watchdog stopped the motor: waiting for the delay */
static uint32_t g_hl_since;        /* [ms] when it did */
static uint8_t g_sensor_ok;

/* closed switches as LIM_* bits, from the pins (inline: used in the step ISR) */
static inline uint8_t read_switches(void)
{
#ifdef AXIS_NO_SWITCHES
    return 0;
#endif
    uint8_t raw = 0;
    if (!(PIND & LOW_BIT)) raw |= LIM_LOW;
    if (!(PINB & HIGH_BIT)) raw |= LIM_HIGH;
    if (!(PINB & SLEEP_BIT)) raw |= LIM_SLEEP;
    return g_switch_nc ? (uint8_t)(raw ^ (LIM_LOW | LIM_HIGH | LIM_SLEEP)) : raw;
}

/* 1 when a closed switch forbids moving in direction d (+1: increasing steps) */
static inline uint8_t blocked(uint8_t sw, int8_t d)
{
    if (ax.homing)
        sw &= (uint8_t)~(1u << ax.home_switch);
    return (d > 0 && (sw & LIM_HIGH)) || (d < 0 && (sw & LIM_LOW));
}

/* Next compare interrupt `ticks` after the last one, but never in the past: a compare
 * value the counter has already passed would only match after a full 32.8 ms wrap. */
static inline void schedule(uint16_t ticks)
{
    uint16_t next = (uint16_t)(OCR1A + ticks);
    uint16_t soonest = (uint16_t)(TCNT1 + 24);
    if ((int16_t)(next - soonest) < 0)
        next = soonest;
    OCR1A = next;
}

static inline void stop_stepping(void)
{
    ax.stepping = 0;
    TIMSK1 &= (uint8_t)~_BV(OCIE1A);
}

/* Returns 1 when the motor must stop here (event raised). */
static inline uint8_t check_switches(int8_t d)
{
    uint8_t sw = read_switches();
    ax.limit_bits = sw;
    if (ax.seek_switch != 0xFF && (sw & (1u << ax.seek_switch))) {
        ax.goal = ax.pos;
        ax.events |= AX_EV_SEEK;
        return 1;
    }
    if (ax.homing && (sw & (1u << ax.home_switch))) {
        ax.pos = ax.home_position;
        ax.goal = ax.home_position;
        ax.events |= AX_EV_HOME;
        return 1;
    }
    if (d && blocked(sw, d)) {
        ax.goal = ax.pos;
        ax.events |= AX_EV_LIMIT;
        return 1;
    }
    return 0;
}

ISR(TIMER1_COMPA_vect)
{
    int32_t p = ax.pos, g = ax.goal;
    if (p == g) {
        stop_stepping();
        return;
    }
    int8_t d = g > p ? 1 : -1;
    if (check_switches(d)) {
        stop_stepping();
        return;
    }
    uint8_t dir_high = (d > 0) ^ g_dir_invert;
    if (((PORTD & DIR_BIT) != 0) != dir_high) {
        /* direction change: DIR first, the step 5 us later (driver set-up time) */
        if (dir_high) PORTD |= DIR_BIT; else PORTD &= (uint8_t)~DIR_BIT;
        schedule(10);
        return;
    }
    PORTD |= STEP_BIT;
    ax.pos = p + d;
    ax.steps_total++;
    schedule(ax.interval);
    if (check_switches(d))
        stop_stepping();
    PORTD &= (uint8_t)~STEP_BIT;          /* pulse >= 2 us: the code above */
}

static void kick_stepping(void)
{
    if (!ax.stepping) {
        ax.stepping = 1;
        OCR1A = TCNT1 + 16;
        TIFR1 = _BV(OCF1A);
        TIMSK1 |= _BV(OCIE1A);
    }
}

/* Decelerate to a stop at `decel` [steps/s^2]: the new target is the stopping point. */
static void stop_motion(float decel)
{
    ax.homing = 0;
    ax.seek_switch = 0xFF;
    ax.decel = decel > g_accel ? decel : 0.0f;
    float v = ax.v;
    float d = v * v / (2.0f * (decel > g_accel ? decel : g_accel));
    int32_t here = ax.pf_int + (ax.pf_frac >= 0.5f ? 1 : 0);
    ax.target = v > 0 ? here + (int32_t)ceilf(d) : (v < 0 ? here - (int32_t)ceilf(d) : here);
}

static void profile_tick(void)
{
    const float dt = 1e-3f;
    uint8_t ev;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
        ev = ax.events;
        ax.events = 0;
    }
    if (ev & AX_EV_HOME) {
        ax.homing = 0;
        ax.homed = 1;
        ax.faults &= (uint16_t)~FAULT_RESET;
    }
    if (ev & AX_EV_LIMIT) {
        ax.homing = 0;
        ax.seek_switch = 0xFF;
        ax.faults |= FAULT_LIMIT;
    }
    if (ev & AX_EV_SEEK)
        ax.seek_switch = 0xFF;
    if (ev) {
        int32_t p;
        ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { p = ax.pos; }
        ax.pf_int = p;
        ax.pf_frac = 0.0f;
        ax.target = p;
        ax.v = 0.0f;
    }
    float err = (float)(ax.target - ax.pf_int) - ax.pf_frac;
    if (err != 0.0f || ax.v != 0.0f) {
        float a = ax.decel > g_accel ? ax.decel : g_accel;
        float d = fabsf(err);
        float vmax = ax.cmd_speed;
        float vb = sqrtf(2.0f * a * d);
        float vd = vb < vmax ? vb : vmax;
        if (err < 0) vd = -vd;
        float dv = vd - ax.v;
        float lim = a * dt;
        if (dv > lim) dv = lim; else if (dv < -lim) dv = -lim;
        ax.v += dv;
        float move = ax.v * dt;
        if ((err > 0 && move >= err) || (err < 0 && move <= err) || (d < 0.5f && fabsf(ax.v) < 2.0f * lim)) {
            move = err;
            ax.v = 0.0f;
        }
        float f = ax.pf_frac + move;
        int32_t whole = (int32_t)floorf(f);
        ax.pf_int += whole;
        ax.pf_frac = f - (float)whole;
        if (move == err) {              /* arrived: exactly on the target */
            ax.pf_int = ax.target;
            ax.pf_frac = 0.0f;
            ax.decel = 0.0f;
        }
    }
    int32_t goal = ax.pf_int + (ax.pf_frac >= 0.5f ? 1 : 0);
    int32_t p;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
        ax.goal = goal;
        p = ax.pos;
    }
    int32_t pending = goal > p ? goal - p : p - goal;
    if (pending) {
        uint32_t iv = TICKS_PER_MS / (uint32_t)pending;
        ax.interval = iv < MIN_INTERVAL ? MIN_INTERVAL : (uint16_t)iv;
        ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { kick_stepping(); }
    }
}

/* 1 kHz, interruptible by the step interrupt and the UART */
ISR(TIMER2_COMPA_vect, ISR_NOBLOCK)
{
    if (g_profile_busy)
        return;
    g_profile_busy = 1;
    profile_tick();
    g_profile_busy = 0;
}

static uint16_t sensor_transfer(uint16_t word)
{
    SPI.beginTransaction(SPISettings(1000000, MSBFIRST, SPI_MODE1));
    digitalWrite(SENSOR_CS, LOW);
    uint16_t r = SPI.transfer16(word);
    digitalWrite(SENSOR_CS, HIGH);
    SPI.endTransaction();
    return r;
}

static uint8_t even_parity(uint16_t w)
{
    w ^= w >> 8; w ^= w >> 4; w ^= w >> 2; w ^= w >> 1;
    return (uint8_t)((w & 1) == 0);
}

/* AS5048A: the answer to a read comes with the next frame; 0xFFFF = read ANGLE (0x3FFF). */
static void sensor_read(void)
{
    sensor_transfer(0xFFFF);
    uint16_t r = sensor_transfer(0xFFFF);
    g_sensor_ok = even_parity(r) && !(r & 0x4000);
    if (g_sensor_ok)
        g_sensor_raw = r & 0x3FFF;
}

static float sensor_angle(void)
{
    if (!(g_config.flags & CFG_HAS_SENSOR) || !g_sensor_ok)
        return NAN;
    int16_t c = (int16_t)((g_sensor_raw - g_config.sensor_zero) & 0x3FFF);
    if (c >= 0x2000) c -= 0x4000;                  /* -pi .. pi */
    float a = (float)c * (float)(2.0 * M_PI / 16384.0);
    return (g_config.flags & CFG_SENSOR_INVERT) ? -a : a;
}

/* ---- host-loss stow --------------------------------------------------------------- */
static uint8_t hl_valid(const msg_host_loss_t *h)
{
    if (h->mode == HL_OFF)
        return 1;
    if (h->mode > HL_SWITCH || !(h->speed != 0.0f) || h->delay_ms == 0 || h->delay_ms > HL_MAX_DELAY_MS)
        return 0;
    if (h->mode == HL_POSITION)
        return h->steps >= g_config.min_steps && h->steps <= g_config.max_steps;
#ifdef AXIS_NO_SWITCHES
    return 0;                       /* no switch to stow toward */
#else
    return h->sw <= 2;
#endif
}

/* The record in EEPROM: HL_SIZE payload bytes + CRC-16; blank, damaged or invalid for
 * this configuration: off. */
static void hl_load(void)
{
    uint8_t raw[HL_SIZE + 2];
    eeprom_read_block(raw, (const void *)HL_EEPROM_ADDR, sizeof raw);
    proto_frame_t f;
    f.len = HL_SIZE;
    memcpy(f.payload, raw, HL_SIZE);
    g_hl.mode = HL_OFF;
    msg_host_loss_t h;
    if (proto_crc16(raw, HL_SIZE, 0xFFFFu) == proto_get_u16(raw + HL_SIZE)
            && !msg_parse_host_loss(&f, &h) && hl_valid(&h))
        g_hl = h;
}

static uint8_t handle_host_loss(const proto_frame_t *req, proto_frame_t *ans)
{
    msg_host_loss_t h;
    if (msg_parse_host_loss(req, &h))
        return session_nack(req, ans, ERR_BAD_PAYLOAD);
    if (!hl_valid(&h))
        return session_nack(req, ans, ERR_OUT_OF_RANGE);
    uint8_t raw[HL_SIZE + 2];
    memcpy(raw, req->payload, HL_SIZE);
    proto_put_u16(raw + HL_SIZE, proto_crc16(raw, HL_SIZE, 0xFFFFu));
    eeprom_update_block(raw, (void *)HL_EEPROM_ADDR, sizeof raw);     /* writes changed bytes only */
    uint8_t back[HL_SIZE + 2];
    eeprom_read_block(back, (const void *)HL_EEPROM_ADDR, sizeof back);
    if (memcmp(raw, back, sizeof raw))
        return session_nack(req, ans, ERR_INTERNAL);
    g_hl = h;
    return session_ack(req, ans);
}

/* Main loop: start the stow once the host has stayed silent for the delay after the
 * watchdog stop; a new request from the host (the watchdog re-armed) cancels the wait. */
static void hl_poll(uint32_t now)
{
    if (!g_hl_armed)
        return;
    if (!g_session.watchdog_tripped || g_hl.mode == HL_OFF) {
        g_hl_armed = 0;
        return;
    }
    if ((uint32_t)(now - g_hl_since) < g_hl.delay_ms)
        return;
    g_hl_armed = 0;
    if (!(PIND & FAULT_BIT))
        return;                                    /* driver fault: nothing moves */
    float s = fabsf(g_hl.speed);
    s = s < g_config.max_speed ? s : g_config.max_speed;
    int32_t p;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { p = ax.pos; }
    if (g_hl.mode == HL_POSITION) {
        if (!ax.homed)
            return;                                /* position unknown: stay */
        int8_t d = g_hl.steps > p ? 1 : (g_hl.steps < p ? -1 : 0);
        if (blocked(read_switches(), d))
            return;
        ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
            ax.target = g_hl.steps;
            ax.decel = 0.0f;
            ax.cmd_speed = s;
            ax.faults |= FAULT_HOST_LOSS;
            ax.hl_stowing = 1;
        }
    } else {
        if (read_switches() & (1u << g_hl.sw)) {
            ax.faults |= FAULT_HOST_LOSS;           /* already there */
            return;
        }
        if (blocked(read_switches(), g_hl.speed > 0 ? 1 : -1))
            return;
        ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
            ax.seek_switch = g_hl.sw;
            ax.decel = 0.0f;
            ax.cmd_speed = s;
            ax.target = ax.pf_int + (g_hl.speed > 0 ? 1000000000L : -1000000000L);
            ax.faults |= FAULT_HOST_LOSS;
            ax.hl_stowing = 1;
        }
    }
}

static void axis_setup(void)
{
    g_accel = g_config.accel;
    g_switch_nc = (g_config.flags & CFG_SWITCH_NC) ? 1 : 0;
    g_dir_invert = (g_config.flags & CFG_INVERT_DIR) ? 1 : 0;
    ax.faults = FAULT_RESET;
    ax.cmd_speed = g_config.max_speed;
    ax.seek_switch = 0xFF;
    hl_load();
    DDRD |= STEP_BIT | DIR_BIT | EN_BIT;
    PORTD &= (uint8_t)~(STEP_BIT | DIR_BIT | EN_BIT);   /* driver enabled, holding */
    DDRD &= (uint8_t)~(FAULT_BIT | LOW_BIT);
    PORTD |= FAULT_BIT | LOW_BIT;
    DDRB &= (uint8_t)~(HIGH_BIT | SLEEP_BIT);
    PORTB |= HIGH_BIT | SLEEP_BIT;
    if (g_config.flags & CFG_HAS_SENSOR) {
        pinMode(SENSOR_CS, OUTPUT);
        digitalWrite(SENSOR_CS, HIGH);
        SPI.begin();
        sensor_read();
    }
    ax.limit_bits = read_switches();
    /* Timer1: normal mode, clk/8 = 2 MHz; compare A schedules the steps */
    TCCR1A = 0;
    TCCR1B = _BV(CS11);
    /* Timer2: CTC, clk/64, 250 counts = 1 kHz profile */
    TCCR2A = _BV(WGM21);
    TCCR2B = _BV(CS22);
    OCR2A = 249;
    TIMSK2 = _BV(OCIE2A);
}

static uint8_t moving(void)
{
    uint8_t m;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { m = ax.v != 0.0f || ax.pos != ax.target || ax.homing; }
    return m;
}

static void axis_poll(uint32_t now)
{
    static uint32_t last_sensor;
    if ((g_config.flags & CFG_HAS_SENSOR) && (uint32_t)(now - last_sensor) >= 10) {
        last_sensor = now;
        sensor_read();
    }
    hl_poll(now);
    if (!moving()) {
        uint8_t sw = read_switches();
        ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
            ax.limit_bits = sw;
            ax.hl_stowing = 0;
        }
    }
}

static uint8_t handle_move(const proto_frame_t *req, proto_frame_t *ans)
{
    msg_move_to_t m;
    if (msg_parse_move_to(req, &m))
        return session_nack(req, ans, ERR_BAD_PAYLOAD);
    if (!ax.homed)
        return session_nack(req, ans, ERR_NOT_HOMED);
    if (!(m.speed > 0.0f) || m.steps < g_config.min_steps || m.steps > g_config.max_steps)
        return session_nack(req, ans, ERR_OUT_OF_RANGE);
    if (!(PIND & FAULT_BIT))
        return session_nack(req, ans, ERR_FAULT_ACTIVE);
    if (ax.homing)
        return session_nack(req, ans, ERR_BUSY);
    int32_t p;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) { p = ax.pos; }
    int8_t d = m.steps > p ? 1 : (m.steps < p ? -1 : 0);
    if (blocked(read_switches(), d))
        return session_nack(req, ans, ERR_LIMIT_ACTIVE);
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
        ax.target = m.steps;
        ax.decel = 0.0f;
        ax.seek_switch = 0xFF;
        ax.hl_stowing = 0;
        ax.cmd_speed = m.speed < g_config.max_speed ? m.speed : g_config.max_speed;
        ax.faults &= (uint16_t)~(FAULT_WATCHDOG | FAULT_LIMIT | FAULT_HOST_LOSS);
    }
    return session_ack(req, ans);
}

#ifndef AXIS_NO_SWITCHES
static uint8_t handle_home(const proto_frame_t *req, proto_frame_t *ans)
{
    msg_home_t m;
    if (msg_parse_home(req, &m))
        return session_nack(req, ans, ERR_BAD_PAYLOAD);
    if (m.sw > 2 || m.speed == 0.0f)
        return session_nack(req, ans, ERR_OUT_OF_RANGE);
    if (!(PIND & FAULT_BIT))
        return session_nack(req, ans, ERR_FAULT_ACTIVE);
    float s = fabsf(m.speed);
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
        ax.home_switch = m.sw;
        ax.home_position = m.position;
        ax.homing = 1;
        ax.decel = 0.0f;
        ax.cmd_speed = s < g_config.max_speed ? s : g_config.max_speed;
        ax.target = ax.pf_int + (m.speed > 0 ? 1000000000L : -1000000000L);
        ax.seek_switch = 0xFF;
        ax.hl_stowing = 0;
        ax.faults &= (uint16_t)~(FAULT_WATCHDOG | FAULT_LIMIT | FAULT_HOST_LOSS);
        if (read_switches() & (1u << m.sw)) {      /* already on the switch */
            ax.pos = m.position;
            ax.goal = m.position;
            ax.events |= AX_EV_HOME;
        }
    }
    return session_ack(req, ans);
}
#endif

static uint8_t handle_status(const proto_frame_t *req, proto_frame_t *ans)
{
    if (req->len != 0)
        return session_nack(req, ans, ERR_BAD_PAYLOAD);
    msg_status_t s;
    uint8_t ev;
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
        s.position = ax.pos;
        s.target = ax.homing ? ax.pos : ax.target;
        s.speed = ax.v;
        ev = ax.events;
    }
    uint8_t homing = ax.homing && !(ev & AX_EV_HOME);
    s.flags = (uint8_t)((s.speed != 0.0f || s.position != s.target) && !(ev & AX_EV_HOME) ? ST_MOVING : 0);
    if (ax.homed || (ev & AX_EV_HOME)) s.flags |= ST_HOMED;
    if (homing) s.flags |= ST_HOMING;
    if (g_config.flags & CFG_HAS_SENSOR) s.flags |= ST_HAS_SENSOR;
    if (ax.hl_stowing) s.flags |= ST_HOST_LOSS_STOWING;
    s.limit_bits = read_switches();
    s.fault_bits = ax.faults;
    if (ev & AX_EV_LIMIT) s.fault_bits |= FAULT_LIMIT;
    if (ev & AX_EV_HOME) s.fault_bits &= (uint16_t)~FAULT_RESET;
    if (!(PIND & FAULT_BIT)) s.fault_bits |= FAULT_DRIVER;
    if ((g_config.flags & CFG_HAS_SENSOR) && !g_sensor_ok) s.fault_bits |= FAULT_SENSOR;
    s.sensor_angle = sensor_angle();
    s.uptime_ms = millis();
    ans->type = MSG_STATUS;
    ans->len = msg_status(ans->payload, &s);
    return 1;
}

static uint8_t axis_handle(const proto_frame_t *req, proto_frame_t *ans)
{
    switch (req->type) {
    case MSG_GET_STATUS:
        return handle_status(req, ans);
    case MSG_MOVE_TO:
        return handle_move(req, ans);
    case MSG_STOP:
        if (req->len != 0)
            return session_nack(req, ans, ERR_BAD_PAYLOAD);
        ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
            stop_motion(0.0f);
            ax.hl_stowing = 0;
        }
        return session_ack(req, ans);
    case MSG_SET_HOST_LOSS_STOW:
        return handle_host_loss(req, ans);
#ifndef AXIS_NO_SWITCHES
    case MSG_HOME:
        return handle_home(req, ans);
#endif
    case MSG_SET_ZERO: {
        int32_t p;
        if (msg_parse_i32(req, &p))
            return session_nack(req, ans, ERR_BAD_PAYLOAD);
        ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
            ax.pos = ax.goal = ax.target = ax.pf_int = p;
            ax.pf_frac = 0.0f;
            ax.v = 0.0f;
            ax.homing = 0;
            ax.homed = 1;
            ax.faults &= (uint16_t)~FAULT_RESET;
        }
        return session_ack(req, ans);
    }
    default:
        return 0;
    }
}

static void axis_host_silent(void)
{
    uint8_t was_moving = moving();
    ATOMIC_BLOCK(ATOMIC_RESTORESTATE) {
        if (was_moving)
            ax.faults |= FAULT_WATCHDOG;
        stop_motion(fabsf(ax.v) / AXIS_WATCHDOG_STOP_S);
        ax.hl_stowing = 0;
    }
    g_hl_armed = g_hl.mode != HL_OFF;
    g_hl_since = millis();
}

static uint8_t axis_busy(void) { return moving(); }
static uint8_t axis_may_sleep(void) { return 1; }

const BoardDef BOARD = {
#ifdef AXIS_NO_SWITCHES
    KIND_AXIS_STEPPER, "sslfr-axis-nosw",
#else
    KIND_AXIS_STEPPER, "sslfr-axis",
#endif
    axis_setup, axis_poll, axis_handle,
    axis_host_silent, axis_busy, axis_may_sleep,
};
