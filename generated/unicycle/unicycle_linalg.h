/* Small dense linear algebra on column-major matrices (leading dimension `ld*`).
 *
 * Generic helpers for fixed-size stage blocks: no allocation, no size limits beyond the
 * caller's arrays. Naming follows BLAS/LAPACK (potrf, trsm, gemm, ...) so the intent of a
 * call is clear; there is no BLAS behind it. The arrays passed to one call must not overlap.
 */
#ifndef UNICYCLE_LINALG_H
#define UNICYCLE_LINALG_H

#include "unicycle_real.h"

/* In-place lower Cholesky factorisation A = L L' of the n x n symmetric matrix A (only the
 * lower triangle is read and written). Returns 0 on success, or j+1 when pivot j is not
 * positive or not finite (A is then partially overwritten). */
int unicycle_la_potrf_l(int n, unicycle_real *A, int lda);

/* As unicycle_la_potrf_l, but a pivot d with -noise[j] <= d <= 0 (noise: absolute round-off
 * estimate of the diagonal entry, n values; NULL means 0) is taken as a numerical zero and
 * replaced by max(noise[j], DBL_EPSILON |A_jj|); *nfloor (if not NULL) counts them. Only
 * pivots below -noise[j] (or non-finite) fail; positive pivots are never changed. */
int unicycle_la_potrf_l_noise(int n, unicycle_real *A, int lda, const unicycle_real *noise, int *nfloor);

/* In-place L D L' factorisation (unit lower L, diagonal D stored on the diagonal) of the
 * symmetric n x n matrix A, no pivoting. Returns 0 on success, j+1 on a zero/non-finite
 * pivot. The number of negative pivots is written to *neg when neg is not NULL. */
int unicycle_la_ldlt_l(int n, unicycle_real *A, int lda, int *neg);

/* Solve L x = b (trsv_ln) or L' x = b (trsv_lt) in place, L lower triangular n x n. */
void unicycle_la_trsv_ln(int n, const unicycle_real *L, int ldl, unicycle_real *x);
void unicycle_la_trsv_lt(int n, const unicycle_real *L, int ldl, unicycle_real *x);

/* B <- L^{-1} B for the n x m matrix B (trsm_lln) or B <- L'^{-1} B (trsm_llt). */
void unicycle_la_trsm_lln(int n, int m, const unicycle_real *L, int ldl, unicycle_real *B, int ldb);
void unicycle_la_trsm_llt(int n, int m, const unicycle_real *L, int ldl, unicycle_real *B, int ldb);

/* y <- alpha A x + beta y, A m x n (gemv_n);  y <- alpha A' x + beta y (gemv_t, y of size n).
 * beta == 0 overwrites y without reading it. */
void unicycle_la_gemv_n(int m, int n, unicycle_real alpha, const unicycle_real *A, int lda, const unicycle_real *x,
                     unicycle_real beta, unicycle_real *y);
void unicycle_la_gemv_t(int m, int n, unicycle_real alpha, const unicycle_real *A, int lda, const unicycle_real *x,
                     unicycle_real beta, unicycle_real *y);

/* y <- alpha A x + beta y for symmetric n x n A of which only the lower triangle is read. */
void unicycle_la_symv_l(int n, unicycle_real alpha, const unicycle_real *A, int lda, const unicycle_real *x,
                     unicycle_real beta, unicycle_real *y);

/* C <- alpha A B + beta C (gemm_nn: A m x k, B k x n); C <- alpha A' B + beta C (gemm_tn:
 * A k x m, B k x n). C is m x n. beta == 0 overwrites C without reading it. */
void unicycle_la_gemm_nn(int m, int n, int k, unicycle_real alpha, const unicycle_real *A, int lda,
                      const unicycle_real *B, int ldb, unicycle_real beta, unicycle_real *C, int ldc);
void unicycle_la_gemm_tn(int m, int n, int k, unicycle_real alpha, const unicycle_real *A, int lda,
                      const unicycle_real *B, int ldb, unicycle_real beta, unicycle_real *C, int ldc);

/* Copy the m x n matrix A into B. */
void unicycle_la_copy_mat(int m, int n, const unicycle_real *A, int lda, unicycle_real *B, int ldb);

/* Mirror the lower triangle of the n x n matrix A into its upper triangle. */
void unicycle_la_symmetrize_l(int n, unicycle_real *A, int lda);

