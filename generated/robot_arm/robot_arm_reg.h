/* Hessian regularisation of the stage and terminal A blocks (docs/algorithm.md section 5).
 *
 * A = V diag(e) V' (symmetric eigen-decomposition by cyclic Jacobi, to machine precision);
 *   ROBOT_ARM_REG_NONE:    A unchanged
 *   ROBOT_ARM_REG_PROJECT: e_i <- max(e_i, eps)
 *   ROBOT_ARM_REG_MIRROR:  e_i <- max(|e_i|, eps)
 * The regularised block is what the QP and the secant criterion rho use.
 */
#ifndef ROBOT_ARM_REG_H
#define ROBOT_ARM_REG_H

#include "robot_arm_real.h"

enum robot_arm_regularization { ROBOT_ARM_REG_NONE = 0, ROBOT_ARM_REG_PROJECT = 1, ROBOT_ARM_REG_MIRROR = 2 };

#ifndef ROBOT_ARM_INTERNAL
#define ROBOT_ARM_INTERNAL
#endif

/* Eigen-decomposition of the symmetric part of the n x n column-major matrix `a`.
 * On return the diagonal of `a` holds the eigenvalues (off-diagonals ~0) and `v` (n x n,
 * column-major) the orthonormal eigenvectors as columns. Returns the number of sweeps
 * used, or -1 if the off-diagonal mass did not fall to round-off within the sweep limit. */
ROBOT_ARM_INTERNAL int robot_arm_reg_jacobi_eig(int n, robot_arm_real *a, robot_arm_real *v);

/* Regularise the n x n column-major block A in place. `work` holds at least 2*n*n doubles.
 * Returns 0 on success, -1 if the eigen-decomposition did not converge (A left as given). */
ROBOT_ARM_INTERNAL int robot_arm_reg_apply(int n, robot_arm_real *A, int mode, robot_arm_real eps, robot_arm_real *work);

#endif /* ROBOT_ARM_REG_H */
