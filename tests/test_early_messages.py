"""Early, clear messages for two faults that used to surface late.

- A float build (``--real float``) of a problem with a number outside the range of float (a
  model constant of 1e-50 that would become 0, a weight above 3.4e38) is refused by
  ``generate`` with one line naming the number and where it is declared; before, ``generate``
  passed and the C compiler refused the folder at build ("floating constant truncated to
  zero"). The classification of a number is compared with the C compiler's own diagnostics
  (the independent reference), and a folder the check lets through compiles.
- A build cache that cannot be written names the cache folder and ``--cache-dir``; before:
  "Permission denied: '.../problems'".
"""
from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest
from click.testing import CliRunner

from dopus_codegen.cli import main
from dopus_codegen.codegen.flags import STRICT_CFLAGS
from dopus_codegen.problem.checks import outside_float

TINY = '''
import casadi as ca
from dopus_codegen import Ocp


def build():
    ocp = Ocp("tiny")
    x = ocp.state("x", 2, lb=[-5, -10], ub=[5, 10])
    u = ocp.control("u", lb=-1, ub=1)
    p = ocp.parameter("p", value={p})
    ocp.dynamics(ca.vertcat(x[1], u - {k} * ca.sin(x[0]) + p))
    ocp.stage_least_squares(ca.vertcat(x[0], u), weights=[1.0, {w}])
    ocp.path_constraint(x[0] + x[1], ub={g})
    ocp.horizon(N=5, dt=0.05)
    ocp.initial_state([0.5, 0.0])
    ocp.scenario(duration=0.1, signals={{"err": x[0]}})
    return ocp
'''
GOOD = dict(k="1.0", w="0.01", g="1.0", p="0.0")


def _ocp_file(tmp_path, **change) -> Path:
    path = tmp_path / "tiny.py"
    path.write_text(TINY.format(**dict(GOOD, **change)))
    return path


def test_the_float_range_agrees_with_the_c_compiler(tmp_path):
    """outside_float says 'below' or 'above' exactly for the literals the C compiler refuses
    in float ('truncated to zero', 'exceeds range')."""
    values = [1e-50, 1e-46, 7e-46, 1e-45, 1.5e-45, 1e-40, 1.2e-38, 1e-30, 1.0, 3.4e38, 3.5e38, 1e39, 1e300,
              -1e-50, -1e39, 0.0]
    src = tmp_path / "literals.c"
    src.write_text("".join(f"float a{i} = {v!r}f;\n" for i, v in enumerate(values)))
    diag = subprocess.run(["cc", "-std=c99", *STRICT_CFLAGS[1:], "-Wno-error", "-c", str(src), "-o",
                           str(tmp_path / "literals.o")], capture_output=True, text=True).stderr
    refused = {}
    for line in diag.splitlines():
        if "literals.c:" in line and ("truncated to zero" in line or "exceeds range" in line):
            row = int(line.split("literals.c:")[1].split(":")[0]) - 1
            refused[row] = "below" if "truncated to zero" in line else "above"
    assert refused, diag
    assert {i: outside_float(v) for i, v in enumerate(values) if outside_float(v)} == refused


@pytest.mark.parametrize("change, named", [
    (dict(k="1e-50"), "the constant 1e-50 in the model (ocp.dynamics) row 1 (below the range of float)"),
    (dict(w="1e45"), "the weight 1e+45 of stage least-squares term 0 (above the range of float)"),
    (dict(g="1e-60"), "the bound 1e-60 of path constraint 0 (below the range of float)"),
    (dict(p="1e-50"), "the parameter value 1e-50 (ocp.parameter) (below the range of float)"),
    # within float's range itself, but the derivatives hold its products with dt: 6.25e-47, ...
    (dict(k="1e-43"), "the generated functions hold numbers a float cannot: 6.25e-47 in tiny_stage_hess_exact "
                      "(below the range of float)"),
])
def test_a_float_build_names_the_number_outside_the_range(tmp_path, change, named):
    ocp_file = _ocp_file(tmp_path, **change)
    out = tmp_path / "float"
    res = CliRunner().invoke(main, ["generate", str(ocp_file), "-o", str(out), "--real", "float"])
    assert res.exit_code == 2, res.output
    assert res.output.startswith("Error: real float: ") and named in res.output
    assert "rescale the problem or use real='double'" in res.output
    assert len(res.output.strip().splitlines()) == 1 and not out.exists()
    # the double build holds the same numbers
    res = CliRunner().invoke(main, ["generate", str(ocp_file), "-o", str(tmp_path / "double")])
    assert res.exit_code == 0, res.output


def test_a_float_build_the_check_passes_compiles(tmp_path):
    """Numbers close to float's limits but inside them (a subnormal constant, a large bound,
    which becomes no bound): generated and compiled with -Werror."""
    ocp_file = _ocp_file(tmp_path, k="1e-30", g="1e39", w="1e30")
    out = tmp_path / "float"
    res = CliRunner().invoke(main, ["generate", str(ocp_file), "-o", str(out), "--real", "float"])
    assert res.exit_code == 0, res.output
    res = CliRunner().invoke(main, ["build", str(out)])
    assert res.exit_code == 0, res.output


def _unwritable_caches(tmp_path):
    a_file = tmp_path / "a_file"
    a_file.write_text("")
    cases = [a_file / "cache"]                  # a file where a folder of the path should be
    if Path("/sys").is_dir():
        cases.append(Path("/sys/dopus-cache"))  # a file system that refuses new entries, root included
    return cases


@pytest.mark.parametrize("verb", [["sil", "--duration", "0.1"], ["converge", "--backend", "c", "--iters", "2", "--start", "cold"]])
def test_an_unwritable_cache_names_the_folder_and_the_option(tmp_path, verb, monkeypatch):
    # --cache-dir sets $DOPUS_CACHE_DIR for the process: restored after the test
    monkeypatch.setenv("DOPUS_CACHE_DIR", os.environ.get("DOPUS_CACHE_DIR", ""))
    ocp_file = _ocp_file(tmp_path)
    for cache in _unwritable_caches(tmp_path):
        res = CliRunner().invoke(main, ["--cache-dir", str(cache), verb[0], str(ocp_file), *verb[1:]])
        assert res.exit_code == 2, res.output
        last = res.output.strip().splitlines()[-1]
        assert f"the build cache folder '{cache}' cannot be written (" in last, res.output
        assert "give a writable folder with --cache-dir (or $DOPUS_CACHE_DIR)" in last
        assert "Traceback" not in res.output
