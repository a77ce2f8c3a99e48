/* Small dense column-major linear algebra, see dopus_linalg.h: the linkable versions of
 * the inline kernels of the header. */
#include "dopus_linalg.h"

int dopus_la_potrf_l(int n, dopus_real *A, int lda)
{
    return dopus_lai_potrf_l(n, A, lda);
}

int dopus_la_potrf_l_noise(int n, dopus_real *A, int lda, const dopus_real *noise, int *nfloor)
{
    return dopus_lai_potrf_l_noise(n, A, lda, noise, nfloor);
}

int dopus_la_ldlt_l(int n, dopus_real *A, int lda, int *neg)
{
    return dopus_lai_ldlt_l(n, A, lda, neg);
}

void dopus_la_trsv_ln(int n, const dopus_real *L, int ldl, dopus_real *x)
{
    dopus_lai_trsv_ln(n, L, ldl, x);
}

void dopus_la_trsv_lt(int n, const dopus_real *L, int ldl, dopus_real *x)
{
    dopus_lai_trsv_lt(n, L, ldl, x);
}

void dopus_la_trsm_lln(int n, int m, const dopus_real *L, int ldl, dopus_real *B, int ldb)
{
    dopus_lai_trsm_lln(n, m, L, ldl, B, ldb);
}

void dopus_la_trsm_llt(int n, int m, const dopus_real *L, int ldl, dopus_real *B, int ldb)
{
    dopus_lai_trsm_llt(n, m, L, ldl, B, ldb);
}

void dopus_la_gemv_n(int m, int n, dopus_real alpha, const dopus_real *A, int lda, const dopus_real *x,
                     dopus_real beta, dopus_real *y)
{
    dopus_lai_gemv_n(m, n, alpha, A, lda, x, beta, y);
}

void dopus_la_gemv_t(int m, int n, dopus_real alpha, const dopus_real *A, int lda, const dopus_real *x,
                     dopus_real beta, dopus_real *y)
{
    dopus_lai_gemv_t(m, n, alpha, A, lda, x, beta, y);
}

void dopus_la_symv_l(int n, dopus_real alpha, const dopus_real *A, int lda, const dopus_real *x,
                     dopus_real beta, dopus_real *y)
{
    dopus_lai_symv_l(n, alpha, A, lda, x, beta, y);
}

void dopus_la_gemm_nn(int m, int n, int k, dopus_real alpha, const dopus_real *A, int lda,
                      const dopus_real *B, int ldb, dopus_real beta, dopus_real *C, int ldc)
{
    dopus_lai_gemm_nn(m, n, k, alpha, A, lda, B, ldb, beta, C, ldc);
}

void dopus_la_gemm_tn(int m, int n, int k, dopus_real alpha, const dopus_real *A, int lda,
                      const dopus_real *B, int ldb, dopus_real beta, dopus_real *C, int ldc)
{
    dopus_lai_gemm_tn(m, n, k, alpha, A, lda, B, ldb, beta, C, ldc);
}

void dopus_la_copy_mat(int m, int n, const dopus_real *A, int lda, dopus_real *B, int ldb)
{
    dopus_lai_copy_mat(m, n, A, lda, B, ldb);
}

void dopus_la_symmetrize_l(int n, dopus_real *A, int lda)
{
    dopus_lai_symmetrize_l(n, A, lda);
}

dopus_real dopus_la_dot(int n, const dopus_real *x, const dopus_real *y)
{
    return dopus_lai_dot(n, x, y);
}

void dopus_la_axpy(int n, dopus_real alpha, const dopus_real *x, dopus_real *y)
{
    dopus_lai_axpy(n, alpha, x, y);
}

dopus_real dopus_la_norm_inf(int n, const dopus_real *x)
{
    return dopus_lai_norm_inf(n, x);
}

dopus_real dopus_la_max_abs_mat(int m, int n, const dopus_real *A, int lda)
{
    return dopus_lai_max_abs_mat(m, n, A, lda);
}

int dopus_la_all_finite(int m, int n, const dopus_real *A, int lda)
{
    return dopus_lai_all_finite(m, n, A, lda);
}
