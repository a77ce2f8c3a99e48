"""Figures a reader can trust: a signal with both signs is never drawn on a log axis, and
every axis says its unit (declared with ``ocp.scenario(units=...)``, else "unit not
declared"; the KKT measure has mixed units; counts and indices are "[-]")."""
from __future__ import annotations

import re

import numpy as np
import pytest

from dopus_codegen.studies import plots

OCP = '''
import casadi as ca
import numpy as np
from dopus_codegen import Ocp, Event


def build():
    ocp = Ocp("plotted")
    x = ocp.state("x", 2, lb=[-5, -10], ub=[5, 10])
    u = ocp.control("u", lb=-1, ub=1)
    ocp.dynamics(ca.vertcat(x[1], u - ca.sin(x[0])))
    ocp.stage_least_squares(ca.vertcat(x[0], u), weights=[1.0, 0.01])
    ocp.horizon(N=5, dt=0.05)
    ocp.initial_state([0.5, 0.0])
    ocp.scenario(duration=0.3, events=[Event(0.1, lambda x: x + np.array([0.05, 0.0]), "kick")],
                 signals={"angle": x[0], "rate": x[1], "tipxy": ca.vertcat(x[0], x[1]),
                          "ref": ca.vertcat(x[0], 0 * x[1])},
                 units={"angle": "rad", "u": "N m", "tipxy": "m"})
    return ocp
'''


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    from dopus_codegen.problem.derivatives import build_functions
    from dopus_codegen.problem.ocp import load_ocp
    from dopus_codegen.studies.sil import run_closed_loop

    f = tmp_path_factory.mktemp("plots") / "plotted.py"
    f.write_text(OCP)
    return run_closed_loop(build_functions(load_ocp(f)), backend="reference", M=1)


@pytest.fixture()
def figures(monkeypatch):
    """The figures the plot functions save, kept open for inspection."""
    saved = []

    def keep(fig, path):
        saved.append(fig)
        return str(path)
    monkeypatch.setattr(plots, "_save", keep)
    yield saved
    import matplotlib.pyplot as plt
    for fig in saved:
        plt.close(fig)


def test_yscale_never_log_for_a_signed_signal():
    signed = np.array([-1e-6, 1e-2, -3.0, 2e-5])
    assert plots.yscale_for(signed)[0] == "symlog"
    assert plots.yscale_for(signed, log=True)[0] == "symlog"
    assert plots.yscale_for(signed, log=False)[0] == "linear"
    assert plots.yscale_for(np.array([-1.0, 0.5, 2.0]))[0] == "linear"      # one decade: linear
    assert plots.yscale_for(np.array([1e-6, 1e-2, 3.0]))[0] == "log"        # positive: log is fine
    scale, opts = plots.yscale_for(signed)
    assert 0 < opts["linthresh"] <= 1e-5


def test_signed_signal_keeps_its_negative_part(run, figures, tmp_path):
    """A signal that changes sign and spans five decades (the closed loop's 'rate' made so):
    drawn on a symmetric-log axis, whose limits include its negative values."""
    r = dict(run)
    rate = np.asarray(r["signals"]["rate"], dtype=float)
    r["signals"] = dict(r["signals"], rate=list(np.where(np.arange(rate.size) % 2, -1e-5, 1.0) * (1 + rate)))
    plots.plot_signals([r], tmp_path / "s.png")
    (fig,) = figures
    ax = {a.get_ylabel(): a for a in fig.axes}
    rate_ax = ax["rate [unit not declared]"]
    assert rate_ax.get_yscale() == "symlog"
    lo, hi = rate_ax.get_ylim()
    assert lo < 0 < hi
    assert ax["angle [rad]"].get_yscale() != "log" or np.all(np.asarray(r["signals"]["angle"]) > 0)


def test_every_axis_has_a_unit(run, figures, tmp_path):
    paths = plots.plot_sil([run], tmp_path)
    assert len(paths) == len(figures) >= 5
    unit = re.compile(r"\[[^\]]+\]$")
    for fig in figures:
        for ax in fig.axes:
            if not ax.get_visible() or ax.get_label() == "<colorbar>":
                continue
            assert unit.search(ax.get_ylabel()), (fig.texts[0].get_text() if fig.texts else "", ax.get_ylabel())
            xl = ax.get_xlabel()
            shared_hidden = not any(t.get_visible() and t.get_text() for t in ax.get_xticklabels()) and not xl
            assert unit.search(xl) or shared_hidden, (ax.get_ylabel(), xl)
    labels = [ax.get_ylabel() for fig in figures for ax in fig.axes]
    assert "angle [rad]" in labels and "u [N m]" in labels and plots.KKT_LABEL in labels
    assert "tipxy[1] [m]" in labels


def test_convergence_plot_axes(tmp_path, monkeypatch):
    import matplotlib.pyplot as plt

    from dopus_codegen.studies import converge

    figs = []
    monkeypatch.setattr(plt.Figure, "savefig", lambda self, *a, **k: figs.append(self))
    monkeypatch.setattr(plt, "close", lambda *a, **k: None)
    study = {"N": 5, "problem": "p", "start": "cold", "hessian": "exact",
             "runs": [{"M": 4, "kkt": [1.0, 1e-3, 1e-9]}, {"M": 1, "kkt": [1.0, 0.0, 1e-12]}]}
    converge.plot_study(study, str(tmp_path / "k.png"))
    (ax,) = figs[0].axes
    assert ax.get_xlabel() == "iteration [-]" and ax.get_ylabel() == "KKT measure (inf-norm) [mixed units]"
    assert ax.get_yscale() == "log"          # the KKT measure is >= 0
