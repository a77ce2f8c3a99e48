"""bench/budget_curves.py's machinery on the chain of masses (its scenario: 20 instants).

The reference is the closed loop without a budget: a work budget of one iteration (3N + 2
units for the full RTI, 2N + 4 for M = 1) must give it bit for bit, and the search for the
needed budget must find the criterion met there. No timing is checked.
"""
import pathlib
import sys

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

import budget_curves as bc  # noqa: E402
from anytime_budget import closed_loop, figures  # noqa: E402

from dopus_codegen import build_functions, load_ocp  # noqa: E402
from dopus_codegen.reference.offline import solve_ocp  # noqa: E402


@pytest.fixture(scope="module")
def chain():
    disc = build_functions(load_ocp(ROOT / "examples" / "chain.py"))
    guess, _ = solve_ocp(disc, disc.x0)
    return disc, guess


_RUNS = {}


def run(chain, kind, budget):
    """The closed loop of one setting, each run once in this module."""
    if (kind, budget) not in _RUNS:
        _RUNS[kind, budget] = closed_loop(*chain, kind, budget)
    return _RUNS[kind, budget]


@pytest.mark.parametrize("kind", ["full", "M=1"])
def test_one_iteration_budget_is_the_plain_closed_loop(chain, kind):
    disc, guess = chain
    units = bc.costs(int(disc.N))[kind]
    plain = run(chain, kind, 0.0)
    budgeted = run(chain, kind, f"{units}u")
    assert len(plain["u"]) == len(budgeted["u"]) == 20
    np.testing.assert_array_equal(np.asarray(budgeted["u"]), np.asarray(plain["u"]))
    np.testing.assert_array_equal(np.asarray(budgeted["x"]), np.asarray(plain["x"]))
    assert budgeted["status"] == plain["status"]


def test_needed_budget_on_a_tiny_grid(chain):
    _, signal = bc.PROBLEMS["chain"]
    c = bc.costs(int(chain[0].N))
    ref = figures(run(chain, "full", 0.0), "full", 0.0, signal)
    seen = []

    def evaluate(b):
        seen.append(b)
        return figures(run(chain, "full", f"{b}u"), "full", b, signal)

    need, rows = bc.smallest(evaluate, [c["M=1"], c["full"]], ref)
    # at one full iteration the run is the reference's: the criterion holds with equality
    assert rows[c["full"]]["rms_after"] == ref["rms_after"]
    assert need is not None and need <= c["full"]
    assert bc.meets(rows[need], ref)
    assert all(not bc.meets(rows[b], ref) for b in seen if b < need)


def test_search_and_criterion():
    ref = {"rms_after": 1.0}
    seen = []

    def evaluate(b):  # met from 45 units on, and at 47 with a failed instant
        seen.append(b)
        return {"rms_after": 1.0 + 0.01 * max(0, 47 - b), "failed": int(b == 47)}

    need, rows = bc.smallest(evaluate, [40, 50, 60], ref)
    assert need == 45
    assert seen == [40, 50, 60, 41, 42, 43, 44, 45]
    assert sorted(rows) == sorted(seen)
    need, _ = bc.smallest(lambda b: {"rms_after": 2.0, "failed": 0}, [40, 50], ref)
    assert need is None
    assert bc.meets({"rms_after": 1.02, "failed": 0}, ref)
    assert not bc.meets({"rms_after": 1.0201, "failed": 0}, ref)
    assert not bc.meets({"rms_after": 0.5, "failed": 1}, ref)


