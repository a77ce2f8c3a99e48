/* libFuzzer harness on the public API of a generated solver (<name>_solver.h).
 *
 * The input is decoded into a sequence of calls in arbitrary order (init, init_nominal,
 * feedback with measurements that may hold NaN, Inf or huge values, prepare, kkt_eval,
 * every setting with arbitrary values, parameters, setup, a zeroed struct) and the
 * documented contracts are checked after every call; a violation aborts (a "crash" for
 * libFuzzer), and so does any AddressSanitizer / UndefinedBehaviorSanitizer report:
 *
 *  - every status is a code of enum <name>_status and equals the info's status;
 *  - the statuses the API defines exactly are predicted by a model of the calling order
 *    and of the argument checks (not initialised, not prepared, already prepared, invalid
 *    argument, non-finite input) and must be returned;
 *  - a failed call leaves the iterate bit-identical (a prepare that fails in a function
 *    evaluation leaves the iterate shifted, as documented); a failed setter leaves the
 *    setting; every setting reads back what the model holds;
 *  - feedback OK: u0 finite, equal to u_0 of the iterate and within the control bounds
 *    (up to the QP tolerance scaled as in dopus_qp.h); prepare OK: the recomputed set has
 *    M + 1 sorted stages ending in N-1, rho >= 0 and never NaN, ring_head advanced by one in
 *    receding mode; kkt OK: four non-negative parts, never NaN; the iterate finite after any
 *    successful call.
 *
 * Build (tests/test_sanitizers.py does it): the generated folder's sources with
 * -fsanitize=fuzzer-no-link,address,undefined, this file with -fsanitize=fuzzer,address,
 * undefined and the defines of solver_api.h. Input format: tests/fuzz/README.md. */
#include <float.h>
#include <limits.h>
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "solver_api.h"

#define MAX_CALLS 48

/* ---- input decoding ------------------------------------------------------------------ */

typedef struct {
    const uint8_t *p;
    size_t n;
} reader;

static unsigned rd_u8(reader *r)
{
    if (r->n == 0) {
        return 0;
    }
    r->n--;
    return *r->p++;
}

static double rd_double(reader *r)
{
    static const double table[] = {0.0,   1.0,    -1.0,   0.5,      1e-12,   1e-4, 1e6,
                                   1e300, -1e300, 1e-300, 4.9e-324, DBL_MAX, -0.0};
    unsigned t = rd_u8(r);
    double v;
    uint8_t b[8];
    int i;
    if (t < sizeof table / sizeof table[0]) {
        return table[t];
    }
    switch (t % 8) {
    case 0:
        return NAN;
    case 1:
        return INFINITY;
    case 2:
        return -INFINITY;
    case 3: /* raw bits */
        for (i = 0; i < 8; ++i) {
            b[i] = (uint8_t)rd_u8(r);
        }
        memcpy(&v, b, sizeof v);
        return v;
    default: /* a moderate number (-8, 8) in steps of 1/16 */
        return ((double)rd_u8(r) - 128.0) / 16.0;
    }
}

static int rd_int(reader *r)
{
    unsigned t = rd_u8(r);
    uint8_t b[4];
    uint32_t u;
    int i;
    switch (t % 12) {
    case 0:
        return 0;
    case 1:
        return 1;
    case 2:
        return -1;
    case 3:
        return N_ - 1;
    case 4:
        return N_;
    case 5:
        return N_ + 1;
    case 6:
        return INT_MAX;
    case 7:
        return INT_MIN;
    case 8:
        for (i = 0; i < 4; ++i) {
            b[i] = (uint8_t)rd_u8(r);
        }
        memcpy(&u, b, sizeof u);
        return (int)(u & 0x7fffffffu) * ((t & 16u) ? -1 : 1);
    default:
        return (int)(t / 12u) - 4; /* small: -4 .. 17 */
    }
}

/* a measurement: x0 itself, x0 plus a small step on some entries, one entry arbitrary, or
 * all arbitrary */
