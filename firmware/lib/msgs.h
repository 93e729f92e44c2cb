/* SSLFR board protocol v2: message codes, error codes and payload layouts
 * (docs/protocol.md "Message registry"; Python: messages.py, messages_sensors.py).
 * Plain C99, shared by the firmware and the host test library. */
#ifndef SSLFR_MSGS_H
#define SSLFR_MSGS_H

#include <stdint.h>
#include "proto.h"

#ifdef __cplusplus
extern "C" {
#endif

/* host -> board */
#define MSG_PING 0x01        /* u32 host_ms -> ACK */
#define MSG_GET_INFO 0x02    /* -> INFO */
#define MSG_GET_STATUS 0x03  /* -> STATUS (sensor boards: NACK UNKNOWN_TYPE) */
#define MSG_RESET 0x04       /* -> ACK, then reboot + BOOT */
#define MSG_GET_CONFIG 0x05  /* -> CONFIG */
#define MSG_SET_CONFIG 0x06  /* config record (CONFIG_SIZE bytes) -> ACK (stored; used after RESET) */
#define MSG_HELLO 0x07       /* 8-byte host nonce, null session -> HELLO_REPLY in the new session */
#define MSG_PROVISION 0x08   /* 16-byte installation key, under the null key; only in the provisioning
                              * window after an external reset (USB adapter's DTR) -> ACK under the new key */
#define MSG_MOVE_TO 0x10     /* i32 steps, f32 speed [steps/s] > 0 */
#define MSG_STOP 0x11
#define MSG_HOME 0x12        /* u8 switch, f32 speed [steps/s] (sign = direction), i32 position */
#define MSG_SET_ZERO 0x13    /* i32 position */
#define MSG_SET_HOST_LOSS_STOW 0x14  /* u8 mode, u8 switch, i32 steps, f32 speed, u32 delay_ms -> ACK (EEPROM) */
#define MSG_SET_PULSE_INPUT 0x40     /* u8 pin (0xFF off) -> ACK; sensor boards (absorber) */
/* board -> host */
#define MSG_ACK 0x80         /* u8 request type */
#define MSG_NACK 0x81        /* u8 request type, u8 error code */
#define MSG_INFO 0x82
#define MSG_STATUS 0x83
#define MSG_BOOT 0x84        /* u8 board kind, u8 protocol */
#define MSG_CONFIG 0x85      /* config record */
#define MSG_HELLO_REPLY 0x86 /* 8-byte board nonce, u32 boot count */
#define MSG_NMEA_CHUNK 0xC0
#define MSG_THERMOCOUPLE_SAMPLE 0xC1
#define MSG_SWITCH_SAMPLE 0xC2
#define MSG_ALS_SAMPLE 0xC3
#define MSG_PULSE_SAMPLE 0xC4        /* u32 board_ms, u32 count, u8 pin */

/* NACK error codes */
#define ERR_UNKNOWN_TYPE 1
#define ERR_BAD_PAYLOAD 2
#define ERR_OUT_OF_RANGE 3
#define ERR_NOT_HOMED 4
#define ERR_FAULT_ACTIVE 5
#define ERR_BUSY 6
#define ERR_LIMIT_ACTIVE 7
#define ERR_VERSION 8
#define ERR_INTERNAL 9
#define ERR_AUTH 10          /* tag does not verify (forged, other key, old session) */
#define ERR_REPLAY 11        /* authenticated but stale in the session */
#define ERR_NO_SESSION 12    /* no session (the board rebooted): send HELLO */
#define ERR_LOCKED 13        /* PROVISION outside the provisioning window */

/* board kinds (INFO, BOOT) */
#define KIND_AXIS_STEPPER 0x01
#define KIND_AXIS_ACTUATOR 0x02
#define KIND_GPS 0x10
#define KIND_ABSORBER 0x11
#define KIND_IRRADIANCE 0x12

/* STATUS flags, limit bits, fault bits */
#define ST_MOVING 0x01
#define ST_HOMED 0x02
#define ST_HOMING 0x04
#define ST_HAS_SENSOR 0x08
#define ST_HOST_LOSS_STOWING 0x10   /* driving to the host-loss stow by itself */
#define LIM_LOW 0x01
#define LIM_HIGH 0x02
#define LIM_SLEEP 0x04
#define FAULT_WATCHDOG 0x0001
#define FAULT_LIMIT 0x0002
#define FAULT_STALL 0x0004
#define FAULT_SENSOR 0x0008
#define FAULT_DRIVER 0x0010
#define FAULT_RESET 0x0020
#define FAULT_HOST_LOSS 0x0040      /* stowed by itself after host loss (cleared by MOVE_TO/HOME) */

#define INFO_SIZE 25
#define STATUS_SIZE 24
#define NAME_SIZE 16

/* ---- request payloads (validated: BAD_PAYLOAD on a wrong size or a non-finite float,
 * exactly where messages.decode raises PayloadError) */
typedef struct { int32_t steps; float speed; } msg_move_to_t;
typedef struct { uint8_t sw; float speed; int32_t position; } msg_home_t;
/* host-loss stow (docs/protocol.md): mode HL_*, switch index, target [steps], speed
 * [steps/s] (sign = direction for HL_SWITCH), delay after the watchdog stop [ms] */
typedef struct { uint8_t mode, sw; int32_t steps; float speed; uint32_t delay_ms; } msg_host_loss_t;
#define HL_OFF 0
#define HL_POSITION 1
#define HL_SWITCH 2
#define HL_SIZE 14
#define HL_MAX_DELAY_MS 86400000UL
#define PULSE_PIN_OFF 0xFF

/* Expected payload size of a request type this protocol defines, -1 if the type is not
 * a v1 request (-2: variable). */
int8_t msg_request_size(uint8_t type);
/* 0 = ok, else an error code (ERR_BAD_PAYLOAD) */
uint8_t msg_parse_move_to(const proto_frame_t *f, msg_move_to_t *m);
uint8_t msg_parse_home(const proto_frame_t *f, msg_home_t *m);
uint8_t msg_parse_i32(const proto_frame_t *f, int32_t *v);
uint8_t msg_parse_host_loss(const proto_frame_t *f, msg_host_loss_t *m);

/* ---- answer payloads: fill payload + len of an outgoing frame, return len */
uint8_t msg_ack(uint8_t *p, uint8_t request_type);
uint8_t msg_nack(uint8_t *p, uint8_t request_type, uint8_t code);
uint8_t msg_boot(uint8_t *p, uint8_t kind);
uint8_t msg_hello_reply(uint8_t *p, const uint8_t nonce[8], uint32_t boot_count);
uint8_t msg_info(uint8_t *p, uint8_t kind, uint8_t major, uint8_t minor, uint8_t patch,
                 uint32_t board_id, const char *name);
typedef struct {
    int32_t position, target;
    float speed;
    uint8_t flags, limit_bits;
    uint16_t fault_bits;
    float sensor_angle;
    uint32_t uptime_ms;
} msg_status_t;
uint8_t msg_status(uint8_t *p, const msg_status_t *s);
uint8_t msg_thermocouple(uint8_t *p, uint32_t board_ms, uint16_t inlet, uint16_t outlet);
uint8_t msg_switches(uint8_t *p, uint32_t board_ms, uint8_t bits);
uint8_t msg_als(uint8_t *p, uint32_t board_ms, uint16_t count, uint8_t gain_code, uint8_t it_code);
uint8_t msg_pulses(uint8_t *p, uint32_t board_ms, uint32_t count, uint8_t pin);

/* ---- the board configuration record (EEPROM address 0, GET_CONFIG / SET_CONFIG
 * payload; docs/firmware.md "EEPROM configuration"). Little-endian, packed:
 *   0  u8  layout (CONFIG_LAYOUT)      1  u8  board kind
 *   2  u32 board id                    6  u32 UART baud rate [bit/s]
 *   10 u8  axis (0 mirrors, 1 mobile structure, 2 secondary reflector; 0xFF none)
 *   11 u8  flags (CFG_*)
 *   12 f32 max speed [steps/s]         16 f32 acceleration [steps/s^2]
 *   20 i32 lowest MOVE_TO target [steps]   24 i32 highest MOVE_TO target [steps]
 *   28 u16 position sensor raw count at joint angle 0
 *   30 u16 CRC-16 of bytes 0..29 (in EEPROM only; SET_CONFIG carries bytes 0..29) */
#define CONFIG_LAYOUT 1
#define CONFIG_SIZE 30
#define CONFIG_EEPROM_SIZE 32
#define CFG_INVERT_DIR 0x01        /* DIR pin low for increasing steps */
#define CFG_SWITCH_NC 0x02         /* normally-closed switches: an open contact (pin high) reads closed */
#define CFG_HAS_SENSOR 0x04        /* AS5048A absolute encoder on the joint */
#define CFG_SENSOR_INVERT 0x08     /* encoder counts decrease with the joint angle */
#define AXIS_MAX_STEP_RATE 25000.0f   /* [steps/s] highest max speed the step ISR accepts */

typedef struct {
    uint8_t layout, kind;
    uint32_t board_id, baud;
    uint8_t axis, flags;
    float max_speed, accel;
    int32_t min_steps, max_steps;
    uint16_t sensor_zero;
} board_config_t;

/* ---- the installation key and the boot counter in EEPROM (docs/firmware.md "EEPROM
 * configuration"): the 16-byte key at KEY_EEPROM_ADDR followed by its CRC-16 (a blank or
 * damaged block: unprovisioned, the null key), the u32 boot count at BOOT_EEPROM_ADDR
 * (+1 at every start, blank 0xFFFFFFFF counts as 0; it makes the board's session nonces
 * fresh across reboots). */
#define KEY_EEPROM_ADDR 64
#define KEY_EEPROM_SIZE 18
#define BOOT_EEPROM_ADDR 96
/* the axis board's host-loss stow: HL_SIZE bytes (the SET_HOST_LOSS_STOW payload) + CRC-16 */
#define HL_EEPROM_ADDR 112

void config_defaults(board_config_t *c, uint8_t kind);
void config_pack(const board_config_t *c, uint8_t *p);            /* CONFIG_SIZE bytes */
void config_unpack(const uint8_t *p, board_config_t *c);
/* 0 = acceptable for a board of `kind`, else ERR_OUT_OF_RANGE */
uint8_t config_check(const board_config_t *c, uint8_t kind);

#ifdef __cplusplus
}
#endif
#endif
