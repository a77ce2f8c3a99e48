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
#define ROBOT_ARM_GLOB_KKT_FACTOR ROBOT_ARM_R(0.5)     /* the full step also when its KKT <= 0.5 kkt_best */

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

/* The caller's memory of a globalised solve. */
struct robot_arm_glob {
    robot_arm_real penalty;  /* the l1 penalty weight nu of the merit function */
    robot_arm_real alpha;    /* the step length of the last step */
    robot_arm_real merit;    /* the merit at the iterate after the last step */
    robot_arm_real slope;    /* the directional derivative D of the last step */
    robot_arm_real kkt;      /* robot_arm_init_globalised: the KKT measure at the end */
    robot_arm_real kkt_best; /* the lowest KKT measure of an iterate of this solve (0: none yet) */
    int iterations;      /* steps taken in this solve */
    int trials;          /* merit evaluations of the last line search */
    int reason;          /* enum robot_arm_glob_reason of the last call */
    int by_kkt;          /* the last step was taken by the KKT test (the merit test refused it) */
    robot_arm_real x[ROBOT_ARM_N + 1][ROBOT_ARM_NX]; /* the iterate before the step, the trial point */
    robot_arm_real u[ROBOT_ARM_N][ROBOT_ARM_NU];
    robot_arm_real xt[ROBOT_ARM_N + 1][ROBOT_ARM_NX];
    robot_arm_real ut[ROBOT_ARM_N][ROBOT_ARM_NU];
    robot_arm_real lam[ROBOT_ARM_N + 1][ROBOT_ARM_NX]; /* multipliers before the step, then interpolated */
    robot_arm_real mu_g[ROBOT_ARM_N][ROBOT_ARM_DIM(ROBOT_ARM_NG)];
    robot_arm_real mu_b[ROBOT_ARM_N][ROBOT_ARM_NW];
    robot_arm_real mu_bN[ROBOT_ARM_NX];
    robot_arm_real mu_r[ROBOT_ARM_DIM(ROBOT_ARM_NR)];
    robot_arm_real nu[ROBOT_ARM_DIM(ROBOT_ARM_NE)];
    robot_arm_real lin_g[ROBOT_ARM_N][ROBOT_ARM_DIM(ROBOT_ARM_NG)]; /* g_k + Ct_k dw_k: soft path rows at the full step */
    robot_arm_real lin_r[ROBOT_ARM_DIM(ROBOT_ARM_NR)];          /* r + R dx_N */
    robot_arm_real a_dot_p; /* sum_k a_k' dw_k + a_N' dx_N: the cost's slope along the step */
};

#endif /* ROBOT_ARM_GLOBALISE_H */
