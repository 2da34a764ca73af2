"""Landmark exchange formats: 3D Slicer ``.mrk.json`` / ``.fcsv``, MeshLab ``.pp``, CSV.

Units and frames
----------------
Positions are mm in the frame of the mesh the points sit on, taken to be 3D
Slicer's RAS world frame (mesh and landmarks overlay in Slicer).  Slicer files
may store LPS (x, y negated; Slicer 5's default): readers honour the file's
system, writers use LPS unless ``coordinate_system="RAS"``.  The flip is exact
and floats are written with ``repr``, so write → read is exact.  MeshLab
``.pp`` and the CSV hold mesh coordinates as they are.

Readers turn labels into catalogue codes (:meth:`LandmarkCatalogue.normalise`);
unknown labels, repeated codes and undefined points (Slicer ``positionStatus``
not ``"defined"``, MeshLab ``active="0"``, status ``absent``/``missing``) are
skipped and reported by name, undefined ones kept without position when
``allow_undefined=True``; ``strict=True`` raises :class:`LandmarkError`
instead.  A file that cannot be parsed raises :class:`InputError` naming it.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import NamedTuple

import numpy as np

from workbench.core.errors import InputError, LandmarkError
from workbench.core.landmarks import DEFINED_STATUSES, STATUSES, Landmark, LandmarkSet
from workbench.io.catalogue import LandmarkCatalogue, load_catalogue

MRK_SCHEMA = (
    "https://raw.githubusercontent.com/slicer/slicer/master/Modules/Loadable/Markups/"
    "Resources/Schema/markups-schema-v1.0.3.json#"
)
FCSV_VERSION = "4.11"
FCSV_COLUMNS = (
    "id",
    "x",
    "y",
    "z",
    "ow",
    "ox",
    "oy",
    "oz",
    "vis",
    "sel",
    "lock",
    "label",
    "desc",
    "associatedNodeID",
    "status",
    "confidence",
)
CSV_COLUMNS = ("code", "x_mm", "y_mm", "z_mm", "status", "confidence", "description")
KEY = (
    "workbench"  #: extra .mrk.json key for status/confidence (Slicer ignores it, drops it on save)
)
_FLIP = {"RAS": np.array([1.0, 1.0, 1.0]), "LPS": np.array([-1.0, -1.0, 1.0])}
PathLike = str | os.PathLike[str]


@dataclass(frozen=True)
class LandmarkReadResult:
    """What a landmark file held, and what was left out.

    Attributes
    ----------
    landmarks : LandmarkSet
        Recognised points (mm, mesh/RAS frame), in file order.
    unknown, duplicates, undefined : tuple of str
        Labels as written in the file: not in the catalogue; a code seen
        before (first one kept); without a defined position.
    messages : tuple of str
        Human-readable notes for the user.
    coordinate_system : str
        ``"RAS"`` or ``"LPS"`` as stored in the file.
    """

    landmarks: LandmarkSet
    unknown: tuple[str, ...] = ()
    duplicates: tuple[str, ...] = ()
    undefined: tuple[str, ...] = ()
    messages: tuple[str, ...] = ()
    coordinate_system: str = "RAS"


class _Point(NamedTuple):
    label: str
    position: np.ndarray | None  # internal frame (mm); None when the file has none
    defined: bool
    status: str | None
    confidence: float | None
    description: str


# ------------------------------------------------------------------ common
def _read_text(path: Path) -> str:
    try:
        with open(path, encoding="utf-8-sig", newline="") as fh:  # keep \r in descriptions
            return fh.read()
    except UnicodeDecodeError:
        raise InputError(path, "not a text file (cannot decode as UTF-8)") from None
    except OSError as exc:
        missing = isinstance(exc, FileNotFoundError)
        raise InputError(
            path, "file not found" if missing else f"cannot read ({exc.strerror})"
        ) from None


def _write_text(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    try:
        tmp.write_text(text, encoding="utf-8", newline="\n")
        os.replace(tmp, path)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise InputError(path, f"cannot write ({exc.strerror})") from None


def _number(path: Path, what: str, value: object, optional: bool = False) -> float | None:
    if optional and value in (None, ""):
        return None
    try:
        number = math.nan if isinstance(value, bool) else float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        number = math.nan
    if not math.isfinite(number):
        raise InputError(path, f"{what}: expected a finite number, got {value!r}")
    return number


def _text_point(
    path: Path,
    label: str,
    values: list,
    status: object,
    confidence: object,
    description: str,
    active: bool = True,
    flip: np.ndarray = _FLIP["RAS"],
) -> _Point:
    """A point from text fields; coordinates are parsed only when the point is defined."""
    status = _status(path, label, status)
    blank = [str(v or "").strip().lower() in ("", "nan") for v in values]
    if any(blank) and not all(blank):  # some coordinates given, some not: a damaged row
        shown = ", ".join(str(v) for v in values)
        raise InputError(
            path,
            f"point {label!r}: coordinates ({shown}) are partly missing",
            "give all three numbers, or none for an undefined point",
        )
    defined = active and status in (None, *DEFINED_STATUSES) and not any(blank)
    xyz = (
        np.array([_number(path, f"point {label!r} coordinate", v) for v in values]) * flip
        if defined
        else None
    )
    return _Point(
        label,
        xyz,
        defined,
        status,
        _number(path, f"point {label!r} confidence", confidence, optional=True),
        description,
    )


def _status(path: Path, label: str, value: object) -> str | None:
    if value in (None, ""):
        return None
    if value not in STATUSES:
        raise InputError(
            path,
            f"point {label!r}: unknown status {value!r}",
            hint=f"use one of {', '.join(STATUSES)}",
        )
    return str(value)


def _build(
    path: Path,
    surface: str,
    points: Iterable[_Point],
    catalogue: LandmarkCatalogue | None,
    allow_undefined: bool,
    strict: bool,
    messages: list[str],
    coordinate_system: str = "RAS",
) -> LandmarkReadResult:
    cat = catalogue if catalogue is not None else load_catalogue()
    kept: list[Landmark] = []
    unknown, duplicates, undefined, seen = [], [], [], set()
    for pt in points:
        try:
            code = cat.normalise(pt.label, surface)
        except LandmarkError:
            unknown.append(pt.label)
            continue
        if code in seen:
            duplicates.append(pt.label)
            continue
        seen.add(code)
        conf = 1.0 if pt.confidence is None else pt.confidence
        if not (pt.defined and pt.position is not None):
            undefined.append(pt.label)
            if not allow_undefined:
                continue
        if pt.position is not None and (pt.defined or pt.status in DEFINED_STATUSES):  # + "preview"
            status = pt.status if pt.status in DEFINED_STATUSES else "placed"
            kept.append(Landmark(code, pt.position, status, conf, pt.description))
        else:
            status = pt.status if pt.status in ("absent", "missing") else "missing"
            kept.append(Landmark(code, np.full(3, np.nan), status, conf, pt.description))
    how = "kept without position" if allow_undefined else "skipped"
    for names, text in (
        (unknown, f"not in the {surface} landmark catalogue, skipped"),
        (duplicates, "repeated landmark(s), first one kept"),
        (undefined, f"undefined point(s) {how}"),
    ):
        if names:
            messages.append(f"{text}: {', '.join(names)}")
    if strict and (unknown or duplicates or (undefined and not allow_undefined)):
        raise LandmarkError(f"{path}: " + "; ".join(messages))
    return LandmarkReadResult(
        LandmarkSet(surface, tuple(kept)),
        tuple(unknown),
        tuple(duplicates),
        tuple(undefined),
        tuple(messages),
        coordinate_system,
    )


def _split_header(text: str) -> tuple[list[str], str]:
    """Leading ``#`` comment lines, and the rest of the text (CSV body)."""
    lines = text.splitlines(keepends=True)
    n = next((i for i, ln in enumerate(lines) if ln.strip() and not ln.startswith("#")), len(lines))
    return [ln.rstrip("\r\n") for ln in lines[:n]], "".join(lines[n:])


