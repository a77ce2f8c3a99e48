/* The globalised first solve (docs/algorithm.md section 15; constants and the caller's
 * memory in unicycle_globalise.h, the API in unicycle_solver.h).
 *
 * One step from the prepared iterate (after init or the previous step: every block fresh),
 * in fixed mode whatever the setting: the merit parts f (cost and the prices of the soft
 * sides) and c (l1 violation of the hard rows) at the iterate; the QP of the iterate through
 * unicycle_feedback (the automatic lm and its retries), which takes the full step; the penalty
 * raised from the QP's multipliers; the backtracking line search on phi = f + nu c from the
 * iterate along that step; then unicycle_init at the accepted point with the interpolated
 * multipliers (every block fresh, the next QP prepared). Only the public API, the generated
 * functions, the ring and the problem data are used, so the real-time calls are unchanged.
 * The Python reference is unicycle_codegen/reference/globalise.py.
 */
#include <float.h>
#include <math.h>

#include "unicycle_globalise.h"
#include "unicycle_linalg.h"
#include "unicycle_problem.h"
#include "unicycle_solver.h"

static void unicycle_glob_copy(unicycle_real *dst, const unicycle_real *src, int n)
{
    int i;
    for (i = 0; i < n; ++i) {
        dst[i] = src[i];
    }
}

size_t unicycle_glob_sizeof(void)
{
    return sizeof(unicycle_glob);
}

/* A zero-filled unicycle_glob: no penalty, no counts, no KKT measure yet (kkt_best 0). */
static void unicycle_glob_reset(unicycle_glob *g)
{
    g->penalty = UNICYCLE_R(0.0);
    g->alpha = UNICYCLE_R(0.0);
    g->merit = UNICYCLE_R(0.0);
    g->slope = UNICYCLE_R(0.0);
    g->kkt = UNICYCLE_R(0.0);
    g->kkt_best = UNICYCLE_R(0.0);
    g->by_kkt = 0;
    g->iterations = 0;
    g->trials = 0;
    g->reason = UNICYCLE_GLOB_OK;
}

void unicycle_glob_get_info(const unicycle_glob *g, unicycle_glob_info *info)
{
    info->iterations = g->iterations;
    info->trials = g->trials;
    info->reason = g->reason;
    info->by_kkt = g->by_kkt;
    info->penalty = g->penalty;
    info->alpha = g->alpha;
    info->merit = g->merit;
    info->slope = g->slope;
    info->kkt = g->kkt;
}

/* The price l1 s + 0.5 l2 s^2 of a side violated by s >= 0. */
static unicycle_real unicycle_glob_price(unicycle_real s, unicycle_real l1, unicycle_real l2)
{
    return l1 * s + UNICYCLE_R(0.5) * l2 * s * s;
}

/* Rows lo <= v <= up (n of them, soft weights w: 4 rows of stride ws, NULL: all hard): the
 * l1 violation of the hard sides into *hard, the prices of the soft sides into *price. */
static void unicycle_glob_rows(int n, const unicycle_real *v, const unicycle_real *lo, const unicycle_real *up,
                            const unicycle_real *w, int ws, unicycle_real *hard, unicycle_real *price)
{
    int i, side;
    for (i = 0; i < n; ++i) {
        for (side = 0; side < 2; ++side) {
            unicycle_real bound = side == 0 ? lo[i] : up[i];
            unicycle_real sv;
            if (!isfinite(bound)) {
                continue;
            }
            sv = side == 0 ? bound - v[i] : v[i] - bound;
            sv = sv > UNICYCLE_R(0.0) ? sv : UNICYCLE_R(0.0);
            if (w && (w[side * ws + i] > UNICYCLE_R(0.0) || w[(2 + side) * ws + i] > UNICYCLE_R(0.0))) {
                *price += unicycle_glob_price(sv, w[side * ws + i], w[(2 + side) * ws + i]);
            } else {
                *hard += sv;
            }
        }
    }
}

#if UNICYCLE_NSOFT > 0
#define UNICYCLE_GLOB_SOFT_X (&unicycle_soft_x[0][0])
#define UNICYCLE_GLOB_SOFT_G (&unicycle_soft_g[0][0])
#define UNICYCLE_GLOB_SOFT_R (&unicycle_soft_r[0][0])
#else
#define UNICYCLE_GLOB_SOFT_X ((const unicycle_real *)0)
#define UNICYCLE_GLOB_SOFT_G ((const unicycle_real *)0)
#define UNICYCLE_GLOB_SOFT_R ((const unicycle_real *)0)
#endif

