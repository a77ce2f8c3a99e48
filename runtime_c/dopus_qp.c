/* Sparse stage-wise QP solver, see dopus_qp.h for the problem, signs and API.
 *
 * Method: infeasible-start primal-dual interior point with Mehrotra's predictor-corrector.
 * Every inequality row i (value v_i = D_i w: a component of w_k, a row of C_k w_k, of
 * x_N or of R x_N) has a lower and an upper side, each with a slack and a multiplier:
 *     v - lo - t_lo = 0,  up - v - t_up = 0,  t, z >= 0,  t_lo z_lo = t_up z_up = sigma mu.
 * Eliminating the slacks and multipliers leaves the Newton system of an equality-constrained
 * LQ problem with stage Hessians H_k + D'QD (Q = z_lo/t_lo + z_up/t_up), solved by a
 * Riccati recursion in which the terminal equality multipliers nu are carried as
 * parameters of the value function (V_k affine in nu) and found from a small ne x ne
 * system at stage 0. This is exact for any scaling of the Req rows.
 *
 * Newton system (unknowns dw, dlam, dnu; rows as in dopus_qp.h):
 *   (H_k + D'QD + delta I) dw_k + [dlam_k; 0] - Phi_k' dlam_{k+1} = rhs_stat_k
 *   (HN + D'QD + delta I) dx_N + dlam_N + Req' dnu               = rhs_stat_N
 *   dx_0 = rhs_dyn_0,  dx_{k+1} - Phi_k dw_k = rhs_dyn_{k+1},  Req dx_N = rhs_eqN
 */
#include "dopus_qp.h"
#include "dopus_linalg.h"

#include <math.h>
#include <stddef.h>

/* Iteration log on stderr, for diagnosis only (compile with -DDOPUS_QP_TRACE). */
#ifdef DOPUS_QP_TRACE
#include <stdio.h>
#define QP_TRACE(...) fprintf(stderr, __VA_ARGS__)
#else
#define QP_TRACE(...) ((void)0)
#endif

/* Full unrolling of the triangular loops over compile-time sizes (dopus_linalg.h): about
 * 15 % of the time of an IPM iteration on the robot arm. */
#define UNROLL DOPUS_UNROLL

#define N DOPUS_N
#define NX DOPUS_NX
#define NU DOPUS_NU
#define NG DOPUS_NG
#define NR DOPUS_NR
#define NE DOPUS_NE
#define NW DOPUS_QP_NW
#define NSI DOPUS_QP_NSTAGEINEQ
#define NI DOPUS_QP_NINEQ
#define NP DOPUS_QP_NPRIM
#define NE1 DOPUS_QP_NE1
#define NU1 DOPUS_QP_NU1
#define TOFF (N * NSI) /* first terminal inequality row */
#define SOFT DOPUS_QP_SOFT
/* The bounded rows of stage k (k = N: the terminal rows): b runs over them, j is the row
 * within the stage (a component of w_k or a row of C_k; of x_N or of R). */
#define FOR_STAGE_ROWS(ws, k, b, j)                                                                          \
    for ((b) = (ws)->bstart[(k)]; (b) < (ws)->bstart[(k) + 1] && ((j) = (ws)->bidx[(b)] - (k)*NSI, 1); ++(b))

/* Fraction-to-boundary factor and limits of the inertia correction. */
#define STEP_TAU DOPUS_R(0.995)
/* Warm start: slacks floored at WARM_FLOOR_T times the bound's scale, multipliers at
 * WARM_FLOOR_Z (both relative to the unit scale of the cold start). */
#ifndef WARM_FLOOR_T
#define WARM_FLOOR_T DOPUS_R(1e-2)
#endif
#ifndef WARM_FLOOR_Z
#define WARM_FLOOR_Z DOPUS_R(1e-2)
#endif
/* Centred cold start: slacks floored at the primal infeasibility of w = 0, at least
 * CENTRED_T_MIN and at most 1, and every multiplier z = floor / t (so t z = floor on
 * every side). */
#define CENTRED_T_MIN DOPUS_R(0.1)
/* Smallest centring parameter of a step taken with the inertia correction (see there). */
#define SIGMA_NONCONVEX DOPUS_R(0.9)
/* Smallest centring parameter after the restart on a nonconvex stall (see dopus_qp_solve). */
#define SIGMA_MIN_RESTART DOPUS_R(0.1)
/* Iterations without progress after an inertia correction that trigger the restart. */
#define RESTART_STALL_ITERS 6
#define DELTA_GROW DOPUS_R(10.0)
/* Largest number of delta increases per factorisation (1e-8 to 1e10 times the Hessian
 * scale takes 18). */
#define DELTA_TRIES 40
#define DELTA_MAX_REL DOPUS_R(1e10)
#define RHO_TRIES 6
#define MU_FLOOR_REL DOPUS_R(0.1)
#define STALL_ITERS 10
#define REFINE_BELOW DOPUS_PREC(1e-6, 1e-3)
#define RHO_MAX_REL DOPUS_R(1e10)
/* Relative rounding unit used in the round-off estimates of the Riccati recursion (a few
 * DBL_EPSILON times the accumulation length). */
#define RICCATI_EPS (DOPUS_R(16.0) * (NW + 1) * DOPUS_REAL_EPSILON)
/* Infeasibility certificates are tested on the dual (primal) iterate normalised to unit
 * infinity norm once it has grown CERT_GROWTH times beyond the data scale: the normalised
 * constraint residual (A'y, or the ray's equality/cone violation) must be below CERT_RES,
 * the separating value (b'y, or the descent g'd / curvature d'Hd) beyond CERT_SEP. */
#define CERT_GROWTH DOPUS_R(1e6)
#define CERT_RES_DUAL DOPUS_PREC(1e-9, 1e-4)
#define CERT_RES_PRIMAL DOPUS_PREC(1e-6, 1e-3)
#define CERT_SEP DOPUS_PREC(1e-6, 1e-3)
/* The separation of a certificate tested after a stall or failure (see
 * primal_infeasible_at_tol): some 5000 (double) or 100 (float) rounding units. */
#define CERT_SEP_STALL DOPUS_PREC(1e-12, 1e-5)
/* Reduction of the normalised certificate residual that counts as progress of the
 * iteration (see qp_last_progress). */
#define CERT_PROGRESS DOPUS_R(0.5)
/* A cold start whose rollout violates a soft side of stage 0 or 1 by more than SOFT_FAR
 * starts from the rollout (see soft_rollout and soft_far); others from w = 0. With 10, the
 * random soft QPs of tests/test_soft.py with N = 40 took up to 37 iterations instead of 18
 * (the start from the rollout suits a violation that the unit slacks cannot take up). */
#ifndef SOFT_FAR
#define SOFT_FAR DOPUS_R(100.0)
#endif

/* Out of line on a scalar FPU with GCC or clang (DOPUS_QP_PHIT 0, see dopus_qp.h): a kernel
 * inlined into a long function shares its registers with the code around it, and on the
 * Cortex-M7's 16 double registers GCC then spilled the accumulators of both. */
#if !DOPUS_QP_PHIT && (defined(__GNUC__) || defined(__clang__))
#define QP_NOINLINE __attribute__((noinline))
#else
#define QP_NOINLINE
#endif

/* Out of line and optimised for size: code that runs only after a failed pivot. */
#if defined(__GNUC__) || defined(__clang__)
#define QP_COLD __attribute__((noinline, cold))
#else
#define QP_COLD
#endif

static dopus_real dmax(dopus_real a, dopus_real b)
{
    return a > b ? a : b;
}
static dopus_real dmin(dopus_real a, dopus_real b)
{
    return a < b ? a : b;
}

void dopus_qp_settings_default(dopus_qp_settings *settings)
{
    settings->tol = DOPUS_PREC(1e-8, 1e-5);
    settings->max_iter = 100;
    settings->warm_start = 0;
    settings->refine_steps = 1;
    settings->active_set = 0;
    settings->clock = NULL;
    settings->clock_ctx = NULL;
    settings->deadline = 0.0;
    settings->iter_price = 0.0;
    settings->prefactored = 0;
}

unsigned long dopus_qp_workspace_size(void)
{
    return (unsigned long)sizeof(dopus_qp_workspace);
}

/* ---------------------------------------------------------------- data checks */

/* 1 when the n entries of x are finite (as dopus_lai_all_finite); *m = max(*m, |x_i|) (the
 * Hessian scale, formed in the same pass). */
static int finite_absmax(int n, const dopus_real *restrict x, dopus_real *restrict m)
{
    int i;
    dopus_real s0 = DOPUS_R(0.0), s1 = DOPUS_R(0.0), m0 = *m, m1 = DOPUS_R(0.0);
    for (i = 0; i + 1 < n; i += 2) {
        const dopus_real a0 = dopus_fabs(x[i]), a1 = dopus_fabs(x[i + 1]);
        s0 += x[i] * DOPUS_R(0.0);
        s1 += x[i + 1] * DOPUS_R(0.0);
        m0 = DOPUS_MAX_ACC(a0, m0);
        m1 = DOPUS_MAX_ACC(a1, m1);
    }
    if (i < n) {
        const dopus_real a0 = dopus_fabs(x[i]);
        s0 += x[i] * DOPUS_R(0.0);
        m0 = DOPUS_MAX_ACC(a0, m0);
    }
    *m = DOPUS_MAX_ACC(m1, m0);
    return s0 + s1 == DOPUS_R(0.0);
}

/* finite_absmax over the lower triangle (with the diagonal) of the n x n column-major A (the
 * QP reads only that triangle of H_k). */
static int finite_absmax_lower(int n, const dopus_real *restrict A, dopus_real *restrict m)
{
    int j, ok = 1;
    for (j = 0; j < n; ++j) /* column j from the diagonal down */
        ok &= finite_absmax(n - j, A + j + j * n, m);
    return ok;
}

/* 1 when the Hessians H_k (lower triangles) and HN are finite; *hmax: their largest |entry|
 * (H_0 .. H_{N-1}, then HN; the pointers checked by the caller). */
static int hessians_absmax(const dopus_qp_in *in, dopus_real *hmax)
{
    int k;
    *hmax = DOPUS_R(0.0);
    for (k = 0; k < N; ++k)
        if (!finite_absmax_lower(NW, in->H[k], hmax))
            return 0;
    return finite_absmax(NX * NX, in->HN, hmax);
}

/* 1 when the data is complete and finite; *hmax: the largest |entry| of the Hessians H_k
 * (lower triangles) and HN (valid when it returns 1). hmax NULL: H_k and HN are known finite
 * (a prefactor scanned them, ws->pre_hmax) and are not read. */
static int check_input(const dopus_qp_in *in, dopus_real *hmax)
{
    int k, i;
    for (k = 0; k < N; ++k) {
        if (in->H[k] == NULL || in->Phi[k] == NULL || (NG > 0 && in->C[k] == NULL))
            return 0;
        if (!dopus_lai_all_finite(NX, NW, in->Phi[k], NX) ||
            (NG > 0 && !dopus_lai_all_finite(NG, NW, in->C[k], NG > 0 ? NG : 1)) ||
            !dopus_lai_all_finite(NW, 1, in->g[k], NW) || !dopus_lai_all_finite(NX, 1, in->b[k], NX))
            return 0;
    }
    if (in->HN == NULL || (NR > 0 && in->R == NULL) || (NE > 0 && in->Req == NULL))
        return 0;
    if (!(in->hess_shift >= DOPUS_R(0.0) && in->hess_shift < INFINITY))
        return 0;
    if ((hmax && !hessians_absmax(in, hmax)) || !dopus_lai_all_finite(NX, 1, in->x0, NX) ||
        !dopus_lai_all_finite(NX, 1, in->gN, NX))
        return 0;
    if (NR > 0 && !dopus_lai_all_finite(NR, NX, in->R, NR > 0 ? NR : 1))
        return 0;
    if (NE > 0 && (!dopus_lai_all_finite(NE, NX, in->Req, NE1) || !dopus_lai_all_finite(NE, 1, in->req, NE1)))
        return 0;
    for (k = 0; k < N; ++k) {
        for (i = 0; i < NW; ++i)
            /* false for a NaN, lo = +inf or up = -inf */
            if (!(in->lbw[k][i] < INFINITY && in->ubw[k][i] > -INFINITY) && (k > 0 || i >= NX))
                return 0;
        for (i = 0; i < NG; ++i)
            if (!(in->lg[k][i] < INFINITY && in->ug[k][i] > -INFINITY))
                return 0;
    }
    for (i = 0; i < NX; ++i)
        if (!(in->lbxN[i] < INFINITY && in->ubxN[i] > -INFINITY))
            return 0;
    for (i = 0; i < NR; ++i)
        if (!(in->lr[i] < INFINITY && in->ur[i] > -INFINITY))
            return 0;
    if (SOFT) {
        for (i = 0; i < DOPUS_QP_NSS; ++i)
            if (!(in->zl[i] >= DOPUS_R(0.0) && in->zl[i] < INFINITY && in->zu[i] >= DOPUS_R(0.0) &&
                  in->zu[i] < INFINITY && in->Zl[i] >= DOPUS_R(0.0) && in->Zl[i] < INFINITY &&
                  in->Zu[i] >= DOPUS_R(0.0) && in->Zu[i] < INFINITY))
                return 0;
        for (i = 0; i < DOPUS_QP_NST; ++i)
            if (!(in->zlN[i] >= DOPUS_R(0.0) && in->zlN[i] < INFINITY && in->zuN[i] >= DOPUS_R(0.0) &&
                  in->zuN[i] < INFINITY && in->ZlN[i] >= DOPUS_R(0.0) && in->ZlN[i] < INFINITY &&
                  in->ZuN[i] >= DOPUS_R(0.0) && in->ZuN[i] < INFINITY))
                return 0;
    }
    return 1;
}

/* The soft weights of inequality row i (flat layout): w = (zl, zu, Zl, Zu). */
static void soft_weights(const dopus_qp_in *in, int i, dopus_real *w)
{
    if (i < TOFF) {
        const int j = i - (i / NSI) * NSI;
        w[0] = in->zl[j];
        w[1] = in->zu[j];
        w[2] = in->Zl[j];
        w[3] = in->Zu[j];
    } else {
        const int j = i - TOFF;
        w[0] = in->zlN[j];
        w[1] = in->zuN[j];
        w[2] = in->ZlN[j];
        w[3] = in->ZuN[j];
    }
}

/* Lower and upper bound of inequality row i (flat row layout of dopus_qp.h). */
static void row_bounds(const dopus_qp_in *in, int i, dopus_real *lo, dopus_real *up)
{
    if (i < TOFF) {
        const int k = i / NSI, j = i - k * NSI;
        if (NG == 0 || j < NW) {
            *lo = in->lbw[k][j];
            *up = in->ubw[k][j];
        } else {
            *lo = in->lg[k][j - NW];
            *up = in->ug[k][j - NW];
        }
    } else if (NR == 0 || i - TOFF < NX) {
        *lo = in->lbxN[i - TOFF];
        *up = in->ubxN[i - TOFF];
    } else {
        *lo = in->lr[i - TOFF - NX];
        *up = in->ur[i - TOFF - NX];
    }
}

/* The bounded rows (a finite side that is not ignored) with their bounds. Returns 0, or 1
 * when some lo > up (trivially infeasible), or 2 when there are more than DOPUS_QP_NB. */
static int setup_bounds(dopus_qp_workspace *ws, const dopus_qp_in *in)
{
    int k, i, ok = 0, nb = 0;
    for (k = 0; k <= N; ++k) {
        const int first = k * NSI, last = k < N ? first + NSI : NI;
        ws->bstart[k] = (dopus_qp_row)nb;
        for (i = first; i < last; ++i) {
            /* x_0 is fixed by x0: its box rows are ignored, and so are the general rows of
             * stage 0 that do not involve u_0 (their value is data; a multiplier on them is
             * not unique, lam_0 absorbs any value, and a violation by round-off in x0 could
             * never be removed) */
            int ignored = (i < NX), data = 0, hl, hu;
            dopus_real lo, up, w[4] = {DOPUS_R(0.0), DOPUS_R(0.0), DOPUS_R(0.0), DOPUS_R(0.0)};
            if (NG > 0 && i >= NW && i < NW + NG) {
                int c;
                data = 1;
                for (c = NX; c < NW; ++c)
                    if (in->C[0][(i - NW) + c * NG] != DOPUS_R(0.0))
                        data = 0;
                ignored = data;
            }
            if (SOFT)
                soft_weights(in, i, w);
            row_bounds(in, i, &lo, &up);
            /* a soft side of such a data row stays: its slack takes up the violation and its
             * multiplier, zl + Zl s, is unique */
            hl = isfinite(lo) && (!ignored || (SOFT && data && (w[0] > DOPUS_R(0.0) || w[2] > DOPUS_R(0.0))));
            hu = isfinite(up) && (!ignored || (SOFT && data && (w[1] > DOPUS_R(0.0) || w[3] > DOPUS_R(0.0))));
            if (!hl && !hu)
                continue;
            if (nb >= DOPUS_QP_NB)
                return 2;
            ws->bidx[nb] = (dopus_qp_row)i;
            ws->has_lo[nb] = (unsigned char)hl;
            ws->has_up[nb] = (unsigned char)hu;
            if (SOFT) {
                ws->soft_lo[nb] = (unsigned char)(hl && (w[0] > DOPUS_R(0.0) || w[2] > DOPUS_R(0.0)));
                ws->soft_up[nb] = (unsigned char)(hu && (w[1] > DOPUS_R(0.0) || w[3] > DOPUS_R(0.0)));
            }
            /* lo > up: no point meets a hard row (a soft side can give way) */
            if (hl && hu && lo > up && !(SOFT && (ws->soft_lo[nb] || ws->soft_up[nb])))
                ok = 1;
            ++nb;
        }
    }
    ws->bstart[N + 1] = (dopus_qp_row)nb;
    ws->nb = nb;
    return ok;
}

/* ---------------------------------------------------------------- row maps D, D' */

/* D_j w for row j of stage k (k = N: the terminal rows), w the stage's primal vector. */
static dopus_real row_dot(const dopus_qp_in *in, int k, int j, const dopus_real *w)
{
    dopus_real s = DOPUS_R(0.0);
    int c;
    if (k < N) {
        if (NG == 0 || j < NW)
            return w[j];
        for (c = 0; c < NW; ++c)
            s += in->C[k][(j - NW) + c * NG] * w[c];
    } else {
        if (NR == 0 || j < NX)
            return w[j];
        for (c = 0; c < NX; ++c)
            s += in->R[(j - NX) + c * NR] * w[c];
    }
    return s;
}

/* o += a D_j' for row j of stage k, o the stage's part of a primal-sized vector. */
static void row_axpy(const dopus_qp_in *in, int k, int j, dopus_real a, dopus_real *o)
{
    int c;
    if (k < N) {
        if (NG == 0 || j < NW)
            o[j] += a;
        else
            for (c = 0; c < NW; ++c)
                o[c] += in->C[k][(j - NW) + c * NG] * a;
    } else if (NR == 0 || j < NX) {
        o[j] += a;
    } else {
        for (c = 0; c < NX; ++c)
            o[c] += in->R[(j - NX) + c * NR] * a;
    }
}

/* y = beta y + alpha A x (A m x n, column-major) as dopus_lai_gemv_n: each entry the sum over
 * the columns in their order, with beta 0 (y overwritten) or 1. With AVX (DOPUS_QP_V4) four
 * rows per vector with the sums in registers and the rows left over alone: the same
 * operations on each entry in the same order, so the same values (GCC 12 left the product
 * with Phi_k at nx = 5 scalar, two instructions per product). */
#if DOPUS_QP_PHIT && DOPUS_LAI_VEC && defined(__AVX__)
#define DOPUS_QP_V4 1
typedef dopus_real qp_v4 __attribute__((vector_size(4 * sizeof(dopus_real))));
static inline void qp_gemv_n(int m, int n, dopus_real alpha, const dopus_real *restrict A, int lda,
                             const dopus_real *restrict x, dopus_real beta, dopus_real *restrict y)
{
    int i = 0, j;
    for (; i + 4 <= m; i += 4) {
        qp_v4 acc = {DOPUS_R(0.0), DOPUS_R(0.0), DOPUS_R(0.0), DOPUS_R(0.0)};
        if (beta != DOPUS_R(0.0))
            __builtin_memcpy(&acc, y + i, sizeof acc);
        for (j = 0; j < n; ++j) {
            qp_v4 a;
            __builtin_memcpy(&a, A + i + j * lda, sizeof a);
            acc += a * (alpha * x[j]);
        }
        __builtin_memcpy(y + i, &acc, sizeof acc);
    }
    for (; i < m; ++i) {
        dopus_real s = beta != DOPUS_R(0.0) ? y[i] : DOPUS_R(0.0);
        for (j = 0; j < n; ++j)
            s += A[i + j * lda] * (alpha * x[j]);
        y[i] = s;
    }
}
#else
#define DOPUS_QP_V4 0
#define qp_gemv_n dopus_lai_gemv_n
#endif

/* y += alpha P x for P packed by lower columns: one sequential pass over the packed
 * entries, each used twice (below the diagonal), the sums kept in a local vector. */
static inline void spmv_packed(const dopus_real *restrict Pp, dopus_real alpha, const dopus_real *restrict x,
                               dopus_real *restrict y)
{
    dopus_real acc[NX];
    int i, j, l = 0;
    for (i = 0; i < NX; ++i)
        acc[i] = DOPUS_R(0.0);
    UNROLL
    for (j = 0; j < NX; ++j) {
        const dopus_real xj = x[j];
        dopus_real s = Pp[l++] * xj;
        UNROLL
        for (i = j + 1; i < NX; ++i, ++l) {
            acc[i] += Pp[l] * xj;
            s += Pp[l] * x[i];
        }
        acc[j] += s;
    }
    for (i = 0; i < NX; ++i)
        y[i] += alpha * acc[i];
}

/* The Cholesky factor Lu (nu x nu, lower) of a stage kept packed by lower columns in the
 * workspace with its diagonal stored inverted, so that the triangular solves multiply
 * (a division on the recursion's critical path costs several multiplications). */
#define PACKED_U(i, j) ((j)*NU - (j) * ((j)-1) / 2 + (i) - (j))
static void pack_lu(const dopus_real *restrict L, dopus_real *restrict Lp)
{
    int i, j, l = 0;
    UNROLL
    for (j = 0; j < NU; ++j) {
        Lp[l++] = DOPUS_R(1.0) / L[j + j * NU1];
        UNROLL
        for (i = j + 1; i < NU; ++i)
            Lp[l++] = L[i + j * NU1];
    }
}
/* x = Lu^{-1} x for the packed factor (column by column: the updates of one column are
 * independent of each other) */
static inline void lu_solve_n(const dopus_real *restrict Lp, dopus_real *restrict x)
{
    int i, j;
    UNROLL
    for (j = 0; j < NU; ++j) {
        const dopus_real xj = x[j] * Lp[PACKED_U(j, j)];
        x[j] = xj;
        UNROLL
        for (i = j + 1; i < NU; ++i)
            x[i] -= Lp[PACKED_U(i, j)] * xj;
    }
}
/* dst = Lu^{-1} src: lu_solve_n on a copy of src (the copy in registers) */
static inline void lu_solve_n_from(const dopus_real *restrict Lp, const dopus_real *restrict src,
                                   dopus_real *restrict dst)
{
    dopus_real x[NU1];
    int i;
    for (i = 0; i < NU; ++i)
        x[i] = src[i];
    lu_solve_n(Lp, x);
    for (i = 0; i < NU; ++i)
        dst[i] = x[i];
}
/* x = Lu'^{-1} x for the packed factor */
static inline void lu_solve_t(const dopus_real *restrict Lp, dopus_real *restrict x)
{
    int i, j;
    UNROLL
    for (j = NU - 1; j >= 0; --j) {
        dopus_real s = x[j];
        UNROLL
        for (i = j + 1; i < NU; ++i)
            s -= Lp[PACKED_U(i, j)] * x[i];
        x[j] = s * Lp[PACKED_U(j, j)];
    }
}

/* Per bounded row b: the residuals of the slack equations, r_lo = v - lo - t_lo and
 * r_up = up - v - t_up (vl = v - lo and uv = up - v are kept), the slack steps of the current direction, dt_lo = dv + r_lo and
 * dt_up = r_up - dv (dv = D dw), and the barrier weight q = z_lo/t_lo + z_up/t_up, formed
 * where they are used rather than stored. */
static dopus_real r_lo(const dopus_qp_workspace *ws, int b)
{
    return SOFT && ws->soft_lo[b] ? ws->vl[b] + ws->s_lo[b] - ws->t_lo[b] : ws->vl[b] - ws->t_lo[b];
}
static dopus_real r_up(const dopus_qp_workspace *ws, int b)
{
    return SOFT && ws->soft_up[b] ? ws->uv[b] + ws->s_up[b] - ws->t_up[b] : ws->uv[b] - ws->t_up[b];
}
/* A soft side's slack step ds enters its row's slack step: dt_lo = dv + ds_lo + r_lo. */
static dopus_real dt_lo(const dopus_qp_workspace *ws, int b)
{
    return SOFT && ws->soft_lo[b] ? ws->dv[b] + ws->ds_lo[b] + r_lo(ws, b) : ws->dv[b] + r_lo(ws, b);
}
static dopus_real dt_up(const dopus_qp_workspace *ws, int b)
{
    return SOFT && ws->soft_up[b] ? r_up(ws, b) - ws->dv[b] + ws->ds_up[b] : r_up(ws, b) - ws->dv[b];
}