/* Vector helpers. */
unicycle_real unicycle_la_dot(int n, const unicycle_real *x, const unicycle_real *y);
void unicycle_la_axpy(int n, unicycle_real alpha, const unicycle_real *x, unicycle_real *y);
unicycle_real unicycle_la_norm_inf(int n, const unicycle_real *x);
/* Infinity norm of the m x n matrix A (largest absolute entry, not the operator norm). */
unicycle_real unicycle_la_max_abs_mat(int m, int n, const unicycle_real *A, int lda);
/* 1 when all m x n entries are finite, else 0. */
int unicycle_la_all_finite(int m, int n, const unicycle_real *A, int lda);

/* ------------------------------------------------------------------------------------
 * Inline kernels (unicycle_lai_*): the same operations as static inline functions, so that
 * a caller with compile-time sizes (the QP solver) gets them specialised and unrolled.
 * The unicycle_la_* functions above are linkable wrappers around them. The arrays of one call
 * must not overlap (restrict): the output then stays in registers across the loops instead
 * of being stored and read back after every update (the input might have been it). */
#include <float.h>
#include <math.h>

/* Full unrolling of short loops whose bounds are compile-time sizes after inlining but whose
 * inner bounds depend on the outer index (triangles): a complete unroll turns them into
 * straight-line code that the compiler schedules well. GCC 8 and later and clang honour the
 * pragma; it is left out for other compilers (an older GCC would warn about an unknown
 * pragma). */
#if (defined(__GNUC__) && __GNUC__ >= 8) || defined(__clang__)
#define UNICYCLE_UNROLL _Pragma("GCC unroll 16")
#else
#define UNICYCLE_UNROLL
#endif

/* The pivot of column j of the Cholesky factorisation: A_jj minus the squares of row j of
 * the factor so far. */
static inline unicycle_real unicycle_lai_potrf_pivot(const unicycle_real *A, int lda, int j)
{
    int k;
    unicycle_real d = A[j + j * lda];
    for (k = 0; k < j; ++k)
        d -= A[j + k * lda] * A[j + k * lda];
    return d;
}

/* Column j of the factor from its pivot d > 0: L_jj = sqrt(d), the entries below. */
static inline void unicycle_lai_potrf_column(int n, unicycle_real *A, int lda, int j, unicycle_real d)
{
    int i, k;
    d = unicycle_sqrt(d);
    A[j + j * lda] = d;
    for (i = j + 1; i < n; ++i) {
        unicycle_real s = A[i + j * lda];
        for (k = 0; k < j; ++k)
            s -= A[i + k * lda] * A[j + k * lda];
        A[i + j * lda] = s / d;
    }
}

static inline int unicycle_lai_potrf_l(int n, unicycle_real *A, int lda)
{
    int j;
    for (j = 0; j < n; ++j) {
        const unicycle_real d = unicycle_lai_potrf_pivot(A, lda, j);
        /* !(d > 0) also rejects NaN */
        if (!(d > UNICYCLE_R(0.0)) || !isfinite(d))
            return j + 1;
        unicycle_lai_potrf_column(n, A, lda, j, d);
    }
    return 0;
}

static inline int unicycle_lai_potrf_l_noise(int n, unicycle_real *A, int lda, const unicycle_real *noise, int *nfloor)
{
    int j;
    for (j = 0; j < n; ++j) {
        const unicycle_real ajj = unicycle_fabs(A[j + j * lda]);
        const unicycle_real tol = noise ? noise[j] : UNICYCLE_R(0.0);
        unicycle_real d = unicycle_lai_potrf_pivot(A, lda, j);
        if (!isfinite(d))
            return j + 1;
        if (d <= UNICYCLE_R(0.0)) {
            const unicycle_real floor_d = tol > UNICYCLE_REAL_EPSILON * ajj ? tol : UNICYCLE_REAL_EPSILON * ajj;
            if (d < -tol || !(floor_d > UNICYCLE_R(0.0)))
                return j + 1;
            d = floor_d;
            if (nfloor)
                ++*nfloor;
        }
        unicycle_lai_potrf_column(n, A, lda, j, d);
    }
    return 0;
}

