"""The C runtime through its Python handle: regularisation, KKT, rho, parameters, errors.

Every number is checked against an independent computation: numpy.linalg.eigh for the
Jacobi eigen-decomposition, dopus_codegen.reference.kkt.kkt_measure (numpy + CasADi) for the KKT
measure, the reference DOPUS for rho_k and for runs after an error.
"""
from __future__ import annotations

import math
import subprocess

import casadi as ca
import numpy as np
import pytest

from dopus_codegen.codegen.flags import DEFAULT_OPT, PIC, STRICT_CFLAGS
from dopus_codegen import Ocp, RK4, build_functions
from dopus_codegen.studies.converge import make_start
from dopus_codegen.reference.kkt import kkt_measure
from dopus_codegen.paths import runtime_c_dir
from dopus_codegen.reference.dopus import ReferenceDopus
from dopus_codegen.runtime.solver import CSolver, DopusError

from dopus_codegen.errors import status_code

STATUS_QP, STATUS_NONFINITE_INPUT, STATUS_NONFINITE_VALUE = (status_code(n) for n in ("qp", "nonfinite_input",
                                                                                     "nonfinite_value"))
STATUS_INVALID, STATUS_NOT_INITIALIZED, STATUS_NOT_PREPARED = (status_code(n) for n in ("invalid_argument",
                                                                                       "not_initialized",
                                                                                       "not_prepared"))


# ------------------------------------------------------------------ the Jacobi regularisation
@pytest.fixture(scope="module")
def reg_lib(tmp_path_factory):
    """runtime_c/dopus_reg.c alone, as a shared library (it has no size dependency; the
    real type is given on the command line instead of by a sizes header)."""
    import cffi

    d = tmp_path_factory.mktemp("reg")
    so = d / "libreg.so"
    subprocess.run(["cc", *STRICT_CFLAGS, DEFAULT_OPT, PIC, "-shared", "-DDOPUS_REAL_FLOAT=0",
                    str(runtime_c_dir() / "dopus_reg.c"), "-o", str(so), "-lm"], check=True)
    ffi = cffi.FFI()
    ffi.cdef("int dopus_reg_jacobi_eig(int n, double *a, double *v);"
             "int dopus_reg_apply(int n, double *A, int mode, double eps, double *work);")
    return ffi, ffi.dlopen(str(so))


def _sym_cases(rng):
    cases = []
    for n in (1, 2, 3, 5, 8, 12):
        B = rng.standard_normal((n, n))
        cases.append(0.5 * (B + B.T))
    # repeated eigenvalues, a graded spectrum, an indefinite block like the robot arm's
    Q, _ = np.linalg.qr(rng.standard_normal((6, 6)))
    cases.append(Q @ np.diag([2.0, 2.0, 2.0, -1.0, -1.0, 0.0]) @ Q.T)
    cases.append(Q @ np.diag([1e4, 1e2, 1.0, 1e-2, -1e-4, -0.02]) @ Q.T)
    cases.append(np.zeros((4, 4)))
    cases.append(np.diag([3.0, -2.0, 1e-6]))
    return cases


def test_jacobi_eigenvalues_match_numpy(reg_lib):
    ffi, lib = reg_lib
    rng = np.random.default_rng(7)
    for A in _sym_cases(rng):
        n = A.shape[0]
        a = np.asfortranarray(A.copy()).ravel(order="F").copy()
        v = np.zeros(n * n)
        sweeps = lib.dopus_reg_jacobi_eig(n, ffi.from_buffer("double[]", a), ffi.from_buffer("double[]", v))
        assert sweeps >= 0
        a = a.reshape((n, n), order="F")
        V = v.reshape((n, n), order="F")
        e = np.diag(a)
        scale = max(1.0, np.max(np.abs(A)))
        assert np.allclose(np.sort(e), np.linalg.eigvalsh(A), rtol=0, atol=1e-13 * scale)
        assert np.max(np.abs(V.T @ V - np.eye(n))) < 1e-13
        assert np.max(np.abs(V @ np.diag(e) @ V.T - A)) < 1e-13 * scale


