/* The benchmark's solver-neutral QP (docs/algorithm.md section 3), read from the binary file
 * written by bench/qp_bench.py, and the primal solution every solver adapter returns.
 *
 * File layout (all little-endian float64, sizes stored as doubles):
 *   count
 *   per QP: N nx nu ng nr ne
 *           dx0[nx]
 *           per stage k < N: H[nw*nw] a[nw] Phi[nx*nw] b[nx] C[ng*nw] lg[ng] ug[ng]
 *                            lbw[nw] ubw[nw]          (w = (x, u); the x part of stage 0 unused)
 *           terminal:        AN[nx*nx] aN[nx] lbxN[nx] ubxN[nx] R[nr*nx] lr[nr] ur[nr]
 *                            Req[ne*nx] req[ne]
 * Matrices are dense column-major. The QP is
 *   min sum_k 0.5 dw_k' H_k dw_k + a_k' dw_k + 0.5 dx_N' AN dx_N + aN' dx_N
 *   s.t. dx_0 = dx0, dx_{k+1} = Phi_k dw_k + b_k, lbw_k <= dw_k <= ubw_k (k >= 1 for the x part),
 *        lg_k <= C_k dw_k <= ug_k, lbxN <= dx_N <= ubxN, lr <= R dx_N <= ur, Req dx_N = req.
 * Infinite bounds mean "no bound on that side".
 */
#ifndef QP_BENCH_QP_H
#define QP_BENCH_QP_H

#include <stdio.h>

typedef struct {
    int N, nx, nu, ng, nr, ne;
    double *dx0;
    double *H, *a, *Phi, *b, *C, *lg, *ug, *lbw, *ubw; /* stage k at offset k * block size */
    double *AN, *aN, *lbxN, *ubxN, *R, *lr, *ur, *Req, *req;
    double *store; /* one allocation holding every array above */
} bench_qp;

/* Primal solution: x_0 u_0 x_1 u_1 ... x_{N-1} u_{N-1} x_N. */
typedef struct {
    double *dw;
    int n;
} bench_sol;

/* Read one QP; returns 0 on success. */
int bench_qp_read(FILE *f, bench_qp *qp);
void bench_qp_free(bench_qp *qp);
/* Objective value of a primal point. */
double bench_qp_objective(const bench_qp *qp, const double *dw);
/* Largest violation of the constraints at a primal point (inf-norm). */
double bench_qp_infeasibility(const bench_qp *qp, const double *dw);

#endif /* QP_BENCH_QP_H */
