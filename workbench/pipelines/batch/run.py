"""Batch studies: every row of a manifest run as its own single command, on Dask distributed.

``workbench batch MANIFEST.csv --out DIR`` (see :mod:`workbench.pipelines.batch.manifest`
for the manifest).  Each row is exactly one job: its argv is built from the
row and read by the job's own parser (passed in: this layer cannot import
the CLI, which builds them), and the parsed options go to the job's function
(the parser's ``handler``: the one the command line runs, which calls the
job's pipeline) inside a Dask worker.  So ``DIR/<id>/`` holds byte for byte
the files the single command writes (mm, each command's own frames), plus
the batch's marker ``DIR/<id>/batch_row.json``, and the row's key figures
come back from the job as values (:class:`~workbench.pipelines.outcome.JobOutcome`).

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
must be new or empty unless ``resume``, and a ``DIR/<id>`` the batch did
not start (no marker, and no ``DIR/logs/<id>.log``) is refused; a stale
batch folder is kept as ``DIR/<id>.1`` before the rerun.

Interruptions and concurrency:

- The marker is written by the task itself (in the worker), atomically
  (a temporary file, then :func:`os.replace`), right after the command's
  outputs are final; a row's log is started before the row runs, so a
  row folder left without a marker (Ctrl-C, a killed machine) is
  recognised as the batch's own and run again by ``resume`` (its old
  folder kept as ``DIR/<id>.1``), not refused.
- Ctrl-C raises :class:`BatchInterrupted` (a ``KeyboardInterrupt``) carrying
  how many rows finished.  Local Dask workers ignore SIGINT once started
  (a preload) and write their stderr to ``DIR/logs/_dask-workers.log``, so
  the terminal shows no worker tracebacks; after a Ctrl-C Dask's loggers
  are silenced (a cluster closed under running tasks complains at length).
- One batch at a time per ``DIR``: :func:`~workbench.pipelines.batch.lock.batch_lock`
  holds ``DIR/.batch.lock`` (see :mod:`workbench.pipelines.batch.lock`).
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import io
import json
import logging
import os
import sys
import time
import uuid
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from workbench.core.errors import InputError, WorkbenchError
from workbench.core.safe_names import child_path
from workbench.io.atomic import write_text_atomic
from workbench.pipelines.batch.figures import Figures
from workbench.pipelines.batch.lock import LOCK, batch_lock
from workbench.pipelines.batch.manifest import BatchRow, read_batch_manifest
from workbench.pipelines.outcome import JobOutcome, failure_status
from workbench.services.registration.skull_check import EXIT_CHECK

MARKER = "batch_row.json"
MARKER_FORMAT = 1
#: the first line of every row log (``DIR/logs/<id>.log``) the batch writes
LOG_START = "$ workbench "
#: the second line of a row log while the row runs (replaced by its output when recorded)
STARTED, NOT_FINISHED = "(started ", "; not finished)"
#: one thread for every numeric library in a worker process
THREAD_ENV = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "NUMBA_NUM_THREADS": "1",
}
DEFAULT_MEMORY_LIMIT = "4GiB"
#: the local workers' stderr, in DIR/logs (no row id starts with "_")
WORKER_LOG = "_dask-workers.log"
#: a local worker's preload (Dask runs a preload text holding a space as a script): Ctrl-C in
#: the terminal reaches the whole process group, but only the batch's own process acts on it
IGNORE_SIGINT = "import signal; signal.signal(signal.SIGINT, signal.SIG_IGN)\n"
#: row statuses whose outputs are complete (a resumed batch does not run them again);
#: "check": written, but the registration asks for a check (exit status 3)
DONE = ("ok", "check")
Notify = Callable[[str], None]


class BatchInterrupted(KeyboardInterrupt):
    """Ctrl-C stopped a batch: ``finished`` of ``total`` rows have their marker."""

    def __init__(self, finished: int, total: int):
        self.finished, self.total = finished, total
        super().__init__(
            f"interrupted: {finished} of {total} rows done; rerun with --resume to run the rest"
        )


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
        from workbench.services.validation.run import read_manifest, validation_inputs

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
    write_text_atomic(path, json.dumps(data, indent=2) + "\n")
    return path


def log_path(out: Path, row: BatchRow) -> Path:
    """``DIR/logs/<id>.log``: the row's command line, then what it printed."""
    return child_path(out / "logs", f"{row.row_id}.log")


