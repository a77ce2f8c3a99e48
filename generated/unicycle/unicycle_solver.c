/* The DOPUS real-time iteration (docs/algorithm.md section 4; paper Algorithm 1).
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
 */
#include <math.h>

#include "unicycle_kkt.h"
#include "unicycle_linalg.h"
#include "unicycle_problem.h"
#include "unicycle_solver.h"
#include "unicycle_solver_internal.h"

#define UNICYCLE_MAGIC 0x444f5055 /* "DOPU" */
#define UNICYCLE_DEFAULT_QP_TOL UNICYCLE_PREC(1e-10, 1e-5)

/* ---- small helpers ------------------------------------------------------------------ */

static void unicycle_copy(unicycle_real *dst, const unicycle_real *src, int n)
{
    int i;
    for (i = 0; i < n; ++i) {
        dst[i] = src[i];
    }
}

static void unicycle_zero(int n, unicycle_real *dst)
{
    int i;
    for (i = 0; i < n; ++i) {
        dst[i] = UNICYCLE_R(0.0);
    }
}

void unicycle_ensure_setup(unicycle_solver *s)
{
    if (s->magic != UNICYCLE_MAGIC) {
        unicycle_defaults(s);
    }
}

void unicycle_clear_x0_multiplier(unicycle_solver *s)
{
    int i;
    for (i = 0; i < UNICYCLE_NX; ++i) {
        s->mu_b[0][i] = UNICYCLE_R(0.0);
    }
}

int unicycle_ret(unicycle_solver *s, int status)
{
    s->status = status;
    return status;
}

/* ---- generic information ------------------------------------------------------------ */

size_t unicycle_solver_sizeof(void)
{
    return sizeof(unicycle_solver);
}

void unicycle_get_dims(unicycle_dims *dims)
{
    dims->N = UNICYCLE_N;
    dims->nx = UNICYCLE_NX;
    dims->nu = UNICYCLE_NU;
    dims->nw = UNICYCLE_NW;
    dims->np = UNICYCLE_NP;
    dims->ng = UNICYCLE_NG;
    dims->nr = UNICYCLE_NR;
    dims->ne = UNICYCLE_NE;
    dims->has_gn = UNICYCLE_HAS_GN;
    dims->has_nominal = UNICYCLE_HAS_NOMINAL;
}

const char *unicycle_name(void)
{
    return UNICYCLE_NAME;
}

const char *unicycle_status_string(int status)
{
    switch (status) {
    case UNICYCLE_OK:
        return "ok";
    case UNICYCLE_ERR_QP:
        return "the QP was not solved (no step taken)";
    case UNICYCLE_ERR_NONFINITE_INPUT:
        return "NaN or Inf in an input array";
    case UNICYCLE_ERR_NONFINITE_VALUE:
        return "a generated function returned NaN or Inf";
    case UNICYCLE_ERR_FUNCTION:
        return "a generated function reported failure";
    case UNICYCLE_ERR_INVALID_ARGUMENT:
        return "invalid argument";
    case UNICYCLE_ERR_NOT_INITIALIZED:
        return "the solver is not initialised (call init first)";
    case UNICYCLE_ERR_NOT_PREPARED:
        return "no prepared QP (call prepare after each feedback)";
    case UNICYCLE_ERR_NO_NOMINAL:
        return "the solver was generated without a nominal guess";
    case UNICYCLE_ERR_REGULARIZATION:
        return "the eigen-decomposition of a Hessian block did not converge";
    case UNICYCLE_ERR_DIVERGED:
        return "the step diverged (outside the problem's scale; no step, fallback control returned)";
    case UNICYCLE_ERR_ALREADY_PREPARED:
        return "already prepared (call feedback before the next prepare)";
    default:
        return "unknown status";
    }
}

/* ---- safety: scales, clipping, health (algorithm.md section 9) -------------------- */

static unicycle_real unicycle_absmax(unicycle_real a, unicycle_real b)
{
    unicycle_real fa = unicycle_fabs(a);
    return isfinite(a) && fa > b ? fa : b;
}

/* The scale of each state and control: the largest magnitude among its finite bounds, the
 * OCP file's guess, the default x0 and 1. */
static void unicycle_compute_scales(unicycle_solver *s)
{
    int k, i;
    for (i = 0; i < UNICYCLE_NX; ++i) {
        unicycle_real v = UNICYCLE_R(1.0);
        v = unicycle_absmax(unicycle_lbx[i], v);
        v = unicycle_absmax(unicycle_ubx[i], v);
        v = unicycle_absmax(unicycle_x0_default[i], v);
        for (k = 0; k <= UNICYCLE_N; ++k) {
            v = unicycle_absmax(unicycle_guess_x[k][i], v);
        }
        s->scale_x[i] = v;
    }
    for (i = 0; i < UNICYCLE_NU; ++i) {
        unicycle_real v = UNICYCLE_R(1.0);
        v = unicycle_absmax(unicycle_lbu[i], v);
        v = unicycle_absmax(unicycle_ubu[i], v);
        for (k = 0; k < UNICYCLE_N; ++k) {
            v = unicycle_absmax(unicycle_guess_u[k][i], v);
        }
        s->scale_u[i] = v;
    }
}

/* Health state after init: no failure, the plan is the iterate's controls. */
static void unicycle_reset_health(unicycle_solver *s)
{
    int k, i;
    s->n_failed = 0;
    s->recover_pending = 0;
    s->flags = 0;
    s->n_recoveries = 0;
    s->recovering = 0;
    s->xhat_fresh = 1;
    s->plan_age = 0;
    for (k = 0; k < UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NU; ++i) {
            s->plan_u[k][i] = s->initialized ? s->u[k][i] : unicycle_guess_u[k][i];
        }
    }
    for (i = 0; i < UNICYCLE_NU; ++i) {
        s->u0_out[i] = s->plan_u[0][i];
    }
    s->kkt_proxy = UNICYCLE_R(0.0);
    s->kkt_proxy_ref = UNICYCLE_R(0.0);
}

/* u clipped to the control bounds into out (NaN: 0 clipped to the bounds); returns 1 when
 * an entry changed. */
static int unicycle_clip_u(const unicycle_real *u, unicycle_real *out)
{
    int i, clipped = 0;
    for (i = 0; i < UNICYCLE_NU; ++i) {
        unicycle_real v = isnan(u[i]) ? UNICYCLE_R(0.0) : u[i];
        if (v < unicycle_lbu[i]) {
            v = unicycle_lbu[i];
        }
        if (v > unicycle_ubu[i]) {
            v = unicycle_ubu[i];
        }
        if (!(v == u[i])) {
            clipped = 1;
        }
        out[i] = v;
    }
    return clipped;
}

/* The box test of a primal point (x (N+1) x nx, u N x nu, row-major) given as the iterate
 * plus an optional step: every entry finite and |v_i| <= BOX scale_i + |xhat0_i| (states),
 * BOX scale_i (controls). Returns 1 when it passes. */
static int unicycle_box_ok(const unicycle_solver *s, const unicycle_real *x, const unicycle_real *dx, int dx_stride,
                        const unicycle_real *u, const unicycle_real *du, int du_stride)
{
    int k, i;
    for (k = 0; k <= UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NX; ++i) {
            unicycle_real v = x[k * UNICYCLE_NX + i] + (dx ? dx[k * dx_stride + i] : UNICYCLE_R(0.0));
            if (!(unicycle_fabs(v) <= UNICYCLE_DIVERGENCE_BOX * s->scale_x[i] + unicycle_fabs(s->xhat0[i]))) {
                return 0;
            }
        }
    }
    for (k = 0; k < UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NU; ++i) {
            unicycle_real v = u[k * UNICYCLE_NU + i] + (du ? du[k * du_stride + i] : UNICYCLE_R(0.0));
            if (!(unicycle_fabs(v) <= UNICYCLE_DIVERGENCE_BOX * s->scale_u[i])) {
                return 0;
            }
        }
    }
    return 1;
}

/* The fallback control of a failed feedback: the next control of the last good plan. */
static void unicycle_fallback_u0(unicycle_solver *s, unicycle_real *u0)
{
    int j = s->mode == UNICYCLE_MODE_RECEDING ? s->plan_age : 0;
    j = j > UNICYCLE_N - 1 ? UNICYCLE_N - 1 : j;
    if (unicycle_clip_u(s->plan_u[j], s->u0_out)) {
        s->flags |= UNICYCLE_FLAG_U0_CLIPPED;
    }
    s->flags |= UNICYCLE_FLAG_FALLBACK;
    if (u0) {
        unicycle_copy(u0, s->u0_out, UNICYCLE_NU);
    }
}

/* A failed feedback: count it, schedule the recovery after K of them, return the fallback. */
static void unicycle_lm_feedback(unicycle_solver *s, int status);

static int unicycle_feedback_failed(unicycle_solver *s, unicycle_real *u0, int status)
{
    unicycle_lm_feedback(s, status);
    s->n_failed += 1;
    if (s->recovery && s->mode == UNICYCLE_MODE_RECEDING && s->n_failed >= s->recovery_failures) {
        s->recover_pending = 1;
    }
    if (status == UNICYCLE_ERR_DIVERGED) {
        s->flags |= UNICYCLE_FLAG_DIVERGED;
    }
    unicycle_fallback_u0(s, u0);
    return unicycle_ret(s, status);
}

/* Divergence measure at the current point from the F values in the slots and the terminal
 * node (after init or a prepare): max of |F_w,k + [lam_k; 0]|, |gL_N + mu_bN + lam_N|,
 * |phi_k - x_{k+1}|, |r_eq| (inf-norms). */
static unicycle_real unicycle_kkt_proxy_eval(const unicycle_solver *s)
{
    unicycle_real m = UNICYCLE_R(0.0), v;
    int k, i;
    for (k = 0; k < UNICYCLE_N; ++k) {
        const unicycle_stage_slot *slot = unicycle_ring_stage_const(&s->ring, k);
        for (i = 0; i < UNICYCLE_NW; ++i) {
            v = unicycle_fabs(slot->F_w[i] + (i < UNICYCLE_NX ? s->lam[k][i] : UNICYCLE_R(0.0)));
            m = (v > m || isnan(v)) ? v : m;
        }
        for (i = 0; i < UNICYCLE_NX; ++i) {
            v = unicycle_fabs(slot->phi[i] - s->x[k + 1][i]);
            m = (v > m || isnan(v)) ? v : m;
        }
    }
    for (i = 0; i < UNICYCLE_NX; ++i) {
        v = unicycle_fabs(s->gL_N[i] + s->mu_bN[i] + s->lam[UNICYCLE_N][i]);
        m = (v > m || isnan(v)) ? v : m;
    }
    for (i = 0; i < UNICYCLE_NE; ++i) {
        v = unicycle_fabs(s->r_eq[i]);
        m = (v > m || isnan(v)) ? v : m;
    }
    return m;
}

/* The divergence test of the prepared iterate: box, finite multipliers, KKT proxy bound. */
static int unicycle_iterate_diverged(unicycle_solver *s)
{
    unicycle_real ref = s->kkt_proxy_ref > UNICYCLE_R(1.0) ? s->kkt_proxy_ref : UNICYCLE_R(1.0);
    if (!unicycle_box_ok(s, &s->x[0][0], 0, 0, &s->u[0][0], 0, 0)) {
        return 1;
    }
    if (!unicycle_lai_vec_finite((UNICYCLE_N + 1) * UNICYCLE_NX, &s->lam[0][0]) ||
        !unicycle_lai_vec_finite(UNICYCLE_N * UNICYCLE_NW, &s->mu_b[0][0]) ||
        !unicycle_lai_vec_finite(UNICYCLE_NX, s->mu_bN)) {
        return 1;
    }
    return !(s->kkt_proxy <= UNICYCLE_DIVERGENCE_KKT * ref);
}

/* ---- automatic Levenberg-Marquardt term (algorithm.md section 10) ------------------- */

