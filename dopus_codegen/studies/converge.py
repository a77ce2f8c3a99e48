"""Fixed-xhat_0 convergence study (the paper's figure 1) and the ``dopus-gen converge`` verb.

For every ``M`` in a list the study runs the DOPUS iteration in fixed mode
(docs/algorithm.md section 4): ``init(xhat_init, guess)``, then ``iters`` times
``feedback(xhat_fixed); prepare()``, recording the KKT measure (section 6) of the
iterate before the first and after every iteration.

Starts:

- ``cold``: the OCP file's initial guess at its initial state, ``xhat_fixed`` = the
  initial state;
- ``warm``: the offline IPOPT solution at the initial state (every block computed
  there, multipliers included), ``xhat_fixed`` = the OCP's disturbance map applied to
  the initial state.

JSON written by :func:`run_study`::

    {"problem": name, "N": N, "backend": "reference" | "c", "start": "cold" | "warm",
     "hessian": ..., "regularization": ..., "reg_eps": ..., "cost_hessian": "fresh" | "stored",
     "qp_tol": ..., "qp_max_iter": ..., "tol": tol, "tol_rel": tol_rel or null,
     "runs": [{"M": M, "kkt": [...], "stat": [...], "eq": [...], "ineq": [...], "comp": [...], "rel": [...],
               "status": "converged" | "not converged" | "failed", "message": why or null,
               "iterations_to_tol": i or null}, ...],
     "globalised": {"kkt": [...], "stat": ..., "status": ..., "message": why and what to try or null,
                    "iterations_to_tol": i or null, "alpha": [...], "relaxed": [...], "penalty": [...],
                    "work": units} or null,
     "solution": {"M": M, "status": ..., "converged": bool, "kkt": last KKT,
                  "x": [[...]], "u": [[...]], "objective": J} or null}

``kkt[i]`` is the measure after ``i`` iterations (``kkt[0]``: the initial point with
``xhat_fixed``), ``rel[i]`` its relative measure (docs/algorithm.md section 6). A run is
``converged`` once ``kkt <= tol``, or with a relative tolerance ``tol_rel`` (the OCP file's
``options(kkt_tol_rel=...)``, ``--tol-rel``) once ``rel <= tol_rel``, ``not converged`` if it ran
every iteration without that, ``failed`` if a call of the backend failed or the measure
became non-finite: it stops there and ``message`` says why (for an infeasible QP, with the
stage-0 rows the state violates). Non-finite numbers are written as ``null``.
``globalised`` (``--globalise``, the default with ``--start cold``) is the globalised first
solve of docs/algorithm.md section 15 from the same start (every stage re-linearised, a line
search on an l1 merit function with a watchdog; ``alpha[i]`` the step length of iteration
``i + 1``, ``relaxed[i]`` whether it was a relaxed full step of the watchdog, shown as ``R`` in
the table); when it fails, ``message`` says why and what to try.
``solution`` is the last iterate of a converged run: the full RTI (``M = N-1``) if it
converged, else the converged run with the largest ``M``, else the globalised solve's
(``"M": null``); when no run converged, of the
full RTI (else the largest ``M``) among the runs that did not fail, with ``converged:
false``; null when every run failed.

``cost_hessian`` (docs/algorithm.md section 4 step 5): ``fresh`` (default) refreshes the
stage-cost Hessian of every stage in every iteration; ``stored`` is the paper's literal
algorithm, whose warm-start study is the paper's figure 1 and docs/design.md section 8.
"""
from __future__ import annotations

import json
import math
import sys
from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from .. import settings
from .. import settings as settings_mod
from .records import json_ready

__all__ = ["StartPoint", "make_start", "run_study", "run_converge_cli", "backend_factory",
           "iterations_to", "objective"]


@dataclass
class StartPoint:
    """Where a convergence run starts: ``init(xhat_init, guess)``, then iterate for ``xhat_fixed``."""
    label: str
    xhat_init: np.ndarray
    guess: object
    xhat_fixed: np.ndarray


