"""Barely infeasible QPs: how the C QP solver and the reference backend report QPs that are
infeasible by a small relative margin.

QPs: tests/harness/qp_problems.py's ``make_infeasible`` with ``margin`` (a general row's
range misses a control's box, a terminal equality's value misses the box of x_N, or a
state's bound lies beyond the reachable set, by that relative margin), 60 per kind and
margin (1e-9 .. 1e-5), at tolerance 1e-10. Per cell: the C solver's statuses, and for the
first ``--ref`` QPs the status of the reference QP solver (IPOPT, with the Farkas LP of
its failure diagnosis). Prints a table and writes bench/results/qp_margins.json.

    .venv/bin/python bench/qp_margins.py            # about 2 minutes
    .venv/bin/python bench/qp_margins.py --ref 0    # the C solver only
"""
from __future__ import annotations

import argparse
import collections
import json
import sys
import zlib
from pathlib import Path

import numpy as np

BENCH = Path(__file__).resolve().parent
ROOT = BENCH.parent
sys.path.insert(0, str(ROOT / "tests"))

from harness import qp_problems as P  # noqa: E402
from harness.qp_harness import build_qp_solver  # noqa: E402

CASES = [
    ("row_vs_box", (10, 4, 2, 1, 2, 1)),
    ("row_vs_box", (40, 5, 3, 2, 0, 2)),
    ("terminal_eq_vs_box", (10, 4, 2, 1, 2, 1)),
    ("unreachable", (6, 3, 2, 0, 0, 0)),
    ("unreachable", (20, 4, 2, 1, 1, 1)),
]
MARGINS = [1e-9, 1e-8, 1e-7, 1e-6, 1e-5]
KEYS = ("N", "nx", "nu", "ng", "nr", "ne")


def reference_status(qp) -> str:
    from dopus_codegen.reference.qp import QPError, solve_qp_reference

    try:
        solve_qp_reference(qp, tol=1e-10)
    except QPError as exc:
        return exc.qp_status
    return "solved"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--count", type=int, default=60, help="QPs per kind and margin (default 60)")
    ap.add_argument("--ref", type=int, default=12, help="of which solved by the reference too (default 12)")
    ap.add_argument("--json", default=str(BENCH / "results" / "qp_margins.json"))
    ap.add_argument("--dump", metavar="DIR", help="write each QP that a backend does not report primal infeasible "
                    "to DIR/<kind>_<margin>_<trial>.npz (the QP dict's arrays and sizes)")
    args = ap.parse_args(argv)
    rows = []
    print(f"{'kind':20s} {'sizes':18s} {'margin':>7s}  C solver (of {args.count})"
          f"{'':22s} reference (of {min(args.ref, args.count)})")
    for kind, sizes in CASES:
        h = build_qp_solver(*sizes)
        for margin in MARGINS:
            rng = np.random.default_rng(zlib.crc32(kind.encode()) + 9)
            c_status, r_status = collections.Counter(), collections.Counter()
            for trial in range(args.count):
                qp = P.make_infeasible(rng, *sizes, kind, margin=margin)
                qp.update(zip(KEYS, sizes))
                _, info = h.solve(qp, tol=1e-10)
                c_status[info["status"]] += 1
                ref = reference_status(qp) if trial < args.ref else None
                if ref is not None:
                    r_status[ref] += 1
                if args.dump and {info["status"], ref or "primal_infeasible"} != {"primal_infeasible"}:
                    dump = Path(args.dump)
                    dump.mkdir(parents=True, exist_ok=True)
                    np.savez(dump / f"{kind}_{margin:.0e}_{trial}.npz", c_status=info["status"],
                             reference_status=str(ref), **qp)
            rows.append({"kind": kind, "sizes": list(sizes), "margin": margin, "c": dict(c_status),
                         "reference": dict(r_status)})
            fmt = lambda cnt: ", ".join(f"{k} {v}" for k, v in sorted(cnt.items()))  # noqa: E731
            print(f"{kind:20s} {str(sizes):18s} {margin:7.0e}  {fmt(c_status):45s} {fmt(r_status)}", flush=True)
    total = sum(r["c"].get("primal_infeasible", 0) for r in rows)
    print(f"C solver: {total} of {args.count * len(rows)} reported primal infeasible")
    if args.ref > 0:
        total_ref = sum(r["reference"].get("primal_infeasible", 0) for r in rows)
        print(f"reference: {total_ref} of {sum(sum(r['reference'].values()) for r in rows)} reported primal infeasible")
    out = Path(args.json)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps({"tol": 1e-10, "count": args.count, "rows": rows}, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
