/* Wrappers around the CasADi-generated per-stage functions (docs/algorithm.md section 2).
 *
 * The definitions are generated (robot_arm_funcs.c) because they call the CasADi functions by
 * their problem-specific names; the runtime only sees these fixed signatures. Every call uses
 * a caller-supplied work struct, so the generated code holds no static state and two solvers
 * (or two threads) never share scratch memory.
 *
 * Matrices are dense column-major (Phi: nx x nw, A: nw x nw, C: ng x nw, R: nr x nx,
 * R_eq: ne x nx). Inputs and outputs of size zero may be pointers to 1-element dummies.
 * Every function returns 0 on success and nonzero if the CasADi function reported failure.
 */
#ifndef ROBOT_ARM_FUNCS_H
#define ROBOT_ARM_FUNCS_H

#include "robot_arm_sizes.h"

typedef struct robot_arm_fun_work_s {
    int iw[ROBOT_ARM_SZ_IW];
    robot_arm_real w[ROBOT_ARM_SZ_W];
    const robot_arm_real *arg[ROBOT_ARM_SZ_ARG];
    robot_arm_real *res[ROBOT_ARM_SZ_RES];
} robot_arm_fun_work;

#ifndef ROBOT_ARM_INTERNAL
#define ROBOT_ARM_INTERNAL
#endif

/* stage_eval: phi (nx), l (1), g (ng) */
ROBOT_ARM_INTERNAL int robot_arm_eval_stage_eval(const robot_arm_real *x, const robot_arm_real *u, const robot_arm_real *p,
                                         robot_arm_real *phi, robot_arm_real *l, robot_arm_real *g, robot_arm_fun_work *wk);

/* stage_grad, F_k of eq. 14: gL = grad_w l - Phi' lam_next + C' mu_g, plus phi, l, g */
ROBOT_ARM_INTERNAL int robot_arm_eval_stage_grad(const robot_arm_real *x, const robot_arm_real *u, const robot_arm_real *p,
                                         const robot_arm_real *lam_next, const robot_arm_real *mu_g, robot_arm_real *gL,
                                         robot_arm_real *phi, robot_arm_real *l, robot_arm_real *g, robot_arm_fun_work *wk);

/* stage_hess, H_k of eq. 15: A (nw x nw), Phi (nx x nw), C (ng x nw).
 * gauss_newton != 0 selects the Gauss-Newton A; nonzero return if !ROBOT_ARM_HAS_GN then. */
ROBOT_ARM_INTERNAL int robot_arm_eval_stage_hess(int gauss_newton, const robot_arm_real *x, const robot_arm_real *u,
                                         const robot_arm_real *p, const robot_arm_real *lam_next,
                                         const robot_arm_real *mu_g, robot_arm_real *A, robot_arm_real *Phi,
                                         robot_arm_real *C, robot_arm_fun_work *wk);

/* stage_grad and stage_hess in one call (one generated function sharing what the two compute
 * in common, stage_grad_hess_exact or _gn): gL, phi, l, g as robot_arm_eval_stage_grad, A, Phi, C
 * as robot_arm_eval_stage_hess with the same gauss_newton (nonzero return if !ROBOT_ARM_HAS_GN then) */
ROBOT_ARM_INTERNAL int robot_arm_eval_stage_grad_hess(int gauss_newton, const robot_arm_real *x, const robot_arm_real *u,
                                              const robot_arm_real *p, const robot_arm_real *lam_next,
                                              const robot_arm_real *mu_g, robot_arm_real *gL, robot_arm_real *phi,
                                              robot_arm_real *l, robot_arm_real *g, robot_arm_real *A, robot_arm_real *Phi,
                                              robot_arm_real *C, robot_arm_fun_work *wk);

/* stage_hess_cost: A_l (nw x nw), the stage-cost part of A (docs/algorithm.md section 4
 * step 5): exact hess_w l, or with gauss_newton != 0 J' W J + hess_w l_extra (nonzero
 * return if !ROBOT_ARM_HAS_GN then). No integrator: l is evaluated at the node. */
ROBOT_ARM_INTERNAL int robot_arm_eval_stage_hess_cost(int gauss_newton, const robot_arm_real *x, const robot_arm_real *u,
                                              const robot_arm_real *p, robot_arm_real *A_l, robot_arm_fun_work *wk);

/* term_eval: E (1), r (nr), r_eq (ne) */
ROBOT_ARM_INTERNAL int robot_arm_eval_term_eval(const robot_arm_real *x, const robot_arm_real *p, robot_arm_real *E,
                                        robot_arm_real *r, robot_arm_real *r_eq, robot_arm_fun_work *wk);

/* term_grad: gL = grad E + R' mu_r + R_eq' nu, plus E, r, r_eq */
ROBOT_ARM_INTERNAL int robot_arm_eval_term_grad(const robot_arm_real *x, const robot_arm_real *p, const robot_arm_real *mu_r,
                                        const robot_arm_real *nu, robot_arm_real *gL, robot_arm_real *E, robot_arm_real *r,
                                        robot_arm_real *r_eq, robot_arm_fun_work *wk);

/* term_hess: A (nx x nx), R (nr x nx), R_eq (ne x nx); always available (no GN restriction) */
ROBOT_ARM_INTERNAL int robot_arm_eval_term_hess(int gauss_newton, const robot_arm_real *x, const robot_arm_real *p,
                                        const robot_arm_real *mu_r, const robot_arm_real *nu, robot_arm_real *A,
                                        robot_arm_real *R, robot_arm_real *R_eq, robot_arm_fun_work *wk);

/* ode: continuous model xdot = f(x, u, p) */
ROBOT_ARM_INTERNAL int robot_arm_eval_ode(const robot_arm_real *x, const robot_arm_real *u, const robot_arm_real *p,
                                  robot_arm_real *xdot, robot_arm_fun_work *wk);

#endif /* ROBOT_ARM_FUNCS_H */
