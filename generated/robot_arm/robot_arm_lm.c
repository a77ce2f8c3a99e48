/* The automatic Levenberg-Marquardt term (robot_arm_lm.h, docs/algorithm.md section 10). */
#include "robot_arm_lm.h"

#include "robot_arm_linalg.h"

#include <math.h>

void robot_arm_lm_reset(robot_arm_lm *lm, int on, robot_arm_real fixed)
{
    lm->on = on;
    lm->lm = on ? ROBOT_ARM_R(0.0) : fixed;
    lm->kkt_prev = -ROBOT_ARM_R(1.0);
    lm->uncapped = -ROBOT_ARM_R(1.0);
    lm->held = 0;
    lm->test = 0;
    lm->test_ctx = 0;
}

/* The Hessian scale h: the largest |diagonal entry| of the QP's stage and terminal blocks. */
static robot_arm_real robot_arm_lm_hessian_scale(const robot_arm_ring *ring, const robot_arm_real *A_N)
{
    robot_arm_real h = ROBOT_ARM_REAL_TINY, v;
    int k, i;
    for (k = 0; k < ROBOT_ARM_N; ++k) {
        const robot_arm_stage_slot *slot = robot_arm_ring_stage_const(ring, k);
        for (i = 0; i < ROBOT_ARM_NW; ++i) {
            v = robot_arm_fabs(slot->Ht[i + i * ROBOT_ARM_NW]);
            h = v > h ? v : h;
        }
    }
    for (i = 0; i < ROBOT_ARM_NX; ++i) {
        v = robot_arm_fabs(A_N[i + i * ROBOT_ARM_NX]);
        h = v > h ? v : h;
    }
    return h;
}

/* The two-wide kernels (ROBOT_ARM_LAI_VEC) pay from about nx = 8 on: 30 % less time for the
 * test at nx = 21 on x86-64, but 5 % more instructions at nx = 5 (short rows); smaller
 * states and targets without vectors take the plain loops. The same values either way. */
#define ROBOT_ARM_LM_VEC (ROBOT_ARM_LAI_VEC && ROBOT_ARM_NX >= 8)

/* Y = P Phi (nx x nw) and the lower triangle of Z (nw x nw) column-major */
#define ROBOT_ARM_LM_Z(i, j) Z[(i) + (j)*ROBOT_ARM_NW]

/* 1 when the QP with the term lm is strictly convex on the dynamics: the Riccati recursion
 * of its Hessian blocks (lower triangles read; inequalities and terminal constraints left
 * out) has control pivots above ROBOT_ARM_LM_PIVOT_REL h and above their round-off,
 * ROBOT_ARM_LM_ROUNDOFF times the stage's largest |Z_uu diagonal entry|.
 *
 * Per stage, Y = P Phi runs down whole columns of P (Phi read in its stored layout: no
 * transposed copy), then only the lower triangle of Z = H + lm I + Phi' Y: about half the
 * multiply-adds of the full Z, and on an in-order core without vector units (the Cortex-M)
 * the cost is the multiply-adds and their loads; there each entry of Z is a dot product of
 * two contiguous columns of length nx (Phi's column i and Y's column j). The Riccati update
 * writes P's lower triangle and mirrors it. With two-wide vectors (ROBOT_ARM_LM_VEC) Y's columns
 * (ROBOT_ARM_LAI_V2_GEMV), Z's pairs of columns over a copy of Phi' (robot_arm_lai_v2_atb_cols2, the
 * QP's kernel for its stage update; the rows of a pair from its diagonal) and the
 * update over a copy of K' run two entries at a time with their accumulators in registers,
 * every entry with the same operations in the same order. */
