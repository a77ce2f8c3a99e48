"""The closed-loop fault suite of tests/test_faults.py as a table: robot arm, the model as the
plant, faults of five kinds over K consecutive instants, DOPUS M = 1 and the full RTI.

Per kind and M: the runs (K = 1..40 or the K given), the runs with a failed instant after the
fault, the latest such instant, the runs back within 1 cm of the path within 150 instants,
the median and largest instant at which they are back, the largest tip deviation after the
fault. Writes bench/results/fault_suite.json.

    .venv/bin/python bench/fault_suite.py [--M 1,full] [--budget UNITS] [--kinds K1,...] [--eps=E] [K ...]

--budget: a work budget per instant (anytime DOPUS, docs/algorithm.md section 14; 0: none).
--kinds: only these kinds of fault. --eps: the initial first joint angle moved by E (the
loops are chaotic: a shift of 1e-9 changes which runs come back; docs/results.md).
"""
from __future__ import annotations

import json
import pathlib
import sys

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from harness.faults import KINDS, Handle, model_plant, run_case  # noqa: E402

from dopus_codegen import build_functions, load_ocp  # noqa: E402
from dopus_codegen.reference.offline import solve_ocp  # noqa: E402


def main(ks, Ms=(1, "full"), budget=0.0, kinds=None, eps=0.0):
    arm = build_functions(load_ocp(ROOT / "examples" / "robot_arm.py"))
    guess, _ = solve_ocp(arm, arm.x0)
    plant = model_plant(arm)
    x0 = np.asarray(arm.x0, float).copy()
    x0[0] += eps
    rows, table = [], []
    print(f"{'M':>4} {'kind':>13} {'runs':>4} {'failed after':>12} {'latest':>6} {'back':>5} "
          f"{'median':>6} {'max':>4} {'max dev [m]':>11}")
    for M in Ms:
        m = arm.N - 1 if M == "full" else M
        for kind in kinds or KINDS:
            runs = [run_case(lambda: Handle(arm, guess, m, budget), plant, x0, kind, K) for K in ks]
            for r in runs:
                r["M"] = M
            rows += runs
            back = [r["back"] for r in runs if r["back"] is not None]
            row = {"M": M, "budget": budget, "kind": kind, "runs": len(runs),
                   "failed_after": sum(r["n_failed_after"] > 0 for r in runs),
                   "latest_failed": max(r["last_failed_after"] for r in runs),
                   "back": len(back), "back_median": float(np.median(back)) if back else None,
                   "back_max": max(back) if back else None,
                   "max_dev": max(r["max_dev_after"] for r in runs)}
            table.append(row)
            print(f"{str(M):>4} {kind:>13} {row['runs']:4d} {row['failed_after']:12d} {row['latest_failed']:6d} "
                  f"{row['back']:5d} {str(row['back_median']):>6} {str(row['back_max']):>4} {row['max_dev']:11.3f}",
                  flush=True)
    out = ROOT / "bench" / "results"
    out.mkdir(parents=True, exist_ok=True)
    (out / "fault_suite.json").write_text(json.dumps({"table": table, "runs": rows}, indent=1))


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--M", default="1,full", help="comma-separated M values (an integer or 'full')")
    ap.add_argument("--budget", type=float, default=0.0, help="work units per instant (0: no budget)")
    ap.add_argument("--kinds", default="", help=f"comma-separated kinds of fault (default all: {', '.join(KINDS)})")
    ap.add_argument("--eps", type=float, default=0.0, help="shift of the initial first joint angle (default 0)")
    ap.add_argument("K", nargs="*", type=int, help="numbers of consecutive faulty instants (default 1..40)")
    a = ap.parse_args()
    kinds = [k for k in a.kinds.split(",") if k]
    bad = [k for k in kinds if k not in KINDS]
    if bad:
        ap.error(f"unknown kind of fault {bad[0]!r} (known: {', '.join(KINDS)})")
    main(a.K or list(range(1, 41)), [m if m == "full" else int(m) for m in a.M.split(",")], a.budget, kinds,
         a.eps)
