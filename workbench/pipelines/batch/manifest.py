"""The manifest of ``workbench batch``: one row per job, each row turned into a command line.

A manifest is a CSV file with a header.  Required columns: ``id`` (the row's
output folder name: letters A-Z a-z, digits, ``-``, ``_``, ``.`` and spaces,
starting with a letter or digit, unique also without letter case; see
:mod:`workbench.core.safe_names`), ``job`` (a sub-command: ``reconstruct``, ``validate``,
``fit-scan``, ``age`` or ``animate``) and ``input`` (that sub-command's
positional input: a mesh, a CT, a validation manifest, a template pack,
``sample:NAME``, ``reference:male`` ...).  Every other column is one long
option of the sub-command, named without its dashes (``units``, ``sex``,
``truth``, ``leave-one-out`` or ``leave_one_out`` ...); in each row:

- an empty cell is the command's default (the option is not given);
- ``true`` gives a bare flag (``--no-pictures``), ``false`` leaves it out;
- an option that may be repeated (``template``, ``override``, ``muscle`` ...)
  takes several values separated by ``;``;
- a relative path is relative to the manifest's folder (like
  ``workbench validate``'s manifest); ``sample:NAME`` and ``reference:SEX``
  pass through as they are.

``--out`` is the batch's: ``DIR/<id>/`` for the commands that write a folder;
for those that write one file (``animate``) ``DIR/<id>/skin.ply`` unless the
row's ``out`` column gives a bare file name (``smile.glb``).  ``--force`` is
never a column: the batch never replaces an output the user made.

Lines starting with ``#`` are comments, and so are columns whose name starts
with ``#`` (``#notes``).  Every structural problem (unknown job,
an option the job does not have, a duplicate or unsafe id, no input) is
collected and raised as one :class:`~workbench.core.errors.InputError` naming
each manifest line, before anything runs.  The check is against the
sub-command's own argparse options (passed in as parsers: this layer cannot
import the CLI).
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import io
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

from workbench.core.errors import InputError
from workbench.core.safe_names import RULE, name_key, name_problem

#: the sub-commands a batch row may run
JOBS = ("reconstruct", "validate", "fit-scan", "age", "animate")
#: sub-commands whose --out is a file, and the file name a row gets by default
FILE_OUTPUT = {"animate": "skin.ply"}
#: names inside DIR the batch writes itself (no row id may take them)
RESERVED = ("logs", "plots", "summary.csv", "summary.md", "summary.pdf")
#: options the batch sets or that make no sense per row
NOT_COLUMNS = ("out", "force", "help", "debug", "list")
TRUE, FALSE = ("true", "yes", "1"), ("false", "no", "0")


@dataclass
class BatchRow:
    """One job of a manifest: its line, id, sub-command and the argv that runs it.

    ``argv`` is the whole command line after ``workbench`` (sub-command first,
    ``--out`` last); ``out`` the row's folder ``DIR/<id>``; ``error`` a problem
    argparse found in a value (the row is then recorded as failed, not run).
    """

    line: int
    row_id: str
    job: str
    argv: list[str]
    out: Path
    values: dict[str, str] = field(default_factory=dict)
    error: str | None = None
    #: ``argv`` parsed by the job's own parser (its ``handler`` is the job's function); None
    #: when argparse refused it (``error``)
    options: argparse.Namespace | None = None


def _option_map(parser: argparse.ArgumentParser) -> dict[str, argparse.Action]:
    return {
        s[2:]: a
        for a in parser._actions  # argparse keeps no public list of its options
        for s in a.option_strings
        if s.startswith("--")
    }


def _is_flag(action: argparse.Action) -> bool:
    return action.nargs == 0 or action.nargs == "?"


def _takes_path(action: argparse.Action | None) -> bool:
    return action is not None and action.type is Path


def _as_path(value: str, base: Path, known_path: bool) -> str:
    """A relative path made absolute against the manifest's folder; other values unchanged."""
    if re.match(r"^[A-Za-z][A-Za-z0-9_]+:", value) or Path(value).is_absolute():
        return value  # sample:NAME, reference:male, an absolute path
    candidate = base / value
    if known_path or candidate.exists():
        return str(candidate.resolve())
    return value


