/* QP benchmark driver: solves every QP of a file with each configured solver in this one
 * process, repetitions interleaved solver by solver (so that load from other processes
 * hits all solvers alike), after warm-up runs (warm caches). Prints one JSON object per
 * QP on stdout; bench/qp_bench.py builds, runs and summarises it.
 *
 * usage: qp_bench_main QPFILE [options]
 *   --reps R         timed repetitions per QP and solver (median reported)
 *   --warmup W       untimed repetitions first (at least 1)
 *   --budget S       at most about S seconds of timed runs per QP (all solvers together), but
 *                    never fewer than --min-reps repetitions
 *   --min-reps M
 *   --tol T          tolerance of every solver
 *   --iter-max K
 *   --sol FILE       write the primal solutions (float64, QP by QP, solver by solver)
 *   --hpipm NAME MODE EQMASK EQSCALE RICALG   add an HPIPM configuration (qp_bench_hpipm.h)
 *   --dopus NAME     add our solver (only when built with QPB_WITH_DOPUS)
 *   --dopus-alt NAME add the renamed copy of our solver built with other flags (QPB_WITH_DOPUS_ALT)
 *   --only NAME      time only that solver (for profilers)
 *   --rotate         start each repetition's round with the next solver (the order rotates, so
 *                    no solver always runs right after another one's cache traffic)
 *   --times          also print every repetition's solve time in repetition order ("t_reps"),
 *                    for ratios of the solves of one round (paired ratios)
 */
#define _POSIX_C_SOURCE 200112L
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "qp_bench_hpipm.h"
#include "qp_bench_qp.h"
#ifdef QPB_WITH_DOPUS
#include "qp_bench_dopus.h"
#endif
#ifdef QPB_WITH_DOPUS_ALT
/* a renamed copy of our solver (prefix qpbn_) compiled with other flags */
#include "qp_bench_qpbn.h"
#endif

#define MAX_SOLVERS 16

