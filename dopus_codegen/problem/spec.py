"""The validated problem: a public, immutable specification made of small frozen parts.

:meth:`~dopus_codegen.problem.ocp.Ocp.validate` returns an :class:`OcpSpec`; everything
after it (:func:`~dopus_codegen.problem.discretize.discretize`,
:func:`~dopus_codegen.problem.derivatives.build_functions`) reads only this object, never
the :class:`Ocp` that declared it.

Immutability: every part is a frozen dataclass (assigning a field raises
``dataclasses.FrozenInstanceError``), sequences are tuples, and every numpy array is a
read-only copy (writing into it raises ``ValueError``). The CasADi expressions are the
SX objects the OCP was declared with, and the callables (event maps, the disturbance)
are the user's functions: both are shared, not copied.

Conventions are those of docs/algorithm.md section 1: ``w = (x, u)`` stacks states and
controls in declaration order; state bounds hold on nodes ``1..N``, control bounds and
path constraints on stages ``0..N-1``; a terminal row with ``lb == ub`` is an equality row.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, Dict, Optional, Tuple

import casadi as ca
import numpy as np

from ..settings import DEFAULTS, FILE_SETTINGS, Settings


class OcpError(ValueError):
    """A mistake in the OCP description; the message names the offending item."""

__all__ = [
    "readonly", "Variable", "ParameterTrajectory", "ModelSpec", "LeastSquares", "CostSpec", "Rows", "ConstraintSpec",
    "HorizonSpec", "OptionsSpec", "GuessSpec", "ClosedLoopSpec", "CampaignSpec", "ScenarioPart", "OcpSpec",
    "ScalingSpec",
]


def readonly(value, shape=None) -> np.ndarray:
    """A read-only float copy of ``value`` (reshaped to ``shape`` when given)."""
    a = np.array(value, dtype=float, copy=True)
    if shape is not None:
        a = a.reshape(shape)
    a.setflags(write=False)
    return a


def _labels(variables) -> Tuple[str, ...]:
    out = []
    for v in variables:
        out += [v.name] if v.size == 1 else [f"{v.name}[{i}]" for i in range(v.size)]
    return tuple(out)


def _stack_syms(variables) -> ca.SX:
    return ca.vertcat(*[v.sym for v in variables]) if variables else ca.SX(0, 1)


# --------------------------------------------------------------------------- model
@dataclass(frozen=True)
class Variable:
    """One declared state, control or parameter vector (``sym`` is its SX symbol); ``scale``:
    the declared scale per component (NaN: not declared), None when none is declared."""
    name: str
    size: int
    sym: ca.SX
    scale: Optional[np.ndarray] = None


class TrajectoryError(ValueError):
    """A declared parameter trajectory failed at some time (the message names it)."""


@dataclass(frozen=True)
class ParameterTrajectory:
    """The stacked parameter vector as a function of time (seconds from the start of a run).

    ``parts``: one ``(name, size, kind, data)`` per declared parameter, in declaration
    order: ``kind`` ``"constant"`` (``data``: its value), ``"function"`` (``data``: the
    user's ``t -> size values``) or ``"table"`` (``data``: ``(times, values)``, linear
    interpolation, held constant before the first and after the last time)."""
    parts: Tuple[Tuple[str, int, str, Any], ...]

    @property
    def time_varying(self) -> bool:
        return any(kind != "constant" for _, _, kind, _ in self.parts)

    def at(self, t: float) -> np.ndarray:
        """``p(t)``, shape ``(np,)``; raises :class:`TrajectoryError` naming the parameter."""
        out = []
        for name, size, kind, data in self.parts:
            if kind == "constant":
                out.append(np.asarray(data, dtype=float).reshape(size))
                continue
            if kind == "table":
                times, values = data
                v = np.array([np.interp(t, times, values[:, i]) for i in range(size)])
            else:
                try:
                    v = np.array(data(float(t)), dtype=float)
                except Exception as exc:  # noqa: BLE001 - the user's function
                    raise TrajectoryError(f"parameter '{name}' trajectory at t = {t:g} s failed: "
                                          f"{type(exc).__name__}: {exc}") from None
                if v.size != size:
                    raise TrajectoryError(f"parameter '{name}' trajectory at t = {t:g} s: expected {size} "
                                          f"values, got shape {v.shape}")
            v = v.reshape(size)
            if not np.all(np.isfinite(v)):
                raise TrajectoryError(f"parameter '{name}' trajectory at t = {t:g} s: non-finite value {v}")
            out.append(v)
        return np.concatenate(out) if out else np.zeros(0)

    def horizon(self, t0: float, N: int, dt: float) -> np.ndarray:
        """``(N+1, np)``: node ``k`` at time ``t0 + k dt``."""
        rows = [self.at(t0 + k * dt) for k in range(N + 1)]
        return np.array(rows, dtype=float).reshape(N + 1, -1)


@dataclass(frozen=True)
class ModelSpec:
    """States, controls, parameters, the continuous model ``xdot = f(x, u, p)`` and the
    integrator that maps it to the interval map ``phi`` (the integrator is a private copy
    of the declared one). ``p_default (np,)``: the parameters' default values (at t = 0);
    ``p_trajectory``: the parameters over time (:class:`ParameterTrajectory`; constant
    unless a parameter declares a trajectory)."""
    states: Tuple[Variable, ...]
    controls: Tuple[Variable, ...]
    parameters: Tuple[Variable, ...]
    xdot: ca.SX
    integrator: Any
    p_default: np.ndarray
    p_trajectory: Optional[ParameterTrajectory] = None
    #: memory states of rate constraints (``Ocp.rate_constraint``): ``(state row, control
    #: row)`` pairs; the state carries the control of the previous interval (x+ = u there,
    #: not integrated), at x_0 the last applied control, which the runtime keeps
    memory: Tuple[Tuple[int, int], ...] = ()

    @property
    def x(self) -> ca.SX:
        return _stack_syms(self.states)

    @property
    def u(self) -> ca.SX:
        return _stack_syms(self.controls)

    @property
    def p(self) -> ca.SX:
        return _stack_syms(self.parameters)

    @property
    def nx(self) -> int:
        return sum(v.size for v in self.states)

    @property
    def nu(self) -> int:
        return sum(v.size for v in self.controls)

    @property
    def np(self) -> int:
        return sum(v.size for v in self.parameters)

    @property
    def state_names(self) -> Tuple[str, ...]:
        """One label per state row: ``name`` or ``name[i]``."""
        return _labels(self.states)

    @property
    def control_names(self) -> Tuple[str, ...]:
        return _labels(self.controls)

    @property
    def parameter_names(self) -> Tuple[str, ...]:
        return _labels(self.parameters)


# --------------------------------------------------------------------------- cost
@dataclass(frozen=True)
class LeastSquares:
    """A term ``0.5 residual' weights residual`` (``weights`` symmetric positive
    semidefinite, ``(n, n)`` for a residual of ``n`` rows)."""
    residual: ca.SX
    weights: np.ndarray


@dataclass(frozen=True)
class CostSpec:
    """Stage cost ``l = sum 0.5 r' W r + sum stage_terms`` (per interval, as written) and
    terminal cost ``E = sum 0.5 r' W r + sum terminal_terms``, terms in declaration order."""
    stage_terms: Tuple[ca.SX, ...]
    stage_least_squares: Tuple[LeastSquares, ...]
    terminal_terms: Tuple[ca.SX, ...]
    terminal_least_squares: Tuple[LeastSquares, ...]

    @property
    def has_stage_least_squares(self) -> bool:
        """True when a Gauss-Newton stage Hessian exists."""
        return bool(self.stage_least_squares)


