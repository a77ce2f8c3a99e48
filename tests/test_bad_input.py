"""Bad input to the Python handle of a generated solver (CSolver) and to its C API.

Every case names its expected error: for CSolver a DopusError (also a ValueError) whose
message names the argument, with the C status code (runtime_c/dopus_solver.h); never a cffi
OverflowError/TypeError, never a silent wrong answer. After each rejected call the solver
still works and its iterate is unchanged, which is checked against a twin solver that never
saw a bad call (the iterates must stay bit-identical). The C API cases call the library
through cffi without the Python checks in front of it. The sanitizer test
(tests/test_sanitizers.py) runs the C API's bad inputs of tests/fuzz/driver.c under
AddressSanitizer and UndefinedBehaviorSanitizer too.
"""
from __future__ import annotations

import numpy as np
import pytest

from dopus_codegen.problem.ocp import Guess
from dopus_codegen.runtime.solver import CSolver, DopusError, load_library

OK, QP, NONFINITE_INPUT, INVALID, NOT_INIT, NOT_PREPARED, ALREADY_PREPARED = 0, 1, 2, 5, 6, 7, 10
FIELDS = ("x", "u", "lam", "mu_g", "mu_b", "mu_bN", "mu_r", "nu")


@pytest.fixture(scope="module")
def pair(second_disc, second_solution):
    """Two unicycle solvers (np = 2, ng = 1) at the same warm start: ``c`` gets every bad
    call, ``twin`` only the good ones."""
    d = second_disc
    c, twin = CSolver(d, M=1, lm=0.0), CSolver(d, M=1, lm=0.0)
    for b in (c, twin):
        # rejected measurements are failed sampling instants, which the automatic recovery
        # counts (docs/algorithm.md section 9); here only the rejection itself is compared
        b.set_recovery(False)
        b.init(d.x0, second_solution[0])
    return c, twin


def _bits(b) -> bytes:
    return b"".join(np.asarray(getattr(b, f), dtype=float).tobytes() for f in FIELDS)


