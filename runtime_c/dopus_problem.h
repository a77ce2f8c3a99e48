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
/* the path-row bounds per stage: the declared ones where a row holds, infinite where the
 * OCP leaves it out (path_constraint(stages=...)) */
extern const dopus_real dopus_lg_k[DOPUS_N][DOPUS_DIM(DOPUS_NG)], dopus_ug_k[DOPUS_N][DOPUS_DIM(DOPUS_NG)];
extern const dopus_real dopus_lr[DOPUS_DIM(DOPUS_NR)], dopus_ur[DOPUS_DIM(DOPUS_NR)];
/* the parameters of the first horizon (node k at time k dt; the same at every node unless
 * a parameter declares a trajectory) */
extern const dopus_real dopus_p_default[DOPUS_N + 1][DOPUS_DIM(DOPUS_NP)];
extern const dopus_real dopus_dt;
/* the default initial state, in the declared units (what dopus_init takes) */
extern const dopus_real dopus_x0_default[DOPUS_NX];
/* Scaling (docs/algorithm.md section 16): the solver works with x / dopus_scale_x,
 * u / dopus_scale_u, the path rows over dopus_scale_g, the terminal rows over dopus_scale_r and
 * dopus_scale_req and the cost over dopus_scale_cost (all 1 without a declared scaling); the
 * bounds, the guess and the soft weights here are those of the scaled problem, the API
 * (dopus_solver.h) and x0_default and the nominal solution are in the declared units. */
extern const dopus_real dopus_scale_x[DOPUS_NX], dopus_scale_u[DOPUS_NU];
extern const dopus_real dopus_scale_g[DOPUS_DIM(DOPUS_NG)], dopus_scale_r[DOPUS_DIM(DOPUS_NR)];
extern const dopus_real dopus_scale_req[DOPUS_DIM(DOPUS_NE)];
extern const dopus_real dopus_scale_cost;
/* the OCP file's initial guess (in the solver's variables) */
extern const dopus_real dopus_guess_x[DOPUS_N + 1][DOPUS_NX];
extern const dopus_real dopus_guess_u[DOPUS_N][DOPUS_NU];
/* the rows' names (dopus_row_name): state and control labels, path rows, terminal
 * inequality rows, terminal equality rows */
extern const char *const dopus_row_names_x[DOPUS_NX];
extern const char *const dopus_row_names_u[DOPUS_NU];
extern const char *const dopus_row_names_g[DOPUS_DIM(DOPUS_NG)];
extern const char *const dopus_row_names_r[DOPUS_DIM(DOPUS_NR)];
extern const char *const dopus_row_names_req[DOPUS_DIM(DOPUS_NE)];
/* the memory states of rate constraints: state row dopus_memory_state[i] carries the last
 * applied value of control dopus_memory_control[i] */
extern const int dopus_memory_state[DOPUS_DIM(DOPUS_NMEM)];
extern const int dopus_memory_control[DOPUS_DIM(DOPUS_NMEM)];

#if DOPUS_HAS_P_SCHEDULE
/* the parameters at t = j dt, j = 0..DOPUS_P_SCHEDULE_NODES-1, from the OCP file's
 * trajectories (the standalone main's closed loop pushes them) */
extern const dopus_real dopus_p_schedule[DOPUS_P_SCHEDULE_NODES][DOPUS_NP];
#endif

#if DOPUS_NSOFT > 0
/* soft weights of the state bounds (nodes 1..N), path rows and terminal inequality rows;
 * rows: L1 lower, L1 upper, L2 lower, L2 upper (docs/algorithm.md section 12) */
extern const dopus_real dopus_soft_x[4][DOPUS_NX];
extern const dopus_real dopus_soft_g[4][DOPUS_DIM(DOPUS_NG)];
extern const dopus_real dopus_soft_r[4][DOPUS_DIM(DOPUS_NR)];
#endif

#if DOPUS_HAS_NOMINAL
/* offline primal-dual solution at dopus_x0_default (IPOPT at generation time), so the
 * controller starts warm (docs/design.md section 8); in the declared units */
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
