/* KKT measure (docs/algorithm.md section 6). */
#include <math.h>

#include "robot_arm_kkt.h"
#include "robot_arm_linalg.h"
#include "robot_arm_problem.h"

#define NG1 ROBOT_ARM_DIM(ROBOT_ARM_NG)
#define NP1 ROBOT_ARM_DIM(ROBOT_ARM_NP)

static robot_arm_real robot_arm_kkt_max(robot_arm_real a, robot_arm_real b)
{
    return a > b ? a : b;
}

/* Violation max(0, v - ub, lb - v) of one row. */
static robot_arm_real robot_arm_kkt_viol(robot_arm_real v, robot_arm_real lb, robot_arm_real ub)
{
    return robot_arm_kkt_max(ROBOT_ARM_R(0.0), robot_arm_kkt_max(v - ub, lb - v));
}

/* Complementarity of a signed multiplier mu of the row lb <= v <= ub:
 * max(mu,0) |ub - v| and max(-mu,0) |v - lb|; a nonzero multiplier on an infinite side
 * contributes |mu|. */
static robot_arm_real robot_arm_kkt_comp(robot_arm_real mu, robot_arm_real v, robot_arm_real lb, robot_arm_real ub)
{
    robot_arm_real c = ROBOT_ARM_R(0.0);
    if (mu > ROBOT_ARM_R(0.0)) {
        c = isinf(ub) ? mu : mu * robot_arm_fabs(ub - v);
    } else if (mu < ROBOT_ARM_R(0.0)) {
        c = isinf(lb) ? -mu : -mu * robot_arm_fabs(v - lb);
    }
    return c;
}

#if ROBOT_ARM_NSOFT > 0
/* A row with soft weights w (w[0 .. 3 * stride]: L1 lower, L1 upper, L2 lower, L2 upper):
 * a hard side as above; a soft side with multiplier m at its best slack s = max(s0, (m - l1)
 * / l2) (s0 = max(0, lb - v) the violation; s = s0 when l2 = 0), where the slack's
 * stationarity l1 + l2 s - m = y must be >= 0, with the complementarity m (v - lb + s) and y s
 * (docs/algorithm.md section 12), each into comp. */
static void robot_arm_kkt_row(robot_arm_real v, robot_arm_real lb, robot_arm_real ub, robot_arm_real mu, const robot_arm_real *w,
                          int stride, robot_arm_real *ineq, robot_arm_real *comp)
{
    const int slo = isfinite(lb) && (w[0] > ROBOT_ARM_R(0.0) || w[2 * stride] > ROBOT_ARM_R(0.0));
    const int sup = isfinite(ub) && (w[stride] > ROBOT_ARM_R(0.0) || w[3 * stride] > ROBOT_ARM_R(0.0));
    const robot_arm_real lbh = slo ? -INFINITY : lb, ubh = sup ? INFINITY : ub;
    const robot_arm_real muh = ((mu > ROBOT_ARM_R(0.0) && sup) || (mu < ROBOT_ARM_R(0.0) && slo)) ? ROBOT_ARM_R(0.0) : mu;
    int side;
    *ineq = robot_arm_kkt_max(*ineq, robot_arm_kkt_viol(v, lbh, ubh));
    *comp = robot_arm_kkt_max(*comp, robot_arm_kkt_comp(muh, v, lbh, ubh));
    for (side = 0; side < 2; ++side) {
        const robot_arm_real m = robot_arm_kkt_max(side ? mu : -mu, ROBOT_ARM_R(0.0));
        const robot_arm_real gap = side ? ub - v : v - lb;
        const robot_arm_real l1 = w[side * stride], l2 = w[(2 + side) * stride];
        robot_arm_real sl = robot_arm_kkt_max(ROBOT_ARM_R(0.0), -gap), y;
        if (!(side ? sup : slo)) {
            continue;
        }
        if (l2 > ROBOT_ARM_R(0.0)) {
            sl = robot_arm_kkt_max(sl, (m - l1) / l2);
        }
        y = l1 + l2 * sl - m;
        *comp = robot_arm_kkt_max(*comp, robot_arm_kkt_max(ROBOT_ARM_R(0.0), -y));
        *comp = robot_arm_kkt_max(*comp, m * (gap + sl));
        *comp = robot_arm_kkt_max(*comp, robot_arm_kkt_max(ROBOT_ARM_R(0.0), y) * sl);
    }
}
#define ROBOT_ARM_KKT_ROW(v, lb, ub, mu, w, stride)                                                              \
    robot_arm_kkt_row((v), (lb), (ub), (mu), (w), (stride), &ineq, &comp)
