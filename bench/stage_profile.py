"""Instructions per call of the generated stage functions, and where they go.

Generates the OCP file's solver folder, compiles its CasADi file as ``dopus-gen build`` does
(``-O3``, plus ``-g``, which changes no instruction) with a small driver that calls one
stage function ``--calls`` times on the OCP's initial guess (stage 0's x and u, the default
parameters, 0.1 in every multiplier), and counts the instructions inside that function
with valgrind's callgrind (``--toggle-collect``: the function and what it calls). Prints,
per function, the instructions per call, the share of CasADi's QR linear solver
(``casadi_qr``, ``casadi_house``, ``casadi_qr_mv``, ``casadi_qr_trs``, ``casadi_qr_solve``:
the Newton steps and the implicit function theorem of an implicit integrator) and the
functions that dominate; writes JSON (``--json``).

    .venv/bin/python bench/stage_profile.py examples/stiff_motor.py [--functions stage_grad,stage_hess_gn]
        [--calls 2000] [--json bench/results/stage_profile.json]

Needs gcc and valgrind (``apt-get install valgrind``).
"""
from __future__ import annotations

import argparse
import json
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

QR_PARTS = ("casadi_qr", "casadi_house", "casadi_qr_mv", "casadi_qr_trs", "casadi_qr_solve", "casadi_qr_colcomb")


def signatures(casadi_c: str, name: str) -> dict:
    """``{function: [(input name, size), ...]}`` from CasADi's comment line per function."""
    out = {}
    for m in re.finditer(rf"^/\* {name}_(\w+):\((.*?)\)->", casadi_c, re.M):
        ins = []
        for part in m.group(2).split(","):
            mm = re.match(r"(\w+)(?:\[(\d+)(?:x(\d+))?(?:,\d+nz)?\])?$", part.strip())
            if mm is None:
                raise SystemExit(f"stage_profile: cannot read the inputs of {m.group(1)}: {m.group(2)}")
            rows, cols = int(mm.group(2) or 1), int(mm.group(3) or 1)
            ins.append((mm.group(1), rows * cols))
        out[m.group(1)] = ins
    return out


def input_values(disc, ins) -> list:
    x = np.asarray(disc.initial_guess.x[0], dtype=float).reshape(-1)
    u = np.asarray(disc.initial_guess.u[0], dtype=float).reshape(-1)
    p = np.asarray(disc.p_default, dtype=float).reshape(-1)
    vals = []
    for nm, size in ins:
        v = {"x": x, "u": u, "p": p}.get(nm, np.full(size, 0.1))
        if v.size != size:
            raise SystemExit(f"stage_profile: input {nm} has {size} entries, the guess {v.size}")
        vals.append(v)
    return vals


DRIVER = """#include <stdio.h>
typedef double casadi_real;
typedef int casadi_int; /* the generated code's (#define casadi_int int) */
int {sym}(const casadi_real **arg, casadi_real **res, casadi_int *iw, casadi_real *w, int mem);
int {sym}_work(casadi_int *sz_arg, casadi_int *sz_res, casadi_int *sz_iw, casadi_int *sz_w);
{inputs}
static casadi_real w[1 << 16], out[1 << 14];
static casadi_int iw[1 << 12];
int main(void)
{{
    const casadi_real *arg[64] = {{{args}}};
    casadi_real *res[64];
    casadi_int n_arg, n_res, n_iw, n_w, k;
    double acc = 0.0;
    {sym}_work(&n_arg, &n_res, &n_iw, &n_w);
    if (n_w > (1 << 16) || n_iw > (1 << 12) || n_arg > 64 || n_res > 64) return 2;
    for (k = 0; k < 64; ++k) res[k] = out + 256 * k;
    for (k = 0; k < {calls}; ++k) {{
        {sym}(arg, res, iw, w, 0);
        acc += out[0];
    }}
    printf("%.17g\\n", acc);
    return 0;
}}
"""


