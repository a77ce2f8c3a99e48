/* The ring buffer of stage slots (docs/design.md section 5, docs/algorithm.md section 4).
 *
 * Stage k lives in slot (ring_head + k) mod N. The receding-horizon shift advances
 * ring_head, so the sensitivities of stage k+1 become those of stage k without a copy and
 * the slot that falls off the front becomes the new last stage. The QP reads Ht, Phit, Ct
 * in place through per-stage pointer tables.
 */
#ifndef DOPUS_RING_H
#define DOPUS_RING_H

#include "dopus_sizes.h"

typedef struct {
    /* the blocks the QP uses (possibly outdated, A regularised), column-major. Ht (nw x nw)
     * holds two symmetric matrices: its lower triangle with the diagonal is the QP's block
     * (the QP reads only that, dopus_qp.h), its strict upper triangle the strict lower
     * triangle of A_dyn = A - A_l of the last H evaluation (unregularised: the curvature of
     * dynamics and path constraints, to which step 5 of prepare adds a fresh stage-cost A_l),
     * A_dyn(i, j) for i > j at Ht[j + i nw]; A_dyn_diag its diagonal
     * (dopus_ring_set_H, dopus_ring_set_A_dyn) */
    dopus_real Ht[DOPUS_NW * DOPUS_NW];
    dopus_real A_dyn_diag[DOPUS_NW];
    dopus_real Phit[DOPUS_NX * DOPUS_NW];          /* nx x nw, [A_k B_k] */
    dopus_real Ct[DOPUS_DIM(DOPUS_NG * DOPUS_NW)]; /* ng x nw (leading dimension ng) */
    /* F_old = (F_w, phi, g) of the last gradient evaluation of this stage (eq. 14) */
    dopus_real F_w[DOPUS_NW];
    dopus_real phi[DOPUS_NX];
    dopus_real g[DOPUS_DIM(DOPUS_NG)];
    /* domega = (dw, dlam_next, dmu_g, dmu_b): the last QP step of this stage */
    dopus_real dw[DOPUS_NW];
    dopus_real dlam[DOPUS_NX];
    dopus_real dmu_g[DOPUS_DIM(DOPUS_NG)];
    dopus_real dmu_b[DOPUS_NW];
    /* the steps dw since the last gradient evaluation of this stage, summed: how far its
     * linear model's point has moved from the evaluation point (the order of an anytime
     * prepare's gradients, algorithm.md section 14) */
    dopus_real dw_acc[DOPUS_NW];
} dopus_stage_slot;

typedef struct {
    dopus_stage_slot slot[DOPUS_N];
    int ring_head;
} dopus_ring;

#ifndef DOPUS_INTERNAL
#define DOPUS_INTERNAL
#endif

/* head = 0, every slot zero. */
DOPUS_INTERNAL void dopus_ring_reset(dopus_ring *ring);

/* The slot of stage k (0 <= k < N). */
DOPUS_INTERNAL dopus_stage_slot *dopus_ring_stage(dopus_ring *ring, int k);
DOPUS_INTERNAL const dopus_stage_slot *dopus_ring_stage_const(const dopus_ring *ring, int k);

/* One sampling interval: ring_head <- (ring_head + 1) mod N. */
DOPUS_INTERNAL void dopus_ring_advance(dopus_ring *ring);

/* The QP's block of the slot (Ht's lower triangle) from the lower triangle of the nw x nw
 * column-major A; A_dyn kept. */
DOPUS_INTERNAL void dopus_ring_set_H(dopus_stage_slot *slot, const dopus_real *A);
/* A_dyn of the slot from the lower triangle of the nw x nw column-major A; the QP's block kept. */
DOPUS_INTERNAL void dopus_ring_set_A_dyn(dopus_stage_slot *slot, const dopus_real *A);
/* A = A_dyn + A_l (nw x nw column-major, both triangles; A_dyn symmetric; A not the slot's). */
DOPUS_INTERNAL void dopus_ring_add_A_dyn(const dopus_stage_slot *slot, const dopus_real *A_l, dopus_real *A);
/* The QP's block of the slot = A_dyn + A_l (the lower triangle of A_l read), in place. */
DOPUS_INTERNAL void dopus_ring_set_H_A_dyn(dopus_stage_slot *slot, const dopus_real *A_l);

/* Zero the step domega of a slot. */
DOPUS_INTERNAL void dopus_ring_clear_step(dopus_stage_slot *slot);

/* Round-off floor of the secant residual (docs/algorithm.md section 4 step 2). */
#define DOPUS_EPS_RHO DOPUS_PREC(1e-12, 1e-6)

/* Secant criterion rho_k (eq. 16) of the slot against the fresh F_new = (F_w, phi, g):
 *   num = | [F_w_old + Ht dw - Phit' dlam + Ct' dmu_g + dmu_b - F_w_new ;
 *            -(phi_old + Phit dw) + phi_new ;
 *            g_old + Ct dw - g_new] |
 *   rho = num / |(dw, dlam, dmu_g, dmu_b)| (2-norms), 0 when the denominator is 0 or
 *   num <= DOPUS_EPS_RHO * (|(F_w_old, phi_old, g_old)| + |(F_w_new, phi_new, g_new)|). */
DOPUS_INTERNAL dopus_real dopus_ring_secant(const dopus_stage_slot *slot, const dopus_real *F_w_new,
                                            const dopus_real *phi_new, const dopus_real *g_new);

/* The linear model's prediction of F at the point after the stored step (the value for which
 * dopus_ring_secant's numerator is 0; Ht the QP's symmetric block, its lower triangle read):
 *   F_w = F_w_old + Ht dw - Phit' dlam + Ct' dmu_g + dmu_b, phi = phi_old + Phit dw,
 *   g = g_old + Ct dw
 * (an anytime prepare whose gradients are cut, docs/algorithm.md section 14). */
DOPUS_INTERNAL void dopus_ring_predict(const dopus_stage_slot *slot, dopus_real *F_w, dopus_real *phi,
                                       dopus_real *g);

/* Store F_new as F_old. */
DOPUS_INTERNAL void dopus_ring_store_F(dopus_stage_slot *slot, const dopus_real *F_w, const dopus_real *phi,
                                       const dopus_real *g);

#endif /* DOPUS_RING_H */