def make_start(disc, start: str, solve_ocp: Optional[Callable] = None) -> StartPoint:
    """The ``cold`` or ``warm`` start of the module docstring.

    ``solve_ocp`` (default :func:`dopus_codegen.reference.offline.solve_ocp`) is called as
    ``solve_ocp(disc, xhat0) -> (Guess, info)`` for the warm start.
    """
    x0 = np.array(disc.x0, dtype=float)
    if start == "cold":
        return StartPoint("cold", x0, disc.initial_guess, x0.copy())
    if start == "warm":
        disturbance = disc.scenario.disturbance
        if disturbance is None:
            raise ValueError(f"{disc.name}: --start warm needs a disturbance map "
                             f"(ocp.disturbance(fn) in the OCP file)")
        try:
            xf = np.array(disturbance(x0.copy()), dtype=float).reshape(-1)
        except Exception as exc:  # noqa: BLE001 - user code
            raise ValueError(f"{disc.name}: the disturbance map failed on the initial state: "
                             f"{type(exc).__name__}: {exc}") from None
        if xf.size != disc.nx or not np.all(np.isfinite(xf)):
            raise ValueError(f"{disc.name}: the disturbance map must return {disc.nx} finite numbers, "
                             f"got {xf}")
        if solve_ocp is None:
            from ..reference.offline import solve_ocp
        guess, info = solve_ocp(disc, x0)
        if not info.get("success", False):
            raise ValueError(f"{disc.name}: IPOPT did not solve the OCP at the initial state "
                             f"({info.get('status', 'unknown status')}); the warm start needs its solution")
        return StartPoint("warm", x0, guess, xf)
    raise ValueError(f"start must be 'cold' or 'warm', got {start!r}")


def backend_factory(backend: str) -> Callable:
    """The class implementing the backend protocol (docs/algorithm.md section 7)."""
    if backend == "reference":
        from ..reference.dopus import ReferenceDopus
        return ReferenceDopus
    if backend == "c":
        try:
            from ..runtime.solver import Solver
        except ImportError as exc:
            raise RuntimeError("backend 'c' is not available: dopus_codegen.runtime.solver.Solver "
                               f"cannot be imported ({exc})") from None
        return Solver
    raise ValueError(f"backend must be 'reference' or 'c', got {backend!r}")


def _resolve_M(m, N: int) -> int:
    """An M of the study's list: ``"full"`` is N-1, a value above N-1 is an error."""
    try:
        return settings.stages(m, N, strict=True)
    except settings.SettingError as exc:
        raise ValueError(str(exc)) from None


def objective(disc, x, u, p=None) -> float:
    """``sum_k l_k + E`` at the primal point (exact functions)."""
    from ..reference.kkt import eval_stages, node_parameters

    P = node_parameters(disc, p)
    N = disc.N
    _phi, l, _g = eval_stages(disc.stage_eval, N, np.asarray(x)[:N], u, P[:N])
    E = float(np.array(disc.term_eval(np.asarray(x)[N], P[N])[0]).reshape(-1)[0])
    return float(np.sum(l)) + E


def iterations_to(kkt: list, tol: float) -> Optional[int]:
    """First iteration whose KKT is ``<= tol`` (None if never)."""
    for i, v in enumerate(kkt):
        if v <= tol:
            return i
    return None


def run_globalised(disc, iters: int, start, s, backend_factory, tol: float, progress=None) -> dict:
    """The globalised first solve (docs/algorithm.md section 15) from ``start`` for
    ``start.xhat_fixed``: ``init``, then up to ``iters`` globalised steps, the KKT measure
    after each; stops at ``tol``. Returns the ``globalised`` record of the module docstring
    and the last iterate."""
    from ..errors import DopusError
    from ..reference.globalise import what_to_try

    be = backend_factory(disc, settings=s.replace(M=disc.N - 1, mode="fixed"))
    rec = {"kkt": [], "stat": [], "eq": [], "ineq": [], "comp": [], "alpha": [], "relaxed": [], "penalty": [],
           "status": None, "message": None}

    def record():
        k = be.kkt(start.xhat_fixed)
        for key in ("kkt", "stat", "eq", "ineq", "comp"):
            rec[key].append(float(k[key]))
        return k["kkt"]

    try:
        be.init(start.xhat_init, start.guess)
        be.globalised_start()
        w0 = be.work
        val = record()
        for it in range(1, iters + 1):
            if val <= tol:
                break
            be.globalised_step(start.xhat_fixed)
            rec["alpha"].append(float(be.glob.alpha))
            rec["relaxed"].append(bool(be.glob.relaxed))
            rec["penalty"].append(float(be.glob.penalty))
            val = record()
            if progress is not None:
                progress(it, val)
            if not math.isfinite(val):
                rec["status"], rec["message"] = FAILED, f"non-finite KKT measure at iteration {it}"
                break
        rec["work"] = float(be.work - w0)
    except DopusError as exc:
        it = len(rec["kkt"])
        what = "init" if it == 0 else f"iteration {it}"
        reason = be.glob.reason if getattr(be, "glob", None) is not None else "function"
        rec["status"] = FAILED
        rec["message"] = f"in {what}: {exc} (status {exc.status} {exc.status_name}); {what_to_try(reason)}"
    rec["iterations_to_tol"] = iterations_to(rec["kkt"], tol)
    if rec["status"] is None:
        if rec["iterations_to_tol"] is not None:
            rec["status"] = CONVERGED
        else:
            rec["status"] = NOT_CONVERGED
            rec["message"] = (f"KKT {rec['kkt'][-1]:.2e} after {iters} iterations; "
                              + what_to_try("iter_limit"))
    return rec, (np.array(be.x, dtype=float), np.array(be.u, dtype=float))


