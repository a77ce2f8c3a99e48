"""Parameters that move (docs/algorithm.md section 4, "Parameters"): a trajectory declared in
the OCP file, the shift with the horizon, the push of the new last node, the calling order
that refuses a write after prepare, on both backends; the figure-eight example
(examples/figure_eight.py) in the closed loop, from Python and from the generated main.

References: an independent CasADi/IPOPT transcription of the figure-eight NLP with the
reference written out node by node (the offline guess), the Python reference DOPUS (the C
iterates with pushes), the Python loop through the generated API (the C main), the full
RTI (DOPUS M = 1's tracking).
"""
from __future__ import annotations

import math
import subprocess
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from dopus_codegen import Ocp, build_functions, load_ocp
from dopus_codegen.codegen.generate import MAIN_ITERATIONS, generate
from dopus_codegen.errors import DopusError, status_code
from dopus_codegen.problem.ocp import OcpError
from dopus_codegen.reference.dopus import ReferenceDopus
from dopus_codegen.reference.offline import solve_ocp
from dopus_codegen.runtime.solver import CSolver

ROOT = Path(__file__).resolve().parent.parent
FILE = ROOT / "examples" / "figure_eight.py"


@pytest.fixture(scope="module")
def f8():
    return build_functions(load_ocp(FILE))


@pytest.fixture(scope="module")
def f8_nominal(f8):
    guess, info = solve_ocp(f8, f8.x0)
    assert info["success"]
    return guess


def _ref(t):
    import importlib.util

    spec = importlib.util.spec_from_file_location("_f8", FILE)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return np.array(mod.figure_eight(t), dtype=float), mod


# ------------------------------------------------------------------ the OCP file

def _small(**param):
    o = Ocp("small")
    x = o.state("x")
    u = o.control("u", lb=-1, ub=1)
    r = o.parameter("r", **param)
    o.dynamics(u)
    o.stage_least_squares(ca.vertcat(x - r, u), [1.0, 0.1])
    o.horizon(N=4, dt=0.5)
    o.initial_state([0.0])
    return o


@pytest.mark.parametrize("kw, message", [
    (dict(value=1.0, trajectory=lambda t: t), r"^parameter 'r': give value or trajectory, not both$"),
    (dict(trajectory=3.0), r"^parameter 'r' trajectory: expected a function of t or a table \(times, values\), "
                           r"got float$"),
    (dict(trajectory=([0.0, 1.0], [[1.0, 2.0], [3.0, 4.0]])),
     r"^parameter 'r' trajectory: expected values of shape \(2, 1\) \(one row per time\), got \(2, 2\)$"),
    (dict(trajectory=([0.0, 1.0, 1.0], [1.0, 2.0, 3.0])),
     r"^parameter 'r' trajectory: times must increase strictly, got 1.0 then 1.0$"),
    (dict(trajectory=([0.0, np.nan], [1.0, 2.0])),
     r"^parameter 'r' trajectory: the table holds a non-finite value \(NaN or inf\)$"),
    (dict(trajectory=([], [])), r"^parameter 'r' trajectory: times must be a non-empty vector, got shape \(0,\)$"),
])
def test_bad_trajectory_declarations(kw, message):
    with pytest.raises(OcpError, match=message):
        _small(**kw).validate()


@pytest.mark.parametrize("fn, message", [
    (lambda t: [t, t], r"^parameter 'r' trajectory at t = 0 s: expected 1 values, got shape \(2,\)$"),
    (lambda t: 1.0 / (t - 1.0) if t != 1.0 else math.nan,
     r"^parameter 'r' trajectory at t = 1 s: non-finite value \[nan\]$"),
    (lambda t: {}["key"], r"^parameter 'r' trajectory at t = 0 s failed: KeyError: 'key'$"),
])
def test_bad_trajectory_functions_are_named_with_the_time(fn, message):
    with pytest.raises(OcpError, match=message):
        _small(trajectory=fn).validate()


def test_table_and_function_give_the_first_horizon():
    """Node k of the first horizon holds the trajectory at k dt; a table interpolates
    linearly and holds its end values."""
    d_fn = build_functions(_small(trajectory=lambda t: [np.cos(t)]).validate())
    assert np.array_equal(d_fn.p0.ravel(), np.cos(0.5 * np.arange(5)))
    d_tab = build_functions(_small(trajectory=([0.25, 1.25], [1.0, 3.0])).validate())
    assert np.allclose(d_tab.p0.ravel(), [1.0, 1.5, 2.5, 3.0, 3.0], rtol=0, atol=1e-15)
    assert d_tab.parameters_at(7.0)[0] == 3.0 and d_tab.time_varying_parameters
    assert not build_functions(_small(value=2.0).validate()).time_varying_parameters


