/* The DOPUS real-time iteration (docs/algorithm.md section 4; paper Algorithm 1).
 *
 * init: F and H of every stage at the guess. Per sampling instant:
 *   feedback: QP with the measured xhat0, full step, u_0 out;
 *   prepare:  shift (receding mode), F_k and rho_k (eq. 16) of every stage, fresh F/H of
 *             stage N-1 and the terminal node, fresh H for the M stages with the largest
 *             rho_k, the fresh stage-cost Hessian A_l of the other stages added to their
 *             A_dyn (cost_hessian fresh), regularisation of every fresh A, QP vectors with
 *             the adjoint-corrected gradient (eq. 12).
 * The order of operations is that of the contract, so that the Python reference and this
 * runtime produce the same iterates to round-off.
 */
#include <math.h>

#include "robot_arm_kkt.h"
#include "robot_arm_linalg.h"
#include "robot_arm_problem.h"
#include "robot_arm_solver.h"

#define ROBOT_ARM_MAGIC 0x444f5055 /* "DOPU" */
#define ROBOT_ARM_DEFAULT_QP_TOL 1e-10

/* ---- small helpers ------------------------------------------------------------------ */

static void robot_arm_copy(double *dst, const double *src, int n)
{
    int i;
    for (i = 0; i < n; ++i) {
        dst[i] = src[i];
    }
}

static void robot_arm_ensure_setup(robot_arm_solver *s)
{
    if (s->magic != ROBOT_ARM_MAGIC) {
        robot_arm_defaults(s);
    }
}

static int robot_arm_ret(robot_arm_solver *s, int status)
{
    s->status = status;
    return status;
}

/* ---- generic information ------------------------------------------------------------ */

size_t robot_arm_solver_sizeof(void)
{
    return sizeof(robot_arm_solver);
}

void robot_arm_get_dims(robot_arm_dims *dims)
{
    dims->N = ROBOT_ARM_N;
    dims->nx = ROBOT_ARM_NX;
    dims->nu = ROBOT_ARM_NU;
    dims->nw = ROBOT_ARM_NW;
    dims->np = ROBOT_ARM_NP;
    dims->ng = ROBOT_ARM_NG;
    dims->nr = ROBOT_ARM_NR;
    dims->ne = ROBOT_ARM_NE;
    dims->has_gn = ROBOT_ARM_HAS_GN;
    dims->has_nominal = ROBOT_ARM_HAS_NOMINAL;
}

const char *robot_arm_name(void)
{
    return ROBOT_ARM_NAME;
}

const char *robot_arm_status_string(int status)
{
    switch (status) {
    case ROBOT_ARM_OK:
        return "ok";
    case ROBOT_ARM_ERR_QP:
        return "the QP was not solved (no step taken)";
    case ROBOT_ARM_ERR_NONFINITE_INPUT:
        return "NaN or Inf in an input array";
    case ROBOT_ARM_ERR_NONFINITE_VALUE:
        return "a generated function returned NaN or Inf";
    case ROBOT_ARM_ERR_FUNCTION:
        return "a generated function reported failure";
    case ROBOT_ARM_ERR_INVALID_ARGUMENT:
        return "invalid argument";
    case ROBOT_ARM_ERR_NOT_INITIALIZED:
        return "the solver is not initialised (call init first)";
    case ROBOT_ARM_ERR_NOT_PREPARED:
        return "no prepared QP (call prepare after each feedback)";
    case ROBOT_ARM_ERR_NO_NOMINAL:
        return "the solver was generated without a nominal guess";
    case ROBOT_ARM_ERR_REGULARIZATION:
        return "the eigen-decomposition of a Hessian block did not converge";
    case ROBOT_ARM_ERR_ALREADY_PREPARED:
        return "already prepared (call feedback before the next prepare)";
    default:
        return "unknown status";
    }
}

void robot_arm_defaults(robot_arm_solver *s)
{
    int k, i;
    s->magic = ROBOT_ARM_MAGIC;
    s->initialized = 0;
    s->qp_ready = 0;
    s->prepare_due = 0;
    s->shifted = 0;
    s->status = ROBOT_ARM_OK;
    s->M = robot_arm_default_M < 0 ? 0 : (robot_arm_default_M > ROBOT_ARM_N - 1 ? ROBOT_ARM_N - 1 : robot_arm_default_M);
    s->mode = ROBOT_ARM_MODE_RECEDING;
    s->hessian = (robot_arm_default_hessian == ROBOT_ARM_HESSIAN_GAUSS_NEWTON && ROBOT_ARM_HAS_GN)
                     ? ROBOT_ARM_HESSIAN_GAUSS_NEWTON
                     : ROBOT_ARM_HESSIAN_EXACT;
    s->regularization = robot_arm_default_regularization;
    s->reg_eps = robot_arm_default_reg_eps;
    s->cost_hessian = robot_arm_default_cost_hessian ? 1 : 0;
    s->lm = (robot_arm_default_lm >= 0.0 && robot_arm_default_lm < INFINITY) ? robot_arm_default_lm : 0.0;
    robot_arm_qp_settings_default(&s->qp_settings);
    s->qp_settings.tol = ROBOT_ARM_DEFAULT_QP_TOL;
    s->qp_warm = 1;
    s->qp_cold_retry = 0;
    for (k = 0; k <= ROBOT_ARM_N; ++k) {
        for (i = 0; i < ROBOT_ARM_NP; ++i) {
            s->p[k][i] = robot_arm_p_default[i];
        }
    }
    for (i = 0; i < ROBOT_ARM_NX; ++i) {
        s->xhat0[i] = robot_arm_x0_default[i];
    }
    s->n_recomputed = 0;
    s->qp_status = 0;
    s->qp_iterations = 0;
    for (k = 0; k < ROBOT_ARM_N; ++k) {
        s->rho[k] = 0.0;
    }
    for (i = 0; i < 4; ++i) {
        s->kkt[i] = NAN;
    }
    robot_arm_timer_init(&s->timer);
}

/* ---- function evaluations ----------------------------------------------------------- */

/* F_k (eq. 14) at the current point into s->tmp_F (= gL + mu_b_k), s->tmp_phi, s->tmp_g. */
static int robot_arm_stage_F(robot_arm_solver *s, int k)
{
    double l = 0.0;
    int i;
    if (robot_arm_eval_stage_grad(s->x[k], s->u[k], s->p[k], s->lam[k + 1], s->mu_g[k], s->tmp_gL,
                              s->tmp_phi, &l, s->tmp_g, &s->fun_work) != 0) {
        return ROBOT_ARM_ERR_FUNCTION;
    }
    if (!robot_arm_lai_vec_finite(ROBOT_ARM_NW, s->tmp_gL) || !robot_arm_lai_vec_finite(ROBOT_ARM_NX, s->tmp_phi) ||
        !robot_arm_lai_vec_finite(ROBOT_ARM_NG, s->tmp_g) || !isfinite(l)) {
        return ROBOT_ARM_ERR_NONFINITE_VALUE;
    }
    for (i = 0; i < ROBOT_ARM_NW; ++i) {
        s->tmp_F[i] = s->tmp_gL[i] + s->mu_b[k][i];
    }
    return ROBOT_ARM_OK;
}

