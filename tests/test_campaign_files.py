"""Campaign result files you can trust: a file is resumed only under its header's fingerprint
(a damaged header or another campaign's is refused with a message naming the file, or
replaced on --overwrite); malformed lines are reported with their line numbers and their runs
computed again; a dask cluster that loses a worker re-submits its runs, and one left without
any worker stops the campaign with a message, resumable.

Every file is compared with the same runs computed in one uninterrupted in-process campaign
(bitwise, except the measured times).
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest
from click.testing import CliRunner

from conftest import ROBOT_ARM_FILE
from test_interrupt import Command

from dopus_codegen.cli import main
from dopus_codegen.studies.campaign import FORMAT, read_results

RUNS, DURATION = 3, 0.7
ARGS = [str(ROBOT_ARM_FILE), "--duration", str(DURATION), "--no-progress"]


def _campaign(out, *args, runs=RUNS):
    return CliRunner().invoke(main, ["campaign", *ARGS, "--runs", str(runs), "--out", str(out), *args])


def _stripped(path) -> dict:
    return {k: {f: v for f, v in r.items() if f != "time"} for k, r in read_results(path).lines.items()}


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """``upto(n)``: the path of a result file with runs 0..n-1, computed in this process."""
    path = tmp_path_factory.mktemp("reference") / "reference.jsonl"

    def upto(n):
        res = _campaign(path, "--workers", "0", runs=n)
        assert res.exit_code == 0, res.output
        return path
    return upto


def _damaged_header(text):
    head, rest = text.split("\n", 1)
    return head[:len(head) // 2] + "\n" + rest                    # the header cut short


def _no_header(text):
    return text.split("\n", 1)[1]                                  # the first line is a run


def _other_format(text):
    head, rest = text.split("\n", 1)
    return json.dumps(dict(json.loads(head), format=99)) + "\n" + rest


@pytest.mark.parametrize("damage, why", [
    (_damaged_header, "not JSON"),
    (_no_header, "no campaign fingerprint"),
    (_other_format, f"format 99, this version reads format {FORMAT}"),
    (lambda text: "time,deviation\n0,0.1\n", "not JSON"),
])
def test_a_damaged_header_is_refused_or_replaced_on_request(reference, tmp_path, damage, why):
    good = reference(RUNS)
    out = tmp_path / "runs.jsonl"
    out.write_text(damage(good.read_text()))
    before = out.read_text()
    res = _campaign(out, "--workers", "0")
    assert res.exit_code == 2, res.output
    assert (f"--out '{out}' cannot be resumed: its first line is not a campaign header of this version (damaged, "
            f"another file or another version: {why}); give another file, or --overwrite to start a new campaign "
            "in it") in res.output
    assert out.read_text() == before                               # nothing merged, nothing written
    res = _campaign(out, "--workers", "0", "--overwrite")
    assert res.exit_code == 0, res.output
    assert "--overwrite: a new campaign replaces it" in res.output
    assert _stripped(out) == _stripped(good)
    assert read_results(out).header == read_results(good).header


def test_another_campaigns_file_is_refused_or_replaced_on_request(reference, tmp_path):
    good = reference(RUNS)
    out = tmp_path / "runs.jsonl"
    out.write_text(good.read_text())
    res = _campaign(out, "--workers", "0", "--settle", "0.3")
    assert res.exit_code == 2, res.output
    assert f"--out '{out}' holds the runs of another campaign" in res.output and "--overwrite" in res.output
    assert out.read_text() == good.read_text()
    res = _campaign(out, "--workers", "0", "--settle", "0.3", "--overwrite")
    assert res.exit_code == 0, res.output
    header = read_results(out).header
    assert header["on_path"]["settle"] == 0.3 and header["campaign"] != read_results(good).header["campaign"]
    # the draws and the closed loops are those of the reference; only the judgement moved
    judged = {k: {f: v for f, v in r.items() if f not in ("on_path", "max_deviation")}
              for k, r in _stripped(out).items()}
    assert judged == {k: {f: v for f, v in r.items() if f not in ("on_path", "max_deviation")}
                      for k, r in _stripped(good).items()}


def test_malformed_lines_are_reported_and_computed_again(reference, tmp_path):
    good = reference(RUNS)
    lines = good.read_text().splitlines()
    run0, run1, run2 = (json.loads(t) for t in lines[1:4])
    del run0["on_path"]                         # a missing field (was: internal error (KeyError): 'on_path')
    run1["failed_instants"] = "3"               # a mistyped field
    run2["time"]["run_s"] = None
    out = tmp_path / "runs.jsonl"
    out.write_text("\n".join([lines[0], json.dumps(run0), json.dumps(run1), "[1, 2]", json.dumps(run2),
                              lines[2][:40]]))  # and a line cut short at the end
    res = _campaign(out, "--workers", "0", "--json", str(tmp_path / "report.json"))
    assert res.exit_code == 0, res.output
    assert (f"warning: '{out}' has 5 malformed lines (line 2: no field 'on_path'; line 3: field 'failed_instants' "
            "is \"3\"; line 4: not a JSON object; line 5: field 'time.run_s' is null; line 6: cut short); "
            "dropped, their runs are computed again") in res.output
    assert "3 to compute" in res.output
    assert json.loads((tmp_path / "report.json").read_text())["computed"] == RUNS
    assert _stripped(out) == _stripped(good)
    assert read_results(out).malformed == []


def _dask(*args, cwd):
    return subprocess.Popen([sys.executable, "-m", "dask", *args], cwd=cwd, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)


def test_lost_workers_are_replaced_or_the_campaign_stops_resumably(reference, tmp_path):
    """A scheduler with two workers (no nanny: a killed worker stays dead). The first worker
    killed mid-campaign: its runs go to the other one and the campaign goes on. The second
    killed: no worker is left, the campaign stops after --worker-timeout with a message and
    the finished runs in --out. A new worker, the same command: the file is complete and
    equal to the runs computed in one process."""
    runs, timeout = 30, 3.0
    sched_file = tmp_path / "scheduler.json"
    procs = [_dask("scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard", "--scheduler-file",
                   str(sched_file), cwd=tmp_path)]
    cmd = None
    try:
        def worker():
            procs.append(_dask("worker", "--scheduler-file", str(sched_file), "--nthreads", "1", "--no-nanny",
                               "--no-dashboard", cwd=tmp_path))
            return procs[-1]

        t_end = time.monotonic() + 60
        while not sched_file.exists():
            assert time.monotonic() < t_end and procs[0].poll() is None, "the dask scheduler did not start"
            time.sleep(0.05)
        time.sleep(0.2)
        address = json.loads(sched_file.read_text())["address"]
        first, second = worker(), worker()
        out = tmp_path / "runs.jsonl"
        cmd = Command(["campaign", *ARGS[:-1], "--runs", runs, "--out", out, "--scheduler", address,
                       "--worker-timeout", timeout], tmp_path)
        cmd.wait_for_line(f"campaign: {runs // 10}/{runs} runs")
        assert "on 2 dask workers" in cmd.output
        first.kill()
        cmd.wait_for_line(f"campaign: {3 * runs // 10}/{runs} runs")        # goes on with the other worker
        second.kill()
        t_kill = time.monotonic()
        rc = cmd.finish(timeout=60)
        waited = time.monotonic() - t_kill
        assert rc == 2, cmd.output
        kept = len(read_results(out).lines)
        assert 3 * runs // 10 <= kept < runs
        assert cmd.lines[-1] == (f"Error: the dask cluster has had no worker for {timeout:g} s (--worker-timeout); "
                                 f"{kept} of {runs} runs are in '{out}', the same command computes the others")
        assert timeout <= waited < 60
        assert read_results(out).malformed == []
        worker()        # the campaign waits for it to join (up to --worker-timeout)
        res = _campaign(out, "--scheduler", address, "--worker-timeout", "60", runs=runs)
        assert res.exit_code == 0, res.output
        assert f"{kept} already in '{out}', {runs - kept} to compute on " in res.output
        assert _stripped(out) == _stripped(reference(runs))
    finally:
        if cmd is not None:
            cmd.kill()
        for p in procs:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait(10)
