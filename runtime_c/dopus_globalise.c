/* The globalised first solve (docs/algorithm.md section 15; constants and the caller's
 * memory in dopus_globalise.h, the API in dopus_solver.h).
 *
 * One step from the prepared iterate (after init or the previous step: every block fresh),
 * in fixed mode whatever the setting: the merit parts f (cost and the prices of the soft
 * sides) and c (l1 violation of the hard rows) at the iterate; the QP of the iterate through
 * dopus_feedback (the automatic lm and its retries), which takes the full step; the penalty
 * raised from the QP's multipliers; the backtracking line search on phi = f + nu c from the
 * iterate along that step; then dopus_init at the accepted point with the interpolated
 * multipliers (every block fresh, the next QP prepared). Only the public API, the generated
 * functions, the ring and the problem data are used, so the real-time calls are unchanged.
 * The Python reference is dopus_codegen/reference/globalise.py.
 */
#include <float.h>
#include <math.h>

#include "dopus_globalise.h"
#include "dopus_linalg.h"
#include "dopus_problem.h"
#include "dopus_solver.h"

static void dopus_glob_copy(dopus_real *dst, const dopus_real *src, int n)
{
    int i;
    for (i = 0; i < n; ++i) {
        dst[i] = src[i];
    }
}

size_t dopus_glob_sizeof(void)
{
    return sizeof(dopus_glob);
}

/* A zero-filled dopus_glob: no penalty, no counts, no KKT measure yet (kkt_best 0). */
static void dopus_glob_reset(dopus_glob *g)
{
    g->penalty = DOPUS_R(0.0);
    g->alpha = DOPUS_R(0.0);
    g->merit = DOPUS_R(0.0);
    g->slope = DOPUS_R(0.0);
    g->kkt = DOPUS_R(0.0);
    g->kkt_best = DOPUS_R(0.0);
    g->by_kkt = 0;
    g->iterations = 0;
    g->trials = 0;
    g->reason = DOPUS_GLOB_OK;
}

void dopus_glob_get_info(const dopus_glob *g, dopus_glob_info *info)
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
static dopus_real dopus_glob_price(dopus_real s, dopus_real l1, dopus_real l2)
{
    return l1 * s + DOPUS_R(0.5) * l2 * s * s;
}

/* Rows lo <= v <= up (n of them, soft weights w: 4 rows of stride ws, NULL: all hard): the
 * l1 violation of the hard sides into *hard, the prices of the soft sides into *price. */
static void dopus_glob_rows(int n, const dopus_real *v, const dopus_real *lo, const dopus_real *up,
                            const dopus_real *w, int ws, dopus_real *hard, dopus_real *price)
{
    int i, side;
    for (i = 0; i < n; ++i) {
        for (side = 0; side < 2; ++side) {
            dopus_real bound = side == 0 ? lo[i] : up[i];
            dopus_real sv;
            if (!isfinite(bound)) {
                continue;
            }
            sv = side == 0 ? bound - v[i] : v[i] - bound;
            sv = sv > DOPUS_R(0.0) ? sv : DOPUS_R(0.0);
            if (w && (w[side * ws + i] > DOPUS_R(0.0) || w[(2 + side) * ws + i] > DOPUS_R(0.0))) {
                *price += dopus_glob_price(sv, w[side * ws + i], w[(2 + side) * ws + i]);
            } else {
                *hard += sv;
            }
        }
    }
}

#if DOPUS_NSOFT > 0
#define DOPUS_GLOB_SOFT_X (&dopus_soft_x[0][0])
#define DOPUS_GLOB_SOFT_G (&dopus_soft_g[0][0])
#define DOPUS_GLOB_SOFT_R (&dopus_soft_r[0][0])
#else
#define DOPUS_GLOB_SOFT_X ((const dopus_real *)0)
#define DOPUS_GLOB_SOFT_G ((const dopus_real *)0)
#define DOPUS_GLOB_SOFT_R ((const dopus_real *)0)
#endif

/* f and c at the primal point (x, u) for xhat0; N + 1 work units. DOPUS_OK, or the status of
 * a function that failed or was not finite. */
