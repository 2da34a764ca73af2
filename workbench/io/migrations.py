"""Pure ``dict -> dict`` upgrades of ``case.json`` from older format versions.

:data:`MIGRATIONS` maps a format version to the function that turns a
document of that version into one of the next version.  :func:`migrate` runs
them in order until :data:`CURRENT_VERSION`.  Functions here never touch
files, never look at array or evidence bytes and never build model objects:
the loader validates the result against the current schema afterwards.

Format history
--------------
0
    Development layout (before 0.1), kept so old test cases still open::

        {"format_version": 0, "software": "workbench 0.0.9",
         "case_id": uuid, "examiner": str, "created": iso-time,
         "skull": {"vertices": ref, "faces": ref, "units": "mm"} | null,
         "head_transform": 4x4 list | null,
         "landmarks": {"skull": {code: [x, y, z]}, "skin": {code: [x, y, z]}},
         "evidence": [{"file", "sha256", "bytes", "kind", "source"}],
         "settings": {...}}

    where ``ref`` is ``{"sha256", "dtype", "shape"}`` naming
    ``arrays/<sha256>.npy``.  Only placed landmarks existed.
1
    Parts ``meta``, ``evidence``, ``evidence_store``, ``specimen``,
    ``landmarks`` and ``parameters``; the reconstruction settings were
    free-form ``parameters`` keys: ``depth_table``, ``sex``, ``build``
    (word or number as text), ``depth_overrides`` ``{code: mm}``,
    ``excluded_landmarks`` ``[code]``, ``guides`` (list of guide dicts) and
    ``orientation`` ``{"anterior", "superior"[, "left"]}``.
2
    Those keys
    became the typed parts ``dowels``, ``orientation`` and ``guides``
    (:mod:`workbench.model.reconstruction_setup`).  :func:`v1_to_v2` moves a
    key only if its value is valid for its part; an unusable old value (a
    build word no table knows, a malformed guide list...) stays in
    ``parameters`` unchanged, so the file still opens and nothing is lost.
3
    The part ``age_study`` (:func:`v2_to_v3` adds it as ``null``).

Content seal (no format change)
    Later format-3 files seal ``case.json`` in the audit log: the last
    record written carries ``content_sha256``
    (:func:`workbench.model.audit.content_digest`).  ``case.json`` itself is
    unchanged, so nothing here migrates; files written before (any format
    up to 3) load as "content not sealed (written by an older version)" and
    are sealed by their next save.  The loader accepts the seal for the
    document as stored or as migrated by :func:`migrate`, so the same case
    in an older layout still verifies, while any change to its content
    does not.

Derived results (no format change)
    Format-3 files may carry an optional ``derived`` object (the fitted
    face kept with the case, :mod:`workbench.services.reconstruction.stored_fit`).
    Files without it are unchanged and nothing migrates; a version before
    it refuses a file that has it (the schema names the key).
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Any

CURRENT_VERSION = 3
SCHEMA_ID = "case-schema-v3"

Migration = Callable[[dict[str, Any]], dict[str, Any]]


class MigrationError(ValueError):
    """A document that cannot be upgraded (unknown version or bad old layout)."""


def _array_ref_v0(ref: Mapping[str, Any]) -> dict[str, Any]:
    return {"@array": ref["sha256"], "dtype": ref["dtype"], "shape": list(ref["shape"])}


def _landmark_set_v0(surface: str, points: Mapping[str, Any]) -> dict[str, Any]:
    landmarks = [
        {
            "code": code,
            "position": [float(x) for x in position],
            "status": "placed",
            "confidence": 1.0,
            "description": "",
        }
        for code, position in points.items()
    ]
    return {"surface": surface, "landmarks": landmarks}


def _evidence_v0(item: Mapping[str, Any]) -> dict[str, Any]:
    return {
        "name": item["file"],
        "sha256": item["sha256"],
        "size": item["bytes"],
        "role": item["kind"],
        "original_path": item.get("source", ""),
        "units_note": "",
    }


def v0_to_v1(doc: dict[str, Any]) -> dict[str, Any]:
    """Format 0 → 1: group meta, name array refs ``@array``, status per landmark."""
    skull = doc.get("skull")
    mesh = None
    if skull is not None:
        mesh = {key: _array_ref_v0(skull[key]) for key in ("vertices", "faces")}
    software = str(doc.get("software", ""))
    evidence = [_evidence_v0(item) for item in doc.get("evidence", [])]
    landmarks = doc.get("landmarks", {})
    return {
        "@schema": "case-schema-v1",
        "format_version": 1,
        "software": software,
        "meta": {
            "case_id": doc["case_id"],
            "examiner": doc.get("examiner", ""),
            "created": doc["created"],
            "modified": doc["created"],
            "software_version": software.split()[-1] if software.split() else "",
            "notes": "",
        },
        "evidence": evidence,
        "evidence_store": copy.deepcopy(evidence),
        "specimen": {
            "mesh": mesh,
            "units": skull.get("units", "mm") if skull is not None else "mm",
            "input_to_head": doc.get("head_transform"),
        },
        "landmarks": {s: _landmark_set_v0(s, landmarks.get(s, {})) for s in ("skin", "skull")},
        "parameters": dict(doc.get("settings", {})),
    }


# ---------------------------------------------------------------- 1 -> 2
_SEXES = ("female", "male")
_BUILDS = ("slender", "normal", "obese")
_MAX_DEPTH_MM = 100.0
_MAX_AXIS_COS = 0.99


def _number(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    return float(value) if math.isfinite(value) else None


def _build_v1(value: Any) -> str | float | None:
    if isinstance(value, str):
        text = value.strip().lower()
        if text in _BUILDS:
            return text
        try:
            value = float(text.removesuffix("sd").strip())
        except ValueError:
            return None
    return _number(value)


def _overrides_v1(value: Any) -> dict[str, float] | None:
    if not isinstance(value, Mapping):
        return None
    out = {}
    for code, depth in value.items():
        mm = _number(depth)
        if (
            not (isinstance(code, str) and code.strip())
            or mm is None
            or not 0.0 < mm <= _MAX_DEPTH_MM
        ):
            return None
        out[code.strip()] = mm
    return dict(sorted(out.items()))


def _codes_v1(value: Any) -> list[str] | None:
    if not isinstance(value, list) or not all(isinstance(c, str) and c.strip() for c in value):
        return None
    return sorted({c.strip() for c in value})


def _vector_v1(value: Any) -> list[float] | None:
    if not isinstance(value, list) or len(value) != 3:
        return None
    v = [n for n in (_number(x) for x in value) if n is not None]
    if len(v) != 3 or math.hypot(*v) < 1e-9:
        return None
    return v


def _orientation_v1(value: Any) -> dict[str, Any] | None:
    if not isinstance(value, Mapping) or set(value) - {"anterior", "superior", "left"}:
        return None
    a, s = _vector_v1(value.get("anterior")), _vector_v1(value.get("superior"))
    left = _vector_v1(value["left"]) if value.get("left") is not None else None
    if a is None or s is None or (value.get("left") is not None and left is None):
        return None
    cos = sum(x * y for x, y in zip(a, s, strict=True)) / (math.hypot(*a) * math.hypot(*s))
    if abs(cos) > _MAX_AXIS_COS:
        return None
    return {"anterior": a, "superior": s, "left": left}


def _guides_v1(value: Any) -> list[Any] | None:
    if not isinstance(value, list):
        return None
    ids = []
    for item in value:
        if not isinstance(item, Mapping) or not isinstance(item.get("id"), str) or not item["id"]:
            return None
        v = item.get("value")
        if not isinstance(v, list) or len(v) not in (1, 2) or any(_number(x) is None for x in v):
            return None
        ids.append(item["id"])
    return copy.deepcopy(value) if len(set(ids)) == len(ids) else None


#: old parameter key -> (part, field or None for the whole part, converter)
_MOVED_V1: Mapping[str, tuple[str, str | None, Callable[[Any], Any]]] = MappingProxyType(
    {
        "depth_table": (
            "dowels",
            "table",
            lambda v: v.strip() if isinstance(v, str) and v.strip() else None,
        ),
        "sex": ("dowels", "sex", lambda v: v if v in _SEXES else None),
        "build": ("dowels", "build", _build_v1),
        "depth_overrides": ("dowels", "overrides", _overrides_v1),
        "excluded_landmarks": ("dowels", "excluded", _codes_v1),
        "orientation": ("orientation", None, _orientation_v1),
        "guides": ("guides", None, _guides_v1),
    }
)


def v1_to_v2(doc: dict[str, Any]) -> dict[str, Any]:
    """Format 1 → 2: the reconstruction parameters become the typed parts (see above)."""
    parameters = dict(doc["parameters"])
    parts: dict[str, Any] = {
        "dowels": {
            # the default of format-1 files, fixed by their history (not today's default)
            "table": "ttable_2023",
            "sex": "male",
            "build": "normal",
            "overrides": {},
            "excluded": [],
            "tissue_model": "table",
            "region_factors": {},
        },
        "orientation": None,
        "guides": None,
    }
    for key, (part, name, convert) in _MOVED_V1.items():
        if key not in parameters:
            continue
        if name is None and parameters[key] in (None, {}):
            del parameters[key]  # the old spelling of "automatic" / "computed"
            continue
        value = convert(parameters[key])
        if value is None:
            continue  # not usable as a setting: stays a loose parameter
        if name is None:
            parts[part] = value
        else:
            parts[part][name] = value
        del parameters[key]
    out = {k: v for k, v in doc.items() if k != "parameters"}
    out.update(
        {"@schema": "case-schema-v2", "format_version": 2, **parts, "parameters": parameters}
    )
    return out


def v2_to_v3(doc: dict[str, Any]) -> dict[str, Any]:
    """Format 2 → 3: the new part ``age_study``, ``null`` (format 2 kept no study)."""
    if "age_study" in doc:
        raise ValueError("a format-2 document has no age_study")
    out = {k: v for k, v in doc.items() if k != "parameters"}
    out.update(
        {
            "@schema": "case-schema-v3",
            "format_version": 3,
            "age_study": None,
            "parameters": doc["parameters"],
        }
    )
    return out


#: ``{from_version: upgrade to from_version + 1}``.
MIGRATIONS: Mapping[int, Migration] = MappingProxyType({0: v0_to_v1, 1: v1_to_v2, 2: v2_to_v3})


def document_version(doc: Mapping[str, Any]) -> int:
    """The ``format_version`` of a decoded ``case.json``; raises if absent or not an integer."""
    version = doc.get("format_version")
    if isinstance(version, bool) or not isinstance(version, int):
        raise MigrationError(f"format_version must be an integer, got {version!r}")
    return version


def migrate(
    doc: Mapping[str, Any], migrations: Mapping[int, Migration] = MIGRATIONS
) -> tuple[dict[str, Any], list[int]]:
    """Upgrade ``doc`` to :data:`CURRENT_VERSION`.

    Returns
    -------
    doc : dict
        A new document (the input is not modified).
    applied : list of int
        The versions migrated from, in order (empty if already current).

    Raises
    ------
    MigrationError
        For a version newer than this software, a missing step, or an old
        document missing fields its version requires.
    """
    version = document_version(doc)
    if version > CURRENT_VERSION:
        raise MigrationError(
            f"format_version {version} was written by a newer version of the software "
            f"(this version reads formats up to {CURRENT_VERSION})"
        )
    current = copy.deepcopy(dict(doc))
    applied: list[int] = []
    while version < CURRENT_VERSION:
        step = migrations.get(version)
        if step is None:
            raise MigrationError(f"no migration from format_version {version}")
        try:
            current = step(current)
        except (KeyError, TypeError, ValueError, AttributeError, IndexError) as error:
            raise MigrationError(
                f"cannot upgrade format_version {version}: {type(error).__name__}: {error}"
            ) from None
        applied.append(version)
        if document_version(current) != version + 1:
            raise MigrationError(f"migration from {version} did not produce {version + 1}")
        version += 1
    return current, applied
