"""Skin surfaces: the fitted face (plain or coloured by a value), the true skin coloured by
its signed distance, the guide view's translucent face, a face scan coloured by its
distance to the fitted skin, and the fitted skin over a scan.

Translucent skins have their back faces culled (:func:`~workbench.render.visuals.style.cull_back_faces`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from workbench.core.mesh import Mesh
from workbench.render.snapshots import to_polydata
from workbench.render.visuals.scalar_bars import bar_args
from workbench.render.visuals.style import SKIN, SMOOTH, cull_back_faces

TRUTH_GREY = (0.7, 0.7, 0.75)
#: where a value is missing (NaN)
NAN_GREY_TRUTH = (0.6, 0.6, 0.6)
#: opacity of the face in the guide view (the skull shows through)
GUIDE_FACE_OPACITY = 0.45
#: a face scan: plain, and where its distance is not counted (NaN)
SCAN_GREY = (0.78, 0.78, 0.80)
NAN_GREY = (0.55, 0.55, 0.57)


def add_face(
    plotter: Any,
    mesh: Mesh,
    scalars: np.ndarray | None = None,
    title: str = "",
    *,
    name: str = "layer_face",
) -> Any:
    """The fitted skin; with ``scalars`` (per vertex, mm) coloured (viridis) with a bar
    titled ``title`` (default "mm")."""
    poly = to_polydata(mesh, normals=True)
    kw: dict[str, Any] = {"color": SKIN}
    if scalars is not None:
        poly.point_data[title or "mm"] = np.asarray(scalars, float)
        kw = {
            "scalars": title or "mm",
            "cmap": "viridis",
            "scalar_bar_args": bar_args(title or "mm"),
        }
    actor = plotter.add_mesh(poly, **SMOOTH, pickable=False, render=False, name=name, **kw)
    return cull_back_faces(actor)


#: a refit held back (it would turn the face or move it away from the edit): amber, faint
HELD = (0.95, 0.55, 0.10)


def add_held_face(plotter: Any, mesh: Mesh, *, name: str = "layer_held") -> Any:
    """A refit the window held back, drawn as a faint amber ghost over the face shown
    (its opacity is the layer's)."""
    poly = to_polydata(mesh, normals=True)
    actor = plotter.add_mesh(poly, color=HELD, **SMOOTH, pickable=False, render=False, name=name)
    return cull_back_faces(actor)


def add_truth(
    plotter: Any,
    mesh: Mesh,
    signed_mm: np.ndarray | None = None,
    limit_mm: float = 5.0,
    *,
    name: str = "layer_truth",
) -> Any:
    """The true skin, grey, or coloured by signed distance (mm, blue–red within
    ±``limit_mm``, NaN grey) when ``signed_mm`` is given."""
    poly = to_polydata(mesh, normals=True)
    kw: dict[str, Any] = {"color": TRUTH_GREY}
    if signed_mm is not None:
        poly.point_data["signed mm"] = np.asarray(signed_mm, float)
        kw = {
            "scalars": "signed mm",
            "cmap": "RdBu_r",
            "clim": (-limit_mm, limit_mm),
            "nan_color": NAN_GREY_TRUTH,
            "scalar_bar_args": bar_args("signed mm"),
        }
    actor = plotter.add_mesh(poly, **SMOOTH, pickable=False, render=False, name=name, **kw)
    return cull_back_faces(actor)


def add_guide_face(plotter: Any, mesh: Mesh, *, name: str = "gv_face") -> Any:
    """The fitted skin of the guide view: translucent over the skull."""
    actor = plotter.add_mesh(
        to_polydata(mesh, normals=True),
        color=SKIN,
        opacity=GUIDE_FACE_OPACITY,
        **SMOOTH,
        pickable=False,
        render=False,
        name=name,
    )
    return cull_back_faces(actor)


def add_skin_part(plotter: Any, mesh: Mesh, *, name: str) -> Any:
    """A fitted skin (part) drawn over a scan, translucent by its caller; the camera is
    kept (it is redrawn when the user toggles detail)."""
    actor = plotter.add_mesh(
        to_polydata(mesh, normals=True),
        color=SKIN,
        **SMOOTH,
        pickable=False,
        render=False,
        reset_camera=False,
        name=name,
    )
    return cull_back_faces(actor)


def add_scan(
    plotter: Any,
    mesh: Mesh,
    distance: np.ndarray | None = None,
    *,
    title: str,
    clim: tuple[float, float],
    name: str = "scan_fit_scan",
) -> tuple[Any, Any]:
    """A face scan, pickable: grey, or coloured by ``distance`` (per vertex, mm; NaN
    where not counted) with a bar titled ``title`` when it has one value per vertex.

    Returns ``(actor, polydata)``: the polydata is the surface clicks are picked on.
    """
    poly = to_polydata(mesh, normals=True)
    kw: dict[str, Any] = {"color": SCAN_GREY}
    if distance is not None and len(distance) == poly.n_points:
        poly.point_data[title] = distance
        kw = {
            "scalars": title,
            "cmap": "viridis",
            "clim": clim,
            "nan_color": NAN_GREY,
            "scalar_bar_args": bar_args(title, n_labels=6, fmt="%.1f"),
        }
    actor = plotter.add_mesh(poly, **SMOOTH, pickable=True, render=False, name=name, **kw)
    return actor, poly
