/* Common firmware of the SSLFR boards (Arduino core, ATmega328P at 16 MHz: the Arduino
 * Pro Mini of seed 000 section 3.5): configuration record in EEPROM, UART and protocol
 * session, common requests (PING, GET_INFO, RESET, GET_CONFIG, SET_CONFIG), the AVR
 * hardware watchdog and idle sleep. Each board's .cpp defines `const BoardDef BOARD`. */
#ifndef SSLFR_BOARD_H
#define SSLFR_BOARD_H

#include <Arduino.h>
#include "msgs.h"
#include "session.h"

struct BoardDef {
    uint8_t kind;
    const char *name;                                  /* INFO name, <= 16 chars */
    void (*setup)(void);                               /* after the config is loaded */
    void (*poll)(uint32_t now_ms);                     /* every pass of the main loop */
    /* a board request (not a common one): 1 = answered (ans filled), 0 = not implemented */
    uint8_t (*handle)(const proto_frame_t *req, proto_frame_t *ans);
    void (*host_silent)(void);                         /* host-silence watchdog expired */
    uint8_t (*busy)(void);                             /* 1: refuse SET_CONFIG (motor moving) */
    uint8_t (*may_sleep)(void);                        /* 1: nothing to do until an interrupt */
};

extern const BoardDef BOARD;
extern board_config_t g_config;
extern session_t g_session;
extern uint8_t g_reset_cause;                          /* MCUSR at power-up */

/* Send an unsolicited frame (samples) to the host. */
void board_send(uint8_t type, const uint8_t *payload, uint8_t len);

#endif
