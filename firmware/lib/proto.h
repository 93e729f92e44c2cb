/* SSLFR board protocol v1: frame layout, CRC-16, stateful deframer, sequence tracking.
 *
 * Plain C99 with no Arduino dependency: the same file is compiled for the ATmega328P
 * (firmware) and natively for the host (host/libsslfr_proto.so, driven from pytest
 * against the Python reference codec src/sslfr_drivers/sslfr_drivers/protocol.py).
 * The wire format is specified in docs/protocol.md ("Frame"):
 *
 *   offset size field
 *   0      2    sync A5 5A
 *   2      1    version (PROTO_VERSION)
 *   3      1    length N of the payload, 0..PROTO_MAX_PAYLOAD
 *   4      1    flags (bit 0 RESPONSE)
 *   5      2    seq (little-endian)
 *   7      2    ref (little-endian)
 *   9      1    type
 *   10     N    payload
 *   10+N   2    CRC-16/CCITT-FALSE over bytes 2 .. 9+N (little-endian)
 *
 * Authentication (a later protocol version) is meant to sit between the payload and
 * the CRC: proto_encode() and the framer's completion test are the two places that
 * know the trailer, see PROTO_TRAILER.
 */
#ifndef SSLFR_PROTO_H
#define SSLFR_PROTO_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define PROTO_VERSION 1
#define PROTO_SYNC0 0xA5
#define PROTO_SYNC1 0x5A
#define PROTO_HEADER 10
#define PROTO_CRC_SIZE 2
#define PROTO_TRAILER PROTO_CRC_SIZE      /* bytes after the payload (v2: MAC + CRC) */
#define PROTO_MAX_PAYLOAD 88
#define PROTO_MAX_FRAME (PROTO_HEADER + PROTO_MAX_PAYLOAD + PROTO_TRAILER)
#define PROTO_FLAG_RESPONSE 0x01

/* One decoded frame (payload copied). */
typedef struct {
    uint8_t version;
    uint8_t len;
    uint8_t flags;
    uint16_t seq;
    uint16_t ref;
    uint8_t type;
    uint8_t payload[PROTO_MAX_PAYLOAD];
} proto_frame_t;

/* CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no xor-out) of n bytes,
 * continuing from crc (pass 0xFFFF to start). Check value: "123456789" -> 0x29B1. */
uint16_t proto_crc16(const uint8_t *data, uint16_t n, uint16_t crc);

/* Serialise a frame into out (at least PROTO_HEADER + len + PROTO_TRAILER bytes).
 * Returns the number of bytes written, 0 if len > PROTO_MAX_PAYLOAD. */
uint8_t proto_encode(const proto_frame_t *f, uint8_t *out);

/* Decode exactly one frame of n bytes. Returns 0 on success, else a PROTO_DECODE_*
 * reason (the Python codec raises FrameError for the same inputs). */
enum { PROTO_DECODE_OK = 0, PROTO_DECODE_SHORT = 1, PROTO_DECODE_SYNC = 2,
       PROTO_DECODE_LENGTH = 3, PROTO_DECODE_CRC = 4 };
uint8_t proto_decode(const uint8_t *data, uint16_t n, proto_frame_t *f);

/* Stateful deframer: bytes in, CRC-checked frames out (any chunking; garbage and
 * damaged frames are skipped: a length above PROTO_MAX_PAYLOAD or a CRC mismatch drops
 * only the first byte of the candidate, so a good frame starting inside a damaged one
 * is still found). The counters follow protocol.Framer exactly. */
typedef struct __attribute__((packed)) {
    uint8_t buf[PROTO_MAX_FRAME];
    uint8_t n;
    uint32_t frames_ok;
    uint32_t crc_errors;
    uint32_t length_errors;
    uint32_t bytes_discarded;
    uint32_t foreign_version;
} proto_framer_t;

typedef void (*proto_frame_cb)(void *ctx, const proto_frame_t *f);

void proto_framer_init(proto_framer_t *fr);
/* Feed one byte; calls cb(ctx, frame) for every frame completed by it (a byte can
 * complete more than one frame after a resynchronisation). Returns the number of
 * frames delivered. */
uint8_t proto_framer_feed(proto_framer_t *fr, uint8_t byte, proto_frame_cb cb, void *ctx);

/* Sequence numbers of one sender (protocol.SequenceTracker). */
enum { PROTO_SEQ_NEW = 0, PROTO_SEQ_DUPLICATE = 1, PROTO_SEQ_STALE = 2 };
typedef struct __attribute__((packed)) {
    uint8_t has_last;
    uint16_t last;
    uint32_t received, lost, duplicates, stale;
} proto_seq_tracker_t;

void proto_tracker_init(proto_seq_tracker_t *t);
void proto_tracker_restart(proto_seq_tracker_t *t);
uint8_t proto_tracker_accept(proto_seq_tracker_t *t, uint16_t seq);

/* Little-endian field access (the AVR and x86 are both little-endian, but payloads are
 * byte arrays without alignment: use these, never pointer casts). */
void proto_put_u16(uint8_t *p, uint16_t v);
void proto_put_u32(uint8_t *p, uint32_t v);
void proto_put_f32(uint8_t *p, float v);
uint16_t proto_get_u16(const uint8_t *p);
uint32_t proto_get_u32(const uint8_t *p);
float proto_get_f32(const uint8_t *p);

#ifdef __cplusplus
}
#endif
#endif
