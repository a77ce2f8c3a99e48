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
 *     static robot_arm_solver s;
 *     robot_arm_init(&s, xhat0, NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL);
 *     loop: robot_arm_feedback(&s, xhat0, u0); apply u0; robot_arm_prepare(&s);
 * The memory is one struct (sizeof is the memory bill; no malloc anywhere). It holds no
 * pointer into itself between calls, so a byte copy (memcpy, struct assignment: a snapshot,
 * a double buffer) is a complete solver, independent of the original. Settings may be
 * changed before robot_arm_init; a struct that was never set up (zeroed or uninitialised
 * memory) gets the generated defaults on its first use.
 *
 * Array conventions: every array argument is a flat, C-contiguous (row-major) array of
 * doubles, node by node: x is (N+1) x nx (x + k*nx is node k), u is N x nu, lam (N+1) x nx,
 * mu_g N x ng, mu_b N x nw, mu_bN nx, mu_r nr, nu ne, parameters (N+1) x np. Multipliers are
 * signed (positive when the upper side of a row is active, negative for the lower side);
 * docs/algorithm.md section 1 gives the Lagrangian. Arrays of size zero are not read or
 * written (any pointer, also NULL, may be passed).
 *
 * Every function returning int returns a status (enum robot_arm_status below) unless stated.
 * On failure the state stays consistent: a failed feedback takes no step; a failed
 * prepare leaves the shifted iterate, and the next prepare re-runs from there.
 */
#ifndef ROBOT_ARM_SOLVER_H
#define ROBOT_ARM_SOLVER_H

#include "robot_arm_real.h"

#include <stddef.h>

/* ROBOT_ARM_CDEF_BEGIN */
typedef struct robot_arm_solver robot_arm_solver;

/* Size of struct robot_arm_solver in bytes (for callers that allocate it as raw memory). */
size_t robot_arm_solver_sizeof(void);
/* Reset every setting to the generated defaults (M, Hessian, regularisation, eps from the
 * OCP file, receding mode, QP tolerance 1e-10, parameters p_default at every node, default
 * clock) and mark the solver uninitialised. */
void robot_arm_defaults(robot_arm_solver *s);
/* Dimensions of the generated problem (nw = nx + nu); has_gn: a Gauss-Newton Hessian is
 * available (least-squares stage cost); has_nominal: robot_arm_init_nominal has data. */
typedef struct {
    int N, nx, nu, nw, np, ng, nr, ne, has_gn, has_nominal;
} robot_arm_dims;
void robot_arm_get_dims(robot_arm_dims *dims);
/* Problem name (the generator's ROBOT_ARM_NAME). */
const char *robot_arm_name(void);
/* A short English description of a status code. */
const char *robot_arm_status_string(int status);

/* Initialisation (algorithm.md section 4, init): the iterate is the given guess; NULL x or
 * u: the OCP file's initial guess; NULL multipliers: zeros. F and H of every stage and of
 * the terminal node are computed (regularised) at the guess, ring_head = 0, domega = 0,
 * rho = 0. xhat0 is checked and kept for robot_arm_kkt_eval (may be NULL: the default x0).
 * A failed init leaves the solver uninitialised (NaN/Inf input: the iterate untouched). */
int robot_arm_init(robot_arm_solver *s, const robot_arm_real *xhat0, const robot_arm_real *x, const robot_arm_real *u,
               const robot_arm_real *lam, const robot_arm_real *mu_g, const robot_arm_real *mu_b, const robot_arm_real *mu_bN,
               const robot_arm_real *mu_r, const robot_arm_real *nu);
/* Initialisation from the generated nominal primal-dual guess (the offline NLP solution at
 * the default x0); ROBOT_ARM_ERR_NO_NOMINAL when the solver was generated without one. */
int robot_arm_init_nominal(robot_arm_solver *s, const robot_arm_real *xhat0);

/* Feedback phase: solve the prepared QP for the measured state xhat0 (nx), take the full
 * step and write u_0 (nu) into u0 (may be NULL). Non-finite xhat0: ROBOT_ARM_ERR_NONFINITE_INPUT,
 * nothing changes. QP failure: ROBOT_ARM_ERR_QP, no step (robot_arm_get_qp_status tells why). */