def _csv_line(values: Iterable[object]) -> str:
    """One CSV record; quotes fields with ``, " CR LF`` (csv.writer leaves a lone CR bare)."""
    fields = [str(v) for v in values]
    return (
        ",".join(
            '"' + v.replace('"', '""') + '"' if any(c in v for c in ',"\r\n') else v for v in fields
        )
        + "\n"
    )


def _csv_rows(path: Path, body: str) -> list[list[str]]:
    try:
        return [row for row in csv.reader(io.StringIO(body, newline="")) if any(row)]
    except csv.Error as exc:
        raise InputError(path, f"not a readable CSV table ({exc})") from None


def _coordinate_system(value: object, path: Path | None = None) -> str:
    """``"RAS"`` / ``"LPS"`` from a file's value (``0`` / ``1`` in old .fcsv) or an argument."""
    mapped = {"RAS": "RAS", "0": "RAS", "LPS": "LPS", "1": "LPS"}.get(str(value).strip().upper())
    if mapped is None:
        if path is None:
            raise ValueError(f"coordinate_system must be 'LPS' or 'RAS', got {value!r}")
        raise InputError(
            path, f"unsupported coordinate system {value!r}", hint="expected LPS or RAS"
        )
    return mapped


# ------------------------------------------------------------- .mrk.json
def read_mrk_json(
    path: PathLike,
    surface: str,
    catalogue: LandmarkCatalogue | None = None,
    allow_undefined: bool = False,
    strict: bool = False,
) -> LandmarkReadResult:
    """Read a 3D Slicer markups point list (``.mrk.json``) into mesh/RAS mm."""
    path = Path(path)
    try:
        doc = json.loads(_read_text(path))
    except json.JSONDecodeError as exc:
        raise InputError(
            path,
            f"not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})",
            hint="the file may be truncated or not a Slicer markups file",
        ) from None
    if not isinstance(doc, dict) or not isinstance(doc.get("markups"), list):
        raise InputError(path, "not a 3D Slicer markups file (no 'markups' list)")
    lists = [m for m in doc["markups"] if isinstance(m, dict) and m.get("type") == "Fiducial"]
    if not lists:
        raise InputError(path, "no point list (markups type 'Fiducial') in the file")
    messages = [f"{len(lists)} point lists in the file; only the first was read"][: len(lists) - 1]
    mk = lists[0]
    cs = _coordinate_system(mk.get("coordinateSystem", "LPS"), path)
    units = mk.get("coordinateUnits", "mm")
    if (units[0] if isinstance(units, list) and units else units) != "mm":
        raise InputError(
            path, f"coordinates are in {units!r}", hint="convert the points to mm first"
        )
    info = mk.get(KEY)
    if not isinstance(info, dict):
        info = {}
    if info.get("surface") not in (None, surface):
        messages.append(f"file holds {info['surface']} landmarks, read as {surface}")
    points, cps = [], mk.get("controlPoints", [])
    if not isinstance(cps, list) or not all(isinstance(cp, dict) for cp in cps):
        raise InputError(path, "'controlPoints' must be a list of JSON objects")
    for i, cp in enumerate(cps, start=1):
        label, pos = str(cp.get("label") or f"<unnamed point {i}>"), cp.get("position")
        if pos is not None and (not isinstance(pos, list) or len(pos) != 3):
            raise InputError(path, f"point {label!r}: position must be 3 numbers")
        position = (
            None
            if pos is None
            else _FLIP[cs] * np.array([_number(path, f"point {label!r} position", v) for v in pos])
        )
        extra = cp.get(KEY) if isinstance(cp.get(KEY), dict) else {}
        state = cp.get("positionStatus", "defined")
        status = _status(path, label, extra.get("status"))
        if state == "preview" and status is None:
            status = "suggested"
        conf = _number(path, f"point {label!r} confidence", extra.get("confidence"), optional=True)
        points.append(
            _Point(
                label, position, state == "defined", status, conf, str(cp.get("description") or "")
            )
        )
    return _build(path, surface, points, catalogue, allow_undefined, strict, messages, cs)


