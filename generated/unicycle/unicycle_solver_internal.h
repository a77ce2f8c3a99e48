/* Functions shared by the C files of the solver (unicycle_solver.c, unicycle_settings.c); not part
 * of the API (unicycle_solver.h). */
#ifndef UNICYCLE_SOLVER_INTERNAL_H
#define UNICYCLE_SOLVER_INTERNAL_H

#include "unicycle_solver.h"

/* unicycle_defaults on a struct that was never set up (no UNICYCLE_MAGIC). */
void unicycle_ensure_setup(unicycle_solver *s);
/* Record status as the status of the last call and return it. */
int unicycle_ret(unicycle_solver *s, int status);
/* The automatic Levenberg-Marquardt term after init or a re-initialisation (QP assembled):
 * the Hessian scale, lm raised from 0 until the QP is convex on the dynamics. */
void unicycle_lm_start(unicycle_solver *s);

#endif /* UNICYCLE_SOLVER_INTERNAL_H */