static void rd_state(reader *r, double *x)
{
    unsigned t = rd_u8(r);
    int i;
    for (i = 0; i < NX; ++i) {
        x[i] = API(x0_default)[i];
    }
    switch (t % 4) {
    case 0:
        break;
    case 1: { /* the same step (b - 128) * 1e-3 on the entries i with bit i % 8 of mask set */
        double step = ((double)rd_u8(r) - 128.0) * 1e-3;
        unsigned mask = rd_u8(r);
        for (i = 0; i < NX; ++i) {
            x[i] += ((mask >> (i % 8)) & 1u) ? step : 0.0;
        }
        break;
    }
    case 2:
        x[rd_u8(r) % NX] = rd_double(r);
        break;
    default:
        for (i = 0; i < NX; ++i) {
            x[i] = rd_double(r);
        }
        break;
    }
}

/* an array of n values: the base values, one entry arbitrary, or all the same arbitrary value */
static void rd_array(reader *r, double *a, const double *base, int n)
{
    unsigned t = rd_u8(r);
    double v;
    int i;
    for (i = 0; i < n; ++i) {
        a[i] = base ? base[i] : 0.0;
    }
    if (n == 0) {
        return;
    }
    switch (t % 3) {
    case 0:
        break;
    case 1:
        a[rd_u8(r) % (unsigned)n] = rd_double(r);
        break;
    default:
        v = rd_double(r);
        for (i = 0; i < n; ++i) {
            a[i] = (t & 4u) ? a[i] + v : v;
        }
        break;
    }
}

/* ---- the model and the checks ------------------------------------------------------- */

static solver_t s;
static void model_shift_parameters(void);
static int model_parameters_writable(void);

/* One setting at a time through the settings API (<name>_get_settings, <name>_update_settings)
 * and the info struct (<name>_get_info), so the harness drives every setting by itself. */
static API(settings) settings_now(void)
{
    API(settings) st;
    API(get_settings)(&s, &st);
    return st;
}

static API(info) info_now(void)
{
    API(info) info;
    API(get_info)(&s, &info);
    return info;
}

#define SETTER_INT(fn, field)                                                                                \
    static int fn(solver_t *sv, int v)                                                                       \
    {                                                                                                        \
        API(settings) st = settings_now();                                                                   \
        st.field = v;                                                                                        \
        return API(update_settings)(sv, &st);                                                                \
    }
#define SETTER_DOUBLE(fn, field)                                                                             \
    static int fn(solver_t *sv, double v)                                                                    \
    {                                                                                                        \
        API(settings) st = settings_now();                                                                   \
        st.field = v;                                                                                        \
        return API(update_settings)(sv, &st);                                                                \
    }
SETTER_INT(set_M, M)
SETTER_INT(set_mode, mode)
SETTER_INT(set_hessian, hessian)
SETTER_INT(set_cost_hessian, cost_hessian)
SETTER_INT(set_qp_max_iter, qp_max_iter)
SETTER_DOUBLE(set_qp_tol, qp_tol)

static int set_regularization(solver_t *sv, int v, double eps)
{
    API(settings) st = settings_now();
    st.regularization = v;
    st.reg_eps = eps;
    return API(update_settings)(sv, &st);
}

/* a fixed Levenberg-Marquardt term */
static int set_levenberg_marquardt(solver_t *sv, double lm)
{
    API(settings) st = settings_now();
    st.lm_auto = 0;
    st.lm = lm;
    return API(update_settings)(sv, &st);
}

static int set_recovery(solver_t *sv, int on, int failures)
{
    API(settings) st = settings_now();
    st.recovery = on;
    st.recovery_failures = failures;
    return API(update_settings)(sv, &st);
}

typedef struct {
    int initialized, qp_ready, prepare_due, shifted, p_shifted;
    int M, mode, hessian, regularization, cost_hessian, max_iter;
    double reg_eps, lm, tol;
    double p[(N_ + 1) * D(NP)];
} model;

typedef struct {
    double x[(N_ + 1) * NX], u[N_ * NU], lam[(N_ + 1) * NX], mu_g[N_ * D(NG)], mu_b[N_ * NW], mu_bN[NX],
        mu_r[D(NR)], nu[D(NE)];
    int head;
} iterate;

static model m;

/* the parameters move with the horizon once per sampling instant (receding mode): at the
 * first parameter write after a feedback, else at the prepare */
static void model_shift_parameters(void)
{
    if (m.mode == K(MODE_RECEDING) && !m.p_shifted) {
        memmove(m.p, &m.p[NP], (size_t)(N_ * NP) * sizeof(double));
        m.p_shifted = 1;
    }
}

/* parameters may be written before init or while a prepare is due (else the prepared QP
 * would read them one instant late: already-prepared) */
