/* Adapter of our QP solver for the benchmark driver (layout of bench_qp in qp_bench_qp.h). */
#include "qp_bench_dopus.h"

#include <stdlib.h>
#include <string.h>

#include "dopus_qp.h"

struct bench_dopus {
    dopus_qp_workspace ws;
    dopus_qp_in in;
    dopus_qp_sol sol;
    dopus_qp_info info;
    dopus_qp_settings settings;
    const bench_dopus_warm *warm;
};

/* the sweeps of the closed loop's active-set start (DOPUS_QP_ACTIVE_SET of dopus_solver.h) */
#define QPB_ACTIVE_SET_SWEEPS 8

struct bench_dopus_warm {
    dopus_qp_sol sol;
    int have;
};

bench_dopus *bench_dopus_create(const bench_qp *qp, double tol, int iter_max)
{
    bench_dopus *d;
    if (qp->N != DOPUS_N || qp->nx != DOPUS_NX || qp->nu != DOPUS_NU || qp->ng != DOPUS_NG
        || qp->nr != DOPUS_NR || qp->ne != DOPUS_NE)
        return NULL;
    d = (bench_dopus *)calloc(1, sizeof(bench_dopus));
    if (d == NULL) return NULL;
    dopus_qp_settings_default(&d->settings);
    d->settings.tol = tol;
    d->settings.max_iter = iter_max;
    bench_dopus_set_data(d, qp);
    return d;
}

void bench_dopus_set_data(bench_dopus *d, const bench_qp *qp)
{
    const int nx = DOPUS_NX, nw = DOPUS_QP_NW, ng = DOPUS_NG;
    int k;
    dopus_qp_in *in = &d->in;
    for (k = 0; k < DOPUS_N; ++k) {
        in->H[k] = qp->H + k * nw * nw;
        in->Phi[k] = qp->Phi + k * nx * nw;
        in->C[k] = ng > 0 ? qp->C + k * ng * nw : NULL;
        memcpy(in->g[k], qp->a + k * nw, sizeof(double) * (size_t)nw);
        memcpy(in->b[k], qp->b + k * nx, sizeof(double) * (size_t)nx);
        memcpy(in->lbw[k], qp->lbw + k * nw, sizeof(double) * (size_t)nw);
        memcpy(in->ubw[k], qp->ubw + k * nw, sizeof(double) * (size_t)nw);
        if (ng > 0) {
            memcpy(in->lg[k], qp->lg + k * ng, sizeof(double) * (size_t)ng);
            memcpy(in->ug[k], qp->ug + k * ng, sizeof(double) * (size_t)ng);
        }
    }
    if (d->warm != NULL && d->warm->have) {
        /* the warm point: the previous solution's multipliers, primal zero but x_0 */
        memcpy(&d->sol, &d->warm->sol, sizeof(d->sol));
        memset(d->sol.x, 0, sizeof(d->sol.x));
        memset(d->sol.u, 0, sizeof(d->sol.u));
        memcpy(d->sol.x[0], qp->dx0, sizeof(double) * (size_t)nx);
        d->settings.warm_start = 1;
        d->settings.active_set = QPB_ACTIVE_SET_SWEEPS;
    } else {
        d->settings.warm_start = 0;
        d->settings.active_set = 0;
    }
    in->HN = qp->AN;
    in->R = DOPUS_NR > 0 ? qp->R : NULL;
    in->Req = DOPUS_NE > 0 ? qp->Req : NULL;
    memcpy(in->x0, qp->dx0, sizeof(double) * (size_t)nx);
    memcpy(in->gN, qp->aN, sizeof(double) * (size_t)nx);
    memcpy(in->lbxN, qp->lbxN, sizeof(double) * (size_t)nx);
    memcpy(in->ubxN, qp->ubxN, sizeof(double) * (size_t)nx);
    if (DOPUS_NR > 0) {
        memcpy(in->lr, qp->lr, sizeof(double) * (size_t)DOPUS_NR);
        memcpy(in->ur, qp->ur, sizeof(double) * (size_t)DOPUS_NR);
    }
    if (DOPUS_NE > 0) memcpy(in->req, qp->req, sizeof(double) * (size_t)DOPUS_NE);
}

int bench_dopus_solve(bench_dopus *d)
{
    return dopus_qp_solve(&d->ws, &d->in, &d->settings, &d->sol, &d->info);
}

int bench_dopus_iterations(const bench_dopus *d) { return d->info.iterations; }

int bench_dopus_residuals(const bench_dopus *d, double res[4])
{
    res[0] = d->info.res_stat;
    res[1] = d->info.res_eq;
    res[2] = d->info.res_ineq;
    res[3] = d->info.res_comp;
    return 0;
}

void bench_dopus_primal(const bench_dopus *d, double *dw)
{
    const int nx = DOPUS_NX, nu = DOPUS_NU, nw = DOPUS_QP_NW;
    int k;
    for (k = 0; k < DOPUS_N; ++k) {
        memcpy(dw + k * nw, d->sol.x[k], sizeof(double) * (size_t)nx);
        if (nu > 0) memcpy(dw + k * nw + nx, d->sol.u[k], sizeof(double) * (size_t)nu);
    }
    memcpy(dw + DOPUS_N * nw, d->sol.x[DOPUS_N], sizeof(double) * (size_t)nx);
}

void bench_dopus_corrections(const bench_dopus *d, int *inertia, int *augment)
{
    *inertia = d->info.inertia_corrections;
    *augment = d->info.terminal_augmentations;
}

int bench_dopus_factorizations(const bench_dopus *d) { return d->info.factorizations; }

bench_dopus_warm *bench_dopus_warm_new(void) { return (bench_dopus_warm *)calloc(1, sizeof(bench_dopus_warm)); }

void bench_dopus_warm_reset(bench_dopus_warm *w) { w->have = 0; }

void bench_dopus_warm_keep(bench_dopus_warm *w, const bench_dopus *d)
{
    memcpy(&w->sol, &d->sol, sizeof(w->sol));
    w->have = d->info.status == 0;
}

void bench_dopus_warm_use(bench_dopus *d, const bench_dopus_warm *w) { d->warm = w; }

void bench_dopus_warm_free(bench_dopus_warm *w) { free(w); }

void bench_dopus_free(bench_dopus *d) { free(d); }
