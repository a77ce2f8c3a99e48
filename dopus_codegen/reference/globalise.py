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
   ``phi(a) <= phi(0) + 1e-4 a min(D, 0) + 10 eps (1 + |phi(0)|)``, ``phi = f + nu c``; with
   the watchdog: a full step the test refuses is taken all the same (the point before it
   kept), and so are up to 4 more, until one meets the test against the kept point; else the
   line search runs from the kept point along its step (and the next refused step is not
   relaxed);
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
    relaxed: bool = False
    relax_ok: bool = True
    restores: int = 0
    watch: Optional[dict] = None
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
            s = be.slot_of(k)
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
    xhat0 = _xhat(be, xhat0, "globalised_step: xhat0")
    st.reason, st.trials = "ok", 0
    if not be.initialized or not be.qp_ready:
        st.reason = "not_prepared"
        raise DopusError.of("not_prepared", "globalised step: no prepared QP (call init first)")
    mode = be.mode
    be.set_mode("fixed")
    be.active_set_start = False    # the step's QP from scratch, as the C runtime's
    try:
        _step(be, st, xhat0, C)
    finally:
        be.set_mode(mode)
        be.active_set_start = True


def _xhat(be, xhat0, what):
    """``xhat0`` as ``nx`` finite numbers, else a DopusError naming the problem."""
    try:
        a = np.array(xhat0, dtype=float)
    except (TypeError, ValueError) as exc:
        raise DopusError.of("invalid_argument", f"{what}: not an array of numbers ({exc})") from None
    if a.size != be.nx:
        raise DopusError.of("invalid_argument", f"{what}: expected shape ({be.nx},), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise DopusError.of("nonfinite_input", f"{what}: NaN or Inf at index "
                            f"{', '.join(str(int(i)) for i in np.flatnonzero(~np.isfinite(a.reshape(-1)))[:5])}")
    return a.reshape(be.nx)


def _merit(be, xhat0, x, u, nu):
    parts = merit_parts(be, xhat0, x, u)
    return None if parts is None else parts[0] + nu * parts[1]


def _armijo(phi, phi0, alpha, D, C):
    floor = C["GLOB_MERIT_FLOOR"] * np.finfo(float).eps * (1.0 + abs(phi0))
    return phi is not None and phi <= phi0 + C["GLOB_ARMIJO"] * alpha * min(D, 0.0) + floor


def _step(be, st, xhat0, C):
    N = be.N
    x0, u0 = be.x.copy(), be.u.copy()
    y0 = {k: getattr(be, k).copy() for k in _MULT}
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
        if st.watch is not None:
            # a relaxed step led here: back to the watchdog's point, a line search there
            _restore(be, st, xhat0, C)
            return
        st.reason = "step_box" if exc.status_name == "diverged" else "qp" if exc.status_name == "qp" else "function"
        raise
    dx, du = be.x - x0, be.u - u0
    yq = {k: getattr(be, k).copy() for k in _MULT}
    ymax = max([float(np.max(np.abs(v), initial=0.0)) for v in yq.values()])
    if st.penalty < C["GLOB_PENALTY_MARGIN"] * ymax:
        st.penalty = C["GLOB_PENALTY_RAISE"] * ymax
    nu = st.penalty
    # the cost's slope along the step (the QP's gradient: every block fresh) and the change
    # of the soft prices, measured with the blocks of the QP just solved
    adp = (float(np.sum(a * np.hstack([dx[:N], du]))) + float(aN @ dx[N])
           + _soft_change(be, x0, u0, dx, du))
    D = adp - nu * c0
    phi0 = f0 + nu * c0
    st.slope = D
    st.trials = 1
    phi1 = _merit(be, xhat0, be.x.copy(), be.u.copy(), nu)
    w = st.watch
    if w is None:
        if _armijo(phi1, phi0, 1.0, D, C):
            _accept(be, st, xhat0, 1.0, be.x.copy(), be.u.copy(), yq, phi1)
        elif phi1 is not None and st.relax_ok:
            # the watchdog: the full step all the same, the point before it kept
            st.watch = {"x": x0, "u": u0, "y": y0, "f": f0, "c": c0, "adp": adp, "dx": dx, "du": du,
                        "yq": yq, "m": 1}
            _accept(be, st, xhat0, 1.0, be.x.copy(), be.u.copy(), yq, phi1, relaxed=True)
        else:
            _line_search(be, st, xhat0, C, x0, u0, y0, dx, du, yq, phi0, D, nu)
            st.relax_ok = True
        return
    phi_s, D_s = w["f"] + nu * w["c"], w["adp"] - nu * w["c"]
    if _armijo(phi1, phi_s, 1.0, D_s, C):
        st.watch = None
        _accept(be, st, xhat0, 1.0, be.x.copy(), be.u.copy(), yq, phi1)
    elif phi1 is not None and w["m"] < C["GLOB_WATCHDOG"]:
        w["m"] += 1
        _accept(be, st, xhat0, 1.0, be.x.copy(), be.u.copy(), yq, phi1, relaxed=True)
    else:
        _restore(be, st, xhat0, C)


