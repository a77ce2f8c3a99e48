/* The wrappers of unicycle_funcs.h over the CasADi functions of unicycle_casadi.c
 * (docs/algorithm.md section 2). All scratch memory comes from the caller's work struct. */
#include "unicycle_funcs.h"
#include "unicycle_casadi.h"

/* The signature of every CasADi function of unicycle_casadi.c. */
typedef int (*unicycle_casadi_fn)(const unicycle_real **arg, unicycle_real **res, int *iw, unicycle_real *w, int mem);

/* f on the inputs in[0..n_in-1] and outputs out[0..n_out-1], placed at the start of the work
 * struct's argument and result arrays (CasADi may use the entries after them as scratch);
 * the pointer arrays are cleared afterwards. */
static int unicycle_call(unicycle_casadi_fn f, const unicycle_real *const *in, int n_in, unicycle_real *const *out,
                      int n_out, unicycle_fun_work *wk)
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
    for (i = 0; i < UNICYCLE_SZ_ARG; ++i) {
        wk->arg[i] = 0;
    }
    for (i = 0; i < UNICYCLE_SZ_RES; ++i) {
        wk->res[i] = 0;
    }
    return rc;
}

/* The stage function of the chosen Hessian; 0 for Gauss-Newton without a least-squares stage
 * cost (no Gauss-Newton Hessian was generated). */
#if UNICYCLE_HAS_GN
#define UNICYCLE_STAGE_FN(gauss_newton, name) ((gauss_newton) ? name##_gn : name##_exact)
#else
#define UNICYCLE_STAGE_FN(gauss_newton, name) ((gauss_newton) ? (unicycle_casadi_fn)0 : name##_exact)
#endif

int unicycle_eval_stage_eval(const unicycle_real *x, const unicycle_real *u, const unicycle_real *p, unicycle_real *phi,
                          unicycle_real *l, unicycle_real *g, unicycle_fun_work *wk)
{
    const unicycle_real *in[3] = {x, u, p};
    unicycle_real *out[3] = {phi, l, g};
    return unicycle_call(unicycle_stage_eval, in, 3, out, 3, wk);
}

int unicycle_eval_stage_grad(const unicycle_real *x, const unicycle_real *u, const unicycle_real *p,
                          const unicycle_real *lam_next, const unicycle_real *mu_g, unicycle_real *gL, unicycle_real *phi,
                          unicycle_real *l, unicycle_real *g, unicycle_fun_work *wk)
{
    const unicycle_real *in[5] = {x, u, p, lam_next, mu_g};
    unicycle_real *out[4] = {gL, phi, l, g};
    return unicycle_call(unicycle_stage_grad, in, 5, out, 4, wk);
}

int unicycle_eval_stage_hess(int gauss_newton, const unicycle_real *x, const unicycle_real *u, const unicycle_real *p,
                          const unicycle_real *lam_next, const unicycle_real *mu_g, unicycle_real *A, unicycle_real *Phi,
                          unicycle_real *C, unicycle_fun_work *wk)
{
    const unicycle_real *in[5] = {x, u, p, lam_next, mu_g};
    unicycle_real *out[3] = {A, Phi, C};
    unicycle_casadi_fn f = UNICYCLE_STAGE_FN(gauss_newton, unicycle_stage_hess);
    return f ? unicycle_call(f, in, 5, out, 3, wk) : 1;
}

int unicycle_eval_stage_grad_hess(int gauss_newton, const unicycle_real *x, const unicycle_real *u,
                               const unicycle_real *p, const unicycle_real *lam_next, const unicycle_real *mu_g,
                               unicycle_real *gL, unicycle_real *phi, unicycle_real *l, unicycle_real *g, unicycle_real *A,
                               unicycle_real *Phi, unicycle_real *C, unicycle_fun_work *wk)
{
    const unicycle_real *in[5] = {x, u, p, lam_next, mu_g};
    unicycle_real *out[7] = {gL, phi, l, g, A, Phi, C};
#if UNICYCLE_HAS_GN_FUSED
    unicycle_casadi_fn f = UNICYCLE_STAGE_FN(gauss_newton, unicycle_stage_grad_hess);
    return unicycle_call(f, in, 5, out, 7, wk);
#else
    /* no fused Gauss-Newton function generated (the OCP file chooses the exact Hessian): the
     * two calls, the same values */
    if (gauss_newton) {
        return unicycle_eval_stage_grad(x, u, p, lam_next, mu_g, gL, phi, l, g, wk) != 0 ||
               unicycle_eval_stage_hess(1, x, u, p, lam_next, mu_g, A, Phi, C, wk) != 0;
    }
    return unicycle_call(unicycle_stage_grad_hess_exact, in, 5, out, 7, wk);
#endif
}

int unicycle_eval_stage_hess_cost(int gauss_newton, const unicycle_real *x, const unicycle_real *u,
                               const unicycle_real *p, unicycle_real *A_l, unicycle_fun_work *wk)
{
    const unicycle_real *in[3] = {x, u, p};
    unicycle_real *out[1] = {A_l};
    unicycle_casadi_fn f = UNICYCLE_STAGE_FN(gauss_newton, unicycle_stage_hess_cost);
    return f ? unicycle_call(f, in, 3, out, 1, wk) : 1;
}

int unicycle_eval_term_eval(const unicycle_real *x, const unicycle_real *p, unicycle_real *E, unicycle_real *r,
                         unicycle_real *r_eq, unicycle_fun_work *wk)
{
    const unicycle_real *in[2] = {x, p};
    unicycle_real *out[3] = {E, r, r_eq};
    return unicycle_call(unicycle_term_eval, in, 2, out, 3, wk);
}

int unicycle_eval_term_grad(const unicycle_real *x, const unicycle_real *p, const unicycle_real *mu_r,
                         const unicycle_real *nu, unicycle_real *gL, unicycle_real *E, unicycle_real *r, unicycle_real *r_eq,
                         unicycle_fun_work *wk)
{
    const unicycle_real *in[4] = {x, p, mu_r, nu};
    unicycle_real *out[4] = {gL, E, r, r_eq};
    return unicycle_call(unicycle_term_grad, in, 4, out, 4, wk);
}

int unicycle_eval_term_hess(int gauss_newton, const unicycle_real *x, const unicycle_real *p, const unicycle_real *mu_r,
                         const unicycle_real *nu, unicycle_real *A, unicycle_real *R, unicycle_real *R_eq,
                         unicycle_fun_work *wk)
{
    const unicycle_real *in[4] = {x, p, mu_r, nu};
    unicycle_real *out[3] = {A, R, R_eq};
    return unicycle_call(gauss_newton ? unicycle_term_hess_gn : unicycle_term_hess_exact, in, 4, out, 3, wk);
}

int unicycle_eval_ode(const unicycle_real *x, const unicycle_real *u, const unicycle_real *p, unicycle_real *xdot,
                   unicycle_fun_work *wk)
{
    const unicycle_real *in[3] = {x, u, p};
    unicycle_real *out[1] = {xdot};
    return unicycle_call(unicycle_ode, in, 3, out, 1, wk);
}