#else
#define ROBOT_ARM_KKT_ROW(v, lb, ub, mu, w, stride)                                                              \
    do {                                                                                                     \
        ineq = robot_arm_kkt_max(ineq, robot_arm_kkt_viol((v), (lb), (ub)));                                         \
        comp = robot_arm_kkt_max(comp, robot_arm_kkt_comp((mu), (v), (lb), (ub)));                                   \
    } while (0)
#endif

int robot_arm_kkt_measure(const robot_arm_real *x, const robot_arm_real *u, const robot_arm_real *lam, const robot_arm_real *mu_g,
                      const robot_arm_real *mu_b, const robot_arm_real *mu_bN, const robot_arm_real *mu_r,
                      const robot_arm_real *nu, const robot_arm_real *p, const robot_arm_real *xhat0,
                      robot_arm_fun_work *work, robot_arm_real *parts)
{
    robot_arm_real stat = ROBOT_ARM_R(0.0), eq = ROBOT_ARM_R(0.0), ineq = ROBOT_ARM_R(0.0), comp = ROBOT_ARM_R(0.0);
    robot_arm_real gL[ROBOT_ARM_NW], phi[ROBOT_ARM_NX], g[ROBOT_ARM_DIM(ROBOT_ARM_NG)], l;
    robot_arm_real gLN[ROBOT_ARM_NX], E, r[ROBOT_ARM_DIM(ROBOT_ARM_NR)], r_eq[ROBOT_ARM_DIM(ROBOT_ARM_NE)];
    int k, i;

    for (i = 0; i < ROBOT_ARM_NX; ++i) {
        eq = robot_arm_kkt_max(eq, robot_arm_fabs(x[i] - xhat0[i]));
    }
    for (k = 0; k < ROBOT_ARM_N; ++k) {
        if (robot_arm_eval_stage_grad(x + k * ROBOT_ARM_NX, u + k * ROBOT_ARM_NU, p + k * NP1, lam + (k + 1) * ROBOT_ARM_NX,
                                  mu_g + k * NG1, gL, phi, &l, g, work) != 0) {
            return ROBOT_ARM_KKT_FUNCTION;
        }
        if (!robot_arm_lai_vec_finite(ROBOT_ARM_NW, gL) || !robot_arm_lai_vec_finite(ROBOT_ARM_NX, phi) ||
            !robot_arm_lai_vec_finite(ROBOT_ARM_NG, g) || !isfinite(l)) {
            return ROBOT_ARM_KKT_NONFINITE;
        }
        /* stationarity gL_k + mu_b_k + [lam_k; 0] */
        for (i = 0; i < ROBOT_ARM_NW; ++i) {
            robot_arm_real v =
                gL[i] + mu_b[k * ROBOT_ARM_NW + i] + (i < ROBOT_ARM_NX ? lam[k * ROBOT_ARM_NX + i] : ROBOT_ARM_R(0.0));
            stat = robot_arm_kkt_max(stat, robot_arm_fabs(v));
        }
        for (i = 0; i < ROBOT_ARM_NX; ++i) {
            eq = robot_arm_kkt_max(eq, robot_arm_fabs(x[(k + 1) * ROBOT_ARM_NX + i] - phi[i]));
        }
        for (i = 0; i < ROBOT_ARM_NG; ++i) {
            ROBOT_ARM_KKT_ROW(g[i], robot_arm_lg_k[k][i], robot_arm_ug_k[k][i], mu_g[k * NG1 + i], &robot_arm_soft_g[0][i],
                          ROBOT_ARM_DIM(ROBOT_ARM_NG));
        }
        /* simple bounds of x_k: none at stage 0 (a multiplier there pairs with infinite
         * sides and counts with its magnitude) */
        if (k == 0) {
            for (i = 0; i < ROBOT_ARM_NX; ++i) {
                comp = robot_arm_kkt_max(comp, robot_arm_fabs(mu_b[i]));
            }
        } else {
            for (i = 0; i < ROBOT_ARM_NX; ++i) {
                ROBOT_ARM_KKT_ROW(x[k * ROBOT_ARM_NX + i], robot_arm_lbx[i], robot_arm_ubx[i], mu_b[k * ROBOT_ARM_NW + i],
                              &robot_arm_soft_x[0][i], ROBOT_ARM_NX);
            }
        }
        for (i = 0; i < ROBOT_ARM_NU; ++i) {
            ineq = robot_arm_kkt_max(ineq, robot_arm_kkt_viol(u[k * ROBOT_ARM_NU + i], robot_arm_lbu[i], robot_arm_ubu[i]));
            comp = robot_arm_kkt_max(comp, robot_arm_kkt_comp(mu_b[k * ROBOT_ARM_NW + ROBOT_ARM_NX + i], u[k * ROBOT_ARM_NU + i],
                                                      robot_arm_lbu[i], robot_arm_ubu[i]));
        }
    }
    if (robot_arm_eval_term_grad(x + ROBOT_ARM_N * ROBOT_ARM_NX, p + ROBOT_ARM_N * NP1, mu_r, nu, gLN, &E, r, r_eq, work) !=
        0) {
        return ROBOT_ARM_KKT_FUNCTION;
    }
    if (!robot_arm_lai_vec_finite(ROBOT_ARM_NX, gLN) || !isfinite(E) || !robot_arm_lai_vec_finite(ROBOT_ARM_NR, r) ||
        !robot_arm_lai_vec_finite(ROBOT_ARM_NE, r_eq)) {
        return ROBOT_ARM_KKT_NONFINITE;
    }
    for (i = 0; i < ROBOT_ARM_NX; ++i) {
        stat = robot_arm_kkt_max(stat, robot_arm_fabs(gLN[i] + mu_bN[i] + lam[ROBOT_ARM_N * ROBOT_ARM_NX + i]));
        ROBOT_ARM_KKT_ROW(x[ROBOT_ARM_N * ROBOT_ARM_NX + i], robot_arm_lbx[i], robot_arm_ubx[i], mu_bN[i], &robot_arm_soft_x[0][i],
                      ROBOT_ARM_NX);
    }
    for (i = 0; i < ROBOT_ARM_NE; ++i) {
        eq = robot_arm_kkt_max(eq, robot_arm_fabs(r_eq[i]));
    }
    for (i = 0; i < ROBOT_ARM_NR; ++i) {
        ROBOT_ARM_KKT_ROW(r[i], robot_arm_lr[i], robot_arm_ur[i], mu_r[i], &robot_arm_soft_r[0][i], ROBOT_ARM_DIM(ROBOT_ARM_NR));
    }
    parts[0] = stat;
    parts[1] = eq;
    parts[2] = ineq;
    parts[3] = comp;
    return ROBOT_ARM_KKT_OK;
}