int robot_arm_feedback(robot_arm_solver *s, const robot_arm_real *xhat0, robot_arm_real *u0);
/* Preparation phase: shift (receding mode), gradients and rho_k of every stage, fresh last
 * stage and terminal node, re-linearise the M stages with the largest rho_k, refresh the
 * stage-cost Hessian of the other stages (robot_arm_set_cost_hessian), assemble the QP. Must
 * run between two feedback calls.
 * Calling order: one prepare per feedback on an initialised solver that reached the QP
 * (solved or not) and, in receding mode, also per feedback whose measurement was rejected
 * as non-finite (the sampling instant has passed all the same and the plan moves on with
 * it). prepare right after a successful init or prepare
 * returns ROBOT_ARM_ERR_ALREADY_PREPARED and changes nothing, in both modes (in receding mode
 * it would shift twice, in fixed mode it would measure rho_k against gradients of the
 * same point). After a failed prepare the next prepare is a retry: it does not shift
 * again, and it measures rho_k against the same F_old (the gradients of a failed prepare are
 * not stored); blocks that the failed attempt had already re-linearised stay fresh. */
int robot_arm_prepare(robot_arm_solver *s);
/* KKT measure (algorithm.md section 6) of the current iterate with exact derivatives, for
 * the initial state xhat0 (NULL: the last one given to init or feedback):
 * kkt4 = stat, eq, ineq, comp (may be NULL). Returns a status; the iterate is not changed.
 * The parts are >= 0 and never NaN; a part is +Inf when it overflows (an iterate or
 * multipliers near DBL_MAX, e.g. from an init guess: |mu| * |ub - v| > DBL_MAX). */
int robot_arm_kkt_eval(robot_arm_solver *s, const robot_arm_real *xhat0, robot_arm_real *kkt4);
/* The largest of the four parts of the last robot_arm_kkt_eval (NaN before the first). */
robot_arm_real robot_arm_get_kkt(const robot_arm_solver *s);

/* Settings. M: stages re-linearised per iteration besides stage N-1, 0 <= M <= N-1
 * (N-1 is the full RTI). mode: ROBOT_ARM_MODE_RECEDING or ROBOT_ARM_MODE_FIXED. hessian:
 * ROBOT_ARM_HESSIAN_EXACT or ROBOT_ARM_HESSIAN_GAUSS_NEWTON (only with a least-squares stage cost).
 * regularization: ROBOT_ARM_REG_NONE, ROBOT_ARM_REG_PROJECT or ROBOT_ARM_REG_MIRROR with eps > 0.
 * The QP tolerance (> 0) and iteration limit (>= 1) are those of robot_arm_qp_solve. */
int robot_arm_set_M(robot_arm_solver *s, int M);
int robot_arm_get_M(robot_arm_solver *s);
int robot_arm_set_mode(robot_arm_solver *s, int mode);
int robot_arm_get_mode(robot_arm_solver *s);
int robot_arm_set_hessian(robot_arm_solver *s, int hessian);
int robot_arm_get_hessian(robot_arm_solver *s);
int robot_arm_set_regularization(robot_arm_solver *s, int regularization, robot_arm_real eps);
int robot_arm_get_regularization(robot_arm_solver *s);
robot_arm_real robot_arm_get_reg_eps(robot_arm_solver *s);
/* Stage-cost Hessian (algorithm.md section 4 step 5): fresh = 1 (the default) refreshes the
 * cost part A_l of the Hessian block of every stage in every prepare (only the curvature of
 * dynamics and constraints is partially updated); fresh = 0 is the paper's literal
 * algorithm (the whole A moves with its slot). The slots always carry A_dyn = A - A_l, so
 * the setting may change between any two calls. */
int robot_arm_set_cost_hessian(robot_arm_solver *s, int fresh);
int robot_arm_get_cost_hessian(robot_arm_solver *s);
/* Levenberg-Marquardt term (algorithm.md section 3): the QP minimises with the Hessian
 * blocks A~_k + lm I and A~_N + lm I (the stored blocks are not changed, so the secant
 * criterion and the fixed point are those of lm = 0). lm finite and >= 0: a fixed term
 * (the automatic one is switched off); default: the OCP file's options(lm=...), else the
 * automatic term. */
int robot_arm_set_levenberg_marquardt(robot_arm_solver *s, robot_arm_real lm);
/* The term of the next QP (fixed, or the current automatic value). */
robot_arm_real robot_arm_get_levenberg_marquardt(robot_arm_solver *s);
/* The automatic, scale-aware, adaptive term (docs/algorithm.md section 10): lm is raised
 * until the QP is convex on the dynamics (Riccati pivots positive definite), after a
 * failed feedback and when the KKT proxy grows; lowered after every successful feedback. */
