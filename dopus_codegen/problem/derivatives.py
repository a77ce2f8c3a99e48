"""The per-stage CasADi functions of docs/algorithm.md section 2 and the
:class:`Discretized` problem every later layer consumes.

The node functions (cost, constraints, terminal) are SX functions; the stage functions
that involve the integrator are MX functions that iterate one substep and its derivative
kernels (:mod:`.sensitivities`). All outputs are dense; the names carry the problem
name (``<name>_stage_grad`` ...) and their inputs follow the order of the table in
algorithm.md section 2. ``build_functions`` is deterministic: the same OCP gives the
same functions and therefore the same generated C.

A :class:`Discretized` is immutable and made of four parts: ``spec`` (the validated
:class:`~.spec.OcpSpec` it was built from, which also holds the options), ``data``
(:class:`ProblemData`: sizes, bounds, defaults, names), ``functions``
(:class:`StageFunctions`) and ``scenario`` (:class:`Scenario`: what the studies need
beyond the OCP). Caches of derived objects (offline solvers) are owned by the modules
that build them, never by the problem.
"""
from __future__ import annotations

import re
import types
from dataclasses import dataclass
from operator import attrgetter
from typing import Callable, Iterator, Mapping, Optional, Tuple, Union

import casadi as ca
import numpy

from . import sensitivities
from .discretize import StageModel, discretize
from .ocp import Guess, Ocp, OcpError, ScenarioSpec, casadi_message
from .spec import OcpSpec, readonly

__all__ = ["Discretized", "ProblemData", "StageFunctions", "Scenario", "build_functions", "cost_hessian_constant"]

# Common-subexpression elimination makes the generated C smaller; it is deterministic.
_FN_OPTS = {"cse": True}

_KINDS = "(expected 'exact' or 'gauss-newton')"


def cost_hessian_constant(exact: ca.Function, gn: Optional[ca.Function] = None) -> bool:
    """True when the stage-cost Hessian A_l is one constant matrix whatever the Hessian in
    use: ``stage_hess_cost_exact`` (and ``stage_hess_cost_gn`` when there is one) depend on
    no input (a quadratic stage cost, e.g. least squares with outputs linear in x, u; no
    parameter in it) and give the same finite values. Step 5 of prepare then keeps the
    blocks as they are: each Ht is reg(A_dyn + A_l) already (docs/algorithm.md section 4)."""
    values = []
    for fun in (exact, gn):
        if fun is None:
            continue
        for i in range(fun.n_in()):
            if fun.sparsity_in(i).nnz() > 0 and any(fun.which_depends(fun.name_in(i), [fun.name_out(0)], 1, False)):
                return False
        out = fun.call([ca.DM.zeros(fun.sparsity_in(i)) for i in range(fun.n_in())])[0]
        values.append([float(v) for v in ca.densify(ca.DM(out)).nonzeros()])
    return bool(values) and all(all(numpy.isfinite(vs)) and vs == values[0] for vs in values)


