"""Mesh import/export without VTK, checked against pyvista/VTK on real data."""

from __future__ import annotations

import hashlib
import os
import time
from pathlib import Path

import numpy as np
import pytest
import pyvista as pv
import vtk
from _mesh_cases import FLOAT32_FORMATS, FORMATS
from _mesh_cases import ids as _ids

from workbench.core.mesh import Mesh
from workbench.io.meshes import read_mesh, write_mesh


@pytest.fixture(scope="module")
def skull(skull_obj: Path):
    return read_mesh(skull_obj, kind="skull")


@pytest.fixture(scope="module")
def pv_skull(skull_obj: Path) -> pv.PolyData:
    return pv.read(skull_obj)


def _pv_faces(poly: pv.PolyData) -> np.ndarray:
    return np.asarray(poly.triangulate().regular_faces, dtype=np.int64)


def _same_triangles(a: Mesh, corners: np.ndarray, atol: float) -> None:
    assert a.n_faces == len(corners)
    np.testing.assert_allclose(a.triangles, corners, rtol=0, atol=atol)


# ------------------------------------------------------------------ real data
def test_skull_obj_loads_like_pyvista(skull, pv_skull):
    mesh = skull.mesh
    assert mesh.n_vertices == 49_999
    assert mesh.n_faces == 100_002
    np.testing.assert_allclose(mesh.vertices, pv_skull.points, rtol=0, atol=1e-6)
    assert np.array_equal(mesh.faces, _pv_faces(pv_skull))
    assert skull.format == ".obj" and skull.scale_applied == 1.0


def test_skull_obj_is_flagged_not_mm(skull):
    report = skull.units
    assert not report.plausible_in_mm
    assert report.needs_confirmation
    assert report.guess == "cm" and report.scale_to_mm == 10.0
    assert report.largest_extent == pytest.approx(13.9, abs=0.01)
    assert "139 mm" in report.message and "too small" in report.message
    assert any("units unclear" in m for m in skull.messages)
    # never rescaled silently
    assert skull.mesh.extent.max() == pytest.approx(13.9, abs=0.01)


def test_skull_obj_loads_fast(skull_obj):
    read_mesh(skull_obj)  # warm caches
    best = min(_timed(lambda: read_mesh(skull_obj)) for _ in range(3))
    assert best < 1.0, f"skull.obj took {best:.2f} s"


def _timed(fn) -> float:
    start = time.perf_counter()
    fn()
    return time.perf_counter() - start


def test_skull_units_cm_and_scale(skull_obj, skull):
    as_cm = read_mesh(skull_obj, units="cm", kind="skull")
    assert as_cm.scale_applied == 10.0
    assert not as_cm.units.needs_confirmation
    np.testing.assert_allclose(as_cm.mesh.vertices, skull.mesh.vertices * 10.0)
    assert as_cm.mesh.extent.max() == pytest.approx(139.0, abs=0.1)
    assert np.array_equal(as_cm.mesh.faces, skull.mesh.faces)
    scaled = read_mesh(skull_obj, scale=185 / 12.1, kind="skull")
    assert scaled.mesh.extent[2] == pytest.approx(185.0 * skull.mesh.extent[2] / 12.1)
    assert not scaled.units.needs_confirmation


def test_fsaverage_ply_is_plausible_mm(fsaverage_ply):
    result = read_mesh(fsaverage_ply)
    poly = pv.read(fsaverage_ply)
    assert (result.mesh.n_vertices, result.mesh.n_faces) == (2033, 4062)
    assert result.units.plausible_in_mm and result.units.guess == "mm"
    assert not result.units.needs_confirmation
    np.testing.assert_allclose(result.mesh.vertices, poly.points, rtol=0, atol=1e-4)
    assert np.array_equal(result.mesh.faces, _pv_faces(poly))
    assert 250 < result.mesh.extent.max() < 280


def test_reading_never_modifies_the_file(skull_obj):
    before = (hashlib.sha256(skull_obj.read_bytes()).hexdigest(), skull_obj.stat().st_mtime_ns)
    read_mesh(skull_obj)
    after = (hashlib.sha256(skull_obj.read_bytes()).hexdigest(), skull_obj.stat().st_mtime_ns)
    assert before == after


