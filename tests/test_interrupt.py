"""Ctrl-C (SIGINT) stops every verb with exit code 130 and the line ``interrupted``, never
reported as a failure of the solver or the plant, and leaves no half-written file.

Each test starts ``dopus-gen`` in its own process group and, once the command is busy (a
marker: a line of its progress output, or a file), sends SIGINT to the whole group, as a
terminal's Ctrl-C does. CasADi catches a Ctrl-C inside IPOPT and CVODES and reports it as a
failure of its computation (IPOPT's ``NonIpopt_Exception_Thrown``, a ``RuntimeError`` of the
integrator): ``generate`` interrupted inside its offline IPOPT solve must not say "did not
converge", a campaign must not record the interrupted run as a run that left the path.

The recorded runs of an interrupted campaign are compared with the same runs computed without
interruption (bitwise, except their measured times).
"""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from conftest import EXAMPLES, ROBOT_ARM_FILE

from dopus_codegen.cli import main
from dopus_codegen.studies.campaign import read_results

RUNS, DURATION = 60, 0.7       # the campaign: 60 short runs, about 5 s in one process


class Command:
    """``dopus-gen ARGS`` in a new process group; its stdout and stderr, line by line."""

    def __init__(self, args, cwd):
        self.proc = subprocess.Popen([sys.executable, "-m", "dopus_codegen.cli", *map(str, args)], cwd=cwd,
                                     stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                     start_new_session=True)
        self.lines = []
        self.reader = threading.Thread(target=self._read, daemon=True)
        self.reader.start()

    def _read(self):
        for line in self.proc.stdout:
            self.lines.append(line.rstrip("\n"))

    @property
    def output(self) -> str:
        return "\n".join(self.lines)

    def wait_for(self, ready, timeout=120.0):
        """Poll ``ready()`` until it holds; fails if the command ends first."""
        t_end = time.monotonic() + timeout
        while not ready():
            assert self.proc.poll() is None, f"the command ended before the marker:\n{self.output}"
            assert time.monotonic() < t_end, f"no marker after {timeout} s:\n{self.output}"
            time.sleep(0.01)

    def wait_for_line(self, text, timeout=120.0):
        self.wait_for(lambda: any(text in line for line in self.lines), timeout)

    def signal(self, sig):
        os.killpg(self.proc.pid, sig)

    def finish(self, timeout=120.0) -> int:
        try:
            rc = self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            raise AssertionError(f"the command did not end within {timeout} s:\n{self.output}") from None
        self.reader.join(timeout)
        return rc

    def group_gone(self, timeout=30.0) -> bool:
        """True once no process of the group is left (dask's workers included)."""
        t_end = time.monotonic() + timeout
        while time.monotonic() < t_end:
            try:
                os.killpg(self.proc.pid, 0)
            except ProcessLookupError:
                return True
            time.sleep(0.05)
        return False

    def kill(self):
        if self.proc.poll() is None or not self.group_gone(0):
            try:
                self.signal(signal.SIGKILL)
            except ProcessLookupError:
                pass


def _assert_interrupted(cmd, rc):
    assert rc == 130, cmd.output
    assert cmd.lines[-1].startswith("interrupted"), cmd.output
    assert "Traceback" not in cmd.output and "Error:" not in cmd.output, cmd.output


def _stripped(lines: dict) -> dict:
    return {k: {f: v for f, v in r.items() if f != "time"} for k, r in lines.items()}


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    """The campaign's runs computed in this process without interruption; ``upto(n)``: the
    runs 0..n-1 (computed on demand by resuming the same file)."""
    path = tmp_path_factory.mktemp("reference") / "reference.jsonl"

    def upto(n):
        res = CliRunner().invoke(main, ["campaign", str(ROBOT_ARM_FILE), "--runs", str(n), "--duration",
                                        str(DURATION), "--no-progress", "--workers", "0", "--out", str(path)])
        assert res.exit_code == 0, res.output
        return _stripped(read_results(path).lines)
    return upto


def _check_campaign_file(cmd, out, uninterrupted):
    """The result file of an interrupted campaign: its header, then only complete runs (no
    malformed line, none aborted), each equal to the same run computed without
    interruption; as many as the message says."""
    res = read_results(out)
    assert res.header is not None and res.malformed == []
    lines = res.lines
    assert 0 < len(lines) < RUNS
    assert f"interrupted: {len(lines)} of {RUNS} runs are in '{out}'" in cmd.lines[-1]
    for r in lines.values():
        assert r["aborted"] is None and r["instants"] == r["instants_planned"], r
    ref = uninterrupted(max(i for _, i in lines) + 1)
    assert _stripped(lines) == {k: ref[k] for k in lines}
    # the same command computes the others
    assert "the same command computes the others" in cmd.lines[-1]


