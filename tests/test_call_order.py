"""Calling order of feedback and prepare (docs/algorithm.md section 4, "Calling order").

One prepare per feedback that reached the QP: a second prepare (or a prepare right after
init) returns status 10 (already prepared) and changes nothing, in both modes; a second
feedback without a prepare returns status 7 (not prepared); after a failed prepare the next
prepare is a retry that does not shift again. The C runtime and the Python reference follow
the same rule with the same codes; after each rejected call both continue and their
iterates still agree (the reference is the oracle: it shifts once per instant by
construction of the test, so agreeing with it proves the C runtime did not shift twice).
"""
from __future__ import annotations

import numpy as np
import pytest

from dopus_codegen.reference.dopus import DopusError as RefError
from dopus_codegen.reference.dopus import ReferenceDopus
from dopus_codegen.runtime.solver import CSolver, DopusError

STATUS_NONFINITE_VALUE, STATUS_NOT_PREPARED, STATUS_ALREADY_PREPARED = 3, 7, 10
REF_NONFINITE = 3             # the reference raises the C codes (dopus_codegen.errors)
FIELDS = ("x", "u", "lam", "mu_g", "mu_b", "mu_bN", "mu_r", "nu")
QP_TOL = 1e-14
REL_TOL = 1e-9


def snapshot(b) -> dict:
    return {f: np.array(getattr(b, f), dtype=float) for f in FIELDS}


def assert_same_bits(a: dict, b: dict, where: str) -> None:
    for f in FIELDS:
        assert a[f].tobytes() == b[f].tobytes(), f"{where}: {f} changed"


def assert_close(c, r, where: str) -> None:
    for f in FIELDS:
        a, b = np.asarray(getattr(c, f)), np.asarray(getattr(r, f))
        if b.size:
            err = np.max(np.abs(a - b)) / max(1.0, np.max(np.abs(b)))
            assert err <= REL_TOL, f"{where}: {f} differs from the reference by {err:.2e} relative"


def rejected(backend, call, status: int) -> None:
    """``call`` raises the backend's DopusError with ``status`` and leaves the iterate as it was."""
    before = snapshot(backend)
    head = getattr(backend, "ring_head")
    with pytest.raises((DopusError, RefError)) as ei:
        call()
    assert ei.value.status == status, f"status {ei.value.status}, expected {status}: {ei.value}"
    assert backend.status == status
    assert_same_bits(before, snapshot(backend), f"rejected call (status {status})")
    assert backend.ring_head == head


@pytest.mark.parametrize("mode", ["receding", "fixed"])
def test_prepare_twice_is_refused_like_the_reference(second_disc, second_solution, mode):
    d = second_disc
    guess = second_solution[0]
    c = CSolver(d, M=1, mode=mode, qp_tol=QP_TOL)
    r = ReferenceDopus(d, M=1, mode=mode, qp_tol=QP_TOL)
    xh = np.asarray(d.disturbance(d.x0), dtype=float)
    for b in (c, r):
        b.init(d.x0, guess)
        rejected(b, b.prepare, STATUS_ALREADY_PREPARED)      # init already prepared the QP
    with pytest.raises(DopusError, match=r"unicycle: prepare: already prepared \(call feedback before "
                                         r"the next prepare\) \(status 10\)"):
        c.prepare()
    for it in range(3):
        uc, ur = c.feedback(xh), r.feedback(xh)
        assert np.max(np.abs(uc - ur)) <= REL_TOL * max(1.0, np.max(np.abs(ur)))
        for b in (c, r):
            rejected(b, lambda b=b: b.feedback(xh), STATUS_NOT_PREPARED)
            b.prepare()
            rejected(b, b.prepare, STATUS_ALREADY_PREPARED)
            rejected(b, b.prepare, STATUS_ALREADY_PREPARED)
        assert_close(c, r, f"{mode}, iteration {it}")
        assert c.recomputed == r.recomputed
        assert c.ring_head == r.ring_head == ((it + 1) % d.N if mode == "receding" else 0)
    if mode == "receding":
        xh = np.asarray(d.x0, dtype=float)
    uc, ur = c.feedback(xh), r.feedback(xh)
    assert np.max(np.abs(uc - ur)) <= REL_TOL * max(1.0, np.max(np.abs(ur)))
    assert_close(c, r, f"{mode}, after the rejected calls")


def test_failed_feedback_still_allows_one_prepare(second_disc, second_solution):
    """A feedback whose QP fails takes no step but counts for the calling order (the sampling
    instant passed: the closed loop shifts once); so does, in receding mode, a feedback whose
    measurement was rejected as non-finite."""
    d = second_disc
    c = CSolver(d, M=1, mode="receding", qp_max_iter=1)
    c.set_recovery(False)                # two failed instants would re-initialise (section 9)
    c.init(d.x0, second_solution[0])
    xh = np.asarray(d.disturbance(d.x0), dtype=float)
    with pytest.raises(DopusError) as ei:
        c.feedback(np.full(d.nx, np.nan))
    assert ei.value.status == 2
    start = snapshot(c)
    c.prepare()                          # the instant passed: its one shift
    assert c.ring_head == 1
    assert np.array_equal(c.x[:-1], start["x"][1:])
    rejected(c, c.prepare, STATUS_ALREADY_PREPARED)
    before = snapshot(c)
    with pytest.raises(DopusError, match="QP status 1") as ei:
        c.feedback(xh)                   # one interior-point iteration: not solved
    assert ei.value.status == 1
    assert_same_bits(before, snapshot(c), "failed feedback")
    c.prepare()                          # the one shift of this instant
    assert c.ring_head == 2
    assert np.array_equal(c.x[:-1], before["x"][1:])
    rejected(c, c.prepare, STATUS_ALREADY_PREPARED)


