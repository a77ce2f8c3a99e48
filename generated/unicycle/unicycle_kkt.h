/* KKT measure of an iterate (docs/algorithm.md section 6): exact derivatives (fresh
 * stage_grad / term_grad at the given point with the given multipliers), never the stored
 * blocks. The module has no state: the iterate, the parameters and the scratch of the
 * generated functions are its arguments. */
#ifndef UNICYCLE_KKT_H
#define UNICYCLE_KKT_H

#include "unicycle_funcs.h"

#ifndef UNICYCLE_INTERNAL
#define UNICYCLE_INTERNAL
#endif

/* Outcome of unicycle_kkt_measure. */
enum unicycle_kkt_result {
    UNICYCLE_KKT_OK = 0,
    UNICYCLE_KKT_FUNCTION = 1, /* a generated function reported failure */
    UNICYCLE_KKT_NONFINITE = 2 /* a generated function returned NaN or Inf */
};

/* parts[0..3] = stat, eq, ineq, comp (infinity norms) of the iterate (shapes of
 * unicycle_solver.h: x (N+1) x nx, u N x nu, lam (N+1) x nx, mu_g N x DIM(ng), mu_b N x nw,
 * mu_bN nx, mu_r DIM(nr), nu DIM(ne), p (N+1) x DIM(np)) for the initial state xhat0. */
UNICYCLE_INTERNAL int unicycle_kkt_measure(const unicycle_real *x, const unicycle_real *u, const unicycle_real *lam,
                                     const unicycle_real *mu_g, const unicycle_real *mu_b, const unicycle_real *mu_bN,
                                     const unicycle_real *mu_r, const unicycle_real *nu, const unicycle_real *p,
                                     const unicycle_real *xhat0, unicycle_fun_work *work, unicycle_real *parts);

/* The relative measure of the same iterate (section 6): max(stat / s_d, eq / s_p, ineq / s_p,
 * comp / (s_d s_p)) with s_d = max(1, the largest multiplier) and s_p = max(1, the largest entry
 * of x and u); parts as written by unicycle_kkt_measure. */
UNICYCLE_INTERNAL unicycle_real unicycle_kkt_relative(const unicycle_real *parts, const unicycle_real *x,
                                             const unicycle_real *u, const unicycle_real *lam,
                                             const unicycle_real *mu_g, const unicycle_real *mu_b,
                                             const unicycle_real *mu_bN, const unicycle_real *mu_r,
                                             const unicycle_real *nu);

#endif /* UNICYCLE_KKT_H */
