"""Small helpers more than one tool uses (no Qt widgets here)."""

from __future__ import annotations

import os
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
