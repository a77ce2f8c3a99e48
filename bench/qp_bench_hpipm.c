/* HPIPM adapter of the benchmark: the stage QP of docs/algorithm.md section 3 in HPIPM's
 * OCP QP form. HPIPM orders each stage as [u; x] with cost blocks R, S (nu x nx), Q and
 * dynamics x_{k+1} = A x_k + B u_k + b_k; dx_0 is a box with lb = ub (what acados does),
 * simple bounds go to idxbu / idxbx (an infinite side masked out), general rows to C / D,
 * the terminal rows to the general constraints of stage N ([R; R_eq], R_eq with lg = ug).
 */
#define _POSIX_C_SOURCE 200112L
#include "qp_bench_hpipm.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

#include "blasfeo_d_aux_ext_dep.h"
#include "hpipm_d_ocp_qp.h"
#include "hpipm_d_ocp_qp_dim.h"
#include "hpipm_d_ocp_qp_ipm.h"
#include "hpipm_d_ocp_qp_sol.h"

/* stand-in value for a masked (infinite) side of a bound */
#define BIG_BOUND 1e9
#define MAX_ROWS 64

struct bench_hpipm {
    struct d_ocp_qp_dim dim;
    struct d_ocp_qp qp;
    struct d_ocp_qp_sol sol;
    struct d_ocp_qp_ipm_arg arg;
    struct d_ocp_qp_ipm_ws ws;
    void *mem[5];
    bench_hpipm_opts opts;
    int N, nx, nu;
    /* per stage: which u / x components carry a bound (at least one finite side) */
    int *nbu, *nbx, *idxbu, *idxbx; /* idx arrays: stage k at offset k * nx or k * nu */
    double *eq_row_scale;           /* ne factors dividing the terminal equality rows */
    double *tmp;                    /* scratch for block extraction */
};

static void *alloc64(size_t n)
{
    void *p = NULL;
    if (posix_memalign(&p, 64, n == 0 ? 64 : n) != 0) return NULL;
    memset(p, 0, n);
    return p;
}

static int has_bound(double lo, double hi) { return isfinite(lo) || isfinite(hi); }

