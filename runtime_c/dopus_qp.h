/* Sparse stage-wise QP solver: primal-dual interior point (Mehrotra predictor-corrector)
 * with the Newton systems solved by a Riccati recursion, O(N (nx+nu)^3) per iteration.
 *
 * The QP (docs/algorithm.md section 3), stages k = 0..N-1, w_k = (x_k, u_k), nw = nx + nu:
 *
 *   minimize   sum_k 0.5 w_k' H_k w_k + g_k' w_k + 0.5 x_N' HN x_N + gN' x_N
 *   subject to x_0 = x0                                       multiplier lam_0
 *              x_{k+1} = Phi_k w_k + b_k                      multiplier lam_{k+1}
 *              lbw_k <= w_k <= ubw_k                          multiplier mu_b_k
 *              lg_k <= C_k w_k <= ug_k                        multiplier mu_g_k
 *              lbxN <= x_N <= ubxN                            multiplier mu_bN
 *              lr <= R x_N <= ur                              multiplier mu_r
 *              Req x_N = req                                  multiplier nu
 *
 * Bounds: an entry -INFINITY (lower) or +INFINITY (upper) means "no bound on that side";
 * the masks are built at run time, so no compile-time index lists are needed. The x part
 * of lbw_0/ubw_0 is ignored (x_0 is fixed by x0), and so are the rows of C_0 whose u part
 * is exactly zero (their value is fixed by x0: a violation, e.g. by round-off in the
 * measured state, cannot be removed and their multiplier would not be unique; mu_g_0 of
 * such a row is returned as 0 and lam_0 carries the force). lb == ub is accepted (two inequality
 * sides); the dynamics, x0 and Req rows are always handled as equalities.
 *
 * Sign conventions (all multipliers SIGNED, positive when the upper side is active,
 * negative when the lower side is), stationarity of the solution:
 *   stage k:  H_k w_k + g_k + [lam_k; 0] - Phi_k' lam_{k+1} + C_k' mu_g_k + mu_b_k = 0
 *   terminal: HN x_N + gN + lam_N + R' mu_r + Req' nu + mu_bN = 0
 * lam_0 multiplies (x_0 - x0). The x part of mu_b_0 is always 0.
 *
 * Storage: all matrices dense column-major. Stage matrices are read through per-stage
 * pointer tables (no copies: the DOPUS ring buffer hands its slots over directly):
 *   H[k]   nw x nw  (symmetric; only the lower triangle is read)
 *   Phi[k] nx x nw  = [A_k B_k], A_k the first nx columns
 *   C[k]   ng x nw  (may be NULL when DOPUS_NG == 0)
 *   HN     nx x nx  (symmetric; lower triangle read), R nr x nx, Req ne x nx (NULL if 0 rows)
 *
 * Hessians may be indefinite: the solver never convexifies up front. The nu x nu Riccati
 * pivot blocks are factored by Cholesky; when one fails, the terminal equality is first
 * added as an exact augmented-Lagrangian term (rho Req'Req, which does not change the
 * solution of the Newton system because Req dx_N is fixed by the equality) and then, if
 * still needed, delta*I is added to the stage Hessians with delta increased geometrically
 * (IPOPT-style inertia correction). Both are counted in dopus_qp_info. Delta > 0 means
 * the QP is nonconvex on the null space of the equalities, with the bounds that supply
 * its curvature not yet identified: every step taken with delta > 0 is a centring step
 * (sigma >= 0.9), and if the iteration then stalls for 6 iterations the solver restarts
 * once from the plain cold start with mu reduced at most 10x per iteration (Mehrotra's
 * aggressive reduction throws the iterate far into the nonconvex region). Such a QP may
 * have several local minimisers; the one found is a KKT point with positive curvature on
 * its active set, not necessarily the one another solver finds. A negative pivot
 * within the round-off estimate of the recursion (cancellation of large barrier terms) is
 * a numerical zero: it is floored, counted, and iterative refinement restores the step.
 *
 * Termination: all four scaled residuals <= settings.tol, where (infinity norms)
 *   stat / max(1, |H w|, |g|, |constraint part of the stationarity|),
 *   eq   / max(1, |x0|, |b|, |Phi w|, |w|, |req|, |Req x_N|),
 *   ineq / max(1, |finite bounds|, |row values|),  comp (max slack*multiplier) / max(1, |mu|).
 * Accuracy of the answer is tol divided by the conditioning of the QP: on the robot-arm
 * exact-Hessian QPs (reduced Hessian down to ~2e-5) tol 1e-10 leaves errors up to ~4e-5 in
 * the primal step, tol 1e-12 about 2e-7.
 *
 * Infeasibility: the dual (primal) iterate, once grown far beyond the data, is tested as
 * a Farkas certificate (unboundedness ray): A'y ~ 0 with b'y > 0 proves infeasibility;
 * a feasible ray with d'Hd < 0, or Hd ~ 0 and g'd < 0, proves unboundedness. On an
 * infeasible QP the residuals stop improving while the dual iterate diverges towards a
 * certificate: each halving of |A'y| / |y| counts as progress, so the iteration is not
 * stopped as stalled before the certificate is exact. When it stalls nonetheless, or the
 * factorisation fails or needs an inertia correction or terminal augmentation, or the
 * iteration limit is reached, the certificate is tested against its own accuracy: every
 * point violates some row by at least b'y / sum |y_i| |a_i|_inf (in the units of the row's
 * largest coefficient), and beyond 1e-12 of the data in those units (float 1e-5; the
 * tolerance when smaller) the QP is infeasible, e.g. a QP infeasible by a relative margin
 * of 1e-9 at tol 1e-10, whose residuals cannot fall below the tolerance.
 *
 * Cold start: w = 0, lam = nu = 0, centred: every slack t = max(v - bound, f) and its
 * multiplier z = f / t (t z = f on every side), with f the primal infeasibility of w = 0
 * clipped to [0.1, 1] (the QPs of an SQP or RTI iteration start nearly feasible, close to
 * the boundary). While no inertia correction is needed, the steps from there are long:
 * separate primal and dual step lengths, the full step when no side blocks it, else a
 * fraction of the step to the boundary that tends to 1 with it (0.99 a for short steps a,
 * 0.9999999 a near 1). When that makes no progress for 6 iterations (a nonconvex QP whose
 * iterate the long steps threw into the wrong region) the solver starts again from the
 * plain cold start (t = max(v - bound, 1), z = 1) with careful steps (one step length,
 * 0.995 of the step to the boundary), the method of the warm start below. On the
 * robot-arm QPs of bench/qp_bench.py this takes 194 instead of 282 iterations (median 5
 * instead of 11; tol 1e-8).
 *
 * Warm start (settings.warm_start): primal and multipliers are read from *sol; slacks are
 * taken from the primal point, slacks and multipliers floored at 1e-2 (relative to the
 * unit values of the cold start; smaller floors save about one iteration in the robot-arm
 * closed loop but let the warm start reach another local minimiser of nonconvex QPs more
 * often); the careful steps throughout. A restart after a stall starts cold.
 *
 * Cold start far outside a soft side (a QP with soft rows whose measured state or its
 * first prediction violates a soft side by more than 100): the primal start is the rollout
 * of the dynamics from x0 (controls at the point of their box nearest to 0), the slacks of
 * the violated soft sides take up the violation with the side's price zl + Zl s split
 * between the side's and the slack's multiplier, and the multipliers of the dynamics and
 * of the control boxes are those that make the stationarity rows hold at the start. From
 * w = 0 such QPs (measurements 1e3 to 1e6 times outside the bounds) stalled. Feedback
 * (dopus_solver.c) warm-starts from the previous solution shifted with the horizon and
 * retries cold when that fails.
 *
 * Active-set start (settings.active_set > 0 with warm_start, no soft side): before the
 * interior point, the active set is guessed from the warm-start point (a side is active
 * when its multiplier points to it and exceeds its slack; a row with lo == up always is),
 * the Riccati recursion is factored once with a penalty weight on the active rows in place
 * of the barrier weights (AS_RHO times the Hessian scale over |D_i|^2), and the
 * equality-constrained QP of that active set is solved by iterative refinement with this
 * one factor (each step a method-of-multipliers update: back-substitutions only), the
 * active simple bounds set to their bounds before each evaluation of the residuals. The
 * residuals are evaluated before a sweep's first step only in the first sweep (a later
 * sweep starts from the last evaluation, updated for the multipliers set to 0 and for the
 * simple bounds that joined the active set, which are set to their bounds at once: their
 * violation then enters the step through the stationarity and dynamics residuals rather
 * than as the penalty weight times it, whose round-off took a second step) and after
 * every step, but in a sweep with rows held by the Schur complement (below) after every
 * second one: the step that follows an evaluation (or the sweep's start) gives its
 * residuals itself, the stationarity part D_s' G^-1 (D_s d + r_s), the dynamics and Req
 * parts 0 and the active rows' values moved by D d (to round-off). A
 * factorisation that succeeds shows the QP convex on the null space of the active rows, the
 * dynamics and Req. The answer is accepted when its scaled residuals (those of the
 * termination test, the active rows' equality residual with the inequality's scale) are
 * below tol and every active multiplier has its side's sign (a wrong sign within tol times
 * the multipliers' scale is set to 0); otherwise the wrong-signed rows leave the active
 * set, the violated inactive sides join it and the next sweep factors again, up to
 * settings.active_set sweeps. A sweep after corrections that only added rows, at most
 * DOPUS_QP_AS_UPDATE since the last factorisation, keeps the factor: the added rows are
 * held by their Schur complement G = D_s K^-1 D_s' (one solve per row, plus 1/penalty on
 * the diagonal, a Cholesky factor of at most 4 x 4), their multipliers moved in each
 * refinement step by G^-1 times their residual after the step; the same KKT point without
 * a factorisation (the factor showed convexity on a larger null space). On the robot arm's
 * closed loop the active set moves by rows joining at the ends of a saturated stretch, and
 * most second and last sweeps are such updates: 1 factorisation per instant in the median
 * instead of 2, at most 4 instead of 5 (bench/issue23/measurements.md, section 15). Then
 * the interior point runs from the warm start as before.
 * The answer is the KKT point of its active set to round-off, with zero multipliers on the
 * inactive rows.
 *
 * Work per iteration (robot arm, N = 40, nx = 5, nu = 3, ne = 2): one factorisation and
 * two solves (predictor, corrector), plus one residual/solve pair per refinement step once
 * the residuals are below 1e-6; the flop count is tabulated in bench/README.md.
 *
 * Soft rows (DOPUS_NSOFT > 0 in dopus_sizes.h): a side of an inequality row whose weights
 * zl, Zl (lower) or zu, Zu (upper) in dopus_qp_in are not both 0 may be violated by a slack
 * s >= 0, lo - s_lo <= v <= up + s_up, at the price zl s_lo + Zl s_lo^2 / 2 (zu, Zu for
 * s_up) added to the objective. The weights are those of a row of every stage (zl[j] for
 * row j of a stage, as in the layout above) and of the terminal rows (zlN). The slacks are
 * eliminated row by row inside the interior point (their Newton equations are scalar), so
 * the Riccati recursion keeps the size of the problem without slacks: a soft side's barrier
 * weight z/t becomes 1 / (t/z + 1/(Zl + y/s)) (y the multiplier of s >= 0), a series of the
 * row's and the slack's barrier. The returned multiplier of a soft side lies in [0, zl + Zl
 * s] (equal to the upper end when the side is violated), the slacks are max(0, lo - v) and
 * max(0, v - up) of the solution. A soft side of a row of C_0 without u_0 is kept (its
 * slack is then data, its multiplier zl + Zl s unique). A soft side never makes the QP infeasible: the
 * infeasibility certificates and dopus_qp_infeasible_row concern the hard sides only. With
 * DOPUS_NSOFT 0 (or undefined) the weights are not read and the solver compiles to the
 * loops of hard rows alone.
 *
 * Sizes come from dopus_sizes.h: DOPUS_N, DOPUS_NX, DOPUS_NU, DOPUS_NG, DOPUS_NR, DOPUS_NE
 * (NG, NR, NE may be 0), DOPUS_NSOFT (optional, 0 without soft rows). No malloc, no VLAs, no recursion, no state outside the workspace.
 * Compile with -O3 where possible: the linear algebra is inlined with compile-time sizes
 * and -O3 vectorises it (about 1.8x faster than -O2 on the robot-arm QPs).
 */
