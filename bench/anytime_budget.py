"""Anytime DOPUS on the robot arm: closed-loop quality against the budget per instant
(docs/algorithm.md section 14).

1. Outliers (the acceptance of the budget): the model as plant (RK4, 20 substeps), K
   measurements with joint velocities (30, -30) from t = 1 s, then exact ones. Per setting:
   the largest tip deviation from the circle after the first outlier, the instants after
   the last outlier until the tip stays within 1 cm, and the failed instants after it.
   Settings: no budget (M = 1), a work budget of 800 units (M = 1 and adaptive M), 2 ms
   (M = 1), a solver run to convergence at every instant (a work budget of 1e9 units,
   KKT proxy 1e-8, at most 50 iterations per instant), and M = 1 with the measurement gate
   (gate 10, gate_hold 25; docs/algorithm.md section 9) without a budget and with 2 ms.
2. Budget curves on `make demo`'s scenario (dopus-gen sil, CVODES plant, the disturbance at
   1 s): tracking RMS before and after the disturbance, max after, max KKT settled and
   failed instants, against the budget, for the full RTI (M = N-1), fixed M = 1 and adaptive
   M; with what the OCP itself weighs: the sum of its stage cost over the closed loop
   (before / after the disturbance) and the progress theta at the end (its terminal reward
   -theta_N is -theta_0 - dt sum dtheta_k, so "cost - progress" is the OCP's own measure of
   the closed loop). The work part adds the controller solved to convergence at every
   instant (1e9 units).

Budgets in work units (deterministic: 84 units are one M = 1 iteration, about 0.2 ms on an
idle host of this kind, so 800 units are about 2 ms) and in time (this host's; noisy on a
loaded machine: a descheduled instant spends its budget waiting). Prints the tables, writes
bench/results/anytime_budget.json and bench/results/anytime_budget.png.

    .venv/bin/python bench/anytime_budget.py [outliers] [work] [time]
"""
from __future__ import annotations

import json
import pathlib
import sys

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from harness.faults import back_on_path, model_plant, tip_deviation, instant  # noqa: E402

from dopus_codegen import build_functions, load_ocp  # noqa: E402
from dopus_codegen.reference.offline import solve_ocp  # noqa: E402
from dopus_codegen.runtime.solver import CSolver  # noqa: E402
from dopus_codegen.studies.sil import run_closed_loop, summarize  # noqa: E402

SETTLE = 100          # the first outlier at t = 1 s
AFTER = 150
ADAPTIVE = (1, 10)    # M_min, M_max of adaptive M
GATE = (10.0, 25)     # the measurement gate of the settings "... gate" (docs/algorithm.md section 9)


def label(kind, budget):
    """A budget: 0 (none), seconds (float) or work units ("800u")."""
    if kind == "converged":
        return "converged (1e9 units)"
    if not budget:
        return f"{kind} no budget"
    if isinstance(budget, str):
        return f"{kind} {budget}"
    return f"{kind} {budget * 1e3:g} ms"


def make(arm, kind, budget):
    s = CSolver(arm, M=1, lm=None)
    if kind.endswith("gate"):
        s.set_gate(*GATE)
    if kind.startswith("adaptive"):
        s.set_M_adaptive(True, *ADAPTIVE)
    elif kind == "full":
        s.set_M(arm.N - 1)
    if kind == "converged":
        s.set_work_budget(1e9)
    elif isinstance(budget, str):
        s.set_work_budget(float(budget.rstrip("u")))
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
    back = back_on_path(after)
    return {"kind": kind, "budget_s": budget, "K": K, "max_dev": float(dev.max()), "back": back,
            "failed_after": int(sum(v != 0 for v in st_after)),
            "budget_used_max": float(np.max(used)) if budget and kind != "converged" else None}


def closed_loop(disc, guess, kind, budget):
    """The closed loop of the OCP file's scenario (its duration, plant and event) for one
    setting: the record of ``run_closed_loop``."""
    s = make(disc, kind, budget)
    return run_closed_loop(disc, backend_obj=s, M=s.M, guess=guess, label=label(kind, budget))


def figures(run, kind, budget, signal="deviation", disc=None):
    """The figures of one run; ``signal``: the scenario's tracking signal (its RMS and max
    before and after the event). With ``disc``, also what the OCP itself weighs: the
    closed-loop cost, the sum of the OCP's stage cost l(x_k, u_k) over the instants (measured
    state, applied control; before and after the event), and the progress, the last
    instant's theta (a state named theta)."""
    sm = summarize(run)
    seg = [g for g in sm["segments"] if g["signal"] == signal and g["segment"].startswith("after")]
    out = {"kind": kind, "budget_s": budget, "rms_after": seg[0]["rms"] if seg else None,
           "max_after": seg[0]["max"] if seg else None, "kkt_max_settled": sm["kkt_max_settled"],
           "failed": sm["qp_failures"], "time_median_us": sm["time_median_us"],
           "rms_before": next((g["rms"] for g in sm["segments"] if g["signal"] == signal
                               and g["segment"].startswith("before")), None)}
    if disc is not None:
        out.update(closed_loop_cost(disc, run))
    return out


