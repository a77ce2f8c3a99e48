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

import numpy as np
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
        "import dopus_codegen, dopus_codegen.paths as p;"
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


def _copy_tracked(dest: Path) -> Path:
    """The tracked files of the checkout, as a fresh clone has them."""
    tracked = subprocess.run(["git", "ls-files", "-z"], cwd=ROOT, capture_output=True, check=True).stdout
    for rel in filter(None, tracked.decode().split("\0")):
        if (ROOT / rel).is_file():
            (dest / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / rel, dest / rel)
    return dest


def test_every_verb_from_a_fresh_install(tmp_path):
    """`pip install .[campaign]` (not editable) into a fresh virtual environment, then, from a
    folder outside the checkout: generate, build, converge, sil, campaign (2 runs on a dask
    worker) and bench exit 0, and the installed handle opens the generated folder with its
    generated settings. Minimal sizes: the point is the installation, not the numbers (pip
    and the build cache are reused)."""
    src = _copy_tracked(tmp_path / "src")
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True)
    py, gen = venv / "bin" / "python", venv / "bin" / "dopus-gen"
    proc = subprocess.run([str(py), "-m", "pip", "install", "-q", f"{src}[campaign]"], capture_output=True, text=True,
                          cwd=str(tmp_path), env={**os.environ, "PIP_DISABLE_PIP_VERSION_CHECK": "1"})
    assert proc.returncode == 0, proc.stderr[-3000:]
    work = tmp_path / "work"
    work.mkdir()
    example = str(src / "examples" / "robot_arm.py")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env["PATH"] = f"{venv / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    verbs = (
        ["generate", example, "-o", "out/robot_arm"],
        ["build", "out/robot_arm"],
        ["converge", example, "--M", "1", "--iters", "2", "--start", "warm", "--json", "conv.json"],
        ["sil", example, "--M", "1", "--duration", "0.1", "--json", "sil.json"],
        ["campaign", example, "--runs", "2", "--duration", "0.1", "--workers", "1", "--no-progress",
         "--out", "runs.jsonl", "--json", "campaign.json"],
        ["bench", example, "--M", "1", "--reps", "3", "--settle", "2", "--steps", "3", "--kkt-iters", "2",
         "--json", "bench.json"],
    )
    for args in verbs:
        proc = subprocess.run([str(gen), *args], capture_output=True, text=True, cwd=str(work), env=env,
                              timeout=1200)
        assert proc.returncode == 0, f"dopus-gen {args[0]}: {proc.stdout[-2000:]}{proc.stderr[-2000:]}"
    code = ("import dopus_codegen, dopus_lab.paths as lp; from dopus_codegen import Solver;"
            "s = Solver.load('out/robot_arm'); print(dopus_codegen.__file__); print(lp.firmware_dir());"
            "print(s.settings.hessian, s.settings.M)")
    proc = subprocess.run([str(py), "-c", code], capture_output=True, text=True, cwd=str(work), env=env)
    assert proc.returncode == 0, proc.stderr
    pkg_file, fw_dir, settings_line = proc.stdout.splitlines()[-3:]
    assert Path(pkg_file).resolve().is_relative_to(venv.resolve())          # the install, not the checkout
    assert sorted(p.name for p in Path(fw_dir).glob("*.c")) == sorted(p.name for p in (ROOT / "firmware").glob("*.c"))
    assert settings_line == "exact 1"                                     # examples/robot_arm.py's options


# Opening a generated folder needs no CasADi (nor the generator's other dependencies): a
# process in which importing them fails drives the generated solver through the handle.
_BLOCKED = '''
import sys
class _Blocked:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in ("casadi", "jinja2", "scipy", "matplotlib", "dask"):
            raise ImportError("blocked: " + name)
sys.meta_path.insert(0, _Blocked())
import numpy as np
from dopus_codegen import Solver
s = Solver.load(sys.argv[1], mode="fixed")
x0 = np.array([float(v) for v in sys.argv[2].split(",")])
s.init_nominal(x0)
for _ in range(3):
    u0 = s.feedback(x0); s.prepare()
print(" ".join(repr(float(v)) for v in u0), s.kkt(x0)["kkt"])
'''


def test_opening_a_generated_folder_needs_no_casadi(tmp_path):
    from dopus_codegen import Solver, build_functions, load_ocp

    folder = shutil.copytree(ROOT / "generated" / "unicycle", tmp_path / "unicycle",
                             ignore=shutil.ignore_patterns("build"))
    x0 = np.array(build_functions(load_ocp(ROOT / "examples" / "unicycle.py")).x0, dtype=float) + 0.05
    proc = subprocess.run([sys.executable, "-c", _BLOCKED, str(folder), ",".join(repr(float(v)) for v in x0)],
                          capture_output=True, text=True, cwd=str(tmp_path))
    assert proc.returncode == 0, proc.stderr
    *u0, kkt = (float(v) for v in proc.stdout.split())
    s = Solver.load(folder, mode="fixed")         # the same library in this process, CasADi loaded
    s.init_nominal(x0)
    for _ in range(3):
        want = s.feedback(x0)
        s.prepare()
    np.testing.assert_array_equal(u0, want)
    assert kkt == s.kkt(x0)["kkt"]
