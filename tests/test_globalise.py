"""The globalised first solve (docs/algorithm.md section 15).

- the crane of examples/crane.py (N = 32, the wall and the energy-like terminal set active)
  from its cold guess: the globalised solve converges to IPOPT's solution of the same NLP
  (1e-6), in both backends, and the C iterates equal the reference's step by step;
- a variant whose line search backtracks and whose QP becomes infeasible: both backends take
  the same step lengths and fail at the same step, and the message says what to try;
- the firmware entry dopus_init_globalised: the work limit, then the real-time loop from the
  converged iterate gives IPOPT's first control; bad limits are refused.
"""
from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from dopus_codegen.errors import DopusError
from dopus_codegen.problem.derivatives import build_functions
from dopus_codegen.reference.dopus import ReferenceDopus
from dopus_codegen.reference.offline import solve_ocp
from dopus_codegen.studies.converge import make_start, run_globalised
from dopus_codegen.settings import of_problem

CRANE = Path(__file__).resolve().parent.parent / "examples" / "crane.py"


def crane(**constants):
    spec = importlib.util.spec_from_file_location("crane_example", CRANE)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    for k, v in constants.items():
        setattr(mod, k, v)
    mod.W2 = mod.GRAV / mod.L
    return build_functions(mod.build())


@pytest.fixture(scope="module")
def disc():
    return crane()


@pytest.fixture(scope="module")
def c_solver():
    from dopus_codegen.runtime.solver import Solver

    return Solver


@pytest.fixture(scope="module")
def ipopt(disc):
    guess, info = solve_ocp(disc, np.array(disc.x0, float))
    assert info["success"]
    assert guess.mu_r[1] > 10.0 and guess.mu_r[0] > 1.0       # the terminal set and the wall at x_N active
    assert np.abs(guess.mu_g).max() > 1.0                       # the wall active on the path
    return guess


@pytest.mark.parametrize("backend", ["reference", "c"])
def test_crane_cold_start_converges_to_ipopt(disc, ipopt, c_solver, backend):
    factory = ReferenceDopus if backend == "reference" else c_solver
    start = make_start(disc, "cold")
    rec, (x, u) = run_globalised(disc, 30, start, of_problem(disc), factory, 1e-9)
    assert rec["status"] == "converged", rec["message"]
    assert rec["kkt"][0] > 10.0 and rec["kkt"][-1] <= 1e-9
    assert np.abs(x - ipopt.x).max() <= 1e-6 * (1 + np.abs(ipopt.x).max())
    assert np.abs(u - ipopt.u).max() <= 1e-6 * (1 + np.abs(ipopt.u).max())


def _steps(be, x0, n, tol=0.0):
    out = []
    be.init(x0)
    be.globalised_start()
    for _ in range(n):
        try:
            be.globalised_step(x0)
        except DopusError as exc:
            out.append(("failed", be.glob.reason, exc.status_name))
            break
        g = be.glob
        out.append((be.x.copy(), be.u.copy(), be.lam.copy(), be.mu_r.copy(), g.alpha, g.penalty, g.trials,
                    g.relaxed, g.restores))
        if tol > 0 and be.kkt(x0)["kkt"] <= tol:
            break
    return out


def _compare(ref, c):
    assert len(ref) == len(c)
    for a, b in zip(ref, c):
        if isinstance(a[0], str):
            assert a == b
            continue
        for va, vb in zip(a[:4], b[:4]):
            assert np.abs(va - vb).max(initial=0.0) <= 1e-6 * (1 + np.abs(va).max(initial=0.0))
        assert a[4] == b[4] and a[6:] == b[6:]          # the same step lengths, trials, watchdog
        assert b[5] == pytest.approx(a[5], rel=1e-6)


def test_c_equals_reference_step_by_step(disc, c_solver):
    x0 = np.array(disc.x0, float)
    N = disc.N
    ref = _steps(ReferenceDopus(disc, M=N - 1, mode="fixed"), x0, 8)
    c = _steps(c_solver(disc, M=N - 1, mode="fixed"), x0, 8)
    _compare(ref, c)


