"""The optimal control problem as the user writes it, and its validation.

An OCP file is a Python file that defines ``build()`` returning an :class:`Ocp`::

    import casadi as ca
    from dopus_codegen import Ocp, RK4, Event

    def build():
        ocp = Ocp("pendulum")
        x = ocp.state("x", 2, lb=[-5, -10], ub=[5, 10])
        u = ocp.control("u", lb=-1, ub=1)
        target = ocp.parameter("target", value=0.0)
        ocp.dynamics(ca.vertcat(x[1], u - ca.sin(x[0])), integrator=RK4(substeps=2))
        ocp.stage_least_squares(ca.vertcat(x[0] - target, u), weights=[1.0, 0.01])
        ocp.horizon(N=20, dt=0.05)
        ocp.initial_state([0.5, 0.0])
        return ocp

Conventions (docs/algorithm.md sections 1 and 8):

- ``state``/``control``/``parameter`` return CasADi ``SX`` column vectors; every other
  expression must be built from them (and constants). The stage vector is
  ``w = (x, u)`` with the states and controls stacked in declaration order.
- The stage cost ``l`` is the cost of one interval as written (no implicit ``dt``
  factor): ``l = 0.5 res' W res + l_extra`` with ``res``/``W`` from
  :meth:`Ocp.stage_least_squares` and ``l_extra`` from :meth:`Ocp.stage_cost`.
  Several calls of either add up (residuals stack, weights become block diagonal).
- Path constraints ``lb <= g(x, u, p) <= ub`` hold on stages ``0..N-1``; state bounds
  on nodes ``1..N``; control bounds on stages ``0..N-1``.
- A terminal constraint row with ``lb == ub`` becomes an equality row.
- Parameters are runtime-settable, one vector per node; ``value`` is the default, or
  ``trajectory`` the parameter over time (a moving reference): node ``k`` of the horizon
  at time ``t`` gets its value at ``t + k dt``.

Every user mistake raises :class:`OcpError` with a message naming the offending item.
:meth:`Ocp.validate` checks everything declared once and returns the problem as an
immutable :class:`~dopus_codegen.problem.spec.OcpSpec`, which is all that the rest of the
pipeline reads.
"""
from __future__ import annotations

import copy
import functools
import importlib.util
import math
import re
import sys
import traceback
import types
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Mapping, Optional, Tuple

import casadi as ca
import numpy as np

from ..cnames import identifier_problem
from .spec import (CampaignSpec, ClosedLoopSpec, ConstraintSpec, CostSpec, GuessSpec, HorizonSpec, LeastSquares,
                   ModelSpec, OcpError, OcpSpec, OptionsSpec, ParameterTrajectory, Rows, ScalingSpec, ScenarioPart,
                   TrajectoryError, Variable, readonly)

__all__ = [
    "OcpError", "Integrator", "RK4", "GaussLegendre", "RadauIIA", "Event", "Pushes", "OnPath", "Guess", "ScenarioSpec",
    "Ocp", "Soft", "load_ocp",
]



# --------------------------------------------------------------------------- integrators
class Integrator:
    """Maps the continuous model ``xdot = f(x, u, p)`` to the interval map ``phi``.

    Subclasses implement :meth:`step`; ``phi`` must be a smooth SX expression so that
    its first and second derivatives can be taken symbolically.
    """

    #: Equal substeps per interval; the derivative functions iterate one substep
    #: (dopus_codegen.problem.sensitivities), so the generated code holds it once.
    substeps = 1
    #: Seed directions per call of the derivative kernels of one substep: "auto", "one"
    #: (smallest code, a loop over the nw directions), "all" (one vectorised kernel) or
    #: an integer chunk (see dopus_codegen.problem.sensitivities.substep_kernels).
    directions = "auto"
    #: "structured": the stage functions iterate one substep and its derivative kernels
    #: (code size independent of the substeps); "unrolled": one SX expression of the whole
    #: interval (fastest for small models, code grows with substeps and nw); "chained": the
    #: Hessian by Jacobian chaining of one substep kernel over the substeps (explicit
    #: schemes; code of one substep at about the unrolled operation count); "auto": unrolled
    #: for small models (dopus_codegen.problem.derivatives.UNROLL_LIMIT), else structured.
    derivatives = "auto"

    def step(self, ode: ca.Function, x: ca.SX, u: ca.SX, p: ca.SX, h: float) -> ca.SX:
        """State after one interval of length ``h`` with ``u`` and ``p`` held constant."""
        raise NotImplementedError

    def substep(self, ode: ca.Function, x: ca.SX, u: ca.SX, p: ca.SX, h: float) -> ca.SX:
        """State after one substep of length ``h`` (an SX expression). The default is
        :meth:`step` itself (one substep per interval)."""
        return self.step(ode, x, u, p, h)

    def substep_function(self, name: str, ode: ca.Function, x: ca.SX, u: ca.SX, p: ca.SX,
                         dt: float) -> ca.Function:
        """``(x, u, p) -> x+`` of one substep of an interval of length ``dt`` (a CasADi
        function; an implicit scheme returns an MX function with its Newton solver)."""
        e = self.substep(ode, x, u, p, dt / self.substeps)
        return ca.Function(name, [x, u, p], [e], ["x", "u", "p"], ["xn"], {"cse": True})

    def describe(self) -> str:
        """Short deterministic description (used in generated headers)."""
        return type(self).__name__


def _derivatives(value, who: str) -> str:
    if value not in ("auto", "unrolled", "structured", "chained"):
        raise OcpError(f"{who}: derivatives must be 'auto', 'unrolled', 'structured' or 'chained', "
                       f"got {value!r}")
    return value


def _directions(value, who: str):
    if value in ("auto", "one", "all"):
        return value
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool) and value >= 1:
        return int(value)
    raise OcpError(f"{who}: directions must be 'auto', 'one', 'all' or an integer >= 1, got {value!r}")


class RK4(Integrator):
    """Classical fourth-order Runge-Kutta with ``substeps`` equal steps per interval.

    ``derivatives`` (``"auto"``, ``"unrolled"``, ``"structured"``, ``"chained"``) and ``directions``
    (``"auto"``, ``"one"``, ``"all"`` or a chunk size; structured only): how the derivative
    code is built, a trade of code size against speed that never changes the computed
    values beyond round-off (see :class:`Integrator`). Firmware with little flash:
    ``RK4(substeps, derivatives="chained")`` (robot arm: half the code of the unrolled
    form) or ``RK4(substeps, derivatives="structured", directions="one")`` (smallest)."""

    def __init__(self, substeps: int = 1, derivatives: str = "auto", directions="auto"):
        if isinstance(substeps, bool) or not isinstance(substeps, (int, np.integer)) or substeps < 1:
            raise OcpError(f"RK4: substeps must be an integer >= 1, got {substeps!r}")
        self.substeps = int(substeps)
        self.derivatives = _derivatives(derivatives, "RK4")
        self.directions = _directions(directions, "RK4")

    def substep(self, ode, x, u, p, hs):
        k1 = ode(x, u, p)
        k2 = ode(x + 0.5 * hs * k1, u, p)
        k3 = ode(x + 0.5 * hs * k2, u, p)
        k4 = ode(x + hs * k3, u, p)
        return x + (hs / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)

    def step(self, ode, x, u, p, h):
        hs = h / self.substeps
        for _ in range(self.substeps):
            x = self.substep(ode, x, u, p, hs)
        return x

    def describe(self) -> str:
        extra = "" if self.derivatives == "auto" else f", derivatives={self.derivatives!r}"
        extra += "" if self.directions == "auto" else f", directions={self.directions!r}"
        return f"RK4(substeps={self.substeps}{extra})"

    def __repr__(self) -> str:
        return self.describe()


def _collocation_points(kind: str, s: int) -> np.ndarray:
    """Gauss-Legendre: the roots of the shifted Legendre polynomial P_s(2t - 1); Radau IIA:
    the roots of P_s - P_{s-1} (shifted), which end with t = 1."""
    from numpy.polynomial import legendre

    coef = [0.0] * s + [1.0]
    if kind == "radau":
        coef = legendre.legsub(coef, [0.0] * (s - 1) + [1.0])
    roots = np.sort(np.real(legendre.legroots(coef)))
    c = (roots + 1.0) / 2.0
    if kind == "radau":
        c[-1] = 1.0
    return c


def collocation_tableau(kind: str, s: int) -> tuple:
    """Butcher tableau ``(A, b, c)`` of the s-stage collocation method: ``a_ij`` and ``b_j``
    are the integrals of the Lagrange polynomials of the points ``c`` over ``[0, c_i]``
    and ``[0, 1]``."""
    from numpy.polynomial import polynomial as P

    c = _collocation_points(kind, s)
    A, b = np.zeros((s, s)), np.zeros(s)
    for j in range(s):
        others = [c[m] for m in range(s) if m != j]
        lj = P.polyfromroots(others) / np.prod([c[j] - cm for cm in others]) if others else np.array([1.0])
        Ij = P.polyint(lj)
        b[j] = P.polyval(1.0, Ij)
        for i in range(s):
            A[i, j] = P.polyval(c[i], Ij)
    return A, b, c


