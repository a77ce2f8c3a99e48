"""The generated solver on an emulated Cortex-M: build, run under QEMU, measure, report.

``dopus-gen firmware-report OCP_FILE`` (and ``make firmware-report``) generates the C folder
of the OCP file (with its nominal solution), builds the firmware program of ``firmware/``
(``fw_main.c``: the fixed-xhat_0 study of ``dopus-gen converge --start warm`` and a short
closed loop against the generated integrator) for every target with Debian's
``arm-none-eabi-gcc``, runs it under ``qemu-system-arm`` and the same program built for the
host, and writes JSON and a table:

- flash: ``.vectors + .text + .rodata`` (+ ``.data``, its initial values live in flash);
- RAM: ``.data + .bss`` (the solver struct is most of ``.bss``) and the stack one
  iteration (feedback + prepare) needs, measured by stack painting;
- instructions per DOPUS iteration (feedback + prepare; median over the iterations of the
  fixed-xhat_0 study) for M = 1 and the full RTI. QEMU runs with ``-icount shift=0``: every
  instruction advances the virtual clock by exactly 1 ns, and the board's 25 MHz CMSDK timer
  then ticks once per 40 instructions (the program checks this on a loop of a known
  instruction count). The Cortex-M's cycle counter (DWT CYCCNT) is not emulated and Debian's
  QEMU ships no TCG plugins, so instructions, not cycles, are what is measured;
- the iterates: KKT per iteration, u0, the solution, the closed-loop states, and their
  difference to the host build (``host_compare``).

Targets: ``m7-double`` (mps2-an500, Cortex-M7, FPv5 double-precision FPU), ``m7-float`` and
``m4f-float`` (mps2-an386, Cortex-M4, FPv4 single-precision FPU). Each real type gets its own generated
folder (``generated_double``, ``generated_float``: ``real="float"``, docs/algorithm.md
section 11), whatever the OCP file's ``options(real=...)`` says.

The image has no heap: the link wraps every allocator entry point (malloc, calloc, realloc,
free, their reentrant forms, _sbrk), so a program that pulls one in fails to link with
``undefined reference to `__wrap_malloc'``; the linked image is also checked with ``nm``.
"""
from __future__ import annotations

import json
import math
import shlex
import shutil
import statistics
import struct
import subprocess
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence

import numpy as np

from dopus_codegen.codegen.flags import CASADI_CFLAGS, DEFAULT_OPT, STRICT_CFLAGS
from dopus_codegen.codegen.folder import read_meta
from .paths import checkout_script, firmware_dir

__all__ = ["TARGETS", "FirmwareError", "firmware_dir", "toolchain_missing", "setup_toolchain",
           "write_problem_header", "build_target", "scenario_of", "event_map", "scenario_image", "run_scenario",
           "SCENARIO_SETTINGS", "link_image", "build_host", "run_qemu", "run_host", "parse_output",
           "compare_runs", "firmware_report", "format_table", "ALLOCATOR_SYMBOLS"]


class FirmwareError(RuntimeError):
    """A firmware build, link or emulated run failed; the message says which and why."""


@dataclass(frozen=True)
class Target:
    name: str
    machine: str          # QEMU board
    cflags: tuple         # code generation flags of the core
    real: str             # "double" or "float"
    core: str


#: The Cortex-M7's flags. -funroll-loops: the runtime's loops have compile-time bounds, and
#: unrolled they take 3 % fewer instructions per M = 1 instant on the robot arm (flash text
#: +22 kB; bench/issue23/measurements.md section 13). -ffp-contract stays at C99's "off": the
#: FPU's chained VMLA.F64 is already used, fused VFMA would save no instruction and round
#: differently.
M7_CFLAGS = ("-mcpu=cortex-m7", "-mthumb", "-mfpu=fpv5-d16", "-mfloat-abi=hard", "-funroll-loops")

TARGETS: Dict[str, Target] = {
    "m7-double": Target("m7-double", "mps2-an500", M7_CFLAGS, "double", "Cortex-M7"),
    "m7-float": Target("m7-float", "mps2-an500", M7_CFLAGS, "float", "Cortex-M7"),
    "m4f-float": Target("m4f-float", "mps2-an386",
                        ("-mcpu=cortex-m4", "-mthumb", "-mfpu=fpv4-sp-d16", "-mfloat-abi=hard"), "float",
                        "Cortex-M4F"),
}

#: Every target: no errno from the math functions. The solver never reads errno, and newlib's
#: sqrt wrapper setting it for a negative argument links the C library's re-entrancy struct
#: (1 064 B of RAM in .data); without it GCC emits the FPU's square root alone (the same
#: correctly rounded value). bench/issue23/measurements.md section 29.
FW_CFLAGS = ("-fno-math-errno",)

