"""Time per DOPUS iteration of the generated C runtime, split by phase (robot arm).

Two settings, each for M = 1 (DOPUS) and M = N-1 (the full RTI):

- ``study``: the fixed-xhat0 warm-start convergence study of docs/design.md section 8 (start at
  the offline IPOPT solution, iterate for the disturbed initial state), --study-iters
  iterations, repeated --repeat times;
- ``loop``: the receding-horizon closed loop on the discrete model from the IPOPT
  solution (the first second of the robot-arm scenario, before its disturbance),
  --loop-iters iterations, repeated --repeat times.

The times are the C runtime's own phase timers (CLOCK_MONOTONIC read inside the C code, so
no Python overhead is counted). Medians are over the iterations whose QP was solved; the
failures column counts feedback calls whose QP the C solver did not solve (such a call
takes no step and is not timed) and prepare calls that failed.

    .venv/bin/python bench/runtime_bench.py [--repeat 5] [--study-iters 30] [--loop-iters 100] [--json FILE]

Prints a table and writes JSON (default bench/results/runtime_bench.json). Never passes or
fails on time.
"""
from __future__ import annotations

import argparse
import json
import platform
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
PHASES = ("feedback", "shift", "gradients", "rho", "hessians", "regularization", "assembly", "lm", "recovery")


def run(solver, disc, guess, setting, iters, repeat):
    """Per-iteration phase times of the iterations whose feedback and prepare succeeded."""
    from dopus_codegen.runtime.solver import DopusError

    rows, failures, qp_iters = [], 0, []
    p0 = solver.p[0]
    x0 = np.array(disc.x0, dtype=float)
    xfixed = np.array(disc.disturbance(x0.copy()), dtype=float).reshape(-1)
    for _ in range(repeat):
        xhat = x0.copy()
        solver.init(xhat, guess)
        for _it in range(iters):
            if setting == "study":
                xhat = xfixed
            ok = True
            try:
                u0 = solver.feedback(xhat)
            except DopusError:
                failures += 1
                ok = False
                u0 = solver.u[0]
            t_fb = solver.timings["feedback"]
            qp_iters.append(solver.qp_iterations)
            try:
                solver.prepare()
            except DopusError:
                failures += 1
                break
            if ok:
                t = solver.timings
                t["feedback"] = t_fb
                t["total"] = sum(t[k] for k in PHASES)
                rows.append(t)
            if setting == "loop":
                xhat = np.array(disc.stage_eval(xhat, u0, p0)[0], dtype=float).reshape(-1)
    return rows, failures, qp_iters


def summarize(rows):
    out = {}
    for k in PHASES + ("total",):
        v = np.array([r[k] for r in rows]) if rows else np.array([np.nan])
        out[k] = {"median": float(np.median(v)), "p90": float(np.percentile(v, 90)), "max": float(np.max(v))}
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5, help="runs per setting (default 5)")
    ap.add_argument("--study-iters", type=int, default=30, help="iterations of the warm-start study (default 30)")
    ap.add_argument("--loop-iters", type=int, default=100, help="closed-loop iterations (default 100 = 1.0 s)")
    ap.add_argument("--json", default=str(ROOT / "bench" / "results" / "runtime_bench.json"))
    args = ap.parse_args(argv)

    from dopus_codegen import build_functions, load_ocp
    from dopus_codegen.reference.offline import solve_ocp
    from dopus_codegen.runtime.solver import CSolver

    disc = build_functions(load_ocp(ROOT / "examples" / "robot_arm.py"))
    guess, _info = solve_ocp(disc, disc.x0)
    results = {"problem": disc.name, "N": disc.N, "nx": disc.nx, "nu": disc.nu, "repeat": args.repeat,
               "machine": platform.machine(), "python": platform.python_version(), "unit": "seconds",
               "runs": []}
    for setting, iters in (("study", args.study_iters), ("loop", args.loop_iters)):
        for label, M in (("M=1", 1), ("full RTI", disc.N - 1)):
            solver = CSolver(disc, M=M, mode="fixed" if setting == "study" else "receding",
                             hessian="exact", regularization="none")
            rows, failures, qp_iters = run(solver, disc, guess, setting, iters, args.repeat)
            results["sizeof_solver"] = solver.sizeof
            results["qp_tol"] = solver.qp_tol
            results["runs"].append({"setting": setting, "label": label, "M": M, "iterations": iters,
                                    "timed": len(rows), "failures": failures,
                                    "qp_iterations_median": float(np.median(qp_iters)),
                                    "phases": summarize(rows)})

    cols = PHASES + ("total",)
    print(f"{disc.name}: N={disc.N}, nx={disc.nx}, nu={disc.nu}; sizeof(solver) = {results['sizeof_solver']} bytes; "
          f"QP tol {results['qp_tol']:g}; median microseconds per iteration (C phase timers)")
    print(f"{'setting':<16}" + "".join(f"{c[:10]:>11}" for c in cols) + f"{'tot p90':>9}{'QP it':>6}{'timed':>6}{'fails':>6}")
    for r in results["runs"]:
        ph = r["phases"]
        print(f"{r['setting'] + ' ' + r['label']:<16}" + "".join(f"{1e6 * ph[c]['median']:>11.1f}" for c in cols)
              + f"{1e6 * ph['total']['p90']:>9.1f}{r['qp_iterations_median']:>6.0f}{r['timed']:>6d}{r['failures']:>6d}")
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=2, sort_keys=True) + "\n")
    print(f"wrote {out}", file=sys.stderr)


if __name__ == "__main__":
    main()
