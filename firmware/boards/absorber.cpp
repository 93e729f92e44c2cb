/* Absorber board (seed 000 section 3.5.3, Temperature PCB, plus the five limit
 * switches of section 3.5.1): two MAX6675 type-K converters (inlet, outlet) on SPI read
 * every 250 ms (conversion time 220 ms) and sent raw (THERMOCOUPLE_SAMPLE; the host
 * decodes, an open thermocouple stays visible as D2); the five switches sampled every
 * millisecond and sent raw (SWITCH_SAMPLE) at 20 Hz and at every change.
 *
 * Pins (Arduino Pro Mini): D2 initial, D3 last, D4 sleeping, D5 longitudinal 1,
 * D6 longitudinal 2 switches (inputs, pull-ups, switch to GND); D9 /CS inlet,
 * D10 /CS outlet, D12 SO (MISO), D13 SCK of the MAX6675s.
 *
 * Pulse input (cup anemometer): SET_PULSE_INPUT names one free pin (D7, D8, D11,
 * A0..A3; input with pull-up, a reed contact or open collector to GND); its falling
 * edges are counted in the pin-change interrupt (an edge within 1 ms of the last
 * counted one is contact bounce, not counted) and the running count goes out as
 * PULSE_SAMPLE with every thermocouple sample (4 Hz). Not stored: the host sets it
 * whenever its link comes up.
 */
#include "board.h"

#include <SPI.h>

#define CS_INLET 9
#define CS_OUTLET 10
#define THERMO_PERIOD_MS 250u
#define SWITCH_PERIOD_MS 50u

static const uint8_t SWITCH_PINS[5] = {2, 3, 4, 5, 6};
static uint32_t g_next_thermo, g_next_switch;
static uint8_t g_last_bits = 0xFF;
uint16_t g_words[2] __attribute__((used));   /* last MAX6675 words (inlet, outlet) */

/* ---- pulse input (anemometer) */
#define PULSE_LOCKOUT_US 1000u
static const uint8_t PULSE_PINS[] = {7, 8, 11, 14, 15, 16, 17};
uint8_t g_pulse_pin __attribute__((used)) = PULSE_PIN_OFF;   /* the harness follows it */
static volatile uint8_t *g_pulse_reg;
static uint8_t g_pulse_mask;
static volatile uint8_t g_pulse_level;
static volatile uint32_t g_pulse_us;
volatile uint32_t g_pulses __attribute__((used));    /* falling edges since SET_PULSE_INPUT */

static void pulse_edge(void)
{
    if (!g_pulse_reg)
        return;
    uint8_t level = (*g_pulse_reg & g_pulse_mask) ? 1 : 0;
    if (g_pulse_level && !level) {
        uint32_t t = micros();
        if ((uint32_t)(t - g_pulse_us) >= PULSE_LOCKOUT_US) {
            g_pulses++;
            g_pulse_us = t;
        }
    }
    g_pulse_level = level;
}

ISR(PCINT0_vect) { pulse_edge(); }
ISR(PCINT1_vect) { pulse_edge(); }
ISR(PCINT2_vect) { pulse_edge(); }

static void pulse_off(void)
{
    if (g_pulse_pin == PULSE_PIN_OFF)
        return;
    *digitalPinToPCMSK(g_pulse_pin) &= (uint8_t)~_BV(digitalPinToPCMSKbit(g_pulse_pin));
    PCICR &= (uint8_t)~_BV(digitalPinToPCICRbit(g_pulse_pin));
    g_pulse_reg = 0;
    g_pulse_pin = PULSE_PIN_OFF;
}

