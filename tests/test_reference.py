"""The Python reference DOPUS and the reference QP solver, checked against independent
references: clarabel (convex QPs), second-order optimality certificates, IPOPT on the
NLP (offline.solve_ocp), finite differences of the stage gradients F_k, and an OCP whose
model is affine (so the secant criterion must vanish). The paper's literal QP throughout
(lm = 0; the automatic term of docs/algorithm.md section 10 is tested in
tests/test_lm_auto.py and tests/test_c_vs_reference.py)."""
from __future__ import annotations

import numpy as np
import pytest

from dopus_codegen.reference.kkt import eval_stages, kkt_of_guess
from dopus_codegen.reference.qp import (QPInfeasibleError, check_qp, qp_kkt_residual, qp_reduced_hessian_min_eig,
                                 solve_qp_reference)
from dopus_codegen.errors import status_code
from dopus_codegen.reference.dopus import DopusError, ReferenceDopus, regularize


# --------------------------------------------------------------------------- QP helpers
def random_qp(seed, N=8, nx=3, nu=2, ng=1, nr=1, ne=1, shift=0.0):
    """A feasible random stage-wise QP; ``shift`` > 0 subtracts shift*I from the blocks."""
    rng = np.random.default_rng(seed)
    nw = nx + nu
    H = []
    for _ in range(N):
        Mx = rng.standard_normal((nw, nw))
        H.append(Mx @ Mx.T + 0.1 * np.eye(nw) - shift * np.eye(nw))
    Phi = np.concatenate([np.eye(nx) + 0.1 * rng.standard_normal((N, nx, nx)),
                          0.3 * rng.standard_normal((N, nx, nu))], axis=2)
    qp = dict(N=N, nx=nx, nu=nu, ng=ng, nr=nr, ne=ne, H=np.array(H), g=3.0 * rng.standard_normal((N, nw)),
              Phi=Phi, b=0.1 * rng.standard_normal((N, nx)), x0=0.5 * rng.standard_normal(nx),
              HN=np.eye(nx), gN=rng.standard_normal(nx),
              lbw=np.full((N, nw), -1.5), ubw=np.full((N, nw), 1.5),
              lbxN=np.full(nx, -np.inf), ubxN=np.ones(nx),
              C=rng.standard_normal((N, ng, nw)), lg=np.full((N, ng), -0.3), ug=np.full((N, ng), np.inf),
              R=rng.standard_normal((nr, nx)), lr=np.full(nr, -0.2), ur=np.full(nr, 0.2),
              Req=rng.standard_normal((ne, nx)), req=np.full(ne, 0.05))
    qp["lbw"][:, 0] = -np.inf        # one-sided bounds are normal
    return qp


def clarabel_solve(qp):
    """Independent convex solve; returns (z, multipliers in our signed convention)."""
    import clarabel
    import scipy.sparse as sp

    from dopus_codegen.reference.qp import flatten_qp

    q = check_qp(qp)
    Hz, gz, rows = flatten_qp(q)
    nz = Hz.shape[0]
    I = sp.identity(nz, format="csr")
    blocks, rhs = [rows.A_eq], [rows.b_eq]
    m_eq = rows.A_eq.shape[0]
    up_in = np.isfinite(rows.u_in); lo_in = np.isfinite(rows.l_in)
    up_z = np.isfinite(rows.ubz); lo_z = np.isfinite(rows.lbz)
    parts = [(rows.A_in[up_in], rows.u_in[up_in]), (-rows.A_in[lo_in], -rows.l_in[lo_in]),
             (I[up_z], rows.ubz[up_z]), (-I[lo_z], -rows.lbz[lo_z])]
    for A, bb in parts:
        blocks.append(A); rhs.append(bb)
    A = sp.vstack(blocks, format="csc")
    b = np.concatenate(rhs)
    cones = [clarabel.ZeroConeT(m_eq), clarabel.NonnegativeConeT(A.shape[0] - m_eq)]
    s = clarabel.DefaultSettings()
    s.verbose = False
    s.tol_gap_abs = s.tol_gap_rel = s.tol_feas = s.tol_ktratio = 1e-12
    sol = clarabel.DefaultSolver(sp.triu(Hz, format="csc"), gz, A, b, cones, s).solve()
    assert str(sol.status) == "Solved"
    y = np.array(sol.z)
    i = m_eq
    y_in = np.zeros(rows.A_in.shape[0]); mu_z = np.zeros(nz)
    n = up_in.sum(); y_in[up_in] += y[i:i + n]; i += n
    n = lo_in.sum(); y_in[lo_in] -= y[i:i + n]; i += n
    n = up_z.sum(); mu_z[up_z] += y[i:i + n]; i += n
    n = lo_z.sum(); mu_z[lo_z] -= y[i:i + n]; i += n
    return np.array(sol.x), y[:m_eq], y_in, mu_z