int robot_arm_set_lm_auto(robot_arm_solver *s);
int robot_arm_get_lm_auto(robot_arm_solver *s);
/* The Hessian scale of the automatic term (largest diagonal entry of the QP blocks). */
robot_arm_real robot_arm_get_lm_scale(robot_arm_solver *s);
/* QP tolerance: 0 < tol <= ROBOT_ARM_QP_TOL_MAX (1e-2); a larger one would let the QP return
 * steps that violate the bounds by that much, so it is refused (ROBOT_ARM_ERR_INVALID_ARGUMENT). */
int robot_arm_set_qp_tol(robot_arm_solver *s, robot_arm_real tol);
robot_arm_real robot_arm_get_qp_tol(robot_arm_solver *s);
int robot_arm_set_qp_max_iter(robot_arm_solver *s, int max_iter);
int robot_arm_get_qp_max_iter(robot_arm_solver *s);
/* Automatic recovery (docs/algorithm.md section 9), receding mode only: on (1, the default)
 * or off (0), and K >= 1, the number of consecutive failed feedbacks after which the next
 * prepare re-initialises (default ROBOT_ARM_RECOVERY_FAILURES). A detected divergence
 * re-initialises at once. While on, the prepare after a failed feedback first takes the step
 * of that instant's QP for the state the iterate predicts (ROBOT_ARM_FLAG_PREDICTED): the plan of
 * the next fallbacks stays current; after a non-finite measurement it clears the count. A
 * feedback whose QP fails (not by its iteration limit) or diverges on a finite measurement
 * re-initialises from that measurement and solves the new QP within the same call before it
 * gives up (ROBOT_ARM_FLAG_RECOVERED; at most one re-initialisation and one QP with its lm
 * retries); a measurement at which the model is not finite is handled as a missing one
 * (ROBOT_ARM_ERR_NONFINITE_VALUE, ROBOT_ARM_FLAG_MEASUREMENT_UNUSABLE). A feedback refused for want of
 * a prepared QP still records its measurement: the recovery starts from the newest one. */
int robot_arm_set_recovery(robot_arm_solver *s, int on, int max_failures);
int robot_arm_get_recovery(robot_arm_solver *s);
int robot_arm_get_recovery_failures(robot_arm_solver *s);
/* QP warm start in feedback (1, the default): start from the previous QP solution shifted
 * with the horizon (a zero step from the shifted iterate, the iterate's multipliers); when
 * that QP is not solved, feedback retries from the cold starting point in the same call.
 * 0: always cold. */
int robot_arm_set_qp_warm_start(robot_arm_solver *s, int on);
int robot_arm_get_qp_warm_start(robot_arm_solver *s);
/* Runtime parameters: all nodes ((N+1) x np) or node k (np); used from the next function
 * evaluation on (prepare, kkt). */
int robot_arm_set_parameters(robot_arm_solver *s, const robot_arm_real *p);
int robot_arm_set_parameters_node(robot_arm_solver *s, int k, const robot_arm_real *pk);
void robot_arm_get_parameters(robot_arm_solver *s, robot_arm_real *p);

/* The iterate (shapes in the header comment). */
void robot_arm_get_x(const robot_arm_solver *s, robot_arm_real *x);
void robot_arm_get_u(const robot_arm_solver *s, robot_arm_real *u);
void robot_arm_get_lam(const robot_arm_solver *s, robot_arm_real *lam);
void robot_arm_get_mu_g(const robot_arm_solver *s, robot_arm_real *mu_g);
void robot_arm_get_mu_b(const robot_arm_solver *s, robot_arm_real *mu_b);
void robot_arm_get_mu_bN(const robot_arm_solver *s, robot_arm_real *mu_bN);
void robot_arm_get_mu_r(const robot_arm_solver *s, robot_arm_real *mu_r);
void robot_arm_get_nu(const robot_arm_solver *s, robot_arm_real *nu);
/* rho_k (N) of the last prepare (eq. 16; 0 for stage N-1): >= 0, never NaN; +Inf when the
 * residual or the step of the stage overflows (the stage then ranks first). */
void robot_arm_get_rho(const robot_arm_solver *s, robot_arm_real *rho);
/* Stages whose H was computed fresh by the last prepare (or init), sorted ascending, stage
 * N-1 included; writes up to N ints and returns their count. */
