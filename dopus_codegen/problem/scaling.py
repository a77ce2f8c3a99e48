"""Scaling: the problem the solver works with, in scaled variables (docs/algorithm.md section 16).

With scales ``Dx`` (states), ``Du`` (controls), ``Dg`` (path rows), ``Dr`` (terminal rows) and
``c`` (cost), the solver's variables are ``xs = x / Dx``, ``us = u / Du``; its functions are

    phi_s(xs, us, p) = phi(Dx xs, Du us, p) / Dx     l_s = l(Dx xs, Du us, p) / c
    g_s = g(Dx xs, Du us, p) / Dg                   r_s = r(Dx xs_N, p) / Dr,   E_s = E / c

with the bounds divided by the same scales and the soft weights of a row of scale ``d``
``l1 d / c`` and ``l2 d^2 / c`` (the same penalty of the same violation). The multipliers of the
scaled problem are those of the declared one times ``D / c`` (``lam_s = lam Dx / c``, ...), so
that a primal-dual point converts exactly, both ways (:class:`Scaling`). The QP, the KKT
measure and a float build all work in the scaled variables; the API of both backends (the
measurement, ``u0``, the iterate, a guess, the slacks) stays in the declared units.

:func:`scaled_spec` transcribes a validated :class:`~.spec.OcpSpec` into the scaled one, an
ordinary problem without scaling (its scenario is left out: the studies run the declared
problem and convert at the backends' boundary). :func:`resolve` turns the declared scales
into numbers (``Ocp.scaling(derive=...)``).
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Optional

import casadi as ca
import numpy as np

from .spec import (ConstraintSpec, CostSpec, GuessSpec, LeastSquares, ModelSpec, OcpError, OcpSpec, ScenarioPart,
                   Variable, readonly)

__all__ = ["Scaling", "resolve", "scaled_spec", "power_of_two", "nominal_solution"]


@dataclass(frozen=True, eq=False)
class Scaling:
    """The scales of one problem: ``x (nx,)``, ``u (nu,)``, ``g (ng,)`` (path rows, stacked),
    ``r (nr,)`` (terminal inequality rows), ``r_eq (ne,)`` (terminal equality rows), ``cost``.
    The ``*_in`` methods convert from the declared units to the solver's, ``*_out`` back."""
    x: np.ndarray
    u: np.ndarray
    g: np.ndarray
    r: np.ndarray
    r_eq: np.ndarray
    cost: float

    @property
    def w(self) -> np.ndarray:
        return np.concatenate([self.x, self.u])

    # primal
    def x_in(self, x):
        return None if x is None else np.asarray(x, dtype=float) / self.x

    def x_out(self, xs):
        return np.asarray(xs, dtype=float) * self.x

    def u_in(self, u):
        return None if u is None else np.asarray(u, dtype=float) / self.u

    def u_out(self, us):
        return np.asarray(us, dtype=float) * self.u

    # duals: physical -> scaled multiplies by D / c, back by c / D (in this order, as the C runtime)
    def dual_in(self, mu, d):
        return None if mu is None else np.asarray(mu, dtype=float) * d / self.cost

    def dual_out(self, mu_s, d):
        return np.asarray(mu_s, dtype=float) * self.cost / d

    def guess_in(self, guess):
        """A primal-dual point (a ``Guess``) of the declared problem in the solver's variables."""
        from .ocp import Guess

        return Guess(x=self.x_in(guess.x), u=self.u_in(guess.u), lam=self.dual_in(guess.lam, self.x),
                     mu_g=self.dual_in(guess.mu_g, self.g), mu_b=self.dual_in(guess.mu_b, self.w),
                     mu_bN=self.dual_in(guess.mu_bN, self.x), mu_r=self.dual_in(guess.mu_r, self.r),
                     nu=self.dual_in(guess.nu, self.r_eq))

    def guess_out(self, guess):
        """A primal-dual point of the solver back in the declared units (multipliers required)."""
        from .ocp import Guess

        return Guess(x=self.x_out(guess.x), u=self.u_out(guess.u), lam=self.dual_out(guess.lam, self.x),
                     mu_g=self.dual_out(guess.mu_g, self.g), mu_b=self.dual_out(guess.mu_b, self.w),
                     mu_bN=self.dual_out(guess.mu_bN, self.x), mu_r=self.dual_out(guess.mu_r, self.r),
                     nu=self.dual_out(guess.nu, self.r_eq))

    def as_dict(self) -> dict:
        return {"x": self.x.tolist(), "u": self.u.tolist(), "g": self.g.tolist(), "r": self.r.tolist(),
                "r_eq": self.r_eq.tolist(), "cost": float(self.cost)}