static inline int unicycle_lai_ldlt_l(int n, unicycle_real *A, int lda, int *neg)
{
    int i, j, k, nneg = 0;
    for (j = 0; j < n; ++j) {
        unicycle_real d = A[j + j * lda];
        for (k = 0; k < j; ++k)
            d -= A[j + k * lda] * A[j + k * lda] * A[k + k * lda];
        if (d == UNICYCLE_R(0.0) || !isfinite(d)) {
            if (neg)
                *neg = nneg;
            return j + 1;
        }
        if (d < UNICYCLE_R(0.0))
            ++nneg;
        A[j + j * lda] = d;
        for (i = j + 1; i < n; ++i) {
            unicycle_real s = A[i + j * lda];
            for (k = 0; k < j; ++k)
                s -= A[i + k * lda] * A[j + k * lda] * A[k + k * lda];
            A[i + j * lda] = s / d;
        }
    }
    if (neg)
        *neg = nneg;
    return 0;
}

static inline void unicycle_lai_trsv_ln(int n, const unicycle_real *restrict L, int ldl, unicycle_real *restrict x)
{
    int i, k;
    for (i = 0; i < n; ++i) {
        unicycle_real s = x[i];
        for (k = 0; k < i; ++k)
            s -= L[i + k * ldl] * x[k];
        x[i] = s / L[i + i * ldl];
    }
}

static inline void unicycle_lai_trsv_lt(int n, const unicycle_real *restrict L, int ldl, unicycle_real *restrict x)
{
    int i, k;
    for (i = n - 1; i >= 0; --i) {
        unicycle_real s = x[i];
        for (k = i + 1; k < n; ++k)
            s -= L[k + i * ldl] * x[k];
        x[i] = s / L[i + i * ldl];
    }
}

static inline void unicycle_lai_trsm_lln(int n, int m, const unicycle_real *restrict L, int ldl,
                                      unicycle_real *restrict B, int ldb)
{
    int j;
    for (j = 0; j < m; ++j)
        unicycle_lai_trsv_ln(n, L, ldl, B + j * ldb);
}

static inline void unicycle_lai_trsm_llt(int n, int m, const unicycle_real *restrict L, int ldl,
                                      unicycle_real *restrict B, int ldb)
{
    int j;
    for (j = 0; j < m; ++j)
        unicycle_lai_trsv_lt(n, L, ldl, B + j * ldb);
}

/* y = beta y (m entries) with beta = 0 writing zeros (y may hold NaN) and beta = 1 no-op. */
static inline void unicycle_lai_scale_y(int m, unicycle_real beta, unicycle_real *restrict y)
{
    int i;
    if (beta == UNICYCLE_R(0.0)) {
        for (i = 0; i < m; ++i)
            y[i] = UNICYCLE_R(0.0);
    } else if (beta != UNICYCLE_R(1.0)) {
        for (i = 0; i < m; ++i)
            y[i] *= beta;
    }
}

static inline void unicycle_lai_gemv_n(int m, int n, unicycle_real alpha, const unicycle_real *restrict A, int lda,
                                    const unicycle_real *restrict x, unicycle_real beta, unicycle_real *restrict y)
{
    int i, j;
    unicycle_lai_scale_y(m, beta, y);
    for (j = 0; j < n; ++j) {
        const unicycle_real a = alpha * x[j];
        for (i = 0; i < m; ++i)
            y[i] += A[i + j * lda] * a;
    }
}

static inline void unicycle_lai_gemv_t(int m, int n, unicycle_real alpha, const unicycle_real *restrict A, int lda,
                                    const unicycle_real *restrict x, unicycle_real beta, unicycle_real *restrict y)
{
    int i, j;
    for (j = 0; j < n; ++j) {
        unicycle_real s = UNICYCLE_R(0.0);
        for (i = 0; i < m; ++i)
            s += A[i + j * lda] * x[i];
        y[j] = (beta == UNICYCLE_R(0.0) ? UNICYCLE_R(0.0) : beta * y[j]) + alpha * s;
    }
}

static inline void unicycle_lai_symv_l(int n, unicycle_real alpha, const unicycle_real *restrict A, int lda,
                                    const unicycle_real *restrict x, unicycle_real beta, unicycle_real *restrict y)
{
    int i, j;
    /* y = beta y + alpha (L + L' - diag) x, L the lower triangle, column by column (the
     * triangle unrolled where n is a compile-time size) */
    unicycle_lai_scale_y(n, beta, y);
    UNICYCLE_UNROLL
    for (j = 0; j < n; ++j) {
        const unicycle_real *a = A + j * lda;
        const unicycle_real xj = alpha * x[j];
        unicycle_real s = UNICYCLE_R(0.0);
        y[j] += a[j] * xj;
        UNICYCLE_UNROLL
        for (i = j + 1; i < n; ++i) {
            y[i] += a[i] * xj;
            s += a[i] * x[i];
        }
        y[j] += alpha * s;
    }
}

