"""Entry point of the ``workbench`` command.

Every sub-command is a thin wrapper over a service or an io function, so the
same work can be scripted from Python.  Errors a user can act on
(:class:`~workbench.core.errors.WorkbenchError`) are printed as one clear
line and exit with status 2; anything unexpected prints a short message
(``--debug`` shows the traceback) and exits with status 1.  A command whose
skull registration asks for a check (``reconstruct``, ``landmarks suggest``,
``template build``) writes its outputs, says why first, and exits with status 3.

A file that cannot be written because the device is full (or over quota,
read-only, ...) is named with the reason, like any other unreadable or
unwritable file (status 2); when the error does not carry the file's name,
the command's ``--out`` is named.

Ctrl-C prints one line, ``interrupted``, and exits with status 130, whichever
command runs and wherever it is (the sub-commands are imported inside
:func:`main`, so this holds while they load too).  Outputs are written whole or
not at all (:mod:`workbench.io.outputs`).  Started as the ``workbench``
command (``main()`` without arguments), :func:`main` owns the process: after
an interrupt it ends it at once, without the interpreter's clean-up (where a
half-loaded native library can crash: exit 139), and once the command has
finished a late Ctrl-C no longer changes its outcome.
"""

from __future__ import annotations

import argparse
import os
import signal
import sys
import threading
from collections.abc import Sequence
from types import FrameType, ModuleType
from typing import Any

import workbench
from workbench.pipelines.outcome import STDOUT_NAME, failure_status

#: exit status after Ctrl-C (128 + SIGINT, what a shell reports for it)
EXIT_INTERRUPTED = 130
#: a Ctrl-C that Python dropped is raised again this long after (s; see _Interrupts), at
#: most _MAX_REDELIVERIES times per command
REDELIVERY_DELAY_S = 0.01
_MAX_REDELIVERIES = 20


#: the sub-command modules of ``workbench.cli`` in the order of ``workbench --help``, with
#: the command names each registers
COMMANDS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("demo_cmd", ("demo",)),
    ("ct_cmd", ("mesh-from-ct",)),
    ("mesh_cmd", ("mesh",)),
    ("landmarks_cmd", ("landmarks",)),
    ("case_cmd", ("case",)),
    ("template_cmd", ("template", "render")),
    ("fit_scan_cmd", ("fit-scan",)),
    ("samples_cmd", ("samples",)),
    ("compare_cmd", ("compare",)),
    ("reconstruct_cmd", ("reconstruct",)),
    ("validate_cmd", ("validate",)),
    ("animate_cmd", ("animate",)),
    ("age_cmd", ("age",)),
    ("portrait_cmd", ("portrait",)),
    ("batch_cmd", ("batch",)),
    ("gui_cmd", ("gui",)),
)


def _command_modules(only: str | None = None) -> tuple[ModuleType, ...]:
    """The sub-command modules (imported here, inside :func:`main`'s handlers, so a Ctrl-C
    while they load ends as any other); with ``only`` (a command name) just the one that
    registers it, so a command does not pay for importing every other one (~0.4 s)."""
    import importlib

    names = [m for m, commands in COMMANDS if only is None or only in commands]
    return tuple(importlib.import_module(f"workbench.cli.{m}") for m in names)


def _command_named(argv: Sequence[str] | None) -> str | None:
    """The sub-command ``argv`` names when it is one of :data:`COMMANDS` (the first word
    after the global options), else None (help, a typo, no command: the whole parser)."""
    words = list(sys.argv[1:] if argv is None else argv)
    known = {c for _, commands in COMMANDS for c in commands}
    for word in words:
        if word in ("--debug",):
            continue
        return word if word in known else None
    return None