static int robot_arm_lm_convex(const robot_arm_lm *st, const robot_arm_ring *ring, const robot_arm_real *A_N, robot_arm_real lm,
                           robot_arm_real *work)
{
    const robot_arm_real tol = ROBOT_ARM_LM_PIVOT_REL * st->scale;
    robot_arm_real *P, *Y, *Z;
#if ROBOT_ARM_LM_VEC
    robot_arm_real PhiT[ROBOT_ARM_NW * ROBOT_ARM_NX]; /* Phi_k' */
#endif
    robot_arm_real v, floor_;
    int k, i, j, l;
    if (st->test) {
        return st->test(st->test_ctx, lm, tol); /* the same test as the QP's factorisation */
    }
    P = work;
    Y = work + ROBOT_ARM_NX * ROBOT_ARM_NX;
    Z = Y + ROBOT_ARM_NX * ROBOT_ARM_NW;
    for (j = 0; j < ROBOT_ARM_NX; ++j) {
        for (i = j; i < ROBOT_ARM_NX; ++i) {
            P[i + j * ROBOT_ARM_NX] = A_N[i + j * ROBOT_ARM_NX];
            P[j + i * ROBOT_ARM_NX] = A_N[i + j * ROBOT_ARM_NX];
        }
        P[j + j * ROBOT_ARM_NX] += lm;
    }
    for (k = ROBOT_ARM_N - 1; k >= 0; --k) {
        const robot_arm_stage_slot *slot = robot_arm_ring_stage_const(ring, k);
        const robot_arm_real *H = slot->Ht, *Phi = slot->Phit;
        /* stage 0 needs only the control block Z_uu (x_0 is fixed): Y's and Z's control
         * columns, the same values as in the full block */
        const int j0 = k == 0 ? ROBOT_ARM_NX : 0;
#if ROBOT_ARM_LM_VEC
        /* Phi' (nw x nx, its rows from j0), then Y = P Phi and Z = H + lm I + Phi' Y two
         * columns at a time */
        for (l = 0; l < ROBOT_ARM_NX; ++l) {
            for (i = j0; i < ROBOT_ARM_NW; ++i) {
                PhiT[i + l * ROBOT_ARM_NW] = Phi[l + i * ROBOT_ARM_NX];
            }
        }
        for (j = j0; j < ROBOT_ARM_NW; ++j) {
            /* column j of Y: P times Phi's column j */
            ROBOT_ARM_LAI_V2_GEMV(ROBOT_ARM_NX, ROBOT_ARM_NX, P, Phi + j * ROBOT_ARM_NX, Y + j * ROBOT_ARM_NX, 1);
        }
        for (j = j0; j + 1 < ROBOT_ARM_NW; j += 2) {
            robot_arm_lai_v2_atb_cols2(ROBOT_ARM_NW, ROBOT_ARM_NX, PhiT, Y, H, Z, j, 0);
        }
        if (j < ROBOT_ARM_NW) {
            Z[j + j * ROBOT_ARM_NW] =
                robot_arm_lai_atb_entry(ROBOT_ARM_NW, ROBOT_ARM_NX, H[j + j * ROBOT_ARM_NW], PhiT + j, Y + j * ROBOT_ARM_NX);
        }
        for (j = j0; j < ROBOT_ARM_NW; ++j) {
            Z[j + j * ROBOT_ARM_NW] += lm;
        }
#else
        /* Y = P Phi (nx x nw), column by column */
        for (j = j0; j < ROBOT_ARM_NW; ++j) {
            robot_arm_real col[ROBOT_ARM_NX];
            for (i = 0; i < ROBOT_ARM_NX; ++i) {
                col[i] = ROBOT_ARM_R(0.0);
            }
            for (l = 0; l < ROBOT_ARM_NX; ++l) {
                const robot_arm_real f = Phi[l + j * ROBOT_ARM_NX];
                for (i = 0; i < ROBOT_ARM_NX; ++i) {
                    col[i] += P[i + l * ROBOT_ARM_NX] * f;
                }
            }
            for (i = 0; i < ROBOT_ARM_NX; ++i) {
                Y[i + j * ROBOT_ARM_NX] = col[i];
            }
        }
        /* Z = H + lm I + Phi' Y, lower triangle */
        for (j = j0; j < ROBOT_ARM_NW; ++j) {
            robot_arm_real y[ROBOT_ARM_NX]; /* Y's column j, held in registers across the column of Z */
            for (l = 0; l < ROBOT_ARM_NX; ++l) {
                y[l] = Y[l + j * ROBOT_ARM_NX];
            }
            for (i = j; i < ROBOT_ARM_NW; ++i) {
                const robot_arm_real *ph = Phi + i * ROBOT_ARM_NX;
                v = H[i + j * ROBOT_ARM_NW];
                for (l = 0; l < ROBOT_ARM_NX; ++l) {
                    v += ph[l] * y[l];
                }
                Z[i + j * ROBOT_ARM_NW] = v;
            }
            Z[j + j * ROBOT_ARM_NW] += lm;
        }
#endif
        /* the pivot floor: tol, or the round-off of a pivot formed from entries of Z_uu's size
         * when that is larger (a linearisation far outside the state's scale: blocks Phi of
         * 1e125 give Z_uu of 1e250, whose pivots after the first are round-off of 1e234 and
         * certify nothing; docs/algorithm.md section 10) */
        floor_ = tol;
        for (j = ROBOT_ARM_NX; j < ROBOT_ARM_NW; ++j) {
            v = ROBOT_ARM_LM_ROUNDOFF * robot_arm_fabs(ROBOT_ARM_LM_Z(j, j));
            floor_ = v > floor_ ? v : floor_;
        }
        /* Cholesky of the control block Z_uu in place (lower triangle) */
        for (j = ROBOT_ARM_NX; j < ROBOT_ARM_NW; ++j) {
            robot_arm_real d = ROBOT_ARM_LM_Z(j, j);
            for (l = ROBOT_ARM_NX; l < j; ++l) {
                d -= ROBOT_ARM_LM_Z(j, l) * ROBOT_ARM_LM_Z(j, l);
            }
            if (!(d > floor_)) {
                return 0;
            }
            d = robot_arm_sqrt(d);
            ROBOT_ARM_LM_Z(j, j) = d;
            for (i = j + 1; i < ROBOT_ARM_NW; ++i) {
                v = ROBOT_ARM_LM_Z(i, j);
                for (l = ROBOT_ARM_NX; l < j; ++l) {
                    v -= ROBOT_ARM_LM_Z(i, l) * ROBOT_ARM_LM_Z(j, l);
                }
                ROBOT_ARM_LM_Z(i, j) = v / d;
            }
        }
        if (k == 0) {
            break; /* x_0 is fixed: P_0 is not needed */
        }
        /* K = L^-1 Z_ux in place, then P = Z_xx - K'K (lower triangle, mirrored) */
        for (j = 0; j < ROBOT_ARM_NX; ++j) {
            for (i = ROBOT_ARM_NX; i < ROBOT_ARM_NW; ++i) {
                v = ROBOT_ARM_LM_Z(i, j);
                for (l = ROBOT_ARM_NX; l < i; ++l) {
                    v -= ROBOT_ARM_LM_Z(i, l) * ROBOT_ARM_LM_Z(l, j);
                }
                ROBOT_ARM_LM_Z(i, j) = v / ROBOT_ARM_LM_Z(i, i);
            }
        }
#if ROBOT_ARM_LM_VEC
        /* K' (nx x nu) in Y's place, then P down the columns two rows at a time (an odd last
         * row by the plain loop below) */
        for (l = ROBOT_ARM_NX; l < ROBOT_ARM_NW; ++l) {
            for (i = 0; i < ROBOT_ARM_NX; ++i) {
                Y[i + (l - ROBOT_ARM_NX) * ROBOT_ARM_NX] = Z[l + i * ROBOT_ARM_NW];
            }
        }
#endif
        for (j = 0; j < ROBOT_ARM_NX; ++j) {
            i = j;
#if ROBOT_ARM_LM_VEC
            for (; i + 2 <= ROBOT_ARM_NX; i += 2) {
                robot_arm_lai_v2 p2 = robot_arm_lai_v2_load(Z + i + j * ROBOT_ARM_NW);
                for (l = ROBOT_ARM_NX; l < ROBOT_ARM_NW; ++l) {
                    p2 -= robot_arm_lai_v2_load(Y + i + (l - ROBOT_ARM_NX) * ROBOT_ARM_NX) *
                          robot_arm_lai_v2_splat(Z[l + j * ROBOT_ARM_NW]);
                }
                robot_arm_lai_v2_store(P + i + j * ROBOT_ARM_NX, p2);
                P[j + i * ROBOT_ARM_NX] = p2[0];
                P[j + (i + 1) * ROBOT_ARM_NX] = p2[1];
            }
#endif
            for (; i < ROBOT_ARM_NX; ++i) {
                v = Z[i + j * ROBOT_ARM_NW];
                for (l = ROBOT_ARM_NX; l < ROBOT_ARM_NW; ++l) {
                    v -= Z[l + i * ROBOT_ARM_NW] * Z[l + j * ROBOT_ARM_NW];
                }
                P[i + j * ROBOT_ARM_NX] = v;
                P[j + i * ROBOT_ARM_NX] = v;
            }
        }
    }
    return 1;
}

