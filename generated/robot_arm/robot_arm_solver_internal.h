/* Functions shared by the C files of the solver (robot_arm_solver.c, robot_arm_settings.c); not part
 * of the API (robot_arm_solver.h). */
#ifndef ROBOT_ARM_SOLVER_INTERNAL_H
#define ROBOT_ARM_SOLVER_INTERNAL_H

#include "robot_arm_solver.h"

/* robot_arm_defaults on a struct that was never set up (no ROBOT_ARM_MAGIC). */
void robot_arm_ensure_setup(robot_arm_solver *s);
/* Record status as the status of the last call and return it. */
int robot_arm_ret(robot_arm_solver *s, int status);
/* The automatic Levenberg-Marquardt term after init or a re-initialisation (QP assembled):
 * the Hessian scale, lm raised from 0 until the QP is convex on the dynamics. */
void robot_arm_lm_start(robot_arm_solver *s);

#endif /* ROBOT_ARM_SOLVER_INTERNAL_H */
