"""A pendulum driven by a DC motor whose electrical time constant is 1 ms (stiff).

States: angle ``theta`` (rad), angular speed ``omega`` (rad/s) and the motor current
``i`` (A); control: the voltage ``v`` (V). The armature circuit

    L di/dt = v - R i - K omega          (L / R = 1 ms: an eigenvalue near -1000 1/s)

drives the pendulum ``J domega/dt = K i - b omega - m g l sin(theta)``. With intervals of
50 ms an explicit scheme must resolve the 1 ms mode to stay stable (RK4: h * 1000 < 2.8,
at least 18 substeps per interval) although the current just follows its quasi-steady
state; Radau IIA (L-stable) is stable with any step. The accuracy table of docs/usage.md ("Integrators
and the size of the derivative code") compares them against a converged reference.

Task: swing the pendulum from rest at 0 to ``TARGET`` rad and hold it, with voltage and
current limits. The OCP file's integrator is Radau IIA with 2 stages and 4 substeps;
``build(integrator)`` takes another one (the tests and the accuracy table use it).

``build(soft_current=Soft(l1=[0, 0, l1], l2=[0, 0, l2]), current_limit=...)`` makes the
current limit soft (a limit the motor may exceed briefly at a price; one weight per state
component, 0 on the unbounded angle and speed); tests/test_soft.py checks the soft variant,
with its implicit integrator and the limit lowered to 1 A so that it is active, against
IPOPT with explicit slacks.
"""
import casadi as ca
import numpy as np

from dopus_codegen import Event, Ocp, RadauIIA

R, L, K = 2.0, 2e-3, 0.1          # ohm, henry, N m / A (= V s / rad)
J, B, MGL = 1e-3, 1e-3, 0.05      # kg m^2, N m s, N m
V_MAX, I_MAX = 12.0, 4.0
TARGET = 1.0
N, DT = 20, 0.05


def motor_ode(x, v):
    theta, omega, i = x[0], x[1], x[2]
    return ca.vertcat(omega,
                      (K * i - B * omega - MGL * ca.sin(theta)) / J,
                      (v - R * i - K * omega) / L)


def push(x):
    x = np.array(x, dtype=float, copy=True)
    x[1] += 2.0
    return x


def build(integrator=None, soft_current=None, current_limit=I_MAX):
    ocp = Ocp("stiff_motor")
    x = ocp.state("x", 3, lb=[-np.inf, -np.inf, -current_limit], ub=[np.inf, np.inf, current_limit],
                  soft=soft_current)
    v = ocp.control("v", lb=-V_MAX, ub=V_MAX)
    ocp.dynamics(motor_ode(x, v), integrator=integrator or RadauIIA(stages=2, substeps=4, newton_iters=2))
    ocp.stage_least_squares(ca.vertcat(x[0] - TARGET, x[1], v), weights=DT * np.array([100.0, 1.0, 0.01]))
    ocp.terminal_least_squares(ca.vertcat(x[0] - TARGET, x[1]), weights=[100.0, 1.0])
    ocp.horizon(N=N, dt=DT)
    x0 = np.zeros(3)
    ocp.initial_state(x0)
    ocp.initial_guess(x=x0, u=[0.0])
    ocp.options(hessian="gauss-newton", M=1)
    ocp.disturbance(push)
    ocp.scenario(duration=1.5, events=[Event(0.75, push, "push")],
                 signals={"angle_error": x[0] - TARGET})
    return ocp
