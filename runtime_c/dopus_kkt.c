/* KKT measure (docs/algorithm.md section 6). */
#include <math.h>

#include "dopus_kkt.h"
#include "dopus_linalg.h"
#include "dopus_problem.h"

#define NG1 DOPUS_DIM(DOPUS_NG)
#define NP1 DOPUS_DIM(DOPUS_NP)

static dopus_real dopus_kkt_max(dopus_real a, dopus_real b)
{
    return a > b ? a : b;
}

/* Violation max(0, v - ub, lb - v) of one row. */
static dopus_real dopus_kkt_viol(dopus_real v, dopus_real lb, dopus_real ub)
{
    return dopus_kkt_max(DOPUS_R(0.0), dopus_kkt_max(v - ub, lb - v));
}

/* Complementarity of a signed multiplier mu of the row lb <= v <= ub:
 * max(mu,0) |ub - v| and max(-mu,0) |v - lb|; a nonzero multiplier on an infinite side
 * contributes |mu|. */
static dopus_real dopus_kkt_comp(dopus_real mu, dopus_real v, dopus_real lb, dopus_real ub)
{
    dopus_real c = DOPUS_R(0.0);
    if (mu > DOPUS_R(0.0)) {
        c = isinf(ub) ? mu : mu * dopus_fabs(ub - v);
    } else if (mu < DOPUS_R(0.0)) {
        c = isinf(lb) ? -mu : -mu * dopus_fabs(v - lb);
    }
    return c;
}

#if DOPUS_NSOFT > 0
/* A row with soft weights w (w[0 .. 3 * stride]: L1 lower, L1 upper, L2 lower, L2 upper):
 * a hard side as above; a soft side with multiplier m at its best slack s = max(s0, (m - l1)
 * / l2) (s0 = max(0, lb - v) the violation; s = s0 when l2 = 0), where the slack's
 * stationarity l1 + l2 s - m = y must be >= 0, with the complementarity m (v - lb + s) and y s
 * (docs/algorithm.md section 12), each into comp. */
static void dopus_kkt_row(dopus_real v, dopus_real lb, dopus_real ub, dopus_real mu, const dopus_real *w,
                          int stride, dopus_real *ineq, dopus_real *comp)
{
    const int slo = isfinite(lb) && (w[0] > DOPUS_R(0.0) || w[2 * stride] > DOPUS_R(0.0));
    const int sup = isfinite(ub) && (w[stride] > DOPUS_R(0.0) || w[3 * stride] > DOPUS_R(0.0));
    const dopus_real lbh = slo ? -INFINITY : lb, ubh = sup ? INFINITY : ub;
    const dopus_real muh = ((mu > DOPUS_R(0.0) && sup) || (mu < DOPUS_R(0.0) && slo)) ? DOPUS_R(0.0) : mu;
    int side;
    *ineq = dopus_kkt_max(*ineq, dopus_kkt_viol(v, lbh, ubh));
    *comp = dopus_kkt_max(*comp, dopus_kkt_comp(muh, v, lbh, ubh));
    for (side = 0; side < 2; ++side) {
        const dopus_real m = dopus_kkt_max(side ? mu : -mu, DOPUS_R(0.0));
        const dopus_real gap = side ? ub - v : v - lb;
        const dopus_real l1 = w[side * stride], l2 = w[(2 + side) * stride];
        dopus_real sl = dopus_kkt_max(DOPUS_R(0.0), -gap), y;
        if (!(side ? sup : slo)) {
            continue;
        }
        if (l2 > DOPUS_R(0.0)) {
            sl = dopus_kkt_max(sl, (m - l1) / l2);
        }
        y = l1 + l2 * sl - m;
        *comp = dopus_kkt_max(*comp, dopus_kkt_max(DOPUS_R(0.0), -y));
        *comp = dopus_kkt_max(*comp, m * (gap + sl));
        *comp = dopus_kkt_max(*comp, dopus_kkt_max(DOPUS_R(0.0), y) * sl);
    }
}
#define DOPUS_KKT_ROW(v, lb, ub, mu, w, stride)                                                              \
    dopus_kkt_row((v), (lb), (ub), (mu), (w), (stride), &ineq, &comp)
