"""The CVODES plant against scipy's solve_ivp on the robot arm (docs/robot_arm.md
section 1, paper eq. 21).

The reference right-hand side is written here a second time in plain numpy, so a slip in
the CasADi model and the same slip in the reference cannot cancel.
"""
import casadi as ca
import numpy as np
import pytest
from scipy.integrate import solve_ivp

from dopus_codegen.studies.plant import Plant, PlantError

M1 = M2 = 1.0
L1 = 0.4
LC1 = LC2 = 0.2
I1 = I2 = 1.0 * 0.4 ** 2 / 12
FV = 0.1
G = 9.81
XHAT0 = np.array([-0.40144188, 1.50042576, 0.0, 0.0, 0.0])


def arm_rhs_numpy(x, u):
    q1, q2, dq1, dq2, _ = x
    a1 = I1 + I2 + M1 * LC1 ** 2 + M2 * (L1 ** 2 + LC2 ** 2)
    a2 = M2 * L1 * LC2
    a3 = I2 + M2 * LC2 ** 2
    c2, s2 = np.cos(q2), np.sin(q2)
    B = np.array([[a1 + 2 * a2 * c2, a3 + a2 * c2], [a3 + a2 * c2, a3]])
    cor = np.array([-a2 * s2 * (2 * dq1 * dq2 + dq2 ** 2), a2 * s2 * dq1 ** 2])
    grav = np.array([(M1 * LC1 + M2 * L1) * G * np.cos(q1) + M2 * LC2 * G * np.cos(q1 + q2),
                     M2 * LC2 * G * np.cos(q1 + q2)])
    dq = np.array([dq1, dq2])
    ddq = np.linalg.solve(B, u[:2] - cor - FV * dq - grav)
    return np.array([dq1, dq2, ddq[0], ddq[1], u[2]])


def arm_ode_casadi(with_param=False):
    x = ca.SX.sym("x", 5)
    u = ca.SX.sym("u", 3)
    p = ca.SX.sym("p", 1 if with_param else 0)
    q1, q2, dq1, dq2 = x[0], x[1], x[2], x[3]
    a1 = I1 + I2 + M1 * LC1 ** 2 + M2 * (L1 ** 2 + LC2 ** 2)
    a2 = M2 * L1 * LC2
    a3 = I2 + M2 * LC2 ** 2
    B = ca.vertcat(ca.horzcat(a1 + 2 * a2 * ca.cos(q2), a3 + a2 * ca.cos(q2)),
                   ca.horzcat(a3 + a2 * ca.cos(q2), a3))
    cor = ca.vertcat(-a2 * ca.sin(q2) * (2 * dq1 * dq2 + dq2 ** 2), a2 * ca.sin(q2) * dq1 ** 2)
    grav = ca.vertcat((M1 * LC1 + M2 * L1) * G * ca.cos(q1) + M2 * LC2 * G * ca.cos(q1 + q2),
                      M2 * LC2 * G * ca.cos(q1 + q2))
    tau = u[:2] * (p[0] if with_param else 1.0)
    ddq = ca.solve(B, tau - cor - FV * x[2:4] - grav)
    return ca.Function("ode", [x, u, p], [ca.vertcat(x[2:4], ddq, u[2])])


def torque_sequence(K, dt):
    t = np.arange(K) * dt
    # Nonzero torques around the gravity load, changing every sample (zero-order hold), that
    # swing the arm away from rest (|dq2| reaches 14 rad/s), and a growing path speed.
    return np.column_stack([6.0 + 3.0 * np.sin(9 * t), 1.0 - 2.0 * np.cos(7 * t), 5.0 + 3.0 * t])


def reference_trajectory(us, dt, method):
    x = XHAT0.copy()
    ref = [x]
    for u in us:
        sol = solve_ivp(lambda t, y: arm_rhs_numpy(y, u), (0.0, dt), x, method=method,
                        rtol=1e-12, atol=1e-12)
        assert sol.success
        x = sol.y[:, -1]
        ref.append(x)
    return np.array(ref)


