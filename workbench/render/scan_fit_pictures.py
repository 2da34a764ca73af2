"""Pictures of a scan fit (``workbench fit-scan``): the scan coloured by its distance to the fit.

Frame and units: everything is in the fitted person's head frame (x to the
subject's left, x = 0 midsagittal, y up, z toward the face), mm — the frame
:class:`workbench.services.scan_fit.settings.ScanFit` holds the scan and the fitted
skin in.  Views are orthographic: "front" looks at the face along -z,
"left" at the subject's left profile (camera on +x), "right" at the right
profile (camera on -x).

Pictures (PNG):

* **distance** — each scan vertex's distance to the fitted skin, unsigned,
  0 … 2.5 mm on a sequential map (pale: on the fit, dark red: 2.5 mm or more);
* **signed** — the same with a sign from the fitted skin's outward
  pseudo-normal at the closest point (:meth:`workbench.core.spatial.MeshIndex.signed_distance`):
  red where the scan lies *outside* the fitted skin, blue inside, −2.5 … +2.5 mm;
* **histogram** — the counted distances with the 1 mm and 2.5 mm lines (matplotlib, Agg).

In both maps the fitted head's eyes, painted with an iris and pupil
(:func:`workbench.render.visuals.face.paint_eyes`), lie under the scan: they show
through its eye openings, and the scan is drawn wherever it covers them.

Grey on the scan marks vertices *not counted* (NaN in ``ScanFit.scan_distance``):
outside the face region, near a hole or field-of-view rim, hidden cavity walls,
not the head (shoulders, a head holder), or thin sheets over the skin (a cord or
strap over the face, hair).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Final, Literal

import numpy as np

from workbench.core.mesh import Mesh
from workbench.core.spatial import MeshIndex
from workbench.render.panels import each_panel, panel_row
from workbench.render.snapshots import _prefer_headless_gl, to_polydata
from workbench.render.visuals.face import EYE_SHADING, PaintedEyes, eyes_polydata, paint_eyes
from workbench.render.visuals.style import SMOOTH

if TYPE_CHECKING:
    from pyvista.plotting._typing import ScalarBarArgs

#: the picture range of the distance maps (mm); the issue's tolerances are 1 and 2.5 mm
LIMIT_MM: Final = 2.5
UNSIGNED_CMAP: Final = "YlOrRd"
SIGNED_CMAP: Final = "RdBu_r"
#: "not counted" — a mid grey, unlike any colour of either map
NAN_COLOUR: Final = "#8c8c8c"
VIEWS: Final = ("front", "left", "right")
UNSIGNED_LEGEND: Final = (
    "distance of each scan vertex to the fitted skin, mm (2.5 mm and more: darkest red)   "
    "grey: not counted (outside the face region, near a hole or scan rim, not the head)"
)
SIGNED_LEGEND: Final = (
    "red: the scan lies outside the fitted skin   blue: inside   "
    "grey: not counted (outside the face region, near a hole or scan rim, not the head)"
)
# head frame: anterior +z, superior +y, subject's left +x
_DIRECTIONS: Final = {
    "front": (0.0, 0.0, 1.0),
    "left": (1.0, 0.0, 0.0),
    "right": (-1.0, 0.0, 0.0),
}


def signed_scan_distance(scan: Mesh, skin: Mesh, distance: np.ndarray) -> np.ndarray:
    """``distance`` (mm, NaN = not counted) with the side of the fitted ``skin`` as sign.

    Positive where the scan vertex lies outside the fitted skin (along its
    outward pseudo-normal at the closest point), negative inside; NaN stays NaN.
    Both meshes in the same frame (the head frame), mm.
    """
    values = np.asarray(distance, dtype=np.float64).ravel()
    if len(values) != scan.n_vertices:
        raise ValueError(
            f"need one distance per scan vertex ({scan.n_vertices}), got {len(values)}"
        )
    out = np.full(len(values), np.nan)
    counted = np.isfinite(values)
    if counted.any():
        signed = MeshIndex(skin).signed_distance(scan.vertices[counted])
        out[counted] = np.copysign(values[counted], signed)
    return out


def render_distance_views(
    scan: Mesh,
    values: np.ndarray,
    path: str | Path,
    *,
    signed: bool = False,
    limit: float = LIMIT_MM,
    views: Sequence[str] = VIEWS,
    skin: Mesh | None = None,
    skin_opacity: float = 0.0,
    eyes: PaintedEyes | None = None,
    title: str = "scan vs fitted skin",
    size: tuple[int, int] = (440, 520),
) -> Path:
    """One PNG at ``path``: ``scan`` coloured by ``values`` (mm per vertex, NaN grey) in ``views``.

    ``signed`` picks the diverging map over ``-limit … +limit``, else the
    sequential one over ``0 … limit``.  The camera frames ``skin`` (the
    fitted head, so shoulders of a bust scan do not shrink the face) or else
    the counted vertices; ``skin_opacity`` > 0 also draws the fitted skin as
    a translucent overlay.  ``eyes`` (the fitted head's, painted with an iris
    and pupil: :func:`~workbench.render.visuals.face.paint_eyes`; same frame)
    are drawn under the scan: they show through its eye openings, and where
    the scan covers them (closed lids, a statue's eyes) the scan is drawn.
    Every panel has the same orthographic scale.
    """
    values = np.asarray(values, dtype=np.float64).ravel()
    if len(values) != scan.n_vertices:
        raise ValueError(f"need one value per scan vertex ({scan.n_vertices}), got {len(values)}")
    unknown = sorted(set(views) - set(_DIRECTIONS))
    if unknown:
        raise ValueError(f"unknown views {unknown}; use {sorted(_DIRECTIONS)}")
    if not limit > 0:
        raise ValueError(f"limit must be positive, got {limit}")
    _prefer_headless_gl()

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    poly = to_polydata(scan)
    poly.point_data["distance_mm"] = values
    # the scan's own vertex normals, once: pyvista's smooth shading would run VTK's normals
    # filter on every panel (~0.13 s each on a 300k-triangle scan)
    poly.point_data.active_normals = scan.vertex_normals
    bounds = _frame_bounds(scan, values, skin)
    centre = bounds.mean(axis=0)
    half_height = 0.5 * float(np.max(bounds[1] - bounds[0])) * 1.08
    clim = [-limit, limit] if signed else [0.0, limit]
    culling = _inner_side(scan)
    plotter = panel_row(len(views), size)
    try:
        for col, view in each_panel(plotter, views):
            last = col == len(views) - 1
            bar: ScalarBarArgs = {
                "title": "mm",
                "color": "black",
                "n_labels": 11 if signed else 6,
                "fmt": "%+.1f" if signed else "%.1f",
                "vertical": True,
                "position_x": 0.85,
                "position_y": 0.14,
                "height": 0.7,
                "width": 0.06,
                "title_font_size": 12,
                "label_font_size": 11,
            }
            plotter.add_mesh(
                poly,
                scalars="distance_mm",
                cmap=SIGNED_CMAP if signed else UNSIGNED_CMAP,
                clim=clim,
                nan_color=NAN_COLOUR,
                smooth_shading=False,
                interpolation="gouraud",
                specular=0.1,
                culling=culling,
                show_scalar_bar=last,
                scalar_bar_args=bar if last else {},
                copy_mesh=True,
            )
            if eyes is not None:
                _add_eyes_under(plotter, eyes)
            if skin is not None and skin_opacity > 0:
                plotter.add_mesh(
                    to_polydata(skin), color="#c9d6e8", opacity=skin_opacity, smooth_shading=True
                )
            direction = np.asarray(_DIRECTIONS[view])
            camera = plotter.camera
            camera.focal_point = tuple(centre)
            camera.position = tuple(centre + direction * 1000.0)
            camera.up = (0.0, 1.0, 0.0)
            plotter.enable_parallel_projection()  # type: ignore[call-arg]  # pyvista stub bug: wraps-typed method
            camera.parallel_scale = half_height
            camera.clipping_range = (1.0, 3000.0)
            label = view if view == "front" else f"{view} side"
            # at a fixed pixel position, so every panel's label has the same size
            plotter.add_text(
                f"{title}: {label}" if col == 0 and title else label,
                position=(10, size[1] - 26),
                font_size=11,
                color="black",
            )
        plotter.screenshot(str(path))
    finally:
        plotter.close()
    return path


def _add_eyes_under(plotter: Any, eyes: PaintedEyes) -> None:
    """The painted eyes, pushed back in depth a little so that a scan surface lying on
    them (within a fraction of a millimetre) is drawn, not the eyes."""
    actor = plotter.add_mesh(eyes_polydata(eyes), scalars="rgb", rgb=True, **SMOOTH, **EYE_SHADING)
    actor.GetMapper().SetRelativeCoincidentTopologyPolygonOffsetParameters(2.0, 40.0)


def _inner_side(scan: Mesh) -> Literal["back", "front"]:
    """The side of the scan's triangles that faces inward ("back" for outward winding).

    Culled in the pictures, so a hole shows the background through it rather
    than the inside of the far wall.  Decided by the area-weighted majority of
    the triangles facing away from the scan's centre.
    """
    if scan.n_faces == 0:
        return "back"
    tri = scan.vertices[scan.faces]
    area_normals = 0.5 * np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    outward = tri.mean(axis=1) - scan.vertices[np.unique(scan.faces)].mean(axis=0)
    return "back" if float(np.einsum("ij,ij->", area_normals, outward)) >= 0 else "front"


def _frame_bounds(scan: Mesh, values: np.ndarray, skin: Mesh | None) -> np.ndarray:
    """(2, 3) box the views frame: the fitted skin, else the counted vertices, else the scan."""
    if skin is not None and skin.n_vertices:
        pts = skin.vertices
    elif np.isfinite(values).any():
        pts = scan.vertices[np.isfinite(values)]
    else:
        pts = scan.vertices
    return np.array([pts.min(axis=0), pts.max(axis=0)])


def render_distance_histogram(
    distances: np.ndarray,
    path: str | Path,
    *,
    tolerances: Sequence[float] = (1.0, 2.5),
    size_inches: tuple[float, float] = (7.0, 2.8),
    dpi: int = 150,
) -> Path:
    """A histogram of the counted distances (mm; NaN dropped) with lines at ``tolerances``.

    Each line is labelled with the per cent of counted vertices at or below it.
    Drawn with matplotlib's Agg canvas (no display, no OpenGL).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    d = np.asarray(distances, dtype=np.float64).ravel()
    d = d[np.isfinite(d)]
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig = Figure(figsize=size_inches, dpi=dpi)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    top = max(4.0, max(tolerances) * 1.4)
    if len(d):
        top = max(top, float(np.percentile(d, 99.5)) * 1.05)
        clipped = np.minimum(d, top)
        ax.hist(
            clipped,
            bins=np.linspace(0.0, top, 61).tolist(),
            color="#d95f0e",
            edgecolor="white",
            lw=0.3,
            log=True,
        )
    else:
        ax.text(0.5, 0.5, "no counted vertices", transform=ax.transAxes, ha="center")
    for tol, style in zip(tolerances, ("--", ":", "-."), strict=False):
        share = 100.0 * float((d <= tol).mean()) if len(d) else 0.0
        ax.axvline(tol, color="#1f3b66", ls=style, lw=1.2)
        ax.text(
            tol,
            0.97,
            f" {tol:g} mm: {share:.1f} %",
            transform=ax.get_xaxis_transform(),
            va="top",
            ha="left",
            fontsize=8,
            color="#1f3b66",
        )
    ax.set_xlim(0.0, top)
    ax.set_xlabel("distance of a counted scan vertex to the fitted skin (mm)", fontsize=8)
    ax.set_ylabel("scan vertices (log scale)", fontsize=8)
    ax.tick_params(labelsize=7)
    beyond = int((d > top).sum())
    note = f"; {beyond} beyond {top:.1f} mm in the last bar" if beyond else ""
    ax.set_title(f"face-region scan vertices counted: {len(d)}{note}", fontsize=9)
    for side in ("top", "right"):
        ax.spines[side].set_visible(False)
    fig.tight_layout()
    fig.savefig(str(path))
    return path


def render_scan_fit_pictures(
    result: Any, folder: str | Path, *, size: tuple[int, int] = (440, 520)
) -> tuple[dict[str, Path], list[str]]:
    """The pictures of a :class:`~workbench.services.scan_fit.settings.ScanFit` into ``folder``.

    Returns ``({"distance": png, "signed": png, "histogram": png}, notes)``;
    a picture that cannot be drawn (no OpenGL, no scan kept in the result)
    is left out and ``notes`` says why.  The histogram needs no OpenGL.
    """
    folder = Path(folder)
    scan: Mesh | None = result.scan
    distance = result.scan_distance
    if scan is None or distance is None:
        return {}, ["the fit kept no scan or distances: no pictures"]
    skin = result.head.skin
    eyes = _head_eyes(result.head)
    out: dict[str, Path] = {}
    notes: list[str] = []
    try:
        out["histogram"] = render_distance_histogram(distance, folder / "distance_histogram.png")
    except (RuntimeError, OSError, ValueError) as exc:
        notes.append(f"no histogram ({exc})")
    jobs = (
        ("distance", "scan_distance.png", False, distance),
        ("signed", "scan_signed_distance.png", True, None),
    )
    for key, name, signed, values in jobs:
        try:
            if values is None:
                values = signed_scan_distance(scan, skin, distance)
            out[key] = render_distance_views(
                scan,
                values,
                folder / name,
                signed=signed,
                skin=skin,
                eyes=eyes,
                title="signed distance" if signed else "distance",
                size=size,
            )
        except (RuntimeError, OSError, ValueError) as exc:
            notes.append(f"no {key} picture ({exc})")
    order = {"distance": 0, "signed": 1, "histogram": 2}
    return dict(sorted(out.items(), key=lambda kv: order[kv[0]])), notes


def _head_eyes(head: Any) -> PaintedEyes | None:
    """The fitted head's eyes painted (None when it has none, or no globe to paint)."""
    meshes = getattr(head, "meshes", None) or {}
    eyes = meshes.get("eyes")
    if eyes is None or not eyes.n_faces:
        return None
    return paint_eyes(eyes, getattr(head, "eye_centres", None), getattr(head, "eye_radius", None))
