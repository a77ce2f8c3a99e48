"""The single-precision build (``options(real="float")``, ``--real float``) on the host.

The same robot arm generated in float and in double, both run through the Python handle
(arrays cross the cffi boundary as float32 in the float build): the fixed-xhat_0 study of
``dopus-gen converge --start warm`` (M = 1 and the full RTI) against the double build and
IPOPT, and the generated folder compiled with ``-Wdouble-promotion -Werror`` (nothing in
the float build is computed in double: a double operation is software-emulated on a
single-precision FPU).

Float tolerances (docs/algorithm.md, "Real type"):

- KKT: the measure reaches ``KKT_FLOAT = 2e-5`` and stays there. Float's rounding unit is
  6e-8; the stationarity rows of the robot arm sum terms up to about 1e2 (the gradients at
  the disturbed state), so one rounding of them is already about 6e-6, the floor the
  iteration hovers on (measured: 6e-6 to 8e-6 from the 8th iteration on); 2e-5 is three
  such roundings.
- Solution: within ``SOL_FLOAT = 5e-3`` of IPOPT's, relative to the largest entry. The
  error is largest in the weakest direction of the reduced Hessian (the terminal joint
  velocities; curvature about 2e-5 relative, docs/design.md section 8), where a KKT residual on float's
  floor moves the solution most; measured: 1.3e-3 (0.014 on a largest entry of 10.8),
  against 1e-6 for the double build.
"""
import subprocess

import numpy as np
import pytest

from dopus_codegen.codegen.flags import STRICT_CFLAGS
from dopus_codegen.codegen.generate import read_meta, render_folder, write_folder
from dopus_codegen.runtime.solver import CSolver
from dopus_codegen.studies.converge import make_start, run_study

KKT_FLOAT = 2e-5
SOL_FLOAT = 5e-3
ITERS = 12


def _factory(real):
    def make(disc, **kw):
        return CSolver(disc, real=real, **kw)
    return make


@pytest.fixture(scope="module")
def studies(robot_disc):
    start = make_start(robot_disc, "warm")
    full = robot_disc.N - 1
    return {real: run_study(robot_disc, [full, 1], ITERS, start, lm=0.0, backend_factory=_factory(real),
                            backend_name=f"c-{real}", tol=KKT_FLOAT)
            for real in ("double", "float")}, start


def test_float_study_converges_like_the_double_build(studies):
    res, _ = studies
    for run_f, run_d in zip(res["float"]["runs"], res["double"]["runs"]):
        assert run_f["status"] == "converged", run_f
        # after convergence the float iteration stays on its floor
        k = run_f["iterations_to_tol"]
        assert max(run_f["kkt"][k:]) <= KKT_FLOAT
        # the first iterations (KKT far above float's floor) follow the double build: the
        # QPs are solved to 1e-5 (float) instead of 1e-10 on their scaled residuals, which
        # moves each step, and with it the KKT measure, by about 1e-4 (measured: 1.3e-4 at
        # the third iteration, where the measure reads 5.5e-3)
        for a, b in zip(run_f["kkt"][:4], run_d["kkt"][:4]):
            assert abs(a - b) <= 1e-2 * b + 3e-4


def test_float_solution_matches_ipopt(studies, robot_disc):
    from dopus_codegen.reference.offline import solve_ocp

    res, start = studies
    sol, info = solve_ocp(robot_disc, start.xhat_fixed)
    assert info["success"]
    s = res["float"]["solution"]
    assert s["converged"] and s["M"] == robot_disc.N - 1
    for got, want in ((np.array(s["x"]), sol.x), (np.array(s["u"]), sol.u)):
        assert np.max(np.abs(got - want)) <= SOL_FLOAT * np.max(np.abs(want))


def test_handle_speaks_float64_with_a_float_build(robot_disc):
    solver = CSolver(robot_disc, real="float")
    assert solver.real == "float" and solver.meta["real"] == "float"
    assert solver.qp_tol == pytest.approx(1e-5)          # settings.QP_TOL_DEFAULT["float"]
    x0 = np.asarray(robot_disc.x0, dtype=float)
    solver.init(x0)
    u0 = solver.feedback(x0)
    assert u0.dtype == np.float64 and solver.x.dtype == np.float64
    # a value passed in comes back rounded to float, not truncated or reinterpreted
    assert np.array_equal(solver.x[0], x0.astype(np.float32).astype(np.float64))
    with pytest.raises(ValueError, match="generated in float, not double"):
        CSolver(robot_disc, lib_dir=solver.lib_dir, real="double")


def test_float_folder_has_no_double_arithmetic(robot_disc, tmp_path):
    files = render_folder(robot_disc, real="float")
    out = write_folder(files, tmp_path / "gen")
    meta = read_meta(out)
    assert meta["real"] == "float"
    assert "#define ROBOT_ARM_REAL_FLOAT 1" in files["robot_arm_sizes.h"]
    assert "typedef float robot_arm_real;" in files["robot_arm_cdef.h"]
    for src in sorted(meta["sources"]["strict"]) + [meta["sources"]["casadi"]]:
        subprocess.run(["cc", *STRICT_CFLAGS, "-O1", "-Wdouble-promotion", "-c", str(out / src), "-o",
                        str(tmp_path / (src + ".o"))], check=True, cwd=out)


def test_real_setting_and_its_qp_tolerance():
    """``real`` is a setting of dopus_codegen.settings: checked, and the default QP
    tolerance follows it unless the command line or the file gives one."""
    from dopus_codegen import settings
    from dopus_codegen.problem.ocp import Ocp, OcpError

    names = ("qp_tol", "real")
    values, sources = settings.resolve({"real": "float"}, {}, names=names)
    assert values == {"qp_tol": 1e-5, "real": "float"} and sources["real"] == settings.SOURCE_FILE
    values, _ = settings.resolve({"real": "float"}, {"real": "double"}, names=names)
    assert values["qp_tol"] == 1e-10
    values, sources = settings.resolve({"real": "float"}, {"qp_tol": 1e-6}, names=names)
    assert values["qp_tol"] == 1e-6 and sources["qp_tol"] == settings.SOURCE_CLI
    with pytest.raises(settings.SettingError, match="real must be 'double' or 'float', got 'single'"):
        settings.validate("real", "single")
    with pytest.raises(OcpError, match="real must be"):
        Ocp("x").options(real="half")
