"""Predictive path following with a planar two-link arm (paper section 3).

Every number is the one of the project's robot-arm reference problem (docs/robot_arm.md):
a two-link arm in the vertical plane follows the circle p(theta) and is rewarded for progress
theta_N; the tip must end on the path (two terminal equality rows).

The soft variant: ``build(soft_terminal=Soft(l1=...))`` makes the two terminal rows soft (the
tip may end off the path at the price ``l1 |tip_N - p|_1``). With ``l1`` above the terminal
multipliers of the hard problem (about 5 at the initial state; ``solve_ocp(...).nu``) it is
an exact penalty: the solution is the hard one wherever the hard problem is feasible
(tests/test_soft.py reproduces the hard IPOPT solution with ``l1 = 20``), and a QP after an
outlier measurement can no longer be infeasible in its terminal rows.

A deployment whose joint-velocity sensor can glitch adds the measurement gate,
``ocp.options(..., gate=10, gate_hold=25)`` (docs/algorithm.md section 9): a measurement more
than 10 rad/s (the velocities' scale is 1) from what the plan predicts is held out for up to
25 instants; 1 to 20 outliers of 30 rad/s then leave the tip within 0.73 cm of the path
instead of 4.5 to 110 cm. The paper's problem runs without it.
"""
import math

import casadi as ca
import numpy as np

from dopus_codegen import RK4, Event, Ocp, OnPath, Pushes

# Model parameters (paper eq. 21).
M1, M2 = 1.0, 1.0
L1, L2 = 0.4, 0.4
LC1, LC2 = 0.2, 0.2
I1, I2 = M1 * L1**2 / 12.0, M2 * L2**2 / 12.0
FV = 0.1
GRAV = 9.81
A1 = I1 + I2 + M1 * LC1**2 + M2 * (L1**2 + LC2**2)
A2 = M2 * L1 * LC2
A3 = I2 + M2 * LC2**2

# OCP (paper eq. 22).
N, DT = 40, 0.01
TAU_MAX, DTHETA_MAX = 10.0, 50.0
W_PATH, W_TAU, W_DTHETA = 1e4, 1e-3, 1e-2


def tip(q):
    """End-effector position for joint angles q."""
    return ca.vertcat(L1 * ca.cos(q[0]) + L2 * ca.cos(q[0] + q[1]),
                      L1 * ca.sin(q[0]) + L2 * ca.sin(q[0] + q[1]))


def path(theta):
    """The circle the tip follows."""
    return ca.vertcat(0.4 + 0.15 * ca.cos(theta), 0.2 + 0.15 * ca.sin(theta))


def arm_ode(q, dq, tau, m1=M1, m2=M2, l1=L1, l2=L2):
    """ddq = B(q)^-1 (tau - C(q,dq) dq - Fv dq - g(q)).

    The masses and lengths are numbers for the controller's model and symbols
    (ocp.plant_quantity) for the plant of a campaign; each link is a uniform rod (centre of
    mass at half its length, inertia m l^2 / 12). With the default numbers the constants are
    those of the module (A1, A2, A3)."""
    lc1, lc2 = l1 / 2, l2 / 2
    i1, i2 = m1 * l1**2 / 12.0, m2 * l2**2 / 12.0
    a1 = i1 + i2 + m1 * lc1**2 + m2 * (l1**2 + lc2**2)
    a2 = m2 * l1 * lc2
    a3 = i2 + m2 * lc2**2
    c2, s2 = ca.cos(q[1]), ca.sin(q[1])
    B = ca.vertcat(ca.horzcat(a1 + 2 * a2 * c2, a3 + a2 * c2),
                   ca.horzcat(a3 + a2 * c2, a3))
    Cdq = ca.vertcat(-a2 * s2 * (2 * dq[0] * dq[1] + dq[1] ** 2), a2 * s2 * dq[0] ** 2)
    grav = ca.vertcat((m1 * lc1 + m2 * l1) * GRAV * ca.cos(q[0]) + m2 * lc2 * GRAV * ca.cos(q[0] + q[1]),
                      m2 * lc2 * GRAV * ca.cos(q[0] + q[1]))
    return ca.solve(B, tau - Cdq - FV * dq - grav)


