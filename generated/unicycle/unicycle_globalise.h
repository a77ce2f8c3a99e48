/* The globalised first solve (docs/algorithm.md section 15): SQP iterations with every stage
 * re-linearised and a backtracking (Armijo) line search on the l1 exact-penalty merit
 * function, for a start far from the solution (a cold guess, an arbitrary state at power-up).
 * Off in the real-time loop: feedback and prepare never call it.
 *
 * The memory of a globalised solve (the penalty, the point before the step, the QP's
 * multipliers) is the caller's struct unicycle_glob, zero-filled at the start of a solve, so the solver struct (the RAM bill of the
 * real-time loop) does not grow; one unicycle_glob serves any number of solvers of this problem
 * one after the other. The functions are declared in unicycle_solver.h.
 */
#ifndef UNICYCLE_GLOBALISE_H
#define UNICYCLE_GLOBALISE_H

#include "unicycle_sizes.h"

/* Constants (docs/algorithm.md section 15). */
#define UNICYCLE_GLOB_ARMIJO UNICYCLE_R(1e-4)        /* sufficient decrease: phi(a) <= phi(0) + 1e-4 a D */
#define UNICYCLE_GLOB_BACKTRACK UNICYCLE_R(0.5)      /* a <- 0.5 a after a rejected trial */
#define UNICYCLE_GLOB_MAX_TRIALS 30               /* trials of one line search at most (a >= 2^-29) */
#define UNICYCLE_GLOB_PENALTY_MARGIN UNICYCLE_R(1.1) /* the penalty is raised when below 1.1 |y|_inf ... */
#define UNICYCLE_GLOB_PENALTY_RAISE UNICYCLE_R(2.0)  /* ... to 2 |y|_inf */
#define UNICYCLE_GLOB_MERIT_FLOOR UNICYCLE_R(10.0)   /* round-off allowance: 10 eps (1 + |phi(0)|) */
#define UNICYCLE_GLOB_KKT_FACTOR UNICYCLE_R(0.5)     /* the full step also when its KKT <= 0.5 kkt_best */

/* Why the last globalised step failed (unicycle_glob_info.reason). */
enum unicycle_glob_reason {
    UNICYCLE_GLOB_OK = 0,
    UNICYCLE_GLOB_QP = 1,           /* the QP of the iterate was not solved (status UNICYCLE_ERR_QP) */
    UNICYCLE_GLOB_STEP_BOX = 2,     /* the full QP step leaves the scale box (UNICYCLE_ERR_DIVERGED) */
    UNICYCLE_GLOB_LINE_SEARCH = 3,  /* no trial step decreased the merit enough (UNICYCLE_ERR_DIVERGED) */
    UNICYCLE_GLOB_FUNCTION = 4,     /* a function failed or was not finite at a point (its status) */
    UNICYCLE_GLOB_WORK_LIMIT = 5,   /* unicycle_init_globalised: the work limit ended the iterations */
    UNICYCLE_GLOB_NOT_PREPARED = 6, /* the solver holds no prepared QP (init first) */
    UNICYCLE_GLOB_ITER_LIMIT = 7    /* unicycle_init_globalised: the iteration limit ended the iterations */
};

/* The caller's memory of a globalised solve. */
struct unicycle_glob {
    unicycle_real penalty;  /* the l1 penalty weight nu of the merit function */
    unicycle_real alpha;    /* the step length of the last step */
    unicycle_real merit;    /* the merit at the iterate after the last step */
    unicycle_real slope;    /* the directional derivative D of the last step */
    unicycle_real kkt;      /* unicycle_init_globalised: the KKT measure at the end */
    unicycle_real kkt_best; /* the lowest KKT measure of an iterate of this solve (0: none yet) */
    int iterations;      /* steps taken in this solve */
    int trials;          /* merit evaluations of the last line search */
    int reason;          /* enum unicycle_glob_reason of the last call */
    int by_kkt;          /* the last step was taken by the KKT test (the merit test refused it) */
    unicycle_real x[UNICYCLE_N + 1][UNICYCLE_NX]; /* the iterate before the step, the trial point */
    unicycle_real u[UNICYCLE_N][UNICYCLE_NU];
    unicycle_real xt[UNICYCLE_N + 1][UNICYCLE_NX];
    unicycle_real ut[UNICYCLE_N][UNICYCLE_NU];
    unicycle_real lam[UNICYCLE_N + 1][UNICYCLE_NX]; /* multipliers before the step, then interpolated */
    unicycle_real mu_g[UNICYCLE_N][UNICYCLE_DIM(UNICYCLE_NG)];
    unicycle_real mu_b[UNICYCLE_N][UNICYCLE_NW];
    unicycle_real mu_bN[UNICYCLE_NX];
    unicycle_real mu_r[UNICYCLE_DIM(UNICYCLE_NR)];
    unicycle_real nu[UNICYCLE_DIM(UNICYCLE_NE)];
    unicycle_real lin_g[UNICYCLE_N][UNICYCLE_DIM(UNICYCLE_NG)]; /* g_k + Ct_k dw_k: soft path rows at the full step */
    unicycle_real lin_r[UNICYCLE_DIM(UNICYCLE_NR)];          /* r + R dx_N */
    unicycle_real a_dot_p; /* sum_k a_k' dw_k + a_N' dx_N: the cost's slope along the step */
};

#endif /* UNICYCLE_GLOBALISE_H */