ALLOCATOR_SYMBOLS = ("malloc", "_malloc_r", "calloc", "_calloc_r", "realloc", "_realloc_r", "free",
                     "_free_r", "_sbrk", "_sbrk_r")
FW_SOURCES = ("fw_main.c", "platform_qemu.c", "startup.c")
HOST_SOURCES = ("fw_main.c", "platform_host.c")
OPT = DEFAULT_OPT


def _repo_script() -> Optional[Path]:
    return checkout_script("setup_firmware.sh")


def toolchain_missing() -> List[str]:
    """Programs of the emulated build that are not on PATH."""
    return [p for p in ("arm-none-eabi-gcc", "arm-none-eabi-size", "arm-none-eabi-nm", "qemu-system-arm")
            if shutil.which(p) is None]


def setup_toolchain() -> List[str]:
    """Install the Debian packages when root and missing (scripts/setup_firmware.sh); returns
    what is still missing afterwards (empty: ready)."""
    missing = toolchain_missing()
    script = _repo_script()
    if missing and script is not None:
        subprocess.run(["bash", str(script)], check=False)
        missing = toolchain_missing()
    return missing


def _require_targets(targets: Sequence[str]) -> None:
    """Refuse an unknown target, and a machine without the ARM toolchain and QEMU (after
    trying to install them)."""
    for t in targets:
        if t not in TARGETS:
            raise FirmwareError(f"unknown target {t!r} (known: {', '.join(TARGETS)})")
    missing = setup_toolchain()
    if missing:
        raise FirmwareError(f"missing programs {missing}: run scripts/setup_firmware.sh as root "
                            "(Debian packages gcc-arm-none-eabi libnewlib-arm-none-eabi qemu-system-arm)")


def _run(cmd: Sequence[str], what: str, cwd: Optional[Path] = None, timeout: Optional[float] = None) -> str:
    try:
        proc = subprocess.run(list(cmd), cwd=None if cwd is None else str(cwd), stdout=subprocess.PIPE,
                              stderr=subprocess.STDOUT, text=True, check=False, timeout=timeout)
    except FileNotFoundError:
        raise FirmwareError(f"{what}: program '{cmd[0]}' not found (scripts/setup_firmware.sh installs it)") from None
    except subprocess.TimeoutExpired:
        raise FirmwareError(f"{what}: no end after {timeout} s:\n  $ {shlex.join(cmd)}") from None
    if proc.returncode != 0:
        raise FirmwareError(f"{what} failed (exit {proc.returncode}):\n  $ {shlex.join(cmd)}\n{proc.stdout.rstrip()}")
    return proc.stdout


def _c_real(v: float) -> str:
    if not math.isfinite(v):
        raise FirmwareError(f"the disturbed state has a non-finite entry {v}")
    return repr(float(v))


def write_problem_header(build_dir: Path, name: str, xhat_fixed: Sequence[float], m_list: Sequence[int],
                         fixed_iters: int, loop_steps: int, fixed_lm: float = 0.0,
                         scenario: Optional[Dict[str, Any]] = None) -> Path:
    """``fw_problem.h``: the problem's prefix for fw_main.c and the scenario; ``scenario``:
    the OCP file's scenario of :func:`scenario_of` (the program's ``scenario`` command)."""
    up = name.upper()
    extra = []
    if scenario is not None:
        extra = [f"#define FW_SCENARIO_STEPS {int(scenario['steps'])}"]
        if scenario["event_step"] is not None:
            extra += [f"#define FW_EVENT_STEP {int(scenario['event_step'])}",
                      "#define FW_EVENT_SCALE {" + ", ".join(_c_real(v) for v in scenario["scale"]) + "}",
                      "#define FW_EVENT_SHIFT {" + ", ".join(_c_real(v) for v in scenario["shift"]) + "}"]
    text = "\n".join([
        "/* The problem and scenario of the firmware program (dopus_lab/firmware.py). */",
        "#ifndef FW_PROBLEM_H", "#define FW_PROBLEM_H",
        f'#include "{name}_solver.h"', f'#include "{name}_problem.h"', f'#include "{name}_funcs.h"',
        f"#define FW(name) {name}_##name", f"#define FW_C(name) {up}_##name",
        "#define FW_XHAT_FIXED {" + ", ".join(_c_real(v) for v in xhat_fixed) + "}",
        "#define FW_M_LIST {" + ", ".join(str(int(m)) for m in m_list) + "}",
        f"#define FW_FIXED_ITERS {int(fixed_iters)}", f"#define FW_LOOP_STEPS {int(loop_steps)}",
        f"#define FW_FIXED_LM {_c_real(fixed_lm)}", *extra,
        "#endif", ""])
    build_dir.mkdir(parents=True, exist_ok=True)
    path = build_dir / "fw_problem.h"
    path.write_text(text)
    return path


