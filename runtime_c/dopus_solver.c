/* The DOPUS real-time iteration (docs/algorithm.md section 4; paper Algorithm 1), and the
 * one translation unit of the runtime library.
 *
 * init: F and H of every stage at the guess. Per sampling instant:
 *   feedback: QP with the measured xhat0, full step, u_0 out;
 *   prepare:  shift (receding mode), F_k and rho_k (eq. 16) of every stage, fresh F/H of
 *             stage N-1 and the terminal node, fresh H for the M stages with the largest
 *             rho_k, the fresh stage-cost Hessian A_l of the other stages added to their
 *             A_dyn (cost_hessian fresh), regularisation of every fresh A, QP vectors with
 *             the adjoint-corrected gradient (eq. 12).
 * The order of operations is that of the contract, so that the Python reference and this
 * runtime produce the same iterates to round-off.
 *
 * The modules (the phase timers, the ring of stage slots, the regularisation, the wrappers
 * of the generated functions, the automatic lm, the health predicates, the KKT measure, the
 * QP) are included at the end of this file, as HPIPM's x_*.c files are, with
 * DOPUS_INTERNAL = static: the library exports the public API of dopus_solver.h and the
 * problem data of dopus_problem.h, nothing else. Each module compiles alone as well (the
 * tests' builds), with external linkage. The modules call only modules below them (timer,
 * ring, reg, funcs, linalg; lm and health read the ring; the QP reads linalg), never this
 * file.
 */
/* clock_gettime is POSIX, not C99: request it before any header (dopus_timer.c). */
#ifndef _POSIX_C_SOURCE
#define _POSIX_C_SOURCE 199309L
#endif

#if defined(__GNUC__)
#define DOPUS_INTERNAL static __attribute__((unused))
#else
#define DOPUS_INTERNAL static
#endif

#include <math.h>

#include "dopus_health.h"
#include "dopus_kkt.h"
#include "dopus_linalg.h"
#include "dopus_lm.h"
#include "dopus_problem.h"
#include "dopus_solver.h"

/* dopus_info.timings is declared with the literal count of the phases (for cffi) */
typedef char dopus_phase_count_check[(DOPUS_N_PHASES == 10) ? 1 : -1];

/* The phases of prepare (every phase but feedback and kkt), as a bit mask. */
#define DOPUS_PREPARE_PHASES                                                                                 \
    (((1u << DOPUS_N_PHASES) - 1u) & ~(1u << DOPUS_PHASE_FEEDBACK) & ~(1u << DOPUS_PHASE_KKT))

/* ---- small helpers ------------------------------------------------------------------ */

static void dopus_copy(dopus_real *dst, const dopus_real *src, int n)
{
    int i;
    for (i = 0; i < n; ++i) {
        dst[i] = src[i];
    }
}

static void dopus_zero(int n, dopus_real *dst)
{
    int i;
    for (i = 0; i < n; ++i) {
        dst[i] = DOPUS_R(0.0);
    }
}

/* x_0 carries no bound (docs/algorithm.md section 1): it is fixed by the measurement, so
 * the simple bounds of the states apply at nodes 1..N only (stage 0 passes infinite sides
 * to the QP, the KKT measure counts a multiplier on x_0 with its magnitude) and the x part
 * of mu_b_0 is 0 (dopus_clear_x0_multiplier). */
static int dopus_x_bounded(int k)
{
    return k > 0;
}

static void dopus_clear_x0_multiplier(dopus_solver *s)
{
    int i;
    for (i = 0; i < DOPUS_NX; ++i) {
        s->mu_b[0][i] = DOPUS_R(0.0);
    }
}

/* Record status as the status of the last call and return it. */
static int dopus_ret(dopus_solver *s, int status)
{
    s->status = status;
    return status;
}

/* The phase of the timer from now on; returns the phase that ran (dopus_timer_switch). */
static int dopus_phase(dopus_solver *s, int phase)
{
    return dopus_timer_switch(&s->timer, phase);
}

static int dopus_has_clock(const dopus_solver *s);

/* ---- the anytime budget (algorithm.md section 14) --------------------------------------- */

/* 1 when a budget is set (a time budget needs a clock). */
static int dopus_budget_on(const dopus_solver *s)
{
    return s->settings.budget > 0.0 && (s->settings.budget_unit == DOPUS_BUDGET_WORK || dopus_has_clock(s));
}

/* Now on the budget's clock: the work counter (work units) or the solver's clock; 0 without
 * a budget (the clock is not read: the phase timers' reads stay theirs). */
static double dopus_budget_now(const dopus_solver *s)
{
    if (!dopus_budget_on(s)) {
        return 0.0;
    }
    if (s->settings.budget_unit == DOPUS_BUDGET_WORK) {
        return s->anytime.work;
    }
    return s->timer.clock ? s->timer.clock(s->timer.ctx) : 0.0;
}

/* A cost measured now against the last estimate: in time, a reading above 1.1 times the
 * estimate raises it by 10 % only (a reading taken while the process was descheduled is not
 * the cost of the work; one such reading would otherwise cut the next QPs and stages); in
 * work units the reading itself (exact). */
static double dopus_cost(const dopus_solver *s, double estimate, double reading)
{
    if (s->settings.budget_unit == DOPUS_BUDGET_TIME && estimate > 0.0 && reading > 1.1 * estimate) {
        return 1.1 * estimate;
    }
    return reading;
}

/* A reserve (the cost of step 3, of steps 6 and 7, of a prepare iteration) measured now
 * against the last estimate: in time it rises as dopus_cost and falls by 10 % at most per
 * reading, so the room kept for the rest of an instant follows its dearer recent readings
 * (the lm test of step 7 varies by up to 40 k instructions between instants on the emulated
 * Cortex-M7, and an instant whose rest was priced at the last, cheaper reading went up to
 * 114 k over a budget of 6 M); in work units the reading itself. */
static double dopus_cost_reserve(const dopus_solver *s, double estimate, double reading)
{
    if (s->settings.budget_unit == DOPUS_BUDGET_TIME && estimate > 0.0 && reading < 0.9 * estimate) {
        return 0.9 * estimate;
    }
    return dopus_cost(s, estimate, reading);
}

/* A part of the least prepare or of the work after a QP (time budget): the peak of its
 * readings. A reading above the estimate raises it, to twice the estimate at most (a reading
 * taken while the process was descheduled is not the cost of the work), one below lowers it
 * by 0.1 % only: the room kept for the rest of an instant follows the dearest recent readings
 * (measured on the emulated Cortex-M7: steps 6 and 7 of the robot arm took 93 k to 222 k
 * instructions between prepare iterations, and priced at a slowly falling last reading the
 * instants went up to 112 k over budgets of 3.2 to 10 M); in work units the reading itself. */
static double dopus_cost_peak(const dopus_solver *s, double estimate, double reading)
{
    if (s->settings.budget_unit != DOPUS_BUDGET_TIME || !(estimate > 0.0)) {
        return reading;
    }
    if (reading > estimate) {
        return reading < 2.0 * estimate ? reading : 2.0 * estimate;
    }
    if (s->anytime.starved) {
        /* the last instant proved the prices too high (dopus_starved_check) */
        return reading > 0.9 * estimate ? reading : 0.9 * estimate;
    }
    return reading > 0.999 * estimate ? reading : 0.999 * estimate;
}

/* The price of one QP iteration for the extra iteration's cap (time budget): the reading
 * `cost` / `iterations` of a QP, the estimate moved by 10 % at most, up or down. A QP whose
 * iterations were unusually cheap (or one descheduled) moves it little: following such a
 * reading (the feedback's estimate, which drops at once) left the caps too generous,
 * measured on the emulated Cortex-M7, where instants went 30 % over their budget; a whole
 * QP as the price cut the extra QPs short on the host (2 ms: the demo's max KKT settled 3e-2
 * to 0.12 instead of 2e-3 to 5e-3). */
static void dopus_cost_qp_step(dopus_solver *s, double cost, int iterations)
{
    double r, e = s->anytime.cost_qp_step;
    if (s->settings.budget_unit != DOPUS_BUDGET_TIME || iterations < 1) {
        return;
    }
    r = cost / (double)iterations;
    s->anytime.cost_qp_step = !(e > 0.0) ? r : r > 1.1 * e ? 1.1 * e : r < 0.9 * e ? 0.9 * e : r;
}

/* 1 without a budget, or when `cost` more still fits in the instant's budget. */
static int dopus_budget_fits(const dopus_solver *s, double cost)
{
    return !dopus_budget_on(s) || dopus_budget_now(s) - s->anytime.instant_start + cost <= s->settings.budget;
}

/* The cost of steps 5 to 7 of a prepare iteration with `fresh_al` stages of 0..N-2 whose
 * stage-cost Hessian step 5 refreshes (those not re-linearised), and of the prepare after
 * it: each stage re-linearised saves its refresh, so the rest of an iteration depends on how
 * many were. */
static double dopus_rest_cost(const dopus_solver *s, int fresh_al)
{
    /* (a constant stage-cost Hessian has no refresh, but after a change of the regularisation) */
    const int refresh = s->settings.cost_hessian && (!DOPUS_COST_HESS_CONST || s->al_resync);
    return (refresh ? s->anytime.cost_al * (double)fresh_al : 0.0) + s->anytime.cost_tail +
           s->anytime.cost_end;
}

/* The least the rest of a prepare iteration costs with `predicted` stages of 0..N-2 still to
 * predict in step 2 (their gradients cut): the iteration's own work, the predictions, step 3
 * and, without a stage re-linearised, steps 5 to 7 and the prepare after them. */
static double dopus_prepare_least(const dopus_solver *s, int predicted)
{
    return s->anytime.cost_fixed + s->anytime.cost_predict * (double)predicted + s->anytime.cost_head +
           dopus_rest_cost(s, DOPUS_N - 1);
}

/* The least a prepare iteration costs: every gradient of stages 0..N-2 cut. */
static double dopus_prepare_floor(const dopus_solver *s)
{
    return dopus_prepare_least(s, DOPUS_N - 1);
}

/* What a QP's deadline leaves free after it for the work that follows it (the step taken)
 * and a prepare iteration costing `prepare`: the QP may pass its last test of the deadline by
 * its finishing work (cost_qp_over). */
static double dopus_after_qp(const dopus_solver *s, double prepare)
{
    return s->anytime.cost_qp_over + s->anytime.cost_fb_tail + prepare;
}

/* At the end of an instant (time budget): its feedback QP stopped by its deadline while the
 * instant still ended with more than half its budget unused proves the prices of the deadline
 * too high (readings taken while the process was descheduled; a QP cut before its first
 * iteration gives no new reading, and the reserves fall by 0.1 % per reading). Until an
 * instant uses half its budget, the feedback QP's deadline then keeps free only what the last
 * instant cost after its feedback QP (when less than the reserves), the QP prices its
 * iterations by its own readings (a fresh price, taken when lower), and the reserves fall by
 * 10 % per reading. On a deterministic clock with a budget that fits, no such instant occurs
 * (algorithm.md section 14). */
static void dopus_starved_check(dopus_solver *s)
{
    s->anytime.starved = dopus_budget_on(s) && s->settings.budget_unit == DOPUS_BUDGET_TIME &&
                         (s->anytime.fb_qp_cut || s->anytime.starved) &&
                         2.0 * s->anytime.used < s->settings.budget;
    s->anytime.rest_last = s->anytime.used - s->anytime.fb_qp_end;
    s->anytime.fb_qp_cut = 0;
}

/* ---- generic information ------------------------------------------------------------ */

size_t dopus_solver_sizeof(void)
{
    return sizeof(dopus_solver);
}

void dopus_get_dims(dopus_dims *dims)
{
    dims->N = DOPUS_N;
    dims->nx = DOPUS_NX;
    dims->nu = DOPUS_NU;
    dims->nw = DOPUS_NW;
    dims->np = DOPUS_NP;
    dims->ng = DOPUS_NG;
    dims->nr = DOPUS_NR;
    dims->ne = DOPUS_NE;
    dims->has_gn = DOPUS_HAS_GN;
    dims->has_nominal = DOPUS_HAS_NOMINAL;
}

const char *dopus_name(void)
{
    return DOPUS_NAME;
}

const char *dopus_status_string(int status)
{
    switch (status) {
    case DOPUS_OK:
        return "ok";
    case DOPUS_ERR_QP:
        return "the QP was not solved (no step taken)";
    case DOPUS_ERR_NONFINITE_INPUT:
        return "NaN or Inf in an input array";
    case DOPUS_ERR_NONFINITE_VALUE:
        return "a generated function returned NaN or Inf";
    case DOPUS_ERR_FUNCTION:
        return "a generated function reported failure";
    case DOPUS_ERR_INVALID_ARGUMENT:
        return "invalid argument";
    case DOPUS_ERR_NOT_INITIALIZED:
        return "the solver is not initialised (call init first)";
    case DOPUS_ERR_NOT_PREPARED:
        return "no prepared QP (call prepare after each feedback)";
    case DOPUS_ERR_NO_NOMINAL:
        return "the solver was generated without a nominal guess";
    case DOPUS_ERR_REGULARIZATION:
        return "the eigen-decomposition of a Hessian block did not converge";
    case DOPUS_ERR_DIVERGED:
        return "the step diverged (outside the problem's scale; no step, fallback control returned)";
    case DOPUS_ERR_ALREADY_PREPARED:
        return "already prepared (call feedback before the next prepare)";
    case DOPUS_ERR_MEASUREMENT_GATED:
        return "the measurement is too far from the plan's prediction (gate): handled as a missing one";
    case DOPUS_ERR_NOT_CONVERGED:
        return "the globalised solve did not reach its tolerance within its limits";
    default:
        return "unknown status";
    }
}

/* ---- health (algorithm.md section 9; the predicates are dopus_health.c) ------------- */

/* Health state after init: no failure, the plan is the iterate's controls (the OCP file's
 * guess before the first init). */
static void dopus_reset_health(dopus_solver *s)
{
    dopus_health_reset(&s->health, s->initialized ? &s->u[0][0] : &dopus_guess_u[0][0]);
}

/* The fallback control of a failed feedback: the next control of the last good plan. */
static void dopus_fallback_u0(dopus_solver *s, dopus_real *u0)
{
    if (dopus_health_fallback(&s->health, s->settings.mode == DOPUS_MODE_RECEDING, u0)) {
        s->health.flags |= DOPUS_FLAG_U0_CLIPPED;
    }
    s->health.flags |= DOPUS_FLAG_FALLBACK;
}

/* A failed feedback: count it, schedule the recovery after K of them, return the fallback. */
static int dopus_feedback_failed(dopus_solver *s, dopus_real *u0, int status)
{
    if (status == DOPUS_ERR_QP || status == DOPUS_ERR_DIVERGED) {
        dopus_lm_feedback(&s->lm, 0);
    }
    s->health.n_failed += 1;
    if (s->settings.recovery && s->settings.mode == DOPUS_MODE_RECEDING &&
        s->health.n_failed >= s->settings.recovery_failures) {
        s->health.recover_pending = 1;
    }
    if (status == DOPUS_ERR_DIVERGED) {
        s->health.flags |= DOPUS_FLAG_DIVERGED;
    }
    dopus_fallback_u0(s, u0);
    return dopus_ret(s, status);
}

/* Divergence measure at the current point (after init or a prepare). */
static dopus_real dopus_kkt_proxy_eval(const dopus_solver *s)
{
    return dopus_kkt_proxy(&s->ring, &s->x[0][0], &s->lam[0][0], s->gL_N, s->mu_bN, s->r_eq);
}

/* The box test of the iterate plus an optional step. */
static int dopus_iterate_box_ok(const dopus_solver *s, const dopus_real *dx, int dx_stride,
                                const dopus_real *du, int du_stride)
{
    return dopus_box_ok(&s->health, s->xhat0, &s->x[0][0], dx, dx_stride, &s->u[0][0], du, du_stride);
}

/* The divergence test of the prepared iterate: box, finite multipliers, KKT proxy bound. */
static int dopus_iterate_diverged(const dopus_solver *s)
{
    return dopus_diverged(&s->health, s->xhat0, &s->x[0][0], &s->u[0][0], &s->lam[0][0], &s->mu_b[0][0],
                          s->mu_bN);
}

static void dopus_qp_bind(dopus_solver *s);
static void dopus_qp_unbind(dopus_solver *s);

/* A factorisation of the next QP at the term lm into the QP's workspace (its data bound for
 * the call, hess_shift restored after), stamped: qp_prefactored its verdict, qp_pre_lm the term.
 * guess 0: dopus_qp_prefactor with no active row, pivots above tol; 1: the active-set start's
 * first factorisation from the warm point in mem.qp.sol (dopus_qp_prefactor_guess). */
static int dopus_prefactor_at(dopus_solver *s, dopus_real lm, dopus_real tol, int guess)
{
    const dopus_real shift = s->qp_in.hess_shift;
    dopus_qp_bind(s);
    s->qp_in.hess_shift = lm;
    s->qp_prefactored = guess ? dopus_qp_prefactor_guess(&s->mem.qp.work, &s->qp_in, &s->mem.qp.sol)
                              : dopus_qp_prefactor(&s->mem.qp.work, &s->qp_in, tol, DOPUS_LM_ROUNDOFF);
    s->qp_pre_lm = lm;
    s->qp_in.hess_shift = shift;
    dopus_qp_unbind(s);
    return s->qp_prefactored;
}

/* The convexity test of the automatic lm (dopus_lm.h, its test hook; ctx: the solver): the QP's
 * factorisation with no active row at the term lm (dopus_qp_prefactor, in the QP's workspace),
 * its pivots above tol and their round-off DOPUS_LM_ROUNDOFF. Each run replaces a kept one:
 * qp_prefactored is its verdict at qp_pre_lm; the prepare keeps the last when it passed at the
 * term it leaves. */
static int dopus_lm_qp_test(void *ctx, dopus_real lm, dopus_real tol)
{
    return dopus_prefactor_at((dopus_solver *)ctx, lm, tol, 0);
}

/* The lm module's test hook, set around each call into it (no pointer into the solver stays
 * between calls). */
static void dopus_lm_hook(dopus_solver *s, int on)
{
    s->lm.test = on ? dopus_lm_qp_test : 0;
    s->lm.test_ctx = on ? (void *)s : 0;
}

/* The automatic lm after init or a re-initialisation (QP assembled), in its phase. */
static void dopus_lm_started(dopus_solver *s)
{
    int prev = dopus_phase(s, DOPUS_PHASE_LM);
    dopus_lm_start(&s->lm, &s->ring, s->A_N, s->mem.ev.lm_work);
    dopus_phase(s, prev);
}

/* 1 when the next feedback's active-set start will guess no active row (a sufficient test:
 * every bound multiplier of the shifted iterate 0, the warm start's, and no row with equal
 * bounds): only then can the QP reuse the prepare's test as its factorisation. */
static int dopus_guess_empty(const dopus_solver *s)
{
    int k, i;
    for (k = 0; k < DOPUS_N; ++k) {
        for (i = 0; i < DOPUS_NW; ++i) {
            if (s->mu_b[k][i] != DOPUS_R(0.0) || s->qp_in.lbw[k][i] == s->qp_in.ubw[k][i]) {
                return 0;
            }
        }
        for (i = 0; i < DOPUS_NG; ++i) {
            if (s->mu_g[k][i] != DOPUS_R(0.0) || s->qp_in.lg[k][i] == s->qp_in.ug[k][i]) {
                return 0;
            }
        }
    }
    for (i = 0; i < DOPUS_NX; ++i) {
        if (s->mu_bN[i] != DOPUS_R(0.0) || s->qp_in.lbxN[i] == s->qp_in.ubxN[i]) {
            return 0;
        }
    }
    for (i = 0; i < DOPUS_NR; ++i) {
        if (s->mu_r[i] != DOPUS_R(0.0) || s->qp_in.lr[i] == s->qp_in.ur[i]) {
            return 0;
        }
    }
    return 1;
}

