/* Small dense linear algebra on column-major matrices (leading dimension `ld*`).
 *
 * Generic helpers for fixed-size stage blocks: no allocation, no size limits beyond the
 * caller's arrays. Naming follows BLAS/LAPACK (potrf, trsm, gemm, ...) so the intent of a
 * call is clear; there is no BLAS behind it.
 */
#ifndef DOPUS_LINALG_H
#define DOPUS_LINALG_H

/* In-place lower Cholesky factorisation A = L L' of the n x n symmetric matrix A (only the
 * lower triangle is read and written). Returns 0 on success, or j+1 when pivot j is not
 * positive or not finite (A is then partially overwritten). */
int dopus_la_potrf_l(int n, double *A, int lda);

/* As dopus_la_potrf_l, but a pivot d with -noise[j] <= d <= 0 (noise: absolute round-off
 * estimate of the diagonal entry, n values; NULL means 0) is taken as a numerical zero and
 * replaced by max(noise[j], DBL_EPSILON |A_jj|); *nfloor (if not NULL) counts them. Only
 * pivots below -noise[j] (or non-finite) fail; positive pivots are never changed. */
int dopus_la_potrf_l_noise(int n, double *A, int lda, const double *noise, int *nfloor);

/* In-place L D L' factorisation (unit lower L, diagonal D stored on the diagonal) of the
 * symmetric n x n matrix A, no pivoting. Returns 0 on success, j+1 on a zero/non-finite
 * pivot. The number of negative pivots is written to *neg when neg is not NULL. */
int dopus_la_ldlt_l(int n, double *A, int lda, int *neg);

/* Solve L x = b (trsv_ln) or L' x = b (trsv_lt) in place, L lower triangular n x n. */
void dopus_la_trsv_ln(int n, const double *L, int ldl, double *x);
void dopus_la_trsv_lt(int n, const double *L, int ldl, double *x);

/* B <- L^{-1} B for the n x m matrix B (trsm_lln) or B <- L'^{-1} B (trsm_llt). */
void dopus_la_trsm_lln(int n, int m, const double *L, int ldl, double *B, int ldb);
void dopus_la_trsm_llt(int n, int m, const double *L, int ldl, double *B, int ldb);

/* y <- alpha A x + beta y, A m x n (gemv_n);  y <- alpha A' x + beta y (gemv_t, y of size n).
 * beta == 0 overwrites y without reading it. */
void dopus_la_gemv_n(int m, int n, double alpha, const double *A, int lda, const double *x,
                     double beta, double *y);
void dopus_la_gemv_t(int m, int n, double alpha, const double *A, int lda, const double *x,
                     double beta, double *y);

/* y <- alpha A x + beta y for symmetric n x n A of which only the lower triangle is read. */
void dopus_la_symv_l(int n, double alpha, const double *A, int lda, const double *x,
                     double beta, double *y);

/* C <- alpha A B + beta C (gemm_nn: A m x k, B k x n); C <- alpha A' B + beta C (gemm_tn:
 * A k x m, B k x n). C is m x n. beta == 0 overwrites C without reading it. */
void dopus_la_gemm_nn(int m, int n, int k, double alpha, const double *A, int lda,
                      const double *B, int ldb, double beta, double *C, int ldc);
void dopus_la_gemm_tn(int m, int n, int k, double alpha, const double *A, int lda,
                      const double *B, int ldb, double beta, double *C, int ldc);

/* Copy the m x n matrix A into B. */
void dopus_la_copy_mat(int m, int n, const double *A, int lda, double *B, int ldb);

/* Mirror the lower triangle of the n x n matrix A into its upper triangle. */
void dopus_la_symmetrize_l(int n, double *A, int lda);

/* Vector helpers. */
double dopus_la_dot(int n, const double *x, const double *y);
void dopus_la_axpy(int n, double alpha, const double *x, double *y);
double dopus_la_norm_inf(int n, const double *x);
/* Infinity norm of the m x n matrix A (largest absolute entry, not the operator norm). */
double dopus_la_max_abs_mat(int m, int n, const double *A, int lda);
/* 1 when all m x n entries are finite, else 0. */
int dopus_la_all_finite(int m, int n, const double *A, int lda);

#endif /* DOPUS_LINALG_H */
