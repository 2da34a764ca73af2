"""The 3D scene of the window: named layers drawn in one pyvista plotter.

Units mm, everything in the specimen's **input frame** (the skull file's
coordinates), so the evidence, landmarks, dowels and the fitted face overlay.

Each layer (``LAYERS``) holds one or more actors, is replaced as a whole when
its data change (addressed by name) and keeps a visibility and an opacity
that apply to *every* actor of the layer (surfaces, lines, points, labels)
and survive redraws.  :meth:`SceneView.set_visible` and
:meth:`SceneView.set_opacity` are the single source of that state: they
emit :attr:`SceneView.layer_changed` only when the state really changes, so
the View menu, the Layers dock and the reconstruct panel can all follow it
(updating their widgets with signals blocked) without feedback loops.

Renders are coalesced: :meth:`SceneView.request_render` schedules one render
on the next event-loop turn however many layers changed.
:meth:`SceneView.update_points` moves a layer's vertices in place (no actor
re-creation) for interactive previews.  The scene never writes the case; it
only draws what the window hands it.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from PySide6.QtCore import QObject, QTimer, Signal
from PySide6.QtWidgets import QWidget

from workbench.core.mesh import Mesh
from workbench.render.snapshots import to_polydata

#: layer name → menu title (also the row order of the Layers dock)
LAYERS = {
    "skull": "Skull",
    "landmarks": "Landmarks",
    "dowels": "Dowels",
    "guides": "Guides",
    "muscles": "Muscles",
    "face": "Face (skin)",
    "truth": "True skin (compare)",
}
#: layers hidden until the user switches them on (everything else starts visible)
HIDDEN_BY_DEFAULT = frozenset({"muscles"})
#: starting opacity per layer (1.0 where not listed)
DEFAULT_OPACITY = {"face": 0.6}
BONE = (0.93, 0.89, 0.80)
#: smooth shading from the point normals a mesh brings (``to_polydata(mesh,
#: normals=True)``): pyvista's ``smooth_shading=True`` would run VTK's normals
#: filter on the GUI thread each time (80 ms for a 100k-triangle skull)
SMOOTH: dict[str, Any] = {"smooth_shading": False, "interpolation": "phong"}
SKIN = (0.91, 0.72, 0.60)
STATUS_COLOURS = {"placed": (0.10, 0.70, 0.25), "suggested": (1.0, 0.55, 0.0)}
SELECTED = (1.0, 0.95, 0.1)
DOWEL = (0.15, 0.35, 0.85)
GUIDE = (0.85, 0.10, 0.55)
MUSCLE = (0.72, 0.12, 0.12)
MUSCLE_FIBRE = (0.45, 0.04, 0.05)


#: colour bars: vertical, inside the view's right edge (titles included), and
#: added without pyvista's immediate render (the next paint draws them; that
#: render cost ~85 ms of the GUI thread on top of the paint)
SCALAR_BAR: dict[str, Any] = {
    "vertical": True,
    "render": False,
    "position_x": 0.82,
    "position_y": 0.25,
    "width": 0.07,
    "height": 0.5,
    "title_font_size": 14,
    "label_font_size": 12,
}

#: OpenGL renderer strings of software rasterisers (no graphics card in use)
SOFTWARE_GL = ("llvmpipe", "softpipe", "swrast", "swiftshader", "software rasterizer")


def is_closed(plotter: Any) -> bool:
    """True once a pyvistaqt view was closed (``plotter.close()``): draw nothing into it.

    The one place that reads pyvistaqt's private ``_closed`` flag:
    ``QtInteractor`` has no public "closed" state, and after ``close()`` its
    render window is finalized, so rendering or adding actors would touch a
    released GL context.  A plotter that never had the flag (not a
    pyvistaqt view) counts as open.
    """
    return bool(getattr(plotter, "_closed", False))


def gl_renderer(render_window: Any) -> str:
    """The OpenGL renderer string of an initialised VTK render window ('' if unknown)."""
    try:
        info = render_window.ReportCapabilities() or ""
    except Exception:  # noqa: BLE001 - a window without a context
        return ""
    line = next((ln for ln in info.splitlines() if "renderer string" in ln), "")
    return line.split(":", 1)[-1].strip()


def is_software_gl(renderer: str) -> bool:
    return any(name in renderer.lower() for name in SOFTWARE_GL)


class SceneView(QObject):
    """Named layers over a plotter (``pyvistaqt.QtInteractor`` or ``pv.Plotter``).

    Signals
    -------
    layer_changed(str)
        A layer's visibility or opacity changed (read the new state from
        :attr:`visible` / :attr:`opacity` or :meth:`layer_state`).
    """

    layer_changed = Signal(str)

    def __init__(self, plotter: Any, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self.plotter = plotter
        self.visible: dict[str, bool] = {k: k not in HIDDEN_BY_DEFAULT for k in LAYERS}
        self.opacity: dict[str, float] = {k: DEFAULT_OPACITY.get(k, 1.0) for k in LAYERS}
        self._actors: dict[str, list[Any]] = {}
        self._render_pending = False
        self.renders = 0
        self.paints = 0  # renders VTK finished (the widget's paints included)
        self._awaiting_paint = False
        self._after_paint: list[Any] = []
        self._paint_fallback = QTimer(self)
        self._paint_fallback.setSingleShot(True)
        self._paint_fallback.timeout.connect(self._run_after_paint)
        # a zero-interval timer, not QTimer.singleShot(0, ...): Qt 6 turns the
        # latter into a posted call that runs before timers and input queued
        # meanwhile, so work that asked for a render and the render itself
        # would block the event loop as one stretch
        self._render_timer = QTimer(self)
        self._render_timer.setSingleShot(True)
        self._render_timer.setInterval(0)
        self._render_timer.timeout.connect(self.render_now)
        #: the OpenGL renderer ('' until the first render); see :meth:`tune`
        self.gl_renderer = ""
        self._tuned: list[Any] = [plotter]
        # translucent layers (skin, truth) are blended without sorting, their
        # back faces culled, instead of VTK's order-independent transparency:
        # one translucent surface over the bone looks the same and a frame
        # costs ~15 ms less on a software renderer
        renderer = getattr(plotter, "renderer", None)
        if renderer is not None:
            renderer.SetUseOIT(False)
        plotter.set_background("#2b2f36", top="#59606b")
        window = getattr(plotter, "render_window", None)
        self._end_observer = (
            None if window is None else window.AddObserver("EndEvent", self._rendered)
        )

    # ------------------------------------------------------------ rendering
    def request_render(self) -> None:
        """Render once on the next event-loop turn."""
        if not self._render_pending:
            self._render_pending = True
            self._render_timer.start()

    def render_now(self) -> None:
        self._render_pending = False
        if self.closed or self.plotter.render_window is None:
            return
        if isinstance(self.plotter, QWidget):
            # the widget renders in its paint; rendering here as well would
            # draw every frame twice (pyvistaqt's paintGL always renders)
            self._awaiting_paint = self.plotter.isVisible()
            self.plotter.update()
        else:
            self.plotter.render()
        self.renders += 1

    @property
    def closed(self) -> bool:
        """The 3D view was closed (see :func:`is_closed`)."""
        return is_closed(self.plotter)

    @property
    def render_queued(self) -> bool:
        """A render was asked for and the view has not painted it yet."""
        return self._render_pending or self._awaiting_paint

    def after_paint(self, callback: Any, render: bool = True) -> None:
        """Call ``callback()`` on a later event-loop turn than the view's next render.

        Sequences heavy steps so that each blocks the event loop on its own
        (with software OpenGL one render of a new scene takes ~200 ms; work
        queued behind it would lengthen that block).  If no render happens
        within 0.5 s (a hidden view), the callback runs anyway.
        """
        self._after_paint.append(callback)
        if render:
            self.request_render()
        self._paint_fallback.start(500)

    @property
    def paint_work_pending(self) -> bool:
        """Callbacks wait for the next paint (see :meth:`after_paint`)."""
        return bool(self._after_paint)

    def also_tune(self, plotter: Any) -> None:
        """Apply the renderer-dependent settings of :meth:`tune` to another view too."""
        self._tuned.append(plotter)
        plotter.renderer.SetUseOIT(False)
        if self.gl_renderer:
            self.tune()

    def tune(self) -> None:
        """Drop FXAA edge smoothing on a software renderer (llvmpipe).

        There it costs ~17 ms of a ~100 ms frame of a 100k-triangle skull;
        the window must keep every block of its event loop under 200 ms.
        With a graphics card it costs well under a millisecond and stays.
        """
        if not is_software_gl(self.gl_renderer):
            return
        for plotter in self._tuned:
            renderer = getattr(plotter, "renderer", None)
            if renderer is not None and not is_closed(plotter):
                renderer.SetUseFXAA(False)

    def _rendered(self, *_args: Any) -> None:
        self.paints += 1
        if not self.gl_renderer:
            window = getattr(self.plotter, "render_window", None)
            self.gl_renderer = (gl_renderer(window) if window is not None else "") or "unknown"
            self.tune()
        self._awaiting_paint = False
        if self._after_paint:
            self._paint_fallback.start(1)  # not now: we are inside the paint

    def _run_after_paint(self) -> None:
        callbacks, self._after_paint = self._after_paint, []
        for callback in callbacks:
            callback()

    def detach(self) -> None:
        """Remove the VTK observer and drop queued callbacks (the window closes)."""
        self._after_paint = []
        self._paint_fallback.stop()
        window = getattr(self.plotter, "render_window", None)
        if self._end_observer is not None and window is not None:
            window.RemoveObserver(self._end_observer)
        self._end_observer = None

    # ------------------------------------------------------------ layers
    def actors(self, layer: str) -> list[Any]:
        return list(self._actors.get(layer, []))

    def has(self, layer: str) -> bool:
        return bool(self._actors.get(layer))

    def clear(self, layer: str) -> None:
        for actor in self._actors.pop(layer, []):
            self.plotter.remove_actor(actor, render=False)
        self.request_render()

    def _add(self, layer: str, actor: Any) -> None:
        """Register ``actor`` under ``layer`` with the layer's visibility and opacity."""
        self._actors.setdefault(layer, []).append(actor)
        actor.SetVisibility(self.visible.get(layer, True))
        actor.GetProperty().SetOpacity(self.opacity.get(layer, 1.0))

    def set_visible(self, layer: str, on: bool) -> None:
        """Show or hide every actor of ``layer`` (kept for later redraws)."""
        on = bool(on)
        changed = self.visible.get(layer) != on
        self.visible[layer] = on
        for actor in self._actors.get(layer, []):
            actor.SetVisibility(on)
        self.request_render()
        if changed:
            self.layer_changed.emit(layer)

    def set_opacity(self, layer: str, value: float) -> None:
        """Opacity in [0, 1] of every actor of ``layer`` (kept for later redraws)."""
        value = min(max(float(value), 0.0), 1.0)
        changed = self.opacity.get(layer) != value
        self.opacity[layer] = value
        for actor in self._actors.get(layer, []):
            actor.GetProperty().SetOpacity(value)
        self.request_render()
        if changed:
            self.layer_changed.emit(layer)

    def layer_state(self) -> dict[str, tuple[bool, float]]:
        """``{layer: (visible, opacity)}`` for every layer of :data:`LAYERS`."""
        return {k: (self.visible[k], self.opacity[k]) for k in LAYERS}

    def update_points(self, layer: str, points: np.ndarray) -> None:
        """Move the vertices of ``layer``'s first actor in place (mm, input frame).

        ``points`` is ``(n, 3)`` with the same count and order as the mesh
        that was drawn (e.g. the face's vertices).  The actor, its colouring
        and its state are kept; only the coordinates (and, for smooth-shaded
        surfaces, the vertex normals) change, then one render is requested.
        Meant for live previews (a dragged landmark), so it does no other work.
        """
        actors = self._actors.get(layer)
        if not actors:
            raise KeyError(f"layer {layer!r} has nothing drawn")
        self._move_points(actors[0], points)
        self.request_render()

    @staticmethod
    def _move_points(actor: Any, points: np.ndarray) -> None:
        data = _drawn_data(actor)
        new = np.asarray(points, dtype=float).reshape(-1, 3)
        vtk_points = data.GetPoints()
        if vtk_points is None or new.shape[0] != vtk_points.GetNumberOfPoints():
            raise ValueError(f"expected {data.GetNumberOfPoints()} points, got {new.shape[0]}")
        from vtkmodules.util.numpy_support import vtk_to_numpy

        vtk_to_numpy(vtk_points.GetData())[:] = new
        vtk_points.Modified()
        normals = data.GetPointData().GetNormals()
        if normals is not None and data.GetPolys().IsHomogeneous() == 3:  # triangles only
            vtk_to_numpy(normals)[:] = _vertex_normals(new, data)
            normals.Modified()
        data.Modified()

    def reset_camera(
        self, anterior: Sequence[float] | None = None, superior: Sequence[float] | None = None
    ) -> None:
        """Look at the face (``anterior`` toward the camera) when the orientation is known."""
        if anterior is not None and superior is not None:
            a = np.asarray(anterior, float)
            focus = np.asarray(self.plotter.center, float)
            self.plotter.camera_position = [
                tuple(focus + 600.0 * a),
                tuple(focus),
                tuple(np.asarray(superior, float)),
            ]
        # Plotter.reset_camera always renders (pyvista 0.49 ignores render=False);
        # the renderer's own reset does not, so the next paint draws it
        self.plotter.renderer.reset_camera(render=False)
        self.request_render()

    # ------------------------------------------------------------ content
    def show_skull(self, mesh: Mesh | None) -> Any:
        self.clear("skull")
        if mesh is None:
            return None
        actor = self.plotter.add_mesh(
            to_polydata(mesh, normals=True),
            color=BONE,
            **SMOOTH,
            pickable=True,
            name="layer_skull",
            render=False,
        )
        self._add("skull", actor)
        self.request_render()
        return actor

    def show_landmarks(
        self,
        points: np.ndarray,
        statuses: Sequence[str],
        selected: np.ndarray | None = None,
        label: str = "",
    ) -> None:
        """Placed (green) and suggested (orange) points; the selected one in yellow."""
        self.clear("landmarks")
        radius = self._marker_size()
        for status, colour in STATUS_COLOURS.items():
            mask = np.array([s == status for s in statuses], dtype=bool)
            if mask.any():
                actor = self.plotter.add_points(
                    np.asarray(points)[mask],
                    color=colour,
                    point_size=radius,
                    render_points_as_spheres=True,
                    pickable=False,
                    render=False,
                    name=f"layer_landmarks_{status}",
                )
                self._add("landmarks", actor)
        if selected is not None and np.isfinite(selected).all():
            actor = self.plotter.add_points(
                np.asarray(selected, float)[None],
                color=SELECTED,
                point_size=radius * 1.8,
                pickable=False,
                render_points_as_spheres=True,
                render=False,
                name="layer_landmarks_selected",
            )
            self._add("landmarks", actor)
            if label:
                labels = self.plotter.add_point_labels(
                    np.asarray(selected, float)[None],
                    [label],
                    font_size=14,
                    point_size=1,
                    shape_opacity=0.6,
                    always_visible=True,
                    pickable=False,
                    render=False,
                    name="layer_landmarks_label",
                )
                self._add("landmarks", labels)
        self.request_render()

    def show_dowels(self, origins: np.ndarray, tips: np.ndarray) -> None:
        """Each dowel as a line from its skull origin to its tip, with a tip sphere."""
        import pyvista as pv

        self.clear("dowels")
        if len(origins):
            n = len(origins)
            pts = np.vstack([origins, tips])
            lines = np.column_stack([np.full(n, 2), np.arange(n), np.arange(n) + n]).ravel()
            poly = pv.PolyData(pts, lines=lines)
            self._add(
                "dowels",
                self.plotter.add_mesh(
                    poly,
                    color=DOWEL,
                    line_width=4,
                    pickable=False,
                    render=False,
                    name="layer_dowels_pegs",
                ),
            )
            self._add(
                "dowels",
                self.plotter.add_points(
                    np.asarray(tips),
                    color=DOWEL,
                    point_size=self._marker_size() * 0.8,
                    render_points_as_spheres=True,
                    pickable=False,
                    render=False,
                    name="layer_dowels_tips",
                ),
            )
        self.request_render()

    def show_face(
        self, mesh: Mesh | None, scalars: np.ndarray | None = None, title: str = ""
    ) -> None:
        """The fitted skin; with ``scalars`` (per vertex, mm) as a colour map."""
        self.clear("face")
        if mesh is None:
            return
        poly = to_polydata(mesh, normals=True)
        kw: dict[str, Any] = {"color": SKIN}
        if scalars is not None:
            poly.point_data[title or "mm"] = np.asarray(scalars, float)
            kw = {
                "scalars": title or "mm",
                "cmap": "viridis",
                "scalar_bar_args": dict(SCALAR_BAR, title=title or "mm"),
            }
        actor = self.plotter.add_mesh(
            poly, **SMOOTH, pickable=False, render=False, name="layer_face", **kw
        )
        actor.GetProperty().BackfaceCullingOn()  # translucent: see SetUseOIT above
        self._add("face", actor)
        self.request_render()

    def show_truth(
        self, mesh: Mesh | None, signed_mm: np.ndarray | None = None, limit_mm: float = 5.0
    ) -> None:
        """The true skin, coloured by signed distance (NaN grey) when given."""
        self.clear("truth")
        if mesh is None:
            return
        poly = to_polydata(mesh, normals=True)
        kw: dict[str, Any] = {"color": (0.7, 0.7, 0.75)}
        if signed_mm is not None:
            poly.point_data["signed mm"] = np.asarray(signed_mm, float)
            kw = {
                "scalars": "signed mm",
                "cmap": "RdBu_r",
                "clim": (-limit_mm, limit_mm),
                "nan_color": (0.6, 0.6, 0.6),
                "scalar_bar_args": dict(SCALAR_BAR, title="signed mm"),
            }
        actor = self.plotter.add_mesh(
            poly, **SMOOTH, pickable=False, render=False, name="layer_truth", **kw
        )
        actor.GetProperty().BackfaceCullingOn()  # translucent: see SetUseOIT above
        self._add("truth", actor)
        self.request_render()

    def show_guides(
        self, segments: list[tuple[np.ndarray, np.ndarray]], points: np.ndarray
    ) -> None:
        """Guide lines (pairs of end points) and guide points, input frame."""
        import pyvista as pv

        self.clear("guides")
        if segments:
            pts = np.array([p for seg in segments for p in seg], float)
            n = len(segments)
            lines = np.column_stack([np.full(n, 2), 2 * np.arange(n), 2 * np.arange(n) + 1]).ravel()
            self._add(
                "guides",
                self.plotter.add_mesh(
                    pv.PolyData(pts, lines=lines),
                    color=GUIDE,
                    line_width=3,
                    pickable=False,
                    render=False,
                    name="layer_guides_lines",
                ),
            )
        if len(points):
            self._add(
                "guides",
                self.plotter.add_points(
                    np.asarray(points, float),
                    color=GUIDE,
                    point_size=self._marker_size(),
                    render_points_as_spheres=True,
                    pickable=False,
                    render=False,
                    name="layer_guides_points",
                ),
            )
        self.request_render()

    def show_muscles(self, muscles: Sequence[Sequence[np.ndarray]]) -> tuple[int, int]:
        """Muscle grids as red sheets with darker fibre lines (mm, input frame).

        ``muscles`` holds, per muscle, its grid rows as ``(n_i, 3)`` arrays in
        order (fixed end → free end for a linear muscle, outer → inner ring
        for a sphincter; see :class:`workbench.model.muscles.MuscleGrid`).
        Rows are resampled to a common point count; consecutive rows span the
        sheet, and the rows plus the columns across them are drawn as lines.
        Returns ``(number of sheet triangles, number of polylines)``.
        """
        import pyvista as pv

        self.clear("muscles")
        points, faces, lines = _muscle_geometry(muscles)
        if not len(points):
            return 0, 0
        if len(faces):
            # normals from numpy (Mesh.vertex_normals), not VTK's normals
            # filter: that took ~50 ms of the GUI thread per fit
            sheet = to_polydata(Mesh(points, faces), normals=True)
            self._add(
                "muscles",
                self.plotter.add_mesh(
                    sheet,
                    color=MUSCLE,
                    **SMOOTH,
                    pickable=False,
                    render=False,
                    name="layer_muscles_sheets",
                ),
            )
        if lines:
            cells = np.concatenate([np.r_[len(line), line] for line in lines])
            fibres = pv.PolyData(points, lines=cells)
            self._add(
                "muscles",
                self.plotter.add_mesh(
                    fibres,
                    color=MUSCLE_FIBRE,
                    line_width=2.5,
                    pickable=False,
                    render=False,
                    name="layer_muscles_fibres",
                ),
            )
        self.request_render()
        return len(faces), len(lines)

    def layer_points(self, layer: str) -> np.ndarray:
        """The drawn points of ``layer``'s first actor (mm, input frame; a copy)."""
        actors = self._actors.get(layer)
        if not actors:
            raise KeyError(f"layer {layer!r} has nothing drawn")
        from vtkmodules.util.numpy_support import vtk_to_numpy

        return np.array(vtk_to_numpy(_drawn_data(actors[0]).GetPoints().GetData()), dtype=float)

    def move_layer_points(self, layer: str, points: np.ndarray) -> None:
        """Move the points of every actor of ``layer`` in place (they share one layout,
        as the muscle sheets and fibres do); one render is requested."""
        actors = self._actors.get(layer)
        if not actors:
            raise KeyError(f"layer {layer!r} has nothing drawn")
        for actor in actors:
            self._move_points(actor, points)
        self.request_render()

    def _marker_size(self) -> float:
        return 12.0


