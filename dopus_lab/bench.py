"""``dopus-gen bench``: time per iteration of the generated solver on an OCP file, by phase,
for several M, optionally against acados, and the scaling of the time with N.

Two processes. This one (the project's environment, CasADi) prepares everything: the
generated and built library (the build cache of :func:`dopus_codegen.runtime.solver.build_for`),
IPOPT's nominal solution at the initial state, the fixed-xhat_0 convergence study of
``dopus-gen converge --start warm --backend c`` (iterations to KKT 1e-6 and 1e-8 per M)
and, with ``--against acados``, acados' solvers (built in acados' own environment by
:mod:`dopus_lab.acados_compare`). It writes a plan; the timing process
(:mod:`dopus_lab.timing`) loads only the compiled libraries, never CasADi, and
alternates one sampling step of every setting, so that load from other processes hits
all settings alike. Timed:

- ``operating point``: the closed loop from the nominal solution at the initial state
  (receding horizon, plant = the generated discrete model), after ``--settle`` untimed
  steps (the closed loop has settled), ``--reps`` timed steps;
- ``closed loop``: the closed loop from the disturbed initial state (the OCP file's
  disturbance map; the nominal solution as the guess), ``--steps`` timed steps.

Per setting and phase: feedback (from the measured state to u_0: the QP and the step;
wall clock of the call and the runtime's ``feedback`` timer), preparation (wall clock and
the runtime's timers, ``timings`` of ``dopus_get_info``: shift, gradients, rho, hessians,
regularization, assembly, lm, recovery), total = feedback + preparation (wall clock); medians and the
10/90 percentiles; ratios to our full RTI (ratio of the medians, and the median of the
per-step ratios of the interleaved run); the CPU model and the load before and after.

``--scaling 20,40,80,160``: the OCP file with the horizon set to each N (same interval),
M = 1 and the full RTI of every N interleaved in one timing process; time per iteration
against N and the exponent of a least-squares fit of log(time) against log(N).
"""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Callable, Optional

import numpy as np

from dopus_codegen import settings as st
from dopus_codegen.studies.records import json_ready

__all__ = ["BenchError", "run_bench", "run_scaling", "format_table", "format_scaling", "plot_bench",
           "fit_exponent", "parse_m_list", "parse_n_list"]

#: What the acados screening varies (docs/results.md): HPIPM's modes, the QP tolerances
#: (besides ours), the Riccati recursions (0 classic, 1 square-root), the build variants
#: (integrator, compile flags of the generated C; ``-O3 -march=native`` as ours where we use it).
ACADOS_MODES = ("SPEED_ABS", "SPEED", "BALANCE", "ROBUST")
ACADOS_TOLS = (1e-6, 1e-8)
ACADOS_RIC = (0, 1)
ACADOS_VARIANTS = (("ERK", "-O2"), ("ERK", "-O3 -march=native"), ("DISCRETE", "-O2"),
                   ("DISCRETE", "-O3 -march=native"))
ACADOS_EXACT_REGS = ("MIRROR", "PROJECT", "NO_REGULARIZE", "CONVEXIFY")


class BenchError(RuntimeError):
    """A bench run cannot be done as asked (the message says why)."""


# ------------------------------------------------------------------------------ arguments
def parse_m_list(text: str) -> list:
    """``"1,5,full"`` -> ``[1, 5, "full"]``; raises BenchError naming a bad item."""
    try:
        return st.parse_m_list(text)
    except st.SettingError as exc:
        raise BenchError(f"--M: {exc}") from None


def parse_n_list(text: str) -> list:
    out = []
    for item in str(text).split(","):
        item = item.strip()
        if not item.isdigit() or int(item) < 2:
            raise BenchError(f"--scaling: '{item}' is not a horizon length N >= 2")
        if int(item) not in out:
            out.append(int(item))
    if len(out) < 2:
        raise BenchError("--scaling needs at least two values of N to fit an exponent")
    return out


def _resolve_Ms(m_list, N: int) -> list:
    Ms = []
    for m in m_list:
        try:
            M = st.stages(m, N, strict=True)
        except st.SettingError as exc:
            raise BenchError(f"--M: {exc}") from None
        if M not in Ms:
            Ms.append(M)
    if N - 1 not in Ms:
        Ms.append(N - 1)        # the reference of the ratios
    return Ms


def _label(M: int, N: int, prefix: str = "") -> str:
    return f"{prefix}full RTI" if M == N - 1 else f"{prefix}M={M}"


# ------------------------------------------------------------------------------ preparation
def _guess_dict(g) -> dict:
    out = {}
    for f in ("x", "u", "lam", "mu_g", "mu_b", "mu_bN", "mu_r", "nu"):
        v = getattr(g, f, None)
        if v is not None:
            out[f] = np.asarray(v, float).tolist()
    return out