static void dopus_qp_warm_point(dopus_solver *s);

/* 1 when the next QP's active-set start will run for the state the plan predicts (dx_0 = 0)
 * and take the term the prepare leaves (algorithm.md sections 4 and 10): warm start on, the
 * automatic term below its maximum and not capped at that state (the cap only falls as the
 * measurement moves away: when it does not bind at dx_0 = 0 it does not bind at all), the last
 * warm start not failed; and no budget (section 14: the factorisation would move into the
 * least prepare the feedback's deadline keeps free; on the emulated Cortex-M7 the full RTI then
 * needed 1.5 times the budget it needs without; bench/issue23/measurements.md section 49); and
 * the last QP factorised itself at most DOPUS_PREFACTOR_AFTER times (after a longer one the
 * factorisation would add to the instant's worst case; section 51).
 * After an extra iteration (extra) the feedback keeps the term (no cap, section 14). */
static int dopus_start_prefactor_due(const dopus_solver *s, int extra)
{
    static const dopus_real dx0[DOPUS_NX] = {DOPUS_R(0.0)};
    dopus_lm lm = s->lm;
    if (!s->settings.qp_warm_start || !s->lm.on || s->qp_no_active_set || s->qp_warm_failed ||
        !dopus_lm_can_raise(&s->lm) || dopus_budget_on(s) ||
        s->qp_factorizations - s->qp_pre_used > DOPUS_PREFACTOR_AFTER) {
        return 0;
    }
    if (!extra) {
        dopus_lm_measured(&lm, dx0, s->health.scale_x, s->health.kkt_proxy);
    }
    return lm.lm == s->lm.lm;
}

/* The active-set start's first factorisation of the next QP (its guess from the warm start at
 * the predicted state) into the QP's workspace, stamped at the prepared term: the feedback's
 * first sweep takes it when its guess is the same (dopus_qp_prefactor_guess). */
static void dopus_start_prefactor(dopus_solver *s)
{
    int i;
    dopus_qp_warm_point(s);
    for (i = 0; i < DOPUS_NX; ++i) {
        s->mem.qp.sol.x[0][i] = DOPUS_R(0.0);
    }
    (void)dopus_prefactor_at(s, s->lm.lm, DOPUS_R(0.0), 1);
}

/* ---- function evaluations ----------------------------------------------------------- */

/* F_k (eq. 14) at the current point into s->mem.ev.tmp_F (= gL + mu_b_k), s->mem.ev.tmp_phi, s->mem.ev.tmp_g. */
static int dopus_stage_F_of(dopus_solver *s, int k, dopus_real l);

/* xn = phi(x, u) with stage k's parameters and the stage cost into *l: one stage evaluation
 * outside the stage functions of a walk (the model at a measurement, a simulated node), 1 work
 * unit of the budget; 1 when it succeeded and xn is finite. */
static int dopus_eval_node(dopus_solver *s, int k, const dopus_real *x, const dopus_real *u, dopus_real *xn,
                           dopus_real *l)
{
    s->anytime.work += 1.0;
    return dopus_eval_stage_eval(x, u, s->p[k], xn, l, s->mem.ev.tmp_g, &s->mem.ev.fun_work) == 0 &&
           dopus_lai_vec_finite(DOPUS_NX, xn);
}

static int dopus_stage_F(dopus_solver *s, int k)
{
    dopus_real l = DOPUS_R(0.0);
    s->anytime.work += 1.0;
    if (dopus_eval_stage_grad(s->x[k], s->u[k], s->p[k], s->lam[k + 1], s->mu_g[k], s->mem.ev.tmp_gL,
                              s->mem.ev.tmp_phi, &l, s->mem.ev.tmp_g, &s->mem.ev.fun_work) != 0) {
        return DOPUS_ERR_FUNCTION;
    }
    return dopus_stage_F_of(s, k, l);
}

/* dopus_stage_F and the evaluation of dopus_stage_H in one call (stage_grad_hess_exact or
 * _gn, the setting's Hessian): F_k as dopus_stage_F, A, Phi, C in s->mem.ev.tmp_A/Phi/C for
 * dopus_stage_H_keep, the stage's slot untouched. */
static int dopus_stage_FH(dopus_solver *s, int k)
{
    dopus_real l = DOPUS_R(0.0);
    s->anytime.work += 2.0;
    if (dopus_eval_stage_grad_hess(s->settings.hessian, s->x[k], s->u[k], s->p[k], s->lam[k + 1], s->mu_g[k],
                                   s->mem.ev.tmp_gL, s->mem.ev.tmp_phi, &l, s->mem.ev.tmp_g, s->mem.ev.tmp_A,
                                   s->mem.ev.tmp_Phi, s->mem.ev.tmp_C, &s->mem.ev.fun_work) != 0) {
        return DOPUS_ERR_FUNCTION;
    }
    return dopus_stage_F_of(s, k, l);
}

/* The checks and tmp_F of dopus_stage_F on the evaluated gL, phi, l, g. */
static int dopus_stage_F_of(dopus_solver *s, int k, dopus_real l)
{
    int i;
    if (!dopus_lai_vec_finite(DOPUS_NW, s->mem.ev.tmp_gL) ||
        !dopus_lai_vec_finite(DOPUS_NX, s->mem.ev.tmp_phi) ||
        !dopus_lai_vec_finite(DOPUS_NG, s->mem.ev.tmp_g) || !isfinite(l)) {
        return DOPUS_ERR_NONFINITE_VALUE;
    }
    for (i = 0; i < DOPUS_NW; ++i) {
        s->mem.ev.tmp_F[i] = s->mem.ev.tmp_gL[i] + s->mu_b[k][i];
    }
    return DOPUS_OK;
}

/* Regularise a fresh A block (algorithm.md section 5), timed as its own phase. */
static int dopus_regularize(dopus_solver *s, int n, dopus_real *A)
{
    int rc, prev;
    if (s->settings.regularization == DOPUS_REG_NONE) {
        return DOPUS_OK;
    }
    prev = dopus_phase(s, DOPUS_PHASE_REGULARIZATION);
    rc = dopus_reg_apply(n, A, s->settings.regularization, s->settings.reg_eps, s->mem.ev.reg_work);
    dopus_phase(s, prev);
    return rc == 0 ? DOPUS_OK : DOPUS_ERR_REGULARIZATION;
}

/* The stage-cost Hessian A_l of stage k at the current point into s->mem.ev.tmp_Al. */
static int dopus_stage_Al(dopus_solver *s, int k)
{
    int prev = dopus_phase(s, DOPUS_PHASE_HESSIANS);
    int rc = dopus_eval_stage_hess_cost(s->settings.hessian, s->x[k], s->u[k], s->p[k], s->mem.ev.tmp_Al,
                                        &s->mem.ev.fun_work);
    rc = rc != 0 ? DOPUS_ERR_FUNCTION
                 : (dopus_lai_vec_finite(DOPUS_NW * DOPUS_NW, s->mem.ev.tmp_Al) ? DOPUS_OK
                                                                                : DOPUS_ERR_NONFINITE_VALUE);
    dopus_phase(s, prev);
    return rc;
}

/* H_k (eq. 15) at the current point, A regularised, stored in stage k's slot with
 * A_dyn = A - A_l (unregularised). Evaluated into scratch first, so a failed evaluation
 * leaves the slot as it was. */
static int dopus_stage_H_store(dopus_solver *s, int k);

static int dopus_stage_H_eval(dopus_solver *s, int k)
{
    dopus_real gL[DOPUS_NW], phi[DOPUS_NX], l, g[DOPUS_DIM(DOPUS_NG)];
    if (s->settings.hessian == DOPUS_HESSIAN_EXACT) {
        /* the exact Hessian through the fused function, its gradient outputs unused: the one
         * Hessian code whichever stages are fresh (the instruction cache; its forward-over-
         * adjoint pass needs the adjoint anyway). The Gauss-Newton blocks need no adjoint:
         * stage_hess_gn alone. */
        if (dopus_eval_stage_grad_hess(DOPUS_HESSIAN_EXACT, s->x[k], s->u[k], s->p[k], s->lam[k + 1],
                                       s->mu_g[k], gL, phi, &l, g, s->mem.ev.tmp_A, s->mem.ev.tmp_Phi,
                                       s->mem.ev.tmp_C, &s->mem.ev.fun_work) != 0) {
            return DOPUS_ERR_FUNCTION;
        }
        return dopus_stage_H_store(s, k);
    }
    if (dopus_eval_stage_hess(s->settings.hessian, s->x[k], s->u[k], s->p[k], s->lam[k + 1], s->mu_g[k],
                              s->mem.ev.tmp_A, s->mem.ev.tmp_Phi, s->mem.ev.tmp_C,
                              &s->mem.ev.fun_work) != 0) {
        return DOPUS_ERR_FUNCTION;
    }
    return dopus_stage_H_store(s, k);
}

/* The rest of dopus_stage_H_eval on A, Phi, C in s->mem.ev.tmp_A/Phi/C: checks, A_dyn,
 * regularisation, stage k's slot. */
static int dopus_stage_H_store(dopus_solver *s, int k)
{
    dopus_stage_slot *slot;
    int rc, i;
    if (!dopus_lai_vec_finite(DOPUS_NW * DOPUS_NW, s->mem.ev.tmp_A) ||
        !dopus_lai_vec_finite(DOPUS_NX * DOPUS_NW, s->mem.ev.tmp_Phi) ||
        !dopus_lai_vec_finite(DOPUS_NG * DOPUS_NW, s->mem.ev.tmp_C)) {
        return DOPUS_ERR_NONFINITE_VALUE;
    }
    /* A_dyn = A - A_l, kept whatever cost_hessian is, so the setting may change at any time */
    rc = dopus_stage_Al(s, k);
    if (rc != DOPUS_OK) {
        return rc;
    }
    for (i = 0; i < DOPUS_NW * DOPUS_NW; ++i) {
        s->mem.ev.tmp_Al[i] = s->mem.ev.tmp_A[i] - s->mem.ev.tmp_Al[i];
    }
    rc = dopus_regularize(s, DOPUS_NW, s->mem.ev.tmp_A);
    if (rc != DOPUS_OK) {
        return rc;
    }
    slot = dopus_ring_stage(&s->ring, k);
    dopus_ring_set_H(slot, s->mem.ev.tmp_A);
    dopus_ring_set_A_dyn(slot, s->mem.ev.tmp_Al);
    dopus_copy(slot->Phit, s->mem.ev.tmp_Phi, DOPUS_NX * DOPUS_NW);
    dopus_copy(slot->Ct, s->mem.ev.tmp_C, DOPUS_NG * DOPUS_NW);
    return DOPUS_OK;
}

/* dopus_stage_H_eval in the phase "hessians" (its regularisation in its own). */
static int dopus_stage_H(dopus_solver *s, int k)
{
    int prev = dopus_phase(s, DOPUS_PHASE_HESSIANS);
    int rc;
    s->anytime.work += 1.0;
    rc = dopus_stage_H_eval(s, k);
    dopus_phase(s, prev);
    return rc;
}

/* The H_k that dopus_stage_FH evaluated, stored as dopus_stage_H stores it (phase "hessians"). */
static int dopus_stage_H_keep(dopus_solver *s, int k)
{
    int prev = dopus_phase(s, DOPUS_PHASE_HESSIANS);
    int rc = dopus_stage_H_store(s, k);
    dopus_phase(s, prev);
    return rc;
}

/* The terminal gradient (term_grad) at the current point: gL (nx), E, r (nr), r_eq (ne).
 * DOPUS_ERR_FUNCTION when the function fails, DOPUS_ERR_NONFINITE_VALUE when a value is not
 * finite, else DOPUS_OK. */
static int dopus_term_grad_checked(dopus_solver *s, dopus_real *gL, dopus_real *E, dopus_real *r,
                                   dopus_real *r_eq)
{
    if (dopus_eval_term_grad(s->x[DOPUS_N], s->p[DOPUS_N], s->mu_r, s->nu, gL, E, r, r_eq,
                             &s->mem.ev.fun_work) != 0) {
        return DOPUS_ERR_FUNCTION;
    }
    if (!dopus_lai_vec_finite(DOPUS_NX, gL) || !isfinite(*E) || !dopus_lai_vec_finite(DOPUS_NR, r) ||
        !dopus_lai_vec_finite(DOPUS_NE, r_eq)) {
        return DOPUS_ERR_NONFINITE_VALUE;
    }
    return DOPUS_OK;
}

/* Terminal F: gL_N, E, r, r_eq at the current point. */
static int dopus_term_F(dopus_solver *s)
{
    dopus_real gL[DOPUS_NX], E = DOPUS_R(0.0), r[DOPUS_DIM(DOPUS_NR)], r_eq[DOPUS_DIM(DOPUS_NE)];
    int rc;
    s->anytime.work += 1.0;
    rc = dopus_term_grad_checked(s, gL, &E, r, r_eq);
    if (rc != DOPUS_OK) {
        return rc;
    }
    dopus_copy(s->gL_N, gL, DOPUS_NX);
    s->E = E;
    dopus_copy(s->r, r, DOPUS_NR);
    dopus_copy(s->r_eq, r_eq, DOPUS_NE);
    return DOPUS_OK;
}

/* Terminal H: A_N (regularised), R, R_eq. */
static int dopus_term_H_eval(dopus_solver *s)
{
    dopus_real R[DOPUS_DIM(DOPUS_NR) * DOPUS_NX], R_eq[DOPUS_DIM(DOPUS_NE) * DOPUS_NX];
    int rc;
    rc = dopus_eval_term_hess(s->settings.hessian, s->x[DOPUS_N], s->p[DOPUS_N], s->mu_r, s->nu,
                              s->mem.ev.tmp_A, R, R_eq, &s->mem.ev.fun_work);
    if (rc != 0) {
        return DOPUS_ERR_FUNCTION;
    }
    if (!dopus_lai_vec_finite(DOPUS_NX * DOPUS_NX, s->mem.ev.tmp_A) ||
        !dopus_lai_vec_finite(DOPUS_NR * DOPUS_NX, R) || !dopus_lai_vec_finite(DOPUS_NE * DOPUS_NX, R_eq)) {
        return DOPUS_ERR_NONFINITE_VALUE;
    }
    rc = dopus_regularize(s, DOPUS_NX, s->mem.ev.tmp_A);
    if (rc != DOPUS_OK) {
        return rc;
    }
    dopus_copy(s->A_N, s->mem.ev.tmp_A, DOPUS_NX * DOPUS_NX);
    dopus_copy(s->R, R, DOPUS_NR * DOPUS_NX);
    dopus_copy(s->R_eq, R_eq, DOPUS_NE * DOPUS_NX);
    return DOPUS_OK;
}

static int dopus_term_H(dopus_solver *s)
{
    int prev = dopus_phase(s, DOPUS_PHASE_HESSIANS);
    int rc;
    s->anytime.work += 1.0;
    rc = dopus_term_H_eval(s);
    dopus_phase(s, prev);
    return rc;
}

/* ---- QP assembly (algorithm.md section 3) ------------------------------------------- */

static void dopus_assemble(dopus_solver *s)
{
    dopus_qp_in *in = &s->qp_in;
    int k, i, j, prev = dopus_phase(s, DOPUS_PHASE_ASSEMBLY);

    for (k = 0; k < DOPUS_N; ++k) {
        const dopus_stage_slot *slot = dopus_ring_stage_const(&s->ring, k);
        /* a_k = F_w,k + Phit_k' lam_{k+1} - Ct_k' mu_g_k - mu_b_k (eq. 12) */
        for (i = 0; i < DOPUS_NW; ++i) {
            dopus_real pl = DOPUS_R(0.0), cm = DOPUS_R(0.0);
            for (j = 0; j < DOPUS_NX; ++j) {
                pl += slot->Phit[j + i * DOPUS_NX] * s->lam[k + 1][j];
            }
            for (j = 0; j < DOPUS_NG; ++j) {
                cm += slot->Ct[j + i * DOPUS_DIM(DOPUS_NG)] * s->mu_g[k][j];
            }
            in->g[k][i] = slot->F_w[i] + pl - cm - s->mu_b[k][i];
        }
        /* dx_{k+1} = Phit_k dw_k + (phi_k - x_{k+1}) */
        for (i = 0; i < DOPUS_NX; ++i) {
            in->b[k][i] = slot->phi[i] - s->x[k + 1][i];
        }
        for (i = 0; i < DOPUS_NX; ++i) {
            in->lbw[k][i] = dopus_x_bounded(k) ? dopus_lbx[i] - s->x[k][i] : -INFINITY;
            in->ubw[k][i] = dopus_x_bounded(k) ? dopus_ubx[i] - s->x[k][i] : INFINITY;
        }
        for (i = 0; i < DOPUS_NU; ++i) {
            in->lbw[k][DOPUS_NX + i] = dopus_lbu[i] - s->u[k][i];
            in->ubw[k][DOPUS_NX + i] = dopus_ubu[i] - s->u[k][i];
        }
        for (i = 0; i < DOPUS_NG; ++i) {
            in->lg[k][i] = dopus_lg_k[k][i] - slot->g[i];
            in->ug[k][i] = dopus_ug_k[k][i] - slot->g[i];
        }
    }
    /* a_N = gL_N - R' mu_r - R_eq' nu (= grad E) */
    for (i = 0; i < DOPUS_NX; ++i) {
        dopus_real rm = DOPUS_R(0.0), en = DOPUS_R(0.0);
        for (j = 0; j < DOPUS_NR; ++j) {
            rm += s->R[j + i * DOPUS_DIM(DOPUS_NR)] * s->mu_r[j];
        }
        for (j = 0; j < DOPUS_NE; ++j) {
            en += s->R_eq[j + i * DOPUS_DIM(DOPUS_NE)] * s->nu[j];
        }
        in->gN[i] = s->gL_N[i] - rm - en;
        in->lbxN[i] = dopus_lbx[i] - s->x[DOPUS_N][i];
        in->ubxN[i] = dopus_ubx[i] - s->x[DOPUS_N][i];
    }
    for (i = 0; i < DOPUS_NR; ++i) {
        in->lr[i] = dopus_lr[i] - s->r[i];
        in->ur[i] = dopus_ur[i] - s->r[i];
    }
    for (i = 0; i < DOPUS_NE; ++i) {
        in->req[i] = -s->r_eq[i];
    }
#if DOPUS_NSOFT > 0
    /* soft weights: the rows of a stage (x, u (hard), g) and the terminal rows (x_N, r) */
    for (j = 0; j < 4; ++j) {
        dopus_real *st = j == 0 ? in->zl : j == 1 ? in->zu : j == 2 ? in->Zl : in->Zu;
        dopus_real *te = j == 0 ? in->zlN : j == 1 ? in->zuN : j == 2 ? in->ZlN : in->ZuN;
        for (i = 0; i < DOPUS_NX; ++i) {
            st[i] = te[i] = dopus_soft_x[j][i];
        }
        for (i = 0; i < DOPUS_NU; ++i) {
            st[DOPUS_NX + i] = DOPUS_R(0.0);
        }
        for (i = 0; i < DOPUS_NG; ++i) {
            st[DOPUS_NW + i] = dopus_soft_g[j][i];
        }
        for (i = 0; i < DOPUS_NR; ++i) {
            te[DOPUS_NX + i] = dopus_soft_r[j][i];
        }
    }
#endif
    dopus_phase(s, prev);
}

/* ---- init --------------------------------------------------------------------------- */

