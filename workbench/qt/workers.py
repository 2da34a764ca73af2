"""Background work for the window: worker threads, results back on the GUI thread.

Workers run plain functions (:mod:`workbench.services.reconstruction.case_steps`, services) that return
values; they never touch the case, Qt widgets or VTK, and hold no reference
to a Qt object (``fn`` must close over data only).  The result (or the
error) goes back through :mod:`workbench.qt.relay`, so the callback runs on
the GUI thread, which applies it through a command.

Channels
--------
Each job has a *channel* name ("suggest", "dowels", "fit", "open" ...).
Submitting again on a channel supersedes the earlier job: its result is
dropped when it arrives (a live preview only shows the newest state).

Cancellation and progress (opt-in)
----------------------------------
Every job gets a :class:`~workbench.core.cancel.CancelToken` (returned by
:meth:`TaskRunner.submit`).  :meth:`TaskRunner.cancel` drops the pending
result of a channel at once, updates the busy state and sets the token;
superseding a job sets its token too.  A job that wants to stop early
either checks a token it was given (``token=``) or asks for a progress
callback (``progress=True``): ``fn`` is then called as ``fn(report)`` and
``report(step, fraction)`` both checks the token (raising
:class:`~workbench.core.errors.Cancelled`) and forwards the progress to the
GUI thread as :attr:`TaskRunner.progress_changed` (queued signal,
``fraction`` of the whole job, 0..1).  Jobs that opt in and are cancelled
before they start are not run at all; plain ``fn()`` jobs always run (their
side effects, e.g. an export, happen even if their result is dropped).
"""

from __future__ import annotations

import contextlib
import importlib
import itertools
import os
import threading
import time
import traceback
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

from PySide6.QtCore import QObject, Signal
from PySide6.QtWidgets import QProgressBar

from workbench.core import helper_process
from workbench.core.cancel import CancelToken
from workbench.core.errors import Cancelled
from workbench.qt import relay

#: a determinate progress bar runs 0..BAR_STEPS
BAR_STEPS = 1000


@dataclass
class _Job:
    """GUI-thread side of a job (it holds the callbacks, which reach Qt objects)."""

    channel: str
    generation: int
    on_done: Callable[[Any], None]
    on_error: Callable[[BaseException], None] | None
    token: CancelToken
    cooperative: bool = False
    started: float = field(default_factory=time.perf_counter)


@dataclass
class _Work:
    """Worker-thread side of a job: plain data only (see :mod:`workbench.qt.relay`)."""

    key: int  # the runner's relay key
    job_id: int
    fn: Callable[..., Any]
    progress: bool
    cooperative: bool
    token: CancelToken
    last_report: tuple[str, float] = ("", -1.0)


class TaskRunner(QObject):
    """Runs callables in background threads; see the module docstring.

    Signals
    -------
    busy_changed(bool, str)
        True with a description when work starts, False when all is done.
    progress_changed(str, str, float)
        ``(channel, step, fraction)`` of the current job of a channel that
        asked for progress (GUI thread; reports of superseded or cancelled
        jobs are dropped).
    cancelled(str)
        A channel's pending job was cancelled with :meth:`cancel`.
    """

    busy_changed = Signal(bool, str)
    progress_changed = Signal(str, str, float)
    cancelled = Signal(str)

    def __init__(self, parent: QObject | None = None, max_workers: int = 2) -> None:
        super().__init__(parent)
        self._pool = ThreadPoolExecutor(
            max_workers=max_workers, thread_name_prefix="workbench", initializer=background_priority
        )
        self._generation: dict[str, int] = {}
        self._pending: dict[str, Future] = {}
        self._tokens: dict[str, CancelToken] = {}
        self._jobs: dict[int, _Job] = {}
        self._ids = itertools.count(1)
        self.timings: dict[str, float] = {}
        self._key = relay.register(self._on_posted)

    @property
    def busy(self) -> bool:
        return bool(self._pending)

    def is_running(self, channel: str) -> bool:
        return channel in self._pending

    def token(self, channel: str) -> CancelToken | None:
        """The cancel token of the channel's pending job (None when idle)."""
        return self._tokens.get(channel) if channel in self._pending else None

    def submit(
        self,
        channel: str,
        description: str,
        fn: Callable[..., Any],
        on_done: Callable[[Any], None],
        on_error: Callable[[BaseException], None] | None = None,
        *,
        progress: bool = False,
        token: CancelToken | None = None,
    ) -> CancelToken:
        """Run ``fn`` in a worker; ``on_done(result)`` / ``on_error(exc)`` on the GUI thread.

        Parameters
        ----------
        progress : bool
            Call ``fn(report)`` with a ``report(step, fraction)`` callback
            that checks the job's token and emits :attr:`progress_changed`;
            otherwise ``fn()``.
        token : CancelToken, optional
            Use this token (e.g. one ``fn`` already closes over) instead of a new one.

        Returns
        -------
        CancelToken
            Set by :meth:`cancel`, by a newer job on the same channel and by
            :meth:`shutdown`.  A job that ends with
            :class:`~workbench.core.errors.Cancelled` never calls ``on_error``.
        """
        old = self._tokens.get(channel)
        if old is not None and channel in self._pending:
            old.cancel("superseded by a newer job")
        generation = self._generation.get(channel, 0) + 1
        self._generation[channel] = generation
        token = token if token is not None else CancelToken()
        job = _Job(
            channel, generation, on_done, on_error, token, cooperative=progress or token is not None
        )
        job_id = next(self._ids)
        self._jobs[job_id] = job
        self._tokens[channel] = token
        work = _Work(self._key, job_id, fn, progress, job.cooperative, token)
        self._pending[channel] = self._pool.submit(_run, work)
        self.busy_changed.emit(True, description)
        return token

    def cancel(self, channel: str) -> bool:
        """Cancel the channel's pending job; False if nothing was pending.

        The result is dropped at once (``on_done``/``on_error`` are never
        called), the busy state is updated, and the job's token is set so a
        cooperative job stops at its next check.
        """
        future = self._pending.pop(channel, None)
        if future is None:
            return False
        self._generation[channel] = self._generation.get(channel, 0) + 1
        token = self._tokens.pop(channel, None)
        if token is not None:
            token.cancel(f"{channel} cancelled")
        future.cancel()  # only succeeds if it has not started
        self.cancelled.emit(channel)
        if not self._pending:
            self.busy_changed.emit(False, "")
        return True

    # ------------------------------------------------------------ GUI side
    def _is_current(self, job: _Job) -> bool:
        return self._generation.get(job.channel) == job.generation and job.channel in self._pending

    def _on_posted(self, payload: tuple) -> None:
        """A worker's message (GUI thread): ``("progress", id, step, f)`` or ``("done", id, result, error)``."""
        kind, job_id, a, b = payload
        if kind == "progress":
            job = self._jobs.get(job_id)
            if job is not None and self._is_current(job):
                self.progress_changed.emit(job.channel, a, b)
            return
        job = self._jobs.pop(job_id, None)
        if job is not None:
            self._on_delivered(job, a, b)

    def _on_delivered(self, job: _Job, result: Any, error: BaseException | None) -> None:
        current = self._is_current(job)
        if current:
            self._pending.pop(job.channel, None)
            self._tokens.pop(job.channel, None)
            self.timings[job.channel] = time.perf_counter() - job.started
        if not self._pending:
            self.busy_changed.emit(False, "")
        if not current or isinstance(error, Cancelled):
            return  # superseded by a newer job, or cancelled
        if error is None:
            job.on_done(result)
        elif job.on_error is not None:
            job.on_error(error)

    def shutdown(self) -> None:
        """Stop accepting work; cooperative jobs stop, the others finish; results are dropped."""
        self._generation = {k: v + 1 for k, v in self._generation.items()}
        for token in self._tokens.values():
            token.cancel("shut down")
        self._tokens.clear()
        self._pending.clear()
        self._jobs.clear()
        relay.unregister(self._key)
        self._pool.shutdown(wait=False, cancel_futures=True)


