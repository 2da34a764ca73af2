"""Snap rules: which skull landmarks are extrema, and of what, in the head frame.

``data_tables/landmarks/snap_rules.csv`` turns the catalogue definitions that
name an extremum ("most anterior midline point ...", "lowest point ...",
"deepest midline point of the profile concavity ...") into machine rules for
:mod:`workbench.services.landmarks.snap`.  A rule only restates its landmark's
catalogue definition; it cites the same source keys (checked against
``catalogue.meta.json``).  Landmarks defined by sutures, midpoints or
constructions have no row.

Directions are head-frame axes (:mod:`workbench.core.frame`: x toward the
subject's left, y up perpendicular to Frankfort Horizontal, z forward; mm);
``lateral`` means +x for a left landmark and -x for a right one.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from workbench.core.errors import InputError
from workbench.io.catalogue import (
    LandmarkCatalogue,
    default_catalogue_path,
    load_catalogue,
    read_table_rows,
)

COLUMNS = ("code", "rule", "direction", "radius_mm", "midline", "between", "source", "note")
RULES = ("extremum", "deepest")
AXES = {
    "+x": (1.0, 0.0, 0.0),
    "-x": (-1.0, 0.0, 0.0),
    "+y": (0.0, 1.0, 0.0),
    "-y": (0.0, -1.0, 0.0),
    "+z": (0.0, 0.0, 1.0),
    "-z": (0.0, 0.0, -1.0),
}
#: words for the explanation shown to the user, per head-frame direction
FEATURE_WORDS = {
    "+x": "most leftward",
    "-x": "most rightward",
    "+y": "highest",
    "-y": "lowest",
    "+z": "most anterior",
    "-z": "most posterior",
    "lateral": "most lateral",
}


@dataclass(frozen=True)
class SnapRule:
    """One row of ``snap_rules.csv`` (skull surface).

    Attributes
    ----------
    code : str
        Skull catalogue code.
    rule : "extremum" | "deepest"
        ``extremum``: largest projection onto ``direction``; ``deepest``:
        deepest point of a midline profile concavity, depth measured along
        ``direction``.
    direction : str
        ``+x``, ``-x``, ``+y``, ``-y``, ``+z``, ``-z`` or ``lateral`` (head frame).
    radius_mm : float
        Search radius around the current position (mm).
    midline : bool
        Search only near the midsagittal plane (midline landmarks).
    between : tuple of str
        ``deepest`` rules: the two landmarks that bound the concavity in the
        definition (e.g. ``("ans", "pr")``); empty otherwise.
    side : str
        ``midline``, ``left`` or ``right`` (from the catalogue).
    sources : tuple of str
        Citation keys of ``catalogue.meta.json``.
    note : str
        Where the rule simplifies the definition.
    """

    code: str
    rule: str
    direction: str
    radius_mm: float
    midline: bool
    between: tuple[str, ...]
    side: str
    sources: tuple[str, ...]
    note: str = ""

    @property
    def axis(self) -> np.ndarray:
        """Unit ``(3,)`` head-frame direction (``lateral`` resolved by side)."""
        if self.direction == "lateral":
            return np.array(AXES["+x" if self.side == "left" else "-x"])
        return np.array(AXES[self.direction])

    @property
    def feature(self) -> str:
        """Short words for the feature, e.g. ``"most anterior midline point"``."""
        if self.rule == "deepest":
            return "deepest point of the midline concavity"
        where = " midline point" if self.midline else " point"
        return FEATURE_WORDS[self.direction] + where


def default_snap_rules_path() -> Path:
    """``snap_rules.csv`` beside the landmark catalogue (wheel copy or checkout)."""
    return default_catalogue_path().with_name("snap_rules.csv")


_CACHE: dict[tuple[str, int, int], dict[str, SnapRule]] = {}


def load_snap_rules(
    path: str | os.PathLike[str] | None = None, catalogue: LandmarkCatalogue | None = None
) -> dict[str, SnapRule]:
    """``{skull code: SnapRule}`` from the table, checked against the catalogue.

    Raises
    ------
    InputError
        Missing file, wrong columns, unknown codes, a rule or direction that
        does not fit the landmark's side, a non-positive radius, or a row
        citing no source or a key the catalogue does not define.
    """
    csv_path = Path(path) if path is not None else default_snap_rules_path()
    try:
        st = csv_path.stat()
    except OSError:
        raise InputError(csv_path, "snap rule table not found") from None
    key = (str(csv_path.resolve()), st.st_mtime_ns, st.st_size)
    if catalogue is not None or key not in _CACHE:
        rules = _read(csv_path, catalogue or load_catalogue())
        if catalogue is not None:
            return rules
        _CACHE[key] = rules
    return _CACHE[key]


def _read(path: Path, catalogue: LandmarkCatalogue) -> dict[str, SnapRule]:
    rows = read_table_rows(path, COLUMNS)
    rules: dict[str, SnapRule] = {}
    for line, row in enumerate(rows, start=2):
        rule = _row(path, line, row, catalogue)
        if rule.code in rules:
            raise InputError(path, f"line {line}: second rule for {rule.code!r}")
        rules[rule.code] = rule
    return rules


def _row(path: Path, line: int, row: dict, catalogue: LandmarkCatalogue) -> SnapRule:
    def fail(problem: str) -> InputError:
        return InputError(path, f"line {line}: {problem}")

    code = (row["code"] or "").strip()
    entry = catalogue.get(code, "skull")
    if entry is None:
        raise fail(f"{code!r} is not a skull landmark of the catalogue")
    rule, direction = (row["rule"] or "").strip(), (row["direction"] or "").strip()
    midline = (row["midline"] or "").strip().lower()
    if rule not in RULES:
        raise fail(f"rule must be one of {', '.join(RULES)}, got {rule!r}")
    if direction not in (*AXES, "lateral"):
        raise fail(f"direction must be +x, -x, +y, -y, +z, -z or lateral, got {direction!r}")
    if midline not in ("yes", "no") or (midline == "yes") != (entry.side == "midline"):
        raise fail(
            f"midline must be 'yes' exactly for midline landmarks ({code} is "
            f"{entry.side}), got {midline!r}"
        )
    if entry.side == "midline" and direction in ("+x", "-x", "lateral"):
        raise fail(f"{code} is a midline landmark: a sideways direction makes no sense")
    if rule == "deepest" and (entry.side != "midline" or direction in ("+x", "-x")):
        raise fail("deepest is defined for midline profiles along y or z only")
    try:
        radius = float(row["radius_mm"])
    except (TypeError, ValueError):
        raise fail(f"radius_mm must be a number, got {row['radius_mm']!r}") from None
    if not (np.isfinite(radius) and 0.0 < radius <= 40.0):
        raise fail(f"radius_mm must be in (0, 40] mm, got {radius:g}")
    between = tuple(s.strip() for s in (row["between"] or "").split(";") if s.strip())
    if between and (
        rule != "deepest"
        or len(between) != 2
        or any(catalogue.get(c, "skull") is None for c in between)
    ):
        raise fail(
            f"between must name two skull landmarks, for deepest rules only; got {row['between']!r}"
        )
    sources = tuple(s.strip() for s in (row["source"] or "").split(";") if s.strip())
    if not sources:
        raise fail(f"{code!r} cites no source")
    undefined = [s for s in sources if s not in catalogue.sources]
    if undefined:
        raise fail(
            f"{code!r} cites source key(s) not in catalogue.meta.json: {', '.join(undefined)}"
        )
    return SnapRule(
        code,
        rule,
        direction,
        radius,
        midline == "yes",
        between,
        entry.side,
        sources,
        (row["note"] or "").strip(),
    )