def _start_log(out: Path, row: BatchRow) -> None:
    """Start the row's log before it runs: the record that ``DIR/<id>`` is the batch's own."""
    path = log_path(out, row)
    path.parent.mkdir(exist_ok=True)
    stamp = time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())
    write_text_atomic(path, f"{LOG_START}{' '.join(row.argv)}\n{STARTED}{stamp}{NOT_FINISHED}\n")


def _started_by_batch(out: Path, row: BatchRow) -> bool:
    """True when this batch folder's log says a batch started the row ``row`` and never
    recorded it: ``DIR/<id>`` is then that run's unfinished folder, not the user's."""
    try:
        with log_path(out, row).open(encoding="utf-8") as fh:
            first, second = fh.readline(), fh.readline().rstrip("\n")
    except (OSError, UnicodeDecodeError, InputError):
        return False
    return (
        first.startswith(LOG_START) and second.startswith(STARTED) and second.endswith(NOT_FINISHED)
    )


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
    if out.is_dir() and any(p.name != LOCK for p in out.iterdir()) and not resume:
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
        try:
            child_path(out, row.row_id)
        except InputError as exc:
            problems.append(f"line {row.line}: {exc.problem}")
            continue
        if not os.path.lexists(row.out):
            to_run.append((row, digests))
            continue
        own = row.out.is_dir() and not row.out.is_symlink()
        marker = read_marker(row.out) if own else None
        if marker is None and own and _started_by_batch(out, row):
            to_run.append((row, digests))  # the batch's own, left unfinished: run it again
        elif marker is None:
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


def run_row_task(options: argparse.Namespace) -> dict[str, Any]:
    """Run one job in this process with one numeric thread: its status, figures and what it said.

    This is the Dask task (one per row).  ``options`` are the row's options as
    its job's parser read them; ``options.handler`` is the job's function (the
    one the command line runs, calling the job's pipeline), which returns a
    :class:`~workbench.pipelines.outcome.JobOutcome` with the figures as values.
    What it prints is captured for the row's log (one task at a time per worker
    thread); an error becomes the command's own one-line message
    (:func:`~workbench.pipelines.outcome.failure_status`).
    """
    from threadpoolctl import threadpool_limits

    out, err = io.StringIO(), io.StringIO()
    t0 = time.perf_counter()
    outcome: JobOutcome | int | None
    with (
        threadpool_limits(limits=1),
        contextlib.redirect_stdout(out),
        contextlib.redirect_stderr(err),
    ):
        try:
            outcome = options.handler(options)
        except SystemExit as exc:  # argparse's own exit on a value checked late
            outcome = exc.code if isinstance(exc.code, int) else 2
        except Exception as exc:  # noqa: BLE001 - the job's error is the row's message
            outcome = failure_status(exc, options)
    done = outcome if isinstance(outcome, JobOutcome) else JobOutcome(int(outcome or 0))
    if done.status == 130:  # the job saw Ctrl-C: the batch stops too
        raise KeyboardInterrupt
    return {
        "exit_status": done.status,
        "figures": dict(done.figures),
        "check": list(done.check),
        "seconds": round(time.perf_counter() - t0, 3),
        "stdout": out.getvalue(),
        "stderr": err.getvalue(),
        "worker": f"{os.uname().nodename}:{os.getpid()}",
    }


def run_row(row: BatchRow, digests: dict[str, str], out: Path) -> RowResult:
    """Run one row and record it (its log and marker) at once: the Dask task.

    The marker is written here, in the worker, as soon as the job's
    outputs are final, so an interrupted batch keeps every finished row.
    """
    assert row.options is not None  # rows argparse refused are recorded, never run
    return _record(row, digests, run_row_task(row.options), out)


