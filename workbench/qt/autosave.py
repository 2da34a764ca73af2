"""Autosave of the open case, and recovery of unsaved work after a crash.

Each window session (one :class:`Autosaver` per window, a random session
id) keeps at most one *snapshot* of its case in the autosave folder:

``autosave-<session>.fcase``
    A complete, loadable case file written by
    :func:`workbench.io.case_file.write_case_snapshot`: evidence bytes
    included, the case itself untouched (no ``save`` audit record, no change
    to ``meta``, ``source_path`` or the undo stack).
``autosave-<session>.json``
    A small sidecar: who wrote it (pid, hostname, session start), when, the
    case's original file (or ``null`` for an untitled case), a title, the
    number of undo steps and the specimen's file name.

The folder is ``$WORKBENCH_AUTOSAVE_DIR``, else Qt's ``AppDataLocation``
plus ``/autosave``.  A timer (every 60 s; ``$WORKBENCH_AUTOSAVE_S``
overrides, ``0`` disables) writes a snapshot when the case has unsaved
changes made since the previous snapshot; a case that becomes clean again
(saved, or undone back to its saved state) has its snapshot removed.  Only a
frozen copy is taken on the GUI thread (well under a millisecond: parts are
immutable and shared); encoding, compressing and copying the evidence run in
a worker thread (about 0.2 s for the 100k-triangle skull case).

A successful Save, a deliberate Discard and a clean close delete the
session's snapshot.  After a crash the files stay behind: at the next
interactive start :func:`offer_recovery` asks "Recover / Discard / Later"
for each snapshot whose owner process is gone (:func:`find_recoverable`).

Recovery (:func:`recover`) opens the snapshot as the current case, marked
unsaved (title with ``*``).  It remembers the case's original file: **Save**
writes to that file (only when the user saves; nothing is written there
before), and an untitled case asks for a name (Save As).  The recovered
snapshot becomes this session's own snapshot, so it is deleted as soon as the
recovered case is saved or discarded, and a second crash leaves exactly one
snapshot.  The undo history before the crash is not recoverable; the audit
log is (it is in the snapshot), and recovery adds a ``do`` record "Recover
unsaved work" naming the snapshot.
"""

from __future__ import annotations

import contextlib
import functools
import json
import math
import os
import socket
import sys
import time
import uuid
from collections.abc import Iterable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

from PySide6.QtCore import QObject, QStandardPaths, QTimer, Signal
from PySide6.QtWidgets import QMessageBox, QWidget

from workbench.commands.stack import Command, CommandStack
from workbench.core.errors import InputError, WorkbenchError
from workbench.core.json_limits import read_json
from workbench.io.atomic import write_text_atomic
from workbench.io.case_file import (
    detached_copy,
    load_case,
    read_case_json,
    write_case_snapshot,
)
from workbench.model.case import Case
from workbench.qt import relay
from workbench.services.case.case_setup import OpenedCase

if TYPE_CHECKING:
    from workbench.qt.hosts import AutosaveHost

ENV_INTERVAL = "WORKBENCH_AUTOSAVE_S"
ENV_FOLDER = "WORKBENCH_AUTOSAVE_DIR"
DEFAULT_INTERVAL_S = 60.0
PREFIX = "autosave-"
SIDECAR_FORMAT = "workbench-autosave"
SIDECAR_VERSION = 1
#: largest description (sidecar) file read; the workbench writes a few hundred bytes
MAX_SIDECAR_BYTES = 1024 * 1024
#: a snapshot written on another computer is only offered once it is this old (s)
FOREIGN_STALE_S = 24 * 3600.0
#: how long a Save / Discard / close waits for a snapshot being written (s)
WRITE_WAIT_S = 60.0


