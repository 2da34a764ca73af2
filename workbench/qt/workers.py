"""Background work for the window: one worker thread, results back on the GUI thread.

Workers run plain functions (:mod:`workbench.qt.jobs`) that return values;
they never touch the case, Qt widgets or VTK.  The result (or the error) is
delivered through a queued Qt signal, so the callback runs on the GUI thread,
which applies it through a command.

Each job has a *channel* name ("suggest", "dowels", "fit" ...).  Submitting
again on a channel supersedes the earlier job: its result is dropped when
it arrives (a live preview only shows the newest state).
"""

from __future__ import annotations

import time
import traceback
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

from PySide6.QtCore import QObject, Signal


@dataclass
class _Job:
    channel: str
    generation: int
    on_done: Callable[[Any], None]
    on_error: Callable[[BaseException], None] | None
    started: float = field(default_factory=time.perf_counter)


class TaskRunner(QObject):
    """Runs callables in background threads; see the module docstring.

    Signals
    -------
    busy_changed(bool, str)
        True with a description when work starts, False when all is done.
    """

    busy_changed = Signal(bool, str)
    _delivered = Signal(object, object, object)  # job, result, error

    def __init__(self, parent: QObject | None = None, max_workers: int = 2) -> None:
        super().__init__(parent)
        self._pool = ThreadPoolExecutor(max_workers=max_workers, thread_name_prefix="workbench")
        self._generation: dict[str, int] = {}
        self._pending: dict[str, Future] = {}
        self.timings: dict[str, float] = {}
        self._delivered.connect(self._on_delivered)

    @property
    def busy(self) -> bool:
        return bool(self._pending)

    def is_running(self, channel: str) -> bool:
        return channel in self._pending

    def submit(self, channel: str, description: str, fn: Callable[[], Any],
               on_done: Callable[[Any], None],
               on_error: Callable[[BaseException], None] | None = None) -> None:
        """Run ``fn()`` in a worker; ``on_done(result)`` / ``on_error(exc)`` on the GUI thread."""
        generation = self._generation.get(channel, 0) + 1
        self._generation[channel] = generation
        job = _Job(channel, generation, on_done, on_error)
        self._pending[channel] = self._pool.submit(self._run, job, fn)
        self.busy_changed.emit(True, description)

    def _run(self, job: _Job, fn: Callable[[], Any]) -> None:
        try:
            result = fn()
        except BaseException as exc:  # delivered to the GUI thread, shown as a dialog
            exc.__dict__.setdefault("worker_traceback", traceback.format_exc())
            self._emit(job, None, exc)
            return
        self._emit(job, result, None)

    def _emit(self, job: _Job, result: Any, error: BaseException | None) -> None:
        try:
            self._delivered.emit(job, result, error)
        except RuntimeError:
            pass  # the window was closed while the job ran

    def _on_delivered(self, job: _Job, result: Any, error: BaseException | None) -> None:
        current = self._generation.get(job.channel) == job.generation
        if current:
            self._pending.pop(job.channel, None)
            self.timings[job.channel] = time.perf_counter() - job.started
        if not self._pending:
            self.busy_changed.emit(False, "")
        if not current:
            return  # superseded by a newer job on the same channel
        if error is None:
            job.on_done(result)
        elif job.on_error is not None:
            job.on_error(error)

    def shutdown(self) -> None:
        """Stop accepting work; running jobs finish, their results are dropped."""
        self._generation = {k: v + 1 for k, v in self._generation.items()}
        self._pending.clear()
        self._pool.shutdown(wait=False, cancel_futures=True)