static int dopus_glob_merit_parts(dopus_solver *s, const dopus_real *xhat0, const dopus_real (*x)[DOPUS_NX],
                                  const dopus_real (*u)[DOPUS_NU], dopus_real *f, dopus_real *c)
{
    dopus_real phi[DOPUS_NX], g[DOPUS_DIM(DOPUS_NG)], r[DOPUS_DIM(DOPUS_NR)], r_eq[DOPUS_DIM(DOPUS_NE)];
    dopus_real l = DOPUS_R(0.0), E = DOPUS_R(0.0), ft = DOPUS_R(0.0), ct = DOPUS_R(0.0);
    dopus_real sl = DOPUS_R(0.0), sc = DOPUS_R(0.0);
    int k, i;

    s->anytime.work += (double)(DOPUS_N + 1);
    /* the cost and the l1 sums are added in the reference's order: the stage costs, then E;
     * |x_0 - xhat0|, the dynamics, r_eq, then the rows node by node */
    for (i = 0; i < DOPUS_NX; ++i) {
        ct += dopus_fabs(x[0][i] - xhat0[i]);
    }
    for (k = 0; k < DOPUS_N; ++k) {
        if (dopus_eval_stage_eval(x[k], u[k], s->p[k], phi, &l, g, &s->mem.ev.fun_work) != 0) {
            return DOPUS_ERR_FUNCTION;
        }
        if (!dopus_lai_vec_finite(DOPUS_NX, phi) || !dopus_lai_vec_finite(DOPUS_NG, g) || !isfinite(l)) {
            return DOPUS_ERR_NONFINITE_VALUE;
        }
        sl += l;
        for (i = 0; i < DOPUS_NX; ++i) {
            sc += dopus_fabs(x[k + 1][i] - phi[i]);
        }
        dopus_glob_copy(s->mem.ev.Fn_g[k], g, DOPUS_NG);
    }
    if (dopus_eval_term_eval(x[DOPUS_N], s->p[DOPUS_N], &E, r, r_eq, &s->mem.ev.fun_work) != 0) {
        return DOPUS_ERR_FUNCTION;
    }
    if (!isfinite(E) || !dopus_lai_vec_finite(DOPUS_NR, r) || !dopus_lai_vec_finite(DOPUS_NE, r_eq)) {
        return DOPUS_ERR_NONFINITE_VALUE;
    }
    ft = sl + E;
    ct += sc;
    for (i = 0; i < DOPUS_NE; ++i) {
        ct += dopus_fabs(r_eq[i]);
    }
    for (k = 0; k < DOPUS_N; ++k) {
        if (k > 0) {
            dopus_glob_rows(DOPUS_NX, x[k], dopus_lbx, dopus_ubx, DOPUS_GLOB_SOFT_X, DOPUS_NX, &ct, &ft);
        }
        dopus_glob_rows(DOPUS_NU, u[k], dopus_lbu, dopus_ubu, 0, DOPUS_NU, &ct, &ft);
        dopus_glob_rows(DOPUS_NG, s->mem.ev.Fn_g[k], dopus_lg_k[k], dopus_ug_k[k], DOPUS_GLOB_SOFT_G,
                        DOPUS_DIM(DOPUS_NG), &ct, &ft);
    }
    dopus_glob_rows(DOPUS_NX, x[DOPUS_N], dopus_lbx, dopus_ubx, DOPUS_GLOB_SOFT_X, DOPUS_NX, &ct, &ft);
    dopus_glob_rows(DOPUS_NR, r, dopus_lr, dopus_ur, DOPUS_GLOB_SOFT_R, DOPUS_DIM(DOPUS_NR), &ct, &ft);
    *f = ft;
    *c = ct;
    return DOPUS_OK;
}

#if DOPUS_NSOFT > 0
/* The soft prices of rows v (n, weights w of stride ws), the hard sides ignored. */
static dopus_real dopus_glob_soft_price(int n, const dopus_real *v, const dopus_real *lo,
                                        const dopus_real *up, const dopus_real *w, int ws)
{
    dopus_real hard = DOPUS_R(0.0), price = DOPUS_R(0.0);
    dopus_glob_rows(n, v, lo, up, w, ws, &hard, &price);
    return price;
}
#endif

