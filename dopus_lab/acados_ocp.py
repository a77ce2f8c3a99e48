"""Translate an exported OCP (``acados_export.py``) to an acados OCP and build its solver.

This file runs **inside acados' own virtual environment** (``scripts/setup_acados.sh``,
``.venv-acados``): it imports acados' Python template and the CasADi shipped with it,
never the project's package, and is started as a script by path::

    .venv-acados/bin/python dopus_lab/acados_ocp.py build EXPORT.json OUT_DIR SETTINGS.json
    .venv-acados/bin/python dopus_lab/acados_ocp.py solve EXPORT.json OUT_DIR START.json RESULT.json

The translation keeps the problem exactly the same NLP as ours (docs/algorithm.md section 1):

- Dynamics (setting ``integrator``): ``"ERK"``, acados' explicit Runge-Kutta with 4 stages
  (the classical RK4 tableau) and as many steps per interval as our ``RK4(substeps)``,
  interval ``dt``, its derivatives by acados' own forward (and adjoint) sensitivities; or
  ``"DISCRETE"``, the same RK4 map written out as a CasADi expression
  (``disc_dyn_expr``), its Jacobians and Hessians by CasADi, as our generated code does.
- Compile flags (setting ``flags``) of the generated C (model functions and solver): acados'
  default ``-O2``, or ours (``-O3``, ``-O3 -march=native``). The wheel's acados, HPIPM and
  BLASFEO libraries are prebuilt (BLASFEO for ``X64_INTEL_HASWELL``).
- Cost: acados multiplies every stage cost by the interval length (its costs are
  integrals); our stage cost is the cost of one interval as written, so the translation
  divides the stage cost by ``dt`` (``l / dt`` for the external cost, ``W / dt`` for
  nonlinear least squares). The terminal cost is not scaled by acados and is passed as is.
  Exact Hessian: external costs (acados differentiates them twice). Gauss-Newton: the stage
  cost as nonlinear least squares ``res, W`` (needs no non least-squares stage term), the
  terminal cost external.
- Constraints: simple bounds stay simple bounds (rows with at least one finite side; the
  other side at +-1e9), on stages 0..N-1 for u and nodes 1..N for x, ``x_0`` fixed by
  acados' initial-state bounds; path constraints as nonlinear ``h`` on stages 0..N-1;
  terminal inequality rows and equality rows as nonlinear ``h_e``.
- Terminal equality rows are multiplied by ``eq_scale`` (default 1e-2). acados' QP solver
  (HPIPM, OCP-structured, via partial condensing) treats an equality row as a two-sided
  inequality with interior-point slacks; with unit scaling the robot arm's QPs stop at the
  iteration limit, with the rows scaled by 1e-2 they solve. The scaled rows have the same
  zero set, so the solution is unchanged (their multipliers are 1/eq_scale times ours).
  The classical Riccati recursion (``qp_solver_ric_alg = 0``) is the default: it needs only
  the reduced Hessian to be positive definite, as the exact Hessian of the robot arm is,
  where the square-root variant needs every stage Hessian positive definite.
"""
from __future__ import annotations

import json
import math
import os
import sys
from pathlib import Path

import casadi as ca
import numpy as np

import acados  # noqa: E402 - the wheel's package: paths of its libraries, headers, renderer

# acados' template finds libraries, headers and the renderer (bin/t_renderer) below this folder.
os.environ.setdefault("ACADOS_SOURCE_DIR", acados.DIR)
os.environ.setdefault("TERA_PATH", acados.TERA_PATH)
# ... and its layout files and C templates in the template package itself.
os.environ.setdefault("ACADOS_PYTHON_INTERFACE_PATH", acados.TEMPLATE_DIR)


