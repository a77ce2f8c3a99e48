"""The records of the studies as strict JSON."""
from __future__ import annotations

import math

import numpy as np

__all__ = ["json_ready"]


def json_ready(v):
    """``v`` with numpy arrays and scalars as lists and numbers; non-finite floats (a diverged
    run) become null, so the result is strict JSON."""
    if isinstance(v, dict):
        return {k: json_ready(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [json_ready(x) for x in v]
    if isinstance(v, (np.floating, float)):
        return float(v) if math.isfinite(v) else None
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, np.ndarray):
        return json_ready(v.tolist())
    return v
