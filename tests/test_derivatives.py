"""The functions of docs/algorithm.md section 2 against finite differences of the
plain evaluations (``stage_eval``, ``term_eval``, the least-squares residuals), at
random points with random multipliers, for both examples; and the robot-arm model and
cost against an independent numpy transcription of docs/robot_arm.md."""
import math

import numpy as np
import pytest

from dopus_codegen import build_functions, load_ocp

from conftest import EXAMPLES, ROBOT_ARM_FILE

H1 = 1e-6     # central differences of first derivatives
H2 = 1e-5     # central differences of gradients (second derivatives)
RTOL = 1e-8   # relative to the largest entry; the differences above are good to about 3e-10


def fd_jac(f, z, h):
    z = np.asarray(z, float)
    cols = []
    for i in range(z.size):
        e = np.zeros_like(z)
        e[i] = h
        cols.append((np.asarray(f(z + e), float).reshape(-1) - np.asarray(f(z - e), float).reshape(-1)) / (2 * h))
    return np.array(cols).T.reshape(-1, z.size)


def close(a, b, rtol):
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    scale = max(1.0, float(np.max(np.abs(b))) if b.size else 1.0)
    return np.allclose(a, b, rtol=0, atol=rtol * scale), float(np.max(np.abs(a - b))) if a.size else 0.0


def random_points(disc, rng, count):
    """Points around the initial guess and bounds-respecting random controls."""
    g = disc.initial_guess
    for _ in range(count):
        k = int(rng.integers(disc.N))
        x = g.x[k] + 0.2 * rng.standard_normal(disc.nx)
        lo = np.where(np.isfinite(disc.lbu), disc.lbu, -2.0)
        hi = np.where(np.isfinite(disc.ubu), disc.ubu, 2.0)
        u = lo + (hi - lo) * rng.random(disc.nu)
        p = disc.p0[k] + 0.1 * rng.standard_normal(disc.np)
        lam = rng.standard_normal(disc.nx)
        mu_g = rng.standard_normal(disc.ng)
        yield x, u, p, lam, mu_g


def dm(v):
    return np.array(v, float)


@pytest.fixture(params=["robot", "second"])
def disc(request, robot_disc, second_disc):
    return robot_disc if request.param == "robot" else second_disc


def test_stage_grad_and_hessian_blocks(disc):
    rng = np.random.default_rng(7)
    nx = disc.nx
    for x, u, p, lam, mu_g in random_points(disc, rng, 4):
        w = np.concatenate([x, u])

        def split(wv):
            return wv[:nx], wv[nx:]

        def lagr(wv):
            phi, l, g = disc.stage_eval(*split(wv), p)
            return float(l) - lam @ dm(phi).ravel() + mu_g @ dm(g).ravel()

        gL, phi, l, g = disc.stage_grad(x, u, p, lam, mu_g)
        phi_e, l_e, g_e = disc.stage_eval(x, u, p)
        assert np.array_equal(dm(phi), dm(phi_e)) and float(l) == float(l_e) and np.array_equal(dm(g), dm(g_e))

        ok, err = close(dm(gL).ravel(), fd_jac(lambda z: np.array([lagr(z)]), w, H1).ravel(), RTOL)
        assert ok, f"gL vs FD: {err}"

        A, Phi, C = disc.stage_hess_exact(x, u, p, lam, mu_g)
        A = dm(A)
        assert np.array_equal(A, A.T)
        A_fd = fd_jac(lambda z: dm(disc.stage_grad(*split(z), p, lam, mu_g)[0]), w, H2)
        ok, err = close(A, A_fd, RTOL)
        assert ok, f"A exact vs FD of gL: {err}"
        ok, err = close(dm(Phi), fd_jac(lambda z: dm(disc.stage_eval(*split(z), p)[0]), w, H1), RTOL)
        assert ok, f"Phi vs FD of phi: {err}"
        if disc.ng:
            ok, err = close(dm(C), fd_jac(lambda z: dm(disc.stage_eval(*split(z), p)[2]), w, H1), RTOL)
            assert ok, f"C vs FD of g: {err}"

        assert disc.has_gn and disc.stage_residual is not None
        A_gn, Phi_gn, C_gn = disc.stage_hess_gn(x, u, p, lam, mu_g)
        J = fd_jac(lambda z: dm(disc.stage_residual(*split(z), p)), w, H1)
        W = disc.data.W
        # both examples have a pure least-squares stage cost: l = 0.5 res' W res
        res = dm(disc.stage_residual(x, u, p)).ravel()
        assert math.isclose(float(l), 0.5 * res @ W @ res, rel_tol=1e-12, abs_tol=1e-15)
        ok, err = close(dm(A_gn), J.T @ W @ J, RTOL)
        assert ok, f"GN A vs J'WJ: {err}"
        assert np.array_equal(dm(Phi_gn), dm(Phi)) and np.array_equal(dm(C_gn), dm(C))


