/* Health of the controller (unicycle_health.h, docs/algorithm.md section 9). */
#include "unicycle_health.h"

#include <math.h>

#include "unicycle_linalg.h"
#include "unicycle_problem.h"

static unicycle_real unicycle_absmax(unicycle_real a, unicycle_real b)
{
    unicycle_real fa = unicycle_fabs(a);
    return isfinite(a) && fa > b ? fa : b;
}

void unicycle_health_scales(unicycle_health *h)
{
    int k, i;
    for (i = 0; i < UNICYCLE_NX; ++i) {
        unicycle_real v = UNICYCLE_R(1.0);
        v = unicycle_absmax(unicycle_lbx[i], v);
        v = unicycle_absmax(unicycle_ubx[i], v);
        v = unicycle_absmax(unicycle_x0_default[i] / unicycle_scale_x[i], v); /* in the solver's variables */
        for (k = 0; k <= UNICYCLE_N; ++k) {
            v = unicycle_absmax(unicycle_guess_x[k][i], v);
        }
        h->scale_x[i] = v;
    }
    for (i = 0; i < UNICYCLE_NU; ++i) {
        unicycle_real v = UNICYCLE_R(1.0);
        v = unicycle_absmax(unicycle_lbu[i], v);
        v = unicycle_absmax(unicycle_ubu[i], v);
        for (k = 0; k < UNICYCLE_N; ++k) {
            v = unicycle_absmax(unicycle_guess_u[k][i], v);
        }
        h->scale_u[i] = v;
    }
    for (i = 0; i < UNICYCLE_NMEM; ++i) { /* a memory state carries its control */
        k = unicycle_memory_state[i];
        h->scale_x[k] = unicycle_absmax(h->scale_u[unicycle_memory_control[i]], h->scale_x[k]);
    }
}

void unicycle_health_reset(unicycle_health *h, const unicycle_real *u)
{
    int k, i;
    h->n_failed = 0;
    h->recover_pending = 0;
    h->flags = 0;
    h->n_recoveries = 0;
    h->recovering = 0;
    h->xhat_fresh = 1;
    h->plan_age = 0;
    for (k = 0; k < UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NU; ++i) {
            h->plan_u[k][i] = u[k * UNICYCLE_NU + i];
        }
    }
    for (i = 0; i < UNICYCLE_NU; ++i) {
        h->u0_out[i] = h->plan_u[0][i];
    }
    h->kkt_proxy = UNICYCLE_R(0.0);
    h->kkt_proxy_ref = UNICYCLE_R(0.0);
    h->kkt_proxy_init = UNICYCLE_R(0.0);
    h->n_stalled = 0;
    h->kkt_flat_ref = UNICYCLE_R(0.0);
    h->n_flat = 0;
    h->n_gated = 0;
    h->gate_rest = 0;
}

int unicycle_clip_u(const unicycle_real *u, unicycle_real *out)
{
    int i, clipped = 0;
    for (i = 0; i < UNICYCLE_NU; ++i) {
        unicycle_real v = isnan(u[i]) ? UNICYCLE_R(0.0) : u[i];
        if (v < unicycle_lbu[i]) {
            v = unicycle_lbu[i];
        }
        if (v > unicycle_ubu[i]) {
            v = unicycle_ubu[i];
        }
        if (!(v == u[i])) {
            clipped = 1;
        }
        out[i] = v;
    }
    return clipped;
}

int unicycle_box_node_ok(const unicycle_health *h, const unicycle_real *xhat0, const unicycle_real *x,
                      const unicycle_real *dx, const unicycle_real *u, const unicycle_real *du)
{
    int i;
    for (i = 0; i < UNICYCLE_NX && x; ++i) {
        unicycle_real v = x[i] + (dx ? dx[i] : UNICYCLE_R(0.0));
        if (!(unicycle_fabs(v) <= UNICYCLE_DIVERGENCE_BOX * h->scale_x[i] + unicycle_fabs(xhat0[i]))) {
            return 0;
        }
    }
    for (i = 0; i < UNICYCLE_NU && u; ++i) {
        unicycle_real v = u[i] + (du ? du[i] : UNICYCLE_R(0.0));
        if (!(unicycle_fabs(v) <= UNICYCLE_DIVERGENCE_BOX * h->scale_u[i])) {
            return 0;
        }
    }
    return 1;
}

int unicycle_box_ok(const unicycle_health *h, const unicycle_real *xhat0, const unicycle_real *x, const unicycle_real *dx,
                 int dx_stride, const unicycle_real *u, const unicycle_real *du, int du_stride)
{
    int k;
    for (k = 0; k <= UNICYCLE_N; ++k) {
        if (!unicycle_box_node_ok(h, xhat0, x + k * UNICYCLE_NX, dx ? dx + k * dx_stride : 0, 0, 0)) {
            return 0;
        }
    }
    for (k = 0; k < UNICYCLE_N; ++k) {
        if (!unicycle_box_node_ok(h, xhat0, 0, 0, u + k * UNICYCLE_NU, du ? du + k * du_stride : 0)) {
            return 0;
        }
    }
    return 1;
}

