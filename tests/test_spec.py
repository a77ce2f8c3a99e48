"""The validated problem (``Ocp.validate()`` -> OcpSpec) is immutable, validated once, and
is all the pipeline reads: the functions built from it agree with independent numpy
evaluations of the spec's own parts, and no module reads another's private members."""
import ast
import dataclasses
import math
import subprocess
from collections.abc import Mapping
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from dopus_codegen import RK4, Event, Ocp, build_functions, load_ocp
from dopus_codegen.problem.discretize import discretize
from dopus_codegen.problem.spec import OcpSpec

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"


def full_ocp(x0=(1.0, 0.0)):
    """A small OCP that declares every part of the spec."""
    ocp = Ocp("full")
    x = ocp.state("x", 2, lb=[-5, -6], ub=[5, 6])
    u = ocp.control("u", lb=0.5, ub=1)
    p = ocp.parameter("ref", 2, value=[0.5, -0.25])
    ocp.dynamics(ca.vertcat(x[1], u - 0.1 * x[0] ** 2 + p[1]), integrator=RK4(2))
    ocp.stage_least_squares(ca.vertcat(x[0] - p[0], u), [[2.0, 0.5], [0.5, 1.0]])
    ocp.stage_cost(0.01 * x[1] ** 4)
    ocp.terminal_least_squares(x - p, [3.0, 1.0])
    ocp.terminal_cost(x[0] * x[1])
    ocp.path_constraint(x[0] + x[1] * u, lb=-3, ub=3)
    ocp.terminal_constraint(ca.vertcat(x[0], x[1] + x[0] ** 2), lb=[0.25, -1], ub=[0.25, 1])
    ocp.horizon(N=6, dt=0.1)
    ocp.initial_state(x0)
    ocp.options(hessian="gauss-newton", M=2, lm=1e-3)
    ocp.disturbance(lambda z: z + 0.1)
    ocp.scenario(duration=1.0, events=[Event(0.5, lambda z: 2 * z, "double")],
                 signals={"pos": x[0] - p[0]}, plant=ca.vertcat(x[1], 0.9 * u), x0=[0.5, 0.5])
    return ocp


def walk(obj, path="spec"):
    """(path, object) for every object reachable through dataclass fields, tuples and
    mappings."""
    yield path, obj
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        for f in dataclasses.fields(obj):
            yield from walk(getattr(obj, f.name), f"{path}.{f.name}")
    elif isinstance(obj, tuple):
        for i, v in enumerate(obj):
            yield from walk(v, f"{path}[{i}]")
    elif isinstance(obj, Mapping):
        for k, v in obj.items():
            yield from walk(v, f"{path}[{k!r}]")


def assert_frozen(root, name):
    n_dataclasses = n_arrays = 0
    for path, obj in walk(root, name):
        if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
            n_dataclasses += 1
            for f in dataclasses.fields(obj):
                with pytest.raises(dataclasses.FrozenInstanceError):
                    setattr(obj, f.name, None)
        elif isinstance(obj, np.ndarray):
            n_arrays += 1
            assert not obj.flags.writeable, path
            if obj.size:
                with pytest.raises(ValueError, match="read-only"):
                    obj.flat[0] = 1.0
        elif isinstance(obj, Mapping):
            with pytest.raises(TypeError):
                obj["new"] = 1  # type: ignore[index]
        elif isinstance(obj, list):
            pytest.fail(f"{path} is a mutable list")
    return n_dataclasses, n_arrays


def test_spec_is_immutable():
    spec = full_ocp().validate()
    assert isinstance(spec, OcpSpec)
    n_dc, n_arr = assert_frozen(spec, "spec")
    # model, its 3 variables, cost, 2 least-squares terms, constraints, 2 row blocks,
    # horizon, options and their settings, guess, scenario, closed loop, the event and the spec itself
    assert n_dc == 19 and n_arr >= 15     # + the parameter trajectory of the model
    # mutating through the integrator copy does not reach the declared one
    assert spec.model.integrator.substeps == 2


def test_discretized_is_immutable():
    disc = build_functions(full_ocp())
    n_dc, _ = assert_frozen(disc, "disc")
    assert n_dc >= 20
    for name in ("N", "nx", "lbx", "stage_eval", "has_gn", "options", "disturbance"):
        with pytest.raises(AttributeError):
            setattr(disc, name, None)
    with pytest.raises(TypeError):
        disc.options["M"] = 5
    with pytest.raises(ValueError, match="read-only"):
        disc.initial_guess.x[0, 0] = 3.0
    # the Guess a caller gets is its own object: replacing its arrays changes nothing
    g = disc.initial_guess
    g.x = np.zeros_like(g.x)
    assert np.array_equal(disc.initial_guess.x, np.tile([1.0, 0.0], (7, 1)))


