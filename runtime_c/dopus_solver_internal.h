/* Functions shared by the C files of the solver (dopus_solver.c, dopus_settings.c,
 * dopus_kkt.c); not part of the API (dopus_solver.h). */
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
/* The terminal gradient (term_grad) at the current point: gL (nx), E, r (nr), r_eq (ne).
 * DOPUS_ERR_FUNCTION when the function fails, DOPUS_ERR_NONFINITE_VALUE when a value is not
 * finite, else DOPUS_OK. */
int dopus_term_grad_checked(dopus_solver *s, dopus_real *gL, dopus_real *E, dopus_real *r, dopus_real *r_eq);
/* x_0 carries no bound (docs/algorithm.md section 1): it is fixed by the measurement, so
 * the simple bounds of the states apply at nodes 1..N only (stage 0 passes infinite sides
 * to the QP, the KKT measure counts a multiplier on x_0 with its magnitude) and the x part
 * of mu_b_0 is 0 (dopus_clear_x0_multiplier). */
static inline int dopus_x_bounded(int k)
{
    return k > 0;
}
void dopus_clear_x0_multiplier(dopus_solver *s);
/* Parameters (algorithm.md section 4): DOPUS_OK when they may be written now (before init,
 * or a prepare is due), else DOPUS_ERR_ALREADY_PREPARED; in receding mode with a prepare due,
 * the shift of this sampling instant's parameters is done first (once). */
int dopus_parameters_writable(dopus_solver *s);

#endif /* DOPUS_SOLVER_INTERNAL_H */
