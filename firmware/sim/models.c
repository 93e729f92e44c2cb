/* Models of what the SSLFR boards are wired to, on libsimavr IRQs:
 *
 * axis       stepper driver + mechanism (`driver_fault 1` pulls /DRIVER_FAULT low): STEP rising edge with /ENABLE low turns the
 *            joint by step_rad in the DIR direction (DIR high = increasing angle),
 *            hard stops `overtravel` beyond the end switches (steps lost), `stall`
 *            (pulses counted, joint still); LOW / HIGH / SLEEP switches close (pin low)
 *            at angle <= lo, >= hi, |angle - sleep| <= width/2 (sim/axis.py geometry);
 *            optional AS5048A absolute encoder on SPI (/CS D10).
 * absorber   two MAX6675 (SPI, /CS D9 inlet, D10 outlet): a 16-bit word latched at the
 *            falling /CS edge (the words come from the host model); five switches
 *            D2..D6 (closed = low), changes optionally bouncing 2 ms apart.
 * irradiance VEML7700 at I2C 0x10: ALS_CONF (0x00) and ALS (0x04) registers; the count of
 *            an integration period is latched at its end from the illuminance then,
 *            count = round(lux / resolution(gain, IT)) clipped at 65535, resolution =
 *            0.0036 lx * (2 / gain) * (800 ms / IT) (sslfr_drivers/veml7700.py).
 * gps        NEO-6 TX -> D8: queued NMEA bytes bit-banged 8N1 at 9600 bit/s.
 * actuator   linear actuator + lever + analogue inclinometer: every 1 ms the PWM duty
 *            (OCR1A / (ICR1 + 1) while OC1A drives D9, sign from DIR D8) moves the
 *            actuator at speed_for_duty (0 below the start duty; `stall 1`: powered,
 *            not moving), clipped to the stroke; line angle = the inverse law of cosines;
 *            at every ADC conversion A0 gets 2500 mV + 44.44 mV/deg x (angle + mounting
 *            offset) + Gaussian noise (noise_mv rms), in whole mV (simavr's ADC input).
 */
#include "fwsim.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "avr_ioport.h"
#include "avr_spi.h"
#include "avr_twi.h"
#include "avr_adc.h"
#include "sim_time.h"

extern uint64_t g_cycle_offset;

uint64_t model_total_cycles(avr_t *avr) { return g_cycle_offset + avr->cycle; }

/* the PINx data addresses of the ATmega328P */
#define PINB_ADDR 0x23
#define PIND_ADDR 0x29

typedef struct {
    char port;
    uint8_t mask, value;   /* externally driven pins */
} ext_port_t;

struct model {
    avr_t *avr;
    enum board_kind kind;
    mech_t *mech;
    ext_port_t ext[2];     /* B, D */
    /* SPI slave */
    uint8_t cs_b;          /* last PORTB/pin level of the chip selects */
    uint16_t spi_word[2];  /* MAX6675: words latched at /CS (inlet, outlet) */
    int spi_sel;           /* selected chip (-1 none) */
    int spi_index;         /* byte index within the word */
    uint16_t spi_cmd;      /* AS5048A: command being shifted in */
    uint16_t spi_answer;   /* AS5048A: answer shifted out */
    uint16_t tc_words[2];  /* words the host model gives (inlet, outlet) */
    uint32_t spi_reads;
    /* pulse input (absorber: cup anemometer on D7, D8 or D11) */
    char pulse_port;       /* 0: none */
    int pulse_bit, pulse_level;
    double pulse_hz;       /* [Hz] 0 = at rest */
    int pulse_running;     /* the square wave's timer is registered */
    uint32_t pulse_pin_addr;   /* firmware RAM of its pulse pin (0: unknown) */
    int pulse_follow;      /* drive the pin the firmware counts on */
    uint64_t pulses_sent;  /* falling edges driven */
    /* switches (absorber) */
    uint8_t sw_seq[16];
    int sw_n, sw_i;
    uint8_t sw_bits;
    /* VEML7700 */
    avr_irq_t *twi_irq;
    int twi_selected, twi_index;
    uint8_t twi_reg;
    uint16_t veml_conf, veml_als;
    uint64_t veml_start;   /* cycle the current integration started */
    double lux;
    uint32_t twi_transactions;
    /* NEO-6 */
    uint8_t *nmea;
    size_t nmea_len, nmea_cap, nmea_pos;
    int bit;               /* -1 idle, 0 start, 1..8 data, 9 stop */
    double bit_phase;      /* fractional cycles */
    uint64_t nmea_sent;
    /* axis */
    avr_irq_t *step_irq;
    uint8_t limit_bits;
};

