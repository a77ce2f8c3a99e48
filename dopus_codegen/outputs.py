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
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

__all__ = ["OutputPathError", "check_output_file", "check_output_dir"]


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