static int model_parameters_writable(void)
{
    if (!m.initialized) {
        return 1;
    }
    if (!m.prepare_due) {
        return 0;
    }
    model_shift_parameters();
    return 1;
}
static iterate before, after;
static int call_index;
static const char *call_name;
static int trace = -1; /* FUZZ_TRACE=1 in the environment prints every call */

static void fail(const char *what)
{
    fprintf(stderr, "contract violated after call %d (%s): %s\n", call_index, call_name, what);
    abort();
}

static void check(int ok, const char *what)
{
    if (!ok) {
        fail(what);
    }
}

static void read_iterate(iterate *it)
{
    API(get_x)(&s, it->x);
    API(get_u)(&s, it->u);
    API(get_lam)(&s, it->lam);
    API(get_mu_g)(&s, it->mu_g);
    API(get_mu_b)(&s, it->mu_b);
    API(get_mu_bN)(&s, it->mu_bN);
    API(get_mu_r)(&s, it->mu_r);
    API(get_nu)(&s, it->nu);
    it->head = info_now().ring_head;
}

static int same_bits(const iterate *a, const iterate *b)
{
    return memcmp(a->x, b->x, sizeof a->x) == 0 && memcmp(a->u, b->u, sizeof a->u) == 0 &&
           memcmp(a->lam, b->lam, sizeof a->lam) == 0 &&
           memcmp(a->mu_g, b->mu_g, NG * N_ * sizeof(double)) == 0 &&
           memcmp(a->mu_b, b->mu_b, sizeof a->mu_b) == 0 &&
           memcmp(a->mu_bN, b->mu_bN, sizeof a->mu_bN) == 0 &&
           memcmp(a->mu_r, b->mu_r, NR * sizeof(double)) == 0 &&
           memcmp(a->nu, b->nu, NE * sizeof(double)) == 0 && a->head == b->head;
}

static int all_finite(const double *v, int n)
{
    int i;
    for (i = 0; i < n; ++i) {
        if (!isfinite(v[i])) {
            return 0;
        }
    }
    return 1;
}

static int iterate_finite(const iterate *a)
{
    return all_finite(a->x, (N_ + 1) * NX) && all_finite(a->u, N_ * NU) &&
           all_finite(a->lam, (N_ + 1) * NX) && all_finite(a->mu_g, N_ * NG) &&
           all_finite(a->mu_b, N_ * NW) && all_finite(a->mu_bN, NX) && all_finite(a->mu_r, NR) &&
           all_finite(a->nu, NE);
}

/* the documented shift of prepare step 1 applied to a (receding mode) */
static int is_shift_of(const iterate *a, const iterate *b)
{
    int k, i;
    for (k = 0; k < N_; ++k) {
        for (i = 0; i < NX; ++i) {
            if (b->x[k * NX + i] != a->x[(k + 1) * NX + i] ||
                b->lam[k * NX + i] != a->lam[(k + 1) * NX + i]) {
                return 0;
            }
        }
    }
    for (k = 0; k + 1 < N_; ++k) {
        for (i = 0; i < NU; ++i) {
            if (b->u[k * NU + i] != a->u[(k + 1) * NU + i]) {
                return 0;
            }
        }
    }
    return b->head == (a->head + 1) % N_;
}

static void check_settings(void)
{
    double p[(N_ + 1) * D(NP)];
    API(settings) st = settings_now();
    API(info) info = info_now();
    check(st.M == m.M, "M reads back");
    check(st.mode == m.mode, "mode reads back");
    check(st.hessian == m.hessian, "hessian reads back");
    check(st.regularization == m.regularization, "regularization reads back");
    check(st.reg_eps == m.reg_eps, "reg_eps reads back");
    check(st.cost_hessian == m.cost_hessian, "cost_hessian reads back");
    check(!st.lm_auto && st.lm == m.lm && info.lm == m.lm, "lm reads back");
    check(st.qp_tol == m.tol, "qp_tol reads back");
    check(st.qp_max_iter == m.max_iter, "qp_max_iter reads back");
    check(info.initialized == m.initialized, "initialized follows the calling-order model");
    if (NP > 0) {
        API(get_parameters)(&s, p);
        check(memcmp(p, m.p, (N_ + 1) * NP * sizeof(double)) == 0, "parameters read back");
    }
}