/* Regularise a fresh A block (algorithm.md section 5), timed as its own phase. */
static int robot_arm_regularize(robot_arm_solver *s, int n, double *A)
{
    double t0;
    int rc;
    if (s->regularization == ROBOT_ARM_REG_NONE) {
        return ROBOT_ARM_OK;
    }
    t0 = robot_arm_timer_now(&s->timer);
    rc = robot_arm_reg_apply(n, A, s->regularization, s->reg_eps, s->reg_work);
    robot_arm_timer_add(&s->timer, ROBOT_ARM_PHASE_REGULARIZATION, t0);
    return rc == 0 ? ROBOT_ARM_OK : ROBOT_ARM_ERR_REGULARIZATION;
}

/* The stage-cost Hessian A_l of stage k at the current point into s->tmp_Al. */
static int robot_arm_stage_Al(robot_arm_solver *s, int k)
{
    double t0 = robot_arm_timer_now(&s->timer);
    int rc = robot_arm_eval_stage_hess_cost(s->hessian, s->x[k], s->u[k], s->p[k], s->tmp_Al, &s->fun_work);
    robot_arm_timer_add(&s->timer, ROBOT_ARM_PHASE_HESSIANS, t0);
    if (rc != 0) {
        return ROBOT_ARM_ERR_FUNCTION;
    }
    return robot_arm_lai_vec_finite(ROBOT_ARM_NW * ROBOT_ARM_NW, s->tmp_Al) ? ROBOT_ARM_OK : ROBOT_ARM_ERR_NONFINITE_VALUE;
}

/* H_k (eq. 15) at the current point, A regularised, stored in stage k's slot with
 * A_dyn = A - A_l (unregularised). Evaluated into scratch first, so a failed evaluation
 * leaves the slot as it was. */
static int robot_arm_stage_H(robot_arm_solver *s, int k)
{
    robot_arm_stage_slot *slot;
    double t0 = robot_arm_timer_now(&s->timer);
    int rc, i;
    rc = robot_arm_eval_stage_hess(s->hessian, s->x[k], s->u[k], s->p[k], s->lam[k + 1], s->mu_g[k],
                               s->tmp_A, s->tmp_Phi, s->tmp_C, &s->fun_work);
    robot_arm_timer_add(&s->timer, ROBOT_ARM_PHASE_HESSIANS, t0);
    if (rc != 0) {
        return ROBOT_ARM_ERR_FUNCTION;
    }
    if (!robot_arm_lai_vec_finite(ROBOT_ARM_NW * ROBOT_ARM_NW, s->tmp_A) ||
        !robot_arm_lai_vec_finite(ROBOT_ARM_NX * ROBOT_ARM_NW, s->tmp_Phi) ||
        !robot_arm_lai_vec_finite(ROBOT_ARM_NG * ROBOT_ARM_NW, s->tmp_C)) {
        return ROBOT_ARM_ERR_NONFINITE_VALUE;
    }
    /* A_dyn = A - A_l, kept whatever cost_hessian is, so the setting may change at any time */
    rc = robot_arm_stage_Al(s, k);
    if (rc != ROBOT_ARM_OK) {
        return rc;
    }
    for (i = 0; i < ROBOT_ARM_NW * ROBOT_ARM_NW; ++i) {
        s->tmp_Al[i] = s->tmp_A[i] - s->tmp_Al[i];
    }
    rc = robot_arm_regularize(s, ROBOT_ARM_NW, s->tmp_A);
    if (rc != ROBOT_ARM_OK) {
        return rc;
    }
    slot = robot_arm_ring_stage(&s->ring, k);
    robot_arm_copy(slot->Ht, s->tmp_A, ROBOT_ARM_NW * ROBOT_ARM_NW);
    robot_arm_copy(slot->A_dyn, s->tmp_Al, ROBOT_ARM_NW * ROBOT_ARM_NW);
    robot_arm_copy(slot->Phit, s->tmp_Phi, ROBOT_ARM_NX * ROBOT_ARM_NW);
    robot_arm_copy(slot->Ct, s->tmp_C, ROBOT_ARM_NG * ROBOT_ARM_NW);
    return ROBOT_ARM_OK;
}

/* Terminal F: gL_N, E, r, r_eq at the current point. */
static int robot_arm_term_F(robot_arm_solver *s)
{
    double gL[ROBOT_ARM_NX], E = 0.0, r[ROBOT_ARM_DIM(ROBOT_ARM_NR)], r_eq[ROBOT_ARM_DIM(ROBOT_ARM_NE)];
    if (robot_arm_eval_term_grad(s->x[ROBOT_ARM_N], s->p[ROBOT_ARM_N], s->mu_r, s->nu, gL, &E, r, r_eq,
                             &s->fun_work) != 0) {
        return ROBOT_ARM_ERR_FUNCTION;
    }
    if (!robot_arm_lai_vec_finite(ROBOT_ARM_NX, gL) || !isfinite(E) || !robot_arm_lai_vec_finite(ROBOT_ARM_NR, r) ||
        !robot_arm_lai_vec_finite(ROBOT_ARM_NE, r_eq)) {
        return ROBOT_ARM_ERR_NONFINITE_VALUE;
    }
    robot_arm_copy(s->gL_N, gL, ROBOT_ARM_NX);
    s->E = E;
    robot_arm_copy(s->r, r, ROBOT_ARM_NR);
    robot_arm_copy(s->r_eq, r_eq, ROBOT_ARM_NE);
    return ROBOT_ARM_OK;
}

/* Terminal H: A_N (regularised), R, R_eq. */
static int robot_arm_term_H(robot_arm_solver *s)
{
    double R[ROBOT_ARM_DIM(ROBOT_ARM_NR) * ROBOT_ARM_NX], R_eq[ROBOT_ARM_DIM(ROBOT_ARM_NE) * ROBOT_ARM_NX];
    double t0 = robot_arm_timer_now(&s->timer);
    int rc;
    rc = robot_arm_eval_term_hess(s->hessian, s->x[ROBOT_ARM_N], s->p[ROBOT_ARM_N], s->mu_r, s->nu, s->tmp_A,
                              R, R_eq, &s->fun_work);
    robot_arm_timer_add(&s->timer, ROBOT_ARM_PHASE_HESSIANS, t0);
    if (rc != 0) {
        return ROBOT_ARM_ERR_FUNCTION;
    }
    if (!robot_arm_lai_vec_finite(ROBOT_ARM_NX * ROBOT_ARM_NX, s->tmp_A) ||
        !robot_arm_lai_vec_finite(ROBOT_ARM_NR * ROBOT_ARM_NX, R) || !robot_arm_lai_vec_finite(ROBOT_ARM_NE * ROBOT_ARM_NX, R_eq)) {
        return ROBOT_ARM_ERR_NONFINITE_VALUE;
    }
    rc = robot_arm_regularize(s, ROBOT_ARM_NX, s->tmp_A);
    if (rc != ROBOT_ARM_OK) {
        return rc;
    }
    robot_arm_copy(s->A_N, s->tmp_A, ROBOT_ARM_NX * ROBOT_ARM_NX);
    robot_arm_copy(s->R, R, ROBOT_ARM_NR * ROBOT_ARM_NX);
    robot_arm_copy(s->R_eq, R_eq, ROBOT_ARM_NE * ROBOT_ARM_NX);
    return ROBOT_ARM_OK;
}