/* ---- pins ------------------------------------------------------------------------ */
static ext_port_t *ext_of(model_t *m, char port) { return port == 'B' ? &m->ext[0] : &m->ext[1]; }

/* Drive an input pin from outside (a switch, a sensor line). The level is both the
 * external state (kept across port writes) and raised on the pin IRQ; the PIN register
 * is patched too so a level equal to the IRQ's cached value still reads right. */
static void pin_drive(model_t *m, char port, int bit, int level)
{
    ext_port_t *e = ext_of(m, port);
    uint8_t mask = (uint8_t)(1u << bit);
    e->mask |= mask;
    e->value = (uint8_t)(level ? (e->value | mask) : (e->value & ~mask));
    avr_ioport_external_t ext = {.name = port, .mask = e->mask, .value = e->value};
    avr_ioctl(m->avr, AVR_IOCTL_IOPORT_SET_EXTERNAL(port), &ext);
    avr_raise_irq(avr_io_getirq(m->avr, AVR_IOCTL_IOPORT_GETIRQ(port), bit), level ? 1 : 0);
    uint16_t addr = port == 'B' ? PINB_ADDR : PIND_ADDR;
    m->avr->data[addr] = (uint8_t)(level ? (m->avr->data[addr] | mask) : (m->avr->data[addr] & ~mask));
}

static void pins_reapply(model_t *m)
{
    for (int p = 0; p < 2; p++)
        for (int b = 0; b < 8; b++)
            if (m->ext[p].mask & (1u << b))
                pin_drive(m, m->ext[p].port, b, (m->ext[p].value >> b) & 1);
}

/* ---- actuator ---------------------------------------------------------------------- */
static double act_angle(const mech_t *k, double length)
{
    double d = k->mount, r = k->lever;
    double c = (d * d + r * r - length * length) / (2.0 * d * r);
    c = c < -1.0 ? -1.0 : (c > 1.0 ? 1.0 : c);
    return acos(c) - k->mount_angle;
}

static double gauss(void)
{
    double u = (random() + 1.0) / (RAND_MAX + 2.0), v = (random() + 1.0) / (RAND_MAX + 2.0);
    return sqrt(-2.0 * log(u)) * cos(2.0 * M_PI * v);
}

static avr_cycle_count_t act_timer(avr_t *avr, avr_cycle_count_t when, void *param)
{
    model_t *m = (model_t *)param;
    mech_t *k = m->mech;
    uint8_t *d = avr->data;
    double duty = 0.0;
    if ((d[0x80] & 0x80) && (d[0x24] & 0x02)) {          /* TCCR1A COM1A1, DDRB PB1 (D9) */
        unsigned top = d[0x86] | (unsigned)d[0x87] << 8, ocr = d[0x88] | (unsigned)d[0x89] << 8;
        duty = (double)ocr / (top + 1.0);
        if (duty > 1.0) duty = 1.0;
        if (!(d[0x25] & 0x01)) duty = -duty;             /* PORTB PB0 (D8) DIR low: shorten */
    }
    k->duty = duty;
    double a = fabs(duty), v = 0.0;
    if (a >= k->min_duty)
        v = copysign(k->max_speed * (a - k->min_duty) / (1.0 - k->min_duty), duty);
    if (!k->stalled && v != 0.0) {
        k->length += v * 1e-3;
        if (k->length < k->stroke_lo) k->length = k->stroke_lo;
        if (k->length > k->stroke_hi) k->length = k->stroke_hi;
        k->angle = act_angle(k, k->length);
    }
    return when + F_CPU_HZ / 1000;
}

static void adc_trigger_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
    model_t *m = (model_t *)param;
    mech_t *k = m->mech;
    (void)irq; (void)value;
    double mv = 2500.0 + 4000.0 / 90.0 * (k->angle + k->inc_offset) * 180.0 / M_PI + k->noise_mv * gauss();
    mv = mv < 0 ? 0 : (mv > 5000 ? 5000 : mv);
    /* simavr 1.6 converts mV * 1023 / AVcc; the ATmega328P Vin * 1024 / Vref: feed the
     * value that gives the chip's count */
    mv *= 1024.0 / 1023.0;
    avr_raise_irq(avr_io_getirq(m->avr, AVR_IOCTL_ADC_GETIRQ, ADC_IRQ_ADC0), (uint32_t)lround(mv));
}

