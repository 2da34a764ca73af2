"""Layer toggles and opacity of the workbench window under Xvfb (QT_QPA_PLATFORM=xcb).

One window per module is fitted once (real skull, suggested landmarks, real
fit), so every layer has actors; the tests then drive the Layers dock, the
View menu and the reconstruct panel's skin slider and check the actors, the
muscles layer (mm, input frame), in-place vertex updates and a picture.
"""

from __future__ import annotations

import os
import time

import numpy as np
import pytest

pytest.importorskip("pytestqt")
if os.environ.get("QT_QPA_PLATFORM") != "xcb":
    pytest.skip(
        "the 3D view needs QT_QPA_PLATFORM=xcb under Xvfb (see HEADLESS.md)",
        allow_module_level=True,
    )

from workbench.qt.scene import HIDDEN_BY_DEFAULT, LAYERS, ON_DEMAND

pytestmark = pytest.mark.gui


@pytest.fixture(scope="module")
def window(qapp, skull_obj):
    """A window with a fitted face (skull OBJ ×15 → mm) and the truth layer drawn."""
    from PySide6.QtTest import QTest

    from workbench.qt.main_window import MainWindow

    w = MainWindow(auto_update=False, interactive=False)
    w.resize(1200, 800)
    w.show()
    QTest.qWaitForWindowExposed(w)
    w.initial_layers = w.scene.layer_state()
    w.open_skull(skull_obj, scale=15.0)
    assert w.wait_idle(60)
    w.suggest_landmarks()
    assert w.wait_idle(120)
    w.reconstruct()
    assert w.wait_idle(120)
    assert not w.errors, w.errors
    assert w.fit is not None
    w.scene.show_truth(w.fit.recon.face)  # any surface will do: the layer needs an actor
    yield w
    w.runner.shutdown()
    w.plotter.close()  # required: finalize VTK while the GL context exists
    w.close()


def _visible(window, layer: str) -> list[bool]:
    return [bool(a.GetVisibility()) for a in window.scene.actors(layer)]


def _opacities(window, layer: str) -> list[float]:
    return [a.GetProperty().GetOpacity() for a in window.scene.actors(layer)]


def test_every_layer_toggles_and_fades_from_the_dock_and_the_menu_in_sync(window):
    scene, panel, menu = window.scene, window.layers_panel, window.actions_by_id
    assert window.initial_layers["muscles"] == (False, 1.0)  # muscles start hidden
    assert window.initial_layers["face"] == (True, 0.6)
    assert {k for k, (on, _) in window.initial_layers.items() if not on} == HIDDEN_BY_DEFAULT
    assert set(panel.checks) == set(LAYERS) == {k[6:] for k in menu if k.startswith("layer_")}
    emitted: list[str] = []
    scene.layer_changed.connect(emitted.append)

    for layer in LAYERS:
        if layer in ON_DEMAND:  # (a held-back refit: tests/qt/test_safe_edits.py; hair:
            # tests/qt/test_hair_layer.py)
            continue
        assert scene.actors(layer), f"{layer}: nothing drawn after the fit"
        start = scene.visible[layer]
        assert panel.checks[layer].isChecked() == menu[f"layer_{layer}"].isChecked() == start

        emitted.clear()
        panel.checks[layer].click()  # dock → scene → menu
        assert _visible(window, layer) == [not start] * len(scene.actors(layer))
        assert menu[f"layer_{layer}"].isChecked() is (not start)
        assert emitted == [layer]  # once: no echo

        emitted.clear()
        menu[f"layer_{layer}"].trigger()  # menu → scene → dock
        assert _visible(window, layer) == [start] * len(scene.actors(layer))
        assert panel.checks[layer].isChecked() is start
        assert emitted == [layer]

        panel.checks[layer].setChecked(True)
        emitted.clear()
        panel.sliders[layer].setValue(37)  # opacity reaches every actor
        assert _opacities(window, layer) == pytest.approx([0.37] * len(scene.actors(layer)))
        assert scene.layer_state()[layer] == (True, pytest.approx(0.37))
        assert emitted == [layer]
        scene.set_opacity(layer, 0.8)  # scene → dock
        assert panel.sliders[layer].value() == 80

    # the reconstruct panel's skin slider and the dock's face slider are one state
    window.reconstruct_panel.opacity.setValue(25)
    assert panel.sliders["face"].value() == 25
    assert _opacities(window, "face") == pytest.approx([0.25])
    panel.sliders["face"].setValue(45)
    assert window.reconstruct_panel.opacity.value() == 45

    # a redraw keeps the layer's state
    panel.checks["muscles"].setChecked(False)
    panel.sliders["muscles"].setValue(50)
    window.draw_muscles()
    assert _visible(window, "muscles") == [False] * len(scene.actors("muscles"))
    assert _opacities(window, "muscles") == pytest.approx([0.5] * len(scene.actors("muscles")))
    scene.layer_changed.disconnect(emitted.append)


