/* The firmware program: the generated solver on a bare-metal target (and, compiled for the
 * host, the reference its output is compared with).
 *
 * fw_problem.h (written by `dopus-gen firmware-report`, dopus_lab/firmware.py) names the
 * problem: FW(name) is the generated symbol <problem>_name, FW_C(NAME) the macro
 * <PROBLEM>_NAME, and it carries the scenario: the disturbed state FW_XHAT_FIXED, the
 * values of M of the fixed-xhat_0 study, the iteration and step counts.
 *
 * 1. Fixed-xhat_0 study (what `dopus-gen converge --start warm` runs): for every M, init
 *    at the generated nominal solution (the offline solution at the default x0), then
 *    feedback(xhat_fixed); prepare() FW_FIXED_ITERS times in fixed mode with the
 *    Levenberg-Marquardt term FW_FIXED_LM; after every iteration the KKT measure, u0, the
 *    QP iterations, the ticks of feedback and prepare and the stack that iteration used;
 *    at the end the whole primal solution.
 * 2. Closed loop: receding mode with the generated defaults, solver at the nominal solution,
 *    plant state at xhat_fixed; the plant is the generated integrator (the discrete model
 *    phi); FW_LOOP_STEPS steps of feedback, plant step with the returned u0 whatever the
 *    status (the closed-loop instant of sil and campaign), prepare.
 * 3. The same closed loop with an anytime budget per instant (docs/algorithm.md section 14)
 *    of FW_BUDGETS instructions on the instruction clock.
 * 4. Only when the command line (semihosting; the host build: the environment variable
 *    FW_COMMAND_LINE) reads "<program> scenario SETTING INSTRUCTIONS": instead of 1 to 3 and 5,
 *    the OCP file's scenario (bench/budget_curves.py --parts m7): FW_SCENARIO_STEPS
 *    instants from x0_default, solver at the nominal solution, the event
 *    x <- FW_EVENT_SCALE .* x + FW_EVENT_SHIFT at instant FW_EVENT_STEP, the generated
 *    integrator as the plant; SETTING "full" (M = N-1), "M1" or "adaptive" (M between 1 and
 *    10), INSTRUCTIONS the budget per instant on the instruction clock (0: none).
 * 5. The steady closed loop at the operating point: as 2, the plant state at the default x0
 *    (no disturbance), FW_LOOP_STEPS steps, lines "steady".
 * The closed loops of 2 and 5 run the solver on the instruction clock (no budget: it only
 * feeds the solver's phase timers), so each of their lines carries the instructions of every
 * phase of dopus_info.timings ("phases", enum dopus_phase order; 0 on the host build).
 *
 * Every real number is printed as the hexadecimal bit pattern of its IEEE representation
 * (16 digits for double, 8 for float): exact, and printed without newlib's printf, whose
 * floating-point conversion allocates memory (there is no heap). The report tool decodes
 * them and prints them with %.17g. */
#include <math.h>
#include <stdint.h>
#include <string.h>

#include "fw_problem.h"
#include "platform.h"

typedef FW(real) fw_real;

static FW(solver) solver;
static FW(settings) settings;
static FW(info) info;
static FW(fun_work) plant_work;

/* QP iterations of the last feedback */
static int qp_iterations(void)
{
    FW(get_info)(&solver, &info);
    return info.qp_iterations;
}

/* ---- output without stdio: a line buffer, written at the end of the line ------------- */

/* 128 characters: the semihosting write of platform_qemu.c goes out in pieces of 128 anyway
 * (a longer buffer would only cost RAM) */
static char line[128];
static int line_len;

static void put_char(char c)
{
    if (line_len == (int)sizeof(line)) { /* a long line goes out in pieces */
        fw_write(line, line_len);
        line_len = 0;
    }
    line[line_len++] = c;
}

static void put_str(const char *s)
{
    while (*s) {
        put_char(*s++);
    }
}

static void put_int(long v)
{
    char digits[24];
    int n = 0;
    unsigned long m = v < 0 ? 0ul - (unsigned long)v : (unsigned long)v;
    if (v < 0) {
        put_char('-');
    }
    do {
        digits[n++] = (char)('0' + (int)(m % 10ul));
        m /= 10ul;
    } while (m && n < (int)sizeof(digits));
    while (n > 0) {
        put_char(digits[--n]);
    }
}

