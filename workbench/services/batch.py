"""Batch studies: every row of a manifest run as its own single command, on Dask distributed.

``workbench batch MANIFEST.csv --out DIR`` (see :mod:`workbench.services.batch_manifest`
for the manifest).  Each row is exactly one sub-command: its argv is built
from the row and handed to the CLI's entry point (``workbench.cli.main.main``)
inside a Dask worker, so ``DIR/<id>/`` holds byte for byte the files the
single command writes (mm, each command's own frames), plus the batch's
marker ``DIR/<id>/batch_row.json``.  This layer cannot import the CLI, so
the entry point and the sub-command parsers are passed in (the CLI does;
a script can pass ``workbench.cli.main.main`` too).

Engine: a ``LocalCluster`` of ``workers`` processes with one thread each, a
bounded memory per worker, and one BLAS/OpenMP/numba thread per worker
(environment of the worker processes, and ``threadpoolctl`` inside each
task); or an existing scheduler (``tcp://HOST:PORT``, e.g. a dask-jobqueue
``SLURMCluster``'s), whose workers must see the same paths and have the
workbench installed.  ``workers=0`` runs the rows one after another in this
process, without Dask.

One task per row (``client.submit(..., pure=False)``), results taken as they
complete; a failed row (its command's one-line error and exit status) is
recorded and the others go on.  The marker holds the argv, the SHA-256 of
every input file, the status, the seconds and the key figures; ``resume``
skips rows whose marker says ok with the same argv and input digests.  The
batch never writes over an input or over a folder it did not make: ``DIR``
must be new or empty unless ``resume``, and a ``DIR/<id>`` without a marker
is refused; a stale batch folder is kept as ``DIR/<id>.1`` before the rerun.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import io
import json
import os
import sys
import time
import uuid
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from workbench.core.errors import InputError, WorkbenchError
from workbench.services.batch_figures import Figures, row_figures
from workbench.services.batch_manifest import BatchRow, read_batch_manifest
from workbench.services.skull_check import EXIT_CHECK

MARKER = "batch_row.json"
MARKER_FORMAT = 1
#: one thread for every numeric library in a worker process
THREAD_ENV = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "NUMBA_NUM_THREADS": "1",
}
DEFAULT_MEMORY_LIMIT = "4GiB"
#: row statuses whose outputs are complete (a resumed batch does not run them again);
#: "check": written, but the registration asks for a check (exit status 3)
DONE = ("ok", "check")
Entry = Callable[[list[str]], int]
Notify = Callable[[str], None]


@dataclass
class RowResult:
    """What became of one row: status ``ok`` | ``failed``, with its figures and message."""

    row: BatchRow
    status: str
    exit_status: int | None = None
    seconds: float | None = None
    message: str = ""
    figures: Figures = field(default_factory=dict)
    inputs: dict[str, str] = field(default_factory=dict)
    resumed: bool = False
    worker: str = ""


# ----------------------------------------------------------------------------- inputs


def file_digest(path: Path) -> str:
    """SHA-256 of a file, or of a folder's files (their relative names and digests, sorted)."""
    h = hashlib.sha256()
    if path.is_dir():
        for item in sorted(p for p in path.rglob("*") if p.is_file()):
            h.update(item.relative_to(path).as_posix().encode() + b"\0")
            h.update(file_digest(item).encode() + b"\n")
        return h.hexdigest()
    with path.open("rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def row_inputs(row: BatchRow) -> list[Path]:
    """Every file or folder a row reads: its paths in the argv (``sample:`` resolved), and
    for ``validate`` the skulls, truths and packs its manifest lists."""
    from workbench.io.samples import resolve_input

    found: list[Path] = []
    argv = row.argv
    out_at = argv.index("--out") + 1
    for i, token in enumerate(argv[1:], start=1):
        if i == out_at or token.startswith("--"):
            continue
        path: Path | None = None
        if token.startswith("sample:"):
            with contextlib.suppress(WorkbenchError, OSError):  # the command reports it
                path = resolve_input(token)
        elif Path(token).is_absolute() and Path(token).exists():
            path = Path(token)
        if path is not None and path not in found:
            found.append(path)
    if row.job == "validate" and found:
        from workbench.services.validation import read_manifest, validation_inputs

        with contextlib.suppress(WorkbenchError, OSError):
            found += [p for p in validation_inputs(read_manifest(found[0])) if p not in found]
    return found


def input_digests(row: BatchRow) -> dict[str, str]:
    return {str(p): file_digest(p) for p in row_inputs(row) if p.exists()}


# ----------------------------------------------------------------------------- markers


def read_marker(folder: Path) -> dict[str, Any] | None:
    try:
        data = json.loads((folder / MARKER).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) and data.get("batch_format") == MARKER_FORMAT else None


def write_marker(result: RowResult) -> Path:
    """``DIR/<id>/batch_row.json`` (atomic), the record ``resume`` trusts."""
    row = result.row
    row.out.mkdir(parents=True, exist_ok=True)
    data = {
        "batch_format": MARKER_FORMAT,
        "id": row.row_id,
        "job": row.job,
        "manifest_line": row.line,
        "argv": row.argv,
        "inputs_sha256": result.inputs,
        "status": result.status,
        "exit_status": result.exit_status,
        "message": result.message,
        "seconds": result.seconds,
        "figures": result.figures,
        "worker": result.worker,
        "finished_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    path = row.out / MARKER
    tmp = path.with_name(MARKER + ".part")
    tmp.write_text(json.dumps(data, indent=2) + "\n", encoding="utf-8")
    tmp.replace(path)
    return path


def _inside(path: Path, folder: Path) -> bool:
    try:
        path.resolve().relative_to(folder.resolve())
    except ValueError:
        return False
    return True


def plan(
    rows: Sequence[BatchRow], out: Path, manifest: Path, resume: bool
) -> tuple[list[tuple[BatchRow, dict[str, str]]], list[RowResult]]:
    """``(to_run, finished)``: rows to run with their input digests, and rows ``resume`` skips.

    Raises ``InputError`` (nothing has run) for an output folder that is not
    new or empty without ``resume``, a ``DIR/<id>`` the batch did not make, or
    an input inside ``DIR``.
    """
    if out.exists() and not out.is_dir():
        raise InputError(out, "is a file", "give a folder for --out")
    if out.is_dir() and any(out.iterdir()) and not resume:
        raise InputError(
            out,
            "exists and is not empty",
            "give --resume to continue a batch there, or a new folder",
        )
    problems = []
    if _inside(manifest, out):
        problems.append(f"the manifest {manifest} lies inside it")
    to_run, finished = [], []
    for row in rows:
        digests = input_digests(row)
        bad = [p for p in digests if _inside(Path(p), out)]
        if bad:
            problems.append(f"line {row.line} ({row.row_id}) reads {bad[0]} inside it")
            continue
        if not os.path.lexists(row.out):
            to_run.append((row, digests))
            continue
        marker = read_marker(row.out) if row.out.is_dir() else None
        if marker is None:
            problems.append(
                f"line {row.line}: {row.out} exists and is not a batch row's folder "
                f"(no {MARKER}); the batch never writes over it"
            )
        elif (
            marker.get("status") in DONE
            and marker.get("argv") == row.argv
            and (marker.get("inputs_sha256") == digests)
        ):
            finished.append(_from_marker(row, marker))
        else:
            to_run.append((row, digests))
    if problems:
        raise InputError(
            out, "; ".join(problems), "move it aside or choose another --out; nothing was run"
        )
    return to_run, finished


def _from_marker(row: BatchRow, marker: dict[str, Any]) -> RowResult:
    return RowResult(
        row,
        str(marker.get("status")),
        marker.get("exit_status"),
        marker.get("seconds"),
        marker.get("message", ""),
        marker.get("figures") or {},
        marker.get("inputs_sha256") or {},
        resumed=True,
        worker=marker.get("worker", ""),
    )


def _clear_stale(row: BatchRow, notify: Notify) -> None:
    """Before a rerun: a marker-only folder is emptied, a stale one kept as ``DIR/<id>.1``."""
    from workbench.io.outputs import backup_existing

    if not row.out.is_dir():
        return
    others = [p for p in row.out.iterdir() if p.name != MARKER]
    if not others:
        (row.out / MARKER).unlink(missing_ok=True)
        return
    kept = backup_existing(row.out)
    notify(f"  {row.row_id}: the previous run's folder kept as {kept}")


# ----------------------------------------------------------------------------- the task


def run_row_task(entry: Entry, argv: list[str]) -> dict[str, Any]:
    """Run one command line in this process with one numeric thread; what it said and returned.

    This is the Dask task (one per row).  ``entry`` is the CLI's ``main``; its
    stdout and stderr are captured (one task at a time per worker thread).
    """
    from threadpoolctl import threadpool_limits

    out, err = io.StringIO(), io.StringIO()
    t0 = time.perf_counter()
    with (
        threadpool_limits(limits=1),
        contextlib.redirect_stdout(out),
        contextlib.redirect_stderr(err),
    ):
        try:
            code = int(entry(list(argv)) or 0)
        except SystemExit as exc:  # argparse's own exit on a bad value
            code = exc.code if isinstance(exc.code, int) else 2
    return {
        "exit_status": code,
        "seconds": round(time.perf_counter() - t0, 3),
        "stdout": out.getvalue(),
        "stderr": err.getvalue(),
        "worker": f"{os.uname().nodename}:{os.getpid()}",
    }


def error_line(stderr: str, code: int, stdout: str = "") -> str:
    """The command's one-line error message (its stderr's ``error:`` line; else the cases
    a validate run reports failed on stdout; else stderr's last line or the exit status)."""
    lines = [ln.strip() for ln in stderr.splitlines() if ln.strip()]
    for ln in reversed(lines):
        if ": error:" in ln or "unexpected error" in ln:
            return ln
    failed = [ln.strip() for ln in stdout.splitlines() if ": failed: " in ln]
    if failed:
        return "; ".join(failed)
    return lines[-1] if lines else f"exit status {code}"


# ----------------------------------------------------------------------------- engines


@contextlib.contextmanager
def dask_client(
    workers: int, scheduler: str | None, memory_limit: str = DEFAULT_MEMORY_LIMIT
) -> Iterator[Any]:
    """A ``distributed.Client``: on ``scheduler``, or on a new local cluster of ``workers``."""
    import dask
    from distributed import Client, LocalCluster

    if scheduler:
        try:
            client = Client(scheduler, timeout="20s")
        except (OSError, TimeoutError) as exc:
            raise InputError(
                f"--scheduler {scheduler}",
                f"cannot be reached ({exc})",
                "start one with `dask scheduler` (or a dask-jobqueue cluster) and give its "
                "address tcp://HOST:PORT",
            ) from None
        with client:
            yield client
        return
    environ = {**dask.config.get("distributed.nanny.pre-spawn-environ", {}), **THREAD_ENV}
    config = {
        "distributed.nanny.pre-spawn-environ": environ,
        # a row whose worker died (memory limit) is recorded as failed, not run again
        "distributed.scheduler.allowed-failures": 0,
    }
    # distributed's nanny writes the workers' pre-spawn environment (OMP_NUM_THREADS=1 ...)
    # into this process's os.environ and leaves it there: every later parallel loop of a
    # window or script that ran a batch would run on one thread (and a reference head
    # built afterwards would differ in the last bits).  Put the environment back.
    saved = dict(os.environ)
    try:
        with dask.config.set(config):
            cluster = LocalCluster(
                n_workers=workers,
                threads_per_worker=1,
                processes=True,
                memory_limit=memory_limit,
                host="127.0.0.1",
                dashboard_address=None,
                env=dict(THREAD_ENV),
            )
            _restore_environ(saved)
            with cluster, Client(cluster) as client:
                yield client
    finally:
        _restore_environ(saved)


def _restore_environ(saved: Mapping[str, str]) -> None:
    """Make ``os.environ`` equal to ``saved`` again."""
    for name in set(os.environ) - set(saved):
        del os.environ[name]
    for name, value in saved.items():
        if os.environ.get(name) != value:
            os.environ[name] = value


def _run_dask(
    tasks: Sequence[BatchRow],
    entry: Entry,
    client: Any,
    done: Callable[[BatchRow, dict[str, Any]], None],
    died: str,
) -> None:
    from distributed import as_completed

    token = uuid.uuid4().hex[:8]
    futures = {
        client.submit(
            run_row_task, entry, row.argv, key=f"workbench-batch-{row.row_id}-{token}", pure=False
        ): row
        for row in tasks
    }
    for future in as_completed(futures):
        row = futures[future]
        try:
            outcome = future.result()
        except Exception as exc:  # noqa: BLE001 - a worker's death must not stop the batch
            outcome = {
                "exit_status": None,
                "seconds": None,
                "stderr": f"{type(exc).__name__}: {exc}\n",  # the whole story, in the log
                "died": f"{died} ({type(exc).__name__})",
            }
        done(row, outcome)


# ----------------------------------------------------------------------------- the batch


def run_batch(
    manifest: str | Path,
    out: str | Path,
    *,
    commands: Mapping[str, argparse.ArgumentParser],
    entry: Entry,
    workers: int = 2,
    scheduler: str | None = None,
    resume: bool = False,
    memory_limit: str = DEFAULT_MEMORY_LIMIT,
    notify: Notify | None = None,
) -> list[RowResult]:
    """Run every row of ``manifest`` into ``out``; the results in manifest order.

    ``commands``: the sub-command parsers by name (columns are checked against
    them); ``entry``: the CLI's ``main(argv) -> exit status``.  ``workers=0``
    runs in this process; otherwise on Dask (``scheduler`` or a local
    cluster).  ``notify`` gets one progress line per finished row.  Writes
    ``out/<id>/batch_row.json`` for every row that ran and ``out/logs/<id>.log``
    (its stdout and stderr); the summary is the caller's
    (:mod:`workbench.reporting.batch_report`).
    """
    say = notify or (lambda m: print(m, file=sys.stderr, flush=True))
    manifest, out = Path(manifest), Path(os.path.abspath(out))
    rows = read_batch_manifest(manifest, out, commands)
    to_run, finished = plan(rows, out, manifest, resume)
    results: dict[str, RowResult] = {r.row.row_id: r for r in finished}
    total = len(rows)
    for r in finished:
        say(_progress_line(len(results), total, r))
    out.mkdir(parents=True, exist_ok=True)
    digests = {row.row_id: d for row, d in to_run}
    runnable = []
    for row, d in to_run:
        _clear_stale(row, say)
        if row.error is not None:  # argparse refused a value: recorded, never run
            refused = {"exit_status": 2, "seconds": None, "stdout": "", "stderr": row.error}
            results[row.row_id] = _record(row, d, refused, out)
            say(_progress_line(len(results), total, results[row.row_id]))
            continue
        if row.argv[-1] != str(row.out):  # a command that writes one file into DIR/<id>/
            row.out.mkdir(parents=True, exist_ok=True)
        runnable.append(row)

    def done(row: BatchRow, outcome: dict[str, Any]) -> None:
        results[row.row_id] = _record(row, digests[row.row_id], outcome, out)
        say(_progress_line(len(results), total, results[row.row_id]))

    if runnable and workers == 0 and not scheduler:
        for row in runnable:
            done(row, run_row_task(entry, row.argv))
    elif runnable:
        n = max(1, min(workers, len(runnable)))
        died = "the worker running it died" + (
            "" if scheduler else f" (over its memory limit of {memory_limit}, or it crashed)"
        )
        with dask_client(n, scheduler, memory_limit) as client:
            _run_dask(runnable, entry, client, done, died)
    return [results[r.row_id] for r in rows]


def _record(
    row: BatchRow, digests: dict[str, str], outcome: dict[str, Any], out: Path
) -> RowResult:
    code = outcome.get("exit_status")
    stdout, stderr = outcome.get("stdout", ""), outcome.get("stderr", "")
    if outcome.get("died"):
        result = RowResult(row, "failed", None, None, outcome["died"], inputs=digests)
    elif code == 0:
        figures = row_figures(row.job, row.argv, stdout)
        result = RowResult(row, "ok", 0, outcome.get("seconds"), "", figures, digests)
    elif code == EXIT_CHECK:  # written, but the registration asks for a check (issue 28)
        figures = row_figures(row.job, row.argv, stdout)
        reasons = [ln[len("CHECK: ") :] for ln in stdout.splitlines() if ln.startswith("CHECK: ")]
        message = "CHECK: " + ("; ".join(reasons) or error_line(stderr, code, stdout))
        result = RowResult(row, "check", code, outcome.get("seconds"), message, figures, digests)
    else:
        message = error_line(stderr, code or 0, stdout)
        result = RowResult(row, "failed", code, outcome.get("seconds"), message, inputs=digests)
        if row.job == "validate":  # the cases that did run are in results.csv
            result.figures = row_figures(row.job, row.argv, stdout)
    result.worker = outcome.get("worker", "")
    logs = out / "logs"
    logs.mkdir(exist_ok=True)
    (logs / f"{row.row_id}.log").write_text(
        f"$ workbench {' '.join(row.argv)}\n{stdout}{stderr}", encoding="utf-8"
    )
    write_marker(result)
    return result


def summary_record(result: RowResult) -> dict[str, Any]:
    """One row of the summary as plain data (:mod:`workbench.reporting.batch_report`)."""
    from workbench.services.batch_figures import validate_rows

    row = result.row
    return {
        "id": row.row_id,
        "job": row.job,
        "line": row.line,
        "status": result.status,
        "resumed": result.resumed,
        "exit_status": result.exit_status,
        "seconds": result.seconds,
        "message": result.message,
        "folder": str(row.out),
        "figures": dict(result.figures),
        "cases": validate_rows(row.out) if row.job == "validate" else [],
    }


def _progress_line(done: int, total: int, r: RowResult) -> str:
    width = 20
    filled = round(width * done / max(total, 1))
    bar = "#" * filled + "." * (width - filled)
    took = "" if r.seconds is None else f" {r.seconds:.1f} s"
    status = "ok (resumed)" if r.resumed else r.status
    line = f"[{bar}] {done}/{total} {r.row.row_id} ({r.row.job}): {status}{took}"
    return line + (f": {r.message}" if r.status != "ok" and r.message else "")
