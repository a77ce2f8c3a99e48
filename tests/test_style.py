"""The checked-in formatter and linter configuration holds for the tree: ruff's lint rules
(pyproject.toml [tool.ruff]) over the Python sources, and clang-format (.clang-format) over
the hand-written C of runtime_c/ and firmware/ (one brace style)."""
from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PY_DIRS = ("dopus_codegen", "tests", "bench", "examples")


def _tool(name: str) -> str:
    exe = shutil.which(name) or str(Path(sys.executable).parent / name)
    if not Path(exe).exists():
        pytest.fail(f"{name} is not installed (make setup installs it: scripts/bootstrap.sh)")
    return exe


def test_ruff_lint_clean():
    proc = subprocess.run([_tool("ruff"), "check", "--no-cache", *PY_DIRS], cwd=ROOT,
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_c_sources_are_clang_formatted():
    files = sorted(str(p.relative_to(ROOT)) for d in ("runtime_c", "firmware")
                   for p in (ROOT / d).glob("*.[ch]"))
    assert files
    proc = subprocess.run([_tool("clang-format"), "--style=file", "--dry-run", "--Werror", *files],
                          cwd=ROOT, capture_output=True, text=True)
    assert proc.returncode == 0, "not clang-formatted (run clang-format -i on them):\n" + proc.stderr[:4000]
