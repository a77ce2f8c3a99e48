/* What the firmware program needs from its platform: text output, exit, a tick counter and
 * stack measurement. platform_qemu.c implements it for the emulated MPS2 boards
 * (semihosting through newlib's librdimon, a CMSDK APB timer), platform_host.c for the host
 * build of the same program (stdout; no ticks, no stack measurement). */
#ifndef FW_PLATFORM_H
#define FW_PLATFORM_H

#include <stdint.h>

void fw_platform_init(void);
void fw_write(const char *buf, int n);
void fw_puts(const char *s);
void fw_exit(int status);
/* 1 if fw_ticks counts (the emulated boards), 0 if it always reads 0 (host) */
int fw_has_ticks(void);
/* A free-running up-counter of the 25 MHz system clock of the board. Under QEMU with
 * -icount shift=0 one instruction takes 1 ns of virtual time, so one tick is exactly
 * FW_INSTRUCTIONS_PER_TICK instructions. */
uint32_t fw_ticks(void);
#define FW_INSTRUCTIONS_PER_TICK 40u
/* Ticks of a loop of exactly FW_CALIBRATION_INSTRUCTIONS instructions (checks the above). */
uint32_t fw_calibration_ticks(void);
#define FW_CALIBRATION_INSTRUCTIONS 2000000u
/* Paint the free stack below the caller's frame; returns the stack pointer it painted up
 * to (the caller's depth). fw_stack_lowest() is the lowest address written since (0 on a
 * platform without stack measurement). */
uint32_t fw_stack_paint(void);
uint32_t fw_stack_lowest(void);
/* The program's command line into buf (at most n - 1 characters and a terminating 0):
 * QEMU's semihosting command line (-semihosting-config arg=...; without arguments the image's
 * path), on the host the environment variable FW_COMMAND_LINE (empty if unset). Returns 0,
 * or -1 (buf empty) if there is none. */
int fw_command_line(char *buf, int n);

#endif /* FW_PLATFORM_H */
