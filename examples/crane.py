"""A gantry crane moves its load next to a wall and leaves it nearly at rest: a nonlinear terminal set.

The trolley (position ``p``, velocity ``v``) carries a load on a rope of length ``L`` (angle
``theta`` from the vertical, angular velocity ``omega``); the control is the trolley's
acceleration ``a``. The load hangs at ``p + L sin(theta)`` and swings as a pendulum driven
by the trolley:

    dp = v,  dv = a,  dtheta = omega,  domega = -(a cos(theta) + g sin(theta)) / L

The load must be brought to the target ``TARGET`` (the stage cost: its distance, the
acceleration and the swing), never past a wall at ``WALL`` just short of it (a path row on
the load's position that also holds at x_N), and left at the end of the horizon in an
energy-like terminal set around the target: the load's distance to the target plus its
kinetic and swing energy (scaled to a length by the pendulum's frequency ``w = sqrt(g / L)``)
within the radius ``R_TERM``:

    (x_load - TARGET)^2 + (v^2 + (L omega)^2 + 2 g L (1 - cos theta)) / w^2 <= R_TERM^2

At the NLP's solution from the initial state (IPOPT) the terminal set is active (multiplier
48.8), and so is the wall, at x_N (4.6) and during the transfer (22.7); the trolley's
acceleration is at its bound for the first 0.4 s.

From the cold guess (the crane at rest at the start) the globalised first solve
(docs/algorithm.md section 15: every stage re-linearised, an l1 merit function with a
watchdog and a line search) converges to that solution in 8 full steps: ``dopus-gen converge
examples/crane.py --start cold`` (which also runs the real-time iteration with M = 1; from
this guess it converges too, in 11 iterations). The controller itself starts from the
offline NLP solution (``options(offline_guess=True)``).
"""
import casadi as ca
import numpy as np

from dopus_codegen import RK4, Event, Ocp

N, DT = 32, 0.1
L, GRAV = 1.0, 9.81          # m, m/s^2
A_MAX = 4.0                  # m/s^2, trolley acceleration
V_MAX = 3.0                  # m/s, trolley speed
TARGET = 2.0                 # m, where the load goes
WALL = 1.98                  # m, the load stays left of the wall (just short of the target)
R_TERM = 0.05                # m, radius of the terminal set
TRACK = 100.0                # weight of the load's distance to the target in the stage cost
W2 = GRAV / L                # the pendulum's squared frequency, 1/s^2


def load_position(p, theta):
    """Horizontal position of the load (m)."""
    return p + L * ca.sin(theta)


def terminal_energy(p, v, theta, omega):
    """The terminal set's function: squared distance to the target plus the scaled energy (m^2)."""
    energy = v**2 + (L * omega) ** 2 + 2.0 * GRAV * L * (1.0 - ca.cos(theta))
    return (load_position(p, theta) - TARGET) ** 2 + energy / W2


def swing(x):
    """A push on the load away from the wall: its angular velocity drops by 0.3 rad/s."""
    x = np.array(x, dtype=float, copy=True)
    x[3] -= 0.3
    return x


def build():
    ocp = Ocp("crane")
    p = ocp.state("p")
    v = ocp.state("v", lb=-V_MAX, ub=V_MAX)
    theta = ocp.state("theta", lb=-1.0, ub=1.0)
    omega = ocp.state("omega")
    a = ocp.control("a", lb=-A_MAX, ub=A_MAX)

    ocp.dynamics(ca.vertcat(v, a, omega, -(a * ca.cos(theta) + GRAV * ca.sin(theta)) / L),
                 integrator=RK4(substeps=2))
    ocp.stage_least_squares(ca.vertcat(a, L * omega, load_position(p, theta) - TARGET),
                            weights=DT * np.array([1.0, 1.0, TRACK]))
    ocp.path_constraint(load_position(p, theta), ub=WALL, name="wall", terminal=True)
    ocp.terminal_constraint(terminal_energy(p, v, theta, omega), ub=R_TERM**2, name="terminal_set")
    ocp.horizon(N=N, dt=DT)

    x0 = np.zeros(4)
    ocp.initial_state(x0)
    ocp.initial_guess(x=x0, u=[0.0])          # the cold guess: the crane at rest at the start
    ocp.options(hessian="exact", M=1, offline_guess=True)
    ocp.disturbance(swing)
    ocp.scenario(duration=5.0, events=[Event(3.5, swing, "swing")],
                 signals={"load_to_wall": load_position(p, theta) - WALL,
                          "load_to_target": load_position(p, theta) - TARGET},
                 units={"load_to_wall": "m", "load_to_target": "m", "p": "m", "v": "m/s", "theta": "rad",
                        "omega": "rad/s", "a": "m/s^2"})
    return ocp
