"""Software-in-the-loop closed loop: a DOPUS backend against the CVODES plant.

Receding-horizon loop of docs/algorithm.md section 4, one DOPUS iteration per sampling
instant ``t_i = i dt``::

    init(xhat_0, offline primal-dual solution at xhat_0)
    for each instant: apply the scenario events due at t_i to the plant state,
                      measure xhat = plant state,
                      u0 = feedback(xhat)           (timed: input-output latency)
                      kkt(xhat)                      (recorded, not timed)
                      plant: u0 held over [t_i, t_i + dt], CVODES (events inside the
                             interval split the step)
                      prepare()                      (timed)

An instant whose feedback fails (QP failure, non-finite input) applies the first control of
the current, already shifted plan, as a controller in the field would, and records the
status; the loop goes on. A plant failure (CVODES cannot integrate, state not finite) ends
the run and is recorded in ``run["aborted"]``.

A run is a plain JSON-ready dict (see :func:`run_closed_loop`); :func:`summarize` condenses it
into the figures of the summary table.
"""
from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import numpy as np

from .plant import Plant, PlantError

__all__ = ["SilError", "make_backend", "run_closed_loop", "summarize", "format_summary",
           "write_json", "run_sil_cli"]

# Tolerance for an event time to count as "on" a sampling instant, relative to dt.
_ON_GRID = 1e-9
# Seconds a run may take before the progress bar shows up.
_PROGRESS_AFTER = 2.0


def default_lm(disc) -> float:
    """The Levenberg-Marquardt term of the closed loop when none is given: the OCP file's
    ``options(lm=...)``, else 0 (docs/algorithm.md section 3; README "Closed loop")."""
    return float(disc.spec.options.lm)


class SilError(RuntimeError):
    """A closed-loop run could not be set up (bad scenario, bad settings)."""


# --------------------------------------------------------------------------- backends
def make_backend(disc, backend: str = "c", M: int = 1, hessian: str = "exact",
                 regularization: str = "none", reg_eps: float = 1e-4, cost_hessian: str = "fresh",
                 lm: float = 0.0):
    """A receding-horizon backend (docs/algorithm.md section 7) by name: 'c' or 'reference'."""
    kwargs = dict(M=M, mode="receding", hessian=hessian, regularization=regularization, reg_eps=reg_eps,
                  cost_hessian=cost_hessian, lm=lm)
    if backend == "reference":
        from ..reference.dopus import ReferenceDopus
        return ReferenceDopus(disc, **kwargs)
    if backend == "c":
        from ..runtime.solver import CSolver
        return CSolver(disc, **kwargs)
    raise SilError(f"unknown backend {backend!r}: expected 'c' or 'reference'")


def _status_of(err) -> int:
    status = getattr(err, "status", None)
    try:
        status = int(status)
    except (TypeError, ValueError):
        status = -1
    return status if status != 0 else -1


def _is_dopus_error(err) -> bool:
    # Both backends raise DopusError (a status attribute); match by name so that this module
    # does not import a backend it does not use.
    return any(cls.__name__ == "DopusError" for cls in type(err).__mro__)


# --------------------------------------------------------------------------- scenario
def _default_parameters(disc) -> np.ndarray:
    """Parameter vector of node 0 used by the plant and the signals."""
    np_ = int(disc.np)
    if np_ == 0:
        return np.zeros(0)
    return np.asarray(disc.p0, dtype=float).reshape(-1, np_)[0].copy()


def _eval(fn, x, u, p) -> np.ndarray:
    return np.asarray(fn(x, u, p), dtype=float).reshape(-1)


def _apply_event(ev, x: np.ndarray, nx: int) -> np.ndarray:
    try:
        out = ev.fn(x.copy())
        out = np.asarray(out, dtype=float).reshape(-1)
    except Exception as exc:  # noqa: BLE001 - a user function of the OCP file
        raise SilError(f"scenario event '{ev.label}' at t = {ev.time} s failed: {exc}") from None
    if out.size != nx or not np.all(np.isfinite(out)):
        raise SilError(f"scenario event '{ev.label}' at t = {ev.time} s must return {nx} finite "
                       f"values, got {out}")
    return out