# ------------------------------------------------------------------ round trips
@pytest.mark.parametrize(("ext", "binary"), FORMATS, ids=_ids(FORMATS))
def test_round_trip(tmp_path, head_mesh, ext, binary):
    path = write_mesh(tmp_path / f"head{ext}", head_mesh, binary=binary)
    back = read_mesh(path).mesh
    if ext == ".stl":  # corners stored per triangle and merged again on reading
        corners = head_mesh.triangles
        if (ext, binary) in FLOAT32_FORMATS:
            corners = corners.astype(np.float32).astype(np.float64)
        _same_triangles(back, corners, atol=0)
        assert back.n_vertices == head_mesh.n_vertices
    else:
        assert np.array_equal(back.faces, head_mesh.faces)
        assert np.array_equal(back.vertices, head_mesh.vertices)


@pytest.mark.parametrize(("ext", "binary"), FORMATS, ids=_ids(FORMATS))
def test_our_files_read_with_pyvista(tmp_path, head_mesh, ext, binary):
    path = write_mesh(tmp_path / f"head{ext}", head_mesh, binary=binary)
    poly = pv.read(path)
    corners = np.asarray(poly.points, np.float64)[_pv_faces(poly)]
    _same_triangles(head_mesh, corners, atol=1e-4)


@pytest.mark.parametrize(("ext", "binary"), FORMATS, ids=_ids(FORMATS))
def test_written_files_state_units_mm(tmp_path, head_mesh, ext, binary):
    path = write_mesh(tmp_path / f"head{ext}", head_mesh, binary=binary)
    assert b"units: mm" in path.read_bytes()[:400]


# ------------------------------------------------------------------ files from pyvista / VTK
PV_FORMATS = [
    (".ply", True),
    (".ply", False),
    (".stl", True),
    (".stl", False),
    (".vtk", True),
    (".vtk", False),
    (".vtp", True),
    (".vtp", False),
    (".obj", True),
]


@pytest.mark.parametrize(("ext", "binary"), PV_FORMATS, ids=_ids(PV_FORMATS))
def test_reads_pyvista_files(tmp_path, fsaverage_ply, ext, binary):
    poly = pv.read(fsaverage_ply)
    path = tmp_path / f"pv{ext}"
    if ext == ".obj":
        poly.save(path)
    else:
        poly.save(path, binary=binary)
    ours = read_mesh(path).mesh
    ref = pv.read(path)
    if ext == ".stl":
        corners = np.asarray(ref.points, np.float64)[_pv_faces(ref)]
        _same_triangles(ours, corners, atol=0)
        assert ours.n_vertices == ref.n_points
    else:
        np.testing.assert_allclose(ours.vertices, ref.points, rtol=0, atol=1e-5)
        assert np.array_equal(ours.faces, _pv_faces(ref))


VTP_VARIANTS = [
    # (data mode, encode appended, compressed, header UInt64, big endian)
    ("binary", False, True, False, False),  # pyvista/VTK default
    ("binary", False, False, True, False),
    ("binary", False, True, True, True),
    ("appended", False, False, False, False),  # raw
    ("appended", False, True, True, False),
    ("appended", True, False, True, False),  # base64
    ("appended", True, True, False, True),
    ("ascii", False, False, False, False),
]


@pytest.mark.parametrize("variant", VTP_VARIANTS, ids=lambda v: "-".join(map(str, v)))
def test_reads_every_vtp_layout(tmp_path, fsaverage_ply, variant):
    mode, encode, compressed, uint64, big = variant
    poly = pv.read(fsaverage_ply)
    poly.cell_data["area"] = np.arange(poly.n_cells, dtype=float)  # extra arrays are skipped
    writer = vtk.vtkXMLPolyDataWriter()
    path = tmp_path / "variant.vtp"
    writer.SetFileName(str(path))
    writer.SetInputData(poly)
    {
        "binary": writer.SetDataModeToBinary,
        "appended": writer.SetDataModeToAppended,
        "ascii": writer.SetDataModeToAscii,
    }[mode]()
    writer.SetEncodeAppendedData(encode)
    if compressed:
        writer.SetCompressorTypeToZLib()
        writer.SetBlockSize(4096)  # several compressed blocks
    else:
        writer.SetCompressorTypeToNone()
    writer.SetHeaderTypeToUInt64() if uint64 else writer.SetHeaderTypeToUInt32()
    writer.SetByteOrderToBigEndian() if big else writer.SetByteOrderToLittleEndian()
    assert writer.Write() == 1
    ours = read_mesh(path).mesh
    if mode == "ascii":  # VTK prints ~9 digits; its own reader rounds them to float32
        np.testing.assert_allclose(ours.vertices, pv.read(path).points, rtol=1e-7, atol=0)
    else:
        np.testing.assert_array_equal(ours.vertices, poly.points)
    assert np.array_equal(ours.faces, _pv_faces(poly))


