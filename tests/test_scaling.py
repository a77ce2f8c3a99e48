"""Scaling (docs/algorithm.md section 16) and the relative KKT measure (section 6).

- The scaled transcription is the declared problem: a problem in millimetres with every kind
  of row (soft path row, rate row with its stage-0 row against the last applied control,
  terminal rows, a moving parameter) solved by the reference in scaled variables equals IPOPT
  on the declared NLP, and its closed loop equals that of the same problem without scales.
- Both backends convert at their boundary identically: the C runtime of the scaled problem
  equals the reference iterate by iterate.
- The stiff reactor in kelvin (examples/cstr.py): the float build without scaling stalls on
  the absolute tolerance, the scaled float build converges in relative terms and is within
  1e-4 (relative to the largest entry) of the double build, which equals IPOPT.
"""
import sys
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from dopus_codegen import RK4, Ocp, OcpError, Soft, build_functions
from dopus_codegen.reference.dopus import ReferenceDopus
from dopus_codegen.reference.kkt import node_parameters
from dopus_codegen.reference.offline import solve_ocp
from dopus_codegen.runtime.solver import CSolver
from dopus_codegen.studies.converge import make_start, run_study

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
import cstr  # noqa: E402

N, DT = 12, 0.1


def millimetres(scaled=True, soft=True, rate=True):
    """A cart in millimetres: position p (mm), speed v (mm/s), acceleration a (mm/s^2) with a
    rate limit, a soft speed limit, terminal rows and a reference that moves."""
    ocp = Ocp("cart_mm")
    x = ocp.state("x", 2, lb=[-5e3, -2e3], ub=[5e3, 2e3], scale=[1e3, 5e2] if scaled else None)
    a = ocp.control("a", lb=-1.5e3, ub=1.5e3, scale=1e3 if scaled else None)
    ref = ocp.parameter("ref", trajectory=lambda t: [800.0 + 300.0 * t])
    ocp.dynamics(ca.vertcat(x[1], a), integrator=RK4(1))
    ocp.stage_least_squares(ca.vertcat(x[0] - ref, a), weights=[1e-2, 1e-6])
    ocp.terminal_least_squares(x[0] - ref, weights=[1e-1])
    ocp.path_constraint(x[1], ub=450.0, name="v_max", soft=Soft(l1=2.0, l2=0.01) if soft else None,
                        scale=5e2 if scaled else None)
    if rate:
        ocp.rate_constraint("a", lb=-600.0, ub=600.0, scale=1e3 if scaled else None)
    ocp.terminal_constraint(x[1], lb=-400.0, ub=400.0, name="v_end", scale=5e2 if scaled else None)
    if scaled:
        ocp.scaling(cost=1e2)
    ocp.horizon(N=N, dt=DT)
    ocp.initial_state([0.0, 0.0])
    ocp.options(hessian="gauss-newton", M=N - 1, lm=0.0)
    return ocp


@pytest.fixture(scope="module")
def cart():
    return build_functions(millimetres()), build_functions(millimetres(scaled=False))


def _rel(a, b):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return float(np.max(np.abs(a - b)) / max(1.0, np.max(np.abs(b))))


def test_the_scaled_problem_has_the_declared_numbers(cart):
    disc, _ = cart
    sc = disc.scaling
    # the memory state of the rate row has the control's scale, the rate rows too
    assert sc.x.tolist() == [1e3, 5e2, 1e3] and sc.u.tolist() == [1e3] and sc.cost == 1e2
    assert sc.g.tolist() == [5e2, 1e3] and sc.r.tolist() == [5e2] and sc.r_eq.size == 0
    s = disc.scaled
    assert np.array_equal(s.lbx, np.array([-5.0, -4.0, -np.inf])) and np.array_equal(s.ubu, [1.5])
    assert np.array_equal(s.ug, [0.9, 0.6]) and np.array_equal(s.ur, [0.8])
    # soft weights: l1 d / c, l2 d^2 / c (the same penalty of the same violation)
    assert s.soft_g[1, 0] == pytest.approx(2.0 * 5e2 / 1e2) and s.soft_g[3, 0] == pytest.approx(0.01 * 5e2**2 / 1e2)
    # the scaled functions are the declared ones, divided by their scales
    xs, us, p = np.array([0.3, -0.2, 0.1]), np.array([0.4]), np.array([900.0])
    phi_s, l_s, g_s = (np.asarray(v, float).ravel() for v in s.stage_eval(xs, us, p))
    phi, l_, g = (np.asarray(v, float).ravel() for v in disc.stage_eval(xs * sc.x, us * sc.u, p))
    assert np.allclose(phi_s, phi / sc.x, rtol=1e-14) and l_s == pytest.approx(l_[0] / sc.cost, rel=1e-14)
    assert np.allclose(g_s, g / sc.g, rtol=1e-14)