/* One raise: from below the minimum to the minimum, else times ROBOT_ARM_LM_RAISE, at most the
 * maximum. */
void robot_arm_lm_raise(robot_arm_lm *st)
{
    robot_arm_real lo = ROBOT_ARM_LM_MIN_REL * st->scale, hi = ROBOT_ARM_LM_MAX_REL * st->scale;
    if (st->uncapped > st->lm) {
        /* the first raise after the cap of robot_arm_lm_measured restores the term it capped */
        st->lm = st->uncapped;
        st->uncapped = -ROBOT_ARM_R(1.0);
        return;
    }
    st->lm = st->lm < lo ? lo : st->lm * ROBOT_ARM_LM_RAISE;
    st->lm = st->lm > hi ? hi : st->lm;
}

int robot_arm_lm_near_convex(const robot_arm_lm *st, const robot_arm_ring *ring, const robot_arm_real *A_N, robot_arm_real *work)
{
    const robot_arm_real lo = ROBOT_ARM_LM_MIN_REL * st->scale, hi = ROBOT_ARM_LM_MAX_REL * st->scale;
    robot_arm_real up;
    if (!st->on || !(st->lm < hi)) {
        return 0;
    }
    if (st->uncapped < ROBOT_ARM_R(0.0)) {
        return 1; /* the prepared term, which the prepare's test passed (below the maximum) */
    }
    up = st->lm < lo ? lo : st->lm * ROBOT_ARM_LM_RAISE; /* robot_arm_lm_raise's step */
    up = up > hi ? hi : up;
    if (up >= st->uncapped && st->uncapped < hi) {
        return 1; /* at least the prepared term (monotone test) */
    }
    return robot_arm_lm_convex(st, ring, A_N, up, work);
}

