/* A realistic run of a generated solver, for the sanitizer test (tests/test_sanitizers.py):
 * the same program is built plainly and with -fsanitize=address,undefined, and the two
 * outputs must agree to round-off with no sanitizer report.
 *
 *   driver XFIXED[nx] PUSH[nx]
 *
 * 1. fixed mode: init (nominal guess when generated, else the OCP file's guess) at the
 *    default x0, then feedback(XFIXED) / prepare / kkt_eval, ITER_FIXED times;
 * 2. fixed mode, Gauss-Newton (when available) with the projected regularisation, from the
 *    OCP file's guess: the Jacobi path and the cold start;
 * 3. receding mode: the closed loop against the generated discrete model (stage_eval, the
 *    integrator of the OCP), pushed by PUSH at step PUSH_STEP;
 * 4. bad inputs: every call prints its status ("bad <label> <status>"), the test compares
 *    them with the documented codes.
 * Every number is printed with 17 significant digits. Exit status 0 unless a call that must
 * succeed fails. */
#include <limits.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "solver_api.h"

#define ITER_FIXED 8
#define ITER_GN 5
#define STEPS 25
#define PUSH_STEP 5

static solver_t s;
static API(settings) st;
static API(fun_work) plant_work;

/* update_settings with one or two fields changed from the current settings */
#define UPDATE(field, value) (API(get_settings)(&s, &st), st.field = (value), API(update_settings)(&s, &st))
#define UPDATE2(f1, v1, f2, v2)                                                                              \
    (API(get_settings)(&s, &st), st.f1 = (v1), st.f2 = (v2), API(update_settings)(&s, &st))

static int info_int(int which)
{
    API(info) info;
    API(get_info)(&s, &info);
    return which == 0 ? info.qp_status : info.ring_head;
}

static void print_vec(const char *label, const double *v, int n)
{
    int i;
    printf("%s", label);
    for (i = 0; i < n; ++i) {
        printf(" %.17g", v[i]);
    }
    printf("\n");
}

static void print_iterate(const char *phase)
{
    static double x[(N_ + 1) * NX], u[N_ * NU], lam[(N_ + 1) * NX], mu_b[N_ * NW];
    char label[64];
    API(get_x)(&s, x);
    API(get_u)(&s, u);
    API(get_lam)(&s, lam);
    API(get_mu_b)(&s, mu_b);
    sprintf(label, "%s x", phase);
    print_vec(label, x, (N_ + 1) * NX);
    sprintf(label, "%s u", phase);
    print_vec(label, u, N_ * NU);
    sprintf(label, "%s lam", phase);
    print_vec(label, lam, (N_ + 1) * NX);
    sprintf(label, "%s mu_b", phase);
    print_vec(label, mu_b, N_ * NW);
}

static int must(int status, const char *what)
{
    if (status != K(OK)) {
        fprintf(stderr, "driver: %s failed: %s (status %d)\n", what, API(status_string)(status), status);
        exit(2);
    }
    return status;
}

static int init_warm(const double *xhat0)
{
#if K(HAS_NOMINAL)
    return API(init_nominal)(&s, xhat0);
#else
    return API(init)(&s, xhat0, NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL);
#endif
}

/* one iteration: feedback, prepare, kkt; prints the statuses, u0 and the KKT parts */
static int iterate(const char *phase, int it, const double *xhat0, double *u0)
{
    double kkt4[4] = {0.0, 0.0, 0.0, 0.0};
    int recomputed[N_], n, i, fb, pr = -1, kk = -1;
    fb = API(feedback)(&s, xhat0, u0);
    if (fb == K(OK) || fb == K(ERR_QP)) {
        pr = API(prepare)(&s);
    }
    if (pr == K(OK)) {
        kk = API(kkt_eval)(&s, xhat0, kkt4);
    }
    printf("%s %d status %d %d %d qp %d", phase, it, fb, pr, kk, info_int(0));
    print_vec(" u0", u0, NU);
    print_vec(" kkt", kkt4, 4);
    n = API(get_recomputed)(&s, recomputed);
    printf("%s %d recomputed", phase, it);
    for (i = 0; i < n; ++i) {
        printf(" %d", recomputed[i]);
    }
    printf(" head %d\n", info_int(1));
    return fb;
}

static void bad(const char *label, int status)
{
    printf("bad %s %d\n", label, status);
}

