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

#include "unicycle_kkt.h"
#include "unicycle_linalg.h"
#include "unicycle_problem.h"
#include "unicycle_solver.h"

#define UNICYCLE_MAGIC 0x444f5055 /* "DOPU" */
#define UNICYCLE_DEFAULT_QP_TOL 1e-10

/* ---- small helpers ------------------------------------------------------------------ */

static void unicycle_copy(double *dst, const double *src, int n)
{
    int i;
    for (i = 0; i < n; ++i) {
        dst[i] = src[i];
    }
}

static void unicycle_ensure_setup(unicycle_solver *s)
{
    if (s->magic != UNICYCLE_MAGIC) {
        unicycle_defaults(s);
    }
}

static int unicycle_ret(unicycle_solver *s, int status)
{
    s->status = status;
    return status;
}

/* ---- generic information ------------------------------------------------------------ */

size_t unicycle_solver_sizeof(void)
{
    return sizeof(unicycle_solver);
}

void unicycle_get_dims(unicycle_dims *dims)
{
    dims->N = UNICYCLE_N;
    dims->nx = UNICYCLE_NX;
    dims->nu = UNICYCLE_NU;
    dims->nw = UNICYCLE_NW;
    dims->np = UNICYCLE_NP;
    dims->ng = UNICYCLE_NG;
    dims->nr = UNICYCLE_NR;
    dims->ne = UNICYCLE_NE;
    dims->has_gn = UNICYCLE_HAS_GN;
    dims->has_nominal = UNICYCLE_HAS_NOMINAL;
}

const char *unicycle_name(void)
{
    return UNICYCLE_NAME;
}

const char *unicycle_status_string(int status)
{
    switch (status) {
    case UNICYCLE_OK:
        return "ok";
    case UNICYCLE_ERR_QP:
        return "the QP was not solved (no step taken)";
    case UNICYCLE_ERR_NONFINITE_INPUT:
        return "NaN or Inf in an input array";
    case UNICYCLE_ERR_NONFINITE_VALUE:
        return "a generated function returned NaN or Inf";
    case UNICYCLE_ERR_FUNCTION:
        return "a generated function reported failure";
    case UNICYCLE_ERR_INVALID_ARGUMENT:
        return "invalid argument";
    case UNICYCLE_ERR_NOT_INITIALIZED:
        return "the solver is not initialised (call init first)";
    case UNICYCLE_ERR_NOT_PREPARED:
        return "no prepared QP (call prepare after each feedback)";
    case UNICYCLE_ERR_NO_NOMINAL:
        return "the solver was generated without a nominal guess";
    case UNICYCLE_ERR_REGULARIZATION:
        return "the eigen-decomposition of a Hessian block did not converge";
    case UNICYCLE_ERR_ALREADY_PREPARED:
        return "already prepared (call feedback before the next prepare)";
    default:
        return "unknown status";
    }
}

void unicycle_defaults(unicycle_solver *s)
{
    int k, i;
    s->magic = UNICYCLE_MAGIC;
    s->initialized = 0;
    s->qp_ready = 0;
    s->prepare_due = 0;
    s->shifted = 0;
    s->status = UNICYCLE_OK;
    s->M = unicycle_default_M < 0 ? 0 : (unicycle_default_M > UNICYCLE_N - 1 ? UNICYCLE_N - 1 : unicycle_default_M);
    s->mode = UNICYCLE_MODE_RECEDING;
    s->hessian = (unicycle_default_hessian == UNICYCLE_HESSIAN_GAUSS_NEWTON && UNICYCLE_HAS_GN)
                     ? UNICYCLE_HESSIAN_GAUSS_NEWTON
                     : UNICYCLE_HESSIAN_EXACT;
    s->regularization = unicycle_default_regularization;
    s->reg_eps = unicycle_default_reg_eps;
    s->cost_hessian = unicycle_default_cost_hessian ? 1 : 0;
    s->lm = (unicycle_default_lm >= 0.0 && unicycle_default_lm < INFINITY) ? unicycle_default_lm : 0.0;
    unicycle_qp_settings_default(&s->qp_settings);
    s->qp_settings.tol = UNICYCLE_DEFAULT_QP_TOL;
    s->qp_warm = 1;
    s->qp_cold_retry = 0;
    for (k = 0; k <= UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NP; ++i) {
            s->p[k][i] = unicycle_p_default[i];
        }
    }
    for (i = 0; i < UNICYCLE_NX; ++i) {
        s->xhat0[i] = unicycle_x0_default[i];
    }
    s->n_recomputed = 0;
    s->qp_status = 0;
    s->qp_iterations = 0;
    for (k = 0; k < UNICYCLE_N; ++k) {
        s->rho[k] = 0.0;
    }
    for (i = 0; i < 4; ++i) {
        s->kkt[i] = NAN;
    }
    unicycle_timer_init(&s->timer);
}

/* ---- function evaluations ----------------------------------------------------------- */

/* F_k (eq. 14) at the current point into s->tmp_F (= gL + mu_b_k), s->tmp_phi, s->tmp_g. */
static int unicycle_stage_F(unicycle_solver *s, int k)
{
    double l = 0.0;
    int i;
    if (unicycle_eval_stage_grad(s->x[k], s->u[k], s->p[k], s->lam[k + 1], s->mu_g[k], s->tmp_gL,
                              s->tmp_phi, &l, s->tmp_g, &s->fun_work) != 0) {
        return UNICYCLE_ERR_FUNCTION;
    }
    if (!unicycle_lai_vec_finite(UNICYCLE_NW, s->tmp_gL) || !unicycle_lai_vec_finite(UNICYCLE_NX, s->tmp_phi) ||
        !unicycle_lai_vec_finite(UNICYCLE_NG, s->tmp_g) || !isfinite(l)) {
        return UNICYCLE_ERR_NONFINITE_VALUE;
    }
    for (i = 0; i < UNICYCLE_NW; ++i) {
        s->tmp_F[i] = s->tmp_gL[i] + s->mu_b[k][i];
    }
    return UNICYCLE_OK;
}

/* Regularise a fresh A block (algorithm.md section 5), timed as its own phase. */
static int unicycle_regularize(unicycle_solver *s, int n, double *A)
{
    double t0;
    int rc;
    if (s->regularization == UNICYCLE_REG_NONE) {
        return UNICYCLE_OK;
    }
    t0 = unicycle_timer_now(&s->timer);
    rc = unicycle_reg_apply(n, A, s->regularization, s->reg_eps, s->reg_work);
    unicycle_timer_add(&s->timer, UNICYCLE_PHASE_REGULARIZATION, t0);
    return rc == 0 ? UNICYCLE_OK : UNICYCLE_ERR_REGULARIZATION;
}

