"""Skin surfaces: the fitted face (plain or coloured by a value), the true skin coloured by
its signed distance, the guide view's translucent face, a face scan coloured by its
distance to the fitted skin or in its own colours (vertex colours or texture), and the
fitted skin over a scan (plain, or in the scan's colours carried onto it).

Translucent skins have their back faces culled (:func:`~workbench.render.visuals.style.cull_back_faces`).

Eyes: a head's globes repainted with an iris and pupil (:func:`paint_eyes`: finer
globes coloured per vertex by :mod:`workbench.core.appearance`), drawn by the window's
face layer, the age tool and the report pictures alike (:func:`add_eyes`,
:func:`eyes_polydata`); globes that must keep their vertices (the animated eyes) take
the same pattern averaged about each vertex (:func:`filtered_eye_colours`).
"""

from __future__ import annotations

import hashlib
import threading
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from workbench.core.appearance import (
    DEFAULT_IRIS,
    eye_gazes,
    eye_owner,
    eyes_colours,
    fine_eyes,
)
from workbench.core.mesh import Mesh
from workbench.render.snapshots import to_polydata
from workbench.render.visuals.scalar_bars import bar_args
from workbench.render.visuals.style import SKIN, SMOOTH, cull_back_faces

if TYPE_CHECKING:
    from workbench.core.colour_transfer import ScanColours

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
    rgb: np.ndarray | None = None,
) -> Any:
    """The fitted skin; with ``scalars`` (per vertex, mm) coloured (viridis) with a bar
    titled ``title`` (default "mm"); else with ``rgb`` (``(n, 3)`` uint8 sRGB per vertex,
    the colours chosen for the face: :func:`paint_face`) in those colours."""
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
    if scalars is None and rgb is not None:
        paint_face(actor, rgb)
    return cull_back_faces(actor)


#: the point array of a face drawn in the colours chosen for it (sRGB, uint8)
FACE_COLOURS = "chosen colours (artistic)"


def face_painted(actor: Any) -> bool:
    """The face ``actor`` shows chosen colours (:func:`paint_face`)."""
    mapper = actor.GetMapper()
    return bool(mapper.GetScalarVisibility()) and mapper.GetArrayName() == FACE_COLOURS


def face_plain(actor: Any) -> bool:
    """The face ``actor`` is drawn in one colour or in chosen colours, not by a value (a
    colour map such as spread or band, which :func:`paint_face` leaves alone)."""
    return face_painted(actor) or not actor.GetMapper().GetScalarVisibility()


def paint_face(actor: Any, rgb: np.ndarray | None) -> bool:
    """Show a drawn face in per-vertex colours (``(n, 3)`` uint8 sRGB, as they are), or,
    with ``rgb=None``, in its plain skin colour again; in place, no new actor.

    Returns False (nothing changed) when the face is coloured by a value, or ``rgb``
    does not have one colour per drawn point.  The colours ride on the points, so the
    face keeps them when its points move (the build slider).
    """
    from vtkmodules.util.numpy_support import numpy_to_vtk

    from workbench.render.visuals.update import source_data

    if not face_plain(actor):
        return False
    mapper = actor.GetMapper()
    data = source_data(actor)
    if rgb is None:
        mapper.ScalarVisibilityOff()
        data.GetPointData().RemoveArray(FACE_COLOURS)
        data.Modified()
        return True
    colours = np.ascontiguousarray(rgb, dtype=np.uint8)
    if colours.shape != (data.GetNumberOfPoints(), 3):
        return False
    array = numpy_to_vtk(colours, deep=True)
    array.SetName(FACE_COLOURS)
    data.GetPointData().AddArray(array)
    mapper.SetScalarModeToUsePointFieldData()
    mapper.SelectColorArray(FACE_COLOURS)
    mapper.SetColorModeToDirectScalars()
    mapper.ScalarVisibilityOn()
    data.Modified()
    return True


def add_colour_note(plotter: Any, text: str) -> Any:
    """A small light caption in the view's lower left corner, hidden until its caller shows
    it (the note that the face's colours are an artistic choice, not evidence)."""
    actor = plotter.add_text(
        text, position="lower_left", font_size=8, color="#e8e8e8", name="face_colour_note"
    )
    actor.SetVisibility(False)
    return actor


#: a refit held back (it would turn the face or move it away from the edit): amber, faint
HELD = (0.95, 0.55, 0.10)


