/*
 * pcr stepper firmware: ATmega328P (Arduino Uno) at 16 MHz driving three 28BYJ-48 steppers
 * through ULN2003 boards, commanded over UART0 at 115200 baud (protocol: driver/PROTOCOL.md).
 *
 * Pin map (IN1..IN4 of each ULN2003 board, full-step two-phase sequence):
 *   motor 0: PD4..PD7 (Uno D4..D7)
 *   motor 1: PB0..PB3 (Uno D8..D11)
 *   motor 2: PC0..PC3 (Uno A0..A3)
 *   UART:    PD0 RX, PD1 TX (USB serial)
 *
 * Timing: Timer1 in CTC mode interrupts at 10 kHz (one "tick" = 100 us). Each accepted setpoint
 * starts a segment of cycle_ms (default 20 ms = 200 ticks); a per-motor DDA spreads the
 * segment's |delta| steps evenly over the ticks so that all motors finish together at the end
 * of the segment. |delta| is clamped to max_rate * cycle_ms / 1000 steps (rate limit); when a
 * target was clamped, further segments follow until it is reached. The main loop only parses
 * frames and sleeps; no busy delay anywhere in the control path.
 *
 * Watchdogs: (1) host silence: no valid setpoint for watchdog_ms while streaming stops the
 * motors and latches a fault (cleared by CLEAR_FAULT); (2) the AVR hardware watchdog (250 ms)
 * resets a hung firmware.
 */
#include <avr/interrupt.h>
#include <avr/io.h>
#include <avr/sleep.h>
#include <avr/wdt.h>
#include <stdint.h>
#include <string.h>

#include "protocol.h"

#define FW_MAJOR 1
#define FW_MINOR 0
#define FW_PATCH 0

#define N_MOTORS 3
#define TICK_HZ 10000u
#define TICKS_PER_MS (TICK_HZ / 1000u)

/* ------------------------------------------------------------------ coils */

/* full-step, two phases on: IN1..IN4 bit patterns */
static const uint8_t SEQ[4] = {0x03, 0x06, 0x0C, 0x09};

static inline void coils_write(uint8_t m, uint8_t pat)
{
	switch (m) {
	case 0:
		PORTD = (PORTD & 0x0F) | (uint8_t)(pat << 4);
		break;
	case 1:
		PORTB = (PORTB & 0xF0) | pat;
		break;
	default:
		PORTC = (PORTC & 0xF0) | pat;
		break;
	}
}

/* ------------------------------------------------------------------ state */

typedef struct {
	int32_t pos;      /* actual position, steps */
	int32_t target;   /* host target, steps */
	uint16_t n;       /* steps in the current segment */
	uint16_t done;    /* steps done in the current segment */
	uint16_t acc;     /* DDA accumulator */
	int8_t dir;       /* +1 / -1 */
	uint8_t phase;    /* index into SEQ */
} motor_t;

static volatile motor_t motors[N_MOTORS];

/* configuration */
static uint16_t cfg_max_rate = DEFAULT_MAX_RATE;
static volatile uint16_t cfg_watchdog_ms = DEFAULT_WATCHDOG_MS;
static volatile uint16_t cfg_idle_off_ms = DEFAULT_IDLE_OFF_MS;
static int32_t cfg_pos_min = DEFAULT_POS_MIN;
static int32_t cfg_pos_max = DEFAULT_POS_MAX;
static uint8_t cfg_cycle_ms = DEFAULT_CYCLE_MS;
static volatile uint16_t seg_ticks = DEFAULT_CYCLE_MS * TICKS_PER_MS;
static volatile uint16_t max_seg_steps = (uint32_t)DEFAULT_MAX_RATE * DEFAULT_CYCLE_MS / 1000u;

