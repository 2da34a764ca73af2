"""Growth norms: facial measurements and head circumference by age and sex (issue 15).

Two kinds of table live in ``data_tables/growth/``:

* **Facial norms** (``facial_norms.csv`` + ``facial_norms.meta.json``): one row per
  measurement, ethnicity, sex, source and age --
  ``measurement_id, name, kind, a, b, ethnicity, sex, age_years, mean_mm, sd_mm, n, source``.
  ``a`` and ``b`` are catalogue **skin** codes; ``kind`` says how the distance is taken
  (``euclidean``: the straight 3D distance, independent of the head frame;
  ``vertical`` / ``horizontal`` / ``depth``: along y / x / z of the Frankfort frame,
  x to the subject's left, y up, z toward the face; ``arc``: along the skin).  Means and
  SDs are millimetres, ages years.  Read with :func:`load_growth_norms`; users can load
  their own CSV in the same format.
* **Head circumference** (``head_circumference_lms.csv``): LMS tables of the WHO 2006
  standard (0-5 y) and the UK90 reference (4-18 y), medians in mm.  Read with
  :func:`load_head_circumference`.

Choosing between rows
---------------------
A measurement can have rows for one ethnicity and sex from several sources (the
European palpebral fissure: Weinberg et al. 2016 by sex, 3-40 y, and Farkas 1981
et al. pooled, 0-16 y).  :meth:`GrowthNorms.at` uses **one** source per
measurement, sex and ethnicity, chosen deterministically: sex-specific rows over
pooled rows (pooled rows are used only when there are no rows of the asked sex),
then the source covering the wider age range, then the one with more tabulated
ages, then the source key in alphabetical order.  Sources are never mixed or
blended, so a z-score stays relative to one population; ``source=`` picks another
one explicitly.
"""

from __future__ import annotations

import difflib
import json
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from workbench.core.data_paths import data_tables_dir
from workbench.core.errors import InputError
from workbench.io.catalogue import LandmarkCatalogue, load_catalogue
from workbench.io.csv_rows import Row, read_csv_rows

COLUMNS = (
    "measurement_id",
    "name",
    "kind",
    "a",
    "b",
    "ethnicity",
    "sex",
    "age_years",
    "mean_mm",
    "sd_mm",
    "n",
    "source",
)
REQUIRED = ("measurement_id", "a", "b", "sex", "age_years", "mean_mm", "sd_mm", "source")
#: measurement kinds (see the module docstring)
KINDS = ("euclidean", "vertical", "horizontal", "depth", "arc")
SEXES = ("female", "male", "pooled")
DEFAULT_ETHNICITY = "European"
#: a facial distance (mm) outside this range is a unit slip or a typing error: the smallest
#: tabulated one (a child's vermilion height) is ~4 mm, the largest head measures ~400 mm
MEAN_MM_RANGE = (1.0, 400.0)
#: ages (years) a growth table may tabulate
AGE_RANGE_YEARS = (0.0, 120.0)
#: ethnicity label of user rows that name none
UNSPECIFIED = "unspecified"


def growth_dir() -> Path:
    """Folder of the shipped growth tables (``data_tables/growth``)."""
    return data_tables_dir() / "growth"


@dataclass(frozen=True)
class NormMeasurement:
    """One measurement between two skin landmarks.

    ``kind`` is one of :data:`KINDS`; ``a`` and ``b`` are catalogue skin codes.
    ``side``: ``"midline"`` (both midline), ``"pair"`` (a left and a right point,
    e.g. ex_l-ex_r), ``"left"`` / ``"right"`` (a one-sided measurement, e.g. the
    left palpebral fissure ex_l-en_l or the left nasal ala ac_l-prn).
    """

    measurement_id: str
    name: str
    kind: str
    a: str
    b: str
    side: str


@dataclass(frozen=True, eq=False)
class _Series:
    """The rows of one measurement, ethnicity, sex and source, sorted by age (mm, years)."""

    source: str
    ages: np.ndarray
    mean: np.ndarray
    sd: np.ndarray
    n: float
    lines: tuple[int, ...]

    @property
    def span(self) -> float:
        return float(self.ages[-1] - self.ages[0])


