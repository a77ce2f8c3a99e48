"""Bad input through the OCP file and the command line: a one-line message naming the
problem and exit code 2, no traceback (unless --debug); a verb whose work failed exits 1 and
its JSON says which run failed.

The cases are tables: ``OCP_CASES`` (an OCP file with one mistake, run through a verb) and
``CLI_CASES`` (a good OCP file with a bad command line). Each asserts the message (a regular
expression) and the exit code. The numbers of the failing and the succeeding runs are
compared with the library called directly (the reference backend).
"""
from __future__ import annotations

import json
import os
import re
import textwrap
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from dopus_codegen import settings
from dopus_codegen.cli import main as cli_main

# A tiny problem: two states, one control, a stage-0 path constraint x0 + x1 <= 1.
BASE = '''
import casadi as ca
import numpy as np
from dopus_codegen import Ocp, Event
from dopus_codegen.problem.ocp import Integrator

NAME = "tiny"
X0 = [0.5, 0.0]


def build():
    ocp = Ocp(NAME)
    x = ocp.state("x", 2, lb=[-5, -10], ub=[5, 10])
    u = ocp.control("u", lb=-1, ub=1)
    ocp.dynamics(ca.vertcat(x[1], u - ca.sin(x[0])))
    ocp.stage_least_squares(ca.vertcat(x[0], u), weights=[1.0, 0.01])
    ocp.path_constraint(x[0] + x[1], ub=1.0)
    ocp.horizon(N=5, dt=0.05)
    ocp.initial_state(X0)
    ocp.disturbance(lambda x: x + np.array([0.1, 0.0]))
    ocp.scenario(duration=0.15, signals={"err": x[0]})
    return ocp
'''

KINSOL = '''
class Implicit(Integrator):
    """Implicit Euler through CasADi's kinsol rootfinder (which has no C code generation)."""

    def step(self, ode, x, u, p, h):
        z = ca.MX.sym("z", x.size1())
        xm = ca.MX.sym("xm", x.size1())
        um = ca.MX.sym("um", u.size1())
        G = ca.Function("G", [z, ca.vertcat(xm, um)], [z - xm - h * ode(z, um, ca.MX(0, 1))])
        return ca.rootfinder("euler_kinsol", "kinsol", G)(x, ca.vertcat(x, u))

    def describe(self):
        return "Implicit(kinsol)"
'''


def variant(*edits, extra: str = "") -> str:
    """BASE with (old, new) replacements (each must apply) and extra code appended."""
    text = BASE
    for old, new in edits:
        assert old in text, old
        text = text.replace(old, new)
    return text + textwrap.dedent(extra)


def invoke(args, debug=False):
    return CliRunner().invoke(cli_main, (["--debug"] if debug else []) + [str(a) for a in args])


def assert_message(res, pattern: str, code: int = 2):
    out = res.output
    assert res.exit_code == code, f"exit {res.exit_code}, expected {code}:\n{out}"
    assert re.search(pattern, out), f"no /{pattern}/ in:\n{out}"
    assert "Traceback" not in out
    # the reason is one line
    line = next(ln for ln in out.splitlines() if re.search(pattern, ln))
    assert line.startswith("Error:") or code == 2 and "Usage:" in out


@pytest.fixture()
def write(tmp_path):
    def _write(text, name="ocp.py"):
        p = tmp_path / name
        p.write_text(text)
        return p
    return _write


