"""Each tool shows its own heads and takes them away when it is left (issue 33): the Animate,
Age and Fit scan docks set the case's layers aside while in front, and leaving them hides
their heads or scan (and the age colour bar) and brings the case back."""

from __future__ import annotations

import os

import pytest

pytest.importorskip("pytestqt")
if os.environ.get("QT_QPA_PLATFORM") != "xcb":
    pytest.skip(
        "the 3D view needs QT_QPA_PLATFORM=xcb under Xvfb (see HEADLESS.md)",
        allow_module_level=True,
    )

pytestmark = pytest.mark.gui


def test_the_animate_head_goes_when_the_dock_is_left(qtbot, window, skull_obj):
    window.open_skull(skull_obj, scale=15.0)
    qtbot.waitUntil(lambda: not window.busy, timeout=30_000)
    assert window.scene.visible["skull"] and window.scene.has("skull")

    window.show_animate()
    qtbot.waitUntil(lambda: window.animate.animator is not None, timeout=60_000)
    skin = window.animate._actors["skin"]
    assert skin.GetVisibility() and not window.scene.visible["skull"]  # the case aside

    window.docks["landmarks"].raise_()
    qtbot.waitUntil(lambda: not window.animate.active, timeout=5_000)
    assert not skin.GetVisibility() and window.scene.visible["skull"]  # the case back
    # nothing of the head stays behind, the eyes included
    assert not [p for p, a in window.animate.actors().items() if a.GetVisibility()]
    assert not window.animate.timer.isActive()

    window.show_animate()
    qtbot.waitUntil(lambda: window.animate.active, timeout=5_000)
    assert skin.GetVisibility() and not window.scene.visible["skull"]


def test_the_scan_goes_when_the_fit_scan_dock_is_left(qtbot, window, skull_obj, tmp_path):
    """The Fit scan dock draws in the scan's frame: the case is set aside while it is in
    front, and its scan is hidden when the dock is left."""
    from workbench.io.meshes import read_mesh, write_mesh

    window.open_skull(skull_obj, scale=15.0)
    qtbot.waitUntil(lambda: not window.busy, timeout=30_000)
    scan = read_mesh(skull_obj, scale=15.0, kind="skull").mesh  # any surface will do
    path = write_mesh(tmp_path / "scan.ply", scan)
    window.open_scan(path)
    qtbot.waitUntil(lambda: not window.busy and window.scan_fit.has_scan, timeout=60_000)
    tool = window.scan_fit
    (actor,) = tool.actors("scan")
    assert tool.active and actor.GetVisibility() and not window.scene.visible["skull"]

    window.docks["landmarks"].raise_()
    qtbot.waitUntil(lambda: not tool.active, timeout=5_000)
    assert not actor.GetVisibility() and window.scene.visible["skull"]

    window.docks["fit_scan"].raise_()
    qtbot.waitUntil(lambda: tool.active, timeout=5_000)
    assert actor.GetVisibility() and not window.scene.visible["skull"]
