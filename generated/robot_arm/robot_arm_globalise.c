/* The globalised first solve (docs/algorithm.md section 15; constants and the caller's
 * memory in robot_arm_globalise.h, the API in robot_arm_solver.h).
 *
 * One step from the prepared iterate (after init or the previous step: every block fresh),
 * in fixed mode whatever the setting: the merit parts f (cost and the prices of the soft
 * sides) and c (l1 violation of the hard rows) at the iterate; the QP of the iterate through
 * robot_arm_feedback (the automatic lm and its retries), which takes the full step; the penalty
 * raised from the QP's multipliers; the backtracking line search on phi = f + nu c from the
 * iterate along that step; then robot_arm_init at the accepted point with the interpolated
 * multipliers (every block fresh, the next QP prepared). Only the public API, the generated
 * functions, the ring and the problem data are used, so the real-time calls are unchanged.
 * The Python reference is robot_arm_codegen/reference/globalise.py.
 */
#include <float.h>
#include <math.h>

#include "robot_arm_globalise.h"
#include "robot_arm_linalg.h"
#include "robot_arm_problem.h"
#include "robot_arm_solver.h"

static void robot_arm_glob_copy(robot_arm_real *dst, const robot_arm_real *src, int n)
{
    int i;
    for (i = 0; i < n; ++i) {
        dst[i] = src[i];
    }
}

size_t robot_arm_glob_sizeof(void)
{
    return sizeof(robot_arm_glob);
}

/* A zero-filled robot_arm_glob: no penalty, no counts, no KKT measure yet (kkt_best 0). */
static void robot_arm_glob_reset(robot_arm_glob *g)
{
    g->penalty = ROBOT_ARM_R(0.0);
    g->alpha = ROBOT_ARM_R(0.0);
    g->merit = ROBOT_ARM_R(0.0);
    g->slope = ROBOT_ARM_R(0.0);
    g->kkt = ROBOT_ARM_R(0.0);
    g->kkt_best = ROBOT_ARM_R(0.0);
    g->by_kkt = 0;
    g->iterations = 0;
    g->trials = 0;
    g->reason = ROBOT_ARM_GLOB_OK;
}

void robot_arm_glob_get_info(const robot_arm_glob *g, robot_arm_glob_info *info)
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
static robot_arm_real robot_arm_glob_price(robot_arm_real s, robot_arm_real l1, robot_arm_real l2)
{
    return l1 * s + ROBOT_ARM_R(0.5) * l2 * s * s;
}

/* Rows lo <= v <= up (n of them, soft weights w: 4 rows of stride ws, NULL: all hard): the
 * l1 violation of the hard sides into *hard, the prices of the soft sides into *price. */
static void robot_arm_glob_rows(int n, const robot_arm_real *v, const robot_arm_real *lo, const robot_arm_real *up,
                            const robot_arm_real *w, int ws, robot_arm_real *hard, robot_arm_real *price)
{
    int i, side;
    for (i = 0; i < n; ++i) {
        for (side = 0; side < 2; ++side) {
            robot_arm_real bound = side == 0 ? lo[i] : up[i];
            robot_arm_real sv;
            if (!isfinite(bound)) {
                continue;
            }
            sv = side == 0 ? bound - v[i] : v[i] - bound;
            sv = sv > ROBOT_ARM_R(0.0) ? sv : ROBOT_ARM_R(0.0);
            if (w && (w[side * ws + i] > ROBOT_ARM_R(0.0) || w[(2 + side) * ws + i] > ROBOT_ARM_R(0.0))) {
                *price += robot_arm_glob_price(sv, w[side * ws + i], w[(2 + side) * ws + i]);
            } else {
                *hard += sv;
            }
        }
    }
}

#if ROBOT_ARM_NSOFT > 0
#define ROBOT_ARM_GLOB_SOFT_X (&robot_arm_soft_x[0][0])
#define ROBOT_ARM_GLOB_SOFT_G (&robot_arm_soft_g[0][0])
#define ROBOT_ARM_GLOB_SOFT_R (&robot_arm_soft_r[0][0])
#else
#define ROBOT_ARM_GLOB_SOFT_X ((const robot_arm_real *)0)
#define ROBOT_ARM_GLOB_SOFT_G ((const robot_arm_real *)0)
#define ROBOT_ARM_GLOB_SOFT_R ((const robot_arm_real *)0)
#endif

