/* fwsim: run one SSLFR board's exact firmware (.elf, or the Arduino bootloader .hex) on
 * libsimavr with the models of what it is wired to (models.c).
 *
 *   fwsim --board axis|absorber|irradiance|gps --elf FILE [--eeprom FILE]
 *         [--bootloader FILE.hex]      start in the bootloader (BOOTRST), app flash empty
 *         [--symbols FILE.elf]         (with --bootloader) the application's symbols for status
 *         [--link PATH] [--path-file FILE]   UART on a new pty (default), symlink to it
 *         [--uart-fd N]                UART on an inherited descriptor (a socketpair)
 *         [--pace X]                   simulated seconds per wall second (0: free run)
 *         [--mech lo,hi,sleep,step_rad,width,overtravel,angle] [--sensor ZERO]
 *         [--act lever,mount,mount_angle,stroke_lo,stroke_hi,max_speed,min_duty,inc_offset,noise_mv,angle]
 *         (--board actuator: the actuator + lever + analogue inclinometer model, models.c)
 *         [--seed N]
 *
 * UART bridge (no libsimavrparts uart_pty: it loses bytes under back-pressure): bytes
 * from the host are fed to the AVR's receiver only while it signals XON; bytes the AVR
 * sends are buffered (1 MiB) until the non-blocking host side takes them, so nothing is
 * lost while a host lags (the buffer's overflow is counted, never silent). Both
 * directions are pumped from a 1 ms cycle timer that also paces simulated time to the
 * wall clock (times --pace) by sleeping in poll() on the UART and command descriptors.
 *
 * Commands, one line each on stdin; every command gets one line "FWSIM ok", "FWSIM error
 * MESSAGE" or "FWSIM status {JSON}" on stdout (the library prints its own lines too:
 * parse only the FWSIM ones):
 *   status                         JSON state (times [s of simulated time], counters,
 *                                  firmware variables read from RAM, model state)
 *   drop P | corrupt P             byte drop / one-bit flip probability, both directions
 *   corrupt_frames P               probability that a board -> host frame gets one bit flipped
 *   disconnect S                   nothing passes either way for S wall seconds
 *   unplug S                       close the pty for S wall seconds, then a new one
 *   reset                          power-cycle the AVR (external reset)
 *   hang                           the firmware hangs with interrupts off (the AVR
 *                                  watchdog must reset it)
 *   mark                           remember "now" for latency figures (first step after)
 *   quit
 *   model commands (models.c): stall 0|1, set_angle RAD, driver_fault 0|1, temps W W,
 *                              switches B..., pulses HZ [PIN], lux L, nmea HEX
 * Events: "FWSIM pty PATH" when a pty is (re)created, "FWSIM reset N" after every reset.
 */
#define _GNU_SOURCE
#include "fwsim.h"

#include <errno.h>
#include <fcntl.h>
#include <math.h>
#include <poll.h>
#include <pty.h>
#include <signal.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <time.h>
#include <unistd.h>

#include "avr_eeprom.h"
#include "avr_uart.h"
#include "sim_elf.h"
#include "sim_hex.h"
#include "session.h"
#include "axis_state.h"
#include "actuator_state.h"

#define TICK_CYCLES (F_CPU_HZ / 1000u)    /* 1 ms */
#define TXBUF_SIZE (1u << 20)
#define RXBUF_SIZE 4096u

uint64_t g_cycle_offset;                   /* 0: the cycle counter runs on across resets */

static avr_t *avr;
static model_t *model;
static mech_t mech;
static enum board_kind kind;
static double pace = 1.0;
static struct timespec t0;
static uint64_t pace_base_cycles;          /* cycles at the pacing anchor t0 */
static double slipped_s;                   /* simulated time given up when the host CPU lagged */
static const char *link_path, *path_file;
static int uart_fd = -1, pty_slave = -1, external_fd = 0;
static char pty_name[128];
static double unplugged_until, silent_until;
static double p_drop, p_corrupt, p_corrupt_frames;
static unsigned long long rx_bytes, tx_bytes, dropped_bytes, corrupted_bytes, corrupted_frames,
    tx_overflow, silenced_bytes, resets, watchdog_resets, lag_slips;
