/* The settings of the solver (robot_arm_solver.h, "Settings"): setters that check their
 * argument and return ROBOT_ARM_ERR_INVALID_ARGUMENT (nothing changed) or ROBOT_ARM_OK, getters, the
 * runtime parameters and the clock of the phase timings. A struct that was never set up gets
 * the generated defaults (robot_arm_defaults) on its first use here too.
 */
#include <limits.h>
#include <math.h>

#include "robot_arm_linalg.h"
#include "robot_arm_solver.h"
#include "robot_arm_solver_internal.h"

/* *field = v when lo <= v <= hi (ROBOT_ARM_OK), else ROBOT_ARM_ERR_INVALID_ARGUMENT and nothing
 * changes. */
static int robot_arm_set_int(robot_arm_solver *s, int *field, int v, int lo, int hi)
{
    robot_arm_ensure_setup(s);
    if (v < lo || v > hi) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_INVALID_ARGUMENT);
    }
    *field = v;
    return robot_arm_ret(s, ROBOT_ARM_OK);
}

int robot_arm_set_M(robot_arm_solver *s, int M)
{
    return robot_arm_set_int(s, &s->M, M, 0, ROBOT_ARM_N - 1);
}

int robot_arm_get_M(robot_arm_solver *s)
{
    robot_arm_ensure_setup(s);
    return s->M;
}

int robot_arm_set_mode(robot_arm_solver *s, int mode)
{
    return robot_arm_set_int(s, &s->mode, mode, ROBOT_ARM_MODE_RECEDING, ROBOT_ARM_MODE_FIXED);
}

int robot_arm_get_mode(robot_arm_solver *s)
{
    robot_arm_ensure_setup(s);
    return s->mode;
}

int robot_arm_set_hessian(robot_arm_solver *s, int hessian)
{
    /* Gauss-Newton needs a least-squares stage cost */
    return robot_arm_set_int(s, &s->hessian, hessian, ROBOT_ARM_HESSIAN_EXACT,
                         ROBOT_ARM_HAS_GN ? ROBOT_ARM_HESSIAN_GAUSS_NEWTON : ROBOT_ARM_HESSIAN_EXACT);
}

int robot_arm_get_hessian(robot_arm_solver *s)
{
    robot_arm_ensure_setup(s);
    return s->hessian;
}

int robot_arm_set_regularization(robot_arm_solver *s, int regularization, robot_arm_real eps)
{
    robot_arm_ensure_setup(s);
    if ((regularization != ROBOT_ARM_REG_NONE && regularization != ROBOT_ARM_REG_PROJECT &&
         regularization != ROBOT_ARM_REG_MIRROR) ||
        !isfinite(eps) || !(eps > ROBOT_ARM_R(0.0))) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_INVALID_ARGUMENT);
    }
    s->regularization = regularization;
    s->reg_eps = eps;
    return robot_arm_ret(s, ROBOT_ARM_OK);
}

int robot_arm_get_regularization(robot_arm_solver *s)
{
    robot_arm_ensure_setup(s);
    return s->regularization;
}

robot_arm_real robot_arm_get_reg_eps(robot_arm_solver *s)
{
    robot_arm_ensure_setup(s);
    return s->reg_eps;
}

int robot_arm_set_cost_hessian(robot_arm_solver *s, int fresh)
{
    return robot_arm_set_int(s, &s->cost_hessian, fresh, 0, 1);
}

int robot_arm_get_cost_hessian(robot_arm_solver *s)
{
    robot_arm_ensure_setup(s);
    return s->cost_hessian;
}

int robot_arm_set_levenberg_marquardt(robot_arm_solver *s, robot_arm_real lm)
{
    robot_arm_ensure_setup(s);
    if (!isfinite(lm) || !(lm >= ROBOT_ARM_R(0.0))) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_INVALID_ARGUMENT);
    }
    s->lm_auto = 0;
    s->lm = lm;
    return robot_arm_ret(s, ROBOT_ARM_OK);
}

int robot_arm_set_lm_auto(robot_arm_solver *s)
{
    robot_arm_ensure_setup(s);
    s->lm_auto = 1;
    s->lm = ROBOT_ARM_R(0.0);
    s->lm_kkt_prev = -ROBOT_ARM_R(1.0);
    if (s->initialized && s->qp_ready) {
        robot_arm_lm_start(s);
    }
    return robot_arm_ret(s, ROBOT_ARM_OK);
}

