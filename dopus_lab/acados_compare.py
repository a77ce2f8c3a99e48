"""Drive acados from the project's environment: export, translate and build in acados' own
environment (a subprocess), solve there, and compare with our solution and IPOPT's.

The two CasADi versions never meet in one process: this module (project environment)
writes the export with ``acados_export``; ``acados_ocp.py`` runs under acados' Python
(``scripts/setup_acados.sh``) to build and solve. Built solvers are cached in
``WORK_DIR/<model name>-<hash of export and settings>``.
"""
from __future__ import annotations

import hashlib
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from .acados_export import write_export
from .paths import ROOT, checkout_script

__all__ = ["AcadosUnavailable", "acados_python", "export", "build", "solve", "ROOT", "TRANSLATOR"]

TRANSLATOR = Path(__file__).resolve().with_name("acados_ocp.py")
SETUP = checkout_script("setup_acados.sh")


class AcadosUnavailable(RuntimeError):
    """acados' environment could not be created (the message says why)."""


def acados_python() -> Path:
    """The Python of acados' environment, created by ``scripts/setup_acados.sh`` if needed."""
    if SETUP is None:
        raise AcadosUnavailable("acados' environment is made by scripts/setup_acados.sh of a checkout of "
                                "dopus-codegen (make bench-acados there); this installation has none")
    proc = subprocess.run(["bash", str(SETUP)], cwd=str(ROOT), stdout=subprocess.PIPE,
                          stderr=subprocess.PIPE, text=True, check=False)
    if proc.returncode != 0:
        raise AcadosUnavailable(f"scripts/setup_acados.sh failed (exit {proc.returncode}): "
                                f"{proc.stderr.strip()[-2000:]}")
    py = Path(proc.stdout.strip().splitlines()[-1])
    if not py.is_absolute():
        py = ROOT / py
    return py


def export(ocp_or_path, work_dir) -> Path:
    """Write the export JSON of an OCP (or OCP file) into ``work_dir``."""
    work_dir = Path(work_dir)
    work_dir.mkdir(parents=True, exist_ok=True)
    out = work_dir / "export.json"
    tmp = work_dir / f".export-{os.getpid()}.json"
    write_export(ocp_or_path, tmp)
    if out.is_file() and out.read_bytes() == tmp.read_bytes():
        tmp.unlink()
    else:
        os.replace(tmp, out)
    return out


def _run(py: Path, args: list, what: str) -> None:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME", "VIRTUAL_ENV")}
    proc = subprocess.run([str(py), str(TRANSLATOR), *map(str, args)], stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT, text=True, check=False, env=env)
    if proc.returncode != 0:
        raise RuntimeError(f"acados {what} failed (exit {proc.returncode}):\n{proc.stdout[-4000:]}")


def build(py: Path, export_json, settings: dict, work_dir) -> dict:
    """Build (or reuse) the acados solver of ``export_json`` with ``settings``; returns the
    ``solver.json`` information plus ``dir``."""
    export_json = Path(export_json)
    h = hashlib.sha256(export_json.read_bytes() + json.dumps(settings, sort_keys=True).encode()
                       + TRANSLATOR.read_bytes()).hexdigest()[:12]
    name = json.loads(export_json.read_text())["name"] + settings.get("suffix", "")
    out = Path(work_dir) / f"{name}-{h}"
    info_path = out / "solver.json"
    if not info_path.is_file():
        out.mkdir(parents=True, exist_ok=True)
        (out / "settings.json").write_text(json.dumps(settings, sort_keys=True))
        _run(py, ["build", export_json, out, out / "settings.json"], f"build of {name}")
    info = json.loads(info_path.read_text())
    info["dir"] = str(out)
    return info


def solve(py: Path, export_json, built: dict, xhat0, x, u, iterations: int = 1) -> dict:
    """Run the built solver from the primal guess ``x (N+1, nx)``, ``u (N, nu)`` with the
    initial state ``xhat0``: ``iterations`` calls of acados' solve (one SQP to its
    tolerance, or one RTI step each). Returns ``x``, ``u`` (arrays), ``status`` (per call),
    ``sqp_iter``, ``cost`` (acados' objective: ours, since the translation undoes the scaling)."""
    out = Path(built["dir"])
    start = {"xhat0": np.asarray(xhat0, float).tolist(), "x": np.asarray(x, float).tolist(),
             "u": np.asarray(u, float).tolist(), "iterations": int(iterations)}
    tag = hashlib.sha256(json.dumps(start).encode()).hexdigest()[:10]
    (out / f"start-{tag}.json").write_text(json.dumps(start))
    _run(py, ["solve", export_json, out, out / "settings.json", out / f"start-{tag}.json",
              out / f"result-{tag}.json"], "solve")
    res = json.loads((out / f"result-{tag}.json").read_text())
    res["x"], res["u"] = np.array(res["x"]), np.array(res["u"])
    return res


if __name__ == "__main__":  # pragma: no cover - manual use
    print(acados_python())
    sys.exit(0)