/* runtime */
static volatile uint8_t seg_active;
static volatile uint16_t seg_tick;
static volatile uint8_t sub_ms;          /* ticks within the current ms */
static volatile uint16_t since_sp_ms;    /* ms since the last accepted setpoint */
static volatile uint16_t idle_ms;        /* ms since motion stopped */
static volatile uint8_t wd_armed;        /* host watchdog armed (streaming) */
static volatile uint8_t status_flags;    /* FLAG_ENABLED | LIMITED | WATCHDOG | FAULT | WDT_RESET */
static volatile uint8_t coils_on;
static uint8_t have_seq, last_seq;
static uint8_t reset_cause;

/* counters (wrapping) */
static uint16_t c_rx_frames, c_crc, c_framing, c_seq, c_range;
static volatile uint16_t c_rate_limited, c_watchdog, c_rx_overflow;
static uint8_t c_other; /* unknown type, bad length */

/* ------------------------------------------------------------------ motion (ISR context) */

static void coils_energise(void)
{
	for (uint8_t m = 0; m < N_MOTORS; m++)
		coils_write(m, SEQ[motors[m].phase]);
	coils_on = 1;
}

static void coils_release(void)
{
	for (uint8_t m = 0; m < N_MOTORS; m++)
		coils_write(m, 0);
	coils_on = 0;
}

/* Plans one segment towards the targets; call with interrupts disabled. */
static void plan_segment(void)
{
	uint8_t moving = 0, limited = 0;
	for (uint8_t m = 0; m < N_MOTORS; m++) {
		volatile motor_t *mo = &motors[m];
		int32_t d = mo->target - mo->pos;
		int8_t dir = 1;
		if (d < 0) {
			dir = -1;
			d = -d;
		}
		if (d > (int32_t)max_seg_steps) {
			d = max_seg_steps;
			limited = 1;
		}
		mo->n = (uint16_t)d;
		mo->dir = dir;
		mo->done = 0;
		mo->acc = 0;
		if (d)
			moving = 1;
	}
	seg_tick = 0;
	seg_active = moving;
	if (limited) {
		status_flags |= FLAG_LIMITED;
		c_rate_limited++;
	} else {
		status_flags &= ~FLAG_LIMITED;
	}
	if (moving) {
		idle_ms = 0;
		if (!coils_on)
			coils_energise();
	}
}

/* Stops where the motors are: target = position. Interrupts disabled. */
static void stop_here(void)
{
	for (uint8_t m = 0; m < N_MOTORS; m++) {
		motors[m].target = motors[m].pos;
		motors[m].n = 0;
	}
	seg_active = 0;
	status_flags &= ~FLAG_LIMITED;
}

ISR(TIMER1_COMPA_vect)
{
	if (seg_active) {
		uint16_t T = seg_ticks;
		for (uint8_t m = 0; m < N_MOTORS; m++) {
			volatile motor_t *mo = &motors[m];
			if (mo->done >= mo->n)
				continue;
			mo->acc += mo->n;
			if (mo->acc >= T) {
				mo->acc -= T;
				mo->done++;
				mo->pos += mo->dir;
				mo->phase = (uint8_t)(mo->phase + mo->dir) & 3;
				coils_write(m, SEQ[mo->phase]);
			}
		}
		if (++seg_tick >= T) {
			/* segment over: every motor has done exactly n steps */
			plan_segment(); /* continues towards a clamped target, or goes idle */
		}
	}
	if (++sub_ms >= TICKS_PER_MS) {
		sub_ms = 0;
		if (since_sp_ms != 0xFFFF)
			since_sp_ms++;
		if (!seg_active) {
			if (idle_ms != 0xFFFF)
				idle_ms++;
			if (cfg_idle_off_ms && coils_on && idle_ms >= cfg_idle_off_ms)
				coils_release();
		}
		if (wd_armed && cfg_watchdog_ms && since_sp_ms >= cfg_watchdog_ms) {
			wd_armed = 0;
			stop_here();
			status_flags |= FLAG_WATCHDOG | FLAG_FAULT;
			c_watchdog++;
		}
	}
}

/* ------------------------------------------------------------------ UART */

