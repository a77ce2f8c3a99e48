"""Soft constraints (docs/algorithm.md section 12): the OCP API and its errors, the QP with
soft rows in both backends against Clarabel with explicit slack variables, the OCPs with
active soft rows against an independent IPOPT transcription with explicit slacks (both
backends), and the QP that cannot be infeasible."""
from __future__ import annotations

import json
import math

import casadi as ca
import numpy as np
import pytest

from dopus_codegen import Ocp, OcpError, Soft
from dopus_codegen.problem.derivatives import build_functions
from dopus_codegen.reference.qp import qp_kkt_residual, solve_qp_reference

from harness.qp_harness import build_qp_solver
from harness.qp_problems import compare, make_qp, make_soft_qp, solve_clarabel_soft
from soft_problems import all_soft, cart_l1, cone, ipopt_with_slacks, orbit_l2, reach_both


# ------------------------------------------------------------------------------ the API
def _base():
    ocp = Ocp("soft_api")
    x = ocp.state("x", 2, lb=-1.0, ub=1.0)
    u = ocp.control("u", lb=-1.0, ub=1.0)
    ocp.dynamics(ca.vertcat(x[1], u))
    ocp.stage_least_squares(ca.vertcat(x, u), [1.0, 1.0, 1.0])
    ocp.horizon(N=5, dt=0.1)
    ocp.initial_state([0.0, 0.0])
    return ocp, x, u


@pytest.mark.parametrize("call, message", [
    (lambda o, x, u: o.state("y", 2, lb=0, soft=Soft(l1=-1.0)), "soft l1 must be >= 0, got -1.0 at row 0"),
    (lambda o, x, u: o.state("y", 2, lb=0, soft=Soft(l2=math.nan)), "soft l2 (lower side): NaN at row 0"),
    (lambda o, x, u: o.state("y", 2, lb=0, soft=Soft(l1=0.0, l2=0.0)), "soft weights are all zero"),
    (lambda o, x, u: o.state("y", 2, lb=0, soft=Soft(l1=[1.0, 2.0, 3.0])), "expected a scalar or 2 values"),
    (lambda o, x, u: o.state("y", 2, lb=0, soft=Soft(l1=(1.0, 2.0, 3.0))), "must be (lower, upper)"),
    (lambda o, x, u: o.state("y", 2, lb=0, soft=Soft(l1=math.inf)), "soft l1 must be finite"),
    (lambda o, x, u: o.state("y", 2, soft=Soft(l1=1.0)), "soft= on row 0, which has no finite bound"),
    (lambda o, x, u: o.state("y", 2, ub=[1.0, math.inf], soft=Soft(l1=1.0)), "soft= on row 1, which has no finite bound"),
    (lambda o, x, u: o.state("y", 2, ub=1.0, soft=Soft(l1=(1.0, 0.0))), "soft weights are zero on every finite bound"),
    (lambda o, x, u: o.state("y", 2, lb=0, soft={"l1": 1}), "soft must be Soft(l1=..., l2=...)"),
    (lambda o, x, u: o.path_constraint(x[0] * u, soft=Soft(l1=1.0)), "path constraint 0: soft= on row 0"),
    (lambda o, x, u: o.terminal_constraint(x, lb=[0, -math.inf], ub=[0, math.inf], soft=Soft(l1=1.0)),
     "terminal constraint 0: soft= on row 1, which has no finite bound"),
    (lambda o, x, u: o.path_constraint(x[0] * u, lb=0, soft=Soft(l1=[1.0, 1.0])), "expected a scalar or 1 values"),
])
def test_soft_weights_are_checked(call, message):
    ocp, x, u = _base()
    with pytest.raises(OcpError) as err:
        call(ocp, x, u)
    assert message in str(err.value)
    assert "\n" not in str(err.value)