/* The stage-cost Hessian A_l of stage k at the current point into s->tmp_Al. */
static int unicycle_stage_Al(unicycle_solver *s, int k)
{
    double t0 = unicycle_timer_now(&s->timer);
    int rc = unicycle_eval_stage_hess_cost(s->hessian, s->x[k], s->u[k], s->p[k], s->tmp_Al, &s->fun_work);
    unicycle_timer_add(&s->timer, UNICYCLE_PHASE_HESSIANS, t0);
    if (rc != 0) {
        return UNICYCLE_ERR_FUNCTION;
    }
    return unicycle_lai_vec_finite(UNICYCLE_NW * UNICYCLE_NW, s->tmp_Al) ? UNICYCLE_OK : UNICYCLE_ERR_NONFINITE_VALUE;
}

/* H_k (eq. 15) at the current point, A regularised, stored in stage k's slot with
 * A_dyn = A - A_l (unregularised). Evaluated into scratch first, so a failed evaluation
 * leaves the slot as it was. */
static int unicycle_stage_H(unicycle_solver *s, int k)
{
    unicycle_stage_slot *slot;
    double t0 = unicycle_timer_now(&s->timer);
    int rc, i;
    rc = unicycle_eval_stage_hess(s->hessian, s->x[k], s->u[k], s->p[k], s->lam[k + 1], s->mu_g[k],
                               s->tmp_A, s->tmp_Phi, s->tmp_C, &s->fun_work);
    unicycle_timer_add(&s->timer, UNICYCLE_PHASE_HESSIANS, t0);
    if (rc != 0) {
        return UNICYCLE_ERR_FUNCTION;
    }
    if (!unicycle_lai_vec_finite(UNICYCLE_NW * UNICYCLE_NW, s->tmp_A) ||
        !unicycle_lai_vec_finite(UNICYCLE_NX * UNICYCLE_NW, s->tmp_Phi) ||
        !unicycle_lai_vec_finite(UNICYCLE_NG * UNICYCLE_NW, s->tmp_C)) {
        return UNICYCLE_ERR_NONFINITE_VALUE;
    }
    /* A_dyn = A - A_l, kept whatever cost_hessian is, so the setting may change at any time */
    rc = unicycle_stage_Al(s, k);
    if (rc != UNICYCLE_OK) {
        return rc;
    }
    for (i = 0; i < UNICYCLE_NW * UNICYCLE_NW; ++i) {
        s->tmp_Al[i] = s->tmp_A[i] - s->tmp_Al[i];
    }
    rc = unicycle_regularize(s, UNICYCLE_NW, s->tmp_A);
    if (rc != UNICYCLE_OK) {
        return rc;
    }
    slot = unicycle_ring_stage(&s->ring, k);
    unicycle_copy(slot->Ht, s->tmp_A, UNICYCLE_NW * UNICYCLE_NW);
    unicycle_copy(slot->A_dyn, s->tmp_Al, UNICYCLE_NW * UNICYCLE_NW);
    unicycle_copy(slot->Phit, s->tmp_Phi, UNICYCLE_NX * UNICYCLE_NW);
    unicycle_copy(slot->Ct, s->tmp_C, UNICYCLE_NG * UNICYCLE_NW);
    return UNICYCLE_OK;
}

/* Terminal F: gL_N, E, r, r_eq at the current point. */
static int unicycle_term_F(unicycle_solver *s)
{
    double gL[UNICYCLE_NX], E = 0.0, r[UNICYCLE_DIM(UNICYCLE_NR)], r_eq[UNICYCLE_DIM(UNICYCLE_NE)];
    if (unicycle_eval_term_grad(s->x[UNICYCLE_N], s->p[UNICYCLE_N], s->mu_r, s->nu, gL, &E, r, r_eq,
                             &s->fun_work) != 0) {
        return UNICYCLE_ERR_FUNCTION;
    }
    if (!unicycle_lai_vec_finite(UNICYCLE_NX, gL) || !isfinite(E) || !unicycle_lai_vec_finite(UNICYCLE_NR, r) ||
        !unicycle_lai_vec_finite(UNICYCLE_NE, r_eq)) {
        return UNICYCLE_ERR_NONFINITE_VALUE;
    }
    unicycle_copy(s->gL_N, gL, UNICYCLE_NX);
    s->E = E;
    unicycle_copy(s->r, r, UNICYCLE_NR);
    unicycle_copy(s->r_eq, r_eq, UNICYCLE_NE);
    return UNICYCLE_OK;
}

/* Terminal H: A_N (regularised), R, R_eq. */
static int unicycle_term_H(unicycle_solver *s)
{
    double R[UNICYCLE_DIM(UNICYCLE_NR) * UNICYCLE_NX], R_eq[UNICYCLE_DIM(UNICYCLE_NE) * UNICYCLE_NX];
    double t0 = unicycle_timer_now(&s->timer);
    int rc;
    rc = unicycle_eval_term_hess(s->hessian, s->x[UNICYCLE_N], s->p[UNICYCLE_N], s->mu_r, s->nu, s->tmp_A,
                              R, R_eq, &s->fun_work);
    unicycle_timer_add(&s->timer, UNICYCLE_PHASE_HESSIANS, t0);
    if (rc != 0) {
        return UNICYCLE_ERR_FUNCTION;
    }
    if (!unicycle_lai_vec_finite(UNICYCLE_NX * UNICYCLE_NX, s->tmp_A) ||
        !unicycle_lai_vec_finite(UNICYCLE_NR * UNICYCLE_NX, R) || !unicycle_lai_vec_finite(UNICYCLE_NE * UNICYCLE_NX, R_eq)) {
        return UNICYCLE_ERR_NONFINITE_VALUE;
    }
    rc = unicycle_regularize(s, UNICYCLE_NX, s->tmp_A);
    if (rc != UNICYCLE_OK) {
        return rc;
    }
    unicycle_copy(s->A_N, s->tmp_A, UNICYCLE_NX * UNICYCLE_NX);
    unicycle_copy(s->R, R, UNICYCLE_NR * UNICYCLE_NX);
    unicycle_copy(s->R_eq, R_eq, UNICYCLE_NE * UNICYCLE_NX);
    return UNICYCLE_OK;
}

