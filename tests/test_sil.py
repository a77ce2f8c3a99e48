"""Closed loop on the robot arm (docs/robot_arm.md section 5): the SIL record checked
against independent numbers.

- the plant: the applied controls replayed through scipy's solve_ivp on a numpy model of the
  arm written a second time (tests/test_plant.py), events applied at the same instants;
- the signals: the tip position, the circle and the deviation recomputed in numpy;
- the controller: its first control is IPOPT's u_0 (it starts at the offline solution);
  KKT, torque bounds and QP status as the method promises them.
"""
import importlib.util
import json
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.integrate import solve_ivp

from dopus_codegen.cli import main as cli_main
from dopus_codegen.problem.derivatives import build_functions
from dopus_codegen.reference.offline import solve_ocp
from dopus_codegen.problem.ocp import Event
from dopus_codegen.studies.sil import format_summary, run_closed_loop, summarize
from test_plant import arm_rhs_numpy

DEFAULT_LM = 1e-4  # examples/robot_arm.py: options(lm=1e-4)

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "robot_arm.py"
DT = 0.01
TAU_MAX = 10.0


def _example_module():
    spec = importlib.util.spec_from_file_location("robot_arm_example_for_sil", EXAMPLE)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


ARM = _example_module()


def tip_numpy(x):
    q1, q2 = x[0], x[1]
    return np.array([0.4 * np.cos(q1) + 0.4 * np.cos(q1 + q2), 0.4 * np.sin(q1) + 0.4 * np.sin(q1 + q2)])


def circle_numpy(theta):
    return np.array([0.4 + 0.15 * np.cos(theta), 0.2 + 0.15 * np.sin(theta)])


def arm_disc(duration, events=()):
    """The robot arm with its scenario shortened, and the tip and the circle as plane signals."""
    ocp = ARM.build()
    q, theta = ocp.x_sym()[0:2], ocp.x_sym()[4]
    ocp.scenario(duration=duration, events=list(events),
                 signals={"deviation": ARM.ca.norm_2(ARM.tip(q) - ARM.path(theta)),
                          "tip": ARM.tip(q), "circle": ARM.path(theta)})
    return build_functions(ocp)


@pytest.fixture(scope="module")
def disc():
    return arm_disc(0.3)


@pytest.fixture(scope="module")
def offline(disc):
    guess, info = solve_ocp(disc, disc.x0)
    assert info["success"]
    return guess


def replay(x0, us, events=()):
    """The plant, independently: solve_ivp (DOP853, 1e-12) over each held control."""
    x = np.array(x0, dtype=float)
    xs = []
    pending = sorted(events, key=lambda e: e.time)
    for i, u in enumerate(us):
        t_i, t_next = i * DT, (i + 1) * DT
        while pending and pending[0].time <= t_i + 1e-12:
            x = pending.pop(0).fn(x)
        xs.append(x.copy())
        t = t_i
        while pending and pending[0].time < t_next - 1e-12:
            ev = pending.pop(0)
            x = solve_ivp(lambda s, y: arm_rhs_numpy(y, u), (t, ev.time), x, method="DOP853",
                          rtol=1e-12, atol=1e-12).y[:, -1]
            x = ev.fn(x)
            t = ev.time
        x = solve_ivp(lambda s, y: arm_rhs_numpy(y, u), (t, t_next), x, method="DOP853",
                      rtol=1e-12, atol=1e-12).y[:, -1]
    return np.array(xs)


def _backend_params():
    params = []
    for backend in ("reference", "c"):
        for hessian, M, cost_hessian, lm in (("exact", 39, "fresh", DEFAULT_LM), ("gauss-newton", 1, "fresh", DEFAULT_LM),
                                             ("gauss-newton", 1, "stored", DEFAULT_LM), ("exact", 1, "fresh", DEFAULT_LM),
                                             ("exact", 1, "fresh", 0.0)):
            marks = []
            if hessian == "exact" and M == 1 and lm == 0.0:
                # Measured without the Levenberg-Marquardt term: with the exact Hessian and one
                # refresh per instant the tip stays on the path but the KKT measure does not
                # settle (0.07 .. 0.5 over the whole 0.3 s, the full RTI reaches 1e-3): the stale
                # blocks carry dynamics curvature weighted by old multipliers, wrong at the
                # scale of the weakest reduced curvature; over 3 s the iteration diverges
                # (t = 2.3 s, both backends). With lm = 1e-4 it settles (the case above).
                marks.append(pytest.mark.xfail(strict=True, reason="DOPUS M = 1 with the exact Hessian and "
                                               "lm = 0: the KKT measure does not settle (see the comment)"))
            params.append(pytest.param(backend, hessian, M, cost_hessian, lm, marks=marks,
                                       id=f"{backend}-{hessian}-M{M}-{cost_hessian}-lm{lm:g}"))
    return params


def _c_available():
    try:
        from dopus_codegen.runtime.solver import CSolver  # noqa: F401
    except ImportError:
        return False
    return True


