"""The active-set start's gate on the automatic lm, instant by instant (docs/algorithm.md
section 4, feedback; bench/issue23/measurements.md section 18).

Runs the reference backend's closed loop of ``dopus-gen sil OCP_FILE --M 1 --backend
reference`` and records, at every feedback whose automatic term the cap lowered: the capped
term, the prepared one, the terms the prepare's convexity test tried and their outcome,
whether the QP is convex at the capped term, the smallest term the test passes (bisection on
a log scale, 60 steps) and the factorisations of the call. Writes JSON.

    python bench/gate_probe.py examples/robot_arm.py --json gate.json
"""
from __future__ import annotations

import argparse
import json

import numpy as np

from dopus_codegen.reference import dopus as ref
from dopus_codegen.studies.sil import run_sil_cli


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("ocp_file")
    ap.add_argument("--json", required=True)
    args = ap.parse_args()

    records, feedbacks = [], [0]
    convex = ref.ReferenceDopus.lm_convex
    convexify = ref.ReferenceDopus.lm_convexify
    solve = ref.ReferenceDopus.solve_with_retries

    def logged_convexify(self):
        tried = []

        def test(lm):
            ok = convex(self, lm)
            tried.append([float(lm), bool(ok)])
            return ok
        self.lm_convex = test
        try:
            convexify(self)
        finally:
            del self.lm_convex
        self._gate_tried = tried

    def logged_solve(self, xhat0):
        i = feedbacks[0]
        feedbacks[0] += 1
        rec = None
        if self.lm_auto and self.lm_uncapped >= 0.0:
            lo, hi = 1e-14 * self.lm_scale, self.lm_uncapped
            if convex(self, 0.0):
                hi = 0.0
            else:
                for _ in range(60):
                    mid = float(np.sqrt(lo * hi))
                    lo, hi = (lo, mid) if convex(self, mid) else (mid, hi)
            rec = dict(instant=i, lm=float(self.lm), lm_prepared=float(self.lm_uncapped), h=float(self.lm_scale),
                       convex_at_capped=bool(convex(self, self.lm)), lm_convex_threshold=hi,
                       prepare_tests=list(getattr(self, "_gate_tried", [])))
        out = solve(self, xhat0)
        if rec is not None:
            rec["factorizations"] = None if out[0] is None else out[0].get("factorizations")
            records.append(rec)
        return out

    ref.ReferenceDopus.lm_convexify = logged_convexify
    ref.ReferenceDopus.solve_with_retries = logged_solve
    run_sil_cli(args.ocp_file, M=1, backend="reference", progress=False)
    with open(args.json, "w") as f:
        json.dump({"instants": records}, f, indent=1)
    below = [r for r in records if not r["lm"] >= 0.1 * r["lm_prepared"]]
    print(f"capped feedbacks {len(records)}; capped term below 0.1 of the prepared: "
          + ", ".join(f"instant {r['instant']} ({r['lm'] / r['lm_prepared']:.4f}, convex from "
                      f"{r['lm_convex_threshold'] / r['lm_prepared']:.4f})" for r in below))


if __name__ == "__main__":
    main()
