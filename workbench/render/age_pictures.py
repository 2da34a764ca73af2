"""Pictures of an age change (``workbench age``): source and aged head at one scale, growth map.

Frame and units: each head is in its own Frankfort frame (x to the
subject's left, x = 0 midsagittal, y up, z toward the face; the origin
between the porions), mm — the frame :func:`workbench.services.age.change.age_head`
settles the aged head in.  The two heads are therefore aligned at the
Frankfort origin with no further registration: what differs between them
is the growth (or age regression) itself.

Views are orthographic and every panel of a picture has the *same*
parallel scale and focal point (the source head's box centre), so a child
head is drawn small beside the adult it came from; "front" looks at the
face along -z, "right side" at the subject's right profile (camera on -x).

Pictures (PNG), per aged result:

* **compare** — source front, aged front, source right side, aged right side, the
  eyes painted with an iris and pupil (:func:`workbench.render.visuals.face.paint_eyes`);
* **growth** — the aged skin (front, right side) coloured by its signed
  distance to the source skin (mm; negative: inside the source skin, the
  head is smaller there; positive: outside, it grew), the source skin's
  outline in grey behind it: the growth displacement normal to the skin.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final

import numpy as np

from workbench.core.mesh import Mesh
from workbench.core.spatial import MeshIndex
from workbench.model.template import TemplateHead
from workbench.render.panels import each_panel, panel_row
from workbench.render.snapshots import _prefer_headless_gl, to_polydata
from workbench.render.visuals.face import EYE_SHADING, eyes_polydata, paint_eyes
from workbench.render.visuals.style import SMOOTH

if TYPE_CHECKING:
    from pyvista.plotting._typing import ScalarBarArgs

SKIN_COLOUR: Final = "#e0b89a"
EYE_COLOUR: Final = "#f4f4f0"
GHOST_COLOUR: Final = "#9aa3ad"
GROWTH_CMAP: Final = "RdBu_r"
# camera directions (focus -> camera) in the head frame: anterior +z, subject's left +x
_DIRECTIONS: Final = {"front": (0.0, 0.0, 1.0), "right side": (-1.0, 0.0, 0.0)}
VIEWS: Final = tuple(_DIRECTIONS)
#: margin around the framed box (parallel scale = half the box's largest side times this)
MARGIN: Final = 1.16
#: length of the scale bar in the first panel of the side-by-side picture (mm)
SCALE_BAR_MM: Final = 50.0


def age_label(age: float) -> str:
    """``3.0`` → ``"3y"``, ``7.5`` → ``"7.5y"`` (picture keys and file names)."""
    return f"{age:g}y"


def growth_distance(source_skin: Mesh, aged_skin: Mesh) -> np.ndarray:
    """Signed distance (mm) of each aged skin vertex to the source skin surface.

    Both skins in their Frankfort frames (aligned at the Frankfort origin, not
    registered further).  The magnitude is the distance to the closest point
    of the source skin; the sign says whether the head grew there (+) or
    became smaller (−).  When the aged skin is the source skin moved (same
    triangles, as :func:`~workbench.services.age.change.age_head` makes it), the sign
    is that of the vertex's own displacement along the source skin's outward
    normal, so a vertex that moved inward reads "smaller" even where its
    closest source point is the wall of a slit (between the lips, the
    eyelids) that faces the other way; otherwise the sign is the side of the
    source skin's outward pseudo-normal at the closest point.
    """
    signed = np.asarray(MeshIndex(source_skin).signed_distance(aged_skin.vertices), np.float64)
    same = aged_skin.n_vertices == source_skin.n_vertices and np.array_equal(
        aged_skin.faces, source_skin.faces
    )
    if not same:
        return signed
    along = np.einsum(
        "ij,ij->i", aged_skin.vertices - source_skin.vertices, source_skin.vertex_normals
    )
    sign = np.where(np.abs(along) > 1e-9, np.sign(along), np.sign(signed))
    return np.abs(signed) * sign


def colour_limit(values: np.ndarray, floor: float = 1.0) -> float:
    """A round symmetric colour limit (mm) covering 99 % of ``|values|`` (at least ``floor``)."""
    v = np.abs(np.asarray(values, np.float64))
    v = v[np.isfinite(v)]
    top = float(np.percentile(v, 99.0)) if len(v) else floor
    top = max(top, floor)
    for step in (1.0, 2.0, 5.0, 10.0):
        if top <= 10.0 * step:
            return float(np.ceil(top / step) * step)
    return float(np.ceil(top / 20.0) * 20.0)


def _frame(meshes: Sequence[Mesh]) -> tuple[np.ndarray, float]:
    """Focal point and parallel scale (mm) that frame every mesh in ``meshes`` in every view."""
    pts = np.vstack([m.bounds for m in meshes if m.n_vertices])
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    return (lo + hi) / 2.0, 0.5 * float(np.max(hi - lo)) * MARGIN


def _place_camera(plotter: Any, view: str, centre: np.ndarray, half_height: float) -> None:
    direction = np.asarray(_DIRECTIONS[view])
    camera = plotter.camera
    camera.focal_point = tuple(centre)
    camera.position = tuple(centre + direction * 1000.0)
    camera.up = (0.0, 1.0, 0.0)
    plotter.enable_parallel_projection()
    camera.parallel_scale = half_height
    camera.clipping_range = (1.0, 3000.0)


def _add_eyes(plotter: Any, head: TemplateHead) -> None:
    """The head's eyes painted with an iris and pupil (:func:`~workbench.render.visuals.face.paint_eyes`;
    the plain mesh in :data:`EYE_COLOUR` when it holds no globe to paint)."""
    eyes = head.meshes.get("eyes")
    if eyes is None or not eyes.n_faces:
        return
    painted = paint_eyes(eyes, head.eye_centres, head.eye_radius)
    if painted is None:
        plotter.add_mesh(to_polydata(eyes, normals=True), color=EYE_COLOUR, **SMOOTH)
    else:
        plotter.add_mesh(eyes_polydata(painted), scalars="rgb", rgb=True, **SMOOTH, **EYE_SHADING)


def render_compare(
    source: TemplateHead,
    aged: TemplateHead,
    path: str | Path,
    *,
    source_label: str = "source",
    aged_label: str = "aged",
    size: tuple[int, int] = (360, 420),
) -> Path:
    """One PNG: source front, aged front, source right side, aged right side, same scale (mm).

    Every panel has the same focal point and orthographic scale (framing the
    larger of the two heads), so their sizes compare directly; a 50 mm bar
    in the first panel gives the scale.  Panels are ``size`` pixels each,
    left to right.
    """
    _prefer_headless_gl()

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    centre, half = _frame([source.skin, aged.skin])
    panels = [
        (source, "front", source_label),
        (aged, "front", aged_label),
        (source, "right side", source_label),
        (aged, "right side", aged_label),
    ]
    plotter = panel_row(len(panels), size)
    try:
        for col, (head, view, label) in each_panel(plotter, panels):
            plotter.add_mesh(
                to_polydata(head.skin, normals=True),
                color=SKIN_COLOUR,
                smooth_shading=True,
                specular=0.15,
            )
            _add_eyes(plotter, head)
            _place_camera(plotter, view, centre, half)
            plotter.add_text(
                f"{label}: {view}", position=(8, size[1] - 24), font_size=10, color="black"
            )
            if col == 0:
                _scale_bar(plotter, centre, half, view, size)
        plotter.screenshot(str(path))
    finally:
        plotter.close()
    return path


def _scale_bar(
    plotter: Any, centre: np.ndarray, half: float, view: str, size: tuple[int, int]
) -> None:
    """A :data:`SCALE_BAR_MM` bar in the panel's bottom left, drawn in the scene (so it scales)."""
    import pyvista as pv

    right = np.array([1.0, 0.0, 0.0]) if view == "front" else np.array([0.0, 0.0, -1.0])
    aspect = size[0] / size[1]
    start = centre + np.array([0.0, -0.9 * half, 0.0]) - right * (0.85 * half * aspect)
    end = start + right * SCALE_BAR_MM
    plotter.add_mesh(pv.Line(tuple(start), tuple(end)), color="black", line_width=3)
    plotter.add_point_labels(
        np.array([(start + end) / 2 + np.array([0.0, 0.08 * half, 0.0])]),
        [f"{SCALE_BAR_MM:g} mm"],
        font_size=13,
        text_color="black",
        shape=None,
        show_points=False,
        always_visible=True,
    )


