"""Build the C QP solver (runtime_c/dopus_qp.c) for given sizes and drive it from numpy.

``build_qp_solver(N, nx, nu, ng, nr, ne, workdir)`` writes a ``dopus_sizes.h``, compiles
``dopus_qp.c`` and ``dopus_linalg.c`` with the project's strict C flags into an object
file, links it into a cffi extension module (API mode) and returns a :class:`QPSolverHandle`.
Builds are cached per size and source hash under ``workdir``.

The QP dict format (shared with ``dopus_codegen.reference.qp``):
``N, nx, nu, ng, nr, ne; H (N,nw,nw); g (N,nw); Phi (N,nx,nw); b (N,nx); x0 (nx,);
HN (nx,nx); gN (nx,); lbw, ubw (N,nw); lbxN, ubxN (nx,); C (N,ng,nw); lg, ug (N,ng);
R (nr,nx); lr, ur (nr,); Req (ne,nx); req (ne,)``. Missing bound/constraint entries
default to "no bound" / empty. Solutions use the signed multipliers of dopus_qp.h.
"""
from __future__ import annotations

import hashlib
import importlib.machinery
import importlib.util
import os
import re
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from dopus_codegen import vocabulary
from dopus_codegen.codegen.generate import render_sizes_header
from dopus_codegen.paths import runtime_c_dir

from dopus_codegen.codegen.flags import DEFAULT_OPT, PIC, QP_HARNESS_OPT, STRICT_CFLAGS as _STRICT

STRICT_CFLAGS = [*_STRICT, QP_HARNESS_OPT, PIC]

#: QP status names by code (enum dopus_qp_status of runtime_c/dopus_qp.h).
STATUS_NAMES = {code: name for name, code in vocabulary.qp_status().codes.items()}

_SOURCES = ("dopus_qp.c", "dopus_linalg.c", "dopus_qp.h", "dopus_linalg.h")


class QPHarnessError(RuntimeError):
    """Raised for a bad QP dict or a failed build."""


def _cc() -> str:
    return os.environ.get("CC", "cc")


def sizes_header(N: int, nx: int, nu: int, ng: int, nr: int, ne: int, soft: int = 0) -> str:
    """The runtime's sizes header (templates/sizes.h.j2) for a QP of these sizes (``soft``:
    1 for a solver that reads the soft weights, DOPUS_NSOFT > 0)."""
    return render_sizes_header("dopus", dict(N=N, nx=nx, nu=nu, ng=ng, nr=nr, ne=ne, nsoft=int(soft)),
                               header="QP sizes for the dopus_qp test harness")


def _eval_c_int(expr: str) -> int:
    """Evaluate a preprocessed C integer constant expression (+ - * / ?: > parentheses)."""
    py = expr
    # (a) > 0 ? (a) : 1  ->  ((a) if (a) > 0 else 1); the only ternary form in dopus_qp.h
    for _ in range(10):
        m = re.search(r"\(\s*([^()?:]*|\([^()]*\))\s*\)\s*>\s*0\s*\?\s*\(([^()]*)\)\s*:\s*1", py)
        if not m:
            break
        py = py[: m.start()] + f"(({m.group(2)}) if ({m.group(1)}) > 0 else 1)" + py[m.end():]
    if not re.fullmatch(r"[0-9\s()+\-*/<>=a-z]*", py):
        raise QPHarnessError(f"cannot evaluate array size '{expr}'")
    return int(eval(py.replace("/", "//"), {"__builtins__": {}}, {}))


def _cdef_from_header(header_dir: Path, build_dir: Path) -> str:
    """The public declarations of dopus_qp.h with all sizes folded to integers (cffi needs
    plain numbers), obtained from the C preprocessor so Python and C cannot drift apart."""
    src = build_dir / "cdef_src.c"
    src.write_text('#include "dopus_qp.h"\n')
    # with the build's flags: they may change the workspace (DOPUS_QP_PHIT)
    out = subprocess.run([_cc(), "-E", "-P", *_extra_cflags(), f"-I{build_dir}", f"-I{header_dir}", str(src)],
                         check=True, capture_output=True, text=True).stdout

    def fold(m: re.Match) -> str:
        return f"[{_eval_c_int(m.group(1))}]"

    # fold innermost bracket contents (they contain no brackets)
    out = re.sub(r"\[([^\[\]]+)\]", fold, out)
    return out


