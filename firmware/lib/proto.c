/* SSLFR board protocol v2: see proto.h and docs/protocol.md. */
#include "proto.h"

#include <string.h>

uint16_t proto_crc16(const uint8_t *data, uint16_t n, uint16_t crc)
{
    while (n--) {
        crc ^= (uint16_t)(*data++) << 8;
        for (uint8_t i = 0; i < 8; i++)
            crc = (crc & 0x8000) ? (uint16_t)((crc << 1) ^ 0x1021) : (uint16_t)(crc << 1);
    }
    return crc;
}

void proto_put_u16(uint8_t *p, uint16_t v) { p[0] = (uint8_t)v; p[1] = (uint8_t)(v >> 8); }
void proto_put_u32(uint8_t *p, uint32_t v)
{
    p[0] = (uint8_t)v; p[1] = (uint8_t)(v >> 8); p[2] = (uint8_t)(v >> 16); p[3] = (uint8_t)(v >> 24);
}
void proto_put_f32(uint8_t *p, float v) { uint32_t u; memcpy(&u, &v, 4); proto_put_u32(p, u); }
uint16_t proto_get_u16(const uint8_t *p) { return (uint16_t)(p[0] | ((uint16_t)p[1] << 8)); }
uint32_t proto_get_u32(const uint8_t *p)
{
    return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}
float proto_get_f32(const uint8_t *p) { uint32_t u = proto_get_u32(p); float v; memcpy(&v, &u, 4); return v; }

uint8_t proto_tag_size(uint8_t version) { return version == PROTO_VERSION ? PROTO_TAG_SIZE : 0; }

void proto_header(const proto_frame_t *f, uint8_t out[8])
{
    out[0] = f->version;
    out[1] = (uint8_t)(f->len + proto_tag_size(f->version));
    out[2] = f->flags;
    proto_put_u16(out + 3, f->seq);
    proto_put_u16(out + 5, f->ref);
    out[7] = f->type;
}

uint8_t proto_encode(const proto_frame_t *f, uint8_t *out)
{
    uint8_t t = proto_tag_size(f->version);
    if (f->len > PROTO_MAX_BODY - t)
        return 0;
    out[0] = PROTO_SYNC0;
    out[1] = PROTO_SYNC1;
    proto_header(f, out + 2);
    memcpy(out + PROTO_HEADER, f->payload, f->len);
    memcpy(out + PROTO_HEADER + f->len, f->tag, t);
    uint8_t body = (uint8_t)(f->len + t);
    proto_put_u16(out + PROTO_HEADER + body, proto_crc16(out + 2, (uint16_t)(PROTO_HEADER - 2 + body), 0xFFFF));
    return (uint8_t)(PROTO_HEADER + body + PROTO_CRC_SIZE);
}

/* 0 when a version-2 body is shorter than its tag */
static uint8_t unpack(const uint8_t *b, proto_frame_t *f)
{
    uint8_t t = proto_tag_size(b[2]);
    if (b[3] < t)
        return 0;
    f->version = b[2];
    f->len = (uint8_t)(b[3] - t);
    f->flags = b[4];
    f->seq = proto_get_u16(b + 5);
    f->ref = proto_get_u16(b + 7);
    f->type = b[9];
    memcpy(f->payload, b + PROTO_HEADER, f->len);
    memcpy(f->tag, b + PROTO_HEADER + f->len, t);
    return 1;
}

static uint8_t crc_ok(const uint8_t *b, uint8_t size)
{
    return proto_get_u16(b + size - 2) == proto_crc16(b + 2, (uint16_t)(size - 4), 0xFFFF);
}

