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
#define UNICYCLE_GLOB_WATCHDOG 10                 /* relaxed full steps of a watchdog at most */

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

/* The primal point as one array (x_0..x_N, then u_0..u_{N-1}) and the multipliers as one
 * (lam, mu_g, mu_b, mu_bN, mu_r, nu, each node by node), in the layout of unicycle_init. */
#define UNICYCLE_GLOB_NZ ((UNICYCLE_N + 1) * UNICYCLE_NX + UNICYCLE_N * UNICYCLE_NU)
#define UNICYCLE_GLOB_NY                                                                                        \
    ((UNICYCLE_N + 1) * UNICYCLE_NX + UNICYCLE_N * (UNICYCLE_NG + UNICYCLE_NW) + UNICYCLE_NX + UNICYCLE_NR + UNICYCLE_NE)

/* The caller's memory of a globalised solve; zero-filled at its start. */
struct unicycle_glob {
    unicycle_real penalty;           /* the l1 penalty weight nu of the merit function */
    unicycle_real alpha;             /* the step length of the last step */
    unicycle_real merit;             /* the merit at the iterate after the last step */
    unicycle_real slope;             /* the directional derivative D of the last line search */
    unicycle_real kkt;               /* unicycle_init_globalised: the KKT measure at the end */
    int iterations;               /* steps taken in this solve */
    int trials;                   /* merit evaluations of the last line search */
    int reason;                   /* enum unicycle_glob_reason of the last call */
    int relaxed;                  /* the last step was a relaxed full step of the watchdog */
    int restores;                 /* returns to a watchdog's point in this solve */
    int no_relax;                 /* the next refused full step is not relaxed (after a return) */
    int watch;                    /* relaxed steps of the running watchdog (0: none) */
    unicycle_real z[UNICYCLE_GLOB_NZ];  /* the iterate before the step */
    unicycle_real zt[UNICYCLE_GLOB_NZ]; /* a trial point */
    unicycle_real dz[UNICYCLE_GLOB_NZ]; /* the QP's step */
    unicycle_real y[UNICYCLE_GLOB_NY];  /* the multipliers before the step, then the accepted ones */
    unicycle_real yq[UNICYCLE_GLOB_NY]; /* the QP's multipliers */
    /* the watchdog's point: iterate, step, multipliers, merit parts and slope of the cost */
    unicycle_real wz[UNICYCLE_GLOB_NZ];
    unicycle_real wdz[UNICYCLE_GLOB_NZ];
    unicycle_real wy[UNICYCLE_GLOB_NY];
    unicycle_real wyq[UNICYCLE_GLOB_NY];
    unicycle_real wf, wc, wadp;
    unicycle_real lin[UNICYCLE_N * UNICYCLE_NG + UNICYCLE_NR + 1]; /* scratch: linearised soft rows */
};

#endif /* UNICYCLE_GLOBALISE_H */
