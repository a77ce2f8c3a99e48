/* Health of the controller (docs/algorithm.md section 9): the scales of the divergence test,
 * the box test and the KKT proxy of an iterate, the control clipped to its bounds, and the
 * state of the safe outputs and the automatic recovery (the last good plan, the fallback
 * control, the count of failed feedbacks). The predicates take the iterate and the blocks
 * as arguments; the solver decides what to do with their answers.
 */
#ifndef ROBOT_ARM_HEALTH_H
#define ROBOT_ARM_HEALTH_H

#include "robot_arm_ring.h"

/* Constants (docs/algorithm.md section 9). */
#define ROBOT_ARM_DIVERGENCE_BOX ROBOT_ARM_R(1e3) /* |x_k,i| <= 1e3 scale_x_i + |xhat0_i|, same for u */
#define ROBOT_ARM_DIVERGENCE_KKT ROBOT_ARM_R(1e6) /* kkt proxy <= 1e6 max(1, proxy at the last init) */
#define ROBOT_ARM_STALL_KKT ROBOT_ARM_R(1e3)      /* a stalled prepare: proxy > 1e3 max(1, proxy at init) */
#define ROBOT_ARM_STALL_PREPARES 10           /* ... in so many prepares in a row: escalate */
#define ROBOT_ARM_FLAT_KKT ROBOT_ARM_R(5.0)       /* a flat prepare: proxy > 5 max(1, proxy at init) ... */
#define ROBOT_ARM_FLAT_DROP ROBOT_ARM_R(0.5)      /* ... not below 0.5 times the proxy the stretch began with */
#define ROBOT_ARM_FLAT_PREPARES 20            /* ... in so many prepares in a row: escalate */
#define ROBOT_ARM_FLAT_HELD_KKT ROBOT_ARM_R(1.0)  /* flat too: proxy > 1 max(1, proxy at init), lm held up */

typedef struct {
    int n_failed;                         /* consecutive failed feedbacks */
    int recover_pending;                  /* the next prepare re-initialises */
    int flags;                            /* ROBOT_ARM_FLAG_* of the last feedback + prepare */
    int n_recoveries;                     /* re-initialisations since init */
    int recovering;                       /* full-RTI prepares left after a recovery */
    int xhat_fresh;                       /* the last feedback had a finite measurement */
    int plan_age;                         /* receding shifts since the last good plan */
    robot_arm_real plan_u[ROBOT_ARM_N][ROBOT_ARM_NU]; /* controls of the last good plan */
    robot_arm_real u0_out[ROBOT_ARM_NU];          /* the control returned by the last feedback */
    robot_arm_real scale_x[ROBOT_ARM_NX];         /* scales of the box test */
    robot_arm_real scale_u[ROBOT_ARM_NU];
    robot_arm_real kkt_proxy;      /* divergence measure of the last prepare or init */
    robot_arm_real kkt_proxy_ref;  /* ... at the last init or re-initialisation */
    robot_arm_real kkt_proxy_init; /* ... at the last init (the stall test) */
    int n_stalled;             /* prepares in a row with a stalled KKT proxy */
    robot_arm_real kkt_flat_ref;   /* the proxy a stretch of flat prepares began with */
    int n_flat;                /* prepares in that stretch */
    int n_gated;               /* measurements in a row held out by the gate */
    int gate_rest;             /* measurements left that the gate lets pass unchecked */
} robot_arm_health;

#ifndef ROBOT_ARM_INTERNAL
#define ROBOT_ARM_INTERNAL
#endif

/* The scale of each state and control: the largest magnitude among its finite bounds, the
 * OCP file's guess, the default x0 and 1. */
ROBOT_ARM_INTERNAL void robot_arm_health_scales(robot_arm_health *h);
/* No failure, no flag; the plan is u (N x nu) and u0 its first control. */
ROBOT_ARM_INTERNAL void robot_arm_health_reset(robot_arm_health *h, const robot_arm_real *u);
/* u (nu) clipped to the control bounds into out (NaN: 0 clipped to the bounds); returns 1
 * when an entry changed. */