#ifndef DOPUS_QP_H
#define DOPUS_QP_H

#include "dopus_sizes.h"

#if !defined(DOPUS_N) || !defined(DOPUS_NX) || !defined(DOPUS_NU) || !defined(DOPUS_NG) ||                   \
    !defined(DOPUS_NR) || !defined(DOPUS_NE)
#error "dopus_sizes.h must define DOPUS_N, DOPUS_NX, DOPUS_NU, DOPUS_NG, DOPUS_NR, DOPUS_NE"
#endif

/* C99 forbids zero-length arrays: arrays of a size that may be 0 use DOPUS_QP_MAX1(n). */
#define DOPUS_QP_MAX1(n) ((n) > 0 ? (n) : 1)

#define DOPUS_QP_NW (DOPUS_NX + DOPUS_NU)
#define DOPUS_QP_NG1 DOPUS_QP_MAX1(DOPUS_NG)
#define DOPUS_QP_NR1 DOPUS_QP_MAX1(DOPUS_NR)
#define DOPUS_QP_NE1 DOPUS_QP_MAX1(DOPUS_NE)
#define DOPUS_QP_NU1 DOPUS_QP_MAX1(DOPUS_NU)
/* All stacked primal variables (w_0, ..., w_{N-1}, x_N). */
#define DOPUS_QP_NPRIM (DOPUS_N * DOPUS_QP_NW + DOPUS_NX)
/* Inequality rows, each with a lower and an upper side: stage k holds nw box rows then ng
 * general rows; then the nx terminal box rows and the nr terminal rows. */
