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
 *     static dopus_solver s;
 *     dopus_init(&s, xhat0, NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL);
 *     loop: dopus_feedback(&s, xhat0, u0); apply u0; dopus_prepare(&s);
 * The memory is one struct (sizeof is the memory bill; no malloc anywhere). It holds no
 * pointer into itself between calls, so a byte copy (memcpy, struct assignment: a snapshot,
 * a double buffer) is a complete solver, independent of the original. Settings may be
 * changed before dopus_init; a struct that was never set up (zeroed or uninitialised
 * memory) gets the generated defaults on its first use.
 *
 * Array conventions: every array argument is a flat, C-contiguous (row-major) array of
 * doubles, node by node: x is (N+1) x nx (x + k*nx is node k), u is N x nu, lam (N+1) x nx,
 * mu_g N x ng, mu_b N x nw, mu_bN nx, mu_r nr, nu ne, parameters (N+1) x np. Multipliers are
 * signed (positive when the upper side of a row is active, negative for the lower side);
 * docs/algorithm.md section 1 gives the Lagrangian. Arrays of size zero are not read or
 * written (any pointer, also NULL, may be passed).
 *
 * Every function returning int returns a status (enum dopus_status below) unless stated.
 * On failure the state stays consistent: a failed feedback takes no step; a failed
 * prepare leaves the shifted iterate, and the next prepare re-runs from there.
 */
#ifndef DOPUS_SOLVER_H
#define DOPUS_SOLVER_H

#include "dopus_real.h"

#include <stddef.h>

/* DOPUS_CDEF_BEGIN */
typedef struct dopus_solver dopus_solver;

/* Size of struct dopus_solver in bytes (for callers that allocate it as raw memory). */
size_t dopus_solver_sizeof(void);
/* Reset every setting to the generated defaults (M, Hessian, regularisation, eps from the
 * OCP file, receding mode, QP tolerance 1e-10, parameters p_default at every node, default
 * clock) and mark the solver uninitialised. */
void dopus_defaults(dopus_solver *s);
/* Dimensions of the generated problem (nw = nx + nu); has_gn: a Gauss-Newton Hessian is
 * available (least-squares stage cost); has_nominal: dopus_init_nominal has data. */
typedef struct {
    int N, nx, nu, nw, np, ng, nr, ne, has_gn, has_nominal;
} dopus_dims;
void dopus_get_dims(dopus_dims *dims);
/* Problem name (the generator's DOPUS_NAME). */
const char *dopus_name(void);
/* A short English description of a status code. */
const char *dopus_status_string(int status);

/* Initialisation (algorithm.md section 4, init): the iterate is the given guess; NULL x or
 * u: the OCP file's initial guess; NULL multipliers: zeros. F and H of every stage and of
 * the terminal node are computed (regularised) at the guess, ring_head = 0, domega = 0,
 * rho = 0. xhat0 is checked and kept for dopus_kkt_eval (may be NULL: the default x0).
 * A failed init leaves the solver uninitialised (NaN/Inf input: the iterate untouched). */
int dopus_init(dopus_solver *s, const dopus_real *xhat0, const dopus_real *x, const dopus_real *u,
               const dopus_real *lam, const dopus_real *mu_g, const dopus_real *mu_b, const dopus_real *mu_bN,
               const dopus_real *mu_r, const dopus_real *nu);
/* Initialisation from the generated nominal primal-dual guess (the offline NLP solution at
 * the default x0); DOPUS_ERR_NO_NOMINAL when the solver was generated without one. */
int dopus_init_nominal(dopus_solver *s, const dopus_real *xhat0);

/* Feedback phase: solve the prepared QP for the measured state xhat0 (nx), take the full
 * step and write u_0 (nu) into u0 (may be NULL). Non-finite xhat0: DOPUS_ERR_NONFINITE_INPUT,
 * nothing changes. QP failure: DOPUS_ERR_QP, no step (dopus_get_qp_status tells why). */
