/* The settings of the solver (unicycle_solver.h, "Settings"): setters that check their
 * argument and return UNICYCLE_ERR_INVALID_ARGUMENT (nothing changed) or UNICYCLE_OK, getters, the
 * runtime parameters and the clock of the phase timings. A struct that was never set up gets
 * the generated defaults (unicycle_defaults) on its first use here too.
 */
#include <limits.h>
#include <math.h>

#include "unicycle_linalg.h"
#include "unicycle_solver.h"
#include "unicycle_solver_internal.h"

/* *field = v when lo <= v <= hi (UNICYCLE_OK), else UNICYCLE_ERR_INVALID_ARGUMENT and nothing
 * changes. */
static int unicycle_set_int(unicycle_solver *s, int *field, int v, int lo, int hi)
{
    unicycle_ensure_setup(s);
    if (v < lo || v > hi) {
        return unicycle_ret(s, UNICYCLE_ERR_INVALID_ARGUMENT);
    }
    *field = v;
    return unicycle_ret(s, UNICYCLE_OK);
}

int unicycle_set_M(unicycle_solver *s, int M)
{
    return unicycle_set_int(s, &s->M, M, 0, UNICYCLE_N - 1);
}

int unicycle_get_M(unicycle_solver *s)
{
    unicycle_ensure_setup(s);
    return s->M;
}

int unicycle_set_mode(unicycle_solver *s, int mode)
{
    return unicycle_set_int(s, &s->mode, mode, UNICYCLE_MODE_RECEDING, UNICYCLE_MODE_FIXED);
}

int unicycle_get_mode(unicycle_solver *s)
{
    unicycle_ensure_setup(s);
    return s->mode;
}

int unicycle_set_hessian(unicycle_solver *s, int hessian)
{
    /* Gauss-Newton needs a least-squares stage cost */
    return unicycle_set_int(s, &s->hessian, hessian, UNICYCLE_HESSIAN_EXACT,
                         UNICYCLE_HAS_GN ? UNICYCLE_HESSIAN_GAUSS_NEWTON : UNICYCLE_HESSIAN_EXACT);
}

int unicycle_get_hessian(unicycle_solver *s)
{
    unicycle_ensure_setup(s);
    return s->hessian;
}

int unicycle_set_regularization(unicycle_solver *s, int regularization, unicycle_real eps)
{
    unicycle_ensure_setup(s);
    if ((regularization != UNICYCLE_REG_NONE && regularization != UNICYCLE_REG_PROJECT &&
         regularization != UNICYCLE_REG_MIRROR) ||
        !isfinite(eps) || !(eps > UNICYCLE_R(0.0))) {
        return unicycle_ret(s, UNICYCLE_ERR_INVALID_ARGUMENT);
    }
    s->regularization = regularization;
    s->reg_eps = eps;
    return unicycle_ret(s, UNICYCLE_OK);
}

int unicycle_get_regularization(unicycle_solver *s)
{
    unicycle_ensure_setup(s);
    return s->regularization;
}

unicycle_real unicycle_get_reg_eps(unicycle_solver *s)
{
    unicycle_ensure_setup(s);
    return s->reg_eps;
}

int unicycle_set_cost_hessian(unicycle_solver *s, int fresh)
{
    return unicycle_set_int(s, &s->cost_hessian, fresh, 0, 1);
}

int unicycle_get_cost_hessian(unicycle_solver *s)
{
    unicycle_ensure_setup(s);
    return s->cost_hessian;
}

int unicycle_set_levenberg_marquardt(unicycle_solver *s, unicycle_real lm)
{
    unicycle_ensure_setup(s);
    if (!isfinite(lm) || !(lm >= UNICYCLE_R(0.0))) {
        return unicycle_ret(s, UNICYCLE_ERR_INVALID_ARGUMENT);
    }
    s->lm_auto = 0;
    s->lm = lm;
    return unicycle_ret(s, UNICYCLE_OK);
}

int unicycle_set_lm_auto(unicycle_solver *s)
{
    unicycle_ensure_setup(s);
    s->lm_auto = 1;
    s->lm = UNICYCLE_R(0.0);
    s->lm_kkt_prev = -UNICYCLE_R(1.0);
    if (s->initialized && s->qp_ready) {
        unicycle_lm_start(s);
    }
    return unicycle_ret(s, UNICYCLE_OK);
}

