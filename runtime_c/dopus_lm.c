/* The automatic Levenberg-Marquardt term (dopus_lm.h, docs/algorithm.md section 10). */
#include "dopus_lm.h"

#include "dopus_linalg.h"

#include <math.h>

void dopus_lm_reset(dopus_lm *lm, int on, dopus_real fixed)
{
    lm->on = on;
    lm->lm = on ? DOPUS_R(0.0) : fixed;
    lm->kkt_prev = -DOPUS_R(1.0);
    lm->uncapped = -DOPUS_R(1.0);
    lm->held = 0;
    lm->test = 0;
    lm->test_ctx = 0;
}

/* The Hessian scale h: the largest |diagonal entry| of the QP's stage and terminal blocks. */
static dopus_real dopus_lm_hessian_scale(const dopus_ring *ring, const dopus_real *A_N)
{
    dopus_real h = DOPUS_REAL_TINY, v;
    int k, i;
    for (k = 0; k < DOPUS_N; ++k) {
        const dopus_stage_slot *slot = dopus_ring_stage_const(ring, k);
        for (i = 0; i < DOPUS_NW; ++i) {
            v = dopus_fabs(slot->Ht[i + i * DOPUS_NW]);
            h = v > h ? v : h;
        }
    }
    for (i = 0; i < DOPUS_NX; ++i) {
        v = dopus_fabs(A_N[i + i * DOPUS_NX]);
        h = v > h ? v : h;
    }
    return h;
}

/* The two-wide kernels (DOPUS_LAI_VEC) pay from about nx = 8 on: 30 % less time for the
 * test at nx = 21 on x86-64, but 5 % more instructions at nx = 5 (short rows); smaller
 * states and targets without vectors take the plain loops. The same values either way. */
#define DOPUS_LM_VEC (DOPUS_LAI_VEC && DOPUS_NX >= 8)

/* Y = P Phi (nx x nw) and the lower triangle of Z (nw x nw) column-major */
#define DOPUS_LM_Z(i, j) Z[(i) + (j)*DOPUS_NW]

/* 1 when the QP with the term lm is strictly convex on the dynamics: the Riccati recursion
 * of its Hessian blocks (lower triangles read; inequalities and terminal constraints left
 * out) has control pivots above DOPUS_LM_PIVOT_REL h and above their round-off,
 * DOPUS_LM_ROUNDOFF times the stage's largest |Z_uu diagonal entry|.
 *
 * Per stage, Y = P Phi runs down whole columns of P (Phi read in its stored layout: no
 * transposed copy), then only the lower triangle of Z = H + lm I + Phi' Y: about half the
 * multiply-adds of the full Z, and on an in-order core without vector units (the Cortex-M)
 * the cost is the multiply-adds and their loads; there each entry of Z is a dot product of
 * two contiguous columns of length nx (Phi's column i and Y's column j). The Riccati update
 * writes P's lower triangle and mirrors it. With two-wide vectors (DOPUS_LM_VEC) Y's columns
 * (DOPUS_LAI_V2_GEMV), Z's pairs of columns over a copy of Phi' (dopus_lai_v2_atb_cols2, the
 * QP's kernel for its stage update; the rows of a pair from its diagonal) and the
 * update over a copy of K' run two entries at a time with their accumulators in registers,
 * every entry with the same operations in the same order. */
