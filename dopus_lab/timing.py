"""The timing process: compiled solvers only, interleaved, no CasADi.

``dopus-gen bench`` and ``bench/acados_bench.py`` prepare everything in the project's
environment (generated and built libraries, IPOPT's nominal solution, acados' builds) and
write a *plan* (JSON). This module runs the plan in a second process that loads only the
compiled shared libraries: ours through the package's one cffi binding of a generated
folder (:func:`dopus_codegen.runtime.solver.load_library`, which needs no CasADi), acados'
generated solver and libacados through ctypes and acados' C API. It never imports CasADi,
so the two CasADi versions of the acados comparison never meet; :func:`assert_no_casadi`
checks it.

Every controller is a :class:`Runner`: ``start(xhat0, guess)``, ``feedback(xhat) -> (u, ok)``
(from the measured state to ``u_0``: our ``<name>_feedback``, acados' RTI phase 2, QP and
step), ``prepare() -> ok`` (our ``<name>_prepare``, acados' RTI phase 1) and ``phases()``
(the solver's own timers of the last iteration, seconds). :func:`closed_loop` runs several
runners in their own closed loops against the same plant (our generated discrete model
``<name>_stage_eval``), alternating one sampling step of each, so that load from other
processes on the machine hits all of them alike.

    python -m dopus_lab.timing PLAN.json OUT.json     # the bench verb's worker
"""
from __future__ import annotations

import json
import math
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

__all__ = ["Ours", "Acados", "Runner", "make_ours", "make_acados", "closed_loop", "operating_point",
           "stats", "summarize", "cpu_info", "Quiet", "Progress", "assert_no_casadi", "run_plan"]

MODE_RECEDING, MODE_FIXED = 0, 1


