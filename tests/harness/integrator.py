"""The scalar integrator x' = u, |u| <= 1, N = 10, dt = 0.1 (so |x_N - x_0| <= 1), with the
rows that make its QPs infeasible on purpose: a terminal row out of reach, a path row under a
parameter, an upper path bound.

Used by tests/test_infeasible_row.py (which row the certificate names) and
tests/test_cold_retry.py (no cold retry after a certificate).
"""
from __future__ import annotations

from dopus_codegen import Ocp, build_functions

N, DT = 10, 0.1


def integrator_model(name, x0, terminal=None, parameter=False, upper=None):
    """The built functions of the integrator named `name` from x_0 = x0; terminal = (lb, ub)
    of x_N, parameter: the row x - p >= 0 with p = -10, upper: the path bound x <= upper."""
    ocp = Ocp(name)
    x = ocp.state("x")
    u = ocp.control("u", lb=-1.0, ub=1.0)
    ocp.dynamics(u)
    ocp.stage_least_squares(u, weights=[1.0])
    if parameter:
        p = ocp.parameter("p", value=-10.0)
        ocp.path_constraint(x - p, lb=0.0)
    if upper is not None:
        ocp.path_constraint(x, ub=upper)
    if terminal is not None:
        ocp.terminal_constraint(x, lb=terminal[0], ub=terminal[1])
    ocp.horizon(N=N, dt=DT)
    ocp.initial_state([x0])
    return build_functions(ocp)
