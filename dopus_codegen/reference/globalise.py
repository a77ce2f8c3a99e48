"""The globalised first solve in numpy (docs/algorithm.md section 15), the oracle of
runtime_c/dopus_globalise.c.

One step from a prepared iterate (after ``init`` or the previous step: every block fresh) for
the initial state ``xhat0``, in fixed mode:

1. the merit parts at the iterate: the cost ``f`` (the stage and terminal costs plus the
   price ``l1 s + 0.5 l2 s^2`` of every soft side's violation ``s``) and the l1 violation
   ``c`` of the hard rows (``|x_0 - xhat0|``, the dynamics, path and terminal rows, the
   bounds, the terminal equalities);
2. the QP of the iterate (the backend's feedback: the automatic lm and its retries) gives the
   step ``p`` and the multipliers ``y_QP``; the penalty ``nu`` is raised to
   ``2 |y_QP|_inf`` when it is below ``1.1 |y_QP|_inf``;
3. the slope ``D = a' p - nu c + sum_soft (psi(v_lin) - psi(v))`` (``a``: the QP's gradient,
   the cost gradient when every block is fresh; ``v_lin`` the linearised rows at the full
   step), and the backtracking line search ``a = 1, 1/2, ...`` until
   ``phi(a) <= phi(0) + 1e-4 a min(D, 0) + 10 eps (1 + |phi(0)|)``, ``phi = f + nu c``; the
   full step is also taken when its KKT measure (with the QP's multipliers) is at most half
   the lowest KKT measure of the solve so far (the Maratos effect);
4. the iterate ``w + a p``, the multipliers ``y + a (y_QP - y)``, and ``init`` there (every
   block fresh, the next QP prepared).

The backends call it through ``globalised_start()``, ``globalised_step(xhat0)`` and
``init_globalised(xhat0, guess, max_work, max_iter, tol)``.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from typing import Optional

import numpy as np

from .. import vocabulary
from ..errors import DopusError
from .kkt import eval_stages

__all__ = ["GlobState", "constants", "merit_parts", "globalised_step", "init_globalised", "REASONS",
           "what_to_try"]


@lru_cache(maxsize=None)
def constants() -> dict:
    """The constants of runtime_c/dopus_globalise.h by name (``GLOB_ARMIJO``, ...)."""
    from ..paths import runtime_c_dir

    return vocabulary.parse_constants((runtime_c_dir() / "dopus_globalise.h").read_text())


#: enum dopus_glob_reason: code -> name
REASONS = {0: "ok", 1: "qp", 2: "step_box", 3: "line_search", 4: "function", 5: "work_limit",
           6: "not_prepared", 7: "iter_limit"}


def what_to_try(reason: str) -> str:
    """The advice of a failed globalised solve, by its reason."""
    return {
        "qp": "the QP of an iterate was not solved: try a better guess (ocp.initial_guess), soft terminal rows "
              "(Soft(l1, l2) on terminal_constraint) or a longer horizon",
        "step_box": "a QP step left the problem's scale box: try a better guess (ocp.initial_guess) or bounds on "
                    "the states that run away",
        "line_search": "the line search found no decrease of the merit function: try a better guess "
                       "(ocp.initial_guess), the Gauss-Newton Hessian (--hessian gauss-newton) or soft terminal "
                       "rows (Soft(l1, l2) on terminal_constraint)",
        "function": "a model function is not finite at a trial point: try a better guess (ocp.initial_guess) "
                    "or bounds that keep the model defined",
        "work_limit": "the work limit ended the iterations: try more iterations (--iters) or a better guess",
        "iter_limit": "the iteration limit ended the iterations: try more iterations (--iters) or a better guess",
        "not_prepared": "the solver holds no prepared QP: call init first",
    }.get(reason, "try more iterations (--iters), a better guess (ocp.initial_guess) or soft terminal rows")


@dataclass
class GlobState:
    """The memory of a globalised solve (``struct dopus_glob``)."""
    penalty: float = 0.0
    alpha: float = 0.0
    merit: float = 0.0
    slope: float = 0.0
    kkt: float = float("nan")
    kkt_best: float = float("inf")
    by_kkt: bool = False
    iterations: int = 0
    trials: int = 0
    reason: str = "ok"
    history: list = field(default_factory=list)


def _side_price(s, l1, l2):
    return l1 * s + 0.5 * l2 * s * s


def _rows(v, lo, up, w):
    """(hard violation l1 sum, soft price) of rows ``lo <= v <= up`` with soft weights ``w``
    (4 x n: l1 lower, l1 upper, l2 lower, l2 upper; None: all hard)."""
    v = np.asarray(v, float).reshape(-1)
    lo = np.asarray(lo, float).reshape(-1)
    up = np.asarray(up, float).reshape(-1)
    hard = price = 0.0
    for i in range(v.size):
        for side, bound, sgn in ((0, lo[i], -1.0), (1, up[i], 1.0)):
            if not np.isfinite(bound):
                continue
            s = max(0.0, sgn * (v[i] - bound))
            if w is not None and (w[side, i] > 0 or w[2 + side, i] > 0):
                price += _side_price(s, w[side, i], w[2 + side, i])
            else:
                hard += s
    return hard, price


def _soft(disc, name):
    if not getattr(disc, "has_soft", False):
        return None
    return getattr(disc, name)


def merit_parts(be, xhat0, x, u):
    """``(f, c)`` at the primal point ``(x, u)``: the cost with the prices of the soft sides,
    and the l1 violation of the hard rows. Counts ``N + 1`` work units."""
    disc, N = be.disc, be.N
    be.work += N + 1
    phi, l, g = eval_stages(disc.stage_eval, N, x[:N], u, be.p[:N])
    te = disc.term_eval(x[N], be.p[N])
    E = float(np.array(te[0]).reshape(-1)[0])
    r = np.array(te[1], float).reshape(be.nr)
    r_eq = np.array(te[2], float).reshape(be.ne)
    vals = [phi, l, g, E, r, r_eq]
    if not all(np.all(np.isfinite(v)) for v in vals):
        return None
    f = float(np.sum(l)) + E
    c = float(np.sum(np.abs(x[0] - xhat0))) + float(np.sum(np.abs(x[1:] - phi))) + float(np.sum(np.abs(r_eq)))
    sx, sg, sr = _soft(disc, "soft_x"), _soft(disc, "soft_g"), _soft(disc, "soft_r")
    for k in range(N):
        if k > 0:
            h, p_ = _rows(x[k], be.lbx, be.ubx, sx)
            c, f = c + h, f + p_
        h, _ = _rows(u[k], be.lbu, be.ubu, None)
        c += h
        if be.ng:
            h, p_ = _rows(g[k], be.lg_k[k], be.ug_k[k], sg)
            c, f = c + h, f + p_
    h, p_ = _rows(x[N], be.lbx, be.ubx, sx)
    c, f = c + h, f + p_
    if be.nr:
        h, p_ = _rows(r, be.lr, be.ur, sr)
        c, f = c + h, f + p_
    return f, c


def _soft_change(be, x, u, dx, du):
    """``sum_soft psi(v_lin) - psi(v)``: the change of the soft prices along the linearised
    rows at the full step (state bounds exact, path rows ``g + Ct dw``, terminal rows ``r + R dx_N``)."""
    disc, N = be.disc, be.N
    if not getattr(disc, "has_soft", False):
        return 0.0
    sx, sg, sr = disc.soft_x, disc.soft_g, disc.soft_r
    total = 0.0
    for k in range(1, N + 1):
        total += _rows(x[k] + dx[k], be.lbx, be.ubx, sx)[1] - _rows(x[k], be.lbx, be.ubx, sx)[1]
    for k in range(N):
        if be.ng:
            s = be.slots[be._slot(k)]
            dw = np.concatenate([dx[k], du[k]])
            total += (_rows(s.g + s.Ct @ dw, be.lg_k[k], be.ug_k[k], sg)[1]
                      - _rows(s.g, be.lg_k[k], be.ug_k[k], sg)[1])
    if be.nr:
        t = be.term
        total += _rows(t["r"] + t["R"] @ dx[N], be.lr, be.ur, sr)[1] - _rows(t["r"], be.lr, be.ur, sr)[1]
    return total


_MULT = ("lam", "mu_g", "mu_b", "mu_bN", "mu_r", "nu")


def globalised_step(be, st: GlobState, xhat0) -> None:
    """One globalised step of the backend ``be`` (a ReferenceDopus) from its prepared iterate;
    raises DopusError on failure with ``st.reason`` set, the iterate unchanged."""
    C = constants()
    xhat0 = np.asarray(xhat0, float).reshape(be.nx)
    st.reason, st.trials = "ok", 0
    if not be._initialised or not be._qp_ready:
        st.reason = "not_prepared"
        raise DopusError.of("not_prepared", "globalised step: no prepared QP (call init first)")
    mode = be.mode
    be.set_mode("fixed")
    try:
        _step(be, st, xhat0, C)
    finally:
        be.set_mode(mode)


def _step(be, st, xhat0, C):
    N = be.N
    x0, u0 = be.x.copy(), be.u.copy()
    y0 = {k: getattr(be, k).copy() for k in _MULT}
    st.by_kkt = False
    st.kkt_best = min(st.kkt_best, _kkt(be, xhat0))
    parts = merit_parts(be, xhat0, x0, u0)
    if parts is None:
        st.reason = "function"
        raise DopusError.of("nonfinite_value", "globalised step: a function is not finite at the iterate")
    f0, c0 = parts
    qp = be.qp_of_current(xhat0)
    a, aN = qp["g"].copy(), qp["gN"].copy()
    try:
        be.feedback(xhat0)
    except DopusError as exc:
        st.reason = "step_box" if exc.status_name == "diverged" else "qp" if exc.status_name == "qp" else "function"
        raise
    dx, du = be.x - x0, be.u - u0
    yq = {k: getattr(be, k).copy() for k in _MULT}
    ymax = max([float(np.max(np.abs(v), initial=0.0)) for v in yq.values()])
    if st.penalty < C["GLOB_PENALTY_MARGIN"] * ymax:
        st.penalty = C["GLOB_PENALTY_RAISE"] * ymax
    nu = st.penalty
    a_dot_p = float(np.sum(a * np.hstack([dx[:N], du]))) + float(aN @ dx[N])
    # the soft change needs the blocks of the iterate: the slots are those of the QP just solved
    D = a_dot_p - nu * c0 + _soft_change(be, x0, u0, dx, du)
    phi0 = f0 + nu * c0
    floor = C["GLOB_MERIT_FLOOR"] * np.finfo(float).eps * (1.0 + abs(phi0))
    alpha, accepted, phi = 1.0, False, float("nan")
    for trial in range(int(C["GLOB_MAX_TRIALS"])):
        st.trials = trial + 1
        xt = be.x.copy() if alpha == 1.0 else x0 + alpha * dx
        ut = be.u.copy() if alpha == 1.0 else u0 + alpha * du
        parts = merit_parts(be, xhat0, xt, ut)
        if parts is not None:
            phi = parts[0] + nu * parts[1]
            if phi <= phi0 + C["GLOB_ARMIJO"] * alpha * min(D, 0.0) + floor:
                accepted = True
                break
        # the full step also when it lowers the KKT measure enough (the backend's iterate is the
        # full step with the QP's multipliers): the Maratos effect
        if trial == 0:
            kkt = _kkt(be, xhat0)
            if kkt <= C["GLOB_KKT_FACTOR"] * st.kkt_best:
                st.kkt_best, st.by_kkt, accepted = kkt, True, True
                break
        alpha *= C["GLOB_BACKTRACK"]
    st.slope = D
    if not accepted:
        # the iterate as it was, its QP prepared again
        be.init(xhat0, _guess(x0, u0, y0))
        st.reason = "line_search"
        raise DopusError.of("diverged", f"globalised step: no step length down to {alpha / C['GLOB_BACKTRACK']:.1e} "
                            f"decreased the merit function (slope {D:.3e}, penalty {nu:.3e})")
    if alpha == 1.0:
        y = yq
    else:
        y = {k: y0[k] + alpha * (yq[k] - y0[k]) for k in _MULT}
    be.init(xhat0, _guess(xt, ut, y))
    st.alpha, st.merit = alpha, phi
    st.iterations += 1
    st.history.append({"alpha": alpha, "penalty": nu, "merit": phi, "slope": D, "trials": st.trials,
                       "by_kkt": st.by_kkt})


def _kkt(be, xhat0) -> float:
    """The KKT measure of the backend's iterate, counted as ``N + 1`` work units."""
    be.work += be.N + 1
    return float(be.kkt(xhat0)["kkt"])


