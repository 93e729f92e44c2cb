/* The firmware's protocol code (lib/) as a host shared library, for the pytest suite
 * (ctypes, sslfr_drivers/fw/native.py): the same CRC, encoder, deframer, sequence tracker,
 * payload codecs and board session as the ATmega328P runs, checked frame for frame
 * against the Python codec. Only thin adapters here: no protocol logic of its own. */
#include <stdlib.h>
#include <string.h>

#include "common.h"

uint16_t hl_crc16(const uint8_t *d, uint16_t n, uint16_t crc) { return proto_crc16(d, n, crc); }

/* tag: 8 bytes (used by version-2 frames) */
uint8_t hl_encode(uint8_t version, uint8_t flags, uint16_t seq, uint16_t ref, uint8_t type,
                  const uint8_t *payload, uint8_t len, const uint8_t *tag, uint8_t *out)
{
    proto_frame_t f = {.version = version, .len = len, .flags = flags, .seq = seq, .ref = ref, .type = type};
    if (len > PROTO_MAX_BODY)
        return 0;
    memcpy(f.payload, payload, len);
    memcpy(f.tag, tag, PROTO_TAG_SIZE);
    return proto_encode(&f, out);
}

/* hdr = version, len, flags, seq, ref, type; tag: 8 bytes (version 2) */
uint8_t hl_decode(const uint8_t *data, uint16_t n, uint32_t *hdr, uint8_t *payload, uint8_t *tag)
{
    proto_frame_t f;
    uint8_t r = proto_decode(data, n, &f);
    if (r == PROTO_DECODE_OK) {
        hdr[0] = f.version; hdr[1] = f.len; hdr[2] = f.flags; hdr[3] = f.seq; hdr[4] = f.ref; hdr[5] = f.type;
        memcpy(payload, f.payload, f.len);
        memcpy(tag, f.tag, proto_tag_size(f.version));
    }
    return r;
}

/* ---- authentication (lib/siphash.c, lib/auth.c) */
void hl_siphash(const uint8_t *key, const uint8_t *data, uint8_t n, uint8_t *out) { siphash24(key, data, n, out); }

/* the tag of a frame in the session (nh, nb; NULL: the null session) for frame number full */
void hl_auth_tag(const uint8_t *key, const uint8_t *nh, const uint8_t *nb, uint8_t dir, uint32_t full,
                 uint8_t version, uint8_t flags, uint16_t seq, uint16_t ref, uint8_t type,
                 const uint8_t *payload, uint8_t len, uint8_t *out)
{
    auth_keys_t k;
    proto_frame_t f = {.version = version, .len = len, .flags = flags, .seq = seq, .ref = ref, .type = type};
    memcpy(f.payload, payload, len);
    auth_keys_init(&k, key, nh, nb);
    auth_tag(&k, key, dir, full, &f, out);
}

void hl_board_nonce(const uint8_t *key, uint32_t boot_count, uint32_t session_count, uint8_t *out)
{
    auth_board_nonce(key, boot_count, session_count, out);
}

void hl_key_image(const uint8_t *key, uint8_t *raw) { key_image(key, raw); }
uint8_t hl_key_load(const uint8_t *raw, uint8_t *key) { return key_load(raw, key); }
uint32_t hl_boot_count_next(uint32_t stored) { return boot_count_next(stored); }

/* ---- deframer: delivered frames are written re-encoded (their bytes as received) */
typedef struct { uint8_t *out; size_t cap, n; } sink_t;

static void sink_frame(void *ctx, const proto_frame_t *f)
{
    sink_t *s = (sink_t *)ctx;
    uint8_t wire[PROTO_MAX_FRAME];
    uint8_t k = proto_encode(f, wire);
    if (s->n + k <= s->cap)
        memcpy(s->out + s->n, wire, k);
    s->n += k;
}

size_t hl_framer_size(void) { return sizeof(proto_framer_t); }
void hl_framer_init(proto_framer_t *fr) { proto_framer_init(fr); }

size_t hl_framer_feed(proto_framer_t *fr, const uint8_t *data, size_t n, uint8_t *out, size_t cap)
{
    sink_t s = {out, cap, 0};
    for (size_t i = 0; i < n; i++)
        proto_framer_feed(fr, data[i], sink_frame, &s);
    return s.n;
}