def test_watchdog_and_backtracking_alike(c_solver):
    """The figure-eight from its cold guess: relaxed full steps of the watchdog, returns to
    its point with a line search there, full steps at the end; both backends alike step by
    step, at IPOPT's solution (1e-6)."""
    from dopus_codegen.problem.ocp import load_ocp

    d = build_functions(load_ocp(str(CRANE.parent / "figure_eight.py")))
    x0 = np.array(d.x0, float)
    ref = _steps(ReferenceDopus(d, M=d.N - 1, mode="fixed"), x0, 40, tol=1e-9)
    c = _steps(c_solver(d, M=d.N - 1, mode="fixed"), x0, 40, tol=1e-9)
    _compare(ref, c)
    assert any(s[7] for s in ref) and ref[-1][8] >= 1 and any(s[4] < 1.0 for s in ref)
    assert all(s[4] == 1.0 and not s[7] for s in ref[-3:])      # full steps at the end
    sol, info = solve_ocp(d, x0)
    assert info["success"]
    assert np.abs(c[-1][0] - sol.x).max() <= 1e-6 * (1 + np.abs(sol.x).max())
    assert np.abs(c[-1][1] - sol.u).max() <= 1e-6 * (1 + np.abs(sol.u).max())


def test_failure_alike_with_advice(c_solver):
    """A transfer too far for its horizon (IPOPT too reports it infeasible): both backends end
    at an infeasible QP, and the study's message says what to try."""
    d = crane(TARGET=3.0, WALL=2.98, V_MAX=1.3, A_MAX=2.0, TRACK=1e-3)
    x0 = np.array(d.x0, float)
    ref = _steps(ReferenceDopus(d, M=d.N - 1, mode="fixed"), x0, 40)
    c = _steps(c_solver(d, M=d.N - 1, mode="fixed"), x0, 40)
    assert ref[-1][:2] == c[-1][:2] == ("failed", "qp")
    _, info = solve_ocp(d, x0)
    assert not info["success"]
    rec, _ = run_globalised(d, 40, make_start(d, "cold"), of_problem(d), ReferenceDopus, 1e-8)
    assert rec["status"] == "failed"
    assert "try a better guess" in rec["message"] and "soft terminal rows" in rec["message"]


def test_init_globalised_then_real_time_loop(disc, ipopt, c_solver):
    x0 = np.array(disc.x0, float)
    s = c_solver(disc, M=1, mode="receding")
    ref = ReferenceDopus(disc, M=1)
    assert s.init_globalised(x0, max_work=600.0) is False and ref.init_globalised(x0, max_work=600.0) is False
    assert s.glob.reason == ref.glob.reason == "work_limit"
    assert s.glob.iterations == ref.glob.iterations >= 1 and s.work == ref.work
    assert s.init_globalised(x0, max_iter=2) is False and s.glob.reason == "iter_limit"
    assert s.init_globalised(x0, tol=1e-9) is True
    assert s.glob.kkt <= 1e-9 and s.settings.mode == "receding"
    u0 = s.feedback(x0)
    assert np.abs(u0 - ipopt.u[0]).max() <= 1e-6
    assert ref.init_globalised(x0, tol=1e-9) is True
    assert np.abs(ref.u - s.u).max() <= 1e-6


@pytest.mark.parametrize("kw", [{"tol": 0.0}, {"tol": -1.0}, {"max_work": -1.0}, {"max_iter": -1}])
def test_bad_limits_are_refused(disc, c_solver, kw):
    x0 = np.array(disc.x0, float)
    for be in (ReferenceDopus(disc), c_solver(disc)):
        with pytest.raises(DopusError) as err:
            be.init_globalised(x0, **kw)
        assert err.value.status_name == "invalid_argument"


