"""Accuracy of the interval map against the number of substeps: RK4 and the implicit
collocation schemes on the stiff example (examples/stiff_motor.py) or another OCP file.

    python bench/integrator_accuracy.py [OCP_FILE]

Error: ``max_k |phi(x_k, u_k) - phi_ref(x_k, u_k)|_inf`` over the stages of IPOPT's solution
of the OCP file's own discretisation, ``phi_ref`` CVODES (BDF, rtol = atol = 1e-13) over
the same interval. A non-finite value is an unstable scheme.
"""
from __future__ import annotations

import importlib.util
import json
import sys
import time
from pathlib import Path

import casadi as ca
import numpy as np

from dopus_codegen import RK4, GaussLegendre, RadauIIA
from dopus_codegen.problem.derivatives import build_functions
from dopus_codegen.reference.offline import solve_ocp

ROOT = Path(__file__).resolve().parent.parent


def load_module(path):
    spec = importlib.util.spec_from_file_location("ocp_module", str(path))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def table(path, configs):
    mod = load_module(path)
    base = build_functions(mod.build())
    sol, info = solve_ocp(base, base.x0)
    x, u, p = ca.SX.sym("x", base.nx), ca.SX.sym("u", base.nu), ca.SX.sym("p", base.np)
    ref = ca.integrator("ref", "cvodes", {"x": x, "p": ca.vertcat(u, p), "ode": base.ode(x, u, p)},
                        0.0, base.dt, {"abstol": 1e-13, "reltol": 1e-13, "max_num_steps": 100000})
    points = [(sol.x[k], sol.u[k], base.p0[k]) for k in range(base.N)]
    exact = [np.array(ref(x0=xk, p=np.concatenate([uk, pk]))["xf"]).ravel() for xk, uk, pk in points]
    rows = []
    for label, integ in configs:
        d = build_functions(mod.build(integ))
        t0 = time.perf_counter()
        phis = [np.array(d.stage_eval(xk, uk, pk)[0]).ravel() for xk, uk, pk in points]
        dt = (time.perf_counter() - t0) / len(points)
        err = max(float(np.max(np.abs(a - b))) if np.all(np.isfinite(a)) else float("inf")
                  for a, b in zip(phis, exact))
        rows.append({"integrator": label, "error": err, "eval_seconds": dt})
    return rows


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    path = Path(argv[0]) if argv else ROOT / "examples" / "stiff_motor.py"
    configs = [(f"RK4(substeps={n})", RK4(substeps=n)) for n in (1, 5, 10, 18, 20, 40, 80, 160)]
    configs += [(f"GaussLegendre(stages={s}, substeps={n})", GaussLegendre(stages=s, substeps=n, newton_iters=3))
                for s in (2, 3) for n in (1, 2, 4)]
    configs += [(f"RadauIIA(stages={s}, substeps={n})", RadauIIA(stages=s, substeps=n, newton_iters=3))
                for s in (2, 3) for n in (1, 2, 4)]
    rows = table(path, configs)
    print(f"{'integrator':42s} {'max error':>12s}")
    for r in rows:
        print(f"{r['integrator']:42s} {r['error']:12.3e}")
    print(json.dumps(rows))


if __name__ == "__main__":
    main()