bench_hpipm *bench_hpipm_create(const bench_qp *qp, const bench_hpipm_opts *opts)
{
    int N = qp->N, nx = qp->nx, nu = qp->nu, nw = nx + nu, ng = qp->ng, k, j;
    bench_hpipm *h;
    /* the row buffers of bench_hpipm_set_data hold at most MAX_ROWS entries */
    if (nx > MAX_ROWS || nu > MAX_ROWS || ng > MAX_ROWS || qp->nr + qp->ne > MAX_ROWS) return NULL;
    h = (bench_hpipm *)calloc(1, sizeof(bench_hpipm));
    if (h == NULL) return NULL;
    h->opts = *opts;
    h->N = N; h->nx = nx; h->nu = nu;
    h->nbu = (int *)calloc((size_t)(N + 1), sizeof(int));
    h->nbx = (int *)calloc((size_t)(N + 1), sizeof(int));
    h->idxbu = (int *)calloc((size_t)(N + 1) * (size_t)(nu + 1), sizeof(int));
    h->idxbx = (int *)calloc((size_t)(N + 1) * (size_t)nx, sizeof(int));
    h->eq_row_scale = (double *)calloc((size_t)qp->ne + 1, sizeof(double));
    h->tmp = (double *)calloc((size_t)(nw * nw + (qp->nr + qp->ne + ng + 1) * nw), sizeof(double));
    if (!h->nbu || !h->nbx || !h->idxbu || !h->idxbx || !h->eq_row_scale || !h->tmp) {
        bench_hpipm_free(h);
        return NULL;
    }
    for (k = 0; k <= N; ++k) {
        for (j = 0; j < nu && k < N; ++j)
            if (has_bound(qp->lbw[k * nw + nx + j], qp->ubw[k * nw + nx + j]))
                h->idxbu[k * (nu + 1) + h->nbu[k]++] = j;
        for (j = 0; j < nx; ++j) {
            int bounded = k == 0 ? 1
                        : k < N ? has_bound(qp->lbw[k * nw + j], qp->ubw[k * nw + j])
                                : has_bound(qp->lbxN[j], qp->ubxN[j]);
            if (bounded) h->idxbx[k * nx + h->nbx[k]++] = j;
        }
    }
    for (j = 0; j < qp->ne; ++j) {
        double s = 1.0;
        if (opts->eq_scale > 0.0) {
            int i;
            double m = 0.0;
            for (i = 0; i < nx; ++i) m = fmax(m, fabs(qp->Req[j + i * qp->ne]));
            s = m > 0.0 ? opts->eq_scale * m : 1.0;
        }
        h->eq_row_scale[j] = s;
    }

    h->mem[0] = alloc64((size_t)d_ocp_qp_dim_memsize(N));
    if (h->mem[0] == NULL) { bench_hpipm_free(h); return NULL; }
    d_ocp_qp_dim_create(N, &h->dim, h->mem[0]);
    for (k = 0; k <= N; ++k) {
        d_ocp_qp_dim_set_nx(k, nx, &h->dim);
        d_ocp_qp_dim_set_nu(k, k < N ? nu : 0, &h->dim);
        d_ocp_qp_dim_set_nbu(k, h->nbu[k], &h->dim);
        d_ocp_qp_dim_set_nbx(k, h->nbx[k], &h->dim);
        d_ocp_qp_dim_set_ng(k, k < N ? ng : qp->nr + qp->ne, &h->dim);
        d_ocp_qp_dim_set_ns(k, 0, &h->dim);
    }
    if (opts->eq_mask) {
        d_ocp_qp_dim_set_nbxe(0, nx, &h->dim);
        d_ocp_qp_dim_set_nge(N, qp->ne, &h->dim);
    }

    h->mem[1] = alloc64((size_t)d_ocp_qp_memsize(&h->dim));
    h->mem[2] = alloc64((size_t)d_ocp_qp_sol_memsize(&h->dim));
    h->mem[3] = alloc64((size_t)d_ocp_qp_ipm_arg_memsize(&h->dim));
    if (!h->mem[1] || !h->mem[2] || !h->mem[3]) { bench_hpipm_free(h); return NULL; }
    d_ocp_qp_create(&h->dim, &h->qp, h->mem[1]);
    d_ocp_qp_sol_create(&h->dim, &h->sol, h->mem[2]);
    d_ocp_qp_ipm_arg_create(&h->dim, &h->arg, h->mem[3]);
    d_ocp_qp_ipm_arg_set_default((enum hpipm_mode)opts->mode, &h->arg);
    {
        double tol = opts->tol;
        int it = opts->iter_max;
        d_ocp_qp_ipm_arg_set_tol_stat(&tol, &h->arg);
        d_ocp_qp_ipm_arg_set_tol_eq(&tol, &h->arg);
        d_ocp_qp_ipm_arg_set_tol_ineq(&tol, &h->arg);
        d_ocp_qp_ipm_arg_set_tol_comp(&tol, &h->arg);
        d_ocp_qp_ipm_arg_set_iter_max(&it, &h->arg);
        if (opts->ric_alg >= 0) {
            int ra = opts->ric_alg;
            d_ocp_qp_ipm_arg_set_ric_alg(&ra, &h->arg);
        }
        if (opts->mode == 0) {
            /* the absolute formulation exits on the duality measure alone; have it compute
             * the residuals and equality duals on exit so they can be reported */
            int one = 1;
            d_ocp_qp_ipm_arg_set_comp_dual_sol_eq(&one, &h->arg);
            d_ocp_qp_ipm_arg_set_comp_res_exit(&one, &h->arg);
        }
    }
    h->mem[4] = alloc64((size_t)d_ocp_qp_ipm_ws_memsize(&h->dim, &h->arg));
    if (!h->mem[4]) { bench_hpipm_free(h); return NULL; }
    d_ocp_qp_ipm_ws_create(&h->dim, &h->arg, &h->ws, h->mem[4]);

    bench_hpipm_set_data(h, qp);
    if (opts->eq_mask) {
        int idx[MAX_ROWS];
        for (j = 0; j < nx; ++j) idx[j] = j;
        d_ocp_qp_set_idxbxe(0, idx, &h->qp);
        for (j = 0; j < qp->ne; ++j) idx[j] = qp->nr + j;
        d_ocp_qp_set_idxge(N, idx, &h->qp);
    }
    return h;
}

