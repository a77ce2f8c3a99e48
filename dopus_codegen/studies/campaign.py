"""Monte Carlo campaign: many closed-loop SIL runs with random starts, pushes and plant mismatch.

Run ``i`` of a campaign with seed ``s`` is the closed loop of :func:`.sil.run_closed_loop` (C
backend, CVODES plant) with the random draw of :func:`draw` for ``(s, i)``, a pure function of
the pair: every quantity the OCP file declares with ``Ocp.plant_quantity`` and mismatches with
``Ocp.campaign(mismatch=...)`` is scaled by a factor uniform in ``[1 - r, 1 + r]``, the
scenario's initial state gets uniform offsets (``initial``), and the scenario's own events are
replaced by the pushes (``Pushes``: a random number of them, at random times, each adding
uniform offsets to some states). The controller starts from the offline solution at the
scenario's nominal initial state (solved once), as a deployed controller would.

A run is **on the path** (``OnPath``) when the plant could be integrated to the end and the
scalar signal named by the file (the robot arm: the distance of the tip to the circle), taken
with its sign, is at or below ``threshold`` at every sampling instant from ``settle`` seconds after the start and
after every push (the instants inside ``[t_push, t_push + settle)`` are not judged).

The runs are distributed with dask.distributed (a LocalCluster, or the scheduler the caller
names); the C solver is generated and built once, before the runs are distributed. Every
finished run is appended to a JSON-lines result file at once: its first line describes the
campaign (a fingerprint of everything that changes a run, except the seed and the number
of runs), every other line is one run keyed by ``"run"`` and ``"seed"``. A campaign started
again on the same file computes only the runs it lacks; at the end the file is rewritten
sorted by seed and run, so an interrupted and resumed campaign gives the same file as an
uninterrupted one, except the measured times (``"time"``) of each run.

A run's line: ``run``, ``seed``, ``draw`` (``quantities``, ``x0``, ``pushes``: ``time`` and
``kick``), ``on_path``, ``max_deviation`` (the largest value of the signal, signed, over the
judged instants), ``max_deviation_all`` (over all instants), ``failed_instants`` (instants whose feedback failed: QP failures),
``recoveries`` (re-initialisations of the runtime's automatic recovery), ``first_failure``,
``aborted``, ``instants``, ``instants_planned``, ``final_x``, ``signal`` (the on-path
signal at every instant) and ``time`` (``median_us``, ``p99_us``, ``max_us`` of feedback +
prepare, ``feedback_median_us``, ``run_s``: the run's wall time).
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .. import interrupt, settings
from ..outputs import atomic_file, save_figure, write_text
from .draws import campaign_events, campaign_plant, draw
from .records import json_ready

__all__ = ["CampaignError", "Job", "draw", "run_one", "judge", "read_results", "run_campaign", "format_report",
           "campaign_plant", "campaign_events"]

#: The version of the result file's layout (in its first line). 2: the on-path signal is
#: judged with its sign (1: its absolute value).
FORMAT = 2
#: Seconds without a dask worker after which a campaign stops (``--worker-timeout``).
WORKER_TIMEOUT = 60.0


class CampaignError(RuntimeError):
    """A campaign could not be set up (bad settings, an unreachable scheduler, a result file
    of another campaign)."""


# --------------------------------------------------------------------------- the job
@dataclass(frozen=True)
class Job:
    """Everything a worker needs for a run; picklable. ``lib_dir``: the C solver built by
    the caller (a worker that does not see the folder builds its own from the OCP file)."""
    ocp_path: str
    ocp_text: str
    lib_dir: str
    backend: str
    solver: dict            # M, hessian, regularization, reg_eps, cost_hessian, lm, qp_tol, qp_max_iter
    duration: float
    mismatch: dict          # plant quantity -> relative half-width
    on_path: tuple          # (signal, threshold, settle)
    guess: object = field(compare=False)
    fingerprint: str = ""


def _fingerprint(ocp_text: str, backend: str, solver: dict, duration: float, mismatch: dict, on_path: tuple,
                 campaign_spec) -> str:
    """A hash of everything that changes a run except the seed and the run index."""
    cs = campaign_spec
    blob = json.dumps({"format": FORMAT, "ocp": hashlib.sha256(ocp_text.encode()).hexdigest(), "backend": backend,
                       "solver": {k: solver[k] for k in sorted(solver)}, "duration": float(duration),
                       "mismatch": {k: float(v) for k, v in sorted(mismatch.items())},
                       "on_path": list(on_path),
                       "initial": [list(r) + list(w) for r, w in cs.initial],
                       "pushes": [list(cs.push_count), list(cs.push_window),
                                  [list(r) + list(w) for r, w in cs.push_kick]]},
                      sort_keys=True, default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:24]


# --------------------------------------------------------------------------- one run (in a worker)
_STATE: dict = {}
_GUESS: dict = {}       # the offline solution of the last OCP file, in the calling process


def _worker_state(job: Job):
    """The problem and the backend of ``job`` in this process, set up once per campaign."""
    st = _STATE.get(job.fingerprint)
    if st is not None:
        return st
    from ..problem.derivatives import build_functions
    from ..problem.ocp import load_ocp

    path = Path(job.ocp_path)
    if not (path.is_file() and path.read_text() == job.ocp_text):
        # a worker on another machine: the OCP file as the caller read it
        folder = Path(tempfile.mkdtemp(prefix="dopus_campaign_"))
        path = folder / Path(job.ocp_path).name
        path.write_text(job.ocp_text)
    disc = build_functions(load_ocp(path))
    _STATE.clear()
    st = _STATE[job.fingerprint] = {"disc": disc, "backend": _backend(job, disc)}
    return st


def _backend(job: Job, disc):
    from .sil import make_backend

    s = settings.Settings.of(job.solver)
    if job.backend == "c":
        from ..runtime.solver import Solver, build_for

        lib = Path(job.lib_dir) if job.lib_dir and Path(job.lib_dir).is_dir() else build_for(disc)
        return Solver(disc, s.replace(mode="receding"), lib_dir=lib)
    return make_backend(disc, job.backend, s)


def run_one(job: Job, index: int, seed: int) -> dict:
    """Run ``index`` of the campaign for ``seed``: the closed loop and its condensed result
    (one line of the result file)."""
    from .sil import run_closed_loop

    st = _worker_state(job)
    disc = st["disc"]
    d = draw(disc.scenario.closed_loop, job.mismatch, index, seed)
    t0 = time.perf_counter()
    run = run_closed_loop(disc, backend=job.backend, backend_obj=st["backend"], guess=job.guess,
                          duration=job.duration, xhat0=d["x0"], events=campaign_events(d),
                          plant=campaign_plant(disc, d), settings=settings.Settings.of(job.solver), label=f"run {index}")
    wall = time.perf_counter() - t0
    return condense(run, d, index, seed, job.on_path, wall)


def _signed(signal) -> np.ndarray:
    """The values of a scalar signal, signed; a missing or non-finite value counts as +inf
    (never on the path)."""
    v = np.asarray([np.inf if a is None else a for a in signal], dtype=float)
    v[~np.isfinite(v)] = np.inf
    return v


def judge(t, signal, pushes, on_path, completed: bool) -> tuple:
    """``(on the path, max signal over the judged instants)`` of a run: the instants from
    ``settle`` s after the start and outside ``[t_push, t_push + settle)`` for every push.
    The signal is taken with its sign: ``OnPath`` asks it to stay at or below the threshold
    (a distance is never negative; "temperature above its limit" is negative when all is
    well)."""
    _, threshold, settle = on_path
    t = np.asarray(t, dtype=float)
    v = _signed(signal)
    tol = 1e-9
    judged = t >= settle - tol
    for tp in pushes:
        judged &= ~((t >= tp - tol) & (t < tp + settle - tol))
    worst = float(np.max(v[judged])) if np.any(judged) else 0.0
    return bool(completed and worst <= threshold), worst


def condense(run: dict, d: dict, index: int, seed: int, on_path: tuple, wall: float) -> dict:
    """One line of the result file from a run of :func:`.sil.run_closed_loop`."""
    name = on_path[0]
    res = run["result"]
    completed = res["status"] == "completed" and res["instants"] == res["instants_planned"]
    pushes = [p["time"] for p in d["pushes"] if p["time"] < run["settings"]["duration"]]
    ok, worst = judge(run["t"], run["signals"][name], pushes, on_path, completed)
    sig = _signed(run["signals"][name])
    tot = np.asarray(run["timing_us"]["total"], dtype=float)
    fb = np.asarray(run["timing_us"]["feedback"], dtype=float)
    q = lambda a, p: float(np.percentile(a, p)) if a.size else None  # noqa: E731
    line = {"run": int(index), "seed": int(seed), "draw": d, "on_path": ok,
            "max_deviation": worst, "max_deviation_all": float(np.max(sig)) if sig.size else None,
            "failed_instants": int(res["failed_instants"]), "recoveries": res.get("recoveries"),
            "first_failure": res.get("first_failure"), "aborted": run.get("aborted"),
            "instants": int(res["instants"]), "instants_planned": int(res["instants_planned"]),
            "final_x": run["x"][-1] if run["x"] else None, "signal": run["signals"][name],
            "soft_violation": {k: float(max(v, default=0.0)) for k, v in (run.get("soft_violation") or {}).items()},
            "time": {"median_us": q(tot, 50), "p99_us": q(tot, 99), "max_us": float(np.max(tot)) if tot.size else None,
                     "feedback_median_us": q(fb, 50), "run_s": float(wall)}}
    return json_ready(line)


# --------------------------------------------------------------------------- the result file
def _header(job: Job, name: str) -> dict:
    return {"campaign": job.fingerprint, "format": FORMAT, "ocp": name, "ocp_file": job.ocp_path,
            "backend": job.backend, "solver": job.solver, "duration": job.duration, "mismatch": job.mismatch,
            "on_path": {"signal": job.on_path[0], "threshold": job.on_path[1], "settle": job.on_path[2]}}


_NUMBER, _INT, _TEXT, _NULL = "number", "integer", "text", "null"
#: The fields of a run's line: the JSON types each may have.
_LINE_FIELDS = {
    "run": (_INT,), "seed": (_INT,), "draw": (dict,), "on_path": (bool,), "max_deviation": (_NUMBER, _NULL),
    "max_deviation_all": (_NUMBER, _NULL), "failed_instants": (_INT,), "recoveries": (_INT, _NULL),
    "first_failure": (dict, _NULL), "aborted": (_TEXT, _NULL), "instants": (_INT,), "instants_planned": (_INT,),
    "final_x": (list, _NULL), "signal": (list,), "time": (dict,),
}
_TIME_FIELDS = {"median_us": (_NUMBER, _NULL), "p99_us": (_NUMBER, _NULL), "max_us": (_NUMBER, _NULL),
                "feedback_median_us": (_NUMBER, _NULL), "run_s": (_NUMBER,)}
_DRAW_FIELDS = {"quantities": (dict,), "x0": (list,), "pushes": (list,)}


def _is(value, kinds) -> bool:
    for kind in kinds:
        if kind == _NULL and value is None:
            return True
        if kind == _INT and type(value) is int and value >= 0:
            return True
        if kind == _NUMBER and type(value) in (int, float):
            return True
        if kind == _TEXT and isinstance(value, str):
            return True
        if isinstance(kind, type) and type(value) is kind:
            return True
    return False


def _fields_problem(obj, fields: dict, where: str = ""):
    for name, kinds in fields.items():
        if name not in obj:
            return f"no field '{where}{name}'"
        if not _is(obj[name], kinds):
            return f"field '{where}{name}' is {json.dumps(obj[name])[:40]}"
    return None


def line_problem(obj):
    """Why ``obj`` (a parsed line of the result file) is not a run's line, or None."""
    if not isinstance(obj, dict):
        return "not a JSON object"
    why = _fields_problem(obj, _LINE_FIELDS) or _fields_problem(obj["time"], _TIME_FIELDS, "time.") \
        or _fields_problem(obj["draw"], _DRAW_FIELDS, "draw.")
    if why is None and obj["instants"] > obj["instants_planned"]:
        why = "more instants than planned"
    if why is None and not all(type(v) in (int, float) for v in obj["draw"]["quantities"].values()):
        why = "field 'draw.quantities' holds a value that is not a number"
    return why


