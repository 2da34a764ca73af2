"""Procedural reference head (Kähler 2003, ch. 5.1): skin, skull, eyes, teeth.

Skin (:mod:`.skin`): authored as data (a symmetric control mesh with named
feature vertices, ``data_tables/template/skin_control_mesh.json``) and code
(Loop subdivision with boundary rules, :mod:`.subdivision`, and an
anthropometric landmark warp).  Everything is in millimetres in the head frame
of :mod:`workbench.core.frame` (x to the subject's left, y up, z forward,
Frankfort Horizontal y = 0, origin between the porions).

Submodules are imported lazily, so importing one part (say the skull) never
pulls in the others.
"""

from __future__ import annotations

from importlib import import_module
from typing import Any

_LAZY = {
    "SkinTemplate": "workbench.core.headgen.skin",
    "build_skin": "workbench.core.headgen.skin",
    "load_control_mesh": "workbench.core.headgen.skin",
    "loop_subdivide": "workbench.core.headgen.subdivision",
    "loop_step": "workbench.core.headgen.subdivision",
}

__all__ = sorted(_LAZY)


def __getattr__(name: str) -> Any:
    if name in _LAZY:
        return getattr(import_module(_LAZY[name]), name)
    raise AttributeError(f"module 'workbench.core.headgen' has no attribute {name!r}")