/* ---- axis -------------------------------------------------------------------------- */
static uint8_t mech_switches(const mech_t *k)
{
    uint8_t bits = 0;
    if (k->angle <= k->lo) bits |= 1;
    if (k->angle >= k->hi) bits |= 2;
    if (fabs(k->angle - k->sleep) <= k->switch_width / 2) bits |= 4;
    return bits;
}

static void axis_update_switches(model_t *m, int force)
{
    uint8_t bits = mech_switches(m->mech);
    if (!force && bits == m->limit_bits)
        return;
    m->limit_bits = bits;
    pin_drive(m, 'D', 7, !(bits & 1));     /* LOW   D7, closed = low */
    pin_drive(m, 'B', 0, !(bits & 2));     /* HIGH  D8 */
    pin_drive(m, 'B', 1, !(bits & 4));     /* SLEEP D9 */
}

static void step_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
    model_t *m = (model_t *)param;
    (void)irq;
    if (!value)
        return;
    uint8_t portd = m->avr->data[0x2B];             /* PORTD */
    if (portd & (1u << 5))                           /* /ENABLE high: driver off */
        return;
    int dir = (portd & (1u << 4)) ? 1 : -1;
    mech_t *k = m->mech;
    k->steps += dir;
    k->last_step_cycle = model_total_cycles(m->avr);
    if (!k->first_step_after_rx)
        k->first_step_after_rx = k->last_step_cycle;
    if (!k->stalled) {
        k->angle += dir * k->step_rad;
        double lo = k->lo - k->overtravel, hi = k->hi + k->overtravel;
        if (k->angle < lo) k->angle = lo;
        if (k->angle > hi) k->angle = hi;
    }
    axis_update_switches(m, 0);
}

static uint16_t as5048_angle(model_t *m)
{
    mech_t *k = m->mech;
    double turns = k->angle / (2 * M_PI);
    long c = lround(turns * 16384.0) + k->sensor_zero;
    uint16_t w = (uint16_t)(c & 0x3FFF);
    uint16_t par = w;
    par ^= par >> 8; par ^= par >> 4; par ^= par >> 2; par ^= par >> 1;
    if (par & 1)
        w |= 0x8000;           /* even parity over the 16 bits */
    return w;
}

/* ---- SPI slaves (MAX6675 x2 on the absorber, AS5048A on the axis) -------------------- */
static void cs_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
    model_t *m = (model_t *)param;
    int chip = irq->irq == 1 ? 0 : 1;    /* PB1 -> 0 (inlet), PB2 -> 1 (outlet / encoder) */
    if (!value) {                        /* selected */
        m->spi_sel = chip;
        m->spi_index = 0;
        m->spi_cmd = 0;
        if (m->kind == B_ABSORBER)
            m->spi_word[chip] = m->tc_words[chip];
    } else if (m->spi_sel == chip) {
        m->spi_sel = -1;
        if (m->kind == B_AXIS && m->spi_index >= 2)   /* a whole command: queue the answer */
            m->spi_answer = (m->spi_cmd & 0x3FFF) == 0x3FFF ? as5048_angle(m) : 0;
    }
}

static void spi_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
    model_t *m = (model_t *)param;
    (void)irq;
    uint8_t out = 0xFF;
    if (m->spi_sel >= 0) {
        uint16_t word = m->kind == B_ABSORBER ? m->spi_word[m->spi_sel] : m->spi_answer;
        if (m->kind == B_AXIS && m->spi_sel != 1)
            word = 0xFFFF;
        out = m->spi_index == 0 ? (uint8_t)(word >> 8) : (m->spi_index == 1 ? (uint8_t)word : 0);
        m->spi_cmd = (uint16_t)((m->spi_cmd << 8) | (value & 0xFF));
        m->spi_index++;
        if (m->spi_index == 2)
            m->spi_reads++;
    }
    avr_raise_irq(avr_io_getirq(m->avr, AVR_IOCTL_SPI_GETIRQ(0), SPI_IRQ_INPUT), out);
}

/* ---- absorber switches ---------------------------------------------------------------- */
static void sw_apply(model_t *m, uint8_t bits)
{
    m->sw_bits = bits;
    for (int i = 0; i < 5; i++)
        pin_drive(m, 'D', 2 + i, !((bits >> i) & 1));   /* D2..D6, closed = low */
}