#define DOPUS_QP_NSTAGEINEQ (DOPUS_QP_NW + DOPUS_NG)
#define DOPUS_QP_NINEQ (DOPUS_N * DOPUS_QP_NSTAGEINEQ + DOPUS_NX + DOPUS_NR)

/* Rows with a finite side at most (sizes every per-row array of the workspace): the
 * generated sizes header counts them from the problem's bounds (DOPUS_NB); a QP with more
 * bounded rows is rejected as invalid input. Without DOPUS_NB, every row. */
#ifdef DOPUS_NB
#define DOPUS_QP_NB DOPUS_QP_MAX1(DOPUS_NB)
#else
#define DOPUS_QP_NB DOPUS_QP_MAX1(DOPUS_QP_NINEQ)
#endif
/* Soft rows: on (1) when dopus_sizes.h declares DOPUS_NSOFT > 0; the sizes of the soft
 * weights (rows of a stage, terminal rows) and of the per-row slack arrays, 1 when off. */
#ifndef DOPUS_NSOFT
#define DOPUS_NSOFT 0
#endif
#define DOPUS_QP_SOFT (DOPUS_NSOFT > 0)
#define DOPUS_QP_NSS (DOPUS_QP_SOFT * DOPUS_QP_NSTAGEINEQ + 1 - DOPUS_QP_SOFT)
#define DOPUS_QP_NST (DOPUS_QP_SOFT * (DOPUS_NX + DOPUS_NR) + 1 - DOPUS_QP_SOFT)
#define DOPUS_QP_NBS (DOPUS_QP_SOFT * DOPUS_QP_NB + 1 - DOPUS_QP_SOFT)
/* A lower triangular nu x nu matrix packed by lower columns. */
#define DOPUS_QP_NUP (DOPUS_QP_NU1 * (DOPUS_QP_NU1 + 1) / 2)
/* A symmetric nx x nx matrix packed by lower columns. */
#define DOPUS_QP_NXP (DOPUS_NX * (DOPUS_NX + 1) / 2)
/* DOPUS_QP_PHIT 1: the workspace keeps Phi_k' for the whole solve (N nw nx reals), so that
 * the products with Phi_k' run down contiguous columns (vectorised where doubles come in
 * vectors) and the factorisation does not transpose. 0 (the default on 32-bit ARM: a
 * scalar FPU and little RAM): the products read Phi_k itself (Phi_k'P as dot products of
 * its columns), and the QP's kernels take the forms that suit a scalar FPU (dopus_qp.c).
 * The same results either way; define it to override. */
