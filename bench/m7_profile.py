"""Where the instructions of one closed-loop instant go on an emulated Cortex-M: a
per-function profile of the firmware program (``dopus-gen firmware-report``'s) under QEMU.

The program is built as the report builds it (the target's flags, ``-O3``) plus ``-g`` (debug
information changes no instruction) and with the study cut to one M = 1 iteration and no
budgeted loops (``FW_BUDGETS=0.0``): the closed loop after the disturbance and the steady
closed loop at the operating point run as in the report, each from its own fresh start, so
their instants are the report's instruction for instruction. A first run (no log) gives the
instants' instruction counts and picks the instants to profile:

- ``op``: the median instant of the steady closed loop (default x0), the report's
  "operating point" figure (the lower middle one of an even count);
- ``worst``: the largest of the instants of the closed loop after the disturbance;
- ``steady:K`` / ``loop:K``: instant K (1-based) of either loop.

A second run logs every executed translation block (QEMU ``-d in_asm,exec,nochain``,
``-icount shift=0``: one instruction = 1 ns, deterministic); an instant is the stretch from
the entry of ``<name>_feedback`` to the program's ``fw_stack_lowest`` after ``prepare``
(the timer readings between are the program's, a few instructions). Each block's
instructions go

- to the ELF function it lies in (``self``) and to every function on the call stack
  rebuilt from the blocks (``incl``: a block at a function's entry is a call, a block in a
  function further down the stack a return; the runtime has no recursion), with the calls
  counted;
- instruction by instruction to the source function of its address (``source``: the
  innermost function of ``arm-none-eabi-addr2line -i``, so code inlined into a caller counts
  for the inlined function), and to its source file.

The instant's total is checked against the program's own count (the board's timer, 40
instructions per tick). Prints the tables, writes JSON (``--json``).

    .venv/bin/python bench/m7_profile.py [examples/robot_arm.py] [--instants op,worst]
        [--target m7-double] [--top 30] [--json bench/results/m7_profile.json]
"""
from __future__ import annotations

import argparse
import bisect
import json
import os
import pathlib
import re
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from dopus_lab.paths import checkout_commit  # noqa: E402

LIBM = "(libc/libm)"


def build(ocp_file, out_dir, target, progress):
    """Generate the folder and build the profiled program; returns (elf, name, header)."""
    from dopus_codegen.codegen import generate as codegen
    from dopus_codegen.problem.derivatives import build_functions
    from dopus_codegen.problem.ocp import load_ocp
    from dopus_lab import firmware as fwm

    import numpy as np

    disc = build_functions(load_ocp(ocp_file))
    if disc.disturbance is None:
        raise SystemExit(f"m7_profile: {disc.name} has no disturbance map (ocp.disturbance), the report's loop needs one")
    x0 = np.array(disc.x0, dtype=float)
    xhat_fixed = np.array(disc.disturbance(x0.copy()), dtype=float).reshape(-1)
    real = fwm.TARGETS[target].real
    gen = out_dir / f"generated_{real}"
    progress(f"m7_profile: generating {disc.name} ({real}) into {gen}")
    codegen.generate(disc, gen, offline_guess=True, real=real)
    bdir = out_dir / f"build_{real}"
    # the report's loops (20 steps each), the study cut to one M = 1 iteration
    fwm.write_problem_header(bdir, disc.name, xhat_fixed, [1], 1, 20)
    progress(f"m7_profile: building {target} with -g")
    b = fwm.build_target(gen, bdir, target, extra_cflags=("-g", "-DFW_BUDGETS=0.0"))
    return pathlib.Path(b["elf"]), disc.name, b


def qemu_cmd(elf, target, log=None):
    from dopus_lab import firmware as fwm

    tg = fwm.TARGETS[target]
    cmd = ["qemu-system-arm", "-M", tg.machine, "-nographic", "-monitor", "none", "-serial", "none",
           "-semihosting-config", "enable=on,target=native", "-icount", "shift=0", "-kernel", str(elf)]
    if log is not None:
        cmd += ["-d", "in_asm,exec,nochain", "-D", str(log)]
    return cmd


def functions(elf):
    """Sorted (start, end, name) of the image's functions."""
    out = subprocess.run(["arm-none-eabi-nm", "-n", "-S", "--defined-only", str(elf)], capture_output=True,
                         text=True, check=True).stdout
    fns = []
    for line in out.splitlines():
        p = line.split()
        if len(p) == 4 and p[2] in "TtWw":
            a = int(p[0], 16) & ~1
            fns.append((a, a + int(p[1], 16), p[3]))
    fns.sort()
    return fns


