"""The prepare's convexity test as the feedback QP's first factorisation (docs/algorithm.md
section 10, bench/issue23/measurements.md section 45).

When the next active-set start will guess no active row, the prepare runs the automatic lm's
test in the QP's form and the feedback's QP takes that factorisation for its first sweep
(``qp_prefactored`` of the handle, ``dopus_info.qp_prefactored``). The chain of masses
(examples/chain.py) takes this path at nearly every instant of its closed loop.

- A reused factor gives the same step as a fresh factorisation: each instant, a byte copy of
  the prepared solver whose stamp a settings update cleared (one that changes no number)
  refactors; both feedbacks return bit-identical iterates, and both equal the Python
  reference backend's (which factors every QP itself) to 1e-9 relative.
- What lies between prepare and feedback: a KKT evaluation leaves the factor (its scratch is
  its own, outside the QP's memory: the feedback reuses it, its step still the fresh
  factorisation's and the reference's); a restart of the automatic term (``lm='auto'``
  again: its own test runs outside the QP's form, in scratch that may share the kept factor's
  memory) is a settings update, which clears the stamp: the feedback refactors and gives the
  fresh factorisation's step bit for bit; a
  fixed term set after the prepare is not the one the test factored: the feedback refactors
  and its step is the reference's with the same change (both QPs at tolerance 1e-14, as in
  test_chain.py: the interior point runs then).

Where the start guesses active rows (the robot arm, examples/robot_arm.py: 21 to 45 rows at
every instant), the prepare forms the start's first factorisation with the penalty weights of
the rows it will guess (``dopus_qp_prefactor_guess``), and the first sweep takes it when its own
guess has the same active rows and weights (bench/issue23/measurements.md section 49):

- the QP alone (a stored closed-loop QP of the arm, the runtime's form of warm start: primal
  step 0 but x_0, the multipliers of the solution): the solve from the kept factor equals a
  solve without it bit for bit (solution and every info field) and PIQP's solution to 1e-6;
  from a warm start with one guessed row fewer (a different working set) the kept factor is
  not taken, and the solve is the fresh one bit for bit;
- the closed loop, from the offline solution and from the disturbed state: each instant's
  feedback reuses the factor unless the prepared term lies above the cap of the predicted
  state or the last QP factorised itself more than ``DOPUS_PREFACTOR_AFTER`` times (then the
  prepare forms none; section 51), also after a KKT
  evaluation between prepare and feedback (the firmware's loop has one), bit-identical to a
  copy whose stamp a settings update cleared, and where it is reused (a convex QP: the prepared term
  passed the convexity test) its step is PIQP's on the reference backend's copy of the QP to
  1e-6; a settings update between prepare and feedback clears the stamp.
"""
from __future__ import annotations

import re

import numpy as np
import pytest

from conftest import EXAMPLES, ROOT
from dopus_codegen.problem.derivatives import build_functions
from dopus_codegen.problem.ocp import load_ocp
from dopus_codegen.reference.dopus import ReferenceDopus
from dopus_codegen.runtime.solver import CSolver
from harness import qp_problems as P
from harness.qp_harness import build_qp_solver

INSTANTS = 6
FIELDS = ("x", "u", "lam", "mu_b", "mu_bN")
REL = 1e-9
QP_TOL = 1e-14


@pytest.fixture(scope="module")
def chain():
    disc = build_functions(load_ocp(EXAMPLES / "chain.py"))
    xhat = np.array(disc.disturbance(np.array(disc.x0, dtype=float)), dtype=float)
    return disc, xhat


def cleared(s) -> None:
    """A settings update that changes no number: it clears the prepared factor's stamp (the
    feedback then factors anew)."""
    s.set_recovery(s.recovery)


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
        cleared(fresh)                     # the copy's QP factors anew
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
    reused, fresh = CSolver(disc), CSolver(disc)
    reused.copy_state_from(c)
    fresh.copy_state_from(c)
    cleared(fresh)
    c.kkt(xhat)
    r.kkt(xhat)
    for s in (c, r, reused, fresh):
        s.feedback(xhat)
    assert c.qp_prefactored and reused.qp_prefactored and not fresh.qp_prefactored
    assert c.qp_status == 0
    assert_same(iterate(c), iterate(fresh), "after kkt")
    assert_same(iterate(reused), iterate(fresh), "reused")
    assert_close(iterate(c), iterate(r), "after kkt")


def test_restarted_term_refactors(chain):
    disc, xhat = chain
    c, r = started(disc, xhat)
    fresh = CSolver(disc)
    fresh.copy_state_from(c)
    cleared(fresh)
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