static int xon = 1;
static uint8_t rxbuf[RXBUF_SIZE];
static size_t rx_head, rx_len;
static uint8_t *txbuf;
static size_t tx_head, tx_len;
static uint8_t frame_buf[PROTO_MAX_FRAME];  /* board -> host frame being assembled */
static size_t frame_n;
static char cmdbuf[65536];
static size_t cmd_len;
static int running = 1;
static uint64_t last_rx_cycle, mark_cycle;
static uint32_t sym_ax, sym_act, sym_session, sym_stop, sym_pulses, sym_pulse_pin;
enum { PENDING_NONE, PENDING_RESET, PENDING_HANG };
static int pending;                        /* CPU state changes asked for by a command */

/* ---------------------------------------------------------------- time */
static double wall_now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)(t.tv_sec - t0.tv_sec) + (t.tv_nsec - t0.tv_nsec) * 1e-9;
}

/* absolute steady time [s]: deadlines (disconnect, unplug) must not move when the
 * pacing anchor t0 does */
static double mono_now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + t.tv_nsec * 1e-9;
}

static double sim_now(void) { return model_total_cycles(avr) / (double)F_CPU_HZ; }

static uint32_t rnd32(void) { return (uint32_t)random(); }
static int chance(double p) { return p > 0 && (rnd32() / 2147483648.0) < p; }

/* ---------------------------------------------------------------- pty */
static void pty_open(void)
{
    int master, slave;
    if (openpty(&master, &slave, pty_name, NULL, NULL) < 0) {
        perror("fwsim: openpty");
        exit(1);
    }
    struct termios tio;
    tcgetattr(slave, &tio);
    cfmakeraw(&tio);
    tcsetattr(slave, TCSANOW, &tio);
    fcntl(master, F_SETFL, fcntl(master, F_GETFL) | O_NONBLOCK);
    uart_fd = master;
    pty_slave = slave;                   /* kept open: a host may come and go */
    if (link_path) {
        char tmp[1024];
        snprintf(tmp, sizeof tmp, "%s.tmp%d", link_path, getpid());
        unlink(tmp);
        if (symlink(pty_name, tmp) == 0)
            rename(tmp, link_path);
    }
    if (path_file) {
        char tmp[1024];
        snprintf(tmp, sizeof tmp, "%s.tmp", path_file);
        FILE *f = fopen(tmp, "w");
        if (f) {
            fprintf(f, "%s\n", pty_name);
            fclose(f);
            rename(tmp, path_file);
        }
    }
    printf("FWSIM pty %s\n", pty_name);
    fflush(stdout);
}

static void pty_close(void)
{
    if (link_path)
        unlink(link_path);
    if (uart_fd >= 0)
        close(uart_fd);
    if (pty_slave >= 0)
        close(pty_slave);
    uart_fd = pty_slave = -1;
    dropped_bytes += rx_len + tx_len;
    rx_len = tx_len = 0;
}

/* ---------------------------------------------------------------- UART bridge */
static void tx_push(uint8_t b)
{
    if (tx_len == TXBUF_SIZE) {
        tx_overflow++;
        return;
    }
    txbuf[(tx_head + tx_len) % TXBUF_SIZE] = b;
    tx_len++;
}

/* board -> host after the byte faults */
static void tx_byte(uint8_t b)
{
    if (p_drop && chance(p_drop)) {
        dropped_bytes++;
        return;
    }
    if (p_corrupt && chance(p_corrupt)) {
        b ^= (uint8_t)(1u << (rnd32() % 8));
        corrupted_bytes++;
    }
    tx_push(b);
}

static void tx_frame_flush(void)
{
    if (p_corrupt_frames && frame_n >= 12 && chance(p_corrupt_frames)) {
        frame_buf[rnd32() % frame_n] ^= (uint8_t)(1u << (rnd32() % 8));
        corrupted_frames++;
    }
    for (size_t i = 0; i < frame_n; i++)
        tx_byte(frame_buf[i]);
    frame_n = 0;
}