def _problem(ocp, echo, opt: Optional[str] = None, work: Optional[Path] = None) -> dict:
    """Discretise, generate and build (cached), IPOPT's nominal solution; the library spec
    of the timing process. ``opt``: our library built with these compile flags instead of
    the default, in a copy of the cached folder under ``work``."""
    import shutil
    import warnings

    from dopus_codegen import vocabulary
    from dopus_codegen.codegen.build import build
    from dopus_codegen.problem.derivatives import build_functions
    from dopus_codegen.reference.offline import solve_ocp
    from dopus_codegen.runtime.solver import build_for

    disc = build_functions(ocp)
    echo(f"{disc.name}: N={disc.N}, nx={disc.nx}, nu={disc.nu}: generating and building ...")
    folder = build_for(disc)
    if opt:
        # a copy, so that the shared cached folder keeps its default build
        slug = "".join(ch if ch.isalnum() else "_" for ch in opt)
        dst = Path(work) / f"{folder.name}_opt{slug}"
        shutil.copytree(folder, dst, dirs_exist_ok=True)
        folder = dst
        echo(f"{disc.name}: our library built with '{opt}' in {folder}")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = build(folder, opt=opt, echo=None)
    else:
        res = build(folder)
    echo(f"{disc.name}: IPOPT's nominal solution at the initial state ...")
    nominal, info = solve_ocp(disc, disc.x0)
    if not info.get("success", False):
        raise BenchError(f"{disc.name}: IPOPT did not solve the OCP at its initial state "
                         f"({info.get('status', 'unknown status')}); the bench starts from that solution")
    p0 = np.asarray(disc.p0, float)
    spec = {"name": disc.name, "lib": str(res.shared_lib), "cdef": str(res.cdef_path), "N": int(disc.N),
            "nx": int(disc.nx), "nu": int(disc.nu), "p0": (p0[0] if p0.ndim > 1 else p0).reshape(-1).tolist(),
            "phases": list(vocabulary.phases()), "folder": str(folder)}
    return {"disc": disc, "spec": spec, "nominal": nominal, "nominal_info": info}


def _default_opt() -> str:
    from dopus_codegen.codegen.flags import DEFAULT_OPT

    return DEFAULT_OPT


def _disturbed(disc) -> Optional[np.ndarray]:
    dist = disc.scenario.disturbance if getattr(disc, "scenario", None) is not None else None
    if dist is None:
        return None
    xd = np.array(dist(np.array(disc.x0, float).copy()), float).reshape(-1)
    if xd.size != disc.nx or not np.all(np.isfinite(xd)):
        raise BenchError(f"{disc.name}: the disturbance map must return {disc.nx} finite numbers")
    return xd


def _settings_codes(values: dict) -> dict:
    return {"hessian": st.code("hessian", values["hessian"]),
            "regularization": st.code("regularization", values["regularization"]),
            "reg_eps": float(values["reg_eps"]), "cost_hessian": st.code("cost_hessian", values["cost_hessian"]),
            "lm": values["lm"] if values["lm"] == st.LM_AUTO else float(values["lm"]),
            "qp_tol": st.qp_tol_default("double") if values.get("qp_tol") is None else float(values["qp_tol"])}


def _kkt_study(prob, Ms, values, iters, echo) -> dict:
    """The fixed-xhat_0 study of ``dopus-gen converge --start warm --backend c`` (cold start
    without a disturbance map): iterations to KKT 1e-6 and 1e-8 per M."""
    from dopus_codegen.studies.converge import StartPoint, backend_factory, iterations_to, run_study

    disc = prob["disc"]
    xd = _disturbed(disc)
    if xd is None:
        start = StartPoint("cold", np.array(disc.x0, float), disc.initial_guess, np.array(disc.x0, float))
    else:
        start = StartPoint("warm", np.array(disc.x0, float), prob["nominal"], xd)
    echo(f"{disc.name}: fixed-xhat_0 study ({start.label} start), {len(Ms)} x {iters} iterations ...")
    study = run_study(disc, Ms, iters, start, st.Settings.of(values), backend_factory=backend_factory("c"),
                      backend_name="c")
    rows = []
    for r in study["runs"]:
        rows.append({"M": r["M"], "label": _label(r["M"], disc.N), "iters_to_1e-6": iterations_to(r["kkt"], 1e-6),
                     "iters_to_1e-8": iterations_to(r["kkt"], 1e-8), "last_kkt": r["kkt"][-1] if r["kkt"] else None,
                     "status": r["status"]})
    return {"start": start.label, "iters": iters, "runs": rows}


def _run_worker(plan: dict, work: Path) -> dict:
    work.mkdir(parents=True, exist_ok=True)
    fd, plan_path = tempfile.mkstemp(prefix="plan-", suffix=".json", dir=str(work))
    os.close(fd)
    out_path = plan_path.replace("plan-", "result-")
    Path(plan_path).write_text(json.dumps(json_ready(plan)))
    root = str(Path(__file__).resolve().parents[1])
    env = dict(os.environ)
    env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    proc = subprocess.run([sys.executable, "-m", "dopus_lab.timing", plan_path, out_path],
                          env=env, check=False)
    if proc.returncode != 0:
        raise BenchError(f"the timing process failed (exit {proc.returncode}); plan: {plan_path}")
    res = json.loads(Path(out_path).read_text())
    for p in (plan_path, out_path):
        try:
            os.unlink(p)
        except OSError:
            pass
    return res