# --------------------------------------------------------------------------- QP tests
@pytest.mark.parametrize("seed", [0, 1, 2])
def test_qp_reference_matches_clarabel_on_convex_qps(seed):
    from dopus_codegen.reference.qp import flatten_solution

    qp = random_qp(seed)
    sol = solve_qp_reference(qp)
    res = qp_kkt_residual(qp, sol)
    assert sol["polished"]
    assert res["kkt"] < 1e-10, res
    z, y_eq, y_in, mu_z = flatten_solution(check_qp(qp), sol)
    zc, y_eqc, y_inc, mu_zc = clarabel_solve(qp)
    assert np.max(np.abs(z - zc)) < 1e-6
    assert np.max(np.abs(y_eq - y_eqc)) < 1e-5
    assert np.max(np.abs(y_in - y_inc)) < 1e-5
    assert np.max(np.abs(mu_z - mu_zc)) < 1e-5
    # some bounds are active, so the active-set identification is exercised
    assert np.count_nonzero(mu_z) > 0 and np.count_nonzero(y_in) > 0


def test_qp_reference_indefinite_blocks_with_positive_reduced_hessian():
    # every stage block gets -1.2 I: most are indefinite, the QP stays bounded because the
    # dynamics and the active set leave a positive definite reduced Hessian
    found = 0
    for seed in range(12):
        qp = random_qp(seed, shift=1.2)
        if min(np.linalg.eigvalsh(h).min() for h in qp["H"]) > -0.5:
            continue
        try:
            sol = solve_qp_reference(qp)
        except Exception:  # noqa: BLE001 - an unbounded draw is skipped
            continue
        red = qp_reduced_hessian_min_eig(qp, sol)
        if red <= 1e-6:
            continue
        res = qp_kkt_residual(qp, sol)
        assert res["kkt"] < 1e-10, res          # first order ...
        assert red > 0                          # ... and second order: a strict local minimiser
        found += 1
    assert found >= 2


def test_qp_reference_robot_arm_exact_hessian_qp(robot_disc, robot_solution):
    """The warm-start QP of the robot arm: indefinite exact blocks (docs/design.md section 8)."""
    d = robot_disc
    sol0, _ = robot_solution
    ref = ReferenceDopus(d, lm=0.0, M=d.N - 1, mode="fixed")
    ref.init(d.x0, sol0)
    qp = ref.qp_of_current(d.disturbance(d.x0))
    assert min(np.linalg.eigvalsh(h).min() for h in qp["H"]) < -1e-3
    sol = solve_qp_reference(qp)
    assert sol["polished"]
    assert qp_kkt_residual(qp, sol)["kkt"] < 1e-10
    assert qp_reduced_hessian_min_eig(qp, sol) > 0


def test_qp_reference_infeasible_and_bad_input():
    qp = random_qp(0)
    qp["lbw"][3, 4], qp["ubw"][3, 4] = 1.0, 0.5
    with pytest.raises(QPInfeasibleError, match="lbw"):
        solve_qp_reference(qp)
    qp = random_qp(0)
    # x_1 = Phi_0 w_0 + b_0 with x_0 fixed: demand an x_1 no bounded u_0 reaches
    qp["x0"][:] = 0.0
    qp["Phi"][0][:, 3:] = 0.0
    qp["b"][0][:] = 0.0
    qp["lbw"][1, 0] = 1.0
    with pytest.raises(QPInfeasibleError, match="infeasible"):
        solve_qp_reference(qp)
    bad = random_qp(0)
    bad["Phi"] = bad["Phi"][:, :, :4]
    with pytest.raises(ValueError, match="Phi"):
        solve_qp_reference(bad)
    bad = random_qp(0)
    del bad["req"]
    with pytest.raises(ValueError, match="req"):
        solve_qp_reference(bad)


def test_regularize_eigenvalues():
    rng = np.random.default_rng(3)
    V, _ = np.linalg.qr(rng.standard_normal((5, 5)))
    e = np.array([-2.0, -1e-6, 0.0, 3e-5, 4.0])
    A = (V * e) @ V.T
    assert np.array_equal(regularize(A, "none", 1e-4), A)
    np.testing.assert_allclose(np.linalg.eigvalsh(regularize(A, "project", 1e-4)),
                               np.sort(np.maximum(e, 1e-4)), atol=1e-12)
    np.testing.assert_allclose(np.linalg.eigvalsh(regularize(A, "mirror", 1e-4)),
                               np.sort(np.maximum(np.abs(e), 1e-4)), atol=1e-12)


# --------------------------------------------------------------------------- DOPUS tests
def _iterate(ref, xhat, iters, tol=0.0):
    ks = [ref.kkt(xhat)["kkt"]]
    for _ in range(iters):
        ref.feedback(xhat)
        ref.prepare()
        ks.append(ref.kkt(xhat)["kkt"])
        if ks[-1] <= tol:
            break
    return ks