# ------------------------------------------------------------------ worker thread
#: modules the jobs import on first use; importing (compiling, loading a
#: shared library) holds the GIL, so the window imports them before it shows
PRELOAD = (
    "embreex.rtcore_scene",
    "embreex.mesh_construction",
    "threadpoolctl",
    "workbench.core.isosurface",
    "workbench.io.samples",
)


def preload() -> None:
    """Import :data:`PRELOAD` now (those not installed are skipped)."""
    for name in PRELOAD:
        with contextlib.suppress(ImportError):
            importlib.import_module(name)


#: nice value of worker threads (0 normal .. 19 lowest)
BACKGROUND_NICE = 10


def background_priority() -> None:
    """Set up a worker thread: lower CPU priority, GIL-heavy calls offloaded.

    Priority: VTK releases the GIL while it renders, and a software
    renderer (llvmpipe) renders on every core: a worker computing at the
    same time takes half the CPU of a 2-core machine and doubles the frame
    time, i.e. how long the event loop is blocked.  At nice 10 a worker gets
    about a tenth of a core the renderer wants and all the rest.  Linux
    keeps the nice value per thread (and threads a worker starts inherit
    it); elsewhere this is a no-op.

    Offloading: library calls that keep the GIL for long (mesh decimation,
    building the reference head) run in the helper process
    (:func:`workbench.core.helper_process.run`), so they cannot stall the
    GUI thread.
    """
    try:
        os.setpriority(os.PRIO_PROCESS, threading.get_native_id(), BACKGROUND_NICE)
    except (AttributeError, OSError):  # no setpriority (Windows), or not per thread
        pass
    # and calls that hold the GIL for long go to the helper process
    helper_process.offload_here()


def _run(work: _Work) -> None:
    """Run one job; post its result (or error) to the GUI thread.  Plain data only."""
    try:
        if work.cooperative:
            work.token.check()  # superseded or cancelled while queued
        result = (
            work.fn(lambda step, fraction: _report(work, step, fraction))
            if work.progress
            else work.fn()
        )
    except Cancelled as exc:
        relay.post(work.key, ("done", work.job_id, None, exc))
        return
    except BaseException as exc:  # noqa: BLE001 - delivered to the GUI thread, shown as a dialog
        exc.__dict__.setdefault("worker_traceback", traceback.format_exc())
        relay.post(work.key, ("done", work.job_id, None, exc))
        return
    relay.post(work.key, ("done", work.job_id, result, None))


def _report(work: _Work, step: str, fraction: float) -> None:
    work.token.check()
    last_step, last_fraction = work.last_report
    fraction = min(max(float(fraction), 0.0), 1.0)
    if step == last_step and abs(fraction - last_fraction) < 0.005 and fraction < 1.0:
        return  # throttle: at most ~200 updates per job
    work.last_report = (step, fraction)
    relay.post(work.key, ("progress", work.job_id, step, fraction))


def show_fraction(bar: QProgressBar, fraction: float, step: str = "") -> None:
    """Make ``bar`` determinate and show ``fraction`` (0..1) of the job, ``step`` as tooltip."""
    if bar.maximum() != BAR_STEPS:
        bar.setRange(0, BAR_STEPS)
    bar.setValue(round(min(max(fraction, 0.0), 1.0) * BAR_STEPS))
    if step:
        bar.setToolTip(step)