def _drawn_data(actor: Any) -> Any:
    """The dataset ``actor`` was drawn from (the one to move points in).

    A surface coloured by scalars reaches its mapper through a pass-through
    algorithm of pyvista's (it sets the active scalars), whose output stays
    empty until the first render and is a shallow copy after it: the data is
    the producer's at the top of the mapper's input pipeline.
    """
    mapper = actor.GetMapper()
    algorithm = mapper.GetInputAlgorithm()
    while (
        algorithm is not None
        and algorithm.GetNumberOfInputPorts() > 0
        and algorithm.GetNumberOfInputConnections(0) > 0
    ):
        algorithm = algorithm.GetInputAlgorithm(0, 0)
    data = algorithm.GetOutputDataObject(0) if algorithm is not None else None
    return data if data is not None else mapper.GetInput()


def _muscle_geometry(
    muscles: Sequence[Sequence[np.ndarray]],
) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """Points, sheet triangles and fibre polylines (point ids) of muscle grids."""
    pts: list[np.ndarray] = []
    tris: list[np.ndarray] = []
    lines: list[np.ndarray] = []
    offset = 0
    for rows in muscles:
        grid = _resampled_grid([np.asarray(r, float).reshape(-1, 3) for r in rows])
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


def _resampled_grid(rows: list[np.ndarray]) -> np.ndarray | None:
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


def _vertex_normals(points: np.ndarray, data: Any) -> np.ndarray:
    """Unit vertex normals of the triangles of ``data`` at ``points``.

    Area-weighted, as :attr:`Mesh.vertex_normals` (the normals the surface
    was first drawn with), so the shading does not jump on the first update.
    """
    from vtkmodules.util.numpy_support import vtk_to_numpy

    cells = vtk_to_numpy(data.GetPolys().GetConnectivityArray()).reshape(-1, 3)
    t = points[cells]
    cross = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])  # length = 2 × area
    n = len(points)
    flat = cells.ravel()
    # float64 (bincount with weights), whatever numpy's stubs say
    out: np.ndarray = np.column_stack(
        [np.bincount(flat, np.repeat(cross[:, k], 3), minlength=n) for k in range(3)]
    )
    out /= np.maximum(np.linalg.norm(out, axis=1, keepdims=True), 1e-12)
    return out
