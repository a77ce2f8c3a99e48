"""Export an OCP file in a form the acados translator reads (``acados_ocp.py``).

acados' Python template runs in its own virtual environment with an older CasADi, and the
two CasADi versions must never meet in one process; their ``Function.serialize`` formats
are not compatible either (an object written by the newer one is refused by the older). So
the expressions travel as a neutral JSON: for each function the list of its scalar
instructions (operation *name*, work-vector indices, constants), which any CasADi version
replays with ``SX.unary``/``SX.binary``; plus the sizes, bounds, horizon, integrator and
guesses as plain numbers.

The exported pieces are the ones of ``discretize`` (docs/algorithm.md section 1):

- ``model(x, u, p) -> (xdot, res, l_extra, g)``: the continuous model, the stacked stage
  least-squares residual, the non least-squares stage cost and the path constraints;
- ``terminal(x, p) -> (res_N, E_extra, r, r_eq)``;
- ``W``, ``W_N``: the least-squares weights (stage cost ``0.5 res' W res + l_extra``).

Run ``python -m dopus_lab.acados_export OCP_FILE OUT.json``.
"""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import casadi as ca
import numpy as np

from dopus_codegen.problem.derivatives import build_functions
from dopus_codegen.problem.discretize import discretize
from dopus_codegen.problem.ocp import RK4, Ocp, OcpError, load_ocp

__all__ = ["FORMAT", "export_function", "export_ocp", "write_export"]

#: Version of the export format; the translator refuses any other.
FORMAT = 1

_OP_NAMES = {getattr(ca, n): n for n in dir(ca) if n.startswith("OP_")}


def _num(v: float):
    """A float for JSON; infinities as strings (JSON has none)."""
    v = float(v)
    if math.isinf(v):
        return "inf" if v > 0 else "-inf"
    if math.isnan(v):
        raise OcpError("export: NaN in the problem data")
    return v


def _vec(a) -> list:
    return [_num(v) for v in np.asarray(a, dtype=float).reshape(-1)]


def export_function(f: ca.Function) -> dict:
    """The scalar instruction list of an SX function in CasADi-version-neutral form.

    Every instruction is ``[op_name, inputs, outputs]`` (``OP_CONST`` adds the constant).
    For ``OP_INPUT`` the inputs are ``(input index, nonzero)`` and the output the work
    index; for ``OP_OUTPUT`` the input is the work index and the outputs ``(output index,
    nonzero)``; for every other operation inputs and output are work indices.
    """
    if not f.is_a("SXFunction"):
        raise OcpError(f"export: {f.name()} is not an SX function")
    instrs = []
    for k in range(f.n_instructions()):
        op = f.instruction_id(k)
        name = _OP_NAMES.get(op)
        if name is None or name == "OP_CALL":
            raise OcpError(f"export: {f.name()} uses the CasADi operation {name or op}, which the "
                           f"acados translation cannot carry (use plain scalar expressions)")
        item = [name, [int(i) for i in f.instruction_input(k)], [int(i) for i in f.instruction_output(k)]]
        if name == "OP_CONST":
            item.append(_num(f.instruction_constant(k)))
        instrs.append(item)
    return {
        "name": f.name(),
        "n_in": f.n_in(), "n_out": f.n_out(),
        "in_sizes": [int(f.nnz_in(i)) for i in range(f.n_in())],
        "out_sizes": [int(f.numel_out(i)) for i in range(f.n_out())],
        "sz_w": int(f.sz_w()),
        "instructions": instrs,
    }


def export_ocp(ocp: Ocp) -> dict:
    """The JSON-ready description of ``ocp`` (see the module docstring)."""
    if not isinstance(ocp, Ocp):
        raise OcpError(f"export: expected an Ocp, got {type(ocp).__name__}")
    if not isinstance(ocp.integrator, RK4):
        raise OcpError(f"export: integrator {ocp.integrator.describe()} has no acados counterpart here "
                       f"(only RK4, which maps to acados' 4-stage ERK)")
    spec = ocp.validate()
    if spec.model.memory:
        raise OcpError("export: rate constraints (a memory state with x+ = u) have no acados counterpart here")
    if any(rows.stages is not None for rows in spec.constraints.path):
        raise OcpError("export: path rows on chosen stages (stages=) have no acados counterpart here")
    if spec.scaling is not None:
        raise OcpError("export: a declared scaling (scale=, Ocp.scaling) is not exported; acados solves the problem "
                       "in its declared units, remove the scales to compare")
    disc = build_functions(ocp)
    m = discretize(spec)
    x, u, p = m.x, m.u, m.p
    dense = ca.densify
    for what, out in (("stage residual", m.res), ("path constraints", m.g), ("terminal residual", m.resN),
                      ("terminal constraints", m.r), ("terminal equality rows", m.r_eq)):
        if out.size2() != 1:
            raise OcpError(f"export: {what} must be a column vector")
    model = ca.Function(f"{ocp.name}_model", [x, u, p],
                        [dense(m.xdot), dense(m.res), dense(m.l_extra), dense(m.g)],
                        ["x", "u", "p"], ["xdot", "res", "l_extra", "g"])
    terminal = ca.Function(f"{ocp.name}_terminal", [x, p],
                           [dense(m.resN), dense(m.E_extra), dense(m.r), dense(m.r_eq)],
                           ["x", "p"], ["res_N", "E_extra", "r", "r_eq"])
    g = disc.initial_guess
    return {
        "format": FORMAT,
        "name": ocp.name,
        "N": disc.N, "dt": disc.dt,
        "integrator": {"kind": "RK4", "substeps": ocp.integrator.substeps},
        "nx": disc.nx, "nu": disc.nu, "np": disc.np, "ng": disc.ng, "nr": disc.nr, "ne": disc.ne,
        "nres": int(m.res.size1()), "nres_N": int(m.resN.size1()),
        "l_extra_zero": bool(m.l_extra.is_zero()),
        "E_extra_zero": bool(m.E_extra.is_zero()),
        "W": [_vec(row) for row in np.atleast_2d(m.W)] if m.W.size else [],
        "W_N": [_vec(row) for row in np.atleast_2d(m.WN)] if m.WN.size else [],
        "lbx": _vec(disc.lbx), "ubx": _vec(disc.ubx), "lbu": _vec(disc.lbu), "ubu": _vec(disc.ubu),
        "lg": _vec(disc.lg), "ug": _vec(disc.ug), "lr": _vec(disc.lr), "ur": _vec(disc.ur),
        "p0": [_vec(row) for row in disc.p0],
        "x0": _vec(disc.x0),
        "guess_x": [_vec(row) for row in g.x], "guess_u": [_vec(row) for row in g.u],
        "options": {k: v for k, v in disc.options.items() if isinstance(v, (int, float, str, bool))},
        "state_names": disc.state_names, "control_names": disc.control_names,
        "functions": {"model": export_function(model), "terminal": export_function(terminal)},
    }


def write_export(ocp_or_path, out) -> Path:
    """Export an :class:`Ocp` (or the OCP file at a path) to the JSON file ``out``."""
    ocp = ocp_or_path if isinstance(ocp_or_path, Ocp) else load_ocp(ocp_or_path)
    data = export_ocp(ocp)
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(data, sort_keys=True) + "\n")
    return out


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if len(argv) != 2:
        print("usage: python -m dopus_lab.acados_export OCP_FILE OUT.json", file=sys.stderr)
        return 2
    try:
        write_export(argv[0], argv[1])
    except OcpError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