# ===================================================================== our generated solver
class Ours:
    """One generated solver library through cffi (ABI mode) with its generated cdef header.

    ``spec``: ``{"name", "lib", "cdef", "N", "nx", "nu", "np", "p0", "phases"}`` (``phases``:
    the names of enum dopus_phase in index order, read by the preparing process)."""

    def __init__(self, spec):
        # the package's one binding of a generated folder (CasADi-free)
        from dopus_codegen.runtime.solver import load_library

        self.spec = spec
        self.name, self.N, self.nx, self.nu = spec["name"], spec["N"], spec["nx"], spec["nu"]
        self.phase_names = list(spec.get("phases", []))
        self.ffi, self.lib, meta = load_library(spec["folder"])
        n = self.name
        # the plant: the generated discrete model phi (the OCP file's integrator and substeps).
        # A scaled problem's stage_eval is phi_s(xs, us) = phi(Dx xs, Du us) / Dx in the solver's
        # variables (docs/algorithm.md section 16); the plant speaks the declared units, as
        # <name>_simulate does: x / Dx and u / Du in, phi_s Dx out
        scaling = meta.get("scaling") or {}
        self.scale_x = np.array(scaling.get("x") or np.ones(self.nx), float).reshape(self.nx)
        self.scale_u = np.array(scaling.get("u") or np.ones(self.nu), float).reshape(self.nu)
        self.ffi.cdef(f"int {n}_stage_eval(const double** arg, double** res, int* iw, double* w, int mem);"
                      f"int {n}_stage_eval_work(int *sz_arg, int* sz_res, int *sz_iw, int *sz_w);"
                      f"int {n}_stage_eval_n_out(void);", override=True)
        self._mem = []
        sz = [self.ffi.new("int*") for _ in range(4)]
        self.c("stage_eval_work")(*sz)
        n_out = int(self.c("stage_eval_n_out")())
        self._iw = self.ffi.new("int[]", max(1, sz[2][0]))
        self._w = self.ffi.new("double[]", max(1, sz[3][0]))
        self._arg = self.ffi.new("const double*[]", max(3, sz[0][0]))
        self._res = self.ffi.new("double*[]", max(n_out, sz[1][0], 1))
        self._phi = self.ffi.new("double[]", self.nx)
        self.u0 = self.ffi.new("double[]", self.nu)
        p0 = np.array(spec.get("p0") or [], float).reshape(-1)
        self.p0 = np.ascontiguousarray(p0)
        # parameters that move: p(j dt) per row; the closed loop writes the first horizon
        # before init, pushes the new last node before every prepare, and the plant of
        # instant j uses row j
        sched = spec.get("p_schedule")
        self.schedule = None if not sched else np.ascontiguousarray(np.array(sched, float))

    def c(self, f):
        return getattr(self.lib, f"{self.name}_{f}")

    def new(self, M, mode, settings):
        """A fresh solver struct with ``settings`` (C codes: hessian, regularization, reg_eps,
        cost_hessian, lm, qp_tol)."""
        mem = self.ffi.new("double[]", (int(self.c("solver_sizeof")()) + 7) // 8)
        self._mem.append(mem)
        s = self.ffi.cast(f"{self.name}_solver *", mem)
        st = self.ffi.new(f"{self.name}_settings *")
        self.c("settings_default")(st)
        st.M, st.mode = int(M), int(mode)
        if "hessian" in settings:
            st.hessian = int(settings["hessian"])
        if "regularization" in settings:
            st.regularization, st.reg_eps = int(settings["regularization"]), float(settings["reg_eps"])
        if "cost_hessian" in settings:
            st.cost_hessian = int(settings["cost_hessian"])
        if settings.get("lm") == "auto":
            st.lm_auto, st.lm = 1, 0.0
        elif "lm" in settings:
            st.lm_auto, st.lm = 0, float(settings["lm"])
        if "qp_tol" in settings:
            st.qp_tol = float(settings["qp_tol"])
        rc = int(self.c("setup")(s, st))
        if rc != 0:
            raise RuntimeError(f"{self.name}_setup{dict(settings, M=M, mode=mode)} returned status {rc}")
        return s

    def info(self, s):
        """The C info struct of the solver ``s``."""
        info = self.ffi.new(f"{self.name}_info *")
        self.c("get_info")(s, info)
        return info

    def _p(self, a):
        return self.ffi.cast("double *", a.ctypes.data) if a.size else self.ffi.NULL

    def init(self, s, xhat0, guess):
        """Status of ``<name>_init`` from ``guess`` (a dict of arrays: x, u and any multipliers)."""
        arrays = [np.ascontiguousarray(xhat0, dtype=float)]
        for f in ("x", "u", "lam", "mu_g", "mu_b", "mu_bN", "mu_r", "nu"):
            v = guess.get(f) if guess else None
            arrays.append(None if v is None else np.ascontiguousarray(v, dtype=float))
        self._keep_init = arrays
        ptrs = [self.ffi.NULL if a is None else self._p(a) for a in arrays]
        return int(self.c("init")(s, *ptrs))

    def first_horizon(self, s):
        """A moving reference: end the run and write the schedule's first horizon (before init)."""
        self.c("stop")(s)
        self._first = np.ascontiguousarray(self.schedule[:self.N + 1])
        self.c("set_parameters")(s, self._p(self._first))

    def push_parameters(self, s, j):
        """Push the schedule's row ``j`` as the next horizon's last node."""
        self.c("push_parameters")(s, self._p(self.schedule[j]))

    def iterate(self, s):
        """The current primal-dual iterate as a dict of arrays."""
        N, nx, nu = self.N, self.nx, self.nu
        dims = self.ffi.new(f"{self.name}_dims *")
        self.c("get_dims")(dims)
        shapes = {"x": (N + 1, nx), "u": (N, nu), "lam": (N + 1, nx), "mu_g": (N, dims.ng), "mu_b": (N, dims.nw),
                  "mu_bN": (nx,), "mu_r": (dims.nr,), "nu": (dims.ne,)}
        out = {}
        for f, shape in shapes.items():
            a = np.zeros(shape)
            if a.size:
                self.c(f"get_{f}")(s, self.ffi.cast("double *", a.ctypes.data))
            out[f] = a
        return out

    def timings(self, s):
        """The C phase timers of the last iteration (seconds), by phase name."""
        info = self.info(s)
        return {k: float(info.timings[i]) for i, k in enumerate(self.phase_names)}

    def plant(self, x, u, instant=None):
        """One step of the generated discrete model phi(x, u, p) (p: p0, or the schedule's row
        of the sampling instant)."""
        xa = np.ascontiguousarray(np.asarray(x, dtype=float).reshape(self.nx) / self.scale_x)
        ua = np.ascontiguousarray(np.asarray(u, dtype=float).reshape(self.nu) / self.scale_u)
        pa = self.p0 if self.schedule is None or instant is None else np.ascontiguousarray(self.schedule[instant])
        self._arg[0] = self.ffi.cast("double *", xa.ctypes.data)
        self._arg[1] = self.ffi.cast("double *", ua.ctypes.data)
        self._arg[2] = self._p(pa)
        self._res[0] = self._phi
        for i in range(1, len(self._res)):
            self._res[i] = self.ffi.NULL
        st = self.c("stage_eval")(self._arg, self._res, self._iw, self._w, 0)
        if st != 0:
            raise RuntimeError(f"{self.name}_stage_eval returned {st}")
        return np.frombuffer(self.ffi.buffer(self._phi, 8 * self.nx), dtype=float) * self.scale_x


# ===================================================================== acados
class Acados:
    """acados' generated solvers through ctypes and its C API."""

    def __init__(self, lib_dir, N, nx, nu):
        import ctypes as ct

        self.ct = ct
        self.N, self.nx, self.nu = N, nx, nu
        lib_dir = Path(lib_dir)
        self._keep = [ct.CDLL(str(lib_dir / f), mode=ct.RTLD_GLOBAL)
                      for f in ("libblasfeo.so", "libhpipm.so", "libqpOASES_e.so.3.1", "libacados.so")
                      if (lib_dir / f).exists()]
        acados = self._keep[-1]
        vp, cp, ip, dp = ct.c_void_p, ct.c_char_p, ct.c_int, ct.c_void_p
        self.model_set = acados.ocp_nlp_constraints_model_set
        self.model_set.argtypes = [vp, vp, vp, ip, cp, dp]
        self.out_get = acados.ocp_nlp_out_get
        self.out_get.argtypes = [vp, vp, vp, ip, cp, dp]
        self.out_set = acados.ocp_nlp_out_set
        self.out_set.argtypes = [vp, vp, vp, ip, cp, dp]
        self.opts_set = acados.ocp_nlp_solver_opts_set
        self.opts_set.argtypes = [vp, vp, cp, dp]
        self.nlp_get = acados.ocp_nlp_get
        self.nlp_get.argtypes = [vp, vp, cp, dp]
        self.dims_get = acados.ocp_nlp_dims_get_from_attr
        self.dims_get.argtypes = [vp, vp, vp, ip, cp]
        self.dims_get.restype = ct.c_int
        self.libs = {}
        self.u0 = (ct.c_double * self.nu)()
        self.xbuf = (ct.c_double * self.nx)()
        self.dbl = ct.c_double()
        self.int1 = ct.c_int()
        self._stat = (ct.c_double * 64)()

    def lib(self, info):
        ct = self.ct
        name = info["model_name"]
        if name not in self.libs:
            lib = ct.CDLL(info["ocp_solver_lib"])
            for f in ("acados_create_capsule", "acados_get_nlp_config", "acados_get_nlp_dims", "acados_get_nlp_in",
                      "acados_get_nlp_out", "acados_get_nlp_solver", "acados_get_nlp_opts"):
                fn = getattr(lib, f"{name}_{f}")
                fn.restype = ct.c_void_p
                fn.argtypes = [] if f == "acados_create_capsule" else [ct.c_void_p]
            for f in ("acados_create", "acados_solve", "acados_free", "acados_free_capsule"):
                fn = getattr(lib, f"{name}_{f}")
                fn.argtypes, fn.restype = [ct.c_void_p], ct.c_int
            fn = getattr(lib, f"{name}_acados_update_qp_solver_cond_N")
            fn.argtypes, fn.restype = [ct.c_void_p, ct.c_int], ct.c_int
            self.libs[name] = lib
        return self.libs[name]

    def new(self, info, cond_N, lm, qp=None):
        """A fresh solver of the built library ``info`` with partial condensing ``cond_N``,
        Levenberg-Marquardt term ``lm`` and the QP options ``qp`` (``mode``: HPIPM's mode,
        ``tol``: its four tolerances, ``ric_alg``: 0 classic, 1 square-root Riccati; None:
        those of the build). HPIPM's mode resets all its options to the mode's defaults, so
        it is set first and the others after it; the solver is then re-created
        (``update_qp_solver_cond_N``) so that its memory is sized with the final options."""
        ct = self.ct
        name = info["model_name"]
        lib = self.lib(info)
        cap = getattr(lib, f"{name}_acados_create_capsule")()
        if getattr(lib, f"{name}_acados_create")(cap) != 0:
            raise RuntimeError(f"{name}_acados_create failed")
        getter = {k: getattr(lib, f"{name}_acados_get_nlp_{k}") for k in ("config", "dims", "in", "out", "solver",
                                                                           "opts")}
        config, opts = getter["config"](cap), getter["opts"](cap)
        if qp:
            built = info.get("settings", {})
            self.opts_set(config, opts, b"qp_hpipm_mode", ct.c_char_p(str(qp["mode"]).encode()))
            it = ct.c_int(int(built.get("qp_iter_max", 100)))
            self.opts_set(config, opts, b"qp_iter_max", ct.byref(it))
            tol = ct.c_double(float(qp["tol"]))
            for f in (b"qp_tol_stat", b"qp_tol_eq", b"qp_tol_ineq", b"qp_tol_comp"):
                self.opts_set(config, opts, f, ct.byref(tol))
            ric = ct.c_int(int(qp["ric_alg"]))
            self.opts_set(config, opts, b"qp_ric_alg", ct.byref(ric))
            cric = ct.c_int(int(built.get("cond_ric_alg", 0)))
            self.opts_set(config, opts, b"qp_cond_ric_alg", ct.byref(cric))
            ws = ct.c_int(0)
            self.opts_set(config, opts, b"qp_warm_start", ct.byref(ws))
        if (qp or cond_N != self.N) and getattr(lib, f"{name}_acados_update_qp_solver_cond_N")(cap, int(cond_N)) != 0:
            raise RuntimeError(f"{name}_acados_update_qp_solver_cond_N({cond_N}) failed")
        h = {"cap": cap, "solve": getattr(lib, f"{name}_acados_solve"), "lib": lib, "name": name}
        for k, g in getter.items():
            h[k] = g(cap)
        v = ct.c_double(lm)
        self.opts_set(h["config"], h["opts"], b"levenberg_marquardt", ct.byref(v))
        return h

    def shifter(self, h):
        """The shift of the iterate by one interval, as ours shifts in every receding-horizon
        prepare: ``x_k <- x_{k+1}`` (k < N), ``u_k <- u_{k+1}`` and the dynamics multipliers
        ``pi_k <- pi_{k+1}`` (k < N-1), the constraint multipliers ``lam_k <- lam_{k+1}`` on
        the stages of equal layout (1 <= k < N-1); the last entries are kept."""
        ct = self.ct
        N = self.N
        cfg, dims, out = h["config"], h["dims"], h["out"]
        lam_n = [int(self.dims_get(cfg, dims, out, k, b"lam")) for k in range(N + 1)]
        buf = (ct.c_double * max([self.nx, self.nu, *lam_n, 1]))()
        plan = [(k, b"x") for k in range(N)] + [(k, f) for k in range(N - 1) for f in (b"u", b"pi")]
        plan += [(k, b"lam") for k in range(1, N - 1) if lam_n[k] == lam_n[k + 1]]
        get, put = self.out_get, self.out_set

        def shift():
            for k, f in plan:
                get(cfg, dims, out, k + 1, f, buf)
                put(cfg, dims, out, k, f, buf)

        return shift

    def free(self, h):
        """Free a solver made by :meth:`new`."""
        lib, name = h["lib"], h["name"]
        getattr(lib, f"{name}_acados_free")(h["cap"])
        getattr(lib, f"{name}_acados_free_capsule")(h["cap"])

    def set_phase(self, h, phase):
        self.int1.value = phase
        self.opts_set(h["config"], h["opts"], b"rti_phase", self.ct.byref(self.int1))

    def init(self, h, x, u):
        ct = self.ct
        for k in range(self.N + 1):
            xa = (ct.c_double * self.nx)(*x[k])
            self.out_set(h["config"], h["dims"], h["out"], k, b"x", xa)
            if k < self.N:
                ua = (ct.c_double * self.nu)(*u[k])
                self.out_set(h["config"], h["dims"], h["out"], k, b"u", ua)

    def set_x0(self, h, xhat0):
        for i, v in enumerate(xhat0):
            self.xbuf[i] = v
        self.model_set(h["config"], h["dims"], h["in"], 0, b"lbx", self.xbuf)
        self.model_set(h["config"], h["dims"], h["in"], 0, b"ubx", self.xbuf)

    def qp_stats(self, h):
        """(status, iterations) of the QP of the last RTI phase 2: the last column of
        acados' statistics (rows: iteration, QP status, QP iterations)."""
        ct = self.ct
        self.nlp_get(h["config"], h["solver"], b"stat_n", ct.byref(self.int1))
        n = self.int1.value
        self.nlp_get(h["config"], h["solver"], b"stat_m", ct.byref(self.int1))
        m = self.int1.value
        self.nlp_get(h["config"], h["solver"], b"sqp_iter", ct.byref(self.int1))
        cols = min(m, self.int1.value + 1)
        if len(self._stat) < (n + 1) * cols:
            self._stat = (ct.c_double * ((n + 1) * cols))()
        self.nlp_get(h["config"], h["solver"], b"statistics", self._stat)
        return int(self._stat[cols + cols - 1]), int(self._stat[2 * cols + cols - 1])

    def get(self, h, field):
        self.nlp_get(h["config"], h["solver"], field, self.ct.byref(self.dbl))
        return self.dbl.value

    def u_now(self, h):
        self.out_get(h["config"], h["dims"], h["out"], 0, b"u", self.u0)
        return np.array(self.u0[:], float)

    def traj(self, h):
        ct = self.ct
        xs, us = [], []
        for k in range(self.N + 1):
            xa = (ct.c_double * self.nx)()
            self.out_get(h["config"], h["dims"], h["out"], k, b"x", xa)
            xs.append(list(xa))
            if k < self.N:
                ua = (ct.c_double * self.nu)()
                self.out_get(h["config"], h["dims"], h["out"], k, b"u", ua)
                us.append(list(ua))
        return xs, us


# ===================================================================== runners
class Runner:
    """One controller behind a common step interface (see the module docstring)."""

    def __init__(self, label, kind, feedback, prepare, start, phases=None, extra=None, between=None, check=None):
        self.label, self.kind = label, kind
        self.feedback, self.prepare, self.start = feedback, prepare, start
        self.phases = phases or (lambda: {})
        self.extra = extra or (lambda: {})
        self.between = between        # untimed, after feedback and before prepare (acados' shift)
        self.check = check            # untimed, after feedback: False when its QP failed (acados' QP status)


def make_ours(ours: Ours, M, mode, settings, label):
    s = ours.new(M, mode, settings)
    xbuf = ours.ffi.new("double[]", ours.nx)

    def feedback(xhat):
        for i, v in enumerate(xhat):
            xbuf[i] = v
        st = int(ours.c("feedback")(s, xbuf, ours.u0))
        return np.frombuffer(ours.ffi.buffer(ours.u0, 8 * ours.nu), dtype=float).copy(), st == 0

    instant = [0]

    def prepare():
        if ours.schedule is not None and int(mode) != MODE_FIXED:
            instant[0] += 1
            ours.push_parameters(s, instant[0] + ours.N)
        return int(ours.c("prepare")(s)) == 0

    def start(xhat0, guess):
        if ours.schedule is not None:
            instant[0] = 0
            ours.first_horizon(s)
        st = ours.init(s, xhat0, guess)
        if st != 0:
            raise RuntimeError(f"{label}: {ours.name}_init returned status {st}")

    def extra():
        return {"qp_iterations": int(ours.info(s).qp_iterations)}

    r = Runner(label, "ours", feedback, prepare, start, phases=lambda: ours.timings(s), extra=extra)
    r.solver, r.ours, r.M = s, ours, M
    return r


def make_acados(ac: Acados, info, cond_N, lm, label, timers=True, qp=None, shift=True):
    """acados' RTI as a runner: feedback = RTI phase 2 (the QP and the step), prepare =
    phase 1 (linearisation, condensing). With ``shift`` the iterate is shifted by one
    interval between the two (untimed: it goes through acados' setters one stage at a time
    from Python), as ours shifts in its (timed) prepare."""
    h = ac.new(info, cond_N, lm, qp=qp)
    last = {}

    def feedback(xhat):
        ac.set_x0(h, xhat)
        ac.set_phase(h, 2)
        st = int(h["solve"](h["cap"]))
        if timers:
            last["qp"] = ac.get(h, b"time_qp")
        return ac.u_now(h), st == 0

    def prepare():
        ac.set_phase(h, 1)
        ok = int(h["solve"](h["cap"])) in (0, 2)
        if timers:
            last["lin"] = ac.get(h, b"time_lin")
        return ok

    def start(xhat0, guess):
        ac.init(h, guess["x"], guess["u"])
        ac.set_x0(h, xhat0)
        prepare()

    it = {}

    def check():
        """acados' RTI accepts a QP stopped at its iteration limit (status ACADOS_MAXITER) as
        a success; here, as for ours, any QP status but success is a failure."""
        qp_status, it["qp_iterations"] = ac.qp_stats(h)
        return qp_status == 0

    r = Runner(label, "acados", feedback, prepare, start, phases=lambda: dict(last),
               between=ac.shifter(h) if shift else None, check=check, extra=lambda: dict(it))
    r.handle = h
    return r


# ===================================================================== progress and output
class Quiet:
    """Sends the C-level stdout to /dev/null while open (acados prints every failed QP);
    show() prints to the real one."""

    def __init__(self):
        sys.stdout.flush()
        self._saved = os.dup(1)
        self._null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(self._null, 1)

    def show(self, text):
        os.write(self._saved, (text + "\n").encode())

    def close(self):
        sys.stdout.flush()
        os.dup2(self._saved, 1)
        os.close(self._saved)
        os.close(self._null)


class Progress:
    """A progress line on stderr: redrawn in place on a terminal, every 25 % otherwise."""

    def __init__(self, label, total, stream=None):
        self.label, self.total = label, max(1, int(total))
        self.stream = stream or sys.stderr
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.t0 = time.monotonic()
        self._last = -1

    def update(self, done):
        pct = int(100 * done / self.total)
        step = 2 if self.tty else 25
        if pct // step == self._last and done < self.total:
            return
        self._last = pct // step
        el = time.monotonic() - self.t0
        eta = el / done * (self.total - done) if done else float("nan")
        text = f"  {self.label}: {done}/{self.total} ({pct:3d} %), {el:5.1f} s elapsed, ~{eta:5.1f} s left"
        if self.tty:
            self.stream.write("\r" + text + ("\n" if done >= self.total else ""))
        else:
            self.stream.write(text + "\n")
        self.stream.flush()


def stats(v):
    a = np.array(v, float)
    a = a[np.isfinite(a)]
    if a.size == 0:
        return {"median": None, "p10": None, "p90": None, "n": 0}
    return {"median": float(np.median(a)), "p10": float(np.percentile(a, 10)),
            "p90": float(np.percentile(a, 90)), "n": int(a.size)}


def cpu_info():
    model = platform.processor() or "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"cpu": model, "cores": os.cpu_count(), "loadavg": [round(v, 2) for v in os.getloadavg()],
            "python": platform.python_version()}