def test_scaled_reference_equals_ipopt_on_the_declared_nlp(cart):
    disc, _ = cart
    x0 = np.array([100.0, 300.0, 0.0])
    sol, info = solve_ocp(disc, x0)
    assert info["success"]
    be = ReferenceDopus(disc, mode="fixed")
    be.init(x0)
    for _ in range(6):
        be.feedback(x0)
        be.prepare()
    k = be.kkt(x0)
    assert k["kkt"] < 1e-9
    g = sol.filled(disc)
    # the rows are active: the rate row at stage 0 (against the given last control 0), the
    # soft speed limit (violated, at a price) and the terminal speed row
    assert abs(sol.u[0, 0]) == pytest.approx(600.0, rel=1e-8)
    assert np.max(sol.x[1:, 1]) > 450.0 + 1.0
    assert abs(g.mu_r[0]) > 1e-6
    for got, want in ((be.x, g.x), (be.u, g.u), (be.lam, g.lam), (be.mu_g, g.mu_g), (be.mu_b, g.mu_b),
                      (be.mu_r, g.mu_r)):
        assert _rel(got, want) < 1e-6
    # the slacks come back in millimetres per second
    assert be.soft_slacks()["max"] == pytest.approx(np.max(sol.x[1:N, 1]) - 450.0, rel=1e-6)


def _loop(backend, disc, steps=8):
    """A receding-horizon loop on the model itself, the reference moving; returns u0 per instant."""
    x = np.array([0.0, 0.0, 0.0])
    backend.init(x)
    out = []
    for i in range(steps):
        u0 = backend.feedback(x)
        out.append(u0.copy())
        backend.push_parameters(disc.parameters_at((i + 1 + N) * DT))
        backend.prepare()
        x = np.array(disc.stage_eval(x, u0, disc.parameters_at(i * DT))[0], dtype=float).ravel()
        x[2] = u0[0]
    return np.array(out)


def test_scaled_loop_equals_the_unscaled_loop(cart):
    disc, plain = cart
    a = _loop(ReferenceDopus(disc), disc)
    b = _loop(ReferenceDopus(plain), plain)
    assert _rel(a, b) < 1e-8


def test_c_equals_the_reference_on_the_scaled_problem(cart):
    disc, _ = cart
    c, r = CSolver(disc, qp_tol=1e-13), ReferenceDopus(disc, qp_tol=1e-13)
    assert _rel(_loop(c, disc), _loop(r, disc)) < 1e-9
    for got, want in ((c.x, r.x), (c.u, r.u), (c.lam, r.lam), (c.mu_g, r.mu_g), (c.mu_b, r.mu_b)):
        assert _rel(got, want) < 1e-9
    x = np.array([10.0, 20.0, 0.0])
    kc, kr = c.kkt(x), r.kkt(x)
    assert kc["kkt"] == pytest.approx(kr["kkt"], rel=1e-8) and kc["rel"] == pytest.approx(kr["rel"], rel=1e-8)
    # the slacks of the last feedback's QP, in millimetres per second
    assert _rel(c.feedback(x), r.feedback(x)) < 1e-9
    sc, sr = c.soft_slacks(), r.soft_slacks()
    assert sr["max"] > 1.0 and _rel(sc["g"], sr["g"]) < 1e-8 and sc["max"] == pytest.approx(sr["max"], rel=1e-8)


# ------------------------------------------------------------------ the reactor in kelvin
ITERS = 20


def _factory(real):
    def make(d, **kw):
        return CSolver(d, real=real, **kw)
    return make


@pytest.fixture(scope="module")
def reactor():
    out = {}
    for scaled in (False, True):
        disc = build_functions(cstr.build(scaled=scaled))
        start = make_start(disc, "warm")
        out[scaled] = {real: run_study(disc, [disc.N - 1, 1], ITERS, start, backend_factory=_factory(real),
                                       tol=2e-5, tol_rel=1e-5) for real in ("double", "float")}
        out[scaled]["start"] = start
        out[scaled]["disc"] = disc
    return out


