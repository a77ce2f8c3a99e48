/* A byte copy of the solver struct is a complete solver (tests/test_struct_copy.py): built
 * with -fsanitize=address,undefined, so a copy that still read the original's memory would
 * be reported as a heap-use-after-free.
 *
 *   struct_copy
 *
 * For each copy point (after prepare: the QP is prepared; after feedback: the prepare is
 * due), a source solver on the heap and a reference solver that is never copied run the
 * same closed loop for WARMUP instants (the measurement of the next instant is the state
 * the solver's own plan predicts, pushed at some instants). Then the source is copied twice,
 * by struct assignment (to the heap) and by memcpy (to static memory), advanced AFTER
 * instants with other measurements, and freed. The two copies and the reference then run
 * RUN more instants: every status, every u0 and the final iterate must be bit for bit equal.
 * Prints one line per instant and "ok"; exit status 1 on the first difference. Only the
 * public API of <name>_solver.h is used. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "solver_api.h"

#define WARMUP 6
#define AFTER 2
#define RUN 20

static solver_t ref, copy_memcpy;

/* The measurement of the next instant: x_1 of the solver's plan, pushed at some instants. */
static void next_measurement(const solver_t *s, int k, double *xhat)
{
    static double x[(N_ + 1) * NX];
    int i;
    API(get_x)(s, x);
    for (i = 0; i < NX; ++i) {
        xhat[i] = x[NX + i];
        if (k % 7 == 3) {
            xhat[i] += 0.05 * (double)(i + 1) * (i % 2 ? -1.0 : 1.0);
        }
    }
}

/* One sampling instant: feedback (u0 out), the next measurement, prepare. Returns the two
 * statuses as 16 * feedback + prepare. */
static int instant(solver_t *s, double *xhat, double *u0, int k)
{
    int fb, pr;
    fb = API(feedback)(s, xhat, u0);
    next_measurement(s, k, xhat);
    pr = API(prepare)(s);
    return 16 * fb + pr;
}

static int setup(solver_t *s)
{
    if (API(setup)(s, NULL) != K(OK)) {
        return -1;
    }
#if K(HAS_NOMINAL)
    return API(init_nominal)(s, API(x0_default));
#else
    return API(init)(s, API(x0_default), NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL);
#endif
}

static int same(const double *a, const double *b, int n)
{
    return memcmp(a, b, (size_t)n * sizeof(double)) == 0;
}

static int run(int after_feedback)
{
    static double xr[NX], xs[NX], xa[NX], xm[NX], ur[NU], us[NU], ua[NU], um[NU];
    static double Xr[(N_ + 1) * NX], Xa[(N_ + 1) * NX], Xm[(N_ + 1) * NX];
    static double Ur[N_ * NU], Ua[N_ * NU], Um[N_ * NU];
    const char *where = after_feedback ? "after_feedback" : "after_prepare";
    solver_t *src = (solver_t *)malloc(sizeof(solver_t)), *copy_assign = (solver_t *)malloc(sizeof(solver_t));
    int k, i, sr, ss, sa, sm, ok = 1;

    if (!src || !copy_assign) {
        fprintf(stderr, "struct_copy: out of memory\n");
        return 0;
    }
    memset(src, 0, sizeof(solver_t));
    if (setup(src) != K(OK) || setup(&ref) != K(OK)) {
        fprintf(stderr, "struct_copy: init failed\n");
        return 0;
    }
    memcpy(xr, API(x0_default), sizeof xr);
    memcpy(xs, API(x0_default), sizeof xs);
    for (k = 0; k < WARMUP; ++k) {
        sr = instant(&ref, xr, ur, k);
        ss = instant(src, xs, us, k);
        if (sr != ss || !same(ur, us, NU)) {
            fprintf(stderr, "struct_copy: source and reference differ before the copy\n");
            return 0;
        }
    }
    if (after_feedback) { /* the copy point between feedback and prepare */
        sr = API(feedback)(&ref, xr, ur);
        ss = API(feedback)(src, xs, us);
        next_measurement(&ref, WARMUP, xr);
        next_measurement(src, WARMUP, xs);
        if (sr != ss || !same(ur, us, NU)) {
            fprintf(stderr, "struct_copy: source and reference differ before the copy\n");
            return 0;
        }
    }
    *copy_assign = *src;
    memcpy(&copy_memcpy, src, sizeof(solver_t));
    memcpy(xa, xs, sizeof xa);
    memcpy(xm, xs, sizeof xm);
    memcpy(ua, us, sizeof ua);
    memcpy(um, us, sizeof um);

    /* the source moves on with other measurements, then its memory is freed */
    if (after_feedback) {
        API(prepare)(src);
    }
    for (k = 0; k < AFTER; ++k) {
        for (i = 0; i < NX; ++i) {
            xs[i] += 0.1;
        }
        instant(src, xs, us, 100 + k);
    }
    memset(src, 0xff, sizeof(solver_t));
    free(src);

    for (k = 0; k < RUN && ok; ++k) {
        if (after_feedback && k == 0) {
            sr = API(prepare)(&ref);
            sa = API(prepare)(copy_assign);
            sm = API(prepare)(&copy_memcpy);
        } else {
            sr = instant(&ref, xr, ur, WARMUP + k);
            sa = instant(copy_assign, xa, ua, WARMUP + k);
            sm = instant(&copy_memcpy, xm, um, WARMUP + k);
        }
        printf("%s %d status %d %d %d u0", where, k, sr, sa, sm);
        for (i = 0; i < NU; ++i) {
            printf(" %.17g", ur[i]);
        }
        printf("\n");
        if (sr != sa || sr != sm || !same(ur, ua, NU) || !same(ur, um, NU) || !same(xr, xa, NX) ||
            !same(xr, xm, NX)) {
            fprintf(stderr, "struct_copy: %s: the copies differ from the reference at instant %d\n", where,
                    k);
            ok = 0;
        }
    }
    API(get_x)(&ref, Xr);
    API(get_x)(copy_assign, Xa);
    API(get_x)(&copy_memcpy, Xm);
    API(get_u)(&ref, Ur);
    API(get_u)(copy_assign, Ua);
    API(get_u)(&copy_memcpy, Um);
    if (ok && !(same(Xr, Xa, (N_ + 1) * NX) && same(Xr, Xm, (N_ + 1) * NX) && same(Ur, Ua, N_ * NU) &&
                same(Ur, Um, N_ * NU))) {
        fprintf(stderr, "struct_copy: %s: the final iterates differ\n", where);
        ok = 0;
    }
    if (ok) {
        printf("%s identical\n", where);
    }
    free(copy_assign);
    return ok;
}

int main(void)
{
    if (!run(0) || !run(1)) {
        return 1;
    }
    printf("ok\n");
    return 0;
}
