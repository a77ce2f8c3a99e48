/* Wrappers around the CasADi-generated per-stage functions (docs/algorithm.md section 2).
 *
 * The definitions are generated (unicycle_funcs.c) because they call the CasADi functions by
 * their problem-specific names; the runtime only sees these fixed signatures. Every call uses
 * a caller-supplied work struct, so the generated code holds no static state and two solvers
 * (or two threads) never share scratch memory.
 *
 * Matrices are dense column-major (Phi: nx x nw, A: nw x nw, C: ng x nw, R: nr x nx,
 * R_eq: ne x nx). Inputs and outputs of size zero may be pointers to 1-element dummies.
 * Every function returns 0 on success and nonzero if the CasADi function reported failure.
 */
#ifndef UNICYCLE_FUNCS_H
#define UNICYCLE_FUNCS_H

#include "unicycle_sizes.h"

typedef struct unicycle_fun_work_s {
    int iw[UNICYCLE_SZ_IW];
    unicycle_real w[UNICYCLE_SZ_W];
    const unicycle_real *arg[UNICYCLE_SZ_ARG];
    unicycle_real *res[UNICYCLE_SZ_RES];
} unicycle_fun_work;

#ifndef UNICYCLE_INTERNAL
#define UNICYCLE_INTERNAL
#endif

/* stage_eval: phi (nx), l (1), g (ng) */
UNICYCLE_INTERNAL int unicycle_eval_stage_eval(const unicycle_real *x, const unicycle_real *u, const unicycle_real *p,
                                         unicycle_real *phi, unicycle_real *l, unicycle_real *g, unicycle_fun_work *wk);

/* stage_grad, F_k of eq. 14: gL = grad_w l - Phi' lam_next + C' mu_g, plus phi, l, g */
UNICYCLE_INTERNAL int unicycle_eval_stage_grad(const unicycle_real *x, const unicycle_real *u, const unicycle_real *p,
                                         const unicycle_real *lam_next, const unicycle_real *mu_g, unicycle_real *gL,
                                         unicycle_real *phi, unicycle_real *l, unicycle_real *g, unicycle_fun_work *wk);

/* stage_hess, H_k of eq. 15: A (nw x nw), Phi (nx x nw), C (ng x nw).
 * gauss_newton != 0 selects the Gauss-Newton A; nonzero return if !UNICYCLE_HAS_GN then. */
UNICYCLE_INTERNAL int unicycle_eval_stage_hess(int gauss_newton, const unicycle_real *x, const unicycle_real *u,
                                         const unicycle_real *p, const unicycle_real *lam_next,
                                         const unicycle_real *mu_g, unicycle_real *A, unicycle_real *Phi,
                                         unicycle_real *C, unicycle_fun_work *wk);

/* stage_grad and stage_hess in one call (one generated function sharing what the two compute
 * in common, stage_grad_hess_exact or _gn): gL, phi, l, g as unicycle_eval_stage_grad, A, Phi, C
 * as unicycle_eval_stage_hess with the same gauss_newton (nonzero return if !UNICYCLE_HAS_GN then) */
UNICYCLE_INTERNAL int unicycle_eval_stage_grad_hess(int gauss_newton, const unicycle_real *x, const unicycle_real *u,
                                              const unicycle_real *p, const unicycle_real *lam_next,
                                              const unicycle_real *mu_g, unicycle_real *gL, unicycle_real *phi,
                                              unicycle_real *l, unicycle_real *g, unicycle_real *A, unicycle_real *Phi,
                                              unicycle_real *C, unicycle_fun_work *wk);

/* stage_hess_cost: A_l (nw x nw), the stage-cost part of A (docs/algorithm.md section 4
 * step 5): exact hess_w l, or with gauss_newton != 0 J' W J + hess_w l_extra (nonzero
 * return if !UNICYCLE_HAS_GN then). No integrator: l is evaluated at the node. */
UNICYCLE_INTERNAL int unicycle_eval_stage_hess_cost(int gauss_newton, const unicycle_real *x, const unicycle_real *u,
                                              const unicycle_real *p, unicycle_real *A_l, unicycle_fun_work *wk);

/* term_eval: E (1), r (nr), r_eq (ne) */
UNICYCLE_INTERNAL int unicycle_eval_term_eval(const unicycle_real *x, const unicycle_real *p, unicycle_real *E,
                                        unicycle_real *r, unicycle_real *r_eq, unicycle_fun_work *wk);

/* term_grad: gL = grad E + R' mu_r + R_eq' nu, plus E, r, r_eq */
UNICYCLE_INTERNAL int unicycle_eval_term_grad(const unicycle_real *x, const unicycle_real *p, const unicycle_real *mu_r,
                                        const unicycle_real *nu, unicycle_real *gL, unicycle_real *E, unicycle_real *r,
                                        unicycle_real *r_eq, unicycle_fun_work *wk);

/* term_hess: A (nx x nx), R (nr x nx), R_eq (ne x nx); always available (no GN restriction) */
UNICYCLE_INTERNAL int unicycle_eval_term_hess(int gauss_newton, const unicycle_real *x, const unicycle_real *p,
                                        const unicycle_real *mu_r, const unicycle_real *nu, unicycle_real *A,
                                        unicycle_real *R, unicycle_real *R_eq, unicycle_fun_work *wk);

/* ode: continuous model xdot = f(x, u, p) */
UNICYCLE_INTERNAL int unicycle_eval_ode(const unicycle_real *x, const unicycle_real *u, const unicycle_real *p,
                                  unicycle_real *xdot, unicycle_fun_work *wk);

#endif /* UNICYCLE_FUNCS_H */
