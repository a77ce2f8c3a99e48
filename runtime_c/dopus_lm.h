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
#ifndef DOPUS_LM_H
#define DOPUS_LM_H

#include "dopus_ring.h"

/* Constants, relative to the Hessian scale h = max(1e-300, largest |diagonal entry| of the
 * QP's blocks). */
#define DOPUS_LM_MIN_REL DOPUS_R(1e-8)    /* smallest nonzero term: 1e-8 h (below: 0) */
#define DOPUS_LM_MAX_REL DOPUS_R(1e2)     /* largest term: 1e2 h */
#define DOPUS_LM_RAISE DOPUS_R(10.0)      /* factor of a raise */
#define DOPUS_LM_LOWER DOPUS_R(0.1)       /* factor after a successful feedback */
#define DOPUS_LM_PIVOT_REL DOPUS_R(1e-10) /* Riccati pivots must exceed 1e-10 h */
/* ... and their round-off: nw double rounding units (2^-52) of the stage's largest |Z_uu diagonal
 * entry|, the double's in both precisions as the limits above (the float's would raise the floor
 * to about 1e-6 h on the robot arm's QPs, the raise docs/algorithm.md section 11 rejected) */
#define DOPUS_LM_ROUNDOFF (DOPUS_NW * DOPUS_R(2.220446049250313080847263336181640625e-16))
#define DOPUS_LM_KKT_GROWTH DOPUS_R(10.0) /* raise when the KKT proxy grows 10x in one prepare */
#define DOPUS_LM_RETRIES 2                /* QP solves again with lm raised after a failure */
#define DOPUS_LM_KKT_REL DOPUS_R(1e-2)    /* feedback: lm <= 1e-2 h d^2, d the distance from the solution */

/* Scratch of the convexity test (P, P Phi and the condensed block). */
#define DOPUS_LM_WORK (DOPUS_NX * DOPUS_NX + DOPUS_NX * DOPUS_NW + DOPUS_NW * DOPUS_NW)

typedef struct {
    dopus_real lm;       /* the term of the next QP */
    dopus_real scale;    /* Hessian scale h */
    dopus_real kkt_prev; /* KKT proxy of the previous prepare (< 0: none since the start) */
    dopus_real uncapped; /* the term before the cap of this feedback (< 0: not capped) */
    int on;              /* 1: automatic; 0: the fixed term lm */
    int held;            /* 1: the last prepare's convexity test raised the term (the stall test) */
    /* the convexity test when set (the solver's prepare, when the feedback's QP may reuse it:
     * the QP's own factorisation, dopus_qp_prefactor; set around that call and NULL between
     * calls): test(test_ctx, lm, tol) with the pivot floor tol = DOPUS_LM_PIVOT_REL h and
     * the round-off DOPUS_LM_ROUNDOFF, the work argument then unused; NULL (dopus_lm_reset): the
     * recursion of dopus_lm.c in work */
    int (*test)(void *test_ctx, dopus_real lm, dopus_real tol);
    void *test_ctx;
} dopus_lm;

#ifndef DOPUS_INTERNAL
#define DOPUS_INTERNAL
#endif

/* A fixed term (on = 0, lm = fixed) or the automatic one (on = 1, lm = 0 until started). */
DOPUS_INTERNAL void dopus_lm_reset(dopus_lm *lm, int on, dopus_real fixed);
/* At init or a re-initialisation (QP assembled): the scale, lm from 0 raised until convex.
 * ring: the stage blocks, A_N the terminal block (nx x nx, lower triangle read). */
DOPUS_INTERNAL void dopus_lm_start(dopus_lm *lm, const dopus_ring *ring, const dopus_real *A_N,
                                   dopus_real *work);
/* After a prepare (QP assembled, KKT proxy evaluated): the scale, a raise when the proxy grew
 * DOPUS_LM_KKT_GROWTH times (proxy_ref: the proxy at the last init, a floor of the growth
 * test), then raised until convex; held = 1 when that last test raised the term (the decay of
 * the feedback undone: the term held up by the test, docs/algorithm.md section 9). */
DOPUS_INTERNAL void dopus_lm_prepared(dopus_lm *lm, const dopus_ring *ring, const dopus_real *A_N,
                                      dopus_real kkt_proxy, dopus_real proxy_ref, dopus_real *work);
/* Feedback, once the measurement is in the QP: the term capped by DOPUS_LM_KKT_REL h d^2 with
 * d = max(kkt_proxy, max_i |dx0_i| / scale_x_i) (0 below DOPUS_LM_MIN_REL h). */
DOPUS_INTERNAL void dopus_lm_measured(dopus_lm *lm, const dopus_real *dx0, const dopus_real *scale_x,
                                      dopus_real kkt_proxy);
/* After a feedback: lowered after a step (solved = 1), raised after a failed QP or a
 * divergence (solved = 0). */
DOPUS_INTERNAL void dopus_lm_feedback(dopus_lm *lm, int solved);
/* 1 when a failed QP may be solved again with the term raised (automatic, below the
 * maximum); then dopus_lm_raise. */
DOPUS_INTERNAL int dopus_lm_can_raise(const dopus_lm *lm);
DOPUS_INTERNAL void dopus_lm_raise(dopus_lm *lm);
/* Feedback, once the measurement is in the QP: 1 when the automatic term is within one raise
 * step of convex (docs/algorithm.md section 4, feedback): the term below its maximum and, when
 * this feedback capped it, the QP convex on the dynamics with the capped term raised once
 * (to DOPUS_LM_MIN_REL h from below it, else times DOPUS_LM_RAISE). The prepare's test
 * certifies that when the raised term is at least the prepared one; else one convexity test
 * at the raised term decides (work: DOPUS_LM_WORK reals). 0 for a fixed term. */
DOPUS_INTERNAL int dopus_lm_near_convex(const dopus_lm *lm, const dopus_ring *ring, const dopus_real *A_N,
                                        dopus_real *work);

#endif /* DOPUS_LM_H */
