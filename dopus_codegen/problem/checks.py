"""Checks of a validated problem that name what is wrong before a solver runs.

- :func:`stage0_violations` / :func:`check_initial_state`: an initial state for which no
  control within its bounds satisfies the stage-0 path constraints makes every QP of the
  first iteration infeasible; the check names the rows (declaration, row, expression, value
  and bound) instead of a bare "QP is infeasible".
- :func:`describe_qp_row`: the row of an infeasible QP (any stage; the C runtime decodes it
  from the QP's infeasibility certificate) in the OCP's words.
- :func:`nonsmooth_terms` / :func:`warn_nonsmooth`: the method takes first and second
  derivatives of every function; ``fabs``, ``fmax``/``fmin``, ``if_else`` and comparisons,
  ``sign``, ``floor``, ``ceil``, ``fmod`` have kinks or jumps where those derivatives are
  wrong or undefined. They are reported as a warning naming the expression.
- :func:`float_range_problems` / :func:`check_float_range`: a build in single precision
  (``options(real="float")``) holds every number of the problem in a C ``float``; a
  constant of an expression, a weight, a bound or a parameter whose magnitude is below
  float's smallest (about 1.4e-45: it would become 0, and the compiler refuses such a
  literal) or above its largest (about 3.4e38) is named before anything is generated. A
  bound beyond the largest float is no bound (it becomes an infinity) and is not reported.
"""
from __future__ import annotations

import math
import warnings
from typing import List, Optional, Tuple

import casadi as ca
import numpy as np

from .. import interrupt
from .spec import OcpError

__all__ = ["NonSmoothWarning", "stage0_violations", "check_initial_state", "nonsmooth_terms", "warn_nonsmooth",
           "describe_qp_row", "outside_float", "float_range_problems", "check_float_range"]

#: Violations above this (absolute, and relative to the bound) count.
FEASIBILITY_TOL = 1e-7
_EXPR_CHARS = 60


class NonSmoothWarning(UserWarning):
    """A function of the problem is not twice continuously differentiable."""


def _short(expr) -> str:
    text = str(expr)
    return text if len(text) <= _EXPR_CHARS else text[:_EXPR_CHARS - 3] + "..."


def _spec(problem):
    return getattr(problem, "spec", problem)


def _path_rows(spec) -> List[Tuple[str, ca.SX, float, float]]:
    """(label, expression, lb, ub) of every stacked path-constraint row."""
    out = []
    for i, rows in enumerate(spec.constraints.path):
        n = rows.expr.size1()
        for r in range(n):
            label = f"path constraint {i}" + (f" row {r}" if n > 1 else "")
            out.append((label, rows.expr[r], float(rows.lb[r]), float(rows.ub[r])))
    return out


def _violation(v: float, lb: float, ub: float) -> float:
    return max(0.0, lb - v, v - ub)


def _tol(lb: float, ub: float) -> float:
    scale = max([1.0] + [abs(b) for b in (lb, ub) if math.isfinite(b)])
    return FEASIBILITY_TOL * scale


def stage0_violations(problem, x, p=None) -> List[str]:
    """The stage-0 path-constraint rows that no control within its bounds satisfies at the
    state ``x`` (parameters ``p``, default: the problem's), one text per row: ``path
    constraint 0 (x_0+x_1): 1.3 > ub 1``. Rows that depend on the controls are evaluated at
    the controls that minimise the summed violation (IPOPT over the control box)."""
    spec = _spec(problem)
    model = spec.model
    rows = _path_rows(spec)
    if not rows:
        return []
    x = np.asarray(x, dtype=float).reshape(-1)
    p = np.asarray(model.p_default if p is None else p, dtype=float).reshape(-1)
    g = ca.vertcat(*[r[1] for r in rows])
    lg = np.array([r[2] for r in rows])
    ug = np.array([r[3] for r in rows])
    xs, us, ps = model.x, model.u, model.p
    lbu = np.asarray(spec.constraints.lbu, dtype=float)
    ubu = np.asarray(spec.constraints.ubu, dtype=float)
    gfun = ca.Function("g0", [xs, us, ps], [g])
    nu = us.size1()
    depends_u = bool(nu) and ca.depends_on(g, us)
    u_best = np.clip(np.zeros(nu), lbu, ubu)
    if depends_u:
        u_best = _least_violating_control(gfun, x, p, lg, ug, lbu, ubu, u_best)
    values = np.array(gfun(x, u_best, p)).reshape(-1)
    out = []
    for (label, expr, lb, ub), v in zip(rows, values):
        if not math.isfinite(v):
            out.append(f"{label} ({_short(expr)}) is not finite ({v})")
        elif _violation(v, lb, ub) > _tol(lb, ub):
            side = f"< lb {lb:g}" if v < lb else f"> ub {ub:g}"
            how = "" if not (depends_u and ca.depends_on(expr, us)) else \
                " for the least-violating controls " + np.array2string(u_best, precision=4)
            out.append(f"{label} ({_short(expr)}) = {v:.6g} {side}{how}")
    return out