def _generated_sources(gen_dir: Path) -> tuple:
    meta = read_meta(gen_dir)
    # the translation units the generated build compiles (the solver's includes its modules)
    return meta["name"], list(meta["sources"]["strict"]), meta["sources"]["casadi"]


def _compile(base: List[str], gen_dir: Path, build_dir: Path, fw_sources, obj_dir: Path, what: str) -> List[Path]:
    """Compile the generated library and the firmware sources ``fw_sources`` with the command
    ``base`` into ``obj_dir`` (the CasADi file with its own flags); returns the objects."""
    fw = firmware_dir()
    _, strict, casadi = _generated_sources(gen_dir)
    obj_dir.mkdir(parents=True, exist_ok=True)
    base = [*base, f"-I{gen_dir}", f"-I{build_dir}", f"-I{fw}"]
    objs = []
    for src, flags in ([(gen_dir / f, STRICT_CFLAGS) for f in strict] + [(fw / f, STRICT_CFLAGS) for f in fw_sources]
                       + [(gen_dir / casadi, CASADI_CFLAGS)]):
        obj = obj_dir / (src.stem + ".o")
        _run([*base, *flags, "-c", str(src), "-o", str(obj)], f"{what}: compiling {src.name}")
        objs.append(obj)
    return objs


def build_target(gen_dir, build_dir, target: str, extra_cflags: Sequence[str] = ()) -> Dict[str, Any]:
    """Compile and link the firmware image of ``target``; returns the ELF path and its sizes.
    ``extra_cflags``: appended to the target's flags (bench/m7_profile.py: ``-g``)."""
    tg = TARGETS[target]
    gen_dir, build_dir = Path(gen_dir).resolve(), Path(build_dir).resolve()
    name = read_meta(gen_dir)["name"]
    obj_dir = build_dir / target
    base = ["arm-none-eabi-gcc", *tg.cflags, *FW_CFLAGS, OPT, *extra_cflags, "-ffunction-sections",
            "-fdata-sections", "-fstack-usage"]
    objs = _compile(base, gen_dir, build_dir, FW_SOURCES, obj_dir, target)
    elf = obj_dir / f"{name}_{target}.elf"
    link_image(target, objs, elf)
    sections = {}
    for line in _run(["arm-none-eabi-size", "-A", str(elf)], f"{target}: size").splitlines():
        parts = line.split()
        if len(parts) == 3 and parts[0].startswith(".") and parts[1].isdigit():
            sections[parts[0]] = int(parts[1])
    return {"target": target, "elf": str(elf), "sections": sections,
            "flash_text": sections.get(".vectors", 0) + sections.get(".text", 0),
            "flash_rodata": sections.get(".rodata", 0),
            "flash": sum(sections.get(s, 0) for s in (".vectors", ".text", ".rodata", ".ARM.exidx", ".data")),
            "ram_data": sections.get(".data", 0), "ram_bss": sections.get(".bss", 0),
            "stack_usage_file_max": _max_stack_usage(obj_dir)}


def link_image(target: str, objs: Sequence[Path], elf: Path) -> Path:
    """Link the objects into a bare-metal image for ``target`` with the start-up code's linker
    script. Every allocator entry point is wrapped to an undefined symbol, so an image that
    needs malloc does not link (FirmwareError); the image's symbols are checked again."""
    tg = TARGETS[target]
    link = ["arm-none-eabi-gcc", *tg.cflags, "-nostartfiles", "-T", str(firmware_dir() / "mps2.ld"),
            "-Wl,--gc-sections", "-Wl,--wrap=" + ",--wrap=".join(ALLOCATOR_SYMBOLS),
            f"-Wl,-Map={Path(elf).with_suffix('.map')}", *map(str, objs), "-lm", "-o", str(elf)]
    _run(link, f"{target}: linking (an allocator in the image is a link error)")
    syms = _run(["arm-none-eabi-nm", str(elf)], f"{target}: nm").split()
    found = sorted(set(ALLOCATOR_SYMBOLS) & set(syms))
    if found:
        raise FirmwareError(f"{target}: the image contains allocator symbols {found}")
    return Path(elf)


def _max_stack_usage(obj_dir: Path) -> int:
    """Largest single frame reported by -fstack-usage (the painted figure is the measured total)."""
    best = 0
    for su in obj_dir.glob("*.su"):
        for line in su.read_text().splitlines():
            parts = line.split("\t")
            if len(parts) >= 2 and parts[1].strip().isdigit():
                best = max(best, int(parts[1]))
    return best


def build_host(gen_dir, build_dir, cc: str = "cc") -> Path:
    """The same firmware program for the host (stdout instead of semihosting, no ticks)."""
    gen_dir, build_dir = Path(gen_dir).resolve(), Path(build_dir).resolve()
    name = read_meta(gen_dir)["name"]
    out = build_dir / "host"
    objs = _compile([cc, OPT], gen_dir, build_dir, HOST_SOURCES, out, "host")
    exe = out / f"fw_{name}_host"
    _run([cc, *map(str, objs), "-lm", "-o", str(exe)], "host: linking")
    return exe


