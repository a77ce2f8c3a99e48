"""Rows users write: names for constraint rows (messages, the C API's row description) and
path rows that also hold at x_N (``path_constraint(..., terminal=True)``).

References: an independent CasADi/IPOPT transcription (Opti) with the row written at every
node 1..N for the terminal rows; the infeasible row of a QP whose infeasible row is known by
construction (x' = u, |u| <= 1: x_k <= x_0 + k dt).
"""
from __future__ import annotations

import re

import casadi as ca
import numpy as np
import pytest

from harness.transcription import double_integrator_nlp, solve_nlp

from dopus_codegen import Ocp, Soft, build_functions
from dopus_codegen.errors import DopusError, qp_status_code
from dopus_codegen.problem.ocp import OcpError
from dopus_codegen.reference.dopus import ReferenceDopus
from dopus_codegen.reference.offline import solve_ocp
from dopus_codegen.runtime.solver import CSolver

N, DT = 10, 0.1


def _base(name="rows"):
    o = Ocp(name)
    x = o.state("x")
    v = o.state("v")
    u = o.control("u", lb=-1.0, ub=1.0)
    o.dynamics(ca.vertcat(v, u))
    o.horizon(N=N, dt=DT)
    o.initial_state([0.0, 0.0])
    return o, x, v, u


@pytest.mark.parametrize("call, message", [
    (lambda o, x, v, u: o.path_constraint(x, ub=1, name="a b"),
     r"^path constraint 0 name: 'a b' is not a valid C identifier"),
    (lambda o, x, v, u: (o.path_constraint(x, ub=1, name="wall"), o.terminal_constraint(v, lb=0, name="wall")),
     r"^terminal constraint 0: duplicate constraint name 'wall'$"),
    (lambda o, x, v, u: o.path_constraint(x + u, ub=1, name="mixed", terminal=True),
     r"^path constraint 'mixed': terminal=True, but the rows use control 'u' \(at x_N a row may use states "
     r"and parameters only\)$"),
    (lambda o, x, v, u: o.path_constraint(x, ub=1, terminal="yes"),
     r"^path constraint 0: terminal must be True or False, got 'yes'$"),
    (lambda o, x, v, u: o.terminal_constraint(x, ub=1, name=3),
     r"^terminal constraint 0 name: 3 "),
])
def test_bad_row_declarations(call, message):
    o, x, v, u = _base()
    with pytest.raises(OcpError, match=message):
        call(o, x, v, u)


def _wall_ocp(terminal: bool, soft=None):
    """Drive x to 2 (terminal cost), the path row x <= 0.3 (named 'wall'), optionally at x_N too."""
    o, x, v, u = _base("wall" if terminal else "wall_path")
    o.stage_least_squares(ca.vertcat(u, v), weights=[0.1, 0.1])
    o.terminal_least_squares(x - 2.0, weights=[100.0])
    o.path_constraint(x, ub=0.3, name="wall", terminal=terminal, soft=soft)
    o.options(offline_guess=True)
    return o


def _opti_wall(terminal: bool):
    """The same NLP written out: RK4 of (v, u), the wall at nodes 0..N-1 (and N)."""
    opti, X, U = double_integrator_nlp(N, DT, 1.0, [0.0, 0.0])
    J = 0
    for k in range(N):
        J += 0.5 * 0.1 * (U[k] ** 2 + X[1, k] ** 2)
        if k >= 1:
            opti.subject_to(X[0, k] <= 0.3)
    if terminal:
        opti.subject_to(X[0, N] <= 0.3)
    J += 0.5 * 100.0 * (X[0, N] - 2.0) ** 2
    return solve_nlp(opti, J, X, U)


@pytest.mark.parametrize("terminal", [True, False])
def test_terminal_path_row_equals_independent_transcription(terminal):
    """With terminal=True the wall holds at x_N (active there: the terminal cost pulls x to 2);
    without, x_N passes it. Both equal the written-out NLP to 1e-6, and the C full RTI from
    the offline solution stays there (KKT <= 1e-8)."""
    disc = build_functions(_wall_ocp(terminal))
    assert disc.nr == (1 if terminal else 0)
    g, info = solve_ocp(disc, disc.x0)
    assert info["success"]
    X, U = _opti_wall(terminal)
    assert np.max(np.abs(g.x - X)) < 1e-6 and np.max(np.abs(g.u - U)) < 1e-6
    if terminal:
        assert abs(g.x[N, 0] - 0.3) < 1e-8 and g.mu_r[0] > 1e-3     # active at x_N
    else:
        assert g.x[N, 0] > 0.31
    c = CSolver(disc, M=N - 1, mode="fixed")
    c.init(disc.x0, g)
    for _ in range(3):
        c.feedback(disc.x0)
        c.prepare()
    assert c.kkt(disc.x0)["kkt"] < 1e-8
    assert np.max(np.abs(c.x - X)) < 1e-6