/* ---- QP assembly (algorithm.md section 3) ------------------------------------------- */

static void unicycle_assemble(unicycle_solver *s)
{
    unicycle_qp_in *in = &s->qp_in;
    int k, i, j;
    double t0 = unicycle_timer_now(&s->timer);

    for (k = 0; k < UNICYCLE_N; ++k) {
        const unicycle_stage_slot *slot = unicycle_ring_stage_const(&s->ring, k);
        /* the QP reads the ring slots in place */
        in->H[k] = slot->Ht;
        in->Phi[k] = slot->Phit;
        in->C[k] = UNICYCLE_NG > 0 ? slot->Ct : 0;
        /* a_k = F_w,k + Phit_k' lam_{k+1} - Ct_k' mu_g_k - mu_b_k (eq. 12) */
        for (i = 0; i < UNICYCLE_NW; ++i) {
            double pl = 0.0, cm = 0.0;
            for (j = 0; j < UNICYCLE_NX; ++j) {
                pl += slot->Phit[j + i * UNICYCLE_NX] * s->lam[k + 1][j];
            }
            for (j = 0; j < UNICYCLE_NG; ++j) {
                cm += slot->Ct[j + i * UNICYCLE_DIM(UNICYCLE_NG)] * s->mu_g[k][j];
            }
            in->g[k][i] = slot->F_w[i] + pl - cm - s->mu_b[k][i];
        }
        /* dx_{k+1} = Phit_k dw_k + (phi_k - x_{k+1}) */
        for (i = 0; i < UNICYCLE_NX; ++i) {
            in->b[k][i] = slot->phi[i] - s->x[k + 1][i];
        }
        for (i = 0; i < UNICYCLE_NX; ++i) {
            /* x_0 is fixed by xhat0; the QP ignores the x part of stage 0 */
            in->lbw[k][i] = k == 0 ? -INFINITY : unicycle_lbx[i] - s->x[k][i];
            in->ubw[k][i] = k == 0 ? INFINITY : unicycle_ubx[i] - s->x[k][i];
        }
        for (i = 0; i < UNICYCLE_NU; ++i) {
            in->lbw[k][UNICYCLE_NX + i] = unicycle_lbu[i] - s->u[k][i];
            in->ubw[k][UNICYCLE_NX + i] = unicycle_ubu[i] - s->u[k][i];
        }
        for (i = 0; i < UNICYCLE_NG; ++i) {
            in->lg[k][i] = unicycle_lg[i] - slot->g[i];
            in->ug[k][i] = unicycle_ug[i] - slot->g[i];
        }
    }
    in->HN = s->A_N;
    in->R = UNICYCLE_NR > 0 ? s->R : 0;
    in->Req = UNICYCLE_NE > 0 ? s->R_eq : 0;
    /* a_N = gL_N - R' mu_r - R_eq' nu (= grad E) */
    for (i = 0; i < UNICYCLE_NX; ++i) {
        double rm = 0.0, en = 0.0;
        for (j = 0; j < UNICYCLE_NR; ++j) {
            rm += s->R[j + i * UNICYCLE_DIM(UNICYCLE_NR)] * s->mu_r[j];
        }
        for (j = 0; j < UNICYCLE_NE; ++j) {
            en += s->R_eq[j + i * UNICYCLE_DIM(UNICYCLE_NE)] * s->nu[j];
        }
        in->gN[i] = s->gL_N[i] - rm - en;
        in->lbxN[i] = unicycle_lbx[i] - s->x[UNICYCLE_N][i];
        in->ubxN[i] = unicycle_ubx[i] - s->x[UNICYCLE_N][i];
    }
    for (i = 0; i < UNICYCLE_NR; ++i) {
        in->lr[i] = unicycle_lr[i] - s->r[i];
        in->ur[i] = unicycle_ur[i] - s->r[i];
    }
    for (i = 0; i < UNICYCLE_NE; ++i) {
        in->req[i] = -s->r_eq[i];
    }
    unicycle_timer_add(&s->timer, UNICYCLE_PHASE_ASSEMBLY, t0);
}

/* ---- init --------------------------------------------------------------------------- */

static void unicycle_clear_timings(unicycle_solver *s, int first, int last)
{
    int i;
    for (i = first; i <= last; ++i) {
        s->timer.t[i] = 0.0;
    }
}

/* F (stored as F_old) and H of every stage, terminal F and H, at the current iterate. */
static int unicycle_linearize_all(unicycle_solver *s)
{
    double t0;
    int k, rc;
    for (k = 0; k < UNICYCLE_N; ++k) {
        t0 = unicycle_timer_now(&s->timer);
        rc = unicycle_stage_F(s, k);
        unicycle_timer_add(&s->timer, UNICYCLE_PHASE_GRADIENTS, t0);
        if (rc != UNICYCLE_OK) {
            return rc;
        }
        unicycle_ring_store_F(unicycle_ring_stage(&s->ring, k), s->tmp_F, s->tmp_phi, s->tmp_g);
        rc = unicycle_stage_H(s, k);
        if (rc != UNICYCLE_OK) {
            return rc;
        }
    }
    t0 = unicycle_timer_now(&s->timer);
    rc = unicycle_term_F(s);
    unicycle_timer_add(&s->timer, UNICYCLE_PHASE_GRADIENTS, t0);
    if (rc != UNICYCLE_OK) {
        return rc;
    }
    return unicycle_term_H(s);
}