static avr_cycle_count_t sw_timer(avr_t *avr, avr_cycle_count_t when, void *param)
{
    model_t *m = (model_t *)param;
    (void)avr;
    if (m->sw_i >= m->sw_n)
        return 0;
    sw_apply(m, m->sw_seq[m->sw_i++]);
    return m->sw_i < m->sw_n ? when + F_CPU_HZ / 500 : 0;     /* 2 ms apart */
}

/* ---- pulse input (cup anemometer) ------------------------------------------------------ */
/* A square wave at pulse_hz on the pin: each period one falling edge (a reed contact
 * closing to GND once per turn of the cups). */
static int pulse_pin_port(int pin, char *port, int *bit)
{
    if (pin == 7) { *port = 'D'; *bit = 7; return 1; }
    if (pin == 8) { *port = 'B'; *bit = 0; return 1; }
    if (pin == 11) { *port = 'B'; *bit = 3; return 1; }
    return 0;
}

void model_set_pulse_pin_addr(model_t *m, uint32_t addr) { m->pulse_pin_addr = addr; }

static avr_cycle_count_t pulse_timer(avr_t *avr, avr_cycle_count_t when, void *param)
{
    model_t *m = (model_t *)param;
    if (!(m->pulse_hz > 0)) {
        m->pulse_running = 0;
        return 0;
    }
    if (m->pulse_follow && m->pulse_pin_addr) {
        char port;
        int bit;
        int pin = avr->data[m->pulse_pin_addr & 0xFFFF];
        if (pulse_pin_port(pin, &port, &bit) && (port != m->pulse_port || bit != m->pulse_bit)) {
            if (m->pulse_port)
                pin_drive(m, m->pulse_port, m->pulse_bit, 1);
            m->pulse_port = port;
            m->pulse_bit = bit;
            m->pulse_level = 1;
        }
    }
    avr_cycle_count_t half = (avr_cycle_count_t)(F_CPU_HZ / (2.0 * m->pulse_hz));
    if (!m->pulse_port)
        return when + (half ? half : 1);           /* no pin yet: keep time */
    m->pulse_level = !m->pulse_level;
    if (!m->pulse_level)
        m->pulses_sent++;
    pin_drive(m, m->pulse_port, m->pulse_bit, m->pulse_level);
    return when + (half ? half : 1);
}

/* ---- VEML7700 -------------------------------------------------------------------------- */
static const double VEML_GAIN[4] = {1.0, 2.0, 0.125, 0.25};

static double veml_it_s(uint16_t conf)
{
    switch ((conf >> 6) & 0xF) {
    case 0xC: return 0.025;
    case 0x8: return 0.050;
    case 0x0: return 0.100;
    case 0x1: return 0.200;
    case 0x2: return 0.400;
    case 0x3: return 0.800;
    default: return 0.100;
    }
}

static void veml_update(model_t *m)
{
    if (m->veml_conf & 1)            /* shut down */
        return;
    uint64_t now = model_total_cycles(m->avr);
    double it = veml_it_s(m->veml_conf);
    uint64_t period = (uint64_t)(it * F_CPU_HZ);
    if (now - m->veml_start < period)
        return;                      /* the first integration with this setting runs */
    m->veml_start += (now - m->veml_start) / period * period;
    double res = 0.0036 * (2.0 / VEML_GAIN[(m->veml_conf >> 11) & 3]) * (0.8 / it);
    double c = m->lux > 0 ? floor(m->lux / res + 0.5) : 0;
    m->veml_als = c > 65535 ? 65535 : (uint16_t)c;
}