int robot_arm_get_recomputed(const robot_arm_solver *s, int *stages);
/* The last QP: iterations, status (enum robot_arm_qp_status of robot_arm_qp.h). */
int robot_arm_get_qp_iterations(const robot_arm_solver *s);
int robot_arm_get_qp_status(const robot_arm_solver *s);
/* A constraint row of the OCP at one stage of the horizon. */
typedef struct {
    int stage;        /* 0..N-1; N: the terminal node */
    int kind;         /* enum robot_arm_row_kind */
    int index;        /* the state or control, or the row among the path rows, the terminal
                     inequality rows or the terminal equality rows (each stacked in
                     declaration order) */
    int side;         /* -1: its lower bound, +1: its upper bound (an equality row: the sign of
                     the certificate's multiplier), 0: lower bound above upper bound */
    robot_arm_real bound; /* the bound's value (the lower one for side 0; 0 for an equality row, whose
                     function is the declared row minus its value) */
} robot_arm_row_info;
/* When the last QP was infeasible (robot_arm_get_qp_status ROBOT_ARM_QP_PRIMAL_INFEASIBLE): the row
 * with the largest multiplier of its infeasibility certificate, the row that the other rows
 * of the certificate (the bounds, dynamics and measured state) keep from being met; stages
 * are those of that QP's horizon. Returns 1 and writes *row, else returns 0. */
int robot_arm_get_qp_infeasible_row(const robot_arm_solver *s, robot_arm_row_info *row);
/* Health of the controller (docs/algorithm.md section 9). Flags (ROBOT_ARM_FLAG_*) raised by
 * the last feedback and the prepare after it (feedback clears them): the returned u0 was
 * clipped to the control bounds, u0 is the fallback of a failed feedback (the next control
 * of the last good plan), a divergence was detected, the prepare re-initialised. */
int robot_arm_get_flags(const robot_arm_solver *s);
/* The control returned by the last feedback (nu), successful or not; within the bounds. */
void robot_arm_get_u0(const robot_arm_solver *s, robot_arm_real *u0);
/* Re-initialisations by the automatic recovery since init; consecutive failed feedbacks. */
int robot_arm_get_recoveries(const robot_arm_solver *s);
int robot_arm_get_failed_feedbacks(const robot_arm_solver *s);
/* The divergence measure of the last prepare or init: the stationarity and equality parts of
 * the KKT measure at the prepared point (max |F_w,k + [lam_k; 0]|, |phi_k - x_{k+1}|, ...);
 * and the scale of the box test of the iterate: state (nx) and control (nu) scales. */
robot_arm_real robot_arm_get_kkt_proxy(const robot_arm_solver *s);
void robot_arm_get_scales(const robot_arm_solver *s, robot_arm_real *scale_x, robot_arm_real *scale_u);
/* 1 when the last feedback's warm-started QP failed and the cold retry ran (the
 * iterations above are then the sum of both solves), else 0. */
int robot_arm_get_qp_cold_retry(const robot_arm_solver *s);
/* Status of the last call that returns a status. */
int robot_arm_get_status(const robot_arm_solver *s);
int robot_arm_is_initialized(const robot_arm_solver *s);
/* ring_head (stage k lives in slot (ring_head + k) mod N). */
int robot_arm_get_ring_head(const robot_arm_solver *s);

/* Seconds per phase of the last call that ran it (t[0..7] = feedback, shift, gradients,
 * rho, hessians, regularization, assembly, kkt; indices of enum robot_arm_phase). init fills
 * the phases it runs too. "hessians" includes the stage-cost Hessians A_l. */
void robot_arm_get_timings(const robot_arm_solver *s, double *t);
/* Replace the clock (seconds, any origin); NULL restores the default clock. The default
 * clock is CLOCK_MONOTONIC where the platform has POSIX timers; on bare metal there is none
 * and every timing reads 0 until a clock is installed (robot_arm_timer.h). */
void robot_arm_set_clock(robot_arm_solver *s, double (*clock_fn)(void *ctx), void *ctx);
/* 1 if the timings measure time (a clock was installed, or the default clock exists on
 * this platform), 0 if they read 0 for want of a clock. */
