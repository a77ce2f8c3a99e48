/* The DOPUS real-time iteration: public API of the generated solver.
 *
 * DOPUS (Dynamic Optimization with Partially Updated Sensitivities, van Duijkeren et al.,
 * IFAC 2017) is an RTI scheme in which the stage sensitivities are shifted with the
 * horizon (a ring buffer of stage slots) and only the M stages with the largest secant
 * violation rho_k (eq. 16) are re-linearised per iteration; the QP gradient carries the
 * adjoint correction (eq. 12), so fixed points satisfy the exact KKT conditions.
 * docs/algorithm.md is the normative description of every step.
 *
 * Usage (receding horizon):
 *     static unicycle_solver s;
 *     unicycle_init(&s, xhat0, NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL);
 *     loop: unicycle_feedback(&s, xhat0, u0); apply u0; unicycle_prepare(&s);
 * The memory is one struct (sizeof is the memory bill; no malloc anywhere). It holds no
 * pointer into itself between calls, so a byte copy (memcpy, struct assignment: a snapshot,
 * a double buffer) is a complete solver, independent of the original. Settings may be
 * changed before unicycle_init; a struct that was never set up (zeroed or uninitialised
 * memory) gets the generated defaults on its first use.
 *
 * Array conventions: every array argument is a flat, C-contiguous (row-major) array of
 * doubles, node by node: x is (N+1) x nx (x + k*nx is node k), u is N x nu, lam (N+1) x nx,
 * mu_g N x ng, mu_b N x nw, mu_bN nx, mu_r nr, nu ne, parameters (N+1) x np. Multipliers are
 * signed (positive when the upper side of a row is active, negative for the lower side);
 * docs/algorithm.md section 1 gives the Lagrangian. Arrays of size zero are not read or
 * written (any pointer, also NULL, may be passed).
 *
 * Every function returning int returns a status (enum unicycle_status below) unless stated.
 * On failure the state stays consistent: a failed feedback takes no step; a failed
 * prepare leaves the shifted iterate, and the next prepare re-runs from there.
 */
#ifndef UNICYCLE_SOLVER_H
#define UNICYCLE_SOLVER_H

#include "unicycle_real.h"

#include <stddef.h>

/* UNICYCLE_CDEF_BEGIN */
typedef struct unicycle_solver unicycle_solver;

/* Size of struct unicycle_solver in bytes (for callers that allocate it as raw memory). */
size_t unicycle_solver_sizeof(void);
/* Reset every setting to the generated defaults (M, Hessian, regularisation, eps from the
 * OCP file, receding mode, QP tolerance 1e-10, parameters p_default at every node, default
 * clock) and mark the solver uninitialised. */
void unicycle_defaults(unicycle_solver *s);
/* Dimensions of the generated problem (nw = nx + nu); has_gn: a Gauss-Newton Hessian is
 * available (least-squares stage cost); has_nominal: unicycle_init_nominal has data. */
typedef struct {
    int N, nx, nu, nw, np, ng, nr, ne, has_gn, has_nominal;
} unicycle_dims;
void unicycle_get_dims(unicycle_dims *dims);
/* Problem name (the generator's UNICYCLE_NAME). */
const char *unicycle_name(void);
/* A short English description of a status code. */
const char *unicycle_status_string(int status);

/* Initialisation (algorithm.md section 4, init): the iterate is the given guess; NULL x or
 * u: the OCP file's initial guess; NULL multipliers: zeros. F and H of every stage and of
 * the terminal node are computed (regularised) at the guess, ring_head = 0, domega = 0,
 * rho = 0. xhat0 is checked and kept for unicycle_kkt_eval (may be NULL: the default x0).
 * A failed init leaves the solver uninitialised (NaN/Inf input: the iterate untouched). */
int unicycle_init(unicycle_solver *s, const unicycle_real *xhat0, const unicycle_real *x, const unicycle_real *u,
               const unicycle_real *lam, const unicycle_real *mu_g, const unicycle_real *mu_b, const unicycle_real *mu_bN,
               const unicycle_real *mu_r, const unicycle_real *nu);
/* Initialisation from the generated nominal primal-dual guess (the offline NLP solution at
 * the default x0); UNICYCLE_ERR_NO_NOMINAL when the solver was generated without one. */
int unicycle_init_nominal(unicycle_solver *s, const unicycle_real *xhat0);