/* F (stored as F_old) and H of every stage, terminal F and H, at the current iterate. */
static int dopus_linearize_all_eval(dopus_solver *s)
{
    double b0, t_F = 0.0, t_H = 0.0;
    int k, rc;
    for (k = 0; k < DOPUS_N; ++k) {
        b0 = dopus_budget_now(s);
        rc = dopus_stage_F(s, k);
        if (rc != DOPUS_OK) {
            return rc;
        }
        t_F += dopus_budget_now(s) - b0;
        dopus_ring_store_F(dopus_ring_stage(&s->ring, k), s->mem.ev.tmp_F, s->mem.ev.tmp_phi,
                           s->mem.ev.tmp_g);
        b0 = dopus_budget_now(s);
        rc = dopus_stage_H(s, k);
        if (rc != DOPUS_OK) {
            return rc;
        }
        t_H += dopus_budget_now(s) - b0;
    }
    b0 = dopus_budget_now(s);
    rc = dopus_term_F(s);
    if (rc == DOPUS_OK) {
        rc = dopus_term_H(s);
    }
    if (rc == DOPUS_OK && dopus_budget_on(s)) {
        /* the first estimates of a budget (algorithm.md section 14): a gradient, a stage
         * re-linearisation and step 3 of prepare, before any prepare has measured them */
        s->anytime.cost_grad = t_F / (double)DOPUS_N;
        s->anytime.cost_stage = t_H / (double)DOPUS_N;
        s->anytime.cost_fh = s->anytime.cost_grad + s->anytime.cost_stage;
        s->anytime.cost_head = s->anytime.cost_grad + s->anytime.cost_stage + (dopus_budget_now(s) - b0);
        /* one refresh of step 5 (stage 0, into scratch; not counted in work units) */
        b0 = dopus_budget_now(s);
        if (s->settings.cost_hessian && dopus_stage_Al(s, 0) == DOPUS_OK) {
            dopus_ring_add_A_dyn(dopus_ring_stage(&s->ring, 0), s->mem.ev.tmp_Al, s->mem.ev.tmp_A);
            (void)dopus_regularize(s, DOPUS_NW, s->mem.ev.tmp_A);
        }
        s->anytime.cost_al = dopus_budget_now(s) - b0;
        /* one prediction of a cut stage (stage 0, into step 2's scratch) */
        b0 = dopus_budget_now(s);
        dopus_ring_predict(dopus_ring_stage(&s->ring, 0), s->mem.ev.Fn_w[0], s->mem.ev.Fn_phi[0],
                           s->mem.ev.Fn_g[0]);
        s->anytime.cost_predict = dopus_budget_now(s) - b0;
    }
    return rc;
}

static int dopus_qp_solve_bound(dopus_solver *s, int warm, int active_set, int max_iter);

/* The first price of one QP iteration (time budget, before any QP was timed): one cold
 * iteration (the solve's own cap, the setting untouched) of the prepared QP, for the last
 * measurement, timed with the solve's own setup; at init when the budget is set before it,
 * else at the first feedback under the budget, before its QP. Its result is not used: the QP's
 * solution buffer is live only inside a feedback (it shares its memory with the scratch of
 * the evaluations), and the feedback's QP starts from its own point, warm or cold; the QP's
 * figures (dopus_info) and its x0 stay. Without it the first feedback's QP had no price for
 * its first iteration, which could pass the deadline by one iteration. */
static void dopus_price_qp(dopus_solver *s)
{
    const dopus_qp_info info = s->qp_info;
    dopus_real x0[DOPUS_NX];
    double b0;
    int i;
    if (!dopus_budget_on(s) || s->settings.budget_unit != DOPUS_BUDGET_TIME ||
        s->anytime.cost_qp_iter > 0.0 || !s->qp_ready) {
        return;
    }
    dopus_copy(x0, s->qp_in.x0, DOPUS_NX);
    for (i = 0; i < DOPUS_NX; ++i) {
        s->qp_in.x0[i] = s->xhat0[i] - s->x[0][i];
    }
    s->qp_in.hess_shift = s->lm.lm;
    b0 = dopus_budget_now(s);
    (void)dopus_qp_solve_bound(s, 0, 0, 1);
    s->anytime.cost_qp_iter = dopus_budget_now(s) - b0;
    if (!(s->anytime.cost_qp_step > 0.0)) {
        s->anytime.cost_qp_step = s->anytime.cost_qp_iter;
    }
    s->qp_info = info;
    dopus_copy(s->qp_in.x0, x0, DOPUS_NX);
}

/* dopus_linearize_all_eval in the phase "gradients" (the blocks in theirs). */
static int dopus_linearize_all(dopus_solver *s)
{
    int prev = dopus_phase(s, DOPUS_PHASE_GRADIENTS);
    int rc = dopus_linearize_all_eval(s);
    dopus_phase(s, prev);
    return rc;
}

/* The second half of init with the iterate in place: ring reset, F and H of every stage and
 * the terminal node, QP assembly. */
/* Before every stage is linearised afresh (init, a re-initialisation): an empty ring, every
 * stage selected, no QP figures, the stage-cost Hessians to be refreshed. */
static void dopus_fresh_start(dopus_solver *s)
{
    int k;
    s->anytime.prepared_extra = 0;
    dopus_ring_reset(&s->ring);
    for (k = 0; k < DOPUS_N; ++k) {
        s->rho[k] = DOPUS_R(0.0);
        s->selected[k] = 1; /* every stage is fresh */
    }
    s->qp_status = 0;
    s->qp_iterations = 0;
    s->qp_factorizations = 0;
    s->qp_pre_used = 0;
    s->al_resync = 1;
}

static int dopus_init_finish(dopus_solver *s)
{
    double b0;
    int rc;
    dopus_fresh_start(s);
    rc = dopus_linearize_all(s);
    if (rc != DOPUS_OK) {
        return rc;
    }
    s->al_resync = 0; /* every block fresh: Ht = reg(A) = reg(A_dyn + A_l) */
    b0 = dopus_budget_now(s);
    dopus_assemble(s);
    s->initialized = 1;
    s->qp_ready = 1;
    s->prepare_due = 0;
    s->shifted = 0;
    dopus_lm_started(s);
    if (dopus_budget_on(s)) {
        /* the first estimate of steps 6 and 7 of prepare (the assembly and the lm test) */
        s->anytime.cost_tail = dopus_budget_now(s) - b0;
    }
    dopus_price_qp(s);
    return DOPUS_OK;
}

/* Scaling (docs/algorithm.md section 16): the API's values are in the declared units, the
 * iterate in the solver's: x / scale_x, u / scale_u, a multiplier of a row of scale d times
 * d / scale_cost. */
static dopus_real dopus_scale_w(int i)
{
    return i < DOPUS_NX ? dopus_scale_x[i] : dopus_scale_u[i - DOPUS_NX];
}

/* out = in / d (n entries); NULL in gives NULL */
static const dopus_real *dopus_scaled_in(const dopus_real *in, const dopus_real *d, int n, dopus_real *out)
{
    int i;
    if (in == 0) {
        return 0;
    }
    for (i = 0; i < n; ++i) {
        out[i] = in[i] / d[i];
    }
    return out;
}

/* out = in * d (n entries, d repeating with period nd) */
static void dopus_scaled_out(dopus_real *out, const dopus_real *in, const dopus_real *d, int n, int nd)
{
    int i;
    for (i = 0; i < n; ++i) {
        out[i] = in[i] * d[i % nd];
    }
}

/* out = in * scale_cost / d (multipliers; d repeating with period nd) */
static void dopus_dual_out(dopus_real *out, const dopus_real *in, const dopus_real *d, int n, int nd)
{
    int i;
    for (i = 0; i < n; ++i) {
        out[i] = in[i] * dopus_scale_cost / d[i % nd];
    }
}

int dopus_init(dopus_solver *s, const dopus_real *xhat0, const dopus_real *x, const dopus_real *u,
               const dopus_real *lam, const dopus_real *mu_g, const dopus_real *mu_b, const dopus_real *mu_bN,
               const dopus_real *mu_r, const dopus_real *nu)
{
    int k, i, rc;

    if (!s->set_up) {
        return DOPUS_ERR_NOT_INITIALIZED;
    }
    s->initialized = 0;
    s->qp_prefactored = 0;
    dopus_reset_health(s);
    s->qp_ready = 0;
    s->p_shifted = 0;
    s->anytime.reinit_next = -1;
    if ((xhat0 && !dopus_lai_vec_finite(DOPUS_NX, xhat0)) ||
        (x && !dopus_lai_vec_finite((DOPUS_N + 1) * DOPUS_NX, x)) ||
        (u && !dopus_lai_vec_finite(DOPUS_N * DOPUS_NU, u)) ||
        (lam && !dopus_lai_vec_finite((DOPUS_N + 1) * DOPUS_NX, lam)) ||
        (mu_g && !dopus_lai_vec_finite(DOPUS_N * DOPUS_NG, mu_g)) ||
        (mu_b && !dopus_lai_vec_finite(DOPUS_N * DOPUS_NW, mu_b)) ||
        (mu_bN && !dopus_lai_vec_finite(DOPUS_NX, mu_bN)) ||
        (mu_r && !dopus_lai_vec_finite(DOPUS_NR, mu_r)) || (nu && !dopus_lai_vec_finite(DOPUS_NE, nu))) {
        return dopus_ret(s, DOPUS_ERR_NONFINITE_INPUT);
    }
    dopus_timer_begin(&s->timer, (1u << DOPUS_N_PHASES) - 1u, DOPUS_PHASE_GRADIENTS);

    for (i = 0; i < DOPUS_NX; ++i) {
        s->xhat0[i] = (xhat0 ? xhat0[i] : dopus_x0_default[i]) / dopus_scale_x[i];
    }
    for (i = 0; i < DOPUS_NU; ++i) {
        s->u_applied[i] = DOPUS_R(0.0);
    }
    for (i = 0; i < DOPUS_NMEM; ++i) {
        /* the last applied control before the first feedback: the memory entries of xhat0 */
        s->u_applied[dopus_memory_control[i]] = s->xhat0[dopus_memory_state[i]];
    }
    for (k = 0; k <= DOPUS_N; ++k) {
        for (i = 0; i < DOPUS_NX; ++i) {
            s->x[k][i] = x ? x[k * DOPUS_NX + i] / dopus_scale_x[i] : dopus_guess_x[k][i];
            s->lam[k][i] = lam ? lam[k * DOPUS_NX + i] * dopus_scale_x[i] / dopus_scale_cost : DOPUS_R(0.0);
        }
    }
    for (k = 0; k < DOPUS_N; ++k) {
        for (i = 0; i < DOPUS_NU; ++i) {
            s->u[k][i] = u ? u[k * DOPUS_NU + i] / dopus_scale_u[i] : dopus_guess_u[k][i];
        }
        for (i = 0; i < DOPUS_DIM(DOPUS_NG); ++i) {
            s->mu_g[k][i] = (mu_g && i < DOPUS_NG)
                                ? mu_g[k * DOPUS_NG + i] * dopus_scale_g[i] / dopus_scale_cost
                                : DOPUS_R(0.0);
        }
        for (i = 0; i < DOPUS_NW; ++i) {
            s->mu_b[k][i] =
                mu_b ? mu_b[k * DOPUS_NW + i] * dopus_scale_w(i) / dopus_scale_cost : DOPUS_R(0.0);
        }
    }
    dopus_clear_x0_multiplier(s);
    for (i = 0; i < DOPUS_NX; ++i) {
        s->mu_bN[i] = mu_bN ? mu_bN[i] * dopus_scale_x[i] / dopus_scale_cost : DOPUS_R(0.0);
    }
    for (i = 0; i < DOPUS_DIM(DOPUS_NR); ++i) {
        s->mu_r[i] = (mu_r && i < DOPUS_NR) ? mu_r[i] * dopus_scale_r[i] / dopus_scale_cost : DOPUS_R(0.0);
    }
    for (i = 0; i < DOPUS_DIM(DOPUS_NE); ++i) {
        s->nu[i] = (nu && i < DOPUS_NE) ? nu[i] * dopus_scale_req[i] / dopus_scale_cost : DOPUS_R(0.0);
    }

    rc = dopus_init_finish(s);
    if (rc == DOPUS_OK) {
        dopus_reset_health(s);
        s->health.kkt_proxy = dopus_kkt_proxy_eval(s);
        s->health.kkt_proxy_ref = s->health.kkt_proxy;
        s->health.kkt_proxy_init = s->health.kkt_proxy;
        /* the first feedback's first factorisation, as a prepare leaves it */
        if (dopus_start_prefactor_due(s, 0)) {
            dopus_start_prefactor(s);
        }
    }
    dopus_timer_end(&s->timer, -1, 0.0);
    return dopus_ret(s, rc);
}

int dopus_init_nominal(dopus_solver *s, const dopus_real *xhat0)
{
#if DOPUS_HAS_NOMINAL
    return dopus_init(s, xhat0, &dopus_nominal_x[0][0], &dopus_nominal_u[0][0], &dopus_nominal_lam[0][0],
                      DOPUS_NG > 0 ? &dopus_nominal_mu_g[0][0] : 0, &dopus_nominal_mu_b[0][0],
                      dopus_nominal_mu_bN, DOPUS_NR > 0 ? dopus_nominal_mu_r : 0,
                      DOPUS_NE > 0 ? dopus_nominal_nu : 0);
#else
    (void)xhat0;
    if (!s->set_up) {
        return DOPUS_ERR_NOT_INITIALIZED;
    }
    return dopus_ret(s, DOPUS_ERR_NO_NOMINAL);
#endif
}

/* ---- feedback ----------------------------------------------------------------------- */

static int dopus_qp_solution_finite(const dopus_qp_sol *sol)
{
    return dopus_lai_vec_finite((DOPUS_N + 1) * DOPUS_NX, &sol->x[0][0]) &&
           dopus_lai_vec_finite(DOPUS_N * DOPUS_QP_NU1, &sol->u[0][0]) &&
           dopus_lai_vec_finite((DOPUS_N + 1) * DOPUS_NX, &sol->lam[0][0]) &&
           dopus_lai_vec_finite(DOPUS_N * DOPUS_QP_NW, &sol->mu_b[0][0]) &&
           dopus_lai_vec_finite(DOPUS_NX, sol->mu_bN) &&
           dopus_lai_vec_finite(DOPUS_N * DOPUS_QP_NG1, &sol->mu_g[0][0]) &&
           dopus_lai_vec_finite(DOPUS_QP_NR1, sol->mu_r) && dopus_lai_vec_finite(DOPUS_QP_NE1, sol->nu);
}

/* Warm-start point of the QP (in s->mem.qp.sol): the previous QP solution shifted with the
 * horizon. Its primal part has been added to the iterate, which prepare shifted, so it is
 * a zero step from the (shifted) iterate, with x_0's step fixed by the measurement; the
 * multipliers are the (shifted) iterate's, which are those of the previous QP. */
static void dopus_qp_warm_point(dopus_solver *s)
{
    dopus_qp_sol *w = &s->mem.qp.sol;
    int k, i;
    for (k = 0; k <= DOPUS_N; ++k) {
        for (i = 0; i < DOPUS_NX; ++i) {
            w->x[k][i] = k == 0 ? s->qp_in.x0[i] : DOPUS_R(0.0);
            w->lam[k][i] = s->lam[k][i];
        }
    }
    for (k = 0; k < DOPUS_N; ++k) {
        for (i = 0; i < DOPUS_QP_NU1; ++i) {
            w->u[k][i] = DOPUS_R(0.0);
        }
        for (i = 0; i < DOPUS_NW; ++i) {
            w->mu_b[k][i] = s->mu_b[k][i];
        }
        for (i = 0; i < DOPUS_QP_NG1; ++i) {
            w->mu_g[k][i] = i < DOPUS_NG ? s->mu_g[k][i] : DOPUS_R(0.0);
        }
    }
    for (i = 0; i < DOPUS_NX; ++i) {
        w->mu_bN[i] = s->mu_bN[i];
    }
    for (i = 0; i < DOPUS_QP_NR1; ++i) {
        w->mu_r[i] = i < DOPUS_NR ? s->mu_r[i] : DOPUS_R(0.0);
    }
    for (i = 0; i < DOPUS_QP_NE1; ++i) {
        w->nu[i] = i < DOPUS_NE ? s->nu[i] : DOPUS_R(0.0);
    }
}

/* Feedback step 1: the call is refused before the QP when the solver is not initialised,
 * the measurement is not finite or no QP is prepared (the fallback control is returned).
 * Returns DOPUS_OK when the QP is to be solved, else the status of the failed call. */
/* The measurement gate (algorithm.md section 9; receding mode, recovery on, gate > 0): 1 when
 * some |xhat0_i - x_0,i| exceeds gate scale_x_i (x_0: the state the plan predicts for the
 * instant) and fewer than gate_hold measurements in a row were gated. The measurement after
 * gate_hold gated ones is accepted whatever its jump, and so are the next gate_hold ones (the
 * gate rests while the loop re-converges on what it accepted). */
static int dopus_gated(dopus_solver *s, const dopus_real *xhat0)
{
    int i, jump = 0;
    if (!(s->settings.gate > DOPUS_R(0.0)) || !s->settings.recovery ||
        s->settings.mode != DOPUS_MODE_RECEDING) {
        return 0;
    }
    if (s->health.gate_rest > 0) {
        s->health.gate_rest -= 1;
        return 0;
    }
    for (i = 0; i < DOPUS_NX; ++i) {
        jump |= dopus_fabs(xhat0[i] - s->x[0][i]) > s->settings.gate * s->health.scale_x[i];
    }
    if (jump && s->health.n_gated >= s->settings.gate_hold) {
        s->health.gate_rest = s->settings.gate_hold;
    }
    if (!jump || s->health.n_gated >= s->settings.gate_hold) {
        s->health.n_gated = 0;
        return 0;
    }
    s->health.n_gated += 1;
    return 1;
}

/* A feedback that attempts no QP: whether its measurement counts (xhat_fresh), and in
 * receding mode the sampling instant has passed all the same, so its prepare (the shift)
 * is due. */
static void dopus_instant_passed(dopus_solver *s, int xhat_fresh)
{
    s->health.xhat_fresh = xhat_fresh;
    if (s->settings.mode == DOPUS_MODE_RECEDING) {
        s->prepare_due = 1;
        s->shifted = 0;
    }
}

static int dopus_feedback_admit(dopus_solver *s, const dopus_real *xhat0, dopus_real *u0)
{
    if (!s->initialized) {
        dopus_fallback_u0(s, u0);
        return dopus_ret(s, DOPUS_ERR_NOT_INITIALIZED);
    }
    if (xhat0 == 0 || !dopus_lai_vec_finite(DOPUS_NX, xhat0)) {
        dopus_instant_passed(s, 0);
        return dopus_feedback_failed(s, u0, DOPUS_ERR_NONFINITE_INPUT);
    }
    if (!s->qp_ready) {
        /* counted as a failed instant: a prepare that keeps failing ends in a recovery, which
         * starts from the newest measurement, so it is recorded all the same (algorithm.md
         * section 9) */
        dopus_copy(s->xhat0, xhat0, DOPUS_NX);
        dopus_instant_passed(s, 1);
        return dopus_feedback_failed(s, u0, DOPUS_ERR_NOT_PREPARED);
    }
    if (dopus_gated(s, xhat0)) {
        /* as a missing measurement: the previous one stays the last, the prepare's predicted
         * step carries the loop (algorithm.md section 9) */
        dopus_instant_passed(s, 0);
        return dopus_feedback_failed(s, u0, DOPUS_ERR_MEASUREMENT_GATED);
    }
    return DOPUS_OK;
}

/* Step 2: the measurement enters the QP as the fixed step of x_0. */
static void dopus_feedback_measure(dopus_solver *s, const dopus_real *xhat0)
{
    int i;
    for (i = 0; i < DOPUS_NX; ++i) {
        s->xhat0[i] = xhat0[i];
        s->qp_in.x0[i] = xhat0[i] - s->x[0][i];
    }
    s->health.xhat_fresh = 1;
    if (!s->anytime.prepared_extra) {
        /* (after extra iterations the term the prepare convexified stays: the iterate has
         * converged at the predicted state and the capped term, 0 there, left QPs that are
         * convex only on the active bounds; algorithm.md section 14) */
        dopus_lm_measured(&s->lm, s->qp_in.x0, s->health.scale_x, s->health.kkt_proxy);
    }
    /* the QP is attempted: a prepare (with its shift) is due, whatever the outcome */
    s->prepare_due = 1;
    s->shifted = 0;
}

