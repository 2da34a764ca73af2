"""Off-screen pictures of meshes (pyvista), for reports, docs and the demo.

Meshes arrive as :class:`workbench.core.mesh.Mesh` in mm; this module is the
boundary where they become ``pyvista.PolyData``.

Handedness: a "front" picture shows the subject's right on the viewer's left
and "side" the subject's right profile (the face toward the picture's
right), whatever the frame of the meshes.  A frame that is a mirror image of
the subject (its anatomy ``left`` given and left-handed, see
:class:`workbench.render.visuals.orientation.Anatomy`) is drawn from the
true side and flipped on screen; the meshes themselves are never changed.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from workbench.core.mesh import Mesh
from workbench.render.panels import each_panel, panel_row
from workbench.render.visuals.orientation import Anatomy, add_edge_letters, mirror_of

# anterior and superior directions of each named frame (head frame: x to the
# subject's left, y up, z forward)
_AXES = {
    "HEAD": ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)),
    "LPS": ((0.0, -1.0, 0.0), (0.0, 0.0, 1.0)),
    "RAS": ((0.0, 1.0, 0.0), (0.0, 0.0, 1.0)),
}


def view_directions(
    view: str,
    anterior: Sequence[float] | np.ndarray,
    superior: Sequence[float] | np.ndarray,
    left: Sequence[float] | np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Camera direction (from the focus toward the camera) and view-up for a named view.

    "front" looks at the face, "side" at the subject's right profile,
    "three_quarter" halfway between.  The directions are in the meshes'
    frame (no units); ``left``, the subject's left, tells the right side in a
    frame that may be a mirror image (without it the frame is taken as
    unmirrored: right = anterior × superior).  In a mirror-image frame the
    picture must also be flipped on screen (:func:`frame_anatomy`).
    """
    a = np.asarray(anterior, float) / np.linalg.norm(anterior)
    s = np.asarray(superior, float) / np.linalg.norm(superior)
    right = np.cross(a, s)
    if Anatomy.of(a, s, left).mirrored:
        right = -right
    directions = {"front": a, "side": right, "three_quarter": (a + right) / np.sqrt(2.0)}
    if view not in directions:
        raise ValueError(f"unknown view {view!r}; use one of {sorted(directions)}")
    return directions[view], s


def frame_anatomy(
    frame: str = "HEAD", orientation: Sequence[Sequence[float] | np.ndarray] | None = None
) -> Anatomy:
    """The subject's directions in the meshes' frame: a named frame ("HEAD", "LPS", "RAS")
    or ``orientation`` = ``(anterior, superior[, left])`` (a mirror image when ``left`` says so)."""
    if orientation is not None:
        a, s, *rest = orientation
        return Anatomy.of(a, s, rest[0] if rest else None)
    return Anatomy.of(*_AXES[frame])


def show_handedness(renderer: Any, anatomy: Anatomy, letters: bool = True) -> None:
    """After the camera is set: flip a mirror-image frame's picture on screen (so the
    subject's right is on the viewer's left) and, with ``letters``, name the subject's sides
    at the picture's left and right edges (R/L, or A/P in a profile)."""
    mirror_of(renderer).flip_screen(anatomy.mirrored)
    if letters:
        add_edge_letters(renderer, anatomy)


def _prefer_headless_gl() -> None:
    """Without an X display, ask VTK for its EGL window directly.

    VTK >= 9.4 would otherwise try X first, print a warning, then fall back.
    """
    if not os.environ.get("DISPLAY") and not os.environ.get("WAYLAND_DISPLAY"):
        os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")


def to_polydata(mesh: Mesh, *, normals: bool = False):
    """``mesh`` as ``pyvista.PolyData`` (mm, same frame).

    The points are a copy: moving them (a view's in-place update) leaves ``mesh`` as it
    was.  With ``normals`` the mesh's cached :attr:`Mesh.vertex_normals` become the
    active point normals, so a renderer can shade it smoothly (Gouraud)
    without running VTK's normals filter on the drawing thread.
    """
    import pyvista as pv

    faces = np.asarray(mesh.faces, np.int64)
    # a copy of the points: VTK wraps a float64 array without copying, and a view that
    # moves drawn points in place (the build slider, a drag) would move the mesh itself
    poly = pv.PolyData.from_regular_faces(
        np.array(mesh.vertices, dtype=float, copy=True),
        faces,  # type: ignore[arg-type]  # pyvista stub: NDArray[int]
    )
    if normals:
        poly.point_data["Normals"] = np.asarray(mesh.vertex_normals, float)
        poly.point_data.active_normals_name = "Normals"
    return poly


def render_surfaces(
    layers: Sequence[tuple[Mesh, str, float]],
    path: str | Path,
    *,
    views: Sequence[str] = ("front", "side", "three_quarter"),
    frame: str = "HEAD",
    orientation: Sequence[Sequence[float] | np.ndarray] | None = None,
    size: tuple[int, int] = (480, 560),
    points: Sequence[tuple[np.ndarray, str]] = (),
) -> Path:
    """Render ``(mesh, colour, opacity)`` layers side by side, one panel per view.

    ``frame`` names the coordinate convention of the meshes ("HEAD", "LPS" or
    "RAS") so that "front" looks at the face; ``orientation`` =
    ``(anterior, superior[, left])`` vectors overrides it for data in a
    non-anatomical frame (``left`` for a mirror-image one: the pictures are
    then flipped, see the module docstring).  ``points`` adds ``((k, 3)
    positions, colour)`` markers (e.g. landmarks) drawn as small spheres.
    Each panel names the subject's sides at its left and right edges (R/L, A/P).
    """
    anatomy = frame_anatomy(frame, orientation)
    anterior, superior, left = anatomy.anterior, anatomy.superior, anatomy.left
    _prefer_headless_gl()
    import pyvista as pv

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    plotter = panel_row(len(views), size)
    try:
        for _col, view in each_panel(plotter, views):
            for mesh, colour, opacity in layers:
                plotter.add_mesh(
                    to_polydata(mesh),
                    color=colour,
                    opacity=opacity,
                    smooth_shading=True,
                    specular=0.2,
                )
            for positions, colour in points:
                if len(positions):
                    plotter.add_mesh(
                        pv.PolyData(np.asarray(positions, float)),
                        color=colour,
                        point_size=9,
                        render_points_as_spheres=True,
                    )
            direction, up = view_directions(view, anterior, superior, left)
            centre = np.mean([m.bounds.mean(axis=0) for m, _, _ in layers], axis=0)
            radius = max(float(np.linalg.norm(m.extent)) for m, _, _ in layers)
            plotter.camera.focal_point = centre
            plotter.camera.position = centre + np.asarray(direction, float) * radius * 1.5
            plotter.camera.up = up
            # keep the direction, fit the distance to the bounds
            plotter.reset_camera()  # type: ignore[call-arg]  # pyvista stub bug: wraps-typed method
            plotter.camera.zoom(1.15)
            plotter.add_text(view.replace("_", " "), font_size=10, color="black")
            show_handedness(plotter.renderer, anatomy)
        plotter.screenshot(str(path))
    finally:
        plotter.close()
    return path
