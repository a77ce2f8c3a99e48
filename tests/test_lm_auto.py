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
import pytest

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
# A file-scope ring filled with the stage blocks Ht (N nw x nw) and Phit (N nx x nw),
# column-major: the start of every harness below.
_RING_FILL = r"""
#include "{name}_lm.h"

static {name}_ring ring;
static void ring_fill(const {name}_real *Ht, const {name}_real *Phit)
{{
    int k, i;
    {name}_ring_reset(&ring);
    for (k = 0; k < {NAME}_N; ++k) {{
        {name}_stage_slot *slot = {name}_ring_stage(&ring, k);
        for (i = 0; i < {NAME}_NW * {NAME}_NW; ++i)
            slot->Ht[i] = Ht[k * {NAME}_NW * {NAME}_NW + i];
        for (i = 0; i < {NAME}_NX * {NAME}_NW; ++i)
            slot->Phit[i] = Phit[k * {NAME}_NX * {NAME}_NW + i];
    }}
}}
"""

_GATE_HARNESS = _RING_FILL + r"""
/* dopus_lm_near_convex on the stage blocks Ht (N nw x nw), Phit (N nx x nw) and the terminal
 * block A_N (nx x nx), all column-major, with the term's state (scale, lm, uncapped, on). */
int gate_decision(const {name}_real *Ht, const {name}_real *Phit, const {name}_real *A_N, {name}_real scale,
                  {name}_real lm, {name}_real uncapped, int on);
int gate_decision(const {name}_real *Ht, const {name}_real *Phit, const {name}_real *A_N, {name}_real scale,
                  {name}_real lm, {name}_real uncapped, int on)
{{
    {name}_real work[{NAME}_LM_WORK];
    {name}_lm st;
    ring_fill(Ht, Phit);
    {name}_lm_reset(&st, on, lm);
    st.lm = lm;
    st.scale = scale;
    st.uncapped = uncapped;
    return {name}_lm_near_convex(&st, &ring, A_N, work);
}}
"""


def _harness_library(disc, tmp_path, harness: str, cdef: str, stem: str, defines=()):
    """The lm and ring modules of the generated folder (tmp_path / "gen", generated once)
    alone, with a C harness (a format string of name and NAME), compiled with the project's
    strict flags and -D defines as the shared library lib<stem>.so (cffi, declared by cdef)."""
    import subprocess

    import cffi

    from dopus_codegen.codegen.flags import DEFAULT_OPT, PIC, STRICT_CFLAGS
    from dopus_codegen.codegen.generate import generate

    folder = tmp_path / "gen"
    if not folder.exists():
        generate(disc, folder, offline_guess=False)
    name = disc.data.name
    src = tmp_path / f"{stem}.c"
    src.write_text(harness.format(name=name, NAME=name.upper()))
    so = tmp_path / f"lib{stem}.so"
    subprocess.run(["cc", *STRICT_CFLAGS, DEFAULT_OPT, PIC, *(f"-D{d}" for d in defines), "-shared", f"-I{folder}",
                    str(src), str(folder / f"{name}_lm.c"), str(folder / f"{name}_ring.c"), "-o", str(so), "-lm"],
                   check=True)
    ffi = cffi.FFI()
    ffi.cdef(cdef)
    return ffi, ffi.dlopen(str(so))


def _gate_library(disc, tmp_path):
    """A ring filled and the gate (dopus_lm_near_convex) called, as a shared library (cffi)."""
    return _harness_library(disc, tmp_path, _GATE_HARNESS,
                            "int gate_decision(const double *Ht, const double *Phit, const double *A_N, double scale,"
                            " double lm, double uncapped, int on);", "gate")


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


