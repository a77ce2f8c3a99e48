"""The OCP file's scenario on the emulated Cortex-M7 (double): the firmware program's
`scenario` command (dopus_lab.firmware.run_scenario), which bench/budget_curves.py --parts m7
runs at a grid of instruction budgets.

The chain of masses (its scenario: 20 instants, the shake at 1 s). References:

- without a budget, the closed loop of the C runtime through Python (the host's build of
  the runtime, the scenario's event by its Python function, the model's discrete map
  ``stage_eval`` as the plant): the same states and controls to 1e-9 relative (the emulated
  build differs from the host's only in newlib's maths library, tests/test_firmware.py);
- with a budget of many iterations per instant, the extra iterations converge every instant
  at the predicted state: the host's closed loop with a work budget of 1e9 units converges
  to the same points (KKT proxy below anytime_tol = 1e-8), so the trajectories agree to the
  accuracy of that convergence;
- with a budget above the least an instant costs, no instant exceeds it by more than one
  stage's re-linearisation (docs/algorithm.md section 14).
"""
import os
from pathlib import Path

import numpy as np
import pytest

from dopus_lab import firmware as fwm

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def chain():
    from dopus_codegen import build_functions, load_ocp
    from dopus_codegen.reference.offline import solve_ocp

    disc = build_functions(load_ocp(ROOT / "examples" / "chain.py"))
    guess, _ = solve_ocp(disc, disc.x0)
    return disc, guess


@pytest.fixture(scope="module")
def image(chain, tmp_path_factory):
    missing = fwm.setup_toolchain()
    if missing:
        if os.geteuid() == 0:
            pytest.fail(f"scripts/setup_firmware.sh ran as root and {missing} are still missing")
        pytest.skip(f"firmware toolchain not installed and not root: missing {missing}")
    return fwm.scenario_image(chain[0], tmp_path_factory.mktemp("scenario"), progress=lambda *_: None)


_RUNS = {}


def emulated(image, setting, instructions):
    if (setting, instructions) not in _RUNS:
        _RUNS[setting, instructions] = fwm.run_scenario(image, setting, instructions)
    return _RUNS[setting, instructions]


def host_loop(chain, setting, work=None):
    """The scenario's closed loop with the C runtime through Python and the model as plant."""
    from dopus_codegen.runtime.solver import CSolver

    disc, guess = chain
    s = CSolver(disc, M=int(disc.N) - 1 if setting == "full" else 1)
    if setting == "adaptive":
        s.set_M_adaptive(True, 1, 10)
    if work is not None:
        s.set_work_budget(work)
    sc = fwm.scenario_of(disc)
    ev = disc.scenario.closed_loop.events[0]
    p = np.zeros(int(disc.np))
    x = np.asarray(disc.x0, dtype=float).copy()
    s.init(x, guess)
    xs, us = [], []
    for k in range(sc["steps"]):
        if k == sc["event_step"]:
            x = np.asarray(ev.fn(x.copy()), dtype=float)
        u = s.feedback(x)
        xs.append(x.copy())
        us.append(np.array(u, dtype=float))
        x = np.asarray(disc.stage_eval(x, u, p)[0], dtype=float).reshape(-1)
        s.prepare()
    return np.array(xs), np.array(us)


def test_scenario_is_the_ocp_files(chain):
    disc, _ = chain
    sc = fwm.scenario_of(disc)
    assert sc["steps"] == 20 and sc["event_step"] == 10
    x = np.random.default_rng(1).normal(size=int(disc.nx))
    ev = disc.scenario.closed_loop.events[0]
    np.testing.assert_array_equal(np.array(sc["scale"]) * x + np.array(sc["shift"]), ev.fn(x.copy()))


def test_an_event_of_another_kind_is_refused():
    from dopus_codegen import Event

    with pytest.raises(fwm.FirmwareError, match="scale .* x \\+ shift"):
        fwm.event_map(Event(1.0, lambda x: x ** 2, "square"), 3)
    with pytest.raises(fwm.FirmwareError, match="scale .* x \\+ shift"):
        fwm.event_map(Event(1.0, lambda x: x[::-1].copy(), "swap"), 3)