def test_converge_cold_runs_the_globalised_solve(tmp_path, ipopt):
    """``converge --start cold``: the globalised row, the JSON record and its iterate at IPOPT's
    solution; ``--no-globalise`` leaves it out."""
    import json

    from click.testing import CliRunner

    from dopus_codegen.cli import main

    out = tmp_path / "conv.json"
    res = CliRunner().invoke(main, ["converge", str(CRANE), "--start", "cold", "--M", "1", "--iters", "12",
                                    "--backend", "c", "--json", str(out)])
    assert res.exit_code == 0, res.output
    assert "glob." in res.output and "step lengths 1, 1" in res.output
    study = json.loads(out.read_text())
    g = study["globalised"]
    assert g["status"] == "converged" and g["kkt"][-1] <= 1e-8 and len(g["alpha"]) == len(g["kkt"]) - 1
    assert study["solution"]["M"] == 1      # the M run converged too: its iterate is the solution
    res = CliRunner().invoke(main, ["converge", str(CRANE), "--start", "cold", "--M", "1", "--iters", "2",
                                    "--backend", "c", "--no-globalise", "--json", str(out)])
    assert res.exit_code == 0, res.output
    assert "glob." not in res.output and json.loads(out.read_text())["globalised"] is None


def test_converge_says_what_to_try(tmp_path):
    """A transfer too far for its horizon: the globalised solve fails at an infeasible QP, the
    verb exits with 1 and names what to try."""
    from click.testing import CliRunner

    from dopus_codegen.cli import main

    ocp = tmp_path / "far_crane.py"
    ocp.write_text("import importlib.util\n"
                   f"spec = importlib.util.spec_from_file_location('crane_example', {str(CRANE)!r})\n"
                   "crane = importlib.util.module_from_spec(spec)\nspec.loader.exec_module(crane)\n"
                   "crane.TARGET, crane.WALL, crane.V_MAX, crane.A_MAX, crane.TRACK = 3.0, 2.98, 1.3, 2.0, 1e-3\n"
                   "build = crane.build\n")
    res = CliRunner().invoke(main, ["converge", str(ocp), "--start", "cold", "--M", "1", "--iters", "40",
                                    "--backend", "c"])
    assert res.exit_code == 1, res.output
    assert "M = globalised" in res.output and "terminal_set" in res.output
    assert "try a better guess" in res.output and "soft terminal rows" in res.output


@pytest.mark.parametrize("make", ["cart_l1", "orbit_l2", "reach_both"])
def test_soft_rows_priced_in_the_merit(make, c_solver):
    """Soft rows (a state bound with L1, a nonlinear path row with L2, a terminal equality and
    a state bound with both): the globalised solve from the cold guess reaches the solution of
    the independent IPOPT transcription with explicit slacks (1e-6), the C iterates equal to
    the reference's step by step."""
    import soft_problems

    disc = build_functions(getattr(soft_problems, make)())
    x0 = np.array(disc.x0, float)
    x_ref, u_ref, _ = soft_problems.ipopt_with_slacks(disc, x0)
    ref = _steps(ReferenceDopus(disc, M=disc.N - 1, mode="fixed"), x0, 6)
    c = _steps(c_solver(disc, M=disc.N - 1, mode="fixed"), x0, 6)
    _compare(ref, c)
    for factory in (ReferenceDopus, c_solver):
        rec, (x, u) = run_globalised(disc, 40, make_start(disc, "cold"), of_problem(disc).replace(qp_tol=1e-12),
                                     factory, 1e-11)
        assert rec["status"] == "converged", rec["message"]
        assert np.abs(x - x_ref).max() <= 1e-6 and np.abs(u - u_ref).max() <= 1e-6


@pytest.mark.parametrize("xhat, status", [(np.zeros(3), "invalid_argument"), ("abc", "invalid_argument"),
                                           ([0.0, np.nan, 0.0, 0.0], "nonfinite_input")])
def test_bad_state_is_refused(disc, c_solver, xhat, status):
    """A measured state of the wrong size, not numbers or not finite: a one-line error naming
    it, in both backends, and the iterate unchanged."""
    x0 = np.array(disc.x0, float)
    for be in (ReferenceDopus(disc, M=disc.N - 1, mode="fixed"), c_solver(disc, M=disc.N - 1, mode="fixed")):
        be.init(x0)
        before = be.x.copy()
        for call in (be.globalised_step, be.init_globalised):
            with pytest.raises(DopusError) as err:
                call(xhat)
            assert err.value.status_name == status and "\n" not in str(err.value) and "xhat0" in str(err.value)
            assert np.array_equal(be.x, before)