class _Collocation(Integrator):
    """Implicit Runge-Kutta collocation with ``stages`` stages, ``substeps`` equal substeps
    per interval and exactly ``newton_iters`` Newton iterations on the stage equations
    ``K_i = f(x + h sum_j a_ij K_j, u, p)`` per substep (started from ``K_i = f(x, u, p)``;
    exact Jacobian, dense QR solve: CasADi's ``fast_newton`` rootfinder, which its code
    generator emits as plain C99 without allocation). The derivatives of the substep are
    those of the implicit function (implicit function theorem at the computed stages),
    so they are exact for the converged stage equations.
    """
    kind = ""
    label = ""
    derivatives = "structured"

    def __init__(self, stages: int = 2, substeps: int = 1, newton_iters: int = 3, directions="auto"):
        for what, v, lo in (("stages", stages, 1), ("substeps", substeps, 1), ("newton_iters", newton_iters, 1)):
            if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < lo:
                raise OcpError(f"{self.label}: {what} must be an integer >= {lo}, got {v!r}")
        if stages > 9:
            raise OcpError(f"{self.label}: stages must be <= 9, got {stages}")
        self.stages, self.substeps, self.newton_iters = int(stages), int(substeps), int(newton_iters)
        self.directions = _directions(directions, self.label)
        self.A, self.b, self.c = collocation_tableau(self.kind, self.stages)

    def substep_function(self, name, ode, x, u, p, dt):
        nx, nu, np_ = x.size1(), u.size1(), p.size1()
        s, h = self.stages, dt / self.substeps
        K = ca.SX.sym("K", nx, s)
        xup = ca.SX.sym("xup", nx + nu + np_)
        xs, us, ps = xup[:nx], xup[nx:nx + nu], xup[nx + nu:]
        G = ca.vertcat(*[K[:, i] - ode(xs + h * ca.mtimes(K, ca.DM(self.A[i, :])), us, ps) for i in range(s)])
        G_fn = ca.Function(f"{name}_stage_equations", [ca.vec(K), xup], [G], {"cse": True})
        # abstol = abstol_step = 0: always newton_iters iterations (an exact root ends early
        # with the same result)
        newton = ca.rootfinder(f"{name}_newton", "fast_newton", G_fn,
                               {"max_iter": self.newton_iters, "abstol": 0.0, "abstolStep": 0.0,
                                "error_on_fail": False})
        X, U, Pm = ca.MX.sym("x", nx), ca.MX.sym("u", nu), ca.MX.sym("p", np_)
        K0 = ca.repmat(ode(X, U, Pm), s, 1)
        Ks = ca.reshape(newton(K0, ca.vertcat(X, U, Pm)), nx, s)
        xn = X + h * ca.mtimes(Ks, ca.DM(self.b))
        return ca.Function(name, [X, U, Pm], [xn], ["x", "u", "p"], ["xn"])

    def step(self, ode, x, u, p, h):
        raise OcpError(f"{self.describe()}: an implicit scheme has no unrolled SX form; "
                       "its stage functions are built from substep_function")

    def describe(self) -> str:
        extra = "" if self.directions == "auto" else f", directions={self.directions!r}"
        return (f"{self.label}(stages={self.stages}, substeps={self.substeps}, "
                f"newton_iters={self.newton_iters}{extra})")

    def __repr__(self) -> str:
        return self.describe()


class GaussLegendre(_Collocation):
    """Gauss-Legendre collocation (order 2s, A-stable, symplectic); see :class:`_Collocation`."""
    kind = "gauss"
    label = "GaussLegendre"


class RadauIIA(_Collocation):
    """Radau IIA collocation (order 2s-1, L-stable: for stiff models); see :class:`_Collocation`."""
    kind = "radau"
    label = "RadauIIA"


# --------------------------------------------------------------------------- plain data
@dataclass(frozen=True)
class Event:
    """At ``time`` (seconds) the closed-loop plant state is replaced by ``fn(x)``."""
    time: float
    fn: Callable[[np.ndarray], np.ndarray]
    label: str = "event"


@dataclass(frozen=True)
class Pushes:
    """The random disturbance events of a campaign run (``Ocp.campaign``): ``count`` pushes
    (an integer, or ``(min, max)``: uniform in ``min..max``), each at a time uniform in
    ``window = (t0, t1)`` seconds, adding to the states named in ``kick`` an offset uniform
    in ``[-a, a]`` (``kick``: state name -> ``a``, one number or one per component), e.g.
    ``Pushes(count=(1, 2), window=(0.3, 1.2), kick={"dq": 2.0})``: joint-velocity kicks."""
    count: object
    window: tuple
    kick: Mapping[str, object]


@dataclass(frozen=True)
class OnPath:
    """When a campaign run counts as on the path: after ``settle`` seconds from the start and
    from every push, the scalar scenario signal ``signal`` stays at or below ``threshold``
    (in its own unit) at every sampling instant, and the plant could be integrated to the
    end of the run."""
    signal: str
    threshold: float
    settle: float


@dataclass
class Guess:
    """A primal-dual point in the signed convention of docs/algorithm.md section 1.

    ``x (N+1, nx)``, ``u (N, nu)``; multipliers ``None`` mean zeros.
    """
    x: np.ndarray
    u: np.ndarray
    lam: Optional[np.ndarray] = None
    mu_g: Optional[np.ndarray] = None
    mu_b: Optional[np.ndarray] = None
    mu_bN: Optional[np.ndarray] = None
    mu_r: Optional[np.ndarray] = None
    nu: Optional[np.ndarray] = None

    def filled(self, disc) -> "Guess":
        """A copy with every multiplier present (zeros where ``None``), float arrays."""
        N, nx, nu_, ng, nr, ne = disc.N, disc.nx, disc.nu, disc.ng, disc.nr, disc.ne

        def arr(v, shape):
            if v is None:
                return np.zeros(shape)
            a = np.array(v, dtype=float).reshape(shape)
            return a

        return Guess(x=arr(self.x, (N + 1, nx)), u=arr(self.u, (N, nu_)),
                     lam=arr(self.lam, (N + 1, nx)), mu_g=arr(self.mu_g, (N, ng)),
                     mu_b=arr(self.mu_b, (N, nx + nu_)), mu_bN=arr(self.mu_bN, (nx,)),
                     mu_r=arr(self.mu_r, (nr,)), nu=arr(self.nu, (ne,)))

    def copy(self) -> "Guess":
        c = lambda v: None if v is None else np.array(v, dtype=float, copy=True)  # noqa: E731
        return Guess(x=c(self.x), u=c(self.u), lam=c(self.lam), mu_g=c(self.mu_g),
                     mu_b=c(self.mu_b), mu_bN=c(self.mu_bN), mu_r=c(self.mu_r), nu=c(self.nu))


@dataclass(frozen=True)
class ScenarioSpec:
    """The closed-loop scenario, in a form the SIL layer reads without CasADi symbols.

    ``events``: tuple of :class:`Event`; ``signals``: read-only mapping name ->
    ``casadi.Function(x, u, p) -> value``; ``plant_ode``: ``casadi.Function(x, u, p) ->
    xdot`` (the model itself unless a mismatch was given); ``x0``: initial plant state
    (read-only); ``units``: read-only mapping of a signal, state or control name to its
    unit (axis labels of the figures); ``quantities``: read-only mapping of the plant
    quantities (``Ocp.plant_quantity``) to their nominal values, in declaration order;
    ``plant_ode_q``: ``casadi.Function(x, u, [p; q]) -> xdot`` with the quantities ``q``
    stacked under the parameters (None without quantities); ``campaign``: the declared
    :class:`~.spec.CampaignSpec` or None.
    """
    duration: float
    events: tuple
    signals: Mapping[str, ca.Function]
    plant_ode: ca.Function
    x0: np.ndarray
    units: Mapping[str, str] = field(default_factory=lambda: types.MappingProxyType({}))
    quantities: Mapping[str, float] = field(default_factory=lambda: types.MappingProxyType({}))
    plant_ode_q: Optional[ca.Function] = None
    campaign: Optional[CampaignSpec] = None


@dataclass
class _Decl:
    name: str
    sym: ca.SX
    size: int
    lb: np.ndarray
    ub: np.ndarray
    value: Optional[np.ndarray] = None
    trajectory: Optional[tuple] = None   # ("function", fn) or ("table", (times, values))
    soft: Optional[np.ndarray] = None
    scale: Optional[np.ndarray] = None   # declared scales (NaN: not declared) or None


# --------------------------------------------------------------------------- helpers
def _broadcast(a: np.ndarray, size: int, what: str) -> np.ndarray:
    """``a`` as a vector of length ``size``: a scalar broadcast, a row or column reshaped."""
    if a.ndim == 0:
        return np.full(size, float(a))
    if a.size == size and (a.ndim == 1 or (a.ndim == 2 and 1 in a.shape)):
        return a.reshape(size)
    raise OcpError(f"{what}: expected a scalar or {size} values, got shape {a.shape}")