@pytest.mark.parametrize("setting", ["full", "adaptive"])
def test_emulated_scenario_is_the_host_closed_loop(chain, image, setting):
    recs = emulated(image, setting, 0)
    xs, us = host_loop(chain, setting)
    x_fw = np.array([r["xhat"] for r in recs])
    u_fw = np.array([r["u0"] for r in recs])
    assert all(r["status"] == 0 for r in recs)
    assert np.max(np.abs(x_fw - xs)) <= 1e-9 * np.max(np.abs(xs))
    assert np.max(np.abs(u_fw - us)) <= 1e-9 * max(1.0, np.max(np.abs(us)))


def test_large_budget_converges_like_the_host(chain, image):
    """Budget 20 full iterations per instant: every instant converges at its predicted state
    (the extra iterations stop on the KKT proxy, not the budget) as the host does with 1e9
    work units; the closed loops then agree to the convergence tolerance."""
    full = emulated(image, "full", 0)
    big = 20 * int(np.median([r["instructions_instant"] for r in full]))
    recs = emulated(image, "M=1", big)
    xs, us = host_loop(chain, "M=1", work=1e9)
    assert all(r["status"] == 0 for r in recs)
    assert max(r["instructions_instant"] for r in recs) < big / 2    # stopped by the tolerance
    assert sum(r["extra"] for r in recs) >= len(recs)
    x_fw = np.array([r["xhat"] for r in recs])
    u_fw = np.array([r["u0"] for r in recs])
    assert np.max(np.abs(x_fw - xs)) <= 1e-6 * np.max(np.abs(xs))
    assert np.max(np.abs(u_fw - us)) <= 1e-6 * max(1.0, np.max(np.abs(us)))


@pytest.mark.parametrize("setting, fraction", [("adaptive", None), ("M=1", 0.5), ("adaptive", 0.8),
                                              ("full", 1.5), ("M=1", 3.0)])
def test_budget_bounds_every_instant(chain, image, setting, fraction):
    """The bound of a time budget on the instruction clock, counted independently of the
    solver (the board's timer around feedback and prepare): no instant above the budget plus
    one stage's re-linearisation (its instructions: the full RTI's minus M = 1's, over the N - 2
    stages the full RTI adds), from about the least an instant costs (half the full RTI's
    median instant: the QP, step 3, the stage-cost Hessians and the lm test of prepare) to
    several iterations per instant. fraction None: halfway between one M = 1 and one full
    iteration, where extra stages are spent."""
    N = int(chain[0].N)
    med = {s: np.median([r["instructions_instant"] for r in emulated(image, s, 0)]) for s in ("full", "M=1")}
    stage = (med["full"] - med["M=1"]) / (N - 2)
    budget = int(0.5 * (med["full"] + med["M=1"]) if fraction is None else fraction * med["full"])
    recs = emulated(image, setting, budget)
    used = [r["instructions_instant"] for r in recs]
    print(f"{setting}, budget {budget}: largest instant {max(used)} (budget + {max(used) - budget}, "
          f"a stage {stage:.0f}), median {np.median(used):.0f}")
    assert max(used) <= budget + stage, (max(used), budget, stage)
    assert all(r["status"] == 0 for r in recs)
    if fraction is None:
        assert max(r["stages"] for r in recs) > 1          # the budget was spent on stages


# ---- the robot arm: the bound around its disturbance --------------------------------------

ARM_STEPS = 130      # the disturbance at instant 100 and the 30 instants after it


@pytest.fixture(scope="module")
def arm_image(tmp_path_factory):
    from dopus_codegen import build_functions, load_ocp

    missing = fwm.setup_toolchain()
    if missing:
        if os.geteuid() == 0:
            pytest.fail(f"scripts/setup_firmware.sh ran as root and {missing} are still missing")
        pytest.skip(f"firmware toolchain not installed and not root: missing {missing}")
    disc = build_functions(load_ocp(ROOT / "examples" / "robot_arm.py"))
    img = fwm.scenario_image(disc, tmp_path_factory.mktemp("arm"), progress=lambda *_: None, steps=ARM_STEPS)
    return disc, img


