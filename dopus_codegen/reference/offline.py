"""Offline solution of the multiple-shooting NLP with IPOPT.

The NLP is exactly the one DOPUS iterates on (docs/algorithm.md section 1), built from
the same ``stage_eval``/``term_eval`` functions of a :class:`Discretized`:

    variables   V = (x_0, u_0, x_1, u_1, ..., x_{N-1}, u_{N-1}, x_N)
    constraints x_0 - xhat_0 = 0;  per stage k: x_{k+1} - phi_k = 0, lg <= g_k <= ug;
                lr <= r(x_N) <= ur;  r_eq(x_N) = 0
    bounds      lbu <= u_k <= ubu;  lbx <= x_k <= ubx for k >= 1 (x_0 free)

CasADi's IPOPT interface uses the Lagrangian ``f + lam_g' g + lam_x' V`` with multipliers
positive when the upper side is active. Each constraint above is written so that this
is term by term the Lagrangian of algorithm.md section 1 (``lam_0'(x_0 - xhat_0)``,
``lam_{k+1}'(x_{k+1} - phi_k)``, ``mu_g' g``, ``mu_r' r``, ``nu' r_eq``, ``mu_b' w``),
so the IPOPT multipliers are the signed multipliers of the project without any sign
flip. ``tests/test_offline.py`` checks this through the KKT measure.

Soft rows (docs/algorithm.md section 12) get explicit slack variables ``s >= 0`` appended to
``V``: a soft path or terminal row becomes ``lg <= g + s_lo - s_up <= ug`` (``s_lo`` only on
a soft lower side, ``s_up`` on a soft upper one), a state component with a soft bound leaves
the variable bounds for the row ``lbx <= x + s_lo - s_up <= ubx`` (appended after the rows
above), and the objective gains ``l1 s + 0.5 l2 s^2`` per slack. The rows' multipliers are
the signed multipliers of the project as before.
"""
from __future__ import annotations

import weakref

import numpy as np
import casadi as ca

from .. import interrupt
from ..problem.ocp import Guess
from .qp import free_initial_state

__all__ = ["solve_ocp", "nlp_layout"]


def nlp_layout(disc):
    """Index arrays of the NLP vectors: ``(ix (N+1, nx), iu (N, nu), ig_dyn (N+1, nx)
    [row 0 = x_0 - xhat_0], ig_path (N, ng), ig_r (nr,), ig_eq (ne,))``."""
    N, nx, nu, ng, nr, ne = disc.N, disc.nx, disc.nu, disc.ng, disc.nr, disc.ne
    nw = nx + nu
    ix = np.array([np.arange(nx) + k * nw for k in range(N + 1)])
    iu = np.array([np.arange(nu) + k * nw + nx for k in range(N)])
    ig_dyn = np.zeros((N + 1, nx), dtype=int)
    ig_path = np.zeros((N, ng), dtype=int)
    ig_dyn[0] = np.arange(nx)
    row = nx
    for k in range(N):
        ig_dyn[k + 1] = np.arange(nx) + row
        row += nx
        ig_path[k] = np.arange(ng) + row
        row += ng
    ig_r = np.arange(nr) + row
    ig_eq = np.arange(ne) + row + nr
    return ix, iu, ig_dyn, ig_path, ig_r, ig_eq


def soft_layout(disc):
    """The slacks of the soft rows: ``(slacks, state_rows)``; ``slacks`` a list of
    ``(kind, k, i, side, l1, l2)`` (kind "x" node k = 1..N, "g" stage k, "r"; side -1 lower,
    +1 upper), one slack variable each in this order; ``state_rows`` the ``(k, i)`` of the
    state components whose bounds became rows. Empty without soft rows."""
    if not getattr(disc, "has_soft", False):
        return [], []
    N, nx, ng, nr = disc.N, disc.nx, disc.ng, disc.nr
    slacks, state_rows = [], []

    def sides(kind, k, i, lo, up, w):
        out = []
        for side, bound, l1, l2 in ((-1, lo, w[0], w[2]), (1, up, w[1], w[3])):
            if np.isfinite(bound) and (l1 > 0 or l2 > 0):
                out.append((kind, k, i, side, float(l1), float(l2)))
        return out

    sx, sg, sr = np.asarray(disc.soft_x), np.asarray(disc.soft_g), np.asarray(disc.soft_r)
    for k in range(1, N + 1):
        for i in range(nx):
            new = sides("x", k, i, disc.lbx[i], disc.ubx[i], sx[:, i])
            if new:
                state_rows.append((k, i))
                slacks += new
    for k in range(N):
        for i in range(ng):
            slacks += sides("g", k, i, disc.lg[i], disc.ug[i], sg[:, i])
    for i in range(nr):
        slacks += sides("r", 0, i, disc.lr[i], disc.ur[i], sr[:, i])
    return slacks, state_rows


