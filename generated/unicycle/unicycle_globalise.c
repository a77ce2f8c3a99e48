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

/* A zero-filled unicycle_glob: no penalty, no counts, no watchdog. */
static void unicycle_glob_reset(unicycle_glob *g)
{
    g->penalty = UNICYCLE_R(0.0);
    g->alpha = UNICYCLE_R(0.0);
    g->merit = UNICYCLE_R(0.0);
    g->slope = UNICYCLE_R(0.0);
    g->kkt = UNICYCLE_R(0.0);
    g->iterations = 0;
    g->trials = 0;
    g->reason = UNICYCLE_GLOB_OK;
    g->relaxed = 0;
    g->restores = 0;
    g->no_relax = 0;
    g->watch = 0;
}

void unicycle_glob_get_info(const unicycle_glob *g, unicycle_glob_info *info)
{
    info->iterations = g->iterations;
    info->trials = g->trials;
    info->reason = g->reason;
    info->relaxed = g->relaxed;
    info->restores = g->restores;
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

/* f and c at the primal point z (x_0..x_N, u_0..u_{N-1}) for xhat0; N + 1 work units.
 * UNICYCLE_OK, or the status of a function that failed or was not finite. */
static int unicycle_glob_merit_parts(unicycle_solver *s, const unicycle_real *xhat0, const unicycle_real *z,
                                  unicycle_real *f, unicycle_real *c)
{
    const unicycle_real *x = z, *u = z + (UNICYCLE_N + 1) * UNICYCLE_NX;
    unicycle_real phi[UNICYCLE_NX], g[UNICYCLE_DIM(UNICYCLE_NG)], r[UNICYCLE_DIM(UNICYCLE_NR)], r_eq[UNICYCLE_DIM(UNICYCLE_NE)];
    unicycle_real l = UNICYCLE_R(0.0), E = UNICYCLE_R(0.0), ft, ct = UNICYCLE_R(0.0), sl = UNICYCLE_R(0.0),
               sc = UNICYCLE_R(0.0);
    int k, i;

    s->anytime.work += (double)(UNICYCLE_N + 1);
    /* the reference's order: |x_0 - xhat0|, the dynamics, r_eq, then the rows node by node */
    for (i = 0; i < UNICYCLE_NX; ++i) {
        ct += unicycle_fabs(x[i] - xhat0[i]);
    }
    for (k = 0; k < UNICYCLE_N; ++k) {
        if (unicycle_eval_stage_eval(x + k * UNICYCLE_NX, u + k * UNICYCLE_NU, s->p[k], phi, &l, g,
                                  &s->mem.ev.fun_work) != 0) {
            return UNICYCLE_ERR_FUNCTION;
        }
        if (!unicycle_lai_vec_finite(UNICYCLE_NX, phi) || !unicycle_lai_vec_finite(UNICYCLE_NG, g) || !isfinite(l)) {
            return UNICYCLE_ERR_NONFINITE_VALUE;
        }
        sl += l;
        for (i = 0; i < UNICYCLE_NX; ++i) {
            sc += unicycle_fabs(x[(k + 1) * UNICYCLE_NX + i] - phi[i]);
        }
        unicycle_glob_copy(s->mem.ev.Fn_g[k], g, UNICYCLE_NG);
    }
    if (unicycle_eval_term_eval(x + UNICYCLE_N * UNICYCLE_NX, s->p[UNICYCLE_N], &E, r, r_eq, &s->mem.ev.fun_work) != 0) {
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
            unicycle_glob_rows(UNICYCLE_NX, x + k * UNICYCLE_NX, unicycle_lbx, unicycle_ubx, UNICYCLE_GLOB_SOFT_X, UNICYCLE_NX,
                            &ct, &ft);
        }
        unicycle_glob_rows(UNICYCLE_NU, u + k * UNICYCLE_NU, unicycle_lbu, unicycle_ubu, 0, UNICYCLE_NU, &ct, &ft);
        unicycle_glob_rows(UNICYCLE_NG, s->mem.ev.Fn_g[k], unicycle_lg_k[k], unicycle_ug_k[k], UNICYCLE_GLOB_SOFT_G,
                        UNICYCLE_DIM(UNICYCLE_NG), &ct, &ft);
    }
    unicycle_glob_rows(UNICYCLE_NX, x + UNICYCLE_N * UNICYCLE_NX, unicycle_lbx, unicycle_ubx, UNICYCLE_GLOB_SOFT_X, UNICYCLE_NX, &ct,
                    &ft);
    unicycle_glob_rows(UNICYCLE_NR, r, unicycle_lr, unicycle_ur, UNICYCLE_GLOB_SOFT_R, UNICYCLE_DIM(UNICYCLE_NR), &ct, &ft);
    *f = ft;
    *c = ct;
    return UNICYCLE_OK;
}

