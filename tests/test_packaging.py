"""A non-editable install carries the templates and the C runtime.

`pip install .` (not editable) must give a `dopus-gen` that finds its
templates and C sources from any directory. We install the project without
dependencies into a scratch folder and import it from there, run from a
different working directory, and compare the installed data files with the
repository's own.
"""
from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    target = tmp_path_factory.mktemp("site")
    build = tmp_path_factory.mktemp("build")
    # Build from a copy of the tracked files, as a fresh clone would: setuptools builds in the
    # source tree, so building the checkout itself would leave build/ and egg-info there, and
    # a stale build/lib from an earlier layout would be installed too.
    tracked = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    src = build / "src"
    for rel in filter(None, tracked.decode().split("\0")):
        if (ROOT / rel).is_file():
            (src / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / rel, src / rel)
    proc = subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-deps", "--no-build-isolation", "--no-compile",
         "-q", "--target", str(target), str(src)],
        capture_output=True, text=True, env={**os.environ, "PIP_NO_WARN_SCRIPT_LOCATION": "1"},
        cwd=str(build),
    )
    assert proc.returncode == 0, proc.stderr
    return target


def _run_installed(target: Path, code: str, cwd: Path) -> str:
    env = {**os.environ, "PYTHONPATH": str(target)}
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, cwd=str(cwd))
    assert proc.returncode == 0, proc.stderr
    return proc.stdout


def test_installed_package_finds_its_data(installed, tmp_path):
    out = _run_installed(
        installed,
        "import dopus_codegen, dopus_codegen.codegen.paths as p;"
        "print(dopus_codegen.__file__); print(p.templates_dir()); print(p.runtime_c_dir())",
        tmp_path,
    )
    pkg_file, tdir, rdir = (Path(line) for line in out.split())
    # Imported from the install, not from the checkout.
    assert Path(pkg_file).resolve().is_relative_to(installed.resolve())
    for installed_dir, repo_dir, patterns in (
        (tdir, ROOT / "templates", ("*.j2",)),
        (rdir, ROOT / "runtime_c", ("*.c", "*.h")),
    ):
        assert installed_dir.resolve().is_relative_to(installed.resolve())
        repo_files = sorted(f.name for pat in patterns for f in repo_dir.glob(pat))
        inst_files = sorted(f.name for pat in patterns for f in installed_dir.glob(pat))
        assert repo_files, f"no {patterns} files in {repo_dir}"
        assert inst_files == repo_files
        for name in repo_files:
            assert (installed_dir / name).read_bytes() == (repo_dir / name).read_bytes(), name


def test_installed_cli_help(installed, tmp_path):
    env = {**os.environ, "PYTHONPATH": str(installed)}
    proc = subprocess.run([sys.executable, "-m", "dopus_codegen.cli", "--help"], capture_output=True,
                          text=True, env=env, cwd=str(tmp_path))
    assert proc.returncode == 0, proc.stderr
    for verb in ("converge", "generate", "build", "sil"):
        assert verb in proc.stdout