int unicycle_init(unicycle_solver *s, const double *xhat0, const double *x, const double *u,
               const double *lam, const double *mu_g, const double *mu_b, const double *mu_bN,
               const double *mu_r, const double *nu)
{
    int k, i, rc;

    unicycle_ensure_setup(s);
    s->initialized = 0;
    s->qp_ready = 0;
    if ((xhat0 && !unicycle_lai_vec_finite(UNICYCLE_NX, xhat0)) ||
        (x && !unicycle_lai_vec_finite((UNICYCLE_N + 1) * UNICYCLE_NX, x)) ||
        (u && !unicycle_lai_vec_finite(UNICYCLE_N * UNICYCLE_NU, u)) ||
        (lam && !unicycle_lai_vec_finite((UNICYCLE_N + 1) * UNICYCLE_NX, lam)) ||
        (mu_g && !unicycle_lai_vec_finite(UNICYCLE_N * UNICYCLE_NG, mu_g)) ||
        (mu_b && !unicycle_lai_vec_finite(UNICYCLE_N * UNICYCLE_NW, mu_b)) ||
        (mu_bN && !unicycle_lai_vec_finite(UNICYCLE_NX, mu_bN)) ||
        (mu_r && !unicycle_lai_vec_finite(UNICYCLE_NR, mu_r)) || (nu && !unicycle_lai_vec_finite(UNICYCLE_NE, nu))) {
        return unicycle_ret(s, UNICYCLE_ERR_NONFINITE_INPUT);
    }
    unicycle_clear_timings(s, 0, UNICYCLE_N_PHASES - 1);

    for (i = 0; i < UNICYCLE_NX; ++i) {
        s->xhat0[i] = xhat0 ? xhat0[i] : unicycle_x0_default[i];
    }
    for (k = 0; k <= UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NX; ++i) {
            s->x[k][i] = x ? x[k * UNICYCLE_NX + i] : unicycle_guess_x[k][i];
            s->lam[k][i] = lam ? lam[k * UNICYCLE_NX + i] : 0.0;
        }
    }
    for (k = 0; k < UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NU; ++i) {
            s->u[k][i] = u ? u[k * UNICYCLE_NU + i] : unicycle_guess_u[k][i];
        }
        for (i = 0; i < UNICYCLE_DIM(UNICYCLE_NG); ++i) {
            s->mu_g[k][i] = (mu_g && i < UNICYCLE_NG) ? mu_g[k * UNICYCLE_NG + i] : 0.0;
        }
        for (i = 0; i < UNICYCLE_NW; ++i) {
            s->mu_b[k][i] = mu_b ? mu_b[k * UNICYCLE_NW + i] : 0.0;
        }
        /* x_0 carries no bound: its multiplier is 0 by definition */
        if (k == 0) {
            for (i = 0; i < UNICYCLE_NX; ++i) {
                s->mu_b[0][i] = 0.0;
            }
        }
    }
    for (i = 0; i < UNICYCLE_NX; ++i) {
        s->mu_bN[i] = mu_bN ? mu_bN[i] : 0.0;
    }
    for (i = 0; i < UNICYCLE_DIM(UNICYCLE_NR); ++i) {
        s->mu_r[i] = (mu_r && i < UNICYCLE_NR) ? mu_r[i] : 0.0;
    }
    for (i = 0; i < UNICYCLE_DIM(UNICYCLE_NE); ++i) {
        s->nu[i] = (nu && i < UNICYCLE_NE) ? nu[i] : 0.0;
    }

    unicycle_ring_reset(&s->ring);
    for (k = 0; k < UNICYCLE_N; ++k) {
        s->rho[k] = 0.0;
        s->recomputed[k] = k;
        s->selected[k] = 0;
    }
    s->n_recomputed = UNICYCLE_N;
    s->qp_status = 0;
    s->qp_iterations = 0;

    rc = unicycle_linearize_all(s);
    if (rc != UNICYCLE_OK) {
        return unicycle_ret(s, rc);
    }
    unicycle_assemble(s);
    s->initialized = 1;
    s->qp_ready = 1;
    s->prepare_due = 0;
    s->shifted = 0;
    return unicycle_ret(s, UNICYCLE_OK);
}

int unicycle_init_nominal(unicycle_solver *s, const double *xhat0)
{
#if UNICYCLE_HAS_NOMINAL
    return unicycle_init(s, xhat0, &unicycle_nominal_x[0][0], &unicycle_nominal_u[0][0],
                      &unicycle_nominal_lam[0][0], UNICYCLE_NG > 0 ? &unicycle_nominal_mu_g[0][0] : 0,
                      &unicycle_nominal_mu_b[0][0], unicycle_nominal_mu_bN,
                      UNICYCLE_NR > 0 ? unicycle_nominal_mu_r : 0, UNICYCLE_NE > 0 ? unicycle_nominal_nu : 0);
#else
    (void)xhat0;
    unicycle_ensure_setup(s);
    return unicycle_ret(s, UNICYCLE_ERR_NO_NOMINAL);
#endif
}

/* ---- feedback ----------------------------------------------------------------------- */

static int unicycle_qp_solution_finite(const unicycle_qp_sol *sol)
{
    return unicycle_lai_vec_finite((UNICYCLE_N + 1) * UNICYCLE_NX, &sol->x[0][0]) &&
           unicycle_lai_vec_finite(UNICYCLE_N * UNICYCLE_QP_NU1, &sol->u[0][0]) &&
           unicycle_lai_vec_finite((UNICYCLE_N + 1) * UNICYCLE_NX, &sol->lam[0][0]) &&
           unicycle_lai_vec_finite(UNICYCLE_N * UNICYCLE_QP_NW, &sol->mu_b[0][0]) &&
           unicycle_lai_vec_finite(UNICYCLE_NX, sol->mu_bN) &&
           unicycle_lai_vec_finite(UNICYCLE_N * UNICYCLE_QP_NG1, &sol->mu_g[0][0]) &&
           unicycle_lai_vec_finite(UNICYCLE_QP_NR1, sol->mu_r) && unicycle_lai_vec_finite(UNICYCLE_QP_NE1, sol->nu);
}

/* Warm-start point of the QP (in s->qp_sol): the previous QP solution shifted with the
 * horizon. Its primal part has been added to the iterate, which prepare shifted, so it is
 * a zero step from the (shifted) iterate, with x_0's step fixed by the measurement; the
 * multipliers are the (shifted) iterate's, which are those of the previous QP. */
static void unicycle_qp_warm_point(unicycle_solver *s)
{
    unicycle_qp_sol *w = &s->qp_sol;
    int k, i;
    for (k = 0; k <= UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NX; ++i) {
            w->x[k][i] = k == 0 ? s->qp_in.x0[i] : 0.0;
            w->lam[k][i] = s->lam[k][i];
        }
    }
    for (k = 0; k < UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_QP_NU1; ++i) {
            w->u[k][i] = 0.0;
        }
        for (i = 0; i < UNICYCLE_NW; ++i) {
            w->mu_b[k][i] = s->mu_b[k][i];
        }
        for (i = 0; i < UNICYCLE_QP_NG1; ++i) {
            w->mu_g[k][i] = i < UNICYCLE_NG ? s->mu_g[k][i] : 0.0;
        }
    }
    for (i = 0; i < UNICYCLE_NX; ++i) {
        w->mu_bN[i] = s->mu_bN[i];
    }
    for (i = 0; i < UNICYCLE_QP_NR1; ++i) {
        w->mu_r[i] = i < UNICYCLE_NR ? s->mu_r[i] : 0.0;
    }
    for (i = 0; i < UNICYCLE_QP_NE1; ++i) {
        w->nu[i] = i < UNICYCLE_NE ? s->nu[i] : 0.0;
    }
}

