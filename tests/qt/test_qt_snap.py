"""The Snap button of the skull-landmarks dock, under Xvfb (xcb).

Real 100k-triangle skull (``skull.obj`` × 15 mm) with the session's suggested
landmarks pushed as one command (no suggestion run in the window, so the test
stays quick).  Needs ``MainWindow.snap_selected`` and the connection of the
panel's ``snap_requested`` signal to it.
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

from PySide6.QtCore import Qt

pytestmark = pytest.mark.gui


def test_snap_button_moves_the_selected_landmark_as_one_undo_step(
    qtbot, window, skull_obj, skull_obj_suggested
):
    from workbench.commands.landmarks import ReplaceLandmarkSet
    from workbench.core.spatial import MeshIndex

    window.open_skull(skull_obj, scale=15.0)
    qtbot.waitUntil(lambda: not window.busy, timeout=30_000)
    assert window.document.has_specimen and not window.errors, window.errors
    _, landmarks = skull_obj_suggested  # suggested on the same file × 15: same frame
    assert window.document.push(ReplaceLandmarkSet("skull", landmarks, "Suggest skull landmarks"))
    qtbot.waitUntil(lambda: not window.busy, timeout=60_000)

    panel = window.landmarks_panel
    panel.select("g")
    before = window.document.case.landmarks["skull"]["g"].position.copy()
    assert "(S)" in panel.snap_button.toolTip()
    assert window.actions_by_id["snap"].shortcut().toString() == "S"
    with qtbot.waitSignal(panel.snap_requested, timeout=1_000) as emitted:
        qtbot.mouseClick(panel.snap_button, Qt.MouseButton.LeftButton)
    assert emitted.args == ["g"]

    after = window.document.case.landmarks["skull"]["g"]
    assert np.linalg.norm(after.position - before) > 0.5 and after.status == "placed"
    skull = window.document.case.specimen.mesh
    assert MeshIndex(skull).closest_points(after.position[None]).distances[0] < 1e-6
    assert "g → most anterior midline point" in window.status_label.text()
    assert window.actions_by_id["undo"].text() == "&Undo Snap g to most anterior midline point"
    assert not window.errors, window.errors

    window.undo()
    np.testing.assert_allclose(window.document.case.landmarks["skull"]["g"].position, before)

    # without a selection the action only explains itself
    panel.table.clearSelection()
    window.snap_selected()
    np.testing.assert_allclose(window.document.case.landmarks["skull"]["g"].position, before)