# ---------------------------------------------------------------- settings
def autosave_interval_s() -> float:
    """Seconds between autosaves: ``$WORKBENCH_AUTOSAVE_S`` or 60; 0 disables."""
    text = os.environ.get(ENV_INTERVAL, "").strip()
    if not text:
        return DEFAULT_INTERVAL_S
    try:
        value = float(text)
    except ValueError:
        return DEFAULT_INTERVAL_S
    return value if math.isfinite(value) and value > 0 else 0.0  # negative, NaN: off


def autosave_folder() -> Path:
    """``$WORKBENCH_AUTOSAVE_DIR``, else the application data folder + ``autosave``."""
    text = os.environ.get(ENV_FOLDER, "").strip()
    if text:
        return Path(text).expanduser()
    base = QStandardPaths.writableLocation(QStandardPaths.StandardLocation.AppDataLocation)
    if not base:
        import tempfile

        base = str(Path(tempfile.gettempdir()) / "forensic-workbench")
    return Path(base) / "autosave"


# ---------------------------------------------------------------- processes
#: every session of this process started after this (earlier processes: before)
_IMPORTED_AT = time.time()


def _proc_stat(pid: int) -> list[str] | None:
    """Fields 3... of ``/proc/<pid>/stat`` (Linux), or None."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text(encoding="ascii", errors="replace")
    except OSError:
        return None
    return text.rsplit(")", 1)[-1].split()


def _process_start(pid: int) -> float | None:
    """Start time of ``pid`` (epoch seconds) where the system tells it (Linux), else None."""
    fields = _proc_stat(pid)
    if fields is None or len(fields) < 20:
        return None
    try:
        with open("/proc/stat", encoding="ascii") as stream:
            boot = next(float(line.split()[1]) for line in stream if line.startswith("btime"))
        return boot + int(fields[19]) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, StopIteration, IndexError):
        return None


def _pid_alive(pid: int) -> bool:
    """Whether a process ``pid`` exists on this computer (zombies count as gone)."""
    if pid <= 0:
        return False
    if sys.platform == "win32":
        import ctypes

        kernel = ctypes.windll.kernel32
        handle = kernel.OpenProcess(0x1000, False, pid)  # PROCESS_QUERY_LIMITED_INFORMATION
        if not handle:
            return kernel.GetLastError() == 5  # access denied: it exists
        code = ctypes.c_ulong()
        try:
            ok = kernel.GetExitCodeProcess(handle, ctypes.byref(code))
        finally:
            kernel.CloseHandle(handle)
        return bool(ok) and code.value == 259  # STILL_ACTIVE
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    except OSError:
        return False
    fields = _proc_stat(pid)
    return not (fields and fields[0] in ("Z", "X"))


def owner_alive(pid: int, hostname: str, session_started: float, last_written: float) -> bool:
    """Whether the session that wrote a sidecar may still be running.

    On this computer: its pid exists and that process started before the
    session did (a later start means the pid was reused).  On another
    computer the process cannot be checked: the session counts as running
    until its sidecar is :data:`FOREIGN_STALE_S` old.
    """
    if hostname != socket.gethostname():
        return time.time() - last_written < FOREIGN_STALE_S
    if pid == os.getpid():  # this process, or an earlier one that had the same pid
        return session_started >= _IMPORTED_AT
    if not _pid_alive(pid):
        return False
    started = _process_start(pid)
    return started is None or started <= session_started + 2.0  # start time has 1/100 s ticks


# ---------------------------------------------------------------- sidecar files
def _write_json_atomic(path: Path, doc: dict[str, Any]) -> None:
    write_text_atomic(path, json.dumps(doc, indent=1, ensure_ascii=False, allow_nan=False))


def _iso(epoch: float) -> str:
    return datetime.fromtimestamp(epoch, UTC).isoformat(timespec="seconds")


@dataclass(frozen=True)
class RecoveryEntry:
    """One snapshot left behind by a session that is gone.

    Attributes
    ----------
    snapshot, sidecar : Path
        The ``.fcase`` snapshot and its ``.json`` description.
    problem : str or None
        Why it cannot be recovered (damaged, missing file...), else None.
    written : float or None
        When the snapshot was written (epoch seconds).
    original_path : Path or None
        The case file the work belongs to; None for an untitled case.
    title, specimen : str
        The case's file name (or "untitled case") and its skull file name.
    undo_steps : int
        Undo steps of the crashed session (the history itself is not kept).
    """

    snapshot: Path
    sidecar: Path
    problem: str | None = None
    written: float | None = None
    original_path: Path | None = None
    title: str = ""
    specimen: str = ""
    undo_steps: int = 0
    pid: int = 0
    hostname: str = ""
    session: str = ""

    @property
    def recoverable(self) -> bool:
        return self.problem is None

    @property
    def when(self) -> str:
        """Local time of the snapshot, e.g. ``2025-03-01 14:05``."""
        if self.written is None:
            return "an unknown time"
        return datetime.fromtimestamp(self.written).strftime("%Y-%m-%d %H:%M")

    def question(self) -> str:
        return f"Recover unsaved work from {self.when} ({self.title})?"

    def details(self) -> str:
        lines = [
            f"Specimen: {self.specimen or 'none'}",
            f"Changes in the lost session: {self.undo_steps} undo step(s)",
            "Saved file: "
            + (
                str(self.original_path) if self.original_path else "none (the case was never saved)"
            ),
            f"Snapshot: {self.snapshot}",
        ]
        return "\n".join(lines)


def _problem_text(exc: BaseException) -> str:
    if isinstance(exc, InputError):
        return exc.problem + (f" ({exc.hint})" if exc.hint else "")
    if isinstance(exc, WorkbenchError):
        return str(exc)
    return f"{type(exc).__name__}: {exc}"


def _read_sidecar(path: Path) -> dict[str, Any]:
    """The sidecar as a dict; ValueError naming what is wrong."""
    try:
        doc = read_json(path, max_bytes=MAX_SIDECAR_BYTES, what="description file")
    except InputError as error:  # unreadable, too large, too deep, not UTF-8 or not JSON
        problem = error.problem.replace("the description file", "its description file", 1)
        raise ValueError(problem) from None
    if not isinstance(doc, dict) or doc.get("format") != SIDECAR_FORMAT:
        raise ValueError("its description file is not a workbench autosave description")
    if doc.get("version") != SIDECAR_VERSION:
        raise ValueError(
            f"its description file has version {doc.get('version')!r}; "
            f"this workbench reads version {SIDECAR_VERSION}"
        )
    types: dict[str, type | tuple[type, ...]] = {
        "pid": int,
        "hostname": str,
        "session": str,
        "session_started": (int, float),
    }
    bad = [key for key, kind in types.items() if not isinstance(doc.get(key), kind)]
    if bad:
        raise ValueError(f"its description file has no valid {', '.join(bad)}")
    return doc


def _entry(sidecar: Path, exclude: set[str]) -> RecoveryEntry | None:
    """The entry for one sidecar, or None if its session is running (or excluded)."""
    snapshot = sidecar.with_suffix(".fcase")
    try:
        doc = _read_sidecar(sidecar)
    except ValueError as error:
        return RecoveryEntry(snapshot, sidecar, str(error), _mtime(snapshot, sidecar))
    written = doc.get("written")
    written = float(written) if isinstance(written, (int, float)) else None
    if doc["session"] in exclude or owner_alive(
        doc["pid"],
        doc["hostname"],
        float(doc["session_started"]),
        written or _mtime(sidecar) or 0.0,
    ):
        return None
    original = doc.get("original_path")
    undo = doc.get("undo_steps")
    entry = RecoveryEntry(
        snapshot,
        sidecar,
        None,
        written,
        Path(original) if isinstance(original, str) and original else None,
        str(doc.get("title") or "untitled case"),
        str(doc.get("specimen") or ""),
        undo if isinstance(undo, int) else 0,
        doc["pid"],
        doc["hostname"],
        doc["session"],
    )
    problem = None
    if written is None or not snapshot.is_file():
        problem = "the session stopped before its first snapshot was complete"
    else:
        try:
            read_case_json(snapshot)
        except (WorkbenchError, OSError, ValueError) as error:
            problem = _problem_text(error)
    return entry if problem is None else replace(entry, problem=problem)


def _mtime(*paths: Path) -> float | None:
    for path in paths:
        with contextlib.suppress(OSError):
            return path.stat().st_mtime
    return None


def find_recoverable(
    folder: str | Path | None = None, exclude: Iterable[str] = ()
) -> list[RecoveryEntry]:
    """Snapshots in ``folder`` whose owning session is gone, newest first.

    Snapshots of running sessions (any window of this process, another
    workbench still open) and of the sessions in ``exclude`` are skipped.
    A damaged snapshot or sidecar, or a snapshot without a sidecar, is listed
    with :attr:`RecoveryEntry.problem` saying why (never raises for those).
    Only ``case.json`` is checked here; :func:`recover` verifies everything.
    """
    folder = Path(folder) if folder is not None else autosave_folder()
    if not folder.is_dir():
        return []
    skip = set(exclude)
    entries = []
    for sidecar in sorted(folder.glob(f"{PREFIX}*.json")):
        entry = _entry(sidecar, skip)
        if entry is not None:
            entries.append(entry)
    for snapshot in sorted(folder.glob(f"{PREFIX}*.fcase")):
        if not snapshot.with_suffix(".json").exists():
            entries.append(
                RecoveryEntry(
                    snapshot,
                    snapshot.with_suffix(".json"),
                    "its description file is missing (open it with File > Open case to look at it)",
                    _mtime(snapshot),
                    title=snapshot.name,
                )
            )
    entries.sort(key=lambda e: e.written or 0.0, reverse=True)
    return entries


def _delete(*paths: Path) -> bool:
    """Delete files that may be missing; False if one could not be deleted."""
    ok = True
    for path in paths:
        try:
            path.unlink(missing_ok=True)
        except OSError:
            ok = False
    return ok


def discard_entry(entry: RecoveryEntry) -> bool:
    """Delete a left-over snapshot and its sidecar (the user chose Discard); True if gone."""
    return _delete(entry.snapshot, entry.sidecar)


# ---------------------------------------------------------------- the autosaver
def _specimen_name(case: Case) -> str:
    skulls = [e.name for e in case.evidence if e.role == "skull_mesh"]
    names = skulls or [e.name for e in case.evidence]
    return names[0] if names else ""


class Autosaver(QObject):
    """Writes snapshots of a document's case; see the module docstring.

    Parameters
    ----------
    document : workbench.qt.document.Document
    folder : path, optional
        Default :func:`autosave_folder`.
    interval_s : float, optional
        Default :func:`autosave_interval_s`; 0 disables the timer
        (:meth:`autosave` still works when called).

    Signals
    -------
    snapshot_written(str)
        Path of the snapshot just written.
    snapshot_failed(str)
        A readable message; the case is unaffected, the next tick retries.
    """

    snapshot_written = Signal(str)
    snapshot_failed = Signal(str)

    def __init__(
        self,
        document: Any,
        folder: str | Path | None = None,
        interval_s: float | None = None,
        parent: QObject | None = None,
    ) -> None:
        super().__init__(parent)
        self.document = document
        self.folder = Path(folder) if folder is not None else autosave_folder()
        self.session = uuid.uuid4().hex
        self.session_started = time.time()
        self.snapshot_path = self.folder / f"{PREFIX}{self.session}.fcase"
        self.sidecar_path = self.snapshot_path.with_suffix(".json")
        self.last_error: str | None = None
        #: milliseconds of the last snapshot: "gui" (frozen copy) and "total"
        self.timings: dict[str, float] = {}
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="workbench-autosave")
        self._future: Future | None = None
        self._again = False
        self._claimed = False
        self._closed = False
        self._generation = 0
        self._written = -1
        self._relay_key = relay.register(self._on_finished)
        for signal in (document.case_replaced, document.part_changed, document.stack_changed):
            signal.connect(self._touch)
        self.timer = QTimer(self)
        self.timer.timeout.connect(self.autosave)
        interval = autosave_interval_s() if interval_s is None else max(0.0, interval_s)
        if interval > 0:
            self.timer.start(max(1, int(interval * 1000)))

    @property
    def writing(self) -> bool:
        return self._future is not None and not self._future.done()

    @property
    def has_snapshot(self) -> bool:
        return self.snapshot_path.exists()

    def _touch(self, *_args: Any) -> None:
        self._generation += 1

    # ------------------------------------------------------------ writing
    def autosave(self, wait: bool = False) -> bool:
        """Snapshot the case if it has unsaved changes not yet in a snapshot.

        With ``wait`` the write finishes before this returns (tests, scripts);
        otherwise it runs in the worker thread.  Returns True if a snapshot
        was written or started.  A clean case has its snapshot removed.
        """
        if self._closed:
            return False
        if wait:
            self._wait()
        if not self.document.is_dirty:
            if not self.writing and self.has_snapshot:
                self.discard_snapshot()
            return False
        if self._generation == self._written:
            return False
        if self.writing:
            self._again = True  # once the running write is done
            return False
        started = time.perf_counter()
        frozen = detached_copy(self.document.case)
        info = self._describe(frozen)
        self.timings = {"gui": 1e3 * (time.perf_counter() - started)}
        claim = not self._claimed
        self._claimed = True  # the worker writes the sidecar first when claiming
        future = self._pool.submit(
            _write_snapshot,
            frozen,
            info,
            self._generation,
            started,
            self.folder,
            self.snapshot_path,
            self.sidecar_path,
            claim,
        )
        self._future = future
        # the worker holds no reference to this QObject (see workbench.qt.relay)
        future.add_done_callback(functools.partial(relay.post, self._relay_key))
        if wait:
            with contextlib.suppress(Exception):
                future.result()
            self._on_finished(future)
        return True

    def _describe(self, case: Case) -> dict[str, Any]:
        path = self.document.path
        return {
            "format": SIDECAR_FORMAT,
            "version": SIDECAR_VERSION,
            "session": self.session,
            "snapshot": self.snapshot_path.name,
            "pid": os.getpid(),
            "hostname": socket.gethostname(),
            "session_started": self.session_started,
            "original_path": str(Path(path).resolve()) if path is not None else None,
            "title": path.name if path is not None else "untitled case",
            "specimen": _specimen_name(case),
            "undo_steps": len(self.document.stack),
            "case_id": case.meta.case_id,
            "examiner": case.meta.examiner,
        }

    def _on_finished(self, future: Future) -> None:
        if future is not self._future:
            return  # already handled (a waited-for write)
        self._future = None
        error = future.exception()
        if error is not None:
            self.last_error = (
                f"Autosave failed: {_problem_text(error)}; the case itself is unaffected"
            )
            self.snapshot_failed.emit(self.last_error)
        else:
            self.last_error = None
            self._written, self.timings["total"] = future.result()
            self.snapshot_written.emit(str(self.snapshot_path))
        if self._again:
            self._again = False
            self.autosave()

    def _wait(self) -> None:
        """Let a running write finish (its files complete) and handle its result."""
        future = self._future
        if future is None:
            return
        with contextlib.suppress(Exception):
            future.result(timeout=WRITE_WAIT_S)
        if future.done():
            self._on_finished(future)

    # ------------------------------------------------------------ deleting
    def discard_snapshot(self) -> None:
        """Delete this session's snapshot and sidecar (after Save, Discard, clean close)."""
        self._again = False
        self._wait()
        _delete(self.snapshot_path, self.sidecar_path)  # best effort: never blocks a close
        self._claimed = False
        self._written = -1  # a case still dirty is written again at the next tick

    def close(self) -> None:
        """A clean close: stop, and delete this session's snapshot."""
        if self._closed:
            return
        self.timer.stop()
        self.discard_snapshot()
        self._closed = True
        self._pool.shutdown(wait=True)

    def abandon(self) -> None:
        """Stop without deleting anything, as a crash would (tests; keeps the files)."""
        self.timer.stop()
        self._wait()
        self._closed = True
        self._pool.shutdown(wait=True)

    # ------------------------------------------------------------ recovery
    def adopt(self, entry: RecoveryEntry, case: Case) -> None:
        """Make ``entry``'s snapshot this session's own (``case`` was loaded from it).

        Claims it with this session's sidecar, moves the file, removes the old
        sidecar and repoints ``case.source_path`` (where the next save or
        snapshot finds the evidence bytes).  Raises OSError with nothing moved.
        """
        self._again = False
        self._wait()
        try:
            old = _read_sidecar(entry.sidecar)
        except ValueError:
            old = {}
        self.folder.mkdir(parents=True, exist_ok=True)
        _write_json_atomic(
            self.sidecar_path,
            {
                **old,
                "session": self.session,
                "snapshot": self.snapshot_path.name,
                "pid": os.getpid(),
                "hostname": socket.gethostname(),
                "session_started": self.session_started,
                "recovered_from": entry.session,
                "format": SIDECAR_FORMAT,
                "version": SIDECAR_VERSION,
            },
        )
        try:
            os.replace(entry.snapshot, self.snapshot_path)
        except OSError:
            with contextlib.suppress(OSError):
                self.sidecar_path.unlink()
            raise
        _delete(entry.sidecar)
        case.source_path = self.snapshot_path.resolve()
        self._claimed = True
        self._written = -1


