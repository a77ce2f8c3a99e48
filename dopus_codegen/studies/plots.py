"""Figures of the software-in-the-loop runs (paper figures 2 to 4 and the DOPUS internals).

Every function takes the run records of :func:`dopus_codegen.studies.sil.run_closed_loop` (plain
dicts, so a JSON file written by ``dopus-gen sil --json`` can be plotted again), draws all
runs on the same axes where that reads well, and marks the scenario events on every time
axis. Files are PNG, written with the non-interactive Agg backend.
"""
from __future__ import annotations

import logging
import re
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

# Some matplotlib wheels ship the DejaVu fonts only: math text then falls back from STIX
# and Computer Modern to DejaVu Sans with one log line per glyph lookup (about 80 for the
# figures of one sil run), which would drown the command's own output.
logging.getLogger("matplotlib.font_manager").setLevel(logging.ERROR)

__all__ = ["plot_sil", "plot_signals", "plot_kkt", "plot_controls", "plot_plane", "plot_recomputed",
           "plot_timing", "yscale_for", "NO_UNIT", "KKT_LABEL"]

_STYLES = [dict(color="C0", lw=1.6, ls="-"), dict(color="C3", lw=1.3, ls="--"),
           dict(color="C2", lw=1.3, ls="-."), dict(color="C4", lw=1.3, ls=":")]
_DPI = 130


def _arr(values):
    return np.asarray([np.nan if v is None else v for v in values], dtype=float)


def _mat(values):
    return np.asarray([[np.nan if v is None else v for v in row] for row in values], dtype=float)


def _style(i):
    return _STYLES[i % len(_STYLES)]


def _mark_events(ax, runs, text=True):
    """Dashed vertical line at each event (events of the first run; all runs share them)."""
    seen = set()
    for run in runs:
        for ev in run.get("events", []):
            key = (round(ev["time"], 9), ev["label"])
            if key in seen:
                continue
            seen.add(key)
            ax.axvline(ev["time"], color="0.35", ls=":", lw=1.2, zorder=0)
            if text:
                ax.annotate(ev["label"], xy=(ev["time"], 1.0), xycoords=("data", "axes fraction"),
                            xytext=(3, -3), textcoords="offset points", ha="left", va="top",
                            fontsize=8, color="0.3")


def _legend_above(ax):
    """Legend in a row above the axes, where it hides no data."""
    handles, labels = ax.get_legend_handles_labels()
    if handles:
        ax.legend(handles, labels, loc="lower left", bbox_to_anchor=(0.0, 1.01), ncol=min(len(labels), 3),
                  fontsize=8, frameon=False, borderaxespad=0.0)


#: The unit written on an axis whose quantity has no unit declared (``ocp.scenario(units=...)``).
NO_UNIT = "unit not declared"
#: The KKT measure is the infinity norm over residuals of different units.
KKT_LABEL = "KKT measure (inf-norm) [mixed units]"


def _time_unit(runs) -> str:
    """The unit of the model's time (``scenario(units={"time": ...})``), else seconds."""
    return _unit_of(runs, "time") or "s"


def _unit_of(runs, name: str):
    """The declared unit of a signal, state or control (``name`` or ``name[i]``), else None."""
    base = re.sub(r"\[\d+\]$", "", name)
    for run in runs:
        units = run.get("settings", {}).get("units") or {}
        for key in (name, base):
            if key in units:
                return units[key]
    return None


def _label_with_unit(name: str, unit=None) -> str:
    """Axis label ``name [unit]``: a name that already ends in '[unit]' is kept as it is; a
    quantity without a declared unit says so."""
    if re.search(r"\[[^\]]*[^\d\]][^\]]*\]$", name):
        return name
    return f"{name} [{unit or NO_UNIT}]"