def test_cold_start_gauss_newton_full_rti_reaches_ipopt(robot_disc, robot_solution):
    d = robot_disc
    sol, _ = robot_solution
    ref = ReferenceDopus(d, lm=0.0, M=d.N - 1, mode="fixed", hessian="gauss-newton")
    ref.init(d.x0)
    ks = _iterate(ref, d.x0, 60, tol=1e-11)
    it = next(i for i, k in enumerate(ks) if k <= 1e-8)
    print(f"\ncold start, Gauss-Newton, full RTI: KKT <= 1e-8 at iteration {it}; "
          f"KKT sequence {' '.join('%.1e' % k for k in ks)}")
    assert it <= 60
    dx = max(np.max(np.abs(ref.x - sol.x)), np.max(np.abs(ref.u - sol.u)))
    print(f"max primal deviation from IPOPT: {dx:.2e}")
    assert dx < 1e-6
    # the multipliers agree as well (same signed convention as offline.solve_ocp)
    assert np.max(np.abs(ref.lam - sol.lam)) < 1e-5
    assert np.max(np.abs(ref.nu - sol.nu)) < 1e-5


@pytest.fixture(scope="module")
def robot_exact_kkt_point(robot_disc, robot_solution):
    """The IPOPT solution polished by two full-RTI iterations to KKT ~1e-14: the smallest
    reduced-Hessian eigenvalue is ~2e-5, so IPOPT's KKT of ~3e-13 still means ~1e-8 in the
    iterate, too coarse to see a fixed point at 1e-9."""
    d = robot_disc
    sol, _ = robot_solution
    ref = ReferenceDopus(d, lm=0.0, M=d.N - 1, mode="fixed")
    ref.init(d.x0, sol)
    for _ in range(2):
        ref.feedback(d.x0)
        ref.prepare()
    point = ref.guess()
    assert kkt_of_guess(d, d.x0, point)["kkt"] < 1e-13
    assert np.max(np.abs(point.u - sol.u)) < 1e-6
    return point


@pytest.mark.parametrize("cost_hessian", ["stored", "fresh"])
@pytest.mark.parametrize("hessian,scale", [("exact", 0.4), ("gauss-newton", 1.0)])
def test_adjoint_correction_keeps_kkt_point_with_stale_blocks(robot_disc, robot_exact_kkt_point, hessian, scale,
                                                              cost_hessian):
    """Eq. 12: with blocks from another point, the exact KKT point is still a fixed point
    (with cost_hessian='fresh' the cost part of the Hessian blocks is at the solution, the
    curvature of the dynamics and Phit, Ct stay stale)."""
    d = robot_disc
    sol = robot_exact_kkt_point
    stale = sol.copy()
    rng = np.random.default_rng(7)
    stale.x = sol.x + scale * 0.05 * rng.standard_normal(sol.x.shape)
    stale.u = sol.u + scale * 0.5 * rng.standard_normal(sol.u.shape)
    stale.lam = sol.lam * (1 + scale * 0.3)
    ref = ReferenceDopus(d, lm=0.0, M=0, mode="fixed", hessian=hessian, cost_hessian=cost_hessian)
    ref.init(d.x0, stale)                    # every block computed at the perturbed point
    ref.x, ref.u = sol.x.copy(), sol.u.copy()
    ref.lam, ref.mu_g, ref.mu_b = sol.lam.copy(), sol.mu_g.copy(), sol.mu_b.copy()
    ref.mu_bN, ref.mu_r, ref.nu = sol.mu_bN.copy(), sol.mu_r.copy(), sol.nu.copy()
    ref.allow_prepare()                      # the iterate was replaced by hand, as a step would
    ref.prepare()                            # F at the solution, blocks of stages 0..N-2 kept (M = 0)
    assert ref.recomputed == [d.N - 1]
    # the stored blocks really are stale
    _, Phi0, _ = d.stage_hess_exact(sol.x[0], sol.u[0], d.p0[0], sol.lam[1], sol.mu_g[0])
    assert np.max(np.abs(ref.slot_of(0).Phit - np.array(Phi0))) > 1e-2
    A0 = np.array(d.stage_hess(hessian)(sol.x[0], sol.u[0], d.p0[0], sol.lam[1], sol.mu_g[0])[0])
    dH = np.max(np.abs(ref.slot_of(0).Ht - A0))
    if hessian == "gauss-newton" and cost_hessian == "fresh":
        assert dH <= 1e-12 * np.abs(A0).max()    # the GN block is all cost: refreshed exactly
    else:
        assert dH > 1e-2                         # stale (exact: the dynamics' curvature)
    qp = ref.qp_of_current(d.x0)
    ref.feedback(d.x0)
    dev = max(np.max(np.abs(ref.x - sol.x)), np.max(np.abs(ref.u - sol.u)),
              np.max(np.abs(ref.lam - sol.lam)), np.max(np.abs(ref.mu_b - sol.mu_b)),
              np.max(np.abs(ref.nu - sol.nu)))
    print(f"\nfixed point with stale blocks ({hessian}): one iteration moves the iterate by {dev:.2e}")
    assert dev < 1e-9
    # without the correction (a_k = grad l_k) the same QP moves away: the test has teeth
    N = d.N
    gradl = eval_stages(d.stage_grad, N, sol.x[:N], sol.u, d.p0[:N], np.zeros((N, d.nx)),
                        np.zeros((N, d.ng)))[0]
    qp["g"] = gradl
    step = solve_qp_reference(qp)
    assert max(np.max(np.abs(step["x"])), np.max(np.abs(step["u"]))) > 1e-4


