/* Health of the controller (robot_arm_health.h, docs/algorithm.md section 9). */
#include "robot_arm_health.h"

#include <math.h>

#include "robot_arm_linalg.h"
#include "robot_arm_problem.h"

static robot_arm_real robot_arm_absmax(robot_arm_real a, robot_arm_real b)
{
    robot_arm_real fa = robot_arm_fabs(a);
    return isfinite(a) && fa > b ? fa : b;
}

void robot_arm_health_scales(robot_arm_health *h)
{
    int k, i;
    for (i = 0; i < ROBOT_ARM_NX; ++i) {
        robot_arm_real v = ROBOT_ARM_R(1.0);
        v = robot_arm_absmax(robot_arm_lbx[i], v);
        v = robot_arm_absmax(robot_arm_ubx[i], v);
        v = robot_arm_absmax(robot_arm_x0_default[i] / robot_arm_scale_x[i], v); /* in the solver's variables */
        for (k = 0; k <= ROBOT_ARM_N; ++k) {
            v = robot_arm_absmax(robot_arm_guess_x[k][i], v);
        }
        h->scale_x[i] = v;
    }
    for (i = 0; i < ROBOT_ARM_NU; ++i) {
        robot_arm_real v = ROBOT_ARM_R(1.0);
        v = robot_arm_absmax(robot_arm_lbu[i], v);
        v = robot_arm_absmax(robot_arm_ubu[i], v);
        for (k = 0; k < ROBOT_ARM_N; ++k) {
            v = robot_arm_absmax(robot_arm_guess_u[k][i], v);
        }
        h->scale_u[i] = v;
    }
    for (i = 0; i < ROBOT_ARM_NMEM; ++i) { /* a memory state carries its control */
        k = robot_arm_memory_state[i];
        h->scale_x[k] = robot_arm_absmax(h->scale_u[robot_arm_memory_control[i]], h->scale_x[k]);
    }
}

void robot_arm_health_reset(robot_arm_health *h, const robot_arm_real *u)
{
    int k, i;
    h->n_failed = 0;
    h->recover_pending = 0;
    h->flags = 0;
    h->n_recoveries = 0;
    h->recovering = 0;
    h->xhat_fresh = 1;
    h->plan_age = 0;
    for (k = 0; k < ROBOT_ARM_N; ++k) {
        for (i = 0; i < ROBOT_ARM_NU; ++i) {
            h->plan_u[k][i] = u[k * ROBOT_ARM_NU + i];
        }
    }
    for (i = 0; i < ROBOT_ARM_NU; ++i) {
        h->u0_out[i] = h->plan_u[0][i];
    }
    h->kkt_proxy = ROBOT_ARM_R(0.0);
    h->kkt_proxy_ref = ROBOT_ARM_R(0.0);
    h->kkt_proxy_init = ROBOT_ARM_R(0.0);
    h->n_stalled = 0;
    h->kkt_flat_ref = ROBOT_ARM_R(0.0);
    h->n_flat = 0;
    h->n_gated = 0;
    h->gate_rest = 0;
}

int robot_arm_clip_u(const robot_arm_real *u, robot_arm_real *out)
{
    int i, clipped = 0;
    for (i = 0; i < ROBOT_ARM_NU; ++i) {
        robot_arm_real v = isnan(u[i]) ? ROBOT_ARM_R(0.0) : u[i];
        if (v < robot_arm_lbu[i]) {
            v = robot_arm_lbu[i];
        }
        if (v > robot_arm_ubu[i]) {
            v = robot_arm_ubu[i];
        }
        if (!(v == u[i])) {
            clipped = 1;
        }
        out[i] = v;
    }
    return clipped;
}

int robot_arm_box_node_ok(const robot_arm_health *h, const robot_arm_real *xhat0, const robot_arm_real *x,
                      const robot_arm_real *dx, const robot_arm_real *u, const robot_arm_real *du)
{
    int i;
    for (i = 0; i < ROBOT_ARM_NX && x; ++i) {
        robot_arm_real v = x[i] + (dx ? dx[i] : ROBOT_ARM_R(0.0));
        if (!(robot_arm_fabs(v) <= ROBOT_ARM_DIVERGENCE_BOX * h->scale_x[i] + robot_arm_fabs(xhat0[i]))) {
            return 0;
        }
    }
    for (i = 0; i < ROBOT_ARM_NU && u; ++i) {
        robot_arm_real v = u[i] + (du ? du[i] : ROBOT_ARM_R(0.0));
        if (!(robot_arm_fabs(v) <= ROBOT_ARM_DIVERGENCE_BOX * h->scale_u[i])) {
            return 0;
        }
    }
    return 1;
}

int robot_arm_box_ok(const robot_arm_health *h, const robot_arm_real *xhat0, const robot_arm_real *x, const robot_arm_real *dx,
                 int dx_stride, const robot_arm_real *u, const robot_arm_real *du, int du_stride)
{
    int k;
    for (k = 0; k <= ROBOT_ARM_N; ++k) {
        if (!robot_arm_box_node_ok(h, xhat0, x + k * ROBOT_ARM_NX, dx ? dx + k * dx_stride : 0, 0, 0)) {
            return 0;
        }
    }
    for (k = 0; k < ROBOT_ARM_N; ++k) {
        if (!robot_arm_box_node_ok(h, xhat0, 0, 0, u + k * ROBOT_ARM_NU, du ? du + k * du_stride : 0)) {
            return 0;
        }
    }
    return 1;
}