# --------------------------------------------------------------------------- constraints
@dataclass(frozen=True)
class Rows:
    """Constraint rows ``lb <= expr <= ub`` (infinite entries allowed); ``soft``: None (hard
    rows) or the ``(4, n)`` weights ``(l1 lower, l1 upper, l2 lower, l2 upper)`` of soft rows
    (a side with both weights 0 is hard)."""
    expr: ca.SX
    lb: np.ndarray
    ub: np.ndarray
    soft: Optional[np.ndarray] = None
    name: Optional[str] = None    # the declared name (messages, tables, the C row names)
    stages: Optional[Tuple[int, ...]] = None   # path rows: the stages where they hold (None: all)
    scale: Optional[np.ndarray] = None   # the declared scale per row (NaN: not declared), or None
    #: rate rows: the control rows whose scales are the rows' scales when none is declared
    scale_controls: Optional[Tuple[int, ...]] = None
    cost: bool = False    # a least-squares term on chosen stages carried as soft rows (not a constraint)

    def labels(self, kind: str, index: int) -> Tuple[str, ...]:
        """One label per row: ``name`` / ``name[i]``, or ``<kind> <index>`` / ``<kind> <index> row i``."""
        n = self.expr.size1()
        if self.name is not None:
            return (self.name,) if n == 1 else tuple(f"{self.name}[{i}]" for i in range(n))
        return (f"{kind} {index}",) if n == 1 else tuple(f"{kind} {index} row {i}" for i in range(n))

    def soft_weights(self) -> np.ndarray:
        """The ``(4, n)`` weights, zeros for hard rows."""
        return self.soft if self.soft is not None else np.zeros((4, self.lb.size))


