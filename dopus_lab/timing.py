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
        self.ffi, self.lib, _meta = load_library(spec["folder"])
        n = self.name
        # the plant: the generated discrete model phi (the OCP file's integrator and substeps)
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

    def plant(self, x, u):
        """One step of the generated discrete model phi(x, u, p0)."""
        xa = np.ascontiguousarray(x, dtype=float)
        ua = np.ascontiguousarray(u, dtype=float)
        self._arg[0] = self.ffi.cast("double *", xa.ctypes.data)
        self._arg[1] = self.ffi.cast("double *", ua.ctypes.data)
        self._arg[2] = self._p(self.p0)
        self._res[0] = self._phi
        for i in range(1, len(self._res)):
            self._res[i] = self.ffi.NULL
        st = self.c("stage_eval")(self._arg, self._res, self._iw, self._w, 0)
        if st != 0:
            raise RuntimeError(f"{self.name}_stage_eval returned {st}")
        return np.frombuffer(self.ffi.buffer(self._phi, 8 * self.nx), dtype=float).copy()


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
        self.libs = {}
        self.u0 = (ct.c_double * self.nu)()
        self.xbuf = (ct.c_double * self.nx)()
        self.dbl = ct.c_double()
        self.int1 = ct.c_int()

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
            for f in ("acados_create", "acados_solve"):
                fn = getattr(lib, f"{name}_{f}")
                fn.argtypes, fn.restype = [ct.c_void_p], ct.c_int
            fn = getattr(lib, f"{name}_acados_update_qp_solver_cond_N")
            fn.argtypes, fn.restype = [ct.c_void_p, ct.c_int], ct.c_int
            self.libs[name] = lib
        return self.libs[name]

    def new(self, info, cond_N, lm):
        ct = self.ct
        name = info["model_name"]
        lib = self.lib(info)
        cap = getattr(lib, f"{name}_acados_create_capsule")()
        if getattr(lib, f"{name}_acados_create")(cap) != 0:
            raise RuntimeError(f"{name}_acados_create failed")
        if cond_N != self.N and getattr(lib, f"{name}_acados_update_qp_solver_cond_N")(cap, int(cond_N)) != 0:
            raise RuntimeError(f"{name}_acados_update_qp_solver_cond_N({cond_N}) failed")
        h = {"cap": cap, "solve": getattr(lib, f"{name}_acados_solve")}
        for k in ("config", "dims", "in", "out", "solver", "opts"):
            h[k] = getattr(lib, f"{name}_acados_get_nlp_{k}")(cap)
        v = ct.c_double(lm)
        self.opts_set(h["config"], h["opts"], b"levenberg_marquardt", ct.byref(v))
        return h

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

    def __init__(self, label, kind, feedback, prepare, start, phases=None, extra=None):
        self.label, self.kind = label, kind
        self.feedback, self.prepare, self.start = feedback, prepare, start
        self.phases = phases or (lambda: {})
        self.extra = extra or (lambda: {})


def make_ours(ours: Ours, M, mode, settings, label):
    s = ours.new(M, mode, settings)
    xbuf = ours.ffi.new("double[]", ours.nx)

    def feedback(xhat):
        for i, v in enumerate(xhat):
            xbuf[i] = v
        st = int(ours.c("feedback")(s, xbuf, ours.u0))
        return np.frombuffer(ours.ffi.buffer(ours.u0, 8 * ours.nu), dtype=float).copy(), st == 0

    def prepare():
        return int(ours.c("prepare")(s)) == 0

    def start(xhat0, guess):
        st = ours.init(s, xhat0, guess)
        if st != 0:
            raise RuntimeError(f"{label}: {ours.name}_init returned status {st}")

    def extra():
        return {"qp_iterations": int(ours.info(s).qp_iterations)}

    r = Runner(label, "ours", feedback, prepare, start, phases=lambda: ours.timings(s), extra=extra)
    r.solver, r.ours, r.M = s, ours, M
    return r


def make_acados(ac: Acados, info, cond_N, lm, label, timers=True):
    h = ac.new(info, cond_N, lm)
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

    r = Runner(label, "acados", feedback, prepare, start, phases=lambda: dict(last))
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