@dataclass(frozen=True, eq=False)
class GrowthNorms:
    """A facial norms table: per measurement, sex and ethnicity, mean and SD (mm) by age (years).

    Build with :func:`load_growth_norms`.  Distances are millimetres; ``euclidean``
    measurements are frame-independent, axis-aligned ones are read in the Frankfort
    frame (x to the subject's left, y up, z toward the face).
    """

    norms_id: str
    meta: dict[str, Any]
    measurements: tuple[NormMeasurement, ...]
    path: str = ""
    #: what error messages name: the id of a shipped table, the file of a user table
    where: str = ""
    _series: Mapping[tuple[str, str, str], tuple[_Series, ...]] = field(
        default_factory=dict, repr=False
    )
    _citations: Mapping[str, str] = field(default_factory=dict, repr=False)

    @property
    def _where(self) -> str:
        return self.where or self.norms_id

    # ------------------------------------------------------------ lookups
    def measurement(self, measurement_id: str) -> NormMeasurement:
        """The measurement with this id (InputError listing the known ids)."""
        for m in self.measurements:
            if m.measurement_id == measurement_id:
                return m
        close = difflib.get_close_matches(measurement_id, self.measurement_ids(), n=3)
        raise InputError(
            self._where,
            f"no measurement {measurement_id!r}",
            f"did you mean {' or '.join(close)}?"
            if close
            else f"measurements: {', '.join(self.measurement_ids())}",
        )

    def measurement_ids(self) -> tuple[str, ...]:
        return tuple(m.measurement_id for m in self.measurements)

    def ethnicities(self) -> tuple[str, ...]:
        """Ethnicity labels of the table, in file order."""
        return tuple(dict.fromkeys(e for (_, e, _) in self._series))

    def sources(
        self, measurement_id: str, sex: str, ethnicity: str | None = None
    ) -> tuple[str, ...]:
        """Source keys :meth:`at` can use for this measurement, sex and ethnicity, best first.

        The sex's own sources (in the order of the choice rule), then the pooled ones.
        """
        own = self._candidates(measurement_id, sex, ethnicity)
        eth = self._ethnicity(ethnicity)
        pooled = self._series.get((measurement_id, eth, "pooled"), ())
        return tuple(dict.fromkeys(s.source for s in (*own, *pooled)))

    def has(self, measurement_id: str, sex: str, ethnicity: str | None = None) -> bool:
        """Whether the table has norms (of this sex, or pooled) for the measurement and ethnicity.

        Unknown measurement ids give False; an unknown ethnicity or sex label is an InputError.
        """
        if measurement_id not in self.measurement_ids():
            return False
        return bool(self._candidates(measurement_id, sex, ethnicity))

    def age_range(
        self,
        measurement_id: str,
        sex: str,
        ethnicity: str | None = None,
        *,
        source: str | None = None,
    ) -> tuple[float, float]:
        """Youngest and oldest tabulated age (years) of the chosen source."""
        s = self._pick(measurement_id, sex, ethnicity, source)
        return float(s.ages[0]), float(s.ages[-1])

    def source_of(self, measurement_id: str, sex: str, ethnicity: str | None = None) -> str:
        """Source key(s) of the rows :meth:`at` uses (``;``-separated when a row cites several)."""
        return self._pick(measurement_id, sex, ethnicity, None).source

    def at(
        self,
        measurement_id: str,
        sex: str,
        age: float,
        ethnicity: str | None = None,
        *,
        source: str | None = None,
    ) -> tuple[float, float]:
        """``(mean_mm, sd_mm)`` of a measurement at an age (years).

        Linear interpolation between the two neighbouring tabulated ages (exact at a
        tabulated age).  ``sex`` is female, male or pooled; when the table has no rows
        of that sex for the measurement and ethnicity, the pooled rows are used.
        ``ethnicity`` defaults to "European" (or the table's only ethnicity).

        Raises
        ------
        InputError
            Unknown measurement, sex or ethnicity (the known ones listed), no norms of
            this measurement for the sex and ethnicity, or an age outside the tabulated
            range (naming the measurement, the age and the range).
        """
        s = self._pick(measurement_id, sex, ethnicity, source)
        age_f = _finite_age(self._where, age)
        lo, hi = float(s.ages[0]), float(s.ages[-1])
        if not lo <= age_f <= hi:
            raise InputError(
                self._where,
                f"{measurement_id}: age {age_f:g} y is outside the tabulated range "
                f"{lo:g}-{hi:g} y ({self._describe(sex, ethnicity)}, {s.source})",
                "choose an age inside the range, or treat the measurement as without norms",
            )
        i = int(np.searchsorted(s.ages, age_f, side="right")) - 1
        if s.ages[i] == age_f:  # a tabulated age: the table's values exactly
            return float(s.mean[i]), float(s.sd[i])
        t = (age_f - s.ages[i]) / (s.ages[i + 1] - s.ages[i])
        mean = s.mean[i] + t * (s.mean[i + 1] - s.mean[i])
        sd = s.sd[i] + t * (s.sd[i + 1] - s.sd[i])
        return float(mean), float(sd)

    def citation(self, source_key: str) -> str:
        """Full citation of a source key; ``;``-joined keys give their citations joined by ``; ``."""
        keys = [k.strip() for k in source_key.split(";") if k.strip()]
        texts = [self._citations.get(k, k) for k in keys]
        return texts[0] if len(texts) == 1 else "; ".join(t.rstrip(".") for t in texts)

    # ------------------------------------------------------------ internals
    def _ethnicity(self, ethnicity: str | None) -> str:
        known = self.ethnicities()
        if ethnicity is None:
            if DEFAULT_ETHNICITY in known or len(known) != 1:
                ethnicity = DEFAULT_ETHNICITY
            else:
                return known[0]
        folded = {e.lower(): e for e in known}
        found = folded.get(" ".join(str(ethnicity).split()).lower())
        if found is None:
            raise InputError(
                self._where,
                f"unknown ethnicity {ethnicity!r}",
                f"known ethnicities: {', '.join(known)}",
            )
        return found

    def _sex(self, sex: str) -> str:
        value = _sex_label(sex)
        if value is None:
            raise InputError(self._where, f"unknown sex {sex!r}", "use female, male or pooled")
        return value

    def _candidates(
        self, measurement_id: str, sex: str, ethnicity: str | None
    ) -> tuple[_Series, ...]:
        eth = self._ethnicity(ethnicity)
        sex_v = self._sex(sex)
        own = self._series.get((measurement_id, eth, sex_v), ())
        if own or sex_v == "pooled":
            return own
        return self._series.get((measurement_id, eth, "pooled"), ())

    def _pick(
        self, measurement_id: str, sex: str, ethnicity: str | None, source: str | None
    ) -> _Series:
        self.measurement(measurement_id)  # unknown id: InputError with suggestions
        found = self._candidates(measurement_id, sex, ethnicity)
        if not found:
            eth = self._ethnicity(ethnicity)
            have = sorted({e for (m, e, _) in self._series if m == measurement_id})
            raise InputError(
                self._where,
                f"no norms for {measurement_id} ({self._describe(sex, eth)})",
                f"ethnicities with this measurement: {', '.join(have)}",
            )
        if source is None:
            return found[0]
        # an explicit source may also be one of the pooled rows behind a sex's own rows
        eth = self._ethnicity(ethnicity)
        pooled = self._series.get((measurement_id, eth, "pooled"), ())
        for s in (*found, *pooled):
            if s.source == source:
                return s
        found = (*found, *(p for p in pooled if p not in found))
        raise InputError(
            self._where,
            f"no rows of source {source!r} for {measurement_id} ({self._describe(sex, ethnicity)})",
            f"sources: {', '.join(s.source for s in found)}",
        )

    def _describe(self, sex: str, ethnicity: str | None) -> str:
        return f"{_sex_label(sex) or sex}, {self._ethnicity(ethnicity)}"