static void put_hex(uint64_t bits, int digits)
{
    static const char hex[] = "0123456789abcdef";
    int i;
    put_str("0x");
    for (i = digits - 1; i >= 0; --i) {
        put_char(hex[(bits >> (4 * i)) & 0xFu]);
    }
}

static void put_real(fw_real v)
{
    if (sizeof(fw_real) == 8) {
        uint64_t b;
        memcpy(&b, &v, 8);
        put_hex(b, 16);
    } else {
        uint32_t b;
        memcpy(&b, &v, 4);
        put_hex(b, 8);
    }
}

static void put_reals(const char *label, const fw_real *v, int n)
{
    int i;
    put_char(' ');
    put_str(label);
    for (i = 0; i < n; ++i) {
        put_char(' ');
        put_real(v[i]);
    }
}

static void put_field(const char *label, long v)
{
    put_char(' ');
    put_str(label);
    put_char(' ');
    put_int(v);
}

static void end_line(void)
{
    put_char('\n');
    fw_write(line, line_len);
    line_len = 0;
}

/* ---- the program ---------------------------------------------------------------------- */

static const fw_real xhat_fixed[FW_C(NX)] = FW_XHAT_FIXED;
static const int m_list[] = FW_M_LIST;

static fw_real kkt_max(const fw_real *k4)
{
    fw_real m = k4[0];
    int i;
    for (i = 1; i < 4; ++i) {
        m = k4[i] > m || k4[i] != k4[i] ? k4[i] : m;
    }
    return m;
}

/* feedback + prepare with ticks and stack; returns the status (the feedback's, else the
 * prepare's). u0 is the control the runtime returned, whatever the status: after a failed
 * feedback its safe control, and prepare runs after it as after any other. */
static int iteration(const fw_real *xhat, fw_real *u0, uint32_t *t_fb, uint32_t *t_prep, uint32_t *stack)
{
    uint32_t sp = fw_stack_paint();
    uint32_t t0 = fw_ticks(), t1, t2;
    int status = FW(feedback)(&solver, xhat, u0);
    int prepared;
    t1 = fw_ticks();
    prepared = FW(prepare)(&solver);
    if (status == FW_C(OK)) {
        status = prepared;
    }
    t2 = fw_ticks();
    *t_fb = t1 - t0;
    *t_prep = t2 - t1;
    *stack = sp ? sp - fw_stack_lowest() : 0u;
    return status;
}

/* The fields of a report line after its label: status, QP iterations, ticks, stack, the
 * KKT measure (0 after a failure) and u0. */
static void put_iteration(int status, int qp_iters, uint32_t t_fb, uint32_t t_prep, uint32_t stack,
                          const fw_real *k4, const fw_real *u0)
{
    put_field("status", status);
    put_field("qp_iters", qp_iters);
    put_field("ticks_feedback", (long)t_fb);
    put_field("ticks_prepare", (long)t_prep);
    put_field("stack", (long)stack);
    put_str(" kkt ");
    put_real(status == FW_C(OK) ? kkt_max(k4) : (fw_real)0);
    put_reals("u0", u0, FW_C(NU));
}

static int fixed_study(int M)
{
    fw_real u0[FW_C(NU)], k4[4];
    fw_real x[FW_C(N) + 1][FW_C(NX)], u[FW_C(N)][FW_C(NU)];
    int k, status;
    uint32_t t_fb = 0, t_prep = 0, stack = 0;

    memset(u0, 0, sizeof(u0));
    FW(settings_default)(&settings);
    settings.mode = FW_C(MODE_FIXED);
    settings.M = M;
    settings.lm_auto = 0;
    settings.lm = FW_FIXED_LM;
    status = FW(setup)(&solver, &settings);
    if (status == FW_C(OK)) {
        status = FW(init_nominal)(&solver, FW(x0_default));
    }
    for (k = 0; k <= FW_FIXED_ITERS; ++k) {
        if (k > 0 && status == FW_C(OK)) {
            status = iteration(xhat_fixed, u0, &t_fb, &t_prep, &stack);
        }
        if (status == FW_C(OK)) {
            status = FW(kkt_eval)(&solver, xhat_fixed, k4);
        }
        put_str("fixed");
        put_field("M", M);
        put_field("iter", k);
        put_iteration(status, k > 0 ? qp_iterations() : 0, t_fb, t_prep, stack, k4, u0);
        end_line();
        if (status != FW_C(OK)) {
            return status;
        }
    }
    FW(get_x)(&solver, &x[0][0]);
    FW(get_u)(&solver, &u[0][0]);
    put_str("solution");
    put_field("M", M);
    put_reals("x", &x[0][0], (FW_C(N) + 1) * FW_C(NX));
    put_reals("u", &u[0][0], FW_C(N) * FW_C(NU));
    end_line();
    return 0;
}