static inline void unicycle_lai_gemm_nn(int m, int n, int k, unicycle_real alpha, const unicycle_real *restrict A,
                                     int lda, const unicycle_real *restrict B, int ldb, unicycle_real beta,
                                     unicycle_real *restrict C, int ldc)
{
    int i, j, l;
    for (j = 0; j < n; ++j) {
        unicycle_real *c = C + j * ldc;
        unicycle_lai_scale_y(m, beta, c);
        for (l = 0; l < k; ++l) {
            const unicycle_real b = alpha * B[l + j * ldb];
            for (i = 0; i < m; ++i)
                c[i] += A[i + l * lda] * b;
        }
    }
}

static inline void unicycle_lai_gemm_tn(int m, int n, int k, unicycle_real alpha, const unicycle_real *restrict A,
                                     int lda, const unicycle_real *restrict B, int ldb, unicycle_real beta,
                                     unicycle_real *restrict C, int ldc)
{
    int i, j, l;
    for (j = 0; j < n; ++j) {
        for (i = 0; i < m; ++i) {
            unicycle_real s = UNICYCLE_R(0.0);
            for (l = 0; l < k; ++l)
                s += A[l + i * lda] * B[l + j * ldb];
            C[i + j * ldc] = (beta == UNICYCLE_R(0.0) ? UNICYCLE_R(0.0) : beta * C[i + j * ldc]) + alpha * s;
        }
    }
}

/* (not restrict: a compiler may turn a copy between restrict arrays into a call of memmove) */
static inline void unicycle_lai_copy_mat(int m, int n, const unicycle_real *A, int lda, unicycle_real *B, int ldb)
{
    int i, j;
    for (j = 0; j < n; ++j)
        for (i = 0; i < m; ++i)
            B[i + j * ldb] = A[i + j * lda];
}

static inline void unicycle_lai_symmetrize_l(int n, unicycle_real *A, int lda)
{
    int i, j;
    for (j = 0; j < n; ++j)
        for (i = j + 1; i < n; ++i)
            A[j + i * lda] = A[i + j * lda];
}

static inline unicycle_real unicycle_lai_dot(int n, const unicycle_real *x, const unicycle_real *y)
{
    int i;
    unicycle_real s = UNICYCLE_R(0.0);
    for (i = 0; i < n; ++i)
        s += x[i] * y[i];
    return s;
}

static inline void unicycle_lai_axpy(int n, unicycle_real alpha, const unicycle_real *restrict x,
                                  unicycle_real *restrict y)
{
    int i;
    for (i = 0; i < n; ++i)
        y[i] += alpha * x[i];
}

/* Two-wide vectors of the real type (the vector extension of GCC and clang) where the target
 * has them for double: x86-64 (SSE2) and AArch64; 0 elsewhere (a scalar FPU such as the
 * Cortex-M's, or float), where the kernels that use them take plain loops. Lane-wise
 * arithmetic, so an entry computed two at a time takes the same operations in the same order
 * as alone: the same values either way. Define it to override. */
#ifndef UNICYCLE_LAI_VEC
#if (defined(__GNUC__) || defined(__clang__)) && !UNICYCLE_REAL_FLOAT &&                                        \
    (defined(__SSE2__) || defined(__aarch64__))
#define UNICYCLE_LAI_VEC 1
#else
#define UNICYCLE_LAI_VEC 0
#endif
#endif

#if UNICYCLE_LAI_VEC
typedef unicycle_real unicycle_lai_v2 __attribute__((vector_size(2 * sizeof(unicycle_real))));

/* x[0], x[1] (any alignment) */
static inline unicycle_lai_v2 unicycle_lai_v2_load(const unicycle_real *x)
{
    unicycle_lai_v2 v;
    __builtin_memcpy(&v, x, sizeof v);
    return v;
}

static inline void unicycle_lai_v2_store(unicycle_real *x, unicycle_lai_v2 v)
{
    __builtin_memcpy(x, &v, sizeof v);
}

/* |x| lane-wise (the sign bits cleared) */
static inline unicycle_lai_v2 unicycle_lai_v2_abs(unicycle_lai_v2 x)
{
    typedef long long unicycle_lai_v2_bits __attribute__((vector_size(sizeof(unicycle_lai_v2))));
    const unicycle_lai_v2_bits mask = {0x7fffffffffffffffLL, 0x7fffffffffffffffLL};
    return (unicycle_lai_v2)((unicycle_lai_v2_bits)x & mask);
}