def _sex_label(sex: str) -> str | None:
    value = str(sex).strip().lower()
    value = {"f": "female", "m": "male", "m f": "pooled", "both": "pooled", "all": "pooled"}.get(
        value, value
    )
    return value if value in SEXES else None


def _finite_age(source: str, age: float) -> float:
    try:
        value = float(age)
    except (TypeError, ValueError):
        raise InputError(source, f"age {age!r} is not a number of years") from None
    if not math.isfinite(value):
        raise InputError(source, f"age {age!r} is not a finite number of years")
    return value


# ---------------------------------------------------------------- loading
def list_growth_norms() -> list[str]:
    """Ids of the shipped facial norms tables (``facial_norms`` first)."""
    ids = sorted(
        p.stem
        for p in growth_dir().glob("*.csv")
        if _read_meta(p.with_suffix(".meta.json")).get("@schema") == "growth-norms-v1"
    )
    return sorted(ids, key=lambda i: i != "facial_norms")


def load_growth_norms(
    id_or_path: str | PathLike[str] = "facial_norms", catalogue: LandmarkCatalogue | None = None
) -> GrowthNorms:
    """Load a shipped facial norms table by id, or a user CSV by path.

    A user CSV has the columns of :data:`COLUMNS` (``name``, ``kind``, ``ethnicity``
    and ``n`` optional: the id, ``euclidean``, "unspecified" and unknown by default);
    landmark labels may be any spelling the catalogue knows (``Lex``, ``exL``,
    ``ex_l``).  A sidecar ``<stem>.meta.json`` with a ``sources`` dict is optional;
    without one every row's ``source`` is its own citation text.

    Raises
    ------
    InputError
        Naming the file and, for row problems, the line: unknown table id, missing
        file or columns, empty values, a missing, zero or negative SD, a non-numeric
        or negative age, means outside 1-400 mm, an SD larger than its mean, unknown
        landmark codes (with the catalogue code they resemble), one measurement id
        with different landmarks, names or kinds on different rows, an unknown kind
        or sex, the same age twice for one measurement, ethnicity, sex and source,
        and source keys the metadata does not define.
    """
    path = Path(id_or_path)
    shipped = path.suffix.lower() != ".csv"
    if shipped:
        path = growth_dir() / f"{id_or_path}.csv"
        if not path.exists() or str(id_or_path) not in list_growth_norms():
            raise InputError(
                str(id_or_path),
                "unknown growth norms table",
                f"shipped tables: {', '.join(list_growth_norms())}; or give a CSV file",
            )
    if not path.exists():
        raise InputError(path, "growth norms table not found")
    meta = _read_meta(path.with_suffix(".meta.json"))
    rows = read_csv_rows(path, REQUIRED, expected=COLUMNS, what="growth norms table")
    if not rows:
        raise InputError(path, "the table has no rows")
    catalogue = catalogue or load_catalogue()
    measurements: dict[str, tuple[NormMeasurement, int]] = {}
    grouped: dict[tuple[str, str, str, str], list[tuple[int, float, float, float, float]]] = {}
    unknown: dict[str, int] = {}
    for line, row in rows:
        mid = _text(path, line, row, "measurement_id")
        a_label, b_label = _text(path, line, row, "a"), _text(path, line, row, "b")
        codes = []
        for label in (a_label, b_label):
            try:
                codes.append(catalogue.normalise(label, "skin"))
            except Exception:  # noqa: BLE001 - LandmarkError: collected, reported once
                unknown.setdefault(label, line)
        age = _number(path, line, row, "age_years")
        if not AGE_RANGE_YEARS[0] <= age <= AGE_RANGE_YEARS[1]:
            raise InputError(
                path,
                f"line {line}: age_years {row['age_years']} is not an age "
                f"({AGE_RANGE_YEARS[0]:g}-{AGE_RANGE_YEARS[1]:g} years)",
            )
        mean = _number(path, line, row, "mean_mm")
        lo, hi = MEAN_MM_RANGE
        if not lo <= mean <= hi:
            raise InputError(
                path,
                f"line {line}: mean_mm {row['mean_mm']} is implausible for a facial "
                f"measurement ({lo:g}-{hi:g} mm)",
                "is the column in mm?",
            )
        sd = _sd(path, line, row, mean)
        n = _count(path, line, row)
        source = _text(path, line, row, "source")
        sex = _sex_label(row.get("sex") or "")
        if sex is None:
            raise InputError(
                path,
                f"line {line}: unknown sex {row.get('sex')!r}",
                "use female, male or pooled",
            )
        ethnicity = " ".join((row.get("ethnicity") or "").split()) or UNSPECIFIED
        if len(codes) < 2:
            continue
        kind = (row.get("kind") or "").strip().lower() or "euclidean"
        if kind not in KINDS:
            raise InputError(
                path, f"line {line}: unknown kind {kind!r}", f"use one of: {', '.join(KINDS)}"
            )
        if codes[0] == codes[1]:
            raise InputError(path, f"line {line}: {mid} measures {codes[0]} to itself")
        m = NormMeasurement(
            mid,
            (row.get("name") or "").strip() or mid,
            kind,
            codes[0],
            codes[1],
            _side(catalogue, codes[0], codes[1]),
        )
        first = measurements.setdefault(mid, (m, line))
        if first[0] != m:
            raise InputError(
                path,
                f"line {line}: measurement {mid} is {_show(m)} here but {_show(first[0])} "
                f"on line {first[1]}",
                "one measurement id is one landmark pair, kind and name",
            )
        grouped.setdefault((mid, ethnicity, sex, source), []).append((line, age, mean, sd, n))
    if unknown:
        raise InputError(
            path,
            f"unknown skin landmark codes: {', '.join(unknown)} ("
            + "; ".join(_unknown_note(line, label, catalogue) for label, line in unknown.items())
            + ")",
            "use the skin codes of data_tables/landmarks/catalogue.csv",
        )
    citations = _citations(path, meta, {k[3] for k in grouped})
    series = _series(path, grouped)
    return GrowthNorms(
        str(meta.get("id", path.stem)),
        meta,
        tuple(m for m, _ in measurements.values()),
        str(path),
        str(id_or_path) if shipped else str(path),
        series,
        citations,
    )


