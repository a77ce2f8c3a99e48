/* Problem data generated from the OCP file (unicycle_problem.c), public and read-only: bounds,
 * the default parameters and x0, the initial guess and, when the OCP asks for it, the
 * offline primal-dual solution at the default x0. (The OCP file's options are the generated
 * settings, unicycle_settings_default of unicycle_solver.h, also in unicycle_problem.c.)
 *
 * Infinite bounds are INFINITY / -INFINITY; the runtime treats them as "no bound on that side"
 * (docs/algorithm.md section 1). Sizes of possibly empty arrays use UNICYCLE_DIM so that every
 * array has at least one element (C99 forbids zero-length arrays).
 */
#ifndef UNICYCLE_PROBLEM_H
#define UNICYCLE_PROBLEM_H

#include "unicycle_sizes.h"

extern const unicycle_real unicycle_lbx[UNICYCLE_NX], unicycle_ubx[UNICYCLE_NX];
extern const unicycle_real unicycle_lbu[UNICYCLE_NU], unicycle_ubu[UNICYCLE_NU];
extern const unicycle_real unicycle_lg[UNICYCLE_DIM(UNICYCLE_NG)], unicycle_ug[UNICYCLE_DIM(UNICYCLE_NG)];
extern const unicycle_real unicycle_lr[UNICYCLE_DIM(UNICYCLE_NR)], unicycle_ur[UNICYCLE_DIM(UNICYCLE_NR)];
extern const unicycle_real unicycle_p_default[UNICYCLE_DIM(UNICYCLE_NP)]; /* every node */
extern const unicycle_real unicycle_dt;
extern const unicycle_real unicycle_x0_default[UNICYCLE_NX];
/* the OCP file's initial guess */
extern const unicycle_real unicycle_guess_x[UNICYCLE_N + 1][UNICYCLE_NX];
extern const unicycle_real unicycle_guess_u[UNICYCLE_N][UNICYCLE_NU];

#if UNICYCLE_NSOFT > 0
/* soft weights of the state bounds (nodes 1..N), path rows and terminal inequality rows;
 * rows: L1 lower, L1 upper, L2 lower, L2 upper (docs/algorithm.md section 12) */
extern const unicycle_real unicycle_soft_x[4][UNICYCLE_NX];
extern const unicycle_real unicycle_soft_g[4][UNICYCLE_DIM(UNICYCLE_NG)];
extern const unicycle_real unicycle_soft_r[4][UNICYCLE_DIM(UNICYCLE_NR)];
#endif

#if UNICYCLE_HAS_NOMINAL
/* offline primal-dual solution at unicycle_x0_default (IPOPT at generation time), so the
 * controller starts warm (docs/design.md section 8) */
extern const unicycle_real unicycle_nominal_x[UNICYCLE_N + 1][UNICYCLE_NX];
extern const unicycle_real unicycle_nominal_u[UNICYCLE_N][UNICYCLE_NU];
extern const unicycle_real unicycle_nominal_lam[UNICYCLE_N + 1][UNICYCLE_NX];
extern const unicycle_real unicycle_nominal_mu_g[UNICYCLE_N][UNICYCLE_DIM(UNICYCLE_NG)];
extern const unicycle_real unicycle_nominal_mu_b[UNICYCLE_N][UNICYCLE_NW];
extern const unicycle_real unicycle_nominal_mu_bN[UNICYCLE_NX];
extern const unicycle_real unicycle_nominal_mu_r[UNICYCLE_DIM(UNICYCLE_NR)];
extern const unicycle_real unicycle_nominal_nu[UNICYCLE_DIM(UNICYCLE_NE)];
#endif

#endif /* UNICYCLE_PROBLEM_H */