def _extra_cflags() -> list:
    """Additional C flags from the environment variable DOPUS_QP_CFLAGS (for example
    ``-DDOPUS_QP_TRACE`` for the iteration log on stderr); part of the build cache key."""
    return os.environ.get("DOPUS_QP_CFLAGS", "").split()


def _source_hash(sizes: tuple) -> str:
    # "cdef-flags": the declarations are preprocessed with the extra flags (a build cached
    # before that may declare a workspace of another layout)
    h = hashlib.sha256(repr((sizes, _extra_cflags(), "cdef-flags")).encode())
    for name in _SOURCES:
        h.update((runtime_c_dir() / name).read_bytes())
    return h.hexdigest()[:16]


def default_workdir() -> Path:
    return Path(tempfile.gettempdir()) / f"dopus_qp_builds_{os.getuid()}"


def build_qp_solver(N: int, nx: int, nu: int, ng: int = 0, nr: int = 0, ne: int = 0,
                    workdir: str | os.PathLike | None = None, soft: bool = False) -> "QPSolverHandle":
    """Compile the QP solver for these sizes (cached) and return a handle; ``soft``: with
    the soft rows compiled in (the weights of the QP dict are read, see
    :mod:`dopus_codegen.reference.qp`)."""
    sizes = tuple(int(v) for v in (N, nx, nu, ng, nr, ne))
    N, nx, nu, ng, nr, ne = sizes
    if N < 1 or nx < 1 or nu < 0 or ng < 0 or nr < 0 or ne < 0:
        raise QPHarnessError(f"invalid QP sizes N={N} nx={nx} nu={nu} ng={ng} nr={nr} ne={ne}: "
                             "need N >= 1, nx >= 1 and nu, ng, nr, ne >= 0")
    workdir = Path(workdir) if workdir is not None else default_workdir()
    workdir.mkdir(parents=True, exist_ok=True)
    key = f"qp_{N}_{nx}_{nu}_{ng}_{nr}_{ne}{'_soft' if soft else ''}_{_source_hash(sizes)}"
    final = workdir / key
    modname = f"_dopus_qp_{key}"
    if not (final / "done").exists():
        tmp = Path(tempfile.mkdtemp(prefix=key + ".", dir=workdir))
        try:
            _build(tmp, sizes, modname, int(bool(soft)))
            (tmp / "done").write_text("ok\n")
            try:
                os.replace(tmp, final)
            except OSError:
                # another process finished the same build first
                shutil.rmtree(tmp, ignore_errors=True)
        except BaseException:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
    handle = QPSolverHandle(final, modname, sizes)
    handle.soft = bool(soft)
    return handle


def _build(build_dir: Path, sizes: tuple, modname: str, soft: int = 0) -> None:
    import cffi

    rc = runtime_c_dir()
    (build_dir / "dopus_sizes.h").write_text(sizes_header(*sizes, soft=soft))
    objs = []
    for name in ("dopus_qp.c", "dopus_linalg.c"):
        obj = build_dir / (name[:-2] + ".o")
        res = subprocess.run([_cc(), *STRICT_CFLAGS, *_extra_cflags(), f"-I{build_dir}", f"-I{rc}", "-c", str(rc / name),
                              "-o", str(obj)], capture_output=True, text=True)
        if res.returncode != 0:
            raise QPHarnessError(f"compiling {name} failed:\n{res.stderr}")
        objs.append(str(obj))
    ffi = cffi.FFI()
    ffi.cdef(_cdef_from_header(rc, build_dir))
    ffi.set_source(modname, '#include "dopus_qp.h"\n', include_dirs=[str(build_dir), str(rc)],
                   extra_objects=objs, extra_compile_args=[DEFAULT_OPT, *_extra_cflags()], libraries=["m"])
    ffi.compile(tmpdir=str(build_dir), verbose=False)


