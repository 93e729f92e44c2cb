/* Requests every SSLFR board answers the same way (PING, GET_INFO, RESET, GET_CONFIG,
 * SET_CONFIG) and the dispatch to the board's own requests. Plain C99: the firmware
 * (core/board.cpp) and the host test library (host/hostlib.c) run this same code. */
#ifndef SSLFR_COMMON_H
#define SSLFR_COMMON_H

#include "msgs.h"
#include "session.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef struct {
    uint8_t kind;
    uint8_t fw_major, fw_minor, fw_patch;
    const char *name;
    board_config_t *config;                      /* the configuration in use */
    /* a board request: 1 = answered (ans filled), 0 = not implemented (UNKNOWN_TYPE) */
    uint8_t (*handle)(const proto_frame_t *req, proto_frame_t *ans);
    uint8_t (*busy)(void);                       /* 1: SET_CONFIG refused with BUSY */
    uint8_t (*store)(const board_config_t *c);   /* write the record; 0 = failed (INTERNAL) */
} common_board_t;

/* The session handler of a board: the common requests, then board->handle. */
uint8_t common_handle(const common_board_t *board, session_t *s, const proto_frame_t *req,
                      proto_frame_t *ans);

/* EEPROM image of a record (CONFIG_EEPROM_SIZE bytes: record + CRC) and back;
 * config_load returns 0 (and defaults) for a blank, damaged or foreign image. */
void config_image(const board_config_t *c, uint8_t *raw);
uint8_t config_load(const uint8_t *raw, uint8_t kind, board_config_t *c);
/* EEPROM image of an installation key (KEY_EEPROM_SIZE bytes: key + CRC) and back;
 * key_load returns 0 (and the null key) for a blank or damaged image. */
void key_image(const uint8_t key[16], uint8_t *raw);
uint8_t key_load(const uint8_t *raw, uint8_t key[16]);
/* The boot count of this start from the EEPROM's u32 (blank 0xFFFFFFFF: 0): stored + 1. */
uint32_t boot_count_next(uint32_t stored);

#ifdef __cplusplus
}
#endif
#endif