def test_offline_guess_follows_the_declared_trajectory(f8, f8_nominal):
    """An independent transcription (CasADi Opti, the model written out again, RK4, the
    reference evaluated node by node at k dt) has the solution of the offline guess."""
    _, mod = _ref(0.0)
    N, dt = f8.N, f8.dt
    opti = ca.Opti()
    X, U = opti.variable(4, N + 1), opti.variable(2, N)

    def f(x, u):
        return ca.vertcat(x[3] * ca.cos(x[2]), x[3] * ca.sin(x[2]), u[1], u[0])

    J = 0
    for k in range(N):
        r = _ref(k * dt)[0]
        k1 = f(X[:, k], U[:, k])
        k2 = f(X[:, k] + dt / 2 * k1, U[:, k])
        k3 = f(X[:, k] + dt / 2 * k2, U[:, k])
        k4 = f(X[:, k] + dt * k3, U[:, k])
        opti.subject_to(X[:, k + 1] == X[:, k] + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4))
        e = ca.vertcat(X[0, k] - r[0], X[1, k] - r[1], U[0, k], U[1, k])
        J += 0.5 * ca.sumsqr(ca.sqrt(dt * ca.DM([10.0, 10.0, 0.1, 0.1])) * e)
        opti.subject_to(opti.bounded(-mod.A_MAX, U[0, k], mod.A_MAX))
        opti.subject_to(opti.bounded(-mod.OMEGA_MAX, U[1, k], mod.OMEGA_MAX))
        opti.subject_to(opti.bounded(-0.5, X[3, k + 1], mod.V_MAX))
    rN = _ref(N * dt)[0]
    J += 0.5 * 10.0 * ((X[0, N] - rN[0]) ** 2 + (X[1, N] - rN[1]) ** 2)
    opti.minimize(J)
    opti.subject_to(X[:, 0] == ca.DM(f8.x0))
    opti.set_initial(X, np.tile(np.asarray(f8.x0).reshape(4, 1), (1, N + 1)))
    opti.solver("ipopt", {"print_time": False}, {"print_level": 0, "tol": 1e-12, "sb": "yes"})
    sol = opti.solve()
    assert np.max(np.abs(sol.value(X).T - f8_nominal.x)) < 1e-6
    assert np.max(np.abs(sol.value(U).T - f8_nominal.u)) < 1e-6


# ------------------------------------------------------------------ the calling order

@pytest.fixture(scope="module")
def f8_c(f8):
    return CSolver(f8, qp_tol=1e-14)


def _backends(f8, f8_c):
    f8_c.stop()
    f8_c.set_mode("receding")
    return (("c", f8_c), ("reference", ReferenceDopus(f8, qp_tol=1e-14)))


def test_a_write_after_prepare_is_refused_on_both_backends(f8, f8_c, f8_nominal):
    already, not_init, invalid = (status_code(n) for n in ("already_prepared", "not_initialized",
                                                           "invalid_argument"))
    for name, b in _backends(f8, f8_c):
        p = f8.parameter_horizon(0.0)
        with pytest.raises(DopusError) as ei:
            b.push_parameters(p[-1])
        assert ei.value.status == not_init, name
        b.set_parameters(p)                      # before init: read by init
        b.init(f8.x0, f8_nominal)
        for write in (lambda: b.set_parameters(p), lambda: b.set_parameters_node(3, p[3]),
                      lambda: b.push_parameters(p[-1])):
            with pytest.raises(DopusError, match=r"write them before init or between feedback and prepare") as ei:
                write()
            assert ei.value.status == already, name
            assert np.array_equal(b.p, p), name   # nothing changed
        b.feedback(f8.x0)
        b.push_parameters([7.0, 8.0])            # shifts first, then the new last node
        expect = np.vstack([p[1:], [[7.0, 8.0]]])
        assert np.array_equal(b.p, expect), name
        b.set_parameters_node(0, [5.0, 6.0])     # the next horizon's node 0: no second shift
        expect[0] = [5.0, 6.0]
        assert np.array_equal(b.p, expect), name
        b.prepare()
        assert np.array_equal(b.p, expect), name
        b.feedback(f8.x0)
        b.prepare()                              # no push: shifted, the last node kept
        assert np.array_equal(b.p, np.vstack([expect[1:], expect[-1:]])), name
        b.set_mode("fixed")
        b.feedback(f8.x0)
        with pytest.raises(DopusError) as ei:
            b.push_parameters([0.0, 0.0])
        assert ei.value.status == invalid, name
        b.set_parameters(p)                      # fixed mode: no shift, read by the prepare
        b.prepare()
        assert np.array_equal(b.p, p), name
    f8_c.set_mode("receding")


