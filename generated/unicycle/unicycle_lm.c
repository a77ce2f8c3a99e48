/* The automatic Levenberg-Marquardt term (unicycle_lm.h, docs/algorithm.md section 10). */
#include "unicycle_lm.h"

#include "unicycle_linalg.h"

#include <math.h>

void unicycle_lm_reset(unicycle_lm *lm, int on, unicycle_real fixed)
{
    lm->on = on;
    lm->lm = on ? UNICYCLE_R(0.0) : fixed;
    lm->kkt_prev = -UNICYCLE_R(1.0);
    lm->uncapped = -UNICYCLE_R(1.0);
    lm->held = 0;
    lm->test = 0;
    lm->test_ctx = 0;
}

/* The Hessian scale h: the largest |diagonal entry| of the QP's stage and terminal blocks. */
static unicycle_real unicycle_lm_hessian_scale(const unicycle_ring *ring, const unicycle_real *A_N)
{
    unicycle_real h = UNICYCLE_REAL_TINY, v;
    int k, i;
    for (k = 0; k < UNICYCLE_N; ++k) {
        const unicycle_stage_slot *slot = unicycle_ring_stage_const(ring, k);
        for (i = 0; i < UNICYCLE_NW; ++i) {
            v = unicycle_fabs(slot->Ht[i + i * UNICYCLE_NW]);
            h = v > h ? v : h;
        }
    }
    for (i = 0; i < UNICYCLE_NX; ++i) {
        v = unicycle_fabs(A_N[i + i * UNICYCLE_NX]);
        h = v > h ? v : h;
    }
    return h;
}

/* The two-wide kernels (UNICYCLE_LAI_VEC) pay from about nx = 8 on: 30 % less time for the
 * test at nx = 21 on x86-64, but 5 % more instructions at nx = 5 (short rows); smaller
 * states and targets without vectors take the plain loops. The same values either way. */
#define UNICYCLE_LM_VEC (UNICYCLE_LAI_VEC && UNICYCLE_NX >= 8)

/* Y = P Phi (nx x nw) and the lower triangle of Z (nw x nw) column-major */
#define UNICYCLE_LM_Z(i, j) Z[(i) + (j)*UNICYCLE_NW]

/* 1 when the QP with the term lm is strictly convex on the dynamics: the Riccati recursion
 * of its Hessian blocks (lower triangles read; inequalities and terminal constraints left
 * out) has control pivots above UNICYCLE_LM_PIVOT_REL h and above their round-off,
 * UNICYCLE_LM_ROUNDOFF times the stage's largest |Z_uu diagonal entry|.
 *
 * Per stage, Y = P Phi runs down whole columns of P (Phi read in its stored layout: no
 * transposed copy), then only the lower triangle of Z = H + lm I + Phi' Y: about half the
 * multiply-adds of the full Z, and on an in-order core without vector units (the Cortex-M)
 * the cost is the multiply-adds and their loads; there each entry of Z is a dot product of
 * two contiguous columns of length nx (Phi's column i and Y's column j). The Riccati update
 * writes P's lower triangle and mirrors it. With two-wide vectors (UNICYCLE_LM_VEC) Y's columns
 * (UNICYCLE_LAI_V2_GEMV), Z's pairs of columns over a copy of Phi' (unicycle_lai_v2_atb_cols2, the
 * QP's kernel for its stage update; the rows of a pair from its diagonal) and the
 * update over a copy of K' run two entries at a time with their accumulators in registers,
 * every entry with the same operations in the same order. */
