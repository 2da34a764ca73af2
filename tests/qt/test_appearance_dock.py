"""The Appearance dock (issue 34, colouring; Kähler 2003 §8.6.6), under Xvfb (xcb).

One window per module fits the real skull once (``skull.obj`` x 15 mm, the reference head's
suggested landmarks, the window's own fit).  The tests colour the face through the dock's
widgets, check the commands (one undo step per region's moves), the face layer's colours
(the drawn face's per-vertex array, mm-free), undo and redo, the case saved and reopened in
a new window (same colours, face coloured again) and File > Export's ``head/head.obj``.
A screenshot of the dock goes to ``/work/scratch/colour34/`` when that folder can be made.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pytestqt")
if os.environ.get("QT_QPA_PLATFORM") != "xcb":
    pytest.skip(
        "the 3D view needs QT_QPA_PLATFORM=xcb under Xvfb (see HEADLESS.md)",
        allow_module_level=True,
    )

from vtkmodules.util.numpy_support import vtk_to_numpy

from workbench.model.appearance import ARTISTIC_NOTE, Appearance
from workbench.qt.tools.appearance import VIEW_NOTE
from workbench.render.visuals.face import FACE_COLOURS, face_painted

pytestmark = pytest.mark.gui

SHOTS = Path(os.environ.get("WORKBENCH_COLOUR_SHOTS", "/work/scratch/colour34"))


@pytest.fixture(scope="module")
def window(qapp, skull_obj, skull_obj_suggested):
    """A window with a fitted face (real skull, real fit), the Appearance dock in front."""
    from PySide6.QtTest import QTest

    from workbench.commands.landmarks import ReplaceLandmarkSet
    from workbench.qt.main_window import MainWindow

    w = MainWindow(auto_update=False, interactive=False)
    w.resize(1400, 900)
    w.show()
    QTest.qWaitForWindowExposed(w)
    w.open_skull(skull_obj, scale=15.0)
    assert w.wait_idle(60)
    w.reconstruct_panel.auto_refit.setChecked(False)
    _, landmarks = skull_obj_suggested
    assert w.document.push(ReplaceLandmarkSet("skull", landmarks, "Suggest skull landmarks"))
    assert w.wait_idle(60)
    w.reconstruct()
    assert w.wait_idle(240)
    assert not w.errors, w.errors
    assert w.fit is not None
    w.docks["appearance"].raise_()
    yield w
    _close(w)


def _close(w) -> None:
    w.runner.shutdown()
    w.plotter.close()  # finalize VTK while the GL context exists
    w.close()


def _painted(window, qtbot) -> None:
    window.scene.request_render()
    qtbot.waitUntil(lambda: not window.scene.render_queued and not window.busy, timeout=20_000)


def _face_colours(window) -> np.ndarray | None:
    actor = window.scene.actors("face")[0]
    data = actor.GetMapper().GetInput().GetPointData().GetArray(FACE_COLOURS)
    if data is None or not face_painted(actor):
        return None
    return np.array(vtk_to_numpy(data))


def _shoot(window, qtbot, name: str) -> None:
    """The face alone, opaque, from the front, into :data:`SHOTS` (for a person to look at)."""
    for layer in ("skull", "landmarks", "dowels", "guides"):
        window.scene.set_visible(layer, False)
    window.scene.set_opacity("face", 1.0)
    window.docks["appearance"].raise_()
    window.reset_view()
    _painted(window, qtbot)
    try:
        SHOTS.mkdir(parents=True, exist_ok=True)
        window.save_screenshot(SHOTS / name)
    except OSError:
        pass


def _choose(combo, key: str) -> None:
    """Pick ``key`` in a combo as the user does (``activated``)."""
    index = combo.findData(key)
    combo.setCurrentIndex(index)
    combo.activated.emit(index)


def test_the_dock_says_the_colours_are_not_evidence(window) -> None:
    panel = window.appearance_panel
    assert ARTISTIC_NOTE in panel.note.text()
    assert "not evidence" in ARTISTIC_NOTE
    assert window.docks["appearance"].windowTitle() == "Appearance"
    assert not panel.shown.isChecked()  # the case keeps no colours yet
    assert window.document.case.appearance is None


def test_colour_undo_redo_and_the_face(window, qtbot) -> None:
    panel, tool, stack = window.appearance_panel, window.appearance, window.document.stack
    steps = len(stack)
    _choose(panel.tone, "mst3")
    case = window.document.case
    assert case.appearance == Appearance(tone="mst3")
    assert panel.shown.isChecked() and stack.undo_text == "Colour the face"
    _painted(window, qtbot)
    drawn = _face_colours(window)
    assert drawn is not None and np.array_equal(drawn, tool.colours())
    assert len(drawn) == window.fit.recon.face.n_vertices
    # the lips' value slider moved three times (keys): one undo step
    lips_v = panel.boxes["lips"].sliders["v"]
    for value in (40, 35, 30):
        lips_v.setValue(value)
    assert len(stack) == steps + 2
    assert case.appearance.colour("lips").v == pytest.approx(0.30)
    assert panel.boxes["lips"].follow.isEnabled()
    _painted(window, qtbot)
    lips = np.concatenate([window.fit.recon.head.regions[r] for r in ("upper_lip", "lower_lip")])
    assert np.all(_face_colours(window)[lips].max(axis=1) <= round(0.30 * 255) + 1)
    # a drag only previews; its release is one more step for the same region (merged)
    brows = panel.boxes["brows"].sliders["h"]
    brows.setSliderDown(True)
    brows.setValue(20)
    assert case.appearance.colour("brows") is None and tool.preview is not None
    brows.setSliderDown(False)  # sliderReleased: pushed
    assert tool.preview is None and case.appearance.colour("brows").h == pytest.approx(20 / 360)
    assert len(stack) == steps + 3
    # undo: the brows, then the lips (all three moves at once); the panel and face follow
    window.undo()
    assert case.appearance.colour("brows") is None
    window.undo()
    assert case.appearance == Appearance(tone="mst3")
    assert not panel.boxes["lips"].follow.isEnabled()
    rule = round(panel.boxes["lips"].hsv().v * 100)
    assert rule != 30 and lips_v.value() == rule
    _painted(window, qtbot)
    assert np.array_equal(_face_colours(window), tool.colours())
    window.redo()
    assert case.appearance.colour("lips").v == pytest.approx(0.30) and lips_v.value() == 30
    # the view says the colours are not evidence while it shows them
    assert tool.note.GetVisibility() and "not evidence" in VIEW_NOTE
    # "Colour the face" off: the face is plain (the case keeps its colours), no note
    panel.shown.setChecked(False)
    _painted(window, qtbot)
    assert _face_colours(window) is None and case.appearance is not None
    assert not tool.note.GetVisibility()
    panel.shown.setChecked(True)
    _painted(window, qtbot)
    assert _face_colours(window) is not None and tool.note.GetVisibility()
    # the face layer hidden: no note either
    window.scene.set_visible("face", False)
    _painted(window, qtbot)
    assert not tool.note.GetVisibility()
    window.scene.set_visible("face", True)
    _painted(window, qtbot)
    assert tool.note.GetVisibility()
    # audit: every step recorded with the note
    records = [r for r in case.audit.records if r["command"] == "SetAppearance"]
    assert records and all(r["parameters"]["note"] == ARTISTIC_NOTE for r in records)


def test_saved_and_reopened_in_a_new_window(window, qtbot, tmp_path) -> None:
    from workbench.qt.main_window import MainWindow

    panel, case = window.appearance_panel, window.document.case
    _choose(panel.iris, "green")
    panel.boxes["cheeks"].sliders["s"].setValue(70)
    want = case.appearance
    assert want is not None and want.iris == "green" and want.colour("cheeks") is not None
    path = tmp_path / "coloured.fcase"
    assert window.save_to(path)
    _painted(window, qtbot)
    try:
        SHOTS.mkdir(parents=True, exist_ok=True)
        window.save_screenshot(SHOTS / "appearance_dock.png")
    except OSError:
        pass

    other = MainWindow(auto_update=False, interactive=False)
    qtbot.addWidget(other, before_close_func=lambda w: (w.runner.shutdown(), w.plotter.close()))
    other.resize(1400, 900)
    other.show()
    qtbot.waitExposed(other)
    other.open_case(path)
    qtbot.waitUntil(lambda: other.fit is not None and not other.busy, timeout=60_000)
    assert not other.errors, other.errors
    assert other.document.case.appearance == want
    assert other.appearance_panel.shown.isChecked()
    assert other.appearance_panel.iris.currentData() == "green"
    assert other.appearance_panel.boxes["cheeks"].sliders["s"].value() == 70
    _painted(other, qtbot)
    drawn = _face_colours(other)
    assert drawn is not None and np.array_equal(drawn, other.appearance.colours())
    assert np.array_equal(drawn, window.appearance.colours())
    assert not other.document.stack.is_dirty
    _shoot(other, qtbot, "appearance_reopened_face.png")
    # "Remove colours" in the reopened case: one undo step, the face plain again
    other.appearance_panel.remove.click()
    assert other.document.case.appearance is None
    assert not other.appearance_panel.shown.isChecked()
    _painted(other, qtbot)
    assert _face_colours(other) is None
    other.undo()
    assert other.document.case.appearance == want and other.appearance_panel.shown.isChecked()
    _painted(other, qtbot)
    assert np.array_equal(_face_colours(other), drawn)


def test_export_writes_the_colours_into_the_head_obj(window, qtbot, tmp_path) -> None:
    from workbench.services.appearance import ATLAS_FILE

    assert window.document.case.appearance is not None
    out = tmp_path / "export"
    assert window.export_to(out)
    assert window.wait_idle(300) and not window.errors, window.errors
    mtl = (out / "head" / "head.mtl").read_text()
    assert f"map_Kd {ATLAS_FILE}" in mtl and "artistic choice" in mtl
    assert (out / "head" / ATLAS_FILE).is_file()
    iris = window.document.case.appearance.iris
    assert (out / "head" / f"eye_{iris}.png").is_file()
    from workbench.io.case_file import load_case

    assert load_case(out / "case.fcase").case.appearance == window.document.case.appearance


def test_a_hand_set_base_and_the_preset_again(window) -> None:
    panel, case = window.appearance_panel, window.document.case
    panel.boxes["skin"].sliders["h"].setValue(200)
    assert case.appearance.custom_base
    assert "set by hand" in panel.base_note.text()
    assert case.appearance.colour("skin").h == pytest.approx(200 / 360)
    _choose(panel.tone, "mst7")
    assert not case.appearance.custom_base and case.appearance.tone == "mst7"
    assert not panel.boxes["skin"].follow.isEnabled()
