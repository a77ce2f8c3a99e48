"""Random OCP-structured QPs with a known primal-dual solution, and independent solvers.

``make_qp`` constructs a QP in the dict format of harness.qp_harness around a chosen
point: it picks w*, lam*, nu* and an active set (strictly active bounds with nonzero signed
multipliers, weakly active ones with zero multiplier, inactive ones at a distance), then
sets the gradients g_k, gN so that the stationarity conditions hold exactly. When the
active constraints satisfy LICQ and the Hessian is positive definite on the null space of
the equalities (checked by ``check_unique``), that point is THE unique solution and its
multipliers are unique, so every array can be compared.

``solve_clarabel`` solves the same QP (stacked, sparse) with Clarabel and maps its duals
to the signed conventions of dopus_qp.h.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp

INF = np.inf


def _status_draw(rng, p_active, p_weak, p_free):
    r = rng.random()
    if r < p_active:
        return "active"
    if r < p_active + p_weak:
        return "weak"
    if r < p_active + p_weak + p_free:
        return "free"
    return "inactive"


def _row(rng, value, status, dual_scale, gap_scale, two_sided_prob=0.7):
    """Bounds (lo, up) around `value` and the signed multiplier for one row."""
    gap = gap_scale * rng.uniform(0.2, 2.0)
    side = rng.choice([-1.0, 1.0])
    other = gap_scale * rng.uniform(0.2, 2.0) if rng.random() < two_sided_prob else INF
    if status == "free":
        return -INF, INF, 0.0
    if status == "inactive":
        lo = value - gap if rng.random() < 0.8 else -INF
        up = value + gap_scale * rng.uniform(0.2, 2.0) if rng.random() < 0.8 else INF
        return lo, up, 0.0
    mu = side * dual_scale * rng.uniform(0.5, 2.0) if status == "active" else 0.0
    if side > 0:  # upper side active
        return value - other, value, mu
    return value, value + other, mu


def make_qp(rng, N, nx, nu, ng=0, nr=0, ne=0, *, p_active=0.25, p_weak=0.0, p_free=0.2,
            hessian="pd", var_scale=0.0, row_scale=0.0, eq_row_scale=0.0, dual_scale=1.0):
    """A random QP with known solution. Scales are log10 ranges of random factors."""
    nw = nx + nu
    xs = 10.0 ** rng.uniform(-var_scale, var_scale, nx)   # per-state scale, all stages
    us = 10.0 ** rng.uniform(-var_scale, var_scale, nu)
    ws_ = np.concatenate([xs, us])
    x = rng.standard_normal((N + 1, nx)) * xs
    u = rng.standard_normal((N, nu)) * us
    lam = rng.standard_normal((N + 1, nx)) * dual_scale
    nu_m = rng.standard_normal(ne) * dual_scale

    Phi = np.empty((N, nx, nw))
    b = np.empty((N, nx))
    H = np.empty((N, nw, nw))
    for k in range(N):
        A = np.eye(nx) + 0.3 * rng.standard_normal((nx, nx)) / np.sqrt(nx)
        A /= max(1.0, np.abs(np.linalg.eigvals(A)).max())  # long horizons stay well conditioned
        B = rng.standard_normal((nx, nu))
        # dynamics in the scaled variables: x~_{k+1} = A x~ + B u~
        Phi[k, :, :nx] = (A * xs[None, :]) / xs[:, None]
        Phi[k, :, nx:] = (B * us[None, :]) / xs[:, None]
        w = np.concatenate([x[k], u[k]])
        b[k] = x[k + 1] - Phi[k] @ w
        M = rng.standard_normal((nw, nw))
        Hs = M @ M.T / nw + 0.1 * np.eye(nw)
        if hessian == "psd":
            # rank-deficient: no curvature on the states and on one control direction
            Hs[:nx, :] = 0.0
            Hs[:, :nx] = 0.0
            if nu > 1:
                v = rng.standard_normal(nu)
                v /= np.linalg.norm(v)
                Hs[nx:, nx:] -= (v @ Hs[nx:, nx:] @ v) * np.outer(v, v)
                Hs[nx:, nx:] = 0.5 * (Hs[nx:, nx:] + Hs[nx:, nx:].T)
                ev, V = np.linalg.eigh(Hs[nx:, nx:])
                Hs[nx:, nx:] = (V * np.maximum(ev, 0.0)) @ V.T
        elif hessian == "indef":
            # small state curvature (congruence keeps it positive definite); make_indefinite
            # then shifts the state blocks down
            sc = np.concatenate([np.full(nx, np.sqrt(0.05)), np.ones(nu)])
            Hs = Hs * np.outer(sc, sc)
        H[k] = Hs / np.outer(ws_, ws_)
    MN = rng.standard_normal((nx, nx))
    HNs = MN @ MN.T / nx + 0.1 * np.eye(nx)
    if hessian == "psd":
        HNs = np.zeros((nx, nx))
    elif hessian == "indef":
        HNs *= 0.05
    HN = HNs / np.outer(xs, xs)

    # Active (strict or weak) rows are drawn under a degree-of-freedom budget so that they
    # satisfy LICQ together with the dynamics generically: rows of stage k touching u_k
    # (control bounds, general rows) use the nu controls of that stage, pure state rows use
    # freedom left over from earlier stages (at most nx can be carried in the state).
    def statuses(nrows, n_state_rows, budget, p_free_rows, max_total=None):
        st = [_status_draw(rng, p_active, p_weak, p_free_rows) for _ in range(nrows)]
        order = list(range(nrows))
        rng.shuffle(order)
        used_x = used_u = 0
        for i in order:
            if st[i] not in ("active", "weak"):
                continue
            if max_total is not None and used_x + used_u >= max_total:
                pass
            elif i < n_state_rows:
                if used_x < budget:
                    used_x += 1
                    continue
            elif used_u < nu:
                used_u += 1
                continue
            st[i] = "inactive"
        return st, used_x, used_u

    lbw = np.full((N, nw), -INF)
    ubw = np.full((N, nw), INF)
    mu_b = np.zeros((N, nw))
    C = np.zeros((N, ng, nw))
    lg = np.full((N, ng), -INF)
    ug = np.full((N, ng), INF)
    mu_g = np.zeros((N, ng))
    # terminal rows first: they and the ne equality rows use the controls of stage N-1
    n_term_cap = max(0, nu - min(ne, nu))
    st_term, _, used_term = statuses(nx + nr, 0, 0, p_free, max_total=n_term_cap)
    budget = 0
    for k in range(N):
        w = np.concatenate([x[k], u[k]])
        max_total = budget + nu
        if k == N - 1:
            max_total = max(0, nu - min(ne, nu) - used_term)
        st, used_x, used_u = statuses(nw + ng, nx if k > 0 else 0, budget, p_free, max_total=max_total)
        if k == 0:
            st[:nx] = ["free"] * nx
        # pure state rows of stage k+1 may only use controls of stage k left free (short
        # chains keep the active-set KKT matrix well conditioned)
        budget = min(nx, nu - used_u)
        for i in range(nw):
            if k == 0 and i < nx:
                continue
            lbw[k, i], ubw[k, i], mu_b[k, i] = _row(rng, w[i], st[i], dual_scale / ws_[i], ws_[i])
        for j in range(ng):
            rs = 10.0 ** rng.uniform(-row_scale, row_scale)
            C[k, j] = rng.standard_normal(nw) / ws_ * rs
            v = C[k, j] @ w
            stj = st[nw + j] if st[nw + j] != "free" else "inactive"
            lg[k, j], ug[k, j], mu_g[k, j] = _row(rng, v, stj, dual_scale / rs, rs)
    lbxN = np.full(nx, -INF)
    ubxN = np.full(nx, INF)
    mu_bN = np.zeros(nx)
    R = np.zeros((nr, nx))
    lr = np.full(nr, -INF)
    ur = np.full(nr, INF)
    mu_r = np.zeros(nr)
    st = st_term
    for i in range(nx):
        lbxN[i], ubxN[i], mu_bN[i] = _row(rng, x[N, i], st[i], dual_scale / xs[i], xs[i])
    for j in range(nr):
        rs = 10.0 ** rng.uniform(-row_scale, row_scale)
        R[j] = rng.standard_normal(nx) / xs * rs
        stj = st[nx + j] if st[nx + j] != "free" else "inactive"
        lr[j], ur[j], mu_r[j] = _row(rng, R[j] @ x[N], stj, dual_scale / rs, rs)
    Req = np.zeros((ne, nx))
    for j in range(ne):
        Req[j] = rng.standard_normal(nx) / xs * 10.0 ** rng.uniform(-eq_row_scale, eq_row_scale)
    req = Req @ x[N]

    g = np.empty((N, nw))
    for k in range(N):
        w = np.concatenate([x[k], u[k]])
        r = H[k] @ w + np.concatenate([lam[k], np.zeros(nu)]) - Phi[k].T @ lam[k + 1] + C[k].T @ mu_g[k] + mu_b[k]
        g[k] = -r
    gN = -(HN @ x[N] + lam[N] + R.T @ mu_r + Req.T @ nu_m + mu_bN)

    qp = dict(N=N, nx=nx, nu=nu, ng=ng, nr=nr, ne=ne, H=H, g=g, Phi=Phi, b=b, x0=x[0].copy(), HN=HN, gN=gN,
              lbw=lbw, ubw=ubw, lbxN=lbxN, ubxN=ubxN, C=C, lg=lg, ug=ug, R=R, lr=lr, ur=ur, Req=Req, req=req)
    sol = dict(x=x, u=u, lam=lam, mu_b=mu_b, mu_bN=mu_bN, mu_g=mu_g, mu_r=mu_r, nu=nu_m)
    return qp, sol


# ------------------------------------------------------------------ stacked form

def stacked(qp):
    """Dense stacked data: z = (w_0, ..., w_{N-1}, x_N).
    Returns P, q, Aeq, beq, D (inequality rows), lo, up, and index helpers."""
    N, nx, nu, ng, nr, ne = (int(qp[k]) for k in ("N", "nx", "nu", "ng", "nr", "ne"))
    nw = nx + nu
    n = N * nw + nx
    P = np.zeros((n, n))
    q = np.zeros(n)
    for k in range(N):
        s = slice(k * nw, (k + 1) * nw)
        P[s, s] = qp["H"][k]
        q[s] = qp["g"][k]
    P[N * nw:, N * nw:] = qp["HN"]
    q[N * nw:] = qp["gN"]
    P = 0.5 * (P + P.T)
    Aeq = np.zeros(((N + 1) * nx + ne, n))
    beq = np.zeros((N + 1) * nx + ne)
    Aeq[:nx, :nx] = np.eye(nx)
    beq[:nx] = qp["x0"]
    for k in range(N):
        r = slice((k + 1) * nx, (k + 2) * nx)
        Aeq[r, k * nw:(k + 1) * nw] = -qp["Phi"][k]
        Aeq[r, (k + 1) * nw:(k + 1) * nw + nx] += np.eye(nx)
        beq[r] = qp["b"][k]
    if ne:
        Aeq[(N + 1) * nx:, N * nw:] = qp["Req"]
        beq[(N + 1) * nx:] = qp["req"]
    rows, lo, up = [], [], []
    for k in range(N):
        for i in range(nw):
            e = np.zeros(n)
            e[k * nw + i] = 1.0
            rows.append(e)
            if k == 0 and i < nx:
                lo.append(-INF); up.append(INF)
            else:
                lo.append(qp["lbw"][k, i]); up.append(qp["ubw"][k, i])
        for j in range(ng):
            e = np.zeros(n)
            e[k * nw:(k + 1) * nw] = qp["C"][k, j]
            rows.append(e); lo.append(qp["lg"][k, j]); up.append(qp["ug"][k, j])
    for i in range(nx):
        e = np.zeros(n)
        e[N * nw + i] = 1.0
        rows.append(e); lo.append(qp["lbxN"][i]); up.append(qp["ubxN"][i])
    for j in range(nr):
        e = np.zeros(n)
        e[N * nw:] = qp["R"][j]
        rows.append(e); lo.append(qp["lr"][j]); up.append(qp["ur"][j])
    D = np.array(rows)
    return P, q, Aeq, beq, D, np.array(lo, float), np.array(up, float)


def stack_primal(qp, sol):
    N, nx, nu = (int(qp[k]) for k in ("N", "nx", "nu"))
    z = [np.concatenate([sol["x"][k], sol["u"][k]]) for k in range(N)]
    return np.concatenate(z + [sol["x"][N]])


def signed_rows(qp, sol):
    """Signed inequality multipliers in the row order of ``stacked``."""
    N, nx, nu, ng, nr = (int(qp[k]) for k in ("N", "nx", "nu", "ng", "nr"))
    out = []
    for k in range(N):
        out.extend(sol["mu_b"][k])
        out.extend(sol["mu_g"][k])
    out.extend(sol["mu_bN"])
    out.extend(sol["mu_r"])
    return np.array(out, float)


def unstack(qp, z, y_eq, y_in):
    N, nx, nu, ng, nr, ne = (int(qp[k]) for k in ("N", "nx", "nu", "ng", "nr", "ne"))
    nw = nx + nu
    x = np.array([z[k * nw:k * nw + nx] for k in range(N)] + [z[N * nw:]])
    u = np.array([z[k * nw + nx:(k + 1) * nw] for k in range(N)]).reshape(N, nu)
    lam = y_eq[:(N + 1) * nx].reshape(N + 1, nx)
    nu_m = y_eq[(N + 1) * nx:]
    per = nw + ng
    mu_b = np.array([y_in[k * per:k * per + nw] for k in range(N)])
    mu_g = np.array([y_in[k * per + nw:(k + 1) * per] for k in range(N)]).reshape(N, ng)
    mu_bN = y_in[N * per:N * per + nx]
    mu_r = y_in[N * per + nx:]
    return dict(x=x, u=u, lam=lam, mu_b=mu_b, mu_bN=mu_bN, mu_g=mu_g, mu_r=mu_r, nu=nu_m)


def kkt_residual(qp, sol, scaled=False):
    """Infinity norms (stat, eq, ineq, comp) of the KKT conditions in dopus_qp.h signs;
    scaled: stat and comp divided by max(1, largest multiplier)."""
    P, q, Aeq, beq, D, lo, up = stacked(qp)
    z = stack_primal(qp, sol)
    ye = np.concatenate([sol["lam"].ravel(), sol["nu"]])
    yi = signed_rows(qp, sol)
    stat = P @ z + q + Aeq.T @ ye + D.T @ yi
    eq = Aeq @ z - beq
    v = D @ z
    with np.errstate(invalid="ignore"):
        viol = np.maximum(0.0, np.maximum(np.where(np.isfinite(lo), lo - v, 0.0), np.where(np.isfinite(up), v - up, 0.0)))
        cu = np.where(yi > 0, yi * np.where(np.isfinite(up), np.abs(up - v), 1.0), 0.0)
        cl = np.where(yi < 0, -yi * np.where(np.isfinite(lo), np.abs(v - lo), 1.0), 0.0)
    out = dict(stat=np.abs(stat).max(), eq=np.abs(eq).max(initial=0.0), ineq=viol.max(initial=0.0),
               comp=max(cu.max(initial=0.0), cl.max(initial=0.0)))
    if scaled:
        s = max(1.0, np.abs(ye).max(initial=0.0), np.abs(yi).max(initial=0.0))
        out["stat"] /= s
        out["comp"] /= s
    return out


def check_unique(qp, sol, tol=1e-9):
    """LICQ of the equalities + active rows, and positive definiteness of the Hessian on
    the null space of the equalities and the strictly active rows. Returns the smallest
    eigenvalue of the reduced Hessian and of the Hessian on the equality null space."""
    P, q, Aeq, beq, D, lo, up = stacked(qp)
    z = stack_primal(qp, sol)
    yi = signed_rows(qp, sol)
    v = D @ z
    scale = np.maximum(1.0, np.abs(v))
    active = (np.abs(v - lo) <= 1e-12 * scale) | (np.abs(up - v) <= 1e-12 * scale)
    strict = active & (yi != 0.0)
    J = np.vstack([Aeq, D[active]])
    Jn = J / np.linalg.norm(J, axis=1, keepdims=True)
    s = np.linalg.svd(Jn, compute_uv=False)
    licq = s.min() > tol * s.max() and J.shape[0] <= J.shape[1]
    Z = sla.null_space(np.vstack([Aeq, D[strict]]))
    red = np.linalg.eigvalsh(Z.T @ P @ Z).min() if Z.shape[1] else np.inf
    Ze = sla.null_space(Aeq)
    red_eq = np.linalg.eigvalsh(Ze.T @ P @ Ze).min() if Ze.shape[1] else np.inf
    return licq, red, red_eq


def _clarabel_solve(P, q, A, b, n_eq, n_in, tol):
    """Clarabel (an independent interior point) on min 0.5 z'Pz + q'z s.t. A z + s = b with
    s in {0}^n_eq x R+^n_in, at tolerance tol."""
    import clarabel

    cones = [clarabel.ZeroConeT(n_eq)]
    if n_in:
        cones.append(clarabel.NonnegativeConeT(n_in))
    st = clarabel.DefaultSettings()
    st.verbose = False
    st.tol_gap_abs = tol
    st.tol_gap_rel = tol
    st.tol_feas = tol
    st.tol_ktratio = 1e-8
    st.max_iter = 500
    solver = clarabel.DefaultSolver(sp.csc_matrix(np.triu(P)), q, sp.csc_matrix(A), b, cones, st)
    return solver.solve()


def solve_clarabel(qp, tol=1e-11):
    """Solve with Clarabel; returns (status string, solution dict in dopus_qp.h signs)."""
    P, q, Aeq, beq, D, lo, up = stacked(qp)
    hasu = np.isfinite(up)
    hasl = np.isfinite(lo)
    A = np.vstack([Aeq, D[hasu], -D[hasl]])
    bvec = np.concatenate([beq, up[hasu], -lo[hasl]])
    res = _clarabel_solve(P, q, A, bvec, Aeq.shape[0], int(hasu.sum() + hasl.sum()), tol)
    status = str(res.status)
    y = np.array(res.z)
    ne_rows = Aeq.shape[0]
    yi = np.zeros(D.shape[0])
    yi[hasu] += y[ne_rows:ne_rows + hasu.sum()]
    yi[hasl] -= y[ne_rows + hasu.sum():]
    return status, unstack(qp, np.array(res.x), y[:ne_rows], yi)


def compare(a, b, keys=("x", "u", "lam", "mu_b", "mu_bN", "mu_g", "mu_r", "nu")):
    """Largest relative difference per array: |a - b|_inf / max(1, |b|_inf)."""
    out = {}
    for k in keys:
        A = np.asarray(a[k], float)
        B = np.asarray(b[k], float)
        if B.size == 0:
            out[k] = 0.0
            continue
        out[k] = float(np.abs(A - B).max() / max(1.0, np.abs(B).max()))
    return out


def recompute_gradients(qp, sol):
    """Set g, gN so that the stationarity conditions hold exactly at sol."""
    N, nx, nu = (int(qp[k]) for k in ("N", "nx", "nu"))
    for k in range(N):
        w = np.concatenate([sol["x"][k], sol["u"][k]])
        r = (qp["H"][k] @ w + np.concatenate([sol["lam"][k], np.zeros(nu)]) - qp["Phi"][k].T @ sol["lam"][k + 1]
             + qp["C"][k].T @ sol["mu_g"][k] + sol["mu_b"][k])
        qp["g"][k] = -r
    qp["gN"] = -(qp["HN"] @ sol["x"][N] + sol["lam"][N] + qp["R"].T @ sol["mu_r"] + qp["Req"].T @ sol["nu"]
                 + sol["mu_bN"])


def make_indefinite(qp, sol, frac=0.6):
    """Subtract gamma*I from the state blocks of H_1..H_{N-1} and HN, with gamma = frac times
    the largest shift that keeps the Hessian positive definite on the null space of the
    equalities (x0, dynamics, Req). The QP stays strictly convex on its feasible set (so sol
    is its unique solution) while stage blocks become indefinite. Returns the smallest
    block eigenvalue and the smallest reduced eigenvalue after the shift."""
    N, nx, nu = (int(qp[k]) for k in ("N", "nx", "nu"))
    nw = nx + nu
    P, q, Aeq, beq, D, lo, up = stacked(qp)
    Z = sla.null_space(Aeq)
    E = np.zeros(P.shape[0])
    for k in range(1, N):
        E[k * nw:k * nw + nx] = 1.0
    E[N * nw:] = 1.0
    A = Z.T @ P @ Z
    B = (Z.T * E) @ Z
    mu = sla.eigh(B, A, eigvals_only=True).max()
    gamma = frac / mu
    for k in range(1, N):
        qp["H"][k][:nx, :nx] -= gamma * np.eye(nx)
    qp["HN"] = qp["HN"] - gamma * np.eye(nx)
    recompute_gradients(qp, sol)
    P2 = stacked(qp)[0]
    block_min = min(np.linalg.eigvalsh(qp["H"][k]).min() for k in range(N))
    block_min = min(block_min, np.linalg.eigvalsh(qp["HN"]).min())
    red_min = np.linalg.eigvalsh(Z.T @ P2 @ Z).min()
    return block_min, red_min


def kkt_sigma_min(qp, sol):
    """Smallest singular value of the KKT matrix of the active set [[P, J'], [J, 0]]
    (J: equalities and strictly active rows), rows of J normalised: small values mean the
    solution and multipliers are ill-conditioned functions of the data."""
    P, q, Aeq, beq, D, lo, up = stacked(qp)
    z = stack_primal(qp, sol)
    v = D @ z
    scale = np.maximum(1.0, np.abs(v))
    active = ((np.abs(v - lo) <= 1e-12 * scale) | (np.abs(up - v) <= 1e-12 * scale))
    J = np.vstack([Aeq, D[active]])
    J = J / np.linalg.norm(J, axis=1, keepdims=True)
    n, m = P.shape[0], J.shape[0]
    K = np.zeros((n + m, n + m))
    K[:n, :n] = P / max(1.0, np.abs(P).max())
    K[:n, n:] = J.T
    K[n:, :n] = J
    return np.linalg.svd(K, compute_uv=False).min()


def make_infeasible(rng, N, nx, nu, ng, nr, ne, kind, margin=None):
    """A random QP made primal infeasible in one of several ways (requires the sizes the
    kind needs: 'row_vs_box' ng >= 1, 'terminal_eq_vs_box' ne >= 1, 'unreachable' nu >= 1,
    'terminal_rows' nr >= 2). ``margin`` (all kinds but 'terminal_rows'): the relative
    distance by which the general row's range misses the control's box, the terminal
    equality's value misses the box of x_N, or the target lies beyond the reachable set
    (default: random in [0.01, 1]; the random draw is made either way, so the rest of the
    QP does not depend on it)."""
    qp, _ = make_qp(rng, N, nx, nu, ng, nr, ne, p_active=0.2)
    k = int(rng.integers(1, N)) if N > 1 else 0
    if kind == "row_vs_box":
        # a general row equal to one control, with its range above the control's box
        j = nx + int(rng.integers(nu)) if nu else int(rng.integers(nx))
        qp["C"][k, 0] = 0.0
        qp["C"][k, 0, j] = rng.uniform(0.5, 2.0)
        qp["lbw"][k, j], qp["ubw"][k, j] = -1.0, 1.0
        m = rng.uniform(0.01, 1.0)
        qp["lg"][k, 0] = qp["C"][k, 0, j] * (1.0 + (m if margin is None else margin))
        qp["ug"][k, 0] = np.inf
    elif kind == "terminal_eq_vs_box":
        # Req x_N = req forces x_N[i] outside its box
        i = int(rng.integers(nx))
        qp["Req"][0] = 0.0
        qp["Req"][0, i] = rng.uniform(0.5, 2.0) * 10.0 ** rng.uniform(-3, 3)
        qp["lbxN"][i], qp["ubxN"][i] = -1.0, 1.0
        m = rng.uniform(0.01, 1.0)
        qp["req"][0] = qp["Req"][0, i] * (1.0 + (m if margin is None else margin))
    elif kind == "unreachable":
        # controls boxed in [-1, 1], x_1 must reach a target outside the reachable set
        qp["lbw"][0, nx:], qp["ubw"][0, nx:] = -1.0, 1.0
        A, B = qp["Phi"][0][:, :nx], qp["Phi"][0][:, nx:]
        reach = np.abs(B).sum(axis=1)
        i = int(np.argmax(reach))
        centre = A[i] @ qp["x0"] + qp["b"][0, i]
        m = rng.uniform(0.01, 1.0)
        beyond = centre + reach[i] * (1.0 + (m if margin is None else margin))
        qp["lbw"][1, i] = beyond if N > 1 else -np.inf
        qp["ubw"][1, i] = np.inf
        if N == 1:
            qp["lbxN"][i] = beyond
            qp["ubxN"][i] = np.inf
    elif kind == "terminal_rows":
        # two terminal rows r and -r with contradicting ranges
        qp["R"][1] = -qp["R"][0] * rng.uniform(0.5, 2.0)
        s = qp["R"][1, 0] / qp["R"][0, 0] if qp["R"][0, 0] else 1.0
        qp["lr"][0], qp["ur"][0] = 1.0, 2.0
        # R1 x = s R0 x in [s, 2s] (s < 0): demand R1 x >= -s/2 > 0 instead
        qp["lr"][1], qp["ur"][1] = -0.5 * s * 2.0, np.inf
    else:
        raise ValueError(kind)
    if margin is not None and kind == "terminal_rows":
        raise ValueError("margin is not implemented for terminal_rows")
    return qp


def least_violation(qp):
    """The smallest violation any point of the QP reaches, in the units of each row's largest
    coefficient: the linear programme (HiGHS) min t over z and t with the initial state and
    the dynamics exact and every other row relaxed by t, ``|Req z - req| <= t`` and
    ``lo - t <= D z <= up + t`` with the rows of Req and D scaled to unit infinity norm
    (the dynamics rows too, so that the LP's tolerances are relative to each row). Positive
    for an infeasible QP (independent of the QP solvers: the stacked data of
    :func:`stacked`, no certificate of theirs)."""
    from scipy.optimize import linprog

    P_, q, Aeq, beq, D, lo, up = stacked(qp)
    n = Aeq.shape[1]
    n_dyn = (int(qp["N"]) + 1) * int(qp["nx"])

    def unit(A, *vecs):
        s = np.abs(A).max(axis=1)
        s[s == 0.0] = 1.0
        return (A / s[:, None],) + tuple(v / s for v in vecs)

    A_dyn, b_dyn = unit(Aeq[:n_dyn], beq[:n_dyn])
    A_e, b_e = unit(Aeq[n_dyn:], beq[n_dyn:])
    D_, lo_, up_ = unit(D, lo, up)
    hi, lw = np.isfinite(up_), np.isfinite(lo_)
    # rows over (z, t): D z - t <= up, -D z - t <= -lo, +-(Req z - req) - t <= 0
    A_ub = np.vstack([np.hstack([D_[hi], -np.ones((hi.sum(), 1))]),
                      np.hstack([-D_[lw], -np.ones((lw.sum(), 1))]),
                      np.hstack([A_e, -np.ones((A_e.shape[0], 1))]),
                      np.hstack([-A_e, -np.ones((A_e.shape[0], 1))])])
    b_ub = np.concatenate([up_[hi], -lo_[lw], b_e, -b_e])
    A_eq = np.hstack([A_dyn, np.zeros((n_dyn, 1))])
    c = np.zeros(n + 1)
    c[-1] = 1.0
    res = linprog(c, A_ub=A_ub, b_ub=b_ub, A_eq=A_eq, b_eq=b_dyn, bounds=[(None, None)] * n + [(0, None)],
                  method="highs", options={"primal_feasibility_tolerance": 1e-10,
                                           "dual_feasibility_tolerance": 1e-10})
    assert res.status == 0, res.message
    return float(res.x[-1])


def make_unbounded(rng, N, nx, nu, ng, nr, ne):
    """Convex QP unbounded below: one control has no curvature, no bounds, and a cost slope."""
    qp, _ = make_qp(rng, N, nx, nu, ng, nr, ne, p_active=0.0, p_free=1.0)
    k = int(rng.integers(N))
    j = nx + int(rng.integers(nu))
    for kk in range(N):
        qp["H"][kk][j, :] = 0.0
        qp["H"][kk][:, j] = 0.0
    qp["H"][k][j, :] = 0.0
    qp["g"][k][j] = -rng.uniform(0.5, 2.0)
    # the control must not move anything constrained: cut it out of the dynamics
    qp["Phi"][k][:, j] = 0.0
    qp["C"][k][:, j] = 0.0
    qp["lbw"][k, j], qp["ubw"][k, j] = -np.inf, np.inf
    return qp


def objective(qp, sol):
    P_, q, *_ = stacked(qp)
    z = stack_primal(qp, sol)
    return float(0.5 * z @ P_ @ z + q @ z)


def active_mask(qp, sol, key, tol=1e-12):
    """Which entries of the multiplier array `key` belong to rows at a bound of sol."""
    P_, q, Aeq, beq, D, lo, up = stacked(qp)
    z = stack_primal(qp, sol)
    v = D @ z
    scale = np.maximum(1.0, np.abs(v))
    act = (np.abs(v - lo) <= tol * scale) | (np.abs(up - v) <= tol * scale)
    # split the row order of `stacked` back into the arrays
    N, nx, nu, ng, nr = (int(qp[k]) for k in ("N", "nx", "nu", "ng", "nr"))
    nw = nx + nu
    per = nw + ng
    if key == "mu_b":
        return np.array([act[k * per:k * per + nw] for k in range(N)])
    if key == "mu_g":
        return np.array([act[k * per + nw:(k + 1) * per] for k in range(N)]).reshape(N, ng)
    if key == "mu_bN":
        return act[N * per:N * per + nx]
    if key == "mu_r":
        return act[N * per + nx:]
    raise KeyError(key)


def reduced_hessian_min(qp, sol, act_tol=1e-7):
    """Smallest eigenvalue of the Hessian on the null space of the equalities and the rows
    that are active (within act_tol) at sol with a nonzero multiplier: >= 0 at a local
    minimiser, < 0 at a saddle point."""
    P_, q, Aeq, beq, D, lo, up = stacked(qp)
    z = stack_primal(qp, sol)
    yi = signed_rows(qp, sol)
    v = D @ z
    scale = np.maximum(1.0, np.abs(v))
    act = ((np.abs(v - lo) <= act_tol * scale) | (np.abs(up - v) <= act_tol * scale)) & (np.abs(yi) > act_tol)
    Z = sla.null_space(np.vstack([Aeq, D[act]]))
    return np.linalg.eigvalsh(Z.T @ P_ @ Z).min() if Z.shape[1] else np.inf


def solve_piqp(qp, tol=1e-12):
    """Solve with PIQP; returns (status string, solution dict in dopus_qp.h signs)."""
    import piqp

    P_, q, Aeq, beq, D, lo, up = stacked(qp)
    s = piqp.SparseSolver()
    s.settings.verbose = False
    s.settings.eps_abs = tol
    s.settings.eps_rel = 0.0
    s.settings.eps_duality_gap_abs = tol
    s.settings.eps_duality_gap_rel = 0.0
    s.settings.max_iter = 500
    s.settings.iterative_refinement_always_enabled = True
    rows = np.isfinite(lo) | np.isfinite(up)
    s.setup(sp.csc_matrix(P_), q, sp.csc_matrix(Aeq), beq, sp.csc_matrix(D[rows]), lo[rows], up[rows])
    status = str(s.solve())
    r = s.result
    z = np.array(r.x)
    y = np.array(r.y)
    yi = np.zeros(D.shape[0])
    yi[rows] = np.array(r.z_u) - np.array(r.z_l)
    # PIQP's sign of the equality multipliers: fix it from stationarity
    stat_plus = P_ @ z + q + Aeq.T @ y + D.T @ yi
    stat_minus = P_ @ z + q - Aeq.T @ y + D.T @ yi
    if np.abs(stat_minus).max() < np.abs(stat_plus).max():
        y = -y
    return status, unstack(qp, z, y, yi)


def solve_independent(qp):
    """PIQP at 1e-12 (the most accurate of the two on these problems); Clarabel at 1e-12
    when PIQP does not converge (it stalls on terminal equality rows scaled by 1e4).
    Returns ("solved" or the failing statuses, solution)."""
    st, sol = solve_piqp(qp, tol=1e-12)
    if "SOLVED" in st:
        return "solved", sol
    st2, sol2 = solve_clarabel(qp, tol=1e-12)
    if st2 == "Solved":
        return "solved", sol2
    return f"{st} / {st2}", sol


def soft_row_weights(qp):
    """The soft weights of the rows of ``stacked`` (4, rows): rows (zl, zu, Zl, Zu); zero on
    the sides without a finite bound."""
    from dopus_codegen.reference.qp import soft_weights

    N = int(qp["N"])
    ws, wt = soft_weights(qp)
    return np.hstack([ws] * N + [wt])


def solve_clarabel_soft(qp, tol=1e-11):
    """Clarabel on the QP with its soft sides as explicit slack variables ``s >= 0``
    (``lo - s <= D z``, ``D z <= up + s``, cost ``zl s + 0.5 Zl s^2``); returns (status,
    solution dict in dopus_qp.h signs, slacks of the lower and upper sides per row)."""
    P, q, Aeq, beq, D, lo, up = stacked(qp)
    W = soft_row_weights(qp)
    n, m = P.shape[0], D.shape[0]
    soft_lo = np.isfinite(lo) & ((W[0] > 0) | (W[2] > 0))
    soft_up = np.isfinite(up) & ((W[1] > 0) | (W[3] > 0))
    il, iu = np.flatnonzero(soft_lo), np.flatnonzero(soft_up)
    ns = il.size + iu.size
    Pz = np.zeros((n + ns, n + ns))
    Pz[:n, :n] = P
    Pz[n + np.arange(ns), n + np.arange(ns)] = np.concatenate([W[2, il], W[3, iu]])
    qz = np.concatenate([q, W[0, il], W[1, iu]])
    Aeqz = np.hstack([Aeq, np.zeros((Aeq.shape[0], ns))])
    # columns of the slacks per row and side
    Sl = np.zeros((m, ns))
    Sl[il, np.arange(il.size)] = 1.0
    Su = np.zeros((m, ns))
    Su[iu, il.size + np.arange(iu.size)] = 1.0
    hasu, hasl = np.isfinite(up), np.isfinite(lo)
    Dz = np.hstack([D, np.zeros((m, ns))])
    A = np.vstack([Aeqz, (Dz - np.hstack([np.zeros((m, n)), Su]))[hasu],
                   (-Dz - np.hstack([np.zeros((m, n)), Sl]))[hasl],
                   np.hstack([np.zeros((ns, n)), -np.eye(ns)])])
    bvec = np.concatenate([beq, up[hasu], -lo[hasl], np.zeros(ns)])
    res = _clarabel_solve(Pz, qz, A, bvec, Aeq.shape[0], int(hasu.sum() + hasl.sum()) + ns, tol)
    y = np.array(res.z)
    ne_rows = Aeq.shape[0]
    yi = np.zeros(m)
    yi[hasu] += y[ne_rows:ne_rows + hasu.sum()]
    yi[hasl] -= y[ne_rows + hasu.sum():ne_rows + hasu.sum() + hasl.sum()]
    zz = np.array(res.x)
    s_lo, s_up = np.zeros(m), np.zeros(m)
    s_lo[il] = zz[n:n + il.size]
    s_up[iu] = zz[n + il.size:]
    return str(res.status), unstack(qp, zz[:n], y[:ne_rows], yi), (s_lo, s_up)


def make_soft_qp(rng, N, nx, nu, ng=0, nr=0, ne=0, *, l1=True, l2=True, frac=0.5):
    """A random convex QP (``make_qp``) with soft weights on a random part (``frac``) of its
    state, path and terminal rows, and the bounds of those rows moved inwards so that the
    solution of the hard problem would violate many of them (the soft rows are active).
    ``l1``/``l2``: which penalty terms the weights have."""
    qp, sol = make_qp(rng, N, nx, nu, ng, nr, ne, p_active=0.3)
    nw = nx + nu
    ws = np.zeros((4, nw + ng))
    wt = np.zeros((4, nx + nr))
    for w, idx in ((ws, list(range(nx)) + list(range(nw, nw + ng))), (wt, list(range(nx + nr)))):
        for i in idx:
            if rng.uniform() < frac:
                w[0:2, i] = rng.uniform(0.1, 3.0, 2) if l1 else 0.0
                w[2:4, i] = rng.uniform(0.1, 10.0, 2) if l2 else 0.0
    qp.update(zl=ws[0], zu=ws[1], Zl=ws[2], Zu=ws[3], zlN=wt[0], zuN=wt[1], ZlN=wt[2], ZuN=wt[3])
    # move the finite bounds of the soft rows inwards by a random amount
    for k in range(N):
        for i in range(nx):
            if ws[0, i] + ws[2, i] > 0 and k > 0:
                c = sol["x"][k, i]
                qp["lbw"][k, i] = c + rng.uniform(-0.5, 0.5)
                qp["ubw"][k, i] = qp["lbw"][k, i] + rng.uniform(0.0, 0.5)
        for j in range(ng):
            if ws[0, nw + j] + ws[2, nw + j] > 0:
                c = qp["C"][k, j] @ np.concatenate([sol["x"][k], sol["u"][k]])
                qp["lg"][k, j] = c + rng.uniform(-0.5, 0.5)
                qp["ug"][k, j] = qp["lg"][k, j] + rng.uniform(0.0, 0.5)
    for i in range(nx):
        if wt[0, i] + wt[2, i] > 0:
            qp["lbxN"][i] = sol["x"][N, i] + rng.uniform(-0.5, 0.5)
            qp["ubxN"][i] = qp["lbxN"][i] + rng.uniform(0.0, 0.5)
    for j in range(nr):
        if wt[0, nx + j] + wt[2, nx + j] > 0:
            c = qp["R"][j] @ sol["x"][N]
            qp["lr"][j] = c + rng.uniform(-0.5, 0.5)
            qp["ur"][j] = qp["lr"][j] + (rng.uniform(0.0, 0.5) if rng.uniform() < 0.7 else 0.0)
    return qp