def assert_no_casadi():
    if "casadi" in sys.modules:
        raise RuntimeError("the timing process imported CasADi")


# ===================================================================== the timed loops
def _new_record():
    return {"fail": 0, "feedback": [], "prepare": [], "phases": [], "extra": []}


def _step(r, x, rec, record, shift=True):
    """One sampling step of a runner: feedback (timed), its check and the shift of an
    acados iterate (untimed), prepare (timed)."""
    t0 = time.perf_counter_ns()
    u, ok = r.feedback(x)
    t1 = time.perf_counter_ns()
    if r.check is not None:
        ok = r.check() and ok
    if r.between is not None and shift:
        r.between()
    tp = time.perf_counter_ns()
    okp = r.prepare()
    t2 = time.perf_counter_ns()
    failed = (not ok) or (not okp) or (not np.all(np.isfinite(u)))
    if failed:
        rec["fail"] += 1
    if record:
        rec["feedback"].append((t1 - t0) * 1e-3)
        rec["prepare"].append((t2 - tp) * 1e-3)
        rec["phases"].append({k: v * 1e6 for k, v in r.phases().items()})
        rec["extra"].append(r.extra())
    return u, failed


def _guess_for(starts, label):
    """``starts`` is one guess (a dict with x, u, ...) or a dict of guesses by label."""
    return starts[label] if "x" not in starts and label in starts else starts