int dopus_feedback(dopus_solver *s, const dopus_real *xhat0, dopus_real *u0);
/* Preparation phase: shift (receding mode), gradients and rho_k of every stage, fresh last
 * stage and terminal node, re-linearise the M stages with the largest rho_k, refresh the
 * stage-cost Hessian of the other stages (dopus_set_cost_hessian), assemble the QP. Must
 * run between two feedback calls.
 * Calling order: one prepare per feedback on an initialised solver that reached the QP
 * (solved or not) and, in receding mode, also per feedback whose measurement was rejected
 * as non-finite (the sampling instant has passed all the same and the plan moves on with
 * it). prepare right after a successful init or prepare
 * returns DOPUS_ERR_ALREADY_PREPARED and changes nothing, in both modes (in receding mode
 * it would shift twice, in fixed mode it would measure rho_k against gradients of the
 * same point). After a failed prepare the next prepare is a retry: it does not shift
 * again, and it measures rho_k against the same F_old (the gradients of a failed prepare are
 * not stored); blocks that the failed attempt had already re-linearised stay fresh. */
int dopus_prepare(dopus_solver *s);
/* KKT measure (algorithm.md section 6) of the current iterate with exact derivatives, for
 * the initial state xhat0 (NULL: the last one given to init or feedback):
 * kkt4 = stat, eq, ineq, comp (may be NULL). Returns a status; the iterate is not changed.
 * The parts are >= 0 and never NaN; a part is +Inf when it overflows (an iterate or
 * multipliers near DBL_MAX, e.g. from an init guess: |mu| * |ub - v| > DBL_MAX). */
int dopus_kkt_eval(dopus_solver *s, const dopus_real *xhat0, dopus_real *kkt4);
/* The largest of the four parts of the last dopus_kkt_eval (NaN before the first). */
dopus_real dopus_get_kkt(const dopus_solver *s);

/* Settings. M: stages re-linearised per iteration besides stage N-1, 0 <= M <= N-1
 * (N-1 is the full RTI). mode: DOPUS_MODE_RECEDING or DOPUS_MODE_FIXED. hessian:
 * DOPUS_HESSIAN_EXACT or DOPUS_HESSIAN_GAUSS_NEWTON (only with a least-squares stage cost).
 * regularization: DOPUS_REG_NONE, DOPUS_REG_PROJECT or DOPUS_REG_MIRROR with eps > 0.
 * The QP tolerance (> 0) and iteration limit (>= 1) are those of dopus_qp_solve. */
int dopus_set_M(dopus_solver *s, int M);
int dopus_get_M(dopus_solver *s);
int dopus_set_mode(dopus_solver *s, int mode);
int dopus_get_mode(dopus_solver *s);
int dopus_set_hessian(dopus_solver *s, int hessian);
int dopus_get_hessian(dopus_solver *s);
int dopus_set_regularization(dopus_solver *s, int regularization, dopus_real eps);
int dopus_get_regularization(dopus_solver *s);
dopus_real dopus_get_reg_eps(dopus_solver *s);
/* Stage-cost Hessian (algorithm.md section 4 step 5): fresh = 1 (the default) refreshes the
 * cost part A_l of the Hessian block of every stage in every prepare (only the curvature of
 * dynamics and constraints is partially updated); fresh = 0 is the paper's literal
 * algorithm (the whole A moves with its slot). The slots always carry A_dyn = A - A_l, so
 * the setting may change between any two calls. */
int dopus_set_cost_hessian(dopus_solver *s, int fresh);
int dopus_get_cost_hessian(dopus_solver *s);
/* Levenberg-Marquardt term (algorithm.md section 3): the QP minimises with the Hessian
 * blocks A~_k + lm I and A~_N + lm I (the stored blocks are not changed, so the secant
 * criterion and the fixed point are those of lm = 0). lm finite and >= 0: a fixed term
 * (the automatic one is switched off); default: the OCP file's options(lm=...), else the
 * automatic term. */
