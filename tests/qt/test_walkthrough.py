"""The artist's whole session in the window, scripted on real CTs (issue 33).

headsq (the VTK quarter CT) and the Visible Human female head (1 mm CT), fully automatic:
CT -> bone -> suggested landmarks (accepted) -> reconstruct -> a guide moved and a landmark
moved (live preview, refit) -> a thinner build -> animate the reconstruction -> age it to
8 years and keep the study -> fit the CT's own skin as a face scan -> examiner -> save ->
export -> reopen.  Each step leaves a screenshot in the artefacts folder
(``$WORKBENCH_TEST_ARTEFACTS/walkthrough/<case>/``, else the test's temporary folder), to
be looked at; the assertions check what the artist relies on at each step.

Data from the Visible Human Project: courtesy of the U.S. National Library of Medicine.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pytestqt")
if os.environ.get("QT_QPA_PLATFORM") != "xcb":
    pytest.skip(
        "the 3D view needs QT_QPA_PLATFORM=xcb under Xvfb (see HEADLESS.md)",
        allow_module_level=True,
    )

pytestmark = [pytest.mark.gui, pytest.mark.slow]

CTS = {
    "headsq": ("vtk_headsq_quarter_ct", "headsq", "quarter.nhdr"),
    "vhp_female": ("vhp_female_head_ct", "vhf_head_ct_1mm.nii.gz"),
}


def _stray(window) -> list:
    """Bounds of visible actors no layer of the case or of the tool in front owns."""

    def address(actor) -> str:
        return actor.GetAddressAsString("vtkObject")

    owned = [a for layer in window.scene.visible for a in window.scene.actors(layer)]
    owned += [a for layer in ("scan", "skin", "landmarks") for a in window.scan_fit.actors(layer)]
    if window.animate.active:
        owned += list(window.animate.actors().values())
    if window.age.active:
        owned += list(window.age.actors().values())
    mine = {address(a) for a in owned}
    return [
        a.GetBounds()
        for a in window.plotter.renderer.GetActors()
        if a.GetVisibility() and address(a) not in mine
    ]


class Shots:
    """Numbered window screenshots of one session."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        folder.mkdir(parents=True, exist_ok=True)
        self.n = 0

    def __call__(self, window, name: str) -> Path:
        self.n += 1
        return window.save_screenshot(self.folder / f"{self.n:02d}_{name}.png")


@pytest.fixture
def artefacts(tmp_path, request) -> Path:
    root = os.environ.get("WORKBENCH_TEST_ARTEFACTS")
    case = request.node.callspec.id
    return (Path(root) / "walkthrough" / case) if root else tmp_path / case