/* The model describes the algorithm with a fixed Levenberg-Marquardt term and without the
 * automatic recovery (docs/algorithm.md sections 9 and 10 change the iterate on their own);
 * both are switched off after every reset of the settings. */
static void pin_automatic_features(void)
{
    set_recovery(&s, 0, 2);
    set_levenberg_marquardt(&s, 1e-4);
}

static void model_from_solver(void)
{
    API(settings) st = settings_now();
    m.M = st.M;
    m.mode = st.mode;
    m.hessian = st.hessian;
    m.regularization = st.regularization;
    m.reg_eps = st.reg_eps;
    m.cost_hessian = st.cost_hessian;
    m.lm = st.lm;
    m.tol = st.qp_tol;
    m.max_iter = st.qp_max_iter;
    m.initialized = m.qp_ready = m.prepare_due = m.shifted = m.p_shifted = 0;
    if (NP > 0) {
        API(get_parameters)(&s, m.p);
    }
}

/* the status of a call: a code of the enum, reported by get_status */
static void check_status(int st)
{
    if (trace) {
        fprintf(stderr, "call %d %s -> status %d\n", call_index, call_name, st);
    }
    check(st >= 0 && st <= STATUS_MAX, "status is a code of the enum");
    check(info_now().status == st, "the info's status is the status of the last call");
    check(API(status_string)(st) != NULL, "status string");
}

/* a numerical failure the caller cannot predict from the arguments */
static int numerical(int st)
{
    return st == K(ERR_QP) || st == K(ERR_NONFINITE_VALUE) || st == K(ERR_FUNCTION) ||
           st == K(ERR_REGULARIZATION);
}

static void after_init(int st, int expect_nonfinite, int expect_no_nominal)
{
    int rec[N_], n, k;
    check_status(st);
    if (expect_no_nominal) {
        check(st == K(ERR_NO_NOMINAL), "init_nominal without a nominal guess");
        check_settings();
        return;
    }
    if (expect_nonfinite) {
        check(st == K(ERR_NONFINITE_INPUT), "init with NaN/Inf input returns the non-finite status");
    } else {
        check(st == K(OK) || numerical(st), "init returns OK or a numerical failure");
    }
    /* any failed init leaves the solver uninitialised (documented: init re-starts) */
    m.initialized = st == K(OK);
    m.qp_ready = st == K(OK);
    m.prepare_due = m.shifted = m.p_shifted = 0;
    read_iterate(&after);
    if (st == K(OK)) {
        check(after.head == 0, "init: ring_head 0");
        n = API(get_recomputed)(&s, rec);
        check(n == N_, "init: every stage computed");
        for (k = 0; k < n; ++k) {
            check(rec[k] == k, "init: recomputed 0..N-1");
        }
        check(iterate_finite(&after), "init: iterate finite");
    } else if (st == K(ERR_NONFINITE_INPUT)) {
        check(same_bits(&before, &after), "init rejected for its input leaves the iterate");
    }
    check_settings();
}

static void do_init(reader *r, double *xhat)
{
    static double x[(N_ + 1) * NX], u[N_ * NU], lam[(N_ + 1) * NX], mu_g[N_ * D(NG)], mu_b[N_ * NW],
        mu_bN[NX], mu_r[D(NR)], nu[D(NE)];
    unsigned which = rd_u8(r);
    int nonfinite, st;
    const double *px = NULL, *pu = NULL, *plam = NULL, *pmg = NULL, *pmb = NULL, *pbN = NULL, *pr = NULL,
                 *pnu = NULL;
    rd_state(r, xhat);
    nonfinite = !(which & 4u) && !all_finite(xhat, NX); /* which & 4: xhat0 NULL (the default x0) */
    if (which & 1u) {
        rd_array(r, x, &API(guess_x)[0][0], (N_ + 1) * NX);
        rd_array(r, u, &API(guess_u)[0][0], N_ * NU);
        px = x;
        pu = u;
        nonfinite |= !all_finite(x, (N_ + 1) * NX) || !all_finite(u, N_ * NU);
    }
    if (which & 2u) {
        rd_array(r, lam, NULL, (N_ + 1) * NX);
        rd_array(r, mu_g, NULL, N_ * NG);
        rd_array(r, mu_b, NULL, N_ * NW);
        rd_array(r, mu_bN, NULL, NX);
        rd_array(r, mu_r, NULL, NR);
        rd_array(r, nu, NULL, NE);
        plam = lam;
        pmg = mu_g;
        pmb = mu_b;
        pbN = mu_bN;
        pr = mu_r;
        pnu = nu;
        nonfinite |= !all_finite(lam, (N_ + 1) * NX) || !all_finite(mu_g, N_ * NG) ||
                     !all_finite(mu_b, N_ * NW) || !all_finite(mu_bN, NX) || !all_finite(mu_r, NR) ||
                     !all_finite(nu, NE);
    }
    call_name = "init";
    st = API(init)(&s, (which & 4u) ? NULL : xhat, px, pu, plam, pmg, pmb, pbN, pr, pnu);
    after_init(st, nonfinite, 0);
}

