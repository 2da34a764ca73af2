"""Surfaces of the reference head that targets are matched against (head frame, mm)."""

from __future__ import annotations

import numpy as np

from workbench.core.mesh import Mesh
from workbench.model.template import TemplateHead

#: the parts a scanned or CT skull shows: vault, face, jaw and teeth
SKULL_PARTS = ("cranium", "mandible", "upper_teeth", "lower_teeth")


def combine(meshes: list[Mesh]) -> Mesh:
    """One mesh holding ``meshes`` in order (vertex ids offset, nothing merged)."""
    offsets = np.cumsum([0] + [m.n_vertices for m in meshes[:-1]])
    return Mesh(np.vstack([m.vertices for m in meshes]),
                np.vstack([m.faces + o for m, o in zip(meshes, offsets, strict=True)]))


def skull_surface(head: TemplateHead, *, with_mandible: bool = True) -> Mesh:
    """The reference skull as a scanner would see it (cranium, mandible, teeth)."""
    parts = [p for p in SKULL_PARTS if with_mandible or p in ("cranium", "upper_teeth")]
    return combine([head.meshes[p] for p in parts])