# --------------------------------------------------------------------------- OCP file
# (id, OCP text, verb and options, message pattern)
OCP_CASES = [
    ("name-250-characters", variant(('NAME = "tiny"', 'NAME = "a" * 250')), ["generate"],
     r"Ocp name: 'a{20}\.\.\.' is 250 characters long; at most 64 are allowed"),
    ("name-not-identifier", variant(('NAME = "tiny"', 'NAME = "my problem"')), ["generate"],
     r"Ocp name: 'my problem' is not a valid C identifier"),
    ("name-reserved", variant(('NAME = "tiny"', 'NAME = "main"')), ["generate"],
     r"'main' is not a valid C identifier \(a reserved word\)"),
    ("initial-state-violates-stage0-row", variant(("X0 = [0.5, 0.0]", "X0 = [0.5, 0.8]")),
     ["converge", "--start", "cold", "--iters", "2"],
     r"initial state x = \[0\.5 0\.8\] violates the stage-0 path constraints .*path constraint 0 "
     r"\(\(x_0\+x_1\)\) = 1\.3 > ub 1"),
    ("initial-state-violates-row-for-every-control",
     variant(("ocp.path_constraint(x[0] + x[1], ub=1.0)", "ocp.path_constraint(x[0] + 0.5 * u, ub=-0.1)")),
     ["converge", "--start", "cold", "--iters", "2"],
     r"path constraint 0 \(\(x_0\+\(0\.5\*u\)\)\) = [-0-9.e]+ > ub -0\.1 for the least-violating controls \[-1\.\]"),
    ("disturbed-state-violates-stage0-row",
     variant(("x + np.array([0.1, 0.0])", "x + np.array([0.1, 0.6])")), ["converge", "--iters", "2"],
     r"the disturbed initial state \(--start warm\) x = \[0\.6 0\.6\] violates .* = 1\.2 > ub 1"),
    ("scenario-x0-violates-stage0-row",
     variant(('signals={"err": x[0]})', 'signals={"err": x[0]}, x0=[0.9, 0.9])')),
     ["sil", "--backend", "reference"],
     r"the scenario's initial state x = \[0\.9 0\.9\] violates .* = 1\.8 > ub 1"),
    ("kinsol-rootfinder-at-generate",
     variant(("ocp.dynamics(ca.vertcat(x[1], u - ca.sin(x[0])))",
              "ocp.dynamics(ca.vertcat(x[1], u - x[0]), integrator=Implicit())"), extra=KINSOL),
     ["generate"],
     r"the CasADi function 'euler_kinsol' \(KinsolInterface\) has no C code generation; it is called by "
     r"'stage_eval'"),
    ("no-build", "x = 1\n", ["generate"], r"defines no build\(\) function"),
    ("syntax-error", "def build(:\n", ["generate"], r"line 1: syntax error"),
    ("build-raises", variant(("    ocp = Ocp(NAME)", "    ocp = Ocp(NAME)\n    1 / 0")), ["converge"],
     r"build\(\) failed: ZeroDivisionError: division by zero"),
    ("build-returns-no-ocp", variant(("    return ocp", "    return 3")), ["sil"],
     r"build\(\) returned int, expected an Ocp"),
    ("state-bound-order", variant(("lb=[-5, -10], ub=[5, 10]", "lb=[5, -10], ub=[-5, 10]")), ["generate"],
     r"lb > ub"),
    ("nan-initial-state", variant(("X0 = [0.5, 0.0]", "X0 = [float('nan'), 0.0]")), ["generate"],
     r"(?i)nan"),
    ("horizon-too-short", variant(("N=5", "N=1")), ["generate"], r"N"),
    ("negative-dt", variant(("dt=0.05", "dt=-0.05")), ["generate"], r"dt"),
    ("bench-float-build", variant(("    return ocp", "    ocp.options(real='float')\n    return ocp")),
     ["bench", "--quick"], r"dopus-gen bench times double builds only; the OCP file declares "
     r"options\(real='float'\)"),
    ("option-unknown-value", variant(("    return ocp", "    ocp.options(hessian='gn')\n    return ocp")),
     ["generate"], r"options: hessian must be 'exact' or 'gauss-newton', got 'gn'"),
    ("units-unknown-name", variant(('signals={"err": x[0]})', 'signals={"err": x[0]}, units={"speed": "m/s"})')),
     ["sil", "--backend", "reference"], r"scenario units: 'speed' is neither a signal nor a state or control"),
    ("units-empty", variant(('signals={"err": x[0]})', 'signals={"err": x[0]}, units={"err": ""})')),
     ["sil", "--backend", "reference"], r"scenario units: the unit of 'err' must be a non-empty string"),
    ("warm-start-without-disturbance",
     variant(("    ocp.disturbance(lambda x: x + np.array([0.1, 0.0]))\n", "")), ["converge"],
     r"--start warm needs a disturbance map"),
    ("gauss-newton-without-least-squares",
     variant(("ocp.stage_least_squares(ca.vertcat(x[0], u), weights=[1.0, 0.01])",
              "ocp.stage_cost(x[0]**2 + u**2)")), ["converge", "--hessian", "gauss-newton"],
     r"gauss-newton needs a least-squares stage cost"),
    ("sil-without-scenario", variant(('    ocp.scenario(duration=0.15, signals={"err": x[0]})\n', "")),
     ["sil", "--backend", "reference"], r"declares no closed-loop scenario"),
]