int robot_arm_has_clock(const robot_arm_solver *s);
/* Anytime DOPUS (docs/algorithm.md section 12): a budget per sampling instant, counted
 * from the start of the instant's feedback. In time (seconds of the solver's clock, robot_arm_set_clock:
 * on firmware an instruction or cycle counter) or in work units (stage_grad, stage_hess,
 * term_grad and term_hess evaluations count 1 each, a QP solve counts N; deterministic, the
 * unit of the Python reference). 0 switches it off (the plain real-time iteration). With a
 * budget, prepare re-linearises stages beyond stage N-1 only while the budget allows, first
 * the M (or adaptive M) stages, then further stages in rho order, and spends the rest on
 * SQP iterations on the next instant's problem at the state the plan predicts (dx_0 = 0)
 * while the KKT proxy exceeds the anytime tolerance; the next feedback starts from that
 * iterate. The feedback's QP iterations are capped by the budget left (the fallback control
 * when the cap stops it). */
int robot_arm_set_time_budget(robot_arm_solver *s, double seconds);
int robot_arm_set_work_budget(robot_arm_solver *s, double units);
/* ROBOT_ARM_BUDGET_OFF, ROBOT_ARM_BUDGET_TIME or ROBOT_ARM_BUDGET_WORK, and the budget in its unit. */
int robot_arm_get_budget_unit(const robot_arm_solver *s);
double robot_arm_get_budget(const robot_arm_solver *s);
/* KKT proxy (robot_arm_get_kkt_proxy) below which no further iteration is spent; > 0. */
int robot_arm_set_anytime_tol(robot_arm_solver *s, robot_arm_real tol);
robot_arm_real robot_arm_get_anytime_tol(const robot_arm_solver *s);
/* Adaptive M (docs/algorithm.md section 12): each iteration re-linearises the stages whose
 * secant residual rho_k |domega_k| exceeds eta times the KKT proxy, at least M_min and at
 * most M_max of them (0 <= M_min <= M_max), the largest rho_k first. on = 0: the fixed M of
 * robot_arm_set_M. eta > 0. */
int robot_arm_set_M_adaptive(robot_arm_solver *s, int on, int M_min, int M_max, robot_arm_real eta);
int robot_arm_get_M_adaptive(const robot_arm_solver *s, int *M_min, int *M_max, robot_arm_real *eta);
/* The last instant: extra iterations after prepare, stages re-linearised over all its
 * iterations (stage N-1 and the terminal node not counted), budget used (its unit). */
int robot_arm_get_extra_iterations(const robot_arm_solver *s);
int robot_arm_get_instant_stages(const robot_arm_solver *s);
double robot_arm_get_budget_used(const robot_arm_solver *s);
/* Work units counted since the solver was set up (the unit of robot_arm_set_work_budget). */
double robot_arm_get_work(const robot_arm_solver *s);
/* ROBOT_ARM_CDEF_END */

/* Status codes returned by the functions above. */
enum robot_arm_status {
    ROBOT_ARM_OK = 0,
    ROBOT_ARM_ERR_QP = 1,                /* QP not solved; no step; see robot_arm_get_qp_status */
    ROBOT_ARM_ERR_NONFINITE_INPUT = 2,   /* NaN or Inf in an input array */
    ROBOT_ARM_ERR_NONFINITE_VALUE = 3,   /* a generated function returned NaN or Inf */
    ROBOT_ARM_ERR_FUNCTION = 4,          /* a generated function reported failure */
    ROBOT_ARM_ERR_INVALID_ARGUMENT = 5,  /* M out of range, bad mode/Hessian/regularisation,
                                        Gauss-Newton without least squares, bad node index */
    ROBOT_ARM_ERR_NOT_INITIALIZED = 6,   /* feedback/prepare/kkt before a successful init */
    ROBOT_ARM_ERR_NOT_PREPARED = 7,      /* feedback without a successful prepare since the last
                                        step (the QP would be stale) */
    ROBOT_ARM_ERR_NO_NOMINAL = 8,        /* robot_arm_init_nominal without ROBOT_ARM_HAS_NOMINAL */
    ROBOT_ARM_ERR_REGULARIZATION = 9,    /* eigen-decomposition did not converge */
    ROBOT_ARM_ERR_ALREADY_PREPARED = 10, /* prepare without a feedback since the last successful
                                        init or prepare (it would shift the horizon twice);
                                        nothing changes */
    ROBOT_ARM_ERR_DIVERGED = 11          /* the QP step leaves the problem's scale box (or is not
                                        finite): no step, the fallback control is returned */
};

