/* KKT measure of the current iterate (docs/algorithm.md section 6): exact derivatives
 * (fresh stage_grad / term_grad at the current point with the current multipliers), never
 * the stored blocks. */
#ifndef DOPUS_KKT_H
#define DOPUS_KKT_H

#include "dopus_real.h"

struct dopus_solver;

/* parts[0..3] = stat, eq, ineq, comp (infinity norms). Returns a status of enum
 * dopus_status (DOPUS_OK, DOPUS_ERR_FUNCTION or DOPUS_ERR_NONFINITE_VALUE). The iterate and
 * the stage slots are not touched; only the function scratch of the solver is used. */
int dopus_kkt_measure(struct dopus_solver *s, const dopus_real *xhat0, dopus_real *parts);

#endif /* DOPUS_KKT_H */