@pytest.mark.parametrize("case", OCP_CASES, ids=[c[0] for c in OCP_CASES])
def test_ocp_file_mistake(case, write, tmp_path):
    _id, text, verb, pattern = case
    f = write(text)
    args = [verb[0], f, *verb[1:]]
    if verb[0] == "generate":
        args += ["-o", tmp_path / "out"]
    res = invoke(args)
    assert_message(res, pattern)
    if verb[0] == "generate":
        assert not (tmp_path / "out").exists(), "nothing is written for a refused problem"


def test_debug_shows_the_traceback(write):
    f = write(variant(('NAME = "tiny"', 'NAME = "a" * 250')))
    res = invoke(["generate", f], debug=True)
    assert res.exit_code != 0 and "250 characters long" in str(res.exception)
    assert res.exc_info is not None and res.exc_info[2] is not None


# --------------------------------------------------------------------------- command line
def _not_writable(tmp_path):
    d = tmp_path / "ro"
    d.mkdir()
    d.chmod(0o500)
    return d


# (id, args with {ocp} and {tmp}, message pattern); everything must fail before any work.
CLI_CASES = [
    ("converge-json-missing-folder", ["converge", "{ocp}", "--json", "no/such/dir/x.json"],
     r"--json 'no/such/dir/x\.json': the folder 'no/such/dir' does not exist"),
    ("converge-json-is-folder", ["converge", "{ocp}", "--json", "{tmp}"], r"--json': File '.*' is a directory"),
    ("converge-plot-under-file", ["converge", "{ocp}", "--plot", "{ocp}/k.png"],
     r"--plot '.*ocp\.py/k\.png': '.*ocp\.py' is not a folder"),
    ("sil-json-missing-folder", ["sil", "{ocp}", "--json", "{tmp}/a/b/r.json"],
     r"--json '.*/a/b/r\.json': the folder '.*/a/b' does not exist"),
    ("sil-plot-dir-under-file", ["sil", "{ocp}", "--plot-dir", "{ocp}/plots"],
     r"--plot-dir '.*/plots': '.*ocp\.py' is a file, not a folder"),
    ("generate-output-under-file", ["generate", "{ocp}", "-o", "{ocp}/out"],
     r"--output '.*ocp\.py/out': '.*ocp\.py' is a file, not a folder"),
    ("generate-output-unwritable", ["generate", "{ocp}", "-o", "/proc/dopus_out"],
     r"--output '/proc/dopus_out': cannot write in the folder '/proc'"),
    ("firmware-output-under-file", ["firmware-report", "{ocp}", "-o", "{ocp}/fw"],
     r"--output '.*/fw': '.*ocp\.py' is a file, not a folder"),
    ("build-missing-folder", ["build", "{tmp}/nothing"], r"folder '.*nothing' does not exist"),
    ("qp-tol-negative", ["converge", "{ocp}", "--qp-tol", "-1"], r"qp_tol must be positive and finite, got -1"),
    ("qp-tol-nan", ["sil", "{ocp}", "--qp-tol", "nan"], r"qp_tol must be positive and finite, got nan"),
    ("qp-max-iter-zero", ["converge", "{ocp}", "--qp-max-iter", "0"], r"qp_max_iter must be an integer >= 1, got 0"),
    ("qp-max-iter-beyond-c-int", ["converge", "{ocp}", "--qp-max-iter", "2147483648"],
     r"qp_max_iter must be at most 2147483647 \(a C int\), got 2147483648"),
    ("qp-max-iter-text", ["sil", "{ocp}", "--qp-max-iter", "many"], r"'many' is not a valid integer"),
    ("reg-eps-zero", ["converge", "{ocp}", "--reg-eps", "0"], r"reg_eps must be positive and finite, got 0"),
    ("lm-negative", ["sil", "{ocp}", "--lm", "-1e-3"], r"lm must be finite and >= 0, got -0\.001"),
    ("hessian-misspelt", ["converge", "{ocp}", "--hessian", "gn"], r"'gn' is not one of 'exact', 'gauss-newton'"),
    ("cost-hessian-misspelt", ["sil", "{ocp}", "--cost-hessian", "old"], r"'old' is not one of 'stored', 'fresh'"),
    ("M-not-a-number", ["converge", "{ocp}", "--M", "full,x"], r"'x' is neither a non-negative integer nor 'full'"),
    ("M-beyond-horizon", ["converge", "{ocp}", "--M", "9"], r"M = 9 exceeds N-1 = 4"),
    ("iters-zero", ["converge", "{ocp}", "--iters", "0"], r"--iters"),
    ("tol-rel-zero", ["converge", "{ocp}", "--tol-rel", "0"], r"--tol-rel"),
    ("ocp-file-missing", ["converge", "{tmp}/none.py"], r"'.*none\.py' does not exist"),
    ("duration-negative", ["sil", "{ocp}", "--duration", "-1"], r"--duration"),
    ("unknown-verb", ["converg", "{ocp}"], r"No such command 'converg'"),
]


