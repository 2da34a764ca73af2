"""``workbench batch MANIFEST.csv --out DIR``: a study of many jobs, each its own single command.

Each row of the manifest (columns ``id``, ``job``, ``input`` and the job's
options; see :mod:`workbench.pipelines.batch.manifest`) runs exactly the
job it names, read by that sub-command's own parser and run by its own
function (which calls the job's pipeline), in a Dask worker
(:mod:`workbench.pipelines.batch.run`), into ``DIR/<id>/``; the row's figures
come back as values.  Afterwards
``DIR/summary.csv``, ``summary.md``, ``plots/`` and ``summary.pdf``
(:mod:`workbench.reporting.batch_report`); each row's output in
``DIR/logs/<id>.log``.  Exit status 0 when every row is ok, 3 when a row
asks for a check, 2 when one failed.

- Ctrl-C: the batch stops, says ``interrupted: N of M rows done; rerun with
  --resume`` and exits with status 130; the finished rows keep their
  markers, so ``--resume`` runs only the rest.
- A closed stdout or stderr (``workbench batch ... 2>&1 | head -2``) does not
  stop the batch: it stops printing to that stream, runs every row, writes
  the summary files and exits with the status of the rows.
- One batch at a time per ``--out`` (``DIR/.batch.lock``, held until the
  summary is written): a second one is refused naming the other's pid.
"""

from __future__ import annotations

import argparse
import errno
import os
import sys
from pathlib import Path
from typing import TextIO


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "batch",
        help="run a manifest of reconstruct/validate/fit-scan/age/animate jobs on Dask",
        description="Run every row of a CSV manifest (columns id, job, input and one column per "
        "long option of the job, named without dashes; empty = default, true = a bare flag, "
        "several values of a repeatable option separated by ';') as its own single command, "
        "on a Dask LocalCluster or an existing scheduler. Each row writes DIR/<id>/ (the "
        "files the single command writes, plus batch_row.json); then DIR/summary.csv, "
        "summary.md, plots/ and summary.pdf.",
    )
    p.add_argument("manifest", type=Path)
    p.add_argument(
        "--out",
        type=Path,
        required=True,
        help="batch folder: new or empty (or a previous batch's with --resume); the inputs may "
        "not lie in it",
    )
    p.add_argument(
        "--workers",
        type=int,
        default=None,
        metavar="N",
        help="local worker processes, one thread each (default: the number of cores, at most "
        "the number of jobs); 0 runs the jobs one after another in this process, without Dask",
    )
    p.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="an existing Dask scheduler, tcp://HOST:PORT (e.g. a dask-jobqueue SLURMCluster's); "
        "its workers must see the same paths and have the workbench installed",
    )
    p.add_argument(
        "--memory-limit",
        default=None,
        metavar="SIZE",
        help="memory per local worker (e.g. 4GiB, the default); a job that goes over it is "
        "recorded as failed",
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="skip rows whose folder has an ok batch_row.json with the same command line and "
        "the same input SHA-256s; run the others again (a stale folder is kept as DIR/<id>.1)",
    )
    p.set_defaults(handler=run)


def commands() -> dict[str, argparse.ArgumentParser]:
    """The sub-command parsers of this CLI by name (the manifest's columns are checked on them)."""
    from workbench.cli.main import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


class _Stream:
    """Prints to a stream until its reader goes away, then quietly drops what follows.

    A closed pipe (``| head``) must not stop the batch half-way: the rows go
    on and the summary files are still written.  The stream's descriptor is
    pointed at the null device, so the interpreter's last flush does not
    fail either.
    """

    def __init__(self, stream: TextIO):
        self.stream, self.closed = stream, False

    def __call__(self, text: str) -> None:
        if self.closed:
            return
        try:
            print(text, file=self.stream, flush=True)
        except (BrokenPipeError, ValueError):
            self._close()
        except OSError as exc:
            if exc.errno != errno.EPIPE:
                raise
            self._close()

    def _close(self) -> None:
        self.closed = True
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, self.stream.fileno())
            os.close(devnull)
        except (OSError, ValueError):
            pass


def run(args: argparse.Namespace) -> int:
    from workbench.pipelines.batch.lock import batch_lock
    from workbench.pipelines.batch.run import BatchInterrupted

    err = _Stream(sys.stderr)
    try:
        with batch_lock(args.out):
            return _run(args, _Stream(sys.stdout), err)
    except BatchInterrupted as exc:
        err(f"workbench batch: {exc}")
        # a local cluster stopped while it started fails Dask's own exit hook: this process
        # ends now, and its one line above says all there is to say
        sys.unraisablehook = lambda _unraisable: None
        return 130
    except KeyboardInterrupt:  # after the rows: while the summary was written
        err(
            "workbench batch: interrupted while writing the summary; every row is done: "
            "rerun with --resume to write it"
        )
        return 130


def _run(args: argparse.Namespace, say: _Stream, notify: _Stream) -> int:
    from workbench import __version__
    from workbench.core.errors import InputError
    from workbench.pipelines.batch.run import DEFAULT_MEMORY_LIMIT, run_batch, summary_record
    from workbench.reporting.batch_report import write_summary

    if args.workers is not None and not 0 <= args.workers <= 256:
        raise InputError(f"--workers {args.workers}", "must be 0 .. 256")
    if args.scheduler and (args.workers is not None or args.memory_limit):
        raise InputError(
            "--scheduler",
            "runs on that cluster's workers",
            "--workers and --memory-limit are for the local cluster; size the remote one itself",
        )
    workers = (os.cpu_count() or 1) if args.workers is None else args.workers
    memory = args.memory_limit or DEFAULT_MEMORY_LIMIT
    _check_memory(memory)
    results = run_batch(
        args.manifest,
        args.out,
        commands={k: v for k, v in commands().items() if k != "batch"},
        workers=workers,
        scheduler=args.scheduler,
        resume=args.resume,
        memory_limit=memory,
        notify=notify,
    )
    engine = (
        f"Dask scheduler {args.scheduler}"
        if args.scheduler
        else "this process, one job after another"
        if workers == 0
        else f"Dask LocalCluster, up to {workers} worker processes x 1 thread, {memory} each"
    )
    info = {"manifest": str(args.manifest), "output folder": str(args.out), "engine": engine}
    records = [summary_record(r) for r in results]
    written = write_summary(records, Path(args.out), info, software=f"workbench {__version__}")
    failed = [r for r in results if r.status not in ("ok", "check")]
    checks = [r for r in results if r.status == "check"]
    to_check = f", {len(checks)} to check (see summary.md)" if checks else ""
    say(
        f"{len(results) - len(failed) - len(checks)} of {len(results)} jobs ok{to_check}; "
        "wrote " + ", ".join(str(p) for p in written[:4])
    )
    # a row to check is not a plain success either (issue 28): exit 3 unless one failed
    return 2 if failed else 3 if checks else 0


def _check_memory(text: str) -> None:
    from dask.utils import parse_bytes

    from workbench.core.errors import InputError

    try:
        size = parse_bytes(text)
    except (ValueError, TypeError):
        raise InputError(f"--memory-limit {text}", "is not a size", "e.g. 4GiB or 2000MB") from None
    if size < 256 * 2**20:
        raise InputError(f"--memory-limit {text}", "is too small for any job (256 MiB at least)")