/* Kinds of robot_arm_row_info. */
enum robot_arm_row_kind {
    ROBOT_ARM_ROW_STATE = 0,      /* a bound of a state (stages 1..N) */
    ROBOT_ARM_ROW_CONTROL = 1,    /* a bound of a control */
    ROBOT_ARM_ROW_PATH = 2,       /* a path-constraint row */
    ROBOT_ARM_ROW_TERMINAL = 3,   /* a terminal inequality row (lb < ub) */
    ROBOT_ARM_ROW_TERMINAL_EQ = 4 /* a terminal equality row (lb == ub) */
};

/* Flags of robot_arm_get_flags (docs/algorithm.md section 9). */
enum robot_arm_flag {
    ROBOT_ARM_FLAG_U0_CLIPPED = 1,           /* u0 was outside the control bounds and was clipped */
    ROBOT_ARM_FLAG_FALLBACK = 2,             /* feedback failed: u0 is the next control of the last good plan */
    ROBOT_ARM_FLAG_DIVERGED = 4,             /* the step or the prepared iterate failed the divergence test */
    ROBOT_ARM_FLAG_RECOVERED = 8,            /* prepare or feedback re-initialised (automatic recovery) */
    ROBOT_ARM_FLAG_PREDICTED = 16,           /* prepare took the step of the QP for the predicted state */
    ROBOT_ARM_FLAG_REINIT_GUESS = 32,        /* a re-initialisation fell back to the OCP file's guess: the
                                     model was not finite at the re-initialised iterate */
    ROBOT_ARM_FLAG_MEASUREMENT_UNUSABLE = 64 /* the model is not finite at the (finite) measurement:
                                            handled as a missing one */
};

/* Safety constants (docs/algorithm.md section 9). */
#define ROBOT_ARM_QP_TOL_MAX ROBOT_ARM_R(1e-2)    /* largest accepted QP tolerance */
#define ROBOT_ARM_RECOVERY_FAILURES 2         /* default K: consecutive failures before recovery */
#define ROBOT_ARM_RECOVERY_FULL_RTI 10        /* successful feedbacks with every block fresh after a recovery */
#define ROBOT_ARM_DIVERGENCE_BOX ROBOT_ARM_R(1e3) /* |x_k,i| <= 1e3 scale_x_i + |xhat0_i|, same for u */
#define ROBOT_ARM_DIVERGENCE_KKT ROBOT_ARM_R(1e6) /* kkt proxy <= 1e6 max(1, proxy at the last init) */

/* Automatic Levenberg-Marquardt term (docs/algorithm.md section 10), relative to the
 * Hessian scale h = max(1e-300, largest |diagonal entry| of the QP's blocks). */
#define ROBOT_ARM_LM_MIN_REL ROBOT_ARM_R(1e-8)    /* smallest nonzero term: 1e-8 h (below: 0) */
#define ROBOT_ARM_LM_MAX_REL ROBOT_ARM_R(1e2)     /* largest term: 1e2 h */
#define ROBOT_ARM_LM_RAISE ROBOT_ARM_R(10.0)      /* factor of a raise */
#define ROBOT_ARM_LM_LOWER ROBOT_ARM_R(0.1)       /* factor after a successful feedback */
#define ROBOT_ARM_LM_PIVOT_REL ROBOT_ARM_R(1e-10) /* Riccati pivots must exceed 1e-10 h */
#define ROBOT_ARM_LM_KKT_GROWTH ROBOT_ARM_R(10.0) /* raise when the KKT proxy grows 10x in one prepare */
#define ROBOT_ARM_LM_RETRIES 2                /* QP solves again with lm raised after a failure */
#define ROBOT_ARM_LM_KKT_REL ROBOT_ARM_R(1e-2)    /* feedback: lm <= 1e-2 h d^2, d the distance from the solution */

enum robot_arm_mode {
    ROBOT_ARM_MODE_RECEDING = 0, /* shift by one sampling interval in every prepare */
    ROBOT_ARM_MODE_FIXED = 1     /* no shift: fixed-xhat0 convergence studies */
};

enum robot_arm_hessian { ROBOT_ARM_HESSIAN_EXACT = 0, ROBOT_ARM_HESSIAN_GAUSS_NEWTON = 1 };

