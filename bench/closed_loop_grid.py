"""Closed loop of an OCP file's scenario over a grid of horizons N and values of M.

    python bench/closed_loop_grid.py OCP_FILE [--N 20,40,80,160] [--M 1,2,5,full]
                                     [--lm auto|VALUE] [--hessian exact|gauss-newton]
                                     [--signal NAME] [--json OUT]

For every N (default: the file's own; the file is re-horizoned with ``horizon(N, dt)`` at
its interval) the generated C solver runs the scenario of ``dopus-gen sil`` against the
CVODES plant, started from IPOPT's solution at the initial state, once per M, with the
settings of the OCP file (the flags override them). The table gives per run the failed
instants, the largest control-bound violation, the RMS of the scenario's first scalar
signal over the run (the tracking measure), its ratio to the full RTI of the same N, and the
number of instants each bounded state or control sat at a bound (the active constraints).
Exits with 1 when a run failed an instant or was aborted.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from dopus_codegen import build_functions, load_ocp, settings
from dopus_codegen.reference.offline import solve_ocp
from dopus_codegen.settings import parse_m_list
from dopus_codegen.studies.sil import run_closed_loop, summarize


def tracking_rms(run: dict, signal=None) -> tuple:
    """(signal, RMS over the whole run) of the named scalar signal of the scenario (default:
    its first scalar signal)."""
    for name, vals in run["signals"].items():
        v = np.asarray([np.nan if a is None else a for a in vals], dtype=float)
        if v.ndim == 1 and signal in (None, name):
            return name, float(np.sqrt(np.nanmean(v ** 2)))
    raise SystemExit(f"the scenario has no scalar signal {signal or ''} to measure the tracking with")


def at_bounds(disc, run, tol=1e-6) -> dict:
    """Instants at which each bounded state (measured) or control (applied) lies within tol
    of one of its bounds: the constraints that became active in the closed loop."""
    out = {}
    for kind, vals, lb, ub in (("x", run["x"], disc.lbx, disc.ubx), ("u", run["u"], disc.lbu, disc.ubu)):
        v = np.asarray(vals, dtype=float)
        lb, ub = np.asarray(lb, float), np.asarray(ub, float)
        for i in range(v.shape[1]):
            n = int(np.count_nonzero((v[:, i] <= lb[i] + tol) | (v[:, i] >= ub[i] - tol)))
            if n:
                out[f"{kind}[{i}]"] = n
    return out


def run_grid(ocp_file, n_list=None, m_list=("1", "2", "5", "full"), cli=None, signal=None,
             echo=print) -> dict:
    results = []
    base = load_ocp(ocp_file)
    hz = base.validate().horizon
    for N in (n_list or [hz.N]):
        ocp = load_ocp(ocp_file)
        ocp.horizon(N=N, dt=hz.dt)
        ocp.name = f"{ocp.name}_N{N}" if N != hz.N else ocp.name
        base_settings, sources = settings.Settings.resolve(ocp.declared_options(), cli or {})
        values = base_settings.as_dict()
        disc = build_functions(ocp)
        guess, info = solve_ocp(disc, disc.x0)
        if not info.get("success", False):
            raise SystemExit(f"{disc.name}: IPOPT did not solve the OCP at its initial state")
        rows = []
        for m in m_list:
            M = settings.stages(m if m == "full" else int(m), N)
            run = run_closed_loop(disc, backend="c", settings=base_settings.replace(M=M), guess=guess)
            s = summarize(run)
            signal, rms = tracking_rms(run, signal)
            rows.append({"N": N, "M": M, "full": M == N - 1, "failed": s["qp_failures"],
                         "aborted": s["aborted"], "bound_violation": s["bound_violation"],
                         "signal": signal, "rms": rms, "at_bounds": at_bounds(disc, run)})
        full = next(r["rms"] for r in rows if r["full"])
        for r in rows:
            r["ratio_to_full"] = r["rms"] / full if full > 0 else float("nan")
            results.append(r)
            echo(f"{disc.name:>16} N={N:<4d} M={'full' if r['full'] else r['M']:<5} failed {r['failed']:4d}  "
                 f"bound violation {r['bound_violation']:.1e}  RMS {r['signal']} {r['rms']:.4e}  "
                 f"/ full {r['ratio_to_full']:.3f}  at bounds {r['at_bounds']}")
    return {"ocp_file": str(ocp_file), "settings": {k: v for k, v in values.items()},
            "sources": sources, "runs": results}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("ocp_file", type=Path)
    ap.add_argument("--N", default=None, help="comma-separated horizons (default: the file's)")
    ap.add_argument("--M", default="1,2,5,full")
    ap.add_argument("--lm", default=None)
    ap.add_argument("--hessian", default=None)
    ap.add_argument("--signal", default=None, help="the scalar signal of the tracking measure "
                    "(default: the scenario's first)")
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args(argv)
    n_list = [int(v) for v in a.N.split(",")] if a.N else None
    res = run_grid(a.ocp_file, n_list, parse_m_list(a.M), cli={"lm": a.lm, "hessian": a.hessian},
                   signal=a.signal)
    if a.json:
        a.json.parent.mkdir(parents=True, exist_ok=True)
        a.json.write_text(json.dumps(res, indent=1, default=float))
    bad = [r for r in res["runs"] if r["failed"] or r["aborted"]]
    worst = max((r["ratio_to_full"] for r in res["runs"] if r["M"] == 1), default=np.nan)
    print(f"failed runs {len(bad)}; largest RMS ratio of M = 1 to the full RTI {worst:.3f}")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