@dataclass(eq=False)
class RecoverSnapshot(Command):
    """Records in the audit log that unsaved work was recovered (changes no part)."""

    snapshot: str = ""
    written: str = ""
    original_path: str = ""

    def default_label(self) -> str:
        return "Recover unsaved work"

    def do(self, case: Case) -> None:
        pass

    def undo(self, case: Case) -> None:
        pass


def install_autosave(
    window: AutosaveHost, folder: str | Path | None = None, interval_s: float | None = None
) -> Autosaver:
    """Give ``window`` (a MainWindow) an :class:`Autosaver` as ``window.autosaver``."""
    saver = Autosaver(window.document, folder, interval_s, parent=window.window())
    saver.snapshot_failed.connect(window.status)
    saver.snapshot_failed.connect(window.messages.append)
    window.autosaver = saver
    return saver


def forget_snapshot(window: object) -> None:
    """Delete the window's snapshot, if it has an autosaver (after Save or Discard)."""
    saver = getattr(window, "autosaver", None)
    if saver is not None:
        saver.discard_snapshot()


def recover(window: AutosaveHost, entry: RecoveryEntry) -> bool:
    """Open ``entry``'s snapshot in ``window`` as an unsaved case; True on success.

    The current case is replaced only if it may be (as for File > Open).
    The recovered case is dirty, has no undo history and keeps its original
    file as the document path (Save writes there; untitled: Save As).  A
    snapshot that fails its integrity checks is reported and left alone.
    """
    if not entry.recoverable:
        window.show_error(f"Could not recover {entry.snapshot.name}", WorkbenchError(entry.problem))
        return False
    try:
        loaded = load_case(entry.snapshot)  # every hash checked before anything is replaced
    except (WorkbenchError, OSError) as error:
        window.show_error(f"Could not recover unsaved work from {entry.when}", error)
        return False
    if not window.may_discard():
        return False
    saver: Autosaver = window.autosaver
    try:
        saver.adopt(entry, loaded.case)
    except OSError as error:
        window.show_error(f"Could not recover unsaved work from {entry.when}", error)
        return False
    stack = CommandStack(loaded.case)
    stack.push(
        RecoverSnapshot(
            snapshot=entry.snapshot.name,
            written=_iso(entry.written) if entry.written else "",
            original_path=str(entry.original_path or ""),
        )
    )
    stack.clear()  # no history to undo, and the case stays unsaved
    note = f"Recovered unsaved work from {entry.when} ({entry.title}); " + (
        f"Save writes to {entry.original_path}"
        if entry.original_path
        else "it was never saved: Save asks for a file name"
    )
    window.replace_case(OpenedCase(loaded.case, stack, [note]), entry.original_path)
    window.status(note)
    return True


