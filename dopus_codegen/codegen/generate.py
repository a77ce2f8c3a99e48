"""Code generation: a ``Discretized`` problem -> one self-contained C99 folder.

The folder holds (names after renaming ``dopus_`` -> ``<name>_``):

- ``<name>_casadi.c/.h``: every per-stage CasADi function of docs/algorithm.md section 2,
  emitted by one ``casadi.CodeGenerator`` with explicit options, in double each sin/cos pair
  of one variable computed by one call (:mod:`.trig`, ``runtime_c/dopus_trig.h``);
- ``<name>_sizes.h``, ``<name>_problem.c``: sizes and problem data, rendered from
  ``templates/*.j2``;
- the hand-written ``runtime_c/*.c|*.h``, copied with the prefix renamed (among them the
  wrappers ``<name>_funcs.c`` of the CasADi functions and the standalone ``<name>_main.c``);
- ``Makefile``, ``<name>.cmake``, ``<name>_cdef.h`` (cffi declarations, cut out of the
  renamed public header) and ``<name>_meta.json``.

Generation is deterministic: everything is rendered in memory first (fixed order, floats
at round-trip precision, no timestamps), so generating twice gives identical bytes.
"""
from __future__ import annotations

import hashlib
import json
import math
import re
import tempfile
from pathlib import Path
from typing import Any, Dict, List, Optional

import casadi as ca
import jinja2
import numpy as np

from .. import __version__
from .. import settings
from ..cnames import identifier_problem, rename_placeholder
from ..outputs import write_bytes
from . import flags
from .flags import CASADI_CFLAGS, DEFAULT_OPT, STRICT_CFLAGS
from .trig import pair_sincos
from .folder import FUNCTION_SLOTS, CodegenError, find_meta, read_meta  # noqa: F401 - re-exported
from ..paths import runtime_c_dir, templates_dir
from ..problem.derivatives import cost_hessian_constant



# ----------------------------------------------------------------------------------------
# small helpers


def c_double(value: float, what: str = "value", real: str = "double") -> str:
    """A C literal of the real type that reads back to exactly ``value`` rounded to that type
    (repr is round-trip): ``0.1`` in double, ``0.1f`` in float, where a value beyond the
    range of float becomes an infinity (a bound that far out is no bound)."""
    v = float(value)
    if math.isnan(v):
        raise CodegenError(f"{what}: NaN cannot be generated")
    if real == "float":
        v = float(np.float32(v)) if abs(v) <= float(np.finfo(np.float32).max) else math.copysign(math.inf, v)
    if math.isinf(v):
        return "INFINITY" if v > 0 else "-INFINITY"
    return repr(v) + ("f" if real == "float" else "")


def c_vector(values, size: int, what: str, real: str = "double") -> str:
    """``{a, b, ...}`` of a vector of ``size`` entries; an empty vector becomes ``{0.0}``
    to match the DIM(n) >= 1 array sizes of dopus_problem.h."""
    arr = np.asarray(values if values is not None else [], dtype=float).reshape(-1)
    if arr.size != size:
        raise CodegenError(f"{what}: expected {size} entries, got {arr.size}")
    if size == 0:
        return "{0.0}"
    return "{" + ", ".join(c_double(v, f"{what}[{i}]", real) for i, v in enumerate(arr)) + "}"


def c_matrix(values, rows: int, cols: int, what: str, real: str = "double") -> List[str]:
    """One ``{...}`` initialiser per row of a (rows, cols) array (row k = node k)."""
    if values is None:
        arr = np.zeros((rows, cols))
    else:
        arr = np.asarray(values, dtype=float)
        if cols == 0 and arr.size == 0:
            arr = np.zeros((rows, 0))
        if arr.shape != (rows, cols):
            raise CodegenError(f"{what}: expected shape ({rows}, {cols}), got {arr.shape}")
    return [c_vector(arr[k], cols, f"{what}[{k}]", real) for k in range(rows)]


def check_name(name: Any) -> str:
    why = identifier_problem(name)
    if why is not None:
        raise CodegenError(f"problem name {name!r} {why}")
    return name


def _option(options: Any, key: str, default: Any) -> Any:
    if options is None:
        return default
    if isinstance(options, dict):
        return options.get(key, default)
    return options.as_dict().get(key, default)   # OptionsSpec


def _attr(disc: Any, key: str) -> Any:
    try:
        return getattr(disc, key)
    except AttributeError:
        raise CodegenError(f"the discretized problem has no '{key}'") from None


# ----------------------------------------------------------------------------------------
# CasADi part


def _expected_io(slot: str, s: Dict[str, int]) -> tuple:
    """(input shapes, output shapes) of each function, docs/algorithm.md section 2."""
    nx, nu, nw, np_, ng, nr, ne = (s[k] for k in ("nx", "nu", "nw", "np", "ng", "nr", "ne"))
    stage_in = [(nx, 1), (nu, 1), (np_, 1)]
    stage_in_dual = stage_in + [(nx, 1), (ng, 1)]
    term_in = [(nx, 1), (np_, 1)]
    term_in_dual = term_in + [(nr, 1), (ne, 1)]
    table = {
        "stage_eval": (stage_in, [(nx, 1), (1, 1), (ng, 1)]),
        "stage_grad": (stage_in_dual, [(nw, 1), (nx, 1), (1, 1), (ng, 1)]),
        "stage_hess_exact": (stage_in_dual, [(nw, nw), (nx, nw), (ng, nw)]),
        "stage_grad_hess_exact": (stage_in_dual, [(nw, 1), (nx, 1), (1, 1), (ng, 1), (nw, nw), (nx, nw), (ng, nw)]),
        "stage_hess_gn": (stage_in_dual, [(nw, nw), (nx, nw), (ng, nw)]),
        "stage_grad_hess_gn": (stage_in_dual, [(nw, 1), (nx, 1), (1, 1), (ng, 1), (nw, nw), (nx, nw), (ng, nw)]),
        "stage_hess_cost_exact": (stage_in, [(nw, nw)]),
        "stage_hess_cost_gn": (stage_in, [(nw, nw)]),
        "term_eval": (term_in, [(1, 1), (nr, 1), (ne, 1)]),
        "term_grad": (term_in_dual, [(nx, 1), (1, 1), (nr, 1), (ne, 1)]),
        "term_hess_exact": (term_in_dual, [(nx, nx), (nr, nx), (ne, nx)]),
        "term_hess_gn": (term_in_dual, [(nx, nx), (nr, nx), (ne, nx)]),
        "ode": (stage_in, [(nx, 1)]),
    }
    return table[slot]