def add_hair(
    plotter: Any, mesh: Mesh, srgb: np.ndarray, normals: np.ndarray, *, name: str = "hair"
) -> Any:
    """Hair ribbons (:func:`workbench.services.grooming.hair_meshes`, mapped to the view's
    frame) in their sRGB colours per vertex, lit with their shading ``normals``, two-sided
    and not pickable."""
    poly = to_polydata(mesh)
    poly.point_data["Normals"] = np.asarray(normals, float)
    poly.point_data.active_normals_name = "Normals"
    poly.point_data["srgb"] = np.asarray(srgb, np.uint8)
    actor = plotter.add_mesh(
        poly,
        scalars="srgb",
        rgb=True,
        pickable=False,
        render=False,
        name=name,
        specular=0.15,
        **SMOOTH,
    )
    return actor


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


#: the point array of a scan, or of a fitted skin, drawn in the scan's own colours (sRGB,
#: uint8, shown as they are)
SCAN_COLOURS = "scan colours"


def add_skin_part(plotter: Any, mesh: Mesh, *, name: str, rgb: np.ndarray | None = None) -> Any:
    """A fitted skin (part) drawn over a scan, translucent by its caller; the camera is
    kept (it is redrawn when the user toggles detail).

    ``rgb``: ``(n_vertices, 3)`` uint8 sRGB per vertex of ``mesh`` (the scan's colours
    carried onto the skin), drawn as they are; else the plain skin colour.
    """
    poly = to_polydata(mesh, normals=True)
    kw: dict[str, Any] = {"color": SKIN}
    if rgb is not None and len(rgb) == poly.n_points:
        poly.point_data[SCAN_COLOURS] = np.ascontiguousarray(rgb, np.uint8)
        kw = {"scalars": SCAN_COLOURS, "rgb": True}
    actor = plotter.add_mesh(
        poly,
        **SMOOTH,
        pickable=False,
        render=False,
        reset_camera=False,
        name=name,
        **kw,
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
    colours: ScanColours | None = None,
) -> tuple[Any, Any]:
    """A face scan, pickable: grey, or coloured by ``distance`` (per vertex, mm; NaN
    where not counted) with a bar titled ``title`` when it has one value per vertex,
    or in its own ``colours`` (:func:`scan_polydata`; ``distance`` is then not shown).
    The camera is left as it is (redrawn when the user changes the colouring).

    Returns ``(actor, polydata)``: the polydata is the surface clicks are picked on
    (the scan's triangles; a textured scan's vertices are split where their
    texture coordinates differ, the surface is the same).
    """
    if colours is not None:
        poly = scan_polydata(mesh, colours)
        if colours.image is not None:
            kw: dict[str, Any] = {"texture": scan_texture(colours.image), "color": "white"}
        else:
            kw = {"scalars": SCAN_COLOURS, "rgb": True}
        actor = plotter.add_mesh(
            poly, **SMOOTH, pickable=True, render=False, reset_camera=False, name=name, **kw
        )
        return actor, poly
    poly = to_polydata(mesh, normals=True)
    kw = {"color": SCAN_GREY}
    if distance is not None and len(distance) == poly.n_points:
        poly.point_data[title] = distance
        kw = {
            "scalars": title,
            "cmap": "viridis",
            "clim": clim,
            "nan_color": NAN_GREY,
            "scalar_bar_args": bar_args(title, n_labels=6, fmt="%.1f"),
        }
    actor = plotter.add_mesh(
        poly, **SMOOTH, pickable=True, render=False, reset_camera=False, name=name, **kw
    )
    return actor, poly


