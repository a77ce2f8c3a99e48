/* Health of the controller (dopus_health.h, docs/algorithm.md section 9). */
#include "dopus_health.h"

#include <math.h>

#include "dopus_linalg.h"
#include "dopus_problem.h"

static dopus_real dopus_absmax(dopus_real a, dopus_real b)
{
    dopus_real fa = dopus_fabs(a);
    return isfinite(a) && fa > b ? fa : b;
}

void dopus_health_scales(dopus_health *h)
{
    int k, i;
    for (i = 0; i < DOPUS_NX; ++i) {
        dopus_real v = DOPUS_R(1.0);
        v = dopus_absmax(dopus_lbx[i], v);
        v = dopus_absmax(dopus_ubx[i], v);
        v = dopus_absmax(dopus_x0_default[i] / dopus_scale_x[i], v); /* in the solver's variables */
        for (k = 0; k <= DOPUS_N; ++k) {
            v = dopus_absmax(dopus_guess_x[k][i], v);
        }
        h->scale_x[i] = v;
    }
    for (i = 0; i < DOPUS_NU; ++i) {
        dopus_real v = DOPUS_R(1.0);
        v = dopus_absmax(dopus_lbu[i], v);
        v = dopus_absmax(dopus_ubu[i], v);
        for (k = 0; k < DOPUS_N; ++k) {
            v = dopus_absmax(dopus_guess_u[k][i], v);
        }
        h->scale_u[i] = v;
    }
    for (i = 0; i < DOPUS_NMEM; ++i) { /* a memory state carries its control */
        k = dopus_memory_state[i];
        h->scale_x[k] = dopus_absmax(h->scale_u[dopus_memory_control[i]], h->scale_x[k]);
    }
}

void dopus_health_reset(dopus_health *h, const dopus_real *u)
{
    int k, i;
    h->n_failed = 0;
    h->recover_pending = 0;
    h->flags = 0;
    h->n_recoveries = 0;
    h->recovering = 0;
    h->xhat_fresh = 1;
    h->plan_age = 0;
    for (k = 0; k < DOPUS_N; ++k) {
        for (i = 0; i < DOPUS_NU; ++i) {
            h->plan_u[k][i] = u[k * DOPUS_NU + i];
        }
    }
    for (i = 0; i < DOPUS_NU; ++i) {
        h->u0_out[i] = h->plan_u[0][i];
    }
    h->kkt_proxy = DOPUS_R(0.0);
    h->kkt_proxy_ref = DOPUS_R(0.0);
    h->kkt_proxy_init = DOPUS_R(0.0);
    h->n_stalled = 0;
    h->kkt_flat_ref = DOPUS_R(0.0);
    h->n_flat = 0;
    h->n_gated = 0;
    h->gate_rest = 0;
}

int dopus_clip_u(const dopus_real *u, dopus_real *out)
{
    int i, clipped = 0;
    for (i = 0; i < DOPUS_NU; ++i) {
        dopus_real v = isnan(u[i]) ? DOPUS_R(0.0) : u[i];
        if (v < dopus_lbu[i]) {
            v = dopus_lbu[i];
        }
        if (v > dopus_ubu[i]) {
            v = dopus_ubu[i];
        }
        if (!(v == u[i])) {
            clipped = 1;
        }
        out[i] = v;
    }
    return clipped;
}

int dopus_box_node_ok(const dopus_health *h, const dopus_real *xhat0, const dopus_real *x,
                      const dopus_real *dx, const dopus_real *u, const dopus_real *du)
{
    int i;
    for (i = 0; i < DOPUS_NX && x; ++i) {
        dopus_real v = x[i] + (dx ? dx[i] : DOPUS_R(0.0));
        if (!(dopus_fabs(v) <= DOPUS_DIVERGENCE_BOX * h->scale_x[i] + dopus_fabs(xhat0[i]))) {
            return 0;
        }
    }
    for (i = 0; i < DOPUS_NU && u; ++i) {
        dopus_real v = u[i] + (du ? du[i] : DOPUS_R(0.0));
        if (!(dopus_fabs(v) <= DOPUS_DIVERGENCE_BOX * h->scale_u[i])) {
            return 0;
        }
    }
    return 1;
}

int dopus_box_ok(const dopus_health *h, const dopus_real *xhat0, const dopus_real *x, const dopus_real *dx,
                 int dx_stride, const dopus_real *u, const dopus_real *du, int du_stride)
{
    int k;
    for (k = 0; k <= DOPUS_N; ++k) {
        if (!dopus_box_node_ok(h, xhat0, x + k * DOPUS_NX, dx ? dx + k * dx_stride : 0, 0, 0)) {
            return 0;
        }
    }
    for (k = 0; k < DOPUS_N; ++k) {
        if (!dopus_box_node_ok(h, xhat0, 0, 0, u + k * DOPUS_NU, du ? du + k * du_stride : 0)) {
            return 0;
        }
    }
    return 1;
}