static void do_feedback(reader *r, double *xhat)
{
    double u0[NU], lo, hi, scale, slack;
    unsigned flags = rd_u8(r);
    int st, i, finite;
    rd_state(r, xhat);
    finite = all_finite(xhat, NX) && !(flags & 1u);
    for (i = 0; i < NU; ++i) {
        u0[i] = -7.0; /* must stay when feedback fails */
    }
    call_name = "feedback";
    st = API(feedback)(&s, (flags & 1u) ? NULL : xhat, (flags & 2u) ? NULL : u0);
    check_status(st);
    read_iterate(&after);
    if (!m.initialized) {
        check(st == K(ERR_NOT_INITIALIZED), "feedback before init");
    } else if (!finite) {
        check(st == K(ERR_NONFINITE_INPUT), "feedback with NULL/NaN/Inf xhat0");
        if (m.mode == K(MODE_RECEDING)) {
            m.prepare_due = 1; /* the sampling instant has passed: its prepare is due */
            m.shifted = 0;
        }
    } else if (!m.qp_ready) {
        check(st == K(ERR_NOT_PREPARED), "feedback without a prepared QP");
        if (m.mode == K(MODE_RECEDING)) {
            m.prepare_due = 1; /* the instant has passed all the same: its prepare is due */
            m.shifted = 0;
        }
    } else {
        check(st == K(OK) || st == K(ERR_QP) || st == K(ERR_DIVERGED),
              "feedback returns OK, a QP failure or a rejected (diverged) step");
        m.prepare_due = 1;
        m.shifted = 0;
    }
    if (st != K(OK)) {
        check(same_bits(&before, &after), "a failed feedback leaves the iterate bit-identical");
        if (!(flags & 2u)) {
            for (i = 0; i < NU; ++i) {
                /* a failed instant still returns a safe control: the fallback, in bounds */
                check(u0[i] >= API(lbu)[i] && u0[i] <= API(ubu)[i],
                      "a failed feedback returns a control within the bounds");
            }
        }
    } else {
        m.qp_ready = 0;
        check(iterate_finite(&after), "feedback: iterate finite");
        check(after.head == before.head, "feedback does not move ring_head");
        /* the QP stops at its tolerance on residuals scaled by max(1, |bounds|, |values|) */
        scale = 1.0;
        for (i = 0; i < N_ * NU; ++i) {
            scale = fmax(scale, fmax(fabs(before.u[i]), fabs(after.u[i])));
        }
        for (i = 0; i < (N_ + 1) * NX; ++i) {
            scale = fmax(scale, fmax(fabs(before.x[i]), fabs(after.x[i])));
        }
        for (i = 0; i < NU; ++i) {
            lo = API(lbu)[i];
            hi = API(ubu)[i];
            scale = fmax(scale, fmax(isfinite(lo) ? fabs(lo) : 0.0, isfinite(hi) ? fabs(hi) : 0.0));
        }
        slack = 10.0 * m.tol * scale + 4.0 * DBL_EPSILON * scale;
        for (i = 0; i < NU; ++i) {
            check(isfinite(after.u[i]), "u0 finite");
            check(after.u[i] >= API(lbu)[i] - slack && after.u[i] <= API(ubu)[i] + slack,
                  "u0 within the control bounds");
            if (!(flags & 2u)) {
                /* docs/algorithm.md section 9: u0 is u_0 of the iterate clipped to the bounds
                 * (the QP meets the bounds to its tolerance only) */
                double clipped = fmin(fmax(after.u[i], API(lbu)[i]), API(ubu)[i]);
                if (!(u0[i] == clipped)) {
                    fprintf(stderr, "u0[%d] %.17g, u_0 of the iterate %.17g, bounds [%.17g, %.17g]\n", i,
                            u0[i], after.u[i], API(lbu)[i], API(ubu)[i]);
                }
                check(u0[i] == clipped, "u0 is u_0 of the iterate, clipped to the control bounds");
            }
        }
    }
    check_settings();
}