/* {a, a} */
static inline unicycle_lai_v2 unicycle_lai_v2_splat(unicycle_real a)
{
    const unicycle_lai_v2 v = {a, a};
    return v;
}
#endif

/* The larger of a and m for an accumulated maximum m (never NaN): a when a > m, else m (a
 * NaN a leaves m). Where the core has a floating-point maximum instruction (VMAXNM, FMAXNM)
 * fmax compiles to it and gives the same value in one instruction instead of a compare and a
 * select: AArch64, ARMv8 with an FPU of the real type, and the Cortex-M7's FPv5 with double
 * precision (an ARMv7E-M core; its single-precision variant cannot be told from the
 * Cortex-M4's FPv4, which has no such instruction, by the predefined macros). Elsewhere fmax
 * is a library call and the comparison is cheaper. */
#if defined(__aarch64__) ||                                                                                  \
    (defined(__ARM_FP) && defined(__ARM_ARCH) && (UNICYCLE_REAL_FLOAT ? (__ARM_FP & 4) : (__ARM_FP & 8)) &&     \
     (__ARM_ARCH >= 8 || (defined(__ARM_ARCH_PROFILE) && __ARM_ARCH_PROFILE == 'M' && (__ARM_FP & 8))))
#define UNICYCLE_MAX_ACC(a, m) unicycle_fmax((a), (m))
#else
#define UNICYCLE_MAX_ACC(a, m) ((a) > (m) ? (a) : (m))
#endif

/* UNICYCLE_MAX_ACC on two lanes at once where the target has it as one instruction: x86-64's
 * MAXPD gives its second operand when either is NaN or both are zero, so MAXPD(a, m) is
 * a > m ? a : m lane by lane, the same value as the select (1 there; 0 elsewhere, where the
 * callers keep their scalar loops). */
#if UNICYCLE_LAI_VEC && defined(__SSE2__)
#define UNICYCLE_LAI_V2_MAX 1
static inline unicycle_lai_v2 unicycle_lai_v2_max_acc(unicycle_lai_v2 a, unicycle_lai_v2 m)
{
    return __builtin_ia32_maxpd(a, m);
}
#else
#define UNICYCLE_LAI_V2_MAX 0
#endif

/* The same four lanes in one vector where the target has AVX (VMAXPD on four lanes, the
 * same select as MAXPD lane by lane). */
#if UNICYCLE_LAI_V2_MAX && defined(__AVX__)
#define UNICYCLE_LAI_V4_MAX 1
typedef unicycle_real unicycle_lai_v4 __attribute__((vector_size(4 * sizeof(unicycle_real))));
static inline unicycle_lai_v4 unicycle_lai_v4_load(const unicycle_real *x)
{
    unicycle_lai_v4 v;
    __builtin_memcpy(&v, x, sizeof v);
    return v;
}

static inline void unicycle_lai_v4_store(unicycle_real *x, unicycle_lai_v4 v)
{
    __builtin_memcpy(x, &v, sizeof v);
}

static inline unicycle_lai_v4 unicycle_lai_v4_abs(unicycle_lai_v4 x)
{
    typedef long long unicycle_lai_v4_bits __attribute__((vector_size(sizeof(unicycle_lai_v4))));
    const unicycle_lai_v4_bits mask = {0x7fffffffffffffffLL, 0x7fffffffffffffffLL, 0x7fffffffffffffffLL,
                                    0x7fffffffffffffffLL};
    return (unicycle_lai_v4)((unicycle_lai_v4_bits)x & mask);
}

static inline unicycle_lai_v4 unicycle_lai_v4_max_acc(unicycle_lai_v4 a, unicycle_lai_v4 m)
{
    return __builtin_ia32_maxpd256(a, m);
}
#else
#define UNICYCLE_LAI_V4_MAX 0
#endif

/* 1 when every entry of the m x n matrix A is finite (no NaN, no Inf). x * 0 is 0 for a finite
 * x and NaN for an infinite or NaN one, so the sum of these products is 0 exactly when every
 * entry is finite: one multiply-add per entry, no branch (two sums, independent chains). */
