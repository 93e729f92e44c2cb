/* Irradiance board (seed 000 section 3.5.5): a VEML7700 ambient light sensor on I2C
 * (address 0x10), one sample per second sent raw with the gain and integration-time
 * codes it was taken with (ALS_SAMPLE; the host converts to lux, 104 lm/W, and flags
 * saturation: count 65535, or above 120 klx).
 *
 * Auto-ranging (Vishay application note "Designing the VEML7700 into an application",
 * the same ladder as sslfr_drivers/veml7700.py): from least to most sensitive
 * (x1/8, 25 ms) (x1/8, 50) (x1/8, 100) (x1/4, 100) (x1, 100) (x2, 100) (x2, 200)
 * (x2, 400) (x2, 800); one step per sample, up at <= 100 counts, down above 10,000.
 * The least sensitive setting reaches 65535 x 1.8432 lx = 120.8 klx: 0-120 klx is
 * covered. After a change the first reading is taken one integration time plus 10 %
 * later (a fresh integration with the new setting).
 *
 * Pins (Arduino Pro Mini): A4 SDA, A5 SCL (external 4.7 kOhm pull-ups to 3.3 V on the
 * sensor module).
 */
#include "board.h"

#include <Wire.h>

#define VEML_ADDR 0x10
#define REG_ALS_CONF 0x00
#define REG_ALS 0x04
#define SAMPLE_PERIOD_MS 1000u
#define LOW_COUNT 100u
#define HIGH_COUNT 10000u

struct Setting { uint8_t gain, it; uint16_t it_ms; };
static const Setting LADDER[9] = {
    {0x2, 0xC, 25}, {0x2, 0x8, 50}, {0x2, 0x0, 100}, {0x3, 0x0, 100}, {0x0, 0x0, 100},
    {0x1, 0x0, 100}, {0x1, 0x1, 200}, {0x1, 0x2, 400}, {0x1, 0x3, 800},
};

static uint8_t g_step = 2;              /* the application note's start: x1/8, 100 ms */
static uint8_t g_state;                 /* 0 configure, 1 integrating */
static uint32_t g_next, g_ready;
uint8_t g_i2c_errors __attribute__((used));

static uint8_t write_reg(uint8_t reg, uint16_t value)
{
    Wire.beginTransmission(VEML_ADDR);
    Wire.write(reg);
    Wire.write((uint8_t)value);
    Wire.write((uint8_t)(value >> 8));
    return Wire.endTransmission() == 0;
}

static uint8_t read_reg(uint8_t reg, uint16_t *value)
{
    Wire.beginTransmission(VEML_ADDR);
    Wire.write(reg);
    if (Wire.endTransmission(false) != 0)
        return 0;
    if (Wire.requestFrom((uint8_t)VEML_ADDR, (uint8_t)2) != 2)
        return 0;
    uint8_t lo = (uint8_t)Wire.read();
    uint8_t hi = (uint8_t)Wire.read();
    *value = (uint16_t)(lo | ((uint16_t)hi << 8));
    return 1;
}

static void irradiance_setup(void)
{
    Wire.begin();
    Wire.setClock(100000);
    g_next = millis() + 100;
    g_state = 0;
}

static void irradiance_poll(uint32_t now)
{
    if (g_state == 0) {
        if ((int32_t)(now - g_next) < 0)
            return;
        const Setting &s = LADDER[g_step];
        /* ALS_GAIN bits 12:11, ALS_IT bits 9:6, persistence 1, interrupt off, power on */
        if (!write_reg(REG_ALS_CONF, (uint16_t)(((uint16_t)s.gain << 11) | ((uint16_t)s.it << 6)))) {
            g_i2c_errors++;
            g_next = now + SAMPLE_PERIOD_MS;
            return;
        }
        g_ready = now + s.it_ms + s.it_ms / 10 + 2;
        g_next += SAMPLE_PERIOD_MS;
        if ((int32_t)(now - g_next) >= 0)
            g_next = now + SAMPLE_PERIOD_MS;
        g_state = 1;
        return;
    }
    if ((int32_t)(now - g_ready) < 0)
        return;
    g_state = 0;
    uint16_t count;
    if (!read_reg(REG_ALS, &count)) {
        g_i2c_errors++;
        return;
    }
    const Setting &s = LADDER[g_step];
    uint8_t p[8];
    board_send(MSG_ALS_SAMPLE, p, msg_als(p, now, count, s.gain, s.it));
    if (count <= LOW_COUNT && g_step < 8)
        g_step++;
    else if (count > HIGH_COUNT && g_step > 0)
        g_step--;
}

static uint8_t irradiance_handle(const proto_frame_t *, proto_frame_t *) { return 0; }
static void irradiance_silent(void) {}
static uint8_t irradiance_busy(void) { return 0; }
static uint8_t irradiance_may_sleep(void) { return 1; }

const BoardDef BOARD = {
    KIND_IRRADIANCE, "sslfr-irradiance", irradiance_setup, irradiance_poll, irradiance_handle,
    irradiance_silent, irradiance_busy, irradiance_may_sleep,
};