static int dopus_lm_convex(const dopus_lm *st, const dopus_ring *ring, const dopus_real *A_N, dopus_real lm,
                           dopus_real *work)
{
    const dopus_real tol = DOPUS_LM_PIVOT_REL * st->scale;
    dopus_real *P, *Y, *Z;
#if DOPUS_LM_VEC
    dopus_real PhiT[DOPUS_NW * DOPUS_NX]; /* Phi_k' */
#endif
    dopus_real v, floor_;
    int k, i, j, l;
    if (st->test) {
        return st->test(st->test_ctx, lm, tol); /* the same test as the QP's factorisation */
    }
    P = work;
    Y = work + DOPUS_NX * DOPUS_NX;
    Z = Y + DOPUS_NX * DOPUS_NW;
    for (j = 0; j < DOPUS_NX; ++j) {
        for (i = j; i < DOPUS_NX; ++i) {
            P[i + j * DOPUS_NX] = A_N[i + j * DOPUS_NX];
            P[j + i * DOPUS_NX] = A_N[i + j * DOPUS_NX];
        }
        P[j + j * DOPUS_NX] += lm;
    }
    for (k = DOPUS_N - 1; k >= 0; --k) {
        const dopus_stage_slot *slot = dopus_ring_stage_const(ring, k);
        const dopus_real *H = slot->Ht, *Phi = slot->Phit;
        /* stage 0 needs only the control block Z_uu (x_0 is fixed): Y's and Z's control
         * columns, the same values as in the full block */
        const int j0 = k == 0 ? DOPUS_NX : 0;
#if DOPUS_LM_VEC
        /* Phi' (nw x nx, its rows from j0), then Y = P Phi and Z = H + lm I + Phi' Y two
         * columns at a time */
        for (l = 0; l < DOPUS_NX; ++l) {
            for (i = j0; i < DOPUS_NW; ++i) {
                PhiT[i + l * DOPUS_NW] = Phi[l + i * DOPUS_NX];
            }
        }
        for (j = j0; j < DOPUS_NW; ++j) {
            /* column j of Y: P times Phi's column j */
            DOPUS_LAI_V2_GEMV(DOPUS_NX, DOPUS_NX, P, Phi + j * DOPUS_NX, Y + j * DOPUS_NX, 1);
        }
        for (j = j0; j + 1 < DOPUS_NW; j += 2) {
            dopus_lai_v2_atb_cols2(DOPUS_NW, DOPUS_NX, PhiT, Y, H, Z, j, 0);
        }
        if (j < DOPUS_NW) {
            Z[j + j * DOPUS_NW] =
                dopus_lai_atb_entry(DOPUS_NW, DOPUS_NX, H[j + j * DOPUS_NW], PhiT + j, Y + j * DOPUS_NX);
        }
        for (j = j0; j < DOPUS_NW; ++j) {
            Z[j + j * DOPUS_NW] += lm;
        }
#else
        /* Y = P Phi (nx x nw), column by column */
        for (j = j0; j < DOPUS_NW; ++j) {
            dopus_real col[DOPUS_NX];
            for (i = 0; i < DOPUS_NX; ++i) {
                col[i] = DOPUS_R(0.0);
            }
            for (l = 0; l < DOPUS_NX; ++l) {
                const dopus_real f = Phi[l + j * DOPUS_NX];
                for (i = 0; i < DOPUS_NX; ++i) {
                    col[i] += P[i + l * DOPUS_NX] * f;
                }
            }
            for (i = 0; i < DOPUS_NX; ++i) {
                Y[i + j * DOPUS_NX] = col[i];
            }
        }
        /* Z = H + lm I + Phi' Y, lower triangle */
        for (j = j0; j < DOPUS_NW; ++j) {
            dopus_real y[DOPUS_NX]; /* Y's column j, held in registers across the column of Z */
            for (l = 0; l < DOPUS_NX; ++l) {
                y[l] = Y[l + j * DOPUS_NX];
            }
            for (i = j; i < DOPUS_NW; ++i) {
                const dopus_real *ph = Phi + i * DOPUS_NX;
                v = H[i + j * DOPUS_NW];
                for (l = 0; l < DOPUS_NX; ++l) {
                    v += ph[l] * y[l];
                }
                Z[i + j * DOPUS_NW] = v;
            }
            Z[j + j * DOPUS_NW] += lm;
        }
#endif
        /* the pivot floor: tol, or the round-off of a pivot formed from entries of Z_uu's size
         * when that is larger (a linearisation far outside the state's scale: blocks Phi of
         * 1e125 give Z_uu of 1e250, whose pivots after the first are round-off of 1e234 and
         * certify nothing; docs/algorithm.md section 10) */
        floor_ = tol;
        for (j = DOPUS_NX; j < DOPUS_NW; ++j) {
            v = DOPUS_LM_ROUNDOFF * dopus_fabs(DOPUS_LM_Z(j, j));
            floor_ = v > floor_ ? v : floor_;
        }
        /* Cholesky of the control block Z_uu in place (lower triangle) */
        for (j = DOPUS_NX; j < DOPUS_NW; ++j) {
            dopus_real d = DOPUS_LM_Z(j, j);
            for (l = DOPUS_NX; l < j; ++l) {
                d -= DOPUS_LM_Z(j, l) * DOPUS_LM_Z(j, l);
            }
            if (!(d > floor_)) {
                return 0;
            }
            d = dopus_sqrt(d);
            DOPUS_LM_Z(j, j) = d;
            for (i = j + 1; i < DOPUS_NW; ++i) {
                v = DOPUS_LM_Z(i, j);
                for (l = DOPUS_NX; l < j; ++l) {
                    v -= DOPUS_LM_Z(i, l) * DOPUS_LM_Z(j, l);
                }
                DOPUS_LM_Z(i, j) = v / d;
            }
        }
        if (k == 0) {
            break; /* x_0 is fixed: P_0 is not needed */
        }
        /* K = L^-1 Z_ux in place, then P = Z_xx - K'K (lower triangle, mirrored) */
        for (j = 0; j < DOPUS_NX; ++j) {
            for (i = DOPUS_NX; i < DOPUS_NW; ++i) {
                v = DOPUS_LM_Z(i, j);
                for (l = DOPUS_NX; l < i; ++l) {
                    v -= DOPUS_LM_Z(i, l) * DOPUS_LM_Z(l, j);
                }
                DOPUS_LM_Z(i, j) = v / DOPUS_LM_Z(i, i);
            }
        }
#if DOPUS_LM_VEC
        /* K' (nx x nu) in Y's place, then P down the columns two rows at a time (an odd last
         * row by the plain loop below) */
        for (l = DOPUS_NX; l < DOPUS_NW; ++l) {
            for (i = 0; i < DOPUS_NX; ++i) {
                Y[i + (l - DOPUS_NX) * DOPUS_NX] = Z[l + i * DOPUS_NW];
            }
        }
#endif
        for (j = 0; j < DOPUS_NX; ++j) {
            i = j;
#if DOPUS_LM_VEC
            for (; i + 2 <= DOPUS_NX; i += 2) {
                dopus_lai_v2 p2 = dopus_lai_v2_load(Z + i + j * DOPUS_NW);
                for (l = DOPUS_NX; l < DOPUS_NW; ++l) {
                    p2 -= dopus_lai_v2_load(Y + i + (l - DOPUS_NX) * DOPUS_NX) *
                          dopus_lai_v2_splat(Z[l + j * DOPUS_NW]);
                }
                dopus_lai_v2_store(P + i + j * DOPUS_NX, p2);
                P[j + i * DOPUS_NX] = p2[0];
                P[j + (i + 1) * DOPUS_NX] = p2[1];
            }
#endif
            for (; i < DOPUS_NX; ++i) {
                v = Z[i + j * DOPUS_NW];
                for (l = DOPUS_NX; l < DOPUS_NW; ++l) {
                    v -= Z[l + i * DOPUS_NW] * Z[l + j * DOPUS_NW];
                }
                P[i + j * DOPUS_NX] = v;
                P[j + i * DOPUS_NX] = v;
            }
        }
    }
    return 1;
}