def _F(d, x, u, p, lam_next, mu_g, mu_b):
    """F_k of eq. 14 as one vector (F_w, -phi, g) for one stage."""
    gL, phi, _l, g = d.stage_grad(x, u, p, lam_next, mu_g)
    return np.concatenate([np.array(gL).ravel() + mu_b, -np.array(phi).ravel(), np.array(g).ravel()])


@pytest.mark.parametrize("mode", ["fixed", "receding"])
def test_rho_matches_finite_difference_secant(robot_disc, robot_solution, mode):
    """rho_k against eq. 16 evaluated independently, H d by central differences of F."""
    d = robot_disc
    sol, _ = robot_solution
    N = d.N
    ref = ReferenceDopus(d, lm=0.0, M=N - 1, mode=mode)
    xf = d.disturbance(d.x0)
    ref.init(d.x0, sol)                 # full RTI: every block fresh at the point omega_old
    old = ref.guess()
    ref.feedback(xf)
    new = ref.guess()
    ref.prepare()
    h = 1e-5
    rho_fd = np.zeros(N - 1)
    for k in range(N - 1):
        j = k + 1 if mode == "receding" else k      # the stage the slot held before
        o = (old.x[j], old.u[j], d.p0[j], old.lam[j + 1], old.mu_g[j], old.mu_b[j])
        dd = (new.x[j] - old.x[j], new.u[j] - old.u[j], 0 * d.p0[j], new.lam[j + 1] - old.lam[j + 1],
              new.mu_g[j] - old.mu_g[j], new.mu_b[j] - old.mu_b[j])
        Fp = _F(d, *[a + h * b for a, b in zip(o, dd)])
        Fm = _F(d, *[a - h * b for a, b in zip(o, dd)])
        Hd = (Fp - Fm) / (2 * h)
        mu_b_new = ref.mu_b[k]
        Fnew = _F(d, ref.x[k], ref.u[k], d.p0[k], ref.lam[k + 1], ref.mu_g[k], mu_b_new)
        den = np.linalg.norm(np.concatenate([dd[0], dd[1], dd[3], dd[4], dd[5]]))
        rho_fd[k] = np.linalg.norm(_F(d, *o) + Hd - Fnew) / den
    rel = np.abs(ref.rho[:N - 1] - rho_fd) / np.maximum(rho_fd, 1e-12)
    print(f"\n{mode}: rho in [{rho_fd.min():.2e}, {rho_fd.max():.2e}], max relative deviation "
          f"of the secant formula by finite differences {rel.max():.2e}")
    assert rel.max() < 1e-4
    assert ref.rho[N - 1] == 0.0
    # selection of the M worst, ties to the lower index
    order = sorted(range(N - 1), key=lambda i: (-ref.rho[i], i))
    ref.set_M(3)
    assert ref.M == 3
    assert order[:3] == sorted(order[:3], key=lambda i: (-ref.rho[i], i))


def test_rho_is_first_order_in_the_step_with_fresh_blocks(robot_disc, robot_solution):
    d = robot_disc
    sol, _ = robot_solution
    out = []
    for eps in (1e-3, 1e-4):
        ref = ReferenceDopus(d, lm=0.0, M=d.N - 1, mode="fixed")
        ref.init(d.x0, sol)
        xf = d.x0.copy()
        xf[2] += eps                    # a small push of the joint velocity
        ref.feedback(xf)
        ref.prepare()
        out.append(ref.rho[:d.N - 1].copy())
    ratio = out[0].max() / out[1].max()
    print(f"\nmax rho for steps 1e-3 / 1e-4: {out[0].max():.2e} / {out[1].max():.2e} (ratio {ratio:.1f})")
    assert 5 < ratio < 20               # O(step): a tenth of the step gives a tenth of rho
    assert out[0].max() < 1.0


def _affine_ocp():
    import casadi as ca

    from dopus_codegen import RK4, Ocp, build_functions

    ocp = Ocp("affine")
    x = ocp.state("x", 2, lb=[-2, -1], ub=[2, 1])
    u = ocp.control("u", lb=-1, ub=1)
    ocp.dynamics(ca.vertcat(x[1], -0.5 * x[0] + u), integrator=RK4(substeps=2))
    ocp.stage_least_squares(ca.vertcat(x, u), weights=[1.0, 0.1, 0.01])
    ocp.stage_cost(0.3 * x[0] * u)
    ocp.path_constraint(x[0] + 0.5 * u, lb=-1.0, ub=0.6)
    ocp.terminal_least_squares(x, weights=[5.0, 5.0])
    ocp.horizon(N=12, dt=0.1)
    ocp.initial_state([0.7, 0.3])
    return build_functions(ocp)


