"""One DOPUS iteration of two generated robot-arm solvers, side by side in one process.

Each solver is a generated folder built with its own flags (`dopus-gen build FOLDER
[--opt ...]` first; the folder keeps the flags it was built with), e.g. the folder of an
older commit at its default -O2 against this tree's at its default -O3:

    git worktree add --detach /tmp/old c2a9b53
    cp -r /tmp/old/generated/robot_arm /tmp/cmp_old && dopus-gen build /tmp/cmp_old --opt -O2
    cp -r generated/robot_arm /tmp/cmp_new && dopus-gen build /tmp/cmp_new
    .venv/bin/python bench/iteration_compare.py --old /tmp/cmp_old --new /tmp/cmp_new

Run: the receding-horizon closed loop on the discrete model from the IPOPT solution, M = 1,
exact Hessian, the OCP file's Levenberg-Marquardt term (as `dopus-gen sil`), the OCP
file's disturbance at the first and the middle iteration; every solver runs its own loop,
the instants interleaved (old, new, old, new, ...) so that load on the machine hits both
alike. Times are the C runtime's own phase timers. Reported: medians per iteration of
feedback (the QP and its bookkeeping), prepare and their sum, the ratio new / old, the QP
share (feedback / iteration) and the QP iterations per instant. Never passes or fails on time.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
PREPARE = ("shift", "gradients", "rho", "hessians", "regularization", "assembly")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--old", required=True, help="generated folder of the baseline")
    ap.add_argument("--new", required=True, help="generated folder to compare")
    ap.add_argument("--iters", type=int, default=200, help="closed-loop iterations per run (default 200)")
    ap.add_argument("--repeat", type=int, default=3, help="runs (default 3)")
    ap.add_argument("--M", type=int, default=1)
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)

    sys.path.insert(0, str(ROOT))
    from dopus_codegen import build_functions, load_ocp
    from dopus_codegen.reference.offline import solve_ocp
    from dopus_codegen.runtime.solver import CSolver, DopusError

    disc = build_functions(load_ocp(ROOT / "examples" / "robot_arm.py"))
    guess = solve_ocp(disc, disc.x0)[0]
    solvers = {name: CSolver(disc, lib_dir=folder, M=args.M, lm=None)
               for name, folder in (("old", args.old), ("new", args.new))}
    p0 = np.asarray(solvers["new"].p[0], dtype=float)
    rec = {name: {"feedback": [], "prepare": [], "qp_iters": [], "failures": 0} for name in solvers}
    for _ in range(args.repeat):
        xs = {}
        for name, s in solvers.items():
            xs[name] = np.array(disc.x0, dtype=float)
            s.init(xs[name], guess)
        for it in range(args.iters):
            for name, s in solvers.items():
                x = xs[name]
                if it in (0, args.iters // 2):
                    x = np.array(disc.disturbance(x.copy()), dtype=float).reshape(-1)
                try:
                    u0 = s.feedback(x)
                    ok = True
                except DopusError:
                    rec[name]["failures"] += 1
                    u0, ok = s.u[0], False
                t_fb = s.timings["feedback"]
                rec[name]["qp_iters"].append(s.qp_iterations)
                s.prepare()
                if ok:
                    t = s.timings
                    rec[name]["feedback"].append(t_fb)
                    rec[name]["prepare"].append(sum(t[k] for k in PREPARE))
                xs[name] = np.array(disc.stage_eval(x, u0, p0)[0], dtype=float).reshape(-1)
    out = {}
    for name, r in rec.items():
        fb, pr = np.array(r["feedback"]), np.array(r["prepare"])
        out[name] = {"feedback_us": float(np.median(fb) * 1e6), "prepare_us": float(np.median(pr) * 1e6),
                     "iteration_us": float(np.median(fb + pr) * 1e6),
                     "qp_share": float(np.median(fb / (fb + pr))),
                     "qp_iters_median": float(np.median(r["qp_iters"])),
                     "qp_iters_mean": float(np.mean(r["qp_iters"])), "failures": r["failures"],
                     "sizeof": solvers[name].sizeof}
    out["ratio_new_old"] = out["new"]["iteration_us"] / out["old"]["iteration_us"]
    for name in ("old", "new"):
        o = out[name]
        print(f"{name}: iteration {o['iteration_us']:.1f} us (feedback {o['feedback_us']:.1f}, prepare "
              f"{o['prepare_us']:.1f}), QP share {o['qp_share']:.0%}, QP iterations median "
              f"{o['qp_iters_median']:.0f} (mean {o['qp_iters_mean']:.1f}), failures {o['failures']}, "
              f"sizeof {o['sizeof']} B")
    print(f"new / old per iteration: {out['ratio_new_old']:.2f}")
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