def _load_module(build_dir: Path, modname: str):
    if modname in sys.modules:
        return sys.modules[modname]
    for f in build_dir.iterdir():
        if f.name.startswith(modname) and f.suffix == ".so":
            loader = importlib.machinery.ExtensionFileLoader(modname, str(f))
            spec = importlib.util.spec_from_file_location(modname, str(f), loader=loader)
            mod = importlib.util.module_from_spec(spec)
            loader.exec_module(mod)
            sys.modules[modname] = mod
            return mod
    raise QPHarnessError(f"no compiled module in {build_dir}")


def _arr(qp: dict, key: str, shape: tuple, default=None) -> np.ndarray:
    if key not in qp or qp[key] is None:
        if default is None:
            raise QPHarnessError(f"QP dict is missing '{key}' (shape {shape})")
        return np.full(shape, default, dtype=float)
    a = np.asarray(qp[key], dtype=float)
    if a.size == 0 and int(np.prod(shape)) == 0:
        return np.zeros(shape)
    if a.shape != shape:
        raise QPHarnessError(f"QP dict entry '{key}' has shape {a.shape}, expected {shape}")
    return a


class QPSolverHandle:
    """A compiled QP solver for fixed sizes; ``solve(qp)`` returns ``(sol, info)``."""

    def __init__(self, build_dir: Path, modname: str, sizes: tuple):
        self.build_dir = Path(build_dir)
        self.sizes = sizes
        self.N, self.nx, self.nu, self.ng, self.nr, self.ne = sizes
        self._mod = _load_module(self.build_dir, modname)
        self.ffi, self.lib = self._mod.ffi, self._mod.lib
        self._ws = self.ffi.new("dopus_qp_workspace *")
        self._in = self.ffi.new("dopus_qp_in *")
        self._sol = self.ffi.new("dopus_qp_sol *")
        self._info = self.ffi.new("dopus_qp_info *")
        self._set = self.ffi.new("dopus_qp_settings *")
        self._keep = []
        self.soft = False

    @property
    def objects(self) -> list:
        """The compiled solver object files (for symbol checks)."""
        return [self.build_dir / "dopus_qp.o", self.build_dir / "dopus_linalg.o"]

    @property
    def workspace_size(self) -> int:
        return int(self.lib.dopus_qp_workspace_size())

    def _field(self, cdata, name: str) -> np.ndarray:
        ptr = getattr(cdata, name)
        return np.frombuffer(self.ffi.buffer(ptr), dtype=np.float64)

    def _set_vec(self, name: str, value: np.ndarray, cols: int) -> None:
        """Copy an (rows, n) array into a struct field of shape (rows, max(1, cols))."""
        buf = self._field(self._in, name)
        value = np.asarray(value, dtype=float)
        rows = value.shape[0] if value.ndim == 2 else 1
        width = max(1, cols)
        view = buf.reshape(rows, width) if value.ndim == 2 else buf.reshape(1, -1)
        view[...] = 0.0
        if cols > 0:
            view[:, :cols] = value.reshape(rows, cols)

    def _mat_ptr(self, a: np.ndarray):
        # a.T in C order is a in column-major order
        f = np.ascontiguousarray(np.asarray(a, dtype=float).T)
        self._keep.append(f)
        return self.ffi.cast("double *", self.ffi.from_buffer(f))

    def solve(self, qp: dict, tol: float = 1e-8, max_iter: int = 100, warm: dict | None = None,
              refine_steps: int = 1, hess_shift: float = 0.0, active_set: int = 0):
        N, nx, nu, ng, nr, ne = self.sizes
        nw = nx + nu
        for key, val in (("N", N), ("nx", nx), ("nu", nu), ("ng", ng), ("nr", nr), ("ne", ne)):
            if key in qp and int(qp[key]) != val:
                raise QPHarnessError(f"QP dict has {key}={qp[key]} but the solver was built for {key}={val}")
        inf = np.inf
        H = _arr(qp, "H", (N, nw, nw))
        g = _arr(qp, "g", (N, nw))
        Phi = _arr(qp, "Phi", (N, nx, nw))
        b = _arr(qp, "b", (N, nx))
        x0 = _arr(qp, "x0", (nx,))
        HN = _arr(qp, "HN", (nx, nx))
        gN = _arr(qp, "gN", (nx,))
        lbw = _arr(qp, "lbw", (N, nw), -inf)
        ubw = _arr(qp, "ubw", (N, nw), inf)
        lbxN = _arr(qp, "lbxN", (nx,), -inf)
        ubxN = _arr(qp, "ubxN", (nx,), inf)
        C = _arr(qp, "C", (N, ng, nw), 0.0)
        lg = _arr(qp, "lg", (N, ng), -inf)
        ug = _arr(qp, "ug", (N, ng), inf)
        R = _arr(qp, "R", (nr, nx), 0.0)
        lr = _arr(qp, "lr", (nr,), -inf)
        ur = _arr(qp, "ur", (nr,), inf)
        Req = _arr(qp, "Req", (ne, nx), 0.0)
        req = _arr(qp, "req", (ne,), 0.0)

        self._keep = []
        inp = self._in
        dummy = self._mat_ptr(np.zeros(1))
        for k in range(N):
            inp.H[k] = self._mat_ptr(H[k])
            inp.Phi[k] = self._mat_ptr(Phi[k])
            inp.C[k] = self._mat_ptr(C[k]) if ng > 0 else dummy
        inp.HN = self._mat_ptr(HN)
        inp.R = self._mat_ptr(R) if nr > 0 else dummy
        inp.Req = self._mat_ptr(Req) if ne > 0 else dummy
        self._set_vec("g", g, nw)
        self._set_vec("b", b, nx)
        self._set_vec("x0", x0[None, :], nx)
        self._set_vec("gN", gN[None, :], nx)
        self._set_vec("lbw", lbw, nw)
        self._set_vec("ubw", ubw, nw)
        self._set_vec("lbxN", lbxN[None, :], nx)
        self._set_vec("ubxN", ubxN[None, :], nx)
        self._set_vec("lg", lg, ng)
        self._set_vec("ug", ug, ng)
        self._set_vec("lr", lr[None, :], nr)
        self._set_vec("ur", ur[None, :], nr)
        self._set_vec("req", req[None, :], ne)
        inp.hess_shift = float(hess_shift)
        if self.soft:
            from dopus_codegen.reference.qp import soft_weights

            ws, wt = soft_weights(qp)
            for name, row in zip(("zl", "zu", "Zl", "Zu"), ws):
                self._set_vec(name, row[None, :], nw + ng)
            for name, row in zip(("zlN", "zuN", "ZlN", "ZuN"), wt):
                self._set_vec(name, row[None, :], nx + nr)
        else:
            from dopus_codegen.reference.qp import has_soft

            if has_soft(qp):
                raise QPHarnessError("QP dict has soft weights but the solver was built without soft rows "
                                     "(build_qp_solver(..., soft=True))")

        st = self._set
        self.lib.dopus_qp_settings_default(st)
        st.tol = float(tol)
        st.max_iter = int(max_iter)
        st.refine_steps = int(refine_steps)
        st.warm_start = 0
        st.active_set = 0
        if warm is not None:
            st.warm_start = 1
            st.active_set = int(active_set)   # the active-set start (dopus_qp.h) from warm
            self._write_sol(warm)
        status = self.lib.dopus_qp_solve(self._ws, inp, st, self._sol, self._info)
        return self._read_sol(), self._read_info(status)

    def solve_again(self) -> int:
        """The QP, settings and warm-start point of the last ``solve`` solved once more (its
        data kept in place; for timing the solve call alone). Returns the status code; the
        warm-start point is the last solution, so use it after cold solves only."""
        return int(self.lib.dopus_qp_solve(self._ws, self._in, self._set, self._sol, self._info))

    def solve_with_deadline(self, clock, deadline: float, iter_price: float, warm: dict | None = None):
        """The QP and settings of the last ``solve`` solved once more with the clock hook
        ``clock`` (a cffi callback ``double(void *)``), ``deadline`` and the price of the first
        iteration ``iter_price`` (dopus_qp_settings, docs/algorithm.md section 14), from
        ``warm`` when given. Returns ``(solution, info)`` as ``solve`` does."""
        if warm is not None:
            self._write_sol(warm)
        st = self._set
        st.clock, st.deadline, st.iter_price = clock, float(deadline), float(iter_price)
        status = self.solve_again()
        return self._read_sol(), self._read_info(status)

    def prefactor_guess(self, warm: dict) -> bool:
        """dopus_qp_prefactor_guess on the QP of the last ``solve`` (its data and hess_shift in
        place) from the warm-start point ``warm``: the active-set start's first factorisation,
        kept in the workspace for ``solve_prefactored``. Returns whether it was kept."""
        self._write_sol(warm)
        return bool(self.lib.dopus_qp_prefactor_guess(self._ws, self._in, self._sol))

    def solve_prefactored(self, warm: dict, active_set: int = 8):
        """The QP and tolerances of the last ``solve`` solved once more from ``warm`` with the
        active-set start and ``settings.prefactored`` (the factorisation ``prefactor_guess``
        kept, for the first sweep when its guess is the same). Returns ``(solution, info)``."""
        st = self._set
        st.warm_start, st.active_set, st.prefactored = 1, int(active_set), 1
        self._write_sol(warm)
        status = self.lib.dopus_qp_solve(self._ws, self._in, st, self._sol, self._info)
        st.prefactored = 0
        return self._read_sol(), self._read_info(status)

    def infeasible_row(self):
        """After a solve that returned primal_infeasible: ``(stage, j, side)`` of the row
        dopus_qp_infeasible_row names (the row with the largest multiplier of the
        certificate), or None."""
        out = self.ffi.new("int[3]")
        if not self.lib.dopus_qp_infeasible_row(self._ws, self._in, out, out + 1, out + 2):
            return None
        return int(out[0]), int(out[1]), int(out[2])

    def _sol_views(self) -> dict:
        N, nx, nu, ng, nr, ne = self.sizes
        nw = nx + nu
        s = self._sol
        return {
            "x": self._field(s, "x").reshape(N + 1, nx),
            "u": self._field(s, "u").reshape(N, max(1, nu))[:, :nu],
            "lam": self._field(s, "lam").reshape(N + 1, nx),
            "mu_b": self._field(s, "mu_b").reshape(N, nw),
            "mu_bN": self._field(s, "mu_bN").reshape(nx),
            "mu_g": self._field(s, "mu_g").reshape(N, max(1, ng))[:, :ng],
            "mu_r": self._field(s, "mu_r").reshape(max(1, nr))[:nr],
            "nu": self._field(s, "nu").reshape(max(1, ne))[:ne],
        }

    def _write_sol(self, warm: dict) -> None:
        views = self._sol_views()
        for key, view in views.items():
            if key in warm and warm[key] is not None:
                val = np.asarray(warm[key], dtype=float)
                if val.shape != view.shape:
                    raise QPHarnessError(f"warm start '{key}' has shape {val.shape}, expected {view.shape}")
                view[...] = val
            else:
                view[...] = 0.0

    def _read_sol(self) -> dict:
        return {k: np.array(v) for k, v in self._sol_views().items()}

    def _read_info(self, status: int) -> dict:
        i = self._info
        return {
            "status": STATUS_NAMES.get(int(status), f"unknown({status})"),
            "status_code": int(status),
            "iterations": int(i.iterations),
            "factorizations": int(i.factorizations),
            "active_set": int(i.active_set),
            "prefactored": bool(i.prefactored),
            "certified": bool(i.certified),
            "inertia_corrections": int(i.inertia_corrections),
            "terminal_augmentations": int(i.terminal_augmentations),
            "pivot_floors": int(i.pivot_floors),
            "delta": float(i.delta),
            "res_stat": float(i.res_stat),
            "res_eq": float(i.res_eq),
            "res_ineq": float(i.res_ineq),
            "res_comp": float(i.res_comp),
            "res_stat_scaled": float(i.res_stat_scaled),
            "res_eq_scaled": float(i.res_eq_scaled),
            "res_ineq_scaled": float(i.res_ineq_scaled),
            "res_comp_scaled": float(i.res_comp_scaled),
            "obj": float(i.obj),
        }