#else
#define DOPUS_KKT_ROW(v, lb, ub, mu, w, stride)                                                              \
    do {                                                                                                     \
        ineq = dopus_kkt_max(ineq, dopus_kkt_viol((v), (lb), (ub)));                                         \
        comp = dopus_kkt_max(comp, dopus_kkt_comp((mu), (v), (lb), (ub)));                                   \
    } while (0)
#endif

int dopus_kkt_measure(const dopus_real *x, const dopus_real *u, const dopus_real *lam, const dopus_real *mu_g,
                      const dopus_real *mu_b, const dopus_real *mu_bN, const dopus_real *mu_r,
                      const dopus_real *nu, const dopus_real *p, const dopus_real *xhat0,
                      dopus_fun_work *work, dopus_real *parts)
{
    dopus_real stat = DOPUS_R(0.0), eq = DOPUS_R(0.0), ineq = DOPUS_R(0.0), comp = DOPUS_R(0.0);
    dopus_real gL[DOPUS_NW], phi[DOPUS_NX], g[DOPUS_DIM(DOPUS_NG)], l;
    dopus_real gLN[DOPUS_NX], E, r[DOPUS_DIM(DOPUS_NR)], r_eq[DOPUS_DIM(DOPUS_NE)];
    int k, i;

    for (i = 0; i < DOPUS_NX; ++i) {
        eq = dopus_kkt_max(eq, dopus_fabs(x[i] - xhat0[i]));
    }
    for (k = 0; k < DOPUS_N; ++k) {
        if (dopus_eval_stage_grad(x + k * DOPUS_NX, u + k * DOPUS_NU, p + k * NP1, lam + (k + 1) * DOPUS_NX,
                                  mu_g + k * NG1, gL, phi, &l, g, work) != 0) {
            return DOPUS_KKT_FUNCTION;
        }
        if (!dopus_lai_vec_finite(DOPUS_NW, gL) || !dopus_lai_vec_finite(DOPUS_NX, phi) ||
            !dopus_lai_vec_finite(DOPUS_NG, g) || !isfinite(l)) {
            return DOPUS_KKT_NONFINITE;
        }
        /* stationarity gL_k + mu_b_k + [lam_k; 0] */
        for (i = 0; i < DOPUS_NW; ++i) {
            dopus_real v =
                gL[i] + mu_b[k * DOPUS_NW + i] + (i < DOPUS_NX ? lam[k * DOPUS_NX + i] : DOPUS_R(0.0));
            stat = dopus_kkt_max(stat, dopus_fabs(v));
        }
        for (i = 0; i < DOPUS_NX; ++i) {
            eq = dopus_kkt_max(eq, dopus_fabs(x[(k + 1) * DOPUS_NX + i] - phi[i]));
        }
        for (i = 0; i < DOPUS_NG; ++i) {
            DOPUS_KKT_ROW(g[i], dopus_lg_k[k][i], dopus_ug_k[k][i], mu_g[k * NG1 + i], &dopus_soft_g[0][i],
                          DOPUS_DIM(DOPUS_NG));
        }
        /* simple bounds of x_k: none at stage 0 (a multiplier there pairs with infinite
         * sides and counts with its magnitude) */
        if (k == 0) {
            for (i = 0; i < DOPUS_NX; ++i) {
                comp = dopus_kkt_max(comp, dopus_fabs(mu_b[i]));
            }
        } else {
            for (i = 0; i < DOPUS_NX; ++i) {
                DOPUS_KKT_ROW(x[k * DOPUS_NX + i], dopus_lbx[i], dopus_ubx[i], mu_b[k * DOPUS_NW + i],
                              &dopus_soft_x[0][i], DOPUS_NX);
            }
        }
        for (i = 0; i < DOPUS_NU; ++i) {
            ineq = dopus_kkt_max(ineq, dopus_kkt_viol(u[k * DOPUS_NU + i], dopus_lbu[i], dopus_ubu[i]));
            comp = dopus_kkt_max(comp, dopus_kkt_comp(mu_b[k * DOPUS_NW + DOPUS_NX + i], u[k * DOPUS_NU + i],
                                                      dopus_lbu[i], dopus_ubu[i]));
        }
    }
    if (dopus_eval_term_grad(x + DOPUS_N * DOPUS_NX, p + DOPUS_N * NP1, mu_r, nu, gLN, &E, r, r_eq, work) !=
        0) {
        return DOPUS_KKT_FUNCTION;
    }
    if (!dopus_lai_vec_finite(DOPUS_NX, gLN) || !isfinite(E) || !dopus_lai_vec_finite(DOPUS_NR, r) ||
        !dopus_lai_vec_finite(DOPUS_NE, r_eq)) {
        return DOPUS_KKT_NONFINITE;
    }
    for (i = 0; i < DOPUS_NX; ++i) {
        stat = dopus_kkt_max(stat, dopus_fabs(gLN[i] + mu_bN[i] + lam[DOPUS_N * DOPUS_NX + i]));
        DOPUS_KKT_ROW(x[DOPUS_N * DOPUS_NX + i], dopus_lbx[i], dopus_ubx[i], mu_bN[i], &dopus_soft_x[0][i],
                      DOPUS_NX);
    }
    for (i = 0; i < DOPUS_NE; ++i) {
        eq = dopus_kkt_max(eq, dopus_fabs(r_eq[i]));
    }
    for (i = 0; i < DOPUS_NR; ++i) {
        DOPUS_KKT_ROW(r[i], dopus_lr[i], dopus_ur[i], mu_r[i], &dopus_soft_r[0][i], DOPUS_DIM(DOPUS_NR));
    }
    parts[0] = stat;
    parts[1] = eq;
    parts[2] = ineq;
    parts[3] = comp;
    return DOPUS_KKT_OK;
}