def _shape_ok(sp: ca.Sparsity, shape: tuple) -> bool:
    rows, cols = shape
    if rows * cols == 0:
        return sp.numel() == 0
    return (sp.size1(), sp.size2()) == shape or (cols == 1 and sp.numel() == rows and 1 in (sp.size1(), sp.size2()))


def _check_function(fun: ca.Function, slot: str, name: str, sizes: Dict[str, int]) -> None:
    want = f"{name}_{slot}"
    if fun.name() != want:
        raise CodegenError(f"function '{slot}' is named '{fun.name()}', expected '{want}'")
    ins, outs = _expected_io(slot, sizes)
    if fun.n_in() != len(ins) or fun.n_out() != len(outs):
        raise CodegenError(f"function '{want}': expected {len(ins)} inputs and {len(outs)} outputs, "
                           f"got {fun.n_in()} and {fun.n_out()}")
    for kind, shapes, get in (("input", ins, fun.sparsity_in), ("output", outs, fun.sparsity_out)):
        for i, shape in enumerate(shapes):
            sp = get(i)
            if not _shape_ok(sp, shape):
                raise CodegenError(f"function '{want}': {kind} {i} has shape {sp.size1()}x{sp.size2()}, "
                                   f"expected {shape[0]}x{shape[1]}")
            if kind == "output" and sp.numel() > 0 and not sp.is_dense():
                raise CodegenError(f"function '{want}': output {i} is not dense (the C glue reads "
                                   "dense column-major blocks)")


def _with_cse(fun: ca.Function) -> ca.Function:
    """An SX function again with common subexpression elimination on (CasADi's Function
    option 'cse'; CodeGenerator has no such option). An MX function is emitted as it is:
    expanding it to SX would unroll its loops (the substeps and the map over directions of
    the stage functions); its SX kernels carry the option themselves."""
    if not fun.is_a("SXFunction"):
        return fun
    args = fun.sx_in()
    return ca.Function(fun.name(), args, fun.call(args), fun.name_in(), fun.name_out(), {"cse": True})


def _algorithm_key(fun: ca.Function) -> Optional[str]:
    """The serialised algorithm of an SX function without its names (None for other
    functions): two functions with the same key compute the same outputs."""
    if not fun.is_a("SXFunction"):
        return None
    args = fun.sx_in()
    canon = ca.Function("same", args, fun.call(args), {"cse": True})
    return canon.serialize()


def _mx_inputs(fun: ca.Function) -> list:
    return [ca.MX.sym(fun.name_in(i), fun.sparsity_in(i)) for i in range(fun.n_in())]


def _compact(fun: ca.Function, emitted: Dict[str, ca.Function]) -> ca.Function:
    """The same function in a form whose C is smaller, computing the same values:

    - an SX function whose outputs depend on no input (the constant Hessian of a quadratic
      cost) becomes an MX function copying one static array per output, instead of one
      assignment per entry;
    - an SX function with the same algorithm as one emitted before (the Gauss-Newton and
      exact Hessians of a least-squares cost without other terms) becomes an MX function
      that calls the earlier one, which is emitted once.

    ``emitted`` maps algorithm keys to the functions emitted so far (updated here)."""
    if not fun.is_a("SXFunction") or fun.n_in() == 0:
        return fun
    args = fun.sx_in()
    every_input = ca.vertcat(*[ca.vec(a) for a in args])
    if not any(out.nnz() > 0 and ca.depends_on(out, every_input) for out in fun.call(args)):
        values = fun.call([ca.DM.zeros(fun.sparsity_in(i)) for i in range(fun.n_in())])
        outs = [ca.MX(ca.densify(v)) if fun.sparsity_out(i).is_dense() else ca.MX(v)
                for i, v in enumerate(values)]
        return ca.Function(fun.name(), _mx_inputs(fun), outs, fun.name_in(), fun.name_out())
    key = _algorithm_key(fun)
    first = emitted.get(key)
    if first is None:
        emitted[key] = fun
        return fun
    ins = _mx_inputs(fun)
    return ca.Function(fun.name(), ins, first.call(ins), fun.name_in(), fun.name_out())


def _composed_grad_hess(name: str, grad: ca.Function, hess: ca.Function, kind: str) -> ca.Function:
    """``stage_grad_hess_<kind>`` of a problem whose functions give none: an MX function
    calling ``stage_grad`` and ``stage_hess_<kind>`` (the runtime's one call, nothing shared)."""
    ins = _mx_inputs(grad)
    return ca.Function(f"{name}_stage_grad_hess_{kind}", ins, grad.call(ins) + hess.call(ins), grad.name_in(),
                       grad.name_out() + hess.name_out())


def casadi_functions(disc: Any, name: str, sizes: Dict[str, int]) -> Dict[str, ca.Function]:
    """The functions to emit, checked against docs/algorithm.md section 2, in emit order
    (SX functions in their compact form, :func:`_compact`)."""
    out: Dict[str, ca.Function] = {}
    emitted: Dict[str, ca.Function] = {}
    spec = getattr(disc, "spec", None)
    gn_default = _option(getattr(spec, "options", None), "hessian", settings.DEFAULTS["hessian"]) == "gauss-newton"
    for slot, optional in FUNCTION_SLOTS:
        if slot == "stage_grad_hess_gn" and not gn_default:
            # only for a problem whose OCP file chooses the Gauss-Newton Hessian: elsewhere the
            # runtime's wrapper calls stage_grad and stage_hess_gn (the same values), and the
            # firmware keeps the flash (robot arm, Cortex-M7: 40 kB)
            continue
        fun = getattr(disc.functions, slot, None)
        kind = slot[len("stage_grad_hess_"):] if slot.startswith("stage_grad_hess_") else None
        if fun is None and kind and "stage_grad" in out and f"stage_hess_{kind}" in out:
            fun = _composed_grad_hess(name, out["stage_grad"], out[f"stage_hess_{kind}"], kind)
        if fun is None:
            if optional:
                continue
            raise CodegenError(f"the discretized problem has no function '{slot}'")
        if not isinstance(fun, ca.Function):
            raise CodegenError(f"'{slot}' is not a casadi.Function")
        _check_function(fun, slot, name, sizes)
        out[slot] = _compact(_with_cse(fun), emitted)
    return out


