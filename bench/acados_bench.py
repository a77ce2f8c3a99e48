"""Time per iteration of our generated solver against acados on the same OCP file.

    .venv/bin/python bench/acados_bench.py [OCP_FILE] [--json OUT] [--quick] [--cond 40,20,10,8,5,4,2] [--block 1]

The same as ``dopus-gen bench OCP_FILE --M 1,full --against acados`` (the work lives in
``dopus_lab/bench.py``, which prepares in the project's environment, and
``dopus_lab/timing.py``, the timing process that loads only the compiled
libraries, never CasADi). docs/acados.md describes the translation, the screening of
acados' settings and the timing process.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("ocp_file", nargs="?", default=str(ROOT / "examples" / "robot_arm.py"))
    ap.add_argument("--json", default=str(ROOT / "bench" / "results" / "acados_bench.json"))
    ap.add_argument("--work", default=str(ROOT / "build" / "acados"))
    ap.add_argument("--quick", action="store_true", help="fewer settings and repetitions (a smoke run)")
    ap.add_argument("--cond", default="40,20,10,8,5,4,2", help="partial-condensing horizons to search")
    ap.add_argument("--block", type=int, default=1, help="the timed settings alternate every BLOCK steps")
    ap.add_argument("--opt", default=None, help="compile flags of our library (default: the generated default)")
    a = ap.parse_args(argv)
    sys.path.insert(0, str(ROOT))
    from dopus_codegen.cli import main as cli

    args = ["bench", a.ocp_file, "--M", "1,full", "--against", "acados", "--json", a.json, "--work", a.work,
            "--cond", a.cond, "--block", str(a.block)] + (["--opt", a.opt] if a.opt else [])
    if a.quick:
        args += ["--quick", "--reps", "100", "--steps", "100", "--settle", "50"]
    return cli.main(args, prog_name="dopus-gen", standalone_mode=True)


if __name__ == "__main__":
    sys.exit(main())