#ifndef DOPUS_QP_PHIT
#if defined(__arm__) && !defined(__aarch64__)
#define DOPUS_QP_PHIT 0
#else
#define DOPUS_QP_PHIT 1
#endif
#endif
/* Scratch of the factorisation: Phi'P, Phi'G and one unpacked P. */
#define DOPUS_QP_NWORK (DOPUS_NX * DOPUS_QP_NW + DOPUS_QP_NW * DOPUS_QP_NE1 + DOPUS_NX * DOPUS_NX)

/* Rows the active-set start may add to the active set of a factorisation without factoring
 * again (see the header comment). */
#define DOPUS_QP_AS_UPDATE 4

/* Row index type of the workspace's bounded-row list (two bytes where they suffice). */
#if DOPUS_QP_NINEQ < 65536
typedef unsigned short dopus_qp_row;
#else
typedef int dopus_qp_row;
#endif

/* Status codes (dopus_qp_solve return value and dopus_qp_info.status). */
enum dopus_qp_status {
    DOPUS_QP_SOLVED = 0,            /* scaled KKT residuals below settings.tol; or, at a
                                       stall, the best point's equality, inequality and
                                       complementarity residuals below it and its
                                       stationarity residual within its round-off (a
                                       tolerance below that round-off; that point returned) */
    DOPUS_QP_MAX_ITER = 1,          /* iteration limit (settings.max_iter) reached; best
                                       point returned */
    DOPUS_QP_PRIMAL_INFEASIBLE = 2, /* Farkas certificate found (or lb > ub) */
    DOPUS_QP_DUAL_INFEASIBLE = 3,   /* unbounded below: feasible descent ray found */
    DOPUS_QP_NUMERICAL = 4,         /* factorisation / step failure */
    DOPUS_QP_INVALID_INPUT = 5,     /* NaN or Inf in data, lb = +inf, ub = -inf, NULL ptr,
                                       more bounded rows than DOPUS_QP_NB */
    DOPUS_QP_STALLED = 6,           /* no progress in the KKT residuals nor towards an
                                       infeasibility certificate for 10 iterations (before
                                       the limit); best point returned */
    DOPUS_QP_DEADLINE = 7           /* cut by settings.deadline (settings.clock): one more
                                       iteration would have passed it; best point returned */
};

