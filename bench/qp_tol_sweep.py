"""Closed-loop quality against the QP tolerance: the basis of the default ``qp_tol``.

    python bench/qp_tol_sweep.py [OCP_FILE ...] [--tol 1e-4,1e-5,...,1e-10] [--M 1,full]
                                 [--backend c|python] [--json OUT]

For every OCP file (default: the robot arm, the chain of masses and the stiff motor) and
every QP tolerance, the generated C solver (or the Python reference) runs the scenario of
``dopus-gen sil`` against the CVODES plant, from IPOPT's solution at the initial state, with
the OCP file's settings and only ``qp_tol`` changed. Per run: failed instants, the tracking
of the scenario's first scalar signal (RMS and max over the run, and their ratios to the
strictest tolerance of the sweep), the KKT measure after settling (max, and median over the
settled instants), the QP iterations per instant (median, 99th percentile, max; one
factorisation of the stage blocks per QP iteration) and the cold retries. Tracking and
failures do not depend on the machine; the iteration counts neither. Times are not
reported (see ``dopus-gen bench``).
"""
from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from dopus_codegen import build_functions, load_ocp, settings
from dopus_codegen.reference.offline import solve_ocp
from dopus_codegen.studies.sil import run_closed_loop, summarize

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_FILES = [ROOT / "examples" / f for f in ("robot_arm.py", "chain.py", "stiff_motor.py")]
DEFAULT_TOLS = "1e-4,1e-5,1e-6,1e-7,1e-8,1e-9,1e-10"


def _signal(run) -> tuple:
    for name, vals in run["signals"].items():
        v = np.asarray([np.nan if a is None else a for a in vals], dtype=float)
        if v.ndim == 1:
            return name, v
    raise SystemExit("the scenario has no scalar signal to measure the tracking with")


def sweep_file(ocp_file, tols, m_list, backend="c", echo=print) -> list:
    ocp = load_ocp(ocp_file)
    base, _sources = settings.Settings.resolve(ocp.declared_options(), {})
    disc = build_functions(ocp)
    guess, info = solve_ocp(disc, disc.x0)
    if not info.get("success", False):
        raise SystemExit(f"{disc.name}: IPOPT did not solve the OCP at its initial state")
    rows = []
    for m in m_list:
        M = settings.stages(m, disc.N)
        for tol in tols:
            run = run_closed_loop(disc, backend=backend, settings=base.replace(M=M, qp_tol=tol), guess=guess)
            s = summarize(run)
            name, v = _signal(run)
            it = np.asarray(run["qp_iterations"], dtype=float)
            t = np.asarray(run["t"], dtype=float)
            kkt = np.asarray([np.nan if a is None else a for a in run["kkt"]], dtype=float)
            settled = t >= s["settle"]
            for ev in run["events"]:
                settled &= ~((t >= ev["time"]) & (t < ev["time"] + s["settle"]))
            ks = kkt[settled & np.isfinite(kkt)]
            row = {"problem": disc.name, "M": M, "full": M == disc.N - 1, "qp_tol": tol,
                   "failed": s["qp_failures"], "aborted": s["aborted"], "signal": name,
                   "rms": float(np.sqrt(np.nanmean(v ** 2))), "max": float(np.nanmax(np.abs(v))),
                   "kkt_max_settled": s["kkt_max_settled"],
                   "kkt_median_settled": float(np.median(ks)) if ks.size else math.nan,
                   "qp_it_median": float(np.median(it)) if it.size else math.nan,
                   "qp_it_p99": float(np.percentile(it, 99)) if it.size else math.nan,
                   "qp_it_max": int(it.max()) if it.size else 0,
                   "qp_it_mean": float(it.mean()) if it.size else math.nan,
                   "cold_retries": int(sum(bool(c) for c in run["qp_cold_retry"])),
                   "instants": len(run["status"])}
            rows.append(row)
            echo(f"{disc.name:>12} M={'full' if row['full'] else M:<5} tol {tol:7.0e}  failed {row['failed']:3d}  "
                 f"RMS {row['rms']:.5e}  max {row['max']:.5e}  KKT settled max {row['kkt_max_settled']:.1e} "
                 f"median {row['kkt_median_settled']:.1e}  QP it median {row['qp_it_median']:.0f} "
                 f"p99 {row['qp_it_p99']:.0f} max {row['qp_it_max']}  cold retries {row['cold_retries']}")
    for m in {r["M"] for r in rows}:
        same = [r for r in rows if r["M"] == m]
        strict = min(same, key=lambda r: r["qp_tol"])
        for r in same:
            r["rms_ratio"] = r["rms"] / strict["rms"] if strict["rms"] > 0 else math.nan
            r["max_ratio"] = r["max"] / strict["max"] if strict["max"] > 0 else math.nan
    return rows


def format_markdown(rows) -> str:
    lines = ["| problem | M | qp_tol | failed | RMS (/ strictest) | max (/ strictest) | KKT settled max / median "
             "| QP it median / p99 / max |",
             "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['problem']} | {'full' if r['full'] else r['M']} | {r['qp_tol']:.0e} | {r['failed']} | "
                     f"{r['rms']:.4e} ({r['rms_ratio']:.4f}) | {r['max']:.4e} ({r['max_ratio']:.4f}) | "
                     f"{r['kkt_max_settled']:.1e} / {r['kkt_median_settled']:.1e} | "
                     f"{r['qp_it_median']:.0f} / {r['qp_it_p99']:.0f} / {r['qp_it_max']} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("ocp_files", nargs="*", type=Path)
    ap.add_argument("--tol", default=DEFAULT_TOLS, help="comma-separated QP tolerances")
    ap.add_argument("--M", default="1", help="comma-separated values of M ('full': the full RTI)")
    ap.add_argument("--backend", default="c", choices=("c", "python"))
    ap.add_argument("--json", type=Path, default=ROOT / "bench" / "results" / "qp_tol_sweep.json")
    a = ap.parse_args(argv)
    tols = [settings.qp_tolerance(float(v)) for v in a.tol.split(",")]
    m_list = settings.parse_m_list(a.M)
    rows = []
    for f in a.ocp_files or DEFAULT_FILES:
        rows += sweep_file(f, tols, m_list, backend=a.backend)
    print(format_markdown(rows))
    a.json.parent.mkdir(parents=True, exist_ok=True)
    a.json.write_text(json.dumps({"tols": tols, "rows": rows}, indent=1, default=float))
    print(f"wrote {a.json}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
