"""Live dragging in the main window: a skull landmark along the surface, a guide line.

A tool the main window composes (:class:`DragTool`).  While the mouse
moves nothing is written to the case: the view being dragged in draws a
*preview* — the landmark marker, its dowel, and the face re-solved by
:class:`workbench.services.reconstruction.preview_fit.PreviewFit` from the last full fit
(a few milliseconds) — with a lighter skull and no multisampling
(:mod:`workbench.qt.lod`).  Mouse moves are coalesced: however fast they
come, one preview is computed and drawn per event-loop turn, with the newest
position.  On release **one** undoable command is pushed (a
``MoveLandmark``, or the guide list as a ``SetGuides``), which starts the
full re-fit in the worker as any other change does.  Esc cancels a drag and
leaves the case as it was.

Units mm; landmark positions in the input frame, guide values in the head
frame (see :mod:`workbench.services.guides.classic`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import numpy as np
from PySide6.QtCore import QTimer

from workbench.commands.landmarks import MoveLandmark
from workbench.core.spatial import MeshIndex
from workbench.services.guides.classic import Guide
from workbench.services.reconstruction.preview_fit import PreviewFit

if TYPE_CHECKING:
    from workbench.qt.document import Document
    from workbench.qt.guide_view import GuideView
    from workbench.qt.lod import InteractiveDetail
    from workbench.qt.panels.landmarks_panel import LandmarksPanel
    from workbench.qt.panels.reconstruct_panel import ReconstructPanel
    from workbench.qt.picking import ClickPicker
    from workbench.qt.scene import SceneView
    from workbench.qt.session import Session


class DragTool:
    """Landmark and guide drags with a live preview (see the module docstring).

    Parameters
    ----------
    document, scene, session
        The case, the main 3D view's layers, the fit previews start from.
    detail : InteractiveDetail
        The lighter skull while dragging.
    plotter
        The main 3D view (one render per dragged frame).
    landmarks_panel, reconstruct_panel
        The selected landmark; the guide list a guide drag stores into.
    draw_landmarks, draw_face
        Redraw the landmarks (``override``: {code: position} of a drag) and the face.

    The click picker and the guide view are attached once they exist
    (:meth:`attach`): both call back into this tool.
    """

    def __init__(
        self,
        document: Document,
        scene: SceneView,
        session: Session,
        detail: InteractiveDetail,
        plotter: Any,
        landmarks_panel: LandmarksPanel,
        reconstruct_panel: ReconstructPanel,
        draw_landmarks: Callable[[dict[str, np.ndarray] | None], None],
        draw_face: Callable[[], None],
    ) -> None:
        self.document = document
        self.scene = scene
        self.session = session
        self.detail = detail
        self.plotter = plotter
        self.landmarks_panel = landmarks_panel
        self.reconstruct_panel = reconstruct_panel
        self._draw_landmarks = draw_landmarks
        self._draw_face = draw_face
        self.picker: ClickPicker | None = None
        self.guide_view: GuideView | None = None
        self.drag_timings: list[float] = []  # seconds per computed preview (tests, benchmarks)
        self._preview_fit: PreviewFit | None = None
        self._drag_pending: tuple[str, Any] | None = None
        self._drag_scheduled = False
        self._muscle_binding: tuple | None = None  # see _preview_muscles

    def attach(self, picker: ClickPicker, guide_view: GuideView) -> None:
        """The views whose drags this tool handles (they are built after it)."""
        self.picker = picker
        self.guide_view = guide_view

    # ------------------------------------------------------------ landmark drags
    def grab_target(self) -> tuple[str, np.ndarray] | None:
        """The selected, defined skull landmark (code, input-frame mm), if any."""
        if not self.landmarks_panel.place_on_click.isChecked():
            return None
        code = self.landmarks_panel.selected_code()
        lm = self.document.case.landmarks["skull"].get(code) if code else None
        if lm is None or not lm.is_defined:
            return None
        return code, np.asarray(lm.position, float)

    def on_drag_start(self, _code: str) -> None:
        self.detail.begin()
        self._preview_fit = self._new_preview_fit()

    def on_drag(self, code: str, point: np.ndarray) -> None:
        self._schedule_drag(("landmark", (code, np.asarray(point, float))))

    def on_drag_end(self, code: str, point: np.ndarray | None) -> None:
        self._drag_pending, self._preview_fit = None, None
        self.detail.end(render=False)
        if point is None:
            self._redraw_after_drag()
            return
        if not self.document.push(
            MoveLandmark(surface="skull", code=code, position=point), merge=False
        ):
            self._redraw_after_drag()

    def cancel_drag(self) -> None:
        """Esc: end a landmark drag without moving anything."""
        if self.picker is not None and self.picker.dragging is not None:
            self.picker.finish_drag(cancel=True)
        if self.guide_view is not None:
            self.guide_view.cancel_drag()

    # ------------------------------------------------------------ guide drags
    def preview_guide(self, guide: Guide) -> None:
        """Show the face as if ``guide`` had this value (nothing stored yet)."""
        if self._preview_fit is None:
            self._preview_fit = self._new_preview_fit()
        self._schedule_drag(("guide", guide))

    def commit_guide(self, row: int, value: tuple[float, ...] | None) -> None:
        """The guide drag ended: store ``value`` (None: cancelled) as one undoable step."""
        self._drag_pending, self._preview_fit = None, None
        self.detail.end(render=False)
        if value is None:
            self._redraw_after_drag()
            return
        self.reconstruct_panel.set_guide(row, value=value)

    # ------------------------------------------------------------ preview
    def _new_preview_fit(self) -> PreviewFit | None:
        fit = self.session.fit
        if fit is None:
            return None
        try:
            return PreviewFit.from_fit(fit.recon, fit.head)
        except ValueError:
            return None

    def _schedule_drag(self, item: tuple[str, Any]) -> None:
        self._drag_pending = item
        if not self._drag_scheduled:
            self._drag_scheduled = True
            QTimer.singleShot(0, self._apply_drag)

    def _apply_drag(self) -> None:
        """Draw the newest dragged state (one per event-loop turn).

        Only the view being dragged in is redrawn: the 3D view for a
        landmark, the guide view for a guide (on a software renderer each
        view costs 50–80 ms a frame).  The other view follows with the full
        re-fit when the drag ends.
        """
        self._drag_scheduled = False
        item, self._drag_pending = self._drag_pending, None
        if item is None:
            return
        t0 = time.perf_counter()
        kind, value = item
        preview = self._preview_fit
        if kind == "landmark":
            code, point = value
            self._draw_landmarks({code: point})
            self._preview_dowel(code, point)
            if preview is not None and preview.move_landmark(code, point):
                skin = preview.skin()
                if self.scene.has("face"):
                    self.scene.update_points("face", skin)
                if self.scene.has("muscles") and self.scene.visible.get("muscles"):
                    self._preview_muscles(skin)
            self.plotter.update()  # one render, in the view's next paint (never two)
        elif self.guide_view is not None:
            self.guide_view.show_dragged(value)
            if preview is not None and preview.move_guide(value):
                self.guide_view.update_face(preview.skin_head())
        self.drag_timings.append(time.perf_counter() - t0)

    def _preview_muscles(self, skin: np.ndarray) -> None:
        """Carry the drawn muscles along with the previewed skin (input frame, mm).

        Each drawn muscle point is tied once per fit to the skin triangle
        nearest to it (barycentric weights; the grids lie 4 mm under the
        skin) and moves by that triangle's displacement.  The normal's turn
        is left out (sub-millimetre for a preview); the re-fit after the
        drag draws them exactly.  ~0.1 ms a frame, against ~20 ms for
        re-evaluating the grids.
        """
        fit = self.session.fit
        if fit is None:
            return
        binding = self._muscle_binding
        if binding is None or binding[0] is not fit:
            face = fit.recon.face
            drawn = self.scene.layer_points("muscles")
            near = MeshIndex(face).closest_points(drawn)
            binding = (fit, face.faces[near.face_ids], near.barycentric, drawn, face.vertices)
            self._muscle_binding = binding
        _, corners, weights, drawn, rest = binding
        moved = np.einsum("kj,kjc->kc", weights, skin[corners] - rest[corners])
        self.scene.move_layer_points("muscles", drawn + moved)

    def _preview_dowel(self, code: str, point: np.ndarray) -> None:
        p = self.session.preview
        if p is None or code not in p.codes:
            return
        i = p.codes.index(code)
        origins, tips = p.origins.copy(), p.tips.copy()
        tips[i] = point + (tips[i] - origins[i])
        origins[i] = point
        self.scene.show_dowels(origins, tips)

    def _redraw_after_drag(self) -> None:
        self._draw_landmarks(None)
        preview = self.session.preview
        if preview is not None:
            self.scene.show_dowels(preview.origins, preview.tips)
        self._draw_face()
        if self.guide_view is not None:
            self.guide_view.refresh()
        self.plotter.update()
