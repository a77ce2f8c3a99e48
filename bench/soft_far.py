"""The QP that cannot be infeasible, far outside its bounds: the all-soft problem of
tests/test_soft.py (every state bound, path row and terminal row soft) for measurements
10^a..10^b times its bounds.

Per range of magnitudes, 60 random measurements (the same seed for every range):
  * the QPs at the initial iterate (the reference backend's qp_of_current after init at 0),
    solved cold by the C QP solver (tests/harness/qp_harness.py, tol 1e-10): statuses and
    the largest iteration count;
  * the C runtime in closed loop (M = 1, Gauss-Newton, its defaults: warm start, cold
    retry, recovery): feedbacks whose QP failed, and those refused by the divergence test
    of docs/algorithm.md section 9 (no QP failure).
Prints a table and writes bench/results/soft_far.json.

    .venv/bin/python bench/soft_far.py       # about 30 seconds
"""
from __future__ import annotations

import collections
import json
import sys
from pathlib import Path

import numpy as np

BENCH = Path(__file__).resolve().parent
ROOT = BENCH.parent
sys.path.insert(0, str(ROOT / "tests"))

from harness.qp_harness import build_qp_solver  # noqa: E402
from soft_problems import all_soft  # noqa: E402

RANGES = [(-1, 2), (2.5, 3.5), (3, 4), (4, 5), (5, 6)]
COUNT = 60


def main() -> int:
    from dopus_codegen.problem.derivatives import build_functions
    from dopus_codegen.reference.dopus import ReferenceDopus
    from dopus_codegen.runtime.solver import CSolver, DopusError

    disc = build_functions(all_soft())
    ref = ReferenceDopus(disc, M=1, hessian="gauss-newton")
    ref.init(np.zeros(2))
    qp0 = ref.qp_of_current(np.zeros(2))
    h = build_qp_solver(*(int(qp0[k]) for k in ("N", "nx", "nu", "ng", "nr", "ne")), soft=True)
    s = CSolver(disc, M=1, hessian="gauss-newton")
    rows = []
    print(f"{'magnitudes':>14s}  {'QPs at the initial iterate (C QP solver)':42s} {'max it':>6s}  "
          f"closed loop (C runtime): QP failures, divergence refusals")
    for lo, hi in RANGES:
        rng = np.random.default_rng(22)
        status, its = collections.Counter(), []
        for _ in range(COUNT):
            xh = rng.standard_normal(2) * 10.0 ** rng.uniform(lo, hi)
            _, info = h.solve(ref.qp_of_current(xh), tol=1e-10)
            status[info["status"]] += 1
            its.append(info["iterations"])
        rng = np.random.default_rng(22)
        s.init(np.zeros(2))
        qp_fail, diverged = collections.Counter(), 0
        for _ in range(COUNT):
            xh = rng.standard_normal(2) * 10.0 ** rng.uniform(lo, hi)
            try:
                s.feedback(xh)
            except DopusError as err:
                if err.qp_status is not None:
                    qp_fail[err.qp_status_name] += 1
                else:
                    diverged += 1
            s.prepare()
        rows.append({"magnitudes": [lo, hi], "qp_status": dict(status), "max_iterations": max(its),
                     "closed_loop_qp_failures": dict(qp_fail), "closed_loop_diverged": diverged})
        fmt = ", ".join(f"{k} {v}" for k, v in sorted(status.items()))
        fails = ", ".join(f"{k} {v}" for k, v in sorted(qp_fail.items())) or "0"
        print(f"10^{lo:<4g}..10^{hi:<4g}  {fmt:42s} {max(its):6d}  {fails}, {diverged}", flush=True)
    out = BENCH / "results" / "soft_far.json"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"count": COUNT, "tol": 1e-10, "rows": rows}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