def _step(r, x, rec, record):
    t0 = time.perf_counter_ns()
    u, ok = r.feedback(x)
    t1 = time.perf_counter_ns()
    okp = r.prepare()
    t2 = time.perf_counter_ns()
    failed = (not ok) or (not okp) or (not np.all(np.isfinite(u)))
    if failed:
        rec["fail"] += 1
    if record:
        rec["feedback"].append((t1 - t0) * 1e-3)
        rec["prepare"].append((t2 - t1) * 1e-3)
        rec["phases"].append({k: v * 1e6 for k, v in r.phases().items()})
        rec["extra"].append(r.extra())
    return u, failed


def _guess_for(starts, label):
    """``starts`` is one guess (a dict with x, u, ...) or a dict of guesses by label."""
    return starts[label] if "x" not in starts and label in starts else starts


def closed_loop(runners, plant, x_start, starts, steps, skip=0, progress=None, x0_init=None):
    """Each runner in its own closed loop against ``plant(x, u) -> x+``, alternating one
    sampling step of each. ``starts[label]`` (or ``starts`` itself, a dict with x, u, ...)
    is the guess of ``start(x0_init or x_start, guess)``. The first ``skip`` steps are not
    recorded (the closed loop settles). Every step applies the control the solver returned,
    whatever its status (the closed-loop instant of dopus_codegen/studies/loops.py: ours
    returns its safe control after a failure; a step of acados that fails counts in ``fail``
    and a plant that diverges on its control is reset). Returns per label: ``fail``,
    ``feedback``/``prepare`` (us per recorded step), ``phases`` (the solver's own timers, us),
    ``x`` (the plant states, steps+1 rows)."""
    out = {r.label: _new_record() for r in runners}
    xs = {r.label: np.array(x_start, float) for r in runners}
    for r in runners:
        guess = _guess_for(starts, r.label)
        r.start(np.array(x_start if x0_init is None else x0_init, float), guess)
        out[r.label]["x"] = [xs[r.label].tolist()]
    total = steps + skip
    for i in range(total):
        for r in runners:
            rec = out[r.label]
            u, _failed = _step(r, xs[r.label], rec, i >= skip)
            xn = plant(xs[r.label], u)
            if not (np.all(np.isfinite(xn)) and np.abs(xn).max() < 1e8):
                rec["diverged_at"] = rec.get("diverged_at", i)
                xn = np.array(x_start, float)
            xs[r.label] = xn
            rec["x"].append(xn.tolist())
        if progress is not None:
            progress.update(i + 1)
    return out


def operating_point(runners, xhat, guess, reps, warmup=0, progress=None):
    """Fixed initial state ``xhat`` (the runners in fixed mode), one iteration of each in
    turn, ``warmup`` untimed rounds and ``reps`` timed ones."""
    out = {r.label: _new_record() for r in runners}
    for r in runners:
        r.start(np.array(xhat, float), _guess_for(guess, r.label))
    for i in range(warmup + reps):
        for r in runners:
            _step(r, xhat, out[r.label], i >= warmup)
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
def screen_acados(ac: Acados, plant, acd, x0, x_disturbed, nominal, cold, steps_warm, steps_cold, echo=None):
    """Every acados setting of ``acd["libs"]`` (exact Hessian under each regularisation, with
    and without the Levenberg-Marquardt term ``acd["lm"]``; Gauss-Newton) and partial
    condensing horizon of ``acd["cond_list"]`` runs two closed loops: from the nominal
    solution with the disturbed initial state (``steps_warm``) and from the cold guess
    (``steps_cold``). A setting works when no QP fails in either. Returns the rows."""
    N, lm = acd["N"], acd["lm"]
    settings = []
    for info in acd["libs"]:
        lms = [0.0] if info["hessian"] == "gauss-newton" else ([0.0, lm] if lm > 0 else [0.0])
        for cond in acd["cond_list"]:
            if cond > N:
                continue
            for lmv in lms:
                settings.append((info, cond, lmv))
    rows = []
    pg = Progress(f"acados screening: {len(settings)} settings x ({steps_warm} warm + {steps_cold} cold steps)",
                  len(settings))
    for i, (info, cond, lmv) in enumerate(settings):
        label = f"acados {info['hessian']} {info['regularize']} pc{cond}" + (f" lm{lmv:g}" if lmv else "")
        r = make_acados(ac, info, cond, lmv, label, timers=False)
        warm = closed_loop([r], plant, x_disturbed, nominal, steps_warm, x0_init=x0)[label]
        r2 = make_acados(ac, info, cond, lmv, label, timers=False)
        coldr = closed_loop([r2], plant, x0, cold, steps_cold)[label]
        row = {"label": label, "hessian": info["hessian"], "regularize": info["regularize"], "cond_N": cond,
               "lm": lmv, "fail_warm": warm["fail"], "fail_cold": coldr["fail"],
               "works": warm["fail"] == 0 and coldr["fail"] == 0 and "diverged_at" not in warm
               and "diverged_at" not in coldr,
               "median_us_warm": stats(np.array(warm["feedback"]) + np.array(warm["prepare"]))["median"],
               "info": info}
        rows.append(row)
        if echo is not None:
            echo(f"  {label:44s} QP failures: warm {warm['fail']:4d}/{steps_warm}, cold {coldr['fail']:4d}/"
                 f"{steps_cold}; median {row['median_us_warm']:8.1f} us")
        pg.update(i + 1)
    return rows