def run_qemu(elf, target: str, timeout: float = 900.0, args: Sequence[str] = ()) -> str:
    """Run the image under QEMU; ``args``: the program's command line after its name
    (semihosting)."""
    tg = TARGETS[target]
    semi = "enable=on,target=native" + ("".join(f",arg={a}" for a in ("fw", *args)) if args else "")
    cmd = ["qemu-system-arm", "-M", tg.machine, "-nographic", "-monitor", "none", "-serial", "none",
           "-semihosting-config", semi, "-icount", "shift=0", "-kernel", str(elf)]
    return _run(cmd, f"{target}: emulated run", timeout=timeout)


def run_host(exe, timeout: float = 900.0) -> str:
    return _run([str(exe)], "host run", timeout=timeout)


def _real(tok: str) -> float:
    if not tok.startswith("0x"):
        raise FirmwareError(f"expected a hexadecimal real, got {tok!r}")
    digits = tok[2:]
    if len(digits) == 16:
        return struct.unpack(">d", bytes.fromhex(digits))[0]
    if len(digits) == 8:
        return struct.unpack(">f", bytes.fromhex(digits))[0]
    raise FirmwareError(f"a real has 8 or 16 hexadecimal digits, got {tok!r}")


_INT_FIELDS = ("instructions", "setting", "used", "extra", "stages", "M", "iter", "step", "status", "qp_iters",
               "qp_status", "flags",
               "ticks_feedback", "ticks_prepare", "stack", "factorizations")


def _parse_record(tokens: List[str]) -> Dict[str, Any]:
    rec: Dict[str, Any] = {}
    i = 0
    key = None
    while i < len(tokens):
        tok = tokens[i]
        if tok.startswith("0x") and key is not None:
            rec.setdefault(key, []).append(_real(tok))
        elif tok == "phases":
            # the instructions per phase of the solver's timers (enum dopus_phase order)
            vals = []
            while i + 1 < len(tokens) and tokens[i + 1].lstrip("-").isdigit():
                vals.append(int(tokens[i + 1]))
                i += 1
            rec["phases"] = vals
            key = None
        else:
            key = tok
            if tok in _INT_FIELDS or tok in ("N", "nx", "nu", "real_bytes", "solver_bytes", "default_clock",
                                             "ticks", "instructions_per_tick", "calibration_instructions",
                                             "calibration_ticks"):
                rec[tok] = int(tokens[i + 1])
                i += 1
                key = None
        i += 1
    for k in ("kkt",):
        if k in rec:
            rec[k] = rec[k][0]
    return rec


def parse_output(text: str) -> Dict[str, Any]:
    """The records printed by fw_main.c: header, fixed runs per M, solutions, loop steps."""
    out: Dict[str, Any] = {"fixed": {}, "solution": {}, "loop": [], "steady": [], "budget": [], "scenario": [],
                           "end": None}
    for line in text.splitlines():
        tokens = line.split()
        if not tokens:
            continue
        kind, rest = tokens[0], tokens[1:]
        if kind == "problem":
            out["header"] = {"name": rest[0], **_parse_record(rest[1:])}
        elif kind == "fixed":
            rec = _parse_record(rest)
            out["fixed"].setdefault(rec["M"], []).append(rec)
        elif kind == "solution":
            rec = _parse_record(rest)
            out["solution"][rec["M"]] = rec
        elif kind in ("loop", "steady"):
            out[kind].append(_parse_record(rest))
        elif kind == "budget":
            out["budget"].append(_parse_record(rest))
        elif kind == "scenario":
            out["scenario"].append(_parse_record(rest))
        elif kind == "end":
            out["end"] = _parse_record(rest)["status"]
        elif kind.startswith("firmware:"):
            raise FirmwareError(line)
    if "header" not in out or out["end"] is None:
        raise FirmwareError(f"incomplete output of the firmware program:\n{text[-2000:]}")
    return out


# ---- the OCP file's scenario on the firmware (bench/budget_curves.py --parts m7) ----------

#: the settings of the program's scenario command: full RTI (M = N-1), M = 1, adaptive M (1..10)
SCENARIO_SETTINGS = {"full": 1, "M=1": 2, "adaptive": 3}
_SCENARIO_WORDS = {"full": "full", "M=1": "M1", "adaptive": "adaptive"}


