"""The feedback's cold retry after a warm start that certified primal infeasibility.

docs/algorithm.md section 4 (feedback): the warm-started QP that fails is solved again cold
in the same call, except after a certificate of primal infeasibility whose separation is
beyond CERT_SEP and the tolerance (dopus_qp_info.certified): the rows of the QP do not depend
on the starting point, so the cold start cannot solve it (bench/issue24/measurements.md
section 21: no such retry was solved in the fault suites). The certificate's status is the
feedback's qp_status, and qp_cold_retry says that no cold solve ran.

The model is x' = u with |u| <= 1 and the terminal row x_N >= 5 with N dt = 1 (the "reach"
problem of tests/test_infeasible_row.py): from x_0 = 0, x_N <= 1, so every QP of the
feedback is infeasible, which Clarabel (an independent interior point) confirms on the
reference backend's copy of the QP.
"""
from __future__ import annotations

import zlib

import numpy as np
import pytest

from dopus_codegen.errors import DopusError, qp_status_code
from dopus_codegen.reference.dopus import ReferenceDopus
from dopus_codegen.runtime.solver import CSolver
from harness import qp_problems as P
from harness.integrator import N, integrator_model
from harness.qp_harness import build_qp_solver

@pytest.fixture(scope="module")
def reach():
    return integrator_model("reach_retry", 0.0, terminal=(5.0, np.inf))


def _failed_feedback(s, xhat):
    with pytest.raises(DopusError) as ei:
        s.feedback(xhat)
    return ei.value


def _warm_point(r: ReferenceDopus, qp: dict) -> dict:
    """The C runtime's warm-start point of the feedback's QP (dopus_qp_warm_point): a zero
    step with x_0's step fixed by the measurement, and the iterate's multipliers."""
    x = np.zeros((N + 1, r.nx))
    x[0] = qp["x0"]
    pt = {"x": x, "u": np.zeros((N, r.n_u)), "lam": r.lam, "mu_b": r.mu_b, "mu_bN": r.mu_bN}
    for key, n in (("mu_g", r.ng), ("mu_r", r.nr), ("nu", r.ne)):
        if n:
            pt[key] = getattr(r, key)
    return pt


@pytest.mark.parametrize("lm", [0.0, None])
def test_certified_warm_start_spends_no_cold_solve(reach, lm):
    """The C runtime's warm-started QP certifies infeasibility: the feedback reports its
    status (primal infeasible, the terminal row) with no cold retry, and its QP iterations
    are those of the warm solve alone: the C QP solver on the reference backend's copy of the
    QP from the runtime's warm point takes as many, a copy of the solver with the warm start
    off as many as the cold start (with the cold retry the feedback spent both; lm fixed). Clarabel
    finds the QP primal infeasible; the reference backend reports the same status and row.
    The recovery within the feedback is off (its re-initialised QP would be the one
    reported). lm=None: the OCP's automatic term, whose raises still follow the certificate
    (the rows do not depend on the term, but a raise moves it: docs/algorithm.md section
    10), the same in both backends and in both C solvers."""
    kw = {} if lm is None else {"lm": lm}
    c = CSolver(reach, M=1, **kw)
    cold = CSolver(reach, M=1, **kw)
    r = ReferenceDopus(reach, M=1, **kw)
    assert c.qp_warm_start
    for s in (c, r):
        s.set_recovery(False)
        s.init([0.0])
    cold.copy_state_from(c)
    cold.set_qp_warm_start(False)
    qp = r.qp_of_current([0.0])

    # an independent solver: the QP is infeasible
    status, _ = P.solve_clarabel(qp)
    assert "Infeasible" in status and "Primal" in status, status
    # the C QP solver on the same QP, warm from the runtime's warm point (a certificate the
    # runtime trusts: certified) and cold
    h = build_qp_solver(N, r.nx, r.n_u, r.ng, r.nr, r.ne)
    _, warm = h.solve(qp, tol=c.qp_tol, max_iter=c.qp_max_iter, warm=_warm_point(r, qp))
    assert warm["status"] == "primal_infeasible" and warm["certified"], warm
    _, cold_qp = h.solve(qp, tol=c.qp_tol, max_iter=c.qp_max_iter)
    assert cold_qp["status"] == "primal_infeasible", cold_qp

    infeasible = qp_status_code("primal_infeasible")
    for s in (c, cold, r):
        assert _failed_feedback(s, [0.0]).qp_status == infeasible
        assert s.qp_status == infeasible
    row = {"stage": N, "kind": "terminal", "index": 0, "side": "lower", "bound": 5.0}
    assert c.qp_infeasible_row == cold.qp_infeasible_row == r.qp_infeasible_row == row
    assert c.qp_cold_retry is False and cold.qp_cold_retry is False
    assert c.lm == cold.lm == r.lm
    if lm is not None:
        # no raise of lm follows, and no active-set start (a fixed term): the feedback's QP
        # iterations are the warm solve's alone, the copy's the cold solve's
        assert (c.qp_iterations, cold.qp_iterations) == (warm["iterations"], cold_qp["iterations"])


def test_certified_flag_of_the_qp_solver():
    """dopus_qp_info.certified on random QPs (tests/harness/qp_problems.py): set on every
    infeasible QP of the default margins (0.01 to 1 relative; Clarabel: primal infeasible),
    never on a solved QP, and not on a certificate found only after a stall (margins down to
    1e-9, tested against CERT_SEP_STALL): of those the flag marks only the ones whose
    certificate separates beyond CERT_SEP."""
    sizes = (10, 4, 2, 1, 2, 1)
    h = build_qp_solver(*sizes)
    rng = np.random.default_rng(zlib.crc32(b"certified"))
    for kind in ("row_vs_box", "terminal_eq_vs_box", "terminal_rows"):
        for _ in range(5):
            qp = P.make_infeasible(rng, *sizes, kind)
            status, _ = P.solve_clarabel(qp)
            assert "Infeasible" in status and "Primal" in status, status
            _, info = h.solve(qp, tol=1e-10)
            assert info["status"] == "primal_infeasible" and info["certified"], (kind, info)
    for _ in range(5):
        qp, _ = P.make_qp(rng, *sizes, p_active=0.3)
        _, info = h.solve(qp, tol=1e-10)
        assert info["status"] == "solved" and not info["certified"], info
    flags = set()
    for _ in range(20):
        qp = P.make_infeasible(rng, *sizes, "terminal_eq_vs_box", margin=1e-9)
        _, info = h.solve(qp, tol=1e-10)
        assert info["status"] == "primal_infeasible", info
        flags.add(info["certified"])
    assert flags == {True, False}      # both tests of the certificate occur at this margin