/* The elimination of a soft side's slack (see dopus_qp.h). With q = z/t, p = y/s and Z the
 * L2 weight, the slack's Newton equation Z ds - dz - dy = -rs (rs = Z s + zsoft - z - y)
 * gives ds = -(rs + rcs/s + a + q dvs) / (Z + q + p), dvs = dv (lower side) or -dv (upper),
 * a = (rc + z r)/t the right-hand side term of a hard side, rcs the barrier right-hand side
 * of the pair s y. Substituted, the side acts on the row as a hard side with the barrier
 * weight q f and the right-hand side term f a - (q / (Z + q + p)) (rs + rcs/s), f = (Z + p)
 * / (Z + q + p). */
static dopus_real soft_f(dopus_real q, dopus_real p, dopus_real Z)
{
    return (Z + p) / (Z + q + p);
}

/* p = y/s of a soft side (flag 1). */
static dopus_real soft_p(unsigned char flag, dopus_real y, dopus_real sl)
{
    return flag == 1 ? y / sl : DOPUS_R(0.0);
}

static dopus_real soft_l2(const dopus_qp_in *in, const dopus_qp_workspace *ws, int b, int upper)
{
    dopus_real w[4];
    soft_weights(in, ws->bidx[b], w);
    return upper ? w[3] : w[2];
}

static dopus_real row_q(const dopus_qp_workspace *ws, const dopus_qp_in *in, int b)
{
    dopus_real q = DOPUS_R(0.0);
    if (ws->penalty) /* the active-set start: the penalty weight of an active row */
        return ws->act[b] ? ws->pen[b] : DOPUS_R(0.0);
    if (ws->has_lo[b]) {
        const dopus_real ql = ws->z_lo[b] / ws->t_lo[b];
        q += SOFT && ws->soft_lo[b]
                 ? ql * soft_f(ql, soft_p(ws->soft_lo[b], ws->y_lo[b], ws->s_lo[b]), soft_l2(in, ws, b, 0))
                 : ql;
    }
    if (ws->has_up[b]) {
        const dopus_real qu = ws->z_up[b] / ws->t_up[b];
        q += SOFT && ws->soft_up[b]
                 ? qu * soft_f(qu, soft_p(ws->soft_up[b], ws->y_up[b], ws->s_up[b]), soft_l2(in, ws, b, 1))
                 : qu;
    }
    return q;
}

/* ---------------------------------------------------------------- Phi' v */

/* PhiT = Phi' (nw x nx, column-major). With DOPUS_QP_PHIT it is formed once per solve for
 * every stage (the data is constant during it): the products with Phi_k' then run down
 * contiguous columns of length nw, vectorised where the target has vectors, instead of a sum
 * of nx products per entry; without it, the products read Phi_k (the factorisation's Phi' P
 * as dot products of its contiguous columns). */
#if DOPUS_QP_PHIT
static void transpose_phi(dopus_qp_workspace *ws, const dopus_qp_in *in)
{
    int k, i, l;
    for (k = 0; k < N; ++k)
        for (i = 0; i < NW; ++i)
            for (l = 0; l < NX; ++l)
                ws->PhiT[k][i + l * NW] = in->Phi[k][l + i * NX];
}
/* PhiT_k (nw x nx) for phit_gemv, and its entry (i, l) = Phi_k(l, i) */
#define QP_PHIT(ws, in, k) ((const dopus_real *)(ws)->PhiT[(k)])
#define PHIT_AT(A, i, l) ((A)[(i) + (l)*NW])
#else
/* without the copy, phit_gemv reads Phi_k itself (nx x nw) */
#define QP_PHIT(ws, in, k) ((in)->Phi[(k)])
#define PHIT_AT(A, i, l) ((A)[(l) + (i)*NX])
#endif

/* y += alpha Phi' v over QP_PHIT (y of size nw, v of size nx): the same sums in the same
 * order as dopus_lai_gemv_t(NX, NW, alpha, Phi, NX, v, 1, y), so the same bits. */
static inline void phit_gemv(const dopus_real *restrict PhiT, dopus_real alpha, const dopus_real *restrict v,
                             dopus_real *restrict y)
{
    dopus_real s[NW];
    int i, l;
    for (i = 0; i < NW; ++i)
        s[i] = DOPUS_R(0.0);
    for (l = 0; l < NX; ++l) {
        const dopus_real f = v[l];
        for (i = 0; i < NW; ++i)
            s[i] += PHIT_AT(PhiT, i, l) * f;
    }
    for (i = 0; i < NW; ++i)
        y[i] += alpha * s[i];
}

/* ---------------------------------------------------------------- residuals */

/* The data parts of the residual scaling (constant during a solve): |g|, |gN| into
 * scale_g; |x0|, |b|, |req| into scale_b; the finite bounds into scale_bounds. */
static void data_scales(dopus_qp_workspace *ws, const dopus_qp_in *in)
{
    int k, i;
    dopus_real sg = dopus_lai_norm_inf(NX, in->gN), sb = dopus_lai_norm_inf(NX, in->x0), sl = DOPUS_R(0.0);
    for (k = 0; k < N; ++k) {
        sg = dmax(sg, dopus_lai_norm_inf(NW, in->g[k]));
        sb = dmax(sb, dopus_lai_norm_inf(NX, in->b[k]));
    }
    if (NE > 0)
        sb = dmax(sb, dopus_lai_norm_inf(NE, in->req));
    for (i = 0; i < ws->nb; ++i) {
        dopus_real lo, up;
        row_bounds(in, ws->bidx[i], &lo, &up);
        if (ws->has_lo[i])
            sl = dmax(sl, dopus_fabs(lo));
        if (ws->has_up[i])
            sl = dmax(sl, dopus_fabs(up));
    }
    ws->scale_g = sg;
    ws->scale_b = sb;
    ws->scale_bounds = sl;
}

typedef struct {
    dopus_real mu;                           /* average complementarity */
    int nsides;                              /* number of bounded sides */
    dopus_real stat, eq, ineq, comp;         /* unscaled inf-norms */
    dopus_real stat_s, eq_s, ineq_s, comp_s; /* scaled */
    dopus_real ny;                           /* inf-norm of the dual iterate */
    dopus_real nw;                           /* inf-norm of the primal iterate */
    dopus_real aty; /* inf-norm of the constraint part A'y of the stationarity residual */
    dopus_real nz;  /* inf-norm of the inequality multipliers */
} qp_res;

/* acc_i = max(acc_i, |x_i|), entry by entry (n a compile-time size: vectorised, no chain of
 * dependent max instructions); the scales below reduce acc once at the end. On a scalar FPU
 * (where Phi_k' is not kept, DOPUS_QP_PHIT 0) the entry-wise maxima cost a load and a store
 * of acc_i per entry: there acc_0 takes the maximum of all (the others stay 0), the same
 * value (a maximum is exact in any order, and DOPUS_MAX_ACC never keeps a NaN of x). */
static inline void absmax_acc(int n, const dopus_real *restrict x, dopus_real *restrict acc)
{
    int i = 0;
#if DOPUS_QP_PHIT
#if DOPUS_LAI_V4_MAX
    /* four entries per vector (the same maxima) */
    for (; i + 3 < n; i += 4)
        dopus_lai_v4_store(acc + i, dopus_lai_v4_max_acc(dopus_lai_v4_abs(dopus_lai_v4_load(x + i)),
                                                         dopus_lai_v4_load(acc + i)));
#endif
#if DOPUS_LAI_V2_MAX
    /* two entries per vector (the same maxima) */
    for (; i + 1 < n; i += 2)
        dopus_lai_v2_store(acc + i, dopus_lai_v2_max_acc(dopus_lai_v2_abs(dopus_lai_v2_load(x + i)),
                                                         dopus_lai_v2_load(acc + i)));
#endif
    for (; i < n; ++i) {
        const dopus_real a = dopus_fabs(x[i]);
        acc[i] = DOPUS_MAX_ACC(a, acc[i]);
    }
#else
    dopus_real m = acc[0];
    for (i = 0; i < n; ++i) {
        const dopus_real a = dopus_fabs(x[i]);
        m = DOPUS_MAX_ACC(a, m);
    }
    acc[0] = m;
#endif
}

/* a -= Phi' v (a of size nw, v of size nx) and rd = -Phi w (rd of size nx): as phit_gemv(PhiT,
 * -1, v, a) and dopus_lai_gemv_n(NX, NW, -1, Phi, NX, w, 0, rd), the same sums in the same
 * order. Without the kept Phi_k' (DOPUS_QP_PHIT 0) both run over the columns of Phi_k in one
 * pass: each entry is loaded once for its two products. */
static inline void phi_both(const dopus_real *restrict Phi, const dopus_real *restrict PhiT,
                            const dopus_real *restrict v, const dopus_real *restrict w,
                            dopus_real *restrict a, dopus_real *restrict rd)
{
#if DOPUS_QP_PHIT
    phit_gemv(PhiT, -DOPUS_R(1.0), v, a);
    qp_gemv_n(NX, NW, -DOPUS_R(1.0), Phi, NX, w, DOPUS_R(0.0), rd);
#else
    dopus_real acc[NX], vr[NX];
    int i, l;
    (void)PhiT;
    for (l = 0; l < NX; ++l) {
        acc[l] = DOPUS_R(0.0);
        vr[l] = v[l];
    }
    UNROLL
    for (i = 0; i < NW; ++i) {
        const dopus_real wi = -w[i];
        dopus_real s = DOPUS_R(0.0);
        UNROLL
        for (l = 0; l < NX; ++l) {
            const dopus_real p = Phi[l + i * NX];
            s += p * vr[l];
            acc[l] += p * wi;
        }
        a[i] += -s;
    }
    for (l = 0; l < NX; ++l)
        rd[l] = acc[l];
#endif
}

static void compute_residuals(dopus_qp_workspace *ws, const dopus_qp_in *in, qp_res *r)
{
    int k, i, b, j;
    dopus_real s_stat = DOPUS_R(1.0), s_eq = DOPUS_R(1.0), s_ineq = DOPUS_R(1.0), nz = DOPUS_R(0.0),
               comp = DOPUS_R(0.0), ineq = DOPUS_R(0.0);
    dopus_real sum_c = DOPUS_R(0.0), naty, nlam, rs_max = DOPUS_R(0.0);
    /* entry-wise maxima over the stages: |Hw|, |A'y|, |w|, |Phi w| and |lam| */
    dopus_real m_h[NW], m_a[NW], m_w[NW], m_pw[NX], m_lam[NX];
    int m = 0;

    /* One pass, stage by stage: the objective part Hw + g and the constraint part A'y (a)
     * of the stationarity residual, the bounded rows of the stage (row values, slack
     * residuals, violation, complementarity), the dynamics residual of the stage's
     * equation and the norms of the iterate. */
    s_ineq = dmax(s_ineq, ws->scale_bounds);
    s_eq = dmax(s_eq, ws->scale_b);
    for (i = 0; i < NW; ++i)
        m_h[i] = m_a[i] = m_w[i] = DOPUS_R(0.0);
    for (i = 0; i < NX; ++i) {
        m_pw[i] = m_lam[i] = DOPUS_R(0.0);
        ws->r_dyn[i] = ws->prim[i] - in->x0[i];
    }
    for (k = 0; k <= N; ++k) {
        const int nk = k < N ? NW : NX;
        const dopus_real *w = ws->prim + k * NW;
        dopus_real *h = ws->r_stat + k * NW;
        dopus_real a[NW];
        if (k < N) {
            dopus_real *rd = ws->r_dyn + (k + 1) * NX;
            const dopus_real *xn = ws->prim + (k + 1) * NW;
            dopus_lai_symv_l(NW, DOPUS_R(1.0), in->H[k], NW, w, DOPUS_R(0.0), h);
            dopus_lai_axpy(NW, in->hess_shift, w, h);
            absmax_acc(NW, h, m_h);
            dopus_lai_axpy(NW, DOPUS_R(1.0), in->g[k], h);
            for (i = 0; i < NW; ++i)
                a[i] = i < NX ? ws->lam[k * NX + i] : DOPUS_R(0.0);
            /* a -= Phi' lam_{k+1} and r_dyn_{k+1} = x_{k+1} - Phi_k w_k - b_k */
            phi_both(in->Phi[k], QP_PHIT(ws, in, k), ws->lam + (k + 1) * NX, w, a, rd);
            absmax_acc(NX, rd, m_pw);
            for (i = 0; i < NX; ++i)
                rd[i] += xn[i] - in->b[k][i];
        } else {
            dopus_lai_symv_l(NX, DOPUS_R(1.0), in->HN, NX, w, DOPUS_R(0.0), h);
            dopus_lai_axpy(NX, in->hess_shift, w, h);
            absmax_acc(NX, h, m_h);
            s_stat = dmax(s_stat, ws->scale_g);
            dopus_lai_axpy(NX, DOPUS_R(1.0), in->gN, h);
            for (i = 0; i < NX; ++i)
                a[i] = ws->lam[N * NX + i];
            if (NE > 0)
                dopus_lai_gemv_t(NE, NX, DOPUS_R(1.0), in->Req, NE1, ws->nu, DOPUS_R(1.0), a);
        }
        absmax_acc(nk, w, m_w);
        absmax_acc(NX, ws->lam + k * NX, m_lam);
        FOR_STAGE_ROWS(ws, k, b, j)
        {
            /* signed multiplier y = z_up - z_lo of the row into A'y */
            const dopus_real zl = ws->has_lo[b] ? ws->z_lo[b] : DOPUS_R(0.0);
            const dopus_real zu = ws->has_up[b] ? ws->z_up[b] : DOPUS_R(0.0);
            const dopus_real v = row_dot(in, k, j, w);
            dopus_real lo, up;
            nz = dmax(nz, dmax(zl, zu));
            row_axpy(in, k, j, zu - zl, a);
            row_bounds(in, ws->bidx[b], &lo, &up);
            /* vl, uv (and the directions) are only defined on the bounded sides */
            if (ws->has_lo[b]) {
                ws->vl[b] = v - lo;
                ineq = dmax(ineq, SOFT && ws->soft_lo[b] ? lo - v - ws->s_lo[b] : lo - v);
                comp = dmax(comp, ws->t_lo[b] * ws->z_lo[b]);
                sum_c += ws->t_lo[b] * ws->z_lo[b];
                ++m;
            }
            if (ws->has_up[b]) {
                ws->uv[b] = up - v;
                ineq = dmax(ineq, SOFT && ws->soft_up[b] ? v - up - ws->s_up[b] : v - up);
                comp = dmax(comp, ws->t_up[b] * ws->z_up[b]);
                sum_c += ws->t_up[b] * ws->z_up[b];
                ++m;
            }
            if (SOFT && (ws->soft_lo[b] || ws->soft_up[b])) {
                /* the slacks: stationarity Z s + zsoft - z - y, complementarity s y */
                dopus_real w[4];
                soft_weights(in, ws->bidx[b], w);
                if (ws->soft_lo[b]) {
                    ws->rs_lo[b] = w[2] * ws->s_lo[b] + w[0] - ws->z_lo[b] - ws->y_lo[b];
                    rs_max = dmax(rs_max, dopus_fabs(ws->rs_lo[b]));
                    s_stat = dmax(s_stat, dmax(w[0], w[2] * dopus_fabs(ws->s_lo[b])));
                    if (ws->soft_lo[b] == 1) {
                        comp = dmax(comp, ws->s_lo[b] * ws->y_lo[b]);
                        sum_c += ws->s_lo[b] * ws->y_lo[b];
                        nz = dmax(nz, ws->y_lo[b]);
                        ++m;
                    }
                }
                if (ws->soft_up[b]) {
                    ws->rs_up[b] = w[3] * ws->s_up[b] + w[1] - ws->z_up[b] - ws->y_up[b];
                    rs_max = dmax(rs_max, dopus_fabs(ws->rs_up[b]));
                    s_stat = dmax(s_stat, dmax(w[1], w[3] * dopus_fabs(ws->s_up[b])));
                    if (ws->soft_up[b] == 1) {
                        comp = dmax(comp, ws->s_up[b] * ws->y_up[b]);
                        sum_c += ws->s_up[b] * ws->y_up[b];
                        nz = dmax(nz, ws->y_up[b]);
                        ++m;
                    }
                }
            }
            s_ineq = dmax(s_ineq, dopus_fabs(v));
        }
        absmax_acc(nk, a, m_a);
        for (i = 0; i < nk; ++i)
            h[i] += a[i];
    }
    naty = dopus_lai_norm_inf(NW, m_a);
    nlam = dopus_lai_norm_inf(NX, m_lam);
    s_stat = dmax(s_stat, dmax(dopus_lai_norm_inf(NW, m_h), naty));
    r->nw = dopus_lai_norm_inf(NW, m_w);
    s_eq = dmax(s_eq, dmax(r->nw, dopus_lai_norm_inf(NX, m_pw)));
    if (NE > 0) {
        dopus_lai_gemv_n(NE, NX, DOPUS_R(1.0), in->Req, NE1, ws->prim + N * NW, DOPUS_R(0.0), ws->r_eqN);
        s_eq = dmax(s_eq, dopus_lai_norm_inf(NE, ws->r_eqN));
        for (i = 0; i < NE; ++i)
            ws->r_eqN[i] -= in->req[i];
    }

    r->nsides = m;
    r->mu = m > 0 ? sum_c / m : DOPUS_R(0.0);
    r->stat = dopus_lai_norm_inf(NP, ws->r_stat);
    if (SOFT)
        r->stat = dmax(r->stat, rs_max);
    r->eq = dmax(dopus_lai_norm_inf((N + 1) * NX, ws->r_dyn),
                 NE > 0 ? dopus_lai_norm_inf(NE, ws->r_eqN) : DOPUS_R(0.0));
    r->ineq = ineq;
    r->comp = comp;
    r->stat_s = r->stat / s_stat;
    r->eq_s = r->eq / s_eq;
    r->ineq_s = r->ineq / s_ineq;
    r->comp_s = r->comp / dmax(DOPUS_R(1.0), nz);
    r->nz = nz;
    r->aty = naty;
    r->ny = dmax(nz, dmax(nlam, NE > 0 ? dopus_lai_norm_inf(NE, ws->nu) : DOPUS_R(0.0)));
    ws->scale_stat = s_stat;
    ws->scale_eq = s_eq;
    ws->scale_ineq = s_ineq;
}

/* ---------------------------------------------------------------- Riccati factorisation */

#if DOPUS_QP_PHIT
/* out = Phi' v over the transposed copy PhiT (NW x NX, column-major): out (NW), v (NX). */
static void phit_mv(const dopus_real *restrict PhiT, const dopus_real *restrict v, dopus_real *restrict out)
{
    int i, l;
    for (i = 0; i < NW; ++i)
        out[i] = DOPUS_R(0.0);
    for (l = 0; l < NX; ++l) {
        const dopus_real f = v[l];
        for (i = 0; i < NW; ++i)
            out[i] += PhiT[i + l * NW] * f;
    }
}
#endif

/* The stage update of the Riccati recursion from PhiT = Phi' (nw x nx; without the kept copy,
 * DOPUS_QP_PHIT 0, Phi itself): WT = Phi' P (nw x nx, P symmetric stored full), the lower
 * triangle of M = H + WT Phi (the upper one is never read), and with terminal equalities
 * Gam = Phi' G (nw x ne). The inner loops run down a column (vectorised where the target has
 * vectors); the ragged columns of the triangle are unrolled. On x86 (two-wide vectors) whole
 * columns of M took the same time (0.99 to 1.02, bench/README.md); on a scalar FPU
 * (Cortex-M7) the triangle saves 45 % of the products. */
QP_NOINLINE static void qp_stage_wt(const dopus_real *restrict P, const dopus_real *restrict G,
                                    const dopus_real *restrict PhiT, dopus_real *restrict WT,
                                    dopus_real *restrict Gam)
{
#if DOPUS_QP_PHIT
    int j;
    for (j = 0; j < NX; ++j)
        phit_mv(PhiT, P + j * NX, WT + j * NW);
    for (j = 0; j < NE; ++j)
        phit_mv(PhiT, G + j * NX, Gam + j * NW);
#else
    int i, j, l;
    for (i = 0; i < NW; ++i) {
        dopus_real pc[NX];
        for (l = 0; l < NX; ++l)
            pc[l] = PhiT[l + i * NX];
        for (j = 0; j < NX; ++j) {
            dopus_real s = DOPUS_R(0.0);
            for (l = 0; l < NX; ++l)
                s += pc[l] * P[l + j * NX];
            WT[i + j * NW] = s;
        }
        for (j = 0; j < NE; ++j) {
            dopus_real s = DOPUS_R(0.0);
            for (l = 0; l < NX; ++l)
                s += pc[l] * G[l + j * NX];
            Gam[i + j * NW] = s;
        }
    }
#endif
}

/* The triangle of M in two-wide vectors (DOPUS_QP_V2). By default it is used with the kept
 * Phi_k' where dopus_linalg.h has two-wide vectors (DOPUS_LAI_VEC) when nw > 17: GCC 12
 * (-O3, SSE2) unrolls the scalar loops below completely up to nw = 17 and vectorises them as
 * well as this kernel (the robot arm's 8, the quadrotor's 17), but above that it leaves a
 * loop per column with a variable start and the column in memory, and the kernel takes 0.76
 * to 0.77 of the factorisation's instructions (nw = 18, 20, 24; bench/issue23/measurements.md
 * section 27). -DDOPUS_QP_V2=1 uses the kernel at every size (with DOPUS_LAI_VEC), 0 never.
 * The kernel is dopus_linalg.h's dopus_lai_v2_lower_atb (its pairs of columns also the lm
 * test's): each entry of M is one sum in the same order as in the scalar loops (two entries of
 * one column per vector, never a sum split across lanes), so both give the same bits; columns
 * j, j + 1 (j even) together, a pair whose count of rows is odd starting a row early, the
 * accumulators in registers, the entries above the diagonal (H's upper triangle is not read)
 * never read. */
#if !defined(DOPUS_QP_V2) || DOPUS_QP_V2
#if DOPUS_QP_PHIT && DOPUS_LAI_VEC && (defined(DOPUS_QP_V2) || NW > 17)
#define QP_V2 1
#endif
#endif
#ifndef QP_V2
#define QP_V2 0
#endif

#if QP_V2
QP_NOINLINE static void qp_stage_update(const dopus_real *restrict Phi, const dopus_real *restrict P,
                                        const dopus_real *restrict G, const dopus_real *restrict H,
                                        const dopus_real *restrict PhiT, dopus_real *restrict WT,
                                        dopus_real *restrict M, dopus_real *restrict Gam)
{
    qp_stage_wt(P, G, PhiT, WT, Gam);
    dopus_lai_v2_lower_atb(NW, NX, WT, Phi, H, M);
}
#else
QP_NOINLINE static void qp_stage_update(const dopus_real *restrict Phi, const dopus_real *restrict P,
                                        const dopus_real *restrict G, const dopus_real *restrict H,
                                        const dopus_real *restrict PhiT, dopus_real *restrict WT,
                                        dopus_real *restrict M, dopus_real *restrict Gam)
{
    int i, j, l;
    qp_stage_wt(P, G, PhiT, WT, Gam);
    UNROLL
    for (j = 0; j < NW; ++j) {
        dopus_real col[NW];
        UNROLL
        for (i = j; i < NW; ++i)
            col[i] = H[i + j * NW];
        for (l = 0; l < NX; ++l) {
            const dopus_real f = Phi[l + j * NX];
            UNROLL
            for (i = j; i < NW; ++i)
                col[i] += WT[i + l * NW] * f;
        }
        UNROLL
        for (i = j; i < NW; ++i)
            M[i + j * NW] = col[i];
    }
}
#endif

/* ---------------------------------------------------------------- round-off of the pivots */

/* A pivot of M_uu at or below zero is judged against an estimate of its round-off (see
 * riccati_factor). The estimate is formed only then, from what the recursion keeps: it
 * needs the diagonal of stage k's terms before Phi' P Phi, the column sums of |Phi_k|, the
 * largest entries of P_{k+1} and P_{k+2} and the columns of stage k+1's Lu^{-1} M_ux (K),
 * all unchanged since they were formed. The estimates are the same as
 * when they were formed for every stage. */

