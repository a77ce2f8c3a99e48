"""Instructions per instant on the emulated Cortex-M7 (double) with a time budget on the
instruction clock: the bound of docs/algorithm.md section 14 ("a bounded worst case").

The robot arm's scenario (its OCP file's: 300 instants, the disturbance at 1 s, instant 100)
runs on the firmware program (dopus_lab.firmware.run_scenario: QEMU with -icount shift=0,
deterministic; the generated integrator as the plant), for each setting (the full RTI,
M = 1, adaptive M 1..10) and each budget. An instant's instructions are those of its
feedback and prepare on the board's timer (counted outside the solver). One stage
evaluation is priced as the test of the chain does (tests/test_firmware_scenario.py): the
full RTI's median instant minus M = 1's without a budget, over the N - 2 stages the full RTI
re-linearises more. The bound: every instant at most the budget plus one stage evaluation.

Per setting and budget: the largest instant of the run, the largest and the median of the
20 instants from the disturbance on, the run's median, its excess over the budget, whether
the bound holds on the run and on the 20 instants, the tracking RMS after the disturbance
(the tip's deviation from the circle, m), the failed instants and the extra iterations; then
the largest feedback of the run (its QP and the step: what sets the budget a setting needs),
the feedback QPs the deadline cut and each failed instant with its QP's iterations and status.

Prints a table, writes bench/results/m7_instants.json (--out).

    .venv/bin/python bench/m7_instants.py [--budgets 3.2,3.4,6,10] [--settings full,M=1,adaptive]
"""
from __future__ import annotations

import argparse
import json
import pathlib
import sys
import time

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

from budget_curves import PROBLEMS, QP_DEADLINE, m7_figures  # noqa: E402

from dopus_codegen import build_functions, load_ocp  # noqa: E402
from dopus_lab.paths import checkout_commit  # noqa: E402

AFTER = 20          # the instants from the disturbance on


def summary(disc, sc, recs, kind, budget, stage, signal):
    """The figures of one run (records of dopus_lab.firmware.run_scenario)."""
    fig = m7_figures(disc, sc, recs, kind, budget, signal)
    ins = [r["instructions_instant"] for r in recs]
    e = sc["event_step"]
    after = ins[e:e + AFTER]
    worst = int(np.argmax(ins))
    bound = budget + stage if budget else None
    # the feedback's share of each instant (its QP and the step) and the failed instants with
    # what their QP did (iterations, dopus_qp_status: 7 the budget's deadline; flags
    # DOPUS_FLAG_*: 256 a cut QP taken as the step)
    fb = [r["ticks_feedback"] * r["instructions_instant"] / max(1, r["ticks_feedback"] + r["ticks_prepare"])
          for r in recs]
    hard = int(np.argmax(fb))
    failed_at = [{"step": r["step"], "status": r["status"], "qp_iterations": r["qp_iters"],
                  "qp_status": r.get("qp_status"), "flags": r.get("flags")} for r in recs if r["status"] != 0]
    return {"setting": kind, "budget": budget, "largest": max(ins), "largest_instant": worst,
            "largest_after": max(after), "median_after": float(np.median(after)),
            "median": float(np.median(ins)),
            "over": None if not budget else max(ins) - budget,
            "within_bound": None if not budget else bool(max(ins) <= bound),
            "within_bound_after": None if not budget else bool(max(after) <= bound),
            "rms_after": fig["rms_after"], "failed": fig["failed"],
            "extra_iterations": fig["extra_iterations"], "kkt_max_settled": fig["kkt_max_settled"],
            "feedback_largest": fb[hard], "feedback_largest_instant": hard,
            "feedback_largest_qp_iterations": recs[hard]["qp_iters"], "failed_at": failed_at,
            "qp_cut": sum(1 for r in recs if r.get("qp_status") == QP_DEADLINE),
            "per_instant": ins, "per_instant_feedback": fb,
            "per_instant_qp_iterations": [r["qp_iters"] for r in recs]}


def _k(v):
    return "-" if v is None else f"{v / 1e3:+.1f}k"


