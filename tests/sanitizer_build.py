"""Builds of a generated solver with AddressSanitizer + UndefinedBehaviorSanitizer (and
libFuzzer) for tests/test_sanitizers.py and tests/test_fuzz.py.

The C programs live in tests/fuzz/ (driver.c: a realistic run; fuzz_solver.c: the libFuzzer
harness) and are written once for every generated solver (tests/fuzz/solver_api.h). clang
and its runtime libraries come from Debian (``scripts/bootstrap.sh`` installs them when run
as root); without them these tests fail with a message saying so.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path
from typing import List, Optional, Sequence

ROOT = Path(__file__).resolve().parent.parent
FUZZ_DIR = ROOT / "tests" / "fuzz"
GENERATED = ROOT / "generated"

STRICT = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"]
SANITIZE = ["-fsanitize=address,undefined", "-fno-sanitize-recover=all", "-fno-omit-frame-pointer"]
# libFuzzer's edge coverage for the library, without the comparison tracing: the tracing of
# every floating-point comparison in the linear algebra made the fuzzer 14x slower (unicycle:
# 628 ms against 46 ms for an 8-step closed loop) for no guidance the harness needs
COVERAGE = ["-fsanitize=fuzzer-no-link", "-fno-sanitize-coverage=trace-cmp"]
# a sanitizer report makes the program exit nonzero; leaks are reported too
SAN_ENV = {
    "ASAN_OPTIONS": "detect_leaks=1:abort_on_error=0:halt_on_error=1:detect_stack_use_after_return=1",
    "UBSAN_OPTIONS": "print_stacktrace=1:halt_on_error=1",
}
SAN_MARKERS = ("ERROR: AddressSanitizer", "runtime error:", "ERROR: LeakSanitizer", "UndefinedBehaviorSanitizer")
MISSING = ("clang with the sanitizer and libFuzzer runtimes is missing: run scripts/bootstrap.sh as root "
           "(it installs Debian's clang and libclang-rt-<version>-dev) or apt-get install them")


def _compiles(cc: str, flags: Sequence[str], tmp: Path) -> bool:
    src = tmp / "probe.c"
    src.write_text("#include <stddef.h>\n#include <stdint.h>\n"
                   "int LLVMFuzzerTestOneInput(const uint8_t *d, size_t n) { (void)d; (void)n; return 0; }\n")
    try:
        proc = subprocess.run([cc, *flags, str(src), "-o", str(tmp / "probe")], capture_output=True, text=True)
    except FileNotFoundError:
        return False
    return proc.returncode == 0


def find_clang(tmp: Path) -> Optional[str]:
    """A clang that links -fsanitize=fuzzer,address,undefined, or None."""
    tmp.mkdir(parents=True, exist_ok=True)
    names = ["clang"] + [f"clang-{v}" for v in range(20, 12, -1)]
    for name in names:
        cc = shutil.which(name)
        if cc and _compiles(cc, ["-fsanitize=fuzzer,address,undefined"], tmp):
            return cc
    return None


def sources(folder: Path) -> tuple:
    meta = json.loads(next(folder.glob("*_meta.json")).read_text())
    return meta["name"], list(meta["sources"]["strict"]), meta["sources"]["casadi"]


def api_defines(name: str) -> List[str]:
    return [f"-DSOLVER_PREFIX={name}_", f"-DSOLVER_UPREFIX={name.upper()}_",
            f'-DSOLVER_HEADER="{name}_solver.h"', f'-DPROBLEM_HEADER="{name}_problem.h"']


def _run(cmd: Sequence[str], cwd: Path) -> None:
    proc = subprocess.run(list(cmd), cwd=str(cwd), capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"build failed: {' '.join(cmd)}\n{proc.stdout}{proc.stderr}")


def make_run(src_folder: Path, dest: Path, cc: str, opt: str, extra: str, env=None):
    """Copy a generated folder to ``dest`` and run its own Makefile there: ``make run`` builds
    the static library and the standalone main and runs the main. Returns the completed
    process of make (its stdout holds the main's output after make's command lines)."""
    if dest.exists():
        shutil.rmtree(dest)
    shutil.copytree(src_folder, dest, ignore=shutil.ignore_patterns("build"))
    cmd = ["make", "-s", "-j2", "run", f"CC={cc}", f"OPT={opt}", f"EXTRA_CFLAGS={extra}"]
    return subprocess.run(cmd, cwd=str(dest), capture_output=True, text=True, env=env)


def link_program(folder: Path, main_c: Path, out: Path, cc: str, opt: Sequence[str],
                 extra: Sequence[str] = ()) -> Path:
    """Compile ``main_c`` (tests/fuzz) against the static library that the folder's Makefile
    built (build/lib<name>.a)."""
    name = sources(folder)[0]
    _run([cc, *opt, *STRICT, *extra, *api_defines(name), f"-I{folder}", f"-I{FUZZ_DIR}", str(main_c),
          str(folder / "build" / f"lib{name}.a"), "-lm", "-o", str(out)], folder)
    return out


def sanitizer_report(stderr: str) -> Optional[str]:
    for marker in SAN_MARKERS:
        if marker in stderr:
            i = stderr.index(marker)
            return stderr[max(0, i - 200): i + 2000]
    return None


def san_env() -> dict:
    env = dict(os.environ)
    env.update(SAN_ENV)
    return env