def _series(
    path: Path,
    grouped: Mapping[tuple[str, str, str, str], list[tuple[int, float, float, float, float]]],
) -> dict[tuple[str, str, str], tuple[_Series, ...]]:
    """Per (measurement, ethnicity, sex): every source's rows, the preferred source first."""
    out: dict[tuple[str, str, str], list[_Series]] = {}
    for (mid, eth, sex, source), rows in grouped.items():
        rows = sorted(rows, key=lambda r: r[1])
        for (l0, a0, *_), (l1, a1, *_) in zip(rows, rows[1:], strict=False):
            if a0 == a1:
                raise InputError(
                    path,
                    f"line {max(l0, l1)}: age {a1:g} y of {mid} ({sex}, {eth}, {source}) "
                    f"is given twice (also on line {min(l0, l1)})",
                    "keep one row per measurement, ethnicity, sex, source and age",
                )
        arr = np.asarray([r[1:] for r in rows], dtype=np.float64)
        counts = arr[:, 3][np.isfinite(arr[:, 3])]
        s = _Series(
            source,
            _ro(arr[:, 0]),
            _ro(arr[:, 1]),
            _ro(arr[:, 2]),
            float(counts.max()) if counts.size else math.nan,
            tuple(r[0] for r in rows),
        )
        out.setdefault((mid, eth, sex), []).append(s)
    return {
        k: tuple(sorted(v, key=lambda s: (-s.span, -len(s.ages), s.source))) for k, v in out.items()
    }


