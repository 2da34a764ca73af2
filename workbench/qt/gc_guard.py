"""Cyclic garbage collection on the GUI thread only.

Python's cyclic collector runs in whichever thread happens to allocate.  If
that is a worker thread and the garbage holds Qt objects (a closed dialog,
lambdas connected to signals), shiboken destroys their wrappers off the GUI
thread and corrupts its binding table; the process crashes later in
``QWidget::~QWidget`` (seen intermittently under Xvfb).  :func:`install`
switches automatic collection off and lets a GUI-thread timer collect
whenever the collector's own thresholds are exceeded — the same thresholds,
just always on the right thread.
"""

from __future__ import annotations

import gc

from PySide6.QtCore import QObject, QTimer

INTERVAL_MS = 500

_COLLECTOR: GuiThreadCollector | None = None


class GuiThreadCollector(QObject):
    """See the module docstring; one per process (:func:`install`)."""

    def __init__(self, interval_ms: int = INTERVAL_MS) -> None:
        super().__init__()
        gc.disable()
        self.timer = QTimer(self)
        self.timer.timeout.connect(self.check)
        self.timer.start(interval_ms)

    def check(self) -> None:
        """Collect the generations whose allocation counts passed their thresholds."""
        counts, thresholds = gc.get_count(), gc.get_threshold()
        for generation in (2, 1, 0):
            if counts[generation] > thresholds[generation]:
                gc.collect(generation)
                return


def install() -> GuiThreadCollector:
    """Start the collector (idempotent; call on the GUI thread)."""
    global _COLLECTOR
    if _COLLECTOR is None:
        _COLLECTOR = GuiThreadCollector()
    return _COLLECTOR
