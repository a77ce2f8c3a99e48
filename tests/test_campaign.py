"""dopus-gen campaign: the distributed runs equal the same runs one by one in this process and
the `sil` replay of the same seed; an interrupted campaign resumed gives the same file as an
uninterrupted one; bad input gives exit code 2 and a one-line message.

Small and short: 3 runs of 0.7 s of the robot arm (run 2 of seed 0 has a push at 0.61 s; the
others' pushes fall after the end).
"""
from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import ROBOT_ARM_FILE

from dopus_codegen.cli import main

RUNS, DURATION = 3, 0.7
ARGS = [str(ROBOT_ARM_FILE), "--runs", str(RUNS), "--duration", str(DURATION), "--no-progress"]


def _lines(path):
    """The run lines of a result file without the measured times, by (seed, run)."""
    out = {}
    with open(path) as fh:
        rows = [json.loads(t) for t in fh]
    for r in rows[1:]:
        r = dict(r)
        r.pop("time")
        out[(r["seed"], r["run"])] = r
    return rows[0], out


def _campaign(*args):
    res = CliRunner().invoke(main, ["campaign", *ARGS, *args])
    return res


@pytest.fixture(scope="module")
def in_process(tmp_path_factory):
    path = tmp_path_factory.mktemp("campaign") / "one_by_one.jsonl"
    res = _campaign("--out", str(path), "--workers", "0")
    assert res.exit_code == 0, res.output
    return path


def test_two_dask_workers_equal_one_by_one_and_the_sil_replay(in_process, tmp_path):
    dist = tmp_path / "dask.jsonl"
    res = _campaign("--out", str(dist), "--workers", "2", "--json", str(tmp_path / "report.json"))
    assert res.exit_code == 0, res.output
    assert "on 2 dask workers" in res.output
    head_a, a = _lines(in_process)
    head_b, b = _lines(dist)
    assert head_a == head_b
    assert sorted(a) == [(0, i) for i in range(RUNS)]
    assert a == b       # bitwise: every draw, trajectory value and count
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["runs"] == RUNS and report["on_path"] == sum(r["on_path"] for r in a.values())

    # the same run through `dopus-gen sil --campaign-run`, judged here from its trajectory
    run = 2
    sil_json = tmp_path / "sil.json"
    res = CliRunner().invoke(main, ["sil", str(ROBOT_ARM_FILE), "--campaign-run", str(run), "--seed", "0",
                                    "--duration", str(DURATION), "--json", str(sil_json)])
    assert res.exit_code == 0, res.output
    rec = json.loads(sil_json.read_text())["runs"][0]
    line = a[(0, run)]
    assert rec["x"][-1] == line["final_x"]
    assert rec["signals"]["deviation"] == line["signal"]
    pushes = [p["time"] for p in line["draw"]["pushes"] if p["time"] < DURATION]
    assert pushes and [ev["time"] for ev in rec["events"]] == pushes
    assert rec["result"]["failed_instants"] == line["failed_instants"]
    t, dev = np.asarray(rec["t"]), np.asarray(rec["signals"]["deviation"])
    threshold, settle = report["on_path_definition"]["threshold"], report["on_path_definition"]["settle"]
    judged = t >= settle - 1e-9
    for ev in rec["events"]:
        judged &= ~((t >= ev["time"] - 1e-9) & (t < ev["time"] + settle - 1e-9))
    assert line["max_deviation"] == (float(dev[judged].max()) if judged.any() else 0.0)
    assert line["on_path"] == bool(line["max_deviation"] <= threshold)


def test_the_draws_are_deterministic_and_within_the_declared_ranges(robot_disc):
    from dopus_codegen.studies.campaign import draw

    sc = robot_disc.scenario.closed_loop
    cs = sc.campaign
    mismatch = dict(cs.mismatch)
    seen = []
    for i in range(200):
        d = draw(sc, mismatch, i, 7)
        assert d == draw(sc, mismatch, i, 7)
        seen.append(d)
        for name, nominal in sc.quantities.items():
            r = mismatch.get(name, 0.0)
            assert abs(d["quantities"][name] / nominal - 1) <= r
        dx = np.asarray(d["x0"]) - np.asarray(sc.x0)
        bound = np.zeros(dx.size)
        for rows, widths in cs.initial:
            bound[list(rows)] = widths
        assert np.all(np.abs(dx) <= bound)
        assert cs.push_count[0] <= len(d["pushes"]) <= cs.push_count[1]
        for p in d["pushes"]:
            assert cs.push_window[0] <= p["time"] <= cs.push_window[1]
    m1 = np.array([d["quantities"]["m1"] for d in seen])
    assert m1.min() < 0.93 and m1.max() > 1.07        # the draws fill the +-10 % range
    assert draw(sc, mismatch, 0, 8) != seen[0]