def test_muscles_lie_inside_the_fitted_face(window):
    actors = window.scene.actors("muscles")
    assert 1 <= len(actors) <= 2  # sheets and fibre lines
    face = np.array(window.scene.actors("face")[0].GetBounds()).reshape(3, 2)
    muscles = np.array([a.GetBounds() for a in actors]).reshape(-1, 3, 2)
    lo, hi = muscles[:, :, 0].min(axis=0), muscles[:, :, 1].max(axis=0)
    assert np.all(lo >= face[:, 0] - 1.0) and np.all(hi <= face[:, 1] + 1.0), (lo, hi, face)
    assert np.all(hi - lo > 40.0)  # they span the face, not a point (mm)
    fibres = window.scene.actors("muscles")[-1].GetMapper().GetInput()
    assert fibres.GetNumberOfLines() >= 2 * len(window.fit.recon.head.muscles)


def test_update_points_moves_the_face_in_place(window):
    from vtkmodules.util.numpy_support import vtk_to_numpy as np_

    scene = window.scene
    actor = scene.actors("face")[0]
    data = actor.GetMapper().GetInput()
    before = np_(data.GetPoints().GetData()).copy()
    normals = np_(data.GetPointData().GetNormals()).copy()
    shifted = before + np.array([0.0, 5.0, 0.0])
    start = time.perf_counter()
    scene.update_points("face", shifted)
    seconds = time.perf_counter() - start
    assert scene.actors("face")[0] is actor
    assert actor.GetMapper().GetInput() is data
    np.testing.assert_allclose(np_(data.GetPoints().GetData()).copy(), shifted)
    # a translation keeps the (recomputed) normals
    np.testing.assert_allclose(np_(data.GetPointData().GetNormals()).copy(), normals, atol=1e-3)
    print(f"update_points: {seconds * 1e3:.1f} ms")  # budgets live in benchmarks/
    with pytest.raises(ValueError):
        scene.update_points("face", shifted[:-1])
    scene.update_points("face", before)
    np.testing.assert_allclose(np_(data.GetPoints().GetData()).copy(), before)


def test_picture_with_muscles_under_a_faint_skin_is_not_blank(window, tmp_path):
    from PySide6.QtGui import QImage

    panel = window.layers_panel
    for layer in LAYERS:
        panel.checks[layer].setChecked(layer in ("skull", "muscles", "face"))
        panel.sliders[layer].setValue(100)
    panel.sliders["face"].setValue(30)
    window.reset_view()
    image = QImage(str(window.save_screenshot(tmp_path / "layers.png")))
    view = window.view_rect()
    colours = np.array(
        [
            image.pixelColor(x, y).getRgb()[:3]
            for x in range(view.left() + 5, view.right() - 5, 7)
            for y in range(view.top() + 5, view.bottom() - 5, 7)
        ],
        float,
    )
    assert colours.mean(axis=1).var() > 50.0
    red = (colours[:, 0] > colours[:, 1] + 60) & (colours[:, 0] > colours[:, 2] + 60)
    assert red.sum() > 50, red.sum()  # the muscles show through the skin

    panel.checks["muscles"].setChecked(False)
    image = QImage(str(window.save_screenshot(tmp_path / "no_muscles.png")))
    colours = np.array(
        [
            image.pixelColor(x, y).getRgb()[:3]
            for x in range(view.left() + 5, view.right() - 5, 7)
            for y in range(view.top() + 5, view.bottom() - 5, 7)
        ],
        float,
    )
    red_off = (colours[:, 0] > colours[:, 1] + 60) & (colours[:, 0] > colours[:, 2] + 60)
    assert red_off.sum() < red.sum() / 4, (red_off.sum(), red.sum())


def test_after_paint_runs_behind_the_next_paint_and_after_a_fit(window, qtbot):
    """Heavy steps are sequenced behind paints; a new fit fills the guide view only after."""
    scene = window.scene
    order: list[tuple[str, int]] = []
    scene.after_paint(lambda: order.append(("callback", scene.paints)))
    painted_before = scene.paints
    assert scene.paint_work_pending and window.busy
    qtbot.waitUntil(lambda: bool(order), timeout=5_000)
    assert order[0][1] > painted_before  # ran after (at least) one more render
    assert not scene.paint_work_pending

    # a hidden view never paints: the callback still runs (fallback timer)
    window.plotter.hide()
    try:
        ran: list[bool] = []
        scene.after_paint(lambda: ran.append(True))
        qtbot.waitUntil(lambda: bool(ran), timeout=5_000)
    finally:
        window.plotter.show()

    # a new fit's guide view is drawn behind the main view's paint, not with it
    from dataclasses import replace

    gv, new_fit = window.guide_view, replace(window.fit)
    refreshed_at: list[int] = []
    original = gv.refresh
    gv.refresh = lambda *a, **k: (refreshed_at.append(scene.paints), original(*a, **k))[1]
    try:
        main_paints = scene.paints
        window.reconstruction.show_fit(new_fit)
        assert gv.drawn_fit is not new_fit and window.busy
        assert window.wait_idle(60)
    finally:
        del gv.refresh
    assert gv.drawn_fit is new_fit
    assert refreshed_at and min(refreshed_at) > main_paints