def build_parser(
    argv: Sequence[str] | None = None, *, every: bool = True
) -> argparse.ArgumentParser:
    """The command line's parser: every sub-command, or (``every=False``) only the one
    ``argv`` names when it names one."""
    parser = argparse.ArgumentParser(
        prog="workbench",
        description=(
            "Forensic and anthropometry workbench: CT and mesh import, skull and skin "
            "landmarks, tissue-depth reconstruction and growth simulation. All geometry "
            "is in millimetres."
        ),
    )
    parser.add_argument("--version", action="version", version=f"workbench {workbench.__version__}")
    parser.add_argument(
        "--debug", action="store_true", help="show full tracebacks for unexpected errors"
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for module in _command_modules(None if every else _command_named(argv)):
        module.register(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command; its exit status.

    ``argv`` None: the process's own arguments, and the process is the
    command's (see the module docstring for what that changes on Ctrl-C).
    """
    owner = argv is None and threading.current_thread() is threading.main_thread()
    watch = _Interrupts()
    try:
        try:
            code = _run(argv, watch)
        finally:
            if owner:  # the outcome is decided: a late Ctrl-C no longer changes it
                signal.signal(signal.SIGINT, signal.SIG_IGN)
            watch.restore()
    except KeyboardInterrupt as exc:  # in the instant between the command's end and the above
        _KEPT.append(exc)
        code = _interrupted()
    if owner and code == EXIT_INTERRUPTED:
        _end_process(code)
    _KEPT.clear()
    return code


#: the interrupt (and what it turned into) of a command that ends interrupted, kept until the
#: process ends: its traceback holds the frames the interrupt left, with their objects (a
#: VTK render window half-way through a picture).  Freed as the except block ends, those
#: objects' native clean-up could crash (exit 139 after "interrupted", seen once in ~100
#: interrupted runs of ``workbench age``); kept, nothing is freed before ``os._exit``.
_KEPT: list[BaseException] = []


def _run(argv: Sequence[str] | None, watch: _Interrupts) -> int:
    args = argparse.Namespace(command=None, debug=False)  # until the arguments are read
    try:
        parser = build_parser(argv, every=False)
        args = parser.parse_args(argv)
        if not getattr(args, "handler", None):
            parser.print_help()
            return 0
        code = int(args.handler(args) or 0)
        if watch.pending():  # a Ctrl-C dropped by Python at the very end of the command
            return _interrupted()
        _flush_stdout()
        return code
    except KeyboardInterrupt as exc:
        _KEPT.append(exc)
        return _interrupted()
    except BrokenPipeError as exc:
        if watch.seen:
            _KEPT.append(exc)
            return _interrupted()
        # the reader went away (``workbench samples list | head``): a normal end
        _silence_stdout()
        return 0
    except Exception as exc:  # noqa: BLE001 - last resort: never a bare traceback for users
        if watch.seen:
            # whatever the interrupt turned into on its way out (an ImportError when it
            # hit a compiled module's import, an error of a library that caught it)
            _KEPT.append(exc)
            return _interrupted()
        return failure_status(exc, args, flush_stdout=_flush_stdout)


class _Interrupts:
    """Ctrl-C while a command runs: seen (:attr:`seen`), and never dropped.

    SIGINT raises ``KeyboardInterrupt`` as Python's own handler does, and
    records that it came, so an error it turned into on its way out (an
    ``ImportError`` when it hit numpy's compiled import) still ends as an
    interrupt.  A ``KeyboardInterrupt`` raised inside a callback from compiled
    code (numba's compiler, ctypes) or a finaliser cannot propagate: Python
    prints "Exception ignored ..." with a traceback and goes on.  Such reports
    are silenced and the interrupt raised again a moment later (from a timer
    thread: raised at once it would land in the same callback), and if the
    command ends before that, it ends as interrupted (:meth:`pending`).  The
    same holds for one printed through ``sys.excepthook`` by compiled code that
    prints it and goes on (numpy's ``import_array`` in an extension's start-up,
    when the interrupt lands in the import it makes: the caller then gets an
    ``ImportError``, and a library that treats the module as optional carries
    on; seen once in CI as a traceback and exit 0).  Where
    SIGINT is ignored or handled by someone else (a Dask worker, another
    program's handler) only the dropped-interrupt part applies.
    """

    def __init__(self) -> None:
        self.seen = False
        self._redelivered = 0
        self._armed = False
        self._lock = threading.Lock()
        self._hook = sys.unraisablehook
        self._excepthook = sys.excepthook
        self._handler: Any = None
        sys.unraisablehook = self._unraisable
        sys.excepthook = self._printed
        on_main = threading.current_thread() is threading.main_thread()
        if on_main and signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            self._handler = signal.signal(signal.SIGINT, self._sigint)

    def _sigint(self, signum: int, frame: FrameType | None) -> None:
        self.seen = True
        self._armed = False  # this is the interrupt (again): no second one (no lock: a
        # handler runs between any two bytecodes of the main thread, maybe holding it)
        raise KeyboardInterrupt

    def _unraisable(self, unraisable: Any) -> None:
        exc_type = getattr(unraisable, "exc_type", None)
        if not (isinstance(exc_type, type) and issubclass(exc_type, KeyboardInterrupt)):
            if not self.seen:
                self._hook(unraisable)
            # else: a finaliser of an object the interrupt cut short in its constructor
            # (pyvista's Renderer.__del__ reading an attribute never set): the command
            # ends as interrupted, and that one line is all the user needs to see
            return
        self._dropped()

    def _printed(self, exc_type: Any, exc: Any, tb: Any) -> None:
        if isinstance(exc_type, type) and issubclass(exc_type, KeyboardInterrupt):
            self._dropped()
        else:
            self._excepthook(exc_type, exc, tb)

    def _dropped(self) -> None:
        """An interrupt that could not propagate: seen, and raised again in a moment."""
        self.seen = True
        with self._lock:
            if self._armed or self._redelivered >= _MAX_REDELIVERIES:
                return
            self._armed = True
            self._redelivered += 1
        timer = threading.Timer(REDELIVERY_DELAY_S, self._redeliver)
        timer.daemon = True
        timer.start()

    def _redeliver(self) -> None:
        with self._lock:
            if not self._armed:
                return
            self._armed = False
            import _thread

            _thread.interrupt_main()  # nothing when SIGINT is ignored or not Python's

    def pending(self) -> bool:
        """Whether a dropped interrupt is still to come (then it never will: disarmed)."""
        with self._lock:
            armed, self._armed = self._armed, False
        return armed

    def restore(self) -> None:
        """Put back the handler and hooks found (a SIG_IGN set meanwhile is kept)."""
        self.pending()
        if sys.unraisablehook == self._unraisable:
            sys.unraisablehook = self._hook
        if sys.excepthook == self._printed:
            sys.excepthook = self._excepthook
        if self._handler is not None and signal.getsignal(signal.SIGINT) == self._sigint:
            signal.signal(signal.SIGINT, self._handler)


def _flush_stdout() -> None:
    """Flush what the command printed, so a full device (``> /dev/full``) is reported
    here, naming the standard output, instead of by the interpreter at exit.  A reader
    that went away (``| head``) is a normal end."""
    try:
        sys.stdout.flush()
    except BrokenPipeError:
        _silence_stdout()
    except OSError as exc:
        _silence_stdout()
        raise OSError(exc.errno, exc.strerror, STDOUT_NAME) from None


def _silence_stdout() -> None:
    """Point the standard output at devnull: what could not be written is dropped, and
    the interpreter's own flush at exit does not fail again."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):  # no descriptor (a stand-in stream)
        pass


def _interrupted() -> int:
    try:
        print("interrupted", file=sys.stderr, flush=True)
    except (OSError, ValueError):  # stderr closed: the status says it
        pass
    return EXIT_INTERRUPTED


def _end_process(code: int) -> None:
    """Flush what was printed and end the process now (no interpreter clean-up)."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError, AttributeError):
            pass
    os._exit(code)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