int dopus_set_levenberg_marquardt(dopus_solver *s, dopus_real lm);
/* The term of the next QP (fixed, or the current automatic value). */
dopus_real dopus_get_levenberg_marquardt(dopus_solver *s);
/* The automatic, scale-aware, adaptive term (docs/algorithm.md section 10): lm is raised
 * until the QP is convex on the dynamics (Riccati pivots positive definite), after a
 * failed feedback and when the KKT proxy grows; lowered after every successful feedback. */
int dopus_set_lm_auto(dopus_solver *s);
int dopus_get_lm_auto(dopus_solver *s);
/* The Hessian scale of the automatic term (largest diagonal entry of the QP blocks). */
dopus_real dopus_get_lm_scale(dopus_solver *s);
/* QP tolerance: 0 < tol <= DOPUS_QP_TOL_MAX (1e-2); a larger one would let the QP return
 * steps that violate the bounds by that much, so it is refused (DOPUS_ERR_INVALID_ARGUMENT). */
int dopus_set_qp_tol(dopus_solver *s, dopus_real tol);
dopus_real dopus_get_qp_tol(dopus_solver *s);
int dopus_set_qp_max_iter(dopus_solver *s, int max_iter);
int dopus_get_qp_max_iter(dopus_solver *s);
/* Automatic recovery (docs/algorithm.md section 9), receding mode only: on (1, the default)
 * or off (0), and K >= 1, the number of consecutive failed feedbacks after which the next
 * prepare re-initialises (default DOPUS_RECOVERY_FAILURES). A detected divergence
 * re-initialises at once. While on, the prepare after a failed feedback first takes the step
 * of that instant's QP for the state the iterate predicts (DOPUS_FLAG_PREDICTED): the plan of
 * the next fallbacks stays current; after a non-finite measurement it clears the count. A
 * feedback whose QP fails (not by its iteration limit) or diverges on a finite measurement
 * re-initialises from that measurement and solves the new QP within the same call before it
 * gives up (DOPUS_FLAG_RECOVERED; at most one re-initialisation and one QP with its lm
 * retries); a measurement at which the model is not finite is handled as a missing one
 * (DOPUS_ERR_NONFINITE_VALUE, DOPUS_FLAG_MEASUREMENT_UNUSABLE). A feedback refused for want of
 * a prepared QP still records its measurement: the recovery starts from the newest one. */
int dopus_set_recovery(dopus_solver *s, int on, int max_failures);
int dopus_get_recovery(dopus_solver *s);
int dopus_get_recovery_failures(dopus_solver *s);
/* QP warm start in feedback (1, the default): start from the previous QP solution shifted
 * with the horizon (a zero step from the shifted iterate, the iterate's multipliers); when
 * that QP is not solved, feedback retries from the cold starting point in the same call.
 * 0: always cold. */
int dopus_set_qp_warm_start(dopus_solver *s, int on);
int dopus_get_qp_warm_start(dopus_solver *s);
/* Runtime parameters: all nodes ((N+1) x np) or node k (np); used from the next function
 * evaluation on (prepare, kkt). */
int dopus_set_parameters(dopus_solver *s, const dopus_real *p);
int dopus_set_parameters_node(dopus_solver *s, int k, const dopus_real *pk);
void dopus_get_parameters(dopus_solver *s, dopus_real *p);

/* The iterate (shapes in the header comment). */
void dopus_get_x(const dopus_solver *s, dopus_real *x);
void dopus_get_u(const dopus_solver *s, dopus_real *u);
void dopus_get_lam(const dopus_solver *s, dopus_real *lam);
void dopus_get_mu_g(const dopus_solver *s, dopus_real *mu_g);
void dopus_get_mu_b(const dopus_solver *s, dopus_real *mu_b);
void dopus_get_mu_bN(const dopus_solver *s, dopus_real *mu_bN);
void dopus_get_mu_r(const dopus_solver *s, dopus_real *mu_r);
void dopus_get_nu(const dopus_solver *s, dopus_real *nu);
/* rho_k (N) of the last prepare (eq. 16; 0 for stage N-1): >= 0, never NaN; +Inf when the
 * residual or the step of the stage overflows (the stage then ranks first). */
