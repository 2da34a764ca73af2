"""The body-build model (``data_tables/build/build_model.csv`` + ``.meta.json``).

What the skull cannot tell — how heavy the person was — as one build score
``z = (BMI − bmi_centre) / bmi_sd`` acting on every tissue-depth landmark
by region: a table row with mean ``m`` and SD ``s`` (mm) becomes
``m + r·s·z`` for the build ``z``, and ``s·√(1 − r²)`` is the individual
spread a known build leaves.  ``r`` per landmark code is a *stated model*
(the shipped one says so in its metadata: no per-landmark depths by BMI
could be read), ordered by region as the cited studies describe the
pattern: least on the forehead and nasal bones, most on the cheeks and jaw.

CSV columns: ``landmark_code, region, r, basis``; side suffixes ``_l``/``_r``
share the row of the bare code.  The metadata gives ``bmi_centre``,
``bmi_sd``, the named builds (``slender``/``average``/``heavy`` with their
BMI), the builds the uncertainty band spans and the citations.  Users can
load their own model in the same format (:func:`load_build_model` with a
path); bad values are refused naming the file and line.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path
from typing import Any

from workbench.core.data_paths import data_tables_dir
from workbench.core.errors import InputError
from workbench.core.json_limits import read_json
from workbench.core.limits import BMI_RANGE
from workbench.io.csv_rows import read_csv_rows

#: the three faces made when the build is unknown, thinnest first
BUILD_FACES = ("slender", "average", "heavy")
#: other names accepted for them (the depth tables' build words)
BUILD_ALIASES = {"normal": "average", "obese": "heavy"}
COLUMNS = ("landmark_code", "region", "r", "basis")
_SIDE = re.compile(r"_(l|r)$")


@dataclass(frozen=True)
class BuildModel:
    """Per-landmark build correlation ``r`` and the BMI scale of the build score.

    Attributes
    ----------
    model_id, title : str
    r : {code: r}
        Correlation of the landmark's depth with the build score (0..1).
    bmi_centre, bmi_sd : float
        kg/m²: the build the depth table's means stand for, and the BMI spread
        one unit of ``z`` is.
    builds : {name: BMI}
        The named faces (:data:`BUILD_FACES`).
    band_builds : (str, str)
        The builds the uncertainty band spans when the build is unknown.
    meta : dict
    path : Path
    """

    model_id: str
    title: str
    r: dict[str, float]
    bmi_centre: float
    bmi_sd: float
    builds: dict[str, float]
    band_builds: tuple[str, str] = ("slender", "heavy")
    meta: dict[str, Any] = field(default_factory=dict)
    path: Path | None = None

    def z_of_bmi(self, bmi: float) -> float:
        """The build score of a BMI (kg/m²)."""
        return (float(bmi) - self.bmi_centre) / self.bmi_sd

    def z(self, build: str) -> float:
        """The build score of a named build (aliases accepted)."""
        return self.z_of_bmi(self.bmi(build))

    def bmi(self, build: str) -> float:
        name = BUILD_ALIASES.get(build, build)
        if name not in self.builds:
            raise InputError(
                self.path or "build model",
                f"no build named {build!r}",
                f"builds: {', '.join(self.builds)}",
            )
        return self.builds[name]

    def loading(self, code: str) -> float:
        """``r`` of a landmark code (``zy_l`` reads the row of ``zy``); 0 for codes the model
        has no row for (their depth does not change with build)."""
        if code in self.r:
            return self.r[code]
        return self.r.get(_SIDE.sub("", code), 0.0)

    def citation_keys(self) -> list[str]:
        return sorted(self.meta.get("sources", {}))


def build_model_dir() -> Path:
    return data_tables_dir() / "build"


def load_build_model(path: str | PathLike[str] | None = None) -> BuildModel:
    """The shipped build model, or a user's (``path`` to its CSV; the ``.meta.json`` beside it).

    Raises
    ------
    InputError
        Missing files or columns, ``r`` outside 0..1, duplicate codes, a
        missing or absurd BMI scale or build (naming the file).
    """
    csv_path = Path(path) if path is not None else build_model_dir() / "build_model.csv"
    if not csv_path.is_file():
        raise InputError(csv_path, "no such build model file")
    meta_path = csv_path.with_suffix(".meta.json")
    if not meta_path.is_file():
        raise InputError(
            meta_path, "the build model's metadata file is missing", "it holds the BMI scale"
        )
    meta = read_json(meta_path, max_bytes=1024 * 1024, what="build model metadata")
    if not isinstance(meta, dict):
        raise InputError(meta_path, "the build model metadata is not a JSON object")
    r: dict[str, float] = {}
    for line, row in read_csv_rows(
        csv_path, ("landmark_code", "r"), expected=COLUMNS, what="build model"
    ):
        code = (row.get("landmark_code") or "").strip()
        if not code:
            raise InputError(csv_path, f"line {line}: empty landmark_code")
        if code in r:
            raise InputError(csv_path, f"line {line}: {code} appears twice")
        try:
            value = float(row.get("r") or "")
        except ValueError:
            raise InputError(csv_path, f"line {line}: r {row.get('r')!r} is not a number") from None
        if not (math.isfinite(value) and 0.0 <= value <= 1.0):
            raise InputError(csv_path, f"line {line}: r = {value:g} is outside 0..1")
        r[code] = value
    centre = _number(meta, "bmi_centre", meta_path)
    sd = _number(meta, "bmi_sd", meta_path)
    if not BMI_RANGE[0] <= centre <= BMI_RANGE[1] or not 1.0 <= sd <= 20.0:
        raise InputError(
            meta_path, f"bmi_centre {centre:g} / bmi_sd {sd:g} kg/m² are not plausible"
        )
    raw = meta.get("builds")
    if not isinstance(raw, dict):
        raise InputError(meta_path, "no 'builds' object (slender, average, heavy with their BMI)")
    builds: dict[str, float] = {}
    for name in BUILD_FACES:
        entry = raw.get(name)
        bmi = entry.get("bmi") if isinstance(entry, dict) else entry
        if not isinstance(bmi, (int, float)) or not BMI_RANGE[0] <= float(bmi) <= BMI_RANGE[1]:
            raise InputError(meta_path, f"build {name!r} has no plausible BMI ({bmi!r})")
        builds[name] = float(bmi)
    if not builds["slender"] < builds["average"] < builds["heavy"]:
        raise InputError(meta_path, "the builds' BMIs must rise: slender < average < heavy")
    band = tuple(meta.get("band_builds", ("slender", "heavy")))
    if len(band) != 2 or any(b not in builds for b in band):
        raise InputError(meta_path, f"band_builds {band!r} must name two of {BUILD_FACES}")
    return BuildModel(
        str(meta.get("id", csv_path.stem)),
        str(meta.get("title", "")),
        r,
        centre,
        sd,
        builds,
        (str(band[0]), str(band[1])),
        meta,
        csv_path,
    )


def _number(meta: dict[str, Any], key: str, path: Path) -> float:
    value = meta.get(key)
    if not isinstance(value, (int, float)) or not math.isfinite(float(value)):
        raise InputError(path, f"{key} is missing or not a number")
    return float(value)
