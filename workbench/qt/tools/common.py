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
    """

    def __init__(self, scene: Any) -> None:
        self.scene = scene
        self.hidden: list[str] = []

    def set_aside(self, aside: bool) -> None:
        scene = self.scene
        if aside:
            for layer, visible in scene.visible.items():
                if visible and scene.has(layer):
                    scene.set_visible(layer, False)
                    self.hidden.append(layer)
            return
        for layer in self.hidden:  # unless the user showed or hid it meanwhile
            if not scene.visible.get(layer, True):
                scene.set_visible(layer, True)
        self.hidden.clear()
