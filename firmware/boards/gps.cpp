/* GPS board (seed 000 section 3.5.2, GPS PCB): a u-blox NEO-6 (GY-GPS6MV2 module) at
 * 9600 bit/s on a second serial line (SoftwareSerial), its NMEA byte stream forwarded
 * unmodified in NMEA_CHUNK frames (the gps node's `framing: protocol`; the host
 * reassembles and checks the sentences, so faults stay visible). A chunk is sent at
 * every end of line, when 64 bytes are buffered, or after 20 ms without a byte.
 *
 * Pins (Arduino Pro Mini): D8 <- NEO-6 TX, D9 -> NEO-6 RX (SoftwareSerial; the module's
 * default configuration is used, nothing is sent to it).
 */
#include "board.h"

#include <SoftwareSerial.h>

#define GPS_RX 8
#define GPS_TX 9
#define CHUNK_MAX 64u
#define IDLE_FLUSH_MS 20u

static SoftwareSerial gps(GPS_RX, GPS_TX);
static uint8_t g_chunk[CHUNK_MAX];
static uint8_t g_n;
static uint32_t g_last_byte;
uint32_t g_nmea_bytes __attribute__((used));
uint16_t g_gps_overflows __attribute__((used));

static void flush_chunk(void)
{
    if (g_n) {
        board_send(MSG_NMEA_CHUNK, g_chunk, g_n);
        g_n = 0;
    }
}

static void gps_setup(void)
{
    gps.begin(9600);
}

static void gps_poll(uint32_t now)
{
    if (gps.overflow())
        g_gps_overflows++;
    while (gps.available() > 0) {
        uint8_t c = (uint8_t)gps.read();
        g_nmea_bytes++;
        g_chunk[g_n++] = c;
        g_last_byte = now;
        if (c == '\n' || g_n == CHUNK_MAX)
            flush_chunk();
    }
    if (g_n && (uint32_t)(now - g_last_byte) >= IDLE_FLUSH_MS)
        flush_chunk();
}

static uint8_t gps_handle(const proto_frame_t *, proto_frame_t *) { return 0; }
static void gps_silent(void) {}
static uint8_t gps_busy(void) { return 0; }
static uint8_t gps_may_sleep(void) { return gps.available() == 0; }

const BoardDef BOARD = {
    KIND_GPS, "sslfr-gps", gps_setup, gps_poll, gps_handle, gps_silent, gps_busy, gps_may_sleep,
};