@pytest.mark.parametrize("mode", ["fixed", "receding"])
def test_rho_vanishes_for_an_affine_model(mode):
    d = _affine_ocp()
    ref = ReferenceDopus(d, lm=0.0, M=0, mode=mode)
    ref.init(d.x0)
    # a different initial state every iteration keeps the steps O(0.1)
    xhats = [d.x0, d.x0 + [0.2, -0.1], d.x0 - [0.3, 0.2], d.x0 + [0.1, 0.3]]
    rhos, steps = [], []
    for xhat in xhats:
        ref.feedback(xhat)
        steps.append(max(np.max(np.abs(ref.last_qp_solution["x"])), np.max(np.abs(ref.last_qp_solution["u"]))))
        ref.prepare()
        rhos.append(ref.rho.max())
    # the quadratic model is exact, so the secant condition holds to round-off
    print(f"\naffine model ({mode}): steps {' '.join('%.1e' % s for s in steps)}, "
          f"max rho {' '.join('%.1e' % r for r in rhos)}")
    assert min(steps) > 1e-2
    assert max(rhos) < 1e-12, rhos
    if mode == "fixed":
        assert ref.kkt(xhats[-1])["kkt"] < 1e-10


def _secant_parts(d, ref, old, new, mode, hess_fn):
    """Per stage k < N-1, evaluated independently of the reference's slots: the relative
    step |domega| / (1 + |omega|), the secant residual of eq. 16 with the blocks of
    ``hess_fn`` at the old point, the residual of the exact linearisation (the Jacobian of F
    along the step by central differences), the scale S_k = |F_old| + |F_new|, |domega|
    and the model error |(Jt - J) domega|."""
    N = d.N
    out = []
    for k in range(N - 1):
        j = k + 1 if mode == "receding" else k      # the stage the slot held before
        o = (old.x[j], old.u[j], d.p0[j], old.lam[j + 1], old.mu_g[j], old.mu_b[j])
        dd = (new.x[j] - old.x[j], new.u[j] - old.u[j], 0 * d.p0[j], new.lam[j + 1] - old.lam[j + 1],
              new.mu_g[j] - old.mu_g[j], new.mu_b[j] - old.mu_b[j])
        den = np.linalg.norm(np.concatenate([dd[0], dd[1], dd[3], dd[4], dd[5]]))
        om = np.linalg.norm(np.concatenate([o[0], o[1], o[3], o[4], o[5]]))
        h = 1e-5                                    # along the unit direction of the step
        Fp = _F(d, *[a + h / den * b for a, b in zip(o, dd)])
        Fm = _F(d, *[a - h / den * b for a, b in zip(o, dd)])
        Jd = (Fp - Fm) / (2 * h) * den
        A, Phi, C = [np.array(v) for v in hess_fn(*o[:5])]
        dw = np.concatenate([dd[0], dd[1]])
        Jtd = np.concatenate([A @ dw - Phi.T @ dd[3] + C.T @ dd[4] + dd[5], -Phi @ dw, C @ dw])
        Fo = _F(d, *o)
        Fn = _F(d, ref.x[k], ref.u[k], d.p0[k], ref.lam[k + 1], ref.mu_g[k], ref.mu_b[k])
        out.append((den / (1 + om), np.linalg.norm(Fo + Jtd - Fn), np.linalg.norm(Fo + Jd - Fn),
                    np.linalg.norm(Fo) + np.linalg.norm(Fn), den, np.linalg.norm(Jtd - Jd)))
    return [np.array(c) for c in zip(*out)]


@pytest.mark.parametrize("mode", ["fixed", "receding"])
def test_rho_is_zero_when_the_secant_residual_is_round_off(robot_disc, robot_solution, mode):
    """Starting at the IPOPT solution the first QP step is that solution's error (1e-10 to
    3e-9, far above round-off of the iterate) and every block is exact at the old point, so
    the true residual of eq. 16 is O(|domega|^2), below the round-off of F: rho_k is 0
    (docs/algorithm.md section 4 step 2), not noise / |domega| that ranks the stages
    differently in every backend."""
    from dopus_codegen.reference.dopus import EPS_RHO

    d = robot_disc
    sol, _ = robot_solution
    ref = ReferenceDopus(d, lm=0.0, M=d.N - 1, mode=mode)
    ref.init(d.x0, sol)
    old = ref.guess()
    ref.feedback(d.x0)
    new = ref.guess()
    ref.prepare()
    rel_step, num, num_fd, S, _, _ = _secant_parts(d, ref, old, new, mode, d.stage_hess_exact)
    print(f"\n{mode}: |domega|/(1+|omega|) in [{rel_step.min():.1e}, {rel_step.max():.1e}], "
          f"num/S <= {np.max(num / S):.1e} (exact linearisation by differences {np.max(num_fd / S):.1e})")
    assert rel_step.min() > 1e-12                   # not a round-off step of the iterate
    assert np.max(num / S) < 0.1 * EPS_RHO          # the independent residual is round-off
    assert np.max(num_fd / S) < 0.1 * EPS_RHO
    assert np.all(ref.rho == 0.0)