void dopus_get_rho(const dopus_solver *s, dopus_real *rho);
/* Stages whose H was computed fresh by the last prepare (or init), sorted ascending, stage
 * N-1 included; writes up to N ints and returns their count. */
int dopus_get_recomputed(const dopus_solver *s, int *stages);
/* The last QP: iterations, status (enum dopus_qp_status of dopus_qp.h). */
int dopus_get_qp_iterations(const dopus_solver *s);
int dopus_get_qp_status(const dopus_solver *s);
/* A constraint row of the OCP at one stage of the horizon. */
typedef struct {
    int stage;        /* 0..N-1; N: the terminal node */
    int kind;         /* enum dopus_row_kind */
    int index;        /* the state or control, or the row among the path rows, the terminal
                     inequality rows or the terminal equality rows (each stacked in
                     declaration order) */
    int side;         /* -1: its lower bound, +1: its upper bound (an equality row: the sign of
                     the certificate's multiplier), 0: lower bound above upper bound */
    dopus_real bound; /* the bound's value (the lower one for side 0; 0 for an equality row, whose
                     function is the declared row minus its value) */
} dopus_row_info;
/* When the last QP was infeasible (dopus_get_qp_status DOPUS_QP_PRIMAL_INFEASIBLE): the row
 * with the largest multiplier of its infeasibility certificate, the row that the other rows
 * of the certificate (the bounds, dynamics and measured state) keep from being met; stages
 * are those of that QP's horizon. Returns 1 and writes *row, else returns 0. */
int dopus_get_qp_infeasible_row(const dopus_solver *s, dopus_row_info *row);
/* Health of the controller (docs/algorithm.md section 9). Flags (DOPUS_FLAG_*) raised by
 * the last feedback and the prepare after it (feedback clears them): the returned u0 was
 * clipped to the control bounds, u0 is the fallback of a failed feedback (the next control
 * of the last good plan), a divergence was detected, the prepare re-initialised. */
int dopus_get_flags(const dopus_solver *s);
/* The control returned by the last feedback (nu), successful or not; within the bounds. */
void dopus_get_u0(const dopus_solver *s, dopus_real *u0);
/* Re-initialisations by the automatic recovery since init; consecutive failed feedbacks. */
int dopus_get_recoveries(const dopus_solver *s);
int dopus_get_failed_feedbacks(const dopus_solver *s);
/* The divergence measure of the last prepare or init: the stationarity and equality parts of
 * the KKT measure at the prepared point (max |F_w,k + [lam_k; 0]|, |phi_k - x_{k+1}|, ...);
 * and the scale of the box test of the iterate: state (nx) and control (nu) scales. */
dopus_real dopus_get_kkt_proxy(const dopus_solver *s);
void dopus_get_scales(const dopus_solver *s, dopus_real *scale_x, dopus_real *scale_u);
/* 1 when the last feedback's warm-started QP failed and the cold retry ran (the
 * iterations above are then the sum of both solves), else 0. */
int dopus_get_qp_cold_retry(const dopus_solver *s);
/* Status of the last call that returns a status. */
int dopus_get_status(const dopus_solver *s);
int dopus_is_initialized(const dopus_solver *s);
/* ring_head (stage k lives in slot (ring_head + k) mod N). */
int dopus_get_ring_head(const dopus_solver *s);

/* Seconds per phase of the last call that ran it (t[0..7] = feedback, shift, gradients,
 * rho, hessians, regularization, assembly, kkt; indices of enum dopus_phase). init fills
 * the phases it runs too. "hessians" includes the stage-cost Hessians A_l. */
void dopus_get_timings(const dopus_solver *s, double *t);
/* Replace the clock (seconds, any origin); NULL restores the default clock. The default
 * clock is CLOCK_MONOTONIC where the platform has POSIX timers; on bare metal there is none
 * and every timing reads 0 until a clock is installed (dopus_timer.h). */