/* Feedback phase: solve the prepared QP for the measured state xhat0 (nx), take the full
 * step and write u_0 (nu) into u0 (may be NULL). Non-finite xhat0: UNICYCLE_ERR_NONFINITE_INPUT,
 * nothing changes. QP failure: UNICYCLE_ERR_QP, no step (unicycle_get_qp_status tells why). */
int unicycle_feedback(unicycle_solver *s, const unicycle_real *xhat0, unicycle_real *u0);
/* Preparation phase: shift (receding mode), gradients and rho_k of every stage, fresh last
 * stage and terminal node, re-linearise the M stages with the largest rho_k, refresh the
 * stage-cost Hessian of the other stages (unicycle_set_cost_hessian), assemble the QP. Must
 * run between two feedback calls.
 * Calling order: one prepare per feedback on an initialised solver that reached the QP
 * (solved or not) and, in receding mode, also per feedback whose measurement was rejected
 * as non-finite (the sampling instant has passed all the same and the plan moves on with
 * it). prepare right after a successful init or prepare
 * returns UNICYCLE_ERR_ALREADY_PREPARED and changes nothing, in both modes (in receding mode
 * it would shift twice, in fixed mode it would measure rho_k against gradients of the
 * same point). After a failed prepare the next prepare is a retry: it does not shift
 * again, and it measures rho_k against the same F_old (the gradients of a failed prepare are
 * not stored); blocks that the failed attempt had already re-linearised stay fresh. */
int unicycle_prepare(unicycle_solver *s);
/* KKT measure (algorithm.md section 6) of the current iterate with exact derivatives, for
 * the initial state xhat0 (NULL: the last one given to init or feedback):
 * kkt4 = stat, eq, ineq, comp (may be NULL). Returns a status; the iterate is not changed.
 * The parts are >= 0 and never NaN; a part is +Inf when it overflows (an iterate or
 * multipliers near DBL_MAX, e.g. from an init guess: |mu| * |ub - v| > DBL_MAX). */
int unicycle_kkt_eval(unicycle_solver *s, const unicycle_real *xhat0, unicycle_real *kkt4);
/* The largest of the four parts of the last unicycle_kkt_eval (NaN before the first). */
unicycle_real unicycle_get_kkt(const unicycle_solver *s);

/* Settings. M: stages re-linearised per iteration besides stage N-1, 0 <= M <= N-1
 * (N-1 is the full RTI). mode: UNICYCLE_MODE_RECEDING or UNICYCLE_MODE_FIXED. hessian:
 * UNICYCLE_HESSIAN_EXACT or UNICYCLE_HESSIAN_GAUSS_NEWTON (only with a least-squares stage cost).
 * regularization: UNICYCLE_REG_NONE, UNICYCLE_REG_PROJECT or UNICYCLE_REG_MIRROR with eps > 0.
 * The QP tolerance (> 0) and iteration limit (>= 1) are those of unicycle_qp_solve. */
int unicycle_set_M(unicycle_solver *s, int M);
int unicycle_get_M(unicycle_solver *s);
int unicycle_set_mode(unicycle_solver *s, int mode);
int unicycle_get_mode(unicycle_solver *s);
int unicycle_set_hessian(unicycle_solver *s, int hessian);
int unicycle_get_hessian(unicycle_solver *s);
int unicycle_set_regularization(unicycle_solver *s, int regularization, unicycle_real eps);
int unicycle_get_regularization(unicycle_solver *s);
unicycle_real unicycle_get_reg_eps(unicycle_solver *s);
/* Stage-cost Hessian (algorithm.md section 4 step 5): fresh = 1 (the default) refreshes the
 * cost part A_l of the Hessian block of every stage in every prepare (only the curvature of
 * dynamics and constraints is partially updated); fresh = 0 is the paper's literal
 * algorithm (the whole A moves with its slot). The slots always carry A_dyn = A - A_l, so
 * the setting may change between any two calls. */
int unicycle_set_cost_hessian(unicycle_solver *s, int fresh);
int unicycle_get_cost_hessian(unicycle_solver *s);
/* Levenberg-Marquardt term (algorithm.md section 3): the QP minimises with the Hessian
 * blocks A~_k + lm I and A~_N + lm I (the stored blocks are not changed, so the secant
 * criterion and the fixed point are those of lm = 0). lm finite and >= 0: a fixed term
 * (the automatic one is switched off); default: the OCP file's options(lm=...), else the
 * automatic term. */