@pytest.mark.parametrize("mode", ["fixed", "receding"])
def test_rho_keeps_a_real_secant_violation_of_a_tiny_step(robot_disc, robot_solution, mode):
    """Gauss-Newton blocks miss the curvature of the dynamics, a secant violation of first
    order in the step. A push of 1e-8 on the initial state gives steps of 2e-9 to 1e-7
    relative to the iterate; rho_k stays positive and equals eq. 16 evaluated independently
    and the first-order prediction |(Jt - J) d| / |d| (J by central differences), so the
    round-off floor does not hide it, where a floor on |domega| of 1e-8 would."""
    d = robot_disc
    sol, _ = robot_solution
    ref = ReferenceDopus(d, lm=0.0, M=d.N - 1, mode=mode, hessian="gauss-newton")
    ref.init(d.x0, sol)
    old = ref.guess()
    xf = np.array(d.x0, dtype=float)
    xf[2] += 1e-8                                   # the joint velocity
    ref.feedback(xf)
    new = ref.guess()
    ref.prepare()
    rel_step, num, num_fd, S, den, model_err = _secant_parts(d, ref, old, new, mode, d.stage_hess_gn)
    rho = ref.rho[:d.N - 1]
    rho_ind = num / den
    rho_first = model_err / den                     # first order: rho - rho_first = O(|d|)
    n_tiny = int(np.sum(rel_step < 1e-8))
    print(f"\n{mode}: {n_tiny} of {d.N - 1} steps below 1e-8 relative, rho in [{rho.min():.2e}, "
          f"{rho.max():.2e}], num/S >= {np.min(num / S):.1e}, deviation from eq. 16 evaluated independently "
          f"{np.max(np.abs(rho - rho_ind) / rho_ind):.1e}, from |(Jt - J) d| / |d| "
          f"{np.max(np.abs(rho - rho_first) / rho):.1e}")
    assert n_tiny >= d.N // 2
    assert np.all(rho > 0.0) and ref.rho[-1] == 0.0
    assert np.max(np.abs(rho - rho_ind) / rho_ind) < 1e-3
    assert np.max(np.abs(num_fd / S)) < 1e-13       # the exact linearisation has round-off residual
    assert np.max(np.abs(rho - rho_first) / rho) < 1e-3


def test_receding_full_recompute_equals_fresh_init(robot_disc, robot_solution):
    """Shift + ring buffer: with every block recomputed the QP equals a fresh init's."""
    d = robot_disc
    sol, _ = robot_solution
    ref = ReferenceDopus(d, lm=0.0, M=d.N - 1, mode="receding")
    ref.init(d.x0, sol)
    for _ in range(3):
        xhat = d.disturbance(d.x0) if _ == 0 else ref.x[0]
        ref.feedback(xhat)
        ref.prepare()
    assert ref.ring_head == 3
    fresh = ReferenceDopus(d, lm=0.0, M=d.N - 1, mode="receding")
    fresh.init(ref.x[0], ref.guess())
    qa, qb = ref.qp_of_current(ref.x[0]), fresh.qp_of_current(ref.x[0])
    for key in ("H", "g", "Phi", "b", "HN", "gN", "lbw", "ubw", "Req", "req"):
        np.testing.assert_allclose(qa[key], qb[key], rtol=0, atol=1e-12, err_msg=key)
    # and with M = 0 the stale stage blocks are those of the right (shifted) stage
    ref0 = ReferenceDopus(d, lm=0.0, M=0, mode="receding", cost_hessian="stored")
    ref0.init(d.x0, sol)
    H1 = ref0.slot_of(1).Ht.copy()
    ref0.feedback(d.x0)
    ref0.prepare()
    np.testing.assert_array_equal(ref0.slot_of(0).Ht, H1)
    # cost_hessian='fresh': Phit and A_dyn shift with the slot, the cost part is new
    ref1 = ReferenceDopus(d, lm=0.0, M=0, mode="receding", cost_hessian="fresh")
    ref1.init(d.x0, sol)
    s1 = ref1.slot_of(1).copy()
    ref1.feedback(d.disturbance(d.x0))
    ref1.prepare()
    s0 = ref1.slot_of(0)
    np.testing.assert_array_equal(s0.Phit, s1.Phit)
    np.testing.assert_array_equal(s0.A_dyn, s1.A_dyn)
    A_l = np.array(d.stage_hess_cost("exact")(ref1.x[0], ref1.u[0], d.p0[0]))
    np.testing.assert_array_equal(s0.Ht, s1.A_dyn + A_l)
    # A_dyn + A_l at the point where H was computed is that H
    A_l1 = np.array(d.stage_hess_cost("exact")(sol.x[1], sol.u[1], d.p0[1]))
    np.testing.assert_allclose(s1.A_dyn + A_l1, s1.Ht, rtol=0, atol=1e-12 * np.abs(s1.Ht).max())


def test_second_example_full_rti_reaches_ipopt_with_active_path_constraint(second_disc, second_solution):
    d = second_disc
    sol, _ = second_solution
    # from the OCP file's (cold) guess the exact Hessian QPs lose convexity; the mirrored
    # Hessian keeps them convex and leaves the fixed point unchanged (docs/design.md section 2)
    ref = ReferenceDopus(d, lm=0.0, M=d.N - 1, mode="fixed", regularization="mirror")
    ref.init(d.x0)
    ks = _iterate(ref, d.x0, 40, tol=1e-11)
    print(f"\nunicycle, cold start, mirrored exact Hessian, full RTI: {len(ks) - 1} iterations, "
          f"KKT {' '.join('%.1e' % k for k in ks)}")
    assert ks[-1] < 1e-8
    assert max(np.max(np.abs(ref.x - sol.x)), np.max(np.abs(ref.u - sol.u))) < 1e-6
    g = eval_stages(d.stage_eval, d.N, ref.x[:d.N], ref.u, d.p0[:d.N])[2][:, 0]
    active = np.abs(g - d.lg[0]) < 1e-8
    assert active.any()
    assert np.all(ref.mu_g[active, 0] < -1e-3)
    np.testing.assert_allclose(ref.mu_g, sol.mu_g, atol=1e-6)
    # the exact Hessian without regularisation from the IPOPT point of the pushed state
    xf = d.disturbance(d.x0)
    ref = ReferenceDopus(d, lm=0.0, M=d.N - 1, mode="fixed")
    ref.init(xf, sol)
    ks = _iterate(ref, d.x0, 10)
    assert ks[-1] < 1e-10


