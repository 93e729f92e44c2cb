/* Cost of the protocol's message authentication code on the ATmega328P (16 MHz), counted
 * in CPU cycles by Timer1 (no prescaler, overflows counted) and printed on the UART as
 * text; run in simavr (cycle-exact): `make -C firmware bench` then
 * `simavr -m atmega328p -f 16000000 firmware/build/macbench.elf`, or
 * benchmarks/bench_link_latency.py, which does both. The figures are what the boards
 * pay per frame (lib/auth.c): verifying a MOVE_TO (8-byte payload), tagging a STATUS
 * (24 bytes), opening a session (prefix states of both directions + the board nonce). */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/sleep.h>
#include <stdio.h>

#include "auth.h"

static volatile uint16_t g_ovf;
ISR(TIMER1_OVF_vect) { g_ovf++; }

static uint32_t cycles(void)
{
    uint8_t sreg = SREG;
    cli();
    uint16_t t = TCNT1;
    uint16_t o = g_ovf;
    if ((TIFR1 & _BV(TOV1)) && t < 0x8000)
        o++;
    SREG = sreg;
    return ((uint32_t)o << 16) | t;
}

static int uart_putc(char c, FILE *f)
{
    (void)f;
    while (!(UCSR0A & _BV(UDRE0))) {
    }
    UDR0 = (uint8_t)c;
    return 0;
}
static FILE g_out = FDEV_SETUP_STREAM(uart_putc, NULL, _FDEV_SETUP_WRITE);

#define N 32
static const uint8_t KEY[16] = {0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15};
static auth_keys_t g_keys;
static proto_frame_t g_f;
volatile uint8_t g_sink;

int main(void)
{
    UBRR0 = 8;                      /* 115200 bit/s at 16 MHz */
    UCSR0B = _BV(TXEN0);
    stdout = &g_out;
    TCCR1A = 0;
    TCCR1B = _BV(CS10);
    TIMSK1 = _BV(TOIE1);
    sei();
    static const uint8_t nh[8] = {1, 2, 3, 4, 5, 6, 7, 8}, nb[8] = {9, 10, 11, 12, 13, 14, 15, 16};
    uint8_t tag[8];
    uint32_t t0, base, c_open, c_move, c_status, c_nonce, c_sip;

    t0 = cycles();
    for (uint8_t i = 0; i < N; i++)
        g_sink++;
    base = cycles() - t0;

    t0 = cycles();
    for (uint8_t i = 0; i < N; i++)
        auth_keys_init(&g_keys, KEY, nh, nb);
    c_open = cycles() - t0 - base;

    g_f.version = PROTO_VERSION; g_f.type = 0x10; g_f.len = 8; g_f.seq = 5;
    auth_keys_init(&g_keys, KEY, nh, nb);
    t0 = cycles();
    for (uint8_t i = 0; i < N; i++)
        g_sink += auth_verify(&g_keys, KEY, AUTH_H2B, 5, &g_f);
    c_move = cycles() - t0 - base;

    g_f.type = 0x83; g_f.len = 24; g_f.flags = 1;
    t0 = cycles();
    for (uint8_t i = 0; i < N; i++)
        auth_seal(&g_keys, KEY, AUTH_B2H, 7, &g_f);
    c_status = cycles() - t0 - base;

    t0 = cycles();
    for (uint8_t i = 0; i < N; i++)
        auth_board_nonce(KEY, 1, i, tag);
    c_nonce = cycles() - t0 - base;

    t0 = cycles();
    for (uint8_t i = 0; i < N; i++)
        siphash24(KEY, g_f.payload, 0, tag);
    c_sip = cycles() - t0 - base;

    printf("MACBENCH n=%u verify_move_to=%lu seal_status=%lu open_session=%lu board_nonce=%lu siphash_empty=%lu\n",
           (unsigned)N, c_move / N, c_status / N, c_open / N, c_nonce / N, c_sip / N);
    while (!(UCSR0A & _BV(TXC0))) {
    }
    cli();
    sleep_cpu();                    /* interrupts off: simavr stops */
    return 0;
}