static void do_prepare(void)
{
    int st, rec[N_], n, k, shift_expected;
    double rho[N_];
    call_name = "prepare";
    shift_expected = m.mode == K(MODE_RECEDING) && !m.shifted;
    if (m.initialized && m.prepare_due) {
        model_shift_parameters();
    }
    st = API(prepare)(&s);
    check_status(st);
    read_iterate(&after);
    if (!m.initialized) {
        check(st == K(ERR_NOT_INITIALIZED), "prepare before init");
        check(same_bits(&before, &after), "prepare before init changes nothing");
    } else if (!m.prepare_due) {
        check(st == K(ERR_ALREADY_PREPARED), "prepare twice returns already-prepared");
        check(same_bits(&before, &after), "a refused prepare changes nothing");
    } else {
        check(st == K(OK) || st == K(ERR_NONFINITE_VALUE) || st == K(ERR_FUNCTION) ||
                  st == K(ERR_REGULARIZATION),
              "prepare returns OK or a function/regularisation failure");
        if (shift_expected) {
            check(is_shift_of(&before, &after), "prepare shifts once in receding mode");
            m.shifted = 1;
        } else if (st != K(OK)) {
            check(same_bits(&before, &after), "a failed prepare without a shift leaves the iterate");
        } else {
            check(after.head == before.head, "no shift in fixed mode or on a retry");
        }
        m.qp_ready = st == K(OK);
        if (st == K(OK)) {
            m.prepare_due = m.shifted = m.p_shifted = 0;
            check(iterate_finite(&after), "prepare: iterate finite");
            n = API(get_recomputed)(&s, rec);
            check(n == m.M + 1, "prepare recomputes M + 1 stages");
            check(rec[n - 1] == N_ - 1, "stage N-1 is always recomputed");
            for (k = 1; k < n; ++k) {
                check(rec[k - 1] < rec[k] && rec[k - 1] >= 0, "recomputed set sorted, unique");
            }
            API(get_rho)(&s, rho);
            for (k = 0; k < N_; ++k) {
                check(!isnan(rho[k]) && rho[k] >= 0.0, "rho >= 0, not NaN (+Inf: overflow, documented)");
            }
        }
    }
    check_settings();
}

static void do_kkt(reader *r, double *xhat)
{
    double kkt4[4] = {-1.0, -1.0, -1.0, -1.0};
    unsigned flags = rd_u8(r);
    int st, i, finite = 1;
    if (flags & 1u) {
        rd_state(r, xhat);
        finite = all_finite(xhat, NX);
    }
    call_name = "kkt_eval";
    st = API(kkt_eval)(&s, (flags & 1u) ? xhat : NULL, (flags & 2u) ? NULL : kkt4);
    check_status(st);
    read_iterate(&after);
    check(same_bits(&before, &after), "kkt_eval never changes the iterate");
    if (!m.initialized) {
        check(st == K(ERR_NOT_INITIALIZED), "kkt before init");
    } else if (!finite) {
        check(st == K(ERR_NONFINITE_INPUT), "kkt with NaN/Inf xhat0");
    } else {
        check(st == K(OK) || st == K(ERR_NONFINITE_VALUE) || st == K(ERR_FUNCTION),
              "kkt returns OK or a function failure");
    }
    if (st == K(OK) && !(flags & 2u)) {
        for (i = 0; i < 4; ++i) {
            /* +Inf is the overflow of a far-off iterate (documented), NaN never */
            check(!isnan(kkt4[i]) && kkt4[i] >= 0.0, "KKT parts >= 0, not NaN");
        }
        check(info_now().kkt_max == fmax(fmax(kkt4[0], kkt4[1]), fmax(kkt4[2], kkt4[3])),
              "kkt_max is the max");
    }
    check_settings();
}

/* a setter: its status must be predicted exactly; the setting changes only on OK */
static void after_setter(int st, int valid)
{
    check_status(st);
    check(st == (valid ? K(OK) : K(ERR_INVALID_ARGUMENT)), "setter status as documented");
    read_iterate(&after);
    check(same_bits(&before, &after), "a setter never changes the iterate");
}