static int unicycle_lm_convex(const unicycle_lm *st, const unicycle_ring *ring, const unicycle_real *A_N, unicycle_real lm,
                           unicycle_real *work)
{
    const unicycle_real tol = UNICYCLE_LM_PIVOT_REL * st->scale;
    unicycle_real *P, *Y, *Z;
#if UNICYCLE_LM_VEC
    unicycle_real PhiT[UNICYCLE_NW * UNICYCLE_NX]; /* Phi_k' */
#endif
    unicycle_real v, floor_;
    int k, i, j, l;
    if (st->test) {
        return st->test(st->test_ctx, lm, tol); /* the same test as the QP's factorisation */
    }
    P = work;
    Y = work + UNICYCLE_NX * UNICYCLE_NX;
    Z = Y + UNICYCLE_NX * UNICYCLE_NW;
    for (j = 0; j < UNICYCLE_NX; ++j) {
        for (i = j; i < UNICYCLE_NX; ++i) {
            P[i + j * UNICYCLE_NX] = A_N[i + j * UNICYCLE_NX];
            P[j + i * UNICYCLE_NX] = A_N[i + j * UNICYCLE_NX];
        }
        P[j + j * UNICYCLE_NX] += lm;
    }
    for (k = UNICYCLE_N - 1; k >= 0; --k) {
        const unicycle_stage_slot *slot = unicycle_ring_stage_const(ring, k);
        const unicycle_real *H = slot->Ht, *Phi = slot->Phit;
        /* stage 0 needs only the control block Z_uu (x_0 is fixed): Y's and Z's control
         * columns, the same values as in the full block */
        const int j0 = k == 0 ? UNICYCLE_NX : 0;
#if UNICYCLE_LM_VEC
        /* Phi' (nw x nx, its rows from j0), then Y = P Phi and Z = H + lm I + Phi' Y two
         * columns at a time */
        for (l = 0; l < UNICYCLE_NX; ++l) {
            for (i = j0; i < UNICYCLE_NW; ++i) {
                PhiT[i + l * UNICYCLE_NW] = Phi[l + i * UNICYCLE_NX];
            }
        }
        for (j = j0; j < UNICYCLE_NW; ++j) {
            /* column j of Y: P times Phi's column j */
            UNICYCLE_LAI_V2_GEMV(UNICYCLE_NX, UNICYCLE_NX, P, Phi + j * UNICYCLE_NX, Y + j * UNICYCLE_NX, 1);
        }
        for (j = j0; j + 1 < UNICYCLE_NW; j += 2) {
            unicycle_lai_v2_atb_cols2(UNICYCLE_NW, UNICYCLE_NX, PhiT, Y, H, Z, j, 0);
        }
        if (j < UNICYCLE_NW) {
            Z[j + j * UNICYCLE_NW] =
                unicycle_lai_atb_entry(UNICYCLE_NW, UNICYCLE_NX, H[j + j * UNICYCLE_NW], PhiT + j, Y + j * UNICYCLE_NX);
        }
        for (j = j0; j < UNICYCLE_NW; ++j) {
            Z[j + j * UNICYCLE_NW] += lm;
        }
#else
        /* Y = P Phi (nx x nw), column by column */
        for (j = j0; j < UNICYCLE_NW; ++j) {
            unicycle_real col[UNICYCLE_NX];
            for (i = 0; i < UNICYCLE_NX; ++i) {
                col[i] = UNICYCLE_R(0.0);
            }
            for (l = 0; l < UNICYCLE_NX; ++l) {
                const unicycle_real f = Phi[l + j * UNICYCLE_NX];
                for (i = 0; i < UNICYCLE_NX; ++i) {
                    col[i] += P[i + l * UNICYCLE_NX] * f;
                }
            }
            for (i = 0; i < UNICYCLE_NX; ++i) {
                Y[i + j * UNICYCLE_NX] = col[i];
            }
        }
        /* Z = H + lm I + Phi' Y, lower triangle */
        for (j = j0; j < UNICYCLE_NW; ++j) {
            unicycle_real y[UNICYCLE_NX]; /* Y's column j, held in registers across the column of Z */
            for (l = 0; l < UNICYCLE_NX; ++l) {
                y[l] = Y[l + j * UNICYCLE_NX];
            }
            for (i = j; i < UNICYCLE_NW; ++i) {
                const unicycle_real *ph = Phi + i * UNICYCLE_NX;
                v = H[i + j * UNICYCLE_NW];
                for (l = 0; l < UNICYCLE_NX; ++l) {
                    v += ph[l] * y[l];
                }
                Z[i + j * UNICYCLE_NW] = v;
            }
            Z[j + j * UNICYCLE_NW] += lm;
        }
#endif
        /* the pivot floor: tol, or the round-off of a pivot formed from entries of Z_uu's size
         * when that is larger (a linearisation far outside the state's scale: blocks Phi of
         * 1e125 give Z_uu of 1e250, whose pivots after the first are round-off of 1e234 and
         * certify nothing; docs/algorithm.md section 10) */
        floor_ = tol;
        for (j = UNICYCLE_NX; j < UNICYCLE_NW; ++j) {
            v = UNICYCLE_LM_ROUNDOFF * unicycle_fabs(UNICYCLE_LM_Z(j, j));
            floor_ = v > floor_ ? v : floor_;
        }
        /* Cholesky of the control block Z_uu in place (lower triangle) */
        for (j = UNICYCLE_NX; j < UNICYCLE_NW; ++j) {
            unicycle_real d = UNICYCLE_LM_Z(j, j);
            for (l = UNICYCLE_NX; l < j; ++l) {
                d -= UNICYCLE_LM_Z(j, l) * UNICYCLE_LM_Z(j, l);
            }
            if (!(d > floor_)) {
                return 0;
            }
            d = unicycle_sqrt(d);
            UNICYCLE_LM_Z(j, j) = d;
            for (i = j + 1; i < UNICYCLE_NW; ++i) {
                v = UNICYCLE_LM_Z(i, j);
                for (l = UNICYCLE_NX; l < j; ++l) {
                    v -= UNICYCLE_LM_Z(i, l) * UNICYCLE_LM_Z(j, l);
                }
                UNICYCLE_LM_Z(i, j) = v / d;
            }
        }
        if (k == 0) {
            break; /* x_0 is fixed: P_0 is not needed */
        }
        /* K = L^-1 Z_ux in place, then P = Z_xx - K'K (lower triangle, mirrored) */
        for (j = 0; j < UNICYCLE_NX; ++j) {
            for (i = UNICYCLE_NX; i < UNICYCLE_NW; ++i) {
                v = UNICYCLE_LM_Z(i, j);
                for (l = UNICYCLE_NX; l < i; ++l) {
                    v -= UNICYCLE_LM_Z(i, l) * UNICYCLE_LM_Z(l, j);
                }
                UNICYCLE_LM_Z(i, j) = v / UNICYCLE_LM_Z(i, i);
            }
        }
#if UNICYCLE_LM_VEC
        /* K' (nx x nu) in Y's place, then P down the columns two rows at a time (an odd last
         * row by the plain loop below) */
        for (l = UNICYCLE_NX; l < UNICYCLE_NW; ++l) {
            for (i = 0; i < UNICYCLE_NX; ++i) {
                Y[i + (l - UNICYCLE_NX) * UNICYCLE_NX] = Z[l + i * UNICYCLE_NW];
            }
        }
#endif
        for (j = 0; j < UNICYCLE_NX; ++j) {
            i = j;
#if UNICYCLE_LM_VEC
            for (; i + 2 <= UNICYCLE_NX; i += 2) {
                unicycle_lai_v2 p2 = unicycle_lai_v2_load(Z + i + j * UNICYCLE_NW);
                for (l = UNICYCLE_NX; l < UNICYCLE_NW; ++l) {
                    p2 -= unicycle_lai_v2_load(Y + i + (l - UNICYCLE_NX) * UNICYCLE_NX) *
                          unicycle_lai_v2_splat(Z[l + j * UNICYCLE_NW]);
                }
                unicycle_lai_v2_store(P + i + j * UNICYCLE_NX, p2);
                P[j + i * UNICYCLE_NX] = p2[0];
                P[j + (i + 1) * UNICYCLE_NX] = p2[1];
            }
#endif
            for (; i < UNICYCLE_NX; ++i) {
                v = Z[i + j * UNICYCLE_NW];
                for (l = UNICYCLE_NX; l < UNICYCLE_NW; ++l) {
                    v -= Z[l + i * UNICYCLE_NW] * Z[l + j * UNICYCLE_NW];
                }
                P[i + j * UNICYCLE_NX] = v;
                P[j + i * UNICYCLE_NX] = v;
            }
        }
    }
    return 1;
}