typedef struct {
    dopus_real tol;   /* tolerance on the scaled KKT residuals (default 1e-8) */
    int max_iter;     /* iteration limit (default 100) */
    int warm_start;   /* nonzero: start from the primal-dual point in *sol (default 0) */
    int refine_steps; /* iterative refinement steps of the corrector direction once the
                          scaled KKT residuals are below 1e-6 (more after a floored pivot);
                          default 1 */
    int active_set;   /* with warm_start: the active-set start (see the header comment) with
                          at most this many factorisations before the interior point; 0 (the
                          default): the interior point alone */
    /* A deadline (optional; clock NULL, the default: none). clock(clock_ctx) reads the
     * caller's clock (seconds, instructions, ...: any unit, increasing). Before each
     * factorisation of the solve (an interior-point iteration or a sweep of the active-set
     * start) the clock is read and the solve stops with DOPUS_QP_DEADLINE and its best point
     * when now plus the price of one iteration would pass `deadline`. The price is the
     * largest time between two reads of this solve, and `iter_price` (>= 0, the caller's
     * estimate) before the first such reading. */
    double (*clock)(void *clock_ctx);
    void *clock_ctx;
    double deadline;
    double iter_price;
    /* 1: the workspace holds the factorisation dopus_qp_prefactor (found convex) or
     * dopus_qp_prefactor_guess formed of this QP (the same data but x0, the same hess_shift;
     * nothing has solved or factored in it since); the solve takes the preparation the prefactor
     * did (Phi_k'; dopus_qp_prefactor_guess: the bounded rows and the Hessian scale too), and the
     * active-set start's first sweep uses the factor when its guess has the rows it was formed
     * with (none for dopus_qp_prefactor; the same active rows and penalty weights for
     * dopus_qp_prefactor_guess): that sweep's factorisation is this one, the same operations,
     * counted in dopus_qp_info.factorizations. 0 (the default): every factorisation formed in
     * the solve. */
    int prefactored;
} dopus_qp_settings;

typedef struct {
    /* stage matrices, one pointer per stage (see header comment for the shapes) */
    const dopus_real *H[DOPUS_N];
    const dopus_real *Phi[DOPUS_N];
    const dopus_real *C[DOPUS_N];
    const dopus_real *HN;
    const dopus_real *R;
    const dopus_real *Req;
    /* vectors */
    dopus_real g[DOPUS_N][DOPUS_QP_NW];
    dopus_real b[DOPUS_N][DOPUS_NX];
    dopus_real x0[DOPUS_NX];
    dopus_real gN[DOPUS_NX];
    dopus_real lbw[DOPUS_N][DOPUS_QP_NW];
    dopus_real ubw[DOPUS_N][DOPUS_QP_NW];
    dopus_real lbxN[DOPUS_NX];
    dopus_real ubxN[DOPUS_NX];
    dopus_real lg[DOPUS_N][DOPUS_QP_NG1];
    dopus_real ug[DOPUS_N][DOPUS_QP_NG1];
    dopus_real lr[DOPUS_QP_NR1];
    dopus_real ur[DOPUS_QP_NR1];
    dopus_real req[DOPUS_QP_NE1];
    /* proximal (Levenberg-Marquardt) term: the objective uses H_k + hess_shift I and
     * HN + hess_shift I instead of H_k and HN; 0 (the value of a zero-filled struct)
     * leaves the QP as given; must be finite and >= 0 */
    dopus_real hess_shift;
    /* soft weights (read only when DOPUS_NSOFT > 0; see the header comment): L1 (zl, zu)
     * and L2 (Zl, Zu) of the lower and upper side of row j of every stage (j = 0..nw+ng-1)
     * and of the terminal rows (j = 0..nx+nr-1: x_N, then R); finite and >= 0 */
    dopus_real zl[DOPUS_QP_NSS];
    dopus_real zu[DOPUS_QP_NSS];
    dopus_real Zl[DOPUS_QP_NSS];
    dopus_real Zu[DOPUS_QP_NSS];
    dopus_real zlN[DOPUS_QP_NST];
    dopus_real zuN[DOPUS_QP_NST];
    dopus_real ZlN[DOPUS_QP_NST];
    dopus_real ZuN[DOPUS_QP_NST];
} dopus_qp_in;

