"""Where the lab finds the firmware program and the checkout's set-up scripts.

``firmware/`` sits at the top level of the repository and is installed as the sub-package
``dopus_lab.firmware_c``; ``scripts/`` (the set-up of acados' environment and of the Arm
toolchain) exists in a checkout only.
"""
from __future__ import annotations

import importlib.util
import subprocess
from pathlib import Path
from typing import Optional

#: The checkout the lab runs from (its parent folder in an installation, which has no scripts/).
ROOT = Path(__file__).resolve().parents[1]


def firmware_dir() -> Path:
    """Folder holding the bare-metal target (start-up code, linker script, the program)."""
    spec = importlib.util.find_spec("dopus_lab.firmware_c")
    if spec is not None and spec.submodule_search_locations:
        for loc in spec.submodule_search_locations:
            if Path(loc).is_dir():
                return Path(loc)
    path = ROOT / "firmware"
    if path.is_dir():
        return path
    raise FileNotFoundError("dopus_lab: cannot locate the 'firmware' folder of the installation")


def checkout_script(name: str) -> Optional[Path]:
    """``scripts/<name>`` of the checkout, or None in an installation (which has none)."""
    path = ROOT / "scripts" / name
    return path if path.is_file() else None


def checkout_commit() -> Optional[str]:
    """The checkout's HEAD as a short commit id (for a benchmark's JSON), or None outside a
    git checkout."""
    try:
        return subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None