/* The merit phi = f + nu c at z; 0 when a function is not finite there (*ok = 0). */
static unicycle_real unicycle_glob_merit(unicycle_solver *s, const unicycle_real *xhat0, const unicycle_real *z,
                                   unicycle_real nu, int *ok)
{
    unicycle_real f = UNICYCLE_R(0.0), c = UNICYCLE_R(0.0);
    *ok = unicycle_glob_merit_parts(s, xhat0, z, &f, &c) == UNICYCLE_OK;
    return *ok ? f + nu * c : UNICYCLE_R(0.0);
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

/* sum_soft psi(v_lin) - psi(v) along the step g->dz from g->z, with the blocks of the
 * iterate g->z (the slots and the terminal blocks of the QP just solved). */
static unicycle_real unicycle_glob_soft_change(unicycle_solver *s, unicycle_glob *g)
{
    unicycle_real total = UNICYCLE_R(0.0);
#if UNICYCLE_NSOFT > 0
    const unicycle_real *x = g->z, *dx = g->dz, *du = g->dz + (UNICYCLE_N + 1) * UNICYCLE_NX;
    int k, i, j;
    for (k = 1; k <= UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NX; ++i) {
            g->zt[i] = x[k * UNICYCLE_NX + i] + dx[k * UNICYCLE_NX + i];
        }
        total += unicycle_glob_soft_price(UNICYCLE_NX, g->zt, unicycle_lbx, unicycle_ubx, UNICYCLE_GLOB_SOFT_X, UNICYCLE_NX) -
                 unicycle_glob_soft_price(UNICYCLE_NX, x + k * UNICYCLE_NX, unicycle_lbx, unicycle_ubx, UNICYCLE_GLOB_SOFT_X,
                                       UNICYCLE_NX);
    }
    for (k = 0; k < UNICYCLE_N && UNICYCLE_NG > 0; ++k) {
        const unicycle_stage_slot *slot = unicycle_ring_stage_const(&s->ring, k);
        unicycle_real *lin = g->lin + k * UNICYCLE_NG;
        for (j = 0; j < UNICYCLE_NG; ++j) {
            unicycle_real acc = slot->g[j];
            for (i = 0; i < UNICYCLE_NX; ++i) {
                acc += slot->Ct[j + i * UNICYCLE_DIM(UNICYCLE_NG)] * dx[k * UNICYCLE_NX + i];
            }
            for (i = 0; i < UNICYCLE_NU; ++i) {
                acc += slot->Ct[j + (UNICYCLE_NX + i) * UNICYCLE_DIM(UNICYCLE_NG)] * du[k * UNICYCLE_NU + i];
            }
            lin[j] = acc;
        }
        total += unicycle_glob_soft_price(UNICYCLE_NG, lin, unicycle_lg_k[k], unicycle_ug_k[k], UNICYCLE_GLOB_SOFT_G,
                                       UNICYCLE_DIM(UNICYCLE_NG)) -
                 unicycle_glob_soft_price(UNICYCLE_NG, slot->g, unicycle_lg_k[k], unicycle_ug_k[k], UNICYCLE_GLOB_SOFT_G,
                                       UNICYCLE_DIM(UNICYCLE_NG));
    }
    if (UNICYCLE_NR > 0) {
        unicycle_real *lin = g->lin + UNICYCLE_N * UNICYCLE_NG;
        for (j = 0; j < UNICYCLE_NR; ++j) {
            unicycle_real acc = s->r[j];
            for (i = 0; i < UNICYCLE_NX; ++i) {
                acc += s->R[j + i * UNICYCLE_DIM(UNICYCLE_NR)] * dx[UNICYCLE_N * UNICYCLE_NX + i];
            }
            lin[j] = acc;
        }
        total +=
            unicycle_glob_soft_price(UNICYCLE_NR, lin, unicycle_lr, unicycle_ur, UNICYCLE_GLOB_SOFT_R, UNICYCLE_DIM(UNICYCLE_NR)) -
            unicycle_glob_soft_price(UNICYCLE_NR, s->r, unicycle_lr, unicycle_ur, UNICYCLE_GLOB_SOFT_R, UNICYCLE_DIM(UNICYCLE_NR));
    }
#else
    (void)s;
    (void)g;
#endif
    return total;
}