int unicycle_get_lm_auto(unicycle_solver *s)
{
    unicycle_ensure_setup(s);
    return s->lm_auto;
}

unicycle_real unicycle_get_lm_scale(unicycle_solver *s)
{
    unicycle_ensure_setup(s);
    return s->lm_scale;
}

unicycle_real unicycle_get_levenberg_marquardt(unicycle_solver *s)
{
    unicycle_ensure_setup(s);
    return s->lm;
}

int unicycle_set_qp_tol(unicycle_solver *s, unicycle_real tol)
{
    unicycle_ensure_setup(s);
    if (!isfinite(tol) || !(tol > UNICYCLE_R(0.0)) || tol > UNICYCLE_QP_TOL_MAX) {
        return unicycle_ret(s, UNICYCLE_ERR_INVALID_ARGUMENT);
    }
    s->qp_settings.tol = tol;
    return unicycle_ret(s, UNICYCLE_OK);
}

unicycle_real unicycle_get_qp_tol(unicycle_solver *s)
{
    unicycle_ensure_setup(s);
    return s->qp_settings.tol;
}

int unicycle_set_qp_max_iter(unicycle_solver *s, int max_iter)
{
    return unicycle_set_int(s, &s->qp_settings.max_iter, max_iter, 1, INT_MAX);
}

int unicycle_get_qp_max_iter(unicycle_solver *s)
{
    unicycle_ensure_setup(s);
    return s->qp_settings.max_iter;
}

int unicycle_set_recovery(unicycle_solver *s, int on, int max_failures)
{
    unicycle_ensure_setup(s);
    if ((on != 0 && on != 1) || max_failures < 1) {
        return unicycle_ret(s, UNICYCLE_ERR_INVALID_ARGUMENT);
    }
    s->recovery = on;
    s->recovery_failures = max_failures;
    if (!on) {
        s->recover_pending = 0;
    }
    return unicycle_ret(s, UNICYCLE_OK);
}

int unicycle_get_recovery(unicycle_solver *s)
{
    unicycle_ensure_setup(s);
    return s->recovery;
}

int unicycle_get_recovery_failures(unicycle_solver *s)
{
    unicycle_ensure_setup(s);
    return s->recovery_failures;
}

int unicycle_set_qp_warm_start(unicycle_solver *s, int on)
{
    return unicycle_set_int(s, &s->qp_warm, on, 0, 1);
}

int unicycle_get_qp_warm_start(unicycle_solver *s)
{
    unicycle_ensure_setup(s);
    return s->qp_warm;
}

int unicycle_set_parameters(unicycle_solver *s, const unicycle_real *p)
{
    int k, i;
    unicycle_ensure_setup(s);
    if (UNICYCLE_NP == 0) {
        return unicycle_ret(s, UNICYCLE_OK);
    }
    if (p == 0) {
        return unicycle_ret(s, UNICYCLE_ERR_INVALID_ARGUMENT);
    }
    if (!unicycle_lai_vec_finite((UNICYCLE_N + 1) * UNICYCLE_NP, p)) {
        return unicycle_ret(s, UNICYCLE_ERR_NONFINITE_INPUT);
    }
    for (k = 0; k <= UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NP; ++i) {
            s->p[k][i] = p[k * UNICYCLE_NP + i];
        }
    }
    return unicycle_ret(s, UNICYCLE_OK);
}

int unicycle_set_parameters_node(unicycle_solver *s, int k, const unicycle_real *pk)
{
    int i;
    unicycle_ensure_setup(s);
    if (k < 0 || k > UNICYCLE_N) {
        return unicycle_ret(s, UNICYCLE_ERR_INVALID_ARGUMENT);
    }
    if (UNICYCLE_NP == 0) {
        return unicycle_ret(s, UNICYCLE_OK);
    }
    if (pk == 0) {
        return unicycle_ret(s, UNICYCLE_ERR_INVALID_ARGUMENT);
    }
    if (!unicycle_lai_vec_finite(UNICYCLE_NP, pk)) {
        return unicycle_ret(s, UNICYCLE_ERR_NONFINITE_INPUT);
    }
    for (i = 0; i < UNICYCLE_NP; ++i) {
        s->p[k][i] = pk[i];
    }
    return unicycle_ret(s, UNICYCLE_OK);
}

