"""The "Open CT" dialog under Xvfb (QT_QPA_PLATFORM=xcb): live bone preview, cancel, extract.

Run with ``QT_QPA_PLATFORM=xcb python -m pytest --xvfb-backend xvfb tests/qt``.
Real data: the VTK headsq CT (raw CT numbers, bone preset 1150; mm, LPS).
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

from workbench.qt.scene import is_closed

pytestmark = pytest.mark.gui
WAIT_MS = 30_000


@pytest.fixture
def dialog(qtbot, window, headsq_nhdr):
    d = window.open_ct_dialog(headsq_nhdr)
    qtbot.waitExposed(d)
    yield d
    d.close()  # cancels its jobs and closes its plotter
    assert is_closed(d.plotter)


def _wait_preview(qtbot, dialog, after: int = 0, iso: float | None = None) -> None:
    qtbot.waitUntil(
        lambda: (
            dialog.previews_shown > after
            and not dialog.runner.busy
            and (iso is None or dialog.shown.iso == iso)
        ),
        timeout=WAIT_MS,
    )
    assert not dialog.window_.errors, dialog.window_.errors


def _bone_pixels(dialog) -> int:
    """Pixels of the 3D view that are bone-coloured (warm; the background is blue-grey)."""
    image = np.asarray(dialog.plotter.screenshot(return_img=True), dtype=int)
    r, b = image[..., 0], image[..., 2]
    return int(np.count_nonzero((r > 90) & (r > b + 15)))


def test_the_dialog_shows_the_bone_preview_and_its_figures(qtbot, dialog):
    _wait_preview(qtbot, dialog)
    assert dialog.state == "preview"
    assert dialog.iso == 1150.0 and dialog.slider.value() == 1150
    assert "bone" in dialog.tissue_label.text() and "preset" in dialog.tissue_label.text()
    names = set(dialog.plotter.renderer.actors)
    assert {"ct_preview", "ct_debris"} <= names
    assert dialog.shown.mesh.n_faces == 75_756  # full resolution: headsq is small
    figures = {k: label.text() for k, label in dialog.figures.items()}
    assert figures["iso"] == "1150"
    assert figures["above"].startswith("34,295 (9.00 %")
    assert "75,756 triangles" in figures["triangles"]
    assert "64 × 64 × 93 voxels" in figures["volume"]
    assert figures["spacing"] == "3.2 × 3.2 × 1.5 mm"
    assert "not HU" in figures["values"] and figures["grid"] == "full resolution"
    assert dialog.extract_button.isEnabled() and not dialog.progress.isVisible()
    assert _bone_pixels(dialog) > 5000


def test_moving_the_slider_recomputes_the_preview(qtbot, dialog):
    _wait_preview(qtbot, dialog)
    first = dialog.shown
    shown = dialog.previews_shown
    for value in (1200, 1300, 1400, 1600):  # a drag: older previews are superseded
        dialog.slider.setValue(value)
    assert dialog.spin.value() == 1600.0
    _wait_preview(qtbot, dialog, shown, iso=1600.0)
    assert dialog.shown.mesh.n_faces != first.mesh.n_faces
    assert dialog.figures["iso"].text() == "1600"
    assert "custom level" in dialog.tissue_label.text()
    assert dialog.shown.summary.voxels_above < first.summary.voxels_above
    shown = dialog.previews_shown
    qtbot.mouseClick(dialog.skin_button, Qt.MouseButton.LeftButton)
    _wait_preview(qtbot, dialog, shown, iso=500.0)
    assert dialog.slider.value() == 500 and "skin" in dialog.tissue_label.text()


def test_cancelling_the_extraction_leaves_the_case_unchanged(qtbot, window, dialog):
    _wait_preview(qtbot, dialog)
    case = window.document.case
    qtbot.mouseClick(dialog.extract_button, Qt.MouseButton.LeftButton)
    assert dialog.state == "extracting" and window.runner.is_running("open")
    token = window.runner.token("open")
    assert not dialog.slider.isEnabled() and dialog.cancel_button.isEnabled()
    qtbot.mouseClick(dialog.cancel_button, Qt.MouseButton.LeftButton)
    assert token.cancelled
    assert dialog.state == "preview" and dialog.isVisible()
    assert not window.runner.is_running("open")
    assert "cancelled" in dialog.status_label.text()
    qtbot.wait(1500)  # longer than the whole extraction
    assert window.document.case is case and not window.document.has_specimen
    assert not window.errors
    assert dialog.extract_button.isEnabled()


def test_extract_starts_a_case_with_the_bone_surface(qtbot, window, dialog, headsq_surfaces):
    _wait_preview(qtbot, dialog)
    progress: list[tuple[str, float, int, int]] = []  # after the window's own slot:
    window.runner.progress_changed.connect(  # what its status bar showed
        lambda channel, _step, f: progress.append(
            (channel, f, window.progress.maximum(), window.progress.value())
        )
    )
    qtbot.mouseClick(dialog.extract_button, Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: dialog.state == "done" and not window.runner.busy, timeout=WAIT_MS)
    assert not window.errors, window.errors
    assert not dialog.isVisible() and is_closed(dialog.plotter)
    mesh = window.document.case.specimen.mesh
    bone = headsq_surfaces["bone"]
    assert mesh.n_faces == bone.n_faces
    # the CT's LPS surface, read as RAS (x and y negated) like a mesh-from-ct file, so the
    # case's landmark files and report (RAS) lie on the CT in 3D Slicer
    np.testing.assert_allclose(mesh.vertices, bone.vertices * [-1.0, -1.0, 1.0], atol=1e-4)
    assert any("bone surface" in note and "iso 1150" in note for note in window.document.notes)
    shown = [(f, top, value) for channel, f, top, value in progress if channel == "open"]
    fractions = [f for f, _, _ in shown]
    assert len(fractions) > 3 and fractions == sorted(fractions) and fractions[-1] == 1.0
    assert all(top == 1000 and value == round(1000 * f) for f, top, value in shown)


def test_cancel_closes_the_dialog_while_previewing(qtbot, window, dialog):
    _wait_preview(qtbot, dialog)
    qtbot.mouseClick(dialog.cancel_button, Qt.MouseButton.LeftButton)
    assert dialog.state == "closed" and not dialog.isVisible() and is_closed(dialog.plotter)
    assert not window.runner.busy and not window.errors


def test_cancel_while_loading_drops_the_volume(qtbot, window, headsq_nhdr):
    d = window.open_ct_dialog(headsq_nhdr)
    assert d.state == "loading" and window.runner.is_running("ct-load")
    d.cancel()
    assert d.state == "closed" and not window.runner.busy and is_closed(d.plotter)
    qtbot.wait(300)
    assert d.ct is None and d.previews_shown == 0 and not window.errors


def test_an_unreadable_file_is_reported_without_traceback(qtbot, window, tmp_path):
    bad = tmp_path / "broken.nrrd"
    bad.write_bytes(b"NRRD0004\ntype: short\ndimension: 3\nsizes: 4 4\n\n" + b"\0" * 10)
    d = window.open_ct_dialog(bad)
    qtbot.waitUntil(lambda: d.state == "closed", timeout=WAIT_MS)
    assert len(window.errors) == 1
    assert window.errors[0].startswith("Could not read the CT broken.nrrd")
    assert "Traceback" not in window.errors[0] and is_closed(d.plotter)


def test_non_interactive_open_ct_uses_the_same_path(qtbot, window, headsq_nhdr, headsq_surfaces):
    assert window.open_ct(headsq_nhdr, iso=1150.0)
    qtbot.waitUntil(lambda: not window.runner.busy, timeout=WAIT_MS)
    assert not window.errors, window.errors
    assert window.document.case.specimen.mesh.n_faces == headsq_surfaces["bone"].n_faces


def test_another_open_in_the_window_stops_the_extraction(qtbot, window, dialog, headsq_nhdr):
    _wait_preview(qtbot, dialog)
    dialog.set_iso(1300.0)
    _wait_preview(qtbot, dialog, dialog.previews_shown, iso=1300.0)
    dialog.extract()
    token = window.runner.token("open")
    assert window.open_ct(headsq_nhdr)  # supersedes the dialog's extraction
    assert token.cancelled and dialog.state == "preview" and "stopped" in dialog.status_label.text()
    qtbot.waitUntil(lambda: not window.runner.is_running("open"), timeout=WAIT_MS)
    assert not window.errors, window.errors
    assert any("iso 1150" in note for note in window.document.notes)  # the window's own open
    dialog.cancel()  # closes; the new case stays
    assert window.document.has_specimen
