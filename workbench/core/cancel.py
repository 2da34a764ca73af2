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
"""

from __future__ import annotations

import threading
from collections.abc import Callable

from workbench.core.errors import Cancelled

__all__ = ["CancelToken", "Cancelled", "checking"]

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