def test_stage_cost_hessian(disc):
    """A_l (algorithm.md section 4 step 5): exact = FD of grad_w l (stage_grad with zero
    multipliers); Gauss-Newton = J' W J with J by FD of the residual."""
    rng = np.random.default_rng(5)
    nx = disc.nx
    zl, zg = np.zeros(disc.nx), np.zeros(disc.ng)
    for x, u, p, _, _ in random_points(disc, rng, 4):
        w = np.concatenate([x, u])

        def split(wv):
            return wv[:nx], wv[nx:]

        A_l = dm(disc.stage_hess_cost("exact")(x, u, p))
        assert A_l.shape == (disc.nw, disc.nw) and np.array_equal(A_l, A_l.T)
        A_fd = fd_jac(lambda z: dm(disc.stage_grad(*split(z), p, zl, zg)[0]), w, H2)
        ok, err = close(A_l, A_fd, RTOL)
        assert ok, f"A_l exact vs FD of grad l: {err}"
        A_gn = dm(disc.stage_hess_cost("gauss-newton")(x, u, p))
        J = fd_jac(lambda z: dm(disc.stage_residual(*split(z), p)), w, H1)
        ok, err = close(A_gn, J.T @ disc.data.W @ J, RTOL)
        assert ok, f"A_l GN vs J'WJ: {err}"
        # the Gauss-Newton A has no curvature besides the cost's: A - A_l = 0
        lam, mu_g = rng.standard_normal(disc.nx), rng.standard_normal(disc.ng)
        assert np.max(np.abs(dm(disc.stage_hess_gn(x, u, p, lam, mu_g)[0]) - A_gn)) <= 1e-14 * max(1.0, np.abs(A_gn).max())


def test_stage_cost_hessian_with_extra_cost():
    """Gauss-Newton A_l = J' W J + hess l_extra: with an affine residual this is the exact
    hess l, checked by FD of grad l; without least squares there is no GN A_l."""
    import casadi as ca

    from dopus_codegen import Ocp
    from dopus_codegen.problem.ocp import OcpError

    ocp = Ocp("extra_cost")
    x = ocp.state("x", 2)
    u = ocp.control("u", lb=-1, ub=1)
    ocp.dynamics(ca.vertcat(x[1], u - ca.sin(x[0])))
    ocp.stage_least_squares(ca.vertcat(x - 1.0, u), weights=[1.0, 0.5, 0.1])
    ocp.stage_cost(x[0] ** 2 * u + ca.cos(x[1]))
    ocp.horizon(N=4, dt=0.1)
    ocp.initial_state([0.3, 0.0])
    d = build_functions(ocp)
    rng = np.random.default_rng(2)
    zl, zg = np.zeros(d.nx), np.zeros(d.ng)
    for _ in range(3):
        w = rng.standard_normal(d.nw)
        A_fd = fd_jac(lambda z: dm(d.stage_grad(z[:2], z[2:], [], zl, zg)[0]), w, H2)
        for kind in ("exact", "gauss-newton"):
            ok, err = close(dm(d.stage_hess_cost(kind)(w[:2], w[2:], [])), A_fd, RTOL)
            assert ok, f"{kind} A_l vs FD: {err}"
    ocp2 = Ocp("no_ls")
    y = ocp2.state("y")
    v = ocp2.control("v")
    ocp2.dynamics(v - y)
    ocp2.stage_cost(y ** 4 + v ** 2)
    ocp2.horizon(N=3, dt=0.1)
    ocp2.initial_state([1.0])
    d2 = build_functions(ocp2)
    assert d2.stage_hess_cost_gn is None
    with pytest.raises(OcpError, match="stage_least_squares"):
        d2.stage_hess_cost("gauss-newton")
    A = dm(d2.stage_hess_cost("exact")([0.5], [0.2], []))
    np.testing.assert_allclose(A, np.diag([12 * 0.25, 2.0]), rtol=1e-14)