/* ---- QP assembly (algorithm.md section 3) ------------------------------------------- */

static void robot_arm_assemble(robot_arm_solver *s)
{
    robot_arm_qp_in *in = &s->qp_in;
    int k, i, j;
    double t0 = robot_arm_timer_now(&s->timer);

    for (k = 0; k < ROBOT_ARM_N; ++k) {
        const robot_arm_stage_slot *slot = robot_arm_ring_stage_const(&s->ring, k);
        /* the QP reads the ring slots in place */
        in->H[k] = slot->Ht;
        in->Phi[k] = slot->Phit;
        in->C[k] = ROBOT_ARM_NG > 0 ? slot->Ct : 0;
        /* a_k = F_w,k + Phit_k' lam_{k+1} - Ct_k' mu_g_k - mu_b_k (eq. 12) */
        for (i = 0; i < ROBOT_ARM_NW; ++i) {
            double pl = 0.0, cm = 0.0;
            for (j = 0; j < ROBOT_ARM_NX; ++j) {
                pl += slot->Phit[j + i * ROBOT_ARM_NX] * s->lam[k + 1][j];
            }
            for (j = 0; j < ROBOT_ARM_NG; ++j) {
                cm += slot->Ct[j + i * ROBOT_ARM_DIM(ROBOT_ARM_NG)] * s->mu_g[k][j];
            }
            in->g[k][i] = slot->F_w[i] + pl - cm - s->mu_b[k][i];
        }
        /* dx_{k+1} = Phit_k dw_k + (phi_k - x_{k+1}) */
        for (i = 0; i < ROBOT_ARM_NX; ++i) {
            in->b[k][i] = slot->phi[i] - s->x[k + 1][i];
        }
        for (i = 0; i < ROBOT_ARM_NX; ++i) {
            /* x_0 is fixed by xhat0; the QP ignores the x part of stage 0 */
            in->lbw[k][i] = k == 0 ? -INFINITY : robot_arm_lbx[i] - s->x[k][i];
            in->ubw[k][i] = k == 0 ? INFINITY : robot_arm_ubx[i] - s->x[k][i];
        }
        for (i = 0; i < ROBOT_ARM_NU; ++i) {
            in->lbw[k][ROBOT_ARM_NX + i] = robot_arm_lbu[i] - s->u[k][i];
            in->ubw[k][ROBOT_ARM_NX + i] = robot_arm_ubu[i] - s->u[k][i];
        }
        for (i = 0; i < ROBOT_ARM_NG; ++i) {
            in->lg[k][i] = robot_arm_lg[i] - slot->g[i];
            in->ug[k][i] = robot_arm_ug[i] - slot->g[i];
        }
    }
    in->HN = s->A_N;
    in->R = ROBOT_ARM_NR > 0 ? s->R : 0;
    in->Req = ROBOT_ARM_NE > 0 ? s->R_eq : 0;
    /* a_N = gL_N - R' mu_r - R_eq' nu (= grad E) */
    for (i = 0; i < ROBOT_ARM_NX; ++i) {
        double rm = 0.0, en = 0.0;
        for (j = 0; j < ROBOT_ARM_NR; ++j) {
            rm += s->R[j + i * ROBOT_ARM_DIM(ROBOT_ARM_NR)] * s->mu_r[j];
        }
        for (j = 0; j < ROBOT_ARM_NE; ++j) {
            en += s->R_eq[j + i * ROBOT_ARM_DIM(ROBOT_ARM_NE)] * s->nu[j];
        }
        in->gN[i] = s->gL_N[i] - rm - en;
        in->lbxN[i] = robot_arm_lbx[i] - s->x[ROBOT_ARM_N][i];
        in->ubxN[i] = robot_arm_ubx[i] - s->x[ROBOT_ARM_N][i];
    }
    for (i = 0; i < ROBOT_ARM_NR; ++i) {
        in->lr[i] = robot_arm_lr[i] - s->r[i];
        in->ur[i] = robot_arm_ur[i] - s->r[i];
    }
    for (i = 0; i < ROBOT_ARM_NE; ++i) {
        in->req[i] = -s->r_eq[i];
    }
    robot_arm_timer_add(&s->timer, ROBOT_ARM_PHASE_ASSEMBLY, t0);
}

/* ---- init --------------------------------------------------------------------------- */

static void robot_arm_clear_timings(robot_arm_solver *s, int first, int last)
{
    int i;
    for (i = first; i <= last; ++i) {
        s->timer.t[i] = 0.0;
    }
}

/* F (stored as F_old) and H of every stage, terminal F and H, at the current iterate. */
static int robot_arm_linearize_all(robot_arm_solver *s)
{
    double t0;
    int k, rc;
    for (k = 0; k < ROBOT_ARM_N; ++k) {
        t0 = robot_arm_timer_now(&s->timer);
        rc = robot_arm_stage_F(s, k);
        robot_arm_timer_add(&s->timer, ROBOT_ARM_PHASE_GRADIENTS, t0);
        if (rc != ROBOT_ARM_OK) {
            return rc;
        }
        robot_arm_ring_store_F(robot_arm_ring_stage(&s->ring, k), s->tmp_F, s->tmp_phi, s->tmp_g);
        rc = robot_arm_stage_H(s, k);
        if (rc != ROBOT_ARM_OK) {
            return rc;
        }
    }
    t0 = robot_arm_timer_now(&s->timer);
    rc = robot_arm_term_F(s);
    robot_arm_timer_add(&s->timer, ROBOT_ARM_PHASE_GRADIENTS, t0);
    if (rc != ROBOT_ARM_OK) {
        return rc;
    }
    return robot_arm_term_H(s);
}