def preload_acados_libraries(lib_dir=None) -> list:
    """Load the wheel's shared libraries globally, dependencies first: they carry no run
    path to each other, so a library that needs them (libacados, a generated solver) only
    resolves once they are loaded."""
    import ctypes

    lib_dir = Path(lib_dir or acados.LIB_DIR)
    handles = []
    for name in ("libblasfeo.so", "libhpipm.so", "libqpOASES_e.so.3.1", "libacados.so"):
        path = lib_dir / name
        if path.exists():
            handles.append(ctypes.CDLL(str(path), mode=ctypes.RTLD_GLOBAL))
    return handles


_PRELOADED = preload_acados_libraries()

FORMAT = 1
BIG = 1e9            # stands for an infinite side of a bound acados gets as a finite number

DEFAULT_SETTINGS = {
    "hessian": "exact",            # or "gauss-newton"
    "nlp_solver": "SQP_RTI",       # or "SQP"
    "regularize": "NO_REGULARIZE",  # MIRROR, PROJECT, CONVEXIFY, PROJECT_REDUC_HESS
    "lm": 0.0,                     # acados' levenberg_marquardt
    "cond_N": None,                # None: N (no condensing)
    "ric_alg": 0,                  # 0: classical Riccati, 1: square root
    "cond_ric_alg": 0,             # partial condensing: 0 no factorisation of the Hessian, 1 factorise
    "eq_scale": 1e-2,
    "qp_iter_max": 100,
    "qp_tol": 1e-10,
    "nlp_max_iter": 200,
    "nlp_tol": 1e-10,
    "integrator": "ERK",           # or "DISCRETE": the same RK4 map as discrete dynamics (CasADi derivatives)
    "flags": "-O2",                # compile flags of the generated C (acados' default)
    "hpipm_mode": "BALANCE",       # SPEED_ABS, SPEED, ROBUST (the timing process sets it at run time too)
    "suffix": "",                  # appended to the model name (one library per setting)
}


class TranslationError(ValueError):
    """The exported problem cannot be translated (the message says which part)."""


def _f(v):
    if isinstance(v, str):
        return {"inf": math.inf, "-inf": -math.inf}[v]
    return float(v)


def _arr(v):
    return np.array([_f(x) for x in v], dtype=float)


def load_export(path) -> dict:
    data = json.loads(Path(path).read_text())
    if data.get("format") != FORMAT:
        raise TranslationError(f"{path}: export format {data.get('format')!r}, this translator reads {FORMAT}")
    return data


def replay(fdesc: dict, inputs) -> list:
    """Rebuild the outputs of an exported function from SX inputs (see acados_export)."""
    if len(inputs) != fdesc["n_in"]:
        raise TranslationError(f"{fdesc['name']}: {len(inputs)} inputs given, {fdesc['n_in']} expected")
    for i, (x, n) in enumerate(zip(inputs, fdesc["in_sizes"])):
        if x.numel() != n:
            raise TranslationError(f"{fdesc['name']}: input {i} has {x.numel()} elements, {n} expected")
    w = [None] * max(1, fdesc["sz_w"])
    outs = [[ca.SX(0)] * n for n in fdesc["out_sizes"]]
    for item in fdesc["instructions"]:
        name, ins, res = item[0], item[1], item[2]
        if name == "OP_INPUT":
            w[res[0]] = inputs[ins[0]][ins[1]]
        elif name == "OP_OUTPUT":
            outs[res[0]][res[1]] = w[ins[0]]
        elif name == "OP_CONST":
            w[res[0]] = ca.SX(_f(item[3]))
        else:
            op = getattr(ca, name, None)
            if op is None:
                raise TranslationError(f"{fdesc['name']}: operation {name} unknown to CasADi {ca.__version__}")
            if len(ins) == 1:
                w[res[0]] = ca.SX.unary(op, w[ins[0]])
            elif len(ins) == 2:
                w[res[0]] = ca.SX.binary(op, w[ins[0]], w[ins[1]])
            else:
                raise TranslationError(f"{fdesc['name']}: operation {name} with {len(ins)} operands")
    return [ca.vertcat(*o) if o else ca.SX(0, 1) for o in outs]


