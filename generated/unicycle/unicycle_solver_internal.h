/* Functions shared by the C files of the solver (unicycle_solver.c, unicycle_settings.c,
 * unicycle_kkt.c); not part of the API (unicycle_solver.h). */
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
/* The terminal gradient (term_grad) at the current point: gL (nx), E, r (nr), r_eq (ne).
 * UNICYCLE_ERR_FUNCTION when the function fails, UNICYCLE_ERR_NONFINITE_VALUE when a value is not
 * finite, else UNICYCLE_OK. */
int unicycle_term_grad_checked(unicycle_solver *s, unicycle_real *gL, unicycle_real *E, unicycle_real *r, unicycle_real *r_eq);
/* x_0 carries no bound (docs/algorithm.md section 1): it is fixed by the measurement, so
 * the simple bounds of the states apply at nodes 1..N only (stage 0 passes infinite sides
 * to the QP, the KKT measure counts a multiplier on x_0 with its magnitude) and the x part
 * of mu_b_0 is 0 (unicycle_clear_x0_multiplier). */
static inline int unicycle_x_bounded(int k)
{
    return k > 0;
}
void unicycle_clear_x0_multiplier(unicycle_solver *s);
/* Parameters (algorithm.md section 4): UNICYCLE_OK when they may be written now (before init,
 * or a prepare is due), else UNICYCLE_ERR_ALREADY_PREPARED; in receding mode with a prepare due,
 * the shift of this sampling instant's parameters is done first (once). */
int unicycle_parameters_writable(unicycle_solver *s);

#endif /* UNICYCLE_SOLVER_INTERNAL_H */
