"""A vehicle follows a figure-eight: a reference that moves, declared in the OCP file.

The reference position is a runtime parameter with a trajectory (``Ocp.parameter(...,
trajectory=f)``): node ``k`` of the horizon at time ``t`` gets ``f(t + k dt)``. The
generated solver shifts the parameters with the horizon; the closed loop pushes the
value of the new last node between feedback and prepare (``dopus-gen sil``, the
generated main), and the initial guess, the offline solution and ``converge`` use the
first horizon (t = 0).

The vehicle is a unicycle with speed and turn-rate dynamics (states: position, heading,
speed; controls: acceleration and turn rate). The figure-eight is the Lissajous curve
``(A sin(w t), A/2 sin(2 w t))``, one lap in ``2 pi / w`` seconds; the vehicle starts
at rest 0.3 m off the curve's start and is pushed sideways half-way.
"""
import casadi as ca
import numpy as np

from dopus_codegen import RK4, Event, Ocp

N, DT = 20, 0.1
A, W = 2.0, 0.5                  # m, rad/s: one lap in 4 pi = 12.6 s, top speed about 1.4 m/s
V_MAX, A_MAX, OMEGA_MAX = 2.5, 3.0, 3.0


def figure_eight(t):
    """The reference position at time ``t`` (s)."""
    return [A * np.sin(W * t), 0.5 * A * np.sin(2.0 * W * t)]


def push(x):
    """A sideways push of 0.3 m."""
    x = np.array(x, dtype=float, copy=True)
    x[1] += 0.3
    return x


def build():
    ocp = Ocp("figure_eight")
    pos = ocp.state("pos", 2)
    psi = ocp.state("psi")
    v = ocp.state("v", lb=-0.5, ub=V_MAX)
    acc = ocp.control("acc", lb=-A_MAX, ub=A_MAX)
    omega = ocp.control("omega", lb=-OMEGA_MAX, ub=OMEGA_MAX)
    ref = ocp.parameter("ref", 2, trajectory=figure_eight)

    ocp.dynamics(ca.vertcat(v * ca.cos(psi), v * ca.sin(psi), omega, acc), integrator=RK4(substeps=1))
    ocp.stage_least_squares(ca.vertcat(pos - ref, acc, omega), weights=DT * np.array([10.0, 10.0, 0.1, 0.1]))
    ocp.terminal_least_squares(pos - ref, weights=[10.0, 10.0])
    ocp.horizon(N=N, dt=DT)

    x0 = np.array([0.0, -0.3, np.pi / 4, 0.0])
    ocp.initial_state(x0)
    ocp.initial_guess(x=x0, u=[0.0, 0.0])
    ocp.options(hessian="exact", M=1, offline_guess=True)
    ocp.disturbance(push)
    ocp.scenario(duration=2 * np.pi / W, events=[Event(6.0, push, "push")],
                 signals={"tracking_error": ca.norm_2(pos - ref)},
                 units={"tracking_error": "m", "pos": "m", "psi": "rad", "v": "m/s", "acc": "m/s^2",
                        "omega": "rad/s"})
    return ocp