void unicycle_get_parameters(unicycle_solver *s, unicycle_real *p)
{
    int k, i;
    unicycle_ensure_setup(s);
    for (k = 0; k <= UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NP; ++i) {
            p[k * UNICYCLE_NP + i] = s->p[k][i];
        }
    }
}

void unicycle_set_clock(unicycle_solver *s, double (*clock_fn)(void *ctx), void *ctx)
{
    unicycle_ensure_setup(s);
    s->timer.clock = clock_fn ? clock_fn : unicycle_timer_default_clock;
    s->timer.ctx = clock_fn ? ctx : 0;
}

int unicycle_has_clock(const unicycle_solver *s)
{
    if (s->timer.clock == 0) {
        return 0;
    }
    return s->timer.clock != unicycle_timer_default_clock || unicycle_timer_has_default_clock();
}

/* ---- anytime budget (docs/algorithm.md section 12) ------------------------------------ */

static int unicycle_set_budget(unicycle_solver *s, double budget, int unit)
{
    unicycle_ensure_setup(s);
    if (!(budget >= 0.0) || !(budget < HUGE_VAL)) {
        return unicycle_ret(s, UNICYCLE_ERR_INVALID_ARGUMENT);
    }
    s->budget = budget;
    s->budget_unit = budget > 0.0 ? unit : UNICYCLE_BUDGET_OFF;
    return unicycle_ret(s, UNICYCLE_OK);
}

int unicycle_set_time_budget(unicycle_solver *s, double seconds)
{
    unicycle_ensure_setup(s);
    if (seconds > 0.0 && !unicycle_has_clock(s)) {
        /* without a clock every time reads 0 and no budget could end */
        return unicycle_ret(s, UNICYCLE_ERR_INVALID_ARGUMENT);
    }
    return unicycle_set_budget(s, seconds, UNICYCLE_BUDGET_TIME);
}

int unicycle_set_work_budget(unicycle_solver *s, double units)
{
    return unicycle_set_budget(s, units, UNICYCLE_BUDGET_WORK);
}

int unicycle_get_budget_unit(const unicycle_solver *s)
{
    return s->budget_unit;
}

double unicycle_get_budget(const unicycle_solver *s)
{
    return s->budget;
}

int unicycle_set_anytime_tol(unicycle_solver *s, unicycle_real tol)
{
    unicycle_ensure_setup(s);
    if (!(tol > UNICYCLE_R(0.0)) || !(tol < INFINITY)) {
        return unicycle_ret(s, UNICYCLE_ERR_INVALID_ARGUMENT);
    }
    s->anytime_tol = tol;
    return unicycle_ret(s, UNICYCLE_OK);
}

unicycle_real unicycle_get_anytime_tol(const unicycle_solver *s)
{
    return s->anytime_tol;
}

int unicycle_set_M_adaptive(unicycle_solver *s, int on, int M_min, int M_max, unicycle_real eta)
{
    unicycle_ensure_setup(s);
    if ((on != 0 && on != 1) || M_min < 0 || M_max < M_min || M_max > UNICYCLE_N - 1 || !(eta > UNICYCLE_R(0.0)) ||
        !(eta < INFINITY)) {
        return unicycle_ret(s, UNICYCLE_ERR_INVALID_ARGUMENT);
    }
    s->M_adaptive = on;
    s->M_min = M_min;
    s->M_max = M_max;
    s->M_eta = eta;
    return unicycle_ret(s, UNICYCLE_OK);
}

int unicycle_get_M_adaptive(const unicycle_solver *s, int *M_min, int *M_max, unicycle_real *eta)
{
    if (M_min) {
        *M_min = s->M_min;
    }
    if (M_max) {
        *M_max = s->M_max;
    }
    if (eta) {
        *eta = s->M_eta;
    }
    return s->M_adaptive;
}

int unicycle_get_extra_iterations(const unicycle_solver *s)
{
    return s->extra_iterations;
}

int unicycle_get_instant_stages(const unicycle_solver *s)
{
    return s->instant_stages;
}

double unicycle_get_budget_used(const unicycle_solver *s)
{
    return s->budget_used;
}

double unicycle_get_work(const unicycle_solver *s)
{
    return s->work;
}