def event_map(ev, nx: int):
    """(scale, shift) with ``ev.fn(x) = scale * x + shift`` entrywise, the only kind of event
    the firmware program applies (the robot arm's disturbance: q shifted, dq set to 0; the
    chain's shake: a velocity shifted); FirmwareError for any other map."""
    def f(x):
        return np.asarray(ev.fn(np.array(x, dtype=float)), dtype=float).reshape(-1)

    shift = f(np.zeros(nx))
    eye = np.eye(nx)
    cols = np.array([f(eye[i]) - shift for i in range(nx)])
    scale = np.diag(cols).copy()
    rng = np.random.default_rng(0)
    probe = rng.uniform(-2.0, 2.0, nx)
    ok = (shift.size == nx and np.allclose(cols - np.diag(scale), 0.0, rtol=0, atol=1e-12)
          and np.allclose(f(probe), scale * probe + shift, rtol=1e-12, atol=1e-12))
    if not ok:
        raise FirmwareError(f"scenario event '{ev.label}': the firmware program applies only maps "
                            "x <- scale .* x + shift (entrywise); this event is another map")
    return scale, shift


def scenario_of(disc) -> Dict[str, Any]:
    """The OCP file's closed-loop scenario as the firmware program runs it: its number of
    instants, the instant of its event (at most one) and the event as (scale, shift). The
    plant is the model (the generated integrator), not the scenario's plant: the firmware has
    no CVODES."""
    spec = disc.scenario.closed_loop
    if spec is None:
        raise FirmwareError(f"{disc.name}: the OCP file declares no closed-loop scenario")
    if spec.x0 is not None and not np.array_equal(np.asarray(spec.x0, float).reshape(-1),
                                                  np.asarray(disc.x0, float).reshape(-1)):
        raise FirmwareError(f"{disc.name}: the firmware scenario starts at the OCP's initial state, "
                            "the scenario declares another")
    dt = float(disc.dt)
    steps = int(round(float(spec.duration) / dt))
    events = [ev for ev in spec.events if float(ev.time) < steps * dt]
    if len(events) > 1:
        raise FirmwareError(f"{disc.name}: the firmware scenario has at most one event, the OCP file's has "
                            f"{len(events)}")
    out = {"steps": steps, "dt": dt, "event_step": None, "event_time": None, "event_label": None,
           "scale": None, "shift": None}
    if events:
        ev = events[0]
        # the instant of sil's loop: the first i with i dt >= time (to 1e-9 dt)
        step = int(math.ceil(float(ev.time) / dt - 1e-9))
        scale, shift = event_map(ev, int(disc.nx))
        out.update(event_step=step, event_time=float(ev.time), event_label=ev.label,
                   scale=scale.tolist(), shift=shift.tolist())
    return out


def scenario_image(disc, out_dir, target: str = "m7-double", progress=print,
                   steps: Optional[int] = None) -> Dict[str, Any]:
    """Generate ``disc`` (with its nominal solution) and build the firmware image of
    ``target`` with its scenario; returns {"elf", "target", "scenario", "gen_dir"}. ``steps``:
    the scenario's first so many instants only (a shorter run around its event)."""
    from dopus_codegen.codegen import generate as codegen

    _require_targets([target])
    sc = scenario_of(disc)
    if steps is not None:
        if int(steps) != steps or not 1 <= steps <= sc["steps"]:
            raise FirmwareError(f"steps: expected an integer from 1 to the scenario's {sc['steps']} instants, "
                                f"got {steps!r}")
        sc["steps"] = int(steps)
        if sc["event_step"] is not None and sc["event_step"] >= sc["steps"]:
            sc.update(event_step=None, event_time=None, event_label=None, scale=None, shift=None)
    out_dir = Path(out_dir)
    real = TARGETS[target].real
    gen = out_dir / f"generated_{real}"
    progress(f"firmware: generating {disc.name} ({real}) into {gen}")
    codegen.generate(disc, gen, offline_guess=True, real=real)
    bdir = out_dir / f"build_{real}"
    x0 = np.asarray(disc.x0, dtype=float).reshape(-1)
    write_problem_header(bdir, disc.name, x0, [1], 0, 0, scenario=sc)
    progress(f"firmware: building {target}")
    b = build_target(gen, bdir, target)
    return {"elf": b["elf"], "target": target, "scenario": sc, "gen_dir": str(gen)}


