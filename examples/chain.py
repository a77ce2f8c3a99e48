"""A hanging chain of masses moved to a new end position (nx = 21, nu = 3).

Five point masses in 3-D are linked by four elastic springs. Mass 0 is fixed at the
origin, masses 1..3 move freely under gravity and the spring forces (position and
velocity: 6 states each), and the velocity of mass 4, the free end, is the control
(its position: 3 states). So nx = 3 * 6 + 3 = 21, nu = 3.

The task: move the free end from its start to ``END_TARGET`` and bring the chain to
rest, with bounded end velocity. Stage and terminal costs are least squares (so the
Gauss-Newton Hessian applies). The chain starts at rest in the equilibrium computed
below for the end at ``END_START``; the spring stiffness makes it a mildly stiff model
(the fastest mode is about 10 rad/s), so RK4 takes two substeps per 0.1 s interval.

The model is the classic benchmark of nonlinear MPC (a chain of masses and springs);
the formulation, data and costs here are this project's own.
"""
import casadi as ca
import numpy as np

from dopus_codegen import RK4, Event, Ocp

N_FREE = 3                  # masses that move freely (between the fixed one and the end)
MASS = 0.03                 # kg, each mass
STIFFNESS = 1.0             # N/m per spring (of rest length REST_LENGTH)
REST_LENGTH = 0.033         # m
DAMPING = 0.005             # N s/m, linear damping of each free mass
GRAVITY = 9.81
END_START = (0.5, 0.0, 0.0)
END_TARGET = (0.6, 0.2, 0.1)
U_MAX = 1.0                 # m/s, each component of the end velocity
N, DT = 20, 0.1


def spring_force(a, b):
    """Force on mass a from the spring to mass b (Hooke, rest length REST_LENGTH)."""
    d = b - a
    dist = ca.sqrt(ca.dot(d, d))
    return STIFFNESS * (1 - REST_LENGTH / dist) * d


def chain_ode(pos, vel, end, u):
    """xdot of (positions of the free masses, their velocities, end position)."""
    pts = [ca.DM.zeros(3)] + [pos[3 * i:3 * i + 3] for i in range(N_FREE)] + [end]
    acc = []
    for i in range(1, N_FREE + 1):
        f = spring_force(pts[i], pts[i + 1]) + spring_force(pts[i], pts[i - 1])
        a = f / MASS - DAMPING / MASS * vel[3 * i - 3:3 * i] - ca.DM([0, 0, GRAVITY])
        acc.append(a)
    return ca.vertcat(vel, ca.vertcat(*acc), u)


def equilibrium(end):
    """Positions of the free masses at rest with the end held at ``end`` (Newton on the
    force balance, started on the straight line; numpy only)."""
    pos = ca.SX.sym("pos", 3 * N_FREE)
    vel = ca.DM.zeros(3 * N_FREE)
    acc = chain_ode(pos, vel, ca.DM(end), ca.DM.zeros(3))[3 * N_FREE:6 * N_FREE]
    F = ca.Function("F", [pos], [acc, ca.jacobian(acc, pos)])
    p = np.concatenate([np.asarray(end) * (i + 1) / (N_FREE + 1) for i in range(N_FREE)])
    p[2::3] -= 0.05
    for _ in range(50):
        r, J = (np.array(v) for v in F(p))
        step = np.linalg.solve(J, -r.ravel())
        p = p + step
        if np.linalg.norm(step) < 1e-14:
            break
    return p


def x_rest(end):
    return np.concatenate([equilibrium(end), np.zeros(3 * N_FREE), np.asarray(end, dtype=float)])


def shake(x):
    """A push on the middle mass: 0.2 m/s sideways."""
    x = np.array(x, dtype=float, copy=True)
    mid = N_FREE // 2
    x[3 * N_FREE + 3 * mid + 1] += 0.2
    return x


def build(integrator=None):
    ocp = Ocp("chain")
    pos = ocp.state("pos", 3 * N_FREE)
    vel = ocp.state("vel", 3 * N_FREE)
    end = ocp.state("end", 3)
    u = ocp.control("u", 3, lb=-U_MAX, ub=U_MAX)
    ocp.dynamics(chain_ode(pos, vel, end, u), integrator=integrator or RK4(substeps=2))

    target = ca.DM(END_TARGET)
    ocp.stage_least_squares(ca.vertcat(end - target, vel, u),
                            weights=np.concatenate([np.full(3, 25.0), np.full(3 * N_FREE, 0.25),
                                                    np.full(3, 0.01)]) * DT)
    ocp.terminal_least_squares(ca.vertcat(end - target, vel),
                               weights=np.concatenate([np.full(3, 25.0), np.full(3 * N_FREE, 2.5)]))
    ocp.horizon(N=N, dt=DT)

    x0 = x_rest(END_START)
    ocp.initial_state(x0)
    ocp.initial_guess(x=x0, u=[0.0, 0.0, 0.0])
    ocp.options(hessian="exact", M=1)
    ocp.disturbance(shake)
    ocp.scenario(duration=2.0, events=[Event(1.0, shake, "shake")],
                 signals={"end_error": ca.norm_2(end - target)})
    return ocp