@pytest.mark.parametrize("mode,name", [(1, "project"), (2, "mirror")])
def test_regularisation_matches_eigh(reg_lib, mode, name):
    ffi, lib = reg_lib
    rng = np.random.default_rng(11)
    eps = 1e-4
    for A in _sym_cases(rng):
        n = A.shape[0]
        e, V = np.linalg.eigh(A)
        e = np.maximum(e, eps) if name == "project" else np.maximum(np.abs(e), eps)
        want = (V * e) @ V.T
        buf = A.ravel(order="F").copy()
        work = np.zeros(2 * n * n)
        assert lib.dopus_reg_apply(n, ffi.from_buffer("double[]", buf), mode, eps,
                                   ffi.from_buffer("double[]", work)) == 0
        got = buf.reshape((n, n), order="F")
        assert np.max(np.abs(got - want)) <= 1e-13 * max(1.0, np.max(np.abs(A)))
        assert np.min(np.linalg.eigvalsh(got)) >= eps - 1e-12 * max(1.0, np.max(np.abs(A)))


# ------------------------------------------------------------------ KKT and rho
@pytest.fixture(scope="module")
def robot_c(robot_disc):
    return CSolver(robot_disc, M=1, mode="fixed", qp_tol=1e-14)


def test_kkt_matches_python_measure(robot_disc, robot_solution, robot_c):
    """C KKT parts at perturbed primal-dual points == dopus_codegen.reference.kkt.kkt_measure."""
    rng = np.random.default_rng(3)
    g = robot_solution[0].filled(robot_disc)
    for trial in range(3):
        pert = g.copy()
        pert.x = g.x + 1e-2 * trial * rng.standard_normal(g.x.shape)
        pert.u = g.u + 1e-1 * trial * rng.standard_normal(g.u.shape)
        pert.lam = g.lam + trial * rng.standard_normal(g.lam.shape)
        pert.mu_b = g.mu_b + 0.1 * trial * rng.standard_normal(g.mu_b.shape)
        pert.mu_b[0, :robot_disc.nx] = 0.0
        pert.mu_bN = g.mu_bN + trial * rng.standard_normal(g.mu_bN.shape)
        pert.nu = g.nu + trial * rng.standard_normal(g.nu.shape)
        xhat = np.array(robot_disc.x0) + 1e-3 * trial
        robot_c.init(xhat, pert)
        kc = robot_c.kkt(xhat)
        kp = kkt_measure(robot_disc, xhat, pert.x, pert.u, pert.lam, pert.mu_g, pert.mu_b, pert.mu_bN,
                         pert.mu_r, pert.nu)
        for key in ("kkt", "stat", "eq", "ineq", "comp", "rel"):
            assert kc[key] == pytest.approx(kp[key], rel=1e-12, abs=1e-14), (trial, key)
        # the relative measure by its definition (docs/algorithm.md section 6)
        s_d = max(1.0, *(np.max(np.abs(a)) for a in (pert.lam, pert.mu_b, pert.mu_bN, pert.nu)))
        s_p = max(1.0, np.max(np.abs(pert.x)), np.max(np.abs(pert.u)))
        assert kc["rel"] == pytest.approx(max(kp["stat"] / s_d, kp["eq"] / s_p, kp["ineq"] / s_p,
                                              kp["comp"] / (s_d * s_p)), rel=1e-12)
    # at the IPOPT solution the measure is small (the solution is optimal to tol 1e-12)
    robot_c.init(robot_disc.x0, g)
    assert robot_c.kkt(robot_disc.x0)["kkt"] < 1e-8


def test_rho_matches_reference(robot_disc, robot_solution):
    """rho_k of eq. 16 (not only the selection it drives) against the reference."""
    start = make_start(robot_disc, "warm", solve_ocp=lambda d, x0: robot_solution)
    c = CSolver(robot_disc, M=3, mode="fixed", qp_tol=1e-14)
    r = ReferenceDopus(robot_disc, M=3, mode="fixed", qp_tol=1e-14)
    for b in (c, r):
        b.init(start.xhat_init, start.guess)
    for it in range(3):
        for b in (c, r):
            b.feedback(start.xhat_fixed)
            b.prepare()
        assert np.max(np.abs(c.rho - r.rho)) <= 1e-8 * np.max(np.abs(r.rho)), it
        # rho_k is 0 only where the secant residual is round-off (docs/algorithm.md, step 2),
        # and then in both backends alike; all but at most one stage carry a real violation.
        assert c.rho[-1] == 0.0 and np.array_equal(c.rho[:-1] > 0, r.rho[:-1] > 0)
        assert np.sum(r.rho[:-1] > 0) >= robot_disc.N - 2
        assert c.recomputed == r.recomputed and len(c.recomputed) == 4


