"""The growth tables beyond the facial norms: the eyeball's growth and the vault's height.

Both live in ``data_tables/growth/`` with their citations in the
``.meta.json`` beside them:

* ``eyeball_axial_length.csv`` -- the eye's axial length (mm) by age (years):
  the eyeball grows little after early childhood (16.8 mm at birth, 22 mm at
  3 y, 23.6 mm in adults), so an aged head's eyes are scaled by this curve,
  not by the face's size change.
* ``vault_norms.csv`` -- the head-ear height (the vertex's height over the
  porion, mm, along y of the Frankfort frame: x to the subject's left, y up,
  z toward the face) and the morphological face height (n-me) of the same
  children by age and sex (Dezső 1967, 7-17 y), in the facial norms' format.
  The head-ear height holds the vault to its own growth; the two together
  give the published vault-to-face ratio.

Tables are values: each is read once per process.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from workbench.core.errors import InputError
from workbench.io.csv_rows import read_csv_rows
from workbench.io.growth_norms import GrowthNorms, growth_dir, load_growth_norms

EYEBALL_FILE = "eyeball_axial_length.csv"
VAULT_FILE = "vault_norms.csv"
#: the vault table's constraint measurements (vertical v-po, one per side)
VAULT_HEIGHT = ("head_ear_height_l", "head_ear_height_r")
#: the vault table's face height of the same children (n-me), for the proportions check
VAULT_FACE_HEIGHT = "morphological_face_height"


@dataclass(frozen=True, eq=False)
class EyeballGrowth:
    """Mean axial length of the eye (mm) by age (years), both sexes pooled.

    Linear between the tabulated ages; before the first and past the last
    one, the first / last value (the eye does not grow after adolescence).
    """

    ages: np.ndarray
    axial: np.ndarray
    sources: tuple[str, ...]
    citations: dict[str, str]

    def axial_mm(self, age: float) -> float:
        """Mean axial length (mm) at ``age`` years."""
        return float(np.interp(float(age), self.ages, self.axial))

    def scale(self, from_age: float, to_age: float) -> float:
        """Factor by which an eyeball changes in size from ``from_age`` to ``to_age``."""
        return self.axial_mm(to_age) / self.axial_mm(from_age)

    def source_at(self, age: float) -> str:
        """Citation keys of the rows that give the value at ``age`` (``;``-separated)."""
        i = int(np.searchsorted(self.ages, float(age)))
        keys = {self.sources[min(max(i - 1, 0), len(self.ages) - 1)]}
        keys.add(self.sources[min(i, len(self.ages) - 1)])
        return ";".join(sorted(keys))


@lru_cache(maxsize=1)
def load_eyeball_growth() -> EyeballGrowth:
    """The shipped eyeball growth table (``data_tables/growth/eyeball_axial_length.csv``).

    Raises :class:`InputError` naming the file for a missing column, a
    non-numeric, negative or repeated age, or an axial length outside 10-35 mm.
    """
    import json

    path = growth_dir() / EYEBALL_FILE
    rows = read_csv_rows(path, ("age_years", "axial_mm", "source"), what="eyeball growth table")
    ages, axial, sources = [], [], []
    for line, row in rows:
        try:
            age = float(row.get("age_years") or "")
            value = float(row.get("axial_mm") or "")
        except ValueError:
            raise InputError(path, f"line {line}: age_years and axial_mm must be numbers") from None
        if not (np.isfinite(age) and age >= 0 and 10.0 <= value <= 35.0):
            raise InputError(path, f"line {line}: age {age} y or axial length {value} mm")
        ages.append(age)
        axial.append(value)
        sources.append(str(row.get("source") or "").strip())
    order = np.argsort(ages, kind="stable")
    a = np.asarray(ages)[order]
    if len(a) < 2 or np.any(np.diff(a) <= 0):
        raise InputError(path, "needs at least two rows and each age once")
    meta = json.loads(path.with_suffix("").with_suffix(".meta.json").read_text(encoding="utf-8"))
    return EyeballGrowth(
        a,
        np.asarray(axial)[order],
        tuple(sources[i] for i in order),
        dict(meta.get("sources", {})),
    )


@lru_cache(maxsize=1)
def load_vault_norms() -> GrowthNorms:
    """The shipped vault table (head-ear height and face height by age and sex, mm)."""
    return load_growth_norms(growth_dir() / VAULT_FILE)


def vault_ages(
    table: GrowthNorms, sex: str, ages: tuple[float, float]
) -> tuple[float, float] | None:
    """The ages (years) at which the vault table is read for a change between ``ages``.

    Ages past the table's last one are read at it (head height is near its
    adult value from about 13 y); None when either age lies before the
    table's first one (the vault then follows the head circumference).
    """
    eth = table.ethnicities()[0]
    lo, hi = table.age_range(VAULT_HEIGHT[0], sex, eth)
    if min(ages) < lo:
        return None
    return (min(ages[0], hi), min(ages[1], hi))


def published_vault_face(sex: str, age: float) -> dict[str, Any] | None:
    """The published head-ear height, face height (n-me) and their ratio at ``age`` (mm).

    Read in the vault table (Dezső 1967; ages past its last one at the last
    one); None below its first age.  ``band`` is the ratio's range when
    each mean is taken ±2 SD in opposite directions (a generous band).
    """
    table = load_vault_norms()
    eth = table.ethnicities()[0]
    lo, hi = table.age_range(VAULT_HEIGHT[0], sex, eth)
    if age < lo:
        return None
    a = min(float(age), hi)
    mv, sv = table.at(VAULT_HEIGHT[0], sex, a, eth)
    mf, sf = table.at(VAULT_FACE_HEIGHT, sex, a, eth)
    return {
        "age_read": a,
        "vault_mm": mv,
        "vault_sd": sv,
        "face_mm": mf,
        "face_sd": sf,
        "ratio": mv / mf,
        "band": ((mv - 2 * sv) / (mf + 2 * sf), (mv + 2 * sv) / (mf - 2 * sf)),
        "source": table.source_of(VAULT_HEIGHT[0], sex, eth),
    }