static void twi_hook(struct avr_irq_t *irq, uint32_t value, void *param)
{
    model_t *m = (model_t *)param;
    (void)irq;
    avr_twi_msg_irq_t v;
    v.u.v = value;
    if (v.u.twi.msg & TWI_COND_STOP) {
        if (m->twi_selected)
            m->twi_transactions++;
        m->twi_selected = 0;
    }
    if (v.u.twi.msg & TWI_COND_START) {
        m->twi_selected = 0;
        m->twi_index = 0;
        if ((v.u.twi.addr >> 1) == 0x10) {
            m->twi_selected = v.u.twi.addr;
            avr_raise_irq(m->twi_irq + TWI_IRQ_INPUT, avr_twi_irq_msg(TWI_COND_ACK, m->twi_selected, 1));
        }
    }
    if (!m->twi_selected)
        return;
    if (v.u.twi.msg & TWI_COND_WRITE) {
        avr_raise_irq(m->twi_irq + TWI_IRQ_INPUT, avr_twi_irq_msg(TWI_COND_ACK, m->twi_selected, 1));
        uint8_t d = v.u.twi.data;
        if (m->twi_index == 0)
            m->twi_reg = d;
        else if (m->twi_reg == 0x00 && m->twi_index == 1)
            m->veml_conf = (uint16_t)((m->veml_conf & 0xFF00) | d);
        else if (m->twi_reg == 0x00 && m->twi_index == 2) {
            m->veml_conf = (uint16_t)((m->veml_conf & 0x00FF) | ((uint16_t)d << 8));
            m->veml_start = model_total_cycles(m->avr);   /* a new integration starts */
        }
        m->twi_index++;
    }
    if (v.u.twi.msg & TWI_COND_READ) {
        uint16_t r = 0;
        if (m->twi_reg == 0x04) {
            veml_update(m);
            r = m->veml_als;
        } else if (m->twi_reg == 0x00)
            r = m->veml_conf;
        else if (m->twi_reg == 0x07)
            r = 0x0081;                   /* device id */
        int byte = m->twi_index++ & 1;
        uint8_t d = byte == 0 ? (uint8_t)r : (uint8_t)(r >> 8);
        avr_raise_irq(m->twi_irq + TWI_IRQ_INPUT, avr_twi_irq_msg(TWI_COND_READ, m->twi_selected, d));
    }
}

/* ---- NEO-6 ------------------------------------------------------------------------------ */
#define BIT_CYCLES ((double)F_CPU_HZ / 9600.0)

static avr_cycle_count_t uart_bit_timer(avr_t *avr, avr_cycle_count_t when, void *param)
{
    model_t *m = (model_t *)param;
    (void)avr;
    if (m->bit < 0) {
        if (m->nmea_pos >= m->nmea_len)
            return 0;                         /* idle: restarted when bytes arrive */
        m->bit = 0;
    }
    uint8_t byte = m->nmea[m->nmea_pos];
    int level = m->bit == 0 ? 0 : (m->bit <= 8 ? (byte >> (m->bit - 1)) & 1 : 1);
    pin_drive(m, 'B', 0, level);
    if (++m->bit > 9) {
        m->bit = -1;
        m->nmea_pos++;
        m->nmea_sent++;
        if (m->nmea_pos == m->nmea_len)
            m->nmea_pos = m->nmea_len = 0;
    }
    m->bit_phase += BIT_CYCLES;
    avr_cycle_count_t step = (avr_cycle_count_t)m->bit_phase;
    m->bit_phase -= (double)step;
    return when + step;
}

static void nmea_queue(model_t *m, const uint8_t *data, size_t n)
{
    if (m->nmea_len + n > m->nmea_cap) {
        m->nmea_cap = (m->nmea_len + n) * 2;
        m->nmea = realloc(m->nmea, m->nmea_cap);
    }
    memcpy(m->nmea + m->nmea_len, data, n);
    m->nmea_len += n;
    if (m->bit < 0 && avr_cycle_timer_status(m->avr, uart_bit_timer, m) == 0)
        avr_cycle_timer_register(m->avr, 1, uart_bit_timer, m);
}