def _slack_sum(T, S, slacks, kind, k, n):
    """``s_lo - s_up`` of the ``n`` rows of ``kind`` at ``k`` (zeros where hard)."""
    out = [T(0) for _ in range(n)]
    for j, (kd, kk, i, side, _, _) in enumerate(slacks):
        if kd == kind and kk == k:
            out[i] = out[i] - side * S[j]
    return ca.vertcat(*out) if n else T(0, 1)


def _build_solver(disc, hessian: str, tol: float, max_iter: int):
    N, nx, nu, npar = disc.N, disc.nx, disc.nu, disc.np
    nw = nx + nu
    # SX when every function can be evaluated symbolically in SX; an implicit integrator
    # (a rootfinder inside the stage functions) needs MX
    T = ca.SX if _sx_ok(disc) else ca.MX
    slacks, state_rows = soft_layout(disc)
    V = T.sym("V", N * nw + nx + len(slacks))
    S = V[N * nw + nx:]
    P = T.sym("P", nx + (N + 1) * npar)     # (xhat_0, p_0, ..., p_N)
    xhat0 = P[:nx]

    def xk(k):
        return V[k * nw:k * nw + nx]

    def uk(k):
        return V[k * nw + nx:(k + 1) * nw]

    def pk(k):
        return P[nx + k * npar:nx + (k + 1) * npar]

    f = 0
    for j, (_, _, _, _, l1, l2) in enumerate(slacks):
        f = f + l1 * S[j] + 0.5 * l2 * S[j] ** 2
    g = [xk(0) - xhat0]
    for k in range(N):
        phi, l, gk = disc.stage_eval(xk(k), uk(k), pk(k))
        f = f + l
        if slacks and disc.ng:
            gk = gk + _slack_sum(T, S, slacks, "g", k, disc.ng)
        g += [xk(k + 1) - phi, gk]
    E, r, r_eq = disc.term_eval(xk(N), pk(N))
    f = f + E
    if slacks and disc.nr:
        r = r + _slack_sum(T, S, slacks, "r", 0, disc.nr)
    g += [r, r_eq]
    for k, i in state_rows:
        g.append(xk(k)[i] + _slack_sum(T, S, slacks, "x", k, nx)[i])
    nlp = {"x": V, "p": P, "f": f, "g": ca.vertcat(*g)}
    opts = {
        "print_time": False,
        "ipopt.print_level": 0,
        "ipopt.sb": "yes",
        "ipopt.tol": tol,
        "ipopt.bound_relax_factor": 0.0,
        "ipopt.honor_original_bounds": "yes",
        "ipopt.max_iter": max_iter,
    }
    if hessian == "limited-memory":
        opts["ipopt.hessian_approximation"] = "limited-memory"
    elif hessian == "gauss-newton":
        opts["hess_lag"] = _gn_hess_lag(disc, V, P, nlp["g"].size1(), xk, uk, pk)
    elif hessian != "exact":
        raise ValueError(f"solve_ocp: hessian must be 'exact', 'gauss-newton' or 'limited-memory', "
                         f"got {hessian!r}")
    return ca.nlpsol(f"{disc.name}_offline", "ipopt", nlp, opts)


def _sx_ok(disc) -> bool:
    try:
        disc.stage_eval(ca.SX.sym("x", disc.nx), ca.SX.sym("u", disc.nu), ca.SX.sym("p", disc.np))
    except Exception:  # noqa: BLE001 - CasADi: no SX evaluation of some node
        return False
    return True


def _gn_hess_lag(disc, V, P, ng_total, xk, uk, pk):
    """Block-diagonal Gauss-Newton Hessian of the Lagrangian from the ``*_hess_gn``
    functions (no curvature of dynamics or constraints)."""
    N, nx = disc.N, disc.nx
    T = type(V)
    lam_f = T.sym("lam_f")
    lam_g = T.sym("lam_g", ng_total)
    blocks = []
    hess = disc.stage_hess("gauss-newton")
    for k in range(N):
        A = hess(xk(k), uk(k), pk(k), T.zeros(nx), T.zeros(disc.ng))[0]
        blocks.append(lam_f * A)
    AN = disc.term_hess_gn(xk(N), pk(N), T.zeros(disc.nr), T.zeros(disc.ne))[0]
    blocks.append(lam_f * AN)
    slacks, _ = soft_layout(disc)
    if slacks:
        blocks.append(lam_f * T(ca.diag(ca.DM([l2 for *_, l2 in slacks]))))
    H = ca.diagcat(*blocks)
    return ca.Function("hess_lag", [V, P, lam_f, lam_g], [ca.triu(H)],
                       ["x", "p", "lam_f", "lam_g"], ["triu_hess_gamma_x_x"])


# The IPOPT solvers already built, per problem and (hessian, tol, max_iter): building one
# takes longer than solving with it. The memo belongs to this module; an entry lives as
# long as its (immutable) problem.
_SOLVERS: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def _solver(disc, hessian: str, tol: float, max_iter: int):
    key = (hessian, float(tol), int(max_iter))
    memo = _SOLVERS.setdefault(disc, {})
    if key not in memo:
        memo[key] = _build_solver(disc, hessian, tol, max_iter)
    return memo[key]