/* frames_ok, crc_errors, length_errors, bytes_discarded, foreign_version, pending */
void hl_framer_counters(const proto_framer_t *fr, uint32_t *c)
{
    c[0] = fr->frames_ok; c[1] = fr->crc_errors; c[2] = fr->length_errors;
    c[3] = fr->bytes_discarded; c[4] = fr->foreign_version; c[5] = fr->n;
}

/* ---- sequence tracker */
size_t hl_tracker_size(void) { return sizeof(proto_seq_tracker_t); }
void hl_tracker_init(proto_seq_tracker_t *t) { proto_tracker_init(t); }
void hl_tracker_restart(proto_seq_tracker_t *t) { proto_tracker_restart(t); }
uint8_t hl_tracker_accept(proto_seq_tracker_t *t, uint16_t seq) { return proto_tracker_accept(t, seq); }
void hl_tracker_counters(const proto_seq_tracker_t *t, uint32_t *c)
{
    c[0] = t->received; c[1] = t->lost; c[2] = t->duplicates; c[3] = t->stale;
}

/* ---- payload codecs */
int8_t hl_request_size(uint8_t type) { return msg_request_size(type); }

static void frame_of(proto_frame_t *f, uint8_t type, const uint8_t *p, uint8_t len)
{
    memset(f, 0, sizeof *f);
    f->type = type;
    f->len = len;
    memcpy(f->payload, p, len);
}

uint8_t hl_parse_move_to(const uint8_t *p, uint8_t len, int32_t *steps, float *speed)
{
    proto_frame_t f;
    msg_move_to_t m;
    frame_of(&f, MSG_MOVE_TO, p, len);
    uint8_t r = msg_parse_move_to(&f, &m);
    *steps = m.steps;
    *speed = m.speed;
    return r;
}

uint8_t hl_parse_home(const uint8_t *p, uint8_t len, uint8_t *sw, float *speed, int32_t *pos)
{
    proto_frame_t f;
    msg_home_t m;
    frame_of(&f, MSG_HOME, p, len);
    uint8_t r = msg_parse_home(&f, &m);
    *sw = m.sw; *speed = m.speed; *pos = m.position;
    return r;
}

uint8_t hl_parse_host_loss(const uint8_t *p, uint8_t len, uint8_t *mode, uint8_t *sw, int32_t *steps,
                           float *speed, uint32_t *delay_ms)
{
    proto_frame_t f;
    msg_host_loss_t m;
    memset(&m, 0, sizeof m);
    frame_of(&f, MSG_SET_HOST_LOSS_STOW, p, len);
    uint8_t r = msg_parse_host_loss(&f, &m);
    *mode = m.mode; *sw = m.sw; *steps = m.steps; *speed = m.speed; *delay_ms = m.delay_ms;
    return r;
}

uint8_t hl_msg_status(uint8_t *out, int32_t position, int32_t target, float speed, uint8_t flags,
                      uint8_t limit_bits, uint16_t fault_bits, float sensor_angle, uint32_t uptime)
{
    msg_status_t s = {position, target, speed, flags, limit_bits, fault_bits, sensor_angle, uptime};
    return msg_status(out, &s);
}

uint8_t hl_msg_info(uint8_t *out, uint8_t kind, uint8_t ma, uint8_t mi, uint8_t pa, uint32_t id, const char *name)
{
    return msg_info(out, kind, ma, mi, pa, id, name);
}

uint8_t hl_msg_samples(uint8_t *out, uint8_t which, uint32_t ms, uint16_t a, uint16_t b, uint8_t c, uint8_t d)
{
    switch (which) {
    case 0: return msg_thermocouple(out, ms, a, b);
    case 1: return msg_switches(out, ms, c);
    case 3: return msg_pulses(out, ms, ((uint32_t)b << 16) | a, c);
    default: return msg_als(out, ms, a, c, d);
    }
}

uint8_t hl_config_check(const uint8_t *record, uint8_t kind)
{
    board_config_t c;
    config_unpack(record, &c);
    return config_check(&c, kind);
}

void hl_config_defaults(uint8_t kind, uint8_t *record)
{
    board_config_t c;
    config_defaults(&c, kind);
    config_pack(&c, record);
}

uint8_t hl_config_load(const uint8_t *image, uint8_t kind, uint8_t *record)
{
    board_config_t c;
    uint8_t ok = config_load(image, kind, &c);
    config_pack(&c, record);
    return ok;
}