def acados_lm(prob, values, echo) -> float:
    """The fixed Levenberg-Marquardt term acados' exact-Hessian settings are screened with
    (besides none): ours when it is a number; acados has no automatic term, so with ours
    automatic (the default) the value our automatic term starts from at the nominal solution
    (1e-5 times the Hessian scale, docs/algorithm.md section 10)."""
    if values["lm"] != st.LM_AUTO:
        return float(values["lm"])
    from dopus_codegen.runtime.solver import Solver

    disc = prob["disc"]
    s = Solver.from_dir(prob["spec"]["folder"], disc, lm=st.LM_AUTO)
    s.init(np.asarray(disc.x0, float), prob["nominal"])
    lm = float(s.lm)
    echo(f"{disc.name}: acados has no automatic Levenberg-Marquardt term: its exact-Hessian settings are "
         f"screened with lm 0 and {lm:.3g}, the value ours starts from at the nominal solution")
    return lm


def _acados_plan(ocp, prob, values, cond_list, quick, work: Path, echo) -> dict:
    from . import acados_compare as ac

    disc = prob["disc"]
    try:
        py = ac.acados_python()
    except ac.AcadosUnavailable as exc:
        raise BenchError(f"--against acados: acados' environment is not available: {exc}") from None
    echo(f"{disc.name}: translating to acados and building its solvers (acados' environment; each build "
         f"variant once, cached in {work}) ...")
    ej = ac.export(ocp, work)
    libs = []
    regs = ("MIRROR",) if quick else ACADOS_EXACT_REGS
    variants = (ACADOS_VARIANTS[0], ACADOS_VARIANTS[-1]) if quick else ACADOS_VARIANTS
    kinds = [("exact", reg) for reg in regs] + ([("gauss-newton", "NO_REGULARIZE")] if disc.has_gn else [])
    for hess, reg in kinds:
        for integ, flags in variants:
            tag = (f"_{'ex_' + reg.lower()[:4] if hess == 'exact' else 'gn'}_{integ.lower()[:4]}_"
                   f"{''.join(w.strip('-').replace('march=native', 'n') for w in flags.split())}")
            settings = {"hessian": hess, "regularize": reg, "integrator": integ, "flags": flags, "suffix": tag}
            try:
                b = ac.build(py, ej, settings, work)
            except RuntimeError as exc:
                echo(f"acados {hess} {reg} {integ} {flags} not built: {str(exc).splitlines()[-1]}")
                continue
            libs.append({"hessian": hess, "regularize": reg, "integrator": integ, "flags": flags, **b})
    if not libs:
        raise BenchError("--against acados: no acados solver could be built")
    xd = _disturbed(disc)
    g = disc.initial_guess
    ours_tol = st.qp_tol_default("double") if values.get("qp_tol") is None else float(values["qp_tol"])
    tols = sorted({*ACADOS_TOLS, ours_tol}, reverse=True)
    return {"lib_dir": libs[0]["acados_lib_dir"], "N": int(disc.N), "nx": int(disc.nx), "nu": int(disc.nu),
            "libs": libs, "cond_list": [c for c in cond_list if c <= disc.N], "lm": acados_lm(prob, values, echo),
            "modes": ["SPEED_ABS", "BALANCE"] if quick else list(ACADOS_MODES),
            "tols": [tols[0], ours_tol] if quick else tols, "ric_algs": [0] if quick else list(ACADOS_RIC),
            "variant_qp": {"mode": "BALANCE", "tol": 1e-6, "ric_alg": 0}, "variant_cond": 10,
            "variant_reps": 60 if quick else 200,
            "plant_lib": "main", "x0": np.asarray(disc.x0, float).tolist(),
            "x_disturbed": (xd if xd is not None else np.asarray(disc.x0, float)).tolist(),
            "nominal": _guess_dict(prob["nominal"]), "cold": {"x": np.asarray(g.x, float).tolist(),
                                                               "u": np.asarray(g.u, float).tolist()},
            "steps_warm": 100 if quick else 200, "steps_cold": 60 if quick else 150,
            "select_reps": 100 if quick else 300, "select_settle": 50}


def _resolve_settings(ocp, cli: dict):
    declared = ocp.declared_options()
    if declared.get("real", "double") != "double":
        # the timing process exchanges doubles with the libraries it loads
        raise st.SettingError(f"dopus-gen bench times double builds only; the OCP file declares "
                         f"options(real={declared['real']!r}) (time a float build on its target with "
                         f"dopus-gen firmware-report, or compare it in closed loop with dopus-gen sil --real)")
    values, sources = st.resolve(declared, {k: v for k, v in cli.items() if v is not None})
    return values, sources


