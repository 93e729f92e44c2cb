/* SSLFR board protocol v1 payloads: see msgs.h. */
#include "msgs.h"

#include <math.h>
#include <string.h>

int8_t msg_request_size(uint8_t type)
{
    switch (type) {
    case MSG_PING: return 4;
    case MSG_GET_INFO: case MSG_GET_STATUS: case MSG_RESET: case MSG_GET_CONFIG: case MSG_STOP: return 0;
    case MSG_SET_CONFIG: return CONFIG_SIZE;
    case MSG_HELLO: return 8;
    case MSG_PROVISION: return 16;
    case MSG_MOVE_TO: return 8;
    case MSG_HOME: return 9;
    case MSG_SET_ZERO: return 4;
    case MSG_SET_HOST_LOSS_STOW: return HL_SIZE;
    case MSG_SET_PULSE_INPUT: return 1;
    default: return -1;
    }
}

static uint8_t finite_f(float v) { return isfinite(v) ? 1 : 0; }

uint8_t msg_parse_move_to(const proto_frame_t *f, msg_move_to_t *m)
{
    if (f->len != 8)
        return ERR_BAD_PAYLOAD;
    m->steps = (int32_t)proto_get_u32(f->payload);
    m->speed = proto_get_f32(f->payload + 4);
    return finite_f(m->speed) ? 0 : ERR_BAD_PAYLOAD;
}

uint8_t msg_parse_home(const proto_frame_t *f, msg_home_t *m)
{
    if (f->len != 9)
        return ERR_BAD_PAYLOAD;
    m->sw = f->payload[0];
    m->speed = proto_get_f32(f->payload + 1);
    m->position = (int32_t)proto_get_u32(f->payload + 5);
    return finite_f(m->speed) ? 0 : ERR_BAD_PAYLOAD;
}

uint8_t msg_parse_i32(const proto_frame_t *f, int32_t *v)
{
    if (f->len != 4)
        return ERR_BAD_PAYLOAD;
    *v = (int32_t)proto_get_u32(f->payload);
    return 0;
}

uint8_t msg_parse_host_loss(const proto_frame_t *f, msg_host_loss_t *m)
{
    if (f->len != HL_SIZE)
        return ERR_BAD_PAYLOAD;
    m->mode = f->payload[0];
    m->sw = f->payload[1];
    m->steps = (int32_t)proto_get_u32(f->payload + 2);
    m->speed = proto_get_f32(f->payload + 6);
    m->delay_ms = proto_get_u32(f->payload + 10);
    return finite_f(m->speed) ? 0 : ERR_BAD_PAYLOAD;
}

uint8_t msg_ack(uint8_t *p, uint8_t request_type) { p[0] = request_type; return 1; }
uint8_t msg_nack(uint8_t *p, uint8_t request_type, uint8_t code) { p[0] = request_type; p[1] = code; return 2; }
uint8_t msg_boot(uint8_t *p, uint8_t kind) { p[0] = kind; p[1] = PROTO_VERSION; return 2; }
uint8_t msg_hello_reply(uint8_t *p, const uint8_t nonce[8], uint32_t boot_count)
{
    memcpy(p, nonce, 8);
    proto_put_u32(p + 8, boot_count);
    return 12;
}

uint8_t msg_info(uint8_t *p, uint8_t kind, uint8_t major, uint8_t minor, uint8_t patch,
                 uint32_t board_id, const char *name)
{
    p[0] = kind; p[1] = major; p[2] = minor; p[3] = patch; p[4] = PROTO_VERSION;
    proto_put_u32(p + 5, board_id);
    memset(p + 9, 0, NAME_SIZE);
    for (uint8_t i = 0; i < NAME_SIZE && name[i]; i++)
        p[9 + i] = (uint8_t)name[i];
    return INFO_SIZE;
}

uint8_t msg_status(uint8_t *p, const msg_status_t *s)
{
    proto_put_u32(p, (uint32_t)s->position);
    proto_put_u32(p + 4, (uint32_t)s->target);
    proto_put_f32(p + 8, s->speed);
    p[12] = s->flags;
    p[13] = s->limit_bits;
    proto_put_u16(p + 14, s->fault_bits);
    proto_put_f32(p + 16, s->sensor_angle);
    proto_put_u32(p + 20, s->uptime_ms);
    return STATUS_SIZE;
}

