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
3N + 2 units, one M = 1 iteration 2N + 4; no budget goes below N + 4 (the feedback's QP and
step 3 of prepare, the last stage and the terminal node, are never cut; the gradients of the
other stages are, the stages whose linear models have moved least since their last evaluation
first), so no setting can need less than (N + 4) / (3N + 2) of the full RTI's budget. Time budgets: fractions of the reference's
median instant time on this host (noisy on a loaded machine: each budget runs --repeat
times, 3 by default, and each figure is the median of the runs, the failed instants too).

Instruction budgets (--parts m7): the emulated Cortex-M7 in double (QEMU with -icount
shift=0, deterministic): the firmware program's scenario command (dopus_lab/firmware.py,
run_scenario) runs the OCP file's scenario, its event as the host's, with the generated
integrator as the plant (the firmware has no CVODES) and the time budget on the program's
instruction clock. The reference is the full RTI without a budget on the firmware; the grid
is fractions of its median instructions per instant, then a bisection to 1 % of it between
the last grid point that misses and the first that meets. Also reported: the largest
instant at the needed budget against the reference's largest (what a controller must
provision for), since an instant's least cost (the feedback's QP, step 3 of prepare, the
stage-cost Hessians and the lm test) is never cut and a budget below it is exceeded.

The criterion need not be monotone in the budget (a single failed instant at some budget
above the bisection's figure): beside the bisection's figure ("needed") each setting reports
the robust reading ("needed_robust"), the least evaluated budget from which every evaluated
budget meets the criterion. The evaluated budgets are the grid, the bisection's and, for time
and instruction budgets, ENVELOPE_FRACTIONS of the reference above the bisection's figure
(the JSON's rows list them all). Both readings' adaptive / full ratios are printed and saved
("adaptive_over_full").

Prints the tables, writes bench/results/budget_curves.json and bench/results/budget_curves.png.

    .venv/bin/python bench/budget_curves.py [--problems robot_arm,chain] [--parts work,time,m7] [--repeat 3]

A fine grid on the emulated Cortex-M7 (--grid START:STOP:STEP, millions of instructions; no
bisection): the reference (the full RTI without a budget), then every budget of the grid for
each of --grid-settings (in that order per budget), each run read by ``m7_figures`` as the
curve reads its budgets, plus the feedback QPs the deadline cut, the stages re-linearised per
instant from the event on and the budget left unused at the cut instants. A grid budget is
``int(v * 1e6)`` of the grid value v rounded to the decimals given (2.03 M is 2 029 999
instructions, as in the grid of bench/issue24/measurements.md section 15, which this
reproduces). Prints one line per budget and the criterion per setting (+ meets it, - misses
it by the RMS alone, F failed instants), writes the JSON (--out, default
bench/results/m7_fine_grid.json) and its plot beside it (.png).

    .venv/bin/python bench/budget_curves.py --problems robot_arm --grid 1.40:2.60:0.03 [--grid-settings adaptive,full]
"""
from __future__ import annotations

import argparse
import json
import pathlib
import sys

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

from anytime_budget import closed_loop, figures  # noqa: E402

import numpy as np  # noqa: E402

from dopus_codegen import build_functions, load_ocp, vocabulary  # noqa: E402
from dopus_codegen.errors import qp_status_code  # noqa: E402
from dopus_codegen.reference.offline import solve_ocp  # noqa: E402
from dopus_codegen.studies.sil import summarize  # noqa: E402

# the OCP file and its scenario's tracking signal
PROBLEMS = {"robot_arm": ("robot_arm.py", "deviation"), "chain": ("chain.py", "end_error")}
KINDS = ("full", "M=1", "adaptive")
TOL = 0.02                                     # tracking RMS at most 2 % above the reference's
TIME_FRACTIONS = (0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.25, 1.5, 2.0)
# instruction budgets: fractions of the full RTI's median instructions per instant on the
# emulated Cortex-M7, then a bisection to 1 % of it
M7_FRACTIONS = (0.05, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9, 1.0, 1.25, 1.5, 2.0)
M7_RESOLUTION = 0.01
# the robust reading: fractions of the reference (time, instructions) evaluated above the
# needed budget besides the curve's grid, halving the grid's steps above one iteration
ENVELOPE_FRACTIONS = (1.125, 1.375, 1.75)
# DOPUS_FLAG_QP_CUT (runtime_c/dopus_solver.h: the deadline's cut QP was the step) and DOPUS_QP_DEADLINE (dopus_qp.h)
FLAG_QP_CUT = vocabulary.enum("dopus_flag").codes["qp_cut"]
QP_DEADLINE = qp_status_code("deadline")


def costs(N):
    """Work units of one full-RTI iteration, of one M = 1 iteration and the least an
    instant can cost."""
    return {"full": 3 * N + 2, "M=1": 2 * N + 4, "floor": N + 4}


def meets(row, ref, measure="rms_after"):
    """The criterion: no failed instant, ``measure`` (the tracking RMS after the event, or
    the max KKT measure settled) at most TOL above the reference's."""
    return row["failed"] == 0 and row[measure] is not None and row[measure] <= (1 + TOL) * ref[measure]


def smallest(evaluate, grid, ref, measure="rms_after", rows=None, resolution=None):
    """The smallest budget meeting the criterion: ``evaluate`` on every budget of the
    ascending ``grid`` (the curve), then on each integer between the last grid point that
    misses and the first that meets (work units), or, with ``resolution``, a bisection of
    that interval down to ``resolution`` (instructions). ``rows``: budgets already
    evaluated. Returns (budget or None, {budget: row})."""
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
    if below and resolution is not None:
        lo, hi = below[-1], first
        while hi - lo > resolution:
            mid = (lo + hi) // 2
            if meets(row(mid), ref, measure):
                hi = mid
            else:
                lo = mid
        return hi, rows
    if below and isinstance(first, int):
        for b in range(below[-1] + 1, first):
            if meets(row(b), ref, measure):
                return b, rows
    return first, rows


def envelope(passes):
    """The robust reading of evaluated budgets: the least budget B of ``passes`` ({budget:
    meets the criterion}) such that every evaluated budget >= B meets it; None if the
    largest evaluated budget misses (or nothing was evaluated)."""
    need = None
    for b in sorted(passes, reverse=True):
        if not passes[b]:
            break
        need = b
    return need


def work_grid(N, step):
    c = costs(N)
    top = 2 * c["full"]
    return sorted(set(range(c["floor"], top + 1, step)) | {c["floor"], c["M=1"], c["full"], top})


def median_figures(rows):
    """One row of figures from the rows of repeated runs: the median of each figure (the
    failed instants too), the repeats' RMS and failures kept."""
    out = dict(rows[0])
    for key in ("rms_after", "max_after", "kkt_max_settled", "failed", "time_median_us", "rms_before"):
        vals = [r[key] for r in rows if r[key] is not None]
        out[key] = float(np.median(vals)) if vals else None
    out["repeats"] = len(rows)
    out["rms_after_runs"] = [r["rms_after"] for r in rows]
    out["failed_runs"] = [r["failed"] for r in rows]
    return out


def m7_figures(disc, sc, recs, kind, budget, signal):
    """The figures of one firmware scenario run (dopus_lab.firmware.run_scenario's records),
    with the definitions of the host's (sil.summarize: the RMS after the event, the max KKT
    measure settled, the failed instants); instructions per instant instead of time."""
    fn = disc.scenario.closed_loop.signals[signal]
    p = np.zeros(int(disc.np))
    sig = [float(np.asarray(fn(r["xhat"], r["u0"], p), dtype=float).reshape(-1)[0]) for r in recs]
    run = {"label": f"m7 {kind} {budget}", "t": [r["step"] * sc["dt"] for r in recs],
           "events": [] if sc["event_step"] is None else [{"time": sc["event_time"], "label": sc["event_label"]}],
           "settings": {"dt": sc["dt"], "lbu": [None] * len(recs[0]["u0"]), "ubu": [None] * len(recs[0]["u0"])},
           "signals": {signal: sig}, "kkt": [r["kkt"] for r in recs], "status": [r["status"] for r in recs],
           "u": [r["u0"] for r in recs],
           "timing_us": {"total": [r["instructions_instant"] for r in recs], "feedback": [0.0] * len(recs)}}
    sm = summarize(run)
    seg = {g["segment"].split(" ")[0]: g for g in sm["segments"] if g["signal"] == signal}
    ins = [r["instructions_instant"] for r in recs]
    return {"kind": kind, "budget_s": budget, "rms_after": seg["after"]["rms"], "max_after": seg["after"]["max"],
            "rms_before": seg["before"]["rms"], "kkt_max_settled": sm["kkt_max_settled"],
            "failed": sm["qp_failures"], "instructions_median": float(np.median(ins)),
            "instructions_max": float(max(ins)),
            "extra_iterations": int(sum(r["extra"] for r in recs))}


def m7_image(disc):
    """The firmware image of the problem's scenario (dopus_lab.firmware.scenario_image)."""
    from dopus_lab import firmware as fwm

    return fwm.scenario_image(disc, ROOT / "bench" / "results" / "firmware_scenario" / disc.name,
                              progress=lambda *_: None)


def m7_part(disc, signal, log=print, plain_kinds=KINDS):
    """The firmware image of the problem's scenario and the figures of its closed loops on
    the emulated Cortex-M7 (double): (evaluate(budget, kind), reference, no-budget rows, scenario);
    ``plain_kinds``: the settings run without a budget (the full RTI, the reference, among them)."""
    from dopus_lab import firmware as fwm

    img = m7_image(disc)
    sc = img["scenario"]

    def evaluate(b, kind):
        return m7_figures(disc, sc, fwm.run_scenario(img, kind, int(b)), kind, int(b), signal)

    plain = {kind: evaluate(0, kind) for kind in plain_kinds}
    return evaluate, plain["full"], plain, sc


def problem(name, parts, step, repeat=3, log=print):
    ocp_file, signal = PROBLEMS[name]
    disc = build_functions(load_ocp(ROOT / "examples" / ocp_file))
    guess, _ = solve_ocp(disc, disc.x0)
    N = int(disc.N)
    c = costs(N)

    def host(kind, budget, n=1):
        return median_figures([figures(closed_loop(disc, guess, kind, budget), kind, budget, signal)
                               for _ in range(n)])

    # each setting without a budget: its tracking and its median instant time on this host
    # (the median of `repeat` runs when time budgets are measured)
    reps = repeat if "time" in parts else 1
    plain = {kind: host(kind, 0.0, reps) for kind in KINDS}
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
        pref, resolution, extra = ref, None, {}
        if part == "work":
            grid, unit, denom = work_grid(N, step), "units", c["full"]

            def evaluate(b, kind):
                return figures(closed_loop(disc, guess, kind, f"{b}u"), kind, b, signal)
        elif part == "time":
            denom = ref["time_median_us"] * 1e-6
            grid, unit = [round(f * denom, 7) for f in TIME_FRACTIONS], "ms"
            extra = {"repeats": repeat, "note": f"each budget run {repeat} times, the median of each figure"}

            def evaluate(b, kind):
                return host(kind, b, repeat)
        else:   # m7: the emulated Cortex-M7 (double), instructions
            evaluate, pref, m7_plain, sc = m7_part(disc, signal, log)
            denom = pref["instructions_median"]
            grid, unit = sorted({int(round(f * denom)) for f in M7_FRACTIONS}), "instructions"
            resolution = max(1, int(round(M7_RESOLUTION * denom)))
            extra = {"reference": pref, "no_budget": m7_plain, "resolution": resolution,
                     "denominator_max": pref["instructions_max"],
                     "plant": "the model (the generated integrator; the firmware has no CVODES)",
                     "scenario": {k: sc[k] for k in ("steps", "event_step", "event_label")},
                     "count_method": "qemu -icount shift=0, the instruction clock of the firmware program"}
            log(f"  m7 (emulated Cortex-M7, double; the model as plant): reference (full RTI, no budget) "
                f"{signal} RMS after the event {pref['rms_after']:.6g}, failed {pref['failed']}, max KKT settled "
                f"{pref['kkt_max_settled']:.3g}, instructions per instant median {denom:.0f}, max "
                f"{pref['instructions_max']:.0f}")
            for kind, r in m7_plain.items():
                log(f"  {kind:<9} no budget: RMS after / reference {r['rms_after'] / pref['rms_after']:.3f}, "
                    f"max KKT settled {r['kkt_max_settled']:.3g}, failed {r['failed']}, instructions median "
                    f"{r['instructions_median'] / denom:.3f}, max {r['instructions_max'] / denom:.3f} of the "
                    f"reference's median")
        out[part] = {"denominator": denom, "unit": unit, **extra, "settings": {}}
        log(f"  {part} budgets: {'setting':<9} {'needed':>10} {'ratio':>6} {'for KKT':>10} {'ratio':>6}   "
            f"per budget: RMS after / reference's (F: failed instants), max KKT settled / reference's")
        above = [] if part == "work" else sorted({round(f * denom, 7) if part == "time" else int(round(f * denom))
                                                  for f in ENVELOPE_FRACTIONS})
        out[part]["envelope_extra"] = above
        for kind in KINDS:
            need, rows = smallest(lambda b, k=kind: evaluate(b, k), grid, pref, resolution=resolution)
            need_kkt, rows = smallest(lambda b, k=kind: evaluate(b, k), grid, pref, "kkt_max_settled", rows,
                                      resolution=resolution)
            found = [n for n in (need, need_kkt) if n is not None]
            for b in above:     # the robust reading's extra points, above the bisection's figures
                if found and b > min(found) and b not in rows:
                    rows[b] = evaluate(b, kind)
            rob = envelope({b: meets(r, pref) for b, r in rows.items()})
            rob_kkt = envelope({b: meets(r, pref, "kkt_max_settled") for b, r in rows.items()})
            ordered = [rows[b] for b in sorted(rows)]
            out[part]["settings"][kind] = {"needed": need, "ratio": None if need is None else need / denom,
                                           "needed_kkt": need_kkt,
                                           "ratio_kkt": None if need_kkt is None else need_kkt / denom,
                                           "needed_robust": rob,
                                           "ratio_robust": None if rob is None else rob / denom,
                                           "needed_kkt_robust": rob_kkt,
                                           "ratio_kkt_robust": None if rob_kkt is None else rob_kkt / denom,
                                           "rows": ordered}
            if part == "m7":
                # what the instants took at the needed budget (the least an instant costs, the
                # feedback's QP and step 3 of prepare, is not cut: a budget below it is
                # exceeded), against the reference's largest instant
                dmax = pref["instructions_max"]
                used = None if need is None else rows[need]["instructions_max"]
                used_rob = None if rob is None else rows[rob]["instructions_max"]
                out[part]["settings"][kind].update(ratio_max=None if need is None else need / dmax,
                                                   ratio_kkt_max=None if need_kkt is None else need_kkt / dmax,
                                                   used_max=used, used_max_ratio=None if used is None else used / dmax,
                                                   ratio_robust_max=None if rob is None else rob / dmax,
                                                   used_max_robust=used_rob)
                log(f"  {'':14}{kind:<9} at the needed budget: largest instant "
                    f"{'-' if used is None else f'{used / 1e6:.3f}M'} "
                    f"({'-' if used is None else f'{used / dmax:.3f}'} of the reference's largest, "
                    f"{dmax / 1e6:.3f}M)")
            shown = " ".join(f"{_fmt(r['budget_s'], part, denom)}:{r['rms_after'] / pref['rms_after']:.3f}"
                             + ("F" if r["failed"] else "") for r in ordered)
            kkt = " ".join(f"{_fmt(r['budget_s'], part, denom)}:{r['kkt_max_settled'] / pref['kkt_max_settled']:.2g}"
                           for r in ordered)
            log(f"  {'':14}{kind:<9} {_fmt(need, part, denom):>10} {_ratio(need, denom):>6} "
                f"{_fmt(need_kkt, part, denom):>10} {_ratio(need_kkt, denom):>6}   {shown}\n  {'':52}{kkt}", flush=True)
            log(f"  {'':14}{kind:<9} robust (every evaluated budget from it on meets the criterion): "
                f"{_fmt(rob, part, denom)} ({_ratio(rob, denom)}), for KKT {_fmt(rob_kkt, part, denom)} "
                f"({_ratio(rob_kkt, denom)})", flush=True)
        st = out[part]["settings"]
        out[part]["adaptive_over_full"] = {
            "bisection": _over(st["adaptive"]["needed"], st["full"]["needed"]),
            "robust": _over(st["adaptive"]["needed_robust"], st["full"]["needed_robust"])}
        r = out[part]["adaptive_over_full"]
        log(f"  {part} budgets, adaptive / full: bisection {_ratio(r['bisection'], 1)}, robust "
            f"{_ratio(r['robust'], 1)} (extra budgets for the robust reading: "
            f"{' '.join(_fmt(b, part, denom) for b in above) or 'none, the grid'})", flush=True)
    return out


def grid_budgets(spec):
    """``START:STOP:STEP`` (millions of instructions) -> the grid's budgets in instructions:
    ``int(v * 1e6)`` of each value v = START + i STEP rounded to the decimals given."""
    parts = spec.split(":")
    if len(parts) != 3:
        raise ValueError(f"expected START:STOP:STEP, got {spec!r}")
    start, stop, step = (float(v) for v in parts)
    dec = max(len(v.split(".")[1]) if "." in v else 0 for v in parts)
    n = round((stop - start) / step) if step > 0 else -1
    if start <= 0 or n < 0 or abs(start + n * step - stop) > 1e-9 * max(1.0, stop):
        raise ValueError(f"{spec!r}: START > 0, STEP > 0 and STOP = START + n STEP for some n >= 0")
    return [int(round(start + i * step, dec) * 1e6) for i in range(n + 1)]


def grid_row(disc, sc, recs, kind, budget, signal, ref):
    """One row of the fine grid: the curve's figures of the run (``m7_figures``) and the
    feedback QPs the deadline cut (QP status DOPUS_QP_DEADLINE), the stages re-linearised per instant from the
    event on and the median of the budget left unused at the instants whose cut QP was the step
    (flag DOPUS_FLAG_QP_CUT; for an even count the upper of the two middle values: an instant's
    own figure)."""
    fig = m7_figures(disc, sc, recs, kind, budget, signal)
    cut = [r for r in recs if r.get("qp_status") == QP_DEADLINE]
    unused = [budget - r["instructions_instant"] for r in recs if (r.get("flags") or 0) & FLAG_QP_CUT]
    after = recs[sc["event_step"] or 0:]
    return {"setting": kind, "budget": budget, "rms_after": fig["rms_after"],
            "rms_after_over_reference": fig["rms_after"] / ref["rms_after"], "failed": fig["failed"],
            "qp_cut": len(cut), "median_instant": fig["instructions_median"],
            "largest_instant": fig["instructions_max"], "extra_iterations": fig["extra_iterations"],
            "meets": meets(fig, ref), "stages_per_instant_after_event": float(np.mean([r["stages"] for r in after])),
            "unused_at_cut_instants": sorted(unused)[len(unused) // 2] if unused else None}


def _mark(row):
    return "F" if row["failed"] else "+" if row["meets"] else "-"


def fine_grid(name, spec, kinds, log=print):
    """Every budget of ``spec`` (START:STOP:STEP) for each setting of ``kinds`` on the emulated
    Cortex-M7: the JSON of bench/issue24/m7_fine_grid_*.json."""
    from dopus_lab import firmware as fwm
    from dopus_lab.paths import checkout_commit

    budgets = grid_budgets(spec)
    ocp_file, signal = PROBLEMS[name]
    disc = build_functions(load_ocp(ROOT / "examples" / ocp_file))
    img = m7_image(disc)
    sc = img["scenario"]
    ref = m7_figures(disc, sc, fwm.run_scenario(img, "full", 0), "full", 0, signal)
    reference = {k: ref[k] for k in ("rms_after", "instructions_median", "instructions_max")}
    log(f"{name}: reference (full RTI, no budget) {signal} RMS after the event {ref['rms_after']:.6g}, "
        f"instructions per instant median {ref['instructions_median']:.0f}, max {ref['instructions_max']:.0f}; "
        f"{len(budgets)} budgets x {len(kinds)} settings", flush=True)
    rows = []
    for b in budgets:
        for kind in kinds:
            r = grid_row(disc, sc, fwm.run_scenario(img, kind, b), kind, b, signal, ref)
            rows.append(r)
            log(f"  {kind:<9} {b / 1e6:.3f}M {_mark(r)} RMS after / reference {r['rms_after_over_reference']:.3f}, "
                f"failed {r['failed']}, cut QPs {r['qp_cut']}, instants median {r['median_instant'] / 1e6:.3f}M, "
                f"largest {r['largest_instant'] / 1e6:.3f}M, stages per instant after the event "
                f"{r['stages_per_instant_after_event']:.3f}", flush=True)
    for kind in kinds:
        mine = [r for r in rows if r["setting"] == kind]
        log(f"{kind:<9} meets the criterion at {sum(r['meets'] for r in mine)} of {len(mine)} budgets: "
            + " ".join(f"{r['budget'] / 1e6:.2f}:{_mark(r)}" for r in mine))
    lo, hi, st = spec.split(":")
    return {"problem": name, "commit": checkout_commit(),
            "what": f"emulated Cortex-M7 (double), the {name.replace('_', ' ')}'s scenario, every budget of a fine "
                    f"grid ({lo} to {hi} M instructions, step {st} M); criterion: no failed instant and {signal} RMS "
                    f"after the event at most {1 + TOL:g} of the full RTI's without a budget",
            "reference": reference, "rows": rows}


def plot_grid(out, path):
    """The fine grid: RMS after the event over the reference's and the cut feedback QPs per
    budget, one line per setting (x: failed instants)."""
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    fig, ax = plt.subplots(2, 1, figsize=(9, 7), sharex=True)
    for kind in dict.fromkeys(r["setting"] for r in out["rows"]):
        rows = [r for r in out["rows"] if r["setting"] == kind]
        x = [r["budget"] / 1e6 for r in rows]
        line, = ax[0].plot(x, [r["rms_after_over_reference"] for r in rows], ".-", label=kind)
        bad = [(xi, r["rms_after_over_reference"]) for xi, r in zip(x, rows) if r["failed"]]
        if bad:
            ax[0].plot(*zip(*bad), "x", color=line.get_color())
        ax[1].plot(x, [r["qp_cut"] for r in rows], ".-", color=line.get_color(), label=kind)
    ax[0].axhline(1 + TOL, color="k", lw=0.8)
    ax[0].set_yscale("log")
    ax[0].set_ylabel("RMS after the event / full RTI's")
    at = f" on {out['commit']}" if out["commit"] else ""
    ax[0].set_title(f"{out['problem']}, emulated Cortex-M7, fine grid{at} (x: failed instants)", fontsize=10)
    ax[0].legend(fontsize=8)
    ax[1].set_ylabel("feedback QPs cut by the deadline")
    ax[1].set_xlabel("budget per instant (M instructions)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def _over(a, b):
    return None if a is None or b is None else a / b


def _ratio(b, denom):
    return "-" if b is None else f"{b / denom:.3f}"


def _fmt(b, part, denom=None):
    """A budget as the table shows it: work units, ms, or millions of instructions."""
    if b is None:
        return "not met"
    if part == "m7":
        return f"{b / 1e6:.3f}M"
    return f"{b:g}" if part == "work" else f"{1e3 * b:.3g}"


def plot(out, path):
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return
    names = list(out)
    cols = [(p, m) for p in ("work", "time", "m7") if any(p in out[n] for n in names)
            for m in ("rms_after", "kkt_max_settled")]
    if not cols:
        return
    fig, ax = plt.subplots(len(names), len(cols), figsize=(5 * len(cols), 4 * len(names)), squeeze=False)
    for i, name in enumerate(names):
        for j, (part, measure) in enumerate(cols):
            a = ax[i][j]
            if part not in out[name]:
                a.set_visible(False)
                continue
            d = out[name][part]
            ref = d.get("reference", out[name]["reference"])
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
            a.set_xlabel("budget / one full-RTI iteration" + {"work": " (work units)", "time": " (its median time)",
                                                               "m7": " (its median instructions, M7)"}[part])
            what = f"{out[name]['signal']} RMS after the event" if measure == "rms_after" else "max KKT settled"
            a.set_ylabel(f"{what} / full RTI's")
            a.set_title(f"{name}, {part} budgets (x: failed instants)", fontsize=10)
            a.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--problems", default=None, help="comma-separated: robot_arm, chain (default both; "
                    "with --grid one, default robot_arm)")
    ap.add_argument("--parts", default="work,time", help="comma-separated: work, time, m7 (the emulated "
                    "Cortex-M7 in double, instructions; needs the firmware toolchain)")
    ap.add_argument("--repeat", type=int, default=3, help="runs per time budget, the median of each figure "
                    "(default 3)")
    ap.add_argument("--step", type=int, default=8, help="work units between grid points (default 8)")
    ap.add_argument("--grid", default=None, metavar="START:STOP:STEP",
                    help="a fine grid on the emulated Cortex-M7 instead of the curves: every budget from START "
                         "to STOP millions of instructions in steps of STEP (e.g. 1.40:2.60:0.03)")
    ap.add_argument("--grid-settings", default="adaptive,full",
                    help="with --grid: comma-separated settings, each budget's runs in this order (default "
                         "adaptive,full)")
    ap.add_argument("--out", default=None, help="the JSON (default bench/results/budget_curves.json, with --grid "
                    "bench/results/m7_fine_grid.json); the plot beside it")
    a = ap.parse_args(argv)
    if a.grid is not None:
        names = [n for n in (a.problems or "robot_arm").split(",") if n]
        kinds = [k for k in a.grid_settings.split(",") if k]
        try:
            grid_budgets(a.grid)
        except ValueError as e:
            ap.error(f"--grid: {e}")
        bad = [n for n in names if n not in PROBLEMS] + [k for k in kinds if k not in KINDS]
        if bad or len(names) != 1 or not kinds:
            ap.error(f"unknown problem or setting {bad}" if bad else "--grid takes one problem and a setting")
        path = pathlib.Path(a.out or ROOT / "bench" / "results" / "m7_fine_grid.json")
        path.parent.mkdir(parents=True, exist_ok=True)
        out = fine_grid(names[0], a.grid, kinds)
        path.write_text(json.dumps(out, indent=1))
        plot_grid(out, path.with_suffix(".png"))
        print(f"wrote {path}")
        return
    names = [n for n in (a.problems or "robot_arm,chain").split(",") if n]
    parts = [p for p in a.parts.split(",") if p]
    bad = [n for n in names if n not in PROBLEMS] + [p for p in parts if p not in ("work", "time", "m7")]
    if bad or a.step < 1 or a.repeat < 1:
        ap.error(f"unknown problem or part {bad}" if bad else "--step and --repeat must be at least 1")
    path = pathlib.Path(a.out or ROOT / "bench" / "results" / "budget_curves.json")
    path.parent.mkdir(parents=True, exist_ok=True)
    out = json.loads(path.read_text()) if path.exists() else {}
    for name in names:
        out.setdefault(name, {}).update(problem(name, parts, a.step, a.repeat))
        path.write_text(json.dumps(out, indent=1))
    plot(out, path.with_suffix(".png"))


if __name__ == "__main__":
    main()
