/* Eigenvalue regularisation by cyclic Jacobi rotations (docs/algorithm.md section 5).
 *
 * Jacobi is chosen over Householder + QR for its simplicity and its high relative
 * accuracy on the small blocks (n = nx + nu) met here; one sweep is O(n^3) and
 * convergence is quadratic, so a handful of sweeps reaches round-off. */
#include <float.h>
#include <math.h>

#include "dopus_reg.h"

#define DOPUS_REG_MAX_SWEEPS 64

static dopus_real dopus_reg_offdiag2(int n, const dopus_real *a)
{
    dopus_real s = DOPUS_R(0.0);
    int i, j;
    for (j = 0; j < n; ++j) {
        for (i = 0; i < j; ++i) {
            s += a[i + j * n] * a[i + j * n];
        }
    }
    return s;
}

int dopus_reg_jacobi_eig(int n, dopus_real *a, dopus_real *v)
{
    dopus_real fro2 = DOPUS_R(0.0);
    int i, j, k, p, q, sweep;

    /* Symmetrise (the CasADi Hessians are symmetric up to round-off) and set V = I. */
    for (j = 0; j < n; ++j) {
        for (i = 0; i < j; ++i) {
            dopus_real s = DOPUS_R(0.5) * (a[i + j * n] + a[j + i * n]);
            a[i + j * n] = s;
            a[j + i * n] = s;
        }
        for (i = 0; i < n; ++i) {
            v[i + j * n] = (i == j) ? DOPUS_R(1.0) : DOPUS_R(0.0);
            fro2 += a[i + j * n] * a[i + j * n];
        }
    }
    if (fro2 == DOPUS_R(0.0)) {
        return 0;
    }

    for (sweep = 0; sweep < DOPUS_REG_MAX_SWEEPS; ++sweep) {
        /* Stop when the off-diagonal part is at round-off level of the whole matrix. */
        if (dopus_reg_offdiag2(n, a) <= (DOPUS_REAL_EPSILON * DOPUS_REAL_EPSILON) * DOPUS_R(1e-2) * fro2) {
            return sweep;
        }
        for (p = 0; p < n - 1; ++p) {
            for (q = p + 1; q < n; ++q) {
                dopus_real apq = a[p + q * n];
                dopus_real app = a[p + p * n];
                dopus_real aqq = a[q + q * n];
                dopus_real tau, t, c, s;
                if (apq == DOPUS_R(0.0)) {
                    continue;
                }
                /* An entry below round-off of both diagonal entries is zero for
                 * every later rotation too (Golub and Van Loan, section 8.5). */
                if (dopus_fabs(apq) <= DOPUS_R(0.25) * DOPUS_REAL_EPSILON * dopus_fabs(app) &&
                    dopus_fabs(apq) <= DOPUS_R(0.25) * DOPUS_REAL_EPSILON * dopus_fabs(aqq)) {
                    a[p + q * n] = DOPUS_R(0.0);
                    a[q + p * n] = DOPUS_R(0.0);
                    continue;
                }
                /* The 2x2 symmetric Schur decomposition (Golub and Van Loan, alg. 8.5.1),
                 * the smaller rotation angle for stability. */
                tau = (aqq - app) / (DOPUS_R(2.0) * apq);
                t = (tau >= DOPUS_R(0.0) ? DOPUS_R(1.0) : -DOPUS_R(1.0)) /
                    (dopus_fabs(tau) + dopus_sqrt(DOPUS_R(1.0) + tau * tau));
                c = DOPUS_R(1.0) / dopus_sqrt(DOPUS_R(1.0) + t * t);
                s = t * c;
                /* A <- A J (columns p, q), then A <- J' A (rows p, q), V <- V J. */
                for (k = 0; k < n; ++k) {
                    dopus_real akp = a[k + p * n], akq = a[k + q * n];
                    a[k + p * n] = c * akp - s * akq;
                    a[k + q * n] = s * akp + c * akq;
                }
                for (k = 0; k < n; ++k) {
                    dopus_real apk = a[p + k * n], aqk = a[q + k * n];
                    a[p + k * n] = c * apk - s * aqk;
                    a[q + k * n] = s * apk + c * aqk;
                }
                a[p + q * n] = DOPUS_R(0.0);
                a[q + p * n] = DOPUS_R(0.0);
                for (k = 0; k < n; ++k) {
                    dopus_real vkp = v[k + p * n], vkq = v[k + q * n];
                    v[k + p * n] = c * vkp - s * vkq;
                    v[k + q * n] = s * vkp + c * vkq;
                }
            }
        }
    }
    return dopus_reg_offdiag2(n, a) <= (DOPUS_REAL_EPSILON * DOPUS_REAL_EPSILON) * fro2 ? sweep : -1;
}

int dopus_reg_apply(int n, dopus_real *A, int mode, dopus_real eps, dopus_real *work)
{
    dopus_real *a = work;
    dopus_real *v = work + n * n;
    int i, j, k;

    if (mode != DOPUS_REG_PROJECT && mode != DOPUS_REG_MIRROR) {
        return 0;
    }
    for (i = 0; i < n * n; ++i) {
        a[i] = A[i];
    }
    if (dopus_reg_jacobi_eig(n, a, v) < 0) {
        return -1;
    }
    /* The regularised eigenvalues go on the diagonal of a. */
    for (k = 0; k < n; ++k) {
        dopus_real e = a[k + k * n];
        if (mode == DOPUS_REG_MIRROR) {
            e = dopus_fabs(e);
        }
        a[k + k * n] = e > eps ? e : eps;
    }
    /* A = V diag(e) V', symmetric by construction. */
    for (j = 0; j < n; ++j) {
        for (i = j; i < n; ++i) {
            dopus_real s = DOPUS_R(0.0);
            for (k = 0; k < n; ++k) {
                s += v[i + k * n] * a[k + k * n] * v[j + k * n];
            }
            A[i + j * n] = s;
            A[j + i * n] = s;
        }
    }
    return 0;
}
