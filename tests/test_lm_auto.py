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


# ------------------------------------------------------------------ the gate, C against the reference
_GATE_HARNESS = r"""
#include "{name}_lm.h"

/* dopus_lm_near_convex on the stage blocks Ht (N nw x nw), Phit (N nx x nw) and the terminal
 * block A_N (nx x nx), all column-major, with the term's state (scale, lm, uncapped, on). */
int gate_decision(const {name}_real *Ht, const {name}_real *Phit, const {name}_real *A_N, {name}_real scale,
                  {name}_real lm, {name}_real uncapped, int on);
int gate_decision(const {name}_real *Ht, const {name}_real *Phit, const {name}_real *A_N, {name}_real scale,
                  {name}_real lm, {name}_real uncapped, int on)
{{
    static {name}_ring ring;
    {name}_real work[{NAME}_LM_WORK];
    {name}_lm st;
    int k, i;
    {name}_ring_reset(&ring);
    for (k = 0; k < {NAME}_N; ++k) {{
        {name}_stage_slot *slot = {name}_ring_stage(&ring, k);
        for (i = 0; i < {NAME}_NW * {NAME}_NW; ++i)
            slot->Ht[i] = Ht[k * {NAME}_NW * {NAME}_NW + i];
        for (i = 0; i < {NAME}_NX * {NAME}_NW; ++i)
            slot->Phit[i] = Phit[k * {NAME}_NX * {NAME}_NW + i];
    }}
    {name}_lm_reset(&st, on, lm);
    st.lm = lm;
    st.scale = scale;
    st.uncapped = uncapped;
    return {name}_lm_near_convex(&st, &ring, A_N, work);
}}
"""


def _gate_library(disc, tmp_path):
    """The lm and ring modules of the generated folder alone, with a harness that fills a ring
    and calls the gate (dopus_lm_near_convex), as a shared library (cffi)."""
    import subprocess

    import cffi

    from dopus_codegen.codegen.flags import DEFAULT_OPT, PIC, STRICT_CFLAGS
    from dopus_codegen.codegen.generate import generate

    folder = generate(disc, tmp_path / "gen", offline_guess=False)
    name = disc.data.name
    src = tmp_path / "gate.c"
    src.write_text(_GATE_HARNESS.format(name=name, NAME=name.upper()))
    so = tmp_path / "libgate.so"
    subprocess.run(["cc", *STRICT_CFLAGS, DEFAULT_OPT, PIC, "-shared", f"-I{folder}", str(src),
                    str(folder / f"{name}_lm.c"), str(folder / f"{name}_ring.c"), "-o", str(so), "-lm"], check=True)
    ffi = cffi.FFI()
    ffi.cdef("int gate_decision(const double *Ht, const double *Phit, const double *A_N, double scale,"
             " double lm, double uncapped, int on);")
    return ffi, ffi.dlopen(str(so))


def _smallest_convex_term(r, lo, hi):
    """lm* of the reference's convexity test (monotone in the term): the smallest term it passes,
    by bisection between lo (refused) and hi (passed) to 1e-12 relative."""
    while hi - lo > 1e-12 * hi:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if r.lm_convex(mid) else (mid, hi)
    return hi