_C_FUNCTION_START = re.compile(r"^(?:static |CASADI_SYMBOL_EXPORT )?[A-Za-z_][\w \*]*?\b(\w+)\(([^()]*)\) \{$")


def silence_unused_parameters(text: str) -> str:
    """CasADi's generated C passes the same (arg, res, iw, w, mem) to every function and
    leaves some unused, which -Wextra reports. Every function definition (one line, body
    closed by a ``}`` in column 0) gets ``(void)name;`` for each parameter its body does
    not use, so the file compiles with the project's strict flags."""
    lines = text.split("\n")
    out: List[str] = []
    i = 0
    while i < len(lines):
        line = lines[i]
        out.append(line)
        m = _C_FUNCTION_START.match(line)
        i += 1
        if not m or m.group(2).strip() in ("", "void"):
            continue
        j = i
        while j < len(lines) and lines[j] != "}":
            j += 1
        body = "\n".join(lines[i:j])
        params = [re.findall(r"\w+", prm)[-1] for prm in m.group(2).split(",")]
        unused = [prm for prm in params if not re.search(rf"\b{prm}\b", body)]
        if unused:
            out.append("  " + " ".join(f"(void){prm};" for prm in unused))
    return "\n".join(out)


#: The math functions CasADi's generated C calls, by name; in single precision each becomes
#: its float form (sinf, ...), so nothing is computed in double.
CASADI_MATH = ("sqrt", "fabs", "fmax", "fmin", "exp", "log", "log10", "log1p", "expm1", "pow", "floor", "ceil",
               "fmod", "sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sinh", "cosh", "tanh", "asinh",
               "acosh", "atanh", "erf", "erfc", "hypot", "copysign", "cbrt", "round", "trunc", "tgamma",
               "lgamma")
_CASADI_MATH_CALL = re.compile(r"(?<![\w.>])(" + "|".join(CASADI_MATH) + r")\(")
_FLOAT_LITERAL = re.compile(r"(?<![\w.])((?:\d+\.\d*|\.\d+)(?:[eE][-+]?\d+)?|\d+[eE][-+]?\d+)(?![\w.])")


def single_precision(source: str) -> str:
    """CasADi's C in single precision: ``casadi_real`` is float (CodeGenerator option
    ``casadi_real``, which only sets the type), and here every floating literal gets the
    ``f`` suffix and every math call its float form (``sin`` -> ``sinf``), so no expression
    is evaluated in double (software-emulated on a single-precision FPU). Comments and
    strings are left alone."""
    out = []
    for line in source.split("\n"):
        code, sep, comment = line.partition("/*")
        if code.lstrip().startswith("#") or code.lstrip().startswith("//"):
            out.append(line)
            continue
        code = _CASADI_MATH_CALL.sub(lambda m: m.group(1) + "f(", code)
        code = _FLOAT_LITERAL.sub(lambda m: m.group(1) + "f", code)
        out.append(code + sep + comment)
    return "\n".join(out)


def _check_float_literals(source: str) -> None:
    """A CodegenError naming the literals of CasADi's C that have no float (a number derived
    from the problem's, e.g. a product of two small constants in a derivative): the C
    compiler would refuse them ('floating constant truncated to zero')."""
    from ..problem.checks import outside_float

    bad, function = [], "?"
    for line in source.split("\n"):
        head = _FUNCTION_HEAD.match(line.strip())
        if head:
            function = head.group(1)
        code = line.partition("/*")[0]
        if code.lstrip().startswith("#"):
            continue
        for m in _FLOAT_LITERAL.finditer(code):
            why = outside_float(float(m.group(1)))
            if why and (function, f"{float(m.group(1)):g}", why) not in bad:
                bad.append((function, f"{float(m.group(1)):g}", why))
    if bad:
        shown = "; ".join(f"{v} in {f} ({why} the range of float)" for f, v, why in bad[:3])
        more = f"; and {len(bad) - 3} more" if len(bad) > 3 else ""
        raise CodegenError(f"real float: the generated functions hold numbers a float cannot: {shown}{more}; "
                           "they are derived from the problem's constants (a product in a derivative, say): "
                           "rescale the problem or use real='double'")


def casadi_sources(functions: Dict[str, ca.Function], name: str, real: str = "double") -> Dict[str, str]:
    """``<name>_casadi.c`` and ``.h`` from one CodeGenerator with explicit options; in double,
    each sin/cos pair of one argument computed by one ``<name>_sincos`` call (:mod:`.trig`)."""
    opts = {"casadi_int": "int", "casadi_real": real, "mex": False, "with_header": True,
            "verbose": False, "main": False, "cpp": False, "with_mem": False}
    base = f"{name}_casadi"
    cg = ca.CodeGenerator(base, opts)
    for fun in functions.values():
        cg.add(fun)
    with tempfile.TemporaryDirectory(prefix="dopus_cg_") as tmp:
        cg.generate(str(Path(tmp)) + "/")
        source = silence_unused_parameters((Path(tmp) / f"{base}.c").read_text())
        if real == "float":
            _check_float_literals(source)
        else:
            source = pair_sincos(source, name)[0]     # sin(a) and cos(a) in one call (codegen/trig.py)
        out = {f"{base}.c": single_precision(source) if real == "float" else source,
               f"{base}.h": (Path(tmp) / f"{base}.h").read_text()}
    _refuse_without_codegen(out[f"{base}.c"], functions)
    return out


_NO_CODEGEN = re.compile(r"#error Code generation not supported for (\w+)")
_FUNCTION_HEAD = re.compile(r"/\* (\w+):\(")


def _refuse_without_codegen(source: str, functions: Dict[str, ca.Function]) -> None:
    """CasADi emits ``#error Code generation not supported for <class>`` for a function it
    cannot generate (a rootfinder or integrator plugin such as kinsol, IDAS, CVODES, an
    external solver): the folder would fail at build. Refuse it here, naming the function,
    its CasADi class and the generated functions that call it."""
    lines = source.splitlines()
    for i, line in enumerate(lines):
        m = _NO_CODEGEN.search(line)
        if not m:
            continue
        fname = next((h.group(1) for h in (_FUNCTION_HEAD.match(ln.strip()) for ln in reversed(lines[:i])) if h),
                     "?")
        users = [slot for slot, fun in functions.items()
                 if any(sub.name() == fname for sub in fun.find_functions())]
        raise CodegenError(
            f"the CasADi function '{fname}' ({m.group(1)}) has no C code generation"
            + (f"; it is called by {', '.join(repr(u) for u in users)}" if users else "")
            + ": the generated folder could not be compiled. Use a construct CasADi generates C for "
              "(an explicit integrator, or the rootfinder plugin 'fast_newton')")