def test_spec_holds_what_was_declared():
    spec = full_ocp().validate()
    m, c, k = spec.model, spec.constraints, spec.cost
    assert (m.nx, m.nu, m.np) == (2, 1, 2)
    assert m.state_names == ("x[0]", "x[1]") and m.control_names == ("u",)
    assert m.parameter_names == ("ref[0]", "ref[1]")
    assert np.array_equal(m.p_default, [0.5, -0.25])
    assert (spec.horizon.N, spec.horizon.dt) == (6, 0.1)
    assert np.array_equal(c.lbx, [-5, -6]) and np.array_equal(c.ubu, [1])
    assert np.array_equal(c.terminal_equality, [True, False])
    assert np.array_equal(k.stage_least_squares[0].weights, [[2.0, 0.5], [0.5, 1.0]])
    assert np.array_equal(k.terminal_least_squares[0].weights, np.diag([3.0, 1.0]))
    assert spec.options.as_dict() == dict(hessian="gauss-newton", regularization="none", reg_eps=1e-4,
                                          M=2, offline_guess=False, lm=1e-3, cost_hessian="fresh",
                                          real="double", gate=0.0, gate_hold=10, kkt_tol_rel=None)
    assert np.array_equal(spec.x0, [1.0, 0.0])
    # default guess: x0 at every node, u = 0 clipped into [0.5, 1]
    assert np.array_equal(spec.guess.x, np.tile([1.0, 0.0], (7, 1)))
    assert np.array_equal(spec.guess.u, np.full((6, 1), 0.5))
    cl = spec.scenario.closed_loop
    assert cl.duration == 1.0 and [e.time for e in cl.events] == [0.5]
    assert np.array_equal(cl.x0, [0.5, 0.5]) and [s for s, _ in cl.signals] == ["pos"]
    assert np.array_equal(spec.scenario.disturbance(np.zeros(2)), [0.1, 0.1])


def test_spec_does_not_follow_later_changes_of_user_data():
    x0 = np.array([1.0, 0.0])
    ocp = full_ocp(x0)
    spec = ocp.validate()
    x0[0] = 99.0                       # the caller's array, after the declaration
    assert ocp.validate() is spec
    assert np.array_equal(spec.x0, [1.0, 0.0])
    assert np.array_equal(build_functions(ocp).x0, [1.0, 0.0])
    ocp.initial_state([2.0, 0.0])      # a new declaration gives a new spec
    spec2 = ocp.validate()
    assert spec2 is not spec and np.array_equal(spec2.x0, [2.0, 0.0])
    assert np.array_equal(spec.x0, [1.0, 0.0])
    ocp.name = "renamed"
    assert ocp.validate().name == "renamed" and spec2.name == "full"


@pytest.fixture
def count_validations(monkeypatch):
    calls = []
    original = Ocp.build_spec

    def counted(self):
        calls.append(self.name)
        return original(self)

    monkeypatch.setattr(Ocp, "build_spec", counted)
    return calls


@pytest.mark.parametrize("example", ["robot_arm.py", "unicycle.py"])
def test_validation_runs_once_per_file(count_validations, example):
    disc = build_functions(load_ocp(EXAMPLES / example))
    assert count_validations == [disc.name]


def test_validation_runs_once_per_build(count_validations):
    ocp = full_ocp()
    d1 = build_functions(ocp)
    assert count_validations == ["full"]
    d2 = build_functions(ocp)            # nothing changed: the same spec
    assert count_validations == ["full"] and d2.spec is d1.spec
    discretize(d1.spec)
    build_functions(d1.spec)             # from the spec: no validation at all
    assert count_validations == ["full"]
    ocp.options(M=3)
    assert build_functions(ocp).options["M"] == 3
    assert count_validations == ["full", "full"]


def rk4(f, x, h, substeps):
    hs = h / substeps
    for _ in range(substeps):
        k1 = f(x)
        k2 = f(x + hs / 2 * k1)
        k3 = f(x + hs / 2 * k2)
        k4 = f(x + hs * k3)
        x = x + hs / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return x



