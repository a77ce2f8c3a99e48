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

Every instant applies the control the runtime returns, whatever the status
(:mod:`.loops`: the one closed-loop instant of the package, the firmware's too): after a
failed feedback (QP failure, non-finite input) that is the runtime's safe control; the
status is recorded and the loop goes on. A plant failure (CVODES cannot integrate, state not finite) ends
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

from .. import interrupt, settings
from ..errors import DopusError
from . import loops
from .plant import Plant, PlantError
from .records import json_ready

__all__ = ["SilError", "make_backend", "run_closed_loop", "summarize", "format_summary",
           "write_json", "run_sil_cli"]

# Tolerance for an event time to count as "on" a sampling instant, relative to dt.
_ON_GRID = 1e-9
# Seconds a run may take before the progress bar shows up.
_PROGRESS_AFTER = 2.0


class SilError(RuntimeError):
    """A closed-loop run could not be set up (bad scenario, bad settings)."""


# --------------------------------------------------------------------------- backends
def make_backend(disc, backend: str = "c", settings=None, **changes):
    """A receding-horizon backend (docs/algorithm.md section 7) by name: 'c' or 'reference',
    with ``settings`` (None: the OCP file's ``options(...)``) and ``changes`` by name."""
    s = _settings_of(disc, settings, changes).replace(mode="receding")
    if backend == "reference":
        from ..reference.dopus import ReferenceDopus
        return ReferenceDopus(disc, s)
    if backend == "c":
        from ..runtime.solver import Solver
        return Solver(disc, s)
    raise SilError(f"unknown backend {backend!r}: expected 'c' or 'reference'")


def _settings_of(disc, s, changes) -> "settings.Settings":
    """``s`` (None: the OCP file's settings of ``disc``) with ``changes`` by name."""
    try:
        return (settings.of_problem(disc) if s is None else s).replace(**changes)
    except settings.SettingError as exc:
        raise SilError(str(exc)) from None


def _status_of(err) -> int:
    status = getattr(err, "status", None)
    try:
        status = int(status)
    except (TypeError, ValueError):
        status = -1
    return status if status != 0 else -1


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


# --------------------------------------------------------------------------- the loop
def run_closed_loop(disc, backend: str = "c", settings=None, duration: float | None = None,
                    guess=None, xhat0=None, progress: bool = False, label: str | None = None,
                    backend_obj=None, sources: dict | None = None, events=None, plant=None, **changes) -> dict:
    """Run the closed loop of the OCP's scenario and return the record of the run.

    ``settings``: the controller's settings (None: the OCP file's ``options(...)``), with
    ``changes`` by name (``M=3``; None: not given). ``guess``: the initialisation of the
    controller (default: the offline solve at the initial state, ``offline.solve_ocp``).
    ``backend_obj``: an already constructed backend with these settings (then ``backend``
    only labels the run). ``sources``: where each setting came from
    (``Settings.resolve``), recorded with the settings. ``xhat0``: the initial plant state
    (default: the scenario's); ``events``: the events of the run instead of the scenario's;
    ``plant``: ``(Plant, parameters)``, the plant and its parameter vector instead of the
    scenario's plant (a campaign run's mismatched plant).

    The record: ``t, x, u, kkt, kkt_parts, status, signals, recomputed, timing_us, settings,
    events`` (one entry per sampling instant; ``x`` is the measured state, ``u`` the applied
    control, ``kkt`` the KKT measure right after feedback), ``aborted`` (None or why the
    run stopped early) and ``result``: ``{"status": "completed" | "aborted", "instants":
    finished, "instants_planned": n, "failed_instants": instants with a non-zero status,
    "first_failure": None or {"t", "message"} of the first failed feedback (for an infeasible
    QP with the stage-0 rows the measured state violates)}``.
    """
    s = _settings_of(disc, settings, changes)
    spec, duration, n_steps, M_eff, label = _scenario_of(disc, duration, s, label)
    p = _default_parameters(disc)
    if xhat0 is None:
        xhat0 = spec.x0 if spec.x0 is not None else disc.x0
    x = np.array(xhat0, dtype=float).reshape(-1)
    if x.size != int(disc.nx):
        raise SilError(f"scenario x0 has {x.size} entries, expected nx = {int(disc.nx)}")
    if plant is None:
        plant_ode = spec.plant_ode if spec.plant_ode is not None else disc.ode
        plant, plant_p = Plant(plant_ode, float(disc.dt), p.size, reltol=1e-10, abstol=1e-10), p
    else:
        plant, plant_p = plant
    events = sorted([ev for ev in (spec.events if events is None else events)
                     if float(ev.time) < duration + _ON_GRID * float(disc.dt)], key=lambda ev: float(ev.time))
    if guess is None:
        from ..reference.offline import solve_ocp
        guess, _info = solve_ocp(disc, x)
    if backend_obj is None:
        backend_obj = _make_backend_for_run(disc, backend, s)
    moving = bool(getattr(disc, "time_varying_parameters", False))
    if moving:
        # the first horizon's parameters (node k at k dt), written before init reads them
        if getattr(backend_obj, "stop", None) is not None:
            backend_obj.stop()
        backend_obj.set_parameters(disc.parameter_horizon(0.0))
    backend_obj.init(x, guess)
    rec = _Record(spec, disc)
    rec.snap = dict(getattr(backend_obj, "timings", {}) or {})
    loop = _Loop(disc, backend_obj, plant, events, p, rec, plant_p=plant_p, moving=moving)
    loop.run(x, n_steps, progress, label)
    used = getattr(backend_obj, "settings", s)     # the settings the backend runs with
    settings_rec = {"M": M_eff, "N": int(disc.N), "dt": float(disc.dt), "duration": n_steps * float(disc.dt),
                    "hessian": used.hessian, "regularization": used.regularization, "reg_eps": float(used.reg_eps),
                    "backend": backend, "real": str(getattr(backend_obj, "real", "double")),
                    "cost_hessian": used.cost_hessian,
                    "lm": float(getattr(backend_obj, "lm", 0.0 if isinstance(used.lm, str) else used.lm)),
                    "lm_setting": used.lm if isinstance(used.lm, str) else float(used.lm),
                    "qp_tol": float(used.qp_tol_of()),
                    "qp_max_iter": s.qp_max_iter,
                    "plant": "CVODES (Adams, reltol = abstol = 1e-10)",
                    "lbu": list(loop.lbu), "ubu": list(loop.ubu),
                    "u_labels": list(disc.data.control_names) or None,
                    "x_labels": list(disc.data.state_names) or None,
                    "plane": list(_plane_signals(spec)) if _plane_signals(spec) else None,
                    "units": dict(getattr(spec, "units", {}) or {})}
    if sources is not None:
        settings_rec["sources"] = dict(sources)
    run = rec.as_run(label, events, settings_rec, loop.aborted)
    run["result"] = {"status": "aborted" if loop.aborted else "completed", "instants": len(rec.status),
                     "instants_planned": n_steps,
                     "failed_instants": int(sum(1 for st in rec.status if st != 0)),
                     "first_failure": loop.first_failure,
                     "recoveries": _recoveries(backend_obj),
                     # the QP's work per instant (docs/algorithm.md section 4, feedback)
                     "qp_factorizations": _per_instant_stats(rec.qp_factorizations),
                     "qp_iterations": _per_instant_stats(rec.qp_iterations)}
    return json_ready(run)


def _per_instant_stats(values):
    """Median, 99th percentile and largest of a per-instant count (None without instants)."""
    a = np.asarray(values, dtype=float)
    if not a.size:
        return None
    return {"median": float(np.median(a)), "p99": float(np.percentile(a, 99)), "max": float(np.max(a))}


def _recoveries(backend_obj):
    """Re-initialisations by the backend's automatic recovery since its init (None if it
    does not count them)."""
    n = getattr(backend_obj, "recoveries", None)
    return None if n is None else int(n)


def _scenario_of(disc, duration, s, label):
    """The scenario, the duration, the number of sampling instants, the effective M and the
    run's label."""
    spec = disc.scenario.closed_loop
    if spec is None:
        raise SilError("the OCP declares no closed-loop scenario: call ocp.scenario(duration, events=..., "
                       "signals=...) in its build()")
    N, dt = int(disc.N), float(disc.dt)
    duration = float(spec.duration if duration is None else duration)
    if not (math.isfinite(duration) and duration > 0):
        raise SilError(f"duration must be positive and finite, got {duration}")
    n_steps = int(round(duration / dt))
    if n_steps < 1:
        raise SilError(f"duration {duration} s is shorter than one sampling interval ({dt} s)")
    M_eff = s.stages(N)
    if label is None:
        label = "full RTI" if M_eff == N - 1 else f"DOPUS M = {M_eff}"
    return spec, duration, n_steps, M_eff, label


def _make_backend_for_run(disc, backend, s):
    try:
        return make_backend(disc, backend, s)
    except SilError:
        raise
    except Exception as exc:  # noqa: BLE001 - settings rejected, C build failed, ...
        raise SilError(f"cannot set up the {backend} backend: {exc}") from None


class _Record:
    """What the loop records, one entry per finished sampling instant."""

    def __init__(self, spec, disc):
        self.spec = spec
        self.t, self.x, self.u, self.kkt, self.parts, self.status, self.recomputed = [], [], [], [], [], [], []
        self.signals = {name: [] for name in spec.signals}
        self.qp_iterations = []
        self.qp_factorizations = []
        self.qp_cold_retry = []
        self.timing: dict[str, list] = {"feedback": [], "prepare": [], "total": []}
        self.phase_timing: dict[str, list] = {}  # the backend's own phase timers
        self.snap: dict = {}
        from .soft import soft_groups

        self.disc = disc
        self.soft_groups = soft_groups(disc) if getattr(disc, "has_soft", False) else []
        self.soft: dict[str, list] = {g[0]: [] for g in self.soft_groups}

    def measurement(self, t_i, xhat, u0, kkt, p):
        self.t.append(t_i)
        self.x.append(xhat)
        self.u.append(u0.copy())
        self.kkt.append(float(kkt["kkt"]))
        self.parts.append({k: float(kkt[k]) for k in ("stat", "eq", "ineq", "comp", "rel") if k in kkt})
        for name, fn in self.spec.signals.items():
            self.signals[name].append(_eval(fn, xhat, u0, p))
        if self.soft_groups:
            from .soft import violations

            for label, v in violations(self.disc, self.soft_groups, xhat, u0, p).items():
                self.soft[label].append(v)

    def instant_done(self, i, status, recomputed, t_fb, t_pr, phases):
        self.status.append(int(status))
        self.recomputed.append(recomputed)
        self.timing["feedback"].append(t_fb * 1e6)
        self.timing["prepare"].append(t_pr * 1e6)
        self.timing["total"].append((t_fb + t_pr) * 1e6)
        _record_phases(self.phase_timing, phases, i)

    def drop_unfinished(self):
        """Drop a half-recorded instant so that all arrays have one entry per finished instant."""
        n = len(self.status)
        self.t, self.x, self.u, self.kkt, self.parts = (a[:n] for a in (self.t, self.x, self.u, self.kkt, self.parts))
        self.signals = {k: v[:n] for k, v in self.signals.items()}
        self.soft = {k: v[:n] for k, v in self.soft.items()}

    def as_run(self, label, events, settings_rec, aborted) -> dict:
        return {
            "label": label,
            "t": self.t,
            "x": [list(v) for v in self.x],
            "u": [list(v) for v in self.u],
            "kkt": self.kkt,
            "kkt_parts": self.parts,
            "status": self.status,
            "signals": {k: [float(v[0]) if v.size == 1 else list(v) for v in vals]
                        for k, vals in self.signals.items()},
            "recomputed": self.recomputed,
            "qp_iterations": self.qp_iterations[:len(self.status)],
            "qp_factorizations": self.qp_factorizations[:len(self.status)],
            "qp_cold_retry": self.qp_cold_retry[:len(self.status)],
            "timing_us": {"feedback": self.timing["feedback"], "prepare": self.timing["prepare"],
                          "total": self.timing["total"],
                          **{f"phase:{k}": v for k, v in self.phase_timing.items()}},
            "events": [{"time": float(ev.time), "label": str(ev.label)} for ev in events],
            # soft rows (docs/algorithm.md section 12): the violation of each group at the
            # measured state and the applied control, per instant
            "soft_violation": {k: list(v) for k, v in self.soft.items()},
            "settings": settings_rec,
            "aborted": aborted,
        }


class _Loop:
    """The receding-horizon loop of the module docstring, one method per step of an instant."""

    def __init__(self, disc, ctrl, plant, events, p, rec: _Record, plant_p=None, moving=False):
        self.ctrl, self.plant, self.events, self.p, self.rec = ctrl, plant, events, p, rec
        self.plant_p = p if plant_p is None else plant_p
        # parameters that move (a trajectory in the OCP file): the instant's values for the
        # plant and the signals, and the new last node pushed before every prepare
        self.moving = moving
        self.memory = tuple(getattr(disc.spec.model, "memory", ()) or ())
        self.p_fixed, self.plant_p_fixed = self.p, self.plant_p
        self.nx, self.dt = int(disc.nx), float(disc.dt)
        self.lbu = np.asarray(disc.lbu, dtype=float).reshape(-1)
        self.ubu = np.asarray(disc.ubu, dtype=float).reshape(-1)
        self.ev_idx = 0
        self.aborted = None
        self.disc = disc
        self.first_failure = None   # {"t", "message"} of the first failed feedback

    def run(self, x, n_steps, progress, label):
        bar = None
        t_start = time.perf_counter()
        try:
            for i in range(n_steps):
                x = self.instant(i, x)
                interrupt.check()   # a Ctrl-C that a CasADi call of the instant swallowed
                if progress and bar is None and time.perf_counter() - t_start > _PROGRESS_AFTER:
                    import click
                    bar = click.progressbar(length=n_steps, label=f"{label:>12}", file=sys.stderr,
                                            show_eta=True, show_percent=True)
                    bar.__enter__()
                    bar.update(i + 1)
                elif bar is not None:
                    bar.update(1)
        except PlantError as err:
            self.aborted = (f"plant failed at t = {len(self.rec.t) * self.dt:.4g} "
                            f"{time_unit(self.disc.scenario.closed_loop.units)}: {err}")
            self.rec.drop_unfinished()
        finally:
            if bar is not None:
                bar.__exit__(None, None, None)

    def instant(self, i, x):
        """One sampling instant: events, measurement, feedback, KKT, plant, prepare."""
        t_i = i * self.dt
        if self.moving:
            self.p = self._parameters_at(t_i)
            n_p = self.p.size
            self.plant_p = np.concatenate([self.p, np.asarray(self.plant_p_fixed, dtype=float)[n_p:]])
        x = self.events_until(x, t_i + _ON_GRID * self.dt)
        xhat = x.copy()
        u0, status, t_fb = self.feedback(xhat)
        if status != 0 and self.first_failure is None:
            self.first_failure = {"t": t_i, "message": self._failure_text(xhat)}
        self.rec.qp_iterations.append(int(getattr(self.ctrl, "qp_iterations", 0) or 0))
        self.rec.qp_factorizations.append(int(getattr(self.ctrl, "qp_factorizations", 0) or 0))
        self.rec.qp_cold_retry.append(bool(getattr(self.ctrl, "qp_cold_retry", False)))
        phases = _split_phases("feedback", _changed(self.rec.snap, dict(getattr(self.ctrl, "timings", {}) or {})))
        kkt, status = self.kkt(xhat, status)
        # A backend may time its KKT evaluation too; that is not part of the iteration.
        snap_fb = dict(getattr(self.ctrl, "timings", {}) or {})
        self.rec.measurement(t_i, xhat, u0, kkt, self.p)
        x = self.plant_interval(x, u0, t_i, (i + 1) * self.dt)
        for row, ctrl in self.memory:    # rate constraints: the memory holds the applied control
            x[row] = u0[ctrl]
        if self.moving:
            status = self.push((i + 1) * self.dt + int(self.disc.N) * self.dt, status)
        status, prepared, t_pr = self.prepare(status)
        self.rec.snap = dict(getattr(self.ctrl, "timings", {}) or {})
        phases.update(_split_phases("prepare", _changed(snap_fb, self.rec.snap)))
        recomputed = [int(k) for k in getattr(self.ctrl, "recomputed", [])] if prepared else []
        self.rec.instant_done(i, status, recomputed, t_fb, t_pr, phases)
        return x

    def _parameters_at(self, t):
        from ..problem.spec import TrajectoryError

        try:
            return np.asarray(self.disc.parameters_at(t), dtype=float).reshape(-1)
        except TrajectoryError as exc:
            raise SilError(str(exc)) from None

    def push(self, t_last, status):
        """The parameters of the next horizon's last node (time ``t_last``), before prepare."""
        try:
            self.ctrl.push_parameters(self._parameters_at(t_last))
        except DopusError as err:
            status = status or _status_of(err)
        return status

    def events_until(self, x, t_end):
        """Apply the events due at an instant (time <= t_end) to the plant state."""
        while self.ev_idx < len(self.events) and float(self.events[self.ev_idx].time) <= t_end:
            x = _apply_event(self.events[self.ev_idx], x, self.nx)
            self.ev_idx += 1
        return x

    def feedback(self, xhat):
        """The control of the instant (timed): the runtime's returned control whatever the
        status (:func:`.loops.feedback`); a failure is recorded, the loop goes on."""
        fb = loops.feedback(self.ctrl, xhat)
        self.last_error = fb.error
        return fb.u0, fb.status, fb.seconds

    def _failure_text(self, xhat) -> str:
        """Why the feedback of an instant failed; for an infeasible QP, with the stage-0 rows
        the measured state violates."""
        err = self.last_error
        if err is None:
            return "the feedback returned a non-finite control"
        text = str(err)
        if getattr(err, "qp_status_name", None) == "primal_infeasible":
            from ..problem.checks import stage0_violations

            try:
                rows = stage0_violations(self.disc, xhat, self.p)
            except Exception:  # noqa: BLE001 - the note is a help, never a second failure
                rows = []
            if rows:
                text += "; the measured state violates at stage 0: " + "; ".join(rows)
        return text

    def kkt(self, xhat, status):
        try:
            return self.ctrl.kkt(xhat), status
        except DopusError as err:
            # A non-finite iterate has no KKT measure; the instant counts as failed.
            return {"kkt": math.nan}, status or _status_of(err)

    def plant_interval(self, x, u0, t_i, t_next):
        """The plant over [t_i, t_next] with u0 held, split at events strictly inside."""
        t_cur = t_i
        while self.ev_idx < len(self.events) and float(self.events[self.ev_idx].time) < t_next - _ON_GRID * self.dt:
            te = float(self.events[self.ev_idx].time)
            x = self.plant.step(x, u0, self.plant_p, duration=te - t_cur)
            x = _apply_event(self.events[self.ev_idx], x, self.nx)
            t_cur = te
            self.ev_idx += 1
        return self.plant.step(x, u0, self.plant_p, duration=t_next - t_cur)

    def prepare(self, status):
        st, seconds = loops.prepare(self.ctrl)
        return status or st, st == 0, seconds


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


def time_unit(units) -> str:
    """The unit of the model's time in a scenario's ``units`` (a mapping or pairs), else
    ``"s"``."""
    return dict(units or {}).get("time", "s")


def summarize(run, settle: float = 0.2) -> dict:
    """Figures of the summary table for one run.

    ``settle``: seconds after the start and after each event during which the KKT measure is
    not counted in "max KKT after settling". A scalar signal's ``min`` and ``max`` are its
    signed extremes over a stretch (a signal that is negative when all is well, "temperature
    above its limit", keeps its sign), ``rms`` its root mean square; ``recoveries`` the
    runtime's automatic re-initialisations (None: the backend does not count them).
    """
    t = np.asarray(run["t"], dtype=float)
    out = {"label": run["label"], "segments": [], "aborted": run.get("aborted"),
           "time_unit": time_unit(run.get("settings", {}).get("units")),
           "first_failure": (run.get("result") or {}).get("first_failure")}
    for name, vals in run["signals"].items():
        v = np.asarray([np.nan if a is None else a for a in vals], dtype=float)
        if v.ndim != 1:
            continue
        for seg, mask in _segments(run):
            vs = v[mask]
            out["segments"].append({"signal": name, "segment": seg,
                                    "min": float(np.min(vs)) if vs.size else math.nan,
                                    "max": float(np.max(vs)) if vs.size else math.nan,
                                    "rms": float(np.sqrt(np.mean(vs ** 2))) if vs.size else math.nan})
    kkt = np.asarray([np.nan if a is None else a for a in run["kkt"]], dtype=float)
    settled = t >= settle
    for ev in run["events"]:
        settled &= ~((t >= ev["time"]) & (t < ev["time"] + settle))
    out["settle"] = settle
    ks = kkt[settled & np.isfinite(kkt)]
    out["kkt_max_settled"] = float(np.max(ks)) if ks.size else math.nan
    rel = np.asarray([math.nan if p.get("rel") is None else p["rel"] for p in run.get("kkt_parts", [])] or
                     [math.nan] * kkt.size, dtype=float)
    rs = rel[settled & np.isfinite(rel)] if rel.size == kkt.size else np.zeros(0)
    out["kkt_rel_max_settled"] = float(np.max(rs)) if rs.size else math.nan
    out["kkt_nonfinite"] = int(np.count_nonzero(~np.isfinite(kkt)))
    out["qp_failures"] = int(np.count_nonzero(np.asarray(run["status"]) != 0))
    out["recoveries"] = (run.get("result") or {}).get("recoveries")
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
    out["soft_violation"] = {k: float(max(v, default=0.0)) for k, v in (run.get("soft_violation") or {}).items()}
    # the QP's work per instant: factorisations of the Riccati recursion and interior-point
    # iterations (median, 99th percentile and largest over the instants)
    for key in ("qp_factorizations", "qp_iterations"):
        out[key] = _per_instant_stats(run.get(key) or [])
    return out


def _num(v, fmt: str) -> str:
    """A number of the summary, or '-' right-aligned where there is none (no instant of a
    stretch, an aborted run)."""
    width = int(fmt.split(".")[0].rstrip("d"))
    return f"{v:{fmt}}" if isinstance(v, (int, float)) and math.isfinite(v) else f"{'-':>{width}}"


def format_summary(summaries) -> str:
    """The summary table of one or more runs as text."""
    lines = []
    sig_rows = [(s["label"], seg) for s in summaries for seg in s["segments"]]
    if sig_rows:
        w_run = max(len("run"), *(len(r) for r, _ in sig_rows))
        w_sig = max(len("signal"), *(len(seg["signal"]) for _, seg in sig_rows))
        w_seg = max(len("stretch"), *(len(seg["segment"]) for _, seg in sig_rows))
        head = (f"{'run':<{w_run}}  {'signal':<{w_sig}}  {'stretch':<{w_seg}}  {'min':>10}  {'max':>10}  "
                f"{'RMS':>10}")
        lines += [head, "-" * len(head)]
        for r, seg in sig_rows:
            lines.append(f"{r:<{w_run}}  {seg['signal']:<{w_sig}}  {seg['segment']:<{w_seg}}  "
                         f"{_num(seg['min'], '10.3e')}  {_num(seg['max'], '10.3e')}  {_num(seg['rms'], '10.3e')}")
        lines.append("(min, max: the signal's signed extremes over the stretch; RMS: its root mean square)")
        lines.append("")
    w_run = max([len("run")] + [len(s["label"]) for s in summaries])
    head = (f"{'run':<{w_run}}  {'max KKT settled':>15}  {'max rel KKT':>11}  {'QP fail':>7}  {'recoveries':>10}  {'u bound viol':>12}  "
            f"{'median it [us]':>14}  {'max it [us]':>11}  {'median fb [us]':>14}")
    lines += [head, "-" * len(head)]
    for s in summaries:
        lines.append(f"{s['label']:<{w_run}}  {_num(s['kkt_max_settled'], '15.3e')}  "
                     f"{_num(s.get('kkt_rel_max_settled'), '11.3e')}  {s['qp_failures']:7d}  "
                     f"{_num(s.get('recoveries'), '10d')}  "
                     f"{_num(s['bound_violation'], '12.2e')}  {_num(s['time_median_us'], '14.1f')}  "
                     f"{_num(s['time_max_us'], '11.1f')}  {_num(s['feedback_median_us'], '14.1f')}")
    if summaries:
        lines.append(f"(max KKT settled: excluding the first {summaries[0]['settle']} {summaries[0]['time_unit']} "
                     "after the start "
                     f"and after each event; rel KKT: the relative measure, docs/algorithm.md section 6; "
                     "it = feedback + prepare, fb = feedback alone)")
    for s in summaries:
        f, it = s.get("qp_factorizations"), s.get("qp_iterations")
        if f and it:
            lines.append(f"{s['label']}: QP factorisations per instant median {f['median']:g}, 99th percentile "
                         f"{f['p99']:g}, max {f['max']:g}; QP iterations (active-set sweeps and interior-point "
                         f"iterations) median {it['median']:g}, "
                         f"99th percentile {it['p99']:g}")
    for s in summaries:
        if s.get("soft_violation"):
            lines.append(f"{s['label']}: largest violation of the soft rows (measured state, applied control): "
                         + ", ".join(f"{k} {v:.3g}" for k, v in s["soft_violation"].items()))
    for s in summaries:
        if s.get("first_failure"):
            ff = s["first_failure"]
            lines.append(f"{s['label']}: first failed instant at t = {ff['t']:.4g} {s['time_unit']}: {ff['message']}")
        if s.get("aborted"):
            lines.append(f"{s['label']}: ABORTED: {s['aborted']}")
    return "\n".join(lines)


def write_json(runs, path) -> None:
    path = Path(path)
    if path.parent and not path.parent.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
    from ..outputs import write_text

    write_text(path, json.dumps({"runs": runs}, allow_nan=False) + "\n")


# --------------------------------------------------------------------------- CLI
def run_sil_cli(ocp_file, M=None, duration=None, json_out=None, plot_dir=None, compare="none", backend="c",
                echo=None, progress=True, real=None, campaign_run=None, seed=None, **flags) -> list:
    """The ``dopus-gen sil`` command: runs, summary table, JSON and plots. ``M`` and
    ``flags`` are the settings given on the command line (None: not given); the others come
    from the OCP file's ``options(...)``, else from the defaults of
    :mod:`dopus_codegen.settings`; the summary and the JSON say where each came from. The
    output paths and the scenario's initial state are checked before any run starts.

    ``campaign_run``: replay run ``campaign_run`` of the OCP file's campaign for ``seed``
    (default 0) with the file's mismatch: its initial state, pushes (instead of the
    scenario's events) and plant (:mod:`.campaign`); the duration stays the scenario's
    unless given."""
    from ..outputs import check_output_dir, check_output_file
    from ..problem.checks import check_initial_state
    from ..problem.ocp import load_ocp
    from ..problem.derivatives import build_functions

    if json_out:
        check_output_file(json_out, "--json")
    if plot_dir:
        check_output_dir(plot_dir, "--plot-dir")

    if echo is None:
        import click
        echo = click.echo

    ocp = load_ocp(ocp_file)
    declared = ocp.declared_options()
    try:
        real_value, real_source = settings.resolve(declared, {"real": real}, names=("real",))
        s, sources = settings.Settings.resolve(declared, dict(flags, M=M), real=real_value["real"])
    except settings.SettingError as exc:
        raise SilError(f"{ocp_file}: {exc}") from None
    values = dict({k: v for k, v in s.as_dict().items() if k != "mode"}, **real_value)
    sources.update(real_source)
    if values["real"] != settings.DEFAULTS["real"] and backend != "c":
        raise SilError(f"--real {values['real']} needs --backend c (the reference backend computes in double)")
    ocp.options(real=values["real"])    # the C backend is generated in this type
    disc = build_functions(ocp)
    if disc.scenario.closed_loop is None:
        raise SilError(f"{ocp_file}: the OCP declares no closed-loop scenario (ocp.scenario(...))")
    if s.hessian == "gauss-newton" and not disc.functions.has_gn:
        raise SilError(f"{ocp_file}: --hessian gauss-newton needs a least-squares stage cost "
                       "(ocp.stage_least_squares)")
    spec = disc.scenario.closed_loop
    x0 = np.array(spec.x0 if spec.x0 is not None else disc.x0, dtype=float).reshape(-1)
    echo(f"settings: {settings.describe(values, sources)}", err=True)
    check_initial_state(disc, x0, "the scenario's initial state")
    replay = {}
    if campaign_run is not None:
        from .draws import campaign_events, campaign_plant, draw

        if spec.campaign is None:
            raise SilError(f"{ocp_file}: --campaign-run needs a campaign declared in the OCP file (ocp.campaign(...))")
        d = draw(spec, dict(spec.campaign.mismatch), int(campaign_run), int(seed or 0))
        replay = dict(xhat0=d["x0"], events=campaign_events(d), plant=campaign_plant(disc, d))
        echo(f"campaign run {campaign_run} (seed {seed or 0}): plant quantities "
             + ", ".join(f"{k} = {v:.6g}" for k, v in d["quantities"].items())
             + f"; {len(d['pushes'])} pushes at " + ", ".join(f"{p['time']:.4g} {time_unit(spec.units)}"
                                                              for p in d["pushes"]), err=True)

    from ..reference.offline import solve_ocp
    guess, info = solve_ocp(disc, x0)
    if not info.get("success", True):
        echo(f"warning: the offline solve at the initial state did not converge ({info.get('status')}); "
             "the controller starts from its last iterate", err=True)

    N = int(disc.N)
    configs = [(s, None, sources)]
    if compare == "full" and s.stages(N) != N - 1:
        configs.append((s.replace(M=N - 1), "full RTI", dict(sources, M=settings.SOURCE_CLI)))  # --compare full
    runs = []
    for run_settings, label, src in configs:
        m = run_settings.stages(N)
        name = label or ("full RTI" if m == N - 1 else f"DOPUS M = {m}")
        echo(f"{name}: {backend} backend, {s.hessian} Hessian, regularization {s.regularization}, "
             f"cost Hessian {s.cost_hessian}, Levenberg-Marquardt {s.lm}, "
             f"{duration if duration is not None else spec.duration} {time_unit(spec.units)} ...", err=True)
        run = run_closed_loop(disc, backend=backend, settings=run_settings, duration=duration, guess=guess,
                              progress=progress, label=label, sources=src, **replay)
        runs.append(run)
    summaries = [summarize(r) for r in runs]
    echo(format_summary(summaries))
    for r in runs:
        st = r["settings"]
        names = [k for k in settings.RUNTIME_SETTINGS if k in st and k in st["sources"]]
        shown = {k: st[k] for k in names}
        if "lm" in shown and st.get("lm_setting") == "auto":     # the setting, and the value it reached
            shown["lm"] = f"auto (now {st['lm']:g})"
        echo(f"{r['label']}: " + settings.describe(shown, st["sources"]))
    if json_out:
        write_json(runs, json_out)
        echo(f"JSON: {json_out}")
    if plot_dir:
        from .plots import plot_sil
        files = plot_sil(runs, plot_dir, title=getattr(disc, "name", None))
        echo(f"plots: {Path(plot_dir).resolve()} ({len(files)} PNG)")
    return runs