#define RX_SIZE 128 /* power of two */
#define TX_SIZE 128
static volatile uint8_t rx_buf[RX_SIZE];
static volatile uint8_t rx_head, rx_tail;
static volatile uint8_t tx_buf[TX_SIZE];
static volatile uint8_t tx_head, tx_tail;

ISR(USART_RX_vect)
{
	uint8_t b = UDR0;
	uint8_t next = (uint8_t)(rx_head + 1) & (RX_SIZE - 1);
	if (next == rx_tail) {
		c_rx_overflow++;
		return;
	}
	rx_buf[rx_head] = b;
	rx_head = next;
}

ISR(USART_UDRE_vect)
{
	if (tx_head == tx_tail) {
		UCSR0B &= ~_BV(UDRIE0);
		return;
	}
	UDR0 = tx_buf[tx_tail];
	tx_tail = (uint8_t)(tx_tail + 1) & (TX_SIZE - 1);
}

static void uart_init(void)
{
	/* 115200 baud with U2X: UBRR = 16 (2.1 % error, as the Uno bootloader) */
	UCSR0A = _BV(U2X0);
	UBRR0H = 0;
	UBRR0L = 16;
	UCSR0C = _BV(UCSZ01) | _BV(UCSZ00); /* 8N1 */
	UCSR0B = _BV(RXEN0) | _BV(TXEN0) | _BV(RXCIE0);
}

static uint8_t tx_free(void)
{
	return (uint8_t)((tx_tail - tx_head - 1) & (TX_SIZE - 1));
}

static void uart_put(uint8_t b)
{
	uint8_t next = (uint8_t)(tx_head + 1) & (TX_SIZE - 1);
	while (next == tx_tail)
		; /* only when a reply does not fit: the UDRE interrupt drains the buffer */
	tx_buf[tx_head] = b;
	tx_head = next;
	UCSR0B |= _BV(UDRIE0);
}

/* ------------------------------------------------------------------ framing */

static uint16_t crc16(const uint8_t *p, uint8_t n)
{
	uint16_t crc = 0xFFFF;
	while (n--) {
		crc ^= (uint16_t)(*p++) << 8;
		for (uint8_t i = 0; i < 8; i++)
			crc = (crc & 0x8000) ? (uint16_t)((crc << 1) ^ 0x1021) : (uint16_t)(crc << 1);
	}
	return crc;
}

static uint8_t txp[PROTO_MAX_PAYLOAD + 2];
static uint8_t txn;

static void put_u8(uint8_t v) { txp[txn++] = v; }
static void put_u16(uint16_t v)
{
	put_u8((uint8_t)v);
	put_u8((uint8_t)(v >> 8));
}
static void put_i32(int32_t v)
{
	uint32_t u = (uint32_t)v;
	for (uint8_t i = 0; i < 4; i++) {
		put_u8((uint8_t)u);
		u >>= 8;
	}
}

static void reply_begin(uint8_t type, uint8_t seq)
{
	txn = 0;
	put_u8(type);
	put_u8(seq);
}

/* appends the CRC, COBS-encodes and queues the frame with its delimiter */
static void reply_send(void)
{
	uint16_t crc = crc16(txp, txn);
	put_u16(crc);
	uint8_t code_pos = 0, code = 1;
	uint8_t out[PROTO_MAX_ENCODED];
	uint8_t o = 1;
	for (uint8_t i = 0; i < txn; i++) {
		if (txp[i] == 0) {
			out[code_pos] = code;
			code_pos = o++;
			code = 1;
		} else {
			out[o++] = txp[i];
			code++;
		}
	}
	out[code_pos] = code;
	for (uint8_t i = 0; i < o; i++)
		uart_put(out[i]);
	uart_put(0);
}

static uint8_t flags_now(void)
{
	uint8_t f = status_flags;
	if (seg_active)
		f |= FLAG_MOVING;
	if (coils_on)
		f |= FLAG_COILS_ON;
	return f;
}

