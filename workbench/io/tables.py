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

import math
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from workbench.core.data_paths import data_tables_dir
from workbench.core.errors import InputError
from workbench.core.json_limits import read_json
from workbench.core.limits import MAX_TISSUE_DEPTH_MM, MAX_TISSUE_SD_MM
from workbench.io.catalogue import LandmarkCatalogue, load_catalogue
from workbench.io.csv_rows import read_csv_rows

COLUMNS = ("landmark_code", "skin_code", "group", "sex", "build", "mean_mm", "sd_mm", "n", "source")
REQUIRED = ("landmark_code", "group", "mean_mm", "source")
#: largest table metadata file read (citations and a description: a few KB)
MAX_META_BYTES = 1024 * 1024


def tables_dir() -> Path:
    """Folder of the shipped tissue-depth tables."""
    return data_tables_dir() / "tissue_depth"


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
    sexes, builds : (k,) labels from the ``sex`` / ``build`` columns
        ("female", "male", "pooled" / "slender", "normal", "obese", "pooled";
        '' where the table does not say).
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
    sexes: tuple[str, ...] = ()
    builds: tuple[str, ...] = ()

    def group_names(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(self.groups))

    def lookup(self, group: str | None = None) -> dict[str, tuple[float, float]]:
        """``{skull code: (mean_mm, sd_mm)}`` for one group (default: the first)."""
        group = group or self.group_names()[0]
        if group not in self.groups:
            raise InputError(
                self.table_id, f"no group {group!r}", f"groups: {', '.join(self.group_names())}"
            )
        return {
            c: (float(m), float(s))
            for c, g, m, s in zip(self.codes, self.groups, self.mean_mm, self.sd_mm, strict=True)
            if g == group
        }

    def group_sex(self, group: str) -> str:
        """The ``sex`` label of a group ('' if the table gives none)."""
        return self._group_attr(self.sexes, group)

    def group_build(self, group: str) -> str:
        """The ``build`` label of a group ('' if the table gives none)."""
        return self._group_attr(self.builds, group)

    def _group_attr(self, values: tuple[str, ...], group: str) -> str:
        if group not in self.groups:
            raise InputError(
                self.table_id, f"no group {group!r}", f"groups: {', '.join(self.group_names())}"
            )
        return values[self.groups.index(group)] if values else ""

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
    meta = read_json(path, max_bytes=MAX_META_BYTES, what="table metadata")
    if not isinstance(meta, dict):
        raise InputError(path, "the table metadata is not a JSON object")
    return meta


def load_depth_table(
    table: str | PathLike[str], catalogue: LandmarkCatalogue | None = None
) -> DepthTable:
    """Load a shipped table by id, or a user CSV by path.

    Raises
    ------
    InputError
        Naming the file and, for row problems, the line: missing file or
        columns, rows with too few or too many values, empty required
        values, non-numeric or non-positive depths, depths or SDs above the
        soft-tissue bound (:data:`workbench.core.limits.MAX_TISSUE_DEPTH_MM`),
        negative SDs or counts, unknown landmark codes (listed by name, with a "did you mean"), skin
        codes that are not skin landmarks, duplicate rows (same landmark and
        group), unknown sex/build labels, groups whose rows disagree on sex or
        build, and rows without a citation key (or citing one the metadata
        does not define).
    """
    path = Path(table)
    if path.suffix.lower() != ".csv":
        path = tables_dir() / f"{table}.csv"
        if not path.exists():
            raise InputError(
                table,
                "unknown tissue-depth table",
                f"shipped tables: {', '.join(list_tables())}; or give a CSV file",
            )
    if not path.exists():
        raise InputError(path, "tissue-depth table not found")
    meta = _read_meta(path.with_suffix(".meta.json"))
    rows = _read_rows(path)
    catalogue = catalogue or load_catalogue()
    codes, skin, groups, sexes, builds, mean, sd, n, src = ([] for _ in range(9))
    unknown: list[tuple[int, str]] = []
    first_line: dict[tuple[str, str], int] = {}
    group_kind: dict[str, tuple[str, str, int]] = {}
    for line, row in rows:
        label = _text(path, line, row, "landmark_code")
        try:
            code = catalogue.normalise(label, "skull")
        except Exception:  # noqa: BLE001 - collect every unknown label, report once
            unknown.append((line, label))
            continue
        group = (row.get("group") or "").strip() or "all"
        if (code, group) in first_line:
            raise InputError(
                path,
                f"line {line}: duplicate row for {code} in group {group!r} "
                f"(first given on line {first_line[code, group]})",
                "keep one row per landmark and group",
            )
        first_line[code, group] = line
        sex = _label(path, line, row, "sex", SEX_LABELS)
        build = _label(path, line, row, "build", BUILD_LABELS)
        kind = group_kind.setdefault(group, (sex, build, line))
        if kind[:2] != (sex, build):
            raise InputError(
                path,
                f"line {line}: group {group!r} is {sex or '-'}/{build or '-'} "
                f"here but {kind[0] or '-'}/{kind[1] or '-'} on line {kind[2]}",
                "one group is one sex and build; use separate group labels",
            )
        codes.append(code)
        skin.append(_skin_code(path, line, row, code, catalogue))
        groups.append(group)
        sexes.append(sex)
        builds.append(build)
        mean.append(_number(path, line, "mean_mm", row["mean_mm"], positive=True))
        sd.append(_number(path, line, "sd_mm", row.get("sd_mm", ""), optional=True))
        n.append(_number(path, line, "n", row.get("n", ""), optional=True))
        src.append(_text(path, line, row, "source"))
    if unknown:
        raise InputError(
            path,
            f"unknown skull landmark codes: {', '.join(u for _, u in unknown)} "
            f"({'; '.join(_unknown_note(line, u, catalogue) for line, u in unknown)})",
            "use the skull codes of data_tables/landmarks/catalogue.csv",
        )
    known_sources = set(meta.get("sources", {}))
    if known_sources:
        missing = sorted({s for s in src if s not in known_sources})
        if missing:
            raise InputError(
                path, f"rows cite sources not defined in the metadata: {', '.join(missing)}"
            )
    return DepthTable(
        meta.get("id", path.stem),
        tuple(codes),
        tuple(skin),
        tuple(groups),
        _ro(mean),
        _ro(sd),
        _ro(n),
        tuple(src),
        meta,
        tuple(sexes),
        tuple(builds),
    )