@pytest.mark.parametrize("case", sorted(CTS))
def test_the_whole_session(qtbot, new_window, shared_data, tmp_path, artefacts, case):
    from workbench.commands.case_edits import SetCaseDetails
    from workbench.commands.landmarks import MoveLandmark
    from workbench.io.meshes import write_mesh
    from workbench.qt.panels.animate_panel import RECONSTRUCTION
    from workbench.services.ct.ct_mesh import mesh_from_ct
    from workbench.services.reconstruction.refit_check import face_turn_deg

    ct = shared_data.joinpath(*CTS[case])
    if not ct.exists():
        pytest.skip(f"{ct} is not in ../shared/data")
    shot = Shots(artefacts)
    window = new_window(1500, 950)

    # CT -> bone, as File > Open CT does
    assert window.open_ct(ct, "bone")
    assert window.wait_idle(300) and not window.errors, window.errors
    assert window.document.case.specimen.mesh is not None
    shot(window, "skull")

    # landmarks suggested (with progress), then accepted as they are
    window.landmarks.suggest_landmarks()
    assert window.wait_idle(300) and not window.errors, window.errors
    panel = window.landmarks_panel
    assert panel.accept_button.isEnabled()
    panel.accept_button.click()
    lms = window.document.case.landmarks["skull"]
    assert not any(lm.status == "suggested" for lm in lms)
    shot(window, "landmarks")

    # reconstruct: the face over the skull, guides, build faces
    window.reconstruct_panel.auto_refit.setChecked(True)
    window.reconstruct()
    assert window.wait_idle(300) and not window.errors, window.errors
    fit = window.fit
    assert fit is not None and fit.recon.figures["penetrating_vertices"] == 0
    assert fit.builds is not None and window.guide_view.isVisible()
    window.docks["reconstruct"].raise_()
    shot(window, "face")

    # a guide moved in the table: the face follows at once, the refit reuses the registration
    tool = window.reconstruction
    rows = window.reconstruct_panel.guides
    row = next(i for i, g in enumerate(rows) if g.enabled and g.kind == "hline")
    before = window.fit
    window.reconstruct_panel.set_guide(row, value=(rows[row].value[0] - 2.0,))
    assert window.wait_idle(300) and not window.errors, window.errors
    assert window.fit is not before and tool.held is None
    # a landmark moved: preview within the edit, refit after, the face does not turn
    before = window.fit
    g = window.document.case.landmarks["skull"]["g"]
    t0 = time.perf_counter()
    assert window.document.push(
        MoveLandmark(surface="skull", code="g", position=g.position + np.array([0, 0, 1.5]))
    )
    assert time.perf_counter() - t0 < 5.0 and tool.edit_timings  # the preview was drawn
    assert window.wait_idle(300) and not window.errors, window.errors
    assert tool.held is None
    assert face_turn_deg(before.recon.face.vertices, window.fit.recon.face.vertices) < 5.0
    shot(window, "guides_after_edits")

    # a thinner build (refit): no skin inside the bone
    combo = window.dowels_panel.build_combo
    minus2 = next(i for i in range(combo.count()) if combo.itemText(i).startswith("-2 SD"))
    combo.setCurrentIndex(minus2)
    assert window.wait_idle(300) and not window.errors, window.errors
    assert window.fit.recon.figures["penetrating_vertices"] == 0
    window.docks["dowels"].raise_()
    shot(window, "build_minus_2sd")
    window.document.undo()  # back to the average build
    assert window.wait_idle(300) and not window.errors, window.errors

    # animate the case's own reconstruction
    heads = window.animate_panel.head
    heads.setCurrentText(RECONSTRUCTION)
    window.show_animate("smile")  # (a name the palette lacks selects nothing)
    qtbot.waitUntil(lambda: window.animate.sex == "reconstruction", timeout=120_000)
    assert window.wait_idle(300) and not window.errors, window.errors
    shot(window, "animate")

    # age the reconstruction to 8 years and keep the study in the case
    window.show_age(to_age=8, reconstructed=True)
    qtbot.waitUntil(lambda: window.age.shown_age == 8, timeout=300_000)
    assert window.wait_idle(300) and not window.errors, window.errors
    assert window.age.source is not None and window.age.source.key == "fit"
    assert window.age.keep()
    shot(window, "age_8")

    # the CT's own skin as a face scan (the Fit scan tool; the case is not touched)
    skin = mesh_from_ct(ct, "skin")  # written as mesh-from-ct writes it: its frame tagged
    scan = write_mesh(tmp_path / f"{case}_skin.ply", skin.mesh, space=skin.frame)
    window.open_scan(scan, units="mm")  # (a CT surface: mm, as the file says)
    assert window.wait_idle(300) and not window.errors, window.errors
    window.fit_scan()
    assert window.wait_idle(600) and not window.errors, window.errors
    assert window.scan_fit.view is not None
    assert not _stray(window)  # the Animate and Age heads (and their eyes) went with them
    shot(window, "scan_fit")

    # the session's own heads in the Animate and Age docks (as the command line takes them)
    heads = window.animate_panel.head
    assert heads.findData("scan") >= 0 and heads.findData("aged") >= 0
    assert heads.itemText(heads.findData("aged")) == "The aged head (8 y)"
    heads.setCurrentIndex(heads.findData("scan"))
    window.show_animate("smile")
    qtbot.waitUntil(lambda: window.animate.sex == "scan", timeout=120_000)
    scanned = window.scan_fit.view.fit.head
    assert window.animate.animator.head.skin.n_vertices == scanned.skin.n_vertices
    window.age_panel.source.setCurrentText("Fitted scan (Fit scan dock)")
    window.show_age(to_age=12)
    qtbot.waitUntil(
        lambda: (
            window.age.source is not None
            and window.age.source.key == "scan"
            and window.age.shown_age == 12
        ),
        timeout=300_000,
    )
    assert window.wait_idle(300) and not window.errors, window.errors
    shot(window, "age_of_the_scan_12")
    assert not window.age.keep()  # the fitted scan is not part of the case: not kept
    assert window.document.case.age_study.source == "reconstruction"

    # examiner, save, export (the command line's folder, report with pictures)
    window.docks["reconstruct"].raise_()
    assert window.document.push(SetCaseDetails(examiner="Walk-through examiner", notes=""))
    path = tmp_path / f"{case}.fcase"
    assert window.save_to(path)
    out = tmp_path / f"{case}_export"
    assert window.export_to(out)
    assert window.wait_idle(600) and not window.errors, window.errors
    assert (out / "report.pdf").exists() and (out / "face.ply").exists()
    assert "Walk-through examiner" in (out / "report.json").read_text()

    # reopen: the face, guides, builds and age study as saved, without fitting
    again = new_window(1500, 950)
    t0 = time.perf_counter()
    again.open_case(path)
    qtbot.waitUntil(lambda: again.fit is not None, timeout=60_000)
    seconds = time.perf_counter() - t0
    print(f"{case}: reopened with the face shown in {seconds:.2f} s")
    assert again.wait_idle(300) and not again.errors, again.errors
    assert np.allclose(again.fit.recon.face.vertices, window.fit.recon.face.vertices)
    assert again.fit.builds is not None and again.scene.has("guides")
    assert again.document.case.age_study is not None
    shot(again, "reopened")
    assert not _stray(again)  # nothing but the case's own layers (no tool's head behind)
    again.show_age()
    qtbot.waitUntil(lambda: again.age.shown_age == 8, timeout=300_000)
    assert again.age.source is not None and again.age.source.key == "fit"
    shot(again, "reopened_age")