def run_scenario(image: Dict[str, Any], setting: str, instructions: int,
                 timeout: float = 3600.0) -> List[Dict[str, Any]]:
    """The scenario's closed loop under QEMU for ``setting`` (a key of SCENARIO_SETTINGS) and
    a budget of ``instructions`` per instant on the instruction clock (0: none): one record
    per instant (step, status, ticks_feedback, ticks_prepare, extra, stages, kkt, u0, xhat)
    plus ``instructions_instant``, the instructions of its feedback and prepare."""
    if setting not in SCENARIO_SETTINGS:
        raise FirmwareError(f"unknown setting {setting!r} (known: {', '.join(SCENARIO_SETTINGS)})")
    if int(instructions) != instructions or instructions < 0:
        raise FirmwareError(f"the budget is a non-negative number of instructions, got {instructions!r}")
    text = run_qemu(image["elf"], image["target"], timeout=timeout,
                    args=("scenario", _SCENARIO_WORDS[setting], str(int(instructions))))
    run = parse_output(text)
    if run["end"] != 0:
        raise FirmwareError(f"the firmware scenario ({setting}, {instructions} instructions) ended with "
                            f"status {run['end']}")
    per_tick = run["header"]["instructions_per_tick"]
    recs = run["scenario"]
    if len(recs) != image["scenario"]["steps"]:
        raise FirmwareError(f"the firmware scenario printed {len(recs)} instants, expected "
                            f"{image['scenario']['steps']}")
    for r in recs:
        r["instructions_instant"] = (r["ticks_feedback"] + r["ticks_prepare"]) * per_tick
    return recs


def _vec_rel(a, b) -> float:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    if a.shape != b.shape:
        return math.inf
    scale = float(np.max(np.abs(b))) if b.size else 0.0
    d = float(np.max(np.abs(a - b))) if a.size else 0.0
    return d / scale if scale > 0 else d


def compare_runs(run: Dict[str, Any], ref: Dict[str, Any], kkt_floor: float) -> Dict[str, float]:
    """Largest relative differences of ``run`` against ``ref`` (per vector, in its inf-norm):
    u0 of every fixed iteration, the solutions, u0 and the state of every closed-loop step;
    the KKT measure relative to max(KKT_ref, kkt_floor): it is a residual, a difference of
    terms of order one and more, so its rounding error is absolute, not relative to itself."""
    d = {"u0": 0.0, "solution": 0.0, "kkt": 0.0, "loop_u0": 0.0, "loop_x": 0.0}
    for M, recs in ref["fixed"].items():
        other = run["fixed"].get(M, [])
        if len(other) != len(recs):
            return {k: math.inf for k in d}
        for a, b in zip(other, recs):
            d["u0"] = max(d["u0"], _vec_rel(a["u0"], b["u0"]))
            d["kkt"] = max(d["kkt"], abs(a["kkt"] - b["kkt"]) / max(abs(b["kkt"]), kkt_floor))
        sa, sb = run["solution"][M], ref["solution"][M]
        d["solution"] = max(d["solution"], _vec_rel(sa["x"], sb["x"]), _vec_rel(sa["u"], sb["u"]))
    if len(run["loop"]) != len(ref["loop"]):
        return {k: math.inf for k in d}
    for a, b in zip(run["loop"], ref["loop"]):
        d["loop_u0"] = max(d["loop_u0"], _vec_rel(a["u0"], b["u0"]))
        d["loop_x"] = max(d["loop_x"], _vec_rel(a["xhat"], b["xhat"]))
    return d


def _instructions(recs: List[Dict[str, Any]], per_tick: float) -> Dict[str, float]:
    its = [r for r in recs if r["iter"] > 0]
    fb = [r["ticks_feedback"] * per_tick for r in its]
    pr = [r["ticks_prepare"] * per_tick for r in its]
    tot = [a + b for a, b in zip(fb, pr)]
    out = {"iteration_median": statistics.median(tot), "iteration_max": max(tot),
           "feedback_median": statistics.median(fb), "prepare_median": statistics.median(pr),
           "qp_iterations_median": statistics.median(r["qp_iters"] for r in its)}
    if its and "factorizations" in its[0]:
        fac = [r["factorizations"] for r in its]
        out.update(factorizations_median=statistics.median(fac), factorizations_max=max(fac),
                   worst_instant=its[max(range(len(tot)), key=tot.__getitem__)]["iter"],
                   per_instant=tot, factorizations=fac)
    if its and its[0].get("phases"):
        # the solver's phase timers on the instruction clock: per phase, the median over the
        # instants and the value at the worst instant
        from dopus_codegen import vocabulary

        names = vocabulary.phases()
        worst = max(range(len(tot)), key=tot.__getitem__)
        out["phases_median"] = {n: statistics.median(r["phases"][j] for r in its) for j, n in enumerate(names)
                                if j < len(its[0]["phases"])}
        out["phases_worst"] = {n: its[worst]["phases"][j] for j, n in enumerate(names)
                               if j < len(its[worst]["phases"])}
    return out