def test_soft_weights_per_side_and_row():
    ocp, x, u = _base()
    y = ocp.state("y", 2, lb=[0.0, -1.0], ub=[math.inf, 1.0], soft=Soft(l1=([1.0, 2.0], 3.0), l2=0.5))
    ocp.dynamics(ca.vertcat(x[1], u, y[0], y[1]))
    ocp.initial_state([0.0, 0.0, 0.5, 0.0])
    ocp.terminal_constraint(x[0] + y[1], lb=0.5, ub=0.5, soft=Soft(l1=4.0))
    ocp.terminal_constraint(x[1], lb=0.0, ub=0.0)
    disc = build_functions(ocp)
    # rows: l1 lower, l1 upper, l2 lower, l2 upper; the upper side of y[0] has no bound
    np.testing.assert_array_equal(disc.soft_x[:, 2:], [[1.0, 2.0], [0.0, 3.0], [0.5, 0.5], [0.0, 0.5]])
    np.testing.assert_array_equal(disc.soft_x[:, :2], np.zeros((4, 2)))
    # the soft terminal row with lb == ub stays an inequality row, the hard one is an equality
    assert (disc.nr, disc.ne) == (1, 1)
    np.testing.assert_array_equal(disc.soft_r[:, 0], [4.0, 4.0, 0.0, 0.0])
    assert disc.has_soft and not disc.always_feasible
    assert disc.soft_stage().shape == (4, disc.nw + disc.ng)


# ------------------------------------------------------------------------------ the QP
SIZES = [(6, 3, 2, 2, 1, 0), (5, 2, 1, 1, 2, 0), (8, 4, 2, 0, 0, 1), (4, 3, 2, 2, 2, 1)]


@pytest.mark.parametrize("sizes", SIZES)
def test_random_soft_qps_against_clarabel_with_slacks(sizes):
    """30 random convex QPs per size with soft rows (L1 only, L2 only, both) whose bounds the
    hard solution violates: the C interior point (slacks eliminated row by row) and the
    reference (explicit slacks) against Clarabel on the QP with explicit slack variables."""
    rng = np.random.default_rng(2200 + sum(sizes))
    h = build_qp_solver(*sizes, soft=True)
    compared, active = 0, 0
    for t in range(30):
        qp = make_soft_qp(rng, *sizes, l1=t % 3 != 1, l2=t % 3 != 0)
        status, ref, (s_lo, s_up) = solve_clarabel_soft(qp)
        sol, info = h.solve(qp, tol=1e-11)
        assert info["status"] == "solved", (t, info)
        assert qp_kkt_residual(qp, sol)["kkt"] < 1e-7
        rsol = solve_qp_reference(qp, tol=1e-11)
        for name, s in (("C", sol), ("reference", rsol)):
            d = compare(s, rsol if name == "C" else sol, keys=("x", "u", "lam", "mu_b", "mu_g", "mu_bN", "mu_r", "nu"))
            assert max(d.values()) < 1e-6, (t, name, d)
        if status != "Solved":
            continue
        compared += 1
        active += int(np.sum(s_lo > 1e-6) + np.sum(s_up > 1e-6))
        d = compare(sol, ref, keys=("x", "u", "lam", "mu_b", "mu_g", "mu_bN", "mu_r", "nu"))
        assert max(d.values()) < 1e-6, (t, d)
    assert compared >= 27
    assert active >= 30


def test_soft_qp_without_soft_weights_equals_the_hard_solver():
    """A QP without soft weights: the solver compiled with the soft rows gives the hard
    solver's answer bit for bit (the soft code paths are not taken)."""
    rng = np.random.default_rng(7)
    sizes = (6, 3, 2, 2, 1, 1)
    hs, hh = build_qp_solver(*sizes, soft=True), build_qp_solver(*sizes)
    for _ in range(5):
        qp, _ = make_qp(rng, *sizes, p_active=0.3)
        a, ia = hs.solve(qp, tol=1e-10)
        b, ib = hh.solve(qp, tol=1e-10)
        assert ia["iterations"] == ib["iterations"]
        for key in ("x", "u", "lam", "mu_b", "mu_g", "mu_r", "nu"):
            np.testing.assert_array_equal(a[key], b[key])