def pick_acados(ac: Acados, rows, x0, nominal, reps, quoted=()):
    """The fastest working setting of each kind: the (up to) four fastest in the screening
    (separate runs) are timed again interleaved at the converged operating point. Also the
    ``quoted`` settings ``(key, hessian, regularize, cond_N)`` where built. Returns
    ``(picks, selection)``: ``picks[key]`` a screening row."""
    picks, selection = {}, {}
    for key, hess in (("acados exact fastest working", "exact"), ("acados GN fastest working", "gauss-newton")):
        ok = sorted((r for r in rows if r["hessian"] == hess and r["works"]), key=lambda r: r["median_us_warm"])[:4]
        if len(ok) == 1:
            picks[key] = ok[0]
        elif ok:
            cand = [make_acados(ac, r["info"], r["cond_N"], r["lm"], r["label"], timers=False) for r in ok]
            t = operating_point(cand, x0, nominal, reps, warmup=10)
            med = {k: stats(np.array(v["feedback"]) + np.array(v["prepare"]))["median"] for k, v in t.items()}
            selection[hess] = med
            picks[key] = min(ok, key=lambda r: med[r["label"]])
    for key, hess, reg, cond in quoted:
        for r in rows:
            if r["hessian"] == hess and r["regularize"] == reg and r["cond_N"] == cond and r["lm"] == 0.0:
                picks.setdefault(key, r)
    return picks, selection


# ===================================================================== the bench verb's worker
def _settings_of(plan, run):
    s = dict(plan["settings_codes"])
    s.update(run.get("settings_codes", {}))
    return s


def _runners_ours(libs, plan, mode):
    rs = []
    for run in plan["runs"]:
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
    if ac is not None:
        a = plan["acados"]
        plant = libs[a["plant_lib"]].plant
        if quiet is not None:
            quiet.show("acados: screening which settings work (QP failures in the closed loop)")
        rows = screen_acados(ac, plant, a, a["x0"], a["x_disturbed"], a["nominal"], a["cold"],
                             a["steps_warm"], a["steps_cold"], echo=echo)
        picks, selection = pick_acados(ac, rows, a["x0"], a["nominal"], a["select_reps"],
                                       quoted=[tuple(q) for q in a.get("quoted", [])])
        result["acados_screen"] = [{k: v for k, v in r.items() if k != "info"} for r in rows]
        result["acados_selection"] = selection
        result["acados_picks"] = {k: {kk: vv for kk, vv in v.items() if kk != "info"} for k, v in picks.items()}
        acados_settings = [{"info": v["info"], "cond_N": v["cond_N"], "lm": v["lm"], "label": k}
                           for k, v in picks.items()]

    def runners(mode):
        rs = _runners_ours(libs, plan, mode)
        for s in acados_settings:
            rs.append(make_acados(ac, s["info"], s["cond_N"], s["lm"], s["label"]))
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
                                  skip=phase.get("skip", 0), progress=pg, x0_init=phase.get("x_init"))
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
