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
#ifndef UNICYCLE_LM_H
#define UNICYCLE_LM_H

#include "unicycle_ring.h"

/* Constants, relative to the Hessian scale h = max(1e-300, largest |diagonal entry| of the
 * QP's blocks). */
#define UNICYCLE_LM_MIN_REL UNICYCLE_R(1e-8)    /* smallest nonzero term: 1e-8 h (below: 0) */
#define UNICYCLE_LM_MAX_REL UNICYCLE_R(1e2)     /* largest term: 1e2 h */
#define UNICYCLE_LM_RAISE UNICYCLE_R(10.0)      /* factor of a raise */
#define UNICYCLE_LM_LOWER UNICYCLE_R(0.1)       /* factor after a successful feedback */
#define UNICYCLE_LM_PIVOT_REL UNICYCLE_R(1e-10) /* Riccati pivots must exceed 1e-10 h */
/* ... and their round-off: nw double rounding units (2^-52) of the stage's largest |Z_uu diagonal
 * entry|, the double's in both precisions as the limits above (the float's would raise the floor
 * to about 1e-6 h on the robot arm's QPs, the raise docs/algorithm.md section 11 rejected) */
#define UNICYCLE_LM_ROUNDOFF (UNICYCLE_NW * UNICYCLE_R(2.220446049250313080847263336181640625e-16))
#define UNICYCLE_LM_KKT_GROWTH UNICYCLE_R(10.0) /* raise when the KKT proxy grows 10x in one prepare */
#define UNICYCLE_LM_RETRIES 2                /* QP solves again with lm raised after a failure */
#define UNICYCLE_LM_KKT_REL UNICYCLE_R(1e-2)    /* feedback: lm <= 1e-2 h d^2, d the distance from the solution */

/* Scratch of the convexity test (P, P Phi and the condensed block). */
#define UNICYCLE_LM_WORK (UNICYCLE_NX * UNICYCLE_NX + UNICYCLE_NX * UNICYCLE_NW + UNICYCLE_NW * UNICYCLE_NW)

typedef struct {
    unicycle_real lm;       /* the term of the next QP */
    unicycle_real scale;    /* Hessian scale h */
    unicycle_real kkt_prev; /* KKT proxy of the previous prepare (< 0: none since the start) */
    unicycle_real uncapped; /* the term before the cap of this feedback (< 0: not capped) */
    int on;              /* 1: automatic; 0: the fixed term lm */
    int held;            /* 1: the last prepare's convexity test raised the term (the stall test) */
    /* the convexity test when set (the solver's prepare, when the feedback's QP may reuse it:
     * the QP's own factorisation, unicycle_qp_prefactor; set around that call and NULL between
     * calls): test(test_ctx, lm, tol) with the pivot floor tol = UNICYCLE_LM_PIVOT_REL h and
     * the round-off UNICYCLE_LM_ROUNDOFF, the work argument then unused; NULL (unicycle_lm_reset): the
     * recursion of unicycle_lm.c in work */
    int (*test)(void *test_ctx, unicycle_real lm, unicycle_real tol);
    void *test_ctx;
} unicycle_lm;

#ifndef UNICYCLE_INTERNAL
#define UNICYCLE_INTERNAL
#endif

/* A fixed term (on = 0, lm = fixed) or the automatic one (on = 1, lm = 0 until started). */
UNICYCLE_INTERNAL void unicycle_lm_reset(unicycle_lm *lm, int on, unicycle_real fixed);
/* At init or a re-initialisation (QP assembled): the scale, lm from 0 raised until convex.
 * ring: the stage blocks, A_N the terminal block (nx x nx, lower triangle read). */
UNICYCLE_INTERNAL void unicycle_lm_start(unicycle_lm *lm, const unicycle_ring *ring, const unicycle_real *A_N,
                                   unicycle_real *work);
/* After a prepare (QP assembled, KKT proxy evaluated): the scale, a raise when the proxy grew
 * UNICYCLE_LM_KKT_GROWTH times (proxy_ref: the proxy at the last init, a floor of the growth
 * test), then raised until convex; held = 1 when that last test raised the term (the decay of
 * the feedback undone: the term held up by the test, docs/algorithm.md section 9). */
UNICYCLE_INTERNAL void unicycle_lm_prepared(unicycle_lm *lm, const unicycle_ring *ring, const unicycle_real *A_N,
                                      unicycle_real kkt_proxy, unicycle_real proxy_ref, unicycle_real *work);
/* Feedback, once the measurement is in the QP: the term capped by UNICYCLE_LM_KKT_REL h d^2 with
 * d = max(kkt_proxy, max_i |dx0_i| / scale_x_i) (0 below UNICYCLE_LM_MIN_REL h). */
UNICYCLE_INTERNAL void unicycle_lm_measured(unicycle_lm *lm, const unicycle_real *dx0, const unicycle_real *scale_x,
                                      unicycle_real kkt_proxy);
/* After a feedback: lowered after a step (solved = 1), raised after a failed QP or a
 * divergence (solved = 0). */
UNICYCLE_INTERNAL void unicycle_lm_feedback(unicycle_lm *lm, int solved);
/* 1 when a failed QP may be solved again with the term raised (automatic, below the
 * maximum); then unicycle_lm_raise. */
UNICYCLE_INTERNAL int unicycle_lm_can_raise(const unicycle_lm *lm);
UNICYCLE_INTERNAL void unicycle_lm_raise(unicycle_lm *lm);
/* Feedback, once the measurement is in the QP: 1 when the automatic term is within one raise
 * step of convex (docs/algorithm.md section 4, feedback): the term below its maximum and, when
 * this feedback capped it, the QP convex on the dynamics with the capped term raised once
 * (to UNICYCLE_LM_MIN_REL h from below it, else times UNICYCLE_LM_RAISE). The prepare's test
 * certifies that when the raised term is at least the prepared one; else one convexity test
 * at the raised term decides (work: UNICYCLE_LM_WORK reals). 0 for a fixed term. */
UNICYCLE_INTERNAL int unicycle_lm_near_convex(const unicycle_lm *lm, const unicycle_ring *ring, const unicycle_real *A_N,
                                        unicycle_real *work);

#endif /* UNICYCLE_LM_H */
