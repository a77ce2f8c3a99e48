/* The ring buffer of stage slots (docs/design.md section 5, docs/algorithm.md section 4).
 *
 * Stage k lives in slot (ring_head + k) mod N. The receding-horizon shift advances
 * ring_head, so the sensitivities of stage k+1 become those of stage k without a copy and
 * the slot that falls off the front becomes the new last stage. The QP reads Ht, Phit, Ct
 * in place through per-stage pointer tables.
 */
#ifndef UNICYCLE_RING_H
#define UNICYCLE_RING_H

#include "unicycle_sizes.h"

typedef struct {
    /* the blocks the QP uses (possibly outdated, A regularised), column-major. Ht (nw x nw)
     * holds two symmetric matrices: its lower triangle with the diagonal is the QP's block
     * (the QP reads only that, unicycle_qp.h), its strict upper triangle the strict lower
     * triangle of A_dyn = A - A_l of the last H evaluation (unregularised: the curvature of
     * dynamics and path constraints, to which step 5 of prepare adds a fresh stage-cost A_l),
     * A_dyn(i, j) for i > j at Ht[j + i nw]; A_dyn_diag its diagonal
     * (unicycle_ring_set_H, unicycle_ring_set_A_dyn) */
    unicycle_real Ht[UNICYCLE_NW * UNICYCLE_NW];
    unicycle_real A_dyn_diag[UNICYCLE_NW];
    unicycle_real Phit[UNICYCLE_NX * UNICYCLE_NW];          /* nx x nw, [A_k B_k] */
    unicycle_real Ct[UNICYCLE_DIM(UNICYCLE_NG * UNICYCLE_NW)]; /* ng x nw (leading dimension ng) */
    /* F_old = (F_w, phi, g) of the last gradient evaluation of this stage (eq. 14) */
    unicycle_real F_w[UNICYCLE_NW];
    unicycle_real phi[UNICYCLE_NX];
    unicycle_real g[UNICYCLE_DIM(UNICYCLE_NG)];
    /* domega = (dw, dlam_next, dmu_g, dmu_b): the last QP step of this stage */
    unicycle_real dw[UNICYCLE_NW];
    unicycle_real dlam[UNICYCLE_NX];
    unicycle_real dmu_g[UNICYCLE_DIM(UNICYCLE_NG)];
    unicycle_real dmu_b[UNICYCLE_NW];
    /* the steps dw since the last gradient evaluation of this stage, summed: how far its
     * linear model's point has moved from the evaluation point (the order of an anytime
     * prepare's gradients, algorithm.md section 14) */
    unicycle_real dw_acc[UNICYCLE_NW];
} unicycle_stage_slot;

typedef struct {
    unicycle_stage_slot slot[UNICYCLE_N];
    int ring_head;
} unicycle_ring;

#ifndef UNICYCLE_INTERNAL
#define UNICYCLE_INTERNAL
#endif

/* head = 0, every slot zero. */
UNICYCLE_INTERNAL void unicycle_ring_reset(unicycle_ring *ring);

/* The slot of stage k (0 <= k < N). */
UNICYCLE_INTERNAL unicycle_stage_slot *unicycle_ring_stage(unicycle_ring *ring, int k);
UNICYCLE_INTERNAL const unicycle_stage_slot *unicycle_ring_stage_const(const unicycle_ring *ring, int k);

/* One sampling interval: ring_head <- (ring_head + 1) mod N. */
UNICYCLE_INTERNAL void unicycle_ring_advance(unicycle_ring *ring);

/* The QP's block of the slot (Ht's lower triangle) from the lower triangle of the nw x nw
 * column-major A; A_dyn kept. */
UNICYCLE_INTERNAL void unicycle_ring_set_H(unicycle_stage_slot *slot, const unicycle_real *A);
/* A_dyn of the slot from the lower triangle of the nw x nw column-major A; the QP's block kept. */
UNICYCLE_INTERNAL void unicycle_ring_set_A_dyn(unicycle_stage_slot *slot, const unicycle_real *A);
/* A = A_dyn + A_l (nw x nw column-major, both triangles; A_dyn symmetric; A not the slot's). */
UNICYCLE_INTERNAL void unicycle_ring_add_A_dyn(const unicycle_stage_slot *slot, const unicycle_real *A_l, unicycle_real *A);
/* The QP's block of the slot = A_dyn + A_l (the lower triangle of A_l read), in place. */
UNICYCLE_INTERNAL void unicycle_ring_set_H_A_dyn(unicycle_stage_slot *slot, const unicycle_real *A_l);

/* Zero the step domega of a slot. */
UNICYCLE_INTERNAL void unicycle_ring_clear_step(unicycle_stage_slot *slot);

/* Round-off floor of the secant residual (docs/algorithm.md section 4 step 2). */
#define UNICYCLE_EPS_RHO UNICYCLE_PREC(1e-12, 1e-6)

/* Secant criterion rho_k (eq. 16) of the slot against the fresh F_new = (F_w, phi, g):
 *   num = | [F_w_old + Ht dw - Phit' dlam + Ct' dmu_g + dmu_b - F_w_new ;
 *            -(phi_old + Phit dw) + phi_new ;
 *            g_old + Ct dw - g_new] |
 *   rho = num / |(dw, dlam, dmu_g, dmu_b)| (2-norms), 0 when the denominator is 0 or
 *   num <= UNICYCLE_EPS_RHO * (|(F_w_old, phi_old, g_old)| + |(F_w_new, phi_new, g_new)|). */
UNICYCLE_INTERNAL unicycle_real unicycle_ring_secant(const unicycle_stage_slot *slot, const unicycle_real *F_w_new,
                                            const unicycle_real *phi_new, const unicycle_real *g_new);

/* The linear model's prediction of F at the point after the stored step (the value for which
 * unicycle_ring_secant's numerator is 0; Ht the QP's symmetric block, its lower triangle read):
 *   F_w = F_w_old + Ht dw - Phit' dlam + Ct' dmu_g + dmu_b, phi = phi_old + Phit dw,
 *   g = g_old + Ct dw
 * (an anytime prepare whose gradients are cut, docs/algorithm.md section 14). */
UNICYCLE_INTERNAL void unicycle_ring_predict(const unicycle_stage_slot *slot, unicycle_real *F_w, unicycle_real *phi,
                                       unicycle_real *g);

/* Store F_new as F_old. */
UNICYCLE_INTERNAL void unicycle_ring_store_F(unicycle_stage_slot *slot, const unicycle_real *F_w, const unicycle_real *phi,
                                       const unicycle_real *g);

#endif /* UNICYCLE_RING_H */
