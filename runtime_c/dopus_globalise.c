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

/* A zero-filled dopus_glob: no penalty, no counts, no watchdog. */
static void dopus_glob_reset(dopus_glob *g)
{
    g->penalty = DOPUS_R(0.0);
    g->alpha = DOPUS_R(0.0);
    g->merit = DOPUS_R(0.0);
    g->slope = DOPUS_R(0.0);
    g->kkt = DOPUS_R(0.0);
    g->iterations = 0;
    g->trials = 0;
    g->reason = DOPUS_GLOB_OK;
    g->relaxed = 0;
    g->restores = 0;
    g->no_relax = 0;
    g->watch = 0;
}

void dopus_glob_get_info(const dopus_glob *g, dopus_glob_info *info)
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

/* f and c at the primal point z (x_0..x_N, u_0..u_{N-1}) for xhat0; N + 1 work units.
 * DOPUS_OK, or the status of a function that failed or was not finite. */
static int dopus_glob_merit_parts(dopus_solver *s, const dopus_real *xhat0, const dopus_real *z,
                                  dopus_real *f, dopus_real *c)
{
    const dopus_real *x = z, *u = z + (DOPUS_N + 1) * DOPUS_NX;
    dopus_real phi[DOPUS_NX], g[DOPUS_DIM(DOPUS_NG)], r[DOPUS_DIM(DOPUS_NR)], r_eq[DOPUS_DIM(DOPUS_NE)];
    dopus_real l = DOPUS_R(0.0), E = DOPUS_R(0.0), ft, ct = DOPUS_R(0.0), sl = DOPUS_R(0.0),
               sc = DOPUS_R(0.0);
    int k, i;

    s->anytime.work += (double)(DOPUS_N + 1);
    /* the reference's order: |x_0 - xhat0|, the dynamics, r_eq, then the rows node by node */
    for (i = 0; i < DOPUS_NX; ++i) {
        ct += dopus_fabs(x[i] - xhat0[i]);
    }
    for (k = 0; k < DOPUS_N; ++k) {
        if (dopus_eval_stage_eval(x + k * DOPUS_NX, u + k * DOPUS_NU, s->p[k], phi, &l, g,
                                  &s->mem.ev.fun_work) != 0) {
            return DOPUS_ERR_FUNCTION;
        }
        if (!dopus_lai_vec_finite(DOPUS_NX, phi) || !dopus_lai_vec_finite(DOPUS_NG, g) || !isfinite(l)) {
            return DOPUS_ERR_NONFINITE_VALUE;
        }
        sl += l;
        for (i = 0; i < DOPUS_NX; ++i) {
            sc += dopus_fabs(x[(k + 1) * DOPUS_NX + i] - phi[i]);
        }
        dopus_glob_copy(s->mem.ev.Fn_g[k], g, DOPUS_NG);
    }
    if (dopus_eval_term_eval(x + DOPUS_N * DOPUS_NX, s->p[DOPUS_N], &E, r, r_eq, &s->mem.ev.fun_work) != 0) {
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
            dopus_glob_rows(DOPUS_NX, x + k * DOPUS_NX, dopus_lbx, dopus_ubx, DOPUS_GLOB_SOFT_X, DOPUS_NX,
                            &ct, &ft);
        }
        dopus_glob_rows(DOPUS_NU, u + k * DOPUS_NU, dopus_lbu, dopus_ubu, 0, DOPUS_NU, &ct, &ft);
        dopus_glob_rows(DOPUS_NG, s->mem.ev.Fn_g[k], dopus_lg_k[k], dopus_ug_k[k], DOPUS_GLOB_SOFT_G,
                        DOPUS_DIM(DOPUS_NG), &ct, &ft);
    }
    dopus_glob_rows(DOPUS_NX, x + DOPUS_N * DOPUS_NX, dopus_lbx, dopus_ubx, DOPUS_GLOB_SOFT_X, DOPUS_NX, &ct,
                    &ft);
    dopus_glob_rows(DOPUS_NR, r, dopus_lr, dopus_ur, DOPUS_GLOB_SOFT_R, DOPUS_DIM(DOPUS_NR), &ct, &ft);
    *f = ft;
    *c = ct;
    return DOPUS_OK;
}

