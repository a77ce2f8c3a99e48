/* Small dense column-major linear algebra, see dopus_linalg.h. */
#include "dopus_linalg.h"

#include <float.h>
#include <math.h>

int dopus_la_potrf_l(int n, double *A, int lda)
{
    int i, j, k;
    for (j = 0; j < n; ++j) {
        double d = A[j + j * lda];
        for (k = 0; k < j; ++k)
            d -= A[j + k * lda] * A[j + k * lda];
        /* !(d > 0) also rejects NaN */
        if (!(d > 0.0) || !isfinite(d))
            return j + 1;
        d = sqrt(d);
        A[j + j * lda] = d;
        for (i = j + 1; i < n; ++i) {
            double s = A[i + j * lda];
            for (k = 0; k < j; ++k)
                s -= A[i + k * lda] * A[j + k * lda];
            A[i + j * lda] = s / d;
        }
    }
    return 0;
}

int dopus_la_potrf_l_noise(int n, double *A, int lda, const double *noise, int *nfloor)
{
    int i, j, k;
    for (j = 0; j < n; ++j) {
        const double ajj = fabs(A[j + j * lda]);
        const double tol = noise ? noise[j] : 0.0;
        double d = A[j + j * lda];
        for (k = 0; k < j; ++k)
            d -= A[j + k * lda] * A[j + k * lda];
        if (!isfinite(d))
            return j + 1;
        if (d <= 0.0) {
            const double floor_d = tol > DBL_EPSILON * ajj ? tol : DBL_EPSILON * ajj;
            if (d < -tol || !(floor_d > 0.0))
                return j + 1;
            d = floor_d;
            if (nfloor)
                ++*nfloor;
        }
        d = sqrt(d);
        A[j + j * lda] = d;
        for (i = j + 1; i < n; ++i) {
            double s = A[i + j * lda];
            for (k = 0; k < j; ++k)
                s -= A[i + k * lda] * A[j + k * lda];
            A[i + j * lda] = s / d;
        }
    }
    return 0;
}

int dopus_la_ldlt_l(int n, double *A, int lda, int *neg)
{
    int i, j, k, nneg = 0;
    for (j = 0; j < n; ++j) {
        double d = A[j + j * lda];
        for (k = 0; k < j; ++k)
            d -= A[j + k * lda] * A[j + k * lda] * A[k + k * lda];
        if (d == 0.0 || !isfinite(d)) {
            if (neg)
                *neg = nneg;
            return j + 1;
        }
        if (d < 0.0)
            ++nneg;
        A[j + j * lda] = d;
        for (i = j + 1; i < n; ++i) {
            double s = A[i + j * lda];
            for (k = 0; k < j; ++k)
                s -= A[i + k * lda] * A[j + k * lda] * A[k + k * lda];
            A[i + j * lda] = s / d;
        }
    }
    if (neg)
        *neg = nneg;
    return 0;
}

void dopus_la_trsv_ln(int n, const double *L, int ldl, double *x)
{
    int i, k;
    for (i = 0; i < n; ++i) {
        double s = x[i];
        for (k = 0; k < i; ++k)
            s -= L[i + k * ldl] * x[k];
        x[i] = s / L[i + i * ldl];
    }
}

void dopus_la_trsv_lt(int n, const double *L, int ldl, double *x)
{
    int i, k;
    for (i = n - 1; i >= 0; --i) {
        double s = x[i];
        for (k = i + 1; k < n; ++k)
            s -= L[k + i * ldl] * x[k];
        x[i] = s / L[i + i * ldl];
    }
}

void dopus_la_trsm_lln(int n, int m, const double *L, int ldl, double *B, int ldb)
{
    int j;
    for (j = 0; j < m; ++j)
        dopus_la_trsv_ln(n, L, ldl, B + j * ldb);
}

void dopus_la_trsm_llt(int n, int m, const double *L, int ldl, double *B, int ldb)
{
    int j;
    for (j = 0; j < m; ++j)
        dopus_la_trsv_lt(n, L, ldl, B + j * ldb);
}