int unicycle_set_levenberg_marquardt(unicycle_solver *s, unicycle_real lm);
/* The term of the next QP (fixed, or the current automatic value). */
unicycle_real unicycle_get_levenberg_marquardt(unicycle_solver *s);
/* The automatic, scale-aware, adaptive term (docs/algorithm.md section 10): lm is raised
 * until the QP is convex on the dynamics (Riccati pivots positive definite), after a
 * failed feedback and when the KKT proxy grows; lowered after every successful feedback. */
int unicycle_set_lm_auto(unicycle_solver *s);
int unicycle_get_lm_auto(unicycle_solver *s);
/* The Hessian scale of the automatic term (largest diagonal entry of the QP blocks). */
unicycle_real unicycle_get_lm_scale(unicycle_solver *s);
/* QP tolerance: 0 < tol <= UNICYCLE_QP_TOL_MAX (1e-2); a larger one would let the QP return
 * steps that violate the bounds by that much, so it is refused (UNICYCLE_ERR_INVALID_ARGUMENT). */
int unicycle_set_qp_tol(unicycle_solver *s, unicycle_real tol);
unicycle_real unicycle_get_qp_tol(unicycle_solver *s);
int unicycle_set_qp_max_iter(unicycle_solver *s, int max_iter);
int unicycle_get_qp_max_iter(unicycle_solver *s);
/* Automatic recovery (docs/algorithm.md section 9), receding mode only: on (1, the default)
 * or off (0), and K >= 1, the number of consecutive failed feedbacks after which the next
 * prepare re-initialises (default UNICYCLE_RECOVERY_FAILURES). A detected divergence
 * re-initialises at once. While on, the prepare after a failed feedback first takes the step
 * of that instant's QP for the state the iterate predicts (UNICYCLE_FLAG_PREDICTED): the plan of
 * the next fallbacks stays current; after a non-finite measurement it clears the count. A
 * feedback whose QP fails (not by its iteration limit) or diverges on a finite measurement
 * re-initialises from that measurement and solves the new QP within the same call before it
 * gives up (UNICYCLE_FLAG_RECOVERED; at most one re-initialisation and one QP with its lm
 * retries); a measurement at which the model is not finite is handled as a missing one
 * (UNICYCLE_ERR_NONFINITE_VALUE, UNICYCLE_FLAG_MEASUREMENT_UNUSABLE). A feedback refused for want of
 * a prepared QP still records its measurement: the recovery starts from the newest one. */
int unicycle_set_recovery(unicycle_solver *s, int on, int max_failures);
int unicycle_get_recovery(unicycle_solver *s);
int unicycle_get_recovery_failures(unicycle_solver *s);
/* QP warm start in feedback (1, the default): start from the previous QP solution shifted
 * with the horizon (a zero step from the shifted iterate, the iterate's multipliers); when
 * that QP is not solved, feedback retries from the cold starting point in the same call.
 * 0: always cold. */
int unicycle_set_qp_warm_start(unicycle_solver *s, int on);
int unicycle_get_qp_warm_start(unicycle_solver *s);
/* Runtime parameters: all nodes ((N+1) x np) or node k (np); used from the next function
 * evaluation on (prepare, kkt). */
int unicycle_set_parameters(unicycle_solver *s, const unicycle_real *p);
int unicycle_set_parameters_node(unicycle_solver *s, int k, const unicycle_real *pk);
void unicycle_get_parameters(unicycle_solver *s, unicycle_real *p);

/* The iterate (shapes in the header comment). */
void unicycle_get_x(const unicycle_solver *s, unicycle_real *x);
void unicycle_get_u(const unicycle_solver *s, unicycle_real *u);
void unicycle_get_lam(const unicycle_solver *s, unicycle_real *lam);
void unicycle_get_mu_g(const unicycle_solver *s, unicycle_real *mu_g);
void unicycle_get_mu_b(const unicycle_solver *s, unicycle_real *mu_b);
void unicycle_get_mu_bN(const unicycle_solver *s, unicycle_real *mu_bN);
void unicycle_get_mu_r(const unicycle_solver *s, unicycle_real *mu_r);
void unicycle_get_nu(const unicycle_solver *s, unicycle_real *nu);
/* rho_k (N) of the last prepare (eq. 16; 0 for stage N-1): >= 0, never NaN; +Inf when the
 * residual or the step of the stage overflows (the stage then ranks first). */