int robot_arm_get_lm_auto(robot_arm_solver *s)
{
    robot_arm_ensure_setup(s);
    return s->lm_auto;
}

robot_arm_real robot_arm_get_lm_scale(robot_arm_solver *s)
{
    robot_arm_ensure_setup(s);
    return s->lm_scale;
}

robot_arm_real robot_arm_get_levenberg_marquardt(robot_arm_solver *s)
{
    robot_arm_ensure_setup(s);
    return s->lm;
}

int robot_arm_set_qp_tol(robot_arm_solver *s, robot_arm_real tol)
{
    robot_arm_ensure_setup(s);
    if (!isfinite(tol) || !(tol > ROBOT_ARM_R(0.0)) || tol > ROBOT_ARM_QP_TOL_MAX) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_INVALID_ARGUMENT);
    }
    s->qp_settings.tol = tol;
    return robot_arm_ret(s, ROBOT_ARM_OK);
}

robot_arm_real robot_arm_get_qp_tol(robot_arm_solver *s)
{
    robot_arm_ensure_setup(s);
    return s->qp_settings.tol;
}

int robot_arm_set_qp_max_iter(robot_arm_solver *s, int max_iter)
{
    return robot_arm_set_int(s, &s->qp_settings.max_iter, max_iter, 1, INT_MAX);
}

int robot_arm_get_qp_max_iter(robot_arm_solver *s)
{
    robot_arm_ensure_setup(s);
    return s->qp_settings.max_iter;
}

int robot_arm_set_recovery(robot_arm_solver *s, int on, int max_failures)
{
    robot_arm_ensure_setup(s);
    if ((on != 0 && on != 1) || max_failures < 1) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_INVALID_ARGUMENT);
    }
    s->recovery = on;
    s->recovery_failures = max_failures;
    if (!on) {
        s->recover_pending = 0;
    }
    return robot_arm_ret(s, ROBOT_ARM_OK);
}

int robot_arm_get_recovery(robot_arm_solver *s)
{
    robot_arm_ensure_setup(s);
    return s->recovery;
}

int robot_arm_get_recovery_failures(robot_arm_solver *s)
{
    robot_arm_ensure_setup(s);
    return s->recovery_failures;
}

int robot_arm_set_qp_warm_start(robot_arm_solver *s, int on)
{
    return robot_arm_set_int(s, &s->qp_warm, on, 0, 1);
}

int robot_arm_get_qp_warm_start(robot_arm_solver *s)
{
    robot_arm_ensure_setup(s);
    return s->qp_warm;
}

int robot_arm_set_parameters(robot_arm_solver *s, const robot_arm_real *p)
{
    int k, i;
    robot_arm_ensure_setup(s);
    if (ROBOT_ARM_NP == 0) {
        return robot_arm_ret(s, ROBOT_ARM_OK);
    }
    if (p == 0) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_INVALID_ARGUMENT);
    }
    if (!robot_arm_lai_vec_finite((ROBOT_ARM_N + 1) * ROBOT_ARM_NP, p)) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_NONFINITE_INPUT);
    }
    for (k = 0; k <= ROBOT_ARM_N; ++k) {
        for (i = 0; i < ROBOT_ARM_NP; ++i) {
            s->p[k][i] = p[k * ROBOT_ARM_NP + i];
        }
    }
    return robot_arm_ret(s, ROBOT_ARM_OK);
}

int robot_arm_set_parameters_node(robot_arm_solver *s, int k, const robot_arm_real *pk)
{
    int i;
    robot_arm_ensure_setup(s);
    if (k < 0 || k > ROBOT_ARM_N) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_INVALID_ARGUMENT);
    }
    if (ROBOT_ARM_NP == 0) {
        return robot_arm_ret(s, ROBOT_ARM_OK);
    }
    if (pk == 0) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_INVALID_ARGUMENT);
    }
    if (!robot_arm_lai_vec_finite(ROBOT_ARM_NP, pk)) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_NONFINITE_INPUT);
    }
    for (i = 0; i < ROBOT_ARM_NP; ++i) {
        s->p[k][i] = pk[i];
    }
    return robot_arm_ret(s, ROBOT_ARM_OK);
}