uint8_t msg_thermocouple(uint8_t *p, uint32_t board_ms, uint16_t inlet, uint16_t outlet)
{
    proto_put_u32(p, board_ms);
    proto_put_u16(p + 4, inlet);
    proto_put_u16(p + 6, outlet);
    return 8;
}

uint8_t msg_switches(uint8_t *p, uint32_t board_ms, uint8_t bits)
{
    proto_put_u32(p, board_ms);
    p[4] = bits & 0x1F;
    p[5] = 0;
    return 6;
}

uint8_t msg_als(uint8_t *p, uint32_t board_ms, uint16_t count, uint8_t gain_code, uint8_t it_code)
{
    proto_put_u32(p, board_ms);
    proto_put_u16(p + 4, count);
    p[6] = gain_code;
    p[7] = it_code;
    return 8;
}

uint8_t msg_pulses(uint8_t *p, uint32_t board_ms, uint32_t count, uint8_t pin)
{
    proto_put_u32(p, board_ms);
    proto_put_u32(p + 4, count);
    p[8] = pin;
    return 9;
}

void config_defaults(board_config_t *c, uint8_t kind)
{
    memset(c, 0, sizeof(*c));
    c->layout = CONFIG_LAYOUT;
    c->kind = kind;
    c->board_id = 0;
    c->baud = 115200;
    c->axis = 0xFF;
    if (kind == KIND_AXIS_STEPPER) {
        c->axis = 0;
        c->max_speed = 3000.0f;      /* seed 000: 0.006 deg/step -> 18 deg/s */
        c->accel = 6000.0f;
        c->min_steps = -(1L << 30);
        c->max_steps = (1L << 30);
    }
}

void config_pack(const board_config_t *c, uint8_t *p)
{
    p[0] = c->layout;
    p[1] = c->kind;
    proto_put_u32(p + 2, c->board_id);
    proto_put_u32(p + 6, c->baud);
    p[10] = c->axis;
    p[11] = c->flags;
    proto_put_f32(p + 12, c->max_speed);
    proto_put_f32(p + 16, c->accel);
    proto_put_u32(p + 20, (uint32_t)c->min_steps);
    proto_put_u32(p + 24, (uint32_t)c->max_steps);
    proto_put_u16(p + 28, c->sensor_zero);
}

void config_unpack(const uint8_t *p, board_config_t *c)
{
    c->layout = p[0];
    c->kind = p[1];
    c->board_id = proto_get_u32(p + 2);
    c->baud = proto_get_u32(p + 6);
    c->axis = p[10];
    c->flags = p[11];
    c->max_speed = proto_get_f32(p + 12);
    c->accel = proto_get_f32(p + 16);
    c->min_steps = (int32_t)proto_get_u32(p + 20);
    c->max_steps = (int32_t)proto_get_u32(p + 24);
    c->sensor_zero = proto_get_u16(p + 28);
}

static uint8_t baud_ok(uint32_t b)
{
    return b == 9600 || b == 19200 || b == 38400 || b == 57600 || b == 115200;
}

uint8_t config_check(const board_config_t *c, uint8_t kind)
{
    if (c->layout != CONFIG_LAYOUT || c->kind != kind || !baud_ok(c->baud))
        return ERR_OUT_OF_RANGE;
    if (kind != KIND_AXIS_STEPPER)
        return 0;
    if (c->axis > 2 || (c->flags & ~0x0F))
        return ERR_OUT_OF_RANGE;
    if (!(c->max_speed >= 1.0f && c->max_speed <= AXIS_MAX_STEP_RATE))   /* also NaN */
        return ERR_OUT_OF_RANGE;
    if (!(c->accel >= 1.0f && c->accel <= 1.0e7f))
        return ERR_OUT_OF_RANGE;
    if (c->min_steps >= c->max_steps)
        return ERR_OUT_OF_RANGE;
    if ((c->flags & CFG_HAS_SENSOR) && c->sensor_zero > 0x3FFF)
        return ERR_OUT_OF_RANGE;
    return 0;
}