def _bounds(lb, ub):
    """(idx, lb, ub) of the rows with a finite side; the other side at +-BIG."""
    idx = [i for i in range(lb.size) if math.isfinite(lb[i]) or math.isfinite(ub[i])]
    lo = np.array([lb[i] if math.isfinite(lb[i]) else -BIG for i in idx])
    hi = np.array([ub[i] if math.isfinite(ub[i]) else BIG for i in idx])
    return np.array(idx, dtype=int), lo, hi


def rk4_map(xdot, x, u, p, dt: float, substeps: int):
    """The classical RK4 map over one interval ``dt`` in ``substeps`` steps (our
    ``RK4(substeps)``, docs/algorithm.md section 1) as an expression in ``x, u, p``."""
    f = ca.Function("f", [x, u, p], [xdot])
    h = dt / substeps
    xk = x
    for _ in range(substeps):
        k1 = f(xk, u, p)
        k2 = f(xk + h / 2 * k1, u, p)
        k3 = f(xk + h / 2 * k2, u, p)
        k4 = f(xk + h * k3, u, p)
        xk = xk + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return xk


def model_name(data: dict, settings: dict) -> str:
    return f"{data['name']}{settings.get('suffix', '')}"


def translate(data: dict, settings: dict):
    """An ``AcadosOcp`` for the exported problem ``data`` and the solver ``settings``."""
    from acados.acados_template import AcadosModel, AcadosOcp

    s = {**DEFAULT_SETTINGS, **settings}
    unknown = set(settings) - set(DEFAULT_SETTINGS)
    if unknown:
        raise TranslationError(f"unknown settings {sorted(unknown)}")
    if data["integrator"]["kind"] != "RK4":
        raise TranslationError(f"integrator {data['integrator']['kind']}: only RK4 is translated")
    N, dt = int(data["N"]), float(data["dt"])
    nx, nu, npar = data["nx"], data["nu"], data["np"]
    x, u = ca.SX.sym("x", nx), ca.SX.sym("u", nu)
    p = ca.SX.sym("p", npar)
    xdot, res, l_extra, g = replay(data["functions"]["model"], [x, u, p])
    resN, E_extra, r, r_eq = replay(data["functions"]["terminal"], [x, p])
    W = np.array([[_f(v) for v in row] for row in data["W"]]) if data["W"] else np.zeros((0, 0))
    WN = np.array([[_f(v) for v in row] for row in data["W_N"]]) if data["W_N"] else np.zeros((0, 0))

    model = AcadosModel()
    model.name = model_name(data, s)
    model.x, model.u = x, u
    if s["integrator"] == "ERK":
        model.xdot = ca.SX.sym("xdot", nx)
        model.f_expl_expr = xdot
        model.f_impl_expr = model.xdot - xdot
    elif s["integrator"] == "DISCRETE":
        model.disc_dyn_expr = rk4_map(xdot, x, u, p, dt, int(data["integrator"]["substeps"]))
    else:
        raise TranslationError(f"integrator must be 'ERK' or 'DISCRETE', got {s['integrator']!r}")
    if npar:
        model.p = p

    ocp = AcadosOcp()
    ocp.model = model
    ocp.dims.N = N
    if npar:
        ocp.parameter_values = _arr(data["p0"][0])

    l_ls = 0.5 * ca.dot(res, ca.mtimes(ca.DM(W), res)) if data["nres"] else ca.SX(0)
    E_ls = 0.5 * ca.dot(resN, ca.mtimes(ca.DM(WN), resN)) if data["nres_N"] else ca.SX(0)
    if s["hessian"] == "exact":
        ocp.cost.cost_type = "EXTERNAL"
        model.cost_expr_ext_cost = (l_ls + l_extra) / dt      # acados multiplies by dt
    elif s["hessian"] == "gauss-newton":
        if not data["nres"]:
            raise TranslationError("hessian gauss-newton needs a stage least-squares cost")
        if not data["l_extra_zero"]:
            raise TranslationError("hessian gauss-newton: the acados translation needs a pure "
                                   "least-squares stage cost (stage_cost terms have no counterpart)")
        ocp.cost.cost_type = "NONLINEAR_LS"
        model.cost_y_expr = res
        ocp.cost.W = W / dt                                  # acados multiplies by dt
        ocp.cost.yref = np.zeros(data["nres"])
    else:
        raise TranslationError(f"hessian must be 'exact' or 'gauss-newton', got {s['hessian']!r}")
    ocp.cost.cost_type_e = "EXTERNAL"
    model.cost_expr_ext_cost_e = E_ls + E_extra

    lbu, ubu = _arr(data["lbu"]), _arr(data["ubu"])
    idx, lo, hi = _bounds(lbu, ubu)
    if idx.size:
        ocp.constraints.idxbu, ocp.constraints.lbu, ocp.constraints.ubu = idx, lo, hi
    lbx, ubx = _arr(data["lbx"]), _arr(data["ubx"])
    idx, lo, hi = _bounds(lbx, ubx)
    if idx.size:
        ocp.constraints.idxbx, ocp.constraints.lbx, ocp.constraints.ubx = idx, lo, hi
        ocp.constraints.idxbx_e, ocp.constraints.lbx_e, ocp.constraints.ubx_e = idx, lo, hi
    ocp.constraints.x0 = _arr(data["x0"])
    if data["ng"]:
        lg, ug = _arr(data["lg"]), _arr(data["ug"])
        model.con_h_expr = g
        ocp.constraints.lh = np.where(np.isfinite(lg), lg, -BIG)
        ocp.constraints.uh = np.where(np.isfinite(ug), ug, BIG)
    he, lhe, uhe = [], [], []
    if data["nr"]:
        lr, ur = _arr(data["lr"]), _arr(data["ur"])
        he.append(r)
        lhe += list(np.where(np.isfinite(lr), lr, -BIG))
        uhe += list(np.where(np.isfinite(ur), ur, BIG))
    if data["ne"]:
        he.append(float(s["eq_scale"]) * r_eq)
        lhe += [0.0] * data["ne"]
        uhe += [0.0] * data["ne"]
    if he:
        model.con_h_expr_e = ca.vertcat(*he)
        ocp.constraints.lh_e, ocp.constraints.uh_e = np.array(lhe), np.array(uhe)

    o = ocp.solver_options
    o.tf = N * dt
    o.integrator_type = s["integrator"]
    if s["integrator"] == "ERK":
        o.sim_method_num_stages = 4
        o.sim_method_num_steps = int(data["integrator"]["substeps"])
    o.hessian_approx = "EXACT" if s["hessian"] == "exact" else "GAUSS_NEWTON"
    o.nlp_solver_type = s["nlp_solver"]
    o.qp_solver = "PARTIAL_CONDENSING_HPIPM"
    o.hpipm_mode = str(s["hpipm_mode"])
    o.qp_solver_cond_N = int(s["cond_N"] or N)
    o.qp_solver_ric_alg = int(s["ric_alg"])
    o.qp_solver_cond_ric_alg = int(s["cond_ric_alg"])
    o.qp_solver_iter_max = int(s["qp_iter_max"])
    o.qp_solver_tol_stat = o.qp_solver_tol_eq = o.qp_solver_tol_ineq = o.qp_solver_tol_comp = float(s["qp_tol"])
    o.qp_solver_warm_start = 0
    o.regularize_method = s["regularize"]
    o.levenberg_marquardt = float(s["lm"])
    o.nlp_solver_max_iter = int(s["nlp_max_iter"])
    o.tol = float(s["nlp_tol"])
    o.print_level = 0
    o.ext_fun_compile_flags = str(s["flags"])
    return ocp


