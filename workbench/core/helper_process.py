"""Run a C extension that holds the GIL in a helper process.

Why: some compiled libraries keep Python's global interpreter lock for their
whole call.  ``fast_simplification.simplify`` holds it for ~230 ms on a
100k-triangle skull (measured; numpy and scipy release it in their long
loops).  Called from a worker thread of the desktop window, such a call
freezes the GUI thread for as long, whatever thread it runs on.  Run in a
separate process instead, the worker thread only waits on a pipe, which
releases the lock.

How: one long-lived child (``python -m workbench.core.helper_process``),
started on first use, reads requests from stdin and answers on stdout:
length-prefixed pickles of ``(function name, args)`` → ``(ok, value)``.
Only functions marked with :func:`runnable` in ``workbench`` modules may be
called.  Calls are serialised (one at a time).  If the child cannot be
started, the call runs in-process instead (same result, only the GUI may
stutter); a child that dies during a call raises ``RuntimeError`` (the
input is not retried here, it might crash this process too) and is replaced
at the next call.  :func:`status` says why the last call did not run in the
child.  The child runs at a lower CPU priority (nice 10) and is stopped at
exit.  Its environment is the one it started with: pass what may change
(folders, settings) as arguments.

Arrays cross as pickles (a 100k-triangle mesh is ~3.6 MB: a few ms).

Who uses it: library code calls :func:`run`, which runs the function right
there, unless the calling thread has opted in with :func:`offload_here`
(the desktop window's worker threads do); then it goes to the child.
:func:`call` always goes to the child: the reconstruction job uses it to
decimate a large skull on the second core while its checks run
(:func:`workbench.services.reconstruction.service.prefetch_working_skull`),
and ``workbench reconstruct`` to draw its report pictures while it writes its
other files (:mod:`workbench.pipelines.pictures`).  Other command-line runs
and scripts never start a second process.  The child's file descriptor 1 is
its stderr: replies travel on a private copy of the pipe, so output printed by
a C library (VTK, a graphics driver) cannot corrupt them.
"""

from __future__ import annotations

import atexit
import contextlib
import importlib
import os
import pickle
import struct
import subprocess
import sys
import threading
from collections.abc import Callable
from typing import IO, Any, TypeVar

_HEADER = struct.Struct("<Q")
_lock = threading.Lock()
_child: subprocess.Popen | None = None
_problem = ""
_thread = threading.local()
_MARK = "_workbench_helper_process"

F = TypeVar("F", bound=Callable[..., Any])


def runnable(fn: F) -> F:
    """Mark ``fn`` as one the helper process may run (arguments and result must pickle)."""
    setattr(fn, _MARK, True)
    return fn


def _resolve(name: str) -> Callable[..., Any]:
    module, _, func = name.partition(":")
    refused = ValueError(f"{name!r} may not run in the helper process")
    if not module.startswith("workbench.") or not func:
        raise refused
    fn = getattr(importlib.import_module(module), func, None)
    if fn is None or not getattr(fn, _MARK, False):
        raise refused
    return fn


def offload_here(on: bool = True) -> None:
    """Let :func:`run` calls made by the calling thread go to the helper process."""
    _thread.offload = bool(on)


def offloading() -> bool:
    """Whether the calling thread opted in with :func:`offload_here`."""
    return bool(getattr(_thread, "offload", False))


def run(name: str, *args: Any) -> Any:
    """``name(*args)``: in the helper process if this thread opted in, else right here."""
    if offloading():
        return call(name, *args)
    return _resolve(name)(*args)


def _send(stream: IO[bytes], obj: Any) -> None:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    stream.write(_HEADER.pack(len(data)))
    stream.write(data)
    stream.flush()


def _receive(stream: IO[bytes]) -> Any:
    head = stream.read(_HEADER.size)
    if len(head) < _HEADER.size:
        raise EOFError("the helper process closed its pipe")
    size = _HEADER.unpack(head)[0]
    data = stream.read(size)
    if len(data) < size:
        raise EOFError("the helper process closed its pipe mid-message")
    return pickle.loads(data)


