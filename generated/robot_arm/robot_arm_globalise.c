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

/* A zero-filled robot_arm_glob: no penalty, no counts, no watchdog. */
static void robot_arm_glob_reset(robot_arm_glob *g)
{
    g->penalty = ROBOT_ARM_R(0.0);
    g->alpha = ROBOT_ARM_R(0.0);
    g->merit = ROBOT_ARM_R(0.0);
    g->slope = ROBOT_ARM_R(0.0);
    g->kkt = ROBOT_ARM_R(0.0);
    g->iterations = 0;
    g->trials = 0;
    g->reason = ROBOT_ARM_GLOB_OK;
    g->relaxed = 0;
    g->restores = 0;
    g->no_relax = 0;
    g->watch = 0;
}

void robot_arm_glob_get_info(const robot_arm_glob *g, robot_arm_glob_info *info)
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

/* f and c at the primal point z (x_0..x_N, u_0..u_{N-1}) for xhat0; N + 1 work units.
 * ROBOT_ARM_OK, or the status of a function that failed or was not finite. */
static int robot_arm_glob_merit_parts(robot_arm_solver *s, const robot_arm_real *xhat0, const robot_arm_real *z,
                                  robot_arm_real *f, robot_arm_real *c)
{
    const robot_arm_real *x = z, *u = z + (ROBOT_ARM_N + 1) * ROBOT_ARM_NX;
    robot_arm_real phi[ROBOT_ARM_NX], g[ROBOT_ARM_DIM(ROBOT_ARM_NG)], r[ROBOT_ARM_DIM(ROBOT_ARM_NR)], r_eq[ROBOT_ARM_DIM(ROBOT_ARM_NE)];
    robot_arm_real l = ROBOT_ARM_R(0.0), E = ROBOT_ARM_R(0.0), ft, ct = ROBOT_ARM_R(0.0), sl = ROBOT_ARM_R(0.0),
               sc = ROBOT_ARM_R(0.0);
    int k, i;

    s->anytime.work += (double)(ROBOT_ARM_N + 1);
    /* the reference's order: |x_0 - xhat0|, the dynamics, r_eq, then the rows node by node */
    for (i = 0; i < ROBOT_ARM_NX; ++i) {
        ct += robot_arm_fabs(x[i] - xhat0[i]);
    }
    for (k = 0; k < ROBOT_ARM_N; ++k) {
        if (robot_arm_eval_stage_eval(x + k * ROBOT_ARM_NX, u + k * ROBOT_ARM_NU, s->p[k], phi, &l, g,
                                  &s->mem.ev.fun_work) != 0) {
            return ROBOT_ARM_ERR_FUNCTION;
        }
        if (!robot_arm_lai_vec_finite(ROBOT_ARM_NX, phi) || !robot_arm_lai_vec_finite(ROBOT_ARM_NG, g) || !isfinite(l)) {
            return ROBOT_ARM_ERR_NONFINITE_VALUE;
        }
        sl += l;
        for (i = 0; i < ROBOT_ARM_NX; ++i) {
            sc += robot_arm_fabs(x[(k + 1) * ROBOT_ARM_NX + i] - phi[i]);
        }
        robot_arm_glob_copy(s->mem.ev.Fn_g[k], g, ROBOT_ARM_NG);
    }
    if (robot_arm_eval_term_eval(x + ROBOT_ARM_N * ROBOT_ARM_NX, s->p[ROBOT_ARM_N], &E, r, r_eq, &s->mem.ev.fun_work) != 0) {
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
            robot_arm_glob_rows(ROBOT_ARM_NX, x + k * ROBOT_ARM_NX, robot_arm_lbx, robot_arm_ubx, ROBOT_ARM_GLOB_SOFT_X, ROBOT_ARM_NX,
                            &ct, &ft);
        }
        robot_arm_glob_rows(ROBOT_ARM_NU, u + k * ROBOT_ARM_NU, robot_arm_lbu, robot_arm_ubu, 0, ROBOT_ARM_NU, &ct, &ft);
        robot_arm_glob_rows(ROBOT_ARM_NG, s->mem.ev.Fn_g[k], robot_arm_lg_k[k], robot_arm_ug_k[k], ROBOT_ARM_GLOB_SOFT_G,
                        ROBOT_ARM_DIM(ROBOT_ARM_NG), &ct, &ft);
    }
    robot_arm_glob_rows(ROBOT_ARM_NX, x + ROBOT_ARM_N * ROBOT_ARM_NX, robot_arm_lbx, robot_arm_ubx, ROBOT_ARM_GLOB_SOFT_X, ROBOT_ARM_NX, &ct,
                    &ft);
    robot_arm_glob_rows(ROBOT_ARM_NR, r, robot_arm_lr, robot_arm_ur, ROBOT_ARM_GLOB_SOFT_R, ROBOT_ARM_DIM(ROBOT_ARM_NR), &ct, &ft);
    *f = ft;
    *c = ct;
    return ROBOT_ARM_OK;
}

