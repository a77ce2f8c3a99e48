/* Standalone run of the 'dopus' solver, no Python: init at the default x0 (from the
 * generated nominal solution when there is one, else from the OCP file's guess), then
 * feedback/prepare iterations in fixed mode (convergence at a fixed x0) and in receding
 * mode (closed loop on the discrete model phi). Prints u0, the KKT measure and the status
 * of every iteration; exits nonzero on the first failure. */
#include <math.h>
#include <stdio.h>

#include "robot_arm_problem.h"
#include "robot_arm_solver.h"

#define ITERATIONS 10

static robot_arm_solver solver;
static robot_arm_fun_work plant_work;

static void print_vector(const char *label, const robot_arm_real *v, int n)
{
    int i;
    printf(" %s", label);
    for (i = 0; i < n; ++i) {
        printf(" %.17g", (double)v[i]);
    }
}

static int report(const char *phase, int iter, int status, const robot_arm_real *u0, const robot_arm_real *kkt4)
{
    robot_arm_real kkt = robot_arm_fmax(robot_arm_fmax(kkt4[0], kkt4[1]), robot_arm_fmax(kkt4[2], kkt4[3]));
    printf("%s %d status %d", phase, iter, status);
    print_vector("u0", u0, ROBOT_ARM_NU);
    printf(" kkt %.17g\n", (double)kkt);
    if (status != ROBOT_ARM_OK || !isfinite(kkt)) {
        fprintf(stderr, "main_dopus: %s iteration %d failed: %s\n", phase, iter, robot_arm_status_string(status));
        return 1;
    }
    return 0;
}

/* one phase: init at x0, then feedback/prepare ITERATIONS times; in receding mode the
 * next measurement is the model's prediction phi(x0, u0) */
static int run(const char *phase, int mode)
{
    robot_arm_real xhat0[ROBOT_ARM_NX], xnext[ROBOT_ARM_NX], u0[ROBOT_ARM_NU], kkt4[4];
    robot_arm_settings settings;
    int i, k, status;

    for (i = 0; i < ROBOT_ARM_NX; ++i) {
        xhat0[i] = robot_arm_x0_default[i];
    }
    for (i = 0; i < ROBOT_ARM_NU; ++i) {
        u0[i] = ROBOT_ARM_R(0.0);
    }
    robot_arm_settings_default(&settings); /* the OCP file's options */
    settings.mode = mode;
    status = robot_arm_setup(&solver, &settings);
#if ROBOT_ARM_HAS_NOMINAL
    if (status == ROBOT_ARM_OK) {
        status = robot_arm_init_nominal(&solver, xhat0);
    }
#else
    if (status == ROBOT_ARM_OK) {
        status = robot_arm_init(&solver, xhat0, NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL);
    }
#endif
    kkt4[0] = kkt4[1] = kkt4[2] = kkt4[3] = NAN;
    if (status == ROBOT_ARM_OK) {
        status = robot_arm_kkt_eval(&solver, xhat0, kkt4);
    }
    if (report(phase, 0, status, u0, kkt4)) {
        return 1;
    }
    for (k = 1; k <= ITERATIONS; ++k) {
        status = robot_arm_feedback(&solver, xhat0, u0);
        if (status == ROBOT_ARM_OK && mode == ROBOT_ARM_MODE_RECEDING) {
            if (robot_arm_simulate(xhat0, u0, NULL, xnext, &plant_work) != ROBOT_ARM_OK) {
                fprintf(stderr, "main_dopus: the model failed to evaluate\n");
                return 1;
            }
            for (i = 0; i < ROBOT_ARM_NX; ++i) {
                xhat0[i] = xnext[i];
            }
        }
        if (status == ROBOT_ARM_OK) {
            status = robot_arm_prepare(&solver);
        }
        if (status == ROBOT_ARM_OK) {
            status = robot_arm_kkt_eval(&solver, xhat0, kkt4);
        }
        if (report(phase, k, status, u0, kkt4)) {
            return 1;
        }
    }
    return 0;
}

int main(void)
{
    printf("problem %s N %d nx %d nu %d nominal %d sizeof %lu\n", robot_arm_name(), ROBOT_ARM_N, ROBOT_ARM_NX, ROBOT_ARM_NU,
           ROBOT_ARM_HAS_NOMINAL, (unsigned long)robot_arm_solver_sizeof());
    if (run("fixed", ROBOT_ARM_MODE_FIXED) || run("receding", ROBOT_ARM_MODE_RECEDING)) {
        return 1;
    }
    printf("ok\n");
    return 0;
}