/* The budget's clock as the QP's (ctx: the solver): the work counter in work units, which
 * the QP's own N units have already moved, or the solver's clock in time. Each read is kept
 * with the price of one iteration the QP has at that read (its first price, then the largest
 * gap between two reads, as dopus_qp.c prices it), for dopus_qp_over (time only). */
static double dopus_qp_clock(void *ctx)
{
    dopus_solver *s = (dopus_solver *)ctx;
    const double now = dopus_budget_now(s);
    if (s->anytime.qp_reads > 0 && now - s->anytime.qp_read > s->anytime.qp_read_price) {
        s->anytime.qp_read_price = now - s->anytime.qp_read;
    }
    s->anytime.qp_read = now;
    s->anytime.qp_reads += 1;
    return now;
}

/* After a timed QP solve (time budget): how far its end passed what its last test of the
 * deadline allowed for (the read plus one iteration's price, or the read alone when the test
 * stopped it), kept as the peak of such readings (cost_qp_over). */
static void dopus_qp_over(dopus_solver *s)
{
    double over;
    if (s->anytime.qp_reads == 0) {
        return;
    }
    over = dopus_budget_now(s) - s->anytime.qp_read;
    if (!(s->anytime.qp_read + s->anytime.qp_read_price > s->anytime.qp_deadline)) {
        over -= s->anytime.qp_read_price;
    }
    s->anytime.cost_qp_over = dopus_cost_peak(s, s->anytime.cost_qp_over, over > 0.0 ? over : 0.0);
}

/* The QP's matrix pointers (dopus_qp_in.H, Phi, C, HN, R, Req) point into this struct: the
 * ring slots in place and the terminal blocks. They are set just before each solve and
 * cleared after it, so the struct holds no pointer into itself between calls and a byte
 * copy (memcpy, struct assignment) is a complete, independent solver. max_iter: the solve's
 * iteration limit (the setting qp_max_iter, or a cap of the caller's). */
static int dopus_qp_solve_bound(dopus_solver *s, int warm, int active_set, int max_iter)
{
    dopus_qp_in *in = &s->qp_in;
    dopus_qp_settings settings;
    int qs;
    dopus_qp_settings_default(&settings);
    settings.tol = s->settings.qp_tol;
    settings.max_iter = max_iter;
    if (s->anytime.qp_timed) {
        /* a budget (section 14): the QP reads the budget's clock before each factorisation */
        settings.clock = dopus_qp_clock;
        settings.clock_ctx = (void *)s;
        settings.deadline = s->anytime.qp_deadline;
        settings.iter_price = s->anytime.qp_price;
        s->anytime.qp_reads = 0;
        s->anytime.qp_read_price = s->anytime.qp_price;
    }
    settings.warm_start = warm;
    settings.active_set = warm && active_set ? DOPUS_QP_ACTIVE_SET : 0;
    /* the prepare's lm test factored this QP at this term: its first sweep may start from it */
    settings.prefactored = settings.active_set > 0 && s->qp_prefactored && in->hess_shift == s->qp_pre_lm;
    s->qp_prefactored = 0;
    dopus_qp_bind(s);
    qs = dopus_qp_solve(&s->mem.qp.work, in, &settings, &s->mem.qp.sol, &s->qp_info);
    if (s->anytime.qp_timed && s->settings.budget_unit == DOPUS_BUDGET_TIME) {
        dopus_qp_over(s);
    }
    dopus_qp_unbind(s);
    return qs;
}

/* The QP's matrix pointers into the ring slots and the terminal blocks, and their clearing. */
static void dopus_qp_bind(dopus_solver *s)
{
    dopus_qp_in *in = &s->qp_in;
    int k;
    for (k = 0; k < DOPUS_N; ++k) {
        const dopus_stage_slot *slot = dopus_ring_stage_const(&s->ring, k);
        in->H[k] = slot->Ht;
        in->Phi[k] = slot->Phit;
        in->C[k] = DOPUS_NG > 0 ? slot->Ct : 0;
    }
    in->HN = s->A_N;
    in->R = DOPUS_NR > 0 ? s->R : 0;
    in->Req = DOPUS_NE > 0 ? s->R_eq : 0;
}

static void dopus_qp_unbind(dopus_solver *s)
{
    dopus_qp_in *in = &s->qp_in;
    int k;
    for (k = 0; k < DOPUS_N; ++k) {
        in->H[k] = 0;
        in->Phi[k] = 0;
        in->C[k] = 0;
    }
    in->HN = 0;
    in->R = 0;
    in->Req = 0;
}

/* 1 when the QP status is "solved" and its solution finite. */
static int dopus_qp_ok(const dopus_solver *s, int qs)
{
    return qs == DOPUS_QP_SOLVED && dopus_qp_solution_finite(&s->mem.qp.sol);
}

/* One solve of the prepared QP, warm (from the point in s->mem.qp.sol; with active_set, the
 * active-set start of dopus_qp.h first) or cold; its iterations and factorisations are added
 * to those of the call. Returns the QP status. */
static int dopus_qp_attempt(dopus_solver *s, int warm, int active_set)
{
    int qs;
    qs = dopus_qp_solve_bound(s, warm, active_set, s->settings.qp_max_iter);
    s->qp_iterations += s->qp_info.iterations;
    s->qp_factorizations += s->qp_info.factorizations;
    s->qp_pre_used |= s->qp_info.prefactored;
    return qs;
}

/* 1 when the measurement lies near the state the plan predicted (|dx_0,i| <=
 * DOPUS_QP_ACTIVE_SET_NEAR scale_x,i): the previous solution's active set is a guess for its
 * QP. */
static int dopus_measurement_near(const dopus_solver *s)
{
    int i;
    for (i = 0; i < DOPUS_NX; ++i) {
        if (!(dopus_fabs(s->qp_in.x0[i]) <= DOPUS_QP_ACTIVE_SET_NEAR * s->health.scale_x[i])) {
            return 0;
        }
    }
    return 1;
}

/* With a time budget's deadline (algorithm.md section 14): 1 unless the time left before it
 * fits DOPUS_ANYTIME_IPM_ITER QP iterations (at the price of one) but not the most sweeps of
 * the active-set start (DOPUS_QP_ACTIVE_SET): the interior point alone then. The start's sweeps
 * give the exact KKT point only at the last one: a start the deadline cuts short leaves the
 * warm start, whose residuals fail the feedback (scaled 0.44 on the robot arm), where the
 * interior point's cut iterates are steps after a few iterations. With room for fewer, the
 * start as before (the chain of masses: one sweep, 2.7 M instructions). Without a deadline,
 * and in work units (the QP is cut only before its first factorisation), 1. */
static int dopus_active_set_fits(const dopus_solver *s)
{
    double fit;
    if (!s->anytime.qp_timed || s->settings.budget_unit != DOPUS_BUDGET_TIME ||
        !(s->anytime.qp_price > 0.0)) {
        return 1;
    }
    fit = (s->anytime.qp_deadline - dopus_budget_now(s)) / s->anytime.qp_price;
    return fit >= (double)DOPUS_QP_ACTIVE_SET || fit < (double)DOPUS_ANYTIME_IPM_ITER;
}

/* Step 3: the QP with the current term lm, warm-started when that is on, and the cold retry
 * in the same call when the warm start failed or needed the inertia correction: the QP is
 * then nonconvex on the null space of its equalities and may have several local
 * minimisers, and the warm start may have reached another one than the cold start finds
 * (the one the closed loop has followed so far). Not after a warm start that certified
 * primal infeasibility beyond CERT_SEP and the tolerance (dopus_qp_info.certified): the
 * rows do not depend on the start, and no such retry was solved (algorithm.md section 4).
 * Returns the QP status. */
static int dopus_feedback_qp(dopus_solver *s)
{
    /* the active-set start only for a measurement near the prediction, not after a feedback
     * whose warm start failed, and for a QP whose automatic term lm is within one raise
     * step of convex (dopus_lm_near_convex; its test, if any, last: before the warm point
     * fills the QP's memory, which the test's scratch shares) (algorithm.md section 4,
     * feedback); with a time budget only when its sweeps fit before the deadline
     * (dopus_active_set_fits, section 14) */
    const int active_set = !s->qp_no_active_set && s->lm.on && dopus_measurement_near(s) &&
                           !s->qp_warm_failed && dopus_active_set_fits(s) &&
                           dopus_lm_near_convex(&s->lm, &s->ring, s->A_N, s->mem.ev.lm_work);
    int qs;
    s->qp_in.hess_shift = s->lm.lm;
    s->qp_iterations = 0;
    s->qp_factorizations = 0;
    s->qp_pre_used = 0;
    s->qp_cold_retry = 0;
    s->qp_warm_failed = 0;
    s->anytime.work += DOPUS_WORK_QP;
    if (s->settings.qp_warm_start) {
        dopus_qp_warm_point(s);
    }
    qs = dopus_qp_attempt(s, s->settings.qp_warm_start, active_set);
    if (s->settings.qp_warm_start && qs != DOPUS_QP_INVALID_INPUT && qs != DOPUS_QP_DEADLINE &&
        (!dopus_qp_ok(s, qs) || s->qp_info.inertia_corrections > 0)) {
        s->qp_warm_failed = 1;
        if (!(qs == DOPUS_QP_PRIMAL_INFEASIBLE && s->qp_info.certified)) {
            s->qp_cold_retry = 1;
            qs = dopus_qp_attempt(s, 0, 0);
        }
    }
    return qs;
}

/* 1 when the budget's deadline is set and one more QP solve would pass it at once (work
 * units: its N units; time: its first iteration's price): no retry is started then. */
static int dopus_qp_deadline_near(const dopus_solver *s)
{
    double next;
    if (!s->anytime.qp_timed) {
        return 0;
    }
    next = s->settings.budget_unit == DOPUS_BUDGET_WORK ? (double)DOPUS_WORK_QP : s->anytime.qp_price;
    return dopus_budget_now(s) + next > s->anytime.qp_deadline;
}

/* Step 4, the automatic term (algorithm.md section 10): a QP still not solved is solved
 * again (cold) with lm raised, at most DOPUS_LM_RETRIES times (with a budget, while one more
 * solve does not pass its deadline at once). Returns the QP status; the
 * number of retries in *retries. */
static int dopus_feedback_lm_retries(dopus_solver *s, int qs, int *retries)
{
    *retries = 0;
    while (*retries < DOPUS_LM_RETRIES && dopus_lm_can_raise(&s->lm) && !dopus_qp_ok(s, qs) &&
           qs != DOPUS_QP_INVALID_INPUT && qs != DOPUS_QP_DEADLINE && !dopus_qp_deadline_near(s)) {
        dopus_lm_raise(&s->lm);
        s->anytime.work += DOPUS_WORK_QP;
        s->qp_in.hess_shift = s->lm.lm;
        qs = dopus_qp_attempt(s, 0, 0);
        *retries += 1;
    }
    return qs;
}

/* Step 5: the outcome of the QP: DOPUS_ERR_QP when it is not solved, DOPUS_ERR_DIVERGED when
 * its step leaves the box of the divergence test (algorithm.md section 9), else DOPUS_OK. */
static int dopus_feedback_check_step(const dopus_solver *s, int qs)
{
    const dopus_qp_sol *sol = &s->mem.qp.sol;
    if (!dopus_qp_ok(s, qs)) {
        return DOPUS_ERR_QP;
    }
    if (!dopus_iterate_box_ok(s, &sol->x[0][0], DOPUS_NX, &sol->u[0][0], DOPUS_QP_NU1)) {
        return DOPUS_ERR_DIVERGED;
    }
    return DOPUS_OK;
}

/* Step 5 of a feedback: as dopus_feedback_check_step, but a QP cut by the budget's deadline
 * with a finite best point is usable (algorithm.md section 14) when it was cut before its
 * first iteration (the warm start: the shifted plan's control) or its scaled residuals are
 * below DOPUS_ANYTIME_CUT_MERIT: that point is the step (DOPUS_FLAG_QP_CUT), not a failure
 * that would start a recovery. A QP cut far from its solution fails the feedback. */
static int dopus_feedback_check_cut(dopus_solver *s, int qs)
{
    const dopus_qp_info *q = &s->qp_info;
    const dopus_real merit = dopus_fmax(dopus_fmax(q->res_stat_scaled, q->res_eq_scaled),
                                        dopus_fmax(q->res_ineq_scaled, q->res_comp_scaled));
    if (qs == DOPUS_QP_DEADLINE && dopus_qp_solution_finite(&s->mem.qp.sol) &&
        (q->iterations == 0 || merit <= DOPUS_ANYTIME_CUT_MERIT)) {
        s->health.flags |= DOPUS_FLAG_QP_CUT;
        return dopus_feedback_check_step(s, DOPUS_QP_SOLVED);
    }
    return dopus_feedback_check_step(s, qs);
}

/* Step 6: the step of each stage kept in its slot for the secant criterion:
 * domega_k = (dw_k, lam_QP_{k+1} - lam_{k+1}, mu_g_QP_k - mu_g_k, mu_b_QP_k - mu_b_k). */
static void dopus_store_domega(dopus_solver *s)
{
    const dopus_qp_sol *sol = &s->mem.qp.sol;
    int k, i;
    for (k = 0; k < DOPUS_N; ++k) {
        dopus_stage_slot *slot = dopus_ring_stage(&s->ring, k);
        for (i = 0; i < DOPUS_NX; ++i) {
            slot->dw[i] = sol->x[k][i];
            slot->dlam[i] = sol->lam[k + 1][i] - s->lam[k + 1][i];
        }
        for (i = 0; i < DOPUS_NU; ++i) {
            slot->dw[DOPUS_NX + i] = sol->u[k][i];
        }
        for (i = 0; i < DOPUS_NG; ++i) {
            slot->dmu_g[i] = sol->mu_g[k][i] - s->mu_g[k][i];
        }
        for (i = 0; i < DOPUS_NW; ++i) {
            slot->dmu_b[i] = sol->mu_b[k][i] - s->mu_b[k][i];
        }
    }
}

/* Step 7, the full step (paper eq. 4): w += dw, multipliers replaced by the QP's. */
static void dopus_take_step(dopus_solver *s)
{
    const dopus_qp_sol *sol = &s->mem.qp.sol;
    int k, i;
    for (k = 0; k <= DOPUS_N; ++k) {
        for (i = 0; i < DOPUS_NX; ++i) {
            s->x[k][i] += sol->x[k][i];
            s->lam[k][i] = sol->lam[k][i];
        }
    }
    for (k = 0; k < DOPUS_N; ++k) {
        for (i = 0; i < DOPUS_NU; ++i) {
            s->u[k][i] += sol->u[k][i];
        }
        for (i = 0; i < DOPUS_NG; ++i) {
            s->mu_g[k][i] = sol->mu_g[k][i];
        }
        for (i = 0; i < DOPUS_NW; ++i) {
            s->mu_b[k][i] = sol->mu_b[k][i];
        }
    }
    for (i = 0; i < DOPUS_NX; ++i) {
        s->mu_bN[i] = sol->mu_bN[i];
    }
    for (i = 0; i < DOPUS_NR; ++i) {
        s->mu_r[i] = sol->mu_r[i];
    }
    for (i = 0; i < DOPUS_NE; ++i) {
        s->nu[i] = sol->nu[i];
    }
    s->qp_ready = 0;
}

/* Step 8: a good plan, the fallback of the next failures; the automatic term lowered unless
 * this QP needed a raise (lowered = 1); u0 clipped to the control bounds. */
static void dopus_keep_plan(dopus_solver *s, dopus_real *u0, int lowered)
{
    if (lowered) {
        dopus_lm_feedback(&s->lm, 1);
    }
    if (dopus_health_keep_plan(&s->health, &s->u[0][0], u0)) {
        s->health.flags |= DOPUS_FLAG_U0_CLIPPED;
    }
}

static int dopus_feedback_recover(dopus_solver *s, int *qs, int *retries);

/* 1 when the model is finite at the state xs with the next control of the last good plan (one
 * stage evaluation, 1 work unit of the budget; nothing tests before it that it fits: without
 * it the feedback could not tell a measurement from no measurement, algorithm.md section 14).
 * A finite measurement at which it is not (an outlier of 1e6 rad/s, say) cannot start a
 * re-initialisation: it is no measurement (algorithm.md section 9). */
static int dopus_model_finite_at(dopus_solver *s, const dopus_real *xs)
{
    dopus_real l = DOPUS_R(0.0), u[DOPUS_NU], xn[DOPUS_NX];
    dopus_clip_u(dopus_health_plan_control(&s->health, 0), u);
    return dopus_eval_node(s, 0, xs, u, xn, &l) && dopus_lai_vec_finite(1, &l);
}

/* Feedback once admitted (steps 2 to 8). */
/* The bounded latency of a time budget (algorithm.md section 14): the next QP solves read
 * the clock before each factorisation and stop (DOPUS_QP_DEADLINE, their best point) when
 * one more iteration would pass the instant's budget less `reserve`; `per_iter` prices the
 * first iteration. A cut QP is not retried: the feedback takes its best point as the step,
 * an extra iteration or a predicted step changes nothing. */
static void dopus_budget_deadline(dopus_solver *s, double reserve, double per_iter)
{
    s->anytime.qp_timed = dopus_budget_on(s);
    s->anytime.qp_deadline = s->anytime.instant_start + s->settings.budget - reserve;
    s->anytime.qp_price = per_iter > 0.0 ? per_iter : 0.0;
}

static int dopus_feedback_run(dopus_solver *s, const dopus_real *xhat0, dopus_real *u0)
{
    dopus_real xhat_prev[DOPUS_NX];
    double b0, b1;
    int rc, qs, retries, recovered = 0;

    dopus_copy(xhat_prev, s->xhat0, DOPUS_NX);
    dopus_feedback_measure(s, xhat0);
    /* the first price of a QP iteration when the budget was set after init */
    dopus_price_qp(s);
    /* the deadline leaves the step and the least a prepare costs free */
    if (s->anytime.starved) {
        /* the last instant proved the prices too high (dopus_starved_check) */
        const double rest = dopus_after_qp(s, dopus_prepare_floor(s));
        dopus_budget_deadline(s, rest < s->anytime.rest_last ? rest : s->anytime.rest_last, 0.0);
    } else {
        dopus_budget_deadline(s, dopus_after_qp(s, dopus_prepare_floor(s)), s->anytime.cost_qp_iter);
    }
    b0 = dopus_budget_now(s);
    qs = dopus_feedback_qp(s);
    qs = dopus_feedback_lm_retries(s, qs, &retries);
    b1 = dopus_budget_now(s);
    s->anytime.cost_qp = dopus_cost(s, s->anytime.cost_qp, b1 - b0);
    s->anytime.fb_qp_end = b1 - s->anytime.instant_start;
    s->anytime.fb_qp_cut = qs == DOPUS_QP_DEADLINE && s->settings.budget_unit == DOPUS_BUDGET_TIME;
    if (s->qp_iterations > 0 && s->settings.budget_unit == DOPUS_BUDGET_TIME) {
        s->anytime.cost_qp_iter =
            dopus_cost(s, s->anytime.cost_qp_iter, s->anytime.cost_qp / (double)s->qp_iterations);
    }
    if (dopus_budget_on(s)) {
        dopus_cost_qp_step(s, dopus_budget_now(s) - b0, s->qp_iterations);
    }
    s->qp_status = qs;
    b0 = dopus_budget_now(s);
    rc = dopus_feedback_check_cut(s, qs);
    /* the recovery within the feedback (algorithm.md section 9); not for a QP stopped by its
     * iteration limit or the budget's deadline (not signs of a wrong iterate) or refused as
     * invalid */
    if (rc != DOPUS_OK && s->settings.recovery && s->settings.mode == DOPUS_MODE_RECEDING &&
        qs != DOPUS_QP_MAX_ITER && qs != DOPUS_QP_INVALID_INPUT && qs != DOPUS_QP_DEADLINE) {
        if (!dopus_model_finite_at(s, xhat0)) {
            /* no measurement: handled as a non-finite one (the iterate and its QP stay; the
             * prepare takes the predicted step) */
            dopus_copy(s->xhat0, xhat_prev, DOPUS_NX);
            s->health.xhat_fresh = 0;
            s->health.flags |= DOPUS_FLAG_MEASUREMENT_UNUSABLE;
            rc = DOPUS_ERR_NONFINITE_VALUE;
        } else {
            recovered = 1;
            rc = dopus_feedback_recover(s, &qs, &retries);
            if (rc == DOPUS_OK) {
                s->qp_status = qs;
                rc = dopus_feedback_check_cut(s, qs);
            }
        }
    }
    if (rc != DOPUS_OK) {
        return dopus_feedback_failed(s, u0, rc);
    }
    dopus_store_domega(s);
    dopus_take_step(s);
    dopus_keep_plan(s, u0, retries == 0);
    if (dopus_budget_on(s) && !recovered) {
        /* the step after the QP (not after a recovery's) */
        s->anytime.cost_fb_tail = dopus_cost_peak(s, s->anytime.cost_fb_tail, dopus_budget_now(s) - b0);
    }
    return dopus_ret(s, DOPUS_OK);
}