/* The merit phi = f + nu c at z; 0 when a function is not finite there (*ok = 0). */
static dopus_real dopus_glob_merit(dopus_solver *s, const dopus_real *xhat0, const dopus_real *z,
                                   dopus_real nu, int *ok)
{
    dopus_real f = DOPUS_R(0.0), c = DOPUS_R(0.0);
    *ok = dopus_glob_merit_parts(s, xhat0, z, &f, &c) == DOPUS_OK;
    return *ok ? f + nu * c : DOPUS_R(0.0);
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

/* sum_soft psi(v_lin) - psi(v) along the step g->dz from g->z, with the blocks of the
 * iterate g->z (the slots and the terminal blocks of the QP just solved). */
static dopus_real dopus_glob_soft_change(dopus_solver *s, dopus_glob *g)
{
    dopus_real total = DOPUS_R(0.0);
#if DOPUS_NSOFT > 0
    const dopus_real *x = g->z, *dx = g->dz, *du = g->dz + (DOPUS_N + 1) * DOPUS_NX;
    int k, i, j;
    for (k = 1; k <= DOPUS_N; ++k) {
        for (i = 0; i < DOPUS_NX; ++i) {
            g->zt[i] = x[k * DOPUS_NX + i] + dx[k * DOPUS_NX + i];
        }
        total += dopus_glob_soft_price(DOPUS_NX, g->zt, dopus_lbx, dopus_ubx, DOPUS_GLOB_SOFT_X, DOPUS_NX) -
                 dopus_glob_soft_price(DOPUS_NX, x + k * DOPUS_NX, dopus_lbx, dopus_ubx, DOPUS_GLOB_SOFT_X,
                                       DOPUS_NX);
    }
    for (k = 0; k < DOPUS_N && DOPUS_NG > 0; ++k) {
        const dopus_stage_slot *slot = dopus_ring_stage_const(&s->ring, k);
        dopus_real *lin = g->lin + k * DOPUS_NG;
        for (j = 0; j < DOPUS_NG; ++j) {
            dopus_real acc = slot->g[j];
            for (i = 0; i < DOPUS_NX; ++i) {
                acc += slot->Ct[j + i * DOPUS_DIM(DOPUS_NG)] * dx[k * DOPUS_NX + i];
            }
            for (i = 0; i < DOPUS_NU; ++i) {
                acc += slot->Ct[j + (DOPUS_NX + i) * DOPUS_DIM(DOPUS_NG)] * du[k * DOPUS_NU + i];
            }
            lin[j] = acc;
        }
        total += dopus_glob_soft_price(DOPUS_NG, lin, dopus_lg_k[k], dopus_ug_k[k], DOPUS_GLOB_SOFT_G,
                                       DOPUS_DIM(DOPUS_NG)) -
                 dopus_glob_soft_price(DOPUS_NG, slot->g, dopus_lg_k[k], dopus_ug_k[k], DOPUS_GLOB_SOFT_G,
                                       DOPUS_DIM(DOPUS_NG));
    }
    if (DOPUS_NR > 0) {
        dopus_real *lin = g->lin + DOPUS_N * DOPUS_NG;
        for (j = 0; j < DOPUS_NR; ++j) {
            dopus_real acc = s->r[j];
            for (i = 0; i < DOPUS_NX; ++i) {
                acc += s->R[j + i * DOPUS_DIM(DOPUS_NR)] * dx[DOPUS_N * DOPUS_NX + i];
            }
            lin[j] = acc;
        }
        total +=
            dopus_glob_soft_price(DOPUS_NR, lin, dopus_lr, dopus_ur, DOPUS_GLOB_SOFT_R, DOPUS_DIM(DOPUS_NR)) -
            dopus_glob_soft_price(DOPUS_NR, s->r, dopus_lr, dopus_ur, DOPUS_GLOB_SOFT_R, DOPUS_DIM(DOPUS_NR));
    }
#else
    (void)s;
    (void)g;
#endif
    return total;
}

/* The solver's primal point into z. */
static void dopus_glob_get_z(const dopus_solver *s, dopus_real *z)
{
    dopus_glob_copy(z, &s->x[0][0], (DOPUS_N + 1) * DOPUS_NX);
    dopus_glob_copy(z + (DOPUS_N + 1) * DOPUS_NX, &s->u[0][0], DOPUS_N * DOPUS_NU);
}

/* The solver's multipliers into y (the layout of dopus_init). */
static void dopus_glob_get_y(const dopus_solver *s, dopus_real *y)
{
    int k, i, o = 0;
    dopus_glob_copy(y, &s->lam[0][0], (DOPUS_N + 1) * DOPUS_NX);
    o += (DOPUS_N + 1) * DOPUS_NX;
    for (k = 0; k < DOPUS_N; ++k) {
        for (i = 0; i < DOPUS_NG; ++i) {
            y[o++] = s->mu_g[k][i];
        }
    }
    dopus_glob_copy(y + o, &s->mu_b[0][0], DOPUS_N * DOPUS_NW);
    o += DOPUS_N * DOPUS_NW;
    dopus_glob_copy(y + o, s->mu_bN, DOPUS_NX);
    o += DOPUS_NX;
    dopus_glob_copy(y + o, s->mu_r, DOPUS_NR);
    o += DOPUS_NR;
    dopus_glob_copy(y + o, s->nu, DOPUS_NE);
}

/* init at the primal point z with the multipliers y. */
static int dopus_glob_init_at(dopus_solver *s, const dopus_real *xhat0, const dopus_real *z,
                              const dopus_real *y)
{
    const dopus_real *mu_g = y + (DOPUS_N + 1) * DOPUS_NX;
    const dopus_real *mu_b = mu_g + DOPUS_N * DOPUS_NG;
    const dopus_real *mu_bN = mu_b + DOPUS_N * DOPUS_NW;
    const dopus_real *mu_r = mu_bN + DOPUS_NX;
    const dopus_real *nu = mu_r + DOPUS_NR;
    return dopus_init(s, xhat0, z, z + (DOPUS_N + 1) * DOPUS_NX, y, DOPUS_NG > 0 ? mu_g : 0, mu_b, mu_bN,
                      DOPUS_NR > 0 ? mu_r : 0, DOPUS_NE > 0 ? nu : 0);
}

/* The sufficient decrease test of a trial's merit phi (ok: finite) against phi0 and slope D. */
static int dopus_glob_armijo(int ok, dopus_real phi, dopus_real phi0, dopus_real alpha, dopus_real D)
{
    dopus_real floor_ = DOPUS_GLOB_MERIT_FLOOR * DOPUS_REAL_EPSILON * (DOPUS_R(1.0) + dopus_fabs(phi0));
    return ok && phi <= phi0 + DOPUS_GLOB_ARMIJO * alpha * dopus_fmin(D, DOPUS_R(0.0)) + floor_;
}

/* Take the point zt with the multipliers y (init there); alpha, merit phi, relaxed. */
static int dopus_glob_accept(dopus_solver *s, dopus_glob *g, const dopus_real *xhat0, dopus_real alpha,
                             dopus_real phi, int relaxed)
{
    int rc = dopus_glob_init_at(s, xhat0, g->zt, g->y);
    if (rc != DOPUS_OK) {
        g->reason = DOPUS_GLOB_FUNCTION;
        return rc;
    }
    g->alpha = alpha;
    g->merit = phi;
    g->relaxed = relaxed;
    g->iterations += 1;
    return DOPUS_OK;
}

/* Backtracking from alpha along dz from z (multipliers y0 -> yq), against phi0 and slope D;
 * the accepted point initialised, else z (its QP prepared again) and a failure. g->y is the
 * blend, g->zt the trial. */
static int dopus_glob_line_search(dopus_solver *s, dopus_glob *g, const dopus_real *xhat0,
                                  const dopus_real *z, const dopus_real *dz, const dopus_real *y0,
                                  const dopus_real *yq, dopus_real phi0, dopus_real D, dopus_real alpha)
{
    dopus_real phi;
    int i, ok, rc;
    while (g->trials < DOPUS_GLOB_MAX_TRIALS) {
        g->trials += 1;
        for (i = 0; i < DOPUS_GLOB_NZ; ++i) {
            g->zt[i] = z[i] + alpha * dz[i];
        }
        phi = dopus_glob_merit(s, xhat0, g->zt, g->penalty, &ok);
        if (dopus_glob_armijo(ok, phi, phi0, alpha, D)) {
            for (i = 0; i < DOPUS_GLOB_NY; ++i) {
                g->y[i] = y0[i] + alpha * (yq[i] - y0[i]);
            }
            return dopus_glob_accept(s, g, xhat0, alpha, phi, 0);
        }
        alpha *= DOPUS_GLOB_BACKTRACK;
    }
    /* the start point, its QP prepared again (g->y may alias y0: copied first) */
    dopus_glob_copy(g->zt, z, DOPUS_GLOB_NZ);
    if (y0 != g->y) {
        dopus_glob_copy(g->y, y0, DOPUS_GLOB_NY);
    }
    rc = dopus_glob_init_at(s, xhat0, g->zt, g->y);
    g->reason = DOPUS_GLOB_LINE_SEARCH;
    return rc != DOPUS_OK ? rc : DOPUS_ERR_DIVERGED;
}

/* The relaxed steps did not decrease the merit enough: the line search from the watchdog's
 * point along its step, from alpha = 1/2 (its full step was refused). */
static int dopus_glob_restore(dopus_solver *s, dopus_glob *g, const dopus_real *xhat0)
{
    dopus_real nu = g->penalty;
    dopus_real phi_s = g->wf + nu * g->wc, D_s = g->wadp - nu * g->wc;
    g->watch = 0;
    g->no_relax = 1;
    g->trials = 0;
    g->restores += 1;
    g->slope = D_s;
    return dopus_glob_line_search(s, g, xhat0, g->wz, g->wdz, g->wy, g->wyq, phi_s, D_s,
                                  DOPUS_GLOB_BACKTRACK);
}

static int dopus_glob_step_fixed(dopus_solver *s, dopus_glob *g, const dopus_real *xhat0)
{
    dopus_real f0 = DOPUS_R(0.0), c0 = DOPUS_R(0.0), nu, ymax = DOPUS_R(0.0), adp, D, phi0, phi1;
    dopus_real u0[DOPUS_NU];
    int k, i, rc, ok;

    dopus_glob_get_z(s, g->z);
    dopus_glob_get_y(s, g->y);
    rc = dopus_glob_merit_parts(s, xhat0, g->z, &f0, &c0);
    if (rc != DOPUS_OK) {
        g->reason = DOPUS_GLOB_FUNCTION;
        return rc;
    }
    /* the interior point only: the step's QP is solved from scratch in both backends */
    s->qp_no_active_set = 1;
    rc = dopus_feedback(s, xhat0, u0);
    s->qp_no_active_set = 0;
    if (rc != DOPUS_OK) {
        if (g->watch > 0) {
            /* a relaxed step led here: back to the watchdog's point, a line search there */
            return dopus_glob_restore(s, g, xhat0);
        }
        g->reason = rc == DOPUS_ERR_DIVERGED ? DOPUS_GLOB_STEP_BOX
                    : rc == DOPUS_ERR_QP     ? DOPUS_GLOB_QP
                                             : DOPUS_GLOB_FUNCTION;
        return rc;
    }
    dopus_glob_get_z(s, g->zt); /* the full step */
    for (i = 0; i < DOPUS_GLOB_NZ; ++i) {
        g->dz[i] = g->zt[i] - g->z[i];
    }
    dopus_glob_get_y(s, g->yq);
    for (i = 0; i < DOPUS_GLOB_NY; ++i) {
        ymax = dopus_fmax(ymax, dopus_fabs(g->yq[i]));
    }
    if (g->penalty < DOPUS_GLOB_PENALTY_MARGIN * ymax) {
        g->penalty = DOPUS_GLOB_PENALTY_RAISE * ymax;
    }
    nu = g->penalty;
    /* the cost's slope along the step (the QP's gradient: every block fresh) and the change
     * of the soft prices, with the blocks of the QP just solved */
    adp = DOPUS_R(0.0);
    for (k = 0; k < DOPUS_N; ++k) {
        for (i = 0; i < DOPUS_NX; ++i) {
            adp += s->qp_in.g[k][i] * g->dz[k * DOPUS_NX + i];
        }
        for (i = 0; i < DOPUS_NU; ++i) {
            adp += s->qp_in.g[k][DOPUS_NX + i] * g->dz[(DOPUS_N + 1) * DOPUS_NX + k * DOPUS_NU + i];
        }
    }
    for (i = 0; i < DOPUS_NX; ++i) {
        adp += s->qp_in.gN[i] * g->dz[DOPUS_N * DOPUS_NX + i];
    }
    adp += dopus_glob_soft_change(s, g);
    D = adp - nu * c0;
    phi0 = f0 + nu * c0;
    g->slope = D;
    g->trials = 1;
    dopus_glob_get_z(s, g->zt); /* (the soft change used zt as scratch) */
    phi1 = dopus_glob_merit(s, xhat0, g->zt, nu, &ok);
    if (g->watch == 0) {
        if (dopus_glob_armijo(ok, phi1, phi0, DOPUS_R(1.0), D)) {
            dopus_glob_copy(g->y, g->yq, DOPUS_GLOB_NY);
            return dopus_glob_accept(s, g, xhat0, DOPUS_R(1.0), phi1, 0);
        }
        if (ok && !g->no_relax) {
            /* the watchdog: the full step all the same, the point before it kept */
            dopus_glob_copy(g->wz, g->z, DOPUS_GLOB_NZ);
            dopus_glob_copy(g->wdz, g->dz, DOPUS_GLOB_NZ);
            dopus_glob_copy(g->wy, g->y, DOPUS_GLOB_NY);
            dopus_glob_copy(g->wyq, g->yq, DOPUS_GLOB_NY);
            g->wf = f0;
            g->wc = c0;
            g->wadp = adp;
            g->watch = 1;
            dopus_glob_copy(g->y, g->yq, DOPUS_GLOB_NY);
            return dopus_glob_accept(s, g, xhat0, DOPUS_R(1.0), phi1, 1);
        }
        rc = dopus_glob_line_search(s, g, xhat0, g->z, g->dz, g->y, g->yq, phi0, D, DOPUS_GLOB_BACKTRACK);
        if (rc == DOPUS_OK) {
            g->no_relax = 0;
        }
        return rc;
    }
    if (dopus_glob_armijo(ok, phi1, g->wf + nu * g->wc, DOPUS_R(1.0), g->wadp - nu * g->wc)) {
        g->watch = 0;
        dopus_glob_copy(g->y, g->yq, DOPUS_GLOB_NY);
        return dopus_glob_accept(s, g, xhat0, DOPUS_R(1.0), phi1, 0);
    }
    if (ok && g->watch < DOPUS_GLOB_WATCHDOG) {
        g->watch += 1;
        dopus_glob_copy(g->y, g->yq, DOPUS_GLOB_NY);
        return dopus_glob_accept(s, g, xhat0, DOPUS_R(1.0), phi1, 1);
    }
    return dopus_glob_restore(s, g, xhat0);
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
    s->qp_prefactored = 0; /* the step's evaluations use the QP's memory */
    rc = dopus_glob_step_fixed(s, g, xh);
    s->qp_prefactored = 0;
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
