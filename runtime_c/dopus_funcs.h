/* Wrappers around the CasADi-generated per-stage functions (docs/algorithm.md section 2).
 *
 * The definitions are generated (dopus_funcs.c) because they call the CasADi functions by
 * their problem-specific names; the runtime only sees these fixed signatures. Every call uses
 * a caller-supplied work struct, so the generated code holds no static state and two solvers
 * (or two threads) never share scratch memory.
 *
 * Matrices are dense column-major (Phi: nx x nw, A: nw x nw, C: ng x nw, R: nr x nx,
 * R_eq: ne x nx). Inputs and outputs of size zero may be pointers to 1-element dummies.
 * Every function returns 0 on success and nonzero if the CasADi function reported failure.
 */
#ifndef DOPUS_FUNCS_H
#define DOPUS_FUNCS_H

#include "dopus_sizes.h"

typedef struct dopus_fun_work_s {
    int iw[DOPUS_SZ_IW];
    dopus_real w[DOPUS_SZ_W];
    const dopus_real *arg[DOPUS_SZ_ARG];
    dopus_real *res[DOPUS_SZ_RES];
} dopus_fun_work;

#ifndef DOPUS_INTERNAL
#define DOPUS_INTERNAL
#endif

/* stage_eval: phi (nx), l (1), g (ng) */
DOPUS_INTERNAL int dopus_eval_stage_eval(const dopus_real *x, const dopus_real *u, const dopus_real *p,
                                         dopus_real *phi, dopus_real *l, dopus_real *g, dopus_fun_work *wk);

/* stage_grad, F_k of eq. 14: gL = grad_w l - Phi' lam_next + C' mu_g, plus phi, l, g */
DOPUS_INTERNAL int dopus_eval_stage_grad(const dopus_real *x, const dopus_real *u, const dopus_real *p,
                                         const dopus_real *lam_next, const dopus_real *mu_g, dopus_real *gL,
                                         dopus_real *phi, dopus_real *l, dopus_real *g, dopus_fun_work *wk);

/* stage_hess, H_k of eq. 15: A (nw x nw), Phi (nx x nw), C (ng x nw).
 * gauss_newton != 0 selects the Gauss-Newton A; nonzero return if !DOPUS_HAS_GN then. */
DOPUS_INTERNAL int dopus_eval_stage_hess(int gauss_newton, const dopus_real *x, const dopus_real *u,
                                         const dopus_real *p, const dopus_real *lam_next,
                                         const dopus_real *mu_g, dopus_real *A, dopus_real *Phi,
                                         dopus_real *C, dopus_fun_work *wk);

/* stage_grad and stage_hess in one call (one generated function sharing what the two compute
 * in common, stage_grad_hess_exact or _gn): gL, phi, l, g as dopus_eval_stage_grad, A, Phi, C
 * as dopus_eval_stage_hess with the same gauss_newton (nonzero return if !DOPUS_HAS_GN then) */
DOPUS_INTERNAL int dopus_eval_stage_grad_hess(int gauss_newton, const dopus_real *x, const dopus_real *u,
                                              const dopus_real *p, const dopus_real *lam_next,
                                              const dopus_real *mu_g, dopus_real *gL, dopus_real *phi,
                                              dopus_real *l, dopus_real *g, dopus_real *A, dopus_real *Phi,
                                              dopus_real *C, dopus_fun_work *wk);

/* stage_hess_cost: A_l (nw x nw), the stage-cost part of A (docs/algorithm.md section 4
 * step 5): exact hess_w l, or with gauss_newton != 0 J' W J + hess_w l_extra (nonzero
 * return if !DOPUS_HAS_GN then). No integrator: l is evaluated at the node. */
DOPUS_INTERNAL int dopus_eval_stage_hess_cost(int gauss_newton, const dopus_real *x, const dopus_real *u,
                                              const dopus_real *p, dopus_real *A_l, dopus_fun_work *wk);

/* term_eval: E (1), r (nr), r_eq (ne) */
DOPUS_INTERNAL int dopus_eval_term_eval(const dopus_real *x, const dopus_real *p, dopus_real *E,
                                        dopus_real *r, dopus_real *r_eq, dopus_fun_work *wk);

/* term_grad: gL = grad E + R' mu_r + R_eq' nu, plus E, r, r_eq */
DOPUS_INTERNAL int dopus_eval_term_grad(const dopus_real *x, const dopus_real *p, const dopus_real *mu_r,
                                        const dopus_real *nu, dopus_real *gL, dopus_real *E, dopus_real *r,
                                        dopus_real *r_eq, dopus_fun_work *wk);

/* term_hess: A (nx x nx), R (nr x nx), R_eq (ne x nx); always available (no GN restriction) */
DOPUS_INTERNAL int dopus_eval_term_hess(int gauss_newton, const dopus_real *x, const dopus_real *p,
                                        const dopus_real *mu_r, const dopus_real *nu, dopus_real *A,
                                        dopus_real *R, dopus_real *R_eq, dopus_fun_work *wk);

/* ode: continuous model xdot = f(x, u, p) */
DOPUS_INTERNAL int dopus_eval_ode(const dopus_real *x, const dopus_real *u, const dopus_real *p,
                                  dopus_real *xdot, dopus_fun_work *wk);

#endif /* DOPUS_FUNCS_H */
