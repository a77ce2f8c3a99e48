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
 *     robot_arm_settings st;
 *     robot_arm_settings_default(&st);          the OCP file's options; change fields here
 *     robot_arm_setup(&s, &st);
 *     robot_arm_init(&s, xhat0, NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL);
 *     loop: robot_arm_feedback(&s, xhat0, u0); apply u0; robot_arm_prepare(&s);
 * With a moving reference (parameters over time): set the first horizon's parameters
 * before init, and push the value of the new last node between feedback and prepare:
 *     loop: robot_arm_feedback(&s, xhat0, u0); apply u0; robot_arm_push_parameters(&s, pN); robot_arm_prepare(&s);
 * The memory is one struct (sizeof is the memory bill; no malloc anywhere). robot_arm_setup
 * must run before any other call on it (on a zero-filled struct that was not set up, every
 * call returns ROBOT_ARM_ERR_NOT_INITIALIZED; uninitialised memory is not valid). It holds no
 * pointer into itself between calls, so a byte copy (memcpy, struct assignment: a snapshot,
 * a double buffer) is a complete solver, independent of the original.
 *
 * Array conventions: every array argument is a flat, C-contiguous (row-major) array of
 * doubles, node by node: x is (N+1) x nx (x + k*nx is node k), u is N x nu, lam (N+1) x nx,
 * mu_g N x ng, mu_b N x nw, mu_bN nx, mu_r nr, nu ne, parameters (N+1) x np. Multipliers are
 * signed (positive when the upper side of a row is active, negative for the lower side);
 * docs/algorithm.md section 1 gives the Lagrangian. Arrays of size zero are not read or
 * written (any pointer, also NULL, may be passed). Every value of the API is in the OCP's
 * declared units: with a declared scaling (docs/algorithm.md section 16) the solver works in
 * scaled variables and converts at this boundary (the KKT measure of robot_arm_kkt_eval and the
 * scales of robot_arm_get_scales are those of the scaled variables).
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

/* Settings (docs/algorithm.md). M: stages re-linearised per iteration besides stage N-1,
 * 0 <= M <= N-1 (N-1 is the full RTI). mode: ROBOT_ARM_MODE_RECEDING or ROBOT_ARM_MODE_FIXED.
 * hessian: ROBOT_ARM_HESSIAN_EXACT or ROBOT_ARM_HESSIAN_GAUSS_NEWTON (only with a least-squares
 * stage cost). regularization: ROBOT_ARM_REG_NONE, ROBOT_ARM_REG_PROJECT or ROBOT_ARM_REG_MIRROR with
 * reg_eps > 0. cost_hessian (algorithm.md section 4 step 5): 1 refreshes the cost part A_l of
 * the Hessian block of every stage in every prepare (only the curvature of dynamics and
 * constraints is partially updated); 0 is the paper's literal algorithm (the whole A moves
 * with its slot). lm_auto 1: the automatic Levenberg-Marquardt term (section 10: raised
 * until the QP is convex on the dynamics, after a failed feedback and when the KKT proxy
 * grows; lowered after every successful feedback); 0: the fixed term lm >= 0 (section 3: the
 * QP minimises with the blocks A~_k + lm I, A~_N + lm I; the stored blocks, the secant
 * criterion and the fixed point are those of lm = 0). qp_tol: 0 < tol <= ROBOT_ARM_QP_TOL_MAX
 * (a larger one would let the QP return steps that violate the bounds by that much);
 * qp_max_iter >= 1. qp_warm_start 1: the QP of feedback starts from the previous solution
 * shifted with the horizon, and retries cold in the same call when that fails; 0: always
 * cold. recovery (section 9, receding mode only) 1: after recovery_failures >= 1
 * consecutive failed feedbacks the next prepare re-initialises, a detected divergence
 * re-initialises at once, the prepare after a failed feedback first takes the step of that
 * instant's QP for the predicted state (ROBOT_ARM_FLAG_PREDICTED), and a feedback whose QP fails
 * (not by its iteration limit) or diverges re-initialises from the measurement and solves
 * again within the call (ROBOT_ARM_FLAG_RECOVERED); a measurement at which the model is not
 * finite is handled as a missing one (ROBOT_ARM_ERR_NONFINITE_VALUE,
 * ROBOT_ARM_FLAG_MEASUREMENT_UNUSABLE); a feedback refused for want of a prepared QP still
 * records its measurement, so the recovery starts from the newest one; 0: off.
 * Anytime DOPUS (section 14): budget > 0 per sampling instant, counted from the start of
 * the instant's feedback, in budget_unit ROBOT_ARM_BUDGET_TIME (seconds of the solver's clock,
 * robot_arm_set_clock: on firmware an instruction or cycle counter; without a clock the budget
 * is off) or ROBOT_ARM_BUDGET_WORK (work units: stage_grad, stage_hess, term_grad and term_hess
 * evaluations 1 each, a QP solve N; deterministic, the unit of the Python reference);
 * budget 0: off, the plain real-time iteration. With a budget, prepare re-linearises stages
 * only while the budget allows (the M of the setting first, then further stages in rho
 * order), then takes SQP iterations on the next instant's problem at the state the plan
 * predicts (dx_0 = 0) while the KKT proxy exceeds anytime_tol > 0 and one more fits; a time
 * budget caps the feedback QP's iterations. M_adaptive 1: each iteration re-linearises the
 * stages whose secant residual rho_k |domega_k| exceeds M_eta > 0 times the KKT proxy, at
 * least M_min and at most M_max (0 <= M_min <= M_max <= N-1), the largest rho_k first;
 * 0: the fixed M. */