def _start() -> subprocess.Popen:
    env = dict(os.environ)
    # the child must import this package from wherever the parent did
    env["PYTHONPATH"] = os.pathsep.join(p for p in sys.path if p)
    env.setdefault("OMP_NUM_THREADS", "1")
    return subprocess.Popen(
        [sys.executable, "-m", "workbench.core.helper_process"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        env=env,
        close_fds=True,
        # a Ctrl-C in the terminal reaches the whole process group: the parent handles it,
        # the child must not die printing a traceback (it stops when its stdin closes)
        start_new_session=True,
    )


def _stop() -> None:
    global _child
    child, _child = _child, None
    if child is None:
        return
    try:
        if child.stdin is not None:
            child.stdin.close()  # the child's read ends, it exits
        child.wait(timeout=2.0)
    except (OSError, subprocess.TimeoutExpired):
        child.kill()
        child.wait()
    finally:
        for pipe in (child.stdin, child.stdout):
            if pipe is not None:
                with contextlib.suppress(OSError):
                    pipe.close()


atexit.register(_stop)


def call(name: str, *args: Any, fallback: bool = True) -> Any:
    """``name(*args)`` in the helper process (in-process if it is unavailable).

    ``name`` is ``"module:function"`` of a :func:`runnable` function.  Exceptions
    raised by the function are raised here again.  Thread-safe.  ``fallback=False``:
    raise ``RuntimeError`` instead of running in-process when there is no helper
    (for a caller on a thread that must not run the function itself).
    """
    global _child, _problem
    fn = _resolve(name)
    if os.environ.get("WORKBENCH_NO_HELPER_PROCESS"):
        if not fallback:
            raise RuntimeError("the helper process is switched off (WORKBENCH_NO_HELPER_PROCESS)")
        return fn(*args)
    with _lock:
        if _child is None or _child.poll() is not None:  # first call, or the child died
            _stop()
            try:
                _child = _start()
            except OSError as exc:
                _problem = f"helper process could not start ({exc}); running in-process"
                if not fallback:
                    raise RuntimeError(_problem) from exc
                return fn(*args)
        try:
            stdin, stdout = _child.stdin, _child.stdout
            if stdin is None or stdout is None:  # started with both pipes
                raise OSError("helper process without its pipes")
            _send(stdin, (name, args))
            ok, value = _receive(stdout)
        except Exception as exc:
            # not re-run in-process: an input that crashed the child would
            # crash this process too (fast_simplification does not check indices)
            _stop()
            _problem = f"helper process failed during {name} ({exc})"
            raise RuntimeError(
                f"{name.split(':')[1]} failed in the helper process; the input mesh may be corrupt"
            ) from exc
        _problem = ""
    if ok:
        return value
    raise value


def status() -> str:
    """Empty when the last call ran in the helper process; else why it did not."""
    return _problem


def _serve() -> None:
    """The child's loop: one request at a time until stdin closes."""
    stdin = sys.stdin.buffer
    # replies go to a private copy of the pipe; file descriptor 1 becomes stderr, so that
    # stray output, Python's or a C library's (VTK, EGL drivers), cannot corrupt the replies
    sys.stdout.flush()
    stdout = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    with contextlib.suppress(AttributeError, OSError):
        os.nice(10)  # background work: the window's renderer comes first
    while True:
        try:
            name, args = _receive(stdin)
        except EOFError:
            return
        try:
            reply = (True, _resolve(name)(*args))
        except Exception as exc:  # noqa: BLE001 - handed back to the caller
            reply = (False, exc)
        try:
            if not reply[0]:  # exceptions with odd constructors may not unpickle
                pickle.loads(pickle.dumps(reply))
        except Exception:  # noqa: BLE001
            reply = (False, RuntimeError(f"{name}: {type(reply[1]).__name__}: {reply[1]}"))
        _send(stdout, reply)


if __name__ == "__main__":
    _serve()