def write_mrk_json(
    path: PathLike, landmark_set: LandmarkSet, coordinate_system: str = "LPS"
) -> None:
    """Write a Slicer 5 markups point list; undefined points get positionStatus ``"undefined"``."""
    cs = _coordinate_system(coordinate_system)
    flip = _FLIP[cs]
    orientation = [float(v) for v in np.diag(flip).ravel()]
    points = []
    for i, lm in enumerate(landmark_set, start=1):
        pos = [float(v) for v in lm.position * flip] if lm.is_defined else [0.0, 0.0, 0.0]
        points.append(
            {
                "id": str(i),
                "label": lm.code,
                "description": lm.description,
                "associatedNodeID": "",
                "position": pos,
                "orientation": orientation,
                "selected": True,
                "locked": False,
                "visibility": lm.is_defined,
                "positionStatus": "defined" if lm.is_defined else "undefined",
                KEY: {"status": lm.status, "confidence": lm.confidence},
            }
        )
    markup = {
        "type": "Fiducial",
        "name": f"{landmark_set.surface} landmarks",
        "coordinateSystem": cs,
        "coordinateUnits": "mm",
        "locked": False,
        "fixedNumberOfControlPoints": False,
        "labelFormat": "%N-%d",
        "lastUsedControlPointNumber": len(points),
        "controlPoints": points,
        "measurements": [],
        KEY: {"surface": landmark_set.surface, "frame": "mesh coordinates = Slicer RAS world"},
    }
    doc = {"@schema": MRK_SCHEMA, "markups": [markup]}
    _write_text(Path(path), json.dumps(doc, indent=4, ensure_ascii=False, allow_nan=False) + "\n")


