"""View ▸ Portrait…: the fitted face as the pictures an appeal would print.

:class:`PortraitDialog` shows the front, three-quarter and profile portraits
of the current case's reconstruction (the fitted head, in its head frame),
drawn by :func:`workbench.render.portrait.make_portrait` at a preview size
(:data:`PREVIEW_PX`) with colour on or off and, by default, the case's own
appearance (the Appearance dock's skin colours, iris, hair, brows and beard;
"Case's appearance"), else a skin tone and an iris colour picked here.
*Save…* asks for a new folder and writes the full-size pictures (PNG and
TIFF, :data:`SAVE_PX` pixels, 300 dpi) and ``portrait.json`` through
:func:`workbench.render.portrait.save_portrait`, the function behind
``workbench portrait``; a folder that is not empty is replaced only when the
user confirms (the old one is kept as ``DIR.1``).

VTK draws on the GUI thread only, so the pictures are rendered there (off
screen; about a second at the preview size, a few seconds at full size).
The dialog is not modal: the window stays usable, and the pictures show the
face that was current when the dialog was opened or last refreshed.
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

import numpy as np
from PySide6.QtCore import Qt
from PySide6.QtGui import QGuiApplication, QImage, QPixmap
from PySide6.QtWidgets import (
    QCheckBox,
    QComboBox,
    QDialog,
    QDialogButtonBox,
    QHBoxLayout,
    QLabel,
    QPushButton,
    QVBoxLayout,
    QWidget,
)

from workbench.core.appearance import DEFAULT_IRIS, DEFAULT_SKIN_TONE, IRIS_COLOURS, SKIN_TONES
from workbench.core.errors import InputError, WorkbenchError

if TYPE_CHECKING:
    from workbench.model.appearance import Appearance
    from workbench.model.template import TemplateHead
    from workbench.render.portrait import Portrait, SavedPortrait

#: the size the previews are rendered at (pixels a side) and shown at
PREVIEW_PX, SHOWN_PX = 600, 300
#: the size Save… writes (pixels a side; 2000 px is 6.7 in at 300 dpi)
SAVE_PX = 2000
TITLES = {"front": "Front", "three_quarter": "Three-quarter (right)", "profile": "Right profile"}


class PortraitHost(Protocol):
    """What the dialog uses of the window: the fit, the case's path, the status and errors."""

    interactive: bool

    @property
    def fit(self) -> Any: ...

    @property
    def document(self) -> Any: ...

    def window(self) -> QWidget: ...

    def status(self, text: str) -> None: ...

    def show_error(self, what: str, exc: BaseException) -> None: ...


def _pixmap(image: np.ndarray, shown: int) -> QPixmap:
    """A ``(h, w, 3)`` uint8 picture as a pixmap ``shown`` pixels a side (smoothly scaled)."""
    rgb = np.ascontiguousarray(image[:, :, :3], dtype=np.uint8)
    h, w, _ = rgb.shape
    qimage = QImage(rgb.data, w, h, 3 * w, QImage.Format.Format_RGB888).copy()
    return QPixmap.fromImage(qimage).scaled(
        shown,
        shown,
        Qt.AspectRatioMode.KeepAspectRatio,
        Qt.TransformationMode.SmoothTransformation,
    )