/* f and c at the primal point (x, u) for xhat0; N + 1 work units. ROBOT_ARM_OK, or the status of
 * a function that failed or was not finite. */
static int robot_arm_glob_merit_parts(robot_arm_solver *s, const robot_arm_real *xhat0, const robot_arm_real (*x)[ROBOT_ARM_NX],
                                  const robot_arm_real (*u)[ROBOT_ARM_NU], robot_arm_real *f, robot_arm_real *c)
{
    robot_arm_real phi[ROBOT_ARM_NX], g[ROBOT_ARM_DIM(ROBOT_ARM_NG)], r[ROBOT_ARM_DIM(ROBOT_ARM_NR)], r_eq[ROBOT_ARM_DIM(ROBOT_ARM_NE)];
    robot_arm_real l = ROBOT_ARM_R(0.0), E = ROBOT_ARM_R(0.0), ft = ROBOT_ARM_R(0.0), ct = ROBOT_ARM_R(0.0);
    robot_arm_real sl = ROBOT_ARM_R(0.0), sc = ROBOT_ARM_R(0.0);
    int k, i;

    s->anytime.work += (double)(ROBOT_ARM_N + 1);
    /* the cost and the l1 sums are added in the reference's order: the stage costs, then E;
     * |x_0 - xhat0|, the dynamics, r_eq, then the rows node by node */
    for (i = 0; i < ROBOT_ARM_NX; ++i) {
        ct += robot_arm_fabs(x[0][i] - xhat0[i]);
    }
    for (k = 0; k < ROBOT_ARM_N; ++k) {
        if (robot_arm_eval_stage_eval(x[k], u[k], s->p[k], phi, &l, g, &s->mem.ev.fun_work) != 0) {
            return ROBOT_ARM_ERR_FUNCTION;
        }
        if (!robot_arm_lai_vec_finite(ROBOT_ARM_NX, phi) || !robot_arm_lai_vec_finite(ROBOT_ARM_NG, g) || !isfinite(l)) {
            return ROBOT_ARM_ERR_NONFINITE_VALUE;
        }
        sl += l;
        for (i = 0; i < ROBOT_ARM_NX; ++i) {
            sc += robot_arm_fabs(x[k + 1][i] - phi[i]);
        }
        robot_arm_glob_copy(s->mem.ev.Fn_g[k], g, ROBOT_ARM_NG);
    }
    if (robot_arm_eval_term_eval(x[ROBOT_ARM_N], s->p[ROBOT_ARM_N], &E, r, r_eq, &s->mem.ev.fun_work) != 0) {
        return ROBOT_ARM_ERR_FUNCTION;
    }
    if (!isfinite(E) || !robot_arm_lai_vec_finite(ROBOT_ARM_NR, r) || !robot_arm_lai_vec_finite(ROBOT_ARM_NE, r_eq)) {
        return ROBOT_ARM_ERR_NONFINITE_VALUE;
    }
    ft = sl + E;
    ct += sc;
    for (i = 0; i < ROBOT_ARM_NE; ++i) {
        ct += robot_arm_fabs(r_eq[i]);
    }
    for (k = 0; k < ROBOT_ARM_N; ++k) {
        if (k > 0) {
            robot_arm_glob_rows(ROBOT_ARM_NX, x[k], robot_arm_lbx, robot_arm_ubx, ROBOT_ARM_GLOB_SOFT_X, ROBOT_ARM_NX, &ct, &ft);
        }
        robot_arm_glob_rows(ROBOT_ARM_NU, u[k], robot_arm_lbu, robot_arm_ubu, 0, ROBOT_ARM_NU, &ct, &ft);
        robot_arm_glob_rows(ROBOT_ARM_NG, s->mem.ev.Fn_g[k], robot_arm_lg_k[k], robot_arm_ug_k[k], ROBOT_ARM_GLOB_SOFT_G,
                        ROBOT_ARM_DIM(ROBOT_ARM_NG), &ct, &ft);
    }
    robot_arm_glob_rows(ROBOT_ARM_NX, x[ROBOT_ARM_N], robot_arm_lbx, robot_arm_ubx, ROBOT_ARM_GLOB_SOFT_X, ROBOT_ARM_NX, &ct, &ft);
    robot_arm_glob_rows(ROBOT_ARM_NR, r, robot_arm_lr, robot_arm_ur, ROBOT_ARM_GLOB_SOFT_R, ROBOT_ARM_DIM(ROBOT_ARM_NR), &ct, &ft);
    *f = ft;
    *c = ct;
    return ROBOT_ARM_OK;
}