typedef struct {
    int M;
    int mode;
    int hessian;
    int regularization;
    robot_arm_real reg_eps;
    int cost_hessian;
    int lm_auto;
    robot_arm_real lm;
    robot_arm_real qp_tol;
    int qp_max_iter;
    int qp_warm_start;
    int recovery;
    int recovery_failures;
    double budget;
    int budget_unit;
    robot_arm_real anytime_tol;
    int M_adaptive;
    int M_min;
    int M_max;
    robot_arm_real M_eta;
    robot_arm_real gate; /* 0: off; else the largest |xhat0_i - x_0,i| / scale_x_i accepted */
    int gate_hold;   /* at most so many gated measurements in a row; the next is accepted */
} robot_arm_settings;
/* The generated defaults: M, Hessian, regularisation, eps, cost Hessian and lm from the OCP
 * file's options; receding mode, QP tolerance ROBOT_ARM_QP_TOL_DEFAULT, 100 QP iterations, warm
 * start and recovery on (K = ROBOT_ARM_RECOVERY_FAILURES). */
void robot_arm_settings_default(robot_arm_settings *st);
/* Set up a solver: every field of the struct written (settings st, NULL: the generated
 * defaults; parameters p_default at every node; the default clock; not initialised).
 * ROBOT_ARM_ERR_INVALID_ARGUMENT when a setting is out of range (the solver is then set up
 * with the generated defaults). */
int robot_arm_setup(robot_arm_solver *s, const robot_arm_settings *st);
/* Change the settings of a set-up solver, at any time between calls (they apply from the
 * next call on): all of them, or none and ROBOT_ARM_ERR_INVALID_ARGUMENT when one is out of
 * range. Switching the automatic lm on restarts it (from 0, raised until the prepared QP is
 * convex); switching the recovery off drops a pending one. */
int robot_arm_update_settings(robot_arm_solver *s, const robot_arm_settings *st);
void robot_arm_get_settings(const robot_arm_solver *s, robot_arm_settings *st);

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
 * step and write u_0 (nu) into u0 (may be NULL). With rate constraints, in receding mode,
 * the entries of xhat0 that are memory states (the last applied control, ROBOT_ARM_NMEM of them)
 * are not read: the runtime fills them with the control it returned last (at the first
 * feedback: the ones given to init); the same holds for robot_arm_kkt_eval. Non-finite xhat0: ROBOT_ARM_ERR_NONFINITE_INPUT,
 * nothing changes. QP failure: ROBOT_ARM_ERR_QP, no step (robot_arm_info.qp_status tells why). On
 * every failure u0 is the fallback control (docs/algorithm.md section 9). */