/* The merit phi = f + nu c at z; 0 when a function is not finite there (*ok = 0). */
static robot_arm_real robot_arm_glob_merit(robot_arm_solver *s, const robot_arm_real *xhat0, const robot_arm_real *z,
                                   robot_arm_real nu, int *ok)
{
    robot_arm_real f = ROBOT_ARM_R(0.0), c = ROBOT_ARM_R(0.0);
    *ok = robot_arm_glob_merit_parts(s, xhat0, z, &f, &c) == ROBOT_ARM_OK;
    return *ok ? f + nu * c : ROBOT_ARM_R(0.0);
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

/* sum_soft psi(v_lin) - psi(v) along the step g->dz from g->z, with the blocks of the
 * iterate g->z (the slots and the terminal blocks of the QP just solved). */
static robot_arm_real robot_arm_glob_soft_change(robot_arm_solver *s, robot_arm_glob *g)
{
    robot_arm_real total = ROBOT_ARM_R(0.0);
#if ROBOT_ARM_NSOFT > 0
    const robot_arm_real *x = g->z, *dx = g->dz, *du = g->dz + (ROBOT_ARM_N + 1) * ROBOT_ARM_NX;
    int k, i, j;
    for (k = 1; k <= ROBOT_ARM_N; ++k) {
        for (i = 0; i < ROBOT_ARM_NX; ++i) {
            g->zt[i] = x[k * ROBOT_ARM_NX + i] + dx[k * ROBOT_ARM_NX + i];
        }
        total += robot_arm_glob_soft_price(ROBOT_ARM_NX, g->zt, robot_arm_lbx, robot_arm_ubx, ROBOT_ARM_GLOB_SOFT_X, ROBOT_ARM_NX) -
                 robot_arm_glob_soft_price(ROBOT_ARM_NX, x + k * ROBOT_ARM_NX, robot_arm_lbx, robot_arm_ubx, ROBOT_ARM_GLOB_SOFT_X,
                                       ROBOT_ARM_NX);
    }
    for (k = 0; k < ROBOT_ARM_N && ROBOT_ARM_NG > 0; ++k) {
        const robot_arm_stage_slot *slot = robot_arm_ring_stage_const(&s->ring, k);
        robot_arm_real *lin = g->lin + k * ROBOT_ARM_NG;
        for (j = 0; j < ROBOT_ARM_NG; ++j) {
            robot_arm_real acc = slot->g[j];
            for (i = 0; i < ROBOT_ARM_NX; ++i) {
                acc += slot->Ct[j + i * ROBOT_ARM_DIM(ROBOT_ARM_NG)] * dx[k * ROBOT_ARM_NX + i];
            }
            for (i = 0; i < ROBOT_ARM_NU; ++i) {
                acc += slot->Ct[j + (ROBOT_ARM_NX + i) * ROBOT_ARM_DIM(ROBOT_ARM_NG)] * du[k * ROBOT_ARM_NU + i];
            }
            lin[j] = acc;
        }
        total += robot_arm_glob_soft_price(ROBOT_ARM_NG, lin, robot_arm_lg_k[k], robot_arm_ug_k[k], ROBOT_ARM_GLOB_SOFT_G,
                                       ROBOT_ARM_DIM(ROBOT_ARM_NG)) -
                 robot_arm_glob_soft_price(ROBOT_ARM_NG, slot->g, robot_arm_lg_k[k], robot_arm_ug_k[k], ROBOT_ARM_GLOB_SOFT_G,
                                       ROBOT_ARM_DIM(ROBOT_ARM_NG));
    }
    if (ROBOT_ARM_NR > 0) {
        robot_arm_real *lin = g->lin + ROBOT_ARM_N * ROBOT_ARM_NG;
        for (j = 0; j < ROBOT_ARM_NR; ++j) {
            robot_arm_real acc = s->r[j];
            for (i = 0; i < ROBOT_ARM_NX; ++i) {
                acc += s->R[j + i * ROBOT_ARM_DIM(ROBOT_ARM_NR)] * dx[ROBOT_ARM_N * ROBOT_ARM_NX + i];
            }
            lin[j] = acc;
        }
        total +=
            robot_arm_glob_soft_price(ROBOT_ARM_NR, lin, robot_arm_lr, robot_arm_ur, ROBOT_ARM_GLOB_SOFT_R, ROBOT_ARM_DIM(ROBOT_ARM_NR)) -
            robot_arm_glob_soft_price(ROBOT_ARM_NR, s->r, robot_arm_lr, robot_arm_ur, ROBOT_ARM_GLOB_SOFT_R, ROBOT_ARM_DIM(ROBOT_ARM_NR));
    }
#else
    (void)s;
    (void)g;
#endif
    return total;
}

/* The solver's primal point into z. */
static void robot_arm_glob_get_z(const robot_arm_solver *s, robot_arm_real *z)
{
    robot_arm_glob_copy(z, &s->x[0][0], (ROBOT_ARM_N + 1) * ROBOT_ARM_NX);
    robot_arm_glob_copy(z + (ROBOT_ARM_N + 1) * ROBOT_ARM_NX, &s->u[0][0], ROBOT_ARM_N * ROBOT_ARM_NU);
}

/* The solver's multipliers into y (the layout of robot_arm_init). */
static void robot_arm_glob_get_y(const robot_arm_solver *s, robot_arm_real *y)
{
    int k, i, o = 0;
    robot_arm_glob_copy(y, &s->lam[0][0], (ROBOT_ARM_N + 1) * ROBOT_ARM_NX);
    o += (ROBOT_ARM_N + 1) * ROBOT_ARM_NX;
    for (k = 0; k < ROBOT_ARM_N; ++k) {
        for (i = 0; i < ROBOT_ARM_NG; ++i) {
            y[o++] = s->mu_g[k][i];
        }
    }
    robot_arm_glob_copy(y + o, &s->mu_b[0][0], ROBOT_ARM_N * ROBOT_ARM_NW);
    o += ROBOT_ARM_N * ROBOT_ARM_NW;
    robot_arm_glob_copy(y + o, s->mu_bN, ROBOT_ARM_NX);
    o += ROBOT_ARM_NX;
    robot_arm_glob_copy(y + o, s->mu_r, ROBOT_ARM_NR);
    o += ROBOT_ARM_NR;
    robot_arm_glob_copy(y + o, s->nu, ROBOT_ARM_NE);
}

/* init at the primal point z with the multipliers y. */
static int robot_arm_glob_init_at(robot_arm_solver *s, const robot_arm_real *xhat0, const robot_arm_real *z,
                              const robot_arm_real *y)
{
    const robot_arm_real *mu_g = y + (ROBOT_ARM_N + 1) * ROBOT_ARM_NX;
    const robot_arm_real *mu_b = mu_g + ROBOT_ARM_N * ROBOT_ARM_NG;
    const robot_arm_real *mu_bN = mu_b + ROBOT_ARM_N * ROBOT_ARM_NW;
    const robot_arm_real *mu_r = mu_bN + ROBOT_ARM_NX;
    const robot_arm_real *nu = mu_r + ROBOT_ARM_NR;
    return robot_arm_init(s, xhat0, z, z + (ROBOT_ARM_N + 1) * ROBOT_ARM_NX, y, ROBOT_ARM_NG > 0 ? mu_g : 0, mu_b, mu_bN,
                      ROBOT_ARM_NR > 0 ? mu_r : 0, ROBOT_ARM_NE > 0 ? nu : 0);
}

/* The sufficient decrease test of a trial's merit phi (ok: finite) against phi0 and slope D. */
static int robot_arm_glob_armijo(int ok, robot_arm_real phi, robot_arm_real phi0, robot_arm_real alpha, robot_arm_real D)
{
    robot_arm_real floor_ = ROBOT_ARM_GLOB_MERIT_FLOOR * ROBOT_ARM_REAL_EPSILON * (ROBOT_ARM_R(1.0) + robot_arm_fabs(phi0));
    return ok && phi <= phi0 + ROBOT_ARM_GLOB_ARMIJO * alpha * robot_arm_fmin(D, ROBOT_ARM_R(0.0)) + floor_;
}

/* Take the point zt with the multipliers y (init there); alpha, merit phi, relaxed. */
static int robot_arm_glob_accept(robot_arm_solver *s, robot_arm_glob *g, const robot_arm_real *xhat0, robot_arm_real alpha,
                             robot_arm_real phi, int relaxed)
{
    int rc = robot_arm_glob_init_at(s, xhat0, g->zt, g->y);
    if (rc != ROBOT_ARM_OK) {
        g->reason = ROBOT_ARM_GLOB_FUNCTION;
        return rc;
    }
    g->alpha = alpha;
    g->merit = phi;
    g->relaxed = relaxed;
    g->iterations += 1;
    return ROBOT_ARM_OK;
}

/* Backtracking from alpha along dz from z (multipliers y0 -> yq), against phi0 and slope D;
 * the accepted point initialised, else z (its QP prepared again) and a failure. g->y is the
 * blend, g->zt the trial. */
static int robot_arm_glob_line_search(robot_arm_solver *s, robot_arm_glob *g, const robot_arm_real *xhat0,
                                  const robot_arm_real *z, const robot_arm_real *dz, const robot_arm_real *y0,
                                  const robot_arm_real *yq, robot_arm_real phi0, robot_arm_real D, robot_arm_real alpha)
{
    robot_arm_real phi;
    int i, ok, rc;
    while (g->trials < ROBOT_ARM_GLOB_MAX_TRIALS) {
        g->trials += 1;
        for (i = 0; i < ROBOT_ARM_GLOB_NZ; ++i) {
            g->zt[i] = z[i] + alpha * dz[i];
        }
        phi = robot_arm_glob_merit(s, xhat0, g->zt, g->penalty, &ok);
        if (robot_arm_glob_armijo(ok, phi, phi0, alpha, D)) {
            for (i = 0; i < ROBOT_ARM_GLOB_NY; ++i) {
                g->y[i] = y0[i] + alpha * (yq[i] - y0[i]);
            }
            return robot_arm_glob_accept(s, g, xhat0, alpha, phi, 0);
        }
        alpha *= ROBOT_ARM_GLOB_BACKTRACK;
    }
    /* the start point, its QP prepared again (g->y may alias y0: copied first) */
    robot_arm_glob_copy(g->zt, z, ROBOT_ARM_GLOB_NZ);
    if (y0 != g->y) {
        robot_arm_glob_copy(g->y, y0, ROBOT_ARM_GLOB_NY);
    }
    rc = robot_arm_glob_init_at(s, xhat0, g->zt, g->y);
    g->reason = ROBOT_ARM_GLOB_LINE_SEARCH;
    return rc != ROBOT_ARM_OK ? rc : ROBOT_ARM_ERR_DIVERGED;
}

/* The relaxed steps did not decrease the merit enough: the line search from the watchdog's
 * point along its step, from alpha = 1/2 (its full step was refused). */
static int robot_arm_glob_restore(robot_arm_solver *s, robot_arm_glob *g, const robot_arm_real *xhat0)
{
    robot_arm_real nu = g->penalty;
    robot_arm_real phi_s = g->wf + nu * g->wc, D_s = g->wadp - nu * g->wc;
    g->watch = 0;
    g->no_relax = 1;
    g->trials = 0;
    g->restores += 1;
    g->slope = D_s;
    return robot_arm_glob_line_search(s, g, xhat0, g->wz, g->wdz, g->wy, g->wyq, phi_s, D_s,
                                  ROBOT_ARM_GLOB_BACKTRACK);
}

static int robot_arm_glob_step_fixed(robot_arm_solver *s, robot_arm_glob *g, const robot_arm_real *xhat0)
{
    robot_arm_real f0 = ROBOT_ARM_R(0.0), c0 = ROBOT_ARM_R(0.0), nu, ymax = ROBOT_ARM_R(0.0), adp, D, phi0, phi1;
    robot_arm_real u0[ROBOT_ARM_NU];
    int k, i, rc, ok;

    robot_arm_glob_get_z(s, g->z);
    robot_arm_glob_get_y(s, g->y);
    rc = robot_arm_glob_merit_parts(s, xhat0, g->z, &f0, &c0);
    if (rc != ROBOT_ARM_OK) {
        g->reason = ROBOT_ARM_GLOB_FUNCTION;
        return rc;
    }
    /* the interior point only: the step's QP is solved from scratch in both backends */
    s->qp_no_active_set = 1;
    rc = robot_arm_feedback(s, xhat0, u0);
    s->qp_no_active_set = 0;
    if (rc != ROBOT_ARM_OK) {
        if (g->watch > 0) {
            /* a relaxed step led here: back to the watchdog's point, a line search there */
            return robot_arm_glob_restore(s, g, xhat0);
        }
        g->reason = rc == ROBOT_ARM_ERR_DIVERGED ? ROBOT_ARM_GLOB_STEP_BOX
                    : rc == ROBOT_ARM_ERR_QP     ? ROBOT_ARM_GLOB_QP
                                             : ROBOT_ARM_GLOB_FUNCTION;
        return rc;
    }
    robot_arm_glob_get_z(s, g->zt); /* the full step */
    for (i = 0; i < ROBOT_ARM_GLOB_NZ; ++i) {
        g->dz[i] = g->zt[i] - g->z[i];
    }
    robot_arm_glob_get_y(s, g->yq);
    for (i = 0; i < ROBOT_ARM_GLOB_NY; ++i) {
        ymax = robot_arm_fmax(ymax, robot_arm_fabs(g->yq[i]));
    }
    if (g->penalty < ROBOT_ARM_GLOB_PENALTY_MARGIN * ymax) {
        g->penalty = ROBOT_ARM_GLOB_PENALTY_RAISE * ymax;
    }
    nu = g->penalty;
    /* the cost's slope along the step (the QP's gradient: every block fresh) and the change
     * of the soft prices, with the blocks of the QP just solved */
    adp = ROBOT_ARM_R(0.0);
    for (k = 0; k < ROBOT_ARM_N; ++k) {
        for (i = 0; i < ROBOT_ARM_NX; ++i) {
            adp += s->qp_in.g[k][i] * g->dz[k * ROBOT_ARM_NX + i];
        }
        for (i = 0; i < ROBOT_ARM_NU; ++i) {
            adp += s->qp_in.g[k][ROBOT_ARM_NX + i] * g->dz[(ROBOT_ARM_N + 1) * ROBOT_ARM_NX + k * ROBOT_ARM_NU + i];
        }
    }
    for (i = 0; i < ROBOT_ARM_NX; ++i) {
        adp += s->qp_in.gN[i] * g->dz[ROBOT_ARM_N * ROBOT_ARM_NX + i];
    }
    adp += robot_arm_glob_soft_change(s, g);
    D = adp - nu * c0;
    phi0 = f0 + nu * c0;
    g->slope = D;
    g->trials = 1;
    robot_arm_glob_get_z(s, g->zt); /* (the soft change used zt as scratch) */
    phi1 = robot_arm_glob_merit(s, xhat0, g->zt, nu, &ok);
    if (g->watch == 0) {
        if (robot_arm_glob_armijo(ok, phi1, phi0, ROBOT_ARM_R(1.0), D)) {
            robot_arm_glob_copy(g->y, g->yq, ROBOT_ARM_GLOB_NY);
            return robot_arm_glob_accept(s, g, xhat0, ROBOT_ARM_R(1.0), phi1, 0);
        }
        if (ok && !g->no_relax) {
            /* the watchdog: the full step all the same, the point before it kept */
            robot_arm_glob_copy(g->wz, g->z, ROBOT_ARM_GLOB_NZ);
            robot_arm_glob_copy(g->wdz, g->dz, ROBOT_ARM_GLOB_NZ);
            robot_arm_glob_copy(g->wy, g->y, ROBOT_ARM_GLOB_NY);
            robot_arm_glob_copy(g->wyq, g->yq, ROBOT_ARM_GLOB_NY);
            g->wf = f0;
            g->wc = c0;
            g->wadp = adp;
            g->watch = 1;
            robot_arm_glob_copy(g->y, g->yq, ROBOT_ARM_GLOB_NY);
            return robot_arm_glob_accept(s, g, xhat0, ROBOT_ARM_R(1.0), phi1, 1);
        }
        rc = robot_arm_glob_line_search(s, g, xhat0, g->z, g->dz, g->y, g->yq, phi0, D, ROBOT_ARM_GLOB_BACKTRACK);
        if (rc == ROBOT_ARM_OK) {
            g->no_relax = 0;
        }
        return rc;
    }
    if (robot_arm_glob_armijo(ok, phi1, g->wf + nu * g->wc, ROBOT_ARM_R(1.0), g->wadp - nu * g->wc)) {
        g->watch = 0;
        robot_arm_glob_copy(g->y, g->yq, ROBOT_ARM_GLOB_NY);
        return robot_arm_glob_accept(s, g, xhat0, ROBOT_ARM_R(1.0), phi1, 0);
    }
    if (ok && g->watch < ROBOT_ARM_GLOB_WATCHDOG) {
        g->watch += 1;
        robot_arm_glob_copy(g->y, g->yq, ROBOT_ARM_GLOB_NY);
        return robot_arm_glob_accept(s, g, xhat0, ROBOT_ARM_R(1.0), phi1, 1);
    }
    return robot_arm_glob_restore(s, g, xhat0);
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
    s->qp_prefactored = 0; /* the step's evaluations use the QP's memory */
    rc = robot_arm_glob_step_fixed(s, g, xh);
    s->qp_prefactored = 0;
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