/* dg = the diagonal of H_k + D'QD + delta I (the terms of M before Phi' P Phi) */
static void stage_diag(const dopus_qp_workspace *ws, const dopus_qp_in *in, int k, dopus_real *dg)
{
    dopus_real q[NSI];
    int i, j, b;
    for (i = 0; i < NSI; ++i)
        q[i] = DOPUS_R(0.0);
    for (b = ws->bstart[k]; b < ws->bstart[k + 1]; ++b)
        q[ws->bidx[b] - k * NSI] = row_q(ws, in, b);
    for (i = 0; i < NW; ++i)
        dg[i] = in->H[k][i + i * NW] + q[i] + ws->delta + in->hess_shift;
    for (j = 0; j < NG; ++j)
        for (i = 0; i < NW; ++i)
            dg[i] += q[NW + j] * in->C[k][j + i * NG] * in->C[k][j + i * NG];
}

/* cs2 = the squares of the column sums of |Phi_k| */
static void stage_cs2(const dopus_real *Phi, dopus_real *cs2)
{
    int i, l;
    for (i = 0; i < NW; ++i) {
        dopus_real colsum = dopus_fabs(Phi[i * NX]);
        for (l = 1; l < NX; ++l)
            colsum += dopus_fabs(Phi[l + i * NX]);
        cs2[i] = colsum * colsum;
    }
}

/* The largest |entry| of P_k (k < N, packed; pmagN for P_N) */
static dopus_real p_absmax(const dopus_qp_workspace *ws, int k, dopus_real pmagN)
{
    dopus_real m = DOPUS_R(0.0);
    int l;
    if (k == N)
        return pmagN;
    for (l = 0; l < DOPUS_QP_NXP; ++l)
        m = dmax(m, dopus_fabs(ws->P[k][l]));
    return m;
}

/* noise[j], the round-off estimate of pivot j of stage k's M_uu: the rounding of its terms
 * plus the error of P_{k+1} propagated through B' P B. P_{k+1} = M_xx - M_xu M_uu^{-1} M_ux
 * of stage k+1 may cancel large barrier terms (an active state bound enters M_xx, is
 * absorbed by the controls of the stage before and cancels), leaving an absolute error of
 * about eps times the magnitude pmag of the cancelled terms: the largest of M_xx's diagonal
 * terms with their propagated error and of the squared columns of Lu^{-1} M_ux (for k = N - 1,
 * the largest entry of P_N). */
QP_COLD static void stage_noise(const dopus_qp_workspace *ws, const dopus_qp_in *in, int k, dopus_real pmagN,
                                dopus_real *noise)
{
    dopus_real dg[NW], cs2[NW];
    const dopus_real pmax = p_absmax(ws, k + 1, pmagN);
    dopus_real pmag = pmax;
    int j;
    if (k + 1 < N) {
        const dopus_real pmax1 = p_absmax(ws, k + 2, pmagN);
        stage_diag(ws, in, k + 1, dg);
        stage_cs2(in->Phi[k + 1], cs2);
        pmag = DOPUS_R(0.0);
        for (j = 0; j < NX; ++j)
            pmag = dmax(pmag, dopus_fabs(dg[j]) + cs2[j] * pmax1);
        for (j = 0; j < NX; ++j)
            pmag = dmax(pmag, dopus_lai_dot(NU, ws->K[k + 1] + j * NU1, ws->K[k + 1] + j * NU1));
    }
    stage_diag(ws, in, k, dg);
    stage_cs2(in->Phi[k], cs2);
    for (j = 0; j < NU; ++j)
        noise[j] = RICCATI_EPS * (dopus_fabs(dg[NX + j]) + cs2[NX + j] * dmax(pmax, pmag));
}

/* The scale of delta and rho: the largest absolute entry of the Hessian data (hmax, from
 * check_input) plus the shift. */
static dopus_real hessian_scale(const dopus_qp_in *in, dopus_real hmax)
{
    const dopus_real s = hmax + in->hess_shift;
    /* a zero Hessian (an LP) still needs a scale for the inertia correction */
    return s > DOPUS_R(0.0) ? s : DOPUS_R(1.0);
}

/* The Cholesky factorisation of M_uu (in Lu, lower triangle) for dopus_qp_prefactor: 1 when
 * every pivot exceeds the floor max(pre_tol, pre_roundoff max_j |M_uu,jj|), each column formed
 * as dopus_lai_potrf_l forms it (the same factor when all pass); 0 at the first that does not
 * (a NaN included). A pivot of +inf passes the test but leaves nothing to keep (pre_roundoff
 * then negative: no factor kept). */
static int pivots_above_floor(dopus_qp_workspace *ws, dopus_real *Lu)
{
    dopus_real floor_ = ws->pre_tol, v;
    int j;
    for (j = 0; j < NU; ++j) {
        v = dopus_fabs(ws->pre_roundoff) * dopus_fabs(Lu[j + j * NU1]);
        floor_ = v > floor_ ? v : floor_;
    }
    for (j = 0; j < NU; ++j) {
        const dopus_real d = dopus_lai_potrf_pivot(Lu, NU1, j);
        if (!(d > floor_))
            return 0;
        if (!isfinite(d))
            ws->pre_roundoff = -dopus_fabs(ws->pre_roundoff);
        dopus_lai_potrf_column(NU, Lu, NU1, j, d);
    }
    return 1;
}

/* The parts of the sweeps, inlined where they are called (a call per stage of the backward
 * sweep cost 7 % of the time of a robot-arm QP) */
#if defined(__GNUC__)
#define QP_SWEEP_INLINE static inline __attribute__((always_inline))
#else
#define QP_SWEEP_INLINE static inline
#endif

/* Barrier right-hand side of one side, rc = t z (predictor) or, for the corrector,
 * t z + eta dt_aff dz_aff - target with the predictor's steps still in dt, dz (so rc
 * needs no storage of its own). */
typedef struct {
    int corrector;
    dopus_real eta, target;
} qp_centring;

/* the predictor's backward sweep run with the factorisation (the host path) */
#ifndef QP_FUSE
#define QP_FUSE DOPUS_QP_PHIT
#endif
#if QP_FUSE
static void newton_rhs(dopus_qp_workspace *ws, const dopus_qp_in *in, const qp_centring *cc, dopus_real *os,
                       dopus_real *od, dopus_real *oe);
#endif

/* The backward sweep of riccati_solve (below) in parts: its terminal step and stage k's step,
 * which needs only the factors of stages k and k + 1. With the kept Phi_k' the factorisation
 * runs the predictor's sweep stage by stage beside its own recursion (riccati_factor with ws->fuse):
 * two chains of dependent operations that the core overlaps, each entry the same operations
 * in the same order as in riccati_solve. tv (NX) and m (NW): the sweep vectors, local arrays
 * on the host path (the compiler then knows that they alias none of the arrays solved in
 * place: on x86 13 % fewer instructions in the solve), ws->work otherwise. */
QP_SWEEP_INLINE void riccati_back_terminal(dopus_qp_workspace *ws, const dopus_qp_in *in, dopus_real *sp,
                                           dopus_real *sl, const dopus_real *sn, dopus_real *tv)
{
    /* p_N = -(rhs_stat_N + rho Req' rhs_eqN), e_N = -rhs_eqN */
    dopus_real *xN = sp + N * NW, *pN = sl + N * NX;
    int i;
    for (i = 0; i < NX; ++i)
        tv[i] = -xN[i];
    if (NE > 0) {
        if (ws->rho_aug > DOPUS_R(0.0))
            dopus_lai_gemv_t(NE, NX, -ws->rho_aug, in->Req, NE1, sn, DOPUS_R(1.0), tv);
        for (i = 0; i < NE; ++i)
            ws->e[i] = -sn[i];
    }
    for (i = 0; i < NX; ++i) {
        xN[i] = pN[i];
        pN[i] = tv[i];
    }
}

/* Stage k's step up to m = -rhs_stat_k + Phi' (P_{k+1} c + p_{k+1}), with e += G_{k+1}' c */
QP_SWEEP_INLINE void riccati_back_m(dopus_qp_workspace *ws, const dopus_qp_in *in, int k,
                                    const dopus_real *sp, const dopus_real *sl, dopus_real *tv, dopus_real *m)
{
    const dopus_real *c = sp + (k + 1) * NW;  /* rhs_dyn_{k+1} */
    const dopus_real *pn = sl + (k + 1) * NX; /* p_{k+1} */
    const dopus_real *xk = sp + k * NW;
    int i;
    (void)in; /* (QP_PHIT reads the kept copy on the host path) */
    for (i = 0; i < NX; ++i)
        tv[i] = pn[i];
    spmv_packed(ws->P[k + 1], DOPUS_R(1.0), c, tv);
    for (i = 0; i < NW; ++i)
        m[i] = -xk[i];
    phit_gemv(QP_PHIT(ws, in, k), DOPUS_R(1.0), tv, m);
    if (NE > 0) {
        dopus_lai_gemv_t(NX, NE, DOPUS_R(1.0), ws->G[k + 1], NX, c, DOPUS_R(1.0), ws->e);
    }
}

#if DOPUS_QP_PHIT
QP_SWEEP_INLINE void riccati_back_stage(dopus_qp_workspace *ws, const dopus_qp_in *in, int k, dopus_real *sp,
                                        dopus_real *sl)
{
    dopus_real tv[NX], m[NW], y[NU1];
    dopus_real *e = ws->e;
    dopus_real *xk = sp + k * NW, *yk = xk + NX, *pk = sl + k * NX;
    int i;
    riccati_back_m(ws, in, k, sp, sl, tv, m);
    /* y = Lu^{-1} m_u; p_k = m_x - M_xu M_uu^{-1} m_u = m_x - LK' y; e -= LKn' y; y is kept
     * where u_k is formed (the forward sweep applies Lu'^{-1}); p_k and y are formed in
     * local arrays and stored once */
    for (i = 0; i < NU; ++i)
        y[i] = m[NX + i];
    lu_solve_n(ws->Lu[k], y);
    for (i = 0; i < NX; ++i)
        xk[i] = pk[i];
    dopus_lai_gemv_t(NU, NX, -DOPUS_R(1.0), ws->K[k], NU1, y, DOPUS_R(1.0), m);
    for (i = 0; i < NX; ++i)
        pk[i] = m[i];
    if (NE > 0)
        dopus_lai_gemv_t(NU, NE, -DOPUS_R(1.0), ws->KN[k], NU1, y, DOPUS_R(1.0), e);
    for (i = 0; i < NU; ++i)
        yk[i] = y[i];
}
#endif

/* Factor the Newton system for the current barrier weights (row_q), delta and rho.
 * Returns 0, or 1 when a stage pivot block M_uu is not positive definite (wrong inertia),
 * or 2 when the terminal-multiplier block S is singular. Per stage it keeps P_k (packed),
 * the packed factor Lu of M_uu = Lu Lu' and Lu^{-1} M_ux in K (with terminal equalities
 * G_k and Lu^{-1} Gam_u in KN); the solve applies Lu'^{-1} (the gain M_uu^{-1} M_ux is never
 * formed). */
static int riccati_factor(dopus_qp_workspace *ws, const dopus_qp_in *in)
{
    int k, i, j;
    dopus_real *WT = ws->work;            /* NW x NX: Phi_k' P_{k+1} */
    dopus_real *Gam = ws->work + NX * NW; /* NW x NE: Phi_k' G_{k+1} */
    dopus_real *Pf = Gam + NW * NE1;      /* NX x NX: P_{k+1} unpacked */
    const dopus_real delta = ws->delta;
    dopus_real pmagN;
    int b;
#if QP_FUSE
    /* the predictor's right-hand side formed at every try (a failed try leaves its sweep
     * half done) */
    const int fused = ws->fuse;
    ws->swept = 0;
    if (fused) {
        const qp_centring pred = {0, DOPUS_R(0.0), DOPUS_R(0.0)};
        newton_rhs(ws, in, &pred, ws->d_prim, ws->d_lam, ws->d_nu);
    }
#endif
    ++ws->n_fact;
    ws->pre_status = -1; /* the factor below replaces one dopus_qp_prefactor kept */

    /* terminal: P_N = HN + D'QD + delta I + rho Req'Req, G_N = Req' */
    {
        dopus_real *P = Pf;
        dopus_real dq[NX];
        int l = 0;
        dopus_lai_copy_mat(NX, NX, in->HN, NX, P, NX);
        dopus_lai_symmetrize_l(NX, P, NX);
        for (i = 0; i < NX; ++i)
            dq[i] = DOPUS_R(0.0);
        for (b = ws->bstart[N]; b < ws->bstart[N + 1]; ++b)
            if (NR == 0 || ws->bidx[b] - TOFF < NX)
                dq[ws->bidx[b] - TOFF] = row_q(ws, in, b);
        for (i = 0; i < NX; ++i)
            P[i + i * NX] += dq[i] + delta + in->hess_shift;
        for (b = ws->bstart[N]; b < ws->bstart[N + 1]; ++b) {
            const int r = ws->bidx[b] - TOFF;
            const dopus_real qr = row_q(ws, in, b);
            if (NR > 0 && r >= NX && qr != DOPUS_R(0.0))
                for (j = 0; j < NX; ++j)
                    for (i = 0; i < NX; ++i)
                        P[i + j * NX] += qr * in->R[(r - NX) + i * NR] * in->R[(r - NX) + j * NR];
        }
        if (NE > 0) {
            if (ws->rho_aug > DOPUS_R(0.0))
                dopus_lai_gemm_tn(NX, NX, NE, ws->rho_aug, in->Req, NE1, in->Req, NE1, DOPUS_R(1.0), P, NX);
            for (j = 0; j < NE; ++j)
                for (i = 0; i < NX; ++i)
                    ws->G[N][i + j * NX] = in->Req[j + i * NE1];
        }
        for (j = 0; j < NX; ++j)
            for (i = j; i < NX; ++i)
                ws->P[N][l++] = P[i + j * NX];
    }
    for (i = 0; i < NE1 * NE1; ++i)
        ws->S[i] = DOPUS_R(0.0);
    /* the largest |entry| of P_N, for the round-off estimate of a pivot (stage_noise) */
    pmagN = dopus_lai_max_abs_mat(NX, NX, Pf, NX);
#if QP_FUSE
    if (fused) {
        dopus_real tv[NX];
        riccati_back_terminal(ws, in, ws->d_prim, ws->d_lam, ws->d_nu, tv);
    }
#endif

    for (k = N - 1; k >= 0; --k) {
        dopus_real *M = ws->M;
        const dopus_real *Phi = in->Phi[k];
#if DOPUS_QP_PHIT
        const dopus_real *PhiT = ws->PhiT[k];
#else
        const dopus_real *PhiT = Phi; /* qp_stage_update reads Phi_k itself */
#endif
        dopus_real q[NSI];
        dopus_real Lu[NU1 * NU1];
        dopus_real *K = ws->K[k];
        dopus_real *KN = ws->KN[k];
        dopus_real *P = ws->P[k];
        int l = 0;

        /* barrier weights of the stage's rows (0 on the unbounded rows) */
        for (i = 0; i < NSI; ++i)
            q[i] = DOPUS_R(0.0);
        for (b = ws->bstart[k]; b < ws->bstart[k + 1]; ++b)
            q[ws->bidx[b] - k * NSI] = row_q(ws, in, b);

        /* M = H_k + Phi' P_{k+1} Phi + D'QD + delta I (the upper triangle of M is never
         * read), Gam = Phi' G_{k+1} */
        qp_stage_update(Phi, Pf, ws->G[k + 1], in->H[k], PhiT, WT, M, Gam);
        /* (hess_shift read here: with a local copy read before the stage update, GCC 12 at -O3
         * no longer vectorised the triangle of M, 1.5 times its instructions) */
        for (i = 0; i < NW; ++i)
            M[i + i * NW] += q[i] + delta + in->hess_shift;
        for (j = 0; j < NG; ++j) {
            const dopus_real qg = q[NW + j];
            const dopus_real *C = in->C[k];
            int a, c;
            if (qg != DOPUS_R(0.0))
                for (c = 0; c < NW; ++c)
                    for (a = c; a < NW; ++a)
                        M[a + c * NW] += qg * C[j + a * NG] * C[j + c * NG];
        }

        /* M_uu = Lu Lu' (its lower triangle). A pivot at or below zero is tried again
         * against its round-off estimate (stage_noise): within the noise it is a numerical
         * zero and floored, below -noise it is wrong inertia. Positive pivots are the same
         * either way. */
        for (j = 0; j < NU; ++j)
            for (i = j; i < NU; ++i)
                Lu[i + j * NU1] = M[NX + i + (NX + j) * NW];
        if (ws->pre_tol > DOPUS_R(0.0)) {
            /* dopus_qp_prefactor: the pivots above its floor, the factor that of potrf_l */
            if (!pivots_above_floor(ws, Lu))
                return 1;
        } else if (dopus_lai_potrf_l(NU, Lu, NU1) != 0) {
            stage_noise(ws, in, k, pmagN, ws->noise);
            for (j = 0; j < NU; ++j)
                for (i = j; i < NU; ++i)
                    Lu[i + j * NU1] = M[NX + i + (NX + j) * NW];
            if (dopus_lai_potrf_l_noise(NU, Lu, NU1, ws->noise, &ws->pivot_floors) != 0) {
                QP_TRACE("   pivot fail stage %d delta %.2e rho %.2e\n", k, delta, ws->rho_aug);
                return 1;
            }
        }
        pack_lu(Lu, ws->Lu[k]);
        /* LK = Lu^{-1} M_ux (in K) */
        for (j = 0; j < NX; ++j)
            lu_solve_n_from(ws->Lu[k], M + NX + j * NW, K + j * NU1);
        /* P_k = M_xx - LK' LK */
        UNROLL
        for (j = 0; j < NX; ++j)
            UNROLL
        for (i = j; i < NX; ++i) {
            dopus_real sum = M[i + j * NW];
            int c;
            for (c = 0; c < NU; ++c)
                sum -= K[c + i * NU1] * K[c + j * NU1];
            P[l++] = sum;
            Pf[i + j * NX] = sum;
            Pf[j + i * NX] = sum;
        }
        if (NE > 0) {
            /* LKn = Lu^{-1} Gam_u (in KN); G_k = Gam_x - LK' LKn; S += LKn' LKn
             * (S = -(nu-nu block of V_0)) */
            for (j = 0; j < NE; ++j)
                lu_solve_n_from(ws->Lu[k], Gam + NX + j * NW, KN + j * NU1);
            dopus_lai_copy_mat(NX, NE, Gam, NW, ws->G[k], NX);
            dopus_lai_gemm_tn(NX, NE, NU, -DOPUS_R(1.0), K, NU1, KN, NU1, DOPUS_R(1.0), ws->G[k], NX);
            dopus_lai_gemm_tn(NE, NE, NU, DOPUS_R(1.0), KN, NU1, KN, NU1, DOPUS_R(1.0), ws->S, NE1);
        }
#if QP_FUSE
        if (fused)
            riccati_back_stage(ws, in, k, ws->d_prim, ws->d_lam);
#endif
    }
    if (NE > 0) {
        /* S is positive definite iff Req has full row rank on the states reachable from
         * x_0 (LICQ). A rank-deficient S gets a tiny shift; refinement removes its effect
         * when the equality rows are consistent. */
        dopus_real smax = DOPUS_R(0.0);
        for (i = 0; i < NE; ++i)
            smax = dmax(smax, ws->S[i + i * NE1]);
        dopus_lai_copy_mat(NE, NE, ws->S, NE1, ws->work, NE1);
        if (dopus_lai_potrf_l(NE, ws->S, NE1) != 0) {
            dopus_lai_copy_mat(NE, NE, ws->work, NE1, ws->S, NE1);
            for (i = 0; i < NE; ++i)
                ws->S[i + i * NE1] += DOPUS_PREC(1e-13, 1e-6) * dmax(smax, DOPUS_REAL_TINY);
            if (dopus_lai_potrf_l(NE, ws->S, NE1) != 0)
                return 2;
        }
    }
#if QP_FUSE
    ws->swept = fused;
#endif
    return 0;
}

QP_SWEEP_INLINE void riccati_forward(dopus_qp_workspace *ws, const dopus_qp_in *in, dopus_real *sp,
                                     dopus_real *sl, dopus_real *sn);

/* Solve the factored Newton system in place: (sp, sl, sn) holds the right-hand side
 * (rhs_stat, rhs_dyn, rhs_eqN) on entry and the solution on exit. Backward sweep of the
 * value-function vectors, nu at stage 0, forward sweep of the primal and the costates
 * lam_k = -dV_k/dx. The sweep vectors live in the arrays they become: once stage k's
 * rhs_stat has been read, its x part takes rhs_dyn_k (x_k is formed there), its u part
 * the vector y_k = Lu^{-1} m_u (u_k is formed there), and sl_k the vector p_k (lam_k is formed there). */
static void riccati_solve(dopus_qp_workspace *ws, const dopus_qp_in *in, dopus_real *sp, dopus_real *sl,
                          dopus_real *sn)
{
    int k;
#if DOPUS_QP_PHIT
    {
        dopus_real tv[NX];
        riccati_back_terminal(ws, in, sp, sl, sn, tv);
    }
    for (k = N - 1; k >= 0; --k)
        riccati_back_stage(ws, in, k, sp, sl);
#else
    int i;
    dopus_real *tv = ws->work;     /* NX */
    dopus_real *m = ws->work + NX; /* NW */
    dopus_real *e = ws->e;

    riccati_back_terminal(ws, in, sp, sl, sn, tv);
    for (k = N - 1; k >= 0; --k) {
        dopus_real *xk = sp + k * NW, *yk = xk + NX, *pk = sl + k * NX;
        riccati_back_m(ws, in, k, sp, sl, tv, m);
        /* y = Lu^{-1} m_u; p_k = m_x - M_xu M_uu^{-1} m_u = m_x - LK' y; e -= LKn' y; y is kept
         * where u_k is formed (the forward sweep applies Lu'^{-1}) */
        lu_solve_n(ws->Lu[k], m + NX);
        for (i = 0; i < NX; ++i) {
            xk[i] = pk[i];
            pk[i] = m[i];
        }
        dopus_lai_gemv_t(NU, NX, -DOPUS_R(1.0), ws->K[k], NU1, m + NX, DOPUS_R(1.0), pk);
        if (NE > 0)
            dopus_lai_gemv_t(NU, NE, -DOPUS_R(1.0), ws->KN[k], NU1, m + NX, DOPUS_R(1.0), e);
        for (i = 0; i < NU; ++i)
            yk[i] = m[NX + i];
    }
#endif
    riccati_forward(ws, in, sp, sl, sn);
}

/* riccati_solve's part after the backward sweep: nu, the forward sweep and the costates. */
QP_SWEEP_INLINE void riccati_forward(dopus_qp_workspace *ws, const dopus_qp_in *in, dopus_real *sp,
                                     dopus_real *sl, dopus_real *sn)
{
    int k, i;
    const dopus_real *e = ws->e;
    /* stage 0: x_0 = rhs_dyn_0 (in place); dV_0/dnu = G_0' x_0 + e_0 - S nu = 0 */
    if (NE > 0) {
        for (i = 0; i < NE; ++i)
            sn[i] = e[i];
        dopus_lai_gemv_t(NX, NE, DOPUS_R(1.0), ws->G[0], NX, sp, DOPUS_R(1.0), sn);
        dopus_lai_trsv_ln(NE, ws->S, NE1, sn);
        dopus_lai_trsv_lt(NE, ws->S, NE1, sn);
    }
#if DOPUS_QP_PHIT
    /* the forward sweep with w_k = (x_k, u_k) and x_{k+1} in local arrays, stored once (the
     * compiler then knows that they alias none of the arrays it reads: the products with
     * LK and Phi_k run as vectors, with the same sums in the same order) */
    {
        dopus_real wl[NW], xn[NX];
        for (i = 0; i < NX; ++i)
            wl[i] = sp[i];
        for (k = 0; k < N; ++k) {
            dopus_real *u = sp + k * NW + NX;
            dopus_real *lamk = sl + k * NX;
            dopus_real *xs = sp + (k + 1) * NW;
            /* u_k = -M_uu^{-1} (M_ux x_k + m_u + Gam_u nu) = -Lu'^{-1} (LK x_k + y_k + LKn nu) */
            dopus_real ul[NU1];
            for (i = 0; i < NU; ++i)
                ul[i] = -u[i];
            dopus_lai_gemv_n(NU, NX, -DOPUS_R(1.0), ws->K[k], NU1, wl, DOPUS_R(1.0), ul);
            if (NE > 0)
                dopus_lai_gemv_n(NU, NE, -DOPUS_R(1.0), ws->KN[k], NU1, sn, DOPUS_R(1.0), ul);
            lu_solve_t(ws->Lu[k], ul);
            for (i = 0; i < NU; ++i) {
                u[i] = ul[i];
                wl[NX + i] = ul[i];
            }
            /* lam_k = -(P_k x_k + p_k + G_k nu) */
            for (i = 0; i < NX; ++i)
                lamk[i] = -lamk[i];
            spmv_packed(ws->P[k], -DOPUS_R(1.0), wl, lamk);
            if (NE > 0)
                dopus_lai_gemv_n(NX, NE, -DOPUS_R(1.0), ws->G[k], NX, sn, DOPUS_R(1.0), lamk);
            /* x_{k+1} = Phi_k w_k + c_k */
            for (i = 0; i < NX; ++i)
                xn[i] = xs[i];
            qp_gemv_n(NX, NW, DOPUS_R(1.0), in->Phi[k], NX, wl, DOPUS_R(1.0), xn);
            for (i = 0; i < NX; ++i) {
                xs[i] = xn[i];
                wl[i] = xn[i];
            }
        }
    }
#else
    for (k = 0; k < N; ++k) {
        dopus_real *w = sp + k * NW;
        dopus_real *u = w + NX;
        dopus_real *lamk = sl + k * NX;
        /* u_k = -M_uu^{-1} (M_ux x_k + m_u + Gam_u nu) = -Lu'^{-1} (LK x_k + y_k + LKn nu) */
        for (i = 0; i < NU; ++i)
            u[i] = -u[i];
        dopus_lai_gemv_n(NU, NX, -DOPUS_R(1.0), ws->K[k], NU1, w, DOPUS_R(1.0), u);
        if (NE > 0)
            dopus_lai_gemv_n(NU, NE, -DOPUS_R(1.0), ws->KN[k], NU1, sn, DOPUS_R(1.0), u);
        lu_solve_t(ws->Lu[k], u);
        /* lam_k = -(P_k x_k + p_k + G_k nu) */
        for (i = 0; i < NX; ++i)
            lamk[i] = -lamk[i];
        spmv_packed(ws->P[k], -DOPUS_R(1.0), w, lamk);
        if (NE > 0)
            dopus_lai_gemv_n(NX, NE, -DOPUS_R(1.0), ws->G[k], NX, sn, DOPUS_R(1.0), lamk);
        /* x_{k+1} = Phi_k w_k + c_k */
        dopus_lai_gemv_n(NX, NW, DOPUS_R(1.0), in->Phi[k], NX, w, DOPUS_R(1.0), sp + (k + 1) * NW);
    }
#endif
    {
        const dopus_real *xN = sp + N * NW;
        dopus_real *lamN = sl + N * NX;
        /* lam_N = -(dV_N/dx); the rho terms cancel because Req x_N = rhs_eqN */
        for (i = 0; i < NX; ++i)
            lamN[i] = -lamN[i];
        spmv_packed(ws->P[N], -DOPUS_R(1.0), xN, lamN);
        if (NE > 0)
            dopus_lai_gemv_n(NX, NE, -DOPUS_R(1.0), ws->G[N], NX, sn, DOPUS_R(1.0), lamN);
    }
}