/* One raise: from below the minimum to the minimum, else times UNICYCLE_LM_RAISE, at most the
 * maximum. */
void unicycle_lm_raise(unicycle_lm *st)
{
    unicycle_real lo = UNICYCLE_LM_MIN_REL * st->scale, hi = UNICYCLE_LM_MAX_REL * st->scale;
    if (st->uncapped > st->lm) {
        /* the first raise after the cap of unicycle_lm_measured restores the term it capped */
        st->lm = st->uncapped;
        st->uncapped = -UNICYCLE_R(1.0);
        return;
    }
    st->lm = st->lm < lo ? lo : st->lm * UNICYCLE_LM_RAISE;
    st->lm = st->lm > hi ? hi : st->lm;
}

int unicycle_lm_near_convex(const unicycle_lm *st, const unicycle_ring *ring, const unicycle_real *A_N, unicycle_real *work)
{
    const unicycle_real lo = UNICYCLE_LM_MIN_REL * st->scale, hi = UNICYCLE_LM_MAX_REL * st->scale;
    unicycle_real up;
    if (!st->on || !(st->lm < hi)) {
        return 0;
    }
    if (st->uncapped < UNICYCLE_R(0.0)) {
        return 1; /* the prepared term, which the prepare's test passed (below the maximum) */
    }
    up = st->lm < lo ? lo : st->lm * UNICYCLE_LM_RAISE; /* unicycle_lm_raise's step */
    up = up > hi ? hi : up;
    if (up >= st->uncapped && st->uncapped < hi) {
        return 1; /* at least the prepared term (monotone test) */
    }
    return unicycle_lm_convex(st, ring, A_N, up, work);
}

