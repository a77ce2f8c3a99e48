"""The closed-loop fault suite of the robot arm (docs/algorithm.md section 9).

The plant is the model itself (RK4 with 20 substeps per sampling instant), so every
deviation comes from the controller. After 50 nominal instants, K consecutive measurements
are corrupted by one fault kind, then the measurements are exact again. Each instant applies
the control the runtime returns whatever the status (the safe output of section 9).

Used by tests/test_faults.py (bounds for every kind, K = 1..40, M = 1 and the full RTI) and
by bench/fault_suite.py (the table and JSON of the same runs).
"""
from __future__ import annotations

import casadi as ca
import numpy as np

from dopus_codegen.studies import loops

SETTLE = 50
AFTER = 150
SUBSTEPS = 20


def _velocity(v):
    def fault(x, x_frozen):
        xm = x.copy()
        xm[2:4] = [v, -v]
        return xm
    return fault


def _frozen(x, x_frozen):
    return x_frozen.copy()


def _nan(x, x_frozen):
    return np.full_like(x, np.nan)


def _position(x, x_frozen):
    xm = x.copy()
    xm[0:2] += [0.5, -0.5]
    return xm


#: fault kind -> measurement(x, x at the fault's first instant)
KINDS = {"velocity 30": _velocity(30.0), "velocity 1e4": _velocity(1e4), "velocity 1e6": _velocity(1e6),
         "frozen": _frozen, "nan": _nan, "position": _position}


def model_plant(disc):
    """x_next = RK4 of the model's ODE over one sampling period with SUBSTEPS substeps."""
    x = ca.SX.sym("x", disc.nx)
    u = ca.SX.sym("u", disc.nu)
    h = disc.dt / SUBSTEPS
    p = ca.DM.zeros(disc.ode.size1_in(2), 1)
    f = lambda z: disc.ode(z, u, p)
    z = x
    for _ in range(SUBSTEPS):
        k1 = f(z); k2 = f(z + h / 2 * k1); k3 = f(z + h / 2 * k2); k4 = f(z + h * k3)
        z = z + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    F = ca.Function("plant", [x, u], [z])
    return lambda xk, uk: np.asarray(F(xk, uk), float).reshape(-1)


def tip_deviation(xs):
    """Distance of the tip from the circle at theta (examples/robot_arm.py)."""
    xs = np.atleast_2d(xs)
    q1, q2, th = xs[:, 0], xs[:, 1], xs[:, 4]
    tip = np.stack([0.4 * np.cos(q1) + 0.4 * np.cos(q1 + q2), 0.4 * np.sin(q1) + 0.4 * np.sin(q1 + q2)], 1)
    ref = np.stack([0.4 + 0.15 * np.cos(th), 0.2 + 0.15 * np.sin(th)], 1)
    return np.linalg.norm(tip - ref, axis=1)


def back_on_path(dev, tol: float = 1e-2):
    """The first instant from which the deviations ``dev`` all stay within ``tol`` (None: never)."""
    dev = np.asarray(dev)
    return next((i for i in range(dev.size) if np.all(dev[i:] <= tol)), None)


def instant(solver, plant, x, xm):
    """One closed-loop instant of the package (dopus_codegen.studies.loops): feedback on the
    measurement xm, the returned control applied whatever the status, prepare. Returns
    (next state, u0, status)."""
    fb = loops.feedback(solver, xm)
    x = plant(x, fb.u0)
    st, _ = loops.prepare(solver)
    return x, fb.u0, fb.status or st


class Handle:
    """The generated solver with the OCP file's settings but M (and an optional work budget per
    instant and measurement gate ``(gate, gate_hold)``), initialised at the given guess
    (IPOPT's solution) by run_case."""

    def __init__(self, disc, guess, M, budget=0.0, gate=None):
        from dopus_codegen.runtime.solver import CSolver

        self.s, self.guess = CSolver(disc, lm=None, M=M), guess
        if budget > 0:
            self.s.set_work_budget(budget)
        if gate is not None:
            self.s.set_gate(*gate)

    def init(self, x):
        self.s.init(x, self.guess)

    def feedback(self, x):
        return self.s.feedback(x)

    def prepare(self):
        self.s.prepare()

    @property
    def recoveries(self):
        return self.s.recoveries


def run_case(make_solver, plant, x0, kind: str, K: int, after: int = AFTER, tol: float = 1e-2):
    """One run: SETTLE nominal instants, K faulty ones, `after` exact ones. Returns a dict:
    failed_settle (count), failed_during, last_failed_after (index of the last failed instant
    after the fault, -1: none), back (first instant after the fault from which the tip stays
    within tol of the path; None: not within the window), max_dev_after (m), u_range (the
    returned controls' min and max over the run)."""
    s = make_solver()
    x = np.asarray(x0, float).copy()
    s.init(x)
    fault = KINDS[kind]
    st_settle, st_during, st_after, us, xs_after = [], [], [], [], []
    for _ in range(SETTLE):
        x, u0, st = instant(s, plant, x, x.copy())
        st_settle.append(st); us.append(u0)
    x_frozen = x.copy()
    for _ in range(K):
        x, u0, st = instant(s, plant, x, fault(x, x_frozen))
        st_during.append(st); us.append(u0)
    for _ in range(after):
        if not np.all(np.isfinite(x)):
            break
        x, u0, st = instant(s, plant, x, x.copy())
        st_after.append(st); us.append(u0); xs_after.append(x.copy())
    dev = tip_deviation(np.array(xs_after)) if xs_after else np.array([np.inf])
    back = back_on_path(dev, tol) if len(xs_after) == after else None
    failed = [i for i, v in enumerate(st_after) if v]
    us = np.array(us)
    return {"kind": kind, "K": K, "failed_settle": sum(v != 0 for v in st_settle),
            "failed_during": sum(v != 0 for v in st_during), "last_failed_after": failed[-1] if failed else -1,
            "n_failed_after": len(failed), "back": back, "max_dev_after": float(dev.max()),
            "u_min": us.min(axis=0).tolist(), "u_max": us.max(axis=0).tolist(), "recoveries": int(s.recoveries)}
