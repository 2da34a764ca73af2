"""The one reader of the project's CSV tables, and the cell guards of the tables it writes.

:func:`read_csv_rows` reads the tissue-depth tables (:mod:`workbench.io.tables`)
and the guide constants and rules (:mod:`workbench.services.guides.measure`):
rows with their line numbers, errors naming the file.  Lines whose first
non-blank character is ``#`` are comments; a UTF-8 byte-order mark is
accepted; header names and values are stripped of surrounding blanks.

:func:`csv_cell` / :func:`csv_row` guard every cell of a CSV file the
workbench writes from user text (case ids, file names, messages) against
formula injection: a spreadsheet runs a cell that starts with ``=``, ``+``,
``-``, ``@``, a tab or a carriage return as a formula, so such text gets a
leading apostrophe (OWASP's advice); numbers stay numbers, also negative
ones.  :func:`md_cell` makes text safe inside a Markdown table cell.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from pathlib import Path

from workbench.core.errors import InputError
from workbench.core.table_cells import FORMULA_STARTS, csv_cell, csv_row, md_cell

Row = dict[str, str | None]

__all__ = ["FORMULA_STARTS", "Row", "csv_cell", "csv_row", "md_cell", "read_csv_rows"]


def read_csv_rows(
    path: Path,
    required: Sequence[str],
    *,
    expected: Sequence[str] = (),
    what: str = "table",
    short_rows: bool = True,
) -> list[tuple[int, Row]]:
    """``(line number, row)`` for every data row of the CSV file ``path``.

    Parameters
    ----------
    required : column names the header must have (else InputError naming them
        and, if given, the ``expected`` columns).
    what : what the file is, for the messages ("depth table", "guide table").
    short_rows : accept rows with fewer values than columns (their missing
        values are None); False refuses them naming the line.  Rows with more
        values than columns are always refused.
    """
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(path, f"the {what} cannot be read as UTF-8 text ({exc})") from None
    kept = [
        (i + 1, ln) for i, ln in enumerate(text.splitlines()) if not ln.lstrip().startswith("#")
    ]
    reader = csv.DictReader(io.StringIO("\n".join(ln for _, ln in kept)), skipinitialspace=True)
    if reader.fieldnames:
        reader.fieldnames = [f.strip() for f in reader.fieldnames]
    missing = [c for c in required if c not in (reader.fieldnames or [])]
    if missing:
        header = kept[0][0] if kept else 1
        raise InputError(
            path,
            f"line {header}: missing columns: {', '.join(missing)}",
            f"expected columns: {', '.join(expected)}" if expected else None,
        )
    rows: list[tuple[int, Row]] = []
    for row in reader:
        line = kept[reader.line_num - 1][0]  # the row's last physical line
        if None in row:
            n = len(reader.fieldnames or [])
            raise InputError(path, f"line {line}: more values than columns ({n})")
        if not short_rows and any(v is None for v in row.values()):
            raise InputError(path, f"line {line}: wrong number of values")
        rows.append((line, {k: (v.strip() if v is not None else None) for k, v in row.items()}))
    return rows
