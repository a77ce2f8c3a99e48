/* Phase timers: the default clock is POSIX clock_gettime(CLOCK_MONOTONIC) where the
 * preprocessor finds POSIX timers, and no clock (reads 0) elsewhere; see unicycle_timer.h. */
/* clock_gettime is POSIX, not C99: request it before any header (harmless without POSIX). */
#ifndef _POSIX_C_SOURCE
#define _POSIX_C_SOURCE 199309L
#endif

#include "unicycle_timer.h"

#ifndef UNICYCLE_CLOCK_POSIX
/* Only Unix-like systems have <unistd.h>; it tells whether the monotonic clock exists. */
#if defined(__unix__) || defined(__unix) || (defined(__APPLE__) && defined(__MACH__))
#include <unistd.h>
#if defined(_POSIX_TIMERS) && (_POSIX_TIMERS > 0) && defined(_POSIX_MONOTONIC_CLOCK)
#define UNICYCLE_CLOCK_POSIX 1
#endif
#endif
#endif
#ifndef UNICYCLE_CLOCK_POSIX
#define UNICYCLE_CLOCK_POSIX 0
#endif

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

int unicycle_timer_has_default_clock(void)
{
    return UNICYCLE_CLOCK_POSIX ? 1 : 0;
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