@dataclass(frozen=True)
class ConstraintSpec:
    """Simple bounds ``lbx, ubx (nx,)`` (nodes 1..N), ``lbu, ubu (nu,)`` (stages 0..N-1),
    path rows ``g(x, u, p)`` (stages 0..N-1) and terminal rows ``r(x_N, p)``, each block in
    declaration order. ``soft_x (4, nx)``: the soft weights of the state bounds (zeros: hard;
    rows as in :class:`Rows`)."""
    lbx: np.ndarray
    ubx: np.ndarray
    lbu: np.ndarray
    ubu: np.ndarray
    path: Tuple[Rows, ...]
    terminal: Tuple[Rows, ...]
    soft_x: Optional[np.ndarray] = None

    @property
    def terminal_equality(self) -> np.ndarray:
        """Over the stacked terminal rows: True where ``lb == ub`` and the row is hard (an
        equality row; a soft row with ``lb == ub`` stays an inequality row)."""
        if not self.terminal:
            eq = np.zeros(0, dtype=bool)
        else:
            eq = np.concatenate([b.lb for b in self.terminal]) == np.concatenate([b.ub for b in self.terminal])
            soft = np.concatenate([np.any(b.soft_weights() > 0, axis=0) for b in self.terminal])
            eq = eq & ~soft
        eq.setflags(write=False)
        return eq


# --------------------------------------------------------------------------- horizon, options
@dataclass(frozen=True)
class HorizonSpec:
    """``N`` shooting intervals of ``dt`` seconds (``dt`` is also the sampling time)."""
    N: int
    dt: float


@dataclass(frozen=True)
class OptionsSpec:
    """The OCP file's ``options(...)``: the settings of its solver (one
    :class:`~dopus_codegen.settings.Settings`: the generated solver's defaults, and those of
    every command and handle built from the file), the generation options ``real`` and
    ``offline_guess``, the relative KKT tolerance ``kkt_tol_rel`` of the studies, and the
    names the file gave (the rest are defaults)."""
    settings: Settings
    real: str = "double"        # real-number type of the generated C: "double" or "float"
    offline_guess: bool = False
    declared: frozenset = frozenset()
    kkt_tol_rel: Optional[float] = None   # the relative KKT tolerance of converge and sil (None: absolute)

    @classmethod
    def of(cls, values: Dict[str, Any], declared=()) -> "OptionsSpec":
        """The options of ``values`` (checked, any of :data:`~dopus_codegen.settings.FILE_SETTINGS`)."""
        return cls(settings=Settings.of(values), real=values.get("real", DEFAULTS["real"]),
                   offline_guess=values.get("offline_guess", DEFAULTS["offline_guess"]), declared=frozenset(declared),
                   kkt_tol_rel=values.get("kkt_tol_rel", DEFAULTS["kkt_tol_rel"]))

    def as_dict(self) -> Dict[str, Any]:
        """Every option of the file by name (declared or default)."""
        solver = self.settings.as_dict()
        return {name: solver[name] if name in solver else getattr(self, name) for name in FILE_SETTINGS}


@dataclass(frozen=True)
class GuessSpec:
    """The declared (cold) initial guess: ``x (N+1, nx)``, ``u (N, nu)``."""
    x: np.ndarray
    u: np.ndarray