static void snapshot(int32_t pos[N_MOTORS], int32_t tgt[N_MOTORS], uint8_t *fl)
{
	cli();
	for (uint8_t m = 0; m < N_MOTORS; m++) {
		pos[m] = motors[m].pos;
		tgt[m] = motors[m].target;
	}
	*fl = flags_now();
	sei();
}

static void send_state(uint8_t seq)
{
	int32_t pos[N_MOTORS], tgt[N_MOTORS];
	uint8_t fl;
	snapshot(pos, tgt, &fl);
	reply_begin(MSG_STATE, seq);
	for (uint8_t m = 0; m < N_MOTORS; m++)
		put_i32(pos[m]);
	put_u8(fl);
	put_u8((uint8_t)(c_crc + c_framing + c_seq + c_range + c_other));
	reply_send();
}

static void send_status(uint8_t seq)
{
	int32_t pos[N_MOTORS], tgt[N_MOTORS];
	uint8_t fl;
	uint16_t rl, wd, ov;
	snapshot(pos, tgt, &fl);
	cli();
	rl = c_rate_limited;
	wd = c_watchdog;
	ov = c_rx_overflow;
	sei();
	reply_begin(MSG_STATUS_REPLY, seq);
	for (uint8_t m = 0; m < N_MOTORS; m++)
		put_i32(pos[m]);
	for (uint8_t m = 0; m < N_MOTORS; m++)
		put_i32(tgt[m]);
	put_u8(fl);
	put_u16(c_rx_frames);
	put_u16(c_crc);
	put_u16(c_framing);
	put_u16(c_seq);
	put_u16(c_range);
	put_u16(rl);
	put_u16(wd);
	put_u16(ov);
	reply_send();
}

static void send_error(uint8_t seq, uint8_t code, uint8_t req_type)
{
	reply_begin(MSG_ERROR, seq);
	put_u8(code);
	put_u8(req_type);
	reply_send();
}

static void put_config(void)
{
	put_u16(cfg_max_rate);
	put_u16(cfg_watchdog_ms);
	put_u16(cfg_idle_off_ms);
	put_i32(cfg_pos_min);
	put_i32(cfg_pos_max);
	put_u8(cfg_cycle_ms);
}

static uint16_t get_u16(const uint8_t *p) { return (uint16_t)p[0] | ((uint16_t)p[1] << 8); }
static int32_t get_i32(const uint8_t *p)
{
	return (int32_t)((uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) |
			 ((uint32_t)p[3] << 24));
}

/* ------------------------------------------------------------------ commands */

static void set_enabled(uint8_t en)
{
	cli();
	if (en) {
		status_flags |= FLAG_ENABLED;
		coils_energise();
		idle_ms = 0;
	} else {
		stop_here();
		status_flags &= ~FLAG_ENABLED;
		coils_release();
		wd_armed = 0;
	}
	sei();
}

static void on_setpoint(uint8_t seq, const uint8_t *b)
{
	if (status_flags & FLAG_FAULT) {
		send_error(seq, ERR_FAULT, MSG_SETPOINT);
		return;
	}
	if (have_seq && (int8_t)(uint8_t)(seq - last_seq) <= 0) {
		c_seq++;
		send_error(seq, ERR_SEQUENCE, MSG_SETPOINT);
		return;
	}
	int32_t tgt[N_MOTORS];
	for (uint8_t m = 0; m < N_MOTORS; m++) {
		tgt[m] = get_i32(b + 1 + 4 * m);
		if (tgt[m] < cfg_pos_min || tgt[m] > cfg_pos_max) {
			c_range++;
			send_error(seq, ERR_RANGE, MSG_SETPOINT);
			return;
		}
	}
	have_seq = 1;
	last_seq = seq;
	if (!(b[0] & 1)) {
		set_enabled(0);
	} else {
		cli();
		if (status_flags & FLAG_FAULT) {
			/* the host watchdog tripped between the check above and here */
			sei();
			send_error(seq, ERR_FAULT, MSG_SETPOINT);
			return;
		}
		if (!(status_flags & FLAG_ENABLED)) {
			status_flags |= FLAG_ENABLED;
			coils_energise();
		}
		uint8_t changed = 0;
		for (uint8_t m = 0; m < N_MOTORS; m++) {
			if (motors[m].target != tgt[m])
				changed = 1;
			motors[m].target = tgt[m];
		}
		/*
		 * A new target starts a new segment from where the motors are (the rest of the
		 * current one is folded into it). An unchanged target lets the running segment
		 * finish: otherwise a host whose 20 ms comes slightly earlier than ours would defer
		 * the segment's last step forever.
		 */
		if (changed || !seg_active)
			plan_segment();
		since_sp_ms = 0;
		wd_armed = 1;
		sei();
	}
	send_state(seq);
}