def pick_instants(run, sel):
    """The instants to profile: list of (label, feedback call index, counted instructions)."""
    per_tick = run["header"]["instructions_per_tick"]
    n_study = sum(1 for recs in run["fixed"].values() for r in recs if r["iter"] > 0)
    loops = {"loop": run["loop"], "steady": run["steady"]}
    start = {"loop": n_study, "steady": n_study + len(run["loop"])}

    def count(r):
        return (r["ticks_feedback"] + r["ticks_prepare"]) * per_tick

    picked = []
    for s in sel:
        if s == "op":
            ins = [count(r) for r in loops["steady"]]
            med = statistics.median_low(ins)
            kind, k = "steady", ins.index(med)
        elif s == "worst":
            ins = [count(r) for r in loops["loop"]]
            kind, k = "loop", ins.index(max(ins))
        elif ":" in s and s.split(":", 1)[0] in loops and s.split(":", 1)[1].isdigit():
            kind, kk = s.split(":", 1)
            k = int(kk) - 1
            if not 0 <= k < len(loops[kind]):
                raise SystemExit(f"m7_profile: --instants {s}: the {kind} loop has {len(loops[kind])} instants")
        else:
            raise SystemExit(f"m7_profile: --instants: unknown {s!r} (op, worst, steady:K, loop:K)")
        r = loops[kind][k]
        picked.append({"label": s, "loop": kind, "step": k + 1, "call": start[kind] + k, "counted": count(r),
                       "factorizations": r.get("factorizations"), "qp_iters": r["qp_iters"],
                       "phases": r.get("phases")})
    return picked


class Profile:
    """The per-instant accumulation over the block trace."""

    def __init__(self, fns, name, wanted):
        self.starts = [f[0] for f in fns]
        self.fns = fns
        self.entry_of = {f[0]: i for i, f in enumerate(fns)}
        idx = {f[2]: i for i, f in enumerate(fns)}
        for need in (f"{name}_feedback", "fw_stack_lowest"):
            if need not in idx:
                raise SystemExit(f"m7_profile: the image has no function {need}")
        self.fb_pc = fns[idx[f"{name}_feedback"]][0]
        self.end_pc = fns[idx["fw_stack_lowest"]][0]
        self.wanted = {w["call"]: w for w in wanted}
        self.tb = {}            # pc -> instruction addresses (last translation)
        self.info = {}          # pc -> (n, fn index, is entry)
        self.calls = -1
        self.cur = None         # the instant being profiled
        self.results = {}

    def fn_of(self, a):
        i = bisect.bisect_right(self.starts, a) - 1
        if i >= 0 and a < max(self.fns[i][1], self.fns[i][0] + 2):
            return i
        return -1

    def block_info(self, pc):
        inf = self.info.get(pc)
        if inf is None:
            addrs = self.tb.get(pc, [pc])
            inf = (len(addrs), self.fn_of(pc), pc in self.entry_of)
            self.info[pc] = inf
        return inf

    def begin(self, w):
        self.cur = {"w": w, "total": 0, "self": Counter(), "incl": Counter(), "ncalls": Counter(),
                    "blocks": Counter(), "stack": []}

    def end(self):
        c = self.cur
        self.results[c["w"]["call"]] = c
        self.cur = None

    def exec_block(self, pc):
        if pc == self.fb_pc:
            self.calls += 1
            if self.cur is None and self.calls in self.wanted:
                self.begin(self.wanted[self.calls])
        elif pc == self.end_pc and self.cur is not None:
            self.end()
        c = self.cur
        if c is None:
            return
        n, f, entry = self.block_info(pc)
        st = c["stack"]
        if entry:
            st.append(f)
            c["ncalls"][f] += 1
        elif not st or st[-1] != f:
            if f in st:
                while st[-1] != f:
                    st.pop()
            else:
                st.append(f)   # a jump into a function's body (no entry seen)
        c["total"] += n
        c["self"][f] += n
        for g in set(st):
            c["incl"][g] += n
        c["blocks"][pc] += 1


def read_log(path, prof):
    """Stream QEMU's in_asm/exec log into the profile."""
    cur_tb = None
    with open(path, "r", errors="replace") as fh:
        for line in fh:
            if line.startswith("Trace "):
                # Trace 0: 0x7f.. [00000000/0000c0de/...] sym
                lb = line.index("[")
                pc = int(line[lb + 10:lb + 18], 16)
                prof.exec_block(pc)
            elif line.startswith("0x"):
                a = int(line[:10], 16)
                if cur_tb is None:
                    cur_tb = a
                    prof.tb[a] = []
                    prof.info.pop(a, None)
                prof.tb[cur_tb].append(a)
            elif line.startswith("IN:") or line.startswith("----"):
                cur_tb = None
            elif not line.strip():
                cur_tb = None


