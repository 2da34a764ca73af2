"""The Fit scan tool of the window (issue 13) under Xvfb: open a damaged scan, fit, assist, save.

The scan is a female reference skin with two holes (``tests/services/_scans.py``),
moved into an arbitrary scanner frame, fitted with the male reference (mm).
"""

from __future__ import annotations

import json
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

from tests.services._scans import damaged_skin
from workbench.core.landmarks import LandmarkSet
from workbench.io.meshes import write_mesh

pytestmark = pytest.mark.gui
FIT_MS = 180_000


@pytest.fixture(scope="module")
def scan_case(head_male, head_female, tmp_path_factory):
    """The damaged scan as a PLY file (scanner frame, mm) and its true skin landmarks."""
    scan, lms = damaged_skin(head_female)
    path = write_mesh(tmp_path_factory.mktemp("scan") / "face_scan.ply", scan)
    return path, lms


def _wait(qtbot, window, timeout=FIT_MS) -> None:
    qtbot.waitUntil(lambda: not window.busy, timeout=timeout)
    assert not window.errors, window.errors


def _open(qtbot, window, path) -> None:
    window.open_scan(path)
    _wait(qtbot, window, 60_000)
    assert window.scan_fit.has_scan


def test_open_fit_place_undo_and_fit_again_with_seeds(qtbot, window, scan_case):
    from workbench.qt.tools.scan_fit.tool import DISTANCE_TITLE

    path, truth = scan_case
    tool, panel = window.scan_fit, window.scan_fit_panel
    _open(qtbot, window, path)
    assert len(tool.actors("scan")) == 1 and not tool.actors("skin")
    assert "face_scan.ply" in panel.file_label.text()
    assert panel.table.rowCount() == len(tool.scan.codes) > 50
    assert panel.fit_button.isEnabled()

    window.fit_scan()
    qtbot.waitUntil(lambda: panel.cancel_button.isEnabled() or not window.busy, timeout=5000)
    _wait(qtbot, window)
    view = tool.view
    assert view is not None
    fig = view.fit.figures
    assert fig["face_within_1mm_fraction"] > 0.9
    # layers: the scan coloured by distance (NaN where not counted), the skin, the landmarks
    scan_actor = tool.actors("scan")[0]
    values = np.asarray(scan_actor.GetMapper().GetInput().point_data[DISTANCE_TITLE])
    assert np.isnan(values).any() and np.nanmax(values) < 10.0
    assert DISTANCE_TITLE in window.plotter.scalar_bars
    assert len(tool.actors("skin")) == 2  # over no scan / on the scan (hidden under the scan)
    assert tool.actors("skin")[0].GetVisibility() and not tool.actors("skin")[1].GetVisibility()
    panel.layer_checks["scan"].setChecked(False)  # no scan: the whole fitted skin
    assert tool.actors("skin")[1].GetVisibility() and not scan_actor.GetVisibility()
    assert not window.plotter.scalar_bars[DISTANCE_TITLE].GetVisibility()  # nor its key
    # the fine detail instead of the animatable skin: 16 fine triangles per skin triangle
    coarse_tris = sum(a.GetMapper().GetInput().n_cells for a in tool.actors("skin"))
    camera = window.plotter.renderer.GetActiveCamera().GetPosition()
    panel.detail_check.setChecked(True)
    assert window.plotter.renderer.GetActiveCamera().GetPosition() == camera  # view kept
    assert len(tool.actors("skin")) == 2 and tool.actors("skin")[1].GetVisibility()
    fine_tris = sum(a.GetMapper().GetInput().n_cells for a in tool.actors("skin"))
    assert fine_tris == 16 * coarse_tris == 16 * view.fit.head.skin.n_faces
    assert "Fine detail" in panel.figures.text()
    panel.detail_check.setChecked(False)
    assert sum(a.GetMapper().GetInput().n_cells for a in tool.actors("skin")) == coarse_tris
    panel.layer_checks["scan"].setChecked(True)
    assert window.plotter.scalar_bars[DISTANCE_TITLE].GetVisibility()
    states = tool.landmark_states()
    assert states["chk_l"] == "over hole"  # the landmark at a hole of the scan
    assert list(states.values()).count("guess") > 40
    assert len(tool.actors("landmarks")) >= 2  # first guess + over holes
    # the guess lies on the scan where the scan has skin
    np.testing.assert_allclose(view.guess["prn"], truth["prn"].position, atol=3.0)
    # figures in the panel
    text = panel.figures.text()
    assert "Face within 1 mm" in text and "%" in text and "Fold-overs" in text
    assert panel.fit_button.text() == "Fit again"

    # place a landmark by clicking the scan (placing mode, code chosen in the list)
    window.docks["fit_scan"].raise_()
    panel.place_check.setChecked(True)
    assert tool.picker.enabled and not window.picker.enabled
    panel.select_code("n")
    window.scene.render_now()
    width, height = window.plotter.render_window.GetSize()
    ratio = window.plotter.devicePixelRatioF()
    expected = tool.picker.pick(width // 2, height // 2)
    assert expected is not None, "the view centre should show the scan"
    centre = QPoint(int(width / 2 / ratio), int(height / 2 / ratio))
    qtbot.mouseClick(window.plotter, Qt.MouseButton.LeftButton, pos=centre)
    placed = tool.landmarks.placed
    assert placed["n"].status == "placed"
    np.testing.assert_allclose(placed["n"].position, expected, atol=1.0)
    assert tool.landmark_states()["n"] == "placed"
    assert panel.selected_code() != "n"  # the next code to place is selected
    # Edit → Undo: the placement is a step of the window's one undo stack
    undo = window.actions_by_id["undo"]
    assert undo.isEnabled() and "Place n (scan fit)" in undo.text()
    assert window.document.stack.undo_text == "Place n (scan fit)"
    undo.trigger()
    assert "n" not in tool.landmarks.placed
    assert tool.landmark_states()["n"] in ("guess", "over hole")  # the guess again
    window.redo()
    assert "n" in tool.landmarks.placed
    panel.undo_button.click()
    assert "n" not in tool.landmarks.placed

    # accept guesses (one undo step), place three from the true landmarks, fit again
    panel.select_code("prn")
    panel.accept_button.click()
    assert tool.landmarks.placed["prn"].status == "placed"
    for code in ("po_l", "po_r", "or_l", "ch_l"):
        tool.place(code, truth[code].position)
    assert len(tool.landmarks.placed) == 5
    assert "5 placed" in panel.seed_label.text()
    tool.accept_all()
    n_all = len(tool.landmarks.placed)
    assert n_all > 40 and "chk_l" not in tool.landmarks.placed  # not over holes
    window.undo()
    assert len(tool.landmarks.placed) == 5
    panel.place_check.setChecked(False)
    assert window.picker.enabled and not tool.picker.enabled

    window.fit_scan()
    _wait(qtbot, window)
    again = tool.view
    assert again is not view and again.seeds == 5
    assert again.fit.figures["orientation"]["method"] == "seeds"
    assert again.fit.figures["skin_landmark_to_user_mm"]["mean"] < 3.0
    assert "5 placed landmarks given" in panel.figures.text()
    assert tool.landmark_states()["po_l"] == "placed"  # the placements survive a fit


def test_save_pack_writes_the_folder_and_refuses_an_existing_one(
    qtbot, window, scan_case, tmp_path
):
    from workbench.qt.tools.scan_fit.work import PLACED_FILE

    path, truth = scan_case
    tool = window.scan_fit
    _open(qtbot, window, path)
    for code in ("po_l", "po_r", "or_l", "prn", "n"):
        tool.place(code, truth[code].position)
    out = tmp_path / "pack"
    assert tool.save_to(out)
    _wait(qtbot, window)
    names = {p.name for p in tool.saved}
    assert {"skin.ply", "skull.ply", "skin.mrk.json", "fit_report.json", PLACED_FILE} <= names
    assert "fit_report.pdf" in names  # the report `workbench fit-scan` writes, pictures too
    assert all(p.parent in (out, out / "pictures") for p in tool.saved)
    report = json.loads((out / "fit_report.json").read_text())
    assert report["scan"] == "face_scan.ply" and report["orientation"]["method"] == "seeds"
    assert report["skin_landmark_to_user_mm"]["mean"] < 3.0
    assert tool.view is not None  # the saved fit is shown

    # again into the same folder: refused without a confirmation (no job started)
    before = (out / "fit_report.json").stat().st_mtime_ns
    assert not tool.save_to(out)
    assert not window.busy
    assert window.errors and "refusing to replace" in window.errors[-1]
    assert (out / "fit_report.json").stat().st_mtime_ns == before
    window.errors.clear()
    # the user confirms: replaced (the service's force)
    tool._may_replace = lambda _folder: True
    assert tool.save_to(out)
    _wait(qtbot, window)
    assert (out / "fit_report.json").stat().st_mtime_ns != before


def test_bad_scans_give_a_readable_message(qtbot, window, tmp_path):
    from workbench.core.mesh import Mesh

    few = write_mesh(
        tmp_path / "few.ply",
        Mesh(np.array([[0, 0, 0], [100, 0, 0], [0, 100, 0.0]]), np.array([[0, 1, 2]])),
    )
    window.open_scan(few)
    qtbot.waitUntil(lambda: not window.busy, timeout=60_000)
    assert window.errors and "few.ply" in window.errors[-1]
    assert "triangles" in window.errors[-1] and "Traceback" not in window.errors[-1]
    assert not window.scan_fit.has_scan and not window.scan_fit.actors("scan")
    window.fit_scan()  # nothing open: a status line, no job
    assert not window.busy and "Open a scan" in window.status_text()


def test_scan_landmark_edits_are_steps_of_the_case_stack() -> None:
    """Placements are commands on the case's one stack: undone in order with the case's
    edits, audited, the case's parts untouched; a new scan leaves old steps inert."""
    from workbench.commands.stack import CommandStack
    from workbench.model.case import Case
    from workbench.qt.tools.scan_fit.state import ScanLandmarks

    case = Case()
    stack = CommandStack(case)
    redrawn = []
    lms = ScanLandmarks(on_change=lambda: redrawn.append(len(lms.placed)))
    lms.clear("face_scan.ply")
    before = case.landmarks
    edit = lms.place("n", np.zeros(3))
    assert edit is not None and edit.label == "Place n (scan fit)"
    stack.push(edit)
    assert stack.undo_text == "Place n (scan fit)" and redrawn == [1]
    edit = lms.place("n", np.ones(3))
    assert edit is not None and edit.label == "Move n (scan fit)"
    stack.push(edit)
    assert lms.place("n", np.ones(3)) is None  # no change, no step
    many = lms.place_many({"prn": np.ones(3), "pg": np.zeros(3)}, "Accept 2")
    assert many is not None and many.codes == ["pg", "prn"]
    stack.push(many)
    stack.push(lms.remove("pg"))
    assert lms.remove("pg") is None
    stack.undo()
    assert "pg" in lms.placed
    stack.undo()
    assert "prn" not in lms.placed
    stack.undo()
    assert np.allclose(lms.placed["n"].position, 0.0)
    stack.redo()
    assert np.allclose(lms.placed["n"].position, 1.0)
    stack.push(lms.place("g", np.zeros(3)))
    assert not stack.can_redo  # a new change drops the redo list
    # audited on the case's log, the case's own parts unchanged
    records = case.audit.records
    assert records[0]["operation"] == "Place n (scan fit)"
    assert records[0]["parameters"]["scan"] == "face_scan.ply"
    assert case.landmarks is before
    # another scan: no placements, and the previous scan's steps no longer act
    lms.clear("other.ply")
    assert not len(lms.placed) and isinstance(lms.placed, LandmarkSet)
    stack.undo()
    assert not len(lms.placed)


def test_gui_options_for_the_fit_scan_tool(tmp_path, scan_case) -> None:
    import argparse

    from workbench.cli import gui_cmd
    from workbench.core.errors import InputError

    parser = argparse.ArgumentParser()
    gui_cmd.add_arguments(parser)
    path, _ = scan_case
    args = parser.parse_args(
        ["--scan", str(path), "--units", "mm", "--tool", "fit-scan", "--fit-scan"]
    )
    options = gui_cmd.options_from(args)
    assert options.scan == path and options.fit_scan and options.tool == "fit-scan"
    assert options.units == "mm" and options.skull is None
    with pytest.raises(InputError, match="--fit-scan"):
        gui_cmd.options_from(parser.parse_args(["--fit-scan"]))


def test_tool_actions_are_in_the_menus(window) -> None:
    from workbench.qt.actions import SCAN_FIT_ACTIONS

    for spec in SCAN_FIT_ACTIONS:
        assert callable(getattr(window.scan_fit, spec.method))
        assert spec.id in window.actions_by_id
    file_menu = window.menuBar().actions()[0].menu()
    titles = [a.text() for a in file_menu.actions()]
    assert titles.index("Open face sca&n…") == titles.index("Open c&ase…") + 1


def test_save_pack_asks_for_a_folder_in_the_case_folder_not_beside_the_scan(
    qtbot, window, scan_case, tmp_path, monkeypatch
):
    """The dialog opens in the case file's folder (else home), never in the evidence's."""
    from pathlib import Path

    from workbench.qt import dialogs

    path, _truth = scan_case
    _open(qtbot, window, path)
    asked: list[Path] = []
    monkeypatch.setattr(dialogs, "ask_new_folder", lambda _p, _t, s: asked.append(s) or "")
    window.scan_fit.ask_save()
    assert asked == [Path.home() / f"{Path(path).stem}_fit"]
    assert window.save_to(tmp_path / "case.fcase")
    window.scan_fit.ask_save()
    assert asked[-1] == tmp_path / f"{Path(path).stem}_fit"


def test_save_pack_writes_the_fit_shown_without_fitting_again(
    qtbot, window, scan_case, tmp_path, monkeypatch
):
    """Save pack after Fit writes that fit (the same files the command line writes for
    the same scan and landmarks), and fits again only when the landmarks changed since."""
    from workbench.pipelines.scan_fit import fit_scan_to_folder
    from workbench.services.scan_fit import pack

    path, truth = scan_case
    tool = window.scan_fit
    _open(qtbot, window, path)
    for code in ("po_l", "po_r", "or_l", "prn", "n"):
        tool.place(code, truth[code].position)
    window.fit_scan()
    _wait(qtbot, window)
    fits: list[int] = []
    real = pack.fit_scan
    monkeypatch.setattr(pack, "fit_scan", lambda *a, **k: (fits.append(1), real(*a, **k))[1])
    assert tool.save_to(tmp_path / "pack")
    _wait(qtbot, window)
    assert not fits  # the fit shown was written
    monkeypatch.setattr(pack, "fit_scan", real)
    cli = tmp_path / "cli"
    fit_scan_to_folder(path, cli, landmarks=tool.landmarks.placed, report=False)
    for name in ("skin.ply", "skull.ply", "skin.mrk.json"):
        assert (tmp_path / "pack" / name).read_bytes() == (cli / name).read_bytes(), name
    # a landmark moved after the fit: the pack is of the landmarks placed now
    monkeypatch.setattr(pack, "fit_scan", lambda *a, **k: (fits.append(1), real(*a, **k))[1])
    tool.place("prn", truth["prn"].position + np.array([0.0, 0.0, 1.0]))
    assert tool.save_to(tmp_path / "pack2")
    _wait(qtbot, window)
    assert fits == [1]