def build(export_path, out_dir, settings: dict) -> dict:
    """Generate and compile the acados solver; returns (and writes ``solver.json``) what the
    timing harness needs to load it without Python's acados: library paths, model name."""
    from acados.acados_template import AcadosOcpSolver

    data = load_export(export_path)
    out_dir = Path(out_dir).resolve()
    out_dir.mkdir(parents=True, exist_ok=True)
    ocp = translate(data, settings)
    ocp.code_export_directory = str(out_dir / "c_generated_code")
    cwd = os.getcwd()
    os.chdir(out_dir)            # acados writes its json and build files relative to the cwd
    try:
        solver = AcadosOcpSolver(ocp, json_file=str(out_dir / "acados_ocp.json"), verbose=False)
    finally:
        os.chdir(cwd)
    name = ocp.model.name
    info = {
        "model_name": name,
        "settings": {**DEFAULT_SETTINGS, **settings},
        "N": int(data["N"]), "nx": data["nx"], "nu": data["nu"], "np": data["np"],
        "ocp_solver_lib": str(out_dir / "c_generated_code" / f"libacados_ocp_solver_{name}.so"),
        "acados_lib_dir": acados.LIB_DIR,
        "casadi_version": ca.__version__,
    }
    (out_dir / "solver.json").write_text(json.dumps(info, indent=1, sort_keys=True) + "\n")
    del solver
    return info