def test_double_reactor_equals_ipopt(reactor):
    disc, start = reactor[True]["disc"], reactor[True]["start"]
    sol, info = solve_ocp(disc, start.xhat_fixed)
    assert info["success"]
    s = reactor[True]["double"]["solution"]
    assert s["converged"]
    assert _rel(s["x"], sol.x) < 1e-8 and _rel(s["u"], sol.u) < 1e-8
    # the coolant's lower limit is active while the reactor is cooled after the disturbance,
    # and the plan ends near the model's steady state at the target
    assert np.min(sol.u[:, 0]) == pytest.approx(cstr.TC_MIN, abs=1e-6)
    assert abs(sol.x[-1, 0] - cstr.CA_REF) < 1e-3 and abs(sol.u[-1, 0] - cstr.TC_REF) < 0.5


def test_reactor_reference_is_a_steady_state_inside_the_bounds():
    """The cost's reference (cA, T, Tc) with the jacket's Tj is an equilibrium of the model."""
    x_ref = np.array([cstr.CA_REF, cstr.T_REF, cstr.TJ_REF])
    dx = np.asarray(ca.DM(cstr.cstr_ode(x_ref, cstr.TC_REF)), float).ravel()
    assert np.max(np.abs(dx / np.array([cstr.CAF, cstr.TF, cstr.TF]))) < 1e-14
    disc = build_functions(cstr.build(scaled=False))
    assert np.all(disc.lbx < x_ref) and np.all(x_ref < disc.ubx)
    assert np.all(disc.lbu < cstr.TC_REF) and np.all(cstr.TC_REF < disc.ubu)
    g = np.asarray(disc.stage_eval(x_ref, [cstr.TC_REF], disc.p_default)[2], float).ravel()
    assert np.all(disc.lg < g) and np.all(g < disc.ug)


