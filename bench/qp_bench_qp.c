/* Reader and checks of the benchmark QP file (layout in qp_bench_qp.h). */
#include "qp_bench_qp.h"

#include <math.h>
#include <stdlib.h>
#include <string.h>

static int read_doubles(FILE *f, double *dst, size_t n)
{
    return n == 0 || fread(dst, sizeof(double), n, f) == n ? 0 : 1;
}

int bench_qp_read(FILE *f, bench_qp *qp)
{
    double hdr[6];
    size_t N, nx, nu, ng, nr, ne, nw, total, off = 0;
    double *s;

    memset(qp, 0, sizeof(*qp));
    if (read_doubles(f, hdr, 6)) return 1;
    qp->N = (int)hdr[0]; qp->nx = (int)hdr[1]; qp->nu = (int)hdr[2];
    qp->ng = (int)hdr[3]; qp->nr = (int)hdr[4]; qp->ne = (int)hdr[5];
    if (qp->N < 1 || qp->nx < 1 || qp->nu < 0 || qp->ng < 0 || qp->nr < 0 || qp->ne < 0) return 2;
    N = (size_t)qp->N; nx = (size_t)qp->nx; nu = (size_t)qp->nu; ng = (size_t)qp->ng;
    nr = (size_t)qp->nr; ne = (size_t)qp->ne; nw = nx + nu;
    total = nx + N * (nw * nw + nw + nx * nw + nx + ng * nw + 2 * ng + 2 * nw)
            + nx * nx + 3 * nx + nr * nx + 2 * nr + ne * nx + ne;
    s = (double *)malloc(total * sizeof(double));
    if (s == NULL) return 3;
    qp->store = s;
#define TAKE(ptr, n) do { qp->ptr = s + off; off += (n); } while (0)
    TAKE(dx0, nx);
    TAKE(H, N * nw * nw); TAKE(a, N * nw); TAKE(Phi, N * nx * nw); TAKE(b, N * nx);
    TAKE(C, N * ng * nw); TAKE(lg, N * ng); TAKE(ug, N * ng); TAKE(lbw, N * nw); TAKE(ubw, N * nw);
    TAKE(AN, nx * nx); TAKE(aN, nx); TAKE(lbxN, nx); TAKE(ubxN, nx);
    TAKE(R, nr * nx); TAKE(lr, nr); TAKE(ur, nr); TAKE(Req, ne * nx); TAKE(req, ne);
#undef TAKE
    /* the file stores stage k's arrays together; scatter them into the per-kind arrays */
    if (read_doubles(f, qp->dx0, nx)) return 4;
    {
        size_t k;
        for (k = 0; k < N; ++k) {
            if (read_doubles(f, qp->H + k * nw * nw, nw * nw) || read_doubles(f, qp->a + k * nw, nw)
                || read_doubles(f, qp->Phi + k * nx * nw, nx * nw) || read_doubles(f, qp->b + k * nx, nx)
                || read_doubles(f, qp->C + k * ng * nw, ng * nw) || read_doubles(f, qp->lg + k * ng, ng)
                || read_doubles(f, qp->ug + k * ng, ng) || read_doubles(f, qp->lbw + k * nw, nw)
                || read_doubles(f, qp->ubw + k * nw, nw))
                return 4;
        }
    }
    if (read_doubles(f, qp->AN, nx * nx) || read_doubles(f, qp->aN, nx) || read_doubles(f, qp->lbxN, nx)
        || read_doubles(f, qp->ubxN, nx) || read_doubles(f, qp->R, nr * nx) || read_doubles(f, qp->lr, nr)
        || read_doubles(f, qp->ur, nr) || read_doubles(f, qp->Req, ne * nx) || read_doubles(f, qp->req, ne))
        return 4;
    return 0;
}

void bench_qp_free(bench_qp *qp)
{
    free(qp->store);
    memset(qp, 0, sizeof(*qp));
}

static double quad(const double *M, const double *v, const double *g, int n)
{
    double s = 0.0;
    int i, j;
    for (j = 0; j < n; ++j) {
        double Mv = 0.0;
        for (i = 0; i < n; ++i) Mv += M[i + j * n] * v[i];
        s += 0.5 * Mv * v[j] + g[j] * v[j];
    }
    return s;
}

double bench_qp_objective(const bench_qp *qp, const double *dw)
{
    int nw = qp->nx + qp->nu, k;
    double J = 0.0;
    for (k = 0; k < qp->N; ++k)
        J += quad(qp->H + k * nw * nw, dw + k * nw, qp->a + k * nw, nw);
    return J + quad(qp->AN, dw + qp->N * nw, qp->aN, qp->nx);
}

static double viol(double v, double lo, double hi)
{
    double e = 0.0;
    if (v > hi) e = v - hi;
    if (v < lo) e = lo - v;
    return e;
}

double bench_qp_infeasibility(const bench_qp *qp, const double *dw)
{
    int nx = qp->nx, nw = qp->nx + qp->nu, k, i, j;
    const double *xN = dw + qp->N * nw;
    double e = 0.0, t;
    for (i = 0; i < nx; ++i) e = fmax(e, fabs(dw[i] - qp->dx0[i]));
    for (k = 0; k < qp->N; ++k) {
        const double *w = dw + k * nw, *xn = dw + (k + 1) * nw;
        for (i = 0; i < nx; ++i) {
            t = qp->b[k * nx + i] - xn[i];
            for (j = 0; j < nw; ++j) t += qp->Phi[k * nx * nw + i + j * nx] * w[j];
            e = fmax(e, fabs(t));
        }
        for (j = (k == 0 ? nx : 0); j < nw; ++j)
            e = fmax(e, viol(w[j], qp->lbw[k * nw + j], qp->ubw[k * nw + j]));
        for (i = 0; i < qp->ng; ++i) {
            t = 0.0;
            for (j = 0; j < nw; ++j) t += qp->C[k * qp->ng * nw + i + j * qp->ng] * w[j];
            e = fmax(e, viol(t, qp->lg[k * qp->ng + i], qp->ug[k * qp->ng + i]));
        }
    }
    for (i = 0; i < nx; ++i) e = fmax(e, viol(xN[i], qp->lbxN[i], qp->ubxN[i]));
    for (i = 0; i < qp->nr; ++i) {
        t = 0.0;
        for (j = 0; j < nx; ++j) t += qp->R[i + j * qp->nr] * xN[j];
        e = fmax(e, viol(t, qp->lr[i], qp->ur[i]));
    }
    for (i = 0; i < qp->ne; ++i) {
        t = -qp->req[i];
        for (j = 0; j < nx; ++j) t += qp->Req[i + j * qp->ne] * xN[j];
        e = fmax(e, fabs(t));
    }
    return e;
}
