/* Ring buffer of stage slots and the secant criterion (eq. 16). */
#include <float.h>
#include <math.h>

#include "dopus_ring.h"

#include "dopus_linalg.h"

/* The prediction's rows of F_w two at a time where doubles come in two-wide vectors and the
 * blocks are large enough to pay (nx >= 8, as the lm test's kernels); the same values as the
 * rows one at a time. */
#define DOPUS_RING_V2 (DOPUS_LAI_VEC && DOPUS_NX >= 8)

static void dopus_ring_zero(dopus_real *v, int n)
{
    int i;
    for (i = 0; i < n; ++i) {
        v[i] = DOPUS_R(0.0);
    }
}

void dopus_ring_reset(dopus_ring *ring)
{
    int k;
    for (k = 0; k < DOPUS_N; ++k) {
        dopus_stage_slot *s = &ring->slot[k];
        dopus_ring_zero(s->Ht, DOPUS_NW * DOPUS_NW);
        dopus_ring_zero(s->A_dyn_diag, DOPUS_NW);
        dopus_ring_zero(s->Phit, DOPUS_NX * DOPUS_NW);
        dopus_ring_zero(s->Ct, DOPUS_DIM(DOPUS_NG * DOPUS_NW));
        dopus_ring_zero(s->F_w, DOPUS_NW);
        dopus_ring_zero(s->phi, DOPUS_NX);
        dopus_ring_zero(s->g, DOPUS_DIM(DOPUS_NG));
        dopus_ring_zero(s->dw_acc, DOPUS_NW);
        dopus_ring_clear_step(s);
    }
    ring->ring_head = 0;
}

void dopus_ring_set_H(dopus_stage_slot *slot, const dopus_real *A)
{
    int i, j;
    for (j = 0; j < DOPUS_NW; ++j)
        for (i = j; i < DOPUS_NW; ++i)
            slot->Ht[i + j * DOPUS_NW] = A[i + j * DOPUS_NW];
}

void dopus_ring_set_A_dyn(dopus_stage_slot *slot, const dopus_real *A)
{
    int i, j;
    for (j = 0; j < DOPUS_NW; ++j) {
        slot->A_dyn_diag[j] = A[j + j * DOPUS_NW];
        for (i = j + 1; i < DOPUS_NW; ++i)
            slot->Ht[j + i * DOPUS_NW] = A[i + j * DOPUS_NW];
    }
}

void dopus_ring_add_A_dyn(const dopus_stage_slot *slot, const dopus_real *A_l, dopus_real *A)
{
    int i, j;
    for (j = 0; j < DOPUS_NW; ++j) {
        A[j + j * DOPUS_NW] = slot->A_dyn_diag[j] + A_l[j + j * DOPUS_NW];
        for (i = j + 1; i < DOPUS_NW; ++i) {
            const dopus_real a = slot->Ht[j + i * DOPUS_NW];
            A[i + j * DOPUS_NW] = a + A_l[i + j * DOPUS_NW];
            A[j + i * DOPUS_NW] = a + A_l[j + i * DOPUS_NW];
        }
    }
}

void dopus_ring_set_H_A_dyn(dopus_stage_slot *slot, const dopus_real *A_l)
{
    int i, j;
    for (j = 0; j < DOPUS_NW; ++j) {
        slot->Ht[j + j * DOPUS_NW] = slot->A_dyn_diag[j] + A_l[j + j * DOPUS_NW];
        for (i = j + 1; i < DOPUS_NW; ++i)
            slot->Ht[i + j * DOPUS_NW] = slot->Ht[j + i * DOPUS_NW] + A_l[i + j * DOPUS_NW];
    }
}

dopus_stage_slot *dopus_ring_stage(dopus_ring *ring, int k)
{
    return &ring->slot[(ring->ring_head + k) % DOPUS_N];
}

const dopus_stage_slot *dopus_ring_stage_const(const dopus_ring *ring, int k)
{
    return &ring->slot[(ring->ring_head + k) % DOPUS_N];
}

void dopus_ring_advance(dopus_ring *ring)
{
    ring->ring_head = (ring->ring_head + 1) % DOPUS_N;
}

void dopus_ring_clear_step(dopus_stage_slot *slot)
{
    dopus_ring_zero(slot->dw, DOPUS_NW);
    dopus_ring_zero(slot->dlam, DOPUS_NX);
    dopus_ring_zero(slot->dmu_g, DOPUS_DIM(DOPUS_NG));
    dopus_ring_zero(slot->dmu_b, DOPUS_NW);
}