robot_arm_real robot_arm_kkt_proxy(const robot_arm_ring *ring, const robot_arm_real *x, const robot_arm_real *lam,
                           const robot_arm_real *gL_N, const robot_arm_real *mu_bN, const robot_arm_real *r_eq)
{
    robot_arm_real m = ROBOT_ARM_R(0.0), v;
    int k, i;
    for (k = 0; k < ROBOT_ARM_N; ++k) {
        const robot_arm_stage_slot *slot = robot_arm_ring_stage_const(ring, k);
        for (i = 0; i < ROBOT_ARM_NW; ++i) {
            v = robot_arm_fabs(slot->F_w[i] + (i < ROBOT_ARM_NX ? lam[k * ROBOT_ARM_NX + i] : ROBOT_ARM_R(0.0)));
            m = (v > m || isnan(v)) ? v : m;
        }
        for (i = 0; i < ROBOT_ARM_NX; ++i) {
            v = robot_arm_fabs(slot->phi[i] - x[(k + 1) * ROBOT_ARM_NX + i]);
            m = (v > m || isnan(v)) ? v : m;
        }
    }
    for (i = 0; i < ROBOT_ARM_NX; ++i) {
        v = robot_arm_fabs(gL_N[i] + mu_bN[i] + lam[ROBOT_ARM_N * ROBOT_ARM_NX + i]);
        m = (v > m || isnan(v)) ? v : m;
    }
    for (i = 0; i < ROBOT_ARM_NE; ++i) {
        v = robot_arm_fabs(r_eq[i]);
        m = (v > m || isnan(v)) ? v : m;
    }
    return m;
}

int robot_arm_diverged(const robot_arm_health *h, const robot_arm_real *xhat0, const robot_arm_real *x, const robot_arm_real *u,
                   const robot_arm_real *lam, const robot_arm_real *mu_b, const robot_arm_real *mu_bN)
{
    robot_arm_real ref = h->kkt_proxy_ref > ROBOT_ARM_R(1.0) ? h->kkt_proxy_ref : ROBOT_ARM_R(1.0);
    if (!robot_arm_box_ok(h, xhat0, x, 0, 0, u, 0, 0)) {
        return 1;
    }
    if (!robot_arm_lai_vec_finite((ROBOT_ARM_N + 1) * ROBOT_ARM_NX, lam) ||
        !robot_arm_lai_vec_finite(ROBOT_ARM_N * ROBOT_ARM_NW, mu_b) || !robot_arm_lai_vec_finite(ROBOT_ARM_NX, mu_bN)) {
        return 1;
    }
    return !(h->kkt_proxy <= ROBOT_ARM_DIVERGENCE_KKT * ref);
}

int robot_arm_health_stalled(robot_arm_health *h, int phase, int lm_held)
{
    robot_arm_real ref = h->kkt_proxy_init > ROBOT_ARM_R(1.0) ? h->kkt_proxy_init : ROBOT_ARM_R(1.0);
    int high, flat;
    if (h->recovering > 0) {
        h->n_stalled = 0;
        h->n_flat = 0;
        return 0;
    }
    high = h->kkt_proxy > ROBOT_ARM_STALL_KKT * ref;
    h->n_stalled = high ? h->n_stalled + 1 : 0;
    /* a flat stretch: the proxy well above its settled level, or above it with the automatic
     * lm held up by the convexity test (the damping that keeps the iterate from progressing),
     * and not falling */
    flat = h->kkt_proxy > ROBOT_ARM_FLAT_KKT * ref || (lm_held && h->kkt_proxy > ROBOT_ARM_FLAT_HELD_KKT * ref);
    if (!flat || h->n_flat == 0 || !(h->kkt_proxy > ROBOT_ARM_FLAT_DROP * h->kkt_flat_ref)) {
        h->kkt_flat_ref = h->kkt_proxy;
        h->n_flat = 0;
    }
    h->n_flat = flat ? h->n_flat + 1 : 0;
    if (h->n_stalled < ROBOT_ARM_STALL_PREPARES && h->n_flat < ROBOT_ARM_FLAT_PREPARES) {
        return 0;
    }
    h->n_stalled = 0;
    h->n_flat = 0;
    h->recovering = phase;
    return 1;
}

const robot_arm_real *robot_arm_health_plan_control(const robot_arm_health *h, int k)
{
    int j = h->plan_age + k;
    return h->plan_u[j > ROBOT_ARM_N - 1 ? ROBOT_ARM_N - 1 : j];
}

int robot_arm_health_fallback(robot_arm_health *h, int receding, robot_arm_real *u0)
{
    int i, clipped;
    clipped = robot_arm_clip_u(receding ? robot_arm_health_plan_control(h, 0) : h->plan_u[0], h->u0_out);
    if (u0) {
        for (i = 0; i < ROBOT_ARM_NU; ++i) {
            u0[i] = h->u0_out[i];
        }
    }
    return clipped;
}

int robot_arm_health_keep_plan(robot_arm_health *h, const robot_arm_real *u, robot_arm_real *u0)
{
    int k, i, clipped;
    h->n_failed = 0;
    h->plan_age = 0;
    h->recovering = h->recovering > 0 ? h->recovering - 1 : 0;
    for (k = 0; k < ROBOT_ARM_N; ++k) {
        for (i = 0; i < ROBOT_ARM_NU; ++i) {
            h->plan_u[k][i] = u[k * ROBOT_ARM_NU + i];
        }
    }
    clipped = robot_arm_clip_u(h->plan_u[0], h->u0_out);
    if (u0) {
        for (i = 0; i < ROBOT_ARM_NU; ++i) {
            u0[i] = h->u0_out[i];
        }
    }
    return clipped;
}