void dopus_set_clock(dopus_solver *s, double (*clock_fn)(void *ctx), void *ctx);
/* 1 if the timings measure time (a clock was installed, or the default clock exists on
 * this platform), 0 if they read 0 for want of a clock. */
int dopus_has_clock(const dopus_solver *s);
/* Anytime DOPUS (docs/algorithm.md section 12): a budget per sampling instant, counted
 * from the start of the instant's feedback. In time (seconds of the solver's clock, dopus_set_clock:
 * on firmware an instruction or cycle counter) or in work units (stage_grad, stage_hess,
 * term_grad and term_hess evaluations count 1 each, a QP solve counts N; deterministic, the
 * unit of the Python reference). 0 switches it off (the plain real-time iteration). With a
 * budget, prepare re-linearises stages beyond stage N-1 only while the budget allows, first
 * the M (or adaptive M) stages, then further stages in rho order, and spends the rest on
 * SQP iterations on the next instant's problem at the state the plan predicts (dx_0 = 0)
 * while the KKT proxy exceeds the anytime tolerance; the next feedback starts from that
 * iterate. The feedback's QP iterations are capped by the budget left (the fallback control
 * when the cap stops it). */
int dopus_set_time_budget(dopus_solver *s, double seconds);
int dopus_set_work_budget(dopus_solver *s, double units);
/* DOPUS_BUDGET_OFF, DOPUS_BUDGET_TIME or DOPUS_BUDGET_WORK, and the budget in its unit. */
int dopus_get_budget_unit(const dopus_solver *s);
double dopus_get_budget(const dopus_solver *s);
/* KKT proxy (dopus_get_kkt_proxy) below which no further iteration is spent; > 0. */
int dopus_set_anytime_tol(dopus_solver *s, dopus_real tol);
dopus_real dopus_get_anytime_tol(const dopus_solver *s);
/* Adaptive M (docs/algorithm.md section 12): each iteration re-linearises the stages whose
 * secant residual rho_k |domega_k| exceeds eta times the KKT proxy, at least M_min and at
 * most M_max of them (0 <= M_min <= M_max), the largest rho_k first. on = 0: the fixed M of
 * dopus_set_M. eta > 0. */
int dopus_set_M_adaptive(dopus_solver *s, int on, int M_min, int M_max, dopus_real eta);
int dopus_get_M_adaptive(const dopus_solver *s, int *M_min, int *M_max, dopus_real *eta);
/* The last instant: extra iterations after prepare, stages re-linearised over all its
 * iterations (stage N-1 and the terminal node not counted), budget used (its unit). */
int dopus_get_extra_iterations(const dopus_solver *s);
int dopus_get_instant_stages(const dopus_solver *s);
double dopus_get_budget_used(const dopus_solver *s);
/* Work units counted since the solver was set up (the unit of dopus_set_work_budget). */
double dopus_get_work(const dopus_solver *s);
/* DOPUS_CDEF_END */

/* Status codes returned by the functions above. */
enum dopus_status {
    DOPUS_OK = 0,
    DOPUS_ERR_QP = 1,                /* QP not solved; no step; see dopus_get_qp_status */
    DOPUS_ERR_NONFINITE_INPUT = 2,   /* NaN or Inf in an input array */
    DOPUS_ERR_NONFINITE_VALUE = 3,   /* a generated function returned NaN or Inf */
    DOPUS_ERR_FUNCTION = 4,          /* a generated function reported failure */
    DOPUS_ERR_INVALID_ARGUMENT = 5,  /* M out of range, bad mode/Hessian/regularisation,
                                        Gauss-Newton without least squares, bad node index */
    DOPUS_ERR_NOT_INITIALIZED = 6,   /* feedback/prepare/kkt before a successful init */
    DOPUS_ERR_NOT_PREPARED = 7,      /* feedback without a successful prepare since the last
                                        step (the QP would be stale) */
    DOPUS_ERR_NO_NOMINAL = 8,        /* dopus_init_nominal without DOPUS_HAS_NOMINAL */
    DOPUS_ERR_REGULARIZATION = 9,    /* eigen-decomposition did not converge */
    DOPUS_ERR_ALREADY_PREPARED = 10, /* prepare without a feedback since the last successful
                                        init or prepare (it would shift the horizon twice);
                                        nothing changes */
    DOPUS_ERR_DIVERGED = 11          /* the QP step leaves the problem's scale box (or is not
                                        finite): no step, the fallback control is returned */
};