void unicycle_get_rho(const unicycle_solver *s, unicycle_real *rho);
/* Stages whose H was computed fresh by the last prepare (or init), sorted ascending, stage
 * N-1 included; writes up to N ints and returns their count. */
int unicycle_get_recomputed(const unicycle_solver *s, int *stages);
/* The last QP: iterations, status (enum unicycle_qp_status of unicycle_qp.h). */
int unicycle_get_qp_iterations(const unicycle_solver *s);
int unicycle_get_qp_status(const unicycle_solver *s);
/* A constraint row of the OCP at one stage of the horizon. */
typedef struct {
    int stage;        /* 0..N-1; N: the terminal node */
    int kind;         /* enum unicycle_row_kind */
    int index;        /* the state or control, or the row among the path rows, the terminal
                     inequality rows or the terminal equality rows (each stacked in
                     declaration order) */
    int side;         /* -1: its lower bound, +1: its upper bound (an equality row: the sign of
                     the certificate's multiplier), 0: lower bound above upper bound */
    unicycle_real bound; /* the bound's value (the lower one for side 0; 0 for an equality row, whose
                     function is the declared row minus its value) */
} unicycle_row_info;
/* When the last QP was infeasible (unicycle_get_qp_status UNICYCLE_QP_PRIMAL_INFEASIBLE): the row
 * with the largest multiplier of its infeasibility certificate, the row that the other rows
 * of the certificate (the bounds, dynamics and measured state) keep from being met; stages
 * are those of that QP's horizon. Returns 1 and writes *row, else returns 0. */
int unicycle_get_qp_infeasible_row(const unicycle_solver *s, unicycle_row_info *row);
/* Health of the controller (docs/algorithm.md section 9). Flags (UNICYCLE_FLAG_*) raised by
 * the last feedback and the prepare after it (feedback clears them): the returned u0 was
 * clipped to the control bounds, u0 is the fallback of a failed feedback (the next control
 * of the last good plan), a divergence was detected, the prepare re-initialised. */
int unicycle_get_flags(const unicycle_solver *s);
/* The control returned by the last feedback (nu), successful or not; within the bounds. */
void unicycle_get_u0(const unicycle_solver *s, unicycle_real *u0);
/* Re-initialisations by the automatic recovery since init; consecutive failed feedbacks. */
int unicycle_get_recoveries(const unicycle_solver *s);
int unicycle_get_failed_feedbacks(const unicycle_solver *s);
/* The divergence measure of the last prepare or init: the stationarity and equality parts of
 * the KKT measure at the prepared point (max |F_w,k + [lam_k; 0]|, |phi_k - x_{k+1}|, ...);
 * and the scale of the box test of the iterate: state (nx) and control (nu) scales. */
unicycle_real unicycle_get_kkt_proxy(const unicycle_solver *s);
void unicycle_get_scales(const unicycle_solver *s, unicycle_real *scale_x, unicycle_real *scale_u);
/* 1 when the last feedback's warm-started QP failed and the cold retry ran (the
 * iterations above are then the sum of both solves), else 0. */
int unicycle_get_qp_cold_retry(const unicycle_solver *s);
/* Status of the last call that returns a status. */
int unicycle_get_status(const unicycle_solver *s);
int unicycle_is_initialized(const unicycle_solver *s);
/* ring_head (stage k lives in slot (ring_head + k) mod N). */
int unicycle_get_ring_head(const unicycle_solver *s);

/* Seconds per phase of the last call that ran it (t[0..7] = feedback, shift, gradients,
 * rho, hessians, regularization, assembly, kkt; indices of enum unicycle_phase). init fills
 * the phases it runs too. "hessians" includes the stage-cost Hessians A_l. */
void unicycle_get_timings(const unicycle_solver *s, double *t);
/* Replace the clock (seconds, any origin); NULL restores the default clock. The default
 * clock is CLOCK_MONOTONIC where the platform has POSIX timers; on bare metal there is none
 * and every timing reads 0 until a clock is installed (unicycle_timer.h). */
void unicycle_set_clock(unicycle_solver *s, double (*clock_fn)(void *ctx), void *ctx);
/* 1 if the timings measure time (a clock was installed, or the default clock exists on
 * this platform), 0 if they read 0 for want of a clock. */