ROBOT_ARM_INTERNAL int robot_arm_clip_u(const robot_arm_real *u, robot_arm_real *out);
/* The box test of one node (x nx, u nu, each NULL: not tested) plus an optional step (dx, du;
 * NULL: none): every entry finite and inside the box of robot_arm_box_ok. Returns 1 when it passes. */
ROBOT_ARM_INTERNAL int robot_arm_box_node_ok(const robot_arm_health *h, const robot_arm_real *xhat0, const robot_arm_real *x,
                                     const robot_arm_real *dx, const robot_arm_real *u, const robot_arm_real *du);
/* The box test of a primal point (x (N+1) x nx, u N x nu, row-major) given as x, u plus an
 * optional step (dx with row stride dx_stride, du with du_stride; NULL: none): every entry
 * finite and |v_i| <= BOX scale_x_i + |xhat0_i| (states), BOX scale_u_i (controls). Returns 1
 * when it passes. */
ROBOT_ARM_INTERNAL int robot_arm_box_ok(const robot_arm_health *h, const robot_arm_real *xhat0, const robot_arm_real *x,
                                const robot_arm_real *dx, int dx_stride, const robot_arm_real *u,
                                const robot_arm_real *du, int du_stride);
/* Divergence measure of a point from the F values in the slots and the terminal node:
 * max of |F_w,k + [lam_k; 0]|, |gL_N + mu_bN + lam_N|, |phi_k - x_{k+1}|, |r_eq| (inf-norms;
 * NaN propagates). */
ROBOT_ARM_INTERNAL robot_arm_real robot_arm_kkt_proxy(const robot_arm_ring *ring, const robot_arm_real *x, const robot_arm_real *lam,
                                          const robot_arm_real *gL_N, const robot_arm_real *mu_bN,
                                          const robot_arm_real *r_eq);
/* The divergence test of a prepared iterate: the box, finite multipliers, h->kkt_proxy
 * <= DIVERGENCE_KKT max(1, h->kkt_proxy_ref). Returns 1 when it diverged. */
ROBOT_ARM_INTERNAL int robot_arm_diverged(const robot_arm_health *h, const robot_arm_real *xhat0, const robot_arm_real *x,
                                  const robot_arm_real *u, const robot_arm_real *lam, const robot_arm_real *mu_b,
                                  const robot_arm_real *mu_bN);
/* The stall test of a prepared iterate (docs/algorithm.md section 9), outside a recovery
 * phase: h->kkt_proxy > STALL_KKT max(1, h->kkt_proxy_init) in STALL_PREPARES prepares in a
 * row, or flat (> FLAT_KKT max(1, h->kkt_proxy_init), or > FLAT_HELD_KKT max(1,
 * h->kkt_proxy_init) with lm_held: the prepare's convexity test raised the automatic
 * Levenberg-Marquardt term) and not below FLAT_DROP times the proxy the stretch began with in
 * FLAT_PREPARES prepares in a row (no progress), begins a recovery phase of `phase` feedbacks
 * without a re-initialisation. Returns 1 when it did. */
ROBOT_ARM_INTERNAL int robot_arm_health_stalled(robot_arm_health *h, int phase, int lm_held);
/* The control of the last good plan for the instant k sampling instants from now (its age
 * plus k, the last control beyond the plan's end). */
ROBOT_ARM_INTERNAL const robot_arm_real *robot_arm_health_plan_control(const robot_arm_health *h, int k);
/* The fallback control of a failed feedback: the control of the last good plan for this
 * instant (plan_age shifts on in receding mode, else the first), clipped, into u0_out and
 * u0 (may be NULL). Returns 1 when it was clipped. */
ROBOT_ARM_INTERNAL int robot_arm_health_fallback(robot_arm_health *h, int receding, robot_arm_real *u0);
/* A good step: no failure, the plan is u (N x nu), u0_out its first control clipped, copied
 * to u0 (may be NULL). Returns 1 when it was clipped. */
ROBOT_ARM_INTERNAL int robot_arm_health_keep_plan(robot_arm_health *h, const robot_arm_real *u, robot_arm_real *u0);

#endif /* ROBOT_ARM_HEALTH_H */
