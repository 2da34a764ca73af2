"""The Age progression dock: the age service under a target-age slider, its table, export."""

from __future__ import annotations

import argparse
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

#: generous: one age step is ~1-2 s alone, several times that on a busy machine
STEP_MS = 180_000


@pytest.fixture
def ageing(head_male, new_window, qtbot):
    """A window with the reference male head (18 y) aged to 10 y and shown.

    ``head_male`` builds the reference head into the session's cache first (the
    worker then reads it instead of building it at low priority).
    """
    w = new_window(1200, 800)
    w.age.prefetch_years = 0
    w.show_age(10, 18, "male")
    qtbot.waitUntil(lambda: w.age.shown_age == 10, timeout=STEP_MS)
    return w


def _height(points: np.ndarray) -> float:
    return float(np.ptp(points[:, 1]))


def test_the_slider_computes_and_shows_a_head(ageing, qtbot):
    w = ageing
    tool = w.age
    src = tool.source.head.skin.vertices
    assert tool.source.key == "reference:male"
    step10 = tool.cache[10]
    # the aged skin is drawn where the service put it; the source beside it, to -x
    assert np.allclose(tool.drawn_points("after"), step10.result.head.skin.vertices)
    assert tool.offset()[0] < -100
    assert np.allclose(tool.drawn_points("before") - tool.offset(), src)
    assert _height(step10.result.head.skin.vertices) < _height(src)  # a 10-year-old is smaller
    actor = tool.actors()["after"]

    tool.prefetch_years = 1
    w.age_panel.target.setValue(12)
    # at once: the nearest computed age stays in view while 12 y is computed
    assert tool.target == 12 and tool.shown_age == 10
    assert w.runner.is_running("age")
    assert "Computing 12 y" in w.age_panel.status.text()
    qtbot.waitUntil(lambda: tool.shown_age == 12, timeout=STEP_MS)
    assert tool.actors()["after"] is actor  # points moved in place, not a new actor
    after12 = tool.drawn_points("after")
    assert np.allclose(after12, tool.cache[12].result.head.skin.vertices)
    assert _height(step10.result.head.skin.vertices) < _height(after12) < _height(src)
    # then the whole years around the slider: scrubbing to one of them shows it at once
    qtbot.waitUntil(lambda: {11, 13} <= set(tool.cache), timeout=2 * STEP_MS)
    w.age_panel.target.setValue(11)
    assert tool.shown_age == 11
    assert np.allclose(tool.drawn_points("after"), tool.cache[11].result.head.skin.vertices)
    # view only: the case and its undo stack are untouched
    assert not w.document.stack.can_undo and not w.document.is_dirty


def test_the_table_fills_with_z_scores(ageing):
    w = ageing
    model = w.age_panel.model
    result = w.age.step.result
    assert model.rowCount() == len(result.rows) > 20
    normed = [r for r in result.rows if r.constraint == "norms"]
    assert len(normed) >= 20
    # measurements with norms first, each with its z-scores before and after
    for i, row in enumerate(model.rows[: len(normed)]):
        assert row.constraint == "norms"
        assert model.index(i, 0).data() == row.name
        assert model.index(i, 1).data() == f"{row.before_mm:.1f}"
        assert model.index(i, 2).data() == f"{row.after_mm:.1f}"
        assert model.index(i, 3).data() == f"{row.z_before:.2f}"
        assert model.index(i, 4).data() == f"{row.z_after:.2f}"
        assert model.index(i, 5).data() == f"{row.residual_mm:.2f}"
        assert abs(row.z_after - row.z_before) < 0.1  # the service keeps the z-score
    # the others have no z-score to show
    others = model.rows[len(normed) :]
    assert others and all(r.constraint != "norms" for r in others)
    assert model.index(len(normed), 3).data() == "–"
    assert "Hard constraints" in w.age_panel.figures.text()