def _header_problem(obj):
    """Why ``obj`` (the parsed first line) is not the header of a result file, or None."""
    if not isinstance(obj, dict):
        return "not a JSON object"
    if not isinstance(obj.get("campaign"), str) or not obj["campaign"]:
        return "no campaign fingerprint"
    if obj.get("format") != FORMAT or type(obj.get("format")) is not int:
        return f"format {obj.get('format')!r}, this version reads format {FORMAT}"
    return None


@dataclass
class Results:
    """A result file as read: ``header`` (None for a missing or empty file, or a damaged
    header: ``header_problem`` says why), ``lines`` ``{(seed, run): line}``, ``malformed``
    ``[(line number, why)]``: the lines that are not a run's line (cut short by an
    interruption, missing or mistyped fields); they are dropped, so their runs are
    computed again."""
    header: object = None
    lines: dict = field(default_factory=dict)
    malformed: list = field(default_factory=list)
    header_problem: object = None


def read_results(path) -> Results:
    """The result file at ``path`` (:class:`Results`; empty for a missing or empty file)."""
    p = Path(path)
    res = Results()
    if not p.exists() or p.stat().st_size == 0:
        return res
    with open(p, "rb") as fh:
        for k, raw in enumerate(fh):
            try:
                obj = json.loads(raw.decode("utf-8"))
            except ValueError:
                obj, why = None, "cut short" if not raw.endswith(b"\n") else "not JSON"
            else:
                why = None
            if k == 0:
                res.header_problem = why or _header_problem(obj)
                res.header = obj if res.header_problem is None else None
                continue
            why = why or line_problem(obj)
            if why is not None:
                res.malformed.append((k + 1, why))
                continue
            res.lines.setdefault((obj["seed"], obj["run"]), obj)
    return res


