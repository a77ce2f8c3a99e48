"""What scaling buys a float build of a model in physical units (docs/algorithm.md section 16).

    python bench/float_scaling.py [--cost 1,10,30,100,300] [--iters 20] [--json OUT]

The reactor of ``examples/cstr.py`` (temperatures about 350 K), the warm-start study of
``dopus-gen converge`` with the generated C solver (full RTI and M = 1), built in double and
in float, without its scales and with them at each cost scale. Per build: the absolute and
the relative KKT measure the iteration settles at (largest over the second half of the
iterations), the iterations to the relative tolerance 1e-5, and the distance of the float
solution from the double build's (largest entry of x and of u, relative to the largest entry
of the double build's). Deterministic: no timing.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "examples"))

import cstr  # noqa: E402

from dopus_codegen import build_functions  # noqa: E402
from dopus_codegen.runtime.solver import CSolver  # noqa: E402
from dopus_codegen.studies.converge import make_start, run_study  # noqa: E402


def _rel(a, b) -> float:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.max(np.abs(a - b)) / max(1.0, np.max(np.abs(b))))


def study(ocp, iters: int) -> dict:
    disc = build_functions(ocp)
    start = make_start(disc, "warm")
    out = {}
    for real in ("double", "float"):
        out[real] = run_study(disc, [disc.N - 1, 1], iters, start, tol=2e-5, tol_rel=1e-5,
                              backend_factory=lambda d, real=real, **kw: CSolver(d, real=real, **kw))
    half = iters // 2
    rows = []
    for fl in out["float"]["runs"]:
        rows.append({"M": fl["M"], "kkt_floor": max(fl["kkt"][half:]), "rel_floor": max(fl["rel"][half:]),
                     "iterations_to_rel": fl["iterations_to_tol"]})
    sf, sd = out["float"]["solution"], out["double"]["solution"]
    return {"runs": rows, "x_error": _rel(sf["x"], sd["x"]), "u_error": _rel(sf["u"], sd["u"])}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cost", default="1,10,30,100,300", help="cost scales of the scaled builds")
    ap.add_argument("--iters", type=int, default=20)
    ap.add_argument("--json", type=Path, default=ROOT / "bench" / "results" / "float_scaling.json")
    args = ap.parse_args(argv)
    cases = [("no scales", cstr.build(scaled=False))]
    cases += [(f"scales, cost {float(c):g}", cstr.build(cost_scale=float(c))) for c in args.cost.split(",")]
    results = []
    print(f"{'build':<18} {'M':>4} {'KKT floor':>10} {'rel floor':>10} {'iters to rel 1e-5':>18} "
          f"{'x error':>9} {'u error':>9}")
    for label, ocp in cases:
        r = study(ocp, args.iters)
        results.append({"build": label, **r})
        for row in r["runs"]:
            it = "-" if row["iterations_to_rel"] is None else str(row["iterations_to_rel"])
            print(f"{label:<18} {row['M']:>4} {row['kkt_floor']:10.2e} {row['rel_floor']:10.2e} {it:>18} "
                  f"{r['x_error']:9.2e} {r['u_error']:9.2e}")
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps(results, indent=1))
    print(f"wrote {args.json}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
