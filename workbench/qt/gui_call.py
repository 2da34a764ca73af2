"""Running a function on the GUI thread from a worker, and waiting for it.

VTK draws only on the GUI thread (ARCHITECTURE.md §3.4), but a pipeline run in
the window's worker writes its pictures half-way through writing its folder
(the folder is staged and renamed as a whole).  :class:`GuiCall` gives the
worker a stand-in for the drawing function that runs it on the GUI thread
(through :mod:`workbench.qt.relay`) and waits, so the pipeline still writes
its folder in one piece.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from workbench.qt import relay


class GuiCall:
    """Lets a worker run a function on the GUI thread and wait for its result.

    Made on the GUI thread; :meth:`wrap` gives the worker a stand-in for
    ``fn`` that posts the call through :mod:`workbench.qt.relay` (plain data:
    the function, its arguments, a box and an event) and waits, checking
    ``report`` (which raises :class:`~workbench.core.errors.Cancelled` when
    the job is cancelled or the window shuts down) while it waits.
    """

    def __init__(self) -> None:
        self._key = relay.register(self._run)
        self.runs = 0

    def _run(self, payload: Any) -> None:
        fn, args, box, done = payload
        try:
            box.append((True, fn(*args)))
        except BaseException as exc:  # noqa: BLE001 - handed back to the waiting worker
            box.append((False, exc))
        finally:
            self.runs += 1
            done.set()

    def wrap(
        self, fn: Callable[..., Any], report: Callable[[str, float], None] | None, step: str
    ) -> Callable[..., Any]:
        key = self._key

        def on_gui_thread(*args: Any) -> Any:
            box: list[tuple[bool, Any]] = []
            done = threading.Event()
            relay.post(key, (fn, args, box, done))
            while not done.wait(0.1):
                if report is not None:
                    report(step, 0.96)
            ok, value = box[0]
            if not ok:
                raise value
            return value

        return on_gui_thread

    def close(self) -> None:
        relay.unregister(self._key)
