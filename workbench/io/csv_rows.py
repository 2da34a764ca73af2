"""The one reader of the project's CSV tables: rows with their line numbers, errors naming the file.

Used by the tissue-depth tables (:mod:`workbench.io.tables`) and the guide
constants and rules (:mod:`workbench.services.guide_measure`).  Lines whose
first non-blank character is ``#`` are comments; a UTF-8 byte-order mark is
accepted; header names and values are stripped of surrounding blanks.
"""

from __future__ import annotations

import csv
import io
from collections.abc import Sequence
from pathlib import Path

from workbench.core.errors import InputError

Row = dict[str, str | None]


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
