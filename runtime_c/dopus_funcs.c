/* The wrappers of dopus_funcs.h over the CasADi functions of dopus_casadi.c
 * (docs/algorithm.md section 2). All scratch memory comes from the caller's work struct. */
#include "dopus_funcs.h"
#include "dopus_casadi.h"

int dopus_eval_stage_eval(const dopus_real *x, const dopus_real *u, const dopus_real *p, dopus_real *phi,
                          dopus_real *l, dopus_real *g, dopus_fun_work *wk)
{
    wk->arg[0] = x;
    wk->arg[1] = u;
    wk->arg[2] = p;
    wk->res[0] = phi;
    wk->res[1] = l;
    wk->res[2] = g;
    return dopus_stage_eval(wk->arg, wk->res, wk->iw, wk->w, 0);
}

int dopus_eval_stage_grad(const dopus_real *x, const dopus_real *u, const dopus_real *p,
                          const dopus_real *lam_next, const dopus_real *mu_g, dopus_real *gL, dopus_real *phi,
                          dopus_real *l, dopus_real *g, dopus_fun_work *wk)
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
    return dopus_stage_grad(wk->arg, wk->res, wk->iw, wk->w, 0);
}

int dopus_eval_stage_hess(int gauss_newton, const dopus_real *x, const dopus_real *u, const dopus_real *p,
                          const dopus_real *lam_next, const dopus_real *mu_g, dopus_real *A, dopus_real *Phi,
                          dopus_real *C, dopus_fun_work *wk)
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
#if DOPUS_HAS_GN
        return dopus_stage_hess_gn(wk->arg, wk->res, wk->iw, wk->w, 0);
#else
        return 1; /* no least-squares stage cost: no Gauss-Newton Hessian */
#endif
    }
    return dopus_stage_hess_exact(wk->arg, wk->res, wk->iw, wk->w, 0);
}

int dopus_eval_stage_hess_cost(int gauss_newton, const dopus_real *x, const dopus_real *u,
                               const dopus_real *p, dopus_real *A_l, dopus_fun_work *wk)
{
    wk->arg[0] = x;
    wk->arg[1] = u;
    wk->arg[2] = p;
    wk->res[0] = A_l;
    if (gauss_newton) {
#if DOPUS_HAS_GN
        return dopus_stage_hess_cost_gn(wk->arg, wk->res, wk->iw, wk->w, 0);
#else
        return 1; /* no least-squares stage cost: no Gauss-Newton Hessian */
#endif
    }
    return dopus_stage_hess_cost_exact(wk->arg, wk->res, wk->iw, wk->w, 0);
}

int dopus_eval_term_eval(const dopus_real *x, const dopus_real *p, dopus_real *E, dopus_real *r,
                         dopus_real *r_eq, dopus_fun_work *wk)
{
    wk->arg[0] = x;
    wk->arg[1] = p;
    wk->res[0] = E;
    wk->res[1] = r;
    wk->res[2] = r_eq;
    return dopus_term_eval(wk->arg, wk->res, wk->iw, wk->w, 0);
}

int dopus_eval_term_grad(const dopus_real *x, const dopus_real *p, const dopus_real *mu_r,
                         const dopus_real *nu, dopus_real *gL, dopus_real *E, dopus_real *r, dopus_real *r_eq,
                         dopus_fun_work *wk)
{
    wk->arg[0] = x;
    wk->arg[1] = p;
    wk->arg[2] = mu_r;
    wk->arg[3] = nu;
    wk->res[0] = gL;
    wk->res[1] = E;
    wk->res[2] = r;
    wk->res[3] = r_eq;
    return dopus_term_grad(wk->arg, wk->res, wk->iw, wk->w, 0);
}

int dopus_eval_term_hess(int gauss_newton, const dopus_real *x, const dopus_real *p, const dopus_real *mu_r,
                         const dopus_real *nu, dopus_real *A, dopus_real *R, dopus_real *R_eq,
                         dopus_fun_work *wk)
{
    wk->arg[0] = x;
    wk->arg[1] = p;
    wk->arg[2] = mu_r;
    wk->arg[3] = nu;
    wk->res[0] = A;
    wk->res[1] = R;
    wk->res[2] = R_eq;
    if (gauss_newton) {
        return dopus_term_hess_gn(wk->arg, wk->res, wk->iw, wk->w, 0);
    }
    return dopus_term_hess_exact(wk->arg, wk->res, wk->iw, wk->w, 0);
}

int dopus_eval_ode(const dopus_real *x, const dopus_real *u, const dopus_real *p, dopus_real *xdot,
                   dopus_fun_work *wk)
{
    wk->arg[0] = x;
    wk->arg[1] = u;
    wk->arg[2] = p;
    wk->res[0] = xdot;
    return dopus_ode(wk->arg, wk->res, wk->iw, wk->w, 0);
}