uint8_t proto_decode(const uint8_t *data, uint16_t n, proto_frame_t *f)
{
    if (n < PROTO_HEADER + PROTO_CRC_SIZE)
        return PROTO_DECODE_SHORT;
    if (data[0] != PROTO_SYNC0 || data[1] != PROTO_SYNC1)
        return PROTO_DECODE_SYNC;
    if (data[3] > PROTO_MAX_BODY || n != (uint16_t)(PROTO_HEADER + data[3] + PROTO_CRC_SIZE))
        return PROTO_DECODE_LENGTH;
    if (!crc_ok(data, (uint8_t)n))
        return PROTO_DECODE_CRC;
    if (!unpack(data, f))
        return PROTO_DECODE_LENGTH;
    return PROTO_DECODE_OK;
}

void proto_framer_init(proto_framer_t *fr) { memset(fr, 0, sizeof(*fr)); }

static void drop(proto_framer_t *fr, uint8_t k)
{
    fr->bytes_discarded += k;
    memmove(fr->buf, fr->buf + k, (uint8_t)(fr->n - k));
    fr->n = (uint8_t)(fr->n - k);
}

uint8_t proto_framer_feed(proto_framer_t *fr, uint8_t byte, proto_frame_cb cb, void *ctx)
{
    uint8_t delivered = 0;
    proto_frame_t f;
    /* the buffer never holds more than one maximal frame: every state with a complete
     * candidate is resolved below before the next byte is appended */
    fr->buf[fr->n++] = byte;
    for (;;) {
        uint8_t i = 0;
        while (i + 1 < fr->n && !(fr->buf[i] == PROTO_SYNC0 && fr->buf[i + 1] == PROTO_SYNC1))
            i++;
        if (i + 1 >= fr->n) {
            /* no SYNC: keep a trailing 0xA5, it may be the first half of one */
            uint8_t keep = (fr->n && fr->buf[fr->n - 1] == PROTO_SYNC0) ? 1 : 0;
            drop(fr, (uint8_t)(fr->n - keep));
            break;
        }
        if (i)
            drop(fr, i);
        if (fr->n < 4)
            break;
        if (fr->buf[3] > PROTO_MAX_BODY) {
            fr->length_errors++;
            drop(fr, 1);
            continue;
        }
        uint8_t size = (uint8_t)(PROTO_HEADER + fr->buf[3] + PROTO_CRC_SIZE);
        if (fr->n < size)
            break;
        if (!crc_ok(fr->buf, size)) {
            fr->crc_errors++;
            drop(fr, 1);
            continue;
        }
        if (!unpack(fr->buf, &f)) {
            fr->length_errors++;
            drop(fr, 1);
            continue;
        }
        memmove(fr->buf, fr->buf + size, (uint8_t)(fr->n - size));
        fr->n = (uint8_t)(fr->n - size);
        fr->frames_ok++;
        if (f.version != PROTO_VERSION)
            fr->foreign_version++;
        delivered++;
        if (cb)
            cb(ctx, &f);
    }
    return delivered;
}

void proto_tracker_init(proto_seq_tracker_t *t) { memset(t, 0, sizeof(*t)); }
void proto_tracker_restart(proto_seq_tracker_t *t) { t->has_last = 0; }

uint8_t proto_tracker_accept(proto_seq_tracker_t *t, uint16_t seq)
{
    if (!t->has_last) {
        t->has_last = 1;
        t->last = seq;
        t->received++;
        return PROTO_SEQ_NEW;
    }
    uint16_t delta = (uint16_t)(seq - (uint16_t)t->last);
    if (delta == 0) {
        t->duplicates++;
        return PROTO_SEQ_DUPLICATE;
    }
    if (delta >= 0x8000u) {
        t->stale++;
        return PROTO_SEQ_STALE;
    }
    t->lost += (uint32_t)(delta - 1);
    t->last += delta;
    t->received++;
    return PROTO_SEQ_NEW;
}

uint32_t proto_tracker_expand(const proto_seq_tracker_t *t, uint16_t seq)
{
    if (!t->has_last)
        return seq;
    uint16_t delta = (uint16_t)(seq - (uint16_t)t->last);
    if (delta < 0x8000u)
        return t->last + delta;
    return t->last - (uint32_t)(uint16_t)(0u - delta);
}