def test_terminal_path_row_composes_with_soft():
    """A soft wall that also holds at x_N: the terminal twin carries the same soft weights."""
    disc = build_functions(_wall_ocp(True, soft=Soft(l1=1.0)))
    assert disc.nr == 1
    assert np.array_equal(np.asarray(disc.data.soft_r).reshape(4, -1)[:, 0],
                          np.asarray(disc.data.soft_g).reshape(4, -1)[:, 0])


def test_row_names_in_the_c_api_and_messages():
    o, x, v, u = _base("named")
    p = o.parameter("p", value=-10.0)
    o.stage_least_squares(u, weights=[1.0])
    o.path_constraint(x - p, lb=0.0, name="floor")
    o.path_constraint(ca.vertcat(v, x + v), lb=-5.0, ub=5.0)
    o.terminal_constraint(ca.vertcat(x, v), lb=[-9.0, 0.0], ub=[9.0, 0.0], name="stop")
    disc = build_functions(o)
    c = CSolver(disc, M=N - 1, mode="fixed")
    assert [c.row_name("state", i) for i in range(2)] == ["x", "v"]
    assert c.row_name("control", 0) == "u"
    assert [c.row_name("path", i) for i in range(3)] == ["floor", "path constraint 1 row 0",
                                                          "path constraint 1 row 1"]
    assert c.row_name("terminal", 0) == "stop[0]" and c.row_name("terminal_eq", 0) == "stop[1]"
    assert c.row_name("path", 3) is None and c.row_name("state", -1) is None
    # the floor at stage 3 cannot be met (x_3 <= 0.03 with x_0 = v_0 = 0 and |u| <= 1)
    pk = np.full((N + 1, 1), -10.0)
    pk[3] = 0.5
    for backend in (c, ReferenceDopus(disc, M=N - 1, mode="fixed")):
        backend.set_parameters(pk)
        backend.init([0.0, 0.0])
        with pytest.raises(DopusError) as ei:
            backend.feedback([0.0, 0.0])
        assert ei.value.qp_status == qp_status_code("primal_infeasible")
        assert re.search(r"infeasible at stage 3: path constraint 'floor' >= lb 0\b", str(ei.value)), str(ei.value)
        backend.stop()


@pytest.mark.parametrize("stages, message", [
    ([N], rf"^path constraint 'wall': stage {N} is outside 0..N-1 = 0..{N - 1}$"),
    ([], r"^path constraint 'wall': stages is empty \(leave it out for every stage\)$"),
    ([1, 1], r"^path constraint 'wall': stage 1 given twice$"),
    (["a"], r"^path constraint 'wall': stages must be integers, got 'a'$"),
    (3, r"^path constraint 'wall': stages must be stage indices \(e.g. range\(5, 10\)\), got 3$"),
])
def test_bad_stages(stages, message):
    o, x, v, u = _base()
    with pytest.raises(OcpError, match=message):
        o.path_constraint(x, ub=0.3, name="wall", stages=stages)
        o.validate()


def _opti_stages(stages):
    opti, X, U = double_integrator_nlp(N, DT, 1.0, [0.0, 0.0])
    J = 0
    for k in range(N):
        J += 0.5 * 0.1 * (U[k] ** 2 + X[1, k] ** 2)
        if k in stages:
            opti.subject_to(X[0, k] <= 0.1)
    J += 0.5 * 100.0 * (X[0, N] - 2.0) ** 2
    return solve_nlp(opti, J, X, U)


