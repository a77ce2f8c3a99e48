"""Robot arm, M = 1, a work budget: the drift of the iterates after the walk's last fallback.

The loop of tests/test_budget_coverage.py::test_walk_fallback_on_the_guess_states_is_priced
(one outlier of (v, v) rad/s at instant 5, recovery after 3 failures, `qp_tol` 1e-14, the
reference's control applied) run by three solvers: the C runtime, the reference and a second
reference whose measurement at instant 6 alone is perturbed by `--pert` (relative, random).
Per instant after the feedback: statuses, lm, QP iterations (and whether the C QP's warm
start was followed by its cold retry), the largest relative difference
of the iterates C - reference and reference' - reference (and where it is). From instant 6,
the feedback's QP of the reference (`qp_of_current`) is also solved by the C QP, cold
(tests/harness/qp_harness.py), and compared with the reference QP solver's solution; its
conditioning: the KKT matrix on the reference's active set (dense; the 2-norm condition
number), the reduced Hessian's eigenvalues on that active set's null space, and the relative
change of the reference's solution per relative perturbation of the QP data (1e-10,
random). bench/issue24/measurements.md section 17.

    .venv/bin/python bench/walk_drift.py [--budget 280] [--v 300] [--pert 1e-11] [--cold]
"""
from __future__ import annotations

import argparse
import pathlib
import sys

import numpy as np

from dopus_codegen import build_functions, load_ocp
from dopus_codegen.reference.dopus import ReferenceDopus
from dopus_codegen.reference.offline import solve_ocp
from dopus_codegen.reference.qp import solve_qp_reference
from dopus_codegen.runtime.solver import CSolver
from dopus_codegen.studies import loops

ROOT = pathlib.Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from harness.compare import FIELDS, rel_err  # noqa: E402
from harness.qp_harness import build_qp_solver  # noqa: E402

TOL = 1e-14


def iterate_err(a, b) -> tuple:
    """The largest relative difference of the iterates and the field and index where it is."""
    best = (0.0, "-")
    for f in FIELDS:
        A, B = np.asarray(getattr(a, f)), np.asarray(getattr(b, f))
        if B.size == 0:
            continue
        e = np.abs(A - B) / max(1.0, float(np.max(np.abs(B))))
        i = np.unravel_index(int(np.argmax(e)), e.shape)
        if e[i] > best[0]:
            best = (float(e[i]), f"{f}{tuple(int(j) for j in i)}")
    return best


def kkt_conditioning(qp: dict, sol: dict) -> tuple:
    """The KKT matrix of the QP with the solution's active rows as equalities (variables
    w_0..w_{N-1}, x_N; rows x_0's, the dynamics, the active bounds and path rows): its
    condition number, the reduced Hessian's smallest and largest eigenvalues, the null
    space's dimension, the number of active rows and the smallest eigenvalue of the Hessian on
    the null space of the equalities alone."""
    N, nx, nu, ng = int(qp["N"]), int(qp["nx"]), int(qp["nu"]), int(qp["ng"])
    nw = nx + nu
    n = N * nw + nx
    H = np.zeros((n, n))
    for k in range(N):
        H[k * nw:(k + 1) * nw, k * nw:(k + 1) * nw] = qp["H"][k]
    H[N * nw:, N * nw:] = qp["HN"]
    rows = [np.eye(n)[i] for i in range(nx)]
    n_active, n_eq = 0, 0
    for k in range(N):
        for i in range(nx):
            e = np.zeros(n)
            e[(k + 1) * nw + i if k + 1 < N else N * nw + i] = 1.0
            e[k * nw:(k + 1) * nw] -= qp["Phi"][k][i]
            rows.append(e)
        n_eq = len(rows)
        for j in range(nw):
            if sol["mu_b"][k][j] != 0 and not (k == 0 and j < nx):
                rows.append(np.eye(n)[k * nw + j])
                n_active += 1
        for j in range(ng):
            if sol["mu_g"][k][j] != 0:
                e = np.zeros(n)
                e[k * nw:(k + 1) * nw] = qp["C"][k][j]
                rows.append(e)
                n_active += 1
    for i in range(nx):
        if sol["mu_bN"][i] != 0:
            rows.append(np.eye(n)[N * nw + i])
            n_active += 1
    A = np.array(rows)
    m = A.shape[0]
    K = np.block([[H, A.T], [A, np.zeros((m, m))]])
    _, sv, vt = np.linalg.svd(A)
    Z = vt[int(np.sum(sv > 1e-12 * sv[0])):].T
    ev = np.linalg.eigvalsh(Z.T @ H @ Z) if Z.shape[1] else np.array([np.nan])
    # the Hessian on the null space of x_0's rows and the dynamics alone (no bound active):
    # negative when the QP is nonconvex there (the C QP's inertia correction)
    Zd = np.linalg.svd(A[:n_eq])[2][n_eq:].T
    ev_dyn = float(np.linalg.eigvalsh(Zd.T @ H @ Zd).min())
    return float(np.linalg.cond(K)), float(ev.min()), float(ev.max()), Z.shape[1], n_active, ev_dyn