_FORWARD_CALL = re.compile(r"\b(\w+)\(arg, res, iw, w, \w+\)")
_C_DEFINITION = re.compile(r"^(?:static |CASADI_SYMBOL_EXPORT )?[A-Za-z_][\w \*]*?\b(\w+)\(([^()]*)\) ?\{$")


def work_array_used(source: str) -> bool:
    """Whether a function of CasADi's C reads or writes its work array ``w``. CasADi's
    CodeGenerator keeps the intermediate values of an SX function in local variables
    (``a0, a1, ...``: its option avoid_stack is off), so the SX functions the project generates
    leave ``w`` alone and their ``sz_w`` (CasADi's count of those values) needs no memory. A
    function uses ``w`` when its body names it other than in passing its own (arg, res, iw, w,
    mem) on to a function of the file that does not use it; a call passing ``w`` to a function
    the file does not define counts as a use."""
    lines = source.split("\n")
    direct: Dict[str, bool] = {}
    forwards: Dict[str, List[str]] = {}
    i = 0
    while i < len(lines):
        m = _C_DEFINITION.match(lines[i])
        i += 1
        if not m:
            continue
        j = i
        while j < len(lines) and lines[j] != "}":
            j += 1
        body = "\n".join(lines[i:j]).replace("(void)w;", "")
        params = [re.findall(r"\w+", prm)[-1] for prm in m.group(2).split(",") if re.findall(r"\w+", prm)]
        if "w" in params:
            forwards[m.group(1)] = _FORWARD_CALL.findall(body)
            direct[m.group(1)] = re.search(r"\bw\b", _FORWARD_CALL.sub("", body)) is not None
        i = j
    return any(direct.values()) or any(c not in direct for calls in forwards.values() for c in calls)


def work_sizes(functions: Dict[str, ca.Function], source: Optional[str] = None) -> Dict[str, int]:
    """SZ_ARG/RES/IW/W: the max over every emitted function, at least 1 (C99 arrays); SZ_W 1
    when ``source`` (the generated CasADi C) is given and no function of it uses its work array
    (:func:`work_array_used`)."""
    return {
        "sz_arg": max([1] + [int(f.sz_arg()) for f in functions.values()]),
        "sz_res": max([1] + [int(f.sz_res()) for f in functions.values()]),
        "sz_iw": max([1] + [int(f.sz_iw()) for f in functions.values()]),
        "sz_w": (max([1] + [int(f.sz_w()) for f in functions.values()])
                 if source is None or work_array_used(source) else 1),
    }


# ----------------------------------------------------------------------------------------
# problem data


def problem_sizes(disc: Any) -> Dict[str, int]:
    sizes = {k: int(_attr(disc.data, k)) for k in ("N", "nx", "nu", "nw", "np", "ng", "nr", "ne")}
    if sizes["N"] < 1 or sizes["nx"] < 1 or sizes["nu"] < 1:
        raise CodegenError(f"sizes N={sizes['N']}, nx={sizes['nx']}, nu={sizes['nu']} must be >= 1")
    if sizes["nw"] != sizes["nx"] + sizes["nu"]:
        raise CodegenError(f"nw={sizes['nw']} is not nx + nu = {sizes['nx'] + sizes['nu']}")
    for k in ("np", "ng", "nr", "ne"):
        if sizes[k] < 0:
            raise CodegenError(f"size {k}={sizes[k]} is negative")
    return sizes


def bounded_row_counts(disc: Any, s: Dict[str, int]) -> Dict[str, int]:
    """Rows of the QP with a finite side, per kind (a component or row counts when its lower
    or its upper bound is finite): nbx state components, nbu controls, nbg path rows, nbr
    terminal rows. They size the QP's per-row arrays (DOPUS_NB of dopus_qp.h)."""
    data = disc.data

    def count(lo: str, up: str, n: int) -> int:
        if n == 0:
            return 0
        lb = np.asarray(_attr(data, lo), dtype=float).reshape(-1)
        ub = np.asarray(_attr(data, up), dtype=float).reshape(-1)
        if lb.size != n or ub.size != n:
            raise CodegenError(f"{lo}/{up}: expected {n} entries, got {lb.size} and {ub.size}")
        return int(np.count_nonzero(np.isfinite(lb) | np.isfinite(ub)))

    return {"nbx": count("lbx", "ubx", s["nx"]), "nbu": count("lbu", "ubu", s["nu"]),
            "nbg": count("lg", "ug", s["ng"]), "nbr": count("lr", "ur", s["nr"])}


def soft_rows(disc: Any) -> Dict[str, Any]:
    """The soft rows of the problem: ``nsoft`` (state components, path rows and terminal
    rows with a soft side, the DOPUS_NSOFT of the sizes header; 0 when every row is hard)
    and ``always_feasible`` (every row that depends on the state is soft: the QP is feasible
    for every finite measurement)."""
    data = disc.data
    if not getattr(data, "has_soft", False):
        return {"nsoft": 0, "always_feasible": False}
    n = sum(int(np.count_nonzero(np.any(np.asarray(getattr(data, key)) > 0, axis=0)))
            for key in ("soft_x", "soft_g", "soft_r"))
    return {"nsoft": n, "always_feasible": bool(data.always_feasible)}


#: Sampling instants of the standalone main's closed loop (runtime_c/dopus_main.c ITERATIONS):
#: the parameter schedule of a time-varying problem covers them and the horizon after them.
MAIN_ITERATIONS = 10


def _default_parameters(disc: Any, s: Dict[str, int]) -> np.ndarray:
    """The parameters of the first horizon, ``(N+1, DIM(np))`` (dopus_problem.h)."""
    p0 = _attr(disc.data, "p0")
    arr = np.asarray(p0 if p0 is not None else np.zeros((s["N"] + 1, s["np"])), dtype=float)
    if s["np"] == 0:
        return np.zeros((s["N"] + 1, 1))
    if arr.ndim == 1:
        arr = np.tile(arr, (s["N"] + 1, 1))
    if arr.shape != (s["N"] + 1, s["np"]):
        raise CodegenError(f"p0: expected shape ({s['N'] + 1}, {s['np']}), got {arr.shape}")
    return arr


