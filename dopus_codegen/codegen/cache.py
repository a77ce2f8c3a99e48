"""The build cache: generate and compile once per problem and build flags.

Location: ``--cache-dir`` of ``dopus-gen`` (any verb), else ``$DOPUS_CACHE_DIR``, else
``~/.cache/dopus-codegen``. It holds

- ``objects/<key>.o``: compiled objects, keyed by the sha256 of the source file, every
  header of its folder, the compiler (its path and ``--version`` output) and the flags;
  ``dopus-gen build``, ``Solver`` and every folder share them, so a file is compiled once;
- ``problems/<name>-<key>/``: the generated folders of the Python handle ``Solver``,
  keyed by :func:`problem_hash` (the problem's CasADi functions, data, runtime sources,
  templates and versions), so an unchanged problem is neither regenerated nor rebuilt.

Entries are written under temporary names and renamed, so concurrent users never see a
half-written file. Deleting the folder is always safe. A folder that cannot be written
(read-only, on a read-only file system, a file in its place) is named in a
:class:`CacheError` that points to ``--cache-dir`` where a command needs to write there
(:func:`writable_folder`); ``dopus-gen build`` works without writing to it.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import subprocess
import tempfile
from pathlib import Path
from typing import Any, Dict, Optional, Sequence

import numpy as np

from .. import __version__
from .folder import FUNCTION_SLOTS
from ..paths import runtime_c_dir, templates_dir

__all__ = ["cache_root", "problem_hash", "object_key", "cached_object", "store_object", "CacheError", "cache_error",
           "writable_folder"]

ENV_VAR = "DOPUS_CACHE_DIR"


def cache_root(cache_dir=None) -> Path:
    """``cache_dir``, else ``$DOPUS_CACHE_DIR``, else ``~/.cache/dopus-codegen``."""
    if cache_dir is not None:
        return Path(cache_dir)
    env = os.environ.get(ENV_VAR)
    return Path(env) if env else Path.home() / ".cache" / "dopus-codegen"


class CacheError(OSError):
    """The build cache folder cannot be written; the message names it and ``--cache-dir``."""


def cache_error(root, exc: OSError) -> CacheError:
    """The :class:`CacheError` of the cache folder ``root`` for the failure ``exc``."""
    why = exc.strerror or str(exc)
    if exc.filename is not None:
        why += f": '{exc.filename}'"
    return CacheError(f"the build cache folder '{root}' cannot be written ({why}); give a writable folder with "
                      f"--cache-dir (or ${ENV_VAR})")


def writable_folder(sub: str, cache_dir=None) -> Path:
    """The folder ``sub`` of the cache, created if needed and checked writable (by creating
    and removing a file, which holds for root too), else :class:`CacheError`."""
    root = cache_root(cache_dir)
    folder = root / sub
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".probe-", dir=str(folder))
        os.close(fd)
        os.unlink(probe)
    except OSError as exc:
        raise cache_error(root, exc) from None
    return folder


def _array_bytes(v) -> bytes:
    if v is None:
        return b"None"
    a = np.ascontiguousarray(np.asarray(v, dtype=float))
    return repr(a.shape).encode() + a.tobytes()


def problem_hash(disc: Any, offline_guess: Optional[bool] = None, real: Optional[str] = None) -> str:
    """A stable sha256 of everything the generated folder of ``disc`` depends on (its
    functions and data, the runtime sources, the templates and the emitter generate.py)."""
    h = hashlib.sha256()

    def put(tag: str, data: bytes) -> None:
        h.update(tag.encode() + b"\0" + data + b"\0")

    import casadi as ca     # here only: building and loading a generated folder needs no CasADi

    put("versions", f"{__version__} {ca.__version__}".encode())
    put("offline_guess", repr(offline_guess).encode())
    put("real", repr(real).encode())
    for slot, _ in FUNCTION_SLOTS:
        fun = getattr(disc, slot, None)
        put(slot, b"None" if fun is None else fun.serialize().encode())
    for key in ("name", "N", "dt", "nx", "nu", "np", "ng", "nr", "ne", "state_names", "control_names"):
        put(key, repr(getattr(disc, key, None)).encode())
    for key in ("lbx", "ubx", "lbu", "ubu", "lg", "ug", "lr", "ur", "p0", "x0"):
        put(key, _array_bytes(getattr(disc, key, None)))
    if getattr(disc, "has_soft", False):
        for key in ("soft_x", "soft_g", "soft_r"):
            put(key, _array_bytes(getattr(disc, key, None)))
    guess = getattr(disc, "initial_guess", None)
    put("guess_x", _array_bytes(getattr(guess, "x", None)))
    put("guess_u", _array_bytes(getattr(guess, "u", None)))
    put("options", json.dumps(getattr(disc, "options", {}) or {}, sort_keys=True, default=repr).encode())
    scaling = getattr(disc, "scaling", None)
    if scaling is not None:     # the generated functions and data are those of the scaled problem
        put("scaling", json.dumps(scaling.as_dict(), sort_keys=True).encode())
    for folder in (runtime_c_dir(), templates_dir()):
        for path in sorted(folder.iterdir()):
            if path.is_file() and path.suffix in (".c", ".h", ".j2"):
                put(path.name, path.read_bytes())
    # the emitter itself: a change of how the functions are written out regenerates
    for emitter in ("generate.py", "folder.py"):
        put(emitter, (Path(__file__).parent / emitter).read_bytes())
    return h.hexdigest()


_CC_IDS: Dict[str, str] = {}


def compiler_id(cc: str) -> str:
    """``cc --version`` (first line) and the resolved path, once per process."""
    if cc not in _CC_IDS:
        path = shutil.which(cc) or cc
        try:
            out = subprocess.run([cc, "--version"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                 text=True, check=False).stdout.splitlines()
            version = out[0] if out else ""
        except OSError:
            version = "unknown"
        _CC_IDS[cc] = f"{os.path.realpath(path)} {version}"
    return _CC_IDS[cc]


def object_key(source: bytes, headers: Dict[str, bytes], cc: str, flags: Sequence[str]) -> str:
    h = hashlib.sha256()
    h.update(json.dumps({"cc": compiler_id(cc), "flags": list(flags)}).encode() + b"\0")
    h.update(source + b"\0")
    for name in sorted(headers):
        h.update(name.encode() + b"\0" + headers[name] + b"\0")
    return h.hexdigest()


def cached_object(root: Path, key: str) -> Optional[Path]:
    path = Path(root) / "objects" / f"{key}.o"
    return path if path.is_file() else None


def store_object(root: Path, key: str, obj: Path) -> None:
    """Copy a freshly compiled object into the cache (atomic rename; a failure to write
    the cache is not an error of the build)."""
    try:
        folder = Path(root) / "objects"
        folder.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=".obj-", dir=str(folder))
        os.close(fd)
        shutil.copyfile(obj, tmp)
        os.replace(tmp, folder / f"{key}.o")
    except OSError:
        pass