# ------------------------------------------------------------------ the two-wide vector path (nx >= 8)
_VEC_HARNESS = _RING_FILL + r"""
/* The convexity test through dopus_lm_near_convex with a capped term lm (its raised term
 * lm * DOPUS_LM_RAISE tested, the prepared term at the maximum: no certificate) on the stage
 * blocks Ht (N nw x nw), Phit (N nx x nw) and A_N (nx x nx), column-major; P out: the
 * test's P (nx x nx) when it returns (P_1 after a pass, P_(k+1) after a refusal at stage k).
 * lm_start: the term dopus_lm_start reaches from 0 on the same blocks. */
int vec_test(const {name}_real *Ht, const {name}_real *Phit, const {name}_real *A_N, {name}_real scale,
             {name}_real lm, {name}_real *P);
int vec_test(const {name}_real *Ht, const {name}_real *Phit, const {name}_real *A_N, {name}_real scale,
             {name}_real lm, {name}_real *P)
{{
    {name}_real work[{NAME}_LM_WORK];
    {name}_lm st;
    int i, r;
    ring_fill(Ht, Phit);
    {name}_lm_reset(&st, 1, 0.0);
    st.lm = lm;
    st.scale = scale;
    st.uncapped = {NAME}_LM_MAX_REL * scale;
    r = {name}_lm_near_convex(&st, &ring, A_N, work);
    for (i = 0; i < {NAME}_NX * {NAME}_NX; ++i)
        P[i] = work[i];
    return r;
}}
{name}_real vec_start(const {name}_real *Ht, const {name}_real *Phit, const {name}_real *A_N);
{name}_real vec_start(const {name}_real *Ht, const {name}_real *Phit, const {name}_real *A_N)
{{
    {name}_real work[{NAME}_LM_WORK];
    {name}_lm st;
    ring_fill(Ht, Phit);
    {name}_lm_reset(&st, 1, 0.0);
    {name}_lm_start(&st, &ring, A_N, work);
    return st.lm;
}}
/* The secant's linear model (dopus_ring_predict) of one slot. */
void vec_predict(const {name}_real *in, {name}_real *F_w, {name}_real *phi, {name}_real *g);
void vec_predict(const {name}_real *in, {name}_real *F_w, {name}_real *phi, {name}_real *g)
{{
    {name}_stage_slot *slot = {name}_ring_stage(&ring, 0);
    {name}_real *f[] = {{slot->Ht, slot->Phit, slot->Ct, slot->F_w, slot->phi, slot->g, slot->dw, slot->dlam,
                         slot->dmu_g, slot->dmu_b}};
    const int n[] = {{{NAME}_NW * {NAME}_NW, {NAME}_NX * {NAME}_NW, {NAME}_NG * {NAME}_NW, {NAME}_NW, {NAME}_NX,
                      {NAME}_NG, {NAME}_NW, {NAME}_NX, {NAME}_NG, {NAME}_NW}};
    int a, i;
    for (a = 0; a < 10; ++a) {{
        for (i = 0; i < n[a]; ++i)
            f[a][i] = *in++;
    }}
    {name}_ring_predict(slot, F_w, phi, g);
}}
"""


def _vec_library(disc, tmp_path, vec: int):
    """The lm and ring modules with _VEC_HARNESS, the two-wide vectors on (vec = 1, the
    default on x86-64 and AArch64) or off (DOPUS_LAI_VEC = 0, prefixed with the problem name in
    the generated folder: the plain loops)."""
    return _harness_library(disc, tmp_path, _VEC_HARNESS,
                            "int vec_test(const double *Ht, const double *Phit, const double *A_N, double scale,"
                            " double lm, double *P); double vec_start(const double *Ht, const double *Phit,"
                            " const double *A_N); void vec_predict(const double *in, double *F_w, double *phi,"
                            " double *g);", f"vec{vec}", (f"{disc.data.name.upper()}_LAI_VEC={vec}",))


def _riccati_P(H, Phi, A_N, lm, tol):
    """The Riccati recursion of the convexity test by dense solves, independent of the
    reference's and the C runtime's Cholesky: (passed, P) with P = P_1 after a pass and
    P_(k+1) (the one that stage k's pivots failed on) after a refusal."""
    nx, nw = Phi[0].shape
    P = A_N + lm * np.eye(nx)
    for k in range(len(H) - 1, -1, -1):
        Z = H[k] + lm * np.eye(nw) + Phi[k].T @ P @ Phi[k]
        Zuu = Z[nx:, nx:]
        try:
            L = np.linalg.cholesky(Zuu)
        except np.linalg.LinAlgError:
            return False, P
        if not np.diag(L).min() ** 2 > tol:
            return False, P
        if k == 0:
            return True, P
        Pn = Z[:nx, :nx] - Z[:nx, nx:] @ np.linalg.solve(Zuu, Z[nx:, :nx])
        P = 0.5 * (Pn + Pn.T)


@pytest.fixture(scope="module")
def chain_disc():
    from conftest import ROOT
    return build_functions(load_ocp(ROOT / "examples" / "chain.py"))


