"""File ▸ Case details…: the examiner's name and the case notes, edited in the window.

:class:`CaseDetailsDialog` shows the case's identity (id, created, the
software that made it; read only) and edits the two free-text fields of
``case.meta``: the examiner, the person responsible for the case, whom the
reconstruction report names (``report.json`` ``"examiner"`` and the PDF's
first page), and the notes.  OK applies both as one
:class:`~workbench.commands.case_edits.SetCaseDetails` on the case's undo
stack, so Edit ▸ Undo takes back both and the audit log records the step
like any other edit; nothing changed, nothing is pushed.

The dialog is window-modal but opened with ``open()`` (it does not block), so
a test or a script can fill it and call ``accept()``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

from PySide6.QtCore import Qt
from PySide6.QtWidgets import (
    QDialog,
    QDialogButtonBox,
    QFormLayout,
    QLabel,
    QLineEdit,
    QPlainTextEdit,
    QVBoxLayout,
    QWidget,
)

from workbench.commands.case_edits import SetCaseDetails

if TYPE_CHECKING:
    from workbench.model.meta import CaseMeta
    from workbench.qt.document import Document


class CaseDetailsHost(Protocol):
    """What the dialog uses of the window: the open case, the dialog's parent, the status."""

    document: Document

    def window(self) -> QWidget: ...

    def status(self, text: str) -> None: ...


class CaseDetailsDialog(QDialog):
    """The examiner's name and the case notes of ``meta``, with OK and Cancel."""

    def __init__(self, meta: CaseMeta, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setWindowTitle("Case details")
        self.setObjectName("case_details")
        self.meta = meta
        form = QFormLayout()
        for title, value in (
            ("Case id", meta.case_id),
            ("Created (UTC)", meta.created or "–"),
            ("Made with", f"workbench {meta.software_version}" if meta.software_version else "–"),
        ):
            label = QLabel(value)
            label.setTextInteractionFlags(Qt.TextInteractionFlag.TextSelectableByMouse)
            form.addRow(title, label)
        self.examiner = QLineEdit(meta.examiner)
        self.examiner.setPlaceholderText("the person responsible for the case")
        self.examiner.setToolTip("Printed as the examiner on the first page of the report")
        form.addRow("&Examiner", self.examiner)
        self.notes = QPlainTextEdit(meta.notes)
        self.notes.setPlaceholderText("e.g. how and when the skull was received")
        self.notes.setTabChangesFocus(True)
        form.addRow("&Notes", self.notes)
        buttons = QDialogButtonBox(
            QDialogButtonBox.StandardButton.Ok | QDialogButtonBox.StandardButton.Cancel
        )
        buttons.accepted.connect(self.accept)
        buttons.rejected.connect(self.reject)
        layout = QVBoxLayout(self)
        layout.addLayout(form)
        layout.addWidget(buttons)
        self.resize(460, 320)

    def values(self) -> tuple[str, str]:
        """The examiner (spaces trimmed) and the notes (trailing blanks trimmed)."""
        return self.examiner.text().strip(), self.notes.toPlainText().rstrip()

    def command(self, current: CaseMeta | None = None) -> SetCaseDetails | None:
        """The edit the fields ask for, or None if ``current`` (default: the meta the dialog
        opened with) already has them."""
        meta = current if current is not None else self.meta
        examiner, notes = self.values()
        if (examiner, notes) == (meta.examiner, meta.notes):
            return None
        return SetCaseDetails(examiner, notes)


def open_case_details(host: CaseDetailsHost) -> CaseDetailsDialog:
    """Open the dialog over the window for the current case; OK pushes its one command."""
    case = host.document.case
    dialog = CaseDetailsDialog(case.meta, host.window())

    def apply() -> None:
        if host.document.case is not case:  # another case was opened meanwhile
            host.status("Case details not changed: another case was opened meanwhile.")
            return
        command = dialog.command(case.meta)
        if command is None:
            return
        if host.document.push(command):  # its own step: it never merges
            examiner = command.examiner or "none"
            host.status(f"Case details changed (examiner: {examiner}); Undo takes them back.")

    dialog.accepted.connect(apply)
    dialog.open()
    return dialog
