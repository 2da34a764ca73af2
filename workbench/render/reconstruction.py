"""Report pictures of a skull-to-face reconstruction (off-screen pyvista).

Units and frame: meshes and dowels in mm, in the *input* frame (e.g. scanner
coordinates).  ``frame`` is the 4×4 matrix from that frame to the head frame
(x to the subject's left, y up, z toward the face, Frankfort Horizontal at
y = 0); it only orients the camera, so "front" looks at the face and "side"
at the right profile even when the skull lies in scanner coordinates.  A
frame that is a mirror image of the subject (a reflection in ``frame``) is
drawn from the true side and flipped on screen, so "front" shows the subject's
right on the viewer's left in every case; on the pictures of one view, letters
at the left and right edges (R/L, A/P) say so
(:func:`workbench.render.snapshots.show_handedness`).  The
pictures are orthographic (parallel projection) and share one scale and one
centre per view, with a 50 mm scale bar, so they can be compared and
measured on the page.

Pictures (PNG, named ``<prefix>_<key>.png``; ``key`` is returned):

- ``skull_dowels_<view>``: the skull with one peg per landmark (a tube from
  the skull landmark to the dowel tip and a ball at the tip), coloured by
  depth in mm;
- ``face_skull_<view>``: the face semi-transparent over the skull and dowels;
- ``face_<view>``: the face alone;
- ``spread``: the face coloured by the ensemble spread (mm), front, side and
  three-quarter in one picture with one colour bar.

``<view>`` is ``front``, ``side`` and ``three_quarter``.  The eyes, when given,
are painted with an iris and pupil (:func:`workbench.render.visuals.face.paint_eyes`:
finer globes, the gaze read from each cornea in the frame drawn) in every picture
with the face.

:func:`render_builds` adds the pictures of an unknown body build (named
``<key>.png``, or ``<prefix>_<key>.png`` with a prefix):

- ``builds_front``, ``builds_side``: the faces of the builds (slender,
  average, heavy) side by side, front and right profile, one camera for all
  three (same scale, same place), each labelled with its build and BMI;
- ``band``: the main face coloured by the half-width (mm) of its 95 %
  uncertainty band, front, side and three-quarter with one colour bar.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from workbench.core.errors import InputError
from workbench.core.mesh import Mesh
from workbench.render.snapshots import (
    _prefer_headless_gl,
    show_handedness,
    to_polydata,
    view_directions,
)
from workbench.render.visuals.face import EYE_SHADING, eyes_polydata, paint_eyes
from workbench.render.visuals.orientation import Anatomy
from workbench.render.visuals.style import SMOOTH

VIEWS = ("front", "side", "three_quarter")
BONE, SKIN, EYE, BACKGROUND = "#e9e0c9", "#e3b48f", "#d8dde3", "white"
DOWEL_CMAP, SPREAD_CMAP = "viridis", "YlOrRd"
#: the views of the build pictures (``builds_<view>``)
BUILD_VIEWS = ("front", "side")
BAND_TITLE = "95 % band half-width (mm)"
TUBE_RADIUS_MM, BALL_RADIUS_MM, SCALE_BAR_MM = 0.9, 1.9, 50.0
FACE_OPACITY = 0.4
#: the face is framed down to this far below the skull (the neck is cut off)
NECK_MARGIN_MM = 20.0


#: colour of skin over missing bone
INFERRED = "#8fa3b8"


def render_reconstruction(
    skull: Mesh,
    face: Mesh | None,
    dowels: tuple[np.ndarray, np.ndarray] | None,
    out_dir: str | Path,
    *,
    frame: np.ndarray | None = None,
    spread: np.ndarray | None = None,
    inferred: np.ndarray | None = None,
    prefix: str = "recon",
    eyes: Mesh | None = None,
    size: tuple[int, int] = (600, 700),
    views: Sequence[str] = VIEWS,
) -> dict[str, Path]:
    """Write the report pictures to ``out_dir`` and return ``{key: path}``.

    Parameters
    ----------
    skull : Mesh
        The skull (cranium and mandible as one mesh), mm, input frame.
    face : Mesh or None
        The reconstructed skin; without it only the skull pictures are made.
    dowels : (origins, tips) or None
        ``(n, 3)`` skull landmarks and dowel tips, mm, input frame.
    frame : (4, 4), optional
        Input frame → head frame (default: the input already is the head frame).
    spread : (face.n_vertices,), optional
        Per-vertex ensemble spread of the face in mm (adds the ``spread`` picture).
    eyes : Mesh, optional
        Eyeballs (mm, input frame), drawn with the face as painted globes with an
        iris and pupil (:func:`~workbench.render.visuals.face.paint_eyes`), also
        under the semi-transparent face and on the spread and inferred maps.
    inferred : (face.n_vertices,) bool, optional
        Skin over bone the registration did not find (shaped by the reference
        alone); with any, the ``inferred`` picture shows it in blue-grey.
    size : (width, height)
        Pixels per view.
    """
    origins, tips = _check(skull, face, dowels, spread)
    anterior, superior, left = _orientation(frame)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    _prefer_headless_gl()
    import pyvista as pv

    framed = [skull.vertices, tips]
    face_pd = None
    if face is not None:  # a bust: the face cut just below the skull (no long neck)
        face_pd, kept = _face_bust(face, skull, superior, spread, inferred)
        framed.append(kept)
    cameras = {v: _camera(np.vstack(framed), v, anterior, superior, size, left) for v in views}
    scene = _Scene(
        # the skull's cached vertex normals: VTK's normals filter on a 200k-triangle skull for
        # every picture it is in cost ~0.1 s each
        skull=to_polydata(skull, normals=True),
        pegs=_pegs(pv, origins, tips) if len(origins) else None,
        depth_range=_nice_range(np.linalg.norm(tips - origins, axis=1)),
        face=face_pd,
        eyes=_eyes_pd(eyes),
        size=size,
    )

    def path(key: str) -> Path:
        return out / f"{prefix}_{key}.png"

    written: dict[str, Path] = {}
    studio = _Studio(pv, size)
    try:
        for view in views:
            written.update(_shoot_view(studio, scene, cameras[view], view, path))
        if spread is not None and face_pd is not None:
            spread_range = _nice_range(np.array([0.0, np.percentile(spread, 99.5)]))

            coloured = _scalar_map(
                face_pd, "spread_mm", spread_range, scene.eyes, "spread (mm)", views, size
            )

            written["spread"] = _shoot(
                studio, path("spread"), [(cameras[v], v) for v in views], coloured
            )
        if inferred is not None and face_pd is not None and np.any(inferred):
            written["inferred"] = _shoot(
                studio,
                path("inferred"),
                [(cameras[v], v) for v in views],
                scene.inferred_painter(views[0]),
            )
    finally:
        studio.close()
    return written


def _face_bust(
    face: Mesh,
    skull: Mesh,
    superior: np.ndarray,
    spread: np.ndarray | None,
    inferred: np.ndarray | None,
) -> tuple[Any, np.ndarray]:
    """The face as PolyData cut :data:`NECK_MARGIN_MM` below the skull, and the vertices it keeps.

    ``superior`` is the unit up direction in the input frame; ``spread`` (mm)
    and ``inferred`` become point data ``spread_mm`` and ``inferred``.
    """
    floor = float((skull.vertices @ superior).min()) - NECK_MARGIN_MM
    keep = face.vertices @ superior >= floor
    face_pd = to_polydata(face)
    if spread is not None:
        face_pd["spread_mm"] = np.asarray(spread, float)
    if inferred is not None:
        face_pd["inferred"] = np.asarray(inferred, float)
    return face_pd.clip(normal=superior, origin=superior * floor, invert=False), face.vertices[keep]


@dataclass(frozen=True)
class _Scene:
    """What the reconstruction pictures draw, as PolyData (mm, input frame).

    ``pegs`` are the dowel tubes and balls (None without dowels), coloured on
    ``depth_range`` (mm, :func:`_nice_range`); ``face`` is the cut bust (None
    without a face); ``size`` is the panel size in pixels.
    """

    skull: Any
    pegs: list | None
    depth_range: tuple[float, float, float]
    face: Any
    eyes: Any
    size: tuple[int, int]

    def draw_skull(self, p, bar: bool) -> None:
        """The bone and the dowels coloured by depth, with its colour bar if ``bar``."""
        p.add_mesh(
            self.skull,
            color=BONE,
            smooth_shading=False,
            interpolation="phong",
            specular=0.15,
            diffuse=0.85,
        )
        if self.pegs is not None:
            actors = [
                p.add_mesh(
                    part,
                    scalars="depth_mm",
                    cmap=DOWEL_CMAP,
                    clim=self.depth_range[:2],
                    smooth_shading=True,
                    show_scalar_bar=False,
                )
                for part in self.pegs
            ]
            if bar:
                _scalar_bar(p, actors[0], "tissue depth (mm)", self.depth_range, self.size)

    def over(self, p, _v) -> None:
        """The skull, dowels and eyes under the semi-transparent face."""
        self.draw_skull(p, False)
        _add_eyes(p, self.eyes)
        p.add_mesh(self.face, color=SKIN, opacity=FACE_OPACITY, smooth_shading=True, specular=0.1)

    def alone(self, p, _v) -> None:
        """The face alone, with the eyes."""
        p.add_mesh(self.face, color=SKIN, smooth_shading=True, specular=0.15, diffuse=0.9)
        _add_eyes(p, self.eyes)

    def inferred_painter(self, first_view: str) -> Callable[[Any, str], None]:
        """A painter for :func:`_shoot`: skin over missing bone in blue-grey, explained in
        the ``first_view`` panel."""

        def marked(p, v) -> None:
            p.add_mesh(
                self.face,
                scalars="inferred",
                cmap=[SKIN, INFERRED],
                clim=(0.0, 1.0),
                smooth_shading=True,
                show_scalar_bar=False,
                specular=0.1,
            )
            _add_eyes(p, self.eyes)
            if v == first_view:
                p.add_text(
                    "blue-grey: no bone under the skin (inferred from the reference)",
                    position="lower_left",
                    font_size=9,
                    color="#333333",
                )

        return marked


def _shoot_view(
    studio: _Studio, scene: _Scene, cam: dict, view: str, path: Callable[[str], Path]
) -> dict[str, Path]:
    """The pictures of one view: skull and dowels, then (with a face) face over skull and face."""
    written = {
        f"skull_dowels_{view}": _shoot(
            studio,
            path(f"skull_dowels_{view}"),
            [(cam, view)],
            lambda p, _v: scene.draw_skull(p, True),
        )
    }
    if scene.face is None:
        return written
    written[f"face_skull_{view}"] = _shoot(
        studio, path(f"face_skull_{view}"), [(cam, view)], scene.over, peel=True
    )
    written[f"face_{view}"] = _shoot(studio, path(f"face_{view}"), [(cam, view)], scene.alone)
    return written


def render_builds(
    faces: Mapping[str, Mesh],
    out_dir: str | Path,
    *,
    frame: np.ndarray | None = None,
    bmi: Mapping[str, float] | None = None,
    main: str | None = None,
    eyes: Mesh | None = None,
    skull: Mesh | None = None,
    band_face: Mesh | None = None,
    band_mm: np.ndarray | None = None,
    prefix: str = "",
    size: tuple[int, int] = (600, 700),
) -> dict[str, Path]:
    """Write the pictures of the build faces and the band to ``out_dir``; return ``{key: path}``.

    Keys ``builds_front``, ``builds_side`` (with ``faces``) and ``band`` (with
    ``band_mm``), written as ``<key>.png``, or ``<prefix>_<key>.png`` with a
    ``prefix``.  Each build picture shows the faces side by side in the order of
    ``faces`` (thinnest first) through one orthographic camera that frames all of
    them, so their widths and profiles compare at the same scale (50 mm bars).

    Parameters
    ----------
    faces : {build name: Mesh}
        The faces of the builds, mm, input frame (empty: only the band picture).
    frame : (4, 4), optional
        Input frame → head frame (default: the input already is the head frame).
    bmi : {build name: BMI kg/m²}, optional
        Printed under each face ("slender · BMI 19"); every face needs one.
    main : str, optional
        The build of the main face (``face.ply``), marked so under its face.
    eyes : Mesh, optional
        Eyeballs (mm, input frame), painted with an iris and pupil and drawn with
        every face and on the band picture.
    skull : Mesh, optional
        The skull, input frame: the faces are cut :data:`NECK_MARGIN_MM` below it
        (a bust, as in :func:`render_reconstruction`); without it they are whole.
    band_face : Mesh, optional
        The main face the band belongs to, mm, input frame.
    band_mm : (band_face.n_vertices,), optional
        Half-width (mm, ≥ 0) of the 95 % band per vertex of ``band_face``
        (adds the ``band`` picture).
    size : (width, height)
        Pixels per panel (one panel per face; the band picture has three).
    """
    names = _check_builds(faces, bmi, main, band_face, band_mm)
    anterior, superior, left = _orientation(frame)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    _prefer_headless_gl()
    import pyvista as pv

    floor = None
    if skull is not None and skull.n_vertices:
        floor = float((skull.vertices @ superior).min()) - NECK_MARGIN_MM

    def bust(mesh: Mesh, scalars: dict[str, np.ndarray] | None = None):
        """``mesh`` as PolyData cut at the floor, and the vertices it keeps (to frame)."""
        pd = to_polydata(mesh)
        for key, values in (scalars or {}).items():
            pd[key] = values
        if floor is None:
            return pd, mesh.vertices
        kept = mesh.vertices[mesh.vertices @ superior >= floor]
        return pd.clip(normal=superior, origin=superior * floor, invert=False), kept

    def path(key: str) -> Path:
        return out / (f"{prefix}_{key}.png" if prefix else f"{key}.png")

    eyes_pd = _eyes_pd(eyes)
    written: dict[str, Path] = {}
    studio = _Studio(pv, size)
    try:
        busts = {n: bust(faces[n]) for n in names}
        if busts:
            # one camera per view frames every face: same scale and place in all panels
            framed = np.vstack([kept for _, kept in busts.values()])
            labels = {n: _build_label(n, bmi, main) for n in names}
            for view in BUILD_VIEWS:
                cam = _camera(framed, view, anterior, superior, size, left)

                def build(p, name: str, cam: dict = cam) -> None:
                    p.add_mesh(
                        busts[name][0], color=SKIN, smooth_shading=True, specular=0.15, diffuse=0.9
                    )
                    _add_eyes(p, eyes_pd)
                    _label(pv, p, cam, labels[name], size)

                written[f"builds_{view}"] = _shoot(
                    studio,
                    path(f"builds_{view}"),
                    [(cam, n) for n in names],
                    build,
                    one_bar=True,
                )
        if band_face is not None and band_mm is not None:
            band_pd, kept = bust(band_face, {"band_mm": np.asarray(band_mm, float)})
            cameras = {v: _camera(kept, v, anterior, superior, size, left) for v in VIEWS}
            band_range = _nice_range(np.array([0.0, np.percentile(band_mm, 99.5)]))

            banded = _scalar_map(band_pd, "band_mm", band_range, eyes_pd, BAND_TITLE, VIEWS, size)

            written["band"] = _shoot(studio, path("band"), [(cameras[v], v) for v in VIEWS], banded)
    finally:
        studio.close()
    return written


# ---------------------------------------------------------------- helpers
def _eyes_pd(eyes: Mesh | None) -> Any:
    """The eyes as PolyData: painted globes with an iris and pupil
    (:func:`~workbench.render.visuals.face.paint_eyes`), or the mesh as it is when it
    holds no globe to paint; None without eyes."""
    if eyes is None or not eyes.n_faces:
        return None
    painted = paint_eyes(eyes)
    return to_polydata(eyes, normals=True) if painted is None else eyes_polydata(painted)


def _add_eyes(p, eyes) -> None:
    """Draw :func:`_eyes_pd`'s eyes (nothing for None): coloured per vertex when painted."""
    if eyes is None:
        return
    if "rgb" in eyes.point_data:
        p.add_mesh(eyes, scalars="rgb", rgb=True, **SMOOTH, **EYE_SHADING)
    else:
        p.add_mesh(eyes, color=EYE, **SMOOTH, specular=0.4)


