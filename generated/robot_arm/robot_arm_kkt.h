/* KKT measure of the current iterate (docs/algorithm.md section 6): exact derivatives
 * (fresh stage_grad / term_grad at the current point with the current multipliers), never
 * the stored blocks. */
#ifndef ROBOT_ARM_KKT_H
#define ROBOT_ARM_KKT_H

#include "robot_arm_real.h"

struct robot_arm_solver;

/* parts[0..3] = stat, eq, ineq, comp (infinity norms). Returns a status of enum
 * robot_arm_status (ROBOT_ARM_OK, ROBOT_ARM_ERR_FUNCTION or ROBOT_ARM_ERR_NONFINITE_VALUE). The iterate and
 * the stage slots are not touched; only the function scratch of the solver is used. */
int robot_arm_kkt_measure(struct robot_arm_solver *s, const robot_arm_real *xhat0, robot_arm_real *parts);

#endif /* ROBOT_ARM_KKT_H */
