/* Phase timers of the DOPUS runtime.
 *
 * The runtime reads time through a clock hook (seconds as a double, any origin) that the
 * user installs with dopus_set_clock(). The default clock needs no macro:
 * - where the preprocessor finds POSIX timers (a Unix-like system whose <unistd.h> defines
 *   _POSIX_TIMERS > 0 and _POSIX_MONOTONIC_CLOCK), it is clock_gettime(CLOCK_MONOTONIC);
 * - anywhere else (bare-metal toolchains such as arm-none-eabi with newlib) there is no
 *   default clock: it reads 0, every phase time reads 0, and dopus_timer_has_default_clock()
 *   and has_clock of dopus_get_info say so. Firmware installs its own clock (a cycle counter, a
 *   hardware timer) with dopus_set_clock().
 * -DDOPUS_CLOCK_POSIX=0 forces the no-clock default, -DDOPUS_CLOCK_POSIX=1 forces POSIX.
 */
#ifndef DOPUS_TIMER_H
#define DOPUS_TIMER_H

/* Phases timed per call (seconds of the last call that ran the phase). Every part of
 * feedback and prepare runs inside one of them, so the phases of a call add up to its wall
 * time (dopus_info.t_feedback, t_prepare). */
enum dopus_phase {
    DOPUS_PHASE_FEEDBACK = 0,       /* dopus_feedback, the whole call: QP solve + step */
    DOPUS_PHASE_SHIFT = 1,          /* prepare step 1: shift, ring head */
    DOPUS_PHASE_GRADIENTS = 2,      /* prepare steps 2-3: stage_grad / term_grad (F_k), F_old stored */
    DOPUS_PHASE_RHO = 3,            /* prepare steps 2 and 4: secant criterion eq. 16, selection */
    DOPUS_PHASE_HESSIANS = 4,       /* stage_hess / term_hess (H_k) and stage_hess_cost (A_l),
                                      without regularisation */
    DOPUS_PHASE_REGULARIZATION = 5, /* eigenvalue regularisation of fresh A blocks */
    DOPUS_PHASE_ASSEMBLY = 6,       /* QP vectors a_k, b_k, bounds */
    DOPUS_PHASE_KKT = 7,            /* dopus_kkt_eval */
    DOPUS_PHASE_LM = 8,             /* the automatic Levenberg-Marquardt term: Hessian scale and
                                      convexity test (prepare, init) */
    DOPUS_PHASE_RECOVERY = 9,       /* prepare: the predicted step after a failed feedback, the
                                      divergence test, the simulation of a re-initialisation */
    DOPUS_N_PHASES = 10
};

typedef double (*dopus_clock_fn)(void *ctx);

typedef struct {
    dopus_clock_fn clock;
    void *ctx;
    double t[DOPUS_N_PHASES];
    double t_call[2]; /* wall time of the last feedback [0] and prepare [1] */
    double mark;      /* clock reading at the last phase change */
    int phase;        /* the running phase (-1: none) */
    int locked;       /* 1: the running phase stays (dopus_timer_switch changes nothing) */
} dopus_timer;

#ifndef DOPUS_INTERNAL
#define DOPUS_INTERNAL
#endif

/* The default clock: CLOCK_MONOTONIC in seconds where POSIX timers exist, else 0. */
DOPUS_INTERNAL double dopus_timer_default_clock(void *ctx);
/* 1 if the default clock measures time on this platform (POSIX timers), 0 if it reads 0. */
DOPUS_INTERNAL int dopus_timer_has_default_clock(void);

DOPUS_INTERNAL void dopus_timer_init(dopus_timer *tm);
/* Start timing a call: the phases of the bit mask `clear` (bit p: phase p) read 0, `phase`
 * runs from now. */
DOPUS_INTERNAL void dopus_timer_begin(dopus_timer *tm, unsigned clear, int phase);
/* The time since the last phase change goes to the running phase; `phase` runs from now.
 * Returns the phase that ran (to switch back after a nested phase). While locked, nothing
 * changes (returns `phase`). */
DOPUS_INTERNAL int dopus_timer_switch(dopus_timer *tm, int phase);
/* End the call begun at `start` (the clock reading of dopus_timer_begin, tm->mark then): the
 * running phase gets its time; t_call[call] = the wall time of the call (call 0 feedback,
 * 1 prepare, -1 none). */
DOPUS_INTERNAL void dopus_timer_end(dopus_timer *tm, int call, double start);

#endif /* DOPUS_TIMER_H */