def _guess(x, u, y):
    from ..problem.ocp import Guess

    return Guess(x=np.array(x, float), u=np.array(u, float), **{k: np.array(v, float) for k, v in y.items()})


def init_globalised(be, st: GlobState, xhat0, guess=None, max_work: float = 0.0, max_iter: int = 100,
                    tol: Optional[float] = None) -> bool:
    """``init`` at the guess, then globalised steps until the KKT measure is at most ``tol``
    (True), or the iteration or work limit (``max_work`` > 0: work units from the init on)
    ends them (False, ``st.reason``). A failed step raises DopusError (the iterate prepared)."""
    from .. import settings as settings_mod

    tol = settings_mod.KKT_TOL_DEFAULT["double"] if tol is None else tol
    st.__init__()
    if not (tol > 0) or not (max_work >= 0) or int(max_iter) < 0:
        raise DopusError.of("invalid_argument", f"init_globalised: tol must be > 0, max_work >= 0 and max_iter >= 0, "
                            f"got {tol!r}, {max_work!r}, {max_iter!r}")
    be.init(xhat0, guess)
    w_start = be.work
    cost = 0.0
    for it in range(max_iter + 1):
        st.kkt = float(be.kkt(xhat0)["kkt"])
        if st.kkt <= tol:
            st.reason = "ok"
            return True
        if it == max_iter:
            st.reason = "iter_limit"
            return False
        if max_work > 0 and be.work - w_start + cost > max_work:
            st.reason = "work_limit"
            return False
        w0 = be.work
        globalised_step(be, st, xhat0)
        cost = be.work - w0
    return False
