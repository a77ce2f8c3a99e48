/* Phase timers of the DOPUS runtime.
 *
 * The runtime reads time through a user-replaceable clock (seconds as a double,
 * any origin). The default clock is POSIX clock_gettime(CLOCK_MONOTONIC); compile
 * with -DROBOT_ARM_CLOCK_POSIX=0 on targets without POSIX, then the default clock
 * reads 0 and firmware installs its own with robot_arm_set_clock().
 */
#ifndef ROBOT_ARM_TIMER_H
#define ROBOT_ARM_TIMER_H

#ifndef ROBOT_ARM_CLOCK_POSIX
#define ROBOT_ARM_CLOCK_POSIX 1
#endif

/* Phases timed per call (seconds of the last call that ran the phase). */
enum robot_arm_phase {
    ROBOT_ARM_PHASE_FEEDBACK = 0,      /* robot_arm_feedback: QP solve + step */
    ROBOT_ARM_PHASE_SHIFT = 1,         /* prepare step 1: shift, ring head */
    ROBOT_ARM_PHASE_GRADIENTS = 2,     /* prepare steps 2-3: stage_grad / term_grad (F_k) */
    ROBOT_ARM_PHASE_RHO = 3,           /* prepare step 2: secant criterion eq. 16 */
    ROBOT_ARM_PHASE_HESSIANS = 4,      /* stage_hess / term_hess (H_k) and stage_hess_cost (A_l),
                                      without regularisation */
    ROBOT_ARM_PHASE_REGULARIZATION = 5,/* eigenvalue regularisation of fresh A blocks */
    ROBOT_ARM_PHASE_ASSEMBLY = 6,      /* QP vectors a_k, b_k, bounds */
    ROBOT_ARM_PHASE_KKT = 7,           /* robot_arm_kkt_eval */
    ROBOT_ARM_N_PHASES = 8
};

typedef double (*robot_arm_clock_fn)(void *ctx);

typedef struct {
    robot_arm_clock_fn clock;
    void *ctx;
    double t[ROBOT_ARM_N_PHASES];
} robot_arm_timer;

/* The default clock: CLOCK_MONOTONIC in seconds (0 when ROBOT_ARM_CLOCK_POSIX is 0). */
double robot_arm_timer_default_clock(void *ctx);

void robot_arm_timer_init(robot_arm_timer *tm);
double robot_arm_timer_now(const robot_arm_timer *tm);
/* t[phase] += now - since; returns now so consecutive phases chain without a second read. */
double robot_arm_timer_add(robot_arm_timer *tm, int phase, double since);

#endif /* ROBOT_ARM_TIMER_H */
