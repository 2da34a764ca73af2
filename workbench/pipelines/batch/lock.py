"""One batch at a time per output folder: ``DIR/.batch.lock``.

:func:`batch_lock` holds the lock (``fcntl.flock`` where there is one, else a
file created with ``O_EXCL``) with the holder's pid and host; a second batch
into the same folder is refused naming that process; the lock of a process
that died is taken over (flock: released by the kernel; ``O_EXCL``: its pid
no longer runs).
"""

from __future__ import annotations

import contextlib
import json
import os
import socket
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

from workbench.core.errors import InputError

#: the lock file of a running batch, inside DIR
LOCK = ".batch.lock"

_HELD: dict[str, int] = {}
_HELD_GUARD = threading.Lock()


def _lock_holder(lock: Path) -> dict[str, Any]:
    try:
        data = json.loads(lock.read_text(encoding="utf-8") or "{}")
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def _lock_busy(out: Path, lock: Path) -> InputError:
    holder = _lock_holder(lock)
    who = (
        f"process {holder.get('pid')} on {holder.get('host')}, started {holder.get('started_utc')}"
        if holder.get("pid")
        else f"another process (see {lock})"
    )
    return InputError(
        out,
        f"another batch is writing into this folder ({who})",
        "wait for it to finish, or choose another --out",
    )


def _lock_text() -> str:
    return json.dumps(
        {
            "pid": os.getpid(),
            "host": socket.gethostname(),
            "started_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        }
    )


def _acquire_flock(out: Path, lock: Path) -> Callable[[], None]:
    import fcntl

    while True:
        fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            raise _lock_busy(out, lock) from None
        try:  # the file may have been removed by its last holder meanwhile: lock the new one
            same = os.path.samestat(os.fstat(fd), os.stat(lock))
        except OSError:
            same = False
        if same:
            break
        os.close(fd)
    os.ftruncate(fd, 0)
    os.write(fd, _lock_text().encode())

    def release() -> None:
        with contextlib.suppress(OSError):
            os.unlink(lock)
        os.close(fd)  # closing releases the flock

    return release


def _acquire_exclusive(out: Path, lock: Path) -> Callable[[], None]:
    """Without flock: the lock file created with O_EXCL; a dead holder's file is taken over."""
    from workbench.io.outputs import _pid_alive

    for _ in range(2):
        try:
            fd = os.open(lock, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
        except FileExistsError:
            holder = _lock_holder(lock)
            stale = (
                holder.get("host") == socket.gethostname()
                and isinstance(holder.get("pid"), int)
                and not _pid_alive(holder["pid"])
            )
            if not stale:
                raise _lock_busy(out, lock) from None
            with contextlib.suppress(OSError):
                os.unlink(lock)
            continue
        os.write(fd, _lock_text().encode())
        os.close(fd)
        return lambda: lock.unlink(missing_ok=True)
    raise _lock_busy(out, lock)


@contextlib.contextmanager
def batch_lock(out: str | Path) -> Iterator[Path]:
    """Hold the batch lock of the folder ``out`` (made if need be) while the block runs.

    Re-entrant within one process (the CLI holds it around ``run_batch`` and
    the summary).  Another process holding it: an InputError naming the
    folder and that process's pid and host.  A folder this call made is
    removed again when it is still empty afterwards (a refused batch leaves
    nothing behind).
    """
    from workbench.io.outputs import check_not_special

    out = Path(os.path.abspath(out))
    key = str(out)
    with _HELD_GUARD:
        if key in _HELD:
            _HELD[key] += 1
            nested = True
        else:
            nested = False
    if nested:
        try:
            yield out / LOCK
        finally:
            with _HELD_GUARD:
                _HELD[key] -= 1
        return
    check_not_special(out)
    if os.path.lexists(out) and not out.is_dir():
        raise InputError(out, "is a file", "give a folder for --out")
    made = not os.path.lexists(out)
    out.mkdir(parents=True, exist_ok=True)
    lock = out / LOCK
    try:
        acquire = _acquire_flock if _has_flock() else _acquire_exclusive
        release = acquire(out, lock)
    except BaseException:
        if made:
            with contextlib.suppress(OSError):
                out.rmdir()
        raise
    with _HELD_GUARD:
        _HELD[key] = 1
    try:
        yield lock
    finally:
        with _HELD_GUARD:
            _HELD.pop(key, None)
        release()
        if made:
            with contextlib.suppress(OSError):
                out.rmdir()  # only when empty


def _has_flock() -> bool:
    try:
        import fcntl
    except ImportError:
        return False
    return hasattr(fcntl, "flock")
