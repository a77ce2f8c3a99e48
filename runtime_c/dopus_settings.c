/* The settings of the solver (dopus_solver.h, "Settings"): setters that check their
 * argument and return DOPUS_ERR_INVALID_ARGUMENT (nothing changed) or DOPUS_OK, getters, the
 * runtime parameters and the clock of the phase timings. A struct that was never set up gets
 * the generated defaults (dopus_defaults) on its first use here too.
 */
#include <limits.h>
#include <math.h>

#include "dopus_linalg.h"
#include "dopus_solver.h"
#include "dopus_solver_internal.h"

/* *field = v when lo <= v <= hi (DOPUS_OK), else DOPUS_ERR_INVALID_ARGUMENT and nothing
 * changes. */
static int dopus_set_int(dopus_solver *s, int *field, int v, int lo, int hi)
{
    dopus_ensure_setup(s);
    if (v < lo || v > hi) {
        return dopus_ret(s, DOPUS_ERR_INVALID_ARGUMENT);
    }
    *field = v;
    return dopus_ret(s, DOPUS_OK);
}

int dopus_set_M(dopus_solver *s, int M)
{
    return dopus_set_int(s, &s->M, M, 0, DOPUS_N - 1);
}

int dopus_get_M(dopus_solver *s)
{
    dopus_ensure_setup(s);
    return s->M;
}

int dopus_set_mode(dopus_solver *s, int mode)
{
    return dopus_set_int(s, &s->mode, mode, DOPUS_MODE_RECEDING, DOPUS_MODE_FIXED);
}

int dopus_get_mode(dopus_solver *s)
{
    dopus_ensure_setup(s);
    return s->mode;
}

int dopus_set_hessian(dopus_solver *s, int hessian)
{
    /* Gauss-Newton needs a least-squares stage cost */
    return dopus_set_int(s, &s->hessian, hessian, DOPUS_HESSIAN_EXACT,
                         DOPUS_HAS_GN ? DOPUS_HESSIAN_GAUSS_NEWTON : DOPUS_HESSIAN_EXACT);
}

int dopus_get_hessian(dopus_solver *s)
{
    dopus_ensure_setup(s);
    return s->hessian;
}

int dopus_set_regularization(dopus_solver *s, int regularization, dopus_real eps)
{
    dopus_ensure_setup(s);
    if ((regularization != DOPUS_REG_NONE && regularization != DOPUS_REG_PROJECT &&
         regularization != DOPUS_REG_MIRROR) ||
        !isfinite(eps) || !(eps > DOPUS_R(0.0))) {
        return dopus_ret(s, DOPUS_ERR_INVALID_ARGUMENT);
    }
    s->regularization = regularization;
    s->reg_eps = eps;
    return dopus_ret(s, DOPUS_OK);
}

int dopus_get_regularization(dopus_solver *s)
{
    dopus_ensure_setup(s);
    return s->regularization;
}

dopus_real dopus_get_reg_eps(dopus_solver *s)
{
    dopus_ensure_setup(s);
    return s->reg_eps;
}

int dopus_set_cost_hessian(dopus_solver *s, int fresh)
{
    return dopus_set_int(s, &s->cost_hessian, fresh, 0, 1);
}

int dopus_get_cost_hessian(dopus_solver *s)
{
    dopus_ensure_setup(s);
    return s->cost_hessian;
}

int dopus_set_levenberg_marquardt(dopus_solver *s, dopus_real lm)
{
    dopus_ensure_setup(s);
    if (!isfinite(lm) || !(lm >= DOPUS_R(0.0))) {
        return dopus_ret(s, DOPUS_ERR_INVALID_ARGUMENT);
    }
    s->lm_auto = 0;
    s->lm = lm;
    return dopus_ret(s, DOPUS_OK);
}

int dopus_set_lm_auto(dopus_solver *s)
{
    dopus_ensure_setup(s);
    s->lm_auto = 1;
    s->lm = DOPUS_R(0.0);
    s->lm_kkt_prev = -DOPUS_R(1.0);
    if (s->initialized && s->qp_ready) {
        dopus_lm_start(s);
    }
    return dopus_ret(s, DOPUS_OK);
}

int dopus_get_lm_auto(dopus_solver *s)
{
    dopus_ensure_setup(s);
    return s->lm_auto;
}

dopus_real dopus_get_lm_scale(dopus_solver *s)
{
    dopus_ensure_setup(s);
    return s->lm_scale;
}

dopus_real dopus_get_levenberg_marquardt(dopus_solver *s)
{
    dopus_ensure_setup(s);
    return s->lm;
}

int dopus_set_qp_tol(dopus_solver *s, dopus_real tol)
{
    dopus_ensure_setup(s);
    if (!isfinite(tol) || !(tol > DOPUS_R(0.0)) || tol > DOPUS_QP_TOL_MAX) {
        return dopus_ret(s, DOPUS_ERR_INVALID_ARGUMENT);
    }
    s->qp_settings.tol = tol;
    return dopus_ret(s, DOPUS_OK);
}

dopus_real dopus_get_qp_tol(dopus_solver *s)
{
    dopus_ensure_setup(s);
    return s->qp_settings.tol;
}

int dopus_set_qp_max_iter(dopus_solver *s, int max_iter)
{
    return dopus_set_int(s, &s->qp_settings.max_iter, max_iter, 1, INT_MAX);
}

int dopus_get_qp_max_iter(dopus_solver *s)
{
    dopus_ensure_setup(s);
    return s->qp_settings.max_iter;
}

