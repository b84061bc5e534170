/*
 * simavr harness for the pcr stepper firmware (used by driver/tests/ and the bench).
 *
 *   pcr_sim FIRMWARE.elf [--link PATH] [--speed X]
 *
 * - loads the ELF into an ATmega328P at 16 MHz;
 * - attaches UART0 to a pseudo-terminal (simavr's uart_pty part) with the UART poll-sleep
 *   disabled, prints "PTY <slave path>" and, with --link, symlinks PATH to the slave so that a
 *   restarted harness appears at the same path (reconnect tests);
 * - watches the coil pins (PD4..PD7, PB0..PB3, PC0..PC3) through the ports' IRQs, decodes the
 *   full-step sequence and prints one line per event on stdout:
 *       S <motor> <position> <cycle>     one step, position after it
 *       C <motor> <0|1> <cycle>          coils released / energised
 *       X <motor> <old> <new> <cycle>    illegal pattern change (lost step)
 *       T <cycle> <busy cycles>          at exit: AVR time and cycles not spent asleep (CPU load)
 * - throttles the emulation so that AVR time never runs ahead of wall-clock time times X
 *   (default 1.0), so that the firmware's watchdog sees the host's real 20 ms cadence; on a busy
 *   machine the emulator may fall behind real time, which only makes the host look faster;
 * - exits when its stdin closes (the parent test died) or the AVR stops.
 */
#define _GNU_SOURCE
#include <errno.h>
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "avr_ioport.h"
#include "avr_uart.h"
#include "sim_avr.h"
#include "sim_elf.h"
#include "uart_pty.h"

static avr_t *avr;
static uart_pty_t uart_pty;
static volatile avr_cycle_count_t sleep_cycles; /* cycles spent asleep */

static const uint8_t SEQ[4] = {0x03, 0x06, 0x0C, 0x09};

typedef struct {
	int motor;
	uint8_t shift;
	uint8_t last;   /* last 4-bit pattern seen */
	int phase;      /* last energised phase index, -1 unknown */
	long pos;
} mon_t;

static mon_t mons[3] = {
	{0, 4, 0, -1, 0},
	{1, 0, 0, -1, 0},
	{2, 0, 0, -1, 0},
};

static int seq_index(uint8_t p)
{
	for (int i = 0; i < 4; i++)
		if (SEQ[i] == p)
			return i;
	return -1;
}

static void on_port(struct avr_irq_t *irq, uint32_t value, void *param)
{
	(void)irq;
	mon_t *m = param;
	uint8_t p = (uint8_t)((value >> m->shift) & 0x0F);
	if (p == m->last)
		return;
	unsigned long long cyc = (unsigned long long)avr->cycle;
	uint8_t old = m->last;
	m->last = p;
	if (p == 0) {
		printf("C %d 0 %llu\n", m->motor, cyc);
		return;
	}
	int idx = seq_index(p);
	if (idx < 0) {
		printf("X %d %u %u %llu\n", m->motor, old, p, cyc);
		return;
	}
	if (old == 0) {
		/* energised: must resume the phase it was released at */
		if (m->phase >= 0 && idx != m->phase)
			printf("X %d %u %u %llu\n", m->motor, old, p, cyc);
		m->phase = idx;
		printf("C %d 1 %llu\n", m->motor, cyc);
		return;
	}
	int d = (idx - m->phase) & 3;
	if (d == 1) {
		m->pos++;
	} else if (d == 3) {
		m->pos--;
	} else {
		printf("X %d %u %u %llu\n", m->motor, old, p, cyc);
		m->phase = idx;
		return;
	}
	m->phase = idx;
	printf("S %d %ld %llu\n", m->motor, m->pos, cyc);
}

static void *stdin_watch(void *arg)
{
	(void)arg;
	char buf[64];
	for (;;) {
		ssize_t n = read(0, buf, sizeof buf);
		if (n == 0 || (n < 0 && errno != EINTR))
			break;
	}
	printf("T %llu %llu\n", (unsigned long long)avr->cycle, (unsigned long long)(avr->cycle - sleep_cycles));
	fflush(stdout);
	_exit(0);
	return NULL;
}