/* The Hessian scale h: the largest |diagonal entry| of the QP's stage and terminal blocks. */
static unicycle_real unicycle_lm_hessian_scale(const unicycle_solver *s)
{
    unicycle_real h = UNICYCLE_REAL_TINY, v;
    int k, i;
    for (k = 0; k < UNICYCLE_N; ++k) {
        const unicycle_stage_slot *slot = unicycle_ring_stage_const(&s->ring, k);
        for (i = 0; i < UNICYCLE_NW; ++i) {
            v = unicycle_fabs(slot->Ht[i + i * UNICYCLE_NW]);
            h = v > h ? v : h;
        }
    }
    for (i = 0; i < UNICYCLE_NX; ++i) {
        v = unicycle_fabs(s->A_N[i + i * UNICYCLE_NX]);
        h = v > h ? v : h;
    }
    return h;
}

/* 1 when the QP with the term lm is strictly convex on the dynamics: the Riccati recursion
 * of its Hessian blocks (lower triangles read; inequalities and terminal constraints left
 * out) has control pivots above UNICYCLE_LM_PIVOT_REL h. */
static int unicycle_lm_convex(unicycle_solver *s, unicycle_real lm)
{
    const unicycle_real tol = UNICYCLE_LM_PIVOT_REL * s->lm_scale;
    unicycle_real *P = s->mem.ev.lm_P, *PA = s->mem.ev.lm_PA, *Z = s->mem.ev.lm_G;
    unicycle_real v;
    int k, i, j, l;
    for (j = 0; j < UNICYCLE_NX; ++j) {
        for (i = 0; i < UNICYCLE_NX; ++i) {
            P[i + j * UNICYCLE_NX] =
                (i >= j ? s->A_N[i + j * UNICYCLE_NX] : s->A_N[j + i * UNICYCLE_NX]) + (i == j ? lm : UNICYCLE_R(0.0));
        }
    }
    for (k = UNICYCLE_N - 1; k >= 0; --k) {
        const unicycle_stage_slot *slot = unicycle_ring_stage_const(&s->ring, k);
        /* PA = P Phi (nx x nw); Z = H + lm I + Phi' P Phi (nw x nw) */
        for (j = 0; j < UNICYCLE_NW; ++j) {
            for (i = 0; i < UNICYCLE_NX; ++i) {
                v = UNICYCLE_R(0.0);
                for (l = 0; l < UNICYCLE_NX; ++l) {
                    v += P[i + l * UNICYCLE_NX] * slot->Phit[l + j * UNICYCLE_NX];
                }
                PA[i + j * UNICYCLE_NX] = v;
            }
        }
        for (j = 0; j < UNICYCLE_NW; ++j) {
            for (i = 0; i < UNICYCLE_NW; ++i) {
                v = (i >= j ? slot->Ht[i + j * UNICYCLE_NW] : slot->Ht[j + i * UNICYCLE_NW]) +
                    (i == j ? lm : UNICYCLE_R(0.0));
                for (l = 0; l < UNICYCLE_NX; ++l) {
                    v += slot->Phit[l + i * UNICYCLE_NX] * PA[l + j * UNICYCLE_NX];
                }
                Z[i + j * UNICYCLE_NW] = v;
            }
        }
        /* Cholesky of the control block Z_uu in place (lower triangle) */
        for (j = UNICYCLE_NX; j < UNICYCLE_NW; ++j) {
            unicycle_real d = Z[j + j * UNICYCLE_NW];
            for (l = UNICYCLE_NX; l < j; ++l) {
                d -= Z[j + l * UNICYCLE_NW] * Z[j + l * UNICYCLE_NW];
            }
            if (!(d > tol)) {
                return 0;
            }
            d = unicycle_sqrt(d);
            Z[j + j * UNICYCLE_NW] = d;
            for (i = j + 1; i < UNICYCLE_NW; ++i) {
                v = Z[i + j * UNICYCLE_NW];
                for (l = UNICYCLE_NX; l < j; ++l) {
                    v -= Z[i + l * UNICYCLE_NW] * Z[j + l * UNICYCLE_NW];
                }
                Z[i + j * UNICYCLE_NW] = v / d;
            }
        }
        if (k == 0) {
            break; /* x_0 is fixed: P_0 is not needed */
        }
        /* Y = L^-1 Z_ux in place, then P = Z_xx - Y' Y */
        for (j = 0; j < UNICYCLE_NX; ++j) {
            for (i = UNICYCLE_NX; i < UNICYCLE_NW; ++i) {
                v = Z[i + j * UNICYCLE_NW];
                for (l = UNICYCLE_NX; l < i; ++l) {
                    v -= Z[i + l * UNICYCLE_NW] * Z[l + j * UNICYCLE_NW];
                }
                Z[i + j * UNICYCLE_NW] = v / Z[i + i * UNICYCLE_NW];
            }
        }
        for (j = 0; j < UNICYCLE_NX; ++j) {
            for (i = 0; i < UNICYCLE_NX; ++i) {
                v = UNICYCLE_R(0.5) * (Z[i + j * UNICYCLE_NW] + Z[j + i * UNICYCLE_NW]);
                for (l = UNICYCLE_NX; l < UNICYCLE_NW; ++l) {
                    v -= Z[l + i * UNICYCLE_NW] * Z[l + j * UNICYCLE_NW];
                }
                P[i + j * UNICYCLE_NX] = v;
            }
        }
    }
    return 1;
}

/* One raise: from below the minimum to the minimum, else times UNICYCLE_LM_RAISE, at most the
 * maximum. */
static void unicycle_lm_raise(unicycle_solver *s)
{
    unicycle_real lo = UNICYCLE_LM_MIN_REL * s->lm_scale, hi = UNICYCLE_LM_MAX_REL * s->lm_scale;
    if (s->lm_uncapped > s->lm) {
        /* the first raise after the cap of unicycle_lm_measured restores the term it capped */
        s->lm = s->lm_uncapped;
        s->lm_uncapped = -UNICYCLE_R(1.0);
        return;
    }
    s->lm = s->lm < lo ? lo : s->lm * UNICYCLE_LM_RAISE;
    s->lm = s->lm > hi ? hi : s->lm;
}

/* Raise until the QP is convex on the dynamics or the term is at its maximum. */
static void unicycle_lm_convexify(unicycle_solver *s)
{
    unicycle_real hi = UNICYCLE_LM_MAX_REL * s->lm_scale;
    while (!unicycle_lm_convex(s, s->lm) && s->lm < hi) {
        unicycle_lm_raise(s);
    }
}

/* After init or a re-initialisation (QP assembled): the scale, lm from 0. */
void unicycle_lm_start(unicycle_solver *s)
{
    if (!s->lm_auto) {
        return;
    }
    s->lm_scale = unicycle_lm_hessian_scale(s);
    s->lm = UNICYCLE_R(0.0);
    s->lm_kkt_prev = -UNICYCLE_R(1.0);
    s->lm_uncapped = -UNICYCLE_R(1.0);
    unicycle_lm_convexify(s);
}

/* After a prepare (QP assembled, KKT proxy evaluated): the scale, a raise when the proxy
 * grew UNICYCLE_LM_KKT_GROWTH times, then convex. */
static void unicycle_lm_prepared(unicycle_solver *s)
{
    unicycle_real floor_ =
        UNICYCLE_PREC(1e-8, 1e-5) * (s->kkt_proxy_ref > UNICYCLE_R(1.0) ? s->kkt_proxy_ref : UNICYCLE_R(1.0));
    unicycle_real prev = s->lm_kkt_prev > floor_ ? s->lm_kkt_prev : floor_;
    if (!s->lm_auto) {
        return;
    }
    s->lm_scale = unicycle_lm_hessian_scale(s);
    s->lm_uncapped = -UNICYCLE_R(1.0);
    if (s->lm_kkt_prev >= UNICYCLE_R(0.0) && !(s->kkt_proxy <= UNICYCLE_LM_KKT_GROWTH * prev)) {
        unicycle_lm_raise(s);
    }
    s->lm_kkt_prev = s->kkt_proxy;
    unicycle_lm_convexify(s);
}

/* Feedback, once the measurement is in the QP: the term capped by the distance from the
 * solution, UNICYCLE_LM_KKT_REL h d^2 with d = max(proxy, max_i |dx0_i| / scale_x_i) (0 below
 * UNICYCLE_LM_MIN_REL h), so that it vanishes where the iterate converges. */
static void unicycle_lm_measured(unicycle_solver *s)
{
    unicycle_real d = s->kkt_proxy, cap, v;
    int i;
    s->lm_uncapped = -UNICYCLE_R(1.0);
    if (!s->lm_auto) {
        return;
    }
    for (i = 0; i < UNICYCLE_NX; ++i) {
        v = unicycle_fabs(s->qp_in.x0[i]) / s->scale_x[i];
        d = v > d ? v : d;
    }
    cap = UNICYCLE_LM_KKT_REL * s->lm_scale * d * d;
    if (!(s->lm <= cap)) {
        s->lm_uncapped = s->lm;
        s->lm = cap < UNICYCLE_LM_MIN_REL * s->lm_scale ? UNICYCLE_R(0.0) : cap;
    }
}

/* After a feedback: lowered after a step, raised after a failed QP or a divergence. */
static void unicycle_lm_feedback(unicycle_solver *s, int status)
{
    if (!s->lm_auto) {
        return;
    }
    if (status == UNICYCLE_OK) {
        s->lm *= UNICYCLE_LM_LOWER;
        if (s->lm < UNICYCLE_LM_MIN_REL * s->lm_scale) {
            s->lm = UNICYCLE_R(0.0);
        }
    } else if (status == UNICYCLE_ERR_QP || status == UNICYCLE_ERR_DIVERGED) {
        unicycle_lm_raise(s);
    }
}

void unicycle_defaults(unicycle_solver *s)
{
    int k, i;
    s->magic = UNICYCLE_MAGIC;
    s->initialized = 0;
    s->qp_ready = 0;
    s->prepare_due = 0;
    s->shifted = 0;
    s->status = UNICYCLE_OK;
    s->M = unicycle_default_M < 0 ? 0 : (unicycle_default_M > UNICYCLE_N - 1 ? UNICYCLE_N - 1 : unicycle_default_M);
    s->mode = UNICYCLE_MODE_RECEDING;
    s->hessian = (unicycle_default_hessian == UNICYCLE_HESSIAN_GAUSS_NEWTON && UNICYCLE_HAS_GN)
                     ? UNICYCLE_HESSIAN_GAUSS_NEWTON
                     : UNICYCLE_HESSIAN_EXACT;
    s->regularization = unicycle_default_regularization;
    s->reg_eps = unicycle_default_reg_eps;
    s->cost_hessian = unicycle_default_cost_hessian ? 1 : 0;
    /* a negative generated default: the automatic term (algorithm.md section 10) */
    s->lm_auto = !(unicycle_default_lm >= UNICYCLE_R(0.0));
    s->lm =
        (unicycle_default_lm >= UNICYCLE_R(0.0) && unicycle_default_lm < INFINITY) ? unicycle_default_lm : UNICYCLE_R(0.0);
    s->lm_scale = UNICYCLE_R(1.0);
    s->lm_kkt_prev = -UNICYCLE_R(1.0);
    s->lm_uncapped = -UNICYCLE_R(1.0);
    for (k = 0; k < UNICYCLE_N; ++k) { /* set only during a QP solve (unicycle_qp_solve_bound) */
        s->qp_in.H[k] = 0;
        s->qp_in.Phi[k] = 0;
        s->qp_in.C[k] = 0;
    }
    s->qp_in.HN = 0;
    s->qp_in.R = 0;
    s->qp_in.Req = 0;
    unicycle_qp_settings_default(&s->qp_settings);
    s->qp_settings.tol = UNICYCLE_DEFAULT_QP_TOL;
    s->qp_warm = 1;
    s->qp_cold_retry = 0;
    for (k = 0; k <= UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NP; ++i) {
            s->p[k][i] = unicycle_p_default[i];
        }
    }
    for (i = 0; i < UNICYCLE_NX; ++i) {
        s->xhat0[i] = unicycle_x0_default[i];
    }
    s->n_recomputed = 0;
    s->qp_status = 0;
    s->qp_iterations = 0;
    for (k = 0; k < UNICYCLE_N; ++k) {
        s->rho[k] = UNICYCLE_R(0.0);
    }
    s->recovery = 1;
    s->recovery_failures = UNICYCLE_RECOVERY_FAILURES;
    unicycle_compute_scales(s);
    unicycle_reset_health(s);
    for (i = 0; i < 4; ++i) {
        s->kkt[i] = NAN;
    }
    unicycle_timer_init(&s->timer);
    s->budget_unit = UNICYCLE_BUDGET_OFF;
    s->budget = 0.0;
    s->anytime_tol = UNICYCLE_ANYTIME_TOL;
    s->M_adaptive = 0;
    s->M_min = 0;
    s->M_max = UNICYCLE_N - 1;
    s->M_eta = UNICYCLE_ADAPTIVE_ETA;
    s->work = 0.0;
    s->instant_start = 0.0;
    s->cost_stage = 0.0;
    s->cost_qp = 0.0;
    s->cost_prepare = 0.0;
    s->cost_qp_iter = 0.0;
    s->budget_used = 0.0;
    s->extra_iterations = 0;
    s->instant_stages = 0;
}