/* Units of the anytime budget (docs/algorithm.md section 12). */
enum robot_arm_budget_unit {
    ROBOT_ARM_BUDGET_OFF = 0,  /* no budget: the plain real-time iteration */
    ROBOT_ARM_BUDGET_TIME = 1, /* seconds of the solver's clock */
    ROBOT_ARM_BUDGET_WORK = 2  /* work units: function evaluations 1, a QP solve N */
};

/* Anytime constants (docs/algorithm.md section 12). */
#define ROBOT_ARM_ANYTIME_TOL ROBOT_ARM_PREC(1e-8, 2e-5) /* default KKT proxy target of the extra iterations */
#define ROBOT_ARM_ANYTIME_MAX_ITER 50                /* extra iterations per instant at most */
#define ROBOT_ARM_ADAPTIVE_ETA ROBOT_ARM_R(0.1)          /* default eta of adaptive M */
#define ROBOT_ARM_WORK_QP ROBOT_ARM_N                    /* work units of a QP solve */

/* ------------------------------------------------------------------------------------- */
/* The full state. Its layout is public so firmware can declare `static robot_arm_solver s;`;
 * the fields are internal (use the functions above). */

#include "robot_arm_sizes.h"
#include "robot_arm_funcs.h"
#include "robot_arm_qp.h"
#include "robot_arm_reg.h"
#include "robot_arm_ring.h"
#include "robot_arm_timer.h"

/* Memory that is live only in some calls: the QP's workspace and its solution (also the
 * warm-start point) in feedback; the scratch of the generated functions, the regularisation,
 * the convexity test of the automatic lm and F_new in init, prepare and kkt. Never both at
 * once, so they share it. */
typedef union {
    struct {
        robot_arm_qp_workspace work;
        robot_arm_qp_sol sol;
    } qp;
    struct {
        robot_arm_fun_work fun_work;
        /* F_new of stages 0..N-2 (prepare step 2), stored as F_old only when prepare
         * succeeds, so a prepare that fails leaves every F_old for its retry */
        robot_arm_real Fn_w[ROBOT_ARM_N][ROBOT_ARM_NW];
        robot_arm_real Fn_phi[ROBOT_ARM_N][ROBOT_ARM_NX];
        robot_arm_real Fn_g[ROBOT_ARM_N][ROBOT_ARM_DIM(ROBOT_ARM_NG)];
        robot_arm_real tmp_A[ROBOT_ARM_NW * ROBOT_ARM_NW];
        robot_arm_real tmp_Al[ROBOT_ARM_NW * ROBOT_ARM_NW];
        robot_arm_real tmp_Phi[ROBOT_ARM_NX * ROBOT_ARM_NW];
        robot_arm_real tmp_C[ROBOT_ARM_DIM(ROBOT_ARM_NG * ROBOT_ARM_NW)];
        robot_arm_real tmp_gL[ROBOT_ARM_NW];
        robot_arm_real tmp_F[ROBOT_ARM_NW];
        robot_arm_real tmp_phi[ROBOT_ARM_NX];
        robot_arm_real tmp_g[ROBOT_ARM_DIM(ROBOT_ARM_NG)];
        robot_arm_real reg_work[2 * ROBOT_ARM_NW * ROBOT_ARM_NW];
        /* Riccati workspace of the convexity test of the automatic lm */
        robot_arm_real lm_P[ROBOT_ARM_NX * ROBOT_ARM_NX];
        robot_arm_real lm_PA[ROBOT_ARM_NX * ROBOT_ARM_NW];
        robot_arm_real lm_G[ROBOT_ARM_NW * ROBOT_ARM_NW];
    } ev;
} robot_arm_solver_mem;

struct robot_arm_solver {
    int magic;       /* ROBOT_ARM_MAGIC once the settings hold valid values */
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
    robot_arm_real reg_eps;
    int cost_hessian;       /* 1: fresh stage-cost Hessian in every prepare, 0: stored */
    robot_arm_real lm;          /* Levenberg-Marquardt term of the QP Hessian (fixed, or the
                           current automatic value) */
    int lm_auto;            /* 1: automatic term (section 10) */
    robot_arm_real lm_scale;    /* Hessian scale h of the automatic term */
    robot_arm_real lm_kkt_prev; /* KKT proxy of the previous prepare (< 0: none since init) */
    robot_arm_real lm_uncapped; /* the term before the cap of this feedback (< 0: not capped) */
    robot_arm_qp_settings qp_settings;

