"""Cells of the tables the workbench writes, made safe for spreadsheets and Markdown.

A spreadsheet runs a CSV cell that starts with ``=``, ``+``, ``-``, ``@``, a
tab or a line break as a formula, so a case id or message such as
``=cmd|' /C calc'!A0`` would run when a results table is opened.
:func:`csv_cell` / :func:`csv_row` give such text a leading apostrophe
(OWASP's advice on CSV injection); numbers stay numbers, negative ones too.
:func:`md_cell` escapes ``|`` and removes line breaks, so user text cannot
split or end a Markdown table row.

Pure Python; the CSV and Markdown writers of ``io`` and ``reporting`` call these.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

#: first characters that make a spreadsheet read a cell as a formula
FORMULA_STARTS = ("=", "+", "-", "@", "\t", "\r", "\n")


def _is_number(text: str) -> bool:
    try:
        return math.isfinite(float(text)) and text.strip() == text
    except ValueError:
        return False


def csv_cell(value: object) -> object:
    """``value`` safe for a spreadsheet: text that would start a formula gets a leading ``'``.

    Numbers (int, float, and text that is one, such as ``-1.5``) and empty
    cells pass unchanged, so numeric columns stay numeric.
    """
    if not isinstance(value, str) or not value.startswith(FORMULA_STARTS):
        return value
    if _is_number(value):
        return value
    return "'" + value


def csv_row(row: Mapping[str, object]) -> dict[str, object]:
    """Every cell of ``row`` through :func:`csv_cell` (for ``csv.DictWriter.writerow``)."""
    return {k: csv_cell(v) for k, v in row.items()}


def md_cell(value: object) -> str:
    """``value`` as text for a Markdown table cell: ``|`` escaped, line breaks made spaces."""
    text = "" if value is None else str(value)
    text = text.replace("\\", "\\\\").replace("|", "\\|")
    return " ".join(text.replace("\r\n", "\n").replace("\r", "\n").split("\n"))
