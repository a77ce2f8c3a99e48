"""Where the package finds its templates and the hand-written C runtime.

Both folders sit at the top level of the repository and are installed as
sub-packages ``dopus_codegen.templates`` and ``dopus_codegen.runtime_c``, so
the same lookup works from a checkout, an editable install and a wheel.
"""
from __future__ import annotations

import importlib.util
from pathlib import Path


def _package_dir(name: str, fallback: str) -> Path:
    spec = importlib.util.find_spec(name)
    if spec is not None and spec.submodule_search_locations:
        for loc in spec.submodule_search_locations:
            if Path(loc).is_dir():
                return Path(loc)
    path = Path(__file__).resolve().parents[1] / fallback
    if path.is_dir():
        return path
    raise FileNotFoundError(f"dopus_codegen: cannot locate the '{fallback}' folder of the installation")


def templates_dir() -> Path:
    """Folder holding the jinja2 templates (``*.j2``)."""
    return _package_dir("dopus_codegen.templates", "templates")


def runtime_c_dir() -> Path:
    """Folder holding the hand-written C runtime sources."""
    return _package_dir("dopus_codegen.runtime_c", "runtime_c")