# ------------------------------------------------------------------ errors through the handle
def test_bad_input_then_good_call(robot_disc, robot_solution):
    """Wrong shapes and NaN give DopusError naming the problem; the next good call works and
    the run continues exactly as a run without the bad calls."""
    start = make_start(robot_disc, "warm", solve_ocp=lambda d, x0: robot_solution)
    clean = CSolver(robot_disc, M=1, mode="receding")
    c = CSolver(robot_disc, M=1, mode="receding")

    with pytest.raises(DopusError, match="not initialised") as ei:
        c.feedback(start.xhat_fixed)
    assert ei.value.status == STATUS_NOT_INITIALIZED
    with pytest.raises(DopusError, match=r"init: xhat0: expected shape \(5,\), got \(4,\)"):
        c.init(start.xhat_init[:4], start.guess)
    bad = start.guess.copy()
    bad.u = bad.u[:-1]
    with pytest.raises(DopusError, match=r"guess.u: expected shape \(40, 3\), got \(39, 3\)"):
        c.init(start.xhat_init, bad)
    bad = start.guess.copy()
    bad.lam = np.array(bad.lam, dtype=float)
    bad.lam[3, 1] = np.nan
    with pytest.raises(DopusError, match=r"guess.lam: NaN or Inf at index \(3, 1\)") as ei:
        c.init(start.xhat_init, bad)
    assert ei.value.status == STATUS_NONFINITE_INPUT

    for b in (clean, c):
        b.init(start.xhat_init, start.guess)
    xh = start.xhat_fixed
    nan_x = xh.copy()
    nan_x[2] = np.nan
    with pytest.raises(DopusError, match=r"robot_arm: feedback: xhat0: NaN or Inf at index 2") as ei:
        c.feedback(nan_x)
    assert ei.value.status == STATUS_NONFINITE_INPUT
    with pytest.raises(DopusError, match=r"expected shape \(5,\), got \(2, 5\)"):
        c.feedback(np.vstack([xh, xh]))
    with pytest.raises(DopusError, match="expected real numbers"):
        c.feedback(np.array(["a"] * 5))
    x_before = c.x
    u0 = c.feedback(xh)
    assert np.array_equal(u0, clean.feedback(xh))
    assert not np.array_equal(c.x, x_before)
    # a second feedback without prepare would solve a stale QP
    with pytest.raises(DopusError, match="no prepared QP") as ei:
        c.feedback(xh)
    assert ei.value.status == STATUS_NOT_PREPARED
    for b in (clean, c):
        b.prepare()
    for it in range(3):
        assert np.array_equal(c.feedback(xh), clean.feedback(xh))
        c.prepare()
        clean.prepare()
    assert np.array_equal(c.x, clean.x) and np.array_equal(c.lam, clean.lam)
    assert c.ring_head == clean.ring_head == 4

    # invalid settings
    with pytest.raises(DopusError, match="M must be an integer >= 0"):
        c.set_M(-1)
    with pytest.raises(DopusError, match="mode must be"):
        c.set_mode("sideways")
    with pytest.raises(DopusError, match="regularization must be"):
        c.set_regularization("flip")
    with pytest.raises(DopusError, match="reg_eps must be positive"):
        c.set_regularization("project", -1.0)
    c.set_M(1000)
    assert c.M == robot_disc.N - 1     # clamped to the full RTI, as the reference does
    assert c.feedback(xh).shape == (3,)


