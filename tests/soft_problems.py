"""Small OCPs with soft rows and an independent CasADi + IPOPT transcription of them with
explicit slack variables (the reference of tests/test_soft.py)."""
from __future__ import annotations

import casadi as ca
import numpy as np

from dopus_codegen import Ocp, RK4, Soft


def cart_l1(N=20):
    """Double integrator driven to p = 1 with a soft speed limit |v| <= 0.3 (L1 only); the
    initial speed 0.5 violates it, so the slacks of the first stages are active."""
    ocp = Ocp("soft_cart_l1")
    p = ocp.state("p")
    v = ocp.state("v", lb=-0.3, ub=0.3, soft=Soft(l1=2.0))
    a = ocp.control("a", lb=-1.0, ub=1.0)
    ocp.dynamics(ca.vertcat(v, a), integrator=RK4(1))
    ocp.stage_least_squares(ca.vertcat(p - 1.0, v, a), [1.0, 0.1, 0.1])
    ocp.terminal_least_squares(ca.vertcat(p - 1.0, v), [10.0, 1.0])
    ocp.horizon(N=N, dt=0.1)
    ocp.initial_state([0.0, 0.5])
    ocp.options(hessian="gauss-newton")
    return ocp


def orbit_l2(N=20):
    """A point steered towards (2, 0) around a soft nonlinear keep-out disc of radius 1 at
    (1, 0) (L2 only, both sides of a two-sided row ... only the lower side is finite)."""
    ocp = Ocp("soft_orbit_l2")
    q = ocp.state("q", 2)
    u = ocp.control("u", 2, lb=-2.0, ub=2.0)
    ocp.dynamics(u, integrator=RK4(1))
    ocp.stage_least_squares(ca.vertcat(q[0] - 2.0, q[1], u), [1.0, 1.0, 0.05, 0.05])
    ocp.terminal_least_squares(ca.vertcat(q[0] - 2.0, q[1]), [5.0, 5.0])
    ocp.path_constraint((q[0] - 1.0) ** 2 + q[1] ** 2, lb=1.0, soft=Soft(l2=20.0))
    ocp.horizon(N=N, dt=0.1)
    ocp.initial_state([-0.2, 0.1])
    ocp.options(hessian="gauss-newton")
    return ocp


def reach_both(N=20):
    """A double integrator whose soft terminal equality p_N = 3 is out of reach with |a| <= 1
    (L1 and L2), and a soft upper speed bound (L1 and L2, different per side)."""
    ocp = Ocp("soft_reach_both")
    p = ocp.state("p")
    v = ocp.state("v", ub=0.95, soft=Soft(l1=(0.0, 0.5), l2=(0.0, 4.0)))
    a = ocp.control("a", lb=-1.0, ub=1.0)
    ocp.dynamics(ca.vertcat(v, a), integrator=RK4(1))
    ocp.stage_least_squares(ca.vertcat(v, a), [0.1, 0.1])
    ocp.terminal_constraint(p, lb=3.0, ub=3.0, soft=Soft(l1=1.0, l2=10.0))
    ocp.horizon(N=N, dt=0.1)
    ocp.initial_state([0.0, 0.0])
    ocp.options(hessian="gauss-newton")
    return ocp