static void uart_out_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
    (void)irq; (void)param;
    uint8_t b = (uint8_t)value;
    tx_bytes++;
    if (uart_fd < 0 || mono_now() < silent_until) {
        silenced_bytes++;
        frame_n = 0;
        return;
    }
    /* whole frames are assembled so corrupt_frames can hit one frame exactly once */
    frame_buf[frame_n++] = b;
    if (frame_n == 1 && b != PROTO_SYNC0) {
        tx_frame_flush();
        return;
    }
    if (frame_n == 2 && b != PROTO_SYNC1) {
        tx_frame_flush();
        return;
    }
    if (frame_n >= 4 && (frame_buf[3] > PROTO_MAX_BODY
                         || frame_n == (size_t)(PROTO_HEADER + frame_buf[3] + PROTO_CRC_SIZE)))
        tx_frame_flush();
}

static void xon_hook(struct avr_irq_t *irq, uint32_t value, void *param) { (void)irq; (void)value; (void)param; xon = 1; }
static void xoff_hook(struct avr_irq_t *irq, uint32_t value, void *param) { (void)irq; (void)value; (void)param; xon = 0; }

static void pump(void)
{
    if (uart_fd < 0)
        return;
    /* host -> AVR: read what fits, feed while the receiver has room */
    if (rx_len < RXBUF_SIZE) {
        uint8_t tmp[RXBUF_SIZE];
        ssize_t n = read(uart_fd, tmp, RXBUF_SIZE - rx_len);
        if (n > 0) {
            last_rx_cycle = model_total_cycles(avr);
            int silent = mono_now() < silent_until;
            for (ssize_t i = 0; i < n; i++) {
                uint8_t b = tmp[i];
                if (silent) { silenced_bytes++; continue; }
                if (p_drop && chance(p_drop)) { dropped_bytes++; continue; }
                if (p_corrupt && chance(p_corrupt)) { b ^= (uint8_t)(1u << (rnd32() % 8)); corrupted_bytes++; }
                rxbuf[(rx_head + rx_len) % RXBUF_SIZE] = b;
                rx_len++;
            }
        } else if (n == 0 && external_fd) {
            running = 0;                   /* the socketpair's other end went away */
        }
    }
    avr_irq_t *in = avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_INPUT);
    while (rx_len && xon) {
        uint8_t b = rxbuf[rx_head];
        rx_head = (rx_head + 1) % RXBUF_SIZE;
        rx_len--;
        rx_bytes++;
        avr_raise_irq(in, b);
    }
    /* AVR -> host: as much as the host side takes now, the rest stays buffered */
    while (tx_len) {
        size_t chunk = tx_len;
        if (tx_head + chunk > TXBUF_SIZE)
            chunk = TXBUF_SIZE - tx_head;
        ssize_t n = write(uart_fd, txbuf + tx_head, chunk);
        if (n <= 0)
            break;
        tx_head = (tx_head + (size_t)n) % TXBUF_SIZE;
        tx_len -= (size_t)n;
    }
}

/* ---------------------------------------------------------------- firmware RAM */
static uint32_t symbol(elf_firmware_t *f, const char *name)
{
    for (uint32_t i = 0; i < f->symbolcount; i++)
        if (!strcmp(f->symbol[i]->symbol, name))
            return f->symbol[i]->addr;
    return 0;
}

static void ram_read(uint32_t sym, size_t off, void *out, size_t n)
{
    memcpy(out, avr->data + (sym & 0xFFFF) + off, n);
}

