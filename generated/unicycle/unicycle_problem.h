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
/* the path-row bounds per stage: the declared ones where a row holds, infinite where the
 * OCP leaves it out (path_constraint(stages=...)) */
extern const unicycle_real unicycle_lg_k[UNICYCLE_N][UNICYCLE_DIM(UNICYCLE_NG)], unicycle_ug_k[UNICYCLE_N][UNICYCLE_DIM(UNICYCLE_NG)];
extern const unicycle_real unicycle_lr[UNICYCLE_DIM(UNICYCLE_NR)], unicycle_ur[UNICYCLE_DIM(UNICYCLE_NR)];
/* the parameters of the first horizon (node k at time k dt; the same at every node unless
 * a parameter declares a trajectory) */
extern const unicycle_real unicycle_p_default[UNICYCLE_N + 1][UNICYCLE_DIM(UNICYCLE_NP)];
extern const unicycle_real unicycle_dt;
/* the default initial state, in the declared units (what unicycle_init takes) */
extern const unicycle_real unicycle_x0_default[UNICYCLE_NX];
/* Scaling (docs/algorithm.md section 16): the solver works with x / unicycle_scale_x,
 * u / unicycle_scale_u, the path rows over unicycle_scale_g, the terminal rows over unicycle_scale_r and
 * unicycle_scale_req and the cost over unicycle_scale_cost (all 1 without a declared scaling); the
 * bounds, the guess and the soft weights here are those of the scaled problem, the API
 * (unicycle_solver.h) and x0_default and the nominal solution are in the declared units. */
extern const unicycle_real unicycle_scale_x[UNICYCLE_NX], unicycle_scale_u[UNICYCLE_NU];
extern const unicycle_real unicycle_scale_g[UNICYCLE_DIM(UNICYCLE_NG)], unicycle_scale_r[UNICYCLE_DIM(UNICYCLE_NR)];
extern const unicycle_real unicycle_scale_req[UNICYCLE_DIM(UNICYCLE_NE)];
extern const unicycle_real unicycle_scale_cost;
/* the OCP file's initial guess (in the solver's variables) */
extern const unicycle_real unicycle_guess_x[UNICYCLE_N + 1][UNICYCLE_NX];
extern const unicycle_real unicycle_guess_u[UNICYCLE_N][UNICYCLE_NU];
/* the rows' names (unicycle_row_name): state and control labels, path rows, terminal
 * inequality rows, terminal equality rows */
extern const char *const unicycle_row_names_x[UNICYCLE_NX];
extern const char *const unicycle_row_names_u[UNICYCLE_NU];
extern const char *const unicycle_row_names_g[UNICYCLE_DIM(UNICYCLE_NG)];
extern const char *const unicycle_row_names_r[UNICYCLE_DIM(UNICYCLE_NR)];
extern const char *const unicycle_row_names_req[UNICYCLE_DIM(UNICYCLE_NE)];
/* the memory states of rate constraints: state row unicycle_memory_state[i] carries the last
 * applied value of control unicycle_memory_control[i] */
extern const int unicycle_memory_state[UNICYCLE_DIM(UNICYCLE_NMEM)];
extern const int unicycle_memory_control[UNICYCLE_DIM(UNICYCLE_NMEM)];

#if UNICYCLE_HAS_P_SCHEDULE
/* the parameters at t = j dt, j = 0..UNICYCLE_P_SCHEDULE_NODES-1, from the OCP file's
 * trajectories (the standalone main's closed loop pushes them) */
extern const unicycle_real unicycle_p_schedule[UNICYCLE_P_SCHEDULE_NODES][UNICYCLE_NP];
#endif

#if UNICYCLE_NSOFT > 0
/* soft weights of the state bounds (nodes 1..N), path rows and terminal inequality rows;
 * rows: L1 lower, L1 upper, L2 lower, L2 upper (docs/algorithm.md section 12) */
extern const unicycle_real unicycle_soft_x[4][UNICYCLE_NX];
extern const unicycle_real unicycle_soft_g[4][UNICYCLE_DIM(UNICYCLE_NG)];
extern const unicycle_real unicycle_soft_r[4][UNICYCLE_DIM(UNICYCLE_NR)];
#endif

#if UNICYCLE_HAS_NOMINAL
/* offline primal-dual solution at unicycle_x0_default (IPOPT at generation time), so the
 * controller starts warm (docs/design.md section 8); in the declared units */
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
