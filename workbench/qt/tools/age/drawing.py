"""How the age tool draws: the source head and the aged one, side by side or overlaid.

:class:`AgeDrawing` is the drawing half of :class:`~workbench.qt.tools.age.tool.AgeTool`
(which it is mixed into): the tool decides which computed age is shown, this part puts
the heads and the caption in the 3D view.  The aged skin has the source's vertices and
triangles, so it is built once and its points are moved in place for each age.

Units mm, each head in its own Frankfort frame; the actors are the tool's own, not
:data:`workbench.qt.scene.LAYERS`.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from workbench.core.mesh import Mesh

if TYPE_CHECKING:
    from workbench.qt.panels.age_panel import AgePanel
    from workbench.qt.scene import SceneView
    from workbench.qt.tools.age.work import AgeSettings, AgeStep, SourceHead

#: space between the two heads side by side (mm)
GAP_MM = 40.0
#: opacity of the source skin in the overlay
OVERLAY_OPACITY = 0.25
DISTANCE_TITLE = "displacement mm"
BEFORE_COLOUR = (0.80, 0.80, 0.84)


class AgeDrawing:
    """The age tool's actors (mixed into the tool, whose ``__init__`` sets these)."""

    panel: AgePanel
    scene: SceneView
    plotter: Any
    source: SourceHead | None
    cache: dict[int, AgeStep]
    shown_age: int | None
    active: bool
    _actors: dict[str, Any]
    _caption: Any

    def settings(self) -> AgeSettings:
        raise NotImplementedError  # the tool's: the panel's choices

    @property
    def step(self) -> AgeStep | None:
        """The computed age drawn now."""
        return None if self.shown_age is None else self.cache.get(self.shown_age)

    def _mode_changed(self, _mode: str) -> None:
        self.draw()
        self.reset_camera()

    def actors(self) -> dict[str, Any]:
        """``{"before" | "after": actor}`` drawn by this tool (tests)."""
        return dict(self._actors)

    def offset(self) -> np.ndarray:
        """Where the source head is drawn relative to its frame (mm): side by side, to −x."""
        if self.source is None or self.panel.mode() != "side":
            return np.zeros(3)
        span = float(np.ptp(self.source.head.skin.vertices[:, 0]))
        return np.array([-(span + GAP_MM), 0.0, 0.0])

    def clear(self) -> None:
        for actor in self._actors.values():
            self.plotter.remove_actor(actor, render=False)
        self._actors.clear()
        if self._caption is not None:
            self.plotter.remove_actor(self._caption, render=False)
            self._caption = None
        self.scene.request_render()

    def draw(self) -> None:
        """(Re)draw the source head and the shown aged head for the panel's mode."""
        from workbench.qt.scene import SKIN, SMOOTH
        from workbench.render.snapshots import to_polydata

        self.clear()
        source = self.source
        if source is None or self.scene.closed:
            return
        overlay = self.panel.mode() == "overlay"
        skin = source.head.skin
        before = to_polydata(skin.transformed(_shift(self.offset())), normals=True)
        actor = self.plotter.add_mesh(
            before,
            color=BEFORE_COLOUR if overlay else SKIN,
            **SMOOTH,
            opacity=OVERLAY_OPACITY if overlay else 1.0,
            pickable=False,
            render=False,
            name="age_before",
        )
        if overlay:  # a translucent shell over the aged head: no depth sorting needed
            actor.GetProperty().BackfaceCullingOn()
        self._actors["before"] = actor
        self._caption = self.plotter.add_text(
            "", position="upper_left", font_size=11, color="black", name="age_caption"
        )
        self._draw_after(rebuild=True)

    def _draw_after(self, rebuild: bool = False) -> None:
        """The aged skin of :attr:`step`: built once, then its points moved in place."""
        from workbench.qt.scene import SCALAR_BAR, SKIN, SMOOTH
        from workbench.render.snapshots import to_polydata

        source, step = self.source, self.step
        if source is None or "before" not in self._actors or self.scene.closed:
            return
        overlay = self.panel.mode() == "overlay"
        actor = self._actors.get("after")
        if rebuild or actor is None:
            if actor is not None:
                self.plotter.remove_actor(actor, render=False)
            # a copy: VTK may share the array, and its points are moved in place below
            skin = source.head.skin
            poly = to_polydata(Mesh(skin.vertices.copy(), skin.faces.copy()), normals=True)
            kw: dict[str, Any] = {"color": SKIN}
            if overlay:
                poly.point_data[DISTANCE_TITLE] = np.zeros(poly.n_points)
                kw = {
                    "scalars": DISTANCE_TITLE,
                    "cmap": "viridis",
                    "clim": (0.0, 10.0),
                    "scalar_bar_args": dict(
                        SCALAR_BAR, title=DISTANCE_TITLE, n_labels=6, fmt="%.0f"
                    ),
                }
            actor = self.plotter.add_mesh(
                poly, **SMOOTH, pickable=False, render=False, name="age_after", **kw
            )
            self._actors["after"] = actor
        if step is not None:
            data = drawn_data(actor)
            _set_array(data.GetPoints().GetData(), step.result.head.skin.vertices)
            data.GetPoints().Modified()
            normals = data.GetPointData().GetNormals()
            if normals is not None:
                _set_array(normals, step.normals)
            if overlay:
                scalars = data.GetPointData().GetArray(DISTANCE_TITLE)
                if scalars is not None:
                    _set_array(scalars, step.distance)
                hi = max(1.0, 5.0 * math.ceil(float(np.percentile(step.distance, 99)) / 5.0))
                actor.GetMapper().SetScalarRange(0.0, hi)
                lut = actor.GetMapper().GetLookupTable()
                if lut is not None:
                    lut.SetRange(0.0, hi)
            data.Modified()
        actor.SetVisibility(self.active and step is not None)
        self._update_caption()
        self.scene.request_render()

    def _update_caption(self) -> None:
        if self._caption is None:
            return
        s = self.settings()
        shown = "–" if self.shown_age is None else f"{self.shown_age} y"
        if self.panel.mode() == "side":
            text = f"left: {s.from_age:g} y (source)   right: {shown} (aged)"
        else:
            text = f"{shown} (coloured: displacement from {s.from_age:g} y, mm); source translucent"
        self._caption.SetText(2, text)  # a corner annotation: 2 = upper left
        self._caption.SetVisibility(self.active)

    def drawn_points(self, which: str) -> np.ndarray:
        """The drawn skin points of ``"before"`` or ``"after"`` (mm; tests)."""
        from vtkmodules.util.numpy_support import vtk_to_numpy

        actor = self._actors[which]
        return vtk_to_numpy(drawn_data(actor).GetPoints().GetData()).copy()

    def reset_camera(self) -> None:
        """Look at both heads from the front (+z toward the face, +y up)."""
        source = self.source
        if source is None or self.scene.closed:
            return
        v = source.head.skin.vertices
        lo = np.minimum(v.min(axis=0), v.min(axis=0) + self.offset())
        hi = np.maximum(v.max(axis=0), v.max(axis=0) + self.offset())
        centre = (lo + hi) / 2
        renderer = self.plotter.renderer
        camera = renderer.GetActiveCamera()
        camera.SetFocalPoint(*centre)
        camera.SetPosition(*(centre + np.array([0.0, 0.0, 800.0])))
        camera.SetViewUp(0.0, 1.0, 0.0)
        renderer.ResetCamera(*np.column_stack([lo, hi]).ravel())
        camera.Zoom(1.3 if self.panel.mode() == "side" else 1.05)
        renderer.ResetCameraClippingRange()
        self.scene.request_render()


def drawn_data(actor: Any) -> Any:
    """The polydata an actor of ``plotter.add_mesh`` draws (mm): pyvista's mapper dataset.

    Not ``GetMapper().GetInput()``: with scalars the mapper is fed through a
    pipeline connection, and its input is an empty output until the first render.
    """
    return actor.mapper.dataset


def _shift(offset: np.ndarray) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = offset
    return m


def _set_array(vtk_array: Any, values: np.ndarray) -> None:
    from vtkmodules.util.numpy_support import vtk_to_numpy

    target = vtk_to_numpy(vtk_array)
    target[:] = np.asarray(values, float).reshape(target.shape)
    vtk_array.Modified()