static void status_json(void)
{
    printf("FWSIM status {\"sim_time\":%.6f,\"wall\":%.6f,\"pace\":%g,\"slipped_s\":%.3f,\"lag_slips\":%llu,"
           "\"resets\":%llu,\"watchdog_resets\":%llu,\"pc\":%u,\"state\":%d,"
           "\"rx_bytes\":%llu,\"tx_bytes\":%llu,\"bytes_dropped\":%llu,\"bytes_corrupted\":%llu,"
           "\"frames_corrupted\":%llu,\"bytes_silenced\":%llu,\"tx_overflow\":%llu,\"tx_pending\":%zu,"
           "\"plugged\":%s,\"path\":\"%s\",\"last_rx_s\":%.6f",
           sim_now(), wall_now(), pace, slipped_s, lag_slips, resets, watchdog_resets, avr->pc,
           avr->state, rx_bytes, tx_bytes, dropped_bytes, corrupted_bytes, corrupted_frames,
           silenced_bytes, tx_overflow, tx_len, uart_fd >= 0 ? "true" : "false", pty_name,
           last_rx_cycle / (double)F_CPU_HZ);
    if (mark_cycle)
        printf(",\"mark_s\":%.6f,\"first_step_after_mark_s\":%.6f", mark_cycle / (double)F_CPU_HZ,
               mech.first_step_after_rx / (double)F_CPU_HZ);
    if (sym_session) {
        uint32_t c[11];
        uint8_t tripped;
        ram_read(sym_session, offsetof(session_t, frames_in), c, sizeof c);
        ram_read(sym_session, offsetof(session_t, watchdog_tripped), &tripped, 1);
        printf(",\"frames_in\":%u,\"frames_out\":%u,\"requests_stale\":%u,\"requests_duplicate\":%u,"
               "\"watchdog_trips\":%u,\"version_errors\":%u,\"auth_failures\":%u,\"no_session\":%u,"
               "\"sessions\":%u,\"boot_count\":%u,\"provision_refused\":%u,\"watchdog_tripped\":%s",
               c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7], c[8], c[9], c[10], tripped ? "true" : "false");
    }
    if (sym_ax) {
        axis_state_t a;
        ram_read(sym_ax, 0, &a, sizeof a);
        printf(",\"goal\":%d,\"pf\":%.3f,\"counter\":%d,\"target\":%d,\"speed\":%.3f,\"homed\":%s,\"homing\":%s,\"faults\":%u,"
               "\"steps_total\":%u", a.goal, a.pf_int + a.pf_frac, a.pos, a.homing ? a.pos : a.target, a.v, a.homed ? "true" : "false",
               a.homing ? "true" : "false", a.faults, a.steps_total);
        printf(",\"hl_stowing\":%s,\"seek_switch\":%u", a.hl_stowing ? "true" : "false", a.seek_switch);
    }
    if (sym_act) {
        act_state_t a;
        ram_read(sym_act, 0, &a, sizeof a);
        printf(",\"measured\":%.9f,\"act_target\":%.9f,\"has_target\":%s,\"zero\":%d,\"homed\":%s,"
               "\"faults\":%u,\"act_speed\":%.6f,\"act_duty\":%.4f,\"driving\":%s", a.measured, a.target,
               a.has_target ? "true" : "false", a.zero, a.homed ? "true" : "false", a.faults, a.speed, a.duty,
               a.driving ? "true" : "false");
    }
    if (sym_pulses) {
        uint32_t n;
        ram_read(sym_pulses, 0, &n, sizeof n);
        printf(",\"fw_pulses\":%u", n);
    }
    model_status_json(model, stdout);
    printf("}\n");
}

/* ---------------------------------------------------------------- commands */
static void command(char *line)
{
    char word[32], reply[256] = "";
    int used = 0;
    if (sscanf(line, "%31s %n", word, &used) != 1)
        return;
    const char *args = line + used;
    double now = mono_now();
    if (!strcmp(word, "status")) {
        status_json();
        fflush(stdout);
        return;
    } else if (!strcmp(word, "drop")) {
        p_drop = atof(args);
    } else if (!strcmp(word, "corrupt")) {
        p_corrupt = atof(args);
    } else if (!strcmp(word, "corrupt_frames")) {
        p_corrupt_frames = atof(args);
    } else if (!strcmp(word, "disconnect")) {
        silent_until = now + atof(args);
    } else if (!strcmp(word, "unplug")) {
        if (external_fd) {
            snprintf(reply, sizeof reply, "unplug: the UART is not on a pty");
        } else {
            pty_close();
            unplugged_until = now + atof(args);
        }
    } else if (!strcmp(word, "reset")) {
        pending = PENDING_RESET;           /* done between two instructions (main loop) */
    } else if (!strcmp(word, "hang")) {
        if (!sym_stop)
            snprintf(reply, sizeof reply, "hang: no _exit in the firmware");
        else
            pending = PENDING_HANG;
    } else if (!strcmp(word, "mark")) {
        mark_cycle = model_total_cycles(avr);
        mech.first_step_after_rx = 0;
    } else if (!strcmp(word, "quit")) {
        running = 0;
    } else {
        int r = model_command(model, line, reply, sizeof reply);
        if (r < 0)
            snprintf(reply, sizeof reply, "unknown command %s", word);
    }
    if (reply[0])
        printf("FWSIM error %s\n", reply);
    else
        printf("FWSIM ok\n");
    fflush(stdout);
}