int unicycle_has_clock(const unicycle_solver *s);
/* Anytime DOPUS (docs/algorithm.md section 12): a budget per sampling instant, counted
 * from the start of the instant's feedback. In time (seconds of the solver's clock, unicycle_set_clock:
 * on firmware an instruction or cycle counter) or in work units (stage_grad, stage_hess,
 * term_grad and term_hess evaluations count 1 each, a QP solve counts N; deterministic, the
 * unit of the Python reference). 0 switches it off (the plain real-time iteration). With a
 * budget, prepare re-linearises stages beyond stage N-1 only while the budget allows, first
 * the M (or adaptive M) stages, then further stages in rho order, and spends the rest on
 * SQP iterations on the next instant's problem at the state the plan predicts (dx_0 = 0)
 * while the KKT proxy exceeds the anytime tolerance; the next feedback starts from that
 * iterate. The feedback's QP iterations are capped by the budget left (the fallback control
 * when the cap stops it). */
int unicycle_set_time_budget(unicycle_solver *s, double seconds);
int unicycle_set_work_budget(unicycle_solver *s, double units);
/* UNICYCLE_BUDGET_OFF, UNICYCLE_BUDGET_TIME or UNICYCLE_BUDGET_WORK, and the budget in its unit. */
int unicycle_get_budget_unit(const unicycle_solver *s);
double unicycle_get_budget(const unicycle_solver *s);
/* KKT proxy (unicycle_get_kkt_proxy) below which no further iteration is spent; > 0. */
int unicycle_set_anytime_tol(unicycle_solver *s, unicycle_real tol);
unicycle_real unicycle_get_anytime_tol(const unicycle_solver *s);
/* Adaptive M (docs/algorithm.md section 12): each iteration re-linearises the stages whose
 * secant residual rho_k |domega_k| exceeds eta times the KKT proxy, at least M_min and at
 * most M_max of them (0 <= M_min <= M_max), the largest rho_k first. on = 0: the fixed M of
 * unicycle_set_M. eta > 0. */
int unicycle_set_M_adaptive(unicycle_solver *s, int on, int M_min, int M_max, unicycle_real eta);
int unicycle_get_M_adaptive(const unicycle_solver *s, int *M_min, int *M_max, unicycle_real *eta);
/* The last instant: extra iterations after prepare, stages re-linearised over all its
 * iterations (stage N-1 and the terminal node not counted), budget used (its unit). */
int unicycle_get_extra_iterations(const unicycle_solver *s);
int unicycle_get_instant_stages(const unicycle_solver *s);
double unicycle_get_budget_used(const unicycle_solver *s);
/* Work units counted since the solver was set up (the unit of unicycle_set_work_budget). */
double unicycle_get_work(const unicycle_solver *s);
/* UNICYCLE_CDEF_END */

/* Status codes returned by the functions above. */
enum unicycle_status {
    UNICYCLE_OK = 0,
    UNICYCLE_ERR_QP = 1,                /* QP not solved; no step; see unicycle_get_qp_status */
    UNICYCLE_ERR_NONFINITE_INPUT = 2,   /* NaN or Inf in an input array */
    UNICYCLE_ERR_NONFINITE_VALUE = 3,   /* a generated function returned NaN or Inf */
    UNICYCLE_ERR_FUNCTION = 4,          /* a generated function reported failure */
    UNICYCLE_ERR_INVALID_ARGUMENT = 5,  /* M out of range, bad mode/Hessian/regularisation,
                                        Gauss-Newton without least squares, bad node index */
    UNICYCLE_ERR_NOT_INITIALIZED = 6,   /* feedback/prepare/kkt before a successful init */
    UNICYCLE_ERR_NOT_PREPARED = 7,      /* feedback without a successful prepare since the last
                                        step (the QP would be stale) */
    UNICYCLE_ERR_NO_NOMINAL = 8,        /* unicycle_init_nominal without UNICYCLE_HAS_NOMINAL */
    UNICYCLE_ERR_REGULARIZATION = 9,    /* eigen-decomposition did not converge */
    UNICYCLE_ERR_ALREADY_PREPARED = 10, /* prepare without a feedback since the last successful
                                        init or prepare (it would shift the horizon twice);
                                        nothing changes */
    UNICYCLE_ERR_DIVERGED = 11          /* the QP step leaves the problem's scale box (or is not
                                        finite): no step, the fallback control is returned */
};