#if ROBOT_ARM_NSOFT > 0
/* The soft prices of rows v (n, weights w of stride ws), the hard sides ignored. */
static robot_arm_real robot_arm_glob_soft_price(int n, const robot_arm_real *v, const robot_arm_real *lo,
                                        const robot_arm_real *up, const robot_arm_real *w, int ws)
{
    robot_arm_real hard = ROBOT_ARM_R(0.0), price = ROBOT_ARM_R(0.0);
    robot_arm_glob_rows(n, v, lo, up, w, ws, &hard, &price);
    return price;
}
#endif

/* sum_soft psi(v_lin) - psi(v) along the step (x - g->x, u - g->u) with the blocks of the
 * iterate before it (the slots and the terminal blocks of the QP just solved). */
static robot_arm_real robot_arm_glob_soft_change(robot_arm_solver *s, robot_arm_glob *g)
{
    robot_arm_real total = ROBOT_ARM_R(0.0);
#if ROBOT_ARM_NSOFT > 0
    robot_arm_real v[ROBOT_ARM_NX], dw[ROBOT_ARM_NW];
    int k, i, j;
    for (k = 1; k <= ROBOT_ARM_N; ++k) {
        total += robot_arm_glob_soft_price(ROBOT_ARM_NX, s->x[k], robot_arm_lbx, robot_arm_ubx, ROBOT_ARM_GLOB_SOFT_X, ROBOT_ARM_NX) -
                 robot_arm_glob_soft_price(ROBOT_ARM_NX, g->x[k], robot_arm_lbx, robot_arm_ubx, ROBOT_ARM_GLOB_SOFT_X, ROBOT_ARM_NX);
    }
    for (k = 0; k < ROBOT_ARM_N && ROBOT_ARM_NG > 0; ++k) {
        const robot_arm_stage_slot *slot = robot_arm_ring_stage_const(&s->ring, k);
        for (i = 0; i < ROBOT_ARM_NX; ++i) {
            dw[i] = s->x[k][i] - g->x[k][i];
        }
        for (i = 0; i < ROBOT_ARM_NU; ++i) {
            dw[ROBOT_ARM_NX + i] = s->u[k][i] - g->u[k][i];
        }
        for (j = 0; j < ROBOT_ARM_NG; ++j) {
            robot_arm_real acc = slot->g[j];
            for (i = 0; i < ROBOT_ARM_NW; ++i) {
                acc += slot->Ct[j + i * ROBOT_ARM_DIM(ROBOT_ARM_NG)] * dw[i];
            }
            g->lin_g[k][j] = acc;
        }
        total += robot_arm_glob_soft_price(ROBOT_ARM_NG, g->lin_g[k], robot_arm_lg_k[k], robot_arm_ug_k[k], ROBOT_ARM_GLOB_SOFT_G,
                                       ROBOT_ARM_DIM(ROBOT_ARM_NG)) -
                 robot_arm_glob_soft_price(ROBOT_ARM_NG, slot->g, robot_arm_lg_k[k], robot_arm_ug_k[k], ROBOT_ARM_GLOB_SOFT_G,
                                       ROBOT_ARM_DIM(ROBOT_ARM_NG));
    }
    if (ROBOT_ARM_NR > 0) {
        for (i = 0; i < ROBOT_ARM_NX; ++i) {
            v[i] = s->x[ROBOT_ARM_N][i] - g->x[ROBOT_ARM_N][i];
        }
        for (j = 0; j < ROBOT_ARM_NR; ++j) {
            robot_arm_real acc = s->r[j];
            for (i = 0; i < ROBOT_ARM_NX; ++i) {
                acc += s->R[j + i * ROBOT_ARM_DIM(ROBOT_ARM_NR)] * v[i];
            }
            g->lin_r[j] = acc;
        }
        total +=
            robot_arm_glob_soft_price(ROBOT_ARM_NR, g->lin_r, robot_arm_lr, robot_arm_ur, ROBOT_ARM_GLOB_SOFT_R,
                                  ROBOT_ARM_DIM(ROBOT_ARM_NR)) -
            robot_arm_glob_soft_price(ROBOT_ARM_NR, s->r, robot_arm_lr, robot_arm_ur, ROBOT_ARM_GLOB_SOFT_R, ROBOT_ARM_DIM(ROBOT_ARM_NR));
    }
#else
    (void)s;
    (void)g;
#endif
    return total;
}