static inline int unicycle_lai_all_finite(int m, int n, const unicycle_real *restrict A, int lda)
{
    int i, j;
    unicycle_real s0 = UNICYCLE_R(0.0), s1 = UNICYCLE_R(0.0);
    for (j = 0; j < n; ++j) {
        const unicycle_real *a = A + j * lda;
        for (i = 0; i + 1 < m; i += 2) {
            s0 += a[i] * UNICYCLE_R(0.0);
            s1 += a[i + 1] * UNICYCLE_R(0.0);
        }
        if (i < m)
            s0 += a[i] * UNICYCLE_R(0.0);
    }
    return s0 + s1 == UNICYCLE_R(0.0);
}

/* 1 when every entry of the vector is finite (no NaN, no Inf) */
static inline int unicycle_lai_vec_finite(int n, const unicycle_real *restrict x)
{
    return unicycle_lai_all_finite(n, 1, x, n);
}

/* The largest |x_i|, NaN when an entry is NaN. Branch-free: four independent maxima (no
 * chain of dependent max instructions; the maximum is a select or one max instruction,
 * UNICYCLE_MAX_ACC) and the sum of the |x_i|, which is NaN exactly when an entry is NaN (the
 * terms are never negative, so infinite ones cannot cancel). A data-dependent branch would
 * mispredict half the time. */
static inline unicycle_real unicycle_lai_norm_inf(int n, const unicycle_real *restrict x)
{
    int i, c;
    unicycle_real m[4] = {UNICYCLE_R(0.0), UNICYCLE_R(0.0), UNICYCLE_R(0.0), UNICYCLE_R(0.0)};
    unicycle_real t[4] = {UNICYCLE_R(0.0), UNICYCLE_R(0.0), UNICYCLE_R(0.0), UNICYCLE_R(0.0)};
#if UNICYCLE_LAI_V4_MAX
    /* the same four maxima and sums, the four lanes in one vector: the same values */
    {
        unicycle_lai_v4 m4 = {UNICYCLE_R(0.0), UNICYCLE_R(0.0), UNICYCLE_R(0.0), UNICYCLE_R(0.0)}, t4 = m4;
        for (i = 0; i + 4 <= n; i += 4) {
            const unicycle_lai_v4 a4 = unicycle_lai_v4_abs(unicycle_lai_v4_load(x + i));
            m4 = unicycle_lai_v4_max_acc(a4, m4);
            t4 += a4;
        }
        for (c = 0; c < 4; ++c) {
            m[c] = m4[c];
            t[c] = t4[c];
        }
        x += i;
        n -= i;
    }
#elif UNICYCLE_LAI_V2_MAX
    /* the same four maxima and sums, two lanes per vector: the same values */
    {
        const unicycle_lai_v2 zero = {UNICYCLE_R(0.0), UNICYCLE_R(0.0)};
        unicycle_lai_v2 m01 = zero, m23 = zero, t01 = zero, t23 = zero;
        for (i = 0; i + 4 <= n; i += 4) {
            const unicycle_lai_v2 a01 = unicycle_lai_v2_abs(unicycle_lai_v2_load(x + i));
            const unicycle_lai_v2 a23 = unicycle_lai_v2_abs(unicycle_lai_v2_load(x + i + 2));
            m01 = unicycle_lai_v2_max_acc(a01, m01);
            m23 = unicycle_lai_v2_max_acc(a23, m23);
            t01 += a01;
            t23 += a23;
        }
        m[0] = m01[0];
        m[1] = m01[1];
        m[2] = m23[0];
        m[3] = m23[1];
        t[0] = t01[0];
        t[1] = t01[1];
        t[2] = t23[0];
        t[3] = t23[1];
        x += i;
        n -= i;
    }
#endif
    for (i = 0; i < n; i += 4)
        for (c = 0; c < 4 && i + c < n; ++c) {
            const unicycle_real a = unicycle_fabs(x[i + c]);
            m[c] = UNICYCLE_MAX_ACC(a, m[c]);
            t[c] += a;
        }
    m[0] = UNICYCLE_MAX_ACC(m[1], m[0]);
    m[2] = UNICYCLE_MAX_ACC(m[3], m[2]);
    t[0] += t[1] + t[2] + t[3];
    return t[0] != t[0] ? (unicycle_real)NAN : UNICYCLE_MAX_ACC(m[2], m[0]);
}

/* The largest |A_ij| of the m x n matrix A, NaN when an entry is NaN. */
static inline unicycle_real unicycle_lai_max_abs_mat(int m, int n, const unicycle_real *restrict A, int lda)
{
    int j, nan = 0;
    unicycle_real r = UNICYCLE_R(0.0);
    if (lda == m) /* contiguous: one pass */
        return unicycle_lai_norm_inf(m * n, A);
    for (j = 0; j < n; ++j) {
        const unicycle_real c = unicycle_lai_norm_inf(m, A + j * lda);
        r = UNICYCLE_MAX_ACC(c, r);
        nan |= c != c;
    }
    return nan ? (unicycle_real)NAN : r;
}