def _citations(path: Path, meta: Mapping[str, Any], keys: Iterable[str]) -> dict[str, str]:
    sources = meta.get("sources")
    if not isinstance(sources, dict) or not sources:
        return {}  # a user table without a sidecar: the source text is the citation
    single = sorted({k.strip() for key in keys for k in key.split(";") if k.strip()})
    missing = [k for k in single if k not in sources]
    if missing:
        raise InputError(
            path, f"rows cite sources not defined in the metadata: {', '.join(missing)}"
        )
    return {str(k): str(v) for k, v in sources.items()}


def _side(catalogue: LandmarkCatalogue, a: str, b: str) -> str:
    sides = {catalogue.entry(a, "skin").side, catalogue.entry(b, "skin").side}
    if sides == {"midline"}:
        return "midline"
    if {"left", "right"} <= sides:
        return "pair"
    return "left" if "left" in sides else "right"


def _show(m: NormMeasurement) -> str:
    return f"{m.kind} {m.a}-{m.b} {m.name!r}"


def _read_meta(path: Path) -> dict[str, Any]:
    if not path.exists():
        return {}
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(path, f"table metadata is not valid JSON ({exc})") from None
    if not isinstance(meta, dict):
        raise InputError(path, "table metadata must be a JSON object")
    return meta