def _restore(be, st, xhat0, C):
    """The relaxed steps did not decrease the merit enough: the line search from the
    watchdog's point along its step, from ``alpha = 1/2`` (the full step was refused)."""
    w, nu = st.watch, st.penalty
    st.watch, st.relax_ok, st.trials = None, False, 0
    st.restores += 1
    phi_s, D_s = w["f"] + nu * w["c"], w["adp"] - nu * w["c"]
    st.slope = D_s
    _line_search(be, st, xhat0, C, w["x"], w["u"], w["y"], w["dx"], w["du"], w["yq"], phi_s, D_s, nu,
                 alpha=C["GLOB_BACKTRACK"])


def _line_search(be, st, xhat0, C, x0, u0, y0, dx, du, yq, phi0, D, nu, alpha=None):
    """Backtracking from ``alpha`` (default: the second trial, 1/2) along ``(dx, du)`` from
    ``(x0, u0)``; the accepted point is initialised, else the start point and a failure."""
    alpha = C["GLOB_BACKTRACK"] if alpha is None else alpha
    while st.trials < int(C["GLOB_MAX_TRIALS"]):
        st.trials += 1
        xt, ut = x0 + alpha * dx, u0 + alpha * du
        phi = _merit(be, xhat0, xt, ut, nu)
        if _armijo(phi, phi0, alpha, D, C):
            y = {k: y0[k] + alpha * (yq[k] - y0[k]) for k in _MULT}
            _accept(be, st, xhat0, alpha, xt, ut, y, phi)
            return
        alpha *= C["GLOB_BACKTRACK"]
    be.init(xhat0, _guess(x0, u0, y0))      # the start point, its QP prepared again
    st.reason = "line_search"
    raise DopusError.of("diverged", f"globalised step: no step length down to {alpha / C['GLOB_BACKTRACK']:.1e} "
                        f"decreased the merit function (slope {D:.3e}, penalty {nu:.3e})")


def _accept(be, st, xhat0, alpha, x, u, y, phi, relaxed=False):
    be.init(xhat0, _guess(x, u, y))
    st.alpha, st.merit, st.relaxed = alpha, phi, relaxed
    st.iterations += 1
    st.history.append({"alpha": alpha, "penalty": st.penalty, "merit": phi, "slope": st.slope,
                       "trials": st.trials, "relaxed": relaxed, "restores": st.restores})


def _guess(x, u, y):
    from ..problem.ocp import Guess

    return Guess(x=np.array(x, float), u=np.array(u, float), **{k: np.array(v, float) for k, v in y.items()})


def init_globalised(be, st: GlobState, xhat0, guess=None, max_work: float = 0.0, max_iter: int = 100,
                    tol: Optional[float] = None) -> bool:
    """``init`` at the guess (its ``x`` and ``u``; the multipliers zero), then globalised steps
    until the KKT measure is at most ``tol``
    (True), or the iteration or work limit (``max_work`` > 0: work units from the init on)
    ends them (False, ``st.reason``). A failed step raises DopusError (the iterate prepared)."""
    from .. import settings as settings_mod

    tol = settings_mod.KKT_TOL_DEFAULT["double"] if tol is None else tol
    st.__init__()
    xhat0 = _xhat(be, xhat0, "init_globalised: xhat0")
    if not (tol > 0) or not (max_work >= 0) or int(max_iter) < 0:
        raise DopusError.of("invalid_argument", f"init_globalised: tol must be > 0, max_work >= 0 and max_iter >= 0, "
                            f"got {tol!r}, {max_work!r}, {max_iter!r}")
    # the primal guess only (the C entry takes x and u): zero multipliers
    be.init(xhat0, None if guess is None else _guess(guess.x, guess.u, {}))
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