def _stage_path_bounds(disc: Any, s: Dict[str, int]):
    """``(N, DIM(ng))`` lower and upper path-row bounds per stage (a zero column without rows)."""
    N, ng = s["N"], s["ng"]
    if ng == 0:
        return np.zeros((N, 1)), np.zeros((N, 1))
    data = disc.data
    if hasattr(data, "path_bounds"):
        lo, up = data.path_bounds()
    else:
        lo = np.tile(np.asarray(data.lg, float).reshape(1, ng), (N, 1))
        up = np.tile(np.asarray(data.ug, float).reshape(1, ng), (N, 1))
    return np.asarray(lo, float).reshape(N, ng), np.asarray(up, float).reshape(N, ng)


def row_names(disc: Any) -> Dict[str, List[str]]:
    """The rows' names of dopus_row_name: ``x``, ``u`` (labels), ``g`` (path rows), ``r``
    (terminal inequality rows), ``req`` (terminal equality rows), in the QP's order."""
    spec = disc.spec
    con = spec.constraints
    g = [n for i, rows in enumerate(con.path) for n in rows.labels("path constraint", i)]
    term = [n for i, rows in enumerate(con.terminal) for n in rows.labels("terminal constraint", i)]
    is_eq = np.asarray(con.terminal_equality, dtype=bool).reshape(-1)
    return {"x": list(spec.model.state_names), "u": list(spec.model.control_names), "g": g,
            "r": [n for n, e in zip(term, is_eq) if not e], "req": [n for n, e in zip(term, is_eq) if e]}


def _row_names(disc: Any) -> Dict[str, str]:
    """The C initialisers of the row-name tables (one "" entry for an empty table)."""
    out = {}
    for key, names in row_names(disc).items():
        for n in names:
            if not n.isascii() or '"' in n or "\\" in n:
                raise CodegenError(f"row name {n!r}: only plain ASCII without quotes or backslashes")
        out[f"row_names_{key}"] = "{" + ", ".join(f'"{n}"' for n in (names or [""])) + "}"
    return out


def _parameter_schedule(disc: Any, s: Dict[str, int]):
    """The parameters at t = j dt, j = 0..N + MAIN_ITERATIONS, of a problem whose parameters
    declare a trajectory (None otherwise)."""
    if s["np"] == 0 or not getattr(disc, "time_varying_parameters", False):
        return None
    return np.array([disc.parameters_at(j * float(disc.dt)) for j in range(s["N"] + 1 + MAIN_ITERATIONS)])


def _settings_of(disc: Any) -> "settings.Settings":
    """The solver settings of the OCP file's options(...)."""
    options = disc.spec.options
    if isinstance(options, dict):
        return settings.Settings.of(options)
    return options.settings


def _code(setting: str, options: Any) -> int:
    try:
        return settings.code(setting, _option(options, setting, settings.DEFAULTS[setting]))
    except settings.SettingError as exc:
        raise CodegenError(f"option {exc}") from None


