/* Phase timers of the DOPUS runtime.
 *
 * The runtime reads time through a clock hook (seconds as a double, any origin) that the
 * user installs with unicycle_set_clock(). The default clock needs no macro:
 * - where the preprocessor finds POSIX timers (a Unix-like system whose <unistd.h> defines
 *   _POSIX_TIMERS > 0 and _POSIX_MONOTONIC_CLOCK), it is clock_gettime(CLOCK_MONOTONIC);
 * - anywhere else (bare-metal toolchains such as arm-none-eabi with newlib) there is no
 *   default clock: it reads 0, every phase time reads 0, and unicycle_timer_has_default_clock()
 *   and unicycle_has_clock() say so. Firmware installs its own clock (a cycle counter, a
 *   hardware timer) with unicycle_set_clock().
 * -DUNICYCLE_CLOCK_POSIX=0 forces the no-clock default, -DUNICYCLE_CLOCK_POSIX=1 forces POSIX.
 */
#ifndef UNICYCLE_TIMER_H
#define UNICYCLE_TIMER_H

/* Phases timed per call (seconds of the last call that ran the phase). */
enum unicycle_phase {
    UNICYCLE_PHASE_FEEDBACK = 0,       /* unicycle_feedback: QP solve + step */
    UNICYCLE_PHASE_SHIFT = 1,          /* prepare step 1: shift, ring head */
    UNICYCLE_PHASE_GRADIENTS = 2,      /* prepare steps 2-3: stage_grad / term_grad (F_k) */
    UNICYCLE_PHASE_RHO = 3,            /* prepare step 2: secant criterion eq. 16 */
    UNICYCLE_PHASE_HESSIANS = 4,       /* stage_hess / term_hess (H_k) and stage_hess_cost (A_l),
                                      without regularisation */
    UNICYCLE_PHASE_REGULARIZATION = 5, /* eigenvalue regularisation of fresh A blocks */
    UNICYCLE_PHASE_ASSEMBLY = 6,       /* QP vectors a_k, b_k, bounds */
    UNICYCLE_PHASE_KKT = 7,            /* unicycle_kkt_eval */
    UNICYCLE_N_PHASES = 8
};

typedef double (*unicycle_clock_fn)(void *ctx);

typedef struct {
    unicycle_clock_fn clock;
    void *ctx;
    double t[UNICYCLE_N_PHASES];
} unicycle_timer;

/* The default clock: CLOCK_MONOTONIC in seconds where POSIX timers exist, else 0. */
double unicycle_timer_default_clock(void *ctx);
/* 1 if the default clock measures time on this platform (POSIX timers), 0 if it reads 0. */
int unicycle_timer_has_default_clock(void);

void unicycle_timer_init(unicycle_timer *tm);
double unicycle_timer_now(const unicycle_timer *tm);
/* t[phase] += now - since; returns now so consecutive phases chain without a second read. */
double unicycle_timer_add(unicycle_timer *tm, int phase, double since);

#endif /* UNICYCLE_TIMER_H */