/* The largest |v_i| of n entries, at least m. */
static dopus_real dopus_kkt_big(dopus_real m, int n, const dopus_real *v)
{
    int i;
    for (i = 0; i < n; ++i) {
        m = dopus_kkt_max(m, dopus_fabs(v[i]));
    }
    return m;
}

dopus_real dopus_kkt_relative(const dopus_real *parts, const dopus_real *x, const dopus_real *u,
                              const dopus_real *lam, const dopus_real *mu_g, const dopus_real *mu_b,
                              const dopus_real *mu_bN, const dopus_real *mu_r, const dopus_real *nu)
{
    dopus_real sd = DOPUS_R(1.0), sp = DOPUS_R(1.0), rel;
    int k;
    sd = dopus_kkt_big(sd, (DOPUS_N + 1) * DOPUS_NX, lam);
    for (k = 0; k < DOPUS_N; ++k) {
        sd = dopus_kkt_big(sd, DOPUS_NG, mu_g + k * NG1);
    }
    sd = dopus_kkt_big(sd, DOPUS_N * DOPUS_NW, mu_b);
    sd = dopus_kkt_big(sd, DOPUS_NX, mu_bN);
    sd = dopus_kkt_big(sd, DOPUS_NR, mu_r);
    sd = dopus_kkt_big(sd, DOPUS_NE, nu);
    sp = dopus_kkt_big(sp, (DOPUS_N + 1) * DOPUS_NX, x);
    sp = dopus_kkt_big(sp, DOPUS_N * DOPUS_NU, u);
    rel = dopus_kkt_max(parts[0] / sd, parts[1] / sp);
    rel = dopus_kkt_max(rel, parts[2] / sp);
    return dopus_kkt_max(rel, parts[3] / (sd * sp));
}
