"""Closed-loop instants of a solver handle against a plant, with an optional corruption of
the measurement: the loop the recovery tests and the outlier benchmark share.

Each instant: feedback on the measurement (a :class:`~dopus_codegen.errors.DopusError`
still hands over the safe control of docs/algorithm.md section 9), one plant step with that
control, then prepare. Works with either backend's handle (``CSolver``, ``ReferenceDopus``).
"""
from __future__ import annotations

from typing import Callable, Optional

import numpy as np

from ..errors import DopusError

__all__ = ["run_instants"]


def run_instants(solver, plant, x, n: int,
                 measure: Optional[Callable[[int, np.ndarray], np.ndarray]] = None):
    """``n`` instants from the plant state ``x``; ``measure(i, x)`` gives the measurement of
    instant ``i`` (None: the state itself). Returns the plant states after each instant
    (n x nx), the status of each instant (0: OK, else the feedback's or prepare's status)
    and the final state."""
    xs, status = [], []
    for i in range(n):
        xm = x.copy() if measure is None else measure(i, x)
        try:
            u0, st = solver.feedback(xm), 0
        except DopusError as err:
            u0, st = err.u0, err.status
        x = plant.step(x, u0, np.zeros(0))
        try:
            solver.prepare()
        except DopusError as err:
            st = st or err.status
        xs.append(x.copy())
        status.append(st)
    return np.array(xs), status, x
