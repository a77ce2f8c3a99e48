"""Robot arm, M = 1, a work budget: where the C runtime and the reference part in the outlier loop.

The closed loop of tests/test_anytime.py's outlier loop (three measurements with joint
velocities (v, -v) from instant 5, both backends fed the same measurements, the reference's
control applied): per instant the feedback's status, the automatic lm after the feedback (its
retries included) and after the prepare, the work of the instant (feedback and prepare), the
flags, the KKT proxy and the largest relative difference of the iterates. Before each prepare
that follows a failed feedback it takes the QP of the predicted step (docs/algorithm.md
section 9: the prepared QP, lm after the retries, dx_0 = 0) and solves it with the C QP
(tests/harness/qp_harness.py) at the loop's QP tolerance and with the reference QP solver:
the C status, its scaled stationarity, that of the reference's solution in the C QP's
measure, the largest multiplier lam and the round-off floor eps |lam|_max / scale.
bench/issue24/measurements.md section 12.

    .venv/bin/python bench/outlier_split.py [--budget 300] [--v 1e4] [--qp-tol 1e-14] [--iters 14]
"""
from __future__ import annotations

import argparse
import pathlib
import sys

import numpy as np

from dopus_codegen import build_functions, load_ocp
from dopus_codegen.reference.dopus import ReferenceDopus
from dopus_codegen.reference.offline import solve_ocp
from dopus_codegen.reference.qp import QPError, solve_qp_reference
from dopus_codegen.runtime.solver import CSolver
from dopus_codegen.studies import loops

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from harness.compare import rel_err, iterate_err  # noqa: E402
from harness.qp_harness import build_qp_solver  # noqa: E402


def stationarity(qp: dict, sol: dict) -> tuple:
    """The stationarity residual of a QP solution (dopus_codegen.reference.qp's equations), the
    C QP's scale of it (max(1, |H w|, |A' y|), entry-wise over the stages) and the largest
    multiplier lam."""
    N, nu = int(qp["N"]), int(qp["nu"])
    res, scale = 0.0, 1.0
    for k in range(N):
        w = np.concatenate([sol["x"][k], sol["u"][k]])
        hw = qp["H"][k] @ w
        a = np.concatenate([sol["lam"][k], np.zeros(nu)]) - qp["Phi"][k].T @ sol["lam"][k + 1] + sol["mu_b"][k]
        res = max(res, float(np.abs(hw + qp["g"][k] + a).max()))
        scale = max(scale, float(np.abs(hw).max()), float(np.abs(a).max()))
    hN = qp["HN"] @ sol["x"][N]
    rN = hN + qp["gN"] + sol["lam"][N] + sol["mu_bN"]
    if int(qp["ne"]) > 0:
        rN = rN + qp["Req"].T @ sol["nu"]
    res = max(res, float(np.abs(rN).max()))
    return res, max(scale, float(np.abs(hN).max())), float(np.abs(sol["lam"]).max())


def predicted_qp(r, qp_tol, harness) -> str:
    qp = r.qp_of_current(r.x[0])
    sol, info = harness.solve(qp, tol=qp_tol, max_iter=100)
    try:
        ref = solve_qp_reference(qp, tol=qp_tol, max_iter=100)
    except QPError as exc:
        return f"C {info['status']}, reference {exc}"
    res, scale, lam = stationarity(qp, ref)
    return (f"lm {r.lm:.6g}: C QP {info['status']} after {info['iterations']} iterations, scaled "
            f"stationarity {info['res_stat_scaled']:.3g}; reference solved, its scaled stationarity "
            f"{res / scale:.3g}; |lam|max {lam:.4g}, eps |lam|/scale {np.finfo(float).eps * lam / scale:.3g}; "
            f"C - reference: u {rel_err(sol['u'], ref['u']):.2g}, lam {rel_err(sol['lam'], ref['lam']):.2g}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--budget", type=float, default=300.0)
    ap.add_argument("--v", type=float, default=1e4, help="the outliers' joint velocities (v, -v)")
    ap.add_argument("--K", type=int, default=3, help="consecutive outliers from instant 5")
    ap.add_argument("--qp-tol", type=float, default=1e-14)
    ap.add_argument("--iters", type=int, default=14)
    a = ap.parse_args()
    disc = build_functions(load_ocp(ROOT / "examples" / "robot_arm.py"))
    guess = solve_ocp(disc, disc.x0)[0]
    c, r = CSolver(disc, qp_tol=a.qp_tol, M=1), ReferenceDopus(disc, qp_tol=a.qp_tol, M=1)
    harness = build_qp_solver(disc.N, disc.nx, disc.nu, disc.ng, disc.nr, disc.ne)
    x = np.array(disc.x0, dtype=float)
    p0 = np.asarray(r.p[0], dtype=float)
    for b in (c, r):
        b.set_work_budget(a.budget)
        b.init(x, guess)
    for it in range(a.iters):
        xm = x.copy()
        if 5 <= it < 5 + a.K:
            xm[2:4] = [a.v, -a.v]
        w0 = c.work, r.work
        fc, fr = loops.feedback(c, xm), loops.feedback(r, xm)
        lm_fb = c.lm, r.lm
        if fr.status:
            print(f"  instant {it}, the predicted step's QP: {predicted_qp(r, a.qp_tol, harness)}")
        loops.prepare(c)
        loops.prepare(r)
        e = iterate_err(c, r)
        print(f"instant {it}: status {fc.status}/{fr.status}, lm after feedback {lm_fb[0]:.6g}/{lm_fb[1]:.6g}, "
              f"after prepare {c.lm:.6g}/{r.lm:.6g}, instant work {c.work - w0[0]:g}/{r.work - w0[1]:g}, "
              f"work {c.work:g}/{r.work:g}, kkt {c.kkt_proxy:.4g}/{r.kkt_proxy:.4g}, iterates {e:.2g}, "
              f"flags {sorted(c.flags)}/{sorted(r.flags)} (C/reference)")
        x = np.array(disc.stage_eval(x, fr.u0, p0)[0], dtype=float).reshape(-1)


if __name__ == "__main__":
    main()
