"""One settings value: the OCP file is the source of every default, wherever the solver runs.

The acceptance case: an OCP file that declares Gauss-Newton and M = 3 gives Gauss-Newton
and M = 3 in the handle built from the file, the handle opened on its generated folder, the
generated main, and the ``sil`` and ``converge`` runs (printed summary and JSON, source
"ocp-file"), unless a flag overrides it (source "cli"); the runs are the same numbers as the
library called with those settings directly.
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


def _c_run(solver, x0, iters):
    """``iters`` fixed-mode iterations from the OCP file's guess at ``x0``: (u0, KKT) per iteration."""
    solver.init(x0)
    out = []
    for _ in range(iters):
        u0 = solver.feedback(x0)
        solver.prepare()
        out.append((*u0, solver.kkt(x0)["kkt"]))
    return np.array(out)


def test_one_settings_value_from_the_file_to_every_handle(ocp_file, tmp_path):
    """The acceptance case of the one settings value: options(hessian="gauss-newton", M=3)
    gives Gauss-Newton and M = 3 in the handle built from the file, the handle opened on its
    generated folder, the generated main, and `sil` and `converge` on the C backend; the
    numbers are those of a handle given Gauss-Newton and M = 3 explicitly, and not those of
    the exact Hessian."""
    import re
    import subprocess

    from dopus_codegen import Settings, Solver, build_functions, load_ocp

    disc = build_functions(load_ocp(ocp_file))
    from_file = Solver(disc)
    assert (from_file.settings.hessian, from_file.settings.M) == ("gauss-newton", 3)
    folder = tmp_path / "gn_three"
    res = CliRunner().invoke(cli_main, ["generate", str(ocp_file), "-o", str(folder)])
    assert res.exit_code == 0, res.output
    opened = Solver.load(folder)
    assert (opened.settings.hessian, opened.settings.M) == ("gauss-newton", 3)
    assert opened.settings == from_file.settings

    # the same numbers as a handle told Gauss-Newton and M = 3, other ones than the exact Hessian
    x0 = np.array(disc.x0, dtype=float)
    told = _c_run(Solver(disc, Settings(hessian="gauss-newton", M=3, mode="fixed")), x0, 6)
    np.testing.assert_array_equal(_c_run(Solver.load(folder, mode="fixed"), x0, 6), told)
    np.testing.assert_array_equal(_c_run(Solver(disc, mode="fixed"), x0, 6), told)
    # the setting matters: the runs are deterministic (equal settings, equal bits), and the
    # exact Hessian (on this nearly linear model close to Gauss-Newton) or the defaults differ
    for other in (Settings(hessian="exact", M=3, mode="fixed"), Settings(mode="fixed")):
        assert not np.array_equal(_c_run(Solver(disc, other), x0, 6), told)

    # the generated main (make alone) runs the generated defaults: its fixed-mode run from the
    # OCP file's guess is the handle's with Gauss-Newton and M = 3
    proc = subprocess.run(["make", "-s", "-C", str(folder), "run"], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    rows = [line.split() for line in proc.stdout.splitlines() if re.match(r"fixed [1-9]\d* status 0", line)]
    main = np.array([[float(v) for v in r[r.index("u0") + 1:r.index("kkt")]] + [float(r[r.index("kkt") + 1])]
                     for r in rows])
    assert len(main) >= 6          # the same objects (the build cache): the same bits, printed round-trip
    np.testing.assert_array_equal(main[:6], told)

    # sil and converge on the C backend
    out = tmp_path / "sil_c.json"
    res = CliRunner().invoke(cli_main, ["sil", str(ocp_file), "--backend", "c", "--json", str(out)])
    assert res.exit_code == 0, res.output
    run = json.loads(out.read_text())["runs"][0]
    assert (run["settings"]["hessian"], run["settings"]["M"]) == ("gauss-newton", 3)
    from dopus_codegen.reference.offline import solve_ocp
    from dopus_codegen.studies.sil import run_closed_loop

    guess, _ = solve_ocp(disc, disc.x0)
    direct = run_closed_loop(disc, backend="c", settings=Settings(hessian="gauss-newton", M=3), guess=guess)
    np.testing.assert_array_equal(np.array(run["u"]), np.array(direct["u"]))
    out = tmp_path / "conv_c.json"
    res = CliRunner().invoke(cli_main, ["converge", str(ocp_file), "--backend", "c", "--start", "cold",
                                        "--iters", "4", "--json", str(out)])
    assert res.exit_code == 0, res.output
    study = json.loads(out.read_text())
    assert study["hessian"] == "gauss-newton" and [r["M"] for r in study["runs"]] == [3]
    kkt = [k for k in told[:4, -1]]
    np.testing.assert_allclose(study["runs"][0]["kkt"][1:], kkt, rtol=1e-12, atol=0)