int robot_arm_init(robot_arm_solver *s, const double *xhat0, const double *x, const double *u,
               const double *lam, const double *mu_g, const double *mu_b, const double *mu_bN,
               const double *mu_r, const double *nu)
{
    int k, i, rc;

    robot_arm_ensure_setup(s);
    s->initialized = 0;
    s->qp_ready = 0;
    if ((xhat0 && !robot_arm_lai_vec_finite(ROBOT_ARM_NX, xhat0)) ||
        (x && !robot_arm_lai_vec_finite((ROBOT_ARM_N + 1) * ROBOT_ARM_NX, x)) ||
        (u && !robot_arm_lai_vec_finite(ROBOT_ARM_N * ROBOT_ARM_NU, u)) ||
        (lam && !robot_arm_lai_vec_finite((ROBOT_ARM_N + 1) * ROBOT_ARM_NX, lam)) ||
        (mu_g && !robot_arm_lai_vec_finite(ROBOT_ARM_N * ROBOT_ARM_NG, mu_g)) ||
        (mu_b && !robot_arm_lai_vec_finite(ROBOT_ARM_N * ROBOT_ARM_NW, mu_b)) ||
        (mu_bN && !robot_arm_lai_vec_finite(ROBOT_ARM_NX, mu_bN)) ||
        (mu_r && !robot_arm_lai_vec_finite(ROBOT_ARM_NR, mu_r)) || (nu && !robot_arm_lai_vec_finite(ROBOT_ARM_NE, nu))) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_NONFINITE_INPUT);
    }
    robot_arm_clear_timings(s, 0, ROBOT_ARM_N_PHASES - 1);

    for (i = 0; i < ROBOT_ARM_NX; ++i) {
        s->xhat0[i] = xhat0 ? xhat0[i] : robot_arm_x0_default[i];
    }
    for (k = 0; k <= ROBOT_ARM_N; ++k) {
        for (i = 0; i < ROBOT_ARM_NX; ++i) {
            s->x[k][i] = x ? x[k * ROBOT_ARM_NX + i] : robot_arm_guess_x[k][i];
            s->lam[k][i] = lam ? lam[k * ROBOT_ARM_NX + i] : 0.0;
        }
    }
    for (k = 0; k < ROBOT_ARM_N; ++k) {
        for (i = 0; i < ROBOT_ARM_NU; ++i) {
            s->u[k][i] = u ? u[k * ROBOT_ARM_NU + i] : robot_arm_guess_u[k][i];
        }
        for (i = 0; i < ROBOT_ARM_DIM(ROBOT_ARM_NG); ++i) {
            s->mu_g[k][i] = (mu_g && i < ROBOT_ARM_NG) ? mu_g[k * ROBOT_ARM_NG + i] : 0.0;
        }
        for (i = 0; i < ROBOT_ARM_NW; ++i) {
            s->mu_b[k][i] = mu_b ? mu_b[k * ROBOT_ARM_NW + i] : 0.0;
        }
        /* x_0 carries no bound: its multiplier is 0 by definition */
        if (k == 0) {
            for (i = 0; i < ROBOT_ARM_NX; ++i) {
                s->mu_b[0][i] = 0.0;
            }
        }
    }
    for (i = 0; i < ROBOT_ARM_NX; ++i) {
        s->mu_bN[i] = mu_bN ? mu_bN[i] : 0.0;
    }
    for (i = 0; i < ROBOT_ARM_DIM(ROBOT_ARM_NR); ++i) {
        s->mu_r[i] = (mu_r && i < ROBOT_ARM_NR) ? mu_r[i] : 0.0;
    }
    for (i = 0; i < ROBOT_ARM_DIM(ROBOT_ARM_NE); ++i) {
        s->nu[i] = (nu && i < ROBOT_ARM_NE) ? nu[i] : 0.0;
    }

    robot_arm_ring_reset(&s->ring);
    for (k = 0; k < ROBOT_ARM_N; ++k) {
        s->rho[k] = 0.0;
        s->recomputed[k] = k;
        s->selected[k] = 0;
    }
    s->n_recomputed = ROBOT_ARM_N;
    s->qp_status = 0;
    s->qp_iterations = 0;

    rc = robot_arm_linearize_all(s);
    if (rc != ROBOT_ARM_OK) {
        return robot_arm_ret(s, rc);
    }
    robot_arm_assemble(s);
    s->initialized = 1;
    s->qp_ready = 1;
    s->prepare_due = 0;
    s->shifted = 0;
    return robot_arm_ret(s, ROBOT_ARM_OK);
}

int robot_arm_init_nominal(robot_arm_solver *s, const double *xhat0)
{
#if ROBOT_ARM_HAS_NOMINAL
    return robot_arm_init(s, xhat0, &robot_arm_nominal_x[0][0], &robot_arm_nominal_u[0][0],
                      &robot_arm_nominal_lam[0][0], ROBOT_ARM_NG > 0 ? &robot_arm_nominal_mu_g[0][0] : 0,
                      &robot_arm_nominal_mu_b[0][0], robot_arm_nominal_mu_bN,
                      ROBOT_ARM_NR > 0 ? robot_arm_nominal_mu_r : 0, ROBOT_ARM_NE > 0 ? robot_arm_nominal_nu : 0);
#else
    (void)xhat0;
    robot_arm_ensure_setup(s);
    return robot_arm_ret(s, ROBOT_ARM_ERR_NO_NOMINAL);
#endif
}

/* ---- feedback ----------------------------------------------------------------------- */

static int robot_arm_qp_solution_finite(const robot_arm_qp_sol *sol)
{
    return robot_arm_lai_vec_finite((ROBOT_ARM_N + 1) * ROBOT_ARM_NX, &sol->x[0][0]) &&
           robot_arm_lai_vec_finite(ROBOT_ARM_N * ROBOT_ARM_QP_NU1, &sol->u[0][0]) &&
           robot_arm_lai_vec_finite((ROBOT_ARM_N + 1) * ROBOT_ARM_NX, &sol->lam[0][0]) &&
           robot_arm_lai_vec_finite(ROBOT_ARM_N * ROBOT_ARM_QP_NW, &sol->mu_b[0][0]) &&
           robot_arm_lai_vec_finite(ROBOT_ARM_NX, sol->mu_bN) &&
           robot_arm_lai_vec_finite(ROBOT_ARM_N * ROBOT_ARM_QP_NG1, &sol->mu_g[0][0]) &&
           robot_arm_lai_vec_finite(ROBOT_ARM_QP_NR1, sol->mu_r) && robot_arm_lai_vec_finite(ROBOT_ARM_QP_NE1, sol->nu);
}

/* Warm-start point of the QP (in s->qp_sol): the previous QP solution shifted with the
 * horizon. Its primal part has been added to the iterate, which prepare shifted, so it is
 * a zero step from the (shifted) iterate, with x_0's step fixed by the measurement; the
 * multipliers are the (shifted) iterate's, which are those of the previous QP. */