@pytest.mark.parametrize("binary", [True, False], ids=["bin", "txt"])
def test_reads_classic_legacy_vtk(tmp_path, fsaverage_ply, binary):
    poly = pv.read(fsaverage_ply)
    writer = vtk.vtkPolyDataWriter()
    path = tmp_path / "classic.vtk"
    writer.SetFileName(str(path))
    writer.SetInputData(poly)
    writer.SetFileVersion(42)
    writer.SetFileTypeToBinary() if binary else writer.SetFileTypeToASCII()
    assert writer.Write() == 1
    assert path.read_bytes().startswith(b"# vtk DataFile Version 4.2")
    ours = read_mesh(path).mesh
    # legacy ASCII keeps only 6 digits; compare with VTK's reading of the same file
    np.testing.assert_allclose(ours.vertices, pv.read(path).points, rtol=1e-7, atol=0)
    if binary:
        np.testing.assert_array_equal(ours.vertices, poly.points)
    assert np.array_equal(ours.faces, _pv_faces(poly))


# ------------------------------------------------------------------ format details
def _ply_bytes(
    fmt: str, verts, polys, vtype="float", ctype="uchar", itype="int", name="vertex_indices"
) -> bytes:
    order = {"binary_little_endian": "<", "binary_big_endian": ">"}.get(fmt)
    head = (
        f"ply\nformat {fmt} 1.0\ncomment test\nelement vertex {len(verts)}\n"
        f"property {vtype} x\nproperty {vtype} y\nproperty {vtype} z\nproperty uchar red\n"
        f"element face {len(polys)}\nproperty list {ctype} {itype} {name}\n"
        "property float quality\nelement edge 1\nproperty int vertex1\nproperty int vertex2\n"
        "end_header\n"
    ).encode()
    types = {
        "float": "f4",
        "double": "f8",
        "uchar": "u1",
        "ushort": "u2",
        "int": "i4",
        "uint": "u4",
    }
    if order is None:
        body = "".join(f"{x!r} {y!r} {z!r} 7\n" for x, y, z in verts)
        body += "".join(f"{len(p)} {' '.join(map(str, p))} 0.5\n" for p in polys) + "0 1\n"
        return head + body.encode()
    out = [head]
    for v in verts:
        out += [np.array(v, order + types[vtype]).tobytes(), b"\x07"]
    for p in polys:
        out += [
            np.array(len(p), order + types[ctype]).tobytes(),
            np.array(p, order + types[itype]).tobytes(),
            np.array(0.5, order + "f4").tobytes(),
        ]
    out.append(np.array([0, 1], order + "i4").tobytes())
    return b"".join(out)


SQUARE_PYRAMID = (
    [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (1.0, 1.0, 0.0), (0.0, 1.0, 0.0), (0.5, 0.5, 1.0)],
    [[3, 2, 1, 0], [0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]],
)
PYRAMID_TRIS = [[3, 2, 1], [3, 1, 0], [0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]]


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
@pytest.mark.parametrize(
    ("vtype", "ctype", "itype", "name"),
    [
        ("float", "uchar", "int", "vertex_indices"),
        ("double", "ushort", "uint", "vertex_index"),
    ],
)
def test_ply_variants(tmp_path, fmt, vtype, ctype, itype, name):
    verts, polys = SQUARE_PYRAMID
    path = tmp_path / "pyramid.ply"
    path.write_bytes(_ply_bytes(fmt, verts, polys, vtype, ctype, itype, name))
    result = read_mesh(path)
    assert np.array_equal(result.mesh.vertices, np.array(verts))
    assert np.array_equal(result.mesh.faces, PYRAMID_TRIS)
    assert any("split into triangles" in m for m in result.messages)
    # uniform triangle lists take the fast path and give the same answer
    path.write_bytes(_ply_bytes(fmt, verts, polys[1:], vtype, ctype, itype, name))
    assert np.array_equal(read_mesh(path).mesh.faces, PYRAMID_TRIS[2:])


def test_obj_variants(tmp_path):
    text = """# comment
mtllib x.mtl
o pyramid
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
vt 0 0
vn 0 0 1
g base
usemtl bone
s off
f 4/1/1 3/1/1 2/1/1 1/1/1
v 0.5 0.5 1.0 1.0
f 1//1 2//1 -1//1
f 2/1 3/1 5/1
  f -3 -2 -1
f 4 1 5
l 1 2
"""
    path = tmp_path / "pyramid.obj"
    path.write_text(text)
    result = read_mesh(path)
    assert np.array_equal(result.mesh.vertices, np.array(SQUARE_PYRAMID[0]))
    assert np.array_equal(result.mesh.faces, PYRAMID_TRIS)


