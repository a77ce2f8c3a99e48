/* KKT measure of an iterate (docs/algorithm.md section 6): exact derivatives (fresh
 * stage_grad / term_grad at the given point with the given multipliers), never the stored
 * blocks. The module has no state: the iterate, the parameters and the scratch of the
 * generated functions are its arguments. */
#ifndef ROBOT_ARM_KKT_H
#define ROBOT_ARM_KKT_H

#include "robot_arm_funcs.h"

#ifndef ROBOT_ARM_INTERNAL
#define ROBOT_ARM_INTERNAL
#endif

/* Outcome of robot_arm_kkt_measure. */
enum robot_arm_kkt_result {
    ROBOT_ARM_KKT_OK = 0,
    ROBOT_ARM_KKT_FUNCTION = 1, /* a generated function reported failure */
    ROBOT_ARM_KKT_NONFINITE = 2 /* a generated function returned NaN or Inf */
};

/* parts[0..3] = stat, eq, ineq, comp (infinity norms) of the iterate (shapes of
 * robot_arm_solver.h: x (N+1) x nx, u N x nu, lam (N+1) x nx, mu_g N x DIM(ng), mu_b N x nw,
 * mu_bN nx, mu_r DIM(nr), nu DIM(ne), p (N+1) x DIM(np)) for the initial state xhat0. */
ROBOT_ARM_INTERNAL int robot_arm_kkt_measure(const robot_arm_real *x, const robot_arm_real *u, const robot_arm_real *lam,
                                     const robot_arm_real *mu_g, const robot_arm_real *mu_b, const robot_arm_real *mu_bN,
                                     const robot_arm_real *mu_r, const robot_arm_real *nu, const robot_arm_real *p,
                                     const robot_arm_real *xhat0, robot_arm_fun_work *work, robot_arm_real *parts);

/* The relative measure of the same iterate (section 6): max(stat / s_d, eq / s_p, ineq / s_p,
 * comp / (s_d s_p)) with s_d = max(1, the largest multiplier) and s_p = max(1, the largest entry
 * of x and u); parts as written by robot_arm_kkt_measure. */
ROBOT_ARM_INTERNAL robot_arm_real robot_arm_kkt_relative(const robot_arm_real *parts, const robot_arm_real *x,
                                             const robot_arm_real *u, const robot_arm_real *lam,
                                             const robot_arm_real *mu_g, const robot_arm_real *mu_b,
                                             const robot_arm_real *mu_bN, const robot_arm_real *mu_r,
                                             const robot_arm_real *nu);

#endif /* ROBOT_ARM_KKT_H */
