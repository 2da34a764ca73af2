"""VTK XML PolyData ``.vtp``.

Reads every layout VTK writes: ``ascii`` arrays, inline ``binary`` (base64)
and ``appended`` data (raw or base64), uncompressed or block-compressed with
``vtkZLibDataCompressor`` (or LZMA), ``header_type`` UInt32 or UInt64, either
byte order, several pieces.  Polys are fanned, strips split; verts and lines
are ignored.  The writer emits uncompressed appended raw data (``binary=True``)
or inline base64 (``binary=False``) with Float64 points and Int64 cells, and
3D Slicer's coordinate-system tag: a field-data string array ``SPACE`` holding
``RAS``, where Slicer reads it (read back into :attr:`ParsedMesh.space`).
"""

from __future__ import annotations

import base64
import binascii
import lzma
import re
import xml.etree.ElementTree as ET
import zlib
from collections.abc import Callable
from pathlib import Path

import numpy as np

from workbench.io.mesh_formats._common import (
    UNITS_NOTE,
    WRITER_NAME,
    ParsedMesh,
    Reader,
    fan_triangulate,
    space_in,
    space_tag,
)
from workbench.io.mesh_formats.vtk_legacy import strips_to_triangles

_TYPES = {
    "Int8": "i1",
    "UInt8": "u1",
    "Int16": "i2",
    "UInt16": "u2",
    "Int32": "i4",
    "UInt32": "u4",
    "Int64": "i8",
    "UInt64": "u8",
    "Float32": "f4",
    "Float64": "f8",
}
_DECOMPRESS: dict[str, Callable[[bytes], bytes]] = {
    "vtkZLibDataCompressor": zlib.decompress,
    "vtkLZMADataCompressor": lzma.decompress,
}