def run_study(disc, m_list, iters: int, start, settings: Optional["settings_mod.Settings"] = None,
              backend_factory: Optional[Callable] = None, backend_name: Optional[str] = None,
              progress: Optional[Callable] = None, tol: float = 1e-8, tol_rel: Optional[float] = None,
              globalise: bool = False,
              **changes) -> dict:
    """Run the study; return the JSON structure of the module docstring.

    ``start``: a :class:`StartPoint` or ``"cold"`` / ``"warm"`` (see :func:`make_start`).
    ``settings``: the solver's settings (None: the OCP file's ``options(...)`` of ``disc``),
    ``changes``: settings changed from them by name (``hessian="exact"``; None: not given);
    every run takes them with its ``M`` in fixed mode.
    ``backend_factory(disc, settings=...)`` builds a backend (default:
    :class:`~dopus_codegen.reference.dopus.ReferenceDopus`).
    ``progress(run_index, M, iteration, kkt)`` is called after every iteration.
    ``tol``: the KKT measure at which a run counts as converged; ``tol_rel`` (None: not used):
    the relative measure at which it does, in place of ``tol``.
    ``globalise``: also run the globalised first solve (:func:`run_globalised`) after the M runs
    (its convergence is on the absolute measure ``tol``).
    """
    from ..errors import DopusError
    from ..reference.dopus import ReferenceDopus

    s = (settings_mod.of_problem(disc) if settings is None else settings).replace(**changes)
    if isinstance(start, str):
        start = make_start(disc, start)
    if backend_factory is None:
        backend_factory = ReferenceDopus
        backend_name = backend_name or "reference"
    if isinstance(iters, bool) or not isinstance(iters, (int, np.integer)) or iters < 1:
        raise ValueError(f"iters must be a positive integer, got {iters!r}")
    Ms = [_resolve_M(m, disc.N) for m in m_list]
    if not Ms:
        raise ValueError("the list of M values is empty")
    runs = []
    last_iterates = {}
    for run_index, M in enumerate(Ms):
        be = backend_factory(disc, settings=s.replace(M=M, mode="fixed"))
        rec = {"M": M, "kkt": [], "stat": [], "eq": [], "ineq": [], "comp": [], "rel": [], "status": None,
               "message": None}

        def record():
            k = be.kkt(start.xhat_fixed)
            for key in ("kkt", "stat", "eq", "ineq", "comp", "rel"):
                rec[key].append(float(k[key]))
            return k["kkt"]

        try:
            be.init(start.xhat_init, start.guess)
            record()
            for it in range(1, iters + 1):
                be.feedback(start.xhat_fixed)
                be.prepare()
                val = record()
                if progress is not None:
                    progress(run_index, M, it, val)
                if not math.isfinite(val):
                    rec["status"], rec["message"] = FAILED, f"non-finite KKT measure at iteration {it}"
                    break
        except DopusError as exc:
            it = len(rec["kkt"])
            what = "init" if it == 0 else f"iteration {it}"
            rec["status"] = FAILED
            rec["message"] = f"in {what}: {exc} (status {exc.status} {exc.status_name})" \
                + _infeasibility_note(disc, exc, start.xhat_fixed)
            if progress is not None:
                progress(run_index, M, iters, float("nan"))
        rec["iterations_to_tol"] = iterations_to(*((rec["kkt"], tol) if tol_rel is None else (rec["rel"], tol_rel)))
        if rec["status"] is None:
            rec["status"] = CONVERGED if rec["iterations_to_tol"] is not None else NOT_CONVERGED
        runs.append(rec)
        last_iterates[M] = (np.array(be.x, dtype=float), np.array(be.u, dtype=float))
    glob = None
    if globalise:
        def glob_progress(it, val):
            if progress is not None:
                progress(len(Ms), None, it, val)

        glob, last_iterates[None] = run_globalised(disc, iters, start, s, backend_factory, tol, glob_progress)
    return {
        "problem": disc.name, "N": int(disc.N), "backend": backend_name or getattr(backend_factory, "__name__", "custom"),
        "start": start.label, "hessian": s.hessian, "regularization": s.regularization, "reg_eps": float(s.reg_eps),
        "cost_hessian": s.cost_hessian, "lm": s.lm if isinstance(s.lm, str) else float(s.lm), "qp_tol": s.qp_tol,
        "qp_max_iter": s.qp_max_iter,
        "tol": float(tol), "tol_rel": None if tol_rel is None else float(tol_rel), "runs": runs, "globalised": glob,
        "solution": _solution(disc, runs, last_iterates, glob),
    }