def error_line(stderr: str, code: int, stdout: str = "") -> str:
    """The job's one-line error message (its stderr's ``error:`` line; else the cases
    a validate run reports failed; else stderr's last line or the exit status)."""
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
    workers: int,
    scheduler: str | None,
    memory_limit: str = DEFAULT_MEMORY_LIMIT,
    worker_log: Path | None = None,
) -> Iterator[Any]:
    """A ``distributed.Client``: on ``scheduler``, or on a new local cluster of ``workers``.

    ``worker_log``: the file the local workers' stderr goes to (else this
    process's stderr).
    """
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
        with dask.config.set(config), _stderr_to(worker_log):
            cluster = LocalCluster(
                n_workers=workers,
                threads_per_worker=1,
                processes=True,
                memory_limit=memory_limit,
                host="127.0.0.1",
                dashboard_address=None,
                env=dict(THREAD_ENV),
                # the workers never see the terminal's Ctrl-C: this process stops the batch
                preload=[*dask.config.get("distributed.worker.preload", []), IGNORE_SIGINT],
            )
            _restore_environ(saved)
            with cluster, Client(cluster) as client:
                yield client
    finally:
        _restore_environ(saved)


@contextlib.contextmanager
def _stderr_to(path: Path | None) -> Iterator[None]:
    """File descriptor 2 points at ``path`` (appended) while the block runs.

    The local cluster's worker processes are started meanwhile and keep it
    as their stderr: their messages (and the tracebacks of a Ctrl-C that
    reaches them while they start) go to the batch's log, not the terminal.
    """
    if path is None:
        yield
        return
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError, AttributeError):  # no descriptor 2 (a windowed program)
        yield
        return
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with path.open("ab") as fh:
            os.dup2(fh.fileno(), 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def _silence_dask() -> None:
    """Dask's loggers quiet from now on: after a Ctrl-C, a cluster closed under running (or
    starting) tasks complains at length, also while the interpreter exits."""
    prefixes = ("distributed", "tornado", "asyncio")
    names = [*prefixes] + [
        n for n in logging.root.manager.loggerDict if n.startswith(tuple(p + "." for p in prefixes))
    ]
    for name in names:
        logging.getLogger(name).setLevel(logging.CRITICAL + 1)


def _restore_environ(saved: Mapping[str, str]) -> None:
    """Make ``os.environ`` equal to ``saved`` again."""
    for name in set(os.environ) - set(saved):
        del os.environ[name]
    for name, value in saved.items():
        if os.environ.get(name) != value:
            os.environ[name] = value


def _run_dask(
    tasks: Sequence[BatchRow],
    client: Any,
    digests: Mapping[str, dict[str, str]],
    out: Path,
    done: Callable[[BatchRow, RowResult | dict[str, Any]], None],
    died: str,
) -> None:
    from distributed import as_completed

    token = uuid.uuid4().hex[:8]
    futures = {
        client.submit(
            run_row,
            row,
            digests[row.row_id],
            out,
            key=f"workbench-batch-{row.row_id}-{token}",
            pure=False,
        ): row
        for row in tasks
    }
    for future in as_completed(futures):
        row = futures[future]
        outcome: RowResult | dict[str, Any]
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
    workers: int = 2,
    scheduler: str | None = None,
    resume: bool = False,
    memory_limit: str = DEFAULT_MEMORY_LIMIT,
    notify: Notify | None = None,
) -> list[RowResult]:
    """Run every row of ``manifest`` into ``out``; the results in manifest order.

    ``commands``: the jobs' parsers by name (columns are checked against them,
    and each parser's ``handler`` default is the job's function).  ``workers=0``
    runs in this process; otherwise on Dask (``scheduler`` or a local
    cluster).  ``notify`` gets one progress line per finished row.  Writes
    ``out/<id>/batch_row.json`` for every row that ran and ``out/logs/<id>.log``
    (its stdout and stderr); the summary is the caller's
    (:mod:`workbench.reporting.batch_report`).
    """
    say = notify or (lambda m: print(m, file=sys.stderr, flush=True))
    manifest, out = Path(manifest), Path(os.path.abspath(out))
    rows = read_batch_manifest(manifest, out, commands)
    with batch_lock(out):
        to_run, finished = plan(rows, out, manifest, resume)
        try:
            results = _run_rows(rows, to_run, finished, out, workers, scheduler, memory_limit, say)
        except KeyboardInterrupt:
            raise BatchInterrupted(_finished_rows(rows), len(rows)) from None
    return [results[r.row_id] for r in rows]