# ------------------------------------------------------------------ .fcsv
def read_fcsv(
    path: PathLike,
    surface: str,
    catalogue: LandmarkCatalogue | None = None,
    allow_undefined: bool = False,
    strict: bool = False,
) -> LandmarkReadResult:
    """Read a legacy Slicer fiducial list (``.fcsv``); ``CoordinateSystem`` 0/RAS or 1/LPS."""
    path = Path(path)
    header, body = _split_header(_read_text(path))
    settings = {
        k.strip(): v.strip() for k, sep, v in (ln[1:].partition("=") for ln in header) if sep
    }
    cs = _coordinate_system(settings.get("CoordinateSystem", "RAS"), path)
    messages = (
        []
        if "CoordinateSystem" in settings
        else ["no CoordinateSystem line; assumed RAS as old Slicer versions do"]
    )
    columns = [c.strip() for c in settings.get("columns", ",".join(FCSV_COLUMNS[:14])).split(",")]
    missing = [c for c in ("x", "y", "z", "label") if c not in columns]
    if missing:
        raise InputError(path, f"columns line lacks {', '.join(missing)}")
    points = []
    for n, row in enumerate(_csv_rows(path, body), start=1):
        rec = dict(zip(columns, row, strict=False))
        label = rec.get("label") or f"<unnamed point {n}>"
        points.append(
            _text_point(
                path,
                label,
                [rec.get(c) for c in "xyz"],
                rec.get("status"),
                rec.get("confidence"),
                rec.get("desc", ""),
                flip=_FLIP[cs],
            )
        )
    return _build(path, surface, points, catalogue, allow_undefined, strict, messages, cs)


