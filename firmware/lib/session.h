/* Board side of the SSLFR protocol: one request, one answer (docs/protocol.md
 * "Requests and answers", the executable model is sim/base.py SimBoard).
 *
 * - a frame of another protocol version is answered NACK(VERSION) and not heard;
 * - every valid frame feeds the host-silence watchdog (1 s, session_watchdog());
 * - a duplicate of the last request (same seq and type: the host retried because the
 *   answer was lost) re-sends the cached answer with a new seq, without executing it;
 * - stale requests are ignored, except PING / GET_INFO (a restarted host) and the
 *   third stale request in a row, which resynchronise the host tracker;
 * - BOOT (seq 0) after power-up.
 * Plain C99; the firmware supplies the I/O and the request handler. */
#ifndef SSLFR_SESSION_H
#define SSLFR_SESSION_H

#include <stdint.h>
#include "proto.h"

#ifdef __cplusplus
extern "C" {
#endif

#define SESSION_WATCHDOG_MS 1000u
#define SESSION_CACHE_MAX 32

typedef struct session session_t;
/* Handle one request; fill ans->type/len/payload and return 1, or return 0 for no
 * answer. Refusals are answers: session_nack(). */
typedef uint8_t (*session_handler_fn)(session_t *s, const proto_frame_t *req, proto_frame_t *ans);
typedef void (*session_write_fn)(void *ctx, const uint8_t *data, uint8_t n);

/* packed, pointers last: the simavr harness reads the counters from the firmware's RAM
 * with offsetof() computed on the host */
struct __attribute__((packed)) session {
    proto_framer_t framer;
    proto_seq_tracker_t host;
    uint16_t tx_seq;
    uint8_t kind;
    uint8_t has_last_req, last_req_type;
    uint16_t last_req_seq;
    uint8_t cached_valid, cached_type, cached_len;
    uint8_t cached[SESSION_CACHE_MAX];
    uint8_t stale_run;
    uint8_t heard, watchdog_tripped, reset_pending;
    uint32_t last_heard_ms, now_ms;
    uint32_t frames_in, frames_out, requests_stale, requests_duplicate, watchdog_trips, version_errors;
    session_handler_fn handler;
    session_write_fn write;
    void *ctx;
};

void session_init(session_t *s, uint8_t kind, session_handler_fn handler, session_write_fn write, void *ctx);
/* Send BOOT (call once after power-up, after session_init). */
void session_boot(session_t *s);
/* Bytes from the host at board time now_ms [ms]. */
void session_rx(session_t *s, const uint8_t *data, uint16_t n, uint32_t now_ms);
/* Advance to now_ms [ms]; returns 1 exactly once when the host has been silent for
 * SESSION_WATCHDOG_MS since the last valid frame (not before the first one). */
uint8_t session_watchdog(session_t *s, uint32_t now_ms);
/* Send an unsolicited frame (samples); returns the bytes written. */
uint8_t session_send(session_t *s, uint8_t type, const uint8_t *payload, uint8_t len);
/* Helpers for handlers: fill ans with ACK / NACK(code) of request req, return 1. */
uint8_t session_ack(const proto_frame_t *req, proto_frame_t *ans);
uint8_t session_nack(const proto_frame_t *req, proto_frame_t *ans, uint8_t code);

#ifdef __cplusplus
}
#endif
#endif
