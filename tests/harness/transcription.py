"""Pieces of the independent IPOPT transcriptions written out in the tests."""
from __future__ import annotations

import casadi as ca


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