static void robot_arm_qp_warm_point(robot_arm_solver *s)
{
    robot_arm_qp_sol *w = &s->qp_sol;
    int k, i;
    for (k = 0; k <= ROBOT_ARM_N; ++k) {
        for (i = 0; i < ROBOT_ARM_NX; ++i) {
            w->x[k][i] = k == 0 ? s->qp_in.x0[i] : 0.0;
            w->lam[k][i] = s->lam[k][i];
        }
    }
    for (k = 0; k < ROBOT_ARM_N; ++k) {
        for (i = 0; i < ROBOT_ARM_QP_NU1; ++i) {
            w->u[k][i] = 0.0;
        }
        for (i = 0; i < ROBOT_ARM_NW; ++i) {
            w->mu_b[k][i] = s->mu_b[k][i];
        }
        for (i = 0; i < ROBOT_ARM_QP_NG1; ++i) {
            w->mu_g[k][i] = i < ROBOT_ARM_NG ? s->mu_g[k][i] : 0.0;
        }
    }
    for (i = 0; i < ROBOT_ARM_NX; ++i) {
        w->mu_bN[i] = s->mu_bN[i];
    }
    for (i = 0; i < ROBOT_ARM_QP_NR1; ++i) {
        w->mu_r[i] = i < ROBOT_ARM_NR ? s->mu_r[i] : 0.0;
    }
    for (i = 0; i < ROBOT_ARM_QP_NE1; ++i) {
        w->nu[i] = i < ROBOT_ARM_NE ? s->nu[i] : 0.0;
    }
}

int robot_arm_feedback(robot_arm_solver *s, const double *xhat0, double *u0)
{
    const robot_arm_qp_sol *sol = &s->qp_sol;
    double t0;
    int k, i, qs;

    robot_arm_ensure_setup(s);
    if (!s->initialized) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_NOT_INITIALIZED);
    }
    if (xhat0 == 0 || !robot_arm_lai_vec_finite(ROBOT_ARM_NX, xhat0)) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_NONFINITE_INPUT);
    }
    if (!s->qp_ready) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_NOT_PREPARED);
    }
    s->timer.t[ROBOT_ARM_PHASE_FEEDBACK] = 0.0;
    t0 = robot_arm_timer_now(&s->timer);

    for (i = 0; i < ROBOT_ARM_NX; ++i) {
        s->xhat0[i] = xhat0[i];
        s->qp_in.x0[i] = xhat0[i] - s->x[0][i];
    }
    /* the QP is attempted: a prepare (with its shift) is due, whatever the outcome */
    s->prepare_due = 1;
    s->shifted = 0;
    s->qp_in.hess_shift = s->lm;
    s->qp_cold_retry = 0;
    s->qp_settings.warm_start = s->qp_warm;
    if (s->qp_warm) {
        robot_arm_qp_warm_point(s);
    }
    qs = robot_arm_qp_solve(&s->qp_work, &s->qp_in, &s->qp_settings, &s->qp_sol, &s->qp_info);
    s->qp_iterations = s->qp_info.iterations;
    if (s->qp_warm && qs != ROBOT_ARM_QP_INVALID_INPUT &&
        (qs != ROBOT_ARM_QP_SOLVED || !robot_arm_qp_solution_finite(sol) || s->qp_info.inertia_corrections > 0)) {
        /* the warm start failed, or it needed the inertia correction: the QP is nonconvex
         * on the null space of its equalities there and may have several local minimisers,
         * and the warm start may have reached another one than the cold start finds (the
         * one the closed loop has followed so far): retry from the cold starting point in
         * the same call */
        s->qp_cold_retry = 1;
        s->qp_settings.warm_start = 0;
        qs = robot_arm_qp_solve(&s->qp_work, &s->qp_in, &s->qp_settings, &s->qp_sol, &s->qp_info);
        s->qp_iterations += s->qp_info.iterations;
    }
    s->qp_status = qs;
    if (qs != ROBOT_ARM_QP_SOLVED || !robot_arm_qp_solution_finite(sol)) {
        robot_arm_timer_add(&s->timer, ROBOT_ARM_PHASE_FEEDBACK, t0);
        return robot_arm_ret(s, ROBOT_ARM_ERR_QP);
    }

    /* domega_k = (dw_k, lam_QP_{k+1} - lam_{k+1}, mu_g_QP_k - mu_g_k, mu_b_QP_k - mu_b_k) */
    for (k = 0; k < ROBOT_ARM_N; ++k) {
        robot_arm_stage_slot *slot = robot_arm_ring_stage(&s->ring, k);
        for (i = 0; i < ROBOT_ARM_NX; ++i) {
            slot->dw[i] = sol->x[k][i];
            slot->dlam[i] = sol->lam[k + 1][i] - s->lam[k + 1][i];
        }
        for (i = 0; i < ROBOT_ARM_NU; ++i) {
            slot->dw[ROBOT_ARM_NX + i] = sol->u[k][i];
        }
        for (i = 0; i < ROBOT_ARM_NG; ++i) {
            slot->dmu_g[i] = sol->mu_g[k][i] - s->mu_g[k][i];
        }
        for (i = 0; i < ROBOT_ARM_NW; ++i) {
            slot->dmu_b[i] = sol->mu_b[k][i] - s->mu_b[k][i];
        }
    }
    /* the full step (paper eq. 4): w += dw, multipliers replaced by the QP's */
    for (k = 0; k <= ROBOT_ARM_N; ++k) {
        for (i = 0; i < ROBOT_ARM_NX; ++i) {
            s->x[k][i] += sol->x[k][i];
            s->lam[k][i] = sol->lam[k][i];
        }
    }
    for (k = 0; k < ROBOT_ARM_N; ++k) {
        for (i = 0; i < ROBOT_ARM_NU; ++i) {
            s->u[k][i] += sol->u[k][i];
        }
        for (i = 0; i < ROBOT_ARM_NG; ++i) {
            s->mu_g[k][i] = sol->mu_g[k][i];
        }
        for (i = 0; i < ROBOT_ARM_NW; ++i) {
            s->mu_b[k][i] = sol->mu_b[k][i];
        }
    }
    for (i = 0; i < ROBOT_ARM_NX; ++i) {
        s->mu_bN[i] = sol->mu_bN[i];
    }
    for (i = 0; i < ROBOT_ARM_NR; ++i) {
        s->mu_r[i] = sol->mu_r[i];
    }
    for (i = 0; i < ROBOT_ARM_NE; ++i) {
        s->nu[i] = sol->nu[i];
    }
    s->qp_ready = 0;
    if (u0) {
        for (i = 0; i < ROBOT_ARM_NU; ++i) {
            u0[i] = s->u[0][i];
        }
    }
    robot_arm_timer_add(&s->timer, ROBOT_ARM_PHASE_FEEDBACK, t0);
    return robot_arm_ret(s, ROBOT_ARM_OK);
}

/* ---- prepare ------------------------------------------------------------------------ */

/* Step 1 (receding mode): shift the iterate by one interval and advance ring_head.
 * x_N is set from phi_{N-1} in step 3. */
