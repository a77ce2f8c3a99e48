/* HPIPM (OCP QP interior point, C API) as a solver of the benchmark QP. */
#ifndef QP_BENCH_HPIPM_H
#define QP_BENCH_HPIPM_H

#include "qp_bench_qp.h"

typedef struct {
    int mode;      /* enum hpipm_mode: 0 SPEED_ABS, 1 SPEED, 2 BALANCE, 3 ROBUST */
    double tol;    /* tol_stat = tol_eq = tol_ineq = tol_comp */
    int iter_max;
    int eq_mask;   /* 1: x0 and the terminal equality rows declared in HPIPM's equality mask */
    double eq_scale; /* > 0: terminal equality rows divided by eq_scale * their inf-norm */
    int ric_alg;   /* -1: the mode's default (square-root Riccati, needs P > 0),
                      0: classic Riccati (indefinite blocks with a positive reduced Hessian) */
} bench_hpipm_opts;

typedef struct bench_hpipm bench_hpipm;

/* Build HPIPM's QP from qp (not timed); NULL on failure. */
bench_hpipm *bench_hpipm_create(const bench_qp *qp, const bench_hpipm_opts *opts);
/* Copy the QP data into HPIPM's structures again (what a controller does every sample). */
void bench_hpipm_set_data(bench_hpipm *h, const bench_qp *qp);
/* One solve from HPIPM's default initialisation; returns HPIPM's status (0 success,
 * 1 max iterations, 2 min step, 3 NaN, 4 inconsistent equality). */
int bench_hpipm_solve(bench_hpipm *h);
int bench_hpipm_iterations(const bench_hpipm *h);
/* Residuals of the last solve as HPIPM measures them: stat, eq, ineq, comp. */
void bench_hpipm_residuals(bench_hpipm *h, double res[4]);
void bench_hpipm_primal(bench_hpipm *h, double *dw); /* layout of bench_sol */
void bench_hpipm_free(bench_hpipm *h);

#endif /* QP_BENCH_HPIPM_H */