def closed_loop(runners, plant, x_start, starts, steps, skip=0, progress=None, x0_init=None, stop_on_fail=False,
                block=1):
    """Each runner in its own closed loop against ``plant(x, u) -> x+``, alternating one
    sampling step of each. ``starts[label]`` (or ``starts`` itself, a dict with x, u, ...)
    is the guess of ``start(x0_init or x_start, guess)``. The first ``skip`` steps are not
    recorded (the closed loop settles). Every step applies the control the solver returned,
    whatever its status (the closed-loop instant of dopus_codegen/studies/loops.py: ours
    returns its safe control after a failure; a step of acados that fails counts in ``fail``
    and a plant that diverges on its control is reset). Returns per label: ``fail``,
    ``feedback``/``prepare`` (us per recorded step), ``phases`` (the solver's own timers, us),
    ``x`` (the plant states, steps+1 rows), ``u`` (the applied controls). ``stop_on_fail``:
    a runner's loop ends at its first failure (the screening only asks whether one fails).
    ``block``: the runners alternate every ``block`` sampling steps (1: every step, each
    step then starts with the caches the other runners left; larger blocks keep a runner's
    data in the caches from one step to the next, as on a core that runs the controller
    alone, while load from other processes still hits all of them alike at that scale)."""
    out = {r.label: _new_record() for r in runners}
    xs = {r.label: np.array(x_start, float) for r in runners}
    for r in runners:
        guess = _guess_for(starts, r.label)
        r.start(np.array(x_start if x0_init is None else x0_init, float), guess)
        out[r.label]["x"] = [xs[r.label].tolist()]
        out[r.label]["u"] = []
    total = steps + skip
    stopped = set()
    block = max(1, int(block))
    for i0 in range(0, total, block):
        for r in runners:
            for i in range(i0, min(total, i0 + block)):
                if r.label in stopped:
                    break
                rec = out[r.label]
                u, failed = _step(r, xs[r.label], rec, i >= skip)
                rec["u"].append(np.asarray(u, float).tolist())
                if failed and stop_on_fail:
                    stopped.add(r.label)
                xn = plant(xs[r.label], u, i)
                if not (np.all(np.isfinite(xn)) and np.abs(xn).max() < 1e8):
                    rec["diverged_at"] = rec.get("diverged_at", i)
                    xn = np.array(x_start, float)
                xs[r.label] = xn
                rec["x"].append(xn.tolist())
        if progress is not None:
            progress.update(min(total, i0 + block))
    return out