/* The largest multiplier of the iterate (the QP's after the full step). */
static robot_arm_real robot_arm_glob_max_multiplier(const robot_arm_solver *s)
{
    robot_arm_real m = ROBOT_ARM_R(0.0);
    int k, i;
    for (k = 0; k <= ROBOT_ARM_N; ++k) {
        for (i = 0; i < ROBOT_ARM_NX; ++i) {
            m = robot_arm_fmax(m, robot_arm_fabs(s->lam[k][i]));
        }
    }
    for (k = 0; k < ROBOT_ARM_N; ++k) {
        for (i = 0; i < ROBOT_ARM_NG; ++i) {
            m = robot_arm_fmax(m, robot_arm_fabs(s->mu_g[k][i]));
        }
        for (i = 0; i < ROBOT_ARM_NW; ++i) {
            m = robot_arm_fmax(m, robot_arm_fabs(s->mu_b[k][i]));
        }
    }
    for (i = 0; i < ROBOT_ARM_NX; ++i) {
        m = robot_arm_fmax(m, robot_arm_fabs(s->mu_bN[i]));
    }
    for (i = 0; i < ROBOT_ARM_NR; ++i) {
        m = robot_arm_fmax(m, robot_arm_fabs(s->mu_r[i]));
    }
    for (i = 0; i < ROBOT_ARM_NE; ++i) {
        m = robot_arm_fmax(m, robot_arm_fabs(s->nu[i]));
    }
    return m;
}

/* y <- y + alpha (y_QP - y) of one array: y in g, y_QP in the solver. */
static void robot_arm_glob_blend(int n, robot_arm_real *y, const robot_arm_real *yq, robot_arm_real alpha)
{
    int i;
    for (i = 0; i < n; ++i) {
        y[i] = alpha == ROBOT_ARM_R(1.0) ? yq[i] : y[i] + alpha * (yq[i] - y[i]);
    }
}

/* init at the point of g (x, u: xt, ut when trial, else the saved iterate) and its multipliers. */
static int robot_arm_glob_init_at(robot_arm_solver *s, robot_arm_glob *g, const robot_arm_real *xhat0, int trial)
{
    return robot_arm_init(s, xhat0, trial ? &g->xt[0][0] : &g->x[0][0], trial ? &g->ut[0][0] : &g->u[0][0],
                      &g->lam[0][0], ROBOT_ARM_NG > 0 ? &g->mu_g[0][0] : 0, &g->mu_b[0][0], g->mu_bN,
                      ROBOT_ARM_NR > 0 ? g->mu_r : 0, ROBOT_ARM_NE > 0 ? g->nu : 0);
}

/* The KKT measure of the solver's iterate (robot_arm_kkt_eval, counted as N + 1 work units). */
static int robot_arm_glob_kkt(robot_arm_solver *s, const robot_arm_real *xhat0, robot_arm_real *kkt)
{
    robot_arm_real kkt4[4];
    int i, rc;
    s->anytime.work += (double)(ROBOT_ARM_N + 1);
    rc = robot_arm_kkt_eval(s, xhat0, kkt4);
    *kkt = kkt4[0];
    for (i = 1; i < 4; ++i) {
        *kkt = robot_arm_fmax(*kkt, kkt4[i]);
    }
    return rc;
}

