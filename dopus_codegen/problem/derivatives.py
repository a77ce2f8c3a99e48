"""The per-stage CasADi functions of docs/algorithm.md section 2 and the
:class:`Discretized` problem every later layer consumes.

All functions are SX functions with dense outputs; their names carry the problem
name (``<name>_stage_grad`` ...) and their inputs follow the order of the table in
algorithm.md section 2. ``build_functions`` is deterministic: the same OCP gives the
same functions and therefore the same generated C.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Callable, Optional

import casadi as ca
import numpy

from .discretize import StageModel, discretize
from .ocp import Guess, Ocp, OcpError, ScenarioSpec, casadi_message

__all__ = ["Discretized", "build_functions"]

# Common-subexpression elimination makes the generated C smaller; it is deterministic.
_FN_OPTS = {"cse": True}


@dataclass
class Discretized:
    """The multiple-shooting problem: sizes, bounds, defaults and the stage functions.

    Shapes: ``lbx, ubx (nx,)``, ``lbu, ubu (nu,)``, ``lg, ug (ng,)``, ``lr, ur (nr,)``
    (infinite entries allowed), ``p0 (N+1, np)``, ``x0 (nx,)``.
    """
    name: str
    N: int
    dt: float
    nx: int
    nu: int
    nw: int
    np: int
    ng: int
    nr: int
    ne: int
    lbx: numpy.ndarray
    ubx: numpy.ndarray
    lbu: numpy.ndarray
    ubu: numpy.ndarray
    lg: numpy.ndarray
    ug: numpy.ndarray
    lr: numpy.ndarray
    ur: numpy.ndarray
    p0: numpy.ndarray
    x0: numpy.ndarray
    initial_guess: Guess
    options: dict
    disturbance: Optional[Callable[[numpy.ndarray], numpy.ndarray]]
    scenario_spec: Optional[ScenarioSpec]
    state_names: list
    control_names: list
    parameter_names: list
    integrator: str
    stage_eval: ca.Function
    stage_grad: ca.Function
    stage_hess_exact: ca.Function
    stage_hess_gn: Optional[ca.Function]
    term_eval: ca.Function
    term_grad: ca.Function
    term_hess_exact: ca.Function
    term_hess_gn: ca.Function
    ode: ca.Function
    has_gn: bool
    weights: dict = field(default_factory=dict)   # {"W": stage LS weight, "WN": terminal}
    # Least-squares residuals (x, u, p) -> res and (x, p) -> res_N, None without them; for
    # checks and plots, not part of the generated code.
    stage_residual: Optional[ca.Function] = None
    term_residual: Optional[ca.Function] = None
    # Stage-cost part A_l of the stage Hessian, (x, u, p) -> A_l (algorithm.md sections 2
    # and 4 step 5): exact hess_w l; Gauss-Newton J' W J + hess_w l_extra (None without a
    # least-squares stage cost). Cheap: l is evaluated at the node, no integrator.
    stage_hess_cost_exact: Optional[ca.Function] = None
    stage_hess_cost_gn: Optional[ca.Function] = None
    cache: dict = field(default_factory=dict, repr=False, compare=False)  # e.g. offline solvers

    def stage_hess(self, kind: str) -> ca.Function:
        """``stage_hess_exact`` for ``"exact"``, ``stage_hess_gn`` for ``"gauss-newton"``."""
        if kind == "exact":
            return self.stage_hess_exact
        if kind in ("gauss-newton", "gn"):
            if self.stage_hess_gn is None:
                raise OcpError(f"{self.name}: hessian='gauss-newton' needs stage_least_squares")
            return self.stage_hess_gn
        raise ValueError(f"unknown Hessian kind {kind!r} (expected 'exact' or 'gauss-newton')")

    def stage_hess_cost(self, kind: str) -> ca.Function:
        """``stage_hess_cost_exact`` for ``"exact"``, ``stage_hess_cost_gn`` for
        ``"gauss-newton"``: ``(x, u, p) -> A_l``, the stage-cost part of ``stage_hess(kind)``'s A."""
        if kind == "exact":
            fun = self.stage_hess_cost_exact
        elif kind in ("gauss-newton", "gn"):
            if self.stage_hess_cost_gn is None:
                raise OcpError(f"{self.name}: hessian='gauss-newton' needs stage_least_squares")
            fun = self.stage_hess_cost_gn
        else:
            raise ValueError(f"unknown Hessian kind {kind!r} (expected 'exact' or 'gauss-newton')")
        if fun is None:
            raise OcpError(f"{self.name}: the problem was built without the stage-cost Hessian functions")
        return fun

    def term_hess(self, kind: str) -> ca.Function:
        """Terminal counterpart of :meth:`stage_hess`."""
        if kind == "exact":
            return self.term_hess_exact
        if kind in ("gauss-newton", "gn"):
            return self.term_hess_gn
        raise ValueError(f"unknown Hessian kind {kind!r} (expected 'exact' or 'gauss-newton')")

    @property
    def functions(self) -> list:
        """Every CasADi function of algorithm.md section 2, in table order (GN stage
        Hessians omitted when the OCP has no least-squares stage cost)."""
        fns = [self.stage_eval, self.stage_grad, self.stage_hess_exact, self.stage_hess_gn,
               self.stage_hess_cost_exact, self.stage_hess_cost_gn,
               self.term_eval, self.term_grad, self.term_hess_exact, self.term_hess_gn, self.ode]
        return [f for f in fns if f is not None]

    @property
    def p_default(self) -> numpy.ndarray:
        """Alias of ``p0`` (the per-node default parameters)."""
        return self.p0

    @property
    def lbw(self) -> numpy.ndarray:
        return numpy.concatenate([self.lbx, self.lbu])

    @property
    def ubw(self) -> numpy.ndarray:
        return numpy.concatenate([self.ubx, self.ubu])