# ---------------------------------------------------------------- startup
RECOVER, DISCARD, LATER = "recover", "discard", "later"


def ask_recovery(parent: QWidget, entry: RecoveryEntry) -> str:
    """The modal question: :data:`RECOVER`, :data:`DISCARD` or :data:`LATER`."""
    box = QMessageBox(
        QMessageBox.Icon.Question,
        "Unsaved work found",
        entry.question(),
        QMessageBox.StandardButton.NoButton,
        parent,
    )
    box.setInformativeText(
        "The workbench stopped before these changes were saved.\n\n" + entry.details()
    )
    recover_button = box.addButton("Recover", QMessageBox.ButtonRole.AcceptRole)
    discard_button = box.addButton("Discard", QMessageBox.ButtonRole.DestructiveRole)
    later_button = box.addButton("Later", QMessageBox.ButtonRole.RejectRole)
    box.setDefaultButton(recover_button)
    box.setEscapeButton(later_button)
    box.exec()
    clicked = box.clickedButton()
    if clicked is recover_button:
        return RECOVER
    return DISCARD if clicked is discard_button else LATER


def offer_recovery(window: AutosaveHost, folder: str | Path | None = None) -> bool:
    """At startup: offer each left-over snapshot, newest first; True if one was recovered.

    Non-interactive windows never see a dialog (nothing happens; use
    :func:`find_recoverable` and :func:`recover`).  Damaged snapshots are
    listed in ``window.messages`` and left on disk.  "Later" keeps this and
    the older snapshots for the next start; "Discard" deletes one and asks
    about the next.
    """
    saver = getattr(window, "autosaver", None)
    exclude = {saver.session} if saver is not None else set()
    entries = find_recoverable(
        folder if folder is not None else (saver.folder if saver is not None else None), exclude
    )
    for entry in entries:
        if not entry.recoverable:
            window.messages.append(
                f"Autosave {entry.snapshot.name} cannot be recovered: {entry.problem}"
            )
    if not window.interactive:
        return False
    for entry in (e for e in entries if e.recoverable):
        answer = ask_recovery(window.window(), entry)
        if answer == RECOVER:
            return recover(window, entry)
        if answer == LATER:
            return False
        discard_entry(entry)
    return False


def _write_snapshot(
    frozen: Case,
    info: dict[str, Any],
    generation: int,
    started: float,
    folder: Path,
    snapshot: Path,
    sidecar: Path,
    claim: bool,
) -> tuple[int, float]:
    """Worker thread: the snapshot, then its sidecar (with ``claim``, a sidecar first).

    Plain data in and out: the worker never holds the Autosaver (a QObject).
    """
    folder.mkdir(parents=True, exist_ok=True)
    if claim:  # a sidecar before the first snapshot: never an orphan .fcase
        _write_json_atomic(sidecar, {**info, "written": None})
    write_case_snapshot(frozen, snapshot)
    now = time.time()
    _write_json_atomic(sidecar, {**info, "written": now, "written_utc": _iso(now)})
    return generation, 1e3 * (time.perf_counter() - started)