int unicycle_feedback(unicycle_solver *s, const double *xhat0, double *u0)
{
    const unicycle_qp_sol *sol = &s->qp_sol;
    double t0;
    int k, i, qs;

    unicycle_ensure_setup(s);
    if (!s->initialized) {
        return unicycle_ret(s, UNICYCLE_ERR_NOT_INITIALIZED);
    }
    if (xhat0 == 0 || !unicycle_lai_vec_finite(UNICYCLE_NX, xhat0)) {
        return unicycle_ret(s, UNICYCLE_ERR_NONFINITE_INPUT);
    }
    if (!s->qp_ready) {
        return unicycle_ret(s, UNICYCLE_ERR_NOT_PREPARED);
    }
    s->timer.t[UNICYCLE_PHASE_FEEDBACK] = 0.0;
    t0 = unicycle_timer_now(&s->timer);

    for (i = 0; i < UNICYCLE_NX; ++i) {
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
        unicycle_qp_warm_point(s);
    }
    qs = unicycle_qp_solve(&s->qp_work, &s->qp_in, &s->qp_settings, &s->qp_sol, &s->qp_info);
    s->qp_iterations = s->qp_info.iterations;
    if (s->qp_warm && qs != UNICYCLE_QP_INVALID_INPUT &&
        (qs != UNICYCLE_QP_SOLVED || !unicycle_qp_solution_finite(sol) || s->qp_info.inertia_corrections > 0)) {
        /* the warm start failed, or it needed the inertia correction: the QP is nonconvex
         * on the null space of its equalities there and may have several local minimisers,
         * and the warm start may have reached another one than the cold start finds (the
         * one the closed loop has followed so far): retry from the cold starting point in
         * the same call */
        s->qp_cold_retry = 1;
        s->qp_settings.warm_start = 0;
        qs = unicycle_qp_solve(&s->qp_work, &s->qp_in, &s->qp_settings, &s->qp_sol, &s->qp_info);
        s->qp_iterations += s->qp_info.iterations;
    }
    s->qp_status = qs;
    if (qs != UNICYCLE_QP_SOLVED || !unicycle_qp_solution_finite(sol)) {
        unicycle_timer_add(&s->timer, UNICYCLE_PHASE_FEEDBACK, t0);
        return unicycle_ret(s, UNICYCLE_ERR_QP);
    }

    /* domega_k = (dw_k, lam_QP_{k+1} - lam_{k+1}, mu_g_QP_k - mu_g_k, mu_b_QP_k - mu_b_k) */
    for (k = 0; k < UNICYCLE_N; ++k) {
        unicycle_stage_slot *slot = unicycle_ring_stage(&s->ring, k);
        for (i = 0; i < UNICYCLE_NX; ++i) {
            slot->dw[i] = sol->x[k][i];
            slot->dlam[i] = sol->lam[k + 1][i] - s->lam[k + 1][i];
        }
        for (i = 0; i < UNICYCLE_NU; ++i) {
            slot->dw[UNICYCLE_NX + i] = sol->u[k][i];
        }
        for (i = 0; i < UNICYCLE_NG; ++i) {
            slot->dmu_g[i] = sol->mu_g[k][i] - s->mu_g[k][i];
        }
        for (i = 0; i < UNICYCLE_NW; ++i) {
            slot->dmu_b[i] = sol->mu_b[k][i] - s->mu_b[k][i];
        }
    }
    /* the full step (paper eq. 4): w += dw, multipliers replaced by the QP's */
    for (k = 0; k <= UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NX; ++i) {
            s->x[k][i] += sol->x[k][i];
            s->lam[k][i] = sol->lam[k][i];
        }
    }
    for (k = 0; k < UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NU; ++i) {
            s->u[k][i] += sol->u[k][i];
        }
        for (i = 0; i < UNICYCLE_NG; ++i) {
            s->mu_g[k][i] = sol->mu_g[k][i];
        }
        for (i = 0; i < UNICYCLE_NW; ++i) {
            s->mu_b[k][i] = sol->mu_b[k][i];
        }
    }
    for (i = 0; i < UNICYCLE_NX; ++i) {
        s->mu_bN[i] = sol->mu_bN[i];
    }
    for (i = 0; i < UNICYCLE_NR; ++i) {
        s->mu_r[i] = sol->mu_r[i];
    }
    for (i = 0; i < UNICYCLE_NE; ++i) {
        s->nu[i] = sol->nu[i];
    }
    s->qp_ready = 0;
    if (u0) {
        for (i = 0; i < UNICYCLE_NU; ++i) {
            u0[i] = s->u[0][i];
        }
    }
    unicycle_timer_add(&s->timer, UNICYCLE_PHASE_FEEDBACK, t0);
    return unicycle_ret(s, UNICYCLE_OK);
}

/* ---- prepare ------------------------------------------------------------------------ */

/* Step 1 (receding mode): shift the iterate by one interval and advance ring_head.
 * x_N is set from phi_{N-1} in step 3. */
static void unicycle_shift(unicycle_solver *s)
{
    int k, i;
    for (k = 0; k < UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NX; ++i) {
            s->x[k][i] = s->x[k + 1][i];
            s->lam[k][i] = s->lam[k + 1][i];
        }
    }
    for (k = 0; k < UNICYCLE_N - 1; ++k) {
        for (i = 0; i < UNICYCLE_NU; ++i) {
            s->u[k][i] = s->u[k + 1][i];
        }
        for (i = 0; i < UNICYCLE_NG; ++i) {
            s->mu_g[k][i] = s->mu_g[k + 1][i];
        }
        for (i = 0; i < UNICYCLE_NW; ++i) {
            s->mu_b[k][i] = s->mu_b[k + 1][i];
        }
    }
    /* the last stage: the x part of mu_b from mu_bN, the u part kept */
    for (i = 0; i < UNICYCLE_NX; ++i) {
        s->mu_b[UNICYCLE_N - 1][i] = s->mu_bN[i];
        s->mu_b[0][i] = 0.0;
    }
    unicycle_ring_advance(&s->ring);
}