/* (os, od, oe) = rhs - K (sp, sl, sn): residual of the (delta-shifted, unaugmented) Newton
 * system, for iterative refinement. The output may be the right-hand side's own arrays
 * (every entry of the right-hand side is read before the same entry is written). */
static void newton_residual(dopus_qp_workspace *ws, const dopus_qp_in *in, const dopus_real *sp,
                            const dopus_real *sl, const dopus_real *sn, const dopus_real *rhs_stat,
                            const dopus_real *rhs_dyn, const dopus_real *rhs_eqN, dopus_real *os,
                            dopus_real *od, dopus_real *oe)
{
    int k, i, b, j;
    /* os = rhs_stat - (H + delta I) sp - D'Q D sp - [sl_k;0] + Phi' sl_{k+1} - Req' sn */
    for (i = 0; i < NP; ++i)
        os[i] = rhs_stat[i] - (ws->delta + in->hess_shift) * sp[i];
    for (k = 0; k <= N; ++k)
        FOR_STAGE_ROWS(ws, k, b, j)
    row_axpy(in, k, j, row_dot(in, k, j, sp + k * NW) * -row_q(ws, in, b), os + k * NW);
    for (k = 0; k < N; ++k) {
        dopus_real *o = os + k * NW;
        dopus_lai_symv_l(NW, -DOPUS_R(1.0), in->H[k], NW, sp + k * NW, DOPUS_R(1.0), o);
        for (i = 0; i < NX; ++i)
            o[i] -= sl[k * NX + i];
        phit_gemv(QP_PHIT(ws, in, k), DOPUS_R(1.0), sl + (k + 1) * NX, o);
    }
    {
        dopus_real *o = os + N * NW;
        dopus_lai_symv_l(NX, -DOPUS_R(1.0), in->HN, NX, sp + N * NW, DOPUS_R(1.0), o);
        for (i = 0; i < NX; ++i)
            o[i] -= sl[N * NX + i];
        if (NE > 0)
            dopus_lai_gemv_t(NE, NX, -DOPUS_R(1.0), in->Req, NE1, sn, DOPUS_R(1.0), o);
    }
    for (i = 0; i < NX; ++i)
        od[i] = rhs_dyn[i] - sp[i];
    for (k = 0; k < N; ++k) {
        dopus_real *o = od + (k + 1) * NX;
        for (i = 0; i < NX; ++i)
            o[i] = rhs_dyn[(k + 1) * NX + i] - sp[(k + 1) * NW + i];
        dopus_lai_gemv_n(NX, NW, DOPUS_R(1.0), in->Phi[k], NX, sp + k * NW, DOPUS_R(1.0), o);
    }
    if (NE > 0) {
        for (i = 0; i < NE; ++i)
            oe[i] = rhs_eqN[i];
        dopus_lai_gemv_n(NE, NX, -DOPUS_R(1.0), in->Req, NE1, sp + N * NW, DOPUS_R(1.0), oe);
    }
}

/* rc of the lower (rc_lo) and the upper side (rc_up) of bounded row b; the predictor's
 * steps dt, dz are read only for the corrector (before the first corrector they are unset) */
static dopus_real rc_lo(const dopus_qp_workspace *ws, int b, const qp_centring *cc)
{
    dopus_real rc = ws->t_lo[b] * ws->z_lo[b];
    if (cc->corrector)
        rc += cc->eta * dt_lo(ws, b) * ws->dz_lo[b] - cc->target;
    return rc;
}

static dopus_real rc_up(const dopus_qp_workspace *ws, int b, const qp_centring *cc)
{
    dopus_real rc = ws->t_up[b] * ws->z_up[b];
    if (cc->corrector)
        rc += cc->eta * dt_up(ws, b) * ws->dz_up[b] - cc->target;
    return rc;
}

#if !(DOPUS_QP_V4 && !SOFT) /* else qp_v4_side_sums and qp_v4_dz */
/* rcs of the pair s y of a soft side, as rc_lo and rc_up for t z but without Mehrotra's
 * second-order term: with it, a two-sided soft row whose sides are both nearly active (a
 * soft equality row met at the solution) made the corrector cycle between a long and a
 * blocked step (a closed-loop QP of tests/test_soft.py at its iteration limit; without it
 * 17 iterations). */
static dopus_real rcs_lo(const dopus_qp_workspace *ws, int b, const qp_centring *cc)
{
    dopus_real rc = ws->s_lo[b] * ws->y_lo[b];
    if (cc->corrector)
        rc -= cc->target;
    return rc;
}

static dopus_real rcs_up(const dopus_qp_workspace *ws, int b, const qp_centring *cc)
{
    dopus_real rc = ws->s_up[b] * ws->y_up[b];
    if (cc->corrector)
        rc -= cc->target;
    return rc;
}

/* The right-hand side term of the lower (side_rhs_lo) and the upper side (side_rhs_up) of
 * bounded row b in the condensed Newton system: (rc + z r) / t for a hard side, the same with
 * the slack eliminated for a soft one (soft_f). */
static dopus_real side_rhs_lo(const dopus_qp_workspace *ws, const dopus_qp_in *in, int b,
                              const qp_centring *cc)
{
    const dopus_real a = (rc_lo(ws, b, cc) + ws->z_lo[b] * r_lo(ws, b)) / ws->t_lo[b];
    if (SOFT && ws->soft_lo[b]) {
        const dopus_real q = ws->z_lo[b] / ws->t_lo[b], p = soft_p(ws->soft_lo[b], ws->y_lo[b], ws->s_lo[b]);
        const dopus_real Z = soft_l2(in, ws, b, 0);
        const dopus_real rcs = ws->soft_lo[b] == 1 ? rcs_lo(ws, b, cc) / ws->s_lo[b] : DOPUS_R(0.0);
        return ((Z + p) * a - q * (ws->rs_lo[b] + rcs)) / (Z + q + p);
    }
    return a;
}

static dopus_real side_rhs_up(const dopus_qp_workspace *ws, const dopus_qp_in *in, int b,
                              const qp_centring *cc)
{
    const dopus_real a = (rc_up(ws, b, cc) + ws->z_up[b] * r_up(ws, b)) / ws->t_up[b];
    if (SOFT && ws->soft_up[b]) {
        const dopus_real q = ws->z_up[b] / ws->t_up[b], p = soft_p(ws->soft_up[b], ws->y_up[b], ws->s_up[b]);
        const dopus_real Z = soft_l2(in, ws, b, 1);
        const dopus_real rcs = ws->soft_up[b] == 1 ? rcs_up(ws, b, cc) / ws->s_up[b] : DOPUS_R(0.0);
        return ((Z + p) * a - q * (ws->rs_up[b] + rcs)) / (Z + q + p);
    }
    return a;
}
#endif

#if DOPUS_QP_V4 && !SOFT
#define QP_V4_STEPS 1
typedef long long qp_v4_bits __attribute__((vector_size(sizeof(qp_v4))));

/* The candidates -t/dt of four sides (t, dt) where the side exists (has, qp_v4_mask) and dt < 0,
 * 2 where not. */
static inline qp_v4 qp_v4_ratio(qp_v4 t, qp_v4 dt, qp_v4_bits has, qp_v4_bits *odd)
{
    const qp_v4 zero = {DOPUS_R(0.0), DOPUS_R(0.0), DOPUS_R(0.0), DOPUS_R(0.0)};
    const qp_v4 two = {DOPUS_R(2.0), DOPUS_R(2.0), DOPUS_R(2.0), DOPUS_R(2.0)};
    const qp_v4_bits m = has & (dt < zero);
    const qp_v4 r = -t / dt;
    /* a NaN or a zero candidate: the minimum can depend on the order (NaN, +0 against -0) */
    *odd |= m & ((r != r) | (r == zero));
    return (qp_v4)(((qp_v4_bits)r & m) | ((qp_v4_bits)two & ~m));
}

/* All bits set in the lanes of the four rows whose flag f is set (has_lo, has_up). */
static inline qp_v4_bits qp_v4_mask(const unsigned char *f)
{
    const qp_v4_bits v = {f[0], f[1], f[2], f[3]}, zero = {0, 0, 0, 0};
    return v != zero;
}
#else
#define QP_V4_STEPS 0
#endif

#if QP_V4_STEPS
/* Four rows per vector (t, z, dz, vl, uv, dv of rows i..i+3). */
typedef struct {
    qp_v4 tl, tu, zl, zu, dzl, dzu, vl, uv, dv;
} qp_v4_rows;

static inline void qp_v4_load_rows(const dopus_qp_workspace *ws, int i, qp_v4_rows *r)
{
    __builtin_memcpy(&r->tl, ws->t_lo + i, sizeof r->tl);
    __builtin_memcpy(&r->tu, ws->t_up + i, sizeof r->tu);
    __builtin_memcpy(&r->zl, ws->z_lo + i, sizeof r->zl);
    __builtin_memcpy(&r->zu, ws->z_up + i, sizeof r->zu);
    __builtin_memcpy(&r->dzl, ws->dz_lo + i, sizeof r->dzl);
    __builtin_memcpy(&r->dzu, ws->dz_up + i, sizeof r->dzu);
    __builtin_memcpy(&r->vl, ws->vl + i, sizeof r->vl);
    __builtin_memcpy(&r->uv, ws->uv + i, sizeof r->uv);
    __builtin_memcpy(&r->dv, ws->dv + i, sizeof r->dv);
}

static inline qp_v4 qp_v4_select(qp_v4_bits m, qp_v4 a, qp_v4 b)
{
    return (qp_v4)(((qp_v4_bits)a & m) | ((qp_v4_bits)b & ~m));
}

/* rc_lo (*a) and rc_up (*b) of four rows, as the functions compute them. */
static inline void qp_v4_rc_rows(const qp_v4_rows *r, const qp_centring *cc, qp_v4 *a, qp_v4 *b)
{
    *a = r->tl * r->zl;
    *b = r->tu * r->zu;
    if (cc->corrector) {
        const qp_v4 eta = {cc->eta, cc->eta, cc->eta, cc->eta};
        const qp_v4 target = {cc->target, cc->target, cc->target, cc->target};
        *a += eta * (r->dv + (r->vl - r->tl)) * r->dzl - target;
        *b += eta * ((r->uv - r->tu) - r->dv) * r->dzu - target;
    }
}

/* rc_lo and rc_up of every row into rcl, rcu: four rows per vector, the rows left over alone;
 * the entries of a side that does not exist are not read. */
static void qp_v4_rc(const dopus_qp_workspace *ws, const qp_centring *cc, dopus_real *rcl, dopus_real *rcu)
{
    int i = 0;
    for (; i + 4 <= ws->nb; i += 4) {
        qp_v4_rows r;
        qp_v4 a, b;
        qp_v4_load_rows(ws, i, &r);
        qp_v4_rc_rows(&r, cc, &a, &b);
        __builtin_memcpy(rcl + i, &a, sizeof a);
        __builtin_memcpy(rcu + i, &b, sizeof b);
    }
    for (; i < ws->nb; ++i) {
        rcl[i] = rc_lo(ws, i, cc);
        rcu[i] = rc_up(ws, i, cc);
    }
}

/* dz = -(rc + z dt) / t of every side that exists (dt of the new dv), four rows per vector. */
static void qp_v4_dz(dopus_qp_workspace *ws, const dopus_real *rcl, const dopus_real *rcu)
{
    int i = 0;
    for (; i + 4 <= ws->nb; i += 4) {
        qp_v4_rows r;
        qp_v4 a, b;
        const qp_v4_bits mlo = qp_v4_mask(ws->has_lo + i), mup = qp_v4_mask(ws->has_up + i);
        qp_v4_load_rows(ws, i, &r);
        __builtin_memcpy(&a, rcl + i, sizeof a);
        __builtin_memcpy(&b, rcu + i, sizeof b);
        a = qp_v4_select(mlo, -(a + r.zl * (r.dv + (r.vl - r.tl))) / r.tl, r.dzl);
        b = qp_v4_select(mup, -(b + r.zu * ((r.uv - r.tu) - r.dv)) / r.tu, r.dzu);
        __builtin_memcpy(ws->dz_lo + i, &a, sizeof a);
        __builtin_memcpy(ws->dz_up + i, &b, sizeof b);
    }
    for (; i < ws->nb; ++i) {
        if (ws->has_lo[i])
            ws->dz_lo[i] = -(rcl[i] + ws->z_lo[i] * dt_lo(ws, i)) / ws->t_lo[i];
        if (ws->has_up[i])
            ws->dz_up[i] = -(rcu[i] + ws->z_up[i] * dt_up(ws, i)) / ws->t_up[i];
    }
}

/* The row sums of newton_rhs: s = 0 + (rc_lo + z_lo r_lo) / t_lo - (rc_up + z_up r_up) / t_up,
 * each side's term only where the side exists, four rows per vector. */
static void qp_v4_side_sums(const dopus_qp_workspace *ws, const qp_centring *cc, dopus_real *sv)
{
    const qp_v4 zero = {DOPUS_R(0.0), DOPUS_R(0.0), DOPUS_R(0.0), DOPUS_R(0.0)};
    int i = 0;
    for (; i + 4 <= ws->nb; i += 4) {
        qp_v4_rows r;
        qp_v4 a, b, sum;
        const qp_v4_bits mlo = qp_v4_mask(ws->has_lo + i), mup = qp_v4_mask(ws->has_up + i);
        qp_v4_load_rows(ws, i, &r);
        qp_v4_rc_rows(&r, cc, &a, &b);
        a = (a + r.zl * (r.vl - r.tl)) / r.tl;
        b = (b + r.zu * (r.uv - r.tu)) / r.tu;
        sum = zero + qp_v4_select(mlo, a, zero);
        sum = qp_v4_select(mup, sum - b, sum);
        __builtin_memcpy(sv + i, &sum, sizeof sum);
    }
    for (; i < ws->nb; ++i) {
        dopus_real t = DOPUS_R(0.0);
        if (ws->has_lo[i])
            t += (rc_lo(ws, i, cc) + ws->z_lo[i] * r_lo(ws, i)) / ws->t_lo[i];
        if (ws->has_up[i])
            t -= (rc_up(ws, i, cc) + ws->z_up[i] * r_up(ws, i)) / ws->t_up[i];
        sv[i] = t;
    }
}
#endif

/* Newton right-hand side for the barrier right-hand side rc (t z - target per side) into
 * (os, od, oe): -r_stat + D'y, -r_dyn, -r_eqN (os may be r_stat itself, and so on). */
static void newton_rhs(dopus_qp_workspace *ws, const dopus_qp_in *in, const qp_centring *cc, dopus_real *os,
                       dopus_real *od, dopus_real *oe)
{
    int i, k, b, j;
    for (i = 0; i < NP; ++i)
        os[i] = -ws->r_stat[i];
#if QP_V4_STEPS
    {
        dopus_real sv[DOPUS_QP_NB];
        qp_v4_side_sums(ws, cc, sv);
        for (k = 0; k <= N; ++k)
            FOR_STAGE_ROWS(ws, k, b, j)
            {
                row_axpy(in, k, j, -sv[b], os + k * NW);
            }
    }
#else
    for (k = 0; k <= N; ++k)
        FOR_STAGE_ROWS(ws, k, b, j)
        {
            dopus_real s = DOPUS_R(0.0);
            if (ws->has_lo[b])
                s += side_rhs_lo(ws, in, b, cc);
            if (ws->has_up[b])
                s -= side_rhs_up(ws, in, b, cc);
            row_axpy(in, k, j, -s, os + k * NW);
        }
#endif
    for (i = 0; i < (N + 1) * NX; ++i)
        od[i] = -ws->r_dyn[i];
    for (i = 0; i < NE; ++i)
        oe[i] = -ws->r_eqN[i];
}

/* Newton direction for the barrier right-hand side rc (t z - target per side): form the
 * condensed right-hand side in the direction arrays, solve in place, refine, recover slack
 * and multiplier steps. A refinement step forms the right-hand side again in the residual
 * arrays r_stat, r_dyn, r_eqN of the iterate (each direction has read them by then: they
 * are formed anew at the next iterate), computes the residual of the Newton system and
 * the correction there in place; a further step first forms the iterate's residuals again. */
static void newton_direction(dopus_qp_workspace *ws, const dopus_qp_in *in, int refine_steps,
                             const qp_centring *cc)
{
    int it, k, b, j;
#if QP_FUSE
    if (ws->swept) { /* the predictor's right-hand side and backward sweep: done */
        ws->swept = 0;
        riccati_forward(ws, in, ws->d_prim, ws->d_lam, ws->d_nu);
    } else
#endif
    {
        newton_rhs(ws, in, cc, ws->d_prim, ws->d_lam, ws->d_nu);
        riccati_solve(ws, in, ws->d_prim, ws->d_lam, ws->d_nu);
    }
    for (it = 0; it < refine_steps; ++it) {
        if (it > 0) {
            qp_res again; /* the same values as at the start of the iteration */
            compute_residuals(ws, in, &again);
        }
        newton_rhs(ws, in, cc, ws->r_stat, ws->r_dyn, ws->r_eqN);
        newton_residual(ws, in, ws->d_prim, ws->d_lam, ws->d_nu, ws->r_stat, ws->r_dyn, ws->r_eqN, ws->r_stat,
                        ws->r_dyn, ws->r_eqN);
        /* the correction overwrites the residual it solves for */
        riccati_solve(ws, in, ws->r_stat, ws->r_dyn, ws->r_eqN);
        dopus_lai_axpy(NP, DOPUS_R(1.0), ws->r_stat, ws->d_prim);
        dopus_lai_axpy((N + 1) * NX, DOPUS_R(1.0), ws->r_dyn, ws->d_lam);
        dopus_lai_axpy(NE, DOPUS_R(1.0), ws->r_eqN, ws->d_nu);
    }

    /* dv = D dw (dt_lo = dv + r_lo, dt_up = r_up - dv; a soft side adds its ds, soft_f),
     * dz = -(rc + z dt) / t, dy = -(rcs + y ds) / s */
#if QP_V4_STEPS
    {
        /* rc from the previous (predictor) direction first, then dv, then dz: the loop below */
        dopus_real rcl[DOPUS_QP_NB], rcu[DOPUS_QP_NB];
        qp_v4_rc(ws, cc, rcl, rcu);
        for (k = 0; k <= N; ++k)
            FOR_STAGE_ROWS(ws, k, b, j)
        ws->dv[b] = row_dot(in, k, j, ws->d_prim + k * NW);
        qp_v4_dz(ws, rcl, rcu);
    }
#else
    for (k = 0; k <= N; ++k)
        FOR_STAGE_ROWS(ws, k, b, j)
        {
            /* rc from the previous (predictor) direction, before it is overwritten */
            const dopus_real rcl = ws->has_lo[b] ? rc_lo(ws, b, cc) : DOPUS_R(0.0);
            const dopus_real rcu = ws->has_up[b] ? rc_up(ws, b, cc) : DOPUS_R(0.0);
            const dopus_real rcsl = SOFT && ws->soft_lo[b] == 1 ? rcs_lo(ws, b, cc) : DOPUS_R(0.0);
            const dopus_real rcsu = SOFT && ws->soft_up[b] == 1 ? rcs_up(ws, b, cc) : DOPUS_R(0.0);
            ws->dv[b] = row_dot(in, k, j, ws->d_prim + k * NW);
            if (SOFT && ws->soft_lo[b]) {
                const dopus_real q = ws->z_lo[b] / ws->t_lo[b];
                const dopus_real p = soft_p(ws->soft_lo[b], ws->y_lo[b], ws->s_lo[b]);
                const dopus_real a = (rcl + ws->z_lo[b] * r_lo(ws, b)) / ws->t_lo[b];
                const dopus_real rcs = ws->soft_lo[b] == 1 ? rcsl / ws->s_lo[b] : DOPUS_R(0.0);
                ws->ds_lo[b] = -(ws->rs_lo[b] + rcs + a + q * ws->dv[b]) / (soft_l2(in, ws, b, 0) + q + p);
                ws->dy_lo[b] =
                    ws->soft_lo[b] == 1 ? -(rcsl + ws->y_lo[b] * ws->ds_lo[b]) / ws->s_lo[b] : DOPUS_R(0.0);
            }
            if (SOFT && ws->soft_up[b]) {
                const dopus_real q = ws->z_up[b] / ws->t_up[b];
                const dopus_real p = soft_p(ws->soft_up[b], ws->y_up[b], ws->s_up[b]);
                const dopus_real a = (rcu + ws->z_up[b] * r_up(ws, b)) / ws->t_up[b];
                const dopus_real rcs = ws->soft_up[b] == 1 ? rcsu / ws->s_up[b] : DOPUS_R(0.0);
                ws->ds_up[b] = -(ws->rs_up[b] + rcs + a - q * ws->dv[b]) / (soft_l2(in, ws, b, 1) + q + p);
                ws->dy_up[b] =
                    ws->soft_up[b] == 1 ? -(rcsu + ws->y_up[b] * ws->ds_up[b]) / ws->s_up[b] : DOPUS_R(0.0);
            }
            if (ws->has_lo[b])
                ws->dz_lo[b] = -(rcl + ws->z_lo[b] * dt_lo(ws, b)) / ws->t_lo[b];
            if (ws->has_up[b])
                ws->dz_up[b] = -(rcu + ws->z_up[b] * dt_up(ws, b)) / ws->t_up[b];
        }
#endif
}

/* Largest steps in (0, 1] keeping t + ap dt >= 0 (ap, the primal step) and z + ad dz >= 0
 * (ad, the dual step), and whether no side blocks the full primal or dual step. */

