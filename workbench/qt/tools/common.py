"""Small helpers more than one tool uses (no Qt widgets here)."""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path
from typing import Any


def folder_is_free(folder: str | Path) -> bool:
    """True when ``folder`` does not exist or is an empty folder."""
    path = Path(folder)
    return not os.path.lexists(path) or (path.is_dir() and not any(path.iterdir()))


class CaseLayersAside:
    """The case's layers (skull, landmarks, face ...) hidden while a tool with heads of its
    own is in front, and shown again when it is left (unless the user changed one meanwhile).

    The age and animate tools draw heads in their own head frame, not the specimen's: the
    two are never shown together (issue 33: the tools' heads stayed on screen after).

    Every tool of one view shares one record (kept on the scene): the layers are hidden
    when the first tool comes to the front and shown again only when the last one has
    left.  Two tools switching places (one tab to another) may report in either order; a
    tool leaving after the next one came must not bring the case's face back under the
    next tool's head.
    """

    def __init__(self, scene: Any) -> None:
        self.scene = scene

    def _shared(self) -> tuple[set[int], list[str]]:
        record = getattr(self.scene, "_case_layers_aside", None)
        if record is None:
            record = (set(), [])
            self.scene._case_layers_aside = record
        return record

    @property
    def hidden(self) -> list[str]:
        """The layers this view's tools have hidden (shown again when the last one leaves)."""
        return self._shared()[1]

    def set_aside(self, aside: bool) -> None:
        scene = self.scene
        owners, hidden = self._shared()
        if aside:
            first = not owners
            owners.add(id(self))
            if not first:
                return
            for layer, visible in scene.visible.items():
                if visible and scene.has(layer):
                    scene.set_visible(layer, False)
                    hidden.append(layer)
            return
        if id(self) not in owners:
            return
        owners.discard(id(self))
        if owners:
            return  # another tool with heads of its own is still in front
        for layer in hidden:  # unless the user showed or hid it meanwhile
            if not scene.visible.get(layer, True):
                scene.set_visible(layer, True)
        hidden.clear()


class HairGrower:
    """Grows the hair a case chose on a head in the window's worker, once per head and choice.

    The grooming service keeps grown pieces (:func:`workbench.services.grooming.head_grooming`);
    :meth:`ready` says whether they are there, and if not asks the worker for them (one job
    per head and choice at a time) and calls ``done`` on the GUI thread when they are.  The
    main view's hair layer, the Age dock and the Animate dock each hold one.  Without a
    worker (``runner`` None) the hair is grown at once.
    """

    def __init__(
        self,
        runner: Any,
        channel: str,
        done: Callable[[], None],
        failed: Callable[[BaseException], None] | None = None,
    ) -> None:
        self.runner, self.channel, self.done, self.failed = runner, channel, done, failed
        self._growing: tuple[int, Any] | None = None

    def ready(self, head: Any, look: Any) -> bool:
        """The pieces of ``look`` (an Appearance) are grown on ``head``; else ask for them."""
        from workbench.services.grooming import grooming_ready, head_grooming

        if grooming_ready(head, look):
            return True
        if self.runner is None:
            head_grooming(head, look)
            return True
        key = (id(head), look.grooming)  # (a head compares by its arrays: by identity here)
        if self._growing != key:
            self._growing = key
            self.runner.submit(
                self.channel,
                "Growing the hair and brows …",
                lambda: head_grooming(head, look),
                self._grown,
                self._failed,
            )
        return False

    def _grown(self, _grown: Any) -> None:
        self._growing = None
        self.done()

    def _failed(self, exc: BaseException) -> None:
        self._growing = None
        if self.failed is not None:
            self.failed(exc)