static int robot_arm_glob_step_fixed(robot_arm_solver *s, robot_arm_glob *g, const robot_arm_real *xhat0)
{
    robot_arm_real f0, c0, f, c, nu, ymax, a_dot_p, slope, phi0, phi = ROBOT_ARM_R(0.0), floor_, alpha;
    robot_arm_real u0[ROBOT_ARM_NU], kkt;
    int k, i, rc, trial, accepted = 0;

    robot_arm_glob_copy(&g->x[0][0], &s->x[0][0], (ROBOT_ARM_N + 1) * ROBOT_ARM_NX);
    robot_arm_glob_copy(&g->u[0][0], &s->u[0][0], ROBOT_ARM_N * ROBOT_ARM_NU);
    robot_arm_glob_copy(&g->lam[0][0], &s->lam[0][0], (ROBOT_ARM_N + 1) * ROBOT_ARM_NX);
    robot_arm_glob_copy(&g->mu_g[0][0], &s->mu_g[0][0], ROBOT_ARM_N * ROBOT_ARM_DIM(ROBOT_ARM_NG));
    robot_arm_glob_copy(&g->mu_b[0][0], &s->mu_b[0][0], ROBOT_ARM_N * ROBOT_ARM_NW);
    robot_arm_glob_copy(g->mu_bN, s->mu_bN, ROBOT_ARM_NX);
    robot_arm_glob_copy(g->mu_r, s->mu_r, ROBOT_ARM_DIM(ROBOT_ARM_NR));
    robot_arm_glob_copy(g->nu, s->nu, ROBOT_ARM_DIM(ROBOT_ARM_NE));
    g->by_kkt = 0;
    rc = robot_arm_glob_kkt(s, xhat0, &kkt);
    if (rc == ROBOT_ARM_OK) {
        /* 0: no KKT measure yet (a zero-filled robot_arm_glob) */
        g->kkt_best = g->kkt_best > ROBOT_ARM_R(0.0) ? robot_arm_fmin(g->kkt_best, kkt) : kkt;
        rc = robot_arm_glob_merit_parts(s, xhat0, (const robot_arm_real(*)[ROBOT_ARM_NX])g->x,
                                    (const robot_arm_real(*)[ROBOT_ARM_NU])g->u, &f0, &c0);
    }
    if (rc != ROBOT_ARM_OK) {
        g->reason = ROBOT_ARM_GLOB_FUNCTION;
        return rc;
    }
    rc = robot_arm_feedback(s, xhat0, u0);
    if (rc != ROBOT_ARM_OK) {
        g->reason = rc == ROBOT_ARM_ERR_DIVERGED ? ROBOT_ARM_GLOB_STEP_BOX
                    : rc == ROBOT_ARM_ERR_QP     ? ROBOT_ARM_GLOB_QP
                                             : ROBOT_ARM_GLOB_FUNCTION;
        return rc;
    }
    /* the cost's slope along the step: the QP's gradient a (every block fresh) */
    a_dot_p = ROBOT_ARM_R(0.0);
    for (k = 0; k < ROBOT_ARM_N; ++k) {
        for (i = 0; i < ROBOT_ARM_NX; ++i) {
            a_dot_p += s->qp_in.g[k][i] * (s->x[k][i] - g->x[k][i]);
        }
        for (i = 0; i < ROBOT_ARM_NU; ++i) {
            a_dot_p += s->qp_in.g[k][ROBOT_ARM_NX + i] * (s->u[k][i] - g->u[k][i]);
        }
    }
    for (i = 0; i < ROBOT_ARM_NX; ++i) {
        a_dot_p += s->qp_in.gN[i] * (s->x[ROBOT_ARM_N][i] - g->x[ROBOT_ARM_N][i]);
    }
    ymax = robot_arm_glob_max_multiplier(s);
    if (g->penalty < ROBOT_ARM_GLOB_PENALTY_MARGIN * ymax) {
        g->penalty = ROBOT_ARM_GLOB_PENALTY_RAISE * ymax;
    }
    nu = g->penalty;
    g->a_dot_p = a_dot_p;
    slope = a_dot_p - nu * c0 + robot_arm_glob_soft_change(s, g);
    phi0 = f0 + nu * c0;
    floor_ = ROBOT_ARM_GLOB_MERIT_FLOOR * ROBOT_ARM_REAL_EPSILON * (ROBOT_ARM_R(1.0) + robot_arm_fabs(phi0));
    alpha = ROBOT_ARM_R(1.0);
    g->trials = 0;
    for (trial = 0; trial < ROBOT_ARM_GLOB_MAX_TRIALS; ++trial) {
        g->trials = trial + 1;
        for (k = 0; k <= ROBOT_ARM_N; ++k) {
            for (i = 0; i < ROBOT_ARM_NX; ++i) {
                g->xt[k][i] =
                    alpha == ROBOT_ARM_R(1.0) ? s->x[k][i] : g->x[k][i] + alpha * (s->x[k][i] - g->x[k][i]);
            }
        }
        for (k = 0; k < ROBOT_ARM_N; ++k) {
            for (i = 0; i < ROBOT_ARM_NU; ++i) {
                g->ut[k][i] =
                    alpha == ROBOT_ARM_R(1.0) ? s->u[k][i] : g->u[k][i] + alpha * (s->u[k][i] - g->u[k][i]);
            }
        }
        rc = robot_arm_glob_merit_parts(s, xhat0, (const robot_arm_real(*)[ROBOT_ARM_NX])g->xt,
                                    (const robot_arm_real(*)[ROBOT_ARM_NU])g->ut, &f, &c);
        if (rc == ROBOT_ARM_OK) {
            phi = f + nu * c;
            if (phi <= phi0 + ROBOT_ARM_GLOB_ARMIJO * alpha * robot_arm_fmin(slope, ROBOT_ARM_R(0.0)) + floor_) {
                accepted = 1;
                break;
            }
        }
        /* the full step also when it lowers the KKT measure enough (the solver's iterate is
         * the full step with the QP's multipliers): the merit function may refuse the steps
         * of a fast local convergence along a curved constraint (the Maratos effect) */
        if (trial == 0 && robot_arm_glob_kkt(s, xhat0, &kkt) == ROBOT_ARM_OK &&
            kkt <= ROBOT_ARM_GLOB_KKT_FACTOR * g->kkt_best) {
            g->kkt_best = kkt;
            g->by_kkt = 1;
            accepted = 1;
            break;
        }
        alpha *= ROBOT_ARM_GLOB_BACKTRACK;
    }
    g->slope = slope;
    if (!accepted) {
        /* the iterate as it was, its QP prepared again */
        rc = robot_arm_glob_init_at(s, g, xhat0, 0);
        g->reason = ROBOT_ARM_GLOB_LINE_SEARCH;
        return rc != ROBOT_ARM_OK ? rc : ROBOT_ARM_ERR_DIVERGED;
    }
    robot_arm_glob_blend((ROBOT_ARM_N + 1) * ROBOT_ARM_NX, &g->lam[0][0], &s->lam[0][0], alpha);
    robot_arm_glob_blend(ROBOT_ARM_N * ROBOT_ARM_DIM(ROBOT_ARM_NG), &g->mu_g[0][0], &s->mu_g[0][0], alpha);
    robot_arm_glob_blend(ROBOT_ARM_N * ROBOT_ARM_NW, &g->mu_b[0][0], &s->mu_b[0][0], alpha);
    robot_arm_glob_blend(ROBOT_ARM_NX, g->mu_bN, s->mu_bN, alpha);
    robot_arm_glob_blend(ROBOT_ARM_DIM(ROBOT_ARM_NR), g->mu_r, s->mu_r, alpha);
    robot_arm_glob_blend(ROBOT_ARM_DIM(ROBOT_ARM_NE), g->nu, s->nu, alpha);
    rc = robot_arm_glob_init_at(s, g, xhat0, 1);
    if (rc != ROBOT_ARM_OK) {
        g->reason = ROBOT_ARM_GLOB_FUNCTION;
        return rc;
    }
    g->alpha = alpha;
    g->merit = phi;
    g->iterations += 1;
    return ROBOT_ARM_OK;
}