@pytest.mark.parametrize("case", CLI_CASES, ids=[c[0] for c in CLI_CASES])
def test_cli_mistake(case, write, tmp_path):
    _id, args, pattern = case
    f = write(BASE)
    args = [a.format(ocp=f, tmp=tmp_path) for a in args]
    res = invoke(args)
    assert_message(res, pattern)
    assert "DOPUS iterations" not in res.output and "preparing" not in res.output, "checked before the work"


@pytest.mark.skipif(os.geteuid() == 0, reason="permission bits do not stop root")
def test_unwritable_folder_by_permissions(write, tmp_path):
    f = write(BASE)
    d = _not_writable(tmp_path)
    try:
        assert_message(invoke(["converge", f, "--json", d / "x.json"]), r"cannot write in the folder")
        assert_message(invoke(["generate", f, "-o", d / "out"]), r"cannot write in the folder")
    finally:
        d.chmod(0o700)


def test_every_runtime_setting_is_a_flag_of_every_solver_verb():
    """The flags come from settings.RUNTIME_SETTINGS: each verb that runs the solver has all."""
    for verb in ("converge", "sil"):
        opts = {o for p in cli_main.commands[verb].params for o in p.opts}
        for name in settings.RUNTIME_SETTINGS:
            assert "--" + name.replace("_", "-") in opts, (verb, name)
        assert "--qp-tol" in opts and "--qp-max-iter" in opts


# --------------------------------------------------------------------------- failed work
def test_converge_failed_run_exits_1_and_has_no_solution(write, tmp_path):
    """--qp-max-iter 1: the first QP cannot be solved; the run is 'failed', the JSON has no
    solution (not the undisturbed initial iterate), the exit code is 1 with the reason."""
    f = write(BASE)
    out = tmp_path / "study.json"
    res = invoke(["converge", f, "--M", "1", "--iters", "3", "--qp-max-iter", "1", "--json", out])
    assert res.exit_code == 1, res.output
    assert re.search(r"Error: 1 of 1 runs failed: M = 1: in iteration 1: feedback: QP iteration limit 1", res.output)
    study = json.loads(out.read_text())
    (run,) = study["runs"]
    assert run["status"] == "failed" and "iteration limit" in run["message"]
    assert study["solution"] is None
    assert study["qp_max_iter"] == 1 and study["sources"]["qp_max_iter"] == "cli"