static void max_steps(const dopus_qp_workspace *ws, dopus_real *ap, dopus_real *ad, int *full)
{
    int i = 0;
    dopus_real a = DOPUS_R(2.0), d = DOPUS_R(2.0);
#if QP_V4_STEPS
    /* four rows per vector: the same candidates -t/dt (each an exact IEEE quotient) and the same
     * selection (MINPD is dmin lane by lane), so the same a and d as the loop below, whose order
     * matters only when a candidate is NaN or zero: then the loop from the first row */
    if (ws->nb >= 4) {
        qp_v4 va = {DOPUS_R(2.0), DOPUS_R(2.0), DOPUS_R(2.0), DOPUS_R(2.0)}, vd = va;
        qp_v4_bits odd = {0, 0, 0, 0};
        long long lo[4];
        dopus_real la[4], ld[4];
        int q;
        for (; i + 4 <= ws->nb; i += 4) {
            qp_v4_rows r;
            const qp_v4_bits hl = qp_v4_mask(ws->has_lo + i), hu = qp_v4_mask(ws->has_up + i);
            qp_v4_load_rows(ws, i, &r);
            /* dt_lo = dv + r_lo, r_lo = vl - t_lo; dt_up = r_up - dv, r_up = uv - t_up */
            va = __builtin_ia32_minpd256(va, qp_v4_ratio(r.tl, r.dv + (r.vl - r.tl), hl, &odd));
            vd = __builtin_ia32_minpd256(vd, qp_v4_ratio(r.zl, r.dzl, hl, &odd));
            va = __builtin_ia32_minpd256(va, qp_v4_ratio(r.tu, (r.uv - r.tu) - r.dv, hu, &odd));
            vd = __builtin_ia32_minpd256(vd, qp_v4_ratio(r.zu, r.dzu, hu, &odd));
        }
        __builtin_memcpy(la, &va, sizeof la);
        __builtin_memcpy(ld, &vd, sizeof ld);
        __builtin_memcpy(lo, &odd, sizeof lo);
        for (q = 0; q < 4; ++q) {
            a = dmin(a, la[q]);
            d = dmin(d, ld[q]);
        }
        if (lo[0] | lo[1] | lo[2] | lo[3]) {
            a = d = DOPUS_R(2.0);
            i = 0;
        }
    }
#endif
    for (; i < ws->nb; ++i) {
        if (ws->has_lo[i]) {
            const dopus_real dt = dt_lo(ws, i);
            if (dt < DOPUS_R(0.0))
                a = dmin(a, -ws->t_lo[i] / dt);
            if (ws->dz_lo[i] < DOPUS_R(0.0))
                d = dmin(d, -ws->z_lo[i] / ws->dz_lo[i]);
        }
        if (ws->has_up[i]) {
            const dopus_real dt = dt_up(ws, i);
            if (dt < DOPUS_R(0.0))
                a = dmin(a, -ws->t_up[i] / dt);
            if (ws->dz_up[i] < DOPUS_R(0.0))
                d = dmin(d, -ws->z_up[i] / ws->dz_up[i]);
        }
        if (SOFT && ws->soft_lo[i] == 1) {
            if (ws->ds_lo[i] < DOPUS_R(0.0))
                a = dmin(a, -ws->s_lo[i] / ws->ds_lo[i]);
            if (ws->dy_lo[i] < DOPUS_R(0.0))
                d = dmin(d, -ws->y_lo[i] / ws->dy_lo[i]);
        }
        if (SOFT && ws->soft_up[i] == 1) {
            if (ws->ds_up[i] < DOPUS_R(0.0))
                a = dmin(a, -ws->s_up[i] / ws->ds_up[i]);
            if (ws->dy_up[i] < DOPUS_R(0.0))
                d = dmin(d, -ws->y_up[i] / ws->dy_up[i]);
        }
    }
    full[0] = a > DOPUS_R(1.0);
    full[1] = d > DOPUS_R(1.0);
    *ap = dmin(DOPUS_R(1.0), a);
    *ad = dmin(DOPUS_R(1.0), d);
}

/* The step taken for the largest step a to the boundary (full: nothing blocks a step of
 * 1): the full step when nothing blocks it, else a fraction that tends to 1 as a does
 * (0.99 a for short steps, 0.9999999 a near a = 1). */
static dopus_real step_to_boundary(dopus_real a, int full)
{
    return full ? DOPUS_R(1.0) : a * ((DOPUS_R(1.0) - a) * DOPUS_R(0.99) + a * DOPUS_R(0.9999999));
}

/* ---------------------------------------------------------------- infeasibility */

/* The separating value of the dual iterate y = (lam, nu, z) as a Farkas certificate,
 *   b'y = -lam_0'x0 - sum lam_{k+1}'b_k - nu'req - up'z_up + lo'z_lo,
 * with *bscale the largest data entry in it (at least 1) and *y1 the 1-norm of y. For
 * A'y = 0 (the constraint part of the stationarity residual) and b'y > 0 no feasible
 * point exists (for feasible w the Lagrangian term is <= 0); more precisely every w
 * violates some constraint by at least b'y / |y|_1. */
static dopus_real farkas_separation(const dopus_qp_workspace *ws, const dopus_qp_in *in, dopus_real *bscale,
                                    dopus_real *y1)
{
    int k, i;
    dopus_real bty = DOPUS_R(0.0), bs = DOPUS_R(1.0), n1 = DOPUS_R(0.0);
    bty -= dopus_lai_dot(NX, ws->lam, in->x0);
    bs = dmax(bs, dopus_lai_norm_inf(NX, in->x0));
    for (k = 0; k < N; ++k) {
        bty -= dopus_lai_dot(NX, ws->lam + (k + 1) * NX, in->b[k]);
        bs = dmax(bs, dopus_lai_norm_inf(NX, in->b[k]));
    }
    for (i = 0; i < (N + 1) * NX; ++i)
        n1 += dopus_fabs(ws->lam[i]);
    if (NE > 0) {
        bty -= dopus_lai_dot(NE, ws->nu, in->req);
        bs = dmax(bs, dopus_lai_norm_inf(NE, in->req));
        for (i = 0; i < NE; ++i)
            n1 += dopus_fabs(ws->nu[i]);
    }
    for (i = 0; i < ws->nb; ++i) {
        dopus_real lo, up;
        row_bounds(in, ws->bidx[i], &lo, &up);
        /* a soft side takes no part in a certificate (its multiplier stays bounded) */
        if (ws->has_lo[i] && !(SOFT && ws->soft_lo[i])) {
            bty += lo * ws->z_lo[i];
            bs = dmax(bs, dopus_fabs(lo));
            n1 += ws->z_lo[i];
        }
        if (ws->has_up[i] && !(SOFT && ws->soft_up[i])) {
            bty -= up * ws->z_up[i];
            bs = dmax(bs, dopus_fabs(up));
            n1 += ws->z_up[i];
        }
    }
    *bscale = bs;
    *y1 = n1;
    return bty;
}

/* The dual iterate has diverged (|y|_inf beyond CERT_GROWTH times the data scale) to a ray
 * with A'y = 0 to CERT_RES_DUAL: a Farkas certificate once b'y separates. */
static int dual_ray(const qp_res *r, dopus_real data_scale)
{
    return r->ny > CERT_GROWTH * data_scale && r->aty / r->ny <= CERT_RES_DUAL;
}

/* Farkas certificate on the normalised dual iterate y / |y|_inf once it has diverged:
 * A'y = 0 to CERT_RES_DUAL and a separating value b'y beyond CERT_SEP. *certified: 1 when
 * b'y separates beyond the tolerance tol as well (dopus_qp_info.certified). */
static int primal_infeasible(const dopus_qp_workspace *ws, const dopus_qp_in *in, const qp_res *r,
                             dopus_real data_scale, dopus_real tol, int *certified)
{
    dopus_real bscale, y1, bty;
    if (!dual_ray(r, data_scale))
        return 0;
    bty = farkas_separation(ws, in, &bscale, &y1) / r->ny;
    *certified = bty > dmax(CERT_SEP, tol) * bscale;
    return bty > CERT_SEP * bscale;
}

/* The largest coefficient of inequality row j of stage k (k = N: the terminal rows). */
static dopus_real row_norm(const dopus_qp_in *in, int k, int j)
{
    dopus_real m = DOPUS_R(0.0);
    int c;
    if (k < N && NG > 0 && j >= NW)
        for (c = 0; c < NW; ++c)
            m = dmax(m, dopus_fabs(in->C[k][(j - NW) + c * NG]));
    else if (k == N && NR > 0 && j >= NX)
        for (c = 0; c < NX; ++c)
            m = dmax(m, dopus_fabs(in->R[(j - NX) + c * NR]));
    else
        m = DOPUS_R(1.0);
    return m;
}

/* The mass of the dual iterate with each multiplier weighted by the largest coefficient of
 * its row, sum |y_i| |a_i|_inf over the initial-state, dynamics and terminal equality rows
 * and the hard sides: with it, (b'y - |A'y|_inf |w|_1) / mass bounds from below the largest
 * violation of a row in the units of its largest coefficient, so that a row written with
 * small coefficients (a terminal equality row scaled by 1e-3) does not pass for a smaller
 * violation than the same row normalised. */
static dopus_real certificate_mass(const dopus_qp_workspace *ws, const dopus_qp_in *in)
{
    dopus_real mass = DOPUS_R(0.0);
    int k, i, c, b, j;
    for (i = 0; i < NX; ++i)
        mass += dopus_fabs(ws->lam[i]);
    for (k = 0; k < N; ++k)
        for (i = 0; i < NX; ++i) {
            dopus_real m = DOPUS_R(1.0);
            for (c = 0; c < NW; ++c)
                m = dmax(m, dopus_fabs(in->Phi[k][i + c * NX]));
            mass += m * dopus_fabs(ws->lam[(k + 1) * NX + i]);
        }
    for (i = 0; i < NE; ++i) {
        dopus_real m = DOPUS_R(0.0);
        for (c = 0; c < NX; ++c)
            m = dmax(m, dopus_fabs(in->Req[i + c * NE1]));
        mass += m * dopus_fabs(ws->nu[i]);
    }
    for (k = 0; k <= N; ++k)
        FOR_STAGE_ROWS(ws, k, b, j)
        {
            const dopus_real m = row_norm(in, k, j);
            if (ws->has_lo[b] && !(SOFT && ws->soft_lo[b]))
                mass += m * ws->z_lo[b];
            if (ws->has_up[b] && !(SOFT && ws->soft_up[b]))
                mass += m * ws->z_up[b];
        }
    return mass;
}

/* The data of the certificate's rows in the units of certificate_mass: the largest of 1,
 * |x0|, |b_k,i| / max(1, |Phi_k row i|_inf), |req_i| / |Req row i|_inf and the finite
 * bounds of the hard sides over their row's largest coefficient. A row written with large
 * coefficients (a terminal equality row scaled by 1e3) scales the separation as much as
 * the mass, and so does not pass for a smaller relative violation than the same row
 * normalised. */
static dopus_real certificate_bound_scale(const dopus_qp_workspace *ws, const dopus_qp_in *in)
{
    dopus_real s = dmax(DOPUS_R(1.0), dopus_lai_norm_inf(NX, in->x0));
    int k, i, c, b, j;
    for (k = 0; k < N; ++k)
        for (i = 0; i < NX; ++i) {
            dopus_real m = DOPUS_R(1.0);
            for (c = 0; c < NW; ++c)
                m = dmax(m, dopus_fabs(in->Phi[k][i + c * NX]));
            s = dmax(s, dopus_fabs(in->b[k][i]) / m);
        }
    for (i = 0; i < NE; ++i) {
        dopus_real m = DOPUS_R(0.0);
        for (c = 0; c < NX; ++c)
            m = dmax(m, dopus_fabs(in->Req[i + c * NE1]));
        if (m > DOPUS_R(0.0))
            s = dmax(s, dopus_fabs(in->req[i]) / m);
    }
    for (k = 0; k <= N; ++k)
        FOR_STAGE_ROWS(ws, k, b, j)
        {
            const dopus_real m = row_norm(in, k, j);
            dopus_real lo, up;
            if (!(m > DOPUS_R(0.0)))
                continue;
            row_bounds(in, ws->bidx[b], &lo, &up);
            if (ws->has_lo[b] && !(SOFT && ws->soft_lo[b]))
                s = dmax(s, dopus_fabs(lo) / m);
            if (ws->has_up[b] && !(SOFT && ws->soft_up[b]))
                s = dmax(s, dopus_fabs(up) / m);
        }
    return s;
}

/* The same certificate, tested when the iteration has stalled or failed, with the
 * separation measured against its own accuracy instead of CERT_SEP: a point w violates
 * some row by at least (b'y - |A'y|_inf |w|_1) / certificate_mass in the units of the row's
 * largest coefficient (the A'y term keeps a residual A'y that is small but not zero from
 * passing for a separation, for points of the size of the iterate), and a separation
 * beyond CERT_SEP_STALL relative to the data (far above the round-off of b'y) proves that
 * no point meets the constraints. A QP infeasible
 * by a margin near the tolerance stalls before its dual iterate has grown to the regular
 * test's certificate (its residuals cannot fall below the tolerance, and the separation of
 * its certificate, which is exact to round-off, is the smallest violation any point can
 * reach); the test uses the smaller of CERT_SEP_STALL and tol, so that a QP infeasible by
 * more than the tolerance asked for is flagged whatever the tolerance. */
static int primal_infeasible_at_tol(const dopus_qp_workspace *ws, const dopus_qp_in *in, const qp_res *r,
                                    dopus_real data_scale, dopus_real tol)
{
    dopus_real bscale, y1, bty, w1 = DOPUS_R(0.0);
    int i;
    QP_TRACE("diagnosis: |y| %.3e (data %.3e) |A'y|/|y| %.3e\n", r->ny, data_scale, r->aty / r->ny);
    if (!dual_ray(r, data_scale))
        return 0;
    bty = farkas_separation(ws, in, &bscale, &y1);
    for (i = 0; i < NP; ++i)
        w1 += dopus_fabs(ws->prim[i]);
    bty -= r->aty * w1;
    y1 = certificate_mass(ws, in);
    bscale = certificate_bound_scale(ws, in);
    QP_TRACE("stalled: certificate separation %.3e (tolerance %.1e)\n", bty / (y1 * bscale), tol);
    return y1 > DOPUS_R(0.0) && bty / y1 > dmin(tol, CERT_SEP_STALL) * bscale;
}

/* Unboundedness certificate on the normalised primal iterate d = w / |w|: a feasible ray
 * (homogeneous equalities, inside the recession cone of the bounds) along which the
 * objective decreases without bound: d'Hd < 0, or Hd = 0 and g'd < 0. */
static int dual_infeasible(dopus_qp_workspace *ws, const dopus_qp_in *in, const qp_res *r,
                           dopus_real data_scale, dopus_real hscale)
{
    int k, i, b, j;
    dopus_real nw = r->nw, dhd = DOPUS_R(0.0), gd = DOPUS_R(0.0), hd = DOPUS_R(0.0), eq = DOPUS_R(0.0),
               cone = DOPUS_R(0.0);
    dopus_real h[NW];
    if (!(nw > CERT_GROWTH * data_scale))
        return 0;
    for (k = 0; k < N; ++k) {
        const dopus_real *w = ws->prim + k * NW;
        dopus_real *t = ws->work;
        dopus_lai_symv_l(NW, DOPUS_R(1.0) / nw, in->H[k], NW, w, DOPUS_R(0.0), h);
        dopus_lai_axpy(NW, in->hess_shift / nw, w, h);
        dhd += dopus_lai_dot(NW, w, h) / nw;
        gd += dopus_lai_dot(NW, in->g[k], w) / nw;
        hd = dmax(hd, dopus_lai_norm_inf(NW, h));
        for (i = 0; i < NX; ++i)
            t[i] = ws->prim[(k + 1) * NW + i] / nw;
        dopus_lai_gemv_n(NX, NW, -DOPUS_R(1.0) / nw, in->Phi[k], NX, w, DOPUS_R(1.0), t);
        eq = dmax(eq, dopus_lai_norm_inf(NX, t));
    }
    {
        const dopus_real *xN = ws->prim + N * NW;
        dopus_lai_symv_l(NX, DOPUS_R(1.0) / nw, in->HN, NX, xN, DOPUS_R(0.0), h);
        dopus_lai_axpy(NX, in->hess_shift / nw, xN, h);
        dhd += dopus_lai_dot(NX, xN, h) / nw;
        gd += dopus_lai_dot(NX, in->gN, xN) / nw;
        hd = dmax(hd, dopus_lai_norm_inf(NX, h));
        if (NE > 0) {
            dopus_lai_gemv_n(NE, NX, DOPUS_R(1.0) / nw, in->Req, NE1, xN, DOPUS_R(0.0), ws->work);
            eq = dmax(eq, dopus_lai_norm_inf(NE, ws->work));
        }
    }
    eq = dmax(eq, dopus_lai_norm_inf(NX, ws->prim) / nw);
    for (k = 0; k <= N; ++k)
        FOR_STAGE_ROWS(ws, k, b, j)
        {
            const dopus_real dv = row_dot(in, k, j, ws->prim + k * NW) / nw;
            if (ws->has_lo[b])
                cone = dmax(cone, -dv);
            if (ws->has_up[b])
                cone = dmax(cone, dv);
        }
    if (eq > CERT_RES_PRIMAL || cone > CERT_RES_PRIMAL)
        return 0;
    if (dhd < -CERT_SEP * hscale)
        return 1;
    return hd <= CERT_RES_PRIMAL * hscale && gd < -CERT_SEP * data_scale;
}

/* ---------------------------------------------------------------- driver */

/* The signed multiplier of inequality row i in the solution layout. */
static dopus_real *row_multiplier(dopus_qp_sol *sol, int i)
{
    if (i < TOFF) {
        const int k = i / NSI, j = i - k * NSI;
        return (NG == 0 || j < NW) ? &sol->mu_b[k][j] : &sol->mu_g[k][j - NW];
    }
    return (NR == 0 || i - TOFF < NX) ? &sol->mu_bN[i - TOFF] : &sol->mu_r[i - TOFF - NX];
}

static dopus_real row_mu(const dopus_qp_sol *sol, int i)
{
    if (i < TOFF) {
        const int k = i / NSI, j = i - k * NSI;
        return (NG == 0 || j < NW) ? sol->mu_b[k][j] : sol->mu_g[k][j - NW];
    }
    return (NR == 0 || i - TOFF < NX) ? sol->mu_bN[i - TOFF] : sol->mu_r[i - TOFF - NX];
}

/* The multipliers of the inequality rows (box, path, terminal box and terminal rows) set
 * to zero, padding included. */
static void zero_row_multipliers(dopus_qp_sol *sol)
{
    int k, i;
    for (k = 0; k < N; ++k) {
        for (i = 0; i < NW; ++i)
            sol->mu_b[k][i] = DOPUS_R(0.0);
        for (i = 0; i < DOPUS_QP_NG1; ++i)
            sol->mu_g[k][i] = DOPUS_R(0.0);
    }
    for (i = 0; i < NX; ++i)
        sol->mu_bN[i] = DOPUS_R(0.0);
    for (i = 0; i < DOPUS_QP_NR1; ++i)
        sol->mu_r[i] = DOPUS_R(0.0);
}

static void write_solution(const dopus_qp_workspace *ws, dopus_qp_sol *sol)
{
    int k, i;
    for (k = 0; k <= N; ++k)
        for (i = 0; i < NX; ++i) {
            sol->x[k][i] = ws->prim[k * NW + i];
            sol->lam[k][i] = ws->lam[k * NX + i];
        }
    for (k = 0; k < N; ++k)
        for (i = 0; i < NU; ++i)
            sol->u[k][i] = ws->prim[k * NW + NX + i];
    zero_row_multipliers(sol);
    for (i = 0; i < ws->nb; ++i)
        *row_multiplier(sol, ws->bidx[i]) =
            (ws->has_up[i] ? ws->z_up[i] : DOPUS_R(0.0)) - (ws->has_lo[i] ? ws->z_lo[i] : DOPUS_R(0.0));
    for (i = 0; i < NE; ++i)
        sol->nu[i] = ws->nu[i];
}

static void zero_solution(dopus_qp_sol *sol)
{
    int k, i;
    for (k = 0; k <= N; ++k)
        for (i = 0; i < NX; ++i)
            sol->x[k][i] = sol->lam[k][i] = DOPUS_R(0.0);
    for (k = 0; k < N; ++k)
        for (i = 0; i < NU1; ++i)
            sol->u[k][i] = DOPUS_R(0.0);
    zero_row_multipliers(sol);
    for (i = 0; i < NE1; ++i)
        sol->nu[i] = DOPUS_R(0.0);
}

/* The slack floor of the centred cold start: the primal infeasibility of w = 0 (the
 * largest |x0|, |b_k|, |req| and bound violation), between CENTRED_T_MIN and 1. A nearly
 * feasible start (the QPs of an SQP or RTI iteration, whose zero step satisfies the bounds
 * of a feasible iterate) starts close to the boundary with small complementarity t z; a
 * far infeasible one with t z = 1. */
static dopus_real centred_floor(const dopus_qp_workspace *ws, const dopus_qp_in *in)
{
    int k, b, j;
    dopus_real viol = ws->scale_b;
    for (k = 0; k <= N; ++k)
        FOR_STAGE_ROWS(ws, k, b, j)
        {
            dopus_real lo, up;
            (void)j;
            row_bounds(in, ws->bidx[b], &lo, &up);
            if (ws->has_lo[b])
                viol = dmax(viol, lo);
            if (ws->has_up[b])
                viol = dmax(viol, -up);
        }
    return dmin(DOPUS_R(1.0), dmax(CENTRED_T_MIN, viol));
}

/* The primal start of a cold solve with soft sides: x_0 = x0 and the states of the
 * dynamics from there, each control at the point of its box nearest to 0. From w = 0 a
 * measurement far outside the soft bounds moved the rows by the whole violation in the
 * first direction, which the slack of the row and the soft slack shared by their barrier
 * weights, so that the row's slack blocked the step at a thousandth of it; from the
 * rollout the soft slacks take up the violation at the start. */
static void soft_rollout(dopus_qp_workspace *ws, const dopus_qp_in *in)
{
    int k, i;
    for (i = 0; i < NX; ++i)
        ws->prim[i] = in->x0[i];
    for (k = 0; k < N; ++k) {
        dopus_real *w = ws->prim + k * NW, *xn = ws->prim + (k + 1) * NW;
        for (i = NX; i < NW; ++i)
            w[i] = dmin(dmax(DOPUS_R(0.0), in->lbw[k][i]), in->ubw[k][i]);
        for (i = 0; i < NX; ++i)
            xn[i] = in->b[k][i];
        dopus_lai_gemv_n(NX, NW, DOPUS_R(1.0), in->Phi[k], NX, w, DOPUS_R(1.0), xn);
    }
}

/* Whether some bounded side is soft (a QP of a solver compiled with soft rows may have
 * none: then it is solved as by the solver without them). */
static int any_soft_side(const dopus_qp_workspace *ws)
{
    int b;
    if (!SOFT)
        return 0;
    for (b = 0; b < ws->nb; ++b)
        if (ws->soft_lo[b] || ws->soft_up[b])
            return 1;
    return 0;
}

/* The soft sides of a cold start that the rollout violates by d: the slack s = d + t
 * takes up the violation, and the side's price zl + Zl s is split between the side's
 * multiplier z and the slack's y in the ratio s : t (the slack's stationarity holds,
 * t z = s y). */
static void soft_cold_sides(dopus_qp_workspace *ws, const dopus_qp_in *in)
{
    int k, b, j;
    for (k = 0; k <= N; ++k)
        FOR_STAGE_ROWS(ws, k, b, j)
        {
            dopus_real lo, up, w[4], price;
            const dopus_real v = row_dot(in, k, j, ws->prim + k * NW);
            row_bounds(in, ws->bidx[b], &lo, &up);
            soft_weights(in, ws->bidx[b], w);
            if (ws->soft_lo[b] && lo - v > DOPUS_R(0.0)) {
                price = w[0] + w[2] * ws->s_lo[b];
                ws->z_lo[b] = dmax(price * ws->s_lo[b] / (ws->s_lo[b] + ws->t_lo[b]), ws->z_lo[b]);
                ws->y_lo[b] = ws->z_lo[b] * ws->t_lo[b] / ws->s_lo[b];
            }
            if (ws->soft_up[b] && v - up > DOPUS_R(0.0)) {
                price = w[1] + w[3] * ws->s_up[b];
                ws->z_up[b] = dmax(price * ws->s_up[b] / (ws->s_up[b] + ws->t_up[b]), ws->z_up[b]);
                ws->y_up[b] = ws->z_up[b] * ws->t_up[b] / ws->s_up[b];
            }
        }
}

/* The multipliers of a cold start with soft sides, backwards from x_N: lam_N and each lam_k
 * such that the stationarity rows of the states hold at the start, and the residual of a
 * control's row on the multiplier of the side of its hard box that can take it (that side's
 * slack t lowered to 1/z, so that t z stays at most the unit of the cold start). With the
 * price on the violated soft sides (soft_cold_sides), the start is then dual feasible but
 * for the controls without a box, however far outside its soft bounds the rollout lies:
 * without it, the stationarity residual of such a start (1e3 to 1e6 times the data of the
 * bounds) made Newton directions of 1e6 that the control boxes cut to steps of 1e-6. */