static uint8_t config_valid(uint16_t rate, uint16_t wd, uint8_t cyc, int32_t lo, int32_t hi)
{
	if (rate < CFG_MAX_RATE_MIN || rate > CFG_MAX_RATE_MAX)
		return 0;
	if (cyc < CFG_CYCLE_MS_MIN || cyc > CFG_CYCLE_MS_MAX)
		return 0;
	if (lo >= hi)
		return 0;
	if (wd != 0 && wd < cyc)
		return 0;
	return 1;
}

static void dispatch(const uint8_t *p, uint8_t n)
{
	uint8_t type = p[0], seq = p[1];
	const uint8_t *b = p + 2;
	uint8_t blen = (uint8_t)(n - 2);
	int8_t want;
	switch (type) {
	case MSG_HELLO: want = LEN_HELLO; break;
	case MSG_SETPOINT: want = LEN_SETPOINT; break;
	case MSG_ZERO: want = LEN_ZERO; break;
	case MSG_ENABLE: want = LEN_ENABLE; break;
	case MSG_CONFIG: want = LEN_CONFIG; break;
	case MSG_STATUS: want = LEN_STATUS; break;
	case MSG_CLEAR_FAULT: want = LEN_CLEAR_FAULT; break;
	default:
		c_other++;
		send_error(seq, ERR_UNKNOWN_TYPE, type);
		return;
	}
	if (blen != (uint8_t)want) {
		c_other++;
		send_error(seq, ERR_BAD_LENGTH, type);
		return;
	}
	c_rx_frames++;
	switch (type) {
	case MSG_HELLO:
		if (b[0] != PROTO_VERSION) {
			send_error(seq, ERR_VERSION, type);
			return;
		}
		have_seq = 0;
		reply_begin(MSG_HELLO_REPLY, seq);
		put_u8(PROTO_VERSION);
		put_u8(FW_MAJOR);
		put_u8(FW_MINOR);
		put_u8(FW_PATCH);
		put_u8(N_MOTORS);
		put_u8(reset_cause);
		put_config();
		reply_send();
		break;
	case MSG_SETPOINT:
		on_setpoint(seq, b);
		break;
	case MSG_ZERO:
		cli();
		if (seg_active) {
			sei();
			send_error(seq, ERR_BUSY, type);
			return;
		}
		for (uint8_t m = 0; m < N_MOTORS; m++) {
			if (b[0] & (1 << m)) {
				int32_t v = get_i32(b + 1 + 4 * m);
				motors[m].pos = v;
				motors[m].target = v;
			}
		}
		sei();
		send_state(seq);
		break;
	case MSG_ENABLE:
		set_enabled(b[0] & 1);
		send_state(seq);
		break;
	case MSG_CONFIG: {
		uint16_t rate = get_u16(b), wd = get_u16(b + 2), idle = get_u16(b + 4);
		int32_t lo = get_i32(b + 6), hi = get_i32(b + 10);
		uint8_t cyc = b[14];
		if (!config_valid(rate, wd, cyc, lo, hi)) {
			send_error(seq, ERR_BAD_CONFIG, type);
			return;
		}
		cli();
		if (seg_active) {
			sei();
			send_error(seq, ERR_BUSY, type);
			return;
		}
		cfg_max_rate = rate;
		cfg_watchdog_ms = wd;
		cfg_idle_off_ms = idle;
		cfg_pos_min = lo;
		cfg_pos_max = hi;
		cfg_cycle_ms = cyc;
		seg_ticks = (uint16_t)cyc * TICKS_PER_MS;
		max_seg_steps = (uint16_t)((uint32_t)rate * cyc / 1000u);
		sei();
		send_state(seq);
		break;
	}
	case MSG_STATUS:
		send_status(seq);
		break;
	case MSG_CLEAR_FAULT:
		cli();
		stop_here();
		status_flags &= ~(FLAG_FAULT | FLAG_WATCHDOG | FLAG_WDT_RESET);
		wd_armed = 0;
		sei();
		have_seq = 0;
		send_state(seq);
		break;
	}
}