/* sum_soft psi(v_lin) - psi(v) along the step (x - g->x, u - g->u) with the blocks of the
 * iterate before it (the slots and the terminal blocks of the QP just solved). */
static dopus_real dopus_glob_soft_change(dopus_solver *s, dopus_glob *g)
{
    dopus_real total = DOPUS_R(0.0);
#if DOPUS_NSOFT > 0
    dopus_real v[DOPUS_NX], dw[DOPUS_NW];
    int k, i, j;
    for (k = 1; k <= DOPUS_N; ++k) {
        total += dopus_glob_soft_price(DOPUS_NX, s->x[k], dopus_lbx, dopus_ubx, DOPUS_GLOB_SOFT_X, DOPUS_NX) -
                 dopus_glob_soft_price(DOPUS_NX, g->x[k], dopus_lbx, dopus_ubx, DOPUS_GLOB_SOFT_X, DOPUS_NX);
    }
    for (k = 0; k < DOPUS_N && DOPUS_NG > 0; ++k) {
        const dopus_stage_slot *slot = dopus_ring_stage_const(&s->ring, k);
        for (i = 0; i < DOPUS_NX; ++i) {
            dw[i] = s->x[k][i] - g->x[k][i];
        }
        for (i = 0; i < DOPUS_NU; ++i) {
            dw[DOPUS_NX + i] = s->u[k][i] - g->u[k][i];
        }
        for (j = 0; j < DOPUS_NG; ++j) {
            dopus_real acc = slot->g[j];
            for (i = 0; i < DOPUS_NW; ++i) {
                acc += slot->Ct[j + i * DOPUS_DIM(DOPUS_NG)] * dw[i];
            }
            g->lin_g[k][j] = acc;
        }
        total += dopus_glob_soft_price(DOPUS_NG, g->lin_g[k], dopus_lg_k[k], dopus_ug_k[k], DOPUS_GLOB_SOFT_G,
                                       DOPUS_DIM(DOPUS_NG)) -
                 dopus_glob_soft_price(DOPUS_NG, slot->g, dopus_lg_k[k], dopus_ug_k[k], DOPUS_GLOB_SOFT_G,
                                       DOPUS_DIM(DOPUS_NG));
    }
    if (DOPUS_NR > 0) {
        for (i = 0; i < DOPUS_NX; ++i) {
            v[i] = s->x[DOPUS_N][i] - g->x[DOPUS_N][i];
        }
        for (j = 0; j < DOPUS_NR; ++j) {
            dopus_real acc = s->r[j];
            for (i = 0; i < DOPUS_NX; ++i) {
                acc += s->R[j + i * DOPUS_DIM(DOPUS_NR)] * v[i];
            }
            g->lin_r[j] = acc;
        }
        total +=
            dopus_glob_soft_price(DOPUS_NR, g->lin_r, dopus_lr, dopus_ur, DOPUS_GLOB_SOFT_R,
                                  DOPUS_DIM(DOPUS_NR)) -
            dopus_glob_soft_price(DOPUS_NR, s->r, dopus_lr, dopus_ur, DOPUS_GLOB_SOFT_R, DOPUS_DIM(DOPUS_NR));
    }
#else
    (void)s;
    (void)g;
#endif
    return total;
}

/* The largest multiplier of the iterate (the QP's after the full step). */
static dopus_real dopus_glob_max_multiplier(const dopus_solver *s)
{
    dopus_real m = DOPUS_R(0.0);
    int k, i;
    for (k = 0; k <= DOPUS_N; ++k) {
        for (i = 0; i < DOPUS_NX; ++i) {
            m = dopus_fmax(m, dopus_fabs(s->lam[k][i]));
        }
    }
    for (k = 0; k < DOPUS_N; ++k) {
        for (i = 0; i < DOPUS_NG; ++i) {
            m = dopus_fmax(m, dopus_fabs(s->mu_g[k][i]));
        }
        for (i = 0; i < DOPUS_NW; ++i) {
            m = dopus_fmax(m, dopus_fabs(s->mu_b[k][i]));
        }
    }
    for (i = 0; i < DOPUS_NX; ++i) {
        m = dopus_fmax(m, dopus_fabs(s->mu_bN[i]));
    }
    for (i = 0; i < DOPUS_NR; ++i) {
        m = dopus_fmax(m, dopus_fabs(s->mu_r[i]));
    }
    for (i = 0; i < DOPUS_NE; ++i) {
        m = dopus_fmax(m, dopus_fabs(s->nu[i]));
    }
    return m;
}

