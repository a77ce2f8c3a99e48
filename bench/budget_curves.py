"""Budget curves: the budget per instant each setting needs to reach the full RTI's
closed-loop tracking (docs/algorithm.md section 14), for the robot arm and the chain of
masses.

Each problem runs its OCP file's scenario (`dopus-gen sil`'s closed loop: the robot arm's
disturbance at 1 s with its CVODES plant, the chain's shake at 1 s) with the C runtime. The
reference is the full RTI (M = N-1) without a budget, one full iteration per instant. Its
tracking is the RMS of the scenario's tracking signal after the event (the robot arm's tip
deviation from the circle, the chain's end error). For each setting, the full RTI with a
budget, fixed M = 1 and adaptive M (M_min, M_max = 1, 10; eta the default 0.1), the needed
budget is the smallest one whose closed loop has no failed instant and a tracking RMS at
most 2 % above the reference's: a grid of budgets, then each unit between the last grid
point that misses and the first that meets. It is reported as a ratio to the cost of one
full iteration.

Work budgets (deterministic, work units of section 14): one full-RTI iteration costs
3N + 2 units, one M = 1 iteration 2N + 4; no budget goes below 2N + 3 (the feedback's QP,
the gradients and the last stage are never cut), so no setting can need less than
(2N + 3) / (3N + 2) of the full RTI's budget. Time budgets: fractions of the reference's
median instant time on this host (noisy on a loaded machine).

Prints the tables, writes bench/results/budget_curves.json and bench/results/budget_curves.png.

    .venv/bin/python bench/budget_curves.py [--problems robot_arm,chain] [--parts work,time]
"""
from __future__ import annotations

import argparse
import json
import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

from anytime_budget import closed_loop, figures  # noqa: E402

from dopus_codegen import build_functions, load_ocp  # noqa: E402
from dopus_codegen.reference.offline import solve_ocp  # noqa: E402

# the OCP file and its scenario's tracking signal
PROBLEMS = {"robot_arm": ("robot_arm.py", "deviation"), "chain": ("chain.py", "end_error")}
KINDS = ("full", "M=1", "adaptive")
TOL = 0.02                                     # tracking RMS at most 2 % above the reference's
TIME_FRACTIONS = (0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.25, 1.5, 2.0)


def costs(N):
    """Work units of one full-RTI iteration, of one M = 1 iteration and the least an
    instant can cost."""
    return {"full": 3 * N + 2, "M=1": 2 * N + 4, "floor": 2 * N + 3}


def meets(row, ref, measure="rms_after"):
    """The criterion: no failed instant, ``measure`` (the tracking RMS after the event, or
    the max KKT measure settled) at most TOL above the reference's."""
    return row["failed"] == 0 and row[measure] is not None and row[measure] <= (1 + TOL) * ref[measure]


def smallest(evaluate, grid, ref, measure="rms_after", rows=None):
    """The smallest budget meeting the criterion: ``evaluate`` on every budget of the
    ascending ``grid`` (the curve), then on each integer between the last grid point that
    misses and the first that meets (work units). ``rows``: budgets already evaluated.
    Returns (budget or None, {budget: row})."""
    rows = {} if rows is None else rows

    def row(b):
        if b not in rows:
            rows[b] = evaluate(b)
        return rows[b]

    ok = [b for b in grid if meets(row(b), ref, measure)]
    if not ok:
        return None, rows
    first = ok[0]
    below = [b for b in grid if b < first]
    if below and isinstance(first, int):
        for b in range(below[-1] + 1, first):
            if meets(row(b), ref, measure):
                return b, rows
    return first, rows


def work_grid(N, step):
    c = costs(N)
    top = 2 * c["full"]
    return sorted(set(range(c["floor"], top + 1, step)) | {c["floor"], c["M=1"], c["full"], top})


