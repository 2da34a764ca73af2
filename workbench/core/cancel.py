"""Cooperative cancellation of long jobs (CT extraction, previews, fits).

A :class:`CancelToken` is shared between whoever may cancel (the GUI thread)
and the job (a worker thread).  Cancelling only sets a flag; the job stops
at its next check, normally inside its ``progress(step, fraction)``
callback, by raising :class:`Cancelled` (a
:class:`~workbench.core.errors.WorkbenchError`, so callers that show error
messages never show a traceback for it).  Nothing is interrupted in the
middle of a numerical step, so no half-written state is left behind: the
job's partial results are simply never returned.

:func:`checking` wraps a progress callback so that every report is also a
cancellation point::

    token = CancelToken()
    mesh_from_ct(path, progress=checking(token, report))   # in the worker
    token.cancel()                                          # from anywhere

No units: fractions are 0..1 of the whole job.

Ctrl-C is the other way a job ends early: Python raises ``KeyboardInterrupt``
wherever the main thread happens to be.  A few places must not be left
half-done that way: importing a compiled library that registers itself as it
loads (VTK: interrupted there, the process later dies of a segmentation
fault).  :func:`interrupts_deferred` holds Ctrl-C back for such a block and
delivers it right after.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Callable, Iterator
from types import FrameType

from workbench.core.errors import Cancelled

__all__ = ["CancelToken", "Cancelled", "checking", "interrupts_deferred"]

Progress = Callable[[str, float], None]


class CancelToken:
    """A thread-safe "please stop" flag.

    Parameters
    ----------
    reason : str
        Default message of the :class:`Cancelled` raised by :meth:`check`.
    """

    __slots__ = ("_event", "reason")

    def __init__(self, reason: str = "cancelled") -> None:
        self._event = threading.Event()
        self.reason = reason

    def cancel(self, reason: str | None = None) -> None:
        """Ask the job to stop at its next check (idempotent, any thread)."""
        if reason is not None:
            self.reason = reason
        self._event.set()

    @property
    def cancelled(self) -> bool:
        """True once :meth:`cancel` was called."""
        return self._event.is_set()

    def check(self) -> None:
        """Raise :class:`Cancelled` if the token was cancelled; else do nothing."""
        if self._event.is_set():
            raise Cancelled(self.reason)

    def wait(self, timeout: float | None = None) -> bool:
        """Block until cancelled or ``timeout`` seconds pass; True if cancelled."""
        return self._event.wait(timeout)

    def __repr__(self) -> str:
        return f"CancelToken(cancelled={self.cancelled})"


def checking(token: CancelToken | None, progress: Progress | None = None) -> Progress:
    """A progress callback that first checks ``token`` and then forwards to ``progress``."""

    def report(step: str, fraction: float) -> None:
        if token is not None:
            token.check()
        if progress is not None:
            progress(step, fraction)

    return report


@contextlib.contextmanager
def interrupts_deferred() -> Iterator[None]:
    """Hold Ctrl-C (SIGINT) back during the block; deliver it when the block ends.

    For work that must not stop half-way, e.g. importing VTK (see the module
    docstring).  A Ctrl-C meanwhile is recorded, and when the block ends the
    handler that was in place runs (normally: ``KeyboardInterrupt`` is raised
    there).  Nests.  Python runs signal handlers on the main thread only, so
    elsewhere (and where SIGINT is ignored or not handled by Python) this does
    nothing: a worker thread is never interrupted by Ctrl-C anyway.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.getsignal(signal.SIGINT)
    if not callable(previous):  # SIG_IGN, SIG_DFL or set outside Python: leave it
        yield
        return
    held: list[tuple[int, FrameType | None]] = []

    def hold(signum: int, frame: FrameType | None) -> None:
        held.append((signum, frame))

    signal.signal(signal.SIGINT, hold)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if held:
            previous(*held[0])
