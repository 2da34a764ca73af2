"""Whole heads of the age and animate tools (mm, the head's own Frankfort frame).

Age: the source head (beside the aged one, or a translucent grey shell over it) and
the aged skin, drawn once from the source's topology and then given each age's points,
normals and displacement colours in place (:func:`show_aged`); the eyes of both, painted
with an iris and pupil (:func:`head_eyes`), the aged ones moved in place
(:func:`show_aged_eyes`).  Animate: the skin and the parts under it (skull, teeth, eyes
with an iris and pupil so that the gaze can be seen); frames move their points with
:func:`workbench.render.visuals.update.set_surface_points`.  Eyes are painted by
:mod:`workbench.core.appearance`, as in the report pictures.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from workbench.core import appearance
from workbench.core.mesh import Mesh
from workbench.render.snapshots import to_polydata
from workbench.render.visuals.face import (
    EYE_SHADING,
    VIEW_EYE_LEVEL,
    PaintedEyes,
    add_eyes,
    filtered_eye_colours,
    paint_eyes,
)
from workbench.render.visuals.scalar_bars import bar_args
from workbench.render.visuals.style import BONE, SKIN, SMOOTH, cull_back_faces
from workbench.render.visuals.update import mapper_dataset, set_array

if TYPE_CHECKING:
    from workbench.model.template import TemplateHead
    from workbench.services.animation.animator import Animator

# ------------------------------------------------------------------ age
#: opacity of the source skin in the overlay
OVERLAY_OPACITY = 0.25
DISTANCE_TITLE = "displacement mm"
BEFORE_COLOUR = (0.80, 0.80, 0.84)


def add_age_source(plotter: Any, skin: Mesh, *, overlay: bool) -> Any:
    """The source skin (already placed): skin-coloured, or in the overlay a translucent grey
    shell over the aged head (back faces culled: no depth sorting needed)."""
    actor = plotter.add_mesh(
        to_polydata(skin, normals=True),
        color=BEFORE_COLOUR if overlay else SKIN,
        **SMOOTH,
        opacity=OVERLAY_OPACITY if overlay else 1.0,
        pickable=False,
        render=False,
        name="age_before",
    )
    return cull_back_faces(actor) if overlay else actor


def add_age_caption(plotter: Any) -> Any:
    """The empty caption in the view's upper left corner (:func:`set_caption` fills it)."""
    return plotter.add_text(
        "", position="upper_left", font_size=11, color="black", name="age_caption"
    )


def set_caption(caption: Any, text: str) -> None:
    caption.SetText(2, text)  # a corner annotation: 2 = upper left


def add_aged_skin(plotter: Any, skin: Mesh, *, overlay: bool) -> Any:
    """The aged skin's actor, with the source's vertices and triangles (a copy: VTK may
    share the array, and :func:`show_aged` moves its points in place); in the overlay
    coloured by displacement (viridis, 0–10 mm until :func:`show_aged` sets the range)."""
    poly = to_polydata(Mesh(skin.vertices.copy(), skin.faces.copy()), normals=True)
    kw: dict[str, Any] = {"color": SKIN}
    if overlay:
        poly.point_data[DISTANCE_TITLE] = np.zeros(poly.n_points)
        kw = {
            "scalars": DISTANCE_TITLE,
            "cmap": "viridis",
            "clim": (0.0, 10.0),
            "scalar_bar_args": bar_args(DISTANCE_TITLE, n_labels=6, fmt="%.0f"),
        }
    return plotter.add_mesh(poly, **SMOOTH, pickable=False, render=False, name="age_after", **kw)


def show_aged(
    actor: Any,
    vertices: np.ndarray,
    normals: np.ndarray,
    distance: np.ndarray,
    *,
    overlay: bool,
) -> None:
    """Give the aged skin's actor one age's vertices and normals (mm) and, in the overlay,
    its displacement colours with the range rounded up to 5 mm (99th percentile)."""
    data = mapper_dataset(actor)
    set_array(data.GetPoints().GetData(), vertices)
    data.GetPoints().Modified()
    drawn_normals = data.GetPointData().GetNormals()
    if drawn_normals is not None:
        set_array(drawn_normals, normals)
    if overlay:
        scalars = data.GetPointData().GetArray(DISTANCE_TITLE)
        if scalars is not None:
            set_array(scalars, distance)
        hi = max(1.0, 5.0 * math.ceil(float(np.percentile(distance, 99)) / 5.0))
        actor.GetMapper().SetScalarRange(0.0, hi)
        lut = actor.GetMapper().GetLookupTable()
        if lut is not None:
            lut.SetRange(0.0, hi)
    data.Modified()