def test_closed_loop_with_pushes_c_equals_reference(f8, f8_c, f8_nominal):
    """The closed loop on the model with the reference pushed every instant: the C iterates
    equal the Python reference's, iteration by iteration (QP tolerance 1e-14)."""
    (_, c), (_, r) = _backends(f8, f8_c)
    N, dt = f8.N, f8.dt
    for b in (c, r):
        b.set_parameters(f8.parameter_horizon(0.0))
        b.init(f8.x0, f8_nominal)
    xhat = np.array(f8.x0, dtype=float)
    for i in range(8):
        uc, ur = c.feedback(xhat), r.feedback(xhat)
        assert np.max(np.abs(uc - ur)) < 1e-9, i
        pN = f8.parameters_at((i + 1) * dt + N * dt)
        for b in (c, r):
            b.push_parameters(pN)
            b.prepare()
        assert np.array_equal(c.p, r.p)
        assert np.allclose(c.p, f8.parameter_horizon((i + 1) * dt), rtol=0, atol=1e-14), i
        for fld in ("x", "u", "lam", "mu_b"):
            a, b_ = getattr(c, fld), getattr(r, fld)
            assert np.max(np.abs(a - b_)) <= 1e-9 * max(1.0, np.max(np.abs(b_))), (i, fld)
        assert c.recomputed == r.recomputed, i
        xhat = np.asarray(f8.stage_eval(xhat, ur, f8.parameters_at(i * dt))[0], dtype=float).reshape(-1)


# ------------------------------------------------------------------ the closed loop

def test_sil_m1_tracks_the_moving_reference_as_the_full_rti(f8):
    """Acceptance: `sil` M = 1 within 5 % of the full RTI's tracking (RMS of the distance to
    the moving reference over one lap with a push)."""
    from dopus_codegen.studies.sil import run_closed_loop

    rms = {}
    for M in (1, f8.N - 1):
        run = run_closed_loop(f8, backend="c", M=M)
        assert run["result"]["status"] == "completed" and run["result"]["failed_instants"] == 0
        e = np.asarray(run["signals"]["tracking_error"], dtype=float)
        rms[M] = float(np.sqrt(np.mean(e ** 2)))
        # the signal is evaluated with the reference of its instant
        t = np.asarray(run["t"])
        pos = np.asarray(run["x"])[:, :2]
        want = np.linalg.norm(pos - np.array([_ref(ti)[0] for ti in t]), axis=1)
        assert np.max(np.abs(e - want)) < 1e-12
    print(f"figure-eight RMS tracking error: M = 1 {rms[1]:.5f} m, full RTI {rms[f8.N - 1]:.5f} m")
    assert abs(rms[1] - rms[f8.N - 1]) <= 0.05 * rms[f8.N - 1]
    assert rms[f8.N - 1] < 0.2


def _main_rows(stdout: str, nu: int) -> list:
    rows = []
    for line in stdout.splitlines():
        tok = line.split()
        if tok and tok[0] == "receding":
            rows.append((int(tok[3]), np.array([float(v) for v in tok[5:5 + nu]]), float(tok[6 + nu])))
    return rows


def test_generated_main_pushes_the_schedule_as_python_does(f8, f8_nominal, tmp_path):
    """The generated main's closed loop (C, through the generated API, pushing the
    parameter schedule) against the same loop driven from Python through the generated
    library: u0 and KKT to 1e-10; and against the Python reference DOPUS."""
    folder = generate(f8, tmp_path / "figure_eight")
    text = (folder / "figure_eight_sizes.h").read_text()
    assert "#define FIGURE_EIGHT_HAS_P_SCHEDULE 1" in text
    proc = subprocess.run(["make", "-j2"], cwd=folder, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    run = subprocess.run([str(folder / "build" / "main_figure_eight")], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stdout + run.stderr
    rows = _main_rows(run.stdout, f8.nu)
    assert len(rows) == MAIN_ITERATIONS + 1
    N, dt = f8.N, f8.dt
    c = CSolver(f8)
    r = ReferenceDopus(f8, M=f8.options["M"], hessian=f8.options["hessian"], lm=f8.options["lm"])
    xhat = np.array(f8.x0, dtype=float)
    for b in (c, r):
        b.init(xhat, f8_nominal)    # the offline solution, which the main carries as data
    for k in range(1, MAIN_ITERATIONS + 1):
        u_c = c.feedback(xhat)
        u_r = r.feedback(xhat)
        for b in (c, r):
            b.push_parameters(f8.parameters_at(k * dt + N * dt))
        xhat = np.asarray(f8.stage_eval(xhat, u_c, f8.parameters_at((k - 1) * dt))[0], dtype=float).reshape(-1)
        for b in (c, r):
            b.prepare()
        kkt = c.kkt(xhat)["kkt"]
        st, u_main, kkt_main = rows[k]
        assert st == 0
        np.testing.assert_allclose(u_main, u_c, rtol=0, atol=1e-10, err_msg=f"iteration {k}: main vs Python (C)")
        assert abs(kkt_main - kkt) <= 1e-10 * max(1.0, kkt), k
        np.testing.assert_allclose(u_main, u_r, rtol=1e-6, atol=1e-7, err_msg=f"iteration {k}: main vs reference")