def power_of_two(v: float) -> float:
    """The power of two nearest to ``v > 0`` in the logarithm (a conversion by it is exact)."""
    return float(2.0 ** round(math.log2(v)))


def _derived(declared: np.ndarray, candidates) -> np.ndarray:
    """Declared scales where given, else the power of two of the largest candidate magnitude
    (``candidates[i]``: the values of row ``i``; none or all zero: 1)."""
    out = np.array(declared, dtype=float, copy=True)
    for i in range(out.size):
        if not np.isnan(out[i]):
            continue
        vals = np.abs(np.asarray(candidates[i], dtype=float).reshape(-1))
        vals = vals[np.isfinite(vals)]
        big = float(np.max(vals)) if vals.size else 0.0
        out[i] = power_of_two(big) if big > 0 else 1.0
    return out


def _bound_values(lb, ub) -> list:
    return [np.array([a for a in (lo, up) if math.isfinite(a)]) for lo, up in zip(lb, ub)]


def _first_nonempty(*lists):
    """Row by row: the first candidate list with a nonzero finite entry."""
    out = []
    for rows in zip(*lists):
        pick = np.zeros(0)
        for r in rows:
            r = np.abs(np.asarray(r, dtype=float).reshape(-1))
            if np.any(np.isfinite(r) & (r > 0)):
                pick = r
                break
        out.append(pick)
    return out