@pytest.mark.parametrize("backend, hessian, M, cost_hessian, lm", _backend_params())
def test_sil_robot_arm(disc, offline, backend, hessian, M, cost_hessian, lm):
    if backend == "c" and not _c_available():
        pytest.skip("the C backend (dopus_codegen.runtime.solver.CSolver) is not available")
    run = run_closed_loop(disc, backend=backend, M=M, hessian=hessian, cost_hessian=cost_hessian, lm=lm,
                          guess=offline)
    assert run["settings"]["cost_hessian"] == cost_hessian and run["settings"]["lm"] == lm
    assert run["aborted"] is None
    t, x, u = np.array(run["t"]), np.array(run["x"]), np.array(run["u"])
    assert len(t) == 30 and np.allclose(t, DT * np.arange(30))

    # Starting at the offline solution with the same initial state, the first QP step is zero.
    assert np.max(np.abs(u[0] - offline.u[0])) < 1e-6
    # The record is the plant: the same controls through an independent integration.
    assert np.max(np.abs(x - replay(disc.x0, u))) < 1e-6
    for name, fn in (("tip", tip_numpy), ("circle", lambda xi: circle_numpy(xi[4]))):
        assert np.max(np.abs(np.array(run["signals"][name]) - np.array([fn(xi) for xi in x]))) < 1e-12
    dev = np.array(run["signals"]["deviation"])
    assert np.max(np.abs(dev - [np.linalg.norm(tip_numpy(xi) - circle_numpy(xi[4])) for xi in x])) < 1e-12

    assert run["status"] == [0] * 30, "QP failures"
    assert np.all(u[:, :2] <= TAU_MAX + 1e-6) and np.all(u[:, :2] >= -TAU_MAX - 1e-6)
    assert np.all(u[:, 2] >= -1e-6) and np.all(u[:, 2] <= 50 + 1e-6)
    kkt = np.array(run["kkt"], dtype=float)
    assert np.all(np.isfinite(kkt))
    assert kkt[0] < 1e-8  # the offline solution, measured with the same xhat_0
    # One sampling interval later the problem has moved (KKT ~ 0.5); the iteration then
    # catches up: the KKT falls, and over the last 0.05 s it is ten times below its early peak.
    assert np.median(kkt[20:]) < np.median(kkt[1:10]), f"KKT {kkt}"
    assert np.max(kkt[25:]) < 0.1 * np.max(kkt[1:10]), f"KKT {kkt}"
    # The tip stays within 1 cm of the circle of radius 15 cm (the optimum trades some
    # deviation for progress: the full RTI reaches 7 mm while the shoulder torque saturates).
    assert np.max(dev) < 0.01
    # Stage N-1 is recomputed at every instant, plus exactly M others.
    assert all(len(r) == min(M, 39) + 1 and r[-1] == 39 for r in run["recomputed"])


def test_sil_events_and_summary():
    """Events on a sampling instant and between two instants act on the plant as declared."""
    events = [Event(0.05, ARM.disturb, "kick"), Event(0.125, ARM.disturb, "second kick")]
    d = arm_disc(0.2, events)
    guess, _ = solve_ocp(d, d.x0)
    run = run_closed_loop(d, backend="reference", M=39, guess=guess)
    x, u = np.array(run["x"]), np.array(run["u"])
    assert np.max(np.abs(x - replay(d.x0, u, events))) < 1e-6
    # The kick at 0.05 s acts before that measurement: the arm is at rest there.
    assert np.max(np.abs(x[5, 2:4])) == 0.0 and np.max(np.abs(x[4, 2:4])) > 0.1
    assert run["status"] == [0] * 20

    s = summarize(run, settle=0.03)
    dev = np.array(run["signals"]["deviation"])
    segs = {(g["signal"], g["segment"]): g for g in s["segments"]}
    for key, sl in ((("deviation", "before kick"), slice(0, 5)), (("deviation", "after kick"), slice(5, 13)),
                    (("deviation", "after second kick"), slice(13, 20))):
        assert segs[key]["max"] == pytest.approx(np.max(dev[sl]), rel=1e-12)
        assert segs[key]["rms"] == pytest.approx(np.sqrt(np.mean(dev[sl] ** 2)), rel=1e-12)
    # a signal negative when all is well keeps its sign: min, max and RMS of the values as they are
    signed = dict(run, signals=dict(run["signals"], over=list(dev - 0.02)))
    segs = {(g["signal"], g["segment"]): g for g in summarize(signed, settle=0.03)["segments"]}
    for key, sl in ((("over", "before kick"), slice(0, 5)), (("over", "after kick"), slice(5, 13))):
        assert segs[key]["max"] == pytest.approx(np.max(dev[sl] - 0.02), rel=1e-12) and segs[key]["max"] < 0
        assert segs[key]["min"] == pytest.approx(np.min(dev[sl] - 0.02), rel=1e-12)
        assert segs[key]["rms"] == pytest.approx(np.sqrt(np.mean((dev[sl] - 0.02) ** 2)), rel=1e-12)
    kkt = np.array(run["kkt"])
    settled = [i for i in range(20) if i >= 3 and not (5 <= i < 8) and not (13 <= i < 16)]
    assert s["kkt_max_settled"] == pytest.approx(np.max(kkt[settled]), rel=1e-12)
    assert s["qp_failures"] == 0
    # the table's recoveries column: the run's count of automatic re-initialisations, '-' where
    # the backend does not count them (the reference backend here)
    for count, shown in ((None, "-"), (3, "3")):
        table = format_summary([summarize(dict(run, result=dict(run["result"], recoveries=count)))]).splitlines()
        head = next(i for i, line in enumerate(table) if "recoveries" in line)
        names = [c for c in re.split(r"\s{2,}", table[head].strip())]
        values = re.split(r"\s{2,}", table[head + 2].strip())
        assert dict(zip(names, values))["recoveries"] == shown
        assert dict(zip(names, values))["QP fail"] == "0"


