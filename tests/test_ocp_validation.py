"""Every user mistake in an OCP gives an OcpError whose message names the item."""
import math
import re
import textwrap

import casadi as ca
import numpy as np
import pytest

from dopus_codegen import RK4, Event, Ocp, OcpError, build_functions, load_ocp
from dopus_codegen.problem.ocp import Integrator


def make(skip=(), **over):
    """A small valid OCP (double integrator, one path constraint); ``skip`` leaves out
    declarations, keyword arguments replace some of them."""
    ocp = Ocp("tiny")
    x = ocp.state("x", 2, lb=[-5, -5], ub=[5, 5])
    u = ocp.control("u", lb=-1, ub=1)
    p = ocp.parameter("ref", value=0.5)
    syms = dict(x=x, u=u, p=p)
    if "dynamics" not in skip:
        ocp.dynamics(over.get("xdot", ca.vertcat(x[1], u)), integrator=RK4(2))
    ocp.stage_least_squares(ca.vertcat(x[0] - p, u), [1.0, 0.1])
    ocp.path_constraint(x[0] + x[1], lb=-3, ub=3)
    ocp.terminal_cost(x[1] ** 2)
    if "horizon" not in skip:
        ocp.horizon(N=10, dt=0.1)
    if "x0" not in skip:
        ocp.initial_state([1.0, 0.0])
    return ocp, syms


def raises(fn, text):
    with pytest.raises(OcpError, match=re.escape(text)):
        fn()


def test_valid_tiny_ocp_builds():
    ocp, _ = make()
    d = build_functions(ocp)
    assert (d.nx, d.nu, d.np, d.ng, d.N) == (2, 1, 1, 1, 10)
    assert np.array_equal(d.p0, np.full((11, 1), 0.5))
    assert d.state_names == ["x[0]", "x[1]"] and d.control_names == ["u"]
    assert np.array_equal(d.initial_guess.x, np.tile([1.0, 0.0], (11, 1)))
    assert np.array_equal(d.initial_guess.u, np.zeros((10, 1)))


# ------------------------------------------------------------ names and declarations
def test_name_not_c_identifier():
    raises(lambda: Ocp("2fast"), "Ocp name: '2fast' is not a valid C identifier")
    raises(lambda: Ocp("double"), "'double' is not a valid C identifier")


def test_duplicate_names():
    ocp = Ocp("dup")
    ocp.state("x")
    raises(lambda: ocp.control("x"), "control 'x': duplicate name")


def test_nan_in_bounds():
    ocp = Ocp("b")
    raises(lambda: ocp.state("x", 2, lb=[0, math.nan]), "state 'x' lb: NaN at row 1")


def test_nan_parameter_value():
    ocp = Ocp("b")
    raises(lambda: ocp.parameter("ref", 2, value=[1.0, math.nan]), "parameter 'ref' value: NaN at row 1")


def test_state_bounds_lb_gt_ub():
    ocp = Ocp("b")
    raises(lambda: ocp.control("u", 2, lb=[0, 2], ub=[1, 1]), "control 'u' bounds: lb > ub at row 1")


def test_path_constraint_lb_gt_ub_names_the_constraint():
    ocp, s = make()
    ocp.path_constraint(s["u"], lb=-1, ub=1)
    raises(lambda: ocp.path_constraint(s["x"][0], lb=1, ub=0), "path constraint 2: lb > ub at row 0")


def test_bound_vector_of_wrong_length():
    ocp, s = make()
    raises(lambda: ocp.path_constraint(s["x"], lb=[0, 0, 0]), "path constraint 1 lb: expected a scalar or 2 values")


# ------------------------------------------------------------ symbols and shapes
def test_undeclared_symbol_in_stage_cost():
    ocp, s = make()
    z = ca.SX.sym("z")
    ocp.stage_cost(s["x"][0] * z)
    raises(ocp.validate, "stage cost uses symbol 'z' that is not a declared state, control or parameter")


def test_control_in_terminal_cost():
    ocp, s = make()
    ocp.terminal_cost(s["u"] ** 2)
    raises(ocp.validate, "terminal cost 1 uses control 'u', but may only depend on state or parameter symbols")