/* Primal-dual solution (output; also the warm-start point when settings.warm_start). */
typedef struct {
    dopus_real x[DOPUS_N + 1][DOPUS_NX];
    dopus_real u[DOPUS_N][DOPUS_QP_NU1];
    dopus_real lam[DOPUS_N + 1][DOPUS_NX];
    dopus_real mu_b[DOPUS_N][DOPUS_QP_NW];
    dopus_real mu_bN[DOPUS_NX];
    dopus_real mu_g[DOPUS_N][DOPUS_QP_NG1];
    dopus_real mu_r[DOPUS_QP_NR1];
    dopus_real nu[DOPUS_QP_NE1];
} dopus_qp_sol;

typedef struct {
    int status;                 /* enum dopus_qp_status */
    int iterations;             /* iterations taken: sweeps of the active-set start and interior-point
                                iterations (settings.max_iter bounds their sum) */
    int inertia_corrections;    /* factorisations retried with delta*I added to the Hessians */
    int terminal_augmentations; /* factorisations retried with rho Req'Req (exact, see top) */
    int pivot_floors;           /* Riccati pivots within their round-off estimate of zero that were
                                floored (cured by iterative refinement), summed over iterations */
    int factorizations;         /* factorisations of the Riccati recursion: one per interior-point
                                iteration, one per inertia correction and terminal augmentation,
                                one per sweep of the active-set start */
    int active_set;             /* sweeps of the active-set start when it solved the QP (they are
                                then its iterations), else 0 */
    int prefactored;            /* 1 when the start's first sweep took the factorisation
                                dopus_qp_prefactor or dopus_qp_prefactor_guess kept
                                (settings.prefactored), else 0 */
    int certified;              /* status DOPUS_QP_PRIMAL_INFEASIBLE: 1 when a row's lower bound lies
                                above its upper bound, or the certificate of the test during the
                                iteration separated beyond CERT_SEP and the tolerance (no point meets
                                the rows to the tolerance, from any start); 0 for one found only
                                after a stall, failure or the iteration limit (a separation down to
                                CERT_SEP_STALL) and for every other status */
    dopus_real delta;           /* largest delta used (0 when no correction was needed) */
    /* final residuals, infinity norms, unscaled */
    dopus_real res_stat; /* stationarity (both equations of the header comment) */
    dopus_real res_eq;   /* x0, dynamics and Req rows */
    dopus_real res_ineq; /* bound / constraint violation max(0, l - v, v - u) */
    dopus_real res_comp; /* complementarity max(slack * multiplier) over all sides */
    /* the same, scaled as compared with settings.tol */
    dopus_real res_stat_scaled;
    dopus_real res_eq_scaled;
    dopus_real res_ineq_scaled;
    dopus_real res_comp_scaled;
    dopus_real obj; /* objective value at the returned point */
} dopus_qp_info;

/* The whole solver memory; the user declares one (static, global or on a task stack).
 * Fields are internal. */