/* Kinds of dopus_row_info. */
enum dopus_row_kind {
    DOPUS_ROW_STATE = 0,      /* a bound of a state (stages 1..N) */
    DOPUS_ROW_CONTROL = 1,    /* a bound of a control */
    DOPUS_ROW_PATH = 2,       /* a path-constraint row */
    DOPUS_ROW_TERMINAL = 3,   /* a terminal inequality row (lb < ub) */
    DOPUS_ROW_TERMINAL_EQ = 4 /* a terminal equality row (lb == ub) */
};

/* Flags of dopus_get_flags (docs/algorithm.md section 9). */
enum dopus_flag {
    DOPUS_FLAG_U0_CLIPPED = 1,           /* u0 was outside the control bounds and was clipped */
    DOPUS_FLAG_FALLBACK = 2,             /* feedback failed: u0 is the next control of the last good plan */
    DOPUS_FLAG_DIVERGED = 4,             /* the step or the prepared iterate failed the divergence test */
    DOPUS_FLAG_RECOVERED = 8,            /* prepare or feedback re-initialised (automatic recovery) */
    DOPUS_FLAG_PREDICTED = 16,           /* prepare took the step of the QP for the predicted state */
    DOPUS_FLAG_REINIT_GUESS = 32,        /* a re-initialisation fell back to the OCP file's guess: the
                                     model was not finite at the re-initialised iterate */
    DOPUS_FLAG_MEASUREMENT_UNUSABLE = 64 /* the model is not finite at the (finite) measurement:
                                            handled as a missing one */
};

/* Safety constants (docs/algorithm.md section 9). */
#define DOPUS_QP_TOL_MAX DOPUS_R(1e-2)    /* largest accepted QP tolerance */
#define DOPUS_RECOVERY_FAILURES 2         /* default K: consecutive failures before recovery */
#define DOPUS_RECOVERY_FULL_RTI 10        /* successful feedbacks with every block fresh after a recovery */
#define DOPUS_DIVERGENCE_BOX DOPUS_R(1e3) /* |x_k,i| <= 1e3 scale_x_i + |xhat0_i|, same for u */
#define DOPUS_DIVERGENCE_KKT DOPUS_R(1e6) /* kkt proxy <= 1e6 max(1, proxy at the last init) */

/* Automatic Levenberg-Marquardt term (docs/algorithm.md section 10), relative to the
 * Hessian scale h = max(1e-300, largest |diagonal entry| of the QP's blocks). */
#define DOPUS_LM_MIN_REL DOPUS_R(1e-8)    /* smallest nonzero term: 1e-8 h (below: 0) */
#define DOPUS_LM_MAX_REL DOPUS_R(1e2)     /* largest term: 1e2 h */
#define DOPUS_LM_RAISE DOPUS_R(10.0)      /* factor of a raise */
#define DOPUS_LM_LOWER DOPUS_R(0.1)       /* factor after a successful feedback */
#define DOPUS_LM_PIVOT_REL DOPUS_R(1e-10) /* Riccati pivots must exceed 1e-10 h */
#define DOPUS_LM_KKT_GROWTH DOPUS_R(10.0) /* raise when the KKT proxy grows 10x in one prepare */
#define DOPUS_LM_RETRIES 2                /* QP solves again with lm raised after a failure */
#define DOPUS_LM_KKT_REL DOPUS_R(1e-2)    /* feedback: lm <= 1e-2 h d^2, d the distance from the solution */

enum dopus_mode {
    DOPUS_MODE_RECEDING = 0, /* shift by one sampling interval in every prepare */
    DOPUS_MODE_FIXED = 1     /* no shift: fixed-xhat0 convergence studies */
};

