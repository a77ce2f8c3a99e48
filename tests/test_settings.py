"""One settings vocabulary: the OCP file is the source of every default of the commands.

The acceptance case: an OCP file that declares Gauss-Newton and M = 3 gives a ``sil`` and a
``converge`` run with Gauss-Newton and M = 3 (printed summary and JSON, source "ocp-file"),
unless a flag overrides it (source "cli"); the runs are the same numbers as the library
called with those settings directly.
"""
from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from dopus_codegen import settings, vocabulary
from dopus_codegen.cli import main as cli_main

OCP_TEXT = '''
import casadi as ca
import numpy as np
from dopus_codegen import Ocp, Event


def build():
    ocp = Ocp("gn_three")
    x = ocp.state("x", 2)
    u = ocp.control("u", lb=-2.0, ub=2.0)
    ocp.dynamics(ca.vertcat(x[1], -0.5 * ca.sin(x[0]) + u))
    ocp.stage_least_squares(ca.vertcat(x, u), weights=[1.0, 0.1, 0.01])
    ocp.horizon(N=8, dt=0.05)
    ocp.initial_state([0.4, 0.0])
    ocp.disturbance(lambda x: x + np.array([0.05, 0.0]))
    ocp.scenario(duration=0.2, events=[Event(0.1, lambda x: x + np.array([0.1, 0.0]), "kick")],
                 signals={"angle": x[0]})
    ocp.options(hessian="gauss-newton", M=3)
    return ocp
'''


@pytest.fixture(scope="module")
def ocp_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("settings") / "gn_three.py"
    path.write_text(OCP_TEXT)
    return path


def test_enumerated_settings_are_the_c_enums():
    """The allowed values are the members of the C enums, spelled with '-'; one spelling."""
    assert dict(zip(settings.choices("hessian"), range(2))) == {
        k.replace("_", "-"): v for k, v in vocabulary.enum("dopus_hessian").codes.items()}
    assert settings.code("regularization", "mirror") == vocabulary.enum("dopus_regularization")["mirror"]
    assert settings.value_of("mode", vocabulary.enum("dopus_mode")["fixed"]) == "fixed"
    for bad in ("gn", "Gauss-Newton", None):
        with pytest.raises(settings.SettingError, match="hessian must be 'exact' or 'gauss-newton'"):
            settings.check("hessian", bad)
    for v in (0.0, -1.0, float("nan"), float("inf"), "x", True):
        with pytest.raises(settings.SettingError, match="reg_eps must be"):
            settings.positive("reg_eps", v)
    assert settings.positive("reg_eps", "1e-3") == 1e-3
    assert settings.nonnegative("lm", 0) == 0.0
    with pytest.raises(settings.SettingError, match="M must be an integer >= 0"):
        settings.count("M", 1.5)


def test_resolve_precedence():
    values, sources = settings.resolve({"hessian": "gauss-newton", "M": 3}, {"M": 2, "lm": None})
    assert set(values) == set(settings.SOLVER_SETTINGS)
    assert (values["hessian"], sources["hessian"]) == ("gauss-newton", "ocp-file")
    assert (values["M"], sources["M"]) == (2, "cli")
    assert (values["lm"], sources["lm"]) == (settings.DEFAULTS["lm"], "default")
    with pytest.raises(settings.SettingError, match="regularization"):
        settings.resolve({"regularization": "clip"}, {})


def test_gn_alias_is_rejected_everywhere(ocp_file):
    """No alias: 'gn' is refused by the OCP API, both backends and the command line."""
    from dopus_codegen import Ocp, build_functions, load_ocp
    from dopus_codegen.errors import DopusError, status_code
    from dopus_codegen.problem.ocp import OcpError
    from dopus_codegen.reference.dopus import ReferenceDopus

    with pytest.raises(OcpError, match="options: hessian must be"):
        Ocp("a").options(hessian="gn")
    disc = build_functions(load_ocp(ocp_file))
    with pytest.raises(DopusError, match="hessian must be") as ei:
        ReferenceDopus(disc, hessian="gn")
    assert ei.value.status == status_code("invalid_argument")
    res = CliRunner().invoke(cli_main, ["sil", str(ocp_file), "--hessian", "gn"])
    assert res.exit_code != 0 and "'gn' is not one of 'exact', 'gauss-newton'" in res.output


