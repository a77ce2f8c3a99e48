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
/* the path-row bounds per stage: the declared ones where a row holds, infinite where the
 * OCP leaves it out (path_constraint(stages=...)) */
extern const robot_arm_real robot_arm_lg_k[ROBOT_ARM_N][ROBOT_ARM_DIM(ROBOT_ARM_NG)], robot_arm_ug_k[ROBOT_ARM_N][ROBOT_ARM_DIM(ROBOT_ARM_NG)];
extern const robot_arm_real robot_arm_lr[ROBOT_ARM_DIM(ROBOT_ARM_NR)], robot_arm_ur[ROBOT_ARM_DIM(ROBOT_ARM_NR)];
/* the parameters of the first horizon (node k at time k dt; the same at every node unless
 * a parameter declares a trajectory) */
extern const robot_arm_real robot_arm_p_default[ROBOT_ARM_N + 1][ROBOT_ARM_DIM(ROBOT_ARM_NP)];
extern const robot_arm_real robot_arm_dt;
/* the default initial state, in the declared units (what robot_arm_init takes) */
extern const robot_arm_real robot_arm_x0_default[ROBOT_ARM_NX];
/* Scaling (docs/algorithm.md section 16): the solver works with x / robot_arm_scale_x,
 * u / robot_arm_scale_u, the path rows over robot_arm_scale_g, the terminal rows over robot_arm_scale_r and
 * robot_arm_scale_req and the cost over robot_arm_scale_cost (all 1 without a declared scaling); the
 * bounds, the guess and the soft weights here are those of the scaled problem, the API
 * (robot_arm_solver.h) and x0_default and the nominal solution are in the declared units. */
extern const robot_arm_real robot_arm_scale_x[ROBOT_ARM_NX], robot_arm_scale_u[ROBOT_ARM_NU];
extern const robot_arm_real robot_arm_scale_g[ROBOT_ARM_DIM(ROBOT_ARM_NG)], robot_arm_scale_r[ROBOT_ARM_DIM(ROBOT_ARM_NR)];
extern const robot_arm_real robot_arm_scale_req[ROBOT_ARM_DIM(ROBOT_ARM_NE)];
extern const robot_arm_real robot_arm_scale_cost;
/* the OCP file's initial guess (in the solver's variables) */
extern const robot_arm_real robot_arm_guess_x[ROBOT_ARM_N + 1][ROBOT_ARM_NX];
extern const robot_arm_real robot_arm_guess_u[ROBOT_ARM_N][ROBOT_ARM_NU];
/* the rows' names (robot_arm_row_name): state and control labels, path rows, terminal
 * inequality rows, terminal equality rows */
extern const char *const robot_arm_row_names_x[ROBOT_ARM_NX];
extern const char *const robot_arm_row_names_u[ROBOT_ARM_NU];
extern const char *const robot_arm_row_names_g[ROBOT_ARM_DIM(ROBOT_ARM_NG)];
extern const char *const robot_arm_row_names_r[ROBOT_ARM_DIM(ROBOT_ARM_NR)];
extern const char *const robot_arm_row_names_req[ROBOT_ARM_DIM(ROBOT_ARM_NE)];
/* the memory states of rate constraints: state row robot_arm_memory_state[i] carries the last
 * applied value of control robot_arm_memory_control[i] */
extern const int robot_arm_memory_state[ROBOT_ARM_DIM(ROBOT_ARM_NMEM)];
extern const int robot_arm_memory_control[ROBOT_ARM_DIM(ROBOT_ARM_NMEM)];

#if ROBOT_ARM_HAS_P_SCHEDULE
/* the parameters at t = j dt, j = 0..ROBOT_ARM_P_SCHEDULE_NODES-1, from the OCP file's
 * trajectories (the standalone main's closed loop pushes them) */
extern const robot_arm_real robot_arm_p_schedule[ROBOT_ARM_P_SCHEDULE_NODES][ROBOT_ARM_NP];
#endif

#if ROBOT_ARM_NSOFT > 0
/* soft weights of the state bounds (nodes 1..N), path rows and terminal inequality rows;
 * rows: L1 lower, L1 upper, L2 lower, L2 upper (docs/algorithm.md section 12) */
extern const robot_arm_real robot_arm_soft_x[4][ROBOT_ARM_NX];
extern const robot_arm_real robot_arm_soft_g[4][ROBOT_ARM_DIM(ROBOT_ARM_NG)];
extern const robot_arm_real robot_arm_soft_r[4][ROBOT_ARM_DIM(ROBOT_ARM_NR)];
#endif

#if ROBOT_ARM_HAS_NOMINAL
/* offline primal-dual solution at robot_arm_x0_default (IPOPT at generation time), so the
 * controller starts warm (docs/design.md section 8); in the declared units */
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
