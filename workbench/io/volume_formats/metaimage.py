"""MetaImage reader (``.mhd`` header + detached data, ``.mha`` single file).

Supported header keys: ``NDims = 3``, ``DimSize`` (x fastest),
``ElementSpacing`` (or ``ElementSize``), ``Offset`` (``Origin``,
``Position``), ``TransformMatrix`` (``Rotation``, ``Orientation``),
``ElementType`` (MET_CHAR ... MET_DOUBLE), ``ElementNumberOfChannels = 1``,
``BinaryData``, ``BinaryDataByteOrderMSB`` / ``ElementByteOrderMSB``,
``CompressedData`` (zlib/deflate), ``HeaderSize`` (-1 = data at the end of
the file), ``Modality`` and ``ElementDataFile`` = ``LOCAL``, a file name, a
numbered pattern ``slice%03d.raw 1 40 1`` or ``LIST`` followed by names.

Geometry follows ITK: the *n*-th triple of ``TransformMatrix`` is the
physical direction of index axis *n* (i, j, k), the physical frame is LPS.
``AnatomicalOrientation`` is informative only and kept in the metadata.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from workbench.core.errors import InputError
from workbench.core.volume import Volume

from ._common import (
    DataSpec,
    check_sizes,
    expand_file_pattern,
    open_header,
    parse_floats,
    read_block,
)

_ELEMENT_TYPES = {
    "MET_CHAR": "i1",
    "MET_UCHAR": "u1",
    "MET_SHORT": "i2",
    "MET_USHORT": "u2",
    "MET_INT": "i4",
    "MET_UINT": "u4",
    "MET_LONG": "i4",
    "MET_ULONG": "u4",
    "MET_LONG_LONG": "i8",
    "MET_ULONG_LONG": "u8",
    "MET_FLOAT": "f4",
    "MET_DOUBLE": "f8",
}
_ALIASES = {
    "elementsize": "elementspacing",
    "origin": "offset",
    "position": "offset",
    "rotation": "transformmatrix",
    "orientation": "transformmatrix",
    "elementbyteordermsb": "binarydatabyteordermsb",
}
_MODALITIES = {"MET_MOD_CT": "CT", "MET_MOD_MR": "MR", "MET_MOD_NM": "NM", "MET_MOD_US": "US"}


def _true(value: str | None) -> bool:
    return (value or "").strip().lower() in ("true", "1", "yes")


def parse_metaimage_header(path: Path) -> tuple[dict[str, str], list[str], int]:
    """Return (fields with lower-case keys, LIST file names, byte offset after the header)."""
    fh = open_header(path)
    fields: dict[str, str] = {}
    listed: list[str] = []
    with fh:
        n_lines = 0
        while True:
            raw = fh.readline(65536)
            if not raw:
                break
            n_lines += 1
            line = raw.decode("latin-1").strip()
            if not line:
                continue
            if "=" not in line:
                raise InputError(path, f"not a MetaImage header (line {n_lines}: {line[:40]!r})")
            key, value = (s.strip() for s in line.split("=", 1))
            key = _ALIASES.get(key.lower(), key.lower())
            fields[key] = value
            if key == "elementdatafile":
                break
        if value_is_list := fields.get("elementdatafile", "").upper().startswith("LIST"):
            for raw in fh:
                name = raw.decode("latin-1").strip()
                if name:
                    listed.append(name)
        offset = fh.tell() if not value_is_list else 0
    if "elementdatafile" not in fields:
        raise InputError(path, "the MetaImage header has no ElementDataFile line")
    return fields, listed, offset


def read_metaimage(path: Path) -> Volume:
    """Read a 3-D scalar ``.mhd`` / ``.mha`` volume (see module docstring)."""
    path = Path(path)
    fields, listed, offset = parse_metaimage_header(path)
    if fields.get("objecttype", "Image").lower() != "image":
        raise InputError(path, f"ObjectType is {fields['objecttype']!r}, not Image")
    try:
        ndims = int(fields.get("ndims", "0"))
        sizes = [int(s) for s in fields.get("dimsize", "").split()]
    except ValueError:
        raise InputError(path, "NDims / DimSize are not integers") from None
    if ndims != 3 or len(sizes) != 3:
        raise InputError(
            path, f"only 3-D MetaImage volumes are supported (NDims {ndims}, DimSize {sizes})"
        )
    shape = check_sizes(path, sizes)
    if fields.get("elementnumberofchannels", "1").strip() != "1":
        raise InputError(path, "multi-channel MetaImage volumes are not supported")
    etype = fields.get("elementtype", "").upper()
    if etype not in _ELEMENT_TYPES:
        raise InputError(path, f"unsupported ElementType {etype or '(missing)'!r}")
    dtype = np.dtype(_ELEMENT_TYPES[etype])
    if dtype.itemsize > 1:
        dtype = dtype.newbyteorder(">" if _true(fields.get("binarydatabyteordermsb")) else "<")
    if "binarydata" in fields and not _true(fields["binarydata"]):
        encoding = "ascii"
    elif _true(fields.get("compresseddata")):
        encoding = "zlib"
    else:
        encoding = "raw"
    try:
        header_size = int(fields.get("headersize", "0"))
    except ValueError:
        raise InputError(path, "HeaderSize is not an integer") from None

    datafile = fields["elementdatafile"]
    parts = datafile.split()
    if datafile.upper() == "LOCAL":
        files, data_offset = [path], offset
    elif parts and parts[0].upper() == "LIST":
        if not listed:
            raise InputError(path, "'ElementDataFile = LIST' is not followed by any file names")
        files, data_offset = [path.parent / n for n in listed], 0
    elif len(parts) >= 4 and "%" in parts[0]:
        try:
            first, last, step = (int(p) for p in parts[1:4])
        except ValueError:
            raise InputError(path, f"bad ElementDataFile pattern: {datafile!r}") from None
        files, data_offset = expand_file_pattern(path, parts[0], first, last, step), 0
    else:
        files, data_offset = [path.parent / datafile], 0
    spec = DataSpec(files, data_offset, header_size, 0, encoding, dtype)

    warnings: list[str] = []
    if "elementspacing" in fields:
        spacing = np.array(parse_floats(fields["elementspacing"], path, "ElementSpacing", 3))
    else:  # reading it as 1 mm would silently change every length measured on the volume
        raise InputError(
            path,
            "the header gives no voxel size (no ElementSpacing)",
            "the voxel size cannot be guessed: add it to the header, e.g. "
            "'ElementSpacing = 0.5 0.5 1.0' (mm), or export the volume again with its geometry",
        )
    origin = (
        np.array(parse_floats(fields["offset"], path, "Offset", 3))
        if "offset" in fields
        else np.zeros(3)
    )
    if "transformmatrix" in fields:
        m = np.array(parse_floats(fields["transformmatrix"], path, "TransformMatrix", 9))
        direction = m.reshape(3, 3).T  # n-th triple = direction of index axis n
    else:
        direction = np.eye(3)
    data = read_block(spec, shape, path)
    metadata = {
        "format": "MetaImage",
        "header": dict(fields),
        "data_files": [str(f) for f in files],
        "anatomical_orientation": fields.get("anatomicalorientation"),
        "warnings": warnings,
    }
    modality = _MODALITIES.get(fields.get("modality", "").upper(), "unknown")
    return Volume(data, spacing, origin, direction, "LPS", modality, "unknown", str(path), metadata)