/* f and c at the primal point (x, u) for xhat0; N + 1 work units. UNICYCLE_OK, or the status of
 * a function that failed or was not finite. */
static int unicycle_glob_merit_parts(unicycle_solver *s, const unicycle_real *xhat0, const unicycle_real (*x)[UNICYCLE_NX],
                                  const unicycle_real (*u)[UNICYCLE_NU], unicycle_real *f, unicycle_real *c)
{
    unicycle_real phi[UNICYCLE_NX], g[UNICYCLE_DIM(UNICYCLE_NG)], r[UNICYCLE_DIM(UNICYCLE_NR)], r_eq[UNICYCLE_DIM(UNICYCLE_NE)];
    unicycle_real l = UNICYCLE_R(0.0), E = UNICYCLE_R(0.0), ft = UNICYCLE_R(0.0), ct = UNICYCLE_R(0.0);
    unicycle_real sl = UNICYCLE_R(0.0), sc = UNICYCLE_R(0.0);
    int k, i;

    s->anytime.work += (double)(UNICYCLE_N + 1);
    /* the cost and the l1 sums are added in the reference's order: the stage costs, then E;
     * |x_0 - xhat0|, the dynamics, r_eq, then the rows node by node */
    for (i = 0; i < UNICYCLE_NX; ++i) {
        ct += unicycle_fabs(x[0][i] - xhat0[i]);
    }
    for (k = 0; k < UNICYCLE_N; ++k) {
        if (unicycle_eval_stage_eval(x[k], u[k], s->p[k], phi, &l, g, &s->mem.ev.fun_work) != 0) {
            return UNICYCLE_ERR_FUNCTION;
        }
        if (!unicycle_lai_vec_finite(UNICYCLE_NX, phi) || !unicycle_lai_vec_finite(UNICYCLE_NG, g) || !isfinite(l)) {
            return UNICYCLE_ERR_NONFINITE_VALUE;
        }
        sl += l;
        for (i = 0; i < UNICYCLE_NX; ++i) {
            sc += unicycle_fabs(x[k + 1][i] - phi[i]);
        }
        unicycle_glob_copy(s->mem.ev.Fn_g[k], g, UNICYCLE_NG);
    }
    if (unicycle_eval_term_eval(x[UNICYCLE_N], s->p[UNICYCLE_N], &E, r, r_eq, &s->mem.ev.fun_work) != 0) {
        return UNICYCLE_ERR_FUNCTION;
    }
    if (!isfinite(E) || !unicycle_lai_vec_finite(UNICYCLE_NR, r) || !unicycle_lai_vec_finite(UNICYCLE_NE, r_eq)) {
        return UNICYCLE_ERR_NONFINITE_VALUE;
    }
    ft = sl + E;
    ct += sc;
    for (i = 0; i < UNICYCLE_NE; ++i) {
        ct += unicycle_fabs(r_eq[i]);
    }
    for (k = 0; k < UNICYCLE_N; ++k) {
        if (k > 0) {
            unicycle_glob_rows(UNICYCLE_NX, x[k], unicycle_lbx, unicycle_ubx, UNICYCLE_GLOB_SOFT_X, UNICYCLE_NX, &ct, &ft);
        }
        unicycle_glob_rows(UNICYCLE_NU, u[k], unicycle_lbu, unicycle_ubu, 0, UNICYCLE_NU, &ct, &ft);
        unicycle_glob_rows(UNICYCLE_NG, s->mem.ev.Fn_g[k], unicycle_lg_k[k], unicycle_ug_k[k], UNICYCLE_GLOB_SOFT_G,
                        UNICYCLE_DIM(UNICYCLE_NG), &ct, &ft);
    }
    unicycle_glob_rows(UNICYCLE_NX, x[UNICYCLE_N], unicycle_lbx, unicycle_ubx, UNICYCLE_GLOB_SOFT_X, UNICYCLE_NX, &ct, &ft);
    unicycle_glob_rows(UNICYCLE_NR, r, unicycle_lr, unicycle_ur, UNICYCLE_GLOB_SOFT_R, UNICYCLE_DIM(UNICYCLE_NR), &ct, &ft);
    *f = ft;
    *c = ct;
    return UNICYCLE_OK;
}