def _scalar_map(
    surface,
    scalars: str,
    scale: tuple[float, float, float],
    eyes,
    title: str,
    views: Sequence[str],
    size: tuple[int, int],
):
    """A painter for :func:`_shoot`: ``surface`` coloured by its point data ``scalars`` (mm)
    on ``scale``, with the eyes, one colour bar titled ``title`` under the middle view."""

    def paint(p, v: str) -> None:
        actor = p.add_mesh(
            surface,
            scalars=scalars,
            cmap=SPREAD_CMAP,
            clim=scale[:2],
            smooth_shading=True,
            show_scalar_bar=False,
        )
        _add_eyes(p, eyes)
        if v == views[len(views) // 2]:
            _scalar_bar(p, actor, title, scale, size)

    return paint


def _check(skull: Mesh, face: Mesh | None, dowels, spread) -> tuple[np.ndarray, np.ndarray]:
    if skull.n_faces == 0:
        raise InputError("skull", "the skull mesh has no triangles")
    origins = tips = np.zeros((0, 3))
    if dowels is not None:
        origins, tips = (np.asarray(a, float).reshape(-1, 3) for a in dowels)
        if origins.shape != tips.shape:
            raise InputError("dowels", f"{len(origins)} origins but {len(tips)} tips")
        if not (np.isfinite(origins).all() and np.isfinite(tips).all()):
            raise InputError(
                "dowels", "dowel origins and tips must be finite (leave absent landmarks out)"
            )
    if spread is not None:
        if face is None:
            raise InputError("spread", "a spread map needs the face it belongs to")
        if np.shape(spread) != (face.n_vertices,):
            raise InputError(
                "spread", f"{np.size(spread)} values for a face of {face.n_vertices} vertices"
            )
        if not np.isfinite(spread).all():
            raise InputError("spread", "the spread map has NaN or infinite values")
    return origins, tips


def _check_builds(
    faces: Mapping[str, Mesh],
    bmi: Mapping[str, float] | None,
    main: str | None,
    band_face: Mesh | None,
    band_mm: np.ndarray | None,
) -> tuple[str, ...]:
    """The build names in order, after checking the inputs of :func:`render_builds`."""
    if not isinstance(faces, Mapping):
        raise InputError(
            "faces", f"the build faces are a {{name: Mesh}} dict, not {type(faces).__name__}"
        )
    names = tuple(faces)
    if not names and band_mm is None:
        raise InputError("faces", "no build faces and no band: nothing to draw")
    for name in names:
        mesh = faces[name]
        if not isinstance(mesh, Mesh) or mesh.n_faces == 0:
            raise InputError("faces", f"the {name!r} face has no triangles")
        if not np.isfinite(mesh.vertices).all():
            raise InputError("faces", f"the {name!r} face has NaN or infinite vertices")
    if bmi is not None:
        missing = [n for n in names if n not in bmi]
        if missing:
            raise InputError("bmi", f"no BMI for the {', '.join(map(repr, missing))} face")
        bad = [n for n in names if not (np.isfinite(bmi[n]) and bmi[n] > 0)]
        if bad:
            raise InputError(
                "bmi", f"the BMI of {', '.join(map(repr, bad))} must be a positive number (kg/m²)"
            )
    if main is not None and not isinstance(main, str):
        raise InputError("main", f"the main build is a name, not {type(main).__name__}")
    if (band_face is None) != (band_mm is None):
        raise InputError(
            "band_mm", "the band picture needs both the face and its per-vertex half-width"
        )
    if band_face is not None and band_mm is not None:
        if band_face.n_faces == 0:
            raise InputError("band_face", "the band's face has no triangles")
        if np.shape(band_mm) != (band_face.n_vertices,):
            raise InputError(
                "band_mm",
                f"{np.size(band_mm)} values for a face of {band_face.n_vertices} vertices",
            )
        values = np.asarray(band_mm, float)
        if not np.isfinite(values).all():
            raise InputError("band_mm", "the band has NaN or infinite values")
        if (values < 0).any():
            raise InputError("band_mm", "a band half-width (mm) cannot be negative")
    return names


def _build_label(name: str, bmi: Mapping[str, float] | None, main: str | None) -> str:
    """``"slender · BMI 19"``; the main face's label says it is ``face.ply``."""
    text = name if bmi is None else f"{name} · BMI {round(float(bmi[name]), 1):g}"
    return text + ("\n(face.ply)" if name == main else "")


def _label(pv, plotter, cam: dict, text: str, size: tuple[int, int]) -> None:
    """``text`` centred under the subject, level with the scale bar, in front of everything."""
    front = cam["centre"] + cam["direction"] * (cam["reach"] / 2)
    anchor = front - cam["up"] * (cam["scale"] * 0.93)
    plotter.add_point_labels(
        pv.PolyData([anchor]),
        [text],
        show_points=False,
        shape=None,
        font_size=_font(size, 8),
        text_color="black",
        always_visible=True,
        bold=False,
        justification_horizontal="center",
    )


def _orientation(frame: np.ndarray | None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Anterior, superior and (the subject's) left directions in the input frame."""
    if frame is None:
        return np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0])
    m = np.asarray(frame, float)
    if m.shape != (4, 4) or not np.isfinite(m).all():
        raise InputError("frame", "the input-to-head frame must be a finite 4x4 matrix")
    rot = m[:3, :3]
    if abs(np.linalg.det(rot)) < 1e-9:
        raise InputError("frame", "the input-to-head frame is singular")
    anterior, superior, left = (np.linalg.solve(rot, axis) for axis in np.eye(3)[[2, 1, 0]])
    return (
        anterior / np.linalg.norm(anterior),
        superior / np.linalg.norm(superior),
        left / np.linalg.norm(left),
    )


def _camera(
    points: np.ndarray,
    view: str,
    anterior: np.ndarray,
    superior: np.ndarray,
    size: tuple[int, int],
    left: np.ndarray | None = None,
) -> dict:
    """One orthographic camera that frames ``points`` for ``view`` with a margin.

    ``right`` is the picture's right as shown (flipped for a mirror-image frame).
    """
    anatomy = Anatomy.of(anterior, superior, left)
    direction, up = view_directions(view, anterior, superior, left)
    up = up - direction * (up @ direction)
    up /= np.linalg.norm(up)
    right = np.cross(up, direction) * (-1.0 if anatomy.mirrored else 1.0)
    u, w = points @ right, points @ up
    lo, hi = np.array([u.min(), w.min()]), np.array([u.max(), w.max()])
    lo[1] -= 0.17 * (hi[1] - lo[1])  # room for the colour and scale bars
    mid = (lo + hi) / 2
    depth = points @ direction
    centre = right * mid[0] + up * mid[1] + direction * (depth.min() + depth.max()) / 2
    half_h = max((hi[1] - lo[1]) / 2, (hi[0] - lo[0]) / 2 * size[1] / size[0]) * 1.06
    reach = float(depth.max() - depth.min()) + 100.0
    return {
        "centre": centre,
        "direction": direction,
        "up": up,
        "right": right,
        "scale": half_h,
        "reach": reach,
        "aspect": size[0] / size[1],
        "anatomy": anatomy,
    }


def _pegs(pv, origins: np.ndarray, tips: np.ndarray) -> list:
    """Tubes from origin to tip and balls at the tips, with point data ``depth_mm``."""
    n = len(origins)
    depth = np.linalg.norm(tips - origins, axis=1)
    lines = pv.PolyData(
        np.vstack([origins, tips]),
        lines=np.column_stack([np.full(n, 2), np.arange(n), np.arange(n) + n]).ravel(),
    )
    lines["depth_mm"] = np.concatenate([depth, depth])
    tubes = lines.tube(radius=TUBE_RADIUS_MM, n_sides=14, capping=True)
    balls = pv.PolyData(tips)
    balls["depth_mm"] = depth
    balls = balls.glyph(
        geom=pv.Sphere(radius=BALL_RADIUS_MM, theta_resolution=16, phi_resolution=12),
        scale=False,
        orient=False,
    )
    return [tubes, balls]


def _nice_range(values: np.ndarray) -> tuple[float, float, float]:
    """``(low, high, step)`` on round numbers covering ``values``, with at most 7 ticks."""
    if not len(values):
        return 0.0, 1.0, 0.5
    lo, hi = float(np.min(values)), float(np.max(values))
    for step in (0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0):
        a, b = np.floor(lo / step) * step, np.ceil(hi / step) * step
        if b <= a:
            b = a + step
        if (b - a) / step <= 6:
            return float(a), float(b), step
    return lo, max(hi, lo + 1.0), (max(hi, lo + 1.0) - lo) / 6


def _font(size: tuple[int, int], points: float) -> int:
    """A font size that prints at about ``points`` pt when the picture is 57 mm wide."""
    return max(8, round(points * size[0] / 600 * 3.3))


def _scalar_bar(
    p, actor, title: str, scale: tuple[float, float, float], size: tuple[int, int]
) -> None:
    """A horizontal colour bar for ``actor`` in the lower left corner."""
    lo, hi, step = scale
    bar = p.add_scalar_bar(
        title=title,
        mapper=actor.mapper,
        vertical=False,
        position_x=0.06,
        position_y=0.015,
        width=0.58,
        height=0.155,
        n_labels=round((hi - lo) / step) + 1,
        fmt="%.0f" if step >= 1 else "%.1f",
        color="black",
        title_font_size=_font(size, 6.5),
        label_font_size=_font(size, 6),
        bold=False,
        unconstrained_font_size=True,
    )
    bar.SetTextPositionToPrecedeScalarBar()  # labels under the bar, title above


class _Studio:
    """One off-screen window of one panel's size, reused for every picture of a call.

    llvmpipe compiles its shaders once per window: a window per picture cost ~0.2 s
    each.  A picture of several panels is rendered panel by panel and put side by
    side, which gives the same image as one window split into viewports.
    """

    def __init__(self, pv, size: tuple[int, int]) -> None:
        self.pv, self.size = pv, size
        self.plotter = pv.Plotter(off_screen=True, border=False, window_size=size)
        self.plotter.set_background(BACKGROUND)
        self.plotter.enable_anti_aliasing("ssaa")

    def close(self) -> None:
        self.plotter.close()


def _shoot(
    studio: _Studio,
    path: Path,
    panels: Sequence[tuple[dict, str]],
    draw,
    *,
    peel: bool = False,
    one_bar: bool = False,
) -> Path:
    """One picture with one panel per ``(camera, view)``; ``draw(plotter, view)`` adds the actors.

    Every panel has a scale bar, or with ``one_bar`` only the last (panels of one camera).
    """
    from PIL import Image

    plotter, images = studio.plotter, []
    for i, (cam, view) in enumerate(panels):
        plotter.suppress_rendering = True  # not a render per added actor
        plotter.clear()  # actors, scalar bars and lights
        plotter.enable_lightkit()
        if peel:
            plotter.enable_depth_peeling(number_of_peels=8)
        else:
            plotter.disable_depth_peeling()
        draw(plotter, view)
        if not one_bar or i == len(panels) - 1:
            _scale_bar(studio.pv, plotter, cam, studio.size)
        camera = plotter.camera
        camera.focal_point = cam["centre"]
        camera.position = cam["centre"] + cam["direction"] * cam["reach"]
        camera.up = cam["up"]
        plotter.enable_parallel_projection()
        camera.parallel_scale = cam["scale"]
        camera.clipping_range = (1.0, 2.0 * cam["reach"] + 400.0)
        # letters on a picture of one view (not beside the faces of a row of panels)
        show_handedness(plotter.renderer, cam["anatomy"], letters=len(panels) == 1)
        plotter.suppress_rendering = False
        plotter.render()  # a screenshot of a window shown before keeps its last frame
        images.append(np.asarray(plotter.screenshot(return_img=True))[..., :3])
    Image.fromarray(np.hstack(images)).save(path, compress_level=4)
    return path


def _scale_bar(pv, plotter, cam: dict, size: tuple[int, int]) -> None:
    """A 50 mm bar in the lower right corner, drawn in front of everything."""
    half_w = cam["scale"] * cam["aspect"]
    front = cam["centre"] + cam["direction"] * (cam["reach"] / 2)
    end = front + cam["right"] * (half_w * 0.9) - cam["up"] * (cam["scale"] * 0.9)
    start = end - cam["right"] * SCALE_BAR_MM
    plotter.add_mesh(pv.Line(start, end), color="black", line_width=3)
    plotter.add_point_labels(
        pv.PolyData([(start + end) / 2 + cam["up"] * cam["scale"] * 0.05]),
        [f"{SCALE_BAR_MM:.0f} mm"],
        show_points=False,
        shape=None,
        font_size=_font(size, 6.5),
        text_color="black",
        always_visible=True,
        bold=False,
        justification_horizontal="center",
    )