def _both_backends_and_an_overflowing_parameter(d):
    """Both backends (M = 1, receding), a measurement, the default parameters and parameters
    whose first entry (1e200) makes the stage cost overflow."""
    c = CSolver(d, M=1, mode="receding", qp_tol=QP_TOL)
    r = ReferenceDopus(d, M=1, mode="receding", qp_tol=QP_TOL)
    xh = np.asarray(d.disturbance(d.x0), dtype=float)
    p_good = np.array(d.p0, dtype=float)
    p_bad = p_good.copy()
    p_bad[:, 0] = 1e200
    return c, r, xh, p_good, p_bad


def test_retry_after_a_failed_prepare_does_not_shift_again(second_disc, second_solution):
    """A parameter of 1e200 makes the stage cost overflow, so prepare fails after its shift;
    with the parameter restored the next prepare is a retry: no second shift, and the result
    equals the reference's (which follows the same rule)."""
    d = second_disc
    c, r, xh, p_good, p_bad = _both_backends_and_an_overflowing_parameter(d)
    for b, nonfinite in ((c, STATUS_NONFINITE_VALUE), (r, REF_NONFINITE)):
        b.init(d.x0, second_solution[0])
        b.feedback(xh)
        shifted_x = np.array(b.x)[1:]
        b.set_parameters(p_bad)
        with pytest.raises((DopusError, RefError)) as ei:
            b.prepare()
        assert ei.value.status == nonfinite
        assert np.array_equal(np.array(b.x)[:-1], shifted_x)     # the shift happened once
        b.set_parameters(p_good)
        b.prepare()                                           # retry: no second shift
        assert np.array_equal(np.array(b.x)[:-1], shifted_x)
        assert b.ring_head == 1
        rejected(b, b.prepare, STATUS_ALREADY_PREPARED)
    assert_close(c, r, "after the retried prepare")
    uc, ur = c.feedback(xh), r.feedback(xh)
    assert np.max(np.abs(uc - ur)) <= REL_TOL * max(1.0, np.max(np.abs(ur)))
    assert_close(c, r, "one iteration after the retry")


def test_a_refused_feedback_after_a_failed_prepare_is_an_instant(second_disc, second_solution):
    """Prepare fails after its shift, the next feedback is refused (no prepared QP): that
    sampling instant has passed all the same, so the next prepare shifts again (ring head 2),
    and the refused feedback's measurement is the one a recovery would start from
    (docs/algorithm.md section 9); both backends alike."""
    d = second_disc
    c, r, xh, p_good, p_bad = _both_backends_and_an_overflowing_parameter(d)
    for b, nonfinite in ((c, STATUS_NONFINITE_VALUE), (r, REF_NONFINITE)):
        b.init(d.x0, second_solution[0])
        b.feedback(xh)
        x_before = np.array(b.x)
        b.set_parameters(p_bad)
        with pytest.raises((DopusError, RefError)) as ei:
            b.prepare()
        assert ei.value.status == nonfinite
        rejected(b, lambda b=b: b.feedback(xh), STATUS_NOT_PREPARED)
        b.set_parameters(p_good)
        b.prepare()                                           # the next instant: shifted again
        assert b.ring_head == 2
        assert np.array_equal(np.array(b.x)[:-2], x_before[2:])
    assert_close(c, r, "after the prepare of the next instant")
    uc, ur = c.feedback(xh), r.feedback(xh)
    assert np.max(np.abs(uc - ur)) <= REL_TOL * max(1.0, np.max(np.abs(ur)))


def test_retry_after_a_failure_in_the_middle_of_the_gradients(second_disc, second_solution):
    """The parameter of node 10 alone overflows, so prepare fails at stage 10 of its gradient
    sweep; the stages before it must keep their F_old (the retry measures rho_k against the
    same gradients as a first attempt would), so after the retry rho_k, the recomputed set
    and the iterate equal the reference's, which evaluates on copies of its slots."""
    d = second_disc
    c = CSolver(d, M=2, mode="receding", qp_tol=QP_TOL)
    r = ReferenceDopus(d, M=2, mode="receding", qp_tol=QP_TOL)
    xh = np.asarray(d.disturbance(d.x0), dtype=float)
    p_good = np.array(d.p0, dtype=float)
    for b, nonfinite in ((c, STATUS_NONFINITE_VALUE), (r, REF_NONFINITE)):
        b.init(d.x0, second_solution[0])
        b.feedback(xh)
        b.prepare()
        b.feedback(xh)                       # a second step, so that rho_k > 0 somewhere
        p_bad = p_good.copy()
        p_bad[10, 0] = 1e200
        b.set_parameters(p_bad)
        with pytest.raises((DopusError, RefError)) as ei:
            b.prepare()
        assert ei.value.status == nonfinite
        b.set_parameters(p_good)
        b.prepare()
    rc, rr = np.asarray(c.rho), np.asarray(r.rho)
    assert rr.max() > 0
    assert np.max(np.abs(rc - rr)) <= 1e-6 * max(1.0, rr.max()), (rc, rr)
    assert c.recomputed == r.recomputed
    assert_close(c, r, "after a retry that failed in stage 10")
    uc, ur = c.feedback(xh), r.feedback(xh)
    assert np.max(np.abs(uc - ur)) <= REL_TOL * max(1.0, np.max(np.abs(ur)))