def operating_point(runners, xhat, guess, reps, warmup=0, progress=None):
    """Fixed initial state ``xhat`` (the runners in fixed mode), one iteration of each in
    turn, ``warmup`` untimed rounds and ``reps`` timed ones."""
    out = {r.label: _new_record() for r in runners}
    for r in runners:
        r.start(np.array(xhat, float), _guess_for(guess, r.label))
    for i in range(warmup + reps):
        for r in runners:
            _step(r, xhat, out[r.label], i >= warmup, shift=False)
        if progress is not None:
            progress.update(i + 1)
    return out


def summarize(rec, ref=None):
    """Medians and spread of one runner's record; ``ref``: the record of the reference
    runner of the same interleaved run (paired per-step ratios of the totals)."""
    fb, pr = np.array(rec["feedback"], float), np.array(rec["prepare"], float)
    tot = fb + pr
    out = {"feedback_us": stats(fb), "prepare_us": stats(pr), "total_us": stats(tot), "qp_failures": rec["fail"],
           "steps": int(tot.size)}
    keys = []
    for p in rec["phases"]:
        keys += [k for k in p if k not in keys]
    out["phases_us"] = {k: stats([p.get(k, np.nan) for p in rec["phases"]]) for k in keys}
    if "feedback" in keys and len(rec["phases"]) == tot.size:
        # ours: the runtime's own timers of the step (the phases of feedback and prepare add
        # up to t_feedback + t_prepare), without the timing process's call overhead
        tim = np.array([sum(v for v in p.values() if np.isfinite(v)) for p in rec["phases"]], float)
        out["timers_total_us"] = stats(tim)
        if ref is not None and len(ref.get("phases", [])) == tim.size and ref["phases"] \
                and "feedback" in ref["phases"][0]:
            rtim = np.array([sum(v for v in p.values() if np.isfinite(v)) for p in ref["phases"]], float)
            out["timers_paired_ratio"] = stats(tim / rtim)
            out["timers_ratio"] = float(np.median(tim) / np.median(rtim))
    if rec["extra"] and "qp_iterations" in rec["extra"][0]:
        out["qp_iterations"] = stats([e["qp_iterations"] for e in rec["extra"]])
    if ref is not None and len(ref["feedback"]) == tot.size and tot.size:
        rt = np.array(ref["feedback"], float) + np.array(ref["prepare"], float)
        out["paired_ratio"] = stats(tot / rt)
        out["ratio"] = float(np.median(tot) / np.median(rt))
    if "diverged_at" in rec:
        out["diverged_at"] = rec["diverged_at"]
    return out


