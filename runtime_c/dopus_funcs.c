/* The wrappers of dopus_funcs.h over the CasADi functions of dopus_casadi.c
 * (docs/algorithm.md section 2). All scratch memory comes from the caller's work struct. */
#include "dopus_funcs.h"
#include "dopus_casadi.h"

/* The signature of every CasADi function of dopus_casadi.c. */
typedef int (*dopus_casadi_fn)(const double **arg, double **res, int *iw, double *w, int mem);

/* f on the inputs in[0..n_in-1] and outputs out[0..n_out-1], placed at the start of the work
 * struct's argument and result arrays (CasADi may use the entries after them as scratch). */
static int dopus_call(dopus_casadi_fn f, const double *const *in, int n_in, double *const *out, int n_out,
                      dopus_fun_work *wk)
{
    int i;
    for (i = 0; i < n_in; ++i) {
        wk->arg[i] = in[i];
    }
    for (i = 0; i < n_out; ++i) {
        wk->res[i] = out[i];
    }
    return f(wk->arg, wk->res, wk->iw, wk->w, 0);
}

/* The stage function of the chosen Hessian; 0 for Gauss-Newton without a least-squares stage
 * cost (no Gauss-Newton Hessian was generated). */
#if DOPUS_HAS_GN
#define DOPUS_STAGE_FN(gauss_newton, name) ((gauss_newton) ? name##_gn : name##_exact)
#else
#define DOPUS_STAGE_FN(gauss_newton, name) ((gauss_newton) ? (dopus_casadi_fn)0 : name##_exact)
#endif

int dopus_eval_stage_eval(const double *x, const double *u, const double *p, double *phi, double *l,
                          double *g, dopus_fun_work *wk)
{
    const double *in[3] = {x, u, p};
    double *out[3] = {phi, l, g};
    return dopus_call(dopus_stage_eval, in, 3, out, 3, wk);
}

int dopus_eval_stage_grad(const double *x, const double *u, const double *p, const double *lam_next,
                          const double *mu_g, double *gL, double *phi, double *l, double *g,
                          dopus_fun_work *wk)
{
    const double *in[5] = {x, u, p, lam_next, mu_g};
    double *out[4] = {gL, phi, l, g};
    return dopus_call(dopus_stage_grad, in, 5, out, 4, wk);
}

int dopus_eval_stage_hess(int gauss_newton, const double *x, const double *u, const double *p,
                          const double *lam_next, const double *mu_g, double *A, double *Phi, double *C,
                          dopus_fun_work *wk)
{
    const double *in[5] = {x, u, p, lam_next, mu_g};
    double *out[3] = {A, Phi, C};
    dopus_casadi_fn f = DOPUS_STAGE_FN(gauss_newton, dopus_stage_hess);
    return f ? dopus_call(f, in, 5, out, 3, wk) : 1;
}

int dopus_eval_stage_hess_cost(int gauss_newton, const double *x, const double *u, const double *p,
                               double *A_l, dopus_fun_work *wk)
{
    const double *in[3] = {x, u, p};
    double *out[1] = {A_l};
    dopus_casadi_fn f = DOPUS_STAGE_FN(gauss_newton, dopus_stage_hess_cost);
    return f ? dopus_call(f, in, 3, out, 1, wk) : 1;
}

int dopus_eval_term_eval(const double *x, const double *p, double *E, double *r, double *r_eq,
                         dopus_fun_work *wk)
{
    const double *in[2] = {x, p};
    double *out[3] = {E, r, r_eq};
    return dopus_call(dopus_term_eval, in, 2, out, 3, wk);
}

int dopus_eval_term_grad(const double *x, const double *p, const double *mu_r, const double *nu, double *gL,
                         double *E, double *r, double *r_eq, dopus_fun_work *wk)
{
    const double *in[4] = {x, p, mu_r, nu};
    double *out[4] = {gL, E, r, r_eq};
    return dopus_call(dopus_term_grad, in, 4, out, 4, wk);
}

int dopus_eval_term_hess(int gauss_newton, const double *x, const double *p, const double *mu_r,
                         const double *nu, double *A, double *R, double *R_eq, dopus_fun_work *wk)
{
    const double *in[4] = {x, p, mu_r, nu};
    double *out[3] = {A, R, R_eq};
    return dopus_call(gauss_newton ? dopus_term_hess_gn : dopus_term_hess_exact, in, 4, out, 3, wk);
}

int dopus_eval_ode(const double *x, const double *u, const double *p, double *xdot, dopus_fun_work *wk)
{
    const double *in[3] = {x, u, p};
    double *out[1] = {xdot};
    return dopus_call(dopus_ode, in, 3, out, 1, wk);
}
