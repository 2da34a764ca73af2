"""Surfaces of the reference head that targets are matched against (head frame, mm)."""

from __future__ import annotations

from workbench.core.mesh import Mesh, concatenate
from workbench.model.template import TemplateHead

#: the parts a scanned or CT skull shows: vault, face, jaw and teeth
SKULL_PARTS = ("cranium", "mandible", "upper_teeth", "lower_teeth")


def skull_surface(head: TemplateHead, *, with_mandible: bool = True) -> Mesh:
    """The reference skull as a scanner would see it (cranium, mandible, teeth)."""
    parts = [p for p in SKULL_PARTS if with_mandible or p in ("cranium", "upper_teeth")]
    return concatenate([head.meshes[p] for p in parts])