def problem_context(disc: Any, s: Dict[str, int], nominal: Any, real: str = "double",
                    declared: Any = None) -> Dict[str, Any]:
    """Everything dopus_problem.c renders, pre-formatted (the template only places it).
    ``disc``: the problem the solver works with; ``declared``: the declared problem when it
    is scaled (docs/algorithm.md section 16: ``x0_default`` and ``nominal`` are in its units)."""
    N, nx, nu, nw = s["N"], s["nx"], s["nu"], s["nw"]
    declared = disc if declared is None else declared
    scaling = getattr(declared, "scaling", None)

    def c_double(value, what):
        return _c_literal(value, what, real)

    def c_vector(values, size, what):
        return _c_vector(values, size, what, real)

    def c_matrix(values, rows, cols, what):
        return _c_matrix(values, rows, cols, what, real)

    options = disc.spec.options
    data = disc.data
    guess = _attr(data, "initial_guess")
    if getattr(guess, "x", None) is None or getattr(guess, "u", None) is None:
        raise CodegenError("initial_guess: x and u are required")
    ctx: Dict[str, Any] = {
        "lbx": c_vector(_attr(data, "lbx"), nx, "lbx"),
        "ubx": c_vector(_attr(data, "ubx"), nx, "ubx"),
        "lbu": c_vector(_attr(data, "lbu"), nu, "lbu"),
        "ubu": c_vector(_attr(data, "ubu"), nu, "ubu"),
        "lg": c_vector(_attr(data, "lg"), s["ng"], "lg"),
        "ug": c_vector(_attr(data, "ug"), s["ng"], "ug"),
        "lr": c_vector(_attr(data, "lr"), s["nr"], "lr"),
        "ur": c_vector(_attr(data, "ur"), s["nr"], "ur"),
        "p_default": c_matrix(_default_parameters(disc, s), N + 1, max(s["np"], 1), "p0"),
        "dt": c_double(_attr(data, "dt"), "dt"),
        "x0_default": c_vector(_attr(declared.data, "x0") if hasattr(declared, "data") else _attr(data, "x0"),
                               nx, "x0"),
        "scale_x": c_vector(np.ones(nx) if scaling is None else scaling.x, nx, "scale_x"),
        "scale_u": c_vector(np.ones(nu) if scaling is None else scaling.u, nu, "scale_u"),
        # (an empty row block has one unused entry, DOPUS_DIM: 1, like every scale that is not declared)
        "scale_g": c_vector(_scales_of(scaling, "g", s["ng"]), max(s["ng"], 1), "scale_g"),
        "scale_r": c_vector(_scales_of(scaling, "r", s["nr"]), max(s["nr"], 1), "scale_r"),
        "scale_req": c_vector(_scales_of(scaling, "r_eq", s["ne"]), max(s["ne"], 1), "scale_req"),
        "scale_cost": c_double(1.0 if scaling is None else scaling.cost, "scale_cost"),
        "guess_x": c_matrix(getattr(guess, "x", None), N + 1, nx, "initial_guess.x"),
        "guess_u": c_matrix(getattr(guess, "u", None), N, nu, "initial_guess.u"),
        "default_M": int(_option(options, "M", settings.DEFAULTS["M"])),
        "default_hessian": _code("hessian", options),
        "default_regularization": _code("regularization", options),
        "default_cost_hessian": _code("cost_hessian", options),
        "default_reg_eps": c_double(_option(options, "reg_eps", settings.DEFAULTS["reg_eps"]), "reg_eps"),
        "default_lm": c_double(settings.lm_code(_option(options, "lm", settings.DEFAULTS["lm"])), "lm"),
        "default_gate": c_double(_option(options, "gate", settings.DEFAULTS["gate"]), "gate"),
        "default_gate_hold": int(_option(options, "gate_hold", settings.DEFAULTS["gate_hold"])),
        "has_nominal": nominal is not None,
    }
    ctx.update(_row_names(disc))
    lg_k, ug_k = _stage_path_bounds(disc, s)
    ctx["lg_k"] = c_matrix(lg_k, N, max(s["ng"], 1), "lg per stage")
    ctx["ug_k"] = c_matrix(ug_k, N, max(s["ng"], 1), "ug per stage")
    memory = list(getattr(disc.spec.model, "memory", ()) or ())
    ctx["memory_state"] = "{" + ", ".join(str(a) for a, _ in memory or [(0, 0)]) + "}"
    ctx["memory_control"] = "{" + ", ".join(str(b) for _, b in memory or [(0, 0)]) + "}"
    schedule = _parameter_schedule(disc, s)
    ctx["p_schedule_nodes"] = 0 if schedule is None else schedule.shape[0]
    if schedule is not None:
        ctx["p_schedule"] = c_matrix(schedule, schedule.shape[0], s["np"], "parameter schedule")
    soft = soft_rows(disc)
    ctx["nsoft"] = soft["nsoft"]
    if soft["nsoft"]:
        d = disc.data
        ctx["soft_x"] = [c_vector(row, nx, "soft_x") for row in np.asarray(d.soft_x)]
        ctx["soft_g"] = [c_vector(_pad_vec(row, s["ng"]), max(1, s["ng"]), "soft_g")
                         for row in np.asarray(d.soft_g).reshape(4, s["ng"])]
        ctx["soft_r"] = [c_vector(_pad_vec(row, s["nr"]), max(1, s["nr"]), "soft_r")
                         for row in np.asarray(d.soft_r).reshape(4, s["nr"])]
    try:
        settings.stages(ctx["default_M"], N, strict=True)
    except settings.SettingError as exc:
        raise CodegenError(f"option {exc}") from None
    if nominal is not None:
        dim = lambda n: max(n, 1)  # noqa: E731  (DOPUS_DIM of the header)
        ctx.update({
            "nominal_x": c_matrix(nominal.x, N + 1, nx, "nominal.x"),
            "nominal_u": c_matrix(nominal.u, N, nu, "nominal.u"),
            "nominal_lam": c_matrix(nominal.lam, N + 1, nx, "nominal.lam"),
            "nominal_mu_g": c_matrix(_pad(nominal.mu_g, N, s["ng"]), N, dim(s["ng"]), "nominal.mu_g"),
            "nominal_mu_b": c_matrix(nominal.mu_b, N, nw, "nominal.mu_b"),
            "nominal_mu_bN": c_vector(_zeros_if_none(nominal.mu_bN, nx), nx, "nominal.mu_bN"),
            "nominal_mu_r": c_vector(_pad_vec(nominal.mu_r, s["nr"]), dim(s["nr"]), "nominal.mu_r"),
            "nominal_nu": c_vector(_pad_vec(nominal.nu, s["ne"]), dim(s["ne"]), "nominal.nu"),
        })
    return ctx


_c_literal, _c_vector, _c_matrix = c_double, c_vector, c_matrix


def _scales_of(scaling, key: str, n: int) -> np.ndarray:
    """The scales of a row block (docs/algorithm.md section 16), 1 without a scaling; at least
    one entry."""
    a = np.ones(n) if scaling is None else np.asarray(getattr(scaling, key), dtype=float)
    return a if n else np.ones(1)


def _zeros_if_none(v, n):
    return np.zeros(n) if v is None else v


def _pad_vec(v, n):
    """An (n,) vector, as the DIM(n) >= 1 array of the header (a zero for n == 0)."""
    arr = np.zeros(n) if v is None else np.asarray(v, dtype=float).reshape(-1)
    return arr if n > 0 else np.zeros(1)


def _pad(v, rows, cols):
    arr = np.zeros((rows, cols)) if v is None else np.asarray(v, dtype=float).reshape(rows, cols)
    return arr if cols > 0 else np.zeros((rows, 1))


# ----------------------------------------------------------------------------------------
# the folder


def _templates() -> jinja2.Environment:
    return jinja2.Environment(
        loader=jinja2.FileSystemLoader(str(templates_dir())),
        undefined=jinja2.StrictUndefined,
        keep_trailing_newline=True,
        trim_blocks=True,
        lstrip_blocks=True,
        autoescape=False,
    )


# runtime_c files that are not part of a generated solver: the linkable wrappers of the
# inline linear algebra, for the tests of the kernels only
TEST_ONLY_RUNTIME = ("dopus_linalg.c",)


def unity_modules(solver_c: str) -> List[str]:
    """The runtime's .c files that dopus_solver.c includes (its one translation unit): they
    are shipped but not compiled on their own."""
    return re.findall(r'^#include "(dopus_\w+\.c)"', solver_c, flags=re.M)


def runtime_sources(name: str) -> Dict[str, str]:
    """runtime_c/*.c|*.h with the prefix renamed, in file names and contents (without the
    test-only files)."""
    root = runtime_c_dir()
    out: Dict[str, str] = {}
    for path in sorted(list(root.glob("*.c")) + list(root.glob("*.h"))):
        if path.name in TEST_ONLY_RUNTIME:
            continue
        out[rename_placeholder(path.name, name)] = rename_placeholder(path.read_text(), name)
    if f"{name}_solver.h" not in out:
        raise CodegenError(f"the runtime has no public header dopus_solver.h in {root}")
    return out


