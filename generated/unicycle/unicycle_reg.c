/* Eigenvalue regularisation by cyclic Jacobi rotations (docs/algorithm.md section 5).
 *
 * Jacobi is chosen over Householder + QR for its simplicity and its high relative
 * accuracy on the small blocks (n = nx + nu) met here; one sweep is O(n^3) and
 * convergence is quadratic, so a handful of sweeps reaches round-off. */
#include <float.h>
#include <math.h>

#include "unicycle_reg.h"

#define UNICYCLE_REG_MAX_SWEEPS 64

static unicycle_real unicycle_reg_offdiag2(int n, const unicycle_real *a)
{
    unicycle_real s = UNICYCLE_R(0.0);
    int i, j;
    for (j = 0; j < n; ++j) {
        for (i = 0; i < j; ++i) {
            s += a[i + j * n] * a[i + j * n];
        }
    }
    return s;
}

int unicycle_reg_jacobi_eig(int n, unicycle_real *a, unicycle_real *v)
{
    unicycle_real fro2 = UNICYCLE_R(0.0);
    int i, j, k, p, q, sweep;

    /* Symmetrise (the CasADi Hessians are symmetric up to round-off) and set V = I. */
    for (j = 0; j < n; ++j) {
        for (i = 0; i < j; ++i) {
            unicycle_real s = UNICYCLE_R(0.5) * (a[i + j * n] + a[j + i * n]);
            a[i + j * n] = s;
            a[j + i * n] = s;
        }
        for (i = 0; i < n; ++i) {
            v[i + j * n] = (i == j) ? UNICYCLE_R(1.0) : UNICYCLE_R(0.0);
            fro2 += a[i + j * n] * a[i + j * n];
        }
    }
    if (fro2 == UNICYCLE_R(0.0)) {
        return 0;
    }

    for (sweep = 0; sweep < UNICYCLE_REG_MAX_SWEEPS; ++sweep) {
        /* Stop when the off-diagonal part is at round-off level of the whole matrix. */
        if (unicycle_reg_offdiag2(n, a) <= (UNICYCLE_REAL_EPSILON * UNICYCLE_REAL_EPSILON) * UNICYCLE_R(1e-2) * fro2) {
            return sweep;
        }
        for (p = 0; p < n - 1; ++p) {
            for (q = p + 1; q < n; ++q) {
                unicycle_real apq = a[p + q * n];
                unicycle_real app = a[p + p * n];
                unicycle_real aqq = a[q + q * n];
                unicycle_real tau, t, c, s;
                if (apq == UNICYCLE_R(0.0)) {
                    continue;
                }
                /* An entry below round-off of both diagonal entries is zero for
                 * every later rotation too (Golub and Van Loan, section 8.5). */
                if (unicycle_fabs(apq) <= UNICYCLE_R(0.25) * UNICYCLE_REAL_EPSILON * unicycle_fabs(app) &&
                    unicycle_fabs(apq) <= UNICYCLE_R(0.25) * UNICYCLE_REAL_EPSILON * unicycle_fabs(aqq)) {
                    a[p + q * n] = UNICYCLE_R(0.0);
                    a[q + p * n] = UNICYCLE_R(0.0);
                    continue;
                }
                /* The 2x2 symmetric Schur decomposition (Golub and Van Loan, alg. 8.5.1),
                 * the smaller rotation angle for stability. */
                tau = (aqq - app) / (UNICYCLE_R(2.0) * apq);
                t = (tau >= UNICYCLE_R(0.0) ? UNICYCLE_R(1.0) : -UNICYCLE_R(1.0)) /
                    (unicycle_fabs(tau) + unicycle_sqrt(UNICYCLE_R(1.0) + tau * tau));
                c = UNICYCLE_R(1.0) / unicycle_sqrt(UNICYCLE_R(1.0) + t * t);
                s = t * c;
                /* A <- A J (columns p, q), then A <- J' A (rows p, q), V <- V J. */
                for (k = 0; k < n; ++k) {
                    unicycle_real akp = a[k + p * n], akq = a[k + q * n];
                    a[k + p * n] = c * akp - s * akq;
                    a[k + q * n] = s * akp + c * akq;
                }
                for (k = 0; k < n; ++k) {
                    unicycle_real apk = a[p + k * n], aqk = a[q + k * n];
                    a[p + k * n] = c * apk - s * aqk;
                    a[q + k * n] = s * apk + c * aqk;
                }
                a[p + q * n] = UNICYCLE_R(0.0);
                a[q + p * n] = UNICYCLE_R(0.0);
                for (k = 0; k < n; ++k) {
                    unicycle_real vkp = v[k + p * n], vkq = v[k + q * n];
                    v[k + p * n] = c * vkp - s * vkq;
                    v[k + q * n] = s * vkp + c * vkq;
                }
            }
        }
    }
    return unicycle_reg_offdiag2(n, a) <= (UNICYCLE_REAL_EPSILON * UNICYCLE_REAL_EPSILON) * fro2 ? sweep : -1;
}

int unicycle_reg_apply(int n, unicycle_real *A, int mode, unicycle_real eps, unicycle_real *work)
{
    unicycle_real *a = work;
    unicycle_real *v = work + n * n;
    int i, j, k;

    if (mode != UNICYCLE_REG_PROJECT && mode != UNICYCLE_REG_MIRROR) {
        return 0;
    }
    for (i = 0; i < n * n; ++i) {
        a[i] = A[i];
    }
    if (unicycle_reg_jacobi_eig(n, a, v) < 0) {
        return -1;
    }
    /* The regularised eigenvalues go on the diagonal of a. */
    for (k = 0; k < n; ++k) {
        unicycle_real e = a[k + k * n];
        if (mode == UNICYCLE_REG_MIRROR) {
            e = unicycle_fabs(e);
        }
        a[k + k * n] = e > eps ? e : eps;
    }
    /* A = V diag(e) V', symmetric by construction. */
    for (j = 0; j < n; ++j) {
        for (i = j; i < n; ++i) {
            unicycle_real s = UNICYCLE_R(0.0);
            for (k = 0; k < n; ++k) {
                s += v[i + k * n] * a[k + k * n] * v[j + k * n];
            }
            A[i + j * n] = s;
            A[j + i * n] = s;
        }
    }
    return 0;
}
