"""Undoable commands and the one command stack of a case.

Every change to a :class:`~workbench.model.case.Case` goes through a
:class:`Command` pushed on the case's :class:`CommandStack` (glue's pure-Python
stack, not ``QUndoStack``, so undo lives below Qt and is tested headless).

Design
------
- A command is a small dataclass.  ``do(case)`` validates first and raises
  before changing anything, then replaces whole parts; it keeps the previous
  value by reference so ``undo(case)`` is exact and cheap (parts are
  immutable).  ``redo`` defaults to ``do``.
- ``merge_with(next)`` lets consecutive edits of the same thing (one slider
  drag, repeated moves of one landmark) collapse into one undo step.  Merging
  only happens between consecutive pushes: undo, redo, ``set_clean``, a
  finished group or gesture all close the merge window.
- ``group(label)`` and ``begin_gesture`` / ``commit_gesture`` /
  ``abort_gesture`` collect commands into one :class:`MacroCommand` step.  A
  failing group and an aborted gesture undo what they did, in reverse order.
- Audit: each top-level ``do``, ``undo`` and ``redo`` calls ``stack.audit``
  with one record (default: the case's append-only audit log).  Commands
  inside an open group or gesture are audited once, when it is committed (as
  one record listing them) or aborted (``action="abort"``).
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable, Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np
from psygnal import Signal

from workbench.core.errors import WorkbenchError
from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh
from workbench.model.audit import make_record
from workbench.model.case import Case
from workbench.model.evidence import EvidenceFile
from workbench.model.landmarks import landmark_set_to_state

AuditHook = Callable[[Mapping[str, Any]], None]


class CommandError(WorkbenchError):
    """A command or stack operation that cannot be carried out."""


def to_jsonable(value: Any) -> Any:
    """A JSON-able summary of a command field for the audit log.

    Arrays become lists (NaN → ``None``); meshes become their size and vertex
    hash; landmark sets and evidence files their state.
    """
    if isinstance(value, Mesh):
        digest = hashlib.sha256(value.vertices.tobytes() + value.faces.tobytes()).hexdigest()
        return {"n_vertices": value.n_vertices, "n_faces": value.n_faces, "sha256": digest}
    if isinstance(value, LandmarkSet):
        return landmark_set_to_state(value)
    if isinstance(value, EvidenceFile):
        return value.to_state()
    if isinstance(value, np.ndarray):
        return to_jsonable(value.tolist())
    if isinstance(value, Mapping):
        return {str(k): to_jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [to_jsonable(v) for v in value]
    if isinstance(value, (np.generic,)):
        return to_jsonable(value.item())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    return repr(value)


@dataclass(eq=False)
class Command:
    """Base of every undoable change to a case.

    Subclasses are dataclasses whose fields are the command's parameters;
    ``label`` (keyword-only) is what the Edit menu shows and defaults to
    :meth:`default_label`.
    """

    label: str = field(default="", kw_only=True)

    def __post_init__(self) -> None:
        if not self.label:
            self.label = self.default_label()

    def default_label(self) -> str:
        return type(self).__name__

    def do(self, case: Case) -> None:
        """Apply the change; must raise before changing anything if it cannot."""
        raise NotImplementedError

    def undo(self, case: Case) -> None:
        """Put back exactly what :meth:`do` replaced."""
        raise NotImplementedError

    def redo(self, case: Case) -> None:
        self.do(case)

    def merge_with(self, other: Command) -> bool:
        """Absorb ``other`` (already done) into this command; ``True`` if merged."""
        return False

    def parameters(self) -> dict[str, Any]:
        """JSON parameters for the audit log (public dataclass fields but ``label``)."""
        return {
            f.name: to_jsonable(getattr(self, f.name))
            for f in fields(self)
            if f.init and f.name != "label" and not f.name.startswith("_")
        }

    def table_ids(self) -> tuple[str, ...]:
        """Ids of the data tables this command used (for the audit log)."""
        return ()


@dataclass(eq=False)
class MacroCommand(Command):
    """Several already-done commands treated as one undo step."""

    commands: list[Command] = field(default_factory=list)

    def do(self, case: Case) -> None:
        for command in self.commands:
            command.redo(case)

    def undo(self, case: Case) -> None:
        for command in reversed(self.commands):
            command.undo(case)

    def parameters(self) -> dict[str, Any]:
        return {"commands": [describe(c) for c in self.commands]}

    def table_ids(self) -> tuple[str, ...]:
        ids = [t for c in self.commands for t in c.table_ids()]
        return tuple(dict.fromkeys(ids))


def describe(command: Command) -> dict[str, Any]:
    """``{"command", "label", "parameters"}`` of one command."""
    return {
        "command": type(command).__name__,
        "label": command.label,
        "parameters": command.parameters(),
    }


@dataclass
class _Frame:
    kind: str  # "group" or "gesture"
    label: str
    commands: list[Command] = field(default_factory=list)


class CommandStack:
    """The linear undo history of one case.

    Parameters
    ----------
    case : Case
        The document every command acts on.
    audit : callable, optional
        ``audit(record)`` for every do/undo/redo; defaults to ``case.audit.append``.
    """

    changed = Signal()

    def __init__(self, case: Case, audit: AuditHook | None = None) -> None:
        self.case = case
        self._audit_hook = audit
        self._undo: list[Command] = []
        self._redo: list[Command] = []
        self._clean: int | None = 0
        self._merge_open = False
        self._frames: list[_Frame] = []

    # ------------------------------------------------------------ state
    @property
    def audit(self) -> AuditHook:
        """Where audit records go: the hook given, else the case's current audit log."""
        return self._audit_hook if self._audit_hook is not None else self.case.audit.append

    @audit.setter
    def audit(self, hook: AuditHook | None) -> None:
        self._audit_hook = hook

    @property
    def can_undo(self) -> bool:
        return bool(self._undo) and not self._frames

    @property
    def can_redo(self) -> bool:
        return bool(self._redo) and not self._frames

    @property
    def undo_text(self) -> str:
        return self._undo[-1].label if self._undo else ""

    @property
    def redo_text(self) -> str:
        return self._redo[-1].label if self._redo else ""

    @property
    def is_dirty(self) -> bool:
        return self._clean != len(self._undo)

    @property
    def in_gesture(self) -> bool:
        return any(f.kind == "gesture" for f in self._frames)

    def __len__(self) -> int:
        return len(self._undo)

    def set_clean(self) -> None:
        """Mark the current state as saved."""
        self._clean = len(self._undo)
        self._merge_open = False
        self.changed.emit()

    def clear(self) -> None:
        """Forget all history (the case is left as it is, and so is the dirty flag)."""
        self._check_idle("clear the history")
        dirty = self.is_dirty
        self._undo.clear()
        self._redo.clear()
        self._clean = None if dirty else 0
        self._merge_open = False
        self.changed.emit()

    # ------------------------------------------------------------ push / undo / redo
    def push(self, command: Command) -> None:
        """Execute ``command`` and record it (merging with the previous one if it can)."""
        command.do(self.case)
        if self._frames:
            frame = self._frames[-1]
            if not (frame.commands and frame.commands[-1].merge_with(command)):
                frame.commands.append(command)
            return
        if self._merge_open and self._undo and self._undo[-1].merge_with(command):
            if self._clean == len(self._undo):
                self._clean = None
        else:
            self._add_step(command)
        self._merge_open = True
        self._audit("do", command)
        self.changed.emit()

    def undo(self) -> None:
        """Undo the last step (a command, merged commands, a group or a gesture)."""
        self._check_idle("undo")
        if not self._undo:
            raise CommandError("there is nothing to undo")
        command = self._undo.pop()
        try:
            command.undo(self.case)
        except BaseException:
            self._undo.append(command)
            raise
        self._redo.append(command)
        self._finish("undo", command)

    def redo(self) -> None:
        """Redo the last undone step."""
        self._check_idle("redo")
        if not self._redo:
            raise CommandError("there is nothing to redo")
        command = self._redo.pop()
        try:
            command.redo(self.case)
        except BaseException:
            self._redo.append(command)
            raise
        self._undo.append(command)
        self._finish("redo", command)

    # ------------------------------------------------------------ groups and gestures
    @contextmanager
    def group(self, label: str) -> Iterator[CommandStack]:
        """Collect the commands pushed inside the block into one undo step.

        An exception inside the block undoes those commands (newest first)
        and is re-raised.
        """
        frame = self._open("group", label)
        try:
            yield self
        except BaseException as error:
            self._unwind(frame, f"{type(error).__name__}: {error}")
            raise
        if self._frames[-1] is not frame:
            self._unwind(frame, "a gesture was left open inside the group")
            raise CommandError(f"a gesture was left open inside group {label!r}")
        self._close(frame)

    def begin_gesture(self, label: str) -> None:
        """Start a gesture (a mouse drag): pushes until commit form one step."""
        if self.in_gesture:
            raise CommandError("a gesture is already in progress")
        self._open("gesture", label)

    def commit_gesture(self) -> None:
        """End the gesture: everything pushed since it began becomes one undo step."""
        self._close(self._gesture_frame())

    def abort_gesture(self) -> None:
        """Undo everything done since :meth:`begin_gesture` (Esc during a drag)."""
        self._unwind(self._gesture_frame(), "aborted")

    # ------------------------------------------------------------ internals
    def _add_step(self, command: Command) -> None:
        if self._clean is not None and self._clean > len(self._undo):
            self._clean = None  # the saved state was in the redo history
        self._redo.clear()
        self._undo.append(command)

    def _finish(self, action: str, command: Command) -> None:
        self._merge_open = False
        self._audit(action, command)
        self.changed.emit()

    def _audit(self, action: str, command: Command, **extra: Any) -> None:
        record = make_record(
            action,
            command.label,
            self.case.meta.examiner,
            {**command.parameters(), **extra},
            command.table_ids(),
            type(command).__name__,
        )
        self.audit(record)

    def _check_idle(self, what: str) -> None:
        if self._frames:
            kind = self._frames[-1].kind
            raise CommandError(f"cannot {what} while a {kind} is in progress")

    def _open(self, kind: str, label: str) -> _Frame:
        frame = _Frame(kind, label)
        self._frames.append(frame)
        if len(self._frames) == 1:
            self.changed.emit()
        return frame

    def _gesture_frame(self) -> _Frame:
        if not self._frames or self._frames[-1].kind != "gesture":
            raise CommandError("no gesture is in progress")
        return self._frames[-1]

    def _close(self, frame: _Frame) -> None:
        self._frames.pop()
        if not frame.commands:
            if not self._frames:
                self.changed.emit()
            return
        macro = MacroCommand(commands=frame.commands, label=frame.label)
        if self._frames:
            self._frames[-1].commands.append(macro)
            return
        self._add_step(macro)
        self._finish("do", macro)

    def _unwind(self, frame: _Frame, reason: str) -> None:
        """Undo ``frame`` and every frame opened inside it, newest first."""
        while self._frames:
            top = self._frames.pop()
            for command in reversed(top.commands):
                command.undo(self.case)
            if top.commands:
                macro = MacroCommand(commands=top.commands, label=top.label)
                self._audit("abort", macro, reason=reason)
            if top is frame:
                break
        if not self._frames:
            self.changed.emit()
