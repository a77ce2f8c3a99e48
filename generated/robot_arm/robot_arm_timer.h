/* Phase timers of the DOPUS runtime.
 *
 * The runtime reads time through a clock hook (seconds as a double, any origin) that the
 * user installs with robot_arm_set_clock(). The default clock needs no macro:
 * - where the preprocessor finds POSIX timers (a Unix-like system whose <unistd.h> defines
 *   _POSIX_TIMERS > 0 and _POSIX_MONOTONIC_CLOCK), it is clock_gettime(CLOCK_MONOTONIC);
 * - anywhere else (bare-metal toolchains such as arm-none-eabi with newlib) there is no
 *   default clock: it reads 0, every phase time reads 0, and robot_arm_timer_has_default_clock()
 *   and robot_arm_has_clock() say so. Firmware installs its own clock (a cycle counter, a
 *   hardware timer) with robot_arm_set_clock().
 * -DROBOT_ARM_CLOCK_POSIX=0 forces the no-clock default, -DROBOT_ARM_CLOCK_POSIX=1 forces POSIX.
 */
#ifndef ROBOT_ARM_TIMER_H
#define ROBOT_ARM_TIMER_H

/* Phases timed per call (seconds of the last call that ran the phase). */
enum robot_arm_phase {
    ROBOT_ARM_PHASE_FEEDBACK = 0,       /* robot_arm_feedback: QP solve + step */
    ROBOT_ARM_PHASE_SHIFT = 1,          /* prepare step 1: shift, ring head */
    ROBOT_ARM_PHASE_GRADIENTS = 2,      /* prepare steps 2-3: stage_grad / term_grad (F_k) */
    ROBOT_ARM_PHASE_RHO = 3,            /* prepare step 2: secant criterion eq. 16 */
    ROBOT_ARM_PHASE_HESSIANS = 4,       /* stage_hess / term_hess (H_k) and stage_hess_cost (A_l),
                                      without regularisation */
    ROBOT_ARM_PHASE_REGULARIZATION = 5, /* eigenvalue regularisation of fresh A blocks */
    ROBOT_ARM_PHASE_ASSEMBLY = 6,       /* QP vectors a_k, b_k, bounds */
    ROBOT_ARM_PHASE_KKT = 7,            /* robot_arm_kkt_eval */
    ROBOT_ARM_N_PHASES = 8
};

typedef double (*robot_arm_clock_fn)(void *ctx);

typedef struct {
    robot_arm_clock_fn clock;
    void *ctx;
    double t[ROBOT_ARM_N_PHASES];
} robot_arm_timer;

/* The default clock: CLOCK_MONOTONIC in seconds where POSIX timers exist, else 0. */
double robot_arm_timer_default_clock(void *ctx);
/* 1 if the default clock measures time on this platform (POSIX timers), 0 if it reads 0. */
int robot_arm_timer_has_default_clock(void);

void robot_arm_timer_init(robot_arm_timer *tm);
double robot_arm_timer_now(const robot_arm_timer *tm);
/* t[phase] += now - since; returns now so consecutive phases chain without a second read. */
double robot_arm_timer_add(robot_arm_timer *tm, int phase, double since);

#endif /* ROBOT_ARM_TIMER_H */