def test_timings_with_a_custom_clock(robot_disc, robot_solution):
    """The clock hook: with a clock that ticks one unit per read, every interval between two
    reads of a call goes to exactly one phase, so the phases of a prepare add up to its wall
    time, the number of reads minus one, exactly."""
    c = CSolver(robot_disc, M=1, mode="receding")
    c.init(robot_disc.x0, robot_solution[0])
    ticks = {"n": 0}

    def clock():
        ticks["n"] += 1
        return float(ticks["n"])

    assert c.has_clock            # Linux has POSIX timers: the default clock measures time
    c.set_clock(clock)
    assert c.has_clock
    c.feedback(robot_disc.x0)
    t = c.timings
    assert t["feedback"] == 1.0 and t["t_feedback"] == 1.0    # one phase: read at the start and the end
    hessians = {}
    for cost_hessian in ("fresh", "stored"):
        c.set_cost_hessian(cost_hessian)
        if cost_hessian == "stored":
            c.feedback(robot_disc.x0)
        before = ticks["n"]
        c.prepare()
        reads = ticks["n"] - before
        t = c.timings
        assert t["t_prepare"] == reads - 1 and t["prepare"] == t["t_prepare"], (cost_hessian, t, reads)
        # every part ran: the automatic lm (the default) and the divergence test included
        for phase in ("shift", "gradients", "rho", "hessians", "assembly", "lm", "recovery"):
            assert t[phase] >= 1.0, (phase, t)
        assert t["regularization"] == 0.0    # no regularisation (the default): not entered
        hessians[cost_hessian] = t["hessians"]
    # stored: A_l only with the two fresh stage H (A_dyn), not for every stage
    assert hessians["stored"] < hessians["fresh"]
    c.set_clock(None)
    c.feedback(robot_disc.x0)
    assert 0.0 < c.timings["feedback"] < 10.0


@pytest.mark.parametrize("M", [1, "full"])
def test_phases_add_up_to_the_wall_time(robot_disc, robot_solution, M):
    """Every part of feedback and prepare is inside a named phase: with the default clock the
    phases of each call add up to the call's wall time (dopus_info.t_feedback, t_prepare,
    measured by the same clock) within 2 %, and that wall time is inside the one Python
    measures around the call. A closed loop of the robot arm with a push (no speed claim)."""
    import time

    c = CSolver(robot_disc, M=robot_disc.N - 1 if M == "full" else M, mode="receding")
    c.init(robot_disc.x0, robot_solution[0])
    p0 = np.asarray(c.p[0], dtype=float)
    x = np.asarray(robot_disc.x0, dtype=float)
    worst = 0.0
    for k in range(30):
        if k == 5:
            x = np.asarray(robot_disc.disturbance(x.copy()), dtype=float).reshape(-1)
        t0 = time.perf_counter()
        u = c.feedback(x)
        t1 = time.perf_counter()
        c.prepare()
        t2 = time.perf_counter()
        t = c.timings
        assert 0.0 < t["t_feedback"] <= t1 - t0 and t["feedback"] == pytest.approx(t["t_feedback"], rel=0.02)
        assert 0.0 < t["t_prepare"] <= t2 - t1
        assert abs(t["prepare"] - t["t_prepare"]) <= 0.02 * t["t_prepare"], (k, t)
        worst = max(worst, abs(t["prepare"] - t["t_prepare"]) / t["t_prepare"])
        x = np.asarray(robot_disc.stage_eval(x, u, p0)[0], dtype=float).reshape(-1)
    print(f"\nM = {M}: phases against the wall time of prepare, largest relative gap {worst:.1e}")


# ------------------------------------------------------------------ a tiny problem: NR > 0, no LS
def _tiny_ocp():
    """A pendulum-like double integrator with no least-squares cost (so no Gauss-Newton), one runtime
    parameter scaling the cost through sqrt(p) (p < 0 makes the functions return NaN), a
    terminal inequality row and a path constraint."""
    ocp = Ocp("tiny")
    x = ocp.state("x", 2, lb=-5, ub=5)
    u = ocp.control("u", lb=-1, ub=1)
    w = ocp.parameter("w", value=1.0)
    ocp.dynamics(ca.vertcat(x[1], u - 2.0 * ca.sin(x[0])), integrator=RK4(substeps=1))
    ocp.stage_cost(ca.sqrt(w) * (x[0] ** 2 + x[1] ** 2 + 0.1 * u ** 2))
    ocp.terminal_cost(10 * (x[0] ** 2 + x[1] ** 2))
    ocp.path_constraint(x[0] + x[1], ub=1.5)
    ocp.terminal_constraint(x[0] - 0.5 * x[1], lb=-0.2)
    ocp.horizon(N=10, dt=0.1)
    ocp.initial_state([1.0, 0.0])
    ocp.initial_guess(x=[1.0, 0.0], u=[0.0])
    return ocp


