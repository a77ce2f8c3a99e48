/* Ring buffer of stage slots and the secant criterion (eq. 16). */
#include <float.h>
#include <math.h>

#include "unicycle_ring.h"

#include "unicycle_linalg.h"

/* The prediction's rows of F_w two at a time where doubles come in two-wide vectors and the
 * blocks are large enough to pay (nx >= 8, as the lm test's kernels); the same values as the
 * rows one at a time. */
#define UNICYCLE_RING_V2 (UNICYCLE_LAI_VEC && UNICYCLE_NX >= 8)

static void unicycle_ring_zero(unicycle_real *v, int n)
{
    int i;
    for (i = 0; i < n; ++i) {
        v[i] = UNICYCLE_R(0.0);
    }
}

void unicycle_ring_reset(unicycle_ring *ring)
{
    int k;
    for (k = 0; k < UNICYCLE_N; ++k) {
        unicycle_stage_slot *s = &ring->slot[k];
        unicycle_ring_zero(s->Ht, UNICYCLE_NW * UNICYCLE_NW);
        unicycle_ring_zero(s->A_dyn_diag, UNICYCLE_NW);
        unicycle_ring_zero(s->Phit, UNICYCLE_NX * UNICYCLE_NW);
        unicycle_ring_zero(s->Ct, UNICYCLE_DIM(UNICYCLE_NG * UNICYCLE_NW));
        unicycle_ring_zero(s->F_w, UNICYCLE_NW);
        unicycle_ring_zero(s->phi, UNICYCLE_NX);
        unicycle_ring_zero(s->g, UNICYCLE_DIM(UNICYCLE_NG));
        unicycle_ring_zero(s->dw_acc, UNICYCLE_NW);
        unicycle_ring_clear_step(s);
    }
    ring->ring_head = 0;
}

void unicycle_ring_set_H(unicycle_stage_slot *slot, const unicycle_real *A)
{
    int i, j;
    for (j = 0; j < UNICYCLE_NW; ++j)
        for (i = j; i < UNICYCLE_NW; ++i)
            slot->Ht[i + j * UNICYCLE_NW] = A[i + j * UNICYCLE_NW];
}

void unicycle_ring_set_A_dyn(unicycle_stage_slot *slot, const unicycle_real *A)
{
    int i, j;
    for (j = 0; j < UNICYCLE_NW; ++j) {
        slot->A_dyn_diag[j] = A[j + j * UNICYCLE_NW];
        for (i = j + 1; i < UNICYCLE_NW; ++i)
            slot->Ht[j + i * UNICYCLE_NW] = A[i + j * UNICYCLE_NW];
    }
}

void unicycle_ring_add_A_dyn(const unicycle_stage_slot *slot, const unicycle_real *A_l, unicycle_real *A)
{
    int i, j;
    for (j = 0; j < UNICYCLE_NW; ++j) {
        A[j + j * UNICYCLE_NW] = slot->A_dyn_diag[j] + A_l[j + j * UNICYCLE_NW];
        for (i = j + 1; i < UNICYCLE_NW; ++i) {
            const unicycle_real a = slot->Ht[j + i * UNICYCLE_NW];
            A[i + j * UNICYCLE_NW] = a + A_l[i + j * UNICYCLE_NW];
            A[j + i * UNICYCLE_NW] = a + A_l[j + i * UNICYCLE_NW];
        }
    }
}

void unicycle_ring_set_H_A_dyn(unicycle_stage_slot *slot, const unicycle_real *A_l)
{
    int i, j;
    for (j = 0; j < UNICYCLE_NW; ++j) {
        slot->Ht[j + j * UNICYCLE_NW] = slot->A_dyn_diag[j] + A_l[j + j * UNICYCLE_NW];
        for (i = j + 1; i < UNICYCLE_NW; ++i)
            slot->Ht[i + j * UNICYCLE_NW] = slot->Ht[j + i * UNICYCLE_NW] + A_l[i + j * UNICYCLE_NW];
    }
}

unicycle_stage_slot *unicycle_ring_stage(unicycle_ring *ring, int k)
{
    return &ring->slot[(ring->ring_head + k) % UNICYCLE_N];
}

const unicycle_stage_slot *unicycle_ring_stage_const(const unicycle_ring *ring, int k)
{
    return &ring->slot[(ring->ring_head + k) % UNICYCLE_N];
}

void unicycle_ring_advance(unicycle_ring *ring)
{
    ring->ring_head = (ring->ring_head + 1) % UNICYCLE_N;
}