int dopus_set_recovery(dopus_solver *s, int on, int max_failures)
{
    dopus_ensure_setup(s);
    if ((on != 0 && on != 1) || max_failures < 1) {
        return dopus_ret(s, DOPUS_ERR_INVALID_ARGUMENT);
    }
    s->recovery = on;
    s->recovery_failures = max_failures;
    if (!on) {
        s->recover_pending = 0;
    }
    return dopus_ret(s, DOPUS_OK);
}

int dopus_get_recovery(dopus_solver *s)
{
    dopus_ensure_setup(s);
    return s->recovery;
}

int dopus_get_recovery_failures(dopus_solver *s)
{
    dopus_ensure_setup(s);
    return s->recovery_failures;
}

int dopus_set_qp_warm_start(dopus_solver *s, int on)
{
    return dopus_set_int(s, &s->qp_warm, on, 0, 1);
}

int dopus_get_qp_warm_start(dopus_solver *s)
{
    dopus_ensure_setup(s);
    return s->qp_warm;
}

int dopus_set_parameters(dopus_solver *s, const dopus_real *p)
{
    int k, i;
    dopus_ensure_setup(s);
    if (DOPUS_NP == 0) {
        return dopus_ret(s, DOPUS_OK);
    }
    if (p == 0) {
        return dopus_ret(s, DOPUS_ERR_INVALID_ARGUMENT);
    }
    if (!dopus_lai_vec_finite((DOPUS_N + 1) * DOPUS_NP, p)) {
        return dopus_ret(s, DOPUS_ERR_NONFINITE_INPUT);
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
    int i;
    dopus_ensure_setup(s);
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
    for (i = 0; i < DOPUS_NP; ++i) {
        s->p[k][i] = pk[i];
    }
    return dopus_ret(s, DOPUS_OK);
}

void dopus_get_parameters(dopus_solver *s, dopus_real *p)
{
    int k, i;
    dopus_ensure_setup(s);
    for (k = 0; k <= DOPUS_N; ++k) {
        for (i = 0; i < DOPUS_NP; ++i) {
            p[k * DOPUS_NP + i] = s->p[k][i];
        }
    }
}

void dopus_set_clock(dopus_solver *s, double (*clock_fn)(void *ctx), void *ctx)
{
    dopus_ensure_setup(s);
    s->timer.clock = clock_fn ? clock_fn : dopus_timer_default_clock;
    s->timer.ctx = clock_fn ? ctx : 0;
}

int dopus_has_clock(const dopus_solver *s)
{
    if (s->timer.clock == 0) {
        return 0;
    }
    return s->timer.clock != dopus_timer_default_clock || dopus_timer_has_default_clock();
}

/* ---- anytime budget (docs/algorithm.md section 12) ------------------------------------ */

static int dopus_set_budget(dopus_solver *s, double budget, int unit)
{
    dopus_ensure_setup(s);
    if (!(budget >= 0.0) || !(budget < HUGE_VAL)) {
        return dopus_ret(s, DOPUS_ERR_INVALID_ARGUMENT);
    }
    s->budget = budget;
    s->budget_unit = budget > 0.0 ? unit : DOPUS_BUDGET_OFF;
    return dopus_ret(s, DOPUS_OK);
}

int dopus_set_time_budget(dopus_solver *s, double seconds)
{
    dopus_ensure_setup(s);
    if (seconds > 0.0 && !dopus_has_clock(s)) {
        /* without a clock every time reads 0 and no budget could end */
        return dopus_ret(s, DOPUS_ERR_INVALID_ARGUMENT);
    }
    return dopus_set_budget(s, seconds, DOPUS_BUDGET_TIME);
}

int dopus_set_work_budget(dopus_solver *s, double units)
{
    return dopus_set_budget(s, units, DOPUS_BUDGET_WORK);
}

int dopus_get_budget_unit(const dopus_solver *s)
{
    return s->budget_unit;
}

double dopus_get_budget(const dopus_solver *s)
{
    return s->budget;
}

int dopus_set_anytime_tol(dopus_solver *s, dopus_real tol)
{
    dopus_ensure_setup(s);
    if (!(tol > DOPUS_R(0.0)) || !(tol < INFINITY)) {
        return dopus_ret(s, DOPUS_ERR_INVALID_ARGUMENT);
    }
    s->anytime_tol = tol;
    return dopus_ret(s, DOPUS_OK);
}

dopus_real dopus_get_anytime_tol(const dopus_solver *s)
{
    return s->anytime_tol;
}

int dopus_set_M_adaptive(dopus_solver *s, int on, int M_min, int M_max, dopus_real eta)
{
    dopus_ensure_setup(s);
    if ((on != 0 && on != 1) || M_min < 0 || M_max < M_min || M_max > DOPUS_N - 1 || !(eta > DOPUS_R(0.0)) ||
        !(eta < INFINITY)) {
        return dopus_ret(s, DOPUS_ERR_INVALID_ARGUMENT);
    }
    s->M_adaptive = on;
    s->M_min = M_min;
    s->M_max = M_max;
    s->M_eta = eta;
    return dopus_ret(s, DOPUS_OK);
}

int dopus_get_M_adaptive(const dopus_solver *s, int *M_min, int *M_max, dopus_real *eta)
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

int dopus_get_extra_iterations(const dopus_solver *s)
{
    return s->extra_iterations;
}

int dopus_get_instant_stages(const dopus_solver *s)
{
    return s->instant_stages;
}

double dopus_get_budget_used(const dopus_solver *s)
{
    return s->budget_used;
}

double dopus_get_work(const dopus_solver *s)
{
    return s->work;
}