# ------------------------------------------------------------------------------ the OCPs
@pytest.mark.parametrize("make, group", [(cart_l1, "x"), (orbit_l2, "g"), (reach_both, "r")])
@pytest.mark.parametrize("backend", ["c", "reference"])
def test_soft_ocp_equals_ipopt_with_explicit_slacks(make, group, backend):
    """Full RTI in fixed mode (Gauss-Newton) converges to the solution of an independent
    CasADi + IPOPT transcription with one slack variable per soft side and node, to 1e-6 in
    x and u; the soft rows are active (L1 only: a state bound; L2 only: a nonlinear path
    row; both: a terminal equality and a state bound)."""
    from dopus_codegen.reference.dopus import ReferenceDopus
    from dopus_codegen.runtime.solver import CSolver

    disc = build_functions(make())
    xh = np.asarray(disc.x0)
    x_ref, u_ref, slack = ipopt_with_slacks(disc, xh)
    assert slack[group] > 1e-2, slack
    B = CSolver if backend == "c" else ReferenceDopus
    s = B(disc, M=disc.N - 1, mode="fixed", hessian="gauss-newton", qp_tol=1e-12, lm=0.0)
    s.init(xh)
    for _ in range(25):
        s.feedback(xh)
        s.prepare()
    assert np.max(np.abs(s.x - x_ref)) < 1e-6
    assert np.max(np.abs(s.u - u_ref)) < 1e-6
    assert s.kkt(xh)["kkt"] < 1e-8


def test_always_feasible_is_generated_and_fuzzed():
    """Every state-dependent row soft: generate says so (sizes header and meta), and in the
    closed loop of the C runtime the QP of each of 300 random finite measurements, 0.1 to
    1e6 times the bounds, is solved (the solutions are checked against IPOPT and the KKT
    conditions in test_all_soft_qps_far_outside_the_bounds). Before the cold start from the
    rollout (runtime_c/dopus_qp.c, soft_rollout), measurements 300 to 3000 times outside
    left 4 QPs of 60 stalled. (A step whose states leave 1e3 times the problem's scale is
    still refused by the divergence test of docs/algorithm.md section 9, a fallback without
    a QP failure: with a measured velocity of 1e3, the predicted positions do.)"""
    from dopus_codegen.codegen.generate import render_folder, soft_rows
    from dopus_codegen.runtime.solver import CSolver, DopusError

    disc = build_functions(all_soft())
    assert soft_rows(disc) == {"nsoft": 4, "always_feasible": True}
    files = render_folder(disc)
    assert "#define SOFT_ALL_QP_ALWAYS_FEASIBLE 1" in files["soft_all_sizes.h"]
    assert "#define SOFT_ALL_NSOFT 4" in files["soft_all_sizes.h"]
    assert '"qp_always_feasible": true' in files["soft_all_meta.json"]
    hard = build_functions(cart_l1())  # a soft v bound, hard p? p is unbounded: also feasible
    assert soft_rows(hard)["nsoft"] == 1
    s = CSolver(disc, M=1, hessian="gauss-newton")
    rng = np.random.default_rng(22)
    s.init(np.zeros(2))
    failures, solved = [], 0
    for i in range(300):
        xh = rng.standard_normal(2) * 10.0 ** rng.uniform(-1, 6)
        try:
            s.feedback(xh)
            solved += 1
        except DopusError as err:
            if err.qp_status is not None:
                failures.append((i, xh, err.qp_status_name))
        s.prepare()
    assert not failures, failures[:3]
    assert solved >= 100


