/* Ring buffer of stage slots and the secant criterion (eq. 16). */
#include <float.h>
#include <math.h>

#include "robot_arm_ring.h"

#include "robot_arm_linalg.h"

/* The prediction's rows of F_w two at a time where doubles come in two-wide vectors and the
 * blocks are large enough to pay (nx >= 8, as the lm test's kernels); the same values as the
 * rows one at a time. */
#define ROBOT_ARM_RING_V2 (ROBOT_ARM_LAI_VEC && ROBOT_ARM_NX >= 8)

static void robot_arm_ring_zero(robot_arm_real *v, int n)
{
    int i;
    for (i = 0; i < n; ++i) {
        v[i] = ROBOT_ARM_R(0.0);
    }
}

void robot_arm_ring_reset(robot_arm_ring *ring)
{
    int k;
    for (k = 0; k < ROBOT_ARM_N; ++k) {
        robot_arm_stage_slot *s = &ring->slot[k];
        robot_arm_ring_zero(s->Ht, ROBOT_ARM_NW * ROBOT_ARM_NW);
        robot_arm_ring_zero(s->A_dyn_diag, ROBOT_ARM_NW);
        robot_arm_ring_zero(s->Phit, ROBOT_ARM_NX * ROBOT_ARM_NW);
        robot_arm_ring_zero(s->Ct, ROBOT_ARM_DIM(ROBOT_ARM_NG * ROBOT_ARM_NW));
        robot_arm_ring_zero(s->F_w, ROBOT_ARM_NW);
        robot_arm_ring_zero(s->phi, ROBOT_ARM_NX);
        robot_arm_ring_zero(s->g, ROBOT_ARM_DIM(ROBOT_ARM_NG));
        robot_arm_ring_zero(s->dw_acc, ROBOT_ARM_NW);
        robot_arm_ring_clear_step(s);
    }
    ring->ring_head = 0;
}

void robot_arm_ring_set_H(robot_arm_stage_slot *slot, const robot_arm_real *A)
{
    int i, j;
    for (j = 0; j < ROBOT_ARM_NW; ++j)
        for (i = j; i < ROBOT_ARM_NW; ++i)
            slot->Ht[i + j * ROBOT_ARM_NW] = A[i + j * ROBOT_ARM_NW];
}

void robot_arm_ring_set_A_dyn(robot_arm_stage_slot *slot, const robot_arm_real *A)
{
    int i, j;
    for (j = 0; j < ROBOT_ARM_NW; ++j) {
        slot->A_dyn_diag[j] = A[j + j * ROBOT_ARM_NW];
        for (i = j + 1; i < ROBOT_ARM_NW; ++i)
            slot->Ht[j + i * ROBOT_ARM_NW] = A[i + j * ROBOT_ARM_NW];
    }
}

void robot_arm_ring_add_A_dyn(const robot_arm_stage_slot *slot, const robot_arm_real *A_l, robot_arm_real *A)
{
    int i, j;
    for (j = 0; j < ROBOT_ARM_NW; ++j) {
        A[j + j * ROBOT_ARM_NW] = slot->A_dyn_diag[j] + A_l[j + j * ROBOT_ARM_NW];
        for (i = j + 1; i < ROBOT_ARM_NW; ++i) {
            const robot_arm_real a = slot->Ht[j + i * ROBOT_ARM_NW];
            A[i + j * ROBOT_ARM_NW] = a + A_l[i + j * ROBOT_ARM_NW];
            A[j + i * ROBOT_ARM_NW] = a + A_l[j + i * ROBOT_ARM_NW];
        }
    }
}

void robot_arm_ring_set_H_A_dyn(robot_arm_stage_slot *slot, const robot_arm_real *A_l)
{
    int i, j;
    for (j = 0; j < ROBOT_ARM_NW; ++j) {
        slot->Ht[j + j * ROBOT_ARM_NW] = slot->A_dyn_diag[j] + A_l[j + j * ROBOT_ARM_NW];
        for (i = j + 1; i < ROBOT_ARM_NW; ++i)
            slot->Ht[i + j * ROBOT_ARM_NW] = slot->Ht[j + i * ROBOT_ARM_NW] + A_l[i + j * ROBOT_ARM_NW];
    }
}

robot_arm_stage_slot *robot_arm_ring_stage(robot_arm_ring *ring, int k)
{
    return &ring->slot[(ring->ring_head + k) % ROBOT_ARM_N];
}

const robot_arm_stage_slot *robot_arm_ring_stage_const(const robot_arm_ring *ring, int k)
{
    return &ring->slot[(ring->ring_head + k) % ROBOT_ARM_N];
}

void robot_arm_ring_advance(robot_arm_ring *ring)
{
    ring->ring_head = (ring->ring_head + 1) % ROBOT_ARM_N;
}

