/* Common requests of the SSLFR boards: see common.h. */
#include "common.h"

#include <string.h>

static uint8_t common_type(uint8_t type)
{
    return type == MSG_PING || type == MSG_GET_INFO || type == MSG_RESET
        || type == MSG_GET_CONFIG || type == MSG_SET_CONFIG;
}

uint8_t common_handle(const common_board_t *b, session_t *s, const proto_frame_t *req, proto_frame_t *ans)
{
    if (!common_type(req->type)) {
        /* a board request (the board checks its payload) or UNKNOWN_TYPE, whatever the
         * payload: a board answers BAD_PAYLOAD only for requests it implements */
        if (b->handle(req, ans))
            return 1;
        return session_nack(req, ans, ERR_UNKNOWN_TYPE);
    }
    if (req->len != (uint8_t)msg_request_size(req->type))
        return session_nack(req, ans, ERR_BAD_PAYLOAD);
    switch (req->type) {
    case MSG_PING:
        return session_ack(req, ans);
    case MSG_GET_INFO:
        ans->type = MSG_INFO;
        ans->len = msg_info(ans->payload, b->kind, b->fw_major, b->fw_minor, b->fw_patch,
                            b->config->board_id, b->name);
        return 1;
    case MSG_RESET:
        s->reset_pending = 1;        /* the firmware reboots after sending the ACK */
        return session_ack(req, ans);
    case MSG_GET_CONFIG:
        ans->type = MSG_CONFIG;
        config_pack(b->config, ans->payload);
        ans->len = CONFIG_SIZE;
        return 1;
    default: {   /* MSG_SET_CONFIG: stored, used from the next start (RESET) */
        board_config_t c;
        config_unpack(req->payload, &c);
        if (config_check(&c, b->kind) != 0)
            return session_nack(req, ans, ERR_OUT_OF_RANGE);
        if (b->busy())
            return session_nack(req, ans, ERR_BUSY);
        if (!b->store(&c))
            return session_nack(req, ans, ERR_INTERNAL);
        return session_ack(req, ans);
    }
    }
}

void config_image(const board_config_t *c, uint8_t *raw)
{
    config_pack(c, raw);
    proto_put_u16(raw + CONFIG_SIZE, proto_crc16(raw, CONFIG_SIZE, 0xFFFF));
}

uint8_t config_load(const uint8_t *raw, uint8_t kind, board_config_t *c)
{
    config_unpack(raw, c);
    if (proto_get_u16(raw + CONFIG_SIZE) != proto_crc16(raw, CONFIG_SIZE, 0xFFFF)
            || config_check(c, kind) != 0) {
        config_defaults(c, kind);
        return 0;
    }
    return 1;
}

void key_image(const uint8_t key[16], uint8_t *raw)
{
    memcpy(raw, key, 16);
    proto_put_u16(raw + 16, proto_crc16(key, 16, 0xFFFF));
}

uint8_t key_load(const uint8_t *raw, uint8_t key[16])
{
    if (proto_get_u16(raw + 16) != proto_crc16(raw, 16, 0xFFFF)) {
        memset(key, 0, 16);
        return 0;
    }
    memcpy(key, raw, 16);
    return 1;
}

uint32_t boot_count_next(uint32_t stored) { return stored == 0xFFFFFFFFu ? 1u : stored + 1u; }
