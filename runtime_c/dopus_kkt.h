/* KKT measure of an iterate (docs/algorithm.md section 6): exact derivatives (fresh
 * stage_grad / term_grad at the given point with the given multipliers), never the stored
 * blocks. The module has no state: the iterate, the parameters and the scratch of the
 * generated functions are its arguments. */
#ifndef DOPUS_KKT_H
#define DOPUS_KKT_H

#include "dopus_funcs.h"

#ifndef DOPUS_INTERNAL
#define DOPUS_INTERNAL
#endif

/* Outcome of dopus_kkt_measure. */
enum dopus_kkt_result {
    DOPUS_KKT_OK = 0,
    DOPUS_KKT_FUNCTION = 1, /* a generated function reported failure */
    DOPUS_KKT_NONFINITE = 2 /* a generated function returned NaN or Inf */
};

/* parts[0..3] = stat, eq, ineq, comp (infinity norms) of the iterate (shapes of
 * dopus_solver.h: x (N+1) x nx, u N x nu, lam (N+1) x nx, mu_g N x DIM(ng), mu_b N x nw,
 * mu_bN nx, mu_r DIM(nr), nu DIM(ne), p (N+1) x DIM(np)) for the initial state xhat0. */
DOPUS_INTERNAL int dopus_kkt_measure(const dopus_real *x, const dopus_real *u, const dopus_real *lam,
                                     const dopus_real *mu_g, const dopus_real *mu_b, const dopus_real *mu_bN,
                                     const dopus_real *mu_r, const dopus_real *nu, const dopus_real *p,
                                     const dopus_real *xhat0, dopus_fun_work *work, dopus_real *parts);

/* The relative measure of the same iterate (section 6): max(stat / s_d, eq / s_p, ineq / s_p,
 * comp / (s_d s_p)) with s_d = max(1, the largest multiplier) and s_p = max(1, the largest entry
 * of x and u); parts as written by dopus_kkt_measure. */
DOPUS_INTERNAL dopus_real dopus_kkt_relative(const dopus_real *parts, const dopus_real *x,
                                             const dopus_real *u, const dopus_real *lam,
                                             const dopus_real *mu_g, const dopus_real *mu_b,
                                             const dopus_real *mu_bN, const dopus_real *mu_r,
                                             const dopus_real *nu);

#endif /* DOPUS_KKT_H */