/* y <- y + alpha (y_QP - y) of one array: y in g, y_QP in the solver. */
static void dopus_glob_blend(int n, dopus_real *y, const dopus_real *yq, dopus_real alpha)
{
    int i;
    for (i = 0; i < n; ++i) {
        y[i] = alpha == DOPUS_R(1.0) ? yq[i] : y[i] + alpha * (yq[i] - y[i]);
    }
}

/* init at the point of g (x, u: xt, ut when trial, else the saved iterate) and its multipliers. */
static int dopus_glob_init_at(dopus_solver *s, dopus_glob *g, const dopus_real *xhat0, int trial)
{
    return dopus_init(s, xhat0, trial ? &g->xt[0][0] : &g->x[0][0], trial ? &g->ut[0][0] : &g->u[0][0],
                      &g->lam[0][0], DOPUS_NG > 0 ? &g->mu_g[0][0] : 0, &g->mu_b[0][0], g->mu_bN,
                      DOPUS_NR > 0 ? g->mu_r : 0, DOPUS_NE > 0 ? g->nu : 0);
}

/* The KKT measure of the solver's iterate (dopus_kkt_eval, counted as N + 1 work units). */
static int dopus_glob_kkt(dopus_solver *s, const dopus_real *xhat0, dopus_real *kkt)
{
    dopus_real kkt4[4];
    int i, rc;
    s->anytime.work += (double)(DOPUS_N + 1);
    rc = dopus_kkt_eval(s, xhat0, kkt4);
    *kkt = kkt4[0];
    for (i = 1; i < 4; ++i) {
        *kkt = dopus_fmax(*kkt, kkt4[i]);
    }
    return rc;
}

