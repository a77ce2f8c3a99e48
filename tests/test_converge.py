"""The fixed-xhat_0 convergence study (paper figure 1) and ``dopus-gen converge``.

The warm-start table of docs/design.md section 8 (the paper's literal algorithm,
``cost_hessian="stored"``) is reproduced with the reference backend and checked against
independent numbers: the KKT measure of the IPOPT point, and IPOPT's own solution for the
disturbed initial state. The default ``cost_hessian="fresh"`` (docs/algorithm.md section 4
step 5) is held to the same iteration bounds.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from dopus_codegen.cli import main
from dopus_codegen.studies.converge import StartPoint, format_table, iterations_to, run_study
from dopus_codegen.reference.kkt import kkt_of_guess

ROBOT_ARM_FILE = Path(__file__).resolve().parent.parent / "examples" / "robot_arm.py"


@pytest.fixture(scope="module")
def warm_study(robot_disc, robot_solution):
    d = robot_disc
    sol, _ = robot_solution
    start = StartPoint("warm", d.x0, sol, d.disturbance(d.x0))
    return run_study(d, ["full", 20, 10, 5, 2, 1, 0], 40, start, hessian="exact", regularization="none",
                     cost_hessian="stored", lm=0.0)


@pytest.fixture(scope="module")
def warm_study_fresh(robot_disc, robot_solution):
    d = robot_disc
    sol, _ = robot_solution
    start = StartPoint("warm", d.x0, sol, d.disturbance(d.x0))
    return run_study(d, ["full", 5, 1], 40, start, hessian="exact", regularization="none", lm=0.0)


@pytest.fixture(scope="module")
def disturbed_ipopt(robot_disc, robot_solution):
    from dopus_codegen.reference.offline import solve_ocp

    d = robot_disc
    sol, info = solve_ocp(d, d.disturbance(d.x0), guess=robot_solution[0])
    assert info["success"]
    return sol, info


def test_warm_start_table(robot_disc, robot_solution, warm_study, disturbed_ipopt):
    d = robot_disc
    runs = {r["M"]: r for r in warm_study["runs"]}
    full = runs[d.N - 1]
    print("\n" + format_table(warm_study))
    print("full RTI KKT sequence: " + " ".join("%.1e" % k for k in full["kkt"][:10]))
    assert all(r["status"] != "failed" for r in warm_study["runs"])
    # kkt[0] is the IPOPT point measured against the disturbed initial state
    k0 = kkt_of_guess(d, d.disturbance(d.x0), robot_solution[0])["kkt"]
    assert all(abs(r["kkt"][0] - k0) <= 1e-12 * k0 for r in warm_study["runs"])
    assert iterations_to(full["kkt"], 1e-10) <= 8
    assert iterations_to(runs[5]["kkt"], 1e-8) <= 20
    assert iterations_to(runs[1]["kkt"], 1e-8) <= 40
    # paper figure 1: the fewer stages re-linearised, the slower (M = 0 never gets there)
    its = [iterations_to(runs[M]["kkt"], 1e-8) for M in (d.N - 1, 20, 10, 5, 2, 1)]
    assert its == sorted(its)
    assert iterations_to(runs[0]["kkt"], 1e-8) is None
    # the full-RTI iterate is IPOPT's solution for the disturbed state
    sol, info = disturbed_ipopt
    x = np.array(warm_study["solution"]["x"])
    u = np.array(warm_study["solution"]["u"])
    assert warm_study["solution"]["M"] == d.N - 1
    assert max(np.max(np.abs(x - sol.x)), np.max(np.abs(u - sol.u))) < 1e-6
    assert abs(warm_study["solution"]["objective"] - info["objective"]) < 1e-8


def test_warm_start_fresh_cost_hessian(robot_disc, robot_solution, warm_study, warm_study_fresh, disturbed_ipopt):
    """The default cost_hessian='fresh': the same bounds as the paper's algorithm; with
    every stage re-linearised (the full RTI) it is the same iteration, bit for bit."""
    d = robot_disc
    assert warm_study_fresh["cost_hessian"] == "fresh" and warm_study["cost_hessian"] == "stored"
    runs = {r["M"]: r for r in warm_study_fresh["runs"]}
    stored = {r["M"]: r for r in warm_study["runs"]}
    print("\n" + format_table(warm_study_fresh))
    assert all(r["status"] != "failed" for r in warm_study_fresh["runs"])
    assert runs[d.N - 1]["kkt"] == stored[d.N - 1]["kkt"]
    assert iterations_to(runs[d.N - 1]["kkt"], 1e-10) <= 8
    assert iterations_to(runs[5]["kkt"], 1e-8) <= 20
    assert iterations_to(runs[1]["kkt"], 1e-8) <= 40
    # partial updates are not the full RTI: M = 1 differs from the first iterations on
    assert runs[1]["kkt"][2] != stored[1]["kkt"][2]
    # the full-RTI iterate is IPOPT's solution for the disturbed state
    sol, info = disturbed_ipopt
    x = np.array(warm_study_fresh["solution"]["x"])
    u = np.array(warm_study_fresh["solution"]["u"])
    assert max(np.max(np.abs(x - sol.x)), np.max(np.abs(u - sol.u))) < 1e-6


def test_levenberg_marquardt_keeps_the_solution(robot_disc, robot_solution, disturbed_ipopt):
    """lm = 1e-4 (the closed-loop default) changes the steps, not the fixed point: the C
    backend's full RTI and DOPUS M = 1 reach IPOPT's solution for the disturbed state, at a
    linear rate (against quadratic without the term): the weakest reduced curvature of the
    robot arm is about 2e-5, so that direction contracts by about lm / (2e-5 + lm) = 0.83 per
    iteration, and 200 iterations are needed for a 1e-6 comparison."""
    from dopus_codegen.runtime.solver import CSolver

    d = robot_disc
    sol0, _ = robot_solution
    start = StartPoint("warm", d.x0, sol0, d.disturbance(d.x0))

    def factory(disc, **kw):
        return CSolver(disc, qp_tol=1e-13, **kw)

    sol, info = disturbed_ipopt
    for M in ("full", 1):
        study = run_study(d, [M], 200, start, hessian="exact", backend_factory=factory, backend_name="c", lm=1e-4)
        run = study["runs"][0]
        assert run["status"] == "converged"
        it = iterations_to(run["kkt"], 1e-8)
        assert it is not None and it > 8, run["kkt"]      # slower than exact Newton ...
        assert run["kkt"][-1] < 1e-11, run["kkt"][-1]
        x = np.array(study["solution"]["x"])
        u = np.array(study["solution"]["u"])
        assert max(np.max(np.abs(x - sol.x)), np.max(np.abs(u - sol.u))) < 1e-6   # ... same point
        print(f"\nlm = 1e-4, M = {M}: KKT <= 1e-8 at iteration {it}")


def test_kkt_parts_are_consistent(warm_study):
    for r in warm_study["runs"]:
        parts = np.array([r["stat"], r["eq"], r["ineq"], r["comp"]])
        np.testing.assert_array_equal(parts.max(axis=0), np.array(r["kkt"]))


def test_converge_cli_warm(tmp_path, robot_disc, warm_study):
    out_json, out_png = tmp_path / "study.json", tmp_path / "study.png"
    res = CliRunner().invoke(main, ["converge", str(ROBOT_ARM_FILE), "--M", "full,1", "--iters", "6", "--lm", "0",
                                    "--cost-hessian", "stored", "--json", str(out_json), "--plot", str(out_png)])
    assert res.exit_code == 0, res.output
    study = json.loads(out_json.read_text())
    assert study["problem"] == "robot_arm" and study["N"] == robot_disc.N
    assert study["backend"] == "reference" and study["start"] == "warm"
    assert study["cost_hessian"] == "stored"
    assert [r["M"] for r in study["runs"]] == [robot_disc.N - 1, 1]
    # the CLI reproduces the library study (same IPOPT start, same iteration)
    ref = {r["M"]: r for r in warm_study["runs"]}
    for r in study["runs"]:
        assert len(r["kkt"]) == 7
        np.testing.assert_allclose(r["kkt"], ref[r["M"]]["kkt"][:7], rtol=1e-6, atol=1e-13)
    assert out_png.stat().st_size > 10000
    assert "iters to" in res.output


def test_converge_cli_fresh_is_the_default(tmp_path, warm_study_fresh):
    out_json = tmp_path / "fresh.json"
    res = CliRunner().invoke(main, ["converge", str(ROBOT_ARM_FILE), "--M", "1", "--iters", "4", "--lm", "0",
                                    "--json", str(out_json)])
    assert res.exit_code == 0, res.output
    study = json.loads(out_json.read_text())
    assert study["cost_hessian"] == "fresh" and "cost Hessian fresh" in res.output
    ref = {r["M"]: r for r in warm_study_fresh["runs"]}
    np.testing.assert_allclose(study["runs"][0]["kkt"], ref[1]["kkt"][:5], rtol=1e-6, atol=1e-13)


def test_converge_cli_bad_input(tmp_path):
    runner = CliRunner()
    res = runner.invoke(main, ["converge", str(ROBOT_ARM_FILE), "--M", "45", "--iters", "2"])
    assert res.exit_code != 0 and "exceeds N-1" in res.output
    res = runner.invoke(main, ["converge", str(ROBOT_ARM_FILE), "--M", "full,x"])
    assert res.exit_code != 0 and "'x'" in res.output
    res = runner.invoke(main, ["converge", str(ROBOT_ARM_FILE), "--cost-hessian", "always"])
    assert res.exit_code != 0 and "cost-hessian" in res.output
    ocp = tmp_path / "no_ls.py"
    ocp.write_text(
        "import casadi as ca\nfrom dopus_codegen import Ocp\n\n"
        "def build():\n"
        "    ocp = Ocp('no_ls')\n"
        "    x = ocp.state('x')\n"
        "    u = ocp.control('u', lb=-1, ub=1)\n"
        "    ocp.dynamics(u - x)\n"
        "    ocp.stage_cost(x**2 + u**2)\n"
        "    ocp.horizon(N=5, dt=0.1)\n"
        "    ocp.initial_state([1.0])\n"
        "    return ocp\n")
    res = runner.invoke(main, ["converge", str(ocp), "--hessian", "gauss-newton", "--start", "cold"])
    assert res.exit_code != 0 and "least-squares" in res.output
    res = runner.invoke(main, ["converge", str(ocp), "--start", "warm"])
    assert res.exit_code != 0 and "disturbance" in res.output


def test_cold_start_study_no_ls_problem_matches_ipopt(tmp_path):
    """run_study on a small problem built here: the cold full RTI reaches IPOPT's optimum."""
    import casadi as ca

    from dopus_codegen import Ocp, build_functions
    from dopus_codegen.reference.offline import solve_ocp

    ocp = Ocp("small")
    x = ocp.state("x", 2)
    u = ocp.control("u", lb=-1, ub=1)
    ocp.dynamics(ca.vertcat(x[1], u - ca.sin(x[0])))
    ocp.stage_cost(x[0] ** 2 + 0.1 * x[1] ** 2 + 0.01 * u ** 2)
    ocp.horizon(N=15, dt=0.1)
    ocp.initial_state([1.0, 0.0])
    d = build_functions(ocp)
    study = run_study(d, ["full", 3], 30, "cold")
    sol, info = solve_ocp(d, d.x0)
    assert info["success"]
    full = study["runs"][0]
    assert full["kkt"][-1] < 1e-10
    assert np.max(np.abs(np.array(study["solution"]["u"]) - sol.u)) < 1e-6
    assert abs(study["solution"]["objective"] - info["objective"]) < 1e-9
    # the control bound is active at the optimum, so the active-set handling is exercised
    assert np.any(np.isclose(np.abs(sol.u), 1.0, atol=1e-8))