typedef struct {
    char name[64];
    int kind; /* 0 HPIPM, 1 ours, 2 ours compiled with the alternative flags, 3 ours warm-started
                 along the sequence (the closed loop's warm point and active-set start) */
    bench_hpipm_opts hopts;
    void *handle;
    double *times, *set_times; /* in repetition order */
    double *sorted;            /* a copy of times for the quantiles */
    int status, iterations;
    double res[4];
    int has_res;
    int inertia, augment; /* ours: inertia corrections and terminal augmentations */
    int factorizations;   /* ours: Riccati factorisations of the solve */
} solver_entry;

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static int cmp_double(const void *a, const void *b)
{
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static double quantile(double *v, int n, double q)
{
    qsort(v, (size_t)n, sizeof(double), cmp_double);
    {
        double pos = q * (double)(n - 1);
        int i = (int)floor(pos);
        double f = pos - (double)i;
        return i + 1 < n ? v[i] * (1.0 - f) + v[i + 1] * f : v[n - 1];
    }
}

static void print_num(double v)
{
    if (isfinite(v)) printf("%.6e", v);
    else printf("null");
}

#ifdef QPB_WITH_DOPUS
/* the solution the warm-started entry (kind 3) starts the next QP from */
static bench_dopus_warm *warm_chain;
#endif

static int solver_create(solver_entry *s, const bench_qp *qp, double tol, int iter_max)
{
    if (s->kind == 0) {
        s->hopts.tol = tol;
        s->hopts.iter_max = iter_max;
        s->handle = bench_hpipm_create(qp, &s->hopts);
        return s->handle == NULL;
    }
#ifdef QPB_WITH_DOPUS
    if (s->kind == 1 || s->kind == 3) s->handle = bench_dopus_create(qp, tol, iter_max);
    if (s->kind == 3 && s->handle != NULL) bench_dopus_warm_use((bench_dopus *)s->handle, warm_chain);
#endif
#ifdef QPB_WITH_DOPUS_ALT
    if (s->kind == 2) s->handle = bench_qpbn_create(qp, tol, iter_max);
#endif
    return s->handle == NULL;
}

static void solver_set(solver_entry *s, const bench_qp *qp)
{
    if (s->kind == 0) bench_hpipm_set_data((bench_hpipm *)s->handle, qp);
#ifdef QPB_WITH_DOPUS
    else if (s->kind == 1 || s->kind == 3) bench_dopus_set_data((bench_dopus *)s->handle, qp);
#endif
#ifdef QPB_WITH_DOPUS_ALT
    else if (s->kind == 2) bench_qpbn_set_data((bench_qpbn *)s->handle, qp);
#endif
}

static int solver_solve(solver_entry *s)
{
    if (s->kind == 0) return bench_hpipm_solve((bench_hpipm *)s->handle);
#ifdef QPB_WITH_DOPUS
    if (s->kind == 1 || s->kind == 3) return bench_dopus_solve((bench_dopus *)s->handle);
#endif
#ifdef QPB_WITH_DOPUS_ALT
    if (s->kind == 2) return bench_qpbn_solve((bench_qpbn *)s->handle);
#endif
    return -1;
}

static void solver_finish(solver_entry *s, double *dw)
{
    s->has_res = 0;
    if (s->kind == 0) {
        bench_hpipm *h = (bench_hpipm *)s->handle;
        s->iterations = bench_hpipm_iterations(h);
        bench_hpipm_residuals(h, s->res);
        s->has_res = 1;
        bench_hpipm_primal(h, dw);
        bench_hpipm_free(h);
    }
#ifdef QPB_WITH_DOPUS
    else if (s->kind == 1 || s->kind == 3) {
        bench_dopus *d = (bench_dopus *)s->handle;
        if (s->kind == 3) bench_dopus_warm_keep(warm_chain, d);
        s->iterations = bench_dopus_iterations(d);
        s->has_res = bench_dopus_residuals(d, s->res) == 0;
        bench_dopus_corrections(d, &s->inertia, &s->augment);
        s->factorizations = bench_dopus_factorizations(d);
        bench_dopus_primal(d, dw);
        bench_dopus_free(d);
    }
#endif
#ifdef QPB_WITH_DOPUS_ALT
    else if (s->kind == 2) {
        bench_qpbn *d = (bench_qpbn *)s->handle;
        s->iterations = bench_qpbn_iterations(d);
        s->has_res = bench_qpbn_residuals(d, s->res) == 0;
        bench_qpbn_corrections(d, &s->inertia, &s->augment);
        s->factorizations = bench_qpbn_factorizations(d);
        bench_qpbn_primal(d, dw);
        bench_qpbn_free(d);
    }
#endif
    s->handle = NULL;
}

int main(int argc, char **argv)
{
    solver_entry sv[MAX_SOLVERS];
    int ns = 0, reps = 100, warmup = 10, iter_max = 100, min_reps = 20, i, q, nqp, rotate = 0, print_times = 0;
    double tol = 1e-8, count, budget = 1e30;
    const char *qpfile = NULL, *solfile = NULL, *only = NULL;
    const char *warm_resets = ""; /* comma-separated QP indices where the warm chain starts cold */
    FILE *f, *fsol = NULL;

    memset(sv, 0, sizeof(sv));
    for (i = 1; i < argc; ++i) {
        if (!strcmp(argv[i], "--reps") && i + 1 < argc) reps = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--warmup") && i + 1 < argc) warmup = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--tol") && i + 1 < argc) tol = atof(argv[++i]);
        else if (!strcmp(argv[i], "--budget") && i + 1 < argc) budget = atof(argv[++i]);
        else if (!strcmp(argv[i], "--min-reps") && i + 1 < argc) min_reps = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--iter-max") && i + 1 < argc) iter_max = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--sol") && i + 1 < argc) solfile = argv[++i];
        else if (!strcmp(argv[i], "--only") && i + 1 < argc) only = argv[++i];
        else if (!strcmp(argv[i], "--rotate")) rotate = 1;
        else if (!strcmp(argv[i], "--times")) print_times = 1;
        else if (!strcmp(argv[i], "--hpipm") && i + 5 < argc && ns < MAX_SOLVERS) {
            solver_entry *s = &sv[ns++];
            strncpy(s->name, argv[i + 1], sizeof(s->name) - 1);
            s->kind = 0;
            s->hopts.mode = atoi(argv[i + 2]);
            s->hopts.eq_mask = atoi(argv[i + 3]);
            s->hopts.eq_scale = atof(argv[i + 4]);
            s->hopts.ric_alg = atoi(argv[i + 5]);
            i += 5;
        } else if (!strcmp(argv[i], "--dopus-alt") && i + 1 < argc && ns < MAX_SOLVERS) {
#ifdef QPB_WITH_DOPUS_ALT
            solver_entry *s = &sv[ns++];
            strncpy(s->name, argv[i + 1], sizeof(s->name) - 1);
            s->kind = 2;
            i += 1;
#else
            fprintf(stderr, "qp_bench_main: built without the alternative build of our solver\n");
            return 2;
#endif
        } else if (!strcmp(argv[i], "--dopus-warm") && i + 2 < argc && ns < MAX_SOLVERS) {
#ifdef QPB_WITH_DOPUS
            solver_entry *s = &sv[ns++];
            strncpy(s->name, argv[i + 1], sizeof(s->name) - 1);
            s->kind = 3;
            warm_resets = argv[i + 2];
            i += 2;
#else
            fprintf(stderr, "qp_bench_main: built without our solver (QPB_WITH_DOPUS)\n");
            return 2;
#endif
        } else if (!strcmp(argv[i], "--dopus") && i + 1 < argc && ns < MAX_SOLVERS) {
#ifdef QPB_WITH_DOPUS
            solver_entry *s = &sv[ns++];
            strncpy(s->name, argv[i + 1], sizeof(s->name) - 1);
            s->kind = 1;
            i += 1;
#else
            fprintf(stderr, "qp_bench_main: built without our solver (QPB_WITH_DOPUS)\n");
            return 2;
#endif
        } else if (argv[i][0] != '-' && qpfile == NULL) qpfile = argv[i];
        else {
            fprintf(stderr, "qp_bench_main: bad argument '%s'\n", argv[i]);
            return 2;
        }
    }
    if (warmup < 1) warmup = 1;
    if (min_reps > reps) min_reps = reps;
    if (qpfile == NULL || ns == 0 || reps < 1 || min_reps < 1) {
        fprintf(stderr, "usage: qp_bench_main QPFILE [--reps R] [--warmup W] [--tol T] [--iter-max K] "
                        "[--sol FILE] [--only NAME] (--hpipm NAME MODE EQMASK EQSCALE RICALG | --dopus NAME | "
                        "--dopus-warm NAME RESETS)...\n");
        return 2;
    }
    if (only != NULL) {
        int keep = 0;
        for (i = 0; i < ns; ++i)
            if (!strcmp(sv[i].name, only)) sv[keep++] = sv[i];
        ns = keep;
        if (ns == 0) { fprintf(stderr, "qp_bench_main: no solver named '%s'\n", only); return 2; }
    }
    f = fopen(qpfile, "rb");
    if (f == NULL) { fprintf(stderr, "qp_bench_main: cannot open %s\n", qpfile); return 2; }
    if (fread(&count, sizeof(double), 1, f) != 1) { fprintf(stderr, "qp_bench_main: empty file\n"); return 2; }
    nqp = (int)count;
    if (solfile != NULL && (fsol = fopen(solfile, "wb")) == NULL) {
        fprintf(stderr, "qp_bench_main: cannot write %s\n", solfile);
        return 2;
    }
    for (i = 0; i < ns; ++i) {
        sv[i].times = (double *)malloc((size_t)reps * sizeof(double));
        sv[i].set_times = (double *)malloc((size_t)reps * sizeof(double));
        sv[i].sorted = (double *)malloc((size_t)reps * sizeof(double));
        if (!sv[i].times || !sv[i].set_times || !sv[i].sorted) return 3;
    }