def test_converge_solution_comes_from_a_converged_run(write, tmp_path):
    """Good runs: status 'converged', exit 0; the solution is the full RTI's iterate and equals
    IPOPT's solution of the disturbed problem."""
    from dopus_codegen.problem.derivatives import build_functions
    from dopus_codegen.problem.ocp import load_ocp
    from dopus_codegen.reference.offline import solve_ocp

    f = write(BASE)
    out = tmp_path / "study.json"
    res = invoke(["converge", f, "--M", "full,1", "--iters", "8", "--json", out])
    assert res.exit_code == 0, res.output
    study = json.loads(out.read_text())
    assert [r["status"] for r in study["runs"]] == ["converged", "converged"]
    sol = study["solution"]
    assert sol["M"] == 4 and sol["converged"] is True and sol["kkt"] <= 1e-8
    disc = build_functions(load_ocp(f))
    ref, info = solve_ocp(disc, disc.disturbance(disc.x0))
    assert info["success"]
    assert np.max(np.abs(np.array(sol["u"]) - ref.u)) < 1e-6
    assert np.max(np.abs(np.array(sol["x"]) - ref.x)) < 1e-6


def test_run_study_marks_a_failed_run_and_takes_the_solution_elsewhere(write):
    """A failing full RTI and a converging M = 1: the solution is M = 1's, the failed run says
    where it failed; a study whose only run ran out of iterations marks its solution."""
    from dopus_codegen.errors import DopusError
    from dopus_codegen.problem.derivatives import build_functions
    from dopus_codegen.problem.ocp import load_ocp
    from dopus_codegen.reference.dopus import ReferenceDopus
    from dopus_codegen.studies.converge import run_study

    disc = build_functions(load_ocp(write(BASE)))

    class FailingFull(ReferenceDopus):
        def feedback(self, xhat0):
            if self.M == disc.N - 1:
                raise DopusError.of("qp", "feedback: planted failure", "numerical")
            return super().feedback(xhat0)

    study = run_study(disc, ["full", 1], 8, "cold", backend_factory=FailingFull)
    full, one = study["runs"]
    assert full["status"] == "failed" and full["message"].startswith("in iteration 1: feedback: planted failure")
    assert one["status"] == "converged"
    assert study["solution"]["M"] == 1 and study["solution"]["converged"] is True
    x_sol = np.array(study["solution"]["x"])
    assert not np.allclose(x_sol[1:], disc.x0), "a converged iterate, not the initial guess"
    short = run_study(disc, [1], 1, "cold")
    assert short["runs"][0]["status"] == "not converged"
    assert short["solution"]["converged"] is False and short["solution"]["status"] == "not converged"


def test_sil_aborted_plant_exits_1(write, tmp_path):
    """A plant whose right-hand side is NaN: CVODES fails; the run is 'aborted' in the JSON,
    the summary shows '-' instead of nan and the exit code is 1 with the reason."""
    f = write(variant(('signals={"err": x[0]})',
                       'signals={"err": x[0]}, plant=ca.vertcat(x[1], u + ca.sqrt(x[0] - 10)))')))
    out = tmp_path / "sil.json"
    res = invoke(["sil", f, "--backend", "reference", "--json", out])
    assert res.exit_code == 1, res.output
    assert re.search(r"Error: run 'DOPUS M = 1' aborted after 0 of 3 instants: plant failed .*CV_FIRST_RHSFUNC_ERR",
                     res.output)
    assert "nan" not in res.output.lower().replace("nan)", "")
    run = json.loads(out.read_text())["runs"][0]
    # the per-instant QP figures cover the feedback of the instant the plant failed in
    per_instant = {k: run["result"].pop(k) for k in ("qp_factorizations", "qp_iterations")}
    assert all(v["max"] >= 1 for v in per_instant.values()), per_instant
    assert run["result"] == {"status": "aborted", "instants": 0, "instants_planned": 3, "failed_instants": 0,
                             "first_failure": None, "recoveries": 0}


