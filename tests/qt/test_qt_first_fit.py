"""The first fit of a session, under Xvfb (xcb): the guide view opens, then the face is drawn.

Opening the guide view narrows the 3D view, so both views repaint in one
pass; the window opens it while both are cheap to draw (a label in place of
the empty guide view, the main view without the face) and draws the fit
after that paint.  Also checks what the views are drawn with: unsorted
blending with back faces culled (no order-independent transparency), FXAA
only on a graphics card, and the guide view's framing (160 mm of the face
across its narrower side).

Real 100k-triangle skull (``skull.obj`` × 15 mm) with the session's
suggested landmarks pushed as one command.
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

from workbench.qt.scene import is_software_gl

pytestmark = pytest.mark.gui


def test_first_fit_opens_the_guide_view_before_drawing_the_face(
    qtbot, window, skull_obj, skull_obj_suggested
):
    from workbench.commands.landmarks import ReplaceLandmarkSet

    gv = window.guide_view
    assert not gv.isVisible() and gv.pages.currentWidget() is gv.placeholder
    window.open_skull(skull_obj, scale=15.0)
    qtbot.waitUntil(lambda: not window.busy, timeout=30_000)
    _, landmarks = skull_obj_suggested
    assert window.document.push(ReplaceLandmarkSet("skull", landmarks, "Suggest skull landmarks"))
    qtbot.waitUntil(lambda: not window.busy, timeout=60_000)

    events: list[tuple[str, bool, int]] = []
    scene, show_face, show_guide_view = window.scene, window.scene.show_face, window.show_guide_view
    scene.show_face = lambda *a, **k: (
        events.append(("face", gv.isVisible(), scene.paints)),
        show_face(*a, **k),
    )[1]
    window.show_guide_view = lambda on, draw=True: (
        events.append(("guide view", bool(on), scene.paints)),
        show_guide_view(on, draw),
    )[1]
    try:
        window.reconstruct()
        assert window.wait_idle(180)
    finally:
        del scene.show_face, window.show_guide_view
    assert not window.errors, window.errors and window.fit is not None

    kinds = [e[0] for e in events]
    opened, drawn = kinds.index("guide view"), kinds.index("face")
    assert opened < drawn and events[drawn][1]  # opened first, visible when drawn
    assert events[drawn][2] > events[opened][2]  # the main view painted in between
    assert gv.pages.currentWidget() is gv.plotter and gv.drawn_fit is window.fit

    # framing: 160 mm of the face across the narrower side of the guide view
    h, w = gv.pages.height(), gv.pages.width()
    assert np.isclose(gv.plotter.camera.parallel_scale, 80.0 * max(1.0, h / w))

    # what the views are drawn with
    face = scene.actors("face")[0]
    assert face.GetProperty().GetBackfaceCulling() and not window.plotter.renderer.GetUseOIT()
    assert not gv.plotter.renderer.GetUseOIT()
    assert scene.gl_renderer not in ("", "unknown")
    smoothing = not is_software_gl(scene.gl_renderer)
    assert bool(window.plotter.renderer.GetUseFXAA()) is smoothing
    assert bool(gv.plotter.renderer.GetUseFXAA()) is smoothing

    # a colour map adds its bar without an immediate render (the next paint
    # draws it), inside the view's right edge
    paints = scene.paints
    face_mesh = window.fit.recon.face
    scene.show_face(face_mesh, np.linspace(-3.0, 3.0, face_mesh.n_vertices), "spread mm")
    assert scene.paints == paints
    bar = window.plotter.scalar_bars["spread mm"]
    x, _ = bar.GetPositionCoordinate().GetValue()[:2]
    assert 0.0 < x and x + bar.GetWidth() <= 0.95
    window.draw_face()

    # where the skull was measured for the guides: yellow marks with their labels
    qtbot.waitUntil(lambda: bool(gv._marks) or bool(gv._unmeasured), timeout=30_000)
    labels = {label for label, _at, _how in gv._marks}
    assert "widest aperture" in labels, (labels, gv._unmeasured)
    gv.refresh()
    assert "gv_marks" in gv.plotter.actors and "Yellow" in gv.info.text()
    gv.show_measures.setChecked(False)
    assert "gv_marks" not in gv.plotter.actors and "Yellow" not in gv.info.text()
    gv.show_measures.setChecked(True)
    if os.environ.get("WORKBENCH_SCREENSHOTS"):  # for looking at it by eye
        gv.plotter.render()
        gv.plotter.screenshot(os.path.join(os.environ["WORKBENCH_SCREENSHOTS"], "guides.png"))