def test_z_scores_beyond_two_are_highlighted(qtbot):
    from PySide6.QtCore import Qt

    from workbench.qt.panels.age_panel import MeasurementModel, out_of_range
    from workbench.services.age.change import MeasurementRow

    def row(mid: str, before: float, after: float, constraint: str = "norms") -> MeasurementRow:
        # norms 50 ± 4 mm before, 40 ± 2 mm after
        return MeasurementRow(
            mid, mid, "euclidean", "a", "b", constraint, before, after, after, 50, 4, 40, 2
        )

    model = MeasurementModel()
    model.set_rows(
        [
            row("far_before", 60.4, 41.0),  # z before +2.6, after +0.5
            row("scale_only", 80.0, 70.0, "scale"),  # no z-scores at all
            row("far_after", 48.0, 35.8),  # z before -0.5, after -2.1
            row("inside", 57.9, 43.9),  # z +1.98, +1.95
        ]
    )
    assert [r.measurement_id for r in model.rows] == [
        "far_before",
        "far_after",
        "inside",
        "scale_only",
    ]
    bg = Qt.ItemDataRole.BackgroundRole
    marked = {
        (model.rows[i].measurement_id, col)
        for i in range(model.rowCount())
        for col in range(model.columnCount())
        if model.index(i, col).data(bg) is not None
    }
    assert marked == {("far_before", 3), ("far_after", 4)}
    assert model.index(3, 3).data() == "–"
    assert out_of_range(-2.01) and out_of_range(2.01)
    assert not out_of_range(2.0) and not out_of_range(float("nan"))


def test_overlay_colours_the_aged_skin_by_displacement(ageing, qtbot):
    from workbench.render.visuals.heads import DISTANCE_TITLE, OVERLAY_OPACITY
    from workbench.render.visuals.update import mapper_dataset

    w = ageing
    tool = w.age
    w.age_panel.mode_buttons["overlay"].setChecked(True)
    assert w.age_panel.mode() == "overlay"
    step = tool.step
    src = tool.source.head.skin.vertices
    assert np.allclose(tool.offset(), 0)
    assert np.allclose(tool.drawn_points("before"), src)  # in place, translucent
    assert tool.actors()["before"].GetProperty().GetOpacity() == pytest.approx(OVERLAY_OPACITY)
    data = mapper_dataset(tool.actors()["after"])
    from vtkmodules.util.numpy_support import vtk_to_numpy

    shown = vtk_to_numpy(data.GetPointData().GetArray(DISTANCE_TITLE))
    expected = np.linalg.norm(step.result.head.skin.vertices - src, axis=1)
    assert np.allclose(shown, expected)
    assert expected.max() > 5.0  # 18 → 10 y moves the skin by centimetres somewhere
    lo, hi = tool.actors()["after"].GetMapper().GetScalarRange()
    assert lo == 0 and hi >= np.percentile(expected, 99)
    # back to side by side
    w.age_panel.mode_buttons["side"].setChecked(True)
    assert tool.offset()[0] < 0
    assert np.allclose(tool.drawn_points("after"), step.result.head.skin.vertices)


def test_export_writes_what_workbench_age_writes(ageing, qtbot, tmp_path):
    w = ageing
    tool = w.age
    out = tmp_path / "aged"
    assert tool.export_to(out)
    with qtbot.waitSignal(tool.exported, timeout=STEP_MS):
        pass
    assert (out / "head" / "template.json").is_file()
    assert (out / "sequence.glb").is_file()
    report = json.loads((out / "report.json").read_text("utf-8"))
    assert [a["to_age"] for a in report["ages"]] == [10.0]
    assert report["source"]["template_id"] == tool.source.head.template_id
    ours = {r.measurement_id: r for r in tool.cache[10].result.rows if r.constraint == "norms"}
    theirs = {m["measurement_id"]: m for m in report["ages"][0]["measurements"]}
    for mid, row in ours.items():
        assert theirs[mid]["z_after"] == pytest.approx(row.z_after, abs=1e-3)
    assert set(tool.files) >= {out / "report.json", out / "sequence.glb", out / "report.pdf"}
    assert (out / "report.pdf").read_bytes()[:5] == b"%PDF-"
    assert tool.gui_call.runs == 1  # the PDF (pictures: VTK) was written on the GUI thread
    # a folder that is not empty is not replaced (not interactive: nobody to confirm)
    assert not tool.export_to(out)
    assert "already exists" in w.age_panel.error.text()
    assert not w.document.stack.can_undo  # export only: the case is not changed


def test_the_report_writer_runs_on_the_gui_thread_inside_the_folder_write(
    ageing, qtbot, tmp_path, monkeypatch
):
    import threading

    from workbench.pipelines import age as pipeline

    seen = []

    def writer(folder, head, results, note=None):
        seen.append((threading.current_thread() is threading.main_thread(), folder))
        path = folder / "extra.txt"
        path.write_text(",".join(f"{r.to_age:g}" for r in results), "utf-8")
        return [path]

    monkeypatch.setattr(pipeline, "write_age_report_pdf", writer)
    w = ageing
    tool = w.age
    w.age_panel.export_all.setChecked(True)  # every computed age: here only 10 y
    out = tmp_path / "aged"
    assert tool.export_to(out)
    with qtbot.waitSignal(tool.exported, timeout=STEP_MS):
        pass
    assert len(seen) == 1 and seen[0][0]  # on the GUI thread ...
    assert seen[0][1] != out  # ... into the folder being written, renamed into place after
    assert (out / "extra.txt").read_text("utf-8") == "10"
    assert out / "extra.txt" in tool.files