def test_undeclared_symbol_in_dynamics_and_constraint():
    ocp, s = make(xdot=ca.vertcat(ca.SX.sym("k"), 0))
    raises(ocp.validate, "dynamics uses symbol 'k'")
    ocp, s = make()
    ocp.path_constraint(ca.SX.sym("c"), lb=0)
    raises(ocp.validate, "path constraint 1 uses symbol 'c'")


def test_dynamics_wrong_rows():
    ocp, s = make(xdot=ca.SX.zeros(3))
    raises(ocp.validate, "dynamics: expected 2 rows (one per state), got 3")


def test_non_scalar_costs():
    ocp, s = make()
    ocp.stage_cost(s["x"])
    raises(ocp.validate, "stage cost 0: must be a scalar, got 2 rows")
    ocp, s = make()
    ocp.terminal_cost(ca.vertcat(s["x"][0], s["x"][1]))
    raises(ocp.validate, "terminal cost 1: must be a scalar, got 2 rows")


def test_mx_expression_rejected():
    ocp, _ = make()
    raises(lambda: ocp.stage_cost(ca.MX.sym("m")), "stage cost 0: got a casadi MX expression")


def test_least_squares_weights():
    ocp, s = make()
    raises(lambda: ocp.stage_least_squares(s["x"], [1, 2, 3]), "stage least squares 1: 3 weights for a residual of 2 rows")
    raises(lambda: ocp.terminal_least_squares(s["x"], [[1, 2], [0, 1]]), "terminal least squares 0: weight matrix is not symmetric")
    raises(lambda: ocp.terminal_least_squares(s["x"], [1, -1]), "terminal least squares 0: weights must be positive semidefinite")


# ------------------------------------------------------------ horizon, data, options
def test_horizon():
    ocp, _ = make()
    raises(lambda: ocp.horizon(N=1, dt=0.1), "N must be >= 2")
    raises(lambda: ocp.horizon(N=10, dt=0.0), "dt must be positive")
    raises(lambda: ocp.horizon(N=10, dt=-1), "dt must be positive")
    raises(lambda: ocp.horizon(N=2.5, dt=0.1), "N must be an integer")


@pytest.mark.parametrize("item,text", [
    ("dynamics", "missing dynamics"), ("horizon", "missing horizon"), ("x0", "missing initial state")])
def test_missing_declarations(item, text):
    ocp, _ = make(skip=(item,))
    raises(ocp.validate, text)


def test_no_states_or_controls():
    raises(Ocp("e").validate, "no state declared")


def test_initial_state_nan_and_shape():
    ocp, _ = make()
    ocp.initial_state([1.0, math.nan])
    raises(ocp.validate, "initial state: non-finite value (NaN or inf) at row 1")
    ocp.initial_state([1.0, 0.0, 0.0])
    raises(ocp.validate, "initial state: expected 2 values, got shape (3,)")


def test_initial_guess_shapes_and_nan():
    ocp, _ = make()
    ocp.initial_guess(x=np.zeros((10, 2)))
    raises(ocp.validate, "initial guess x: expected 2 values or a (11, 2) array, got shape (10, 2)")
    ocp.initial_guess(u=np.zeros((10, 2)))
    raises(ocp.validate, "initial guess u: expected 1 values or a (10, 1) array")
    g = np.zeros((11, 2))
    g[4, 1] = math.nan
    ocp.initial_guess(x=g)
    raises(ocp.validate, "initial guess x: non-finite value (NaN or inf) at node 4, row 1")


def test_gauss_newton_needs_least_squares():
    ocp = Ocp("nols")
    x = ocp.state("x")
    u = ocp.control("u")
    ocp.dynamics(u)
    ocp.stage_cost(x**2 + u**2)
    ocp.horizon(5, 0.1)
    ocp.initial_state([0])
    ocp.options(hessian="gauss-newton")
    raises(ocp.validate, "hessian='gauss-newton' needs stage_least_squares")
    ocp.options(hessian="exact")
    d = build_functions(ocp)
    assert d.stage_hess_gn is None and not d.has_gn
    raises(lambda: d.stage_hess("gauss-newton"), "needs stage_least_squares")


