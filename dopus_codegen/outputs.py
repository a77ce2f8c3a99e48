"""Output paths checked before any long work starts.

A verb that writes a file (``--json``, ``--plot``) or a folder (``-o``, ``--plot-dir``)
checks the path first, so that a typo costs a second, not a finished study:

- a file: its folder must exist, be a folder and accept a new file; the path itself must not
  be a folder;
- a folder: an existing one must be a folder that accepts a new file; a missing one is
  created later with its missing parents, so the nearest existing ancestor must be a folder
  that accepts a new entry.

"Accepts" is tested by creating and removing a temporary entry, which holds for any user
(permission bits, read-only file systems, ``/proc``), root included.

Every output file is written atomically (:func:`atomic_file`, :func:`write_text`,
:func:`save_figure`): into a temporary file of the same folder, renamed over the target
when complete, so an interrupted command (Ctrl-C, a crash) leaves either the old file or
the new one, never a half-written one.
"""
from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path

__all__ = ["OutputPathError", "check_output_file", "check_output_dir", "atomic_file", "write_text", "write_bytes",
           "save_figure"]


class OutputPathError(ValueError):
    """An output path cannot be written; the message names the option, the path and why."""


def _probe(folder: Path, what: str, path) -> None:
    try:
        fd, name = tempfile.mkstemp(prefix=".dopus_probe_", dir=folder)
    except OSError as exc:
        raise OutputPathError(f"{what} '{path}': cannot write in the folder '{folder}' "
                              f"({exc.strerror or exc})") from None
    os.close(fd)
    os.unlink(name)


def check_output_file(path, what: str) -> Path:
    """``path`` as a Path if a file can be written there, else :class:`OutputPathError`."""
    p = Path(path)
    if str(path).strip() == "":
        raise OutputPathError(f"{what}: the path is empty")
    if p.is_dir():
        raise OutputPathError(f"{what} '{path}' is a folder, expected a file name")
    folder = p.parent if str(p.parent) else Path(".")
    if not folder.exists():
        raise OutputPathError(f"{what} '{path}': the folder '{folder}' does not exist")
    if not folder.is_dir():
        raise OutputPathError(f"{what} '{path}': '{folder}' is not a folder")
    _probe(folder, what, path)
    if p.exists() and not os.access(p, os.W_OK):
        raise OutputPathError(f"{what} '{path}': the file exists and is read-only")
    return p


def check_output_dir(path, what: str) -> Path:
    """``path`` as a Path if the folder exists and is writable, or can be created."""
    p = Path(path)
    if str(path).strip() == "":
        raise OutputPathError(f"{what}: the path is empty")
    if p.exists():
        if not p.is_dir():
            raise OutputPathError(f"{what} '{path}' exists and is not a folder")
        _probe(p, what, path)
        return p
    anc = p.absolute().parent
    while not anc.exists() and anc != anc.parent:
        anc = anc.parent
    if not anc.is_dir():
        raise OutputPathError(f"{what} '{path}': '{anc}' is a file, not a folder")
    _probe(anc, what, path)
    return p


def _file_mode(path: Path) -> int:
    """The permission bits a new file at ``path`` gets (those of the file it replaces)."""
    try:
        return path.stat().st_mode & 0o7777
    except OSError:
        mask = os.umask(0)
        os.umask(mask)
        return 0o666 & ~mask


@contextlib.contextmanager
def atomic_file(path, mode: str = "w"):
    """An open temporary file in the folder of ``path`` (``mode`` ``"w"`` or ``"wb"``),
    renamed to ``path`` when the block ends normally and removed when it raises (also on
    ``KeyboardInterrupt``)."""
    p = Path(path)
    folder = p.parent if str(p.parent) else Path(".")
    fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".part", dir=folder)
    try:
        with os.fdopen(fd, mode) as fh:
            yield fh
        os.chmod(tmp, _file_mode(p))
        os.replace(tmp, p)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def write_text(path, text: str) -> None:
    """``text`` into ``path``, atomically."""
    with atomic_file(path) as fh:
        fh.write(text)


def write_bytes(path, data: bytes) -> None:
    """``data`` into ``path``, atomically."""
    with atomic_file(path, "wb") as fh:
        fh.write(data)


def save_figure(fig, path, **kwargs) -> None:
    """``fig.savefig(path, **kwargs)``, atomically (the format from the file's suffix)."""
    fmt = kwargs.pop("format", None) or (Path(path).suffix.lstrip(".").lower() or "png")
    with atomic_file(path, "wb") as fh:
        fig.savefig(fh, format=fmt, **kwargs)