def test_campaign_in_process(tmp_path, uninterrupted):
    out = tmp_path / "runs.jsonl"
    cmd = Command(["campaign", ROBOT_ARM_FILE, "--runs", RUNS, "--duration", DURATION, "--workers", "0",
                   "--out", out, "--json", tmp_path / "report.json", "--plot-dir", tmp_path / "plots"], tmp_path)
    try:
        cmd.wait_for_line(f"campaign: {RUNS // 10}/{RUNS} runs")     # the progress line of the first tenth
        cmd.signal(signal.SIGINT)
        rc = cmd.finish()
    finally:
        cmd.kill()
    _assert_interrupted(cmd, rc)
    _check_campaign_file(cmd, out, uninterrupted)
    assert not (tmp_path / "report.json").exists() and not (tmp_path / "plots").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["runs.jsonl"]      # no temporary file left


def test_campaign_on_dask_workers(tmp_path, uninterrupted):
    """Ctrl-C reaches the local cluster's worker processes too (the same process group):
    they leave it to the campaign, which stops them; no process is left."""
    out = tmp_path / "runs.jsonl"
    cmd = Command(["campaign", ROBOT_ARM_FILE, "--runs", RUNS, "--duration", DURATION, "--workers", "2",
                   "--out", out], tmp_path)
    try:
        cmd.wait_for_line(f"campaign: {RUNS // 10}/{RUNS} runs")
        cmd.signal(signal.SIGINT)
        rc = cmd.finish()
        assert cmd.group_gone(), "dask's processes are still running after the campaign ended"
    finally:
        cmd.kill()
    _assert_interrupted(cmd, rc)
    _check_campaign_file(cmd, out, uninterrupted)


#: Appended to an OCP file: a thread that stops the process (SIGSTOP) once its main thread
#: is inside CasADi's call of the offline IPOPT solver, after writing the marker file; the
#: test then sends Ctrl-C and continues the process, so the interrupt arrives inside IPOPT.
STOP_INSIDE_IPOPT = '''

def _stop_inside_ipopt(marker):
    import linecache, os, signal, sys, threading, time

    main = threading.main_thread().ident

    def inside_ipopt():
        f = sys._current_frames().get(main)
        if f is None or "casadi" not in f.f_code.co_filename:
            return False
        while f is not None and "casadi" in f.f_code.co_filename:
            f = f.f_back
        return (f is not None and f.f_code.co_name == "solve_ocp"
                and "= solver(" in linecache.getline(f.f_code.co_filename, f.f_lineno))

    def watch():
        while not inside_ipopt():
            time.sleep(0.0005)
        open(marker, "w").close()
        os.kill(os.getpid(), signal.SIGSTOP)

    threading.Thread(target=watch, daemon=True).start()


_build = build


def build():
    _stop_inside_ipopt(MARKER)
    return _build()
'''


def _stopped(pid) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] == "T"
    except OSError:
        return False


def test_generate_inside_the_offline_ipopt_solve(tmp_path):
    """Ctrl-C inside IPOPT (the offline guess of ``generate``): 'interrupted', not 'the
    IPOPT solve at x0 did not converge' (exit 2, as if the OCP were bad), and no folder."""
    text = (EXAMPLES / "unicycle.py").read_text()
    assert "N, DT = 20, 0.1" in text
    marker = tmp_path / "in_ipopt"
    ocp_file = tmp_path / "long_unicycle.py"
    ocp_file.write_text(text.replace("N, DT = 20, 0.1", "N, DT = 300, 0.1") + f"\nMARKER = {str(marker)!r}\n"
                        + STOP_INSIDE_IPOPT)
    out = tmp_path / "generated"
    cmd = Command(["generate", ocp_file, "-o", out, "--offline-guess"], tmp_path)
    try:
        cmd.wait_for(lambda: marker.exists() and _stopped(cmd.proc.pid))
        cmd.signal(signal.SIGINT)
        cmd.signal(signal.SIGCONT)
        rc = cmd.finish()
    finally:
        cmd.kill()
    _assert_interrupted(cmd, rc)
    assert "KeyboardInterruptException" in cmd.output       # CasADi: the interrupt arrived inside IPOPT
    assert "did not converge" not in cmd.output
    assert not out.exists()