int robot_arm_glob_step(robot_arm_solver *s, robot_arm_glob *g, const robot_arm_real *xhat0)
{
    robot_arm_real xh[ROBOT_ARM_NX];
    int mode, rc;

    if (!s->set_up) {
        return ROBOT_ARM_ERR_NOT_INITIALIZED;
    }
    g->reason = ROBOT_ARM_GLOB_OK;
    if (!s->initialized || !s->qp_ready) {
        g->reason = ROBOT_ARM_GLOB_NOT_PREPARED;
        s->status = s->initialized ? ROBOT_ARM_ERR_NOT_PREPARED : ROBOT_ARM_ERR_NOT_INITIALIZED;
        return s->status;
    }
    if (xhat0 && !robot_arm_lai_vec_finite(ROBOT_ARM_NX, xhat0)) {
        s->status = ROBOT_ARM_ERR_NONFINITE_INPUT;
        return s->status;
    }
    /* xhat0 may point into the solver (robot_arm_init reads it while writing s->xhat0) */
    robot_arm_glob_copy(xh, xhat0 ? xhat0 : s->xhat0, ROBOT_ARM_NX);
    mode = s->settings.mode;
    s->settings.mode = ROBOT_ARM_MODE_FIXED;
    rc = robot_arm_glob_step_fixed(s, g, xh);
    s->settings.mode = mode;
    s->status = rc;
    return rc;
}