static uint8_t handle_pulse_input(const proto_frame_t *req, proto_frame_t *ans)
{
    if (req->len != 1)
        return session_nack(req, ans, ERR_BAD_PAYLOAD);
    uint8_t pin = req->payload[0], ok = pin == PULSE_PIN_OFF;
    for (uint8_t i = 0; i < sizeof PULSE_PINS; i++)
        ok |= pin == PULSE_PINS[i];
    if (!ok)
        return session_nack(req, ans, ERR_OUT_OF_RANGE);
    cli();
    pulse_off();
    if (pin != PULSE_PIN_OFF) {
        pinMode(pin, INPUT_PULLUP);
        g_pulse_reg = portInputRegister(digitalPinToPort(pin));
        g_pulse_mask = digitalPinToBitMask(pin);
        g_pulse_level = (*g_pulse_reg & g_pulse_mask) ? 1 : 0;
        g_pulses = 0;
        g_pulse_us = micros() - PULSE_LOCKOUT_US;
        g_pulse_pin = pin;
        *digitalPinToPCMSK(pin) |= _BV(digitalPinToPCMSKbit(pin));
        PCIFR = _BV(digitalPinToPCICRbit(pin));
        PCICR |= _BV(digitalPinToPCICRbit(pin));
    }
    sei();
    return session_ack(req, ans);
}

static uint16_t max6675_read(uint8_t cs)
{
    SPI.beginTransaction(SPISettings(1000000, MSBFIRST, SPI_MODE0));
    digitalWrite(cs, LOW);
    uint16_t w = SPI.transfer16(0);
    digitalWrite(cs, HIGH);
    SPI.endTransaction();
    return w;            /* reading also starts the next conversion */
}

static uint8_t read_switches(void)
{
    uint8_t bits = 0;
    for (uint8_t i = 0; i < 5; i++)
        if (digitalRead(SWITCH_PINS[i]) == LOW)
            bits |= (uint8_t)(1u << i);
    return bits;
}

static void absorber_setup(void)
{
    for (uint8_t i = 0; i < 5; i++)
        pinMode(SWITCH_PINS[i], INPUT_PULLUP);
    pinMode(CS_INLET, OUTPUT);
    pinMode(CS_OUTLET, OUTPUT);
    digitalWrite(CS_INLET, HIGH);
    digitalWrite(CS_OUTLET, HIGH);
    SPI.begin();
    uint32_t now = millis();
    g_next_thermo = now + THERMO_PERIOD_MS;   /* first conversion after power-up */
    g_next_switch = now;
}

static void absorber_poll(uint32_t now)
{
    uint8_t p[8];
    if ((int32_t)(now - g_next_thermo) >= 0) {
        g_next_thermo += THERMO_PERIOD_MS;
        if ((int32_t)(now - g_next_thermo) >= 0)
            g_next_thermo = now + THERMO_PERIOD_MS;
        g_words[0] = max6675_read(CS_INLET);
        g_words[1] = max6675_read(CS_OUTLET);
        board_send(MSG_THERMOCOUPLE_SAMPLE, p, msg_thermocouple(p, now, g_words[0], g_words[1]));
        if (g_pulse_pin != PULSE_PIN_OFF) {
            uint8_t q[9];
            uint32_t n;
            cli();
            n = g_pulses;
            sei();
            board_send(MSG_PULSE_SAMPLE, q, msg_pulses(q, now, n, g_pulse_pin));
        }
    }
    uint8_t bits = read_switches();
    if (bits != g_last_bits || (int32_t)(now - g_next_switch) >= 0) {
        g_last_bits = bits;
        g_next_switch = now + SWITCH_PERIOD_MS;
        board_send(MSG_SWITCH_SAMPLE, p, msg_switches(p, now, bits));
    }
}

static uint8_t absorber_handle(const proto_frame_t *req, proto_frame_t *ans)
{
    return req->type == MSG_SET_PULSE_INPUT ? handle_pulse_input(req, ans) : 0;
}
static void absorber_silent(void) {}
static uint8_t absorber_busy(void) { return 0; }
static uint8_t absorber_may_sleep(void) { return 1; }

const BoardDef BOARD = {
    KIND_ABSORBER, "sslfr-absorber", absorber_setup, absorber_poll, absorber_handle,
    absorber_silent, absorber_busy, absorber_may_sleep,
};