#if UNICYCLE_NSOFT > 0
/* The soft prices of rows v (n, weights w of stride ws), the hard sides ignored. */
static unicycle_real unicycle_glob_soft_price(int n, const unicycle_real *v, const unicycle_real *lo,
                                        const unicycle_real *up, const unicycle_real *w, int ws)
{
    unicycle_real hard = UNICYCLE_R(0.0), price = UNICYCLE_R(0.0);
    unicycle_glob_rows(n, v, lo, up, w, ws, &hard, &price);
    return price;
}
#endif

/* sum_soft psi(v_lin) - psi(v) along the step (x - g->x, u - g->u) with the blocks of the
 * iterate before it (the slots and the terminal blocks of the QP just solved). */
static unicycle_real unicycle_glob_soft_change(unicycle_solver *s, unicycle_glob *g)
{
    unicycle_real total = UNICYCLE_R(0.0);
#if UNICYCLE_NSOFT > 0
    unicycle_real v[UNICYCLE_NX], dw[UNICYCLE_NW];
    int k, i, j;
    for (k = 1; k <= UNICYCLE_N; ++k) {
        total += unicycle_glob_soft_price(UNICYCLE_NX, s->x[k], unicycle_lbx, unicycle_ubx, UNICYCLE_GLOB_SOFT_X, UNICYCLE_NX) -
                 unicycle_glob_soft_price(UNICYCLE_NX, g->x[k], unicycle_lbx, unicycle_ubx, UNICYCLE_GLOB_SOFT_X, UNICYCLE_NX);
    }
    for (k = 0; k < UNICYCLE_N && UNICYCLE_NG > 0; ++k) {
        const unicycle_stage_slot *slot = unicycle_ring_stage_const(&s->ring, k);
        for (i = 0; i < UNICYCLE_NX; ++i) {
            dw[i] = s->x[k][i] - g->x[k][i];
        }
        for (i = 0; i < UNICYCLE_NU; ++i) {
            dw[UNICYCLE_NX + i] = s->u[k][i] - g->u[k][i];
        }
        for (j = 0; j < UNICYCLE_NG; ++j) {
            unicycle_real acc = slot->g[j];
            for (i = 0; i < UNICYCLE_NW; ++i) {
                acc += slot->Ct[j + i * UNICYCLE_DIM(UNICYCLE_NG)] * dw[i];
            }
            g->lin_g[k][j] = acc;
        }
        total += unicycle_glob_soft_price(UNICYCLE_NG, g->lin_g[k], unicycle_lg_k[k], unicycle_ug_k[k], UNICYCLE_GLOB_SOFT_G,
                                       UNICYCLE_DIM(UNICYCLE_NG)) -
                 unicycle_glob_soft_price(UNICYCLE_NG, slot->g, unicycle_lg_k[k], unicycle_ug_k[k], UNICYCLE_GLOB_SOFT_G,
                                       UNICYCLE_DIM(UNICYCLE_NG));
    }
    if (UNICYCLE_NR > 0) {
        for (i = 0; i < UNICYCLE_NX; ++i) {
            v[i] = s->x[UNICYCLE_N][i] - g->x[UNICYCLE_N][i];
        }
        for (j = 0; j < UNICYCLE_NR; ++j) {
            unicycle_real acc = s->r[j];
            for (i = 0; i < UNICYCLE_NX; ++i) {
                acc += s->R[j + i * UNICYCLE_DIM(UNICYCLE_NR)] * v[i];
            }
            g->lin_r[j] = acc;
        }
        total +=
            unicycle_glob_soft_price(UNICYCLE_NR, g->lin_r, unicycle_lr, unicycle_ur, UNICYCLE_GLOB_SOFT_R,
                                  UNICYCLE_DIM(UNICYCLE_NR)) -
            unicycle_glob_soft_price(UNICYCLE_NR, s->r, unicycle_lr, unicycle_ur, UNICYCLE_GLOB_SOFT_R, UNICYCLE_DIM(UNICYCLE_NR));
    }
#else
    (void)s;
    (void)g;
#endif
    return total;
}

/* The largest multiplier of the iterate (the QP's after the full step). */
static unicycle_real unicycle_glob_max_multiplier(const unicycle_solver *s)
{
    unicycle_real m = UNICYCLE_R(0.0);
    int k, i;
    for (k = 0; k <= UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NX; ++i) {
            m = unicycle_fmax(m, unicycle_fabs(s->lam[k][i]));
        }
    }
    for (k = 0; k < UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NG; ++i) {
            m = unicycle_fmax(m, unicycle_fabs(s->mu_g[k][i]));
        }
        for (i = 0; i < UNICYCLE_NW; ++i) {
            m = unicycle_fmax(m, unicycle_fabs(s->mu_b[k][i]));
        }
    }
    for (i = 0; i < UNICYCLE_NX; ++i) {
        m = unicycle_fmax(m, unicycle_fabs(s->mu_bN[i]));
    }
    for (i = 0; i < UNICYCLE_NR; ++i) {
        m = unicycle_fmax(m, unicycle_fabs(s->mu_r[i]));
    }
    for (i = 0; i < UNICYCLE_NE; ++i) {
        m = unicycle_fmax(m, unicycle_fabs(s->nu[i]));
    }
    return m;
}

