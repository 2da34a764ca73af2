"""Pictures of the reference head: skin, skull with landmarks, muscle grids (head frame, mm)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from workbench.model.template import TemplateHead
from workbench.render.snapshots import render_surfaces

VIEWS = ("front", "side", "three_quarter")


def render_template(head: TemplateHead, folder: str | Path) -> list[Path]:
    """PNGs of the skin, the skull with landmarks and the head (front, side, three-quarter),
    and of the muscle grid points on the skin (front, three-quarter)."""
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    m = head.meshes
    bone = [
        (m["cranium"], "ivory", 1.0),
        (m["mandible"], "ivory", 1.0),
        (m["upper_teeth"], "white", 1.0),
        (m["lower_teeth"], "white", 1.0),
        (m["eyes"], "lightsteelblue", 1.0),
    ]
    landmarks = head.skull_landmarks.defined().positions
    written = []
    for view in VIEWS:
        path = out / f"skin_{view}.png"
        written.append(
            render_surfaces(
                [(m["skin"], "peachpuff", 1.0), (m["eyes"], "lightsteelblue", 1.0)],
                path,
                views=(view,),
            )
        )
        path = out / f"skull_{view}.png"
        written.append(render_surfaces(bone, path, views=(view,), points=[(landmarks, "red")]))
        path = out / f"head_{view}.png"
        written.append(
            render_surfaces([*bone, (m["skin"], "peachpuff", 0.35)], path, views=(view,))
        )
    lines = [grid.points.evaluate(head.skin) for grid in head.muscles]
    for view in ("front", "three_quarter"):
        path = out / f"muscles_{view}.png"
        written.append(
            render_surfaces(
                [(m["skin"], "peachpuff", 0.6)],
                path,
                views=(view,),
                points=[(np.vstack(lines), "darkred")] if lines else (),
            )
        )
    return written
