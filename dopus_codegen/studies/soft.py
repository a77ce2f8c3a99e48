"""The soft rows of a problem as the closed-loop studies report them (docs/algorithm.md
section 12): one group per soft state vector and per path-constraint call with soft rows,
and the largest violation of each group at a measured state and the control applied there.
(Terminal rows constrain the end of the horizon, not the plant: the solver's slacks report
them, ``soft_slacks()``.)"""
from __future__ import annotations

import numpy as np

__all__ = ["soft_groups", "violations"]


def soft_groups(disc) -> list:
    """``[(label, kind, rows, lo, up, soft_lo, soft_up)]``: ``kind`` "x" (rows of the state)
    or "g" (rows of the stacked path rows); ``soft_lo``/``soft_up`` the sides that are soft."""
    out = []
    con = disc.spec.constraints
    sx = np.asarray(disc.soft_x)
    start = 0
    for var in disc.spec.model.states:
        rows = np.arange(start, start + var.size)
        start += var.size
        w = sx[:, rows]
        if np.any(w > 0):
            out.append((f"state {var.name}", "x", rows, np.asarray(disc.lbx)[rows], np.asarray(disc.ubx)[rows],
                        (w[0] > 0) | (w[2] > 0), (w[1] > 0) | (w[3] > 0)))
    start = 0
    for i, block in enumerate(con.path):
        n = block.lb.size
        rows = np.arange(start, start + n)
        start += n
        w = block.soft_weights()
        if np.any(w > 0) and not getattr(block, "cost", False):
            out.append((f"path {i}", "g", rows, np.asarray(block.lb), np.asarray(block.ub),
                        (w[0] > 0) | (w[2] > 0), (w[1] > 0) | (w[3] > 0)))
    return out


def violations(disc, groups, x, u, p) -> dict:
    """The largest violation of the soft sides of each group at state ``x`` and control
    ``u`` (parameters ``p``): ``{label: value}``."""
    if not groups:
        return {}
    g = None
    out = {}
    for label, kind, rows, lo, up, slo, sup in groups:
        if kind == "x":
            v = np.asarray(x, float)[rows]
        else:
            if g is None:
                g = np.asarray(disc.stage_eval(x, u, p)[2], float).reshape(-1)
            v = g[rows]
        with np.errstate(invalid="ignore"):
            viol = np.maximum(np.where(slo, lo - v, 0.0), np.where(sup, v - up, 0.0))
        out[label] = float(max(0.0, np.nanmax(viol))) if viol.size else 0.0
    return out