def extract_cdef(header_text: str, name: str, header_name: str) -> str:
    """The cffi declarations: the lines between the CDEF marker lines of the public header."""
    begin, end = f"/* {name.upper()}_CDEF_BEGIN */", f"/* {name.upper()}_CDEF_END */"
    lines = header_text.splitlines()
    stripped = [ln.strip() for ln in lines]
    if stripped.count(begin) != 1 or stripped.count(end) != 1:
        raise CodegenError(f"{header_name}: expected exactly one '{begin}' and one '{end}' line")
    i, j = stripped.index(begin), stripped.index(end)
    if j < i:
        raise CodegenError(f"{header_name}: '{end}' comes before '{begin}'")
    return "\n".join(lines[i + 1:j]).strip("\n") + "\n"


def render_sizes_header(name: str, sizes: Dict[str, int], *, has_gn: int = 0, has_gn_fused: int = 0,
                        has_nominal: int = 0,
                        work: Optional[Dict[str, int]] = None, header: str = "",
                        casadi_version: str = "", real: str = "double", p_schedule_nodes: int = 0,
                        cost_hess_const: int = 0) -> str:
    """``<name>_sizes.h`` from templates/sizes.h.j2: the one sizes header of the runtime, also
    for the QP harness and the QP benchmark (which give only the QP sizes N, nx, nu, ng, nr,
    ne; the other entries then hold placeholders: no CasADi work, no Gauss-Newton)."""
    s = dict(sizes)
    s.setdefault("nw", s["nx"] + s["nu"])
    s.setdefault("np", 0)
    # without the bound pattern every row counts as bounded
    for key, n in (("nbx", "nx"), ("nbu", "nu"), ("nbg", "ng"), ("nbr", "nr")):
        s.setdefault(key, s[n])
    s["nb"] = s["N"] * (s["nbx"] + s["nbu"] + s["nbg"]) + s["nbr"]
    s.setdefault("nsoft", 0)
    s.setdefault("always_feasible", 0)
    ctx = {"name": name, "NAME": name.upper(), "sizes": s, "has_gn": int(has_gn), "has_gn_fused": int(has_gn_fused),
           "cost_hess_const": int(cost_hess_const), "has_nominal": int(has_nominal), "header": header or f"Sizes of '{name}'",
           "p_schedule_nodes": int(p_schedule_nodes),
           "casadi_version": casadi_version, "real_float": settings.REALS[settings.check_real(real)],
           "work": work or {"sz_arg": 1, "sz_res": 1, "sz_iw": 1, "sz_w": 1}}
    return _templates().get_template("sizes.h.j2").render(**ctx)


def real_of(disc: Any, real: Optional[str] = None) -> str:
    """The real type to generate: ``real`` if given, else the OCP file's ``options(real=...)``."""
    value = _option(disc.spec.options, "real", settings.DEFAULTS["real"]) if real is None else real
    try:
        return settings.check_real(value)
    except settings.SettingError as exc:
        raise CodegenError(f"option {exc}") from None


def render_folder(disc: Any, nominal: Any = None, problem_hash: Optional[str] = None,
                  real: Optional[str] = None) -> Dict[str, str]:
    """Every file of the generated folder, as {file name: text}, without touching the disk.
    ``real`` overrides the OCP file's ``options(real=...)``."""
    name = check_name(_attr(disc.data, "name"))
    NAME = name.upper()
    real = real_of(disc, real)
    declared = disc
    disc = getattr(disc, "solver_problem", disc)     # a scaled problem: the solver's variables
    if real == "float" and hasattr(disc, "spec"):
        from ..problem.checks import check_float_range

        check_float_range(disc)     # the problem's own numbers, named, before any code is generated
    s = problem_sizes(disc)
    functions = casadi_functions(disc, name, s)
    files: Dict[str, str] = {}
    files.update(casadi_sources(functions, name, real))
    files.update(runtime_sources(name))

    header = (f"Generated by dopus-gen {__version__} with CasADi {ca.__version__} "
              f"for the problem '{name}'. Do not edit: regenerate with dopus-gen generate.")
    has_gn = "stage_hess_gn" in functions
    has_gn_fused = "stage_grad_hess_gn" in functions
    if has_gn != ("stage_hess_cost_gn" in functions):
        raise CodegenError("stage_hess_gn and stage_hess_cost_gn must both be present or both absent")
    main_file = f"{name}_main.c"
    ctx: Dict[str, Any] = {
        "name": name, "NAME": NAME, "header": header, "casadi_version": ca.__version__,
        "has_gn": int(has_gn), "sizes": s, "work": work_sizes(functions, files[f"{name}_casadi.c"]), "main_file": main_file,
        "strict_cflags": " ".join(STRICT_CFLAGS), "casadi_cflags": " ".join(CASADI_CFLAGS),
        "default_opt": DEFAULT_OPT, "cmake_options": flags.cmake_options(),
    }
    ctx.update(problem_context(disc, s, nominal, real, declared))
    ctx["has_nominal"] = int(ctx["has_nominal"])

    env = _templates()
    soft = soft_rows(disc)
    files[f"{name}_sizes.h"] = render_sizes_header(name, dict(s, **bounded_row_counts(disc, s), nsoft=soft["nsoft"],
                                                                  nmem=len(getattr(disc.spec.model, "memory", ()) or ()),
                                                               always_feasible=int(soft["always_feasible"])),
                                                   has_gn=ctx["has_gn"], has_gn_fused=int(has_gn_fused),
                                                   has_nominal=ctx["has_nominal"],
                                                   work=ctx["work"], header=header,
                                                   casadi_version=ca.__version__, real=real,
                                                   p_schedule_nodes=ctx["p_schedule_nodes"],
                                                   cost_hess_const=int(cost_hessian_constant(
                                                       functions["stage_hess_cost_exact"],
                                                       functions.get("stage_hess_cost_gn"))))
    files[f"{name}_problem.c"] = env.get_template("problem.c.j2").render(**ctx)

    cdef = extract_cdef(files[f"{name}_solver.h"], name, f"{name}_solver.h")
    files[f"{name}_cdef.h"] = (f"/* {header} */\n/* cffi declarations cut from {name}_solver.h */\n"
                               f"typedef {real} {name}_real;\n" + cdef)

    modules = {rename_placeholder(f, name) for f in unity_modules((runtime_c_dir() / "dopus_solver.c").read_text())}
    c_sources = sorted(f for f in files if f.endswith(".c") and f != main_file and f not in modules)
    headers = sorted(f for f in files if f.endswith(".h") and f != f"{name}_cdef.h")
    build_ctx = dict(ctx, casadi_source=f"{name}_casadi.c",
                     strict_sources=[f for f in c_sources if f != f"{name}_casadi.c"],
                     lib_sources=c_sources, headers=headers, modules=sorted(modules))
    files["Makefile"] = env.get_template("Makefile.j2").render(**build_ctx)
    files[f"{name}.cmake"] = env.get_template("cmake.j2").render(**build_ctx)

    meta_file = f"{name}_meta.json"
    meta = {
        "generator": "dopus-gen",
        "generator_version": __version__,
        "casadi_version": ca.__version__,
        "name": name,
        "sizes": s,
        "work": ctx["work"],
        "has_gn": bool(has_gn),
        "has_nominal": bool(ctx["has_nominal"]),
        "real": real,
        # the solver settings of the OCP file's options(...): the generated defaults, which a
        # handle opened on this folder starts from (Solver.load)
        "settings": _settings_of(disc).as_dict(),
        "state_names": list(disc.data.state_names),
        "control_names": list(disc.data.control_names),
        "files": sorted(list(files) + [meta_file]),
        "sources": {"strict": build_ctx["strict_sources"], "casadi": f"{name}_casadi.c", "main": main_file},
        "cdef": f"{name}_cdef.h",
        # sha256 of every other file, and of the problem (codegen/cache.py): a second
        # `dopus-gen generate` of an unchanged problem finds both and writes nothing
        "sha256": {f: hashlib.sha256(files[f].encode("utf-8")).hexdigest() for f in sorted(files)},
    }
    if getattr(declared, "scaling", None) is not None:
        meta["scaling"] = declared.scaling.as_dict()     # docs/algorithm.md section 16
    if soft["nsoft"]:
        meta["soft_rows"] = soft["nsoft"]
        meta["qp_always_feasible"] = soft["always_feasible"]
    if problem_hash is not None:
        meta["problem_hash"] = problem_hash
    files[meta_file] = json.dumps(meta, indent=2, sort_keys=True) + "\n"
    return files