/* A setter of one int (double) setting: the status as documented for the validity of the
 * value, the iterate unchanged, the model's field set when the value is valid. */
static void int_setter(const char *name, int (*set)(solver_t *, int), int v, int valid, int *field)
{
    call_name = name;
    after_setter(set(&s, v), valid);
    if (valid) {
        *field = v;
    }
}

static void double_setter(const char *name, int (*set)(solver_t *, double), double d, int valid,
                          double *field)
{
    call_name = name;
    after_setter(set(&s, d), valid);
    if (valid) {
        *field = d;
    }
}

static void do_setter(unsigned op, reader *r)
{
    int v = 0, st, valid, k;
    double d = 0.0;
    static double p[(N_ + 1) * D(NP)], p_default[(N_ + 1) * D(NP)];
    switch (op) {
    case 0:
        v = rd_int(r);
        int_setter("set_M", set_M, v, v >= 0 && v <= N_ - 1, &m.M);
        break;
    case 1:
        v = rd_int(r);
        int_setter("set_mode", set_mode, v, v == K(MODE_RECEDING) || v == K(MODE_FIXED), &m.mode);
        break;
    case 2:
        v = rd_int(r);
        int_setter("set_hessian", set_hessian, v,
                   v == K(HESSIAN_EXACT) || (v == K(HESSIAN_GAUSS_NEWTON) && K(HAS_GN)), &m.hessian);
        break;
    case 3:
        v = rd_int(r);
        d = rd_double(r);
        call_name = "set_regularization";
        valid = (v == K(REG_NONE) || v == K(REG_PROJECT) || v == K(REG_MIRROR)) && isfinite(d) && d > 0.0;
        st = set_regularization(&s, v, d);
        after_setter(st, valid);
        if (valid) {
            m.regularization = v;
            m.reg_eps = d;
        }
        break;
    case 4:
        v = rd_int(r);
        int_setter("set_cost_hessian", set_cost_hessian, v, v == 0 || v == 1, &m.cost_hessian);
        break;
    case 5:
        d = rd_double(r);
        double_setter("set_levenberg_marquardt", set_levenberg_marquardt, d, isfinite(d) && d >= 0.0, &m.lm);
        break;
    case 6:
        d = rd_double(r);
        double_setter("set_qp_tol", set_qp_tol, d, isfinite(d) && d > 0.0 && d <= K(QP_TOL_MAX), &m.tol);
        break;
    case 7:
        v = rd_int(r);
        int_setter("set_qp_max_iter", set_qp_max_iter, v, v >= 1, &m.max_iter);
        break;
    case 8: {
        unsigned null = rd_u8(r) & 1u;
        for (k = 0; k <= N_; ++k) {
            memcpy(&p_default[k * D(NP)], API(p_default)[k], D(NP) * sizeof(double));
        }
        rd_array(r, p, p_default, (N_ + 1) * NP);
        call_name = "set_parameters";
        st = API(set_parameters)(&s, null ? NULL : p);
        check_status(st);
        if (NP == 0) {
            check(st == K(OK), "set_parameters without parameters is OK");
        } else if (null) {
            check(st == K(ERR_INVALID_ARGUMENT), "set_parameters(NULL)");
        } else if (!all_finite(p, (N_ + 1) * NP)) {
            check(st == K(ERR_NONFINITE_INPUT), "set_parameters with NaN/Inf");
        } else if (!model_parameters_writable()) {
            check(st == K(ERR_ALREADY_PREPARED), "set_parameters while a QP is prepared");
        } else {
            check(st == K(OK), "set_parameters with finite values");
            memcpy(m.p, p, (N_ + 1) * NP * sizeof(double));
        }
        read_iterate(&after);
        check(same_bits(&before, &after), "set_parameters never changes the iterate");
        break;
    }
    default: {
        unsigned flags = rd_u8(r), null = flags & 1u;
        k = rd_int(r);
        rd_array(r, p, API(p_default)[0], NP);
        if (flags & 2u) {
            /* the new last node of the next horizon (receding mode, a prepare due) */
            call_name = "push_parameters";
            st = API(push_parameters)(&s, null ? NULL : p);
            check_status(st);
            if (!m.initialized) {
                check(st == K(ERR_NOT_INITIALIZED), "push_parameters before init");
            } else if (m.mode != K(MODE_RECEDING)) {
                check(st == K(ERR_INVALID_ARGUMENT), "push_parameters in fixed mode");
            } else if (NP == 0) {
                check(st == K(OK), "push_parameters without parameters is OK");
            } else if (null) {
                check(st == K(ERR_INVALID_ARGUMENT), "push_parameters(NULL)");
            } else if (!all_finite(p, NP)) {
                check(st == K(ERR_NONFINITE_INPUT), "push_parameters with NaN/Inf");
            } else if (!model_parameters_writable()) {
                check(st == K(ERR_ALREADY_PREPARED), "push_parameters while a QP is prepared");
            } else {
                check(st == K(OK), "push_parameters with finite values");
                memcpy(&m.p[N_ * NP], p, NP * sizeof(double));
            }
            read_iterate(&after);
            check(same_bits(&before, &after), "push_parameters never changes the iterate");
            break;
        }
        call_name = "set_parameters_node";
        st = API(set_parameters_node)(&s, k, null ? NULL : p);
        check_status(st);
        if (k < 0 || k > N_) {
            check(st == K(ERR_INVALID_ARGUMENT), "set_parameters_node with a bad node index");
        } else if (NP == 0) {
            check(st == K(OK), "set_parameters_node without parameters is OK");
        } else if (null) {
            check(st == K(ERR_INVALID_ARGUMENT), "set_parameters_node(NULL)");
        } else if (!all_finite(p, NP)) {
            check(st == K(ERR_NONFINITE_INPUT), "set_parameters_node with NaN/Inf");
        } else if (!model_parameters_writable()) {
            check(st == K(ERR_ALREADY_PREPARED), "set_parameters_node while a QP is prepared");
        } else {
            check(st == K(OK), "set_parameters_node with finite values");
            memcpy(&m.p[k * NP], p, NP * sizeof(double));
        }
        read_iterate(&after);
        check(same_bits(&before, &after), "set_parameters_node never changes the iterate");
        break;
    }
    }
    check_settings();
}