static void robot_arm_shift(robot_arm_solver *s)
{
    int k, i;
    for (k = 0; k < ROBOT_ARM_N; ++k) {
        for (i = 0; i < ROBOT_ARM_NX; ++i) {
            s->x[k][i] = s->x[k + 1][i];
            s->lam[k][i] = s->lam[k + 1][i];
        }
    }
    for (k = 0; k < ROBOT_ARM_N - 1; ++k) {
        for (i = 0; i < ROBOT_ARM_NU; ++i) {
            s->u[k][i] = s->u[k + 1][i];
        }
        for (i = 0; i < ROBOT_ARM_NG; ++i) {
            s->mu_g[k][i] = s->mu_g[k + 1][i];
        }
        for (i = 0; i < ROBOT_ARM_NW; ++i) {
            s->mu_b[k][i] = s->mu_b[k + 1][i];
        }
    }
    /* the last stage: the x part of mu_b from mu_bN, the u part kept */
    for (i = 0; i < ROBOT_ARM_NX; ++i) {
        s->mu_b[ROBOT_ARM_N - 1][i] = s->mu_bN[i];
        s->mu_b[0][i] = 0.0;
    }
    robot_arm_ring_advance(&s->ring);
}

/* Step 4: the M stages among 0..N-2 with the largest rho_k, ties to the lower index. */
static void robot_arm_select(robot_arm_solver *s, int M)
{
    int m, k, n = 0;
    for (k = 0; k < ROBOT_ARM_N; ++k) {
        s->selected[k] = 0;
    }
    for (m = 0; m < M; ++m) {
        int best = -1;
        for (k = 0; k < ROBOT_ARM_N - 1; ++k) {
            if (!s->selected[k] && (best < 0 || s->rho[k] > s->rho[best])) {
                best = k;
            }
        }
        if (best < 0) {
            break;
        }
        s->selected[best] = 1;
    }
    for (k = 0; k < ROBOT_ARM_N - 1; ++k) {
        if (s->selected[k]) {
            s->recomputed[n++] = k;
        }
    }
    s->recomputed[n++] = ROBOT_ARM_N - 1;
    s->n_recomputed = n;
}

int robot_arm_prepare(robot_arm_solver *s)
{
    double xN_saved[ROBOT_ARM_NX];
    double t0;
    int k, rc, M;

    robot_arm_ensure_setup(s);
    if (!s->initialized) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_NOT_INITIALIZED);
    }
    if (!s->prepare_due) {
        /* a second prepare would shift the horizon twice */
        return robot_arm_ret(s, ROBOT_ARM_ERR_ALREADY_PREPARED);
    }
    robot_arm_clear_timings(s, ROBOT_ARM_PHASE_SHIFT, ROBOT_ARM_PHASE_ASSEMBLY);
    s->qp_ready = 0;

    /* 1. shift (once per sampling instant: a retry after a failed prepare does not) */
    t0 = robot_arm_timer_now(&s->timer);
    if (s->mode == ROBOT_ARM_MODE_RECEDING && !s->shifted) {
        robot_arm_shift(s);
        s->shifted = 1;
    }
    t0 = robot_arm_timer_add(&s->timer, ROBOT_ARM_PHASE_SHIFT, t0);
    robot_arm_copy(xN_saved, s->x[ROBOT_ARM_N], ROBOT_ARM_NX);

    /* 2. F_k and rho_k (eq. 16) of stages 0..N-2 (F_new kept for step 6) */
    for (k = 0; k < ROBOT_ARM_N - 1; ++k) {
        robot_arm_stage_slot *slot = robot_arm_ring_stage(&s->ring, k);
        rc = robot_arm_stage_F(s, k);
        t0 = robot_arm_timer_add(&s->timer, ROBOT_ARM_PHASE_GRADIENTS, t0);
        if (rc != ROBOT_ARM_OK) {
            return robot_arm_ret(s, rc);
        }
        s->rho[k] = robot_arm_ring_secant(slot, s->tmp_F, s->tmp_phi, s->tmp_g);
        /* stored as F_old in step 6, once nothing can fail */
        robot_arm_copy(s->Fn_w[k], s->tmp_F, ROBOT_ARM_NW);
        robot_arm_copy(s->Fn_phi[k], s->tmp_phi, ROBOT_ARM_NX);
        robot_arm_copy(s->Fn_g[k], s->tmp_g, ROBOT_ARM_NG);
        t0 = robot_arm_timer_add(&s->timer, ROBOT_ARM_PHASE_RHO, t0);
    }

    /* 3. stage N-1 fresh; in receding mode x_N <- phi_{N-1} before the terminal node */
    rc = robot_arm_stage_F(s, ROBOT_ARM_N - 1);
    t0 = robot_arm_timer_add(&s->timer, ROBOT_ARM_PHASE_GRADIENTS, t0);
    if (rc != ROBOT_ARM_OK) {
        return robot_arm_ret(s, rc);
    }
    if (s->mode == ROBOT_ARM_MODE_RECEDING) {
        robot_arm_copy(s->x[ROBOT_ARM_N], s->tmp_phi, ROBOT_ARM_NX);
    }
    robot_arm_ring_store_F(robot_arm_ring_stage(&s->ring, ROBOT_ARM_N - 1), s->tmp_F, s->tmp_phi, s->tmp_g);
    s->rho[ROBOT_ARM_N - 1] = 0.0;
    rc = robot_arm_stage_H(s, ROBOT_ARM_N - 1);
    if (rc == ROBOT_ARM_OK) {
        t0 = robot_arm_timer_now(&s->timer);
        rc = robot_arm_term_F(s);
        robot_arm_timer_add(&s->timer, ROBOT_ARM_PHASE_GRADIENTS, t0);
    }
    if (rc == ROBOT_ARM_OK) {
        rc = robot_arm_term_H(s);
    }

    /* 4. re-linearise the M stages with the largest rho_k */
    if (rc == ROBOT_ARM_OK) {
        M = s->M < 0 ? 0 : (s->M > ROBOT_ARM_N - 1 ? ROBOT_ARM_N - 1 : s->M);
        robot_arm_select(s, M);
        for (k = 0; k < ROBOT_ARM_N - 1 && rc == ROBOT_ARM_OK; ++k) {
            if (s->selected[k]) {
                rc = robot_arm_stage_H(s, k);
            }
        }
    }

    /* 5. cost_hessian fresh: every stage whose H was not computed above gets
     *    Ht = reg(A_dyn + A_l) with A_l at the current point (Phit, Ct, A_dyn kept) */
    if (rc == ROBOT_ARM_OK && s->cost_hessian) {
        for (k = 0; k < ROBOT_ARM_N - 1 && rc == ROBOT_ARM_OK; ++k) {
            robot_arm_stage_slot *slot = robot_arm_ring_stage(&s->ring, k);
            int i;
            if (s->selected[k]) {
                continue;
            }
            rc = robot_arm_stage_Al(s, k);
            if (rc != ROBOT_ARM_OK) {
                break;
            }
            for (i = 0; i < ROBOT_ARM_NW * ROBOT_ARM_NW; ++i) {
                s->tmp_A[i] = slot->A_dyn[i] + s->tmp_Al[i];
            }
            rc = robot_arm_regularize(s, ROBOT_ARM_NW, s->tmp_A);
            if (rc == ROBOT_ARM_OK) {
                robot_arm_copy(slot->Ht, s->tmp_A, ROBOT_ARM_NW * ROBOT_ARM_NW);
            }
        }
    }
    if (rc != ROBOT_ARM_OK) {
        /* leave the iterate as it was after step 1 */
        robot_arm_copy(s->x[ROBOT_ARM_N], xN_saved, ROBOT_ARM_NX);
        return robot_arm_ret(s, rc);
    }

    /* 6. F_new of step 2 becomes F_old; QP vectors (the fresh A blocks were regularised
     *    when stored) */
    for (k = 0; k < ROBOT_ARM_N - 1; ++k) {
        robot_arm_ring_store_F(robot_arm_ring_stage(&s->ring, k), s->Fn_w[k], s->Fn_phi[k], s->Fn_g[k]);
    }
    robot_arm_assemble(s);
    s->qp_ready = 1;
    s->prepare_due = 0;
    s->shifted = 0;
    return robot_arm_ret(s, ROBOT_ARM_OK);
}