@pytest.mark.parametrize("example", ["robot_arm.py", "unicycle.py", None])
def test_functions_agree_with_the_spec_parts(example):
    """stage_eval / term_eval against a numpy evaluation of the spec's own parts: RK4 on
    the model's xdot, 0.5 r' W r + terms for the costs, the path rows, and the terminal
    rows split by the spec's equality mark."""
    spec = (load_ocp(EXAMPLES / example) if example else full_ocp()).validate()
    disc = build_functions(spec)
    m, cost, con = spec.model, spec.cost, spec.constraints
    x, u, p = m.x, m.u, m.p

    def ev(expr, xv, uv, pv):
        return np.array(ca.Function("e", [x, u, p], [expr])(xv, uv, pv), dtype=float).reshape(-1)

    def lsq(terms, xv, uv, pv):
        total = 0.0
        for t in terms:
            r = ev(t.residual, xv, uv, pv)
            total += 0.5 * r @ np.asarray(t.weights) @ r
        return total

    rng = np.random.default_rng(11)
    eq = np.asarray(con.terminal_equality)
    rows_lb = np.concatenate([b.lb for b in con.terminal]) if con.terminal else np.zeros(0)
    for _ in range(5):
        xv = spec.x0 + 0.2 * rng.standard_normal(m.nx)
        uv = np.clip(rng.standard_normal(m.nu), con.lbu, con.ubu)
        pv = m.p_default + 0.1 * rng.standard_normal(m.np)
        phi, l, g = (np.array(v, dtype=float).reshape(-1) for v in disc.stage_eval(xv, uv, pv))
        f = lambda z: ev(m.xdot, z, uv, pv)  # noqa: E731
        phi_ref = rk4(f, xv, spec.horizon.dt, m.integrator.substeps)
        assert np.allclose(phi, phi_ref, rtol=1e-13, atol=1e-13)
        l_ref = lsq(cost.stage_least_squares, xv, uv, pv) + sum(float(ev(t, xv, uv, pv)[0])
                                                                 for t in cost.stage_terms)
        assert math.isclose(float(l[0]), l_ref, rel_tol=1e-12, abs_tol=1e-12)
        g_ref = np.concatenate([ev(b.expr, xv, uv, pv) for b in con.path]) if con.path else np.zeros(0)
        assert np.allclose(g, g_ref, rtol=1e-14, atol=1e-14)
        E, r, r_eq = (np.array(v, dtype=float).reshape(-1) for v in disc.term_eval(xv, pv))
        E_ref = lsq(cost.terminal_least_squares, xv, uv, pv) + sum(float(ev(t, xv, uv, pv)[0])
                                                                    for t in cost.terminal_terms)
        assert math.isclose(float(E[0]), E_ref, rel_tol=1e-12, abs_tol=1e-12)
        rows = np.concatenate([ev(b.expr, xv, uv, pv) for b in con.terminal]) if con.terminal else np.zeros(0)
        assert np.allclose(r, rows[~eq], rtol=1e-14, atol=1e-14)
        assert np.allclose(r_eq, rows[eq] - rows_lb[eq], rtol=1e-14, atol=1e-14)
    assert np.array_equal(disc.lr, rows_lb[~eq]) and np.array_equal(disc.p0, np.tile(m.p_default, (spec.horizon.N + 1, 1)))


def test_no_module_reads_another_modules_private_members():
    """``obj._name`` only on ``self``/``cls``; no ``from module import _name``."""
    hits = []
    # the tracked sources only (bench/.env, a virtual environment of the HPIPM benchmark, is not ours)
    tracked = subprocess.run(["git", "ls-files", "-z", "--", "*.py"], cwd=ROOT, capture_output=True,
                             check=True).stdout.decode().split("\0")
    roots = ("dopus_codegen/", "tests/", "bench/", "examples/", "scripts/")
    for path in sorted(ROOT / f for f in tracked if f.startswith(roots)):
        tree = ast.parse(path.read_text(), str(path))
        for node in ast.walk(tree):
            if (isinstance(node, ast.Attribute) and node.attr.startswith("_")
                    and not node.attr.startswith("__")
                    and not (isinstance(node.value, ast.Name) and node.value.id in ("self", "cls"))):
                hits.append(f"{path.relative_to(ROOT)}:{node.lineno}: {ast.unparse(node)}")
            if isinstance(node, ast.ImportFrom):
                hits += [f"{path.relative_to(ROOT)}:{node.lineno}: import {a.name}" for a in node.names
                         if a.name.startswith("_") and not a.name.startswith("__")]
    assert not hits, "\n".join(hits)