typedef struct {
    /* the inequality rows with a finite side ("bounded rows"), nb <= DOPUS_QP_NB of them in
     * increasing row order: the row, its sides and bounds; the rows of stage k are
     * b = bstart[k] .. bstart[k+1]-1 (k = N: the terminal rows). Every per-row array below
     * is indexed by b. */
    dopus_qp_row bidx[DOPUS_QP_NB];
    unsigned char has_lo[DOPUS_QP_NB];
    unsigned char has_up[DOPUS_QP_NB];
    dopus_qp_row bstart[DOPUS_N + 2];
    int nb;
    /* iterate: primal, equality multipliers, slacks and multipliers of each side */
    dopus_real prim[DOPUS_QP_NPRIM];
    dopus_real lam[(DOPUS_N + 1) * DOPUS_NX];
    dopus_real nu[DOPUS_QP_NE1];
    dopus_real t_lo[DOPUS_QP_NB];
    dopus_real t_up[DOPUS_QP_NB];
    dopus_real z_lo[DOPUS_QP_NB];
    dopus_real z_up[DOPUS_QP_NB];
    /* soft sides (DOPUS_NSOFT > 0): flags, slacks s >= 0 and their multipliers y, the
     * residual of the slack's stationarity (Z s + z_soft - z - y) and the steps */
    unsigned char soft_lo[DOPUS_QP_NBS];
    unsigned char soft_up[DOPUS_QP_NBS];
    dopus_real s_lo[DOPUS_QP_NBS];
    dopus_real s_up[DOPUS_QP_NBS];
    dopus_real y_lo[DOPUS_QP_NBS];
    dopus_real y_up[DOPUS_QP_NBS];
    dopus_real rs_lo[DOPUS_QP_NBS];
    dopus_real rs_up[DOPUS_QP_NBS];
    dopus_real ds_lo[DOPUS_QP_NBS];
    dopus_real ds_up[DOPUS_QP_NBS];
    dopus_real dy_lo[DOPUS_QP_NBS];
    dopus_real dy_up[DOPUS_QP_NBS];
    /* residuals */
    dopus_real r_stat[DOPUS_QP_NPRIM];
    dopus_real r_dyn[(DOPUS_N + 1) * DOPUS_NX];
    dopus_real r_eqN[DOPUS_QP_NE1];
    /* v - lo and up - v of the row values v = D w: the slack residuals and steps and the
     * barrier weights are formed from them and dv, t, z (the bounds are read from the QP
     * data where needed); the refinement of a direction also works in r_stat, r_dyn, r_eqN */
    dopus_real vl[DOPUS_QP_NB];
    dopus_real uv[DOPUS_QP_NB];
    /* Newton directions (the Newton right-hand side is formed in the direction arrays and
     * solved in place) */
    dopus_real d_prim[DOPUS_QP_NPRIM];
    dopus_real d_lam[(DOPUS_N + 1) * DOPUS_NX];
    dopus_real d_nu[DOPUS_QP_NE1];
    dopus_real dv[DOPUS_QP_NB]; /* D d_prim */
    dopus_real dz_lo[DOPUS_QP_NB];
    dopus_real dz_up[DOPUS_QP_NB];
    /* Riccati factorisation: condensed stage Hessians and value-function data */
#if DOPUS_QP_PHIT
    dopus_real PhiT[DOPUS_N][DOPUS_QP_NW * DOPUS_NX]; /* Phi_k' (nw x nx), formed once per solve */
    /* fuse: 1 while the solve's factorisation runs the predictor's backward sweep beside its
     * recursion; swept: 1 when the last factorisation did (the predictor's direction needs
     * only the forward sweep) */
    int fuse, swept;
#endif
    dopus_real M[DOPUS_QP_NW * DOPUS_QP_NW];             /* H + D'QD + delta I + Phi'P Phi */
    dopus_real P[DOPUS_N + 1][DOPUS_QP_NXP];             /* value function Hessians, packed lower */
    dopus_real G[DOPUS_N + 1][DOPUS_NX * DOPUS_QP_NE1];  /* value function x-nu coupling */
    dopus_real Lu[DOPUS_N][DOPUS_QP_NUP];                /* Cholesky factor of M_uu, packed, 1/diagonal */
    dopus_real K[DOPUS_N][DOPUS_QP_NU1 * DOPUS_NX];      /* Lu^{-1} M_ux (the gain is Lu'^{-1} of it) */
    dopus_real KN[DOPUS_N][DOPUS_QP_NU1 * DOPUS_QP_NE1]; /* Lu^{-1} (Phi'G)_u */
    dopus_real S[DOPUS_QP_NE1 * DOPUS_QP_NE1];           /* -(nu-nu block) at stage 0, factored */
    dopus_real e[DOPUS_QP_NE1];
    dopus_real work[DOPUS_QP_NWORK];
    dopus_real delta;               /* current inertia-correction shift */
    dopus_real rho_aug;             /* current terminal augmented-Lagrangian weight */
    dopus_real noise[DOPUS_QP_NU1]; /* round-off estimate of M_uu pivots */
    /* the active-set start: each bounded row's state (0 inactive, -1 lower side, +1 upper
     * side, 2 a row with lo == up) and its penalty weight; penalty: 1 while the factorisation
     * uses these weights in place of the barrier weights */
    signed char act[DOPUS_QP_NB];
    dopus_real pen[DOPUS_QP_NB];
    int penalty;
    /* the rows the start added after the sweep's factorisation (DOPUS_QP_AS_UPDATE at most),
     * held by the Schur complement of that factor: their rows, how many, and the Cholesky
     * factor of their Schur complement plus the inverse penalty weights (packed lower) */
    dopus_qp_row as_rows[DOPUS_QP_AS_UPDATE];
    int as_n;
    dopus_real as_L[DOPUS_QP_AS_UPDATE * (DOPUS_QP_AS_UPDATE + 1) / 2];
    /* dopus_qp_prefactor: its pivot floor (pre_tol > 0 while it factors: the floor max(pre_tol,
     * pre_roundoff times the largest |diagonal entry| of each stage's M_uu)), and what its or
     * dopus_qp_prefactor_guess's factorisation returned (-1: none kept: a pivot at or below the
     * floor or not finite, a factorisation since, or a guess without the kept working set,
     * which act and pen hold until the solve's guess) */
    dopus_real pre_tol;
    dopus_real pre_roundoff;
    int pre_status;
    /* dopus_qp_prefactor_guess: 1 when it set up the bounded rows (bidx, bstart, has_lo, has_up,
     * nb) as the solve would, with pre_hmax the solve's Hessian scale (check_input's hmax); a
     * solve with settings.prefactored and a kept factor takes them (and Phi_k') as they are */
    int pre_rows;
    dopus_real pre_hmax;
    int n_fact;            /* factorisations of the solve */
    int n_pre;             /* of them, the one a prefactor kept (0 or 1) */
    int pivot_floors;      /* pivots within round-off of zero, replaced (see linalg) */
    dopus_real scale_stat; /* residual scaling factors */
    dopus_real scale_eq;
    dopus_real scale_ineq;
    dopus_real scale_g; /* data parts of the scaling (constant during a solve) */
    dopus_real scale_b;
    dopus_real scale_bounds;
} dopus_qp_workspace;

