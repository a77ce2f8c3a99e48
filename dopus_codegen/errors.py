"""The one error class of both DOPUS backends.

:class:`DopusError` carries ``status``, a code of ``enum dopus_status`` (read from
runtime_c/dopus_solver.h by :mod:`dopus_codegen.vocabulary`), and for a failed QP
``qp_status``, a code of ``enum dopus_qp_status``. The generated C solver
(:class:`~dopus_codegen.runtime.solver.Solver`) and the numpy reference
(:class:`~dopus_codegen.reference.dopus.ReferenceDopus`) raise it with the same codes for
the same failure. It is a ``RuntimeError`` (a call failed) and a ``ValueError`` (most
failures are bad input).
"""
from __future__ import annotations

from typing import Optional

from . import vocabulary

__all__ = ["DopusError", "status_code", "status_name", "qp_status_code", "qp_status_name", "qp_failure_text"]


def status_code(name: str) -> int:
    """The code of ``enum dopus_status`` named ``name`` (``"qp"``, ``"nonfinite_input"``, ...)."""
    return vocabulary.status()[name]


def status_name(code: int) -> str:
    return vocabulary.status().name(code)


def qp_status_code(name: str) -> int:
    """The code of ``enum dopus_qp_status`` named ``name`` (``"max_iter"``, ...)."""
    return vocabulary.qp_status()[name]


def qp_status_name(code: int) -> str:
    return vocabulary.qp_status().name(code)


def qp_failure_text(name: str, iterations: Optional[int] = None, max_iter: Optional[int] = None,
                    code: Optional[int] = None) -> str:
    """Why the QP failed, in words that match its status ``name`` (``enum dopus_qp_status``,
    ``code`` its value): the iteration limit is named with its value, a stall with the
    iterations it took; ends with ``(QP status <code> (<name>))``."""
    its = "" if iterations is None else f" after {int(iterations)} iterations"
    tag = f"(QP status {name})" if code is None else f"(QP status {int(code)} ({name}))"
    if name == "max_iter":
        limit = f" of {int(max_iter)}" if max_iter is not None else ""
        return f"the QP solver reached its iteration limit{limit}{its} {tag}"
    if name == "stalled":
        return f"the QP solver stalled{its}: no progress in its KKT residuals {tag}"
    if name == "primal_infeasible":
        return f"the QP is infeasible{its} {tag}"
    if name == "dual_infeasible":
        return f"the QP is unbounded below{its} {tag}"
    if name == "numerical":
        return f"the QP solver failed numerically{its} {tag}"
    return f"the QP failed{its} {tag}"


class DopusError(RuntimeError, ValueError):
    """A call of a DOPUS backend failed. ``status``: the code of ``enum dopus_status``;
    ``qp_status``: the code of ``enum dopus_qp_status`` when the QP failed, else None. The
    iterate is unchanged by the failing call (docs/algorithm.md section 4)."""

    def __init__(self, message: str, status: int, qp_status: Optional[int] = None):
        super().__init__(message)
        self.status = int(status)
        self.qp_status = None if qp_status is None else int(qp_status)

    @property
    def status_name(self) -> str:
        return status_name(self.status)

    @property
    def qp_status_name(self) -> Optional[str]:
        return None if self.qp_status is None else qp_status_name(self.qp_status)

    @classmethod
    def of(cls, name: str, message: str, qp_status: Optional[str] = None) -> "DopusError":
        """The error of status ``name`` (and QP status ``qp_status``, by name)."""
        return cls(message, status_code(name), None if qp_status is None else qp_status_code(qp_status))
