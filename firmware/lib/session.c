/* Board side of the SSLFR protocol v2: see session.h. */
#include "session.h"
#include "msgs.h"

#include <string.h>

static const uint8_t NULL_KEY[SIP_KEY_SIZE] = {0};

/* Send a frame tagged in session sk (NULL: the null session). */
static void put_frame(session_t *s, session_keys_t *sk, uint8_t type, const uint8_t *payload, uint8_t len,
                      uint8_t response, uint16_t ref)
{
    proto_frame_t f;
    uint8_t wire[PROTO_MAX_FRAME];
    f.version = PROTO_VERSION;
    f.len = len;
    f.flags = response ? PROTO_FLAG_RESPONSE : 0;
    f.ref = response ? ref : 0;
    f.type = type;
    memcpy(f.payload, payload, len);
    if (sk)
        auth_seal(&sk->keys, s->key, AUTH_B2H, sk->tx++, &f);
    else
        auth_seal(&s->null_keys, s->key, AUTH_B2H, s->null_tx++, &f);
    uint8_t n = proto_encode(&f, wire);
    s->frames_out++;
    s->write(s->ctx, wire, n);
}

static void nack_in(session_t *s, session_keys_t *sk, const proto_frame_t *req, uint8_t code)
{
    uint8_t p[2];
    put_frame(s, sk, MSG_NACK, p, msg_nack(p, req->type, code), 1, req->seq);
}

/* NACK(code) to req in session sk, at most once per SESSION_REFUSAL_MS. */
static void refuse(session_t *s, const proto_frame_t *req, uint8_t code, session_keys_t *sk)
{
    if (s->refused && (uint32_t)(s->now_ms - s->last_refusal_ms) < SESSION_REFUSAL_MS)
        return;
    s->refused = 1;
    s->last_refusal_ms = s->now_ms;
    nack_in(s, sk, req, code);
}

static session_keys_t *current(session_t *s) { return s->cur.active ? &s->cur : 0; }

void session_init(session_t *s, uint8_t kind, const uint8_t *key, uint32_t boot_count,
                  session_handler_fn handler, session_write_fn write, session_store_key_fn store_key,
                  void *ctx)
{
    memset(s, 0, sizeof(*s));
    proto_framer_init(&s->framer);
    memcpy(s->key, key ? key : NULL_KEY, SIP_KEY_SIZE);
    auth_keys_init(&s->null_keys, s->key, 0, 0);
    s->kind = kind;
    s->boot_count = boot_count;
    s->handler = handler;
    s->write = write;
    s->store_key = store_key;
    s->ctx = ctx;
}

void session_boot(session_t *s)
{
    uint8_t p[2];
    put_frame(s, 0, MSG_BOOT, p, msg_boot(p, s->kind), 0, 0);
}

void session_open_provisioning(session_t *s, uint32_t now_ms)
{
    s->provision_open = 1;
    s->provision_from_ms = now_ms;
}

uint8_t session_send(session_t *s, uint8_t type, const uint8_t *payload, uint8_t len)
{
    if (!s->cur.active)
        return 0;
    put_frame(s, &s->cur, type, payload, len, 0, 0);
    return (uint8_t)(PROTO_HEADER + len + PROTO_TAG_SIZE + PROTO_CRC_SIZE);
}

uint8_t session_ack(const proto_frame_t *req, proto_frame_t *ans)
{
    ans->type = MSG_ACK;
    ans->len = msg_ack(ans->payload, req->type);
    return 1;
}

uint8_t session_nack(const proto_frame_t *req, proto_frame_t *ans, uint8_t code)
{
    ans->type = MSG_NACK;
    ans->len = msg_nack(ans->payload, req->type, code);
    return 1;
}

static void hello_reply(session_t *s)
{
    uint8_t p[12];
    s->pend.tx = 0;
    put_frame(s, &s->pend, MSG_HELLO_REPLY, p, msg_hello_reply(p, s->pend.keys.nb, s->boot_count), 1,
              s->hello_ref);
}

/* HELLO (null session): open a pending session and answer HELLO_REPLY in it. */
static void on_hello(session_t *s, const proto_frame_t *f)
{
    if (!auth_verify(&s->null_keys, s->key, AUTH_H2B, f->seq, f)) {
        s->auth_failures++;
        refuse(s, f, ERR_AUTH, current(s));
        return;
    }
    if (f->len != 8) {
        nack_in(s, 0, f, ERR_BAD_PAYLOAD);
        return;
    }
    if (s->pend.active && memcmp(s->pend.keys.nh, f->payload, AUTH_NONCE_SIZE) == 0) {
        hello_reply(s);                   /* a retried HELLO: the same reply again */
        return;
    }
    uint8_t nb[AUTH_NONCE_SIZE];
    s->session_count++;
    auth_board_nonce(s->key, s->boot_count, s->session_count, nb);
    auth_keys_init(&s->pend.keys, s->key, f->payload, nb);
    proto_tracker_init(&s->pend.rx);
    s->pend.active = 1;
    s->hello_ref = f->seq;
    hello_reply(s);
}