/* ---- the budget clock (algorithm.md section 12) --------------------------------------- */

/* Now on the budget's clock: the work counter (work units) or the solver's clock. */
static double unicycle_budget_now(const unicycle_solver *s)
{
    return s->budget_unit == UNICYCLE_BUDGET_WORK ? s->work : unicycle_timer_now(&s->timer);
}

/* 1 when no budget is set, or when `cost` more still fits in the instant's budget. */
static int unicycle_budget_fits(const unicycle_solver *s, double cost)
{
    return s->budget_unit == UNICYCLE_BUDGET_OFF || unicycle_budget_now(s) - s->instant_start + cost <= s->budget;
}

/* ---- function evaluations ----------------------------------------------------------- */

/* F_k (eq. 14) at the current point into s->mem.ev.tmp_F (= gL + mu_b_k), s->mem.ev.tmp_phi, s->mem.ev.tmp_g. */
static int unicycle_stage_F(unicycle_solver *s, int k)
{
    unicycle_real l = UNICYCLE_R(0.0);
    int i;
    s->work += 1.0;
    if (unicycle_eval_stage_grad(s->x[k], s->u[k], s->p[k], s->lam[k + 1], s->mu_g[k], s->mem.ev.tmp_gL,
                              s->mem.ev.tmp_phi, &l, s->mem.ev.tmp_g, &s->mem.ev.fun_work) != 0) {
        return UNICYCLE_ERR_FUNCTION;
    }
    if (!unicycle_lai_vec_finite(UNICYCLE_NW, s->mem.ev.tmp_gL) ||
        !unicycle_lai_vec_finite(UNICYCLE_NX, s->mem.ev.tmp_phi) ||
        !unicycle_lai_vec_finite(UNICYCLE_NG, s->mem.ev.tmp_g) || !isfinite(l)) {
        return UNICYCLE_ERR_NONFINITE_VALUE;
    }
    for (i = 0; i < UNICYCLE_NW; ++i) {
        s->mem.ev.tmp_F[i] = s->mem.ev.tmp_gL[i] + s->mu_b[k][i];
    }
    return UNICYCLE_OK;
}

/* Regularise a fresh A block (algorithm.md section 5), timed as its own phase. */
static int unicycle_regularize(unicycle_solver *s, int n, unicycle_real *A)
{
    double t0;
    int rc;
    if (s->regularization == UNICYCLE_REG_NONE) {
        return UNICYCLE_OK;
    }
    t0 = unicycle_timer_now(&s->timer);
    rc = unicycle_reg_apply(n, A, s->regularization, s->reg_eps, s->mem.ev.reg_work);
    unicycle_timer_add(&s->timer, UNICYCLE_PHASE_REGULARIZATION, t0);
    return rc == 0 ? UNICYCLE_OK : UNICYCLE_ERR_REGULARIZATION;
}

/* The stage-cost Hessian A_l of stage k at the current point into s->mem.ev.tmp_Al. */
static int unicycle_stage_Al(unicycle_solver *s, int k)
{
    double t0 = unicycle_timer_now(&s->timer);
    int rc = unicycle_eval_stage_hess_cost(s->hessian, s->x[k], s->u[k], s->p[k], s->mem.ev.tmp_Al,
                                        &s->mem.ev.fun_work);
    unicycle_timer_add(&s->timer, UNICYCLE_PHASE_HESSIANS, t0);
    if (rc != 0) {
        return UNICYCLE_ERR_FUNCTION;
    }
    return unicycle_lai_vec_finite(UNICYCLE_NW * UNICYCLE_NW, s->mem.ev.tmp_Al) ? UNICYCLE_OK : UNICYCLE_ERR_NONFINITE_VALUE;
}

/* H_k (eq. 15) at the current point, A regularised, stored in stage k's slot with
 * A_dyn = A - A_l (unregularised). Evaluated into scratch first, so a failed evaluation
 * leaves the slot as it was. */
static int unicycle_stage_H(unicycle_solver *s, int k)
{
    unicycle_stage_slot *slot;
    double t0 = unicycle_timer_now(&s->timer);
    int rc, i;
    s->work += 1.0;
    rc = unicycle_eval_stage_hess(s->hessian, s->x[k], s->u[k], s->p[k], s->lam[k + 1], s->mu_g[k],
                               s->mem.ev.tmp_A, s->mem.ev.tmp_Phi, s->mem.ev.tmp_C, &s->mem.ev.fun_work);
    unicycle_timer_add(&s->timer, UNICYCLE_PHASE_HESSIANS, t0);
    if (rc != 0) {
        return UNICYCLE_ERR_FUNCTION;
    }
    if (!unicycle_lai_vec_finite(UNICYCLE_NW * UNICYCLE_NW, s->mem.ev.tmp_A) ||
        !unicycle_lai_vec_finite(UNICYCLE_NX * UNICYCLE_NW, s->mem.ev.tmp_Phi) ||
        !unicycle_lai_vec_finite(UNICYCLE_NG * UNICYCLE_NW, s->mem.ev.tmp_C)) {
        return UNICYCLE_ERR_NONFINITE_VALUE;
    }
    /* A_dyn = A - A_l, kept whatever cost_hessian is, so the setting may change at any time */
    rc = unicycle_stage_Al(s, k);
    if (rc != UNICYCLE_OK) {
        return rc;
    }
    for (i = 0; i < UNICYCLE_NW * UNICYCLE_NW; ++i) {
        s->mem.ev.tmp_Al[i] = s->mem.ev.tmp_A[i] - s->mem.ev.tmp_Al[i];
    }
    rc = unicycle_regularize(s, UNICYCLE_NW, s->mem.ev.tmp_A);
    if (rc != UNICYCLE_OK) {
        return rc;
    }
    slot = unicycle_ring_stage(&s->ring, k);
    unicycle_copy(slot->Ht, s->mem.ev.tmp_A, UNICYCLE_NW * UNICYCLE_NW);
    unicycle_ring_store_A_dyn(slot, s->mem.ev.tmp_Al);
    unicycle_copy(slot->Phit, s->mem.ev.tmp_Phi, UNICYCLE_NX * UNICYCLE_NW);
    unicycle_copy(slot->Ct, s->mem.ev.tmp_C, UNICYCLE_NG * UNICYCLE_NW);
    return UNICYCLE_OK;
}

int unicycle_term_grad_checked(unicycle_solver *s, unicycle_real *gL, unicycle_real *E, unicycle_real *r, unicycle_real *r_eq)
{
    if (unicycle_eval_term_grad(s->x[UNICYCLE_N], s->p[UNICYCLE_N], s->mu_r, s->nu, gL, E, r, r_eq,
                             &s->mem.ev.fun_work) != 0) {
        return UNICYCLE_ERR_FUNCTION;
    }
    if (!unicycle_lai_vec_finite(UNICYCLE_NX, gL) || !isfinite(*E) || !unicycle_lai_vec_finite(UNICYCLE_NR, r) ||
        !unicycle_lai_vec_finite(UNICYCLE_NE, r_eq)) {
        return UNICYCLE_ERR_NONFINITE_VALUE;
    }
    return UNICYCLE_OK;
}

/* Terminal F: gL_N, E, r, r_eq at the current point. */
static int unicycle_term_F(unicycle_solver *s)
{
    unicycle_real gL[UNICYCLE_NX], E = UNICYCLE_R(0.0), r[UNICYCLE_DIM(UNICYCLE_NR)], r_eq[UNICYCLE_DIM(UNICYCLE_NE)];
    int rc;
    s->work += 1.0;
    rc = unicycle_term_grad_checked(s, gL, &E, r, r_eq);
    if (rc != UNICYCLE_OK) {
        return rc;
    }
    unicycle_copy(s->gL_N, gL, UNICYCLE_NX);
    s->E = E;
    unicycle_copy(s->r, r, UNICYCLE_NR);
    unicycle_copy(s->r_eq, r_eq, UNICYCLE_NE);
    return UNICYCLE_OK;
}

/* Terminal H: A_N (regularised), R, R_eq. */
static int unicycle_term_H(unicycle_solver *s)
{
    unicycle_real R[UNICYCLE_DIM(UNICYCLE_NR) * UNICYCLE_NX], R_eq[UNICYCLE_DIM(UNICYCLE_NE) * UNICYCLE_NX];
    double t0 = unicycle_timer_now(&s->timer);
    int rc;
    s->work += 1.0;
    rc = unicycle_eval_term_hess(s->hessian, s->x[UNICYCLE_N], s->p[UNICYCLE_N], s->mu_r, s->nu, s->mem.ev.tmp_A, R,
                              R_eq, &s->mem.ev.fun_work);
    unicycle_timer_add(&s->timer, UNICYCLE_PHASE_HESSIANS, t0);
    if (rc != 0) {
        return UNICYCLE_ERR_FUNCTION;
    }
    if (!unicycle_lai_vec_finite(UNICYCLE_NX * UNICYCLE_NX, s->mem.ev.tmp_A) ||
        !unicycle_lai_vec_finite(UNICYCLE_NR * UNICYCLE_NX, R) || !unicycle_lai_vec_finite(UNICYCLE_NE * UNICYCLE_NX, R_eq)) {
        return UNICYCLE_ERR_NONFINITE_VALUE;
    }
    rc = unicycle_regularize(s, UNICYCLE_NX, s->mem.ev.tmp_A);
    if (rc != UNICYCLE_OK) {
        return rc;
    }
    unicycle_copy(s->A_N, s->mem.ev.tmp_A, UNICYCLE_NX * UNICYCLE_NX);
    unicycle_copy(s->R, R, UNICYCLE_NR * UNICYCLE_NX);
    unicycle_copy(s->R_eq, R_eq, UNICYCLE_NE * UNICYCLE_NX);
    return UNICYCLE_OK;
}

/* ---- QP assembly (algorithm.md section 3) ------------------------------------------- */