def test_c_backend_factory_error_is_clear(monkeypatch):
    import builtins

    from dopus_codegen.studies.converge import backend_factory

    real_import = builtins.__import__

    def fake_import(name, globals=None, locals=None, fromlist=(), level=0):
        if name == "runtime.solver" and level == 2 or name == "dopus_codegen.runtime.solver":
            raise ImportError("no module named solver")
        return real_import(name, globals, locals, fromlist, level)

    monkeypatch.setattr(builtins, "__import__", fake_import)
    with pytest.raises(RuntimeError, match="backend 'c' is not available"):
        backend_factory("c")
    with pytest.raises(ValueError, match="backend"):
        backend_factory("fortran")


def test_automatic_lm_reaches_the_solution(robot_disc, robot_solution, disturbed_ipopt):
    """The default automatic term (docs/algorithm.md section 10) vanishes near the solution:
    the warm-start study with the exact Hessian reaches KKT 1e-8 within the 40 iterations
    of the table for the full RTI, M = 5, 1 and 0 (it stalled at 4e-6 to 4e-5 while the
    convexity test alone set the term), at IPOPT's solution for the disturbed state."""
    from dopus_codegen.runtime.solver import CSolver

    d = robot_disc
    sol0, _ = robot_solution
    start = StartPoint("warm", d.x0, sol0, d.disturbance(d.x0))
    study = run_study(d, ["full", 5, 1, 0], 40, start, hessian="exact", regularization="none", lm="auto",
                      backend_factory=lambda disc, **kw: CSolver(disc, qp_tol=1e-13, **kw), backend_name="c")
    print("\n" + format_table(study))
    sol, info = disturbed_ipopt
    for run in study["runs"]:
        assert run["status"] == "converged", (run["M"], run["kkt"][-1])
        assert iterations_to(run["kkt"], 1e-8) <= 40
    x = np.array(study["solution"]["x"])
    u = np.array(study["solution"]["u"])
    assert max(np.max(np.abs(x - sol.x)), np.max(np.abs(u - sol.u))) < 1e-6
