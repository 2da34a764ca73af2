"""Typed reconstruction settings of a case: dowels, skull orientation and guides.

Three case parts (see :data:`workbench.model.case.PARTS`):

=========== ==================================================================
part        value
=========== ==================================================================
dowels      :class:`DowelSettings`: depth table, sex, build, per-landmark
            overrides (mm) and exclusions, soft-tissue model, region factors
orientation :class:`Orientation` (face and up directions of the skull file)
            or ``None``: found automatically from the bone
guides      :class:`GuideList` (guides set or edited by the user) or ``None``:
            computed from the skull at every fit
=========== ==================================================================

The values are frozen and compare by value; each has ``to_state()`` /
``from_state()`` (plain JSON, see ``data_tables/schemas/case.schema.json``).
They are checked cheaply here (finite positive depths, known builds, sexes,
tissue models and regions, unit directions); the services check landmark
codes against the catalogue, table ids against the tables and guides against
the guide rules (:mod:`workbench.services.reconstruction.service`).

Notes
-----
Depths are millimetres along the dowel.  Orientation vectors are directions
in the skull file's coordinates (the specimen's input frame), stored with unit
length.  Guide values are millimetres in the head frame (x to the subject's
left, y up, z toward the face, Frankfort Horizontal); their JSON layout is
that of :func:`workbench.services.guides.classic.guides_to_json`.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Any

from workbench.core.data_paths import DEFAULT_DEPTH_TABLE
from workbench.core.errors import InputError
from workbench.core.limits import BMI_RANGE, MAX_BUILD_SD, MAX_TISSUE_DEPTH_MM, REGION_FACTOR_RANGE
from workbench.model.state import freeze_json, thaw_json

DEFAULT_TABLE = DEFAULT_DEPTH_TABLE
SEXES = ("female", "male")
#: named builds (a table's build groups, else the build model's faces: normal = the means,
#: obese = heavy); ``bmi:X`` a BMI for the build model; a number k means mean + k SD
BUILDS = ("slender", "normal", "obese", "average", "heavy")
#: soft-tissue models (:mod:`workbench.services.tissue.tissue_model`, ``MODELS``)
TISSUE_MODELS = ("table", "reference")
#: where the mandible is for the face (see DowelSettings.jaw)
JAW_MODES = ("occlusion", "as-scanned")
#: face regions a thickness factor can be set for (``tissue_model.REGIONS``)
REGIONS = ("forehead", "orbits", "nose", "cheeks", "mouth", "chin")
#: plausible region factors (``tissue_model.FACTOR_RANGE``)
FACTOR_RANGE = REGION_FACTOR_RANGE
#: largest depth override accepted (mm): the soft-tissue bound of :mod:`workbench.core.limits`
MAX_DEPTH_MM = MAX_TISSUE_DEPTH_MM
#: anterior and superior may not be closer to parallel than this (|cos|)
MAX_AXIS_COS = 0.99


class SetupError(InputError, ValueError):
    """An invalid reconstruction setting (names the setting and the problem)."""


# ------------------------------------------------------------------ dowels
def parse_bmi_build(text: str) -> float | None:
    """The BMI (kg/m²) of a build written ``bmi:27.5`` / ``bmi 27.5`` / ``bmi=27.5``, or None
    when ``text`` is not such a build.

    Raises
    ------
    SetupError
        A BMI that is not a number or lies outside :data:`~workbench.core.limits.BMI_RANGE`.
    """
    t = str(text).strip().lower()
    if not t.startswith("bmi"):
        return None
    try:
        bmi = float(t[3:].lstrip(" :="))
    except ValueError:
        raise SetupError("build", f"{text!r}: the BMI is not a number", "e.g. bmi:27.5") from None
    if not (math.isfinite(bmi) and BMI_RANGE[0] <= bmi <= BMI_RANGE[1]):
        raise SetupError(
            "build",
            f"BMI {bmi:g} kg/m² is outside {BMI_RANGE[0]:g}-{BMI_RANGE[1]:g}",
            "a BMI is weight in kg over height in m squared, e.g. bmi:27.5",
        )
    return bmi


def parse_build(value: Any) -> str | float:
    """``"normal"`` / ``"slender"`` / ``"obese"``, or k (float) for mean + k SD.

    Numbers and numeric text (``"1.5"``, ``"-1 SD"``) become a float k.
    """
    if isinstance(value, bool):
        raise SetupError("build", f"unknown build {value!r}")
    if isinstance(value, (int, float)):
        k = float(value)
    else:
        text = str(value).strip().lower()
        if text in BUILDS:
            return text
        bmi = parse_bmi_build(text)
        if bmi is not None:
            return f"bmi:{bmi:g}"
        try:
            k = float(text.removesuffix("sd").strip())
        except ValueError:
            raise SetupError(
                "build",
                f"unknown build {value!r}",
                "use slender, average, heavy (or normal, obese), bmi:X for a BMI, "
                "or a number k for mean + k SD",
            ) from None
    if not math.isfinite(k):
        raise SetupError("build", f"k must be a finite number of SDs, got {value!r}")
    if abs(k) > MAX_BUILD_SD:
        raise SetupError(
            "build",
            f"k = {k:g} SD is outside ±{MAX_BUILD_SD:g} SD",
            "a build is mean + k SD of the table group; beyond "
            f"±{MAX_BUILD_SD:g} SD the table is extrapolated, not read",
        )
    return k


def build_text(build: str | float) -> str:
    """A build as the user types it: ``"normal"``, ``"1.5"``, ``"-1"``."""
    return build if isinstance(build, str) else f"{build:g}"


def _code(value: Any, what: str) -> str:
    if not isinstance(value, str) or not value.strip():
        raise SetupError(what, f"a landmark code must be non-empty text, got {value!r}")
    return value.strip()


def _depth(code: str, value: Any) -> float:
    try:
        depth = float(value)
    except (TypeError, ValueError):
        depth = math.nan
    if isinstance(value, bool) or not (math.isfinite(depth) and 0.0 < depth <= MAX_DEPTH_MM):
        raise SetupError(
            f"depth override {code}", f"{value!r} is not a depth in mm (0-{MAX_DEPTH_MM:g})"
        )
    return depth


def _factor(region: Any, value: Any) -> float:
    if region not in REGIONS:
        raise SetupError(
            "region factor", f"unknown region {region!r}", f"regions: {', '.join(REGIONS)}"
        )
    try:
        f = float(value)
    except (TypeError, ValueError):
        f = math.nan
    lo, hi = FACTOR_RANGE
    if isinstance(value, bool) or not (math.isfinite(f) and lo <= f <= hi):
        raise SetupError("region factor", f"{region}={value!r} is outside {lo:g}-{hi:g}")
    return f


def _mapping(value: Any, what: str) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise SetupError(what, f"expected a mapping, got {type(value).__name__}")
    return value


@dataclass(frozen=True)
class DowelSettings:
    """How the skull landmarks become dowels, and how the soft tissue is set.

    Attributes
    ----------
    table : str
        Depth table id (``workbench.io.tables.list_tables``) or a CSV path.
    sex : "female" | "male"
        Table group and built-in reference head.
    build : "slender" | "normal" | "obese" or float k
        A named build group, or mean + k SD (numeric text becomes k).
    overrides : {skull code: depth mm}
        Depths set by hand (read-only mapping, sorted by code).
    excluded : tuple of str
        Skull codes whose dowels are off (sorted, unique).
    tissue_model : "table" | "reference"
        The reference's thickness calibrated to the table, or kept as it is.
    region_factors : {region: factor}
        Thickness factors per face region (:data:`REGIONS`, :data:`FACTOR_RANGE`).
    jaw : "occlusion" | "as-scanned"
        Where the mandible is for the face: brought into occlusion (teeth
        together, condyles in the fossae; what practitioners do before they
        reconstruct) or left where the scan has it.
    """

    table: str = DEFAULT_TABLE
    sex: str = "male"
    build: str | float = "normal"
    overrides: Mapping[str, float] = field(default_factory=dict)
    excluded: tuple[str, ...] = ()
    tissue_model: str = "table"
    region_factors: Mapping[str, float] = field(default_factory=dict)
    jaw: str = "occlusion"

    def __post_init__(self) -> None:
        if not isinstance(self.table, str) or not self.table.strip():
            raise SetupError("depth table", f"a table id or CSV path is needed, got {self.table!r}")
        if self.sex not in SEXES:
            raise SetupError("sex", f"{self.sex!r} is not one of {', '.join(SEXES)}")
        if self.tissue_model not in TISSUE_MODELS:
            raise SetupError(
                "tissue model",
                f"unknown tissue model {self.tissue_model!r}",
                f"use {' or '.join(TISSUE_MODELS)}",
            )
        if self.jaw not in JAW_MODES:
            raise SetupError(
                "jaw", f"unknown jaw position {self.jaw!r}", f"use {' or '.join(JAW_MODES)}"
            )
        overrides = _mapping(self.overrides, "depth overrides")
        depths = {_code(c, "depth override"): _depth(str(c), v) for c, v in overrides.items()}
        excluded = self.excluded
        if isinstance(excluded, (str, bytes)) or not isinstance(
            excluded, (Sequence, set, frozenset)
        ):
            raise SetupError("excluded dowels", f"expected a list of codes, got {excluded!r}")
        codes = {_code(c, "excluded dowel") for c in excluded}
        factors = {
            r: _factor(r, f) for r, f in _mapping(self.region_factors, "region factors").items()
        }
        set_ = object.__setattr__
        set_(self, "table", self.table.strip())
        set_(self, "build", parse_build(self.build))
        set_(self, "overrides", MappingProxyType(dict(sorted(depths.items()))))
        set_(self, "excluded", tuple(sorted(codes)))
        set_(
            self,
            "region_factors",
            MappingProxyType({r: factors[r] for r in REGIONS if r in factors}),
        )

    def __hash__(self) -> int:
        return hash(json.dumps(self.to_state(), sort_keys=True))

    @property
    def build_text(self) -> str:
        return build_text(self.build)

    def replaced(self, **fields_: Any) -> DowelSettings:
        """A copy with some fields changed (validated)."""
        return replace(self, **fields_)

    def with_override(self, code: str, depth_mm: float | None) -> DowelSettings:
        """A copy with ``code``'s depth set (mm), or its override removed (``None``)."""
        code = _code(code, "depth override")
        overrides = {k: v for k, v in self.overrides.items() if k != code}
        if depth_mm is not None:
            overrides[code] = depth_mm
        return replace(self, overrides=overrides)

    def with_exclusion(self, code: str, excluded: bool) -> DowelSettings:
        """A copy with ``code``'s dowel switched off (``excluded``) or on."""
        code = _code(code, "excluded dowel")
        codes = set(self.excluded) | {code} if excluded else set(self.excluded) - {code}
        return replace(self, excluded=tuple(codes))

    def to_state(self) -> dict[str, Any]:
        return {
            "table": self.table,
            "sex": self.sex,
            "build": self.build,
            "overrides": dict(self.overrides),
            "excluded": list(self.excluded),
            "tissue_model": self.tissue_model,
            "region_factors": dict(self.region_factors),
            "jaw": self.jaw,
        }

    @classmethod
    def from_state(cls, state: Mapping[str, Any]) -> DowelSettings:
        unknown = sorted(set(state) - set(cls.__dataclass_fields__))
        if unknown:
            raise SetupError("dowel settings", f"unknown fields {', '.join(unknown)}")
        return cls(**{k: v for k, v in state.items()})