def write_fcsv(path: PathLike, landmark_set: LandmarkSet, coordinate_system: str = "LPS") -> None:
    """Write a Slicer 4.11-style ``.fcsv`` with two extra columns, ``status`` and ``confidence``."""
    cs = _coordinate_system(coordinate_system)
    lines = [
        f"# Markups fiducial file version = {FCSV_VERSION}\n# CoordinateSystem = {cs}\n"
        f"# columns = {','.join(FCSV_COLUMNS)}\n"
    ]
    for i, lm in enumerate(landmark_set):
        xyz = lm.position * _FLIP[cs] if lm.is_defined else np.zeros(3)
        lines.append(
            _csv_line(
                [
                    f"vtkMRMLMarkupsFiducialNode_{i}",
                    *(repr(float(v)) for v in xyz),
                    0,
                    0,
                    0,
                    1,
                    int(lm.is_defined),
                    1,
                    0,
                    lm.code,
                    lm.description,
                    "",
                    lm.status,
                    repr(lm.confidence),
                ]
            )
        )
    _write_text(Path(path), "".join(lines))


# -------------------------------------------------------------------- .pp
def _unescape(text: str, own: bool) -> str:
    """Undo write_pp's JSON-style escapes (XML 1.0 cannot hold control characters)."""
    try:
        return json.loads(f'"{text}"') if own else text
    except ValueError:
        return text


def read_pp(
    path: PathLike,
    surface: str,
    catalogue: LandmarkCatalogue | None = None,
    allow_undefined: bool = False,
    strict: bool = False,
) -> LandmarkReadResult:
    """Read MeshLab PickedPoints (``.pp``); mesh coordinates, ``active="0"`` = undefined."""
    path = Path(path)
    try:
        root = ET.fromstring(_read_text(path))
    except ET.ParseError as exc:
        raise InputError(path, f"broken XML ({exc})", hint="not a MeshLab .pp file?") from None
    if root.tag != "PickedPoints":
        raise InputError(path, f"not a MeshLab PickedPoints file (root element <{root.tag}>)")
    points = []
    for n, el in enumerate(root.iter("point"), start=1):
        label = el.get("name") or f"<unnamed point {n}>"
        active = el.get("active", "1").strip() not in ("0", "false")
        own = el.get("status") is not None
        points.append(
            _text_point(
                path,
                label,
                [el.get(c) for c in "xyz"],
                el.get("status"),
                el.get("confidence"),
                _unescape(el.get("description", ""), own),
                active=active,
            )
        )
    return _build(path, surface, points, catalogue, allow_undefined, strict, [])


def write_pp(path: PathLike, landmark_set: LandmarkSet, mesh_file: str = "") -> None:
    """Write MeshLab PickedPoints in mesh coordinates; extra attributes keep status etc."""
    root = ET.Element("PickedPoints")
    doc, now = ET.SubElement(root, "DocumentData"), datetime.now()
    ET.SubElement(doc, "DateTime", date=now.strftime("%Y-%m-%d"), time=now.strftime("%H:%M:%S"))
    for tag, name in (
        ("User", "forensic-workbench"),
        ("DataFileName", mesh_file),
        ("templateName", ""),
    ):
        ET.SubElement(doc, tag, name=name)
    for lm in landmark_set:
        xyz = lm.position if lm.is_defined else np.zeros(3)
        ET.SubElement(
            root,
            "point",
            x=repr(float(xyz[0])),
            y=repr(float(xyz[1])),
            z=repr(float(xyz[2])),
            active="1" if lm.is_defined else "0",
            name=lm.code,
            status=lm.status,
            confidence=repr(lm.confidence),
            description=json.dumps(lm.description, ensure_ascii=False)[1:-1],
        )
    ET.indent(root, space=" ")
    _write_text(
        Path(path), "<!DOCTYPE PickedPoints>\n" + ET.tostring(root, encoding="unicode") + "\n"
    )


