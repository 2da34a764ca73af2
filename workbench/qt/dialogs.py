"""Small dialogs: readable error messages, units of a mesh file, file choosers.

Errors are shown as their message (:class:`~workbench.core.errors.WorkbenchError`
messages name the file and the problem); an unexpected exception shows its
type and message with the traceback under "Show Details…", never as the
main text.  When the window is not interactive (tests, ``--screenshot``)
dialogs are not shown; the message goes to ``window.messages`` instead.
"""

from __future__ import annotations

import re
import traceback
from pathlib import Path

from PySide6.QtWidgets import QInputDialog, QMessageBox, QWidget

from workbench.core.errors import WorkbenchError

UNITS = ("mm", "cm", "m", "in", "other scale factor…")


def error_text(what: str, exc: BaseException) -> tuple[str, str]:
    """``(message, details)`` for a failed action."""
    if isinstance(exc, WorkbenchError):
        return f"{what}.\n\n{exc}", ""
    if isinstance(exc, (OSError, ValueError, KeyError)):
        return f"{what}.\n\n{type(exc).__name__}: {exc}", ""
    details = getattr(exc, "worker_traceback", "") or "".join(
        traceback.format_exception(type(exc), exc, exc.__traceback__)
    )
    return (
        f"{what}.\n\nUnexpected error ({type(exc).__name__}: {exc}). The case is "
        "unchanged; please report this with the details below."
    ), details


def show_error(parent: QWidget, what: str, exc: BaseException) -> QMessageBox:
    """A modal-less warning box with the readable message (returned for tests)."""
    text, details = error_text(what, exc)
    box = QMessageBox(
        QMessageBox.Icon.Warning, "Forensic workbench", text, QMessageBox.StandardButton.Ok, parent
    )
    if details:
        box.setDetailedText(details)
    box.open()
    return box


def _in_window_words(problem: str) -> str:
    """A units problem as the command line says it, with its option advice replaced by what
    the dialog offers (issue 33: the window's dialog spoke of ``--scale``)."""
    text = re.sub(
        r"confirm with --units (\w+), or give --scale or a reference length",
        r"choose \1 below, or 'other scale factor…' for a factor of your own",
        problem,
    )
    return text.replace(
        "give --scale or scale to a reference length",
        "choose 'other scale factor…' below (millimetres per file unit)",
    )


def ask_units(parent: QWidget, file_name: str, problem: str) -> float | None:
    """Ask for the units of a mesh whose size does not look like mm; returns the mm factor."""
    choice, ok = QInputDialog.getItem(
        parent,
        "Units of the mesh file",
        f"{file_name}: {_in_window_words(problem)}\n\nWhich unit are the file's numbers in?",
        list(UNITS),
        0,
        False,
    )
    if not ok:
        return None
    factors = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}
    if choice in factors:
        return factors[choice]
    value, ok = QInputDialog.getDouble(
        parent, "Scale factor", "Millimetres per file unit:", 1.0, 1e-6, 1e6, 4
    )
    return value if ok else None


def ask_save_changes(parent: QWidget, name: str) -> QMessageBox.StandardButton:
    return QMessageBox.question(
        parent,
        "Unsaved changes",
        f"Save the changes to {name}?",
        QMessageBox.StandardButton.Save
        | QMessageBox.StandardButton.Discard
        | QMessageBox.StandardButton.Cancel,
        QMessageBox.StandardButton.Save,
    )


def ask_replace_folder(parent: QWidget, folder: object, what: str) -> bool:
    """Ask before replacing a folder that is not empty with ``what``; True: replace it.

    Nothing is deleted: the previous folder is kept beside the new one as a
    numbered copy (``DIR.1``, :func:`workbench.io.outputs.staged_folder`).
    """
    answer = QMessageBox.question(
        parent,
        "Replace the folder?",
        f"{folder} already exists and is not empty.\n\nReplace it with {what}? (The old "
        "folder is kept beside it as a numbered copy.)",
        QMessageBox.StandardButton.Yes | QMessageBox.StandardButton.Cancel,
        QMessageBox.StandardButton.Cancel,
    )
    return answer == QMessageBox.StandardButton.Yes


def start_folder(case_path: object | None) -> Path:
    """Where a dialog for an output folder opens: the case file's folder, else the home
    folder (never the folder of the evidence, which the outputs must not clutter)."""
    if case_path is not None:
        return Path(str(case_path)).parent
    return Path.home()


def ask_new_folder(parent: QWidget, title: str, suggested: Path) -> str:
    """Ask for an output folder, which may be a new name (the folder is made by the writer);
    ``suggested`` (a path) is offered.  "" when cancelled."""
    from PySide6.QtWidgets import QFileDialog

    name, _ = QFileDialog.getSaveFileName(parent, title, str(suggested), "Folders (*)")
    return name