static void soft_dual_rollout(dopus_qp_workspace *ws, const dopus_qp_in *in)
{
    int k, i, b, j;
    for (k = N; k >= 0; --k) {
        const dopus_real *w = ws->prim + k * NW;
        dopus_real a[NW];
        if (k < N) {
            dopus_lai_symv_l(NW, DOPUS_R(1.0), in->H[k], NW, w, DOPUS_R(0.0), a);
            dopus_lai_axpy(NW, in->hess_shift, w, a);
            dopus_lai_axpy(NW, DOPUS_R(1.0), in->g[k], a);
            dopus_lai_gemv_t(NX, NW, -DOPUS_R(1.0), in->Phi[k], NX, ws->lam + (k + 1) * NX, DOPUS_R(1.0), a);
        } else {
            dopus_lai_symv_l(NX, DOPUS_R(1.0), in->HN, NX, w, DOPUS_R(0.0), a);
            dopus_lai_axpy(NX, in->hess_shift, w, a);
            dopus_lai_axpy(NX, DOPUS_R(1.0), in->gN, a);
        }
        FOR_STAGE_ROWS(ws, k, b, j)
        {
            const dopus_real zl = ws->has_lo[b] ? ws->z_lo[b] : DOPUS_R(0.0);
            const dopus_real zu = ws->has_up[b] ? ws->z_up[b] : DOPUS_R(0.0);
            row_axpy(in, k, j, zu - zl, a);
        }
        /* the controls' rows: the residual goes to the multiplier of the side of a hard box
         * that can take it */
        if (k < N)
            FOR_STAGE_ROWS(ws, k, b, j)
            {
                if (j < NX || j >= NW)
                    continue;
                if (a[j] > DOPUS_R(0.0) && ws->has_lo[b] && !(SOFT && ws->soft_lo[b])) {
                    ws->z_lo[b] += a[j];
                    ws->t_lo[b] = dmin(ws->t_lo[b], DOPUS_R(1.0) / ws->z_lo[b]);
                    a[j] = DOPUS_R(0.0);
                } else if (a[j] < DOPUS_R(0.0) && ws->has_up[b] && !(SOFT && ws->soft_up[b])) {
                    ws->z_up[b] -= a[j];
                    ws->t_up[b] = dmin(ws->t_up[b], DOPUS_R(1.0) / ws->z_up[b]);
                    a[j] = DOPUS_R(0.0);
                }
            }
        for (i = 0; i < NX; ++i)
            ws->lam[k * NX + i] = -a[i];
    }
}

/* Whether the rollout violates a soft side of stage 0 or 1 (the measured state and its
 * first prediction, before the drift of the rollout over the horizon) by more than
 * SOFT_FAR, in the units in which the cold start's slacks and multipliers are 1. */
static int soft_far(const dopus_qp_workspace *ws, const dopus_qp_in *in)
{
    int k, b, j;
    const dopus_real lim = SOFT_FAR;
    for (k = 0; k <= N && k <= 1; ++k)
        FOR_STAGE_ROWS(ws, k, b, j)
        {
            dopus_real lo, up;
            const dopus_real v = row_dot(in, k, j, ws->prim + k * NW);
            row_bounds(in, ws->bidx[b], &lo, &up);
            if ((ws->soft_lo[b] && lo - v > lim) || (ws->soft_up[b] && v - up > lim))
                return 1;
        }
    return 0;
}

/* The primal part of the warm-start point *sol in ws->prim (x_k and u_k; the rest as it is). */
static void warm_primal(dopus_qp_workspace *ws, const dopus_qp_sol *sol)
{
    int k, i;
    for (k = 0; k <= N; ++k)
        for (i = 0; i < NX; ++i)
            ws->prim[k * NW + i] = sol->x[k][i];
    for (k = 0; k < N; ++k)
        for (i = 0; i < NU; ++i)
            ws->prim[k * NW + NX + i] = sol->u[k][i];
}

/* Starting point. Cold (centred = 0): w = 0, lam = nu = 0, slacks max(1, v - lo),
 * multipliers 1. Centred cold start (centred = 1): slacks max(floor, v - lo) and
 * multipliers floor / t (centred_floor). Warm: the given primal-dual point with slacks and
 * multipliers pushed off zero. A cold start whose measurement lies far outside a soft side
 * (soft_far) starts from the rollout instead of w = 0, with the price on the violated soft
 * sides and the multipliers of the dual rollout. */
static void initial_point(dopus_qp_workspace *ws, const dopus_qp_in *in, const dopus_qp_settings *st,
                          const dopus_qp_sol *sol, int centred)
{
    int k, i, b, j, far = 0;
    const int warm = st->warm_start != 0;
    const dopus_real floor_c = !warm && centred ? centred_floor(ws, in) : DOPUS_R(1.0);
    for (i = 0; i < NP; ++i)
        ws->prim[i] = DOPUS_R(0.0);
    for (i = 0; i < (N + 1) * NX; ++i)
        ws->lam[i] = DOPUS_R(0.0);
    for (i = 0; i < NE1; ++i)
        ws->nu[i] = DOPUS_R(0.0);
    if (SOFT && !warm && any_soft_side(ws)) {
        soft_rollout(ws, in);
        far = soft_far(ws, in);
        if (!far)
            for (i = 0; i < NP; ++i)
                ws->prim[i] = DOPUS_R(0.0);
    }
    if (warm) {
        warm_primal(ws, sol);
        for (k = 0; k <= N; ++k)
            for (i = 0; i < NX; ++i)
                ws->lam[k * NX + i] = sol->lam[k][i];
        for (i = 0; i < NE; ++i)
            ws->nu[i] = sol->nu[i];
    }
    for (k = 0; k <= N; ++k)
        FOR_STAGE_ROWS(ws, k, b, j)
        {
            const dopus_real mu_signed = warm ? row_mu(sol, ws->bidx[b]) : DOPUS_R(0.0);
            const dopus_real v = row_dot(in, k, j, ws->prim + k * NW);
            dopus_real lo, up;
            row_bounds(in, ws->bidx[b], &lo, &up);
            ws->t_lo[b] = ws->t_up[b] = DOPUS_R(1.0);
            ws->z_lo[b] = ws->z_up[b] = DOPUS_R(0.0);
            if (ws->has_lo[b]) {
                const dopus_real floor_t = warm ? WARM_FLOOR_T * dmax(DOPUS_R(1.0), dopus_fabs(lo)) : floor_c;
                /* a soft side: the slack takes up the violation, s = max(lo - v, 0) + floor */
                const dopus_real sl =
                    SOFT && ws->soft_lo[b] ? dmax(lo - v, DOPUS_R(0.0)) + floor_t : DOPUS_R(0.0);
                ws->t_lo[b] = dmax(v - lo + sl, floor_t);
                ws->z_lo[b] = warm      ? dmax(-mu_signed, WARM_FLOOR_Z)
                              : centred ? floor_c / ws->t_lo[b]
                                        : DOPUS_R(1.0);
                if (SOFT && ws->soft_lo[b]) {
                    dopus_real w[4];
                    soft_weights(in, ws->bidx[b], w);
                    ws->s_lo[b] = sl;
                    ws->y_lo[b] = ws->soft_lo[b] != 1 ? DOPUS_R(0.0)
                                  : warm              ? dmax(w[0] + w[2] * sl - ws->z_lo[b], WARM_FLOOR_Z)
                                  : centred           ? floor_c / sl
                                                      : DOPUS_R(1.0);
                }
            }
            if (ws->has_up[b]) {
                const dopus_real floor_t = warm ? WARM_FLOOR_T * dmax(DOPUS_R(1.0), dopus_fabs(up)) : floor_c;
                const dopus_real su =
                    SOFT && ws->soft_up[b] ? dmax(v - up, DOPUS_R(0.0)) + floor_t : DOPUS_R(0.0);
                ws->t_up[b] = dmax(up - v + su, floor_t);
                ws->z_up[b] = warm      ? dmax(mu_signed, WARM_FLOOR_Z)
                              : centred ? floor_c / ws->t_up[b]
                                        : DOPUS_R(1.0);
                if (SOFT && ws->soft_up[b]) {
                    dopus_real w[4];
                    soft_weights(in, ws->bidx[b], w);
                    ws->s_up[b] = su;
                    ws->y_up[b] = ws->soft_up[b] != 1 ? DOPUS_R(0.0)
                                  : warm              ? dmax(w[1] + w[3] * su - ws->z_up[b], WARM_FLOOR_Z)
                                  : centred           ? floor_c / su
                                                      : DOPUS_R(1.0);
                }
            }
        }
    if (far) {
        soft_cold_sides(ws, in);
        soft_dual_rollout(ws, in);
    }
}

static dopus_real merit(const qp_res *r)
{
    return dmax(dmax(r->stat_s, r->eq_s), dmax(r->ineq_s, r->comp_s));
}

static int finish(dopus_qp_workspace *ws, const qp_res *r, int status, int iter, dopus_qp_sol *sol,
                  dopus_qp_info *info)
{
    if (sol)
        write_solution(ws, sol);
    if (info) {
        info->status = status;
        info->iterations = iter;
        info->res_stat = r->stat;
        info->res_eq = r->eq;
        info->res_ineq = r->ineq;
        info->res_comp = r->comp;
        info->res_stat_scaled = r->stat_s;
        info->res_eq_scaled = r->eq_s;
        info->res_ineq_scaled = r->ineq_s;
        info->res_comp_scaled = r->comp_s;
    }
    return status;
}

/* Returned by the steps of the loop below: the iteration goes on; the iterate was replaced
 * by a restart (test it afresh). Never returned by dopus_qp_solve. */
#define QP_GO_ON (-1)
#define QP_RESTARTED (-2)

/* The state of the interior point loop of one solve. */
typedef struct {
    dopus_qp_settings st;  /* the settings, checked (warm_start cleared by the restart) */
    dopus_real hscale;     /* Hessian scale: the size of the inertia corrections */
    dopus_real data_scale; /* data scale for the divergence tests of the certificates */
    /* attempt 0: the centred cold start with the long steps; 1: the plain start (a warm
     * start, or the cold start again after attempt 0 stalled) with the careful steps; 2:
     * the restart after a nonconvex stall (see qp_track_best) */
    int attempt;
    /* sweeps of the active-set start: iterations of the solve before the interior point's */
    int as_sweeps;
    int n_corr, n_aug;     /* delta corrections and terminal augmentations, every attempt */
    int n_corr_attempt;    /* n_corr when attempt 1 began */
    dopus_real delta_last; /* delta of the last corrected factorisation */
    dopus_real delta_used; /* the largest delta of the solve */
    dopus_real mu_prev;    /* mu of the previous iteration */
    dopus_real sigma_min;  /* SIGMA_MIN_RESTART after a restart */
    dopus_real best_merit; /* the best iterate so far (it is in *sol) */
    int best_iter;
    int best_solved; /* the stall ended at the best iterate's round-off: it is the solution */
    int certified;   /* the regular test's certificate (primal_infeasible) ended the solve */
    qp_res best_r;
    /* progress towards an infeasibility certificate (see qp_track_best): the smallest
     * normalised constraint residual |A'y| / |y| of a dual iterate beyond the data scale,
     * and the iteration that last reduced it by CERT_PROGRESS */
    dopus_real best_cert;
    int cert_iter;
    /* the deadline (settings.clock): the last read of the clock (have_read: one was made)
     * and the price of one iteration */
    double t_read;
    double price;
    int have_read;
} qp_loop;

/* ---------------------------------------------------------------- data, scales, start */

/* The settings, with the defaults for the missing or meaningless ones. */
static void checked_settings(const dopus_qp_settings *settings, dopus_qp_settings *st)
{
    if (settings)
        *st = *settings;
    else
        dopus_qp_settings_default(st);
    if (!(st->tol > DOPUS_R(0.0)))
        st->tol = DOPUS_PREC(1e-8, 1e-5);
    if (st->max_iter < 0)
        st->max_iter = 0;
    if (st->refine_steps < 0)
        st->refine_steps = 0;
    if (!(st->iter_price >= 0.0))
        st->iter_price = 0.0;
}

/* 1 when the caller's deadline leaves no room for one more iteration (settings.clock; 0
 * without a clock). Read before each factorisation: the time since the last read is one
 * iteration (or sweep) of this solve, and the price of the next is the largest of them. */
static int qp_deadline_passed(qp_loop *L)
{
    double now;
    if (L->st.clock == NULL)
        return 0;
    now = L->st.clock(L->st.clock_ctx);
    if (L->have_read && now - L->t_read > L->price)
        L->price = now - L->t_read;
    L->t_read = now;
    L->have_read = 1;
    return now + L->price > L->st.deadline;
}

/* The info of a solve that stops before its first iterate. */
static void info_not_solved(dopus_qp_info *info)
{
    info->status = DOPUS_QP_INVALID_INPUT;
    info->iterations = info->inertia_corrections = info->terminal_augmentations = 0;
    info->pivot_floors = 0;
    info->factorizations = info->active_set = info->certified = info->prefactored = 0;
    info->delta = DOPUS_R(0.0);
    info->res_stat = info->res_eq = info->res_ineq = info->res_comp = INFINITY;
    info->res_stat_scaled = info->res_eq_scaled = info->res_ineq_scaled = info->res_comp_scaled = INFINITY;
    info->obj = NAN;
}

static int warm_start_finite(const dopus_qp_sol *sol)
{
    return dopus_lai_all_finite(NX, N + 1, &sol->x[0][0], NX) &&
           dopus_lai_all_finite(NX, N + 1, &sol->lam[0][0], NX) &&
           dopus_lai_all_finite(NU1, N, &sol->u[0][0], NU1) &&
           dopus_lai_all_finite(NW, N, &sol->mu_b[0][0], NW) &&
           dopus_lai_all_finite(DOPUS_QP_NG1, N, &sol->mu_g[0][0], DOPUS_QP_NG1) &&
           dopus_lai_all_finite(NX, 1, sol->mu_bN, NX) &&
           dopus_lai_all_finite(DOPUS_QP_NR1, 1, sol->mu_r, DOPUS_QP_NR1) &&
           dopus_lai_all_finite(NE1, 1, sol->nu, NE1);
}

/* The largest data entry the certificates compare their diverging iterates with: the
 * finite bounds, x0, b, g, gN and req, at least 1; from the data scales (the same maxima of
 * the finite data, data_scales). */
static dopus_real certificate_data_scale(const dopus_qp_workspace *ws)
{
    return dmax(dmax(DOPUS_R(1.0), ws->scale_bounds), dmax(ws->scale_b, ws->scale_g));
}

/* The state the factorisations start from in a solve or a prefactor: no correction, no
 * augmentation, no penalty, the counters 0, and Phi_k' formed where it is kept (phit 0: it is,
 * by the prefactor of the same data). */
static void factor_state_reset(dopus_qp_workspace *ws, const dopus_qp_in *in, int phit)
{
    ws->delta = DOPUS_R(0.0);
    ws->rho_aug = DOPUS_R(0.0);
    ws->pivot_floors = 0;
    ws->penalty = 0;
    ws->n_fact = 0;
#if DOPUS_QP_PHIT
    ws->fuse = 0; /* (only the solve's loop fuses the predictor's sweep) */
    ws->swept = 0;
    if (phit)
        transpose_phi(ws, in);
#else
    (void)in;
    (void)phit;
#endif
}

/* Settings, data checks, the bounded rows, the data scales and the starting point of the
 * first attempt. Returns QP_GO_ON, or the status of a solve that ends here (*sol zeroed
 * unless a pointer was NULL). */
static int qp_prepare(qp_loop *L, dopus_qp_workspace *ws, const dopus_qp_in *in,
                      const dopus_qp_settings *settings, dopus_qp_sol *sol, dopus_qp_info *info)
{
    int bounds, kept, rows;
    dopus_real hmax;
    checked_settings(settings, &L->st);
    L->certified = 0;
    if (info)
        info_not_solved(info);
    if (ws == NULL || in == NULL || sol == NULL)
        return DOPUS_QP_INVALID_INPUT;
    /* a prefactor's factorisation of these data: the preparation it did is this solve's (Phi_k'
     * formed; dopus_qp_prefactor_guess: the bounded rows and the Hessian scale too) */
    kept = L->st.prefactored && ws->pre_status >= 0;
    rows = kept && ws->pre_rows;
    /* a non-finite warm start is bad input, not a reason to produce NaN */
    if (!check_input(in, rows ? NULL : &hmax) || (L->st.warm_start && !warm_start_finite(sol))) {
        zero_solution(sol);
        return DOPUS_QP_INVALID_INPUT;
    }
    if (rows)
        hmax = ws->pre_hmax;
    factor_state_reset(ws, in, !kept);
    ws->n_pre = 0;
    ws->pre_tol = DOPUS_R(0.0); /* (the workspace may hold anything between solves) */
    bounds = rows ? 0 : setup_bounds(ws, in);
    if (bounds == 2) {
        /* more bounded rows than the workspace was generated for */
        zero_solution(sol);
        return DOPUS_QP_INVALID_INPUT;
    }
    if (bounds == 1) {
        zero_solution(sol);
        if (info) {
            info->status = DOPUS_QP_PRIMAL_INFEASIBLE;
            info->certified = 1;
        }
        return DOPUS_QP_PRIMAL_INFEASIBLE;
    }
    L->hscale = hessian_scale(in, hmax);
    data_scales(ws, in);
    L->attempt = L->st.warm_start ? 1 : 0;
    initial_point(ws, in, &L->st, sol, L->attempt == 0);
    L->data_scale = certificate_data_scale(ws);
    L->best_solved = 0;
    L->n_corr = L->n_aug = L->n_corr_attempt = 0;
    L->as_sweeps = 0;
    L->delta_last = L->delta_used = DOPUS_R(0.0);
    L->mu_prev = INFINITY;
    L->sigma_min = DOPUS_R(0.0);
    L->best_merit = INFINITY;
    L->best_iter = 0;
    L->best_cert = INFINITY;
    L->cert_iter = 0;
    L->t_read = 0.0;
    L->price = L->st.iter_price;
    L->have_read = 0;
    return QP_GO_ON;
}

/* ---------------------------------------------------------------- stopping tests, restarts */

/* A fresh start of the iteration within one solve (after a stall, at iteration iter): the
 * cold initial point, no augmentation or regularisation carried over, no best iterate yet. */
static void qp_restart(qp_loop *L, dopus_qp_workspace *ws, const dopus_qp_in *in, const dopus_qp_sol *sol,
                       int attempt, int iter)
{
    L->attempt = attempt;
    initial_point(ws, in, &L->st, sol, 0);
    ws->rho_aug = DOPUS_R(0.0);
    L->delta_last = DOPUS_R(0.0);
    L->mu_prev = INFINITY;
    L->best_merit = INFINITY;
    L->best_iter = iter + 1;
    L->best_cert = INFINITY;
    L->cert_iter = iter + 1;
}

/* The iteration of the last progress: a better iterate (smaller merit), or a step towards
 * a Farkas certificate. On an infeasible QP the residuals stop improving while the dual
 * iterate y diverges and its direction converges to a certificate (A'y / |y| -> 0, see
 * primal_infeasible); the iterations until the certificate is exact are progress too, not
 * a stall. Counted once y is beyond the data scale and each time |A'y| / |y| falls by
 * CERT_PROGRESS. */
static int qp_last_progress(qp_loop *L, const qp_res *r, int iter)
{
    if (r->ny > L->data_scale && r->aty < CERT_PROGRESS * L->best_cert * r->ny) {
        L->best_cert = r->aty / r->ny;
        L->cert_iter = iter;
    }
    return L->best_iter > L->cert_iter ? L->best_iter : L->cert_iter;
}

/* 1 when the best iterate, at a stall, is the solution to the precision its residuals can
 * have: the equality, inequality and complementarity residuals within the tolerance, and the
 * stationarity residual within its round-off, the rounding unit times the terms its sums
 * add up (the largest |H w|, |Phi_k' lam_{k+1}|, |C' mu_g|, |R' mu_r|, |Req' nu| entry
 * bounded by the sum's length times the largest data entry times the largest |w| or
 * multiplier, plus |g| and |lam_k|, |mu_b|). Below a tolerance smaller than that round-off
 * (the cancellation of terms far larger than their sum: a long step of the robot arm's QP
 * from the OCP file's guess to the measurement, |H| 68 times |w| 18 against a residual
 * scale of 1), whether an iterate meets the tolerance is chance; the Python reference's
 * QP solves to round-off (docs/algorithm.md section 13). Evaluated once, at a stall. */
static int qp_best_at_roundoff(const qp_loop *L, const dopus_qp_workspace *ws, const dopus_qp_in *in)
{
    const qp_res *r = &L->best_r;
    const dopus_real tol = L->st.tol;
    dopus_real pmax = DOPUS_R(0.0), cmax = DOPUS_R(0.0), rmax = DOPUS_R(0.0), emax = DOPUS_R(0.0), terms;
    int k;
    if (!(r->eq_s <= tol && r->ineq_s <= tol && r->comp_s <= tol))
        return 0;
    for (k = 0; k < N; ++k) {
        pmax = dmax(pmax, dopus_lai_max_abs_mat(NX, NW, in->Phi[k], NX));
        if (NG > 0)
            cmax = dmax(cmax, dopus_lai_max_abs_mat(NG, NW, in->C[k], NG));
    }
    if (NR > 0)
        rmax = dopus_lai_max_abs_mat(NR, NX, in->R, NR);
    if (NE > 0)
        emax = dopus_lai_max_abs_mat(NE, NX, in->Req, NE1);
    terms = (DOPUS_R(1.0) * NW) * L->hscale * r->nw +
            (DOPUS_R(1.0) + NX * pmax + NG * cmax + NR * rmax + NE * emax) * r->ny + ws->scale_g;
    return r->stat <= DOPUS_REAL_EPSILON * terms;
}

/* The best iterate so far, and what to do when progress stalls: restart (QP_RESTARTED) or
 * give up (DOPUS_QP_STALLED, or DOPUS_QP_PRIMAL_INFEASIBLE when the diverged dual iterate
 * proves that no point meets the constraints to the tolerance; DOPUS_QP_SOLVED when the
 * best iterate meets them to its round-off, qp_best_at_roundoff); else QP_GO_ON. */
static int qp_track_best(qp_loop *L, dopus_qp_workspace *ws, const dopus_qp_in *in, dopus_qp_sol *sol,
                         const qp_res *r, int iter)
{
    int last;
    if (iter == 0 || merit(r) < L->best_merit) {
        /* the best point so far goes straight into the output (the warm-start point
         * has been read by then; a restart starts cold) */
        L->best_merit = merit(r);
        L->best_iter = iter;
        L->best_r = *r;
        write_solution(ws, sol);
    }
    last = qp_last_progress(L, r, iter);
    if (L->best_iter == iter) {
        return QP_GO_ON;
    } else if (L->attempt == 0 && iter - L->best_iter >= RESTART_STALL_ITERS) {
        /* The centred start with its long steps made no progress (a nonconvex QP, whose
         * iterate it threw into the wrong region): start again from the plain cold
         * start with the careful steps. */
        L->n_corr_attempt = L->n_corr;
        qp_restart(L, ws, in, sol, 1, iter);
        QP_TRACE("plain start at iteration %d\n", iter);
        return QP_RESTARTED;
    } else if (L->attempt == 1 && L->n_corr > L->n_corr_attempt &&
               iter - L->best_iter >= RESTART_STALL_ITERS) {
        /* Stalled after inertia corrections: the QP is nonconvex on the null space of
         * the equalities, and Mehrotra's aggressive mu reduction let a near-singular
         * barrier Hessian throw the iterate far into the nonconvex region before the
         * bounds that supply the curvature were identified (primal steps of 60 and
         * more on the robot-arm QPs); the inertia-corrected steps cannot recover.
         * Start again from the initial point with mu reduced at most
         * 1/SIGMA_MIN_RESTART per iteration. (Restarting at the first correction
         * instead saves iterations but loses the QPs that the first attempt solves
         * and the cautious one does not.) */
        L->sigma_min = SIGMA_MIN_RESTART;
        L->st.warm_start = 0;
        qp_restart(L, ws, in, sol, 2, iter);
        QP_TRACE("restart at iteration %d\n", iter);
        return QP_RESTARTED;
    } else if (iter - last >= STALL_ITERS) {
        if (qp_best_at_roundoff(L, ws, in)) {
            L->best_solved = 1;
            return DOPUS_QP_SOLVED;
        }
        return primal_infeasible_at_tol(ws, in, r, L->data_scale, L->st.tol) ? DOPUS_QP_PRIMAL_INFEASIBLE
                                                                             : DOPUS_QP_STALLED;
    }
    return QP_GO_ON;
}

/* The tests of iterate iter with residuals r, in this order: non-finite, converged, the
 * best iterate and stalls, the infeasibility certificates, the iteration limit. Returns
 * the status to stop with, QP_RESTARTED or QP_GO_ON. */
static int qp_stopping_tests(qp_loop *L, dopus_qp_workspace *ws, const dopus_qp_in *in, dopus_qp_sol *sol,
                             const qp_res *r, int iter)
{
    const dopus_real tol = L->st.tol;
    int s;
    if (!(isfinite(r->stat) && isfinite(r->eq) && isfinite(r->mu)))
        return DOPUS_QP_NUMERICAL;
    if (r->stat_s <= tol && r->eq_s <= tol && r->ineq_s <= tol && r->comp_s <= tol)
        return DOPUS_QP_SOLVED;
    s = qp_track_best(L, ws, in, sol, r, iter);
    if (s != QP_GO_ON)
        return s;
    if (primal_infeasible(ws, in, r, L->data_scale, tol, &L->certified))
        return DOPUS_QP_PRIMAL_INFEASIBLE;
    if (dual_infeasible(ws, in, r, L->data_scale, L->hscale))
        return DOPUS_QP_DUAL_INFEASIBLE;
    if (iter >= L->st.max_iter)
        return DOPUS_QP_MAX_ITER;
    return QP_GO_ON;
}