void robot_arm_ring_clear_step(robot_arm_stage_slot *slot)
{
    robot_arm_ring_zero(slot->dw, ROBOT_ARM_NW);
    robot_arm_ring_zero(slot->dlam, ROBOT_ARM_NX);
    robot_arm_ring_zero(slot->dmu_g, ROBOT_ARM_DIM(ROBOT_ARM_NG));
    robot_arm_ring_zero(slot->dmu_b, ROBOT_ARM_NW);
}

void robot_arm_ring_predict(const robot_arm_stage_slot *slot, robot_arm_real *F_w, robot_arm_real *phi, robot_arm_real *g)
{
    /* the step in locals: the outputs might alias the slot for the compiler, which would
     * then load the step again for every row */
    robot_arm_real dw[ROBOT_ARM_NW], dlam[ROBOT_ARM_NX], dmu_g[ROBOT_ARM_DIM(ROBOT_ARM_NG)];
    int i, j;
#if ROBOT_ARM_LAI_VEC
    /* Phi dw down the columns (each entry the sum of the dot product below) */
    robot_arm_real pd[ROBOT_ARM_NX];
#endif
    for (j = 0; j < ROBOT_ARM_NW; ++j)
        dw[j] = slot->dw[j];
    for (j = 0; j < ROBOT_ARM_NX; ++j)
        dlam[j] = slot->dlam[j];
    for (j = 0; j < ROBOT_ARM_NG; ++j)
        dmu_g[j] = slot->dmu_g[j];
#if ROBOT_ARM_LAI_VEC
    ROBOT_ARM_LAI_V2_GEMV(ROBOT_ARM_NX, ROBOT_ARM_NW, slot->Phit, dw, pd, 1);
#endif
    i = 0;
#if ROBOT_ARM_RING_V2
    /* rows i, i + 1 of F_w together, each lane the sums below in the same order: Ht's pair
     * of rows (its lower triangle: a pair of a column up to row i, then strided pairs of the
     * columns i and i + 1 below it) and Phi's pair of columns times a broadcast step */
    {
        robot_arm_lai_v2 dwb[ROBOT_ARM_NW], dlb[ROBOT_ARM_NX];
        for (j = 0; j < ROBOT_ARM_NW; ++j)
            dwb[j] = (robot_arm_lai_v2){dw[j], dw[j]};
        for (j = 0; j < ROBOT_ARM_NX; ++j)
            dlb[j] = (robot_arm_lai_v2){dlam[j], dlam[j]};
        for (; i + 1 < ROBOT_ARM_NW; i += 2) {
            const robot_arm_real *h0 = slot->Ht + i * ROBOT_ARM_NW, *h1 = h0 + ROBOT_ARM_NW;
            const robot_arm_real *f0 = slot->Phit + i * ROBOT_ARM_NX, *f1 = f0 + ROBOT_ARM_NX;
            robot_arm_lai_v2 hd = {ROBOT_ARM_R(0.0), ROBOT_ARM_R(0.0)}, pl = hd, cm = hd, r;
            for (j = 0; j <= i; ++j)
                hd += robot_arm_lai_v2_load(slot->Ht + i + j * ROBOT_ARM_NW) * dwb[j];
            hd += (robot_arm_lai_v2){h0[i + 1], h1[i + 1]} * dwb[i + 1];
            for (j = i + 2; j < ROBOT_ARM_NW; ++j)
                hd += (robot_arm_lai_v2){h0[j], h1[j]} * dwb[j];
            ROBOT_ARM_UNROLL
            for (j = 0; j < ROBOT_ARM_NX; ++j)
                pl += (robot_arm_lai_v2){f0[j], f1[j]} * dlb[j];
            for (j = 0; j < ROBOT_ARM_NG; ++j)
                cm += (robot_arm_lai_v2){slot->Ct[j + i * ROBOT_ARM_DIM(ROBOT_ARM_NG)],
                                     slot->Ct[j + (i + 1) * ROBOT_ARM_DIM(ROBOT_ARM_NG)]} *
                      dmu_g[j];
            r = robot_arm_lai_v2_load(slot->F_w + i) + hd - pl + cm + robot_arm_lai_v2_load(slot->dmu_b + i);
            robot_arm_lai_v2_store(F_w + i, r);
        }
    }
#endif
    for (; i < ROBOT_ARM_NW; ++i) {
        robot_arm_real hd = ROBOT_ARM_R(0.0), pl = ROBOT_ARM_R(0.0), cm = ROBOT_ARM_R(0.0);
        /* Ht dw from its lower triangle: row i is Ht's row i up to the diagonal, then its
         * column i below it */
        for (j = 0; j <= i; ++j)
            hd += slot->Ht[i + j * ROBOT_ARM_NW] * dw[j];
        for (j = i + 1; j < ROBOT_ARM_NW; ++j)
            hd += slot->Ht[j + i * ROBOT_ARM_NW] * dw[j];
        for (j = 0; j < ROBOT_ARM_NX; ++j)
            pl += slot->Phit[j + i * ROBOT_ARM_NX] * dlam[j];
        for (j = 0; j < ROBOT_ARM_NG; ++j)
            cm += slot->Ct[j + i * ROBOT_ARM_DIM(ROBOT_ARM_NG)] * dmu_g[j];
        F_w[i] = slot->F_w[i] + hd - pl + cm + slot->dmu_b[i];
    }
    for (i = 0; i < ROBOT_ARM_NX; ++i) {
#if ROBOT_ARM_LAI_VEC
        phi[i] = slot->phi[i] + pd[i];
#else
        robot_arm_real p = ROBOT_ARM_R(0.0);
        for (j = 0; j < ROBOT_ARM_NW; ++j)
            p += slot->Phit[i + j * ROBOT_ARM_NX] * dw[j];
        phi[i] = slot->phi[i] + p;
#endif
    }
    for (i = 0; i < ROBOT_ARM_NG; ++i) {
        robot_arm_real cd = ROBOT_ARM_R(0.0);
        for (j = 0; j < ROBOT_ARM_NW; ++j)
            cd += slot->Ct[i + j * ROBOT_ARM_DIM(ROBOT_ARM_NG)] * dw[j];
        g[i] = slot->g[i] + cd;
    }
}