def test_binary_stl_starting_with_solid(tmp_path, head_mesh):
    path = write_mesh(tmp_path / "head.stl", head_mesh)
    data = bytearray(path.read_bytes())
    data[:80] = b"solid exported by a careless CAD program".ljust(80)
    path.write_bytes(bytes(data))
    result = read_mesh(path).mesh
    corners32 = head_mesh.triangles.astype(np.float32).astype(np.float64)
    _same_triangles(result, corners32, atol=0)


def test_stl_merges_identical_corners_exactly(tmp_path):
    tris = np.array(
        [
            [[0, 0, 0], [1, 0, 0], [0, 1, 0]],
            [[1, 0, 0], [1, 1, 0], [0, 1, 0]],
            [[-0.0, 0, 0], [0, 1, 0], [0, 0, 1]],
            [[1e-7, 0, 0], [0, 1, 0], [0, 0, 1]],
        ]
    )
    facets = [
        " facet normal 0 0 1\n  outer loop\n"
        + "".join(f"   vertex {x:.9g} {y:.9g} {z:.9g}\n" for x, y, z in t)
        + "  endloop\n endfacet\n"
        for t in tris
    ]
    text = "solid t\n" + "".join(facets) + "endsolid t\n"
    path = tmp_path / "t.stl"
    path.write_text(text)
    mesh = read_mesh(path).mesh
    assert mesh.n_vertices == 6  # -0 merges with 0, 1e-7 stays separate
    assert np.array_equal(mesh.faces, [[0, 1, 2], [1, 3, 2], [0, 2, 4], [5, 2, 4]])


def _canonical(faces: np.ndarray) -> np.ndarray:
    """Rows rotated so the smallest index comes first (winding kept), then sorted."""
    faces = np.asarray(faces)
    shift = faces.argmin(axis=1)
    rolled = np.stack([np.roll(f, -s) for f, s in zip(faces, shift, strict=False)])
    return rolled[np.lexsort(rolled.T[::-1])]


@pytest.mark.parametrize("ext", [".vtk", ".vtp"])
def test_triangle_strips_are_split_with_vtk_winding(tmp_path, fsaverage_ply, ext):
    strips = pv.read(fsaverage_ply).strip()
    assert strips.n_strips > 0
    path = tmp_path / f"strips{ext}"
    strips.save(path)
    ours = read_mesh(path).mesh
    ref = pv.read(path).triangulate()
    np.testing.assert_array_equal(ours.vertices, ref.points)
    assert np.array_equal(_canonical(ours.faces), _canonical(ref.regular_faces))


def test_vtp_joint_base64_header_and_several_pieces(tmp_path):
    import base64

    def inline(values: np.ndarray) -> str:  # header + data encoded as ONE base64 stream
        raw = values.tobytes()
        return base64.b64encode(np.uint32(len(raw)).tobytes() + raw).decode()

    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], "<f4")
    conn, offs = np.array([0, 1, 2], "<i4"), np.array([3], "<i4")
    piece = (
        '<Piece NumberOfPoints="3" NumberOfPolys="1"><Points>'
        f'<DataArray type="Float32" NumberOfComponents="3" format="binary">{inline(pts)}'
        "</DataArray></Points><Polys>"
        f'<DataArray type="Int32" Name="connectivity" format="binary">{inline(conn)}</DataArray>'
        f'<DataArray type="Int32" Name="offsets" format="ascii">{offs[0]}</DataArray>'
        "</Polys></Piece>"
    )
    path = tmp_path / "joint.vtp"
    path.write_text(
        f'<VTKFile type="PolyData" version="0.1"><PolyData>{piece}{piece}</PolyData></VTKFile>'
    )
    mesh = read_mesh(path).mesh
    assert np.array_equal(mesh.vertices, np.concatenate([pts, pts]))
    assert np.array_equal(mesh.faces, [[0, 1, 2], [3, 4, 5]])


def test_written_files_get_normal_permissions(tmp_path, head_mesh):
    umask = os.umask(0)
    os.umask(umask)
    path = write_mesh(tmp_path / "head.ply", head_mesh)
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask
    path.chmod(0o640)
    write_mesh(path, head_mesh)  # overwriting keeps the file's permissions
    assert path.stat().st_mode & 0o777 == 0o640
    assert os.listdir(tmp_path) == ["head.ply"]