def test_rows_on_chosen_stages_equal_independent_transcription():
    """x <= 0.1 at stages 4..6 only: active there, passed after; the offline solution and the
    C full RTI (from the cold guess) equal the written-out NLP to 1e-6, and the reference's
    KKT measure of the C solution is that of a solution."""
    from dopus_codegen.reference.kkt import kkt_measure

    stages = (4, 5, 6)
    o, x, v, u = _base("staged")
    o.stage_least_squares(ca.vertcat(u, v), weights=[0.1, 0.1])
    o.terminal_least_squares(x - 2.0, weights=[100.0])
    o.path_constraint(x, ub=0.1, name="gate", stages=range(4, 7))
    disc = build_functions(o)
    lo, up = disc.data.path_bounds()
    assert np.all(np.isinf(up[[0, 1, 2, 3, 7, 8, 9], 0])) and np.all(up[[4, 5, 6], 0] == 0.1)
    X, U = _opti_stages(stages)
    g, info = solve_ocp(disc, disc.x0)
    assert info["success"]
    assert np.max(np.abs(g.x - X)) < 1e-6 and np.max(np.abs(g.u - U)) < 1e-6
    assert abs(X[6, 0] - 0.1) < 1e-8 and X[8, 0] > 0.12 and abs(g.mu_g[6, 0]) > 1e-3
    c = CSolver(disc, M=N - 1, mode="fixed", hessian="gauss-newton")
    c.init(disc.x0)
    for _ in range(30):
        c.feedback(disc.x0)
        c.prepare()
    assert np.max(np.abs(c.x - X)) < 1e-6 and np.max(np.abs(c.u - U)) < 1e-6
    k = kkt_measure(disc, disc.x0, c.x, c.u, c.lam, c.mu_g, c.mu_b, c.mu_bN, c.mu_r, c.nu)
    assert k["kkt"] < 1e-8 and c.kkt(disc.x0)["kkt"] == pytest.approx(k["kkt"], rel=1e-6, abs=1e-12)


def _opti_staged_weights(stages, W):
    """The written-out NLP of _staged_weights_ocp: 0.5 [x - 1, v]' W [x - 1, v] at the chosen stages."""
    opti, X, U = double_integrator_nlp(N, DT, 1.0, [0.0, 0.0])
    J = 0
    for k in range(N):
        J += 0.5 * 1.0 * U[k] ** 2
        if k in stages:
            r = ca.vertcat(X[0, k] - 1.0, X[1, k])
            J += 0.5 * ca.mtimes([r.T, ca.DM(W), r])
    J += 0.5 * 1.0 * X[1, N] ** 2
    return solve_nlp(opti, J, X, U)


def _staged_weights_ocp(stages, W):
    o, x, v, u = _base("staged_weights")
    o.stage_least_squares(u, weights=[1.0])
    o.stage_least_squares(ca.vertcat(x - 1.0, v), weights=W, stages=stages)
    o.terminal_least_squares(v, weights=[1.0])
    return o


@pytest.mark.parametrize("W", [np.diag([5.0, 0.5]), np.array([[5.0, 0.8], [0.8, 0.4]])])
def test_weights_on_chosen_stages_equal_independent_transcription(W):
    """stage_least_squares(..., stages=range(6, 10)): the tracking term only on the last four
    stages (a diagonal and a full weight matrix): the offline solution, the C full RTI from
    the cold guess and the reference equal the written-out NLP to 1e-6, and the term is
    active (the solution with it on every stage differs)."""
    stages = tuple(range(6, 10))
    X, U = _opti_staged_weights(stages, W)
    Xall, _ = _opti_staged_weights(tuple(range(N)), W)
    assert np.max(np.abs(X - Xall)) > 1e-2
    disc = build_functions(_staged_weights_ocp(range(6, 10), W))
    g, info = solve_ocp(disc, disc.x0)
    assert info["success"]
    assert np.max(np.abs(g.x - X)) < 1e-6 and np.max(np.abs(g.u - U)) < 1e-6
    for b in (CSolver(disc, M=N - 1, mode="fixed"), ReferenceDopus(disc, M=N - 1, mode="fixed")):
        b.init(disc.x0)
        for _ in range(30):
            b.feedback(disc.x0)
            b.prepare()
        assert np.max(np.abs(b.x - X)) < 1e-6 and np.max(np.abs(b.u - U)) < 1e-6, type(b).__name__


@pytest.mark.parametrize("call, message", [
    (lambda o, x, v, u: o.stage_least_squares(x, weights=[1.0], stages=[]),
     r"^stage least squares 0: stages is empty \(leave it out for every stage\)$"),
    (lambda o, x, v, u: o.stage_least_squares(x, weights=[1.0], stages=[2, 2]),
     r"^stage least squares 0: stage 2 given twice$"),
    (lambda o, x, v, u: o.stage_least_squares(x, weights=[1.0], stages="ab"),
     r"^stage least squares 0: stages must be integers, got 'a'$"),
    (lambda o, x, v, u: (o.stage_least_squares(x, weights=[1.0], stages=[N]), o.validate()),
     rf"^stage least squares 0: stage {N} is outside 0..N-1 = 0..{N - 1}$"),
    (lambda o, x, v, u: o.stage_least_squares(x, weights=[0.0], stages=[1]),
     r"^stage least squares 0: weights are all zero$"),
])
def test_bad_weight_stages(call, message):
    o, x, v, u = _base()
    with pytest.raises(OcpError, match=message):
        call(o, x, v, u)