def _row_argv(
    job: str,
    values: dict[str, str],
    parser: argparse.ArgumentParser,
    base: Path,
    out: Path,
    where: str,
) -> tuple[list[str], list[str]]:
    """``(argv, problems)`` for one row's non-empty cells."""
    options = _option_map(parser)
    problems: list[str] = []
    argv = [job]
    argv.append(_as_path(values["input"], base, True))  # relative to the manifest
    out_name = FILE_OUTPUT.get(job)
    for column, value in values.items():
        if column in ("id", "job", "input"):
            continue
        name = column.replace("_", "-")
        if name == "out" and out_name is not None:
            problem = name_problem(value)
            if problem is not None:
                problems.append(
                    f"{where}: column out must be a bare file name, not {value!r} ({problem})"
                )
            out_name = value
            continue
        if name in NOT_COLUMNS:
            problems.append(f"{where}: column {column} is set by the batch, not the manifest")
            continue
        action = options.get(name)
        if action is None:
            problems.append(
                f"{where}: {job} has no option --{name} (column {column}); its options: "
                + ", ".join(sorted(n for n in options if n not in NOT_COLUMNS))
            )
            continue
        low = value.lower()
        if _is_flag(action) and low in TRUE:
            argv.append(f"--{name}")
        elif _is_flag(action) and low in FALSE:
            continue
        elif action.nargs == 0:
            problems.append(f"{where}: column {column} is a flag: true or false, not {value!r}")
        else:
            many = isinstance(action, argparse._AppendAction)
            for item in [v.strip() for v in value.split(";")] if many else [value]:
                if item:
                    argv += [f"--{name}", _as_path(item, base, _takes_path(action))]
    target = out if out_name is None else out / out_name
    argv += ["--out", str(target)]
    return argv, problems


def _parse(
    parser: argparse.ArgumentParser, argv: list[str]
) -> tuple[argparse.Namespace | None, str | None]:
    """The row's options as its job reads them, or argparse's own complaint about a value
    (bad choice, not a number)."""
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err):
            options = parser.parse_args(argv[1:])
    except SystemExit:
        lines = [ln for ln in err.getvalue().splitlines() if ln.strip()]
        return None, lines[-1].split(": error: ", 1)[-1] if lines else "invalid arguments"
    options.command, options.debug = argv[0], False  # as the command line's parser sets them
    return options, None


def read_batch_manifest(
    path: str | Path, out: Path, commands: Mapping[str, argparse.ArgumentParser]
) -> list[BatchRow]:
    """Rows of the manifest ``path``, each with the argv of its sub-command.

    ``out`` is the batch folder (each row writes ``out/<id>``); ``commands``
    the sub-command parsers by name (``workbench.cli.main`` builds them).
    Raises one ``InputError`` listing every structural problem, by line.
    """
    path = Path(path)
    base = path.resolve().parent
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(path, f"cannot be read as a CSV manifest ({exc})") from None
    reader = csv.reader(io.StringIO(text))
    header = [h.strip() for h in next(reader, [])]
    missing = [c for c in ("id", "job", "input") if c not in header]
    if missing:
        raise InputError(
            path,
            f"line 1: the header has no column {', '.join(missing)}",
            "the first line must name the columns id,job,input and the options",
        )
    dupes = sorted({h for h in header if header.count(h) > 1})
    if dupes or "" in header:
        raise InputError(path, f"line 1: empty or repeated column names {dupes or ['']}")
    rows: list[BatchRow] = []
    known = {n for parser in commands.values() for n in _option_map(parser)}
    problems: list[str] = [
        f"line 1: column {h} is no option of any job"
        for h in header
        if h not in ("id", "job", "input", "out")
        and not h.startswith("#")
        and h.replace("_", "-") not in known
    ]
    seen: dict[str, tuple[int, str]] = {}
    line = reader.line_num
    for cells in reader:
        start, line = line + 1, reader.line_num
        if not any(c.strip() for c in cells) or cells[0].lstrip().startswith("#"):
            continue
        where = f"line {start}"
        if len(cells) > len(header):
            problems.append(f"{where}: {len(cells)} cells for {len(header)} columns")
            continue
        values = {
            h: c.strip()
            for h, c in zip(header, cells, strict=False)
            if c.strip() and not h.startswith("#")  # a "#notes" column is the user's own
        }
        row_id, job = values.get("id", ""), values.get("job", "")
        problem = name_problem(row_id, RESERVED)
        if problem is None and ".partial" in row_id:
            problem = "'.partial' marks the workbench's unfinished folders"
        if problem is not None:
            problems.append(
                f"{where}: id {row_id!r} is not a usable folder name: {problem} ({RULE}; "
                f"not {', '.join(RESERVED)})"
            )
            continue
        key = name_key(row_id)
        if key in seen:
            first_line, first_id = seen[key]
            problems.append(
                f"{where}: id {row_id} is used twice (first on line {first_line}"
                + (
                    ""
                    if first_id == row_id
                    else f" as {first_id}; ids differing only in letter case are one folder"
                )
                + ")"
            )
            continue
        seen[key] = (start, row_id)
        if job not in JOBS:
            problems.append(f"{where}: job {job!r} is not one of {', '.join(JOBS)}")
            continue
        if job not in commands:
            problems.append(f"{where}: job {job} is not available in this workbench version")
            continue
        if "input" not in values:
            problems.append(f"{where}: no input")
            continue
        argv, bad = _row_argv(job, values, commands[job], base, out / row_id, where)
        problems += bad
        if not bad:
            options, error = _parse(commands[job], argv)
            rows.append(BatchRow(start, row_id, job, argv, out / row_id, values, error, options))
    if problems:
        raise InputError(path, "; ".join(problems), "fix these lines; nothing was run")
    if not rows:
        raise InputError(path, "holds no job rows")
    return rows