void dopus_la_gemv_n(int m, int n, double alpha, const double *A, int lda, const double *x,
                     double beta, double *y)
{
    int i, j;
    if (beta == 0.0) {
        for (i = 0; i < m; ++i)
            y[i] = 0.0;
    } else if (beta != 1.0) {
        for (i = 0; i < m; ++i)
            y[i] *= beta;
    }
    for (j = 0; j < n; ++j) {
        const double a = alpha * x[j];
        for (i = 0; i < m; ++i)
            y[i] += A[i + j * lda] * a;
    }
}

void dopus_la_gemv_t(int m, int n, double alpha, const double *A, int lda, const double *x,
                     double beta, double *y)
{
    int i, j;
    for (j = 0; j < n; ++j) {
        double s = 0.0;
        for (i = 0; i < m; ++i)
            s += A[i + j * lda] * x[i];
        y[j] = (beta == 0.0 ? 0.0 : beta * y[j]) + alpha * s;
    }
}

void dopus_la_symv_l(int n, double alpha, const double *A, int lda, const double *x,
                     double beta, double *y)
{
    int i, j;
    for (i = 0; i < n; ++i) {
        double s = 0.0;
        for (j = 0; j < n; ++j)
            s += (i >= j ? A[i + j * lda] : A[j + i * lda]) * x[j];
        y[i] = (beta == 0.0 ? 0.0 : beta * y[i]) + alpha * s;
    }
}

void dopus_la_gemm_nn(int m, int n, int k, double alpha, const double *A, int lda,
                      const double *B, int ldb, double beta, double *C, int ldc)
{
    int i, j, l;
    for (j = 0; j < n; ++j) {
        double *c = C + j * ldc;
        if (beta == 0.0) {
            for (i = 0; i < m; ++i)
                c[i] = 0.0;
        } else if (beta != 1.0) {
            for (i = 0; i < m; ++i)
                c[i] *= beta;
        }
        for (l = 0; l < k; ++l) {
            const double b = alpha * B[l + j * ldb];
            for (i = 0; i < m; ++i)
                c[i] += A[i + l * lda] * b;
        }
    }
}

void dopus_la_gemm_tn(int m, int n, int k, double alpha, const double *A, int lda,
                      const double *B, int ldb, double beta, double *C, int ldc)
{
    int i, j, l;
    for (j = 0; j < n; ++j) {
        for (i = 0; i < m; ++i) {
            double s = 0.0;
            for (l = 0; l < k; ++l)
                s += A[l + i * lda] * B[l + j * ldb];
            C[i + j * ldc] = (beta == 0.0 ? 0.0 : beta * C[i + j * ldc]) + alpha * s;
        }
    }
}

void dopus_la_copy_mat(int m, int n, const double *A, int lda, double *B, int ldb)
{
    int i, j;
    for (j = 0; j < n; ++j)
        for (i = 0; i < m; ++i)
            B[i + j * ldb] = A[i + j * lda];
}

void dopus_la_symmetrize_l(int n, double *A, int lda)
{
    int i, j;
    for (j = 0; j < n; ++j)
        for (i = j + 1; i < n; ++i)
            A[j + i * lda] = A[i + j * lda];
}

double dopus_la_dot(int n, const double *x, const double *y)
{
    int i;
    double s = 0.0;
    for (i = 0; i < n; ++i)
        s += x[i] * y[i];
    return s;
}

void dopus_la_axpy(int n, double alpha, const double *x, double *y)
{
    int i;
    for (i = 0; i < n; ++i)
        y[i] += alpha * x[i];
}

double dopus_la_norm_inf(int n, const double *x)
{
    int i;
    double m = 0.0;
    for (i = 0; i < n; ++i) {
        const double a = fabs(x[i]);
        if (a > m || a != a)
            m = a;
    }
    return m;
}

double dopus_la_max_abs_mat(int m, int n, const double *A, int lda)
{
    int j;
    double r = 0.0;
    for (j = 0; j < n; ++j) {
        const double c = dopus_la_norm_inf(m, A + j * lda);
        if (c > r || c != c)
            r = c;
    }
    return r;
}

int dopus_la_all_finite(int m, int n, const double *A, int lda)
{
    int i, j;
    for (j = 0; j < n; ++j)
        for (i = 0; i < m; ++i)
            if (!isfinite(A[i + j * lda]))
                return 0;
    return 1;
}