# --------------------------------------------------------------------------- scenario
@dataclass(frozen=True)
class CampaignSpec:
    """The declared Monte Carlo campaign of ``dopus-gen campaign`` (``Ocp.campaign``), with
    state names resolved to rows of ``x``.

    ``mismatch``: ((plant quantity, relative half-width), ...): the plant of a run scales the
    quantity's nominal value by a factor uniform in ``[1 - r, 1 + r]``; ``initial``: ((state
    rows, half-widths), ...): offsets uniform in ``[-a, a]`` added to the scenario's initial
    state; ``push_count`` (min, max), ``push_window`` (t0, t1) seconds and ``push_kick``
    ((state rows, half-widths), ...): every run has a number of pushes uniform in
    ``min..max``, each at a time uniform in the window, adding uniform offsets in ``[-a, a]``
    to those rows; ``on_path``: (signal, threshold, settle) or None; ``runs``, ``duration``:
    None when not declared."""
    mismatch: Tuple[Tuple[str, float], ...] = ()
    initial: Tuple[Tuple[Tuple[int, ...], Tuple[float, ...]], ...] = ()
    push_count: Tuple[int, int] = (0, 0)
    push_window: Tuple[float, float] = (0.0, 0.0)
    push_kick: Tuple[Tuple[Tuple[int, ...], Tuple[float, ...]], ...] = ()
    on_path: Optional[Tuple[str, float, float]] = None
    runs: Optional[int] = None
    duration: Optional[float] = None


@dataclass(frozen=True)
class ClosedLoopSpec:
    """The declared closed-loop scenario: ``duration`` seconds, state ``events`` (sorted as
    declared), recorded ``signals`` ((name, SX expression of x, u, p) pairs), the plant
    model ``plant`` (None: the model itself), its initial state ``x0`` (None: the OCP's) and
    the ``units`` of signals, states and controls ((name, unit) pairs) for the figures.

    ``quantities``: the plant quantities ((name, SX symbol, nominal value), ...) declared with
    ``Ocp.plant_quantity``; ``plant`` has them replaced by their nominal values and
    ``plant_q`` (None without quantities) keeps the symbols; ``campaign``: the declared
    :class:`CampaignSpec` or None."""
    duration: float
    events: Tuple[Any, ...]
    signals: Tuple[Tuple[str, ca.SX], ...]
    plant: Optional[ca.SX]
    x0: Optional[np.ndarray]
    units: Tuple[Tuple[str, str], ...] = ()
    quantities: Tuple[Tuple[str, ca.SX, float], ...] = ()
    plant_q: Optional[ca.SX] = None
    campaign: Optional[CampaignSpec] = None


@dataclass(frozen=True)
class ScenarioPart:
    """What the studies use beyond the OCP: the ``disturbance`` state map of the
    warm-start convergence study and the closed-loop scenario of ``dopus-gen sil``."""
    disturbance: Optional[Callable[[np.ndarray], np.ndarray]]
    closed_loop: Optional[ClosedLoopSpec]


# --------------------------------------------------------------------------- scaling
@dataclass(frozen=True)
class ScalingSpec:
    """The declared scaling (``Ocp.scaling`` and the ``scale=`` of the declarations): ``x
    (nx,)``, ``u (nu,)`` the declared scales (NaN: not declared: 1, or derived), ``cost`` the
    cost scale, ``derive`` None, ``"bounds"`` or ``"nominal"``: how the scales not declared are
    derived (docs/algorithm.md section 16). The row scales are those of :class:`Rows`."""
    x: np.ndarray
    u: np.ndarray
    cost: float = 1.0
    derive: Optional[str] = None


# --------------------------------------------------------------------------- the whole
@dataclass(frozen=True)
class OcpSpec:
    """One validated OCP. ``x0 (nx,)`` is the initial state ``xhat_0`` of the examples, the
    default guess and the scenario."""
    name: str
    model: ModelSpec
    cost: CostSpec
    constraints: ConstraintSpec
    horizon: HorizonSpec
    options: OptionsSpec
    x0: np.ndarray
    guess: GuessSpec
    scenario: ScenarioPart
    scaling: Optional[ScalingSpec] = None   # None: the problem is solved in its own units