@pytest.mark.parametrize("M,hessian", [("full", "exact"), (1, "gauss-newton")])
def test_receding_horizon_tracks_from_ipopt_solution(robot_disc, robot_solution, M, hessian):
    """16 closed-loop steps on the nominal model from the IPOPT solution: u0 against IPOPT's
    optimal u0 for the current state; the KKT measure after each feedback stays bounded
    (the shift perturbs the problem by ~0.4 in KKT every step, DOPUS contracts it)."""
    from dopus_codegen.reference.offline import solve_ocp

    d = robot_disc
    sol, _ = robot_solution
    ref = ReferenceDopus(d, lm=0.0, M=d.N - 1 if M == "full" else M, mode="receding", hessian=hessian)
    ref.init(d.x0, sol)
    xhat = d.x0.copy()
    kkts, du = [], []
    for step in range(16):
        u0 = ref.feedback(xhat)
        assert np.all(np.isfinite(u0))
        kkts.append(ref.kkt(xhat)["kkt"])
        if step in (0, 15):
            opt, info = solve_ocp(d, xhat, guess=ref.guess())
            assert info["success"]
            du.append(np.max(np.abs(u0 - opt.u[0])))
        xhat = np.array(d.stage_eval(xhat, u0, d.p0[0])[0]).ravel()   # nominal plant
        ref.prepare()
        assert d.N - 1 in ref.recomputed and len(ref.recomputed) == ref.M + 1
    print(f"\nreceding horizon, M = {M}, {hessian}: KKT after each feedback "
          f"{' '.join('%.0e' % k for k in kkts)}; |u0 - u0_IPOPT| at steps 0 and 15: {du[0]:.1e} {du[1]:.1e}")
    assert du[0] < 1e-8                  # at the start the iterate is the IPOPT solution
    assert max(kkts) < 2.0
    if M == "full":
        assert kkts[-1] < 1e-2
        assert du[1] < 1e-3              # the full RTI has caught up with the moving optimum
    else:
        assert du[1] < 1.0               # torques span +-10: M = 1 stays near the optimum


@pytest.mark.parametrize("hessian", ["exact", "gauss-newton"])
def test_cost_hessian_settings_agree_for_the_full_rti(robot_disc, robot_solution, hessian):
    """With every stage re-linearised (M = N-1) 'fresh' and 'stored' are the same algorithm:
    identical iterates, bit for bit (receding mode, disturbed start)."""
    d = robot_disc
    sol, _ = robot_solution
    a = ReferenceDopus(d, lm=0.0, M=d.N - 1, hessian=hessian, cost_hessian="fresh")
    b = ReferenceDopus(d, lm=0.0, M=d.N - 1, hessian=hessian, cost_hessian="stored")
    x = d.disturbance(d.x0)
    for r in (a, b):
        r.init(d.x0, sol)
    for _ in range(4):
        ua, ub = a.feedback(x), b.feedback(x)
        np.testing.assert_array_equal(ua, ub)
        for f in ("x", "u", "lam", "mu_b", "mu_bN", "nu"):
            np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)
        x = np.array(d.stage_eval(x, ua, d.p0[0])[0]).ravel()
        a.prepare()
        b.prepare()
        for sa, sb in zip(a.slots, b.slots):
            np.testing.assert_array_equal(sa.Ht, sb.Ht)


def _closed_loop(d, guess, M, cost_hessian, steps, hessian="gauss-newton"):
    """``steps`` sampling instants on the discrete model phi, the OCP's disturbance at the
    first; returns u0 per instant and the KKT measure after each feedback."""
    r = ReferenceDopus(d, lm=0.0, M=M, mode="receding", hessian=hessian, cost_hessian=cost_hessian)
    r.init(d.x0, guess)
    x = d.disturbance(d.x0)
    us, kkts = [], []
    for _ in range(steps):
        u0 = r.feedback(x)
        us.append(u0)
        kkts.append(r.kkt(x)["kkt"])
        x = np.array(d.stage_eval(x, u0, d.p0[0])[0]).ravel()
        r.prepare()
    return np.array(us), np.array(kkts)


