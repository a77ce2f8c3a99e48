"""The simulated plant of the software-in-the-loop test: the continuous model under CVODES.

The controller predicts with a fixed-step integrator (RK4 with a few substeps); the plant
integrates the continuous ODE with SUNDIALS CVODES (BDF, variable step and order) at tight
tolerances, so the closed loop sees the model mismatch of a real discretisation, not its
own prediction played back.

The input is held constant over each step (zero-order hold). The ODE is integrated in the
scaled time ``s = t / h`` on ``[0, 1]`` with the step length ``h`` as an integrator
parameter, so one integrator object serves the regular sampling interval and the partial
intervals around an event that falls between two sampling instants.
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from .. import interrupt


class PlantError(RuntimeError):
    """The plant could not be integrated (bad input, or CVODES failed)."""


class Plant:
    """CVODES simulation of ``xdot = ode_fn(x, u, p)`` with ``u`` held constant per step.

    Parameters
    ----------
    ode_fn : casadi.Function
        Inputs ``(x, u, p)``, first output ``xdot`` of the size of ``x``.
    dt : float
        Default step length (the sampling interval), seconds.
    np : int
        Number of parameters ``p`` (0 when the model has none). Checked against ``ode_fn``.
    reltol, abstol : float
        CVODES tolerances (the scenario of the paper uses 1e-10 for both).
    method : "adams" or "bdf"
        CVODES linear multistep family. Adams (orders up to 12) is the default: mechanical
        plants such as the robot arm are not stiff, and at the same tolerances its global
        error is about five times smaller than BDF's (measured against solve_ivp at 1e-12:
        5e-8 against 2.6e-7 over 0.5 s of the arm swinging at 14 rad/s). Use "bdf" for a
        stiff plant.
    """

    def __init__(self, ode_fn, dt: float, np: int = 0, reltol: float = 1e-10, abstol: float = 1e-10,
                 method: str = "adams"):
        if not isinstance(ode_fn, ca.Function):
            raise PlantError(f"Plant: ode_fn must be a casadi.Function (x, u, p) -> xdot, got {type(ode_fn).__name__}")
        if ode_fn.n_in() != 3:
            raise PlantError(f"Plant: ode_fn must take exactly three inputs (x, u, p), it takes {ode_fn.n_in()}")
        if ode_fn.n_out() < 1:
            raise PlantError("Plant: ode_fn has no output (expected xdot)")
        for i, what in enumerate(("x", "u", "p")):
            if ode_fn.size2_in(i) != 1 and ode_fn.numel_in(i) != 0:
                raise PlantError(f"Plant: input {what} of ode_fn must be a column vector, "
                                 f"it is {ode_fn.size1_in(i)}x{ode_fn.size2_in(i)}")
        self.nx = int(ode_fn.numel_in(0))
        self.nu = int(ode_fn.numel_in(1))
        self.np = int(ode_fn.numel_in(2))
        if self.nx == 0:
            raise PlantError("Plant: the model has no state")
        if ode_fn.numel_out(0) != self.nx:
            raise PlantError(f"Plant: ode_fn returns {ode_fn.numel_out(0)} values, expected nx = {self.nx}")
        if int(np) != self.np:
            raise PlantError(f"Plant: np = {np} but ode_fn takes {self.np} parameters")
        dt = float(dt)
        if not (np_isfinite(dt) and dt > 0):
            raise PlantError(f"Plant: dt must be a positive finite number, got {dt}")
        for name, tol in (("reltol", reltol), ("abstol", abstol)):
            if not (np_isfinite(tol) and tol > 0):
                raise PlantError(f"Plant: {name} must be positive and finite, got {tol}")
        if method not in ("adams", "bdf"):
            raise PlantError(f"Plant: method must be 'adams' or 'bdf', got {method!r}")
        self.dt = dt
        self.ode_fn = ode_fn
        self.reltol, self.abstol, self.method = float(reltol), float(abstol), method

        x = ca.MX.sym("x", self.nx)
        u = ca.MX.sym("u", self.nu)
        p = ca.MX.sym("p", self.np)
        h = ca.MX.sym("h")
        xdot = ode_fn(x, u, p)
        if isinstance(xdot, (list, tuple)):
            xdot = xdot[0]
        dae = {"x": x, "p": ca.vertcat(u, p, h), "ode": h * ca.reshape(xdot, self.nx, 1)}
        opts = {"reltol": float(reltol), "abstol": float(abstol), "max_num_steps": 100000,
                "linear_multistep_method": method,
                "show_eval_warnings": False, "disable_internal_warnings": True}
        self._integrator = ca.integrator("plant", "cvodes", dae, 0.0, 1.0, opts)

    def _vector(self, value, n: int, what: str) -> np.ndarray:
        arr = np.asarray(value if value is not None else np.zeros(n), dtype=float).reshape(-1)
        if arr.size != n:
            raise PlantError(f"Plant: {what} has {arr.size} entries, expected {n}")
        if not np.all(np.isfinite(arr)):
            raise PlantError(f"Plant: {what} is not finite: {arr}")
        return arr

    def step(self, x, u, p=None, duration: float | None = None) -> np.ndarray:
        """State after ``duration`` (default ``dt``) seconds from ``x`` with ``u`` held constant."""
        x = self._vector(x, self.nx, "state x")
        u = self._vector(u, self.nu, "control u")
        p = self._vector(p, self.np, "parameter p")
        h = self.dt if duration is None else float(duration)
        if not (np_isfinite(h) and h >= 0):
            raise PlantError(f"Plant: step duration must be finite and >= 0, got {h}")
        if h == 0:
            return x.copy()
        try:
            res = self._integrator(x0=x, p=np.concatenate([u, p, [h]]))
        except RuntimeError as err:  # CVODES failure (too many steps, convergence failure, ...)
            interrupt.check()        # or CasADi's report of a Ctrl-C
            raise PlantError(f"Plant: CVODES failed over a step of {h} s from x = {x}, u = {u}: "
                             f"{str(err).splitlines()[-1] if str(err) else err}") from None
        # CasADi may also swallow a Ctrl-C whole: inside CVODES a failed right-hand side can be
        # retried with a smaller step, and the integration then succeeds
        interrupt.check()
        xf = np.asarray(res["xf"], dtype=float).reshape(-1)
        if not np.all(np.isfinite(xf)):
            raise PlantError(f"Plant: the state became non-finite over a step from x = {x}, u = {u}")
        return xf

    def simulate(self, x0, us, p=None) -> np.ndarray:
        """States ``(K+1, nx)`` for the control sequence ``us`` ``(K, nu)``, each held for ``dt``."""
        us = np.atleast_2d(np.asarray(us, dtype=float))
        xs = [self._vector(x0, self.nx, "initial state x0")]
        for u in us:
            xs.append(self.step(xs[-1], u, p))
        return np.array(xs)


def np_isfinite(v: float) -> bool:
    return bool(np.isfinite(v))