def solve_ocp(disc, xhat0, guess: Guess | None = None, tol: float = 1e-12, hessian: str = "exact",
              p=None, max_iter: int = 3000):
    """Solve the NLP for initial state ``xhat0`` with IPOPT.

    ``guess``: starting point (``disc.initial_guess`` if None; only ``x``, ``u`` are used).
    ``p``: parameters, ``(np,)`` or ``(N+1, np)``; None: ``disc.p0``.
    Returns ``(Guess, info)``: the primal-dual solution in the signed convention of
    algorithm.md section 1, and ``info = {"objective", "x_N", "status", "success",
    "iterations"}``.
    """
    N, nx, nu, npar = disc.N, disc.nx, disc.nu, disc.np
    nw = nx + nu
    xhat0 = np.asarray(xhat0, dtype=float).reshape(-1)
    if xhat0.size != nx or not np.all(np.isfinite(xhat0)):
        raise ValueError(f"solve_ocp: xhat0 must be {nx} finite numbers, got {xhat0}")
    if p is None:
        P = disc.p0
    else:
        P = np.array(p, dtype=float)
        if P.ndim <= 1 and P.size == npar:
            P = np.tile(P.reshape(1, npar), (N + 1, 1))
        if P.shape != (N + 1, npar):
            raise ValueError(f"solve_ocp: p must have shape ({npar},) or ({N + 1}, {npar}), got {P.shape}")
    guess = disc.initial_guess if guess is None else guess
    ix, iu, ig_dyn, ig_path, ig_r, ig_eq = nlp_layout(disc)

    slacks, state_rows = soft_layout(disc)
    v0 = np.zeros(N * nw + nx + len(slacks))
    v0[ix] = np.asarray(guess.x, float).reshape(N + 1, nx)
    v0[iu] = np.asarray(guess.u, float).reshape(N, nu)
    lbv = np.full(v0.size, -np.inf)
    ubv = np.full(v0.size, np.inf)
    lbv[ix[1:]] = disc.lbx
    ubv[ix[1:]] = disc.ubx
    lbv[iu] = disc.lbu
    ubv[iu] = disc.ubu
    ns = len(slacks)
    lbv[N * nw + nx:] = 0.0
    ngt = nx + N * (nx + disc.ng) + disc.nr + disc.ne
    lbg = np.zeros(ngt + len(state_rows))
    ubg = np.zeros(ngt + len(state_rows))
    if disc.ng:
        lbg[ig_path] = disc.lg
        ubg[ig_path] = disc.ug
    lbg[ig_r] = disc.lr
    ubg[ig_r] = disc.ur
    # soft state bounds: rows instead of variable bounds (section 12)
    ig_state = ngt + np.arange(len(state_rows), dtype=int)
    for row, (k, i) in zip(ig_state, state_rows):
        lbv[ix[k, i]], ubv[ix[k, i]] = -np.inf, np.inf
        lbg[row], ubg[row] = disc.lbx[i], disc.ubx[i]
    if ns:
        # the slacks start at the violation of the guess
        for j, (kind, k, i, side, _, _) in enumerate(slacks):
            if kind == "x":
                v, lo, up = v0[ix[k, i]], disc.lbx[i], disc.ubx[i]
            else:
                continue
            v0[N * nw + nx + j] = max(0.0, lo - v) if side < 0 else max(0.0, v - up)

    solver = _solver(disc, hessian, tol, max_iter)
    sol = solver(x0=v0, p=np.concatenate([xhat0, P.reshape(-1)]), lbx=lbv, ubx=ubv, lbg=lbg, ubg=ubg)
    interrupt.check()       # IPOPT ends a solve interrupted by Ctrl-C as a failed one
    stats = solver.stats()
    V = np.array(sol["x"]).reshape(-1)
    lg_ = np.array(sol["lam_g"]).reshape(-1)
    lx_ = np.array(sol["lam_x"]).reshape(-1)

    lx_ = lx_.copy()
    for row, (k, i) in zip(ig_state, state_rows):
        lx_[ix[k, i]] += lg_[row]
    mu_b = np.hstack([lx_[ix[:N]], lx_[iu]])
    free_initial_state(nx, mu_b=mu_b)
    out = Guess(x=V[ix].copy(), u=V[iu].copy(), lam=lg_[ig_dyn].copy(),
                mu_g=lg_[ig_path].copy() if disc.ng else np.zeros((N, 0)),
                mu_b=mu_b, mu_bN=lx_[ix[N]].copy(), mu_r=lg_[ig_r].copy(), nu=lg_[ig_eq].copy())
    info = {
        "objective": float(sol["f"]),
        "x_N": out.x[N].copy(),
        "status": stats.get("return_status", "unknown"),
        "success": bool(stats.get("success", False)),
        "iterations": int(stats.get("iter_count", -1)),
    }
    return out, info
