/* SSLFR board protocol v2: frame layout, CRC-16, stateful deframer, sequence tracking.
 *
 * Plain C99 with no Arduino dependency: the same file is compiled for the ATmega328P
 * (firmware) and natively for the host (host/libsslfr_proto.so, driven from pytest
 * against the Python reference codec src/sslfr_drivers/sslfr_drivers/protocol.py).
 * The wire format is specified in docs/protocol.md ("Frame"):
 *
 *   offset size field
 *   0      2    sync A5 5A
 *   2      1    version (PROTO_VERSION = 2)
 *   3      1    length L = N + 8 of payload and tag, 8..PROTO_MAX_BODY
 *   4      1    flags (bit 0 RESPONSE)
 *   5      2    seq (little-endian)
 *   7      2    ref (little-endian)
 *   9      1    type
 *   10     N    payload, 0..PROTO_MAX_PAYLOAD
 *   10+N   8    tag (lib/auth.c)
 *   18+N   2    CRC-16/CCITT-FALSE over bytes 2 .. 17+N (little-endian)
 *
 * Version 1 had no tag (length = N). Bytes 0..3 and the CRC trailer are the same for
 * every version (the tag counts in the length), so a frame of another version is still
 * delimited and CRC-checked (and refused with NACK VERSION).
 */
#ifndef SSLFR_PROTO_H
#define SSLFR_PROTO_H

#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

#define PROTO_VERSION 2
#define PROTO_V1 1
#define PROTO_SYNC0 0xA5
#define PROTO_SYNC1 0x5A
#define PROTO_HEADER 10
#define PROTO_CRC_SIZE 2
#define PROTO_TAG_SIZE 8
#define PROTO_MAX_BODY 88                  /* the length field's largest value */
#define PROTO_MAX_PAYLOAD (PROTO_MAX_BODY - PROTO_TAG_SIZE)
#define PROTO_MAX_FRAME (PROTO_HEADER + PROTO_MAX_BODY + PROTO_CRC_SIZE)
#define PROTO_FLAG_RESPONSE 0x01

/* One decoded frame (payload copied; a version-2 frame's tag apart, other versions have
 * none and up to PROTO_MAX_BODY payload bytes). */
typedef struct {
    uint8_t version;
    uint8_t len;                          /* payload bytes */
    uint8_t flags;
    uint16_t seq;
    uint16_t ref;
    uint8_t type;
    uint8_t payload[PROTO_MAX_BODY];
    uint8_t tag[PROTO_TAG_SIZE];
} proto_frame_t;

/* Bytes of tag a frame of this version carries. */
uint8_t proto_tag_size(uint8_t version);
/* Bytes 2..9 of f's wire form (version, length, flags, seq, ref, type): the first
 * block the tag covers. */
void proto_header(const proto_frame_t *f, uint8_t out[8]);

/* CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, no xor-out) of n bytes,
 * continuing from crc (pass 0xFFFF to start). Check value: "123456789" -> 0x29B1. */
uint16_t proto_crc16(const uint8_t *data, uint16_t n, uint16_t crc);

/* Serialise a frame into out (at least PROTO_MAX_FRAME bytes), its tag included (version
 * 2). Returns the number of bytes written, 0 if the payload does not fit. */
uint8_t proto_encode(const proto_frame_t *f, uint8_t *out);

/* Decode exactly one frame of n bytes. Returns 0 on success, else a PROTO_DECODE_*
 * reason (the Python codec raises FrameError for the same inputs). */
enum { PROTO_DECODE_OK = 0, PROTO_DECODE_SHORT = 1, PROTO_DECODE_SYNC = 2,
       PROTO_DECODE_LENGTH = 3, PROTO_DECODE_CRC = 4 };
uint8_t proto_decode(const uint8_t *data, uint16_t n, proto_frame_t *f);

/* Stateful deframer: bytes in, CRC-checked frames out (any chunking; garbage and
 * damaged frames are skipped: a length above PROTO_MAX_BODY, a CRC mismatch or a
 * version-2 length shorter than the tag drops only the first byte of the candidate, so
 * a good frame starting inside a damaged one is still found). The counters follow
 * protocol.Framer exactly. */
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

/* Sequence numbers of one sender (protocol.SequenceTracker): the 16 bits on the wire
 * classified against the last new one, and the sender's full 32-bit count behind them. */
enum { PROTO_SEQ_NEW = 0, PROTO_SEQ_DUPLICATE = 1, PROTO_SEQ_STALE = 2 };
typedef struct __attribute__((packed)) {
    uint8_t has_last;
    uint32_t last;
    uint32_t received, lost, duplicates, stale;
} proto_seq_tracker_t;

void proto_tracker_init(proto_seq_tracker_t *t);
void proto_tracker_restart(proto_seq_tracker_t *t);
uint8_t proto_tracker_accept(proto_seq_tracker_t *t, uint16_t seq);
/* The full 32-bit number seq stands for: the nearest to the last new one (epoch 0
 * after a restart). */
uint32_t proto_tracker_expand(const proto_seq_tracker_t *t, uint16_t seq);

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