static int dopus_glob_step_fixed(dopus_solver *s, dopus_glob *g, const dopus_real *xhat0)
{
    dopus_real f0, c0, f, c, nu, ymax, a_dot_p, slope, phi0, phi = DOPUS_R(0.0), floor_, alpha;
    dopus_real u0[DOPUS_NU], kkt;
    int k, i, rc, trial, accepted = 0;

    dopus_glob_copy(&g->x[0][0], &s->x[0][0], (DOPUS_N + 1) * DOPUS_NX);
    dopus_glob_copy(&g->u[0][0], &s->u[0][0], DOPUS_N * DOPUS_NU);
    dopus_glob_copy(&g->lam[0][0], &s->lam[0][0], (DOPUS_N + 1) * DOPUS_NX);
    dopus_glob_copy(&g->mu_g[0][0], &s->mu_g[0][0], DOPUS_N * DOPUS_DIM(DOPUS_NG));
    dopus_glob_copy(&g->mu_b[0][0], &s->mu_b[0][0], DOPUS_N * DOPUS_NW);
    dopus_glob_copy(g->mu_bN, s->mu_bN, DOPUS_NX);
    dopus_glob_copy(g->mu_r, s->mu_r, DOPUS_DIM(DOPUS_NR));
    dopus_glob_copy(g->nu, s->nu, DOPUS_DIM(DOPUS_NE));
    g->by_kkt = 0;
    rc = dopus_glob_kkt(s, xhat0, &kkt);
    if (rc == DOPUS_OK) {
        /* 0: no KKT measure yet (a zero-filled dopus_glob) */
        g->kkt_best = g->kkt_best > DOPUS_R(0.0) ? dopus_fmin(g->kkt_best, kkt) : kkt;
        rc = dopus_glob_merit_parts(s, xhat0, (const dopus_real(*)[DOPUS_NX])g->x,
                                    (const dopus_real(*)[DOPUS_NU])g->u, &f0, &c0);
    }
    if (rc != DOPUS_OK) {
        g->reason = DOPUS_GLOB_FUNCTION;
        return rc;
    }
    rc = dopus_feedback(s, xhat0, u0);
    if (rc != DOPUS_OK) {
        g->reason = rc == DOPUS_ERR_DIVERGED ? DOPUS_GLOB_STEP_BOX
                    : rc == DOPUS_ERR_QP     ? DOPUS_GLOB_QP
                                             : DOPUS_GLOB_FUNCTION;
        return rc;
    }
    /* the cost's slope along the step: the QP's gradient a (every block fresh) */
    a_dot_p = DOPUS_R(0.0);
    for (k = 0; k < DOPUS_N; ++k) {
        for (i = 0; i < DOPUS_NX; ++i) {
            a_dot_p += s->qp_in.g[k][i] * (s->x[k][i] - g->x[k][i]);
        }
        for (i = 0; i < DOPUS_NU; ++i) {
            a_dot_p += s->qp_in.g[k][DOPUS_NX + i] * (s->u[k][i] - g->u[k][i]);
        }
    }
    for (i = 0; i < DOPUS_NX; ++i) {
        a_dot_p += s->qp_in.gN[i] * (s->x[DOPUS_N][i] - g->x[DOPUS_N][i]);
    }
    ymax = dopus_glob_max_multiplier(s);
    if (g->penalty < DOPUS_GLOB_PENALTY_MARGIN * ymax) {
        g->penalty = DOPUS_GLOB_PENALTY_RAISE * ymax;
    }
    nu = g->penalty;
    g->a_dot_p = a_dot_p;
    slope = a_dot_p - nu * c0 + dopus_glob_soft_change(s, g);
    phi0 = f0 + nu * c0;
    floor_ = DOPUS_GLOB_MERIT_FLOOR * DOPUS_REAL_EPSILON * (DOPUS_R(1.0) + dopus_fabs(phi0));
    alpha = DOPUS_R(1.0);
    g->trials = 0;
    for (trial = 0; trial < DOPUS_GLOB_MAX_TRIALS; ++trial) {
        g->trials = trial + 1;
        for (k = 0; k <= DOPUS_N; ++k) {
            for (i = 0; i < DOPUS_NX; ++i) {
                g->xt[k][i] =
                    alpha == DOPUS_R(1.0) ? s->x[k][i] : g->x[k][i] + alpha * (s->x[k][i] - g->x[k][i]);
            }
        }
        for (k = 0; k < DOPUS_N; ++k) {
            for (i = 0; i < DOPUS_NU; ++i) {
                g->ut[k][i] =
                    alpha == DOPUS_R(1.0) ? s->u[k][i] : g->u[k][i] + alpha * (s->u[k][i] - g->u[k][i]);
            }
        }
        rc = dopus_glob_merit_parts(s, xhat0, (const dopus_real(*)[DOPUS_NX])g->xt,
                                    (const dopus_real(*)[DOPUS_NU])g->ut, &f, &c);
        if (rc == DOPUS_OK) {
            phi = f + nu * c;
            if (phi <= phi0 + DOPUS_GLOB_ARMIJO * alpha * dopus_fmin(slope, DOPUS_R(0.0)) + floor_) {
                accepted = 1;
                break;
            }
        }
        /* the full step also when it lowers the KKT measure enough (the solver's iterate is
         * the full step with the QP's multipliers): the merit function may refuse the steps
         * of a fast local convergence along a curved constraint (the Maratos effect) */
        if (trial == 0 && dopus_glob_kkt(s, xhat0, &kkt) == DOPUS_OK &&
            kkt <= DOPUS_GLOB_KKT_FACTOR * g->kkt_best) {
            g->kkt_best = kkt;
            g->by_kkt = 1;
            accepted = 1;
            break;
        }
        alpha *= DOPUS_GLOB_BACKTRACK;
    }
    g->slope = slope;
    if (!accepted) {
        /* the iterate as it was, its QP prepared again */
        rc = dopus_glob_init_at(s, g, xhat0, 0);
        g->reason = DOPUS_GLOB_LINE_SEARCH;
        return rc != DOPUS_OK ? rc : DOPUS_ERR_DIVERGED;
    }
    dopus_glob_blend((DOPUS_N + 1) * DOPUS_NX, &g->lam[0][0], &s->lam[0][0], alpha);
    dopus_glob_blend(DOPUS_N * DOPUS_DIM(DOPUS_NG), &g->mu_g[0][0], &s->mu_g[0][0], alpha);
    dopus_glob_blend(DOPUS_N * DOPUS_NW, &g->mu_b[0][0], &s->mu_b[0][0], alpha);
    dopus_glob_blend(DOPUS_NX, g->mu_bN, s->mu_bN, alpha);
    dopus_glob_blend(DOPUS_DIM(DOPUS_NR), g->mu_r, s->mu_r, alpha);
    dopus_glob_blend(DOPUS_DIM(DOPUS_NE), g->nu, s->nu, alpha);
    rc = dopus_glob_init_at(s, g, xhat0, 1);
    if (rc != DOPUS_OK) {
        g->reason = DOPUS_GLOB_FUNCTION;
        return rc;
    }
    g->alpha = alpha;
    g->merit = phi;
    g->iterations += 1;
    return DOPUS_OK;
}