#ifdef DOPUS_QP_TRACE
/* barrier weights of every row, for an inertia analysis of H + D'QD offline */
static void trace_barrier_weights(const dopus_qp_workspace *ws, const dopus_qp_in *in, int iter)
{
    int kk, b2 = 0;
    QP_TRACE("QD %d", iter);
    for (kk = 0; kk < NI; ++kk) {
        const dopus_real qk = (b2 < ws->nb && ws->bidx[b2] == kk) ? row_q(ws, in, b2++) : DOPUS_R(0.0);
        QP_TRACE(" %.17g", qk);
    }
    QP_TRACE("\n");
}
#else
#define trace_barrier_weights(ws, in, iter) ((void)0)
#endif

/* ---------------------------------------------------------------- factorisation */

/* Exact terminal augmentation rho Req'Req after a failed pivot: rho grows from the Hessian
 * scale over |Req|^2 by factors of 100. Returns riccati_factor's code of the last try. */
static int qp_augment_terminal(qp_loop *L, dopus_qp_workspace *ws, const dopus_qp_in *in)
{
    int tries, fact = 1;
    dopus_real rho0 = L->hscale / dmax(dopus_lai_max_abs_mat(NE, NX, in->Req, NE1), DOPUS_REAL_SQRT_TINY);
    rho0 /= dmax(dopus_lai_max_abs_mat(NE, NX, in->Req, NE1), DOPUS_REAL_SQRT_TINY);
    for (tries = 0; tries < RHO_TRIES && fact == 1 && ws->rho_aug < rho0 * RHO_MAX_REL; ++tries) {
        ws->rho_aug = ws->rho_aug > DOPUS_R(0.0) ? DOPUS_R(100.0) * ws->rho_aug : rho0;
        ++L->n_aug;
        fact = riccati_factor(ws, in);
    }
    return fact;
}

/* Inertia correction delta I after a failed pivot, growing geometrically from a third of
 * the last one used. Returns riccati_factor's code of the last try. */
static int qp_correct_delta(qp_loop *L, dopus_qp_workspace *ws, const dopus_qp_in *in)
{
    int tries, fact;
    ws->delta = L->delta_last > DOPUS_R(0.0) ? dmax(DOPUS_R(1e-20) * L->hscale, L->delta_last / DOPUS_R(3.0))
                                             : DOPUS_R(1e-8) * L->hscale;
    /* bounded by count as well as by size: with huge or non-finite data the size
     * test alone may never fire (NaN compares false, inf * 10 stays inf) */
    for (tries = 0;; ++tries) {
        ++L->n_corr;
        fact = riccati_factor(ws, in);
        if (fact != 1 || !(ws->delta <= DELTA_MAX_REL * L->hscale) || tries >= DELTA_TRIES)
            break;
        ws->delta *= DELTA_GROW;
    }
    L->delta_last = ws->delta;
    L->delta_used = dmax(L->delta_used, ws->delta);
    return fact;
}

/* Factorisation with minimal inertia correction: first the exact terminal augmentation
 * rho Req'Req, then delta I growing geometrically. Returns 0 when factorised. */
static int qp_factor_with_correction(qp_loop *L, dopus_qp_workspace *ws, const dopus_qp_in *in)
{
    int fact;
    ws->delta = DOPUS_R(0.0);
    fact = riccati_factor(ws, in);
    if (fact == 1 && NE > 0)
        fact = qp_augment_terminal(L, ws, in);
    if (fact == 1)
        fact = qp_correct_delta(L, ws, in);
    return fact;
}

/* A factorisation that needed a correction (a failed pivot) at an iterate whose dual
 * iterate has diverged to a Farkas certificate: on a QP infeasible by a margin near the
 * tolerance the barrier weights of the rows of the certificate grow beyond what the
 * Riccati recursion resolves in floating point, and the corrected steps from here on
 * damage the certificate (a delta of 1e10 times the Hessian scale, steps of 1e-12 that
 * move the multipliers off their ray) until a factorisation fails outright. The
 * certificate is tested here, before the step, as after a stall or failure
 * (primal_infeasible_at_tol). Returns 1 when it proves infeasibility. */
static int qp_certificate_at_failure(const qp_loop *L, const dopus_qp_workspace *ws, const dopus_qp_in *in,
                                     const qp_res *r)
{
    return dual_ray(r, L->data_scale) && primal_infeasible_at_tol(ws, in, r, L->data_scale, L->st.tol);
}

/* Iterative refinement steps of the corrector's solve. */
static int qp_refine_steps(const qp_loop *L, const dopus_qp_workspace *ws, const qp_res *r, int iter,
                           int floors_before)
{
    /* floored pivots make the factorisation inexact: refine more; far from the
     * solution the directions need no refinement */
    int nref = L->st.refine_steps + (ws->pivot_floors > floors_before ? 2 : 0);
    /* no progress in the last iteration near the solution: the directions are limited
     * by the accuracy of the factorisation, refine more */
    if (iter > L->best_iter)
        nref += 2;
    if (merit(r) > REFINE_BELOW && ws->pivot_floors == floors_before)
        nref = 0;
    return nref;
}

/* ---------------------------------------------------------------- steps */

/* Equality-constrained QP (no bounded side): one full Newton step is exact. */
static void qp_newton_step(dopus_qp_workspace *ws, const dopus_qp_in *in, int nref)
{
    const qp_centring none = {0, DOPUS_R(0.0), DOPUS_R(0.0)}; /* no bounded side: rc is never formed */
    newton_direction(ws, in, nref, &none);
    dopus_lai_axpy(NP, DOPUS_R(1.0), ws->d_prim, ws->prim);
    dopus_lai_axpy((N + 1) * NX, DOPUS_R(1.0), ws->d_lam, ws->lam);
    dopus_lai_axpy(NE, DOPUS_R(1.0), ws->d_nu, ws->nu);
}

/* Predictor (affine scaling): the Newton direction without centring, its step lengths
 * (*alpha_aff, primal; one length for both unless long_steps) and the average
 * complementarity mu_aff that step would reach, returned. */
static dopus_real qp_predictor(dopus_qp_workspace *ws, const dopus_qp_in *in, const qp_res *r, int long_steps,
                               dopus_real *alpha_aff)
{
    const qp_centring pred = {0, DOPUS_R(0.0), DOPUS_R(0.0)};
    dopus_real alpha, alpha_d, mu_aff = DOPUS_R(0.0);
    int i, full[2];
    newton_direction(ws, in, 0, &pred);
    max_steps(ws, &alpha, &alpha_d, full);
    if (!long_steps)
        alpha = alpha_d = dmin(alpha, alpha_d);
    *alpha_aff = alpha;
    i = 0;
#if QP_V4_STEPS
    /* the products of four rows per vector, summed in the loop's order (a side that does not
     * exist adds +0, which leaves every sum that starts at +0 as it is) */
    if (ws->nb >= 4) {
        const qp_v4 zero = {DOPUS_R(0.0), DOPUS_R(0.0), DOPUS_R(0.0), DOPUS_R(0.0)};
        for (; i + 4 <= ws->nb; i += 4) {
            qp_v4_rows r;
            qp_v4 pl, pu;
            dopus_real sl[4], su[4];
            int q;
            const qp_v4_bits mlo = qp_v4_mask(ws->has_lo + i), mup = qp_v4_mask(ws->has_up + i);
            qp_v4_load_rows(ws, i, &r);
            pl = (r.tl + alpha * (r.dv + (r.vl - r.tl))) * (r.zl + alpha_d * r.dzl);
            pu = (r.tu + alpha * ((r.uv - r.tu) - r.dv)) * (r.zu + alpha_d * r.dzu);
            pl = qp_v4_select(mlo, pl, zero);
            pu = qp_v4_select(mup, pu, zero);
            __builtin_memcpy(sl, &pl, sizeof sl);
            __builtin_memcpy(su, &pu, sizeof su);
            for (q = 0; q < 4; ++q) {
                mu_aff += sl[q];
                mu_aff += su[q];
            }
        }
    }
#endif
    for (; i < ws->nb; ++i) {
        if (ws->has_lo[i])
            mu_aff += (ws->t_lo[i] + alpha * dt_lo(ws, i)) * (ws->z_lo[i] + alpha_d * ws->dz_lo[i]);
        if (ws->has_up[i])
            mu_aff += (ws->t_up[i] + alpha * dt_up(ws, i)) * (ws->z_up[i] + alpha_d * ws->dz_up[i]);
        if (SOFT && ws->soft_lo[i] == 1)
            mu_aff += (ws->s_lo[i] + alpha * ws->ds_lo[i]) * (ws->y_lo[i] + alpha_d * ws->dy_lo[i]);
        if (SOFT && ws->soft_up[i] == 1)
            mu_aff += (ws->s_up[i] + alpha * ws->ds_up[i]) * (ws->y_up[i] + alpha_d * ws->dy_up[i]);
    }
    return mu_aff / r->nsides;
}

/* Centring parameter sigma = (mu_aff / mu)^3 (Mehrotra), with the floors below. */
static dopus_real qp_sigma(const qp_loop *L, const dopus_qp_workspace *ws, const qp_res *r, dopus_real mu_aff)
{
    dopus_real sigma = r->mu > DOPUS_R(0.0) ? mu_aff / r->mu : DOPUS_R(0.0);
    sigma = dmin(DOPUS_R(1.0), dmax(DOPUS_R(0.0), sigma * sigma * sigma));
    /* Nonconvex region: the barrier-augmented Hessian needed the inertia correction,
     * so the current barrier problem is not convex on the null space of the
     * equalities. Reducing mu there freezes the iterate in the wrong region (the
     * bounds that must become active to supply curvature keep tiny multipliers, and
     * the delta-shifted steps stall); keep mu nearly constant (a centring step)
     * until the barrier terms make the inertia right again. */
    if (ws->delta > DOPUS_R(0.0))
        sigma = dmax(sigma, SIGMA_NONCONVEX);
    return dmax(sigma, L->sigma_min);
}

/* Corrector: the direction towards the centring target sigma mu with Mehrotra's
 * second-order term, and its step lengths (*alpha primal, *alpha_d dual): up to the
 * boundary with the long steps, else one length, STEP_TAU of the way to the boundary. */
static void qp_corrector(qp_loop *L, dopus_qp_workspace *ws, const dopus_qp_in *in, const qp_res *r, int iter,
                         int nref, dopus_real sigma, int long_steps, dopus_real *alpha, dopus_real *alpha_d)
{
    qp_centring corr;
    int full[2];
    /* rc = t z + dt_aff dz_aff - target. The target is kept above a fraction of the
     * complementarity tolerance: driving mu far below what the termination test needs
     * only makes the barrier weights z/t of active rows huge, and their cancellation in
     * the Riccati recursion spoils the Newton directions. */
    corr.corrector = 1;
    corr.target = dmax(sigma * r->mu, MU_FLOOR_REL * L->st.tol * dmax(DOPUS_R(1.0), r->nz));
    /* safeguard: when complementarity is all that is left and the last step raised mu,
     * drop the second-order term this time (Mehrotra's corrector can otherwise cycle
     * on a pair far from the central path) */
    corr.eta = (iter > 0 && r->mu > L->mu_prev && dmax(r->stat_s, r->eq_s) < r->comp_s) ? DOPUS_R(0.0)
                                                                                        : DOPUS_R(1.0);
    L->mu_prev = r->mu;
    newton_direction(ws, in, nref, &corr);
    max_steps(ws, alpha, alpha_d, full);
    if (long_steps) {
        *alpha = step_to_boundary(*alpha, full[0]);
        *alpha_d = step_to_boundary(*alpha_d, full[1]);
    } else {
        *alpha = *alpha_d = STEP_TAU * dmin(*alpha, *alpha_d);
    }
}

/* The step: primal and slacks by alpha, multipliers by alpha_d. */
static void qp_take_step(dopus_qp_workspace *ws, dopus_real alpha, dopus_real alpha_d)
{
    int i;
    dopus_lai_axpy(NP, alpha, ws->d_prim, ws->prim);
    dopus_lai_axpy((N + 1) * NX, alpha_d, ws->d_lam, ws->lam);
    dopus_lai_axpy(NE, alpha_d, ws->d_nu, ws->nu);
    i = 0;
#if QP_V4_STEPS
    /* four rows per vector: a side that exists takes the loop's update, one that does not keeps
     * its entries */
    for (; i + 4 <= ws->nb; i += 4) {
        qp_v4_rows r;
        qp_v4 ntl, ntu, nzl, nzu;
        const qp_v4_bits mlo = qp_v4_mask(ws->has_lo + i), mup = qp_v4_mask(ws->has_up + i);
        qp_v4_load_rows(ws, i, &r);
        ntl = qp_v4_select(mlo, r.tl + alpha * (r.dv + (r.vl - r.tl)), r.tl);
        nzl = qp_v4_select(mlo, r.zl + alpha_d * r.dzl, r.zl);
        ntu = qp_v4_select(mup, r.tu + alpha * ((r.uv - r.tu) - r.dv), r.tu);
        nzu = qp_v4_select(mup, r.zu + alpha_d * r.dzu, r.zu);
        __builtin_memcpy(ws->t_lo + i, &ntl, sizeof ntl);
        __builtin_memcpy(ws->z_lo + i, &nzl, sizeof nzl);
        __builtin_memcpy(ws->t_up + i, &ntu, sizeof ntu);
        __builtin_memcpy(ws->z_up + i, &nzu, sizeof nzu);
    }
#endif
    for (; i < ws->nb; ++i) {
        if (ws->has_lo[i]) {
            ws->t_lo[i] += alpha * dt_lo(ws, i);
            ws->z_lo[i] += alpha_d * ws->dz_lo[i];
        }
        if (ws->has_up[i]) {
            ws->t_up[i] += alpha * dt_up(ws, i);
            ws->z_up[i] += alpha_d * ws->dz_up[i];
        }
        /* after t: its step reads s */
        if (SOFT && ws->soft_lo[i]) {
            ws->s_lo[i] += alpha * ws->ds_lo[i];
            ws->y_lo[i] += alpha_d * ws->dy_lo[i];
        }
        if (SOFT && ws->soft_up[i]) {
            ws->s_up[i] += alpha * ws->ds_up[i];
            ws->y_up[i] += alpha_d * ws->dy_up[i];
        }
    }
}

/* ---------------------------------------------------------------- the solve */

/* The result of a loop that stopped at iteration iter with status: the last iterate, or
 * the best one seen when the loop failed at a worse point (it is in *sol already; its
 * residuals are reported). */
/* The objective 1/2 w'(H + hess_shift I) w + g'w of the QP at the point in sol (evaluated
 * once, for the point reported, not at every iterate). */
static dopus_real qp_objective(const dopus_qp_in *in, const dopus_qp_sol *sol)
{
    dopus_real obj = DOPUS_R(0.0), w[NW], h[NW];
    int k, i;
    for (k = 0; k <= N; ++k) {
        const int nk = k < N ? NW : NX;
        for (i = 0; i < nk; ++i)
            w[i] = i < NX ? sol->x[k][i] : sol->u[k][i - NX];
        if (k < N)
            dopus_lai_symv_l(NW, DOPUS_R(1.0), in->H[k], NW, w, DOPUS_R(0.0), h);
        else
            dopus_lai_symv_l(NX, DOPUS_R(1.0), in->HN, NX, w, DOPUS_R(0.0), h);
        dopus_lai_axpy(nk, in->hess_shift, w, h);
        obj += DOPUS_R(0.5) * dopus_lai_dot(nk, w, h) + dopus_lai_dot(nk, k < N ? in->g[k] : in->gN, w);
    }
    return obj;
}

static int qp_result(const qp_loop *L, dopus_qp_workspace *ws, const dopus_qp_in *in, const qp_res *r,
                     int status, int iter, dopus_qp_sol *sol, dopus_qp_info *info)
{
    int keep_best;
    /* a failed factorisation or the iteration limit: the diverged dual iterate may prove
     * infeasibility as at a stall (qp_track_best) */
    if ((status == DOPUS_QP_NUMERICAL || status == DOPUS_QP_MAX_ITER || status == DOPUS_QP_DEADLINE) &&
        primal_infeasible_at_tol(ws, in, r, L->data_scale, L->st.tol))
        status = DOPUS_QP_PRIMAL_INFEASIBLE;
    keep_best = L->best_solved || ((status == DOPUS_QP_MAX_ITER || status == DOPUS_QP_STALLED ||
                                    status == DOPUS_QP_NUMERICAL || status == DOPUS_QP_DEADLINE) &&
                                   isfinite(L->best_merit) && !(merit(r) <= L->best_merit));
    if (info) {
        info->inertia_corrections = L->n_corr;
        info->terminal_augmentations = L->n_aug;
        info->pivot_floors = ws->pivot_floors;
        info->delta = L->delta_used;
        info->factorizations = ws->n_fact;
        info->prefactored = ws->n_pre;
        info->certified = status == DOPUS_QP_PRIMAL_INFEASIBLE && L->certified;
    }
    status = finish(ws, keep_best ? &L->best_r : r, status, iter, keep_best ? NULL : sol, info);
    if (info)
        info->obj = qp_objective(in, sol);
    return status;
}

/* ---------------------------------------------------------------- active-set start */

/* The penalty weight of an active row relative to the Hessian scale (a refinement step
 * contracts the error of the active multipliers by about 1 / (1 + AS_RHO) on a well-scaled
 * QP) and the refinement steps of one sweep at most. */
#define AS_RHO DOPUS_PREC(1e6, 1e3)
#define AS_REFINE 6
#define AS_DROP DOPUS_R(0.4)

/* |D_j|^2 of row j of stage k (k = N: the terminal rows). */
static dopus_real row_norm2(const dopus_qp_in *in, int k, int j)
{
    dopus_real s = DOPUS_R(0.0);
    int c;
    if (k < N) {
        if (NG == 0 || j < NW)
            return DOPUS_R(1.0);
        for (c = 0; c < NW; ++c)
            s += in->C[k][(j - NW) + c * NG] * in->C[k][(j - NW) + c * NG];
    } else {
        if (NR == 0 || j < NX)
            return DOPUS_R(1.0);
        for (c = 0; c < NX; ++c)
            s += in->R[(j - NX) + c * NR] * in->R[(j - NX) + c * NR];
    }
    return s;
}

/* The signed multiplier of bounded row b, kept in z_up (in z_lo for a row without an upper
 * side) as write_solution and compute_residuals read it; the slacks 0 on an active row (its
 * complementarity is exact), 1 on an inactive one (multiplier 0). */
static void as_set_mu(dopus_qp_workspace *ws, int b, dopus_real mu)
{
    ws->t_lo[b] = ws->t_up[b] = ws->act[b] ? DOPUS_R(0.0) : DOPUS_R(1.0);
    if (ws->has_up[b]) {
        ws->z_up[b] = mu;
        ws->z_lo[b] = DOPUS_R(0.0);
    } else {
        ws->z_lo[b] = -mu;
        ws->z_up[b] = DOPUS_R(0.0);
    }
}

static dopus_real as_mu(const dopus_qp_workspace *ws, int b)
{
    return ws->has_up[b] ? ws->z_up[b] : -ws->z_lo[b];
}

/* The equality residual v - bound of an active row (from vl, uv of compute_residuals), 0 for
 * an inactive one. */
static dopus_real as_res(const dopus_qp_workspace *ws, int b)
{
    return ws->act[b] == -1 ? ws->vl[b] : (ws->act[b] != 0 ? -ws->uv[b] : DOPUS_R(0.0));
}

/* The row values of row b moved by dv (its residuals vl, uv of compute_residuals). */
static void as_res_add(dopus_qp_workspace *ws, int b, dopus_real dv)
{
    if (ws->has_lo[b])
        ws->vl[b] += dv;
    if (ws->has_up[b])
        ws->uv[b] -= dv;
}

/* The guess from the warm-start point (the primal part in the iterate, the multipliers in
 * *sol): a side is active when its multiplier points to it and exceeds its slack, a row with
 * lo == up always. Returns 0 when a row has a soft side (the start does not apply). compare:
 * the factor a prefactor kept is discarded (pre_status -1) unless this guess has its active
 * rows with the same penalty weights (act and pen as the prefactor left them). */
static int as_guess(dopus_qp_workspace *ws, const dopus_qp_in *in, const dopus_qp_sol *sol, dopus_real hscale,
                    int compare)
{
    int k, b, j;
    for (k = 0; k <= N; ++k)
        FOR_STAGE_ROWS(ws, k, b, j)
        {
            const dopus_real mu = row_mu(sol, ws->bidx[b]);
            const dopus_real v = row_dot(in, k, j, ws->prim + k * NW);
            const int was = ws->act[b] != 0;
            const dopus_real pen_was = ws->pen[b];
            dopus_real lo, up;
            if (SOFT && (ws->soft_lo[b] || ws->soft_up[b]))
                return 0;
            row_bounds(in, ws->bidx[b], &lo, &up);
            ws->act[b] = 0;
            if (ws->has_lo[b] && ws->has_up[b] && lo == up)
                ws->act[b] = 2;
            else if (ws->has_up[b] && mu > DOPUS_R(0.0) && mu > up - v)
                ws->act[b] = 1;
            else if (ws->has_lo[b] && mu < DOPUS_R(0.0) && -mu > v - lo)
                ws->act[b] = -1;
            ws->pen[b] = AS_RHO * hscale / dmax(row_norm2(in, k, j), DOPUS_REAL_EPSILON);
            /* the kept factor's rows (act, pen as the prefactor left them): the factorisation
             * reads a row's weight only when it is active (row_q) */
            if (compare && (was != (ws->act[b] != 0) || (was && pen_was != ws->pen[b])))
                ws->pre_status = -1;
            as_set_mu(ws, b, ws->act[b] ? mu : DOPUS_R(0.0));
        }
    return 1;
}

/* The largest scaled equality residual of the active rows (from the last residuals). */
static dopus_real as_active_residual(const dopus_qp_workspace *ws)
{
    dopus_real ra = DOPUS_R(0.0);
    int b;
    for (b = 0; b < ws->nb; ++b)
        ra = dmax(ra, dopus_fabs(as_res(ws, b)));
    return ra / ws->scale_ineq;
}

/* The residuals of the iterate (into *r) and the largest scaled equality residual of the
 * active rows. */
static dopus_real as_residuals(dopus_qp_workspace *ws, const dopus_qp_in *in, qp_res *r)
{
    compute_residuals(ws, in, r);
    return as_active_residual(ws);
}

/* The stage k and row j within it of bounded row b. */
static void as_row(const dopus_qp_workspace *ws, int b, int *k, int *j)
{
    const int i = ws->bidx[b];
    *k = i < TOFF ? i / NSI : N;
    *j = i - *k * NSI;
}

/* 1 when the active row b is held by the Schur complement (added after the factorisation). */
static int as_updated(const dopus_qp_workspace *ws, int b)
{
    int i;
    for (i = 0; i < ws->as_n; ++i)
        if (ws->as_rows[i] == b)
            return 1;
    return 0;
}

/* The factorisation of a sweep with the penalty weights of all active rows (and the exact
 * terminal augmentation when a pivot fails). Returns 1 when it succeeded. */
static int as_factor(qp_loop *L, dopus_qp_workspace *ws, const dopus_qp_in *in)
{
    int fact;
    ws->as_n = 0;
    ws->delta = DOPUS_R(0.0);
    ws->rho_aug = DOPUS_R(0.0);
    if (L->st.prefactored && L->as_sweeps == 1 && ws->pre_status >= 0) {
        /* the first sweep: the factorisation a prefactor kept of this guess (as_guess compared
         * the working sets: riccati_factor with these rows' penalty weights, or with none) */
        ++ws->n_fact;
        ws->n_pre = 1;
        fact = ws->pre_status;
    } else {
        fact = riccati_factor(ws, in);
    }
    if (fact == 1 && NE > 0) {
        QP_TRACE("active set: terminal augmentation\n");
        fact = qp_augment_terminal(L, ws, in);
    }
    if (fact != 0)
        QP_TRACE("active set: factorisation failed\n");
    return fact == 0;
}

/* The rows added since the factorisation (ws->as_rows) held by its Schur complement instead of
 * a new factorisation: G_ij = D_i K^-1 D_j' (K the factored KKT matrix, D_i the row, one solve
 * per row) plus 1/pen_i on the diagonal, factored by Cholesky into ws->as_L. G is positive
 * semidefinite where the factorisation showed K convex on the null space of the equalities;
 * returns 0 when a pivot is not positive (then the sweep factors again). */