static void read_commands(void)
{
    for (;;) {
        ssize_t n = read(0, cmdbuf + cmd_len, sizeof cmdbuf - 1 - cmd_len);
        if (n == 0) {                      /* stdin closed: the controller is gone */
            running = 0;
            return;
        }
        if (n < 0)
            return;
        cmd_len += (size_t)n;
        cmdbuf[cmd_len] = 0;
        char *nl;
        while ((nl = memchr(cmdbuf, '\n', cmd_len)) != NULL) {
            *nl = 0;
            command(cmdbuf);
            size_t rest = cmd_len - (size_t)(nl + 1 - cmdbuf);
            memmove(cmdbuf, nl + 1, rest);
            cmd_len = rest;
        }
        if (cmd_len == sizeof cmdbuf - 1)
            cmd_len = 0;                   /* an absurd line: dropped */
    }
}

/* ---------------------------------------------------------------- the 1 ms tick */
static avr_cycle_count_t tick(avr_t *a, avr_cycle_count_t when, void *param)
{
    (void)a; (void)param;
    double now = wall_now();
    if (uart_fd < 0 && !external_fd && mono_now() >= unplugged_until)
        pty_open();
    read_commands();
    pump();
    if (pace > 0) {
        double sim = (model_total_cycles(avr) - pace_base_cycles) / (double)F_CPU_HZ;
        double ahead = sim - now * pace;
        if (ahead < -0.1) {                /* the host CPU fell behind: do not sprint */
            lag_slips++;
            slipped_s += -ahead / pace;
            clock_gettime(CLOCK_MONOTONIC, &t0);
            pace_base_cycles = model_total_cycles(avr);
        }
        while (running && ahead > 0.0005) {
            struct pollfd fds[2] = {{.fd = 0, .events = POLLIN}, {.fd = uart_fd, .events = POLLIN}};
            int ms = (int)(ahead / pace * 1000.0);
            if (ms < 1) ms = 1;
            if (ms > 20) ms = 20;
            int r = poll(fds, uart_fd >= 0 && rx_len < RXBUF_SIZE ? 2 : 1, ms);
            if (r > 0) {
                read_commands();
                pump();
            }
            if (!external_fd && uart_fd < 0 && mono_now() >= unplugged_until)
                pty_open();
            ahead = sim - wall_now() * pace;
        }
    }
    return when + TICK_CYCLES;
}

/* one cycle after a reset: the reset cause is in MCUSR (the watchdog sets WDRF after
 * avr_reset() returns; the firmware clears MCUSR in .init3, a few cycles later) */
static avr_cycle_count_t after_reset(avr_t *a, avr_cycle_count_t when, void *param)
{
    (void)when; (void)param;
    if (a->data[0x54] & 0x08)             /* MCUSR.WDRF */
        watchdog_resets++;
    return 0;
}

static int rearm;
static avr_cycle_count_t cycle_at_reset;

/* Every reset cancels all cycle timers, and avr_reset() zeroes the cycle counter after
 * this hook while the peripherals' reset (the watchdog restarting at 16 ms after a
 * watchdog reset) registered their timers in the old time base. The main loop puts the
 * counter back (time runs on, and those timers fire when they should) and re-arms ours. */
static void on_reset(avr_t *a)
{
    cycle_at_reset = a->cycle;
    resets++;
    rearm = 1;
    frame_n = 0;
    printf("FWSIM reset %llu\n", resets);
    fflush(stdout);
}

static void no_sleep(avr_t *a, avr_cycle_count_t how_long) { (void)a; (void)how_long; }