dopus_real dopus_kkt_proxy(const dopus_ring *ring, const dopus_real *x, const dopus_real *lam,
                           const dopus_real *gL_N, const dopus_real *mu_bN, const dopus_real *r_eq)
{
    dopus_real m = DOPUS_R(0.0), v;
    int k, i;
    for (k = 0; k < DOPUS_N; ++k) {
        const dopus_stage_slot *slot = dopus_ring_stage_const(ring, k);
        for (i = 0; i < DOPUS_NW; ++i) {
            v = dopus_fabs(slot->F_w[i] + (i < DOPUS_NX ? lam[k * DOPUS_NX + i] : DOPUS_R(0.0)));
            m = (v > m || isnan(v)) ? v : m;
        }
        for (i = 0; i < DOPUS_NX; ++i) {
            v = dopus_fabs(slot->phi[i] - x[(k + 1) * DOPUS_NX + i]);
            m = (v > m || isnan(v)) ? v : m;
        }
    }
    for (i = 0; i < DOPUS_NX; ++i) {
        v = dopus_fabs(gL_N[i] + mu_bN[i] + lam[DOPUS_N * DOPUS_NX + i]);
        m = (v > m || isnan(v)) ? v : m;
    }
    for (i = 0; i < DOPUS_NE; ++i) {
        v = dopus_fabs(r_eq[i]);
        m = (v > m || isnan(v)) ? v : m;
    }
    return m;
}

int dopus_diverged(const dopus_health *h, const dopus_real *xhat0, const dopus_real *x, const dopus_real *u,
                   const dopus_real *lam, const dopus_real *mu_b, const dopus_real *mu_bN)
{
    dopus_real ref = h->kkt_proxy_ref > DOPUS_R(1.0) ? h->kkt_proxy_ref : DOPUS_R(1.0);
    if (!dopus_box_ok(h, xhat0, x, 0, 0, u, 0, 0)) {
        return 1;
    }
    if (!dopus_lai_vec_finite((DOPUS_N + 1) * DOPUS_NX, lam) ||
        !dopus_lai_vec_finite(DOPUS_N * DOPUS_NW, mu_b) || !dopus_lai_vec_finite(DOPUS_NX, mu_bN)) {
        return 1;
    }
    return !(h->kkt_proxy <= DOPUS_DIVERGENCE_KKT * ref);
}

int dopus_health_stalled(dopus_health *h, int phase, int lm_held)
{
    dopus_real ref = h->kkt_proxy_init > DOPUS_R(1.0) ? h->kkt_proxy_init : DOPUS_R(1.0);
    int high, flat;
    if (h->recovering > 0) {
        h->n_stalled = 0;
        h->n_flat = 0;
        return 0;
    }
    high = h->kkt_proxy > DOPUS_STALL_KKT * ref;
    h->n_stalled = high ? h->n_stalled + 1 : 0;
    /* a flat stretch: the proxy well above its settled level, or above it with the automatic
     * lm held up by the convexity test (the damping that keeps the iterate from progressing),
     * and not falling */
    flat = h->kkt_proxy > DOPUS_FLAT_KKT * ref || (lm_held && h->kkt_proxy > DOPUS_FLAT_HELD_KKT * ref);
    if (!flat || h->n_flat == 0 || !(h->kkt_proxy > DOPUS_FLAT_DROP * h->kkt_flat_ref)) {
        h->kkt_flat_ref = h->kkt_proxy;
        h->n_flat = 0;
    }
    h->n_flat = flat ? h->n_flat + 1 : 0;
    if (h->n_stalled < DOPUS_STALL_PREPARES && h->n_flat < DOPUS_FLAT_PREPARES) {
        return 0;
    }
    h->n_stalled = 0;
    h->n_flat = 0;
    h->recovering = phase;
    return 1;
}

const dopus_real *dopus_health_plan_control(const dopus_health *h, int k)
{
    int j = h->plan_age + k;
    return h->plan_u[j > DOPUS_N - 1 ? DOPUS_N - 1 : j];
}

int dopus_health_fallback(dopus_health *h, int receding, dopus_real *u0)
{
    int i, clipped;
    clipped = dopus_clip_u(receding ? dopus_health_plan_control(h, 0) : h->plan_u[0], h->u0_out);
    if (u0) {
        for (i = 0; i < DOPUS_NU; ++i) {
            u0[i] = h->u0_out[i];
        }
    }
    return clipped;
}

int dopus_health_keep_plan(dopus_health *h, const dopus_real *u, dopus_real *u0)
{
    int k, i, clipped;
    h->n_failed = 0;
    h->plan_age = 0;
    h->recovering = h->recovering > 0 ? h->recovering - 1 : 0;
    for (k = 0; k < DOPUS_N; ++k) {
        for (i = 0; i < DOPUS_NU; ++i) {
            h->plan_u[k][i] = u[k * DOPUS_NU + i];
        }
    }
    clipped = dopus_clip_u(h->plan_u[0], h->u0_out);
    if (u0) {
        for (i = 0; i < DOPUS_NU; ++i) {
            u0[i] = h->u0_out[i];
        }
    }
    return clipped;
}