#if UNICYCLE_LAI_VEC
/* out = A x for the m x n column-major A, as the sum over the columns j of A(:, j) x_j in the
 * order of j (the order of a row's dot product), two rows at a time with the accumulators in
 * registers: A's columns read down instead of its rows across. Entry i goes to out[i os]. m
 * and n are compile-time constants (the accumulators are an array of m / 2 vectors). */
#define UNICYCLE_LAI_V2_GEMV(m, n, A, x, out, os)                                                               \
    do {                                                                                                     \
        unicycle_lai_v2 acc_[UNICYCLE_DIM((m) / 2)];                                                               \
        unicycle_real last_ = UNICYCLE_R(0.0);                                                                     \
        int i_, j_;                                                                                          \
        for (i_ = 0; i_ < (m) / 2; ++i_)                                                                     \
            acc_[i_] = (unicycle_lai_v2){UNICYCLE_R(0.0), UNICYCLE_R(0.0)};                                           \
        for (j_ = 0; j_ < (n); ++j_) {                                                                       \
            const unicycle_real f_ = (x)[j_];                                                                   \
            const unicycle_real *a_ = (A) + j_ * (m);                                                           \
            for (i_ = 0; i_ < (m) / 2; ++i_)                                                                 \
                acc_[i_] += unicycle_lai_v2_load(a_ + 2 * i_) * f_;                                             \
            if ((m) % 2)                                                                                     \
                last_ += a_[(m)-1] * f_;                                                                     \
        }                                                                                                    \
        for (i_ = 0; i_ < (m) / 2; ++i_) {                                                                   \
            (out)[2 * i_ * (os)] = acc_[i_][0];                                                              \
            (out)[(2 * i_ + 1) * (os)] = acc_[i_][1];                                                        \
        }                                                                                                    \
        if ((m) % 2)                                                                                         \
            (out)[((m)-1) * (os)] = last_;                                                                   \
    } while (0)

/* The parts of unicycle_lai_v2_atb_cols2 and unicycle_lai_v2_lower_atb (described below them).
 * s + sum_l AT(r, l) b[l], l = 0..m-1 in order (atr = AT + r, the leading dimension n) */
static inline unicycle_real unicycle_lai_atb_entry(int n, int m, unicycle_real s, const unicycle_real *restrict atr,
                                             const unicycle_real *restrict b)
{
    int l;
    for (l = 0; l < m; ++l)
        s += atr[l * n] * b[l];
    return s;
}

/* Rows r .. r + 2 nv - 1 of columns j, j + 1 of unicycle_lai_v2_atb_cols2 (nv <= 4;
 * b0, h0, c0 and b1, h1, c1 the two columns of B, H and C). */
static inline void unicycle_lai_v2_atb_block(int n, int m, int nv, const unicycle_real *restrict AT,
                                          const unicycle_real *restrict b0, const unicycle_real *restrict b1,
                                          const unicycle_real *restrict h0, const unicycle_real *restrict h1,
                                          unicycle_real *restrict c0, unicycle_real *restrict c1, int j, int r)
{
    unicycle_lai_v2 a0[4], a1[4];
    int v, l;
    UNICYCLE_UNROLL
    for (v = 0; v < nv; ++v) {
        const int i = r + 2 * v; /* rows i, i + 1 */
        if (i + 1 == j) {
            const unicycle_lai_v2 d0 = {UNICYCLE_R(0.0), h0[j]}, d1 = {UNICYCLE_R(0.0), UNICYCLE_R(0.0)};
            a0[v] = d0;
            a1[v] = d1;
        } else if (i == j) {
            const unicycle_lai_v2 d1 = {UNICYCLE_R(0.0), h1[j + 1]};
            a0[v] = unicycle_lai_v2_load(h0 + i);
            a1[v] = d1;
        } else {
            a0[v] = unicycle_lai_v2_load(h0 + i);
            a1[v] = unicycle_lai_v2_load(h1 + i);
        }
    }
    for (l = 0; l < m; ++l) {
        const unicycle_lai_v2 s0 = unicycle_lai_v2_splat(b0[l]), s1 = unicycle_lai_v2_splat(b1[l]);
        UNICYCLE_UNROLL
        for (v = 0; v < nv; ++v) {
            const unicycle_lai_v2 x = unicycle_lai_v2_load(AT + r + 2 * v + l * n);
            a0[v] += x * s0;
            a1[v] += x * s1;
        }
    }
    UNICYCLE_UNROLL
    for (v = 0; v < nv; ++v) {
        unicycle_lai_v2_store(c0 + r + 2 * v, a0[v]);
        unicycle_lai_v2_store(c1 + r + 2 * v, a1[v]);
    }
}

