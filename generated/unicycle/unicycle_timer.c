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
    tm->t_call[0] = tm->t_call[1] = 0.0;
    tm->mark = 0.0;
    tm->phase = -1;
    tm->locked = 0;
}

static double unicycle_timer_now(const unicycle_timer *tm)
{
    return tm->clock ? tm->clock(tm->ctx) : 0.0;
}

void unicycle_timer_begin(unicycle_timer *tm, unsigned clear, int phase)
{
    int i;
    for (i = 0; i < UNICYCLE_N_PHASES; ++i) {
        if (clear & (1u << i)) {
            tm->t[i] = 0.0;
        }
    }
    tm->locked = 0;
    tm->phase = phase;
    tm->mark = unicycle_timer_now(tm);
}

int unicycle_timer_switch(unicycle_timer *tm, int phase)
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
    now = unicycle_timer_now(tm);
    if (prev >= 0 && prev < UNICYCLE_N_PHASES) {
        tm->t[prev] += now - tm->mark;
    }
    tm->mark = now;
    tm->phase = phase;
    return prev;
}

void unicycle_timer_end(unicycle_timer *tm, int call, double start)
{
    tm->locked = 0;
    unicycle_timer_switch(tm, -1);
    if (call >= 0 && call < 2) {
        tm->t_call[call] = tm->mark - start;
    }
}
