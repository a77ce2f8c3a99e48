/* Phase timers: the POSIX monotonic clock behind DOPUS_CLOCK_POSIX. */
/* clock_gettime is POSIX, not C99: request it before any header. */
#ifndef _POSIX_C_SOURCE
#define _POSIX_C_SOURCE 199309L
#endif

#include "dopus_timer.h"

#if DOPUS_CLOCK_POSIX
#include <time.h>
#endif

double dopus_timer_default_clock(void *ctx)
{
    (void)ctx;
#if DOPUS_CLOCK_POSIX
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

void dopus_timer_init(dopus_timer *tm)
{
    int i;
    tm->clock = dopus_timer_default_clock;
    tm->ctx = 0;
    for (i = 0; i < DOPUS_N_PHASES; ++i) {
        tm->t[i] = 0.0;
    }
}

double dopus_timer_now(const dopus_timer *tm)
{
    return tm->clock ? tm->clock(tm->ctx) : 0.0;
}

double dopus_timer_add(dopus_timer *tm, int phase, double since)
{
    double now = dopus_timer_now(tm);
    if (phase >= 0 && phase < DOPUS_N_PHASES) {
        tm->t[phase] += now - since;
    }
    return now;
}