void dopus_ring_predict(const dopus_stage_slot *slot, dopus_real *F_w, dopus_real *phi, dopus_real *g)
{
    /* the step in locals: the outputs might alias the slot for the compiler, which would
     * then load the step again for every row */
    dopus_real dw[DOPUS_NW], dlam[DOPUS_NX], dmu_g[DOPUS_DIM(DOPUS_NG)];
    int i, j;
#if DOPUS_LAI_VEC
    /* Phi dw down the columns (each entry the sum of the dot product below) */
    dopus_real pd[DOPUS_NX];
#endif
    for (j = 0; j < DOPUS_NW; ++j)
        dw[j] = slot->dw[j];
    for (j = 0; j < DOPUS_NX; ++j)
        dlam[j] = slot->dlam[j];
    for (j = 0; j < DOPUS_NG; ++j)
        dmu_g[j] = slot->dmu_g[j];
#if DOPUS_LAI_VEC
    DOPUS_LAI_V2_GEMV(DOPUS_NX, DOPUS_NW, slot->Phit, dw, pd, 1);
#endif
    i = 0;
#if DOPUS_RING_V2
    /* rows i, i + 1 of F_w together, each lane the sums below in the same order: Ht's pair
     * of rows (its lower triangle: a pair of a column up to row i, then strided pairs of the
     * columns i and i + 1 below it) and Phi's pair of columns times a broadcast step */
    {
        dopus_lai_v2 dwb[DOPUS_NW], dlb[DOPUS_NX];
        for (j = 0; j < DOPUS_NW; ++j)
            dwb[j] = (dopus_lai_v2){dw[j], dw[j]};
        for (j = 0; j < DOPUS_NX; ++j)
            dlb[j] = (dopus_lai_v2){dlam[j], dlam[j]};
        for (; i + 1 < DOPUS_NW; i += 2) {
            const dopus_real *h0 = slot->Ht + i * DOPUS_NW, *h1 = h0 + DOPUS_NW;
            const dopus_real *f0 = slot->Phit + i * DOPUS_NX, *f1 = f0 + DOPUS_NX;
            dopus_lai_v2 hd = {DOPUS_R(0.0), DOPUS_R(0.0)}, pl = hd, cm = hd, r;
            for (j = 0; j <= i; ++j)
                hd += dopus_lai_v2_load(slot->Ht + i + j * DOPUS_NW) * dwb[j];
            hd += (dopus_lai_v2){h0[i + 1], h1[i + 1]} * dwb[i + 1];
            for (j = i + 2; j < DOPUS_NW; ++j)
                hd += (dopus_lai_v2){h0[j], h1[j]} * dwb[j];
            DOPUS_UNROLL
            for (j = 0; j < DOPUS_NX; ++j)
                pl += (dopus_lai_v2){f0[j], f1[j]} * dlb[j];
            for (j = 0; j < DOPUS_NG; ++j)
                cm += (dopus_lai_v2){slot->Ct[j + i * DOPUS_DIM(DOPUS_NG)],
                                     slot->Ct[j + (i + 1) * DOPUS_DIM(DOPUS_NG)]} *
                      dmu_g[j];
            r = dopus_lai_v2_load(slot->F_w + i) + hd - pl + cm + dopus_lai_v2_load(slot->dmu_b + i);
            dopus_lai_v2_store(F_w + i, r);
        }
    }
#endif
    for (; i < DOPUS_NW; ++i) {
        dopus_real hd = DOPUS_R(0.0), pl = DOPUS_R(0.0), cm = DOPUS_R(0.0);
        /* Ht dw from its lower triangle: row i is Ht's row i up to the diagonal, then its
         * column i below it */
        for (j = 0; j <= i; ++j)
            hd += slot->Ht[i + j * DOPUS_NW] * dw[j];
        for (j = i + 1; j < DOPUS_NW; ++j)
            hd += slot->Ht[j + i * DOPUS_NW] * dw[j];
        for (j = 0; j < DOPUS_NX; ++j)
            pl += slot->Phit[j + i * DOPUS_NX] * dlam[j];
        for (j = 0; j < DOPUS_NG; ++j)
            cm += slot->Ct[j + i * DOPUS_DIM(DOPUS_NG)] * dmu_g[j];
        F_w[i] = slot->F_w[i] + hd - pl + cm + slot->dmu_b[i];
    }
    for (i = 0; i < DOPUS_NX; ++i) {
#if DOPUS_LAI_VEC
        phi[i] = slot->phi[i] + pd[i];
#else
        dopus_real p = DOPUS_R(0.0);
        for (j = 0; j < DOPUS_NW; ++j)
            p += slot->Phit[i + j * DOPUS_NX] * dw[j];
        phi[i] = slot->phi[i] + p;
#endif
    }
    for (i = 0; i < DOPUS_NG; ++i) {
        dopus_real cd = DOPUS_R(0.0);
        for (j = 0; j < DOPUS_NW; ++j)
            cd += slot->Ct[i + j * DOPUS_DIM(DOPUS_NG)] * dw[j];
        g[i] = slot->g[i] + cd;
    }
}