/* ---- the anytime budget (docs/algorithm.md section 14) on the firmware clock ------------ */

/* The budgets of the budgeted closed loops, in instructions (0 ends the list). */
#ifndef FW_BUDGETS
#define FW_BUDGETS 10000000.0, 20000000.0, 0.0
#endif
static const double budgets[] = {FW_BUDGETS};

/* The solver's clock on the firmware: the instructions executed (ticks of the board's
 * timer times the instructions per tick under QEMU's -icount); on the host build, which has
 * no ticks, it reads 0 (every budget then lasts: the host run is not compared). */
static double instruction_clock(void *ctx)
{
    /* the ticks since the first reading, in 64 bits: the 32-bit counter wraps after 1.7e11
     * instructions, the clock does not */
    static uint32_t last;
    static uint64_t total;
    static int started;
    uint32_t now = fw_ticks();
    (void)ctx;
    if (started) {
        total += (uint32_t)(now - last);
    }
    started = 1;
    last = now;
    /* the 64-bit count as two 32-bit halves: the FPU converts those (VCVT), a 64-bit integer
     * would go through the C library's software conversion at every phase switch; exact,
     * as is the count (below 2^53) */
    return ((double)(uint32_t)(total >> 32) * 4294967296.0 + (double)(uint32_t)total) *
           (double)FW_INSTRUCTIONS_PER_TICK;
}

/* Set up the solver with `settings` (the caller's choices) and a time budget of `budget`
 * instructions per instant on the instruction clock when budget > 0 (clock 1: the clock also
 * without a budget, for the phase timers), then start it from the nominal solution. */
static int start_solver(double budget, int clock)
{
    int status;
    if (budget > 0.0) {
        settings.budget = budget;
        settings.budget_unit = FW_C(BUDGET_TIME);
    }
    status = FW(setup)(&solver, &settings);
    if (clock || budget > 0.0) {
        FW(set_clock)(&solver, instruction_clock, 0);
    }
    if (status == FW_C(OK)) {
        status = FW(init_nominal)(&solver, FW(x0_default));
    }
    return status;
}

/* The closed-loop instant of the package (dopus_codegen/studies/loops.py): the measurement
 * in, the returned u0 applied whatever the status; a failed instant is reported and the loop
 * goes on. budget 0: the generated settings, lines "loop", returns the first failure;
 * budget > 0: a time budget of `budget` instructions per instant on the instruction clock,
 * lines "budget" with the extra iterations of each instant. */
static int closed_loop(double budget, int steady)
{
    fw_real xhat[FW_C(NX)], xnext[FW_C(NX)], u0[FW_C(NU)], k4[4];
    int i, k, status, plant_ok = 1, first_failure = FW_C(OK);
    uint32_t t_fb, t_prep, stack;

    FW(settings_default)(&settings); /* the generated settings */
    /* without a budget the clock only feeds the phase timers (instructions per phase) */
    status = start_solver(budget, 1);
    if (status != FW_C(OK)) {
        return status;
    }
    for (i = 0; i < FW_C(NX); ++i) {
        xhat[i] = steady ? FW(x0_default)[i] : xhat_fixed[i];
    }
    for (k = 1; k <= FW_LOOP_STEPS && plant_ok; ++k) {
        status = iteration(xhat, u0, &t_fb, &t_prep, &stack);
        /* the plant: the generated integrator from the measured state with the applied u0
         * (iteration() ran prepare already: the plant step does not touch the solver) */
        if (FW(simulate)(xhat, u0, NULL, xnext, &plant_work) != FW_C(OK)) {
            plant_ok = 0;
            status = FW_C(ERR_FUNCTION);
        }
        if (status == FW_C(OK)) {
            status = FW(kkt_eval)(&solver, xhat, k4);
        }
        if (first_failure == FW_C(OK)) {
            first_failure = status;
        }
        if (budget > 0.0) {
            FW(get_info)(&solver, &info);
            put_str("budget");
            put_field("instructions", (long)budget);
            put_field("step", k);
            put_field("extra", info.extra_iterations);
            put_field("stages", info.instant_stages);
            put_field("used", (long)info.budget_used); /* the solver's own count of the instant */
            put_iteration(status, info.qp_iterations, t_fb, t_prep, stack, k4, u0);
        } else {
            unsigned ph;
            put_str(steady ? "steady" : "loop");
            FW(get_settings)(&solver, &settings);
            put_field("M", settings.M);
            put_field("step", k);
            put_iteration(status, qp_iterations(), t_fb, t_prep, stack, k4, u0);
            FW(get_info)(&solver, &info);
            put_field("factorizations", info.qp_factorizations);
            put_str(" phases");
            for (ph = 0; ph < sizeof(info.timings) / sizeof(info.timings[0]); ++ph) {
                put_char(' ');
                put_int((long)info.timings[ph]);
            }
        }
        put_reals("xhat", xhat, FW_C(NX));
        end_line();
        for (i = 0; i < FW_C(NX); ++i) {
            xhat[i] = xnext[i];
        }
    }
    return budget > 0.0 ? FW_C(OK) : first_failure;
}