enum dopus_hessian { DOPUS_HESSIAN_EXACT = 0, DOPUS_HESSIAN_GAUSS_NEWTON = 1 };

/* Units of the anytime budget (docs/algorithm.md section 12). */
enum dopus_budget_unit {
    DOPUS_BUDGET_OFF = 0,  /* no budget: the plain real-time iteration */
    DOPUS_BUDGET_TIME = 1, /* seconds of the solver's clock */
    DOPUS_BUDGET_WORK = 2  /* work units: function evaluations 1, a QP solve N */
};

/* Anytime constants (docs/algorithm.md section 12). */
#define DOPUS_ANYTIME_TOL DOPUS_PREC(1e-8, 2e-5) /* default KKT proxy target of the extra iterations */
#define DOPUS_ANYTIME_MAX_ITER 50                /* extra iterations per instant at most */
#define DOPUS_ADAPTIVE_ETA DOPUS_R(0.1)          /* default eta of adaptive M */
#define DOPUS_WORK_QP DOPUS_N                    /* work units of a QP solve */

/* ------------------------------------------------------------------------------------- */
/* The full state. Its layout is public so firmware can declare `static dopus_solver s;`;
 * the fields are internal (use the functions above). */

#include "dopus_sizes.h"
#include "dopus_funcs.h"
#include "dopus_qp.h"
#include "dopus_reg.h"
#include "dopus_ring.h"
#include "dopus_timer.h"

/* Memory that is live only in some calls: the QP's workspace and its solution (also the
 * warm-start point) in feedback; the scratch of the generated functions, the regularisation,
 * the convexity test of the automatic lm and F_new in init, prepare and kkt. Never both at
 * once, so they share it. */
typedef union {
    struct {
        dopus_qp_workspace work;
        dopus_qp_sol sol;
    } qp;
    struct {
        dopus_fun_work fun_work;
        /* F_new of stages 0..N-2 (prepare step 2), stored as F_old only when prepare
         * succeeds, so a prepare that fails leaves every F_old for its retry */
        dopus_real Fn_w[DOPUS_N][DOPUS_NW];
        dopus_real Fn_phi[DOPUS_N][DOPUS_NX];
        dopus_real Fn_g[DOPUS_N][DOPUS_DIM(DOPUS_NG)];
        dopus_real tmp_A[DOPUS_NW * DOPUS_NW];
        dopus_real tmp_Al[DOPUS_NW * DOPUS_NW];
        dopus_real tmp_Phi[DOPUS_NX * DOPUS_NW];
        dopus_real tmp_C[DOPUS_DIM(DOPUS_NG * DOPUS_NW)];
        dopus_real tmp_gL[DOPUS_NW];
        dopus_real tmp_F[DOPUS_NW];
        dopus_real tmp_phi[DOPUS_NX];
        dopus_real tmp_g[DOPUS_DIM(DOPUS_NG)];
        dopus_real reg_work[2 * DOPUS_NW * DOPUS_NW];
        /* Riccati workspace of the convexity test of the automatic lm */
        dopus_real lm_P[DOPUS_NX * DOPUS_NX];
        dopus_real lm_PA[DOPUS_NX * DOPUS_NW];
        dopus_real lm_G[DOPUS_NW * DOPUS_NW];
    } ev;
} dopus_solver_mem;

struct dopus_solver {
    int magic;       /* DOPUS_MAGIC once the settings hold valid values */
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
    dopus_real reg_eps;
    int cost_hessian;       /* 1: fresh stage-cost Hessian in every prepare, 0: stored */
    dopus_real lm;          /* Levenberg-Marquardt term of the QP Hessian (fixed, or the
                           current automatic value) */
    int lm_auto;            /* 1: automatic term (section 10) */
    dopus_real lm_scale;    /* Hessian scale h of the automatic term */
    dopus_real lm_kkt_prev; /* KKT proxy of the previous prepare (< 0: none since init) */
    dopus_real lm_uncapped; /* the term before the cap of this feedback (< 0: not capped) */
    dopus_qp_settings qp_settings;