/* ---- construction ------------------------------------------------------------------------ */
model_t *model_create(avr_t *avr, enum board_kind kind, mech_t *mech)
{
    model_t *m = calloc(1, sizeof(*m));
    m->avr = avr;
    m->kind = kind;
    m->mech = mech;
    m->ext[0].port = 'B';
    m->ext[1].port = 'D';
    m->spi_sel = -1;
    m->bit = -1;
    m->tc_words[0] = m->tc_words[1] = (uint16_t)((25 * 4) << 3);    /* 25 degC */
    if (kind == B_AXIS) {
        avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('D'), 3), step_hook, m);
        pin_drive(m, 'D', 6, 1);                  /* driver fault line inactive */
        axis_update_switches(m, 1);
        if (mech->has_sensor) {
            avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('B'), 2), cs_hook, m);
            avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_SPI_GETIRQ(0), SPI_IRQ_OUTPUT), spi_hook, m);
        }
    } else if (kind == B_ABSORBER) {
        avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('B'), 1), cs_hook, m);
        avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('B'), 2), cs_hook, m);
        avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_SPI_GETIRQ(0), SPI_IRQ_OUTPUT), spi_hook, m);
        sw_apply(m, 0);
    } else if (kind == B_IRRADIANCE) {
        static const char *names[2] = {"8>veml.out", "32<veml.in"};
        m->twi_irq = avr_alloc_irq(&avr->irq_pool, 0, 2, names);
        avr_irq_register_notify(m->twi_irq + TWI_IRQ_OUTPUT, twi_hook, m);
        avr_connect_irq(m->twi_irq + TWI_IRQ_INPUT, avr_io_getirq(avr, AVR_IOCTL_TWI_GETIRQ(0), TWI_IRQ_INPUT));
        avr_connect_irq(avr_io_getirq(avr, AVR_IOCTL_TWI_GETIRQ(0), TWI_IRQ_OUTPUT), m->twi_irq + TWI_IRQ_OUTPUT);
        m->veml_conf = 0x0001;                   /* power-on default: shut down */
    } else if (kind == B_GPS) {
        pin_drive(m, 'B', 0, 1);                 /* UART idle high */
    } else if (kind == B_ACTUATOR) {
        avr->vcc = avr->avcc = avr->aref = 5000;
        double d = mech->mount, r = mech->lever, g = mech->mount_angle + mech->angle;
        mech->length = sqrt(d * d + r * r - 2.0 * d * r * cos(g));
        avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_ADC_GETIRQ, ADC_IRQ_OUT_TRIGGER), adc_trigger_hook, m);
        avr_cycle_timer_register(avr, F_CPU_HZ / 1000, act_timer, m);
    }
    return m;
}

void model_after_reset(model_t *m)
{
    pins_reapply(m);
    m->spi_sel = -1;
    if (m->kind == B_GPS && m->nmea_len) {
        m->bit = -1;
        avr_cycle_timer_register(m->avr, 1, uart_bit_timer, m);
    }
    if (m->kind == B_ABSORBER && m->sw_i < m->sw_n)
        avr_cycle_timer_register(m->avr, 1, sw_timer, m);
    if (m->kind == B_ACTUATOR)
        avr_cycle_timer_register(m->avr, F_CPU_HZ / 1000, act_timer, m);
    m->pulse_running = 0;                        /* the reset dropped the cycle timers */
    if (m->kind == B_ABSORBER && m->pulse_hz > 0) {
        avr_cycle_timer_register(m->avr, 1, pulse_timer, m);
        m->pulse_running = 1;
    }
}

static int hexval(int c)
{
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
}

