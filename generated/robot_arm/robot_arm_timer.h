/* Phase timers of the DOPUS runtime.
 *
 * The runtime reads time through a clock hook (seconds as a double, any origin) that the
 * user installs with robot_arm_set_clock(). The default clock needs no macro:
 * - where the preprocessor finds POSIX timers (a Unix-like system whose <unistd.h> defines
 *   _POSIX_TIMERS > 0 and _POSIX_MONOTONIC_CLOCK), it is clock_gettime(CLOCK_MONOTONIC);
 * - anywhere else (bare-metal toolchains such as arm-none-eabi with newlib) there is no
 *   default clock: it reads 0, every phase time reads 0, and robot_arm_timer_has_default_clock()
 *   and has_clock of robot_arm_get_info say so. Firmware installs its own clock (a cycle counter, a
 *   hardware timer) with robot_arm_set_clock().
 * -DROBOT_ARM_CLOCK_POSIX=0 forces the no-clock default, -DROBOT_ARM_CLOCK_POSIX=1 forces POSIX.
 */
#ifndef ROBOT_ARM_TIMER_H
#define ROBOT_ARM_TIMER_H

/* Phases timed per call (seconds of the last call that ran the phase). Every part of
 * feedback and prepare runs inside one of them, so the phases of a call add up to its wall
 * time (robot_arm_info.t_feedback, t_prepare). */
enum robot_arm_phase {
    ROBOT_ARM_PHASE_FEEDBACK = 0,       /* robot_arm_feedback, the whole call: QP solve + step */
    ROBOT_ARM_PHASE_SHIFT = 1,          /* prepare step 1: shift, ring head */
    ROBOT_ARM_PHASE_GRADIENTS = 2,      /* prepare steps 2-3: stage_grad / term_grad (F_k), F_old stored */
    ROBOT_ARM_PHASE_RHO = 3,            /* prepare steps 2 and 4: secant criterion eq. 16, selection */
    ROBOT_ARM_PHASE_HESSIANS = 4,       /* stage_hess / term_hess (H_k) and stage_hess_cost (A_l),
                                      without regularisation */
    ROBOT_ARM_PHASE_REGULARIZATION = 5, /* eigenvalue regularisation of fresh A blocks */
    ROBOT_ARM_PHASE_ASSEMBLY = 6,       /* QP vectors a_k, b_k, bounds */
    ROBOT_ARM_PHASE_KKT = 7,            /* robot_arm_kkt_eval */
    ROBOT_ARM_PHASE_LM = 8,             /* the automatic Levenberg-Marquardt term: Hessian scale and
                                      convexity test (prepare, init) */
    ROBOT_ARM_PHASE_RECOVERY = 9,       /* prepare: the predicted step after a failed feedback, the
                                      divergence test, the simulation of a re-initialisation */
    ROBOT_ARM_N_PHASES = 10
};

typedef double (*robot_arm_clock_fn)(void *ctx);

typedef struct {
    robot_arm_clock_fn clock;
    void *ctx;
    double t[ROBOT_ARM_N_PHASES];
    double t_call[2]; /* wall time of the last feedback [0] and prepare [1] */
    double mark;      /* clock reading at the last phase change */
    int phase;        /* the running phase (-1: none) */
    int locked;       /* 1: the running phase stays (robot_arm_timer_switch changes nothing) */
} robot_arm_timer;

#ifndef ROBOT_ARM_INTERNAL
#define ROBOT_ARM_INTERNAL
#endif

/* The default clock: CLOCK_MONOTONIC in seconds where POSIX timers exist, else 0. */
ROBOT_ARM_INTERNAL double robot_arm_timer_default_clock(void *ctx);
/* 1 if the default clock measures time on this platform (POSIX timers), 0 if it reads 0. */
ROBOT_ARM_INTERNAL int robot_arm_timer_has_default_clock(void);

ROBOT_ARM_INTERNAL void robot_arm_timer_init(robot_arm_timer *tm);
/* Start timing a call: the phases of the bit mask `clear` (bit p: phase p) read 0, `phase`
 * runs from now. */
ROBOT_ARM_INTERNAL void robot_arm_timer_begin(robot_arm_timer *tm, unsigned clear, int phase);
/* The time since the last phase change goes to the running phase; `phase` runs from now.
 * Returns the phase that ran (to switch back after a nested phase). While locked, nothing
 * changes (returns `phase`). */
ROBOT_ARM_INTERNAL int robot_arm_timer_switch(robot_arm_timer *tm, int phase);
/* End the call begun at `start` (the clock reading of robot_arm_timer_begin, tm->mark then): the
 * running phase gets its time; t_call[call] = the wall time of the call (call 0 feedback,
 * 1 prepare, -1 none). */
ROBOT_ARM_INTERNAL void robot_arm_timer_end(robot_arm_timer *tm, int call, double start);

#endif /* ROBOT_ARM_TIMER_H */
