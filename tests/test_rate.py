"""Rate constraints on controls (``Ocp.rate_constraint``): ``lb <= u_k - u_{k-1} <= ub`` between
stages and at stage 0 against the last applied control, which the runtime keeps.

References: an independent CasADi/IPOPT transcription (Opti) written with the controls only
(no memory state) and the last applied control as data; the Python reference DOPUS for the
C runtime's closed loop (the memory entries of the measurement are filled by the backend).
"""
from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from harness.transcription import double_integrator_nlp, solve_nlp

from dopus_codegen import Ocp, build_functions
from dopus_codegen.problem.ocp import OcpError
from dopus_codegen.reference.dopus import ReferenceDopus
from dopus_codegen.reference.offline import solve_ocp
from dopus_codegen.runtime.solver import CSolver

N, DT, RATE, U_LAST = 12, 0.1, 0.25, -1.0


def _ocp():
    o = Ocp("rate")
    x = o.state("x")
    v = o.state("v")
    a = o.control("a", lb=-3.0, ub=3.0)
    o.dynamics(ca.vertcat(v, a))
    o.stage_least_squares(ca.vertcat(x - 1.0, v, a), weights=[10.0, 0.1, 0.01])
    o.terminal_least_squares(ca.vertcat(x - 1.0, v), weights=[10.0, 1.0])
    o.rate_constraint("a", lb=-RATE, ub=RATE, initial=U_LAST)
    o.horizon(N=N, dt=DT)
    o.initial_state([0.0, 0.0])
    o.options(offline_guess=True)
    return o


@pytest.fixture(scope="module")
def rate():
    return build_functions(_ocp())


def _opti(x0, u_last):
    opti, X, U = double_integrator_nlp(N, DT, 3.0, x0)
    J = 0
    for k in range(N):
        J += 0.5 * (10.0 * (X[0, k] - 1.0) ** 2 + 0.1 * X[1, k] ** 2 + 0.01 * U[k] ** 2)
        prev = u_last if k == 0 else U[k - 1]
        opti.subject_to(opti.bounded(-RATE, U[k] - prev, RATE))
    J += 0.5 * (10.0 * (X[0, N] - 1.0) ** 2 + X[1, N] ** 2)
    return solve_nlp(opti, J, X, U)


@pytest.mark.parametrize("call, message", [
    (lambda o: o.rate_constraint("b", ub=1), r"^rate constraint: 'b' is not a declared control; the controls are \['a'\]$"),
    (lambda o: o.rate_constraint(3, ub=1), r"^rate constraint: control must be the name of a declared control, got 3$"),
    (lambda o: o.rate_constraint("a"), r"^rate constraint of 'a': no finite bound \(give lb or ub\)$"),
    (lambda o: o.rate_constraint("a", lb=1, ub=0), r"^rate constraint of 'a': lb > ub at row 0 \(1.0 > 0.0\)$"),
    (lambda o: o.rate_constraint("a", ub=1, initial=[1, 2]),
     r"^rate constraint of 'a' initial: expected a scalar or 1 values, got shape \(2,\)$"),
    (lambda o: o.rate_constraint("a", ub=1, name="bad name"), r"^rate constraint of 'a' name: 'bad name' is not a valid"),
])
def test_bad_rate_declarations(call, message):
    o = Ocp("bad")
    o.state("x")
    o.control("a")
    with pytest.raises(OcpError, match=message):
        call(o)


def test_declared_twice_is_refused():
    o = _ocp()
    with pytest.raises(OcpError, match=r"^rate constraint of 'a': declared twice$"):
        o.rate_constraint("a", ub=1.0)


def test_rate_ocp_equals_independent_transcription(rate):
    """The offline solution and the C full RTI (fixed x0, from the cold guess) equal the
    written-out NLP to 1e-6, with the rate rows active at stage 0 (against the last applied
    control -1) and between stages."""
    assert rate.state_names == ["x", "v", "a_prev"] and rate.ng == 1
    X, U = _opti([0.0, 0.0], U_LAST)
    g, info = solve_ocp(rate, rate.x0)
    assert info["success"]
    assert np.max(np.abs(g.x[:, :2] - X)) < 1e-6 and np.max(np.abs(g.u - U)) < 1e-6
    du = np.diff(np.concatenate([[U_LAST], U[:, 0]]))
    active = np.flatnonzero(np.abs(np.abs(du) - RATE) < 1e-8)
    assert 0 in active and len(active) >= 3, du
    assert abs(g.mu_g[0, 0]) > 1e-4      # the stage-0 row carries a multiplier
    c = CSolver(rate, M=N - 1, mode="fixed", qp_tol=1e-12)
    c.init(rate.x0)
    for _ in range(30):
        c.feedback(rate.x0)
        c.prepare()
        if c.kkt(rate.x0)["kkt"] < 1e-10:
            break
    assert c.kkt(rate.x0)["kkt"] < 1e-10
    assert np.max(np.abs(c.x[:, :2] - X)) < 1e-6 and np.max(np.abs(c.u - U)) < 1e-6
    assert np.allclose(c.x[1:, 2], c.u[:, 0], rtol=0, atol=1e-9)    # the memory is u_{k-1}


def test_runtime_keeps_the_last_applied_control(rate):
    """Closed loop on the model: the measurement's memory entry is garbage (42), the
    backends fill it with the control they returned; C equals the reference iteration by
    iteration, and every applied control respects the rate against the one before."""
    g, _ = solve_ocp(rate, rate.x0)
    c = CSolver(rate, M=1, qp_tol=1e-14)
    r = ReferenceDopus(rate, M=1, qp_tol=1e-14)
    x = np.array(rate.x0, dtype=float)
    for b in (c, r):
        b.init(x, g)
    applied = [U_LAST]
    for i in range(10):
        meas = x.copy()
        meas[2] = 42.0
        uc, ur = c.feedback(meas), r.feedback(meas)
        assert np.max(np.abs(uc - ur)) < 1e-9, i
        assert abs(uc[0] - applied[-1]) <= RATE + 1e-9, (i, uc, applied[-1])
        kc, kr = c.kkt(meas), r.kkt(meas)
        assert kc["kkt"] == pytest.approx(kr["kkt"], rel=1e-6, abs=1e-9)
        applied.append(float(uc[0]))
        for b in (c, r):
            b.prepare()
        for fld in ("x", "u", "lam", "mu_g"):
            a, b_ = getattr(c, fld), getattr(r, fld)
            assert np.max(np.abs(a - b_)) <= 1e-9 * max(1.0, np.max(np.abs(b_))), (i, fld)
        x = np.asarray(rate.stage_eval(x, uc, [])[0], dtype=float).reshape(-1)
        assert x[2] == uc[0]      # the model's memory: the applied control
    assert max(abs(d) for d in np.diff(applied)) == pytest.approx(RATE, abs=1e-9)