/* y <- y + alpha (y_QP - y) of one array: y in g, y_QP in the solver. */
static void unicycle_glob_blend(int n, unicycle_real *y, const unicycle_real *yq, unicycle_real alpha)
{
    int i;
    for (i = 0; i < n; ++i) {
        y[i] = alpha == UNICYCLE_R(1.0) ? yq[i] : y[i] + alpha * (yq[i] - y[i]);
    }
}

/* init at the point of g (x, u: xt, ut when trial, else the saved iterate) and its multipliers. */
static int unicycle_glob_init_at(unicycle_solver *s, unicycle_glob *g, const unicycle_real *xhat0, int trial)
{
    return unicycle_init(s, xhat0, trial ? &g->xt[0][0] : &g->x[0][0], trial ? &g->ut[0][0] : &g->u[0][0],
                      &g->lam[0][0], UNICYCLE_NG > 0 ? &g->mu_g[0][0] : 0, &g->mu_b[0][0], g->mu_bN,
                      UNICYCLE_NR > 0 ? g->mu_r : 0, UNICYCLE_NE > 0 ? g->nu : 0);
}

/* The KKT measure of the solver's iterate (unicycle_kkt_eval, counted as N + 1 work units). */
static int unicycle_glob_kkt(unicycle_solver *s, const unicycle_real *xhat0, unicycle_real *kkt)
{
    unicycle_real kkt4[4];
    int i, rc;
    s->anytime.work += (double)(UNICYCLE_N + 1);
    rc = unicycle_kkt_eval(s, xhat0, kkt4);
    *kkt = kkt4[0];
    for (i = 1; i < 4; ++i) {
        *kkt = unicycle_fmax(*kkt, kkt4[i]);
    }
    return rc;
}

