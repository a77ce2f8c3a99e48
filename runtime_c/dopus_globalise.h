/* The globalised first solve (docs/algorithm.md section 15): SQP iterations with every stage
 * re-linearised and a backtracking (Armijo) line search on the l1 exact-penalty merit
 * function, for a start far from the solution (a cold guess, an arbitrary state at power-up).
 * Off in the real-time loop: feedback and prepare never call it.
 *
 * The memory of a globalised solve (the penalty, the point before the step, the QP's
 * multipliers) is the caller's struct dopus_glob, zero-filled at the start of a solve, so the solver struct (the RAM bill of the
 * real-time loop) does not grow; one dopus_glob serves any number of solvers of this problem
 * one after the other. The functions are declared in dopus_solver.h.
 */
#ifndef DOPUS_GLOBALISE_H
#define DOPUS_GLOBALISE_H

#include "dopus_sizes.h"

/* Constants (docs/algorithm.md section 15). */
#define DOPUS_GLOB_ARMIJO DOPUS_R(1e-4)        /* sufficient decrease: phi(a) <= phi(0) + 1e-4 a D */
#define DOPUS_GLOB_BACKTRACK DOPUS_R(0.5)      /* a <- 0.5 a after a rejected trial */
#define DOPUS_GLOB_MAX_TRIALS 30               /* trials of one line search at most (a >= 2^-29) */
#define DOPUS_GLOB_PENALTY_MARGIN DOPUS_R(1.1) /* the penalty is raised when below 1.1 |y|_inf ... */
#define DOPUS_GLOB_PENALTY_RAISE DOPUS_R(2.0)  /* ... to 2 |y|_inf */
#define DOPUS_GLOB_MERIT_FLOOR DOPUS_R(10.0)   /* round-off allowance: 10 eps (1 + |phi(0)|) */
#define DOPUS_GLOB_KKT_FACTOR DOPUS_R(0.5)     /* the full step also when its KKT <= 0.5 kkt_best */

/* Why the last globalised step failed (dopus_glob_info.reason). */
enum dopus_glob_reason {
    DOPUS_GLOB_OK = 0,
    DOPUS_GLOB_QP = 1,           /* the QP of the iterate was not solved (status DOPUS_ERR_QP) */
    DOPUS_GLOB_STEP_BOX = 2,     /* the full QP step leaves the scale box (DOPUS_ERR_DIVERGED) */
    DOPUS_GLOB_LINE_SEARCH = 3,  /* no trial step decreased the merit enough (DOPUS_ERR_DIVERGED) */
    DOPUS_GLOB_FUNCTION = 4,     /* a function failed or was not finite at a point (its status) */
    DOPUS_GLOB_WORK_LIMIT = 5,   /* dopus_init_globalised: the work limit ended the iterations */
    DOPUS_GLOB_NOT_PREPARED = 6, /* the solver holds no prepared QP (init first) */
    DOPUS_GLOB_ITER_LIMIT = 7    /* dopus_init_globalised: the iteration limit ended the iterations */
};

/* The caller's memory of a globalised solve. */
struct dopus_glob {
    dopus_real penalty;  /* the l1 penalty weight nu of the merit function */
    dopus_real alpha;    /* the step length of the last step */
    dopus_real merit;    /* the merit at the iterate after the last step */
    dopus_real slope;    /* the directional derivative D of the last step */
    dopus_real kkt;      /* dopus_init_globalised: the KKT measure at the end */
    dopus_real kkt_best; /* the lowest KKT measure of an iterate of this solve (0: none yet) */
    int iterations;      /* steps taken in this solve */
    int trials;          /* merit evaluations of the last line search */
    int reason;          /* enum dopus_glob_reason of the last call */
    int by_kkt;          /* the last step was taken by the KKT test (the merit test refused it) */
    dopus_real x[DOPUS_N + 1][DOPUS_NX]; /* the iterate before the step, the trial point */
    dopus_real u[DOPUS_N][DOPUS_NU];
    dopus_real xt[DOPUS_N + 1][DOPUS_NX];
    dopus_real ut[DOPUS_N][DOPUS_NU];
    dopus_real lam[DOPUS_N + 1][DOPUS_NX]; /* multipliers before the step, then interpolated */
    dopus_real mu_g[DOPUS_N][DOPUS_DIM(DOPUS_NG)];
    dopus_real mu_b[DOPUS_N][DOPUS_NW];
    dopus_real mu_bN[DOPUS_NX];
    dopus_real mu_r[DOPUS_DIM(DOPUS_NR)];
    dopus_real nu[DOPUS_DIM(DOPUS_NE)];
    dopus_real lin_g[DOPUS_N][DOPUS_DIM(DOPUS_NG)]; /* g_k + Ct_k dw_k: soft path rows at the full step */
    dopus_real lin_r[DOPUS_DIM(DOPUS_NR)];          /* r + R dx_N */
    dopus_real a_dot_p; /* sum_k a_k' dw_k + a_N' dx_N: the cost's slope along the step */
};

#endif /* DOPUS_GLOBALISE_H */