def test_active_set_gate_c_against_the_reference(robot_disc, robot_solution, tmp_path):
    """The gate of the active-set start (docs/algorithm.md section 4, feedback): the C decision
    (dopus_lm_near_convex, called directly on a ring filled with the reference's blocks) equals
    the reference's (ReferenceDopus.lm_near_convex) on the robot arm's exact-Hessian QPs along a
    disturbed run, for a fixed term, a term at and just below its maximum, an uncapped term, and
    capped terms on either side of each of the rule's thresholds: below and at the smallest
    nonzero term 1e-8 h, the raised term just below and at the prepared term (the prepare's
    certificate; also with a prepared term the test refuses, where only the certificate lets
    the capped term through), the raised term 1e-4 relative below and above lm* (the smallest
    term the convexity test passes: the test at the raised term decides), a prepared term at
    the maximum; and a grid of capped terms."""
    ffi, lib = _gate_library(robot_disc, tmp_path)
    nx, nw, N = robot_disc.nx, robot_disc.nx + robot_disc.nu, robot_disc.N
    r = ReferenceDopus(robot_disc, lm=0.0)
    xhat = np.array(robot_disc.disturbance(np.array(robot_disc.x0, dtype=float)), dtype=float)
    r.init(robot_disc.x0, robot_solution[0])
    decided = {"fixed": [], "uncapped": [], "certificate": [], "test": [], "lm* below": [], "lm* above": [],
               "edge refused": []}
    for it in range(4):
        Ht = np.concatenate([np.asarray(r.slot_of(k).Ht, float).ravel(order="F") for k in range(N)])
        Phit = np.concatenate([np.asarray(r.slot_of(k).Phit, float).ravel(order="F") for k in range(N)])
        A_N = np.asarray(r.term["A"], float).ravel(order="F").copy()
        assert Ht.size == N * nw * nw and Phit.size == N * nx * nw and A_N.size == nx * nx
        h = r.lm_scale = r.lm_hessian_scale()
        lo, hi = 1e-8 * h, 1e2 * h
        lm_p = next(v for v in lo * 10.0 ** np.arange(11) if r.lm_convex(v))   # the prepared term
        star = _smallest_convex_term(r, lm_p / 10.0, lm_p) if lm_p > lo else lo
        below = np.nextafter
        cases = [("fixed", 0.0, -1.0, 0), ("fixed", lm_p, lm_p, 0),
                 ("uncapped", 0.0, -1.0, 1), ("uncapped", lm_p, -1.0, 1), ("uncapped", below(hi, 0.0), -1.0, 1),
                 ("uncapped", hi, -1.0, 1), ("uncapped", hi, lm_p, 1),
                 ("certificate", lm_p / 10.0, lm_p, 1), ("certificate", lm_p, lm_p, 1),
                 ("test", below(lm_p / 10.0, 0.0), lm_p, 1), ("test", 0.0, lm_p, 1), ("test", 0.5 * lo, lm_p, 1),
                 ("test", below(lo, 0.0), lm_p, 1), ("test", lo, lm_p, 1), ("test", lm_p, hi, 1),
                 ("lm* below", star / 10.0 * (1.0 - 1e-4), lm_p, 1), ("lm* above", star / 10.0 * (1.0 + 1e-4), lm_p, 1)]
        # the certificate's own edge: a prepared term u the test refuses (u = 10 c < lm*), the
        # term c capped from it is let through (10 c >= u: certified, no test) and a term
        # just below it is not (the test at its raised term refuses it)
        c_edge = star / 20.0
        c_below = c_edge * (1.0 - 1e-12)         # (the next double may give the same 10 c)
        assert c_below * 10.0 < c_edge * 10.0
        cases += [("certificate", c_edge, c_edge * 10.0, 1), ("edge refused", c_below, c_edge * 10.0, 1)]
        if lm_p <= lo:      # the blocks convex without a term: no lm* above the smallest term
            cases = [cs for cs in cases if not cs[0].startswith(("lm*", "edge"))]
        cases += [("test", c, lm_p, 1) for c in np.logspace(-4, 0, 17, endpoint=False) * (lm_p / 10.0)]
        for kind, lm, uncapped, on in cases:
            r.lm_auto, r.lm, r.lm_uncapped = bool(on), float(lm), float(uncapped)
            ref = r.lm_near_convex()
            c = lib.gate_decision(ffi.from_buffer("double[]", Ht), ffi.from_buffer("double[]", Phit),
                                  ffi.from_buffer("double[]", A_N), h, lm, uncapped, on)
            assert bool(c) == ref, (it, kind, lm / h, uncapped / h, on, ref)
            decided[kind].append(ref)
        r.lm_auto, r.lm, r.lm_uncapped = False, 0.0, -1.0
        r.feedback(xhat)
        r.prepare()
    assert not any(decided["fixed"]) and all(decided["certificate"])
    assert decided["uncapped"].count(True) == 3 * 4 and decided["uncapped"].count(False) == 2 * 4
    assert decided["test"].count(True) > 10 and decided["test"].count(False) > 10, decided["test"]
    # either side of lm*, the test at the raised term decides both ways
    print("gate decisions (True, False):", {k: (v.count(True), v.count(False)) for k, v in decided.items()})
    assert decided["lm* below"] and not any(decided["lm* below"]) and all(decided["lm* above"]), decided
    assert decided["edge refused"] and not any(decided["edge refused"]), decided