def test_all_soft_qps_far_outside_the_bounds():
    """The QPs of the all-soft problem for measurements 1e2 to 1e6 times outside the bounds,
    at the initial iterate (40) and along a closed loop of the reference backend (25, its
    iterates after such measurements): the C interior point solves each within 40
    iterations, with the KKT residual of the reference (soft rows included) at most 1e-9 of
    the sizes of its parts (the states, the multipliers, their products), and equals IPOPT
    with explicit slacks (the reference QP solver, polished to round-off) to 1e-8 of the
    size of the states in x and u where that solves them (measurements up to 1e4, where it
    fails on a few; beyond, its restoration phase fails on some). Before the start from the rollout with the slack price and the dual rollout
    (runtime_c/dopus_qp.c), of 60 such QPs at the initial iterate 42, 52, 59 and 60 stalled
    or reached the iteration limit for measurements 10^2.5..3.5, 10^3..4, 10^4..5 and
    10^5..6 (bench/soft_far.py)."""
    from dopus_codegen.reference.dopus import ReferenceDopus
    from dopus_codegen.reference.qp import QPError
    from dopus_codegen.runtime.solver import DopusError

    disc = build_functions(all_soft())
    ref = ReferenceDopus(disc, M=1, hessian="gauss-newton")
    ref.init(np.zeros(2))
    rng = np.random.default_rng(2222)
    qps = [ref.qp_of_current(rng.standard_normal(2) * 10.0 ** rng.uniform(2, 6)) for _ in range(40)]
    for _ in range(25):
        xh = rng.standard_normal(2) * 10.0 ** rng.uniform(2, 6)
        qps.append(ref.qp_of_current(xh))
        try:
            ref.feedback(xh)
        except DopusError:
            pass  # the reference's own IPOPT may fail here: only its iterates are used
        ref.prepare()
    h = build_qp_solver(*(int(qps[0][k]) for k in ("N", "nx", "nu", "ng", "nr", "ne")), soft=True)
    weights = max(1.0, *(float(np.max(qps[0][k])) for k in ("zl", "zu", "Zl", "Zu", "zlN", "zuN", "ZlN", "ZuN")))
    compared = 0
    for t, qp in enumerate(qps):
        sol, info = h.solve(qp, tol=1e-10)
        assert info["status"] == "solved" and info["iterations"] <= 40, (t, info)
        # multipliers of the size of the weights times the states, distances of the states
        size = max(1.0, float(np.max(np.abs(qp["x0"]))))
        res = qp_kkt_residual(qp, sol)
        assert res["stat"] <= 1e-9 * weights * size and max(res["eq"], res["ineq"]) <= 1e-9 * size, (t, res)
        assert res["comp"] <= 1e-9 * weights * size * size and res["sign"] <= 1e-9 * weights * size, (t, res)
        if np.max(np.abs(qp["x0"])) <= 1e4:
            try:
                r = solve_qp_reference(qp, tol=1e-10)
            except QPError:
                continue  # IPOPT's own failure on these scales
            # relative to the size of the states: u follows from their second differences
            err = max(np.max(np.abs(sol[k] - r[k])) for k in ("x", "u")) / max(1.0, np.max(np.abs(r["x"])))
            assert err < 1e-8, (t, err)
            compared += 1
    assert compared >= 15, compared


def test_hard_rows_of_a_soft_problem_still_diagnosed_infeasible():
    """A QP whose hard rows contradict each other stays infeasible with soft rows present,
    and the row named is a hard one."""
    rng = np.random.default_rng(3)
    sizes = (5, 2, 1, 1, 1, 0)
    h = build_qp_solver(*sizes, soft=True)
    qp = make_soft_qp(rng, *sizes)
    # control 0 of stage 2 in [1, 2] and [-2, -1] at once: through the path row C = e_u, hard
    qp["C"][2, 0] = 0.0
    qp["C"][2, 0, 2] = 1.0
    qp["zl"][3] = qp["zu"][3] = qp["Zl"][3] = qp["Zu"][3] = 0.0
    qp["lg"][2, 0], qp["ug"][2, 0] = 1.0, 2.0
    qp["lbw"][2, 2], qp["ubw"][2, 2] = -2.0, -1.0
    sol, info = h.solve(qp, tol=1e-10)
    assert info["status"] == "primal_infeasible", info
    k, j, side = h.infeasible_row()
    assert k == 2 and j in (2, 3)