int main(int argc, char **argv)
{
    double xfixed[NX], push[NX], x0[NX], xhat[NX], xnext[NX], u0[NU];
    static double guess_x[(N_ + 1) * NX], big[(N_ + 1) * D(NP)];
    double nan = NAN, inf = INFINITY, kkt4[4];
    int i, k, rc;

    if (argc != 1 + 2 * NX) {
        fprintf(stderr, "usage: driver XFIXED[%d] PUSH[%d]\n", NX, NX);
        return 2;
    }
    for (i = 0; i < NX; ++i) {
        xfixed[i] = strtod(argv[1 + i], NULL);
        push[i] = strtod(argv[1 + NX + i], NULL);
        x0[i] = API(x0_default)[i];
    }
    printf("problem %s N %d nx %d nu %d\n", API(name)(), N_, NX, NU);
    memset(u0, 0, sizeof u0);

    /* 1. fixed xhat0, warm start */
    API(settings_default)(&st);
    st.mode = K(MODE_FIXED);
    st.M = 1;
    st.qp_tol = 1e-12;
    must(API(setup)(&s, &st), "setup");
    must(init_warm(x0), "init");
    for (k = 1; k <= ITER_FIXED; ++k) {
        iterate("fixed", k, xfixed, u0);
    }
    print_iterate("fixed");

    /* 2. Gauss-Newton (when the cost is least squares), projected, from the OCP file's guess */
    API(settings_default)(&st);
    st.mode = K(MODE_FIXED);
    if (K(HAS_GN)) {
        st.hessian = K(HESSIAN_GAUSS_NEWTON);
    }
    st.regularization = K(REG_PROJECT);
    st.reg_eps = 1e-4;
    st.M = N_ - 1;
    must(API(setup)(&s, &st), "setup");
    must(API(init)(&s, x0, NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL), "init");
    for (k = 1; k <= ITER_GN; ++k) {
        iterate("gn", k, x0, u0);
    }
    print_iterate("gn");

    /* 3. receding horizon against the discrete model, one push */
    must(API(setup)(&s, NULL), "setup");
    must(init_warm(x0), "init");
    for (i = 0; i < NX; ++i) {
        xhat[i] = x0[i];
    }
    for (k = 1; k <= STEPS; ++k) {
        if (k == PUSH_STEP) {
            for (i = 0; i < NX; ++i) {
                xhat[i] += push[i];
            }
        }
        /* a failed feedback writes the fallback control to u0 (docs/algorithm.md section 9) */
        iterate("receding", k, xhat, u0);
        rc = API(simulate)(xhat, u0, NULL, xnext, &plant_work);
        if (rc != K(OK)) {
            fprintf(stderr, "driver: the model failed to evaluate\n");
            return 2;
        }
        for (i = 0; i < NX; ++i) {
            xhat[i] = xnext[i];
        }
    }
    print_iterate("receding");

    /* 4. bad inputs: statuses only (the iterate is compared above and by the fuzz harness) */
    must(API(setup)(&s, NULL), "setup");
    bad("feedback_before_init", API(feedback)(&s, x0, u0));
    bad("prepare_before_init", API(prepare)(&s));
    bad("kkt_before_init", API(kkt_eval)(&s, x0, kkt4));
    xhat[0] = nan;
    for (i = 1; i < NX; ++i) {
        xhat[i] = x0[i];
    }
    bad("init_nan_xhat0", API(init)(&s, xhat, NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL));
    for (k = 0; k <= N_; ++k) {
        for (i = 0; i < NX; ++i) {
            guess_x[k * NX + i] = API(guess_x)[k][i];
        }
    }
    guess_x[3 * NX + 1] = inf;
    bad("init_inf_guess_x", API(init)(&s, x0, guess_x, NULL, NULL, NULL, NULL, NULL, NULL, NULL));
    bad("init_nominal", init_warm(x0));
    bad("prepare_after_init", API(prepare)(&s));
    bad("feedback_null_xhat0", API(feedback)(&s, NULL, u0));
    bad("feedback_nan_xhat0", API(feedback)(&s, xhat, u0));
    xhat[0] = -inf;
    bad("feedback_minus_inf_xhat0", API(feedback)(&s, xhat, u0));
    bad("kkt_nan_xhat0", API(kkt_eval)(&s, xhat, kkt4));
    bad("feedback", API(feedback)(&s, x0, u0));
    bad("feedback_twice", API(feedback)(&s, x0, u0));
    bad("prepare", API(prepare)(&s));
    bad("prepare_twice", API(prepare)(&s));
    bad("set_M_negative", UPDATE(M, -1));
    bad("set_M_N", UPDATE(M, N_));
    bad("set_M_int_max", UPDATE(M, INT_MAX));
    bad("set_mode_2", UPDATE(mode, 2));
    bad("set_hessian_minus_1", UPDATE(hessian, -1));
    bad("set_regularization_3", UPDATE2(regularization, 3, reg_eps, 1e-4));
    bad("set_regularization_eps_0", UPDATE2(regularization, K(REG_MIRROR), reg_eps, 0.0));
    bad("set_regularization_eps_nan", UPDATE2(regularization, K(REG_MIRROR), reg_eps, nan));
    bad("set_cost_hessian_2", UPDATE(cost_hessian, 2));
    bad("set_lm_negative", UPDATE2(lm_auto, 0, lm, -1e-3));
    bad("set_lm_inf", UPDATE2(lm_auto, 0, lm, inf));
    bad("set_qp_tol_0", UPDATE(qp_tol, 0.0));
    bad("set_qp_tol_nan", UPDATE(qp_tol, nan));
    bad("set_qp_max_iter_0", UPDATE(qp_max_iter, 0));
    bad("set_qp_max_iter_int_min", UPDATE(qp_max_iter, INT_MIN));
    bad("set_parameters_node_minus_1", API(set_parameters_node)(&s, -1, big));
    bad("set_parameters_node_N_plus_1", API(set_parameters_node)(&s, N_ + 1, big));
    for (i = 0; i < (N_ + 1) * D(NP); ++i) {
        big[i] = nan;
    }
    /* without parameters (np = 0) there is nothing to check: OK */
    bad("set_parameters_nan", API(set_parameters)(&s, big));
    bad("set_parameters_null", API(set_parameters)(&s, NULL));
    bad("set_parameters_node_nan", API(set_parameters_node)(&s, 0, big));
    bad("init_nominal_again", init_warm(x0));
    bad("status_string_unknown", strcmp(API(status_string)(12345), "unknown status") == 0 ? 0 : -1);
    bad("final_feedback", API(feedback)(&s, x0, u0));
    print_vec("final u0", u0, NU);
    printf("ok\n");
    return 0;
}