def test_convexity_test_vector_path_against_the_reference(chain_disc, tmp_path):
    """The convexity test and the secant's linear model at nx = 21 (the chain of masses),
    where the two-wide kernels run (DOPUS_LM_VEC, DOPUS_RING_V2: nx >= 8; odd nx, even nw, an
    odd count of control columns at stage 0), on random indefinite stage blocks: the C
    decision equals the reference's (ReferenceDopus.lm_convex) 1e-6 relative on either side of
    lm* (the smallest term the reference passes, by bisection) and at a grid of terms; the C
    test's P equals a Riccati recursion by dense solves (1e-8 relative) and the plain loops'
    P (DOPUS_LAI_VEC = 0) bit for bit; dopus_lm_start's term equals the reference's
    lm_convexify; dopus_ring_predict equals the linear model of the reference's secant
    criterion (F + [H -Phi' C' I] domega, phi + Phi dw, g + C dw) and the plain loops bit
    for bit."""
    disc = chain_disc
    nx, nw, N = disc.nx, disc.nx + disc.nu, disc.N
    assert nx >= 8 and nx % 2 == 1 and nw % 2 == 0
    libs = {v: _vec_library(disc, tmp_path, v) for v in (1, 0)}
    r = ReferenceDopus(disc, lm=0.0)
    r.init(disc.x0)
    rng = np.random.default_rng(24)
    dbl = "double[]"
    decided = {True: 0, False: 0}
    for trial in range(6):
        # random blocks: H symmetric with its control block shifted down (indefinite: some
        # term needed), its strict upper triangle NaN for C (the runtime's H holds other data
        # there); Phi = [A B] with A about I
        H, Phi = [], []
        for k in range(N):
            G = rng.standard_normal((nw, nw))
            Hk = G @ G.T / nw
            Hk[nx:, nx:] -= np.diag(rng.uniform(0.0, 1.0 + trial, nw - nx))
            H.append(Hk)
            Phi.append(np.hstack([np.eye(nx) + 0.3 * rng.standard_normal((nx, nx)) / np.sqrt(nx),
                                  0.1 * rng.standard_normal((nx, nw - nx))]))
        G = rng.standard_normal((nx, nx))
        A_N = G @ G.T / nx
        for k in range(N):
            r.slot_of(k).Ht, r.slot_of(k).Phit = H[k].copy(), Phi[k].copy()
        r.term["A"] = A_N.copy()
        h = r.lm_scale = r.lm_hessian_scale()
        tol = 1e-10 * h
        Hc = np.concatenate([np.where(np.tril(np.ones((nw, nw))) > 0, Hk, np.nan).ravel(order="F") for Hk in H])
        Pc = np.concatenate([p.ravel(order="F") for p in Phi])
        Ac = A_N.ravel(order="F").copy()
        lo, hi = 1e-8 * h, 1e2 * h
        assert not r.lm_convex(lo) and r.lm_convex(hi), trial
        star = _smallest_convex_term(r, lo, hi)

        def c_test(lm, v):
            ffi, lib = libs[v]
            P = np.zeros(nx * nx)
            d = lib.vec_test(ffi.from_buffer(dbl, Hc), ffi.from_buffer(dbl, Pc), ffi.from_buffer(dbl, Ac), h,
                             lm, ffi.from_buffer(dbl, P))
            return bool(d), P.reshape((nx, nx), order="F")

        # the capped term c is tested at its raise 10 c (the same product in both backends)
        terms = [star / 10.0 * (1.0 - 1e-6), star / 10.0 * (1.0 + 1e-6)]
        terms += list(star / 10.0 * np.logspace(-2, 2, 9))
        terms = [c for c in terms if lo <= c and 10.0 * c <= hi]
        for c in terms:
            ref = r.lm_convex(10.0 * c)
            dec, P = c_test(c, 1)
            dec0, P0 = c_test(c, 0)
            assert dec == ref == dec0, (trial, c / star, ref, dec, dec0)
            assert np.array_equal(P, P0), (trial, c / star)
            passed, P_ref = _riccati_P(H, Phi, A_N, 10.0 * c, tol)
            assert passed == ref, (trial, c / star)
            if abs(10.0 * c / star - 1.0) > 1e-3:      # P off the threshold (well conditioned)
                np.testing.assert_allclose(P, P_ref, rtol=0, atol=1e-8 * np.abs(P_ref).max())
            decided[ref] += 1
        # the start: lm from 0 raised until convex, the same term in both backends
        r.lm_auto, r.lm, r.lm_uncapped = True, 0.0, -1.0
        r.lm_convexify()
        for v in (1, 0):
            ffi, lib = libs[v]
            lm_c = lib.vec_start(ffi.from_buffer(dbl, Hc), ffi.from_buffer(dbl, Pc), ffi.from_buffer(dbl, Ac))
            assert lm_c == r.lm, (trial, v, lm_c, r.lm)
        r.lm_auto, r.lm = False, 0.0
        # the secant's linear model of one slot
        ng = disc.ng
        parts = [H[0], Phi[0], rng.standard_normal((ng, nw)), rng.standard_normal(nw), rng.standard_normal(nx),
                 rng.standard_normal(ng), rng.standard_normal(nw), rng.standard_normal(nx),
                 rng.standard_normal(ng), rng.standard_normal(nw)]
        Ht, Phit, Ct, F_w, phi, g, dw, dlam, dmu_g, dmu_b = parts
        flat = np.concatenate([p.ravel(order="F") for p in parts])
        flat[:nw * nw] = Hc[:nw * nw]
        ref_F = F_w + Ht @ dw - Phit.T @ dlam + Ct.T @ dmu_g + dmu_b
        ref_phi, ref_g = phi + Phit @ dw, g + Ct @ dw
        out = {}
        for v in (1, 0):
            ffi, lib = libs[v]
            o = (np.zeros(nw), np.zeros(nx), np.zeros(max(ng, 1)))
            lib.vec_predict(ffi.from_buffer(dbl, flat), *(ffi.from_buffer(dbl, a) for a in o))
            out[v] = o
        for a, b, ref in zip(out[1], out[0], (ref_F, ref_phi, ref_g)):
            assert np.array_equal(a, b)
            np.testing.assert_allclose(a[:ref.size], ref, rtol=0, atol=1e-12 * (1.0 + np.max(np.abs(ref), initial=0.0)) * nw)
    print("vector path decisions (passed, refused):", decided)
    assert decided[True] >= 12 and decided[False] >= 12, decided
