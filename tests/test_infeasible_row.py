"""An infeasible QP is decoded to its stage and row, also at a later stage than 0.

The constructions make the infeasible row known in advance. The model is x' = u with
|u| <= 1, so whatever the controls, x_k <= x_0 + k dt and x_k >= x_0 - k dt:

- "late": the path constraint x - p >= 0 with the runtime parameter p_k = 0.5 at stage 3
  and -10 at every other node. From x_0 = 0, x_3 <= 0.3 < 0.5: only that row at stage 3
  (its lower side, lb = 0) cannot be met. With p_3 = -10 the same QP is feasible, so the
  named row is the cause.
- "reach": the terminal inequality x_N >= 5 with N dt = 1: the terminal row (lower side,
  lb = 5).
- "home": the terminal equality x_N = 0 from x_0 = 3: the terminal equality row; x_N
  cannot come down to 0, so its upper side is the one the certificate pushes against.
- "start": the path constraint x <= 1 measured at x_0 = 3: x_1 >= 2.9, so the row at
  stage 1 (upper side, ub = 1). The row at stage 0 does not involve u_0: its value is data,
  the C QP solver drops it, and the reference leaves it out of its certificate too.

Both backends name them by the same rule (the row with the largest multiplier of the QP's
infeasibility certificate): the C runtime's getter (dopus_get_qp_infeasible_row) through the
Python handle, and the reference from its own certificate (the smallest violation of the
rows). The handles' errors and the messages of `converge` and `sil` (on either backend) name
them too.
"""
from __future__ import annotations

import json
import re

import numpy as np
import pytest
from click.testing import CliRunner

from dopus_codegen.cli import main as cli_main
from dopus_codegen.errors import DopusError, qp_status_code
from dopus_codegen.reference.dopus import ReferenceDopus
from dopus_codegen.runtime.solver import CSolver
from harness.integrator import N, integrator_model

@pytest.fixture(scope="module")
def late():
    return integrator_model("late", 0.0, parameter=True)


@pytest.fixture(scope="module")
def reach():
    return integrator_model("reach", 0.0, terminal=(5.0, np.inf))


@pytest.fixture(scope="module")
def home():
    return integrator_model("home", 3.0, terminal=(0.0, 0.0))


@pytest.fixture(params=["c", "reference"])
def backend(request):
    return {"c": CSolver, "reference": ReferenceDopus}[request.param]


@pytest.fixture(scope="module")
def start():
    return integrator_model("start", 0.0, upper=1.0)


def _params(p3):
    p = np.full((N + 1, 1), -10.0)
    p[3] = p3
    return p


def _infeasible(s, xhat):
    with pytest.raises(DopusError) as ei:
        s.feedback(xhat)
    assert ei.value.qp_status == qp_status_code("primal_infeasible"), str(ei.value)
    return str(ei.value), s.qp_infeasible_row


def test_later_stage_path_row_is_named(late, backend):
    s = backend(late, M=N - 1, mode="fixed")
    s.set_parameters(_params(-10.0))
    s.init([0.0])
    s.feedback([0.0])                         # every row satisfiable: solved
    assert s.qp_infeasible_row is None
    s.set_parameters(_params(0.5))            # used from the next prepare on
    s.prepare()
    msg, row = _infeasible(s, [0.0])
    assert row == {"stage": 3, "kind": "path", "index": 0, "side": "lower", "bound": 0.0}, row
    assert re.search(r"infeasible at stage 3: path constraint 0 \(\(x-p\)\) >= lb 0\b", msg), msg
    # the same QP without that row is feasible: the named row is the cause
    s.set_parameters(_params(-10.0))
    s.prepare()
    s.feedback([0.0])
    assert s.qp_infeasible_row is None


