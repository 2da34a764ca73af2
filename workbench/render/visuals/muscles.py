"""Facial muscles: each muscle grid as a red sheet with darker fibre lines (mm).

A muscle arrives as its grid rows, ``(n_i, 3)`` arrays in order (fixed end → free end
for a linear muscle, outer → inner ring for a sphincter; see
:class:`workbench.model.muscles.MuscleGrid`).  Rows are resampled to a common point
count; consecutive rows span the sheet, and the rows plus the columns across them are
drawn as lines.  Sheets and fibres share one point layout, so both can be moved in place
with the same points.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from workbench.core.mesh import Mesh
from workbench.render.snapshots import to_polydata
from workbench.render.visuals.style import SMOOTH

MUSCLE = (0.72, 0.12, 0.12)
MUSCLE_FIBRE = (0.45, 0.04, 0.05)


def add_muscles(
    plotter: Any, muscles: Sequence[Sequence[np.ndarray]]
) -> tuple[list[Any], int, int]:
    """Draw the muscle sheets and fibres; ``(actors, number of sheet triangles, number of
    polylines)`` (no actors when there is nothing to draw)."""
    import pyvista as pv

    points, faces, lines = muscle_geometry(muscles)
    actors: list[Any] = []
    if not len(points):
        return actors, 0, 0
    if len(faces):
        # normals from numpy (Mesh.vertex_normals), not VTK's normals
        # filter: that took ~50 ms of the GUI thread per fit
        sheet = to_polydata(Mesh(points, faces), normals=True)
        actors.append(
            plotter.add_mesh(
                sheet,
                color=MUSCLE,
                **SMOOTH,
                pickable=False,
                render=False,
                name="layer_muscles_sheets",
            )
        )
    if lines:
        cells = np.concatenate([np.r_[len(line), line] for line in lines])
        fibres = pv.PolyData(points, lines=cells)
        actors.append(
            plotter.add_mesh(
                fibres,
                color=MUSCLE_FIBRE,
                line_width=2.5,
                pickable=False,
                render=False,
                name="layer_muscles_fibres",
            )
        )
    return actors, len(faces), len(lines)


def muscle_geometry(
    muscles: Sequence[Sequence[np.ndarray]],
) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """Points, sheet triangles and fibre polylines (point ids) of muscle grids."""
    pts: list[np.ndarray] = []
    tris: list[np.ndarray] = []
    lines: list[np.ndarray] = []
    offset = 0
    for rows in muscles:
        grid = resampled_grid([np.asarray(r, float).reshape(-1, 3) for r in rows])
        if grid is None:
            continue
        n_rows, n_cols = grid.shape[:2]
        ids = offset + np.arange(n_rows * n_cols).reshape(n_rows, n_cols)
        pts.append(grid.reshape(-1, 3))
        if n_rows > 1 and n_cols > 1:
            a, b = ids[:-1, :-1].ravel(), ids[:-1, 1:].ravel()
            c, d = ids[1:, 1:].ravel(), ids[1:, :-1].ravel()
            tris += [np.column_stack([a, b, c]), np.column_stack([a, c, d])]
        lines += [ids[i] for i in range(n_rows) if n_cols > 1]
        lines += [ids[:, j] for j in range(n_cols) if n_rows > 1]
        offset += n_rows * n_cols
    points = np.vstack(pts) if pts else np.zeros((0, 3))
    faces = np.vstack(tris) if tris else np.zeros((0, 3), np.int64)
    return points, faces, lines


def resampled_grid(rows: list[np.ndarray]) -> np.ndarray | None:
    """Rows of unequal length → ``(n_rows, n_cols, 3)``, each row resampled by arc length."""
    rows = [r for r in rows if len(r)]
    if not rows:
        return None
    n_cols = max(len(r) for r in rows)
    out = np.empty((len(rows), n_cols, 3))
    for i, row in enumerate(rows):
        if len(row) == n_cols:
            out[i] = row
            continue
        if len(row) == 1:
            out[i] = row[0]
            continue
        s = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(row, axis=0), axis=1))]
        t = np.linspace(0.0, s[-1], n_cols)
        out[i] = np.column_stack([np.interp(t, s, row[:, k]) for k in range(3)])
    return out
