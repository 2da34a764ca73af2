"""The "Animate" tool of the window: a reference head's face moved live in the 3D view.

The physics is the service's (:class:`workbench.services.animation.Animator`,
``workbench animate``); this tool only sets its parameters from the
:class:`~workbench.qt.panels.animate_panel.AnimatePanel` and shows the
result.  The head is loaded in the window's worker (the reference head from
the template cache, then the animator's set-up, ~1.5 s); afterwards a
:class:`QTimer` every :data:`FRAME_MS` ms advances the skin
:data:`STEPS_PER_FRAME` simulation steps on the GUI thread (~600 steps/s for
the reference skin: ~17 ms a frame) and moves the drawn skin's points in
place (no actor is re-added).  The timer stops once the skin has settled
(largest vertex move in a frame below :data:`SETTLED_MM` for
:data:`SETTLED_FRAMES` frames) and starts again with the next change.

Frames and units: mm, the head's own frame (the reference head is stored in
the Frankfort head frame: x to the subject's left, y up, z toward the face),
not the case's skull.  Its layers (skin; skull, teeth and eyes) belong to
this tool, not to :data:`workbench.qt.scene.LAYERS`.

Undo: slider and preset changes are view state, not case edits.  The case
is not changed, nothing goes on the document's undo stack, and Relax is the
way back to the face at rest.
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from PySide6.QtCore import QObject, QTimer, Signal

from workbench.core.mesh import Mesh
from workbench.core.normals import vertex_normals

if TYPE_CHECKING:
    from PySide6.QtWidgets import QWidget

    from workbench.qt.panels.animate_panel import AnimatePanel
    from workbench.qt.scene import SceneView
    from workbench.qt.workers import TaskRunner
    from workbench.services.animation import Animator

#: the worker channel of head loading (a newer load supersedes the older)
CHANNEL = "animate"
#: timer interval and simulation steps per frame (the reference skin: ~17 ms of stepping)
FRAME_MS = 30
STEPS_PER_FRAME = 10
#: the skin has settled when no vertex moves more than this (mm) in a frame ...
SETTLED_MM = 2e-3
#: ... for this many frames in a row
SETTLED_FRAMES = 3
#: parts drawn under the skin (the "Skull and teeth" check box); the eyes are always shown
INNER_PARTS = ("cranium", "mandible", "upper_teeth", "lower_teeth")
ALWAYS_SHOWN = ("eyes",)
INNER_COLOURS = {"eyes": (0.95, 0.95, 0.95), "upper_teeth": (1.0, 1.0, 0.94)}


class AnimateHost(Protocol):
    """What the tool uses of the window: status line, readable errors."""

    def status(self, text: str) -> None: ...

    def show_error(self, what: str, exc: BaseException) -> None: ...

    def window(self) -> QWidget: ...


def load_animator(sex: str) -> Animator:
    """The reference head of ``sex`` ready to animate (worker side: no Qt, no VTK)."""
    from workbench.services.animation import Animator
    from workbench.services.template_cache import reference_head

    return Animator(reference_head(sex))


class AnimateTool(QObject):
    """See the module docstring.

    Signals
    -------
    loaded()    a head was loaded (``animator`` is set)
    settled()   the timer stopped: the skin is at rest for the current parameters
    """

    loaded = Signal()
    settled = Signal()

    def __init__(
        self,
        panel: AnimatePanel,
        scene: SceneView,
        plotter: Any,
        runner: TaskRunner,
        host: AnimateHost,
        parent: QObject | None = None,
    ) -> None:
        super().__init__(parent)
        self.panel, self.scene, self.plotter = panel, scene, plotter
        self.runner, self.host = runner, host
        self.animator: Animator | None = None
        self.sex = ""
        self._loading = ""
        self._actors: dict[str, Any] = {}
        self._points: np.ndarray | None = None  # the skin as drawn (mm)
        self._jaw_drawn = 0.0
        self._quiet_frames = 0
        #: milliseconds per timer frame (stepping + moving the points), newest last
        self.frame_ms: list[float] = []
        #: largest vertex move (mm) of the last frame
        self.last_move_mm = 0.0
        self.timer = QTimer(self)
        self.timer.setInterval(FRAME_MS)
        self.timer.timeout.connect(self.tick)
        panel.head_changed.connect(self.load)
        panel.expression_changed.connect(self.set_expression)
        panel.muscle_changed.connect(self.set_muscle)
        panel.jaw_changed.connect(self.set_jaw)
        panel.relax_requested.connect(self.relax)
        panel.bones_toggled.connect(self._show_inner)

    # ------------------------------------------------------------ loading
    def ensure_loaded(self) -> None:
        """Load the panel's head unless it is loaded or on its way (the dock was opened)."""
        if self.animator is None and not self._loading:
            self.load(self.panel.sex())

    def load(self, sex: str) -> None:
        if sex == self._loading or (sex == self.sex and self.animator is not None):
            return
        self._loading = sex
        self.panel.show_status(f"Loading the reference {sex} head …")

        def done(anim: Animator) -> None:
            self._loaded(sex, anim)

        self.runner.submit(
            CHANNEL,
            f"Loading the {sex} head for animation …",
            lambda: load_animator(sex),
            done,
            self._failed,
        )

    def _failed(self, exc: BaseException) -> None:
        self._loading = ""
        self.panel.show_status("The head could not be loaded.")
        self.host.show_error("Could not load the head to animate", exc)

    def _loaded(self, sex: str, anim: Animator) -> None:
        if sex != self._loading or self.scene.closed:
            return  # superseded, or the window closed
        self._loading = ""
        self.timer.stop()
        self.animator, self.sex = anim, sex
        self.panel.set_muscles(anim.muscle_codes)
        self.draw()
        self.reset_camera()
        self.panel.show_status(
            f"Reference {sex} head: {len(anim.head.skin.vertices):,} skin vertices, "
            f"{len(anim.muscle_codes)} muscles."
        )
        self.host.status(f"Animate: the reference {sex} head (view only: the case is not changed).")
        self.loaded.emit()
        name = self.panel.expression.currentText()
        if name and name != "neutral":
            self.set_expression(name, self.panel.weight())

    # ------------------------------------------------------------ parameters
    def set_expression(self, name: str, weight: float = 1.0) -> None:
        """Replace every muscle and the jaw with the preset ``name`` at ``weight`` (0..1)."""
        anim = self.animator
        if anim is None or not name:
            return
        anim.set_expression(name, weight)
        self._show_state()
        self._start()

    def set_muscle(self, code: str, contraction: float) -> None:
        anim = self.animator
        if anim is None:
            return
        anim.set_muscles({code: float(contraction)})
        self._start()

    def set_jaw(self, degrees: float) -> None:
        anim = self.animator
        if anim is None:
            return
        anim.set_jaw(float(degrees), anim.protrusion_mm)
        self._start()

    def relax(self) -> None:
        """All muscles relaxed, jaw closed; the timer carries the face back to rest."""
        anim = self.animator
        if anim is None:
            return
        anim.set_expression("neutral")
        self._show_state()
        self._start()

    def contraction(self) -> dict[str, float]:
        """``{muscle code: contraction}`` the animator has now."""
        anim = self.animator
        if anim is None:
            return {}
        return {c: float(anim.contraction[i]) for i, c in enumerate(anim.muscle_codes)}

    def _show_state(self) -> None:
        anim = self.animator
        if anim is not None:
            self.panel.show_state(self.contraction(), anim.jaw_deg)

    # ------------------------------------------------------------ running
    @property
    def running(self) -> bool:
        return self.timer.isActive()

    def _start(self) -> None:
        self._quiet_frames = 0
        if not self.timer.isActive():
            self.timer.start()
        self.panel.show_status("Moving …")

    def tick(self) -> None:
        """One frame: step the skin, move the drawn points, stop when settled."""
        anim = self.animator
        if anim is None or self.scene.closed:
            self.timer.stop()
            return
        t0 = time.perf_counter()
        anim.step(STEPS_PER_FRAME)
        # a live frame: the filtered skin without the exact (slow) inside-bone test; at rest
        # (settle_now, the final frame) the exact one is drawn
        points = anim.skin(exact=False).vertices
        before = self._points
        self.last_move_mm = (
            float(np.abs(points - before).max()) if before is not None else float("inf")
        )
        self._move_skin(points)
        if anim.jaw_deg != self._jaw_drawn:
            self._move_inner()
        self.scene.request_render()
        self.frame_ms.append(1000.0 * (time.perf_counter() - t0))
        del self.frame_ms[:-200]
        self._quiet_frames = self._quiet_frames + 1 if self.last_move_mm < SETTLED_MM else 0
        if self._quiet_frames >= SETTLED_FRAMES:
            self.timer.stop()
            self._move_skin(anim.skin().vertices)
            self.scene.request_render()
            ms = np.median(self.frame_ms[-50:])
            self.panel.show_status(
                f"At rest ({STEPS_PER_FRAME} steps a frame, {ms:.0f} ms median frame)."
            )
            self.settled.emit()

    def settle_now(self) -> int:
        """Run the skin to rest at once (the service's ``settle``; blocks ~1-3 s); returns steps."""
        anim = self.animator
        if anim is None:
            return 0
        self.timer.stop()
        steps = anim.settle()
        self._move_skin(anim.skin().vertices)
        self._move_inner()
        self.scene.request_render()
        self.panel.show_status(f"At rest ({steps} steps).")
        self.settled.emit()
        return steps

    def displacement(self) -> np.ndarray:
        """``(n,)`` distance (mm) of each skin vertex from its rest position."""
        anim = self.animator
        if anim is None:
            return np.zeros(0)
        return np.linalg.norm(anim.skin().vertices - anim.head.skin.vertices, axis=1)

    # ------------------------------------------------------------ drawing
    def draw(self) -> None:
        """(Re)draw the skin and the inner parts of the loaded head."""
        from workbench.qt.scene import BONE, SKIN, SMOOTH
        from workbench.render.snapshots import to_polydata

        self.clear()
        anim = self.animator
        if anim is None:
            return
        meshes = anim.meshes()
        skin = meshes["skin"]
        actor = self.plotter.add_mesh(
            to_polydata(skin, normals=True),
            color=SKIN,
            **SMOOTH,
            pickable=False,
            render=False,
            name="animate_skin",
        )
        self._actors["skin"] = actor
        self._points = skin.vertices.copy()
        for part in INNER_PARTS + ALWAYS_SHOWN:
            if part not in meshes:
                continue
            actor = self.plotter.add_mesh(
                to_polydata(meshes[part], normals=True),
                color=INNER_COLOURS.get(part, BONE),
                **SMOOTH,
                pickable=False,
                render=False,
                name=f"animate_{part}",
            )
            actor.SetVisibility(part in ALWAYS_SHOWN or self.panel.bones.isChecked())
            self._actors[part] = actor
        self._jaw_drawn = anim.jaw_deg
        self._show_inner(self.panel.bones.isChecked())

    def actors(self) -> dict[str, Any]:
        """``{part: actor}`` drawn by this tool (tests)."""
        return dict(self._actors)

    def clear(self) -> None:
        for actor in self._actors.values():
            self.plotter.remove_actor(actor, render=False)
        self._actors.clear()
        self._points = None
        self.scene.request_render()

    def _show_inner(self, on: bool) -> None:
        for part in INNER_PARTS:
            actor = self._actors.get(part)
            if actor is not None:
                actor.SetVisibility(bool(on))
        skin = self._actors.get("skin")
        if skin is not None:  # the bones show through a translucent skin
            skin.GetProperty().SetOpacity(0.55 if on else 1.0)
            if on:
                skin.GetProperty().BackfaceCullingOn()
            else:
                skin.GetProperty().BackfaceCullingOff()
        self.scene.request_render()

    def _move_skin(self, points: np.ndarray) -> None:
        actor = self._actors.get("skin")
        anim = self.animator
        if actor is None or anim is None:
            return
        _set_points(actor, points, anim.head.skin.faces)
        self._points = points

    def _move_inner(self) -> None:
        anim = self.animator
        if anim is None:
            return
        meshes = anim.meshes()
        for part in ("mandible", "lower_teeth", "tongue"):
            actor = self._actors.get(part)
            if actor is not None and part in meshes:
                _set_points(actor, meshes[part].vertices, meshes[part].faces)
        self._jaw_drawn = anim.jaw_deg

    def reset_camera(self) -> None:
        """Look at the face from the front (the head frame: +z toward the face, +y up)."""
        anim = self.animator
        if anim is None:
            return
        v = anim.skin().vertices
        lm = anim.head.skin_landmarks.as_dict()
        face = v[v[:, 2] > np.percentile(v[:, 2], 40)]  # the front of the head
        lo, hi = face.min(axis=0), face.max(axis=0)
        centre = (lo + hi) / 2
        if "prn" in lm and "gn" in lm and "g" in lm:  # between brow and chin
            centre[1] = (float(lm["g"][1]) + float(lm["gn"][1])) / 2
        renderer = self.plotter.renderer
        camera = renderer.GetActiveCamera()
        camera.SetFocalPoint(*centre)
        camera.SetPosition(*(centre + np.array([0.0, 0.0, 600.0])))
        camera.SetViewUp(0.0, 1.0, 0.0)
        renderer.ResetCamera(*np.column_stack([lo, hi]).ravel())
        camera.Zoom(1.5)
        renderer.ResetCameraClippingRange()
        self.scene.request_render()

    def detach(self) -> None:
        """Stop the timer (before the view closes)."""
        self.timer.stop()


def _set_points(actor: Any, points: np.ndarray, faces: np.ndarray) -> None:
    """Move an actor's polydata points (and its normals) in place."""
    from vtkmodules.util.numpy_support import vtk_to_numpy

    data = actor.GetMapper().GetInput()
    vtk_points = data.GetPoints()
    new = np.asarray(points, float)
    vtk_to_numpy(vtk_points.GetData())[:] = new
    vtk_points.Modified()
    normals = data.GetPointData().GetNormals()
    if normals is not None:
        vtk_to_numpy(normals)[:] = vertex_normals(Mesh(new, faces))
        normals.Modified()
    data.Modified()