/* The solver's primal point into z. */
static void unicycle_glob_get_z(const unicycle_solver *s, unicycle_real *z)
{
    unicycle_glob_copy(z, &s->x[0][0], (UNICYCLE_N + 1) * UNICYCLE_NX);
    unicycle_glob_copy(z + (UNICYCLE_N + 1) * UNICYCLE_NX, &s->u[0][0], UNICYCLE_N * UNICYCLE_NU);
}

/* The solver's multipliers into y (the layout of unicycle_init). */
static void unicycle_glob_get_y(const unicycle_solver *s, unicycle_real *y)
{
    int k, i, o = 0;
    unicycle_glob_copy(y, &s->lam[0][0], (UNICYCLE_N + 1) * UNICYCLE_NX);
    o += (UNICYCLE_N + 1) * UNICYCLE_NX;
    for (k = 0; k < UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NG; ++i) {
            y[o++] = s->mu_g[k][i];
        }
    }
    unicycle_glob_copy(y + o, &s->mu_b[0][0], UNICYCLE_N * UNICYCLE_NW);
    o += UNICYCLE_N * UNICYCLE_NW;
    unicycle_glob_copy(y + o, s->mu_bN, UNICYCLE_NX);
    o += UNICYCLE_NX;
    unicycle_glob_copy(y + o, s->mu_r, UNICYCLE_NR);
    o += UNICYCLE_NR;
    unicycle_glob_copy(y + o, s->nu, UNICYCLE_NE);
}

/* init at the primal point z with the multipliers y. */
static int unicycle_glob_init_at(unicycle_solver *s, const unicycle_real *xhat0, const unicycle_real *z,
                              const unicycle_real *y)
{
    const unicycle_real *mu_g = y + (UNICYCLE_N + 1) * UNICYCLE_NX;
    const unicycle_real *mu_b = mu_g + UNICYCLE_N * UNICYCLE_NG;
    const unicycle_real *mu_bN = mu_b + UNICYCLE_N * UNICYCLE_NW;
    const unicycle_real *mu_r = mu_bN + UNICYCLE_NX;
    const unicycle_real *nu = mu_r + UNICYCLE_NR;
    return unicycle_init(s, xhat0, z, z + (UNICYCLE_N + 1) * UNICYCLE_NX, y, UNICYCLE_NG > 0 ? mu_g : 0, mu_b, mu_bN,
                      UNICYCLE_NR > 0 ? mu_r : 0, UNICYCLE_NE > 0 ? nu : 0);
}

/* The sufficient decrease test of a trial's merit phi (ok: finite) against phi0 and slope D. */
static int unicycle_glob_armijo(int ok, unicycle_real phi, unicycle_real phi0, unicycle_real alpha, unicycle_real D)
{
    unicycle_real floor_ = UNICYCLE_GLOB_MERIT_FLOOR * UNICYCLE_REAL_EPSILON * (UNICYCLE_R(1.0) + unicycle_fabs(phi0));
    return ok && phi <= phi0 + UNICYCLE_GLOB_ARMIJO * alpha * unicycle_fmin(D, UNICYCLE_R(0.0)) + floor_;
}

/* Take the point zt with the multipliers y (init there); alpha, merit phi, relaxed. */
static int unicycle_glob_accept(unicycle_solver *s, unicycle_glob *g, const unicycle_real *xhat0, unicycle_real alpha,
                             unicycle_real phi, int relaxed)
{
    int rc = unicycle_glob_init_at(s, xhat0, g->zt, g->y);
    if (rc != UNICYCLE_OK) {
        g->reason = UNICYCLE_GLOB_FUNCTION;
        return rc;
    }
    g->alpha = alpha;
    g->merit = phi;
    g->relaxed = relaxed;
    g->iterations += 1;
    return UNICYCLE_OK;
}

