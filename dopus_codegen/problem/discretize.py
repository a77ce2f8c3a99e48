"""Direct multiple shooting: from a validated problem (:class:`~.spec.OcpSpec`, what
``Ocp.validate()`` returns) to the symbolic per-stage pieces ``phi_k, l_k, g_k`` and the
terminal ``E, r, r_eq``.

Everything here is SX (the integrator's substep map may be an MX function), built in
declaration order so that the same OCP always yields the same expressions (and hence
byte-identical generated C). The interval map ``phi`` is the substep map applied
``n_substeps`` times; derivatives.py builds it and its derivatives from the substep.
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np

from .ocp import OcpError, casadi_message
from .spec import OcpSpec

__all__ = ["StageModel", "discretize"]


@dataclass
class StageModel:
    """Symbolic stage and terminal expressions of one OCP (docs/algorithm.md section 1)."""
    x: ca.SX
    u: ca.SX
    p: ca.SX
    w: ca.SX
    xdot: ca.SX
    substep: ca.Function   # (x, u, p) -> x+ of one integrator substep
    n_substeps: int        # phi = substep applied n_substeps times
    l: ca.SX              # full stage cost 0.5 res' W res + l_extra
    res: ca.SX            # stacked stage least-squares residual (0 rows if none)
    W: np.ndarray
    l_extra: ca.SX
    g: ca.SX
    lg: np.ndarray
    ug: np.ndarray
    E: ca.SX
    resN: ca.SX
    WN: np.ndarray
    E_extra: ca.SX
    r: ca.SX              # terminal inequality rows
    lr: np.ndarray
    ur: np.ndarray
    r_eq: ca.SX           # terminal equality rows, r_eq = r_row - value
    has_stage_ls: bool
    soft_g: np.ndarray = None   # (4, ng) soft weights of the path rows (zeros: hard)
    soft_r: np.ndarray = None   # (4, nr) soft weights of the terminal inequality rows


def _stack(items, what: str):
    """Vertical stack of (expr, lb, ub) triples."""
    items = [(b.expr, b.lb, b.ub) for b in items]
    if not items:
        return ca.SX(0, 1), np.zeros(0), np.zeros(0)
    try:
        expr = ca.vertcat(*[e for e, _, _ in items])
    except Exception as exc:  # noqa: BLE001 - CasADi errors on user expressions
        raise OcpError(f"{what}: {casadi_message(exc)}") from None
    return expr, np.concatenate([a for _, a, _ in items]), np.concatenate([b for _, _, b in items])


def _least_squares(items, what: str):
    """Stacked residual, block-diagonal weight and the cost 0.5 res' W res."""
    items = [(t.residual, t.weights) for t in items]
    if not items:
        return ca.SX(0, 1), np.zeros((0, 0)), ca.SX(0)
    res = ca.vertcat(*[r for r, _ in items])
    n = res.size1()
    W = np.zeros((n, n))
    i = 0
    for r, Wi in items:
        m = r.size1()
        W[i:i + m, i:i + m] = Wi
        i += m
    try:
        cost = 0.5 * ca.dot(res, ca.mtimes(ca.DM(W), res))
    except Exception as exc:  # noqa: BLE001
        raise OcpError(f"{what}: {casadi_message(exc)}") from None
    return res, W, cost


def _sum(items) -> ca.SX:
    out = ca.SX(0)
    for c in items:
        out = out + c
    return out


def discretize(spec: OcpSpec) -> StageModel:
    """The symbolic multiple-shooting pieces of a validated problem (no validation here:
    ``spec`` comes from ``Ocp.validate()``)."""
    if not isinstance(spec, OcpSpec):
        raise OcpError(f"discretize: expected the OcpSpec of Ocp.validate(), got {type(spec).__name__}")
    model, cost, con = spec.model, spec.cost, spec.constraints
    integrator = model.integrator
    x, u, p = model.x, model.u, model.p
    w = ca.vertcat(x, u)
    xdot = model.xdot
    try:
        ode = ca.Function("ode_tmp", [x, u, p], [xdot])
        substep = integrator.substep_function(f"{spec.name}_substep", ode, x, u, p, spec.horizon.dt)
    except OcpError:
        raise
    except Exception as exc:  # noqa: BLE001
        raise OcpError(f"dynamics: cannot discretise with {integrator.describe()}: {casadi_message(exc)}") from None
    if not isinstance(substep, ca.Function) or substep.n_in() != 3 or substep.n_out() != 1:
        raise OcpError(f"dynamics: integrator {integrator.describe()} must give a function (x, u, p) -> x+")
    if substep.size_out(0) != (x.size1(), 1):
        raise OcpError(f"dynamics: integrator {integrator.describe()} returned shape "
                       f"{substep.size_out(0)}, expected ({x.size1()}, 1)")
    n_substeps = int(getattr(integrator, "substeps", 1))

    res, W, l_ls = _least_squares(cost.stage_least_squares, "stage least squares")
    l_extra = _sum(cost.stage_terms)
    l = l_ls + l_extra
    g, lg, ug = _stack(con.path, "path constraints")
    soft_g = np.hstack([b.soft_weights() for b in con.path]) if con.path else np.zeros((4, 0))

    resN, WN, E_ls = _least_squares(cost.terminal_least_squares, "terminal least squares")
    E_extra = _sum(cost.terminal_terms)
    E = E_ls + E_extra

    rows, lbs, ubs = _stack(con.terminal, "terminal constraints")
    is_eq = con.terminal_equality
    ineq = np.flatnonzero(~is_eq)
    eq = np.flatnonzero(is_eq)
    r = rows[ineq.tolist()] if ineq.size else ca.SX(0, 1)
    r_eq = rows[eq.tolist()] - ca.DM(lbs[eq]) if eq.size else ca.SX(0, 1)
    soft_rows = np.hstack([b.soft_weights() for b in con.terminal]) if con.terminal else np.zeros((4, 0))

    return StageModel(x=x, u=u, p=p, w=w, xdot=xdot, substep=substep, n_substeps=n_substeps, l=l, res=res, W=W, l_extra=l_extra,
                      g=g, lg=lg, ug=ug, E=E, resN=resN, WN=WN, E_extra=E_extra,
                      r=r, lr=lbs[ineq], ur=ubs[ineq], r_eq=r_eq,
                      has_stage_ls=cost.has_stage_least_squares, soft_g=soft_g, soft_r=soft_rows[:, ineq])
