/* The automatic, scale-aware, adaptive Levenberg-Marquardt term of the QP (docs/algorithm.md
 * section 10). The module owns its state (the term, the Hessian scale, the KKT proxy of the
 * previous prepare, the term before a cap) and takes the QP's blocks and measures as
 * arguments; the solver calls it at init, after each prepare, when the measurement is in the
 * QP, after each feedback and before each retry of a failed QP.
 *
 * The term lm is raised until the QP is convex on the dynamics (Riccati pivots of its
 * Hessian blocks positive definite), after a failed feedback and when the KKT proxy grows;
 * lowered after every successful feedback; capped by the distance from the solution once
 * the measurement is known. A fixed term (on = 0) is never changed.
 */
#ifndef ROBOT_ARM_LM_H
#define ROBOT_ARM_LM_H

#include "robot_arm_ring.h"

/* Constants, relative to the Hessian scale h = max(1e-300, largest |diagonal entry| of the
 * QP's blocks). */
#define ROBOT_ARM_LM_MIN_REL ROBOT_ARM_R(1e-8)    /* smallest nonzero term: 1e-8 h (below: 0) */
#define ROBOT_ARM_LM_MAX_REL ROBOT_ARM_R(1e2)     /* largest term: 1e2 h */
#define ROBOT_ARM_LM_RAISE ROBOT_ARM_R(10.0)      /* factor of a raise */
#define ROBOT_ARM_LM_LOWER ROBOT_ARM_R(0.1)       /* factor after a successful feedback */
#define ROBOT_ARM_LM_PIVOT_REL ROBOT_ARM_R(1e-10) /* Riccati pivots must exceed 1e-10 h */
/* ... and their round-off: nw double rounding units (2^-52) of the stage's largest |Z_uu diagonal
 * entry|, the double's in both precisions as the limits above (the float's would raise the floor
 * to about 1e-6 h on the robot arm's QPs, the raise docs/algorithm.md section 11 rejected) */
#define ROBOT_ARM_LM_ROUNDOFF (ROBOT_ARM_NW * ROBOT_ARM_R(2.220446049250313080847263336181640625e-16))
#define ROBOT_ARM_LM_KKT_GROWTH ROBOT_ARM_R(10.0) /* raise when the KKT proxy grows 10x in one prepare */
#define ROBOT_ARM_LM_RETRIES 2                /* QP solves again with lm raised after a failure */
#define ROBOT_ARM_LM_KKT_REL ROBOT_ARM_R(1e-2)    /* feedback: lm <= 1e-2 h d^2, d the distance from the solution */

/* Scratch of the convexity test (P, P Phi and the condensed block). */
#define ROBOT_ARM_LM_WORK (ROBOT_ARM_NX * ROBOT_ARM_NX + ROBOT_ARM_NX * ROBOT_ARM_NW + ROBOT_ARM_NW * ROBOT_ARM_NW)

typedef struct {
    robot_arm_real lm;       /* the term of the next QP */
    robot_arm_real scale;    /* Hessian scale h */
    robot_arm_real kkt_prev; /* KKT proxy of the previous prepare (< 0: none since the start) */
    robot_arm_real uncapped; /* the term before the cap of this feedback (< 0: not capped) */
    int on;              /* 1: automatic; 0: the fixed term lm */
    int held;            /* 1: the last prepare's convexity test raised the term (the stall test) */
    /* the convexity test when set (the solver's prepare, when the feedback's QP may reuse it:
     * the QP's own factorisation, robot_arm_qp_prefactor; set around that call and NULL between
     * calls): test(test_ctx, lm, tol) with the pivot floor tol = ROBOT_ARM_LM_PIVOT_REL h and
     * the round-off ROBOT_ARM_LM_ROUNDOFF, the work argument then unused; NULL (robot_arm_lm_reset): the
     * recursion of robot_arm_lm.c in work */
    int (*test)(void *test_ctx, robot_arm_real lm, robot_arm_real tol);
    void *test_ctx;
} robot_arm_lm;

#ifndef ROBOT_ARM_INTERNAL
#define ROBOT_ARM_INTERNAL
#endif

/* A fixed term (on = 0, lm = fixed) or the automatic one (on = 1, lm = 0 until started). */
ROBOT_ARM_INTERNAL void robot_arm_lm_reset(robot_arm_lm *lm, int on, robot_arm_real fixed);
/* At init or a re-initialisation (QP assembled): the scale, lm from 0 raised until convex.
 * ring: the stage blocks, A_N the terminal block (nx x nx, lower triangle read). */
ROBOT_ARM_INTERNAL void robot_arm_lm_start(robot_arm_lm *lm, const robot_arm_ring *ring, const robot_arm_real *A_N,
                                   robot_arm_real *work);
/* After a prepare (QP assembled, KKT proxy evaluated): the scale, a raise when the proxy grew
 * ROBOT_ARM_LM_KKT_GROWTH times (proxy_ref: the proxy at the last init, a floor of the growth
 * test), then raised until convex; held = 1 when that last test raised the term (the decay of
 * the feedback undone: the term held up by the test, docs/algorithm.md section 9). */
ROBOT_ARM_INTERNAL void robot_arm_lm_prepared(robot_arm_lm *lm, const robot_arm_ring *ring, const robot_arm_real *A_N,
                                      robot_arm_real kkt_proxy, robot_arm_real proxy_ref, robot_arm_real *work);
/* Feedback, once the measurement is in the QP: the term capped by ROBOT_ARM_LM_KKT_REL h d^2 with
 * d = max(kkt_proxy, max_i |dx0_i| / scale_x_i) (0 below ROBOT_ARM_LM_MIN_REL h). */
ROBOT_ARM_INTERNAL void robot_arm_lm_measured(robot_arm_lm *lm, const robot_arm_real *dx0, const robot_arm_real *scale_x,
                                      robot_arm_real kkt_proxy);
/* After a feedback: lowered after a step (solved = 1), raised after a failed QP or a
 * divergence (solved = 0). */
ROBOT_ARM_INTERNAL void robot_arm_lm_feedback(robot_arm_lm *lm, int solved);
/* 1 when a failed QP may be solved again with the term raised (automatic, below the
 * maximum); then robot_arm_lm_raise. */
ROBOT_ARM_INTERNAL int robot_arm_lm_can_raise(const robot_arm_lm *lm);
ROBOT_ARM_INTERNAL void robot_arm_lm_raise(robot_arm_lm *lm);
/* Feedback, once the measurement is in the QP: 1 when the automatic term is within one raise
 * step of convex (docs/algorithm.md section 4, feedback): the term below its maximum and, when
 * this feedback capped it, the QP convex on the dynamics with the capped term raised once
 * (to ROBOT_ARM_LM_MIN_REL h from below it, else times ROBOT_ARM_LM_RAISE). The prepare's test
 * certifies that when the raised term is at least the prepared one; else one convexity test
 * at the raised term decides (work: ROBOT_ARM_LM_WORK reals). 0 for a fixed term. */
ROBOT_ARM_INTERNAL int robot_arm_lm_near_convex(const robot_arm_lm *lm, const robot_arm_ring *ring, const robot_arm_real *A_N,
                                        robot_arm_real *work);

#endif /* ROBOT_ARM_LM_H */