def yscale_for(values, log=None):
    """(scale, options) of a y axis for ``values``: a signal with both signs is never drawn on
    a log axis (its negative part would vanish): it gets a symmetric-log axis when it spans
    more than three decades, else a linear one. ``log`` True/False forces the choice between
    a (symmetric-)log and a linear axis; None decides by the span."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    mag = np.abs(v[v != 0])
    wide = mag.size > 0 and np.max(mag) / max(np.min(mag), 1e-300) > 1e3
    use_log = wide if log is None else bool(log)
    if not use_log or mag.size == 0:
        return "linear", {}
    if np.any(v < 0):
        return "symlog", {"linthresh": float(max(np.percentile(mag, 2), 1e-300))}
    return "log", {}


def _suptitle(fig, title, what):
    fig.suptitle(f"{title}: {what}" if title else what, fontsize=11)


def _save(fig, path):
    from ..outputs import save_figure

    save_figure(fig, path, dpi=_DPI)
    plt.close(fig)
    return str(path)


def _scalar_signals(runs):
    names = []
    for run in runs:
        for name, vals in run["signals"].items():
            if name not in names and vals and not isinstance(vals[0], list):
                names.append(name)
    return names


def plot_signals(runs, path, title=None, log=None):
    """Scalar scenario signals against time (paper figure 2: the path deviation).

    ``log``: logarithmic y axis; by default when a signal spans more than three decades. A
    signal with both signs gets a symmetric-log axis instead (:func:`yscale_for`).
    """
    names = _scalar_signals(runs)
    if not names:
        return None
    fig, axes = plt.subplots(len(names), 1, figsize=(8, 2.2 + 1.8 * len(names)), sharex=True, squeeze=False)
    for ax, name in zip(axes[:, 0], names):
        vals = []
        for i, run in enumerate(runs):
            if name not in run["signals"]:
                continue
            v = _arr(run["signals"][name])
            ax.plot(run["t"], v, label=run["label"], **_style(i))
            vals.extend(v[np.isfinite(v)])
        scale, opts = yscale_for(vals, log)
        if scale == "log":
            ax.set_yscale("log")
            # The start (often exactly on the reference) would stretch the axis over many
            # decades; the axis starts just below the bulk of the values.
            pos = np.abs(np.asarray(vals))
            ax.set_ylim(bottom=np.percentile(pos[pos > 0], 2) / 3)
        elif scale == "symlog":
            ax.set_yscale("symlog", **opts)
        ax.set_ylabel(_label_with_unit(name, _unit_of(runs, name)))
        ax.grid(True, which="both", alpha=0.3)
        _mark_events(ax, runs)
        _legend_above(ax)
    axes[-1, 0].set_xlabel(f"time [{_time_unit(runs)}]")
    _suptitle(fig, title, "closed-loop signals (CVODES plant)")
    fig.tight_layout()
    return _save(fig, path)


def plot_kkt(runs, path, title=None, cap=1e4):
    """KKT measure of every iteration, right after its feedback step (paper figure 3).

    Values above ``cap`` (a diverged iteration) are drawn on the upper edge as triangles so
    that they do not flatten the rest of the figure.
    """
    fig, ax = plt.subplots(figsize=(8, 4.4))
    clipped = False
    for i, run in enumerate(runs):
        k = _arr(run["kkt"])
        t = np.asarray(run["t"], dtype=float)
        over = ~(k <= cap)  # also NaN: no KKT measure (non-finite iterate)
        ax.semilogy(t, np.where(over, np.nan, k), label=run["label"], **_style(i))
        if np.any(over):
            clipped = True
            ax.semilogy(t[over], np.full(np.count_nonzero(over), cap), "^", color=_style(i)["color"], ms=5,
                        label=f"{run['label']}: > {cap:g} or not finite")
        bad = np.asarray(run["status"]) != 0
        if np.any(bad):
            ax.semilogy(t[bad], np.where(k[bad] <= cap, k[bad], cap), "x", color=_style(i)["color"], ms=7,
                        label=f"{run['label']}: QP failure ({np.count_nonzero(bad)})")
    if clipped:
        lo = ax.get_ylim()[0]
        ax.set_ylim(lo, cap * 3)
    ax.set_xlabel(f"time [{_time_unit(runs)}]")
    ax.set_ylabel(KKT_LABEL)
    ax.grid(True, which="both", alpha=0.3)
    _mark_events(ax, runs)
    _legend_above(ax)
    _suptitle(fig, title, "KKT measure after each feedback")
    fig.tight_layout()
    return _save(fig, path)


def plot_controls(runs, path, title=None, names=None):
    """Applied controls (zero-order hold) with their bounds (paper figure 4: the torques)."""
    u0 = _mat(runs[0]["u"])
    nu = u0.shape[1] if u0.ndim == 2 else 0
    if nu == 0:
        return None
    names = names or runs[0]["settings"].get("u_labels") or [f"u[{j}]" for j in range(nu)]
    fig, axes = plt.subplots(nu, 1, figsize=(8, 1.2 + 1.9 * nu), sharex=True, squeeze=False)
    lbu = _arr(runs[0]["settings"].get("lbu", [None] * nu))
    ubu = _arr(runs[0]["settings"].get("ubu", [None] * nu))
    for j, ax in enumerate(axes[:, 0]):
        for i, run in enumerate(runs):
            u = _mat(run["u"])
            t = np.asarray(run["t"], dtype=float)
            dt = run["settings"]["dt"]
            # Step plot over [t_i, t_i + dt): the control is held by the plant.
            ax.step(np.append(t, t[-1] + dt), np.append(u[:, j], u[-1, j]), where="post",
                    label=run["label"], **_style(i))
        for b, txt in ((lbu[j], "lower bound"), (ubu[j], "upper bound")):
            if np.isfinite(b):
                ax.axhline(b, color="k", ls="--", lw=0.9, alpha=0.7)
        lo, hi = ax.get_ylim()
        finite = [b for b in (lbu[j], ubu[j]) if np.isfinite(b)]
        if finite:
            span = max(hi, *finite) - min(lo, *finite)
            ax.set_ylim(min(lo, *finite) - 0.05 * span, max(hi, *finite) + 0.05 * span)
        ax.set_ylabel(_label_with_unit(names[j], _unit_of(runs, names[j])))
        ax.grid(True, alpha=0.3)
        _mark_events(ax, runs, text=(j == 0))
        if j == 0:
            _legend_above(ax)
    axes[-1, 0].set_xlabel(f"time [{_time_unit(runs)}]")
    _suptitle(fig, title, "applied controls (dashed black: bounds)")
    fig.tight_layout()
    return _save(fig, path)


def plot_plane(runs, path, title=None, plane=None):
    """A two-component signal against a reference curve in the plane (the tip on the circle)."""
    plane = plane or runs[0]["settings"].get("plane")
    if not plane:
        return None
    path_name, ref_name = plane
    fig, ax = plt.subplots(figsize=(6.4, 6.0))
    ref = _mat(runs[0]["signals"][ref_name])
    ax.plot(ref[:, 0], ref[:, 1], color="0.55", lw=3, alpha=0.5, label=f"{ref_name} (reference)", zorder=0)
    for i, run in enumerate(runs):
        xy = _mat(run["signals"][path_name])
        ax.plot(xy[:, 0], xy[:, 1], label=f"{run['label']}: {path_name}", **_style(i))
        t = np.asarray(run["t"], dtype=float)
        for ev in run.get("events", []):
            k = int(np.searchsorted(t, ev["time"] - 1e-9))
            if k < len(t):
                ax.plot(xy[k, 0], xy[k, 1], "o", mfc="none", mec=_style(i)["color"], ms=9)
                if i == 0:
                    ax.annotate(f"{ev['label']} (t = {ev['time']:g} {_time_unit(runs)})", xy=(xy[k, 0], xy[k, 1]),
                                xytext=(8, 8), textcoords="offset points", fontsize=8)
    ax.plot(ref[0, 0], ref[0, 1], "k^", ms=7, label="start")
    ax.set_aspect("equal", adjustable="datalim")
    unit = _unit_of(runs, path_name)
    ax.set_xlabel(_label_with_unit(f"{path_name}[0]", unit))
    ax.set_ylabel(_label_with_unit(f"{path_name}[1]", unit))
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best", fontsize=8)
    _suptitle(fig, title, f"{path_name} in the plane against {ref_name}")
    fig.tight_layout()
    return _save(fig, path)


def plot_recomputed(runs, path, title=None):
    """Stages whose sensitivities were recomputed at each instant (time x stage raster)."""
    fig, axes = plt.subplots(len(runs), 1, figsize=(8, 1.0 + 2.4 * len(runs)), sharex=True, squeeze=False)
    for ax, (i, run) in zip(axes[:, 0], enumerate(runs)):
        N = int(run["settings"]["N"])
        t = np.asarray(run["t"], dtype=float)
        dt = run["settings"]["dt"]
        img = np.zeros((N, len(t)))
        for j, stages in enumerate(run["recomputed"]):
            img[list(stages), j] = 1.0
        ax.imshow(img, aspect="auto", origin="lower", interpolation="nearest", cmap="Greys", vmin=0, vmax=1,
                  extent=(t[0] - 0.5 * dt if len(t) else 0, (t[-1] + 0.5 * dt) if len(t) else 1, -0.5, N - 0.5))
        ax.set_ylabel("stage k [-]")
        counts = [len(s) for s in run["recomputed"]]
        ax.set_title(f"{run['label']}: {np.mean(counts):.2f} stages per instant on average "
                     f"(stage N-1 = {N - 1} is always fresh)", fontsize=9)
        _mark_events(ax, runs)
    axes[-1, 0].set_xlabel(f"time [{_time_unit(runs)}]")
    _suptitle(fig, title, "stages with recomputed Hessian and Jacobians (black)")
    fig.tight_layout()
    return _save(fig, path)


def _phase_series(run):
    """(labels, arrays in us) of the disjoint phases of each iteration."""
    tim = run["timing_us"]
    phases = [k for k in tim if k.startswith("phase:")]
    if phases:
        return [k.split(":", 1)[1] for k in phases], [_arr(tim[k]) for k in phases]
    return ["feedback", "prepare"], [_arr(tim["feedback"]), _arr(tim["prepare"])]


def plot_timing(runs, path, title=None):
    """Computation time per iteration: median split by phase (stacked bars) and the
    wall-clock time of every iteration against time."""
    fig, (ax_bar, ax_t) = plt.subplots(1, 2, figsize=(11.5, 4.6), gridspec_kw={"width_ratios": [1, 1.9]},
                                       layout="constrained")
    all_labels = []
    for run in runs:
        for lab in _phase_series(run)[0]:
            if lab not in all_labels:
                all_labels.append(lab)
    colors = {lab: f"C{j % 10}" for j, lab in enumerate(all_labels)}
    heights = []
    for i, run in enumerate(runs):
        labels, data = _phase_series(run)
        bottom = 0.0
        for lab, v in zip(labels, data):
            med = float(np.nanmedian(v)) if v.size else 0.0
            ax_bar.bar(i, med, bottom=bottom, color=colors[lab], width=0.6,
                       label=lab if i == next(j for j, r in enumerate(runs) if lab in _phase_series(r)[0]) else None)
            bottom += med
        heights.append(bottom)
        ax_bar.annotate(f"{bottom:.0f} us", xy=(i, bottom), xytext=(0, 3), textcoords="offset points",
                        ha="center", fontsize=8)
    ax_bar.set_xticks(range(len(runs)))
    ax_bar.set_xticklabels([f"{r['label']}\n({r['settings']['backend']})" for r in runs], fontsize=8)
    ax_bar.set_xlabel("run (backend) [-]")
    ax_bar.set_ylabel("median time per iteration [us]")
    ax_bar.set_title("median by phase (backend timers)", fontsize=9)
    ax_bar.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.0, 1.0), borderaxespad=0.2)
    ax_bar.set_xlim(-0.6, len(runs) - 0.4)
    ax_bar.set_ylim(0, 1.15 * max(heights + [1e-9]))
    ax_bar.grid(True, axis="y", alpha=0.3)
    for i, run in enumerate(runs):
        t = np.asarray(run["t"], dtype=float)
        tot = _arr(run["timing_us"]["total"])
        ax_t.semilogy(t, tot, ".", ms=3, color=_style(i)["color"], alpha=0.7,
                      label=f"{run['label']}: feedback + prepare")
        ax_t.axhline(np.nanmedian(tot), color=_style(i)["color"], ls=_style(i)["ls"], lw=1.2,
                     label=f"{run['label']}: median {np.nanmedian(tot):.0f} us")
    ax_t.set_xlabel(f"time [{_time_unit(runs)}]")
    ax_t.set_ylabel("wall-clock time per iteration [us]")
    ax_t.set_title("every iteration (wall clock, Python call included)", fontsize=9)
    ax_t.grid(True, which="both", alpha=0.3)
    _mark_events(ax_t, runs)
    ax_t.legend(fontsize=7, loc="upper right")
    _suptitle(fig, title, "computation time per iteration")
    return _save(fig, path)


def plot_sil(runs, plot_dir, title=None) -> list:
    """All SIL figures into ``plot_dir``; returns the written paths."""
    d = Path(plot_dir)
    d.mkdir(parents=True, exist_ok=True)
    out = [
        plot_signals(runs, d / "sil_signals.png", title),
        plot_kkt(runs, d / "sil_kkt.png", title),
        plot_controls(runs, d / "sil_controls.png", title),
        plot_plane(runs, d / "sil_plane.png", title),
        plot_recomputed(runs, d / "sil_recomputed.png", title),
        plot_timing(runs, d / "sil_timing.png", title),
    ]
    return [p for p in out if p]