#: The status of a run: it reached the tolerance; it ran every iteration without reaching
#: it; an iteration failed (an error of the backend or a non-finite KKT measure).
CONVERGED, NOT_CONVERGED, FAILED = "converged", "not converged", "failed"


def failed_runs(study: dict) -> list:
    """The runs of a study whose status is ``failed`` (the globalised solve's with ``"M":
    "globalised"``)."""
    bad = [r for r in study["runs"] if r["status"] == FAILED]
    g = study.get("globalised")
    if g is not None and g["status"] == FAILED:
        bad.append(dict(g, M="globalised"))
    return bad


def _infeasibility_note(disc, exc, xhat) -> str:
    """For an infeasible QP: the stage-0 rows the measured state violates (if any)."""
    if exc.qp_status_name != "primal_infeasible":
        return ""
    from ..problem.checks import stage0_violations

    try:
        rows = stage0_violations(disc, xhat)
    except Exception:  # noqa: BLE001 - the note is a help, never a second failure
        return ""
    return f"; the state violates at stage 0: {'; '.join(rows)}" if rows else ""


def _solution(disc, runs, last_iterates, glob=None):
    """The last iterate of the full-RTI run if it converged, else of the converged run with
    the largest M, else of the globalised solve if it converged (``M`` None); if none
    converged, of the preferred run that did not fail, marked ``converged: false``; None if
    every run failed."""
    by_M = {r["M"]: r for r in runs}
    order = sorted(by_M, key=lambda m: (m != disc.N - 1, -m))
    pick = next((m for m in order if by_M[m]["status"] == CONVERGED), None)
    if pick is None and glob is not None and glob["status"] == CONVERGED:
        xs, us = last_iterates[None]
        return _solution_record(disc, None, glob, xs, us)
    if pick is None:
        pick = next((m for m in order if by_M[m]["status"] != FAILED), None)
    if pick is None:
        return None
    xs, us = last_iterates[pick]
    return _solution_record(disc, int(pick), by_M[pick], xs, us)


def _solution_record(disc, M, rec, xs, us):
    try:
        obj = objective(disc, xs, us)
    except Exception:  # noqa: BLE001 - a diverged iterate may not evaluate
        obj = float("nan")
    return {"M": M, "status": rec["status"], "converged": rec["status"] == CONVERGED,
            "kkt": rec["kkt"][-1], "x": xs.tolist(), "u": us.tolist(), "objective": obj}