int model_command(model_t *m, const char *line, char *reply, size_t n)
{
    char word[32];
    int used = 0;
    if (sscanf(line, "%31s %n", word, &used) != 1)
        return -1;
    const char *args = line + used;
    if (!strcmp(word, "stall") && (m->kind == B_AXIS || m->kind == B_ACTUATOR)) {
        m->mech->stalled = atoi(args);
        return 0;
    }
    if (!strcmp(word, "driver_fault") && m->kind == B_AXIS) {
        pin_drive(m, 'D', 6, !atoi(args));   /* /DRIVER_FAULT low = fault */
        return 0;
    }
    if (!strcmp(word, "set_angle") && m->kind == B_AXIS) {
        m->mech->angle = atof(args);        /* [rad] */
        axis_update_switches(m, 0);
        return 0;
    }
    if (!strcmp(word, "temps") && m->kind == B_ABSORBER) {
        unsigned a, b;
        if (sscanf(args, "%u %u", &a, &b) != 2) {
            snprintf(reply, n, "temps: two MAX6675 words");
            return 1;
        }
        m->tc_words[0] = (uint16_t)a;
        m->tc_words[1] = (uint16_t)b;
        return 0;
    }
    if (!strcmp(word, "switches") && m->kind == B_ABSORBER) {
        /* one or more bit patterns applied 2 ms apart (contact bounce) */
        int k = 0, off = 0;
        unsigned v;
        while (k < 16 && sscanf(args + off, "%u%n", &v, &used) == 1) {
            m->sw_seq[k++] = (uint8_t)(v & 0x1F);
            off += used;
        }
        if (!k) {
            snprintf(reply, n, "switches: bit patterns");
            return 1;
        }
        m->sw_n = k;
        m->sw_i = 0;
        avr_cycle_timer_cancel(m->avr, sw_timer, m);
        sw_timer(m->avr, m->avr->cycle, m);
        if (m->sw_i < m->sw_n)
            avr_cycle_timer_register(m->avr, F_CPU_HZ / 500, sw_timer, m);
        return 0;
    }
    if (!strcmp(word, "pulses") && m->kind == B_ABSORBER) {
        /* pulses HZ [PIN]: a square wave of HZ on Arduino pin PIN (7, 8 or 11); without
         * PIN on the pin the firmware counts on (SET_PULSE_INPUT). A new HZ on a running
         * wave keeps its phase (the next edge comes at the new half period): restarting
         * it at every command (the sim sends one with every thermocouple sample, 4 Hz)
         * added up to one edge per command */
        double hz;
        int pin = -1, k = sscanf(args, "%lf %d", &hz, &pin);
        char port = 0;
        int bit = 0;
        if (k < 1 || !(hz >= 0 && hz <= 2000) || (k == 2 && !pulse_pin_port(pin, &port, &bit))) {
            snprintf(reply, n, "pulses: HZ (0..2000) [PIN (7, 8 or 11)]");
            return 1;
        }
        m->pulse_follow = k == 1;
        if (k == 2 && (port != m->pulse_port || bit != m->pulse_bit)) {
            avr_cycle_timer_cancel(m->avr, pulse_timer, m);    /* another pin: start again */
            m->pulse_running = 0;
            if (m->pulse_port)
                pin_drive(m, m->pulse_port, m->pulse_bit, 1);
            m->pulse_port = port;
            m->pulse_bit = bit;
            m->pulse_level = 0;
        }
        if (m->pulse_port && !m->pulse_level && !m->pulse_running) {
            m->pulse_level = 1;
            pin_drive(m, m->pulse_port, m->pulse_bit, 1);
        }
        m->pulse_hz = hz;
        if (hz > 0 && !m->pulse_running) {
            avr_cycle_timer_register(m->avr, (avr_cycle_count_t)(F_CPU_HZ / (2.0 * hz)) + 1, pulse_timer, m);
            m->pulse_running = 1;
        }
        return 0;
    }
    if (!strcmp(word, "lux") && m->kind == B_IRRADIANCE) {
        m->lux = atof(args);
        return 0;
    }
    if (!strcmp(word, "nmea") && m->kind == B_GPS) {
        size_t len = strlen(args);
        uint8_t *buf = malloc(len / 2 + 1);
        size_t k = 0;
        for (size_t i = 0; i + 1 < len; i += 2) {
            int hi = hexval(args[i]), lo = hexval(args[i + 1]);
            if (hi < 0 || lo < 0)
                break;
            buf[k++] = (uint8_t)(hi << 4 | lo);
        }
        nmea_queue(m, buf, k);
        free(buf);
        return 0;
    }
    return -1;
}

void model_status_json(model_t *m, FILE *out)
{
    if (m->kind == B_AXIS) {
        mech_t *k = m->mech;
        fprintf(out, ",\"angle\":%.9f,\"stalled\":%s,\"model_steps\":%lld,\"limit_bits\":%u,"
                "\"last_step_s\":%.6f", k->angle, k->stalled ? "true" : "false",
                (long long)k->steps, m->limit_bits, k->last_step_cycle / (double)F_CPU_HZ);
    } else if (m->kind == B_ABSORBER) {
        fprintf(out, ",\"switch_bits\":%u,\"words\":[%u,%u],\"spi_reads\":%u,\"pulse_hz\":%.6f,"
                "\"pulses_sent\":%llu", m->sw_bits, m->tc_words[0], m->tc_words[1], m->spi_reads,
                m->pulse_hz, (unsigned long long)m->pulses_sent);
    } else if (m->kind == B_IRRADIANCE) {
        fprintf(out, ",\"lux\":%.3f,\"veml_conf\":%u,\"twi_transactions\":%u", m->lux, m->veml_conf,
                m->twi_transactions);
    } else if (m->kind == B_ACTUATOR) {
        mech_t *k = m->mech;
        fprintf(out, ",\"angle\":%.9f,\"length\":%.9f,\"duty\":%.4f,\"stalled\":%s", k->angle, k->length,
                k->duty, k->stalled ? "true" : "false");
    } else if (m->kind == B_GPS) {
        fprintf(out, ",\"nmea_sent\":%llu,\"nmea_queued\":%zu", (unsigned long long)m->nmea_sent,
                m->nmea_len - m->nmea_pos);
    }
}