def summarize(target: str, build: Dict[str, Any], run: Dict[str, Any], N: int) -> Dict[str, Any]:
    hdr = run["header"]
    per_tick = hdr["instructions_per_tick"]
    calib = hdr["calibration_ticks"] * per_tick / hdr["calibration_instructions"]
    stack = max([r["stack"] for recs in run["fixed"].values() for r in recs] + [r["stack"] for r in run["loop"]])
    res = {
        "target": target, "core": TARGETS[target].core, "machine": TARGETS[target].machine,
        "real": TARGETS[target].real, "real_bytes": hdr["real_bytes"], "solver_bytes": hdr["solver_bytes"],
        "default_clock": hdr["default_clock"],
        "flash_text": build["flash_text"], "flash_rodata": build["flash_rodata"], "flash": build["flash"],
        "ram_data": build["ram_data"], "ram_bss": build["ram_bss"], "stack_iteration": stack,
        "ram_total": build["ram_data"] + build["ram_bss"] + stack,
        "largest_frame_fstack_usage": build["stack_usage_file_max"],
        "calibration_ratio": calib,
        "instructions": {}, "kkt": {}, "loop": [],
    }
    for M, recs in run["fixed"].items():
        label = "full" if M == N - 1 else f"M{M}"
        res["instructions"][label] = _instructions(recs, per_tick)
        res["kkt"][label] = [r["kkt"] for r in recs]
    res["instructions"]["loop_M1"] = _instructions([dict(r, iter=r["step"]) for r in run["loop"]], per_tick)
    if run.get("steady"):
        # the operating point: the closed loop from the default x0 (no disturbance)
        res["instructions"]["steady_M1"] = _instructions([dict(r, iter=r["step"]) for r in run["steady"]], per_tick)
    res["loop"] = [{"step": r["step"], "kkt": r["kkt"], "u0": r["u0"], "xhat": r["xhat"]} for r in run["loop"]]
    # the budgeted closed loops (docs/algorithm.md section 14): instructions per instant
    res["budget"] = {}
    for b in sorted({r["instructions"] for r in run.get("budget", [])}):
        recs = [r for r in run["budget"] if r["instructions"] == b]
        tot = [(r["ticks_feedback"] + r["ticks_prepare"]) * per_tick for r in recs]
        res["budget"][str(b)] = {"instant_median": statistics.median(tot), "instant_max": max(tot),
                                 "extra_iterations": [r["extra"] for r in recs],
                                 "failed": sum(1 for r in recs if r["status"] != 0),
                                 "kkt_max": max(r["kkt"] for r in recs),
                                 "xhat": [r["xhat"] for r in recs]}
    res["solution"] = {str(M): {"x": s["x"], "u": s["u"]} for M, s in run["solution"].items()}
    return res


def _loop_deviation(run: Dict[str, Any], ref: Dict[str, Any]) -> float:
    """Largest state difference over the closed loop (absolute, inf-norm)."""
    return max(float(np.max(np.abs(np.subtract(a["xhat"], b["xhat"])))) for a, b in zip(run["loop"], ref["loop"]))


# Tolerances of the comparisons with the host build (docs/results.md, "The firmware report").
TOL_DOUBLE = 1e-8     # relative; newlib's sin/cos differ from glibc's in the last bit
KKT_FLOOR_DOUBLE = 1.0   # the KKT measure is a residual: its rounding error is absolute


def firmware_report(ocp_file, out_dir, targets: Sequence[str] = ("m7-double",),
                    fixed_iters: int = 12, loop_steps: int = 20, m_list: Optional[Sequence] = None,
                    json_out=None, progress=print) -> Dict[str, Any]:
    """Generate, build, run under QEMU and on the host; return (and write) the report."""
    from dopus_codegen.codegen import generate as codegen
    from dopus_codegen.problem.derivatives import build_functions
    from dopus_codegen.problem.ocp import load_ocp

    _require_targets(targets)
    out_dir = Path(out_dir)
    disc = build_functions(load_ocp(ocp_file))
    if disc.disturbance is None:
        raise FirmwareError(f"{disc.name}: the fixed-xhat_0 study needs a disturbance map (ocp.disturbance)")
    x0 = np.array(disc.x0, dtype=float)
    xhat_fixed = np.array(disc.disturbance(x0.copy()), dtype=float).reshape(-1)
    N = int(disc.N)
    Ms = [1, N - 1] if m_list is None else [N - 1 if m == "full" else int(m) for m in m_list]
    reals = sorted({TARGETS[t].real for t in targets} | {"double"})
    gen: Dict[str, Path] = {}
    for real in reals:
        d = out_dir / f"generated_{real}"
        progress(f"firmware: generating {disc.name} ({real}) into {d}")
        # the target's type, whatever the OCP file's options(real=...) says
        codegen.generate(disc, d, offline_guess=True, real=real)
    for real in reals:
        gen[real] = out_dir / f"generated_{real}"
    runs: Dict[str, Any] = {}
    report: Dict[str, Any] = {"problem": disc.name, "N": N, "M_list": Ms, "fixed_iters": fixed_iters,
                              "loop_steps": loop_steps, "xhat_fixed": xhat_fixed.tolist(),
                              "count_method": "qemu -icount shift=0 (1 instruction = 1 ns virtual), "
                                              "CMSDK APB timer at 25 MHz = 40 instructions per tick",
                              "targets": {}}
    host_runs = {}
    for real in reals:
        bdir = out_dir / f"build_{real}"
        write_problem_header(bdir, disc.name, xhat_fixed, Ms, fixed_iters, loop_steps)
        progress(f"firmware: host build ({real})")
        host_runs[real] = parse_output(run_host(build_host(gen[real], bdir)))
    for t in targets:
        real = TARGETS[t].real
        bdir = out_dir / f"build_{real}"
        progress(f"firmware: building {t}")
        b = build_target(gen[real], bdir, t)
        progress(f"firmware: running {t} under QEMU ({TARGETS[t].machine})")
        run = parse_output(run_qemu(b["elf"], t))
        runs[t] = run
        s = summarize(t, b, run, N)
        s["end_status"] = run["end"]
        s["host_compare"] = compare_runs(run, host_runs[real],
                                         KKT_FLOOR_DOUBLE if real == "double" else 1e-3)
        s["loop_deviation_vs_host_double"] = _loop_deviation(run, host_runs["double"])
        report["targets"][t] = s
    report["host_double"] = {"kkt": {("full" if M == N - 1 else f"M{M}"): [r["kkt"] for r in recs]
                                     for M, recs in host_runs["double"]["fixed"].items()}}
    if json_out is not None:
        Path(json_out).parent.mkdir(parents=True, exist_ok=True)
        Path(json_out).write_text(json.dumps(report, indent=1))
    return report


