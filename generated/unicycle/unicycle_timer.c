/* Phase timers: the POSIX monotonic clock behind UNICYCLE_CLOCK_POSIX. */
/* clock_gettime is POSIX, not C99: request it before any header. */
#ifndef _POSIX_C_SOURCE
#define _POSIX_C_SOURCE 199309L
#endif

#include "unicycle_timer.h"

#if UNICYCLE_CLOCK_POSIX
#include <time.h>
#endif

double unicycle_timer_default_clock(void *ctx)
{
    (void)ctx;
#if UNICYCLE_CLOCK_POSIX
    {
        struct timespec ts;
        if (clock_gettime(CLOCK_MONOTONIC, &ts) != 0) {
            return 0.0;
        }
        return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
    }
#else
    return 0.0;
#endif
}

void unicycle_timer_init(unicycle_timer *tm)
{
    int i;
    tm->clock = unicycle_timer_default_clock;
    tm->ctx = 0;
    for (i = 0; i < UNICYCLE_N_PHASES; ++i) {
        tm->t[i] = 0.0;
    }
}

double unicycle_timer_now(const unicycle_timer *tm)
{
    return tm->clock ? tm->clock(tm->ctx) : 0.0;
}

double unicycle_timer_add(unicycle_timer *tm, int phase, double since)
{
    double now = unicycle_timer_now(tm);
    if (phase >= 0 && phase < UNICYCLE_N_PHASES) {
        tm->t[phase] += now - since;
    }
    return now;
}