/* Kinds of unicycle_row_info. */
enum unicycle_row_kind {
    UNICYCLE_ROW_STATE = 0,      /* a bound of a state (stages 1..N) */
    UNICYCLE_ROW_CONTROL = 1,    /* a bound of a control */
    UNICYCLE_ROW_PATH = 2,       /* a path-constraint row */
    UNICYCLE_ROW_TERMINAL = 3,   /* a terminal inequality row (lb < ub) */
    UNICYCLE_ROW_TERMINAL_EQ = 4 /* a terminal equality row (lb == ub) */
};

/* Flags of unicycle_get_flags (docs/algorithm.md section 9). */
enum unicycle_flag {
    UNICYCLE_FLAG_U0_CLIPPED = 1,           /* u0 was outside the control bounds and was clipped */
    UNICYCLE_FLAG_FALLBACK = 2,             /* feedback failed: u0 is the next control of the last good plan */
    UNICYCLE_FLAG_DIVERGED = 4,             /* the step or the prepared iterate failed the divergence test */
    UNICYCLE_FLAG_RECOVERED = 8,            /* prepare or feedback re-initialised (automatic recovery) */
    UNICYCLE_FLAG_PREDICTED = 16,           /* prepare took the step of the QP for the predicted state */
    UNICYCLE_FLAG_REINIT_GUESS = 32,        /* a re-initialisation fell back to the OCP file's guess: the
                                     model was not finite at the re-initialised iterate */
    UNICYCLE_FLAG_MEASUREMENT_UNUSABLE = 64 /* the model is not finite at the (finite) measurement:
                                            handled as a missing one */
};

/* Safety constants (docs/algorithm.md section 9). */
#define UNICYCLE_QP_TOL_MAX UNICYCLE_R(1e-2)    /* largest accepted QP tolerance */
#define UNICYCLE_RECOVERY_FAILURES 2         /* default K: consecutive failures before recovery */
#define UNICYCLE_RECOVERY_FULL_RTI 10        /* successful feedbacks with every block fresh after a recovery */
#define UNICYCLE_DIVERGENCE_BOX UNICYCLE_R(1e3) /* |x_k,i| <= 1e3 scale_x_i + |xhat0_i|, same for u */
#define UNICYCLE_DIVERGENCE_KKT UNICYCLE_R(1e6) /* kkt proxy <= 1e6 max(1, proxy at the last init) */

/* Automatic Levenberg-Marquardt term (docs/algorithm.md section 10), relative to the
 * Hessian scale h = max(1e-300, largest |diagonal entry| of the QP's blocks). */
#define UNICYCLE_LM_MIN_REL UNICYCLE_R(1e-8)    /* smallest nonzero term: 1e-8 h (below: 0) */
#define UNICYCLE_LM_MAX_REL UNICYCLE_R(1e2)     /* largest term: 1e2 h */
#define UNICYCLE_LM_RAISE UNICYCLE_R(10.0)      /* factor of a raise */
#define UNICYCLE_LM_LOWER UNICYCLE_R(0.1)       /* factor after a successful feedback */
#define UNICYCLE_LM_PIVOT_REL UNICYCLE_R(1e-10) /* Riccati pivots must exceed 1e-10 h */
#define UNICYCLE_LM_KKT_GROWTH UNICYCLE_R(10.0) /* raise when the KKT proxy grows 10x in one prepare */
#define UNICYCLE_LM_RETRIES 2                /* QP solves again with lm raised after a failure */
#define UNICYCLE_LM_KKT_REL UNICYCLE_R(1e-2)    /* feedback: lm <= 1e-2 h d^2, d the distance from the solution */

enum unicycle_mode {
    UNICYCLE_MODE_RECEDING = 0, /* shift by one sampling interval in every prepare */
    UNICYCLE_MODE_FIXED = 1     /* no shift: fixed-xhat0 convergence studies */
};

enum unicycle_hessian { UNICYCLE_HESSIAN_EXACT = 0, UNICYCLE_HESSIAN_GAUSS_NEWTON = 1 };

/* Units of the anytime budget (docs/algorithm.md section 12). */
enum unicycle_budget_unit {
    UNICYCLE_BUDGET_OFF = 0,  /* no budget: the plain real-time iteration */
    UNICYCLE_BUDGET_TIME = 1, /* seconds of the solver's clock */
    UNICYCLE_BUDGET_WORK = 2  /* work units: function evaluations 1, a QP solve N */
};