def test_bad_options():
    ocp, _ = make()
    raises(lambda: ocp.options(hessian="bfgs"), "options: hessian must be")
    raises(lambda: ocp.options(lm=-1e-3), "options: lm must be finite and >= 0")
    raises(lambda: ocp.options(lm="x"), "options: lm must be 'auto' or a number")
    raises(lambda: ocp.options(regularization="clip"), "options: regularization must be")
    raises(lambda: ocp.options(M=-1), "options: M must be an integer >= 0")
    raises(lambda: ocp.options(reg_eps=0), "options: reg_eps must be positive")
    raises(lambda: ocp.options(offline_guess="yes"), "options: offline_guess must be True or False")
    raises(lambda: ocp.options(hesian="exact"), "options: unknown option 'hesian'; the options are M, hessian")
    raises(lambda: ocp.options(mode="fixed"), "options: unknown option 'mode'")   # the verb's, not the file's
    raises(lambda: ocp.options(gate=-1.0), "options: gate must be finite and >= 0")
    raises(lambda: ocp.options(gate=float("nan")), "options: gate must be finite and >= 0")
    raises(lambda: ocp.options(gate_hold=0), "options: gate_hold must be an integer >= 1")
    raises(lambda: ocp.options(gate_hold=2.5), "options: gate_hold must be an integer >= 1")


def test_options_update_only_what_is_given():
    ocp, _ = make()
    ocp.options(hessian="gauss-newton", M=3)
    ocp.options(regularization="mirror")
    assert build_functions(ocp).options == dict(hessian="gauss-newton", regularization="mirror",
                                                reg_eps=1e-4, M=3, offline_guess=False, lm="auto",
                                                cost_hessian="fresh", real="double", gate=0.0, gate_hold=10,
                                                kkt_tol_rel=None)
    ocp.options(lm=2e-4)
    assert build_functions(ocp).options["lm"] == 2e-4 and build_functions(ocp).options["M"] == 3


def test_terminal_equality_at_infinity():
    ocp, s = make()
    raises(lambda: ocp.terminal_constraint(s["x"][0], lb=math.inf, ub=math.inf), "terminal constraint 0: lb == ub == inf")


def test_terminal_rows_split_into_equalities():
    ocp, s = make()
    ocp.terminal_constraint(ca.vertcat(s["x"][0], s["x"][1], s["x"][0] - s["x"][1]), lb=[0.5, -1, 0.2], ub=[0.5, 1, 0.2])
    d = build_functions(ocp)
    assert (d.nr, d.ne) == (1, 2)
    E, r, r_eq = d.term_eval([2.0, 3.0], [0.5])
    assert float(r[0]) == 3.0 and np.allclose(np.array(r_eq).ravel(), [1.5, -1.2])


def test_model_not_finite_at_guess():
    ocp, s = make()
    ocp.stage_cost(ca.sqrt(s["x"][0] - 2))      # x0[0] = 1: sqrt of a negative number
    raises(lambda: build_functions(ocp), "stage 0 of the initial guess gives non-finite l")


def test_integrator_returning_wrong_shape():
    class Broken(Integrator):
        def step(self, ode, x, u, p, h):
            return x[0]

    ocp, s = make()
    ocp.dynamics(ca.vertcat(s["x"][1], s["u"]), integrator=Broken())
    raises(lambda: build_functions(ocp), "dynamics: integrator Broken returned shape (1, 1), expected (2, 1)")
    raises(lambda: ocp.dynamics(s["x"], integrator="rk4"), "dynamics: integrator must be an Integrator")
    raises(lambda: RK4(0), "RK4: substeps must be an integer >= 1")

    class Raising(Integrator):
        def step(self, ode, x, u, p, h):
            return ca.mtimes(ca.SX.ones(3, 3), ode(x, u, p))

    ocp.dynamics(ca.vertcat(s["x"][1], s["u"]), integrator=Raising())
    raises(lambda: build_functions(ocp), "dynamics: cannot discretise with Raising: Matrix product with "
                                         "incompatible dimensions. Lhs is 3x3 and rhs is 2x1.")