def _sil(ocp_file, tmp_path, *flags):
    out = tmp_path / "sil.json"
    res = CliRunner().invoke(cli_main, ["sil", str(ocp_file), "--backend", "reference", "--json", str(out),
                                        *flags])
    assert res.exit_code == 0, res.output
    return res.output, json.loads(out.read_text())["runs"]


def test_sil_starts_from_the_ocp_file(ocp_file, tmp_path):
    from dopus_codegen import build_functions, load_ocp
    from dopus_codegen.reference.offline import solve_ocp
    from dopus_codegen.studies.sil import run_closed_loop

    output, runs = _sil(ocp_file, tmp_path)
    st = runs[0]["settings"]
    assert (st["hessian"], st["M"]) == ("gauss-newton", 3)
    assert st["sources"]["hessian"] == "ocp-file" and st["sources"]["M"] == "ocp-file"
    assert st["sources"]["lm"] == "default" and st["lm"] == 0.0
    assert "hessian gauss-newton (ocp-file)" in output and "M 3 (ocp-file)" in output
    # the same numbers as the library with Gauss-Newton and M = 3 given explicitly
    disc = build_functions(load_ocp(ocp_file))
    guess, _ = solve_ocp(disc, disc.x0)
    direct = run_closed_loop(disc, backend="reference", M=3, hessian="gauss-newton", guess=guess)
    np.testing.assert_array_equal(np.array(runs[0]["u"]), np.array(direct["u"]))
    exact = run_closed_loop(disc, backend="reference", M=3, hessian="exact", guess=guess)
    assert np.max(np.abs(np.array(exact["u"]) - np.array(direct["u"]))) > 1e-9  # the setting matters

    output, runs = _sil(ocp_file, tmp_path, "--M", "2", "--hessian", "exact")
    st = runs[0]["settings"]
    assert (st["hessian"], st["M"]) == ("exact", 2)
    assert st["sources"]["hessian"] == "cli" and st["sources"]["M"] == "cli"
    assert "hessian exact (cli)" in output and "M 2 (cli)" in output


def _converge(ocp_file, tmp_path, *flags):
    out = tmp_path / "conv.json"
    res = CliRunner().invoke(cli_main, ["converge", str(ocp_file), "--start", "cold", "--json", str(out), *flags])
    assert res.exit_code == 0, res.output
    return res, json.loads(out.read_text())


def test_converge_starts_from_the_ocp_file(ocp_file, tmp_path):
    from dopus_codegen import build_functions, load_ocp
    from dopus_codegen.studies.converge import run_study

    res, study = _converge(ocp_file, tmp_path, "--iters", "4")
    assert study["hessian"] == "gauss-newton" and [r["M"] for r in study["runs"]] == [3]
    assert study["sources"]["hessian"] == "ocp-file" and study["sources"]["M"] == "ocp-file"
    assert "hessian gauss-newton (ocp-file)" in res.output and "M 3 (ocp-file)" in res.output
    assert "gauss-newton Hessian" in res.output
    disc = build_functions(load_ocp(ocp_file))
    direct = run_study(disc, [3], 4, "cold", hessian="gauss-newton")
    np.testing.assert_allclose(study["runs"][0]["kkt"], direct["runs"][0]["kkt"], rtol=1e-12, atol=0)

    res, study = _converge(ocp_file, tmp_path, "--iters", "2", "--M", "1", "--hessian", "exact")
    assert study["hessian"] == "exact" and [r["M"] for r in study["runs"]] == [1]
    assert study["sources"]["hessian"] == "cli" and study["sources"]["M"] == "cli"
