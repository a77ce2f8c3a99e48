"""The automatic Levenberg-Marquardt term (docs/algorithm.md section 10).

- The convexity test of both backends against an independent computation: the reduced
  Hessian of the QP without inequalities (the Hessian projected on the null space of the
  dynamics with x_0 fixed, formed densely with numpy) is positive definite exactly when
  the Riccati test passes, on the robot arm's exact-Hessian QPs with a range of lm.
- The active-set start's gate on the term (docs/algorithm.md section 4, feedback) against the
  same computation: a capped term passes exactly when the reduced Hessian with the term
  raised once is positive definite.
- The robot arm with the exact Hessian and the default settings (the OCP file declares no
  lm) at N = 80, where the fixed lm = 1e-4 of earlier versions failed 247 of 300 QPs:
  closed loop of the scenario against the CVODES plant with no QP failure, DOPUS M = 1
  within 20 % of the full RTI (RMS tip deviation).
"""
from __future__ import annotations

import re

import numpy as np

from dopus_codegen import build_functions, load_ocp
from dopus_codegen.reference.dopus import ReferenceDopus
from dopus_codegen.runtime.solver import CSolver

from conftest import ROBOT_ARM_FILE


def reduced_hessian_min_eig(qp: dict, lm: float) -> float:
    """Smallest eigenvalue of the QP Hessian (plus lm I) on the null space of the dynamics
    with x_0 fixed: the controls are free, the states follow them linearly."""
    N, nx, nu = qp["N"], qp["nx"], qp["nu"]
    nw = nx + nu
    # w = T v + const, v = (u_0 .. u_{N-1}), x_0 fixed (dx_0 = 0)
    T = np.zeros((N * nw + nx, N * nu))
    Sx = np.zeros((nx, N * nu))               # d x_k / d v
    for k in range(N):
        T[k * nw:k * nw + nx] = Sx
        T[k * nw + nx:(k + 1) * nw, k * nu:(k + 1) * nu] = np.eye(nu)
        A, B = qp["Phi"][k][:, :nx], qp["Phi"][k][:, nx:]
        Sx = A @ Sx
        Sx[:, k * nu:(k + 1) * nu] += B
    T[N * nw:] = Sx
    H = np.zeros((N * nw + nx, N * nw + nx))
    for k in range(N):
        Hk = qp["H"][k]
        H[k * nw:(k + 1) * nw, k * nw:(k + 1) * nw] = 0.5 * (Hk + Hk.T)
    H[N * nw:, N * nw:] = 0.5 * (qp["HN"] + qp["HN"].T)
    H += lm * np.eye(H.shape[0])
    return float(np.linalg.eigvalsh(T.T @ H @ T).min())


def test_convexity_test_against_the_reduced_hessian(robot_disc, robot_solution):
    r = ReferenceDopus(robot_disc, lm=0.0)
    c = CSolver(robot_disc, lm=0.0)
    xhat = np.array(robot_disc.disturbance(np.array(robot_disc.x0, dtype=float)), dtype=float)
    for b in (c, r):
        b.init(robot_disc.x0, robot_solution[0])
    checked = {True: 0, False: 0}
    for it in range(6):
        qp = r.qp_of_current(xhat)      # lm = 0: the blocks themselves
        r.lm_scale = r.lm_hessian_scale()
        for lm in [0.0] + list(np.logspace(-7, -1, 13) * r.lm_scale):
            eig = reduced_hessian_min_eig(qp, lm)
            passes = r.lm_convex(lm)
            if abs(eig) > 1e-6 * r.lm_scale:          # away from the pivot threshold
                assert passes == (eig > 0), (it, lm, eig)
                checked[passes] += 1
        for b in (c, r):
            b.feedback(xhat)
            b.prepare()
    assert checked[True] > 10 and checked[False] >= 3, checked


def test_active_set_gate_against_the_reduced_hessian(robot_disc, robot_solution):
    """The gate of the active-set start on the automatic term: the prepared term (the
    smallest of the raise grid 1e-8 h * 10^j that the test passes) is let through, a term at
    the maximum is not, and a capped term is let through exactly when the QP's reduced Hessian
    (numpy, as above) with the capped term raised once (to 1e-8 h from below that, else times
    10) is positive definite: the prepare's certificate and the gate's own test agree with it."""
    r = ReferenceDopus(robot_disc, lm=0.0)
    xhat = np.array(robot_disc.disturbance(np.array(robot_disc.x0, dtype=float)), dtype=float)
    r.init(robot_disc.x0, robot_solution[0])
    checked = {True: 0, False: 0}
    for it in range(4):
        qp = r.qp_of_current(xhat)      # lm = 0: the blocks themselves
        h = r.lm_scale = r.lm_hessian_scale()
        lm_p = next(v for v in 1e-8 * h * 10.0 ** np.arange(11) if r.lm_convex(v))
        try:
            r.lm_auto, r.lm, r.lm_uncapped = True, lm_p, -1.0
            assert r.lm_near_convex()
            r.lm = 1e2 * h
            assert not r.lm_near_convex()
            for c in [0.0] + list(np.logspace(-3, 0, 13, endpoint=False) * lm_p):
                r.lm, r.lm_uncapped = c, lm_p
                eig = reduced_hessian_min_eig(qp, 1e-8 * h if c < 1e-8 * h else 10.0 * c)
                passes = r.lm_near_convex()
                if abs(eig) > 1e-6 * h:          # away from the pivot threshold
                    assert passes == (eig > 0), (it, c / lm_p, eig)
                    checked[passes] += 1
        finally:
            r.lm_auto, r.lm, r.lm_uncapped = False, 0.0, -1.0
        r.feedback(xhat)
        r.prepare()
    assert checked[True] > 10 and checked[False] >= 3, checked


def _arm_with_horizon(tmp_path, N: int):
    src = ROBOT_ARM_FILE.read_text()
    assert "lm=" not in src.split("ocp.options(")[1].split(")")[0]   # the default: automatic
    f = tmp_path / f"robot_arm_{N}.py"
    f.write_text(re.sub(r"^N, DT = \d+,", f"N, DT = {N},", src, flags=re.M))
    disc = build_functions(load_ocp(f))
    assert disc.N == N
    return disc


def test_robot_arm_exact_hessian_default_settings_n80(tmp_path):
    from dopus_codegen.reference.offline import solve_ocp
    from dopus_codegen.studies.sil import run_closed_loop, summarize

    disc = _arm_with_horizon(tmp_path, 80)
    guess, _ = solve_ocp(disc, disc.x0)
    rms = {}
    for M in (1, disc.N - 1):
        run = run_closed_loop(disc, backend="c", M=M, hessian="exact", lm=None, guess=guess)
        s = summarize(run)
        assert s["qp_failures"] == 0, (M, s["qp_failures"])
        assert s["aborted"] is None
        assert s["bound_violation"] == 0.0
        rms[M] = max(seg["rms"] for seg in s["segments"] if seg["signal"] == "deviation")
    print(f"robot arm N = 80, exact Hessian, lm auto: RMS deviation M = 1 {rms[1]:.3e}, full {rms[disc.N - 1]:.3e}")
    assert rms[1] <= 1.2 * rms[disc.N - 1]