/* column-major sub-block rows [r0, r0+m) x cols [c0, c0+n) of an ld-row matrix */
static void sub_block(const double *M, int ld, int r0, int c0, int m, int n, double *out)
{
    int i, j;
    for (j = 0; j < n; ++j)
        for (i = 0; i < m; ++i) out[i + j * m] = M[(r0 + i) + (c0 + j) * ld];
}

static void set_bounds(int nb, const int *idx, const double *lo, const double *hi,
                       double *l, double *u, double *lm, double *um)
{
    int i;
    for (i = 0; i < nb; ++i) {
        double a = lo[idx[i]], b = hi[idx[i]];
        lm[i] = isfinite(a) ? 1.0 : 0.0;
        um[i] = isfinite(b) ? 1.0 : 0.0;
        l[i] = isfinite(a) ? a : -BIG_BOUND;
        u[i] = isfinite(b) ? b : BIG_BOUND;
    }
}

void bench_hpipm_set_data(bench_hpipm *h, const bench_qp *qp)
{
    int N = qp->N, nx = qp->nx, nu = qp->nu, nw = nx + nu, ng = qp->ng, k, i, j;
    double *t = h->tmp;
    double l[MAX_ROWS], u[MAX_ROWS], lm[MAX_ROWS], um[MAX_ROWS];

    for (k = 0; k < N; ++k) {
        const double *H = qp->H + k * nw * nw, *Phi = qp->Phi + k * nx * nw;
        sub_block(H, nw, 0, 0, nx, nx, t);
        d_ocp_qp_set_Q(k, t, &h->qp);
        sub_block(H, nw, nx, 0, nu, nx, t);
        d_ocp_qp_set_S(k, t, &h->qp);
        sub_block(H, nw, nx, nx, nu, nu, t);
        d_ocp_qp_set_R(k, t, &h->qp);
        d_ocp_qp_set_q(k, (double *)qp->a + k * nw, &h->qp);
        d_ocp_qp_set_r(k, (double *)qp->a + k * nw + nx, &h->qp);
        sub_block(Phi, nx, 0, 0, nx, nx, t);
        d_ocp_qp_set_A(k, t, &h->qp);
        sub_block(Phi, nx, 0, nx, nx, nu, t);
        d_ocp_qp_set_B(k, t, &h->qp);
        d_ocp_qp_set_b(k, (double *)qp->b + k * nx, &h->qp);

        d_ocp_qp_set_idxbu(k, h->idxbu + k * (nu + 1), &h->qp);
        set_bounds(h->nbu[k], h->idxbu + k * (nu + 1), qp->lbw + k * nw + nx, qp->ubw + k * nw + nx,
                   l, u, lm, um);
        d_ocp_qp_set_lbu(k, l, &h->qp); d_ocp_qp_set_ubu(k, u, &h->qp);
        d_ocp_qp_set_lbu_mask(k, lm, &h->qp); d_ocp_qp_set_ubu_mask(k, um, &h->qp);

        d_ocp_qp_set_idxbx(k, h->idxbx + k * nx, &h->qp);
        if (k == 0) {
            d_ocp_qp_set_lbx(0, (double *)qp->dx0, &h->qp);
            d_ocp_qp_set_ubx(0, (double *)qp->dx0, &h->qp);
        } else {
            set_bounds(h->nbx[k], h->idxbx + k * nx, qp->lbw + k * nw, qp->ubw + k * nw, l, u, lm, um);
            d_ocp_qp_set_lbx(k, l, &h->qp); d_ocp_qp_set_ubx(k, u, &h->qp);
            d_ocp_qp_set_lbx_mask(k, lm, &h->qp); d_ocp_qp_set_ubx_mask(k, um, &h->qp);
        }
        if (ng > 0) {
            const double *C = qp->C + k * ng * nw;
            sub_block(C, ng, 0, 0, ng, nx, t);
            d_ocp_qp_set_C(k, t, &h->qp);
            sub_block(C, ng, 0, nx, ng, nu, t);
            d_ocp_qp_set_D(k, t, &h->qp);
            for (i = 0; i < ng; ++i) {
                double a = qp->lg[k * ng + i], b = qp->ug[k * ng + i];
                lm[i] = isfinite(a) ? 1.0 : 0.0; um[i] = isfinite(b) ? 1.0 : 0.0;
                l[i] = isfinite(a) ? a : -BIG_BOUND; u[i] = isfinite(b) ? b : BIG_BOUND;
            }
            d_ocp_qp_set_lg(k, l, &h->qp); d_ocp_qp_set_ug(k, u, &h->qp);
            d_ocp_qp_set_lg_mask(k, lm, &h->qp); d_ocp_qp_set_ug_mask(k, um, &h->qp);
        }
    }
    /* terminal node */
    d_ocp_qp_set_Q(N, (double *)qp->AN, &h->qp);
    d_ocp_qp_set_q(N, (double *)qp->aN, &h->qp);
    d_ocp_qp_set_idxbx(N, h->idxbx + N * nx, &h->qp);
    set_bounds(h->nbx[N], h->idxbx + N * nx, qp->lbxN, qp->ubxN, l, u, lm, um);
    d_ocp_qp_set_lbx(N, l, &h->qp); d_ocp_qp_set_ubx(N, u, &h->qp);
    d_ocp_qp_set_lbx_mask(N, lm, &h->qp); d_ocp_qp_set_ubx_mask(N, um, &h->qp);
    {
        int nr = qp->nr, ne = qp->ne, nt = nr + ne;
        if (nt > 0) {
            for (j = 0; j < nx; ++j) {
                for (i = 0; i < nr; ++i) t[i + j * nt] = qp->R[i + j * nr];
                for (i = 0; i < ne; ++i) t[nr + i + j * nt] = qp->Req[i + j * ne] / h->eq_row_scale[i];
            }
            d_ocp_qp_set_C(N, t, &h->qp);
            for (i = 0; i < nr; ++i) {
                lm[i] = isfinite(qp->lr[i]) ? 1.0 : 0.0; um[i] = isfinite(qp->ur[i]) ? 1.0 : 0.0;
                l[i] = isfinite(qp->lr[i]) ? qp->lr[i] : -BIG_BOUND;
                u[i] = isfinite(qp->ur[i]) ? qp->ur[i] : BIG_BOUND;
            }
            for (i = 0; i < ne; ++i) {
                lm[nr + i] = um[nr + i] = 1.0;
                l[nr + i] = u[nr + i] = qp->req[i] / h->eq_row_scale[i];
            }
            d_ocp_qp_set_lg(N, l, &h->qp); d_ocp_qp_set_ug(N, u, &h->qp);
            d_ocp_qp_set_lg_mask(N, lm, &h->qp); d_ocp_qp_set_ug_mask(N, um, &h->qp);
        }
    }
}