def render_growth_map(
    source: TemplateHead,
    aged: TemplateHead,
    path: str | Path,
    *,
    values: np.ndarray | None = None,
    limit: float | None = None,
    title: str = "growth",
    size: tuple[int, int] = (400, 440),
) -> tuple[Path, float]:
    """One PNG: the aged skin coloured by ``values`` (default :func:`growth_distance`), mm.

    Front and right side (the aged eyes painted), the source skin's inner side in
    grey behind it (its outline where it is larger), a colour
    bar labelled in mm over ``-limit … +limit`` (default :func:`colour_limit`).
    Returns the path and the limit used.
    """
    if values is None:
        values = growth_distance(source.skin, aged.skin)
    values = np.asarray(values, np.float64).ravel()
    if len(values) != aged.skin.n_vertices:
        raise ValueError(
            f"need one value per aged skin vertex ({aged.skin.n_vertices}), got {len(values)}"
        )
    lim = colour_limit(values) if limit is None else float(limit)
    if not lim > 0:
        raise ValueError(f"limit must be positive, got {lim}")
    _prefer_headless_gl()

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    centre, half = _frame([source.skin, aged.skin])
    poly = to_polydata(aged.skin, normals=True)
    poly.point_data["growth_mm"] = values
    ghost = to_polydata(source.skin, normals=True)
    plotter = panel_row(len(VIEWS), size)
    try:
        for col, view in each_panel(plotter, VIEWS):
            last = col == len(VIEWS) - 1
            bar: ScalarBarArgs = {
                "title": "growth, mm",
                "color": "black",
                "n_labels": 5,
                "fmt": "%+.0f" if lim >= 4 else "%+.1f",
                "vertical": True,
                "position_x": 0.82,
                "position_y": 0.08,
                "height": 0.70,
                "width": 0.07,
                "title_font_size": 11,
                "label_font_size": 11,
            }
            plotter.add_mesh(
                poly,
                scalars="growth_mm",
                cmap=GROWTH_CMAP,
                clim=[-lim, lim],
                smooth_shading=True,
                specular=0.1,
                show_scalar_bar=last,
                scalar_bar_args=bar if last else {},
                copy_mesh=True,
            )
            _add_eyes(plotter, aged)
            # the source skin's inner (back-facing) side only: a grey shape behind the aged
            # head where the source is larger, never a veil over the colours
            plotter.add_mesh(
                ghost, color=GHOST_COLOUR, opacity=0.35, culling="front", smooth_shading=True
            )
            _place_camera(plotter, view, centre, half)
            plotter.add_text(
                f"{title}: {view}" if col == 0 and title else view,
                position=(8, size[1] - 24),
                font_size=10,
                color="black",
            )
        plotter.screenshot(str(path))
    finally:
        plotter.close()
    return path, lim