def _least_violating_control(gfun, x, p, lg, ug, lbu, ubu, u_start):
    """argmin over lbu <= u <= ubu of the summed violation of lg <= g(x, u, p) <= ug."""
    nu, ng = u_start.size, lg.size
    u = ca.SX.sym("u", nu)
    s = ca.SX.sym("s", ng)
    gv = gfun(ca.DM(x), u, ca.DM(p))
    nlp = {"x": ca.vertcat(u, s), "f": ca.sum1(s), "g": ca.vertcat(gv + s, gv - s)}
    big = 1e19
    lo = np.concatenate([np.where(np.isfinite(lg), lg, -big), np.full(ng, -big)])
    hi = np.concatenate([np.full(ng, big), np.where(np.isfinite(ug), ug, big)])
    solver = ca.nlpsol("stage0_feasibility", "ipopt", nlp,
                       {"print_time": False, "ipopt.print_level": 0, "ipopt.sb": "yes", "ipopt.tol": 1e-12,
                        "ipopt.max_iter": 200})
    lbx = np.concatenate([np.where(np.isfinite(lbu), lbu, -big), np.zeros(ng)])
    ubx = np.concatenate([np.where(np.isfinite(ubu), ubu, big), np.full(ng, big)])
    g0 = np.array(gfun(x, u_start, p)).reshape(-1)
    s0 = np.maximum(0.0, np.maximum(np.nan_to_num(lg - g0, neginf=0.0, posinf=0.0),
                                    np.nan_to_num(g0 - ug, neginf=0.0, posinf=0.0)))
    res = solver(x0=np.concatenate([u_start, s0]), lbx=lbx, ubx=ubx, lbg=lo, ubg=hi)
    interrupt.check()       # IPOPT ends a solve interrupted by Ctrl-C as a failed one
    ub = np.array(res["x"]).reshape(-1)[:nu]
    return np.clip(ub, lbu, ubu)


def check_initial_state(problem, x, what: str = "the initial state", p=None) -> None:
    """:class:`OcpError` naming the stage-0 rows that ``x`` violates for every control
    within its bounds (then no QP of the first iteration is feasible)."""
    spec = _spec(problem)
    x = np.asarray(x, dtype=float).reshape(-1)
    rows = stage0_violations(spec, x, p)
    if rows:
        raise OcpError(f"{spec.name}: {what} x = {np.array2string(x, precision=6)} violates the stage-0 "
                       f"path constraints (every QP is infeasible): {'; '.join(rows)}")


# --------------------------------------------------------------------------- smoothness
def _op_names():
    names = {}
    for attr, text in (("OP_FABS", "fabs"), ("OP_FMAX", "fmax"), ("OP_FMIN", "fmin"), ("OP_SIGN", "sign"),
                       ("OP_FLOOR", "floor"), ("OP_CEIL", "ceil"), ("OP_FMOD", "fmod"),
                       ("OP_REMAINDER", "remainder"), ("OP_COPYSIGN", "copysign"),
                       ("OP_LT", "a comparison (if_else)"), ("OP_LE", "a comparison (if_else)"), ("OP_EQ", "a comparison"),
                       ("OP_NE", "a comparison"),
                       ("OP_AND", "a logical operation"), ("OP_OR", "a logical operation")):
        if hasattr(ca, attr):
            names[int(getattr(ca, attr))] = text
    return names


_NONSMOOTH = _op_names()


