/* Hessian regularisation of the stage and terminal A blocks (docs/algorithm.md section 5).
 *
 * A = V diag(e) V' (symmetric eigen-decomposition by cyclic Jacobi, to machine precision);
 *   UNICYCLE_REG_NONE:    A unchanged
 *   UNICYCLE_REG_PROJECT: e_i <- max(e_i, eps)
 *   UNICYCLE_REG_MIRROR:  e_i <- max(|e_i|, eps)
 * The regularised block is what the QP and the secant criterion rho use.
 */
#ifndef UNICYCLE_REG_H
#define UNICYCLE_REG_H

#include "unicycle_real.h"

enum unicycle_regularization { UNICYCLE_REG_NONE = 0, UNICYCLE_REG_PROJECT = 1, UNICYCLE_REG_MIRROR = 2 };

#ifndef UNICYCLE_INTERNAL
#define UNICYCLE_INTERNAL
#endif

/* Eigen-decomposition of the symmetric part of the n x n column-major matrix `a`.
 * On return the diagonal of `a` holds the eigenvalues (off-diagonals ~0) and `v` (n x n,
 * column-major) the orthonormal eigenvectors as columns. Returns the number of sweeps
 * used, or -1 if the off-diagonal mass did not fall to round-off within the sweep limit. */
UNICYCLE_INTERNAL int unicycle_reg_jacobi_eig(int n, unicycle_real *a, unicycle_real *v);

/* Regularise the n x n column-major block A in place. `work` holds at least 2*n*n doubles.
 * Returns 0 on success, -1 if the eigen-decomposition did not converge (A left as given). */
UNICYCLE_INTERNAL int unicycle_reg_apply(int n, unicycle_real *A, int mode, unicycle_real eps, unicycle_real *work);

#endif /* UNICYCLE_REG_H */