/* The lower triangle of C = H + A' B for n x n C and H, n x m A' (AT) and m x n B, all
 * column-major with the leading dimension of their row count (n, n, n and m); only H's lower
 * triangle is read. Each entry is one sum in the order of l, H(i, c) + sum_l AT(i, l) B(l, c)
 * with a multiply and an add per term, as the plain loop over l gives it: two rows of one
 * column per vector (never a sum split across lanes), so the same bits. Used by the QP's stage
 * update (M = H + WT' Phi, unicycle_lai_v2_lower_atb) and the lm test (Z = H + Phi' Y from a
 * run-time first column, its own loop over unicycle_lai_v2_atb_cols2).
 *
 * unicycle_lai_v2_atb_cols2: columns j and j + 1 (j + 1 < n), their rows from the diagonal down,
 * two rows of both at a time in blocks of up to 4 vectors (2 x 4 accumulators in registers, 2
 * broadcasts and one load of AT's pair of rows per term); the entries above the diagonal in
 * those blocks are formed from 0 and never meant to be read. With early, a pair whose count of
 * rows is odd starts a row early (its rows from j - 1: AT's row j - 1 read, C(j - 1, j) and
 * C(j - 1, j + 1) written), so that only a pair from j = 0 can have an odd last row; without,
 * the odd last row is formed alone. */
static inline void unicycle_lai_v2_atb_cols2(int n, int m, const unicycle_real *restrict AT,
                                          const unicycle_real *restrict B, const unicycle_real *restrict H,
                                          unicycle_real *restrict C, int j, int early)
{
    const unicycle_real *b0 = B + j * m, *b1 = b0 + m, *h0 = H + j * n, *h1 = h0 + n;
    unicycle_real *c0 = C + j * n, *c1 = c0 + n;
    const int r0 = early && (n - j) % 2 && j > 0 ? j - 1 : j;
    int r;
    UNICYCLE_UNROLL
    for (r = r0; r + 8 <= n; r += 8)
        unicycle_lai_v2_atb_block(n, m, 4, AT, b0, b1, h0, h1, c0, c1, j, r);
    /* the last block: the pairs of rows left (3, 2 or 1) */
    if (n - r >= 6)
        unicycle_lai_v2_atb_block(n, m, 3, AT, b0, b1, h0, h1, c0, c1, j, r);
    else if (n - r >= 4)
        unicycle_lai_v2_atb_block(n, m, 2, AT, b0, b1, h0, h1, c0, c1, j, r);
    else if (n - r >= 2)
        unicycle_lai_v2_atb_block(n, m, 1, AT, b0, b1, h0, h1, c0, c1, j, r);
    if ((n - r0) % 2) {
        c0[n - 1] = unicycle_lai_atb_entry(n, m, h0[n - 1], AT + n - 1, b0);
        c1[n - 1] = unicycle_lai_atb_entry(n, m, h1[n - 1], AT + n - 1, b1);
    }
}

/* The whole triangle from column j0 = 0 with the loop over the pairs unrolled (compile-time
 * sizes: the QP). A caller with a run-time j0 (the lm test) runs its own loop over the pairs of
 * unicycle_lai_v2_atb_cols2 without the pragma: clang cannot unroll a loop of run-time count
 * around the unrolled blocks (-Wpass-failed), and GCC copies the pairs up to its bound. */
static inline void unicycle_lai_v2_lower_atb(int n, int m, const unicycle_real *restrict AT,
                                          const unicycle_real *restrict B, const unicycle_real *restrict H,
                                          unicycle_real *restrict C)
{
    int j;
    UNICYCLE_UNROLL
    for (j = 0; j + 1 < n; j += 2)
        unicycle_lai_v2_atb_cols2(n, m, AT, B, H, C, j, 1);
    if (j < n)
        C[j + j * n] = unicycle_lai_atb_entry(n, m, H[j + j * n], AT + j, B + j * m);
}
#endif

#endif /* UNICYCLE_LINALG_H */