@dataclass(frozen=True)
class ProblemData:
    """The numbers of the multiple-shooting problem (arrays read-only).

    Shapes: ``lbx, ubx (nx,)``, ``lbu, ubu (nu,)``, ``lg, ug (ng,)``, ``lr, ur (nr,)``
    (infinite entries allowed), ``p0 (N+1, np)``, ``x0 (nx,)``, ``guess_x (N+1, nx)``,
    ``guess_u (N, nu)`` (the declared cold guess), ``W``/``WN``: the stacked stage and
    terminal least-squares weights (``(0, 0)`` without them). ``integrator``: its
    description, e.g. ``"RK4(substeps=2)"``.
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
    guess_x: numpy.ndarray
    guess_u: numpy.ndarray
    state_names: Tuple[str, ...]
    control_names: Tuple[str, ...]
    parameter_names: Tuple[str, ...]
    integrator: str
    W: numpy.ndarray
    WN: numpy.ndarray
    #: soft weights ``(4, n)``, rows ``(l1 lower, l1 upper, l2 lower, l2 upper)``, zeros on
    #: hard sides: state bounds (nodes 1..N), path rows, terminal inequality rows
    soft_x: numpy.ndarray = None
    soft_g: numpy.ndarray = None
    soft_r: numpy.ndarray = None
    #: path-row bounds per stage ``(N, ng)``: the declared ones where a row holds, infinite
    #: where it is absent (``path_constraint(stages=...)``); None: ``lg``/``ug`` at every stage
    lg_stage: numpy.ndarray = None
    ug_stage: numpy.ndarray = None

    def path_bounds(self) -> tuple:
        """``(lg, ug)`` per stage, ``(N, ng)`` each."""
        if self.lg_stage is None:
            return (numpy.tile(numpy.asarray(self.lg, float).reshape(1, -1), (self.N, 1)),
                    numpy.tile(numpy.asarray(self.ug, float).reshape(1, -1), (self.N, 1)))
        return numpy.asarray(self.lg_stage, float), numpy.asarray(self.ug_stage, float)

    @property
    def has_soft(self) -> bool:
        """True when some row has a soft side."""
        return any(a is not None and bool(numpy.any(a > 0)) for a in (self.soft_x, self.soft_g, self.soft_r))

    @property
    def always_feasible(self) -> bool:
        """True when every row that depends on the state is soft on each of its finite
        sides (state bounds, path rows, terminal rows; no terminal equality row): the QP
        is then feasible for every finite measurement (control bounds are hard and always
        satisfiable on their own). A path row that involves only the controls does not
        depend on the state, but it is counted here as well (a conservative answer)."""
        def all_soft(lo, up, w):
            lo, up = numpy.asarray(lo, float), numpy.asarray(up, float)
            if lo.size == 0:
                return True
            w = numpy.zeros((4, lo.size)) if w is None else numpy.asarray(w)
            ok_lo = ~numpy.isfinite(lo) | (w[0] > 0) | (w[2] > 0)
            ok_up = ~numpy.isfinite(up) | (w[1] > 0) | (w[3] > 0)
            return bool(numpy.all(ok_lo & ok_up))
        if self.ne > 0:
            return False
        return (all_soft(self.lbx, self.ubx, self.soft_x) and all_soft(self.lg, self.ug, self.soft_g)
                and all_soft(self.lr, self.ur, self.soft_r))

    def soft_stage(self) -> numpy.ndarray:
        """The ``(4, nw + ng)`` soft weights of the rows of one stage (state bounds, control
        bounds (hard), path rows), in the row order of the QP (dopus_qp.h)."""
        sx = numpy.zeros((4, self.nx)) if self.soft_x is None else self.soft_x
        sg = numpy.zeros((4, self.ng)) if self.soft_g is None else self.soft_g
        return numpy.hstack([sx, numpy.zeros((4, self.nu)), sg])

    def soft_terminal(self) -> numpy.ndarray:
        """The ``(4, nx + nr)`` soft weights of the terminal rows (x_N bounds, then r)."""
        sx = numpy.zeros((4, self.nx)) if self.soft_x is None else self.soft_x
        sr = numpy.zeros((4, self.nr)) if self.soft_r is None else self.soft_r
        return numpy.hstack([sx, sr])

    @property
    def initial_guess(self) -> Guess:
        """The declared guess as a new :class:`Guess` (its arrays are read-only)."""
        return Guess(x=self.guess_x, u=self.guess_u)

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


@dataclass(frozen=True)
class StageFunctions:
    """Every CasADi function of algorithm.md section 2 (``name`` is the problem's).

    ``stage_hess_gn``/``stage_hess_cost_gn`` are None without a least-squares stage cost.
    ``stage_hess_cost_*``: the stage-cost part A_l of the stage Hessian, ``(x, u, p) ->
    A_l`` (algorithm.md sections 2 and 4 step 5): exact ``hess_w l``; Gauss-Newton ``J' W J
    + hess_w l_extra``; cheap, ``l`` is evaluated at the node, no integrator.
    ``stage_residual (x, u, p) -> res`` and ``term_residual (x, p) -> res_N`` are the
    least-squares residuals (None without them), for checks and plots, not generated.
    Iterating yields the functions of the table in its order (absent ones skipped).
    """
    name: str
    stage_eval: ca.Function
    stage_grad: ca.Function
    stage_hess_exact: ca.Function
    stage_hess_gn: Optional[ca.Function]
    stage_hess_cost_exact: ca.Function
    stage_hess_cost_gn: Optional[ca.Function]
    term_eval: ca.Function
    term_grad: ca.Function
    term_hess_exact: ca.Function
    term_hess_gn: ca.Function
    ode: ca.Function
    stage_residual: Optional[ca.Function] = None
    term_residual: Optional[ca.Function] = None
    #: ``stage_grad`` and ``stage_hess_exact`` in one function, ``(x, u, p, lam_next, mu_g)
    #: -> (gL, phi, l, g, A, Phi, C)``, built from the same graph so that the generated code
    #: shares what the two compute in common (the forward pass of the interval, the
    #: gradient's reverse pass); the runtime calls it where a stage needs both in the same
    #: step. None: the generator composes it from the two.
    stage_grad_hess_exact: Optional[ca.Function] = None
    #: ``stage_grad`` and ``stage_hess_gn`` in one function, ``(x, u, p, lam_next, mu_g) ->
    #: (gL, phi, l, g, A, Phi, C)`` with the Gauss-Newton ``A``, from the same graph (the
    #: interval's forward pass once); None without a least-squares stage cost, or where the
    #: two share no graph (the generator then composes it from the two).
    stage_grad_hess_gn: Optional[ca.Function] = None

    def __iter__(self) -> Iterator[ca.Function]:
        fns = [self.stage_eval, self.stage_grad, self.stage_hess_exact, self.stage_hess_gn,
               self.stage_hess_cost_exact, self.stage_hess_cost_gn,
               self.term_eval, self.term_grad, self.term_hess_exact, self.term_hess_gn, self.ode]
        return iter([f for f in fns if f is not None])

    @property
    def has_gn(self) -> bool:
        """True when the Gauss-Newton stage Hessian exists."""
        return self.stage_hess_gn is not None

    def _of_kind(self, kind: str, exact: ca.Function, gn: Optional[ca.Function]) -> ca.Function:
        """``exact`` for ``"exact"``, ``gn`` for ``"gauss-newton"`` (an OcpError when there
        is none: no least-squares stage cost)."""
        if kind == "exact":
            return exact
        if kind == "gauss-newton":
            if gn is None:
                raise OcpError(f"{self.name}: hessian='gauss-newton' needs stage_least_squares")
            return gn
        raise ValueError(f"unknown Hessian kind {kind!r} {_KINDS}")

    def stage_hess(self, kind: str) -> ca.Function:
        """``stage_hess_exact`` for ``"exact"``, ``stage_hess_gn`` for ``"gauss-newton"``."""
        return self._of_kind(kind, self.stage_hess_exact, self.stage_hess_gn)

    def stage_hess_cost(self, kind: str) -> ca.Function:
        """``stage_hess_cost_exact`` for ``"exact"``, ``stage_hess_cost_gn`` for
        ``"gauss-newton"``: ``(x, u, p) -> A_l``, the stage-cost part of ``stage_hess(kind)``'s A."""
        return self._of_kind(kind, self.stage_hess_cost_exact, self.stage_hess_cost_gn)

    def term_hess(self, kind: str) -> ca.Function:
        """Terminal counterpart of :meth:`stage_hess` (the Gauss-Newton form always exists)."""
        return self._of_kind(kind, self.term_hess_exact, self.term_hess_gn)


@dataclass(frozen=True)
class Scenario:
    """What the studies use beyond the OCP: the ``disturbance`` state map of the
    warm-start convergence study (None if not declared) and the closed-loop scenario of
    ``dopus-gen sil`` (None if not declared)."""
    disturbance: Optional[Callable[[numpy.ndarray], numpy.ndarray]]
    closed_loop: Optional[ScenarioSpec]


@dataclass(frozen=True, eq=False)
class Discretized:
    """The multiple-shooting problem: the validated spec, its data, its stage functions
    and its scenario (see the module docstring).

    For brevity every field of :class:`ProblemData` and :class:`StageFunctions` is also a
    read-only attribute of the problem (``disc.N`` is ``disc.data.N``, ``disc.stage_grad``
    is ``disc.functions.stage_grad``), as are ``initial_guess``, ``has_gn``,
    ``disturbance``, ``scenario_spec`` (``scenario.closed_loop``) and the Hessian selectors.
    """
    spec: OcpSpec
    data: ProblemData
    functions: StageFunctions
    scenario: Scenario
    #: with a declared scaling (``Ocp.scaling``, ``scale=``): its numbers and the problem in the
    #: solver's variables (docs/algorithm.md section 16), which the backends and the generated C
    #: solve; their API converts at the boundary. None: the problem is solved as declared.
    scaling: Optional[object] = None
    scaled: Optional["Discretized"] = None

    @property
    def solver_problem(self) -> "Discretized":
        """The problem the solver works with: ``scaled``, or the problem itself."""
        return self if self.scaled is None else self.scaled

    @property
    def options(self) -> Mapping[str, object]:
        """The declared solver options, a read-only mapping (``spec.options``)."""
        return types.MappingProxyType(self.spec.options.as_dict())

    @property
    def initial_guess(self) -> Guess:
        return self.data.initial_guess

    @property
    def state_names(self) -> list:
        return list(self.data.state_names)

    @property
    def control_names(self) -> list:
        return list(self.data.control_names)

    @property
    def parameter_names(self) -> list:
        return list(self.data.parameter_names)

    @property
    def disturbance(self) -> Optional[Callable[[numpy.ndarray], numpy.ndarray]]:
        return self.scenario.disturbance

    @property
    def scenario_spec(self) -> Optional[ScenarioSpec]:
        """``scenario.closed_loop``."""
        return self.scenario.closed_loop

    @property
    def time_varying_parameters(self) -> bool:
        """A parameter of the OCP declares a trajectory (``Ocp.parameter(trajectory=...)``)."""
        tr = getattr(self.spec.model, "p_trajectory", None)
        return bool(tr is not None and tr.time_varying)

    def parameters_at(self, t: float) -> numpy.ndarray:
        """The parameter vector at time ``t`` seconds, ``(np,)`` (the default when constant)."""
        tr = getattr(self.spec.model, "p_trajectory", None)
        if tr is None:
            return numpy.array(self.spec.model.p_default, dtype=float)
        return tr.at(t)

    def parameter_horizon(self, t0: float) -> numpy.ndarray:
        """``(N+1, np)``: the parameters of the horizon at time ``t0`` (node k at ``t0 + k dt``)."""
        return numpy.array([self.parameters_at(t0 + k * self.dt) for k in range(self.N + 1)],
                           dtype=float).reshape(self.N + 1, self.np)

    def stage_hess(self, kind: str) -> ca.Function:
        return self.functions.stage_hess(kind)

    def stage_hess_cost(self, kind: str) -> ca.Function:
        return self.functions.stage_hess_cost(kind)

    def term_hess(self, kind: str) -> ca.Function:
        return self.functions.term_hess(kind)


def _shortcuts(part: str, names) -> None:
    for n in names:
        if not hasattr(Discretized, n):
            setattr(Discretized, n, property(attrgetter(f"{part}.{n}"), doc=f"``{part}.{n}``"))


_shortcuts("data", ("name", "N", "dt", "nx", "nu", "nw", "np", "ng", "nr", "ne", "lbx", "ubx", "lbu",
                    "ubu", "lg", "ug", "lr", "ur", "p0", "x0", "p_default", "lbw", "ubw", "integrator",
                    "soft_x", "soft_g", "soft_r", "has_soft", "always_feasible", "soft_stage", "soft_terminal"))
_shortcuts("functions", ("stage_eval", "stage_grad", "stage_hess_exact", "stage_hess_gn",
                         "stage_hess_cost_exact", "stage_hess_cost_gn", "term_eval", "term_grad",
                         "term_hess_exact", "term_hess_gn", "ode", "stage_residual", "term_residual",
                         "stage_grad_hess_exact", "stage_grad_hess_gn", "has_gn"))


def _d(e):
    return ca.densify(e)


_FUSED_OUT = ["gL", "phi", "l", "g", "A", "Phi", "C"]


def _fused(name: str, ins, in_names, grad_outs, hess_outs, opts=None, kind="exact") -> ca.Function:
    """``stage_grad_hess_exact`` (``stage_grad_hess_gn``): the outputs of ``stage_grad`` and
    ``stage_hess_exact`` (``stage_hess_gn``) as one function of the same expressions (see
    :class:`StageFunctions`)."""
    return ca.Function(f"{name}_stage_grad_hess_{kind}", ins, list(grad_outs) + list(hess_outs), in_names,
                       _FUSED_OUT, *([opts] if opts else []))


def _same_algorithm(f: ca.Function, g: ca.Function) -> bool:
    """True when the SX functions ``f`` and ``g`` compute the same outputs by the same
    algorithm (names aside), so one of them can stand for both in the generated code."""
    def key(fun):
        args = fun.sx_in()
        return ca.Function("same", args, fun.call(args), _FN_OPTS).serialize()
    return (f.n_in() == g.n_in() and f.n_out() == g.n_out()
            and all(f.sparsity_in(i) == g.sparsity_in(i) for i in range(f.n_in()))
            and key(f) == key(g))


def _stage_functions_unrolled(name: str, m: StageModel, phi: ca.SX):
    """The stage functions as single SX expressions of the unrolled interval map ``phi``
    (every substep inlined, derivatives by CasADi's SX differentiation with common
    subexpressions shared across substeps and directions): the fastest code for small
    models, but its size grows with the substeps and, for the Hessian, with nw times the
    model."""
    nx, ng = m.x.size1(), m.g.size1()
    lam = ca.SX.sym("lam_next", nx)
    mu_g = ca.SX.sym("mu_g", ng)
    x, u, p, w = m.x, m.u, m.p, m.w
    # L_k = l - lam_next' phi + mu_g' g  (algorithm.md section 1)
    Lk = m.l - ca.dot(lam, phi) + (ca.dot(mu_g, m.g) if ng else 0)
    Phi = ca.jacobian(phi, w)
    C = ca.jacobian(m.g, w) if ng else ca.SX(0, w.size1())
    gL = ca.gradient(Lk, w)
    A = ca.hessian(Lk, w)[0]
    ins = [x, u, p, lam, mu_g]
    in_names = ["x", "u", "p", "lam_next", "mu_g"]
    stage_eval = ca.Function(f"{name}_stage_eval", [x, u, p], [_d(phi), _d(m.l), _d(m.g)],
                             ["x", "u", "p"], ["phi", "l", "g"], _FN_OPTS)
    stage_grad = ca.Function(f"{name}_stage_grad", ins, [_d(gL), _d(phi), _d(m.l), _d(m.g)],
                             in_names, ["gL", "phi", "l", "g"], _FN_OPTS)
    stage_hess_exact = ca.Function(f"{name}_stage_hess_exact", ins, [_d(A), _d(Phi), _d(C)],
                                   in_names, ["A", "Phi", "C"], _FN_OPTS)
    fused = _fused(name, ins, in_names, [_d(gL), _d(phi), _d(m.l), _d(m.g)], [_d(A), _d(Phi), _d(C)], _FN_OPTS)
    stage_hess_cost_exact, stage_hess_cost_gn, A_gn = _stage_cost_hessians(name, m)
    stage_hess_gn = fused_gn = None
    if A_gn is not None:
        stage_hess_gn = ca.Function(f"{name}_stage_hess_gn", ins, [_d(A_gn), _d(Phi), _d(C)],
                                    in_names, ["A", "Phi", "C"], _FN_OPTS)
        fused_gn = _fused(name, ins, in_names, [_d(gL), _d(phi), _d(m.l), _d(m.g)], [_d(A_gn), _d(Phi), _d(C)],
                          _FN_OPTS, "gn")
    return (stage_eval, stage_grad, stage_hess_exact, stage_hess_gn, stage_hess_cost_exact, stage_hess_cost_gn,
            fused, fused_gn)


def _stage_cost_hessians(name: str, m: StageModel) -> tuple:
    """``(stage_hess_cost_exact, stage_hess_cost_gn, A_gn)``: the stage-cost part of A
    (algorithm.md section 4 step 5), exact and Gauss-Newton, and the SX expression of the
    Gauss-Newton A (``None`` twice without a least-squares stage cost). l is evaluated at
    the node, so this needs no integrator sensitivities."""
    x, u, p, w = m.x, m.u, m.p, m.w
    cost_in, cost_in_names = [x, u, p], ["x", "u", "p"]
    exact = ca.Function(f"{name}_stage_hess_cost_exact", cost_in, [_d(ca.hessian(m.l, w)[0])], cost_in_names,
                        ["A_l"], _FN_OPTS)
    if not m.has_stage_ls:
        return exact, None, None
    J = ca.jacobian(m.res, w)
    # Gauss-Newton: J' W J + exact Hessian of the non least-squares part, no curvature of
    # dynamics or constraints (algorithm.md section 2).
    A_gn = ca.mtimes([J.T, ca.DM(m.W), J]) + ca.hessian(m.l_extra, w)[0]
    # the same expression: A - A_l = 0 for Gauss-Newton
    gn = ca.Function(f"{name}_stage_hess_cost_gn", cost_in, [_d(A_gn)], cost_in_names, ["A_l"], _FN_OPTS)
    return exact, gn, A_gn


def _node_parts(name: str, m: StageModel) -> types.SimpleNamespace:
    """What every form of the stage functions shares: the sizes, the node part of L_k
    (algorithm.md section 1: ``Ln = l + mu_g' g``), the path-constraint Jacobian ``C``, the
    SX node functions (``node_eval``: l, g; ``node_hess``: the Hessian of Ln, C) and the MX
    inputs ``(x, u, p, lam_next, mu_g)`` of the stage functions."""
    nx, nu, ng = m.x.size1(), m.u.size1(), m.g.size1()
    nw, np_ = nx + nu, m.p.size1()
    x, u, p, w = m.x, m.u, m.p, m.w
    mu_g_sx = ca.SX.sym("mu_g", ng)
    Ln = m.l + (ca.dot(mu_g_sx, m.g) if ng else 0)
    C_sx = ca.jacobian(m.g, w) if ng else ca.SX(0, nw)
    node_in, node_names = [x, u, p, mu_g_sx], ["x", "u", "p", "mu_g"]
    node_eval = ca.Function(f"{name}_node_eval", [x, u, p], [_d(m.l), _d(m.g)], ["x", "u", "p"],
                            ["l", "g"], _FN_OPTS)
    node_hess = ca.Function(f"{name}_node_hess", node_in, [_d(ca.hessian(Ln, w)[0]), _d(C_sx)], node_names,
                            ["An", "C"], _FN_OPTS)
    mx = (ca.MX.sym("x", nx), ca.MX.sym("u", nu), ca.MX.sym("p", np_), ca.MX.sym("lam_next", nx),
          ca.MX.sym("mu_g", ng))
    return types.SimpleNamespace(nx=nx, nu=nu, ng=ng, nw=nw, np_=np_, Ln=Ln, C_sx=C_sx, node_in=node_in,
                                 node_names=node_names, node_eval=node_eval, node_hess=node_hess, mx=mx,
                                 in_names=["x", "u", "p", "lam_next", "mu_g"])


def _stage_functions(name: str, m: StageModel, directions="auto"):
    """The stage functions of algorithm.md section 2 as MX functions over SX kernels.

    The cost ``l`` and the path constraints ``g`` live at the shooting node: their
    derivatives are plain SX functions. The integrator part (``phi``, ``Phi``, the
    adjoint ``-Phi' lam_next`` and the Hessian of ``-lam_next' phi``) is propagated through
    the substeps by :mod:`.sensitivities`, so the generated code keeps one substep.
    """
    nd = _node_parts(name, m)
    nx, nu, np_ = nd.nx, nd.nu, nd.np_
    node_in, node_names, C_sx = nd.node_in, nd.node_names, nd.C_sx
    node_eval, node_hess = nd.node_eval, nd.node_hess
    node_grad = ca.Function(f"{name}_node_grad", node_in, [_d(ca.gradient(nd.Ln, m.w))], node_names, ["gLn"],
                            _FN_OPTS)
    K = sensitivities.substep_kernels(f"{name}_substep", m.substep, nx, nu, np_, directions)
    n = m.n_substeps
    X, U, P, LAM, MUG = nd.mx
    ins, in_names = list(nd.mx), nd.in_names
    xs = sensitivities.interval_map(K, n, X, U, P)
    phi = xs[-1]
    l, g = node_eval(X, U, P)
    stage_eval = ca.Function(f"{name}_stage_eval", [X, U, P], [phi, l, g], ["x", "u", "p"], ["phi", "l", "g"])
    implicit = not m.substep.is_a("SXFunction")
    if implicit:
        # An implicit substep (an MX function with a rootfinder): its graph inlined, so the
        # derivatives of each rootfinder call take the stages it computed instead of solving
        # the stage equations again inside a kernel (section "Integrators" of docs/usage.md)
        phi_in = sensitivities.interval_map_inlined(m.substep, n, X, U, P)
        g_dyn = sensitivities.adjoint_inlined(phi_in, X, U, -LAM)
        phi_grad = phi_in
    else:
        # L_k = l - lam_next' phi + mu_g' g: the adjoint sweep starts from -lam_next
        g_dyn, _ = sensitivities.propagate_adjoint(K, xs, U, P, -LAM)
        phi_grad = phi
    gL = node_grad(X, U, P, MUG) + g_dyn
    stage_grad = ca.Function(f"{name}_stage_grad", ins, [gL, phi_grad, l, g], in_names,
                             ["gL", "phi", "l", "g"])
    if implicit and directions == "auto":
        Phi, H_dyn = sensitivities.hessian_inlined(phi_in, g_dyn, X, U)
    else:
        S = sensitivities.propagate_forward(K, xs, U, P)
        Phi = S[-1]
        _, H_dyn = sensitivities.propagate_adjoint(K, xs, U, P, -LAM, S)
    An, C = node_hess(X, U, P, MUG)
    A = An + 0.5 * (H_dyn + H_dyn.T)
    stage_hess_exact = ca.Function(f"{name}_stage_hess_exact", ins, [A, Phi, C], in_names, ["A", "Phi", "C"])
    # one MX graph: the interval's forward pass (and, inlined, the gradient's reverse pass) once
    fused = _fused(name, ins, in_names, [gL, phi_grad, l, g], [A, Phi, C])
    stage_hess_cost_exact, stage_hess_cost_gn, A_gn = _stage_cost_hessians(name, m)
    stage_hess_gn = fused_gn = None
    if A_gn is not None:
        node_gn = ca.Function(f"{name}_node_gn", node_in, [_d(A_gn), _d(C_sx)], node_names, ["A", "C"],
                              _FN_OPTS)
        if _same_algorithm(node_gn, node_hess):
            # a least-squares cost without other terms and no path constraints: one kernel
            node_gn = node_hess
        A_gn_mx, C_gn = node_gn(X, U, P, MUG)
        stage_hess_gn = ca.Function(f"{name}_stage_hess_gn", ins, [A_gn_mx, Phi, C_gn], in_names,
                                    ["A", "Phi", "C"])
        fused_gn = _fused(name, ins, in_names, [gL, phi_grad, l, g], [A_gn_mx, Phi, C_gn], kind="gn")
    return (stage_eval, stage_grad, stage_hess_exact, stage_hess_gn, stage_hess_cost_exact, stage_hess_cost_gn,
            fused, fused_gn)


def _stage_functions_chained(name: str, m: StageModel):
    """Hessians by Jacobian chaining over the substeps (:func:`.sensitivities.chain_hessian`):
    one SX kernel of a substep with its Jacobian, adjoint and Hessian, called once per
    substep, so the Hessian code holds one substep at about the operation count of the
    unrolled expression. The gradient is the unrolled expression (its code is small; a
    per-substep adjoint would evaluate the first substeps twice); ``stage_eval`` iterates
    the substep; the Gauss-Newton ``Phi`` reuses the chaining kernel (no more code)."""
    phi_sx = m.x
    for _ in range(m.n_substeps):
        phi_sx = m.substep(phi_sx, m.u, m.p)
    unrolled = _stage_functions_unrolled(name, m, phi_sx)
    nd = _node_parts(name, m)
    nx, nu, np_, w = nd.nx, nd.nu, nd.np_, m.w
    node_in, node_names, C_sx = nd.node_in, nd.node_names, nd.C_sx
    node_eval, node_hess = nd.node_eval, nd.node_hess
    K = sensitivities.chain_kernel(f"{name}_substep", m.substep, nx, nu, np_)
    n = m.n_substeps
    X, U, P, LAM, MUG = nd.mx
    ins, in_names = list(nd.mx), nd.in_names
    phi = sensitivities.interval_map(types.SimpleNamespace(F=m.substep), n, X, U, P)[-1]
    l, g = node_eval(X, U, P)
    stage_eval = ca.Function(f"{name}_stage_eval", [X, U, P], [phi, l, g], ["x", "u", "p"], ["phi", "l", "g"])
    # L_k = l - lam_next' phi + mu_g' g: the chaining starts from a_n = -lam_next
    _, Phi, _, H_dyn = sensitivities.chain_hessian(K, m.substep, n, X, U, P, -LAM)
    An, C = node_hess(X, U, P, MUG)
    A = An + 0.5 * (H_dyn + H_dyn.T)
    stage_hess_exact = ca.Function(f"{name}_stage_hess_exact", ins, [A, Phi, C], in_names, ["A", "Phi", "C"])
    stage_hess_gn = None
    if m.has_stage_ls:
        J = ca.jacobian(m.res, w)
        A_gn = ca.mtimes([J.T, ca.DM(m.W), J]) + ca.hessian(m.l_extra, w)[0]
        node_gn = ca.Function(f"{name}_node_gn", node_in, [_d(A_gn), _d(C_sx)], node_names, ["A", "C"],
                              _FN_OPTS)
        if _same_algorithm(node_gn, node_hess):
            node_gn = node_hess
        # Phi from the same kernel, its Hessian output unused (a_n = 0)
        _, Phi_gn, _, _ = sensitivities.chain_hessian(K, m.substep, n, X, U, P, ca.MX.zeros(nx))
        A_gn_mx, C_gn = node_gn(X, U, P, MUG)
        stage_hess_gn = ca.Function(f"{name}_stage_hess_gn", ins, [A_gn_mx, Phi_gn, C_gn], in_names,
                                    ["A", "Phi", "C"])
    # the gradient (unrolled SX) and the chained Hessian share no graph: no fused function
    return (stage_eval, unrolled[1], stage_hess_exact, stage_hess_gn, unrolled[4], unrolled[5], None, None)



#: derivatives="auto" unrolls while the vectorised forward-over-adjoint kernel of one
#: substep times the substeps stays below this many SX instructions (robot arm: 2 x 6882;
#: chain of masses: 2 x 51768), i.e. for small models, where the unrolled expression is
#: the fastest code (robot arm: the structured Hessian takes 2x to 4x its time).
UNROLL_LIMIT = 20000


def _stage_functions_choice(name: str, integ, m: StageModel):
    """Unrolled or structured stage functions, after the integrator's ``derivatives``."""
    how = getattr(integ, "derivatives", "auto")
    directions = getattr(integ, "directions", "auto")
    sx_substep = m.substep.is_a("SXFunction")
    if how == "unrolled" and not sx_substep:
        raise OcpError(f"{integ.describe()}: derivatives='unrolled' needs an explicit (SX) substep")
    if how == "auto" and sx_substep:
        nx, nu = m.x.size1(), m.u.size1()
        K = sensitivities.substep_kernels(f"{name}_substep", m.substep, nx, nu, m.p.size1(), "all")
        how = "unrolled" if K.soa.n_instructions() * m.n_substeps <= UNROLL_LIMIT else "structured"
    if how == "chained":
        if not sx_substep:
            raise OcpError(f"{integ.describe()}: derivatives='chained' needs an explicit (SX) substep")
        return _stage_functions_chained(name, m)
    if how == "unrolled":
        phi = m.x
        for _ in range(m.n_substeps):
            phi = m.substep(phi, m.u, m.p)
        return _stage_functions_unrolled(name, m, phi)
    return _stage_functions(name, m, directions)


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




def _scenario(spec: OcpSpec, m: StageModel, ode: ca.Function) -> Scenario:
    sc = spec.scenario.closed_loop
    if sc is None:
        return Scenario(disturbance=spec.scenario.disturbance, closed_loop=None)
    name = spec.name
    signals = {}
    for i, (sig, e) in enumerate(sc.signals):
        safe = re.sub(r"[^0-9A-Za-z_]", "_", sig)
        signals[sig] = ca.Function(f"{name}_signal_{i}_{safe}", [m.x, m.u, m.p], [_d(e)],
                                   ["x", "u", "p"], ["value"])
    if sc.plant is None:
        plant = ode
    else:
        plant = ca.Function(f"{name}_plant_ode", [m.x, m.u, m.p], [_d(sc.plant)], ["x", "u", "p"], ["xdot"])
    plant_q = None
    if sc.plant_q is not None:
        q = ca.vertcat(*[sym for _, sym, _ in sc.quantities])
        plant_q = ca.Function(f"{name}_plant_ode_q", [m.x, m.u, ca.vertcat(m.p, q)], [_d(sc.plant_q)],
                              ["x", "u", "p_q"], ["xdot"])
    closed = ScenarioSpec(duration=sc.duration, events=sc.events, signals=types.MappingProxyType(signals),
                          plant_ode=plant, x0=spec.x0 if sc.x0 is None else sc.x0,
                          units=types.MappingProxyType(dict(getattr(sc, "units", ()))),
                          quantities=types.MappingProxyType({n: v for n, _, v in sc.quantities}),
                          plant_ode_q=plant_q, campaign=sc.campaign)
    return Scenario(disturbance=spec.scenario.disturbance, closed_loop=closed)


def build_functions(problem: Union[Ocp, OcpSpec]) -> Discretized:
    """Discretise a problem and build every function of algorithm.md section 2.

    ``problem``: an :class:`Ocp` (validated here by ``Ocp.validate()``, which runs the
    consistency pass once) or the :class:`~.spec.OcpSpec` it returned."""
    if isinstance(problem, Ocp):
        spec = problem.validate()
    elif isinstance(problem, OcpSpec):
        spec = problem
    else:
        raise OcpError(f"build_functions: expected an Ocp, got {type(problem).__name__}")
    m = discretize(spec)
    name = spec.name
    try:
        stage = _stage_functions_choice(name, spec.model.integrator, m)
        term = _terminal_functions(name, m)
        ode = ca.Function(f"{name}_ode", [m.x, m.u, m.p], [_d(m.xdot)], ["x", "u", "p"], ["xdot"], _FN_OPTS)
    except OcpError:
        raise
    except Exception as exc:  # noqa: BLE001 - CasADi failures on user expressions
        raise OcpError(f"{name}: cannot build the stage functions: {casadi_message(exc)}") from None
    stage_residual = term_residual = None
    if m.res.size1():
        stage_residual = ca.Function(f"{name}_stage_residual", [m.x, m.u, m.p], [_d(m.res)],
                                     ["x", "u", "p"], ["res"])
    if m.resN.size1():
        term_residual = ca.Function(f"{name}_term_residual", [m.x, m.p], [_d(m.resN)],
                                    ["x", "p"], ["res"])
    functions = StageFunctions(
        name=name, stage_eval=stage[0], stage_grad=stage[1], stage_hess_exact=stage[2],
        stage_hess_gn=stage[3], stage_hess_cost_exact=stage[4], stage_hess_cost_gn=stage[5],
        term_eval=term[0], term_grad=term[1], term_hess_exact=term[2], term_hess_gn=term[3], ode=ode,
        stage_residual=stage_residual, term_residual=term_residual, stage_grad_hess_exact=stage[6],
        stage_grad_hess_gn=stage[7])
    model, con, N = spec.model, spec.constraints, spec.horizon.N
    nx, nu, np_ = m.x.size1(), m.u.size1(), m.p.size1()
    data = ProblemData(
        name=name, N=N, dt=spec.horizon.dt, nx=nx, nu=nu, nw=nx + nu, np=np_, ng=m.g.size1(),
        nr=m.r.size1(), ne=m.r_eq.size1(), lbx=con.lbx, ubx=con.ubx, lbu=con.lbu, ubu=con.ubu,
        lg=readonly(m.lg), ug=readonly(m.ug), lr=readonly(m.lr), ur=readonly(m.ur),
        lg_stage=readonly(m.lg_stage), ug_stage=readonly(m.ug_stage),
        p0=readonly(_first_horizon(model, N, spec.horizon.dt), (N + 1, np_)), x0=spec.x0,
        guess_x=spec.guess.x, guess_u=spec.guess.u, state_names=model.state_names,
        control_names=model.control_names, parameter_names=model.parameter_names,
        integrator=model.integrator.describe(), W=readonly(m.W), WN=readonly(m.WN),
        soft_x=readonly(con.soft_x if con.soft_x is not None else numpy.zeros((4, nx))),
        soft_g=readonly(m.soft_g), soft_r=readonly(m.soft_r))
    disc = Discretized(spec=spec, data=data, functions=functions, scenario=_scenario(spec, m, ode))
    _check_finite_at_guess(disc)
    if spec.scaling is not None:
        disc = _with_scaling(disc)
    return disc


def _with_scaling(disc: "Discretized") -> "Discretized":
    """``disc`` with its scaling resolved and the scaled problem built (docs/algorithm.md
    section 16); ``derive="nominal"`` solves the declared problem offline first."""
    import dataclasses

    from .scaling import nominal_solution, resolve, scaled_spec

    nominal = None
    if disc.spec.scaling.derive == "nominal":
        nominal = nominal_solution(disc)
        if nominal is None:
            raise OcpError(f"{disc.name}: scaling(derive='nominal'): IPOPT did not solve the OCP at the initial "
                           "state; declare the scales with scale= or use derive='bounds'")
    sc = resolve(disc.spec, disc, nominal)
    return dataclasses.replace(disc, scaling=sc, scaled=build_functions(scaled_spec(disc.spec, sc)))


def _first_horizon(model, N: int, dt: float) -> numpy.ndarray:
    """The parameters of the horizon at t = 0 (node k at k dt), ``(N+1, np)``."""
    tr = getattr(model, "p_trajectory", None)
    if tr is None:
        return numpy.tile(model.p_default, (N + 1, 1))
    return tr.horizon(0.0, N, dt).reshape(N + 1, -1)


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