#: Accepted ``sex`` and ``build`` labels ('' = not given); "pooled" covers both sexes or all builds.
SEX_LABELS = ("female", "male", "pooled")
BUILD_LABELS = ("slender", "normal", "obese", "pooled")
_POOLED_WORDS = ("all", "both", "any", "mixed", "combined")


def _read_rows(path: Path) -> list[tuple[int, dict[str, str | None]]]:
    """Data rows with their line numbers in the file (comment lines ``#`` are skipped)."""
    rows = read_csv_rows(path, REQUIRED, expected=COLUMNS, what="depth table")
    if not rows:
        raise InputError(path, "the table has no rows")
    return rows


def _text(path: Path, line: int, row: dict[str, str | None], column: str) -> str:
    value = (row.get(column) or "").strip()
    if not value:
        raise InputError(path, f"line {line}: {column} is empty")
    return value


def _label(
    path: Path, line: int, row: dict[str, str | None], column: str, allowed: tuple[str, ...]
) -> str:
    value = (row.get(column) or "").strip().lower()
    if value in _POOLED_WORDS:
        return "pooled"
    if column == "sex" and value in ("f", "m"):
        return {"f": "female", "m": "male"}[value]
    if value and value not in allowed:
        raise InputError(
            path,
            f"line {line}: unknown {column} {value!r}",
            f"use one of: {', '.join(allowed)} (or leave it empty)",
        )
    return value


def _skin_code(
    path: Path, line: int, row: dict[str, str | None], code: str, catalogue: LandmarkCatalogue
) -> str:
    label = (row.get("skin_code") or "").strip()
    if not label:
        return catalogue.partner(code, "skull") or ""
    try:
        return catalogue.normalise(label, "skin")
    except Exception:  # noqa: BLE001 - LandmarkError: reported with the line
        raise InputError(
            path,
            f"line {line}: unknown skin landmark code {label!r}",
            "use the skin codes of data_tables/landmarks/catalogue.csv, or leave "
            "skin_code empty for the catalogue's partner",
        ) from None


def _unknown_note(line: int, label: str, catalogue: LandmarkCatalogue) -> str:
    """``line 3: 'pgn' (did you mean pg?)`` -- close catalogue codes, names or aliases."""
    import difflib

    note = f"line {line}: {label!r}"
    try:
        skin = catalogue.normalise(label, "skin")
    except Exception:  # noqa: BLE001 - not a skin code either
        skin = None
    if skin is not None:
        partner = catalogue.partner(skin, "skin")
        return note + (
            f" is a skin landmark; its skull partner is {partner}"
            if partner
            else " is a skin landmark"
        )
    names: dict[str, str] = {}
    for e in catalogue.entries:
        if e.surface == "skull":
            for name in (e.code, e.name, *e.aliases):
                names.setdefault(name.lower(), e.code)
    close = difflib.get_close_matches(label.lower(), list(names), n=6, cutoff=0.6)
    guesses = list(dict.fromkeys(names[c] for c in close))[:3]
    return note + (f", did you mean {' or '.join(guesses)}?" if guesses else "")


def _number(
    path: Path,
    line: int,
    column: str,
    text: str | None,
    *,
    positive: bool = False,
    optional: bool = False,
) -> float:
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
        what = (
            "a positive number of mm"
            if positive
            else "a non-negative number of mm"
            if column.endswith("_mm")
            else "a non-negative number"
        )
        raise InputError(path, f"line {line}: {column} must be {what}, got {text}")
    limit = {"mean_mm": MAX_TISSUE_DEPTH_MM, "sd_mm": MAX_TISSUE_SD_MM}.get(column)
    if limit is not None and value > limit:
        raise InputError(
            path,
            f"line {line}: {column} {text} mm is implausible (at most {limit:g} mm)",
            "no face has soft tissue that thick; is the column in mm?",
        )
    return value


def _ro(values: list[float]) -> np.ndarray:
    a = np.asarray(values, dtype=np.float64)
    a.setflags(write=False)
    return a
