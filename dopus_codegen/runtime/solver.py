"""The Python handle of a generated C solver (cffi, ABI mode): :class:`Solver`.

The way to drive a generated solver from Python. :class:`Solver` implements the backend
protocol of docs/algorithm.md section 7, so the convergence study (``dopus-gen converge
--backend c``) and the software-in-the-loop runs drive the generated C exactly as they
drive :class:`~dopus_codegen.reference.dopus.ReferenceDopus`::

    from dopus_codegen import Solver

    solver = Solver.load("out/robot_arm")       # a generated folder: its generated defaults
    solver.init_nominal(xhat0)                  # or init(xhat0, guess)
    u0 = solver.feedback(xhat0); solver.prepare()

:meth:`Solver.load` opens a folder of ``dopus-gen generate`` (built first if needed) with
the settings generated into it (the OCP file's ``options(...)``, recorded in the folder's
``<name>_meta.json``); ``Solver(disc)`` generates and builds the problem of an OCP file into
the build cache (:mod:`dopus_codegen.codegen.cache`: ``$DOPUS_CACHE_DIR``, default
``~/.cache/dopus-codegen``, keyed by a hash of the problem, so an unchanged problem is
neither regenerated nor recompiled; it says on stderr when it generates or compiles) with
the file's settings. Either takes a :class:`~dopus_codegen.settings.Settings` instead, and
settings changed by name: ``Solver.load(folder, M=3)``; :attr:`Solver.settings` reads them
back.

numpy in, numpy out: every array is checked for shape, dtype and finiteness before it
reaches C; a bad input raises :class:`DopusError` (which is also a ``ValueError``) naming
the argument, with ``status`` the C status code. A failing call leaves the solver usable:
the next good call works (the C runtime keeps its state consistent).
"""
from __future__ import annotations

import os
import tempfile
import threading
from pathlib import Path
from typing import Dict, Optional

import numpy as np

from .. import settings, vocabulary
from ..errors import PARAMETER_ORDER, DopusError, qp_failure_text, status_code
from ..settings import SettingError, Settings, of_problem as settings_of_problem

__all__ = ["Solver", "CSolver", "DopusError", "STATUS", "QP_STATUS", "PHASES", "load_library", "build_for"]

#: C status codes by name (enum dopus_status of runtime_c/dopus_solver.h).
STATUS = vocabulary.status().codes
#: QP status codes by name (enum dopus_qp_status of runtime_c/dopus_qp.h).
QP_STATUS = vocabulary.qp_status().codes
#: Health flags by bit (enum dopus_flag of runtime_c/dopus_solver.h): bit -> name.
FLAGS = {bit: name for name, bit in vocabulary.enum("dopus_flag").codes.items()}
#: Timed phases, in the order of enum dopus_phase (runtime_c/dopus_timer.h).
PHASES = vocabulary.phases()
STATUS_OK, STATUS_QP = status_code("ok"), status_code("qp")
STATUS_NOT_CONVERGED = status_code("not_converged")
STATUS_NONFINITE_INPUT, STATUS_INVALID_ARGUMENT = status_code("nonfinite_input"), status_code("invalid_argument")
STATUS_ALREADY_PREPARED = status_code("already_prepared")
_DIMS = ("N", "nx", "nu", "nw", "np", "ng", "nr", "ne", "has_gn", "has_nominal")
_INT_MAX = 2**31 - 1   # the largest C int (qp_max_iter)


# ---------------------------------------------------------------------------------- build
_LIB_CACHE: Dict[str, tuple] = {}
_DISC_CACHE: Dict[int, tuple] = {}
_LOCK = threading.Lock()


def cache_root() -> Path:
    from ..codegen.cache import cache_root as _root

    return _root()


def build_for(disc, cache_dir=None, echo=None, real: Optional[str] = None) -> Path:
    """The generated and built folder of ``disc`` in the cache (``cache_dir``, else
    ``$DOPUS_CACHE_DIR``, else ``~/.cache/dopus-codegen``), keyed by the problem hash of
    :mod:`dopus_codegen.codegen.cache`: an unchanged problem is neither regenerated nor
    recompiled. Says on stderr (or to ``echo``) when it generates or compiles. ``real``
    (``"double"``, ``"float"``) overrides the OCP file's ``options(real=...)``."""
    import sys

    from ..codegen import cache
    from ..codegen.build import build
    from ..codegen.generate import real_of, render_folder, write_folder

    say = echo or (lambda msg: print(msg, file=sys.stderr, flush=True))
    real = real_of(disc, real)
    key = (id(disc), real)
    with _LOCK:
        hit = _DISC_CACHE.get(key)
        if hit is not None and hit[0] is disc and (cache_dir is None or Path(cache_dir) / "problems" == hit[1].parent):
            build(hit[1], cache_dir=cache_dir, echo=say)
            return hit[1]
    root = cache.cache_root(cache_dir)
    out = root / "problems" / f"{disc.name}-{cache.problem_hash(disc, None, real)[:20]}"
    if not (out / f"{disc.name}_meta.json").is_file():
        files = render_folder(disc, None, real=real)
        cache.writable_folder("problems", cache_dir)
        say(f"dopus-codegen: generating C for '{disc.name}' into {out}")
        tmp = Path(tempfile.mkdtemp(prefix=f".{disc.name}-", dir=str(out.parent)))
        write_folder(files, tmp)
        try:
            os.rename(tmp, out)
        except OSError:  # another process won the race: its folder has the same content
            import shutil

            shutil.rmtree(tmp, ignore_errors=True)
    try:
        build(out, cache_dir=cache_dir, echo=say)
    except OSError as exc:
        if not str(exc.filename or "").startswith(str(root)):
            raise
        raise cache.cache_error(root, exc) from None    # the folder in the cache could not be written
    with _LOCK:
        _DISC_CACHE[key] = (disc, out)
    return out