def initial_state() -> np.ndarray:
    """At rest on the path start (theta = 0), elbow q2 > 0, closed-form inverse kinematics."""
    px, py = 0.4 + 0.15, 0.2
    c2 = (px**2 + py**2 - L1**2 - L2**2) / (2 * L1 * L2)
    q2 = math.acos(c2)
    q1 = math.atan2(py, px) - math.atan2(L2 * math.sin(q2), L1 + L2 * math.cos(q2))
    return np.array([q1, q2, 0.0, 0.0, 0.0])


def disturb(x):
    """Brings the arm to a standstill and turns it slightly: dq <- 0, q += [0.05, -0.05]."""
    x = np.array(x, dtype=float, copy=True)
    x[0] += 0.05
    x[1] -= 0.05
    x[2:4] = 0.0
    return x


def build(soft_terminal=None):
    """The paper's problem; ``soft_terminal``: a :class:`~dopus_codegen.Soft` for the terminal
    rows (None: hard equality rows, the paper's)."""
    ocp = Ocp("robot_arm")
    q = ocp.state("q", 2)
    dq = ocp.state("dq", 2)
    theta = ocp.state("theta")
    tau = ocp.control("tau", 2, lb=-TAU_MAX, ub=TAU_MAX)
    dtheta = ocp.control("dtheta", lb=0.0, ub=DTHETA_MAX)

    ocp.dynamics(ca.vertcat(dq, arm_ode(q, dq, tau), dtheta), integrator=RK4(substeps=2))
    # l = dt (1e4 |tip - p|^2 + 1e-3 |tau|^2 + 1e-2 dtheta^2) = 0.5 res' W res
    ocp.stage_least_squares(ca.vertcat(tip(q) - path(theta), tau, dtheta),
                            weights=2 * DT * np.array([W_PATH, W_PATH, W_TAU, W_TAU, W_DTHETA]))
    ocp.terminal_cost(-theta)
    ocp.terminal_constraint(tip(q) - path(theta), lb=0, ub=0, soft=soft_terminal)
    ocp.horizon(N=N, dt=DT)

    x0 = initial_state()
    ocp.initial_state(x0)
    ocp.initial_guess(x=x0, u=[0.0, 0.0, 5.0])
    # From the cold guess the exact-Hessian DOPUS diverges (docs/design.md section 8): the
    # generated controller carries the offline NLP solution to start warm.
    # The Levenberg-Marquardt term of the QP is the automatic one (lm="auto", the default;
    # docs/algorithm.md section 10): nothing to tune; it changes the steps, never the solution.
    ocp.options(hessian="exact", regularization="none", reg_eps=1e-4, M=1, offline_guess=True)
    ocp.disturbance(disturb)
    # The plant may differ from the model in the masses and lengths of the links: the plant of
    # the scenario uses these quantities (their nominal values in `dopus-gen sil`), a campaign
    # draws them as `campaign(mismatch=...)` says.
    quantities = {name: ocp.plant_quantity(name, value)
                  for name, value in (("m1", M1), ("m2", M2), ("l1", L1), ("l2", L2))}
    plant = ca.vertcat(dq, arm_ode(q, dq, tau, **quantities), dtheta)
    ocp.scenario(duration=3.0, events=[Event(1.0, disturb, "disturbance")],
                 signals={"deviation": ca.norm_2(tip(q) - path(theta)),
                          # the first two 2-component signals: the tip and its reference in the plane
                          "tip": tip(q), "circle": path(theta)},
                 plant=plant,
                 units={"deviation": "m", "tip": "m", "circle": "m", "q": "rad", "dq": "rad/s", "theta": "rad",
                        "tau": "N m", "dtheta": "rad/s"})
    # dopus-gen campaign: +-10 % link masses, a start near the path, one or two pushes (joint
    # velocity kicks); on the path = the tip within 2 cm of the circle (the nominal closed loop
    # swings up to 6 mm off it while it follows the circle at speed), 0.4 s after the start
    # and after every push.
    ocp.campaign(mismatch={"m1": 0.10, "m2": 0.10},
                 initial={"q": 0.02, "dq": 0.2},
                 pushes=Pushes(count=(1, 2), window=(0.4, 1.2), kick={"dq": 2.0}),
                 on_path=OnPath(signal="deviation", threshold=0.02, settle=0.4),
                 runs=1000, duration=2.0)
    return ocp
