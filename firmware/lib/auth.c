/* Authentication of the board protocol v2: see auth.h. */
#include "auth.h"

#include <string.h>

static sip_t *prefix_state(auth_keys_t *k, const uint8_t *key, uint8_t dir, uint16_t epoch);

void auth_keys_init(auth_keys_t *k, const uint8_t key[SIP_KEY_SIZE], const uint8_t *nh, const uint8_t *nb)
{
    memset(k, 0, sizeof *k);
    if (nh)
        memcpy(k->nh, nh, AUTH_NONCE_SIZE);
    if (nb)
        memcpy(k->nb, nb, AUTH_NONCE_SIZE);
    prefix_state(k, key, AUTH_H2B, 0);       /* the session's cost is paid here, once */
    prefix_state(k, key, AUTH_B2H, 0);
}

static sip_t *prefix_state(auth_keys_t *k, const uint8_t *key, uint8_t dir, uint16_t epoch)
{
    auth_dir_t *d = &k->dir[dir == AUTH_B2H];
    if (!d->valid || d->epoch != epoch) {
        uint8_t block[8] = {'s', 's', 'l', 'f', 'r', dir, (uint8_t)epoch, (uint8_t)(epoch >> 8)};
        sip_init(&d->st, key);
        sip_absorb(&d->st, block, 1);
        sip_absorb(&d->st, k->nh, 1);
        sip_absorb(&d->st, k->nb, 1);
        d->epoch = epoch;
        d->valid = 1;
    }
    return &d->st;
}

void auth_tag(auth_keys_t *k, const uint8_t key[SIP_KEY_SIZE], uint8_t dir, uint32_t full,
              const proto_frame_t *f, uint8_t out[SIP_TAG_SIZE])
{
    sip_t s = *prefix_state(k, key, dir, (uint16_t)(full >> 16));
    uint8_t hdr[8];
    proto_header(f, hdr);
    sip_absorb(&s, hdr, 1);
    sip_tag(&s, f->payload, f->len, out);
}

void auth_seal(auth_keys_t *k, const uint8_t key[SIP_KEY_SIZE], uint8_t dir, uint32_t full, proto_frame_t *f)
{
    f->seq = (uint16_t)full;
    auth_tag(k, key, dir, full, f, f->tag);
}

uint8_t auth_verify(auth_keys_t *k, const uint8_t key[SIP_KEY_SIZE], uint8_t dir, uint32_t full,
                    const proto_frame_t *f)
{
    uint8_t t[SIP_TAG_SIZE], diff = 0;
    auth_tag(k, key, dir, full, f, t);
    for (uint8_t i = 0; i < SIP_TAG_SIZE; i++)
        diff |= (uint8_t)(t[i] ^ f->tag[i]);
    return diff == 0;
}

void auth_board_nonce(const uint8_t key[SIP_KEY_SIZE], uint32_t boot_count, uint32_t session_count,
                      uint8_t out[AUTH_NONCE_SIZE])
{
    uint8_t m[16] = {'s', 's', 'l', 'f', 'r', '-', 'n', 'b'};
    proto_put_u32(m + 8, boot_count);
    proto_put_u32(m + 12, session_count);
    siphash24(key, m, sizeof m, out);
}