static uint8_t rxf[PROTO_MAX_ENCODED];
static uint8_t rxn;
static uint8_t rx_overlong;

/* one complete block between delimiters */
static void on_block(void)
{
	uint8_t raw[PROTO_MAX_ENCODED];
	uint8_t n = 0, i = 0;
	if (rx_overlong) {
		c_framing++;
		return;
	}
	/* COBS decode */
	while (i < rxn) {
		uint8_t code = rxf[i];
		if (code == 0 || (uint16_t)i + code > rxn) {
			c_framing++;
			return;
		}
		for (uint8_t k = 1; k < code; k++)
			raw[n++] = rxf[i + k];
		i = (uint8_t)(i + code);
		if (code != 0xFF && i < rxn)
			raw[n++] = 0;
	}
	if (n < 4) {
		c_framing++;
		return;
	}
	uint16_t got = (uint16_t)raw[n - 2] | ((uint16_t)raw[n - 1] << 8);
	if (crc16(raw, (uint8_t)(n - 2)) != got) {
		c_crc++;
		/* only if it fits without waiting: a burst of garbage must not stall the parser
		 * (and overflow the RX ring) behind a flood of error replies */
		if (tx_free() >= 16)
			send_error(0, ERR_CRC, 0);
		return;
	}
	dispatch(raw, (uint8_t)(n - 2));
}

static void rx_byte(uint8_t b)
{
	if (b == 0) {
		if (rxn || rx_overlong)
			on_block();
		rxn = 0;
		rx_overlong = 0;
		return;
	}
	if (rxn < sizeof rxf)
		rxf[rxn++] = b;
	else
		rx_overlong = 1;
}

/* ------------------------------------------------------------------ main */

/* read and clear the reset cause before the hardware watchdog can fire again */
static uint8_t mcusr_at_boot __attribute__((section(".noinit")));
void early_init(void) __attribute__((naked, used, section(".init3")));
void early_init(void)
{
	mcusr_at_boot = MCUSR;
	MCUSR = 0;
	wdt_disable();
}

int main(void)
{
	reset_cause = mcusr_at_boot;
	if (reset_cause & _BV(WDRF))
		status_flags |= FLAG_WDT_RESET;

	DDRD |= 0xF0;
	DDRB |= 0x0F;
	DDRC |= 0x0F;
	coils_release();

	uart_init();

	/* Timer1 CTC, no prescaler, 16 MHz / 1600 = 10 kHz */
	TCCR1A = 0;
	TCCR1B = _BV(WGM12) | _BV(CS10);
	OCR1A = (F_CPU / TICK_HZ) - 1;
	TIMSK1 = _BV(OCIE1A);

	wdt_enable(WDTO_250MS);
	set_sleep_mode(SLEEP_MODE_IDLE);
	sei();

	for (;;) {
		wdt_reset();
		while (rx_tail != rx_head) {
			uint8_t b = rx_buf[rx_tail];
			rx_tail = (uint8_t)(rx_tail + 1) & (RX_SIZE - 1);
			rx_byte(b);
		}
		cli();
		if (rx_tail == rx_head) {
			sleep_enable();
			sei();
			sleep_cpu(); /* woken by the 10 kHz tick or a received byte */
			sleep_disable();
		}
		sei();
	}
}