def test_scenario_errors():
    ocp, s = make()
    ocp.scenario(duration=1.0, events=[Event(2.0, lambda x: x, "kick")])
    raises(ocp.validate, "scenario event 0 ('kick'): time 2.0 outside [0, 1.0]")
    ocp.scenario(duration=1.0, signals={"err": ca.SX.sym("y")})
    raises(ocp.validate, "scenario signal 'err' uses symbol 'y'")
    ocp.scenario(duration=1.0, plant=s["x"][0])
    raises(ocp.validate, "scenario plant: expected 2 rows (one per state), got 1")
    ocp.scenario(duration=-1.0)
    raises(ocp.validate, "scenario: duration must be positive")
    raises(lambda: ocp.disturbance(3), "disturbance: expected a function of the state")
    raises(lambda: ocp.scenario(1.0, events=Event(0.5, lambda x: x)), "scenario: events must be a list of Event")
    raises(lambda: ocp.scenario(1.0, signals=[s["x"]]), "scenario: signals must be a dict")


def test_scenario_spec_with_plant_mismatch():
    ocp, s = make()
    ocp.scenario(duration=2.0, events=[Event(0.5, lambda x: 2 * x, "double")],
                 signals={"pos": s["x"][0] - s["p"]}, plant=ca.vertcat(s["x"][1], 0.5 * s["u"]))
    spec = build_functions(ocp).scenario_spec
    assert spec.duration == 2.0 and spec.events[0].label == "double"
    assert float(spec.signals["pos"]([3.0, 0.0], [0.0], [0.5])) == 2.5
    assert np.allclose(np.array(spec.plant_ode([0.0, 1.0], [4.0], [0.5])).ravel(), [1.0, 2.0])
    assert np.array_equal(spec.x0, [1.0, 0.0])


# ------------------------------------------------------------ load_ocp
def write(tmp_path, body, name="prob.py"):
    f = tmp_path / name
    f.write_text(textwrap.dedent(body))
    return f


def test_load_missing_file(tmp_path):
    raises(lambda: load_ocp(tmp_path / "nope.py"), f"OCP file '{tmp_path / 'nope.py'}' does not exist")


def test_load_directory(tmp_path):
    raises(lambda: load_ocp(tmp_path), f"OCP file '{tmp_path}' is not a file")


def test_load_syntax_error_names_file_and_line(tmp_path):
    f = write(tmp_path, """\
        import casadi as ca

        def build(:
            pass
        """)
    raises(lambda: load_ocp(f), f"OCP file '{f}', line 3: syntax error")


def test_load_without_build(tmp_path):
    f = write(tmp_path, "x = 1\n")
    raises(lambda: load_ocp(f), f"OCP file '{f}' defines no build() function")


def test_load_build_returns_wrong_type(tmp_path):
    f = write(tmp_path, "def build():\n    return 42\n")
    raises(lambda: load_ocp(f), f"OCP file '{f}': build() returned int, expected an Ocp")


def test_load_casadi_error_in_user_code_names_file_and_line(tmp_path):
    f = write(tmp_path, """\
        import casadi as ca
        from dopus_codegen import Ocp

        def build():
            ocp = Ocp("bad")
            x = ocp.state("x", 2)
            bad = ca.mtimes(ca.SX.ones(3, 3), x)
            return ocp
        """)
    with pytest.raises(OcpError, match=re.escape(f"OCP file '{f}', line 7: build() failed: ")) as info:
        load_ocp(f)
    msg = str(info.value)
    assert msg.endswith("Matrix product with incompatible dimensions. Lhs is 3x3 and rhs is 2x1.")
    assert ".cpp" not in msg


def test_load_validates(tmp_path):
    f = write(tmp_path, """\
        from dopus_codegen import Ocp

        def build():
            ocp = Ocp("half")
            ocp.state("x")
            ocp.control("u")
            return ocp
        """)
    raises(lambda: load_ocp(f), "missing dynamics")
