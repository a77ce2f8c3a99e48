"""Build a generated folder: a shared library (for cffi) and a static library (firmware).

The runtime and the generated glue compile with the strict flags of the project
(``-std=c99 -Wall -Wextra -Werror -pedantic``); the CasADi file with ``-std=c99 -Wall``.
The products go to ``<folder>/build/py/`` (the folder's own Makefile uses ``build/``),
with a stamp holding a hash of the sources, the compiler and the flags: an unchanged
folder is not rebuilt. Outputs are written under temporary names and renamed, so a
concurrent build never leaves a half-written library behind.
"""
from __future__ import annotations

import hashlib
import json
import os
import shlex
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import List, Sequence

from .flags import CASADI_CFLAGS, DEFAULT_OPT, PIC, STRICT_CFLAGS
from .generate import CodegenError, read_meta

BUILD_SUBDIR = Path("build") / "py"


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


def build(out_dir, cc: str = "cc", opt: str = DEFAULT_OPT, *, force: bool = False) -> BuildResult:
    """Compile the generated folder ``out_dir``; skip the work if nothing changed."""
    out_dir = Path(out_dir)
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
        cdef_path = out_dir / meta["cdef"]
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

    bdir.mkdir(parents=True, exist_ok=True)
    objdir = Path(tempfile.mkdtemp(prefix="obj_", dir=str(bdir)))
    try:
        objects = []
        for src in strict + [casadi_src]:
            flags = CASADI_CFLAGS if src == casadi_src else STRICT_CFLAGS
            obj = objdir / (Path(src).stem + ".o")
            _run([cc, *opt_flags, PIC, *flags, "-c", src, "-o", str(obj)], out_dir, f"compiling {src}")
            objects.append(str(obj))
        tmp_a, tmp_so = objdir / static_lib.name, objdir / shared_lib.name
        _run([os.environ.get("AR", "ar"), "rcs", str(tmp_a), *objects], out_dir, f"archiving {static_lib.name}")
        _run([cc, "-shared", "-o", str(tmp_so), *objects, "-lm"], out_dir, f"linking {shared_lib.name}")
        os.replace(tmp_a, static_lib)
        os.replace(tmp_so, shared_lib)
        tmp_stamp = objdir / "stamp.json"
        tmp_stamp.write_text(json.dumps({"hash": digest, "cc": cc, "opt": opt_flags}, sort_keys=True) + "\n")
        os.replace(tmp_stamp, stamp)
    finally:
        shutil.rmtree(objdir, ignore_errors=True)
    return result


__all__ = ["build", "BuildResult", "BuildError", "BUILD_SUBDIR"]
