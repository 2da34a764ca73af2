"""NRRD reader (``.nrrd`` with attached data, ``.nhdr`` with detached data).

Implements the parts of the NRRD0001-0005 format that scalar 3-D medical
volumes use (http://teem.sourceforge.net/nrrd/format.html):

* ``type`` (all integer and floating point spellings), ``dimension: 3``,
  ``sizes`` (x fastest), ``endian``, ``encoding`` raw / gzip / bzip2 /
  ascii / hex, ``byte skip`` (-1 = data at end of a raw file), ``line skip``;
* ``data file``: a single name, a numbered pattern
  ``data file: quarter.%d 1 93 1`` or ``data file: LIST`` followed by one
  name per line;
* geometry from ``space`` + ``space directions`` + ``space origin``
  (``space units`` scaled to mm), else ``spacings`` (+ ``axis mins``).

Frames: ``left-posterior-superior`` -> LPS, ``right-anterior-superior`` ->
RAS, ``left-anterior-superior`` is converted to LPS.  Spaces without
anatomical meaning (``3D-left-handed``, ``3D-right-handed``,
``scanner-xyz`` or none) are taken as LPS with the identity mapping;
``metadata["frame_assumed"]`` is then True and a warning is recorded.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from workbench.core.errors import InputError
from workbench.core.volume import Volume

from ._common import (
    ENCODINGS,
    DataSpec,
    check_sizes,
    expand_file_pattern,
    open_header,
    parse_floats,
    read_block,
)

_TYPES: dict[str, str] = {}
for _names, _dt in [
    ("signed char|int8|int8_t", "i1"),
    ("uchar|unsigned char|uint8|uint8_t", "u1"),
    ("short|short int|signed short|signed short int|int16|int16_t", "i2"),
    ("ushort|unsigned short|unsigned short int|uint16|uint16_t", "u2"),
    ("int|signed int|int32|int32_t", "i4"),
    ("uint|unsigned int|uint32|uint32_t", "u4"),
    ("longlong|long long|long long int|signed long long|signed long long int|int64|int64_t", "i8"),
    ("ulonglong|unsigned long long|unsigned long long int|uint64|uint64_t", "u8"),
    ("float", "f4"),
    ("double", "f8"),
]:
    for _name in _names.split("|"):
        _TYPES[_name] = _dt

_SPACES = {
    "left-posterior-superior": "LPS",
    "lps": "LPS",
    "right-anterior-superior": "RAS",
    "ras": "RAS",
    "left-anterior-superior": "LAS",
    "las": "LAS",
    "scanner-xyz": None,
    "3d-right-handed": None,
    "3d-left-handed": None,
}
_UNITS_TO_MM = {
    "mm": 1.0,
    "millimeter": 1.0,
    "millimeters": 1.0,
    "cm": 10.0,
    "m": 1000.0,
    "um": 1e-3,
    "µm": 1e-3,
    "micron": 1e-3,
    "microns": 1e-3,
}
_VECTOR = re.compile(r"\(([^)]*)\)|none", re.IGNORECASE)


def parse_nrrd_header(path: Path) -> tuple[dict[str, str], dict[str, str], list[str], int]:
    """Return (fields, key/value pairs, LIST file names, byte offset of attached data).

    Field names are lower-cased with spaces removed (``data file`` -> ``datafile``).
    """
    fh = open_header(path)
    fields: dict[str, str] = {}
    pairs: dict[str, str] = {}
    listed: list[str] = []
    with fh:
        magic = fh.readline(64).decode("latin-1").strip()
        if not re.fullmatch(r"NRRD000[1-9]", magic):
            raise InputError(
                path, f"not a NRRD file (first line is {magic[:20]!r}, expected NRRD000x)"
            )
        in_list = False
        while True:
            raw = fh.readline()
            if not raw:
                break
            line = raw.decode("latin-1").rstrip("\r\n")
            if in_list:
                if not line.strip():
                    break
                listed.append(line.strip())
                continue
            if not line.strip():
                break  # blank line: attached data follow
            if line.startswith("#"):
                continue
            if ":=" in line:
                key, value = line.split(":=", 1)
                pairs[key] = value
                continue
            if ": " not in line and not line.endswith(":"):
                raise InputError(path, f"malformed NRRD header line: {line!r}")
            key, value = line.split(":", 1)
            key = key.strip().lower().replace(" ", "")
            fields[key] = value.strip()
            if key == "datafile" and value.strip().upper().startswith("LIST"):
                in_list = True
        offset = fh.tell()
    return fields, pairs, listed, offset


def _data_spec(path: Path, fields: dict[str, str], listed: list[str], offset: int) -> DataSpec:
    type_name = " ".join(fields.get("type", "").lower().split())
    if type_name not in _TYPES:
        problem = "has no 'type' field" if not type_name else f"has unsupported type {type_name!r}"
        raise InputError(path, f"the NRRD header {problem}")
    dtype = np.dtype(_TYPES[type_name])
    if dtype.itemsize > 1:
        endian = fields.get("endian", "little").lower()
        if endian not in ("little", "big"):
            raise InputError(path, f"unknown endian {endian!r} (expected little or big)")
        dtype = dtype.newbyteorder("<" if endian == "little" else ">")
    encoding = ENCODINGS.get(fields.get("encoding", "").lower())
    if encoding is None or encoding == "zlib":
        raise InputError(
            path,
            f"unsupported NRRD encoding {fields.get('encoding')!r}",
            hint="supported: raw, gzip, bzip2, ascii, hex",
        )
    try:
        byte_skip = int(fields.get("byteskip", "0"))
        line_skip = int(fields.get("lineskip", "0"))
    except ValueError:
        raise InputError(path, "byte skip / line skip must be integers") from None
    datafile = fields.get("datafile")
    if datafile is None:
        files, data_offset = [path], offset
    else:
        data_offset = 0
        parts = datafile.split()
        if parts and parts[0].upper() == "LIST":
            if not listed:
                raise InputError(path, "'data file: LIST' is not followed by any file names")
            files = [path.parent / name for name in listed]
        elif len(parts) >= 4 and "%" in parts[0]:
            try:
                first, last, step = (int(p) for p in parts[1:4])
            except ValueError:
                raise InputError(path, f"bad data file pattern line: {datafile!r}") from None
            files = expand_file_pattern(path, parts[0], first, last, step)
        else:
            files = [path.parent / datafile]
    return DataSpec(files, data_offset, byte_skip, line_skip, encoding, dtype)


def _geometry(path: Path, fields: dict[str, str], warnings: list[str]):
    space_name = fields.get("space", "").strip().lower()
    space_dim = fields.get("spacedimension")
    if space_name and space_name not in _SPACES:
        raise InputError(
            path, f"unsupported NRRD space {fields['space']!r} (only 3-D spaces are read)"
        )
    if space_dim is not None and space_dim.strip() != "3":
        raise InputError(path, f"space dimension {space_dim} is not 3")
    frame = _SPACES.get(space_name)
    if "spacedirections" in fields:
        tokens = _VECTOR.findall(fields["spacedirections"])
        vectors = []
        for tok in _VECTOR.finditer(fields["spacedirections"]):
            if tok.group(0).lower() == "none":
                raise InputError(path, "a spatial axis has 'none' as space direction")
            vectors.append(parse_floats(tok.group(1), path, "a space direction", 3))
        if len(tokens) != 3 or len(vectors) != 3:
            raise InputError(
                path, f"expected 3 space direction vectors, got {fields['spacedirections']!r}"
            )
        axes = np.array(vectors, dtype=np.float64).T  # columns = i, j, k step vectors
        spacing = np.linalg.norm(axes, axis=0)
        if np.any(spacing == 0):
            raise InputError(path, "a space direction vector has zero length")
        direction = axes / spacing
    else:
        text = fields.get("spacings")
        spacing = np.array(parse_floats(text, path, "spacings", 3) if text else [np.nan] * 3)
        if not np.all(np.isfinite(spacing)) or np.any(spacing <= 0):
            # reading it as 1 mm would silently change every length measured on the volume
            raise InputError(
                path,
                "the header gives no usable voxel size "
                + (
                    f"(spacings: {text})" if text else "(neither 'space directions' nor 'spacings')"
                ),
                "the voxel size cannot be guessed: add it to the header, e.g. "
                "'spacings: 0.5 0.5 1.0' (mm), or export the volume again with its geometry",
            )
        direction = np.eye(3)
    if "spaceorigin" in fields:
        origin = np.array(parse_floats(fields["spaceorigin"], path, "space origin", 3))
    elif "axismins" in fields:
        origin = np.array(parse_floats(fields["axismins"], path, "axis mins", 3))
    else:
        origin = np.zeros(3)
    if "spaceunits" in fields:
        units = [u.strip('"') for u in re.findall(r'"[^"]*"|\S+', fields["spaceunits"])]
        factors = {_UNITS_TO_MM.get(u.lower()) for u in units}
        if len(factors) != 1 or None in factors:
            warnings.append(f"space units {units} not understood; assuming mm")
        else:
            f = factors.pop()
            spacing, origin = spacing * f, origin * f
    assumed = frame is None
    if frame == "LAS":  # L stays, anterior -> posterior: negate y
        flip = np.diag([1.0, -1.0, 1.0])
        origin, direction, frame = flip @ origin, flip @ direction, "LPS"
    if assumed:
        frame = "LPS"
        described = f"space {fields['space']!r}" if space_name else "no 'space' field"
        warnings.append(f"{described} has no anatomical meaning; the axes are taken as LPS")
    return spacing, origin, direction, frame, assumed


def read_nrrd(path: Path) -> Volume:
    """Read a 3-D scalar ``.nrrd`` / ``.nhdr`` volume (see module docstring)."""
    path = Path(path)
    fields, pairs, listed, offset = parse_nrrd_header(path)
    try:
        dimension = int(fields.get("dimension", ""))
        sizes = [int(s) for s in fields.get("sizes", "").split()]
    except ValueError:
        raise InputError(path, "the NRRD header lacks a valid 'dimension' or 'sizes'") from None
    if dimension != 3 or len(sizes) != 3:
        raise InputError(
            path,
            f"only 3-D scalar NRRD volumes are supported (dimension {dimension}, sizes {sizes})",
        )
    shape = check_sizes(path, sizes)
    warnings: list[str] = []
    spec = _data_spec(path, fields, listed, offset)
    spacing, origin, direction, frame, assumed = _geometry(path, fields, warnings)
    data = read_block(spec, shape, path)
    metadata = {
        "format": "NRRD",
        "header": dict(fields),
        "key_values": pairs,
        "data_files": [str(f) for f in spec.files],
        "frame_assumed": assumed,
        "warnings": warnings,
    }
    modality = pairs.get("modality", "unknown")
    return Volume(data, spacing, origin, direction, frame, modality, "unknown", str(path), metadata)