def _write_outputs(result: dict, json_out, plot_out, plot, echo) -> dict:
    """The JSON (``json_out``) and the figure (``plot(result, plot_out)``) of a study, where
    asked; returns ``result``."""
    if json_out:
        Path(json_out).parent.mkdir(parents=True, exist_ok=True)
        Path(json_out).write_text(json.dumps(json_ready(result), indent=1, allow_nan=False) + "\n")
        echo(f"wrote {json_out}")
    if plot_out:
        plot(result, plot_out)
        echo(f"wrote {plot_out}")
    return result


def run_bench(ocp_file, m_list=("1", "5", "full"), against: Optional[str] = None, json_out=None, plot_out=None,
              reps: int = 300, steps: int = 300, settle: int = 100, kkt_iters: int = 60,
              cond_list=(40, 20, 10, 8, 5, 4, 2), quick: bool = False, work=None,
              echo: Callable = None, keep_samples: bool = False, block: int = 1, opt: Optional[str] = None,
              **cli) -> dict:
    """The body of ``dopus-gen bench OCP_FILE``; returns the result (also written as JSON)."""
    from dopus_codegen.problem.ocp import load_ocp

    echo = echo or (lambda t: print(t, file=sys.stderr))
    if against not in (None, "none", "acados"):
        raise BenchError(f"--against must be 'acados', got {against!r}")
    for name, v in (("--reps", reps), ("--steps", steps), ("--kkt-iters", kkt_iters)):
        if isinstance(v, bool) or not isinstance(v, int) or v < 1:
            raise BenchError(f"{name} must be a positive integer, got {v!r}")
    if isinstance(settle, bool) or not isinstance(settle, int) or settle < 0:
        raise BenchError(f"--settle must be a non-negative integer, got {settle!r}")
    if isinstance(block, bool) or not isinstance(block, int) or block < 1:
        raise BenchError(f"--block must be a positive integer, got {block!r}")
    m_list = parse_m_list(m_list) if isinstance(m_list, str) else list(m_list)
    ocp = load_ocp(ocp_file)
    values, sources = _resolve_settings(ocp, cli)
    work = Path(work) if work else Path(tempfile.gettempdir()) / f"dopus-bench-{os.getuid()}"
    work.mkdir(parents=True, exist_ok=True)
    prob = _problem(ocp, echo, opt=opt, work=work)
    disc = prob["disc"]
    if values["hessian"] == "gauss-newton" and not disc.has_gn:
        raise BenchError(f"{disc.name}: --hessian gauss-newton needs a least-squares stage cost "
                         f"(ocp.stage_least_squares)")
    if disc.time_varying_parameters:
        if against == "acados":
            raise BenchError(f"{disc.name}: --against acados: the OCP's parameters move (trajectory); the acados "
                             "translation carries constant parameters only")
        # the parameters at t = j dt for every instant of the closed loops and their horizons
        n_sched = settle + max(reps, steps) + disc.N + 2
        prob["spec"]["p_schedule"] = [disc.parameters_at(j * float(disc.dt)).tolist() for j in range(n_sched)]
    Ms = _resolve_Ms([int(m) if isinstance(m, str) and m.isdigit() else m for m in m_list], disc.N)
    echo(f"{disc.name}: settings: M {','.join(map(str, Ms))}, "
         + st.describe({k: v for k, v in values.items() if k != "M"}, sources))
    kkt = _kkt_study(prob, Ms, values, kkt_iters, echo)
    xd = _disturbed(disc)
    x0 = np.asarray(disc.x0, float)
    nominal = _guess_dict(prob["nominal"])
    ref = _label(disc.N - 1, disc.N)
    plan = {"libs": {"main": prob["spec"]}, "settings_codes": _settings_codes(values),
            "runs": [{"lib": "main", "M": M, "label": _label(M, disc.N)} for M in Ms],
            "reps": reps, "warmup": 10, "ref_label": ref, "keep_samples": keep_samples, "block": block,
            "phases": [{"name": "operating point", "kind": "loop", "plant_lib": "main", "x_start": x0.tolist(),
                        "guess": nominal, "skip": settle, "steps": reps},
                       {"name": "closed loop", "kind": "loop", "plant_lib": "main",
                        "x_start": (xd if xd is not None else x0).tolist(), "x_init": x0.tolist(),
                        "guess": nominal, "skip": 0, "steps": steps}]}
    if against == "acados":
        plan["acados"] = _acados_plan(ocp, prob, values, cond_list, quick, work, echo)
    echo(f"{disc.name}: timing process (compiled libraries only, settings interleaved) ...")
    res = _run_worker(plan, work)
    result = {"problem": disc.name, "ocp_file": str(ocp_file), "N": int(disc.N), "nx": int(disc.nx),
              "nu": int(disc.nu), "dt": float(disc.dt), "settings": {k: values[k] for k in values if k != "M"},
              "sources": {k: sources[k] for k in sources if k != "M"}, "M": Ms, "reference": ref,
              "library": prob["spec"]["lib"], "reps": reps, "settle": settle, "steps": steps, "block": block,
              "ours_opt": opt or _default_opt(),
              "nominal_objective": float(prob["nominal_info"].get("objective", float("nan"))),
              "kkt": kkt, **res}
    result["machine"] = res.get("machine_before")
    result["tracking"] = tracking(disc, result)
    if not keep_samples:
        result.pop("trajectories", None)
    result["headline"] = headline(result)
    return _write_outputs(result, json_out, plot_out, plot_bench, echo)