#ifdef QPB_WITH_DOPUS
    warm_chain = bench_dopus_warm_new();
    if (warm_chain == NULL) return 3;
#endif
    for (q = 0; q < nqp; ++q) {
        bench_qp qp;
        double *dw;
        int reps_done;
        int r, n, rc = bench_qp_read(f, &qp);
        if (rc != 0) { fprintf(stderr, "qp_bench_main: QP %d unreadable (code %d)\n", q, rc); return 3; }
        n = qp.N * (qp.nx + qp.nu) + qp.nx;
        dw = (double *)calloc((size_t)n, sizeof(double));
#ifdef QPB_WITH_DOPUS
        {
            /* a new sequence starts cold at each listed index */
            const char *p = warm_resets;
            while (*p) {
                if (atoi(p) == q) bench_dopus_warm_reset(warm_chain);
                while (*p && *p != ',') ++p;
                if (*p == ',') ++p;
            }
        }
#else
        (void)warm_resets;
#endif
        for (i = 0; i < ns; ++i)
            if (solver_create(&sv[i], &qp, tol, iter_max)) {
                fprintf(stderr, "qp_bench_main: solver %s could not take QP %d\n", sv[i].name, q);
                return 3;
            }
        {
            int nrep = reps;
            double round_time = 0.0;
            for (r = 0; r < warmup + nrep; ++r) {
                double tr = now();
                int o;
                for (o = 0; o < ns; ++o) {
                    double t0, t1, t2;
                    i = rotate ? (o + r) % ns : o;
                    t0 = now();
                    solver_set(&sv[i], &qp);
                    t1 = now();
                    sv[i].status = solver_solve(&sv[i]);
                    t2 = now();
                    if (r >= warmup) {
                        sv[i].set_times[r - warmup] = t1 - t0;
                        sv[i].times[r - warmup] = t2 - t1;
                    }
                }
                /* after the warm-up, cap the repetitions by the time budget */
                if (r == warmup - 1) {
                    round_time = now() - tr;
                    if (round_time * (double)nrep > budget) {
                        nrep = (int)(budget / round_time);
                        if (nrep < min_reps) nrep = min_reps;
                    }
                }
            }
            reps_done = nrep;
        }
        printf("{\"qp\": %d, \"N\": %d, \"solvers\": {", q, qp.N);
        for (i = 0; i < ns; ++i) {
            solver_entry *s = &sv[i];
            double med, q25, q75, tmin, tset;
            memcpy(s->sorted, s->times, (size_t)reps_done * sizeof(double));
            med = quantile(s->sorted, reps_done, 0.5);
            q25 = quantile(s->sorted, reps_done, 0.25);
            q75 = quantile(s->sorted, reps_done, 0.75);
            tmin = s->sorted[0];
            tset = quantile(s->set_times, reps_done, 0.5);
            solver_finish(s, dw);
            if (fsol != NULL) fwrite(dw, sizeof(double), (size_t)n, fsol);
            printf("%s\"%s\": {\"status\": %d, \"iterations\": %d, \"reps\": %d, \"t_median\": ",
                   i ? ", " : "", s->name, s->status, s->iterations, reps_done);
            print_num(med);
            printf(", \"t_q25\": "); print_num(q25);
            printf(", \"t_q75\": "); print_num(q75);
            printf(", \"t_min\": "); print_num(tmin);
            printf(", \"t_set_median\": "); print_num(tset);
            printf(", \"objective\": "); print_num(bench_qp_objective(&qp, dw));
            printf(", \"infeasibility\": "); print_num(bench_qp_infeasibility(&qp, dw));
            if (s->kind != 0)
                printf(", \"inertia_corrections\": %d, \"terminal_augmentations\": %d, \"factorizations\": %d",
                       s->inertia, s->augment, s->factorizations);
            if (print_times) {
                int j;
                printf(", \"t_reps\": [");
                for (j = 0; j < reps_done; ++j) { if (j) printf(", "); print_num(s->times[j]); }
                printf("]");
            }
            if (s->has_res) {
                int j;
                printf(", \"residuals\": [");
                for (j = 0; j < 4; ++j) { if (j) printf(", "); print_num(s->res[j]); }
                printf("]");
            }
            printf("}");
        }
        printf("}}\n");
        fflush(stdout);
        free(dw);
        bench_qp_free(&qp);
    }
    fclose(f);
    if (fsol != NULL) fclose(fsol);
    for (i = 0; i < ns; ++i) { free(sv[i].times); free(sv[i].set_times); free(sv[i].sorted); }
    return 0;
}