robot_arm_real robot_arm_ring_secant(const robot_arm_stage_slot *slot, const robot_arm_real *F_w_new,
                             const robot_arm_real *phi_new, const robot_arm_real *g_new)
{
    robot_arm_real num2 = ROBOT_ARM_R(0.0), den2 = ROBOT_ARM_R(0.0), old2 = ROBOT_ARM_R(0.0), new2 = ROBOT_ARM_R(0.0);
    robot_arm_real F_w[ROBOT_ARM_NW], phi[ROBOT_ARM_NX], g[ROBOT_ARM_DIM(ROBOT_ARM_NG)];
    int i;

    /* the residual of the linear model: its prediction minus F_new, row by row (stationarity,
     * dynamics, path constraints) */
    robot_arm_ring_predict(slot, F_w, phi, g);
    for (i = 0; i < ROBOT_ARM_NW; ++i) {
        robot_arm_real v = F_w[i] - F_w_new[i];
        num2 += v * v;
    }
    for (i = 0; i < ROBOT_ARM_NX; ++i) {
        robot_arm_real v = phi_new[i] - phi[i];
        num2 += v * v;
    }
    for (i = 0; i < ROBOT_ARM_NG; ++i) {
        robot_arm_real v = g[i] - g_new[i];
        num2 += v * v;
    }
    for (i = 0; i < ROBOT_ARM_NW; ++i)
        den2 += slot->dw[i] * slot->dw[i] + slot->dmu_b[i] * slot->dmu_b[i];
    for (i = 0; i < ROBOT_ARM_NX; ++i)
        den2 += slot->dlam[i] * slot->dlam[i];
    for (i = 0; i < ROBOT_ARM_NG; ++i)
        den2 += slot->dmu_g[i] * slot->dmu_g[i];
    /* round-off scale of num: |F_old| + |F_new| */
    for (i = 0; i < ROBOT_ARM_NW; ++i)
        old2 += slot->F_w[i] * slot->F_w[i];
    for (i = 0; i < ROBOT_ARM_NX; ++i)
        old2 += slot->phi[i] * slot->phi[i];
    for (i = 0; i < ROBOT_ARM_NG; ++i)
        old2 += slot->g[i] * slot->g[i];
    for (i = 0; i < ROBOT_ARM_NW; ++i)
        new2 += F_w_new[i] * F_w_new[i];
    for (i = 0; i < ROBOT_ARM_NX; ++i)
        new2 += phi_new[i] * phi_new[i];
    for (i = 0; i < ROBOT_ARM_NG; ++i)
        new2 += g_new[i] * g_new[i];
    if (den2 == ROBOT_ARM_R(0.0)) {
        return ROBOT_ARM_R(0.0);
    }
    /* a residual or step whose square overflows (or a NaN from Inf - Inf in the residual):
     * the linear model of this stage says nothing, it ranks first */
    if (!(num2 <= ROBOT_ARM_REAL_MAX) || !(den2 <= ROBOT_ARM_REAL_MAX)) {
        return INFINITY;
    }
    /* a residual at the round-off level of F is noise, not a secant violation */
    if (robot_arm_sqrt(num2) <= ROBOT_ARM_EPS_RHO * (robot_arm_sqrt(old2) + robot_arm_sqrt(new2))) {
        return ROBOT_ARM_R(0.0);
    }
    return robot_arm_sqrt(num2) / robot_arm_sqrt(den2);
}

void robot_arm_ring_store_F(robot_arm_stage_slot *slot, const robot_arm_real *F_w, const robot_arm_real *phi,
                        const robot_arm_real *g)
{
    int i;
    for (i = 0; i < ROBOT_ARM_NW; ++i)
        slot->F_w[i] = F_w[i];
    for (i = 0; i < ROBOT_ARM_NX; ++i)
        slot->phi[i] = phi[i];
    for (i = 0; i < ROBOT_ARM_NG; ++i)
        slot->g[i] = g[i];
}
