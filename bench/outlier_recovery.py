"""Robot arm: K finite outlier measurements (joint velocities (30, -30)), then good ones.

For K = 5, 10, 20, 40 (or the K given on the command line): the failed instants during the
outliers and after the good measurements return (200 instants), the recoveries, and the
first instant from which the tip stays within 1 cm of the path, against a freshly
initialised solver (IPOPT at the state where the good measurements return) run in its own
loop from the same plant state. docs/algorithm.md section 9. Prints a table and writes
bench/results/outlier_recovery.json.

    .venv/bin/python bench/outlier_recovery.py [--soft L1] [--eps E,...] [K ...]

``--eps``: the loop is chaotic (an initial state moved by 1e-7 changes the failed instants
during and after the outliers several times over), so a comparison of two versions runs an
ensemble: every K once per initial first joint angle moved by each E (default 0), with the
totals over the ensemble at the end.

``--soft L1``: the robot arm with its terminal rows soft, ``Soft(l1=L1)`` (examples/robot_arm.py
``build(soft_terminal=...)``; the hard IPOPT solution is its solution for L1 above the terminal
multipliers), started from the hard solution; the fresh solver is the soft one too. Writes
bench/results/outlier_recovery_soft.json.
"""
from __future__ import annotations

import argparse
import json
import pathlib
import sys

import numpy as np

from dopus_codegen import build_functions, load_ocp
from dopus_codegen.reference.offline import solve_ocp
from dopus_codegen.runtime.solver import CSolver
from dopus_codegen.studies.loops import run_instants
from dopus_codegen.studies.plant import Plant

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from harness.faults import back_on_path, tip_deviation  # noqa: E402
N_AFTER = 200


def outlier(x):
    xm = x.copy()
    xm[2:4] = [30.0, -30.0]
    return xm


def soft_arm(l1):
    """The soft variant of the robot arm and a function mapping a hard solution (Guess) to
    its start (the terminal equality multipliers become those of the soft inequality rows)."""
    import dataclasses
    import importlib.util

    from dopus_codegen import Soft

    spec = importlib.util.spec_from_file_location("robot_arm_soft", ROOT / "examples" / "robot_arm.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    disc = build_functions(mod.build(soft_terminal=Soft(l1=l1)))
    return disc, lambda g: dataclasses.replace(g, mu_r=g.nu, nu=None)


def main(ks, soft=None, epss=(0.0,)):
    hard = build_functions(load_ocp(ROOT / "examples" / "robot_arm.py"))
    arm, start = (hard, lambda g: g) if soft is None else soft_arm(soft)
    guess = start(solve_ocp(hard, hard.x0)[0])
    rows = []
    print(f"{'eps':>8} {'K':>3} {'failed during':>13} {'failed after':>12} {'recoveries':>10} {'on path':>8} "
          f"{'fresh':>6}")
    for eps, k in ((e, k) for e in epss for k in ks):
        plant = Plant(arm.ode, arm.dt, 0, reltol=1e-10, abstol=1e-10)
        s = CSolver(arm, lm=None)
        x = np.asarray(arm.x0, float).copy()
        x[0] += eps
        s.init(x, guess)
        _, _, x = run_instants(s, plant, x, 50)
        _, st_bad, x = run_instants(s, plant, x, k, measure=lambda i, x: outlier(x))
        xs_rec, st_rec, _ = run_instants(s, plant, x.copy(), N_AFTER)
        fresh = CSolver(arm, lm=None)
        fresh.init(x, start(solve_ocp(hard, x)[0]))
        xs_fresh, st_fresh, _ = run_instants(fresh, plant, x.copy(), N_AFTER)
        row = {"eps": eps, "K": k, "failed_during": sum(v != 0 for v in st_bad), "failed_after": sum(v != 0 for v in st_rec),
               "recoveries": s.recoveries, "on_path": back_on_path(tip_deviation(xs_rec)),
               "on_path_fresh": back_on_path(tip_deviation(xs_fresh)), "fresh_failed": sum(v != 0 for v in st_fresh)}
        rows.append(row)
        print(f"{eps:8.0e} {k:3d} {row['failed_during']:13d} {row['failed_after']:12d} {row['recoveries']:10d} "
              f"{str(row['on_path']):>8} {str(row['on_path_fresh']):>6}", flush=True)
    if len(rows) > 1:
        lag = [r["on_path"] - r["on_path_fresh"] for r in rows
               if r["on_path"] is not None and r["on_path_fresh"] is not None]
        print(f"total over {len(rows)} runs: failed during {sum(r['failed_during'] for r in rows)} "
              f"({sum(r['failed_during'] > 0 for r in rows)} runs), failed after "
              f"{sum(r['failed_after'] for r in rows)} ({sum(r['failed_after'] > 0 for r in rows)} runs), "
              f"recoveries {sum(r['recoveries'] for r in rows)}, never back "
              f"{sum(r['on_path'] is None for r in rows)}, fresh never back "
              f"{sum(r['on_path_fresh'] is None for r in rows)}, fresh failed "
              f"{sum(r['fresh_failed'] for r in rows)}, lag behind the fresh solver median "
              f"{np.median(lag) if lag else float('nan'):.1f} max {max(lag) if lag else float('nan')}")
    out = ROOT / "bench" / "results"
    out.mkdir(parents=True, exist_ok=True)
    name = "outlier_recovery.json" if soft is None else "outlier_recovery_soft.json"
    (out / name).write_text(json.dumps({"soft_l1": soft, "rows": rows} if soft is not None else rows, indent=1))


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("K", type=int, nargs="*", help="numbers of consecutive outliers (default 5 10 20 40)")
    ap.add_argument("--soft", type=float, metavar="L1", default=None,
                    help="the robot arm with soft terminal rows, Soft(l1=L1)")
    ap.add_argument("--eps", default="0", metavar="E,...",
                    help="comma-separated shifts of the initial first joint angle: one run per shift and K")
    a = ap.parse_args()
    main(a.K or [5, 10, 20, 40], a.soft, [float(e) for e in a.eps.split(",")])