@pytest.fixture(scope="module")
def tiny_disc():
    return build_functions(_tiny_ocp())


def test_tiny_matches_reference_and_recovers(tiny_disc):
    disc = tiny_disc
    assert (disc.nr, disc.ne, disc.np, disc.ng) == (1, 0, 1, 1)
    c = CSolver(disc, M=2, mode="receding", qp_tol=1e-14)
    r = ReferenceDopus(disc, M=2, mode="receding", qp_tol=1e-14)
    with pytest.raises(DopusError, match="gauss-newton.*least-squares"):
        c.set_hessian("gauss-newton")
    xhat = np.array(disc.x0, dtype=float)
    for b in (c, r):
        b.init(xhat, None)
    for it in range(12):
        uc, ur = c.feedback(xhat), r.feedback(xhat)
        assert np.max(np.abs(uc - ur)) < 1e-9
        # parameters are written between feedback and prepare (the next QP's horizon)
        if it == 4:
            for b in (c, r):
                b.set_parameters(np.array([4.0]))
        if it == 8:
            p = np.ones((disc.N + 1, 1))
            p[3] = 2.0
            for b in (c, r):
                b.set_parameters(p)
        for b in (c, r):
            b.prepare()
        for f in ("x", "u", "lam", "mu_g", "mu_b", "mu_bN", "mu_r"):
            a, b_ = getattr(c, f), getattr(r, f)
            assert np.max(np.abs(a - b_)) <= 1e-9 * max(1.0, np.max(np.abs(b_))), (it, f)
        assert c.recomputed == r.recomputed, it
        kc, kr = c.kkt(xhat), r.kkt(xhat)
        assert kc["kkt"] == pytest.approx(kr["kkt"], rel=1e-9, abs=1e-12)
        xhat = np.array(disc.stage_eval(xhat, ur, r.p[0])[0], dtype=float).reshape(-1)

    # a parameter that makes the stage functions return NaN: prepare fails with a status,
    # the iterate stays as after the shift, and the next prepare with a good parameter works
    c.feedback(xhat)
    c.set_parameters(np.array([-1.0]))
    x_fb = c.x
    with pytest.raises(DopusError, match="non-finite|NaN") as ei:
        c.prepare()
    assert ei.value.status == STATUS_NONFINITE_VALUE
    shifted = np.vstack([x_fb[1:], x_fb[-1:]])
    assert np.array_equal(c.x, shifted)
    with pytest.raises(DopusError, match="no prepared QP"):
        c.feedback(xhat)
    c.set_parameters(np.array([1.0]))
    c.set_mode("fixed")          # do not shift a second time
    c.prepare()
    u0 = c.feedback(xhat)
    assert np.all(np.isfinite(u0)) and c.kkt(xhat)["kkt"] < math.inf


def test_sizeof_and_dims(robot_c, robot_disc):
    """The memory bill: one struct, a compile-time constant."""
    print(f"sizeof(robot_arm_solver) = {robot_c.sizeof} bytes")
    assert robot_c.sizeof > 8 * (robot_disc.N * (robot_disc.nw ** 2 + robot_disc.nx * robot_disc.nw))
    assert (robot_c.N, robot_c.nx, robot_c.n_u, robot_c.ne) == (40, 5, 3, 2)


# ------------------------------------------------------------------ nominal guess, clock macro
def test_init_nominal_is_the_offline_solution(robot_disc, robot_solution, robot_c, tmp_path):
    """A folder generated with the offline guess starts at the IPOPT solution (carried as
    static data); a folder without it says so."""
    from dopus_codegen.codegen.generate import generate

    with pytest.raises(DopusError, match="without a nominal guess") as ei:
        robot_c.init_nominal(robot_disc.x0)
    assert ei.value.status == 8
    out = generate(robot_disc, tmp_path / "robot_arm", offline_guess=True)
    c = CSolver.from_dir(out, robot_disc, M=1, mode="fixed")
    assert c.has_nominal
    c.init_nominal(robot_disc.x0)
    g = robot_solution[0].filled(robot_disc)
    for f in ("x", "u", "lam", "mu_b", "mu_bN", "nu"):
        a, b = getattr(c, f), getattr(g, f)
        if f == "mu_b":
            b = b.copy()
            b[0, :robot_disc.nx] = 0.0
        assert np.max(np.abs(a - b)) <= 1e-9 * max(1.0, np.max(np.abs(b))), f
    assert c.kkt(robot_disc.x0)["kkt"] < 1e-8