static int unicycle_glob_step_fixed(unicycle_solver *s, unicycle_glob *g, const unicycle_real *xhat0)
{
    unicycle_real f0, c0, f, c, nu, ymax, a_dot_p, slope, phi0, phi = UNICYCLE_R(0.0), floor_, alpha;
    unicycle_real u0[UNICYCLE_NU], kkt;
    int k, i, rc, trial, accepted = 0;

    unicycle_glob_copy(&g->x[0][0], &s->x[0][0], (UNICYCLE_N + 1) * UNICYCLE_NX);
    unicycle_glob_copy(&g->u[0][0], &s->u[0][0], UNICYCLE_N * UNICYCLE_NU);
    unicycle_glob_copy(&g->lam[0][0], &s->lam[0][0], (UNICYCLE_N + 1) * UNICYCLE_NX);
    unicycle_glob_copy(&g->mu_g[0][0], &s->mu_g[0][0], UNICYCLE_N * UNICYCLE_DIM(UNICYCLE_NG));
    unicycle_glob_copy(&g->mu_b[0][0], &s->mu_b[0][0], UNICYCLE_N * UNICYCLE_NW);
    unicycle_glob_copy(g->mu_bN, s->mu_bN, UNICYCLE_NX);
    unicycle_glob_copy(g->mu_r, s->mu_r, UNICYCLE_DIM(UNICYCLE_NR));
    unicycle_glob_copy(g->nu, s->nu, UNICYCLE_DIM(UNICYCLE_NE));
    g->by_kkt = 0;
    rc = unicycle_glob_kkt(s, xhat0, &kkt);
    if (rc == UNICYCLE_OK) {
        /* 0: no KKT measure yet (a zero-filled unicycle_glob) */
        g->kkt_best = g->kkt_best > UNICYCLE_R(0.0) ? unicycle_fmin(g->kkt_best, kkt) : kkt;
        rc = unicycle_glob_merit_parts(s, xhat0, (const unicycle_real(*)[UNICYCLE_NX])g->x,
                                    (const unicycle_real(*)[UNICYCLE_NU])g->u, &f0, &c0);
    }
    if (rc != UNICYCLE_OK) {
        g->reason = UNICYCLE_GLOB_FUNCTION;
        return rc;
    }
    rc = unicycle_feedback(s, xhat0, u0);
    if (rc != UNICYCLE_OK) {
        g->reason = rc == UNICYCLE_ERR_DIVERGED ? UNICYCLE_GLOB_STEP_BOX
                    : rc == UNICYCLE_ERR_QP     ? UNICYCLE_GLOB_QP
                                             : UNICYCLE_GLOB_FUNCTION;
        return rc;
    }
    /* the cost's slope along the step: the QP's gradient a (every block fresh) */
    a_dot_p = UNICYCLE_R(0.0);
    for (k = 0; k < UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NX; ++i) {
            a_dot_p += s->qp_in.g[k][i] * (s->x[k][i] - g->x[k][i]);
        }
        for (i = 0; i < UNICYCLE_NU; ++i) {
            a_dot_p += s->qp_in.g[k][UNICYCLE_NX + i] * (s->u[k][i] - g->u[k][i]);
        }
    }
    for (i = 0; i < UNICYCLE_NX; ++i) {
        a_dot_p += s->qp_in.gN[i] * (s->x[UNICYCLE_N][i] - g->x[UNICYCLE_N][i]);
    }
    ymax = unicycle_glob_max_multiplier(s);
    if (g->penalty < UNICYCLE_GLOB_PENALTY_MARGIN * ymax) {
        g->penalty = UNICYCLE_GLOB_PENALTY_RAISE * ymax;
    }
    nu = g->penalty;
    g->a_dot_p = a_dot_p;
    slope = a_dot_p - nu * c0 + unicycle_glob_soft_change(s, g);
    phi0 = f0 + nu * c0;
    floor_ = UNICYCLE_GLOB_MERIT_FLOOR * UNICYCLE_REAL_EPSILON * (UNICYCLE_R(1.0) + unicycle_fabs(phi0));
    alpha = UNICYCLE_R(1.0);
    g->trials = 0;
    for (trial = 0; trial < UNICYCLE_GLOB_MAX_TRIALS; ++trial) {
        g->trials = trial + 1;
        for (k = 0; k <= UNICYCLE_N; ++k) {
            for (i = 0; i < UNICYCLE_NX; ++i) {
                g->xt[k][i] =
                    alpha == UNICYCLE_R(1.0) ? s->x[k][i] : g->x[k][i] + alpha * (s->x[k][i] - g->x[k][i]);
            }
        }
        for (k = 0; k < UNICYCLE_N; ++k) {
            for (i = 0; i < UNICYCLE_NU; ++i) {
                g->ut[k][i] =
                    alpha == UNICYCLE_R(1.0) ? s->u[k][i] : g->u[k][i] + alpha * (s->u[k][i] - g->u[k][i]);
            }
        }
        rc = unicycle_glob_merit_parts(s, xhat0, (const unicycle_real(*)[UNICYCLE_NX])g->xt,
                                    (const unicycle_real(*)[UNICYCLE_NU])g->ut, &f, &c);
        if (rc == UNICYCLE_OK) {
            phi = f + nu * c;
            if (phi <= phi0 + UNICYCLE_GLOB_ARMIJO * alpha * unicycle_fmin(slope, UNICYCLE_R(0.0)) + floor_) {
                accepted = 1;
                break;
            }
        }
        /* the full step also when it lowers the KKT measure enough (the solver's iterate is
         * the full step with the QP's multipliers): the merit function may refuse the steps
         * of a fast local convergence along a curved constraint (the Maratos effect) */
        if (trial == 0 && unicycle_glob_kkt(s, xhat0, &kkt) == UNICYCLE_OK &&
            kkt <= UNICYCLE_GLOB_KKT_FACTOR * g->kkt_best) {
            g->kkt_best = kkt;
            g->by_kkt = 1;
            accepted = 1;
            break;
        }
        alpha *= UNICYCLE_GLOB_BACKTRACK;
    }
    g->slope = slope;
    if (!accepted) {
        /* the iterate as it was, its QP prepared again */
        rc = unicycle_glob_init_at(s, g, xhat0, 0);
        g->reason = UNICYCLE_GLOB_LINE_SEARCH;
        return rc != UNICYCLE_OK ? rc : UNICYCLE_ERR_DIVERGED;
    }
    unicycle_glob_blend((UNICYCLE_N + 1) * UNICYCLE_NX, &g->lam[0][0], &s->lam[0][0], alpha);
    unicycle_glob_blend(UNICYCLE_N * UNICYCLE_DIM(UNICYCLE_NG), &g->mu_g[0][0], &s->mu_g[0][0], alpha);
    unicycle_glob_blend(UNICYCLE_N * UNICYCLE_NW, &g->mu_b[0][0], &s->mu_b[0][0], alpha);
    unicycle_glob_blend(UNICYCLE_NX, g->mu_bN, s->mu_bN, alpha);
    unicycle_glob_blend(UNICYCLE_DIM(UNICYCLE_NR), g->mu_r, s->mu_r, alpha);
    unicycle_glob_blend(UNICYCLE_DIM(UNICYCLE_NE), g->nu, s->nu, alpha);
    rc = unicycle_glob_init_at(s, g, xhat0, 1);
    if (rc != UNICYCLE_OK) {
        g->reason = UNICYCLE_GLOB_FUNCTION;
        return rc;
    }
    g->alpha = alpha;
    g->merit = phi;
    g->iterations += 1;
    return UNICYCLE_OK;
}