def test_cli_sil(tmp_path):
    out = tmp_path / "sil.json"
    plots = tmp_path / "plots"
    res = CliRunner().invoke(cli_main, ["sil", str(EXAMPLE), "--duration", "0.05", "--backend", "reference",
                                        "--compare", "full", "--json", str(out), "--plot-dir", str(plots)])
    assert res.exit_code == 0, res.output
    assert "full RTI" in res.output and str(plots.resolve()) in res.output
    runs = json.loads(out.read_text())["runs"]
    assert [r["settings"]["M"] for r in runs] == [1, 39]
    assert [r["settings"]["backend"] for r in runs] == ["reference", "reference"]
    for r in runs:
        x, u = np.array(r["x"]), np.array(r["u"])
        assert x.shape == (5, 5) and u.shape == (5, 3)
        assert np.max(np.abs(x - replay(ARM.initial_state(), u))) < 1e-6
        assert r["status"] == [0] * 5
        # the automatic lm: the setting and the value it reached, not the value as if it were the setting
        assert r["settings"]["lm_setting"] == "auto"
        assert f"{r['label']}: " in res.output and f"lm auto (now {r['settings']['lm']:g}) (default)" in \
            res.output.split(f"{r['label']}: hessian", 1)[1].splitlines()[0]
    for name in ("sil_signals.png", "sil_kkt.png", "sil_controls.png", "sil_recomputed.png", "sil_timing.png"):
        assert (plots / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_cli_sil_errors(tmp_path):
    no_scenario = tmp_path / "no_scenario.py"
    no_scenario.write_text(
        "import casadi as ca\nfrom dopus_codegen import Ocp\n\n"
        "def build():\n"
        "    ocp = Ocp('tiny')\n    x = ocp.state('x')\n    u = ocp.control('u', lb=-1, ub=1)\n"
        "    ocp.dynamics(u)\n    ocp.stage_cost(x**2 + u**2)\n    ocp.horizon(N=5, dt=0.1)\n"
        "    ocp.initial_state([1.0])\n    return ocp\n")
    res = CliRunner().invoke(cli_main, ["sil", str(no_scenario), "--backend", "reference"])
    assert res.exit_code != 0 and "no closed-loop scenario" in res.output
    assert "Traceback" not in res.output
    res = CliRunner().invoke(cli_main, ["sil", str(EXAMPLE), "--duration", "-1"])
    assert res.exit_code != 0 and "duration" in res.output


def test_a_time_unit_of_the_scenario_is_shown(tmp_path, monkeypatch):
    """scenario(units={"time": "min"}): a model whose time is in minutes (a slow process) is
    shown in minutes: the run's line, the summary's footnote, the figures' time axes."""
    from dopus_codegen.studies import plots

    ocp_file = tmp_path / "slow.py"
    ocp_file.write_text(
        "import casadi as ca\nfrom dopus_codegen import Ocp, Event\n\n"
        "def build():\n"
        "    ocp = Ocp('slow')\n    x = ocp.state('x')\n    u = ocp.control('u', lb=-1, ub=1)\n"
        "    ocp.dynamics(u - 0.1 * x)\n    ocp.stage_cost(x**2 + u**2)\n    ocp.horizon(N=5, dt=0.5)\n"
        "    ocp.initial_state([1.0])\n"
        "    ocp.scenario(duration=5.0, events=[Event(2.0, lambda x: x + 0.5, 'step')], signals={'level': x},\n"
        "                 units={'time': 'min', 'level': 'm'})\n"
        "    return ocp\n")
    labels = []

    def keep_labels(fig, path):
        labels.extend(ax.get_xlabel() for ax in fig.axes if ax.get_xlabel())
        plots.plt.close(fig)
        return path

    monkeypatch.setattr(plots, "_save", keep_labels)
    res = CliRunner().invoke(cli_main, ["sil", str(ocp_file), "--backend", "reference", "--plot-dir",
                                        str(tmp_path / "plots")])
    assert res.exit_code == 0, res.output
    assert "DOPUS M = 1: reference backend" in res.output and "5.0 min ..." in res.output
    assert "excluding the first 0.2 min after the start" in res.output
    time_axes = [label for label in labels if label.startswith("time")]
    assert time_axes and set(time_axes) == {"time [min]"}
