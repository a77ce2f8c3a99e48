"""The prepare's convexity test as the feedback QP's first factorisation (docs/algorithm.md
section 10, bench/issue23/measurements.md section 45).

When the next active-set start will guess no active row, the prepare runs the automatic lm's
test in the QP's form and the feedback's QP takes that factorisation for its first sweep
(``qp_prefactored`` of the handle, ``dopus_info.qp_prefactored``). The chain of masses
(examples/chain.py) takes this path at nearly every instant of its closed loop.

- A reused factor gives the same step as a fresh factorisation: each instant, a byte copy of
  the prepared solver whose stamp a KKT evaluation cleared (``kkt``: its scratch shares the
  QP's memory) refactors; both feedbacks return bit-identical iterates, and both equal the
  Python reference backend's (which factors every QP itself) to 1e-9 relative.
- What lies between prepare and feedback: a KKT evaluation clears the stamp (the feedback
  refactors, its step still the reference's); a restart of the automatic term (``lm='auto'``
  again: its own test runs outside the QP's form, in scratch that may share the kept factor's
  memory) is a settings update, which clears the stamp: the feedback refactors and gives the
  fresh factorisation's step bit for bit; a
  fixed term set after the prepare is not the one the test factored: the feedback refactors
  and its step is the reference's with the same change (both QPs at tolerance 1e-14, as in
  test_chain.py: the interior point runs then).
"""
from __future__ import annotations

import numpy as np
import pytest

from conftest import EXAMPLES
from dopus_codegen.problem.derivatives import build_functions
from dopus_codegen.problem.ocp import load_ocp
from dopus_codegen.reference.dopus import ReferenceDopus
from dopus_codegen.runtime.solver import CSolver

INSTANTS = 6
FIELDS = ("x", "u", "lam", "mu_b", "mu_bN")
REL = 1e-9
QP_TOL = 1e-14


@pytest.fixture(scope="module")
def chain():
    disc = build_functions(load_ocp(EXAMPLES / "chain.py"))
    xhat = np.array(disc.disturbance(np.array(disc.x0, dtype=float)), dtype=float)
    return disc, xhat


def iterate(s) -> dict:
    return {f: np.array(getattr(s, f), dtype=float, copy=True) for f in FIELDS}


def assert_same(a: dict, b: dict, what: str) -> None:
    for f in FIELDS:
        assert np.array_equal(a[f], b[f]), f"{what}: {f} differs by {np.abs(a[f] - b[f]).max():.3e}"


def assert_close(c: dict, r: dict, what: str) -> None:
    for f in FIELDS:
        err = np.abs(c[f] - r[f]).max() / max(1.0, np.abs(r[f]).max())
        assert err <= REL, f"{what}: {f} differs from the reference by {err:.2e} relative"


def started(disc, xhat, **changes):
    """The C solver and the reference after init and one instant, prepared."""
    c, r = CSolver(disc, **changes), ReferenceDopus(disc, **changes)
    for s in (c, r):
        s.init(xhat)
        s.feedback(xhat)
        s.prepare()
    return c, r


def test_reused_factor_equals_a_fresh_factorisation(chain):
    disc, xhat = chain
    c, r = started(disc, xhat)
    fresh = CSolver(disc)
    x = xhat
    for k in range(INSTANTS):
        fresh.copy_state_from(c)
        fresh.kkt(x)                       # clears the copy's stamp: its QP factors anew
        u_c, u_f, u_r = c.feedback(x), fresh.feedback(x), r.feedback(x)
        assert c.qp_prefactored and not fresh.qp_prefactored, k
        assert c.qp_status == fresh.qp_status == 0, k
        assert c.qp_factorizations == fresh.qp_factorizations, k
        assert np.array_equal(u_c, u_f), k
        assert_same(iterate(c), iterate(fresh), f"instant {k}")
        np.testing.assert_allclose(u_c, u_r, rtol=0, atol=REL * max(1.0, np.abs(u_r).max()))
        assert_close(iterate(c), iterate(r), f"instant {k}")
        x = np.array(c.x[1], dtype=float, copy=True)   # the predicted state as the next measurement
        c.prepare()
        r.prepare()


def test_kkt_evaluation_between_prepare_and_feedback(chain):
    disc, xhat = chain
    c, r = started(disc, xhat)
    reused = CSolver(disc)
    reused.copy_state_from(c)
    c.kkt(xhat)
    r.kkt(xhat)
    c.feedback(xhat)
    r.feedback(xhat)
    reused.feedback(xhat)
    assert reused.qp_prefactored and not c.qp_prefactored
    assert c.qp_status == 0
    assert_close(iterate(c), iterate(r), "after kkt")
    assert_close(iterate(reused), iterate(r), "reused")


def test_restarted_term_refactors(chain):
    disc, xhat = chain
    c, r = started(disc, xhat)
    fresh = CSolver(disc)
    fresh.copy_state_from(c)
    fresh.kkt(xhat)
    c.set_levenberg_marquardt(0.0)
    c.set_levenberg_marquardt("auto")      # the lm module's own test, in the evaluations' scratch
    assert c.lm == fresh.lm == 0.0
    c.feedback(xhat)
    fresh.feedback(xhat)
    r.feedback(xhat)
    assert not c.qp_prefactored and not fresh.qp_prefactored
    assert_same(iterate(c), iterate(fresh), "restarted term")
    assert_close(iterate(c), iterate(r), "restarted term")


def test_changed_term_refactors(chain):
    disc, xhat = chain
    c, r = started(disc, xhat, qp_tol=QP_TOL)   # the interior point's step, to round-off
    lm = 1e-3 * max(c.lm_scale, 1.0)
    assert lm != c.lm
    for s in (c, r):
        s.set_levenberg_marquardt(lm)
        s.feedback(xhat)
    assert not c.qp_prefactored
    assert c.qp_status == 0
    assert_close(iterate(c), iterate(r), "changed term")
