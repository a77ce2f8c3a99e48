/* Our stage-wise QP solver (runtime_c/dopus_qp.h) as a solver of the benchmark QP.
 * Compiled once per problem size: dopus_sizes.h of the build folder fixes N, nx, nu, ... */
#ifndef QP_BENCH_DOPUS_H
#define QP_BENCH_DOPUS_H

#include "qp_bench_qp.h"

typedef struct bench_dopus bench_dopus;

/* NULL when the QP's sizes differ from the compiled ones. */
bench_dopus *bench_dopus_create(const bench_qp *qp, double tol, int iter_max);
/* Vectors copied into dopus_qp_in; matrices handed over by pointer (as the ring buffer does). */
void bench_dopus_set_data(bench_dopus *d, const bench_qp *qp);
int bench_dopus_solve(bench_dopus *d); /* enum dopus_qp_status */
int bench_dopus_iterations(const bench_dopus *d);
/* Unscaled final residuals stat, eq, ineq, comp; returns 0. */
int bench_dopus_residuals(const bench_dopus *d, double res[4]);
void bench_dopus_primal(const bench_dopus *d, double *dw);
/* inertia corrections and terminal augmentations of the last solve */
void bench_dopus_corrections(const bench_dopus *d, int *inertia, int *augment);
/* Factorisations of the Riccati recursion of the last solve (interior-point iterations,
 * inertia corrections, sweeps of the active-set start). */
int bench_dopus_factorizations(const bench_dopus *d);
/* The closed loop's warm start on a sequence of QPs (the warm point of dopus_solver.c):
 * the multipliers of the previous QP's solution, the primal point zero but x_0 = dx0 of the
 * QP, settings.warm_start and the active-set start on. bench_dopus_warm_keep stores the
 * solution of a solver; bench_dopus_warm_use makes a solver start every solve from the kept
 * one (NULL, or nothing kept yet: the cold start). */
typedef struct bench_dopus_warm bench_dopus_warm;
bench_dopus_warm *bench_dopus_warm_new(void);
void bench_dopus_warm_reset(bench_dopus_warm *w);
void bench_dopus_warm_keep(bench_dopus_warm *w, const bench_dopus *d);
void bench_dopus_warm_use(bench_dopus *d, const bench_dopus_warm *w);
void bench_dopus_warm_free(bench_dopus_warm *w);
void bench_dopus_free(bench_dopus *d);

#endif /* QP_BENCH_DOPUS_H */
