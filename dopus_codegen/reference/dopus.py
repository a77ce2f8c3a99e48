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

import numpy as np

from .. import settings
from ..errors import DopusError, qp_status_code as status_code_qp, status_code
from ..settings import SettingError
from .kkt import eval_stages, kkt_measure, node_parameters
from .qp import QPError, free_initial_state, solve_qp_reference

__all__ = ["DopusError", "ReferenceDopus", "regularize", "EPS_RHO"]

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
    __slots__ = ("Ht", "Phit", "Ct", "F_w", "phi", "g", "dw", "dlam", "dmu_g", "dmu_b", "A_dyn")

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

    def copy(self):
        s = _Slot.__new__(_Slot)
        for name in _Slot.__slots__:
            setattr(s, name, getattr(self, name).copy())
        return s


def _arr(v, shape, what):
    a = np.array(v, dtype=float)
    if a.size != int(np.prod(shape)):
        raise DopusError.of("invalid_argument", f"{what}: expected shape {shape}, got {a.shape}")
    return a.reshape(shape)


def _setting(check, *args):
    """A value checked by :mod:`dopus_codegen.settings`; a bad one is DopusError (invalid
    argument), as the C backend reports it."""
    try:
        return check(*args)
    except SettingError as exc:
        raise DopusError.of("invalid_argument", str(exc)) from None