static void unicycle_assemble(unicycle_solver *s)
{
    unicycle_qp_in *in = &s->qp_in;
    int k, i, j;
    double t0 = unicycle_timer_now(&s->timer);

    for (k = 0; k < UNICYCLE_N; ++k) {
        const unicycle_stage_slot *slot = unicycle_ring_stage_const(&s->ring, k);
        /* a_k = F_w,k + Phit_k' lam_{k+1} - Ct_k' mu_g_k - mu_b_k (eq. 12) */
        for (i = 0; i < UNICYCLE_NW; ++i) {
            unicycle_real pl = UNICYCLE_R(0.0), cm = UNICYCLE_R(0.0);
            for (j = 0; j < UNICYCLE_NX; ++j) {
                pl += slot->Phit[j + i * UNICYCLE_NX] * s->lam[k + 1][j];
            }
            for (j = 0; j < UNICYCLE_NG; ++j) {
                cm += slot->Ct[j + i * UNICYCLE_DIM(UNICYCLE_NG)] * s->mu_g[k][j];
            }
            in->g[k][i] = slot->F_w[i] + pl - cm - s->mu_b[k][i];
        }
        /* dx_{k+1} = Phit_k dw_k + (phi_k - x_{k+1}) */
        for (i = 0; i < UNICYCLE_NX; ++i) {
            in->b[k][i] = slot->phi[i] - s->x[k + 1][i];
        }
        for (i = 0; i < UNICYCLE_NX; ++i) {
            in->lbw[k][i] = unicycle_x_bounded(k) ? unicycle_lbx[i] - s->x[k][i] : -INFINITY;
            in->ubw[k][i] = unicycle_x_bounded(k) ? unicycle_ubx[i] - s->x[k][i] : INFINITY;
        }
        for (i = 0; i < UNICYCLE_NU; ++i) {
            in->lbw[k][UNICYCLE_NX + i] = unicycle_lbu[i] - s->u[k][i];
            in->ubw[k][UNICYCLE_NX + i] = unicycle_ubu[i] - s->u[k][i];
        }
        for (i = 0; i < UNICYCLE_NG; ++i) {
            in->lg[k][i] = unicycle_lg[i] - slot->g[i];
            in->ug[k][i] = unicycle_ug[i] - slot->g[i];
        }
    }
    /* a_N = gL_N - R' mu_r - R_eq' nu (= grad E) */
    for (i = 0; i < UNICYCLE_NX; ++i) {
        unicycle_real rm = UNICYCLE_R(0.0), en = UNICYCLE_R(0.0);
        for (j = 0; j < UNICYCLE_NR; ++j) {
            rm += s->R[j + i * UNICYCLE_DIM(UNICYCLE_NR)] * s->mu_r[j];
        }
        for (j = 0; j < UNICYCLE_NE; ++j) {
            en += s->R_eq[j + i * UNICYCLE_DIM(UNICYCLE_NE)] * s->nu[j];
        }
        in->gN[i] = s->gL_N[i] - rm - en;
        in->lbxN[i] = unicycle_lbx[i] - s->x[UNICYCLE_N][i];
        in->ubxN[i] = unicycle_ubx[i] - s->x[UNICYCLE_N][i];
    }
    for (i = 0; i < UNICYCLE_NR; ++i) {
        in->lr[i] = unicycle_lr[i] - s->r[i];
        in->ur[i] = unicycle_ur[i] - s->r[i];
    }
    for (i = 0; i < UNICYCLE_NE; ++i) {
        in->req[i] = -s->r_eq[i];
    }
    unicycle_timer_add(&s->timer, UNICYCLE_PHASE_ASSEMBLY, t0);
}

/* ---- init --------------------------------------------------------------------------- */

static void unicycle_clear_timings(unicycle_solver *s, int first, int last)
{
    int i;
    for (i = first; i <= last; ++i) {
        s->timer.t[i] = UNICYCLE_R(0.0);
    }
}

/* F (stored as F_old) and H of every stage, terminal F and H, at the current iterate. */
static int unicycle_linearize_all(unicycle_solver *s)
{
    double t0;
    int k, rc;
    for (k = 0; k < UNICYCLE_N; ++k) {
        t0 = unicycle_timer_now(&s->timer);
        rc = unicycle_stage_F(s, k);
        unicycle_timer_add(&s->timer, UNICYCLE_PHASE_GRADIENTS, t0);
        if (rc != UNICYCLE_OK) {
            return rc;
        }
        unicycle_ring_store_F(unicycle_ring_stage(&s->ring, k), s->mem.ev.tmp_F, s->mem.ev.tmp_phi,
                           s->mem.ev.tmp_g);
        rc = unicycle_stage_H(s, k);
        if (rc != UNICYCLE_OK) {
            return rc;
        }
    }
    t0 = unicycle_timer_now(&s->timer);
    rc = unicycle_term_F(s);
    unicycle_timer_add(&s->timer, UNICYCLE_PHASE_GRADIENTS, t0);
    if (rc != UNICYCLE_OK) {
        return rc;
    }
    return unicycle_term_H(s);
}

/* The second half of init with the iterate in place: ring reset, F and H of every stage and
 * the terminal node, QP assembly. */
static int unicycle_init_finish(unicycle_solver *s)
{
    int k, rc;
    unicycle_ring_reset(&s->ring);
    for (k = 0; k < UNICYCLE_N; ++k) {
        s->rho[k] = UNICYCLE_R(0.0);
        s->recomputed[k] = k;
        s->selected[k] = 0;
    }
    s->n_recomputed = UNICYCLE_N;
    s->qp_status = 0;
    s->qp_iterations = 0;

    rc = unicycle_linearize_all(s);
    if (rc != UNICYCLE_OK) {
        return rc;
    }
    unicycle_assemble(s);
    s->initialized = 1;
    s->qp_ready = 1;
    s->prepare_due = 0;
    s->shifted = 0;
    unicycle_lm_start(s);
    return UNICYCLE_OK;
}

int unicycle_init(unicycle_solver *s, const unicycle_real *xhat0, const unicycle_real *x, const unicycle_real *u,
               const unicycle_real *lam, const unicycle_real *mu_g, const unicycle_real *mu_b, const unicycle_real *mu_bN,
               const unicycle_real *mu_r, const unicycle_real *nu)
{
    int k, i, rc;

    unicycle_ensure_setup(s);
    s->initialized = 0;
    unicycle_reset_health(s);
    s->qp_ready = 0;
    if ((xhat0 && !unicycle_lai_vec_finite(UNICYCLE_NX, xhat0)) ||
        (x && !unicycle_lai_vec_finite((UNICYCLE_N + 1) * UNICYCLE_NX, x)) ||
        (u && !unicycle_lai_vec_finite(UNICYCLE_N * UNICYCLE_NU, u)) ||
        (lam && !unicycle_lai_vec_finite((UNICYCLE_N + 1) * UNICYCLE_NX, lam)) ||
        (mu_g && !unicycle_lai_vec_finite(UNICYCLE_N * UNICYCLE_NG, mu_g)) ||
        (mu_b && !unicycle_lai_vec_finite(UNICYCLE_N * UNICYCLE_NW, mu_b)) ||
        (mu_bN && !unicycle_lai_vec_finite(UNICYCLE_NX, mu_bN)) ||
        (mu_r && !unicycle_lai_vec_finite(UNICYCLE_NR, mu_r)) || (nu && !unicycle_lai_vec_finite(UNICYCLE_NE, nu))) {
        return unicycle_ret(s, UNICYCLE_ERR_NONFINITE_INPUT);
    }
    unicycle_clear_timings(s, 0, UNICYCLE_N_PHASES - 1);

    for (i = 0; i < UNICYCLE_NX; ++i) {
        s->xhat0[i] = xhat0 ? xhat0[i] : unicycle_x0_default[i];
    }
    for (k = 0; k <= UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NX; ++i) {
            s->x[k][i] = x ? x[k * UNICYCLE_NX + i] : unicycle_guess_x[k][i];
            s->lam[k][i] = lam ? lam[k * UNICYCLE_NX + i] : UNICYCLE_R(0.0);
        }
    }
    for (k = 0; k < UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NU; ++i) {
            s->u[k][i] = u ? u[k * UNICYCLE_NU + i] : unicycle_guess_u[k][i];
        }
        for (i = 0; i < UNICYCLE_DIM(UNICYCLE_NG); ++i) {
            s->mu_g[k][i] = (mu_g && i < UNICYCLE_NG) ? mu_g[k * UNICYCLE_NG + i] : UNICYCLE_R(0.0);
        }
        for (i = 0; i < UNICYCLE_NW; ++i) {
            s->mu_b[k][i] = mu_b ? mu_b[k * UNICYCLE_NW + i] : UNICYCLE_R(0.0);
        }
    }
    unicycle_clear_x0_multiplier(s);
    for (i = 0; i < UNICYCLE_NX; ++i) {
        s->mu_bN[i] = mu_bN ? mu_bN[i] : UNICYCLE_R(0.0);
    }
    for (i = 0; i < UNICYCLE_DIM(UNICYCLE_NR); ++i) {
        s->mu_r[i] = (mu_r && i < UNICYCLE_NR) ? mu_r[i] : UNICYCLE_R(0.0);
    }
    for (i = 0; i < UNICYCLE_DIM(UNICYCLE_NE); ++i) {
        s->nu[i] = (nu && i < UNICYCLE_NE) ? nu[i] : UNICYCLE_R(0.0);
    }

    rc = unicycle_init_finish(s);
    if (rc != UNICYCLE_OK) {
        return unicycle_ret(s, rc);
    }
    unicycle_reset_health(s);
    s->kkt_proxy = unicycle_kkt_proxy_eval(s);
    s->kkt_proxy_ref = s->kkt_proxy;
    return unicycle_ret(s, UNICYCLE_OK);
}

int unicycle_init_nominal(unicycle_solver *s, const unicycle_real *xhat0)
{
#if UNICYCLE_HAS_NOMINAL
    return unicycle_init(s, xhat0, &unicycle_nominal_x[0][0], &unicycle_nominal_u[0][0], &unicycle_nominal_lam[0][0],
                      UNICYCLE_NG > 0 ? &unicycle_nominal_mu_g[0][0] : 0, &unicycle_nominal_mu_b[0][0],
                      unicycle_nominal_mu_bN, UNICYCLE_NR > 0 ? unicycle_nominal_mu_r : 0,
                      UNICYCLE_NE > 0 ? unicycle_nominal_nu : 0);
#else
    (void)xhat0;
    unicycle_ensure_setup(s);
    return unicycle_ret(s, UNICYCLE_ERR_NO_NOMINAL);
#endif
}

/* ---- feedback ----------------------------------------------------------------------- */

static int unicycle_qp_solution_finite(const unicycle_qp_sol *sol)
{
    return unicycle_lai_vec_finite((UNICYCLE_N + 1) * UNICYCLE_NX, &sol->x[0][0]) &&
           unicycle_lai_vec_finite(UNICYCLE_N * UNICYCLE_QP_NU1, &sol->u[0][0]) &&
           unicycle_lai_vec_finite((UNICYCLE_N + 1) * UNICYCLE_NX, &sol->lam[0][0]) &&
           unicycle_lai_vec_finite(UNICYCLE_N * UNICYCLE_QP_NW, &sol->mu_b[0][0]) &&
           unicycle_lai_vec_finite(UNICYCLE_NX, sol->mu_bN) &&
           unicycle_lai_vec_finite(UNICYCLE_N * UNICYCLE_QP_NG1, &sol->mu_g[0][0]) &&
           unicycle_lai_vec_finite(UNICYCLE_QP_NR1, sol->mu_r) && unicycle_lai_vec_finite(UNICYCLE_QP_NE1, sol->nu);
}

/* Warm-start point of the QP (in s->mem.qp.sol): the previous QP solution shifted with the
 * horizon. Its primal part has been added to the iterate, which prepare shifted, so it is
 * a zero step from the (shifted) iterate, with x_0's step fixed by the measurement; the
 * multipliers are the (shifted) iterate's, which are those of the previous QP. */
static void unicycle_qp_warm_point(unicycle_solver *s)
{
    unicycle_qp_sol *w = &s->mem.qp.sol;
    int k, i;
    for (k = 0; k <= UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NX; ++i) {
            w->x[k][i] = k == 0 ? s->qp_in.x0[i] : UNICYCLE_R(0.0);
            w->lam[k][i] = s->lam[k][i];
        }
    }
    for (k = 0; k < UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_QP_NU1; ++i) {
            w->u[k][i] = UNICYCLE_R(0.0);
        }
        for (i = 0; i < UNICYCLE_NW; ++i) {
            w->mu_b[k][i] = s->mu_b[k][i];
        }
        for (i = 0; i < UNICYCLE_QP_NG1; ++i) {
            w->mu_g[k][i] = i < UNICYCLE_NG ? s->mu_g[k][i] : UNICYCLE_R(0.0);
        }
    }
    for (i = 0; i < UNICYCLE_NX; ++i) {
        w->mu_bN[i] = s->mu_bN[i];
    }
    for (i = 0; i < UNICYCLE_QP_NR1; ++i) {
        w->mu_r[i] = i < UNICYCLE_NR ? s->mu_r[i] : UNICYCLE_R(0.0);
    }
    for (i = 0; i < UNICYCLE_QP_NE1; ++i) {
        w->nu[i] = i < UNICYCLE_NE ? s->nu[i] : UNICYCLE_R(0.0);
    }
}

