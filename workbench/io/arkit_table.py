"""ARKit blendshape recipes: ``{ARKit name: {target: weight}}`` from a CSV table.

The built-in table is ``data_tables/animation/arkit52_from_facs.csv`` (the 52
names of Apple's ``ARFaceAnchor.BlendShapeLocation`` as weighted sums of FACS
action-unit targets; an approximation, see the table's README).  A table has
the columns ``arkit_name,recipe,source,notes``; a recipe is ``target:weight``
pairs joined by ``;`` (``au26:0.5;au27:0.5``), or empty for a shape with no
basis.  The valid target names are the caller's (this layer does not know
the expression palette).
"""

from __future__ import annotations

import csv
from collections.abc import Iterable
from os import PathLike
from pathlib import Path

import numpy as np

from workbench.core.data_paths import data_tables_dir
from workbench.core.errors import InputError

__all__ = ["ARKIT_COLUMNS", "builtin_arkit_table", "read_arkit_table"]

ARKIT_COLUMNS = ("arkit_name", "recipe", "source", "notes")


def builtin_arkit_table() -> Path:
    """Path of the shipped ARKit-52 table."""
    return data_tables_dir() / "animation" / "arkit52_from_facs.csv"


def _parse_recipe(text: str, where: str, path: Path) -> dict[str, float]:
    out: dict[str, float] = {}
    for item in text.split(";"):
        item = item.strip()
        if not item:
            continue
        name, sep, value = item.partition(":")
        name = name.strip()
        try:
            weight = float(value) if sep else float("nan")
        except ValueError:
            weight = float("nan")
        if not name or not np.isfinite(weight):
            raise InputError(
                path, f"{where}: recipe item {item!r} is not TARGET:WEIGHT", "e.g. au12:1.0"
            )
        out[name] = out.get(name, 0.0) + weight
    return out


def read_arkit_table(
    path: str | PathLike[str] | None = None, valid: Iterable[str] | None = None
) -> dict[str, dict[str, float]]:
    """``{ARKit name: {target: weight}}`` in table order (empty recipe: ``{}``).

    ``path``: the table (default: the built-in one).  ``valid``: the target
    names a recipe may use; an unknown one is an :class:`InputError` naming
    the file, the row and the valid names.
    """
    p = builtin_arkit_table() if path is None else Path(path)
    allowed = None if valid is None else list(valid)
    try:
        text = p.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise InputError(p, f"cannot be read ({exc.strerror or exc})") from None
    # "#" comment lines and blank lines are skipped; rows keep the file's line numbers
    numbered = [
        (i, ln)
        for i, ln in enumerate(text.splitlines(), start=1)
        if ln.strip() and not ln.lstrip().startswith("#")
    ]
    parsed = list(csv.reader([ln for _, ln in numbered]))
    header = [c.strip() for c in parsed[0]] if parsed else []
    missing = [c for c in ARKIT_COLUMNS[:2] if c not in header]
    if missing:
        raise InputError(
            p,
            f"has no column {', '.join(missing)}",
            "an ARKit table has the columns " + ",".join(ARKIT_COLUMNS),
        )
    out: dict[str, dict[str, float]] = {}
    for (line_no, _), cells in zip(numbered[1:], parsed[1:], strict=True):
        row = dict(zip(header, cells, strict=False))
        name = (row.get("arkit_name") or "").strip()
        where = f"line {line_no}"
        if not name:
            raise InputError(p, f"{where}: arkit_name is empty")
        if name in out:
            raise InputError(p, f"{where}: {name} is listed twice")
        recipe = _parse_recipe(row.get("recipe") or "", f"{where} ({name})", p)
        if allowed is not None:
            unknown = [t for t in recipe if t not in allowed]
            if unknown:
                raise InputError(
                    p,
                    f"{where} ({name}): {', '.join(unknown)} is not a target name",
                    "valid names: " + ", ".join(allowed),
                )
        out[name] = recipe
    if not out:
        raise InputError(p, "lists no ARKit shape")
    return out