def test_robot_arm_exact_penalty(robot_disc, robot_solution):
    """The robot arm with its terminal rows soft, l1 = 20 (above the hard problem's terminal
    multipliers): the IPOPT transcription with explicit slacks reproduces the hard IPOPT
    solution, and the C full RTI started there stays on it (its KKT measure with the soft
    rows is that of a solution)."""
    import importlib.util

    from dopus_codegen.problem.ocp import Guess
    from dopus_codegen.runtime.solver import CSolver
    from conftest import ROBOT_ARM_FILE

    spec = importlib.util.spec_from_file_location("robot_arm_soft_test", ROBOT_ARM_FILE)
    arm = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(arm)
    hard, _ = robot_solution
    l1 = 20.0
    assert np.max(np.abs(hard.nu)) < l1 / 3
    disc = build_functions(arm.build(soft_terminal=Soft(l1=l1)))
    assert (disc.nr, disc.ne) == (2, 0)
    xh = np.asarray(disc.x0)
    x, u, slack = ipopt_with_slacks(disc, xh)
    assert slack["r"] < 1e-8
    assert np.max(np.abs(x - hard.x)) < 1e-6
    assert np.max(np.abs(u - hard.u)) < 1e-6
    g = Guess(x=hard.x, u=hard.u, lam=hard.lam, mu_g=hard.mu_g, mu_b=hard.mu_b, mu_bN=hard.mu_bN,
              mu_r=np.asarray(hard.nu), nu=np.zeros(0))
    s = CSolver(disc, M=disc.N - 1, mode="fixed", qp_tol=1e-12)
    s.init(xh, g)
    assert s.kkt(xh)["kkt"] < 1e-8
    for _ in range(3):
        s.feedback(xh)
        s.prepare()
    assert np.max(np.abs(s.x - hard.x)) < 1e-6
    assert s.kkt(xh)["kkt"] < 1e-8


@pytest.mark.parametrize("M", [1, 5])
@pytest.mark.parametrize("backend", ["c", "reference"])
def test_stale_linearisation_is_relinearised(M, backend):
    """The cone of soft_problems.cone from its cold guess (where the row's gradient
    vanishes), Gauss-Newton, fixed mode: the stages whose stored linearisation makes the
    row unsatisfiable are re-linearised ahead of the rho ranking (more than M + 1 stages
    recomputed in the second iteration), and the iteration converges to IPOPT's solution."""
    from dopus_codegen.reference.dopus import ReferenceDopus
    from dopus_codegen.runtime.solver import CSolver

    disc = build_functions(cone())
    xh = np.asarray(disc.x0)
    x_ref, u_ref, _ = ipopt_with_slacks(disc, xh)
    B = CSolver if backend == "c" else ReferenceDopus
    s = B(disc, M=M, mode="fixed", hessian="gauss-newton", qp_tol=1e-12)
    s.init(xh)
    counts = []
    for _ in range(60):
        s.feedback(xh)
        s.prepare()
        counts.append(len(s.recomputed))
        if s.kkt(xh)["kkt"] < 1e-9:
            break
    assert counts[0] > M + 1, counts
    assert s.kkt(xh)["kkt"] < 1e-9, (len(counts), s.kkt(xh))
    assert np.max(np.abs(s.x - x_ref)) < 1e-6
    assert np.max(np.abs(s.u - u_ref)) < 1e-6


