/* Functions shared by the C files of the solver (robot_arm_solver.c, robot_arm_settings.c,
 * robot_arm_kkt.c); not part of the API (robot_arm_solver.h). */
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
/* The terminal gradient (term_grad) at the current point: gL (nx), E, r (nr), r_eq (ne).
 * ROBOT_ARM_ERR_FUNCTION when the function fails, ROBOT_ARM_ERR_NONFINITE_VALUE when a value is not
 * finite, else ROBOT_ARM_OK. */
int robot_arm_term_grad_checked(robot_arm_solver *s, robot_arm_real *gL, robot_arm_real *E, robot_arm_real *r, robot_arm_real *r_eq);
/* x_0 carries no bound (docs/algorithm.md section 1): it is fixed by the measurement, so
 * the simple bounds of the states apply at nodes 1..N only (stage 0 passes infinite sides
 * to the QP, the KKT measure counts a multiplier on x_0 with its magnitude) and the x part
 * of mu_b_0 is 0 (robot_arm_clear_x0_multiplier). */
static inline int robot_arm_x_bounded(int k)
{
    return k > 0;
}
void robot_arm_clear_x0_multiplier(robot_arm_solver *s);
/* Parameters (algorithm.md section 4): ROBOT_ARM_OK when they may be written now (before init,
 * or a prepare is due), else ROBOT_ARM_ERR_ALREADY_PREPARED; in receding mode with a prepare due,
 * the shift of this sampling instant's parameters is done first (once). */
int robot_arm_parameters_writable(robot_arm_solver *s);

#endif /* ROBOT_ARM_SOLVER_INTERNAL_H */
