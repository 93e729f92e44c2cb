/* Board side of the SSLFR protocol: see session.h. */
#include "session.h"
#include "msgs.h"

#include <string.h>

static void put_frame(session_t *s, uint8_t type, const uint8_t *payload, uint8_t len,
                      uint8_t response, uint16_t ref)
{
    proto_frame_t f;
    uint8_t wire[PROTO_MAX_FRAME];
    f.version = PROTO_VERSION;
    f.len = len;
    f.flags = response ? PROTO_FLAG_RESPONSE : 0;
    f.seq = s->tx_seq++;
    f.ref = response ? ref : 0;
    f.type = type;
    memcpy(f.payload, payload, len);
    uint8_t n = proto_encode(&f, wire);
    s->frames_out++;
    s->write(s->ctx, wire, n);
}

void session_init(session_t *s, uint8_t kind, session_handler_fn handler, session_write_fn write, void *ctx)
{
    memset(s, 0, sizeof(*s));
    proto_framer_init(&s->framer);
    proto_tracker_init(&s->host);
    s->kind = kind;
    s->handler = handler;
    s->write = write;
    s->ctx = ctx;
}

void session_boot(session_t *s)
{
    uint8_t p[2];
    put_frame(s, MSG_BOOT, p, msg_boot(p, s->kind), 0, 0);
}

uint8_t session_send(session_t *s, uint8_t type, const uint8_t *payload, uint8_t len)
{
    put_frame(s, type, payload, len, 0, 0);
    return (uint8_t)(PROTO_HEADER + len + PROTO_TRAILER);
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

static void on_frame(void *ctx, const proto_frame_t *f)
{
    session_t *s = (session_t *)ctx;
    proto_frame_t ans;
    if (f->version != PROTO_VERSION) {
        uint8_t p[2];
        s->version_errors++;
        put_frame(s, MSG_NACK, p, msg_nack(p, f->type, ERR_VERSION), 1, f->seq);
        return;
    }
    s->frames_in++;
    s->heard = 1;
    s->last_heard_ms = s->now_ms;
    s->watchdog_tripped = 0;
    uint8_t verdict = proto_tracker_accept(&s->host, f->seq);
    if (verdict == PROTO_SEQ_DUPLICATE && s->has_last_req && s->last_req_seq == f->seq
            && s->last_req_type == f->type) {
        s->requests_duplicate++;
        if (s->cached_valid)
            put_frame(s, s->cached_type, s->cached, s->cached_len, 1, f->seq);
        return;
    }
    if (verdict == PROTO_SEQ_STALE) {
        s->stale_run++;
        if (s->stale_run < 3 && f->type != MSG_PING && f->type != MSG_GET_INFO) {
            s->requests_stale++;
            return;
        }
        proto_tracker_restart(&s->host);
        proto_tracker_accept(&s->host, f->seq);
    }
    s->stale_run = 0;
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
        put_frame(s, ans.type, ans.payload, ans.len, 1, f->seq);
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
