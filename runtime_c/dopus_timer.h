/* Phase timers of the DOPUS runtime.
 *
 * The runtime reads time through a clock hook (seconds as a double, any origin) that the
 * user installs with dopus_set_clock(). The default clock needs no macro:
 * - where the preprocessor finds POSIX timers (a Unix-like system whose <unistd.h> defines
 *   _POSIX_TIMERS > 0 and _POSIX_MONOTONIC_CLOCK), it is clock_gettime(CLOCK_MONOTONIC);
 * - anywhere else (bare-metal toolchains such as arm-none-eabi with newlib) there is no
 *   default clock: it reads 0, every phase time reads 0, and dopus_timer_has_default_clock()
 *   and dopus_has_clock() say so. Firmware installs its own clock (a cycle counter, a
 *   hardware timer) with dopus_set_clock().
 * -DDOPUS_CLOCK_POSIX=0 forces the no-clock default, -DDOPUS_CLOCK_POSIX=1 forces POSIX.
 */
#ifndef DOPUS_TIMER_H
#define DOPUS_TIMER_H

/* Phases timed per call (seconds of the last call that ran the phase). */
enum dopus_phase {
    DOPUS_PHASE_FEEDBACK = 0,       /* dopus_feedback: QP solve + step */
    DOPUS_PHASE_SHIFT = 1,          /* prepare step 1: shift, ring head */
    DOPUS_PHASE_GRADIENTS = 2,      /* prepare steps 2-3: stage_grad / term_grad (F_k) */
    DOPUS_PHASE_RHO = 3,            /* prepare step 2: secant criterion eq. 16 */
    DOPUS_PHASE_HESSIANS = 4,       /* stage_hess / term_hess (H_k) and stage_hess_cost (A_l),
                                      without regularisation */
    DOPUS_PHASE_REGULARIZATION = 5, /* eigenvalue regularisation of fresh A blocks */
    DOPUS_PHASE_ASSEMBLY = 6,       /* QP vectors a_k, b_k, bounds */
    DOPUS_PHASE_KKT = 7,            /* dopus_kkt_eval */
    DOPUS_N_PHASES = 8
};

typedef double (*dopus_clock_fn)(void *ctx);

typedef struct {
    dopus_clock_fn clock;
    void *ctx;
    double t[DOPUS_N_PHASES];
} dopus_timer;

/* The default clock: CLOCK_MONOTONIC in seconds where POSIX timers exist, else 0. */
double dopus_timer_default_clock(void *ctx);
/* 1 if the default clock measures time on this platform (POSIX timers), 0 if it reads 0. */
int dopus_timer_has_default_clock(void);

void dopus_timer_init(dopus_timer *tm);
double dopus_timer_now(const dopus_timer *tm);
/* t[phase] += now - since; returns now so consecutive phases chain without a second read. */
double dopus_timer_add(dopus_timer *tm, int phase, double since);

#endif /* DOPUS_TIMER_H */