/* ---- the entry point ------------------------------------------------------------------ */

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    reader r;
    double xhat[NX];
    int st;
    r.p = data;
    r.n = size;
    if (trace < 0) {
        trace = getenv("FUZZ_TRACE") != NULL;
    }
    /* a fresh struct per input, set up with the generated defaults */
    memset(&s, 0, sizeof s);
    API(setup)(&s, NULL);
    pin_automatic_features();
    model_from_solver();
    check(m.M >= 0 && m.M <= N_ - 1 && m.tol > 0.0 && m.max_iter >= 1, "defaults are valid settings");
    for (call_index = 0; call_index < MAX_CALLS && r.n > 0; ++call_index) {
        unsigned op = rd_u8(&r) % 19u;
        read_iterate(&before);
        switch (op) {
        case 0:
            do_init(&r, xhat);
            break;
        case 1:
            rd_state(&r, xhat);
            call_name = "init_nominal";
            st = API(init_nominal)(&s, xhat);
            after_init(st, !all_finite(xhat, NX) && K(HAS_NOMINAL), !K(HAS_NOMINAL));
            break;
        case 2:
        case 3:
            do_feedback(&r, xhat);
            break;
        case 4:
            do_prepare();
            break;
        case 5:
            do_kkt(&r, xhat);
            break;
        case 6: /* one step of the loop: feedback, then prepare */
            do_feedback(&r, xhat);
            read_iterate(&before);
            do_prepare();
            break;
        case 7:
            call_name = "setup";
            API(setup)(&s, NULL);
            pin_automatic_features();
            model_from_solver();
            break;
        case 8:
            call_name = "zeroed struct";
            memset(&s, 0, sizeof s);
            /* not set up: every call is refused, nothing is written */
            check(API(init)(&s, NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL) ==
                          K(ERR_NOT_INITIALIZED) &&
                      API(feedback)(&s, API(x0_default), NULL) == K(ERR_NOT_INITIALIZED) &&
                      API(prepare)(&s) == K(ERR_NOT_INITIALIZED) && set_M(&s, 0) == K(ERR_NOT_INITIALIZED),
                  "a zeroed struct that is not set up refuses every call");
            check(!info_now().initialized, "a zeroed struct is not initialised");
            API(setup)(&s, NULL);
            pin_automatic_features();
            model_from_solver();
            break;
        default:
            do_setter(op - 9u, &r);
            break;
        }
    }
    return 0;
}