def folder_up_to_date(out_dir: Path, problem_hash: str) -> bool:
    """True if ``out_dir`` holds the generation of this problem hash, every file intact."""
    path = find_meta(Path(out_dir))
    if path is None:
        return False
    try:
        meta = json.loads(path.read_text())
        digests = meta["sha256"]
        if meta.get("problem_hash") != problem_hash or set(meta["files"]) != set(digests) | {path.name}:
            return False
        for fname, digest in digests.items():
            f = Path(out_dir) / fname
            if not f.is_file() or hashlib.sha256(f.read_bytes()).hexdigest() != digest:
                return False
    except (OSError, ValueError, KeyError, TypeError, AttributeError):
        return False
    return True


def write_folder(files: Dict[str, str], out_dir: Path) -> Path:
    """Write the files; replace a previous generation, refuse to overwrite anything else.

    Files whose content is unchanged are left alone (their time stamps too, so a Makefile
    build after regenerating an unchanged problem recompiles nothing); files of the previous
    generation that are no longer produced are removed.
    """
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise CodegenError(f"output '{out_dir}' exists and is not a directory")
    if out_dir.is_dir():
        meta_path = find_meta(out_dir)
        if meta_path is not None:
            for fname in json.loads(meta_path.read_text()).get("files", []):
                p = out_dir / fname
                if fname not in files and p.is_file() and p.parent == out_dir:
                    p.unlink()
        else:
            foreign = sorted(p.name for p in out_dir.iterdir() if p.name != "build")
            if foreign:
                raise CodegenError(f"output folder '{out_dir}' is not empty and was not generated by "
                                   f"dopus-gen (found {', '.join(foreign[:5])}); choose another folder")
    out_dir.mkdir(parents=True, exist_ok=True)
    for fname in sorted(files):
        path = out_dir / fname
        data = files[fname].encode("utf-8")
        if path.is_file() and path.read_bytes() == data:
            continue
        write_bytes(path, data)
    return out_dir


def generate(disc: Any, out_dir, *, offline_guess: Optional[bool] = None, real: Optional[str] = None) -> Path:
    """Generate the C folder of ``disc`` into ``out_dir`` and return its path.

    ``offline_guess`` overrides the OCP option of the same name: when on, the OCP is solved
    with IPOPT at its default x0 and the primal-dual solution becomes static data
    (DOPUS_HAS_NOMINAL 1), so firmware can start warm (``dopus_init_nominal``).
    ``real`` (``"double"`` or ``"float"``) overrides the OCP option of the same name.
    """
    want_nominal = _option(disc.spec.options, "offline_guess", False) \
        if offline_guess is None else bool(offline_guess)
    from .cache import problem_hash as _problem_hash

    real = real_of(disc, real)
    phash = _problem_hash(disc, bool(want_nominal), real)
    if folder_up_to_date(Path(out_dir), phash):
        return Path(out_dir)
    nominal = None
    if want_nominal:
        from ..reference.offline import solve_ocp

        nominal, info = solve_ocp(disc, np.asarray(_attr(disc.data, "x0"), dtype=float))
        _check_offline(info)
    files = render_folder(disc, nominal, problem_hash=phash, real=real)
    return write_folder(files, Path(out_dir))


def _check_offline(info: Any) -> None:
    success = _option(info, "success", None)
    status = _option(info, "status", None)
    if success is False or (success is None and status is not None
                            and str(status) not in ("Solve_Succeeded", "0")):
        raise CodegenError(f"offline_guess: the IPOPT solve at x0 did not converge (status {status!r}); "
                           "the nominal guess would not be a solution")


def generate_file(ocp_file, out_dir=None, *, offline_guess: Optional[bool] = None,
                  real: Optional[str] = None) -> Path:
    """``dopus-gen generate``: load the OCP file, discretise, generate (default generated/<name>)."""
    from ..problem.derivatives import build_functions
    from ..problem.ocp import load_ocp

    ocp = load_ocp(ocp_file)
    disc = build_functions(ocp)
    if out_dir is None:
        out_dir = Path("generated") / check_name(_attr(disc.data, "name"))
    return generate(disc, out_dir, offline_guess=offline_guess, real=real)


__all__ = ["CodegenError", "generate", "generate_file", "render_folder", "read_meta", "find_meta",
           "rename_placeholder", "render_sizes_header", "c_double", "STRICT_CFLAGS", "CASADI_CFLAGS",
           "folder_up_to_date", "silence_unused_parameters", "single_precision", "real_of"]