void unicycle_ring_clear_step(unicycle_stage_slot *slot)
{
    unicycle_ring_zero(slot->dw, UNICYCLE_NW);
    unicycle_ring_zero(slot->dlam, UNICYCLE_NX);
    unicycle_ring_zero(slot->dmu_g, UNICYCLE_DIM(UNICYCLE_NG));
    unicycle_ring_zero(slot->dmu_b, UNICYCLE_NW);
}

void unicycle_ring_predict(const unicycle_stage_slot *slot, unicycle_real *F_w, unicycle_real *phi, unicycle_real *g)
{
    /* the step in locals: the outputs might alias the slot for the compiler, which would
     * then load the step again for every row */
    unicycle_real dw[UNICYCLE_NW], dlam[UNICYCLE_NX], dmu_g[UNICYCLE_DIM(UNICYCLE_NG)];
    int i, j;
#if UNICYCLE_LAI_VEC
    /* Phi dw down the columns (each entry the sum of the dot product below) */
    unicycle_real pd[UNICYCLE_NX];
#endif
    for (j = 0; j < UNICYCLE_NW; ++j)
        dw[j] = slot->dw[j];
    for (j = 0; j < UNICYCLE_NX; ++j)
        dlam[j] = slot->dlam[j];
    for (j = 0; j < UNICYCLE_NG; ++j)
        dmu_g[j] = slot->dmu_g[j];
#if UNICYCLE_LAI_VEC
    UNICYCLE_LAI_V2_GEMV(UNICYCLE_NX, UNICYCLE_NW, slot->Phit, dw, pd, 1);
#endif
    i = 0;
#if UNICYCLE_RING_V2
    /* rows i, i + 1 of F_w together, each lane the sums below in the same order: Ht's pair
     * of rows (its lower triangle: a pair of a column up to row i, then strided pairs of the
     * columns i and i + 1 below it) and Phi's pair of columns times a broadcast step */
    {
        unicycle_lai_v2 dwb[UNICYCLE_NW], dlb[UNICYCLE_NX];
        for (j = 0; j < UNICYCLE_NW; ++j)
            dwb[j] = (unicycle_lai_v2){dw[j], dw[j]};
        for (j = 0; j < UNICYCLE_NX; ++j)
            dlb[j] = (unicycle_lai_v2){dlam[j], dlam[j]};
        for (; i + 1 < UNICYCLE_NW; i += 2) {
            const unicycle_real *h0 = slot->Ht + i * UNICYCLE_NW, *h1 = h0 + UNICYCLE_NW;
            const unicycle_real *f0 = slot->Phit + i * UNICYCLE_NX, *f1 = f0 + UNICYCLE_NX;
            unicycle_lai_v2 hd = {UNICYCLE_R(0.0), UNICYCLE_R(0.0)}, pl = hd, cm = hd, r;
            for (j = 0; j <= i; ++j)
                hd += unicycle_lai_v2_load(slot->Ht + i + j * UNICYCLE_NW) * dwb[j];
            hd += (unicycle_lai_v2){h0[i + 1], h1[i + 1]} * dwb[i + 1];
            for (j = i + 2; j < UNICYCLE_NW; ++j)
                hd += (unicycle_lai_v2){h0[j], h1[j]} * dwb[j];
            UNICYCLE_UNROLL
            for (j = 0; j < UNICYCLE_NX; ++j)
                pl += (unicycle_lai_v2){f0[j], f1[j]} * dlb[j];
            for (j = 0; j < UNICYCLE_NG; ++j)
                cm += (unicycle_lai_v2){slot->Ct[j + i * UNICYCLE_DIM(UNICYCLE_NG)],
                                     slot->Ct[j + (i + 1) * UNICYCLE_DIM(UNICYCLE_NG)]} *
                      dmu_g[j];
            r = unicycle_lai_v2_load(slot->F_w + i) + hd - pl + cm + unicycle_lai_v2_load(slot->dmu_b + i);
            unicycle_lai_v2_store(F_w + i, r);
        }
    }
#endif
    for (; i < UNICYCLE_NW; ++i) {
        unicycle_real hd = UNICYCLE_R(0.0), pl = UNICYCLE_R(0.0), cm = UNICYCLE_R(0.0);
        /* Ht dw from its lower triangle: row i is Ht's row i up to the diagonal, then its
         * column i below it */
        for (j = 0; j <= i; ++j)
            hd += slot->Ht[i + j * UNICYCLE_NW] * dw[j];
        for (j = i + 1; j < UNICYCLE_NW; ++j)
            hd += slot->Ht[j + i * UNICYCLE_NW] * dw[j];
        for (j = 0; j < UNICYCLE_NX; ++j)
            pl += slot->Phit[j + i * UNICYCLE_NX] * dlam[j];
        for (j = 0; j < UNICYCLE_NG; ++j)
            cm += slot->Ct[j + i * UNICYCLE_DIM(UNICYCLE_NG)] * dmu_g[j];
        F_w[i] = slot->F_w[i] + hd - pl + cm + slot->dmu_b[i];
    }
    for (i = 0; i < UNICYCLE_NX; ++i) {
#if UNICYCLE_LAI_VEC
        phi[i] = slot->phi[i] + pd[i];
#else
        unicycle_real p = UNICYCLE_R(0.0);
        for (j = 0; j < UNICYCLE_NW; ++j)
            p += slot->Phit[i + j * UNICYCLE_NX] * dw[j];
        phi[i] = slot->phi[i] + p;
#endif
    }
    for (i = 0; i < UNICYCLE_NG; ++i) {
        unicycle_real cd = UNICYCLE_R(0.0);
        for (j = 0; j < UNICYCLE_NW; ++j)
            cd += slot->Ct[i + j * UNICYCLE_DIM(UNICYCLE_NG)] * dw[j];
        g[i] = slot->g[i] + cd;
    }
}