class ReferenceDopus:
    """The DOPUS iteration in numpy (backend protocol, docs/algorithm.md section 7).

    Extra to the protocol: :meth:`qp_of_current` (the QP the next ``feedback`` solves,
    in the :mod:`dopus_codegen.reference.qp` format), ``last_qp`` / ``last_qp_solution`` (the
    QP solved by the last ``feedback`` and its solution) and ``status``.
    """

    def __init__(self, disc, M: int = settings.DEFAULTS["M"], mode: str = settings.DEFAULTS["mode"],
                 hessian: str = settings.DEFAULTS["hessian"],
                 regularization: str = settings.DEFAULTS["regularization"],
                 reg_eps: float = settings.DEFAULTS["reg_eps"], qp_tol: float = settings.DEFAULTS["qp_tol"],
                 cost_hessian: str = settings.DEFAULTS["cost_hessian"], lm: float = settings.DEFAULTS["lm"],
                 qp_max_iter=None):
        self.disc = disc
        self.cost_hessian = _setting(settings.check, "cost_hessian", cost_hessian)
        self.N, self.nx, self.n_u, self.ng = disc.N, disc.nx, disc.nu, disc.ng
        self.nr, self.ne, self.np = disc.nr, disc.ne, disc.np
        self.nw = self.nx + self.n_u
        self.hessian = _setting(settings.check, "hessian", hessian)
        if self.hessian == "exact":
            self._stage_hess, self._term_hess = disc.stage_hess_exact, disc.term_hess_exact
        else:
            if getattr(disc, "stage_hess_gn", None) is None or getattr(disc, "term_hess_gn", None) is None:
                raise DopusError.of("invalid_argument", "hessian='gauss-newton' needs a least-squares stage cost "
                                    "(the OCP declares no stage_least_squares)")
            self._stage_hess, self._term_hess = disc.stage_hess_gn, disc.term_hess_gn
        # (x, u, p) -> A_l, the stage-cost part of A (section 4 step 5)
        self._stage_hess_cost = getattr(disc, "stage_hess_cost_exact" if self.hessian == "exact"
                                        else "stage_hess_cost_gn", None)
        if cost_hessian == "fresh" and self._stage_hess_cost is None:
            raise DopusError.of("invalid_argument", "cost_hessian='fresh' needs the stage-cost Hessian function "
                                "of the problem (Discretized.stage_hess_cost); use cost_hessian='stored'")
        self.regularization = _setting(settings.check, "regularization", regularization)
        self.reg_eps = _setting(settings.positive, "reg_eps", reg_eps)
        self.qp_tol = _setting(settings.positive, "qp_tol", qp_tol)
        self.lm = _setting(settings.nonnegative, "lm", lm)
        self.qp_max_iter = None
        if qp_max_iter is not None:
            self.set_qp_max_iter(qp_max_iter)
        self.qp_status = 0
        self.set_M(M)
        self.set_mode(mode)
        self.lbx, self.ubx = np.asarray(disc.lbx, float), np.asarray(disc.ubx, float)
        self.lbu, self.ubu = np.asarray(disc.lbu, float), np.asarray(disc.ubu, float)
        self.lg, self.ug = np.asarray(disc.lg, float).reshape(self.ng), np.asarray(disc.ug, float).reshape(self.ng)
        self.lr, self.ur = np.asarray(disc.lr, float).reshape(self.nr), np.asarray(disc.ur, float).reshape(self.nr)
        self.p = node_parameters(disc, None)
        self.status = status_code("ok")
        self.timings = {}
        self.qp_iterations = 0
        self.rho = np.zeros(self.N)
        self.recomputed = []
        self.last_qp = None
        self.last_qp_solution = None
        self._initialised = False
        # calling order (docs/algorithm.md section 4): a prepared QP, a prepare due, the shift
        # of this sampling instant done (a prepare failed after it)
        self._qp_ready = self._prepare_due = self._shifted = False

    # ------------------------------------------------------------------ settings
    def set_M(self, M: int) -> None:
        """Values above N-1 mean the full RTI (N-1), as in the C runtime."""
        self.M = min(_setting(settings.count, "M", M), self.N - 1)

    def set_mode(self, mode: str) -> None:
        self.mode = _setting(settings.check, "mode", mode)

    def set_qp_max_iter(self, max_iter: int) -> None:
        """The QP solver's iteration limit (None: the reference QP solver's own); reaching it
        fails the feedback with the QP status ``max_iter``, as in the C runtime."""
        self.qp_max_iter = None if max_iter is None else _setting(settings.count, "qp_max_iter", max_iter, 1)

    def set_parameters(self, p) -> None:
        """``(np,)`` for every node or ``(N+1, np)``; used from the next evaluation on."""
        self.p = node_parameters(self.disc, p)

    # ------------------------------------------------------------------ evaluations
    def _slot(self, k: int) -> int:
        return (self.ring_head + k) % self.N

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
        A, s.Phit, s.Ct = self._stage_hess_eval(k, x, u, lam, mu_g)
        s.A_dyn = A - self._cost_hess_eval(k, x, u) if self._stage_hess_cost is not None else A
        s.Ht = regularize(A, self.regularization, self.reg_eps)
        return s

    def _term_eval(self, xN, mu_r, nu):
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
        N, nx, nu, ng = self.N, self.nx, self.n_u, self.ng
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
        slots = [_Slot(nx, nu, ng) for _ in range(N)]
        gL, phi, lv, gv = eval_stages(self.disc.stage_grad, N, x[:N], u, self.p[:N], lam[1:], mu_g)
        for k in range(N):
            s = slots[k]
            s.F_w = gL[k] + mu_b[k]
            s.phi = phi[k].copy()
            s.g = gv[k].copy()
            self._set_block(s, k, x, u, lam, mu_g)
        term = self._term_eval(x[N], g.mu_r, g.nu)
        if not self._finite(gL, phi, lv, gv, *[v for s in slots for v in (s.Ht, s.A_dyn, s.Phit, s.Ct)],
                            *term.values()):
            raise DopusError.of("nonfinite_value", "init: a derivative function returned a non-finite value "
                                "at the guess")
        self.x, self.u, self.lam, self.mu_g, self.mu_b = x, u, lam, mu_g, mu_b
        self.mu_bN, self.mu_r, self.nu = g.mu_bN.copy(), g.mu_r.copy(), g.nu.copy()
        self.ring_head = 0
        self._xhat_last = xhat0.copy()
        self.slots = slots
        self.term = term
        self.rho = np.zeros(N)
        self.recomputed = list(range(N))
        self.status = status_code("ok")
        self._initialised = True
        self._qp_ready = True        # init assembles the QP of the guess
        self._prepare_due = False    # a feedback must come first
        self._shifted = False
        self.timings = {"init": time.perf_counter() - t0}

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
            lgq[k] = self.lg - s.g
            ugq[k] = self.ug - s.g
            lbw[k, :nx] = self.lbx - self.x[k]
            ubw[k, :nx] = self.ubx - self.x[k]
            lbw[k, nx:] = self.lbu - self.u[k]
            ubw[k, nx:] = self.ubu - self.u[k]
        free_initial_state(nx, lower=lbw, upper=ubw)
        t = self.term
        gN = t["gL"] - t["R"].T @ self.mu_r - t["Req"].T @ self.nu
        return {
            "N": N, "nx": nx, "nu": nu, "ng": ng, "nr": nr, "ne": ne,
            "H": H, "g": gq, "Phi": Phi, "b": b, "x0": xhat0 - self.x[0],
            "HN": t["A"] + shift[:nx, :nx], "gN": gN, "lbw": lbw, "ubw": ubw,
            "lbxN": self.lbx - self.x[N], "ubxN": self.ubx - self.x[N],
            "C": C, "lg": lgq, "ug": ugq, "R": t["R"].copy(), "lr": self.lr - t["r"], "ur": self.ur - t["r"],
            "Req": t["Req"].copy(), "req": -t["r_eq"],
        }

    # ------------------------------------------------------------------ feedback
    def feedback(self, xhat0) -> np.ndarray:
        """Solve the QP for ``xhat0``, store ``domega`` per slot, full step; return ``u_0``."""
        self._need_init()
        t0 = time.perf_counter()
        xhat0 = np.array(xhat0, dtype=float).reshape(-1)
        if xhat0.size != self.nx:
            raise self._fail("invalid_argument", f"feedback: xhat0 must be {self.nx} numbers, got {xhat0.size}")
        if not np.all(np.isfinite(xhat0)):
            raise self._fail("nonfinite_input", f"feedback: xhat0 must be {self.nx} finite numbers, got {xhat0}")
        if not self._qp_ready:
            raise self._fail("not_prepared", "feedback: no prepared QP (call prepare after each feedback)")
        qp = self.qp_of_current(xhat0)
        self._xhat_last = xhat0.copy()
        # the QP is attempted: a prepare (with its shift) is due, whatever the outcome
        self._prepare_due, self._shifted = True, False
        t1 = time.perf_counter()
        try:
            sol = solve_qp_reference(qp, tol=self.qp_tol, max_iter=self.qp_max_iter)
        except QPError as exc:
            self.qp_status = status_code_qp(exc.qp_status)
            raise self._fail("qp", f"feedback: {exc}; QP status {self.qp_status} ({exc.qp_status})",
                             exc.qp_status) from None
        self.qp_status = status_code_qp("solved")
        t2 = time.perf_counter()
        N, nx = self.N, self.nx
        dW = np.hstack([sol["x"][:N], sol["u"]])
        for k in range(N):
            s = self.slots[self._slot(k)]
            s.dw = dW[k].copy()
            s.dlam = sol["lam"][k + 1] - self.lam[k + 1]
            s.dmu_g = sol["mu_g"][k] - self.mu_g[k]
            s.dmu_b = sol["mu_b"][k] - self.mu_b[k]
        # full step (eq. 4): primal increment, multipliers replaced
        self.x = self.x + sol["x"]
        self.u = self.u + sol["u"]
        self.lam = sol["lam"].copy()
        self.mu_g = sol["mu_g"].copy()
        self.mu_b = sol["mu_b"].copy()
        self.mu_bN = sol["mu_bN"].copy()
        self.mu_r = sol["mu_r"].copy()
        self.nu = sol["nu"].copy()
        self.qp_iterations = int(sol.get("iterations", 0))
        self.last_qp = qp
        self.last_qp_solution = sol
        self._qp_ready = False
        self.status = status_code("ok")
        t3 = time.perf_counter()
        self.timings.update({"feedback": t3 - t0, "qp": t2 - t1})
        return self.u[0].copy()

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
        t0 = time.perf_counter()
        self._qp_ready = False
        if not self._shifted:        # a retry after a failed prepare does not shift again
            self._shift()
            self._shifted = self.mode == "receding"
        t1 = time.perf_counter()
        slots = [s.copy() for s in self.slots]
        stage_values = self._stage_gradients()
        rho = self._secant_criterion(slots, stage_values)
        t2 = time.perf_counter()
        xN, term = self._fresh_last_stage(slots, stage_values)
        chosen = self._relinearise_worst(slots, rho)
        t3 = time.perf_counter()
        if self.cost_hessian == "fresh":
            self._refresh_cost_hessians(slots, set(chosen) | {self.N - 1})
        t4 = time.perf_counter()
        self._commit(slots, term, rho, chosen, xN)
        self.timings.update({"prepare": time.perf_counter() - t0, "shift": t1 - t0,
                             "stage_grad_rho": t2 - t1, "stage_hess": t3 - t2, "cost_hessian": t4 - t3})

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

    def _stage_gradients(self):
        """``(gL, phi, g)`` of every stage at the current iterate (stage_grad)."""
        gL, phi, lv, gv = eval_stages(self.disc.stage_grad, self.N, self.x[:self.N], self.u, self.p[:self.N],
                                      self.lam[1:], self.mu_g)
        # every output of a function is checked, the stage cost l too (as the C runtime does)
        if not self._finite(gL, phi, lv, gv):
            raise self._fail("nonfinite_value", "prepare: stage_grad returned a non-finite value")
        return gL, phi, gv

    def _secant_criterion(self, slots, stage_values) -> np.ndarray:
        """Step 2: rho_k (eq. 16) of the stages 0..N-2 with the block the last QP used, and
        their F values moved into the slots."""
        gL, phi, gv = stage_values
        rho = np.zeros(self.N)
        for k in range(self.N - 1):
            s = slots[self._slot(k)]
            F_w = gL[k] + self.mu_b[k]
            r1 = s.F_w + s.Ht @ s.dw - s.Phit.T @ s.dlam + s.Ct.T @ s.dmu_g + s.dmu_b - F_w
            r2 = -(s.phi + s.Phit @ s.dw) + phi[k]
            r3 = s.g + s.Ct @ s.dw - gv[k]
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

    def _fresh_last_stage(self, slots, stage_values):
        """Step 3: stage N-1 and the terminal node, always fresh. Returns ``(x_N, term)``."""
        gL, phi, gv = stage_values
        k = self.N - 1
        s = slots[self._slot(k)]
        s.F_w = gL[k] + self.mu_b[k]
        s.phi = phi[k].copy()
        s.g = gv[k].copy()
        self._set_block(s, k, self.x, self.u, self.lam, self.mu_g)
        xN = phi[k].copy() if self.mode == "receding" else self.x[self.N].copy()
        term = self._term_eval(xN, self.mu_r, self.nu)
        if not self._finite(s.Ht, s.A_dyn, s.Phit, s.Ct, *term.values()):
            raise self._fail("nonfinite_value", "prepare: a derivative function returned a non-finite value "
                             "(last stage or terminal node)")
        return xN, term

    def _relinearise_worst(self, slots, rho) -> list:
        """Step 4: fresh H for the M stages among 0..N-2 with the largest rho (ties: lower index)."""
        order = sorted(range(self.N - 1), key=lambda i: (-rho[i], i))
        chosen = order[:self.M]
        for i in chosen:
            si = slots[self._slot(i)]
            self._set_block(si, i, self.x, self.u, self.lam, self.mu_g)
            if not self._finite(si.Ht, si.A_dyn, si.Phit, si.Ct):
                raise self._fail("nonfinite_value", f"prepare: stage_hess returned a non-finite value at stage {i}")
        return chosen

    def _refresh_cost_hessians(self, slots, fresh) -> None:
        """Step 5: the cost part of every A_k at the current point (no integrator); the other
        stages keep the curvature of dynamics and constraints A_dyn of their last H."""
        for k in range(self.N):
            if k in fresh:
                continue      # A_l,k was evaluated with its H above, at the same point
            s = slots[self._slot(k)]
            Al = self._cost_hess_eval(k, self.x, self.u)
            if not self._finite(Al):
                raise self._fail("nonfinite_value", f"prepare: stage_hess_cost returned a non-finite value "
                                 f"at stage {k}")
            s.Ht = regularize(s.A_dyn + Al, self.regularization, self.reg_eps)

    def _commit(self, slots, term, rho, chosen, xN) -> None:
        if self.mode == "receding":
            self.x = self.x.copy()
            self.x[self.N] = xN
        self.slots = slots
        self.term = term
        self.rho = rho
        self.recomputed = sorted(chosen + [self.N - 1])
        self._qp_ready, self._prepare_due, self._shifted = True, False, False
        self.status = status_code("ok")

    # ------------------------------------------------------------------ KKT
    def kkt(self, xhat0) -> dict:
        """Section 6 at the current iterate for initial state ``xhat0``."""
        self._need_init()
        return kkt_measure(self.disc, xhat0, self.x, self.u, self.lam, self.mu_g, self.mu_b,
                           self.mu_bN, self.mu_r, self.nu, self.p)

    def guess(self):
        """The current iterate as a ``Guess``."""
        from ..problem.ocp import Guess

        return Guess(x=self.x.copy(), u=self.u.copy(), lam=self.lam.copy(), mu_g=self.mu_g.copy(),
                     mu_b=self.mu_b.copy(), mu_bN=self.mu_bN.copy(), mu_r=self.mu_r.copy(), nu=self.nu.copy())
