"""The generated solver on emulated Cortex-M cores: M7 in double and in float (QEMU
mps2-an500), M4F in float (mps2-an386, single-precision FPU).

The firmware program of firmware/ runs the fixed-xhat_0 study (M = 1 and the full RTI, warm
start at the nominal solution, disturbed state) and a closed loop against the generated
integrator; the same program built for the host is the reference of the emulated run, and
IPOPT at the disturbed state the reference of the converged solution.

Tolerance of the emulated double run against the host build: 1e-9 relative (each printed
vector in its inf-norm). Both builds run the same C with -std=c99 (no contraction into FMA,
IEEE double on both sides, sqrt correctly rounded), so the only difference is the maths
library: newlib's sin and cos differ from glibc's in the last bit (1.1e-16 relative) for a
few percent of arguments, and the iteration carries such differences through the QP's
Riccati factorisations (the robot arm's weights span 1e-3 to 1e4) and the KKT measure; a
last-bit difference amplified by the conditioning of these systems stays below 1e-9
(measured: about 1e-14 on the iterates of this scenario). The KKT measure is compared
relative to max(KKT, 1): it is a residual, the difference of terms of order one and more,
so its rounding error is absolute (measured: 5e-15 where it reads 1e-9).

Float builds (``real="float"``): the emulated M7 and M4F builds are checked against IPOPT
and the double build, not bit for bit against the host float build (newlib's sinf and cosf
differ from glibc's in the last bit, and in float a last-bit difference is 6e-8, which the
iteration carries to the size of the QP tolerance 1e-5). The fixed-xhat_0 study converges to
the float floor of the KKT measure, ``KKT_FLOAT`` (the justification is that of
tests/test_float.py: one rounding of the stationarity rows, whose terms reach 1e2, is 6e-6);
the full RTI's solution is within ``SOL_FLOAT`` of IPOPT's (tests/test_float.py); the closed
loop's states stay within ``LOOP_FLOAT`` of the double build's (absolute; the states reach
4 rad/s): a QP solved to 1e-5 instead of 1e-10 moves a control that sits at a switching
point of the bang-bang torque by about 1e-2 at some instants, which the plant integrates
over one sampling interval (measured: 2e-3 on the host and on both cores).

Needs gcc-arm-none-eabi, libnewlib-arm-none-eabi and qemu-system-arm; installed by
scripts/setup_firmware.sh when running as root, else the tests are skipped with the reason.
"""
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from dopus_lab import firmware as fwm

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = ROOT / "examples" / "robot_arm.py"
TOL_HOST = 1e-9
FLOAT_TARGETS = ("m7-float", "m4f-float")
KKT_FLOAT = 2e-5
SOL_FLOAT = 5e-3
LOOP_FLOAT = 2e-2


@pytest.fixture(scope="module")
def toolchain():
    missing = fwm.setup_toolchain()
    if missing:
        if os.geteuid() == 0:
            pytest.fail(f"scripts/setup_firmware.sh ran as root and {missing} are still missing")
        pytest.skip(f"firmware toolchain not installed and not root: missing {missing}")
    return True


@pytest.fixture(scope="module")
def report(toolchain, tmp_path_factory):
    out = tmp_path_factory.mktemp("firmware")
    return fwm.firmware_report(EXAMPLE, out, targets=("m7-double", *FLOAT_TARGETS), fixed_iters=12, loop_steps=20,
                               json_out=out / "report.json", progress=lambda *_: None)


def test_emulated_double_reproduces_the_host_build(report):
    s = report["targets"]["m7-double"]
    assert s["end_status"] == 0
    for key, d in s["host_compare"].items():
        assert d <= TOL_HOST, f"{key}: emulated M7 double differs from the host build by {d:.3g} (relative)"


def test_emulated_full_rti_reaches_ipopt_solution(report, robot_disc):
    """The full RTI of the fixed-xhat_0 study converges (quadratically) on the M7 to the
    solution IPOPT finds for the disturbed initial state."""
    from dopus_codegen.reference.offline import solve_ocp

    s = report["targets"]["m7-double"]
    kkt = s["kkt"]["full"]
    assert kkt[-1] <= 1e-9 and kkt[0] > 1e-3
    xf = np.array(report["xhat_fixed"])
    sol, info = solve_ocp(robot_disc, xf)
    assert info["success"]
    N = robot_disc.N
    x = np.array(s["solution"][str(N - 1)]["x"]).reshape(N + 1, -1)
    u = np.array(s["solution"][str(N - 1)]["u"]).reshape(N, -1)
    # KKT 5e-11 and the weakest reduced curvature of the robot arm (about 2e-5, docs/design.md section 8)
    # bound the primal error by about 2.5e-6; the interior-point QP (tolerance 1e-10) keeps
    # active torques 1e-8 inside their bounds
    tol = 1e-5
    assert np.max(np.abs(x - sol.x)) <= tol * max(1.0, np.max(np.abs(sol.x)))
    assert np.max(np.abs(u - sol.u)) <= tol * max(1.0, np.max(np.abs(sol.u)))
    # M = 1 converges too (fresh cost Hessian: below 1e-8 within the 12 iterations)
    assert min(s["kkt"]["M1"]) <= 1e-8