def _text(path: Path, line: int, row: Row, column: str) -> str:
    value = (row.get(column) or "").strip()
    if not value:
        raise InputError(path, f"line {line}: {column} is empty")
    return value


def _number(path: Path, line: int, row: Row, column: str) -> float:
    text = _text(path, line, row, column)
    try:
        value = float(text)
    except ValueError:
        raise InputError(path, f"line {line}: {column} is not a number ({text!r})") from None
    if not math.isfinite(value):
        raise InputError(path, f"line {line}: {column} is not a finite number ({text!r})")
    return value


def _sd(path: Path, line: int, row: Row, mean: float) -> float:
    text = (row.get("sd_mm") or "").strip()
    if not text:
        raise InputError(
            path,
            f"line {line}: sd_mm is missing",
            "growth targets keep each measurement's z-score, which needs an SD on every row",
        )
    sd = _number(path, line, row, "sd_mm")
    if sd <= 0:
        raise InputError(path, f"line {line}: sd_mm must be a positive number of mm, got {text}")
    if sd > mean:
        raise InputError(
            path,
            f"line {line}: sd_mm {text} mm is larger than the mean {row['mean_mm']} mm",
            "no facial measurement varies that much; are the columns swapped?",
        )
    return sd


def _count(path: Path, line: int, row: Row) -> float:
    text = (row.get("n") or "").strip()
    if not text:
        return math.nan
    n = _number(path, line, row, "n")
    if n < 0:
        raise InputError(path, f"line {line}: n must be a non-negative count, got {text}")
    return n


def _unknown_note(line: int, label: str, catalogue: LandmarkCatalogue) -> str:
    """``line 3: 'exx_l', did you mean ex_l?`` -- close skin codes, names or aliases."""
    note = f"line {line}: {label!r}"
    try:
        skull = catalogue.normalise(label, "skull")
    except Exception:  # noqa: BLE001 - not a skull code either
        skull = None
    if skull is not None:
        partner = catalogue.partner(skull, "skull")
        return note + (
            f" is a skull landmark; its skin partner is {partner}"
            if partner
            else " is a skull landmark"
        )
    names: dict[str, str] = {}
    for e in catalogue.entries:
        if e.surface == "skin":
            for name in (e.code, e.name, *e.aliases):
                names.setdefault(name.lower(), e.code)
    close = difflib.get_close_matches(label.lower(), list(names), n=6, cutoff=0.6)
    guesses = list(dict.fromkeys(names[c] for c in close))[:3]
    return note + (f", did you mean {' or '.join(guesses)}?" if guesses else "")


def _ro(values: np.ndarray) -> np.ndarray:
    a = np.array(values, dtype=np.float64)
    a.setflags(write=False)
    return a


