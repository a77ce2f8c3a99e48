"""Ctrl-C (SIGINT) that stops a command, even where CasADi catches it.

CasADi checks for Ctrl-C inside its long computations (IPOPT, CVODES, building a
function) and turns it into a failure of that computation: IPOPT returns the status
``NonIpopt_Exception_Thrown``, the integrator raises a ``RuntimeError``. Without care a
Ctrl-C during the offline solve of ``generate`` reads as "the IPOPT solve did not
converge", and a Ctrl-C during a closed-loop run as a plant failure.

:func:`handling` (around every verb of ``dopus-gen``) replaces Python's SIGINT handler by
one that records the interrupt before raising ``KeyboardInterrupt`` as usual. The code
after a CasADi call that can fail this way calls :func:`check`, which raises
``KeyboardInterrupt`` again when an interrupt was recorded, so the failure is reported as
what it is; ``dopus-gen`` exits with :data:`EXIT_INTERRUPTED` and the line
``interrupted``. Outside :func:`handling`, :func:`check` does nothing.

:func:`deferred` holds the ``KeyboardInterrupt`` of a SIGINT back to the end of a block: for
calls that do not survive one raised in their middle (dask's client waits in its event
loop; interrupted, it logs a traceback of its own).
"""
from __future__ import annotations

import signal
import threading

import contextlib

__all__ = ["EXIT_INTERRUPTED", "handling", "interrupted", "check", "deferred"]

#: The exit code of a command stopped by SIGINT (128 + the signal number, as a shell gives).
EXIT_INTERRUPTED = 128 + int(signal.SIGINT)

_SEEN = threading.Event()
_STATE = {"hits": 0, "deferring": 0}


def _handler(signum, frame):
    _SEEN.set()
    _STATE["hits"] += 1
    if not _STATE["deferring"]:
        raise KeyboardInterrupt


@contextlib.contextmanager
def handling():
    """Record every SIGINT of this process for the time of the block (called from the main
    thread; elsewhere nothing is changed); the previous handler is restored after it."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    _SEEN.clear()
    previous = signal.signal(signal.SIGINT, _handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        _SEEN.clear()


def interrupted() -> bool:
    """True once a SIGINT arrived inside :func:`handling`."""
    return _SEEN.is_set()


def check() -> None:
    """Raise ``KeyboardInterrupt`` if a SIGINT arrived (one that CasADi caught and turned
    into a failure of its computation)."""
    if _SEEN.is_set():
        raise KeyboardInterrupt


@contextlib.contextmanager
def deferred():
    """Inside the block a SIGINT (under :func:`handling`) is recorded but its
    ``KeyboardInterrupt`` raised only when the block ends, and only if it arrived inside
    it (not while the block unwinds an exception)."""
    hits = _STATE["hits"]
    _STATE["deferring"] += 1
    try:
        yield
    finally:
        _STATE["deferring"] -= 1
    if _STATE["hits"] != hits:
        raise KeyboardInterrupt