int robot_arm_feedback(robot_arm_solver *s, const robot_arm_real *xhat0, robot_arm_real *u0);
/* Preparation phase: shift (receding mode), gradients and rho_k of every stage, fresh last
 * stage and terminal node, re-linearise the M stages with the largest rho_k, refresh the
 * stage-cost Hessian of the other stages (settings.cost_hessian), assemble the QP. Must
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

/* Runtime parameters (algorithm.md section 4, "Parameters"): one vector per node, p_k at the
 * time of node k. They are read by init and prepare, which build the QP, so they may be
 * written only before init or between a feedback and its prepare (after a failed prepare:
 * before its retry); a write while a QP is prepared and not yet used by a feedback returns
 * ROBOT_ARM_ERR_ALREADY_PREPARED and changes nothing (it would reach the QP one instant late).
 * In receding mode the parameters move with the horizon: the prepare after a feedback
 * shifts them (p_k <- p_{k+1}, p_N kept) once per sampling instant, before its first
 * evaluation; a write between the feedback and the prepare shifts them first, so every
 * write addresses the horizon of the next QP:
 *   push_parameters: p_N of the next horizon (the value at t_next + N dt), the usual
 *     call of a moving reference: loop { feedback; apply u0; push(p(t + dt + N dt)); prepare }
 *   set_parameters: all nodes ((N+1) x np); set_parameters_node: node k (np).
 * push_parameters needs an initialised solver (ROBOT_ARM_ERR_NOT_INITIALIZED) in receding mode
 * (else ROBOT_ARM_ERR_INVALID_ARGUMENT). Parameters that are never written stay as they are
 * (a constant parameter is unaffected by the shift). */
int robot_arm_set_parameters(robot_arm_solver *s, const robot_arm_real *p);
int robot_arm_set_parameters_node(robot_arm_solver *s, int k, const robot_arm_real *pk);
int robot_arm_push_parameters(robot_arm_solver *s, const robot_arm_real *pN);
void robot_arm_get_parameters(const robot_arm_solver *s, robot_arm_real *p);
/* End the run: the solver is uninitialised (settings and parameters kept), so that the
 * parameters of the next run's first horizon may be written before its init. */
void robot_arm_stop(robot_arm_solver *s);
/* Replace the clock (seconds, any origin); NULL restores the default clock. The default
 * clock is CLOCK_MONOTONIC where the platform has POSIX timers; on bare metal there is none
 * and every timing reads 0 until a clock is installed (robot_arm_timer.h). */
void robot_arm_set_clock(robot_arm_solver *s, double (*clock_fn)(void *ctx), void *ctx);

/* The discrete model (the OCP file's integrator): x_next = phi(x, u, p) (p NULL: the
 * default parameters), with the caller's scratch of the generated functions (a plant for
 * tests and examples; the solver's own is not touched). Returns ROBOT_ARM_OK,
 * ROBOT_ARM_ERR_FUNCTION or ROBOT_ARM_ERR_NONFINITE_VALUE. */
struct robot_arm_fun_work_s; /* robot_arm_fun_work of robot_arm_funcs.h */
int robot_arm_simulate(const robot_arm_real *x, const robot_arm_real *u, const robot_arm_real *p, robot_arm_real *x_next,
                   struct robot_arm_fun_work_s *work);

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
/* The control returned by the last feedback (nu), successful or not; within the bounds. */
void robot_arm_get_u0(const robot_arm_solver *s, robot_arm_real *u0);
/* The scale of the box test of the divergence test: state (nx) and control (nu) scales
 * (either may be NULL). */
void robot_arm_get_scales(const robot_arm_solver *s, robot_arm_real *scale_x, robot_arm_real *scale_u);

