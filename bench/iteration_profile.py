"""Instructions of one DOPUS iteration (feedback + prepare), M = 1 against the full RTI, and
where they go: a per-function profile of the closed loop at the operating point on this
machine, with valgrind's callgrind (deterministic counts).

Generates the OCP file's solver folder with the offline guess (IPOPT's solution at the
initial state, as ``dopus-gen bench`` starts its operating point), compiles it as
``dopus-gen build`` does (``-O3``, the strict flags; plus ``-g``, which changes no
instruction) into one program per setting that runs the closed loop on the discrete model
from the nominal start: ``--settle`` steps, then ``--steps`` profiled ones (only the calls of
feedback and prepare of those are counted: ``--toggle-collect`` on two wrappers). Prints the
instructions per step of both settings, their ratio, and per function the instructions per
step (inclusive: the function and what it calls) of the parts that decide the ratio: the QP,
the lm test, the stage functions (CasADi's file), the secants; writes JSON (``--json``).

    .venv/bin/python bench/iteration_profile.py examples/chain.py [--settle 100] [--steps 50]
        [--json bench/results/iteration_profile.json]

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

DRIVER = """#include <stdio.h>
#include <stdlib.h>
#include "{name}_funcs.h"
#include "{name}_problem.h"
#include "{name}_solver.h"
static {name}_solver solver;
static {name}_fun_work plant_work;
/* the profiled calls (callgrind --toggle-collect) */
__attribute__((noinline)) int profiled_feedback(const {name}_real *x, {name}_real *u)
{{
    return {name}_feedback(&solver, x, u);
}}
__attribute__((noinline)) int profiled_prepare(void)
{{
    return {name}_prepare(&solver);
}}
int main(int argc, char **argv)
{{
    {name}_real x[{NAME}_NX], xn[{NAME}_NX], u[{NAME}_NU];
    {name}_settings st;
    {name}_dims d;
    int M = atoi(argv[1]), settle = atoi(argv[2]), steps = atoi(argv[3]), i, k, rc;
    double chk = 0.0;
    {name}_get_dims(&d);
    for (i = 0; i < {NAME}_NX; ++i)
        x[i] = {name}_x0_default[i];
    {name}_settings_default(&st);
    st.M = M < 0 ? d.N - 1 : M;
    rc = {name}_setup(&solver, &st);
    if (rc == 0)
        rc = {name}_init_nominal(&solver, x);
    for (k = 0; rc == 0 && k < settle + steps; ++k) {{
        rc = k < settle ? {name}_feedback(&solver, x, u) : profiled_feedback(x, u);
        if (rc == 0)
            rc = {name}_simulate(x, u, 0, xn, &plant_work);
        for (i = 0; i < {NAME}_NX; ++i)
            x[i] = xn[i];
        if (rc == 0)
            rc = k < settle ? {name}_prepare(&solver) : profiled_prepare();
        for (i = 0; i < {NAME}_NU; ++i)
            chk += u[i] * (k + 1);
    }}
    /* the closed loop's fingerprint: equal digits, equal iterates */
    printf("M %d status %d x0 %.17g u0 %.17g sum %.17g\\n", st.M, rc, (double)x[0], (double)u[0], chk);
    return rc != 0;
}}
"""

#: inclusive parts reported per step (function names without the problem's prefix)
PARTS = ("qp_solve", "lm_convex", "stage_grad_hess_exact", "stage_grad", "stage_hess", "ring_secant",
         "ring_predict", "assemble", "kkt_proxy", "qp_prefactor_guess", "riccati_factor")


def profile(exe: Path, folder: Path, name: str, m: int, settle: int, steps: int) -> dict:
    out = folder / f"cg_{m}.out"
    run = subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={out}",
                          "--toggle-collect=profiled_feedback", "--toggle-collect=profiled_prepare",
                          str(exe), str(m), str(settle), str(steps)], capture_output=True, text=True)
    if run.returncode != 0:
        raise SystemExit(f"iteration_profile: the closed loop with M = {m} failed:\n{run.stdout}{run.stderr[-2000:]}")
    text = subprocess.run(["callgrind_annotate", "--inclusive=yes", "--threshold=100", "--auto=no", str(out)],
                          check=True, capture_output=True, text=True).stdout
    total, parts = 0, {}
    for line in text.splitlines():
        mm = re.match(r"\s*([\d,]+)\s+\(\s*[\d.]+%\)\s+(.*)$", line)
        if not mm:
            continue
        n = int(mm.group(1).replace(",", ""))
        if "PROGRAM TOTALS" in mm.group(2):
            total = n
            continue
        if not mm.group(2).endswith("]"):  # the file:function lines without the object are repeats
            continue
        func = mm.group(2).split(":", 1)[-1].split(" ")[0]
        func = re.sub(rf"^{name}_", "", func).split(".")[0]  # the prefix and GCC's .constprop/.isra
        if func in PARTS:
            parts[func] = max(parts.get(func, 0), n)
    return {"M": m, "fingerprint": run.stdout.strip(), "instructions_per_step": total / steps,
            "parts_per_step": {k: parts[k] / steps for k in PARTS if k in parts}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("ocp_file", nargs="?", default="examples/chain.py")
    ap.add_argument("--settle", type=int, default=100, help="untimed closed-loop steps first (default 100)")
    ap.add_argument("--steps", type=int, default=50, help="profiled steps (default 50)")
    ap.add_argument("--cc", default="gcc")
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args(argv)
    if a.steps < 1 or a.settle < 0:
        ap.error("--steps must be at least 1 and --settle at least 0")
    for tool in (a.cc, "valgrind", "callgrind_annotate"):
        if shutil.which(tool) is None:
            ap.error(f"{tool} is not on PATH (valgrind: apt-get install valgrind)")
    from dopus_codegen.codegen.flags import CASADI_CFLAGS, DEFAULT_OPT, STRICT_CFLAGS
    from dopus_codegen.problem.ocp import load_ocp

    name = load_ocp(a.ocp_file).name
    with tempfile.TemporaryDirectory(prefix="iteration_profile_") as tmp:
        folder = Path(tmp)
        gen = folder / "gen"
        subprocess.run([sys.executable, "-m", "dopus_codegen.cli", "generate", a.ocp_file, "-o", str(gen),
                        "--offline-guess"], check=True, capture_output=True)
        objs = []
        for src, flags in ((f"{name}_solver.c", STRICT_CFLAGS), (f"{name}_problem.c", STRICT_CFLAGS),
                           (f"{name}_casadi.c", CASADI_CFLAGS)):
            obj = folder / (src[:-2] + ".o")
            subprocess.run([a.cc, DEFAULT_OPT, "-g", *flags, "-c", str(gen / src), "-o", str(obj)], check=True)
            objs.append(str(obj))
        drv = folder / "drive.c"
        drv.write_text(DRIVER.format(name=name, NAME=name.upper()))
        exe = folder / "drive"
        subprocess.run([a.cc, DEFAULT_OPT, "-g", "-std=c99", f"-I{gen}", str(drv), *objs, "-lm", "-o", str(exe)],
                       check=True)
        rows = [profile(exe, folder, name, m, a.settle, a.steps) for m in (1, -1)]
    one, full = rows
    ratio = one["instructions_per_step"] / full["instructions_per_step"]
    print(f"{name}: instructions per step (feedback + prepare), closed loop at the operating point, "
          f"steps {a.settle + 1}..{a.settle + a.steps}")
    print(f"{'':>24} {'M = 1':>12} {'full RTI':>12}")
    print(f"{'total':>24} {one['instructions_per_step']:12.0f} {full['instructions_per_step']:12.0f}")
    for k in PARTS:
        if k in one["parts_per_step"] or k in full["parts_per_step"]:
            print(f"{k:>24} {one['parts_per_step'].get(k, 0):12.0f} {full['parts_per_step'].get(k, 0):12.0f}")
    print(f"ratio M = 1 / full RTI: {ratio:.4f}")
    print(f"fingerprints: {one['fingerprint']} | {full['fingerprint']}")
    if a.json:
        a.json.parent.mkdir(parents=True, exist_ok=True)
        a.json.write_text(json.dumps({"ocp_file": str(a.ocp_file), "settle": a.settle, "steps": a.steps,
                                      "settings": rows, "ratio": ratio}, indent=1))
        print(f"JSON: {a.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