dopus_real dopus_ring_secant(const dopus_stage_slot *slot, const dopus_real *F_w_new,
                             const dopus_real *phi_new, const dopus_real *g_new)
{
    dopus_real num2 = DOPUS_R(0.0), den2 = DOPUS_R(0.0), old2 = DOPUS_R(0.0), new2 = DOPUS_R(0.0);
    dopus_real F_w[DOPUS_NW], phi[DOPUS_NX], g[DOPUS_DIM(DOPUS_NG)];
    int i;

    /* the residual of the linear model: its prediction minus F_new, row by row (stationarity,
     * dynamics, path constraints) */
    dopus_ring_predict(slot, F_w, phi, g);
    for (i = 0; i < DOPUS_NW; ++i) {
        dopus_real v = F_w[i] - F_w_new[i];
        num2 += v * v;
    }
    for (i = 0; i < DOPUS_NX; ++i) {
        dopus_real v = phi_new[i] - phi[i];
        num2 += v * v;
    }
    for (i = 0; i < DOPUS_NG; ++i) {
        dopus_real v = g[i] - g_new[i];
        num2 += v * v;
    }
    for (i = 0; i < DOPUS_NW; ++i)
        den2 += slot->dw[i] * slot->dw[i] + slot->dmu_b[i] * slot->dmu_b[i];
    for (i = 0; i < DOPUS_NX; ++i)
        den2 += slot->dlam[i] * slot->dlam[i];
    for (i = 0; i < DOPUS_NG; ++i)
        den2 += slot->dmu_g[i] * slot->dmu_g[i];
    /* round-off scale of num: |F_old| + |F_new| */
    for (i = 0; i < DOPUS_NW; ++i)
        old2 += slot->F_w[i] * slot->F_w[i];
    for (i = 0; i < DOPUS_NX; ++i)
        old2 += slot->phi[i] * slot->phi[i];
    for (i = 0; i < DOPUS_NG; ++i)
        old2 += slot->g[i] * slot->g[i];
    for (i = 0; i < DOPUS_NW; ++i)
        new2 += F_w_new[i] * F_w_new[i];
    for (i = 0; i < DOPUS_NX; ++i)
        new2 += phi_new[i] * phi_new[i];
    for (i = 0; i < DOPUS_NG; ++i)
        new2 += g_new[i] * g_new[i];
    if (den2 == DOPUS_R(0.0)) {
        return DOPUS_R(0.0);
    }
    /* a residual or step whose square overflows (or a NaN from Inf - Inf in the residual):
     * the linear model of this stage says nothing, it ranks first */
    if (!(num2 <= DOPUS_REAL_MAX) || !(den2 <= DOPUS_REAL_MAX)) {
        return INFINITY;
    }
    /* a residual at the round-off level of F is noise, not a secant violation */
    if (dopus_sqrt(num2) <= DOPUS_EPS_RHO * (dopus_sqrt(old2) + dopus_sqrt(new2))) {
        return DOPUS_R(0.0);
    }
    return dopus_sqrt(num2) / dopus_sqrt(den2);
}

void dopus_ring_store_F(dopus_stage_slot *slot, const dopus_real *F_w, const dopus_real *phi,
                        const dopus_real *g)
{
    int i;
    for (i = 0; i < DOPUS_NW; ++i)
        slot->F_w[i] = F_w[i];
    for (i = 0; i < DOPUS_NX; ++i)
        slot->phi[i] = phi[i];
    for (i = 0; i < DOPUS_NG; ++i)
        slot->g[i] = g[i];
}