def scan_polydata(mesh: Mesh, colours: ScanColours) -> Any:
    """``pyvista.PolyData`` of a scan in its own colours (mm, the scan's frame).

    Vertex colours: the scan's vertices and triangles with the point array
    :data:`SCAN_COLOURS`.  A texture (it wins, as in the colour transfer): VTK
    holds one texture coordinate per point, so the scan's vertices come first
    (each with one of its corners' coordinates) and a vertex gets one more point
    per other coordinate its corners have (a seam), with the vertex's normal;
    the triangles are ``colours.faces`` (the file's corner order, which the
    coordinates follow).  Corners of a triangle without a texture (NaN) take the
    image's corner.  Raises ValueError when the colours belong to another mesh.
    """
    if colours.n_vertices != mesh.n_vertices:
        raise ValueError(
            f"the colours are of {colours.n_vertices} vertices, the scan has {mesh.n_vertices}"
        )
    if colours.image is None or colours.corner_uv is None:
        poly = to_polydata(mesh, normals=True)
        assert colours.vertex_rgb is not None
        poly.point_data[SCAN_COLOURS] = np.ascontiguousarray(colours.vertex_rgb, np.uint8)
        return poly
    import pyvista as pv

    faces = np.asarray(colours.faces, np.int64)
    uv = np.nan_to_num(np.asarray(colours.corner_uv, float), nan=0.0).reshape(-1, 2)
    vid = faces.ravel()
    n = mesh.n_vertices
    # each vertex keeps one of its corners' coordinates; only the corners across a seam
    # (another coordinate) become new points, one per distinct (vertex, coordinate)
    per_vertex = np.zeros((n, 2))
    per_vertex[vid] = uv
    seam = np.flatnonzero((per_vertex[vid] != uv).any(axis=1))
    keys = np.column_stack([vid[seam].astype(float), uv[seam]])
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    corner_point = vid.copy()
    corner_point[seam] = n + inverse.ravel()
    points = np.r_[np.arange(n), vid[seam][first]]
    poly = pv.PolyData.from_regular_faces(
        np.array(mesh.vertices[points], float),
        corner_point.reshape(-1, 3),  # type: ignore[arg-type]
    )
    poly.point_data["Normals"] = np.asarray(mesh.vertex_normals, float)[points]
    poly.point_data.active_normals_name = "Normals"
    poly.active_texture_coordinates = np.r_[per_vertex, uv[seam][first]]
    return poly


def scan_texture(image: np.ndarray) -> Any:
    """A VTK texture of a scan's sRGB image (row 0 at the top), interpolated and
    mip-mapped.  Not marked sRGB: the dock's lighting is not gamma-corrected, and the
    scan's vertex colours (and the fitted skin's) are drawn as they are too."""
    import pyvista as pv

    tex = pv.Texture(np.ascontiguousarray(np.asarray(image, np.uint8)[::-1]))
    tex.InterpolateOn()
    tex.MipmapOn()
    return tex


# ------------------------------------------------------------------ painted eyes
#: icosphere level of the painted globes in report pictures and in the views
#: (:func:`workbench.core.appearance.fine_eyes`): level 6 has ~240 vertices inside the
#: 3.5 mm pupil, level 5 ~60 (a quarter of the triangles, for the interactive views)
PICTURE_EYE_LEVEL = 6
VIEW_EYE_LEVEL = 5
#: how the painted eyes are lit: a wet, glossy surface with a small highlight
EYE_SHADING: dict[str, Any] = {"specular": 0.35, "specular_power": 40.0, "ambient": 0.15}
#: the largest globe radius (mm) taken as an eye; a part that fits no sphere stays plain
_MAX_EYE_RADIUS_MM = 20.0
#: the widest the pattern is averaged over about a vertex of a coarse globe (mm)
_MAX_FILTER_MM = 0.7