#ifndef DOPUS_INTERNAL
#define DOPUS_INTERNAL
#endif

/* Default settings: tol 1e-8, max_iter 100, cold start, one refinement step. */
DOPUS_INTERNAL void dopus_qp_settings_default(dopus_qp_settings *settings);

/* sizeof(dopus_qp_workspace), the memory bill of the solver. */
DOPUS_INTERNAL unsigned long dopus_qp_workspace_size(void);

/* Solve the QP. `sol` is read as the warm-start point when settings->warm_start is
 * nonzero and always written (best point found; zeros on invalid input). `info` may be
 * NULL. Returns the status (enum dopus_qp_status). */
DOPUS_INTERNAL int dopus_qp_solve(dopus_qp_workspace *ws, const dopus_qp_in *in,
                                  const dopus_qp_settings *settings, dopus_qp_sol *sol, dopus_qp_info *info);

/* The convexity test of the automatic Levenberg-Marquardt term (dopus_lm.h) as the QP's own
 * factorisation: the Riccati recursion of the solve's first factorisation with no active row
 * (the active-set start's first sweep when its guess is empty: H_k + hess_shift I, no barrier
 * or penalty weight, no inertia correction, no terminal augmentation; C and R not read), every
 * control pivot required above max(tol, roundoff times the largest |diagonal entry| of its
 * stage's M_uu). Returns 1 when every pivot is (the QP convex on the dynamics), else 0. The
 * factorisation stays in ws for a solve of the same QP with settings.prefactored; any other use
 * of ws discards it. */
DOPUS_INTERNAL int dopus_qp_prefactor(dopus_qp_workspace *ws, const dopus_qp_in *in, dopus_real tol,
                                      dopus_real roundoff);

/* The active-set start's first factorisation of this QP from the warm start *sol, formed as a
 * solve with settings.warm_start and active_set forms it (its guess from the multipliers of
 * *sol, its primal part and the bounds; the penalty weights of the guessed active rows at the
 * Hessian scale with hess_shift). Returns 1 when it kept the factorisation in ws (it succeeded,
 * or found S singular, with no pivot floored), else 0. A solve of the same QP with
 * settings.prefactored then takes it for its first sweep when its own guess has the same
 * active rows with the same weights (else it factors); any other use of ws discards it. */
DOPUS_INTERNAL int dopus_qp_prefactor_guess(dopus_qp_workspace *ws, const dopus_qp_in *in,
                                            const dopus_qp_sol *sol);

/* After dopus_qp_solve returned DOPUS_QP_PRIMAL_INFEASIBLE (ws and in as they were then): the
 * row with the largest multiplier of the infeasibility certificate among the bounded rows
 * and the terminal equality rows, or a row whose lower bound lies above its upper bound.
 * stage: 0..N-1, or N for the terminal rows; row: within the stage in the order of the
 * header comment (w_k, then the rows of C_k; x_N, the rows of R, then those of Req); side:
 * -1 the lower bound, +1 the upper bound (an equality row: the sign of its multiplier), 0
 * lower above upper. Returns 1, or 0 when no row carries a multiplier. */
DOPUS_INTERNAL int dopus_qp_infeasible_row(const dopus_qp_workspace *ws, const dopus_qp_in *in, int *stage,
                                           int *row, int *side);

#endif /* DOPUS_QP_H */
