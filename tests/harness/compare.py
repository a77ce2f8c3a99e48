"""C runtime against the Python reference: the iterate's fields and their relative
difference (used by the tests that compare the two backends instant by instant and by
bench/outlier_split.py and bench/walk_drift.py)."""
from __future__ import annotations

import numpy as np

# the iterate's primal and dual fields, in both backends' attribute names
FIELDS = ("x", "u", "lam", "mu_g", "mu_b", "mu_bN", "mu_r", "nu")


def rel_err(c, r) -> float:
    """The largest |c - r| relative to max(1, the largest |r|); 0 for empty arrays."""
    c, r = np.asarray(c), np.asarray(r)
    if r.size == 0:
        return 0.0
    return float(np.max(np.abs(c - r)) / max(1.0, float(np.max(np.abs(r)))))


def iterate_err(c, r) -> float:
    """rel_err over every field of FIELDS of two solvers' iterates, the largest."""
    return max(rel_err(getattr(c, f), getattr(r, f)) for f in FIELDS)