class PortraitDialog(QDialog):
    """Three portraits of ``head`` with the colour choices, *Save…* and *Close*."""

    def __init__(self, head: TemplateHead, host: PortraitHost, parent: QWidget | None = None):
        super().__init__(parent)
        from workbench.render.portrait import DISCLAIMER, VIEWS

        self.setWindowTitle("Portrait")
        self.setObjectName("portrait")
        self.setModal(False)
        self.head, self.host = head, host
        self.portrait: Portrait | None = None
        self.saved: SavedPortrait | None = None
        self.views: dict[str, QLabel] = {}
        row = QHBoxLayout()
        for view in VIEWS:
            column = QVBoxLayout()
            picture = QLabel()
            picture.setFixedSize(SHOWN_PX, SHOWN_PX)
            picture.setAlignment(Qt.AlignmentFlag.AlignCenter)
            picture.setObjectName(f"portrait_{view}")
            caption = QLabel(TITLES[view])
            caption.setAlignment(Qt.AlignmentFlag.AlignCenter)
            column.addWidget(picture)
            column.addWidget(caption)
            row.addLayout(column)
            self.views[view] = picture
        self.colour = QCheckBox("&Colour")
        self.colour.setChecked(True)
        self.colour.setToolTip("Off: one neutral clay, claiming no colour")
        self.skin_tone = QComboBox()
        self.skin_tone.addItems(list(SKIN_TONES))
        self.skin_tone.setCurrentText(DEFAULT_SKIN_TONE)
        self.skin_tone.setToolTip(
            "Monk Skin Tone swatches mst1-mst10 (light, medium, dark: mst3, mst6, mst9); "
            "an artistic default, not evidence"
        )
        self.iris = QComboBox()
        self.iris.addItems(list(IRIS_COLOURS))
        self.iris.setCurrentText(DEFAULT_IRIS)
        self.case_look = QCheckBox("Case's &appearance")
        self.case_look.setObjectName("portrait_case_appearance")
        chosen = self.appearance_of_case()
        self.case_look.setEnabled(chosen is not None)
        self.case_look.setChecked(chosen is not None)
        self.case_look.setToolTip(
            "The colours, iris, hair and brows chosen in the Appearance dock"
            if chosen is not None
            else "The case has no appearance yet: choose one in the Appearance dock"
        )
        if chosen is not None:
            self.skin_tone.setCurrentText(chosen.tone)
            self.iris.setCurrentText(chosen.iris)
        options = QHBoxLayout()
        options.addWidget(self.colour)
        options.addWidget(self.case_look)
        for title, box in (("&Skin tone", self.skin_tone), ("&Iris", self.iris)):
            label = QLabel(title)
            label.setBuddy(box)
            options.addWidget(label)
            options.addWidget(box)
        options.addStretch(1)
        note = QLabel(f"An {DISCLAIMER}.")
        note.setWordWrap(True)
        self.save_button = QPushButton("&Save…")
        self.save_button.setToolTip(
            f"Write the three portraits at {SAVE_PX} x {SAVE_PX} px (PNG and TIFF, 300 dpi) "
            "and portrait.json into a new folder"
        )
        buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Close)
        buttons.addButton(self.save_button, QDialogButtonBox.ButtonRole.ActionRole)
        buttons.rejected.connect(self.close)
        self.save_button.clicked.connect(self.ask_save)
        layout = QVBoxLayout(self)
        layout.addLayout(row)
        layout.addLayout(options)
        layout.addWidget(note)
        layout.addWidget(buttons)
        self.colour.toggled.connect(self._enable)
        self.case_look.toggled.connect(self._enable)
        self._enable()
        self.colour.toggled.connect(self.refresh)
        self.case_look.toggled.connect(self.refresh)
        self.skin_tone.currentTextChanged.connect(self.refresh)
        self.iris.currentTextChanged.connect(self.refresh)

    def appearance_of_case(self) -> Appearance | None:
        """The case's chosen appearance (the Appearance dock), or None."""
        document = getattr(self.host, "document", None)
        case = getattr(document, "case", None)
        return getattr(case, "appearance", None)

    def _enable(self, *_args: Any) -> None:
        """Tone and iris are picked here only with colour and without the case's appearance."""
        own = self.colour.isChecked() and not self.case_look.isChecked()
        self.skin_tone.setEnabled(own)
        self.iris.setEnabled(own)

    def options(self) -> dict[str, Any]:
        """The choices as :func:`~workbench.render.portrait.make_portrait` options."""
        chosen = self.appearance_of_case() if self.case_look.isChecked() else None
        return {
            "colour": self.colour.isChecked(),
            "skin_tone": self.skin_tone.currentText(),
            "iris": self.iris.currentText(),
            "appearance": chosen,
        }

    def refresh(self) -> bool:
        """Render the previews (GUI thread, off screen); False when that failed."""
        from workbench.render.portrait import make_portrait

        QGuiApplication.setOverrideCursor(Qt.CursorShape.WaitCursor)
        try:
            portrait = make_portrait(self.head, size=PREVIEW_PX, **self.options())
        except (WorkbenchError, ValueError, RuntimeError) as exc:
            self.host.show_error("The portrait could not be drawn", exc)
            return False
        finally:
            QGuiApplication.restoreOverrideCursor()
        self.portrait = portrait
        for view, label in self.views.items():
            label.setPixmap(_pixmap(portrait.images[view], SHOWN_PX))
        return True

    # ------------------------------------------------------------ save
    def ask_save(self) -> None:
        """Ask for a new folder (starting in the case file's folder) and save there."""
        from workbench.qt import dialogs

        case_path = getattr(self.host.document, "path", None)
        suggested = dialogs.start_folder(case_path) / "portrait"
        name = dialogs.ask_new_folder(self, "Save the portraits (a new folder)", suggested)
        if name:
            self.save_to(name)

    def save_to(self, folder: str | Path, force: bool = False, size: int = SAVE_PX) -> bool:
        """Write the portraits at ``size`` into ``folder`` as ``workbench portrait`` does.

        A non-empty ``folder`` is replaced (kept as ``DIR.1``) only with
        ``force`` or when the user confirms; False when refused or failed.
        """
        from workbench.qt import dialogs
        from workbench.qt.tools.common import folder_is_free
        from workbench.render.portrait import save_portrait

        out = Path(folder)
        if not force and not folder_is_free(out):
            if not (
                self.host.interactive and dialogs.ask_replace_folder(self, out, "the portraits")
            ):
                self.host.show_error(
                    "The portraits were not saved",
                    InputError(
                        out,
                        "already exists and is not empty; refusing to replace it",
                        "choose a new folder name, or confirm replacing it",
                    ),
                )
                return False
            force = True
        QGuiApplication.setOverrideCursor(Qt.CursorShape.WaitCursor)
        try:
            self.saved = save_portrait(
                self.head, out, force=force, size=size, notify=self.host.status, **self.options()
            )
        except (WorkbenchError, OSError, ValueError, RuntimeError) as exc:
            self.host.show_error("The portraits were not saved", exc)
            return False
        finally:
            QGuiApplication.restoreOverrideCursor()
        seconds = self.saved.summary["seconds"].get("render", 0.0)
        self.host.status(
            f"Portraits saved to {out} ({len(self.saved.files)} views, {size} px, PNG and "
            f"TIFF; {seconds:.1f} s)."
        )
        return True


def open_portrait(host: PortraitHost) -> PortraitDialog | None:
    """Open the dialog for the current fitted face (None, with a status line, when there
    is none); the previews are rendered before it shows."""
    fit = host.fit
    if fit is None:
        host.status(
            "No face to portray yet: reconstruct the face first (Tools ▸ Reconstruct face)."
        )
        return None
    dialog = PortraitDialog(fit.recon.head, host, host.window())
    dialog.refresh()
    dialog.show()
    return dialog