@pytest.mark.parametrize("make", [cart_l1, reach_both])
def test_soft_c_equals_reference_iterate_by_iterate(make):
    """Receding horizon, Gauss-Newton, M = 1, 30 instants on the discrete model with two
    pushes that violate the soft rows: the C iterate (every primal and multiplier array)
    equals the reference's to 1e-9 relative after every feedback, and the recomputed stages
    are the same (tests/test_c_vs_reference.py's measure, QP tolerance 1e-14). (On
    soft_problems.orbit_l2 the backends differ by up to 3e-8: path rows inactive by 1e-6
    carry interior-point multipliers of complementarity over gap, as hard rows would. A push
    of the speed by 0.4 instead of 0.37 makes the speed reach its bound exactly in the step
    where the force is at its own bound: the two multipliers are then not unique.)"""
    from dopus_codegen.reference.dopus import ReferenceDopus
    from dopus_codegen.runtime.solver import CSolver

    disc = build_functions(make())
    xh = np.asarray(disc.x0, float)
    c = CSolver(disc, M=1, hessian="gauss-newton", qp_tol=1e-14)
    r = ReferenceDopus(disc, M=1, hessian="gauss-newton", qp_tol=1e-14)
    c.init(xh)
    r.init(xh)
    worst = 0.0
    for it in range(30):
        c.feedback(xh)
        u0 = r.feedback(xh)
        for f in ("x", "u", "lam", "mu_g", "mu_b", "mu_bN", "mu_r", "nu"):
            a, b = np.asarray(getattr(c, f)), np.asarray(getattr(r, f))
            if b.size:
                worst = max(worst, float(np.max(np.abs(a - b)) / max(1.0, float(np.max(np.abs(b))))))
        c.prepare()
        r.prepare()
        assert c.recomputed == r.recomputed
        xh = np.asarray(disc.stage_eval(xh, u0, disc.p0[0])[0], float).reshape(-1)
        if it in (5, 15):
            xh = xh + np.array([0.3, 0.37])
    assert worst < 1e-9, worst


def test_soft_slacks_reported_by_both_backends():
    """dopus_get_soft_slacks: after a feedback that violates the soft speed limit, the slacks
    of the C QP equal the reference's and the violation of the new iterate (the states of the
    QP solution), node by node."""
    from dopus_codegen.reference.dopus import ReferenceDopus
    from dopus_codegen.runtime.solver import CSolver

    disc = build_functions(reach_both())
    xh = np.asarray(disc.x0, float)
    c = CSolver(disc, M=1, hessian="gauss-newton", qp_tol=1e-12)
    r = ReferenceDopus(disc, M=1, hessian="gauss-newton", qp_tol=1e-12)
    c.init(xh)
    r.init(xh)
    c.feedback(xh)
    r.feedback(xh)
    sc, sr = c.soft_slacks(), r.soft_slacks()
    assert sr["max"] > 0.1 and sr["r"][0] > 0.1
    for key in ("x", "g", "r"):
        np.testing.assert_allclose(sc[key], sr[key], atol=1e-8)
    viol = np.maximum(0.0, c.x[:, 1] - disc.ubx[1])
    viol[0] = 0.0
    np.testing.assert_allclose(sc["x"][:, 1], viol, atol=1e-9)
    np.testing.assert_allclose(sc["r"], np.abs(c.x[-1, 0] - 3.0), atol=1e-9)


@pytest.mark.parametrize("make", [cart_l1, orbit_l2, reach_both])
def test_offline_solver_with_soft_rows(make):
    """reference/offline.py (the project's IPOPT, with its slack variables) equals the
    independent transcription, and its multipliers pass the soft KKT measure."""
    from dopus_codegen.reference.kkt import kkt_of_guess
    from dopus_codegen.reference.offline import solve_ocp

    disc = build_functions(make())
    x, u, _ = ipopt_with_slacks(disc, disc.x0)
    g, info = solve_ocp(disc, disc.x0)
    assert info["success"]
    assert np.max(np.abs(g.x - x)) < 1e-8 and np.max(np.abs(g.u - u)) < 1e-8
    assert kkt_of_guess(disc, disc.x0, g)["kkt"] < 1e-9


def test_sil_reports_the_largest_soft_violation():
    """The closed loop of a soft OCP records the violation of each soft group at the measured
    state and applied control, and summarize reports its maximum: equal to the violation
    computed from the recorded states and controls."""
    from dopus_codegen.studies.sil import format_summary, run_closed_loop, summarize

    ocp = cart_l1()
    ocp.path_constraint(ocp.x_sym()[1] + 0.1 * ocp.u_sym()[0], ub=0.25, soft=Soft(l1=3.0))
    ocp.scenario(duration=1.0)
    disc = build_functions(ocp)
    run = run_closed_loop(disc, M=1, hessian="gauss-newton")
    s = summarize(run)
    x, u = np.asarray(run["x"]), np.asarray(run["u"])
    assert s["soft_violation"]["state v"] == pytest.approx(max(0.0, float(np.max(np.abs(x[:, 1]) - 0.3))), abs=1e-15)
    assert s["soft_violation"]["path 0"] == pytest.approx(max(0.0, float(np.max(x[:, 1] + 0.1 * u[:, 0] - 0.25))),
                                                          rel=1e-12, abs=1e-15)
    assert s["soft_violation"]["state v"] > 0.1
    assert "largest violation of the soft rows" in format_summary([s])