def sensitivity(qp: dict, ref: dict, rng, eps: float = 1e-10) -> float:
    """The relative change of the reference's solution (x, u, lam) per relative random
    perturbation eps of H, g, Phi, b, x0, HN, gN."""
    q = dict(qp)
    for key in ("H", "g", "Phi", "b", "x0", "HN", "gN"):
        a = np.asarray(qp[key], dtype=float)
        q[key] = a * (1 + eps * rng.standard_normal(a.shape))
    q["H"] = 0.5 * (q["H"] + np.transpose(q["H"], (0, 2, 1)))
    q["HN"] = 0.5 * (q["HN"] + q["HN"].T)
    other = solve_qp_reference(q, tol=TOL, max_iter=100)
    return max(rel_err(other[k], ref[k]) for k in ("x", "u", "lam")) / eps


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--budget", type=float, default=280.0, help="work budget (0: off)")
    ap.add_argument("--v", type=float, default=300.0, help="the outlier's joint velocities (v, v)")
    ap.add_argument("--pert", type=float, default=1e-11, help="relative perturbation of the instant-6 measurement")
    ap.add_argument("--cold", action="store_true", help="the C runtime's QP without its warm start")
    ap.add_argument("--iters", type=int, default=16)
    a = ap.parse_args()
    disc = build_functions(load_ocp(ROOT / "examples" / "robot_arm.py"))
    guess = solve_ocp(disc, disc.x0)[0]
    c = CSolver(disc, qp_tol=TOL, M=1)
    r, r2 = ReferenceDopus(disc, qp_tol=TOL, M=1), ReferenceDopus(disc, qp_tol=TOL, M=1)
    harness = build_qp_solver(disc.N, disc.nx, disc.nu, disc.ng, disc.nr, disc.ne)
    x = np.array(disc.x0, dtype=float)
    p0 = np.asarray(r.p[0], dtype=float)
    for b in (c, r, r2):
        b.set_work_budget(a.budget)
        b.set_recovery(True, 3)
        b.init(x, guess)
    if a.cold:
        c.set_qp_warm_start(False)
    rng = np.random.default_rng(0)
    for it in range(a.iters):
        xm = x.copy()
        if it == 5:
            xm[2:4] = [a.v, a.v]
        qp = r.qp_of_current(xm) if it >= 6 else None
        xm2 = xm * (1 + a.pert * rng.standard_normal(xm.size)) if it == 6 else xm
        fc, fr, f2 = loops.feedback(c, xm), loops.feedback(r, xm), loops.feedback(r2, xm2)
        ec, ec_at = iterate_err(c, r)
        e2, e2_at = iterate_err(r2, r)
        line = (f"instant {it}: status {fc.status}/{fr.status}/{f2.status}, lm {c.lm:.3g}/{r.lm:.3g}/{r2.lm:.3g}, "
                f"QP iterations {c.qp_iterations}/{r.qp_iterations}/{r2.qp_iterations} (C/reference/reference'"
                f"{', C cold retry' if c.qp_cold_retry else ''}); "
                f"iterates C - reference {ec:.2g} at {ec_at}, reference' - reference {e2:.2g} at {e2_at}")
        if qp is not None and fr.status == 0:
            ref = solve_qp_reference(qp, tol=TOL, max_iter=100)
            sol, info = harness.solve(qp, tol=TOL, max_iter=200)
            cond, lo, hi, dim, n_active, ev_dyn = kkt_conditioning(qp, ref)
            line += (f"\n    the reference's QP: C QP cold {info['status']} in {info['iterations']} iterations, "
                     f"- reference x {rel_err(sol['x'], ref['x']):.2g} u {rel_err(sol['u'], ref['u']):.2g} "
                     f"lam {rel_err(sol['lam'], ref['lam']):.2g}; |lam| {np.abs(ref['lam']).max():.3g}, "
                     f"active rows {n_active}, KKT condition {cond:.3g}, reduced Hessian {lo:.3g} .. {hi:.3g} "
                     f"(dimension {dim}), on the dynamics' null space from {ev_dyn:.3g}, solution change per data change {sensitivity(qp, ref, rng):.3g}")
        print(line, flush=True)
        for b in (c, r, r2):
            loops.prepare(b)
        x = np.array(disc.stage_eval(x, fr.u0, p0)[0], dtype=float).reshape(-1)


if __name__ == "__main__":
    main()