# ---------------------------------------------------------------- guessed rows (robot arm)

STORED = EXAMPLES.parent / "tests" / "data" / "robot_arm_qp_M39_exact_instant36.npz"
REL_QP = 1e-6          # agreement with the independent solver (tests/test_qp.py's REL)
ARM_INSTANTS = 32      # the discrete loop's prepared term lies above the cap at 24..31


def stored_qp() -> dict:
    with np.load(STORED) as f:
        qp = {k: f[k] for k in f.files}
    for k in ("N", "nx", "nu", "ng", "nr", "ne"):
        qp[k] = int(qp[k])
    return qp


def warm_point(qp: dict, mult: dict) -> dict:
    """The runtime's warm start (dopus_qp_warm_point): primal step 0 but x_0, the multipliers
    of mult."""
    N, nx, nu = qp["N"], qp["nx"], qp["nu"]
    x = np.zeros((N + 1, nx))
    x[0] = qp["x0"]
    return {"x": x, "u": np.zeros((N, nu)), "lam": mult["lam"], "mu_b": mult["mu_b"], "mu_bN": mult["mu_bN"],
            "nu": mult["nu"]}


@pytest.mark.parametrize("rel_shift", [1e-6, 1e-4])
def test_guessed_rows_factor_kept_in_the_qp(rel_shift):
    qp = stored_qp()
    h = build_qp_solver(*(qp[k] for k in ("N", "nx", "nu", "ng", "nr", "ne")))
    status, ref = P.solve_independent(qp)
    assert status == "solved"
    shift = rel_shift * max(np.abs(qp["H"]).max(), np.abs(qp["HN"]).max())
    warm = warm_point(qp, ref)
    fresh, fresh_info = h.solve(qp, tol=1e-10, warm=warm, active_set=8, hess_shift=shift)
    assert fresh_info["status"] == "solved" and fresh_info["active_set"] > 0, fresh_info
    assert not fresh_info["prefactored"]
    assert h.prefactor_guess(warm)
    sol, info = h.solve_prefactored(warm)
    assert info["prefactored"]
    assert {k: v for k, v in info.items() if k != "prefactored"} == \
        {k: v for k, v in fresh_info.items() if k != "prefactored"}
    for k in fresh:
        assert np.array_equal(sol[k], fresh[k]), k
    # the QP with the shift against PIQP (the shift is in the QP's Hessian, hess_shift I)
    shifted = dict(qp, H=qp["H"] + shift * np.eye(qp["nx"] + qp["nu"]), HN=qp["HN"] + shift * np.eye(qp["nx"]))
    status, ref_s = P.solve_independent(shifted)
    assert status == "solved"
    err = P.compare(sol, ref_s, keys=("x", "u", "lam", "mu_b", "mu_bN", "nu"))
    assert max(err.values()) <= REL_QP, err

    # one guessed row fewer (the largest multiplier set to 0): another working set, the kept
    # factor is not taken and the solve is the fresh one from that start
    other = {k: np.array(v, copy=True) for k, v in warm.items()}
    k, j = np.unravel_index(np.argmax(np.abs(other["mu_b"])), other["mu_b"].shape)
    other["mu_b"][k, j] = 0.0
    fresh_o, fresh_o_info = h.solve(qp, tol=1e-10, warm=other, active_set=8, hess_shift=shift)
    assert h.prefactor_guess(warm)
    sol_o, info_o = h.solve_prefactored(other)
    assert not info_o["prefactored"]
    assert info_o == fresh_o_info
    for k in fresh_o:
        assert np.array_equal(sol_o[k], fresh_o[k]), k


@pytest.fixture(scope="module")
def arm(robot_disc, robot_solution):
    return robot_disc, robot_solution[0]


def capped_at_predicted_state(c) -> bool:
    """The prepared automatic term above the feedback's cap at dx_0 = 0 (docs/algorithm.md
    section 10: lm <= 1e-2 h d^2, d at least the KKT proxy)."""
    return not c.lm <= 1e-2 * c.lm_scale * c.kkt_proxy ** 2


def prefactor_after() -> int:
    """DOPUS_PREFACTOR_AFTER of runtime_c/dopus_solver.h: the prepare forms the start's
    factorisation only after a QP that factorised itself at most this many times."""
    m = re.search(r"#define DOPUS_PREFACTOR_AFTER (\d+)", (ROOT / "runtime_c" / "dopus_solver.h").read_text())
    assert m is not None
    return int(m.group(1))