int bench_hpipm_solve(bench_hpipm *h)
{
    int status = 0;
    d_ocp_qp_ipm_solve(&h->qp, &h->sol, &h->arg, &h->ws);
    d_ocp_qp_ipm_get_status(&h->ws, &status);
    return status;
}

int bench_hpipm_iterations(const bench_hpipm *h)
{
    int it = 0;
    d_ocp_qp_ipm_get_iter((struct d_ocp_qp_ipm_ws *)&h->ws, &it);
    return it;
}

void bench_hpipm_residuals(bench_hpipm *h, double res[4])
{
    d_ocp_qp_ipm_get_max_res_stat(&h->ws, &res[0]);
    d_ocp_qp_ipm_get_max_res_eq(&h->ws, &res[1]);
    d_ocp_qp_ipm_get_max_res_ineq(&h->ws, &res[2]);
    d_ocp_qp_ipm_get_max_res_comp(&h->ws, &res[3]);
}

void bench_hpipm_primal(bench_hpipm *h, double *dw)
{
    int nw = h->nx + h->nu, k;
    for (k = 0; k < h->N; ++k) {
        d_ocp_qp_sol_get_x(k, &h->sol, dw + k * nw);
        d_ocp_qp_sol_get_u(k, &h->sol, dw + k * nw + h->nx);
    }
    d_ocp_qp_sol_get_x(h->N, &h->sol, dw + h->N * nw);
}

void bench_hpipm_free(bench_hpipm *h)
{
    int i;
    if (h == NULL) return;
    for (i = 0; i < 5; ++i) free(h->mem[i]);
    free(h->nbu); free(h->nbx); free(h->idxbu); free(h->idxbx); free(h->eq_row_scale); free(h->tmp);
    free(h);
}
