"""Build a generated folder: a shared library (for cffi) and a static library (firmware).

Every C file compiles with the strict flags of the project (``-std=c99 -Wall -Wextra
-Werror -pedantic``), the CasADi file included. The products go to ``<folder>/build/``,
with the same object and library names and the same flags as the folder's own Makefile
(``build/obj/*.o``, ``build/lib<name>.a``, ``build/lib<name>.so``), so ``make`` or
``make run`` in the folder afterwards only links the standalone program. A stamp holds a
hash of the sources, the compiler and the flags: an unchanged folder is not rebuilt, and
every object is also looked up in (and added to) the object cache of
:mod:`dopus_codegen.codegen.cache`, so a source compiled once, in any folder, is never
compiled again. Outputs are written under temporary names and renamed, so a concurrent
build never leaves a half-written library behind.
"""
from __future__ import annotations

import hashlib
import json
import os
import shlex
import shutil
import subprocess
import sys
import tempfile
import warnings
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, List, Optional, Sequence

from . import cache
from .flags import CASADI_CFLAGS, DEFAULT_OPT, PIC, STRICT_CFLAGS
from .folder import CodegenError, read_meta

BUILD_SUBDIR = Path("build")


def _stderr(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


class BuildError(RuntimeError):
    """The C compiler (or archiver) failed; the message carries its command and output."""


@dataclass(frozen=True)
class BuildResult:
    shared_lib: Path
    static_lib: Path
    cdef_path: Path
    name: str
    out_dir: Path
    rebuilt: bool
    compiled: List[str] = field(default_factory=list)   # sources compiled (not from the cache)


#: Environment variable: how many C files ``build`` compiles at once (default: the
#: processors this process may use).
JOBS_VAR = "DOPUS_BUILD_JOBS"


def build_jobs(n_files: int) -> int:
    """Parallel compilations: ``$DOPUS_BUILD_JOBS``, else the usable processors, at most
    ``n_files`` and at least 1."""
    raw = os.environ.get(JOBS_VAR, "").strip()
    if raw:
        try:
            jobs = int(raw)
        except ValueError:
            raise BuildError(f"{JOBS_VAR}={raw!r} is not a whole number") from None
        if jobs < 1:
            raise BuildError(f"{JOBS_VAR}={raw!r} must be at least 1")
    else:
        jobs = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return max(1, min(jobs, n_files))


def _run(cmd: Sequence[str], cwd: Path, what: str) -> None:
    try:
        proc = subprocess.run(list(cmd), cwd=str(cwd), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                              text=True, check=False)
    except FileNotFoundError:
        raise BuildError(f"{what}: program '{cmd[0]}' not found (install a C toolchain or pass cc=...)") from None
    if proc.returncode != 0:
        raise BuildError(f"{what} failed (exit {proc.returncode}):\n  $ {shlex.join(cmd)}\n{proc.stdout.rstrip()}")


def _source_hash(out_dir: Path, files: List[str], cc: str, opt: Sequence[str]) -> str:
    h = hashlib.sha256()
    h.update(json.dumps({"cc": cc, "opt": list(opt), "strict": STRICT_CFLAGS, "casadi": CASADI_CFLAGS}).encode())
    for fname in files:
        h.update(fname.encode() + b"\0")
        h.update((out_dir / fname).read_bytes())
        h.update(b"\0")
    return h.hexdigest()


def recorded_opt(out_dir) -> str | None:
    """The optimisation flags the folder was last built with (its stamp), or None."""
    stamp = Path(out_dir) / BUILD_SUBDIR / "stamp.json"
    try:
        opt = json.loads(stamp.read_text()).get("opt")
    except (OSError, ValueError):
        return None
    return shlex.join(opt) if isinstance(opt, list) else None


def build(out_dir, cc: str = "cc", opt: str | None = None, *, force: bool = False, cache_dir=None,
          echo: Optional[Callable[[str], None]] = _stderr) -> BuildResult:
    """Compile the generated folder ``out_dir``; skip the work if nothing changed.

    ``opt`` None keeps the flags the folder was built with (recorded in its stamp), else
    DEFAULT_OPT: so loading a folder (the Python handle) never rebuilds it with other flags
    than `dopus-gen build --opt` chose. Explicit flags that differ from the recorded ones
    rebuild it with a warning naming both. ``cache_dir``: the object cache (default
    :func:`cache.cache_root`). ``echo`` receives one line per compiled file and per link
    (None: silent); nothing is said when the folder is up to date.
    """
    say = echo or (lambda msg: None)
    out_dir = Path(out_dir)
    if opt is None:
        opt = recorded_opt(out_dir) or DEFAULT_OPT
    else:
        was = recorded_opt(out_dir)
        if was is not None and shlex.split(was) != shlex.split(opt):
            warnings.warn(f"build: '{out_dir}' was built with '{was}', rebuilding it with '{opt}'", stacklevel=2)
    if not out_dir.exists():
        raise BuildError(f"build: folder '{out_dir}' does not exist (generate it first with dopus-gen generate)")
    try:
        meta = read_meta(out_dir)
    except CodegenError as exc:
        raise BuildError(f"build: {exc}") from None
    try:
        name = meta["name"]
        strict = list(meta["sources"]["strict"])
        casadi_src = meta["sources"]["casadi"]
        listed = sorted(set(meta["files"]))
    except (KeyError, TypeError) as exc:
        raise BuildError(f"build: the meta data of '{out_dir}' lacks {exc}; regenerate the folder "
                         "with this version of dopus-gen") from None
    missing = [f for f in listed if not (out_dir / f).is_file()]
    if missing:
        raise BuildError(f"build: generated folder '{out_dir}' is incomplete, missing {', '.join(missing)}; "
                         "regenerate it")
    opt_flags = shlex.split(opt)
    digest = _source_hash(out_dir, listed, cc, opt_flags)

    out_dir = out_dir.resolve()  # the compiler runs inside the folder: absolute paths only
    bdir = out_dir / BUILD_SUBDIR
    shared_lib, static_lib = bdir / f"lib{name}.so", bdir / f"lib{name}.a"
    stamp = bdir / "stamp.json"
    result = BuildResult(shared_lib, static_lib, (out_dir / meta["cdef"]), name, out_dir, True)
    if not force and stamp.is_file() and shared_lib.is_file() and static_lib.is_file():
        try:
            if json.loads(stamp.read_text()).get("hash") == digest:
                return BuildResult(**{**result.__dict__, "rebuilt": False})
        except ValueError:
            pass

    root = cache.cache_root(cache_dir)
    # what an object depends on besides its source: the headers, and the module .c files that
    # the runtime's translation unit includes (every .c file that is not compiled on its own)
    compiled_alone = set(strict) | {casadi_src, meta["sources"].get("main")}
    headers = {f: (out_dir / f).read_bytes() for f in listed
               if f.endswith(".h") or (f.endswith(".c") and f not in compiled_alone)}
    objdir_final = bdir / "obj"
    objdir_final.mkdir(parents=True, exist_ok=True)
    tmpdir = Path(tempfile.mkdtemp(prefix="tmp_", dir=str(bdir)))
    compiled: List[str] = []
    try:
        objects, todo = [], []
        for src in strict + [casadi_src]:
            flags = [*opt_flags, PIC, *(CASADI_CFLAGS if src == casadi_src else STRICT_CFLAGS)]
            obj = objdir_final / (Path(src).stem + ".o")
            key = cache.object_key((out_dir / src).read_bytes(), headers, cc, flags)
            hit = None if force else cache.cached_object(root, key)
            if hit is not None:
                shutil.copyfile(hit, tmpdir / obj.name)
            else:
                todo.append((src, flags, key, tmpdir / obj.name))
            objects.append(obj)
        # the compilations that miss the cache run side by side, the largest source first
        todo.sort(key=lambda t: -(out_dir / t[0]).stat().st_size)
        for src, *_ in todo:
            say(f"dopus-gen build: compiling {out_dir / src}")

        def compile_one(job):
            src, flags, key, tmp_obj = job
            _run([cc, *flags, "-c", src, "-o", str(tmp_obj)], out_dir, f"compiling {src}")
            cache.store_object(root, key, tmp_obj)

        if todo:
            with ThreadPoolExecutor(max_workers=build_jobs(len(todo))) as pool:
                for future in [pool.submit(compile_one, job) for job in todo]:
                    future.result()
        compiled = [src for src in strict + [casadi_src] if any(src == t[0] for t in todo)]
        for obj in objects:
            os.replace(tmpdir / obj.name, obj)
        objects = [str(obj) for obj in objects]
        say(f"dopus-gen build: linking {shared_lib.name} and {static_lib.name} in {bdir}")
        tmp_a, tmp_so = tmpdir / static_lib.name, tmpdir / shared_lib.name
        _run([os.environ.get("AR", "ar"), "rcs", str(tmp_a), *objects], out_dir, f"archiving {static_lib.name}")
        _run([cc, "-shared", "-o", str(tmp_so), *objects, "-lm"], out_dir, f"linking {shared_lib.name}")
        os.replace(tmp_a, static_lib)
        os.replace(tmp_so, shared_lib)
        tmp_stamp = tmpdir / "stamp.json"
        tmp_stamp.write_text(json.dumps({"hash": digest, "cc": cc, "opt": opt_flags}, sort_keys=True) + "\n")
        os.replace(tmp_stamp, stamp)
    finally:
        shutil.rmtree(tmpdir, ignore_errors=True)
    return BuildResult(**{**result.__dict__, "compiled": compiled})


__all__ = ["build", "BuildResult", "BuildError", "BUILD_SUBDIR"]
