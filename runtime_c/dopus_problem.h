/* Problem data generated from the OCP file (dopus_problem.c), public and read-only: bounds,
 * the default parameters and x0, the initial guess and, when the OCP asks for it, the
 * offline primal-dual solution at the default x0. (The OCP file's options are the generated
 * settings, dopus_settings_default of dopus_solver.h, also in dopus_problem.c.)
 *
 * Infinite bounds are INFINITY / -INFINITY; the runtime treats them as "no bound on that side"
 * (docs/algorithm.md section 1). Sizes of possibly empty arrays use DOPUS_DIM so that every
 * array has at least one element (C99 forbids zero-length arrays).
 */
#ifndef DOPUS_PROBLEM_H
#define DOPUS_PROBLEM_H

#include "dopus_sizes.h"

extern const dopus_real dopus_lbx[DOPUS_NX], dopus_ubx[DOPUS_NX];
extern const dopus_real dopus_lbu[DOPUS_NU], dopus_ubu[DOPUS_NU];
extern const dopus_real dopus_lg[DOPUS_DIM(DOPUS_NG)], dopus_ug[DOPUS_DIM(DOPUS_NG)];
extern const dopus_real dopus_lr[DOPUS_DIM(DOPUS_NR)], dopus_ur[DOPUS_DIM(DOPUS_NR)];
extern const dopus_real dopus_p_default[DOPUS_DIM(DOPUS_NP)]; /* every node */
extern const dopus_real dopus_dt;
extern const dopus_real dopus_x0_default[DOPUS_NX];
/* the OCP file's initial guess */
extern const dopus_real dopus_guess_x[DOPUS_N + 1][DOPUS_NX];
extern const dopus_real dopus_guess_u[DOPUS_N][DOPUS_NU];

#if DOPUS_NSOFT > 0
/* soft weights of the state bounds (nodes 1..N), path rows and terminal inequality rows;
 * rows: L1 lower, L1 upper, L2 lower, L2 upper (docs/algorithm.md section 12) */
extern const dopus_real dopus_soft_x[4][DOPUS_NX];
extern const dopus_real dopus_soft_g[4][DOPUS_DIM(DOPUS_NG)];
extern const dopus_real dopus_soft_r[4][DOPUS_DIM(DOPUS_NR)];
#endif

#if DOPUS_HAS_NOMINAL
/* offline primal-dual solution at dopus_x0_default (IPOPT at generation time), so the
 * controller starts warm (docs/design.md section 8) */
extern const dopus_real dopus_nominal_x[DOPUS_N + 1][DOPUS_NX];
extern const dopus_real dopus_nominal_u[DOPUS_N][DOPUS_NU];
extern const dopus_real dopus_nominal_lam[DOPUS_N + 1][DOPUS_NX];
extern const dopus_real dopus_nominal_mu_g[DOPUS_N][DOPUS_DIM(DOPUS_NG)];
extern const dopus_real dopus_nominal_mu_b[DOPUS_N][DOPUS_NW];
extern const dopus_real dopus_nominal_mu_bN[DOPUS_NX];
extern const dopus_real dopus_nominal_mu_r[DOPUS_DIM(DOPUS_NR)];
extern const dopus_real dopus_nominal_nu[DOPUS_DIM(DOPUS_NE)];
#endif

#endif /* DOPUS_PROBLEM_H */