int unicycle_glob_step(unicycle_solver *s, unicycle_glob *g, const unicycle_real *xhat0)
{
    unicycle_real xh[UNICYCLE_NX];
    int mode, rc;

    if (!s->set_up) {
        return UNICYCLE_ERR_NOT_INITIALIZED;
    }
    g->reason = UNICYCLE_GLOB_OK;
    if (!s->initialized || !s->qp_ready) {
        g->reason = UNICYCLE_GLOB_NOT_PREPARED;
        s->status = s->initialized ? UNICYCLE_ERR_NOT_PREPARED : UNICYCLE_ERR_NOT_INITIALIZED;
        return s->status;
    }
    if (xhat0 && !unicycle_lai_vec_finite(UNICYCLE_NX, xhat0)) {
        s->status = UNICYCLE_ERR_NONFINITE_INPUT;
        return s->status;
    }
    /* xhat0 may point into the solver (unicycle_init reads it while writing s->xhat0) */
    unicycle_glob_copy(xh, xhat0 ? xhat0 : s->xhat0, UNICYCLE_NX);
    mode = s->settings.mode;
    s->settings.mode = UNICYCLE_MODE_FIXED;
    rc = unicycle_glob_step_fixed(s, g, xh);
    s->settings.mode = mode;
    s->status = rc;
    return rc;
}

int unicycle_init_globalised(unicycle_solver *s, unicycle_glob *g, const unicycle_real *xhat0, const unicycle_real *x,
                          const unicycle_real *u, double max_work, int max_iter, unicycle_real tol)
{
    unicycle_real kkt4[4], xh[UNICYCLE_NX];
    double w_start, w0, cost = 0.0;
    int it, rc, i;

    if (!s->set_up) {
        return UNICYCLE_ERR_NOT_INITIALIZED;
    }
    unicycle_glob_reset(g);
    if (max_iter < 0 || !(tol > UNICYCLE_R(0.0)) || !(max_work >= 0.0)) {
        s->status = UNICYCLE_ERR_INVALID_ARGUMENT;
        return s->status;
    }
    rc = unicycle_init(s, xhat0, x, u, 0, 0, 0, 0, 0, 0);
    if (rc != UNICYCLE_OK) {
        return rc;
    }
    unicycle_glob_copy(xh, s->xhat0, UNICYCLE_NX);
    w_start = s->anytime.work;
    for (it = 0;; ++it) {
        rc = unicycle_kkt_eval(s, xh, kkt4);
        if (rc != UNICYCLE_OK) {
            g->reason = UNICYCLE_GLOB_FUNCTION;
            return rc;
        }
        g->kkt = kkt4[0];
        for (i = 1; i < 4; ++i) {
            g->kkt = unicycle_fmax(g->kkt, kkt4[i]);
        }
        if (g->kkt <= tol) {
            g->reason = UNICYCLE_GLOB_OK;
            s->status = UNICYCLE_OK;
            return UNICYCLE_OK;
        }
        if (it == max_iter) {
            g->reason = UNICYCLE_GLOB_ITER_LIMIT;
            break;
        }
        if (max_work > 0.0 && s->anytime.work - w_start + cost > max_work) {
            g->reason = UNICYCLE_GLOB_WORK_LIMIT;
            break;
        }
        w0 = s->anytime.work;
        rc = unicycle_glob_step(s, g, xh);
        if (rc != UNICYCLE_OK) {
            return rc;
        }
        cost = s->anytime.work - w0;
    }
    s->status = UNICYCLE_ERR_NOT_CONVERGED;
    return s->status;
}
