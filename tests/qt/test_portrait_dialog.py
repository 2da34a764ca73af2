"""View ▸ Portrait… (issue 34 item 4): the fitted face's portraits in a non-modal dialog, with
colour on or off, and Save… writing the full pictures as ``workbench portrait`` does.

Most tests stand the window in with a small host holding the male reference head as the
fit's head (head frame, mm); one fits the real skull (``skull.obj`` x 15 mm with the
suggested landmarks) in a real window, opens the dialog from the menu action and saves.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

pytest.importorskip("pytestqt")
if os.environ.get("QT_QPA_PLATFORM") != "xcb":
    pytest.skip(
        "the 3D view needs QT_QPA_PLATFORM=xcb under Xvfb (see HEADLESS.md)",
        allow_module_level=True,
    )

pytestmark = pytest.mark.gui


class _Host:
    """The window as the dialog sees it: a fit whose head is ``head`` (or none)."""

    interactive = False

    def __init__(self, qtbot, head=None) -> None:
        from PySide6.QtWidgets import QWidget

        self.fit = None if head is None else SimpleNamespace(recon=SimpleNamespace(head=head))
        self.document = SimpleNamespace(path=None)
        self.messages: list[str] = []
        self.errors: list[str] = []
        self._window = QWidget()
        qtbot.addWidget(self._window)

    def window(self):
        return self._window

    def status(self, text: str) -> None:
        self.messages.append(text)

    def show_error(self, what: str, exc: BaseException) -> None:
        self.errors.append(f"{what}: {exc}")


def _files(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


def test_the_dialog_shows_three_previews_and_follows_the_colour(qtbot, head_male) -> None:
    from workbench.qt.portrait_dialog import SHOWN_PX, open_portrait

    host = _Host(qtbot, head_male)
    dialog = open_portrait(host)
    assert dialog is not None
    qtbot.addWidget(dialog)
    assert dialog.isVisible() and not dialog.isModal()
    for label in dialog.views.values():
        pixmap = label.pixmap()
        assert not pixmap.isNull() and max(pixmap.width(), pixmap.height()) == SHOWN_PX
    assert dialog.portrait is not None and dialog.portrait.colour
    dialog.skin_tone.setCurrentText("mst2")
    assert dialog.portrait.skin_tone == "mst2"
    dialog.colour.setChecked(False)  # clay: no hue, the colour choices greyed
    image = dialog.portrait.images["front"].astype(int)
    assert not dialog.portrait.colour and (image.max(axis=2) - image.min(axis=2)).max() <= 3
    assert not dialog.skin_tone.isEnabled() and not dialog.iris.isEnabled()
    assert not host.errors


def test_save_writes_the_portrait_folder_and_keeps_an_old_one(qtbot, head_male, tmp_path) -> None:
    from PIL import Image

    from workbench.qt.portrait_dialog import PortraitDialog

    host = _Host(qtbot, head_male)
    dialog = PortraitDialog(head_male, host)
    qtbot.addWidget(dialog)
    dialog.iris.setCurrentText("blue")
    out = tmp_path / "portrait"
    assert dialog.save_to(out, size=256)
    assert _files(out) == sorted(
        ["portrait.json"]
        + [
            f"portrait_{v}.{e}"
            for v in ("front", "three_quarter", "profile")
            for e in ("png", "tif")
        ]
    )
    assert Image.open(out / "portrait_front.png").size == (256, 256)
    summary = json.loads((out / "portrait.json").read_text())
    assert summary["iris"] == "blue" and summary["colour"] is True
    assert any("Portraits saved" in m for m in host.messages)
    # not interactive: a folder that is not empty is not replaced without force
    assert not dialog.save_to(out, size=256)
    assert any("already exists" in e for e in host.errors)
    assert dialog.save_to(out, force=True, size=256)
    assert (tmp_path / "portrait.1" / "portrait.json").is_file()


def test_without_a_fit_the_dialog_says_what_to_do(qtbot) -> None:
    from workbench.qt.portrait_dialog import open_portrait

    host = _Host(qtbot)
    assert open_portrait(host) is None
    assert "reconstruct the face first" in host.messages[-1]


@pytest.fixture
def fitted(qtbot, window, skull_obj, skull_obj_suggested):
    from workbench.commands.landmarks import ReplaceLandmarkSet

    window.show_portrait()  # no face yet: a status line, no dialog
    assert window.portrait is None and "reconstruct the face first" in window.status_text()
    window.open_skull(skull_obj, scale=15.0)
    qtbot.waitUntil(lambda: not window.busy, timeout=30_000)
    _, landmarks = skull_obj_suggested
    window.reconstruct_panel.auto_refit.setChecked(False)
    assert window.document.push(ReplaceLandmarkSet("skull", landmarks, "Suggest skull landmarks"))
    window.reconstruct()
    assert window.wait_idle(180) and not window.errors, window.errors
    return window


def test_the_menu_opens_the_portrait_of_the_fitted_face_and_saves(fitted, tmp_path) -> None:
    from PIL import Image

    window = fitted
    window.actions_by_id["portrait"].trigger()
    dialog = window.portrait
    assert dialog is not None and dialog.isVisible()
    assert dialog.head is window.fit.recon.head  # the fitted head, in its head frame
    image = dialog.portrait.images["front"]
    cam = dialog.portrait.cameras["front"]
    framed = dialog.portrait.head
    left = framed.eye_centres[np.argmax(framed.eye_centres[:, 0])]
    assert cam.project(left[None], image.shape[0])[0, 0] > image.shape[1] / 2  # not mirrored
    out = tmp_path / "appeal"
    assert dialog.save_to(out, size=400)
    assert Image.open(out / "portrait_profile.tif").size == (400, 400)
    assert not window.errors, window.errors
    dialog.close()


def test_the_case_appearance_with_hair_is_drawn_by_default(qtbot, head_male) -> None:
    """A case with an appearance (Appearance dock): the dialog draws its colours and hair;
    unticked, the dialog's own tone and iris apply again, without the hair."""
    from workbench.model.appearance import Appearance
    from workbench.qt.portrait_dialog import open_portrait

    look = Appearance(tone="mst8", iris="blue", grooming={"hair": "buzz", "brows": "thick"})
    host = _Host(qtbot, head_male)
    host.document = SimpleNamespace(path=None, case=SimpleNamespace(appearance=look))
    dialog = open_portrait(host)
    assert dialog is not None
    qtbot.addWidget(dialog)
    assert dialog.case_look.isChecked() and not dialog.skin_tone.isEnabled()
    portrait = dialog.portrait
    assert portrait.skin_tone == "mst8" and portrait.iris == "blue"
    assert dict(portrait.grooming) == {"hair": "buzz", "brows": "thick"}
    with_hair = portrait.images["profile"].astype(int)
    dialog.case_look.setChecked(False)
    assert dialog.skin_tone.isEnabled() and dialog.portrait.grooming == ()
    bare = dialog.portrait.images["profile"].astype(int)
    # the top of the head is darker with hair (the dark brown preset) than bare skin
    top = slice(0, with_hair.shape[0] // 3)
    assert with_hair[top].mean() < bare[top].mean() - 5.0
    assert not host.errors


def test_without_a_case_appearance_the_option_is_off(qtbot, head_male) -> None:
    from workbench.qt.portrait_dialog import open_portrait

    host = _Host(qtbot, head_male)
    dialog = open_portrait(host)
    qtbot.addWidget(dialog)
    assert not dialog.case_look.isEnabled() and not dialog.case_look.isChecked()
    assert dialog.options()["appearance"] is None