@pytest.mark.parametrize("start", ["offline", "disturbed"])
def test_guessed_rows_factor_reused_in_the_closed_loop(arm, start):
    disc, guess = arm
    x0 = np.array(disc.x0, dtype=float)
    xhat = x0 if start == "offline" else np.array(disc.disturbance(x0), dtype=float)
    after = prefactor_after()
    c, r, fresh = CSolver(disc), ReferenceDopus(disc), CSolver(disc)
    for s in (c, r):
        s.init(x0, guess)
        s.feedback(xhat)
    own = c.qp_factorizations - int(bool(c.qp_prefactored))
    x = np.array(c.x[1], dtype=float, copy=True)
    reused = capped = long_fb = 0
    for k in range(ARM_INSTANTS):
        for s in (c, r):
            s.prepare()
        is_capped = capped_at_predicted_state(c)
        # the prepare forms the factorisation unless the term is capped at the predicted state
        # or the last QP factorised itself more than DOPUS_PREFACTOR_AFTER times
        expect = not is_capped and own <= after
        qp = r.qp_of_current(x)
        fresh.copy_state_from(c)
        cleared(fresh)                     # the copy's QP factors anew
        c.kkt(x)                           # leaves the prepared factor
        before = {"x": np.array(c.x, dtype=float), "u": np.array(c.u, dtype=float)}
        u_c, u_f = c.feedback(x), fresh.feedback(x)
        r.feedback(x)
        assert bool(c.qp_prefactored) == expect and not fresh.qp_prefactored, (k, own)
        reused += expect
        capped += is_capped
        long_fb += not is_capped and own > after
        assert c.qp_status == fresh.qp_status == 0, k
        assert c.qp_factorizations == fresh.qp_factorizations and c.qp_iterations == fresh.qp_iterations, k
        assert np.array_equal(u_c, u_f), k
        assert_same(iterate(c), iterate(fresh), f"instant {k}")
        own = c.qp_factorizations - int(bool(c.qp_prefactored))
        if is_capped:
            # the capped term: the QP may be convex only on its active bounds, with several
            # local minimisers (docs/algorithm.md section 4); the uncapped one passed the
            # prepare's convexity test, its solution unique
            x = np.array(c.x[1], dtype=float, copy=True)
            continue
        status, ref = P.solve_independent(qp)
        assert status == "solved", k
        step = {"x": np.array(c.x) - before["x"], "u": np.array(c.u) - before["u"], "lam": np.array(c.lam),
                "mu_b": np.array(c.mu_b), "mu_bN": np.array(c.mu_bN), "nu": np.array(c.nu)}
        err = P.compare(step, ref, keys=tuple(step))
        assert max(err.values()) <= REL_QP, (k, err)
        x = np.array(c.x[1], dtype=float, copy=True)
    # from the offline start the instants without the prepared factor are the capped stretch
    # 24..31 and those after a long feedback
    if start == "offline":
        assert reused >= ARM_INSTANTS - 8 - long_fb and capped > 0, (reused, capped, long_fb)
    else:
        # the feedback at the disturbance factorised itself more often: its prepare formed none
        assert reused >= ARM_INSTANTS // 2 and long_fb > 0, (reused, capped, long_fb)


def test_guessed_rows_settings_update_refactors(arm):
    disc, guess = arm
    x0 = np.array(disc.x0, dtype=float)
    after = prefactor_after()
    c = CSolver(disc)
    c.init(x0, guess)
    x = x0
    for _ in range(4):
        # an instant whose prepare forms the factorisation (the first feedback from the offline
        # solution factorises itself more than DOPUS_PREFACTOR_AFTER times: its prepare does not)
        c.feedback(x)
        own = c.qp_factorizations - int(bool(c.qp_prefactored))
        c.prepare()
        if own <= after and not capped_at_predicted_state(c):
            break
        x = np.array(c.x[0], dtype=float, copy=True)
    assert own <= after and not capped_at_predicted_state(c)
    reused, fresh = CSolver(disc), CSolver(disc)
    reused.copy_state_from(c)
    fresh.copy_state_from(c)
    fresh.set_qp_tol(fresh.qp_tol)         # another settings update
    cleared(c)
    x = np.array(c.x[0], dtype=float, copy=True)
    for s in (c, reused, fresh):
        s.feedback(x)
    assert reused.qp_prefactored and not c.qp_prefactored and not fresh.qp_prefactored
    assert_same(iterate(c), iterate(fresh), "settings update")
    assert_same(iterate(reused), iterate(fresh), "reused")
