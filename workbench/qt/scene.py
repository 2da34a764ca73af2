"""The 3D scene of the window: named layers drawn in one pyvista plotter.

Units mm, everything in the specimen's **input frame** (the skull file's
coordinates), so the evidence, landmarks, dowels and the fitted face overlay.

One handedness (:mod:`workbench.render.visuals.orientation`): a frontal view
shows the subject's right on the viewer's left, as the guide view and the
report pictures do.  When the input frame is a mirror image of the subject
(the landmarks or the file's known anatomy say so), :meth:`SceneView.reset_camera`
has the view reflect its display across the midsagittal plane — the data,
picking and the files stay in the input frame — and small letters at the
view's edges (R/L, S/I, A/P) name the subject's sides.

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
only draws what the window hands it.  What a layer looks like (colours, sizes,
colour bars) is the render layer's (:mod:`workbench.render.visuals`); the scene
decides when to draw, which layer an actor belongs to, and removes actors.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from PySide6.QtCore import QObject, QTimer, Signal
from PySide6.QtWidgets import QWidget

from workbench.core.mesh import Mesh
from workbench.render.visuals import face, markers, skull, update
from workbench.render.visuals import muscles as muscle_visuals
from workbench.render.visuals.orientation import Anatomy, DisplayMirror, EdgeLetters, reflection
from workbench.render.visuals.style import set_view_background

#: layer name → menu title (also the row order of the Layers dock)
LAYERS = {
    "skull": "Skull",
    "landmarks": "Landmarks",
    "dowels": "Dowels",
    "guides": "Guides",
    "muscles": "Muscles",
    "face": "Face (skin)",
    "hair": "Hair and brows (artistic)",
    "held": "Held-back refit (ghost)",
    "truth": "True skin (compare)",
}
#: layers hidden until the user switches them on (everything else starts visible)
HIDDEN_BY_DEFAULT = frozenset({"muscles"})
#: starting opacity per layer (1.0 where not listed)
DEFAULT_OPACITY = {"face": 0.6, "held": 0.35}
#: layers drawn only while there is something to show (a refit held back for the user; the
#: hair, brows and beard the case chose in the Appearance dock)
ON_DEMAND = frozenset({"held", "hair"})
#: actors drawn with a layer and following its visibility and opacity, kept apart so that
#: the layer's first actor stays its surface (:meth:`SceneView.update_points`): the
#: fitted head's eyes go with the face.  Not in the menus; their state in
#: :attr:`SceneView.visible` and :attr:`SceneView.opacity` is their owner's.
COMPANIONS = {"eyes": "face"}
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


def case_anatomy(case: Any) -> Anatomy | None:
    """The subject's directions in ``case``'s input frame, for the camera; None when unknown.

    From the head frame of the skull landmarks when they define one (with a
    reflection in it when their left/right labels say the file is a mirror
    image), else from the case's orientation (its ``left``, when given, says
    the same), as :func:`workbench.services.reconstruction.case_steps.view_axes`.
    """
    from workbench.core.errors import WorkbenchError
    from workbench.services.landmarks.frame import input_frame

    try:
        to_head, _ = input_frame(case.landmarks["skull"])
    except (WorkbenchError, ValueError, KeyError, np.linalg.LinAlgError):
        orient = case.orientation
        if orient is None:
            return None
        return Anatomy.of(orient.anterior, orient.superior, orient.left)
    return Anatomy.from_head_frame(to_head)


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
        for name, owner in COMPANIONS.items():
            self.visible[name], self.opacity[name] = self.visible[owner], self.opacity[owner]
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
        set_view_background(plotter)
        window = getattr(plotter, "render_window", None)
        self._end_observer = (
            None if window is None else window.AddObserver("EndEvent", self._rendered)
        )
        #: the subject's directions in the input frame (None: unknown), as last reset
        self.anatomy: Anatomy | None = None
        # the display reflection and the side letters apply while the case's layers are
        # shown (the age and animate tools lend this view's camera for their heads)
        self.mirror: DisplayMirror | None = None
        self.letters: EdgeLetters | None = None
        if renderer is not None:
            self.mirror = DisplayMirror(renderer, when=self.case_shown)
            self.letters = EdgeLetters(renderer, when=self.case_shown)

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
        for helper in (self.mirror, self.letters):
            if helper is not None:
                helper.detach()
        self.mirror = self.letters = None

    # ------------------------------------------------------------ layers
    def actors(self, layer: str) -> list[Any]:
        return list(self._actors.get(layer, []))

    def has(self, layer: str) -> bool:
        return bool(self._actors.get(layer))

    def clear(self, layer: str) -> None:
        """Remove ``layer``'s actors and those of its :data:`COMPANIONS`."""
        for name in (layer, *self._companions(layer)):
            for actor in self._actors.pop(name, []):
                self.plotter.remove_actor(actor, render=False)
        self.request_render()

    @staticmethod
    def _companions(layer: str) -> list[str]:
        return [name for name, owner in COMPANIONS.items() if owner == layer]

    def _add(self, layer: str, actor: Any) -> None:
        """Register ``actor`` under ``layer`` with the layer's visibility and opacity."""
        self._actors.setdefault(layer, []).append(actor)
        actor.SetVisibility(self.visible.get(layer, True))
        actor.GetProperty().SetOpacity(self.opacity.get(layer, 1.0))

    def set_visible(self, layer: str, on: bool) -> None:
        """Show or hide every actor of ``layer`` and its companions (kept for later redraws)."""
        on = bool(on)
        changed = self.visible.get(layer) != on
        for name in (layer, *self._companions(layer)):
            self.visible[name] = on
            for actor in self._actors.get(name, []):
                actor.SetVisibility(on)
        self.request_render()
        if changed:
            self.layer_changed.emit(layer)

    def set_opacity(self, layer: str, value: float) -> None:
        """Opacity in [0, 1] of every actor of ``layer`` and its companions (kept for later
        redraws)."""
        value = min(max(float(value), 0.0), 1.0)
        changed = self.opacity.get(layer) != value
        for name in (layer, *self._companions(layer)):
            self.opacity[name] = value
            for actor in self._actors.get(name, []):
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
        update.move_points(actors[0], points)
        self.request_render()

    def case_shown(self) -> bool:
        """Some layer of the case is drawn and visible (not set aside for a tool's heads)."""
        return any(self.visible.get(k, True) and self._actors.get(k) for k in LAYERS)

    @property
    def mirrored(self) -> bool:
        """The view shows its input frame reflected (a mirror-image input, see the module doc)."""
        return self.mirror is not None and self.mirror.active

    def set_anatomy(
        self, anatomy: Anatomy | None, centre: Sequence[float] | np.ndarray | None = None
    ) -> None:
        """The subject's directions in the input frame (None: unknown); the camera stays.

        The letters at the edges follow them; a mirror-image input is shown
        reflected across the midsagittal plane through ``centre`` (mm, input
        frame; default the camera's focal point), so the subject's right is on
        the viewer's left.  A reflection already shown for the same
        midsagittal direction is kept (the view does not jump).
        """
        self.anatomy = anatomy
        if self.letters is not None:
            self.letters.set_anatomy(anatomy)
        if self.mirror is not None:
            if anatomy is None or not anatomy.mirrored:
                self.mirror.reflect_world(None)
            elif centre is not None or not self._reflects_across(anatomy.left):
                point = self.plotter.camera.focal_point if centre is None else centre
                self.mirror.reflect_world(reflection(point, anatomy.left))
        self.request_render()

    def _reflects_across(self, normal: np.ndarray) -> bool:
        """The view already reflects across a plane normal to ``normal`` (within ~6°)."""
        world = None if self.mirror is None else self.mirror.world
        if world is None:
            return False
        current = np.eye(3) - world[:3, :3]  # 2 n nᵀ
        axis = current @ normal
        return float(np.linalg.norm(axis)) > 1.99  # |2 n (n · normal)| = 2 cos θ

    def reset_camera(self, anatomy: Anatomy | None = None) -> None:
        """Look at the face from the front when the subject's directions are known.

        ``anatomy`` holds them in the input frame (:func:`case_anatomy`); a
        mirror-image input is shown reflected across the midsagittal plane
        through the view's centre (:meth:`set_anatomy`).
        """
        focus = np.asarray(self.plotter.center, float)
        self.set_anatomy(anatomy, centre=focus)
        if anatomy is not None:
            # (the reflection keeps the anterior and superior directions and the focus)
            self.plotter.camera_position = [
                tuple(focus + 600.0 * anatomy.anterior),
                tuple(focus),
                tuple(anatomy.superior),
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
        actor = skull.add_skull(self.plotter, mesh, name="layer_skull", pickable=True)
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
        size = self._marker_size()
        p = self.plotter
        drawn = markers.add_status_markers(
            p, points, statuses, markers.STATUS_COLOURS, size, "layer_landmarks_"
        )
        if selected is not None and np.isfinite(selected).all():
            drawn.append(markers.add_selected(p, selected, size, "layer_landmarks_selected"))
            if label:
                drawn.append(markers.add_label(p, selected, label, "layer_landmarks_label"))
        for actor in drawn:
            self._add("landmarks", actor)
        self.request_render()

    def show_dowels(self, origins: np.ndarray, tips: np.ndarray) -> None:
        """Each dowel as a line from its skull origin to its tip, with a tip sphere."""
        self.clear("dowels")
        if len(origins):
            for actor in markers.add_dowels(self.plotter, origins, tips, self._marker_size()):
                self._add("dowels", actor)
        self.request_render()

    def show_face(
        self,
        mesh: Mesh | None,
        scalars: np.ndarray | None = None,
        title: str = "",
        eyes: face.PaintedEyes | None = None,
    ) -> None:
        """The fitted skin; with ``scalars`` (per vertex, mm) as a colour map; ``eyes`` (the
        fitted head's, painted: :func:`~workbench.render.visuals.face.paint_eyes`) drawn with
        it as the face's companion layer "eyes" (they do not move with the build slider)."""
        self.clear("face")
        if mesh is None:
            return
        # translucent: back faces culled (see SetUseOIT above)
        self._add("face", face.add_face(self.plotter, mesh, scalars, title))
        if eyes is not None:
            self._add("eyes", face.add_eyes(self.plotter, eyes))
        self.request_render()

    def show_hair(self, pieces: Sequence[tuple[Mesh, np.ndarray, np.ndarray]]) -> None:
        """The hair, brows, beard and moustache chosen for the face: ``(mesh, sRGB per vertex,
        shading normals)`` per piece, input frame, mm (the Appearance dock draws them);
        empty: none.  Drawn opaque whatever the face's opacity."""
        self.clear("hair")
        for i, (mesh, srgb, normals) in enumerate(pieces):
            self._add("hair", face.add_hair(self.plotter, mesh, srgb, normals, name=f"hair_{i}"))
        self.request_render()

    def show_held(self, mesh: Mesh | None) -> None:
        """A refit held back (see the reconstruct tool), as a ghost over the face; None: gone."""
        self.clear("held")
        if mesh is not None:
            self._add("held", face.add_held_face(self.plotter, mesh))
        self.request_render()

    def show_truth(
        self, mesh: Mesh | None, signed_mm: np.ndarray | None = None, limit_mm: float = 5.0
    ) -> None:
        """The true skin, coloured by signed distance (NaN grey) when given."""
        self.clear("truth")
        if mesh is None:
            return
        self._add("truth", face.add_truth(self.plotter, mesh, signed_mm, limit_mm))
        self.request_render()

    def show_guides(
        self, segments: list[tuple[np.ndarray, np.ndarray]], points: np.ndarray
    ) -> None:
        """Guide lines (pairs of end points) and guide points, input frame."""
        self.clear("guides")
        for actor in markers.add_guides(self.plotter, segments, points, self._marker_size()):
            self._add("guides", actor)
        self.request_render()

    def show_muscles(self, muscles: Sequence[Sequence[np.ndarray]]) -> tuple[int, int]:
        """Muscle grids as red sheets with darker fibre lines (mm, input frame).

        ``muscles`` holds, per muscle, its grid rows as ``(n_i, 3)`` arrays in
        order (see :mod:`workbench.render.visuals.muscles`).
        Returns ``(number of sheet triangles, number of polylines)``.
        """
        self.clear("muscles")
        actors, n_faces, n_lines = muscle_visuals.add_muscles(self.plotter, muscles)
        if not actors:
            return 0, 0
        for actor in actors:
            self._add("muscles", actor)
        self.request_render()
        return n_faces, n_lines

    def layer_points(self, layer: str) -> np.ndarray:
        """The drawn points of ``layer``'s first actor (mm, input frame; a copy)."""
        actors = self._actors.get(layer)
        if not actors:
            raise KeyError(f"layer {layer!r} has nothing drawn")
        return update.drawn_points(update.source_data(actors[0]))

    def move_layer_points(self, layer: str, points: np.ndarray) -> None:
        """Move the points of every actor of ``layer`` in place (they share one layout,
        as the muscle sheets and fibres do); one render is requested."""
        actors = self._actors.get(layer)
        if not actors:
            raise KeyError(f"layer {layer!r} has nothing drawn")
        for actor in actors:
            update.move_points(actor, points)
        self.request_render()

    def _marker_size(self) -> float:
        return markers.MARKER_PX
