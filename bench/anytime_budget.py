"""Anytime DOPUS on the robot arm: closed-loop quality against the budget per instant
(docs/algorithm.md section 12).

1. Outliers (the acceptance of the budget): the model as plant (RK4, 20 substeps), K
   measurements with joint velocities (30, -30) from t = 1 s, then exact ones. Per setting:
   the largest tip deviation from the circle after the first outlier, the instants after
   the last outlier until the tip stays within 1 cm, and the failed instants after it.
   Settings: no budget (M = 1), a time budget (M = 1 and adaptive M), and a solver run to
   convergence at every instant (a work budget of 1e9 units, KKT proxy 1e-8, at most 50
   iterations per instant).
2. Budget curves on `make demo`'s scenario (dopus-gen sil, CVODES plant, the disturbance at
   1 s): tracking RMS and max after the disturbance, max KKT settled and failed instants,
   against the time budget, for the full RTI (M = N-1), fixed M = 1 and adaptive M.

Times are this host's; rerun for another. Prints the tables, writes
bench/results/anytime_budget.json and bench/results/anytime_budget.png.

    .venv/bin/python bench/anytime_budget.py [--quick]
"""
from __future__ import annotations

import json
import pathlib
import sys

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from harness.faults import model_plant, tip_deviation, instant  # noqa: E402

from dopus_codegen import build_functions, load_ocp  # noqa: E402
from dopus_codegen.reference.offline import solve_ocp  # noqa: E402
from dopus_codegen.runtime.solver import CSolver  # noqa: E402
from dopus_codegen.studies.sil import run_closed_loop, summarize  # noqa: E402

SETTLE = 100          # the first outlier at t = 1 s
AFTER = 150
ADAPTIVE = (1, 10)    # M_min, M_max of adaptive M


def make(arm, kind, budget):
    s = CSolver(arm, M=1, lm=None)
    if kind == "adaptive":
        s.set_M_adaptive(True, *ADAPTIVE)
    elif kind == "full":
        s.set_M(arm.N - 1)
    if kind == "converged":
        s.set_work_budget(1e9)
    elif budget:
        s.set_time_budget(budget)
    return s


def outliers(arm, guess, kind, budget, K):
    plant = model_plant(arm)
    s = make(arm, kind, budget)
    x = np.asarray(arm.x0, float).copy()
    s.init(x, guess)
    for _ in range(SETTLE):
        x, _, _ = instant(s, plant, x, x.copy())
    xs, st_after, used = [], [], []
    for _ in range(K):
        xm = x.copy()
        xm[2:4] = [30.0, -30.0]
        x, _, _ = instant(s, plant, x, xm)
        xs.append(x.copy())
    for _ in range(AFTER):
        x, _, st = instant(s, plant, x, x.copy())
        xs.append(x.copy())
        st_after.append(st)
        used.append(s.budget_used)
    dev = tip_deviation(np.array(xs))
    after = dev[K:]
    back = next((i for i in range(after.size) if np.all(after[i:] <= 1e-2)), None)
    return {"kind": kind, "budget_s": budget, "K": K, "max_dev": float(dev.max()), "back": back,
            "failed_after": int(sum(v != 0 for v in st_after)),
            "budget_used_max_s": float(np.max(used)) if budget and kind != "converged" else None}


def demo(arm, guess, kind, budget):
    s = make(arm, kind, budget)
    run = run_closed_loop(arm, backend_obj=s, M=s.M, guess=guess, duration=3.0,
                          label=f"{kind} {budget * 1e3:g} ms" if budget else f"{kind} no budget")
    sm = summarize(run)
    seg = [g for g in sm["segments"] if g["signal"] == "deviation" and g["segment"].startswith("after")]
    return {"kind": kind, "budget_s": budget, "rms_after": seg[0]["rms"] if seg else None,
            "max_after": seg[0]["max"] if seg else None, "kkt_max_settled": sm["kkt_max_settled"],
            "failed": sm["qp_failures"], "time_median_us": sm["time_median_us"]}


def main(quick=False):
    arm = build_functions(load_ocp(ROOT / "examples" / "robot_arm.py"))
    guess, _ = solve_ocp(arm, arm.x0)
    out = {"outliers": [], "curves": []}
    print(f"{'setting':<22} {'K':>3} {'max dev [cm]':>12} {'back after':>10} {'failed after':>12}")
    for K in (1, 5, 20):
        for kind, budget in (("M=1", 0.0), ("M=1", 2e-3), ("adaptive", 2e-3), ("converged", 0.0)):
            r = outliers(arm, guess, kind, budget, K)
            out["outliers"].append(r)
            label = kind + (f" {budget * 1e3:g} ms" if budget else "")
            print(f"{label:<22} {K:3d} {100 * r['max_dev']:12.2f} {str(r['back']):>10} {r['failed_after']:12d}",
                  flush=True)
    budgets = [0.0, 2e-4, 5e-4, 1e-3, 2e-3] if quick else [0.0, 2e-4, 3e-4, 5e-4, 1e-3, 2e-3, 5e-3]
    print(f"\n{'setting':<22} {'RMS after [mm]':>14} {'max after [mm]':>14} {'max KKT settled':>15} {'failed':>6}")
    for kind in ("full", "M=1", "adaptive"):
        for budget in budgets:
            r = demo(arm, guess, kind, budget)
            out["curves"].append(r)
            label = kind + (f" {budget * 1e3:g} ms" if budget else " no budget")
            print(f"{label:<22} {1e3 * r['rms_after']:14.3f} {1e3 * r['max_after']:14.3f} "
                  f"{r['kkt_max_settled']:15.3e} {r['failed']:6d}", flush=True)
    res = ROOT / "bench" / "results"
    res.mkdir(parents=True, exist_ok=True)
    (res / "anytime_budget.json").write_text(json.dumps(out, indent=1))
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(1, 2, figsize=(10, 4))
        for kind in ("full", "M=1", "adaptive"):
            rows = [r for r in out["curves"] if r["kind"] == kind and r["budget_s"] > 0]
            b = [1e3 * r["budget_s"] for r in rows]
            ax[0].semilogx(b, [1e3 * r["rms_after"] for r in rows], "o-", label=kind)
            ax[1].loglog(b, [r["kkt_max_settled"] for r in rows], "o-", label=kind)
        ax[0].set_xlabel("budget per instant [ms]"); ax[0].set_ylabel("tracking RMS after the disturbance [mm]")
        ax[1].set_xlabel("budget per instant [ms]"); ax[1].set_ylabel("max KKT settled")
        ax[0].legend(); fig.tight_layout(); fig.savefig(res / "anytime_budget.png", dpi=120)
    except ImportError:
        pass


if __name__ == "__main__":
    main(quick="--quick" in sys.argv[1:])
