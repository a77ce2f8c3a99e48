/* KKT measure (docs/algorithm.md section 6). */
#include <math.h>

#include "unicycle_kkt.h"
#include "unicycle_linalg.h"
#include "unicycle_problem.h"

#define NG1 UNICYCLE_DIM(UNICYCLE_NG)
#define NP1 UNICYCLE_DIM(UNICYCLE_NP)

static unicycle_real unicycle_kkt_max(unicycle_real a, unicycle_real b)
{
    return a > b ? a : b;
}

/* Violation max(0, v - ub, lb - v) of one row. */
static unicycle_real unicycle_kkt_viol(unicycle_real v, unicycle_real lb, unicycle_real ub)
{
    return unicycle_kkt_max(UNICYCLE_R(0.0), unicycle_kkt_max(v - ub, lb - v));
}

/* Complementarity of a signed multiplier mu of the row lb <= v <= ub:
 * max(mu,0) |ub - v| and max(-mu,0) |v - lb|; a nonzero multiplier on an infinite side
 * contributes |mu|. */
static unicycle_real unicycle_kkt_comp(unicycle_real mu, unicycle_real v, unicycle_real lb, unicycle_real ub)
{
    unicycle_real c = UNICYCLE_R(0.0);
    if (mu > UNICYCLE_R(0.0)) {
        c = isinf(ub) ? mu : mu * unicycle_fabs(ub - v);
    } else if (mu < UNICYCLE_R(0.0)) {
        c = isinf(lb) ? -mu : -mu * unicycle_fabs(v - lb);
    }
    return c;
}

#if UNICYCLE_NSOFT > 0
/* A row with soft weights w (w[0 .. 3 * stride]: L1 lower, L1 upper, L2 lower, L2 upper):
 * a hard side as above; a soft side with multiplier m at its best slack s = max(s0, (m - l1)
 * / l2) (s0 = max(0, lb - v) the violation; s = s0 when l2 = 0), where the slack's
 * stationarity l1 + l2 s - m = y must be >= 0, with the complementarity m (v - lb + s) and y s
 * (docs/algorithm.md section 12), each into comp. */
static void unicycle_kkt_row(unicycle_real v, unicycle_real lb, unicycle_real ub, unicycle_real mu, const unicycle_real *w,
                          int stride, unicycle_real *ineq, unicycle_real *comp)
{
    const int slo = isfinite(lb) && (w[0] > UNICYCLE_R(0.0) || w[2 * stride] > UNICYCLE_R(0.0));
    const int sup = isfinite(ub) && (w[stride] > UNICYCLE_R(0.0) || w[3 * stride] > UNICYCLE_R(0.0));
    const unicycle_real lbh = slo ? -INFINITY : lb, ubh = sup ? INFINITY : ub;
    const unicycle_real muh = ((mu > UNICYCLE_R(0.0) && sup) || (mu < UNICYCLE_R(0.0) && slo)) ? UNICYCLE_R(0.0) : mu;
    int side;
    *ineq = unicycle_kkt_max(*ineq, unicycle_kkt_viol(v, lbh, ubh));
    *comp = unicycle_kkt_max(*comp, unicycle_kkt_comp(muh, v, lbh, ubh));
    for (side = 0; side < 2; ++side) {
        const unicycle_real m = unicycle_kkt_max(side ? mu : -mu, UNICYCLE_R(0.0));
        const unicycle_real gap = side ? ub - v : v - lb;
        const unicycle_real l1 = w[side * stride], l2 = w[(2 + side) * stride];
        unicycle_real sl = unicycle_kkt_max(UNICYCLE_R(0.0), -gap), y;
        if (!(side ? sup : slo)) {
            continue;
        }
        if (l2 > UNICYCLE_R(0.0)) {
            sl = unicycle_kkt_max(sl, (m - l1) / l2);
        }
        y = l1 + l2 * sl - m;
        *comp = unicycle_kkt_max(*comp, unicycle_kkt_max(UNICYCLE_R(0.0), -y));
        *comp = unicycle_kkt_max(*comp, m * (gap + sl));
        *comp = unicycle_kkt_max(*comp, unicycle_kkt_max(UNICYCLE_R(0.0), y) * sl);
    }
}
#define UNICYCLE_KKT_ROW(v, lb, ub, mu, w, stride)                                                              \
    unicycle_kkt_row((v), (lb), (ub), (mu), (w), (stride), &ineq, &comp)