int robot_arm_init_globalised(robot_arm_solver *s, robot_arm_glob *g, const robot_arm_real *xhat0, const robot_arm_real *x,
                          const robot_arm_real *u, double max_work, int max_iter, robot_arm_real tol)
{
    robot_arm_real kkt4[4], xh[ROBOT_ARM_NX];
    double w_start, w0, cost = 0.0;
    int it, rc, i;

    if (!s->set_up) {
        return ROBOT_ARM_ERR_NOT_INITIALIZED;
    }
    robot_arm_glob_reset(g);
    if (max_iter < 0 || !(tol > ROBOT_ARM_R(0.0)) || !(max_work >= 0.0)) {
        s->status = ROBOT_ARM_ERR_INVALID_ARGUMENT;
        return s->status;
    }
    rc = robot_arm_init(s, xhat0, x, u, 0, 0, 0, 0, 0, 0);
    if (rc != ROBOT_ARM_OK) {
        return rc;
    }
    robot_arm_glob_copy(xh, s->xhat0, ROBOT_ARM_NX);
    w_start = s->anytime.work;
    for (it = 0;; ++it) {
        rc = robot_arm_kkt_eval(s, xh, kkt4);
        if (rc != ROBOT_ARM_OK) {
            g->reason = ROBOT_ARM_GLOB_FUNCTION;
            return rc;
        }
        g->kkt = kkt4[0];
        for (i = 1; i < 4; ++i) {
            g->kkt = robot_arm_fmax(g->kkt, kkt4[i]);
        }
        if (g->kkt <= tol) {
            g->reason = ROBOT_ARM_GLOB_OK;
            s->status = ROBOT_ARM_OK;
            return ROBOT_ARM_OK;
        }
        if (it == max_iter) {
            g->reason = ROBOT_ARM_GLOB_ITER_LIMIT;
            break;
        }
        if (max_work > 0.0 && s->anytime.work - w_start + cost > max_work) {
            g->reason = ROBOT_ARM_GLOB_WORK_LIMIT;
            break;
        }
        w0 = s->anytime.work;
        rc = robot_arm_glob_step(s, g, xh);
        if (rc != ROBOT_ARM_OK) {
            return rc;
        }
        cost = s->anytime.work - w0;
    }
    s->status = ROBOT_ARM_ERR_NOT_CONVERGED;
    return s->status;
}