def test_sil_completed_run_and_qp_settings_reach_the_backend(write, tmp_path):
    """A completed closed loop exits 0 and records 'completed'; --qp-tol reaches the backend:
    the controls equal those of the reference backend driven by hand with that tolerance."""
    from dopus_codegen.problem.derivatives import build_functions
    from dopus_codegen.problem.ocp import load_ocp
    from dopus_codegen.reference.dopus import ReferenceDopus
    from dopus_codegen.reference.offline import solve_ocp
    from dopus_codegen.studies.plant import Plant

    f = write(BASE)
    out = tmp_path / "sil.json"
    res = invoke(["sil", f, "--backend", "reference", "--qp-tol", "1e-6", "--json", out])
    assert res.exit_code == 0, res.output
    run = json.loads(out.read_text())["runs"][0]
    assert run["result"]["status"] == "completed" and run["result"]["instants"] == 3
    assert run["settings"]["qp_tol"] == 1e-6 and run["settings"]["sources"]["qp_tol"] == "cli"
    disc = build_functions(load_ocp(f))
    be = ReferenceDopus(disc, M=1, mode="receding", qp_tol=1e-6)
    x = np.array(disc.x0, dtype=float)
    guess, _ = solve_ocp(disc, x)
    be.init(x, guess)
    plant = Plant(disc.ode, float(disc.dt), 0, reltol=1e-10, abstol=1e-10)
    us = []
    for _ in range(3):
        u0 = be.feedback(x)
        us.append(u0)
        x = plant.step(x, u0, np.zeros(0), duration=float(disc.dt))
        be.prepare()
    assert np.max(np.abs(np.array(run["u"]) - np.array(us))) < 1e-9


# --------------------------------------------------------------------------- non-smooth models
@pytest.mark.parametrize("expr, named", [
    ("u - ca.fabs(x[0])", r"fabs 'fabs\(x_0\)'"),
    ("u - ca.fmax(x[0], 0.1)", r"fmax 'fmax\(x_0,0\.1\)'"),
    ("ca.if_else(x[0] > 0, u, -u)", r"a comparison \(if_else\) '\(0<x_0\)'"),
])
def test_nonsmooth_model_is_warned(expr, named, write, tmp_path):
    f = write(variant(("u - ca.sin(x[0])", expr)))
    res = invoke(["generate", f, "-o", tmp_path / "out"])
    assert res.exit_code == 0, res.output
    assert re.search(r"warning: tiny: the dynamics has non-smooth operations: " + named, res.output), res.output


def test_smooth_examples_have_no_warning():
    from dopus_codegen.problem.checks import nonsmooth_terms
    from dopus_codegen.problem.ocp import load_ocp

    root = Path(__file__).resolve().parents[1]
    for name in ("robot_arm", "unicycle"):
        assert nonsmooth_terms(load_ocp(root / "examples" / f"{name}.py").validate()) == []


# --------------------------------------------------------------------------- QP status words
def test_qp_failure_text_matches_the_status():
    from dopus_codegen.errors import qp_failure_text

    assert qp_failure_text("max_iter", 100, 100, 1) == \
        "the QP solver reached its iteration limit of 100 after 100 iterations (QP status 1 (max_iter))"
    stalled = qp_failure_text("stalled", 12, 100)
    assert "stalled after 12 iterations" in stalled and "limit" not in stalled
    assert "infeasible" in qp_failure_text("primal_infeasible", 7)


def test_sil_infeasible_instant_names_the_row(write, tmp_path):
    """An event pushes the plant to a state that violates the stage-0 path constraint: that
    instant's QP is infeasible; the summary and the JSON name the row, its value and bound."""
    f = write(variant(('signals={"err": x[0]})',
                       'signals={"err": x[0]}, events=[Event(0.05, lambda x: np.array([0.9, 0.5]), "shove")])')))
    out = tmp_path / "sil.json"
    res = invoke(["sil", f, "--backend", "reference", "--json", out])
    assert res.exit_code == 0, res.output
    pattern = (r"first failed instant at t = 0\.05 s: .*QP is infeasible.*the measured state violates at stage 0: "
               r"path constraint 0 \(\(x_0\+x_1\)\) = 1\.4 > ub 1")
    assert re.search(pattern, res.output), res.output
    run = json.loads(out.read_text())["runs"][0]
    assert run["result"]["first_failure"]["t"] == pytest.approx(0.05)
    assert run["status"][1] != 0 and run["result"]["failed_instants"] >= 1