/* Step 4: the M stages among 0..N-2 with the largest rho_k, ties to the lower index. */
static void unicycle_select(unicycle_solver *s, int M)
{
    int m, k, n = 0;
    for (k = 0; k < UNICYCLE_N; ++k) {
        s->selected[k] = 0;
    }
    for (m = 0; m < M; ++m) {
        int best = -1;
        for (k = 0; k < UNICYCLE_N - 1; ++k) {
            if (!s->selected[k] && (best < 0 || s->rho[k] > s->rho[best])) {
                best = k;
            }
        }
        if (best < 0) {
            break;
        }
        s->selected[best] = 1;
    }
    for (k = 0; k < UNICYCLE_N - 1; ++k) {
        if (s->selected[k]) {
            s->recomputed[n++] = k;
        }
    }
    s->recomputed[n++] = UNICYCLE_N - 1;
    s->n_recomputed = n;
}

int unicycle_prepare(unicycle_solver *s)
{
    double xN_saved[UNICYCLE_NX];
    double t0;
    int k, rc, M;

    unicycle_ensure_setup(s);
    if (!s->initialized) {
        return unicycle_ret(s, UNICYCLE_ERR_NOT_INITIALIZED);
    }
    if (!s->prepare_due) {
        /* a second prepare would shift the horizon twice */
        return unicycle_ret(s, UNICYCLE_ERR_ALREADY_PREPARED);
    }
    unicycle_clear_timings(s, UNICYCLE_PHASE_SHIFT, UNICYCLE_PHASE_ASSEMBLY);
    s->qp_ready = 0;

    /* 1. shift (once per sampling instant: a retry after a failed prepare does not) */
    t0 = unicycle_timer_now(&s->timer);
    if (s->mode == UNICYCLE_MODE_RECEDING && !s->shifted) {
        unicycle_shift(s);
        s->shifted = 1;
    }
    t0 = unicycle_timer_add(&s->timer, UNICYCLE_PHASE_SHIFT, t0);
    unicycle_copy(xN_saved, s->x[UNICYCLE_N], UNICYCLE_NX);

    /* 2. F_k and rho_k (eq. 16) of stages 0..N-2 (F_new kept for step 6) */
    for (k = 0; k < UNICYCLE_N - 1; ++k) {
        unicycle_stage_slot *slot = unicycle_ring_stage(&s->ring, k);
        rc = unicycle_stage_F(s, k);
        t0 = unicycle_timer_add(&s->timer, UNICYCLE_PHASE_GRADIENTS, t0);
        if (rc != UNICYCLE_OK) {
            return unicycle_ret(s, rc);
        }
        s->rho[k] = unicycle_ring_secant(slot, s->tmp_F, s->tmp_phi, s->tmp_g);
        /* stored as F_old in step 6, once nothing can fail */
        unicycle_copy(s->Fn_w[k], s->tmp_F, UNICYCLE_NW);
        unicycle_copy(s->Fn_phi[k], s->tmp_phi, UNICYCLE_NX);
        unicycle_copy(s->Fn_g[k], s->tmp_g, UNICYCLE_NG);
        t0 = unicycle_timer_add(&s->timer, UNICYCLE_PHASE_RHO, t0);
    }

    /* 3. stage N-1 fresh; in receding mode x_N <- phi_{N-1} before the terminal node */
    rc = unicycle_stage_F(s, UNICYCLE_N - 1);
    t0 = unicycle_timer_add(&s->timer, UNICYCLE_PHASE_GRADIENTS, t0);
    if (rc != UNICYCLE_OK) {
        return unicycle_ret(s, rc);
    }
    if (s->mode == UNICYCLE_MODE_RECEDING) {
        unicycle_copy(s->x[UNICYCLE_N], s->tmp_phi, UNICYCLE_NX);
    }
    unicycle_ring_store_F(unicycle_ring_stage(&s->ring, UNICYCLE_N - 1), s->tmp_F, s->tmp_phi, s->tmp_g);
    s->rho[UNICYCLE_N - 1] = 0.0;
    rc = unicycle_stage_H(s, UNICYCLE_N - 1);
    if (rc == UNICYCLE_OK) {
        t0 = unicycle_timer_now(&s->timer);
        rc = unicycle_term_F(s);
        unicycle_timer_add(&s->timer, UNICYCLE_PHASE_GRADIENTS, t0);
    }
    if (rc == UNICYCLE_OK) {
        rc = unicycle_term_H(s);
    }

    /* 4. re-linearise the M stages with the largest rho_k */
    if (rc == UNICYCLE_OK) {
        M = s->M < 0 ? 0 : (s->M > UNICYCLE_N - 1 ? UNICYCLE_N - 1 : s->M);
        unicycle_select(s, M);
        for (k = 0; k < UNICYCLE_N - 1 && rc == UNICYCLE_OK; ++k) {
            if (s->selected[k]) {
                rc = unicycle_stage_H(s, k);
            }
        }
    }

    /* 5. cost_hessian fresh: every stage whose H was not computed above gets
     *    Ht = reg(A_dyn + A_l) with A_l at the current point (Phit, Ct, A_dyn kept) */
    if (rc == UNICYCLE_OK && s->cost_hessian) {
        for (k = 0; k < UNICYCLE_N - 1 && rc == UNICYCLE_OK; ++k) {
            unicycle_stage_slot *slot = unicycle_ring_stage(&s->ring, k);
            int i;
            if (s->selected[k]) {
                continue;
            }
            rc = unicycle_stage_Al(s, k);
            if (rc != UNICYCLE_OK) {
                break;
            }
            for (i = 0; i < UNICYCLE_NW * UNICYCLE_NW; ++i) {
                s->tmp_A[i] = slot->A_dyn[i] + s->tmp_Al[i];
            }
            rc = unicycle_regularize(s, UNICYCLE_NW, s->tmp_A);
            if (rc == UNICYCLE_OK) {
                unicycle_copy(slot->Ht, s->tmp_A, UNICYCLE_NW * UNICYCLE_NW);
            }
        }
    }
    if (rc != UNICYCLE_OK) {
        /* leave the iterate as it was after step 1 */
        unicycle_copy(s->x[UNICYCLE_N], xN_saved, UNICYCLE_NX);
        return unicycle_ret(s, rc);
    }

    /* 6. F_new of step 2 becomes F_old; QP vectors (the fresh A blocks were regularised
     *    when stored) */
    for (k = 0; k < UNICYCLE_N - 1; ++k) {
        unicycle_ring_store_F(unicycle_ring_stage(&s->ring, k), s->Fn_w[k], s->Fn_phi[k], s->Fn_g[k]);
    }
    unicycle_assemble(s);
    s->qp_ready = 1;
    s->prepare_due = 0;
    s->shifted = 0;
    return unicycle_ret(s, UNICYCLE_OK);
}