def _complete_png(path: Path) -> bool:
    data = path.read_bytes()
    return data.startswith(b"\x89PNG\r\n\x1a\n") and data.endswith(b"IEND\xaeB`\x82")


@pytest.mark.parametrize("when", ["during the closed loop", "while the figures are written"])
def test_sil(tmp_path, when):
    """Early: no run is reported aborted (the plant 'failed' by the interrupt) and no JSON is
    written; late (the JSON written, the figures being drawn): the JSON is whole, every
    figure on disk is whole, no temporary file is left."""
    json_out, plots = tmp_path / "sil.json", tmp_path / "plots"
    # early: a closed loop long enough (20 s of plant time, some seconds of wall time) that the
    # interrupt surely lands in it on an idle machine too; late: a short one, to reach the figures
    duration = "20" if when == "during the closed loop" else "1.5"
    cmd = Command(["sil", ROBOT_ARM_FILE, "--compare", "full", "--duration", duration, "--json", json_out,
                   "--plot-dir", plots], tmp_path)
    try:
        cmd.wait_for_line("DOPUS M = 1: c backend" if when == "during the closed loop" else "JSON: ")
        cmd.signal(signal.SIGINT)
        rc = cmd.finish()
    finally:
        cmd.kill()
    _assert_interrupted(cmd, rc)
    assert "ABORTED" not in cmd.output and "plant failed" not in cmd.output
    if when == "during the closed loop":
        assert sorted(p.name for p in tmp_path.iterdir()) == []
        return
    runs = json.loads(json_out.read_text())["runs"]
    assert [r["label"] for r in runs] == ["DOPUS M = 1", "full RTI"]
    for r in runs:
        assert r["result"]["status"] == "completed" and r["result"]["instants"] == r["result"]["instants_planned"]
    figures = sorted(plots.iterdir()) if plots.exists() else []
    assert all(p.suffix == ".png" and _complete_png(p) for p in figures), [p.name for p in figures]
    assert {p.name for p in tmp_path.iterdir()} <= {"plots", "sil.json"}


def test_converge_with_the_reference_backend(tmp_path):
    """The reference backend solves every QP with IPOPT: Ctrl-C there is not a failed run."""
    json_out = tmp_path / "converge.json"
    cmd = Command(["converge", ROBOT_ARM_FILE, "--backend", "reference", "--iters", "40", "--M", "1,full",
                   "--json", json_out, "--plot", tmp_path / "converge.png"], tmp_path)
    try:
        cmd.wait_for_line("DOPUS iterations")
        cmd.signal(signal.SIGINT)
        rc = cmd.finish()
    finally:
        cmd.kill()
    _assert_interrupted(cmd, rc)
    assert "failed" not in cmd.output
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_a_ctrl_c_casadi_swallowed_stops_the_plant():
    """A Ctrl-C that CasADi swallowed whole (inside CVODES a failed right-hand side may be
    retried with a smaller step, and the integration then succeeds) still stops the next
    plant step: the closed loop does not run to its end and write its files. Without the
    recorded interrupt the same step gives the state of an independent integration."""
    import casadi as ca
    import numpy as np
    from scipy.integrate import solve_ivp

    from dopus_codegen import interrupt
    from dopus_codegen.studies.plant import Plant

    x, u = ca.SX.sym("x", 2), ca.SX.sym("u")
    ode = ca.Function("ode", [x, u, ca.SX.sym("p", 0)], [ca.vertcat(x[1], u - ca.sin(x[0]))])
    plant = Plant(ode, 0.1, 0)
    ref = solve_ivp(lambda t, s: [s[1], 0.5 - np.sin(s[0])], (0, 0.1), [0.3, 0.0], rtol=1e-12, atol=1e-12).y[:, -1]
    assert np.allclose(plant.step([0.3, 0.0], [0.5]), ref, atol=1e-8)
    with interrupt.handling():
        with pytest.raises(KeyboardInterrupt):
            with interrupt.deferred():           # records the Ctrl-C; raises it at the end
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(0.01)
        assert interrupt.interrupted()            # as after CasADi swallowed it
        with pytest.raises(KeyboardInterrupt):
            plant.step([0.3, 0.0], [0.5])
    assert not interrupt.interrupted()