#else
#define UNICYCLE_KKT_ROW(v, lb, ub, mu, w, stride)                                                              \
    do {                                                                                                     \
        ineq = unicycle_kkt_max(ineq, unicycle_kkt_viol((v), (lb), (ub)));                                         \
        comp = unicycle_kkt_max(comp, unicycle_kkt_comp((mu), (v), (lb), (ub)));                                   \
    } while (0)
#endif

int unicycle_kkt_measure(const unicycle_real *x, const unicycle_real *u, const unicycle_real *lam, const unicycle_real *mu_g,
                      const unicycle_real *mu_b, const unicycle_real *mu_bN, const unicycle_real *mu_r,
                      const unicycle_real *nu, const unicycle_real *p, const unicycle_real *xhat0,
                      unicycle_fun_work *work, unicycle_real *parts)
{
    unicycle_real stat = UNICYCLE_R(0.0), eq = UNICYCLE_R(0.0), ineq = UNICYCLE_R(0.0), comp = UNICYCLE_R(0.0);
    unicycle_real gL[UNICYCLE_NW], phi[UNICYCLE_NX], g[UNICYCLE_DIM(UNICYCLE_NG)], l;
    unicycle_real gLN[UNICYCLE_NX], E, r[UNICYCLE_DIM(UNICYCLE_NR)], r_eq[UNICYCLE_DIM(UNICYCLE_NE)];
    int k, i;

    for (i = 0; i < UNICYCLE_NX; ++i) {
        eq = unicycle_kkt_max(eq, unicycle_fabs(x[i] - xhat0[i]));
    }
    for (k = 0; k < UNICYCLE_N; ++k) {
        if (unicycle_eval_stage_grad(x + k * UNICYCLE_NX, u + k * UNICYCLE_NU, p + k * NP1, lam + (k + 1) * UNICYCLE_NX,
                                  mu_g + k * NG1, gL, phi, &l, g, work) != 0) {
            return UNICYCLE_KKT_FUNCTION;
        }
        if (!unicycle_lai_vec_finite(UNICYCLE_NW, gL) || !unicycle_lai_vec_finite(UNICYCLE_NX, phi) ||
            !unicycle_lai_vec_finite(UNICYCLE_NG, g) || !isfinite(l)) {
            return UNICYCLE_KKT_NONFINITE;
        }
        /* stationarity gL_k + mu_b_k + [lam_k; 0] */
        for (i = 0; i < UNICYCLE_NW; ++i) {
            unicycle_real v =
                gL[i] + mu_b[k * UNICYCLE_NW + i] + (i < UNICYCLE_NX ? lam[k * UNICYCLE_NX + i] : UNICYCLE_R(0.0));
            stat = unicycle_kkt_max(stat, unicycle_fabs(v));
        }
        for (i = 0; i < UNICYCLE_NX; ++i) {
            eq = unicycle_kkt_max(eq, unicycle_fabs(x[(k + 1) * UNICYCLE_NX + i] - phi[i]));
        }
        for (i = 0; i < UNICYCLE_NG; ++i) {
            UNICYCLE_KKT_ROW(g[i], unicycle_lg_k[k][i], unicycle_ug_k[k][i], mu_g[k * NG1 + i], &unicycle_soft_g[0][i],
                          UNICYCLE_DIM(UNICYCLE_NG));
        }
        /* simple bounds of x_k: none at stage 0 (a multiplier there pairs with infinite
         * sides and counts with its magnitude) */
        if (k == 0) {
            for (i = 0; i < UNICYCLE_NX; ++i) {
                comp = unicycle_kkt_max(comp, unicycle_fabs(mu_b[i]));
            }
        } else {
            for (i = 0; i < UNICYCLE_NX; ++i) {
                UNICYCLE_KKT_ROW(x[k * UNICYCLE_NX + i], unicycle_lbx[i], unicycle_ubx[i], mu_b[k * UNICYCLE_NW + i],
                              &unicycle_soft_x[0][i], UNICYCLE_NX);
            }
        }
        for (i = 0; i < UNICYCLE_NU; ++i) {
            ineq = unicycle_kkt_max(ineq, unicycle_kkt_viol(u[k * UNICYCLE_NU + i], unicycle_lbu[i], unicycle_ubu[i]));
            comp = unicycle_kkt_max(comp, unicycle_kkt_comp(mu_b[k * UNICYCLE_NW + UNICYCLE_NX + i], u[k * UNICYCLE_NU + i],
                                                      unicycle_lbu[i], unicycle_ubu[i]));
        }
    }
    if (unicycle_eval_term_grad(x + UNICYCLE_N * UNICYCLE_NX, p + UNICYCLE_N * NP1, mu_r, nu, gLN, &E, r, r_eq, work) !=
        0) {
        return UNICYCLE_KKT_FUNCTION;
    }
    if (!unicycle_lai_vec_finite(UNICYCLE_NX, gLN) || !isfinite(E) || !unicycle_lai_vec_finite(UNICYCLE_NR, r) ||
        !unicycle_lai_vec_finite(UNICYCLE_NE, r_eq)) {
        return UNICYCLE_KKT_NONFINITE;
    }
    for (i = 0; i < UNICYCLE_NX; ++i) {
        stat = unicycle_kkt_max(stat, unicycle_fabs(gLN[i] + mu_bN[i] + lam[UNICYCLE_N * UNICYCLE_NX + i]));
        UNICYCLE_KKT_ROW(x[UNICYCLE_N * UNICYCLE_NX + i], unicycle_lbx[i], unicycle_ubx[i], mu_bN[i], &unicycle_soft_x[0][i],
                      UNICYCLE_NX);
    }
    for (i = 0; i < UNICYCLE_NE; ++i) {
        eq = unicycle_kkt_max(eq, unicycle_fabs(r_eq[i]));
    }
    for (i = 0; i < UNICYCLE_NR; ++i) {
        UNICYCLE_KKT_ROW(r[i], unicycle_lr[i], unicycle_ur[i], mu_r[i], &unicycle_soft_r[0][i], UNICYCLE_DIM(UNICYCLE_NR));
    }
    parts[0] = stat;
    parts[1] = eq;
    parts[2] = ineq;
    parts[3] = comp;
    return UNICYCLE_KKT_OK;
}