# ===================================================================== acados: which settings work
def _short_flags(flags: str) -> str:
    return "".join(w.lstrip("-").replace("march=native", "native") for w in str(flags).split())


def variant_label(info) -> str:
    """``ERK O2``, ``DISCRETE O3native``: the build variant of an acados library."""
    return f"{info.get('integrator', 'ERK')} {_short_flags(info.get('flags', '-O2'))}"


def setting_label(info, cond, lm, qp) -> str:
    hess = "exact" if info["hessian"] == "exact" else "GN"
    reg = "" if info["hessian"] != "exact" else " " + {"NO_REGULARIZE": "noreg"}.get(info["regularize"],
                                                                                    info["regularize"])
    return (f"acados {hess}{reg} {variant_label(info)} pc{cond} {qp['mode']} tol{qp['tol']:g} "
            f"ric{qp['ric_alg']}" + (f" lm{lm:g}" if lm else ""))


def _screen_space(acd, info):
    lm = acd["lm"]
    lms = [0.0] if info["hessian"] == "gauss-newton" or info["regularize"] != "NO_REGULARIZE" or not lm > 0 \
        else [0.0, lm]
    out = []
    for cond in acd["cond_list"]:
        if cond > acd["N"]:
            continue
        for mode in acd["modes"]:
            for tol in acd["tols"]:
                for ric in acd["ric_algs"]:
                    for lmv in lms:
                        out.append((cond, lmv, {"mode": mode, "tol": float(tol), "ric_alg": int(ric)}))
    return out


def choose_variants(ac: Acados, acd, x0, nominal, echo=None):
    """Per kind of acados setting (Hessian, regularisation), the fastest build variant
    (integrator ERK or the same RK4 map as discrete dynamics, compile flags): the variants,
    which solve the same QPs, timed interleaved at the converged operating point (fixed
    initial state, nominal solution) with one QP setting (``acd["variant_qp"]``, partial
    condensing ``acd["variant_cond"]``). Returns ``{(hessian, regularize): {"info", "medians"}}``."""
    groups = {}
    for info in acd["libs"]:
        groups.setdefault((info["hessian"], info["regularize"]), []).append(info)
    out = {}
    cond = min(int(acd.get("variant_cond", 10)), acd["N"])
    for key, infos in groups.items():
        if len(infos) == 1:
            out[key] = {"info": infos[0], "medians": {}}
            continue
        cand = [make_acados(ac, info, cond, 0.0, variant_label(info), timers=False, qp=acd["variant_qp"], shift=False)
                for info in infos]
        t = operating_point(cand, x0, nominal, int(acd.get("variant_reps", 200)), warmup=10)
        med = {k: stats(np.array(v["feedback"]) + np.array(v["prepare"]))["median"] for k, v in t.items()}
        for r in cand:
            ac.free(r.handle)
        best = min(infos, key=lambda info: med[variant_label(info)])
        out[key] = {"info": best, "medians": med}
        if echo is not None:
            echo(f"  acados {key[0]} {key[1]}: build variants (us, medians at the operating point): "
                 + ", ".join(f"{k} {v:.1f}" for k, v in sorted(med.items(), key=lambda kv: kv[1]))
                 + f" -> {variant_label(best)}")
    return out