int unicycle_lm_can_raise(const unicycle_lm *st)
{
    return st->on && st->lm < UNICYCLE_LM_MAX_REL * st->scale;
}

/* Raise until the QP is convex on the dynamics or the term is at its maximum. */
static void unicycle_lm_convexify(unicycle_lm *st, const unicycle_ring *ring, const unicycle_real *A_N, unicycle_real *work)
{
    unicycle_real hi = UNICYCLE_LM_MAX_REL * st->scale;
    while (!unicycle_lm_convex(st, ring, A_N, st->lm, work) && st->lm < hi) {
        unicycle_lm_raise(st);
    }
}

void unicycle_lm_start(unicycle_lm *st, const unicycle_ring *ring, const unicycle_real *A_N, unicycle_real *work)
{
    if (!st->on) {
        return;
    }
    st->scale = unicycle_lm_hessian_scale(ring, A_N);
    st->lm = UNICYCLE_R(0.0);
    st->kkt_prev = -UNICYCLE_R(1.0);
    st->uncapped = -UNICYCLE_R(1.0);
    st->held = 0;
    unicycle_lm_convexify(st, ring, A_N, work);
}

void unicycle_lm_prepared(unicycle_lm *st, const unicycle_ring *ring, const unicycle_real *A_N, unicycle_real kkt_proxy,
                       unicycle_real proxy_ref, unicycle_real *work)
{
    unicycle_real floor_ = UNICYCLE_PREC(1e-8, 1e-5) * (proxy_ref > UNICYCLE_R(1.0) ? proxy_ref : UNICYCLE_R(1.0));
    unicycle_real prev = st->kkt_prev > floor_ ? st->kkt_prev : floor_;
    unicycle_real before;
    st->held = 0;
    if (!st->on) {
        return;
    }
    st->scale = unicycle_lm_hessian_scale(ring, A_N);
    st->uncapped = -UNICYCLE_R(1.0);
    if (st->kkt_prev >= UNICYCLE_R(0.0) && !(kkt_proxy <= UNICYCLE_LM_KKT_GROWTH * prev)) {
        unicycle_lm_raise(st);
    }
    st->kkt_prev = kkt_proxy;
    before = st->lm;
    unicycle_lm_convexify(st, ring, A_N, work);
    st->held = st->lm > before;
}

void unicycle_lm_measured(unicycle_lm *st, const unicycle_real *dx0, const unicycle_real *scale_x, unicycle_real kkt_proxy)
{
    unicycle_real d = kkt_proxy, cap, v;
    int i;
    st->uncapped = -UNICYCLE_R(1.0);
    if (!st->on) {
        return;
    }
    for (i = 0; i < UNICYCLE_NX; ++i) {
        v = unicycle_fabs(dx0[i]) / scale_x[i];
        d = v > d ? v : d;
    }
    cap = UNICYCLE_LM_KKT_REL * st->scale * d * d;
    if (!(st->lm <= cap)) {
        st->uncapped = st->lm;
        st->lm = cap < UNICYCLE_LM_MIN_REL * st->scale ? UNICYCLE_R(0.0) : cap;
    }
}

void unicycle_lm_feedback(unicycle_lm *st, int solved)
{
    if (!st->on) {
        return;
    }
    if (solved) {
        st->lm *= UNICYCLE_LM_LOWER;
        if (st->lm < UNICYCLE_LM_MIN_REL * st->scale) {
            st->lm = UNICYCLE_R(0.0);
        }
    } else {
        unicycle_lm_raise(st);
    }
}