int robot_arm_lm_can_raise(const robot_arm_lm *st)
{
    return st->on && st->lm < ROBOT_ARM_LM_MAX_REL * st->scale;
}

/* Raise until the QP is convex on the dynamics or the term is at its maximum. */
static void robot_arm_lm_convexify(robot_arm_lm *st, const robot_arm_ring *ring, const robot_arm_real *A_N, robot_arm_real *work)
{
    robot_arm_real hi = ROBOT_ARM_LM_MAX_REL * st->scale;
    while (!robot_arm_lm_convex(st, ring, A_N, st->lm, work) && st->lm < hi) {
        robot_arm_lm_raise(st);
    }
}

void robot_arm_lm_start(robot_arm_lm *st, const robot_arm_ring *ring, const robot_arm_real *A_N, robot_arm_real *work)
{
    if (!st->on) {
        return;
    }
    st->scale = robot_arm_lm_hessian_scale(ring, A_N);
    st->lm = ROBOT_ARM_R(0.0);
    st->kkt_prev = -ROBOT_ARM_R(1.0);
    st->uncapped = -ROBOT_ARM_R(1.0);
    st->held = 0;
    robot_arm_lm_convexify(st, ring, A_N, work);
}

void robot_arm_lm_prepared(robot_arm_lm *st, const robot_arm_ring *ring, const robot_arm_real *A_N, robot_arm_real kkt_proxy,
                       robot_arm_real proxy_ref, robot_arm_real *work)
{
    robot_arm_real floor_ = ROBOT_ARM_PREC(1e-8, 1e-5) * (proxy_ref > ROBOT_ARM_R(1.0) ? proxy_ref : ROBOT_ARM_R(1.0));
    robot_arm_real prev = st->kkt_prev > floor_ ? st->kkt_prev : floor_;
    robot_arm_real before;
    st->held = 0;
    if (!st->on) {
        return;
    }
    st->scale = robot_arm_lm_hessian_scale(ring, A_N);
    st->uncapped = -ROBOT_ARM_R(1.0);
    if (st->kkt_prev >= ROBOT_ARM_R(0.0) && !(kkt_proxy <= ROBOT_ARM_LM_KKT_GROWTH * prev)) {
        robot_arm_lm_raise(st);
    }
    st->kkt_prev = kkt_proxy;
    before = st->lm;
    robot_arm_lm_convexify(st, ring, A_N, work);
    st->held = st->lm > before;
}

void robot_arm_lm_measured(robot_arm_lm *st, const robot_arm_real *dx0, const robot_arm_real *scale_x, robot_arm_real kkt_proxy)
{
    robot_arm_real d = kkt_proxy, cap, v;
    int i;
    st->uncapped = -ROBOT_ARM_R(1.0);
    if (!st->on) {
        return;
    }
    for (i = 0; i < ROBOT_ARM_NX; ++i) {
        v = robot_arm_fabs(dx0[i]) / scale_x[i];
        d = v > d ? v : d;
    }
    cap = ROBOT_ARM_LM_KKT_REL * st->scale * d * d;
    if (!(st->lm <= cap)) {
        st->uncapped = st->lm;
        st->lm = cap < ROBOT_ARM_LM_MIN_REL * st->scale ? ROBOT_ARM_R(0.0) : cap;
    }
}

void robot_arm_lm_feedback(robot_arm_lm *st, int solved)
{
    if (!st->on) {
        return;
    }
    if (solved) {
        st->lm *= ROBOT_ARM_LM_LOWER;
        if (st->lm < ROBOT_ARM_LM_MIN_REL * st->scale) {
            st->lm = ROBOT_ARM_R(0.0);
        }
    } else {
        robot_arm_lm_raise(st);
    }
}