def _nonsmooth_nodes(expr: ca.SX) -> List[Tuple[str, str]]:
    """(kind, expression) of the non-smooth nodes of an SX expression, in a deterministic
    order (depth-first from the outputs), each once."""
    if not isinstance(expr, ca.SX):
        return []
    found, seen = [], set()
    stack = [expr.nz[i] for i in reversed(range(expr.nnz()))]
    while stack:
        e = stack.pop()
        h = e.element_hash()
        if h in seen:
            continue
        seen.add(h)
        if e.is_symbolic() or e.is_constant():
            continue
        op = int(e.op())
        if op in _NONSMOOTH:
            found.append((_NONSMOOTH[op], _short(e)))
        for k in reversed(range(e.n_dep())):
            stack.append(e.dep(k))
    return found


def nonsmooth_terms(problem) -> List[Tuple[str, str, str]]:
    """(where, kind, expression) for every non-smooth operation in the problem's functions."""
    spec = _spec(problem)
    parts = [("dynamics", spec.model.xdot)]
    parts += [(f"stage cost term {i}", t) for i, t in enumerate(spec.cost.stage_terms)]
    parts += [(f"stage least squares {i}", t.residual) for i, t in enumerate(spec.cost.stage_least_squares)]
    parts += [(f"terminal cost term {i}", t) for i, t in enumerate(spec.cost.terminal_terms)]
    parts += [(f"terminal least squares {i}", t.residual) for i, t in enumerate(spec.cost.terminal_least_squares)]
    parts += [(f"path constraint {i}", r.expr) for i, r in enumerate(spec.constraints.path)]
    parts += [(f"terminal constraint {i}", r.expr) for i, r in enumerate(spec.constraints.terminal)]
    out = []
    for where, expr in parts:
        for kind, text in _nonsmooth_nodes(expr):
            out.append((where, kind, text))
    return out


def warn_nonsmooth(problem, limit: int = 3) -> Optional[str]:
    """Warn (:class:`NonSmoothWarning`) once per part of the problem that has non-smooth
    operations, naming up to ``limit`` of them; returns the text (None if smooth)."""
    spec = _spec(problem)
    by_part = {}
    for where, kind, text in nonsmooth_terms(spec):
        by_part.setdefault(where, []).append(f"{kind} '{text}'")
    texts = []
    for where, items in by_part.items():
        more = f" and {len(items) - limit} more" if len(items) > limit else ""
        msg = (f"{spec.name}: the {where} has non-smooth operations: {', '.join(items[:limit])}{more}; the method needs "
               "twice continuously differentiable functions (derivatives at a kink or jump are arbitrary)")
        warnings.warn(NonSmoothWarning(msg), stacklevel=2)
        texts.append(msg)
    return "\n".join(texts) if texts else None


# --------------------------------------------------------------------------- QP rows
def _terminal_rows(spec, equality: bool) -> List[Tuple[str, ca.SX, float, float]]:
    """(label, expression, lb, ub) of the stacked terminal rows with ``lb == ub``
    (``equality``) or ``lb < ub``, in declaration order."""
    out = []
    for i, rows in enumerate(spec.constraints.terminal):
        n = rows.expr.size1()
        for r in range(n):
            lb, ub = float(rows.lb[r]), float(rows.ub[r])
            if (lb == ub) == equality:
                label = f"terminal constraint {i}" + (f" row {r}" if n > 1 else "")
                out.append((label, rows.expr[r], lb, ub))
    return out


def describe_qp_row(problem, row: dict) -> str:
    """The row of an infeasible QP (``row``: stage, kind, index, side, bound, as
    ``Solver.qp_infeasible_row`` gives it) in the OCP's words: ``infeasible at stage 3: path
    constraint 0 ((x-p)) >= lb 0``; ``problem`` (a spec or a discretised problem, or None)
    supplies the names and expressions."""
    spec = None if problem is None else _spec(problem)
    k, kind, i, side, bound = row["stage"], row["kind"], row["index"], row["side"], row["bound"]
    where = f"stage {k}" if spec is None or k < spec.horizon.N else f"the terminal node (stage {k})"
    rel = {"lower": f">= lb {bound:g}", "upper": f"<= ub {bound:g}"}.get(side, f"lb > ub ({bound:g})")
    if kind in ("state", "control"):
        names = None if spec is None else (spec.model.state_names if kind == "state" else spec.model.control_names)
        what = f"{kind} {names[i] if names else i}"
    elif kind == "path" and spec is not None:
        label, expr, _, _ = _path_rows(spec)[i]
        what = f"{label} ({_short(expr)})"
    elif kind in ("terminal", "terminal_eq") and spec is not None:
        label, expr, lb, _ = _terminal_rows(spec, kind == "terminal_eq")[i]
        what = f"{label} ({_short(expr)})"
        if kind == "terminal_eq":
            rel = f"= {lb:g}"
    else:
        what = f"{kind.replace('_', ' ')} row {i}"
        if kind == "terminal_eq":
            rel = "= its value"
    return f"infeasible at {where}: {what} {rel}"


