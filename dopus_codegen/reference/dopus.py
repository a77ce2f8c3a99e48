"""The pure-Python DOPUS reference implementation (the oracle of the C runtime).

Implements docs/algorithm.md sections 3 to 7 literally, with numpy, the per-stage CasADi
functions of a ``Discretized`` and the reference QP solver of
:mod:`dopus_codegen.reference.qp`. The C runtime is compared against it iterate by iterate, so
the order of operations follows the contract:

- the ring buffer: stage ``k`` lives in slot ``(ring_head + k) mod N``; a slot holds the
  blocks the QP uses (``Ht, Phit, Ct``), ``A_dyn = A - A_l`` of its last H evaluation,
  ``F_old = (F_w, phi, g)`` of the last gradient evaluation of its stage and
  ``domega = (dw, dlam_next, dmu_g, dmu_b)`` of the last QP;
- ``feedback`` solves the QP, stores ``domega`` per stage, takes the full step;
- ``prepare`` shifts (receding mode), evaluates ``F_k`` and ``rho_k`` (eq. 16) for
  ``k < N-1``, evaluates stage ``N-1`` and the terminal node fresh, recomputes ``H`` for
  the ``M`` stages with the largest ``rho`` (ties: lower index), with
  ``cost_hessian="fresh"`` (default) refreshes the stage-cost Hessian ``A_l`` of every
  other stage (``Ht = reg(A_dyn + A_l)``; ``"stored"`` is the paper's literal algorithm),
  regularises every fresh ``A`` (section 5) and assembles the adjoint-corrected QP
  (eq. 12, section 3).

Usage (the backend protocol of section 7)::

    ref = ReferenceDopus(disc, M=1, mode="receding", hessian="exact")
    ref.init(xhat0, guess)
    u0 = ref.feedback(xhat0); ref.prepare()
"""
from __future__ import annotations

import time
from typing import Optional

import numpy as np

from .. import settings, vocabulary
from ..errors import PARAMETER_ORDER, DopusError, qp_status_code as status_code_qp, status_code
from ..settings import SettingError, Settings, check_adaptive_M, of_problem as settings_of_problem
from .kkt import eval_stages, kkt_measure, node_parameters
from ..problem.checks import describe_qp_row
from ..problem.derivatives import cost_hessian_constant
from .qp import QPError, free_initial_state, solve_qp_reference

# the QP solution arrays whose finiteness a step needs
FIELDS_QP = ("x", "u", "lam", "mu_g", "mu_b", "mu_bN", "mu_r", "nu")
#: the C QP's floor of a warm start's multipliers (WARM_FLOOR_Z of runtime_c/dopus_qp.c): the
#: point of a QP cut by its deadline before its first iteration (section 14)
QP_WARM_FLOOR_Z = 1e-2

__all__ = ["DopusError", "ReferenceDopus", "regularize", "EPS_RHO", "FLAGS"]

#: Health flags (enum dopus_flag of runtime_c/dopus_solver.h): bit -> name.
FLAGS = {bit: name for name, bit in vocabulary.enum("dopus_flag").codes.items()}
_FLAG = vocabulary.enum("dopus_flag").codes
#: The safety constants of runtime_c/dopus_solver.h (docs/algorithm.md section 9).
_SAFETY = vocabulary.constants()

#: Default KKT-proxy target of the anytime iterations (DOPUS_ANYTIME_TOL, double).
ANYTIME_TOL = float(_SAFETY["ANYTIME_TOL"])


# Round-off floor of the secant residual (docs/algorithm.md section 4 step 2): rho_k = 0
# when num_k <= EPS_RHO * (|F_old| + |F_new|), i.e. when the linear model of the stage is
# exact along its last step to within the round-off of the F values it is formed from.
EPS_RHO = 1e-12


def regularize(A: np.ndarray, mode: str, eps: float) -> np.ndarray:
    """Section 5: eigenvalue floor on the symmetric block ``A`` (``none`` returns it as is)."""
    if mode == "none":
        return A
    S = 0.5 * (A + A.T)
    e, V = np.linalg.eigh(S)
    if mode == "project":
        e = np.maximum(e, eps)
    elif mode == "mirror":
        e = np.maximum(np.abs(e), eps)
    else:
        settings.check("regularization", mode)
    return (V * e) @ V.T


class _Slot:
    """One ring-buffer slot (docs/algorithm.md section 4)."""
    __slots__ = ("Ht", "Phit", "Ct", "F_w", "phi", "g", "dw", "dlam", "dmu_g", "dmu_b", "A_dyn", "dw_acc")

    def __init__(self, nx, nu, ng):
        nw = nx + nu
        self.Ht = np.zeros((nw, nw))
        self.A_dyn = np.zeros((nw, nw))
        self.Phit = np.zeros((nx, nw))
        self.Ct = np.zeros((ng, nw))
        self.F_w = np.zeros(nw)
        self.phi = np.zeros(nx)
        self.g = np.zeros(ng)
        self.dw = np.zeros(nw)
        self.dlam = np.zeros(nx)
        self.dmu_g = np.zeros(ng)
        self.dmu_b = np.zeros(nw)
        # the steps dw since the last gradient evaluation, summed: how far the linear model's
        # point has moved (the order of an anytime prepare's gradients, section 14)
        self.dw_acc = np.zeros(nw)

    def copy(self):
        s = _Slot.__new__(_Slot)
        for name in _Slot.__slots__:
            setattr(s, name, getattr(self, name).copy())
        return s


def _path_bounds(disc, N: int, ng: int):
    """The path-row bounds per stage ``(N, ng)`` (``path_constraint(stages=...)``)."""
    data = getattr(disc, "data", None)
    if data is not None and hasattr(data, "path_bounds"):
        lo, up = data.path_bounds()
        return lo.reshape(N, ng), up.reshape(N, ng)
    return (np.tile(np.asarray(disc.lg, float).reshape(1, ng), (N, 1)),
            np.tile(np.asarray(disc.ug, float).reshape(1, ng), (N, 1)))


def _arr(v, shape, what):
    a = np.array(v, dtype=float)
    if a.size != int(np.prod(shape)):
        raise DopusError.of("invalid_argument", f"{what}: expected shape {shape}, got {a.shape}")
    return a.reshape(shape)


def _setting(check, *args, **kwargs):
    """A value checked by :mod:`dopus_codegen.settings`; a bad one is DopusError (invalid
    argument), as the C backend reports it."""
    try:
        return check(*args, **kwargs)
    except SettingError as exc:
        raise DopusError.of("invalid_argument", str(exc)) from None


