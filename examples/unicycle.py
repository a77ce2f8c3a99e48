"""A unicycle drives to a target past a circular obstacle.

Small companion to the robot arm: a nonlinear path inequality (stay outside the
obstacle) that is active at the solution, a runtime parameter (the target position),
least-squares stage and terminal costs (so Gauss-Newton applies) and a closed-loop
scenario with a sideways push.

As with the robot arm, DOPUS starts from the offline NLP solution
(``options(offline_guess=True)``) or uses the Gauss-Newton Hessian: from the cold guess
below (standing still) the exact-Hessian QPs lose convexity within a few iterations.
Reversing is allowed (v >= -0.5) so that the car can come to rest at the target with no
active speed bound there.
"""
import casadi as ca
import numpy as np

from dopus_codegen import RK4, Event, Ocp

N, DT = 20, 0.1
OBSTACLE = (1.0, 0.1)       # centre, m; slightly above the straight line to the target
RADIUS = 0.4                # m
TARGET = (2.5, 0.0)         # default of the runtime parameter "target"
V_MAX, V_REVERSE, A_MAX, OMEGA_MAX = 1.5, 0.5, 2.0, 2.0


def clearance_sq(px, py):
    """Squared distance to the obstacle centre."""
    return (px - OBSTACLE[0]) ** 2 + (py - OBSTACLE[1]) ** 2


def push(x):
    """Sideways push: 0.1 m and 0.2 rad away from the obstacle (a push into it would make
    the path constraint of stage 0, which only sees the fixed x_0, infeasible)."""
    x = np.array(x, dtype=float, copy=True)
    x[1] -= 0.1
    x[2] -= 0.2
    return x


def build():
    ocp = Ocp("unicycle")
    pos = ocp.state("pos", 2)
    psi = ocp.state("psi")
    v = ocp.state("v", lb=-V_REVERSE, ub=V_MAX)
    acc = ocp.control("acc", lb=-A_MAX, ub=A_MAX)
    omega = ocp.control("omega", lb=-OMEGA_MAX, ub=OMEGA_MAX)
    target = ocp.parameter("target", 2, value=TARGET)

    ocp.dynamics(ca.vertcat(v * ca.cos(psi), v * ca.sin(psi), omega, acc), integrator=RK4(substeps=1))
    ocp.stage_least_squares(ca.vertcat(pos - target, acc, omega),
                            weights=DT * np.array([1.0, 1.0, 0.1, 0.1]))
    ocp.terminal_least_squares(ca.vertcat(pos - target, v), weights=[10.0, 10.0, 1.0])
    ocp.path_constraint(clearance_sq(pos[0], pos[1]), lb=RADIUS**2)
    ocp.horizon(N=N, dt=DT)

    x0 = np.array([0.0, 0.0, 0.0, 0.0])
    ocp.initial_state(x0)
    ocp.initial_guess(x=x0, u=[0.0, 0.0])
    ocp.options(hessian="exact", regularization="none", M=1, offline_guess=True)
    ocp.disturbance(push)
    ocp.scenario(duration=3.0, events=[Event(1.0, push, "push")],
                 signals={"clearance": ca.sqrt(clearance_sq(pos[0], pos[1])) - RADIUS,
                          "distance_to_target": ca.norm_2(pos - target)},
                 units={"clearance": "m", "distance_to_target": "m", "pos": "m", "psi": "rad", "v": "m/s",
                        "acc": "m/s^2", "omega": "rad/s"})
    return ocp