def test_a_bad_request_shows_a_message_not_a_traceback(ageing, qtbot):
    w = ageing
    tool = w.age
    panel = w.age_panel
    tool.request(60)
    qtbot.waitUntil(lambda: 60 in tool.failed, timeout=STEP_MS)
    text = panel.error.text()
    assert panel.error.isVisible()
    assert "outside the norms' range" in text and "60" in text
    assert "Target age" in text and "--to" not in text  # the dock's field, not the CLI's
    assert "Traceback" not in text and "Unexpected" not in text
    assert tool.shown_age is None and not tool.actors()["after"].GetVisibility()
    assert panel.model.rowCount() == 0
    assert w.errors == []  # the message is in the dock, no error dialog
    # a good age again: the message goes, the head comes back (10 y is still computed)
    tool.request(10)
    assert tool.shown_age == 10 and not panel.error.isVisible()
    # a source age the norms do not cover fails for every target
    panel.from_age.setValue(60)
    assert not tool.cache  # the results of 18 y are stale
    qtbot.waitUntil(lambda: 10 in tool.failed, timeout=STEP_MS)
    assert "outside the norms' range" in panel.error.text()
    assert "Age now: age 60 y" in panel.error.text()


def test_the_case_layers_are_hidden_while_the_dock_is_in_front(
    head_male, new_window, qtbot, skull_obj
):
    w = new_window(1200, 800)
    w.age.prefetch_years = 0
    w.open_skull(skull_obj, scale=15.0)
    qtbot.waitUntil(lambda: not w.busy, timeout=60_000)
    assert w.scene.visible["skull"] and w.scene.has("skull")
    w.scene.set_visible("muscles", False)  # hidden by the user: stays hidden
    w.show_age(10)
    qtbot.waitUntil(lambda: w.age.shown_age == 10, timeout=STEP_MS)
    assert not w.scene.visible["skull"]
    assert not w.scene.actors("skull")[0].GetVisibility()
    assert w.age.actors()["after"].GetVisibility()
    assert w.age.actors()["before"].GetVisibility()
    w.docks["landmarks"].raise_()  # another tool in front: the case comes back, the heads go
    qtbot.waitUntil(lambda: w.scene.visible["skull"], timeout=5_000)
    assert w.scene.actors("skull")[0].GetVisibility()
    assert not w.scene.visible["muscles"]
    assert not w.age.actors()["after"].GetVisibility()
    assert not w.age.actors()["before"].GetVisibility()


def test_gui_options_accept_the_age_tool():
    from workbench.cli import gui_cmd

    parser = argparse.ArgumentParser()
    gui_cmd.register(parser.add_subparsers())
    opts = gui_cmd.options_from(parser.parse_args(["gui", "--tool", "age"]))
    assert opts.tool == "age" and opts.age == {
        "to_age": None,
        "from_age": None,
        "sex": None,
        "view": None,
    }
    opts = gui_cmd.options_from(
        parser.parse_args(
            ["gui", "--age-to", "8", "--age-from", "17", "--sex", "female", "--age-view", "overlay"]
        )
    )
    assert opts.tool == "age"
    assert opts.age == {"to_age": 8.0, "from_age": 17.0, "sex": "female", "view": "overlay"}
    assert gui_cmd.options_from(parser.parse_args(["gui"])).age is None


# ------------------------------------------------------------------ the case's age study
def _settings(panel):
    return (
        panel.source_key(),
        panel.sex_value(),
        panel.from_age_value(),
        panel.target_age(),
        panel.export_all.isChecked(),
    )