/* The memory states of rate constraints (algorithm.md section 4, "Rate constraints"): in
 * receding mode the measured state with their entries set to the last applied control (a
 * fixed-xhat0 study reads them as given: nothing is applied there). */
static const dopus_real *dopus_with_memory(const dopus_solver *s, const dopus_real *xhat0, dopus_real *xm)
{
    int i;
    if (DOPUS_NMEM == 0 || xhat0 == 0 || !s->initialized || s->settings.mode != DOPUS_MODE_RECEDING) {
        return xhat0;
    }
    dopus_copy(xm, xhat0, DOPUS_NX);
    for (i = 0; i < DOPUS_NMEM; ++i) {
        xm[dopus_memory_state[i]] = s->u_applied[dopus_memory_control[i]];
    }
    return xm;
}

static int dopus_feedback_call(dopus_solver *s, const dopus_real *xhat0, dopus_real *u0);

int dopus_feedback(dopus_solver *s, const dopus_real *xhat0, dopus_real *u0)
{
    dopus_real xm[DOPUS_NX], xs[DOPUS_NX];
    int rc;
    if (!s->set_up) {
        return DOPUS_ERR_NOT_INITIALIZED;
    }
    rc = dopus_feedback_call(s, dopus_with_memory(s, dopus_scaled_in(xhat0, dopus_scale_x, DOPUS_NX, xs), xm),
                             u0);
    if (s->initialized) {
        /* the control returned is the one applied: the next stage-0 rate row is against it */
        dopus_copy(s->u_applied, s->health.u0_out, DOPUS_NU);
    }
    if (u0) { /* every feedback of a set-up solver wrote u0 = u0_out (the fallback on failure) */
        dopus_scaled_out(u0, s->health.u0_out, dopus_scale_u, DOPUS_NU, DOPUS_NU);
    }
    return rc;
}

static int dopus_feedback_call(dopus_solver *s, const dopus_real *xhat0, dopus_real *u0)
{
    double start;
    int rc;

    /* the whole call is the phase "feedback" (a recovery within it included) */
    dopus_timer_begin(&s->timer, 1u << DOPUS_PHASE_FEEDBACK, DOPUS_PHASE_FEEDBACK);
    s->timer.locked = 1;
    start = s->timer.mark;
    s->health.flags = 0;
    s->anytime.instant_start = dopus_budget_now(s);
    s->anytime.extra_iterations = 0;
    s->anytime.instant_stages = 0;
    rc = dopus_feedback_admit(s, xhat0, u0);
    if (rc == DOPUS_OK) {
        rc = dopus_feedback_run(s, xhat0, u0);
    }
    s->anytime.qp_timed = 0;
    s->anytime.used = dopus_budget_now(s) - s->anytime.instant_start;
    s->timer.locked = 0;
    dopus_timer_end(&s->timer, 0, start);
    return rc;
}

/* ---- prepare ------------------------------------------------------------------------ */

/* Step 1 (receding mode): shift the iterate by one interval and advance ring_head.
 * x_N is set from phi_{N-1} in step 3. */
static void dopus_shift(dopus_solver *s)
{
    int k, i;
    for (k = 0; k < DOPUS_N; ++k) {
        for (i = 0; i < DOPUS_NX; ++i) {
            s->x[k][i] = s->x[k + 1][i];
            s->lam[k][i] = s->lam[k + 1][i];
        }
    }
    for (k = 0; k < DOPUS_N - 1; ++k) {
        for (i = 0; i < DOPUS_NU; ++i) {
            s->u[k][i] = s->u[k + 1][i];
        }
        for (i = 0; i < DOPUS_NG; ++i) {
            s->mu_g[k][i] = s->mu_g[k + 1][i];
        }
        for (i = 0; i < DOPUS_NW; ++i) {
            s->mu_b[k][i] = s->mu_b[k + 1][i];
        }
    }
    /* the last stage: the x part of mu_b from mu_bN, the u part kept */
    for (i = 0; i < DOPUS_NX; ++i) {
        s->mu_b[DOPUS_N - 1][i] = s->mu_bN[i];
    }
    dopus_clear_x0_multiplier(s);
    dopus_ring_advance(&s->ring);
}

/* A stage 1..N-2 whose stored linearisation makes a hard path row unsatisfiable for the
 * QP: its row of Ct is zero and the value g_new of step 2 lies outside that side's bound
 * (0 dw >= lg - g_new > 0). Stage 0 is left out (the QP ignores its rows without u). */
static int dopus_stale_stage(const dopus_solver *s, int k)
{
    const dopus_stage_slot *slot = dopus_ring_stage_const(&s->ring, k);
    const dopus_real *g = s->mem.ev.Fn_g[k];
    int i, j;
    if (k == 0) {
        return 0;
    }
    for (j = 0; j < DOPUS_NG; ++j) {
        int hard_lo = 1, hard_up = 1, zero = 1;
#if DOPUS_NSOFT > 0
        hard_lo = !(dopus_soft_g[0][j] > DOPUS_R(0.0) || dopus_soft_g[2][j] > DOPUS_R(0.0));
        hard_up = !(dopus_soft_g[1][j] > DOPUS_R(0.0) || dopus_soft_g[3][j] > DOPUS_R(0.0));
#endif
        for (i = 0; i < DOPUS_NW && zero; ++i) {
            zero = slot->Ct[j + i * DOPUS_DIM(DOPUS_NG)] == DOPUS_R(0.0);
        }
        if (zero && ((hard_lo && g[j] < dopus_lg_k[k][j]) || (hard_up && g[j] > dopus_ug_k[k][j]))) {
            return 1;
        }
    }
    return 0;
}

/* |domega_k| of stage k's slot (the denominator of rho_k). */
static dopus_real dopus_step_norm(const dopus_solver *s, int k)
{
    const dopus_stage_slot *slot = dopus_ring_stage_const(&s->ring, k);
    dopus_real d2 = DOPUS_R(0.0);
    int i;
    for (i = 0; i < DOPUS_NW; ++i) {
        d2 += slot->dw[i] * slot->dw[i] + slot->dmu_b[i] * slot->dmu_b[i];
    }
    for (i = 0; i < DOPUS_NX; ++i) {
        d2 += slot->dlam[i] * slot->dlam[i];
    }
    for (i = 0; i < DOPUS_NG; ++i) {
        d2 += slot->dmu_g[i] * slot->dmu_g[i];
    }
    return dopus_sqrt(d2);
}

/* The number of stages among 0..N-2 to re-linearise (before the budget): N-1 after a
 * recovery, the fixed M, or adaptive M (algorithm.md section 14): the stages whose secant
 * residual rho_k |domega_k| exceeds eta times the KKT proxy of the point before the step,
 * between M_min and M_max. */
static int dopus_M_now(const dopus_solver *s)
{
    const dopus_settings *st = &s->settings;
    dopus_real thr = st->M_eta * s->health.kkt_proxy;
    int k, n = 0;
    if (s->health.recovering > 0) {
        return DOPUS_N - 1; /* after a recovery: every block fresh until it has settled */
    }
    if (!st->M_adaptive) {
        return st->M < 0 ? 0 : (st->M > DOPUS_N - 1 ? DOPUS_N - 1 : st->M);
    }
    for (k = 0; k < DOPUS_N - 1; ++k) {
        if (s->rho[k] * dopus_step_norm(s, k) > thr) {
            n += 1;
        }
    }
    return n < st->M_min ? st->M_min : (n > st->M_max ? st->M_max : n);
}

/* The stage among 0..N-2 not selected yet with the largest rho_k, ties to the lower index. */
static int dopus_next_worst(const dopus_solver *s)
{
    int k, best = -1;
    for (k = 0; k < DOPUS_N - 1; ++k) {
        if (!s->selected[k] && (best < 0 || s->rho[k] > s->rho[best])) {
            best = k;
        }
    }
    return best;
}

/* Step 4: re-linearise the stale stages (dopus_stale_stage) not re-linearised in step 2 (the
 * n_fh of the budgeted full RTI), then among the other stages of 0..N-2 those with the largest
 * rho_k: M of them (dopus_M_now; the n_fh count among them), then, with a budget,
 * further stages in rho order while one more iteration still fits after them
 * (algorithm.md section 14); each only while the budget allows. The cost of the stages
 * beyond M goes to *ext_cost. */
static int dopus_relinearise(dopus_solver *s, int n_fh, double *ext_cost, double *stage_time)
{
    int M = dopus_M_now(s), m, k, n = n_fh, rc = DOPUS_OK, extend;
    double b0, reserve;
    *stage_time = 0.0;
    /* the n_fh stages step 2 re-linearised with their gradients (the budgeted full RTI, each
     * selected there) count among the M */
    for (k = 0; k < DOPUS_N && n_fh == 0; ++k) {
        s->selected[k] = 0;
    }
    /* the stale stages first, whatever the budget: without them the QP is infeasible */
    for (k = 0; k < DOPUS_N - 1 && DOPUS_NG > 0; ++k) {
        if (!s->selected[k] && dopus_stale_stage(s, k)) {
            b0 = dopus_budget_now(s);
            rc = dopus_stage_H(s, k);
            *stage_time += dopus_budget_now(s) - b0;
            if (rc != DOPUS_OK) {
                s->anytime.instant_stages += n;
                return rc;
            }
            s->selected[k] = 1;
            n += 1;
        }
    }
    extend = dopus_budget_on(s);
    *ext_cost = 0.0;
    /* the stages beyond M keep room for one more iteration after this one */
    reserve = s->anytime.cost_qp + s->anytime.cost_prepare;
    for (m = n_fh; m < DOPUS_N - 1; ++m) {
        /* the stages of M leave room for the rest of this prepare iteration, those beyond M
         * for one more iteration */
        if ((m >= M && !extend) ||
            !dopus_budget_fits(s, s->anytime.cost_stage + dopus_rest_cost(s, DOPUS_N - 2 - n) +
                                      (m >= M ? reserve : 0.0))) {
            break;
        }
        k = dopus_next_worst(s);
        if (k < 0) {
            break;
        }
        b0 = dopus_budget_now(s);
        rc = dopus_stage_H(s, k);
        if (rc != DOPUS_OK) {
            break;
        }
        s->selected[k] = 1;
        n += 1;
        if (dopus_budget_on(s)) {
            double reading = dopus_budget_now(s) - b0;
            *stage_time += reading;
            s->anytime.cost_stage = dopus_cost(s, s->anytime.cost_stage, reading);
            if (m >= M) {
                /* what the stage took (not the estimate) less the step-5 refresh it saved:
                 * the rest is the prepare's own cost */
                *ext_cost += reading - (s->settings.cost_hessian ? s->anytime.cost_al : 0.0);
            }
        }
    }
    s->anytime.instant_stages += n;
    return rc;
}

/* 1 when the setting re-linearises every stage of 0..N-2 whatever their rho_k: M = N-1
 * (fixed, or after a recovery), as dopus_M_now decides. */
static int dopus_setting_full(const dopus_solver *s)
{
    const dopus_settings *st = &s->settings;
    return s->health.recovering > 0 || (!st->M_adaptive && st->M >= DOPUS_N - 1);
}

/* 1 when step 4 re-linearises every stage of 0..N-2 whatever their rho_k: no budget and the
 * full RTI (dopus_setting_full), as dopus_relinearise decides. */
static int dopus_every_stage_fresh(const dopus_solver *s)
{
    return !dopus_budget_on(s) && dopus_setting_full(s);
}

/* Step 4 when step 2 re-linearised every stage of 0..N-2 (dopus_every_stage_fresh). */
static int dopus_all_selected(dopus_solver *s)
{
    int k;
    for (k = 0; k < DOPUS_N - 1; ++k) {
        s->selected[k] = 1;
    }
    s->anytime.instant_stages += DOPUS_N - 1;
    return DOPUS_OK;
}

/* Forward simulation from x[0] with the controls of the last good plan from its current age
 * on (use_plan) or the OCP file's guess, clipped to the bounds, into the iterate. Returns 1
 * when every node is finite and inside the box. */
static int dopus_simulate_plan(dopus_solver *s, int use_plan)
{
    dopus_real l = DOPUS_R(0.0);
    int k;
    for (k = 0; k < DOPUS_N; ++k) {
        dopus_clip_u(use_plan ? dopus_health_plan_control(&s->health, k) : dopus_guess_u[k], s->u[k]);
        if (dopus_eval_stage_eval(s->x[k], s->u[k], s->p[k], s->x[k + 1], &l, s->mem.ev.tmp_g,
                                  &s->mem.ev.fun_work) != 0 ||
            !dopus_lai_vec_finite(DOPUS_NX, s->x[k + 1])) {
            return 0;
        }
    }
    return dopus_iterate_box_ok(s, 0, 0, 0, 0);
}

/* The OCP file's guess states from node `first` on and its controls (clipped) into the iterate. */
static void dopus_guess_primal(dopus_solver *s, int first)
{
    int k;
    for (k = first; k <= DOPUS_N; ++k) {
        dopus_copy(s->x[k], dopus_guess_x[k], DOPUS_NX);
    }
    for (k = 0; k < DOPUS_N; ++k) {
        dopus_clip_u(dopus_guess_u[k], s->u[k]);
    }
}

/* The bookkeeping of a re-initialisation that succeeded: the KKT proxy, the recovery phase. */
static void dopus_reinit_done(dopus_solver *s)
{
    s->health.kkt_proxy = dopus_kkt_proxy_eval(s);
    s->health.kkt_proxy_ref = s->health.kkt_proxy;
    s->health.n_failed = 0;
    s->health.recover_pending = 0;
    s->health.n_recoveries += 1;
    s->health.recovering = DOPUS_RECOVERY_FULL_RTI;
    s->health.flags |= DOPUS_FLAG_RECOVERED;
}

/* The controls of a re-initialisation's forward simulation (anytime.reinit_sim 1: the last
 * good plan's, 2: the guess's; clipped) into the iterate. */
static void dopus_reinit_controls(dopus_solver *s)
{
    int k;
    for (k = 0; k < DOPUS_N; ++k) {
        dopus_clip_u(s->anytime.reinit_sim == 1 ? dopus_health_plan_control(&s->health, k) : dopus_guess_u[k],
                     s->u[k]);
    }
}

/* A re-initialisation with a budget (algorithm.md section 14), from the iterate in place: the
 * gradient and blocks of each stage in stage order while one more, the terminal node and
 * `reserve` still fit, then the terminal node and the QP; what does not fit continues in the
 * next prepares (anytime.reinit_next, the next stage; -1 when none is under way), whose
 * feedbacks return the fallback control (no QP prepared). Gauss-Newton blocks when the problem
 * has them; the terminal node's price (the step-3 reading less a stage's) and the assembly
 * with the lm test's (steps 6 and 7, cost_tail) stay free after each stage: measured on the
 * emulated Cortex-M7, a walk that ended in a feedback passed the budget by 63 k instructions
 * without the latter. The forward simulation is done by the stage evaluations (anytime.reinit_sim):
 * x_{k+1} is the phi of stage k's gradient, so it is priced as they are; a stage whose
 * evaluation fails or leaves the box starts the walk again from stage 0 with the guess
 * controls, then from the guess (as dopus_reinit's simulations fall back). A failed
 * evaluation without a simulation returns its status (the caller falls back on the guess). */
static int dopus_reinit_walk(dopus_solver *s, double reserve)
{
    const double term = s->anytime.cost_head - s->anytime.cost_grad - s->anytime.cost_stage;
    const int hessian = s->settings.hessian;
    int k, rc = DOPUS_OK;
    s->settings.hessian = DOPUS_HAS_GN ? DOPUS_HESSIAN_GAUSS_NEWTON : hessian;
    while ((k = s->anytime.reinit_next) < DOPUS_N &&
           dopus_budget_fits(s, s->anytime.cost_grad + s->anytime.cost_stage + term + s->anytime.cost_tail +
                                    reserve)) {
        rc = dopus_stage_F(s, k);
        if (s->anytime.reinit_sim &&
            (rc != DOPUS_OK || (k == 0 && !dopus_box_node_ok(&s->health, s->xhat0, s->x[0], 0, 0, 0)) ||
             !dopus_box_node_ok(&s->health, s->xhat0, s->mem.ev.tmp_phi, 0, s->u[k], 0))) {
            /* the simulation failed: again from stage 0 with the guess controls, else the guess */
            s->anytime.reinit_sim = s->anytime.reinit_sim == 1 ? 2 : 0;
            if (s->anytime.reinit_sim) {
                dopus_reinit_controls(s);
            } else {
                dopus_guess_primal(s, 1);
            }
            s->anytime.reinit_next = 0;
            rc = DOPUS_OK;
            continue;
        }
        if (rc != DOPUS_OK) {
            break;
        }
        if (s->anytime.reinit_sim) {
            dopus_copy(s->x[k + 1], s->mem.ev.tmp_phi, DOPUS_NX);
        }
        dopus_ring_store_F(dopus_ring_stage(&s->ring, k), s->mem.ev.tmp_F, s->mem.ev.tmp_phi,
                           s->mem.ev.tmp_g);
        rc = dopus_stage_H(s, k);
        if (rc != DOPUS_OK) {
            break;
        }
        s->anytime.reinit_next = k + 1;
    }
    if (rc == DOPUS_OK && s->anytime.reinit_next == DOPUS_N) {
        rc = dopus_term_F(s);
        if (rc == DOPUS_OK) {
            rc = dopus_term_H(s);
        }
        if (rc == DOPUS_OK) {
            s->al_resync = 0; /* every block fresh */
            dopus_assemble(s);
            s->qp_ready = 1;
            dopus_lm_started(s);
            s->anytime.reinit_next = -1;
            dopus_reinit_done(s);
        }
    }
    s->settings.hessian = hessian;
    return rc;
}

/* The linearisation of a re-initialisation: Gauss-Newton blocks when the problem has them
 * (convex in the cost, whatever the multipliers); the next prepares use the setting. With a
 * budget, spread over the prepares (dopus_reinit_walk; `reserve`: what it leaves free). */
static int dopus_reinit_finish(dopus_solver *s, double reserve)
{
    int rc, hessian = s->settings.hessian;
    if (dopus_budget_on(s)) {
        dopus_fresh_start(s);
        s->qp_ready = 0;
        s->health.n_failed = 0;
        s->health.recover_pending = 0;
        s->anytime.reinit_next = 0;
        return dopus_reinit_walk(s, reserve);
    }
    s->settings.hessian = DOPUS_HAS_GN ? DOPUS_HESSIAN_GAUSS_NEWTON : hessian;
    rc = dopus_init_finish(s);
    s->settings.hessian = hessian;
    if (rc == DOPUS_OK) {
        dopus_reinit_done(s);
    }
    return rc;
}

