/* Phase timers: the default clock is POSIX clock_gettime(CLOCK_MONOTONIC) where the
 * preprocessor finds POSIX timers, and no clock (reads 0) elsewhere; see dopus_timer.h. */
/* clock_gettime is POSIX, not C99: request it before any header (harmless without POSIX). */
#ifndef _POSIX_C_SOURCE
#define _POSIX_C_SOURCE 199309L
#endif

#include "dopus_timer.h"

#ifndef DOPUS_CLOCK_POSIX
/* Only Unix-like systems have <unistd.h>; it tells whether the monotonic clock exists. */
#if defined(__unix__) || defined(__unix) || (defined(__APPLE__) && defined(__MACH__))
#include <unistd.h>
#if defined(_POSIX_TIMERS) && (_POSIX_TIMERS > 0) && defined(_POSIX_MONOTONIC_CLOCK)
#define DOPUS_CLOCK_POSIX 1
#endif
#endif
#endif
#ifndef DOPUS_CLOCK_POSIX
#define DOPUS_CLOCK_POSIX 0
#endif

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

int dopus_timer_has_default_clock(void)
{
    return DOPUS_CLOCK_POSIX ? 1 : 0;
}

void dopus_timer_init(dopus_timer *tm)
{
    int i;
    tm->clock = dopus_timer_default_clock;
    tm->ctx = 0;
    for (i = 0; i < DOPUS_N_PHASES; ++i) {
        tm->t[i] = 0.0;
    }
    tm->t_call[0] = tm->t_call[1] = 0.0;
    tm->mark = 0.0;
    tm->phase = -1;
    tm->locked = 0;
}

static double dopus_timer_now(const dopus_timer *tm)
{
    return tm->clock ? tm->clock(tm->ctx) : 0.0;
}

void dopus_timer_begin(dopus_timer *tm, unsigned clear, int phase)
{
    int i;
    for (i = 0; i < DOPUS_N_PHASES; ++i) {
        if (clear & (1u << i)) {
            tm->t[i] = 0.0;
        }
    }
    tm->locked = 0;
    tm->phase = phase;
    tm->mark = dopus_timer_now(tm);
}

int dopus_timer_switch(dopus_timer *tm, int phase)
{
    double now;
    int prev = tm->phase;
    if (tm->locked) {
        return phase;
    }
    if (phase == prev && phase >= 0) {
        /* no switch: the running phase keeps accumulating, no clock reading needed (the
         * switch to -1 at the end of a call always reads it) */
        return prev;
    }
    now = dopus_timer_now(tm);
    if (prev >= 0 && prev < DOPUS_N_PHASES) {
        tm->t[prev] += now - tm->mark;
    }
    tm->mark = now;
    tm->phase = phase;
    return prev;
}

void dopus_timer_end(dopus_timer *tm, int call, double start)
{
    tm->locked = 0;
    dopus_timer_switch(tm, -1);
    if (call >= 0 && call < 2) {
        tm->t_call[call] = tm->mark - start;
    }
}
