/* Functions shared by the C files of the solver (dopus_solver.c, dopus_settings.c); not part
 * of the API (dopus_solver.h). */
#ifndef DOPUS_SOLVER_INTERNAL_H
#define DOPUS_SOLVER_INTERNAL_H

#include "dopus_solver.h"

/* dopus_defaults on a struct that was never set up (no DOPUS_MAGIC). */
void dopus_ensure_setup(dopus_solver *s);
/* Record status as the status of the last call and return it. */
int dopus_ret(dopus_solver *s, int status);
/* The automatic Levenberg-Marquardt term after init or a re-initialisation (QP assembled):
 * the Hessian scale, lm raised from 0 until the QP is convex on the dynamics. */
void dopus_lm_start(dopus_solver *s);

#endif /* DOPUS_SOLVER_INTERNAL_H */