def _cases(d):
    N, nx, nu, np_ = d.N, d.nx, d.nu, d.np
    xh = np.asarray(d.x0, dtype=float)
    nan_x = xh.copy()
    nan_x[1] = np.nan
    g = Guess(x=np.zeros((N + 1, nx)), u=np.zeros((N - 1, nu)))
    g_nan = Guess(x=np.zeros((N + 1, nx)), u=np.zeros((N, nu)), lam=np.full((N + 1, nx), np.inf))
    p_nan = np.tile(np.asarray(d.p0[0], dtype=float), (N + 1, 1))
    p_nan[4, 1] = np.nan
    # (label, call, message regex, status)
    return [
        # first, while no sampling instant has passed since init (a rejected measurement in
        # receding mode also ends one: docs/algorithm.md section 4)
        ("prepare right after init", lambda c: c.prepare(), r"unicycle: prepare: already prepared \(call "
                                                            r"feedback before the next prepare\) \(status 10\)",
         ALREADY_PREPARED),
        ("qp_max_iter 2**31", lambda c: c.set_qp_max_iter(2**31), r"qp_max_iter must be at most 2147483647 \(a C int\), got 2147483648", INVALID),
        ("qp_max_iter 10**30", lambda c: c.set_qp_max_iter(10**30), r"qp_max_iter must be at most", INVALID),
        ("qp_max_iter 0", lambda c: c.set_qp_max_iter(0), r"qp_max_iter must be an integer >= 1, got 0", INVALID),
        ("qp_max_iter 2.5", lambda c: c.set_qp_max_iter(2.5), r"qp_max_iter must be an integer >= 1, got 2.5", INVALID),
        ("qp_max_iter True", lambda c: c.set_qp_max_iter(True), r"qp_max_iter must be an integer >= 1, got True", INVALID),
        ("qp_tol 0", lambda c: c.set_qp_tol(0.0), r"qp_tol must be positive and finite, got 0.0", INVALID),
        ("qp_tol nan", lambda c: c.set_qp_tol(float("nan")), r"qp_tol must be positive and finite", INVALID),
        ("qp_tol 1e-400 (underflows to 0)", lambda c: c.set_qp_tol(1e-400), r"qp_tol must be positive", INVALID),
        ("qp_tol 10**400", lambda c: c.set_qp_tol(10**400), r"qp_tol must be a positive number, got 1000", INVALID),
        ("qp_tol 'abc'", lambda c: c.set_qp_tol("abc"), r"qp_tol must be a positive number, got 'abc'",
         INVALID),
        ("lm -1", lambda c: c.set_levenberg_marquardt(-1.0), r"lm must be finite and >= 0, got -1.0", INVALID),
        ("lm inf", lambda c: c.set_levenberg_marquardt(float("inf")), r"lm must be finite and >= 0", INVALID),
        ("lm 10**400", lambda c: c.set_levenberg_marquardt(10**400), r"lm must be a number >= 0, got 1000", INVALID),
        ("lm None", lambda c: c.set_levenberg_marquardt(None), r"lm must be a number >= 0, got None",
         INVALID),
        ("M -1", lambda c: c.set_M(-1), r"M must be an integer >= 0, got -1", INVALID),
        ("M 1.5", lambda c: c.set_M(1.5), r"M must be an integer >= 0, got 1.5", INVALID),
        ("M '3'", lambda c: c.set_M("3"), r"M must be an integer >= 0, got '3'", INVALID),
        ("mode 'sideways'", lambda c: c.set_mode("sideways"), r"mode must be 'receding' or 'fixed'", INVALID),
        ("mode ['fixed'] (unhashable)", lambda c: c.set_mode(["fixed"]), r"mode must be 'receding' or 'fixed'",
         INVALID),
        ("hessian {} (unhashable)", lambda c: c.set_hessian({}), r"hessian must be 'exact' or 'gauss-newton'",
         INVALID),
        ("regularization ['project']", lambda c: c.set_regularization(["project"]),
         r"regularization must be 'none', 'project' or 'mirror'", INVALID),
        ("reg_eps -1", lambda c: c.set_regularization("project", -1.0), r"reg_eps must be positive", INVALID),
        ("cost_hessian 1", lambda c: c.set_cost_hessian(1), r"cost_hessian must be 'stored' or 'fresh', got 1", INVALID),
        ("parameters NaN", lambda c: c.set_parameters(p_nan), r"parameters: NaN or Inf at index \(4, 1\)",
         NONFINITE_INPUT),
        ("parameters shape", lambda c: c.set_parameters(np.zeros((N, np_))),
         rf"parameters: expected shape \({N + 1}, {np_}\), got \({N}, {np_}\)", INVALID),
        ("parameters of node N+1", lambda c: c.set_parameters_node(N + 1, np.zeros(np_)),
         rf"node index must be an integer in 0..{N}, got {N + 1}", INVALID),
        ("parameters of node 2**70", lambda c: c.set_parameters_node(2**70, np.zeros(np_)),
         r"node index must be an integer in 0\.\.", INVALID),
        ("parameters of node 1.0", lambda c: c.set_parameters_node(1.0, np.zeros(np_)),
         r"node index must be an integer", INVALID),
        ("parameters of a node: Inf", lambda c: c.set_parameters_node(3, [np.inf, 0.0]),
         r"parameters of node 3: NaN or Inf at index 0", NONFINITE_INPUT),
        ("feedback NaN", lambda c: c.feedback(nan_x), r"unicycle: feedback: xhat0: NaN or Inf at index 1",
         NONFINITE_INPUT),
        ("feedback 1e400 (Inf)", lambda c: c.feedback([1e400] + [0.0] * (nx - 1)),
         r"feedback: xhat0: NaN or Inf at index 0", NONFINITE_INPUT),
        ("feedback None", lambda c: c.feedback(None), r"feedback: xhat0: expected real numbers", INVALID),
        ("feedback strings", lambda c: c.feedback(["a"] * nx), r"feedback: xhat0: expected real numbers", INVALID),
        ("feedback complex", lambda c: c.feedback(xh + 1j), r"feedback: xhat0: expected real numbers", INVALID),
        ("feedback ragged", lambda c: c.feedback([[1.0], [1.0, 2.0]]), r"feedback: xhat0: not an array", INVALID),
        ("feedback wrong length", lambda c: c.feedback(xh[:-1]),
         rf"feedback: xhat0: expected shape \({nx},\), got \({nx - 1},\)", INVALID),
        ("kkt NaN", lambda c: c.kkt(nan_x), r"kkt: xhat0: NaN or Inf at index 1", NONFINITE_INPUT),
        ("init guess.u shape", lambda c: c.init(xh, g),
         rf"init: guess.u: expected shape \({N}, {nu}\), got \({N - 1}, {nu}\)", INVALID),
        ("init guess.lam Inf", lambda c: c.init(xh, g_nan), r"init: guess.lam: NaN or Inf at index \(0, 0\)",
         NONFINITE_INPUT),
        ("init without guess.x", lambda c: c.init(xh, Guess(x=None, u=np.zeros((N, nu)))),
         r"init: guess.x is required", INVALID),
        ("init xhat0 NaN", lambda c: c.init(nan_x), r"init: xhat0: NaN or Inf at index 1", NONFINITE_INPUT),
        ("set_clock 42", lambda c: c.set_clock(42), r"set_clock: expected a callable", INVALID),
    ]