@pytest.mark.parametrize("target", FLOAT_TARGETS)
def test_emulated_float_converges_and_tracks(report, robot_disc, target):
    """M7 float and M4F float: the fixed-xhat_0 study (M = 1 and the full RTI) reaches the
    float floor of the KKT measure and stays there, the full RTI's solution is IPOPT's to
    float accuracy, and the closed loop follows the double build."""
    from dopus_codegen.reference.offline import solve_ocp

    s = report["targets"][target]
    assert s["end_status"] == 0 and s["real_bytes"] == 4
    for label in ("M1", "full"):
        kkt = s["kkt"][label]
        first = next(i for i, k in enumerate(kkt) if k <= KKT_FLOAT)
        assert max(kkt[first:]) <= KKT_FLOAT, (label, kkt)
    sol, info = solve_ocp(robot_disc, np.array(report["xhat_fixed"]))
    assert info["success"]
    N = robot_disc.N
    x = np.array(s["solution"][str(N - 1)]["x"]).reshape(N + 1, -1)
    u = np.array(s["solution"][str(N - 1)]["u"]).reshape(N, -1)
    assert np.max(np.abs(x - sol.x)) <= SOL_FLOAT * np.max(np.abs(sol.x))
    assert np.max(np.abs(u - sol.u)) <= SOL_FLOAT * np.max(np.abs(sol.u))
    assert s["loop_deviation_vs_host_double"] <= LOOP_FLOAT


def test_float_halves_the_solver_and_the_m4f_needs_no_double(report):
    """The float solver struct is about half the double one; the M4F (single-precision FPU
    only) runs the float build in about the M7's instruction count, which it could not if
    any double operation were left (software emulation: 135 M instructions per iteration
    for the double build on the M4F)."""
    d, m7, m4 = (report["targets"][t] for t in ("m7-double", "m7-float", "m4f-float"))
    assert m7["solver_bytes"] <= 0.55 * d["solver_bytes"]
    assert m4["solver_bytes"] == m7["solver_bytes"]
    ratio = m4["instructions"]["M1"]["iteration_median"] / m7["instructions"]["M1"]["iteration_median"]
    assert ratio <= 1.5


def test_instruction_count_and_memory_figures(report):
    """The instruction count is exact: a loop of a known number of instructions reads back
    exactly; the solver struct lies in .bss; one iteration uses a measured stack."""
    s = report["targets"]["m7-double"]
    # exact up to the instructions of the two clock reads around the loop (their calls and the
    # loop's set-up: a few dozen, depending on the code's layout), out of 2e6
    assert abs(s["calibration_ratio"] - 1.0) * 2e6 <= 64, s["calibration_ratio"]
    assert s["ram_bss"] >= s["solver_bytes"]
    assert 0 < s["stack_iteration"] < 65536
    assert s["default_clock"] == 0          # bare metal: no default clock, timings say so
    it = s["instructions"]["M1"]
    assert it["feedback_median"] + it["prepare_median"] >= it["iteration_median"] * 0.9
    # the closed loops run the solver on the instruction clock: its phase timers of an instant
    # (all but kkt, which times the program's own kkt_eval after the instant) add up to the
    # program's count around the two calls, up to the timer reads and the tick of 40
    for key in ("steady_M1", "loop_M1"):
        r = s["instructions"][key]
        worst = r["per_instant"].index(r["iteration_max"])
        phases = sum(v for k, v in r["phases_worst"].items() if k != "kkt")
        assert abs(phases - r["iteration_max"]) <= 0.01 * r["iteration_max"], (key, phases, r["iteration_max"])
        assert worst + 1 == r["worst_instant"]
        assert len(r["per_instant"]) == len(r["factorizations"]) == 20 and min(r["factorizations"]) >= 1


def test_link_fails_on_an_allocator(toolchain, tmp_path):
    """An image that needs malloc does not link."""
    src = tmp_path / "uses_malloc.c"
    src.write_text("#include <stdlib.h>\nint main(void) { void *p = malloc(16); free(p); return p != 0; }\n")
    obj = tmp_path / "uses_malloc.o"
    subprocess.run(["arm-none-eabi-gcc", *fwm.TARGETS["m7-double"].cflags, "-c", str(src), "-o", str(obj)],
                   check=True)
    fw = fwm.firmware_dir()
    objs = [obj]
    for name in ("startup.c", "platform_qemu.c"):
        o = tmp_path / (name + ".o")
        subprocess.run(["arm-none-eabi-gcc", *fwm.TARGETS["m7-double"].cflags, "-O2", f"-I{fw}", "-c",
                        str(fw / name), "-o", str(o)], check=True)
        objs.append(o)
    with pytest.raises(fwm.FirmwareError, match="__wrap_malloc"):
        fwm.link_image("m7-double", objs, tmp_path / "uses_malloc.elf")
