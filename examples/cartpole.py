"""A cart-pole swings its pole up from hanging and balances it, on a short track.

A swing-up: the controller starts with the pole hanging (theta = 0) and must bring it
upright (theta = pi) with a bounded force (active during the swing), then hold it there
through a kick on the pole. The dynamics are those of a point mass on a massless rod (theta
measured from the downward vertical):

    (m_c + m_p sin^2 th) ddp = F + m_p sin th (l dth^2 + g cos th)
    l (m_c + m_p sin^2 th) ddth = -F cos th - m_p l dth^2 cos th sin th - (m_c + m_p) g sin th

Exact Hessian and the default settings (the automatic Levenberg-Marquardt term); the
controller starts from the offline NLP solution (``options(offline_guess=True)``).

The track ends at |p| = 1 m, a soft state bound (docs/algorithm.md section 12). As hard
bounds (``ocp.state("p", lb=-1.0, ub=1.0)``) the swing-up runs the cart into the end with the
force at its bound, along the edge of the set of states from which the cart can still stop
in time; the plant, integrated more accurately than the RK4 model, ends a little beyond that
edge (p = -1.0000005), and the QPs of the next instants are infeasible by margins of 4e-10 to
7e-9 (relative): the QP solver reports them infeasible and names the track's lower bound
(tests/data/cartpole_qp_M1_exact_track_instant14.npz). Soft, the QP cannot be infeasible
(every state-dependent row is soft) and the plant may overrun the end by what the model
error demands, at a price.

How to choose the weights: ``l1`` above the multipliers the hard problem has on the bound
(an exact penalty: wherever the hard problem is feasible its solution is the soft one).
With hard ends at +-1 m the offline solution at the initial state has track multipliers up
to 6.3 (``solve_ocp(...).mu_b[:, 0]``); ``l1 = 25`` is four times that, and the small ``l2 =
100`` makes a forced overrun cost more the deeper it goes.
"""
import casadi as ca
import numpy as np

from dopus_codegen import RK4, Event, Ocp, OnPath, Pushes, Soft

N, DT = 40, 0.05
M_CART, M_POLE, LENGTH, GRAV = 1.0, 0.2, 0.5, 9.81
F_MAX = 12.0         # N
TRACK = 1.0          # m, the track's ends
TRACK_L1, TRACK_L2 = 25.0, 100.0


def cartpole_ode(x, F):
    """xdot for x = (p, theta, v, omega)."""
    th, v, om = x[1], x[2], x[3]
    s, c = ca.sin(th), ca.cos(th)
    den = M_CART + M_POLE * s**2
    acc = (F + M_POLE * s * (LENGTH * om**2 + GRAV * c)) / den
    alpha = (-F * c - M_POLE * LENGTH * om**2 * c * s - (M_CART + M_POLE) * GRAV * s) / (LENGTH * den)
    return ca.vertcat(v, om, acc, alpha)


def kick(x):
    """A kick on the pole: its angular velocity jumps by 2 rad/s."""
    x = np.array(x, dtype=float, copy=True)
    x[3] += 2.0
    return x


def build():
    ocp = Ocp("cartpole")
    p = ocp.state("p", lb=-TRACK, ub=TRACK, soft=Soft(l1=TRACK_L1, l2=TRACK_L2))
    theta = ocp.state("theta")
    v = ocp.state("v")
    omega = ocp.state("omega")
    force = ocp.control("F", lb=-F_MAX, ub=F_MAX)
    x = ca.vertcat(p, theta, v, omega)

    ocp.dynamics(cartpole_ode(x, force), integrator=RK4(substeps=2))
    ocp.stage_least_squares(ca.vertcat(p, theta - ca.pi, v, omega, force),
                            weights=DT * np.array([1.0, 10.0, 0.1, 0.1, 1e-2]))
    ocp.terminal_least_squares(ca.vertcat(p, theta - ca.pi, v, omega), weights=[10.0, 100.0, 1.0, 1.0])
    ocp.horizon(N=N, dt=DT)

    x0 = np.zeros(4)
    ocp.initial_state(x0)
    # the offline solver starts from the pole turning up at a constant rate
    ocp.initial_guess(x=np.column_stack([np.zeros(N + 1), np.linspace(0.0, np.pi, N + 1), np.zeros(N + 1),
                                         np.full(N + 1, np.pi / (N * DT))]), u=[0.0])
    ocp.options(hessian="exact", regularization="none", M=1, offline_guess=True)
    ocp.disturbance(kick)
    ocp.scenario(duration=4.0, events=[Event(3.0, kick, "kick")],
                 signals={"upright_error": theta - ca.pi, "cart_position": p},
                 units={"upright_error": "rad", "cart_position": "m", "p": "m", "theta": "rad", "v": "m/s",
                        "omega": "rad/s", "F": "N"})
    # dopus-gen campaign: a start near the hanging rest, one or two pushes on the balanced
    # pole (pole and cart velocity kicks) between 2.2 s and 3.5 s; upright = the pole within
    # 0.3 rad of the top 2 s after the start (the swing-up) and 2 s after every push (6 s runs).
    ocp.campaign(initial={"theta": 0.05, "p": 0.05},
                 pushes=Pushes(count=(1, 2), window=(2.2, 3.5), kick={"omega": 2.0, "v": 0.5}),
                 on_path=OnPath(signal="upright_error", threshold=0.3, settle=2.0),
                 runs=1000, duration=6.0)
    return ocp