/* The largest |v_i| of n entries, at least m. */
static robot_arm_real robot_arm_kkt_big(robot_arm_real m, int n, const robot_arm_real *v)
{
    int i;
    for (i = 0; i < n; ++i) {
        m = robot_arm_kkt_max(m, robot_arm_fabs(v[i]));
    }
    return m;
}

robot_arm_real robot_arm_kkt_relative(const robot_arm_real *parts, const robot_arm_real *x, const robot_arm_real *u,
                              const robot_arm_real *lam, const robot_arm_real *mu_g, const robot_arm_real *mu_b,
                              const robot_arm_real *mu_bN, const robot_arm_real *mu_r, const robot_arm_real *nu)
{
    robot_arm_real sd = ROBOT_ARM_R(1.0), sp = ROBOT_ARM_R(1.0), rel;
    int k;
    sd = robot_arm_kkt_big(sd, (ROBOT_ARM_N + 1) * ROBOT_ARM_NX, lam);
    for (k = 0; k < ROBOT_ARM_N; ++k) {
        sd = robot_arm_kkt_big(sd, ROBOT_ARM_NG, mu_g + k * NG1);
    }
    sd = robot_arm_kkt_big(sd, ROBOT_ARM_N * ROBOT_ARM_NW, mu_b);
    sd = robot_arm_kkt_big(sd, ROBOT_ARM_NX, mu_bN);
    sd = robot_arm_kkt_big(sd, ROBOT_ARM_NR, mu_r);
    sd = robot_arm_kkt_big(sd, ROBOT_ARM_NE, nu);
    sp = robot_arm_kkt_big(sp, (ROBOT_ARM_N + 1) * ROBOT_ARM_NX, x);
    sp = robot_arm_kkt_big(sp, ROBOT_ARM_N * ROBOT_ARM_NU, u);
    rel = robot_arm_kkt_max(parts[0] / sd, parts[1] / sp);
    rel = robot_arm_kkt_max(rel, parts[2] / sp);
    return robot_arm_kkt_max(rel, parts[3] / (sd * sp));
}