/* Anytime constants (docs/algorithm.md section 12). */
#define UNICYCLE_ANYTIME_TOL UNICYCLE_PREC(1e-8, 2e-5) /* default KKT proxy target of the extra iterations */
#define UNICYCLE_ANYTIME_MAX_ITER 50                /* extra iterations per instant at most */
#define UNICYCLE_ADAPTIVE_ETA UNICYCLE_R(0.1)          /* default eta of adaptive M */
#define UNICYCLE_WORK_QP UNICYCLE_N                    /* work units of a QP solve */

/* ------------------------------------------------------------------------------------- */
/* The full state. Its layout is public so firmware can declare `static unicycle_solver s;`;
 * the fields are internal (use the functions above). */

#include "unicycle_sizes.h"
#include "unicycle_funcs.h"
#include "unicycle_qp.h"
#include "unicycle_reg.h"
#include "unicycle_ring.h"
#include "unicycle_timer.h"

/* Memory that is live only in some calls: the QP's workspace and its solution (also the
 * warm-start point) in feedback; the scratch of the generated functions, the regularisation,
 * the convexity test of the automatic lm and F_new in init, prepare and kkt. Never both at
 * once, so they share it. */
typedef union {
    struct {
        unicycle_qp_workspace work;
        unicycle_qp_sol sol;
    } qp;
    struct {
        unicycle_fun_work fun_work;
        /* F_new of stages 0..N-2 (prepare step 2), stored as F_old only when prepare
         * succeeds, so a prepare that fails leaves every F_old for its retry */
        unicycle_real Fn_w[UNICYCLE_N][UNICYCLE_NW];
        unicycle_real Fn_phi[UNICYCLE_N][UNICYCLE_NX];
        unicycle_real Fn_g[UNICYCLE_N][UNICYCLE_DIM(UNICYCLE_NG)];
        unicycle_real tmp_A[UNICYCLE_NW * UNICYCLE_NW];
        unicycle_real tmp_Al[UNICYCLE_NW * UNICYCLE_NW];
        unicycle_real tmp_Phi[UNICYCLE_NX * UNICYCLE_NW];
        unicycle_real tmp_C[UNICYCLE_DIM(UNICYCLE_NG * UNICYCLE_NW)];
        unicycle_real tmp_gL[UNICYCLE_NW];
        unicycle_real tmp_F[UNICYCLE_NW];
        unicycle_real tmp_phi[UNICYCLE_NX];
        unicycle_real tmp_g[UNICYCLE_DIM(UNICYCLE_NG)];
        unicycle_real reg_work[2 * UNICYCLE_NW * UNICYCLE_NW];
        /* Riccati workspace of the convexity test of the automatic lm */
        unicycle_real lm_P[UNICYCLE_NX * UNICYCLE_NX];
        unicycle_real lm_PA[UNICYCLE_NX * UNICYCLE_NW];
        unicycle_real lm_G[UNICYCLE_NW * UNICYCLE_NW];
    } ev;
} unicycle_solver_mem;

struct unicycle_solver {
    int magic;       /* UNICYCLE_MAGIC once the settings hold valid values */
    int initialized; /* a successful init happened */
    int qp_ready;    /* QP assembled at the current iterate (prepare or init succeeded) */
    int prepare_due; /* a feedback reached the QP since the last successful init/prepare */
    int shifted;     /* the shift of this sampling instant is done (a prepare failed after it) */
    int status;      /* status of the last call */

    /* settings */
    int M;
    int mode;
    int hessian;
    int regularization;
    unicycle_real reg_eps;
    int cost_hessian;       /* 1: fresh stage-cost Hessian in every prepare, 0: stored */
    unicycle_real lm;          /* Levenberg-Marquardt term of the QP Hessian (fixed, or the
                           current automatic value) */
    int lm_auto;            /* 1: automatic term (section 10) */
    unicycle_real lm_scale;    /* Hessian scale h of the automatic term */
    unicycle_real lm_kkt_prev; /* KKT proxy of the previous prepare (< 0: none since init) */
    unicycle_real lm_uncapped; /* the term before the cap of this feedback (< 0: not capped) */
    unicycle_qp_settings qp_settings;

