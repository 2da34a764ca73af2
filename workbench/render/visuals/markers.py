"""Points and lines over the surfaces: landmark markers, the selected marker and its label,
dowels, guide lines and points, and the guide view's guide sets and measurement marks.

Markers are drawn as spheres of a fixed size on screen (pixels), never pickable (clicks
go to the surface under them).  Points are ``(n, 3)`` arrays in mm, in the frame of
the view they are drawn in.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

#: landmark markers by status in the main view
STATUS_COLOURS = {"placed": (0.10, 0.70, 0.25), "suggested": (1.0, 0.55, 0.0)}
SELECTED = (1.0, 0.95, 0.1)
DOWEL = (0.15, 0.35, 0.85)
GUIDE = (0.85, 0.10, 0.55)
#: the published-rule predictions and the skull measurements in the guide view
PREDICTION = (0.10, 0.75, 0.85)
MEASURE = (0.95, 0.80, 0.15)
#: marker size (pixels) of the main view's landmarks (selected: 1.8×, dowel tips: 0.8×)
MARKER_PX = 12.0
#: the selected marker is this much larger than the others
SELECTED_SCALE = 1.8


def segments(starts: np.ndarray, ends: np.ndarray) -> Any:
    """``pyvista.PolyData`` of the line segments ``starts[i]`` → ``ends[i]`` (``(n, 3)`` each)."""
    import pyvista as pv

    n = len(starts)
    pts = np.vstack([starts, ends])
    lines = np.column_stack([np.full(n, 2), np.arange(n), np.arange(n) + n]).ravel()
    return pv.PolyData(pts, lines=lines)


def paired_segments(ends: np.ndarray) -> Any:
    """``pyvista.PolyData`` of line segments given as consecutive pairs of points
    (``ends[2i]`` → ``ends[2i + 1]``)."""
    import pyvista as pv

    n = len(ends) // 2
    lines = np.column_stack([np.full(n, 2), 2 * np.arange(n), 2 * np.arange(n) + 1]).ravel()
    return pv.PolyData(ends, lines=lines)


def add_markers(
    plotter: Any, points: np.ndarray, colour: Sequence[float], size: float, name: str
) -> Any:
    """Sphere markers of ``size`` pixels at ``points``."""
    return plotter.add_points(
        points,
        color=colour,
        point_size=size,
        render_points_as_spheres=True,
        pickable=False,
        render=False,
        name=name,
    )


def add_lines(plotter: Any, lines: Any, colour: Sequence[float], width: float, name: str) -> Any:
    """Line cells (``pyvista.PolyData``) ``width`` pixels wide."""
    return plotter.add_mesh(
        lines, color=colour, line_width=width, pickable=False, render=False, name=name
    )


def add_status_markers(
    plotter: Any,
    points: np.ndarray,
    statuses: Sequence[str],
    colours: dict[str, tuple[float, float, float]],
    size: float,
    prefix: str,
) -> list[Any]:
    """One marker actor per status of ``colours`` that occurs in ``statuses`` (one status
    per row of ``points``), named ``prefix + status`` (spaces as underscores)."""
    actors = []
    for status, colour in colours.items():
        mask = np.array([s == status for s in statuses], dtype=bool)
        if mask.any():
            name = f"{prefix}{status.replace(' ', '_')}"
            actors.append(add_markers(plotter, np.asarray(points)[mask], colour, size, name))
    return actors


def add_selected(plotter: Any, point: np.ndarray, size: float, name: str) -> Any:
    """The selected landmark: a yellow marker :data:`SELECTED_SCALE` × ``size``."""
    return add_markers(
        plotter, np.asarray(point, float)[None], SELECTED, size * SELECTED_SCALE, name
    )


def add_label(plotter: Any, point: np.ndarray, text: str, name: str) -> Any:
    """A text label on a grey box at ``point``, never hidden behind the surfaces."""
    return plotter.add_point_labels(
        np.asarray(point, float)[None],
        [text],
        font_size=14,
        point_size=1,
        shape_opacity=0.6,
        always_visible=True,
        pickable=False,
        render=False,
        name=name,
    )


def add_dowels(plotter: Any, origins: np.ndarray, tips: np.ndarray, size: float) -> list[Any]:
    """Each dowel as a line from its skull origin to its tip, with a tip sphere."""
    return [
        add_lines(plotter, segments(origins, tips), DOWEL, 4, "layer_dowels_pegs"),
        add_markers(plotter, np.asarray(tips), DOWEL, size * 0.8, "layer_dowels_tips"),
    ]


def add_guides(
    plotter: Any, lines: list[tuple[np.ndarray, np.ndarray]], points: np.ndarray, size: float
) -> list[Any]:
    """Guide lines (pairs of end points) and guide points of the main view, magenta."""
    actors = []
    if lines:
        ends = np.array([p for seg in lines for p in seg], float)
        actors.append(add_lines(plotter, paired_segments(ends), GUIDE, 3, "layer_guides_lines"))
    if len(points):
        actors.append(
            add_markers(plotter, np.asarray(points, float), GUIDE, size, "layer_guides_points")
        )
    return actors


def add_flat_labels(
    plotter: Any,
    points: np.ndarray,
    texts: Sequence[str],
    colour: Sequence[float],
    font_size: int,
    name: str,
) -> Any:
    """Coloured text at ``points`` without a box or a point (the guide view's labels)."""
    return plotter.add_point_labels(
        points,
        list(texts),
        font_size=font_size,
        text_color=colour,
        shape_opacity=0.0,
        show_points=False,
        always_visible=True,
        pickable=False,
        render=False,
        name=name,
    )


def add_guide_set(
    plotter: Any,
    lines: list[np.ndarray],
    points: list[np.ndarray],
    colour: Sequence[float],
    width: float,
    prefix: str,
) -> dict[str, Any]:
    """A set of guides of the guide view: ``lines`` (each ``(2, 3)``) as one line actor,
    ``points`` (each ``(1, 3)``) as one marker actor (14 px); ``{"lines" | "points": actor}``."""
    actors = {}
    if lines:
        actors["lines"] = add_lines(
            plotter, paired_segments(np.vstack(lines)), colour, width, f"{prefix}_lines"
        )
    if points:
        actors["points"] = add_markers(plotter, np.vstack(points), colour, 14, f"{prefix}_points")
    return actors


def add_measure_marks(
    plotter: Any, points: np.ndarray, label_points: np.ndarray, label_texts: Sequence[str]
) -> list[Any]:
    """Where the skull was measured (yellow markers, 9 px) and their labels."""
    return [
        add_markers(plotter, points, MEASURE, 9, "gv_marks"),
        add_flat_labels(plotter, label_points, label_texts, MEASURE, 9, "gv_mark_labels"),
    ]