/* Feedback step 1: the call is refused before the QP when the solver is not initialised,
 * the measurement is not finite or no QP is prepared (the fallback control is returned).
 * Returns UNICYCLE_OK when the QP is to be solved, else the status of the failed call. */
static int unicycle_feedback_admit(unicycle_solver *s, const unicycle_real *xhat0, unicycle_real *u0)
{
    if (!s->initialized) {
        unicycle_fallback_u0(s, u0);
        return unicycle_ret(s, UNICYCLE_ERR_NOT_INITIALIZED);
    }
    if (xhat0 == 0 || !unicycle_lai_vec_finite(UNICYCLE_NX, xhat0)) {
        s->xhat_fresh = 0;
        if (s->mode == UNICYCLE_MODE_RECEDING) {
            /* the sampling instant has passed all the same: its prepare (the shift) is due */
            s->prepare_due = 1;
            s->shifted = 0;
        }
        return unicycle_feedback_failed(s, u0, UNICYCLE_ERR_NONFINITE_INPUT);
    }
    if (!s->qp_ready) {
        /* counted as a failed instant: a prepare that keeps failing ends in a recovery, which
         * starts from the newest measurement, so it is recorded all the same (algorithm.md
         * section 9); the instant has passed: its prepare (the shift) is due */
        unicycle_copy(s->xhat0, xhat0, UNICYCLE_NX);
        s->xhat_fresh = 1;
        if (s->mode == UNICYCLE_MODE_RECEDING) {
            s->prepare_due = 1;
            s->shifted = 0;
        }
        return unicycle_feedback_failed(s, u0, UNICYCLE_ERR_NOT_PREPARED);
    }
    return UNICYCLE_OK;
}

/* Step 2: the measurement enters the QP as the fixed step of x_0. */
static void unicycle_feedback_measure(unicycle_solver *s, const unicycle_real *xhat0)
{
    int i;
    for (i = 0; i < UNICYCLE_NX; ++i) {
        s->xhat0[i] = xhat0[i];
        s->qp_in.x0[i] = xhat0[i] - s->x[0][i];
    }
    s->xhat_fresh = 1;
    unicycle_lm_measured(s);
    /* the QP is attempted: a prepare (with its shift) is due, whatever the outcome */
    s->prepare_due = 1;
    s->shifted = 0;
}

/* The QP's matrix pointers (unicycle_qp_in.H, Phi, C, HN, R, Req) point into this struct: the
 * ring slots in place and the terminal blocks. They are set just before each solve and
 * cleared after it, so the struct holds no pointer into itself between calls and a byte
 * copy (memcpy, struct assignment) is a complete, independent solver. */
static int unicycle_qp_solve_bound(unicycle_solver *s)
{
    unicycle_qp_in *in = &s->qp_in;
    int k, qs;
    for (k = 0; k < UNICYCLE_N; ++k) {
        const unicycle_stage_slot *slot = unicycle_ring_stage_const(&s->ring, k);
        in->H[k] = slot->Ht;
        in->Phi[k] = slot->Phit;
        in->C[k] = UNICYCLE_NG > 0 ? slot->Ct : 0;
    }
    in->HN = s->A_N;
    in->R = UNICYCLE_NR > 0 ? s->R : 0;
    in->Req = UNICYCLE_NE > 0 ? s->R_eq : 0;
    qs = unicycle_qp_solve(&s->mem.qp.work, in, &s->qp_settings, &s->mem.qp.sol, &s->qp_info);
    for (k = 0; k < UNICYCLE_N; ++k) {
        in->H[k] = 0;
        in->Phi[k] = 0;
        in->C[k] = 0;
    }
    in->HN = 0;
    in->R = 0;
    in->Req = 0;
    return qs;
}

/* 1 when the QP status is "solved" and its solution finite. */
static int unicycle_qp_ok(const unicycle_solver *s, int qs)
{
    return qs == UNICYCLE_QP_SOLVED && unicycle_qp_solution_finite(&s->mem.qp.sol);
}

/* One solve of the prepared QP, warm (from the point in s->mem.qp.sol) or cold; its iterations
 * are added to those of the call. Returns the QP status. */
static int unicycle_qp_attempt(unicycle_solver *s, int warm)
{
    int qs;
    s->qp_settings.warm_start = warm;
    qs = unicycle_qp_solve_bound(s);
    s->qp_iterations += s->qp_info.iterations;
    return qs;
}

/* Step 3: the QP with the current term lm, warm-started when that is on, and the cold retry
 * in the same call when the warm start failed or needed the inertia correction: the QP is
 * then nonconvex on the null space of its equalities and may have several local
 * minimisers, and the warm start may have reached another one than the cold start finds
 * (the one the closed loop has followed so far). Returns the QP status. */
static int unicycle_feedback_qp(unicycle_solver *s)
{
    int qs;
    s->qp_in.hess_shift = s->lm;
    s->qp_iterations = 0;
    s->qp_cold_retry = 0;
    s->work += UNICYCLE_WORK_QP;
    if (s->qp_warm) {
        unicycle_qp_warm_point(s);
    }
    qs = unicycle_qp_attempt(s, s->qp_warm);
    if (s->qp_warm && qs != UNICYCLE_QP_INVALID_INPUT && !(qs == UNICYCLE_QP_MAX_ITER && s->qp_capped) &&
        (!unicycle_qp_ok(s, qs) || s->qp_info.inertia_corrections > 0)) {
        s->qp_cold_retry = 1;
        qs = unicycle_qp_attempt(s, 0);
    }
    return qs;
}

/* Step 4, the automatic term (algorithm.md section 10): a QP still not solved is solved
 * again (cold) with lm raised, at most UNICYCLE_LM_RETRIES times. Returns the QP status; the
 * number of retries in *retries. */
static int unicycle_feedback_lm_retries(unicycle_solver *s, int qs, int *retries)
{
    *retries = 0;
    while (s->lm_auto && *retries < UNICYCLE_LM_RETRIES && s->lm < UNICYCLE_LM_MAX_REL * s->lm_scale &&
           !unicycle_qp_ok(s, qs) && qs != UNICYCLE_QP_INVALID_INPUT &&
           !(qs == UNICYCLE_QP_MAX_ITER && s->qp_capped)) {
        unicycle_lm_raise(s);
        s->work += UNICYCLE_WORK_QP;
        s->qp_in.hess_shift = s->lm;
        qs = unicycle_qp_attempt(s, 0);
        *retries += 1;
    }
    return qs;
}

/* Step 5: the outcome of the QP: UNICYCLE_ERR_QP when it is not solved, UNICYCLE_ERR_DIVERGED when
 * its step leaves the box of the divergence test (algorithm.md section 9), else UNICYCLE_OK. */
static int unicycle_feedback_check_step(const unicycle_solver *s, int qs)
{
    const unicycle_qp_sol *sol = &s->mem.qp.sol;
    if (!unicycle_qp_ok(s, qs)) {
        return UNICYCLE_ERR_QP;
    }
    if (!unicycle_box_ok(s, &s->x[0][0], &sol->x[0][0], UNICYCLE_NX, &s->u[0][0], &sol->u[0][0], UNICYCLE_QP_NU1)) {
        return UNICYCLE_ERR_DIVERGED;
    }
    return UNICYCLE_OK;
}

/* Step 6: the step of each stage kept in its slot for the secant criterion:
 * domega_k = (dw_k, lam_QP_{k+1} - lam_{k+1}, mu_g_QP_k - mu_g_k, mu_b_QP_k - mu_b_k). */
static void unicycle_store_domega(unicycle_solver *s)
{
    const unicycle_qp_sol *sol = &s->mem.qp.sol;
    int k, i;
    for (k = 0; k < UNICYCLE_N; ++k) {
        unicycle_stage_slot *slot = unicycle_ring_stage(&s->ring, k);
        for (i = 0; i < UNICYCLE_NX; ++i) {
            slot->dw[i] = sol->x[k][i];
            slot->dlam[i] = sol->lam[k + 1][i] - s->lam[k + 1][i];
        }
        for (i = 0; i < UNICYCLE_NU; ++i) {
            slot->dw[UNICYCLE_NX + i] = sol->u[k][i];
        }
        for (i = 0; i < UNICYCLE_NG; ++i) {
            slot->dmu_g[i] = sol->mu_g[k][i] - s->mu_g[k][i];
        }
        for (i = 0; i < UNICYCLE_NW; ++i) {
            slot->dmu_b[i] = sol->mu_b[k][i] - s->mu_b[k][i];
        }
    }
}

/* Step 7, the full step (paper eq. 4): w += dw, multipliers replaced by the QP's. */
static void unicycle_take_step(unicycle_solver *s)
{
    const unicycle_qp_sol *sol = &s->mem.qp.sol;
    int k, i;
    for (k = 0; k <= UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NX; ++i) {
            s->x[k][i] += sol->x[k][i];
            s->lam[k][i] = sol->lam[k][i];
        }
    }
    for (k = 0; k < UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NU; ++i) {
            s->u[k][i] += sol->u[k][i];
        }
        for (i = 0; i < UNICYCLE_NG; ++i) {
            s->mu_g[k][i] = sol->mu_g[k][i];
        }
        for (i = 0; i < UNICYCLE_NW; ++i) {
            s->mu_b[k][i] = sol->mu_b[k][i];
        }
    }
    for (i = 0; i < UNICYCLE_NX; ++i) {
        s->mu_bN[i] = sol->mu_bN[i];
    }
    for (i = 0; i < UNICYCLE_NR; ++i) {
        s->mu_r[i] = sol->mu_r[i];
    }
    for (i = 0; i < UNICYCLE_NE; ++i) {
        s->nu[i] = sol->nu[i];
    }
    s->qp_ready = 0;
}

/* Step 8: a good plan, the fallback of the next failures; the automatic term lowered unless
 * this QP needed a raise (lowered = 1); u0 clipped to the control bounds. */
static void unicycle_keep_plan(unicycle_solver *s, unicycle_real *u0, int lowered)
{
    s->n_failed = 0;
    s->plan_age = 0;
    s->recovering = s->recovering > 0 ? s->recovering - 1 : 0;
    if (lowered) {
        unicycle_lm_feedback(s, UNICYCLE_OK);
    }
    unicycle_copy(&s->plan_u[0][0], &s->u[0][0], UNICYCLE_N * UNICYCLE_NU);
    if (unicycle_clip_u(s->u[0], s->u0_out)) {
        s->flags |= UNICYCLE_FLAG_U0_CLIPPED;
    }
    if (u0) {
        unicycle_copy(u0, s->u0_out, UNICYCLE_NU);
    }
}

static int unicycle_feedback_recover(unicycle_solver *s, int *qs, int *retries);

/* The bounded latency of a time budget (algorithm.md section 12): the QP's iterations are
 * capped by the budget of the instant over the cost of one QP iteration measured before; a
 * QP stopped by the cap is not retried (the fallback control). Returns the setting's limit. */
static int unicycle_feedback_cap(unicycle_solver *s)
{
    int max_iter = s->qp_settings.max_iter;
    double left = s->budget - (unicycle_budget_now(s) - s->instant_start), n;
    s->qp_capped = 0;
    if (s->budget_unit != UNICYCLE_BUDGET_TIME || !(s->cost_qp_iter > 0.0)) {
        return max_iter;
    }
    n = left / s->cost_qp_iter;
    n = n < 1.0 ? 1.0 : n;
    if (n < (double)max_iter) {
        s->qp_settings.max_iter = (int)n;
        s->qp_capped = 1;
    }
    return max_iter;
}

/* The end of a feedback: the iteration limit of the setting back, the instant's cost so far. */
static void unicycle_feedback_end(unicycle_solver *s, int max_iter, double t0)
{
    s->qp_settings.max_iter = max_iter;
    s->qp_capped = 0;
    s->budget_used = unicycle_budget_now(s) - s->instant_start;
    unicycle_timer_add(&s->timer, UNICYCLE_PHASE_FEEDBACK, t0);
}

/* 1 when the model is finite at the state xs with the next control of the last good plan (one
 * stage evaluation). A finite measurement at which it is not (an outlier of 1e6 rad/s, say)
 * cannot start a re-initialisation: it is no measurement (algorithm.md section 9). */
