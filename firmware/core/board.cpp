/* Common firmware of the SSLFR boards: see board.h and docs/firmware.md. */
#include "board.h"

#include <avr/eeprom.h>
#include <avr/sleep.h>
#include <avr/wdt.h>
#include <string.h>

#ifndef FW_MAJOR
#error "FW_MAJOR/FW_MINOR/FW_PATCH come from the Makefile"
#endif

board_config_t g_config;
session_t g_session;
uint8_t g_reset_cause __attribute__((section(".noinit")));

/* As on every AVR that uses the watchdog: read and clear the reset cause and stop the
 * watchdog before anything else runs (after a watchdog reset WDE stays set with the
 * shortest time-out, and the C start-up alone could outlast it). */
extern "C" void early_init(void) __attribute__((naked, used, section(".init3")));
void early_init(void)
{
    g_reset_cause = MCUSR;
    MCUSR = 0;
    wdt_disable();
}

static void serial_write(void *, const uint8_t *data, uint8_t n) { Serial.write(data, n); }

void board_send(uint8_t type, const uint8_t *payload, uint8_t len) { session_send(&g_session, type, payload, len); }

static void load_config(void)
{
    uint8_t raw[CONFIG_EEPROM_SIZE];
    eeprom_read_block(raw, (const void *)0, CONFIG_EEPROM_SIZE);
    uint16_t crc = proto_crc16(raw, CONFIG_SIZE, 0xFFFF);
    config_unpack(raw, &g_config);
    if (crc != proto_get_u16(raw + CONFIG_SIZE) || config_check(&g_config, BOARD.kind) != 0)
        config_defaults(&g_config, BOARD.kind);      /* blank or foreign EEPROM */
}

static uint8_t store_config(const board_config_t *c)
{
    uint8_t raw[CONFIG_EEPROM_SIZE], back[CONFIG_EEPROM_SIZE];
    config_pack(c, raw);
    proto_put_u16(raw + CONFIG_SIZE, proto_crc16(raw, CONFIG_SIZE, 0xFFFF));
    eeprom_update_block(raw, (void *)0, CONFIG_EEPROM_SIZE);
    eeprom_read_block(back, (const void *)0, CONFIG_EEPROM_SIZE);
    return memcmp(raw, back, CONFIG_EEPROM_SIZE) == 0;
}

static uint8_t common_type(uint8_t type)
{
    return type == MSG_PING || type == MSG_GET_INFO || type == MSG_RESET
        || type == MSG_GET_CONFIG || type == MSG_SET_CONFIG;
}

static uint8_t handle(session_t *s, const proto_frame_t *req, proto_frame_t *ans)
{
    if (!common_type(req->type)) {
        /* a board request (the board checks its payload) or UNKNOWN_TYPE */
        if (BOARD.handle(req, ans))
            return 1;
        return session_nack(req, ans, ERR_UNKNOWN_TYPE);
    }
    if (req->len != (uint8_t)msg_request_size(req->type))
        return session_nack(req, ans, ERR_BAD_PAYLOAD);
    switch (req->type) {
    case MSG_PING:
        return session_ack(req, ans);
    case MSG_GET_INFO:
        ans->type = MSG_INFO;
        ans->len = msg_info(ans->payload, BOARD.kind, FW_MAJOR, FW_MINOR, FW_PATCH,
                            g_config.board_id, BOARD.name);
        return 1;
    case MSG_RESET:
        s->reset_pending = 1;
        return session_ack(req, ans);
    case MSG_GET_CONFIG:
        ans->type = MSG_CONFIG;
        config_pack(&g_config, ans->payload);
        ans->len = CONFIG_SIZE;
        return 1;
    default: {   /* MSG_SET_CONFIG */
        board_config_t c;
        config_unpack(req->payload, &c);
        if (config_check(&c, BOARD.kind) != 0)
            return session_nack(req, ans, ERR_OUT_OF_RANGE);
        if (BOARD.busy())
            return session_nack(req, ans, ERR_BUSY);
        if (!store_config(&c))
            return session_nack(req, ans, ERR_INTERNAL);
        return session_ack(req, ans);   /* takes effect at the next start (RESET) */
    }
    }
}

static void reboot(void)
{
    Serial.flush();                 /* the ACK of RESET leaves first */
    cli();
    wdt_enable(WDTO_15MS);
    for (;;) {
    }
}

void setup(void)
{
    /* INT0/INT1 (D2, D3) are not used as interrupts: sense "rising edge" instead of the
     * reset default "low level". No effect on the hardware (EIMSK stays 0), but simavr
     * polls a low INT pin every cycle in low-level mode, 10x slower simulation. */
    EICRA = _BV(ISC11) | _BV(ISC10) | _BV(ISC01) | _BV(ISC00);
    load_config();
    Serial.begin(g_config.baud);
    session_init(&g_session, BOARD.kind, handle, serial_write, 0);
    BOARD.setup();
    session_boot(&g_session);
    wdt_enable(WDTO_500MS);         /* a main loop stuck for 0.5 s resets the board */
}

void loop(void)
{
    wdt_reset();
    uint32_t now = millis();
    uint8_t buf[16];
    uint8_t n = 0;
    while (n < sizeof(buf) && Serial.available() > 0)
        buf[n++] = (uint8_t)Serial.read();
    if (n)
        session_rx(&g_session, buf, n, now);
    if (g_session.reset_pending)
        reboot();
    if (session_watchdog(&g_session, now))
        BOARD.host_silent();
    BOARD.poll(now);
    /* idle sleep until the next interrupt (UART byte, 1 ms timer tick, step timer...) */
    cli();
    if (Serial.available() == 0 && BOARD.may_sleep()) {
        set_sleep_mode(SLEEP_MODE_IDLE);
        sleep_enable();
        sei();
        sleep_cpu();
        sleep_disable();
    }
    sei();
}