def _b64len(n_bytes: int) -> int:
    return 4 * ((n_bytes + 2) // 3)


class _Context:
    def __init__(self, r: Reader, root: ET.Element, appended: bytes, appended_encoding: str):
        self.r = r
        self.order = ">" if root.get("byte_order", "LittleEndian") == "BigEndian" else "<"
        header_type = root.get("header_type", "UInt32")
        if header_type not in ("UInt32", "UInt64"):
            raise r.fail(f"unsupported header_type {header_type!r}")
        self.header = np.dtype(self.order + _TYPES[header_type])
        self.compressor = root.get("compressor") or None
        if self.compressor and self.compressor not in _DECOMPRESS:
            raise r.fail(
                f"data compressed with {self.compressor} cannot be read",
                "save the file uncompressed or with zlib compression",
            )
        self.appended = appended
        is_b64 = appended_encoding == "base64"
        self.appended_text = appended.decode("ascii", "replace") if is_b64 else ""
        self.appended_raw = appended_encoding == "raw"

    # ---------------------------------------------------------- decoding
    def _ints(self, raw: bytes, count: int, what: str) -> list[int]:
        if len(raw) < count * self.header.itemsize:
            raise self.r.truncated(what)
        return [int(x) for x in np.frombuffer(raw, self.header, count)]

    def _b64(self, text: str, what: str) -> bytes:
        try:
            return base64.b64decode(text)
        except (binascii.Error, ValueError):
            raise self.r.fail(f"invalid or truncated base64 data in {what}") from None

    def _payload_from_b64(self, text: str, what: str) -> tuple[list[int], bytes]:
        """Header ints and payload from base64, header encoded separately or jointly."""
        hs = self.header.itemsize
        n_first = 3 if self.compressor else 1
        first = self._ints(self._b64(text[: _b64len(n_first * hs)], what), n_first, what)
        n_header = 3 + first[0] if self.compressor else 1
        h_bytes = n_header * hs
        hl = _b64len(h_bytes)
        header = self._ints(self._b64(text[:hl], what), n_header, what)
        size = sum(header[3:]) if self.compressor else header[0]
        if h_bytes % 3 == 0 or text[hl - 1 : hl] == "=":  # header stream stands alone
            payload = self._b64(text[hl : hl + _b64len(size)], what)
        else:  # header and data encoded as one stream
            payload = self._b64(text[: _b64len(h_bytes + size)], what)[h_bytes:]
        if len(payload) < size:
            raise self.r.truncated(what)
        return header, payload[:size]

    def _payload_from_raw(self, offset: int, what: str) -> tuple[list[int], bytes]:
        hs, buf = self.header.itemsize, self.appended
        n_header = 3 + self._ints(buf[offset : offset + hs], 1, what)[0] if self.compressor else 1
        header = self._ints(buf[offset : offset + n_header * hs], n_header, what)
        size = sum(header[3:]) if self.compressor else header[0]
        start = offset + n_header * hs
        if start + size > len(buf):
            raise self.r.truncated(what)
        return header, buf[start : start + size]

    def _inflate(self, header: list[int], payload: bytes, what: str) -> bytes:
        if not self.compressor:
            return payload
        n_blocks, block, last = header[:3]
        sizes = header[3 : 3 + n_blocks]
        expected = (n_blocks - 1) * block + (last or block) if n_blocks else 0
        out, pos = [], 0
        try:
            for size in sizes:
                out.append(_DECOMPRESS[self.compressor](payload[pos : pos + size]))
                pos += size
        except (zlib.error, lzma.LZMAError):
            raise self.r.fail(f"compressed data in {what} are damaged") from None
        raw = b"".join(out)
        if len(raw) != expected:
            raise self.r.fail(f"{what}: decompressed size does not match its header (damaged file)")
        return raw

    def array(self, el: ET.Element, what: str) -> np.ndarray:
        """One DataArray as a 1-D numpy array of its declared type."""
        typ = el.get("type", "")
        if typ not in _TYPES:
            raise self.r.fail(f"{what} has unsupported type {typ!r}")
        dtype = np.dtype(self.order + _TYPES[typ])
        fmt = el.get("format", "ascii")
        if fmt == "ascii":
            tokens = (el.text or "").split()
            if dtype.kind == "f":
                return self.r.to_float(tokens, what)
            return self.r.to_int(tokens, what)
        if fmt == "binary":
            header, payload = self._payload_from_b64("".join((el.text or "").split()), what)
        elif fmt == "appended":
            try:
                offset = int(el.get("offset", ""))
            except ValueError:
                raise self.r.fail(f"{what} has no valid 'offset'") from None
            if self.appended_raw:
                header, payload = self._payload_from_raw(offset, what)
            else:
                header, payload = self._payload_from_b64(self.appended_text[offset:], what)
        else:
            raise self.r.fail(f"{what} has unknown format {fmt!r}")
        raw = self._inflate(header, payload, what)
        if len(raw) % dtype.itemsize:
            raise self.r.fail(f"{what}: byte count is not a multiple of the {typ} size")
        return np.frombuffer(raw, dtype)


def _split_appended(r: Reader) -> tuple[bytes, bytes, str]:
    """Cut the (possibly raw binary) AppendedData payload out of the XML text."""
    data = r.data
    start = data.find(b"<AppendedData")
    if start < 0:
        return data, b"", ""
    tag_end = data.find(b">", start)
    close = data.rfind(b"</AppendedData>")
    if tag_end < 0 or close < tag_end:
        raise r.truncated("the appended data (no closing </AppendedData> tag)")
    match = re.search(rb'encoding\s*=\s*"(\w+)"', data[start:tag_end])
    encoding = match.group(1).decode() if match else "raw"
    underscore = data.find(b"_", tag_end, close)
    if underscore < 0:
        raise r.fail("the appended data block does not start with '_'")
    payload = data[underscore + 1 : close]
    if encoding == "base64":
        payload = b"".join(payload.split())
    return data[: tag_end + 1] + data[close:], payload, encoding


def _cells(
    ctx: _Context, parent: ET.Element | None, n: int, what: str
) -> tuple[np.ndarray, np.ndarray]:
    if parent is None or n == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    arrays = {el.get("Name"): el for el in parent.findall("DataArray")}
    if "connectivity" not in arrays or "offsets" not in arrays:
        raise ctx.r.fail(f"{what} need 'connectivity' and 'offsets' arrays")
    conn = ctx.array(arrays["connectivity"], f"the {what} connectivity").astype(np.int64)
    ends = ctx.array(arrays["offsets"], f"the {what} offsets").astype(np.int64)
    if len(ends) != n:
        raise ctx.r.fail(f"{what}: expected {n} offsets, found {len(ends)}")
    counts = np.diff(np.concatenate([[0], ends]))
    if np.any(counts < 0) or ends[-1] != len(conn):
        raise ctx.r.fail(f"{what} offsets do not match the connectivity (damaged file)")
    return counts, conn


def read(path: Path, data: bytes) -> ParsedMesh:
    """Parse VTK XML PolyData bytes; vertices in file units."""
    r = Reader(path, data, "VTP")
    xml, appended, encoding = _split_appended(r)
    try:
        root = ET.fromstring(xml)
    except ET.ParseError as exc:
        raise r.fail(f"the XML is malformed or truncated ({exc})") from None
    if root.tag != "VTKFile" or root.get("type") != "PolyData":
        kind = root.get("type") if root.tag == "VTKFile" else root.tag
        raise r.fail(f"expected a VTKFile of type PolyData, found {kind!r}")
    ctx = _Context(r, root, appended, encoding)
    all_points, all_tris, base = [], [], 0
    for number, piece in enumerate(root.findall("PolyData/Piece"), start=1):
        try:
            n_pts = int(piece.get("NumberOfPoints", "0"))
            n_polys = int(piece.get("NumberOfPolys", "0"))
            n_strips = int(piece.get("NumberOfStrips", "0"))
            n_other = int(piece.get("NumberOfVerts", "0")) + int(piece.get("NumberOfLines", "0"))
        except ValueError:
            raise r.fail(f"piece {number} has non-numeric element counts") from None
        el = piece.find("Points/DataArray")
        if el is None:
            if n_pts:
                raise r.fail(f"piece {number} has no Points array")
            continue
        pts = ctx.array(el, "the points").astype(np.float64)
        if len(pts) != 3 * n_pts:
            raise r.fail(f"piece {number}: expected {n_pts} points, found {len(pts) / 3:g}")
        polys = fan_triangulate(*_cells(ctx, piece.find("Polys"), n_polys, "polys"), r)
        strips = strips_to_triangles(*_cells(ctx, piece.find("Strips"), n_strips, "strips"))
        if n_other:
            r.note(f"piece {number}: {n_other} vertex/line cells were ignored")
        all_points.append(pts.reshape(-1, 3))
        all_tris += [polys + base, strips + base]
        base += n_pts
    if not all_points:
        raise r.fail("the file contains no points")
    parsed = r.finish(np.concatenate(all_points), np.concatenate(all_tris))
    parsed.space = _field_space(ctx, root)
    return parsed


def _field_space(ctx: _Context, root: ET.Element) -> str | None:
    """3D Slicer's ``SPACE`` string array in the dataset's field data (None: not there).

    VTK writes a string array as its characters' codes, each string ended by a 0
    (ascii), or as those bytes (binary, appended, compressed).
    """
    for el in root.findall("PolyData/FieldData/*"):
        if el.get("Name") != "SPACE" or el.get("type") != "String":
            continue
        if el.get("format", "ascii") == "ascii":
            codes = ctx.r.to_int((el.text or "").split(), "the SPACE field")
        else:
            codes = ctx.array(_as_bytes(el), "the SPACE field")
        if np.any((codes < 0) | (codes > 255)):
            raise ctx.r.fail("the SPACE field holds values that are not characters")
        first = bytes(codes.astype(np.uint8).tolist()).split(b"\0")[0]
        return space_in(b"SPACE=" + first.strip())
    return None


def _as_bytes(el: ET.Element) -> ET.Element:
    """A copy of a String array element read as raw UInt8 (the characters and 0 ends)."""
    copy = ET.Element(el.tag, dict(el.attrib, type="UInt8"))
    copy.text = el.text
    return copy


def _xml(n: int, m: int, arrays: list[str], appended: bytes | None, space: str) -> bytes:
    tag = space_tag(space)
    codes = " ".join(str(c) for c in space.encode("ascii"))  # "82 65 83" for RAS
    head = (
        f'<?xml version="1.0"?>\n<!-- {UNITS_NOTE}; {tag}; written by {WRITER_NAME} -->\n'
        '<VTKFile type="PolyData" version="1.0" byte_order="LittleEndian" header_type="UInt64">\n'
        "  <PolyData>\n"
        # 3D Slicer's coordinate-system tag: a string array SPACE (character codes, 0 ends it)
        '    <FieldData>\n      <Array type="String" Name="SPACE" NumberOfTuples="1" '
        f'format="ascii">{codes} 0</Array>\n    </FieldData>\n'
        f'    <Piece NumberOfPoints="{n}" NumberOfVerts="0" NumberOfLines="0"'
        f' NumberOfStrips="0" NumberOfPolys="{m}">\n'
        f"      <Points>\n        {arrays[0]}\n      </Points>\n"
        f"      <Polys>\n        {arrays[1]}\n        {arrays[2]}\n      </Polys>\n"
        "    </Piece>\n  </PolyData>\n"
    ).encode("ascii")
    if appended is None:
        return head + b"</VTKFile>\n"
    tail = b"\n  </AppendedData>\n</VTKFile>\n"
    return head + b'  <AppendedData encoding="raw">\n   _' + appended + tail


def encode(
    vertices: np.ndarray, faces: np.ndarray, binary: bool = True, *, space: str = "RAS"
) -> bytes:
    """VTP bytes: appended raw (``binary=True``) or inline base64, uncompressed."""
    blocks = [
        ("Float64", 'Name="Points" NumberOfComponents="3"', np.ascontiguousarray(vertices, "<f8")),
        ("Int64", 'Name="connectivity"', np.ascontiguousarray(faces, "<i8").ravel()),
        ("Int64", 'Name="offsets"', 3 * np.arange(1, len(faces) + 1, dtype="<i8")),
    ]
    tags, chunks, offset = [], [], 0
    for typ, attrs, values in blocks:
        payload = values.tobytes()
        header = np.uint64(len(payload)).astype("<u8").tobytes()
        if binary:
            tags.append(f'<DataArray type="{typ}" {attrs} format="appended" offset="{offset}"/>')
            chunks.append(header + payload)
            offset += len(header) + len(payload)
        else:
            text = (base64.b64encode(header) + base64.b64encode(payload)).decode("ascii")
            tags.append(f'<DataArray type="{typ}" {attrs} format="binary">{text}</DataArray>')
    return _xml(len(vertices), len(faces), tags, b"".join(chunks) if binary else None, space)
