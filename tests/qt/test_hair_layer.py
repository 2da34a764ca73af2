"""Hair, brows, beard and moustache in the window (issue 34), under Xvfb (xcb).

One window fits the real skull once (``skull.obj`` x 15 mm, the reference head's suggested
landmarks).  Styles picked in the Appearance dock are undoable case edits; the ``hair`` layer
draws them on the face as shown, follows the build slider, goes with undo, and the dock and
the layer's name say they are artistic additions.  A screenshot goes to
``/work/scratch/hair34/`` when that folder can be made.
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

from workbench.core.grooming import ARTISTIC_NOTE as GROOMING_NOTE
from workbench.qt.scene import LAYERS
from workbench.render.visuals.update import drawn_points, source_data

pytestmark = pytest.mark.gui

SHOTS = Path(os.environ.get("WORKBENCH_HAIR_SHOTS", "/work/scratch/hair34"))


@pytest.fixture(scope="module")
def window(qapp, skull_obj, skull_obj_suggested):
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
    w.docks["appearance"].raise_()
    yield w
    w.runner.shutdown()
    w.plotter.close()
    w.close()


def _choose(combo, key: str) -> None:
    index = combo.findData(key)
    assert index >= 0, key
    combo.setCurrentIndex(index)
    combo.activated.emit(index)


def _settled(window, qtbot) -> None:
    """Renders until the hair layer is drawn for what is shown (worker and timer done)."""

    def done() -> bool:
        window.scene.request_render()
        tool = window.appearance
        return (
            not window.busy
            and not tool._hair_timer.isActive()
            and tool._hair_wanted() == tool._hair_key
        )

    qtbot.waitUntil(done, timeout=60_000)


def _hair_points(window) -> np.ndarray:
    return np.vstack([drawn_points(source_data(a)) for a in window.scene.actors("hair")])


def test_styles_are_case_edits_drawn_on_the_face(window, qtbot) -> None:
    panel, case, stack = window.appearance_panel, window.document.case, window.document.stack
    assert GROOMING_NOTE in panel.findChild(type(panel.note), "grooming_note").text()
    assert "artistic" in LAYERS["hair"]
    steps = len(stack)
    _choose(panel.styles["hair"], "short")
    _choose(panel.styles["brows"], "soft_arch")
    _choose(panel.styles["beard"], "short")
    assert len(stack) == steps + 3
    assert dict(case.appearance.grooming) == {
        "hair": "short",
        "brows": "soft_arch",
        "beard": "short",
    }
    _settled(window, qtbot)
    assert len(window.scene.actors("hair")) == 3
    hair = _hair_points(window)
    face = window.fit.recon.face
    # on the head: every hair point within 40 mm of the drawn skin, most within 10 mm
    from scipy.spatial import cKDTree

    d, _ = cKDTree(face.vertices).query(hair)
    assert d.max() < 40.0 and np.median(d) < 10.0
    try:
        SHOTS.mkdir(parents=True, exist_ok=True)
        for layer in ("skull", "landmarks", "dowels", "guides"):
            window.scene.set_visible(layer, False)
        window.scene.set_opacity("face", 1.0)
        window.reset_view()
        _settled(window, qtbot)
        window.save_screenshot(SHOTS / "hair_in_window.png")
    except OSError:
        pass
    # the build slider moves the face: the hair follows it (rebuilt once it rests)
    builds = window.fit.builds
    assert builds is not None
    before = _hair_points(window)
    window.show_build(builds.main_z + 2.0)
    _settled(window, qtbot)
    after = _hair_points(window)
    assert after.shape == before.shape and not np.allclose(after, before)
    # undo the three choices: no hair drawn
    for _ in range(3):
        window.undo()
    assert case.appearance is None or not case.appearance.grooming
    _settled(window, qtbot)
    assert not window.scene.actors("hair")
    window.redo()
    _settled(window, qtbot)
    assert len(window.scene.actors("hair")) == 1


def test_the_age_dock_shows_the_hair_on_both_heads(window, qtbot) -> None:
    """The case's hair on the source and the aged reconstruction: the same strands, tied to
    the skin, so the aged head's hair sits on its own (smaller) head."""
    _choose(window.appearance_panel.styles["hair"], "short")
    window.show_age(to_age=8, reconstructed=True)
    qtbot.waitUntil(lambda: window.age.shown_age == 8, timeout=300_000)

    def drawn() -> bool:
        keys = window.age.actors()
        return any(k.startswith("after_hair_") for k in keys) and any(
            k.startswith("before_hair_") for k in keys
        )

    qtbot.waitUntil(drawn, timeout=60_000)
    actors = window.age.actors()
    before = drawn_points(source_data(actors["before_hair_hair"]))
    after = drawn_points(source_data(actors["after_hair_hair"]))
    assert before.shape == after.shape
    # an 8-year-old's head is smaller: the aged hair spans less than the adult's
    assert np.ptp(after[:, 1]) < np.ptp(before[:, 1])
    assert window.age.actors()["after_hair_hair"].GetVisibility()
    try:
        SHOTS.mkdir(parents=True, exist_ok=True)
        window.scene.request_render()
        qtbot.waitUntil(lambda: not window.scene.render_queued, timeout=20_000)
        window.save_screenshot(SHOTS / "hair_in_age_dock.png")
    except OSError:
        pass


