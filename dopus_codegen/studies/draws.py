"""The random draw of a campaign run (``dopus-gen campaign``, ``dopus-gen sil --campaign-run``).

Run ``i`` of a campaign with seed ``s`` draws, as a pure function of the pair, the plant
quantities (each declared ``Ocp.plant_quantity`` scaled within ``Ocp.campaign(mismatch=...)``),
offsets of the scenario's initial state (``initial``) and the pushes that replace the
scenario's events (``Pushes``); :mod:`.campaign` runs the draws, :mod:`.sil` replays one.
"""
from __future__ import annotations

import numpy as np

__all__ = ["draw", "campaign_events", "campaign_plant"]


def draw(closed_loop, mismatch: dict, index: int, seed: int) -> dict:
    """The random draw of run ``index`` for ``seed`` (a pure function of both): the plant
    quantities, the initial state and the pushes (time, state offsets). The random stream is
    ``numpy.random.default_rng([seed, index])``; one number is drawn per declared plant
    quantity whether it is mismatched or not, so the draws of the other quantities do not
    depend on which ones are."""
    cs = closed_loop.campaign
    rng = np.random.default_rng([int(seed), int(index)])
    quantities = {}
    for name, nominal in closed_loop.quantities.items():
        u = rng.uniform(-1.0, 1.0)
        quantities[name] = float(nominal) * (1.0 + float(mismatch.get(name, 0.0)) * u)
    x0 = np.array(closed_loop.x0, dtype=float).reshape(-1)
    for rows, widths in cs.initial:
        x0[list(rows)] += np.asarray(widths) * rng.uniform(-1.0, 1.0, len(rows))
    n = int(rng.integers(cs.push_count[0], cs.push_count[1] + 1))
    times = np.sort(rng.uniform(cs.push_window[0], cs.push_window[1], n))
    pushes = []
    for t in times:
        kick = np.zeros(x0.size)
        for rows, widths in cs.push_kick:
            kick[list(rows)] += np.asarray(widths) * rng.uniform(-1.0, 1.0, len(rows))
        pushes.append({"time": float(t), "kick": kick.tolist()})
    return {"quantities": quantities, "x0": x0.tolist(), "pushes": pushes}


class _Kick:
    """The state map of a push: x + kick (a picklable callable for :class:`Event`)."""

    def __init__(self, kick):
        self.kick = np.asarray(kick, dtype=float)

    def __call__(self, x):
        return np.asarray(x, dtype=float) + self.kick


def campaign_events(d: dict) -> list:
    """The pushes of a draw as scenario events."""
    from ..problem.ocp import Event

    return [Event(p["time"], _Kick(p["kick"]), f"push {k + 1}") for k, p in enumerate(d["pushes"])]


def campaign_plant(disc, d: dict):
    """``(Plant, parameters)`` of a draw: the scenario's plant with the drawn quantities."""
    from .plant import Plant

    spec = disc.scenario.closed_loop
    n_p = int(disc.np)      # the parameters of node 0, as the closed loop of sil uses them
    p = np.asarray(disc.p0, dtype=float).reshape(-1, n_p)[0].copy() if n_p else np.zeros(0)
    if spec.plant_ode_q is None:
        return Plant(spec.plant_ode, float(disc.dt), p.size, reltol=1e-10, abstol=1e-10), p
    q = np.array([d["quantities"][n] for n in spec.quantities], dtype=float)
    return Plant(spec.plant_ode_q, float(disc.dt), p.size + q.size, reltol=1e-10, abstol=1e-10), \
        np.concatenate([p, q])