def test_generate_says_the_qp_is_always_feasible(tmp_path):
    """`dopus-gen generate` of an OCP whose state-dependent rows are all soft says so."""
    from click.testing import CliRunner

    from dopus_codegen.cli import main

    ocp_file = tmp_path / "all_soft.py"
    ocp_file.write_text("import sys\nsys.path.insert(0, %r)\nfrom soft_problems import all_soft\n\n\n"
                        "def build():\n    return all_soft()\n" % str(__import__("pathlib").Path(__file__).parent))
    res = CliRunner().invoke(main, ["generate", str(ocp_file), "-o", str(tmp_path / "out")])
    assert res.exit_code == 0, res.output
    assert "soft rows: 4; the QP is always feasible (every state-dependent row is soft)" in res.output


def test_soft_state_limit_with_an_implicit_integrator():
    """examples/stiff_motor.py (Radau IIA) with its current limit lowered to 1 A and made
    soft (L1 and L2): the C full RTI equals IPOPT with explicit slacks, the limit exceeded."""
    import importlib.util

    from conftest import EXAMPLES
    from dopus_codegen.runtime.solver import CSolver

    spec = importlib.util.spec_from_file_location("stiff_motor_soft_test", EXAMPLES / "stiff_motor.py")
    motor = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(motor)
    disc = build_functions(motor.build(soft_current=Soft(l1=[0, 0, 0.05], l2=[0, 0, 0.1]), current_limit=1.0))
    xh = np.asarray(disc.x0, float)
    x_ref, u_ref, slack = ipopt_with_slacks(disc, xh)
    assert slack["x"] > 0.1
    s = CSolver(disc, M=disc.N - 1, mode="fixed", qp_tol=1e-12)
    s.init(xh)
    for _ in range(30):
        s.feedback(xh)
        s.prepare()
    assert np.max(np.abs(s.x - x_ref)) < 1e-6
    assert np.max(np.abs(s.u - u_ref)) < 1e-6
    assert s.kkt(xh)["kkt"] < 1e-8


def test_campaign_reports_the_largest_soft_violation(tmp_path):
    """A two-run campaign of the cart-pole (soft track ends): every result line carries the
    largest violation of each soft group of its run, equal to the one computed from the run's
    closed loop, and the report the largest over the runs."""
    from conftest import EXAMPLES
    from dopus_codegen.studies import campaign

    runs = {}
    real = campaign.condense

    def keep(run, d, index, seed, *args):
        runs[index] = run
        return real(run, d, index, seed, *args)

    campaign.condense = keep
    try:
        rep = campaign.run_campaign(str(EXAMPLES / "cartpole.py"), str(tmp_path / "c.jsonl"), workers=0, runs=2,
                                    duration=0.5, progress=False, echo=lambda *a, **k: None)
    finally:
        campaign.condense = real
    lines = [json.loads(s) for s in (tmp_path / "c.jsonl").read_text().splitlines()[1:]]
    assert len(lines) == 2
    for line in lines:
        x = np.asarray(runs[line["run"]]["x"])
        assert line["soft_violation"]["state p"] == pytest.approx(max(0.0, float(np.max(np.abs(x[:, 0]) - 1.0))),
                                                                  abs=1e-15)
    assert rep["soft_violation_max"]["state p"] == max(line["soft_violation"]["state p"] for line in lines)
    assert "largest violation of the soft rows" in campaign.format_report(rep)