def tracking(disc, result: dict) -> dict:
    """Per closed-loop phase and setting: RMS and max of the scenario's first scalar signal
    over the timed steps of that setting's closed loop (equal tracking is the condition of
    a fair time ratio)."""
    from dopus_codegen.studies.sil import _default_parameters, _eval

    spec = getattr(getattr(disc, "scenario", None), "closed_loop", None)
    if spec is None or not spec.signals:
        return {}
    p = _default_parameters(disc)
    out = {}
    for phase, runs in (result.get("trajectories") or {}).items():
        rows = {}
        for label, tr in runs.items():
            x, u, skip = np.asarray(tr["x"], float), np.asarray(tr["u"], float), int(tr.get("skip", 0))
            n = min(len(u), len(x) - 1)
            for name, fn in spec.signals.items():
                vals = [_eval(fn, x[i], u[i], p) for i in range(skip, n)]
                if vals and np.asarray(vals[0]).size == 1:
                    v = np.abs(np.array([float(np.asarray(a).reshape(-1)[0]) for a in vals]))
                    rows[label] = {"signal": name, "rms": float(np.sqrt(np.mean(v ** 2))), "max": float(v.max())}
                    break
        out[phase] = rows
    return out


def _failures(result: dict, label: str) -> int:
    """QP failures of a setting over every timed phase, the settling steps included."""
    return sum(int(t[label]["qp_failures"]) for t in result.get("timed", {}).values() if label in t)


def headline(result: dict) -> dict:
    """The ratios the project steers by, per timed phase: ratio of the medians of the total
    and the median of the per-step ratios (same interleaved run), with the tracking (RMS,
    max) of both settings beside them. A pair where either setting failed a QP in any
    timed phase (settling included) gets no ratio, only the failures. Against acados:
    ours at its defaults, and ours at the QP tolerance of acados' pick (equal tolerance);
    ``acados fastest working`` is the faster (at that phase) of the fastest working
    exact-Hessian and Gauss-Newton settings."""
    out = {}
    N = result["N"]
    m1, full = _label(1, N), _label(N - 1, N)
    picks = result.get("acados_picks") or {}
    matched = result.get("matched_runs") or {}

    def at_tol(label, tol):
        for k, v in matched.items():
            if v["of"] == label and math.isclose(v["qp_tol"], tol):
                return k
        return label            # acados' tolerance is ours

    timed_labels = {k for t in result.get("timed", {}).values() for k in t}

    def working(key):
        """The pick, else the first of its alternates (the next fastest of its group in the
        steady loop), that failed no QP in any timed phase; the pick when all failed."""
        cands = [key] + sorted(k for k in picks if k.startswith(key + " alternate "))
        cands = [k for k in cands if k in timed_labels]
        return next((k for k in cands if _failures(result, k) == 0), key)

    resolved = {key: working(key) for key in ("acados exact fastest working", "acados GN fastest working")}

    for phase, t in result.get("timed", {}).items():
        paired = (result.get("paired_ratios") or {}).get(phase, {})
        track = (result.get("tracking") or {}).get(phase, {})
        med = {k: v["total_us"]["median"] for k, v in t.items()}
        rows = {}

        def pair(a, b, name, extra=None):
            if a not in med or b not in med:
                return
            row = {"a": a, "b": b, **(extra or {})}
            fails = {k: _failures(result, k) for k in (a, b)}
            if any(fails.values()):
                row["failed"] = fails
            elif med[a] and med[b]:
                row.update(ratio=med[a] / med[b], paired_ratio=(paired.get(a) or {}).get(b))
                ta, tb = (t[k].get("timers_total_us", {}).get("median") for k in (a, b))
                if ta and tb:
                    # both ours: the same ratio on the runtime's own timers (no call overhead)
                    row["timers_ratio"] = ta / tb
            if a in track and b in track:
                row["tracking"] = {a: track[a], b: track[b]}
            rows[name] = row

        pair(m1, full, "M=1 / our full RTI")
        for k in t:
            if k.startswith("M=") and k != m1 and " qp_tol " not in k:
                pair(k, full, f"{k} / our full RTI")
        work = [resolved[k] for k in ("acados exact fastest working", "acados GN fastest working")
                if resolved[k] in med]
        if work:
            fastest = min(work, key=lambda k: med[k])
            pair(m1, fastest, "M=1 / acados fastest working RTI", {"acados_setting": picks.get(fastest, {}).get("label")})
        for pick, ours, name in (("acados GN fastest working", m1, "M=1 / acados fastest working GN RTI"),
                                 ("acados exact fastest working", full,
                                  "our full RTI / acados fastest working exact RTI")):
            key = resolved[pick]
            if key not in picks:
                continue
            tol = float(picks[key]["qp"]["tol"])
            extra = {"acados_setting": picks[key]["label"], "acados_qp_tol": tol, "acados_run": key}
            pair(ours, key, f"{name} (each at its defaults)", extra)
            pair(at_tol(ours, tol), key, f"{name} (equal QP tolerance {tol:g})", extra)
        fb = {k: v["feedback_us"]["median"] for k, v in t.items()}
        rows["feedback latency (us, median)"] = fb
        out[phase] = rows
    return out


