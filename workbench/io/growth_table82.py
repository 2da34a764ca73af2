"""Kähler's Table 8.2 measurement list (``data_tables/growth/table82.csv``).

Each row is one measurement between two skin landmarks (catalogue codes)
after left/right duplication: ``measurement, kind, a, b, mid, region,
norm_measurement_id, note``.  ``kind`` is ``vertical`` (y), ``horizontal``
(x) or ``depth`` (z) of the Frankfort frame, ``euclidean`` (3-D) or ``arc``
(along the skin).  ``norm_measurement_id`` names the facial-norms
measurement that covers it; an empty one means there are no norms for it
here, and the growth solve lets it follow the global head scale.  Units mm.
"""

from __future__ import annotations

from dataclasses import dataclass
from os import PathLike
from pathlib import Path

from workbench.core.errors import InputError
from workbench.io.csv_rows import read_csv_rows
from workbench.io.growth_norms import growth_dir

KINDS = ("vertical", "horizontal", "depth", "euclidean", "arc")
#: the Frankfort-frame axis of each axis-aligned kind
AXIS_OF = {"horizontal": 0, "vertical": 1, "depth": 2}


@dataclass(frozen=True)
class Table82Row:
    measurement: str
    kind: str
    a: str
    b: str
    mid: str
    region: str
    norm_measurement_id: str
    note: str


def load_table82(path: str | PathLike[str] | None = None) -> tuple[Table82Row, ...]:
    """The rows of the shipped Table 8.2 list (or of ``path`` in the same format)."""
    file = Path(path) if path is not None else growth_dir() / "table82.csv"
    rows = []
    for line, row in read_csv_rows(file, ("kind", "a", "b"), what="measurement list"):
        kind = (row.get("kind") or "").strip()
        if kind not in KINDS:
            raise InputError(
                file, f"line {line}: unknown kind '{kind}'", "one of " + ", ".join(KINDS)
            )
        a, b = (row.get("a") or "").strip(), (row.get("b") or "").strip()
        if not a or not b:
            raise InputError(file, f"line {line}: a measurement needs two landmark codes")
        rows.append(
            Table82Row(
                (row.get("measurement") or f"{kind}:{a}-{b}").strip(),
                kind,
                a,
                b,
                (row.get("mid") or "").strip(),
                (row.get("region") or "").strip(),
                (row.get("norm_measurement_id") or "").strip(),
                (row.get("note") or "").strip(),
            )
        )
    return tuple(rows)