def test_terminal_functions(disc):
    rng = np.random.default_rng(11)
    for x, _, p, _, _ in random_points(disc, rng, 4):
        mu_r = rng.standard_normal(disc.nr)
        nu = rng.standard_normal(disc.ne)

        def lagr(z):
            E, r, r_eq = disc.term_eval(z, p)
            return float(E) + mu_r @ dm(r).ravel() + nu @ dm(r_eq).ravel()

        gL, E, r, r_eq = disc.term_grad(x, p, mu_r, nu)
        ok, err = close(dm(gL).ravel(), fd_jac(lambda z: np.array([lagr(z)]), x, H1).ravel(), RTOL)
        assert ok, f"terminal gL vs FD: {err}"
        A, R, R_eq = disc.term_hess_exact(x, p, mu_r, nu)
        ok, err = close(dm(A), fd_jac(lambda z: dm(disc.term_grad(z, p, mu_r, nu)[0]), x, H2), RTOL)
        assert ok, f"terminal A vs FD: {err}"
        if disc.nr:
            ok, err = close(dm(R), fd_jac(lambda z: dm(disc.term_eval(z, p)[1]), x, H1), RTOL)
            assert ok, err
        if disc.ne:
            ok, err = close(dm(R_eq), fd_jac(lambda z: dm(disc.term_eval(z, p)[2]), x, H1), RTOL)
            assert ok, err
        A_gn = dm(disc.term_hess_gn(x, p, mu_r, nu)[0])
        if disc.term_residual is not None:
            J = fd_jac(lambda z: dm(disc.term_residual(z, p)), x, H1)
            expect = J.T @ disc.data.WN @ J
        else:
            # robot arm: E = -theta_N is linear, so the Gauss-Newton block is zero
            expect = fd_jac(lambda z: dm(disc.term_grad(z, p, 0 * mu_r, 0 * nu)[0]), x, H2)
        ok, err = close(A_gn, expect, RTOL)
        assert ok, f"terminal GN A: {err}"


# ---------------------------------------------------------------- robot arm, by hand
def arm_xdot(x, u):
    """docs/robot_arm.md section 1, transcribed with numpy."""
    m1 = m2 = 1.0
    l1 = 0.4
    lc1 = lc2 = 0.2
    I1 = I2 = 1.0 * 0.4**2 / 12
    a1 = I1 + I2 + m1 * lc1**2 + m2 * (l1**2 + lc2**2)
    a2 = m2 * l1 * lc2
    a3 = I2 + m2 * lc2**2
    q1, q2, dq1, dq2, _ = x
    c2, s2 = math.cos(q2), math.sin(q2)
    B = np.array([[a1 + 2 * a2 * c2, a3 + a2 * c2], [a3 + a2 * c2, a3]])
    Cdq = np.array([-a2 * s2 * (2 * dq1 * dq2 + dq2**2), a2 * s2 * dq1**2])
    g = 9.81
    grav = np.array([(m1 * lc1 + m2 * l1) * g * math.cos(q1) + m2 * lc2 * g * math.cos(q1 + q2),
                     m2 * lc2 * g * math.cos(q1 + q2)])
    ddq = np.linalg.solve(B, u[:2] - Cdq - 0.1 * np.array([dq1, dq2]) - grav)
    return np.array([dq1, dq2, ddq[0], ddq[1], u[2]])


def arm_tip(q):
    return np.array([0.4 * math.cos(q[0]) + 0.4 * math.cos(q[0] + q[1]),
                     0.4 * math.sin(q[0]) + 0.4 * math.sin(q[0] + q[1])])


def arm_path(th):
    return np.array([0.4 + 0.15 * math.cos(th), 0.2 + 0.15 * math.sin(th)])


