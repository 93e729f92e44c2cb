/* Common firmware of the SSLFR boards: see board.h and docs/firmware.md. */
#include "board.h"
#include "common.h"

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

static uint8_t store_config(const board_config_t *c)
{
    uint8_t raw[CONFIG_EEPROM_SIZE], back[CONFIG_EEPROM_SIZE];
    config_image(c, raw);
    eeprom_update_block(raw, (void *)0, CONFIG_EEPROM_SIZE);
    eeprom_read_block(back, (const void *)0, CONFIG_EEPROM_SIZE);
    return memcmp(raw, back, CONFIG_EEPROM_SIZE) == 0;
}

/* PROVISION: the new installation key, written and read back */
static uint8_t store_key(const uint8_t key[16])
{
    uint8_t raw[KEY_EEPROM_SIZE], back[KEY_EEPROM_SIZE];
    key_image(key, raw);
    eeprom_update_block(raw, (void *)KEY_EEPROM_ADDR, KEY_EEPROM_SIZE);
    eeprom_read_block(back, (const void *)KEY_EEPROM_ADDR, KEY_EEPROM_SIZE);
    return memcmp(raw, back, KEY_EEPROM_SIZE) == 0;
}

/* this start's boot count: the EEPROM counter + 1, stored back (one EEPROM write per start:
 * 100 000 starts of endurance) */
static uint32_t next_boot_count(void)
{
    uint32_t n = boot_count_next(eeprom_read_dword((const uint32_t *)BOOT_EEPROM_ADDR));
    eeprom_update_dword((uint32_t *)BOOT_EEPROM_ADDR, n);
    return n;
}

static const common_board_t COMMON = {
    0, FW_MAJOR, FW_MINOR, FW_PATCH, 0, &g_config, 0, 0, store_config,
};
static common_board_t g_common;

static uint8_t handle(session_t *s, const proto_frame_t *req, proto_frame_t *ans)
{
    return common_handle(&g_common, s, req, ans);
}

/* RESET request: restart the firmware from its reset vector after putting the
 * peripherals it uses back to their reset state. Not through the watchdog: after a
 * watchdog reset the chip starts in the bootloader with the watchdog still running at
 * 16 ms, and the Pro Mini's stock bootloader (ATmegaBOOT) does not stop it, so the board
 * would reset forever (docs/firmware.md "Watchdogs"). */
static void reboot(void)
{
    /* the ACK of RESET leaves first: wait (at most 20 ms) for the transmit buffer to
     * drain, then one character time for the last byte in the shift register */
    uint32_t t0 = millis();
    while (Serial.availableForWrite() < SERIAL_TX_BUFFER_SIZE - 1 && (uint32_t)(millis() - t0) < 20) {
    }
    delayMicroseconds(200);
    cli();
    wdt_disable();
    TIMSK0 = 0; TIMSK1 = 0; TIMSK2 = 0;
    TCCR0A = 0; TCCR0B = 0; TCCR1A = 0; TCCR1B = 0; TCCR2A = 0; TCCR2B = 0;
    UCSR0B = 0; SPCR = 0; TWCR = 0; ADCSRA = 0;
    PCICR = 0; PCMSK0 = 0; PCMSK1 = 0; PCMSK2 = 0; EIMSK = 0;
    TIFR0 = 0xFF; TIFR1 = 0xFF; TIFR2 = 0xFF; PCIFR = 0xFF; EIFR = 0xFF;
    DDRB = 0; DDRC = 0; DDRD = 0; PORTB = 0; PORTC = 0; PORTD = 0;
    asm volatile("jmp 0");
    for (;;) {
    }
}

void setup(void)
{
    /* INT0/INT1 (D2, D3) are not used as interrupts: sense "rising edge" instead of the
     * reset default "low level". No effect on the hardware (EIMSK stays 0), but simavr
     * polls a low INT pin every cycle in low-level mode, 10x slower simulation. */
    EICRA = _BV(ISC11) | _BV(ISC10) | _BV(ISC01) | _BV(ISC00);
    uint8_t raw[CONFIG_EEPROM_SIZE];
    eeprom_read_block(raw, (const void *)0, CONFIG_EEPROM_SIZE);
    config_load(raw, BOARD.kind, &g_config);      /* defaults when blank or foreign */
    g_common = COMMON;
    g_common.kind = BOARD.kind;
    g_common.name = BOARD.name;
    g_common.handle = BOARD.handle;
    g_common.busy = BOARD.busy;
    Serial.begin(g_config.baud);
    uint8_t key[16];
    eeprom_read_block(raw, (const void *)KEY_EEPROM_ADDR, KEY_EEPROM_SIZE);
    key_load(raw, key);                          /* the null key when unprovisioned */
    session_init(&g_session, BOARD.kind, key, next_boot_count(), handle, serial_write, store_key, 0);
    memset(key, 0, sizeof key);
    /* an external reset (the USB adapter's DTR when the port opens, or the reset button):
     * the provisioning window opens; the radio cannot pull the RESET pin */
    if (g_reset_cause & _BV(EXTRF))
        session_open_provisioning(&g_session, millis());
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