def test_python_handle_bad_inputs(pair, second_disc):
    """Each bad call raises DopusError with its message and status; the iterate stays
    bit-identical to a twin's that never saw it, and the solver keeps working."""
    c, twin = pair
    d = second_disc
    cases = _cases(d)
    for label, call, pattern, status in cases:
        before = _bits(c)
        with pytest.raises(DopusError, match=pattern) as ei:
            call(c)
        assert isinstance(ei.value, ValueError), label
        assert ei.value.status == status, f"{label}: status {ei.value.status}, expected {status}"
        assert c.status == status, label
        assert _bits(c) == before == _bits(twin), f"{label}: the iterate changed"
    # the settings are those of the twin (no bad value got through)
    for attr in ("M", "mode", "hessian", "regularization", "cost_hessian", "qp_tol", "lm", "reg_eps"):
        assert getattr(c, attr) == getattr(twin, attr), attr
    assert np.array_equal(c.p, twin.p)
    # and the solver still runs, bit for bit like the twin
    xh = np.asarray(d.disturbance(d.x0), dtype=float)
    for _ in range(3):
        assert np.array_equal(c.feedback(xh), twin.feedback(xh))
        c.prepare()
        twin.prepare()
    assert _bits(c) == _bits(twin)
    print(f"\nPython handle: {len(cases)} bad-input cases, each with its message and status")


def test_python_handle_before_init(second_disc):
    c = CSolver(second_disc, M=1)
    for call, what in ((lambda: c.feedback(second_disc.x0), "feedback"), (c.prepare, "prepare"),
                       (lambda: c.kkt(second_disc.x0), "kkt")):
        with pytest.raises(DopusError, match=rf"unicycle: {what}: the solver is not initialised \(call init "
                                             r"first\) \(status 6\)") as ei:
            call()
        assert ei.value.status == NOT_INIT


def test_python_handle_bad_construction(second_disc, tmp_path):
    with pytest.raises(ValueError, match="Solver needs a Discretized problem or lib_dir"):
        CSolver(None)
    with pytest.raises(DopusError, match="qp_max_iter must be at most 2147483647"):
        CSolver(second_disc, qp_max_iter=2**31)
    with pytest.raises(DopusError, match="M must be an integer >= 0, got -2"):
        CSolver(second_disc, M=-2)
    with pytest.raises(RuntimeError, match=r"build: folder '.*no_such_folder' does not exist"):
        CSolver(second_disc, lib_dir=tmp_path / "no_such_folder")


