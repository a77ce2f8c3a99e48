"""A byte copy of the solver struct is a complete, independent solver.

Embedded code copies the struct for a snapshot or a double buffer (``memcpy``, struct
assignment); the Python handle does the same in ``CSolver.copy_state_from``. The struct
holds no pointer into itself between calls, so the copy must neither read the original's
memory nor depend on what happens to it afterwards.

- C, under AddressSanitizer + UndefinedBehaviorSanitizer (tests/fuzz/struct_copy.c, linked
  against the robot arm's static library built by its own Makefile with clang): the struct
  is copied after a prepare and after a feedback, by struct assignment and by memcpy; the
  source is advanced two instants with other measurements, overwritten and freed; both
  copies then give the statuses, u0 and final iterate of a solver that was never copied,
  bit for bit, and ASan reports nothing (a copy that read the freed source is a
  heap-use-after-free).
- Python, through the handle: the same after ``copy_state_from``, the source advanced two
  instants and released, in the closed loop against the generated model.
"""
from __future__ import annotations

import gc
import subprocess

import numpy as np
import pytest

import sanitizer_build as SB
from dopus_codegen.runtime.solver import CSolver


def test_struct_copy_under_sanitizers(tmp_path):
    cc = SB.find_clang(tmp_path / "probe")
    if cc is None:
        pytest.fail(SB.MISSING)
    folder = tmp_path / "robot_arm"
    flags = " ".join(SB.SANITIZE + ["-g"])
    made = SB.make_run(SB.GENERATED / "robot_arm", folder, cc, "-O1", flags, env=SB.san_env())
    assert made.returncode == 0, made.stderr[-3000:]
    prog = SB.link_program(folder, SB.FUZZ_DIR / "struct_copy.c", tmp_path / "struct_copy", cc, ["-O1", "-g"],
                           SB.SANITIZE)
    proc = subprocess.run([str(prog)], capture_output=True, text=True, env=SB.san_env(), timeout=600)
    report = SB.sanitizer_report(proc.stderr + proc.stdout)
    assert report is None, f"sanitizer report:\n{report}"
    assert proc.returncode == 0, proc.stderr[-3000:]
    lines = proc.stdout.splitlines()
    assert lines[-1] == "ok"
    for where in ("after_prepare", "after_feedback"):
        assert f"{where} identical" in lines
        statuses = [l.split()[3:6] for l in lines if l.startswith(f"{where} ") and " status " in l]
        assert len(statuses) == 20
        # the loop ran: every feedback and prepare of the reference and both copies succeeded
        assert all(s == ["0", "0", "0"] for s in statuses), statuses


def _plant(disc, p0):
    return lambda x, u: np.asarray(disc.stage_eval(x, u, p0)[0], dtype=float).reshape(-1)


def test_copy_state_from_is_independent_of_the_source(robot_disc):
    src, ref, dst = (CSolver(robot_disc, M=1) for _ in range(3))
    x0 = np.asarray(robot_disc.x0, dtype=float)
    for s in (src, ref):
        s.init(x0)
    plant = _plant(robot_disc, np.asarray(ref.p[0], dtype=float))
    push = np.array(robot_disc.disturbance(x0.copy()), dtype=float).reshape(-1) - x0
    xs = xr = x0
    for k in range(6):
        us, ur = src.feedback(xs), ref.feedback(xr)
        assert us.tobytes() == ur.tobytes()
        xs, xr = plant(xs, us), plant(xr, ur)
        if k == 3:
            xs, xr = xs + push, xr + push
        src.prepare()
        ref.prepare()
    dst.copy_state_from(src)
    # the source moves on with other measurements (its iterate and ring then differ from
    # the copy's), then its memory is released
    xo = xs.copy()
    for _ in range(2):
        xo = xo + 0.1
        uo = src.feedback(xo)
        src.prepare()
    assert np.max(np.abs(uo - ref.feedback(xr))) > 1e-3   # the source's plan is another one now
    ref_state = np.array(ref.x)
    del src
    gc.collect()
    # the reference above took this instant's feedback: the copy takes the same one
    ud = dst.feedback(xr)
    assert np.array(dst.x).tobytes() == ref_state.tobytes()
    xd = xr = plant(xr, ud)
    dst.prepare()
    ref.prepare()
    for k in range(20):
        ud, ur = dst.feedback(xd), ref.feedback(xr)
        assert ud.tobytes() == ur.tobytes(), (k, ud, ur)
        xd, xr = plant(xd, ud), plant(xr, ur)
        dst.prepare()
        ref.prepare()
    for f in ("x", "u", "lam", "mu_b", "nu"):
        assert np.array(getattr(dst, f)).tobytes() == np.array(getattr(ref, f)).tobytes(), f