/* ---- the OCP file's scenario (bench/budget_curves.py --parts m7) ---------------------- */

#ifndef FW_SCENARIO_STEPS
#define FW_SCENARIO_STEPS 0
#endif
#ifndef FW_EVENT_STEP
#define FW_EVENT_STEP (-1)
#endif
#ifdef FW_EVENT_SCALE
static const fw_real event_scale[FW_C(NX)] = FW_EVENT_SCALE;
static const fw_real event_shift[FW_C(NX)] = FW_EVENT_SHIFT;
#endif

enum { FW_SETTING_FULL = 1, FW_SETTING_M1 = 2, FW_SETTING_ADAPTIVE = 3 };
#define FW_ADAPTIVE_M_MIN 1
#define FW_ADAPTIVE_M_MAX 10

/* The instant of `dopus-gen sil` (dopus_codegen/studies/sil.py): the event due, the
 * measurement (the exact state), feedback, the KKT measure at it, the plant from the state
 * with the returned u0 whatever the status, prepare. Only feedback and prepare are timed and
 * count against the budget. One line "scenario" per instant. */
static int scenario(int setting, long budget)
{
    fw_real x[FW_C(NX)], xnext[FW_C(NX)], u0[FW_C(NU)], k4[4];
    int i, k, status, prepared;
    uint32_t t0, t1, t2, t3;

    FW(settings_default)(&settings); /* the OCP file's options */
    settings.M = setting == FW_SETTING_FULL ? FW_C(N) - 1 : 1;
    if (setting == FW_SETTING_ADAPTIVE) {
        settings.M_adaptive = 1;
        settings.M_min = FW_ADAPTIVE_M_MIN;
        settings.M_max = FW_ADAPTIVE_M_MAX < FW_C(N) - 1 ? FW_ADAPTIVE_M_MAX : FW_C(N) - 1;
    }
    status = start_solver((double)budget, 0);
    if (status != FW_C(OK)) {
        return status;
    }
    for (i = 0; i < FW_C(NX); ++i) {
        x[i] = FW(x0_default)[i];
    }
    memset(u0, 0, sizeof(u0));
    for (k = 0; k < FW_SCENARIO_STEPS; ++k) {
#ifdef FW_EVENT_SCALE
        if (k == FW_EVENT_STEP) {
            for (i = 0; i < FW_C(NX); ++i) {
                x[i] = event_scale[i] * x[i] + event_shift[i];
            }
        }
#endif
        t0 = fw_ticks();
        status = FW(feedback)(&solver, x, u0);
        t1 = fw_ticks();
        i = FW(kkt_eval)(&solver, x, k4);
        if (i != FW_C(OK)) { /* no KKT measure: NaN and a failed instant, as in the host loop */
            k4[0] = k4[1] = k4[2] = k4[3] = (fw_real)NAN;
            status = status == FW_C(OK) ? i : status;
        }
        if (FW(simulate)(x, u0, NULL, xnext, &plant_work) != FW_C(OK)) {
            return FW_C(ERR_FUNCTION);
        }
        t2 = fw_ticks();
        prepared = FW(prepare)(&solver);
        t3 = fw_ticks();
        if (status == FW_C(OK)) {
            status = prepared;
        }
        FW(get_info)(&solver, &info);
        put_str("scenario");
        put_field("setting", setting);
        put_field("instructions", budget);
        put_field("step", k);
        put_field("extra", info.extra_iterations);
        put_field("stages", info.instant_stages);
        put_field("status", status);
        put_field("qp_iters", info.qp_iterations);
        put_field("qp_status", info.qp_status);
        put_field("flags", info.flags);
        put_field("ticks_feedback", (long)(t1 - t0));
        put_field("ticks_prepare", (long)(t3 - t2));
        put_str(" kkt ");
        put_real(kkt_max(k4));
        put_field("used", (long)info.budget_used); /* the solver's own count of the instant */
        put_reals("u0", u0, FW_C(NU));
        put_reals("xhat", x, FW_C(NX));
        end_line();
        for (i = 0; i < FW_C(NX); ++i) {
            x[i] = xnext[i];
        }
    }
    return FW_C(OK);
}

