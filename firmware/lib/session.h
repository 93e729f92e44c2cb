/* Board side of the SSLFR protocol v2: one request, one answer, every frame authenticated
 * (docs/protocol.md "Requests and answers" and "Authentication"; the executable model is
 * sim/base.py SimBoard, compared byte for byte by tests/test_fw_protocol.py).
 *
 * - BOOT (null session, seq 0) after power-up;
 * - HELLO (tagged in the null session) opens a *pending* session: HELLO_REPLY with the
 *   board's nonce Nb = SipHash(K, 'sslfr-nb' | boot count | session count), tagged in the
 *   new session; a retried HELLO (same host nonce) gets the same reply again. The first
 *   request that verifies in the pending session makes it the current one (the previous
 *   one ends then: a replayed HELLO cannot end the host's session);
 * - every other request must verify in the current session: else NACK AUTH (NO_SESSION
 *   when the board has none), never executed, counted; an authenticated request older
 *   than the last one is NACK REPLAY (counted as stale); refusals are sent at most once
 *   per SESSION_REFUSAL_MS (a flood is counted, not echoed);
 * - a duplicate of the last request (same seq and type: the host retried because the
 *   answer was lost) re-sends the cached answer with a new seq, without executing it;
 * - a frame of another protocol version is refused NACK VERSION;
 * - PROVISION (tagged under the null key) sets the installation key, only inside the
 *   provisioning window the firmware opens after an external reset (the USB adapter's
 *   DTR or the reset button: never from the radio), else NACK LOCKED;
 * - only new authenticated requests feed the host-silence watchdog (1 s).
 * Plain C99; the firmware supplies the I/O, the key store and the request handler. */
#ifndef SSLFR_SESSION_H
#define SSLFR_SESSION_H

#include <stdint.h>
#include "auth.h"
#include "proto.h"

#ifdef __cplusplus
extern "C" {
#endif

#define SESSION_WATCHDOG_MS 1000u
#define SESSION_CACHE_MAX 32
#define SESSION_REFUSAL_MS 50u          /* least time between two refusal NACKs */
#define SESSION_PROVISION_MS 10000u     /* provisioning window after an external reset */

typedef struct session session_t;
/* Handle one request; fill ans->type/len/payload and return 1, or return 0 for no
 * answer. Refusals are answers: session_nack(). */
typedef uint8_t (*session_handler_fn)(session_t *s, const proto_frame_t *req, proto_frame_t *ans);
typedef void (*session_write_fn)(void *ctx, const uint8_t *data, uint8_t n);
/* Store a new installation key (EEPROM); 0 = failed (NACK INTERNAL). */
typedef uint8_t (*session_store_key_fn)(const uint8_t key[SIP_KEY_SIZE]);

/* One session as the board keeps it: tags, the host's numbers, its own. */
typedef struct __attribute__((packed)) {
    auth_keys_t keys;
    proto_seq_tracker_t rx;
    uint32_t tx;                        /* next own frame number */
    uint8_t active;
} session_keys_t;

/* packed, pointers last: the simavr harness reads the counters from the firmware's RAM
 * with offsetof() computed on the host */
struct __attribute__((packed)) session {
    proto_framer_t framer;
    uint8_t key[SIP_KEY_SIZE];
    auth_keys_t null_keys;              /* the null session of the key */
    uint16_t null_tx;
    session_keys_t cur, pend;
    uint16_t hello_ref;                 /* the pending session's HELLO (its reply is resent) */
    uint32_t session_count;             /* sessions opened since boot (the board nonce) */
    uint8_t kind;
    uint8_t has_last_req, last_req_type;
    uint16_t last_req_seq;
    uint8_t cached_valid, cached_type, cached_len;
    uint8_t cached[SESSION_CACHE_MAX];
    uint8_t refused, provision_open;
    uint32_t last_refusal_ms, provision_from_ms;
    uint8_t heard, watchdog_tripped, reset_pending;
    uint32_t last_heard_ms, now_ms;
    uint32_t frames_in, frames_out, requests_stale, requests_duplicate, watchdog_trips, version_errors,
        auth_failures, no_session, sessions, boot_count, provision_refused;
    session_handler_fn handler;
    session_write_fn write;
    session_store_key_fn store_key;
    void *ctx;
};

/* key: the board's installation key (NULL: unprovisioned, the null key); boot_count: the
 * EEPROM boot counter, already advanced for this start. */
void session_init(session_t *s, uint8_t kind, const uint8_t *key, uint32_t boot_count,
                  session_handler_fn handler, session_write_fn write, session_store_key_fn store_key,
                  void *ctx);
/* Send BOOT (call once after power-up, after session_init). */
void session_boot(session_t *s);
/* Open the provisioning window at now_ms (the firmware: after an external reset). */
void session_open_provisioning(session_t *s, uint32_t now_ms);
/* Bytes from the host at board time now_ms [ms]. */
void session_rx(session_t *s, const uint8_t *data, uint16_t n, uint32_t now_ms);
/* Advance to now_ms [ms]; returns 1 exactly once when the host has been silent for
 * SESSION_WATCHDOG_MS since the last new authenticated request (not before the first). */
uint8_t session_watchdog(session_t *s, uint32_t now_ms);
/* Send an unsolicited frame (samples) in the current session; returns the bytes written
 * (0: no session, nothing sent). */
uint8_t session_send(session_t *s, uint8_t type, const uint8_t *payload, uint8_t len);
/* Helpers for handlers: fill ans with ACK / NACK(code) of request req, return 1. */
uint8_t session_ack(const proto_frame_t *req, proto_frame_t *ans);
uint8_t session_nack(const proto_frame_t *req, proto_frame_t *ans, uint8_t code);

#ifdef __cplusplus
}
#endif
#endif