def test_the_animate_dock_moves_the_hair_with_the_face(window, qtbot) -> None:
    """The case's reconstruction animated: its beard and brows are drawn and move with the
    skin (an open jaw carries the beard down), the scalp hair stays on the skull."""
    from workbench.qt.panels.animate_panel import RECONSTRUCTION

    panel = window.appearance_panel
    _choose(panel.styles["hair"], "short")
    _choose(panel.styles["beard"], "short")
    window.animate_panel.head.setCurrentText(RECONSTRUCTION)
    window.show_animate()
    qtbot.waitUntil(lambda: window.animate.sex == "reconstruction", timeout=120_000)
    qtbot.waitUntil(
        lambda: "hair_beard" in window.animate.actors() and not window.busy, timeout=60_000
    )
    tool = window.animate

    def points(kind: str) -> np.ndarray:
        return drawn_points(source_data(tool.actors()[f"hair_{kind}"]))

    beard, hair = points("beard"), points("hair")
    tool.set_jaw(15.0)
    qtbot.waitUntil(lambda: not tool.running, timeout=60_000)
    moved_beard = np.linalg.norm(points("beard") - beard, axis=1)
    moved_hair = np.linalg.norm(points("hair") - hair, axis=1)
    assert np.quantile(moved_beard, 0.9) > 3.0  # the chin went down with the jaw
    assert np.median(moved_hair) < 0.5
    assert tool.actors()["hair_beard"].GetVisibility()
    try:
        SHOTS.mkdir(parents=True, exist_ok=True)
        window.save_screenshot(SHOTS / "hair_in_animate_dock.png")
    except OSError:
        pass
    window.docks["appearance"].raise_()
    qtbot.waitUntil(lambda: not tool.actors()["hair_beard"].GetVisibility(), timeout=10_000)


def test_export_report_shows_the_portraits_and_says_not_evidence(window, qtbot, tmp_path) -> None:
    """File > Export of a case with hair: the report's appearance section (schema-valid
    report.json, the PDF's section) with portraits in the case's appearance, and head.obj
    with the pieces as objects of their own."""
    import json

    import pypdf

    _choose(window.appearance_panel.styles["hair"], "short")
    _choose(window.appearance_panel.styles["brows"], "thick")
    out = tmp_path / "export"
    assert window.export_to(out)
    assert window.wait_idle(300) and not window.errors, window.errors
    report = json.loads((out / "report.json").read_text(encoding="utf-8"))
    section = report["appearance"]
    assert "not evidence" in section["note"]
    assert section["artistic_additions"]["hair_and_brows"]["hair"] == "short"
    for view in ("front", "three_quarter", "profile"):
        assert (out / report["pictures"][f"portrait_{view}"]).is_file()
    text = "\n".join(p.extract_text() for p in pypdf.PdfReader(str(out / "report.pdf")).pages)
    assert "Appearance: an artistic presentation" in text and "hair short" in text
    obj = (out / "head" / "head.obj").read_text(encoding="utf-8")
    assert "\no hair\n" in obj and "\no brows\n" in obj