def format_table(study: dict, tol: Optional[float] = None) -> str:
    """Plain-text summary: per M the iterations to ``tol`` (default: the study's), the last
    KKT, the status and, for a failed run, why."""
    N = study["N"]
    tol_rel = study.get("tol_rel")
    rel = tol_rel is not None and tol is None
    tol = (tol_rel if rel else study.get("tol", 1e-8)) if tol is None else tol
    head = ("iters to rel %.0e" if rel else "iters to %.0e") % tol
    lines = [f"{study['problem']}: {study['start']} start, {study['hessian']} Hessian, "
             f"regularization {study['regularization']}, cost Hessian {study.get('cost_hessian', 'fresh')}, "
             f"backend {study['backend']}",
             f"{'M':>8} {head:>18} {'last KKT':>10} {'last rel':>10}  status"]
    for r in study["runs"]:
        it = iterations_to(r["rel"] if rel else r["kkt"], tol)
        label = f"{r['M']} (full)" if r["M"] == N - 1 else str(r["M"])
        last = r["kkt"][-1] if r["kkt"] else float("nan")
        last_rel = r["rel"][-1] if r.get("rel") else float("nan")
        status = r["status"] + (f": {r['message']}" if r.get("message") else "")
        lines.append(f"{label:>8} {('-' if it is None else str(it)):>18} {last:10.2e} {last_rel:10.2e}  {status}")
    g = study.get("globalised")
    if g is not None:
        it = iterations_to(g["kkt"], study.get("tol", 1e-8) if rel else tol)
        last = g["kkt"][-1] if g["kkt"] else float("nan")
        relaxed = g.get("relaxed") or [False] * len(g["alpha"])
        steps = ", ".join("R" if r else f"{a:g}" for a, r in zip(g["alpha"][:12], relaxed)) \
            + (", ..." if len(g["alpha"]) > 12 else "")
        status = g["status"] + (f": {g['message']}" if g.get("message") else "")
        lines.append(f"{'glob.':>8} {('-' if it is None else str(it)):>18} {last:10.2e} {float('nan'):10.2e}  {status}"
                     + (f" (step lengths {steps})" if steps else ""))
    sol = study.get("solution")
    if sol is None:
        lines.append("solution: none (every run failed)")
    else:
        who = "the globalised solve" if sol["M"] is None else f"M = {sol['M']}"
        lines.append(f"solution: the last iterate of {who} ({sol['status']}, KKT {sol['kkt']:.2e})")
    return "\n".join(lines)