@dataclass(frozen=True, eq=False)
class PaintedEyes:
    """Finer globes standing in for a head's eyes, with a colour per vertex.

    ``mesh`` holds one globe per centre (mm, the frame the eyes were given in),
    ``rgb`` its ``(n, 3)`` uint8 sRGB colours (pupil, iris, sclera by the angle
    from each globe's gaze: :func:`workbench.core.appearance.eyes_colours`),
    ``owner`` the globe of each vertex, ``centres`` ``(k, 3)``, ``gazes`` ``(k, 3)``
    unit and ``radius`` (mm) the globes'.
    """

    mesh: Mesh
    rgb: np.ndarray
    owner: np.ndarray
    centres: np.ndarray
    gazes: np.ndarray
    radius: float

    def posed(
        self, centres: np.ndarray, radius: float, gazes: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """``((n, 3) vertices, (n, 3) normals)`` of the same globes moved to ``centres``,
        scaled to ``radius`` (mm) and turned to look along ``gazes`` (each by the least
        turn): the colours stay valid, as the pattern is painted about the gaze."""
        c = np.asarray(centres, float).reshape(-1, 3)
        g = np.asarray(gazes, float).reshape(-1, 3)
        k = float(radius) / self.radius
        vertices = np.empty_like(self.mesh.vertices)
        normals = np.empty_like(self.mesh.vertices)
        for i in range(len(c)):
            sel = self.owner == i
            turn = _least_turn(self.gazes[i], g[i])
            vertices[sel] = c[i] + k * (self.mesh.vertices[sel] - self.centres[i]) @ turn.T
            normals[sel] = self.mesh.vertex_normals[sel] @ turn.T
        return vertices, normals


def _least_turn(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The 3x3 rotation by the least angle taking unit ``a`` to the direction of ``b``."""
    a = np.asarray(a, float) / np.linalg.norm(a)
    b = np.asarray(b, float) / np.linalg.norm(b)
    v, cos = np.cross(a, b), float(a @ b)
    if cos < -1.0 + 1e-9:  # opposite: half a turn about any axis across a
        axis = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        axis /= np.linalg.norm(axis)
        return 2.0 * np.outer(axis, axis) - np.eye(3)
    vx = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    return np.eye(3) + vx + vx @ vx / (1.0 + cos)


def globe_centres(eyes: Mesh) -> tuple[np.ndarray, float] | None:
    """``((k, 3) centres, radius)`` (mm) of the globes of an eyes mesh, or None.

    Each connected piece of ``eyes`` is one globe; its centre and radius are a
    least-squares sphere through the vertices, fitted again without the
    corneal bulge (vertices more than 0.1 mm outside the sphere before).  The
    radius is the median of the globes'.  None when a piece fits no sphere of
    radius 3-20 mm (not a globe).
    """
    if eyes.n_faces == 0:
        return None
    vertex_piece = np.full(eyes.n_vertices, -1)
    vertex_piece[eyes.faces.ravel()] = np.repeat(eyes.face_components, 3)
    centres, radii = [], []
    for piece in np.unique(vertex_piece[vertex_piece >= 0]):
        points = eyes.vertices[vertex_piece == piece]
        fit = _sphere(points)
        for _ in range(2):  # again without the cornea, standing out of the sphere
            if fit is not None:
                r = np.linalg.norm(points - fit[0], axis=1)
                fit = _sphere(points[r < fit[1] + 0.1])
        if fit is None or not 3.0 <= fit[1] <= _MAX_EYE_RADIUS_MM:
            return None
        centres.append(fit[0])
        radii.append(fit[1])
    return np.array(centres), float(np.median(radii))


def _sphere(points: np.ndarray) -> tuple[np.ndarray, float] | None:
    """Least-squares sphere ``(centre, radius)`` through ``points`` (None: too few, flat)."""
    if len(points) < 10:
        return None
    a = np.column_stack([2.0 * points, np.ones(len(points))])
    b = (points**2).sum(axis=1)
    sol, _, rank, _ = np.linalg.lstsq(a, b, rcond=None)
    if rank < 4:
        return None
    centre = sol[:3]
    r2 = float(sol[3] + centre @ centre)
    return (centre, float(np.sqrt(r2))) if r2 > 0 else None


_PAINTED: dict[bytes, PaintedEyes] = {}
_PAINTED_KEPT = 4
_PAINTED_LOCK = threading.Lock()  # the window paints on its thread, exports on a worker


def paint_eyes(
    eyes: Mesh,
    centres: np.ndarray | None = None,
    radius: float | None = None,
    *,
    level: int = PICTURE_EYE_LEVEL,
    iris: str = DEFAULT_IRIS,
) -> PaintedEyes | None:
    """The eyes of a head as :class:`PaintedEyes`, in the frame ``eyes`` is in (mm).

    ``centres`` ``(k, 3)`` and ``radius`` are the globes' when known (a
    :class:`~workbench.model.template.TemplateHead`'s ``eye_centres`` and
    ``eye_radius`` carried into the same frame), else read from the mesh
    (:func:`globe_centres`).  Each globe's gaze is read from its corneal
    bulge (+z when it has none), so it holds in a mirrored frame too; the
    globes are rebuilt at icosphere ``level`` (:func:`~workbench.core.appearance.fine_eyes`)
    so the pupil is a round disc.  None when the mesh holds no globe.  The
    last few results are kept (a view redraws the same eyes often).
    """
    if eyes.n_faces == 0:
        return None
    key = hashlib.sha1(np.ascontiguousarray(eyes.vertices, float).tobytes())
    for extra in (centres, radius):
        key.update(repr(None if extra is None else np.round(np.asarray(extra, float), 9)).encode())
    key.update(f"{level} {iris}".encode())
    digest = key.digest()
    with _PAINTED_LOCK:
        if digest in _PAINTED:
            return _PAINTED[digest]
    if centres is None or radius is None:
        found = globe_centres(eyes)
        if found is None:
            return None
        centres = found[0] if centres is None else centres
        radius = found[1] if radius is None else radius
    c = np.asarray(centres, float).reshape(-1, 3)
    gazes = eye_gazes(eyes.vertices, c)
    mesh = fine_eyes(c, gazes, radius=float(radius), subdivisions=level)
    painted = PaintedEyes(
        mesh=mesh,
        rgb=eyes_colours(mesh.vertices, c, gazes, iris=iris, radius=float(radius)),
        owner=eye_owner(mesh.vertices, c),
        centres=c,
        gazes=gazes,
        radius=float(radius),
    )
    with _PAINTED_LOCK:
        while len(_PAINTED) >= _PAINTED_KEPT:
            _PAINTED.pop(next(iter(_PAINTED)))
        _PAINTED[digest] = painted
    return painted


def filtered_eye_colours(
    eyes: Mesh,
    centres: np.ndarray,
    gazes: np.ndarray,
    radius: float,
    *,
    iris: str = DEFAULT_IRIS,
) -> np.ndarray:
    """``(n, 3)`` uint8 sRGB per vertex of coarse globes, the painted pattern averaged
    over a disc of half an edge about each vertex.

    For globes that must keep their own vertices (the animated eyes move them
    every frame): sampled only at the vertices, the 3.5 mm pupil of a globe with
    ~0.9 mm edges shows as a star; averaged (19 samples: the vertex and rings at
    a quarter and half an edge, at most :data:`_MAX_FILTER_MM` on the globe of
    ``radius``), it shows as a round, soft-edged disc.
    """
    v = np.asarray(eyes.vertices, float)
    c = np.asarray(centres, float).reshape(-1, 3)
    owner = eye_owner(v, c)
    edges = eyes.edges_unique
    step = 0.5 * float(np.linalg.norm(v[edges[:, 0]] - v[edges[:, 1]], axis=1).mean())
    d = v - c[owner]
    r = np.maximum(np.linalg.norm(d, axis=1, keepdims=True), 1e-9)
    # at most a fifth of the pupil's diameter on the pattern: its middle stays pure black
    step = min(step, _MAX_FILTER_MM * float(np.median(r)) / float(radius))
    u = d / r
    helper = np.where(np.abs(u[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t1 = np.cross(u, helper)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(u, t1)
    offsets = [(0.0, 0.0)] + [
        (ring * step * np.cos(a), ring * step * np.sin(a))
        for ring, count in ((0.5, 6), (1.0, 12))
        for a in np.linspace(0.0, 2.0 * np.pi, count, endpoint=False)
    ]
    total = np.zeros((len(v), 3))
    for a, b in offsets:
        samples = c[owner] + d + a * t1 + b * t2
        total += eyes_colours(samples, c, gazes, iris=iris, radius=radius)
    return np.clip(np.rint(total / len(offsets)), 0, 255).astype(np.uint8)


def eyes_polydata(painted: PaintedEyes, offset: np.ndarray | None = None) -> Any:
    """The painted globes as PolyData with their normals and sRGB point data ``rgb``,
    moved by ``offset`` (mm) when given."""
    poly = to_polydata(painted.mesh, normals=True)
    if offset is not None:
        poly.points += np.asarray(offset, float).reshape(1, 3)
    poly.point_data["rgb"] = painted.rgb
    return poly


def add_eyes(
    plotter: Any,
    painted: PaintedEyes,
    *,
    name: str = "layer_eyes",
    offset: np.ndarray | None = None,
    **kw: Any,
) -> Any:
    """The painted globes (moved by ``offset``, mm), coloured per vertex and glossy
    (``kw``: more ``add_mesh`` options); back faces culled, so that drawn translucent
    (with the face) each globe blends once, unsorted, like the skin."""
    actor = plotter.add_mesh(
        eyes_polydata(painted, offset),
        scalars="rgb",
        rgb=True,
        **SMOOTH,
        **EYE_SHADING,
        pickable=False,
        render=False,
        name=name,
        **kw,
    )
    return cull_back_faces(actor)