# -------------------------------------------------------------------- .csv
def read_csv(
    path: PathLike,
    surface: str,
    catalogue: LandmarkCatalogue | None = None,
    allow_undefined: bool = False,
    strict: bool = False,
) -> LandmarkReadResult:
    """Read ``code,x_mm,y_mm,z_mm[,status,confidence,description]`` (also ``name``/``label``, ``x``)."""
    path = Path(path)
    header, body = _split_header(_read_text(path))
    units = [ln.split("units:", 1)[1].split(";")[0].strip() for ln in header if "units:" in ln]
    if any(u != "mm" for u in units):
        raise InputError(
            path,
            f"coordinates are in {next(u for u in units if u != 'mm')!r}",
            hint="convert the points to mm first",
        )
    table = _csv_rows(path, body)
    names = [c.strip() for c in table[0]] if table else []
    rows = [dict(zip(names, r, strict=False)) for r in table[1:]]
    fields = set(names)
    label_col = next((c for c in ("code", "label", "name") if c in fields), None)
    found = [next((c for c in (f"{a}_mm", a) if c in fields), None) for a in "xyz"]
    xyz_cols = [c for c in found if c is not None]
    if not table:
        return _build(path, surface, [], catalogue, allow_undefined, strict, [])
    if label_col is None or len(xyz_cols) != 3:
        raise InputError(path, "needs columns code (or label/name) and x_mm, y_mm, z_mm")
    points = []
    for n, row in enumerate(rows, start=1):
        label = (row.get(label_col) or "").strip() or f"<unnamed point {n}>"
        status, conf = ((row.get(c) or "").strip() for c in ("status", "confidence"))
        points.append(
            _text_point(
                path,
                label,
                [row.get(c) for c in xyz_cols],
                status,
                conf,
                row.get("description") or "",
            )
        )
    return _build(path, surface, points, catalogue, allow_undefined, strict, [])


def write_csv(
    path: PathLike, landmark_set: LandmarkSet, frame: str = "mesh coordinates (Slicer RAS world)"
) -> None:
    """Write the plain CSV with a ``# units: mm; frame: ...`` comment line."""
    lines = [
        f"# units: mm; frame: {frame}; surface: {landmark_set.surface}\n",
        _csv_line(CSV_COLUMNS),
    ]
    for lm in landmark_set:
        xyz = [repr(float(v)) for v in lm.position] if lm.is_defined else ["", "", ""]
        lines.append(_csv_line([lm.code, *xyz, lm.status, repr(lm.confidence), lm.description]))
    _write_text(Path(path), "".join(lines))


# --------------------------------------------------------------- dispatch
FORMATS: dict[str, tuple[Callable[..., LandmarkReadResult], Callable[..., None]]] = {
    ".mrk.json": (read_mrk_json, write_mrk_json),
    ".json": (read_mrk_json, write_mrk_json),
    ".fcsv": (read_fcsv, write_fcsv),
    ".pp": (read_pp, write_pp),
    ".csv": (read_csv, write_csv),
}


def _format(path: Path) -> tuple[Callable[..., LandmarkReadResult], Callable[..., None]]:
    name = path.name.lower()
    for ext in sorted(FORMATS, key=len, reverse=True):
        if name.endswith(ext):
            return FORMATS[ext]
    raise InputError(path, "unknown landmark file type", hint=f"use one of {', '.join(FORMATS)}")


def read_landmarks(path: PathLike, surface: str, **kwargs) -> LandmarkReadResult:
    """Read any supported landmark file, chosen by extension (see module doc)."""
    return _format(Path(path))[0](path, surface, **kwargs)


def write_landmarks(path: PathLike, landmark_set: LandmarkSet, **kwargs) -> None:
    """Write any supported landmark file, chosen by extension; kwargs go to the writer."""
    _format(Path(path))[1](path, landmark_set, **kwargs)
