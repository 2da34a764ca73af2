"""Off-screen heat maps of per-vertex distances (mm) on a mesh, e.g. validation errors.

Units: mm.  The mesh is drawn in its own frame; ``frame`` names that frame
("HEAD": x to the subject's left, y up, z toward the face; "LPS"; "RAS") or
gives ``(anterior, superior)`` vectors, so that "front" looks at the face.

Colours: a diverging map centred on 0 mm — blue where the value is negative
(for :mod:`workbench.services.validation.compare`: the reconstruction lies *inside* the
true skin, too little tissue), white near 0, red where positive (outside,
too much tissue).  Values beyond ``clim`` saturate; vertices without a value
(NaN: not compared) are grey.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Final

import numpy as np

from workbench.core.mesh import Mesh
from workbench.render.panels import each_panel, panel_row
from workbench.render.snapshots import _AXES, _prefer_headless_gl, to_polydata, view_directions

if TYPE_CHECKING:
    from pyvista.plotting._typing import ScalarBarArgs

CMAP: Final = "RdBu_r"  # blue (negative) - white - red (positive)
NAN_COLOUR = "#7a7a7a"  # darker than the lit white of 0 mm
LEGEND = "red: reconstruction outside the true skin   blue: inside   grey: not compared"


def render_heatmap(
    mesh: Mesh,
    scalars: np.ndarray,
    path: str | Path,
    *,
    views: Sequence[str] = ("front", "side", "three_quarter"),
    clim: tuple[float, float] = (-10.0, 10.0),
    title: str = "reconstruction vs true skin",
    bar_title: str = "signed distance (mm)",
    legend: str | None = LEGEND,
    frame: str | tuple[Sequence[float], Sequence[float]] | None = None,
    size: tuple[int, int] = (480, 560),
) -> Path:
    """Render ``scalars`` (one value per vertex, mm, NaN = no value) on ``mesh``.

    One PNG at ``path`` with the ``views`` side by side, ``title`` above the
    first panel, a scalar bar labelled ``bar_title`` (mm) in the last and the
    colour ``legend`` under the panels.  ``frame`` is a frame name ("HEAD", the default,
    "LPS", "RAS") or ``(anterior, superior)`` vectors in the mesh's frame.
    """
    values = np.asarray(scalars, dtype=np.float64).ravel()
    if len(values) != mesh.n_vertices:
        raise ValueError(f"need one value per vertex ({mesh.n_vertices}), got {len(values)}")
    if not clim[0] < clim[1]:
        raise ValueError(f"clim must be (low, high) with low < high, got {clim}")
    anterior: Sequence[float]
    superior: Sequence[float]
    if frame is None or isinstance(frame, str):
        anterior, superior = _AXES[(frame or "HEAD").upper()]
    else:
        anterior, superior = frame
    _prefer_headless_gl()

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    poly = to_polydata(mesh)
    poly.point_data["distance_mm"] = values
    centre = mesh.bounds.mean(axis=0)
    radius = float(np.linalg.norm(mesh.extent))
    plotter = panel_row(len(views), size)
    try:
        for col, view in each_panel(plotter, views):
            bar: ScalarBarArgs | None = None
            if col == len(views) - 1:  # one bar, in the last panel
                bar = {
                    "title": bar_title,
                    "color": "black",
                    "n_labels": 5,
                    "fmt": "%.1f",
                    "vertical": True,
                    "position_x": 0.8,
                    "position_y": 0.12,
                    "height": 0.72,
                    "width": 0.08,
                    "title_font_size": 12,
                    "label_font_size": 11,
                }
            plotter.add_mesh(
                poly,
                scalars="distance_mm",
                cmap=CMAP,
                clim=list(clim),
                nan_color=NAN_COLOUR,
                smooth_shading=True,
                specular=0.1,
                show_scalar_bar=bar is not None,
                scalar_bar_args=bar or {},
                copy_mesh=True,
            )
            direction, up = view_directions(view, anterior, superior)
            plotter.camera.focal_point = centre
            plotter.camera.position = centre + np.asarray(direction, float) * radius * 1.5
            plotter.camera.up = up
            plotter.reset_camera()  # type: ignore[call-arg]  # pyvista stub bug: wraps-typed method
            plotter.camera.zoom(1.1)
            label = view.replace("_", " ")
            plotter.add_text(
                f"{title}: {label}" if col == 0 and title else label, font_size=10, color="black"
            )
            if col == 0 and legend:
                plotter.add_text(legend, position="lower_left", font_size=8, color="black")
        plotter.screenshot(str(path))
    finally:
        plotter.close()
    return path