def render_age_pictures(
    source: TemplateHead,
    results: Sequence[Any],
    folder: str | Path,
    *,
    size: tuple[int, int] = (360, 420),
) -> tuple[dict[str, Path], list[str]]:
    """Both pictures of every :class:`~workbench.services.age.change.AgeResult` into ``folder``.

    Returns ``({"compare_<age>y": png, "growth_<age>y": png, ...}, notes)``
    in the results' order; the notes say why a picture could not be drawn
    (no OpenGL).
    """
    folder = Path(folder)
    out: dict[str, Path] = {}
    notes: list[str] = []
    for r in results:
        tag = age_label(r.to_age)
        src_label = f"source, {r.from_age:g} y"
        aged_label = f"aged, {r.to_age:g} y"
        try:
            out[f"compare_{tag}"] = render_compare(
                source,
                r.head,
                folder / f"compare_{tag}.png",
                source_label=src_label,
                aged_label=aged_label,
                size=size,
            )
        except (RuntimeError, OSError, ValueError) as exc:
            notes.append(f"no before/after picture for {r.to_age:g} y ({exc})")
        try:
            png, _lim = render_growth_map(
                source,
                r.head,
                folder / f"growth_{tag}.png",
                title=f"{r.from_age:g} -> {r.to_age:g} y",
                size=(size[0] + 40, size[1]),
            )
            out[f"growth_{tag}"] = png
        except (RuntimeError, OSError, ValueError) as exc:
            notes.append(f"no growth map for {r.to_age:g} y ({exc})")
    return out, notes
