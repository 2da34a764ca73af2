"""Landmark exchange formats: 3D Slicer ``.mrk.json`` / ``.fcsv``, MeshLab ``.pp``, CSV.

Units and frames
----------------
Positions are mm in the frame of the mesh the points sit on, taken to be 3D
Slicer's RAS world frame: the workbench's mesh writers tag their files
``SPACE=RAS`` (:mod:`workbench.io.meshes`), so mesh and landmarks overlay when
Slicer loads both.  Slicer files may store LPS (x, y negated; Slicer 5's
default): readers honour the file's system, writers use LPS unless
``coordinate_system="RAS"``.  The flip is exact and floats are written with
``repr``, so write → read is exact.  MeshLab ``.pp`` and the CSV hold mesh
coordinates as they are.  A reconstruction's landmark files are written in
:data:`OUTPUT_SYSTEM` (RAS), the frame its report names for its positions
(:data:`OUTPUT_FRAME`, said once: in the ``.fcsv`` ``CoordinateSystem`` line,
the ``.mrk.json`` ``coordinateSystem`` and ``workbench.frame`` fields, and the
report's landmark section).

Slicer 5 point states
---------------------
Slicer keeps a ``positionStatus`` per control point: undefined (0), preview
(1), defined (2) or missing (3, "skip this point").  ``.mrk.json`` stores the
name, ``.fcsv`` the number in the 15th field (after ``associatedNodeID``; the
16th is ``autoCreated``; Slicer reads the fields by position and ignores the
``# columns`` line).  Placed and suggested points are written as defined,
absent and missing ones as missing (no position).  The workbench's own status
and confidence travel in the point's description, after the user's text, as
``[workbench: suggested; confidence 0.35]``: Slicer shows and keeps it.  On
reading, Slicer's state decides whether a point has a position (a point the
user placed in Slicer is "placed" even if the description still says
"missing"); the description's status and confidence fill in the rest.

Readers turn labels into catalogue codes (:meth:`LandmarkCatalogue.normalise`);
unknown labels, repeated codes and undefined points (Slicer state not defined,
MeshLab ``active="0"``, status ``absent``/``missing``) are skipped and
reported by name, undefined ones kept without position when
``allow_undefined=True``; ``strict=True`` raises :class:`LandmarkError`
instead.  A file that cannot be parsed raises :class:`InputError` naming it;
``.mrk.json`` goes through :func:`workbench.core.json_limits.read_json`
(size and nesting limits).
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import re
import xml.etree.ElementTree as ET
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import NamedTuple

import numpy as np

from workbench.core.errors import InputError, LandmarkError
from workbench.core.json_limits import read_json
from workbench.core.landmarks import DEFINED_STATUSES, STATUSES, Landmark, LandmarkSet
from workbench.core.table_cells import FORMULA_STARTS, csv_cell
from workbench.io.catalogue import LandmarkCatalogue, load_catalogue

MRK_SCHEMA = (
    "https://raw.githubusercontent.com/slicer/slicer/master/Modules/Loadable/Markups/"
    "Resources/Schema/markups-schema-v1.0.3.json#"
)
FCSV_VERSION = "5.6"  #: the Slicer version whose .fcsv layout is written
#: Slicer's own ``.fcsv`` fields, in the order Slicer 5 reads them (by position)
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
    "positionStatus",
    "autoCreated",
)
#: what Slicer 4 writes and Slicer 5 still writes on its ``# columns`` line
_FCSV_LEGACY_COLUMNS = FCSV_COLUMNS[:14]
#: Slicer's vtkMRMLMarkupsNode position states: .fcsv number -> .mrk.json name
POSITION_STATES = {0: "undefined", 1: "preview", 2: "defined", 3: "missing"}
_NOTE = re.compile(
    r"(?:^| )\[workbench: (?P<status>[a-z]+); confidence (?P<conf>[^\]\s]+)\]\Z", re.DOTALL
)
CSV_COLUMNS = ("code", "x_mm", "y_mm", "z_mm", "status", "confidence", "description")
KEY = (
    "workbench"  #: extra .mrk.json key for status/confidence (Slicer ignores it, drops it on save)
)
_FLIP = {"RAS": np.array([1.0, 1.0, 1.0]), "LPS": np.array([-1.0, -1.0, 1.0])}
#: the coordinate system of the landmark files a reconstruction writes
#: (``skull_landmarks.mrk.json`` / ``.fcsv``), the same as its meshes' ``SPACE`` tag
OUTPUT_SYSTEM = "RAS"
#: that frame's name, as the report's landmark section gives it
OUTPUT_FRAME_NAME = "RAS (3D Slicer's world frame), mm"
#: that frame in words, as ``report.json`` states it for its positions and directions and
#: the ``.mrk.json`` file in its header
OUTPUT_FRAME = (
    f"{OUTPUT_FRAME_NAME}: the skull file's coordinates as the workbench reads them (a mesh "
    "tagged SPACE=LPS with x and y negated), so they lie on the skull in Slicer"
)
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


def _with_note(description: str, status: str, confidence: float) -> str:
    """The description Slicer shows: the user's text, then the workbench's status note."""
    note = f"[workbench: {status}; confidence {float(confidence)!r}]"
    return f"{description} {note}" if description else note


def _split_note(description: str) -> tuple[str, str | None, float | None]:
    """``(user's text, status, confidence)`` from a description :func:`_with_note` wrote.

    A description without a (valid) note comes back whole, with None, None.
    """
    m = _NOTE.search(description)
    if m is None or m["status"] not in STATUSES:
        return description, None, None
    try:
        confidence = float(m["conf"])
    except ValueError:
        return description, None, None
    if not math.isfinite(confidence):
        return description, None, None
    return description[: m.start()], m["status"], confidence


def _slicer_point(
    label: str,
    position: np.ndarray | None,
    state: str,
    description: str,
    status: str | None = None,
    confidence: float | None = None,
) -> _Point:
    """A point from Slicer's state (a :data:`POSITION_STATES` name) and its description.

    Slicer's state decides whether the point has a position: only "defined"
    and "preview" points keep theirs (an undefined or missing point's numbers
    are never used).  ``status``/``confidence`` (the workbench's own fields,
    when the file kept them) win over the description's note.
    """
    text, note_status, note_conf = _split_note(description)
    status = note_status if status is None else status
    confidence = note_conf if confidence is None else confidence
    if state in ("defined", "preview") and position is not None:
        if status not in DEFINED_STATUSES:  # placed (or moved) in Slicer
            status = "placed" if state == "defined" else "suggested"
        return _Point(label, position, state == "defined", status, confidence, text)
    if status not in ("absent", "missing"):
        status = "missing"
    return _Point(label, None, False, status, confidence, text)


def _frame_note(system: str) -> str:
    """The ``.mrk.json`` header's words for the frame of the positions written in ``system``."""
    if system == OUTPUT_SYSTEM:
        return OUTPUT_FRAME
    return f"{system}, mm: the mesh coordinates (Slicer's RAS world) with x and y negated"


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
    if not path.is_file():
        raise InputError(
            path, "is a folder, not a landmark file" if path.is_dir() else "file not found"
        )
    doc = read_json(path, what="landmark file")
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
    names = tuple(POSITION_STATES.values())
    for i, cp in enumerate(cps, start=1):
        label, pos = str(cp.get("label") or f"<unnamed point {i}>"), cp.get("position")
        state = cp.get("positionStatus", "defined")
        if state not in names:
            raise InputError(
                path,
                f"point {label!r}: unknown positionStatus {state!r}",
                hint=f"Slicer writes one of {', '.join(names)}",
            )
        position = None
        if state in ("defined", "preview") and pos not in (None, ""):  # Slicer writes "" for none
            if not isinstance(pos, list) or len(pos) != 3:
                raise InputError(path, f"point {label!r}: position must be 3 numbers")
            xyz = [_number(path, f"point {label!r} position", v) for v in pos]
            position = _FLIP[cs] * np.array(xyz)
        extra = cp.get(KEY) if isinstance(cp.get(KEY), dict) else {}
        status = _status(path, label, extra.get("status"))
        conf = _number(path, f"point {label!r} confidence", extra.get("confidence"), optional=True)
        text = str(cp.get("description") or "")
        points.append(_slicer_point(label, position, state, text, status, conf))
    return _build(path, surface, points, catalogue, allow_undefined, strict, messages, cs)


def write_mrk_json(
    path: PathLike, landmark_set: LandmarkSet, coordinate_system: str = "LPS"
) -> None:
    """Write a Slicer 5 markups point list.

    Placed and suggested points are ``"defined"``; absent and missing ones
    ``"missing"`` without a position (as Slicer writes them).  Status and
    confidence go into each point's description (see the module doc) and
    into the ``workbench`` key.
    """
    cs = _coordinate_system(coordinate_system)
    flip = _FLIP[cs]
    orientation = [float(v) for v in np.diag(flip).ravel()]
    points = []
    for i, lm in enumerate(landmark_set, start=1):
        pos = [float(v) for v in lm.position * flip] if lm.is_defined else ""
        points.append(
            {
                "id": str(i),
                "label": lm.code,
                "description": _with_note(lm.description, lm.status, lm.confidence),
                "associatedNodeID": "",
                "position": pos,
                "orientation": orientation,
                "selected": True,
                "locked": False,
                "visibility": lm.is_defined,
                "positionStatus": "defined" if lm.is_defined else "missing",
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
        KEY: {"surface": landmark_set.surface, "frame": _frame_note(cs)},
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
    """Read a Slicer fiducial list (``.fcsv``); ``CoordinateSystem`` 0/RAS or 1/LPS.

    Slicer 5's ``positionStatus`` field (the 15th) decides which points have a
    position; files without it (Slicer 4, the workbench's older files with
    ``status``/``confidence`` columns) count every point with numbers as
    defined, as Slicer does.
    """
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
    columns = [c.strip() for c in settings.get("columns", ",".join(FCSV_COLUMNS)).split(",")]
    if tuple(columns) == _FCSV_LEGACY_COLUMNS:
        # Slicer 5 still names 14 columns but writes and reads 16 fields, by position
        columns = list(FCSV_COLUMNS)
    missing = [c for c in ("x", "y", "z", "label") if c not in columns]
    if missing:
        raise InputError(path, f"columns line lacks {', '.join(missing)}")
    points = []
    for n, row in enumerate(_csv_rows(path, body), start=1):
        rec = dict(zip(columns, row, strict=False))
        label = rec.get("label") or f"<unnamed point {n}>"
        state = _fcsv_state(path, label, rec.get("positionStatus"))
        if state is None:  # no Slicer 5 state: the older layouts
            text, note_status, note_conf = _split_note(rec.get("desc", ""))
            points.append(
                _text_point(
                    path,
                    label,
                    [rec.get(c) for c in "xyz"],
                    rec.get("status") or note_status,
                    rec.get("confidence") or note_conf,
                    text,
                    flip=_FLIP[cs],
                )
            )
            continue
        position = None
        if state in ("defined", "preview"):
            xyz = [_number(path, f"point {label!r} coordinate", rec.get(c)) for c in "xyz"]
            position = np.array(xyz) * _FLIP[cs]
        points.append(
            _slicer_point(
                label,
                position,
                state,
                rec.get("desc", ""),
                _status(path, label, rec.get("status")),
                _number(path, f"point {label!r} confidence", rec.get("confidence"), optional=True),
            )
        )
    return _build(path, surface, points, catalogue, allow_undefined, strict, messages, cs)


def _fcsv_state(path: Path, label: str, value: str | None) -> str | None:
    """The :data:`POSITION_STATES` name of an ``.fcsv`` positionStatus field (None: no field)."""
    if value is None or not value.strip():
        return None
    try:
        return POSITION_STATES[int(value.strip())]
    except (ValueError, KeyError):
        states = ", ".join(f"{k} ({v})" for k, v in POSITION_STATES.items())
        raise InputError(
            path,
            f"point {label!r}: positionStatus {value!r} is not a Slicer point state",
            hint=f"Slicer 5 writes one of {states}",
        ) from None


def write_fcsv(path: PathLike, landmark_set: LandmarkSet, coordinate_system: str = "LPS") -> None:
    """Write a Slicer 5 ``.fcsv``: Slicer's 16 fields, positionStatus 2 (defined) or 3 (missing).

    Status and confidence go into the ``desc`` field (see the module doc);
    missing points are written at 0, 0, 0 with positionStatus 3, which tells
    Slicer 5 (and :func:`read_fcsv`) that the numbers are not a position.
    """
    cs = _coordinate_system(coordinate_system)
    lines = [
        f"# Markups fiducial file version = {FCSV_VERSION}\n# CoordinateSystem = {cs}\n"
        f"# columns = {','.join(FCSV_COLUMNS)}\n"
    ]
    for i, lm in enumerate(landmark_set, start=1):
        xyz = lm.position * _FLIP[cs] if lm.is_defined else np.zeros(3)
        lines.append(
            _csv_line(
                [
                    str(i),
                    *(repr(float(v)) for v in xyz),
                    0,
                    0,
                    0,
                    1,
                    int(lm.is_defined),
                    1,
                    0,
                    lm.code,
                    _with_note(lm.description, lm.status, lm.confidence),
                    "",
                    2 if lm.is_defined else 3,
                    0,
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
                _unguarded(row.get("description") or ""),
            )
        )
    return _build(path, surface, points, catalogue, allow_undefined, strict, [])


def _unguarded(text: str) -> str:
    """A description as written before :func:`write_csv` guarded it (its ``'`` taken off)."""
    return text[1:] if text[:1] == "'" and text[1:2] in FORMULA_STARTS and text[1:] else text


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
        # a description is free text: one that would start a spreadsheet formula is guarded
        desc = csv_cell(lm.description)
        lines.append(_csv_line([lm.code, *xyz, lm.status, repr(lm.confidence), desc]))
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