# ------------------------------------------------------------------ orientation
Vector = tuple[float, float, float]


def _unit(value: Any, what: str) -> Vector:
    try:
        v = tuple(float(x) for x in value)
    except (TypeError, ValueError):
        v = ()
    if len(v) != 3 or not all(math.isfinite(x) for x in v):
        raise SetupError(f"orientation {what}", f"expected 3 finite numbers, got {value!r}")
    norm = math.sqrt(sum(x * x for x in v))
    if norm < 1e-9:
        raise SetupError(f"orientation {what}", "the direction has zero length")
    if abs(norm - 1.0) > 1e-12:  # idempotent: a stored unit vector is kept bit for bit
        v = tuple(x / norm for x in v)
    return v  # type: ignore[return-value]


@dataclass(frozen=True)
class Orientation:
    """Where the face looks and where up is, in the skull file's coordinates.

    Attributes
    ----------
    anterior, superior : (3,) tuple of float
        Unit directions (stored normalised; need not be exactly perpendicular).
    left : (3,) tuple of float or None
        The subject's left, only needed for mirrored files.
    """

    anterior: Vector
    superior: Vector
    left: Vector | None = None

    def __post_init__(self) -> None:
        a, s = _unit(self.anterior, "anterior"), _unit(self.superior, "superior")
        if abs(sum(x * y for x, y in zip(a, s, strict=True))) > MAX_AXIS_COS:
            raise SetupError("orientation", "anterior and superior are (nearly) parallel")
        object.__setattr__(self, "anterior", a)
        object.__setattr__(self, "superior", s)
        if self.left is not None:
            object.__setattr__(self, "left", _unit(self.left, "left"))

    @property
    def hint(self) -> tuple[Vector, ...]:
        """``(anterior, superior[, left])``, the ``hint`` of the registration."""
        return (self.anterior, self.superior) + ((self.left,) if self.left is not None else ())

    @classmethod
    def from_hint(cls, hint: Sequence[Any]) -> Orientation:
        """From ``(anterior, superior[, left])``."""
        if len(hint) not in (2, 3):
            raise SetupError("orientation", "give (anterior, superior[, left])")
        return cls(*hint)

    def to_state(self) -> dict[str, Any]:
        return {
            "anterior": list(self.anterior),
            "superior": list(self.superior),
            "left": None if self.left is None else list(self.left),
        }

    @classmethod
    def from_state(cls, state: Mapping[str, Any]) -> Orientation:
        return cls(state["anterior"], state["superior"], state.get("left"))