    /* iterate (algorithm.md section 1) */
    robot_arm_real x[ROBOT_ARM_N + 1][ROBOT_ARM_NX];
    robot_arm_real u[ROBOT_ARM_N][ROBOT_ARM_NU];
    robot_arm_real lam[ROBOT_ARM_N + 1][ROBOT_ARM_NX];
    robot_arm_real mu_g[ROBOT_ARM_N][ROBOT_ARM_DIM(ROBOT_ARM_NG)];
    robot_arm_real mu_b[ROBOT_ARM_N][ROBOT_ARM_NW];
    robot_arm_real mu_bN[ROBOT_ARM_NX];
    robot_arm_real mu_r[ROBOT_ARM_DIM(ROBOT_ARM_NR)];
    robot_arm_real nu[ROBOT_ARM_DIM(ROBOT_ARM_NE)];
    robot_arm_real p[ROBOT_ARM_N + 1][ROBOT_ARM_DIM(ROBOT_ARM_NP)];
    robot_arm_real xhat0[ROBOT_ARM_NX];

    /* stage slots (Ht, A_dyn, Phit, Ct, F_old, domega) and ring_head */
    robot_arm_ring ring;

    /* terminal node, always fresh: A (regularised), R, R_eq and F = (gL, E, r, r_eq) */
    robot_arm_real A_N[ROBOT_ARM_NX * ROBOT_ARM_NX];
    robot_arm_real R[ROBOT_ARM_DIM(ROBOT_ARM_NR) * ROBOT_ARM_NX];
    robot_arm_real R_eq[ROBOT_ARM_DIM(ROBOT_ARM_NE) * ROBOT_ARM_NX];
    robot_arm_real gL_N[ROBOT_ARM_NX];
    robot_arm_real E;
    robot_arm_real r[ROBOT_ARM_DIM(ROBOT_ARM_NR)];
    robot_arm_real r_eq[ROBOT_ARM_DIM(ROBOT_ARM_NE)];

    /* secant criterion and the recomputed set of the last prepare */
    robot_arm_real rho[ROBOT_ARM_N];
    int recomputed[ROBOT_ARM_N];
    int n_recomputed;
    unsigned char selected[ROBOT_ARM_N];

    /* QP data: the vectors; the matrix pointers are set to the ring slots and the terminal
     * blocks only during a QP solve (NULL between calls, so a byte copy is a valid solver) */
    robot_arm_qp_in qp_in;
    robot_arm_qp_info qp_info;
    int qp_status;
    int qp_iterations;
    int qp_warm;       /* warm start in feedback (robot_arm_set_qp_warm_start) */
    int qp_cold_retry; /* the last feedback needed the cold retry */

    /* the QP's workspace and solution, live only inside feedback, share their memory with
     * the scratch of the function evaluations, live only outside it (robot_arm_solver_mem) */
    robot_arm_solver_mem mem;

    /* safe outputs, divergence test and recovery (algorithm.md section 9) */
    int recovery;          /* automatic recovery on */
    int recovery_failures; /* K */
    int n_failed;          /* consecutive failed feedbacks */
    int recover_pending;   /* the next prepare re-initialises */
    int flags;             /* ROBOT_ARM_FLAG_* of the last feedback + prepare */
    int n_recoveries;
    int recovering;                       /* full-RTI prepares left after a recovery */
    int xhat_fresh;                       /* the last feedback had a finite measurement */
    int plan_age;                         /* receding shifts since the last good plan */
    robot_arm_real plan_u[ROBOT_ARM_N][ROBOT_ARM_NU]; /* controls of the last good plan */
    robot_arm_real u0_out[ROBOT_ARM_NU];          /* the control returned by the last feedback */
    robot_arm_real scale_x[ROBOT_ARM_NX];
    robot_arm_real scale_u[ROBOT_ARM_NU];
    robot_arm_real kkt_proxy;
    robot_arm_real kkt_proxy_ref;

    /* KKT parts of the last robot_arm_kkt_eval: stat, eq, ineq, comp */
    robot_arm_real kkt[4];

    robot_arm_timer timer;

    /* anytime budget (algorithm.md section 12) */
    int budget_unit;        /* enum robot_arm_budget_unit */
    double budget;          /* per instant, in its unit */
    robot_arm_real anytime_tol; /* no extra iteration below this KKT proxy */
    int M_adaptive;         /* 1: adaptive M between M_min and M_max */
    int M_min, M_max;
    robot_arm_real M_eta;
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

#endif /* ROBOT_ARM_SOLVER_H */
