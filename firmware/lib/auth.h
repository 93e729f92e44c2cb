/* Authentication of the SSLFR board protocol v2 (docs/protocol.md "Authentication";
 * Python: src/sslfr_drivers/sslfr_drivers/link/auth.py). Every frame carries
 *
 *   tag = SipHash-2-4(K, prefix | frame bytes 2 .. 9+N)        (8 bytes, little-endian)
 *   prefix = 'sslfr' | direction (1 host->board, 2 board->host) | epoch (u16) | Nh | Nb
 *
 * with K the installation key, Nh / Nb the session's nonces (both zero: the null session
 * of HELLO, BOOT and NO_SESSION) and the epoch the upper half of the sender's 32-bit frame
 * count in the session (the wire carries the lower half). The prefix is absorbed once per
 * session, direction and epoch (auth_keys_t caches the two states), so a frame costs its
 * 8-byte header block, its payload blocks and the finalisation. Plain C99. */
#ifndef SSLFR_AUTH_H
#define SSLFR_AUTH_H

#include <stdint.h>
#include "proto.h"
#include "siphash.h"

#ifdef __cplusplus
extern "C" {
#endif

#define AUTH_H2B 1
#define AUTH_B2H 2
#define AUTH_NONCE_SIZE 8

typedef struct __attribute__((packed)) {
    sip_t st;                  /* state after the prefix of `epoch` */
    uint16_t epoch;
    uint8_t valid;
} auth_dir_t;

/* The keys of one session (or of the null session: nonces zero). */
typedef struct __attribute__((packed)) {
    uint8_t nh[AUTH_NONCE_SIZE], nb[AUTH_NONCE_SIZE];
    auth_dir_t dir[2];         /* [0] host->board, [1] board->host */
} auth_keys_t;

/* nh / nb NULL: zero (the null session). */
void auth_keys_init(auth_keys_t *k, const uint8_t key[SIP_KEY_SIZE], const uint8_t *nh, const uint8_t *nb);
/* The tag of frame f (its version, len, flags, seq, ref, type, payload) sent in direction
 * dir as the sender's frame number full (32 bits). */
void auth_tag(auth_keys_t *k, const uint8_t key[SIP_KEY_SIZE], uint8_t dir, uint32_t full,
              const proto_frame_t *f, uint8_t out[SIP_TAG_SIZE]);
/* Set f->seq to the low half of full and f->tag to its tag. */
void auth_seal(auth_keys_t *k, const uint8_t key[SIP_KEY_SIZE], uint8_t dir, uint32_t full, proto_frame_t *f);
/* 1 when f->tag is the tag of f for frame number full (constant time). */
uint8_t auth_verify(auth_keys_t *k, const uint8_t key[SIP_KEY_SIZE], uint8_t dir, uint32_t full,
                    const proto_frame_t *f);
/* The board's session nonce: SipHash-2-4(K, 'sslfr-nb' | boot count u32 | session count u32). */
void auth_board_nonce(const uint8_t key[SIP_KEY_SIZE], uint32_t boot_count, uint32_t session_count,
                      uint8_t out[AUTH_NONCE_SIZE]);

#ifdef __cplusplus
}
#endif
#endif
