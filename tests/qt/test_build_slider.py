"""The reconstruct dock's build slider and band colouring (issue 31), under Xvfb (xcb).

One window per module fits the real skull once (``skull.obj`` × 15 mm, the
reference head's suggested landmarks pushed as one command, the window's own
fit, as ``test_qt_first_fit``), so ``fit.builds`` holds the slender, average
and heavy faces.  The tests move the slider and check what the 3D view draws
(mm, input frame): the face actor's points morph in place to the build's
vertices, the band colouring shows the band's half-width and keeps it while
the points move, and a fit without build faces disables the slider.
"""

from __future__ import annotations

import os
from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("pytestqt")
if os.environ.get("QT_QPA_PLATFORM") != "xcb":
    pytest.skip(
        "the 3D view needs QT_QPA_PLATFORM=xcb under Xvfb (see HEADLESS.md)",
        allow_module_level=True,
    )

from vtkmodules.util.numpy_support import vtk_to_numpy

from workbench.qt.panels.reconstruct_panel import BAND_TITLE

pytestmark = pytest.mark.gui


@pytest.fixture(scope="module")
def window(qapp, skull_obj, skull_obj_suggested):
    """A window with a fitted face that has build faces (real skull, real fit)."""
    from PySide6.QtTest import QTest

    from workbench.commands.landmarks import ReplaceLandmarkSet
    from workbench.qt.main_window import MainWindow

    w = MainWindow(auto_update=False, interactive=False)
    w.resize(1200, 800)
    w.show()
    QTest.qWaitForWindowExposed(w)
    w.open_skull(skull_obj, scale=15.0)
    assert w.wait_idle(60)
    _, landmarks = skull_obj_suggested
    assert w.document.push(ReplaceLandmarkSet("skull", landmarks, "Suggest skull landmarks"))
    assert w.wait_idle(60)
    w.reconstruct()
    assert w.wait_idle(180)
    assert not w.errors, w.errors
    assert w.fit is not None and w.fit.builds is not None
    w.docks["reconstruct"].raise_()
    yield w
    w.runner.shutdown()
    w.plotter.close()  # required: finalize VTK while the GL context exists
    w.close()


@pytest.fixture(scope="module")
def real_fit(window):
    return window.fit


@pytest.fixture
def fitted(window, real_fit, qtbot):
    """The module's window on its real fit, skin colouring, main build, painted."""
    panel = window.reconstruct_panel
    panel.colouring.setCurrentText("skin")
    if window.fit is not real_fit:
        window.reconstruction.show_fit(real_fit)
    assert window.wait_idle(60)
    panel.set_build(real_fit.builds.main)
    _painted(window, qtbot)
    return window


def _painted(window, qtbot) -> None:
    qtbot.waitUntil(lambda: not window.scene.render_queued and not window.busy, timeout=10_000)


def _drawn(window) -> np.ndarray:
    return window.scene.layer_points("face")


def _expected(fit, build: str) -> np.ndarray:
    return fit.recon.to_input(fit.builds.vertices(build))


def _drawn_scalars(window, qtbot, name: str) -> np.ndarray | None:
    """The face actor's point array ``name`` as the renderer sees it (after a paint)."""
    window.scene.request_render()
    _painted(window, qtbot)
    data = window.scene.actors("face")[0].GetMapper().GetInput()
    array = data.GetPointData().GetArray(name)
    return None if array is None else np.array(vtk_to_numpy(array), dtype=float)


def test_the_slider_lists_the_builds_and_starts_on_the_main_face(fitted):
    window = fitted
    panel, builds = window.reconstruct_panel, window.fit.builds
    assert builds.names == ("slender", "average", "heavy") and builds.main == "average"
    assert panel.build_slider.isEnabled() and panel.build_slider.isVisibleTo(panel)
    assert panel.build_ticks.isVisibleTo(panel)
    shown = [label.text().replace("\n", " ") for label in panel.build_labels]
    assert shown == [
        f"{n} (BMI {round(builds.bmi[n], 1):g})" for n in ("slender", "average", "heavy")
    ]
    assert shown == ["slender (BMI 19)", "average (BMI 24.3)", "heavy (BMI 34)"]
    assert panel.build_slider.value() == panel.build_position("average")
    assert panel.build_z() == builds.main_z
    assert panel.build_value.text() == "BMI 24.3"
    np.testing.assert_allclose(_drawn(window), window.fit.recon.face.vertices, atol=1e-6)
    # the labels sit under the track: the first at its left end, the last at its right end
    slider, first, last = panel.build_slider, panel.build_labels[0], panel.build_labels[-1]
    left = slider.mapTo(panel, slider.rect().topLeft()).x()
    right = slider.mapTo(panel, slider.rect().topRight()).x()
    assert abs(first.mapTo(panel, first.rect().topLeft()).x() - left) <= 12
    assert abs(last.mapTo(panel, last.rect().topRight()).x() - right) <= 12
    for label in panel.build_labels:  # never clipped
        assert label.width() >= label.sizeHint().width(), label.text()