static int unicycle_model_finite_at(unicycle_solver *s, const unicycle_real *xs)
{
    unicycle_real l = UNICYCLE_R(0.0), u[UNICYCLE_NU], xn[UNICYCLE_NX];
    int j = s->plan_age > UNICYCLE_N - 1 ? UNICYCLE_N - 1 : s->plan_age;
    unicycle_clip_u(s->plan_u[j], u);
    return unicycle_eval_stage_eval(xs, u, s->p[0], xn, &l, s->mem.ev.tmp_g, &s->mem.ev.fun_work) == 0 &&
           unicycle_lai_vec_finite(UNICYCLE_NX, xn) && unicycle_lai_vec_finite(1, &l);
}

int unicycle_feedback(unicycle_solver *s, const unicycle_real *xhat0, unicycle_real *u0)
{
    unicycle_real xhat_prev[UNICYCLE_NX];
    double t0, b0;
    int rc, qs, retries, max_iter;

    unicycle_ensure_setup(s);
    s->flags = 0;
    s->instant_start = unicycle_budget_now(s);
    s->extra_iterations = 0;
    s->instant_stages = 0;
    rc = unicycle_feedback_admit(s, xhat0, u0);
    if (rc != UNICYCLE_OK) {
        return rc;
    }
    s->timer.t[UNICYCLE_PHASE_FEEDBACK] = UNICYCLE_R(0.0);
    t0 = unicycle_timer_now(&s->timer);
    unicycle_copy(xhat_prev, s->xhat0, UNICYCLE_NX);
    unicycle_feedback_measure(s, xhat0);
    max_iter = unicycle_feedback_cap(s);
    b0 = unicycle_budget_now(s);
    qs = unicycle_feedback_qp(s);
    qs = unicycle_feedback_lm_retries(s, qs, &retries);
    s->cost_qp = unicycle_budget_now(s) - b0;
    if (s->qp_iterations > 0 && s->budget_unit == UNICYCLE_BUDGET_TIME) {
        s->cost_qp_iter = s->cost_qp / (double)s->qp_iterations;
    }
    s->qp_status = qs;
    rc = unicycle_feedback_check_step(s, qs);
    /* the recovery within the feedback (algorithm.md section 9); not for a QP stopped by its
     * iteration limit (a budget, not a sign of a wrong iterate) or refused as invalid */
    if (rc != UNICYCLE_OK && s->recovery && s->mode == UNICYCLE_MODE_RECEDING && qs != UNICYCLE_QP_MAX_ITER &&
        qs != UNICYCLE_QP_INVALID_INPUT) {
        if (!unicycle_model_finite_at(s, xhat0)) {
            /* no measurement: handled as a non-finite one (the iterate and its QP stay; the
             * prepare takes the predicted step) */
            unicycle_copy(s->xhat0, xhat_prev, UNICYCLE_NX);
            s->xhat_fresh = 0;
            s->flags |= UNICYCLE_FLAG_MEASUREMENT_UNUSABLE;
            rc = UNICYCLE_ERR_NONFINITE_VALUE;
        } else {
            rc = unicycle_feedback_recover(s, &qs, &retries);
            if (rc == UNICYCLE_OK) {
                s->qp_status = qs;
                rc = unicycle_feedback_check_step(s, qs);
            }
        }
    }
    if (rc != UNICYCLE_OK) {
        unicycle_feedback_end(s, max_iter, t0);
        return unicycle_feedback_failed(s, u0, rc);
    }
    unicycle_store_domega(s);
    unicycle_take_step(s);
    unicycle_keep_plan(s, u0, retries == 0);
    unicycle_feedback_end(s, max_iter, t0);
    return unicycle_ret(s, UNICYCLE_OK);
}

/* ---- prepare ------------------------------------------------------------------------ */

/* Step 1 (receding mode): shift the iterate by one interval and advance ring_head.
 * x_N is set from phi_{N-1} in step 3. */
static void unicycle_shift(unicycle_solver *s)
{
    int k, i;
    for (k = 0; k < UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NX; ++i) {
            s->x[k][i] = s->x[k + 1][i];
            s->lam[k][i] = s->lam[k + 1][i];
        }
    }
    for (k = 0; k < UNICYCLE_N - 1; ++k) {
        for (i = 0; i < UNICYCLE_NU; ++i) {
            s->u[k][i] = s->u[k + 1][i];
        }
        for (i = 0; i < UNICYCLE_NG; ++i) {
            s->mu_g[k][i] = s->mu_g[k + 1][i];
        }
        for (i = 0; i < UNICYCLE_NW; ++i) {
            s->mu_b[k][i] = s->mu_b[k + 1][i];
        }
    }
    /* the last stage: the x part of mu_b from mu_bN, the u part kept */
    for (i = 0; i < UNICYCLE_NX; ++i) {
        s->mu_b[UNICYCLE_N - 1][i] = s->mu_bN[i];
    }
    unicycle_clear_x0_multiplier(s);
    unicycle_ring_advance(&s->ring);
}

/* |domega_k| of stage k's slot (the denominator of rho_k). */
static unicycle_real unicycle_step_norm(const unicycle_solver *s, int k)
{
    const unicycle_stage_slot *slot = unicycle_ring_stage_const(&s->ring, k);
    unicycle_real d2 = UNICYCLE_R(0.0);
    int i;
    for (i = 0; i < UNICYCLE_NW; ++i) {
        d2 += slot->dw[i] * slot->dw[i] + slot->dmu_b[i] * slot->dmu_b[i];
    }
    for (i = 0; i < UNICYCLE_NX; ++i) {
        d2 += slot->dlam[i] * slot->dlam[i];
    }
    for (i = 0; i < UNICYCLE_NG; ++i) {
        d2 += slot->dmu_g[i] * slot->dmu_g[i];
    }
    return unicycle_sqrt(d2);
}

/* The number of stages among 0..N-2 to re-linearise (before the budget): N-1 after a
 * recovery, the fixed M, or adaptive M (algorithm.md section 12): the stages whose secant
 * residual rho_k |domega_k| exceeds eta times the KKT proxy of the point before the step,
 * between M_min and M_max. */
static int unicycle_M_now(const unicycle_solver *s)
{
    unicycle_real thr = s->M_eta * s->kkt_proxy;
    int k, n = 0;
    if (s->recovering > 0) {
        return UNICYCLE_N - 1; /* after a recovery: every block fresh until it has settled */
    }
    if (!s->M_adaptive) {
        return s->M < 0 ? 0 : (s->M > UNICYCLE_N - 1 ? UNICYCLE_N - 1 : s->M);
    }
    for (k = 0; k < UNICYCLE_N - 1; ++k) {
        if (s->rho[k] * unicycle_step_norm(s, k) > thr) {
            n += 1;
        }
    }
    return n < s->M_min ? s->M_min : (n > s->M_max ? s->M_max : n);
}

/* The stage among 0..N-2 not selected yet with the largest rho_k, ties to the lower index. */
static int unicycle_next_worst(const unicycle_solver *s)
{
    int k, best = -1;
    for (k = 0; k < UNICYCLE_N - 1; ++k) {
        if (!s->selected[k] && (best < 0 || s->rho[k] > s->rho[best])) {
            best = k;
        }
    }
    return best;
}

/* Step 4: re-linearise the stages with the largest rho_k: M of them (unicycle_M_now), then, with
 * a budget, further stages in rho order in the instant's prepare and in an extra iteration
 * after which no further iteration fits (algorithm.md section 12); each only while the
 * budget allows. The recomputed set (sorted, stage N-1 included) is recorded; the cost of
 * the stages beyond M in *ext_cost. */
static int unicycle_relinearise(unicycle_solver *s, int extra, double *ext_cost)
{
    int M = unicycle_M_now(s), m, k, n = 0, rc = UNICYCLE_OK, extend;
    double b0;
    for (k = 0; k < UNICYCLE_N; ++k) {
        s->selected[k] = 0;
    }
    extend =
        s->budget_unit != UNICYCLE_BUDGET_OFF && (!extra || !unicycle_budget_fits(s, s->cost_qp + s->cost_prepare));
    *ext_cost = 0.0;
    for (m = 0; m < UNICYCLE_N - 1; ++m) {
        if ((m >= M && !extend) || !unicycle_budget_fits(s, s->cost_stage)) {
            break;
        }
        k = unicycle_next_worst(s);
        b0 = unicycle_budget_now(s);
        rc = unicycle_stage_H(s, k);
        if (rc != UNICYCLE_OK) {
            break;
        }
        s->selected[k] = 1;
        if (s->budget_unit != UNICYCLE_BUDGET_OFF) {
            s->cost_stage = unicycle_budget_now(s) - b0;
            if (m >= M) {
                *ext_cost += s->cost_stage;
            }
        }
    }
    for (k = 0; k < UNICYCLE_N - 1; ++k) {
        if (s->selected[k]) {
            s->recomputed[n++] = k;
        }
    }
    s->instant_stages += n;
    s->recomputed[n++] = UNICYCLE_N - 1;
    s->n_recomputed = n;
    return rc;
}

/* Forward simulation from x[0] with the controls of the last good plan from its current age
 * on (use_plan) or the OCP file's guess, clipped to the bounds, into the iterate. Returns 1
 * when every node is finite and inside the box. */
static int unicycle_simulate(unicycle_solver *s, int use_plan)
{
    unicycle_real l = UNICYCLE_R(0.0);
    int k, j;
    for (k = 0; k < UNICYCLE_N; ++k) {
        j = s->plan_age + k > UNICYCLE_N - 1 ? UNICYCLE_N - 1 : s->plan_age + k;
        unicycle_clip_u(use_plan ? s->plan_u[j] : unicycle_guess_u[k], s->u[k]);
        if (unicycle_eval_stage_eval(s->x[k], s->u[k], s->p[k], s->x[k + 1], &l, s->mem.ev.tmp_g,
                                  &s->mem.ev.fun_work) != 0 ||
            !unicycle_lai_vec_finite(UNICYCLE_NX, s->x[k + 1])) {
            return 0;
        }
    }
    return unicycle_box_ok(s, &s->x[0][0], 0, 0, &s->u[0][0], 0, 0);
}

/* The OCP file's guess states from node `first` on and its controls (clipped) into the iterate. */
static void unicycle_guess_primal(unicycle_solver *s, int first)
{
    int k;
    for (k = first; k <= UNICYCLE_N; ++k) {
        unicycle_copy(s->x[k], unicycle_guess_x[k], UNICYCLE_NX);
    }
    for (k = 0; k < UNICYCLE_N; ++k) {
        unicycle_clip_u(unicycle_guess_u[k], s->u[k]);
    }
}

/* The linearisation of a re-initialisation: Gauss-Newton blocks when the problem has them
 * (convex in the cost, whatever the multipliers); the next prepares use the setting. */
static int unicycle_reinit_finish(unicycle_solver *s)
{
    int rc, hessian = s->hessian;
    s->hessian = UNICYCLE_HAS_GN ? UNICYCLE_HESSIAN_GAUSS_NEWTON : hessian;
    rc = unicycle_init_finish(s);
    s->hessian = hessian;
    return rc;
}

/* The last resort of a re-initialisation whose model evaluation failed (the model is not
 * finite at the measured or predicted state, e.g. an outlier of 1e6 rad/s): the OCP file's
 * guess whole, x_0 included, with zero multipliers; the next feedback's QP steps from it to
 * the measurement. Flag UNICYCLE_FLAG_REINIT_GUESS. */
static int unicycle_reinit_at_guess(unicycle_solver *s)
{
    unicycle_guess_primal(s, 0);
    unicycle_zero((UNICYCLE_N + 1) * UNICYCLE_NX, &s->lam[0][0]);
    unicycle_zero(UNICYCLE_N * UNICYCLE_NW, &s->mu_b[0][0]);
    unicycle_zero(UNICYCLE_NX, s->mu_bN);
    unicycle_zero(UNICYCLE_N * UNICYCLE_DIM(UNICYCLE_NG), &s->mu_g[0][0]);
    unicycle_zero(UNICYCLE_DIM(UNICYCLE_NR), s->mu_r);
    unicycle_zero(UNICYCLE_DIM(UNICYCLE_NE), s->nu);
    s->flags |= UNICYCLE_FLAG_REINIT_GUESS;
    return unicycle_reinit_finish(s);
}

