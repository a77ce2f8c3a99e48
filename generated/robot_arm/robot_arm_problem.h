/* Problem data generated from the OCP file (robot_arm_problem.c), public and read-only: bounds,
 * the default parameters and x0, the initial guess and, when the OCP asks for it, the
 * offline primal-dual solution at the default x0. (The OCP file's options are the generated
 * settings, robot_arm_settings_default of robot_arm_solver.h, also in robot_arm_problem.c.)
 *
 * Infinite bounds are INFINITY / -INFINITY; the runtime treats them as "no bound on that side"
 * (docs/algorithm.md section 1). Sizes of possibly empty arrays use ROBOT_ARM_DIM so that every
 * array has at least one element (C99 forbids zero-length arrays).
 */
#ifndef ROBOT_ARM_PROBLEM_H
#define ROBOT_ARM_PROBLEM_H

#include "robot_arm_sizes.h"

extern const robot_arm_real robot_arm_lbx[ROBOT_ARM_NX], robot_arm_ubx[ROBOT_ARM_NX];
extern const robot_arm_real robot_arm_lbu[ROBOT_ARM_NU], robot_arm_ubu[ROBOT_ARM_NU];
extern const robot_arm_real robot_arm_lg[ROBOT_ARM_DIM(ROBOT_ARM_NG)], robot_arm_ug[ROBOT_ARM_DIM(ROBOT_ARM_NG)];
extern const robot_arm_real robot_arm_lr[ROBOT_ARM_DIM(ROBOT_ARM_NR)], robot_arm_ur[ROBOT_ARM_DIM(ROBOT_ARM_NR)];
extern const robot_arm_real robot_arm_p_default[ROBOT_ARM_DIM(ROBOT_ARM_NP)]; /* every node */
extern const robot_arm_real robot_arm_dt;
extern const robot_arm_real robot_arm_x0_default[ROBOT_ARM_NX];
/* the OCP file's initial guess */
extern const robot_arm_real robot_arm_guess_x[ROBOT_ARM_N + 1][ROBOT_ARM_NX];
extern const robot_arm_real robot_arm_guess_u[ROBOT_ARM_N][ROBOT_ARM_NU];

#if ROBOT_ARM_NSOFT > 0
/* soft weights of the state bounds (nodes 1..N), path rows and terminal inequality rows;
 * rows: L1 lower, L1 upper, L2 lower, L2 upper (docs/algorithm.md section 12) */
extern const robot_arm_real robot_arm_soft_x[4][ROBOT_ARM_NX];
extern const robot_arm_real robot_arm_soft_g[4][ROBOT_ARM_DIM(ROBOT_ARM_NG)];
extern const robot_arm_real robot_arm_soft_r[4][ROBOT_ARM_DIM(ROBOT_ARM_NR)];
#endif

#if ROBOT_ARM_HAS_NOMINAL
/* offline primal-dual solution at robot_arm_x0_default (IPOPT at generation time), so the
 * controller starts warm (docs/design.md section 8) */
extern const robot_arm_real robot_arm_nominal_x[ROBOT_ARM_N + 1][ROBOT_ARM_NX];
extern const robot_arm_real robot_arm_nominal_u[ROBOT_ARM_N][ROBOT_ARM_NU];
extern const robot_arm_real robot_arm_nominal_lam[ROBOT_ARM_N + 1][ROBOT_ARM_NX];
extern const robot_arm_real robot_arm_nominal_mu_g[ROBOT_ARM_N][ROBOT_ARM_DIM(ROBOT_ARM_NG)];
extern const robot_arm_real robot_arm_nominal_mu_b[ROBOT_ARM_N][ROBOT_ARM_NW];
extern const robot_arm_real robot_arm_nominal_mu_bN[ROBOT_ARM_NX];
extern const robot_arm_real robot_arm_nominal_mu_r[ROBOT_ARM_DIM(ROBOT_ARM_NR)];
extern const robot_arm_real robot_arm_nominal_nu[ROBOT_ARM_DIM(ROBOT_ARM_NE)];
#endif

#endif /* ROBOT_ARM_PROBLEM_H */
