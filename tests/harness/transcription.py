"""Pieces of the independent IPOPT transcriptions written out in the tests."""
from __future__ import annotations

import casadi as ca
import numpy as np


def rk4_double_integrator(x, u, dt):
    """One RK4 step of (position, velocity)' = (velocity, u) over dt: the integrator map the
    examples of tests/test_rate.py and tests/test_rows.py generate with the default integrator, RK4(1)."""
    def f(z):
        return ca.vertcat(z[1], u)

    k1 = f(x)
    k2 = f(x + dt / 2 * k1)
    k3 = f(x + dt / 2 * k2)
    k4 = f(x + dt * k3)
    return x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)


def double_integrator_nlp(N, dt, u_max, x0):
    """The skeleton of the written-out NLPs: ``(opti, X, U)`` with X (2 x N+1), U (1 x N), the
    RK4 map at every stage, ``|u_k| <= u_max`` and ``x_0 = x0``; the caller adds its cost and rows."""
    opti = ca.Opti()
    X, U = opti.variable(2, N + 1), opti.variable(1, N)
    for k in range(N):
        opti.subject_to(X[:, k + 1] == rk4_double_integrator(X[:, k], U[k], dt))
        opti.subject_to(opti.bounded(-u_max, U[k], u_max))
    opti.subject_to(X[:, 0] == ca.DM(x0))
    return opti, X, U


def solve_nlp(opti, J, X, U):
    """Minimise J with IPOPT to 1e-12: ``(x (N+1, 2), u (N, 1))``."""
    opti.minimize(J)
    opti.solver("ipopt", {"print_time": False}, {"print_level": 0, "tol": 1e-12, "sb": "yes"})
    sol = opti.solve()
    return sol.value(X).T, np.atleast_1d(sol.value(U)).reshape(U.size2(), 1)