def test_moving_the_slider_morphs_the_drawn_face_in_place(fitted, qtbot):
    window = fitted
    panel, scene, fit = window.reconstruct_panel, window.scene, window.fit
    actor = scene.actors("face")[0]
    undo_steps, dirty = len(window.document.stack), window.document.is_dirty
    fits = window.runner.timings.get("fit")

    average = _drawn(window)
    panel.set_build("heavy")
    heavy = _drawn(window)
    np.testing.assert_allclose(heavy, _expected(fit, "heavy"), atol=1e-6)
    assert np.abs(heavy - average).max() > 2.0  # the heavy face really is another face
    assert scene.actors("face") == [actor]  # moved in place, not redrawn
    assert panel.build_value.text() == "BMI 34.0"
    _painted(window, qtbot)

    # between two faces: the blend at the slider's build score
    panel.build_slider.setValue(panel.build_position("average") + 50)
    z = 0.5 * (fit.builds.z["average"] + fit.builds.z["heavy"])
    assert panel.build_z() == pytest.approx(z)
    np.testing.assert_allclose(
        _drawn(window), fit.recon.to_input(fit.builds.vertices_at(z)), atol=1e-6
    )

    panel.set_build("slender")
    np.testing.assert_allclose(_drawn(window), _expected(fit, "slender"), atol=1e-6)
    panel.set_build("average")
    np.testing.assert_allclose(_drawn(window), average, atol=1e-6)
    np.testing.assert_allclose(_drawn(window), _expected(fit, "average"), atol=1e-6)
    assert scene.actors("face") == [actor]
    # view state: no case edit, no undo step, no re-fit
    assert len(window.document.stack) == undo_steps and window.document.is_dirty == dirty
    assert window.runner.timings.get("fit") == fits and window.fit is fit
    # the light skull while the slider moves; the full one once it rests
    assert window.detail.active
    qtbot.waitUntil(lambda: not window.detail.active, timeout=5_000)


def test_the_band_colouring_keeps_its_colours_while_the_face_morphs(fitted, qtbot):
    window = fitted
    panel, scene, fit = window.reconstruct_panel, window.scene, window.fit
    half = fit.builds.half_width_mm
    assert half.shape == (fit.recon.face.n_vertices,) and np.ptp(half) > 0.5

    panel.colouring.setCurrentText("band")
    assert BAND_TITLE in window.plotter.scalar_bars
    np.testing.assert_allclose(_drawn_scalars(window, qtbot, BAND_TITLE), half)
    actor = scene.actors("face")[0]

    panel.set_build("heavy")
    np.testing.assert_allclose(_drawn(window), _expected(fit, "heavy"), atol=1e-6)
    np.testing.assert_allclose(_drawn_scalars(window, qtbot, BAND_TITLE), half)
    assert scene.actors("face") == [actor] and BAND_TITLE in window.plotter.scalar_bars

    # a colouring change redraws the face at the slider's build, not the main one
    panel.colouring.setCurrentText("skin")
    np.testing.assert_allclose(_drawn(window), _expected(fit, "heavy"), atol=1e-6)
    assert _drawn_scalars(window, qtbot, BAND_TITLE) is None
    assert BAND_TITLE not in window.plotter.scalar_bars

    # a move right after the coloured face was drawn, before any paint
    panel.colouring.setCurrentText("band")
    panel.set_build("slender")
    np.testing.assert_allclose(_drawn(window), _expected(fit, "slender"), atol=1e-6)
    np.testing.assert_allclose(_drawn_scalars(window, qtbot, BAND_TITLE), half)
    drawn = window.scene.actors("face")[0].GetMapper().GetInput()  # what the renderer used
    np.testing.assert_allclose(
        vtk_to_numpy(drawn.GetPoints().GetData()), _expected(fit, "slender"), atol=1e-6
    )


def test_a_fit_without_build_faces_disables_the_slider(fitted, qtbot):
    window = fitted
    panel, fit = window.reconstruct_panel, window.fit
    panel.set_build("heavy")
    one_face = replace(fit, builds=None)
    window.reconstruction.show_fit(one_face)
    assert window.wait_idle(60)
    try:
        assert window.fit is one_face
        assert not panel.build_slider.isEnabled()
        assert not panel.build_ticks.isVisibleTo(panel)
        assert "one face" in panel.build_slider.toolTip().lower()
        assert panel.build_z() is None
        with pytest.raises(ValueError):
            panel.set_build("heavy")
        # the face drawn is the fit's own; moving the (disabled) slider changes nothing
        np.testing.assert_allclose(_drawn(window), fit.recon.face.vertices, atol=1e-6)
        panel.build_slider.setValue(panel.build_slider.maximum())
        np.testing.assert_allclose(_drawn(window), fit.recon.face.vertices, atol=1e-6)
        # band colouring without a band: the plain skin
        panel.colouring.setCurrentText("band")
        assert _drawn_scalars(window, qtbot, BAND_TITLE) is None
        assert BAND_TITLE not in window.plotter.scalar_bars
    finally:
        panel.colouring.setCurrentText("skin")
        window.reconstruction.show_fit(fit)
        assert window.wait_idle(60)
    # the real fit again: enabled, on its main build
    assert panel.build_slider.isEnabled()
    assert panel.build_slider.value() == panel.build_position("average")
    np.testing.assert_allclose(_drawn(window), fit.recon.face.vertices, atol=1e-6)
