/* The ring buffer of stage slots (docs/design.md section 5, docs/algorithm.md section 4).
 *
 * Stage k lives in slot (ring_head + k) mod N. The receding-horizon shift advances
 * ring_head, so the sensitivities of stage k+1 become those of stage k without a copy and
 * the slot that falls off the front becomes the new last stage. The QP reads Ht, Phit, Ct
 * in place through per-stage pointer tables.
 */
#ifndef ROBOT_ARM_RING_H
#define ROBOT_ARM_RING_H

#include "robot_arm_sizes.h"

typedef struct {
    /* the blocks the QP uses (possibly outdated, A regularised), column-major. Ht (nw x nw)
     * holds two symmetric matrices: its lower triangle with the diagonal is the QP's block
     * (the QP reads only that, robot_arm_qp.h), its strict upper triangle the strict lower
     * triangle of A_dyn = A - A_l of the last H evaluation (unregularised: the curvature of
     * dynamics and path constraints, to which step 5 of prepare adds a fresh stage-cost A_l),
     * A_dyn(i, j) for i > j at Ht[j + i nw]; A_dyn_diag its diagonal
     * (robot_arm_ring_set_H, robot_arm_ring_set_A_dyn) */
    robot_arm_real Ht[ROBOT_ARM_NW * ROBOT_ARM_NW];
    robot_arm_real A_dyn_diag[ROBOT_ARM_NW];
    robot_arm_real Phit[ROBOT_ARM_NX * ROBOT_ARM_NW];          /* nx x nw, [A_k B_k] */
    robot_arm_real Ct[ROBOT_ARM_DIM(ROBOT_ARM_NG * ROBOT_ARM_NW)]; /* ng x nw (leading dimension ng) */
    /* F_old = (F_w, phi, g) of the last gradient evaluation of this stage (eq. 14) */
    robot_arm_real F_w[ROBOT_ARM_NW];
    robot_arm_real phi[ROBOT_ARM_NX];
    robot_arm_real g[ROBOT_ARM_DIM(ROBOT_ARM_NG)];
    /* domega = (dw, dlam_next, dmu_g, dmu_b): the last QP step of this stage */
    robot_arm_real dw[ROBOT_ARM_NW];
    robot_arm_real dlam[ROBOT_ARM_NX];
    robot_arm_real dmu_g[ROBOT_ARM_DIM(ROBOT_ARM_NG)];
    robot_arm_real dmu_b[ROBOT_ARM_NW];
    /* the steps dw since the last gradient evaluation of this stage, summed: how far its
     * linear model's point has moved from the evaluation point (the order of an anytime
     * prepare's gradients, algorithm.md section 14) */
    robot_arm_real dw_acc[ROBOT_ARM_NW];
} robot_arm_stage_slot;

typedef struct {
    robot_arm_stage_slot slot[ROBOT_ARM_N];
    int ring_head;
} robot_arm_ring;

#ifndef ROBOT_ARM_INTERNAL
#define ROBOT_ARM_INTERNAL
#endif

/* head = 0, every slot zero. */
ROBOT_ARM_INTERNAL void robot_arm_ring_reset(robot_arm_ring *ring);

/* The slot of stage k (0 <= k < N). */
ROBOT_ARM_INTERNAL robot_arm_stage_slot *robot_arm_ring_stage(robot_arm_ring *ring, int k);
ROBOT_ARM_INTERNAL const robot_arm_stage_slot *robot_arm_ring_stage_const(const robot_arm_ring *ring, int k);

/* One sampling interval: ring_head <- (ring_head + 1) mod N. */
ROBOT_ARM_INTERNAL void robot_arm_ring_advance(robot_arm_ring *ring);

/* The QP's block of the slot (Ht's lower triangle) from the lower triangle of the nw x nw
 * column-major A; A_dyn kept. */
ROBOT_ARM_INTERNAL void robot_arm_ring_set_H(robot_arm_stage_slot *slot, const robot_arm_real *A);
/* A_dyn of the slot from the lower triangle of the nw x nw column-major A; the QP's block kept. */
ROBOT_ARM_INTERNAL void robot_arm_ring_set_A_dyn(robot_arm_stage_slot *slot, const robot_arm_real *A);
/* A = A_dyn + A_l (nw x nw column-major, both triangles; A_dyn symmetric; A not the slot's). */
ROBOT_ARM_INTERNAL void robot_arm_ring_add_A_dyn(const robot_arm_stage_slot *slot, const robot_arm_real *A_l, robot_arm_real *A);
/* The QP's block of the slot = A_dyn + A_l (the lower triangle of A_l read), in place. */
ROBOT_ARM_INTERNAL void robot_arm_ring_set_H_A_dyn(robot_arm_stage_slot *slot, const robot_arm_real *A_l);

/* Zero the step domega of a slot. */
ROBOT_ARM_INTERNAL void robot_arm_ring_clear_step(robot_arm_stage_slot *slot);

/* Round-off floor of the secant residual (docs/algorithm.md section 4 step 2). */
#define ROBOT_ARM_EPS_RHO ROBOT_ARM_PREC(1e-12, 1e-6)

/* Secant criterion rho_k (eq. 16) of the slot against the fresh F_new = (F_w, phi, g):
 *   num = | [F_w_old + Ht dw - Phit' dlam + Ct' dmu_g + dmu_b - F_w_new ;
 *            -(phi_old + Phit dw) + phi_new ;
 *            g_old + Ct dw - g_new] |
 *   rho = num / |(dw, dlam, dmu_g, dmu_b)| (2-norms), 0 when the denominator is 0 or
 *   num <= ROBOT_ARM_EPS_RHO * (|(F_w_old, phi_old, g_old)| + |(F_w_new, phi_new, g_new)|). */
ROBOT_ARM_INTERNAL robot_arm_real robot_arm_ring_secant(const robot_arm_stage_slot *slot, const robot_arm_real *F_w_new,
                                            const robot_arm_real *phi_new, const robot_arm_real *g_new);

/* The linear model's prediction of F at the point after the stored step (the value for which
 * robot_arm_ring_secant's numerator is 0; Ht the QP's symmetric block, its lower triangle read):
 *   F_w = F_w_old + Ht dw - Phit' dlam + Ct' dmu_g + dmu_b, phi = phi_old + Phit dw,
 *   g = g_old + Ct dw
 * (an anytime prepare whose gradients are cut, docs/algorithm.md section 14). */
ROBOT_ARM_INTERNAL void robot_arm_ring_predict(const robot_arm_stage_slot *slot, robot_arm_real *F_w, robot_arm_real *phi,
                                       robot_arm_real *g);

/* Store F_new as F_old. */
ROBOT_ARM_INTERNAL void robot_arm_ring_store_F(robot_arm_stage_slot *slot, const robot_arm_real *F_w, const robot_arm_real *phi,
                                       const robot_arm_real *g);

#endif /* ROBOT_ARM_RING_H */