    /* iterate (algorithm.md section 1) */
    dopus_real x[DOPUS_N + 1][DOPUS_NX];
    dopus_real u[DOPUS_N][DOPUS_NU];
    dopus_real lam[DOPUS_N + 1][DOPUS_NX];
    dopus_real mu_g[DOPUS_N][DOPUS_DIM(DOPUS_NG)];
    dopus_real mu_b[DOPUS_N][DOPUS_NW];
    dopus_real mu_bN[DOPUS_NX];
    dopus_real mu_r[DOPUS_DIM(DOPUS_NR)];
    dopus_real nu[DOPUS_DIM(DOPUS_NE)];
    dopus_real p[DOPUS_N + 1][DOPUS_DIM(DOPUS_NP)];
    dopus_real xhat0[DOPUS_NX];

    /* stage slots (Ht, A_dyn, Phit, Ct, F_old, domega) and ring_head */
    dopus_ring ring;

    /* terminal node, always fresh: A (regularised), R, R_eq and F = (gL, E, r, r_eq) */
    dopus_real A_N[DOPUS_NX * DOPUS_NX];
    dopus_real R[DOPUS_DIM(DOPUS_NR) * DOPUS_NX];
    dopus_real R_eq[DOPUS_DIM(DOPUS_NE) * DOPUS_NX];
    dopus_real gL_N[DOPUS_NX];
    dopus_real E;
    dopus_real r[DOPUS_DIM(DOPUS_NR)];
    dopus_real r_eq[DOPUS_DIM(DOPUS_NE)];

    /* secant criterion and the recomputed set of the last prepare */
    dopus_real rho[DOPUS_N];
    int recomputed[DOPUS_N];
    int n_recomputed;
    unsigned char selected[DOPUS_N];

    /* QP data: the vectors; the matrix pointers are set to the ring slots and the terminal
     * blocks only during a QP solve (NULL between calls, so a byte copy is a valid solver) */
    dopus_qp_in qp_in;
    dopus_qp_info qp_info;
    int qp_status;
    int qp_iterations;
    int qp_warm;       /* warm start in feedback (dopus_set_qp_warm_start) */
    int qp_cold_retry; /* the last feedback needed the cold retry */

    /* the QP's workspace and solution, live only inside feedback, share their memory with
     * the scratch of the function evaluations, live only outside it (dopus_solver_mem) */
    dopus_solver_mem mem;

    /* safe outputs, divergence test and recovery (algorithm.md section 9) */
    int recovery;          /* automatic recovery on */
    int recovery_failures; /* K */
    int n_failed;          /* consecutive failed feedbacks */
    int recover_pending;   /* the next prepare re-initialises */
    int flags;             /* DOPUS_FLAG_* of the last feedback + prepare */
    int n_recoveries;
    int recovering;                       /* full-RTI prepares left after a recovery */
    int xhat_fresh;                       /* the last feedback had a finite measurement */
    int plan_age;                         /* receding shifts since the last good plan */
    dopus_real plan_u[DOPUS_N][DOPUS_NU]; /* controls of the last good plan */
    dopus_real u0_out[DOPUS_NU];          /* the control returned by the last feedback */
    dopus_real scale_x[DOPUS_NX];
    dopus_real scale_u[DOPUS_NU];
    dopus_real kkt_proxy;
    dopus_real kkt_proxy_ref;

    /* KKT parts of the last dopus_kkt_eval: stat, eq, ineq, comp */
    dopus_real kkt[4];

    dopus_timer timer;

    /* anytime budget (algorithm.md section 12) */
    int budget_unit;        /* enum dopus_budget_unit */
    double budget;          /* per instant, in its unit */
    dopus_real anytime_tol; /* no extra iteration below this KKT proxy */
    int M_adaptive;         /* 1: adaptive M between M_min and M_max */
    int M_min, M_max;
    dopus_real M_eta;
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

#endif /* DOPUS_SOLVER_H */
