/* KKT measure of the current iterate (docs/algorithm.md section 6): exact derivatives
 * (fresh stage_grad / term_grad at the current point with the current multipliers), never
 * the stored blocks. */
#ifndef UNICYCLE_KKT_H
#define UNICYCLE_KKT_H

#include "unicycle_real.h"

struct unicycle_solver;

/* parts[0..3] = stat, eq, ineq, comp (infinity norms). Returns a status of enum
 * unicycle_status (UNICYCLE_OK, UNICYCLE_ERR_FUNCTION or UNICYCLE_ERR_NONFINITE_VALUE). The iterate and
 * the stage slots are not touched; only the function scratch of the solver is used. */
int unicycle_kkt_measure(struct unicycle_solver *s, const unicycle_real *xhat0, unicycle_real *parts);

#endif /* UNICYCLE_KKT_H */