def test_bisection_to_a_resolution():
    """Instruction budgets: a bisection between the last grid point that misses and the first
    that meets, down to the resolution; it returns a budget that meets, within the resolution
    of one that misses."""
    ref = {"rms_after": 1.0}
    seen = []

    def evaluate(b):  # met from 3_141_593 instructions on
        seen.append(b)
        return {"rms_after": 1.0 if b >= 3_141_593 else 1.5, "failed": 0}

    need, rows = bc.smallest(evaluate, [1_000_000, 2_000_000, 4_000_000, 8_000_000], ref, resolution=10_000)
    assert 3_141_593 <= need < 3_141_593 + 10_000
    assert bc.meets(rows[need], ref)
    assert any(need - 10_000 <= b < need and not bc.meets(rows[b], ref) for b in rows)
    assert len(seen) == 4 + 8          # the grid, then log2(2e6 / 1e4) ~ 7.6 halvings


def _envelope_brute_force(passes):
    """The robust reading by its definition: every evaluated budget B, kept if every
    evaluated budget >= B meets the criterion; the least kept, or None."""
    kept = [b for b in passes if all(passes[c] for c in passes if c >= b)]
    return min(kept) if kept else None


def test_envelope_rule_against_brute_force():
    """The robust reading of the needed budget on synthetic pass/fail data: the least
    evaluated budget from which every evaluated budget meets the criterion."""
    # the Cortex-M7 pattern of the full RTI: met at 1.521 M, a failed instant at 1.975 M
    passes = {1_422_000: False, 1_521_000: True, 1_580_000: True, 1_975_000: False, 2_370_000: True,
              3_160_000: True}
    assert bc.envelope(passes) == 2_370_000 == _envelope_brute_force(passes)
    assert bc.envelope({1: True, 2: True}) == 1
    assert bc.envelope({1: True, 2: False}) is None
    assert bc.envelope({}) is None
    rng = np.random.default_rng(24)
    for _ in range(2000):
        budgets = rng.choice(10_000, size=int(rng.integers(1, 12)), replace=False)
        passes = {int(b): bool(rng.random() < 0.7) for b in budgets}
        assert bc.envelope(passes) == _envelope_brute_force(passes)


def test_robust_reading_from_evaluated_rows():
    """The robust reading of rows a search evaluated: the criterion not monotone (a failed
    instant above the bisection's figure) moves it above the failure; it is never below the
    least budget that meets and every budget from it on meets."""
    ref = {"rms_after": 1.0}

    def evaluate(b):  # met from 3_141_593 on, except a failed instant at 6_000_000
        return {"rms_after": 1.0 if b >= 3_141_593 else 1.5, "failed": int(b == 6_000_000)}

    need, rows = bc.smallest(evaluate, [1_000_000, 2_000_000, 4_000_000, 6_000_000, 8_000_000], ref,
                             resolution=10_000)
    passes = {b: bc.meets(r, ref) for b, r in rows.items()}
    assert bc.envelope(passes) == 8_000_000 == _envelope_brute_force(passes)
    assert 3_141_593 <= need < 3_141_593 + 10_000
    del rows[6_000_000]
    assert bc.envelope({b: bc.meets(r, ref) for b, r in rows.items()}) == need


def test_fine_grid_budgets():
    """--grid START:STOP:STEP gives the budgets of the stored fine grid of
    bench/issue24/measurements.md section 15 (each budget, both settings, in its JSON), a
    sub-grid of it gives its own budgets, and a STEP that does not reach STOP is refused."""
    import json

    stored = json.loads((ROOT / "bench" / "issue24" / "m7_fine_grid_main_6caedf5.json").read_text())
    budgets = bc.grid_budgets("1.40:2.60:0.03")
    assert budgets == sorted({r["budget"] for r in stored["rows"]})
    assert [(r["budget"], r["setting"]) for r in stored["rows"]] == [(b, k) for b in budgets
                                                                     for k in ("adaptive", "full")]
    assert bc.grid_budgets("2.00:2.06:0.03") == budgets[20:23]
    for bad in ("1.40:2.60", "1.40:2.61:0.03", "1.40:2.60:0", "2.60:1.40:0.03", "a:b:c"):
        with pytest.raises(ValueError):
            bc.grid_budgets(bad)
