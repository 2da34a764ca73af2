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
    Current layout, see ``data_tables/schemas/case.schema.json``.
"""

from __future__ import annotations

import copy
from collections.abc import Callable, Mapping
from types import MappingProxyType
from typing import Any

CURRENT_VERSION = 1
SCHEMA_ID = "case-schema-v1"

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
        "@schema": SCHEMA_ID,
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


#: ``{from_version: upgrade to from_version + 1}``.
MIGRATIONS: Mapping[int, Migration] = MappingProxyType({0: v0_to_v1})


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
