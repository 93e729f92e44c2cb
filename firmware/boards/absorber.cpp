/* Absorber board (seed 000 section 3.5.3, Temperature PCB, plus the five limit
 * switches of section 3.5.1): two MAX6675 type-K converters (inlet, outlet) on SPI read
 * every 250 ms (conversion time 220 ms) and sent raw (THERMOCOUPLE_SAMPLE; the host
 * decodes, an open thermocouple stays visible as D2); the five switches sampled every
 * millisecond and sent raw (SWITCH_SAMPLE) at 20 Hz and at every change.
 *
 * Pins (Arduino Pro Mini): D2 initial, D3 last, D4 sleeping, D5 longitudinal 1,
 * D6 longitudinal 2 switches (inputs, pull-ups, switch to GND); D9 /CS inlet,
 * D10 /CS outlet, D12 SO (MISO), D13 SCK of the MAX6675s.
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
    }
    uint8_t bits = read_switches();
    if (bits != g_last_bits || (int32_t)(now - g_next_switch) >= 0) {
        g_last_bits = bits;
        g_next_switch = now + SWITCH_PERIOD_MS;
        board_send(MSG_SWITCH_SAMPLE, p, msg_switches(p, now, bits));
    }
}

static uint8_t absorber_handle(const proto_frame_t *, proto_frame_t *) { return 0; }
static void absorber_silent(void) {}
static uint8_t absorber_busy(void) { return 0; }
static uint8_t absorber_may_sleep(void) { return 1; }

const BoardDef BOARD = {
    KIND_ABSORBER, "sslfr-absorber", absorber_setup, absorber_poll, absorber_handle,
    absorber_silent, absorber_busy, absorber_may_sleep,
};