def nominal_solution(disc):
    """``(x (N+1, nx), u (N, nu))``: the NLP of ``disc`` at its initial state solved with IPOPT
    (its hard rows and bounds; soft sides left free), for ``derive="nominal"``; None when IPOPT
    fails. Only magnitudes are taken from it, rounded to powers of two."""
    N, nx, nu = disc.N, disc.nx, disc.nu
    P = np.asarray(disc.p0, float)
    X, U = ca.MX.sym("x", nx, N + 1), ca.MX.sym("u", nu, N)
    soft = np.asarray(disc.soft_x) > 0
    lbx = np.where(soft[0] | soft[2], -np.inf, np.asarray(disc.lbx, float))
    ubx = np.where(soft[1] | soft[3], np.inf, np.asarray(disc.ubx, float))
    cost, g, lbg, ubg = 0, [X[:, 0] - ca.DM(disc.x0)], [np.zeros(nx)], [np.zeros(nx)]
    sg = np.asarray(disc.soft_g) > 0
    for k in range(N):
        phi, l_, gk = disc.stage_eval(X[:, k], U[:, k], P[k])
        cost = cost + l_
        g += [X[:, k + 1] - phi]
        lbg += [np.zeros(nx)]
        ubg += [np.zeros(nx)]
        if disc.ng:
            lo = np.asarray(disc.data.lg_stage, float)[k]
            up = np.asarray(disc.data.ug_stage, float)[k]
            g += [gk]
            lbg += [np.where(sg[0] | sg[2], -np.inf, lo)]
            ubg += [np.where(sg[1] | sg[3], np.inf, up)]
    E, r, r_eq = disc.term_eval(X[:, N], P[N])
    sr = np.asarray(disc.soft_r) > 0
    g += [r, r_eq]
    lbg += [np.where(sr[0] | sr[2], -np.inf, disc.lr), np.zeros(disc.ne)]
    ubg += [np.where(sr[1] | sr[3], np.inf, disc.ur), np.zeros(disc.ne)]
    V = ca.vertcat(ca.vec(X), ca.vec(U))
    solver = ca.nlpsol("nominal", "ipopt", {"x": V, "f": cost + E, "g": ca.vertcat(*g)},
                       {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes"})
    lbv = np.concatenate([np.tile(lbx, N + 1), np.tile(disc.lbu, N)])
    ubv = np.concatenate([np.tile(ubx, N + 1), np.tile(disc.ubu, N)])
    lbv[:nx], ubv[:nx] = -np.inf, np.inf
    v0 = np.concatenate([np.asarray(disc.initial_guess.x, float).ravel(),
                         np.asarray(disc.initial_guess.u, float).ravel()])
    sol = solver(x0=v0, lbx=lbv, ubx=ubv, lbg=np.concatenate(lbg), ubg=np.concatenate(ubg))
    if not solver.stats().get("success", False):
        return None
    v = np.asarray(sol["x"], float).ravel()
    return v[:(N + 1) * nx].reshape(N + 1, nx), v[(N + 1) * nx:].reshape(N, nu)


def resolve(spec: OcpSpec, disc=None, nominal=None) -> Optional[Scaling]:
    """The numbers of the declared scaling of ``spec`` (None without one). ``disc``: the
    declared problem's ``Discretized`` (for the row values at the nominal solution);
    ``nominal``: ``(x, u)`` of its solution at the initial state (``derive="nominal"``,
    :func:`nominal_solution`)."""
    sc = spec.scaling
    if sc is None:
        return None
    model, con = spec.model, spec.constraints
    derive = sc.derive
    x_decl, u_decl = np.array(sc.x, dtype=float), np.array(sc.u, dtype=float)
    gx, gu = np.asarray(spec.guess.x, float), np.asarray(spec.guess.u, float)
    x0 = np.asarray(spec.x0, float)
    if derive is None:
        xs, us = np.where(np.isnan(x_decl), 1.0, x_decl), np.where(np.isnan(u_decl), 1.0, u_decl)
    else:
        bx, bu = _bound_values(con.lbx, con.ubx), _bound_values(con.lbu, con.ubu)
        ix = [np.concatenate([[x0[i]], gx[:, i]]) for i in range(x0.size)]
        iu = [gu[:, i] for i in range(gu.shape[1])]
        if derive == "nominal":
            nx_ = [np.concatenate([[x0[i]], np.asarray(nominal[0])[:, i]]) for i in range(x0.size)]
            nu_ = [np.asarray(nominal[1])[:, i] for i in range(gu.shape[1])]
            xs = _derived(x_decl, _first_nonempty(nx_, bx, ix))
            us = _derived(u_decl, _first_nonempty(nu_, bu, iu))
        else:
            xs = _derived(x_decl, _first_nonempty(bx, ix))
            us = _derived(u_decl, _first_nonempty(bu, iu))
    for srow, crow in model.memory:          # a memory state carries its control: the same scale
        xs[srow] = us[crow]

    g_at = r_at = None     # the rows' values along the nominal solution
    if derive == "nominal" and disc is not None:
        N = spec.horizon.N
        P = np.asarray(disc.p0, float)
        g_at = np.array([np.asarray(disc.stage_eval(nominal[0][k], nominal[1][k], P[k])[2], float).reshape(-1)
                         for k in range(N)]).reshape(N, -1)

    def row_scales(blocks, values=None):
        out, start = [], 0
        for b in blocks:
            n = b.lb.size
            decl = np.full(n, np.nan) if b.scale is None else np.array(b.scale, dtype=float)
            if b.scale_controls is not None and b.scale is None:
                decl = np.array([us[c] for c in b.scale_controls], dtype=float)
            if derive is None:
                out.append(np.where(np.isnan(decl), 1.0, decl))
            else:
                bounds = _bound_values(b.lb, b.ub)
                cand = bounds if values is None else _first_nonempty(
                    [values[:, start + i] for i in range(n)], bounds)
                out.append(_derived(decl, cand))
            start += n
        return np.concatenate(out) if out else np.zeros(0)

    g = row_scales(con.path, g_at)
    if derive == "nominal" and disc is not None and con.terminal:
        tv = disc.term_eval(nominal[0][-1], np.asarray(disc.p0, float)[-1])
        # term_eval splits the rows into inequality and equality rows; the blocks stack them whole
        r_all = _terminal_values(con, np.asarray(tv[1], float).reshape(-1), np.asarray(tv[2], float).reshape(-1))
        r_at = r_all.reshape(1, -1)
    rows = row_scales(con.terminal, r_at)
    eq = np.asarray(con.terminal_equality, dtype=bool)
    return Scaling(x=readonly(xs), u=readonly(us), g=readonly(g), r=readonly(rows[~eq]), r_eq=readonly(rows[eq]),
                   cost=float(sc.cost))


def _terminal_values(con: ConstraintSpec, r_ineq: np.ndarray, r_eq: np.ndarray) -> np.ndarray:
    """The stacked terminal rows' values from the inequality and equality parts (an equality
    row's value is its declared row, ``r_eq + lb``)."""
    eq = np.asarray(con.terminal_equality, dtype=bool)
    lb = np.concatenate([b.lb for b in con.terminal]) if con.terminal else np.zeros(0)
    out = np.zeros(eq.size)
    out[~eq] = r_ineq
    out[eq] = r_eq + lb[eq]
    return out


def _soft(weights: Optional[np.ndarray], d: np.ndarray, c: float) -> Optional[np.ndarray]:
    """Soft weights (rows l1 lower, l1 upper, l2 lower, l2 upper) of rows of scale ``d``."""
    if weights is None:
        return None
    w = np.array(weights, dtype=float, copy=True)
    w[:2] = w[:2] * d / c
    w[2:] = w[2:] * d * d / c
    return readonly(w)


def scaled_spec(spec: OcpSpec, s: Scaling) -> OcpSpec:
    """The problem of ``spec`` in the variables of ``s`` (module docstring), without scaling."""
    model, cost, con = spec.model, spec.cost, spec.constraints
    try:
        states = tuple(Variable(v.name, v.size, ca.SX.sym(v.name, v.size)) for v in model.states)
        controls = tuple(Variable(v.name, v.size, ca.SX.sym(v.name, v.size)) for v in model.controls)
        xs = ca.vertcat(*[v.sym for v in states])
        us = ca.vertcat(*[v.sym for v in controls])
        old = ca.vertcat(model.x, model.u)
        new = ca.vertcat(ca.DM(s.x) * xs, ca.DM(s.u) * us)

        def sub(e):
            return ca.substitute(e, old, new)

        c = float(s.cost)
        xdot = sub(model.xdot) / ca.DM(s.x)
        new_cost = CostSpec(
            stage_terms=tuple(sub(e) / c for e in cost.stage_terms),
            stage_least_squares=tuple(LeastSquares(sub(t.residual), readonly(np.asarray(t.weights) / c))
                                      for t in cost.stage_least_squares),
            terminal_terms=tuple(sub(e) / c for e in cost.terminal_terms),
            terminal_least_squares=tuple(LeastSquares(sub(t.residual), readonly(np.asarray(t.weights) / c))
                                         for t in cost.terminal_least_squares))

        def rows(blocks, d):
            out, start = [], 0
            for b in blocks:
                n = b.lb.size
                db = d[start:start + n]
                start += n
                out.append(dataclasses.replace(b, expr=sub(b.expr) / ca.DM(db), lb=readonly(b.lb / db),
                                               ub=readonly(b.ub / db), soft=_soft(b.soft, db, c), scale=None,
                                               scale_controls=None))
            return tuple(out)

        eq = np.asarray(con.terminal_equality, dtype=bool)
        r_all = np.zeros(eq.size)
        r_all[~eq], r_all[eq] = s.r, s.r_eq
        new_con = ConstraintSpec(lbx=readonly(con.lbx / s.x), ubx=readonly(con.ubx / s.x),
                                 lbu=readonly(con.lbu / s.u), ubu=readonly(con.ubu / s.u),
                                 path=rows(con.path, s.g), terminal=rows(con.terminal, r_all),
                                 soft_x=_soft(con.soft_x, s.x, c))
    except OcpError:
        raise
    except Exception as exc:  # noqa: BLE001 - CasADi on user expressions
        raise OcpError(f"scaling: cannot transcribe the problem: {exc}") from None
    new_model = ModelSpec(states=states, controls=controls, parameters=model.parameters, xdot=xdot,
                          integrator=model.integrator, p_default=model.p_default, p_trajectory=model.p_trajectory,
                          memory=model.memory)
    return dataclasses.replace(
        spec, model=new_model, cost=new_cost, constraints=new_con, x0=readonly(spec.x0 / s.x),
        guess=GuessSpec(x=readonly(spec.guess.x / s.x), u=readonly(spec.guess.u / s.u)),
        scenario=ScenarioPart(disturbance=None, closed_loop=None), scaling=None)