def test_an_interrupted_campaign_resumed_gives_the_same_file(in_process, tmp_path, monkeypatch):
    from dopus_codegen.studies import campaign

    out = tmp_path / "resumed.jsonl"
    real, calls = campaign.run_one, []

    def interrupted(job, index, seed):
        if len(calls) == 2:
            raise KeyboardInterrupt
        calls.append(index)
        return real(job, index, seed)

    monkeypatch.setattr(campaign, "run_one", interrupted)
    with pytest.raises(KeyboardInterrupt):
        campaign.run_campaign(str(ROBOT_ARM_FILE), str(out), workers=0, runs=RUNS, duration=DURATION,
                              progress=False, echo=lambda *a, **k: None)
    monkeypatch.setattr(campaign, "run_one", real)
    assert len(out.read_text().splitlines()) == 1 + 2        # the header and the two finished runs
    with open(out, "a") as fh:                               # a line cut short by the interruption
        fh.write('{"run": 2, "seed": 0, "draw": {"quanti')
    rep = campaign.run_campaign(str(ROBOT_ARM_FILE), str(out), workers=0, runs=RUNS, duration=DURATION,
                                progress=False, echo=lambda *a, **k: None)
    assert rep["computed"] == RUNS - 2
    assert _lines(out) == _lines(in_process)
    # nothing left to do: the file stays as it is
    before = out.read_text()
    rep = campaign.run_campaign(str(ROBOT_ARM_FILE), str(out), workers=0, runs=RUNS, duration=DURATION,
                                progress=False, echo=lambda *a, **k: None)
    assert rep["computed"] == 0 and out.read_text() == before


@pytest.mark.parametrize("args, message", [
    (["--runs", "0"], "runs must be an integer >= 1"),
    (["--runs", "-3"], "runs must be an integer >= 1"),
    (["--scheduler", "tcp://127.0.0.1:9"], "cannot reach the dask scheduler at 'tcp://127.0.0.1:9'"),
    (["--out", "/proc/campaign.jsonl"], "--out '/proc/campaign.jsonl': cannot write"),
    (["--out", "/"], "is a directory"),
    (["--mismatch", "m3=0.1"], "'m3' is not a plant quantity"),
    (["--mismatch", "m1=1.5"], "[0, 1)"),
    (["--workers", "-1"], "--workers must be >= 0"),
])
def test_bad_input_exit_2_with_a_message(tmp_path, args, message):
    if "--out" not in args:
        args = ["--out", str(tmp_path / "c.jsonl"), *args]
    res = CliRunner().invoke(main, ["campaign", str(ROBOT_ARM_FILE), *args])
    assert res.exit_code == 2, res.output
    assert message in res.output
    assert "Traceback" not in res.output
    assert not (tmp_path / "c.jsonl").exists() or "--out" in args[2:]


def test_a_result_file_of_another_campaign_is_refused(in_process, tmp_path):
    other = tmp_path / "other.jsonl"
    other.write_text(in_process.read_text())
    res = _campaign("--out", str(other), "--workers", "0", "--settle", "0.3")
    assert res.exit_code == 2
    assert "holds the runs of another campaign" in res.output
    assert other.read_text() == in_process.read_text()


def test_the_on_path_signal_and_the_plant_are_checked_by_the_campaign(tmp_path):
    """What depends on the scenario as finally declared is checked when the campaign starts."""
    text = ROBOT_ARM_FILE.read_text()
    for old, new, message in [
            ('signal="deviation"', 'signal="tip"', "the signal 'tip' must be a scalar"),
            ('signal="deviation"', 'signal="speed"', "'speed' is not a signal of the scenario"),
            ("plant=plant,", "plant=None,", "the scenario's plant does not use the plant quantities")]:
        assert old in text
        f = tmp_path / "arm.py"
        f.write_text(text.replace(old, new))
        res = CliRunner().invoke(main, ["campaign", str(f), "--out", str(tmp_path / "c.jsonl")])
        assert res.exit_code == 2, res.output
        assert message in res.output