def source_attribution(elf, results, tb, lines_of=None):
    """Per instant: the instructions per source function (innermost inline) and per file."""
    addrs = sorted({a for c in results.values() for pc in c["blocks"] for a in tb.get(pc, [pc])})
    if not addrs:
        return {}
    proc = subprocess.run(["arm-none-eabi-addr2line", "-a", "-f", "-i", "-e", str(elf)],
                          input="\n".join(f"{a:#x}" for a in addrs) + "\n", capture_output=True, text=True,
                          check=True)
    where = {}
    cur, frames = None, []
    lines = proc.stdout.splitlines()
    i = 0
    while i < len(lines):
        s = lines[i]
        if s.startswith("0x") and (i + 1 >= len(lines) or not lines[i + 1].startswith("0x")):
            if cur is not None:
                where[cur] = frames
            cur, frames = int(s, 16), []
            i += 1
            continue
        if i + 1 < len(lines):
            frames.append((s, lines[i + 1]))
        i += 2
    if cur is not None:
        where[cur] = frames
    out = {}
    for call, c in results.items():
        src, files, lines = Counter(), Counter(), Counter()
        for pc, k in c["blocks"].items():
            for a in tb.get(pc, [pc]):
                fr = where.get(a) or [("??", "??:0")]
                fn, loc = fr[0]
                fil = os.path.basename(loc.split(":")[0])
                if fil in ("??", ""):
                    fil = LIBM
                src[f"{fn} [{fil}]"] += k
                files[fil] += k
                outer = fr[-1][0]
                if lines_of and (lines_of in fn or lines_of in outer):
                    lines[f"{os.path.basename(loc.split(' ')[0])} {fn} (in {outer})"] += k
        out[call] = {"source": src, "files": files, "lines": lines}
    return out


def _line_key(label):
    """file:line sort key of a --lines row."""
    loc = label.split(" ")[0]
    f, _, ln = loc.partition(":")
    return (f, int(ln) if ln.isdigit() else 0, label)


