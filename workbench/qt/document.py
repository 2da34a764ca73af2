"""The open case as the window sees it: case + command stack + file, with Qt signals.

:class:`Document` owns nothing geometric.  It forwards the case's psygnal
``changed(part)`` and the stack's ``changed`` as Qt signals, pushes
commands (a refused command becomes a readable message, never a traceback,
and leaves the case as it was), and knows the file the case came from.
Units and frames are the case's (mm, specimen input frame; see
:mod:`workbench.model.case`).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from PySide6.QtCore import QObject, Signal

from workbench.commands.stack import Command, CommandStack
from workbench.core.errors import WorkbenchError
from workbench.model.case import Case

ErrorSink = Callable[[str, BaseException], None]


class Document(QObject):
    """The current case of a window.

    Signals
    -------
    case_replaced()
        A different case was opened (everything must be redrawn).
    part_changed(str)
        A part of the current case was replaced (``"landmarks"``, ``"dowels"`` ...).
    stack_changed()
        Undo/redo availability, labels or the dirty flag may have changed.
    """

    case_replaced = Signal()
    part_changed = Signal(str)
    stack_changed = Signal()

    def __init__(self, on_error: ErrorSink | None = None, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self.on_error = on_error
        self.path: Path | None = None
        self.notes: list[str] = []
        self.case = Case()
        self.stack = CommandStack(self.case)
        self._connect()

    def _connect(self) -> None:
        self.case.events.changed.connect(self._on_part)
        self.stack.changed.connect(self._on_stack)

    def _disconnect(self) -> None:
        self.case.events.changed.disconnect(self._on_part)
        self.stack.changed.disconnect(self._on_stack)

    def _on_part(self, part: str) -> None:
        self.part_changed.emit(part)

    def _on_stack(self) -> None:
        self.stack_changed.emit()

    # ------------------------------------------------------------ lifecycle
    def replace(
        self,
        case: Case,
        stack: CommandStack | None = None,
        path: str | Path | None = None,
        notes: list[str] | None = None,
    ) -> None:
        """Make ``case`` the current case (a fresh history unless ``stack`` is given)."""
        self._disconnect()
        self.case = case
        self.stack = stack if stack is not None else CommandStack(case)
        self.path = Path(path) if path is not None else None
        self.notes = list(notes or [])
        self._connect()
        self.case_replaced.emit()
        self.stack_changed.emit()

    @property
    def has_specimen(self) -> bool:
        return self.case.specimen.mesh is not None

    @property
    def is_dirty(self) -> bool:
        return self.stack.is_dirty

    @property
    def title(self) -> str:
        name = self.path.name if self.path is not None else "untitled case"
        return f"{name}{' *' if self.is_dirty else ''} — Forensic workbench"

    # ------------------------------------------------------------ commands
    def push(self, command: Command, merge: bool = True) -> bool:
        """Run ``command`` through the stack; ``False`` (and a message) if it was refused.

        ``merge=False`` makes it its own undo step even when it could merge
        with the previous command (one drag of a landmark is one step).
        """
        try:
            if merge:
                self.stack.push(command)
            else:
                self.stack.begin_gesture(command.label)
                try:
                    self.stack.push(command)
                except BaseException:
                    self.stack.abort_gesture()
                    raise
                self.stack.commit_gesture()
        except (WorkbenchError, ValueError, KeyError) as exc:
            self._report(f"Could not {command.label[:1].lower() + command.label[1:]}", exc)
            return False
        return True

    def undo(self) -> None:
        if self.stack.can_undo:
            try:
                self.stack.undo()
            except (WorkbenchError, ValueError, KeyError) as exc:
                self._report("Could not undo", exc)

    def redo(self) -> None:
        if self.stack.can_redo:
            try:
                self.stack.redo()
            except (WorkbenchError, ValueError, KeyError) as exc:
                self._report("Could not redo", exc)

    def _report(self, what: str, exc: BaseException) -> None:
        if self.on_error is not None:
            self.on_error(what, exc)
        else:
            raise exc