def load_library(folder) -> tuple:
    """``(ffi, lib, meta)`` of a built folder (built first if needed); cached per library."""
    import cffi

    from ..codegen.build import build
    from ..codegen.folder import read_meta

    folder = Path(folder)
    res = build(folder)
    meta = read_meta(folder)
    key = str(res.shared_lib)
    stamp = res.shared_lib.stat().st_mtime_ns
    with _LOCK:
        hit = _LIB_CACHE.get(key)
        if hit is not None and hit[3] == stamp:
            return hit[0], hit[1], hit[2]
        ffi = cffi.FFI()
        ffi.cdef(Path(res.cdef_path).read_text())
        lib = ffi.dlopen(str(res.shared_lib))
        _LIB_CACHE[key] = (ffi, lib, meta, stamp)
    return ffi, lib, meta


#: enum dopus_budget_unit (runtime_c/dopus_solver.h, docs/algorithm.md section 14)
BUDGET_UNITS = {"time": 1, "work": 2}


def _info_property(field: str, kind=int, doc: Optional[str] = None) -> property:
    """A read-only property: ``kind(info.field)`` of ``<name>_get_info``."""
    return property(lambda self: kind(getattr(self._info(), field)), doc=doc)


def _settings_property(field: str, kind=int, doc: Optional[str] = None) -> property:
    """A read-only property: ``kind(settings.field)`` of ``<name>_get_settings``."""
    return property(lambda self: kind(getattr(self._c_settings(), field)), doc=doc)


def _setting_property(name: str) -> property:
    """A read-only property: the value of the setting ``name`` (a field of
    ``<name>_settings``) by its name in :mod:`dopus_codegen.settings`."""
    return property(lambda self: settings.value_of(name, getattr(self._c_settings(), name)))


def _array_property(fname: str, shape, doc: Optional[str] = None) -> property:
    """A read-only property: the array ``<name>_<fname>(solver, out)`` writes, of the shape
    ``shape(handle)``."""
    return property(lambda self: self._get(fname, shape(self)), doc=doc)