static int as_schur(dopus_qp_workspace *ws, const dopus_qp_in *in)
{
    const int n = ws->as_n;
    dopus_real *Lp = ws->as_L;
    int i, j, c, k, kj, ki, ji;
    for (j = 0; j < n; ++j) {
        for (i = 0; i < NP; ++i)
            ws->d_prim[i] = DOPUS_R(0.0);
        for (i = 0; i < (N + 1) * NX; ++i)
            ws->d_lam[i] = DOPUS_R(0.0);
        for (i = 0; i < NE; ++i)
            ws->d_nu[i] = DOPUS_R(0.0);
        as_row(ws, ws->as_rows[j], &k, &kj);
        row_axpy(in, k, kj, DOPUS_R(1.0), ws->d_prim + k * NW);
        riccati_solve(ws, in, ws->d_prim, ws->d_lam, ws->d_nu);
        for (i = j; i < n; ++i) {
            as_row(ws, ws->as_rows[i], &k, &ki);
            Lp[j * n - j * (j - 1) / 2 + (i - j)] = row_dot(in, k, ki, ws->d_prim + k * NW);
        }
        Lp[j * n - j * (j - 1) / 2] += DOPUS_R(1.0) / ws->pen[ws->as_rows[j]];
    }
    /* Cholesky in place (column j at offset j n - j (j - 1) / 2), reciprocal diagonal */
    for (j = 0; j < n; ++j) {
        dopus_real *cj = Lp + j * n - j * (j - 1) / 2;
        for (c = 0; c < j; ++c) {
            const dopus_real *cc = Lp + c * n - c * (c - 1) / 2;
            for (i = j; i < n; ++i)
                cj[i - j] -= cc[i - c] * cc[j - c];
        }
        if (!(cj[0] > DOPUS_R(0.0)))
            return 0;
        cj[0] = DOPUS_R(1.0) / dopus_sqrt(cj[0]);
        for (ji = 1; ji < n - j; ++ji)
            cj[ji] *= cj[0];
    }
    return 1;
}

/* e <- (L L')^-1 e with the packed factor of as_schur (reciprocal diagonal). */
static void as_schur_solve(const dopus_qp_workspace *ws, dopus_real *e)
{
    const int n = ws->as_n;
    const dopus_real *Lp = ws->as_L;
    int i, j;
    for (j = 0; j < n; ++j) {
        const dopus_real *cj = Lp + j * n - j * (j - 1) / 2;
        e[j] *= cj[0];
        for (i = j + 1; i < n; ++i)
            e[i] -= cj[i - j] * e[j];
    }
    for (j = n - 1; j >= 0; --j) {
        const dopus_real *cj = Lp + j * n - j * (j - 1) / 2;
        for (i = j + 1; i < n; ++i)
            e[j] -= cj[i - j] * e[i];
        e[j] *= cj[0];
    }
}

/* The residuals of compute_residuals moved with component j of w_k (k = N: of x_N) by dv:
 * H_k's column j (and the shift) into r_stat, the dynamics rows of x_k and x_{k+1} (Req for
 * x_N) and the values of the stage's bounded rows. */
static void as_move_var(dopus_qp_workspace *ws, const dopus_qp_in *in, int k, int j, dopus_real dv)
{
    const int ld = k < N ? NW : NX;
    const dopus_real *H = k < N ? in->H[k] : in->HN;
    dopus_real *rs = ws->r_stat + k * NW;
    int i, b, jj;
    for (i = 0; i < ld; ++i)
        rs[i] += (i >= j ? H[i + j * ld] : H[j + i * ld]) * dv;
    rs[j] += in->hess_shift * dv;
    if (j < NX)
        ws->r_dyn[k * NX + j] += dv;
    if (k < N) {
        for (i = 0; i < NX; ++i)
            ws->r_dyn[(k + 1) * NX + i] -= in->Phi[k][i + j * NX] * dv;
    } else {
        for (i = 0; i < NE; ++i)
            ws->r_eqN[i] += in->Req[i + j * NE1] * dv;
    }
    FOR_STAGE_ROWS(ws, k, b, jj)
    {
        dopus_real c;
        if (k < N)
            c = NG == 0 || jj < NW ? (jj == j ? DOPUS_R(1.0) : DOPUS_R(0.0)) : in->C[k][(jj - NW) + j * NG];
        else
            c = NR == 0 || jj < NX ? (jj == j ? DOPUS_R(1.0) : DOPUS_R(0.0)) : in->R[(jj - NX) + j * NR];
        if (c != DOPUS_R(0.0))
            as_res_add(ws, b, c * dv);
    }
}

/* Every active simple bound (a component of w_k or x_N) set to its bound exactly: before
 * each evaluation of the residuals (after a refinement step it is met to round-off), so
 * that the tests of a sweep and the answer are those of the iterate with its active bounds
 * met, and the answer's control lands on the bound exactly, as a clipped control would;
 * and (moved != 0) the bounds that joined the active set, with the residuals of the last
 * evaluation moved with them (as_move_var): their violation then enters the next step
 * through the stationarity and dynamics residuals instead of as the penalty weight times
 * it, whose round-off (1e-9 of the scale with AS_RHO 1e6) took a second refinement step. */
static void as_snap_bounds(dopus_qp_workspace *ws, const dopus_qp_in *in, int moved)
{
    int k, b, j;
    for (k = 0; k <= N; ++k)
        FOR_STAGE_ROWS(ws, k, b, j)
        {
            dopus_real lo, up, v;
            if (!ws->act[b] || (k < N && NG > 0 && j >= NW) || (k == N && NR > 0 && j >= NX))
                continue;
            row_bounds(in, ws->bidx[b], &lo, &up);
            v = ws->act[b] == -1 ? lo : up;
            if (moved && v != ws->prim[k * NW + j])
                as_move_var(ws, in, k, j, v - ws->prim[k * NW + j]);
            ws->prim[k * NW + j] = v;
        }
}

/* Refinement steps with the sweep's factor to the KKT point of the active set. Each step
 * solves (K + D_a' pen D_a) d = -r_stat - D_a' pen r_a, -r_dyn, -r_eqN over the rows a of the
 * factorisation and updates their multipliers by pen (D_a d + r_a) (the method of multipliers
 * with the factor kept); the multipliers of the rows added since (as_schur) move by their
 * Schur complement's answer to their residual after the step, G^-1 (D_s d + r_s), which the
 * next step's stationarity residual carries into the primal.
 *
 * The residuals are evaluated (compute_residuals, after the active simple bounds are set to
 * their bounds) before the first step and after every step, except where the step itself
 * gives them: known != 0 when the residual vectors of ws already hold those of the iterate
 * (the previous sweep's last evaluation, updated by as_update for the multipliers it set to
 * 0; the first step is then taken without a test), and after a step of a sweep with rows
 * held by the Schur complement that followed an evaluation: the step solves the linear
 * system, so the stationarity residual is D_s' G^-1 (D_s d + r_s), the dynamics and Req
 * residuals 0 and the active rows' values moved by D_a d (to round-off, which the
 * evaluation after the next step measures). Returns 1 when the evaluated residuals reached
 * tol (in *r), else 0. */
static int as_refine(qp_loop *L, dopus_qp_workspace *ws, const dopus_qp_in *in, qp_res *r, int known)
{
    int it, i, k, b, j, predicted = 0;
    dopus_real e[DOPUS_QP_AS_UPDATE];
    for (it = 0;; ++it) {
        int predict;
        if (!known) {
            dopus_real ra;
            as_snap_bounds(ws, in, 0);
            ra = as_residuals(ws, in, r);
            QP_TRACE("active set: refinement %d stat %.2e eq %.2e act %.2e ineq %.2e (%d rows updated)\n", it,
                     r->stat_s, r->eq_s, ra, r->ineq_s, ws->as_n);
            if (!(isfinite(r->stat) && isfinite(r->eq) && isfinite(ra)))
                return 0;
            if (r->stat_s <= L->st.tol && r->eq_s <= L->st.tol && ra <= L->st.tol)
                return 1;
        }
        if (it >= AS_REFINE)
            return 0;
        /* the residuals after this step from the step itself (see above) */
        predict = ws->as_n > 0 && !predicted;
        for (i = 0; i < NP; ++i)
            ws->d_prim[i] = -ws->r_stat[i];
        for (k = 0; k <= N; ++k)
            FOR_STAGE_ROWS(ws, k, b, j)
        if (ws->act[b] && !as_updated(ws, b))
            row_axpy(in, k, j, -ws->pen[b] * as_res(ws, b), ws->d_prim + k * NW);
        for (i = 0; i < (N + 1) * NX; ++i)
            ws->d_lam[i] = -ws->r_dyn[i];
        for (i = 0; i < NE; ++i)
            ws->d_nu[i] = -ws->r_eqN[i];
        riccati_solve(ws, in, ws->d_prim, ws->d_lam, ws->d_nu);
        for (i = 0; i < ws->as_n; ++i) {
            dopus_real dv;
            as_row(ws, ws->as_rows[i], &k, &j);
            dv = row_dot(in, k, j, ws->d_prim + k * NW);
            e[i] = dv + as_res(ws, ws->as_rows[i]);
            if (predict)
                as_res_add(ws, ws->as_rows[i], dv);
        }
        for (k = 0; k <= N; ++k)
            FOR_STAGE_ROWS(ws, k, b, j)
        if (ws->act[b] && !as_updated(ws, b)) {
            const dopus_real dv = row_dot(in, k, j, ws->d_prim + k * NW);
            as_set_mu(ws, b, as_mu(ws, b) + ws->pen[b] * (dv + as_res(ws, b)));
            if (predict)
                as_res_add(ws, b, dv);
        }
        if (ws->as_n > 0) {
            as_schur_solve(ws, e);
            for (i = 0; i < ws->as_n; ++i)
                as_set_mu(ws, ws->as_rows[i], as_mu(ws, ws->as_rows[i]) + e[i]);
        }
        dopus_lai_axpy(NP, DOPUS_R(1.0), ws->d_prim, ws->prim);
        dopus_lai_axpy((N + 1) * NX, DOPUS_R(1.0), ws->d_lam, ws->lam);
        dopus_lai_axpy(NE, DOPUS_R(1.0), ws->d_nu, ws->nu);
        if (predict) {
            for (i = 0; i < NP; ++i)
                ws->r_stat[i] = DOPUS_R(0.0);
            for (i = 0; i < (N + 1) * NX; ++i)
                ws->r_dyn[i] = DOPUS_R(0.0);
            for (i = 0; i < NE; ++i)
                ws->r_eqN[i] = DOPUS_R(0.0);
            for (i = 0; i < ws->as_n; ++i) {
                as_row(ws, ws->as_rows[i], &k, &j);
                row_axpy(in, k, j, e[i], ws->r_stat + k * NW);
            }
        }
        known = predicted = predict;
    }
}

/* The family of bounded row b: its row within the stage, or NSI + its terminal row (a
 * component of w_k or a path row of every stage is one family). */
#define AS_NFAM (NSI + NX + NR)
static int as_family(const dopus_qp_workspace *ws, int b)
{
    const int i = ws->bidx[b];
    return i < TOFF ? i - (i / NSI) * NSI : NSI + (i - TOFF);
}

static int as_wrong_sign(const dopus_qp_workspace *ws, int b, dopus_real mu)
{
    return (ws->act[b] == 1 && mu < DOPUS_R(0.0)) || (ws->act[b] == -1 && mu > DOPUS_R(0.0));
}

/* Multiplier mu of active row b set to 0, the stationarity residual r_stat of the last
 * evaluation updated by D_b' (0 - mu) (compute_residuals' A'y). */
static void as_zero_mu(dopus_qp_workspace *ws, const dopus_qp_in *in, int b, dopus_real mu)
{
    int k, j;
    as_row(ws, b, &k, &j);
    row_axpy(in, k, j, -mu, ws->r_stat + k * NW);
    as_set_mu(ws, b, DOPUS_R(0.0));
}

/* The checks of a refined sweep: an active multiplier of the wrong sign leaves the active
 * set when it is at least AS_DROP times the largest wrong one of its family (the others
 * wait for the next sweep; within tol times the multipliers' scale a multiplier is set to 0
 * and its row stays), and an inactive side violated beyond tol joins it. Returns 1 when the
 * active set changed; *zeroed: 1 when a multiplier was set to 0 and its row stays; *update: 1
 * when the change only added rows and they join those added since the factorisation
 * (ws->as_rows, DOPUS_QP_AS_UPDATE at most): the next sweep keeps the factor. The primal
 * iterate does not change: the residuals of the last evaluation stay those of the iterate
 * but for the multipliers set to 0 (as_zero_mu), and the next sweep starts from them
 * (as_refine's known). */
static int as_update(const qp_loop *L, dopus_qp_workspace *ws, const dopus_qp_in *in, int *zeroed,
                     int *update)
{
    dopus_real zscale = DOPUS_R(1.0), wrong[AS_NFAM];
    const dopus_real feas = L->st.tol * ws->scale_ineq;
    int b, changed = 0, dropped = 0, n_add = ws->as_n;
    for (b = 0; b < AS_NFAM; ++b)
        wrong[b] = DOPUS_R(0.0);
    for (b = 0; b < ws->nb; ++b) {
        const dopus_real mu = as_mu(ws, b);
        zscale = dmax(zscale, dopus_fabs(mu));
        if (as_wrong_sign(ws, b, mu))
            wrong[as_family(ws, b)] = dmax(wrong[as_family(ws, b)], dopus_fabs(mu));
    }
    zscale *= L->st.tol;
    *zeroed = 0;
    for (b = 0; b < ws->nb; ++b) {
        const dopus_real mu = as_mu(ws, b);
        if (as_wrong_sign(ws, b, mu)) {
            QP_TRACE("active set: row %d side %d multiplier %.3e\n", (int)ws->bidx[b], (int)ws->act[b], mu);
            if (dopus_fabs(mu) <= zscale) {
                as_zero_mu(ws, in, b, mu);
                *zeroed = 1;
            } else if (dopus_fabs(mu) >= AS_DROP * wrong[as_family(ws, b)]) {
                ws->act[b] = 0;
                changed = dropped = 1;
                as_zero_mu(ws, in, b, mu);
            } else {
                changed = dropped = 1; /* a wrong sign stays: this is no answer yet */
            }
        } else if (ws->act[b] == 0) {
            const int lo = ws->has_lo[b] && ws->vl[b] < -feas;
            const int up = ws->has_up[b] && ws->uv[b] < -feas;
            if (lo || up) {
                QP_TRACE("active set: row %d violated %.3e %.3e\n", (int)ws->bidx[b],
                         ws->has_lo[b] ? ws->vl[b] : 0.0, ws->has_up[b] ? ws->uv[b] : 0.0);
                ws->act[b] = (signed char)(lo ? -1 : 1);
                changed = 1;
                as_set_mu(ws, b, DOPUS_R(0.0));
                if (n_add < DOPUS_QP_AS_UPDATE)
                    ws->as_rows[n_add] = (dopus_qp_row)b;
                ++n_add;
            }
        }
    }
    *update = changed && !dropped && n_add <= DOPUS_QP_AS_UPDATE;
    if (*update)
        ws->as_n = n_add;
    return changed;
}

/* The active-set start (dopus_qp.h). Returns DOPUS_QP_SOLVED with the solution and info
 * written, or QP_GO_ON with the iterate set back to the warm start for the interior point. */
static int qp_active_set(qp_loop *L, dopus_qp_workspace *ws, const dopus_qp_in *in, dopus_qp_sol *sol,
                         dopus_qp_info *info)
{
    int solved = 0, zeroed, update = 0, known = 0, refined;
    qp_res r;
    if (!as_guess(ws, in, sol, L->hscale, L->st.prefactored && ws->pre_status >= 0))
        return QP_GO_ON;
    ws->penalty = 1;
    ws->as_n = 0;
    /* each sweep counts as an iteration of the solve (settings.max_iter) */
    while (L->as_sweeps < L->st.active_set && L->as_sweeps < L->st.max_iter && !solved) {
        if (qp_deadline_passed(L))
            break; /* the interior point stops at once with the warm start (its iterate 0) */
        ++L->as_sweeps;
        /* rows only added since the factorisation: its Schur complement, else (or when that
         * does not converge: from an evaluation) a new factorisation */
        if (update && as_schur(ws, in)) {
            refined = as_refine(L, ws, in, &r, known);
            known = 0;
        } else {
            refined = 0;
        }
        if (!refined && !(as_factor(L, ws, in) && as_refine(L, ws, in, &r, known)))
            break;
        known = as_update(L, ws, in, &zeroed, &update);
        if (known) {
            as_snap_bounds(ws, in, 1); /* the bounds that joined, from the last evaluation */
        } else {
            /* the residuals again after multipliers were set to 0 (else the iterate is the
             * sweep's, whose residuals r holds) */
            const dopus_real ra = zeroed ? as_residuals(ws, in, &r) : as_active_residual(ws);
            solved = merit(&r) <= L->st.tol && ra <= L->st.tol;
            if (!solved)
                break;
        }
    }
    ws->penalty = 0;
    ws->as_n = 0;
    ws->delta = DOPUS_R(0.0);
    ws->rho_aug = DOPUS_R(0.0);
    QP_TRACE("active set: %s after %d sweeps\n", solved ? "solved" : "not solved", L->as_sweeps);
    if (solved) {
        /* the iterate with its active simple bounds set, as evaluated in r */
        const int status = qp_result(L, ws, in, &r, DOPUS_QP_SOLVED, L->as_sweeps, sol, info);
        if (info)
            info->active_set = L->as_sweeps;
        return status;
    }
    initial_point(ws, in, &L->st, sol, 0);
    return QP_GO_ON;
}

int dopus_qp_prefactor(dopus_qp_workspace *ws, const dopus_qp_in *in, dopus_real tol, dopus_real roundoff)
{
    int k, fact;
    /* no bounded row (every weight 0), no correction, no augmentation */
    ws->nb = 0;
    for (k = 0; k < N + 2; ++k)
        ws->bstart[k] = 0;
    for (k = 0; k < DOPUS_QP_NB; ++k)
        ws->act[k] = 0; /* the working set the factor is kept for: no active row */
    ws->pre_rows = 0;
    factor_state_reset(ws, in, 1);
    ws->pre_tol = tol > DOPUS_REAL_TINY ? tol : DOPUS_REAL_TINY;
    ws->pre_roundoff = roundoff;
    fact = riccati_factor(ws, in);
    ws->pre_status = fact != 1 && ws->pre_roundoff >= DOPUS_R(0.0) ? fact : -1;
    ws->pre_tol = DOPUS_R(0.0);
    return fact != 1;
}

int dopus_qp_prefactor_guess(dopus_qp_workspace *ws, const dopus_qp_in *in, const dopus_qp_sol *sol)
{
    dopus_real hmax = DOPUS_R(0.0);
    int k, i, fact;
    ws->pre_status = -1;
    ws->pre_rows = 0;
    /* the Hessian scale of the solve (check_input's hmax) and its bounded rows */
    for (k = 0; k < N; ++k)
        if (in->H[k] == NULL || in->Phi[k] == NULL)
            return 0;
    if (in->HN == NULL || (NE > 0 && in->Req == NULL) || !hessians_absmax(in, &hmax) ||
        !(in->hess_shift >= DOPUS_R(0.0) && in->hess_shift < INFINITY) || setup_bounds(ws, in) != 0)
        return 0;
    factor_state_reset(ws, in, 1);
    ws->pre_tol = DOPUS_R(0.0);
    /* the warm start's primal part (as initial_point sets it), the guess of the active-set start */
    for (i = 0; i < NP; ++i)
        ws->prim[i] = DOPUS_R(0.0);
    warm_primal(ws, sol);
    if (!as_guess(ws, in, sol, hessian_scale(in, hmax), 0))
        return 0;
    /* as_factor's first sweep: the penalty weights of the active rows, no correction */
    ws->penalty = 1;
    ws->as_n = 0;
    fact = riccati_factor(ws, in);
    ws->penalty = 0;
    /* kept when it is the sweep's whole factorisation: no augmentation follows (a pivot
     * failed: status 1) and no pivot was floored (the solve's count starts at 0) */
    ws->pre_status = fact != 1 && ws->pivot_floors == 0 ? fact : -1;
    ws->pre_rows = 1;
    ws->pre_hmax = hmax;
    return ws->pre_status >= 0;
}

/* Mehrotra's predictor-corrector. Per iteration: the residuals and the stopping tests (with
 * the restarts on a stall), the factorisation with inertia correction, the predictor, the
 * centring parameter, the corrector and the step. */
int dopus_qp_solve(dopus_qp_workspace *ws, const dopus_qp_in *in, const dopus_qp_settings *settings,
                   dopus_qp_sol *sol, dopus_qp_info *info)
{
    qp_loop L;
    qp_res r;
    int iter, status = qp_prepare(&L, ws, in, settings, sol, info);

    if (status != QP_GO_ON)
        return status;
    if (L.st.warm_start && L.st.active_set > 0) {
        status = qp_active_set(&L, ws, in, sol, info);
        if (status != QP_GO_ON)
            return status;
    }
    for (iter = L.as_sweeps;; ++iter) {
        dopus_real alpha, alpha_d, alpha_aff, sigma;
        int floors_before, nref, corrections, fact;
        /* the long steps (separate primal and dual step lengths, up to the boundary) in the
         * first attempt from the centred start while the QP is convex (no correction) */
        const int long_steps = L.attempt == 0 && L.n_corr == 0 && L.n_aug == 0;

        compute_residuals(ws, in, &r);
        status = qp_stopping_tests(&L, ws, in, sol, &r, iter);
        if (status == QP_RESTARTED)
            continue;
        if (status != QP_GO_ON)
            break;
        if (qp_deadline_passed(&L)) {
            status = DOPUS_QP_DEADLINE;
            break;
        }
        trace_barrier_weights(ws, in, iter);

        floors_before = ws->pivot_floors;
        corrections = L.n_corr + L.n_aug;
#if QP_FUSE
        ws->fuse = r.nsides > 0; /* the predictor follows */
#endif
        fact = qp_factor_with_correction(&L, ws, in);
#if QP_FUSE
        ws->fuse = 0;
#endif
        if (fact != 0) {
            status = DOPUS_QP_NUMERICAL;
            break;
        }
        if (L.n_corr + L.n_aug > corrections && qp_certificate_at_failure(&L, ws, in, &r)) {
            status = DOPUS_QP_PRIMAL_INFEASIBLE;
            break;
        }
        nref = qp_refine_steps(&L, ws, &r, iter, floors_before);
        if (r.nsides == 0) {
            qp_newton_step(ws, in, nref);
            continue;
        }
        sigma = qp_sigma(&L, ws, &r, qp_predictor(ws, in, &r, long_steps, &alpha_aff));
        qp_corrector(&L, ws, in, &r, iter, nref, sigma, long_steps, &alpha, &alpha_d);
        QP_TRACE("it %2d mu %.2e stat %.2e eq %.2e ineq %.2e comp %.2e | a_aff %.3f sigma %.2e "
                 "alpha %.3e delta %.1e rho %.1e floors %d |dp| %.2e\n",
                 iter, r.mu, r.stat_s, r.eq_s, r.ineq_s, r.comp_s, alpha_aff, sigma, alpha, ws->delta,
                 ws->rho_aug, ws->pivot_floors - floors_before, dopus_lai_norm_inf(NP, ws->d_prim));
        (void)alpha_aff;
        qp_take_step(ws, alpha, alpha_d);
    }
    return qp_result(&L, ws, in, &r, status, iter, sol, info);
}

/* ---------------------------------------------------------------- infeasible row */

int dopus_qp_infeasible_row(const dopus_qp_workspace *ws, const dopus_qp_in *in, int *stage, int *row,
                            int *side)
{
    int i, flat = -1, s = 0;
    dopus_real lo, up, zmax = DOPUS_R(0.0);
    for (i = 0; i < ws->nb; ++i) {
        row_bounds(in, ws->bidx[i], &lo, &up);
        if (ws->has_lo[i] && ws->has_up[i] && lo > up && !(SOFT && (ws->soft_lo[i] || ws->soft_up[i]))) {
            zmax = INFINITY; /* the solve stopped before forming a certificate */
            flat = ws->bidx[i];
            s = 0;
            break;
        }
        if (ws->has_lo[i] && !(SOFT && ws->soft_lo[i]) && ws->z_lo[i] > zmax) {
            zmax = ws->z_lo[i];
            flat = ws->bidx[i];
            s = -1;
        }
        if (ws->has_up[i] && !(SOFT && ws->soft_up[i]) && ws->z_up[i] > zmax) {
            zmax = ws->z_up[i];
            flat = ws->bidx[i];
            s = 1;
        }
    }
    for (i = 0; i < NE; ++i) {
        if (dopus_fabs(ws->nu[i]) > zmax) {
            zmax = dopus_fabs(ws->nu[i]);
            flat = NI + i; /* after the inequality rows: terminal equality row i */
            s = ws->nu[i] > DOPUS_R(0.0) ? 1 : -1;
        }
    }
    if (flat < 0)
        return 0;
    *stage = flat < TOFF ? flat / NSI : N;
    *row = flat - *stage * NSI;
    *side = s;
    return 1;
}