/* One raise: from below the minimum to the minimum, else times DOPUS_LM_RAISE, at most the
 * maximum. */
void dopus_lm_raise(dopus_lm *st)
{
    dopus_real lo = DOPUS_LM_MIN_REL * st->scale, hi = DOPUS_LM_MAX_REL * st->scale;
    if (st->uncapped > st->lm) {
        /* the first raise after the cap of dopus_lm_measured restores the term it capped */
        st->lm = st->uncapped;
        st->uncapped = -DOPUS_R(1.0);
        return;
    }
    st->lm = st->lm < lo ? lo : st->lm * DOPUS_LM_RAISE;
    st->lm = st->lm > hi ? hi : st->lm;
}

int dopus_lm_near_convex(const dopus_lm *st, const dopus_ring *ring, const dopus_real *A_N, dopus_real *work)
{
    const dopus_real lo = DOPUS_LM_MIN_REL * st->scale, hi = DOPUS_LM_MAX_REL * st->scale;
    dopus_real up;
    if (!st->on || !(st->lm < hi)) {
        return 0;
    }
    if (st->uncapped < DOPUS_R(0.0)) {
        return 1; /* the prepared term, which the prepare's test passed (below the maximum) */
    }
    up = st->lm < lo ? lo : st->lm * DOPUS_LM_RAISE; /* dopus_lm_raise's step */
    up = up > hi ? hi : up;
    if (up >= st->uncapped && st->uncapped < hi) {
        return 1; /* at least the prepared term (monotone test) */
    }
    return dopus_lm_convex(st, ring, A_N, up, work);
}

