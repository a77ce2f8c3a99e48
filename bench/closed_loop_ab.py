"""A closed loop of the generated robot arm, a git revision's build (``--base``) against the
working tree's: for a change of the runtime that must not alter the method (a
restructuring of runtime_c/), every u0, status, flag and iterate must be bit for bit equal.

Each side runs in its own process with its own package (the revision's tree from
``git archive``): it generates examples/robot_arm.py with its own runtime_c/ and
templates, builds the folder and drives it through the Python handle. The plant is the solver's own
prediction (x_1 of the plan after the feedback), pushed every 37 instants, with a NaN
measurement at instant 150 and a velocity outlier at 220 (the recovery paths); M = 1 and
the full RTI, 300 instants each.

    .venv/bin/python bench/closed_loop_ab.py --base main

Prints one line per configuration (instants, failed instants, bitwise equal or the first
instant that differs) and exits 1 when a configuration differs.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
INSTANTS = 300

CHILD = r"""
import json, sys
import numpy as np
from dopus_codegen.runtime.solver import CSolver
from dopus_codegen.errors import DopusError

folder, instants = sys.argv[1], int(sys.argv[2])
out = {}
for M in ("1", "full"):
    s = CSolver(lib_dir=folder)
    s.set_M(s.N - 1 if M == "full" else int(M))
    x = np.array(s.x[0], dtype=float)
    s.init(x)
    x = np.array(s.x[0], dtype=float)
    rows = []
    for k in range(instants):
        xm = x.copy()
        if k == 150:
            xm[:] = np.nan
        if k == 220:
            xm[-1] += 1e4
        try:
            u0 = s.feedback(xm)
            fb = 0
        except DopusError as e:
            u0, fb = np.array(s.u0, dtype=float), e.status
        flags = sorted(s.flags)
        x = np.array(s.x[1], dtype=float)
        if k % 37 == 5:
            x = x + 0.05 * np.cos(np.arange(x.size) + k)
        try:
            s.prepare()
            pr = 0
        except DopusError as e:
            pr = e.status
        rows.append([k, fb, pr, flags, np.asarray(u0, dtype=float).tobytes().hex(),
                     np.asarray(s.x, dtype=float).tobytes().hex(), np.asarray(s.u, dtype=float).tobytes().hex(),
                     np.asarray(s.lam, dtype=float).tobytes().hex()])
    out[M] = rows
json.dump(out, sys.stdout)
"""


def run_side(tree: Path, work: Path) -> dict:
    folder = work / "robot_arm"
    env = dict(os.environ, PYTHONPATH=str(tree))
    gen = subprocess.run([sys.executable, "-c", "from dopus_codegen.cli import main; main()", "generate",
                          str(tree / "examples" / "robot_arm.py"), "-o", str(folder)], capture_output=True,
                         text=True, env=env, cwd=str(work))
    if gen.returncode != 0:
        raise SystemExit(f"closed_loop_ab: generating in {tree} failed:\n{gen.stdout[-2000:]}{gen.stderr[-2000:]}")
    proc = subprocess.run([sys.executable, "-c", CHILD, str(folder), str(INSTANTS)], capture_output=True,
                          text=True, env=env, cwd=str(work))
    if proc.returncode != 0:
        raise SystemExit(f"closed_loop_ab: the run in {tree} failed:\n{proc.stderr[-3000:]}")
    return json.loads(proc.stdout)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--base", default="main", help="git revision to compare with (default main)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="closed_loop_ab_") as tmp:
        tmp = Path(tmp)
        base = tmp / "base"
        base.mkdir()
        archive = subprocess.run(["git", "archive", args.base], cwd=str(ROOT), capture_output=True, check=True)
        subprocess.run(["tar", "-x", "-C", str(base)], input=archive.stdout, check=True)
        (tmp / "wa").mkdir()
        (tmp / "wb").mkdir()
        a, b = run_side(base, tmp / "wa"), run_side(ROOT, tmp / "wb")
    differ = 0
    for M in a:
        ra, rb = a[M], b[M]
        first = next((k for k, (x, y) in enumerate(zip(ra, rb)) if x != y), None)
        failed = sum(1 for r in rb if r[1] != 0 or r[2] != 0)
        digest = hashlib.sha256(json.dumps(rb).encode()).hexdigest()[:16]
        if first is None and len(ra) == len(rb):
            print(f"M = {M:>4}: {len(rb)} instants, {failed} with a failed call, bitwise equal to {args.base} "
                  f"(sha256 {digest})")
        else:
            differ += 1
            print(f"M = {M:>4}: differs from {args.base} at instant {first}: {ra[first][:4]} vs {rb[first][:4]}")
    return 1 if differ else 0


if __name__ == "__main__":
    sys.exit(main())
