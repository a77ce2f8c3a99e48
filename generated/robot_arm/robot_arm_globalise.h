/* The globalised first solve (docs/algorithm.md section 15): SQP iterations with every stage
 * re-linearised and a backtracking (Armijo) line search on the l1 exact-penalty merit
 * function, for a start far from the solution (a cold guess, an arbitrary state at power-up).
 * Off in the real-time loop: feedback and prepare never call it.
 *
 * The memory of a globalised solve (the penalty, the point before the step, the QP's
 * multipliers) is the caller's struct robot_arm_glob, zero-filled at the start of a solve, so the solver struct (the RAM bill of the
 * real-time loop) does not grow; one robot_arm_glob serves any number of solvers of this problem
 * one after the other. The functions are declared in robot_arm_solver.h.
 */
#ifndef ROBOT_ARM_GLOBALISE_H
#define ROBOT_ARM_GLOBALISE_H

#include "robot_arm_sizes.h"

/* Constants (docs/algorithm.md section 15). */
#define ROBOT_ARM_GLOB_ARMIJO ROBOT_ARM_R(1e-4)        /* sufficient decrease: phi(a) <= phi(0) + 1e-4 a D */
#define ROBOT_ARM_GLOB_BACKTRACK ROBOT_ARM_R(0.5)      /* a <- 0.5 a after a rejected trial */
#define ROBOT_ARM_GLOB_MAX_TRIALS 30               /* trials of one line search at most (a >= 2^-29) */
#define ROBOT_ARM_GLOB_PENALTY_MARGIN ROBOT_ARM_R(1.1) /* the penalty is raised when below 1.1 |y|_inf ... */
#define ROBOT_ARM_GLOB_PENALTY_RAISE ROBOT_ARM_R(2.0)  /* ... to 2 |y|_inf */
#define ROBOT_ARM_GLOB_MERIT_FLOOR ROBOT_ARM_R(10.0)   /* round-off allowance: 10 eps (1 + |phi(0)|) */
#define ROBOT_ARM_GLOB_WATCHDOG 10                 /* relaxed full steps of a watchdog at most */

/* Why the last globalised step failed (robot_arm_glob_info.reason). */
enum robot_arm_glob_reason {
    ROBOT_ARM_GLOB_OK = 0,
    ROBOT_ARM_GLOB_QP = 1,           /* the QP of the iterate was not solved (status ROBOT_ARM_ERR_QP) */
    ROBOT_ARM_GLOB_STEP_BOX = 2,     /* the full QP step leaves the scale box (ROBOT_ARM_ERR_DIVERGED) */
    ROBOT_ARM_GLOB_LINE_SEARCH = 3,  /* no trial step decreased the merit enough (ROBOT_ARM_ERR_DIVERGED) */
    ROBOT_ARM_GLOB_FUNCTION = 4,     /* a function failed or was not finite at a point (its status) */
    ROBOT_ARM_GLOB_WORK_LIMIT = 5,   /* robot_arm_init_globalised: the work limit ended the iterations */
    ROBOT_ARM_GLOB_NOT_PREPARED = 6, /* the solver holds no prepared QP (init first) */
    ROBOT_ARM_GLOB_ITER_LIMIT = 7    /* robot_arm_init_globalised: the iteration limit ended the iterations */
};

/* The primal point as one array (x_0..x_N, then u_0..u_{N-1}) and the multipliers as one
 * (lam, mu_g, mu_b, mu_bN, mu_r, nu, each node by node), in the layout of robot_arm_init. */
#define ROBOT_ARM_GLOB_NZ ((ROBOT_ARM_N + 1) * ROBOT_ARM_NX + ROBOT_ARM_N * ROBOT_ARM_NU)
#define ROBOT_ARM_GLOB_NY                                                                                        \
    ((ROBOT_ARM_N + 1) * ROBOT_ARM_NX + ROBOT_ARM_N * (ROBOT_ARM_NG + ROBOT_ARM_NW) + ROBOT_ARM_NX + ROBOT_ARM_NR + ROBOT_ARM_NE)

/* The caller's memory of a globalised solve; zero-filled at its start. */
struct robot_arm_glob {
    robot_arm_real penalty;           /* the l1 penalty weight nu of the merit function */
    robot_arm_real alpha;             /* the step length of the last step */
    robot_arm_real merit;             /* the merit at the iterate after the last step */
    robot_arm_real slope;             /* the directional derivative D of the last line search */
    robot_arm_real kkt;               /* robot_arm_init_globalised: the KKT measure at the end */
    int iterations;               /* steps taken in this solve */
    int trials;                   /* merit evaluations of the last line search */
    int reason;                   /* enum robot_arm_glob_reason of the last call */
    int relaxed;                  /* the last step was a relaxed full step of the watchdog */
    int restores;                 /* returns to a watchdog's point in this solve */
    int no_relax;                 /* the next refused full step is not relaxed (after a return) */
    int watch;                    /* relaxed steps of the running watchdog (0: none) */
    robot_arm_real z[ROBOT_ARM_GLOB_NZ];  /* the iterate before the step */
    robot_arm_real zt[ROBOT_ARM_GLOB_NZ]; /* a trial point */
    robot_arm_real dz[ROBOT_ARM_GLOB_NZ]; /* the QP's step */
    robot_arm_real y[ROBOT_ARM_GLOB_NY];  /* the multipliers before the step, then the accepted ones */
    robot_arm_real yq[ROBOT_ARM_GLOB_NY]; /* the QP's multipliers */
    /* the watchdog's point: iterate, step, multipliers, merit parts and slope of the cost */
    robot_arm_real wz[ROBOT_ARM_GLOB_NZ];
    robot_arm_real wdz[ROBOT_ARM_GLOB_NZ];
    robot_arm_real wy[ROBOT_ARM_GLOB_NY];
    robot_arm_real wyq[ROBOT_ARM_GLOB_NY];
    robot_arm_real wf, wc, wadp;
    robot_arm_real lin[ROBOT_ARM_N * ROBOT_ARM_NG + ROBOT_ARM_NR + 1]; /* scratch: linearised soft rows */
};

#endif /* ROBOT_ARM_GLOBALISE_H */
