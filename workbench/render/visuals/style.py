"""The palette and shading shared by the visuals (RGB in 0–1)."""

from __future__ import annotations

from typing import Any

BONE = (0.93, 0.89, 0.80)
SKIN = (0.91, 0.72, 0.60)
#: smooth shading from the point normals a mesh brings (``to_polydata(mesh,
#: normals=True)``): pyvista's ``smooth_shading=True`` would run VTK's normals
#: filter on the GUI thread each time (80 ms for a 100k-triangle skull)
SMOOTH: dict[str, Any] = {"smooth_shading": False, "interpolation": "phong"}


def cull_back_faces(actor: Any) -> Any:
    """Hide ``actor``'s back faces and return it.

    The views blend translucent surfaces unsorted (no order-independent
    transparency, which costs ~15 ms a frame on a software renderer); one
    translucent surface with its back faces culled looks the same.
    """
    actor.GetProperty().BackfaceCullingOn()
    return actor


#: the background of the 3D views: a vertical gradient, lighter at the top
BACKGROUND = ("#2b2f36", "#59606b")
#: the guide view's plain, darker background
GUIDE_BACKGROUND = "#1f2329"


def set_view_background(plotter: Any, *, guide: bool = False) -> None:
    """Paint the background of a 3D view (:data:`BACKGROUND`, or the guide view's)."""
    if guide:
        plotter.set_background(GUIDE_BACKGROUND)
    else:
        bottom, top = BACKGROUND
        plotter.set_background(bottom, top=top)