/* Backtracking from alpha along dz from z (multipliers y0 -> yq), against phi0 and slope D;
 * the accepted point initialised, else z (its QP prepared again) and a failure. g->y is the
 * blend, g->zt the trial. */
static int unicycle_glob_line_search(unicycle_solver *s, unicycle_glob *g, const unicycle_real *xhat0,
                                  const unicycle_real *z, const unicycle_real *dz, const unicycle_real *y0,
                                  const unicycle_real *yq, unicycle_real phi0, unicycle_real D, unicycle_real alpha)
{
    unicycle_real phi;
    int i, ok, rc;
    while (g->trials < UNICYCLE_GLOB_MAX_TRIALS) {
        g->trials += 1;
        for (i = 0; i < UNICYCLE_GLOB_NZ; ++i) {
            g->zt[i] = z[i] + alpha * dz[i];
        }
        phi = unicycle_glob_merit(s, xhat0, g->zt, g->penalty, &ok);
        if (unicycle_glob_armijo(ok, phi, phi0, alpha, D)) {
            for (i = 0; i < UNICYCLE_GLOB_NY; ++i) {
                g->y[i] = y0[i] + alpha * (yq[i] - y0[i]);
            }
            return unicycle_glob_accept(s, g, xhat0, alpha, phi, 0);
        }
        alpha *= UNICYCLE_GLOB_BACKTRACK;
    }
    /* the start point, its QP prepared again (g->y may alias y0: copied first) */
    unicycle_glob_copy(g->zt, z, UNICYCLE_GLOB_NZ);
    if (y0 != g->y) {
        unicycle_glob_copy(g->y, y0, UNICYCLE_GLOB_NY);
    }
    rc = unicycle_glob_init_at(s, xhat0, g->zt, g->y);
    g->reason = UNICYCLE_GLOB_LINE_SEARCH;
    return rc != UNICYCLE_OK ? rc : UNICYCLE_ERR_DIVERGED;
}

/* The relaxed steps did not decrease the merit enough: the line search from the watchdog's
 * point along its step, from alpha = 1/2 (its full step was refused). */
static int unicycle_glob_restore(unicycle_solver *s, unicycle_glob *g, const unicycle_real *xhat0)
{
    unicycle_real nu = g->penalty;
    unicycle_real phi_s = g->wf + nu * g->wc, D_s = g->wadp - nu * g->wc;
    g->watch = 0;
    g->no_relax = 1;
    g->trials = 0;
    g->restores += 1;
    g->slope = D_s;
    return unicycle_glob_line_search(s, g, xhat0, g->wz, g->wdz, g->wy, g->wyq, phi_s, D_s,
                                  UNICYCLE_GLOB_BACKTRACK);
}

