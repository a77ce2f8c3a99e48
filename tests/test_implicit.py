"""Implicit collocation integrators (Gauss-Legendre, Radau IIA) in the OCP file.

- Their interval maps against CVODES (BDF, tolerances 1e-13) on the stiff example, where
  RK4 needs about 20 substeps per interval to be stable and as accurate.
- Their sensitivities (implicit function theorem, forward over adjoint) against central
  finite differences of the interval map and of the stage gradient; Phi and the Hessian
  taken on the inlined interval graph (the default) against the substep's derivative
  kernels (``directions="one"``, ``"all"``).
- On a non-stiff problem (the unicycle) IPOPT's solution with Gauss-Legendre equals the one
  with RK4 within the discretisation difference.
- The stiff example: both backends reach IPOPT's solution of the same discretisation, and
  the C iterates equal the reference's to 1e-9.
"""
from __future__ import annotations

import dataclasses
import importlib.util

import casadi as ca
import numpy as np
import pytest

from conftest import EXAMPLES, SECOND_FILE
from dopus_codegen import RK4, GaussLegendre, RadauIIA
from dopus_codegen.problem.derivatives import build_functions
from dopus_codegen.problem.ocp import OcpError, collocation_tableau, load_ocp
from dopus_codegen.reference.dopus import ReferenceDopus
from dopus_codegen.reference.offline import solve_ocp
from dopus_codegen.runtime.solver import CSolver

STIFF_FILE = EXAMPLES / "stiff_motor.py"


def _module(path):
    spec = importlib.util.spec_from_file_location(f"m_{path.stem}", str(path))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.fixture(scope="module")
def stiff():
    return _module(STIFF_FILE)


def test_tableaus_have_their_order():
    """sum_j b_j c_j^(k-1) = 1/k up to the order (2s Gauss, 2s-1 Radau), and the stage
    order s: sum_j a_ij c_j^(k-1) = c_i^k / k."""
    for kind, order in (("gauss", lambda s: 2 * s), ("radau", lambda s: 2 * s - 1)):
        for s in (1, 2, 3, 4):
            A, b, c = collocation_tableau(kind, s)
            for k in range(1, order(s) + 1):
                assert abs(b @ c ** (k - 1) - 1.0 / k) < 1e-13, (kind, s, k)
            for k in range(1, s + 1):
                np.testing.assert_allclose(A @ c ** (k - 1), c ** k / k, atol=1e-13)
    assert collocation_tableau("radau", 3)[2][-1] == 1.0


def test_bad_integrator_arguments_are_named():
    with pytest.raises(OcpError, match="stages"):
        RadauIIA(stages=0)
    with pytest.raises(OcpError, match="newton_iters"):
        GaussLegendre(newton_iters=0)
    with pytest.raises(OcpError, match="derivatives"):
        RK4(2, derivatives="fast")


def _interval_errors(mod, integrators):
    base = build_functions(mod.build())
    sol, _ = solve_ocp(base, base.x0)
    x, u = ca.SX.sym("x", base.nx), ca.SX.sym("u", base.nu)
    ref = ca.integrator("ref", "cvodes", {"x": x, "p": u, "ode": base.ode(x, u, ca.DM.zeros(0))},
                        0.0, base.dt, {"abstol": 1e-13, "reltol": 1e-13, "max_num_steps": 100000})
    exact = [np.array(ref(x0=sol.x[k], p=sol.u[k])["xf"]).ravel() for k in range(base.N)]
    out = []
    for integ in integrators:
        d = build_functions(mod.build(integ))
        errs = [np.abs(np.array(d.stage_eval(sol.x[k], sol.u[k], [])[0]).ravel() - exact[k]).max()
                for k in range(base.N)]
        out.append(max(errs) if np.all(np.isfinite(errs)) else np.inf)
    return out


def test_stiff_example_needs_many_rk4_substeps(stiff):
    rk10, rk20, radau, radau3, gauss = _interval_errors(stiff, [
        RK4(10), RK4(20), RadauIIA(2, 4, 2), RadauIIA(3, 4, 2), GaussLegendre(3, 4, 2)])
    assert rk10 > 1.0                      # unstable: the 1 ms mode with h = 5 ms
    assert rk20 < 1e-3
    assert radau < 2e-4 and radau3 < 5e-5  # 4 substeps, as accurate as RK4 with 20
    assert gauss < 2e-3