def _d(e):
    return ca.densify(e)


def _stage_functions(name: str, m: StageModel):
    nx, ng = m.x.size1(), m.g.size1()
    lam = ca.SX.sym("lam_next", nx)
    mu_g = ca.SX.sym("mu_g", ng)
    x, u, p, w = m.x, m.u, m.p, m.w
    # L_k = l - lam_next' phi + mu_g' g  (algorithm.md section 1)
    Lk = m.l - ca.dot(lam, m.phi) + (ca.dot(mu_g, m.g) if ng else 0)
    Phi = ca.jacobian(m.phi, w)
    C = ca.jacobian(m.g, w) if ng else ca.SX(0, w.size1())
    gL = ca.gradient(Lk, w)
    A = ca.hessian(Lk, w)[0]
    ins = [x, u, p, lam, mu_g]
    in_names = ["x", "u", "p", "lam_next", "mu_g"]
    stage_eval = ca.Function(f"{name}_stage_eval", [x, u, p], [_d(m.phi), _d(m.l), _d(m.g)],
                             ["x", "u", "p"], ["phi", "l", "g"], _FN_OPTS)
    stage_grad = ca.Function(f"{name}_stage_grad", ins, [_d(gL), _d(m.phi), _d(m.l), _d(m.g)],
                             in_names, ["gL", "phi", "l", "g"], _FN_OPTS)
    stage_hess_exact = ca.Function(f"{name}_stage_hess_exact", ins, [_d(A), _d(Phi), _d(C)],
                                   in_names, ["A", "Phi", "C"], _FN_OPTS)
    # stage-cost part of A (algorithm.md section 4 step 5): l is evaluated at the node, so
    # this needs no integrator sensitivities
    cost_in, cost_in_names = [x, u, p], ["x", "u", "p"]
    stage_hess_cost_exact = ca.Function(f"{name}_stage_hess_cost_exact", cost_in,
                                        [_d(ca.hessian(m.l, w)[0])], cost_in_names, ["A_l"], _FN_OPTS)
    stage_hess_gn = stage_hess_cost_gn = None
    if m.has_stage_ls:
        J = ca.jacobian(m.res, w)
        # Gauss-Newton: J' W J + exact Hessian of the non least-squares part, no curvature
        # of dynamics or constraints (algorithm.md section 2).
        A_gn = ca.mtimes([J.T, ca.DM(m.W), J]) + ca.hessian(m.l_extra, w)[0]
        stage_hess_gn = ca.Function(f"{name}_stage_hess_gn", ins, [_d(A_gn), _d(Phi), _d(C)],
                                    in_names, ["A", "Phi", "C"], _FN_OPTS)
        # the same expression: A - A_l = 0 for Gauss-Newton
        stage_hess_cost_gn = ca.Function(f"{name}_stage_hess_cost_gn", cost_in, [_d(A_gn)],
                                         cost_in_names, ["A_l"], _FN_OPTS)
    return stage_eval, stage_grad, stage_hess_exact, stage_hess_gn, stage_hess_cost_exact, stage_hess_cost_gn