unicycle_real unicycle_kkt_proxy(const unicycle_ring *ring, const unicycle_real *x, const unicycle_real *lam,
                           const unicycle_real *gL_N, const unicycle_real *mu_bN, const unicycle_real *r_eq)
{
    unicycle_real m = UNICYCLE_R(0.0), v;
    int k, i;
    for (k = 0; k < UNICYCLE_N; ++k) {
        const unicycle_stage_slot *slot = unicycle_ring_stage_const(ring, k);
        for (i = 0; i < UNICYCLE_NW; ++i) {
            v = unicycle_fabs(slot->F_w[i] + (i < UNICYCLE_NX ? lam[k * UNICYCLE_NX + i] : UNICYCLE_R(0.0)));
            m = (v > m || isnan(v)) ? v : m;
        }
        for (i = 0; i < UNICYCLE_NX; ++i) {
            v = unicycle_fabs(slot->phi[i] - x[(k + 1) * UNICYCLE_NX + i]);
            m = (v > m || isnan(v)) ? v : m;
        }
    }
    for (i = 0; i < UNICYCLE_NX; ++i) {
        v = unicycle_fabs(gL_N[i] + mu_bN[i] + lam[UNICYCLE_N * UNICYCLE_NX + i]);
        m = (v > m || isnan(v)) ? v : m;
    }
    for (i = 0; i < UNICYCLE_NE; ++i) {
        v = unicycle_fabs(r_eq[i]);
        m = (v > m || isnan(v)) ? v : m;
    }
    return m;
}

int unicycle_diverged(const unicycle_health *h, const unicycle_real *xhat0, const unicycle_real *x, const unicycle_real *u,
                   const unicycle_real *lam, const unicycle_real *mu_b, const unicycle_real *mu_bN)
{
    unicycle_real ref = h->kkt_proxy_ref > UNICYCLE_R(1.0) ? h->kkt_proxy_ref : UNICYCLE_R(1.0);
    if (!unicycle_box_ok(h, xhat0, x, 0, 0, u, 0, 0)) {
        return 1;
    }
    if (!unicycle_lai_vec_finite((UNICYCLE_N + 1) * UNICYCLE_NX, lam) ||
        !unicycle_lai_vec_finite(UNICYCLE_N * UNICYCLE_NW, mu_b) || !unicycle_lai_vec_finite(UNICYCLE_NX, mu_bN)) {
        return 1;
    }
    return !(h->kkt_proxy <= UNICYCLE_DIVERGENCE_KKT * ref);
}

int unicycle_health_stalled(unicycle_health *h, int phase, int lm_held)
{
    unicycle_real ref = h->kkt_proxy_init > UNICYCLE_R(1.0) ? h->kkt_proxy_init : UNICYCLE_R(1.0);
    int high, flat;
    if (h->recovering > 0) {
        h->n_stalled = 0;
        h->n_flat = 0;
        return 0;
    }
    high = h->kkt_proxy > UNICYCLE_STALL_KKT * ref;
    h->n_stalled = high ? h->n_stalled + 1 : 0;
    /* a flat stretch: the proxy well above its settled level, or above it with the automatic
     * lm held up by the convexity test (the damping that keeps the iterate from progressing),
     * and not falling */
    flat = h->kkt_proxy > UNICYCLE_FLAT_KKT * ref || (lm_held && h->kkt_proxy > UNICYCLE_FLAT_HELD_KKT * ref);
    if (!flat || h->n_flat == 0 || !(h->kkt_proxy > UNICYCLE_FLAT_DROP * h->kkt_flat_ref)) {
        h->kkt_flat_ref = h->kkt_proxy;
        h->n_flat = 0;
    }
    h->n_flat = flat ? h->n_flat + 1 : 0;
    if (h->n_stalled < UNICYCLE_STALL_PREPARES && h->n_flat < UNICYCLE_FLAT_PREPARES) {
        return 0;
    }
    h->n_stalled = 0;
    h->n_flat = 0;
    h->recovering = phase;
    return 1;
}

const unicycle_real *unicycle_health_plan_control(const unicycle_health *h, int k)
{
    int j = h->plan_age + k;
    return h->plan_u[j > UNICYCLE_N - 1 ? UNICYCLE_N - 1 : j];
}

int unicycle_health_fallback(unicycle_health *h, int receding, unicycle_real *u0)
{
    int i, clipped;
    clipped = unicycle_clip_u(receding ? unicycle_health_plan_control(h, 0) : h->plan_u[0], h->u0_out);
    if (u0) {
        for (i = 0; i < UNICYCLE_NU; ++i) {
            u0[i] = h->u0_out[i];
        }
    }
    return clipped;
}

int unicycle_health_keep_plan(unicycle_health *h, const unicycle_real *u, unicycle_real *u0)
{
    int k, i, clipped;
    h->n_failed = 0;
    h->plan_age = 0;
    h->recovering = h->recovering > 0 ? h->recovering - 1 : 0;
    for (k = 0; k < UNICYCLE_N; ++k) {
        for (i = 0; i < UNICYCLE_NU; ++i) {
            h->plan_u[k][i] = u[k * UNICYCLE_NU + i];
        }
    }
    clipped = unicycle_clip_u(h->plan_u[0], h->u0_out);
    if (u0) {
        for (i = 0; i < UNICYCLE_NU; ++i) {
            u0[i] = h->u0_out[i];
        }
    }
    return clipped;
}