/* ---- KKT ---------------------------------------------------------------------------- */

int robot_arm_kkt_eval(robot_arm_solver *s, const double *xhat0, double *kkt4)
{
    double parts[4];
    double t0;
    int i, rc;

    robot_arm_ensure_setup(s);
    if (!s->initialized) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_NOT_INITIALIZED);
    }
    if (xhat0 && !robot_arm_lai_vec_finite(ROBOT_ARM_NX, xhat0)) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_NONFINITE_INPUT);
    }
    s->timer.t[ROBOT_ARM_PHASE_KKT] = 0.0;
    t0 = robot_arm_timer_now(&s->timer);
    rc = robot_arm_kkt_measure(s, xhat0 ? xhat0 : s->xhat0, parts);
    robot_arm_timer_add(&s->timer, ROBOT_ARM_PHASE_KKT, t0);
    if (rc != ROBOT_ARM_OK) {
        return robot_arm_ret(s, rc);
    }
    for (i = 0; i < 4; ++i) {
        s->kkt[i] = parts[i];
        if (kkt4) {
            kkt4[i] = parts[i];
        }
    }
    return robot_arm_ret(s, ROBOT_ARM_OK);
}

double robot_arm_get_kkt(const robot_arm_solver *s)
{
    double m = s->kkt[0];
    int i;
    for (i = 1; i < 4; ++i) {
        m = s->kkt[i] > m ? s->kkt[i] : m;
    }
    return m;
}

/* ---- settings ----------------------------------------------------------------------- */

int robot_arm_set_M(robot_arm_solver *s, int M)
{
    robot_arm_ensure_setup(s);
    if (M < 0 || M > ROBOT_ARM_N - 1) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_INVALID_ARGUMENT);
    }
    s->M = M;
    return robot_arm_ret(s, ROBOT_ARM_OK);
}

int robot_arm_get_M(robot_arm_solver *s)
{
    robot_arm_ensure_setup(s);
    return s->M;
}

int robot_arm_set_mode(robot_arm_solver *s, int mode)
{
    robot_arm_ensure_setup(s);
    if (mode != ROBOT_ARM_MODE_RECEDING && mode != ROBOT_ARM_MODE_FIXED) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_INVALID_ARGUMENT);
    }
    s->mode = mode;
    return robot_arm_ret(s, ROBOT_ARM_OK);
}

int robot_arm_get_mode(robot_arm_solver *s)
{
    robot_arm_ensure_setup(s);
    return s->mode;
}

int robot_arm_set_hessian(robot_arm_solver *s, int hessian)
{
    robot_arm_ensure_setup(s);
    if (hessian != ROBOT_ARM_HESSIAN_EXACT && hessian != ROBOT_ARM_HESSIAN_GAUSS_NEWTON) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_INVALID_ARGUMENT);
    }
    if (hessian == ROBOT_ARM_HESSIAN_GAUSS_NEWTON && !ROBOT_ARM_HAS_GN) {
        /* Gauss-Newton needs a least-squares stage cost */
        return robot_arm_ret(s, ROBOT_ARM_ERR_INVALID_ARGUMENT);
    }
    s->hessian = hessian;
    return robot_arm_ret(s, ROBOT_ARM_OK);
}

int robot_arm_get_hessian(robot_arm_solver *s)
{
    robot_arm_ensure_setup(s);
    return s->hessian;
}

int robot_arm_set_regularization(robot_arm_solver *s, int regularization, double eps)
{
    robot_arm_ensure_setup(s);
    if ((regularization != ROBOT_ARM_REG_NONE && regularization != ROBOT_ARM_REG_PROJECT &&
         regularization != ROBOT_ARM_REG_MIRROR) ||
        !isfinite(eps) || !(eps > 0.0)) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_INVALID_ARGUMENT);
    }
    s->regularization = regularization;
    s->reg_eps = eps;
    return robot_arm_ret(s, ROBOT_ARM_OK);
}

int robot_arm_get_regularization(robot_arm_solver *s)
{
    robot_arm_ensure_setup(s);
    return s->regularization;
}

double robot_arm_get_reg_eps(robot_arm_solver *s)
{
    robot_arm_ensure_setup(s);
    return s->reg_eps;
}

int robot_arm_set_cost_hessian(robot_arm_solver *s, int fresh)
{
    robot_arm_ensure_setup(s);
    if (fresh != 0 && fresh != 1) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_INVALID_ARGUMENT);
    }
    s->cost_hessian = fresh;
    return robot_arm_ret(s, ROBOT_ARM_OK);
}

int robot_arm_get_cost_hessian(robot_arm_solver *s)
{
    robot_arm_ensure_setup(s);
    return s->cost_hessian;
}

int robot_arm_set_levenberg_marquardt(robot_arm_solver *s, double lm)
{
    robot_arm_ensure_setup(s);
    if (!isfinite(lm) || !(lm >= 0.0)) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_INVALID_ARGUMENT);
    }
    s->lm = lm;
    return robot_arm_ret(s, ROBOT_ARM_OK);
}

double robot_arm_get_levenberg_marquardt(robot_arm_solver *s)
{
    robot_arm_ensure_setup(s);
    return s->lm;
}

int robot_arm_set_qp_tol(robot_arm_solver *s, double tol)
{
    robot_arm_ensure_setup(s);
    if (!isfinite(tol) || !(tol > 0.0)) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_INVALID_ARGUMENT);
    }
    s->qp_settings.tol = tol;
    return robot_arm_ret(s, ROBOT_ARM_OK);
}