/* The last resort of a re-initialisation whose model evaluation failed (the model is not
 * finite at the measured or predicted state, e.g. an outlier of 1e6 rad/s): the OCP file's
 * guess whole, x_0 included, with zero multipliers; the next feedback's QP steps from it to
 * the measurement. Flag DOPUS_FLAG_REINIT_GUESS. */
static int dopus_reinit_at_guess(dopus_solver *s, double reserve)
{
    dopus_guess_primal(s, 0);
    s->anytime.reinit_sim = 0;
    dopus_zero((DOPUS_N + 1) * DOPUS_NX, &s->lam[0][0]);
    dopus_zero(DOPUS_N * DOPUS_NW, &s->mu_b[0][0]);
    dopus_zero(DOPUS_NX, s->mu_bN);
    dopus_zero(DOPUS_N * DOPUS_DIM(DOPUS_NG), &s->mu_g[0][0]);
    dopus_zero(DOPUS_DIM(DOPUS_NR), s->mu_r);
    dopus_zero(DOPUS_DIM(DOPUS_NE), s->nu);
    s->health.flags |= DOPUS_FLAG_REINIT_GUESS;
    return dopus_reinit_finish(s, reserve);
}

/* The re-initialisation of the recovery from x_0 in place: a forward simulation with the last
 * good plan (else with the OCP file's guess controls; else the guess itself), the multipliers
 * of the iterate, every block recomputed (Gauss-Newton when the problem has it); when the
 * model fails there, the OCP file's guess whole (dopus_reinit_at_guess). With a budget the
 * evaluations leave `reserve` free and may continue in the next prepares (dopus_reinit_walk). */
static int dopus_reinit(dopus_solver *s, double reserve)
{
    int rc;
    if (dopus_budget_on(s)) {
        /* the forward simulation in the stage evaluations of dopus_reinit_walk, priced as they
         * are (algorithm.md section 14) */
        s->anytime.reinit_sim = 1;
        dopus_reinit_controls(s);
    } else if (!dopus_simulate_plan(s, 1) && !dopus_simulate_plan(s, 0)) {
        dopus_guess_primal(s, 1);
    }
    rc = dopus_reinit_finish(s, reserve);
    if (rc != DOPUS_OK) {
        rc = dopus_reinit_at_guess(s, reserve);
    }
    if (rc != DOPUS_OK) {
        s->qp_ready = 0;
        s->anytime.reinit_next = -1;
    }
    return rc;
}

/* x_{k+1} = phi_k(x_k, u_k) (1 work unit, dopus_eval_node), kept only when the evaluation
 * succeeds and is finite. */
static void dopus_simulate_node(dopus_solver *s, int k)
{
    dopus_real l = DOPUS_R(0.0), xn[DOPUS_NX];
    if (dopus_eval_node(s, k, s->x[k], s->u[k], xn, &l)) {
        dopus_copy(s->x[k + 1], xn, DOPUS_NX);
    }
}

/* A prepare while a re-initialisation is under way (a budget): the shift of the instant (the
 * evaluated stages move with the ring, the new last node is simulated from the one before it),
 * then the evaluations that fit (dopus_reinit_walk); a failed one falls back on the guess. */
static int dopus_reinit_continue(dopus_solver *s)
{
    int rc;
    if (s->settings.mode == DOPUS_MODE_RECEDING && !s->shifted) {
        /* the node that becomes x_0: simulated by the walk, or (no stage evaluated yet) now,
         * one stage evaluation of the budget (1 work unit; in time the walk's tests read it) */
        if (s->anytime.reinit_sim && s->anytime.reinit_next == 0) {
            dopus_simulate_node(s, 0);
        }
        dopus_shift(s);
        s->shifted = 1;
        if (s->anytime.reinit_next > 0) {
            s->anytime.reinit_next -= 1;
        }
        /* the new last node: simulated by the walk, or (no simulation: after the OCP file's
         * guess) from the one before it, one stage evaluation of the budget (1 work unit;
         * nothing tests before it that it fits: without it the guess's last node would not
         * move with the ring; the walk's tests after it read it, algorithm.md section 14) */
        if (!s->anytime.reinit_sim) {
            dopus_simulate_node(s, DOPUS_N - 1);
        }
    }
    rc = dopus_reinit_walk(s, s->anytime.cost_end);
    if (rc != DOPUS_OK) {
        rc = dopus_reinit_at_guess(s, s->anytime.cost_end);
    }
    if (rc != DOPUS_OK) {
        s->qp_ready = 0;
        s->anytime.reinit_next = -1;
    }
    return rc;
}

/* The automatic recovery (algorithm.md section 9): re-initialise from a forward simulation of
 * the predicted state phi(xhat0, u0) (dopus_reinit). */
static int dopus_recover(dopus_solver *s, int shifted)
{
    dopus_real l = DOPUS_R(0.0);
    int i;
    s->qp_prefactored = 0;
    /* x_0: the state predicted for this instant from the last measurement and control (one
     * stage evaluation, 1 work unit of the budget; nothing tests before it that it fits: x_0 =
     * xhat0 instead would change the re-initialisation; the walk's tests after it read it,
     * algorithm.md section 14); when the last feedback had no usable measurement, the
     * (shifted) iterate's x_0 */
    if (!s->health.xhat_fresh) {
        if (!shifted) {
            dopus_copy(s->x[0], s->x[1], DOPUS_NX);
        }
    } else if (!dopus_eval_node(s, 0, s->xhat0, s->health.u0_out, s->x[0], &l)) {
        dopus_copy(s->x[0], s->xhat0, DOPUS_NX);
    }
    for (i = 0; i < DOPUS_NX; ++i) {
        if (!(dopus_fabs(s->x[0][i]) <=
              DOPUS_DIVERGENCE_BOX * s->health.scale_x[i] + dopus_fabs(s->xhat0[i]))) {
            dopus_copy(s->x[0], s->xhat0, DOPUS_NX);
            break;
        }
    }
    return dopus_reinit(s, s->anytime.cost_end);
}

/* The recovery within a feedback (algorithm.md section 9): the QP of a finite measurement
 * failed (not by its iteration limit) or diverged; re-initialise from the measured state (x_0 = xhat0) and
 * solve the QP of the re-initialised iterate (cold, with the lm retries). Returns DOPUS_OK
 * with the QP status in *qs, or the status of a re-initialisation that could not start from
 * the measurement (the model failed there: DOPUS_ERR_NONFINITE_VALUE or DOPUS_ERR_FUNCTION;
 * the iterate is then the OCP file's guess, prepared, when the model is finite there). */
static int dopus_feedback_recover(dopus_solver *s, int *qs, int *retries)
{
    int i, rc, n_failed = s->health.n_failed;
    dopus_copy(s->x[0], s->xhat0, DOPUS_NX);
    /* with a budget the QP after it and the least prepare stay free */
    rc = dopus_reinit(s, s->anytime.cost_qp + dopus_after_qp(s, dopus_prepare_floor(s)));
    s->health.n_failed = n_failed; /* still the count of consecutive failed feedbacks */
    /* the measurement's instant: its prepare (with the shift) is still due */
    s->prepare_due = 1;
    s->shifted = 0;
    if (rc == DOPUS_OK && (s->health.flags & DOPUS_FLAG_REINIT_GUESS)) {
        /* the model failed at the measured state: no QP from it */
        rc = DOPUS_ERR_NONFINITE_VALUE;
    }
    if (rc == DOPUS_OK && s->anytime.reinit_next >= 0) {
        /* the evaluations continue in the prepare (a budget): no QP yet */
        rc = DOPUS_ERR_NOT_PREPARED;
    }
    if (rc != DOPUS_OK) {
        return rc;
    }
    for (i = 0; i < DOPUS_NX; ++i) {
        s->qp_in.x0[i] = DOPUS_R(0.0);
    }
    s->qp_in.hess_shift = s->lm.lm;
    s->anytime.work += DOPUS_WORK_QP;
    *qs = dopus_qp_attempt(s, 0, 0);
    *qs = dopus_feedback_lm_retries(s, *qs, retries);
    return DOPUS_OK;
}

/* The predicted step (algorithm.md section 9): after a failed feedback whose QP is still the
 * prepared one, the QP is solved for the state the iterate predicts for this instant
 * (dx_0 = 0; the measurement, absent or unusable, is left out) and its step taken; its
 * controls become the plan the next fallbacks read. A failure of this QP changes nothing. */
static void dopus_predicted_step(dopus_solver *s)
{
    int i, qs;
    for (i = 0; i < DOPUS_NX; ++i) {
        s->qp_in.x0[i] = DOPUS_R(0.0);
    }
    s->qp_in.hess_shift = s->lm.lm;
    s->anytime.work += DOPUS_WORK_QP;
    qs = dopus_qp_solve_bound(s, 0, 0, s->settings.qp_max_iter);
    if (dopus_feedback_check_step(s, qs) != DOPUS_OK) {
        return;
    }
    dopus_store_domega(s);
    dopus_take_step(s);
    dopus_copy(&s->health.plan_u[0][0], &s->u[0][0], DOPUS_N * DOPUS_NU);
    s->health.plan_age = 0;
    if (!s->health.xhat_fresh) {
        /* no measurement to distrust: the model's prediction carries the loop */
        s->health.n_failed = 0;
        s->health.recover_pending = 0;
    }
    s->health.flags |= DOPUS_FLAG_PREDICTED;
}

static int dopus_prepare_iteration(dopus_solver *s, int extra);
static int dopus_anytime_run(dopus_solver *s);

/* Step 1 for the parameters (receding mode, once per sampling instant): p_k <- p_{k+1}, p_N
 * kept (a push replaces it). */
static void dopus_shift_parameters(dopus_solver *s)
{
    int k, i;
    if (s->settings.mode != DOPUS_MODE_RECEDING || s->p_shifted) {
        return;
    }
    for (k = 0; k < DOPUS_N; ++k) {
        for (i = 0; i < DOPUS_NP; ++i) {
            s->p[k][i] = s->p[k + 1][i];
        }
    }
    s->p_shifted = 1;
}

/* Parameters (algorithm.md section 4): DOPUS_OK when they may be written now (before init,
 * or a prepare is due), else DOPUS_ERR_ALREADY_PREPARED; in receding mode with a prepare due,
 * the shift of this sampling instant's parameters is done first (once). */
static int dopus_parameters_writable(dopus_solver *s)
{
    if (!s->initialized) {
        return DOPUS_OK;
    }
    if (!s->prepare_due) {
        /* the prepared QP has read the parameters: a write now would reach the QP one
         * sampling instant late */
        return DOPUS_ERR_ALREADY_PREPARED;
    }
    dopus_shift_parameters(s);
    return DOPUS_OK;
}

int dopus_prepare(dopus_solver *s)
{
    double start;
    int rc, hessian;
    if (!s->set_up) {
        return DOPUS_ERR_NOT_INITIALIZED;
    }
    if (!s->initialized) {
        return dopus_ret(s, DOPUS_ERR_NOT_INITIALIZED);
    }
    if (!s->prepare_due) {
        /* a second prepare would shift the horizon twice */
        return dopus_ret(s, DOPUS_ERR_ALREADY_PREPARED);
    }
    dopus_timer_begin(&s->timer, DOPUS_PREPARE_PHASES, DOPUS_PHASE_RECOVERY);
    start = s->timer.mark;
    s->qp_prefactored = 0; /* (the memory is the evaluations' now) */
    dopus_shift_parameters(s);
    s->anytime.extra_iterations = 0;
    s->anytime.prepared_extra = 0;
    /* the instant's budget counts the solver's own calls: the feedback's part (used) and
     * this prepare from now, not the caller's time between them */
    s->anytime.instant_start = dopus_budget_now(s) - s->anytime.used;
    s->anytime.mark = -1.0;
    hessian = s->settings.hessian;
    if (s->qp_ready && s->health.n_failed > 0 && !s->health.recover_pending && s->settings.recovery &&
        s->settings.mode == DOPUS_MODE_RECEDING && !(s->health.flags & DOPUS_FLAG_REINIT_GUESS)) {
        /* (not from the OCP file's guess: its plan is not the plant's); with a time budget
         * its QP stops where the least prepare still fits (a cut QP changes nothing) */
        dopus_budget_deadline(s, dopus_after_qp(s, dopus_prepare_floor(s)), s->anytime.cost_qp_step);
        if (!dopus_qp_deadline_near(s)) {
            /* (not when it would pass the deadline at once: in work units its N units) */
            dopus_predicted_step(s);
        }
        s->anytime.qp_timed = 0;
    }
    s->qp_ready = 0;
    if (s->settings.mode == DOPUS_MODE_RECEDING && s->health.plan_age < DOPUS_N) {
        s->health.plan_age += 1;
    }
    if (s->anytime.reinit_next >= 0) {
        /* a re-initialisation under way (a budget): its next evaluations */
        rc = dopus_reinit_continue(s);
    } else if (s->health.recover_pending && s->settings.recovery && s->settings.mode == DOPUS_MODE_RECEDING) {
        rc = dopus_recover(s, 0);
    } else {
        /* the recovery phase: Gauss-Newton blocks (convex in the cost whatever the
         * multipliers), every block fresh */
        if (s->health.recovering > 0 && DOPUS_HAS_GN) {
            s->settings.hessian = DOPUS_HESSIAN_GAUSS_NEWTON;
        }
        rc = dopus_prepare_iteration(s, 0);
    }
    if (rc == DOPUS_OK) {
        /* the budget left (algorithm.md section 14), with the Hessian of the recovery phase */
        if (s->health.recovering > 0 && DOPUS_HAS_GN) {
            s->settings.hessian = DOPUS_HESSIAN_GAUSS_NEWTON;
        }
        rc = dopus_anytime_run(s);
    }
    s->settings.hessian = hessian;
    if (rc == DOPUS_OK && s->settings.recovery && s->settings.mode == DOPUS_MODE_RECEDING &&
        dopus_health_stalled(&s->health, DOPUS_RECOVERY_FULL_RTI, s->lm.held)) {
        s->health.flags |= DOPUS_FLAG_STALLED;
    }
    if (rc == DOPUS_OK && dopus_budget_on(s) && s->anytime.mark >= 0.0) {
        /* the prepare after its last iteration (the test for one more) */
        s->anytime.cost_end = dopus_cost_peak(s, s->anytime.cost_end, dopus_budget_now(s) - s->anytime.mark);
    }
    s->anytime.used = dopus_budget_now(s) - s->anytime.instant_start;
    dopus_starved_check(s);
    if (rc == DOPUS_OK) {
        /* one prepare per sampling instant: the next needs a feedback first */
        s->prepare_due = 0;
        s->shifted = 0;
        s->p_shifted = 0;
    }
    dopus_timer_end(&s->timer, 1, start);
    return dopus_ret(s, rc);
}

/* The order of step 2's gradients with a budget (algorithm.md section 14): stages 0..N-2 by
 * the distance their linear model's point has moved since their last evaluation, |dw_acc + dw|
 * (2-norm, largest first, a non-finite one first, ties: the lower index); without a budget
 * stage order. */
static void dopus_gradient_order(const dopus_solver *s, int *order)
{
    dopus_real dist[DOPUS_N];
    int i, j, k;
    for (k = 0; k < DOPUS_N - 1; ++k) {
        order[k] = k;
    }
    if (!dopus_budget_on(s)) {
        return;
    }
    for (k = 0; k < DOPUS_N - 1; ++k) {
        const dopus_stage_slot *slot = dopus_ring_stage_const(&s->ring, k);
        dopus_real d2 = DOPUS_R(0.0);
        for (j = 0; j < DOPUS_NW; ++j) {
            const dopus_real v = slot->dw_acc[j] + slot->dw[j];
            d2 += v * v;
        }
        dist[k] = isfinite(d2) ? d2 : DOPUS_REAL_HUGE;
    }
    /* a stable insertion sort, largest first */
    for (i = 1; i < DOPUS_N - 1; ++i) {
        const int v = order[i];
        for (j = i - 1; j >= 0 && dist[order[j]] < dist[v]; --j) {
            order[j + 1] = order[j];
        }
        order[j + 1] = v;
    }
}

/* Steps 1 to 7 of prepare (algorithm.md sections 4 and 9); extra: an iteration of the
 * anytime budget (section 14), without the shift, x_N kept. */