# ---------------------------------------------------------------------------------- handle
class Solver:
    """The generated C solver behind the backend protocol of docs/algorithm.md section 7.

    ``Solver(disc)``: the problem of an OCP file (``build_functions(load_ocp(path))``),
    generated and built into the build cache, with the file's settings;
    ``Solver.load(folder)``: a generated folder, with its generated settings. ``settings``
    replaces those settings whole, ``changes`` change some by name (``M=3``; None: not
    given); a bad value raises :class:`DopusError` (invalid argument) naming the setting.

    Read-only state after each call: ``x (N+1,nx)``, ``u (N,nu)``, ``lam (N+1,nx)``,
    ``mu_g (N,ng)``, ``mu_b (N,nw)``, ``mu_bN (nx,)``, ``mu_r (nr,)``, ``nu (ne,)``,
    ``rho (N,)``, ``recomputed`` (sorted stage list), ``qp_iterations``, ``qp_status``,
    ``status``, ``timings`` (seconds per phase of the last call that ran it, see
    :data:`PHASES`, plus ``prepare`` = the sum of its phases), ``ring_head``, ``settings``.
    """

    def __init__(self, disc=None, settings: Optional[Settings] = None, *, lib_dir=None,
                 real: Optional[str] = None, qp_warm_start: Optional[bool] = None, **changes):
        what = getattr(disc, "name", None) or "solver"
        if settings is not None and not isinstance(settings, Settings):
            raise DopusError.of("invalid_argument", f"{what}: settings must be a Settings, got {settings!r}")
        try:
            Settings().replace(**changes)        # a bad name or value fails before any build
        except SettingError as exc:
            raise DopusError.of("invalid_argument", f"{what}: {exc}") from None
        opened_on_folder = lib_dir is not None
        if lib_dir is None:
            if disc is None:
                raise ValueError("Solver needs a Discretized problem or lib_dir (a generated folder)")
            lib_dir = build_for(disc, real=real)
        self.lib_dir = Path(lib_dir)
        self._ffi, self._lib, self.meta = load_library(self.lib_dir)
        self.name = self.meta["name"]
        # the real type of the library: arrays cross the boundary as float32 in a float
        # build (converted from and to float64 here, the handle speaks float64)
        self.real = self.meta.get("real", "double")
        if real is not None and real != self.real:
            raise ValueError(f"the library in '{self.lib_dir}' is generated in {self.real}, not {real}")
        self._dtype = np.float32 if self.real == "float" else np.float64
        dims = self._ffi.new(f"{self.name}_dims *")
        self._c("get_dims")(dims)
        self.dims = {f: int(getattr(dims, f)) for f in _DIMS}
        self.N, self.nx, self.n_u, self.nw = (self.dims[f] for f in ("N", "nx", "nu", "nw"))
        self.np, self.ng, self.nr, self.ne = (self.dims[f] for f in ("np", "ng", "nr", "ne"))
        self.has_gn, self.has_nominal = bool(self.dims["has_gn"]), bool(self.dims["has_nominal"])
        self.disc = disc
        if disc is not None:
            want = (disc.N, disc.nx, disc.nu, disc.np, disc.ng, disc.nr, disc.ne)
            have = (self.N, self.nx, self.n_u, self.np, self.ng, self.nr, self.ne)
            if tuple(int(v) for v in want) != have or disc.name != self.name:
                raise ValueError(f"the library in '{self.lib_dir}' is problem '{self.name}' with sizes "
                                 f"(N, nx, nu, np, ng, nr, ne) = {have}, the given problem is "
                                 f"'{disc.name}' with {tuple(int(v) for v in want)}")
        # the codes of the headers this library was compiled from (the generated folder)
        self.enums = vocabulary.generated_enums(str(self.lib_dir.resolve()), self.name)
        size = int(self._c("solver_sizeof")())
        self.sizeof = size
        # doubles keep the struct 8-byte aligned; the C side's setup writes every field
        self._mem = self._ffi.new("double[]", (size + 7) // 8)
        self._s = self._ffi.cast(f"{self.name}_solver *", self._mem)
        self._c("setup")(self._s, self._ffi.NULL)   # the generated settings (the OCP file's options)
        self.status = STATUS_OK
        if settings is None:
            settings = self._generated_settings() if opened_on_folder else settings_of_problem(disc)
        self.set_settings(settings.replace(**changes))
        if qp_warm_start is not None:  # None: the runtime's default (on)
            self.set_qp_warm_start(qp_warm_start)

    @classmethod
    def load(cls, folder, settings: Optional[Settings] = None, **changes) -> "Solver":
        """The solver of a folder generated by ``dopus-gen generate`` (built first if
        needed), with the settings generated into it (the OCP file's ``options(...)``),
        ``settings`` instead, or those changed by name (``M=3``)."""
        return cls(None, settings, lib_dir=folder, **changes)

    @classmethod
    def from_dir(cls, path, disc=None, settings: Optional[Settings] = None, **changes) -> "Solver":
        """Load an already generated (and built, or buildable) folder; ``disc`` (the problem
        it was generated from) names the rows of an infeasible QP."""
        return cls(disc, settings, lib_dir=path, **changes)

    def _generated_settings(self) -> Settings:
        """The folder's generated settings: its meta file's record of the OCP file's
        options, else (a folder generated before the record) the runtime's defaults."""
        recorded = self.meta.get("settings")
        return Settings.of(recorded) if recorded is not None else self.settings

    def set_settings(self, s: Settings) -> None:
        """Set every setting of ``s`` (a QP tolerance or iteration limit of None keeps the
        solver's own)."""
        if not isinstance(s, Settings):
            self._bad(f"settings must be a Settings, got {s!r}")
        if s.qp_tol is not None:
            self.set_qp_tol(s.qp_tol)
        if s.qp_max_iter is not None:
            self.set_qp_max_iter(s.qp_max_iter)
        self.set_M(s.M)
        self.set_mode(s.mode)
        self.set_hessian(s.hessian)
        self.set_regularization(s.regularization, s.reg_eps)
        self.set_cost_hessian(s.cost_hessian)
        self.set_levenberg_marquardt(s.lm)
        self._update("budget", budget=s.budget, budget_unit=BUDGET_UNITS[s.budget_unit])
        if s.anytime_tol is not None:
            self.set_anytime_tol(s.anytime_tol)
        self.set_M_adaptive(s.M_adaptive, s.M_min, s.M_max, s.M_eta)
        self.set_gate(s.gate, s.gate_hold)

    @property
    def settings(self) -> Settings:
        """The settings the solver runs with (``M`` as the runtime holds it: at most N-1)."""
        st = self._c_settings()
        return Settings(M=self.M, hessian=self.hessian, regularization=self.regularization, reg_eps=self.reg_eps,
                        cost_hessian=self.cost_hessian, lm="auto" if self.lm_auto else self.lm, qp_tol=self.qp_tol,
                        qp_max_iter=self.qp_max_iter, mode=self.mode, budget=float(st.budget),
                        budget_unit=self.budget_unit, anytime_tol=float(st.anytime_tol),
                        M_adaptive=bool(st.M_adaptive), M_min=int(st.M_min), M_max=int(st.M_max), M_eta=float(st.M_eta),
                        gate=float(st.gate), gate_hold=int(st.gate_hold))

    # ------------------------------------------------------------------ plumbing
    def _c(self, fname: str):
        return getattr(self._lib, f"{self.name}_{fname}")

    def call_c(self, fname: str, *args) -> int:
        """``<name>_<fname>(solver, *args)`` called directly, without the checks of the
        Python setters; returns the C status (for tests of the C side's own checks)."""
        return int(self._c(fname)(self._s, *args))

    def state_bytes(self) -> bytes:
        """A copy of the whole solver struct (settings and iterate included)."""
        return bytes(self._ffi.buffer(self._mem, self.sizeof))

    def copy_state_from(self, other: "Solver") -> None:
        """Copy the whole solver state of another handle on the same library, settings and
        iterate included (the two then face the same QP)."""
        if other.lib_dir != self.lib_dir or other.sizeof != self.sizeof:
            raise ValueError("copy_state_from: the two handles load different libraries")
        self._ffi.memmove(self._mem, other.state_bytes(), self.sizeof)

    def _status_text(self, status: int) -> str:
        return self._ffi.string(self._c("status_string")(int(status))).decode()

    def _check(self, status: int, what: str) -> None:
        status = int(status)
        self.status = status
        if status == STATUS_OK:
            return
        qp_status = None
        msg = f"{self.name}: {what}: {self._status_text(status)} (status {status})"
        if status == STATUS_QP:
            info = self._info()
            qp_status = int(info.qp_status)
            msg += "; " + qp_failure_text(self.enums["dopus_qp_status"].name(qp_status), int(info.qp_iterations),
                                          self.qp_max_iter, qp_status)
            row = self.qp_infeasible_row
            if row is not None:
                from ..problem.checks import describe_qp_row

                msg += "; " + describe_qp_row(self.disc, row)
        if what == "feedback" and "measurement_unusable" in self.flags:
            msg += "; at the measured state: handled as a missing measurement"
        elif what == "feedback" and status != STATUS_QP and "reinit_guess" in self.flags:
            msg += ("; at the measured state (the recovery's re-initialisation from it): the iterate is the "
                    "OCP file's guess, prepared for the next measurement")
        raise DopusError(msg, status, qp_status)

    def _bad(self, message: str, status: int = STATUS_INVALID_ARGUMENT):
        self.status = status
        raise DopusError(f"{self.name}: {message}", status)

    def _array(self, value, shape, what: str, check_finite: bool = True) -> np.ndarray:
        """A C-contiguous float64 copy of ``value`` with exactly ``shape`` (a vector may
        also come as a row or column)."""
        try:
            a = np.asarray(value)
        except Exception as exc:  # noqa: BLE001 - ragged lists and the like
            self._bad(f"{what}: not an array ({exc})")
        if a.dtype.kind not in "biuf":
            self._bad(f"{what}: expected real numbers, got dtype {a.dtype}")
        shape = tuple(int(s) for s in shape)
        if a.shape != shape:
            vector_like = len(shape) == 1 and a.size == shape[0] and sum(d != 1 for d in a.shape) <= 1
            if not vector_like:
                self._bad(f"{what}: expected shape {shape}, got {a.shape}")
            a = a.reshape(shape)
        a = np.ascontiguousarray(a, dtype=np.float64)
        if check_finite and not np.all(np.isfinite(a)):
            bad = np.argwhere(~np.isfinite(a))
            where = ", ".join(str(tuple(int(i) for i in b)) if a.ndim > 1 else str(int(b[0]))
                              for b in bad[:5])
            self._bad(f"{what}: NaN or Inf at index {where}", STATUS_NONFINITE_INPUT)
        return a

    def _ptr(self, a: Optional[np.ndarray]):
        """A pointer to ``a`` as the library's real type (an input converted to float32 in a
        float build; an output buffer must come from :meth:`_out`)."""
        if a is None or a.size == 0:
            return self._ffi.NULL
        if a.dtype != self._dtype:
            a = np.ascontiguousarray(a, dtype=self._dtype)
        return self._ffi.from_buffer(self._ffi.typeof(f"{self.name}_real[]"), a)

    def _out(self, shape) -> np.ndarray:
        """An output buffer of the library's real type (:meth:`_f64` reads it back)."""
        return np.zeros(shape, dtype=self._dtype)

    @staticmethod
    def _f64(a: np.ndarray) -> np.ndarray:
        return a if a.dtype == np.float64 else a.astype(np.float64)

    def _get(self, fname: str, shape) -> np.ndarray:
        out = self._out(shape)
        if out.size:
            self._c(fname)(self._s, self._ptr(out))
        return self._f64(out)

    def _setting(self, check, *args):
        """A value checked by :mod:`dopus_codegen.settings`; a bad one is DopusError
        (invalid argument) naming the setting."""
        try:
            return check(*args)
        except SettingError as exc:
            self._bad(str(exc))

    def _positive(self, v, what: str) -> float:
        return self._setting(settings.positive, what, v)

    # ------------------------------------------------------------------ settings
    def _c_settings(self):
        """The C settings struct (``<name>_get_settings``), a fresh copy."""
        st = self._ffi.new(f"{self.name}_settings *")
        self._c("get_settings")(self._s, st)
        return st

    def _info(self):
        """The C info struct (``<name>_get_info``), a fresh copy."""
        info = self._ffi.new(f"{self.name}_info *")
        self._c("get_info")(self._s, info)
        return info

    def update_settings_c(self, **fields) -> int:
        """``<name>_update_settings`` with the current settings and ``fields`` changed, called
        without the checks of the Python setters; returns the C status (for tests of the C
        side's own checks)."""
        st = self._c_settings()
        for k, v in fields.items():
            setattr(st, k, v)
        return int(self._c("update_settings")(self._s, st))

    def _update(self, what: str, **fields) -> None:
        self._check(self.update_settings_c(**fields), what)

    def set_M(self, M: int) -> None:
        """Stages re-linearised per iteration; values above N-1 mean the full RTI (N-1),
        as in the reference (:func:`dopus_codegen.settings.stages`)."""
        stages = self._setting(settings.stages, M, self.N)
        self._update(f"M={M!r}", M=stages)

    def set_mode(self, mode: str) -> None:
        self._update(f"mode={mode!r}", mode=self._setting(settings.code, "mode", mode))

    def set_hessian(self, hessian: str) -> None:
        code = self._setting(settings.code, "hessian", hessian)
        if hessian == "gauss-newton" and not self.has_gn:
            self._bad("hessian='gauss-newton' needs a least-squares stage cost (the OCP declares no "
                      "stage_least_squares)")
        self._update(f"hessian={hessian!r}", hessian=code)

    def set_regularization(self, regularization: str, reg_eps: Optional[float] = None) -> None:
        code = self._setting(settings.code, "regularization", regularization)
        eps = self.reg_eps if reg_eps is None else self._positive(reg_eps, "reg_eps")
        self._update(f"regularization={regularization!r}, reg_eps={reg_eps!r}", regularization=code, reg_eps=eps)

    def set_cost_hessian(self, cost_hessian: str) -> None:
        """``"fresh"``: the stage-cost Hessian of every stage is refreshed in every prepare;
        ``"stored"``: the paper's literal algorithm (docs/algorithm.md section 4 step 5)."""
        self._update(f"cost_hessian={cost_hessian!r}",
                     cost_hessian=self._setting(settings.code, "cost_hessian", cost_hessian))

    def set_levenberg_marquardt(self, lm) -> None:
        """Levenberg-Marquardt term: the QP uses the Hessian blocks plus ``lm * I``
        (docs/algorithm.md section 3): ``"auto"`` for the automatic, adaptive term (section
        10; it restarts from 0), or a fixed number >= 0."""
        v = self._setting(settings.levenberg_marquardt, lm)
        if v == settings.LM_AUTO:
            if self._c_settings().lm_auto:   # already on: restart it (off, then on)
                self._update("lm='auto'", lm_auto=0, lm=0.0)
            self._update("lm='auto'", lm_auto=1)
        else:
            self._update(f"lm={lm!r}", lm_auto=0, lm=v)

    lm = _info_property("lm", float, "The term of the next QP (fixed, or the current automatic value).")
    lm_auto = _settings_property("lm_auto", bool)
    lm_scale = _info_property("lm_scale", float, "The Hessian scale of the automatic term (section 10).")
    lm_held = _info_property("lm_held", bool, "The last prepare's convexity test raised the automatic term "
                             "(the flat stall test of section 9).")

    def set_qp_tol(self, tol: float) -> None:
        self._update("qp_tol", qp_tol=self._positive(tol, "qp_tol"))

    def set_qp_max_iter(self, max_iter: int) -> None:
        self._update("qp_max_iter", qp_max_iter=self._setting(settings.count, "qp_max_iter", max_iter, 1, _INT_MAX))

    def set_qp_warm_start(self, on: bool) -> None:
        """Warm start of the QP in feedback (default on), with a cold retry when it fails."""
        if not isinstance(on, (bool, np.bool_)) and on not in (0, 1):
            self._bad(f"qp_warm_start must be True or False, got {on!r}")
        self._update("qp_warm_start", qp_warm_start=int(bool(on)))

    # ------------------------------------------------------------------ anytime (section 14)
    def set_time_budget(self, seconds) -> None:
        """The budget per sampling instant in seconds of the solver's clock (0: off)."""
        v = self._setting(settings.nonnegative, "time_budget", seconds)
        self._update("time_budget", budget=v, budget_unit=BUDGET_UNITS["time"])

    def set_work_budget(self, units) -> None:
        """The budget per sampling instant in work units (function evaluations 1, a QP solve
        N; 0: off): deterministic, the unit the reference counts."""
        v = self._setting(settings.nonnegative, "work_budget", units)
        self._update("work_budget", budget=v, budget_unit=BUDGET_UNITS["work"])

    def set_gate(self, gate, hold=None) -> None:
        """The measurement gate (docs/algorithm.md section 9): ``gate`` 0 (off) or the largest
        jump ``|xhat0_i - x_0,i| / scale_x_i`` accepted, ``hold`` the most measurements in a
        row held out (None: unchanged)."""
        g = self._setting(settings.validate, "gate", gate)
        h = int(self._c_settings().gate_hold) if hold is None else self._setting(settings.validate, "gate_hold", hold)
        self._update("gate", gate=g, gate_hold=h)

    def set_anytime_tol(self, tol) -> None:
        self._update("anytime_tol", anytime_tol=self._positive(tol, "anytime_tol"))

    def set_M_adaptive(self, on: bool = True, M_min: int = 0, M_max=None, eta=None) -> None:
        """Adaptive M (section 14): the stages whose secant residual ``rho_k |domega_k|``
        exceeds ``eta`` times the KKT proxy, between ``M_min`` and ``M_max``."""

        M_max = self.N - 1 if M_max is None else M_max
        eta = float(vocabulary.constants()["ADAPTIVE_ETA"]) if eta is None else eta
        on, M_min, M_max, eta = self._setting(settings.check_adaptive_M, on, M_min, M_max, eta, self.N)
        self._update("M_adaptive", M_adaptive=int(on), M_min=M_min, M_max=M_max, M_eta=eta)

    @property
    def budget_unit(self) -> str:
        """``"time"`` or ``"work"`` (the budget is off when it is 0)."""
        return {v: k for k, v in BUDGET_UNITS.items()}[int(self._c_settings().budget_unit)]

    budget = _settings_property("budget", float)
    anytime_tol = _settings_property("anytime_tol", float)
    M_adaptive = _settings_property("M_adaptive", bool)
    extra_iterations = _info_property("extra_iterations", int, "Extra iterations of the last prepare.")
    instant_stages = _info_property("instant_stages", int, "Stages re-linearised in the last instant.")
    budget_used = _info_property("budget_used", float, "Budget used by the last instant (its unit).")
    work = _info_property("work", float, "Work units counted since setup.")

    qp_warm_start = _settings_property("qp_warm_start", bool)
    qp_cold_retry = _info_property("qp_cold_retry", bool,
                                   "True when the last feedback's warm-started QP failed and the cold retry ran "
                                   "(not after a warm start that certified primal infeasibility).")

    def _check_parameters(self, status: int, what: str) -> None:
        if int(status) == STATUS_ALREADY_PREPARED:
            what += f" ({PARAMETER_ORDER})"
        self._check(status, what)

    def set_parameters(self, p) -> None:
        """``(np,)`` for every node or ``(N+1, np)``: the parameters of the next QP's horizon
        (before init, or between feedback and prepare: docs/algorithm.md section 4)."""
        a = np.asarray(p) if not isinstance(p, np.ndarray) else p
        if a.ndim <= 1 and a.size == self.np:
            a = np.tile(self._array(a, (self.np,), "parameters").reshape(1, self.np), (self.N + 1, 1))
        a = self._array(a, (self.N + 1, self.np), "parameters")
        self._check_parameters(self._c("set_parameters")(self._s, self._ptr(a)), "set_parameters")

    def set_parameters_node(self, k: int, pk) -> None:
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 0 <= k <= self.N:
            self._bad(f"node index must be an integer in 0..{self.N}, got {k!r}")
        a = self._array(pk, (self.np,), f"parameters of node {k}")
        self._check_parameters(self._c("set_parameters_node")(self._s, int(k), self._ptr(a)), "set_parameters_node")

    def stop(self) -> None:
        """End the run: uninitialised, settings and parameters kept (write the parameters
        of the next run's first horizon, then init)."""
        self._c("stop")(self._s)

    def push_parameters(self, pN) -> None:
        """The parameters of the next horizon's last node (receding mode, between feedback
        and prepare; the prepare shifts the others with the horizon)."""
        a = self._array(pN, (self.np,), "parameters of the new last node")
        self._check_parameters(self._c("push_parameters")(self._s, self._ptr(a)), "push_parameters")

    M = _settings_property("M")
    mode = _setting_property("mode")
    hessian = _setting_property("hessian")
    regularization = _setting_property("regularization")
    cost_hessian = _setting_property("cost_hessian")
    reg_eps = _settings_property("reg_eps", float)
    qp_tol = _settings_property("qp_tol", float)
    qp_max_iter = _settings_property("qp_max_iter")
    p = _array_property("get_parameters", lambda s: (s.N + 1, s.np))

    # ------------------------------------------------------------------ the iteration
    def init(self, xhat0, guess=None) -> None:
        """Iterate = ``guess`` (None: the OCP file's guess compiled into the library; missing
        multipliers: zeros); every stage and the terminal node linearised there."""
        N, nx, nu, ng, nr, ne, nw = self.N, self.nx, self.n_u, self.ng, self.nr, self.ne, self.nw
        xh = self._array(xhat0, (nx,), "init: xhat0")
        arrays = [None] * 8
        if guess is not None:
            specs = (("x", (N + 1, nx)), ("u", (N, nu)), ("lam", (N + 1, nx)), ("mu_g", (N, ng)),
                     ("mu_b", (N, nw)), ("mu_bN", (nx,)), ("mu_r", (nr,)), ("nu", (ne,)))
            for i, (field, shape) in enumerate(specs):
                v = getattr(guess, field, None)
                if v is None and field in ("x", "u"):
                    self._bad(f"init: guess.{field} is required")
                if v is not None:
                    arrays[i] = self._array(v, shape, f"init: guess.{field}")
        self._check(self._c("init")(self._s, self._ptr(xh), *[self._ptr(a) for a in arrays]), "init")

    def init_nominal(self, xhat0) -> None:
        """Initialise from the nominal primal-dual guess generated into the library."""
        xh = self._array(xhat0, (self.nx,), "init_nominal: xhat0")
        self._check(self._c("init_nominal")(self._s, self._ptr(xh)), "init_nominal")

    def feedback(self, xhat0) -> np.ndarray:
        """Solve the prepared QP for ``xhat0``, take the full step, return ``u_0`` (clipped
        to the control bounds). On failure the raised :class:`DopusError` carries ``u0``, the
        fallback control of docs/algorithm.md section 9 (the next control of the last good
        plan, clipped), which is also :attr:`u0`. A non-finite ``xhat0`` reaches the C
        runtime, which counts it as a failed instant."""
        xh = self._array(xhat0, (self.nx,), "feedback: xhat0", check_finite=False)
        u0 = self._out(self.n_u)
        status = self._c("feedback")(self._s, self._ptr(xh), self._ptr(u0))
        u0 = self._f64(u0)
        try:
            if not np.all(np.isfinite(xh)):
                self._array(xh, (self.nx,), "feedback: xhat0")    # the message naming the entry
            self._check(status, "feedback")
        except DopusError as err:
            self.status = int(status)
            err.u0 = self.u0
            raise
        return u0

    # ------------------------------------------------------------------ globalised first solve
    def globalised_start(self) -> None:
        """Forget the penalty and the counts of a previous globalised solve (section 15)."""
        size = int(self._c("glob_sizeof")())
        self._glob_buf = self._ffi.new("double[]", (size + 7) // 8)
        self._glob = self._ffi.cast(f"{self.name}_glob *", self._glob_buf)   # zero-filled: a new solve

    @property
    def glob(self):
        """The state of the globalised solve: penalty, alpha, merit, slope, kkt, iterations,
        trials, reason (a name of enum dopus_glob_reason)."""
        from types import SimpleNamespace

        from ..reference.globalise import REASONS

        if getattr(self, "_glob", None) is None:
            self.globalised_start()
        info = self._ffi.new(f"{self.name}_glob_info *")
        self._c("glob_get_info")(self._glob, info)
        return SimpleNamespace(penalty=float(info.penalty), alpha=float(info.alpha), merit=float(info.merit),
                               slope=float(info.slope), kkt=float(info.kkt), iterations=int(info.iterations),
                               trials=int(info.trials), relaxed=bool(info.relaxed),
                               restores=int(info.restores),
                               reason=REASONS.get(int(info.reason), str(info.reason)))

    def globalised_step(self, xhat0) -> None:
        """One step of the globalised first solve from the prepared iterate (section 15)."""
        if getattr(self, "_glob", None) is None:
            self.globalised_start()
        xh = self._array(xhat0, (self.nx,), "globalised_step: xhat0")
        self._check(self._c("glob_step")(self._s, self._glob, self._ptr(xh)), "globalised step")

    def init_globalised(self, xhat0, guess=None, max_work: float = 0.0, max_iter: int = 100, tol=None) -> bool:
        """``init`` at the guess (x and u; None: the OCP file's), then globalised steps until
        the KKT measure is at most ``tol`` (True) or a limit ends them (False; ``glob.reason``)
        (section 15)."""
        from .. import settings as settings_mod

        self.globalised_start()
        tol = settings_mod.KKT_TOL_DEFAULT["float" if self.real == "float" else "double"] if tol is None else tol
        xh = self._array(xhat0, (self.nx,), "init_globalised: xhat0")
        x = u = None
        if guess is not None:
            x = self._array(guess.x, (self.N + 1, self.nx), "init_globalised: guess.x")
            u = self._array(guess.u, (self.N, self.n_u), "init_globalised: guess.u")
        status = int(self._c("init_globalised")(self._s, self._glob, self._ptr(xh), self._ptr(x), self._ptr(u),
                                                float(max_work), int(max_iter), float(tol)))
        if status == STATUS_NOT_CONVERGED:
            self.status = status
            return False
        self._check(status, "init_globalised")
        return True

    # ------------------------------------------------------------------ health
    def set_recovery(self, on: bool = True, max_failures: Optional[int] = None) -> None:
        """Automatic recovery (docs/algorithm.md section 9): on/off and K, the consecutive
        failed feedbacks after which the next prepare re-initialises."""
        if not isinstance(on, (bool, np.bool_)):
            self._bad(f"recovery must be True or False, got {on!r}")
        k = self.recovery_failures if max_failures is None else max_failures
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 1 <= k <= 2**31 - 1:
            self._bad(f"recovery max_failures must be an integer >= 1, got {max_failures!r}")
        self._update("set_recovery", recovery=int(bool(on)), recovery_failures=int(k))

    recovery = _settings_property("recovery", bool)
    recovery_failures = _settings_property("recovery_failures")
    u0 = _array_property("get_u0", lambda s: (s.n_u,), "The control returned by the last feedback (successful or not).")

    @property
    def flags(self) -> set:
        """The health flags of the last feedback and the prepare after it, by name:
        ``u0_clipped``, ``fallback``, ``diverged``, ``recovered``, ``predicted``."""
        f = int(self._info().flags)
        return {name for bit, name in FLAGS.items() if f & bit}

    recoveries = _info_property("recoveries", int, "Re-initialisations by the automatic recovery since init.")
    failed_feedbacks = _info_property("failed_feedbacks", int, "Consecutive failed feedbacks.")
    kkt_proxy = _info_property("kkt_proxy", float, "The divergence measure of the last prepare or init (section 9).")

    @property
    def scales(self) -> tuple:
        """``(scale_x, scale_u)`` of the box test (section 9)."""
        sx, su = self._out(self.nx), self._out(self.n_u)
        self._c("get_scales")(self._s, self._ptr(sx), self._ptr(su))
        return self._f64(sx), self._f64(su)

    def prepare(self) -> None:
        """Shift (receding mode), F and rho, fresh last stage and terminal node, the M worst H."""
        self._check(self._c("prepare")(self._s), "prepare")

    def kkt(self, xhat0=None) -> dict:
        """KKT measure (algorithm.md section 6) of the current iterate for ``xhat0``."""
        xh = None if xhat0 is None else self._array(xhat0, (self.nx,), "kkt: xhat0")
        out = self._out(4)
        self._check(self._c("kkt_eval")(self._s, self._ptr(xh), self._ptr(out)), "kkt")
        stat, eq, ineq, comp = (float(v) for v in out)
        return {"kkt": max(stat, eq, ineq, comp), "stat": stat, "eq": eq, "ineq": ineq, "comp": comp,
                "rel": float(self._info().kkt_rel)}

    # ------------------------------------------------------------------ read-only state
    initialized = _info_property("initialized", bool)
    x = _array_property("get_x", lambda s: (s.N + 1, s.nx))
    u = _array_property("get_u", lambda s: (s.N, s.n_u))
    lam = _array_property("get_lam", lambda s: (s.N + 1, s.nx))
    mu_g = _array_property("get_mu_g", lambda s: (s.N, s.ng))
    mu_b = _array_property("get_mu_b", lambda s: (s.N, s.nw))
    mu_bN = _array_property("get_mu_bN", lambda s: (s.nx,))
    mu_r = _array_property("get_mu_r", lambda s: (s.nr,))
    nu = _array_property("get_nu", lambda s: (s.ne,))
    rho = _array_property("get_rho", lambda s: (s.N,))

    @property
    def recomputed(self) -> list:
        buf = self._ffi.new("int[]", self.N)
        n = int(self._c("get_recomputed")(self._s, buf))
        return [int(buf[i]) for i in range(n)]

    ring_head = _info_property("ring_head")
    qp_iterations = _info_property("qp_iterations")
    qp_factorizations = _info_property("qp_factorizations", int,
                                       "Factorisations of the last feedback's QP solves (interior-point "
                                       "iterations, inertia corrections, sweeps of the active-set start).")
    qp_prefactored = _info_property("qp_prefactored", bool,
                                    "The last feedback's QP took a factorisation the prepare formed (its "
                                    "convexity test's, or the active-set start's with the guessed rows) as "
                                    "that of its first sweep (section 10).")
    qp_status = _info_property("qp_status")
    M_used = _info_property("M_used", int, "Stages the last prepare (or init) re-linearised besides stage N-1.")

    @property
    def qp_infeasible_row(self) -> Optional[dict]:
        """When the last QP was infeasible: the row of the OCP with the largest multiplier of
        its infeasibility certificate, ``{"stage", "kind", "index", "side", "bound"}`` (kind:
        ``state``, ``control``, ``path``, ``terminal`` or ``terminal_eq``; side: ``lower``
        or ``upper``; see dopus_get_qp_infeasible_row); else None."""
        import cffi

        try:
            get, row = self._c("get_qp_infeasible_row"), self._ffi.new(f"{self.name}_row_info *")
        except (AttributeError, cffi.CDefError):  # a library generated before the getter existed
            return None
        if not get(self._s, row):
            return None
        return {"stage": int(row.stage), "kind": self.enums["dopus_row_kind"].name(row.kind),
                "index": int(row.index), "side": {-1: "lower", 1: "upper"}.get(int(row.side), "lower above upper"),
                "bound": float(row.bound)}

    def row_name(self, kind: str, index: int) -> Optional[str]:
        """The C API's name of a row (``dopus_row_name``): kind ``state``, ``control``,
        ``path``, ``terminal`` or ``terminal_eq``; None out of range."""
        code = self.enums["dopus_row_kind"][kind]
        p = self._c("row_name")(code, int(index))
        return None if p == self._ffi.NULL else self._ffi.string(p).decode()

    def soft_slacks(self) -> dict:
        """The slacks of the soft rows in the QP of the last feedback (read it before the next
        prepare; dopus_get_soft_slacks): ``{"x": (N+1, nx), "g": (N, ng), "r": (nr,), "max"}``,
        zeros on hard rows (docs/algorithm.md section 12)."""
        N, nx, ng, nr = self.N, self.nx, self.ng, self.nr
        vx, vg, vr = np.zeros((N + 1, nx)), np.zeros((N, max(ng, 1))), np.zeros(max(nr, 1))
        real = f"{self.name}_real[]"
        worst = self._c("get_soft_slacks")(self._s, self._ffi.from_buffer(real, vx),
                                            self._ffi.from_buffer(real, vg), self._ffi.from_buffer(real, vr))
        return {"x": vx, "g": vg[:, :ng], "r": vr[:nr], "max": float(worst)}

    @property
    def timings(self) -> dict:
        """Seconds per phase of the last call that ran it (enum dopus_phase), plus
        ``prepare`` = the sum of the phases of prepare, and the wall times of the last
        feedback and prepare calls (``t_feedback``, ``t_prepare``)."""
        phases = self.enums["dopus_phase"].names()
        info = self._info()
        out = {name: float(info.timings[i]) for i, name in enumerate(phases)}   # double in both precisions
        out["prepare"] = sum(v for k, v in out.items() if k not in ("feedback", "kkt"))
        out["t_feedback"], out["t_prepare"] = float(info.t_feedback), float(info.t_prepare)
        return out

    def guess(self):
        """The current iterate as a ``Guess``."""
        from ..problem.ocp import Guess

        return Guess(x=self.x, u=self.u, lam=self.lam, mu_g=self.mu_g, mu_b=self.mu_b,
                     mu_bN=self.mu_bN, mu_r=self.mu_r, nu=self.nu)

    def set_clock(self, clock=None) -> None:
        """Replace the C clock by a Python callable returning seconds (None: the default).
        The callback is kept alive by the handle."""
        if clock is not None and not callable(clock):
            self.status = STATUS_INVALID_ARGUMENT
            raise DopusError(f"{self.name}: set_clock: expected a callable returning seconds (or None), got {clock!r}",
                             STATUS_INVALID_ARGUMENT)
        if clock is None:
            self._clock_cb = None
            self._c("set_clock")(self._s, self._ffi.NULL, self._ffi.NULL)
            return
        cb = self._ffi.callback("double(void *)", lambda _ctx: float(clock()))
        self._clock_cb = cb
        self._c("set_clock")(self._s, cb, self._ffi.NULL)

    has_clock = _info_property("has_clock", bool,
                               "True if the timings measure time (False: no clock on this platform, they read 0).")

    def __repr__(self) -> str:
        return (f"Solver({self.name!r}, N={self.N}, M={self.M}, mode={self.mode!r}, "
                f"hessian={self.hessian!r}, regularization={self.regularization!r}, lib_dir='{self.lib_dir}')")


#: The name the handle had before it was public; the same class.
CSolver = Solver