/* What the last calls did, read in one call (docs/algorithm.md sections 4, 9, 10). */
typedef struct {
    int status;           /* status of the last call that returns one */
    int initialized;      /* a successful init happened */
    int qp_status;        /* enum robot_arm_qp_status of the last feedback's QP (also when the
                            feedback failed after it: an unusable measurement; 0 after a
                            re-initialisation until its QP) */
    int qp_iterations;    /* its iterations (the sum over the solves of the call) */
    int qp_cold_retry;    /* 1 when its warm-started QP failed and the cold retry ran; 0 after a
                            warm start that certified primal infeasibility (no retry: qp_status
                            is that certificate's 2, or a later raise of lm's) */
    int flags;            /* ROBOT_ARM_FLAG_* raised by the last feedback and the prepare after it:
                            u0 clipped, fallback control, divergence, recovery, ... */
    int recoveries;       /* re-initialisations by the automatic recovery since init */
    int failed_feedbacks; /* consecutive failed feedbacks */
    int M_used;           /* stages the last prepare (or init) re-linearised besides stage N-1
                            (M, or N-1 after a recovery and at init) */
    int ring_head;        /* stage k lives in slot (ring_head + k) mod N */
    int has_clock;        /* 1 if the timings measure time (a clock was installed, or the
                            default clock exists on this platform), 0 if they read 0 */
    robot_arm_real lm;        /* the Levenberg-Marquardt term of the next QP (fixed or automatic) */
    robot_arm_real lm_scale;  /* the Hessian scale of the automatic term */
    int lm_held;          /* 1: the last prepare's convexity test raised the automatic term (the
                            flat stall test of docs/algorithm.md section 9) */
    robot_arm_real kkt_proxy; /* divergence measure of the last prepare or init: the stationarity
                            and equality parts of the KKT measure at the prepared point */
    robot_arm_real kkt[4];    /* stat, eq, ineq, comp of the last robot_arm_kkt_eval (NaN before) */
    robot_arm_real kkt_max;   /* their largest */
    robot_arm_real kkt_rel;   /* the relative measure of the same iterate (docs/algorithm.md section 6) */
    /* the factorisations of the Riccati recursion of the last feedback's QP (the sum over the
     * solves of the call: interior-point iterations, inertia corrections, sweeps of the
     * active-set start) */
    int qp_factorizations;
    /* 1 when the last feedback's QP took a factorisation the prepare formed (its convexity
     * test's, or the active-set start's with the guessed rows) as that of its first sweep
     * (docs/algorithm.md section 10), else 0 */
    int qp_prefactored;
    /* seconds per phase of the last call that ran it (enum robot_arm_phase: feedback, shift,
     * gradients, rho, hessians, regularization, assembly, kkt, lm, recovery; init fills
     * the phases it runs too); the phases of a feedback (prepare) add up to t_feedback
     * (t_prepare), the wall time of that call */
    double timings[10];
    double t_feedback;
    double t_prepare;
    /* anytime DOPUS (section 14), the last instant: extra iterations after prepare, stages
     * re-linearised over all its iterations (stage N-1 not counted), budget used (its unit);
     * the work units counted since setup */
    int extra_iterations;
    int instant_stages;
    double budget_used;
    double work;
} robot_arm_info;
void robot_arm_get_info(const robot_arm_solver *s, robot_arm_info *info);
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
/* When the last QP was infeasible (robot_arm_info.qp_status ROBOT_ARM_QP_PRIMAL_INFEASIBLE, until the
 * next prepare): the row with the largest multiplier of its infeasibility certificate, the
 * row that the other rows of the certificate (the bounds, dynamics and measured state) keep
 * from being met; stages are those of that QP's horizon. Returns 1 and writes *row, else
 * returns 0. */
int robot_arm_get_qp_infeasible_row(const robot_arm_solver *s, robot_arm_row_info *row);
/* The name of a row of the OCP (kind: enum robot_arm_row_kind; index as in robot_arm_row_info): the
 * state or control label ("pos[0]"), the declared name of a constraint ("wall", "wall[1]"
 * for row 1 of several) or "path constraint 0" / "terminal constraint 1 row 2" for an
 * unnamed one; NULL for a kind or index out of range. */
const char *robot_arm_row_name(int kind, int index);
/* Soft rows (docs/algorithm.md section 12): the slacks of the QP of the last feedback, read
 * after that feedback and before the next prepare: max(0, lb - v, v - ub) of every soft row
 * at the QP's solution, v the state x_k + dx_k (viol_x, (N+1) x nx, node 0 zero), the
 * linearised path row g_k + Ct_k dw_k (viol_g, N x max(ng, 1)) and the linearised terminal
 * row r + R dx_N (viol_r, max(nr, 1)); 0 on hard rows. A pointer may be NULL. Returns the
 * largest slack (0 without soft rows). */
robot_arm_real robot_arm_get_soft_slacks(const robot_arm_solver *s, robot_arm_real *viol_x, robot_arm_real *viol_g,
                                 robot_arm_real *viol_r);
