"""Dragging a landmark along the skull and a guide in the guide view, under Xvfb (xcb).

Real 100k-triangle skull (``skull.obj`` × 15 mm), real suggestion and fit.
Asserts on the case (one undo step per drag, the landmark stays on the
skull, the guide value stored), on the scene (the face follows during the
drag, before the full re-fit; the view does not rotate) and that Esc
cancels a drag.
"""

from __future__ import annotations

import os

import numpy as np
import pytest

pytest.importorskip("pytestqt")
if os.environ.get("QT_QPA_PLATFORM") != "xcb":
    pytest.skip(
        "the 3D view needs QT_QPA_PLATFORM=xcb under Xvfb (see HEADLESS.md)",
        allow_module_level=True,
    )

from PySide6.QtCore import QPoint, Qt

pytestmark = pytest.mark.gui


@pytest.fixture
def fitted(qtbot, new_window, skull_obj):
    w = new_window(1400, 900)
    w.open_skull(skull_obj, scale=15.0)
    qtbot.waitUntil(lambda: not w.busy, timeout=60_000)
    w.suggest_landmarks()
    qtbot.waitUntil(lambda: not w.busy, timeout=120_000)
    w.reconstruct()
    qtbot.waitUntil(lambda: not w.busy, timeout=120_000)
    assert w.fit is not None and not w.errors, w.errors
    return w


def _widget_pos(plotter, display_xy) -> QPoint:
    """VTK display pixels (origin bottom left) → Qt widget position (top left)."""
    ratio = plotter.devicePixelRatioF()
    height = plotter.render_window.GetSize()[1]
    return QPoint(int(round(display_xy[0] / ratio)), int(round((height - display_xy[1]) / ratio)))


def _drag(qtbot, plotter, start: QPoint, offsets) -> None:
    qtbot.mousePress(plotter, Qt.MouseButton.LeftButton, pos=start)
    for dx, dy in offsets:
        qtbot.mouseMove(plotter, start + QPoint(dx, dy))
        qtbot.wait(5)
    end = start + QPoint(*offsets[-1])
    qtbot.mouseRelease(plotter, Qt.MouseButton.LeftButton, pos=end)


def test_drag_a_landmark_along_the_skull_previews_the_face(qtbot, fitted):
    from workbench.core.spatial import MeshIndex

    w = fitted
    w.landmarks_panel.select("g")
    w.scene.render_now()
    before = w.document.case.landmarks["skull"]["g"]
    assert before.status == "suggested"
    camera = w.plotter.camera_position
    face_actor = w.scene.actors("face")[0]
    face_before = np.array(face_actor.GetMapper().GetInput().GetPoints().GetData())
    w.scene.set_visible("muscles", True)  # shown muscles follow the preview too
    muscle_actor = w.scene.actors("muscles")[0]
    muscles_before = np.array(muscle_actor.GetMapper().GetInput().GetPoints().GetData())
    start = _widget_pos(w.plotter, w.picker.display_position(before.position))
    n_steps = len(w.document.stack)
    seen: list[np.ndarray] = []
    seen_muscles: list[np.ndarray] = []
    w.scene.render_now()
    w.document.part_changed.connect(
        lambda _p: (
            seen.append(np.array(face_actor.GetMapper().GetInput().GetPoints().GetData())),
            seen_muscles.append(
                np.array(muscle_actor.GetMapper().GetInput().GetPoints().GetData())
            ),
        )
    )

    _drag(qtbot, w.plotter, start, [(0, -3 * k) for k in range(1, 9)])

    after = w.document.case.landmarks["skull"]["g"]
    assert after.status == "placed"
    assert np.linalg.norm(after.position - before.position) > 2.0
    skull = w.document.case.specimen.mesh
    assert MeshIndex(skull).closest_points(after.position[None]).distances[0] < 0.05
    assert w.plotter.camera_position == camera  # no rotation
    assert len(w.document.stack) == n_steps + 1
    assert w.document.stack.undo_text == "Move skull landmark g"
    assert w.drag_timings, "no preview was drawn during the drag"
    # the face followed during the drag, before the command (and the re-fit) ran
    assert seen and np.abs(seen[0] - face_before).max() > 0.5
    # (the actor drawn before the drag: moved in place, not re-created)
    assert seen_muscles and np.abs(seen_muscles[0] - muscles_before).max() > 0.2
    qtbot.waitUntil(lambda: not w.busy, timeout=120_000)
    assert not w.errors, w.errors

    w.undo()
    np.testing.assert_allclose(w.document.case.landmarks["skull"]["g"].position, before.position)


def test_escape_cancels_a_landmark_drag(qtbot, fitted):
    w = fitted
    w.landmarks_panel.select("n")
    w.scene.render_now()
    before = w.document.case.landmarks["skull"]["n"].position.copy()
    start = _widget_pos(w.plotter, w.picker.display_position(before))
    qtbot.mousePress(w.plotter, Qt.MouseButton.LeftButton, pos=start)
    qtbot.mouseMove(w.plotter, start + QPoint(0, -15))
    qtbot.wait(20)
    assert w.picker.dragging == "n"
    w.cancel_drag()
    qtbot.mouseRelease(w.plotter, Qt.MouseButton.LeftButton, pos=start + QPoint(0, -15))
    np.testing.assert_array_equal(w.document.case.landmarks["skull"]["n"].position, before)
    assert w.picker.dragging is None and not w.detail.active


def test_drag_a_guide_in_the_guide_view(qtbot, fitted):
    w = fitted
    gv = w.guide_view
    qtbot.waitUntil(lambda: not w.busy, timeout=30_000)
    gv.refresh(reset_camera=True)
    guides = w.reconstruct_panel.guides
    row = next(i for i, g in enumerate(guides) if g.kind == "hline" and g.enabled)
    g = guides[row]
    seg = gv._segment(g)
    mid = gv._display((seg[0] + seg[1]) / 2)
    assert gv.guide_at(*mid) == row
    start = _widget_pos(gv.plotter, mid)
    n_steps = len(w.document.stack)
    w.drag_timings.clear()

    _drag(qtbot, gv.plotter, start, [(0, -2 * k) for k in range(1, 8)])  # up on screen

    stored = w.document.case.guides.to_state()[row]
    assert stored["value"][0] > g.value[0] + 1.0  # moved up: y grows (head frame)
    assert stored["source"] == "user"
    assert len(w.document.stack) == n_steps + 1
    assert w.drag_timings
    qtbot.waitUntil(lambda: not w.busy, timeout=120_000)
    assert not w.errors, w.errors
    assert w.fit.recon.guide_targets, "the re-fit used the moved guide"
    code = g.affects[0]
    assert w.fit.recon.guide_targets[code][1] == pytest.approx(stored["value"][0])