# CVODES controls the local error per internal step; over 50 restarts (one per sample) and
# velocities of 14 rad/s the global error at tolerance 1e-10 is a few 1e-8 (measured 4.9e-8
# for Adams, 2.6e-7 for BDF), and it falls with the tolerance as expected (7.7e-10 at 1e-12).
@pytest.mark.parametrize("method", ["DOP853", "Radau"])
@pytest.mark.parametrize("cvodes, tol, bound", [("adams", 1e-10, 1e-7), ("adams", 1e-12, 1e-8),
                                                ("bdf", 1e-12, 1e-8)])
def test_plant_matches_solve_ivp(method, cvodes, tol, bound):
    dt, K = 0.01, 50  # 0.5 s
    us = torque_sequence(K, dt)
    plant = Plant(arm_ode_casadi(), dt, 0, reltol=tol, abstol=tol, method=cvodes)
    xs = plant.simulate(XHAT0, us)
    ref = reference_trajectory(us, dt, method)
    # The arm really moved, so the comparison is not trivial.
    assert np.max(np.abs(ref[:, 2:4])) > 10.0
    assert np.max(np.abs(ref[-1, :2] - XHAT0[:2])) > 0.1
    err = np.max(np.abs(xs - ref))
    assert err < bound, f"plant ({cvodes}, tol {tol}) vs solve_ivp ({method}): max abs error {err:.3e}"


def test_plant_partial_steps_compose():
    """Two partial steps (an event between samples) equal one full step."""
    plant = Plant(arm_ode_casadi(), 0.01, 0)
    u = np.array([3.0, -2.0, 5.0])
    full = plant.step(XHAT0, u)
    half = plant.step(plant.step(XHAT0, u, duration=0.0037), u, duration=0.0063)
    assert np.max(np.abs(full - half)) < 1e-9


def test_plant_parameters_enter():
    """A parameter scaling the torques: p = 0 gives the unforced motion, p = 1 the forced one."""
    plant = Plant(arm_ode_casadi(with_param=True), 0.01, 1)
    plant0 = Plant(arm_ode_casadi(), 0.01, 0)
    u = np.array([3.0, -2.0, 5.0])
    forced = plant.step(XHAT0, u, p=[1.0])
    assert np.max(np.abs(forced - plant0.step(XHAT0, u))) < 1e-12
    unforced = plant.step(XHAT0, u, p=[0.0])
    assert np.max(np.abs(unforced - plant0.step(XHAT0, [0.0, 0.0, 5.0]))) < 1e-12


def test_plant_bad_input():
    x = ca.SX.sym("x", 2)
    with pytest.raises(PlantError, match="three inputs"):
        Plant(ca.Function("f", [x], [x]), 0.01, 0)
    with pytest.raises(PlantError, match="method"):
        Plant(arm_ode_casadi(), 0.01, 0, method="rk4")
    with pytest.raises(PlantError, match="np = 2"):
        Plant(arm_ode_casadi(), 0.01, 2)
    with pytest.raises(PlantError, match="dt"):
        Plant(arm_ode_casadi(), -1.0, 0)
    plant = Plant(arm_ode_casadi(), 0.01, 0)
    with pytest.raises(PlantError, match="control u has 2 entries"):
        plant.step(XHAT0, [1.0, 2.0])
    with pytest.raises(PlantError, match="not finite"):
        plant.step(XHAT0 * np.nan, [1.0, 2.0, 3.0])


def test_plant_integration_failure_is_reported():
    """xdot = x^2 from x = 10 leaves every bound at t = 0.1 s: CVODES must fail, clearly."""
    x, u, p = ca.SX.sym("x"), ca.SX.sym("u"), ca.SX.sym("p", 0)
    plant = Plant(ca.Function("blowup", [x, u, p], [x ** 2 + u]), 0.5, 0)
    # Before the blow-up the plant is the exact solution x(t) = 1 / (1/10 - t).
    assert plant.step([10.0], [0.0], duration=0.05)[0] == pytest.approx(20.0, rel=1e-8)
    with pytest.raises(PlantError, match="CVODES failed"):
        plant.step([10.0], [0.0])
