/* Minimal start-up code of the emulated firmware image (ARMv7-M: Cortex-M7 and Cortex-M4F).
 *
 * The vector table holds the initial stack pointer and the reset handler; every other
 * exception ends the program with a message (semihosting). The reset handler enables the
 * floating-point unit, copies .data from flash, zeroes .bss, paints the stack (so the
 * program can measure how deep it went), runs main (which calls fw_platform_init) and exits with its status. */
#include <stdint.h>

#include "platform.h"

extern uint32_t __data_start__[], __data_end__[], __data_load__[];
extern uint32_t __bss_start__[], __bss_end__[];
extern uint32_t __stack_limit__[], __stack_top__[];

int main(void);
void fw_reset_handler(void);
static void fw_fault_handler(void);

typedef void (*fw_vector)(void);

/* initial SP, reset, NMI, HardFault, MemManage, BusFault, UsageFault, 4 reserved, SVCall,
 * DebugMonitor, reserved, PendSV, SysTick */
__attribute__((section(".vectors"), used))
const fw_vector fw_vectors[16] = {(fw_vector)(uintptr_t)__stack_top__,
                                  fw_reset_handler,
                                  fw_fault_handler,
                                  fw_fault_handler,
                                  fw_fault_handler,
                                  fw_fault_handler,
                                  fw_fault_handler,
                                  0,
                                  0,
                                  0,
                                  0,
                                  fw_fault_handler,
                                  fw_fault_handler,
                                  0,
                                  fw_fault_handler,
                                  fw_fault_handler};

static void fw_fault_handler(void)
{
    fw_puts("firmware: fault exception\n");
    fw_exit(3);
    for (;;) {
    }
}

__attribute__((noreturn, used)) void fw_reset_handler(void)
{
    uint32_t *p, *q;
#if defined(__ARM_FP)
    /* CPACR: full access to the coprocessors CP10 and CP11 (the FPU) */
    *(volatile uint32_t *)0xE000ED88u |= (0xFu << 20);
    __asm__ volatile("dsb\n\tisb" ::: "memory");
#endif
    for (p = __data_start__, q = __data_load__; p < __data_end__; ++p, ++q) {
        *p = *q;
    }
    for (p = __bss_start__; p < __bss_end__; ++p) {
        *p = 0u;
    }
    fw_stack_paint();
    fw_exit(main());
    for (;;) {
    }
}
