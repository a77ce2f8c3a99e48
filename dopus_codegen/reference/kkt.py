"""The KKT measure of docs/algorithm.md section 6 (the one place it is implemented in Python).

Everything is evaluated with the exact derivative functions of a ``Discretized``
(``stage_grad``, ``term_grad``) at the given primal-dual point, never with stored or
outdated blocks::

    stat = max( max_k |gL_k + mu_b_k + [lam_k; 0]|_inf , |gL_N + mu_bN + lam_N|_inf )
    eq   = max( |x_0 - xhat_0|, max_k |x_{k+1} - phi_k|, |r_eq| )
    ineq = max(0, g - ug, lg - g, r - ur, lr - r, x_k - ubx, lbx - x_k (k >= 1), u - ubu, lbu - u)
    comp = max over signed pairs of max(mu,0)|ub - v| and max(-mu,0)|v - lb|
           (a nonzero multiplier on an infinite side contributes |mu|)
    kkt  = max(stat, eq, ineq, comp)
    rel  = max(stat / s_d, eq / s_p, ineq / s_p, comp / (s_d s_p))      (the relative measure)
    s_d  = max(1, |lam|_inf, |mu_g|_inf, |mu_b|_inf, |mu_bN|_inf, |mu_r|_inf, |nu|_inf)
    s_p  = max(1, |x|_inf, |u|_inf)

The x part of ``mu_b[0]`` has no bound to pair with (``x_0`` is fixed by ``xhat_0``; the
entry is always 0 by section 1): it enters ``stat`` only, as in the C runtime.
"""
from __future__ import annotations

import numpy as np

from .qp import free_initial_state

__all__ = ["kkt_measure", "relative_kkt", "kkt_of_guess", "node_parameters", "signed_comp", "eval_stages", "path_bounds"]


def path_bounds(disc):
    """The path-row bounds per stage, ``(N, ng)`` each (``path_constraint(stages=...)``)."""
    data = getattr(disc, "data", None)
    N, ng = int(disc.N), int(disc.ng)
    if data is not None and hasattr(data, "path_bounds"):
        lo, up = data.path_bounds()
        return np.asarray(lo, float).reshape(N, ng), np.asarray(up, float).reshape(N, ng)
    return (np.tile(np.asarray(disc.lg, float).reshape(1, ng), (N, 1)),
            np.tile(np.asarray(disc.ug, float).reshape(1, ng), (N, 1)))