def test_clock_macro(tmp_path):
    """dopus_timer.c builds strict with and without the POSIX clock; the default clock is
    CLOCK_MONOTONIC (Python's time.monotonic on Linux) or, without POSIX, reads 0."""
    import time

    import cffi

    for posix in (1, 0):
        so = tmp_path / f"libtimer{posix}.so"
        subprocess.run(["cc", *STRICT_CFLAGS, DEFAULT_OPT, PIC, "-shared",
                        f"-DDOPUS_CLOCK_POSIX={posix}", str(runtime_c_dir() / "dopus_timer.c"), "-o", str(so)],
                       check=True)
        ffi = cffi.FFI()
        ffi.cdef("double dopus_timer_default_clock(void *ctx);")
        lib = ffi.dlopen(str(so))
        t_c = lib.dopus_timer_default_clock(ffi.NULL)
        if posix:
            assert abs(t_c - time.monotonic()) < 0.5
        else:
            assert t_c == 0.0


@pytest.mark.parametrize("lm", [0.0, "auto"])
def test_failed_qp_takes_no_step(robot_disc, robot_solution, lm):
    """A QP stopped by its iteration limit: DopusError with the QP status, no step, and the
    run goes on exactly like the reference's run that skipped that feedback (fixed lm), or
    whose QP failed the same way (the automatic lm, whose retries and raise after a failure
    both backends make: docs/algorithm.md section 10). The failing feedback's measurement
    lies two state scales from the prediction: the QP goes to the interior point without the
    active-set start (docs/algorithm.md section 4, feedback), which would solve the QP of
    the nearer measurement within the limit of one iteration."""
    xhat = np.array(robot_disc.disturbance(np.array(robot_disc.x0, dtype=float)), dtype=float)
    c = CSolver(robot_disc, M=2, mode="receding", qp_tol=1e-14, lm=lm)
    r = ReferenceDopus(robot_disc, M=2, mode="receding", qp_tol=1e-14, lm=lm)
    for b in (c, r):
        b.init(robot_disc.x0, robot_solution[0])
    state = {f: getattr(c, f) for f in ("x", "u", "lam", "mu_b", "nu")}
    lm0 = c.lm
    assert lm0 == r.lm
    xfar = xhat.copy()
    xfar[2] += 2.0 * c.scales[0][2]
    c.set_qp_max_iter(1)
    with pytest.raises(DopusError, match=r"QP status 1 \(max_iter\)") as ei:
        c.feedback(xfar)
    assert ei.value.status == STATUS_QP and ei.value.qp_status == 1
    for f, v in state.items():
        assert np.array_equal(getattr(c, f), v), f
    c.set_qp_max_iter(100)
    if lm == "auto":
        # three solves with lm raised in between, then one raise after the failure
        assert c.lm == pytest.approx(max(lm0, 1e-8 * c.lm_scale) * 1e3, rel=1e-12)
        r.set_qp_max_iter(1)
        with pytest.raises(DopusError) as er:
            r.feedback(xfar)
        assert er.value.status == STATUS_QP and er.value.qp_status == 1
        r.set_qp_max_iter(None)
        assert abs(r.lm - c.lm) <= 1e-12 * c.lm
    else:
        # the reference skipped the feedback: it is told the instant passed as a failed
        # feedback would (the calling order of docs/algorithm.md section 4)
        r.allow_prepare()
    for b in (c, r):      # the sampling instant passes without a step: one prepare each
        b.prepare()
    with pytest.raises(DopusError, match="already prepared") as ei:
        c.prepare()
    assert ei.value.status == 10
    for it in range(3):
        uc, ur = c.feedback(xhat), r.feedback(xhat)
        assert np.max(np.abs(uc - ur)) <= 1e-9 * max(1.0, np.max(np.abs(ur))), it
        for b in (c, r):
            b.prepare()
        for f in ("x", "u", "lam", "mu_b", "mu_bN", "nu"):
            a, b_ = getattr(c, f), getattr(r, f)
            assert np.max(np.abs(a - b_)) <= 1e-9 * max(1.0, np.max(np.abs(b_))), (it, f)
        assert c.recomputed == r.recomputed