def profile(folder: Path, name: str, fn: str, vals: list, calls: int, cc: str) -> dict:
    sym = f"{name}_{fn}"
    inputs = "\n".join(f"static const casadi_real in{i}[{max(v.size, 1)}] = {{"
                       + (", ".join(repr(float(a)) for a in v) or "0.0") + "};" for i, v in enumerate(vals))
    args = ", ".join(f"in{i}" for i in range(len(vals)))
    src = folder / f"drive_{fn}.c"
    src.write_text(DRIVER.format(sym=sym, inputs=inputs, args=args, calls=calls))
    exe = folder / f"drive_{fn}"
    subprocess.run([cc, "-O3", "-g", "-std=c99", str(src), str(folder / "casadi.o"), "-lm", "-o", str(exe)],
                   check=True)
    out = folder / f"cg_{fn}.out"
    run = subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}", f"--toggle-collect={sym}",
                          str(exe)], capture_output=True, text=True)
    if run.returncode != 0:
        raise SystemExit(f"stage_profile: the driver of {fn} failed (exit {run.returncode}; 2: its work arrays "
                         f"exceed the driver's):\n{run.stderr[-2000:]}")
    text = subprocess.run(["callgrind_annotate", "--threshold=100", "--auto=no", str(out)], check=True, capture_output=True,
                          text=True).stdout
    total, parts = 0, {}
    for line in text.splitlines():
        m = re.match(r"\s*([\d,]+)\s+\(\s*[\d.]+%\)\s+(.*)$", line)
        if not m:
            continue
        n = int(m.group(1).replace(",", ""))
        if "PROGRAM TOTALS" in m.group(2):
            total = n
            continue
        func = m.group(2).split(":", 1)[-1].split(" ")[0]
        func = re.sub(rf"^{name}_", "", func).split(".")[0]      # the prefix and GCC's .constprop/.isra
        parts[func] = parts.get(func, 0) + n
    per_call = {k: v / calls for k, v in sorted(parts.items(), key=lambda kv: -kv[1])}
    qr = sum(v for k, v in per_call.items() if k in QR_PARTS)
    return {"function": fn, "instructions_per_call": total / calls, "qr_per_call": qr,
            "qr_share": qr / (total / calls) if total else float("nan"), "self_per_call": per_call}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("ocp_file", nargs="?", default="examples/stiff_motor.py")
    ap.add_argument("--functions", default=None,
                    help="comma-separated stage functions (without the problem's prefix); default: every "
                         "stage_* function of the folder")
    ap.add_argument("--calls", type=int, default=2000, help="calls per function (default 2000)")
    ap.add_argument("--cc", default="gcc")
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args(argv)
    if a.calls < 1:
        ap.error("--calls must be at least 1")
    for tool in (a.cc, "valgrind", "callgrind_annotate"):
        if shutil.which(tool) is None:
            ap.error(f"{tool} is not on PATH (valgrind: apt-get install valgrind)")
    from dopus_codegen.codegen.flags import CASADI_CFLAGS, DEFAULT_OPT
    from dopus_codegen.problem.derivatives import build_functions
    from dopus_codegen.problem.ocp import load_ocp

    disc = build_functions(load_ocp(a.ocp_file))
    name = disc.name
    with tempfile.TemporaryDirectory(prefix="stage_profile_") as tmp:
        folder = Path(tmp)
        subprocess.run([sys.executable, "-m", "dopus_codegen.cli", "generate", a.ocp_file, "-o", str(folder / "gen")],
                       check=True, capture_output=True)
        casadi_c = folder / "gen" / f"{name}_casadi.c"
        # compiled as dopus-gen build compiles it, plus -g
        subprocess.run([a.cc, DEFAULT_OPT, "-g", *CASADI_CFLAGS, "-c", str(casadi_c), "-o", str(folder / "casadi.o")],
                       check=True)
        sigs = signatures(casadi_c.read_text(), name)
        fns = a.functions.split(",") if a.functions else [f for f in sigs if f.startswith("stage_")]
        unknown = [f for f in fns if f not in sigs]
        if unknown:
            ap.error(f"no such function in {name}_casadi.c: {', '.join(unknown)} (there are: {', '.join(sigs)})")
        rows = []
        for fn in fns:
            rows.append(profile(folder, name, fn, input_values(disc, sigs[fn]), a.calls, a.cc))
            r = rows[-1]
            print(f"{fn:>28}: {r['instructions_per_call']:9.0f} instructions per call, CasADi's QR "
                  f"{r['qr_per_call']:8.0f} ({100 * r['qr_share']:4.1f} %)", flush=True)
    print()
    for r in rows:
        top = list(r["self_per_call"].items())[:6]
        print(f"{r['function']}: " + ", ".join(f"{k} {v:.0f}" for k, v in top))
    if a.json:
        a.json.parent.mkdir(parents=True, exist_ok=True)
        a.json.write_text(json.dumps({"ocp_file": str(a.ocp_file), "calls": a.calls, "functions": rows}, indent=1))
        print(f"JSON: {a.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
