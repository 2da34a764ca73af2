"""What each helper of the main window needs of it, as small typed interfaces.

The guide view, the autosave functions, the CT import dialog and the menu
builder each take a *host* instead of ``window: Any``; each protocol below
names exactly the attributes and methods that user touches, so a change to
:class:`workbench.qt.main_window.MainWindow` that breaks one shows up in
``mypy`` and a test can pass a small stand-in.  ``window()`` is
:meth:`QWidget.window` (the top-level widget: the main window itself), the
parent of dialogs and actions.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    from collections.abc import Callable

    from PySide6.QtWidgets import QDockWidget, QMenuBar, QWidget

    from workbench.qt.document import Document
    from workbench.qt.scene import SceneView
    from workbench.qt.workers import TaskRunner
    from workbench.services.case.case_setup import OpenedCase
    from workbench.services.guides.classic import Guide


class GuideRows(Protocol):
    """The guides shown in the guide view, in their table's row order (the reconstruct panel)."""

    @property
    def guides(self) -> Sequence[Guide]: ...


class GuideDragHost(Protocol):
    """Receives the guide view's drags (the main window's drag tool)."""

    def preview_guide(self, guide: Guide) -> None: ...

    def commit_guide(self, row: int, value: tuple[float, ...] | None) -> None: ...


class AutosaveHost(Protocol):
    """What :func:`workbench.qt.autosave.install_autosave`, ``recover`` and
    ``offer_recovery`` use of the window."""

    document: Document
    messages: list[str]
    interactive: bool
    #: the window's :class:`workbench.qt.autosave.Autosaver`, typed where it is used
    #: (``recover`` annotates it): naming the class here made hosts and autosave import
    #: each other
    autosaver: Any

    def window(self) -> QWidget: ...

    def status(self, text: str) -> None: ...

    def show_error(self, what: str, exc: BaseException) -> None: ...

    def may_discard(self) -> bool: ...

    def replace_case(self, opened: OpenedCase, path: Path | None) -> None: ...


class CtImportHost(Protocol):
    """What :class:`workbench.qt.ct_import.CtImportDialog` uses of the window."""

    @property
    def runner(self) -> TaskRunner: ...

    def window(self) -> QWidget: ...

    def show_error(self, what: str, exc: BaseException) -> None: ...

    def open_ct(
        self,
        path: str | Path,
        tissue: str = "bone",
        iso: float | None = None,
        *,
        volume: Any = None,
        finished: Callable[[bool], None] | None = None,
    ) -> bool: ...


class MenuHost(Protocol):
    """What :func:`workbench.qt.actions.build_menus` uses: the menu bar, the scene's
    layers, the docks, and the method of every action in :data:`workbench.qt.actions.ACTIONS`
    (called by name)."""

    @property
    def scene(self) -> SceneView: ...

    @property
    def docks(self) -> dict[str, QDockWidget]: ...

    def window(self) -> QWidget: ...

    def menuBar(self) -> QMenuBar: ...  # noqa: N802 - Qt name

    def user_toggled_guide_view(self, on: bool) -> None: ...

    # the actions' methods (ActionSpec.method)
    def ask_open_skull(self) -> None: ...
    def ask_open_ct(self) -> None: ...
    def ask_open_case(self) -> None: ...
    def save(self) -> bool: ...
    def ask_save_as(self) -> bool: ...
    def ask_export(self) -> None: ...
    def ask_case_details(self) -> None: ...
    def close(self) -> bool: ...
    def undo(self) -> None: ...
    def redo(self) -> None: ...
    def mark_absent(self) -> None: ...
    def snap_selected(self) -> None: ...
    def select_next_missing(self) -> None: ...
    def suggest_landmarks(self) -> None: ...
    def reconstruct(self) -> None: ...
    def ask_load_truth(self) -> None: ...
    def reset_view(self) -> None: ...
    def ask_screenshot(self) -> None: ...
    def show_portrait(self) -> None: ...


class Feedback(Protocol):
    """Where a tool reports: the status line, readable errors, and notes for the user;
    whether someone is there to answer a question (``interactive``) and the dialogs' parent."""

    messages: list[str]
    interactive: bool

    def status(self, text: str) -> None: ...

    def show_error(self, what: str, exc: BaseException) -> None: ...

    def window(self) -> QWidget: ...


class FileHost(CtImportHost, Protocol):
    """What :class:`workbench.qt.file_ops.FileTool` uses of the window (beyond the
    document, session and worker it is built from): the messages, the dialogs'
    parent, the truth loader and the window picture.  It is also the CT import
    dialog's host and the holder of the autosaver (``forget_snapshot``)."""

    messages: list[str]
    interactive: bool

    def status(self, text: str) -> None: ...

    def status_text(self) -> str: ...

    def load_truth(self, path: str | Path, scale: float | None = None) -> None: ...

    def save_screenshot(self, path: str | Path) -> Path: ...

    def restore_fit(self, stored: Any) -> None:
        """Show a fit kept in a reopened case (a
        :class:`~workbench.services.reconstruction.stored_fit.StoredFit`)."""