def _vector(value, size: int, what: str, allow_inf: bool = True) -> np.ndarray:
    """A float vector of length ``size`` (scalars broadcast); NaN always rejected."""
    try:
        a = np.array(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise OcpError(f"{what}: expected numbers, got {value!r} ({exc})") from None
    a = _broadcast(a, size, what)
    if np.any(np.isnan(a)):
        raise OcpError(f"{what}: NaN at row {int(np.flatnonzero(np.isnan(a))[0])}")
    if not allow_inf and np.any(np.isinf(a)):
        raise OcpError(f"{what}: infinite value at row {int(np.flatnonzero(np.isinf(a))[0])}")
    return a


def _scales(value, size: int, what: str) -> Optional[np.ndarray]:
    """Declared scales: None, or ``size`` positive finite numbers (a scalar broadcasts)."""
    if value is None:
        return None
    try:
        a = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise OcpError(f"{what} scale: expected a positive number or {size}, got {value!r}") from None
    a = _broadcast(a, size, f"{what} scale")
    bad = np.flatnonzero(~(np.isfinite(a) & (a > 0)))
    if bad.size:
        raise OcpError(f"{what} scale: must be positive and finite, got {float(a[bad[0]])!r} at row {int(bad[0])}")
    return a


def _trajectory(value, size: int, what: str) -> tuple:
    """``("function", fn)`` or ``("table", (times, values))`` of a declared trajectory."""
    if callable(value):
        return ("function", value)
    if not isinstance(value, (tuple, list)) or len(value) != 2:
        raise OcpError(f"{what} trajectory: expected a function of t or a table (times, values), "
                       f"got {type(value).__name__}")
    try:
        times = np.array(value[0], dtype=float)
        values = np.array(value[1], dtype=float)
    except (TypeError, ValueError) as exc:
        raise OcpError(f"{what} trajectory: the table must hold numbers ({exc})") from None
    if times.ndim != 1 or times.size < 1:
        raise OcpError(f"{what} trajectory: times must be a non-empty vector, got shape {times.shape}")
    if values.ndim == 1 and size == 1:
        values = values.reshape(-1, 1)
    if values.shape != (times.size, size):
        raise OcpError(f"{what} trajectory: expected values of shape ({times.size}, {size}) "
                       f"(one row per time), got {values.shape}")
    if not (np.all(np.isfinite(times)) and np.all(np.isfinite(values))):
        raise OcpError(f"{what} trajectory: the table holds a non-finite value (NaN or inf)")
    if np.any(np.diff(times) <= 0):
        i = int(np.flatnonzero(np.diff(times) <= 0)[0])
        raise OcpError(f"{what} trajectory: times must increase strictly, got {times[i]} then {times[i + 1]}")
    return ("table", (readonly(times), readonly(values)))


def _as_sx(expr, what: str) -> ca.SX:
    """Column SX vector from a user expression (numbers allowed)."""
    if isinstance(expr, ca.MX):
        raise OcpError(f"{what}: got a casadi MX expression; build it from the SX symbols "
                       f"returned by state()/control()/parameter()")
    if isinstance(expr, (ca.DM, int, float, np.ndarray, list, tuple, np.floating, np.integer)):
        try:
            expr = ca.SX(ca.DM(np.array(expr, dtype=float)))
        except Exception as exc:  # noqa: BLE001 - user data of any kind
            raise OcpError(f"{what}: cannot convert {expr!r} to an expression ({casadi_message(exc)})") from None
    if not isinstance(expr, ca.SX):
        raise OcpError(f"{what}: expected a casadi SX expression, got {type(expr).__name__}")
    if expr.size2() != 1:
        if expr.size1() == 1:
            expr = expr.T
        else:
            raise OcpError(f"{what}: expected a column vector, got a {expr.size1()}x{expr.size2()} matrix")
    return ca.densify(expr)


def _rows(expr, lb, ub, what: str) -> tuple:
    """``(expr, lb, ub)`` of a block of constraint rows, checked: an SX column and two bound
    vectors of its size with ``lb <= ub``."""
    e = _as_sx(expr, what)
    lbv = _vector(lb, e.size1(), f"{what} lb")
    ubv = _vector(ub, e.size1(), f"{what} ub")
    _check_bounds(lbv, ubv, what)
    return e, lbv, ubv


def _stage_list(stages, what: str) -> Optional[Tuple[int, ...]]:
    """``stages=`` of a declaration (None: every stage): sorted distinct integers, checked
    against 0..N-1 when the OCP is validated."""
    if stages is None:
        return None
    try:
        stages = tuple(stages)
    except TypeError:
        raise OcpError(f"{what}: stages must be stage indices (e.g. range(5, 10)), got {stages!r}") from None
    bad = [k for k in stages if isinstance(k, bool) or not isinstance(k, (int, np.integer))]
    if bad:
        raise OcpError(f"{what}: stages must be integers, got {bad[0]!r}")
    if not stages:
        raise OcpError(f"{what}: stages is empty (leave it out for every stage)")
    if len(set(stages)) != len(stages):
        raise OcpError(f"{what}: stage {next(k for k in stages if stages.count(k) > 1)} given twice")
    return tuple(sorted(int(k) for k in stages))


def _check_bounds(lb: np.ndarray, ub: np.ndarray, what: str) -> None:
    bad = np.flatnonzero(lb > ub)
    if bad.size:
        i = int(bad[0])
        raise OcpError(f"{what}: lb > ub at row {i} ({lb[i]} > {ub[i]})")


@dataclass(frozen=True)
class Soft:
    """Soft rows: the rows may be violated at a price (docs/algorithm.md section 12).

    The penalty of a row and side is ``l1 * s + 0.5 * l2 * s**2`` with ``s >= 0`` its
    violation (``lb - s_lo <= g <= ub + s_up``), added at every node where the row applies,
    with no implicit ``dt``. ``l1``, ``l2``: a non-negative number (every row, both sides),
    a list or array of one value per row, or a tuple ``(lower, upper)`` of two such values
    (one per side). A side with ``l1 = l2 = 0`` stays hard; at least one weight must be
    positive. With ``l1`` above the multiplier the hard problem has on the row (an exact
    penalty), the soft solution is the hard one whenever the hard problem is feasible."""
    l1: object = 0.0
    l2: object = 0.0


def _soft_weights(soft, n: int, lb: np.ndarray, ub: np.ndarray, what: str) -> Optional[np.ndarray]:
    """The weights of ``soft`` for ``n`` rows with bounds ``lb, ub``: a read-only ``(4, n)``
    array with rows ``(l1 lower, l1 upper, l2 lower, l2 upper)``, zero on the sides without a
    finite bound; None for ``soft=None``."""
    if soft is None:
        return None
    if not isinstance(soft, Soft):
        raise OcpError(f"{what}: soft must be Soft(l1=..., l2=...), got {type(soft).__name__}")

    def sides(value, name):
        if isinstance(value, tuple):
            if len(value) != 2:
                raise OcpError(f"{what}: soft {name} as a tuple must be (lower, upper), got {len(value)} values")
            pair = value
        else:
            pair = (value, value)
        out = []
        for side, v in zip(("lower", "upper"), pair):
            a = _vector(v, n, f"{what}: soft {name} ({side} side)")
            if np.any(np.isinf(a)):
                raise OcpError(f"{what}: soft {name} must be finite, got {a[np.isinf(a)][0]} at row "
                               f"{int(np.flatnonzero(np.isinf(a))[0])}")
            if np.any(a < 0):
                i = int(np.flatnonzero(a < 0)[0])
                raise OcpError(f"{what}: soft {name} must be >= 0, got {a[i]} at row {i}")
            out.append(a)
        return out

    l1lo, l1up = sides(soft.l1, "l1")
    l2lo, l2up = sides(soft.l2, "l2")
    w = np.vstack([l1lo, l1up, l2lo, l2up])
    if not np.any(w > 0):
        raise OcpError(f"{what}: soft weights are all zero (give l1 > 0 or l2 > 0)")
    none = np.flatnonzero(~np.isfinite(lb) & ~np.isfinite(ub) & np.any(w > 0, axis=0))
    if none.size:
        raise OcpError(f"{what}: soft= on row {int(none[0])}, which has no finite bound "
                       "(give it the weight 0: one value per row)")
    w[[0, 2]] *= np.isfinite(lb)
    w[[1, 3]] *= np.isfinite(ub)
    if not np.any(w > 0):
        raise OcpError(f"{what}: soft weights are zero on every finite bound")
    return readonly(w)


def casadi_message(exc: BaseException) -> str:
    """The user-relevant part of an exception message: CasADi prefixes its messages with
    source locations of its own C++ code, which say nothing about the OCP."""
    text = str(exc).strip()
    if ".cpp:" in text or "casadi" in text.lower():
        lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
        useful = [ln for ln in lines if ".cpp:" not in ln]
        text = useful[-1] if useful else re.sub(r"^.*\.cpp:\d+:\s*", "", lines[-1])
    return text


def _check_identifier(name, what: str) -> str:
    why = identifier_problem(name)
    if why is not None:
        shown = repr(name) if not isinstance(name, str) or len(name) <= 40 else repr(name[:20] + "...")
        raise OcpError(f"{what}: {shown} {why}")
    return name


def _snapshot(value):
    """A private copy of user data kept until validation (the user's object may change)."""
    try:
        return copy.deepcopy(value)
    except Exception:  # noqa: BLE001 - not copyable: validation reads it as given
        return value


def _declaration(method):
    """Marks a method that changes the declaration: the validated spec is recomputed."""
    @functools.wraps(method)
    def wrapper(self, *args, **kwargs):
        self._spec = None
        return method(self, *args, **kwargs)
    return wrapper


# --------------------------------------------------------------------------- the OCP
class Ocp:
    """Declarative description of one OCP (see the module docstring).

    :meth:`validate` returns the problem as an immutable :class:`~.spec.OcpSpec`; the
    validation runs once and its result is kept until the next declaration.
    """

    def __init__(self, name: str):
        self._spec: Optional[OcpSpec] = None
        self.name = _check_identifier(name, "Ocp name")
        self._states: list[_Decl] = []
        self._controls: list[_Decl] = []
        self._params: list[_Decl] = []
        self._xdot = None
        self._integrator: Integrator = RK4(1)
        self._stage_costs: list[ca.SX] = []
        self._stage_ls: list[tuple[ca.SX, np.ndarray]] = []
        self._stage_ls_staged: list[tuple] = []   # (rows, L2 weights, stages, what): stages= terms
        self._term_costs: list[ca.SX] = []
        self._term_ls: list[tuple[ca.SX, np.ndarray]] = []
        self._rates: list[tuple] = []     # (control decl, lb, ub, name, initial, memory decl)
        self._path: list[tuple] = []      # (expr, lb, ub, soft weights or None)
        self._term_con: list[tuple] = []
        self._N = None
        self._dt = None
        self._x0 = None
        self._guess_x = None
        self._guess_u = None
        from ..settings import DEFAULTS, FILE_SETTINGS

        self._options = {k: DEFAULTS[k] for k in FILE_SETTINGS}
        self._declared: set = set()
        self._disturbance = None
        self._scenario = None
        self._quantities: list = []
        self._campaign = None
        # the declared scales of the path rows, terminal rows and rate rows (aligned with
        # _path, _term_con and _rates; None: not declared) and Ocp.scaling's cost and derive
        self._path_scale: list = []
        self._term_scale: list = []
        self._rate_scale: list = []
        self._scaling = {"cost": None, "derive": None}

    def __setattr__(self, key, value):
        if key != "_spec":
            object.__setattr__(self, "_spec", None)
        object.__setattr__(self, key, value)

    # ------------------------------------------------------------------ declarations
    def _declare(self, kind: str, store: list, name, size, lb, ub, value=None, soft=None, scale=None) -> ca.SX:
        _check_identifier(name, f"{kind} name")
        for decl in self._states + self._controls + self._params:
            if decl.name == name:
                raise OcpError(f"{kind} '{name}': duplicate name (already declared)")
        if isinstance(size, bool) or not isinstance(size, (int, np.integer)) or size < 1:
            raise OcpError(f"{kind} '{name}': size must be an integer >= 1, got {size!r}")
        size = int(size)
        lbv = _vector(lb, size, f"{kind} '{name}' lb")
        ubv = _vector(ub, size, f"{kind} '{name}' ub")
        _check_bounds(lbv, ubv, f"{kind} '{name}' bounds")
        val = None
        if value is not None:
            val = _vector(value, size, f"{kind} '{name}' value", allow_inf=False)
        weights = _soft_weights(soft, size, lbv, ubv, f"{kind} '{name}'")
        scales = _scales(scale, size, f"{kind} '{name}'")
        sym = ca.SX.sym(name, size)
        store.append(_Decl(name, sym, size, lbv, ubv, value=val, soft=weights, scale=scales))
        return sym

    @_declaration
    def state(self, name: str, size: int = 1, lb=-math.inf, ub=math.inf, soft: Optional[Soft] = None,
              scale=None) -> ca.SX:
        """Declare a state vector; bounds hold on nodes 1..N. ``soft``: :class:`Soft`
        weights that make the bounds soft (control bounds are always hard). ``scale``: its
        typical size (a positive number, or one per component): the solver works with
        ``x / scale`` (docs/algorithm.md section 16; :meth:`scaling`)."""
        return self._declare("state", self._states, name, size, lb, ub, soft=soft, scale=scale)

    @_declaration
    def control(self, name: str, size: int = 1, lb=-math.inf, ub=math.inf, scale=None) -> ca.SX:
        """Declare a control vector; bounds hold on stages 0..N-1. ``scale``: as for
        :meth:`state`."""
        return self._declare("control", self._controls, name, size, lb, ub, scale=scale)

    @_declaration
    def parameter(self, name: str, size: int = 1, value=None, trajectory=None) -> ca.SX:
        """Declare a runtime parameter (one value per node); ``value`` is the default (0).

        ``trajectory``: the parameter over time, for references that move: a function of
        the time ``t`` in seconds returning ``size`` values, or a table ``(times, values)``
        (``times`` increasing, ``values`` one row of ``size`` per time; linear in between,
        held before the first and after the last time). Node ``k`` of the horizon at
        instant ``t`` gets ``trajectory(t + k dt)``: the initial guess, the offline
        solution, ``converge`` (t = 0), ``sil``, ``campaign``, ``bench`` and the generated
        main use it; at run time the solver shifts the parameters with the horizon and the
        caller pushes the value of the new last node (docs/algorithm.md section 4)."""
        if value is not None and trajectory is not None:
            raise OcpError(f"parameter '{name}': give value or trajectory, not both")
        sym = self._declare("parameter", self._params, name, size, -math.inf, math.inf,
                            value=0.0 if value is None else value)
        if trajectory is not None:
            self._params[-1].trajectory = _trajectory(trajectory, self._params[-1].size, f"parameter '{name}'")
        return sym

    # ------------------------------------------------------------------ model and costs
    @_declaration
    def dynamics(self, xdot, integrator: Optional[Integrator] = None) -> None:
        """Continuous model ``xdot = f(x, u, p)``, discretised by ``integrator``."""
        self._xdot = _as_sx(xdot, "dynamics")
        if integrator is not None:
            if not isinstance(integrator, Integrator):
                raise OcpError(f"dynamics: integrator must be an Integrator such as RK4(substeps=2), "
                               f"got {type(integrator).__name__}")
            self._integrator = integrator

    @_declaration
    def stage_cost(self, expr) -> None:
        """Add a general (non least-squares) term to the stage cost."""
        self._stage_costs.append(_as_sx(expr, f"stage cost {len(self._stage_costs)}"))

    @_declaration
    def terminal_cost(self, expr) -> None:
        """Add a general term to the terminal cost ``E(x_N, p)``."""
        self._term_costs.append(_as_sx(expr, f"terminal cost {len(self._term_costs)}"))

    def _weights(self, weights, n: int, what: str) -> np.ndarray:
        try:
            W = np.array(weights, dtype=float)
        except (TypeError, ValueError) as exc:
            raise OcpError(f"{what}: weights must be numbers ({exc})") from None
        if W.ndim == 0:
            W = np.full(n, float(W))
        if W.ndim == 1 or (W.ndim == 2 and W.shape[1] == 1 and n != 1):
            W = W.reshape(-1)
            if W.size != n:
                raise OcpError(f"{what}: {W.size} weights for a residual of {n} rows")
            W = np.diag(W)
        if W.shape != (n, n):
            raise OcpError(f"{what}: weight matrix must be {n}x{n}, got {W.shape}")
        if not np.all(np.isfinite(W)):
            raise OcpError(f"{what}: weights must be finite (no NaN/inf)")
        if not np.allclose(W, W.T, rtol=0, atol=1e-12 * max(1.0, np.abs(W).max())):
            raise OcpError(f"{what}: weight matrix is not symmetric")
        W = 0.5 * (W + W.T)
        if n and np.linalg.eigvalsh(W).min() < -1e-12 * max(1.0, np.abs(W).max()):
            raise OcpError(f"{what}: weights must be positive semidefinite")
        return W

    @_declaration
    def stage_least_squares(self, residual, weights, stages=None) -> None:
        """Add ``0.5 res' W res`` to the stage cost (weights: vector = diagonal, or matrix);
        ``stages``: the stages (integers in 0..N-1, e.g. ``range(30, 40)``) where the term
        applies (default: all). A term on chosen stages is carried as soft equality rows
        ``q_i' res = 0`` on those stages with the L2 weights ``d_i`` (``W = Q diag(d) Q'``),
        whose penalty ``0.5 d_i (q_i' res)^2`` sums to the term (docs/algorithm.md section 12);
        the Gauss-Newton Hessian needs a term on every stage."""
        what = f"stage least squares {len(self._stage_ls) + len(self._stage_ls_staged)}"
        res = _as_sx(residual, what)
        W = self._weights(weights, res.size1(), what)
        stages = _stage_list(stages, what)
        if stages is None:
            self._stage_ls.append((res, W))
            return
        d, Q = np.linalg.eigh(W)
        keep = d > 1e-12 * max(1.0, float(np.abs(d).max(initial=0.0)))
        if not np.any(keep):
            raise OcpError(f"{what}: weights are all zero")
        rows = ca.mtimes(ca.DM(Q[:, keep].T), res)
        self._stage_ls_staged.append((rows, d[keep], stages, what))

    @_declaration
    def terminal_least_squares(self, residual, weights) -> None:
        """Add ``0.5 res' W res`` to the terminal cost."""
        what = f"terminal least squares {len(self._term_ls)}"
        res = _as_sx(residual, what)
        self._term_ls.append((res, self._weights(weights, res.size1(), what)))

    @_declaration
    def path_constraint(self, expr, lb=-math.inf, ub=math.inf, soft: Optional[Soft] = None,
                        name: Optional[str] = None, terminal: bool = False, stages=None, scale=None) -> None:
        """``lb <= g(x, u, p) <= ub`` on stages 0..N-1 (several calls stack); ``soft``:
        :class:`Soft` weights that make the rows soft; ``name``: the rows' name in messages,
        tables and the C API's row description (``name[i]`` for row i of several; default
        ``path constraint <i>``); ``terminal=True``: the rows also hold at x_N (a terminal
        constraint of the same rows, bounds and name; they may use states and parameters only);
        ``stages``: the stages (integers in 0..N-1, e.g. ``range(5, 10)``) where the rows hold
        (default: all); at the other stages they are absent (infinite bounds); ``scale``: the
        rows' typical size (one number or one per row): the solver works with ``g / scale``
        (docs/algorithm.md section 16)."""
        what = f"path constraint {len(self._path)}"
        name = self._row_name(name, what)
        if name is not None:
            what = f"path constraint '{name}'"
        if not isinstance(terminal, (bool, np.bool_)):
            raise OcpError(f"{what}: terminal must be True or False, got {terminal!r}")
        g, lbv, ubv = _rows(expr, lb, ub, what)
        weights = _soft_weights(soft, g.size1(), lbv, ubv, what)
        scales = _scales(scale, g.size1(), what)
        if terminal:
            used = [d.name for d in self._controls if ca.depends_on(g, d.sym)]
            if used:
                raise OcpError(f"{what}: terminal=True, but the rows use control '{used[0]}' "
                               f"(at x_N a row may use states and parameters only)")
            eq = np.flatnonzero((lbv == ubv) & np.isinf(lbv))
            if eq.size:
                raise OcpError(f"{what}: lb == ub == {lbv[eq[0]]} at row {int(eq[0])}")
        stages = _stage_list(stages, what)
        self._path.append((g, lbv, ubv, weights, name, stages))
        self._path_scale.append(scales)
        if terminal:
            self._term_con.append((g, lbv, ubv, weights, name, None))
            self._term_scale.append(scales)

    @_declaration
    def rate_constraint(self, control: str, lb=-math.inf, ub=math.inf, name: Optional[str] = None,
                        initial=None, soft: Optional[Soft] = None, scale=None) -> None:
        """``lb <= u_k - u_{k-1} <= ub`` for the control named ``control`` (the change per
        sampling interval), at stages 1..N-1 and at stage 0 against the last applied control,
        which the runtime keeps (``initial``: its value before the first feedback; default 0
        clipped into the control's bounds). A memory state ``<control>_prev`` (after the
        declared states) carries ``u_{k-1}``: its interval map is ``x+ = u``, the measured
        state's entry is filled by the runtime, the guess and the initial state get it from
        ``initial`` and the guessed controls. ``name``: the rows' name (default
        ``<control>_rate``); ``soft``: :class:`Soft` weights, as for :meth:`path_constraint`;
        ``scale``: the rows' scale (default: the control's; the memory state always has the
        control's)."""
        if not isinstance(control, str):
            raise OcpError(f"rate constraint: control must be the name of a declared control, got {control!r}")
        decl = next((d for d in self._controls if d.name == control), None)
        if decl is None:
            raise OcpError(f"rate constraint: {control!r} is not a declared control; the controls are "
                           f"{[d.name for d in self._controls]}")
        if any(r[0].name == control for r in self._rates):
            raise OcpError(f"rate constraint of '{control}': declared twice")
        what = f"rate constraint of '{control}'"
        lbv = _vector(lb, decl.size, f"{what} lb")
        ubv = _vector(ub, decl.size, f"{what} ub")
        _check_bounds(lbv, ubv, what)
        if not np.any(np.isfinite(lbv) | np.isfinite(ubv)):
            raise OcpError(f"{what}: no finite bound (give lb or ub)")
        name = self._row_name(f"{control}_rate" if name is None else name, what)
        init = None if initial is None else _vector(initial, decl.size, f"{what} initial", allow_inf=False)
        mem_name = f"{control}_prev"
        if any(d.name == mem_name for d in self._states + self._controls + self._params):
            raise OcpError(f"{what}: its memory state '{mem_name}' clashes with a declared name")
        mem = _Decl(mem_name, ca.SX.sym(mem_name, decl.size), decl.size, np.full(decl.size, -math.inf),
                    np.full(decl.size, math.inf))
        weights = _soft_weights(soft, decl.size, lbv, ubv, what)
        scales = _scales(scale, decl.size, what)
        self._rates.append((decl, lbv, ubv, name, init, mem, weights))
        self._rate_scale.append(scales)

    def _row_name(self, name, what: str) -> Optional[str]:
        """A checked row name (an identifier, unique among the constraint names) or None."""
        if name is None:
            return None
        _check_identifier(name, f"{what} name")
        if any(entry[4] == name for entry in self._path + self._term_con) or \
                any(entry[3] == name for entry in self._rates):
            raise OcpError(f"{what}: duplicate constraint name {name!r}")
        return name

    @_declaration
    def terminal_constraint(self, expr, lb=-math.inf, ub=math.inf, soft: Optional[Soft] = None,
                            name: Optional[str] = None, scale=None) -> None:
        """``lb <= r(x_N, p) <= ub``; hard rows with ``lb == ub`` become equality rows;
        ``soft``: :class:`Soft` weights that make the rows soft (a soft row with ``lb ==
        ub`` stays a two-sided inequality row whose sides may be violated at a price);
        ``scale``: as for :meth:`path_constraint`."""
        what = f"terminal constraint {len(self._term_con)}"
        name = self._row_name(name, what)
        if name is not None:
            what = f"terminal constraint '{name}'"
        r, lbv, ubv = _rows(expr, lb, ub, what)
        eq = np.flatnonzero((lbv == ubv) & np.isinf(lbv))
        if eq.size:
            raise OcpError(f"{what}: lb == ub == {lbv[eq[0]]} at row {int(eq[0])}")
        scales = _scales(scale, r.size1(), what)
        self._term_con.append((r, lbv, ubv, _soft_weights(soft, r.size1(), lbv, ubv, what), name, None))
        self._term_scale.append(scales)

    @_declaration
    def scaling(self, cost=None, derive: Optional[str] = None) -> None:
        """The scaling of the problem the solver works with (docs/algorithm.md section 16):
        ``cost``: the cost's typical size (the solver minimises ``cost / scale``); ``derive``:
        the scales not declared with ``scale=`` are derived, ``"bounds"`` from the finite
        bounds (else the initial state and guess), ``"nominal"`` from the offline (IPOPT)
        solution at the initial state, rounded to powers of two; None (default): 1.
        The solver's API stays in the declared units."""
        if cost is not None:
            c = _scales(cost, 1, "scaling cost")
            if np.isnan(c[0]):
                raise OcpError(f"scaling: cost must be a positive finite number, got {cost!r}")
            cost = float(c[0])
        if derive not in (None, "bounds", "nominal"):
            raise OcpError(f"scaling: derive must be None, 'bounds' or 'nominal', got {derive!r}")
        self._scaling = {"cost": cost, "derive": derive}

    # ------------------------------------------------------------------ horizon and data
    @_declaration
    def horizon(self, N: int, dt: float) -> None:
        """``N`` shooting intervals of length ``dt`` seconds (also the sampling time)."""
        if isinstance(N, bool) or not isinstance(N, (int, np.integer)):
            raise OcpError(f"horizon: N must be an integer, got {N!r}")
        if N < 2:
            raise OcpError(f"horizon: N must be >= 2, got {N}")
        try:
            dtf = float(dt)
        except (TypeError, ValueError):
            raise OcpError(f"horizon: dt must be a number, got {dt!r}") from None
        if not math.isfinite(dtf) or dtf <= 0:
            raise OcpError(f"horizon: dt must be positive and finite, got {dt!r}")
        self._N, self._dt = int(N), dtf

    @_declaration
    def initial_state(self, x0) -> None:
        """The initial state ``xhat_0`` used by the examples, the guess and the scenario."""
        self._x0 = _snapshot(x0)

    @_declaration
    def initial_guess(self, x=None, u=None) -> None:
        """Guess: a vector broadcast to all nodes, or a full (N+1, nx) / (N, nu) array."""
        self._guess_x, self._guess_u = _snapshot(x), _snapshot(u)

    @_declaration
    def options(self, **values) -> None:
        """Solver defaults: the generated solver's, and those of every command and handle
        built from this file (a command-line flag overrides them); only the options given
        change. The options are the rows of :data:`dopus_codegen.settings.TABLE` that the
        file may give (:data:`~dopus_codegen.settings.FILE_SETTINGS`), with their checks
        and defaults: ``hessian="exact"``, ``regularization="none"``, ``reg_eps=1e-4``,
        ``M=1``, ``lm="auto"``, ``cost_hessian="fresh"``, ``real="double"``,
        ``offline_guess=False``.

        ``real``: the real-number type of the generated C, ``"double"`` or ``"float"``
        (single precision, for microcontrollers with a single-precision FPU); the default
        QP tolerance follows it (:data:`dopus_codegen.settings.QP_TOL_DEFAULT`).

        ``lm``: the Levenberg-Marquardt term of the QP (docs/algorithm.md sections 3 and
        10): ``"auto"`` (the default: scale-aware and adaptive, nothing to tune) or a fixed
        number >= 0 (``0`` is the paper's literal algorithm).

        ``offline_guess=True``: the code generator solves the NLP at the initial state
        offline (IPOPT) and carries the primal-dual solution as static data, so the
        controller can start warm; ``initial_guess`` stays the declared (cold) guess.
        """
        from ..settings import FILE_SETTINGS, SettingError, validate

        opts = dict(self._options)
        declared = set(self._declared)
        for name, value in values.items():
            if name not in FILE_SETTINGS:
                raise OcpError(f"options: unknown option {name!r}; the options are {', '.join(FILE_SETTINGS)}")
            if value is None:
                continue
            try:
                opts[name] = validate(name, value)
            except SettingError as exc:
                raise OcpError(f"options: {exc}") from None
            declared.add(name)
        self._options, self._declared = opts, declared

    def declared_options(self) -> dict:
        """The options this OCP file gave with :meth:`options` (the rest are defaults)."""
        return {k: v for k, v in self._options.items() if k in self._declared}

    @_declaration
    def disturbance(self, fn: Callable[[np.ndarray], np.ndarray]) -> None:
        """State map used by the warm-start convergence study (numpy in, numpy out)."""
        if not callable(fn):
            raise OcpError(f"disturbance: expected a function of the state, got {type(fn).__name__}")
        self._disturbance = fn

    @_declaration
    def scenario(self, duration: float, events=(), signals=None, plant=None, x0=None, units=None) -> None:
        """Closed-loop scenario: ``duration`` seconds, state ``events``, recorded ``signals``
        (name -> expression of the declared symbols), ``plant`` xdot (None: the model),
        ``units``: the unit of a signal, state or control by name (``{"deviation": "m",
        "tau": "N m"}``), written on the axes of the figures; ``"time"``: the unit of the
        model's time (of ``dt``, ``duration`` and the event times; default ``"s"``), written
        wherever a time of the scenario is shown."""
        try:
            events = list(events)
        except TypeError:
            raise OcpError(f"scenario: events must be a list of Event, got {type(events).__name__}") from None
        if signals is not None and not isinstance(signals, dict):
            raise OcpError(f"scenario: signals must be a dict name -> expression, got {type(signals).__name__}")
        if units is not None and not isinstance(units, dict):
            raise OcpError(f"scenario: units must be a dict name -> unit, got {type(units).__name__}")
        self._scenario = dict(duration=duration, events=events, signals=dict(signals or {}),
                              plant=plant, x0=_snapshot(x0), units=dict(units or {}))

    @_declaration
    def plant_quantity(self, name: str, nominal: float) -> ca.SX:
        """A scalar quantity of the plant (a mass, a length) that a campaign may mismatch.

        Returns a symbol to use in the scenario's ``plant`` expression (only there: the
        controller's model keeps its own numbers). The plant of ``dopus-gen sil`` uses the
        ``nominal`` value; a campaign run scales it as ``Ocp.campaign(mismatch=...)`` says."""
        _check_identifier(name, "plant quantity name")
        if any(n == name for n, _, _ in self._quantities):
            raise OcpError(f"plant quantity '{name}': duplicate name (already declared)")
        try:
            value = float(nominal)
        except (TypeError, ValueError):
            raise OcpError(f"plant quantity '{name}': nominal must be a number, got {nominal!r}") from None
        if not math.isfinite(value):
            raise OcpError(f"plant quantity '{name}': nominal must be finite, got {nominal!r}")
        sym = ca.SX.sym(name)
        self._quantities.append((name, sym, value))
        return sym

    @_declaration
    def campaign(self, mismatch=None, initial=None, pushes: Optional[Pushes] = None,
                 on_path: Optional[OnPath] = None, runs: Optional[int] = None,
                 duration: Optional[float] = None) -> None:
        """The Monte Carlo campaign of ``dopus-gen campaign`` (needs :meth:`scenario`).

        ``mismatch``: plant quantity name -> relative half-width ``r`` in [0, 1) (the run's
        plant uses ``nominal * U(1 - r, 1 + r)``); ``initial``: state name -> half-width
        ``a`` (one number or one per component; the run starts at the scenario's initial
        state plus ``U(-a, a)``); ``pushes``: :class:`Pushes`; ``on_path``: :class:`OnPath`;
        ``runs``, ``duration``: defaults of the command's ``--runs`` and ``--duration``.
        The scenario's own events are not applied in a campaign run, its pushes are."""
        for what, value in (("mismatch", mismatch), ("initial", initial)):
            if value is not None and not isinstance(value, dict):
                raise OcpError(f"campaign: {what} must be a dict name -> half-width, got {type(value).__name__}")
        if pushes is not None and not isinstance(pushes, Pushes):
            raise OcpError(f"campaign: pushes must be Pushes(count, window, kick), got {type(pushes).__name__}")
        if on_path is not None and not isinstance(on_path, OnPath):
            raise OcpError(f"campaign: on_path must be OnPath(signal, threshold, settle), got {type(on_path).__name__}")
        self._campaign = dict(mismatch=dict(mismatch or {}), initial=dict(initial or {}), pushes=pushes,
                              on_path=on_path, runs=runs, duration=duration)

    # ------------------------------------------------------------------ derived views
    @property
    def N(self) -> Optional[int]:
        return self._N

    @property
    def dt(self) -> Optional[float]:
        return self._dt

    @property
    def integrator(self) -> Integrator:
        return self._integrator

    def x_sym(self) -> ca.SX:
        return ca.vertcat(*[d.sym for d in self._states]) if self._states else ca.SX(0, 1)

    def u_sym(self) -> ca.SX:
        return ca.vertcat(*[d.sym for d in self._controls]) if self._controls else ca.SX(0, 1)

    def p_sym(self) -> ca.SX:
        return ca.vertcat(*[d.sym for d in self._params]) if self._params else ca.SX(0, 1)

    # ------------------------------------------------------------------ validation
    def _check_symbols(self, expr: ca.SX, what: str, allowed: str) -> None:
        """``allowed``: which kinds may appear: subset of 'xup'."""
        kinds = {"x": ("state", self._states), "u": ("control", self._controls),
                 "p": ("parameter", self._params)}
        ok = {}
        for key in allowed:
            for d in kinds[key][1]:
                for i in range(d.size):
                    ok[d.sym[i].element_hash()] = True
        for s in ca.symvar(expr):
            if s.element_hash() in ok:
                continue
            name = s.name()
            for key in "xup":
                for d in kinds[key][1]:
                    if any(d.sym[i].element_hash() == s.element_hash() for i in range(d.size)):
                        allowed_names = " or ".join(kinds[k][0] for k in allowed)
                        raise OcpError(f"{what} uses {kinds[key][0]} '{name}', but may only depend on "
                                       f"{allowed_names} symbols")
            names = {"xup": "state, control or parameter", "xp": "state or parameter",
                     "p": "parameter"}.get(allowed, "declared")
            raise OcpError(f"{what} uses symbol '{name}' that is not a declared {names}")

    def validate(self) -> OcpSpec:
        """The validated problem as an immutable :class:`~.spec.OcpSpec`; raises OcpError.

        The consistency pass runs once: the spec is kept and returned again until a
        declaration changes the problem."""
        if self._spec is None:
            spec = self.build_spec()
            self._spec = spec
        return self._spec

    def build_spec(self) -> OcpSpec:
        """One consistency pass over everything declared and a new spec from it; raises
        OcpError. :meth:`validate` calls it once and keeps the result."""
        if not self._states:
            raise OcpError("no state declared (use ocp.state(...))")
        if not self._controls:
            raise OcpError("no control declared (use ocp.control(...))")
        if self._xdot is None:
            raise OcpError("missing dynamics (use ocp.dynamics(xdot))")
        if self._N is None:
            raise OcpError("missing horizon (use ocp.horizon(N, dt))")
        if self._x0 is None:
            raise OcpError("missing initial state (use ocp.initial_state(x0))")
        nx = sum(d.size for d in self._states)
        nu = sum(d.size for d in self._controls)
        if self._xdot.size1() != nx:
            raise OcpError(f"dynamics: expected {nx} rows (one per state), got {self._xdot.size1()}")
        self._check_symbols(self._xdot, "dynamics", "xup")
        for i, c in enumerate(self._stage_costs):
            if c.numel() != 1:
                raise OcpError(f"stage cost {i}: must be a scalar, got {c.size1()} rows")
            self._check_symbols(c, "stage cost" if len(self._stage_costs) == 1 else f"stage cost {i}", "xup")
        for i, (res, _) in enumerate(self._stage_ls):
            self._check_symbols(res, f"stage least squares {i}", "xup")
        for i, c in enumerate(self._term_costs):
            if c.numel() != 1:
                raise OcpError(f"terminal cost {i}: must be a scalar, got {c.size1()} rows")
            self._check_symbols(c, "terminal cost" if len(self._term_costs) == 1 else f"terminal cost {i}", "xp")
        for i, (res, _) in enumerate(self._term_ls):
            self._check_symbols(res, f"terminal least squares {i}", "xp")
        for i, (g, *_, name, stages) in enumerate(self._path):
            self._check_symbols(g, f"path constraint {i}", "xup")
            out = [k for k in (stages or ()) if not 0 <= k <= self._N - 1]
            if out:
                what = f"path constraint '{name}'" if name is not None else f"path constraint {i}"
                raise OcpError(f"{what}: stage {out[0]} is outside 0..N-1 = 0..{self._N - 1}")
        for rows, _, stages, what in self._stage_ls_staged:
            self._check_symbols(rows, what, "xup")
            out = [k for k in stages if not 0 <= k <= self._N - 1]
            if out:
                raise OcpError(f"{what}: stage {out[0]} is outside 0..N-1 = 0..{self._N - 1}")
        for i, (r, *_) in enumerate(self._term_con):
            self._check_symbols(r, f"terminal constraint {i}", "xp")
        if self._options["hessian"] == "gauss-newton" and not self._stage_ls:
            raise OcpError("options: hessian='gauss-newton' needs stage_least_squares")
        x0 = self._full_vector(self._x0, nx, "initial state")
        N = self._N
        gx, gu = self._guess_arrays(nx, nu, N, x0)
        if self._campaign is not None and self._scenario is None:
            raise OcpError("campaign: needs a closed-loop scenario (ocp.scenario(...))")
        closed_loop = self._validate_scenario(nx) if self._scenario is not None else None
        if self._rates:
            x0, gx, closed_loop = self._with_memory(x0, gx, gu, closed_loop)
        return self._spec_parts(x0, gx, gu, closed_loop)

    def _memory_initial(self, decl, init) -> np.ndarray:
        return np.clip(np.zeros(decl.size), decl.lb, decl.ub) if init is None else init

    def _with_memory(self, x0, gx, gu, closed_loop):
        """Initial state, state guess and scenario extended by the memory states of the rate
        constraints: z_0 = the initial last control, z_k = the guessed u_{k-1}."""
        import dataclasses

        offsets, start = {}, 0
        for d in self._controls:
            offsets[d.name] = start
            start += d.size
        init = np.concatenate([self._memory_initial(decl, ini) for decl, _, _, _, ini, *_ in self._rates])
        cols = [offsets[decl.name] + i for decl, *_ in self._rates for i in range(decl.size)]
        z = np.vstack([init.reshape(1, -1), gu[:, cols]])
        x0 = np.concatenate([x0, init])
        gx = np.hstack([gx, z])
        if closed_loop is not None:
            nz = init.size
            changes = {}
            if closed_loop.x0 is not None:
                changes["x0"] = readonly(np.concatenate([closed_loop.x0, init]))
            if closed_loop.plant is not None:
                changes["plant"] = ca.vertcat(closed_loop.plant, ca.SX.zeros(nz))
            if closed_loop.plant_q is not None:
                changes["plant_q"] = ca.vertcat(closed_loop.plant_q, ca.SX.zeros(nz))
            closed_loop = dataclasses.replace(closed_loop, **changes)
        return x0, gx, closed_loop

    def _spec_parts(self, x0, gx, gu, closed_loop) -> OcpSpec:
        """The immutable spec from declarations that passed validation."""
        def variables(decls):
            return tuple(Variable(d.name, d.size, d.sym, None if d.scale is None else readonly(d.scale))
                         for d in decls)

        def bounds(decls, which):
            return readonly(np.concatenate([getattr(d, which) for d in decls]))

        states = self._states + [r[5] for r in self._rates]
        soft_x = np.hstack([d.soft if d.soft is not None else np.zeros((4, d.size)) for d in states])
        xdot = self._xdot
        memory, path = [], list(self._path)
        path_scale = [(sc, None) for sc in self._path_scale]
        if self._rates:
            nz = sum(r[5].size for r in self._rates)
            xdot = ca.vertcat(self._xdot, ca.SX.zeros(nz))
            row = sum(d.size for d in self._states)
            offsets, start = {}, 0
            for d in self._controls:
                offsets[d.name] = start
                start += d.size
            for (decl, lbv, ubv, name, _, mem, weights), sc in zip(self._rates, self._rate_scale):
                memory += [(row + i, offsets[decl.name] + i) for i in range(decl.size)]
                row += decl.size
                path.append((decl.sym - mem.sym, lbv, ubv, weights, name, None))
                path_scale.append((sc, tuple(offsets[decl.name] + i for i in range(decl.size))))

        trajectory = ParameterTrajectory(tuple(
            (d.name, d.size, "constant", readonly(d.value)) if d.trajectory is None
            else (d.name, d.size, d.trajectory[0], d.trajectory[1]) for d in self._params))
        try:
            p_default = trajectory.at(0.0)
            for k in range(1, self._N + 1):    # every node of the first horizon
                trajectory.at(k * self._dt)
        except TrajectoryError as exc:
            raise OcpError(str(exc)) from None
        model = ModelSpec(states=variables(states), controls=variables(self._controls),
                          parameters=variables(self._params), xdot=xdot,
                          integrator=copy.copy(self._integrator), p_default=readonly(p_default),
                          p_trajectory=trajectory, memory=tuple(memory))
        cost = CostSpec(
            stage_terms=tuple(self._stage_costs),
            stage_least_squares=tuple(LeastSquares(r, readonly(W)) for r, W in self._stage_ls),
            terminal_terms=tuple(self._term_costs),
            terminal_least_squares=tuple(LeastSquares(r, readonly(W)) for r, W in self._term_ls))
        constraints = ConstraintSpec(
            lbx=bounds(states, "lb"), ubx=bounds(states, "ub"),
            lbu=bounds(self._controls, "lb"), ubu=bounds(self._controls, "ub"),
            path=tuple(Rows(g, readonly(lb), readonly(ub), sw, nm, st, None if sc is None else readonly(sc), sctl)
                       for (g, lb, ub, sw, nm, st), (sc, sctl) in zip(path, path_scale))
            + tuple(Rows(rows, readonly(np.zeros(d.size)), readonly(np.zeros(d.size)),
                         readonly(np.vstack([np.zeros(d.size), np.zeros(d.size), d, d])),
                         f"stage_least_squares_{i}", st, cost=True)
                    for i, (rows, d, st, _) in enumerate(self._stage_ls_staged)),
            terminal=tuple(Rows(r, readonly(lb), readonly(ub), sw, nm, None, None if sc is None else readonly(sc))
                           for (r, lb, ub, sw, nm, _), sc in zip(self._term_con, self._term_scale)),
            soft_x=readonly(soft_x))
        declared = (any(d.scale is not None for d in self._states + self._controls)
                    or any(sc is not None for sc in self._path_scale + self._term_scale + self._rate_scale)
                    or self._scaling["cost"] is not None or self._scaling["derive"] is not None)
        scaling = None
        if declared:
            def column(decls):
                return readonly(np.concatenate([d.scale if d.scale is not None else np.full(d.size, np.nan)
                                                for d in decls]))
            scaling = ScalingSpec(x=column(states), u=column(self._controls),
                                  cost=1.0 if self._scaling["cost"] is None else self._scaling["cost"],
                                  derive=self._scaling["derive"])
        return OcpSpec(name=self.name, model=model, cost=cost, constraints=constraints,
                       horizon=HorizonSpec(N=self._N, dt=self._dt),
                       options=OptionsSpec.of(self._options, self._declared), x0=readonly(x0),
                       guess=GuessSpec(x=readonly(gx), u=readonly(gu)),
                       scenario=ScenarioPart(disturbance=self._disturbance, closed_loop=closed_loop),
                       scaling=scaling)

    @staticmethod
    def _full_vector(value, n: int, what: str) -> np.ndarray:
        try:
            a = np.array(value, dtype=float)
        except (TypeError, ValueError) as exc:
            raise OcpError(f"{what}: expected {n} numbers ({exc})") from None
        if a.size != n or a.ndim > 2 or (a.ndim == 2 and 1 not in a.shape):
            raise OcpError(f"{what}: expected {n} values, got shape {a.shape}")
        a = a.reshape(n)
        if not np.all(np.isfinite(a)):
            raise OcpError(f"{what}: non-finite value (NaN or inf) at row {int(np.flatnonzero(~np.isfinite(a))[0])}")
        return a

    def _guess_arrays(self, nx: int, nu: int, N: int, x0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The initial guess as (N+1, nx), (N, nu) arrays; defaults: x0 everywhere, u = 0
        clipped into the control bounds."""
        def full(value, rows, n, what, default):
            if value is None:
                return np.tile(default, (rows, 1))
            try:
                a = np.array(value, dtype=float)
            except (TypeError, ValueError) as exc:
                raise OcpError(f"{what}: expected numbers ({exc})") from None
            if a.ndim == 0 and n == 1:
                a = np.full((rows, 1), float(a))
            elif a.ndim == 1 and a.size == n:
                a = np.tile(a, (rows, 1))
            elif a.ndim == 2 and a.shape == (rows, n):
                a = a.copy()
            elif n == 1 and a.ndim == 1 and a.size == rows:
                a = a.reshape(rows, 1)
            else:
                raise OcpError(f"{what}: expected {n} values or a ({rows}, {n}) array, got shape {a.shape}")
            if not np.all(np.isfinite(a)):
                bad = np.argwhere(~np.isfinite(a))[0]
                raise OcpError(f"{what}: non-finite value (NaN or inf) at node {bad[0]}, row {bad[1]}")
            return a

        lbu = np.concatenate([d.lb for d in self._controls])
        ubu = np.concatenate([d.ub for d in self._controls])
        gx = full(self._guess_x, N + 1, nx, "initial guess x", x0)
        gu = full(self._guess_u, N, nu, "initial guess u", np.clip(np.zeros(nu), lbu, ubu))
        return gx, gu

    def _validate_scenario(self, nx: int) -> ClosedLoopSpec:
        sc = self._scenario
        try:
            dur = float(sc["duration"])
        except (TypeError, ValueError):
            raise OcpError(f"scenario: duration must be a number, got {sc['duration']!r}") from None
        if not math.isfinite(dur) or dur <= 0:
            raise OcpError(f"scenario: duration must be positive and finite, got {sc['duration']!r}")
        events = []
        for i, ev in enumerate(sc["events"]):
            if not isinstance(ev, Event):
                raise OcpError(f"scenario event {i}: expected Event(time, fn, label), got {type(ev).__name__}")
            if not callable(ev.fn):
                raise OcpError(f"scenario event {i} ('{ev.label}'): fn is not callable")
            try:
                t = float(ev.time)
            except (TypeError, ValueError):
                raise OcpError(f"scenario event {i} ('{ev.label}'): time must be a number") from None
            if not (0 <= t <= dur):
                raise OcpError(f"scenario event {i} ('{ev.label}'): time {t} outside [0, {dur}]")
            events.append(Event(time=t, fn=ev.fn, label=ev.label))
        signals = []
        for name, expr in sc["signals"].items():
            if not isinstance(name, str) or not name:
                raise OcpError(f"scenario signal {name!r}: the name must be a non-empty string")
            e = _as_sx(expr, f"scenario signal '{name}'")
            self._check_symbols(e, f"scenario signal '{name}'", "xup")
            signals.append((name, e))
        plant, plant_q = None, None
        if sc["plant"] is not None:
            plant = _as_sx(sc["plant"], "scenario plant")
            if plant.size1() != nx:
                raise OcpError(f"scenario plant: expected {nx} rows (one per state), got {plant.size1()}")
            if self._quantities:
                plant_q = plant
                plant = ca.substitute(plant, ca.vertcat(*[q for _, q, _ in self._quantities]),
                                      ca.DM([v for _, _, v in self._quantities]))
            self._check_symbols(plant, "scenario plant", "xup")
        x0 = None
        if sc["x0"] is not None:
            x0 = readonly(self._full_vector(sc["x0"], nx, "scenario x0"))
        known = {n for n, _ in signals} | {d.name for d in self._states + self._controls}
        units = []
        for key, unit in sc.get("units", {}).items():
            if key not in known and key != "time":
                raise OcpError(f"scenario units: {key!r} is neither a signal nor a state or control (nor 'time'); "
                               f"the names are {sorted(known)}")
            if not isinstance(unit, str) or not unit.strip():
                raise OcpError(f"scenario units: the unit of {key!r} must be a non-empty string, got {unit!r}")
            units.append((key, unit.strip()))
        campaign = self._validate_campaign() if self._campaign is not None else None
        return ClosedLoopSpec(duration=dur, events=tuple(events), signals=tuple(signals), plant=plant, x0=x0,
                              units=tuple(units), quantities=tuple(self._quantities), plant_q=plant_q,
                              campaign=campaign)

    def _state_rows(self, table, what: str) -> tuple:
        """((rows, half-widths), ...) of a dict state name -> half-width (a number or one per
        component, finite and >= 0)."""
        offsets, start = {}, 0
        for d in self._states:
            offsets[d.name] = (start, d.size)
            start += d.size
        out = []
        for name, width in table.items():
            if name not in offsets:
                raise OcpError(f"campaign {what}: {name!r} is not a state; the states are {sorted(offsets)}")
            first, size = offsets[name]
            try:
                a = np.broadcast_to(np.asarray(width, dtype=float), (size,)).copy()
            except (TypeError, ValueError):
                raise OcpError(f"campaign {what} '{name}': expected one number or {size}, got {width!r}") from None
            if not np.all(np.isfinite(a)) or np.any(a < 0):
                raise OcpError(f"campaign {what} '{name}': half-widths must be finite and >= 0, got {width!r}")
            out.append((tuple(range(first, first + size)), tuple(float(v) for v in a)))
        return tuple(out)

    def _validate_campaign(self) -> CampaignSpec:
        """The campaign declaration on its own; what depends on the scenario as finally
        declared (the on-path signal, a plant that uses the quantities) is checked by the
        campaign, so that a file may declare its scenario again after the campaign."""
        cp = self._campaign
        known = {n: v for n, _, v in self._quantities}
        mismatch = []
        for name, r in cp["mismatch"].items():
            if name not in known:
                raise OcpError(f"campaign mismatch: {name!r} is not a plant quantity (ocp.plant_quantity); "
                               f"the plant quantities are {sorted(known) or 'none'}")
            try:
                r = float(r)
            except (TypeError, ValueError):
                raise OcpError(f"campaign mismatch '{name}': expected a number in [0, 1), got {r!r}") from None
            if not (0 <= r < 1):
                raise OcpError(f"campaign mismatch '{name}': the relative half-width must be in [0, 1), got {r!r}")
            mismatch.append((name, r))
        initial = self._state_rows(cp["initial"], "initial")
        count, window, kick = (0, 0), (0.0, 0.0), ()
        pu = cp["pushes"]
        if pu is not None:
            c = pu.count if isinstance(pu.count, (tuple, list)) else (pu.count, pu.count)
            if (len(c) != 2 or any(isinstance(v, bool) or not isinstance(v, (int, np.integer)) for v in c)
                    or not 0 <= c[0] <= c[1]):
                raise OcpError(f"campaign pushes: count must be an integer >= 0 or (min, max), got {pu.count!r}")
            try:
                t0, t1 = (float(v) for v in pu.window)
            except (TypeError, ValueError):
                raise OcpError(f"campaign pushes: window must be (t0, t1) seconds, got {pu.window!r}") from None
            if not (math.isfinite(t0) and math.isfinite(t1) and 0 <= t0 <= t1):
                raise OcpError(f"campaign pushes: window must satisfy 0 <= t0 <= t1, got {pu.window!r}")
            if not isinstance(pu.kick, Mapping) or not pu.kick:
                raise OcpError(f"campaign pushes: kick must be a non-empty dict state name -> half-width, "
                               f"got {pu.kick!r}")
            count, window, kick = (int(c[0]), int(c[1])), (t0, t1), self._state_rows(pu.kick, "pushes kick")
        on_path = None
        if cp["on_path"] is not None:
            op = cp["on_path"]
            if not isinstance(op.signal, str) or not op.signal:
                raise OcpError(f"campaign on_path: signal must be the name of a scenario signal, got {op.signal!r}")
            try:
                thr, settle = float(op.threshold), float(op.settle)
            except (TypeError, ValueError):
                raise OcpError("campaign on_path: threshold and settle must be numbers") from None
            if not (math.isfinite(thr) and thr > 0 and math.isfinite(settle) and settle >= 0):
                raise OcpError(f"campaign on_path: threshold must be > 0 and settle >= 0, got {op.threshold!r}, "
                               f"{op.settle!r}")
            on_path = (op.signal, thr, settle)
        runs, dur = cp["runs"], cp["duration"]
        if runs is not None and (isinstance(runs, bool) or not isinstance(runs, (int, np.integer)) or runs < 1):
            raise OcpError(f"campaign: runs must be an integer >= 1, got {runs!r}")
        if dur is not None:
            try:
                dur = float(dur)
            except (TypeError, ValueError):
                raise OcpError(f"campaign: duration must be a number, got {dur!r}") from None
            if not (math.isfinite(dur) and dur > 0):
                raise OcpError(f"campaign: duration must be positive and finite, got {cp['duration']!r}")
        return CampaignSpec(mismatch=tuple(mismatch), initial=initial, push_count=count, push_window=window,
                            push_kick=kick, on_path=on_path, runs=None if runs is None else int(runs), duration=dur)


# --------------------------------------------------------------------------- loading
def load_ocp(path) -> Ocp:
    """Import an OCP file, call its ``build()`` and validate the result."""
    p = Path(path)
    if not p.exists():
        raise OcpError(f"OCP file '{path}' does not exist")
    if not p.is_file():
        raise OcpError(f"OCP file '{path}' is not a file")
    try:
        source = p.read_text()
    except OSError as exc:
        raise OcpError(f"OCP file '{path}': cannot read it ({exc})") from None
    try:
        code = compile(source, str(p), "exec")
    except SyntaxError as exc:
        raise OcpError(f"OCP file '{path}', line {exc.lineno}: syntax error: {exc.msg}") from None
    modname = f"_dopus_ocp_{re.sub(r'[^0-9A-Za-z_]', '_', p.stem)}"
    spec = importlib.util.spec_from_file_location(modname, str(p))
    module = importlib.util.module_from_spec(spec)
    sys.modules[modname] = module
    try:
        exec(code, module.__dict__)  # noqa: S102 - running the user's OCP file is the point
    except OcpError:
        raise
    except Exception as exc:  # noqa: BLE001 - any failure of user code gets the file and line
        raise OcpError(f"OCP file '{path}'{_user_line(exc, p)}: {type(exc).__name__}: "
                       f"{casadi_message(exc)}") from None
    build = getattr(module, "build", None)
    if not callable(build):
        raise OcpError(f"OCP file '{path}' defines no build() function")
    try:
        ocp = build()
    except OcpError:
        raise
    except Exception as exc:  # noqa: BLE001
        raise OcpError(f"OCP file '{path}'{_user_line(exc, p)}: build() failed: {type(exc).__name__}: "
                       f"{casadi_message(exc)}") from None
    if not isinstance(ocp, Ocp):
        raise OcpError(f"OCP file '{path}': build() returned {type(ocp).__name__}, expected an Ocp")
    from .checks import warn_nonsmooth

    warn_nonsmooth(ocp.validate())
    return ocp


def _user_line(exc: BaseException, path: Path) -> str:
    """', line L' of the innermost frame in the OCP file, if any."""
    line = None
    for frame in traceback.extract_tb(exc.__traceback__):
        if Path(frame.filename) == path:
            line = frame.lineno
    return f", line {line}" if line is not None else ""
