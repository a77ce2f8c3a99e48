"""Where the scaled float reactor's KKT floor sits (bench/issue23/measurements.md section 41).

    python bench/float_floor.py [--iters 20] [--M 29,1] [--qp-tol 1e-5,3e-7]

The warm-start study of ``dopus-gen converge`` on ``examples/cstr.py`` (the file's scales),
built in float. Per iteration: the stationarity part of the float build's KKT measure, the
same iterate's stationarity evaluated in double by the reference (``kkt_measure`` of the
scaled problem), split into the largest stage entry (stage, component) and the terminal
node's, the terminal temperature in the solver's variables, and the QP iterations. The
float iterate is read through the handle (declared units, float64 copies of float values)
and converted to the solver's variables. Deterministic: no timing.
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "examples"))

import cstr  # noqa: E402

from dopus_codegen import build_functions  # noqa: E402
from dopus_codegen.reference.kkt import eval_stages, node_parameters  # noqa: E402
from dopus_codegen.runtime.solver import CSolver  # noqa: E402
from dopus_codegen.studies.converge import make_start  # noqa: E402


def stationarity_in_double(disc, be):
    """Largest |stationarity| of the backend's iterate over the stages (with its stage and
    component) and at the terminal node, in the solver's variables, evaluated in double."""
    sc, S = disc.scaling, disc.scaled
    N, nx = disc.N, disc.nx
    pt = sc.guess_in(be.guess())   # the iterate in the solver's variables
    x, u, lam, mu_g, mu_b, mu_bN, mu_r = pt.x, pt.u, pt.lam, pt.mu_g, pt.mu_b, pt.mu_bN, pt.mu_r
    P = node_parameters(S)
    sk = eval_stages(S.stage_grad, N, x[:N], u, P[:N], lam[1:], mu_g)[0] + mu_b
    sk[:, :nx] += lam[:N]
    sN = np.asarray(S.term_grad(x[N], P[N], mu_r, pt.nu)[0], float).ravel() + mu_bN + lam[N]
    k, j = np.unravel_index(np.argmax(np.abs(sk)), sk.shape)
    return float(np.abs(sk[k, j])), int(k), int(j), float(np.max(np.abs(sN))), int(np.argmax(np.abs(sN))), x[N]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--iters", type=int, default=20)
    ap.add_argument("--M", default="29,1")
    ap.add_argument("--qp-tol", default="1e-5")
    args = ap.parse_args(argv)
    disc = build_functions(cstr.build())
    start = make_start(disc, "warm")
    for M in (int(m) for m in args.M.split(",")):
        for tol in (float(t) for t in args.qp_tol.split(",")):
            be = CSolver(disc, real="float", M=M, mode="fixed", qp_tol=tol)
            be.init(start.xhat_init, start.guess)
            print(f"M = {M}, qp_tol {tol:g}")
            print(f"{'it':>3} {'stat float':>10} {'rel':>9} {'stage (double)':>14} {'at k, j':>8} "
                  f"{'terminal':>9} {'at j':>4} {'x_N[1]':>18} {'QP it':>5}")
            for it in range(1, args.iters + 1):
                be.feedback(start.xhat_fixed)
                be.prepare()
                k = be.kkt(start.xhat_fixed)
                s, ks, js, sN, jN, xN = stationarity_in_double(disc, be)
                print(f"{it:>3} {k['stat']:10.3e} {k['rel']:9.2e} {s:14.3e} {f'{ks}, {js}':>8} {sN:9.3e} {jN:>4} "
                      f"{xN[1]:18.15f} {be.qp_iterations:>5}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
