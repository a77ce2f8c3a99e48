/* Small dense column-major linear algebra, see unicycle_linalg.h: the linkable versions of
 * the inline kernels of the header. */
#include "unicycle_linalg.h"

int unicycle_la_potrf_l(int n, unicycle_real *A, int lda)
{
    return unicycle_lai_potrf_l(n, A, lda);
}

int unicycle_la_potrf_l_noise(int n, unicycle_real *A, int lda, const unicycle_real *noise, int *nfloor)
{
    return unicycle_lai_potrf_l_noise(n, A, lda, noise, nfloor);
}

int unicycle_la_ldlt_l(int n, unicycle_real *A, int lda, int *neg)
{
    return unicycle_lai_ldlt_l(n, A, lda, neg);
}

void unicycle_la_trsv_ln(int n, const unicycle_real *L, int ldl, unicycle_real *x)
{
    unicycle_lai_trsv_ln(n, L, ldl, x);
}

void unicycle_la_trsv_lt(int n, const unicycle_real *L, int ldl, unicycle_real *x)
{
    unicycle_lai_trsv_lt(n, L, ldl, x);
}

void unicycle_la_trsm_lln(int n, int m, const unicycle_real *L, int ldl, unicycle_real *B, int ldb)
{
    unicycle_lai_trsm_lln(n, m, L, ldl, B, ldb);
}

void unicycle_la_trsm_llt(int n, int m, const unicycle_real *L, int ldl, unicycle_real *B, int ldb)
{
    unicycle_lai_trsm_llt(n, m, L, ldl, B, ldb);
}

void unicycle_la_gemv_n(int m, int n, unicycle_real alpha, const unicycle_real *A, int lda, const unicycle_real *x,
                     unicycle_real beta, unicycle_real *y)
{
    unicycle_lai_gemv_n(m, n, alpha, A, lda, x, beta, y);
}

void unicycle_la_gemv_t(int m, int n, unicycle_real alpha, const unicycle_real *A, int lda, const unicycle_real *x,
                     unicycle_real beta, unicycle_real *y)
{
    unicycle_lai_gemv_t(m, n, alpha, A, lda, x, beta, y);
}

void unicycle_la_symv_l(int n, unicycle_real alpha, const unicycle_real *A, int lda, const unicycle_real *x,
                     unicycle_real beta, unicycle_real *y)
{
    unicycle_lai_symv_l(n, alpha, A, lda, x, beta, y);
}

void unicycle_la_gemm_nn(int m, int n, int k, unicycle_real alpha, const unicycle_real *A, int lda,
                      const unicycle_real *B, int ldb, unicycle_real beta, unicycle_real *C, int ldc)
{
    unicycle_lai_gemm_nn(m, n, k, alpha, A, lda, B, ldb, beta, C, ldc);
}

void unicycle_la_gemm_tn(int m, int n, int k, unicycle_real alpha, const unicycle_real *A, int lda,
                      const unicycle_real *B, int ldb, unicycle_real beta, unicycle_real *C, int ldc)
{
    unicycle_lai_gemm_tn(m, n, k, alpha, A, lda, B, ldb, beta, C, ldc);
}

void unicycle_la_copy_mat(int m, int n, const unicycle_real *A, int lda, unicycle_real *B, int ldb)
{
    unicycle_lai_copy_mat(m, n, A, lda, B, ldb);
}

void unicycle_la_symmetrize_l(int n, unicycle_real *A, int lda)
{
    unicycle_lai_symmetrize_l(n, A, lda);
}

unicycle_real unicycle_la_dot(int n, const unicycle_real *x, const unicycle_real *y)
{
    return unicycle_lai_dot(n, x, y);
}

void unicycle_la_axpy(int n, unicycle_real alpha, const unicycle_real *x, unicycle_real *y)
{
    unicycle_lai_axpy(n, alpha, x, y);
}

unicycle_real unicycle_la_norm_inf(int n, const unicycle_real *x)
{
    return unicycle_lai_norm_inf(n, x);
}

unicycle_real unicycle_la_max_abs_mat(int m, int n, const unicycle_real *A, int lda)
{
    return unicycle_lai_max_abs_mat(m, n, A, lda);
}

int unicycle_la_all_finite(int m, int n, const unicycle_real *A, int lda)
{
    return unicycle_lai_all_finite(m, n, A, lda);
}