def test_receding_gauss_newton_m1_fresh_stays_with_the_full_rti(robot_disc, robot_solution):
    """The robot arm's end-of-horizon manoeuvre moves with the horizon, so the stored cost
    Hessians of M = 1 go stale; refreshed ('fresh') the M = 1 closed loop follows the full
    RTI. Bounds: the torques span +-10 and the full RTI itself is ~0.02 in KKT (median)
    from the moving optimum, so M = 1 must stay within 0.5 (max) / 0.1 (RMS) of the full
    RTI's u0 and within twice its median KKT; 'stored' misses each bound by a factor >= 5
    (so the test has teeth)."""
    d = robot_disc
    sol, _ = robot_solution
    steps = 30
    u_full, k_full = _closed_loop(d, sol, d.N - 1, "fresh", steps)
    res = {}
    for ch in ("fresh", "stored"):
        u, k = _closed_loop(d, sol, 1, ch, steps)
        du = u - u_full
        res[ch] = (np.abs(du).max(), np.sqrt(np.mean(du ** 2)), np.median(k))
    print(f"\nreceding GN, {steps} steps, u0 against the full RTI (max, RMS) and median KKT "
          f"(full RTI {np.median(k_full):.2e}): " +
          "; ".join(f"M=1 {ch}: {a:.3f}, {b:.3f}, {c:.2e}" for ch, (a, b, c) in res.items()))
    mx, rms, kmed = res["fresh"]
    assert mx < 0.5 and rms < 0.1
    assert kmed < 2.0 * np.median(k_full)
    mx, rms, kmed = res["stored"]
    assert mx > 2.5 and rms > 0.5 and kmed > 10.0 * np.median(k_full)


def test_reference_rejects_bad_input(robot_disc):
    d = robot_disc
    with pytest.raises(ValueError, match="hessian"):
        ReferenceDopus(d, lm=0.0, hessian="bfgs")
    with pytest.raises(ValueError, match="regularization"):
        ReferenceDopus(d, lm=0.0, regularization="clip")
    with pytest.raises(ValueError, match="mode"):
        ReferenceDopus(d, lm=0.0, mode="free")
    with pytest.raises(ValueError, match="cost_hessian"):
        ReferenceDopus(d, lm=0.0, cost_hessian="always")
    ref = ReferenceDopus(d, lm=0.0, M=1000)
    assert ref.M == d.N - 1
    with pytest.raises(DopusError, match="init"):
        ref.feedback(d.x0)
    ref.init(d.x0)
    before = ref.x.copy()
    with pytest.raises(DopusError) as exc:
        ref.feedback([np.nan, 0, 0, 0, 0])
    assert exc.value.status == status_code("nonfinite_input")
    np.testing.assert_array_equal(ref.x, before)
    with pytest.raises(ValueError, match="parameters"):
        ref.set_parameters(np.zeros(3))


def test_parameters_reach_every_function(second_disc, second_solution):
    """set_parameters: the full RTI converges to IPOPT's solution for the new target."""
    from dopus_codegen.reference.offline import solve_ocp

    d = second_disc
    sol, _ = second_solution
    p = d.p0[0].copy()
    p[1] += 0.3                                 # target 0.3 m further up
    opt, info = solve_ocp(d, d.x0, guess=sol, p=p)
    assert info["success"]
    ref = ReferenceDopus(d, lm=0.0, M=d.N - 1, mode="fixed")
    ref.init(d.x0, sol)                         # blocks at the old target's solution
    ref.stop()                                  # a new run: its parameters are written before init
    ref.set_parameters(p)
    ref.init(d.x0, sol)                         # the old target's solution, F, H at the new parameters
    ks = _iterate(ref, d.x0, 15, tol=1e-11)
    assert ks[-1] < 1e-10
    assert max(np.max(np.abs(ref.x - opt.x)), np.max(np.abs(ref.u - opt.u))) < 1e-6
    assert kkt_of_guess(d, d.x0, ref.guess(), p=p)["kkt"] < 1e-10


def test_nonfinite_function_value_leaves_state(tmp_path):
    import casadi as ca

    from dopus_codegen import Ocp, build_functions

    ocp = Ocp("logdyn")
    x = ocp.state("x")
    u = ocp.control("u", lb=-1, ub=1)
    ocp.dynamics(-ca.log(x) + u)               # NaN for x < 0
    ocp.stage_least_squares(ca.vertcat(x - 1.0, u), weights=[1.0, 0.1])
    ocp.horizon(N=5, dt=0.1)
    ocp.initial_state([1.2])
    d = build_functions(ocp)
    ref = ReferenceDopus(d, lm=0.0, M=4, mode="fixed")
    ref.init(d.x0)
    ref.feedback(d.x0)
    ref.prepare()
    ref.feedback(d.x0)                         # a prepare is due (docs/algorithm.md, calling order)
    x_before = ref.x.copy()
    H_before = [s.Ht.copy() for s in ref.slots]
    ref.x[3, 0] = -1.0
    with pytest.raises(DopusError, match="non-finite") as exc:
        ref.prepare()
    assert exc.value.status == status_code("nonfinite_value")
    assert ref.x[3, 0] == -1.0 and np.array_equal(np.delete(ref.x, 3), np.delete(x_before, 3))
    assert all(np.array_equal(s.Ht, h) for s, h in zip(ref.slots, H_before))
    with pytest.raises(DopusError, match="non-finite"):
        ref.init(d.x0, ref.guess())
