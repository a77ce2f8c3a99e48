/* Standalone run of the 'dopus' solver, no Python: init at the default x0 (from the
 * generated nominal solution when there is one, else from the OCP file's guess), then
 * feedback/prepare iterations in fixed mode (convergence at a fixed x0) and in receding
 * mode (closed loop on the discrete model phi). Prints u0, the KKT measure and the status
 * of every iteration; exits nonzero on the first failure. */
#include <math.h>
#include <stdio.h>

#include "dopus_problem.h"
#include "dopus_solver.h"

#define ITERATIONS 10

static dopus_solver solver;
static dopus_fun_work plant_work;

static void print_vector(const char *label, const dopus_real *v, int n)
{
    int i;
    printf(" %s", label);
    for (i = 0; i < n; ++i) {
        printf(" %.17g", (double)v[i]);
    }
}

static int report(const char *phase, int iter, int status, const dopus_real *u0, const dopus_real *kkt4)
{
    dopus_real kkt = dopus_fmax(dopus_fmax(kkt4[0], kkt4[1]), dopus_fmax(kkt4[2], kkt4[3]));
    printf("%s %d status %d", phase, iter, status);
    print_vector("u0", u0, DOPUS_NU);
    printf(" kkt %.17g\n", (double)kkt);
    if (status != DOPUS_OK || !isfinite(kkt)) {
        fprintf(stderr, "main_dopus: %s iteration %d failed: %s\n", phase, iter, dopus_status_string(status));
        return 1;
    }
    return 0;
}

/* one phase: init at x0, then feedback/prepare ITERATIONS times; in receding mode the
 * next measurement is the model's prediction phi(x0, u0) */
static int run(const char *phase, int mode)
{
    dopus_real xhat0[DOPUS_NX], xnext[DOPUS_NX], u0[DOPUS_NU], kkt4[4];
    dopus_settings settings;
    int i, k, status;

    for (i = 0; i < DOPUS_NX; ++i) {
        xhat0[i] = dopus_x0_default[i];
    }
    for (i = 0; i < DOPUS_NU; ++i) {
        u0[i] = DOPUS_R(0.0);
    }
    dopus_settings_default(&settings); /* the OCP file's options */
    settings.mode = mode;
    status = dopus_setup(&solver, &settings);
#if DOPUS_HAS_NOMINAL
    if (status == DOPUS_OK) {
        status = dopus_init_nominal(&solver, xhat0);
    }
#else
    if (status == DOPUS_OK) {
        status = dopus_init(&solver, xhat0, NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL);
    }
#endif
    kkt4[0] = kkt4[1] = kkt4[2] = kkt4[3] = NAN;
    if (status == DOPUS_OK) {
        status = dopus_kkt_eval(&solver, xhat0, kkt4);
    }
    if (report(phase, 0, status, u0, kkt4)) {
        return 1;
    }
    for (k = 1; k <= ITERATIONS; ++k) {
        status = dopus_feedback(&solver, xhat0, u0);
        if (status == DOPUS_OK && mode == DOPUS_MODE_RECEDING) {
            if (dopus_simulate(xhat0, u0, NULL, xnext, &plant_work) != DOPUS_OK) {
                fprintf(stderr, "main_dopus: the model failed to evaluate\n");
                return 1;
            }
            for (i = 0; i < DOPUS_NX; ++i) {
                xhat0[i] = xnext[i];
            }
        }
        if (status == DOPUS_OK) {
            status = dopus_prepare(&solver);
        }
        if (status == DOPUS_OK) {
            status = dopus_kkt_eval(&solver, xhat0, kkt4);
        }
        if (report(phase, k, status, u0, kkt4)) {
            return 1;
        }
    }
    return 0;
}

int main(void)
{
    printf("problem %s N %d nx %d nu %d nominal %d sizeof %lu\n", dopus_name(), DOPUS_N, DOPUS_NX, DOPUS_NU,
           DOPUS_HAS_NOMINAL, (unsigned long)dopus_solver_sizeof());
    if (run("fixed", DOPUS_MODE_FIXED) || run("receding", DOPUS_MODE_RECEDING)) {
        return 1;
    }
    printf("ok\n");
    return 0;
}