/* The globalised first solve (docs/algorithm.md section 15), for a start far from the
 * solution (a cold guess, an arbitrary state at power-up); off in the real-time loop. The
 * memory of a solve is the caller's struct robot_arm_glob of robot_arm_globalise.h, or
 * robot_arm_glob_sizeof() bytes; zero-filled it starts a solve (no penalty, no counts: `static
 * robot_arm_glob g;`, memset to 0 for the next one). robot_arm_glob_step: one SQP step from the
 * prepared iterate (after init or the previous step) for xhat0 (NULL: the one of the last
 * init), in fixed mode whatever the setting: the QP of the iterate (every block fresh), then
 * along its step the l1 exact-penalty merit function decides, with a watchdog (relaxed full
 * steps) and a backtracking line search; then init at the accepted point (every block fresh,
 * the next QP prepared). On failure (robot_arm_glob_info.reason: the QP, the step box, the line
 * search, a function) the iterate is the one before the step, prepared.
 * robot_arm_init_globalised: init at the guess (x, u NULL: the OCP file's; zero multipliers),
 * then steps until the KKT measure (robot_arm_kkt_eval) is at most tol > 0: ROBOT_ARM_OK;
 * ROBOT_ARM_ERR_NOT_CONVERGED when max_iter >= 0 steps or the work limit (max_work > 0 work units
 * from the init on, the next step estimated as the last one; 0: none) end them first, the
 * iterate prepared for feedback either way; the status of a failed step. */
typedef struct robot_arm_glob robot_arm_glob;
typedef struct {
    int iterations; /* steps in this solve */
    int trials;     /* merit evaluations of the last line search */
    int reason;     /* enum robot_arm_glob_reason of the last call */
    int relaxed;    /* the last step was a relaxed full step of the watchdog */
    int restores;   /* returns to a watchdog's point in this solve */
    robot_arm_real penalty, alpha, merit, slope, kkt;
} robot_arm_glob_info;
size_t robot_arm_glob_sizeof(void);
int robot_arm_glob_step(robot_arm_solver *s, robot_arm_glob *g, const robot_arm_real *xhat0);
int robot_arm_init_globalised(robot_arm_solver *s, robot_arm_glob *g, const robot_arm_real *xhat0, const robot_arm_real *x,
                          const robot_arm_real *u, double max_work, int max_iter, robot_arm_real tol);
void robot_arm_glob_get_info(const robot_arm_glob *g, robot_arm_glob_info *info);
/* ROBOT_ARM_CDEF_END */

/* Status codes returned by the functions above. */
enum robot_arm_status {
    ROBOT_ARM_OK = 0,
    ROBOT_ARM_ERR_QP = 1,                 /* QP not solved; no step; see robot_arm_info.qp_status */
    ROBOT_ARM_ERR_NONFINITE_INPUT = 2,    /* NaN or Inf in an input array */
    ROBOT_ARM_ERR_NONFINITE_VALUE = 3,    /* a generated function returned NaN or Inf */
    ROBOT_ARM_ERR_FUNCTION = 4,           /* a generated function reported failure */
    ROBOT_ARM_ERR_INVALID_ARGUMENT = 5,   /* M out of range, bad mode/Hessian/regularisation,
                                        Gauss-Newton without least squares, bad node index */
    ROBOT_ARM_ERR_NOT_INITIALIZED = 6,    /* a call before robot_arm_setup, or feedback/prepare/kkt
                                        before a successful init */
    ROBOT_ARM_ERR_NOT_PREPARED = 7,       /* feedback without a successful prepare since the last
                                        step (the QP would be stale) */
    ROBOT_ARM_ERR_NO_NOMINAL = 8,         /* robot_arm_init_nominal without ROBOT_ARM_HAS_NOMINAL */
    ROBOT_ARM_ERR_REGULARIZATION = 9,     /* eigen-decomposition did not converge */
    ROBOT_ARM_ERR_ALREADY_PREPARED = 10,  /* prepare without a feedback since the last successful
                                        init or prepare (it would shift the horizon twice);
                                        nothing changes */
    ROBOT_ARM_ERR_DIVERGED = 11,          /* the QP step leaves the problem's scale box (or is not
                                        finite): no step, the fallback control is returned */
    ROBOT_ARM_ERR_MEASUREMENT_GATED = 12, /* the measurement jumped further from the plan's
                                        prediction than the gate allows: handled as a missing
                                        one (settings gate, gate_hold) */
    ROBOT_ARM_ERR_NOT_CONVERGED = 13      /* robot_arm_init_globalised: a limit came before the tolerance */
};