def closed_loop_cost(disc, run):
    """The OCP's stage cost summed over the closed loop (before / after the first event) and
    the progress theta at the last instant (None without a state theta)."""
    x = np.asarray(run["x"], dtype=float)
    u = np.asarray(run["u"], dtype=float)
    t = np.asarray(run["t"], dtype=float)
    p = np.zeros(int(disc.np))
    cost = np.array([float(disc.stage_eval(xk, uk, p)[1]) for xk, uk in zip(x, u)])
    t_ev = run["events"][0]["time"] if run["events"] else np.inf
    after = t >= t_ev - 1e-9 * float(disc.dt)
    names = list(disc.data.state_names)
    return {"cost": float(cost.sum()), "cost_before": float(cost[~after].sum()),
            "cost_after": float(cost[after].sum()),
            "progress": float(x[-1, names.index("theta")]) if "theta" in names else None,
            # the OCP's terminal reward -theta_N is -theta_0 - dt sum dtheta_k: over the closed
            # loop the OCP weighs the stage cost against the progress one to one
            "cost_minus_progress": (float(cost.sum() - (x[-1, names.index("theta")] - x[0, names.index("theta")]))
                                    if "theta" in names else None)}


def demo(arm, guess, kind, budget):
    return figures(closed_loop(arm, guess, kind, budget), kind, budget, disc=arm)


WORK = ["84u", "150u", "300u", "500u", "800u", "1500u"]   # 84 units: one M = 1 iteration
TIME = [2e-4, 5e-4, 1e-3, 2e-3, 5e-3]


def _units(b):
    return float(b.rstrip("u")) if isinstance(b, str) else 1e3 * b


def main(parts):
    arm = build_functions(load_ocp(ROOT / "examples" / "robot_arm.py"))
    guess, _ = solve_ocp(arm, arm.x0)
    res = ROOT / "bench" / "results"
    res.mkdir(parents=True, exist_ok=True)
    path = res / "anytime_budget.json"
    out = json.loads(path.read_text()) if path.exists() else {}
    if "outliers" in parts:
        out["outliers"] = []
        print(f"{'setting':<22} {'K':>3} {'max dev [cm]':>12} {'back after':>10} {'failed after':>12}")
        for K in (1, 5, 20):
            for kind, budget in (("M=1", 0.0), ("M=1", "800u"), ("adaptive", "800u"), ("M=1", 2e-3),
                                 ("converged", 0.0), ("M=1 gate", 0.0), ("M=1 gate", 2e-3)):
                r = outliers(arm, guess, kind, budget, K)
                r["budget"] = budget
                out["outliers"].append(r)
                print(f"{label(kind, budget):<22} {K:3d} {100 * r['max_dev']:12.2f} {str(r['back']):>10} "
                      f"{r['failed_after']:12d}", flush=True)
    for part, budgets in (("work", WORK), ("time", TIME)):
        if part not in parts:
            continue
        out[part] = []
        print(f"\n{'setting':<22} {'RMS before/after [mm]':>22} {'max after [mm]':>14} {'max KKT settled':>15} "
              f"{'failed':>6} {'cost before/after':>19} {'progress':>9} {'cost - progress':>15}")
        runs = [(kind, budget) for kind in ("full", "M=1", "adaptive") for budget in [0.0] + budgets]
        if part == "work":   # solved to convergence at every instant (1e9 units)
            runs.append(("converged", 0.0))
        for kind, budget in runs:
            r = demo(arm, guess, kind, budget)
            r["budget"] = budget
            out[part].append(r)
            print(f"{label(kind, budget):<22} {1e3 * r['rms_before']:10.3f} {1e3 * r['rms_after']:11.3f} "
                  f"{1e3 * r['max_after']:14.3f} {r['kkt_max_settled']:15.3e} {r['failed']:6d} "
                  f"{r['cost_before']:9.4f} {r['cost_after']:9.4f} {r['progress']:9.4f} "
                  f"{r['cost_minus_progress']:15.4f}", flush=True)
    path.write_text(json.dumps(out, indent=1))
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        import matplotlib.ticker
    except ImportError:
        return
    parts_done = [p for p in ("work", "time") if p in out]
    if not parts_done:
        return
    fig, ax = plt.subplots(len(parts_done), 2, figsize=(10, 4 * len(parts_done)), squeeze=False)
    for row, part in enumerate(parts_done):
        unit = "work units" if part == "work" else "ms"
        for kind in ("full", "M=1", "adaptive"):
            rows = [r for r in out[part] if r["kind"] == kind and r["budget"]]
            b = [_units(r["budget"]) for r in rows]
            ax[row][0].semilogx(b, [1e3 * r["rms_after"] for r in rows], "o-", label=kind)
            ax[row][1].loglog(b, [r["kkt_max_settled"] for r in rows], "o-", label=kind)
            base = [r for r in out[part] if r["kind"] == kind and not r["budget"]]
            if base:
                ax[row][1].axhline(base[0]["kkt_max_settled"], ls=":", color=ax[row][1].lines[-1].get_color())
        ticks = sorted({_units(r["budget"]) for r in out[part] if r["budget"]})
        for a in ax[row]:
            a.set_xticks(ticks)
            a.set_xticklabels([f"{v:g}" for v in ticks])
            a.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ax[row][0].set_yscale("log")
        ax[row][0].set_xlabel(f"budget per instant [{unit}]")
        ax[row][0].set_ylabel("tracking RMS after the disturbance [mm]")
        ax[row][1].set_xlabel(f"budget per instant [{unit}]")
        ax[row][1].set_ylabel("max KKT settled (dotted: no budget)")
        ax[row][0].legend()
    fig.tight_layout()
    fig.savefig(res / "anytime_budget.png", dpi=120)


if __name__ == "__main__":
    main(sys.argv[1:] or ["outliers", "work", "time"])