# ------------------------------------------------------------------------------ scaling
def fit_exponent(Ns, times) -> float:
    """Slope of the least-squares line through (log N, log t)."""
    a = np.log(np.asarray(Ns, float))
    b = np.log(np.asarray(times, float))
    return float(np.polyfit(a, b, 1)[0])


def run_scaling(ocp_file, n_list, m_list=("1", "full"), json_out=None, plot_out=None, reps: int = 200,
                settle: int = 50, work=None, echo: Callable = None, **cli) -> dict:
    """Time per iteration against N (same interval dt): the OCP file with ``horizon(N, dt)``
    for each N, M = 1 and the full RTI of every N interleaved in one timing process, at the
    operating point (the settled closed loop)."""
    from dopus_codegen.problem.ocp import OcpError, load_ocp

    echo = echo or (lambda t: print(t, file=sys.stderr))
    n_list = parse_n_list(n_list) if isinstance(n_list, str) else list(n_list)
    m_list = parse_m_list(m_list) if isinstance(m_list, str) else list(m_list)
    libs, runs, guesses, per_n = {}, [], {}, {}
    values = sources = None
    x0 = None
    for N in n_list:
        ocp = load_ocp(ocp_file)
        try:
            dt = ocp.validate().horizon.dt
        except OcpError as exc:
            raise BenchError(str(exc)) from None
        try:
            ocp.horizon(N=N, dt=dt)
        except OcpError as exc:
            raise BenchError(f"--scaling N={N}: {exc}") from None
        ocp.name = f"{ocp.name}_N{N}"
        try:
            ocp.validate()
        except OcpError as exc:
            raise BenchError(f"--scaling N={N}: the OCP file does not take another horizon: {exc}") from None
        values, sources = _resolve_settings(ocp, cli)
        prob = _problem(ocp, echo)
        disc = prob["disc"]
        key = f"N{N}"
        libs[key] = prob["spec"]
        Ms = []
        for m in m_list:
            M = N - 1 if m == "full" else min(int(m), N - 1)
            if M not in Ms:
                Ms.append(M)
        per_n[N] = {"M": Ms, "objective": float(prob["nominal_info"].get("objective", float("nan")))}
        for M in Ms:
            label = _label(M, N, prefix=f"N={N} ")
            runs.append({"lib": key, "M": M, "label": label})
            guesses[label] = _guess_dict(prob["nominal"])
        x0 = np.asarray(disc.x0, float)
    plan = {"libs": libs, "settings_codes": _settings_codes(values), "runs": runs, "reps": reps, "warmup": 10,
            "ref_label": None,
            "phases": [{"name": "converged", "kind": "fixed", "plant_lib": f"N{n_list[0]}",
                        "xhat": x0.tolist(), "guess": guesses},
                       {"name": "operating point", "kind": "loop", "plant_lib": f"N{n_list[0]}",
                        "x_start": x0.tolist(), "guess": guesses, "skip": settle, "steps": reps}]}
    work = Path(work) if work else Path(tempfile.gettempdir()) / f"dopus-bench-{os.getuid()}"
    echo(f"timing process: {len(runs)} settings interleaved ...")
    res = _run_worker(plan, work)
    scaling = {}
    for phase, t in res["timed"].items():
        fits = {}
        for m in m_list:
            rows = []
            for N in n_list:
                M = N - 1 if m == "full" else min(int(m), N - 1)
                rec = t[_label(M, N, prefix=f"N={N} ")]
                qpit = (rec.get("qp_iterations") or {}).get("median")
                rows.append({"N": N, "M": M, "total_us": rec["total_us"]["median"],
                             "feedback_us": rec["feedback_us"]["median"], "prepare_us": rec["prepare_us"]["median"],
                             "qp_failures": rec["qp_failures"], "qp_iterations": qpit,
                             "feedback_per_qp_iteration_us": rec["feedback_us"]["median"] / qpit if qpit else None})
            key = "full" if m == "full" else f"M={m}"
            Ns = [r["N"] for r in rows]
            fits[key] = {"rows": rows, "exponent_total": fit_exponent(Ns, [r["total_us"] for r in rows]),
                         "exponent_feedback": fit_exponent(Ns, [r["feedback_us"] for r in rows]),
                         "exponent_prepare": fit_exponent(Ns, [r["prepare_us"] for r in rows])}
            if all(r["feedback_per_qp_iteration_us"] for r in rows):
                fits[key]["exponent_per_qp_iteration"] = fit_exponent(
                    Ns, [r["feedback_per_qp_iteration_us"] for r in rows])
        scaling[phase] = fits
    result = {"problem": Path(ocp_file).stem, "ocp_file": str(ocp_file), "N_list": n_list,
              "settings": {k: values[k] for k in values if k != "M"}, "sources": sources, "per_N": per_n,
              "scaling": scaling, **res}
    result["machine"] = res.get("machine_before")
    return _write_outputs(result, json_out, plot_out, plot_scaling, echo)


