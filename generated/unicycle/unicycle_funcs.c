/* The wrappers of unicycle_funcs.h over the CasADi functions of unicycle_casadi.c
 * (docs/algorithm.md section 2). All scratch memory comes from the caller's work struct. */
#include "unicycle_funcs.h"
#include "unicycle_casadi.h"

int unicycle_eval_stage_eval(const unicycle_real *x, const unicycle_real *u, const unicycle_real *p, unicycle_real *phi,
                          unicycle_real *l, unicycle_real *g, unicycle_fun_work *wk)
{
    wk->arg[0] = x;
    wk->arg[1] = u;
    wk->arg[2] = p;
    wk->res[0] = phi;
    wk->res[1] = l;
    wk->res[2] = g;
    return unicycle_stage_eval(wk->arg, wk->res, wk->iw, wk->w, 0);
}

int unicycle_eval_stage_grad(const unicycle_real *x, const unicycle_real *u, const unicycle_real *p,
                          const unicycle_real *lam_next, const unicycle_real *mu_g, unicycle_real *gL, unicycle_real *phi,
                          unicycle_real *l, unicycle_real *g, unicycle_fun_work *wk)
{
    wk->arg[0] = x;
    wk->arg[1] = u;
    wk->arg[2] = p;
    wk->arg[3] = lam_next;
    wk->arg[4] = mu_g;
    wk->res[0] = gL;
    wk->res[1] = phi;
    wk->res[2] = l;
    wk->res[3] = g;
    return unicycle_stage_grad(wk->arg, wk->res, wk->iw, wk->w, 0);
}

int unicycle_eval_stage_hess(int gauss_newton, const unicycle_real *x, const unicycle_real *u, const unicycle_real *p,
                          const unicycle_real *lam_next, const unicycle_real *mu_g, unicycle_real *A, unicycle_real *Phi,
                          unicycle_real *C, unicycle_fun_work *wk)
{
    wk->arg[0] = x;
    wk->arg[1] = u;
    wk->arg[2] = p;
    wk->arg[3] = lam_next;
    wk->arg[4] = mu_g;
    wk->res[0] = A;
    wk->res[1] = Phi;
    wk->res[2] = C;
    if (gauss_newton) {
#if UNICYCLE_HAS_GN
        return unicycle_stage_hess_gn(wk->arg, wk->res, wk->iw, wk->w, 0);
#else
        return 1; /* no least-squares stage cost: no Gauss-Newton Hessian */
#endif
    }
    return unicycle_stage_hess_exact(wk->arg, wk->res, wk->iw, wk->w, 0);
}

int unicycle_eval_stage_hess_cost(int gauss_newton, const unicycle_real *x, const unicycle_real *u,
                               const unicycle_real *p, unicycle_real *A_l, unicycle_fun_work *wk)
{
    wk->arg[0] = x;
    wk->arg[1] = u;
    wk->arg[2] = p;
    wk->res[0] = A_l;
    if (gauss_newton) {
#if UNICYCLE_HAS_GN
        return unicycle_stage_hess_cost_gn(wk->arg, wk->res, wk->iw, wk->w, 0);
#else
        return 1; /* no least-squares stage cost: no Gauss-Newton Hessian */
#endif
    }
    return unicycle_stage_hess_cost_exact(wk->arg, wk->res, wk->iw, wk->w, 0);
}

int unicycle_eval_term_eval(const unicycle_real *x, const unicycle_real *p, unicycle_real *E, unicycle_real *r,
                         unicycle_real *r_eq, unicycle_fun_work *wk)
{
    wk->arg[0] = x;
    wk->arg[1] = p;
    wk->res[0] = E;
    wk->res[1] = r;
    wk->res[2] = r_eq;
    return unicycle_term_eval(wk->arg, wk->res, wk->iw, wk->w, 0);
}

int unicycle_eval_term_grad(const unicycle_real *x, const unicycle_real *p, const unicycle_real *mu_r,
                         const unicycle_real *nu, unicycle_real *gL, unicycle_real *E, unicycle_real *r, unicycle_real *r_eq,
                         unicycle_fun_work *wk)
{
    wk->arg[0] = x;
    wk->arg[1] = p;
    wk->arg[2] = mu_r;
    wk->arg[3] = nu;
    wk->res[0] = gL;
    wk->res[1] = E;
    wk->res[2] = r;
    wk->res[3] = r_eq;
    return unicycle_term_grad(wk->arg, wk->res, wk->iw, wk->w, 0);
}

int unicycle_eval_term_hess(int gauss_newton, const unicycle_real *x, const unicycle_real *p, const unicycle_real *mu_r,
                         const unicycle_real *nu, unicycle_real *A, unicycle_real *R, unicycle_real *R_eq,
                         unicycle_fun_work *wk)
{
    wk->arg[0] = x;
    wk->arg[1] = p;
    wk->arg[2] = mu_r;
    wk->arg[3] = nu;
    wk->res[0] = A;
    wk->res[1] = R;
    wk->res[2] = R_eq;
    if (gauss_newton) {
        return unicycle_term_hess_gn(wk->arg, wk->res, wk->iw, wk->w, 0);
    }
    return unicycle_term_hess_exact(wk->arg, wk->res, wk->iw, wk->w, 0);
}

int unicycle_eval_ode(const unicycle_real *x, const unicycle_real *u, const unicycle_real *p, unicycle_real *xdot,
                   unicycle_fun_work *wk)
{
    wk->arg[0] = x;
    wk->arg[1] = u;
    wk->arg[2] = p;
    wk->res[0] = xdot;
    return unicycle_ode(wk->arg, wk->res, wk->iw, wk->w, 0);
}