def screen_acados(ac: Acados, plant, acd, x0, x_disturbed, nominal, cold, steps_warm, steps_cold, echo=None,
                  variants=None):
    """Every acados setting: per kind (Hessian, regularisation; its fastest build variant of
    :func:`choose_variants`) every partial condensing horizon of ``acd["cond_list"]``, HPIPM
    mode of ``acd["modes"]``, QP tolerance of ``acd["tols"]``, Riccati recursion of
    ``acd["ric_algs"]`` (and, exact Hessian without regularisation, with and without the
    Levenberg-Marquardt term ``acd["lm"]``), the iterate shifted as ours. Each runs two
    closed loops: from the nominal solution with the disturbed initial state (``steps_warm``)
    and from the cold guess (``steps_cold``); a loop ends at the first failure. A setting
    works when no QP fails in either. Returns the rows."""
    variants = variants or choose_variants(ac, acd, x0, nominal)
    settings = [(v["info"], cond, lmv, qp) for v in variants.values() for cond, lmv, qp in _screen_space(acd, v["info"])]
    rows = []
    pg = Progress(f"acados screening: {len(settings)} settings x ({steps_warm} disturbed + {steps_cold} cold steps)",
                  len(settings))
    for i, (info, cond, lmv, qp) in enumerate(settings):
        label = setting_label(info, cond, lmv, qp)
        r = make_acados(ac, info, cond, lmv, label, timers=False, qp=qp)
        warm = closed_loop([r], plant, x_disturbed, nominal, steps_warm, x0_init=x0, stop_on_fail=True)[label]
        ac.free(r.handle)
        ok_warm = warm["fail"] == 0 and "diverged_at" not in warm
        coldr = {"fail": None}
        if ok_warm:
            r2 = make_acados(ac, info, cond, lmv, label, timers=False, qp=qp)
            coldr = closed_loop([r2], plant, x0, cold, steps_cold, stop_on_fail=True)[label]
            ac.free(r2.handle)
        works = ok_warm and coldr["fail"] == 0 and "diverged_at" not in coldr
        row = {"label": label, "hessian": info["hessian"], "regularize": info["regularize"],
               "integrator": info.get("integrator", "ERK"), "flags": info.get("flags", "-O2"), "cond_N": cond,
               "lm": lmv, "qp": dict(qp), "fail_warm": warm["fail"], "fail_cold": coldr["fail"], "works": works,
               "median_us_warm": stats(np.array(warm["feedback"]) + np.array(warm["prepare"]))["median"],
               "info": info}
        rows.append(row)
        pg.update(i + 1)
    if echo is not None:
        for key in sorted({(r["hessian"], r["regularize"]) for r in rows}):
            rs = [r for r in rows if (r["hessian"], r["regularize"]) == key]
            ok = sorted((r for r in rs if r["works"]), key=lambda r: r["median_us_warm"])
            echo(f"  acados {key[0]} {key[1]}: {len(ok)} of {len(rs)} settings work"
                 + (f"; fastest {ok[0]['label']} ({ok[0]['median_us_warm']:.1f} us)" if ok else ""))
    return rows


#: Working settings timed besides each pick (the next fastest of its group in the steady loop).
ALTERNATES = 2


def pick_acados(ac: Acados, rows, plant, x0, nominal, reps, settle, echo=None):
    """The fastest working setting of each Hessian: the working settings in the order of
    their screening times, four at a time, run interleaved in the closed loop from the
    nominal solution (``settle`` untimed steps, then ``reps`` timed ones); one with a QP
    failure there does not count; the next ``ALTERNATES`` working ones of the same group are
    kept as ``picks[key + " alternate i"]``. Returns ``(picks, selection)``: ``picks[key]`` a screening
    row, ``selection[hessian]`` the medians (us) of the candidates and their failures."""
    picks, selection = {}, {}
    for key, hess in (("acados exact fastest working", "exact"), ("acados GN fastest working", "gauss-newton")):
        ok = sorted((r for r in rows if r["hessian"] == hess and r["works"]), key=lambda r: r["median_us_warm"])
        sel = {}
        for start in range(0, min(len(ok), 12), 4):
            chunk = ok[start:start + 4]
            cand = [make_acados(ac, r["info"], r["cond_N"], r["lm"], r["label"], timers=False, qp=r["qp"])
                    for r in chunk]
            t = closed_loop(cand, plant, x0, nominal, reps, skip=settle)
            for r in cand:
                ac.free(r.handle)
            for r in chunk:
                v = t[r["label"]]
                sel[r["label"]] = {"median_us": stats(np.array(v["feedback"]) + np.array(v["prepare"]))["median"],
                                   "fail": v["fail"]}
            good = sorted((r for r in chunk if sel[r["label"]]["fail"] == 0),
                          key=lambda r: sel[r["label"]]["median_us"])
            if good:
                picks[key] = good[0]
                # the next ones of the group, timed too: the headline takes the first of
                # pick and alternates that fails no QP in any timed phase
                for i, r in enumerate(good[1:ALTERNATES + 1]):
                    picks[f"{key} alternate {i + 1}"] = r
                break
        selection[hess] = sel
        if echo is not None:
            echo(f"  {key}: " + (picks[key]["label"] if key in picks else "none")
                 + f" ({len(sel)} candidates timed in the steady loop)")
    return picks, selection


# ===================================================================== the bench verb's worker
def _settings_of(plan, run):
    s = dict(plan["settings_codes"])
    s.update(run.get("settings_codes", {}))
    return s


def _runners_ours(libs, plan, mode, extra_runs=()):
    rs = []
    for run in [*plan["runs"], *extra_runs]:
        ours = libs[run["lib"]]
        rs.append(make_ours(ours, run["M"], mode, _settings_of(plan, run), run["label"]))
    return rs


