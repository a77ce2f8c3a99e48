"""IPOPT on the multiple-shooting NLP: the robot-arm figures of docs/robot_arm.md section 4,
and the
sign convention of the returned multipliers checked through the KKT measure
(docs/algorithm.md section 6), which uses the exact derivative functions."""
import numpy as np
import pytest

from dopus_codegen.reference.kkt import kkt_of_guess
from dopus_codegen.reference.offline import solve_ocp


def test_robot_arm_objective_and_progress(robot_disc, robot_solution):
    sol, info = robot_solution
    assert info["success"], info["status"]
    # docs/robot_arm.md section 4: objective -3.7377630 and theta_N = 4.6062345
    # (8 significant digits)
    assert round(info["objective"], 7) == -3.7377630
    assert round(info["x_N"][4], 7) == 4.6062345
    assert sol.x[-1, 4] == info["x_N"][4]


def test_robot_arm_torque_bounds_active_at_55_percent(robot_disc, robot_solution):
    sol, _ = robot_solution
    tau = sol.u[:, :2]
    active = np.isclose(np.abs(tau), 10.0, rtol=0, atol=1e-7)
    # 44 of the 80 torque entries sit on a bound; each carries a nonzero signed multiplier
    # with the sign of the active side.
    assert round(active.mean(), 2) == 0.55
    mu = sol.mu_b[:, robot_disc.nx:robot_disc.nx + 2]
    assert np.all(np.sign(mu[active]) == np.sign(tau[active]))
    assert np.all(np.abs(mu[~active]) < 1e-8)


def test_robot_arm_kkt_of_ipopt_point(robot_disc, robot_solution):
    sol, _ = robot_solution
    k = kkt_of_guess(robot_disc, robot_disc.x0, sol)
    assert k["kkt"] < 1e-8, k
    # flipping the sign convention of the dynamics multipliers breaks stationarity
    bad = sol.copy()
    bad.lam = -bad.lam
    assert kkt_of_guess(robot_disc, robot_disc.x0, bad)["stat"] > 1e-2


def test_robot_arm_gauss_newton_hessian_same_optimum(robot_disc, robot_solution):
    _, info_exact = robot_solution
    sol, info = solve_ocp(robot_disc, robot_disc.x0, hessian="gauss-newton")
    assert info["success"], info["status"]
    assert abs(info["objective"] - info_exact["objective"]) < 1e-9
    assert kkt_of_guess(robot_disc, robot_disc.x0, sol)["kkt"] < 1e-8


def test_second_example_path_constraint_active(second_disc, second_solution):
    d = second_disc
    sol, info = second_solution
    assert info["success"], info["status"]
    assert d.ng == 1 and np.isfinite(d.lg[0]) and np.isinf(d.ug[0])
    g = np.array([float(d.stage_eval(sol.x[k], sol.u[k], d.p0[k])[2]) for k in range(d.N)])
    active = np.abs(g - d.lg[0]) < 1e-8
    assert active.any()
    # lower side active: signed multiplier negative and clearly away from zero
    assert np.all(sol.mu_g[active, 0] < -1e-3)
    assert np.all(np.abs(sol.mu_g[~active, 0]) < 1e-8)
    # the constraint is feasible (inactive) at the initial state
    g0 = float(d.stage_eval(d.x0, sol.u[0], d.p0[0])[2])
    assert g0 > d.lg[0] + 0.1
    assert kkt_of_guess(d, d.x0, sol)["kkt"] < 1e-8


def test_second_example_parameter_moves_solution(second_disc, second_solution):
    d = second_disc
    _, info = second_solution
    p = d.p0[0].copy()
    p[1] += 0.5                     # target 0.5 m further up
    sol, info2 = solve_ocp(d, d.x0, p=p)
    assert info2["success"]
    assert kkt_of_guess(d, d.x0, sol, p=np.tile(p, (d.N + 1, 1)))["kkt"] < 1e-8
    assert sol.x[-1, 1] > info["x_N"][1] + 0.1


def test_solve_ocp_rejects_bad_xhat0(robot_disc):
    with pytest.raises(ValueError, match="xhat0"):
        solve_ocp(robot_disc, [np.nan, 0, 0, 0, 0])
    with pytest.raises(ValueError, match="xhat0"):
        solve_ocp(robot_disc, [0, 0, 0])