# ------------------------------------------------------------------ guides
def _check_guide(item: Any, index: int) -> str:
    where = f"guide {index + 1}"
    if not isinstance(item, Mapping):
        raise SetupError(where, f"expected an object, got {type(item).__name__}")
    gid = item.get("id")
    if not isinstance(gid, str) or not gid:
        raise SetupError(where, "needs a non-empty text id")
    value = item.get("value")
    ok = (
        isinstance(value, (list, tuple))
        and len(value) in (1, 2)
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
    )
    if not ok:
        raise SetupError(f"guide {gid!r}", f"value must be 1 or 2 numbers (mm), got {value!r}")
    return gid


@dataclass(frozen=True)
class GuideList:
    """Guides stored in the case, as frozen JSON (``guides_to_json`` layout).

    Attributes
    ----------
    guides : tuple of read-only mappings
        One per guide, in order; ids unique.  Turned into ``Guide`` objects
        (and fully checked) by the services.
    """

    guides: tuple[Mapping[str, Any], ...] = ()

    def __post_init__(self) -> None:
        if isinstance(self.guides, (str, bytes, Mapping)) or not isinstance(self.guides, Sequence):
            raise SetupError("guides", "expected a list of guides")
        frozen = freeze_json(list(self.guides), "guides")
        ids = [_check_guide(item, i) for i, item in enumerate(frozen)]
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise SetupError("guides", f"duplicate guide ids: {', '.join(dup)}")
        object.__setattr__(self, "guides", frozen)

    def __hash__(self) -> int:
        return hash(json.dumps(self.to_state(), sort_keys=True))

    def __len__(self) -> int:
        return len(self.guides)

    @property
    def ids(self) -> tuple[str, ...]:
        return tuple(g["id"] for g in self.guides)

    def to_state(self) -> list[dict[str, Any]]:
        return thaw_json(self.guides)

    @classmethod
    def from_state(cls, state: Sequence[Mapping[str, Any]]) -> GuideList:
        return cls(tuple(state))


# ------------------------------------------------------------------ part codecs
def optional_to_state(value: Orientation | GuideList | None) -> Any:
    return None if value is None else value.to_state()


def orientation_from_state(state: Any) -> Orientation | None:
    return None if state is None else Orientation.from_state(state)


def guides_from_state(state: Any) -> GuideList | None:
    return None if state is None else GuideList.from_state(state)