def run_plan(plan, quiet_acados=True):
    """Run a plan of ``dopus_lab.bench`` (see there); return the result dict."""
    libs = {k: Ours(v) for k, v in plan["libs"].items()}
    ac = None
    if plan.get("acados"):
        a = plan["acados"]
        ac = Acados(a["lib_dir"], a["N"], a["nx"], a["nu"])
    result = {"machine_before": cpu_info(), "timed": {}}
    reps, warmup = plan["reps"], plan.get("warmup", 10)
    acados_settings = []
    quiet = Quiet() if (ac is not None and quiet_acados) else None
    echo = quiet.show if quiet is not None else (lambda t: print(t, file=sys.stderr))
    extra_runs = []
    if ac is not None:
        a = plan["acados"]
        plant = libs[a["plant_lib"]].plant
        if quiet is not None:
            quiet.show("acados: the build variants, then which settings work (QP failures in the closed loop)")
        variants = choose_variants(ac, a, a["x0"], a["nominal"], echo=echo)
        rows = screen_acados(ac, plant, a, a["x0"], a["x_disturbed"], a["nominal"], a["cold"],
                             a["steps_warm"], a["steps_cold"], echo=echo, variants=variants)
        picks, selection = pick_acados(ac, rows, plant, a["x0"], a["nominal"], a["select_reps"],
                                       a.get("select_settle", 50), echo=echo)
        result["acados_variants"] = {f"{k[0]} {k[1]}": {"chosen": variant_label(v["info"]), "medians": v["medians"]}
                                     for k, v in variants.items()}
        result["acados_screen"] = [{k: v for k, v in r.items() if k != "info"} for r in rows]
        result["acados_selection"] = selection
        result["acados_picks"] = {k: {kk: vv for kk, vv in v.items() if kk != "info"} for k, v in picks.items()}
        acados_settings = [{"info": v["info"], "cond_N": v["cond_N"], "lm": v["lm"], "qp": v["qp"], "label": k}
                           for k, v in picks.items()]
        # ours at acados' tolerance too (the headline at equal QP tolerance)
        ours_tol = plan["settings_codes"].get("qp_tol")
        matched = {}
        for v in picks.values():
            tol = float(v["qp"]["tol"])
            if ours_tol is not None and math.isclose(tol, float(ours_tol)):
                continue
            for run in plan["runs"]:
                if run["M"] in (1, plan["acados"]["N"] - 1):
                    label = f"{run['label']} qp_tol {tol:g}"
                    if label not in matched:
                        matched[label] = {"of": run["label"], "qp_tol": tol}
                        extra_runs.append({**run, "label": label,
                                           "settings_codes": {**run.get("settings_codes", {}), "qp_tol": tol}})
        result["matched_runs"] = matched

    def runners(mode):
        rs = _runners_ours(libs, plan, mode, extra_runs)
        for s in acados_settings:
            rs.append(make_acados(ac, s["info"], s["cond_N"], s["lm"], s["label"], qp=s["qp"]))
        return rs

    ref_label = plan.get("ref_label")
    try:
        for phase in plan["phases"]:
            lib = libs[phase["plant_lib"]]
            rs = runners(MODE_FIXED if phase["kind"] == "fixed" else MODE_RECEDING)
            n = (warmup + reps) if phase["kind"] == "fixed" else (phase.get("skip", 0) + phase["steps"])
            pg = Progress(f"{phase['name']} ({len(rs)} settings interleaved)", n)
            if phase["kind"] == "fixed":
                rec = operating_point(rs, phase["xhat"], phase["guess"], reps, warmup=warmup, progress=pg)
            else:
                rec = closed_loop(rs, lib.plant, phase["x_start"], phase["guess"], phase["steps"],
                                  skip=phase.get("skip", 0), progress=pg, x0_init=phase.get("x_init"),
                                  block=plan.get("block", 1))
            ref = rec.get(ref_label)
            # per-step ratios of every pair (ours / any) of this interleaved run
            paired = {}
            for a in rs:
                if a.kind != "ours":
                    continue
                ta = np.array(rec[a.label]["feedback"]) + np.array(rec[a.label]["prepare"])
                for b in rs:
                    tb = np.array(rec[b.label]["feedback"]) + np.array(rec[b.label]["prepare"])
                    if b is not a and ta.size == tb.size and ta.size:
                        paired.setdefault(a.label, {})[b.label] = stats(ta / tb)["median"]
            result.setdefault("paired_ratios", {})[phase["name"]] = paired
            result["timed"][phase["name"]] = {
                k: dict(summarize(v, ref), **({"x_end": v["x"][-1]} if "x" in v else {}))
                for k, v in rec.items()}
            if phase["kind"] == "loop":
                # the closed-loop trajectories (the tracking beside the times)
                result.setdefault("trajectories", {})[phase["name"]] = {
                    k: {"x": v["x"], "u": v["u"], "skip": phase.get("skip", 0)} for k, v in rec.items()}
            if plan.get("keep_samples"):
                result.setdefault("samples", {})[phase["name"]] = {
                    k: {"feedback": v["feedback"], "prepare": v["prepare"], "phases": v["phases"],
                        "x": v.get("x")} for k, v in rec.items()}
    finally:
        if quiet is not None:
            quiet.close()
    result["machine_after"] = cpu_info()
    assert_no_casadi()
    result["casadi_imported"] = False
    return result


def _finite(v):
    """Strict JSON: non-finite floats become null."""
    if isinstance(v, dict):
        return {k: _finite(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_finite(x) for x in v]
    if isinstance(v, (float, np.floating)):
        return float(v) if np.isfinite(v) else None
    if isinstance(v, np.integer):
        return int(v)
    return v


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if len(argv) != 2:
        print("usage: python -m dopus_lab.timing PLAN.json OUT.json", file=sys.stderr)
        return 2
    plan = json.loads(Path(argv[0]).read_text())
    res = run_plan(plan)
    Path(argv[1]).write_text(json.dumps(_finite(res), indent=1, allow_nan=False) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