/* Kinds of robot_arm_row_info and robot_arm_row_name. */
enum robot_arm_row_kind {
    ROBOT_ARM_ROW_STATE = 0,      /* a bound of a state (stages 1..N) */
    ROBOT_ARM_ROW_CONTROL = 1,    /* a bound of a control */
    ROBOT_ARM_ROW_PATH = 2,       /* a path-constraint row */
    ROBOT_ARM_ROW_TERMINAL = 3,   /* a terminal inequality row (lb < ub) */
    ROBOT_ARM_ROW_TERMINAL_EQ = 4 /* a terminal equality row (lb == ub) */
};

/* Flags of robot_arm_info.flags (docs/algorithm.md section 9). */
enum robot_arm_flag {
    ROBOT_ARM_FLAG_U0_CLIPPED = 1,            /* u0 was outside the control bounds and was clipped */
    ROBOT_ARM_FLAG_FALLBACK = 2,              /* feedback failed: u0 is the next control of the last good plan */
    ROBOT_ARM_FLAG_DIVERGED = 4,              /* the step or the prepared iterate failed the divergence test */
    ROBOT_ARM_FLAG_RECOVERED = 8,             /* prepare or feedback re-initialised (automatic recovery) */
    ROBOT_ARM_FLAG_PREDICTED = 16,            /* prepare took the step of the QP for the predicted state */
    ROBOT_ARM_FLAG_REINIT_GUESS = 32,         /* a re-initialisation fell back to the OCP file's guess: the
                                            model was not finite at the re-initialised iterate */
    ROBOT_ARM_FLAG_MEASUREMENT_UNUSABLE = 64, /* the model is not finite at the (finite) measurement:
                                            handled as a missing one */
    ROBOT_ARM_FLAG_STALLED = 128,             /* the KKT proxy stalled high: a recovery phase began
                                             without a re-initialisation */
    ROBOT_ARM_FLAG_QP_CUT = 256               /* the budget's deadline cut the feedback's QP: its best
                                             point is the step (algorithm.md section 14) */
};

/* Safety constants (docs/algorithm.md section 9; the divergence box and KKT bound are in
 * robot_arm_health.h, the constants of the automatic lm in robot_arm_lm.h). */
#define ROBOT_ARM_QP_TOL_MAX ROBOT_ARM_R(1e-2)               /* largest accepted QP tolerance */
#define ROBOT_ARM_QP_TOL_DEFAULT ROBOT_ARM_PREC(1e-10, 1e-5) /* the QP tolerance of the defaults */
#define ROBOT_ARM_QP_MAX_ITER_DEFAULT 100                /* the QP iteration limit of the defaults */
#define ROBOT_ARM_RECOVERY_FAILURES 2                    /* default K: consecutive failures before recovery */
#define ROBOT_ARM_RECOVERY_FULL_RTI 10  /* successful feedbacks with every block fresh after a recovery */
#define ROBOT_ARM_RECOVERY_EXTRA_ITER 5 /* extra iterations per prepare of a recovery phase, no budget */

enum robot_arm_mode {
    ROBOT_ARM_MODE_RECEDING = 0, /* shift by one sampling interval in every prepare */
    ROBOT_ARM_MODE_FIXED = 1     /* no shift: fixed-xhat0 convergence studies */
};

enum robot_arm_hessian { ROBOT_ARM_HESSIAN_EXACT = 0, ROBOT_ARM_HESSIAN_GAUSS_NEWTON = 1 };

/* Units of the anytime budget (docs/algorithm.md section 14). */
enum robot_arm_budget_unit {
    ROBOT_ARM_BUDGET_TIME = 1, /* seconds of the solver's clock */
    ROBOT_ARM_BUDGET_WORK = 2  /* work units: function evaluations 1, a QP solve N */
};

/* Anytime constants (docs/algorithm.md section 14). */
#define ROBOT_ARM_ANYTIME_TOL ROBOT_ARM_PREC(1e-8, 2e-5) /* default KKT proxy target of the extra iterations */
#define ROBOT_ARM_ANYTIME_MAX_ITER 50                /* extra iterations per instant at most */
/* a feedback QP cut after iterations is its step when its scaled residuals are at most this
 * (an interior-point iterate; the warm start a cut active-set start leaves is refused) */
#define ROBOT_ARM_ANYTIME_CUT_MERIT ROBOT_ARM_R(1e-1)
#define ROBOT_ARM_ADAPTIVE_ETA ROBOT_ARM_R(0.1) /* default eta of adaptive M */
/* QP iterations a time budget's deadline must leave for the interior point alone */
#define ROBOT_ARM_ANYTIME_IPM_ITER 4
#define ROBOT_ARM_WORK_QP ROBOT_ARM_N /* work units of a QP solve */