@pytest.mark.parametrize("problem, x0, row, pattern", [
    ("reach", 0.0, {"stage": N, "kind": "terminal", "index": 0, "side": "lower", "bound": 5.0},
     r"terminal constraint 0 \(x\) >= lb 5\b"),
    ("home", 3.0, {"stage": N, "kind": "terminal_eq", "index": 0, "side": "upper", "bound": 0.0},
     r"terminal constraint 0 \(x\) = 0\b"),
])
def test_terminal_row_is_named(problem, x0, row, pattern, request, backend):
    s = backend(request.getfixturevalue(problem), M=1)
    s.init([x0])
    msg, got = _infeasible(s, [x0])
    assert got == row, got
    assert re.search(rf"infeasible at the terminal node \(stage {N}\): " + pattern, msg), msg


def test_state_only_row_of_stage_0_is_left_out(start, backend):
    s = backend(start, M=1)
    s.init([0.0])
    msg, row = _infeasible(s, [3.0])
    assert row == {"stage": 1, "kind": "path", "index": 0, "side": "upper", "bound": 1.0}, row
    assert re.search(r"infeasible at stage 1: path constraint 0 \(x\) <= ub 1\b", msg), msg


def test_reference_names_a_state_only_row_of_stage_0_when_nothing_else_is_infeasible(start):
    """x_0 = 1.05 > 1 while x_1 can come down to 0.95: only the row of stage 0 is violated.
    The reference's QP keeps it (the C QP solver drops it and solves), so the reference
    names it."""
    s = ReferenceDopus(start, M=1)
    s.init([0.0])
    msg, row = _infeasible(s, [1.05])
    assert row == {"stage": 0, "kind": "path", "index": 0, "side": "upper", "bound": 1.0}, row
    assert re.search(r"infeasible at stage 0: path constraint 0 \(x\) <= ub 1\b", msg), msg


def test_no_row_without_an_infeasible_qp(reach, backend):
    s = backend(reach, M=1)
    s.set_qp_max_iter(1)
    s.init([0.0])
    with pytest.raises(DopusError) as ei:
        s.feedback([0.0])
    assert ei.value.qp_status == qp_status_code("max_iter")
    assert s.qp_infeasible_row is None
    assert "infeasible at" not in str(ei.value)


# --------------------------------------------------------------------------- the commands
REACH_FILE = '''
import numpy as np
from dopus_codegen import Ocp

def build():
    ocp = Ocp("reachfile")
    x = ocp.state("x")
    u = ocp.control("u", lb=-1.0, ub=1.0)
    ocp.dynamics(u)
    ocp.stage_least_squares(u, weights=[1.0])
    ocp.terminal_constraint(x, lb=5.0)
    ocp.horizon(N=10, dt=0.1)
    ocp.initial_state([0.0])
    ocp.scenario(duration=0.2, signals={"x": x[0]})
    return ocp
'''

NAMED = r"infeasible at the terminal node \(stage 10\): terminal constraint 0 \(x\) >= lb 5"


def _invoke(args):
    return CliRunner().invoke(cli_main, [str(a) for a in args])


@pytest.mark.parametrize("backend_args", [["--backend", "c"], ["--backend", "reference"], []],
                         ids=["c", "reference", "default"])
def test_converge_names_the_row(tmp_path, backend_args):
    f = tmp_path / "reachfile.py"
    f.write_text(REACH_FILE)
    out = tmp_path / "c.json"
    res = _invoke(["converge", f, *backend_args, "--start", "cold", "--M", "1", "--iters", "2", "--json", out])
    assert res.exit_code == 1, res.output
    assert re.search(NAMED, res.output), res.output
    (run,) = json.loads(out.read_text())["runs"]
    assert re.search(NAMED, run["message"]), run["message"]


@pytest.mark.parametrize("name", ["c", "reference"])
def test_sil_names_the_row(tmp_path, name):
    f = tmp_path / "reachfile.py"
    f.write_text(REACH_FILE)
    out = tmp_path / "s.json"
    res = _invoke(["sil", f, "--backend", name, "--M", "1", "--json", out])
    assert re.search(r"first failed instant at t = 0(\.0+)? s: .*" + NAMED, res.output), res.output
    run = json.loads(out.read_text())["runs"][0]
    assert re.search(NAMED, run["result"]["first_failure"]["message"])
