/* The automatic Levenberg-Marquardt term (unicycle_lm.h, docs/algorithm.md section 10). */
#include "unicycle_lm.h"

#include <math.h>

void unicycle_lm_reset(unicycle_lm *lm, int on, unicycle_real fixed)
{
    lm->on = on;
    lm->lm = on ? UNICYCLE_R(0.0) : fixed;
    lm->kkt_prev = -UNICYCLE_R(1.0);
    lm->uncapped = -UNICYCLE_R(1.0);
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

/* 1 when the QP with the term lm is strictly convex on the dynamics: the Riccati recursion
 * of its Hessian blocks (lower triangles read; inequalities and terminal constraints left
 * out) has control pivots above UNICYCLE_LM_PIVOT_REL h.
 *
 * Per stage, Y = P Phi runs down whole columns of P (vectorised, no reductions, Phi read in
 * its stored layout: no transposed copy), then only the lower triangle of
 * Z = H + lm I + Phi' Y, each entry a dot product of two contiguous columns of length nx
 * (Phi's column r and Y's column j): about half the multiply-adds of the full Z, and on an
 * in-order core without vector units (the Cortex-M) the cost is the multiply-adds and their
 * loads. The Riccati update writes P's lower triangle and mirrors it. */
static int unicycle_lm_convex(const unicycle_lm *st, const unicycle_ring *ring, const unicycle_real *A_N, unicycle_real lm,
                           unicycle_real *work)
{
    const unicycle_real tol = UNICYCLE_LM_PIVOT_REL * st->scale;
    unicycle_real *P = work, *Y = work + UNICYCLE_NX * UNICYCLE_NX, *Z = Y + UNICYCLE_NX * UNICYCLE_NW;
    unicycle_real v;
    int k, i, j, l;
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
        /* Cholesky of the control block Z_uu in place (lower triangle) */
        for (j = UNICYCLE_NX; j < UNICYCLE_NW; ++j) {
            unicycle_real d = Z[j + j * UNICYCLE_NW];
            for (l = UNICYCLE_NX; l < j; ++l) {
                d -= Z[j + l * UNICYCLE_NW] * Z[j + l * UNICYCLE_NW];
            }
            if (!(d > tol)) {
                return 0;
            }
            d = unicycle_sqrt(d);
            Z[j + j * UNICYCLE_NW] = d;
            for (i = j + 1; i < UNICYCLE_NW; ++i) {
                v = Z[i + j * UNICYCLE_NW];
                for (l = UNICYCLE_NX; l < j; ++l) {
                    v -= Z[i + l * UNICYCLE_NW] * Z[j + l * UNICYCLE_NW];
                }
                Z[i + j * UNICYCLE_NW] = v / d;
            }
        }
        if (k == 0) {
            break; /* x_0 is fixed: P_0 is not needed */
        }
        /* Y = L^-1 Z_ux in place, then P = Z_xx - Y' Y (lower triangle, mirrored) */
        for (j = 0; j < UNICYCLE_NX; ++j) {
            for (i = UNICYCLE_NX; i < UNICYCLE_NW; ++i) {
                v = Z[i + j * UNICYCLE_NW];
                for (l = UNICYCLE_NX; l < i; ++l) {
                    v -= Z[i + l * UNICYCLE_NW] * Z[l + j * UNICYCLE_NW];
                }
                Z[i + j * UNICYCLE_NW] = v / Z[i + i * UNICYCLE_NW];
            }
        }
        for (j = 0; j < UNICYCLE_NX; ++j) {
            for (i = j; i < UNICYCLE_NX; ++i) {
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
    unicycle_lm_convexify(st, ring, A_N, work);
}

void unicycle_lm_prepared(unicycle_lm *st, const unicycle_ring *ring, const unicycle_real *A_N, unicycle_real kkt_proxy,
                       unicycle_real proxy_ref, unicycle_real *work)
{
    unicycle_real floor_ = UNICYCLE_PREC(1e-8, 1e-5) * (proxy_ref > UNICYCLE_R(1.0) ? proxy_ref : UNICYCLE_R(1.0));
    unicycle_real prev = st->kkt_prev > floor_ ? st->kkt_prev : floor_;
    if (!st->on) {
        return;
    }
    st->scale = unicycle_lm_hessian_scale(ring, A_N);
    st->uncapped = -UNICYCLE_R(1.0);
    if (st->kkt_prev >= UNICYCLE_R(0.0) && !(kkt_proxy <= UNICYCLE_LM_KKT_GROWTH * prev)) {
        unicycle_lm_raise(st);
    }
    st->kkt_prev = kkt_proxy;
    unicycle_lm_convexify(st, ring, A_N, work);
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
