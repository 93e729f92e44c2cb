/* SipHash-2-4: see siphash.h. */
#include "siphash.h"

#include <string.h>

/* the rotations of a SipRound; on the AVR (8-bit registers) the ones by 16 and 32 are
 * byte moves, the others a byte move and a few single-bit shifts */
#define ROTL(x, b) (uint64_t)(((x) << (b)) | ((x) >> (64 - (b))))

static uint64_t load64(const uint8_t *p)
{
    uint64_t v;
    memcpy(&v, p, 8);            /* the AVR and x86 are little-endian */
    return v;
}

static void rounds(sip_t *s, uint8_t n)
{
    uint64_t v0 = s->v0, v1 = s->v1, v2 = s->v2, v3 = s->v3;
    while (n--) {
        v0 += v1; v1 = ROTL(v1, 13); v1 ^= v0; v0 = ROTL(v0, 32);
        v2 += v3; v3 = ROTL(v3, 16); v3 ^= v2;
        v0 += v3; v3 = ROTL(v3, 21); v3 ^= v0;
        v2 += v1; v1 = ROTL(v1, 17); v1 ^= v2; v2 = ROTL(v2, 32);
    }
    s->v0 = v0; s->v1 = v1; s->v2 = v2; s->v3 = v3;
}

static void block(sip_t *s, uint64_t m)
{
    s->v3 ^= m;
    rounds(s, 2);
    s->v0 ^= m;
}

void sip_init(sip_t *s, const uint8_t key[SIP_KEY_SIZE])
{
    uint64_t k0 = load64(key), k1 = load64(key + 8);
    s->v0 = k0 ^ 0x736f6d6570736575ULL;
    s->v1 = k1 ^ 0x646f72616e646f6dULL;
    s->v2 = k0 ^ 0x6c7967656e657261ULL;
    s->v3 = k1 ^ 0x7465646279746573ULL;
    s->len = 0;
}

void sip_absorb(sip_t *s, const uint8_t *data, uint8_t nblocks)
{
    while (nblocks--) {
        block(s, load64(data));
        data += 8;
        s->len = (uint8_t)(s->len + 8);
    }
}

void sip_tag(const sip_t *st, const uint8_t *data, uint8_t n, uint8_t out[SIP_TAG_SIZE])
{
    sip_t s = *st;
    uint8_t last[8] = {0};
    uint8_t total = (uint8_t)(s.len + n);
    while (n >= 8) {
        block(&s, load64(data));
        data += 8;
        n = (uint8_t)(n - 8);
    }
    memcpy(last, data, n);
    last[7] = total;              /* the length modulo 256 in the last byte */
    block(&s, load64(last));
    s.v2 ^= 0xff;
    rounds(&s, 4);
    uint64_t t = s.v0 ^ s.v1 ^ s.v2 ^ s.v3;
    memcpy(out, &t, 8);
}

void siphash24(const uint8_t key[SIP_KEY_SIZE], const uint8_t *data, uint8_t n, uint8_t out[SIP_TAG_SIZE])
{
    sip_t s;
    sip_init(&s, key);
    sip_tag(&s, data, n, out);
}