def table(rows, head):
    widths = [max(len(str(r[i])) for r in [head] + rows) for i in range(len(head))]
    fmt = lambda r: "  ".join(str(v).rjust(w) if j else str(v).ljust(w) for j, (v, w) in enumerate(zip(r, widths)))
    return "\n".join([fmt(head), "  ".join("-" * w for w in widths)] + [fmt(r) for r in rows])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="\n\n".join(__doc__.split("\n\n")[1:]))
    ap.add_argument("ocp_file", nargs="?", default=str(ROOT / "examples" / "robot_arm.py"),
                    help="OCP file with a disturbance map (default: examples/robot_arm.py)")
    ap.add_argument("--target", default="m7-double", help="firmware target (dopus_lab.firmware.TARGETS)")
    ap.add_argument("--instants", default="op,worst", help="comma-separated: op, worst, steady:K, loop:K")
    ap.add_argument("--top", type=int, default=30, help="rows per table")
    ap.add_argument("--out-dir", default=str(ROOT / "build" / "m7_profile"), help="build folder")
    ap.add_argument("--json", default=str(ROOT / "bench" / "results" / "m7_profile.json"), help="output JSON")
    ap.add_argument("--lines", metavar="FUNCTION", help="also the instructions per source line of the "
                    "functions whose name (or the function they are inlined into) contains FUNCTION")
    ap.add_argument("--keep-log", action="store_true", help="keep QEMU's log (hundreds of MB) in --out-dir")
    a = ap.parse_args(argv)
    from dopus_lab import firmware as fwm

    if a.target not in fwm.TARGETS:
        ap.error(f"--target: unknown {a.target!r} (known: {', '.join(fwm.TARGETS)})")
    if not pathlib.Path(a.ocp_file).is_file():
        ap.error(f"no OCP file {a.ocp_file}")
    sel = [s for s in a.instants.split(",") if s]
    bad = [s for s in sel if s not in ("op", "worst") and not re.fullmatch(r"(steady|loop):[1-9][0-9]*", s)]
    if not sel or bad:
        ap.error(f"--instants: op, worst, steady:K or loop:K (K from 1), got {bad or a.instants!r}")
    missing = fwm.setup_toolchain()
    if missing or not subprocess.run(["which", "arm-none-eabi-addr2line"], capture_output=True).returncode == 0:
        sys.exit(f"m7_profile: the firmware toolchain is missing {missing or ['arm-none-eabi-addr2line']} "
                 "(scripts/setup_firmware.sh)")
    out_dir = pathlib.Path(a.out_dir).resolve()
    t0 = time.time()
    elf, name, b = build(pathlib.Path(a.ocp_file), out_dir, a.target, lambda m: print(m, file=sys.stderr))
    print(f"m7_profile: plain run ({time.time() - t0:.0f} s)", file=sys.stderr)
    run = fwm.parse_output(subprocess.run(qemu_cmd(elf, a.target), stdout=subprocess.PIPE,
                                          stderr=subprocess.STDOUT, text=True, timeout=900).stdout)
    wanted = pick_instants(run, sel)
    fns = functions(elf)
    prof = Profile(fns, name, wanted)
    print(f"m7_profile: logged run of instants {[(w['loop'], w['step']) for w in wanted]} "
          f"({time.time() - t0:.0f} s)", file=sys.stderr)
    with tempfile.TemporaryDirectory(dir=out_dir) as tmp:
        if a.keep_log:
            # the whole log on disk, read after the run
            log = out_dir / "qemu.log"
            subprocess.run(qemu_cmd(elf, a.target, log), capture_output=True, text=True, timeout=3600, check=True)
            read_log(log, prof)
        else:
            # streamed through a pipe while QEMU runs
            log = pathlib.Path(tmp) / "qemu.log"
            os.mkfifo(log)
            err = []

            def reader():
                try:
                    read_log(log, prof)
                except Exception as e:  # noqa: BLE001 (raised below)
                    err.append(e)

            th = threading.Thread(target=reader)
            th.start()
            subprocess.run(qemu_cmd(elf, a.target, log), capture_output=True, text=True, timeout=3600, check=True)
            th.join()
            if err:
                raise err[0]
    print(f"m7_profile: attributing ({time.time() - t0:.0f} s)", file=sys.stderr)
    src = source_attribution(elf, prof.results, prof.tb, a.lines)
    fname = lambda i: fns[i][2] if i >= 0 else "?"
    report = {"problem": name, "target": a.target, "commit": checkout_commit(), "elf_flash_text": b["flash_text"],
              "method": "qemu -icount shift=0 -d in_asm,exec,nochain; instant = feedback entry .. fw_stack_lowest",
              "instants": []}
    for w in wanted:
        c = prof.results.get(w["call"])
        if c is None:
            sys.exit(f"m7_profile: instant {w['label']} not found in the log")
        s = src.get(w["call"], {"source": Counter(), "files": Counter(), "lines": Counter()})
        inst = {k: w[k] for k in ("label", "loop", "step", "counted", "factorizations", "qp_iters")}
        inst["phases"] = None
        if w.get("phases"):
            from dopus_codegen import vocabulary

            inst["phases"] = dict(zip(vocabulary.phases(), w["phases"]))
        inst["traced"] = c["total"]
        inst["functions"] = sorted(({"function": fname(f), "self": c["self"][f], "incl": c["incl"][f],
                                     "calls": c["ncalls"][f]} for f in c["incl"]), key=lambda r: -r["incl"])
        inst["source"] = dict(s["source"].most_common())
        inst["files"] = dict(s["files"].most_common())
        report["instants"].append(inst)
        print(f"\n=== {w['label']}: {w['loop']} loop instant {w['step']}: traced {c['total']} instructions "
              f"(program's count {w['counted']:.0f}), {w['factorizations']} factorisations, "
              f"{w['qp_iters']} QP iterations")
        if inst["phases"]:
            print("phases (the solver's timers): " + ", ".join(f"{k} {v / 1e3:.1f}k" for k, v in inst["phases"].items()
                                                                 if v))
        rows = [(r["function"], f"{r['incl'] / 1e3:.1f}k", f"{100 * r['incl'] / c['total']:.1f}%",
                 f"{r['self'] / 1e3:.1f}k", r["calls"]) for r in inst["functions"][:a.top]]
        print(table(rows, ("function (ELF symbol)", "incl", "incl %", "self", "calls")))
        rows = [(k, f"{v / 1e3:.1f}k", f"{100 * v / c['total']:.1f}%") for k, v in list(inst["source"].items())[:a.top]]
        print()
        print(table(rows, ("source function [file] (inlined code to its own function)", "instr", "%")))
        rows = [(k, f"{v / 1e3:.1f}k", f"{100 * v / c['total']:.1f}%") for k, v in inst["files"].items()]
        print()
        print(table(rows, ("source file", "instr", "%")))
        if a.lines:
            inst["lines"] = dict(sorted(s["lines"].items(), key=lambda kv: _line_key(kv[0])))
            rows = [(k, v) for k, v in inst["lines"].items()]
            print()
            print(table(rows, (f"source line of {a.lines}", "instr")))
    pathlib.Path(a.json).parent.mkdir(parents=True, exist_ok=True)
    pathlib.Path(a.json).write_text(json.dumps(report, indent=1))
    print(f"\nJSON: {a.json} ({time.time() - t0:.0f} s)", file=sys.stderr)


if __name__ == "__main__":
    main()