/* The largest |v_i| of n entries, at least m. */
static unicycle_real unicycle_kkt_big(unicycle_real m, int n, const unicycle_real *v)
{
    int i;
    for (i = 0; i < n; ++i) {
        m = unicycle_kkt_max(m, unicycle_fabs(v[i]));
    }
    return m;
}

unicycle_real unicycle_kkt_relative(const unicycle_real *parts, const unicycle_real *x, const unicycle_real *u,
                              const unicycle_real *lam, const unicycle_real *mu_g, const unicycle_real *mu_b,
                              const unicycle_real *mu_bN, const unicycle_real *mu_r, const unicycle_real *nu)
{
    unicycle_real sd = UNICYCLE_R(1.0), sp = UNICYCLE_R(1.0), rel;
    int k;
    sd = unicycle_kkt_big(sd, (UNICYCLE_N + 1) * UNICYCLE_NX, lam);
    for (k = 0; k < UNICYCLE_N; ++k) {
        sd = unicycle_kkt_big(sd, UNICYCLE_NG, mu_g + k * NG1);
    }
    sd = unicycle_kkt_big(sd, UNICYCLE_N * UNICYCLE_NW, mu_b);
    sd = unicycle_kkt_big(sd, UNICYCLE_NX, mu_bN);
    sd = unicycle_kkt_big(sd, UNICYCLE_NR, mu_r);
    sd = unicycle_kkt_big(sd, UNICYCLE_NE, nu);
    sp = unicycle_kkt_big(sp, (UNICYCLE_N + 1) * UNICYCLE_NX, x);
    sp = unicycle_kkt_big(sp, UNICYCLE_N * UNICYCLE_NU, u);
    rel = unicycle_kkt_max(parts[0] / sd, parts[1] / sp);
    rel = unicycle_kkt_max(rel, parts[2] / sp);
    return unicycle_kkt_max(rel, parts[3] / (sd * sp));
}