def problem(name, parts, step, log=print):
    ocp_file, signal = PROBLEMS[name]
    disc = build_functions(load_ocp(ROOT / "examples" / ocp_file))
    guess, _ = solve_ocp(disc, disc.x0)
    N = int(disc.N)
    c = costs(N)
    # each setting without a budget: its tracking and its median instant time on this host
    plain = {kind: figures(closed_loop(disc, guess, kind, 0.0), kind, 0.0, signal) for kind in KINDS}
    ref = plain["full"]
    out = {"N": N, "signal": signal, "costs": c, "reference": ref, "tol": TOL, "no_budget": plain}
    log(f"\n{name}: N = {N}, one full iteration {c['full']} units, one M = 1 iteration {c['M=1']}, "
        f"least per instant {c['floor']} (ratio {c['floor'] / c['full']:.3f}); reference (full RTI, no budget): "
        f"{signal} RMS after the event {ref['rms_after']:.6g}, failed {ref['failed']}, "
        f"max KKT settled {ref['kkt_max_settled']:.3g}, median instant {ref['time_median_us']:.0f} us")
    for kind, r in plain.items():
        log(f"  {kind:<9} no budget: RMS after / reference {r['rms_after'] / ref['rms_after']:.3f}, "
            f"max KKT settled {r['kkt_max_settled']:.3g}, failed {r['failed']}, "
            f"median instant {r['time_median_us']:.0f} us "
            f"({r['time_median_us'] / ref['time_median_us']:.2f} of the reference's)")
    for part in parts:
        if part == "work":
            grid, unit, denom = work_grid(N, step), "units", c["full"]

            def evaluate(b, kind):
                return figures(closed_loop(disc, guess, kind, f"{b}u"), kind, b, signal)
        else:
            denom = ref["time_median_us"] * 1e-6
            grid, unit = [round(f * denom, 7) for f in TIME_FRACTIONS], "ms"

            def evaluate(b, kind):
                return figures(closed_loop(disc, guess, kind, b), kind, b, signal)
        out[part] = {"denominator": denom, "unit": unit, "settings": {}}
        log(f"  {part} budgets: {'setting':<9} {'needed':>10} {'ratio':>6} {'for KKT':>10} {'ratio':>6}   "
            f"per budget: RMS after / reference's (F: failed instants), max KKT settled / reference's")
        for kind in KINDS:
            need, rows = smallest(lambda b, k=kind: evaluate(b, k), grid, ref)
            need_kkt, rows = smallest(lambda b, k=kind: evaluate(b, k), grid, ref, "kkt_max_settled", rows)
            ordered = [rows[b] for b in sorted(rows)]
            out[part]["settings"][kind] = {"needed": need, "ratio": None if need is None else need / denom,
                                           "needed_kkt": need_kkt,
                                           "ratio_kkt": None if need_kkt is None else need_kkt / denom,
                                           "rows": ordered}
            shown = " ".join(f"{_fmt(r['budget_s'], part)}:{r['rms_after'] / ref['rms_after']:.3f}"
                             + ("F" if r["failed"] else "") for r in ordered)
            kkt = " ".join(f"{_fmt(r['budget_s'], part)}:{r['kkt_max_settled'] / ref['kkt_max_settled']:.2g}"
                           for r in ordered)
            log(f"  {'':14}{kind:<9} {_fmt(need, part):>10} {_ratio(need, denom):>6} {_fmt(need_kkt, part):>10} "
                f"{_ratio(need_kkt, denom):>6}   {shown}\n  {'':52}{kkt}", flush=True)
    return out


def _ratio(b, denom):
    return "-" if b is None else f"{b / denom:.3f}"


def _fmt(b, part):
    if b is None:
        return "not met"
    return f"{b:g}" if part == "work" else f"{1e3 * b:.3g}"


def plot(out, path):
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    names = list(out)
    cols = [(p, m) for p in ("work", "time") if any(p in out[n] for n in names)
            for m in ("rms_after", "kkt_max_settled")]
    if not cols:
        return
    fig, ax = plt.subplots(len(names), len(cols), figsize=(5 * len(cols), 4 * len(names)), squeeze=False)
    for i, name in enumerate(names):
        ref = out[name]["reference"]
        for j, (part, measure) in enumerate(cols):
            a = ax[i][j]
            if part not in out[name]:
                a.set_visible(False)
                continue
            d = out[name][part]
            for kind, s in d["settings"].items():
                rows = s["rows"]
                x = [r["budget_s"] / d["denominator"] for r in rows]
                y = [r[measure] / ref[measure] for r in rows]
                line, = a.plot(x, y, ".-", label=kind)
                bad = [(xi, yi) for xi, yi, r in zip(x, y, rows) if r["failed"]]
                if bad:
                    a.plot(*zip(*bad), "x", color=line.get_color())
                need = s["ratio"] if measure == "rms_after" else s["ratio_kkt"]
                if need is not None:
                    a.axvline(need, ls=":", color=line.get_color())
            a.axhline(1 + TOL, color="k", lw=0.8)
            a.axvline(0.6, color="grey", lw=0.8, ls="--")
            a.set_yscale("log")
            a.set_xlabel("budget / one full-RTI iteration" + (" (work units)" if part == "work"
                                                               else " (its median time)"))
            what = f"{out[name]['signal']} RMS after the event" if measure == "rms_after" else "max KKT settled"
            a.set_ylabel(f"{what} / full RTI's")
            a.set_title(f"{name}, {part} budgets (x: failed instants)", fontsize=10)
            a.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--problems", default="robot_arm,chain", help="comma-separated: robot_arm, chain")
    ap.add_argument("--parts", default="work,time", help="comma-separated: work, time")
    ap.add_argument("--step", type=int, default=8, help="work units between grid points (default 8)")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "budget_curves.json"))
    a = ap.parse_args(argv)
    names = [n for n in a.problems.split(",") if n]
    parts = [p for p in a.parts.split(",") if p]
    bad = [n for n in names if n not in PROBLEMS] + [p for p in parts if p not in ("work", "time")]
    if bad or a.step < 1:
        ap.error(f"unknown problem or part {bad}" if bad else "--step must be at least 1")
    path = pathlib.Path(a.out)
    path.parent.mkdir(parents=True, exist_ok=True)
    out = json.loads(path.read_text()) if path.exists() else {}
    for name in names:
        out.setdefault(name, {}).update(problem(name, parts, a.step))
        path.write_text(json.dumps(out, indent=1))
    plot(out, path.with_suffix(".png"))


if __name__ == "__main__":
    main()