/* Factorisations of the active-set start of a warm-started QP at most (docs/algorithm.md
 * section 4, feedback; robot_arm_qp.h) and the distance of the measurement from the predicted
 * state, in state scales, beyond which it is not tried (the term lm it needs:
 * robot_arm_lm_near_convex). */
#define ROBOT_ARM_QP_ACTIVE_SET 8
#define ROBOT_ARM_QP_ACTIVE_SET_NEAR ROBOT_ARM_R(1.0)

/* The prepare forms the next feedback's first factorisation (its active-set start's, with the
 * guessed rows) only after a QP that factorised itself at most this many times (a
 * factorisation it took from the prepare not counted): an instant that forms it factorises at
 * most this many times plus one, and a long feedback (after a disturbance) is not followed by
 * one more factorisation in its prepare (bench/issue23/measurements.md section 51). */
#define ROBOT_ARM_PREFACTOR_AFTER 3

/* ------------------------------------------------------------------------------------- */
/* The full state. Its layout is public so firmware can declare `static robot_arm_solver s;`;
 * the fields are internal (use the functions above). */

#include "robot_arm_sizes.h"
#include "robot_arm_funcs.h"
#include "robot_arm_globalise.h"
#include "robot_arm_health.h"
#include "robot_arm_lm.h"
#include "robot_arm_qp.h"
#include "robot_arm_reg.h"
#include "robot_arm_ring.h"
#include "robot_arm_timer.h"

/* Memory that is live only in some calls: the QP's workspace and its solution (also the
 * warm-start point) in feedback, and the QP's workspace at the end of the prepare, where the
 * feedback QP's first factorisation may be formed (the convexity test of the automatic lm in
 * the QP's form, or the active-set start's first factorisation: solver.qp_prefactored); the
 * scratch of the generated functions, the regularisation and F_new in init and prepare (kkt
 * has its own, solver.kkt_work). Never both at once, so they share it. */
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
        /* the scratch of robot_arm_lm.c's own recursion (the lm test outside the QP's form) */
        robot_arm_real lm_work[ROBOT_ARM_LM_WORK];
    } ev;
} robot_arm_solver_mem;

/* The bookkeeping of the anytime budget (algorithm.md section 14); costs in the budget's unit. */
typedef struct {
    double work;          /* work units counted since setup */
    double instant_start; /* the budget clock at the start of the instant's feedback */
    double cost_stage;    /* one stage re-linearisation (the last) */
    double cost_qp;       /* the last QP solve */
    double cost_prepare;  /* the last prepare iteration without the stages beyond M */
    double cost_qp_iter;  /* one QP iteration of the last feedback (time budget) */
    double cost_qp_step;  /* one QP iteration, moved 10 % at most per QP (the extra QP's cap) */
    double cost_tail;     /* steps 6 and 7 of the last prepare iteration */
    double cost_grad;     /* one gradient of stages 0..N-2 (step 2) */
    double cost_fh;       /* one gradient and re-linearisation in one call (step 2 of the full RTI) */
    double cost_head;     /* step 3: stage N-1 and the terminal node */
    double cost_al;       /* one stage's cost-Hessian refresh (step 5) */
    /* the rest of the least prepare and of the feedback (time budget; 0 in work units), each
     * the peak of its readings (robot_arm_cost_peak) */
    double cost_predict; /* one cut stage's prediction (step 2) */
    double cost_fixed;   /* a prepare iteration's own work outside its priced steps */
    double cost_end;     /* the prepare after its last iteration */
    double cost_fb_tail; /* a feedback (or an extra iteration) after its QP: the step taken */
    double cost_qp_over; /* a QP past its last deadline test beyond the price of one iteration */
    double qp_read;      /* the QP's last read of the budget's clock (its price at qp_read_price) */
    double qp_read_price;
    double mark;          /* the end of the last prepare iteration (< 0: something else since) */
    int qp_reads;         /* reads of the clock by the current QP solve */
    double used;          /* budget used by the last instant */
    double qp_deadline;   /* the QP's deadline on the budget's clock (qp_timed) */
    double qp_price;      /* the QP's first estimate of one iteration (qp_timed) */
    int qp_timed;         /* 1: the next QP solves stop at qp_deadline (a time budget) */
    double fb_qp_end;     /* the instant's feedback QP ended this far into it (time budget) */
    double rest_last;     /* the last instant from its feedback QP's end to its end */
    int fb_qp_cut;        /* the instant's feedback QP was stopped by its deadline (time budget) */
    int starved;          /* the last instant proved the prices too high (time budget, section 14) */
    int extra_iterations; /* extra iterations of the last prepare */
    int instant_stages;   /* stages re-linearised in the last instant */
    int prepared_extra;   /* the prepared QP comes from extra iterations (the feedback keeps lm) */
    int uncapped;         /* an extra iteration of this instant raised the KKT proxy */
    int reinit_next;      /* a re-initialisation under way: its next stage (-1: none) */
    int reinit_sim;       /* its forward simulation, done by its stage evaluations: 1 with the last
                            good plan's controls, 2 with the guess controls, 0 none (the guess) */
} robot_arm_anytime;