static int dopus_prepare_iteration(dopus_solver *s, int extra)
{
    dopus_real xN_saved[DOPUS_NX];
    double b_start = dopus_budget_now(s), ext_cost = 0.0, b_tail, b0, b1, b_cut = 0.0, fixed,
           stage_time = 0.0;
    double t_fh = 0.0;
    int k, i, rc, n_grad = 0, n_fh = 0, n_al = 0, cut = 0, all_fresh, fuse, defer, diverged;
    int order[DOPUS_N];
    unsigned char evaluated[DOPUS_N];

    /* 1. shift (once per sampling instant: a retry after a failed prepare does not) */
    dopus_phase(s, DOPUS_PHASE_SHIFT);
    if (s->settings.mode == DOPUS_MODE_RECEDING && !s->shifted && !extra) {
        dopus_shift(s);
        s->shifted = 1;
    }
    dopus_copy(xN_saved, s->x[DOPUS_N], DOPUS_NX);

    /* 2. F_k and rho_k (eq. 16) of stages 0..N-2 (F_new kept for step 6); with a budget in
     *    the order of the distance their linear models have moved while one more and the
     *    least rest of the iteration fit, the stages after the cut keep their linear model's
     *    prediction (algorithm.md section 14); when step 4
     *    will re-linearise every one of them (all_fresh: no budget), H_k too, in the same call.
     *    Without a budget and with H_k apart (defer), every gradient first and then every
     *    rho_k: the same values, two phase switches (clock readings) per prepare instead of
     *    two per stage. With a budget the full RTI (fuse) evaluates H_k in the same call too
     *    while that call, the gradients of the stages after it and the least rest of the
     *    iteration fit (algorithm.md section 14); those stages are re-linearised (selected) */
    all_fresh = dopus_every_stage_fresh(s);
    fuse = !all_fresh && dopus_budget_on(s) && dopus_setting_full(s);
    defer = !all_fresh && !dopus_budget_on(s);
    dopus_gradient_order(s, order);
    for (k = 0; k < DOPUS_N && fuse; ++k) {
        s->selected[k] = 0;
    }
    b0 = dopus_budget_now(s);
    fixed = b0 - b_start;
    for (i = 0; i < DOPUS_N - 1; ++i) {
        dopus_stage_slot *slot;
        k = order[i];
        slot = dopus_ring_stage(&s->ring, k);
        evaluated[k] = 0;
        if (!cut && !dopus_budget_fits(s, s->anytime.cost_grad + dopus_prepare_least(s, DOPUS_N - 2 - i))) {
            cut = 1;
            b_cut = dopus_budget_now(s);
        }
        if (cut) {
            dopus_ring_predict(slot, s->mem.ev.Fn_w[k], s->mem.ev.Fn_phi[k], s->mem.ev.Fn_g[k]);
            s->rho[k] = DOPUS_R(0.0);
            continue;
        }
        evaluated[k] = 1;
        n_grad += 1;
        if (fuse &&
            !dopus_budget_fits(s, s->anytime.cost_fh + s->anytime.cost_grad * (double)(DOPUS_N - 2 - i) +
                                      dopus_prepare_least(s, 0))) {
            fuse = 0;
        }
        b1 = dopus_budget_now(s);
        dopus_phase(s, DOPUS_PHASE_GRADIENTS);
        rc = all_fresh || fuse ? dopus_stage_FH(s, k) : dopus_stage_F(s, k);
        if (rc != DOPUS_OK) {
            return rc;
        }
        /* stored as F_old in step 6, once nothing can fail */
        dopus_copy(s->mem.ev.Fn_w[k], s->mem.ev.tmp_F, DOPUS_NW);
        dopus_copy(s->mem.ev.Fn_phi[k], s->mem.ev.tmp_phi, DOPUS_NX);
        dopus_copy(s->mem.ev.Fn_g[k], s->mem.ev.tmp_g, DOPUS_NG);
        if (defer) {
            continue;
        }
        dopus_phase(s, DOPUS_PHASE_RHO);
        s->rho[k] = dopus_ring_secant(slot, s->mem.ev.Fn_w[k], s->mem.ev.Fn_phi[k], s->mem.ev.Fn_g[k]);
        if (all_fresh || fuse) {
            /* the slot's H after the secant, which reads the old one */
            rc = dopus_stage_H_keep(s, k);
            if (rc != DOPUS_OK) {
                return rc;
            }
        }
        if (fuse) {
            s->selected[k] = 1;
            n_fh += 1;
            t_fh += dopus_budget_now(s) - b1;
        }
    }

    if (defer) {
        dopus_phase(s, DOPUS_PHASE_RHO);
        for (k = 0; k < DOPUS_N - 1; ++k) {
            s->rho[k] = dopus_ring_secant(dopus_ring_stage_const(&s->ring, k), s->mem.ev.Fn_w[k],
                                          s->mem.ev.Fn_phi[k], s->mem.ev.Fn_g[k]);
        }
    }

    if (dopus_budget_on(s)) {
        const double b_end = dopus_budget_now(s);
        if (!cut) {
            b_cut = b_end;
        }
        if (n_grad > n_fh) {
            s->anytime.cost_grad =
                dopus_cost(s, s->anytime.cost_grad, (b_cut - b0 - t_fh) / (double)(n_grad - n_fh));
        }
        if (n_fh > 0) {
            s->anytime.cost_fh = dopus_cost(s, s->anytime.cost_fh, t_fh / (double)n_fh);
        }
        if (n_grad < DOPUS_N - 1) {
            s->anytime.cost_predict =
                dopus_cost_peak(s, s->anytime.cost_predict, (b_end - b_cut) / (double)(DOPUS_N - 1 - n_grad));
        }
    }
    /* 3. stage N-1 fresh; in receding mode x_N <- phi_{N-1} before the terminal node */
    b0 = dopus_budget_now(s);
    dopus_phase(s, DOPUS_PHASE_GRADIENTS);
    rc = dopus_stage_FH(s, DOPUS_N - 1);
    if (rc != DOPUS_OK) {
        return rc;
    }
    if (s->settings.mode == DOPUS_MODE_RECEDING && !extra) {
        dopus_copy(s->x[DOPUS_N], s->mem.ev.tmp_phi, DOPUS_NX);
    }
    dopus_ring_store_F(dopus_ring_stage(&s->ring, DOPUS_N - 1), s->mem.ev.tmp_F, s->mem.ev.tmp_phi,
                       s->mem.ev.tmp_g);
    s->rho[DOPUS_N - 1] = DOPUS_R(0.0);
    rc = dopus_stage_H_keep(s, DOPUS_N - 1);
    if (rc == DOPUS_OK) {
        rc = dopus_term_F(s);
    }
    if (rc == DOPUS_OK) {
        rc = dopus_term_H(s);
    }
    if (rc == DOPUS_OK && dopus_budget_on(s)) {
        s->anytime.cost_head = dopus_cost_peak(s, s->anytime.cost_head, dopus_budget_now(s) - b0);
    }

    /* 4. re-linearise the M stages with the largest rho_k (more as the budget allows) */
    b0 = dopus_budget_now(s);
    if (rc == DOPUS_OK) {
        dopus_phase(s, DOPUS_PHASE_RHO);
        rc = all_fresh ? dopus_all_selected(s) : dopus_relinearise(s, n_fh, &ext_cost, &stage_time);
    }
    /* step 4's own work beyond its stages */
    fixed += dopus_budget_now(s) - b0 - stage_time;
    b0 = dopus_budget_now(s);

    /* 5. cost_hessian fresh: every stage whose H was not computed above gets
     *    Ht = reg(A_dyn + A_l) with A_l at the current point (Phit, Ct, A_dyn kept); with a
     *    constant A_l (DOPUS_COST_HESS_CONST) that is the block stored with A_dyn, reg(A), up
     *    to the rounding of A - A_l + A_l: kept as it is (unless al_resync) */
    if (rc == DOPUS_OK && s->settings.cost_hessian && (!DOPUS_COST_HESS_CONST || s->al_resync)) {
        dopus_phase(s, DOPUS_PHASE_HESSIANS);
        for (k = 0; k < DOPUS_N - 1 && rc == DOPUS_OK; ++k) {
            dopus_stage_slot *slot = dopus_ring_stage(&s->ring, k);
            if (s->selected[k]) {
                continue;
            }
            rc = dopus_stage_Al(s, k);
            if (rc != DOPUS_OK) {
                break;
            }
            n_al += 1;
            if (s->settings.regularization == DOPUS_REG_NONE) {
                /* nothing to regularise: the sum straight into the slot, no copy */
                dopus_ring_set_H_A_dyn(slot, s->mem.ev.tmp_Al);
                continue;
            }
            dopus_ring_add_A_dyn(slot, s->mem.ev.tmp_Al, s->mem.ev.tmp_A);
            rc = dopus_regularize(s, DOPUS_NW, s->mem.ev.tmp_A);
            if (rc == DOPUS_OK) {
                dopus_ring_set_H(slot, s->mem.ev.tmp_A);
            }
        }
    }
    if (rc != DOPUS_OK) {
        /* leave the iterate as it was after step 1 */
        dopus_copy(s->x[DOPUS_N], xN_saved, DOPUS_NX);
        return rc;
    }
    if (s->settings.cost_hessian) {
        s->al_resync = 0;
    }

    if (dopus_budget_on(s) && n_al > 0) {
        s->anytime.cost_al =
            dopus_cost_peak(s, s->anytime.cost_al, (dopus_budget_now(s) - b0) / (double)n_al);
    } else {
        fixed += dopus_budget_now(s) - b0;
    }
    b_tail = dopus_budget_now(s);

    /* 6. F_new of step 2 becomes F_old, the distance moved since the last evaluation restarts
     *    at an evaluated stage and grows by the step at a predicted one; QP vectors (the fresh
     *    A blocks were regularised when stored) */
    dopus_phase(s, DOPUS_PHASE_GRADIENTS);
    for (k = 0; k < DOPUS_N; ++k) {
        dopus_stage_slot *slot = dopus_ring_stage(&s->ring, k);
        if (k == DOPUS_N - 1 || evaluated[k]) {
            dopus_zero(DOPUS_NW, slot->dw_acc);
        } else {
            dopus_lai_axpy(DOPUS_NW, DOPUS_R(1.0), slot->dw, slot->dw_acc);
        }
        if (k < DOPUS_N - 1) {
            dopus_ring_store_F(slot, s->mem.ev.Fn_w[k], s->mem.ev.Fn_phi[k], s->mem.ev.Fn_g[k]);
        }
    }
    dopus_assemble(s);
    s->qp_ready = 1;

    /* 7. the divergence test of the prepared iterate (algorithm.md section 9) and the
     *    automatic Levenberg-Marquardt term (section 10) */
    dopus_phase(s, DOPUS_PHASE_RECOVERY);
    s->health.kkt_proxy = dopus_kkt_proxy_eval(s);
    dopus_phase(s, DOPUS_PHASE_LM);
    /* the test as the QP's factorisation where the feedback may reuse it, else dopus_lm.c's
     * (the same test; on the robot arm, whose start always has active rows, the QP's form cost
     * 29 % more on the Cortex-M7: bench/issue23/measurements.md section 45) */
    s->qp_prefactored = 0; /* (a previous iteration's: the evaluations used the memory since) */
    dopus_lm_hook(s, dopus_guess_empty(s));
    dopus_lm_prepared(&s->lm, &s->ring, s->A_N, s->health.kkt_proxy, s->health.kkt_proxy_ref,
                      s->mem.ev.lm_work);
    dopus_lm_hook(s, 0);
    /* the test's factorisation at the term the feedback's QP starts from (unless capped); else
     * the start's first factorisation with the rows it will guess, where it will run */
    s->qp_prefactored = s->qp_prefactored && s->qp_pre_lm == s->lm.lm;
    if (!s->qp_prefactored && dopus_start_prefactor_due(s, extra)) {
        dopus_start_prefactor(s);
    }
    dopus_phase(s, DOPUS_PHASE_RECOVERY);
    diverged = dopus_iterate_diverged(s);
    if (dopus_budget_on(s)) {
        s->anytime.cost_prepare =
            dopus_cost_reserve(s, s->anytime.cost_prepare, dopus_budget_now(s) - b_start - ext_cost);
        s->anytime.cost_tail = dopus_cost_peak(s, s->anytime.cost_tail, dopus_budget_now(s) - b_tail);
        s->anytime.cost_fixed = dopus_cost_peak(s, s->anytime.cost_fixed, fixed > 0.0 ? fixed : 0.0);
        s->anytime.mark = dopus_budget_now(s);
    }
    if (diverged) {
        s->health.flags |= DOPUS_FLAG_DIVERGED;
        if (s->settings.recovery && s->settings.mode == DOPUS_MODE_RECEDING) {
            return dopus_recover(s, 1);
        }
    }
    return DOPUS_OK;
}

/* ---- anytime (algorithm.md section 14) -------------------------------------------------- */

/* One extra iteration on the next instant's problem: the prepared QP for the state the plan
 * predicts (dx_0 = 0), its full step, then a prepare iteration without the shift. A QP not
 * solved (or a step outside the box) changes nothing and returns DOPUS_ERR_QP. */
static int dopus_extra_iteration(dopus_solver *s)
{
    dopus_lm lm = s->lm;
    dopus_real proxy = s->health.kkt_proxy;
    double b0 = dopus_budget_now(s);
    int i, qs, rc;
    for (i = 0; i < DOPUS_NX; ++i) {
        s->qp_in.x0[i] = DOPUS_R(0.0);
    }
    /* the cap of the term while the extra iterations make progress; after one of them raised
     * the KKT proxy, the term the prepare convexified (algorithm.md section 14) */
    if (!s->anytime.uncapped) {
        dopus_lm_measured(&s->lm, s->qp_in.x0, s->health.scale_x, s->health.kkt_proxy);
    }
    /* the QP stops at the budget's deadline less the prepare iteration that follows it (a QP
     * stopped there changes nothing) */
    s->anytime.mark = -1.0;
    dopus_budget_deadline(s, dopus_after_qp(s, fmax(s->anytime.cost_prepare, dopus_prepare_floor(s))),
                          s->anytime.cost_qp_step);
    qs = dopus_feedback_qp(s);
    s->anytime.qp_timed = 0;
    if (dopus_budget_on(s)) {
        dopus_cost_qp_step(s, dopus_budget_now(s) - b0, s->qp_iterations);
    }
    if (dopus_feedback_check_step(s, qs) != DOPUS_OK) {
        s->lm = lm;
        return DOPUS_ERR_QP;
    }
    s->anytime.cost_qp = dopus_cost(s, s->anytime.cost_qp, dopus_budget_now(s) - b0);
    b0 = dopus_budget_now(s);
    dopus_store_domega(s);
    dopus_take_step(s);
    dopus_lm_feedback(&s->lm, 1);
    if (dopus_budget_on(s)) {
        s->anytime.cost_fb_tail = dopus_cost_peak(s, s->anytime.cost_fb_tail, dopus_budget_now(s) - b0);
    }
    rc = dopus_prepare_iteration(s, 1);
    if (!(s->health.kkt_proxy < proxy)) {
        s->anytime.uncapped = 1;
    }
    return rc;
}

/* The budget left after prepare (algorithm.md section 14): extra iterations while the KKT
 * proxy exceeds the tolerance and one more fits. The last feedback's QP figures stay those
 * of dopus_info. */
static int dopus_anytime_run(dopus_solver *s)
{
    int qp_status = s->qp_status, qp_iterations = s->qp_iterations, cold = s->qp_cold_retry, rc = DOPUS_OK;
    const int warm_failed = s->qp_warm_failed;
    const int qp_factorizations = s->qp_factorizations, pre_used = s->qp_pre_used;
    int max_iter = DOPUS_ANYTIME_MAX_ITER;
    if (!dopus_budget_on(s)) {
        /* without a budget: the recovery phase's extra iterations (algorithm.md section 9) */
        if (s->health.recovering <= 0 || !s->settings.recovery || s->settings.mode != DOPUS_MODE_RECEDING) {
            return DOPUS_OK;
        }
        max_iter = DOPUS_RECOVERY_EXTRA_ITER;
    }
    s->anytime.uncapped = 0;
    while (s->anytime.extra_iterations < max_iter && s->qp_ready &&
           s->health.kkt_proxy > s->settings.anytime_tol &&
           dopus_budget_fits(s, s->anytime.cost_qp + s->anytime.cost_prepare)) {
        rc = dopus_extra_iteration(s);
        if (rc != DOPUS_OK) {
            break;
        }
        s->anytime.extra_iterations += 1;
    }
    s->qp_status = qp_status;
    s->qp_iterations = qp_iterations;
    s->qp_factorizations = qp_factorizations;
    s->qp_pre_used = pre_used;
    s->qp_cold_retry = cold;
    s->qp_warm_failed = warm_failed;
    s->anytime.prepared_extra = s->anytime.extra_iterations > 0 && s->qp_ready;
    return rc == DOPUS_ERR_QP ? DOPUS_OK : rc;
}

/* ---- KKT ---------------------------------------------------------------------------- */

int dopus_kkt_eval(dopus_solver *s, const dopus_real *xhat0, dopus_real *kkt4)
{
    dopus_real parts[4], xm[DOPUS_NX], xs[DOPUS_NX];
    int i, rc;

    if (!s->set_up) {
        return DOPUS_ERR_NOT_INITIALIZED;
    }
    if (!s->initialized) {
        return dopus_ret(s, DOPUS_ERR_NOT_INITIALIZED);
    }
    xhat0 = dopus_with_memory(s, dopus_scaled_in(xhat0, dopus_scale_x, DOPUS_NX, xs), xm);
    if (xhat0 && !dopus_lai_vec_finite(DOPUS_NX, xhat0)) {
        return dopus_ret(s, DOPUS_ERR_NONFINITE_INPUT);
    }
    dopus_timer_begin(&s->timer, 1u << DOPUS_PHASE_KKT, DOPUS_PHASE_KKT);
    /* (its own scratch: the prepared factorisation in mem stays) */
    rc = dopus_kkt_measure(&s->x[0][0], &s->u[0][0], &s->lam[0][0], &s->mu_g[0][0], &s->mu_b[0][0], s->mu_bN,
                           s->mu_r, s->nu, &s->p[0][0], xhat0 ? xhat0 : s->xhat0, &s->kkt_work, parts);
    dopus_timer_end(&s->timer, -1, 0.0);
    if (rc != DOPUS_KKT_OK) {
        return dopus_ret(s, rc == DOPUS_KKT_FUNCTION ? DOPUS_ERR_FUNCTION : DOPUS_ERR_NONFINITE_VALUE);
    }
    for (i = 0; i < 4; ++i) {
        s->kkt[i] = parts[i];
        if (kkt4) {
            kkt4[i] = parts[i];
        }
    }
    s->kkt_rel = dopus_kkt_relative(parts, &s->x[0][0], &s->u[0][0], &s->lam[0][0], &s->mu_g[0][0],
                                    &s->mu_b[0][0], s->mu_bN, s->mu_r, s->nu);
    return dopus_ret(s, DOPUS_OK);
}

/* ---- getters ------------------------------------------------------------------------ */

void dopus_get_x(const dopus_solver *s, dopus_real *x)
{
    dopus_scaled_out(x, &s->x[0][0], dopus_scale_x, (DOPUS_N + 1) * DOPUS_NX, DOPUS_NX);
}

void dopus_get_u(const dopus_solver *s, dopus_real *u)
{
    dopus_scaled_out(u, &s->u[0][0], dopus_scale_u, DOPUS_N * DOPUS_NU, DOPUS_NU);
}

void dopus_get_lam(const dopus_solver *s, dopus_real *lam)
{
    dopus_dual_out(lam, &s->lam[0][0], dopus_scale_x, (DOPUS_N + 1) * DOPUS_NX, DOPUS_NX);
}

void dopus_get_mu_g(const dopus_solver *s, dopus_real *mu_g)
{
    int k;
    for (k = 0; k < DOPUS_N; ++k) {
        dopus_dual_out(mu_g + k * DOPUS_NG, s->mu_g[k], dopus_scale_g, DOPUS_NG, DOPUS_DIM(DOPUS_NG));
    }
}

void dopus_get_mu_b(const dopus_solver *s, dopus_real *mu_b)
{
    int k, i;
    for (k = 0; k < DOPUS_N; ++k) {
        for (i = 0; i < DOPUS_NW; ++i) {
            mu_b[k * DOPUS_NW + i] = s->mu_b[k][i] * dopus_scale_cost / dopus_scale_w(i);
        }
    }
}

void dopus_get_mu_bN(const dopus_solver *s, dopus_real *mu_bN)
{
    dopus_dual_out(mu_bN, s->mu_bN, dopus_scale_x, DOPUS_NX, DOPUS_NX);
}

void dopus_get_mu_r(const dopus_solver *s, dopus_real *mu_r)
{
    dopus_dual_out(mu_r, s->mu_r, dopus_scale_r, DOPUS_NR, DOPUS_DIM(DOPUS_NR));
}

void dopus_get_nu(const dopus_solver *s, dopus_real *nu)
{
    dopus_dual_out(nu, s->nu, dopus_scale_req, DOPUS_NE, DOPUS_DIM(DOPUS_NE));
}

void dopus_get_rho(const dopus_solver *s, dopus_real *rho)
{
    dopus_copy(rho, s->rho, DOPUS_N);
}

int dopus_get_recomputed(const dopus_solver *s, int *stages)
{
    int k, n = 0;
    for (k = 0; k < DOPUS_N - 1; ++k) {
        if (s->selected[k]) {
            stages[n++] = k;
        }
    }
    stages[n++] = DOPUS_N - 1;
    return n;
}

/* The bound of side (-1 lower, else upper) from the arrays lo, up at entry i. */
static dopus_real dopus_side_bound(const dopus_real *lo, const dopus_real *up, int i, int side)
{
    return side > 0 ? up[i] : lo[i];
}

#if DOPUS_NSOFT > 0
/* The slack of the row value v against [lb, ub] on the sides with soft weights w (stride). */
static dopus_real dopus_soft_slack(dopus_real v, dopus_real lb, dopus_real ub, const dopus_real *w,
                                   int stride)
{
    dopus_real sl = DOPUS_R(0.0);
    if ((w[0] > DOPUS_R(0.0) || w[2 * stride] > DOPUS_R(0.0)) && lb - v > sl) {
        sl = lb - v;
    }
    if ((w[stride] > DOPUS_R(0.0) || w[3 * stride] > DOPUS_R(0.0)) && v - ub > sl) {
        sl = v - ub;
    }
    return sl;
}
#endif

