"""Shared fixtures: the two example problems, discretised once per session.

``robot_disc`` / ``second_disc``: the :class:`~dopus_codegen.problem.derivatives.Discretized` of
examples/robot_arm.py and examples/unicycle.py. ``robot_solution`` /
``second_solution``: their IPOPT solution ``(Guess, info)`` at the initial state.
Treat all of them as read-only.
"""
from __future__ import annotations

from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"
ROBOT_ARM_FILE = EXAMPLES / "robot_arm.py"
SECOND_FILE = EXAMPLES / "unicycle.py"


@pytest.fixture(scope="session")
def robot_disc():
    from dopus_codegen import build_functions, load_ocp

    return build_functions(load_ocp(ROBOT_ARM_FILE))


@pytest.fixture(scope="session")
def second_disc():
    from dopus_codegen import build_functions, load_ocp

    return build_functions(load_ocp(SECOND_FILE))


@pytest.fixture(scope="session")
def robot_solution(robot_disc):
    from dopus_codegen.reference.offline import solve_ocp

    return solve_ocp(robot_disc, robot_disc.x0)


@pytest.fixture(scope="session")
def second_solution(second_disc):
    from dopus_codegen.reference.offline import solve_ocp

    return solve_ocp(second_disc, second_disc.x0)
