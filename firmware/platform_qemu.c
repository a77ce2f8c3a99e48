/* Platform of the emulated firmware image (QEMU mps2-an500 / mps2-an386).
 *
 * Output and exit are Arm semihosting calls (bkpt 0xAB; QEMU runs with
 * -semihosting-config enable=on): SYS_WRITE0 writes a string to the host's stdout,
 * SYS_EXIT_EXTENDED ends QEMU with the program's status, SYS_GET_CMDLINE reads the command
 * line. They are issued here directly:
 * newlib's librdimon implements the same calls, but its system-call object pulls in
 * newlib's stdio initialisation and with it malloc, which this image must not contain.
 * The tick counter is the board's CMSDK APB timer 0 (0x40000000), a 32-bit down-counter on
 * the 25 MHz system clock. The stack is painted with a pattern and scanned for the lowest
 * word that changed. errno is one static int (__errno below). */
#include "platform.h"

extern uint32_t __stack_limit__[], __stack_top__[];

#define FW_TIMER0_CTRL (*(volatile uint32_t *)0x40000000u)
#define FW_TIMER0_VALUE (*(volatile uint32_t *)0x40000004u)
#define FW_TIMER0_RELOAD (*(volatile uint32_t *)0x40000008u)
#define FW_STACK_PATTERN 0xC5C5C5C5u

#define FW_SYS_WRITE0 0x04u
#define FW_SYS_GET_CMDLINE 0x15u
#define FW_SYS_EXIT_EXTENDED 0x20u
#define FW_ADP_STOPPED_APPLICATION_EXIT 0x20026u

static uint32_t fw_semihost(uint32_t op, const void *arg)
{
    register uint32_t r0 __asm__("r0") = op;
    register const void *r1 __asm__("r1") = arg;
    __asm__ volatile("bkpt 0xab" : "+r"(r0) : "r"(r1) : "memory");
    return r0;
}

void fw_platform_init(void)
{
    FW_TIMER0_CTRL = 0u;
    FW_TIMER0_RELOAD = 0xFFFFFFFFu;
    FW_TIMER0_VALUE = 0xFFFFFFFFu;
    FW_TIMER0_CTRL = 1u; /* enable, system clock, no interrupt */
}

void fw_write(const char *buf, int n)
{
    char chunk[129];
    while (n > 0) {
        int i, m = n < 128 ? n : 128;
        for (i = 0; i < m; ++i) {
            chunk[i] = buf[i];
        }
        chunk[m] = '\0';
        fw_semihost(FW_SYS_WRITE0, chunk);
        buf += m;
        n -= m;
    }
}

void fw_puts(const char *s)
{
    fw_semihost(FW_SYS_WRITE0, s);
}

void fw_exit(int status)
{
    uint32_t block[2];
    block[0] = FW_ADP_STOPPED_APPLICATION_EXIT;
    block[1] = (uint32_t)status;
    fw_semihost(FW_SYS_EXIT_EXTENDED, block);
}

int fw_has_ticks(void)
{
    return 1;
}

uint32_t fw_ticks(void)
{
    return 0xFFFFFFFFu - FW_TIMER0_VALUE;
}

uint32_t fw_calibration_ticks(void)
{
    /* FW_CALIBRATION_INSTRUCTIONS / 2 turns of a two-instruction loop */
    register uint32_t n __asm__("r0") = FW_CALIBRATION_INSTRUCTIONS / 2u;
    uint32_t t0 = fw_ticks(), t1;
    __asm__ volatile("1:\n\tsubs %0, %0, #1\n\tbne 1b" : "+r"(n) : : "cc");
    t1 = fw_ticks();
    return t1 - t0;
}

__attribute__((noinline)) uint32_t fw_stack_paint(void)
{
    uint32_t sp, *p;
    __asm__ volatile("mov %0, sp" : "=r"(sp));
    /* leave this function's own frame (and a margin) untouched */
    for (p = __stack_limit__; (uint32_t)(uintptr_t)p < sp - 64u; ++p) {
        *p = FW_STACK_PATTERN;
    }
    return sp;
}

uint32_t fw_stack_lowest(void)
{
    const uint32_t *p = __stack_limit__;
    while (p < __stack_top__ && *p == FW_STACK_PATTERN) {
        ++p;
    }
    return (uint32_t)(uintptr_t)p;
}

int fw_command_line(char *buf, int n)
{
    uint32_t block[2];
    if (n < 2) {
        return -1;
    }
    block[0] = (uint32_t)(uintptr_t)buf;
    block[1] = (uint32_t)(n - 1);
    buf[0] = '\0';
    if (fw_semihost(FW_SYS_GET_CMDLINE, block) != 0u) {
        buf[0] = '\0';
        return -1;
    }
    buf[block[1] < (uint32_t)(n - 1) ? block[1] : (uint32_t)(n - 1)] = '\0';
    return 0;
}

/* errno of the C library for a program with one thread: newlib's own __errno keeps it in its
 * re-entrancy struct (1 064 B of .data, linked only for it: the math functions' error paths,
 * such as cosf of an infinity, set errno). bench/issue23/measurements.md section 29. */
int *__errno(void);
int *__errno(void)
{
    static int fw_errno;
    return &fw_errno;
}