static void usage(void)
{
    fprintf(stderr, "usage: fwsim --board axis|absorber|irradiance|gps --elf FILE [--eeprom FILE] "
                    "[--bootloader HEX] [--link PATH] [--path-file FILE] [--uart-fd N] [--pace X] "
                    "[--mech lo,hi,sleep,step_rad,width,overtravel,angle] [--sensor ZERO] [--seed N]\n");
    exit(2);
}

int main(int argc, char **argv)
{
    const char *elf = NULL, *eeprom = NULL, *boot = NULL, *symbols = NULL;
    unsigned seed = 1;
    kind = B_AXIS;
    mech = (mech_t){.lo = -M_PI / 4, .hi = M_PI / 2, .sleep = M_PI / 2, .step_rad = 0.006 * M_PI / 180,
                    .switch_width = 0.2 * M_PI / 180, .overtravel = M_PI / 180, .angle = M_PI / 2};
    for (int i = 1; i < argc; i++) {
        const char *a = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (!strcmp(a, "--board") && v) {
            kind = !strcmp(v, "axis") ? B_AXIS : !strcmp(v, "absorber") ? B_ABSORBER
                 : !strcmp(v, "irradiance") ? B_IRRADIANCE : !strcmp(v, "gps") ? B_GPS
                 : !strcmp(v, "actuator") ? B_ACTUATOR : (usage(), B_AXIS);
            i++;
        } else if (!strcmp(a, "--elf") && v) { elf = v; i++; }
        else if (!strcmp(a, "--symbols") && v) { symbols = v; i++; }
        else if (!strcmp(a, "--eeprom") && v) { eeprom = v; i++; }
        else if (!strcmp(a, "--bootloader") && v) { boot = v; i++; }
        else if (!strcmp(a, "--link") && v) { link_path = v; i++; }
        else if (!strcmp(a, "--path-file") && v) { path_file = v; i++; }
        else if (!strcmp(a, "--uart-fd") && v) { uart_fd = atoi(v); external_fd = 1; i++; }
        else if (!strcmp(a, "--pace") && v) { pace = atof(v); i++; }
        else if (!strcmp(a, "--seed") && v) { seed = (unsigned)atoi(v); i++; }
        else if (!strcmp(a, "--sensor") && v) { mech.has_sensor = 1; mech.sensor_zero = (uint16_t)atoi(v); i++; }
        else if (!strcmp(a, "--act") && v) {
            if (sscanf(v, "%lf,%lf,%lf,%lf,%lf,%lf,%lf,%lf,%lf,%lf", &mech.lever, &mech.mount, &mech.mount_angle,
                       &mech.stroke_lo, &mech.stroke_hi, &mech.max_speed, &mech.min_duty, &mech.inc_offset,
                       &mech.noise_mv, &mech.angle) != 10)
                usage();
            i++;
        }
        else if (!strcmp(a, "--mech") && v) {
            if (sscanf(v, "%lf,%lf,%lf,%lf,%lf,%lf,%lf", &mech.lo, &mech.hi, &mech.sleep, &mech.step_rad,
                       &mech.switch_width, &mech.overtravel, &mech.angle) != 7)
                usage();
            i++;
        } else
            usage();
    }
    if (!elf && !boot)
        usage();
    srandom(seed);
    signal(SIGPIPE, SIG_IGN);
    txbuf = malloc(TXBUF_SIZE);
    avr = avr_make_mcu_by_name("atmega328p");
    if (!avr) {
        fprintf(stderr, "fwsim: libsimavr has no atmega328p\n");
        return 1;
    }
    avr_init(avr);
    avr->frequency = F_CPU_HZ;
    avr->log = LOG_ERROR;
    elf_firmware_t f;
    memset(&f, 0, sizeof f);
    if (elf) {
        if (elf_read_firmware(elf, &f) != 0) {
            fprintf(stderr, "fwsim: cannot read %s\n", elf);
            return 1;
        }
        strcpy(f.mmcu, "atmega328p");      /* our ELFs carry no .mmcu section */
        f.frequency = F_CPU_HZ;
        avr_load_firmware(avr, &f);
        sym_ax = symbol(&f, "ax");
        sym_act = symbol(&f, "act");
        sym_session = symbol(&f, "g_session");
        sym_stop = symbol(&f, "_exit");        /* cli; rjmp . */
        sym_pulses = symbol(&f, "g_pulses");
        sym_pulse_pin = symbol(&f, "g_pulse_pin");
    }
    if (symbols && !elf) {                 /* the application's symbols, its code not loaded */
        if (elf_read_firmware(symbols, &f) != 0) {
            fprintf(stderr, "fwsim: cannot read %s\n", symbols);
            return 1;
        }
        sym_ax = symbol(&f, "ax");
        sym_act = symbol(&f, "act");
        sym_session = symbol(&f, "g_session");
        sym_stop = symbol(&f, "_exit");
    }
    if (boot) {
        uint32_t base, size;
        uint8_t *code = read_ihex_file(boot, &size, &base);
        if (!code) {
            fprintf(stderr, "fwsim: cannot read %s\n", boot);
            return 1;
        }
        memcpy(avr->flash + base, code, size);
        free(code);
        avr->pc = avr->reset_pc = base;    /* BOOTRST programmed, as the Pro Mini's fuses */
        avr->codeend = avr->flashend;
    }
    if (eeprom) {
        uint8_t ee[1024];
        FILE *fe = fopen(eeprom, "rb");
        if (!fe) {
            fprintf(stderr, "fwsim: cannot read %s\n", eeprom);
            return 1;
        }
        size_t n = fread(ee, 1, sizeof ee, fe);
        fclose(fe);
        avr_eeprom_desc_t d = {.ee = ee, .offset = 0, .size = (uint32_t)n};
        avr_ioctl(avr, AVR_IOCTL_EEPROM_SET, &d);
    }
    avr->sleep = no_sleep;                 /* pacing is ours (tick), not usleep per sleep */
    avr->reset = on_reset;
    uint32_t flags = 0;
    avr_ioctl(avr, AVR_IOCTL_UART_GET_FLAGS('0'), &flags);
    flags &= ~(AVR_UART_FLAG_POLL_SLEEP | AVR_UART_FLAG_STDIO);
    avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUTPUT), uart_out_hook, NULL);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XON), xon_hook, NULL);
    avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_UART_GETIRQ('0'), UART_IRQ_OUT_XOFF), xoff_hook, NULL);
    model = model_create(avr, boot && !elf ? B_BOOTLOADER : kind, &mech);
    model_set_pulse_pin_addr(model, sym_pulse_pin);
    fcntl(0, F_SETFL, fcntl(0, F_GETFL) | O_NONBLOCK);
    if (external_fd)
        fcntl(uart_fd, F_SETFL, fcntl(uart_fd, F_GETFL) | O_NONBLOCK);
    else
        pty_open();
    clock_gettime(CLOCK_MONOTONIC, &t0);
    avr_cycle_timer_register(avr, TICK_CYCLES, tick, NULL);
    printf("FWSIM ready\n");
    fflush(stdout);
    while (running) {
        int state = avr_run(avr);
        if (pending) {
            /* commands run inside a cycle timer, after which simavr restores the PC:
             * CPU state changes are applied here, between two instructions */
            if (pending == PENDING_RESET) {
                avr_reset(avr);                 /* external reset */
                avr->data[0x54] |= 0x02;        /* MCUSR.EXTRF */
            } else {
                avr->sreg[S_I] = 0;             /* hung with interrupts off */
                avr->pc = sym_stop;
                avr->state = cpu_Running;
            }
            pending = PENDING_NONE;
        }
        if (rearm) {
            rearm = 0;
            avr->cycle = cycle_at_reset;
            avr_cycle_timer_register(avr, TICK_CYCLES, tick, NULL);
            avr_cycle_timer_register(avr, 1, after_reset, NULL);
            model_after_reset(model);
        }
        if (state == cpu_Done || state == cpu_Crashed) {
            printf("FWSIM error the AVR stopped (state %d, pc 0x%04x)\n", state, avr->pc);
            fflush(stdout);
            return 3;
        }
    }
    if (!external_fd)
        pty_close();
    return 0;
}