dopus_real dopus_get_soft_slacks(const dopus_solver *s, dopus_real *viol_x, dopus_real *viol_g,
                                 dopus_real *viol_r)
{
    dopus_real worst = DOPUS_R(0.0);
    int k, i;
    for (k = 0; k <= DOPUS_N; ++k) {
        for (i = 0; i < DOPUS_NX && viol_x; ++i) {
            viol_x[k * DOPUS_NX + i] = DOPUS_R(0.0);
        }
    }
    for (k = 0; k < DOPUS_N; ++k) {
        for (i = 0; i < DOPUS_DIM(DOPUS_NG) && viol_g; ++i) {
            viol_g[k * DOPUS_DIM(DOPUS_NG) + i] = DOPUS_R(0.0);
        }
    }
    for (i = 0; i < DOPUS_DIM(DOPUS_NR) && viol_r; ++i) {
        viol_r[i] = DOPUS_R(0.0);
    }
#if DOPUS_NSOFT > 0
    {
        const dopus_qp_in *in = &s->qp_in;
        const dopus_qp_sol *sol = &s->mem.qp.sol;
        /* the QP's matrices are not pointed to between calls: the slots of the horizon of the
         * last feedback (no shift since) and the terminal R */
        for (k = 1; k <= DOPUS_N; ++k) {
            for (i = 0; i < DOPUS_NX; ++i) {
                const dopus_real lb = k < DOPUS_N ? in->lbw[k][i] : in->lbxN[i];
                const dopus_real ub = k < DOPUS_N ? in->ubw[k][i] : in->ubxN[i];
                const dopus_real sl =
                    dopus_soft_slack(sol->x[k][i], lb, ub, &dopus_soft_x[0][i], DOPUS_NX) * dopus_scale_x[i];
                worst = sl > worst ? sl : worst;
                if (viol_x) {
                    viol_x[k * DOPUS_NX + i] = sl;
                }
            }
        }
        for (k = 0; k < DOPUS_N && DOPUS_NG > 0; ++k) {
            for (i = 0; i < DOPUS_NG; ++i) {
                dopus_real v = DOPUS_R(0.0), sl;
                int c;
                for (c = 0; c < DOPUS_NW; ++c) {
                    v += dopus_ring_stage_const(&s->ring, k)->Ct[i + c * DOPUS_DIM(DOPUS_NG)] *
                         (c < DOPUS_NX ? sol->x[k][c] : sol->u[k][c - DOPUS_NX]);
                }
                sl = dopus_soft_slack(v, in->lg[k][i], in->ug[k][i], &dopus_soft_g[0][i],
                                      DOPUS_DIM(DOPUS_NG)) *
                     dopus_scale_g[i];
                worst = sl > worst ? sl : worst;
                if (viol_g) {
                    viol_g[k * DOPUS_DIM(DOPUS_NG) + i] = sl;
                }
            }
        }
        for (i = 0; i < DOPUS_NR; ++i) {
            dopus_real v = DOPUS_R(0.0), sl;
            int c;
            for (c = 0; c < DOPUS_NX; ++c) {
                v += s->R[i + c * DOPUS_DIM(DOPUS_NR)] * sol->x[DOPUS_N][c];
            }
            sl = dopus_soft_slack(v, in->lr[i], in->ur[i], &dopus_soft_r[0][i], DOPUS_DIM(DOPUS_NR)) *
                 dopus_scale_r[i];
            worst = sl > worst ? sl : worst;
            if (viol_r) {
                viol_r[i] = sl;
            }
        }
    }
#else
    (void)s;
#endif
    return worst;
}

int dopus_get_qp_infeasible_row(const dopus_solver *s, dopus_row_info *row)
{
    int k, j, side;
    if (s->qp_status != DOPUS_QP_PRIMAL_INFEASIBLE ||
        !dopus_qp_infeasible_row(&s->mem.qp.work, &s->qp_in, &k, &j, &side)) {
        return 0;
    }
    row->stage = k;
    row->side = side;
    if (j < DOPUS_NX) {
        row->kind = DOPUS_ROW_STATE;
        row->index = j;
        row->bound = dopus_side_bound(dopus_lbx, dopus_ubx, j, side);
    } else if (k < DOPUS_N && j < DOPUS_NW) {
        row->kind = DOPUS_ROW_CONTROL;
        row->index = j - DOPUS_NX;
        row->bound = dopus_side_bound(dopus_lbu, dopus_ubu, row->index, side);
    } else if (k < DOPUS_N) {
        row->kind = DOPUS_ROW_PATH;
        row->index = j - DOPUS_NW;
        row->bound = dopus_side_bound(dopus_lg_k[k], dopus_ug_k[k], row->index, side);
    } else if (j < DOPUS_NX + DOPUS_NR) {
        row->kind = DOPUS_ROW_TERMINAL;
        row->index = j - DOPUS_NX;
        row->bound = dopus_side_bound(dopus_lr, dopus_ur, row->index, side);
    } else {
        row->kind = DOPUS_ROW_TERMINAL_EQ;
        row->index = j - DOPUS_NX - DOPUS_NR;
        row->bound = DOPUS_R(0.0);
    }
    row->bound *= row->kind == DOPUS_ROW_STATE      ? dopus_scale_x[row->index]
                  : row->kind == DOPUS_ROW_CONTROL  ? dopus_scale_u[row->index]
                  : row->kind == DOPUS_ROW_PATH     ? dopus_scale_g[row->index]
                  : row->kind == DOPUS_ROW_TERMINAL ? dopus_scale_r[row->index]
                                                    : dopus_scale_req[row->index];
    return 1;
}

void dopus_get_u0(const dopus_solver *s, dopus_real *u0)
{
    dopus_scaled_out(u0, s->health.u0_out, dopus_scale_u, DOPUS_NU, DOPUS_NU);
}

void dopus_get_scales(const dopus_solver *s, dopus_real *scale_x, dopus_real *scale_u)
{
    if (scale_x) {
        dopus_copy(scale_x, s->health.scale_x, DOPUS_NX);
    }
    if (scale_u) {
        dopus_copy(scale_u, s->health.scale_u, DOPUS_NU);
    }
}

static int dopus_has_clock(const dopus_solver *s)
{
    if (s->timer.clock == 0) {
        return 0;
    }
    return s->timer.clock != dopus_timer_default_clock || dopus_timer_has_default_clock();
}

void dopus_get_info(const dopus_solver *s, dopus_info *info)
{
    int k, i;
    info->status = s->status;
    info->initialized = s->set_up && s->initialized;
    info->qp_status = s->qp_status;
    info->qp_iterations = s->qp_iterations;
    info->qp_factorizations = s->qp_factorizations;
    info->qp_prefactored = s->qp_pre_used;
    info->qp_cold_retry = s->qp_cold_retry;
    info->flags = s->health.flags;
    info->recoveries = s->health.n_recoveries;
    info->failed_feedbacks = s->health.n_failed;
    info->M_used = 0;
    for (k = 0; k < DOPUS_N - 1; ++k) {
        info->M_used += s->selected[k] ? 1 : 0;
    }
    info->ring_head = s->ring.ring_head;
    info->has_clock = dopus_has_clock(s);
    info->lm = s->lm.lm;
    info->lm_scale = s->lm.scale;
    info->lm_held = s->lm.held;
    info->kkt_proxy = s->health.kkt_proxy;
    info->kkt_max = s->kkt[0];
    for (i = 0; i < 4; ++i) {
        info->kkt[i] = s->kkt[i];
        info->kkt_max = s->kkt[i] > info->kkt_max ? s->kkt[i] : info->kkt_max;
    }
    info->kkt_rel = s->kkt_rel;
    for (i = 0; i < DOPUS_N_PHASES; ++i) { /* times are double in both precisions */
        info->timings[i] = s->timer.t[i];
    }
    info->t_feedback = s->timer.t_call[0];
    info->t_prepare = s->timer.t_call[1];
    info->extra_iterations = s->anytime.extra_iterations;
    info->instant_stages = s->anytime.instant_stages;
    info->budget_used = s->anytime.used;
    info->work = s->anytime.work;
}

/* ---- settings, setup, parameters, clock ---------------------------------------------- */

/* DOPUS_OK when every setting is in range, else DOPUS_ERR_INVALID_ARGUMENT. */
static int dopus_settings_check(const dopus_settings *st)
{
    int reg = st->regularization;
    if (st->M < 0 || st->M > DOPUS_N - 1 ||
        (st->mode != DOPUS_MODE_RECEDING && st->mode != DOPUS_MODE_FIXED) ||
        (st->hessian != DOPUS_HESSIAN_EXACT &&
         !(st->hessian == DOPUS_HESSIAN_GAUSS_NEWTON && DOPUS_HAS_GN)) ||
        (reg != DOPUS_REG_NONE && reg != DOPUS_REG_PROJECT && reg != DOPUS_REG_MIRROR) ||
        !isfinite(st->reg_eps) || !(st->reg_eps > DOPUS_R(0.0)) ||
        (st->cost_hessian != 0 && st->cost_hessian != 1) || (st->lm_auto != 0 && st->lm_auto != 1) ||
        !isfinite(st->lm) || !(st->lm >= DOPUS_R(0.0)) || !isfinite(st->qp_tol) ||
        !(st->qp_tol > DOPUS_R(0.0)) || st->qp_tol > DOPUS_QP_TOL_MAX || st->qp_max_iter < 1 ||
        (st->qp_warm_start != 0 && st->qp_warm_start != 1) || (st->recovery != 0 && st->recovery != 1) ||
        st->recovery_failures < 1 || !(st->budget >= 0.0) || !(st->budget < HUGE_VAL) ||
        (st->budget_unit != DOPUS_BUDGET_TIME && st->budget_unit != DOPUS_BUDGET_WORK) ||
        !isfinite(st->anytime_tol) || !(st->anytime_tol > DOPUS_R(0.0)) ||
        (st->M_adaptive != 0 && st->M_adaptive != 1) || st->M_min < 0 || st->M_max < st->M_min ||
        st->M_max > DOPUS_N - 1 || !isfinite(st->M_eta) || !(st->M_eta > DOPUS_R(0.0)) ||
        !isfinite(st->gate) || !(st->gate >= DOPUS_R(0.0)) || st->gate_hold < 1) {
        return DOPUS_ERR_INVALID_ARGUMENT;
    }
    return DOPUS_OK;
}

int dopus_setup(dopus_solver *s, const dopus_settings *st)
{
    dopus_settings defaults;
    int k, i, rc;
    dopus_settings_default(&defaults);
    rc = st ? dopus_settings_check(st) : DOPUS_OK;
    s->settings = (st && rc == DOPUS_OK) ? *st : defaults;
    s->set_up = 1;
    s->initialized = 0;
    s->qp_ready = 0;
    s->prepare_due = 0;
    s->shifted = 0;
    s->al_resync = 1;
    s->status = DOPUS_OK;
    s->qp_prefactored = 0;
    s->qp_pre_lm = DOPUS_R(0.0);
    dopus_lm_reset(&s->lm, s->settings.lm_auto, s->settings.lm);
    s->lm.scale = DOPUS_R(1.0);
    for (k = 0; k < DOPUS_N; ++k) { /* set only during a QP solve (dopus_qp_solve_bound) */
        s->qp_in.H[k] = 0;
        s->qp_in.Phi[k] = 0;
        s->qp_in.C[k] = 0;
    }
    s->qp_in.HN = 0;
    s->qp_in.R = 0;
    s->qp_in.Req = 0;
    s->qp_cold_retry = 0;
    s->qp_warm_failed = 0;
    s->qp_no_active_set = 0;
    for (k = 0; k <= DOPUS_N; ++k) {
        for (i = 0; i < DOPUS_NP; ++i) {
            s->p[k][i] = dopus_p_default[k][i];
        }
    }
    s->p_shifted = 0;
    for (i = 0; i < DOPUS_NU; ++i) {
        s->u_applied[i] = DOPUS_R(0.0);
    }
    for (i = 0; i < DOPUS_NX; ++i) {
        s->xhat0[i] = dopus_x0_default[i] / dopus_scale_x[i];
    }
    s->qp_status = 0;
    s->qp_iterations = 0;
    s->qp_factorizations = 0;
    s->qp_pre_used = 0;
    for (k = 0; k < DOPUS_N; ++k) {
        s->rho[k] = DOPUS_R(0.0);
        s->selected[k] = 0;
    }
    dopus_health_scales(&s->health);
    dopus_reset_health(s);
    for (i = 0; i < 4; ++i) {
        s->kkt[i] = NAN;
    }
    s->kkt_rel = NAN;
    dopus_timer_init(&s->timer);
    s->anytime.work = 0.0;
    s->anytime.instant_start = 0.0;
    s->anytime.cost_stage = 0.0;
    s->anytime.cost_qp = 0.0;
    s->anytime.cost_prepare = 0.0;
    s->anytime.cost_qp_iter = 0.0;
    s->anytime.cost_qp_step = 0.0;
    s->anytime.cost_tail = 0.0;
    s->anytime.cost_grad = 0.0;
    s->anytime.cost_head = 0.0;
    s->anytime.cost_al = 0.0;
    s->anytime.cost_predict = 0.0;
    s->anytime.cost_fixed = 0.0;
    s->anytime.cost_end = 0.0;
    s->anytime.cost_fb_tail = 0.0;
    s->anytime.cost_qp_over = 0.0;
    s->anytime.mark = -1.0;
    s->anytime.qp_reads = 0;
    s->anytime.qp_read = 0.0;
    s->anytime.qp_read_price = 0.0;
    s->anytime.used = 0.0;
    s->anytime.qp_timed = 0;
    s->anytime.fb_qp_cut = 0;
    s->anytime.fb_qp_end = 0.0;
    s->anytime.rest_last = 0.0;
    s->anytime.starved = 0;
    s->anytime.extra_iterations = 0;
    s->anytime.instant_stages = 0;
    s->anytime.prepared_extra = 0;
    s->anytime.uncapped = 0;
    s->anytime.reinit_next = -1;
    return dopus_ret(s, rc);
}

int dopus_update_settings(dopus_solver *s, const dopus_settings *st)
{
    dopus_settings old;
    if (!s->set_up) {
        return DOPUS_ERR_NOT_INITIALIZED;
    }
    if (st == 0 || dopus_settings_check(st) != DOPUS_OK) {
        return dopus_ret(s, DOPUS_ERR_INVALID_ARGUMENT);
    }
    old = s->settings;
    s->settings = *st;
    /* the prepared factor was formed under the old settings (and the lm restart below reuses
     * its memory): the feedback factorises afresh */
    s->qp_prefactored = 0;
    if (st->regularization != old.regularization || st->reg_eps != old.reg_eps) {
        /* the blocks were regularised with the old setting: step 5 refreshes them */
        s->al_resync = 1;
    }
    if (st->lm_auto && !old.lm_auto) {
        /* the automatic term restarts: from 0, raised until the prepared QP is convex */
        dopus_lm_reset(&s->lm, 1, DOPUS_R(0.0));
        if (s->initialized && s->qp_ready) {
            dopus_lm_start(&s->lm, &s->ring, s->A_N, s->mem.ev.lm_work);
        }
    } else if (!st->lm_auto) {
        dopus_lm_reset(&s->lm, 0, st->lm);
    }
    if (!st->recovery) {
        s->health.recover_pending = 0;
    }
    return dopus_ret(s, DOPUS_OK);
}

void dopus_get_settings(const dopus_solver *s, dopus_settings *st)
{
    *st = s->settings;
}

int dopus_set_parameters(dopus_solver *s, const dopus_real *p)
{
    int k, i, rc;
    if (!s->set_up) {
        return DOPUS_ERR_NOT_INITIALIZED;
    }
    if (DOPUS_NP == 0) {
        return dopus_ret(s, DOPUS_OK);
    }
    if (p == 0) {
        return dopus_ret(s, DOPUS_ERR_INVALID_ARGUMENT);
    }
    if (!dopus_lai_vec_finite((DOPUS_N + 1) * DOPUS_NP, p)) {
        return dopus_ret(s, DOPUS_ERR_NONFINITE_INPUT);
    }
    rc = dopus_parameters_writable(s);
    if (rc != DOPUS_OK) {
        return dopus_ret(s, rc);
    }
    for (k = 0; k <= DOPUS_N; ++k) {
        for (i = 0; i < DOPUS_NP; ++i) {
            s->p[k][i] = p[k * DOPUS_NP + i];
        }
    }
    return dopus_ret(s, DOPUS_OK);
}

int dopus_set_parameters_node(dopus_solver *s, int k, const dopus_real *pk)
{
    int i, rc;
    if (!s->set_up) {
        return DOPUS_ERR_NOT_INITIALIZED;
    }
    if (k < 0 || k > DOPUS_N) {
        return dopus_ret(s, DOPUS_ERR_INVALID_ARGUMENT);
    }
    if (DOPUS_NP == 0) {
        return dopus_ret(s, DOPUS_OK);
    }
    if (pk == 0) {
        return dopus_ret(s, DOPUS_ERR_INVALID_ARGUMENT);
    }
    if (!dopus_lai_vec_finite(DOPUS_NP, pk)) {
        return dopus_ret(s, DOPUS_ERR_NONFINITE_INPUT);
    }
    rc = dopus_parameters_writable(s);
    if (rc != DOPUS_OK) {
        return dopus_ret(s, rc);
    }
    for (i = 0; i < DOPUS_NP; ++i) {
        s->p[k][i] = pk[i];
    }
    return dopus_ret(s, DOPUS_OK);
}

int dopus_push_parameters(dopus_solver *s, const dopus_real *pN)
{
    if (!s->set_up) {
        return DOPUS_ERR_NOT_INITIALIZED;
    }
    if (!s->initialized) {
        return dopus_ret(s, DOPUS_ERR_NOT_INITIALIZED);
    }
    if (s->settings.mode != DOPUS_MODE_RECEDING) {
        return dopus_ret(s, DOPUS_ERR_INVALID_ARGUMENT);
    }
    /* the new last node's parameters: the same checks and write as for any node */
    return dopus_set_parameters_node(s, DOPUS_N, pN);
}

void dopus_stop(dopus_solver *s)
{
    if (!s->set_up) {
        return;
    }
    s->initialized = 0;
    s->qp_ready = 0;
    s->prepare_due = 0;
    s->shifted = 0;
    s->p_shifted = 0;
}

const char *dopus_row_name(int kind, int index)
{
    switch (kind) {
    case DOPUS_ROW_STATE:
        return index >= 0 && index < DOPUS_NX ? dopus_row_names_x[index] : 0;
    case DOPUS_ROW_CONTROL:
        return index >= 0 && index < DOPUS_NU ? dopus_row_names_u[index] : 0;
    case DOPUS_ROW_PATH:
        return index >= 0 && index < DOPUS_NG ? dopus_row_names_g[index] : 0;
    case DOPUS_ROW_TERMINAL:
        return index >= 0 && index < DOPUS_NR ? dopus_row_names_r[index] : 0;
    case DOPUS_ROW_TERMINAL_EQ:
        return index >= 0 && index < DOPUS_NE ? dopus_row_names_req[index] : 0;
    default:
        return 0;
    }
}

void dopus_get_parameters(const dopus_solver *s, dopus_real *p)
{
    int k, i;
    for (k = 0; k <= DOPUS_N; ++k) {
        for (i = 0; i < DOPUS_NP; ++i) {
            p[k * DOPUS_NP + i] = s->p[k][i];
        }
    }
}

void dopus_set_clock(dopus_solver *s, double (*clock_fn)(void *ctx), void *ctx)
{
    s->timer.clock = clock_fn ? clock_fn : dopus_timer_default_clock;
    s->timer.ctx = clock_fn ? ctx : 0;
}

int dopus_simulate(const dopus_real *x, const dopus_real *u, const dopus_real *p, dopus_real *x_next,
                   struct dopus_fun_work_s *work)
{
    dopus_real l = DOPUS_R(0.0), g[DOPUS_DIM(DOPUS_NG)], xs[DOPUS_NX], us[DOPUS_NU], xn[DOPUS_NX];
    if (dopus_eval_stage_eval(dopus_scaled_in(x, dopus_scale_x, DOPUS_NX, xs),
                              dopus_scaled_in(u, dopus_scale_u, DOPUS_NU, us), p ? p : dopus_p_default[0], xn,
                              &l, g, work) != 0) {
        return DOPUS_ERR_FUNCTION;
    }
    dopus_scaled_out(x_next, xn, dopus_scale_x, DOPUS_NX, DOPUS_NX);
    return dopus_lai_vec_finite(DOPUS_NX, x_next) ? DOPUS_OK : DOPUS_ERR_NONFINITE_VALUE;
}

/* ---- the modules (one translation unit; DOPUS_INTERNAL functions are static) --------- */

#include "dopus_timer.c"
#include "dopus_ring.c"
#include "dopus_reg.c"
#include "dopus_funcs.c"
#include "dopus_lm.c"
#include "dopus_health.c"
#include "dopus_kkt.c"
#include "dopus_globalise.c"
#include "dopus_qp.c" /* last: its short macros (N, NX, ...) stay inside it */