class ReferenceDopus:
    """The DOPUS iteration in numpy (backend protocol, docs/algorithm.md section 7).

    Extra to the protocol: :meth:`qp_of_current` (the QP the next ``feedback`` solves,
    in the :mod:`dopus_codegen.reference.qp` format), ``last_qp`` / ``last_qp_solution`` (the
    QP solved by the last ``feedback`` and its solution), ``status`` and
    ``qp_infeasible_row`` (the row that makes the last QP infeasible, as ``Solver`` gives it).
    """

    def __new__(cls, disc=None, *args, **kwargs):
        # a scaled problem (docs/algorithm.md section 16): the iteration runs on disc.scaled and
        # the API converts at its boundary
        if cls is ReferenceDopus and getattr(disc, "scaled", None) is not None:
            from .scaled import ScaledReference

            return ScaledReference(ReferenceDopus(disc.scaled, *args, **kwargs), disc)
        return super().__new__(cls)

    def __init__(self, disc, settings: Optional[Settings] = None, **changes):
        """``settings``: the solver's settings (None: the OCP file's ``options(...)`` of
        ``disc``); ``changes``: settings changed from them by name (``M=3``; None: not given).
        A QP tolerance of None is that of double precision."""
        self.disc = disc
        if settings is None:
            settings = settings_of_problem(disc)
        elif not isinstance(settings, Settings):
            raise DopusError.of("invalid_argument", f"settings must be a Settings, got {settings!r}")
        s = _setting(settings.replace, **changes)
        self.cost_hessian = s.cost_hessian
        self.N, self.nx, self.n_u, self.ng = disc.N, disc.nx, disc.nu, disc.ng
        self.nr, self.ne, self.np = disc.nr, disc.ne, disc.np
        self.nw = self.nx + self.n_u
        self.hessian = s.hessian
        self.has_gn = (getattr(disc, "stage_hess_gn", None) is not None
                       and getattr(disc, "term_hess_gn", None) is not None)
        if self.hessian != "exact" and not self.has_gn:
            raise DopusError.of("invalid_argument", "hessian='gauss-newton' needs a least-squares stage cost "
                                "(the OCP declares no stage_least_squares)")
        if s.cost_hessian == "fresh" and self._stage_hess_cost is None:
            raise DopusError.of("invalid_argument", "cost_hessian='fresh' needs the stage-cost Hessian function "
                                "of the problem (Discretized.stage_hess_cost); use cost_hessian='stored'")
        self.regularization = s.regularization
        self.reg_eps = s.reg_eps
        # a constant stage-cost Hessian: step 5 keeps the blocks (as the C runtime,
        # DOPUS_COST_HESS_CONST)
        exact_al = getattr(disc, "stage_hess_cost_exact", None)
        self._cost_hess_const = exact_al is not None and cost_hessian_constant(
            exact_al, getattr(disc, "stage_hess_cost_gn", None))
        self._al_resync = False     # step 5 once all the same (set_regularization)
        self.qp_tol = s.qp_tol_of("double")
        self.lm, self.lm_auto, self.lm_scale, self._lm_kkt_prev = 0.0, False, 1.0, -1.0
        # the prepared automatic term before this feedback's cap (-1: not capped; C's lm.uncapped)
        self.lm_uncapped = -1.0
        # the last prepare's convexity test raised the automatic term (C's lm.held; section 9)
        self.lm_held = False
        self.set_levenberg_marquardt(s.lm)
        self.qp_max_iter = None
        if s.qp_max_iter is not None:
            self.set_qp_max_iter(s.qp_max_iter)
        self.qp_status = 0
        self.set_M(s.M)
        self.set_mode(s.mode)
        self.lbx, self.ubx = np.asarray(disc.lbx, float), np.asarray(disc.ubx, float)
        self.lbu, self.ubu = np.asarray(disc.lbu, float), np.asarray(disc.ubu, float)
        self.lg, self.ug = np.asarray(disc.lg, float).reshape(self.ng), np.asarray(disc.ug, float).reshape(self.ng)
        self.lg_k, self.ug_k = _path_bounds(disc, self.N, self.ng)     # per stage (stages=)
        self.lr, self.ur = np.asarray(disc.lr, float).reshape(self.nr), np.asarray(disc.ur, float).reshape(self.nr)
        self.p = node_parameters(disc, None)
        self.status = status_code("ok")
        self.timings = {}
        self.qp_iterations = 0
        self.qp_factorizations = 0
        self.rho = np.zeros(self.N)
        self.recomputed = []
        self.last_qp = None
        self.last_qp_solution = None
        self._initialised = False
        # calling order (docs/algorithm.md section 4): a prepared QP, a prepare due, the shift
        # of this sampling instant done (a prepare failed after it)
        self._qp_ready = self._prepare_due = self._shifted = False
        self._p_shifted = False      # this sampling instant's parameters are shifted
        # section 9: safe outputs, divergence test, recovery
        self.recovery, self.recovery_failures = True, int(_SAFETY["RECOVERY_FAILURES"])
        self.scales = self._compute_scales()
        self._xhat_last = np.asarray(disc.x0, float).reshape(self.nx).copy()
        self._reset_health(np.asarray(disc.initial_guess.u, float).reshape(self.N, self.n_u))
        # section 14: the anytime budget (off), adaptive M (off), the work counter
        self.budget_unit, self.budget = s.budget_unit, s.budget
        self.anytime_tol = ANYTIME_TOL if s.anytime_tol is None else s.anytime_tol
        self.set_M_adaptive(s.M_adaptive, s.M_min, s.M_max, s.M_eta)
        self.gate, self.gate_hold = s.gate, s.gate_hold
        self.active_set_start = True    # False inside a globalised step: the QP from scratch
        self.work = 0.0
        self._instant_start = 0.0
        self._qp_deadline = None      # the deadline of the QPs of an instant (section 14)
        self._cost_stage = self._cost_qp = self._cost_prepare = 0.0
        # one gradient of stages 0..N-2, step 3 of prepare, one stage-cost Hessian refresh
        # (step 5) and steps 6 and 7: the estimates of the anytime prepare (section 14)
        self._cost_grad = self._cost_head = self._cost_al = self._cost_tail = 0.0
        # one gradient and re-linearisation in one call (step 2 of the budgeted full RTI)
        self._cost_fh = 0.0
        self.budget_used = 0.0
        self._prepared_extra = False
        self._reinit_next = -1        # a re-initialisation under way: its next stage (section 14)
        self._reinit_sim = 0          # its forward simulation: 1 the plan's controls, 2 the guess's, 0 none
        self.extra_iterations = 0
        self.instant_stages = 0

    # ------------------------------------------------------------------ the Hessian in use
    def _fns(self):
        """(stage_hess, term_hess, stage_hess_cost) of the Hessian in use (the setting, or
        Gauss-Newton during a recovery, section 9)."""
        d = self.disc
        if self.hessian == "exact":
            return d.stage_hess_exact, d.term_hess_exact, getattr(d, "stage_hess_cost_exact", None)
        return d.stage_hess_gn, d.term_hess_gn, getattr(d, "stage_hess_cost_gn", None)

    @property
    def _stage_hess(self):
        return self._fns()[0]

    @property
    def _term_hess(self):
        return self._fns()[1]

    @property
    def _stage_hess_cost(self):
        """(x, u, p) -> A_l, the stage-cost part of A (section 4 step 5)."""
        return self._fns()[2]

    # ------------------------------------------------------------------ settings
    @property
    def settings(self) -> Settings:
        """The settings it runs with (``M`` at most N-1)."""
        return Settings(M=self.M, hessian=self.hessian, regularization=self.regularization, reg_eps=self.reg_eps,
                        cost_hessian=self.cost_hessian, lm="auto" if self.lm_auto else self.lm, qp_tol=self.qp_tol,
                        qp_max_iter=self.qp_max_iter, mode=self.mode, budget=self.budget,
                        budget_unit=self.budget_unit, anytime_tol=self.anytime_tol, M_adaptive=self.M_adaptive,
                        M_min=self.M_min, M_max=self.M_max, M_eta=self.M_eta, gate=self.gate,
                        gate_hold=self.gate_hold)

    def set_M(self, M: int) -> None:
        """Values above N-1 mean the full RTI (N-1), as in the C runtime
        (:func:`dopus_codegen.settings.stages`)."""
        self.M = _setting(settings.stages, M, self.N)

    def set_levenberg_marquardt(self, lm) -> None:
        """``"auto"``: the automatic, adaptive term of section 10; a number >= 0: fixed."""
        v = _setting(settings.levenberg_marquardt, lm)
        if v == settings.LM_AUTO:
            self.lm_auto, self.lm, self._lm_kkt_prev, self.lm_held = True, 0.0, -1.0, False
            if self._initialised_and_ready():
                self._lm_start()
        else:
            self.lm_auto, self.lm, self.lm_held = False, float(v), False

    def _initialised_and_ready(self) -> bool:
        return bool(getattr(self, "_initialised", False) and getattr(self, "_qp_ready", False))

    def set_mode(self, mode: str) -> None:
        self.mode = _setting(settings.check, "mode", mode)

    def set_regularization(self, regularization: str, reg_eps: Optional[float] = None) -> None:
        """The regularisation of the blocks computed from now on (section 5); the next
        prepare's step 5 refreshes every other block with it, a constant stage-cost Hessian
        included (as the C runtime's ``dopus_update_settings``)."""
        regularization = _setting(settings.check, "regularization", regularization)
        eps = self.reg_eps if reg_eps is None else _setting(settings.positive, "reg_eps", reg_eps)
        if (regularization, eps) != (self.regularization, self.reg_eps):
            self._al_resync = True
        self.regularization, self.reg_eps = regularization, eps

    def set_qp_max_iter(self, max_iter: int) -> None:
        """The QP solver's iteration limit (None: the reference QP solver's own); reaching it
        fails the feedback with the QP status ``max_iter``, as in the C runtime."""
        self.qp_max_iter = None if max_iter is None else _setting(settings.count, "qp_max_iter", max_iter, 1)

    def _parameters_writable(self, who: str) -> None:
        """Parameters are read by init and prepare (docs/algorithm.md section 4): writable
        before init or while a prepare is due; in receding mode the shift of this sampling
        instant's parameters comes first (once)."""
        if not getattr(self, "_initialised", False):
            return
        if not self._prepare_due:
            raise self._fail("already_prepared", f"{who} ({PARAMETER_ORDER})")
        self._shift_parameters()

    def _shift_parameters(self) -> None:
        """p_k <- p_{k+1}, p_N kept; once per sampling instant, receding mode only."""
        if self.mode == "receding" and not self._p_shifted:
            p = self.p.copy()
            p[:self.N] = self.p[1:]
            self.p = p
            self._p_shifted = True

    def set_parameters(self, p) -> None:
        """``(np,)`` for every node or ``(N+1, np)``: the parameters of the next QP's horizon."""
        value = node_parameters(self.disc, p)
        self._parameters_writable("set_parameters")
        self.p = value

    def set_parameters_node(self, k: int, pk) -> None:
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 0 <= k <= self.N:
            raise DopusError.of("invalid_argument", f"node index must be an integer in 0..{self.N}, got {k!r}")
        v = _arr(pk, (self.np,), f"parameters of node {k}")
        if not np.all(np.isfinite(v)):
            raise DopusError.of("nonfinite_input", f"parameters of node {k}: NaN or Inf")
        self._parameters_writable("set_parameters_node")
        p = self.p.copy()
        p[k] = v
        self.p = p

    def stop(self) -> None:
        """End the run: uninitialised, settings and parameters kept."""
        self._initialised = self._qp_ready = self._prepare_due = self._shifted = self._p_shifted = False

    def push_parameters(self, pN) -> None:
        """The parameters of the next horizon's last node (receding mode, between feedback
        and prepare)."""
        self._need_init()
        if self.mode != "receding":
            raise DopusError.of("invalid_argument", "push_parameters: only in receding mode (the horizon moves)")
        v = _arr(pN, (self.np,), "parameters of the new last node")
        if not np.all(np.isfinite(v)):
            raise DopusError.of("nonfinite_input", "push_parameters: NaN or Inf")
        self._parameters_writable("push_parameters")
        p = self.p.copy()
        p[self.N] = v
        self.p = p

    # ------------------------------------------------------------------ section 14: anytime
    def set_work_budget(self, units) -> None:
        """The budget per sampling instant in work units (function evaluations 1, a QP solve
        N); 0 switches it off."""
        self._set_budget(units, "work")

    def set_time_budget(self, seconds) -> None:
        """The budget per sampling instant in seconds (time.perf_counter); 0 switches it off.
        Only the work budget makes the iterates comparable with the C runtime."""
        self._set_budget(seconds, "time")

    def _set_budget(self, value, unit) -> None:
        v = _setting(settings.nonnegative, f"{unit}_budget", value)
        self.budget = v
        self.budget_unit = unit

    def set_gate(self, gate, hold=None) -> None:
        """The measurement gate (section 9): 0 (off) or the largest jump
        ``|xhat0_i - x_0,i| / scale_x_i`` accepted; ``hold`` the most measurements in a row
        held out (None: unchanged)."""
        g = _setting(settings.validate, "gate", gate)
        self.gate_hold = self.gate_hold if hold is None else _setting(settings.validate, "gate_hold", hold)
        self.gate = g

    def set_anytime_tol(self, tol) -> None:
        self.anytime_tol = _setting(settings.positive, "anytime_tol", tol)

    def set_M_adaptive(self, on: bool = True, M_min: int = 0, M_max=None, eta=None) -> None:
        """Adaptive M (section 14): the stages whose secant residual ``rho_k |domega_k|``
        exceeds ``eta`` times the KKT proxy, between ``M_min`` and ``M_max``."""
        M_max = self.N - 1 if M_max is None else M_max
        eta = float(_SAFETY["ADAPTIVE_ETA"]) if eta is None else eta
        self.M_adaptive, self.M_min, self.M_max, self.M_eta = _setting(check_adaptive_M, on, M_min, M_max, eta,
                                                                       self.N)

    def _budget_on(self) -> bool:
        return self.budget > 0

    def _budget_now(self) -> float:
        """Now on the budget's clock (0 without a budget, as in the C runtime)."""
        if not self._budget_on():
            return 0.0
        return self.work if self.budget_unit == "work" else time.perf_counter()

    def _budget_fits(self, cost) -> bool:
        return not self._budget_on() or self._budget_now() - self._instant_start + cost <= self.budget

    # ------------------------------------------------------------------ evaluations
    def _slot(self, k: int) -> int:
        return (self.ring_head + k) % self.N

    @property
    def initialized(self) -> bool:
        """init has succeeded (and stop has not been called since)."""
        return self._initialised

    @property
    def qp_ready(self) -> bool:
        """A QP is prepared for the next feedback."""
        return self._qp_ready

    def slot_of(self, k: int):
        """The ring-buffer slot that holds stage ``k`` (``slots[(ring_head + k) mod N]``)."""
        return self.slots[self._slot(k)]

    def _stage_hess_eval(self, k, x, u, lam, mu_g):
        A, Phi, C = self._stage_hess(x[k], u[k], self.p[k], lam[k + 1], mu_g[k])
        A = np.array(A, float).reshape(self.nw, self.nw)
        Phi = np.array(Phi, float).reshape(self.nx, self.nw)
        C = np.array(C, float).reshape(self.ng, self.nw)
        return A, Phi, C

    def _cost_hess_eval(self, k, x, u):
        A = self._stage_hess_cost(x[k], u[k], self.p[k])
        return np.array(A, float).reshape(self.nw, self.nw)

    def _set_block(self, s, k, x, u, lam, mu_g):
        """Fresh H of stage k into slot s: ``A_dyn = A - A_l`` (the curvature of dynamics and
        path constraints, used by step 5 with ``cost_hessian='fresh'``; kept under both
        settings, as in the C slots), ``Ht = reg(A)``."""
        self.work += 1
        A, s.Phit, s.Ct = self._stage_hess_eval(k, x, u, lam, mu_g)
        s.A_dyn = A - self._cost_hess_eval(k, x, u) if self._stage_hess_cost is not None else A
        s.Ht = regularize(A, self.regularization, self.reg_eps)
        return s

    def _term_eval(self, xN, mu_r, nu):
        self.work += 2
        gL, _E, r, r_eq = self.disc.term_grad(xN, self.p[self.N], mu_r, nu)
        A, R, Req = self._term_hess(xN, self.p[self.N], mu_r, nu)
        t = {
            "gL": np.array(gL, float).reshape(self.nx), "r": np.array(r, float).reshape(self.nr),
            "r_eq": np.array(r_eq, float).reshape(self.ne),
            "A": regularize(np.array(A, float).reshape(self.nx, self.nx), self.regularization, self.reg_eps),
            "R": np.array(R, float).reshape(self.nr, self.nx), "Req": np.array(Req, float).reshape(self.ne, self.nx),
        }
        return t

    @staticmethod
    def _finite(*arrays) -> bool:
        return all(np.all(np.isfinite(a)) for a in arrays)

    # ------------------------------------------------------------------ init
    def init(self, xhat0, guess=None) -> None:
        """Iterate = guess; every stage and the terminal node evaluated fresh (section 4)."""
        t0 = time.perf_counter()
        nx = self.nx
        xhat0 = _arr(xhat0, (nx,), "xhat0")
        if not np.all(np.isfinite(xhat0)):
            raise DopusError.of("nonfinite_input", "init: xhat0 has non-finite entries")
        if guess is None:
            guess = self.disc.initial_guess
        g = guess.filled(self.disc)
        for name in ("x", "u", "lam", "mu_g", "mu_b", "mu_bN", "mu_r", "nu"):
            if not np.all(np.isfinite(getattr(g, name))):
                raise DopusError.of("nonfinite_input", f"init: guess.{name} has non-finite entries")
        x, u, lam, mu_g, mu_b = g.x.copy(), g.u.copy(), g.lam.copy(), g.mu_g.copy(), g.mu_b.copy()
        free_initial_state(nx, mu_b=mu_b)
        self._initialised = False
        self._qp_ready = False
        self._p_shifted = False
        self._reset_health(u)
        self._reinit_next = -1
        self._init_finish(x, u, lam, mu_g, mu_b, g.mu_bN.copy(), g.mu_r.copy(), g.nu.copy(), "init", "at the guess")
        self._xhat_last = xhat0.copy()
        self._u_applied = np.zeros(self.n_u)
        for row, ctrl in getattr(self.disc.spec.model, "memory", ()) or ():
            self._u_applied[ctrl] = xhat0[row]
        self._reset_health(self.u)
        self.kkt_proxy = self._kkt_proxy_eval()
        self.kkt_proxy_ref = self.kkt_proxy
        self._kkt_proxy_init = self.kkt_proxy
        self.timings = {"init": time.perf_counter() - t0}

    def _init_finish(self, x, u, lam, mu_g, mu_b, mu_bN, mu_r, nu, who, where) -> None:
        """Every stage and the terminal node evaluated fresh at the given iterate (init and
        the re-initialisation of section 9); the state changes only on success."""
        N, nx, nu_, ng = self.N, self.nx, self.n_u, self.ng
        self._prepared_extra = False
        slots = [_Slot(nx, nu_, ng) for _ in range(N)]
        b0 = self._budget_now()
        self.work += N
        gL, phi, lv, gv = eval_stages(self.disc.stage_grad, N, x[:N], u, self.p[:N], lam[1:], mu_g)
        b1 = self._budget_now()
        for k in range(N):
            s = slots[k]
            s.F_w = gL[k] + mu_b[k]
            s.phi = phi[k].copy()
            s.g = gv[k].copy()
            self._set_block(s, k, x, u, lam, mu_g)
        b2 = self._budget_now()
        term = self._term_eval(x[N], mu_r, nu)
        if not self._finite(gL, phi, lv, gv, *[v for s in slots for v in (s.Ht, s.A_dyn, s.Phit, s.Ct)],
                            *term.values()):
            raise self._fail("nonfinite_value", f"{who}: a derivative function returned a non-finite value {where}")
        if self._budget_on():
            # the first estimates of a budget (section 14), before any prepare measured them:
            # a gradient, a re-linearisation, step 3 (the stage-cost Hessian refresh and steps
            # 6 and 7 are not counted in work units; in time the later prepares measure them)
            self._cost_grad = (b1 - b0) / N
            self._cost_stage = (b2 - b1) / N
            self._cost_head = self._cost_grad + self._cost_stage + (self._budget_now() - b2)
            self._cost_fh = self._cost_grad + self._cost_stage
            self._cost_al = self._cost_tail = 0.0
        self.x, self.u, self.lam, self.mu_g, self.mu_b = x, u, lam, mu_g, mu_b
        self.mu_bN, self.mu_r, self.nu = mu_bN, mu_r, nu
        self.ring_head = 0
        self.slots = slots
        self._al_resync = False     # every block fresh, with the current regularisation
        self.term = term
        self.rho = np.zeros(N)
        self.recomputed = list(range(N))
        self.qp_status = 0
        self.qp_iterations = self.qp_factorizations = 0
        self.status = status_code("ok")
        self._initialised = True
        self._qp_ready = True
        self._lm_start()
        self._prepare_due = False    # a feedback must come first
        self._shifted = False
        self._p_shifted = False

    def _need_init(self):
        if not self._initialised:
            raise self._fail("not_initialized", "call init(xhat0, guess) first")

    def _fail(self, status: str, message: str, qp_status=None) -> DopusError:
        """The error of a failed call (``status`` names the code of enum dopus_status); the
        status is kept, as the C runtime keeps it."""
        err = DopusError.of(status, message, qp_status)
        self.status = err.status
        return err

    # ------------------------------------------------------------------ the QP
    def qp_of_current(self, xhat0=None) -> dict:
        """The QP of section 3 at the current iterate for initial state ``xhat0`` (default:
        the last one given to ``init``/``feedback``), in the :mod:`dopus_codegen.reference.qp`
        format. Meaningful after ``init`` or ``prepare`` (it is the QP the next ``feedback``
        solves)."""
        self._need_init()
        N, nx, nu, ng, nr, ne, nw = self.N, self.nx, self.n_u, self.ng, self.nr, self.ne, self.nw
        xhat0 = _arr(self._xhat_last if xhat0 is None else xhat0, (nx,), "xhat0")
        H = np.empty((N, nw, nw)); gq = np.empty((N, nw)); Phi = np.empty((N, nx, nw))
        b = np.empty((N, nx)); C = np.empty((N, ng, nw)); lgq = np.empty((N, ng)); ugq = np.empty((N, ng))
        lbw = np.empty((N, nw)); ubw = np.empty((N, nw))
        shift = self.lm * np.eye(nw)  # the Levenberg-Marquardt term (section 3)
        for k in range(N):
            s = self.slots[self._slot(k)]
            H[k] = s.Ht + shift
            Phi[k] = s.Phit
            C[k] = s.Ct
            # eq. 12: a_k = F_w + Phit' lam_{k+1} - Ct' mu_g_k - mu_b_k
            gq[k] = s.F_w + s.Phit.T @ self.lam[k + 1] - s.Ct.T @ self.mu_g[k] - self.mu_b[k]
            b[k] = s.phi - self.x[k + 1]
            lgq[k] = self.lg_k[k] - s.g
            ugq[k] = self.ug_k[k] - s.g
            lbw[k, :nx] = self.lbx - self.x[k]
            ubw[k, :nx] = self.ubx - self.x[k]
            lbw[k, nx:] = self.lbu - self.u[k]
            ubw[k, nx:] = self.ubu - self.u[k]
        free_initial_state(nx, lower=lbw, upper=ubw)
        t = self.term
        gN = t["gL"] - t["R"].T @ self.mu_r - t["Req"].T @ self.nu
        soft = {}
        if self.disc.has_soft:
            ws, wt = self.disc.soft_stage(), self.disc.soft_terminal()
            soft = dict(zip(("zl", "zu", "Zl", "Zu"), ws.copy()))
            soft.update(zip(("zlN", "zuN", "ZlN", "ZuN"), wt.copy()))
        return {**soft,
            "N": N, "nx": nx, "nu": nu, "ng": ng, "nr": nr, "ne": ne,
            "H": H, "g": gq, "Phi": Phi, "b": b, "x0": xhat0 - self.x[0],
            "HN": t["A"] + shift[:nx, :nx], "gN": gN, "lbw": lbw, "ubw": ubw,
            "lbxN": self.lbx - self.x[N], "ubxN": self.ubx - self.x[N],
            "C": C, "lg": lgq, "ug": ugq, "R": t["R"].copy(), "lr": self.lr - t["r"], "ur": self.ur - t["r"],
            "Req": t["Req"].copy(), "req": -t["r_eq"],
        }

    def _row_info(self, row):
        """``(stage, j, side)`` of :func:`qp_infeasible_row` as the C runtime's
        dopus_get_qp_infeasible_row gives it: ``{"stage", "kind", "index", "side", "bound"}``
        with the OCP's bound of that side (0 for a terminal equality row)."""
        if row is None:
            return None
        k, j, side = (int(v) for v in row)
        nx, nw, nr = self.nx, self.nw, self.nr
        if j < nx:
            kind, index, lo, up = "state", j, self.lbx, self.ubx
        elif k < self.N and j < nw:
            kind, index, lo, up = "control", j - nx, self.lbu, self.ubu
        elif k < self.N:
            kind, index, lo, up = "path", j - nw, self.lg_k[k], self.ug_k[k]
        elif j < nx + nr:
            kind, index, lo, up = "terminal", j - nx, self.lr, self.ur
        else:
            kind, index, lo, up = "terminal_eq", j - nx - nr, None, None
        bound = 0.0 if lo is None else float(up[index] if side > 0 else lo[index])
        return {"stage": k, "kind": kind, "index": index,
                "side": {-1: "lower", 1: "upper"}.get(side, "lower above upper"), "bound": bound}

    @property
    def qp_infeasible_row(self):
        """When the last QP was infeasible: the row of the OCP with the largest multiplier of
        its infeasibility certificate (:func:`dopus_codegen.reference.qp.qp_infeasible_row`),
        as ``Solver.qp_infeasible_row`` gives it; else None."""
        if self.qp_status != status_code_qp("primal_infeasible"):
            return None
        return getattr(self, "_infeasible_row", None)

    # ------------------------------------------------------------------ feedback
    def _with_memory(self, xhat0):
        """The measured state with the memory entries of the rate constraints set to the last
        applied control (docs/algorithm.md section 4, "Rate constraints")."""
        memory = getattr(self.disc.spec.model, "memory", ()) or ()
        if not memory or xhat0 is None or not self._initialised or self.mode != "receding":
            return xhat0
        x = np.array(xhat0, dtype=float).reshape(-1).copy()
        if x.size != self.nx:
            return xhat0
        for row, ctrl in memory:
            x[row] = self._u_applied[ctrl]
        return x

    def feedback(self, xhat0) -> np.ndarray:
        """The feedback step; with rate constraints the memory entries of ``xhat0`` are the
        last applied control, which the backend keeps."""
        try:
            return self._feedback_step(self._with_memory(xhat0))
        finally:
            if self._initialised and getattr(self, "u0", None) is not None:
                self._u_applied = np.array(self.u0, dtype=float).copy()

    def _feedback_step(self, xhat0) -> np.ndarray:
        """Solve the QP for ``xhat0``, store ``domega`` per slot, full step; return ``u_0``."""
        self._instant_start = self._budget_now()
        try:
            return self._feedback(xhat0)
        finally:
            self.budget_used = self._budget_now() - self._instant_start

    def _instant_passed(self, xhat_fresh: bool) -> None:
        """A feedback that attempts no QP: whether its measurement counts, and in receding
        mode the sampling instant has passed all the same, so its prepare (the shift) is due."""
        self._xhat_fresh = xhat_fresh
        if self.mode == "receding":
            self._prepare_due, self._shifted = True, False

    def _feedback(self, xhat0) -> np.ndarray:
        t0 = time.perf_counter()
        xhat0 = np.array(xhat0, dtype=float).reshape(-1)
        if xhat0.size != self.nx:
            raise self._fail("invalid_argument", f"feedback: xhat0 must be {self.nx} numbers, got {xhat0.size}")
        self._flags = 0
        self.extra_iterations = self.instant_stages = 0
        if not self._initialised:
            err = self._fail("not_initialized", "call init(xhat0, guess) first")
            err.u0 = self._fallback_u0()
            raise err
        if not np.all(np.isfinite(xhat0)):
            self._instant_passed(False)
            raise self._feedback_failed("nonfinite_input",
                                        f"feedback: xhat0 must be {self.nx} finite numbers, got {xhat0}")
        if not self._qp_ready:
            # counted as a failed instant; the measurement is recorded all the same: the
            # recovery that repeated failures call for starts from it (section 9)
            self._xhat_last = xhat0.copy()
            self._instant_passed(True)
            raise self._feedback_failed("not_prepared", "feedback: no prepared QP (call prepare after a "
                                        "successful feedback)")
        if self._gated(xhat0):
            # as a missing measurement: the previous one stays the last, the prepare's
            # predicted step carries the loop (section 9)
            self._instant_passed(False)
            raise self._feedback_failed("measurement_gated", f"feedback: the measurement {xhat0} is further from "
                                        f"the plan's prediction {self.x[0]} than the gate {self.gate:g} (times the "
                                        "state scales) allows: handled as a missing one")
        if not self._prepared_extra:
            # after extra iterations the term the prepare convexified stays (section 14)
            self._lm_measured(xhat0)
        xhat_prev = self._xhat_last
        self._xhat_last = xhat0.copy()
        self._xhat_fresh = True
        # the QP is attempted: a prepare (with its shift) is due, whatever the outcome
        self._prepare_due, self._shifted = True, False
        t1 = time.perf_counter()
        # the QPs of the feedback stop where the least prepare still fits (section 14)
        self._qp_deadline = (self._instant_start + self.budget - self._prepare_floor()
                             if self._budget_on() else None)
        try:
            sol, failure, retries = self._feedback_qps(xhat0, xhat_prev)
        finally:
            self._qp_deadline = None
        cut = sol is not None and failure in (None, "diverged") and bool(sol.get("cut", False))
        if cut:
            self._flag("qp_cut")
        if isinstance(failure, DopusError):
            raise self._feedback_failed(failure.status_name, str(failure)) from None
        if isinstance(failure, QPError):
            exc = failure
            msg = f"feedback: {exc}; QP status {self.qp_status} ({exc.qp_status})"
            if self.qp_infeasible_row is not None:
                msg += "; " + describe_qp_row(self.disc, self.qp_infeasible_row)
            raise self._feedback_failed("qp", msg, exc.qp_status) from None
        self.qp_iterations = int(sol.get("iterations", 0))
        self.qp_factorizations = int(sol.get("factorizations", 0))
        t2 = time.perf_counter()
        if failure == "nonfinite":
            raise self._feedback_failed("qp", "feedback: the QP solution is not finite", "solved")
        if failure == "diverged":
            raise self._feedback_failed("diverged", "feedback: the QP step leaves the problem's scale box (or is "
                                        "not finite); no step, the fallback control is returned")
        return self._feedback_step_taken(sol, retries, t0, t1, t2)

    def _feedback_qps(self, xhat0, xhat_prev):
        """The feedback's QP with its retries and the recovery within the feedback (section 9).
        Returns (solution, failure, retries)."""
        b0 = self._budget_now()
        sol, failure, retries = self.solve_with_retries(xhat0)
        self._cost_qp = self._budget_now() - b0
        # qp_status: the status of the feedback's QP as soon as it was tried (as the C
        # runtime's dopus_info.qp_status), so a failure raised before the end of the feedback
        # (an unusable measurement, a recovery that builds no QP) reports the QP that failed
        self._set_qp_status(sol, failure)
        if (failure is not None and self.recovery and self.mode == "receding"
                and getattr(failure, "qp_status", None) not in ("max_iter", "invalid_input")):
            # the recovery within the feedback (section 9): re-initialise from the measured
            # state and solve the QP of the re-initialised iterate; not for a QP stopped by
            # its iteration limit (not a sign of a wrong iterate) or refused as invalid
            if not self._model_finite_at(xhat0):
                # no measurement: handled as a non-finite one (the iterate and its QP stay)
                self._xhat_last, self._xhat_fresh = xhat_prev, False
                self._flag("measurement_unusable")
                raise self._feedback_failed("nonfinite_value", "feedback: the model is not finite at the measured "
                                            f"state {xhat0}: handled as a missing measurement")
            sol, failure, retries = self._feedback_recover(xhat0)
            if not isinstance(failure, DopusError):
                # the recovery's QP (its re-initialisation reset qp_status to 0)
                self._set_qp_status(sol, failure)
        return sol, failure, retries

    def _set_qp_status(self, sol, failure) -> None:
        """qp_status (and the infeasible row) of a feedback's QP as solve_with_retries
        returns it: the QPError's status, "deadline" for a cut QP whose point is the step,
        else "solved" (also for a solution that is not finite or a step that diverged)."""
        if isinstance(failure, QPError):
            self.qp_status = status_code_qp(failure.qp_status)
            self._infeasible_row = self._row_info(getattr(failure, "row", None))
            return
        cut = sol is not None and failure in (None, "diverged") and bool(sol.get("cut", False))
        self.qp_status = status_code_qp("deadline" if cut else "solved")

    def _feedback_step_taken(self, sol, retries, t0, t1, t2) -> np.ndarray:
        """Steps 6 to 8 of a feedback whose QP gave a step (solved, or cut by the deadline)."""
        self._take_step(sol)
        self.qp_iterations = int(sol.get("iterations", 0))
        self.qp_factorizations = int(sol.get("factorizations", 0))
        self.last_qp = self._last_qp_tried
        self.last_qp_solution = sol
        self._qp_ready = False
        # a good plan: the fallback of the next failures; u0 clipped to the bounds
        self._n_failed = 0
        self._plan_age = 0
        self._recovering = max(self._recovering - 1, 0)
        if retries == 0:
            self._lm_feedback("ok")   # lowered, unless this QP needed a raise
        self._plan_u = self.u.copy()
        self.u0, clipped = self._clip_u(self.u[0])
        if clipped:
            self._flag("u0_clipped")
        self.status = status_code("ok")
        t3 = time.perf_counter()
        self.timings.update({"feedback": t3 - t0, "qp": t2 - t1})
        return self.u0.copy()

    def soft_slacks(self) -> dict:
        """The slacks of the soft rows in the QP of the last feedback, as
        ``CSolver.soft_slacks`` (docs/algorithm.md section 12)."""
        N, nx, ng, nr = self.N, self.nx, self.ng, self.nr
        out = {"x": np.zeros((N + 1, nx)), "g": np.zeros((N, ng)), "r": np.zeros(nr), "max": 0.0}
        q, sol = getattr(self, "last_qp", None), getattr(self, "last_qp_solution", None)
        if q is None or sol is None or not self.disc.has_soft:
            return out

        def slack(v, lo, up, w):
            sl = np.zeros(np.shape(v))
            with np.errstate(invalid="ignore"):
                sl = np.where((w[0] > 0) | (w[2] > 0), np.maximum(sl, lo - v), sl)
                sl = np.where((w[1] > 0) | (w[3] > 0), np.maximum(sl, v - up), sl)
            return np.nan_to_num(sl, nan=0.0, posinf=0.0, neginf=0.0)

        for k in range(1, N + 1):
            lo = q["lbw"][k, :nx] if k < N else q["lbxN"]
            up = q["ubw"][k, :nx] if k < N else q["ubxN"]
            out["x"][k] = slack(sol["x"][k], lo, up, self.disc.soft_x)
        for k in range(N):
            if ng:
                v = q["C"][k] @ np.concatenate([sol["x"][k], sol["u"][k]])
                out["g"][k] = slack(v, q["lg"][k], q["ug"][k], self.disc.soft_g)
        if nr:
            out["r"] = slack(q["R"] @ sol["x"][N], q["lr"], q["ur"], self.disc.soft_r)
        out["max"] = float(max(out["x"].max(initial=0.0), out["g"].max(initial=0.0), out["r"].max(initial=0.0)))
        return out

    def _qp_warm_point(self, qp: dict) -> dict:
        """The warm-start point of the feedback's QP (dopus_qp_warm_point of the C runtime): a
        zero step from the (shifted) iterate, x_0's step fixed by the measurement, and the
        iterate's multipliers, which are those of the previous QP shifted with the horizon."""
        x = np.zeros((self.N + 1, self.nx))
        x[0] = qp["x0"]
        return {"x": x, "u": np.zeros((self.N, self.n_u)), "lam": self.lam, "nu": self.nu, "mu_g": self.mu_g,
                "mu_r": self.mu_r, "mu_b": self.mu_b, "mu_bN": self.mu_bN}

    def _qp_deadline_passed(self) -> bool:
        """A QP of the instant would pass its deadline before its first iteration (section 14;
        the C QP reads the budget's clock before each factorisation, and in work units its N
        units have moved the counter already)."""
        return self._qp_deadline is not None and self._budget_now() > self._qp_deadline

    def _qp_deadline_near(self) -> bool:
        """One more QP solve would pass the deadline at once (work units: its N units; in time
        the reference has no price of a QP iteration: 0)."""
        nxt = self.N if self.budget_unit == "work" else 0.0
        return self._qp_deadline is not None and self._budget_now() + nxt > self._qp_deadline

    def _qp_cut_point(self, qp: dict) -> dict:
        """The point of a QP cut by its deadline before its first iteration (section 14): the C
        QP's iterate 0 from the warm start (dopus_qp.c, initial_point): the warm-start point with
        the multiplier of each bounded row floored on its sides, max(mu, f) on a finite upper
        side less max(-mu, f) on a finite lower side (f = QP_WARM_FLOOR_Z), 0 on a row without
        a finite side."""
        w = self._qp_warm_point(qp)
        f = QP_WARM_FLOOR_Z

        def floored(mu, lo, up):
            mu, lo, up = (np.asarray(a, dtype=float) for a in (mu, lo, up))
            return (np.where(np.isfinite(up), np.maximum(mu, f), 0.0)
                    - np.where(np.isfinite(lo), np.maximum(-mu, f), 0.0))

        out = {k: np.array(v, dtype=float, copy=True) for k, v in w.items()}
        out["mu_b"] = floored(w["mu_b"], qp["lbw"], qp["ubw"])
        out["mu_b"][0, :self.nx] = 0.0
        if self.ng > 0:
            out["mu_g"] = floored(w["mu_g"], qp["lg"], qp["ug"])
            u_free = ~np.any(np.asarray(qp["C"])[0][:, self.nx:] != 0.0, axis=1)
            out["mu_g"][0, u_free] = 0.0     # rows of C_0 fixed by x0 (dopus_qp.h)
        out["mu_bN"] = floored(w["mu_bN"], qp["lbxN"], qp["ubxN"])
        if self.nr > 0:
            out["mu_r"] = floored(w["mu_r"], qp["lr"], qp["ur"])
        out.update(iterations=0, factorizations=0, cut=True)
        return out

    def solve_with_retries(self, xhat0):
        """The QP of the current iterate for xhat0, solved again with lm raised while it is not
        solved (section 10). Returns (solution, failure, retries): failure None, a QPError,
        "nonfinite" or "diverged" (the step fails the box test of section 9)."""
        qp = self.qp_of_current(xhat0)
        retries = 0
        while True:
            sol = None
            self.work += self.N
            if self._qp_deadline_passed():
                # cut before its first iteration (section 14): the C QP's iterate 0
                sol, failure = self._qp_cut_point(qp), None
                break
            try:
                # the first solve starts from the active set of the previous solution, as the C
                # QP's warm start does for a measurement near the predicted state and a QP whose
                # automatic lm is within one raise step of convex (section 4, feedback); a retry
                # with lm raised does not
                start = (retries == 0 and self.active_set_start and self.lm_auto
                         and bool(np.all(np.abs(qp["x0"]) <= _SAFETY["QP_ACTIVE_SET_NEAR"] * self.scales[0]))
                         and self._active_set_fits() and self.lm_near_convex())
                sol = solve_qp_reference(qp, tol=self.qp_tol, max_iter=self.qp_max_iter,
                                         guess=self._qp_warm_point(qp) if start else None,
                                         guess_sweeps=int(_SAFETY["QP_ACTIVE_SET"]))
                failure = None if self._finite(*(sol[k] for k in FIELDS_QP)) else "nonfinite"
            except QPError as exc:
                failure = exc
            # the automatic term (section 10): a QP not solved is solved again with lm raised
            # (with a budget, while one more solve does not pass the deadline at once)
            if (failure is None or not self.lm_auto or retries >= _SAFETY["LM_RETRIES"]
                    or not self.lm < _SAFETY["LM_MAX_REL"] * self.lm_scale or self._qp_deadline_near()):
                break
            self._lm_raise()
            qp = self.qp_of_current(xhat0)
            retries += 1
        if failure is None and not self._box_ok(self.x + sol["x"], self.u + sol["u"]):
            failure = "diverged"
        self._last_qp_tried = qp
        return sol, failure, retries

    def _active_set_fits(self) -> bool:
        """Section 14: with a time budget's deadline, not when the time left before it fits
        ANYTIME_IPM_ITER QP iterations (at the price of one: here the last feedback QP's time
        over its iterations) but not the start's most sweeps (QP_ACTIVE_SET): a start cut short
        leaves the warm start, which fails the feedback, where the interior point's cut
        iterates are steps. In work units (a QP is cut only before its first factorisation)
        always, as in the C runtime."""
        price = self._cost_qp / max(1, self.qp_iterations)
        if self._qp_deadline is None or self.budget_unit != "time" or not price > 0.0:
            return True
        fit = (self._qp_deadline - self._budget_now()) / price
        return fit >= _SAFETY["QP_ACTIVE_SET"] or fit < _SAFETY["ANYTIME_IPM_ITER"]

    def _feedback_recover(self, xhat0):
        """Section 9: the QP of a finite measurement failed; re-initialise from the measured
        state (x_0 = xhat0) and solve the QP of the re-initialised iterate."""
        x, u = self.x.copy(), self.u.copy()
        x[0] = xhat0
        n_failed = self._n_failed
        failure = None
        try:
            # with a budget the QP after it and the least prepare stay free (section 14)
            self._reinit(x, u, self._cost_qp + self._prepare_floor())
        except DopusError as exc:
            failure = exc
        self._n_failed = n_failed     # still the count of consecutive failed feedbacks
        # the measurement's instant: its prepare (with the shift) is still due
        self._prepare_due, self._shifted = True, False
        if failure is None and "reinit_guess" in self.flags:
            failure = DopusError.of("nonfinite_value", "feedback: the model is not finite at the measured state "
                                    "(the recovery's re-initialisation from it); the iterate is the OCP file's "
                                    "guess, prepared for the next measurement")
        if failure is None and self._reinit_next >= 0:
            failure = DopusError.of("not_prepared", "feedback: the recovery's re-initialisation continues in the "
                                    "prepare (the budget of the instant is spent); no QP yet")
        if failure is not None:
            return None, failure, 0
        return self.solve_with_retries(xhat0)

    def _take_step(self, sol) -> None:
        """``domega`` of each stage into its slot, then the full step (eq. 4): primal
        increment, multipliers replaced by the QP's."""
        N = self.N
        dW = np.hstack([sol["x"][:N], sol["u"]])
        for k in range(N):
            s = self.slots[self._slot(k)]
            s.dw = dW[k].copy()
            s.dlam = sol["lam"][k + 1] - self.lam[k + 1]
            s.dmu_g = sol["mu_g"][k] - self.mu_g[k]
            s.dmu_b = sol["mu_b"][k] - self.mu_b[k]
        self.x = self.x + sol["x"]
        self.u = self.u + sol["u"]
        self.lam = sol["lam"].copy()
        self.mu_g = sol["mu_g"].copy()
        self.mu_b = sol["mu_b"].copy()
        self.mu_bN = sol["mu_bN"].copy()
        self.mu_r = sol["mu_r"].copy()
        self.nu = sol["nu"].copy()
        self._qp_ready = False

    def allow_prepare(self) -> None:
        """Let the next ``prepare`` run although no feedback reached the QP since the last
        ``init`` or ``prepare``: for a sampling instant whose feedback was skipped (the C
        runtime allows one prepare after a feedback whose QP failed, which takes no step),
        or after the iterate was replaced by hand. The calling order of
        docs/algorithm.md section 4 otherwise refuses it (status already_prepared)."""
        self._need_init()
        self._prepare_due = True

    # ------------------------------------------------------------------ prepare
    def prepare(self) -> None:
        """Shift (receding), F and rho, fresh last stage and terminal, M worst H, fresh
        stage-cost Hessians (section 4). Steps 2 to 5 work on copies of the slots: a
        non-finite value leaves the state of step 1."""
        self._need_init()
        if not self._prepare_due:
            raise self._fail("already_prepared", "prepare: already prepared (call feedback before the next prepare)")
        self._shift_parameters()
        self.extra_iterations = 0
        self._prepared_extra = False
        # the instant's budget counts the solver's own calls, not the caller's time between them
        self._instant_start = self._budget_now() - self.budget_used
        if (self._qp_ready and self._n_failed > 0 and not self._recover_pending and self.recovery
                and self.mode == "receding" and "reinit_guess" not in self.flags):
            # (not from the OCP file's guess: its plan is not the plant's; with a budget not when
            # its QP would pass the deadline of the least prepare at once, section 14)
            self._qp_deadline = (self._instant_start + self.budget - self._prepare_floor()
                                 if self._budget_on() else None)
            try:
                if not self._qp_deadline_near():
                    self._predicted_step()
            finally:
                self._qp_deadline = None
        self._qp_ready = False
        if self.mode == "receding" and self._plan_age < self.N:
            self._plan_age += 1
        hessian = self.hessian
        try:
            if self._reinit_next >= 0:
                # a re-initialisation under way (a budget): its next evaluations
                self._reinit_continue()
            elif self._recover_pending and self.recovery and self.mode == "receding":
                self._recover(shifted=False)
            else:
                if self._recovering > 0 and self.has_gn:
                    # the recovery phase (section 9): Gauss-Newton blocks, every block fresh
                    self.hessian = "gauss-newton"
                self._prepare_iteration()
            if self._recovering > 0 and self.has_gn:
                self.hessian = "gauss-newton"
            self._anytime()
        finally:
            self.hessian = hessian
            self.budget_used = self._budget_now() - self._instant_start
        if self.recovery and self.mode == "receding" and self._stalled():
            self._flag("stalled")

    def _gated(self, xhat0) -> bool:
        """Section 9: the measurement gate (receding mode, recovery on, gate > 0): a jump
        ``|xhat0_i - x_0,i| > gate scale_x_i`` is held out while fewer than gate_hold
        measurements in a row were; the next is accepted, and so are the gate_hold after it."""
        if not self.gate > 0 or not self.recovery or self.mode != "receding":
            return False
        if self._gate_rest > 0:
            # after gate_hold held-out measurements the next gate_hold pass unchecked
            self._gate_rest -= 1
            return False
        jump = bool(np.any(np.abs(xhat0 - self.x[0]) > self.gate * self.scales[0]))
        if jump and self._n_gated >= self.gate_hold:
            self._gate_rest = self.gate_hold
        if not jump or self._n_gated >= self.gate_hold:
            self._n_gated = 0
            return False
        self._n_gated += 1
        return True

    def _stalled(self) -> bool:
        """Section 9: outside a recovery phase, a KKT proxy above STALL_KKT max(1, proxy at
        init) in STALL_PREPARES prepares in a row, or flat (above FLAT_KKT max(1, proxy at
        init), or above FLAT_HELD_KKT max(1, proxy at init) with the automatic term held up
        by the prepare's convexity test) and not below FLAT_DROP times the proxy the stretch
        began with in FLAT_PREPARES prepares in a row (no progress), begins a recovery phase
        without a re-initialisation."""
        if self._recovering > 0:
            self._n_stalled, self._n_flat = 0, 0
            return False
        ref = max(self._kkt_proxy_init, 1.0)
        high = self.kkt_proxy > _SAFETY["STALL_KKT"] * ref
        self._n_stalled = self._n_stalled + 1 if high else 0
        flat = (self.kkt_proxy > _SAFETY["FLAT_KKT"] * ref
                or (self.lm_held and self.kkt_proxy > _SAFETY["FLAT_HELD_KKT"] * ref))
        if not flat or self._n_flat == 0 or not self.kkt_proxy > _SAFETY["FLAT_DROP"] * self._kkt_flat_ref:
            self._kkt_flat_ref, self._n_flat = self.kkt_proxy, 0
        self._n_flat = self._n_flat + 1 if flat else 0
        if self._n_stalled < _SAFETY["STALL_PREPARES"] and self._n_flat < _SAFETY["FLAT_PREPARES"]:
            return False
        self._n_stalled, self._n_flat = 0, 0
        self._recovering = int(_SAFETY["RECOVERY_FULL_RTI"])
        return True

    def _extra_iteration(self) -> bool:
        """Section 12: the prepared QP for the state the plan predicts (dx_0 = 0), its full
        step, a prepare iteration without the shift. False (nothing changed) when the QP is
        not solved or its step leaves the box."""
        lm, b0, proxy = self.lm, self._budget_now(), self.kkt_proxy
        # the cap of the term while the extra iterations make progress; after one of them
        # raised the KKT proxy, the term the prepare convexified
        if not self._uncapped:
            self._lm_measured(self.x[0])
        self.work += self.N
        try:
            sol = solve_qp_reference(self.qp_of_current(self.x[0]), tol=self.qp_tol, max_iter=self.qp_max_iter)
        except QPError:
            sol = None
        if (sol is None or not self._finite(*(sol[k] for k in FIELDS_QP))
                or not self._box_ok(self.x + sol["x"], self.u + sol["u"])):
            self.lm, self.lm_uncapped = lm, -1.0
            return False
        self._cost_qp = self._budget_now() - b0
        self._take_step(sol)
        self._lm_feedback("ok")
        self._prepare_iteration(extra=True)
        if not self.kkt_proxy < proxy:
            self._uncapped = True
        return True

    def _anytime(self) -> None:
        """Section 12: extra iterations while the KKT proxy exceeds the tolerance and one more
        fits in the budget."""
        max_iter = _SAFETY["ANYTIME_MAX_ITER"]
        if not self._budget_on():
            # without a budget: the recovery phase's extra iterations (section 9)
            if self._recovering <= 0 or not self.recovery or self.mode != "receding":
                return
            max_iter = _SAFETY["RECOVERY_EXTRA_ITER"]
        self._uncapped = False
        while (self.extra_iterations < max_iter and self._qp_ready
               and self.kkt_proxy > self.anytime_tol and self._budget_fits(self._cost_qp + self._cost_prepare)):
            if not self._extra_iteration():
                break
            self.extra_iterations += 1
        self._prepared_extra = self.extra_iterations > 0 and self._qp_ready

    def _prepare_iteration(self, extra: bool = False) -> None:
        t0 = time.perf_counter()
        b_start = self._budget_now()
        self._qp_ready = False
        if not self._shifted and not extra:   # a retry after a failed prepare does not shift again
            self._shift()
            self._shifted = self.mode == "receding"
        t1 = time.perf_counter()
        slots = [s.copy() for s in self.slots]
        # 2. the gradients of stages 0..N-2 that fit (all without a budget) in the order of
        #    the distance their linear models have moved, then step 3
        order = self._gradient_order(slots)
        n_fh, n_grad = self._gradients_that_fit()
        evaluated = sorted(order[:n_grad])
        b0 = self._budget_now()
        stage_values = self._stage_gradients(evaluated)
        if self._budget_on() and n_grad > n_fh:
            self._cost_grad = (self._budget_now() - b0) / n_grad
        b0 = self._budget_now()
        stage_values = self._last_stage_gradient(stage_values)
        rho = self._secant_criterion(slots, stage_values, set(evaluated))
        t2 = time.perf_counter()
        xN, term = self._fresh_last_stage(slots, stage_values, extra)
        if self._budget_on():
            self._cost_head = self._budget_now() - b0
        chosen, ext_cost = self._relinearise_worst(slots, rho, order[:n_fh])
        if self._budget_on() and n_fh > 0:
            # the C runtime's reading of its fused calls: two units each (in time, here, the
            # gradient's and the re-linearisation's estimates)
            self._cost_fh = 2.0 if self.budget_unit == "work" else self._cost_grad + self._cost_stage
        t3 = time.perf_counter()
        b0 = self._budget_now()
        if self.cost_hessian == "fresh" and (not self._cost_hess_const or self._al_resync):
            n_al = self._refresh_cost_hessians(slots, set(chosen) | {self.N - 1})
            if self._budget_on() and n_al > 0:
                self._cost_al = (self._budget_now() - b0) / n_al
        if self.cost_hessian == "fresh":
            self._al_resync = False
        t4 = time.perf_counter()
        b0 = self._budget_now()
        self._commit(slots, term, rho, chosen, xN)
        self._qp_ready = True
        self.timings.update({"prepare": time.perf_counter() - t0, "shift": t1 - t0,
                             "stage_grad_rho": t2 - t1, "stage_hess": t3 - t2, "cost_hessian": t4 - t3})
        # 7. the divergence test of the prepared iterate (section 9)
        self.kkt_proxy = self._kkt_proxy_eval()
        self._lm_prepared()   # the automatic Levenberg-Marquardt term (section 10)
        if self._budget_on():
            self._cost_tail = self._budget_now() - b0
            self._cost_prepare = self._budget_now() - b_start - ext_cost
        if self._iterate_diverged():
            self._flag("diverged")
            if self.recovery and self.mode == "receding":
                self._recover(shifted=True)

    def _shift(self) -> None:
        """Step 1 (receding mode only): the iterate moves one stage forward, the ring head too."""
        if self.mode != "receding":
            return
        N, nx = self.N, self.nx
        x = self.x.copy(); u = self.u.copy(); lam = self.lam.copy()
        mu_g = self.mu_g.copy(); mu_b = self.mu_b.copy()
        x[:N] = self.x[1:]
        u[:N - 1] = self.u[1:]
        lam[:N] = self.lam[1:]
        mu_g[:N - 1] = self.mu_g[1:]
        mu_b[:N - 1] = self.mu_b[1:]
        mu_b[N - 1, :nx] = self.mu_bN
        free_initial_state(nx, mu_b=mu_b)
        self.x, self.u, self.lam, self.mu_g, self.mu_b = x, u, lam, mu_g, mu_b
        self.ring_head = (self.ring_head + 1) % N

    def _prepare_floor(self) -> float:
        """The least a prepare iteration costs after its gradients of stages 0..N-2: step 3
        and steps 5 to 7 with no stage re-linearised (section 14)."""
        al = self._cost_al * (self.N - 1) if self.cost_hessian == "fresh" else 0.0
        return self._cost_head + al + self._cost_tail

    def _rest_cost(self, fresh_al: int) -> float:
        """Steps 5 to 7 with ``fresh_al`` stages of 0..N-2 not re-linearised (section 14)."""
        return (self._cost_al * fresh_al if self.cost_hessian == "fresh" else 0.0) + self._cost_tail

    def _gradient_order(self, slots) -> list:
        """Step 2's order with a budget (section 14): stages 0..N-2 by the distance their
        linear model's point has moved since their last evaluation, |dw_acc + dw| (largest
        first, a non-finite one first, ties: the lower index); stage order without a budget.
        The squares are summed in index order, as the C runtime sums them."""
        if not self._budget_on():
            return list(range(self.N - 1))
        dist = []
        for k in range(self.N - 1):
            s = slots[self._slot(k)]
            d2 = 0.0
            for v in s.dw_acc + s.dw:
                d2 += float(v) * float(v)
            dist.append(d2 if np.isfinite(d2) else np.inf)
        return sorted(range(self.N - 1), key=lambda k: -dist[k])

    def _setting_full(self) -> bool:
        """The setting re-linearises every stage of 0..N-2: M = N-1 (fixed, or after a
        recovery)."""
        return self._recovering > 0 or (not self.M_adaptive and self.M >= self.N - 1)

    def _gradients_that_fit(self):
        """Step 2 with a budget (section 14): ``(n_fh, n_grad)``, how many gradients of stages
        0..N-2, in the order of :meth:`_gradient_order`, while one more and the least rest of
        the iteration fit, the first ``n_fh`` of them with their blocks in the same call (the
        full RTI, as the C runtime's fused function of either Hessian: while that call, the
        gradients of the stages after it and the least rest fit); all gradients without a
        budget. (The C runtime reads its clock before each; here a gradient costs one work
        unit and the fused call two, in time the last estimates.)"""
        if not self._budget_on():
            return 0, self.N - 1
        work = self.budget_unit == "work"
        step = 1.0 if work else self._cost_grad
        fh = 2.0 if work else self._cost_fh
        used = self._budget_now() - self._instant_start
        floor = self._prepare_floor()
        n_fh = 0
        if self._setting_full():
            while (n_fh < self.N - 1
                   and used + n_fh * fh + self._cost_fh + (self.N - 2 - n_fh) * self._cost_grad + floor
                   <= self.budget):
                n_fh += 1
        n = n_fh
        while n < self.N - 1 and used + n_fh * fh + (n - n_fh) * step + self._cost_grad + floor <= self.budget:
            n += 1
        return n_fh, n

    def _stage_gradients(self, stages=None):
        """``(gL, phi, g)`` of every stage at the current iterate (stage_grad); with ``stages``
        (a budget: a list of stages of 0..N-2) of those only, the rest NaN until
        :meth:`_last_stage_gradient`."""
        N = self.N
        n = N - 1 if stages is None else len(stages)
        if stages is None or (n == N - 1 and not self._budget_on()):
            self.work += N
            gL, phi, lv, gv = eval_stages(self.disc.stage_grad, N, self.x[:N], self.u, self.p[:N],
                                          self.lam[1:], self.mu_g)
            # every output of a function is checked, the stage cost l too (as the C runtime does)
            if not self._finite(gL, phi, lv, gv):
                raise self._fail("nonfinite_value", "prepare: stage_grad returned a non-finite value")
            return gL, phi, gv
        gL = np.full((N, self.nw), np.nan)
        phi = np.full((N, self.nx), np.nan)
        gv = np.full((N, self.ng), np.nan)
        if n > 0:
            idx = np.asarray(stages, dtype=int)
            self.work += n
            a, b, lv, c = eval_stages(self.disc.stage_grad, n, self.x[idx], self.u[idx], self.p[idx],
                                      self.lam[idx + 1], self.mu_g[idx])
            if not self._finite(a, b, lv, c):
                raise self._fail("nonfinite_value", "prepare: stage_grad returned a non-finite value")
            gL[idx], phi[idx], gv[idx] = a, b, c
        return gL, phi, gv

    def _last_stage_gradient(self, stage_values):
        """Stage N-1's gradient when :meth:`_stage_gradients` left it out (a budget)."""
        gL, phi, gv = stage_values
        k = self.N - 1
        if np.all(np.isfinite(gL[k])):
            return stage_values
        self.work += 1
        a, b, lv, c = eval_stages(self.disc.stage_grad, 1, self.x[k:k + 1], self.u[k:k + 1], self.p[k:k + 1],
                                  self.lam[k + 1:k + 2], self.mu_g[k:k + 1])
        if not self._finite(a, b, lv, c):
            raise self._fail("nonfinite_value", "prepare: stage_grad returned a non-finite value")
        gL[k], phi[k], gv[k] = a[0], b[0], c[0]
        return gL, phi, gv

    def _secant_criterion(self, slots, stage_values, evaluated=None) -> np.ndarray:
        """Step 2: rho_k (eq. 16) of the stages 0..N-2 with the block the last QP used, and
        their F values moved into the slots; the stages not in ``evaluated`` (gradients cut by
        a budget, section 14) take their linear model's prediction, rho_k = 0, and their
        distance moved grows by the step (it restarts at 0 at an evaluated stage)."""
        gL, phi, gv = stage_values
        rho = np.zeros(self.N)
        for k in range(self.N - 1):
            s = slots[self._slot(k)]
            # the linear model's prediction of F after the stored step
            p_F_w = s.F_w + s.Ht @ s.dw - s.Phit.T @ s.dlam + s.Ct.T @ s.dmu_g + s.dmu_b
            p_phi = s.phi + s.Phit @ s.dw
            p_g = s.g + s.Ct @ s.dw
            if evaluated is not None and k not in evaluated:
                s.F_w, s.phi, s.g = p_F_w, p_phi, p_g
                s.dw_acc = s.dw_acc + s.dw
                continue
            s.dw_acc = np.zeros(self.nw)
            F_w = gL[k] + self.mu_b[k]
            r1 = p_F_w - F_w
            r2 = phi[k] - p_phi
            r3 = p_g - gv[k]
            num = np.linalg.norm(np.concatenate([r1, r2, r3]))
            den = np.linalg.norm(np.concatenate([s.dw, s.dlam, s.dmu_g, s.dmu_b]))
            # a residual at the round-off level of F is noise, not a secant violation
            scale = (np.linalg.norm(np.concatenate([s.F_w, s.phi, s.g]))
                     + np.linalg.norm(np.concatenate([F_w, phi[k], gv[k]])))
            if den == 0.0:
                rho[k] = 0.0
            elif not (np.isfinite(num) and np.isfinite(den)):
                rho[k] = np.inf     # the residual or the step overflows: the stage ranks first
            else:
                rho[k] = num / den if num > EPS_RHO * scale else 0.0
            s.F_w = F_w
            s.phi = phi[k].copy()
            s.g = gv[k].copy()
        return rho

    def _fresh_last_stage(self, slots, stage_values, extra=False):
        """Step 3: stage N-1 and the terminal node, always fresh. Returns ``(x_N, term)``."""
        gL, phi, gv = stage_values
        k = self.N - 1
        s = slots[self._slot(k)]
        s.F_w = gL[k] + self.mu_b[k]
        s.phi = phi[k].copy()
        s.g = gv[k].copy()
        s.dw_acc = np.zeros(self.nw)
        self._set_block(s, k, self.x, self.u, self.lam, self.mu_g)
        xN = phi[k].copy() if self.mode == "receding" and not extra else self.x[self.N].copy()
        term = self._term_eval(xN, self.mu_r, self.nu)
        if not self._finite(s.Ht, s.A_dyn, s.Phit, s.Ct, *term.values()):
            raise self._fail("nonfinite_value", "prepare: a derivative function returned a non-finite value "
                             "(last stage or terminal node)")
        return xN, term

    def _M_now(self, slots, rho) -> int:
        """The number of stages to re-linearise before the budget: N-1 after a recovery, the
        fixed M, or adaptive M (section 14)."""
        if self._recovering > 0:
            return self.N - 1
        if not self.M_adaptive:
            return self.M
        thr = self.M_eta * self.kkt_proxy
        n = 0
        for k in range(self.N - 1):
            s = slots[self._slot(k)]
            den = np.linalg.norm(np.concatenate([s.dw, s.dlam, s.dmu_g, s.dmu_b]))
            if rho[k] * den > thr:
                n += 1
        return min(max(n, self.M_min), self.M_max)

    def _stale(self, slots, k) -> bool:
        """A stage 1..N-2 whose stored linearisation makes a hard path row unsatisfiable for
        the QP: its row of Ct is zero and g (of step 2) lies outside that side's bound."""
        if k == 0 or self.ng == 0:
            return False
        s = slots[self._slot(k)]
        w = self.disc.soft_g
        hard_lo = ~((w[0] > 0) | (w[2] > 0))
        hard_up = ~((w[1] > 0) | (w[3] > 0))
        zero = ~np.any(s.Ct != 0.0, axis=1)
        return bool(np.any(zero & ((hard_lo & (s.g < self.lg_k[k])) | (hard_up & (s.g > self.ug_k[k])))))

    def _relinearise_worst(self, slots, rho, fused=()):
        """Step 4: fresh H for the stages ``fused`` (the budgeted full RTI's of step 2, whose
        blocks the C runtime evaluates with their gradients; they count among the M), for the
        stale stages (:meth:`_stale`), then among the other stages of 0..N-2 for the M with the
        largest rho (ties: lower index), then with a budget for further stages in rho order
        while one more iteration still fits after them, each while the budget allows (section
        14). Returns the stages and the cost of those beyond M."""
        stale = [k for k in range(self.N - 1) if k not in fused and self._stale(slots, k)]
        order = sorted((k for k in range(self.N - 1) if k not in stale and k not in fused),
                       key=lambda i: (-rho[i], i))
        M = self._M_now(slots, rho)
        extend = self._budget_on()
        chosen, ext_cost = [], 0.0
        for i in list(fused) + stale:      # stale: whatever the budget, else the QP is infeasible
            self._relinearise_stage(slots, i)
            chosen.append(i)
        # the stages beyond M keep room for one more iteration after this one
        reserve = self._cost_qp + self._cost_prepare
        for m, i in enumerate(order, start=len(fused)):
            rest = self._rest_cost(self.N - 2 - len(chosen))   # steps 5 to 7 after this stage
            if (m >= M and not extend) or not self._budget_fits(self._cost_stage + rest
                                                                 + (reserve if m >= M else 0.0)):
                break
            b0 = self._budget_now()
            self._relinearise_stage(slots, i)
            chosen.append(i)
            if self._budget_on():
                self._cost_stage = self._budget_now() - b0
                if m >= M:
                    # less the step-5 refresh the stage saved: the rest is the prepare's own
                    ext_cost += self._cost_stage - (self._cost_al if self.cost_hessian == "fresh" else 0.0)
        self.instant_stages += len(chosen)
        return chosen, ext_cost

    def _relinearise_stage(self, slots, i) -> None:
        si = slots[self._slot(i)]
        self._set_block(si, i, self.x, self.u, self.lam, self.mu_g)
        if not self._finite(si.Ht, si.A_dyn, si.Phit, si.Ct):
            raise self._fail("nonfinite_value", f"prepare: stage_hess returned a non-finite value at stage {i}")

    def _refresh_cost_hessians(self, slots, fresh) -> None:
        """Step 5: the cost part of every A_k at the current point (no integrator); the other
        stages keep the curvature of dynamics and constraints A_dyn of their last H."""
        n = 0
        for k in range(self.N):
            if k in fresh:
                continue      # A_l,k was evaluated with its H above, at the same point
            s = slots[self._slot(k)]
            Al = self._cost_hess_eval(k, self.x, self.u)
            if not self._finite(Al):
                raise self._fail("nonfinite_value", f"prepare: stage_hess_cost returned a non-finite value "
                                 f"at stage {k}")
            s.Ht = regularize(s.A_dyn + Al, self.regularization, self.reg_eps)
            n += 1
        return n

    def _commit(self, slots, term, rho, chosen, xN) -> None:
        if self.mode == "receding":
            self.x = self.x.copy()
            self.x[self.N] = xN
        self.slots = slots
        self.term = term
        self.rho = rho
        self.recomputed = sorted(chosen + [self.N - 1])
        self._qp_ready, self._prepare_due, self._shifted = True, False, False
        self._p_shifted = False
        self.status = status_code("ok")

    # ------------------------------------------------------------------ section 9: health
    def set_recovery(self, on: bool = True, max_failures=None) -> None:
        """Automatic recovery (section 9): on/off and K, the consecutive failed feedbacks
        after which the next prepare re-initialises."""
        if not isinstance(on, (bool, np.bool_)):
            raise DopusError.of("invalid_argument", f"recovery must be True or False, got {on!r}")
        k = self.recovery_failures if max_failures is None else max_failures
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 1 <= k <= 2**31 - 1:
            raise DopusError.of("invalid_argument", f"recovery max_failures must be an integer >= 1, "
                                f"got {max_failures!r}")
        self.recovery, self.recovery_failures = bool(on), int(k)
        if not on:
            self._recover_pending = False

    @property
    def flags(self) -> set:
        """The health flags of the last feedback and the prepare after it, by name."""
        return {name for bit, name in FLAGS.items() if self._flags & bit}

    def _flag(self, name: str) -> None:
        self._flags |= _FLAG[name]

    def _compute_scales(self):
        """``(scale_x, scale_u)``: the largest magnitude among the finite bounds, the OCP
        file's guess, the default x0 and 1; a memory state of a rate constraint at least its
        control's."""
        d = self.disc
        gx = np.asarray(d.initial_guess.x, float).reshape(self.N + 1, self.nx)
        gu = np.asarray(d.initial_guess.u, float).reshape(self.N, self.n_u)
        x0 = np.asarray(d.x0, float).reshape(self.nx)

        def scale(cols):
            a = np.abs(np.vstack(cols))
            a[~np.isfinite(a)] = 0.0
            return np.maximum(1.0, a.max(axis=0))
        sx, su = scale([self.lbx[None], self.ubx[None], x0[None], gx]), scale([self.lbu[None], self.ubu[None], gu])
        for srow, crow in getattr(d.spec.model, "memory", ()) or ():
            sx[srow] = max(sx[srow], su[crow])     # a memory state carries its control
        return sx, su

    def _reset_health(self, plan_u) -> None:
        self._n_failed = 0
        self._recover_pending = False
        self._flags = 0
        self.recoveries = 0
        self._recovering = 0
        self._xhat_fresh = True
        self._plan_age = 0
        self._plan_u = np.array(plan_u, float).reshape(self.N, self.n_u).copy()
        self.u0 = self._plan_u[0].copy()
        self.kkt_proxy = 0.0
        self.kkt_proxy_ref = 0.0
        self._kkt_proxy_init = 0.0
        self._n_stalled = 0
        self._kkt_flat_ref, self._n_flat = 0.0, 0
        self._n_gated = 0
        self._gate_rest = 0

    @property
    def failed_feedbacks(self) -> int:
        """Consecutive failed feedbacks."""
        return self._n_failed

    def _clip_u(self, u):
        """u clipped to the control bounds (NaN: 0, then clipped) and whether it changed."""
        u = np.asarray(u, float)
        v = np.minimum(np.maximum(np.where(np.isnan(u), 0.0, u), self.lbu), self.ubu)
        return v, bool(np.any(~(v == u)))

    def _box_ok(self, x, u=None) -> bool:
        """The box test of section 9 on a primal point, or one node of it (finite and inside
        the scale box; u None: the states alone)."""
        box = _SAFETY["DIVERGENCE_BOX"]
        sx, su = self.scales
        with np.errstate(invalid="ignore"):
            return bool(np.all(np.abs(x) <= box * sx + np.abs(self._xhat_last))
                        and (u is None or np.all(np.abs(u) <= box * su)))

    def _plan_control(self, k: int = 0) -> np.ndarray:
        """The control of the last good plan for the instant k sampling instants from now (its
        age plus k, the last control beyond the plan's end)."""
        return self._plan_u[min(self._plan_age + k, self.N - 1)]

    def _fallback_u0(self) -> np.ndarray:
        self.u0, clipped = self._clip_u(self._plan_control() if self.mode == "receding" else self._plan_u[0])
        if clipped:
            self._flag("u0_clipped")
        self._flag("fallback")
        return self.u0.copy()

    def _feedback_failed(self, status: str, message: str, qp_status=None) -> DopusError:
        """A failed feedback: counted, the recovery scheduled after K of them, the fallback
        control attached to the error as ``u0``."""
        self._lm_feedback(status)
        self._n_failed += 1
        if self.recovery and self.mode == "receding" and self._n_failed >= self.recovery_failures:
            self._recover_pending = True
        if status == "diverged":
            self._flag("diverged")
        err = self._fail(status, message, qp_status)
        err.u0 = self._fallback_u0()
        return err

    def _kkt_proxy_eval(self) -> float:
        """The divergence measure of section 9 from the F values of the slots and the
        terminal node."""
        N, nx = self.N, self.nx
        parts = [0.0]
        for k in range(N):
            sl = self.slots[self._slot(k)]
            F = sl.F_w.copy()
            F[:nx] += self.lam[k]
            parts += [np.abs(F).max(initial=0.0), np.abs(sl.phi - self.x[k + 1]).max(initial=0.0)]
        parts.append(np.abs(self.term["gL"] + self.mu_bN + self.lam[N]).max(initial=0.0))
        parts.append(np.abs(self.term["r_eq"]).max(initial=0.0))
        a = np.array(parts)
        return float("nan") if np.any(np.isnan(a)) else float(a.max())

    def _iterate_diverged(self) -> bool:
        ref = max(self.kkt_proxy_ref, 1.0)
        if not self._box_ok(self.x, self.u):
            return True
        if not self._finite(self.lam, self.mu_b, self.mu_bN):
            return True
        return not (self.kkt_proxy <= _SAFETY["DIVERGENCE_KKT"] * ref)

    def _stage_phi(self, x, u, p):
        phi = np.array(self.disc.stage_eval(x, u, p)[0], float).reshape(self.nx)
        return phi

    def _node_phi(self, x, u, k):
        """phi_k(x, u) outside the stage functions of a walk (a predicted or simulated node):
        one stage evaluation, 1 work unit (section 14); None when it fails or is not finite."""
        self.work += 1
        try:
            xn = self._stage_phi(x, u, self.p[k])
        except RuntimeError:
            return None
        return xn if np.all(np.isfinite(xn)) else None

    def _simulate(self, x, u, use_plan: bool) -> bool:
        """Forward simulation from x[0] with the last good plan from its current age on (or
        the OCP file's guess controls), clipped, into x and u; True when every node is
        finite and inside the box."""
        gu = np.asarray(self.disc.initial_guess.u, float).reshape(self.N, self.n_u)
        for k in range(self.N):
            u[k] = self._clip_u(self._plan_control(k) if use_plan else gu[k])[0]
            try:
                x[k + 1] = self._stage_phi(x[k], u[k], self.p[k])
            except RuntimeError:
                return False
            if not np.all(np.isfinite(x[k + 1])):
                return False
        return self._box_ok(x, u)

    def _model_finite_at(self, xs) -> bool:
        """Section 9: the model finite at the state xs with the next control of the last good
        plan (one stage evaluation, 1 work unit; nothing tests before it that it fits,
        section 14)."""
        u = self._clip_u(self._plan_control())[0]
        self.work += 1
        try:
            out = self.disc.stage_eval(xs, u, self.p[0])
        except RuntimeError:
            return False
        return all(np.all(np.isfinite(np.asarray(v, float))) for v in out[:2])

    def _predicted_step(self) -> None:
        """Section 9: after a failed feedback whose QP is still the prepared one, the step of
        that QP for the state the iterate predicts for this instant (dx_0 = 0); its controls
        become the plan of the next fallbacks. A failure of this QP changes nothing."""
        self.work += self.N
        try:
            sol = solve_qp_reference(self.qp_of_current(self.x[0]), tol=self.qp_tol, max_iter=self.qp_max_iter)
        except QPError:
            return
        if not self._finite(*(sol[k] for k in FIELDS_QP)) or not self._box_ok(self.x + sol["x"],
                                                                                 self.u + sol["u"]):
            return
        self._take_step(sol)
        self._plan_u = self.u.copy()
        self._plan_age = 0
        if not self._xhat_fresh:      # no measurement to distrust: the prediction carries the loop
            self._n_failed = 0
            self._recover_pending = False
        self._flag("predicted")

    def _recover(self, shifted: bool) -> None:
        """The automatic recovery of section 9: re-initialise from a forward simulation of the
        predicted state with the last good plan, the iterate's multipliers, every block
        recomputed (Gauss-Newton when the problem has it)."""
        x, u = self.x.copy(), self.u.copy()
        if not self._xhat_fresh:
            if not shifted:
                x[0] = x[1]
        else:
            # the predicted state: one stage evaluation, 1 work unit (section 14)
            x0 = self._node_phi(self._xhat_last, self.u0, 0)
            x[0] = x0 if x0 is not None else self._xhat_last
        if not self._box_ok(x[0]):
            x[0] = self._xhat_last
        self._reinit(x, u)

    def _reinit(self, x, u, reserve: float = 0.0) -> None:
        """The re-initialisation of section 9 from x[0] in place: a forward simulation with
        the last good plan (else the OCP file's guess controls; else the guess itself), the
        iterate's multipliers, every block recomputed (Gauss-Newton when the problem has it).
        With a budget the evaluations leave ``reserve`` free and may continue in the next
        prepares (:meth:`_reinit_walk`, section 14)."""
        N, nx = self.N, self.nx
        gx = np.asarray(self.disc.initial_guess.x, float).reshape(N + 1, nx)
        gu = np.asarray(self.disc.initial_guess.u, float).reshape(N, self.n_u)
        if self._budget_on():
            # the forward simulation in the stage evaluations of _reinit_walk, priced as they
            # are (section 14)
            self._reinit_sim = 1
            self._reinit_controls(u)
        elif not self._simulate(x, u, True) and not self._simulate(x, u, False):
            x[1:] = gx[1:]
            for k in range(N):
                u[k] = self._clip_u(gu[k])[0]
        if self._budget_on():
            try:
                try:
                    self._reinit_start(x, u, self.lam.copy(), self.mu_g.copy(), self.mu_b.copy(),
                                       self.mu_bN.copy(), self.mu_r.copy(), self.nu.copy(), reserve)
                except DopusError:
                    self._reinit_at_guess(reserve)
            except DopusError:
                self._qp_ready = False
                self._reinit_next = -1
                raise
            return
        hessian = self.hessian
        self.hessian = "gauss-newton" if self.has_gn else hessian
        try:
            try:
                self._init_finish(x, u, self.lam.copy(), self.mu_g.copy(), self.mu_b.copy(), self.mu_bN.copy(),
                                  self.mu_r.copy(), self.nu.copy(), "prepare", "at the re-initialised iterate")
            except DopusError:
                # the last resort: the model is not finite there (an outlier of 1e6 rad/s, say);
                # the OCP file's guess whole, x_0 included, with zero multipliers
                x = gx.copy()
                u = np.array([self._clip_u(gu[k])[0] for k in range(N)])
                self._flag("reinit_guess")
                z = np.zeros
                self._init_finish(x, u, z((N + 1, nx)), z((N, self.ng)), z((N, self.nw)), z(nx), z(self.nr),
                                  z(self.ne), "prepare", "at the OCP file's guess")
        except DopusError:
            self.x, self.u = x, u
            self._qp_ready = False
            raise
        finally:
            self.hessian = hessian
        self._reinit_done()

    def _reinit_done(self) -> None:
        """The bookkeeping of a re-initialisation that succeeded: the KKT proxy, the recovery
        phase."""
        self.kkt_proxy = self._kkt_proxy_eval()
        self.kkt_proxy_ref = self.kkt_proxy
        self._n_failed = 0
        self._recover_pending = False
        self.recoveries += 1
        self._recovering = int(_SAFETY["RECOVERY_FULL_RTI"])
        self._flag("recovered")

    def _reinit_at_guess(self, reserve: float) -> None:
        """The last resort of a re-initialisation with a budget: the OCP file's guess whole,
        x_0 included, with zero multipliers."""
        N, nx = self.N, self.nx
        gx = np.asarray(self.disc.initial_guess.x, float).reshape(N + 1, nx)
        gu = np.asarray(self.disc.initial_guess.u, float).reshape(N, self.n_u)
        u = np.array([self._clip_u(gu[k])[0] for k in range(N)])
        self._flag("reinit_guess")
        self._reinit_sim = 0
        z = np.zeros
        self._reinit_start(gx.copy(), u, z((N + 1, nx)), z((N, self.ng)), z((N, self.nw)), z(nx), z(self.nr),
                           z(self.ne), reserve)

    def _reinit_start(self, x, u, lam, mu_g, mu_b, mu_bN, mu_r, nu, reserve: float) -> None:
        """A re-initialisation with a budget (section 14): the iterate in place, fresh slots,
        then :meth:`_reinit_walk`."""
        N = self.N
        self._prepared_extra = False
        self.x, self.u, self.lam, self.mu_g, self.mu_b = x, u, lam, mu_g, mu_b
        self.mu_bN, self.mu_r, self.nu = mu_bN, mu_r, nu
        self.ring_head = 0
        self.slots = [_Slot(self.nx, self.n_u, self.ng) for _ in range(N)]
        self.rho = np.zeros(N)
        self.recomputed = list(range(N))
        self.qp_status = 0
        self.qp_iterations = self.qp_factorizations = 0
        self._qp_ready = False
        self._al_resync = True
        self._n_failed = 0
        self._recover_pending = False
        self._reinit_next = 0
        self._reinit_walk(reserve)

    def _reinit_controls(self, u) -> None:
        """The controls of a re-initialisation's forward simulation (``_reinit_sim`` 1: the last
        good plan's, 2: the guess's; clipped) into ``u``."""
        gu = np.asarray(self.disc.initial_guess.u, float).reshape(self.N, self.n_u)
        for k in range(self.N):
            u[k] = self._clip_u(self._plan_control(k) if self._reinit_sim == 1 else gu[k])[0]

    def _reinit_walk(self, reserve: float) -> None:
        """The evaluations of a re-initialisation with a budget (section 14): the gradient and
        blocks of each stage in stage order while one more, the terminal node and ``reserve``
        still fit, then the terminal node and the QP; the rest in the next prepares
        (``_reinit_next``), whose feedbacks return the fallback control. Gauss-Newton blocks
        when the problem has them. The forward simulation is done by the stage evaluations
        (``_reinit_sim``): x_{k+1} is the phi of stage k's gradient, priced as they are; a stage
        whose evaluation fails or leaves the box starts the walk again from stage 0 with the
        guess controls, then from the guess (as the simulations of :meth:`_reinit` fall
        back)."""
        N = self.N
        term_cost = self._cost_head - self._cost_grad - self._cost_stage
        hessian = self.hessian
        self.hessian = "gauss-newton" if self.has_gn else hessian
        try:
            while (self._reinit_next < N
                   and self._budget_fits(self._cost_grad + self._cost_stage + term_cost + self._cost_tail
                                         + reserve)):
                k = self._reinit_next
                self.work += 1
                try:
                    gL, phi, lv, gv = eval_stages(self.disc.stage_grad, 1, self.x[k:k + 1], self.u[k:k + 1],
                                                  self.p[k:k + 1], self.lam[k + 1:k + 2], self.mu_g[k:k + 1])
                    ok = self._finite(gL, phi, lv, gv)
                except RuntimeError:
                    if not self._reinit_sim:
                        raise
                    ok = False
                if self._reinit_sim and (not ok or (k == 0 and not self._box_ok(self.x[0]))
                                         or not self._box_ok(phi[0], self.u[k])):
                    # the simulation failed: again from stage 0 with the guess controls, else the guess
                    self._reinit_sim = 2 if self._reinit_sim == 1 else 0
                    self.x, self.u = self.x.copy(), self.u.copy()
                    if self._reinit_sim:
                        self._reinit_controls(self.u)
                    else:
                        gx = np.asarray(self.disc.initial_guess.x, float).reshape(N + 1, self.nx)
                        gu = np.asarray(self.disc.initial_guess.u, float).reshape(N, self.n_u)
                        self.x[1:] = gx[1:]
                        for j in range(N):
                            self.u[j] = self._clip_u(gu[j])[0]
                    self._reinit_next = 0
                    continue
                if not ok:
                    raise self._fail("nonfinite_value", "prepare: stage_grad returned a non-finite value at the "
                                     "re-initialised iterate")
                if self._reinit_sim:
                    self.x = self.x.copy()
                    self.x[k + 1] = phi[0]
                sl = self.slots[self._slot(k)]
                sl.F_w = gL[0] + self.mu_b[k]
                sl.phi = phi[0].copy()
                sl.g = gv[0].copy()
                self._set_block(sl, k, self.x, self.u, self.lam, self.mu_g)
                if not self._finite(sl.Ht, sl.A_dyn, sl.Phit, sl.Ct):
                    raise self._fail("nonfinite_value", "prepare: stage_hess returned a non-finite value at the "
                                     "re-initialised iterate")
                self._reinit_next = k + 1
            self._prepare_due = self._shifted = self._p_shifted = False
            if self._reinit_next == N:
                term = self._term_eval(self.x[N], self.mu_r, self.nu)
                if not self._finite(*term.values()):
                    raise self._fail("nonfinite_value", "prepare: a derivative function returned a non-finite "
                                     "value at the re-initialised iterate (terminal node)")
                self.term = term
                self._al_resync = False
                self._qp_ready = True
                self.status = status_code("ok")
                self._lm_start()
                self._reinit_next = -1
                self._reinit_done()
        finally:
            self.hessian = hessian

    def _reinit_continue(self) -> None:
        """A prepare while a re-initialisation is under way (a budget, section 14): the shift
        of the instant (the evaluated stages move with the ring, the new last node is simulated
        from the one before it), then the evaluations that fit; a failed one falls back on the
        guess."""
        N = self.N
        if self.mode == "receding" and not self._shifted:
            if self._reinit_sim and self._reinit_next == 0:
                # the node that becomes x_0, not simulated by the walk yet: one stage
                # evaluation of the budget (1 work unit)
                x1 = self._node_phi(self.x[0], self.u[0], 0)
                if x1 is not None:
                    self.x = self.x.copy()
                    self.x[1] = x1
            self._shift()
            self._shifted = True
            self._reinit_next = max(self._reinit_next - 1, 0)
            # the new last node: simulated by the walk, or (no simulation: after the OCP file's
            # guess) from the one before it, one stage evaluation of the budget (1 work unit;
            # nothing tests before it that it fits, section 14)
            xn = None if self._reinit_sim else self._node_phi(self.x[N - 1], self.u[N - 1], N - 1)
            if xn is not None:
                self.x = self.x.copy()
                self.x[N] = xn
        try:
            try:
                self._reinit_walk(0.0)
            except DopusError:
                self._reinit_at_guess(0.0)
        except DopusError:
            self._qp_ready = False
            self._reinit_next = -1
            raise

    # ------------------------------------------------------------------ section 10: automatic lm
    def lm_hessian_scale(self) -> float:
        """h: the largest |diagonal entry| of the QP's stage and terminal blocks."""
        d = [np.abs(np.diag(sl.Ht)).max() for sl in self.slots] + [np.abs(np.diag(self.term["A"])).max()]
        return float(max(1e-300, *d))

    def lm_convex(self, lm: float) -> bool:
        """The QP with the term lm is strictly convex on the dynamics: the Riccati recursion
        of its blocks (lower triangles; inequalities and terminal constraints left out)
        has control pivots above DOPUS_LM_PIVOT_REL h."""
        nx, nw = self.nx, self.nw
        tol = _SAFETY["LM_PIVOT_REL"] * self.lm_scale

        def sym(A):
            return np.tril(A) + np.tril(A, -1).T
        P = sym(self.term["A"]) + lm * np.eye(nx)
        for k in range(self.N - 1, -1, -1):
            sl = self.slots[self._slot(k)]
            Z = sym(sl.Ht) + lm * np.eye(nw) + sl.Phit.T @ (P @ sl.Phit)
            nu = nw - nx
            L = np.zeros((nu, nu))
            Zuu = Z[nx:, nx:]
            # the pivot floor: tol, or the round-off of a pivot formed from entries of Z_uu's
            # size (DOPUS_LM_ROUNDOFF: nw rounding units of its largest |diagonal entry|)
            floor = max(tol, nw * np.finfo(float).eps * float(np.abs(np.diag(Zuu)).max()))
            for j in range(nu):
                d = Zuu[j, j] - L[j, :j] @ L[j, :j]
                if not d > floor:
                    return False
                L[j, j] = np.sqrt(d)
                for i in range(j + 1, nu):
                    L[i, j] = (Zuu[i, j] - L[i, :j] @ L[j, :j]) / L[j, j]
            if k == 0:
                break
            Y = np.linalg.solve(L, Z[nx:, :nx])
            Zxx = Z[:nx, :nx]
            P = 0.5 * (Zxx + Zxx.T) - Y.T @ Y
        return True

    def lm_near_convex(self) -> bool:
        """Feedback, once the measurement is in the QP: the automatic term is within one raise
        step of convex (section 4, feedback; dopus_lm_near_convex): below its maximum and, when
        this feedback capped it, the QP convex with the capped term raised once (to
        LM_MIN_REL h from below it, else times LM_RAISE). The prepare's test certifies that
        when the raised term is at least the prepared one; else one test at the raised term."""
        lo, hi = _SAFETY["LM_MIN_REL"] * self.lm_scale, _SAFETY["LM_MAX_REL"] * self.lm_scale
        if not (self.lm_auto and self.lm < hi):
            return False
        if self.lm_uncapped < 0.0:
            return True
        up = min(lo if self.lm < lo else self.lm * _SAFETY["LM_RAISE"], hi)
        if up >= self.lm_uncapped and self.lm_uncapped < hi:
            return True
        return self.lm_convex(up)

    def _lm_raise(self) -> None:
        lo, hi = _SAFETY["LM_MIN_REL"] * self.lm_scale, _SAFETY["LM_MAX_REL"] * self.lm_scale
        if self.lm_uncapped > self.lm:
            # the first raise after the cap of _lm_measured restores the term it capped
            self.lm, self.lm_uncapped = self.lm_uncapped, -1.0
            return
        self.lm = min(lo if self.lm < lo else self.lm * _SAFETY["LM_RAISE"], hi)

    def lm_convexify(self) -> None:
        """The automatic term raised (section 10's steps) until the QP is convex or at its maximum."""
        hi = _SAFETY["LM_MAX_REL"] * self.lm_scale
        while not self.lm_convex(self.lm) and self.lm < hi:
            self._lm_raise()

    def _lm_start(self) -> None:
        """After init or a re-initialisation: the scale, lm from 0, raised until convex."""
        if not self.lm_auto:
            return
        self.lm_scale = self.lm_hessian_scale()
        self.lm = 0.0
        self._lm_kkt_prev = -1.0
        self.lm_uncapped = -1.0
        self.lm_held = False
        self.lm_convexify()

    def _lm_prepared(self) -> None:
        """After a prepare: the scale, a raise when the KKT proxy grew, then convex; held when
        that last test raised the term (the feedback's decay undone: the stall test, section 9)."""
        self.lm_held = False
        if not self.lm_auto:
            return
        floor = 1e-8 * max(self.kkt_proxy_ref, 1.0)
        prev = max(self._lm_kkt_prev, floor)
        self.lm_scale = self.lm_hessian_scale()
        self.lm_uncapped = -1.0
        if self._lm_kkt_prev >= 0.0 and not self.kkt_proxy <= _SAFETY["LM_KKT_GROWTH"] * prev:
            self._lm_raise()
        self._lm_kkt_prev = self.kkt_proxy
        before = self.lm
        self.lm_convexify()
        self.lm_held = self.lm > before

    def _lm_measured(self, xhat0) -> None:
        """Feedback, once the measurement is known: the term capped by the distance from the
        solution, ``LM_KKT_REL h d^2`` with ``d = max(proxy, max_i |dx0_i| / scale_x_i)`` (0
        below ``LM_MIN_REL h``)."""
        self.lm_uncapped = -1.0
        if not self.lm_auto:
            return
        d = max(self.kkt_proxy, float(np.max(np.abs(xhat0 - self.x[0]) / self.scales[0])))
        cap = _SAFETY["LM_KKT_REL"] * self.lm_scale * d * d
        if not self.lm <= cap:
            self.lm_uncapped = self.lm
            self.lm = 0.0 if cap < _SAFETY["LM_MIN_REL"] * self.lm_scale else cap

    def _lm_feedback(self, status: str) -> None:
        """After a feedback: lowered after a step, raised after a failed QP or a divergence."""
        if not self.lm_auto:
            return
        if status == "ok":
            self.lm *= _SAFETY["LM_LOWER"]
            if self.lm < _SAFETY["LM_MIN_REL"] * self.lm_scale:
                self.lm = 0.0
        elif status in ("qp", "diverged"):
            self._lm_raise()

    # ------------------------------------------------------------------ KKT
    def kkt(self, xhat0) -> dict:
        """Section 6 at the current iterate for initial state ``xhat0``."""
        self._need_init()
        xhat0 = self._with_memory(xhat0)
        return kkt_measure(self.disc, xhat0, self.x, self.u, self.lam, self.mu_g, self.mu_b,
                           self.mu_bN, self.mu_r, self.nu, self.p)

    # ------------------------------------------------------------------ globalised first solve
    def globalised_start(self) -> None:
        """Forget the penalty and the counts of a previous globalised solve (section 15)."""
        from .globalise import GlobState

        self.glob = GlobState()

    def globalised_step(self, xhat0) -> None:
        """One step of the globalised first solve from the prepared iterate (section 15)."""
        from .globalise import globalised_step

        if getattr(self, "glob", None) is None:
            self.globalised_start()
        globalised_step(self, self.glob, xhat0)

    def init_globalised(self, xhat0, guess=None, max_work: float = 0.0, max_iter: int = 100, tol=None) -> bool:
        """``init`` at the guess, then globalised steps until the KKT measure is at most
        ``tol`` (True) or a limit ends them (False; ``glob.reason``) (section 15)."""
        from .globalise import init_globalised

        self.globalised_start()
        return init_globalised(self, self.glob, xhat0, guess, max_work, max_iter, tol)

    def guess(self):
        """The current iterate as a ``Guess``."""
        from ..problem.ocp import Guess

        return Guess(x=self.x.copy(), u=self.u.copy(), lam=self.lam.copy(), mu_g=self.mu_g.copy(),
                     mu_b=self.mu_b.copy(), mu_bN=self.mu_bN.copy(), mu_r=self.mu_r.copy(), nu=self.nu.copy())