def _finished_rows(rows: Sequence[BatchRow]) -> int:
    """How many rows have their marker (after an interruption)."""
    return sum(1 for r in rows if (m := read_marker(r.out)) is not None and m.get("argv") == r.argv)


def _run_rows(
    rows: Sequence[BatchRow],
    to_run: Sequence[tuple[BatchRow, dict[str, str]]],
    finished: Sequence[RowResult],
    out: Path,
    workers: int,
    scheduler: str | None,
    memory_limit: str,
    say: Notify,
) -> dict[str, RowResult]:
    results: dict[str, RowResult] = {r.row.row_id: r for r in finished}
    total = len(rows)
    for r in finished:
        say(_progress_line(len(results), total, r))
    digests = {row.row_id: d for row, d in to_run}
    runnable = []
    for row, d in to_run:
        _clear_stale(row, say)
        _start_log(out, row)
        if row.error is not None:  # argparse refused a value: recorded, never run
            refused = {"exit_status": 2, "seconds": None, "stdout": "", "stderr": row.error}
            results[row.row_id] = _record(row, d, refused, out)
            say(_progress_line(len(results), total, results[row.row_id]))
            continue
        if row.argv[-1] != str(row.out):  # a command that writes one file into DIR/<id>/
            row.out.mkdir(parents=True, exist_ok=True)
        runnable.append(row)

    def done(row: BatchRow, outcome: RowResult | dict[str, Any]) -> None:
        if isinstance(outcome, dict):  # the worker died: recorded here
            outcome = _record(row, digests[row.row_id], outcome, out)
        results[row.row_id] = outcome
        say(_progress_line(len(results), total, outcome))

    if runnable and workers == 0 and not scheduler:
        for row in runnable:
            done(row, run_row(row, digests[row.row_id], out))
    elif runnable:
        n = max(1, min(workers, len(runnable)))
        died = "the worker running it died" + (
            "" if scheduler else f" (over its memory limit of {memory_limit}, or it crashed)"
        )
        try:
            with dask_client(n, scheduler, memory_limit, out / "logs" / WORKER_LOG) as client:
                try:
                    _run_dask(runnable, client, digests, out, done, died)
                except KeyboardInterrupt:
                    _silence_dask()  # before the cluster closes
                    raise
        except KeyboardInterrupt:
            _silence_dask()  # also when it came while the cluster started
            raise
    return results


def _record(
    row: BatchRow, digests: dict[str, str], outcome: dict[str, Any], out: Path
) -> RowResult:
    code = outcome.get("exit_status")
    stdout, stderr = outcome.get("stdout", ""), outcome.get("stderr", "")
    figures = dict(outcome.get("figures") or {})
    if outcome.get("died"):
        result = RowResult(row, "failed", None, None, outcome["died"], inputs=digests)
    elif code == 0:
        result = RowResult(row, "ok", 0, outcome.get("seconds"), "", figures, digests)
    elif code == EXIT_CHECK:  # written, but the registration asks for a check (issue 28)
        reasons = list(outcome.get("check") or ())
        message = "CHECK: " + ("; ".join(reasons) or error_line(stderr, code, stdout))
        result = RowResult(row, "check", code, outcome.get("seconds"), message, figures, digests)
    else:
        message = error_line(stderr, code or 0, stdout)
        # a validate run whose cases partly failed still has figures for those that ran
        result = RowResult(
            row, "failed", code, outcome.get("seconds"), message, figures, inputs=digests
        )
    result.worker = outcome.get("worker", "")
    write_marker(result)  # first: a row with its marker is done, whatever happens next
    log = log_path(out, row)
    log.parent.mkdir(exist_ok=True)
    write_text_atomic(log, f"{LOG_START}{' '.join(row.argv)}\n{stdout}{stderr}")
    return result


def summary_record(result: RowResult) -> dict[str, Any]:
    """One row of the summary as plain data (:mod:`workbench.reporting.batch_report`)."""
    from workbench.pipelines.batch.figures import validate_rows

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
