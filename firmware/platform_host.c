/* Platform of the host build of the firmware program (the reference its emulated output is
 * compared with): stdout and exit, no tick counter, no stack measurement. */
#include <stdio.h>
#include <stdlib.h>

#include "platform.h"

void fw_platform_init(void)
{
}

void fw_write(const char *buf, int n)
{
    fwrite(buf, 1, (size_t)n, stdout);
}

void fw_puts(const char *s)
{
    int n = 0;
    while (s[n]) {
        ++n;
    }
    fw_write(s, n);
}

void fw_exit(int status)
{
    fflush(stdout);
    exit(status);
}

int fw_has_ticks(void)
{
    return 0;
}

uint32_t fw_ticks(void)
{
    return 0u;
}

uint32_t fw_calibration_ticks(void)
{
    return 0u;
}

uint32_t fw_stack_paint(void)
{
    return 0u;
}

uint32_t fw_stack_lowest(void)
{
    return 0u;
}

int fw_command_line(char *buf, int n)
{
    const char *s = getenv("FW_COMMAND_LINE");
    int i = 0;
    if (n < 1) {
        return -1;
    }
    while (s && s[i] && i < n - 1) {
        buf[i] = s[i];
        ++i;
    }
    buf[i] = '\0';
    return s ? 0 : -1;
}