int dopus_lm_can_raise(const dopus_lm *st)
{
    return st->on && st->lm < DOPUS_LM_MAX_REL * st->scale;
}

/* Raise until the QP is convex on the dynamics or the term is at its maximum. */
static void dopus_lm_convexify(dopus_lm *st, const dopus_ring *ring, const dopus_real *A_N, dopus_real *work)
{
    dopus_real hi = DOPUS_LM_MAX_REL * st->scale;
    while (!dopus_lm_convex(st, ring, A_N, st->lm, work) && st->lm < hi) {
        dopus_lm_raise(st);
    }
}

void dopus_lm_start(dopus_lm *st, const dopus_ring *ring, const dopus_real *A_N, dopus_real *work)
{
    if (!st->on) {
        return;
    }
    st->scale = dopus_lm_hessian_scale(ring, A_N);
    st->lm = DOPUS_R(0.0);
    st->kkt_prev = -DOPUS_R(1.0);
    st->uncapped = -DOPUS_R(1.0);
    st->held = 0;
    dopus_lm_convexify(st, ring, A_N, work);
}

void dopus_lm_prepared(dopus_lm *st, const dopus_ring *ring, const dopus_real *A_N, dopus_real kkt_proxy,
                       dopus_real proxy_ref, dopus_real *work)
{
    dopus_real floor_ = DOPUS_PREC(1e-8, 1e-5) * (proxy_ref > DOPUS_R(1.0) ? proxy_ref : DOPUS_R(1.0));
    dopus_real prev = st->kkt_prev > floor_ ? st->kkt_prev : floor_;
    dopus_real before;
    st->held = 0;
    if (!st->on) {
        return;
    }
    st->scale = dopus_lm_hessian_scale(ring, A_N);
    st->uncapped = -DOPUS_R(1.0);
    if (st->kkt_prev >= DOPUS_R(0.0) && !(kkt_proxy <= DOPUS_LM_KKT_GROWTH * prev)) {
        dopus_lm_raise(st);
    }
    st->kkt_prev = kkt_proxy;
    before = st->lm;
    dopus_lm_convexify(st, ring, A_N, work);
    st->held = st->lm > before;
}

void dopus_lm_measured(dopus_lm *st, const dopus_real *dx0, const dopus_real *scale_x, dopus_real kkt_proxy)
{
    dopus_real d = kkt_proxy, cap, v;
    int i;
    st->uncapped = -DOPUS_R(1.0);
    if (!st->on) {
        return;
    }
    for (i = 0; i < DOPUS_NX; ++i) {
        v = dopus_fabs(dx0[i]) / scale_x[i];
        d = v > d ? v : d;
    }
    cap = DOPUS_LM_KKT_REL * st->scale * d * d;
    if (!(st->lm <= cap)) {
        st->uncapped = st->lm;
        st->lm = cap < DOPUS_LM_MIN_REL * st->scale ? DOPUS_R(0.0) : cap;
    }
}

void dopus_lm_feedback(dopus_lm *st, int solved)
{
    if (!st->on) {
        return;
    }
    if (solved) {
        st->lm *= DOPUS_LM_LOWER;
        if (st->lm < DOPUS_LM_MIN_REL * st->scale) {
            st->lm = DOPUS_R(0.0);
        }
    } else {
        dopus_lm_raise(st);
    }
}