def ipopt_with_slacks(disc, xhat0, tol=1e-12):
    """The OCP of ``disc`` with every soft side as an explicit slack variable ``s >= 0``
    (``lb - s <= row``, ``row <= ub + s``, cost ``l1 s + 0.5 l2 s^2`` per side and node),
    solved by IPOPT from the declared guess. Returns ``(x, u, slacks)``: slacks a dict of
    the largest slack per group ``x``, ``g``, ``r``."""
    N, nx, nu, ng, nr, ne = disc.N, disc.nx, disc.nu, disc.ng, disc.nr, disc.ne
    P = disc.p0
    X = ca.MX.sym("X", nx, N + 1)
    U = ca.MX.sym("U", nu, N)
    f = 0
    cons, lbg, ubg, slacks, groups = [], [], [], [], []

    def soften(expr, lb, ub, w, group):
        nonlocal f
        for i in range(expr.size1()):
            for side, bound in ((0, lb[i]), (1, ub[i])):
                if not np.isfinite(bound):
                    continue
                l1, l2 = w[side, i], w[2 + side, i]
                if l1 > 0 or l2 > 0:
                    s = ca.MX.sym("s")
                    slacks.append(s)
                    groups.append(group)
                    f += l1 * s + 0.5 * l2 * s ** 2
                    cons.append(expr[i] + s if side == 0 else expr[i] - s)
                else:
                    cons.append(expr[i])
                lbg.append(bound if side == 0 else -np.inf)
                ubg.append(np.inf if side == 0 else bound)

    cons.append(X[:, 0] - xhat0)
    lbg += [0.0] * nx
    ubg += [0.0] * nx
    for k in range(N):
        phi, l, g = disc.stage_eval(X[:, k], U[:, k], P[k])
        f += l
        cons.append(X[:, k + 1] - phi)
        lbg += [0.0] * nx
        ubg += [0.0] * nx
        soften(U[:, k], disc.lbu, disc.ubu, np.zeros((4, nu)), "u")
        soften(X[:, k + 1], disc.lbx, disc.ubx, disc.soft_x, "x")
        if ng:
            soften(g, disc.lg, disc.ug, disc.soft_g, "g")
    E, r, r_eq = disc.term_eval(X[:, N], P[N])
    f += E
    if nr:
        soften(r, disc.lr, disc.ur, disc.soft_r, "r")
    if ne:
        cons.append(r_eq)
        lbg += [0.0] * ne
        ubg += [0.0] * ne
    S = ca.vertcat(*slacks) if slacks else ca.MX(0, 1)
    z = ca.vertcat(ca.vec(X), ca.vec(U), S)
    solver = ca.nlpsol("soft_ipopt", "ipopt", {"x": z, "f": f, "g": ca.vertcat(*cons)},
                       {"print_time": False, "ipopt": {"print_level": 0, "sb": "yes", "tol": tol,
                                                        "bound_relax_factor": 0.0, "max_iter": 3000}})
    g0 = disc.initial_guess
    z0 = np.concatenate([g0.x.reshape(-1), g0.u.reshape(-1), np.zeros(len(slacks))])
    lbz = np.concatenate([np.full((N + 1) * nx + N * nu, -np.inf), np.zeros(len(slacks))])
    res = solver(x0=z0, lbx=lbz, ubx=np.inf, lbg=np.array(lbg), ubg=np.array(ubg))
    assert solver.stats()["success"], solver.stats()["return_status"]
    zz = np.array(res["x"]).reshape(-1)
    x = zz[:(N + 1) * nx].reshape(N + 1, nx)
    u = zz[(N + 1) * nx:(N + 1) * nx + N * nu].reshape(N, nu)
    s = zz[(N + 1) * nx + N * nu:]
    out = {grp: float(max([v for v, gr in zip(s, groups) if gr == grp], default=0.0)) for grp in ("x", "g", "r")}
    return x, u, out


def cone(N=20):
    """A point pulled towards (1, 1) and kept in the cone 1 - 2(a^2 + b^2) >= 0.5 (a hard
    path row), guessed at a = b = 0 where the row's gradient vanishes: after the first
    step, a stage that still holds the guess's linearisation has the row 0 dw >= 0.5 - g
    with g < 0.5 (docs/algorithm.md section 4, step 4)."""
    ocp = Ocp("stale_cone")
    q = ocp.state("q", 2)
    v = ocp.control("v", 2, lb=-5.0, ub=5.0)
    ocp.dynamics(v, integrator=RK4(1))
    ocp.stage_least_squares(ca.vertcat(q[0] - 1.0, q[1] - 1.0, v), [1.0, 1.0, 0.01, 0.01])
    ocp.terminal_least_squares(ca.vertcat(q[0] - 1.0, q[1] - 1.0), [1.0, 1.0])
    ocp.path_constraint(1.0 - 2.0 * (q[0] ** 2 + q[1] ** 2), lb=0.5)
    ocp.horizon(N=N, dt=0.1)
    ocp.initial_state([0.0, 0.0])
    ocp.options(hessian="gauss-newton")
    return ocp


def all_soft(N=15):
    """Every state-dependent row soft (a state bound L1 + L2, an L1 speed bound, an L2 path row,
    an L1 terminal equality): the QP is feasible for every finite measurement."""
    ocp = Ocp("soft_all")
    p = ocp.state("p", lb=-1.0, ub=1.0, soft=Soft(l1=10.0, l2=1.0))
    v = ocp.state("v", lb=-0.5, ub=0.5, soft=Soft(l1=10.0))
    a = ocp.control("a", lb=-1.0, ub=1.0)
    ocp.dynamics(ca.vertcat(v, a), integrator=RK4(1))
    ocp.stage_least_squares(ca.vertcat(p, v, a), [1.0, 0.1, 0.1])
    ocp.path_constraint(p + 0.5 * v, lb=-1.2, ub=1.2, soft=Soft(l2=50.0))
    ocp.terminal_constraint(p, lb=0.0, ub=0.0, soft=Soft(l1=5.0))
    ocp.horizon(N=N, dt=0.1)
    ocp.initial_state([0.0, 0.0])
    ocp.options(hessian="gauss-newton")
    return ocp