# --------------------------------------------------------------------------- QP warm start
def _clone(dst: CSolver, src: CSolver) -> None:
    """Copy the whole solver state (same library): both then face the same QP."""
    dst.copy_state_from(src)


def _warm_vs_cold(robot_disc, guess, iters, disturb, **kw):
    """Closed loop with the warm start (the default); at every instant a clone of the state
    solves the same QP cold. Returns the per-instant (cold retry taken, warm QP iterations,
    largest relative difference of the iterate after feedback)."""
    warm = CSolver(robot_disc, qp_tol=1e-14, **kw)
    cold = CSolver(robot_disc, qp_tol=1e-14, **kw)
    assert warm.qp_warm_start
    warm.init(robot_disc.x0, guess)
    p0 = np.asarray(warm.p[0], dtype=float)
    xhat = np.array(robot_disc.x0, dtype=float)
    out = []
    for it in range(iters):
        if it in disturb:
            xhat = np.array(robot_disc.disturbance(xhat.copy()), dtype=float).reshape(-1)
        _clone(cold, warm)
        cold.set_qp_warm_start(False)
        uw, uc = warm.feedback(xhat), cold.feedback(xhat)
        errs = [np.max(np.abs(getattr(warm, f) - getattr(cold, f))) / max(1.0, np.max(np.abs(getattr(cold, f))))
                for f in ("x", "u", "lam", "mu_b", "nu")]
        errs.append(np.max(np.abs(uw - uc)) / max(1.0, np.max(np.abs(uc))))
        out.append((warm.qp_cold_retry, warm.qp_iterations, max(errs)))
        assert not cold.qp_cold_retry
        warm.prepare()
        xhat = np.array(robot_disc.stage_eval(xhat, uw, p0)[0], dtype=float).reshape(-1)
    return out


def test_qp_warm_start_same_minimiser_as_cold(robot_disc, robot_solution):
    """Closed loop of the robot arm as `dopus-gen sil` runs it (M = 1, exact Hessian, the OCP
    file's Levenberg-Marquardt term), disturbed twice: at every instant the warm-started QP
    (previous solution shifted, the default) reaches the same minimiser as the cold start
    on the same QP, to the accuracy of a QP tolerance of 1e-14."""
    runs = _warm_vs_cold(robot_disc, robot_solution[0], 30, (0, 15), M=1, lm=None)
    worst = max(e for _, _, e in runs)
    assert worst <= 1e-9, runs
    print(f"\nwarm vs cold, 30 instants: worst relative difference {worst:.1e}, warm QP iterations "
          f"{[n for _, n, _ in runs]}, cold retries {sum(r for r, _, _ in runs)}")


def test_qp_warm_start_falls_back_to_cold(robot_disc, robot_solution):
    """The paper's stored-Hessian loop (cost_hessian stored, M = 1, exact Hessian, no
    Levenberg-Marquardt term) from the IPOPT solution: at its fifth instant the warm-started
    QP needs the inertia correction (nonconvex on the null space of the equalities, where a
    warm start may reach another local minimiser than the closed loop follows); feedback
    then retries cold in the same call, and the result is the cold start's."""
    runs = _warm_vs_cold(robot_disc, robot_solution[0], 6, (), M=1, cost_hessian="stored", lm=0.0)
    assert any(r for r, _, _ in runs), runs
    assert max(e for _, _, e in runs) <= 1e-9, runs


def test_qp_warm_start_setting(robot_disc):
    c = CSolver(robot_disc)
    assert c.qp_warm_start is True
    c.set_qp_warm_start(False)
    assert c.qp_warm_start is False
    with pytest.raises(DopusError, match="qp_warm_start"):
        c.set_qp_warm_start(2)
    assert CSolver(robot_disc, qp_warm_start=False).qp_warm_start is False
