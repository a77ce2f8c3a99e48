"""The chain of masses (examples/chain.py, nx = 21): both backends reach IPOPT's solution
of the same NLP, and the C iterates equal the reference's.

Start: IPOPT's solution at the rest state; then the full RTI (every stage Hessian
recomputed, exact Hessian) in fixed mode for the pushed state ``shake(x0)``. Reference
solution: IPOPT (tol 1e-12) at the pushed state. As in test_c_vs_reference.py, both QP
solvers run at tolerance 1e-14 and every array is compared relative to max(1, max|ref|).
"""
from __future__ import annotations

import numpy as np
import pytest

from conftest import EXAMPLES
from dopus_codegen.problem.derivatives import build_functions
from dopus_codegen.problem.ocp import load_ocp
from dopus_codegen.reference.dopus import ReferenceDopus
from dopus_codegen.reference.offline import solve_ocp
from dopus_codegen.runtime.solver import CSolver

ITERS = 12
QP_TOL = 1e-14
FIELDS = ("x", "u", "lam", "mu_b", "mu_bN")


@pytest.fixture(scope="module")
def chain():
    disc = build_functions(load_ocp(EXAMPLES / "chain.py"))
    start, info0 = solve_ocp(disc, disc.x0)
    assert info0["success"]
    xhat = disc.disturbance(disc.x0)
    sol, info = solve_ocp(disc, xhat)
    assert info["success"]
    return disc, start, xhat, sol


def test_chain_both_backends_reach_ipopt_and_agree(chain):
    disc, start, xhat, sol = chain
    runs = {}
    for name, cls in (("reference", ReferenceDopus), ("c", CSolver)):
        s = cls(disc, M=disc.N - 1, mode="fixed", hessian="exact", qp_tol=QP_TOL)
        s.init(xhat, start)
        its = []
        for _ in range(ITERS):
            s.feedback(xhat)
            s.prepare()
            its.append({f: np.array(getattr(s, f), copy=True) for f in FIELDS})
        runs[name] = (its, s.kkt(xhat)["kkt"])
    for name, (its, kkt) in runs.items():
        assert kkt < 1e-9, (name, kkt)
        np.testing.assert_allclose(its[-1]["x"], sol.x, rtol=0, atol=1e-6)
        np.testing.assert_allclose(its[-1]["u"], sol.u, rtol=0, atol=1e-6)
        np.testing.assert_allclose(its[-1]["lam"], sol.lam, rtol=0, atol=1e-6)
    for it, (c, r) in enumerate(zip(runs["c"][0], runs["reference"][0])):
        for f in FIELDS:
            err = np.abs(c[f] - r[f]).max() / max(1.0, np.abs(r[f]).max())
            assert err <= 1e-9, f"iteration {it}: {f} differs by {err:.2e} relative"