# ---------------------------------------------------------------- head circumference
HC_COLUMNS = ("reference", "sex", "age_years", "L", "M_mm", "S", "source")
#: the age (years) at which the head circumference reference switches from WHO 2006 to UK90
HC_SWITCH_AGE_YEARS = 4.0
#: a head circumference median (mm) outside this range is not a human head (newborn ~300 mm)
HC_MEDIAN_MM_RANGE = (200.0, 700.0)


@dataclass(frozen=True, eq=False)
class _Lms:
    ages: np.ndarray
    L: np.ndarray
    M: np.ndarray
    S: np.ndarray
    source: str


@dataclass(frozen=True, eq=False)
class HeadCircumferenceReference:
    """Head (occipito-frontal) circumference growth by sex and age from LMS tables, in mm.

    Ages below :data:`HC_SWITCH_AGE_YEARS` (4.0 y) read the WHO 2006 standard, ages
    from 4.0 y the UK90 reference: one switch, no blending (at 4.0 y the UK90 median
    is about 20 mm larger than the WHO one, see ``data_tables/growth/README.md``).
    L, M and S are interpolated linearly in age between the tabulated (monthly) ages.
    A circumference is a length along the head, so it does not depend on the frame.
    """

    meta: dict[str, Any]
    path: str
    _tables: Mapping[tuple[str, str], _Lms] = field(default_factory=dict, repr=False)

    def references(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(r for r, _ in self._tables))

    def reference_for(self, age: float) -> str:
        """``"WHO2006"`` below 4.0 y, ``"UK90"`` from 4.0 y."""
        return "WHO2006" if float(age) < HC_SWITCH_AGE_YEARS else "UK90"

    def age_range(self, sex: str) -> tuple[float, float]:
        """Youngest and oldest age (years) covered for a sex (girls' UK90 rows end at 17 y)."""
        sex_v = self._sex(sex)
        who, uk = self._tables[("WHO2006", sex_v)], self._tables[("UK90", sex_v)]
        return float(who.ages[0]), float(uk.ages[-1])

    def lms(self, sex: str, age: float) -> tuple[float, float, float]:
        """``(L, M_mm, S)`` at an age (years), interpolated linearly in age."""
        sex_v = self._sex(sex)
        age_f = _finite_age(self.path, age)
        lo, hi = self.age_range(sex_v)
        if not lo <= age_f <= hi:
            raise InputError(
                self.path,
                f"head circumference: age {age_f:g} y is outside the references' range "
                f"{lo:g}-{hi:g} y ({sex_v})",
                "WHO 2006 covers 0-5 y and UK90 4-18 y (girls 4-17 y); adults are the "
                "caller's decision",
            )
        t = self._tables[(self.reference_for(age_f), sex_v)]
        return (
            float(np.interp(age_f, t.ages, t.L)),
            float(np.interp(age_f, t.ages, t.M)),
            float(np.interp(age_f, t.ages, t.S)),
        )

    def median_mm(self, sex: str, age: float) -> float:
        return self.lms(sex, age)[1]

    def sd_mm(self, sex: str, age: float) -> float:
        """The SD (mm): M*S when L = 1 (every row of the shipped tables), else half the
        distance between the values at z = -1 and z = +1."""
        L, M, S = self.lms(sex, age)
        if abs(L - 1.0) < 1e-9:
            return M * S
        return 0.5 * (_lms_value(L, M, S, 1.0) - _lms_value(L, M, S, -1.0))

    def z(self, sex: str, age: float, value_mm: float) -> float:
        """z-score of a head circumference (mm): ((x/M)^L - 1)/(L S), or ln(x/M)/S for L = 0."""
        if not (math.isfinite(value_mm) and value_mm > 0):
            raise InputError(
                self.path, f"head circumference {value_mm!r} mm must be a positive number"
            )
        L, M, S = self.lms(sex, age)
        if abs(L) < 1e-12:
            return math.log(value_mm / M) / S
        return float(((value_mm / M) ** L - 1.0) / (L * S))

    def value_at(self, sex: str, age: float, z: float) -> float:
        """Head circumference (mm) at a z-score: M (1 + L S z)^(1/L), or M exp(S z) for L = 0."""
        if not math.isfinite(z):
            raise InputError(self.path, f"z-score {z!r} must be finite")
        L, M, S = self.lms(sex, age)
        value = _lms_value(L, M, S, z)
        if not math.isfinite(value):
            raise InputError(self.path, f"z-score {z:g} is beyond the LMS curve at {age:g} y")
        return value

    def citation(self, reference: str) -> str:
        """Full citation of a reference ("WHO2006" / "UK90") or a source key."""
        sources = self.meta.get("sources", {})
        key = next((t.source for (r, _), t in self._tables.items() if r == reference), reference)
        return str(sources.get(key, key))

    def _sex(self, sex: str) -> str:
        value = _sex_label(sex)
        if value not in ("female", "male"):
            raise InputError(self.path, f"head circumference needs sex female or male, got {sex!r}")
        return value


