"""An exothermic continuous stirred-tank reactor with a cooling jacket, in physical units.

States: the concentration ``cA`` of the reactant (mol/l), the reactor temperature ``T`` (K)
and the jacket temperature ``Tj`` (K); control: the coolant inlet temperature ``Tc`` (K).
Time is in minutes. The first-order reaction A -> B releases heat at the Arrhenius rate
``k(T) = k0 exp(-E/(R T))`` (the reactor of Seborg et al., "Process Dynamics and Control",
with a jacket of 2 l flushed at 400 l/min: its time constant of 0.3 s makes the model stiff,
an eigenvalue near -200 1/min against intervals of 0.05 min; Radau IIA, L-stable, integrates
it with any step).

    dcA/dt = q/V (cAf - cA) - k(T) cA
    dT/dt  = q/V (Tf - T) + (-dH)/(rho Cp) k(T) cA + UA/(V rho Cp) (Tj - T)
    dTj/dt = Fj/Vj (Tc - Tj) + UA/(rho_j Cp_j Vj) (T - Tj)

Task: from the steady state at ``Tc = 300 K`` (cA 0.575 mol/l, T 345.8 K) raise the
conversion to ``CA_REF`` mol/l without the reactor exceeding ``T_MAX`` (a hard path row by
default, ``build(soft_tmax=Soft(...))`` makes it soft).

The numbers span four decades (0.3 mol/l, 350 K, a cost of order 1): ``build(scaled=True)``
(the OCP file's default) declares the scales of section 16 of docs/algorithm.md, so that the
solver works with variables of order one; ``build(scaled=False)`` is the same problem without
them, ``build(cost_scale=c)`` another cost scale. tests/test_scaling.py runs both in float and
double against IPOPT; bench/float_scaling.py sweeps the cost scale.
"""
import casadi as ca
import numpy as np

from dopus_codegen import Event, Ocp, RadauIIA

Q, V, CAF, TF = 100.0, 100.0, 1.0, 350.0           # l/min, l, mol/l, K
RHO, CP, DH, ER, K0, UA = 1000.0, 0.239, -5e4, 8750.0, 7.2e10, 5e4   # g/l, J/(g K), J/mol, K, 1/min, J/(min K)
VJ, FJ, CPJ = 2.0, 400.0, 4.18                     # l, l/min, J/(g K)
TC_MIN, TC_MAX = 280.0, 330.0                      # K
T_MAX = 355.0                                      # K
# the target: the steady state with cA = 0.5 mol/l, the three ODEs below with dx/dt = 0 solved
# in turn: dcA/dt = 0 gives the rate k(T) cA = q/V (cAf - cA) (k(T) = 1 1/min, T = E/R / ln k0);
# dT/dt = 0 the jacket temperature, dTj/dt = 0 the coolant's (Tj 300.0 K, Tc 298.5 K)
CA_REF = 0.5
RATE_REF = Q / V * (CAF - CA_REF)                  # k(T_REF) CA_REF, mol/(l min)
T_REF = ER / np.log(K0 * CA_REF / RATE_REF)        # 350.0 K
TJ_REF = T_REF - (Q / V * (TF - T_REF) + (-DH) / (RHO * CP) * RATE_REF) / (UA / (V * RHO * CP))
TC_REF = TJ_REF - UA / (RHO * CPJ * VJ) * (T_REF - TJ_REF) / (FJ / VJ)
COST_SCALE = 10.0                                  # the cost's typical size (a few units of 10)
N, DT = 30, 0.05                                   # intervals of 0.05 min (3 s)
X0 = np.array([0.5754807664, 345.7926648692, 301.3296360333])   # the steady state at Tc = 300 K


def cstr_ode(x, Tc):
    cA, T, Tj = x[0], x[1], x[2]
    rate = K0 * ca.exp(-ER / T) * cA
    return ca.vertcat(Q / V * (CAF - cA) - rate,
                      Q / V * (TF - T) + (-DH) / (RHO * CP) * rate + UA / (V * RHO * CP) * (Tj - T),
                      FJ / VJ * (Tc - Tj) + UA / (RHO * CPJ * VJ) * (T - Tj))


def push(x):
    """A feed disturbance: 0.1 mol/l more reactant and the reactor 3 K warmer."""
    x = np.array(x, dtype=float, copy=True)
    x[0] += 0.1
    x[1] += 3.0
    return x


def build(scaled=True, soft_tmax=None, real=None, cost_scale=COST_SCALE):
    ocp = Ocp("cstr")
    x = ocp.state("x", 3, lb=[0.0, 250.0, 250.0], ub=[CAF, 450.0, 450.0],
                  scale=[0.5, 350.0, 300.0] if scaled else None)
    Tc = ocp.control("Tc", lb=TC_MIN, ub=TC_MAX, scale=300.0 if scaled else None)
    ocp.dynamics(cstr_ode(x, Tc), integrator=RadauIIA(stages=2, substeps=1, newton_iters=3))
    ocp.stage_least_squares(ca.vertcat(x[0] - CA_REF, x[1] - T_REF, Tc - TC_REF), weights=DT * np.array([1e3, 1e-2, 1e-2]))
    ocp.terminal_least_squares(ca.vertcat(x[0] - CA_REF, x[1] - T_REF), weights=[1e2, 1e-1])
    ocp.path_constraint(x[1], ub=T_MAX, name="T_max", soft=soft_tmax, terminal=True,
                        scale=350.0 if scaled else None)
    if scaled:
        ocp.scaling(cost=cost_scale)
    ocp.horizon(N=N, dt=DT)
    ocp.initial_state(X0)
    ocp.initial_guess(x=X0, u=[300.0])
    ocp.options(hessian="exact", M=1, kkt_tol_rel=1e-6)
    if real is not None:
        ocp.options(real=real)
    ocp.disturbance(push)
    ocp.scenario(duration=3.0, events=[Event(1.5, push, "feed disturbance")],
                 signals={"cA_error": x[0] - CA_REF, "T_above_max": x[1] - T_MAX},
                 units={"time": "min", "cA_error": "mol/l", "T_above_max": "K", "Tc": "K"})
    return ocp