/* simavr calls this when the AVR sleeps; the core then skips how_long + 1 cycles. We do not
 * sleep here (the main loop throttles) but count them to report the firmware's CPU load. */
static void no_sleep(avr_t *a, avr_cycle_count_t how_long)
{
	(void)a;
	sleep_cycles += how_long + 1;
}

static uint64_t now_ns(void)
{
	struct timespec ts;
	clock_gettime(CLOCK_MONOTONIC, &ts);
	return (uint64_t)ts.tv_sec * 1000000000ull + (uint64_t)ts.tv_nsec;
}

int main(int argc, char **argv)
{
	const char *fw = NULL, *link = NULL;
	double speed = 1.0;
	for (int i = 1; i < argc; i++) {
		if (!strcmp(argv[i], "--link") && i + 1 < argc)
			link = argv[++i];
		else if (!strcmp(argv[i], "--speed") && i + 1 < argc)
			speed = atof(argv[++i]);
		else
			fw = argv[i];
	}
	if (!fw || speed <= 0) {
		fprintf(stderr, "usage: %s FIRMWARE.elf [--link PATH] [--speed X]\n", argv[0]);
		return 2;
	}
	setvbuf(stdout, NULL, _IOLBF, 0);

	elf_firmware_t f;
	memset(&f, 0, sizeof f);
	if (elf_read_firmware(fw, &f) != 0) {
		fprintf(stderr, "cannot read %s\n", fw);
		return 1;
	}
	if (!f.mmcu[0])
		strcpy(f.mmcu, "atmega328p");
	if (!f.frequency)
		f.frequency = 16000000;
	avr = avr_make_mcu_by_name(f.mmcu);
	if (!avr) {
		fprintf(stderr, "unknown mcu %s\n", f.mmcu);
		return 1;
	}
	avr_init(avr);
	avr_load_firmware(avr, &f);
	avr->sleep = no_sleep;

	uart_pty_init(avr, &uart_pty);
	uart_pty_connect(&uart_pty, '0');
	uint32_t flags = 0;
	avr_ioctl(avr, AVR_IOCTL_UART_GET_FLAGS('0'), &flags);
	flags &= ~(uint32_t)AVR_UART_FLAG_POLL_SLEEP;
	flags &= ~(uint32_t)AVR_UART_FLAG_STDIO;
	avr_ioctl(avr, AVR_IOCTL_UART_SET_FLAGS('0'), &flags);

	avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('D'), IOPORT_IRQ_REG_PORT),
				on_port, &mons[0]);
	avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('B'), IOPORT_IRQ_REG_PORT),
				on_port, &mons[1]);
	avr_irq_register_notify(avr_io_getirq(avr, AVR_IOCTL_IOPORT_GETIRQ('C'), IOPORT_IRQ_REG_PORT),
				on_port, &mons[2]);

	if (link) {
		unlink(link);
		if (symlink(uart_pty.pty.slavename, link) != 0) {
			fprintf(stderr, "symlink %s: %s\n", link, strerror(errno));
			return 1;
		}
	}
	printf("PTY %s\n", uart_pty.pty.slavename);

	pthread_t th;
	pthread_create(&th, NULL, stdin_watch, NULL);

	const uint64_t freq = avr->frequency ? avr->frequency : 16000000;
	const avr_cycle_count_t check_every = freq / 2000; /* every 0.5 ms of AVR time */
	avr_cycle_count_t next_check = check_every;
	uint64_t t0 = now_ns();
	for (;;) {
		int st = avr_run(avr);
		if (st == cpu_Done || st == cpu_Crashed) {
			fprintf(stderr, "avr stopped (state %d)\n", st);
			break;
		}
		if (avr->cycle >= next_check) {
			next_check = avr->cycle + check_every;
			uint64_t avr_ns = (uint64_t)((double)avr->cycle * 1e9 / (double)freq / speed);
			uint64_t wall = now_ns() - t0;
			if (avr_ns > wall + 200000) {
				uint64_t d = avr_ns - wall;
				struct timespec ts = {(time_t)(d / 1000000000ull), (long)(d % 1000000000ull)};
				nanosleep(&ts, NULL);
			}
		}
	}
	uart_pty_stop(&uart_pty);
	return 0;
}