void robot_arm_get_parameters(robot_arm_solver *s, robot_arm_real *p)
{
    int k, i;
    robot_arm_ensure_setup(s);
    for (k = 0; k <= ROBOT_ARM_N; ++k) {
        for (i = 0; i < ROBOT_ARM_NP; ++i) {
            p[k * ROBOT_ARM_NP + i] = s->p[k][i];
        }
    }
}

void robot_arm_set_clock(robot_arm_solver *s, double (*clock_fn)(void *ctx), void *ctx)
{
    robot_arm_ensure_setup(s);
    s->timer.clock = clock_fn ? clock_fn : robot_arm_timer_default_clock;
    s->timer.ctx = clock_fn ? ctx : 0;
}

int robot_arm_has_clock(const robot_arm_solver *s)
{
    if (s->timer.clock == 0) {
        return 0;
    }
    return s->timer.clock != robot_arm_timer_default_clock || robot_arm_timer_has_default_clock();
}

/* ---- anytime budget (docs/algorithm.md section 12) ------------------------------------ */

static int robot_arm_set_budget(robot_arm_solver *s, double budget, int unit)
{
    robot_arm_ensure_setup(s);
    if (!(budget >= 0.0) || !(budget < HUGE_VAL)) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_INVALID_ARGUMENT);
    }
    s->budget = budget;
    s->budget_unit = budget > 0.0 ? unit : ROBOT_ARM_BUDGET_OFF;
    return robot_arm_ret(s, ROBOT_ARM_OK);
}

int robot_arm_set_time_budget(robot_arm_solver *s, double seconds)
{
    robot_arm_ensure_setup(s);
    if (seconds > 0.0 && !robot_arm_has_clock(s)) {
        /* without a clock every time reads 0 and no budget could end */
        return robot_arm_ret(s, ROBOT_ARM_ERR_INVALID_ARGUMENT);
    }
    return robot_arm_set_budget(s, seconds, ROBOT_ARM_BUDGET_TIME);
}

int robot_arm_set_work_budget(robot_arm_solver *s, double units)
{
    return robot_arm_set_budget(s, units, ROBOT_ARM_BUDGET_WORK);
}

int robot_arm_get_budget_unit(const robot_arm_solver *s)
{
    return s->budget_unit;
}

double robot_arm_get_budget(const robot_arm_solver *s)
{
    return s->budget;
}

int robot_arm_set_anytime_tol(robot_arm_solver *s, robot_arm_real tol)
{
    robot_arm_ensure_setup(s);
    if (!(tol > ROBOT_ARM_R(0.0)) || !(tol < INFINITY)) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_INVALID_ARGUMENT);
    }
    s->anytime_tol = tol;
    return robot_arm_ret(s, ROBOT_ARM_OK);
}

robot_arm_real robot_arm_get_anytime_tol(const robot_arm_solver *s)
{
    return s->anytime_tol;
}

int robot_arm_set_M_adaptive(robot_arm_solver *s, int on, int M_min, int M_max, robot_arm_real eta)
{
    robot_arm_ensure_setup(s);
    if ((on != 0 && on != 1) || M_min < 0 || M_max < M_min || M_max > ROBOT_ARM_N - 1 || !(eta > ROBOT_ARM_R(0.0)) ||
        !(eta < INFINITY)) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_INVALID_ARGUMENT);
    }
    s->M_adaptive = on;
    s->M_min = M_min;
    s->M_max = M_max;
    s->M_eta = eta;
    return robot_arm_ret(s, ROBOT_ARM_OK);
}

int robot_arm_get_M_adaptive(const robot_arm_solver *s, int *M_min, int *M_max, robot_arm_real *eta)
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

int robot_arm_get_extra_iterations(const robot_arm_solver *s)
{
    return s->extra_iterations;
}

int robot_arm_get_instant_stages(const robot_arm_solver *s)
{
    return s->instant_stages;
}

double robot_arm_get_budget_used(const robot_arm_solver *s)
{
    return s->budget_used;
}

double robot_arm_get_work(const robot_arm_solver *s)
{
    return s->work;
}