def test_float_reactor_without_scaling_stalls_on_the_absolute_tolerance(reactor):
    """Measured (bench/float_scaling.py): the absolute KKT measure of the float build settles at
    1.0e-4 (full RTI) to 1.6e-3 (M = 1), above float's tolerance 2e-5: not converged in absolute
    terms; its relative measure reaches 1e-5 after 3 (full RTI) and 6 (M = 1) iterations and
    then stays below 2.4e-6 (full RTI) and 2.2e-5 (M = 1)."""
    for run in reactor[False]["float"]["runs"]:
        assert min(run["kkt"][ITERS // 2:]) > 2e-5
        assert run["iterations_to_tol"] is not None and min(run["rel"][ITERS // 2:]) < 1e-5


def _stationarity_roundoff(disc, sol):
    """The round-off of the stationarity a float build of ``disc`` computes, at the solution
    ``sol`` (declared units, IPOPT's): ``(B, s_d)``, ``B`` the largest entry over the stages and
    the terminal node of eps_float times the sizes of the terms that enter it, ``s_d`` the
    multipliers' size of the relative measure (both in the solver's variables).

    Stage k, entry j of w = (x, u): ``eps (|A_k| |w_k| + |grad l_k| + kappa_k T_k' |lam_{k+1}|
    + |C_k|' |mu_g,k| + |mu_b,k| + |lam_k|)_j``: the iterate is a float vector (``|A_k| |w_k|``,
    ``A_k`` the exact Hessian of the Lagrangian), and the dynamics' part ``Phi_k' lam_{k+1}``
    is summed from ``Phi_k = [I 0] + h sum_i b_i dK_i/dw`` (``T_k`` the same sum of absolute
    values) whose sensitivities ``dK/dw`` a float build solves with the Jacobian of the
    collocation's stage equations ``I - h A (x) J``: round-off times its condition number
    ``kappa_k`` (infinity norm, at the stage values). Terminal node: ``eps (|A_N| |x_N| +
    |grad E| + |R|' |mu_r| + |mu_bN| + |lam_N|)``."""
    sc, S = disc.scaling, disc.scaled
    integ = disc.spec.model.integrator
    assert integ.substeps == 1
    eps = float(np.finfo(np.float32).eps)
    N, nx, nu = disc.N, disc.nx, disc.nu
    pt = sc.guess_in(sol)   # the solution in the solver's variables
    x, u, lam, mu_g, mu_b, mu_bN, mu_r = pt.x, pt.u, pt.lam, pt.mu_g, pt.mu_b, pt.mu_bN, pt.mu_r
    P = node_parameters(S)
    xs, us, ps = ca.SX.sym("x", nx), ca.SX.sym("u", nu), ca.SX.sym("p", S.np)
    f = S.ode(xs, us, ps)
    fj = ca.Function("fj", [xs, us, ps], [f, ca.jacobian(f, ca.vertcat(xs, us))])
    A, b, h, s = np.asarray(integ.A, float), np.asarray(integ.b, float), disc.dt, len(integ.b)
    out = 0.0
    for k in range(N):
        gl = np.asarray(S.stage_grad(x[k], u[k], P[k], np.zeros(nx), np.zeros_like(mu_g[k]))[0], float).ravel()
        Ak, _, Ck = (np.asarray(v, float) for v in S.stage_hess_exact(x[k], u[k], P[k], lam[k + 1], mu_g[k]))
        K = np.tile(np.asarray(fj(x[k], u[k], P[k])[0], float).ravel(), (s, 1))
        for _ in range(20):   # the stage equations K_i = f(x + h sum_j a_ij K_j), Newton in double
            stage = [fj(x[k] + h * A[i] @ K, u[k], P[k]) for i in range(s)]
            G = np.concatenate([K[i] - np.asarray(stage[i][0], float).ravel() for i in range(s)])
            jac = np.block([[np.eye(nx) * (i == j) - h * A[i, j] * np.asarray(stage[i][1], float)[:, :nx]
                             for j in range(s)] for i in range(s)])
            K = K - np.linalg.solve(jac, G).reshape(s, nx)
        dK = np.linalg.solve(jac, np.vstack([np.asarray(st[1], float) for st in stage]))
        T = np.hstack([np.eye(nx), np.zeros((nx, nu))]) + h * sum(b[i] * np.abs(dK[i * nx:(i + 1) * nx])
                                                                  for i in range(s))
        terms = (np.abs(Ak) @ np.abs(np.concatenate([x[k], u[k]])) + np.abs(gl)
                 + np.linalg.cond(jac, np.inf) * T.T @ np.abs(lam[k + 1])
                 + np.abs(Ck).T @ np.abs(mu_g[k]) + np.abs(mu_b[k]))
        terms[:nx] += np.abs(lam[k])
        out = max(out, eps * float(np.max(terms)))
    gE = np.asarray(S.term_grad(x[N], P[N], np.zeros_like(mu_r), pt.nu)[0], float).ravel()
    AN, RN, _ = (np.asarray(v, float) for v in S.term_hess_exact(x[N], P[N], mu_r, pt.nu))
    terms = np.abs(AN) @ np.abs(x[N]) + np.abs(gE) + np.abs(RN).T @ np.abs(mu_r) + np.abs(mu_bN) + np.abs(lam[N])
    out = max(out, eps * float(np.max(terms)))
    s_d = max([1.0] + [float(np.max(np.abs(a))) for a in (lam, mu_g, mu_b, mu_bN, mu_r) if np.size(a)])
    return out, s_d


def test_float_reactor_with_scaling_converges_to_the_double_build(reactor):
    """The scaled float build converges in relative terms to its round-off floor and is within
    1e-4 of the double build (relative to the largest entry), 10 times closer than without the
    scales (measured, bench/float_scaling.py: 7.6e-7 against 8.5e-5).

    The floor. Once the relative measure reached 1e-5 (3 iterations for the full RTI, 8 for
    M = 1) the stationarity of every iterate stays below 2 B, B the round-off bound of
    `_stationarity_roundoff` at the solution: the iterate solves the QP of float data (the
    gradient and the Jacobians of the previous linearisation, each entry off by at most B) and
    the measure evaluates the stationarity in float once more (at most B again): c = 2. Measured
    (bench/float_floor.py, bench/issue23/measurements.md section 41): B = 1.46e-4, set by the
    terminal node, whose cost has the curvature 1225 in the temperature (0.1 / K^2 declared, the
    scale 350 K, the cost scale 10) at x_N about 1: one float step of x_N (6e-8) moves its
    stationarity by 7.3e-5. The largest entry of the measure is that one: x_N's temperature
    alternates between two adjacent floats, the measure between 3.7e-5 and 7.0e-5 (0.25 to
    0.48 B; the relative measure between 8e-6 and 1.6e-5, so it does not stay below 1e-5), the active
    set unchanged; the stages' entries, evaluated in double, stay below 1.7e-5 (their part of B
    4.4e-5: the collocation's stage equations have condition number 38). The QP tolerance does
    not set the floor (the same with qp_tol 3e-7), and the double build is at 5.7e-12 there."""
    disc, start = reactor[True]["disc"], reactor[True]["start"]
    fl, db = reactor[True]["float"], reactor[True]["double"]
    sol, info = solve_ocp(disc, start.xhat_fixed)
    assert info["success"]
    B, s_d = _stationarity_roundoff(disc, sol.filled(disc))
    assert min(db["runs"][0]["stat"]) < 1e-3 * B
    for run in fl["runs"]:
        assert run["status"] == "converged", run
        for i in range(run["iterations_to_tol"], ITERS + 1):
            assert run["stat"][i] <= 2 * B, (run["M"], i, run["stat"][i], B)
            assert run["rel"][i] <= 2 * B / s_d, (run["M"], i, run["rel"][i], B / s_d)
    assert fl["solution"]["M"] == db["solution"]["M"]
    for key in ("x", "u"):
        assert _rel(fl["solution"][key], db["solution"][key]) <= 1e-4
        assert _rel(fl["solution"][key], db["solution"][key]) * 10 < _rel(reactor[False]["float"]["solution"][key],
                                                                          db["solution"][key])


def test_derived_scales():
    ocp = cstr.build(scaled=False)
    ocp.scaling(derive="bounds")
    sc = build_functions(ocp).scaling
    # powers of two of the largest finite bound: cA 1, T and Tj 450, Tc 330, the row's bound 355
    assert sc.x.tolist() == [1.0, 512.0, 512.0] and sc.u.tolist() == [256.0] and sc.g.tolist() == [256.0]
    ocp.scaling(derive="nominal")
    sc = build_functions(ocp).scaling
    assert sc.x.tolist() == [0.5, 256.0, 256.0] and sc.u.tolist() == [256.0] and sc.g.tolist() == [256.0]


# ------------------------------------------------------------------ bad input
@pytest.mark.parametrize("call, text", [
    (lambda o: o.state("y", 2, scale=[1.0, -2.0]), "state 'y' scale: must be positive and finite, got -2.0 at row 1"),
    (lambda o: o.state("y", 2, scale=[1.0, 2.0, 3.0]), "state 'y' scale: expected a scalar or 2 values, got shape (3,)"),
    (lambda o: o.control("w", scale=0.0), "control 'w' scale: must be positive and finite, got 0.0 at row 0"),
    (lambda o: o.control("w", scale="big"), "control 'w' scale: expected a positive number or 1, got 'big'"),
    (lambda o: o.path_constraint(o.x_sym()[0], ub=1, scale=float("nan")),
     "path constraint 1 scale: must be positive and finite, got nan at row 0"),
    (lambda o: o.terminal_constraint(o.x_sym()[0], ub=1, scale=float("inf")),
     "terminal constraint 1 scale: must be positive and finite, got inf at row 0"),
    (lambda o: o.rate_constraint("a", lb=-1, ub=1, scale=-1), "rate constraint of 'a' scale: must be positive"),
    (lambda o: o.scaling(cost=-3.0), "scaling cost scale: must be positive and finite, got -3.0 at row 0"),
    (lambda o: o.scaling(derive="guess"), "scaling: derive must be None, 'bounds' or 'nominal', got 'guess'"),
    (lambda o: o.options(kkt_tol_rel=0.0), "options: kkt_tol_rel must be"),
])
def test_bad_scaling_input(call, text):
    ocp = millimetres(scaled=False, rate=False)
    with pytest.raises(OcpError) as err:
        call(ocp)
    assert text in str(err.value) and "\n" not in str(err.value)


def test_acados_export_refuses_a_scaled_problem():
    from dopus_lab.acados_export import export_ocp

    ocp = millimetres(soft=False, rate=False)
    with pytest.raises(OcpError, match="export: a declared scaling"):
        export_ocp(ocp)


def test_nominal_solution_is_generated_in_the_declared_units(cart, tmp_path):
    """dopus_x0_default and the offline solution are generated in the declared units (what
    init takes); init_nominal converts them like any guess."""
    from dopus_codegen.codegen.build import build
    from dopus_codegen.codegen.generate import generate

    disc, _ = cart
    out = generate(disc, tmp_path / "cart_mm", offline_guess=True)
    build(out)
    text = (out / "cart_mm_problem.c").read_text()
    assert "cart_mm_scale_x[CART_MM_NX] = {1000.0, 500.0, 1000.0}" in text.replace("1e3", "1000.0")
    c = CSolver(disc, lib_dir=out)
    sol, info = solve_ocp(disc, np.asarray(disc.x0, float))
    assert info["success"]
    c.init_nominal(disc.x0)
    g = sol.filled(disc)
    for got, want in ((c.x, g.x), (c.u, g.u), (c.lam, g.lam), (c.mu_b, g.mu_b)):
        assert _rel(got, want) < 1e-13