@pytest.mark.parametrize("integ", [RadauIIA(2, 2, 4), GaussLegendre(2, 1, 4)], ids=["radau", "gauss"])
def test_implicit_sensitivities_by_finite_differences(stiff, integ):
    d = build_functions(stiff.build(integ))
    rng = np.random.default_rng(7)
    x = np.array([0.3, 1.0, 0.5])
    u = np.array([2.0])
    lam = rng.standard_normal(d.nx)
    w = np.concatenate([x, u])

    def phi(wv):
        return np.array(d.stage_eval(wv[:3], wv[3:], [])[0]).ravel()

    def gL(wv):
        return np.array(d.stage_grad(wv[:3], wv[3:], [], lam, [])[0]).ravel()

    A, Phi, _ = (np.array(v) for v in d.stage_hess_exact(x, u, [], lam, []))
    Phi_fd, A_fd = np.zeros_like(Phi), np.zeros_like(A)
    for j in range(d.nw):
        h = 1e-6 * max(1.0, abs(w[j]))
        e = np.zeros(d.nw)
        e[j] = h
        Phi_fd[:, j] = (phi(w + e) - phi(w - e)) / (2 * h)
        A_fd[:, j] = (gL(w + e) - gL(w - e)) / (2 * h)
    np.testing.assert_allclose(Phi, Phi_fd, rtol=0, atol=1e-6 * (1 + np.abs(Phi).max()))
    np.testing.assert_allclose(A, A_fd, rtol=0, atol=1e-5 * (1 + np.abs(A).max()))
    # the gradient's dynamics part is -Phi' lam (node part: gL at lam = 0)
    g0 = np.array(d.stage_grad(x, u, [], np.zeros(d.nx), [])[0]).ravel()
    np.testing.assert_allclose(gL(w) - g0, -Phi.T @ lam, rtol=0, atol=1e-12 * (1 + np.abs(Phi).max()))


@pytest.mark.parametrize("directions", ["one", "all"])
def test_implicit_kernels_equal_the_inlined_graph(stiff, directions):
    """Two constructions of Phi and the dynamics' Hessian: the default (forward over reverse
    on the interval's graph with the substeps inlined) and the forward and
    forward-over-adjoint kernels of one substep (``directions="one"``/``"all"``)."""
    d = build_functions(stiff.build(RadauIIA(2, 2, 4)))
    dk = build_functions(stiff.build(RadauIIA(2, 2, 4, directions=directions)))
    rng = np.random.default_rng(11)
    for _ in range(3):
        x = np.array([0.3, 1.0, 0.5]) + 0.2 * rng.standard_normal(d.nx)
        u = 2.0 + rng.standard_normal(d.nu)
        lam, mu_g = rng.standard_normal(d.nx), rng.standard_normal(d.ng)
        for fn, fk in ((d.stage_hess_exact, dk.stage_hess_exact), (d.stage_hess_gn, dk.stage_hess_gn)):
            for a, b in zip(fn(x, u, [], lam, mu_g), fk(x, u, [], lam, mu_g)):
                a, b = np.array(a), np.array(b)
                np.testing.assert_allclose(a, b, rtol=0, atol=1e-12 * (1 + np.abs(b).max(initial=0.0)))
        np.testing.assert_array_equal(np.array(d.stage_grad(x, u, [], lam, mu_g)[0]),
                                      np.array(dk.stage_grad(x, u, [], lam, mu_g)[0]))


def test_non_stiff_problem_same_solution_as_rk4_within_discretisation():
    mod = _module(SECOND_FILE)
    d_rk = build_functions(mod.build())
    spec = load_ocp(SECOND_FILE).validate()
    gl = GaussLegendre(stages=2, substeps=1, newton_iters=4)
    d_gl = build_functions(dataclasses.replace(spec, model=dataclasses.replace(spec.model, integrator=gl)))
    s_rk, i_rk = solve_ocp(d_rk, d_rk.x0)
    s_gl, i_gl = solve_ocp(d_gl, d_gl.x0)
    assert i_rk["success"] and i_gl["success"]
    # the discretisation difference: the two interval maps along the RK4 solution
    delta = max(np.abs(np.array(d_gl.stage_eval(s_rk.x[k], s_rk.u[k], d_rk.p0[k])[0])
                       - np.array(d_rk.stage_eval(s_rk.x[k], s_rk.u[k], d_rk.p0[k])[0])).max()
                for k in range(d_rk.N))
    assert 0 < delta < 1e-4
    diff = max(np.abs(s_gl.x - s_rk.x).max(), np.abs(s_gl.u - s_rk.u).max())
    assert diff < 50 * d_rk.N * delta, (diff, delta)


def test_stiff_example_both_backends_reach_ipopt(stiff, tmp_path):
    d = build_functions(stiff.build())
    start, info0 = solve_ocp(d, d.x0)
    xhat = stiff.push(d.x0)
    sol, info = solve_ocp(d, xhat)
    assert info0["success"] and info["success"]
    runs = {}
    for name, cls in (("reference", ReferenceDopus), ("c", CSolver)):
        s = cls(d, M=d.N - 1, mode="fixed", hessian="exact", qp_tol=1e-14)
        s.init(xhat, start)
        its = []
        for _ in range(10):
            s.feedback(xhat)
            s.prepare()
            its.append({f: np.array(getattr(s, f), copy=True) for f in ("x", "u", "lam", "mu_b")})
        assert s.kkt(xhat)["kkt"] < 1e-9, name
        np.testing.assert_allclose(s.x, sol.x, rtol=0, atol=1e-6)
        np.testing.assert_allclose(s.u, sol.u, rtol=0, atol=1e-6)
        runs[name] = its
    for it, (c, r) in enumerate(zip(runs["c"], runs["reference"])):
        for f in c:
            err = np.abs(c[f] - r[f]).max() / max(1.0, np.abs(r[f]).max())
            assert err <= 1e-9, f"iteration {it}: {f} differs by {err:.2e}"