def plot_study(study: dict, path: str) -> None:
    """KKT against iteration, log scale, one curve per M."""
    from .plots import plt

    N = study["N"]
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for r in study["runs"]:
        kk = np.maximum(np.array(r["kkt"], dtype=float), 1e-16)  # exact zeros cannot be drawn on a log axis
        label = f"M = {r['M']} (full RTI)" if r["M"] == N - 1 else f"M = {r['M']}"
        ax.semilogy(np.arange(kk.size), kk, marker="o", markersize=3, label=label)
    g = study.get("globalised")
    if g is not None and g["kkt"]:
        kk = np.maximum(np.array(g["kkt"], dtype=float), 1e-16)
        ax.semilogy(np.arange(kk.size), kk, marker="s", markersize=3, color="k", label="globalised")
    ax.set_xlabel("iteration [-]")
    ax.set_ylabel("KKT measure (inf-norm) [mixed units]")
    ax.set_title(f"{study['problem']}: DOPUS convergence, {study['start']} start, {study['hessian']} Hessian, "
                 f"{study.get('cost_hessian', 'fresh')} cost Hessian", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend()
    fig.tight_layout()
    from ..outputs import save_figure

    save_figure(fig, path, dpi=120)
    plt.close(fig)


#: The M values of the study when neither the command line nor the OCP file gives M.
DEFAULT_M_LIST = ("full", 5, 1, 0)


def _cli_M_list(m_list, N: int, is_default: bool = False) -> list:
    """Resolve the CLI's M values. An explicit value above N-1 is an error; the default list
    (full,5,1,0) drops entries a short horizon cannot have."""
    if is_default:
        m_list = [m for m in m_list if m == "full" or settings.stages(m, N) == m]
    out = []
    for m in m_list:
        M = _resolve_M(m, N)
        if M not in out:
            out.append(M)
    return out


def effective_settings(declared: dict, m_list, real: str = "double", **flags):
    """The settings of a study: the command line's ``flags`` (None = not given) over the OCP
    file's ``declared`` options over the defaults (a QP tolerance not given: that of
    ``real``); the M list is the command line's, else the file's M, else
    :data:`DEFAULT_M_LIST`. Returns ``(settings, sources, m_list, m_is_default)``."""
    s, sources = settings.Settings.resolve(declared, dict(flags, M=None), real=real)
    if m_list is not None:
        sources["M"] = settings.SOURCE_CLI
        return s, sources, list(m_list), False
    if "M" in declared:
        sources["M"] = settings.SOURCE_FILE
        return s, sources, [int(declared["M"])], False
    sources["M"] = settings.SOURCE_DEFAULT
    return s, sources, list(DEFAULT_M_LIST), True


def run_converge_cli(ocp_file, m_list, iters, start, backend="reference", json_out=None, plot_out=None, tol=None,
                     real=None, tol_rel=None, globalise=None, **flags) -> dict:
    """The body of ``dopus-gen converge`` (bad input raises OcpError, ValueError or
    RuntimeError with a message; the command line turns them into one line). ``flags``: the
    settings given on the command line (:data:`dopus_codegen.settings.RUNTIME_SETTINGS`,
    None: not given); the others come from the OCP file's ``options(...)``, else from the
    defaults of :mod:`dopus_codegen.settings`; the summary and the JSON say where each came
    from. The output paths are checked before the study runs."""
    import click

    from ..outputs import check_output_file
    from ..problem.checks import check_initial_state
    from ..problem.derivatives import build_functions
    from ..problem.ocp import load_ocp

    if json_out:
        check_output_file(json_out, "--json")
    if plot_out:
        check_output_file(plot_out, "--plot")
    factory = backend_factory(backend)
    ocp = load_ocp(ocp_file)
    declared = ocp.declared_options()
    real_values, real_sources = settings.resolve(declared, {"real": real}, names=("real",))
    real = real_values["real"]
    s, sources, m_list, m_default = effective_settings(declared, m_list, real=real, **flags)
    sources["real"] = real_sources["real"]
    if real != settings.DEFAULTS["real"] and backend != "c":
        raise ValueError(f"--real {real} needs --backend c (the reference backend computes in double)")
    ocp.options(real=real)    # the C backend is generated in this type
    if tol is None:
        tol = settings.KKT_TOL_DEFAULT[real]
    if tol_rel is None:
        tol_rel = declared.get("kkt_tol_rel")
    disc = build_functions(ocp)
    if s.hessian == "gauss-newton" and disc.stage_hess_gn is None:
        raise ValueError(f"{disc.name}: --hessian gauss-newton needs a least-squares stage cost "
                         f"(ocp.stage_least_squares)")
    Ms = _cli_M_list(m_list, disc.N, m_default)
    shown = {k: v for k, v in s.as_dict().items() if k not in ("M", "mode")}
    click.echo(f"{disc.name}: settings: M {','.join(str(m) for m in Ms)} ({sources['M']}), "
               + settings.describe(dict(shown, real=real), sources), err=True)
    check_initial_state(disc, disc.x0, "the initial state")
    click.echo(f"{disc.name}: preparing the {start} start ...", err=True)
    sp = make_start(disc, start)
    if start == "warm":
        check_initial_state(disc, sp.xhat_fixed, "the disturbed initial state (--start warm)")

    if globalise is None:
        globalise = start == "cold"
    total = (len(Ms) + int(bool(globalise))) * iters
    with click.progressbar(length=total, label="DOPUS iterations", file=sys.stderr,
                           show_pos=True) as bar:
        done = {"n": 0}

        def progress(run_index, M, it, kkt):
            # a run that stops early jumps to its end
            target = run_index * iters + it
            if target > done["n"]:
                bar.update(target - done["n"])
                done["n"] = target

        study = run_study(disc, Ms, iters, sp, s, backend_factory=factory, backend_name=backend,
                          progress=progress, tol=tol, tol_rel=tol_rel, globalise=bool(globalise))
    study["sources"] = {k: sources[k] for k in ("M", *settings.RUNTIME_SETTINGS, "real") if k in sources}
    study["real"] = real
    click.echo(format_table(study))
    if json_out:
        from ..outputs import write_text

        write_text(json_out, json.dumps(json_ready(study), indent=1, allow_nan=False))
        click.echo(f"wrote {json_out}", err=True)
    if plot_out:
        plot_study(study, plot_out)
        click.echo(f"wrote {plot_out}", err=True)
    return study
