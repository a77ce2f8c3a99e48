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
#define DOPUS_GLOB_WATCHDOG 10                 /* relaxed full steps of a watchdog at most */

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

/* The primal point as one array (x_0..x_N, then u_0..u_{N-1}) and the multipliers as one
 * (lam, mu_g, mu_b, mu_bN, mu_r, nu, each node by node), in the layout of dopus_init. */
#define DOPUS_GLOB_NZ ((DOPUS_N + 1) * DOPUS_NX + DOPUS_N * DOPUS_NU)
#define DOPUS_GLOB_NY                                                                                        \
    ((DOPUS_N + 1) * DOPUS_NX + DOPUS_N * (DOPUS_NG + DOPUS_NW) + DOPUS_NX + DOPUS_NR + DOPUS_NE)

/* The caller's memory of a globalised solve; zero-filled at its start. */
struct dopus_glob {
    dopus_real penalty;           /* the l1 penalty weight nu of the merit function */
    dopus_real alpha;             /* the step length of the last step */
    dopus_real merit;             /* the merit at the iterate after the last step */
    dopus_real slope;             /* the directional derivative D of the last line search */
    dopus_real kkt;               /* dopus_init_globalised: the KKT measure at the end */
    int iterations;               /* steps taken in this solve */
    int trials;                   /* merit evaluations of the last line search */
    int reason;                   /* enum dopus_glob_reason of the last call */
    int relaxed;                  /* the last step was a relaxed full step of the watchdog */
    int restores;                 /* returns to a watchdog's point in this solve */
    int no_relax;                 /* the next refused full step is not relaxed (after a return) */
    int watch;                    /* relaxed steps of the running watchdog (0: none) */
    dopus_real z[DOPUS_GLOB_NZ];  /* the iterate before the step */
    dopus_real zt[DOPUS_GLOB_NZ]; /* a trial point */
    dopus_real dz[DOPUS_GLOB_NZ]; /* the QP's step */
    dopus_real y[DOPUS_GLOB_NY];  /* the multipliers before the step, then the accepted ones */
    dopus_real yq[DOPUS_GLOB_NY]; /* the QP's multipliers */
    /* the watchdog's point: iterate, step, multipliers, merit parts and slope of the cost */
    dopus_real wz[DOPUS_GLOB_NZ];
    dopus_real wdz[DOPUS_GLOB_NZ];
    dopus_real wy[DOPUS_GLOB_NY];
    dopus_real wyq[DOPUS_GLOB_NY];
    dopus_real wf, wc, wadp;
    dopus_real lin[DOPUS_N * DOPUS_NG + DOPUS_NR + 1]; /* scratch: linearised soft rows */
};

#endif /* DOPUS_GLOBALISE_H */
