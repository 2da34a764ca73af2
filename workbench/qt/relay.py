"""One process-wide relay that carries results from worker threads to the GUI thread.

Why: a worker thread must never drop the last reference to a Qt object's
Python wrapper (a window, a runner, a bound method of either).  If it does,
shiboken destroys the wrapper on the worker thread, which corrupts its
binding table; the crash comes later, when Qt deletes the widget tree
(observed under Xvfb: ``Shiboken::BindingManager::unregisterWrapper``
segfaults in ``QWidget::~QWidget``).  So workers hold only plain data — a
handler *key* (an int), the job's function and its result — and post
``(key, payload)`` here.  The relay object itself is created once on the GUI
thread and never released; its slot runs on the GUI thread (a queued
connection, since it lives there) and calls the handler registered for the
key, if its owner still exists (handlers are held weakly).
"""

from __future__ import annotations

import itertools
import weakref
from collections.abc import Callable
from typing import Any

from PySide6.QtCore import QObject, Signal, Slot


class _Relay(QObject):
    posted = Signal(int, object)

    def __init__(self) -> None:
        super().__init__()
        self.handlers: dict[int, weakref.WeakMethod | Callable[[], Any]] = {}
        self.posted.connect(self._dispatch)

    @Slot(int, object)
    def _dispatch(self, key: int, payload: object) -> None:
        ref = self.handlers.get(key)
        handler = ref() if ref is not None else None
        if handler is None:
            self.handlers.pop(key, None)
            return
        handler(payload)


_RELAY: _Relay | None = None
_KEYS = itertools.count(1)


def _relay() -> _Relay:
    global _RELAY
    if _RELAY is None:
        _RELAY = _Relay()  # first use is on the GUI thread (a window or runner being built)
    return _RELAY


def register(handler: Callable[[Any], None]) -> int:
    """GUI thread: a key that workers can :func:`post` to; ``handler(payload)`` runs here.

    A bound method is held weakly (its object may go away); anything else strongly.
    """
    relay = _relay()
    key = next(_KEYS)
    if hasattr(handler, "__self__") and hasattr(handler, "__func__"):
        relay.handlers[key] = weakref.WeakMethod(handler)
    else:

        def strong() -> Callable[[Any], None]:
            return handler

        relay.handlers[key] = strong
    return key


def unregister(key: int) -> None:
    """GUI thread: posts to ``key`` are dropped from now on."""
    if _RELAY is not None:
        _RELAY.handlers.pop(key, None)


def post(key: int, payload: object) -> None:
    """Any thread: deliver ``payload`` to the handler of ``key`` on the GUI thread."""
    relay = _RELAY
    if relay is not None:
        relay.posted.emit(key, payload)