    /* iterate (algorithm.md section 1) */
    unicycle_real x[UNICYCLE_N + 1][UNICYCLE_NX];
    unicycle_real u[UNICYCLE_N][UNICYCLE_NU];
    unicycle_real lam[UNICYCLE_N + 1][UNICYCLE_NX];
    unicycle_real mu_g[UNICYCLE_N][UNICYCLE_DIM(UNICYCLE_NG)];
    unicycle_real mu_b[UNICYCLE_N][UNICYCLE_NW];
    unicycle_real mu_bN[UNICYCLE_NX];
    unicycle_real mu_r[UNICYCLE_DIM(UNICYCLE_NR)];
    unicycle_real nu[UNICYCLE_DIM(UNICYCLE_NE)];
    unicycle_real p[UNICYCLE_N + 1][UNICYCLE_DIM(UNICYCLE_NP)];
    unicycle_real xhat0[UNICYCLE_NX];

    /* stage slots (Ht, A_dyn, Phit, Ct, F_old, domega) and ring_head */
    unicycle_ring ring;

    /* terminal node, always fresh: A (regularised), R, R_eq and F = (gL, E, r, r_eq) */
    unicycle_real A_N[UNICYCLE_NX * UNICYCLE_NX];
    unicycle_real R[UNICYCLE_DIM(UNICYCLE_NR) * UNICYCLE_NX];
    unicycle_real R_eq[UNICYCLE_DIM(UNICYCLE_NE) * UNICYCLE_NX];
    unicycle_real gL_N[UNICYCLE_NX];
    unicycle_real E;
    unicycle_real r[UNICYCLE_DIM(UNICYCLE_NR)];
    unicycle_real r_eq[UNICYCLE_DIM(UNICYCLE_NE)];

    /* secant criterion and the recomputed set of the last prepare */
    unicycle_real rho[UNICYCLE_N];
    int recomputed[UNICYCLE_N];
    int n_recomputed;
    unsigned char selected[UNICYCLE_N];

    /* QP data: the vectors; the matrix pointers are set to the ring slots and the terminal
     * blocks only during a QP solve (NULL between calls, so a byte copy is a valid solver) */
    unicycle_qp_in qp_in;
    unicycle_qp_info qp_info;
    int qp_status;
    int qp_iterations;
    int qp_warm;       /* warm start in feedback (unicycle_set_qp_warm_start) */
    int qp_cold_retry; /* the last feedback needed the cold retry */

    /* the QP's workspace and solution, live only inside feedback, share their memory with
     * the scratch of the function evaluations, live only outside it (unicycle_solver_mem) */
    unicycle_solver_mem mem;

    /* safe outputs, divergence test and recovery (algorithm.md section 9) */
    int recovery;          /* automatic recovery on */
    int recovery_failures; /* K */
    int n_failed;          /* consecutive failed feedbacks */
    int recover_pending;   /* the next prepare re-initialises */
    int flags;             /* UNICYCLE_FLAG_* of the last feedback + prepare */
    int n_recoveries;
    int recovering;                       /* full-RTI prepares left after a recovery */
    int xhat_fresh;                       /* the last feedback had a finite measurement */
    int plan_age;                         /* receding shifts since the last good plan */
    unicycle_real plan_u[UNICYCLE_N][UNICYCLE_NU]; /* controls of the last good plan */
    unicycle_real u0_out[UNICYCLE_NU];          /* the control returned by the last feedback */
    unicycle_real scale_x[UNICYCLE_NX];
    unicycle_real scale_u[UNICYCLE_NU];
    unicycle_real kkt_proxy;
    unicycle_real kkt_proxy_ref;

    /* KKT parts of the last unicycle_kkt_eval: stat, eq, ineq, comp */
    unicycle_real kkt[4];

    unicycle_timer timer;

    /* anytime budget (algorithm.md section 12) */
    int budget_unit;        /* enum unicycle_budget_unit */
    double budget;          /* per instant, in its unit */
    unicycle_real anytime_tol; /* no extra iteration below this KKT proxy */
    int M_adaptive;         /* 1: adaptive M between M_min and M_max */
    int M_min, M_max;
    unicycle_real M_eta;
    double work;          /* work units counted since setup */
    double instant_start; /* budget clock at the start of the instant's feedback */
    double cost_stage;    /* estimated cost of one stage re-linearisation */
    double cost_qp;       /* cost of the last QP solve */
    double cost_prepare;  /* cost of the last prepare iteration without its extension */
    double cost_qp_iter;  /* cost of one QP iteration (the feedback's cap) */
    double budget_used;   /* budget used by the last instant */
    int qp_capped;        /* the feedback's QP iterations are capped by the budget */
    int extra_iterations; /* extra iterations of the last prepare */
    int instant_stages;   /* stages re-linearised in the last instant */
};

#endif /* UNICYCLE_SOLVER_H */
