"""Tissue-depth tables (``data_tables/tissue_depth/<id>.csv`` + ``<id>.meta.json``).

A table has one row per skull landmark code and group:
``landmark_code, skin_code, group, sex, build, mean_mm, sd_mm, n, source``.
Depths are millimetres from the skull landmark to the skin.  Every row names
the key of its primary publication; the sidecar ``.meta.json`` holds the
citations, population, method and caveats.  Users can load their own CSV in
the same format (``load_depth_table(path)``); unknown landmark codes and
missing citations are reported by name.
"""

from __future__ import annotations

import csv
import io
import json
import math
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from workbench.core.errors import InputError
from workbench.io.catalogue import LandmarkCatalogue, default_catalogue_path, load_catalogue

COLUMNS = ("landmark_code", "skin_code", "group", "sex", "build", "mean_mm", "sd_mm", "n", "source")
REQUIRED = ("landmark_code", "group", "mean_mm", "source")


def tables_dir() -> Path:
    """Folder of the shipped tissue-depth tables."""
    return default_catalogue_path().parents[1] / "tissue_depth"


@dataclass(frozen=True, eq=False)
class DepthTable:
    """A tissue-depth table as arrays (one entry per row).

    Attributes
    ----------
    table_id : str
    codes : (k,) skull landmark codes
    skin_codes : (k,) paired skin codes ('' if none)
    groups : (k,) group labels (e.g. "adult", "female/normal")
    mean_mm, sd_mm : (k,) float64 (sd NaN where the source gives none)
    n : (k,) float64 (NaN where unknown)
    sources : (k,) citation keys
    meta : dict
        The sidecar metadata (title, population, sources, caveats ...).
    """

    table_id: str
    codes: tuple[str, ...]
    skin_codes: tuple[str, ...]
    groups: tuple[str, ...]
    mean_mm: np.ndarray
    sd_mm: np.ndarray
    n: np.ndarray
    sources: tuple[str, ...]
    meta: dict[str, Any] = field(default_factory=dict)

    def group_names(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(self.groups))

    def lookup(self, group: str | None = None) -> dict[str, tuple[float, float]]:
        """``{skull code: (mean_mm, sd_mm)}`` for one group (default: the first)."""
        group = group or self.group_names()[0]
        if group not in self.groups:
            raise InputError(self.table_id, f"no group {group!r}",
                             f"groups: {', '.join(self.group_names())}")
        return {c: (float(m), float(s)) for c, g, m, s in
                zip(self.codes, self.groups, self.mean_mm, self.sd_mm, strict=True) if g == group}

    def citation(self, key: str) -> str:
        return str(self.meta.get("sources", {}).get(key, key))


def list_tables() -> list[str]:
    """Ids of the shipped tables (default table first)."""
    ids = sorted(p.stem for p in tables_dir().glob("*.csv"))
    defaults = [i for i in ids if _read_meta(tables_dir() / f"{i}.meta.json").get("default")]
    return defaults + [i for i in ids if i not in defaults]


def _read_meta(path: Path) -> dict[str, Any]:
    if not path.exists():
        return {}
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError) as exc:
        raise InputError(path, f"table metadata is not valid JSON ({exc})") from None


def load_depth_table(table: str | PathLike[str], catalogue: LandmarkCatalogue | None = None
                     ) -> DepthTable:
    """Load a shipped table by id, or a user CSV by path.

    Raises
    ------
    InputError
        Missing file or columns, non-numeric or non-positive depths, unknown
        landmark codes (listed by name), rows without a citation key.
    """
    path = Path(table)
    if path.suffix.lower() != ".csv":
        path = tables_dir() / f"{table}.csv"
        if not path.exists():
            raise InputError(table, "unknown tissue-depth table",
                             f"shipped tables: {', '.join(list_tables())}; or give a CSV file")
    if not path.exists():
        raise InputError(path, "tissue-depth table not found")
    meta = _read_meta(path.with_suffix(".meta.json"))
    rows = _read_rows(path)
    catalogue = catalogue or load_catalogue()
    codes, skin, groups, mean, sd, n, src = [], [], [], [], [], [], []
    unknown: list[str] = []
    for line, row in rows:
        label = row["landmark_code"].strip()
        try:
            code = catalogue.normalise(label, "skull")
        except Exception:  # noqa: BLE001 - collect every unknown label, report once
            unknown.append(label)
            continue
        codes.append(code)
        skin.append((row.get("skin_code") or catalogue.partner(code, "skull") or "").strip())
        groups.append((row.get("group") or "all").strip())
        mean.append(_number(path, line, "mean_mm", row["mean_mm"], positive=True))
        sd.append(_number(path, line, "sd_mm", row.get("sd_mm", ""), optional=True))
        n.append(_number(path, line, "n", row.get("n", ""), optional=True))
        src.append(row["source"].strip())
    if unknown:
        raise InputError(path, f"unknown skull landmark codes: {', '.join(unknown)}",
                         "use the codes of data_tables/landmarks/catalogue.csv")
    known_sources = set(meta.get("sources", {}))
    if known_sources:
        missing = sorted({s for s in src if s not in known_sources})
        if missing:
            raise InputError(path, f"rows cite sources not defined in the metadata: {', '.join(missing)}")
    return DepthTable(meta.get("id", path.stem), tuple(codes), tuple(skin), tuple(groups),
                      _ro(mean), _ro(sd), _ro(n), tuple(src), meta)


def _read_rows(path: Path) -> list[tuple[int, dict[str, str]]]:
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(path, f"cannot be read as UTF-8 text ({exc})") from None
    lines = [ln for ln in text.splitlines() if not ln.lstrip().startswith("#")]
    reader = csv.DictReader(io.StringIO("\n".join(lines)))
    missing = [c for c in REQUIRED if c not in (reader.fieldnames or [])]
    if missing:
        raise InputError(path, f"missing columns: {', '.join(missing)}",
                         f"expected columns: {', '.join(COLUMNS)}")
    rows = [(i + 2, r) for i, r in enumerate(reader)]
    if not rows:
        raise InputError(path, "the table has no rows")
    return rows


def _number(path: Path, line: int, column: str, text: str | None, *, positive: bool = False,
            optional: bool = False) -> float:
    text = (text or "").strip()
    if not text:
        if optional:
            return math.nan
        raise InputError(path, f"line {line}: {column} is empty")
    try:
        value = float(text)
    except ValueError:
        raise InputError(path, f"line {line}: {column} is not a number ({text!r})") from None
    if not math.isfinite(value) or (positive and value <= 0) or value < 0:
        raise InputError(path, f"line {line}: {column} must be a positive number of mm, got {text}")
    return value


def _ro(values: list[float]) -> np.ndarray:
    a = np.asarray(values, dtype=np.float64)
    a.setflags(write=False)
    return a
