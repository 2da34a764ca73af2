"""Bone surfaces: the specimen skull and the CT dialog's iso-surface preview."""

from __future__ import annotations

from typing import Any

from workbench.core.mesh import Mesh
from workbench.render.snapshots import to_polydata
from workbench.render.visuals.style import BONE, SMOOTH

#: the pieces of a CT preview that the extraction would drop
DEBRIS = (0.55, 0.57, 0.62)
#: actor name → (colour, opacity) of the two parts of a CT preview
ISO_PARTS = {"ct_preview": (BONE, 1.0), "ct_debris": (DEBRIS, 0.45)}


def add_skull(plotter: Any, surface: Mesh | Any, *, name: str, pickable: bool) -> Any:
    """The skull in bone colour, smooth-shaded from its own normals; returns the actor.

    ``surface`` is a :class:`Mesh` (its cached vertex normals are used) or a
    ``pyvista.PolyData`` made by ``to_polydata(mesh, normals=True)`` beforehand.
    """
    poly = to_polydata(surface, normals=True) if isinstance(surface, Mesh) else surface
    return plotter.add_mesh(poly, color=BONE, **SMOOTH, pickable=pickable, name=name, render=False)


def add_iso_part(plotter: Any, name: str, mesh: Mesh) -> Any:
    """One part of the CT preview (``name`` a key of :data:`ISO_PARTS`), replacing the
    actor of that name; the camera stays where the user put it."""
    colour, opacity = ISO_PARTS[name]
    return plotter.add_mesh(
        to_polydata(mesh),
        color=colour,
        opacity=opacity,
        smooth_shading=True,
        name=name,
        pickable=False,
        render=False,
        reset_camera=False,
    )