def solve(export_path, out_dir, start: dict, settings: dict) -> dict:
    """Solve from ``start`` (``x (N+1, nx)``, ``u (N, nu)``, ``xhat0``) with the solver built
    in ``out_dir`` (SQP to the tolerance, or ``iterations`` RTI steps)."""
    from acados.acados_template import AcadosOcpSolver

    data = load_export(export_path)
    out_dir = Path(out_dir).resolve()
    ocp = translate(data, settings)
    ocp.code_export_directory = str(out_dir / "c_generated_code")
    cwd = os.getcwd()
    os.chdir(out_dir)
    try:
        solver = AcadosOcpSolver(ocp, json_file=str(out_dir / "acados_ocp.json"), build=False,
                                 generate=False, verbose=False)
    finally:
        os.chdir(cwd)
    N = int(data["N"])
    X, U = np.array(start["x"], dtype=float), np.array(start["u"], dtype=float)
    for k in range(N + 1):
        solver.set(k, "x", X[k])
        if k < N:
            solver.set(k, "u", U[k])
        if data["np"]:
            solver.set(k, "p", _arr(data["p0"][k]))
    xh = np.array(start["xhat0"], dtype=float)
    solver.set(0, "lbx", xh)
    solver.set(0, "ubx", xh)
    statuses = []
    iters = int(start.get("iterations", 1))
    for _ in range(iters):
        statuses.append(int(solver.solve()))
    Xs = np.array([solver.get(k, "x") for k in range(N + 1)])
    Us = np.array([solver.get(k, "u") for k in range(N)])
    out = {"x": Xs.tolist(), "u": Us.tolist(), "status": statuses,
           "sqp_iter": int(np.asarray(solver.get_stats("sqp_iter")).reshape(-1)[0]),
           "cost": float(solver.get_cost())}
    return out


def main(argv) -> int:
    if len(argv) >= 4 and argv[0] == "build":
        settings = json.loads(Path(argv[3]).read_text()) if len(argv) > 3 else {}
        build(argv[1], argv[2], settings)
        return 0
    if len(argv) == 6 and argv[0] == "solve":
        settings = json.loads(Path(argv[3]).read_text())
        start = json.loads(Path(argv[4]).read_text())
        Path(argv[5]).write_text(json.dumps(solve(argv[1], argv[2], start, settings)) + "\n")
        return 0
    print(__doc__, file=sys.stderr)
    return 2


if __name__ == "__main__":
    try:
        sys.exit(main(sys.argv[1:]))
    except TranslationError as exc:
        print(f"error: {exc}", file=sys.stderr)
        sys.exit(1)