def test_the_campaign_declaration_is_checked():
    import casadi as ca

    from dopus_codegen import OcpError, OnPath, Pushes, load_ocp

    ocp = load_ocp(ROBOT_ARM_FILE)
    with pytest.raises(OcpError, match="'mass' is not a plant quantity"):
        ocp.campaign(mismatch={"mass": 0.1})
        ocp.validate()
    with pytest.raises(OcpError, match="'speed' is not a state"):
        ocp.campaign(initial={"speed": 0.1})
        ocp.validate()
    with pytest.raises(OcpError, match="threshold must be > 0"):
        ocp.campaign(on_path=OnPath("deviation", 0.0, 0.1))
        ocp.validate()
    with pytest.raises(OcpError, match="window must satisfy"):
        ocp.campaign(pushes=Pushes(count=1, window=(0.5, 0.2), kick={"dq": 1.0}))
        ocp.validate()
    with pytest.raises(OcpError, match="duplicate name"):
        ocp.plant_quantity("m1", 2.0)
    q = ocp.plant_quantity("k", 3.0)
    with pytest.raises(OcpError, match="may only depend on|not a declared"):
        ocp.dynamics(ca.vertcat(*[q] * 5))         # a plant quantity is not part of the model
        ocp.validate()


def test_sil_and_campaign_apply_the_same_controls_through_failures(tmp_path, monkeypatch):
    """One closed-loop instant: with a QP iteration limit that fails many feedbacks, the
    campaign's runs and their `sil --campaign-run` replays apply the same controls, bit for
    bit, failed instants included (both apply the runtime's returned control whatever the
    status: after a failure its safe control)."""
    from dopus_codegen.studies import campaign

    captured, real = {}, campaign.condense

    def keep(run, d, index, seed, *args):
        captured[index] = run
        return real(run, d, index, seed, *args)

    monkeypatch.setattr(campaign, "condense", keep)
    campaign.run_campaign(str(ROBOT_ARM_FILE), str(tmp_path / "c.jsonl"), workers=0, runs=2, duration=0.3,
                          qp_max_iter=1, progress=False, echo=lambda *a, **k: None)
    monkeypatch.undo()
    failed = 0
    for index, run in sorted(captured.items()):
        out = tmp_path / f"sil{index}.json"
        res = CliRunner().invoke(main, ["sil", str(ROBOT_ARM_FILE), "--campaign-run", str(index), "--seed", "0",
                                        "--duration", "0.3", "--qp-max-iter", "1", "--json", str(out)])
        assert res.exit_code == 0, res.output
        rec = json.loads(out.read_text())["runs"][0]
        assert rec["status"] == run["status"]
        np.testing.assert_array_equal(np.array(rec["u"]), np.array(run["u"]))
        failed += sum(1 for st in run["status"] if st != 0)
    assert failed > 0, "the QP iteration limit failed no feedback: the test sees no failure"


def test_a_signed_on_path_signal_keeps_its_sign(in_process, tmp_path):
    """OnPath asks the signal to stay at or below the threshold, with its sign: the robot arm
    with the signal 'over' = deviation - 2 cm (negative while the tip is within 2 cm) and the
    threshold 1 mm puts on the path the runs whose deviation stays at or below 2.1 cm, with
    the largest 'over' equal to the largest deviation - 2 cm (judged by its absolute value,
    no run was on the path: that asks 1.9 cm <= deviation <= 2.1 cm)."""
    text = ROBOT_ARM_FILE.read_text()
    old_signal = 'signals={"deviation": ca.norm_2(tip(q) - path(theta)),'
    old_on_path = 'on_path=OnPath(signal="deviation", threshold=0.02, settle=0.4)'
    assert old_signal in text and old_on_path in text
    ocp_file = tmp_path / "robot_arm_over.py"
    ocp_file.write_text(text.replace(old_signal, old_signal + ' "over": ca.norm_2(tip(q) - path(theta)) - 0.02,')
                        .replace(old_on_path, 'on_path=OnPath(signal="over", threshold=0.001, settle=0.4)'))
    out = tmp_path / "over.jsonl"
    res = CliRunner().invoke(main, ["campaign", str(ocp_file), *ARGS[1:], "--out", str(out), "--workers", "0"])
    assert res.exit_code == 0, res.output
    _, ref = _lines(in_process)
    _, over = _lines(out)
    assert sorted(over) == sorted(ref)
    for key, r in over.items():
        assert r["on_path"] == (ref[key]["aborted"] is None and ref[key]["max_deviation"] <= 0.021)
        assert r["max_deviation"] == pytest.approx(ref[key]["max_deviation"] - 0.02, abs=1e-15)
        assert r["max_deviation"] < 0 and r["signal"] == pytest.approx(np.asarray(ref[key]["signal"]) - 0.02,
                                                                       abs=1e-15)
    assert sum(r["on_path"] for r in over.values()) == RUNS