def _malformed_text(path, malformed: list) -> str:
    shown = "; ".join(f"line {n}: {why}" for n, why in malformed[:5])
    more = f"; and {len(malformed) - 5} more" if len(malformed) > 5 else ""
    return (f"warning: '{path}' has {len(malformed)} malformed line{'s' if len(malformed) > 1 else ''} "
            f"({shown}{more}); dropped, their runs are computed again")


def _dump(obj) -> str:
    return json.dumps(obj, sort_keys=True, allow_nan=False)


def _append(fd: int, text: str) -> None:
    """One complete line at the end of the file open at ``fd`` (O_APPEND)."""
    data = text.encode("utf-8")
    while data:
        data = data[os.write(fd, data):]


def _rewrite(path, header: dict, lines: dict) -> None:
    """The result file with ``header`` and ``lines`` sorted by (seed, run), replaced atomically."""
    with atomic_file(path) as fh:
        fh.write(_dump(header) + "\n")
        for key in sorted(lines):
            fh.write(_dump(lines[key]) + "\n")


# --------------------------------------------------------------------------- distribution
def _in_process(job, todo, seed, on_result, on_error):
    for i in todo:
        try:
            on_result(run_one(job, i, seed))
        except Exception as exc:  # noqa: BLE001 - reported with the run index
            on_error(i, exc)