/* The re-initialisation of the recovery from x_0 in place: a forward simulation with the last
 * good plan (else with the OCP file's guess controls; else the guess itself), the multipliers
 * of the iterate, every block recomputed (Gauss-Newton when the problem has it); when the
 * model fails there, the OCP file's guess whole (unicycle_reinit_at_guess). */
static int unicycle_reinit(unicycle_solver *s)
{
    int rc;
    if (!unicycle_simulate(s, 1) && !unicycle_simulate(s, 0)) {
        unicycle_guess_primal(s, 1);
    }
    rc = unicycle_reinit_finish(s);
    if (rc != UNICYCLE_OK) {
        rc = unicycle_reinit_at_guess(s);
    }
    if (rc != UNICYCLE_OK) {
        s->qp_ready = 0;
        return rc;
    }
    s->kkt_proxy = unicycle_kkt_proxy_eval(s);
    s->kkt_proxy_ref = s->kkt_proxy;
    s->n_failed = 0;
    s->recover_pending = 0;
    s->n_recoveries += 1;
    s->recovering = UNICYCLE_RECOVERY_FULL_RTI;
    s->flags |= UNICYCLE_FLAG_RECOVERED;
    return UNICYCLE_OK;
}

/* The automatic recovery (algorithm.md section 9): re-initialise from a forward simulation of
 * the predicted state phi(xhat0, u0) (unicycle_reinit). */
static int unicycle_recover(unicycle_solver *s, int shifted)
{
    unicycle_real l = UNICYCLE_R(0.0);
    int i;
    /* x_0: the state predicted for this instant from the last measurement and control; when
     * the last feedback had no usable measurement, the (shifted) iterate's x_0 */
    if (!s->xhat_fresh) {
        if (!shifted) {
            unicycle_copy(s->x[0], s->x[1], UNICYCLE_NX);
        }
    } else if (unicycle_eval_stage_eval(s->xhat0, s->u0_out, s->p[0], s->x[0], &l, s->mem.ev.tmp_g,
                                     &s->mem.ev.fun_work) != 0 ||
               !unicycle_lai_vec_finite(UNICYCLE_NX, s->x[0])) {
        unicycle_copy(s->x[0], s->xhat0, UNICYCLE_NX);
    }
    for (i = 0; i < UNICYCLE_NX; ++i) {
        if (!(unicycle_fabs(s->x[0][i]) <= UNICYCLE_DIVERGENCE_BOX * s->scale_x[i] + unicycle_fabs(s->xhat0[i]))) {
            unicycle_copy(s->x[0], s->xhat0, UNICYCLE_NX);
            break;
        }
    }
    return unicycle_reinit(s);
}

/* The recovery within a feedback (algorithm.md section 9): the QP of a finite measurement
 * failed (not by its iteration limit) or diverged; re-initialise from the measured state (x_0 = xhat0) and
 * solve the QP of the re-initialised iterate (cold, with the lm retries). Returns UNICYCLE_OK
 * with the QP status in *qs, or the status of a re-initialisation that could not start from
 * the measurement (the model failed there: UNICYCLE_ERR_NONFINITE_VALUE or UNICYCLE_ERR_FUNCTION;
 * the iterate is then the OCP file's guess, prepared, when the model is finite there). */
static int unicycle_feedback_recover(unicycle_solver *s, int *qs, int *retries)
{
    int i, rc, n_failed = s->n_failed;
    unicycle_copy(s->x[0], s->xhat0, UNICYCLE_NX);
    rc = unicycle_reinit(s);
    s->n_failed = n_failed; /* still the count of consecutive failed feedbacks */
    /* the measurement's instant: its prepare (with the shift) is still due */
    s->prepare_due = 1;
    s->shifted = 0;
    if (rc == UNICYCLE_OK && (s->flags & UNICYCLE_FLAG_REINIT_GUESS)) {
        /* the model failed at the measured state: no QP from it */
        rc = UNICYCLE_ERR_NONFINITE_VALUE;
    }
    if (rc != UNICYCLE_OK) {
        return rc;
    }
    for (i = 0; i < UNICYCLE_NX; ++i) {
        s->qp_in.x0[i] = UNICYCLE_R(0.0);
    }
    s->qp_in.hess_shift = s->lm;
    s->work += UNICYCLE_WORK_QP;
    *qs = unicycle_qp_attempt(s, 0);
    *qs = unicycle_feedback_lm_retries(s, *qs, retries);
    return UNICYCLE_OK;
}

/* The predicted step (algorithm.md section 9): after a failed feedback whose QP is still the
 * prepared one, the QP is solved for the state the iterate predicts for this instant
 * (dx_0 = 0; the measurement, absent or unusable, is left out) and its step taken; its
 * controls become the plan the next fallbacks read. A failure of this QP changes nothing. */
static void unicycle_predicted_step(unicycle_solver *s)
{
    int i, qs;
    for (i = 0; i < UNICYCLE_NX; ++i) {
        s->qp_in.x0[i] = UNICYCLE_R(0.0);
    }
    s->qp_in.hess_shift = s->lm;
    s->qp_settings.warm_start = 0;
    s->work += UNICYCLE_WORK_QP;
    qs = unicycle_qp_solve_bound(s);
    if (unicycle_feedback_check_step(s, qs) != UNICYCLE_OK) {
        return;
    }
    unicycle_store_domega(s);
    unicycle_take_step(s);
    unicycle_copy(&s->plan_u[0][0], &s->u[0][0], UNICYCLE_N * UNICYCLE_NU);
    s->plan_age = 0;
    if (!s->xhat_fresh) {
        /* no measurement to distrust: the model's prediction carries the loop */
        s->n_failed = 0;
        s->recover_pending = 0;
    }
    s->flags |= UNICYCLE_FLAG_PREDICTED;
}

static int unicycle_prepare_iteration(unicycle_solver *s, int extra);
static int unicycle_anytime(unicycle_solver *s);

int unicycle_prepare(unicycle_solver *s)
{
    int rc, hessian;
    unicycle_ensure_setup(s);
    if (!s->initialized) {
        return unicycle_ret(s, UNICYCLE_ERR_NOT_INITIALIZED);
    }
    if (!s->prepare_due) {
        /* a second prepare would shift the horizon twice */
        return unicycle_ret(s, UNICYCLE_ERR_ALREADY_PREPARED);
    }
    unicycle_clear_timings(s, UNICYCLE_PHASE_SHIFT, UNICYCLE_PHASE_ASSEMBLY);
    s->extra_iterations = 0;
    hessian = s->hessian;
    if (s->qp_ready && s->n_failed > 0 && !s->recover_pending && s->recovery &&
        s->mode == UNICYCLE_MODE_RECEDING && !(s->flags & UNICYCLE_FLAG_REINIT_GUESS)) {
        /* (not from the OCP file's guess: its plan is not the plant's) */
        unicycle_predicted_step(s);
    }
    s->qp_ready = 0;
    if (s->mode == UNICYCLE_MODE_RECEDING && s->plan_age < UNICYCLE_N) {
        s->plan_age += 1;
    }
    if (s->recover_pending && s->recovery && s->mode == UNICYCLE_MODE_RECEDING) {
        rc = unicycle_recover(s, 0);
    } else {
        /* the recovery phase: Gauss-Newton blocks (convex in the cost whatever the
         * multipliers), every block fresh */
        if (s->recovering > 0 && UNICYCLE_HAS_GN) {
            s->hessian = UNICYCLE_HESSIAN_GAUSS_NEWTON;
        }
        rc = unicycle_prepare_iteration(s, 0);
    }
    if (rc == UNICYCLE_OK) {
        /* the time left (algorithm.md section 12), with the Hessian of the recovery phase */
        if (s->recovering > 0 && UNICYCLE_HAS_GN) {
            s->hessian = UNICYCLE_HESSIAN_GAUSS_NEWTON;
        }
        rc = unicycle_anytime(s);
    }
    s->hessian = hessian;
    s->budget_used = unicycle_budget_now(s) - s->instant_start;
    if (rc == UNICYCLE_OK) {
        /* one prepare per sampling instant: the next needs a feedback first */
        s->prepare_due = 0;
        s->shifted = 0;
    }
    return unicycle_ret(s, rc);
}

/* Steps 1 to 7 of prepare (algorithm.md sections 4 and 9); extra: an iteration of the
 * anytime budget (section 12), without the shift, x_N kept. */
static int unicycle_prepare_iteration(unicycle_solver *s, int extra)
{
    unicycle_real xN_saved[UNICYCLE_NX];
    double t0, b_start = unicycle_budget_now(s), ext_cost = 0.0;
    int k, rc;

    /* 1. shift (once per sampling instant: a retry after a failed prepare does not) */
    t0 = unicycle_timer_now(&s->timer);
    if (s->mode == UNICYCLE_MODE_RECEDING && !s->shifted) {
        unicycle_shift(s);
        s->shifted = 1;
    }
    t0 = unicycle_timer_add(&s->timer, UNICYCLE_PHASE_SHIFT, t0);
    unicycle_copy(xN_saved, s->x[UNICYCLE_N], UNICYCLE_NX);

    /* 2. F_k and rho_k (eq. 16) of stages 0..N-2 (F_new kept for step 6) */
    for (k = 0; k < UNICYCLE_N - 1; ++k) {
        unicycle_stage_slot *slot = unicycle_ring_stage(&s->ring, k);
        rc = unicycle_stage_F(s, k);
        t0 = unicycle_timer_add(&s->timer, UNICYCLE_PHASE_GRADIENTS, t0);
        if (rc != UNICYCLE_OK) {
            return rc;
        }
        s->rho[k] = unicycle_ring_secant(slot, s->mem.ev.tmp_F, s->mem.ev.tmp_phi, s->mem.ev.tmp_g);
        /* stored as F_old in step 6, once nothing can fail */
        unicycle_copy(s->mem.ev.Fn_w[k], s->mem.ev.tmp_F, UNICYCLE_NW);
        unicycle_copy(s->mem.ev.Fn_phi[k], s->mem.ev.tmp_phi, UNICYCLE_NX);
        unicycle_copy(s->mem.ev.Fn_g[k], s->mem.ev.tmp_g, UNICYCLE_NG);
        t0 = unicycle_timer_add(&s->timer, UNICYCLE_PHASE_RHO, t0);
    }

    /* 3. stage N-1 fresh; in receding mode x_N <- phi_{N-1} before the terminal node */
    rc = unicycle_stage_F(s, UNICYCLE_N - 1);
    t0 = unicycle_timer_add(&s->timer, UNICYCLE_PHASE_GRADIENTS, t0);
    if (rc != UNICYCLE_OK) {
        return rc;
    }
    if (s->mode == UNICYCLE_MODE_RECEDING && !extra) {
        unicycle_copy(s->x[UNICYCLE_N], s->mem.ev.tmp_phi, UNICYCLE_NX);
    }
    unicycle_ring_store_F(unicycle_ring_stage(&s->ring, UNICYCLE_N - 1), s->mem.ev.tmp_F, s->mem.ev.tmp_phi,
                       s->mem.ev.tmp_g);
    s->rho[UNICYCLE_N - 1] = UNICYCLE_R(0.0);
    rc = unicycle_stage_H(s, UNICYCLE_N - 1);
    if (rc == UNICYCLE_OK) {
        t0 = unicycle_timer_now(&s->timer);
        rc = unicycle_term_F(s);
        unicycle_timer_add(&s->timer, UNICYCLE_PHASE_GRADIENTS, t0);
    }
    if (rc == UNICYCLE_OK) {
        rc = unicycle_term_H(s);
    }

    /* 4. re-linearise the M stages with the largest rho_k (and more as the budget allows) */
    if (rc == UNICYCLE_OK) {
        rc = unicycle_relinearise(s, extra, &ext_cost);
    }

    /* 5. cost_hessian fresh: every stage whose H was not computed above gets
     *    Ht = reg(A_dyn + A_l) with A_l at the current point (Phit, Ct, A_dyn kept) */
    if (rc == UNICYCLE_OK && s->cost_hessian) {
        for (k = 0; k < UNICYCLE_N - 1 && rc == UNICYCLE_OK; ++k) {
            unicycle_stage_slot *slot = unicycle_ring_stage(&s->ring, k);
            if (s->selected[k]) {
                continue;
            }
            rc = unicycle_stage_Al(s, k);
            if (rc != UNICYCLE_OK) {
                break;
            }
            unicycle_ring_add_A_dyn(slot, s->mem.ev.tmp_Al, s->mem.ev.tmp_A);
            rc = unicycle_regularize(s, UNICYCLE_NW, s->mem.ev.tmp_A);
            if (rc == UNICYCLE_OK) {
                unicycle_copy(slot->Ht, s->mem.ev.tmp_A, UNICYCLE_NW * UNICYCLE_NW);
            }
        }
    }
    if (rc != UNICYCLE_OK) {
        /* leave the iterate as it was after step 1 */
        unicycle_copy(s->x[UNICYCLE_N], xN_saved, UNICYCLE_NX);
        return rc;
    }

    /* 6. F_new of step 2 becomes F_old; QP vectors (the fresh A blocks were regularised
     *    when stored) */
    for (k = 0; k < UNICYCLE_N - 1; ++k) {
        unicycle_ring_store_F(unicycle_ring_stage(&s->ring, k), s->mem.ev.Fn_w[k], s->mem.ev.Fn_phi[k],
                           s->mem.ev.Fn_g[k]);
    }
    unicycle_assemble(s);
    s->qp_ready = 1;

    /* 7. the divergence test of the prepared iterate (algorithm.md section 9) */
    s->kkt_proxy = unicycle_kkt_proxy_eval(s);
    unicycle_lm_prepared(s); /* the automatic Levenberg-Marquardt term (section 10) */
    if (s->budget_unit != UNICYCLE_BUDGET_OFF) {
        s->cost_prepare = unicycle_budget_now(s) - b_start - ext_cost;
    }
    if (unicycle_iterate_diverged(s)) {
        s->flags |= UNICYCLE_FLAG_DIVERGED;
        if (s->recovery && s->mode == UNICYCLE_MODE_RECEDING) {
            return unicycle_recover(s, 1);
        }
    }
    return UNICYCLE_OK;
}

