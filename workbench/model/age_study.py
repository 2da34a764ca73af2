"""The age-progression study of a case: which head is aged, from what age, to which ages.

One case part (see :data:`workbench.model.case.PARTS`): ``age_study``, an
:class:`AgeStudy` or ``None`` (no study kept; the default, and what older
case files without the part load as).

The study records the *settings* of the Age progression dock (and of
``workbench age``): the source head, its sex and age now, the target ages,
the norms table and population, and the head-arc increase.  It does not hold
a head: the aged heads are results, recomputed from these settings (a
reconstruction source is the case's reconstructed face, itself derived).

Notes
-----
Ages are years (0-100).  ``arc_increase`` is the service's young-child
increase of the head arcs (a fraction, 0-0.1; see
:func:`workbench.services.age.change.age_head`).  The heads the study ages are in
their Frankfort frame (x to the subject's left, x = 0 midsagittal, y up,
z toward the face), in mm; nothing here is a length.  Values are checked
cheaply here (known source and sex, ages and arc increase in range); the
service checks the norms id and population against the norms tables.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields, replace
from typing import Any

from workbench.core.errors import InputError

#: the heads a study can age: a built-in reference, or the case's reconstruction
SOURCES = ("reference:male", "reference:female", "reconstruction")
SEXES = ("female", "male")
#: ages accepted (years)
AGE_RANGE = (0.0, 100.0)
#: head-arc increase accepted (a fraction)
ARC_RANGE = (0.0, 0.1)
DEFAULT_NORMS = "facial_norms"


class AgeStudyError(InputError, ValueError):
    """An invalid age-study setting (names the setting and the problem)."""


def _number(value: Any, what: str, lo: float, hi: float, unit: str) -> float:
    number = isinstance(value, (int, float)) and not isinstance(value, bool)
    x = float(value) if number else math.nan  # text is refused: state and widgets give numbers
    if not (math.isfinite(x) and lo <= x <= hi):
        raise AgeStudyError(what, f"{value!r} is not {unit} in {lo:g}-{hi:g}")
    return x


def _text(value: Any, what: str) -> str:
    if not isinstance(value, str) or not value.strip():
        raise AgeStudyError(what, f"needs non-empty text, got {value!r}")
    return value.strip()


@dataclass(frozen=True)
class AgeStudy:
    """The settings of one age-progression study (frozen; compares by value).

    Attributes
    ----------
    source : "reference:male" | "reference:female" | "reconstruction"
        The head aged: a built-in reference head or the case's reconstructed face.
    sex : "female" | "male"
        Norms and head-circumference chart of this sex.
    from_age : float
        The source head's age now (years, 0-100).
    target_ages : tuple of float
        The ages to show (years, 0-100; at least one, no repeats).  The first
        is the one the dock's slider shows; the others are further ages to
        export with it.
    norms : str
        Id of the growth-norms table.
    ethnicity : str or None
        Population of the facial norms (``None``: the table's default).
    arc_increase : float
        Young-child increase of the head arcs (a fraction, 0-0.1).
    """

    source: str = "reference:male"
    sex: str = "male"
    from_age: float = 18.0
    target_ages: tuple[float, ...] = (8.0,)
    norms: str = DEFAULT_NORMS
    ethnicity: str | None = None
    arc_increase: float = 0.0

    def __post_init__(self) -> None:
        if self.source not in SOURCES:
            raise AgeStudyError(
                "age study source",
                f"unknown head {self.source!r}",
                f"use one of {', '.join(SOURCES)}",
            )
        if self.sex not in SEXES:
            raise AgeStudyError("age study sex", f"{self.sex!r} is not one of {', '.join(SEXES)}")
        lo, hi = AGE_RANGE
        from_age = _number(self.from_age, "age now", lo, hi, "an age in years")
        ages = self.target_ages
        if isinstance(ages, (str, bytes)) or not isinstance(ages, Sequence):
            ages = (ages,)
        checked = tuple(_number(a, "target age", lo, hi, "an age in years") for a in ages)
        if not checked:
            raise AgeStudyError("target age", "at least one target age is needed")
        repeated = sorted({a for a in checked if checked.count(a) > 1})
        if repeated:
            raise AgeStudyError(
                "target age", f"{', '.join(f'{a:g}' for a in repeated)} y given twice"
            )
        ethnicity = self.ethnicity
        if ethnicity is not None:
            ethnicity = _text(ethnicity, "norms population")
        arc = _number(self.arc_increase, "arc increase", *ARC_RANGE, "a fraction")
        set_ = object.__setattr__
        set_(self, "from_age", from_age)
        set_(self, "target_ages", checked)
        set_(self, "norms", _text(self.norms, "norms"))
        set_(self, "ethnicity", ethnicity)
        set_(self, "arc_increase", arc)

    def replaced(self, **fields_: Any) -> AgeStudy:
        """A copy with some fields changed (validated)."""
        return replace(self, **fields_)

    def changed_fields(self, other: AgeStudy | None) -> tuple[str, ...]:
        """Names of the fields that differ from ``other`` (all of them if ``other`` is None)."""
        names = tuple(f.name for f in fields(self))
        if other is None:
            return names
        return tuple(n for n in names if getattr(self, n) != getattr(other, n))

    def to_state(self) -> dict[str, Any]:
        return {
            "source": self.source,
            "sex": self.sex,
            "from_age": self.from_age,
            "target_ages": list(self.target_ages),
            "norms": self.norms,
            "ethnicity": self.ethnicity,
            "arc_increase": self.arc_increase,
        }

    @classmethod
    def from_state(cls, state: Mapping[str, Any]) -> AgeStudy:
        if not isinstance(state, Mapping):
            raise AgeStudyError("age study", f"expected an object, got {type(state).__name__}")
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(state) - known)
        if unknown:
            raise AgeStudyError("age study", f"unknown fields {', '.join(unknown)}")
        missing = sorted(known - set(state))
        if missing:
            raise AgeStudyError("age study", f"missing fields {', '.join(missing)}")
        return cls(**{k: state[k] for k in known})


# ------------------------------------------------------------------ part codec
def age_study_to_state(value: AgeStudy | None) -> dict[str, Any] | None:
    return None if value is None else value.to_state()


def age_study_from_state(state: Any) -> AgeStudy | None:
    return None if state is None else AgeStudy.from_state(state)
