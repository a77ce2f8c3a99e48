/* The wrappers of robot_arm_funcs.h over the CasADi functions of robot_arm_casadi.c
 * (docs/algorithm.md section 2). All scratch memory comes from the caller's work struct. */
#include "robot_arm_funcs.h"
#include "robot_arm_casadi.h"

int robot_arm_eval_stage_eval(const robot_arm_real *x, const robot_arm_real *u, const robot_arm_real *p, robot_arm_real *phi,
                          robot_arm_real *l, robot_arm_real *g, robot_arm_fun_work *wk)
{
    wk->arg[0] = x;
    wk->arg[1] = u;
    wk->arg[2] = p;
    wk->res[0] = phi;
    wk->res[1] = l;
    wk->res[2] = g;
    return robot_arm_stage_eval(wk->arg, wk->res, wk->iw, wk->w, 0);
}

int robot_arm_eval_stage_grad(const robot_arm_real *x, const robot_arm_real *u, const robot_arm_real *p,
                          const robot_arm_real *lam_next, const robot_arm_real *mu_g, robot_arm_real *gL, robot_arm_real *phi,
                          robot_arm_real *l, robot_arm_real *g, robot_arm_fun_work *wk)
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
    return robot_arm_stage_grad(wk->arg, wk->res, wk->iw, wk->w, 0);
}

int robot_arm_eval_stage_hess(int gauss_newton, const robot_arm_real *x, const robot_arm_real *u, const robot_arm_real *p,
                          const robot_arm_real *lam_next, const robot_arm_real *mu_g, robot_arm_real *A, robot_arm_real *Phi,
                          robot_arm_real *C, robot_arm_fun_work *wk)
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
#if ROBOT_ARM_HAS_GN
        return robot_arm_stage_hess_gn(wk->arg, wk->res, wk->iw, wk->w, 0);
#else
        return 1; /* no least-squares stage cost: no Gauss-Newton Hessian */
#endif
    }
    return robot_arm_stage_hess_exact(wk->arg, wk->res, wk->iw, wk->w, 0);
}

int robot_arm_eval_stage_hess_cost(int gauss_newton, const robot_arm_real *x, const robot_arm_real *u,
                               const robot_arm_real *p, robot_arm_real *A_l, robot_arm_fun_work *wk)
{
    wk->arg[0] = x;
    wk->arg[1] = u;
    wk->arg[2] = p;
    wk->res[0] = A_l;
    if (gauss_newton) {
#if ROBOT_ARM_HAS_GN
        return robot_arm_stage_hess_cost_gn(wk->arg, wk->res, wk->iw, wk->w, 0);
#else
        return 1; /* no least-squares stage cost: no Gauss-Newton Hessian */
#endif
    }
    return robot_arm_stage_hess_cost_exact(wk->arg, wk->res, wk->iw, wk->w, 0);
}

int robot_arm_eval_term_eval(const robot_arm_real *x, const robot_arm_real *p, robot_arm_real *E, robot_arm_real *r,
                         robot_arm_real *r_eq, robot_arm_fun_work *wk)
{
    wk->arg[0] = x;
    wk->arg[1] = p;
    wk->res[0] = E;
    wk->res[1] = r;
    wk->res[2] = r_eq;
    return robot_arm_term_eval(wk->arg, wk->res, wk->iw, wk->w, 0);
}

int robot_arm_eval_term_grad(const robot_arm_real *x, const robot_arm_real *p, const robot_arm_real *mu_r,
                         const robot_arm_real *nu, robot_arm_real *gL, robot_arm_real *E, robot_arm_real *r, robot_arm_real *r_eq,
                         robot_arm_fun_work *wk)
{
    wk->arg[0] = x;
    wk->arg[1] = p;
    wk->arg[2] = mu_r;
    wk->arg[3] = nu;
    wk->res[0] = gL;
    wk->res[1] = E;
    wk->res[2] = r;
    wk->res[3] = r_eq;
    return robot_arm_term_grad(wk->arg, wk->res, wk->iw, wk->w, 0);
}

int robot_arm_eval_term_hess(int gauss_newton, const robot_arm_real *x, const robot_arm_real *p, const robot_arm_real *mu_r,
                         const robot_arm_real *nu, robot_arm_real *A, robot_arm_real *R, robot_arm_real *R_eq,
                         robot_arm_fun_work *wk)
{
    wk->arg[0] = x;
    wk->arg[1] = p;
    wk->arg[2] = mu_r;
    wk->arg[3] = nu;
    wk->res[0] = A;
    wk->res[1] = R;
    wk->res[2] = R_eq;
    if (gauss_newton) {
        return robot_arm_term_hess_gn(wk->arg, wk->res, wk->iw, wk->w, 0);
    }
    return robot_arm_term_hess_exact(wk->arg, wk->res, wk->iw, wk->w, 0);
}

int robot_arm_eval_ode(const robot_arm_real *x, const robot_arm_real *u, const robot_arm_real *p, robot_arm_real *xdot,
                   robot_arm_fun_work *wk)
{
    wk->arg[0] = x;
    wk->arg[1] = u;
    wk->arg[2] = p;
    wk->res[0] = xdot;
    return robot_arm_ode(wk->arg, wk->res, wk->iw, wk->w, 0);
}