def test_robot_arm_model_cost_and_integrator(robot_disc):
    d = robot_disc
    assert (d.N, d.dt, d.nx, d.nu, d.ng, d.nr, d.ne) == (40, 0.01, 5, 3, 0, 0, 2)
    assert np.array_equal(d.lbu, [-10, -10, 0]) and np.array_equal(d.ubu, [10, 10, 50])
    assert np.all(np.isinf(d.lbx)) and np.all(np.isinf(d.ubx))
    # xhat_0 of docs/robot_arm.md section 3, 8 significant digits
    assert np.allclose(d.x0, [-0.40144188, 1.50042576, 0, 0, 0], rtol=0, atol=5e-9)
    assert np.allclose(arm_tip(d.x0[:2]), arm_path(0.0), atol=1e-15)
    assert np.array_equal(d.initial_guess.u, np.tile([0, 0, 5.0], (40, 1)))
    assert np.array_equal(d.initial_guess.x, np.tile(d.x0, (41, 1)))
    # the offline solution is carried by the generated code; the guess stays the cold one
    assert d.options["offline_guess"] is True
    rng = np.random.default_rng(3)
    for _ in range(5):
        x = d.x0 + 0.3 * rng.standard_normal(5)
        u = np.array([20 * rng.random() - 10, 20 * rng.random() - 10, 50 * rng.random()])
        assert np.allclose(dm(d.ode(x, u, [])).ravel(), arm_xdot(x, u), rtol=1e-13, atol=1e-12)
        # RK4, 2 substeps of dt/2
        z, h = x.copy(), d.dt / 2
        for _ in range(2):
            k1 = arm_xdot(z, u)
            k2 = arm_xdot(z + h / 2 * k1, u)
            k3 = arm_xdot(z + h / 2 * k2, u)
            k4 = arm_xdot(z + h * k3, u)
            z = z + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        phi, l, _ = d.stage_eval(x, u, [])
        assert np.allclose(dm(phi).ravel(), z, rtol=1e-13, atol=1e-13)
        e = arm_tip(x[:2]) - arm_path(x[4])
        l_ref = d.dt * (1e4 * e @ e + 1e-3 * u[:2] @ u[:2] + 1e-2 * u[2] ** 2)
        assert math.isclose(float(l), l_ref, rel_tol=1e-13)
        E, _, r_eq = d.term_eval(x, [])
        assert float(E) == -x[4]
        assert np.allclose(dm(r_eq).ravel(), e, atol=1e-15)
    # the scenario signal is the path deviation
    spec = d.scenario.closed_loop
    assert spec.duration == 3.0 and [ev.time for ev in spec.events] == [1.0]
    x = d.x0 + 0.1
    dev = float(spec.signals["deviation"](x, [0, 0, 0], []))
    assert math.isclose(dev, np.linalg.norm(arm_tip(x[:2]) - arm_path(x[4])), rel_tol=1e-13)
    xd = spec.events[0].fn(np.array([0.1, 0.2, 1.0, -1.0, 0.3]))
    assert np.allclose(xd, [0.15, 0.15, 0, 0, 0.3], atol=1e-15)
    assert np.array_equal(d.disturbance(np.array([0.1, 0.2, 1.0, -1.0, 0.3])), xd)
    assert np.allclose(dm(spec.plant_ode(x, [1, 2, 3], [])).ravel(), arm_xdot(x, np.array([1, 2, 3.0])))


def test_build_is_deterministic(robot_disc):
    again = build_functions(load_ocp(ROBOT_ARM_FILE))
    for f1, f2 in zip(robot_disc.functions, again.functions):
        assert f1.name() == f2.name()
        assert f1.serialize() == f2.serialize(), f1.name()


FUSED_EXAMPLES = sorted(p.stem for p in EXAMPLES.glob("*.py"))
FUSED_SOFT = ["cart_l1", "orbit_l2", "reach_both", "cone", "all_soft"]


@pytest.mark.parametrize("source", [f"examples/{e}" for e in FUSED_EXAMPLES] + [f"soft/{s}" for s in FUSED_SOFT])
def test_fused_stage_functions_equal_the_separate_calls_bit_for_bit(source):
    """``stage_grad_hess_exact`` and ``stage_grad_hess_gn`` (docs/algorithm.md section 2)
    give the outputs of ``stage_grad`` then those of ``stage_hess_exact`` /
    ``stage_hess_gn`` at random points, the same numbers bit for bit (one graph, the same
    operations), for every example and every soft test problem that has them."""
    import soft_problems

    kind, name = source.split("/")
    disc = build_functions(load_ocp(EXAMPLES / f"{name}.py") if kind == "examples"
                           else getattr(soft_problems, name)())
    f = disc.functions
    pairs = [(f.stage_grad_hess_exact, f.stage_hess_exact), (f.stage_grad_hess_gn, f.stage_hess_gn)]
    pairs = [(fused, hess) for fused, hess in pairs if fused is not None]
    if f.stage_hess_gn is not None and f.stage_grad_hess_exact is not None:
        # a Gauss-Newton Hessian next to a fused exact one: the fused Gauss-Newton one exists too
        assert f.stage_grad_hess_gn is not None
    rng = np.random.default_rng(23)
    for point in random_points(disc, rng, 5):
        separate_grad = [dm(v) for v in f.stage_grad(*point)]
        for fused, hess in pairs:
            got = [dm(v) for v in fused(*point)]
            want = separate_grad + [dm(v) for v in hess(*point)]
            assert len(got) == len(want) == 7
            for i, (a, b) in enumerate(zip(got, want)):
                assert a.shape == b.shape and np.array_equal(a, b), (fused.name(), fused.name_out(i))