def connect(workers: int | None, scheduler: str | None, timeout: float = 5.0):
    """A dask client: on the scheduler at ``scheduler``, else on a new LocalCluster of
    ``workers`` single-threaded worker processes (default: one per core)."""
    import logging

    try:
        from dask.distributed import Client, LocalCluster
    except ImportError as exc:  # pragma: no cover - a dependency of the package
        raise CampaignError(f"dask.distributed is not installed ({exc}): pip install 'dopus-codegen[campaign]', "
                            "or run the campaign in this process with --workers 0") from None
    if scheduler:
        try:
            return Client(scheduler, timeout=f"{timeout}s"), None
        except (OSError, TimeoutError, ValueError) as exc:
            raise CampaignError(f"cannot reach the dask scheduler at '{scheduler}': {exc}") from None
    n = workers or os.cpu_count() or 1
    cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                           silence_logs=logging.ERROR, preload=[__name__])
    return Client(cluster), cluster


def dask_setup(worker) -> None:
    """The preload of the local cluster's workers: they ignore Ctrl-C, which a terminal
    sends to the whole process group; the campaign stops them."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


class _NoWorker(Exception):
    """The dask cluster lost its workers (or its scheduler) for longer than allowed."""


def _distributed(client, job, todo, seed, on_result, on_error, worker_timeout: float = WORKER_TIMEOUT,
                 poll: float = 1.0):
    """The runs ``todo`` on the dask cluster of ``client``. The scheduler re-submits the
    runs of a worker it loses to the others (a run that killed its workers three times
    fails with ``KilledWorker``, reported by ``on_error``); while no worker is left, the
    cluster is asked every ``poll`` seconds, and after ``worker_timeout`` seconds without a
    worker (or without an answer of the scheduler) :class:`_NoWorker` stops the campaign."""
    from dask.distributed import wait

    # every call of the client is made with Ctrl-C deferred to its end (interrupt.deferred):
    # dask's client does not survive a KeyboardInterrupt raised while it waits
    with interrupt.deferred():
        futures = {client.submit(run_one, job, i, seed, key=f"dopus-campaign-{job.fingerprint}-{seed}-{i}",
                                 pure=False): i for i in todo}
    pending = set(futures)
    alone_since = None
    try:
        while pending:
            try:
                with interrupt.deferred():
                    done, pending = wait(pending, timeout=poll, return_when="FIRST_COMPLETED")
            except TimeoutError:
                done = ()
            except Exception as exc:  # noqa: BLE001 - the scheduler cancelled the runs or went away
                raise _NoWorker(f"the dask cluster stopped the runs ({type(exc).__name__}: {exc})") from None
            got = 0
            for fut in done:
                try:
                    with interrupt.deferred():
                        failed = fut.status == "error"
                        value = fut.exception(timeout=poll) if failed else fut.result(timeout=poll)
                        fut.release()
                except TimeoutError:    # its result was on a worker lost since: the run is computed again
                    pending.add(fut)
                    continue
                got += 1
                if failed:
                    on_error(futures[fut], value)
                else:
                    on_result(value)
            if got:
                alone_since = None
                continue
            try:
                with interrupt.deferred():
                    n_workers = len(client.nthreads())
            except Exception:  # noqa: BLE001 - the scheduler does not answer
                n_workers = 0
            if n_workers:
                alone_since = None
            elif alone_since is None:
                alone_since = time.monotonic()
            elif time.monotonic() - alone_since >= worker_timeout:
                raise _NoWorker(f"the dask cluster has had no worker for {worker_timeout:g} s (--worker-timeout)")
    finally:
        with interrupt.deferred():
            client.cancel(list(futures))


class _Progress:
    """Runs done, on the path and failed instants so far, on stderr: a bar on a terminal,
    a line every tenth of the runs (and at least every 30 s) otherwise."""

    def __init__(self, total: int, done: int, enabled: bool):
        self.total, self.done, self.enabled = total, done, enabled
        self.on_path = self.failed = 0
        self.t0 = self.t_last = time.perf_counter()
        self.bar = None
        self.tty = enabled and sys.stderr.isatty()
        self.step = max(1, total // 10)
        if self.tty:
            import click
            self.bar = click.progressbar(length=total, label="campaign", file=sys.stderr, show_eta=True,
                                         show_pos=True, item_show_func=lambda _: self._text())
            self.bar.__enter__()
            self.bar.update(done)

    def _text(self):
        return f"{self.on_path} on path, {self.failed} failed instants"

    def add(self, line):
        self.done += 1
        self.on_path += bool(line["on_path"])
        self.failed += int(line["failed_instants"])
        if not self.enabled:
            return
        if self.bar is not None:
            self.bar.update(1, line)
            return
        now = time.perf_counter()
        if self.done % self.step == 0 or self.done == self.total or now - self.t_last > 30:
            self.t_last = now
            print(f"campaign: {self.done}/{self.total} runs, {self._text()} ({now - self.t0:.0f} s)",
                  file=sys.stderr, flush=True)

    def close(self):
        if self.bar is not None:
            self.bar.__exit__(None, None, None)
            self.bar = None


# --------------------------------------------------------------------------- the command
def _resolve(ocp, cli: dict):
    """Solver and campaign settings: the flags, else the OCP file, else the defaults."""
    declared = ocp.declared_options()
    s, s_src = settings.Settings.resolve(declared, {k: cli.get(k) for k in settings.SOLVER_SETTINGS})
    solver = {k: v for k, v in s.as_dict().items() if k != "mode"}
    spec = ocp.validate()
    sc = spec.scenario.closed_loop
    if sc is None:
        raise CampaignError("the OCP declares no closed-loop scenario (ocp.scenario(...))")
    cs = sc.campaign
    if cs is None:
        raise CampaignError("the OCP declares no campaign (ocp.campaign(mismatch=..., initial=..., pushes=..., "
                            "on_path=...))")
    file_c = {"mismatch": dict(cs.mismatch)}
    if cs.runs is not None:
        file_c["runs"] = cs.runs
    if cs.duration is not None:
        file_c["duration"] = cs.duration
    if cs.on_path is not None:
        file_c["threshold"], file_c["settle"] = cs.on_path[1], cs.on_path[2]
    camp, c_src = settings.resolve(file_c, {k: cli.get(k) for k in settings.CAMPAIGN_SETTINGS},
                                   names=settings.CAMPAIGN_SETTINGS)
    if cs.on_path is None:
        raise CampaignError("the OCP's campaign declares no on_path=OnPath(signal, threshold, settle)")
    signals = dict(sc.signals)
    if cs.on_path[0] not in signals:
        raise CampaignError(f"campaign on_path: {cs.on_path[0]!r} is not a signal of the scenario; its signals are "
                            f"{sorted(signals)}")
    if signals[cs.on_path[0]].numel() != 1:
        raise CampaignError(f"campaign on_path: the signal {cs.on_path[0]!r} must be a scalar")
    if camp["mismatch"] and sc.plant_q is None:
        raise CampaignError("mismatch: the scenario's plant does not use the plant quantities (declare them with "
                            "ocp.plant_quantity and use them in ocp.scenario(plant=...)); give --mismatch none")
    if camp["duration"] is None:
        camp["duration"] = float(sc.duration)
    known = [n for n, _, _ in sc.quantities]
    for name in camp["mismatch"]:
        if name not in known:
            raise CampaignError(f"mismatch: {name!r} is not a plant quantity of the OCP; its plant quantities are "
                                f"{known or 'none'} (ocp.plant_quantity)")
    return solver, s_src, camp, c_src, (cs.on_path[0], camp["threshold"], camp["settle"])


def run_campaign(ocp_file, out, workers: int | None = None, scheduler: str | None = None, backend: str = "c",
                 json_out=None, plot_dir=None, echo=None, progress: bool = True, worst: int = 4,
                 overwrite: bool = False, worker_timeout: float = WORKER_TIMEOUT, **cli) -> dict:
    """The ``dopus-gen campaign`` command; returns the report (:func:`format_report`).

    ``workers``: None = one LocalCluster worker per core; 0 = the runs one by one in this
    process (no dask); ``scheduler``: the address of an existing dask scheduler. ``cli``:
    the solver settings and :data:`settings.CAMPAIGN_SETTINGS` given as flags (None: not
    given). The output paths, the settings and the scheduler are checked before any run.

    ``out`` is resumed only when its header carries this campaign's fingerprint; a damaged
    header or another campaign's is refused (:class:`CampaignError`), or with ``overwrite``
    replaced by a new file. Malformed run lines are reported and computed again. A
    ``KeyboardInterrupt`` (Ctrl-C) stops the campaign with the finished runs in ``out`` and
    records no interrupted run; the dask cluster without a worker for ``worker_timeout``
    seconds stops it the same way, with :class:`CampaignError`."""
    from ..outputs import check_output_dir, check_output_file
    from ..problem.ocp import load_ocp

    say = echo or (lambda text, err=False: print(text, file=sys.stderr if err else sys.stdout))
    check_output_file(out, "--out")
    if json_out:
        check_output_file(json_out, "--json")
    if plot_dir:
        check_output_dir(plot_dir, "--plot-dir")
    if workers is not None and workers < 0:
        raise CampaignError(f"--workers must be >= 0, got {workers}")
    ocp = load_ocp(ocp_file)
    try:
        solver, s_src, camp, c_src, on_path = _resolve(ocp, cli)
    except settings.SettingError as exc:
        raise CampaignError(f"{ocp_file}: {exc}") from None
    ocp_text = Path(ocp_file).read_text()
    spec = ocp.validate()
    fp = _fingerprint(ocp_text, backend, solver, camp["duration"], camp["mismatch"], on_path,
                      spec.scenario.closed_loop.campaign)
    if not (worker_timeout > 0):
        raise CampaignError(f"--worker-timeout must be > 0 s, got {worker_timeout}")
    old = read_results(out)
    lines = old.lines
    if old.header_problem is not None or (old.header is not None and old.header.get("campaign") != fp):
        if old.header_problem is not None:
            why = (f"--out '{out}' cannot be resumed: its first line is not a campaign header of this version "
                   f"(damaged, another file or another version: {old.header_problem})")
        else:
            why = (f"--out '{out}' holds the runs of another campaign (another OCP file or other settings: "
                   f"fingerprint {old.header.get('campaign')}, this one {fp})")
        if not overwrite:
            raise CampaignError(f"{why}; give another file, or --overwrite to start a new campaign in it")
        say(f"warning: {why}; --overwrite: a new campaign replaces it", err=True)
        lines = {}
    elif old.malformed:
        say(_malformed_text(out, old.malformed), err=True)
    runs, seed = camp["runs"], camp["seed"]
    todo = [i for i in range(runs) if (seed, i) not in lines]
    say(f"settings: {settings.describe(solver, s_src)}; {settings.describe(camp, c_src)}", err=True)

    client = cluster = None
    try:
        if todo and workers != 0:
            with interrupt.deferred():      # Ctrl-C while the cluster starts: stopped once it runs
                client, cluster = connect(workers, scheduler)
        from ..problem.derivatives import build_functions
        from ..reference.offline import solve_ocp

        disc = build_functions(ocp)
        lib_dir = ""
        if backend == "c" and (todo or plot_dir):
            from ..runtime.solver import build_for
            lib_dir = str(build_for(disc))     # built once, before the runs are distributed
        guess = None
        if todo or plot_dir:
            x0 = np.array(disc.scenario.closed_loop.x0, dtype=float)
            key = (hashlib.sha256(ocp_text.encode()).hexdigest(), x0.tobytes())
            if key not in _GUESS:
                guess, info = solve_ocp(disc, x0)
                if not info.get("success", True):
                    say(f"warning: the offline solve at the initial state did not converge ({info.get('status')})",
                        err=True)
                _GUESS.clear()
                _GUESS[key] = guess
            guess = _GUESS[key]
        job = Job(ocp_path=str(Path(ocp_file).resolve()), ocp_text=ocp_text, lib_dir=lib_dir, backend=backend,
                  solver=dict(solver), duration=float(camp["duration"]), mismatch=dict(camp["mismatch"]),
                  on_path=tuple(on_path), guess=guess, fingerprint=fp)
        header = _header(job, spec.name)
        _rewrite(out, header, lines)       # a clean file (a line cut short by an interruption dropped)
        errors = []
        where = ("in this process" if workers == 0 else
                 f"on {len(client.scheduler_info()['workers'])} dask workers" if client else "")
        say(f"campaign: {runs} runs (seed {seed}), {runs - len(todo)} already in '{out}', {len(todo)} to compute "
            f"{where}".rstrip(), err=True)
        prog = _Progress(runs, runs - len(todo), progress)
        t0 = time.perf_counter()

        fd = os.open(out, os.O_WRONLY | os.O_APPEND)

        def on_result(line):
            interrupt.check()       # a run that ended with Ctrl-C is not a result
            _append(fd, _dump(line) + "\n")
            lines[(line["seed"], line["run"])] = line
            prog.add(line)

        def on_error(i, exc):
            errors.append((i, f"{type(exc).__name__}: {exc}"))

        def kept():
            return f"{sum(1 for i in range(runs) if (seed, i) in lines)} of {runs} runs are in '{out}'"

        try:
            if not todo:
                pass
            elif workers == 0:
                _in_process(job, todo, seed, on_result, on_error)
            else:
                _distributed(client, job, todo, seed, on_result, on_error, worker_timeout)
        except KeyboardInterrupt:
            raise KeyboardInterrupt(f"{kept()}; the same command computes the others") from None
        except _NoWorker as exc:
            raise CampaignError(f"{exc}; {kept()}, the same command computes the others") from None
        finally:
            prog.close()
            os.close(fd)
        wall = time.perf_counter() - t0
        _rewrite(out, header, lines)
    finally:
        with interrupt.deferred():
            if client is not None:
                client.close()
            if cluster is not None:
                cluster.close()
    chosen = [lines[(seed, i)] for i in range(runs) if (seed, i) in lines]
    report = summarize(chosen, job, camp, spec, wall=wall, computed=len(todo) - len(errors),
                       workers=where, errors=errors)
    say(format_report(report))
    if json_out:
        write_text(json_out, json.dumps(json_ready(report), indent=1, allow_nan=False) + "\n")
        say(f"JSON: {json_out}")
    if plot_dir and chosen:
        files = plot_campaign(report, chosen, disc, job, plot_dir, worst=worst)
        say(f"plots: {Path(plot_dir).resolve()} ({len(files)} PNG)")
    return report


# --------------------------------------------------------------------------- report
def summarize(lines, job, camp, spec, wall=None, computed=0, workers="", errors=()) -> dict:
    n = len(lines)
    on = sum(1 for r in lines if r["on_path"])
    failed = [r["failed_instants"] for r in lines]
    rec = [r["recoveries"] or 0 for r in lines]
    med = np.asarray([r["time"]["median_us"] for r in lines if r["time"]["median_us"] is not None], dtype=float)
    p99 = np.asarray([r["time"]["p99_us"] for r in lines if r["time"]["p99_us"] is not None], dtype=float)
    mx = np.asarray([r["time"]["max_us"] for r in lines if r["time"]["max_us"] is not None], dtype=float)
    order = sorted(lines, key=lambda r: (r["on_path"], -(r["max_deviation"] if r["max_deviation"] is not None
                                                          else math.inf)))
    signal, threshold, settle = job.on_path
    cs = spec.scenario.closed_loop.campaign
    return {
        "ocp": spec.name, "runs": n, "runs_asked": camp["runs"], "seed": camp["seed"], "duration": job.duration,
        "solver": job.solver, "backend": job.backend, "mismatch": job.mismatch,
        "pushes": {"count": list(cs.push_count), "window": list(cs.push_window)},
        "on_path_definition": {"signal": signal, "unit": dict(spec.scenario.closed_loop.units).get(signal),
                               "threshold": threshold, "settle": settle},
        "time_unit": dict(spec.scenario.closed_loop.units).get("time", "s"),
        "on_path": on, "on_path_fraction": on / n if n else None,
        "aborted": sum(1 for r in lines if r["aborted"]),
        "runs_with_failed_instants": sum(1 for f in failed if f), "failed_instants": int(sum(failed)),
        "failed_instants_max": int(max(failed)) if failed else 0,
        "recoveries": int(sum(rec)), "runs_with_recoveries": sum(1 for v in rec if v),
        "time_per_iteration_us": {"median_of_run_medians": float(np.median(med)) if med.size else None,
                                  "p99_of_run_p99": float(np.percentile(p99, 99)) if p99.size else None,
                                  "max": float(np.max(mx)) if mx.size else None},
        "worst": [{"run": r["run"], "seed": r["seed"], "on_path": r["on_path"], "max_deviation": r["max_deviation"],
                   "failed_instants": r["failed_instants"], "recoveries": r["recoveries"], "aborted": r["aborted"]}
                  for r in order[:5]],
        "soft_violation_max": {k: max(r["soft_violation"][k] for r in lines if k in (r.get("soft_violation") or {}))
                               for k in sorted({k for r in lines for k in (r.get("soft_violation") or {})})},
        "wall_s": wall, "computed": computed, "workers": workers,
        "errors": [{"run": i, "message": m} for i, m in errors],
    }


def format_report(rep: dict) -> str:
    d = rep["on_path_definition"]
    unit = f" {d['unit']}" if d["unit"] else ""
    mm = ", ".join(f"{k} +-{100 * v:g} %" for k, v in rep["mismatch"].items()) or "none"
    t = rep["time_per_iteration_us"]
    f = lambda v, fmt: "-" if v is None else format(v, fmt)  # noqa: E731
    tu = rep.get("time_unit", "s")      # of the model's time (the wall time is in seconds)
    lines = [
        f"campaign {rep['ocp']}: {rep['runs']} of {rep['runs_asked']} runs (seed {rep['seed']}), {rep['duration']:g} "
        f"{tu} each, M = {rep['solver']['M']}, {rep['backend']} backend; mismatch {mm}; "
        f"{rep['pushes']['count'][0]}..{rep['pushes']['count'][1]} pushes in [{rep['pushes']['window'][0]:g}, "
        f"{rep['pushes']['window'][1]:g}] {tu}",
        f"on the path: {rep['on_path']} of {rep['runs']} ({f(100 * rep['on_path_fraction'] if rep['runs'] else None, '.1f')} %)"
        f"  [{d['signal']} <= {d['threshold']:g}{unit} from {d['settle']:g} {tu} after the start and after every push, "
        "plant integrated to the end]",
        f"failed instants (QP failures): {rep['failed_instants']} in {rep['runs_with_failed_instants']} runs "
        f"(at most {rep['failed_instants_max']} in one run); recoveries: {rep['recoveries']} in "
        f"{rep['runs_with_recoveries']} runs; aborted runs (plant): {rep['aborted']}",
        f"time per iteration (feedback + prepare): median of the runs' medians {f(t['median_of_run_medians'], '.1f')}"
        f" us, 99th percentile of the runs' 99th percentiles {f(t['p99_of_run_p99'], '.1f')} us, "
        f"max {f(t['max'], '.1f')} us",
        "worst runs: " + "; ".join(f"run {w['run']}: {d['signal']} {f(w['max_deviation'], '.3g')}{unit}"
                                   f"{'' if w['on_path'] else ' (off the path)'}, {w['failed_instants']} failed"
                                   for w in rep["worst"]),
    ]
    if rep.get("soft_violation_max"):
        lines.append("largest violation of the soft rows over the runs (measured state, applied control): "
                     + ", ".join(f"{k} {v:.3g}" for k, v in rep["soft_violation_max"].items()))
    if rep["wall_s"] is not None:
        lines.append(f"wall time: {rep['wall_s']:.1f} s for {rep['computed']} runs computed {rep['workers']}".rstrip())
    for e in rep["errors"]:
        lines.append(f"run {e['run']} FAILED: {e['message']}")
    return "\n".join(lines)


# --------------------------------------------------------------------------- plots
def _log_ticks(axis):
    """Labels at 1, 2 and 5 times the powers of ten of a log axis, in plain numbers."""
    import matplotlib.ticker as ticker

    axis.set_major_locator(ticker.LogLocator(subs=(1.0, 2.0, 5.0)))
    axis.set_major_formatter(ticker.FormatStrFormatter("%g"))
    axis.set_minor_formatter(ticker.NullFormatter())


def plot_campaign(rep, lines, disc, job, plot_dir, worst: int = 4) -> list:
    """Histograms of the campaign (max on-path signal after settling, time per iteration,
    failed instants and recoveries per run, the drawn mismatch against the deviation) and
    the trajectories of the ``worst`` runs, simulated again in this process."""
    import matplotlib.ticker

    from .plots import plot_plane, plot_signals, plt

    out = Path(plot_dir)
    out.mkdir(parents=True, exist_ok=True)
    files = []
    d = rep["on_path_definition"]
    unit = d["unit"] or "-"
    dev = np.asarray([r["max_deviation"] if r["max_deviation"] is not None else np.inf for r in lines], dtype=float)
    fig, axes = plt.subplots(2, 2, figsize=(10, 7))
    ax = axes[0, 0]
    finite = dev[np.isfinite(dev)]
    log = bool(finite.size) and finite.min() > 0 and d["threshold"] > 0   # else a signed signal: linear axes
    if finite.size and log:
        bins = np.logspace(np.log10(finite.min()), np.log10(max(finite.max(), d["threshold"] * 1.01)), 40)
        ax.hist(finite, bins=bins, color="C0")
        ax.set_xscale("log")
        _log_ticks(ax.xaxis)
    elif finite.size:
        ax.hist(finite, bins=np.linspace(min(finite.min(), d["threshold"]), max(finite.max(), d["threshold"]), 41),
                color="C0")
    ax.axvline(d["threshold"], color="C3", ls="--", label=f"threshold {d['threshold']:g} {unit}")
    ax.set_xlabel(f"max {d['signal']} after settling [{unit}]")
    ax.set_ylabel("runs [-]")
    ax.legend(fontsize=8)
    ax = axes[0, 1]
    med = np.asarray([r["time"]["median_us"] for r in lines if r["time"]["median_us"] is not None], dtype=float)
    ax.hist(med, bins=40, color="C2")
    ax.set_xlabel("median time per iteration of a run [us]")
    ax.set_ylabel("runs [-]")
    ax = axes[1, 0]
    fi = np.asarray([r["failed_instants"] for r in lines], dtype=int)
    rc = np.asarray([r["recoveries"] or 0 for r in lines], dtype=int)
    top = int(max(fi.max(initial=0), rc.max(initial=0)))
    edges = np.arange(-0.5, top + 1.5)
    ax.hist([fi, rc], bins=edges, label=["failed instants", "recoveries"], color=["C3", "C1"])
    ax.set_xticks(range(top + 1)) if top <= 20 else ax.xaxis.set_major_locator(
        matplotlib.ticker.MaxNLocator(integer=True))
    ax.set_xlabel("count per run [-]")
    ax.set_ylabel("runs [-]")
    ax.set_yscale("log")
    ax.legend(fontsize=8)
    ax = axes[1, 1]
    names = list(job.mismatch) or list(disc.scenario.closed_loop.quantities)[:1]
    nominal = disc.scenario.closed_loop.quantities
    for k, name in enumerate(names[:4]):
        rel = np.asarray([100 * (r["draw"]["quantities"][name] / nominal[name] - 1) for r in lines], dtype=float)
        ax.scatter(rel, np.where(np.isfinite(dev), dev, np.nan), s=6, color=f"C{k}", label=name, alpha=0.6)
    ax.axhline(d["threshold"], color="C3", ls="--")
    if log:
        ax.set_yscale("log")
        _log_ticks(ax.yaxis)
    ax.set_xlabel("plant quantity against nominal [%]")
    ax.set_ylabel(f"max {d['signal']} after settling [{unit}]")
    if names:
        ax.legend(fontsize=8)
    fig.suptitle(f"{rep['ocp']}: campaign of {rep['runs']} runs, {rep['on_path']} on the path")
    fig.tight_layout()
    path = out / "campaign_histograms.png"
    save_figure(fig, path, dpi=130)
    plt.close(fig)
    files.append(path)
    if worst > 0 and lines:
        from .sil import run_closed_loop

        chosen = sorted(lines, key=lambda r: (r["on_path"], -(r["max_deviation"] if r["max_deviation"] is not None
                                                               else math.inf)))[:worst]
        st = {"disc": disc, "backend": _backend(job, disc)}
        runs = []
        for r in chosen:
            dr = draw(disc.scenario.closed_loop, job.mismatch, r["run"], r["seed"])
            runs.append(run_closed_loop(disc, backend=job.backend, backend_obj=st["backend"], guess=job.guess,
                                        duration=job.duration, xhat0=dr["x0"], events=campaign_events(dr),
                                        plant=campaign_plant(disc, dr), settings=settings.Settings.of(job.solver),
                                        label=f"run {r['run']}"))
        title = f"{rep['ocp']}: the {len(runs)} worst runs of the campaign"
        for name, fn in (("campaign_worst_signals.png", plot_signals), ("campaign_worst_plane.png", plot_plane)):
            try:
                fn(runs, out / name, title=title)
                files.append(out / name)
            except (ValueError, KeyError):
                pass
    return files
