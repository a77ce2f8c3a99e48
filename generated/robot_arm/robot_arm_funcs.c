/* The wrappers of robot_arm_funcs.h over the CasADi functions of robot_arm_casadi.c
 * (docs/algorithm.md section 2). All scratch memory comes from the caller's work struct. */
#include "robot_arm_funcs.h"
#include "robot_arm_casadi.h"

/* The signature of every CasADi function of robot_arm_casadi.c. */
typedef int (*robot_arm_casadi_fn)(const robot_arm_real **arg, robot_arm_real **res, int *iw, robot_arm_real *w, int mem);

/* f on the inputs in[0..n_in-1] and outputs out[0..n_out-1], placed at the start of the work
 * struct's argument and result arrays (CasADi may use the entries after them as scratch);
 * the pointer arrays are cleared afterwards. */
static int robot_arm_call(robot_arm_casadi_fn f, const robot_arm_real *const *in, int n_in, robot_arm_real *const *out,
                      int n_out, robot_arm_fun_work *wk)
{
    int i, rc;
    for (i = 0; i < n_in; ++i) {
        wk->arg[i] = in[i];
    }
    for (i = 0; i < n_out; ++i) {
        wk->res[i] = out[i];
    }
    rc = f(wk->arg, wk->res, wk->iw, wk->w, 0);
    /* no pointer stays behind in the work struct (the solver struct that holds it may be
     * copied byte for byte, docs/design.md) */
    for (i = 0; i < ROBOT_ARM_SZ_ARG; ++i) {
        wk->arg[i] = 0;
    }
    for (i = 0; i < ROBOT_ARM_SZ_RES; ++i) {
        wk->res[i] = 0;
    }
    return rc;
}

/* The stage function of the chosen Hessian; 0 for Gauss-Newton without a least-squares stage
 * cost (no Gauss-Newton Hessian was generated). */
#if ROBOT_ARM_HAS_GN
#define ROBOT_ARM_STAGE_FN(gauss_newton, name) ((gauss_newton) ? name##_gn : name##_exact)
#else
#define ROBOT_ARM_STAGE_FN(gauss_newton, name) ((gauss_newton) ? (robot_arm_casadi_fn)0 : name##_exact)
#endif

int robot_arm_eval_stage_eval(const robot_arm_real *x, const robot_arm_real *u, const robot_arm_real *p, robot_arm_real *phi,
                          robot_arm_real *l, robot_arm_real *g, robot_arm_fun_work *wk)
{
    const robot_arm_real *in[3] = {x, u, p};
    robot_arm_real *out[3] = {phi, l, g};
    return robot_arm_call(robot_arm_stage_eval, in, 3, out, 3, wk);
}

int robot_arm_eval_stage_grad(const robot_arm_real *x, const robot_arm_real *u, const robot_arm_real *p,
                          const robot_arm_real *lam_next, const robot_arm_real *mu_g, robot_arm_real *gL, robot_arm_real *phi,
                          robot_arm_real *l, robot_arm_real *g, robot_arm_fun_work *wk)
{
    const robot_arm_real *in[5] = {x, u, p, lam_next, mu_g};
    robot_arm_real *out[4] = {gL, phi, l, g};
    return robot_arm_call(robot_arm_stage_grad, in, 5, out, 4, wk);
}

int robot_arm_eval_stage_hess(int gauss_newton, const robot_arm_real *x, const robot_arm_real *u, const robot_arm_real *p,
                          const robot_arm_real *lam_next, const robot_arm_real *mu_g, robot_arm_real *A, robot_arm_real *Phi,
                          robot_arm_real *C, robot_arm_fun_work *wk)
{
    const robot_arm_real *in[5] = {x, u, p, lam_next, mu_g};
    robot_arm_real *out[3] = {A, Phi, C};
    robot_arm_casadi_fn f = ROBOT_ARM_STAGE_FN(gauss_newton, robot_arm_stage_hess);
    return f ? robot_arm_call(f, in, 5, out, 3, wk) : 1;
}