def _yes(v):
    return "-" if v is None else "yes" if v else "NO"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--problem", default="robot_arm", choices=sorted(PROBLEMS))
    ap.add_argument("--budgets", default="3.2,3.4,6,10", help="comma-separated, millions of instructions")
    ap.add_argument("--settings", default="full,M=1,adaptive", help="comma-separated: full, M=1, adaptive")
    ap.add_argument("--out", default=str(ROOT / "bench" / "results" / "m7_instants.json"))
    a = ap.parse_args(argv)
    from dopus_lab import firmware as fwm

    try:
        budgets = [int(round(float(b) * 1e6)) for b in a.budgets.split(",") if b]
    except ValueError:
        ap.error(f"--budgets: expected numbers (millions of instructions), got {a.budgets!r}")
    kinds = [k for k in a.settings.split(",") if k]
    bad = [k for k in kinds if k not in fwm.SCENARIO_SETTINGS]
    if bad or not budgets or min(budgets) <= 0:
        ap.error(f"unknown settings {bad}" if bad else "--budgets: positive numbers")
    missing = fwm.setup_toolchain()
    if missing:
        sys.exit(f"m7_instants: the firmware toolchain is missing {missing} (scripts/setup_firmware.sh)")
    ocp_file, signal = PROBLEMS[a.problem]
    disc = build_functions(load_ocp(ROOT / "examples" / ocp_file))
    img = fwm.scenario_image(disc, ROOT / "bench" / "results" / "firmware_scenario" / disc.name,
                             progress=lambda *_: None)
    sc = img["scenario"]
    N = int(disc.N)
    runs = [(k, 0) for k in ("full", "M=1")] + [(k, b) for b in budgets for k in kinds]
    t0 = time.time()
    done = {}

    def run(kind, budget):
        i = len(done) + 1
        print(f"[{i}/{len(runs)}] {kind}, budget {budget / 1e6:g} M ... ", end="", file=sys.stderr, flush=True)
        t = time.time()
        recs = fwm.run_scenario(img, kind, budget)
        print(f"{time.time() - t:.0f} s (elapsed {time.time() - t0:.0f} s)", file=sys.stderr, flush=True)
        done[kind, budget] = recs
        return recs

    plain = {k: run(k, 0) for k in ("full", "M=1")}
    med = {k: float(np.median([r["instructions_instant"] for r in v])) for k, v in plain.items()}
    stage = (med["full"] - med["M=1"]) / (N - 2)
    rows = [summary(disc, sc, plain[k], k, 0, stage, signal) for k in ("full", "M=1")]
    for b in budgets:
        for k in kinds:
            rows.append(summary(disc, sc, run(k, b), k, b, stage, signal))
    print(f"\n{disc.name}: emulated Cortex-M7 (double), {sc['steps']} instants, disturbance at instant "
          f"{sc['event_step']}; one stage evaluation {stage / 1e3:.1f} k instructions "
          f"(full RTI median {med['full'] / 1e6:.3f} M, M = 1 {med['M=1'] / 1e6:.3f} M, no budget)")
    head = (f"{'setting':<9} {'budget':>7} {'largest':>8} {'at':>4} {'over':>8} {'bound':>5} "
            f"{'20 after: max':>13} {'median':>7} {'bound':>5} {'median':>7} {'RMS after':>10} {'failed':>6} {'extra':>5}")
    print(head)
    for r in rows:
        b = r["budget"]
        print(f"{r['setting']:<9} {(f'{b / 1e6:g} M' if b else 'none'):>7} {r['largest'] / 1e6:>7.3f}M "
              f"{r['largest_instant']:>4} "
              f"{_k(r['over']):>8} "
              f"{_yes(r['within_bound']):>5} "
              f"{r['largest_after'] / 1e6:>12.3f}M {r['median_after'] / 1e6:>6.3f}M "
              f"{_yes(r['within_bound_after']):>5} "
              f"{r['median'] / 1e6:>6.3f}M {r['rms_after']:>10.3e} {r['failed']:>6} {r['extra_iterations']:>5}")
    print("\nthe largest feedback (its QP and the step) of each run, the feedback QPs cut by the deadline, the "
          "failed instants (instant: QP iterations, status of the QP; 7 = cut by the deadline)")
    for r in rows:
        b = r["budget"]
        fails = ", ".join(f"{f['step']}: {f['qp_iterations']}/{f['qp_status']}" for f in r["failed_at"][:8])
        more = f" (+{len(r['failed_at']) - 8})" if len(r["failed_at"]) > 8 else ""
        print(f"{r['setting']:<9} {(f'{b / 1e6:g} M' if b else 'none'):>7} feedback {r['feedback_largest'] / 1e6:.3f}M at "
              f"{r['feedback_largest_instant']} ({r['feedback_largest_qp_iterations']} QP iterations), "
              f"cut QPs {r['qp_cut']}, failed: {fails or '-'}{more}")
    out = {"problem": disc.name, "commit": checkout_commit(), "N": N, "steps": sc["steps"], "event_step": sc["event_step"],
           "after": AFTER, "stage": stage, "median_no_budget": med,
           "count_method": "qemu -icount shift=0; an instant: its feedback and prepare on the board's timer",
           "plant": "the model (the generated integrator)", "rows": rows}
    path = pathlib.Path(a.out)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(out, indent=1))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