def test_robot_arm_scenario_can_be_shortened(arm_image):
    disc, img = arm_image
    sc = fwm.scenario_of(disc)
    assert img["scenario"]["steps"] == ARM_STEPS and img["scenario"]["event_step"] == sc["event_step"] == 100
    with pytest.raises(fwm.FirmwareError, match="steps: expected an integer from 1"):
        fwm.scenario_image(disc, "unused", steps=sc["steps"] + 1)


@pytest.mark.parametrize("setting, budget", [("full", 3_400_000), ("M=1", 3_200_000)])
def test_robot_arm_budget_bounds_the_disturbance(arm_image, setting, budget):
    """The robot arm's disturbance on the emulated Cortex-M7 (docs/algorithm.md section 14,
    "a bounded worst case"): with a budget of about one and a half full-RTI instants, no
    instant of the run, the disturbance's QP and the 30 instants after it included, goes past
    the budget plus one stage evaluation (priced as above: the full RTI's median instant less
    M = 1's, without a budget, over the N - 2 stages the full RTI adds), counted on the
    board's timer around feedback and prepare (instructions, deterministic). Before the
    least prepare was priced by its parts, the full RTI's disturbance instant went 95 k over
    3.4 M and M = 1's extra iterations 43 k over 3.2 M (a stage: 17 k)."""
    disc, img = arm_image
    runs = {s: fwm.run_scenario(img, s, 0) for s in ("full", "M=1")}
    med = {s: np.median([r["instructions_instant"] for r in recs]) for s, recs in runs.items()}
    stage = (med["full"] - med["M=1"]) / (int(disc.N) - 2)
    recs = fwm.run_scenario(img, setting, budget)
    used = [r["instructions_instant"] for r in recs]
    event = img["scenario"]["event_step"]
    print(f"{setting}, budget {budget}: largest instant {max(used)} at {int(np.argmax(used))} "
          f"(budget + {max(used) - budget}, a stage {stage:.0f}), after the disturbance "
          f"{max(used[event:])}, median {np.median(used):.0f}")
    assert 10e3 < stage < 40e3                       # one stage's blocks, as measured without a budget
    assert max(used) <= budget + stage, (max(used), budget, stage)
    assert all(r["status"] == 0 for r in recs)
    # without the budget the disturbance's instant passes it: the budget is what bounds it
    assert max(r["instructions_instant"] for r in runs[setting][event:]) > budget + stage


def test_robot_arm_below_the_active_set_start_cuts_to_interior_point_steps(arm_image):
    """Adaptive M at 1.8 M instructions per instant, below the budget its feedback QPs' active-
    set start needs (docs/algorithm.md section 14): where the deadline leaves room for a few QP
    iterations but not the start's most sweeps, the QP runs the interior point alone and the
    deadline cuts it (qp_status 7) at an iterate that is the step (flag DOPUS_FLAG_QP_CUT,
    status OK). No instant of the run fails, the disturbance and the 30 instants after it
    included; before, the start cut short left its warm start, the disturbance's feedback
    failed and the loop fell into a cycle of re-initialisations (bench/issue24/measurements.md
    section 9). Every instant stays within the budget plus one stage evaluation."""
    disc, img = arm_image
    budget = 1_800_000
    recs = fwm.run_scenario(img, "adaptive", budget)
    used = [r["instructions_instant"] for r in recs]
    cut = [r for r in recs if r["qp_status"] == 7]
    print(f"adaptive, budget {budget}: largest instant {max(used)}, QPs cut {len(cut)} of {len(recs)}, "
          f"statuses {sorted(set(r['status'] for r in recs))}")
    assert all(r["status"] == 0 for r in recs)
    assert len(cut) > len(recs) // 2 and all(r["flags"] & 256 for r in cut)
    assert max(used) <= budget + 40e3
