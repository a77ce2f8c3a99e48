/* Hessian regularisation of the stage and terminal A blocks (docs/algorithm.md section 5).
 *
 * A = V diag(e) V' (symmetric eigen-decomposition by cyclic Jacobi, to machine precision);
 *   DOPUS_REG_NONE:    A unchanged
 *   DOPUS_REG_PROJECT: e_i <- max(e_i, eps)
 *   DOPUS_REG_MIRROR:  e_i <- max(|e_i|, eps)
 * The regularised block is what the QP and the secant criterion rho use.
 */
#ifndef DOPUS_REG_H
#define DOPUS_REG_H

#include "dopus_real.h"

enum dopus_regularization { DOPUS_REG_NONE = 0, DOPUS_REG_PROJECT = 1, DOPUS_REG_MIRROR = 2 };

#ifndef DOPUS_INTERNAL
#define DOPUS_INTERNAL
#endif

/* Eigen-decomposition of the symmetric part of the n x n column-major matrix `a`.
 * On return the diagonal of `a` holds the eigenvalues (off-diagonals ~0) and `v` (n x n,
 * column-major) the orthonormal eigenvectors as columns. Returns the number of sweeps
 * used, or -1 if the off-diagonal mass did not fall to round-off within the sweep limit. */
DOPUS_INTERNAL int dopus_reg_jacobi_eig(int n, dopus_real *a, dopus_real *v);

/* Regularise the n x n column-major block A in place. `work` holds at least 2*n*n doubles.
 * Returns 0 on success, -1 if the eigen-decomposition did not converge (A left as given). */
DOPUS_INTERNAL int dopus_reg_apply(int n, dopus_real *A, int mode, dopus_real eps, dopus_real *work);

#endif /* DOPUS_REG_H */