void hl_config_image(const uint8_t *record, uint8_t *image)
{
    board_config_t c;
    config_unpack(record, &c);
    config_image(&c, image);
}

/* ---- a board speaking the protocol with the common requests only (the base board of
 * the simulators, sim/base.py SimBoard), for session-level comparison */
typedef struct {
    session_t s;
    board_config_t cfg;
    common_board_t common;
    uint8_t eeprom[CONFIG_EEPROM_SIZE];
    uint8_t key_raw[KEY_EEPROM_SIZE];
    uint32_t boot_count;
    sink_t out;
    char name[NAME_SIZE + 1];
} hl_board_t;

static hl_board_t *g_current;

static void board_write(void *ctx, const uint8_t *d, uint8_t n)
{
    hl_board_t *b = (hl_board_t *)ctx;
    if (b->out.n + n <= b->out.cap)
        memcpy(b->out.out + b->out.n, d, n);
    b->out.n += n;
}

static uint8_t no_board_requests(const proto_frame_t *req, proto_frame_t *ans) { (void)req; (void)ans; return 0; }
static uint8_t never_busy(void) { return 0; }
static uint8_t store_ram(const board_config_t *c) { config_image(c, g_current->eeprom); return 1; }
static uint8_t store_key_ram(const uint8_t key[16]) { key_image(key, g_current->key_raw); return 1; }

static uint8_t board_handler(session_t *s, const proto_frame_t *req, proto_frame_t *ans)
{
    return common_handle(&g_current->common, s, req, ans);
}

static void board_start(hl_board_t *b)
{
    uint8_t key[16];
    config_load(b->eeprom, b->common.kind, &b->cfg);
    key_load(b->key_raw, key);
    b->boot_count = boot_count_next(b->boot_count);
    session_init(&b->s, b->common.kind, key, b->boot_count, board_handler, board_write, store_key_ram, b);
    session_boot(&b->s);
}

/* key: 16 bytes (NULL: unprovisioned); boot_count: the EEPROM counter before this start */
hl_board_t *hl_board_new(uint8_t kind, uint32_t board_id, const char *name, const uint8_t *key,
                         uint32_t boot_count, uint8_t *out, size_t cap)
{
    hl_board_t *b = calloc(1, sizeof *b);
    board_config_t c;
    config_defaults(&c, kind);
    c.board_id = board_id;
    config_image(&c, b->eeprom);
    memset(b->key_raw, 0xFF, sizeof b->key_raw);
    if (key)
        key_image(key, b->key_raw);
    b->boot_count = boot_count;
    strncpy(b->name, name, NAME_SIZE);
    b->common = (common_board_t){kind, 1, 0, 0, b->name, &b->cfg, no_board_requests, never_busy, store_ram};
    b->out = (sink_t){out, cap, 0};
    g_current = b;
    board_start(b);
    return b;
}

/* bytes from the host at now_ms; returns the bytes the board sent (RESET: reboot + BOOT) */
size_t hl_board_rx(hl_board_t *b, const uint8_t *data, size_t n, uint32_t now_ms, uint8_t *out, size_t cap)
{
    g_current = b;
    b->out = (sink_t){out, cap, 0};
    for (size_t i = 0; i < n; i++) {
        session_rx(&b->s, data + i, 1, now_ms);
        if (b->s.reset_pending)
            board_start(b);
    }
    return b->out.n;
}

uint8_t hl_board_watchdog(hl_board_t *b, uint32_t now_ms) { return session_watchdog(&b->s, now_ms); }
void hl_board_open_provisioning(hl_board_t *b, uint32_t now_ms) { session_open_provisioning(&b->s, now_ms); }

/* frames_in, frames_out, requests_stale, requests_duplicate, watchdog_trips, version_errors,
 * auth_failures, no_session, sessions, boot_count, provision_refused */
void hl_board_counters(const hl_board_t *b, uint32_t *c)
{
    c[0] = b->s.frames_in; c[1] = b->s.frames_out; c[2] = b->s.requests_stale;
    c[3] = b->s.requests_duplicate; c[4] = b->s.watchdog_trips; c[5] = b->s.version_errors;
    c[6] = b->s.auth_failures; c[7] = b->s.no_session; c[8] = b->s.sessions; c[9] = b->s.boot_count;
    c[10] = b->s.provision_refused;
}

void hl_board_free(hl_board_t *b) { free(b); }