/* PROVISION (tagged under the null key): a new installation key, only inside the
 * provisioning window; answered ACK in the null session of the new key. */
static void on_provision(session_t *s, const proto_frame_t *f)
{
    auth_keys_t nk;
    auth_keys_init(&nk, NULL_KEY, 0, 0);
    if (!auth_verify(&nk, NULL_KEY, AUTH_H2B, f->seq, f)) {
        s->auth_failures++;
        refuse(s, f, ERR_AUTH, current(s));
        return;
    }
    if (!s->provision_open || (uint32_t)(s->now_ms - s->provision_from_ms) >= SESSION_PROVISION_MS) {
        s->provision_refused++;
        refuse(s, f, ERR_LOCKED, 0);
        return;
    }
    if (f->len != SIP_KEY_SIZE) {
        nack_in(s, 0, f, ERR_BAD_PAYLOAD);
        return;
    }
    if (!s->store_key || !s->store_key(f->payload)) {
        nack_in(s, 0, f, ERR_INTERNAL);
        return;
    }
    memcpy(s->key, f->payload, SIP_KEY_SIZE);
    auth_keys_init(&s->null_keys, s->key, 0, 0);
    s->cur.active = s->pend.active = 0;
    s->has_last_req = 0;
    uint8_t p[1];
    put_frame(s, 0, MSG_ACK, p, msg_ack(p, f->type), 1, f->seq);
}

static void on_frame(void *ctx, const proto_frame_t *f)
{
    session_t *s = (session_t *)ctx;
    proto_frame_t ans;
    if (f->version != PROTO_VERSION) {
        s->version_errors++;
        refuse(s, f, ERR_VERSION, 0);
        return;
    }
    if (f->type == MSG_HELLO) {
        on_hello(s, f);
        return;
    }
    if (f->type == MSG_PROVISION) {
        on_provision(s, f);
        return;
    }
    session_keys_t *sk = 0;
    if (s->cur.active && auth_verify(&s->cur.keys, s->key, AUTH_H2B, proto_tracker_expand(&s->cur.rx, f->seq), f)) {
        sk = &s->cur;
    } else if (s->pend.active && auth_verify(&s->pend.keys, s->key, AUTH_H2B, f->seq, f)) {
        s->cur = s->pend;                 /* the host uses the new session: the old one ends */
        s->pend.active = 0;
        s->has_last_req = 0;
        s->sessions++;
        sk = &s->cur;
    }
    if (!sk) {
        if (!s->cur.active && !s->pend.active) {
            s->no_session++;
            refuse(s, f, ERR_NO_SESSION, 0);
        } else {
            s->auth_failures++;
            refuse(s, f, ERR_AUTH, current(s));
        }
        return;
    }
    uint8_t verdict = proto_tracker_accept(&sk->rx, f->seq);
    if (verdict == PROTO_SEQ_DUPLICATE && s->has_last_req && s->last_req_seq == f->seq
            && s->last_req_type == f->type) {
        s->requests_duplicate++;
        if (s->cached_valid)
            put_frame(s, sk, s->cached_type, s->cached, s->cached_len, 1, f->seq);
        return;
    }
    if (verdict != PROTO_SEQ_NEW) {
        s->requests_stale++;
        refuse(s, f, ERR_REPLAY, sk);
        return;
    }
    s->frames_in++;
    s->heard = 1;
    s->last_heard_ms = s->now_ms;
    s->watchdog_tripped = 0;
    uint8_t has_answer = s->handler(s, f, &ans);
    s->has_last_req = 1;
    s->last_req_seq = f->seq;
    s->last_req_type = f->type;
    s->cached_valid = has_answer && ans.len <= SESSION_CACHE_MAX;
    if (has_answer) {
        if (s->cached_valid) {
            s->cached_type = ans.type;
            s->cached_len = ans.len;
            memcpy(s->cached, ans.payload, ans.len);
        }
        put_frame(s, sk, ans.type, ans.payload, ans.len, 1, f->seq);
    }
}

void session_rx(session_t *s, const uint8_t *data, uint16_t n, uint32_t now_ms)
{
    s->now_ms = now_ms;
    while (n--)
        proto_framer_feed(&s->framer, *data++, on_frame, s);
}

uint8_t session_watchdog(session_t *s, uint32_t now_ms)
{
    s->now_ms = now_ms;
    if (s->watchdog_tripped || !s->heard || (uint32_t)(now_ms - s->last_heard_ms) <= SESSION_WATCHDOG_MS)
        return 0;
    s->watchdog_tripped = 1;
    s->watchdog_trips++;
    return 1;
}