def _terminal_functions(name: str, m: StageModel):
    x, p = m.x, m.p
    nr, ne = m.r.size1(), m.r_eq.size1()
    mu_r = ca.SX.sym("mu_r", nr)
    nu = ca.SX.sym("nu", ne)
    LN = m.E + (ca.dot(mu_r, m.r) if nr else 0) + (ca.dot(nu, m.r_eq) if ne else 0)
    R = ca.jacobian(m.r, x) if nr else ca.SX(0, x.size1())
    Req = ca.jacobian(m.r_eq, x) if ne else ca.SX(0, x.size1())
    gL = ca.gradient(LN, x)
    A = ca.hessian(LN, x)[0]
    if m.resN.size1():
        JN = ca.jacobian(m.resN, x)
        A_gn = ca.mtimes([JN.T, ca.DM(m.WN), JN]) + ca.hessian(m.E_extra, x)[0]
    else:
        A_gn = ca.hessian(m.E_extra, x)[0]
    ins = [x, p, mu_r, nu]
    in_names = ["x", "p", "mu_r", "nu"]
    term_eval = ca.Function(f"{name}_term_eval", [x, p], [_d(m.E), _d(m.r), _d(m.r_eq)],
                            ["x", "p"], ["E", "r", "r_eq"], _FN_OPTS)
    term_grad = ca.Function(f"{name}_term_grad", ins, [_d(gL), _d(m.E), _d(m.r), _d(m.r_eq)],
                            in_names, ["gL", "E", "r", "r_eq"], _FN_OPTS)
    term_hess_exact = ca.Function(f"{name}_term_hess_exact", ins, [_d(A), _d(R), _d(Req)],
                                  in_names, ["A", "R", "R_eq"], _FN_OPTS)
    term_hess_gn = ca.Function(f"{name}_term_hess_gn", ins, [_d(A_gn), _d(R), _d(Req)],
                               in_names, ["A", "R", "R_eq"], _FN_OPTS)
    return term_eval, term_grad, term_hess_exact, term_hess_gn


def _scenario(ocp: Ocp, m: StageModel, ode: ca.Function, x0: numpy.ndarray) -> Optional[ScenarioSpec]:
    sc = ocp._scenario
    if sc is None:
        return None
    from .ocp import _as_sx  # the same conversion the validation used
    signals = {}
    for i, (sig, expr) in enumerate(sc["signals"].items()):
        e = _as_sx(expr, f"scenario signal '{sig}'")
        safe = re.sub(r"[^0-9A-Za-z_]", "_", sig)
        signals[sig] = ca.Function(f"{ocp.name}_signal_{i}_{safe}", [m.x, m.u, m.p], [_d(e)],
                                   ["x", "u", "p"], ["value"])
    if sc["plant"] is None:
        plant = ode
    else:
        e = _as_sx(sc["plant"], "scenario plant")
        plant = ca.Function(f"{ocp.name}_plant_ode", [m.x, m.u, m.p], [_d(e)], ["x", "u", "p"], ["xdot"])
    sx0 = x0.copy() if sc["x0"] is None else Ocp._full_vector(sc["x0"], x0.size, "scenario x0")
    return ScenarioSpec(duration=float(sc["duration"]), events=list(sc["events"]), signals=signals,
                        plant_ode=plant, x0=sx0)