def head_eyes(head: TemplateHead, level: int = VIEW_EYE_LEVEL) -> PaintedEyes | None:
    """The eyes of ``head`` painted with an iris and pupil (its own frame, mm), or None
    when it has none (:func:`~workbench.render.visuals.face.paint_eyes`)."""
    eyes = head.meshes.get("eyes")
    if eyes is None or not eyes.n_faces:
        return None
    return paint_eyes(eyes, head.eye_centres, head.eye_radius, level=level)


def add_age_eyes(
    plotter: Any, painted: PaintedEyes, *, name: str, offset: np.ndarray | None = None
) -> Any:
    """A head's painted eyes in the age view (moved by ``offset``, mm, as its skin is)."""
    return add_eyes(plotter, painted, name=name, offset=offset)


def show_aged_eyes(actor: Any, painted: PaintedEyes, head: TemplateHead) -> None:
    """Move the eyes drawn from ``painted`` (the source head's) to those of the aged
    ``head`` in place: its globe centres, radius and gazes (read from its corneas)."""
    eyes = head.meshes["eyes"]
    centres = np.asarray(head.eye_centres, float)
    gazes = appearance.eye_gazes(eyes.vertices, centres)
    vertices, normals = painted.posed(centres, float(head.eye_radius), gazes)
    data = mapper_dataset(actor)
    set_array(data.GetPoints().GetData(), vertices)
    data.GetPoints().Modified()
    drawn_normals = data.GetPointData().GetNormals()
    if drawn_normals is not None:
        set_array(drawn_normals, normals)
    data.Modified()


# ------------------------------------------------------------------ animate
INNER_COLOURS = {"upper_teeth": (1.0, 1.0, 0.94)}
#: opacity of the skin while the parts under it are shown
SEE_THROUGH_OPACITY = 0.55


def add_animated_skin(plotter: Any, skin: Mesh) -> Any:
    return plotter.add_mesh(
        to_polydata(skin, normals=True),
        color=SKIN,
        **SMOOTH,
        pickable=False,
        render=False,
        name="animate_skin",
    )


def add_animated_part(plotter: Any, part: str, mesh: Mesh, anim: Animator) -> Any:
    """A part under the skin, bone-coloured unless :data:`INNER_COLOURS` says otherwise; the
    eyes coloured per vertex (:func:`eye_colours`) and glossy."""
    poly = to_polydata(mesh, normals=True)
    paint: dict[str, Any] = {"color": INNER_COLOURS.get(part, BONE)}
    if part == "eyes":  # an iris and pupil, so that the gaze can be seen
        poly.point_data["rgb"] = eye_colours(anim)
        paint = {"scalars": "rgb", "rgb": True, **EYE_SHADING}
    return plotter.add_mesh(
        poly,
        **paint,
        **SMOOTH,
        pickable=False,
        render=False,
        name=f"animate_{part}",
    )


def set_see_through(skin: Any, on: bool) -> None:
    """Make the skin translucent (back faces culled) so the bones show through, or opaque."""
    skin.GetProperty().SetOpacity(SEE_THROUGH_OPACITY if on else 1.0)
    if on:
        skin.GetProperty().BackfaceCullingOn()
    else:
        skin.GetProperty().BackfaceCullingOff()


#: the colours of the pupil and the white of the animated eyes (sRGB): the presets of
#: :mod:`workbench.core.appearance`, which paints them
PUPIL, EYE_WHITE = appearance.PUPIL.srgb, appearance.SCLERA.srgb


def eye_colours(anim: Animator) -> np.ndarray:
    """``(n, 3)`` uint8 sRGB colours of the eyes' vertices as the animator holds them at rest.

    The pattern of :func:`workbench.core.appearance.eyes_colours` (pupil, iris
    and sclera by the angle from each globe's gaze, read from its cornea in the
    Frankfort frame of ``anim.head``; +z when a globe has none), averaged about
    each vertex (:func:`~workbench.render.visuals.face.filtered_eye_colours`: the
    animated globes keep their ~0.9 mm edges), one colour per vertex in the
    order drawn: a frame turns the vertices, so the iris turns with the eye and
    the gaze can be seen.
    """
    head = anim.head
    eyes = head.meshes["eyes"]
    centres = np.asarray(head.eye_centres, float).reshape(-1, 3)
    radius = float(getattr(head, "eye_radius", appearance.EYE_RADIUS_MM))
    gazes = appearance.eye_gazes(eyes.vertices, centres)
    return filtered_eye_colours(eyes, centres, gazes, radius)
