"""The stage-wise QP format and the reference QP solver.

QP format (a dict of numpy float arrays and ints; the C QP solver's tests and
benchmark consume the same dict, keep it stable):

=========  ===============  =====================================================
key        shape            meaning
=========  ===============  =====================================================
N, nx, nu  int              stages, states, controls; ``nw = nx + nu``
ng, nr, ne int              path rows per stage, terminal inequality/equality rows
H          (N, nw, nw)      stage Hessian blocks (symmetric, may be indefinite)
g          (N, nw)          stage gradients
Phi        (N, nx, nw)      dynamics ``[A_k B_k]``
b          (N, nx)          ``x_{k+1} = Phi_k w_k + b_k``
x0         (nx,)            ``x_0 = x0``
HN, gN     (nx, nx), (nx,)  terminal Hessian and gradient
lbw, ubw   (N, nw)          simple bounds on ``w_k = (x_k, u_k)``; the x part of
                            stage 0 is ignored; +-inf means no bound on that side
lbxN, ubxN (nx,)            simple bounds on ``x_N``
C          (N, ng, nw)      path constraint Jacobians, ``lg_k <= C_k w_k <= ug_k``
lg, ug     (N, ng)
R          (nr, nx)         ``lr <= R x_N <= ur``
lr, ur     (nr,)
Req, req   (ne, nx), (ne,)  ``Req x_N = req``
zl, zu,    (nw+ng,)         optional soft weights of the stage rows (the nw box rows of
Zl, Zu                      ``w_k``, then the ng rows of ``C_k``; the same at every
                            stage): L1 ``zl``/``zu`` and L2 ``Zl``/``Zu`` of the lower
                            and upper side; a side with both weights 0 is hard
zlN, zuN,  (nx+nr,)         optional soft weights of the terminal rows (``x_N``, then
ZlN, ZuN                    the rows of ``R``)
=========  ===============  =====================================================

A soft side admits a violation ``s >= 0`` (``lo - s_lo <= v <= up + s_up``) at the price
``zl s + 0.5 Zl s^2`` added to the objective. The reference solves the QP with the
slacks as explicit variables; the solution dict has the primal and the multipliers of the
rows as above (the multiplier of a soft side lies in ``[0, zl + Zl s]``, equal to the
upper end where the side is violated); the slacks are ``max(0, lo - v)``, ``max(0, v - up)``.

Problem::

    min  sum_k 0.5 w_k' H_k w_k + g_k' w_k + 0.5 x_N' HN x_N + gN' x_N
    s.t. x_0 = x0,  x_{k+1} = Phi_k w_k + b_k,  bounds,  lg <= C_k w_k <= ug,
         lr <= R x_N <= ur,  Req x_N = req

Solution dict: ``x (N+1, nx)``, ``u (N, nu)``, ``lam (N+1, nx)``, ``mu_b (N, nw)``,
``mu_bN (nx,)``, ``mu_g (N, ng)``, ``mu_r (nr,)``, ``nu (ne,)``, plus ``iterations``
(IPOPT iterations) and ``polished`` (bool). Multipliers are signed as in
docs/algorithm.md (positive when the upper side is active). Stationarity of stage k::

    H_k w_k + g_k + [lam_k; 0] - Phi_k' lam_{k+1} + C_k' mu_g_k + mu_b_k = 0

terminal ``HN x_N + gN + lam_N + R' mu_r + Req' nu + mu_bN = 0``; ``lam_0``
multiplies ``x_0 - x0``.

Why IPOPT plus an active-set polish: the QPs of the exact-Hessian DOPUS iteration
have indefinite stage blocks whose reduced Hessian is positive definite (docs/design.md
section 8). Convex conic solvers (clarabel, piqp) reject them, and a convexification
that provably keeps the solution must know the active set, which is what we are
looking for. IPOPT (through CasADi) takes the nonconvex QP as it is and corrects the
inertia only when the factorisation asks for it, so it finds the local minimiser with
the right active set; its interior-point answer is accurate only to about the barrier
parameter (1e-9 .. 1e-11 in the multipliers). We therefore identify the active set from
IPOPT's answer and solve the equality-constrained KKT system of that active set once
with a sparse direct factorisation (the "polish" of OSQP). The result satisfies
stationarity and feasibility to round-off (~1e-13) with exactly zero multipliers on
inactive constraints; it is accepted only if every inactive constraint stays feasible
and every active multiplier keeps its sign, otherwise the active set is corrected
(a few primal-dual active-set sweeps) or the IPOPT answer is returned unpolished.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Optional

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .. import interrupt

__all__ = ["QPError", "QPInfeasibleError", "QPIterationLimitError", "free_initial_state", "solve_qp_reference",
           "qp_kkt_residual", "check_qp", "qp_infeasible_row", "qp_reduced_hessian_min_eig", "flatten_qp", "flatten_solution"]


class QPError(RuntimeError):
    """The reference QP solver failed. ``qp_status``: the name of the ``enum
    dopus_qp_status`` member that says why (the C QP solver's vocabulary)."""
    qp_status = "numerical"


class QPInfeasibleError(QPError):
    """The QP has no feasible point. ``row``: ``(stage, j, side)`` of the row that
    :func:`qp_infeasible_row` names (None when it names none)."""
    qp_status = "primal_infeasible"
    row = None


class QPIterationLimitError(QPError):
    """The QP solver stopped at its iteration limit (``max_iter``) before converging."""
    qp_status = "max_iter"


def free_initial_state(nx: int, mu_b=None, lower=None, upper=None) -> None:
    """The rule "x_0 carries no bound" (docs/algorithm.md section 1): ``x_0`` is fixed by
    the equality row ``x_0 = xhat_0``, so the x part of stage 0 has no bound and its
    multiplier is zero. In place: ``mu_b[0, :nx] = 0``, ``lower[0, :nx] = -inf`` and
    ``upper[0, :nx] = +inf`` (for a flat vector, its first ``nx`` entries)."""
    for arr, value in ((mu_b, 0.0), (lower, -np.inf), (upper, np.inf)):
        if arr is None:
            continue
        if arr.ndim == 1:
            arr[:nx] = value
        else:
            arr[0, :nx] = value


_INT_KEYS = ("N", "nx", "nu", "ng", "nr", "ne")
_SOFT_STAGE = ("zl", "zu", "Zl", "Zu")
_SOFT_TERM = ("zlN", "zuN", "ZlN", "ZuN")


def soft_weights(q: dict):
    """``(stage, terminal)`` soft weights of a QP dict: ``(4, nw+ng)`` and ``(4, nx+nr)``
    arrays with rows ``(zl, zu, Zl, Zu)`` (zeros where a key is missing)."""
    N, nx, nu, ng, nr, ne = (int(q[k]) for k in _INT_KEYS)
    out = []
    for keys, n in ((_SOFT_STAGE, nx + nu + ng), (_SOFT_TERM, nx + nr)):
        rows = []
        for key in keys:
            a = np.zeros(n) if q.get(key) is None else np.array(q[key], dtype=float).reshape(-1)
            if a.shape != (n,):
                raise ValueError(f"QP entry '{key}' has {a.size} values, expected {n}")
            if not np.all(np.isfinite(a)) or np.any(a < 0):
                raise ValueError(f"QP entry '{key}' must be finite and >= 0")
            rows.append(a)
        out.append(np.vstack(rows))
    return out[0], out[1]


def has_soft(q: dict) -> bool:
    """True when the QP dict has a soft side."""
    ws, wt = soft_weights(q)
    return bool(np.any(ws > 0) or np.any(wt > 0))


def _shapes(N, nx, nu, ng, nr, ne):
    nw = nx + nu
    return {
        "H": (N, nw, nw), "g": (N, nw), "Phi": (N, nx, nw), "b": (N, nx), "x0": (nx,),
        "HN": (nx, nx), "gN": (nx,), "lbw": (N, nw), "ubw": (N, nw), "lbxN": (nx,), "ubxN": (nx,),
        "C": (N, ng, nw), "lg": (N, ng), "ug": (N, ng), "R": (nr, nx), "lr": (nr,), "ur": (nr,),
        "Req": (ne, nx), "req": (ne,),
    }


def check_qp(qp: dict) -> dict:
    """Validate a QP dict; return a copy with float arrays of the documented shapes."""
    if not isinstance(qp, dict):
        raise TypeError("QP must be a dict (see dopus_codegen.reference.qp)")
    missing = [k for k in _INT_KEYS if k not in qp]
    if missing:
        raise ValueError(f"QP dict lacks the size entries {missing}")
    sizes = {k: int(qp[k]) for k in _INT_KEYS}
    if sizes["N"] < 1 or sizes["nx"] < 1 or min(sizes.values()) < 0:
        raise ValueError(f"QP sizes must be N >= 1, nx >= 1, others >= 0; got {sizes}")
    out = dict(sizes)
    for key, shape in _shapes(**sizes).items():
        if key not in qp:
            raise ValueError(f"QP dict lacks '{key}' of shape {shape}")
        arr = np.array(qp[key], dtype=float)
        if arr.size == 0 and 0 in shape:
            arr = arr.reshape(shape)
        if arr.shape != shape:
            raise ValueError(f"QP entry '{key}' has shape {arr.shape}, expected {shape}")
        if key not in ("lbw", "ubw", "lbxN", "ubxN", "lg", "ug", "lr", "ur") and not np.all(np.isfinite(arr)):
            raise ValueError(f"QP entry '{key}' has non-finite values")
        if np.any(np.isnan(arr)):
            raise ValueError(f"QP entry '{key}' has NaN values")
        out[key] = arr
    ws, wt = soft_weights(qp)
    for key, a in zip(_SOFT_STAGE + _SOFT_TERM, list(ws) + list(wt)):
        out[key] = a
    nw = sizes["nx"] + sizes["nu"]
    soft_st = np.any(ws > 0, axis=0)
    soft_t = np.any(wt > 0, axis=0)
    for lo, hi, soft in (("lbw", "ubw", soft_st[:nw]), ("lbxN", "ubxN", soft_t[:sizes["nx"]]),
                         ("lg", "ug", soft_st[nw:]), ("lr", "ur", soft_t[sizes["nx"]:])):
        if np.any((out[lo] > out[hi]) & ~soft):
            raise QPInfeasibleError(f"QP is infeasible: some entry of '{lo}' exceeds '{hi}'")
    return out


# ---------------------------------------------------------------------------
# Flattening: z = (x_0, u_0, x_1, u_1, ..., x_{N-1}, u_{N-1}, x_N)
# ---------------------------------------------------------------------------

@dataclass
class _Rows:
    """The constraints of the QP as sparse rows over z."""
    A_eq: sp.csr_matrix      # x0 equality, dynamics, Req rows
    b_eq: np.ndarray
    A_in: sp.csr_matrix      # C rows (stage-wise), R rows
    l_in: np.ndarray
    u_in: np.ndarray
    lbz: np.ndarray
    ubz: np.ndarray
    moved: Optional[list] = None  # soft QPs (_with_slacks): (column, row) of the moved box rows
    nz: int = 0                   # soft QPs: the size of z without the slacks
    m_in: int = 0                 # soft QPs: the rows of A_in without the moved box rows


def flatten_qp(q: dict):
    """The stage-wise QP ``q`` as one sparse problem: ``(Hz, gz, rows)`` over the stacked
    ``z = (w_0, ..., w_{N-1}, x_N)``."""
    N, nx, nu, ng, nr, ne = (q[k] for k in _INT_KEYS)
    nw = nx + nu
    nz = N * nw + nx
    Hz = sp.block_diag([q["H"][k] for k in range(N)] + [q["HN"]], format="csc")
    Hz = 0.5 * (Hz + Hz.T)
    gz = np.concatenate([q["g"].reshape(-1), q["gN"]])
    # equality rows: x_0 = x0 ; x_{k+1} - Phi_k w_k = b_k ; Req x_N = req
    rows, cols, vals = [], [], []
    for i in range(nx):
        rows.append(i); cols.append(i); vals.append(1.0)
    for k in range(N):
        r0 = nx * (k + 1)
        blk = -q["Phi"][k]
        ii, jj = np.nonzero(np.ones_like(blk))
        rows.extend(r0 + ii); cols.extend(k * nw + jj); vals.extend(blk[ii, jj])
        c0 = (k + 1) * nw if k < N - 1 else N * nw
        rows.extend(r0 + np.arange(nx)); cols.extend(c0 + np.arange(nx)); vals.extend([1.0] * nx)
    r0 = nx * (N + 1)
    if ne:
        ii, jj = np.nonzero(np.ones_like(q["Req"]))
        rows.extend(r0 + ii); cols.extend(N * nw + jj); vals.extend(q["Req"][ii, jj])
    A_eq = sp.csr_matrix((vals, (rows, cols)), shape=(nx * (N + 1) + ne, nz))
    b_eq = np.concatenate([q["x0"], q["b"].reshape(-1), q["req"]])
    # inequality rows: C_k w_k (stage-wise), then R x_N
    rows, cols, vals = [], [], []
    for k in range(N):
        if ng:
            ii, jj = np.nonzero(np.ones_like(q["C"][k]))
            rows.extend(k * ng + ii); cols.extend(k * nw + jj); vals.extend(q["C"][k][ii, jj])
    if nr:
        ii, jj = np.nonzero(np.ones_like(q["R"]))
        rows.extend(N * ng + ii); cols.extend(N * nw + jj); vals.extend(q["R"][ii, jj])
    A_in = sp.csr_matrix((vals, (rows, cols)), shape=(N * ng + nr, nz))
    l_in = np.concatenate([q["lg"].reshape(-1), q["lr"]])
    u_in = np.concatenate([q["ug"].reshape(-1), q["ur"]])
    lbz = np.concatenate([q["lbw"].reshape(-1), q["lbxN"]])
    ubz = np.concatenate([q["ubw"].reshape(-1), q["ubxN"]])
    free_initial_state(nx, lower=lbz, upper=ubz)
    rows_ = _Rows(A_eq, b_eq, A_in, l_in, u_in, lbz, ubz)
    if has_soft(q):
        return _with_slacks(q, Hz, gz, rows_)
    return Hz, gz, rows_


def _with_slacks(q: dict, Hz, gz, rows: _Rows):
    """The flattened QP with one explicit slack variable per soft side (appended to ``z``):
    a soft box row moves from the bounds of ``z`` to a row of ``A_in``, and each soft side
    of a row adds ``+s`` (lower) or ``-s`` (upper) to it, ``s >= 0`` at the price ``zl s +
    0.5 Zl s^2``. ``rows.moved`` lists ``(column, row)`` of the moved box rows and
    ``rows.nz`` the size of the original ``z`` (see :func:`_unflatten`)."""
    N, nx, nu, ng, nr = (q[k] for k in _INT_KEYS[:5])
    nw = nx + nu
    nz = Hz.shape[0]
    ws, wt = soft_weights(q)
    A_in = sp.lil_matrix(rows.A_in)
    l_in, u_in = list(rows.l_in), list(rows.u_in)
    lbz, ubz = rows.lbz.copy(), rows.ubz.copy()
    extra_rows = []           # new rows of A_in: (column,)
    moved = []
    slack_cols = []           # (row of A_in, sign, l1, l2)

    def soften(k, j, w, col=None, row=None):
        if not np.any(w > 0):
            return
        if col is not None:
            lo, up = lbz[col], ubz[col]
            if not (np.isfinite(lo) or np.isfinite(up)):
                return
            row = A_in.shape[0] + len(extra_rows)
            extra_rows.append(col)
            l_in.append(lo)
            u_in.append(up)
            lbz[col], ubz[col] = -np.inf, np.inf
            moved.append((col, row))
        lo, up = l_in[row], u_in[row]
        if np.isfinite(lo) and (w[0] > 0 or w[2] > 0):
            slack_cols.append((row, 1.0, w[0], w[2]))
        if np.isfinite(up) and (w[1] > 0 or w[3] > 0):
            slack_cols.append((row, -1.0, w[1], w[3]))

    for k in range(N):
        for j in range(nx if k == 0 else 0, nw):
            soften(k, j, ws[:, j], col=k * nw + j)
        for i in range(ng):
            soften(k, nw + i, ws[:, nw + i], row=k * ng + i)
    for j in range(nx):
        soften(N, j, wt[:, j], col=N * nw + j)
    for i in range(nr):
        soften(N, nx + i, wt[:, nx + i], row=N * ng + i)
    ns = len(slack_cols)
    m0 = A_in.shape[0]
    m = m0 + len(extra_rows)
    A = sp.lil_matrix((m, nz + ns))
    A[:m0, :nz] = A_in
    for r, col in enumerate(extra_rows):
        A[m0 + r, col] = 1.0
    for c, (row, sign, _, _) in enumerate(slack_cols):
        A[row, nz + c] = sign
    Hs = sp.diags([l2 for _, _, _, l2 in slack_cols], format="csc") if ns else sp.csc_matrix((0, 0))
    Hx = sp.block_diag([Hz, Hs], format="csc")
    gx = np.concatenate([gz, [l1 for _, _, l1, _ in slack_cols]])
    A_eq = sp.hstack([rows.A_eq, sp.csr_matrix((rows.A_eq.shape[0], ns))], format="csr")
    out = _Rows(A_eq, rows.b_eq, A.tocsr(), np.array(l_in), np.array(u_in),
                np.concatenate([lbz, np.zeros(ns)]), np.concatenate([ubz, np.full(ns, np.inf)]),
                moved=moved, nz=nz, m_in=m0)
    return Hx, gx, out


def _unflatten(q: dict, z, y_eq, y_in, mu_z, rows=None) -> dict:
    N, nx, nu, ng, nr, ne = (q[k] for k in _INT_KEYS)
    nw = nx + nu
    if rows is not None and getattr(rows, "moved", None) is not None:
        # the soft problem of _with_slacks: drop the slacks, the moved box rows' multipliers
        # go back to their variables
        mu_z = np.array(mu_z[:rows.nz], dtype=float)
        for col, row in rows.moved:
            mu_z[col] += y_in[row]
        z, y_in = z[:rows.nz], y_in[:rows.m_in]
    W = z[: N * nw].reshape(N, nw)
    x = np.vstack([W[:, :nx], z[N * nw:][None, :]])
    mu_b = mu_z[: N * nw].reshape(N, nw).copy()
    free_initial_state(nx, mu_b=mu_b)
    return {
        "x": x, "u": W[:, nx:].copy(),
        "lam": y_eq[: nx * (N + 1)].reshape(N + 1, nx).copy(),
        "nu": y_eq[nx * (N + 1):].copy(),
        "mu_b": mu_b, "mu_bN": mu_z[N * nw:].copy(),
        "mu_g": y_in[: N * ng].reshape(N, ng).copy(), "mu_r": y_in[N * ng:].copy(),
    }


def flatten_solution(q: dict, sol: dict):
    """A stage-wise solution of ``q`` as ``(z, y_eq, y_in, mu_z)`` in the layout of
    :func:`flatten_qp`."""
    N = q["N"]
    z = np.concatenate([np.hstack([sol["x"][:N], sol["u"]]).reshape(-1), sol["x"][N]])
    y_eq = np.concatenate([np.asarray(sol["lam"]).reshape(-1), np.asarray(sol["nu"]).reshape(-1)])
    y_in = np.concatenate([np.asarray(sol["mu_g"]).reshape(-1), np.asarray(sol["mu_r"]).reshape(-1)])
    mu_z = np.concatenate([np.asarray(sol["mu_b"]).reshape(-1), np.asarray(sol["mu_bN"]).reshape(-1)])
    return z, y_eq, y_in, mu_z


# ---------------------------------------------------------------------------
# KKT residual of a QP solution (independent of how it was computed)
# ---------------------------------------------------------------------------

def _signed_pairs(v, lo, hi, mu):
    """Complementarity and dual-sign violation of signed multipliers on lo <= v <= hi."""
    mu = np.asarray(mu, dtype=float)
    if mu.size == 0:
        return 0.0, 0.0
    up = np.maximum(mu, 0.0)
    dn = np.maximum(-mu, 0.0)
    comp = 0.0
    sign = 0.0
    fin_hi = np.isfinite(hi)
    fin_lo = np.isfinite(lo)
    if np.any(fin_hi):
        comp = max(comp, float(np.max(up[fin_hi] * np.abs(hi[fin_hi] - v[fin_hi]))))
    if np.any(fin_lo):
        comp = max(comp, float(np.max(dn[fin_lo] * np.abs(v[fin_lo] - lo[fin_lo]))))
    if np.any(~fin_hi):
        sign = max(sign, float(np.max(up[~fin_hi])))
    if np.any(~fin_lo):
        sign = max(sign, float(np.max(dn[~fin_lo])))
    return comp, sign


def row_check(v, lo, hi, mu, w):
    """``(ineq, comp, sign)`` of rows ``lo <= v <= hi`` with signed multipliers ``mu`` and
    soft weights ``w`` (4, n) (rows zl, zu, Zl, Zu; a side with both 0 is hard). A hard side
    as in :func:`_signed_pairs`. A soft side with multiplier ``m`` is measured at its best
    slack ``s = max(s0, (m - zl) / Zl)`` (``s0 = max(0, lo - v)`` the violation; ``s = s0``
    when ``Zl = 0``), at which the slack's stationarity ``zl + Zl s - m = y >= 0`` holds
    unless ``m > zl + Zl s0`` with ``Zl = 0`` (a sign violation): complementarity ``m (v - lo +
    s)`` and ``y s``. (An interior point leaves a weakly inactive soft side with a multiplier
    of complementarity over its gap, as on a hard side; the over-slack is what it means.)"""
    v = np.asarray(v, float).reshape(-1)
    lo = np.asarray(lo, float).reshape(-1)
    hi = np.asarray(hi, float).reshape(-1)
    mu = np.asarray(mu, float).reshape(-1)
    if v.size == 0:
        return 0.0, 0.0, 0.0
    w = np.zeros((4, v.size)) if w is None else np.asarray(w, float).reshape(4, v.size)
    soft_lo = ((w[0] > 0) | (w[2] > 0)) & np.isfinite(lo)
    soft_up = ((w[1] > 0) | (w[3] > 0)) & np.isfinite(hi)
    lo_h = np.where(soft_lo, -np.inf, lo)
    hi_h = np.where(soft_up, np.inf, hi)
    mu_h = np.where(((mu > 0) & soft_up) | ((mu < 0) & soft_lo), 0.0, mu)
    ineq = float(np.max(np.maximum(0.0, np.maximum(v - hi_h, lo_h - v))))
    comp, sign = _signed_pairs(v, lo_h, hi_h, mu_h)
    for side, flag, bound, l1, l2 in ((-1, soft_lo, lo, w[0], w[2]), (1, soft_up, hi, w[1], w[3])):
        if not np.any(flag):
            continue
        m = np.maximum(side * mu[flag], 0.0)
        gap = side * (bound[flag] - v[flag])    # >= 0 on the satisfied side
        s0 = np.maximum(0.0, -gap)
        L1, L2 = l1[flag], l2[flag]
        with np.errstate(divide="ignore", invalid="ignore"):
            s_ = np.where(L2 > 0, np.maximum(s0, (m - L1) / np.where(L2 > 0, L2, 1.0)), s0)
        y = L1 + L2 * s_ - m
        sign = max(sign, float(np.max(np.maximum(0.0, -y))))
        comp = max(comp, float(np.max(m * (gap + s_))), float(np.max(np.maximum(0.0, y) * s_)))
    return ineq, comp, sign


def qp_kkt_residual(qp: dict, sol: dict) -> dict:
    """Inf-norm KKT residuals of ``sol`` for ``qp``.

    Returns ``{"stat", "eq", "ineq", "comp", "sign", "kkt"}``: stationarity (per
    stage and terminal, the formulas of the module docstring), equality violation
    (initial value, dynamics, Req rows), inequality violation (bounds, C, R rows),
    complementarity ``max(mu,0)|ub - v|`` / ``max(-mu,0)|v - lb|`` on finite sides,
    and dual sign (the size of a multiplier pushing on an infinite side, including
    a nonzero x part of ``mu_b[0]``); ``kkt`` is their maximum. Soft sides: no
    inequality violation, the conditions of :func:`row_check` instead.
    """
    q = check_qp(qp)
    N, nx, nu, ng, nr, ne = (q[k] for k in _INT_KEYS)
    nw = nx + nu
    ws, wt = soft_weights(q)
    x = np.asarray(sol["x"], float); u = np.asarray(sol["u"], float)
    lam = np.asarray(sol["lam"], float)
    mu_b = np.asarray(sol["mu_b"], float).reshape(N, nx + nu)
    mu_g = np.asarray(sol["mu_g"], float).reshape(N, ng)
    mu_bN = np.asarray(sol["mu_bN"], float).reshape(nx)
    mu_r = np.asarray(sol["mu_r"], float).reshape(nr)
    nu_ = np.asarray(sol["nu"], float).reshape(ne)
    stat = 0.0
    eq = float(np.max(np.abs(x[0] - q["x0"])))
    ineq = 0.0
    comp = 0.0
    sign = 0.0

    def add(check):
        nonlocal ineq, comp, sign
        ineq, comp, sign = max(ineq, check[0]), max(comp, check[1]), max(sign, check[2])

    for k in range(N):
        w = np.concatenate([x[k], u[k]])
        r = q["H"][k] @ w + q["g"][k] - q["Phi"][k].T @ lam[k + 1] + q["C"][k].T @ mu_g[k] + mu_b[k]
        r[:nx] += lam[k]
        stat = max(stat, float(np.max(np.abs(r))))
        eq = max(eq, float(np.max(np.abs(x[k + 1] - q["Phi"][k] @ w - q["b"][k]))))
        lo = q["lbw"][k].copy(); hi = q["ubw"][k].copy()
        if k == 0:
            lo[:nx] = -np.inf; hi[:nx] = np.inf
        add(row_check(w, lo, hi, mu_b[k], ws[:, :nw]))
        if ng:
            add(row_check(q["C"][k] @ w, q["lg"][k], q["ug"][k], mu_g[k], ws[:, nw:]))
    xN = x[N]
    r = q["HN"] @ xN + q["gN"] + lam[N] + q["R"].T @ mu_r + q["Req"].T @ nu_ + mu_bN
    stat = max(stat, float(np.max(np.abs(r))))
    if ne:
        eq = max(eq, float(np.max(np.abs(q["Req"] @ xN - q["req"]))))
    add(row_check(xN, q["lbxN"], q["ubxN"], mu_bN, wt[:, :nx]))
    if nr:
        add(row_check(q["R"] @ xN, q["lr"], q["ur"], mu_r, wt[:, nx:]))
    return {"stat": stat, "eq": eq, "ineq": ineq, "comp": comp, "sign": sign,
            "kkt": max(stat, eq, ineq, comp, sign)}


# ---------------------------------------------------------------------------
# IPOPT on the QP (one parametric CasADi NLP per size tuple, cached)
# ---------------------------------------------------------------------------

_IPOPT_CACHE: dict = {}


def _ipopt_options(max_iter):
    """IPOPT as a QP solver: tight tolerance, no bound relaxation, constant derivatives."""
    return {
        "print_time": False,
        "ipopt": {
            "print_level": 0, "sb": "yes", "tol": 1e-12, "acceptable_iter": 0,
            "bound_relax_factor": 0.0, "honor_original_bounds": "yes",
            "mu_strategy": "adaptive", "max_iter": int(max_iter),
            "hessian_constant": "yes", "jac_c_constant": "yes", "jac_d_constant": "yes",
        },
    }


def _run_ipopt(solver, rows: _Rows, **args):
    """One solve of a QP's IPOPT function over the rows (equalities, then inequalities):
    (z, lam_eq, lam_in, lam_z, status, iterations)."""
    lbg = np.concatenate([rows.b_eq, rows.l_in])
    ubg = np.concatenate([rows.b_eq, rows.u_in])
    # start inside the bounds: IPOPT pushes the start anyway, a clipped zero is as good as any
    z0 = np.clip(np.zeros(rows.lbz.shape[0]), rows.lbz, rows.ubz)
    z0 = np.where(np.isfinite(z0), z0, 0.0)
    res = solver(x0=z0, lbx=rows.lbz, ubx=rows.ubz, lbg=lbg, ubg=ubg, **args)
    interrupt.check()       # IPOPT ends a solve interrupted by Ctrl-C as a failed one
    stats = solver.stats()
    z = np.array(res["x"]).reshape(-1)
    lam_g = np.array(res["lam_g"]).reshape(-1)
    lam_x = np.array(res["lam_x"]).reshape(-1)
    neq = rows.A_eq.shape[0]
    return z, lam_g[:neq], lam_g[neq:], lam_x, stats.get("return_status", ""), int(stats.get("iter_count", -1))


def _ipopt_solver(N, nx, nu, ng, nr, ne, max_iter=500):
    key = (N, nx, nu, ng, nr, ne, max_iter)
    if key in _IPOPT_CACHE:
        return _IPOPT_CACHE[key]
    import casadi as ca

    nw = nx + nu
    nz = N * nw + nx
    z = ca.SX.sym("z", nz)
    H = ca.SX.sym("H", N * nw * nw)      # row-major per stage, as numpy reshape(-1)
    g = ca.SX.sym("g", N * nw)
    Phi = ca.SX.sym("Phi", N * nx * nw)
    HN = ca.SX.sym("HN", nx * nx)
    gN = ca.SX.sym("gN", nx)
    C = ca.SX.sym("C", N * ng * nw)
    R = ca.SX.sym("R", nr * nx)
    Req = ca.SX.sym("Req", ne * nx)
    f = 0
    cons = [z[:nx]]
    cin = []
    for k in range(N):
        w = z[k * nw:(k + 1) * nw]
        Hk = ca.reshape(H[k * nw * nw:(k + 1) * nw * nw], nw, nw).T
        f += 0.5 * ca.dot(w, ca.mtimes(Hk, w)) + ca.dot(g[k * nw:(k + 1) * nw], w)
        Pk = ca.reshape(Phi[k * nx * nw:(k + 1) * nx * nw], nw, nx).T
        xn = z[(k + 1) * nw:(k + 1) * nw + nx]
        cons.append(xn - ca.mtimes(Pk, w))
        if ng:
            Ck = ca.reshape(C[k * ng * nw:(k + 1) * ng * nw], nw, ng).T
            cin.append(ca.mtimes(Ck, w))
    xN = z[N * nw:]
    HNm = ca.reshape(HN, nx, nx).T
    f += 0.5 * ca.dot(xN, ca.mtimes(HNm, xN)) + ca.dot(gN, xN)
    if ne:
        cons.append(ca.mtimes(ca.reshape(Req, nx, ne).T, xN))
    if nr:
        cin.append(ca.mtimes(ca.reshape(R, nx, nr).T, xN))
    gexpr = ca.vertcat(*(cons + cin))
    p = ca.vertcat(H, g, Phi, HN, gN, C, R, Req)
    solver = ca.nlpsol("qpref_ipopt", "ipopt", {"x": z, "p": p, "f": f, "g": gexpr}, _ipopt_options(max_iter))
    _IPOPT_CACHE[key] = solver
    return solver


def _solve_ipopt(q: dict, Hz, gz, rows: _Rows, max_iter=500):
    N, nx, nu, ng, nr, ne = (q[k] for k in _INT_KEYS)
    solver = _ipopt_solver(N, nx, nu, ng, nr, ne, max_iter)
    p = np.concatenate([q["H"].reshape(-1), q["g"].reshape(-1), q["Phi"].reshape(-1), q["HN"].reshape(-1),
                        q["gN"], q["C"].reshape(-1), q["R"].reshape(-1), q["Req"].reshape(-1)])
    return _run_ipopt(solver, rows, p=p)


def _solve_ipopt_flat(Hz, gz, rows: _Rows, max_iter=500):
    """IPOPT on the flattened QP itself (the soft QPs, whose slack columns the stage-wise
    parametric NLP of :func:`_ipopt_solver` does not have); built for each call."""
    import casadi as ca

    nz = Hz.shape[0]
    z = ca.SX.sym("z", nz)
    H = ca.DM(sp.csc_matrix(Hz))
    A = ca.DM(sp.csc_matrix(sp.vstack([rows.A_eq, rows.A_in])))
    f = 0.5 * ca.dot(z, ca.mtimes(H, z)) + ca.dot(ca.DM(gz), z)
    solver = ca.nlpsol("qpref_ipopt_flat", "ipopt", {"x": z, "f": f, "g": ca.mtimes(A, z)}, _ipopt_options(max_iter))
    return _run_ipopt(solver, rows)


# ---------------------------------------------------------------------------
# Active-set polish
# ---------------------------------------------------------------------------

def _families(q: dict):
    """The family of each entry of ``z`` and each row of ``A_in`` (flattened, without soft
    slacks), as the C QP's active-set start numbers them: the row within the stage (a
    component of ``w_k``: ``j``; a path row: ``nw + i``), ``nw + ng + j`` for ``x_N`` and
    ``nw + ng + nx + i`` for the rows of ``R``."""
    N, nx, nu, ng, nr = (q[k] for k in _INT_KEYS[:5])
    nw, nsi = nx + nu, nx + nu + ng
    fz = np.concatenate([np.tile(np.arange(nw), N), nsi + np.arange(nx)])
    fin = np.concatenate([np.tile(nw + np.arange(ng), N), nsi + nx + np.arange(nr)]).astype(int)
    return fz, fin


#: An active row of the wrong sign leaves the active set of a sweep of the active-set start
#: when its multiplier is at least this fraction of the largest wrong one of its family
#: (AS_DROP of runtime_c/dopus_qp.c).
AS_DROP = 0.4
#: Rows the active-set start adds to the active set of a factorisation without factoring
#: again: a sweep whose corrections only added rows, at most this many since the last
#: factorisation, solves with that factor and the Schur complement of the added rows
#: (DOPUS_QP_AS_UPDATE of runtime_c/dopus_qp.h; the same KKT point, no factorisation).
AS_UPDATE = 4


def _polish(Hz, gz, rows: _Rows, z, y_in, mu_z, tol, sweeps=10, families=None):
    """Solve the KKT system of the active set read from (z, y_in, mu_z); refine it. Up to
    ``sweeps`` active-set corrections; ``families`` (:func:`_families`): the C QP's active-set
    start, where a wrong-signed row leaves the active set only when its multiplier is at
    least AS_DROP times the largest wrong one of its family (else every wrong-signed row
    does), and a sweep after corrections that only added rows (AS_UPDATE at most since the
    last factorisation) is no factorisation. Returns ``(answer, factorisations, sweeps)``,
    the answer (zp, y_eq, y_in, mu_z) or None."""
    nz = Hz.shape[0]
    Ain = rows.A_in
    v_in = Ain @ z
    # +1: upper side active, -1: lower side active, 0: inactive. A side is active when
    # its multiplier outweighs its slack (the two are complementary at IPOPT's answer).
    def classify(v, lo, hi, mu):
        act = np.zeros(v.shape, dtype=int)
        eqrow = np.isfinite(lo) & np.isfinite(hi) & (lo == hi)
        up = np.isfinite(hi) & (mu > 0) & (mu > hi - v)
        dn = np.isfinite(lo) & (mu < 0) & (-mu > v - lo)
        act[up] = 1
        act[dn] = -1
        act[eqrow] = np.where(act[eqrow] != 0, act[eqrow], 1)
        return act
    act_z = classify(z, rows.lbz, rows.ubz, mu_z)
    act_in = classify(v_in, rows.l_in, rows.u_in, y_in)
    neq = rows.A_eq.shape[0]
    n_fact, added, update = 0, 0, False
    for sweep in range(sweeps):
        # a sweep after additions alone keeps the factor (the C start's Schur complement)
        n_fact += 0 if update else 1
        iz = np.nonzero(act_z)[0]
        ii = np.nonzero(act_in)[0]
        Ab = sp.csr_matrix((np.ones(iz.size), (np.arange(iz.size), iz)), shape=(iz.size, nz))
        A = sp.vstack([rows.A_eq, Ain[ii], Ab], format="csc")
        rhs_c = np.concatenate([
            rows.b_eq,
            np.where(act_in[ii] > 0, rows.u_in[ii], rows.l_in[ii]),
            np.where(act_z[iz] > 0, rows.ubz[iz], rows.lbz[iz]),
        ])
        K = sp.bmat([[Hz, A.T], [A, None]], format="csc")
        rhs = np.concatenate([-gz, rhs_c])
        try:
            with np.errstate(all="raise"):
                lu = spla.splu(K)
                sol = lu.solve(rhs)
                # one step of iterative refinement against the unfactored matrix
                sol = sol + lu.solve(rhs - K @ sol)
        except (RuntimeError, FloatingPointError):
            return None, n_fact, sweep + 1
        if not np.all(np.isfinite(sol)):
            return None, n_fact, sweep + 1
        zp = sol[:nz].copy()
        # the active simple bounds met exactly (they are to round-off), as in the C QP's
        # active-set start: the iterate plus the step lands on the bound
        zp[iz] = np.where(act_z[iz] > 0, rows.ubz[iz], rows.lbz[iz])
        y = sol[nz:]
        y_eq = y[:neq]
        yin = np.zeros(Ain.shape[0]); yin[ii] = y[neq:neq + ii.size]
        muz = np.zeros(nz); muz[iz] = y[neq + ii.size:]
        vin = Ain @ zp
        changed = dropped = False
        # dual sign of the active set: drop rows whose multiplier points the wrong way
        wrong = []
        for act, mu, lo, hi in ((act_z, muz, rows.lbz, rows.ubz), (act_in, yin, rows.l_in, rows.u_in)):
            eqrow = np.isfinite(lo) & np.isfinite(hi) & (lo == hi)
            wrong.append((~eqrow) & (((act > 0) & (mu < -tol)) | ((act < 0) & (mu > tol))))
        if families is not None:
            worst = np.zeros(int(max(np.max(families[0], initial=0), np.max(families[1], initial=0))) + 1)
            for bad, mu, fam in zip(wrong, (muz, yin), families):
                np.maximum.at(worst, fam[bad], np.abs(mu[bad]))
        for bad, act, mu, k in zip(wrong, (act_z, act_in), (muz, yin), (0, 1)):
            if np.any(bad):
                changed = dropped = True
                if families is not None:
                    bad = bad & (np.abs(mu) >= AS_DROP * worst[families[k]])
                act[bad] = 0
        # primal feasibility of the inactive set: add violated sides
        n_add = 0
        for act, v, lo, hi in ((act_z, zp, rows.lbz, rows.ubz), (act_in, vin, rows.l_in, rows.u_in)):
            up = (act == 0) & (v > hi + tol)
            dn = (act == 0) & (v < lo - tol)
            if np.any(up | dn):
                act[up] = 1
                act[dn] = -1
                changed = True
                n_add += int(np.count_nonzero(up | dn))
        if not changed:
            return (zp, y_eq, yin, muz), n_fact, sweep + 1
        # rows added since the last factorisation (``added``), held by its Schur complement
        update = families is not None and not dropped and added + n_add <= AS_UPDATE
        added = added + n_add if update else 0
    return None, n_fact, sweeps


def _active_set_start(q: dict, Hz, gz, rows: _Rows, guess: dict, tol: float, sweeps: int):
    """The C QP's active-set start (runtime_c/dopus_qp.h) on the flattened QP: the active set
    read from the warm-start point ``guess`` (a stage-wise solution dict), its KKT system
    solved and the set corrected for up to ``sweeps`` sweeps (a factorisation each, except
    after corrections that only added rows, :data:`AS_UPDATE`); the answer is accepted
    as the polish's is, and when the Hessian is positive definite on the null space of the
    equality and active rows (the C start's factorisation succeeds only then). Returns
    (solution dict or None, factorisations, sweeps)."""
    z, _, y_in, mu_z = flatten_solution(q, guess)
    pol, n_fact, n_sweeps = _polish(Hz, gz, rows, z, y_in, mu_z, tol, sweeps=sweeps, families=_families(q))
    if pol is None:
        return None, n_fact, n_sweeps
    sol = _unflatten(q, *pol, rows=rows)
    res = qp_kkt_residual(q, sol)
    scale = max(1.0, float(np.max(np.abs(gz))), float(np.max(np.abs(Hz.data))) if Hz.nnz else 1.0)
    if not (res["ineq"] <= tol and res["sign"] <= tol and max(res["stat"], res["eq"]) <= 1e-9 * scale):
        return None, n_fact, n_sweeps
    if qp_reduced_hessian_min_eig(q, sol, tol=0.0) <= 0.0:
        return None, n_fact, n_sweeps
    return sol, n_fact, n_sweeps


def solve_qp_reference(qp: dict, tol: float = 1e-9, polish: bool = True, max_iter=None, guess=None,
                       guess_sweeps: int = 0) -> dict:
    """Solve a QP of the module's format; return the solution dict (see module docstring).

    ``tol`` is the feasibility / dual-sign tolerance the polished active set must meet
    (floored at 1e-12; the polished solution itself satisfies stationarity and the active
    rows to round-off, its inactive multipliers are exactly zero). ``polished`` is False
    when no consistent active set was found: the answer is then IPOPT's (tol 1e-12). Raises :class:`QPInfeasibleError` for an infeasible QP
    (IPOPT's verdict, or, when IPOPT fails otherwise, a Farkas certificate of the hard rows
    found by :func:`qp_infeasible_row`) and :class:`QPError` when IPOPT fails otherwise. ``max_iter`` (default None: 500 with the
    polish as the fallback): IPOPT's iteration limit; reaching it raises
    :class:`QPIterationLimitError`, as the C QP solver reports its limit.

    ``guess`` (a solution dict, the warm-start point) with ``guess_sweeps > 0``: first the C
    QP's active-set start from it (:func:`_active_set_start`; not for soft rows), IPOPT only
    when it finds no answer (its sweeps count as iterations: at most ``max_iter``, and
    ``iterations`` when it gives the answer). ``factorizations`` counts the factorisations of KKT systems:
    the start's sweeps that factor (:data:`AS_UPDATE`), IPOPT's iterations and the polish's
    sweeps; ``active_set`` the start's sweeps when it gave the answer, else 0.
    """
    t0 = time.perf_counter()
    try:
        q = check_qp(qp)
    except QPInfeasibleError as exc:
        exc.row = qp_infeasible_row(qp)
        raise
    Hz, gz, rows = flatten_qp(q)
    n_fact = 0
    if max_iter is not None:
        guess_sweeps = min(int(guess_sweeps), int(max_iter))   # a sweep is an iteration of the solve
    if guess is not None and guess_sweeps > 0 and rows.moved is None:
        sol, n_fact, n_sweeps = _active_set_start(q, Hz, gz, rows, guess, max(float(tol), 1e-12), int(guess_sweeps))
        if sol is not None:
            sol.update(polished=True, iterations=n_sweeps, status="active_set", factorizations=n_fact,
                       active_set=n_sweeps,
                       solve_time=time.perf_counter() - t0)
            return sol
    solve = _solve_ipopt_flat if rows.moved is not None else (lambda *a: _solve_ipopt(q, *a))
    z, y_eq, y_in, mu_z, status, iters = solve(Hz, gz, rows, 500 if max_iter is None else max_iter)
    n_fact += max(iters, 0)
    if status in ("Infeasible_Problem_Detected", "Restoration_Failed"):
        exc = QPInfeasibleError(f"QP is infeasible (IPOPT: {status})")
        exc.row = qp_infeasible_row(q)
        raise exc
    if max_iter is not None and status == "Maximum_Iterations_Exceeded":
        raise QPIterationLimitError(f"QP iteration limit {max_iter} reached (IPOPT: {status})")
    ok_status = status in ("Solve_Succeeded", "Solved_To_Acceptable_Level")
    if not ok_status:
        # the diagnosis of a failed solve, as the C solver's after a stall or failure: a
        # Farkas certificate of the hard rows (an LP, exact to its tolerances) proves
        # infeasibility (the iteration limit asked for is reported as such, as in C)
        row = qp_infeasible_row(q)
        if row is not None:
            exc = QPInfeasibleError(f"QP is infeasible (IPOPT: {status}; a Farkas certificate)")
            exc.row = row
            raise exc
    out = None
    if polish and np.all(np.isfinite(z)):
        # active-set decisions at the requested tolerance, but never below round-off
        ftol = max(float(tol), 1e-12)
        pol, pol_fact, _ = _polish(Hz, gz, rows, z, y_in, mu_z, ftol)
        if pol is not None:
            n_fact += pol_fact
            sol = _unflatten(q, *pol, rows=rows)
            res = qp_kkt_residual(q, sol)
            scale = max(1.0, float(np.max(np.abs(gz))), float(np.max(np.abs(Hz.data))) if Hz.nnz else 1.0)
            if res["ineq"] <= ftol and res["sign"] <= ftol and max(res["stat"], res["eq"]) <= 1e-9 * scale:
                out = sol
                out["polished"] = True
    if out is None:
        if not ok_status:
            raise QPError(f"reference QP solver failed (IPOPT: {status})")
        if status != "Solve_Succeeded":
            # IPOPT's "acceptable" answer that no active set polishes: on a QP infeasible by
            # a margin near the tolerance IPOPT stops at its acceptable level with the
            # dynamics violated far beyond the tolerance (1e-8 .. 1e-6 at margins 1e-9 ..
            # 1e-7); the diagnosis of a failed solve (a Farkas certificate) decides, as the
            # C solver's diagnosis after a stall
            row = qp_infeasible_row(q)
            if row is not None:
                exc = QPInfeasibleError(f"QP is infeasible (IPOPT: {status}, no polished active set; "
                                        "a Farkas certificate)")
                exc.row = row
                raise exc
        out = _unflatten(q, z, y_eq, y_in, mu_z, rows=rows)
        out["polished"] = False
    out["iterations"] = iters
    out["factorizations"] = n_fact
    out["active_set"] = 0
    out["status"] = status
    out["solve_time"] = time.perf_counter() - t0
    return out


def qp_reduced_hessian_min_eig(qp: dict, sol: dict, tol: float = 1e-9) -> float:
    """Smallest eigenvalue of the QP Hessian on the null space of the equality rows and
    the active inequality rows of ``sol`` (second-order check; dense, for tests)."""
    import scipy.linalg as sla

    q = check_qp(qp)
    Hz, gz, rows = flatten_qp(q)
    z, _, y_in, mu_z = flatten_solution(q, sol)
    act_z = np.nonzero(np.abs(mu_z) > tol)[0]
    act_in = np.nonzero(np.abs(y_in) > tol)[0]
    A = np.vstack([rows.A_eq.toarray(), rows.A_in.toarray()[act_in], np.eye(Hz.shape[0])[act_z]])
    Z = sla.null_space(A)
    if Z.shape[1] == 0:
        return float("inf")
    return float(np.min(np.linalg.eigvalsh(Z.T @ Hz.toarray() @ Z)))


# ---------------------------------------------------------------------------
# The row of an infeasible QP
# ---------------------------------------------------------------------------

def _stage_rows(q: dict, data_rows: bool = False):
    """The inequality rows of ``q`` in the numbering of the C QP solver (dopus_qp.c): per
    stage ``k < N`` the ``nw`` box rows of ``w_k`` then the ``ng`` path rows (``j``
    0..nw+ng-1), at the terminal node the ``nx`` box rows of ``x_N`` then the ``nr`` rows
    of ``R``; the ``ne`` equality rows of ``Req`` follow as ``j = nx + nr + i`` of stage N.
    Yields ``(k, j, a, lo, up)`` with ``a`` the row over ``z`` (see :func:`flatten_qp`), in
    that order; the x rows of stage 0 (``x_0`` is fixed) are left out, as in the C solver,
    and so are the path rows of stage 0 that do not involve ``u_0`` (their value is data)
    unless ``data_rows``."""
    N, nx, nu, ng, nr, ne = (q[k] for k in _INT_KEYS)
    nw = nx + nu
    nz = N * nw + nx

    def unit(c):
        a = np.zeros(nz)
        a[c] = 1.0
        return a

    for k in range(N):
        for j in range(nx if k == 0 else 0, nw):
            yield k, j, unit(k * nw + j), q["lbw"][k, j], q["ubw"][k, j]
        for i in range(ng):
            if k == 0 and not data_rows and not np.any(q["C"][0][i, nx:]):
                continue
            a = np.zeros(nz)
            a[k * nw:(k + 1) * nw] = q["C"][k][i]
            yield k, nw + i, a, q["lg"][k, i], q["ug"][k, i]
    for j in range(nx):
        yield N, j, unit(N * nw + j), q["lbxN"][j], q["ubxN"][j]
    for i in range(nr):
        a = np.zeros(nz)
        a[N * nw:] = q["R"][i]
        yield N, nx + i, a, q["lr"][i], q["ur"][i]
    for i in range(ne):
        a = np.zeros(nz)
        a[N * nw:] = q["Req"][i]
        yield N, nx + nr + i, a, q["req"][i], q["req"][i]


def _shaped(qp: dict) -> dict:
    """A copy of the QP dict with integer sizes and arrays in their shapes."""
    q = dict(qp)
    for k in _INT_KEYS:
        q[k] = int(q[k])
    for key, shape in _shapes(**{k: q[k] for k in _INT_KEYS}).items():
        q[key] = np.asarray(q[key], dtype=float).reshape(shape)
    return q


def qp_infeasible_row(qp: dict):
    """The row of an infeasible QP that its infeasibility certificate weighs most, by the
    rule of the C QP solver (dopus_qp_infeasible_row): ``(stage, j, side)`` with ``j`` the
    row in the C numbering (see :func:`_stage_rows`), ``side`` -1 (its lower bound), +1 (its
    upper bound; an equality row: the sign of its multiplier) or 0 (the first row, in that
    order, whose lower bound exceeds its upper bound). None when the QP is feasible.

    The certificate is Farkas's for the rows other than the initial state and the
    dynamics (those eliminated by the controls ``v``: each row ``lo <= G v + h <= up``):
    multipliers ``l >= 0`` of the finite sides with ``G'(l_up - l_lo) = 0`` and a positive
    gap ``l_lo'(lo - h) - l_up'(up - h)``, the one of the largest gap per unit of
    multiplier mass (``sum l = 1``; a linear programme, HiGHS). It is a vertex, the
    certificate of one infeasible subset of rows, as the C solver's diverging multipliers
    single one out. The named row is the one with the largest multiplier (the first in the
    order above on a tie, the lower side before the upper one).

    As in the C solver, the path rows of stage 0 that do not involve ``u_0`` take no part;
    only when the other rows are feasible (this QP keeps those rows, the C solver's drops
    them) is the certificate sought with them. When neither finds a certificate, both are
    sought again with every row divided by its largest coefficient (multiplier mass and
    gap in the units of each row, as the C solver's test after a stall weighs them): a row
    written with small coefficients (a terminal equality row scaled by 4e-3) otherwise
    carries a multiplier hundreds of times the others and its certificate's gap per unit
    of mass falls below the LP's threshold; the row named is still the one of the largest
    multiplier of the rows as written."""
    q = _hardened(_shaped(qp))
    for normalised in (False, True):
        for data_rows in (False, True):
            row = _certificate_row(q, data_rows, normalised=normalised)
            if row is not None:
                return row
    return None


def _hardened(q: dict) -> dict:
    """The QP dict with its soft sides dropped (set to infinite bounds): a soft side never
    makes a QP infeasible, the certificates are those of the hard rows."""
    if not has_soft(q):
        return q
    q = dict(q)
    ws, wt = soft_weights(q)
    nx, nw = q["nx"], q["nx"] + q["nu"]
    for lo_key, up_key, w in (("lbw", "ubw", ws[:, :nw]), ("lg", "ug", ws[:, nw:]),
                              ("lbxN", "ubxN", wt[:, :nx]), ("lr", "ur", wt[:, nx:])):
        lo, up = np.array(q[lo_key], float), np.array(q[up_key], float)
        lo[..., (w[0] > 0) | (w[2] > 0)] = -np.inf
        up[..., (w[1] > 0) | (w[3] > 0)] = np.inf
        q[lo_key], q[up_key] = lo, up
    return q


def qp_row_in_certificate(qp: dict, row) -> float:
    """The largest share of multiplier mass that the row ``row = (stage, j, side)`` (as
    :func:`qp_infeasible_row` names rows) can carry in a Farkas certificate of the QP's
    infeasibility (the certificates of :func:`qp_infeasible_row`, gap at least a
    thousandth of the largest); 0 when no certificate uses it. A QP with several
    infeasible subsets of rows has several valid certificates, and a solver may single out
    any of them: a row named by a solver is valid when this is positive."""
    q = _hardened(_shaped(qp))
    best = 0.0
    for normalised in (False, True):
        for data_rows in (False, True):
            share = _certificate_row(q, data_rows, weigh=tuple(row), normalised=normalised)
            best = max(best, share or 0.0)
    return best


_LP_TOL = {"primal_feasibility_tolerance": 1e-10, "dual_feasibility_tolerance": 1e-10}


def _certificate_row(q: dict, data_rows: bool, weigh=None, normalised: bool = False):
    """:func:`qp_infeasible_row` of a checked QP dict, with or without the data rows; with
    ``weigh`` a row ``(stage, j, side)``, the largest multiplier share that row can take
    in a certificate instead (see :func:`qp_row_in_certificate`); ``normalised``: every row
    divided by its largest coefficient."""
    from scipy.optimize import linprog

    N, nx, nu = q["N"], q["nx"], q["nu"]
    rows = list(_stage_rows(q, data_rows))
    for k, j, _, lo, up in rows:
        if lo > up:
            return k, j, 0
    nw = nx + nu
    nz = N * nw + nx
    # z = T v + c over the controls v = (u_0, ..., u_{N-1}): the initial state and dynamics
    T = np.zeros((nz, N * nu))
    c = np.zeros(nz)
    Tx, cx = np.zeros((nx, N * nu)), q["x0"].copy()
    for k in range(N):
        T[k * nw:k * nw + nx], c[k * nw:k * nw + nx] = Tx, cx
        T[k * nw + nx:(k + 1) * nw, k * nu:(k + 1) * nu] = np.eye(nu)
        Phi = q["Phi"][k]
        Tx = Phi[:, :nx] @ Tx
        Tx[:, k * nu:(k + 1) * nu] += Phi[:, nx:]
        cx = Phi[:, :nx] @ cx + q["b"][k]
    T[N * nw:], c[N * nw:] = Tx, cx
    kept = [r for r in rows if np.isfinite(r[3]) or np.isfinite(r[4])]
    A = np.array([r[2] for r in kept])
    lo = np.array([r[3] for r in kept])
    up = np.array([r[4] for r in kept])
    G, h = A @ T, A @ c
    # the rows' scales: 1 as written, else the largest coefficient of each row (the
    # multipliers of the rows as written are those of the scaled rows over it)
    rs = np.abs(A).max(axis=1) if normalised else np.ones(len(kept))
    rs[rs == 0.0] = 1.0
    G, h, lo, up = G / rs[:, None], h / rs, lo / rs, up / rs
    # Farkas: lo <= G v + h <= up has no v iff some l_lo, l_up >= 0 (on the finite sides)
    # have G'(l_up - l_lo) = 0 and l_lo'(lo - h) - l_up'(up - h) > 0; the certificate of
    # the largest gap per unit of multiplier mass (a vertex: one infeasible subsystem)
    m = len(kept)
    flo, fup = np.isfinite(lo), np.isfinite(up)
    cols = [(i, -1) for i in range(m) if flo[i]] + [(i, 1) for i in range(m) if fup[i]]
    if not cols:
        return None
    sgn = np.array([sd for _, sd in cols], dtype=float)
    idx = np.array([i for i, _ in cols])
    gap = np.array([(lo[i] - h[i]) if sd < 0 else -(up[i] - h[i]) for i, sd in cols])
    A_eq = np.vstack([G[idx].T * sgn, np.ones(len(cols))])
    b_eq = np.concatenate([np.zeros(G.shape[1]), [1.0]])
    res = linprog(-gap, A_eq=A_eq, b_eq=b_eq, bounds=(0, None), method="highs", options=_LP_TOL)
    if res.status != 0 or not -res.fun > 1e-12 * _scale(h, lo, up):
        return None
    if weigh is not None:
        cand = [col for col in range(len(cols))
                if (kept[idx[col]][0], kept[idx[col]][1]) == weigh[:2] and (weigh[2] == 0 or sgn[col] == weigh[2])]
        share = 0.0
        for col in cand:
            # the largest weight of this column over the certificates with a gap of at
            # least a thousandth of the largest one
            r2 = linprog(-np.eye(len(cols))[col], A_ub=-gap[None, :], b_ub=[1e-3 * res.fun],
                         A_eq=A_eq, b_eq=b_eq, bounds=(0, None), method="highs", options=_LP_TOL)
            if r2.status == 0:
                share = max(share, -r2.fun)
        return share
    # the largest multiplier; on a tie the first row in the order above, its lower side
    # first (the C rule's scan)
    best = -1
    lam = res.x / rs[idx]
    for col in sorted(range(len(cols)), key=lambda col: (idx[col], sgn[col])):
        if lam[col] > (lam[best] if best >= 0 else 0.0):
            best = col
    if best < 0:
        return None
    i = int(idx[best])
    k, j = kept[i][0], kept[i][1]
    return k, j, int(sgn[best])


def _scale(h, lo, up):
    return max(1.0, float(np.max(np.abs(h), initial=0.0)),
               float(np.max(np.abs(np.where(np.isfinite(lo), lo, 0.0)), initial=0.0)),
               float(np.max(np.abs(np.where(np.isfinite(up), up, 0.0)), initial=0.0)))