/* ---- KKT ---------------------------------------------------------------------------- */

int unicycle_kkt_eval(unicycle_solver *s, const double *xhat0, double *kkt4)
{
    double parts[4];
    double t0;
    int i, rc;

    unicycle_ensure_setup(s);
    if (!s->initialized) {
        return unicycle_ret(s, UNICYCLE_ERR_NOT_INITIALIZED);
    }
    if (xhat0 && !unicycle_lai_vec_finite(UNICYCLE_NX, xhat0)) {
        return unicycle_ret(s, UNICYCLE_ERR_NONFINITE_INPUT);
    }
    s->timer.t[UNICYCLE_PHASE_KKT] = 0.0;
    t0 = unicycle_timer_now(&s->timer);
    rc = unicycle_kkt_measure(s, xhat0 ? xhat0 : s->xhat0, parts);
    unicycle_timer_add(&s->timer, UNICYCLE_PHASE_KKT, t0);
    if (rc != UNICYCLE_OK) {
        return unicycle_ret(s, rc);
    }
    for (i = 0; i < 4; ++i) {
        s->kkt[i] = parts[i];
        if (kkt4) {
            kkt4[i] = parts[i];
        }
    }
    return unicycle_ret(s, UNICYCLE_OK);
}

double unicycle_get_kkt(const unicycle_solver *s)
{
    double m = s->kkt[0];
    int i;
    for (i = 1; i < 4; ++i) {
        m = s->kkt[i] > m ? s->kkt[i] : m;
    }
    return m;
}

/* ---- settings ----------------------------------------------------------------------- */

int unicycle_set_M(unicycle_solver *s, int M)
{
    unicycle_ensure_setup(s);
    if (M < 0 || M > UNICYCLE_N - 1) {
        return unicycle_ret(s, UNICYCLE_ERR_INVALID_ARGUMENT);
    }
    s->M = M;
    return unicycle_ret(s, UNICYCLE_OK);
}

int unicycle_get_M(unicycle_solver *s)
{
    unicycle_ensure_setup(s);
    return s->M;
}

int unicycle_set_mode(unicycle_solver *s, int mode)
{
    unicycle_ensure_setup(s);
    if (mode != UNICYCLE_MODE_RECEDING && mode != UNICYCLE_MODE_FIXED) {
        return unicycle_ret(s, UNICYCLE_ERR_INVALID_ARGUMENT);
    }
    s->mode = mode;
    return unicycle_ret(s, UNICYCLE_OK);
}

int unicycle_get_mode(unicycle_solver *s)
{
    unicycle_ensure_setup(s);
    return s->mode;
}

int unicycle_set_hessian(unicycle_solver *s, int hessian)
{
    unicycle_ensure_setup(s);
    if (hessian != UNICYCLE_HESSIAN_EXACT && hessian != UNICYCLE_HESSIAN_GAUSS_NEWTON) {
        return unicycle_ret(s, UNICYCLE_ERR_INVALID_ARGUMENT);
    }
    if (hessian == UNICYCLE_HESSIAN_GAUSS_NEWTON && !UNICYCLE_HAS_GN) {
        /* Gauss-Newton needs a least-squares stage cost */
        return unicycle_ret(s, UNICYCLE_ERR_INVALID_ARGUMENT);
    }
    s->hessian = hessian;
    return unicycle_ret(s, UNICYCLE_OK);
}

int unicycle_get_hessian(unicycle_solver *s)
{
    unicycle_ensure_setup(s);
    return s->hessian;
}

int unicycle_set_regularization(unicycle_solver *s, int regularization, double eps)
{
    unicycle_ensure_setup(s);
    if ((regularization != UNICYCLE_REG_NONE && regularization != UNICYCLE_REG_PROJECT &&
         regularization != UNICYCLE_REG_MIRROR) ||
        !isfinite(eps) || !(eps > 0.0)) {
        return unicycle_ret(s, UNICYCLE_ERR_INVALID_ARGUMENT);
    }
    s->regularization = regularization;
    s->reg_eps = eps;
    return unicycle_ret(s, UNICYCLE_OK);
}

int unicycle_get_regularization(unicycle_solver *s)
{
    unicycle_ensure_setup(s);
    return s->regularization;
}

double unicycle_get_reg_eps(unicycle_solver *s)
{
    unicycle_ensure_setup(s);
    return s->reg_eps;
}

int unicycle_set_cost_hessian(unicycle_solver *s, int fresh)
{
    unicycle_ensure_setup(s);
    if (fresh != 0 && fresh != 1) {
        return unicycle_ret(s, UNICYCLE_ERR_INVALID_ARGUMENT);
    }
    s->cost_hessian = fresh;
    return unicycle_ret(s, UNICYCLE_OK);
}

int unicycle_get_cost_hessian(unicycle_solver *s)
{
    unicycle_ensure_setup(s);
    return s->cost_hessian;
}

int unicycle_set_levenberg_marquardt(unicycle_solver *s, double lm)
{
    unicycle_ensure_setup(s);
    if (!isfinite(lm) || !(lm >= 0.0)) {
        return unicycle_ret(s, UNICYCLE_ERR_INVALID_ARGUMENT);
    }
    s->lm = lm;
    return unicycle_ret(s, UNICYCLE_OK);
}

double unicycle_get_levenberg_marquardt(unicycle_solver *s)
{
    unicycle_ensure_setup(s);
    return s->lm;
}

int unicycle_set_qp_tol(unicycle_solver *s, double tol)
{
    unicycle_ensure_setup(s);
    if (!isfinite(tol) || !(tol > 0.0)) {
        return unicycle_ret(s, UNICYCLE_ERR_INVALID_ARGUMENT);
    }
    s->qp_settings.tol = tol;
    return unicycle_ret(s, UNICYCLE_OK);
}

double unicycle_get_qp_tol(unicycle_solver *s)
{
    unicycle_ensure_setup(s);
    return s->qp_settings.tol;
}

