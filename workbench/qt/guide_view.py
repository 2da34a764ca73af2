"""The second view: the nose and mouth guides over the face, frontal or lateral, orthographic.

Drawn in the **head frame** of the last fit (mm; x to the subject's left,
y up, z forward, Frankfort Horizontal at y = 0) with a parallel projection,
so a vertical guide line *is* ``x = value`` on screen and a lateral guide
point *is* ``(y, z)``:

* the skull (a light copy, :mod:`workbench.qt.lod`) and the fitted skin;
* the guides of the reconstruct panel in magenta — vertical lines (x),
  horizontal lines (y) in the frontal view, points (y, z) in the lateral
  view — each with its label;
* the published-rule predictions for the same features in cyan, side by
  side with the classic guides (:func:`workbench.services.guides.classic.guides_from_prediction`);
* in yellow, where the skull measurements behind the guides were taken (the
  widest aperture, the nasal spine, the canines, the incisal edge and the
  cemento-enamel junctions, :func:`workbench.services.guides.measure.marks_for_view`),
  and under the view the measurements that could not be taken, with why;
* at the view's edges, small letters naming the subject's sides (R/L, S/I,
  A/P; :class:`workbench.render.visuals.orientation.EdgeLetters`).

Handedness: the frontal view looks at the face from in front (+z toward the
camera, y up), so the subject's right (−x) is on the viewer's left, as in a
photograph, the main 3D view and the report pictures; the lateral view looks
at the subject's left side (from +x), the face toward the screen's left.  The
head frame is right-handed and anatomically true even for a mirror-image
skull file (its reflection is in the fit's input → head map), so this view
never needs reflecting.

A guide is dragged with the left button (press within
:data:`GRAB_RADIUS_PX` of it): the window previews the re-solved face at
every move (the drag host's ``preview_guide``, :class:`workbench.qt.hosts.GuideDragHost`)
and stores the new value as one undoable step on release (its ``commit_guide``),
which re-fits the face in the worker.  The fit drawn is the session's
(:class:`workbench.qt.session.Session`); the guides are the reconstruct
panel's list (:class:`workbench.qt.hosts.GuideRows`).  Elsewhere the left button pans and the
wheel zooms (the view never rotates by accident).

The surfaces, lines, points and labels themselves are made by
:mod:`workbench.render.visuals`; this view decides what is drawn where and when.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
from PySide6.QtCore import QEvent, Qt, QTimer
from PySide6.QtWidgets import (
    QButtonGroup,
    QCheckBox,
    QHBoxLayout,
    QLabel,
    QRadioButton,
    QStackedWidget,
    QVBoxLayout,
    QWidget,
)

from workbench.qt.lod import decimated, with_normals
from workbench.qt.scene import is_closed
from workbench.render.snapshots import to_polydata
from workbench.render.visuals import markers, update
from workbench.render.visuals.face import add_guide_face
from workbench.render.visuals.markers import GUIDE, PREDICTION
from workbench.render.visuals.orientation import HEAD, Anatomy, EdgeLetters
from workbench.render.visuals.skull import add_skull
from workbench.render.visuals.style import set_view_background
from workbench.services.guides.classic import AXES, Guide, guides_from_prediction

if TYPE_CHECKING:
    from workbench.qt.hosts import GuideDragHost, GuideRows
    from workbench.qt.scene import SceneView
    from workbench.qt.session import Session
    from workbench.qt.workers import TaskRunner
    from workbench.services.reconstruction.case_steps import FitResult

GRAB_RADIUS_PX = 8.0
PRIORITY = 10.0
#: vertical extent of a vline, horizontal extent of an hline (head frame, mm)
VLINE_Y = (-80.0, 10.0)
HLINE_X = (-40.0, 40.0)


class GuideView(QWidget):
    """See the module docstring.

    Parameters
    ----------
    session : Session
        Holds the fit drawn here.
    runner : TaskRunner
        The window's worker (the light skull is prepared there).
    scene : SceneView
        The main 3D view (this view paints after its pending paint).
    guide_list : GuideRows
        The guides, in table row order (the reconstruct panel).
    drag_host : GuideDragHost
        Previews and stores the guide drags.
    """

    def __init__(
        self,
        session: Session,
        runner: TaskRunner,
        scene: SceneView,
        guide_list: GuideRows,
        drag_host: GuideDragHost,
        parent: QWidget | None = None,
    ) -> None:
        from pyvistaqt import QtInteractor

        super().__init__(parent)
        self.session = session
        self.runner = runner
        self.scene = scene
        self.guide_list = guide_list
        self.drag_host = drag_host
        self.side = "frontal"
        self.closed_by_user = False
        self.stale = True  # needs drawing when next shown (changed while hidden)
        self._samples = 0
        self.dragging: tuple[int, Guide] | None = None
        self._skull_light: Any = None
        self.drawn_fit: Any = None  # the fit the view shows (None: none yet)
        self._face_actor: Any = None
        self._guide_slots: dict[int, tuple[Any, int, int]] = {}
        self._marks: list[tuple[str, np.ndarray, str]] = []
        self._unmeasured: list[str] = []

        self.frontal = QRadioButton("Frontal")
        self.lateral = QRadioButton("Lateral")
        self.frontal.setChecked(True)
        group = QButtonGroup(self)
        for b in (self.frontal, self.lateral):
            group.addButton(b)
        self.frontal.toggled.connect(lambda on: self.set_side("frontal" if on else "lateral"))
        self.show_predictions = self._toggle(
            "Published predictions",
            "Cyan: the published prediction rules for the same "
            "features, beside the classic guides (magenta)",
        )
        self.show_measures = self._toggle(
            "Measurements",
            "Yellow: where the skull was measured for the guides (aperture, "
            "nasal spine, canines, incisal edge, cemento-enamel junctions)",
        )
        self.info = QLabel("Drag a magenta guide; the face follows.")
        self.info.setWordWrap(True)
        bar = QHBoxLayout()
        for w in (self.frontal, self.lateral, self.show_predictions, self.show_measures):
            bar.addWidget(w)
        bar.addStretch(1)

        self.plotter = QtInteractor(self, auto_update=False)
        # no 4x multisampling (llvmpipe: 73 → 42 ms a frame for this view);
        # FXAA as in the 3D view, dropped with it on a software renderer
        # (SceneView.tune)
        self._render_window().SetMultiSamples(0)
        self.plotter.enable_anti_aliasing("fxaa")
        set_view_background(self.plotter, guide=True)
        self.plotter.enable_parallel_projection()  # type: ignore[call-arg]  # pyvista stub bug: wraps-typed method
        self.plotter.enable_2d_style()  # type: ignore[call-arg]  # pyvista stub bug: wraps-typed method
        self.plotter.clear_events_for_key("q")  # type: ignore[arg-type]  # pyvista stub bug: wraps-typed method
        # R/L, S/I, A/P at the edges (put back after each clear_actors)
        self.letters = EdgeLetters(self.plotter.renderer)
        self.letters.set_anatomy(HEAD)
        # until a fit is drawn a plain label stands in for the 3D view: an
        # empty OpenGL view would still cost a software-GL paint, in the same
        # pass as the main view's when the first fit opens this view
        self.placeholder = QLabel(
            "The nose and mouth guides appear here once the face is fitted (Reconstruct)."
        )
        self.placeholder.setWordWrap(True)
        self.placeholder.setAlignment(Qt.AlignmentFlag.AlignCenter)
        self.placeholder.setStyleSheet("background: #1f2329; color: #c8ccd2; padding: 24px;")
        self.pages = QStackedWidget(self)
        self.pages.addWidget(self.placeholder)
        self.pages.addWidget(self.plotter)
        self.pages.installEventFilter(self)
        layout = QVBoxLayout(self)
        layout.setContentsMargins(2, 2, 2, 2)
        layout.addLayout(bar)
        layout.addWidget(self.pages, 1)
        layout.addWidget(self.info)
        iren = self._iren = self.plotter.iren.interactor
        self._tags = {
            event: iren.AddObserver(event, handler, PRIORITY)
            for event, handler in (
                ("LeftButtonPressEvent", self._on_press),
                ("MouseMoveEvent", self._on_move),
                ("LeftButtonReleaseEvent", self._on_release),
            )
        }

    def _toggle(self, text: str, tip: str) -> QCheckBox:
        """A check box, on, that redraws the view when toggled."""
        box = QCheckBox(text)
        box.setChecked(True)
        box.setToolTip(tip)
        box.toggled.connect(lambda _on: self.refresh())
        return box

    # ------------------------------------------------------------ content
    def set_side(self, side: str) -> None:
        self.side = side
        self.refresh(reset_camera=True)

    def fit_changed(self) -> None:
        """A new fit: prepare the light skull in the worker, then draw once.

        The view keeps showing the previous fit for the ~0.2 s the light
        skull takes, rather than being drawn twice (face first, then skull).
        The main view takes the fit's handedness (its input → head map) at
        once, so the two views never show the subject mirrored to each other.
        """
        fit = self.session.fit
        self._skull_light = None
        self._marks, self._unmeasured = [], []
        if fit is None:
            self.refresh()
            return
        self.scene.set_anatomy(Anatomy.from_head_frame(fit.recon.input_to_head))

        def prepare() -> tuple[Any, Any]:
            from workbench.services.guides.measure import marks_for_view

            light = with_normals(decimated(fit.skull_h, 15_000))
            lms_h = fit.recon.landmarks
            if lms_h is not None:
                lms_h = lms_h.transformed(fit.recon.input_to_head)
                return light, marks_for_view(lms_h, fit.skull_h)
            return light, ([], [])

        self.runner.submit(
            "guide_view",
            "Preparing the guide view …",
            prepare,
            lambda got: self._skull_ready(to_polydata(got[0], normals=True), got[1]),
            lambda _exc: self.refresh(reset_camera=True),
        )

    def _skull_ready(self, light: Any, marks: Any = ([], [])) -> None:
        self._skull_light = light
        self._marks, self._unmeasured = marks
        self.refresh(reset_camera=True)

    def refresh(self, reset_camera: bool = False) -> None:
        """Redraw skull, face, guides and predictions from the session's fit."""
        p = self.plotter
        if is_closed(p):
            return
        if not self.isVisible():
            self.stale = True  # drawn when shown (hidden views cost nothing)
            return
        self.stale = False
        p.clear_actors()
        self._face_actor, self._guide_slots = None, {}
        fit = self.session.fit
        if fit is None:
            self.drawn_fit = None
            self.info.setText("The guides appear here once the face is fitted.")
            self.pages.setCurrentWidget(self.placeholder)
            return
        if self._skull_light is not None:
            add_skull(p, self._skull_light, name="gv_skull", pickable=False)
        # translucent, back faces culled: blended unsorted (no OIT)
        self._face_actor = add_guide_face(p, fit.recon.head.skin)
        self._draw_guides()
        self.drawn_fit = fit
        if reset_camera:
            self._reset_camera()
        # one render, in the widget's paint, asked for on a later turn: the
        # drawing above and the (software-GL) paint then block the event
        # loop one after the other, not as one long stretch; and after the
        # main view's pending paint (views of one window paint together)
        if self.scene.render_queued:
            self.scene.after_paint(self._paint, render=False)
        else:
            QTimer.singleShot(0, self._paint)

    def _paint(self) -> None:
        if is_closed(self.plotter):
            return
        if self.drawn_fit is not None:
            self.pages.setCurrentWidget(self.plotter)  # (a first show paints by itself)
        self.plotter.update()

    def _fit(self) -> FitResult:
        """The session's fit (drawing and dragging happen only while there is one)."""
        fit = self.session.fit
        if fit is None:
            raise RuntimeError("the guide view has no fit to draw")
        return fit

    def _render_window(self) -> Any:
        win = self.plotter.render_window
        if win is None:
            raise RuntimeError("the guide view's render window is closed")
        return win

    def _front(self) -> float:
        return float(self._fit().recon.head.skin.vertices[:, 2].max()) + 20.0

    def _segment(self, g: Guide) -> np.ndarray | None:
        """Drawn ends (2, 3) of a frontal guide, or one point (1, 3) of a lateral one."""
        if g.view != self.side:
            return None
        z = self._front()
        if g.kind == "vline":
            return np.array([[g.value[0], VLINE_Y[0], z], [g.value[0], VLINE_Y[1], z]])
        if g.kind == "hline":
            return np.array([[HLINE_X[0], g.value[0], z], [HLINE_X[1], g.value[0], z]])
        return np.array([[150.0, g.value[0], g.value[1]]])  # lateral: in front of the head

    def _draw_guides(self) -> None:
        """Guides (magenta) and predictions (cyan): one lines and one points actor each.

        ``self._guide_slots`` maps a guide's row to ``(actor, first point
        index, number of points)`` so a drag moves its points in place.
        """
        guides = list(self.guide_list.guides)
        self._guide_slots = {}
        self._add_set(list(enumerate(guides)), GUIDE, 4, "gv_guide", track=True)
        if self.show_predictions.isChecked():
            predicted: list[Guide] = []
            for pred in self._fit().predictions:
                try:
                    predicted += [
                        g for g in guides_from_prediction(pred, guides) if g.view == self.side
                    ]
                except Exception:  # noqa: BLE001 - a prediction that maps to no guide
                    continue
            self._add_set(list(enumerate(predicted)), PREDICTION, 2, "gv_pred", track=False)
        text = (
            "Magenta: guides (drag to move). Cyan: published predictions."
            if self.show_predictions.isChecked()
            else "Magenta: guides (drag to move)."
        )
        if self.show_measures.isChecked():
            self._draw_marks()
            text += " Yellow: where the skull was measured."
            if self._unmeasured:
                text += "\nNot measured — " + "; ".join(self._unmeasured[:3])
        self.info.setText(text)

    def _draw_marks(self) -> None:
        """The skull measurements' places, yellow, each with its short label."""
        if not self._marks:
            return
        pts = np.array([at for _label, at, _how in self._marks])
        # brought to the front of the head along the view (parallel projection: the
        # place on screen is the same), so the translucent face cannot hide them
        if self.side == "frontal":
            pts[:, 2] = self._front() - 1.0
        else:
            pts[:, 0] = 149.0
        # one label per kind and side (the two canine points of a side share a place)
        labels: dict[tuple[str, int], np.ndarray] = {}
        for (label, at, _how), shown in zip(self._marks, pts, strict=True):
            side = int(np.sign(round(at[0], 1))) if self.side == "frontal" else 0
            labels.setdefault((label, side), shown)
        markers.add_measure_marks(
            self.plotter, pts, np.array(list(labels.values())), [label for label, _side in labels]
        )

    def _add_set(
        self,
        items: list[tuple[int, Guide]],
        colour: tuple,
        width: float,
        prefix: str,
        *,
        track: bool,
    ) -> None:
        lines: list[np.ndarray] = []
        points: list[np.ndarray] = []
        slots: list[tuple[int, str, int, int]] = []
        label_points, label_text = [], []
        for row, g in items:
            seg = self._segment(g)
            if seg is None or not g.enabled:
                continue
            target = lines if len(seg) == 2 else points
            first = sum(len(x) for x in target)
            target.append(seg)
            slots.append((row, "lines" if len(seg) == 2 else "points", first, len(seg)))
            label_points.append(seg[0] if g.kind == "hline" else seg[-1])
            label_text.append(g.label)  # the name an artist reads, not the id
        actors = markers.add_guide_set(self.plotter, lines, points, colour, width, prefix)
        if track:
            self._guide_slots = {row: (actors[kind], first, n) for row, kind, first, n in slots}
            if label_points:
                markers.add_flat_labels(
                    self.plotter,
                    np.array(label_points),
                    label_text,
                    colour,
                    10,
                    f"{prefix}_labels",
                )

    def _reset_camera(self) -> None:
        skin = self._fit().recon.head.skin.vertices
        face = skin[skin[:, 1] > -110.0]
        centre = np.array([0.0, float(np.median(face[:, 1])) - 20.0, float(np.median(face[:, 2]))])
        eye = centre + ([0.0, 0.0, 500.0] if self.side == "frontal" else [500.0, 0.0, 0.0])
        self.plotter.camera_position = [tuple(eye), tuple(centre), (0.0, 1.0, 0.0)]
        # Plotter.reset_camera always renders (pyvista 0.49 ignores render=False);
        # the renderer's own reset does not, so the next paint draws it
        self.plotter.renderer.reset_camera(render=False)
        self._fit_scale()

    def showEvent(self, event: Any) -> None:  # noqa: N802 - Qt name
        super().showEvent(event)
        if self.stale:
            self.refresh(reset_camera=True)

    def eventFilter(self, watched: Any, event: Any) -> bool:  # noqa: N802 - Qt name
        # the page stack resized (after this widget's own resize event, with
        # its new size): keep 160 mm of the face across the narrower side
        if (
            watched is self.pages
            and event.type() == QEvent.Type.Resize
            and self.session.fit is not None
            and not is_closed(self.plotter)
        ):
            self._fit_scale()
        return False

    def _fit_scale(self) -> None:
        # parallel scale = half the view's height in mm: show a 160 mm square of the face
        # the page stack's size: the 3D view may not be the current page yet
        # (a hidden page of a stack keeps a stale size)
        width, height = self.pages.width(), self.pages.height()
        self.plotter.camera.parallel_scale = 80.0 * max(1.0, height / max(width, 1))

    # ------------------------------------------------------------ live updates
    def update_face(self, skin_head: np.ndarray) -> None:
        """New skin vertex positions (head frame) during a drag; no actor is re-created."""
        if self._face_actor is None:
            return
        update.set_input_points(self._face_actor, skin_head)
        self.plotter.update()

    def show_dragged(self, guide: Guide) -> None:
        """Move the dragged guide's line (or point) to ``guide.value``, in place."""
        if self.dragging is None:
            return
        row, _ = self.dragging
        slot = self._guide_slots.get(row)
        seg = self._segment(guide)
        if slot is None or seg is None or len(seg) != slot[2]:
            return
        actor, first, _n = slot
        update.set_input_points(actor, seg, first)
        self.plotter.update()

    # ------------------------------------------------------------ mouse
    def _display(self, point: np.ndarray) -> np.ndarray:
        ren = self.plotter.renderer
        ren.SetWorldPoint(*np.asarray(point, float), 1.0)
        ren.WorldToDisplay()
        return np.array(ren.GetDisplayPoint()[:2], float)

    def _world(self, x: float, y: float) -> np.ndarray:
        ren = self.plotter.renderer
        ren.SetDisplayPoint(float(x), float(y), 0.0)
        ren.DisplayToWorld()
        wx, wy, wz, w = ren.GetWorldPoint()
        return np.array([wx, wy, wz]) / w

    def guide_at(self, x: float, y: float) -> int | None:
        """Row of the guide drawn within :data:`GRAB_RADIUS_PX` of display ``(x, y)``."""
        if self.session.fit is None:
            return None
        best, best_d = None, GRAB_RADIUS_PX
        for row, g in enumerate(self.guide_list.guides):
            seg = self._segment(g)
            if seg is None or not g.enabled:
                continue
            ends = [self._display(p) for p in seg]
            d = _distance_to_segment(np.array([x, y], float), ends[0], ends[-1])
            if d <= best_d:
                best, best_d = row, d
        return best

    def _swallow(self, obj: Any, event: str) -> None:
        obj.GetCommand(self._tags[event]).SetAbortFlag(1)

    def _position(self) -> tuple[int, int]:
        x, y = self.plotter.iren.interactor.GetEventPosition()
        return int(x), int(y)

    def _on_press(self, obj: Any, event: str) -> None:
        row = self.guide_at(*self._position())
        if row is None:
            return
        self._swallow(obj, event)
        self.dragging = (row, self.guide_list.guides[row])
        self._samples = self._render_window().GetMultiSamples()
        self._render_window().SetMultiSamples(0)  # a lighter frame while dragging

    def _on_move(self, obj: Any, event: str) -> None:
        if self.dragging is None:
            return
        self._swallow(obj, event)
        row, start = self.dragging
        world = self._world(*self._position())
        value = tuple(float(world[a]) for a in AXES[start.kind])
        moved = start.moved(value)
        self.dragging = (row, moved)
        self.drag_host.preview_guide(moved)

    def _on_release(self, obj: Any, event: str) -> None:
        if self.dragging is None:
            return
        self._swallow(obj, event)
        row, guide = self.dragging
        self.dragging = None
        self._render_window().SetMultiSamples(self._samples)
        original = self.guide_list.guides[row]
        self.drag_host.commit_guide(row, None if guide.value == original.value else guide.value)

    def cancel_drag(self) -> None:
        if self.dragging is not None:
            row, _ = self.dragging
            self.dragging = None
            self._render_window().SetMultiSamples(self._samples)
            self.drag_host.commit_guide(row, None)

    def close_view(self) -> None:
        """Remove the VTK observers (they hold this widget), then finalize the view."""
        for tag in self._tags.values():
            self._iren.RemoveObserver(tag)
        self._tags = {}
        self.letters.detach()
        self.plotter.close()


def _distance_to_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    ab = b - a
    t = 0.0 if not ab.any() else float(np.clip((p - a) @ ab / (ab @ ab), 0.0, 1.0))
    return float(np.linalg.norm(p - (a + t * ab)))