def format_table(report: Dict[str, Any]) -> str:
    """The size/instruction table and the accuracy lines of a report."""
    rows = [("target", "flash text", "flash rodata", "RAM data+bss", "stack/iter", "RAM total",
             "solver struct", "instr M=1", "instr full", "QP share M=1", "KKT M=1 last", "KKT full last",
             "vs host (rel)")]
    for t, s in report["targets"].items():
        i1 = s["instructions"].get("M1", {})
        ifull = s["instructions"].get("full", {})
        qp = i1.get("feedback_median", float("nan")) / i1["iteration_median"] if i1 else float("nan")
        hc = s["host_compare"]
        rows.append((t, str(s["flash_text"]), str(s["flash_rodata"]), str(s["ram_data"] + s["ram_bss"]),
                     str(s["stack_iteration"]), f"{s['ram_total'] / 1024:.1f} KiB", str(s["solver_bytes"]),
                     f"{i1.get('iteration_median', float('nan')) / 1e6:.2f} M",
                     f"{ifull.get('iteration_median', float('nan')) / 1e6:.2f} M", f"{100 * qp:.0f} %",
                     f"{s['kkt'].get('M1', [float('nan')])[-1]:.3g}",
                     f"{s['kkt'].get('full', [float('nan')])[-1]:.3g}",
                     f"{max(hc.values()):.2g}"))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines = [" | ".join(c.ljust(w) for c, w in zip(r, widths)) for r in rows]
    lines.insert(1, "-+-".join("-" * w for w in widths))
    lines.append("")
    lines.append(f"instruction count: {report['count_method']}")
    tg = report["targets"]
    if "m7-float" in tg and "m4f-float" in tg:
        r = (tg["m4f-float"]["instructions"]["M1"]["iteration_median"]
             / tg["m7-float"]["instructions"]["M1"]["iteration_median"])
        lines.append(f"M4F float / M7 float instructions per M = 1 iteration: {r:.2f} (goal: at most 1.5)")
    for t, s in tg.items():
        goal = 64 if s["real"] == "float" else 128
        lines.append(f"{t}: RAM (data + bss + stack of one iteration) {s['ram_total'] / 1024:.1f} KiB "
                     f"(goal: at most {goal} KiB), of which the solver struct {s['solver_bytes'] / 1024:.1f} KiB")
    for t, s in tg.items():
        for key, what in (("steady_M1", "closed loop at the operating point (default x0)"),
                          ("loop_M1", "closed loop after the disturbance")):
            r = s["instructions"].get(key)
            if r:
                lines.append(f"{t}: {what}, instructions per instant: median {r['iteration_median'] / 1e6:.2f} M "
                             f"(feedback {r['feedback_median'] / 1e6:.2f} M), worst {r['iteration_max'] / 1e6:.2f} M"
                             + (f"; QP factorisations median {r['factorizations_median']:g}, max "
                                f"{r['factorizations_max']}" if "factorizations_median" in r else ""))
    for t, s in report["targets"].items():
        lines.append(f"{t}: calibration {s['calibration_ratio']:.6f} (counted / known instructions); "
                     f"closed-loop state deviation from the host double build {s['loop_deviation_vs_host_double']:.3g}; "
                     f"KKT M=1 per iteration: " + " ".join(f"{v:.17g}" for v in s["kkt"].get("M1", [])))
    return "\n".join(lines)