unicycle_real unicycle_ring_secant(const unicycle_stage_slot *slot, const unicycle_real *F_w_new,
                             const unicycle_real *phi_new, const unicycle_real *g_new)
{
    unicycle_real num2 = UNICYCLE_R(0.0), den2 = UNICYCLE_R(0.0), old2 = UNICYCLE_R(0.0), new2 = UNICYCLE_R(0.0);
    unicycle_real F_w[UNICYCLE_NW], phi[UNICYCLE_NX], g[UNICYCLE_DIM(UNICYCLE_NG)];
    int i;

    /* the residual of the linear model: its prediction minus F_new, row by row (stationarity,
     * dynamics, path constraints) */
    unicycle_ring_predict(slot, F_w, phi, g);
    for (i = 0; i < UNICYCLE_NW; ++i) {
        unicycle_real v = F_w[i] - F_w_new[i];
        num2 += v * v;
    }
    for (i = 0; i < UNICYCLE_NX; ++i) {
        unicycle_real v = phi_new[i] - phi[i];
        num2 += v * v;
    }
    for (i = 0; i < UNICYCLE_NG; ++i) {
        unicycle_real v = g[i] - g_new[i];
        num2 += v * v;
    }
    for (i = 0; i < UNICYCLE_NW; ++i)
        den2 += slot->dw[i] * slot->dw[i] + slot->dmu_b[i] * slot->dmu_b[i];
    for (i = 0; i < UNICYCLE_NX; ++i)
        den2 += slot->dlam[i] * slot->dlam[i];
    for (i = 0; i < UNICYCLE_NG; ++i)
        den2 += slot->dmu_g[i] * slot->dmu_g[i];
    /* round-off scale of num: |F_old| + |F_new| */
    for (i = 0; i < UNICYCLE_NW; ++i)
        old2 += slot->F_w[i] * slot->F_w[i];
    for (i = 0; i < UNICYCLE_NX; ++i)
        old2 += slot->phi[i] * slot->phi[i];
    for (i = 0; i < UNICYCLE_NG; ++i)
        old2 += slot->g[i] * slot->g[i];
    for (i = 0; i < UNICYCLE_NW; ++i)
        new2 += F_w_new[i] * F_w_new[i];
    for (i = 0; i < UNICYCLE_NX; ++i)
        new2 += phi_new[i] * phi_new[i];
    for (i = 0; i < UNICYCLE_NG; ++i)
        new2 += g_new[i] * g_new[i];
    if (den2 == UNICYCLE_R(0.0)) {
        return UNICYCLE_R(0.0);
    }
    /* a residual or step whose square overflows (or a NaN from Inf - Inf in the residual):
     * the linear model of this stage says nothing, it ranks first */
    if (!(num2 <= UNICYCLE_REAL_MAX) || !(den2 <= UNICYCLE_REAL_MAX)) {
        return INFINITY;
    }
    /* a residual at the round-off level of F is noise, not a secant violation */
    if (unicycle_sqrt(num2) <= UNICYCLE_EPS_RHO * (unicycle_sqrt(old2) + unicycle_sqrt(new2))) {
        return UNICYCLE_R(0.0);
    }
    return unicycle_sqrt(num2) / unicycle_sqrt(den2);
}

void unicycle_ring_store_F(unicycle_stage_slot *slot, const unicycle_real *F_w, const unicycle_real *phi,
                        const unicycle_real *g)
{
    int i;
    for (i = 0; i < UNICYCLE_NW; ++i)
        slot->F_w[i] = F_w[i];
    for (i = 0; i < UNICYCLE_NX; ++i)
        slot->phi[i] = phi[i];
    for (i = 0; i < UNICYCLE_NG; ++i)
        slot->g[i] = g[i];
}