def test_keep_in_case_is_one_undo_step_and_undo_restores_the_dock(new_window, qtbot, tmp_path):
    from workbench.io.case_file import save_case
    from workbench.model.age_study import AgeStudy
    from workbench.model.case import Case

    w = new_window(1200, 800)
    panel, tool, doc = w.age_panel, w.age, w.document
    assert not panel.keep_button.isEnabled()  # no case open: nothing to keep it in
    assert not tool.keep() and doc.case.age_study is None
    assert "Open a case first" in w.status_text()
    path = save_case(Case(), tmp_path / "c.fcase")
    w.open_case(path)
    qtbot.waitUntil(lambda: w.document.path == path, timeout=60_000)
    assert panel.keep_button.isEnabled()
    assert "keeps no age study" in panel.case_note.text()

    panel.source.setCurrentText("Reference female")
    panel.sex.setCurrentText("female")
    panel.from_age.setValue(30.0)
    panel.target.setValue(12)
    first = _settings(panel)
    panel.keep_button.click()
    kept = doc.case.age_study
    assert kept == AgeStudy(
        source="reference:female", sex="female", from_age=30.0, target_ages=(12.0,)
    )
    assert doc.stack.can_undo and doc.stack.undo_text == "Keep the age study" and doc.is_dirty
    assert "kept in the case (undo: Ctrl+Z)" in panel.case_note.text()
    assert "kept in the case (undo: Ctrl+Z)" in w.status_text()
    record = doc.case.audit.records[-1]
    assert (
        record["command"] == "SetAgeStudy" and record["parameters"]["age_study"]["sex"] == "female"
    )

    panel.source.setCurrentText("Reference male")
    panel.sex.setCurrentText("male")
    panel.from_age.setValue(18.0)
    panel.target.setValue(6)
    assert doc.case.age_study == kept  # the dock alone does not change the case
    panel.keep_button.click()
    assert doc.case.age_study.target_ages == (6.0,) and len(doc.stack) == 2
    assert not tool.keep()  # the same settings again: no second step
    assert len(doc.stack) == 2

    w.undo()  # Edit ▸ Undo: the case and the dock go back to the first study
    assert doc.case.age_study == kept
    assert _settings(panel) == first
    w.redo()
    assert _settings(panel) == ("reference:male", "male", 18.0, 6, False)
    w.undo()
    w.undo()
    assert doc.case.age_study is None and not doc.stack.can_undo
    assert "keeps no age study" in panel.case_note.text()


def test_a_case_with_a_study_opens_with_its_settings_and_ages_them(
    head_male, new_window, qtbot, tmp_path
):
    from workbench.io.case_file import save_case
    from workbench.model.age_study import AgeStudy
    from workbench.model.case import Case

    study = AgeStudy(
        source="reference:male",
        sex="female",
        from_age=25.0,
        target_ages=(9.0, 11.0),
        ethnicity="European",
    )
    path = save_case(Case(age_study=study), tmp_path / "study.fcase")
    w = new_window(1200, 800)
    w.age.prefetch_years = 0
    w.open_case(path)
    qtbot.waitUntil(lambda: w.document.path == path, timeout=60_000)
    panel = w.age_panel
    assert _settings(panel) == ("reference:male", "female", 25.0, 9, True)
    assert "keeps an age study" in panel.case_note.text()
    w.show_age()
    qtbot.waitUntil(lambda: w.age.shown_age == 9, timeout=STEP_MS)
    # the head's load did not put back its own sex: the study's is used
    assert panel.sex_value() == "female" and panel.ethnicity_value() == "European"
    assert w.age.settings().sex == "female" and w.age.settings().from_age == 25.0
    assert w.age.current_study() == study.replaced(target_ages=(9.0,))  # 11 y not computed yet
    assert not w.document.stack.can_undo  # opening shows the study, it does not edit it


def test_the_arc_increase_field_is_part_of_the_settings_and_the_study(
    head_female, new_window, qtbot, tmp_path
):
    from workbench.io.case_file import save_case
    from workbench.model.age_study import AgeStudy
    from workbench.model.case import Case

    study = AgeStudy(
        source="reference:female",
        sex="female",
        from_age=20.0,
        target_ages=(4.0,),
        arc_increase=0.05,
    )
    path = save_case(Case(age_study=study), tmp_path / "arc.fcase")
    w = new_window(1200, 800)
    w.age.prefetch_years = 0
    w.open_case(path)
    qtbot.waitUntil(lambda: w.document.path == path, timeout=60_000)
    panel = w.age_panel
    assert panel.arc_increase.value() == pytest.approx(5.0)  # the kept study's, shown
    assert w.age.settings().arc_increase == pytest.approx(0.05)
    panel.arc_increase.setValue(8.0)
    assert w.age.settings().arc_increase == pytest.approx(0.08)
    assert w.age.current_study().arc_increase == pytest.approx(0.08)
    assert panel.arc_increase.maximum() == pytest.approx(10.0)  # the 10 % at most


def test_norms_of_the_other_sex_are_said_in_the_dock(ageing):
    """The command line refuses them without --allow-sex-mismatch; the dock, where the sex is
    chosen on purpose, says so in its status line."""
    w = ageing
    assert "Warning" not in w.age._status_text()
    w.age_panel.sex.setCurrentText("female")
    assert "Warning: a male head aged with the female norms." in w.age._status_text()