# --------------------------------------------------------------------------- float range
_FLT_MAX = float(np.finfo(np.float32).max)


def outside_float(v: float, infinite_ok: bool = False) -> Optional[str]:
    """Why the finite number ``v`` has no C ``float``, or None: ``"below"`` (not zero, but
    it rounds to zero in float) or ``"above"`` (beyond the largest float; None with
    ``infinite_ok``, where it is meant as no bound)."""
    v = float(v)
    if v == 0.0 or not math.isfinite(v):
        return None
    with np.errstate(over="ignore", under="ignore"):
        f = float(np.float32(v))
    if f == 0.0:
        return "below"
    if not math.isfinite(f):
        return None if infinite_ok else "above"
    return None


def _constants(expr) -> List[float]:
    """The numeric constants of the SX expression ``expr`` (in evaluation order)."""
    expr = ca.SX(expr)
    if expr.numel() == 0:
        return []
    f = ca.Function("constants", ca.symvar(expr), [expr])
    return [float(f.instruction_constant(k)) for k in range(f.n_instructions()) if f.instruction_id(k) == ca.OP_CONST]


def float_range_problems(problem) -> List[str]:
    """Every number of the problem (a spec or a discretised problem) that a float build
    cannot hold, named: ``"the constant 1e-50 in the model (ocp.dynamics) row 1"``."""
    spec = _spec(problem)
    out: List[str] = []

    def numbers(template: str, values, infinite_ok: bool = False):
        for v in np.asarray(values, dtype=float).reshape(-1):
            why = outside_float(v, infinite_ok)
            if why:
                out.append(template.format(f"{v:g}") + f" ({why} the range of float)")

    def expressions(what: str, expr) -> None:
        expr = ca.SX(expr)
        n = expr.size1() if expr.size2() == 1 else 1
        for r in range(n):
            row = expr[r] if n > 1 else expr
            numbers("the constant {} in " + what + (f" row {r}" if n > 1 else ""), _constants(row))

    m, c, k = spec.model, spec.cost, spec.constraints
    expressions("the model (ocp.dynamics)", m.xdot)
    numbers("the parameter value {} (ocp.parameter)", m.p_default)
    numbers("the interval dt {} (ocp.horizon)", [spec.horizon.dt])
    for i, term in enumerate(c.stage_terms):
        expressions(f"stage cost term {i}", term)
    for i, term in enumerate(c.terminal_terms):
        expressions(f"terminal cost term {i}", term)
    for kind, terms in (("stage", c.stage_least_squares), ("terminal", c.terminal_least_squares)):
        for i, ls in enumerate(terms):
            expressions(f"the residual of {kind} least-squares term {i}", ls.residual)
            numbers(f"the weight {{}} of {kind} least-squares term {i}", ls.weights)
    for name, values in (("state", (k.lbx, k.ubx)), ("control", (k.lbu, k.ubu))):
        numbers(f"the {name} bound {{}}", values, infinite_ok=True)
    for kind, blocks in (("path", k.path), ("terminal", k.terminal)):
        for i, rows in enumerate(blocks):
            expressions(f"{kind} constraint {i}", rows.expr)
            numbers(f"the bound {{}} of {kind} constraint {i}", (rows.lb, rows.ub), infinite_ok=True)
    return out


def check_float_range(problem) -> None:
    """:class:`OcpError` naming the numbers a float build cannot hold (:func:`float_range_problems`)."""
    bad = float_range_problems(problem)
    if bad:
        more = f"; and {len(bad) - 3} more" if len(bad) > 3 else ""
        raise OcpError("real float: " + "; ".join(bad[:3]) + more + f" (float holds magnitudes from "
                       f"{float(np.finfo(np.float32).smallest_subnormal):.2g} to {_FLT_MAX:.2g}); rescale the "
                       "problem or use real='double'")