/* ---- anytime (algorithm.md section 12) -------------------------------------------------- */

/* One extra iteration on the next instant's problem: the prepared QP for the state the plan
 * predicts (dx_0 = 0), its full step, then a prepare iteration without the shift. A QP not
 * solved (or a step outside the box) changes nothing and returns UNICYCLE_ERR_QP. */
static int unicycle_extra_iteration(unicycle_solver *s)
{
    unicycle_real lm = s->lm;
    double b0 = unicycle_budget_now(s);
    int i, qs;
    for (i = 0; i < UNICYCLE_NX; ++i) {
        s->qp_in.x0[i] = UNICYCLE_R(0.0);
    }
    unicycle_lm_measured(s);
    qs = unicycle_feedback_qp(s);
    if (unicycle_feedback_check_step(s, qs) != UNICYCLE_OK) {
        s->lm = lm;
        s->lm_uncapped = -UNICYCLE_R(1.0);
        return UNICYCLE_ERR_QP;
    }
    s->cost_qp = unicycle_budget_now(s) - b0;
    unicycle_store_domega(s);
    unicycle_take_step(s);
    unicycle_lm_feedback(s, UNICYCLE_OK);
    return unicycle_prepare_iteration(s, 1);
}

/* The time left after prepare (algorithm.md section 12): extra iterations while the KKT proxy
 * exceeds the tolerance and one more fits in the budget. The last feedback's QP figures are
 * kept for unicycle_get_qp_status and unicycle_get_qp_iterations. */
static int unicycle_anytime(unicycle_solver *s)
{
    int qp_status = s->qp_status, qp_iterations = s->qp_iterations, cold = s->qp_cold_retry, rc = UNICYCLE_OK;
    if (s->budget_unit == UNICYCLE_BUDGET_OFF) {
        return UNICYCLE_OK;
    }
    while (s->extra_iterations < UNICYCLE_ANYTIME_MAX_ITER && s->qp_ready && s->kkt_proxy > s->anytime_tol &&
           unicycle_budget_fits(s, s->cost_qp + s->cost_prepare)) {
        rc = unicycle_extra_iteration(s);
        if (rc != UNICYCLE_OK) {
            break;
        }
        s->extra_iterations += 1;
    }
    s->qp_status = qp_status;
    s->qp_iterations = qp_iterations;
    s->qp_cold_retry = cold;
    return rc == UNICYCLE_ERR_QP ? UNICYCLE_OK : rc;
}

/* ---- KKT ---------------------------------------------------------------------------- */

int unicycle_kkt_eval(unicycle_solver *s, const unicycle_real *xhat0, unicycle_real *kkt4)
{
    unicycle_real parts[4];
    double t0;
    int i, rc;

    unicycle_ensure_setup(s);
    if (!s->initialized) {
        return unicycle_ret(s, UNICYCLE_ERR_NOT_INITIALIZED);
    }
    if (xhat0 && !unicycle_lai_vec_finite(UNICYCLE_NX, xhat0)) {
        return unicycle_ret(s, UNICYCLE_ERR_NONFINITE_INPUT);
    }
    s->timer.t[UNICYCLE_PHASE_KKT] = UNICYCLE_R(0.0);
    t0 = unicycle_timer_now(&s->timer);
    rc = unicycle_kkt_measure(s, xhat0 ? xhat0 : s->xhat0, parts);
    unicycle_timer_add(&s->timer, UNICYCLE_PHASE_KKT, t0);
    if (rc != UNICYCLE_OK) {
        return unicycle_ret(s, rc);
    }
    for (i = 0; i < 4; ++i) {
        s->kkt[i] = parts[i];
        if (kkt4) {
            kkt4[i] = parts[i];
        }
    }
    return unicycle_ret(s, UNICYCLE_OK);
}

unicycle_real unicycle_get_kkt(const unicycle_solver *s)
{
    unicycle_real m = s->kkt[0];
    int i;
    for (i = 1; i < 4; ++i) {
        m = s->kkt[i] > m ? s->kkt[i] : m;
    }
    return m;
}

/* ---- getters ------------------------------------------------------------------------ */

void unicycle_get_x(const unicycle_solver *s, unicycle_real *x)
{
    unicycle_copy(x, &s->x[0][0], (UNICYCLE_N + 1) * UNICYCLE_NX);
}

void unicycle_get_u(const unicycle_solver *s, unicycle_real *u)
{
    unicycle_copy(u, &s->u[0][0], UNICYCLE_N * UNICYCLE_NU);
}

void unicycle_get_lam(const unicycle_solver *s, unicycle_real *lam)
{
    unicycle_copy(lam, &s->lam[0][0], (UNICYCLE_N + 1) * UNICYCLE_NX);
}

void unicycle_get_mu_g(const unicycle_solver *s, unicycle_real *mu_g)
{
    int k, i;
    for (k = 0; k < UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NG; ++i) {
            mu_g[k * UNICYCLE_NG + i] = s->mu_g[k][i];
        }
    }
}

void unicycle_get_mu_b(const unicycle_solver *s, unicycle_real *mu_b)
{
    unicycle_copy(mu_b, &s->mu_b[0][0], UNICYCLE_N * UNICYCLE_NW);
}

void unicycle_get_mu_bN(const unicycle_solver *s, unicycle_real *mu_bN)
{
    unicycle_copy(mu_bN, s->mu_bN, UNICYCLE_NX);
}

void unicycle_get_mu_r(const unicycle_solver *s, unicycle_real *mu_r)
{
    unicycle_copy(mu_r, s->mu_r, UNICYCLE_NR);
}

void unicycle_get_nu(const unicycle_solver *s, unicycle_real *nu)
{
    unicycle_copy(nu, s->nu, UNICYCLE_NE);
}

void unicycle_get_rho(const unicycle_solver *s, unicycle_real *rho)
{
    unicycle_copy(rho, s->rho, UNICYCLE_N);
}

int unicycle_get_recomputed(const unicycle_solver *s, int *stages)
{
    int i;
    for (i = 0; i < s->n_recomputed; ++i) {
        stages[i] = s->recomputed[i];
    }
    return s->n_recomputed;
}

int unicycle_get_qp_iterations(const unicycle_solver *s)
{
    return s->qp_iterations;
}

int unicycle_get_qp_status(const unicycle_solver *s)
{
    return s->qp_status;
}

/* The bound of side (-1 lower, else upper) from the arrays lo, up at entry i. */
static unicycle_real unicycle_side_bound(const unicycle_real *lo, const unicycle_real *up, int i, int side)
{
    return side > 0 ? up[i] : lo[i];
}

int unicycle_get_qp_infeasible_row(const unicycle_solver *s, unicycle_row_info *row)
{
    int k, j, side;
    if (s->qp_status != UNICYCLE_QP_PRIMAL_INFEASIBLE ||
        !unicycle_qp_infeasible_row(&s->mem.qp.work, &s->qp_in, &k, &j, &side)) {
        return 0;
    }
    row->stage = k;
    row->side = side;
    if (j < UNICYCLE_NX) {
        row->kind = UNICYCLE_ROW_STATE;
        row->index = j;
        row->bound = unicycle_side_bound(unicycle_lbx, unicycle_ubx, j, side);
    } else if (k < UNICYCLE_N && j < UNICYCLE_NW) {
        row->kind = UNICYCLE_ROW_CONTROL;
        row->index = j - UNICYCLE_NX;
        row->bound = unicycle_side_bound(unicycle_lbu, unicycle_ubu, row->index, side);
    } else if (k < UNICYCLE_N) {
        row->kind = UNICYCLE_ROW_PATH;
        row->index = j - UNICYCLE_NW;
        row->bound = unicycle_side_bound(unicycle_lg, unicycle_ug, row->index, side);
    } else if (j < UNICYCLE_NX + UNICYCLE_NR) {
        row->kind = UNICYCLE_ROW_TERMINAL;
        row->index = j - UNICYCLE_NX;
        row->bound = unicycle_side_bound(unicycle_lr, unicycle_ur, row->index, side);
    } else {
        row->kind = UNICYCLE_ROW_TERMINAL_EQ;
        row->index = j - UNICYCLE_NX - UNICYCLE_NR;
        row->bound = UNICYCLE_R(0.0);
    }
    return 1;
}

int unicycle_get_flags(const unicycle_solver *s)
{
    return s->flags;
}

void unicycle_get_u0(const unicycle_solver *s, unicycle_real *u0)
{
    unicycle_copy(u0, s->u0_out, UNICYCLE_NU);
}

int unicycle_get_recoveries(const unicycle_solver *s)
{
    return s->n_recoveries;
}

int unicycle_get_failed_feedbacks(const unicycle_solver *s)
{
    return s->n_failed;
}

unicycle_real unicycle_get_kkt_proxy(const unicycle_solver *s)
{
    return s->kkt_proxy;
}

void unicycle_get_scales(const unicycle_solver *s, unicycle_real *scale_x, unicycle_real *scale_u)
{
    if (scale_x) {
        unicycle_copy(scale_x, s->scale_x, UNICYCLE_NX);
    }
    if (scale_u) {
        unicycle_copy(scale_u, s->scale_u, UNICYCLE_NU);
    }
}

int unicycle_get_qp_cold_retry(const unicycle_solver *s)
{
    return s->qp_cold_retry;
}

int unicycle_get_status(const unicycle_solver *s)
{
    return s->status;
}

int unicycle_is_initialized(const unicycle_solver *s)
{
    return s->magic == UNICYCLE_MAGIC && s->initialized;
}

int unicycle_get_ring_head(const unicycle_solver *s)
{
    return s->ring.ring_head;
}

void unicycle_get_timings(const unicycle_solver *s, double *t)
{
    int i;
    for (i = 0; i < UNICYCLE_N_PHASES; ++i) { /* times are double in both precisions */
        t[i] = s->timer.t[i];
    }
}