int robot_arm_eval_stage_grad_hess(int gauss_newton, const robot_arm_real *x, const robot_arm_real *u,
                               const robot_arm_real *p, const robot_arm_real *lam_next, const robot_arm_real *mu_g,
                               robot_arm_real *gL, robot_arm_real *phi, robot_arm_real *l, robot_arm_real *g, robot_arm_real *A,
                               robot_arm_real *Phi, robot_arm_real *C, robot_arm_fun_work *wk)
{
    const robot_arm_real *in[5] = {x, u, p, lam_next, mu_g};
    robot_arm_real *out[7] = {gL, phi, l, g, A, Phi, C};
#if ROBOT_ARM_HAS_GN_FUSED
    robot_arm_casadi_fn f = ROBOT_ARM_STAGE_FN(gauss_newton, robot_arm_stage_grad_hess);
    return robot_arm_call(f, in, 5, out, 7, wk);
#else
    /* no fused Gauss-Newton function generated (the OCP file chooses the exact Hessian): the
     * two calls, the same values */
    if (gauss_newton) {
        return robot_arm_eval_stage_grad(x, u, p, lam_next, mu_g, gL, phi, l, g, wk) != 0 ||
               robot_arm_eval_stage_hess(1, x, u, p, lam_next, mu_g, A, Phi, C, wk) != 0;
    }
    return robot_arm_call(robot_arm_stage_grad_hess_exact, in, 5, out, 7, wk);
#endif
}

int robot_arm_eval_stage_hess_cost(int gauss_newton, const robot_arm_real *x, const robot_arm_real *u,
                               const robot_arm_real *p, robot_arm_real *A_l, robot_arm_fun_work *wk)
{
    const robot_arm_real *in[3] = {x, u, p};
    robot_arm_real *out[1] = {A_l};
    robot_arm_casadi_fn f = ROBOT_ARM_STAGE_FN(gauss_newton, robot_arm_stage_hess_cost);
    return f ? robot_arm_call(f, in, 3, out, 1, wk) : 1;
}

int robot_arm_eval_term_eval(const robot_arm_real *x, const robot_arm_real *p, robot_arm_real *E, robot_arm_real *r,
                         robot_arm_real *r_eq, robot_arm_fun_work *wk)
{
    const robot_arm_real *in[2] = {x, p};
    robot_arm_real *out[3] = {E, r, r_eq};
    return robot_arm_call(robot_arm_term_eval, in, 2, out, 3, wk);
}

int robot_arm_eval_term_grad(const robot_arm_real *x, const robot_arm_real *p, const robot_arm_real *mu_r,
                         const robot_arm_real *nu, robot_arm_real *gL, robot_arm_real *E, robot_arm_real *r, robot_arm_real *r_eq,
                         robot_arm_fun_work *wk)
{
    const robot_arm_real *in[4] = {x, p, mu_r, nu};
    robot_arm_real *out[4] = {gL, E, r, r_eq};
    return robot_arm_call(robot_arm_term_grad, in, 4, out, 4, wk);
}

int robot_arm_eval_term_hess(int gauss_newton, const robot_arm_real *x, const robot_arm_real *p, const robot_arm_real *mu_r,
                         const robot_arm_real *nu, robot_arm_real *A, robot_arm_real *R, robot_arm_real *R_eq,
                         robot_arm_fun_work *wk)
{
    const robot_arm_real *in[4] = {x, p, mu_r, nu};
    robot_arm_real *out[3] = {A, R, R_eq};
    return robot_arm_call(gauss_newton ? robot_arm_term_hess_gn : robot_arm_term_hess_exact, in, 4, out, 3, wk);
}

int robot_arm_eval_ode(const robot_arm_real *x, const robot_arm_real *u, const robot_arm_real *p, robot_arm_real *xdot,
                   robot_arm_fun_work *wk)
{
    const robot_arm_real *in[3] = {x, u, p};
    robot_arm_real *out[1] = {xdot};
    return robot_arm_call(robot_arm_ode, in, 3, out, 1, wk);
}