# ------------------------------------------------------------------ the C API through cffi
def test_c_api_bad_inputs(second_disc, second_solution):
    """The C functions themselves (no Python checks in front): each bad argument gets its
    documented status, the setting or iterate is unchanged, and the next good call works."""
    d = second_disc
    c = CSolver(d, M=1)                      # built into the cache; its library is used raw
    ffi, lib, meta = load_library(c.lib_dir)
    name = meta["name"]
    fn = lambda f: getattr(lib, f"{name}_{f}")  # noqa: E731
    mem = ffi.new("double[]", (int(fn("solver_sizeof")()) + 7) // 8)   # zeroed memory
    s = ffi.cast(f"{name}_solver *", mem)
    N, nx, np_ = d.N, d.nx, d.np
    dbl = lambda a: ffi.from_buffer("double[]", np.ascontiguousarray(a, dtype=float))  # noqa: E731
    x0 = np.asarray(d.x0, dtype=float)
    nan_x = x0.copy()
    nan_x[0] = np.nan
    u0 = np.zeros(d.nu)
    NULL = ffi.NULL

    def update(**fields):
        """update_settings with the current settings and ``fields`` changed."""
        st = ffi.new(f"{name}_settings *")
        fn("get_settings")(s, st)
        for k, v in fields.items():
            setattr(st, k, v)
        return fn("update_settings")(s, st)

    def info():
        out = ffi.new(f"{name}_info *")
        fn("get_info")(s, out)
        return out

    # zeroed memory that was not set up refuses every call
    refused = (("init", lambda: fn("init")(s, dbl(x0), *[NULL] * 8)),
               ("feedback", lambda: fn("feedback")(s, dbl(x0), NULL)), ("prepare", lambda: fn("prepare")(s)),
               ("kkt", lambda: fn("kkt_eval")(s, NULL, NULL)), ("update_settings", lambda: update(M=0)),
               ("set_parameters", lambda: fn("set_parameters")(s, NULL)))
    for label, call in refused:
        assert int(call()) == NOT_INIT, f"{label} on a struct that was not set up"
    cases = [
        ("feedback before init", lambda: fn("feedback")(s, dbl(x0), dbl(u0)), NOT_INIT),
        ("prepare before init", lambda: fn("prepare")(s), NOT_INIT),
        ("kkt before init", lambda: fn("kkt_eval")(s, dbl(x0), NULL), NOT_INIT),
        ("init NaN xhat0", lambda: fn("init")(s, dbl(nan_x), NULL, NULL, NULL, NULL, NULL, NULL, NULL, NULL),
         NONFINITE_INPUT),
        ("init_nominal without a generated nominal guess",
         lambda: fn("init_nominal")(s, dbl(x0)), OK if meta.get("has_nominal", c.has_nominal) else 8),
        ("M N", lambda: update(M=N), INVALID),
        ("M -2147483648", lambda: update(M=-2**31), INVALID),
        ("mode -1", lambda: update(mode=-1), INVALID),
        ("hessian 2", lambda: update(hessian=2), INVALID),
        ("reg_eps -inf", lambda: update(regularization=1, reg_eps=-np.inf), INVALID),
        ("cost_hessian -1", lambda: update(cost_hessian=-1), INVALID),
        ("lm nan", lambda: update(lm_auto=0, lm=np.nan), INVALID),
        ("lm_auto 2", lambda: update(lm_auto=2), INVALID),
        ("qp_tol -inf", lambda: update(qp_tol=-np.inf), INVALID),
        ("qp_tol inf", lambda: update(qp_tol=np.inf), INVALID),
        ("qp_tol above DOPUS_QP_TOL_MAX", lambda: update(qp_tol=0.1), INVALID),
        ("qp_max_iter -1", lambda: update(qp_max_iter=-1), INVALID),
        ("qp_warm_start 2", lambda: update(qp_warm_start=2), INVALID),
        ("recovery_failures 0", lambda: update(recovery_failures=0), INVALID),
        ("set_parameters NULL", lambda: fn("set_parameters")(s, NULL), INVALID),
        ("set_parameters Inf", lambda: fn("set_parameters")(s, dbl(np.full((N + 1) * np_, np.inf))), NONFINITE_INPUT),
        ("set_parameters_node N+1", lambda: fn("set_parameters_node")(s, N + 1, dbl(np.zeros(np_))), INVALID),
        ("set_parameters_node NULL", lambda: fn("set_parameters_node")(s, 0, NULL), INVALID),
    ]
    def settings():
        st = ffi.new(f"{name}_settings *")
        fn("get_settings")(s, st)
        return tuple(float(getattr(st, g)) for g in ("M", "mode", "hessian", "regularization", "reg_eps", "cost_hessian",
                                                     "lm_auto", "lm", "qp_tol", "qp_max_iter", "qp_warm_start",
                                                     "recovery", "recovery_failures"))

    def get(f, n):
        out = np.zeros(n)
        fn(f"get_{f}")(s, dbl_out(out))
        return out

    dbl_out = lambda a: ffi.from_buffer("double[]", a)  # noqa: E731
    guess = second_solution[0]

    def init():
        return int(fn("init")(s, dbl(x0), dbl(np.ravel(guess.x)), dbl(np.ravel(guess.u)), NULL, NULL, NULL, NULL,
                              NULL, NULL))

    assert int(fn("setup")(s, NULL)) == OK
    before, p_before = settings(), get("parameters", (N + 1) * np_)
    for label, call, status in cases:
        got = int(call())
        assert got == status, f"{label}: status {got}, documented {status}"
        assert int(info().status) == status
    assert settings() == before
    assert np.array_equal(get("parameters", (N + 1) * np_), p_before)
    # initialised: the order and input cases
    assert init() == OK
    x_init = get("x", (N + 1) * nx)
    more = [
        ("prepare after init", lambda: fn("prepare")(s), ALREADY_PREPARED),
        ("feedback NULL xhat0", lambda: fn("feedback")(s, NULL, dbl(u0)), NONFINITE_INPUT),
        ("feedback NaN xhat0", lambda: fn("feedback")(s, dbl(nan_x), NULL), NONFINITE_INPUT),
        ("kkt NaN xhat0", lambda: fn("kkt_eval")(s, dbl(nan_x), NULL), NONFINITE_INPUT),
        ("init NaN guess x", lambda: fn("init")(s, dbl(x0), dbl(np.full((N + 1) * nx, np.nan)), NULL, NULL, NULL,
                                                NULL, NULL, NULL, NULL), NONFINITE_INPUT),
    ]
    for label, call, status in more:
        got = int(call())
        assert got == status, f"{label}: status {got}, documented {status}"
    # init rejected for its input leaves the solver uninitialised but the iterate unchanged
    assert np.array_equal(get("x", (N + 1) * nx), x_init) and not info().initialized
    assert init() == OK
    assert int(fn("feedback")(s, dbl(x0), NULL)) == OK
    assert int(fn("feedback")(s, dbl(x0), NULL)) == NOT_PREPARED
    assert int(fn("prepare")(s)) == OK
    assert int(fn("prepare")(s)) == ALREADY_PREPARED
    assert ffi.string(fn("status_string")(10)).decode() == "already prepared (call feedback before the next prepare)"
    assert ffi.string(fn("status_string")(-1)).decode() == "unknown status"
    print(f"\nC API through cffi: {len(cases) + len(more) + 2} bad-input cases with their documented statuses")