def _lms_value(L: float, M: float, S: float, z: float) -> float:
    if abs(L) < 1e-12:
        return M * math.exp(S * z)
    base = 1.0 + L * S * z
    return M * base ** (1.0 / L) if base > 0 else math.nan


def load_head_circumference(path: str | PathLike[str] | None = None) -> HeadCircumferenceReference:
    """Read ``data_tables/growth/head_circumference_lms.csv`` (or a file in its format).

    Raises
    ------
    InputError
        Naming the file and line: missing columns, non-numeric values, medians outside
        200-700 mm, S not positive, the same age twice, and a file lacking the WHO2006
        or UK90 rows of a sex.
    """
    csv_path = Path(path) if path is not None else growth_dir() / "head_circumference_lms.csv"
    if not csv_path.exists():
        raise InputError(csv_path, "head circumference table not found")
    meta = _read_meta(csv_path.with_suffix(".meta.json"))
    rows = read_csv_rows(csv_path, HC_COLUMNS, expected=HC_COLUMNS, what="head circumference table")
    grouped: dict[tuple[str, str], list[tuple[int, float, float, float, float, str]]] = {}
    for line, row in rows:
        ref = _text(csv_path, line, row, "reference")
        sex = _sex_label(row.get("sex") or "")
        if sex not in ("female", "male"):
            raise InputError(csv_path, f"line {line}: sex must be female or male")
        age = _number(csv_path, line, row, "age_years")
        L = _number(csv_path, line, row, "L")
        M = _number(csv_path, line, row, "M_mm")
        S = _number(csv_path, line, row, "S")
        lo, hi = HC_MEDIAN_MM_RANGE
        if not lo <= M <= hi:
            raise InputError(
                csv_path,
                f"line {line}: M_mm {row['M_mm']} is not a head circumference ({lo:g}-{hi:g} mm)",
                "is the column in mm (cm x 10)?",
            )
        if not 0 < S < 1:
            raise InputError(csv_path, f"line {line}: S must be between 0 and 1, got {row['S']}")
        grouped.setdefault((ref, sex), []).append(
            (line, age, L, M, S, _text(csv_path, line, row, "source"))
        )
    tables: dict[tuple[str, str], _Lms] = {}
    for key, items in grouped.items():
        items.sort(key=lambda r: r[1])
        for prev, cur in zip(items, items[1:], strict=False):
            if prev[1] == cur[1]:
                raise InputError(
                    csv_path,
                    f"line {cur[0]}: age {cur[1]:g} y of {key[0]} {key[1]} is given twice "
                    f"(also on line {prev[0]})",
                )
        arr = np.asarray([r[1:5] for r in items], dtype=np.float64)
        tables[key] = _Lms(
            _ro(arr[:, 0]), _ro(arr[:, 1]), _ro(arr[:, 2]), _ro(arr[:, 3]), items[0][5]
        )
    for need in (("WHO2006", s) for s in ("female", "male")):
        if need not in tables or ("UK90", need[1]) not in tables:
            raise InputError(csv_path, f"the table needs WHO2006 and UK90 rows for {need[1]}s")
    return HeadCircumferenceReference(meta, str(csv_path), tables)