int dopus_glob_step(dopus_solver *s, dopus_glob *g, const dopus_real *xhat0)
{
    dopus_real xh[DOPUS_NX];
    int mode, rc;

    if (!s->set_up) {
        return DOPUS_ERR_NOT_INITIALIZED;
    }
    g->reason = DOPUS_GLOB_OK;
    if (!s->initialized || !s->qp_ready) {
        g->reason = DOPUS_GLOB_NOT_PREPARED;
        s->status = s->initialized ? DOPUS_ERR_NOT_PREPARED : DOPUS_ERR_NOT_INITIALIZED;
        return s->status;
    }
    if (xhat0 && !dopus_lai_vec_finite(DOPUS_NX, xhat0)) {
        s->status = DOPUS_ERR_NONFINITE_INPUT;
        return s->status;
    }
    /* xhat0 may point into the solver (dopus_init reads it while writing s->xhat0) */
    dopus_glob_copy(xh, xhat0 ? xhat0 : s->xhat0, DOPUS_NX);
    mode = s->settings.mode;
    s->settings.mode = DOPUS_MODE_FIXED;
    rc = dopus_glob_step_fixed(s, g, xh);
    s->settings.mode = mode;
    s->status = rc;
    return rc;
}

int dopus_init_globalised(dopus_solver *s, dopus_glob *g, const dopus_real *xhat0, const dopus_real *x,
                          const dopus_real *u, double max_work, int max_iter, dopus_real tol)
{
    dopus_real kkt4[4], xh[DOPUS_NX];
    double w_start, w0, cost = 0.0;
    int it, rc, i;

    if (!s->set_up) {
        return DOPUS_ERR_NOT_INITIALIZED;
    }
    dopus_glob_reset(g);
    if (max_iter < 0 || !(tol > DOPUS_R(0.0)) || !(max_work >= 0.0)) {
        s->status = DOPUS_ERR_INVALID_ARGUMENT;
        return s->status;
    }
    rc = dopus_init(s, xhat0, x, u, 0, 0, 0, 0, 0, 0);
    if (rc != DOPUS_OK) {
        return rc;
    }
    dopus_glob_copy(xh, s->xhat0, DOPUS_NX);
    w_start = s->anytime.work;
    for (it = 0;; ++it) {
        rc = dopus_kkt_eval(s, xh, kkt4);
        if (rc != DOPUS_OK) {
            g->reason = DOPUS_GLOB_FUNCTION;
            return rc;
        }
        g->kkt = kkt4[0];
        for (i = 1; i < 4; ++i) {
            g->kkt = dopus_fmax(g->kkt, kkt4[i]);
        }
        if (g->kkt <= tol) {
            g->reason = DOPUS_GLOB_OK;
            s->status = DOPUS_OK;
            return DOPUS_OK;
        }
        if (it == max_iter) {
            g->reason = DOPUS_GLOB_ITER_LIMIT;
            break;
        }
        if (max_work > 0.0 && s->anytime.work - w_start + cost > max_work) {
            g->reason = DOPUS_GLOB_WORK_LIMIT;
            break;
        }
        w0 = s->anytime.work;
        rc = dopus_glob_step(s, g, xh);
        if (rc != DOPUS_OK) {
            return rc;
        }
        cost = s->anytime.work - w0;
    }
    s->status = DOPUS_ERR_NOT_CONVERGED;
    return s->status;
}
