"""Time per DOPUS iteration of the generated C runtime, split by phase (robot arm).

The closed loop of the robot-arm scenario on the discrete model: start at the offline
IPOPT solution, one feedback + prepare per sampling instant for the first second of the
scenario (100 iterations, before its disturbance; --disturb adds the disturbance of the
OCP file at t = 1.0 s), repeated --repeat times. The times are the C runtime's own phase
timers (CLOCK_MONOTONIC read inside the C code, so no Python overhead is counted);
the table shows medians (and the 90th percentile of the total) per iteration for M = 1
(DOPUS) and M = N-1 (the full RTI).

    .venv/bin/python bench/runtime_bench.py [--iters 100] [--repeat 5] [--disturb] [--json FILE]

Prints a table and writes JSON. Never passes or fails on time.
"""
from __future__ import annotations

import argparse
import json
import platform
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
PHASES = ("feedback", "shift", "gradients", "rho", "hessians", "regularization", "assembly")


def run(disc, guess, M, iters, repeat, disturb):
    from dopus_codegen.solver import CSolver, DopusError

    solver = CSolver(disc, M=M, mode="receding", hessian="exact", regularization="none")
    rows, failures, qp_iters = [], 0, []
    p0 = solver.p[0]
    for _ in range(repeat):
        xhat = np.array(disc.x0, dtype=float)
        solver.init(xhat, guess)
        for it in range(iters):
            if disturb and it == int(round(1.0 / disc.dt)) and disc.disturbance is not None:
                xhat = np.array(disc.disturbance(xhat.copy()), dtype=float).reshape(-1)
            try:
                u0 = solver.feedback(xhat)
                ok = True
            except DopusError:
                failures += 1
                ok = False
                u0 = solver.u[0]
            t_fb = solver.timings["feedback"]
            qp_iters.append(solver.qp_iterations)
            try:
                solver.prepare()
            except DopusError:          # a diverged loop: count it and start over
                failures += 1
                break
            t = solver.timings
            t["feedback"] = t_fb
            t["total"] = sum(t[k] for k in PHASES)
            t["ok"] = ok
            rows.append(t)
            xhat = np.array(disc.stage_eval(xhat, u0, p0)[0], dtype=float).reshape(-1)
    return solver, rows, failures, qp_iters


def summarize(rows):
    out = {}
    for k in PHASES + ("total",):
        v = np.array([r[k] for r in rows])
        out[k] = {"median": float(np.median(v)), "p90": float(np.percentile(v, 90)), "max": float(np.max(v))}
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--iters", type=int, default=100, help="iterations per run (default 100 = 1.0 s)")
    ap.add_argument("--repeat", type=int, default=5, help="runs per setting (default 5)")
    ap.add_argument("--disturb", action="store_true", help="apply the OCP file's disturbance at t = 1.0 s")
    ap.add_argument("--json", default=str(ROOT / "bench" / "results" / "runtime_bench.json"))
    args = ap.parse_args(argv)

    from dopus_codegen import build_functions, load_ocp
    from dopus_codegen.offline import solve_ocp

    disc = build_functions(load_ocp(ROOT / "examples" / "robot_arm.py"))
    guess, info = solve_ocp(disc, disc.x0)
    results = {"problem": disc.name, "N": disc.N, "nx": disc.nx, "nu": disc.nu, "iterations": args.iters,
               "repeat": args.repeat, "disturb": bool(args.disturb), "machine": platform.machine(), "python": platform.python_version(),
               "unit": "seconds", "runs": []}
    for label, M in (("DOPUS M=1", 1), ("full RTI M=N-1", disc.N - 1)):
        solver, rows, failures, qp_iters = run(disc, guess, M, args.iters, args.repeat, args.disturb)
        results["sizeof_solver"] = solver.sizeof
        results["runs"].append({"label": label, "M": M, "failures": failures, "samples": len(rows),
                                "qp_iterations_median": float(np.median(qp_iters)),
                                "phases": summarize(rows)})

    cols = PHASES + ("total",)
    print(f"{disc.name}: N={disc.N}, nx={disc.nx}, nu={disc.nu}; sizeof(solver) = {results['sizeof_solver']} bytes; "
          f"{args.iters} closed-loop iterations x {args.repeat}; median microseconds per iteration")
    print(f"{'run':<18}" + "".join(f"{c:>15}" for c in cols) + f"{'total p90':>12}{'QP it':>7}{'fails':>7}")
    for run_ in results["runs"]:
        ph = run_["phases"]
        print(f"{run_['label']:<18}" + "".join(f"{1e6 * ph[c]['median']:>15.1f}" for c in cols)
              + f"{1e6 * ph['total']['p90']:>12.1f}{run_['qp_iterations_median']:>7.0f}{run_['failures']:>7d}")
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(results, indent=2, sort_keys=True) + "\n")
    print(f"wrote {out}", file=sys.stderr)


if __name__ == "__main__":
    main()