static int unicycle_glob_step_fixed(unicycle_solver *s, unicycle_glob *g, const unicycle_real *xhat0)
{
    unicycle_real f0 = UNICYCLE_R(0.0), c0 = UNICYCLE_R(0.0), nu, ymax = UNICYCLE_R(0.0), adp, D, phi0, phi1;
    unicycle_real u0[UNICYCLE_NU];
    int k, i, rc, ok;

    unicycle_glob_get_z(s, g->z);
    unicycle_glob_get_y(s, g->y);
    rc = unicycle_glob_merit_parts(s, xhat0, g->z, &f0, &c0);
    if (rc != UNICYCLE_OK) {
        g->reason = UNICYCLE_GLOB_FUNCTION;
        return rc;
    }
    /* the interior point only: the step's QP is solved from scratch in both backends */
    s->qp_no_active_set = 1;
    rc = unicycle_feedback(s, xhat0, u0);
    s->qp_no_active_set = 0;
    if (rc != UNICYCLE_OK) {
        if (g->watch > 0) {
            /* a relaxed step led here: back to the watchdog's point, a line search there */
            return unicycle_glob_restore(s, g, xhat0);
        }
        g->reason = rc == UNICYCLE_ERR_DIVERGED ? UNICYCLE_GLOB_STEP_BOX
                    : rc == UNICYCLE_ERR_QP     ? UNICYCLE_GLOB_QP
                                             : UNICYCLE_GLOB_FUNCTION;
        return rc;
    }
    unicycle_glob_get_z(s, g->zt); /* the full step */
    for (i = 0; i < UNICYCLE_GLOB_NZ; ++i) {
        g->dz[i] = g->zt[i] - g->z[i];
    }
    unicycle_glob_get_y(s, g->yq);
    for (i = 0; i < UNICYCLE_GLOB_NY; ++i) {
        ymax = unicycle_fmax(ymax, unicycle_fabs(g->yq[i]));
    }
    if (g->penalty < UNICYCLE_GLOB_PENALTY_MARGIN * ymax) {
        g->penalty = UNICYCLE_GLOB_PENALTY_RAISE * ymax;
    }
    nu = g->penalty;
    /* the cost's slope along the step (the QP's gradient: every block fresh) and the change
     * of the soft prices, with the blocks of the QP just solved */
    adp = UNICYCLE_R(0.0);
    for (k = 0; k < UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NX; ++i) {
            adp += s->qp_in.g[k][i] * g->dz[k * UNICYCLE_NX + i];
        }
        for (i = 0; i < UNICYCLE_NU; ++i) {
            adp += s->qp_in.g[k][UNICYCLE_NX + i] * g->dz[(UNICYCLE_N + 1) * UNICYCLE_NX + k * UNICYCLE_NU + i];
        }
    }
    for (i = 0; i < UNICYCLE_NX; ++i) {
        adp += s->qp_in.gN[i] * g->dz[UNICYCLE_N * UNICYCLE_NX + i];
    }
    adp += unicycle_glob_soft_change(s, g);
    D = adp - nu * c0;
    phi0 = f0 + nu * c0;
    g->slope = D;
    g->trials = 1;
    unicycle_glob_get_z(s, g->zt); /* (the soft change used zt as scratch) */
    phi1 = unicycle_glob_merit(s, xhat0, g->zt, nu, &ok);
    if (g->watch == 0) {
        if (unicycle_glob_armijo(ok, phi1, phi0, UNICYCLE_R(1.0), D)) {
            unicycle_glob_copy(g->y, g->yq, UNICYCLE_GLOB_NY);
            return unicycle_glob_accept(s, g, xhat0, UNICYCLE_R(1.0), phi1, 0);
        }
        if (ok && !g->no_relax) {
            /* the watchdog: the full step all the same, the point before it kept */
            unicycle_glob_copy(g->wz, g->z, UNICYCLE_GLOB_NZ);
            unicycle_glob_copy(g->wdz, g->dz, UNICYCLE_GLOB_NZ);
            unicycle_glob_copy(g->wy, g->y, UNICYCLE_GLOB_NY);
            unicycle_glob_copy(g->wyq, g->yq, UNICYCLE_GLOB_NY);
            g->wf = f0;
            g->wc = c0;
            g->wadp = adp;
            g->watch = 1;
            unicycle_glob_copy(g->y, g->yq, UNICYCLE_GLOB_NY);
            return unicycle_glob_accept(s, g, xhat0, UNICYCLE_R(1.0), phi1, 1);
        }
        rc = unicycle_glob_line_search(s, g, xhat0, g->z, g->dz, g->y, g->yq, phi0, D, UNICYCLE_GLOB_BACKTRACK);
        if (rc == UNICYCLE_OK) {
            g->no_relax = 0;
        }
        return rc;
    }
    if (unicycle_glob_armijo(ok, phi1, g->wf + nu * g->wc, UNICYCLE_R(1.0), g->wadp - nu * g->wc)) {
        g->watch = 0;
        unicycle_glob_copy(g->y, g->yq, UNICYCLE_GLOB_NY);
        return unicycle_glob_accept(s, g, xhat0, UNICYCLE_R(1.0), phi1, 0);
    }
    if (ok && g->watch < UNICYCLE_GLOB_WATCHDOG) {
        g->watch += 1;
        unicycle_glob_copy(g->y, g->yq, UNICYCLE_GLOB_NY);
        return unicycle_glob_accept(s, g, xhat0, UNICYCLE_R(1.0), phi1, 1);
    }
    return unicycle_glob_restore(s, g, xhat0);
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
    s->qp_prefactored = 0; /* the step's evaluations use the QP's memory */
    rc = unicycle_glob_step_fixed(s, g, xh);
    s->qp_prefactored = 0;
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