def node_parameters(disc, p=None) -> np.ndarray:
    """Parameters as an ``(N+1, np)`` array: ``None`` -> the OCP defaults, ``(np,)`` ->
    the same vector at every node, ``(N+1, np)`` as given."""
    N, npar = disc.N, disc.np
    if p is None:
        p = getattr(disc, "p_default", None)
        if p is None:
            p = np.zeros(npar)
    a = np.array(p, dtype=float)
    if a.ndim <= 1 and a.size == npar:
        a = np.tile(a.reshape(1, npar), (N + 1, 1))
    if a.shape != (N + 1, npar):
        raise ValueError(f"parameters must have shape ({npar},) or ({N + 1}, {npar}), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError("parameters contain non-finite values")
    return a


_MAPPED: dict = {}


def eval_stages(fn, N: int, *args) -> list:
    """Evaluate a per-stage CasADi function for ``N`` stages in one call.

    ``args`` are ``(N, n)`` numpy arrays (one row per stage); returns the outputs as
    ``(N, n_out)`` arrays (row k = stage k). Matrix outputs are not supported here.
    """
    key = (id(fn), N)
    m = _MAPPED.get(key)
    if m is None or m[0] is not fn:
        m = (fn, fn.map(N))
        _MAPPED[key] = m
    ins = []
    for a in args:
        a = np.asarray(a, dtype=float)
        ins.append(a.reshape(N, a.size // N).T)
    res = m[1](*ins)
    if not isinstance(res, (list, tuple)):
        res = [res]
    out = []
    for r in res:
        r = np.array(r, dtype=float)
        out.append(r.T.reshape(N, r.size // N))
    return out


def signed_comp(v, lo, hi, mu) -> float:
    """Complementarity of signed multipliers ``mu`` on rows ``lo <= v <= hi``."""
    v = np.asarray(v, float).reshape(-1)
    lo = np.asarray(lo, float).reshape(-1)
    hi = np.asarray(hi, float).reshape(-1)
    mu = np.asarray(mu, float).reshape(-1)
    if mu.size == 0:
        return 0.0
    up = np.maximum(mu, 0.0)
    dn = np.maximum(-mu, 0.0)
    with np.errstate(invalid="ignore"):
        cu = np.where(np.isfinite(hi), up * np.abs(hi - v), up)
        cl = np.where(np.isfinite(lo), dn * np.abs(v - lo), dn)
    return float(max(np.max(cu), np.max(cl)))


def _viol(v, lo, hi) -> float:
    v = np.asarray(v, float).reshape(-1)
    if v.size == 0:
        return 0.0
    return float(np.max(np.maximum(0.0, np.maximum(v - np.asarray(hi).reshape(-1),
                                                   np.asarray(lo).reshape(-1) - v))))


def relative_kkt(parts: dict, x, u, lam, mu_g, mu_b, mu_bN, mu_r, nu) -> float:
    """The relative KKT measure of docs/algorithm.md section 6: each part divided by the size
    of what it sums (the multipliers for stationarity, the primal point for the equality and
    inequality rows, both for complementarity), each size at least 1."""
    def big(*arrays) -> float:
        return max([1.0] + [float(np.max(np.abs(a))) for a in arrays if np.size(a)])

    s_d = big(lam, mu_g, mu_b, mu_bN, mu_r, nu)
    s_p = big(x, u)
    return max(parts["stat"] / s_d, parts["eq"] / s_p, parts["ineq"] / s_p, parts["comp"] / (s_d * s_p))


def kkt_measure(disc, xhat0, x, u, lam, mu_g, mu_b, mu_bN, mu_r, nu, p=None) -> dict:
    """``{"kkt", "stat", "eq", "ineq", "comp", "rel"}`` of the point for initial state ``xhat0``
    (``rel``: :func:`relative_kkt`)."""
    out = _kkt_parts(disc, xhat0, x, u, lam, mu_g, mu_b, mu_bN, mu_r, nu, p)
    out["rel"] = relative_kkt(out, x, u, lam, mu_g, mu_b, mu_bN, mu_r, nu)
    return out


def _kkt_parts(disc, xhat0, x, u, lam, mu_g, mu_b, mu_bN, mu_r, nu, p=None) -> dict:
    N, nx, nu_, ng, nr, ne = disc.N, disc.nx, disc.nu, disc.ng, disc.nr, disc.ne
    nw = nx + nu_
    P = node_parameters(disc, p)
    x = np.asarray(x, float).reshape(N + 1, nx)
    u = np.asarray(u, float).reshape(N, nu_)
    lam = np.asarray(lam, float).reshape(N + 1, nx)
    mu_g = np.asarray(mu_g, float).reshape(N, ng)
    mu_b = np.asarray(mu_b, float).reshape(N, nw)
    mu_bN = np.asarray(mu_bN, float).reshape(nx)
    mu_r = np.asarray(mu_r, float).reshape(nr)
    nu = np.asarray(nu, float).reshape(ne)
    xhat0 = np.asarray(xhat0, float).reshape(nx)

    gL, phi, _l, g = eval_stages(disc.stage_grad, N, x[:N], u, P[:N], lam[1:], mu_g)
    tg = disc.term_grad(x[N], P[N], mu_r, nu)
    gLN = np.array(tg[0], float).reshape(nx)
    r = np.array(tg[2], float).reshape(nr)
    r_eq = np.array(tg[3], float).reshape(ne)

    sk = gL + mu_b
    sk[:, :nx] += lam[:N]
    stat = max(float(np.max(np.abs(sk))), float(np.max(np.abs(gLN + mu_bN + lam[N]))))

    eq = max(float(np.max(np.abs(x[0] - xhat0))), float(np.max(np.abs(x[1:] - phi))))
    if ne:
        eq = max(eq, float(np.max(np.abs(r_eq))))

    lbx, ubx = np.asarray(disc.lbx, float), np.asarray(disc.ubx, float)
    lbu, ubu = np.asarray(disc.lbu, float), np.asarray(disc.ubu, float)
    ineq = max(0.0, _viol(x[1:], np.tile(lbx, N), np.tile(ubx, N)), _viol(u, np.tile(lbu, N), np.tile(ubu, N)))
    if ng:
        lg_k, ug_k = path_bounds(disc)
        ineq = max(ineq, _viol(g, lg_k.reshape(np.shape(g)), ug_k.reshape(np.shape(g))))
    if nr:
        ineq = max(ineq, _viol(r, disc.lr, disc.ur))

    if getattr(disc, "has_soft", False):
        return _soft_kkt(disc, stat, eq, x, u, g, r, mu_g, mu_b, mu_bN, mu_r)
    # x_0 carries no bound: the x part of mu_b[0] (always 0, section 1) has no pair
    lbw = np.tile(np.concatenate([lbx, lbu]), (N, 1))
    ubw = np.tile(np.concatenate([ubx, ubu]), (N, 1))
    mu_bc = mu_b.copy()
    free_initial_state(nx, mu_b=mu_bc)
    W = np.hstack([x[:N], u])
    comp = max(signed_comp(W, lbw, ubw, mu_bc), signed_comp(x[N], lbx, ubx, mu_bN))
    if ng:
        comp = max(comp, signed_comp(g, lg_k.reshape(np.shape(g)), ug_k.reshape(np.shape(g)),
                                     np.reshape(mu_g, np.shape(g))))
    if nr:
        comp = max(comp, signed_comp(r, disc.lr, disc.ur, mu_r))
    return {"kkt": max(stat, eq, ineq, comp), "stat": stat, "eq": eq, "ineq": ineq, "comp": comp}


def _soft_kkt(disc, stat, eq, x, u, g, r, mu_g, mu_b, mu_bN, mu_r) -> dict:
    """``ineq`` and ``comp`` of a problem with soft rows (docs/algorithm.md section 12): a
    soft side has no violation but its multiplier must lie in ``[0, l1 + l2 s]`` with the
    complementarity of the side and of its slack ``s`` (both into ``comp``)."""
    from .qp import row_check

    N, nx = disc.N, disc.nx
    lbx, ubx = np.asarray(disc.lbx, float), np.asarray(disc.ubx, float)
    ineq = comp = 0.0

    def add(v, lo, hi, mu, w):
        nonlocal ineq, comp
        i_, c_, s_ = row_check(v, lo, hi, mu, w)
        ineq, comp = max(ineq, i_), max(comp, c_, s_)

    lg_k, ug_k = path_bounds(disc)
    mu_b0 = mu_b[0, :nx]
    comp = max(comp, float(np.max(np.abs(mu_b0)))) if mu_b0.size else comp
    for k in range(N):
        if k > 0:
            add(x[k], lbx, ubx, mu_b[k, :nx], disc.soft_x)
        add(u[k], disc.lbu, disc.ubu, mu_b[k, nx:], None)
        if disc.ng:
            add(g[k], lg_k[k], ug_k[k], mu_g[k], disc.soft_g)
    add(x[N], lbx, ubx, mu_bN, disc.soft_x)
    if disc.nr:
        add(r, disc.lr, disc.ur, mu_r, disc.soft_r)
    return {"kkt": max(stat, eq, ineq, comp), "stat": stat, "eq": eq, "ineq": ineq, "comp": comp}


def kkt_of_guess(disc, xhat0, guess, p=None) -> dict:
    """:func:`kkt_measure` of a ``Guess`` (missing multipliers are zeros)."""
    gf = guess.filled(disc)
    return kkt_measure(disc, xhat0, gf.x, gf.u, gf.lam, gf.mu_g, gf.mu_b, gf.mu_bN, gf.mu_r, gf.nu, p)
