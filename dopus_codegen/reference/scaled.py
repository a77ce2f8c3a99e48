"""The reference backend of a scaled problem: the iteration runs on the problem in the solver's
variables (``disc.scaled``), the API converts at its boundary exactly as the C runtime's does
(docs/algorithm.md section 16): measurements, guesses and the iterate's primal variables
divided or multiplied by their scales, multipliers by ``D / c``, the slacks of soft rows and
the bound of an infeasible row by their row's scale. The KKT measure is that of the solver's
variables. Everything else is the wrapped :class:`~.dopus.ReferenceDopus` itself."""
from __future__ import annotations

import numpy as np

from ..errors import DopusError

__all__ = ["ScaledReference"]


class ScaledReference:
    """A :class:`~.dopus.ReferenceDopus` of ``disc.scaled`` with the API in ``disc``'s units."""

    def __init__(self, inner, disc):
        object.__setattr__(self, "inner", inner)
        object.__setattr__(self, "disc_declared", disc)
        object.__setattr__(self, "scaling", disc.scaling)

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def __setattr__(self, name, value):
        setattr(self.inner, name, value)

    def _xin(self, xhat0):
        return None if xhat0 is None else self.scaling.x_in(np.asarray(xhat0, dtype=float).reshape(-1))

    def init(self, xhat0, guess=None) -> None:
        self.inner.init(self._xin(xhat0), None if guess is None else self.scaling.guess_in(guess))

    def feedback(self, xhat0) -> np.ndarray:
        try:
            return self.scaling.u_out(self.inner.feedback(self._xin(xhat0)))
        except DopusError as exc:
            if getattr(exc, "u0", None) is not None:
                exc.u0 = self.scaling.u_out(exc.u0)
            raise

    def kkt(self, xhat0) -> dict:
        return self.inner.kkt(self._xin(xhat0))

    def qp_of_current(self, xhat0=None) -> dict:
        return self.inner.qp_of_current(self._xin(xhat0))

    @property
    def x(self):
        return self.scaling.x_out(self.inner.x)

    @property
    def u(self):
        return self.scaling.u_out(self.inner.u)

    @property
    def lam(self):
        return self.scaling.dual_out(self.inner.lam, self.scaling.x)

    @property
    def mu_g(self):
        return self.scaling.dual_out(self.inner.mu_g, self.scaling.g)

    @property
    def mu_b(self):
        return self.scaling.dual_out(self.inner.mu_b, self.scaling.w)

    @property
    def mu_bN(self):
        return self.scaling.dual_out(self.inner.mu_bN, self.scaling.x)

    @property
    def mu_r(self):
        return self.scaling.dual_out(self.inner.mu_r, self.scaling.r)

    @property
    def nu(self):
        return self.scaling.dual_out(self.inner.nu, self.scaling.r_eq)

    def guess(self):
        return self.scaling.guess_out(self.inner.guess())

    def soft_slacks(self) -> dict:
        out = self.inner.soft_slacks()
        sc = self.scaling
        out = {"x": out["x"] * sc.x, "g": out["g"] * sc.g, "r": out["r"] * sc.r}
        out["max"] = float(max(out["x"].max(initial=0.0), out["g"].max(initial=0.0), out["r"].max(initial=0.0)))
        return out

    @property
    def qp_infeasible_row(self):
        row = self.inner.qp_infeasible_row
        if row is None:
            return None
        sc = self.scaling
        d = {"state": sc.x, "control": sc.u, "path": sc.g, "terminal": sc.r, "terminal_eq": sc.r_eq}[row["kind"]]
        return dict(row, bound=float(row["bound"] * d[row["index"]]))