/* Token `index` (0-based, blank-separated) of `text` into `out` (at most n - 1 characters);
 * returns 1 if it is there. */
static int token(const char *text, int index, char *out, int n)
{
    int len = 0;
    while (*text) {
        while (*text == ' ') {
            ++text;
        }
        if (!*text) {
            break;
        }
        if (index-- == 0) {
            while (*text && *text != ' ' && len < n - 1) {
                out[len++] = *text++;
            }
            out[len] = '\0';
            return 1;
        }
        while (*text && *text != ' ') {
            ++text;
        }
    }
    return 0;
}

/* A non-negative decimal integer of at most 2e9 (a 32-bit long), or -1. */
static long parse_count(const char *t)
{
    long v = 0;
    if (!*t) {
        return -1;
    }
    for (; *t; ++t) {
        if (*t < '0' || *t > '9' || v > 200000000L) { /* at most 2e9 (a 32-bit long) */
            return -1;
        }
        v = 10 * v + (*t - '0');
    }
    return v;
}

/* "<program> scenario SETTING INSTRUCTIONS": runs the scenario and returns 1 with its
 * status in *status; else 0 (the program's default runs). */
static int scenario_command(int *status)
{
    static char cmd[256];
    char word[32];
    int setting = 0;
    long budget;

    if (fw_command_line(cmd, (int)sizeof(cmd)) != 0 || !token(cmd, 1, word, (int)sizeof(word)) ||
        strcmp(word, "scenario") != 0) {
        return 0;
    }
    if (token(cmd, 2, word, (int)sizeof(word))) {
        setting = strcmp(word, "full") == 0       ? FW_SETTING_FULL
                  : strcmp(word, "M1") == 0       ? FW_SETTING_M1
                  : strcmp(word, "adaptive") == 0 ? FW_SETTING_ADAPTIVE
                                                  : 0;
    }
    budget = token(cmd, 3, word, (int)sizeof(word)) ? parse_count(word) : -1;
    if (setting == 0 || budget < 0 || FW_SCENARIO_STEPS <= 0) {
        fw_puts("firmware: expected the command line '<program> scenario full|M1|adaptive INSTRUCTIONS' "
                "and a scenario in fw_problem.h\n");
        *status = 2;
        return 1;
    }
    *status = scenario(setting, budget);
    return 1;
}

int main(void)
{
    unsigned i;
    int status = 0;

    fw_platform_init();
    FW(setup)(&solver, NULL);
    FW(get_info)(&solver, &info);
    put_str("problem ");
    put_str(FW(name)());
    put_field("N", FW_C(N));
    put_field("nx", FW_C(NX));
    put_field("nu", FW_C(NU));
    put_field("real_bytes", (long)sizeof(fw_real));
    put_field("solver_bytes", (long)FW(solver_sizeof)());
    put_field("default_clock", info.has_clock);
    put_field("ticks", fw_has_ticks());
    put_field("instructions_per_tick", (long)FW_INSTRUCTIONS_PER_TICK);
    put_field("calibration_instructions", (long)FW_CALIBRATION_INSTRUCTIONS);
    put_field("calibration_ticks", (long)fw_calibration_ticks());
    end_line();
    if (scenario_command(&status)) {
        put_str("end");
        put_field("status", status);
        end_line();
        return status == 0 ? 0 : 1;
    }
    for (i = 0; i < sizeof(m_list) / sizeof(m_list[0]) && status == 0; ++i) {
        status = fixed_study(m_list[i]);
    }
    if (status == 0) {
        status = closed_loop(0.0, 0);
    }
    for (i = 0; budgets[i] > 0.0 && status == 0; ++i) {
        status = closed_loop(budgets[i], 0);
    }
    if (status == 0) {
        status = closed_loop(0.0, 1);
    }
    put_str("end");
    put_field("status", status);
    end_line();
    return status == 0 ? 0 : 1;
}
