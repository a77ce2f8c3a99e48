"""The closed-loop instant: measurement in, the runtime's returned control applied.

One rule for every closed loop of the package (``dopus-gen sil``, ``dopus-gen campaign``,
which runs the loop of sil, and :func:`run_instants`, the loop of the recovery tests and the
outlier benchmark): the control applied at an instant is the one the runtime returns from
``feedback``, whatever its status. After a failed feedback the runtime returns the safe
control of docs/algorithm.md section 9 (the next control of the last good plan, clipped to
the bounds), which both backends hand over with the :class:`~dopus_codegen.errors.DopusError`
as ``u0``; the loop applies it, records the status and goes on with ``prepare``. The timing
process of the lab (``dopus_lab/timing.py``) and the firmware harness (``firmware/fw_main.c``)
apply the returned ``u0`` at the C API by the same rule.

Works with either backend's handle (``Solver``, ``ReferenceDopus``).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from ..errors import DopusError

__all__ = ["Feedback", "feedback", "prepare", "run_instants"]


@dataclass
class Feedback:
    """The feedback of one instant: ``u0`` the control to apply, ``status`` 0 or the status
    of the failed feedback (never 0 then), ``error`` the failure (None: none), ``seconds``
    the wall time of the call."""
    u0: np.ndarray
    status: int
    error: Optional[DopusError]
    seconds: float


def feedback(solver, xhat) -> Feedback:
    """``solver.feedback(xhat)``; the control to apply is the one the runtime returns,
    whatever the status (on failure the safe control the error carries)."""
    t0 = time.perf_counter()
    try:
        u0, status, error = solver.feedback(xhat), 0, None
    except DopusError as err:
        u0, status, error = err.u0, int(err.status or -1), err
    return Feedback(np.array(u0, dtype=float).reshape(-1), status, error, time.perf_counter() - t0)


def prepare(solver) -> tuple:
    """``solver.prepare()``: ``(status, seconds)``, status 0 or that of the failure."""
    t0 = time.perf_counter()
    try:
        solver.prepare()
        status = 0
    except DopusError as err:
        status = int(err.status or -1)
    return status, time.perf_counter() - t0


def run_instants(solver, plant, x, n: int,
                 measure: Optional[Callable[[int, np.ndarray], np.ndarray]] = None):
    """``n`` instants from the plant state ``x``; ``measure(i, x)`` gives the measurement of
    instant ``i`` (None: the state itself). Each instant: :func:`feedback` on the
    measurement, one plant step with the returned control, :func:`prepare`. Returns the
    plant states after each instant (n x nx), the status of each instant (0: OK, else the
    feedback's or prepare's status) and the final state."""
    xs, status = [], []
    for i in range(n):
        xm = x.copy() if measure is None else measure(i, x)
        fb = feedback(solver, xm)
        x = plant.step(x, fb.u0, np.zeros(0))
        st, _ = prepare(solver)
        xs.append(x.copy())
        status.append(fb.status or st)
    return np.array(xs), status, x