def build_functions(ocp: Ocp) -> Discretized:
    """Validate ``ocp``, discretise it and build every function of algorithm.md section 2."""
    if not isinstance(ocp, Ocp):
        raise OcpError(f"build_functions: expected an Ocp, got {type(ocp).__name__}")
    m = discretize(ocp)
    name = ocp.name
    try:
        stage = _stage_functions(name, m)
        term = _terminal_functions(name, m)
        ode = ca.Function(f"{name}_ode", [m.x, m.u, m.p], [_d(m.xdot)], ["x", "u", "p"], ["xdot"], _FN_OPTS)
    except OcpError:
        raise
    except Exception as exc:  # noqa: BLE001 - CasADi failures on user expressions
        raise OcpError(f"{name}: cannot build the stage functions: {casadi_message(exc)}") from None
    nx, nu, np_ = m.x.size1(), m.u.size1(), m.p.size1()
    N = ocp.N
    x0 = ocp.x0_array(nx)
    gx, gu = ocp.guess_arrays(nx, nu, N, x0)
    p0 = numpy.zeros((N + 1, np_))
    col = 0
    for d in ocp._params:
        p0[:, col:col + d.size] = d.value
        col += d.size
    disc = Discretized(
        name=name, N=N, dt=ocp.dt, nx=nx, nu=nu, nw=nx + nu, np=np_, ng=m.g.size1(),
        nr=m.r.size1(), ne=m.r_eq.size1(),
        lbx=numpy.concatenate([d.lb for d in ocp._states]), ubx=numpy.concatenate([d.ub for d in ocp._states]),
        lbu=numpy.concatenate([d.lb for d in ocp._controls]), ubu=numpy.concatenate([d.ub for d in ocp._controls]),
        lg=m.lg.copy(), ug=m.ug.copy(), lr=m.lr.copy(), ur=m.ur.copy(), p0=p0, x0=x0,
        initial_guess=Guess(x=gx, u=gu), options=dict(ocp._options), disturbance=ocp._disturbance,
        scenario_spec=_scenario(ocp, m, ode, x0),
        state_names=Ocp._labels(ocp._states), control_names=Ocp._labels(ocp._controls),
        parameter_names=Ocp._labels(ocp._params), integrator=ocp.integrator.describe(),
        stage_eval=stage[0], stage_grad=stage[1], stage_hess_exact=stage[2], stage_hess_gn=stage[3],
        term_eval=term[0], term_grad=term[1], term_hess_exact=term[2], term_hess_gn=term[3],
        ode=ode, has_gn=stage[3] is not None, weights={"W": m.W.copy(), "WN": m.WN.copy()},
        stage_hess_cost_exact=stage[4], stage_hess_cost_gn=stage[5],
    )
    if m.res.size1():
        disc.stage_residual = ca.Function(f"{name}_stage_residual", [m.x, m.u, m.p], [_d(m.res)],
                                          ["x", "u", "p"], ["res"])
    if m.resN.size1():
        disc.term_residual = ca.Function(f"{name}_term_residual", [m.x, m.p], [_d(m.resN)],
                                         ["x", "p"], ["res"])
    _check_finite_at_guess(disc)
    return disc


def _check_finite_at_guess(disc: Discretized) -> None:
    """A model that is not even finite at the initial guess is a user error, said here."""
    g = disc.initial_guess
    for k in range(disc.N):
        out = disc.stage_eval(g.x[k], g.u[k], disc.p0[k])
        for what, v in zip(("phi", "l", "g"), out):
            if not numpy.all(numpy.isfinite(numpy.array(v))):
                raise OcpError(f"{disc.name}: stage {k} of the initial guess gives non-finite {what} "
                               f"(check the dynamics, cost and path constraints)")
    for what, v in zip(("E", "r", "r_eq"), disc.term_eval(g.x[disc.N], disc.p0[disc.N])):
        if not numpy.all(numpy.isfinite(numpy.array(v))):
            raise OcpError(f"{disc.name}: the terminal node of the initial guess gives non-finite {what}")
