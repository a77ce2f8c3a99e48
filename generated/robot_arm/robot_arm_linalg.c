/* Small dense column-major linear algebra, see robot_arm_linalg.h: the linkable versions of
 * the inline kernels of the header. */
#include "robot_arm_linalg.h"

int robot_arm_la_potrf_l(int n, robot_arm_real *A, int lda)
{
    return robot_arm_lai_potrf_l(n, A, lda);
}

int robot_arm_la_potrf_l_noise(int n, robot_arm_real *A, int lda, const robot_arm_real *noise, int *nfloor)
{
    return robot_arm_lai_potrf_l_noise(n, A, lda, noise, nfloor);
}

int robot_arm_la_ldlt_l(int n, robot_arm_real *A, int lda, int *neg)
{
    return robot_arm_lai_ldlt_l(n, A, lda, neg);
}

void robot_arm_la_trsv_ln(int n, const robot_arm_real *L, int ldl, robot_arm_real *x)
{
    robot_arm_lai_trsv_ln(n, L, ldl, x);
}

void robot_arm_la_trsv_lt(int n, const robot_arm_real *L, int ldl, robot_arm_real *x)
{
    robot_arm_lai_trsv_lt(n, L, ldl, x);
}

void robot_arm_la_trsm_lln(int n, int m, const robot_arm_real *L, int ldl, robot_arm_real *B, int ldb)
{
    robot_arm_lai_trsm_lln(n, m, L, ldl, B, ldb);
}

void robot_arm_la_trsm_llt(int n, int m, const robot_arm_real *L, int ldl, robot_arm_real *B, int ldb)
{
    robot_arm_lai_trsm_llt(n, m, L, ldl, B, ldb);
}

void robot_arm_la_gemv_n(int m, int n, robot_arm_real alpha, const robot_arm_real *A, int lda, const robot_arm_real *x,
                     robot_arm_real beta, robot_arm_real *y)
{
    robot_arm_lai_gemv_n(m, n, alpha, A, lda, x, beta, y);
}

void robot_arm_la_gemv_t(int m, int n, robot_arm_real alpha, const robot_arm_real *A, int lda, const robot_arm_real *x,
                     robot_arm_real beta, robot_arm_real *y)
{
    robot_arm_lai_gemv_t(m, n, alpha, A, lda, x, beta, y);
}

void robot_arm_la_symv_l(int n, robot_arm_real alpha, const robot_arm_real *A, int lda, const robot_arm_real *x,
                     robot_arm_real beta, robot_arm_real *y)
{
    robot_arm_lai_symv_l(n, alpha, A, lda, x, beta, y);
}

void robot_arm_la_gemm_nn(int m, int n, int k, robot_arm_real alpha, const robot_arm_real *A, int lda,
                      const robot_arm_real *B, int ldb, robot_arm_real beta, robot_arm_real *C, int ldc)
{
    robot_arm_lai_gemm_nn(m, n, k, alpha, A, lda, B, ldb, beta, C, ldc);
}

void robot_arm_la_gemm_tn(int m, int n, int k, robot_arm_real alpha, const robot_arm_real *A, int lda,
                      const robot_arm_real *B, int ldb, robot_arm_real beta, robot_arm_real *C, int ldc)
{
    robot_arm_lai_gemm_tn(m, n, k, alpha, A, lda, B, ldb, beta, C, ldc);
}

void robot_arm_la_copy_mat(int m, int n, const robot_arm_real *A, int lda, robot_arm_real *B, int ldb)
{
    robot_arm_lai_copy_mat(m, n, A, lda, B, ldb);
}

void robot_arm_la_symmetrize_l(int n, robot_arm_real *A, int lda)
{
    robot_arm_lai_symmetrize_l(n, A, lda);
}

robot_arm_real robot_arm_la_dot(int n, const robot_arm_real *x, const robot_arm_real *y)
{
    return robot_arm_lai_dot(n, x, y);
}

void robot_arm_la_axpy(int n, robot_arm_real alpha, const robot_arm_real *x, robot_arm_real *y)
{
    robot_arm_lai_axpy(n, alpha, x, y);
}

robot_arm_real robot_arm_la_norm_inf(int n, const robot_arm_real *x)
{
    return robot_arm_lai_norm_inf(n, x);
}

robot_arm_real robot_arm_la_max_abs_mat(int m, int n, const robot_arm_real *A, int lda)
{
    return robot_arm_lai_max_abs_mat(m, n, A, lda);
}

int robot_arm_la_all_finite(int m, int n, const robot_arm_real *A, int lda)
{
    return robot_arm_lai_all_finite(m, n, A, lda);
}
