/* The wrappers of dopus_funcs.h over the CasADi functions of dopus_casadi.c
 * (docs/algorithm.md section 2). All scratch memory comes from the caller's work struct. */
#include "dopus_funcs.h"
#include "dopus_casadi.h"

/* The signature of every CasADi function of dopus_casadi.c. */
typedef int (*dopus_casadi_fn)(const dopus_real **arg, dopus_real **res, int *iw, dopus_real *w, int mem);

/* f on the inputs in[0..n_in-1] and outputs out[0..n_out-1], placed at the start of the work
 * struct's argument and result arrays (CasADi may use the entries after them as scratch);
 * the pointer arrays are cleared afterwards. */
static int dopus_call(dopus_casadi_fn f, const dopus_real *const *in, int n_in, dopus_real *const *out,
                      int n_out, dopus_fun_work *wk)
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
    for (i = 0; i < DOPUS_SZ_ARG; ++i) {
        wk->arg[i] = 0;
    }
    for (i = 0; i < DOPUS_SZ_RES; ++i) {
        wk->res[i] = 0;
    }
    return rc;
}

/* The stage function of the chosen Hessian; 0 for Gauss-Newton without a least-squares stage
 * cost (no Gauss-Newton Hessian was generated). */
#if DOPUS_HAS_GN
#define DOPUS_STAGE_FN(gauss_newton, name) ((gauss_newton) ? name##_gn : name##_exact)
#else
#define DOPUS_STAGE_FN(gauss_newton, name) ((gauss_newton) ? (dopus_casadi_fn)0 : name##_exact)
#endif

int dopus_eval_stage_eval(const dopus_real *x, const dopus_real *u, const dopus_real *p, dopus_real *phi,
                          dopus_real *l, dopus_real *g, dopus_fun_work *wk)
{
    const dopus_real *in[3] = {x, u, p};
    dopus_real *out[3] = {phi, l, g};
    return dopus_call(dopus_stage_eval, in, 3, out, 3, wk);
}

int dopus_eval_stage_grad(const dopus_real *x, const dopus_real *u, const dopus_real *p,
                          const dopus_real *lam_next, const dopus_real *mu_g, dopus_real *gL, dopus_real *phi,
                          dopus_real *l, dopus_real *g, dopus_fun_work *wk)
{
    const dopus_real *in[5] = {x, u, p, lam_next, mu_g};
    dopus_real *out[4] = {gL, phi, l, g};
    return dopus_call(dopus_stage_grad, in, 5, out, 4, wk);
}

int dopus_eval_stage_hess(int gauss_newton, const dopus_real *x, const dopus_real *u, const dopus_real *p,
                          const dopus_real *lam_next, const dopus_real *mu_g, dopus_real *A, dopus_real *Phi,
                          dopus_real *C, dopus_fun_work *wk)
{
    const dopus_real *in[5] = {x, u, p, lam_next, mu_g};
    dopus_real *out[3] = {A, Phi, C};
    dopus_casadi_fn f = DOPUS_STAGE_FN(gauss_newton, dopus_stage_hess);
    return f ? dopus_call(f, in, 5, out, 3, wk) : 1;
}

int dopus_eval_stage_grad_hess(int gauss_newton, const dopus_real *x, const dopus_real *u,
                               const dopus_real *p, const dopus_real *lam_next, const dopus_real *mu_g,
                               dopus_real *gL, dopus_real *phi, dopus_real *l, dopus_real *g, dopus_real *A,
                               dopus_real *Phi, dopus_real *C, dopus_fun_work *wk)
{
    const dopus_real *in[5] = {x, u, p, lam_next, mu_g};
    dopus_real *out[7] = {gL, phi, l, g, A, Phi, C};
#if DOPUS_HAS_GN_FUSED
    dopus_casadi_fn f = DOPUS_STAGE_FN(gauss_newton, dopus_stage_grad_hess);
    return dopus_call(f, in, 5, out, 7, wk);
#else
    /* no fused Gauss-Newton function generated (the OCP file chooses the exact Hessian): the
     * two calls, the same values */
    if (gauss_newton) {
        return dopus_eval_stage_grad(x, u, p, lam_next, mu_g, gL, phi, l, g, wk) != 0 ||
               dopus_eval_stage_hess(1, x, u, p, lam_next, mu_g, A, Phi, C, wk) != 0;
    }
    return dopus_call(dopus_stage_grad_hess_exact, in, 5, out, 7, wk);
#endif
}

int dopus_eval_stage_hess_cost(int gauss_newton, const dopus_real *x, const dopus_real *u,
                               const dopus_real *p, dopus_real *A_l, dopus_fun_work *wk)
{
    const dopus_real *in[3] = {x, u, p};
    dopus_real *out[1] = {A_l};
    dopus_casadi_fn f = DOPUS_STAGE_FN(gauss_newton, dopus_stage_hess_cost);
    return f ? dopus_call(f, in, 3, out, 1, wk) : 1;
}

int dopus_eval_term_eval(const dopus_real *x, const dopus_real *p, dopus_real *E, dopus_real *r,
                         dopus_real *r_eq, dopus_fun_work *wk)
{
    const dopus_real *in[2] = {x, p};
    dopus_real *out[3] = {E, r, r_eq};
    return dopus_call(dopus_term_eval, in, 2, out, 3, wk);
}

int dopus_eval_term_grad(const dopus_real *x, const dopus_real *p, const dopus_real *mu_r,
                         const dopus_real *nu, dopus_real *gL, dopus_real *E, dopus_real *r, dopus_real *r_eq,
                         dopus_fun_work *wk)
{
    const dopus_real *in[4] = {x, p, mu_r, nu};
    dopus_real *out[4] = {gL, E, r, r_eq};
    return dopus_call(dopus_term_grad, in, 4, out, 4, wk);
}

int dopus_eval_term_hess(int gauss_newton, const dopus_real *x, const dopus_real *p, const dopus_real *mu_r,
                         const dopus_real *nu, dopus_real *A, dopus_real *R, dopus_real *R_eq,
                         dopus_fun_work *wk)
{
    const dopus_real *in[4] = {x, p, mu_r, nu};
    dopus_real *out[3] = {A, R, R_eq};
    return dopus_call(gauss_newton ? dopus_term_hess_gn : dopus_term_hess_exact, in, 4, out, 3, wk);
}

int dopus_eval_ode(const dopus_real *x, const dopus_real *u, const dopus_real *p, dopus_real *xdot,
                   dopus_fun_work *wk)
{
    const dopus_real *in[3] = {x, u, p};
    dopus_real *out[1] = {xdot};
    return dopus_call(dopus_ode, in, 3, out, 1, wk);
}