def _round_json(v):
    """Floats as JSON numbers; non-finite values become null (strict JSON)."""
    if isinstance(v, dict):
        return {k: _round_json(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_round_json(x) for x in v]
    if isinstance(v, (np.floating, float)):
        return float(v) if math.isfinite(v) else None
    if isinstance(v, np.integer):
        return int(v)
    if isinstance(v, np.ndarray):
        return _round_json(v.tolist())
    return v


# --------------------------------------------------------------------------- the loop
def run_closed_loop(disc, backend: str = "c", M: int = 1, hessian: str = "exact",
                    regularization: str = "none", reg_eps: float = 1e-4, cost_hessian: str = "fresh",
                    lm: float | None = None, duration: float | None = None,
                    guess=None, xhat0=None, progress: bool = False, label: str | None = None,
                    backend_obj=None) -> dict:
    """Run the closed loop of the OCP's scenario and return the record of the run.

    ``guess``: the initialisation of the controller (default: the offline solve at the
    initial state, ``offline.solve_ocp``). ``backend_obj``: an already constructed backend
    (then ``backend``, ``M``, ``hessian``, ... only label the run).

    The record: ``t, x, u, kkt, kkt_parts, status, signals, recomputed, timing_us, settings,
    events`` (one entry per sampling instant; ``x`` is the measured state, ``u`` the applied
    control, ``kkt`` the KKT measure right after feedback), and ``aborted`` (None or why the
    run stopped early).
    """
    spec = disc.scenario.closed_loop
    if spec is None:
        raise SilError("the OCP declares no closed-loop scenario: call ocp.scenario(duration, events=..., "
                       "signals=...) in its build()")
    N, nx, nu, dt = int(disc.N), int(disc.nx), int(disc.nu), float(disc.dt)
    duration = float(spec.duration if duration is None else duration)
    if not (math.isfinite(duration) and duration > 0):
        raise SilError(f"duration must be positive and finite, got {duration}")
    n_steps = int(round(duration / dt))
    if n_steps < 1:
        raise SilError(f"duration {duration} s is shorter than one sampling interval ({dt} s)")
    M_eff = max(0, min(int(M), N - 1))
    if label is None:
        label = "full RTI" if M_eff == N - 1 else f"DOPUS M = {M_eff}"

    if lm is None:
        lm = default_lm(disc)
    p = _default_parameters(disc)
    x = np.array(spec.x0 if spec.x0 is not None else disc.x0, dtype=float).reshape(-1)
    if x.size != nx:
        raise SilError(f"scenario x0 has {x.size} entries, expected nx = {nx}")
    plant_ode = spec.plant_ode if spec.plant_ode is not None else disc.ode
    plant = Plant(plant_ode, dt, p.size, reltol=1e-10, abstol=1e-10)
    lbu = np.asarray(disc.lbu, dtype=float).reshape(-1)
    ubu = np.asarray(disc.ubu, dtype=float).reshape(-1)

    events = sorted([ev for ev in spec.events if float(ev.time) < duration + _ON_GRID * dt],
                    key=lambda ev: float(ev.time))

    if guess is None:
        from ..reference.offline import solve_ocp
        guess, _info = solve_ocp(disc, x)
    if backend_obj is None:
        try:
            backend_obj = make_backend(disc, backend, M=M_eff, hessian=hessian, regularization=regularization,
                                       reg_eps=reg_eps, cost_hessian=cost_hessian, lm=lm)
        except SilError:
            raise
        except Exception as exc:  # noqa: BLE001 - settings rejected, C build failed, ...
            raise SilError(f"cannot set up the {backend} backend: {exc}") from None
    ctrl = backend_obj
    ctrl.init(x, guess)
    snap = dict(getattr(ctrl, "timings", {}) or {})

    rec_t, rec_x, rec_u, rec_kkt, rec_parts, rec_status, rec_rec = [], [], [], [], [], [], []
    rec_sig = {name: [] for name in spec.signals}
    rec_qp_it = []
    timing: dict[str, list] = {"feedback": [], "prepare": [], "total": []}
    phase_timing: dict[str, list] = {}  # the backend's own phase timers
    aborted = None

    bar = None
    t_start = time.perf_counter()
    ev_idx = 0
    try:
        for i in range(n_steps):
            t_i = i * dt
            # Events on this instant act before the measurement.
            while ev_idx < len(events) and float(events[ev_idx].time) <= t_i + _ON_GRID * dt:
                x = _apply_event(events[ev_idx], x, nx)
                ev_idx += 1
            xhat = x.copy()

            status = 0
            t0 = time.perf_counter()
            try:
                u0 = np.asarray(ctrl.feedback(xhat), dtype=float).reshape(-1)
            except Exception as err:  # noqa: BLE001
                if not _is_dopus_error(err):
                    raise
                status = _status_of(err)
                u0 = np.asarray(ctrl.u, dtype=float)[0].copy()
            t_fb = time.perf_counter() - t0
            rec_qp_it.append(int(getattr(ctrl, "qp_iterations", 0) or 0))
            snap_fb = dict(getattr(ctrl, "timings", {}) or {})
            phases = _split_phases("feedback", _changed(snap, snap_fb))
            if not np.all(np.isfinite(u0)):
                u0 = np.clip(np.nan_to_num(np.asarray(ctrl.u, dtype=float)[0]), lbu, ubu)
                status = status or -1

            try:
                kkt = ctrl.kkt(xhat)
            except Exception as err:  # noqa: BLE001
                if not _is_dopus_error(err):
                    raise
                # A non-finite iterate has no KKT measure; the instant counts as failed.
                kkt = {"kkt": math.nan}
                status = status or _status_of(err)
            # A backend may time its KKT evaluation too; that is not part of the iteration.
            snap_fb = dict(getattr(ctrl, "timings", {}) or {})

            rec_t.append(t_i)
            rec_x.append(xhat)
            rec_u.append(u0.copy())
            rec_kkt.append(float(kkt["kkt"]))
            rec_parts.append({k: float(kkt[k]) for k in ("stat", "eq", "ineq", "comp") if k in kkt})
            for name, fn in spec.signals.items():
                rec_sig[name].append(_eval(fn, xhat, u0, p))

            # Plant over [t_i, t_i + dt], split at events strictly inside the interval.
            t_cur, t_next = t_i, (i + 1) * dt
            while ev_idx < len(events) and float(events[ev_idx].time) < t_next - _ON_GRID * dt:
                te = float(events[ev_idx].time)
                x = plant.step(x, u0, p, duration=te - t_cur)
                x = _apply_event(events[ev_idx], x, nx)
                t_cur = te
                ev_idx += 1
            x = plant.step(x, u0, p, duration=t_next - t_cur)

            t0 = time.perf_counter()
            prepared = True
            try:
                ctrl.prepare()
            except Exception as err:  # noqa: BLE001
                if not _is_dopus_error(err):
                    raise
                status = status or _status_of(err)
                prepared = False
            t_pr = time.perf_counter() - t0
            snap = dict(getattr(ctrl, "timings", {}) or {})
            phases.update(_split_phases("prepare", _changed(snap_fb, snap)))
            rec_status.append(int(status))
            rec_rec.append([int(k) for k in getattr(ctrl, "recomputed", [])] if prepared else [])

            timing["feedback"].append(t_fb * 1e6)
            timing["prepare"].append(t_pr * 1e6)
            timing["total"].append((t_fb + t_pr) * 1e6)
            _record_phases(phase_timing, phases, i)

            if progress and bar is None and time.perf_counter() - t_start > _PROGRESS_AFTER:
                import click
                bar = click.progressbar(length=n_steps, label=f"{label:>12}", file=sys.stderr,
                                        show_eta=True, show_percent=True)
                bar.__enter__()
                bar.update(i + 1)
            elif bar is not None:
                bar.update(1)
    except PlantError as err:
        aborted = f"plant failed at t = {len(rec_t) * dt:.4g} s: {err}"
        n_done = len(rec_status)
        # Drop the half-recorded instant so that all arrays have one entry per finished instant.
        rec_t, rec_x, rec_u, rec_kkt, rec_parts = (a[:n_done] for a in (rec_t, rec_x, rec_u, rec_kkt, rec_parts))
        rec_sig = {k: v[:n_done] for k, v in rec_sig.items()}
    finally:
        if bar is not None:
            bar.__exit__(None, None, None)

    run = {
        "label": label,
        "t": rec_t,
        "x": [list(v) for v in rec_x],
        "u": [list(v) for v in rec_u],
        "kkt": rec_kkt,
        "kkt_parts": rec_parts,
        "status": rec_status,
        "signals": {k: [float(v[0]) if v.size == 1 else list(v) for v in vals] for k, vals in rec_sig.items()},
        "recomputed": rec_rec,
        "qp_iterations": rec_qp_it[:len(rec_status)],
        "timing_us": {"feedback": timing["feedback"], "prepare": timing["prepare"], "total": timing["total"],
                      **{f"phase:{k}": v for k, v in phase_timing.items()}},
        "events": [{"time": float(ev.time), "label": str(ev.label)} for ev in events],
        "settings": {"M": M_eff, "N": N, "dt": dt, "duration": n_steps * dt, "hessian": hessian,
                     "regularization": regularization, "reg_eps": float(reg_eps), "backend": backend,
                     "cost_hessian": str(getattr(backend_obj, "cost_hessian", cost_hessian)),
                     "lm": float(getattr(backend_obj, "lm", lm)),
                     "plant": "CVODES (Adams, reltol = abstol = 1e-10)",
                     "lbu": list(lbu), "ubu": list(ubu),
                     "u_labels": list(disc.data.control_names) or None,
                     "x_labels": list(disc.data.state_names) or None,
                     "plane": list(_plane_signals(spec)) if _plane_signals(spec) else None},
        "aborted": aborted,
    }
    return _round_json(run)


def _changed(before: dict, after: dict) -> dict:
    """Entries of the backend's ``timings`` (seconds) that the last call wrote."""
    return {k: float(v) for k, v in after.items() if k not in before or before[k] != v}


def _split_phases(call: str, changed: dict) -> dict:
    """Disjoint phases of one call: its sub-phases and the rest of its total.

    A backend reports the total of a call under the call's name ("feedback", "prepare")
    and the parts it times separately under other names; the part not covered by them is
    "<call>: other".
    """
    total = changed.pop(call, None)
    changed.pop("init", None)
    if total is None:
        return changed
    out = dict(changed)
    rest = total - sum(changed.values())
    out[f"{call}: other" if changed else call] = max(rest, 0.0)
    return out


def _record_phases(timing, phases, i):
    """Append this instant's phase durations (microseconds); absent phases count 0."""
    for k, v in phases.items():
        if k not in timing:
            timing[k] = [0.0] * i
        timing[k].append(v * 1e6)
    for k in timing:
        if len(timing[k]) < i + 1:
            timing[k].append(0.0)


def _plane_signals(spec):
    """(path, reference) signal names for the plane plot, or None.

    The scenario names them with ``spec.plane = (path, reference)`` when it has that
    attribute; otherwise the first two signals with two components are taken, in their
    declaration order (for the robot arm: the tip position, then the point on the circle).
    """
    plane = getattr(spec, "plane", None)
    if plane:
        return tuple(plane)
    two = [name for name, fn in spec.signals.items() if int(fn.numel_out(0)) == 2]
    return (two[0], two[1]) if len(two) >= 2 else None


# --------------------------------------------------------------------------- summary
def _segments(run):
    """(label, mask) per stretch of time: before the first event, after each event."""
    t = np.asarray(run["t"], dtype=float)
    evs = run["events"]
    if not evs:
        return [("whole run", np.ones(t.size, bool))]
    bounds = [ev["time"] for ev in evs]
    tol = _ON_GRID * run["settings"]["dt"]
    segs = [(f"before {evs[0]['label']}", t < bounds[0] - tol)]
    for j, ev in enumerate(evs):
        end = bounds[j + 1] if j + 1 < len(bounds) else np.inf
        segs.append((f"after {ev['label']}", (t >= ev["time"] - tol) & (t < end - tol)))
    return segs


def summarize(run, settle: float = 0.2) -> dict:
    """Figures of the summary table for one run.

    ``settle``: seconds after the start and after each event during which the KKT measure is
    not counted in "max KKT after settling".
    """
    t = np.asarray(run["t"], dtype=float)
    out = {"label": run["label"], "segments": [], "aborted": run.get("aborted")}
    for name, vals in run["signals"].items():
        v = np.asarray([np.nan if a is None else a for a in vals], dtype=float)
        if v.ndim != 1:
            continue
        for seg, mask in _segments(run):
            vs = np.abs(v[mask])
            out["segments"].append({"signal": name, "segment": seg,
                                    "max": float(np.max(vs)) if vs.size else math.nan,
                                    "rms": float(np.sqrt(np.mean(vs ** 2))) if vs.size else math.nan})
    kkt = np.asarray([np.nan if a is None else a for a in run["kkt"]], dtype=float)
    settled = t >= settle
    for ev in run["events"]:
        settled &= ~((t >= ev["time"]) & (t < ev["time"] + settle))
    out["settle"] = settle
    ks = kkt[settled & np.isfinite(kkt)]
    out["kkt_max_settled"] = float(np.max(ks)) if ks.size else math.nan
    out["kkt_nonfinite"] = int(np.count_nonzero(~np.isfinite(kkt)))
    out["qp_failures"] = int(np.count_nonzero(np.asarray(run["status"]) != 0))
    u = np.asarray(run["u"], dtype=float)
    lbu = np.asarray([-np.inf if a is None else a for a in run["settings"]["lbu"]], dtype=float)
    ubu = np.asarray([np.inf if a is None else a for a in run["settings"]["ubu"]], dtype=float)
    out["bound_violation"] = float(max(0.0, np.max(u - ubu), np.max(lbu - u))) if u.size else 0.0
    tot = np.asarray(run["timing_us"]["total"], dtype=float)
    fb = np.asarray(run["timing_us"]["feedback"], dtype=float)
    out["time_median_us"] = float(np.median(tot)) if tot.size else math.nan
    out["time_max_us"] = float(np.max(tot)) if tot.size else math.nan
    out["feedback_median_us"] = float(np.median(fb)) if fb.size else math.nan
    out["feedback_max_us"] = float(np.max(fb)) if fb.size else math.nan
    return out


def format_summary(summaries) -> str:
    """The summary table of one or more runs as text."""
    lines = []
    sig_rows = [(s["label"], seg) for s in summaries for seg in s["segments"]]
    if sig_rows:
        w_run = max(len("run"), *(len(r) for r, _ in sig_rows))
        w_sig = max(len("signal"), *(len(seg["signal"]) for _, seg in sig_rows))
        w_seg = max(len("stretch"), *(len(seg["segment"]) for _, seg in sig_rows))
        head = f"{'run':<{w_run}}  {'signal':<{w_sig}}  {'stretch':<{w_seg}}  {'max':>10}  {'RMS':>10}"
        lines += [head, "-" * len(head)]
        for r, seg in sig_rows:
            lines.append(f"{r:<{w_run}}  {seg['signal']:<{w_sig}}  {seg['segment']:<{w_seg}}  "
                         f"{seg['max']:10.3e}  {seg['rms']:10.3e}")
        lines.append("")
    w_run = max([len("run")] + [len(s["label"]) for s in summaries])
    head = (f"{'run':<{w_run}}  {'max KKT settled':>15}  {'QP fail':>7}  {'u bound viol':>12}  "
            f"{'median it [us]':>14}  {'max it [us]':>11}  {'median fb [us]':>14}")
    lines += [head, "-" * len(head)]
    for s in summaries:
        lines.append(f"{s['label']:<{w_run}}  {s['kkt_max_settled']:15.3e}  {s['qp_failures']:7d}  "
                     f"{s['bound_violation']:12.2e}  {s['time_median_us']:14.1f}  {s['time_max_us']:11.1f}  "
                     f"{s['feedback_median_us']:14.1f}")
    if summaries:
        lines.append(f"(max KKT settled: excluding the first {summaries[0]['settle']} s after the start "
                     f"and after each event; it = feedback + prepare, fb = feedback alone)")
    for s in summaries:
        if s.get("aborted"):
            lines.append(f"{s['label']}: ABORTED: {s['aborted']}")
    return "\n".join(lines)


def write_json(runs, path) -> None:
    path = Path(path)
    if path.parent and not path.parent.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w") as fh:
        json.dump({"runs": runs}, fh, allow_nan=False)
        fh.write("\n")


# --------------------------------------------------------------------------- CLI
def run_sil_cli(ocp_file, M, duration, json_out, plot_dir, compare, hessian, regularization, reg_eps,
                backend, cost_hessian="fresh", echo=None, progress=True, lm=None) -> list:
    """The ``dopus-gen sil`` command: runs, summary table, JSON and plots."""
    from ..problem.ocp import load_ocp
    from ..problem.derivatives import build_functions

    if echo is None:
        import click
        echo = click.echo

    ocp = load_ocp(ocp_file)
    disc = build_functions(ocp)
    if disc.scenario.closed_loop is None:
        raise SilError(f"{ocp_file}: the OCP declares no closed-loop scenario (ocp.scenario(...))")
    if hessian == "gauss-newton" and not disc.functions.has_gn:
        raise SilError(f"{ocp_file}: --hessian gauss-newton needs a least-squares stage cost "
                       "(ocp.stage_least_squares)")
    spec = disc.scenario.closed_loop
    x0 = np.array(spec.x0 if spec.x0 is not None else disc.x0, dtype=float).reshape(-1)

    from ..reference.offline import solve_ocp
    guess, info = solve_ocp(disc, x0)
    if not info.get("success", True):
        echo(f"warning: the offline solve at the initial state did not converge ({info.get('status')}); "
             "the controller starts from its last iterate", err=True)

    if lm is None:
        lm = default_lm(disc)
    N = int(disc.N)
    configs = [(M, None)]
    if compare == "full" and min(M, N - 1) != N - 1:
        configs.append((N - 1, "full RTI"))
    runs = []
    for m, label in configs:
        name = label or ("full RTI" if min(m, N - 1) == N - 1 else f"DOPUS M = {m}")
        echo(f"{name}: {backend} backend, {hessian} Hessian, regularization {regularization}, "
             f"cost Hessian {cost_hessian}, Levenberg-Marquardt {lm:g}, "
             f"{duration if duration is not None else spec.duration} s ...", err=True)
        run = run_closed_loop(disc, backend=backend, M=m, hessian=hessian, regularization=regularization,
                              reg_eps=reg_eps, cost_hessian=cost_hessian, lm=lm, duration=duration, guess=guess,
                              progress=progress, label=label)
        runs.append(run)
    summaries = [summarize(r) for r in runs]
    echo(format_summary(summaries))
    if json_out:
        write_json(runs, json_out)
        echo(f"JSON: {json_out}")
    if plot_dir:
        from .plots import plot_sil
        files = plot_sil(runs, plot_dir, title=getattr(disc, "name", None))
        echo(f"plots: {Path(plot_dir).resolve()} ({len(files)} PNG)")
    return runs
