/* SipHash-2-4 with a 64-bit output (Aumasson and Bernstein 2012), able to resume from a
 * saved state: the board protocol's message authentication code (docs/protocol.md
 * "Authentication", lib/auth.c). Plain C99; the same file runs on the ATmega328P and on
 * the host (tests: the paper's reference vectors, libsodium, the Python implementation
 * src/sslfr_drivers/sslfr_drivers/link/siphash.py). */
#ifndef SSLFR_SIPHASH_H
#define SSLFR_SIPHASH_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define SIP_KEY_SIZE 16
#define SIP_TAG_SIZE 8

/* A state that has absorbed a whole number of 8-byte blocks (len = bytes absorbed). */
typedef struct __attribute__((packed)) {
    uint64_t v0, v1, v2, v3;
    uint8_t len;
} sip_t;

void sip_init(sip_t *s, const uint8_t key[SIP_KEY_SIZE]);
/* Absorb nblocks 8-byte blocks. */
void sip_absorb(sip_t *s, const uint8_t *data, uint8_t nblocks);
/* The tag of everything absorbed followed by n more bytes (any n), as 8 little-endian
 * bytes; s is not changed. */
void sip_tag(const sip_t *s, const uint8_t *data, uint8_t n, uint8_t out[SIP_TAG_SIZE]);
/* SipHash-2-4 of n bytes under key, as 8 little-endian bytes. */
void siphash24(const uint8_t key[SIP_KEY_SIZE], const uint8_t *data, uint8_t n, uint8_t out[SIP_TAG_SIZE]);

#ifdef __cplusplus
}
#endif
#endif