# ------------------------------------------------------------------------------ output
def _f(v, fmt="8.1f"):
    return format(v, fmt) if isinstance(v, (int, float)) and v is not None and math.isfinite(v) else "-".rjust(
        int(fmt.split(".")[0]) if fmt[0].isdigit() else 1)


def format_table(result: dict) -> str:
    m = result.get("machine") or {}
    ma = result.get("machine_after") or {}
    lines = [f"{result['problem']}: N={result['N']}, nx={result['nx']}, nu={result['nu']}; "
             + ", ".join(f"{k} {v}" for k, v in result.get("settings", {}).items()),
             f"CPU {m.get('cpu')}, {m.get('cores')} cores, load {m.get('loadavg')} before, {ma.get('loadavg')} after; "
             f"the settings alternate every {result.get('block', 1)} step(s); ours built with "
             f"'{result.get('ours_opt', '')}'"]
    prep_keys = ("shift", "gradients", "rho", "hessians", "regularization", "assembly", "lm", "recovery")
    for phase, t in result.get("timed", {}).items():
        lines.append(f"\n{phase} (us per iteration: median [p10, p90]; ratio to our full RTI: of the medians / "
                     f"median of the per-step ratios)")
        lines.append(f"{'setting':30s} {'feedback':>22s} {'preparation':>22s} {'total':>22s} {'ratio':>11s} "
                     f"{'QP fail':>7s} {'QP it':>5s}")
        for k, v in t.items():
            cells = [f"{_f(v[p]['median'])} [{_f(v[p]['p10'], '6.1f')},{_f(v[p]['p90'], '7.1f')}]"
                     for p in ("feedback_us", "prepare_us", "total_us")]
            ratio = f"{_f(v.get('ratio'), '5.2f')}/{_f((v.get('paired_ratio') or {}).get('median'), '5.2f')}"
            qpit = (v.get("qp_iterations") or {}).get("median")
            lines.append(f"{k:30s} {cells[0]:>22s} {cells[1]:>22s} {cells[2]:>22s} {ratio:>11s} "
                         f"{v['qp_failures']:7d} {_f(qpit, '5.0f')}")
        ours = {k: v for k, v in t.items() if "feedback" in v.get("phases_us", {})}
        if ours:
            lines.append(f"  runtime timers (us, medians): {'setting':24s} {'feedback':>9s} "
                         + " ".join(f"{p[:9]:>9s}" for p in prep_keys))
            for k, v in ours.items():
                ph = v["phases_us"]
                lines.append(f"  {'':29s} {k:24s} {_f(ph['feedback']['median'], '9.1f')} "
                             + " ".join(_f((ph.get(p) or {}).get('median'), '9.1f') for p in prep_keys))
        acad = {k: v for k, v in t.items() if "qp" in v.get("phases_us", {})}
        if acad:
            lines.append(f"  acados timers (us, medians): {'setting':32s} {'QP':>9s} {'linearise':>9s}")
            for k, v in acad.items():
                ph = v["phases_us"]
                lines.append(f"  {'':28s} {k:32s} {_f(ph['qp']['median'], '9.1f')} "
                             f"{_f((ph.get('lin') or {}).get('median'), '9.1f')}")
    kk = result.get("kkt")
    if kk:
        lines.append(f"\nfixed xhat_0 ({kk['start']} start, as dopus-gen converge --backend c): iterations to KKT")
        lines.append(f"{'M':>12s} {'1e-6':>6s} {'1e-8':>6s} {'last KKT':>10s}")
        for r in kk["runs"]:
            lines.append(f"{r['label']:>12s} {str(r['iters_to_1e-6'] if r['iters_to_1e-6'] is not None else '-'):>6s} "
                         f"{str(r['iters_to_1e-8'] if r['iters_to_1e-8'] is not None else '-'):>6s} "
                         f"{_f(r['last_kkt'], '10.2e')}  {r['status'] if r['status'] != 'ok' else ''}")
    for phase, rows in (result.get("headline") or {}).items():
        lines.append(f"\nheadline ratios, {phase} (ratio of the medians / median of the per-step ratios; "
                     f"tracking RMS / max of both, a / b):")
        for name, r in rows.items():
            if "a" not in r:
                continue
            tr = r.get("tracking") or {}
            track = ""
            if r["a"] in tr and r["b"] in tr:
                ta, tb = tr[r["a"]], tr[r["b"]]
                track = (f"  [{ta['signal']} RMS {ta['rms']:.4e} / {tb['rms']:.4e}, max {ta['max']:.4e} / "
                         f"{tb['max']:.4e}]")
            if "failed" in r:
                lines.append(f"  {name:62s} no ratio: QP failures " + ", ".join(f"{k} {v}" for k, v in
                                                                            r["failed"].items()))
            elif "ratio" in r:
                tim = f"  (runtime timers {r['timers_ratio']:.2f})" if r.get("timers_ratio") else ""
                lines.append(f"  {name:62s} {r['ratio']:6.2f} / {_f(r.get('paired_ratio'), '5.2f')}{tim}{track}")
    if result.get("acados_picks"):
        lines.append("\nacados settings timed: " + "; ".join(f"{k} = {v['label']}"
                                                               for k, v in result["acados_picks"].items()))
        for k, v in (result.get("acados_variants") or {}).items():
            lines.append(f"acados build variant of {k}: {v['chosen']}")
        n_ok = sum(1 for r in result.get("acados_screen", []) if r["works"])
        lines.append(f"acados screening: {n_ok} of {len(result.get('acados_screen', []))} settings work "
                     f"(no QP failure from the disturbed nominal and from the cold guess, the iterate shifted)")
    return "\n".join(lines)