double robot_arm_get_qp_tol(robot_arm_solver *s)
{
    robot_arm_ensure_setup(s);
    return s->qp_settings.tol;
}

int robot_arm_set_qp_max_iter(robot_arm_solver *s, int max_iter)
{
    robot_arm_ensure_setup(s);
    if (max_iter < 1) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_INVALID_ARGUMENT);
    }
    s->qp_settings.max_iter = max_iter;
    return robot_arm_ret(s, ROBOT_ARM_OK);
}

int robot_arm_get_qp_max_iter(robot_arm_solver *s)
{
    robot_arm_ensure_setup(s);
    return s->qp_settings.max_iter;
}

int robot_arm_set_qp_warm_start(robot_arm_solver *s, int on)
{
    robot_arm_ensure_setup(s);
    if (on != 0 && on != 1) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_INVALID_ARGUMENT);
    }
    s->qp_warm = on;
    return robot_arm_ret(s, ROBOT_ARM_OK);
}

int robot_arm_get_qp_warm_start(robot_arm_solver *s)
{
    robot_arm_ensure_setup(s);
    return s->qp_warm;
}

int robot_arm_get_qp_cold_retry(const robot_arm_solver *s)
{
    return s->qp_cold_retry;
}

int robot_arm_set_parameters(robot_arm_solver *s, const double *p)
{
    int k, i;
    robot_arm_ensure_setup(s);
    if (ROBOT_ARM_NP == 0) {
        return robot_arm_ret(s, ROBOT_ARM_OK);
    }
    if (p == 0) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_INVALID_ARGUMENT);
    }
    if (!robot_arm_lai_vec_finite((ROBOT_ARM_N + 1) * ROBOT_ARM_NP, p)) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_NONFINITE_INPUT);
    }
    for (k = 0; k <= ROBOT_ARM_N; ++k) {
        for (i = 0; i < ROBOT_ARM_NP; ++i) {
            s->p[k][i] = p[k * ROBOT_ARM_NP + i];
        }
    }
    return robot_arm_ret(s, ROBOT_ARM_OK);
}

int robot_arm_set_parameters_node(robot_arm_solver *s, int k, const double *pk)
{
    int i;
    robot_arm_ensure_setup(s);
    if (k < 0 || k > ROBOT_ARM_N) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_INVALID_ARGUMENT);
    }
    if (ROBOT_ARM_NP == 0) {
        return robot_arm_ret(s, ROBOT_ARM_OK);
    }
    if (pk == 0) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_INVALID_ARGUMENT);
    }
    if (!robot_arm_lai_vec_finite(ROBOT_ARM_NP, pk)) {
        return robot_arm_ret(s, ROBOT_ARM_ERR_NONFINITE_INPUT);
    }
    for (i = 0; i < ROBOT_ARM_NP; ++i) {
        s->p[k][i] = pk[i];
    }
    return robot_arm_ret(s, ROBOT_ARM_OK);
}

void robot_arm_get_parameters(robot_arm_solver *s, double *p)
{
    int k, i;
    robot_arm_ensure_setup(s);
    for (k = 0; k <= ROBOT_ARM_N; ++k) {
        for (i = 0; i < ROBOT_ARM_NP; ++i) {
            p[k * ROBOT_ARM_NP + i] = s->p[k][i];
        }
    }
}

/* ---- getters ------------------------------------------------------------------------ */

void robot_arm_get_x(const robot_arm_solver *s, double *x)
{
    robot_arm_copy(x, &s->x[0][0], (ROBOT_ARM_N + 1) * ROBOT_ARM_NX);
}

void robot_arm_get_u(const robot_arm_solver *s, double *u)
{
    robot_arm_copy(u, &s->u[0][0], ROBOT_ARM_N * ROBOT_ARM_NU);
}

void robot_arm_get_lam(const robot_arm_solver *s, double *lam)
{
    robot_arm_copy(lam, &s->lam[0][0], (ROBOT_ARM_N + 1) * ROBOT_ARM_NX);
}

void robot_arm_get_mu_g(const robot_arm_solver *s, double *mu_g)
{
    int k, i;
    for (k = 0; k < ROBOT_ARM_N; ++k) {
        for (i = 0; i < ROBOT_ARM_NG; ++i) {
            mu_g[k * ROBOT_ARM_NG + i] = s->mu_g[k][i];
        }
    }
}

void robot_arm_get_mu_b(const robot_arm_solver *s, double *mu_b)
{
    robot_arm_copy(mu_b, &s->mu_b[0][0], ROBOT_ARM_N * ROBOT_ARM_NW);
}

void robot_arm_get_mu_bN(const robot_arm_solver *s, double *mu_bN)
{
    robot_arm_copy(mu_bN, s->mu_bN, ROBOT_ARM_NX);
}

void robot_arm_get_mu_r(const robot_arm_solver *s, double *mu_r)
{
    robot_arm_copy(mu_r, s->mu_r, ROBOT_ARM_NR);
}

void robot_arm_get_nu(const robot_arm_solver *s, double *nu)
{
    robot_arm_copy(nu, s->nu, ROBOT_ARM_NE);
}

void robot_arm_get_rho(const robot_arm_solver *s, double *rho)
{
    robot_arm_copy(rho, s->rho, ROBOT_ARM_N);
}

int robot_arm_get_recomputed(const robot_arm_solver *s, int *stages)
{
    int i;
    for (i = 0; i < s->n_recomputed; ++i) {
        stages[i] = s->recomputed[i];
    }
    return s->n_recomputed;
}

int robot_arm_get_qp_iterations(const robot_arm_solver *s)
{
    return s->qp_iterations;
}

int robot_arm_get_qp_status(const robot_arm_solver *s)
{
    return s->qp_status;
}

int robot_arm_get_status(const robot_arm_solver *s)
{
    return s->status;
}

int robot_arm_is_initialized(const robot_arm_solver *s)
{
    return s->magic == ROBOT_ARM_MAGIC && s->initialized;
}

int robot_arm_get_ring_head(const robot_arm_solver *s)
{
    return s->ring.ring_head;
}

void robot_arm_get_timings(const robot_arm_solver *s, double *t)
{
    robot_arm_copy(t, s->timer.t, ROBOT_ARM_N_PHASES);
}

void robot_arm_set_clock(robot_arm_solver *s, double (*clock_fn)(void *ctx), void *ctx)
{
    robot_arm_ensure_setup(s);
    s->timer.clock = clock_fn ? clock_fn : robot_arm_timer_default_clock;
    s->timer.ctx = clock_fn ? ctx : 0;
}

int robot_arm_has_clock(const robot_arm_solver *s)
{
    if (s->timer.clock == 0) {
        return 0;
    }
    return s->timer.clock != robot_arm_timer_default_clock || robot_arm_timer_has_default_clock();
}