/* One object per concept: lifecycle, settings, iterate, stage slots, terminal node, secant
 * selection, QP data, shared scratch, health and recovery, the automatic lm, KKT, timers. */
struct robot_arm_solver {
    int set_up;      /* robot_arm_setup ran */
    int initialized; /* a successful init happened */
    int qp_ready;    /* QP assembled at the current iterate (prepare or init succeeded) */
    int prepare_due; /* a feedback reached the QP since the last successful init/prepare */
    int shifted;     /* the shift of this sampling instant is done (a prepare failed after it) */
    int al_resync;   /* a constant A_l (ROBOT_ARM_COST_HESS_CONST): step 5 of the next prepare runs
                        all the same (after a change of the regularisation or a failed init) */
    int p_shifted;   /* the parameters of this sampling instant are shifted (a parameter write
                        or a prepare since the feedback) */
    int status;      /* status of the last call */

    robot_arm_settings settings;

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
    /* the last applied control (rate constraints: the memory entries of the measurement) */
    robot_arm_real u_applied[ROBOT_ARM_NU];

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

    /* secant criterion and the stages re-linearised by the last prepare (stage N-1 always;
     * every stage after init) */
    robot_arm_real rho[ROBOT_ARM_N];
    unsigned char selected[ROBOT_ARM_N];

    /* QP data: the vectors; the matrix pointers are set to the ring slots and the terminal
     * blocks only during a QP solve (NULL between calls, so a byte copy is a valid solver) */
    robot_arm_qp_in qp_in;
    robot_arm_qp_info qp_info;
    int qp_status;
    int qp_iterations;
    int qp_factorizations;
    int qp_cold_retry;  /* the last feedback's cold retry ran */
    int qp_warm_failed; /* the last feedback's warm start failed (retried cold, or certified
                             infeasibility: no retry) */
    /* the prepare's lm test in the QP's form (robot_arm_qp_prefactor, kept in mem.qp.work; when the
     * next active-set start will guess no row), or else the start's first factorisation with
     * its guessed rows (robot_arm_qp_prefactor_guess): the term it was formed at; qp_prefactored: 1
     * when it is kept (at the end of the prepare: at the term it leaves) until anything else
     * uses mem or solves (the feedback's QP may then reuse it) */
    robot_arm_real qp_pre_lm;
    int qp_prefactored;
    int qp_pre_used;      /* the last feedback's QP took that factorisation (robot_arm_info.qp_prefactored) */
    int qp_no_active_set; /* 1 inside a globalised step: the interior point only */

    /* the QP's workspace and solution, live only inside feedback, share their memory with
     * the scratch of the function evaluations, live only outside it (robot_arm_solver_mem) */
    robot_arm_solver_mem mem;
    /* the generated functions' scratch of robot_arm_kkt_eval, outside mem: a KKT evaluation
     * between prepare and feedback leaves the prepared factorisation in place */
    robot_arm_fun_work kkt_work;

    robot_arm_health health; /* safe outputs, divergence test and recovery (section 9) */
    robot_arm_lm lm;         /* the Levenberg-Marquardt term (sections 3 and 10) */
    robot_arm_real kkt[4];   /* KKT parts of the last robot_arm_kkt_eval: stat, eq, ineq, comp */
    robot_arm_real kkt_rel;  /* its relative measure */
    robot_arm_timer timer;
    robot_arm_anytime anytime; /* the budget's bookkeeping (section 14) */
};

#endif /* ROBOT_ARM_SOLVER_H */