def format_scaling(result: dict) -> str:
    m = result.get("machine") or {}
    lines = [f"{result['problem']}: time per iteration against N (medians, us; the same interval dt); "
             f"CPU {m.get('cpu')}, load {m.get('loadavg')}",
             "converged: fixed initial state at IPOPT's solution (fixed mode); operating point: the closed loop "
             "from that solution after it settled"]
    for phase, fits in result["scaling"].items():
        for key, f in fits.items():
            lines.append(f"\n{phase}, {key}: exponent total {f['exponent_total']:.3f}, feedback "
                         f"{f['exponent_feedback']:.3f}, preparation {f['exponent_prepare']:.3f}, feedback per QP "
                         f"iteration {_f(f.get('exponent_per_qp_iteration'), '.3f')}")
            lines.append(f"{'N':>5s} {'M':>5s} {'total':>9s} {'feedback':>9s} {'prepare':>9s} {'QP it':>6s} "
                         f"{'per it':>8s} {'fail':>5s}")
            for r in f["rows"]:
                lines.append(f"{r['N']:5d} {r['M']:5d} {_f(r['total_us'], '9.1f')} {_f(r['feedback_us'], '9.1f')} "
                             f"{_f(r['prepare_us'], '9.1f')} {_f(r['qp_iterations'], '6.0f')} "
                             f"{_f(r['feedback_per_qp_iteration_us'], '8.1f')} {r['qp_failures']:5d}")
    return "\n".join(lines)


def plot_bench(result: dict, path) -> None:
    """Stacked bars (feedback, preparation) per setting and timed phase."""
    from dopus_codegen.studies.plots import plt

    phases = list(result.get("timed", {}))
    fig, axes = plt.subplots(1, max(1, len(phases)), figsize=(6 * max(1, len(phases)), 0.5 * 8 + 1.5), squeeze=False)
    for ax, ph in zip(axes[0], phases):
        t = result["timed"][ph]
        labels = list(t)
        fb = [t[k]["feedback_us"]["median"] or 0 for k in labels]
        pr = [t[k]["prepare_us"]["median"] or 0 for k in labels]
        y = np.arange(len(labels))
        ax.barh(y, fb, label="feedback (QP + step)")
        ax.barh(y, pr, left=fb, label="preparation")
        ax.set_yticks(y)
        ax.set_yticklabels(labels, fontsize=8)
        ax.invert_yaxis()
        ax.set_xlabel("median time per iteration [us]")
        ax.set_title(f"{result['problem']}: {ph}", fontsize=10)
        ax.grid(True, axis="x", alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_scaling(result: dict, path) -> None:
    from dopus_codegen.studies.plots import plt

    fig, ax = plt.subplots(figsize=(6, 4.5))
    for phase, fits in result["scaling"].items():
        for key, f in fits.items():
            Ns = [r["N"] for r in f["rows"]]
            ax.loglog(Ns, [r["total_us"] for r in f["rows"]], "o-" if phase == "converged" else "s--",
                      label=f"{phase}, {key} (exponent {f['exponent_total']:.2f})")
    ax.set_xlabel("N")
    ax.set_ylabel("median time per iteration [us]")
    ax.set_title(f"{result['problem']}: time per iteration against N", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