int unicycle_set_qp_max_iter(unicycle_solver *s, int max_iter)
{
    unicycle_ensure_setup(s);
    if (max_iter < 1) {
        return unicycle_ret(s, UNICYCLE_ERR_INVALID_ARGUMENT);
    }
    s->qp_settings.max_iter = max_iter;
    return unicycle_ret(s, UNICYCLE_OK);
}

int unicycle_get_qp_max_iter(unicycle_solver *s)
{
    unicycle_ensure_setup(s);
    return s->qp_settings.max_iter;
}

int unicycle_set_qp_warm_start(unicycle_solver *s, int on)
{
    unicycle_ensure_setup(s);
    if (on != 0 && on != 1) {
        return unicycle_ret(s, UNICYCLE_ERR_INVALID_ARGUMENT);
    }
    s->qp_warm = on;
    return unicycle_ret(s, UNICYCLE_OK);
}

int unicycle_get_qp_warm_start(unicycle_solver *s)
{
    unicycle_ensure_setup(s);
    return s->qp_warm;
}

int unicycle_get_qp_cold_retry(const unicycle_solver *s)
{
    return s->qp_cold_retry;
}

int unicycle_set_parameters(unicycle_solver *s, const double *p)
{
    int k, i;
    unicycle_ensure_setup(s);
    if (UNICYCLE_NP == 0) {
        return unicycle_ret(s, UNICYCLE_OK);
    }
    if (p == 0) {
        return unicycle_ret(s, UNICYCLE_ERR_INVALID_ARGUMENT);
    }
    if (!unicycle_lai_vec_finite((UNICYCLE_N + 1) * UNICYCLE_NP, p)) {
        return unicycle_ret(s, UNICYCLE_ERR_NONFINITE_INPUT);
    }
    for (k = 0; k <= UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NP; ++i) {
            s->p[k][i] = p[k * UNICYCLE_NP + i];
        }
    }
    return unicycle_ret(s, UNICYCLE_OK);
}

int unicycle_set_parameters_node(unicycle_solver *s, int k, const double *pk)
{
    int i;
    unicycle_ensure_setup(s);
    if (k < 0 || k > UNICYCLE_N) {
        return unicycle_ret(s, UNICYCLE_ERR_INVALID_ARGUMENT);
    }
    if (UNICYCLE_NP == 0) {
        return unicycle_ret(s, UNICYCLE_OK);
    }
    if (pk == 0) {
        return unicycle_ret(s, UNICYCLE_ERR_INVALID_ARGUMENT);
    }
    if (!unicycle_lai_vec_finite(UNICYCLE_NP, pk)) {
        return unicycle_ret(s, UNICYCLE_ERR_NONFINITE_INPUT);
    }
    for (i = 0; i < UNICYCLE_NP; ++i) {
        s->p[k][i] = pk[i];
    }
    return unicycle_ret(s, UNICYCLE_OK);
}

void unicycle_get_parameters(unicycle_solver *s, double *p)
{
    int k, i;
    unicycle_ensure_setup(s);
    for (k = 0; k <= UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NP; ++i) {
            p[k * UNICYCLE_NP + i] = s->p[k][i];
        }
    }
}

/* ---- getters ------------------------------------------------------------------------ */

void unicycle_get_x(const unicycle_solver *s, double *x)
{
    unicycle_copy(x, &s->x[0][0], (UNICYCLE_N + 1) * UNICYCLE_NX);
}

void unicycle_get_u(const unicycle_solver *s, double *u)
{
    unicycle_copy(u, &s->u[0][0], UNICYCLE_N * UNICYCLE_NU);
}

void unicycle_get_lam(const unicycle_solver *s, double *lam)
{
    unicycle_copy(lam, &s->lam[0][0], (UNICYCLE_N + 1) * UNICYCLE_NX);
}

void unicycle_get_mu_g(const unicycle_solver *s, double *mu_g)
{
    int k, i;
    for (k = 0; k < UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NG; ++i) {
            mu_g[k * UNICYCLE_NG + i] = s->mu_g[k][i];
        }
    }
}

void unicycle_get_mu_b(const unicycle_solver *s, double *mu_b)
{
    unicycle_copy(mu_b, &s->mu_b[0][0], UNICYCLE_N * UNICYCLE_NW);
}

void unicycle_get_mu_bN(const unicycle_solver *s, double *mu_bN)
{
    unicycle_copy(mu_bN, s->mu_bN, UNICYCLE_NX);
}

void unicycle_get_mu_r(const unicycle_solver *s, double *mu_r)
{
    unicycle_copy(mu_r, s->mu_r, UNICYCLE_NR);
}

void unicycle_get_nu(const unicycle_solver *s, double *nu)
{
    unicycle_copy(nu, s->nu, UNICYCLE_NE);
}

void unicycle_get_rho(const unicycle_solver *s, double *rho)
{
    unicycle_copy(rho, s->rho, UNICYCLE_N);
}

int unicycle_get_recomputed(const unicycle_solver *s, int *stages)
{
    int i;
    for (i = 0; i < s->n_recomputed; ++i) {
        stages[i] = s->recomputed[i];
    }
    return s->n_recomputed;
}

int unicycle_get_qp_iterations(const unicycle_solver *s)
{
    return s->qp_iterations;
}

int unicycle_get_qp_status(const unicycle_solver *s)
{
    return s->qp_status;
}

int unicycle_get_status(const unicycle_solver *s)
{
    return s->status;
}

int unicycle_is_initialized(const unicycle_solver *s)
{
    return s->magic == UNICYCLE_MAGIC && s->initialized;
}

int unicycle_get_ring_head(const unicycle_solver *s)
{
    return s->ring.ring_head;
}

void unicycle_get_timings(const unicycle_solver *s, double *t)
{
    unicycle_copy(t, s->timer.t, UNICYCLE_N_PHASES);
}

void unicycle_set_clock(unicycle_solver *s, double (*clock_fn)(void *ctx), void *ctx)
{
    unicycle_ensure_setup(s);
    s->timer.clock = clock_fn ? clock_fn : unicycle_timer_default_clock;
    s->timer.ctx = clock_fn ? ctx : 0;
}

int unicycle_has_clock(const unicycle_solver *s)
{
    if (s->timer.clock == 0) {
        return 0;
    }
    return s->timer.clock != unicycle_timer_default_clock || unicycle_timer_has_default_clock();
}
