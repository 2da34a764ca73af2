"""Issue 29: exported meshes, landmarks and glTF line up in 3D Slicer and Blender.

Every file is read back the way the other program reads it: meshes with
VTK's readers and 3D Slicer's ``SPACE=`` rule (``vtkMRMLModelStorageNode``:
the token anywhere in the header, LPS when there is none), markups with
Slicer's rules (``coordinateSystem``, LPS by default; ``.fcsv`` fields by
position, ``positionStatus`` the 15th), the ``.glb`` as glTF numbers.
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pygltflib
import pytest
from scipy.spatial import cKDTree

from workbench.cli.main import main
from workbench.core.errors import InputError
from workbench.core.landmarks import Landmark, LandmarkSet
from workbench.core.mesh import Mesh
from workbench.io.markups import read_fcsv, read_landmarks, write_fcsv, write_mrk_json
from workbench.io.meshes import read_mesh, write_mesh

LPS_FLIP = np.array([-1.0, -1.0, 1.0])
NAN3 = [np.nan] * 3


# ------------------------------------------------------------ Slicer's readers
def _vtk_mesh(path: Path) -> tuple[np.ndarray, str]:
    """``(points as stored, header text Slicer checks)`` through VTK, as Slicer reads them."""
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkIOGeometry import vtkOBJReader, vtkSTLReader
    from vtkmodules.vtkIOLegacy import vtkPolyDataReader
    from vtkmodules.vtkIOPLY import vtkPLYReader
    from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

    ext = path.suffix.lower()
    reader = {
        ".ply": vtkPLYReader,
        ".stl": vtkSTLReader,
        ".obj": vtkOBJReader,
        ".vtk": vtkPolyDataReader,
        ".vtp": vtkXMLPolyDataReader,
    }[ext]()
    reader.SetFileName(str(path))
    reader.Update()
    out = reader.GetOutput()
    points = vtk_to_numpy(out.GetPoints().GetData()).astype(float)
    if ext == ".ply":
        comments = reader.GetComments()
        header = "\n".join(comments.GetValue(i) for i in range(comments.GetNumberOfValues()))
    elif ext == ".obj":
        header = reader.GetComment() or ""
    elif ext == ".vtp":  # Slicer: the first value of a string field array named SPACE
        array = out.GetFieldData().GetAbstractArray("SPACE")
        header = "" if array is None else "SPACE=" + array.GetValue(0)
    else:
        header = reader.GetHeader() or ""
    return points, header


def _slicer_space(header: str) -> str:
    """``GetCoordinateSystemFromFileHeader``, with Slicer 5's LPS default for untagged files."""
    if "SPACE=RAS" in header:
        return "RAS"
    if "SPACE=LPS" in header:
        return "LPS"
    return "LPS"


def _slicer_mesh_ras(path: Path) -> np.ndarray:
    points, header = _vtk_mesh(path)
    return points if _slicer_space(header) == "RAS" else points * LPS_FLIP


def _slicer_mrk_json_ras(path: Path) -> dict[str, np.ndarray]:
    """Defined control points in Slicer's RAS world, by label (vtkMRMLMarkupsJsonStorageNode)."""
    mk = json.loads(path.read_text(encoding="utf-8"))["markups"][0]
    flip = LPS_FLIP if mk.get("coordinateSystem", "LPS") == "LPS" else np.ones(3)
    return {
        cp["label"]: np.asarray(cp["position"], float) * flip
        for cp in mk["controlPoints"]
        if cp.get("positionStatus", "defined") == "defined"
    }


def _slicer_fcsv_rows(path: Path) -> tuple[str, list[dict]]:
    """Slicer 5's ``.fcsv`` reading: ``# columns`` ignored, fields by position, integers parsed."""
    system, rows = "LPS", []
    for line in path.read_text(encoding="utf-8").splitlines():
        if line.startswith("#"):
            name, _, value = line[1:].partition("=")
            if name.strip() == "CoordinateSystem":
                system = value.strip()
            continue
        f = next(csv.reader([line]))  # Slicer's CsvCodec: quotes open a field, "" is a quote
        rows.append(
            {
                "xyz": np.array([float(v) for v in f[1:4]]),
                "vis": int(f[8]),
                "sel": int(f[9]),
                "lock": int(f[10]),
                "label": f[11],
                "desc": f[12],
                "positionStatus": int(f[14]) if len(f) > 14 and f[14] else 2,
                "autoCreated": int(f[15]) if len(f) > 15 and f[15] else 0,
            }
        )
    return system, rows


# ------------------------------------------------------------ a skull and its points
def _skull_and_points() -> tuple[Mesh, LandmarkSet]:
    """A lumpy closed surface well off the origin (the LPS/RAS mix-up moves it > 100 mm)."""
    n_lat, n_lon = 24, 36
    theta = np.linspace(0.05, np.pi - 0.05, n_lat)
    phi = np.linspace(0.0, 2 * np.pi, n_lon, endpoint=False)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    r = 1.0 + 0.08 * np.sin(3 * p) * np.sin(2 * t)
    xyz = np.stack(
        [70 * r * np.sin(t) * np.cos(p), 90 * r * np.sin(t) * np.sin(p), 65 * r * np.cos(t)],
        axis=-1,
    ).reshape(-1, 3) + [55.0, 40.0, -20.0]
    faces = []
    for i in range(n_lat - 1):
        for j in range(n_lon):
            a, b = i * n_lon + j, i * n_lon + (j + 1) % n_lon
            c, d = a + n_lon, b + n_lon
            faces += [[a, c, b], [b, c, d]]
    mesh = Mesh(xyz, np.array(faces))
    codes = ("n", "g", "pr", "gn", "zy_l", "zy_r", "go_l", "go_r", "po_l", "po_r", "or_l", "or_r")
    picks = np.linspace(40, len(xyz) - 40, len(codes)).astype(int)
    marks = [Landmark(c, xyz[k] + 0.5) for c, k in zip(codes, picks, strict=True)]
    marks.append(Landmark("op", NAN3, "absent", description="broken off"))
    return mesh, LandmarkSet("skull", tuple(marks))


MESH_CASES = [
    pytest.param("skull.ply", True, id="slicer-mesh-space-tag-ply"),
    pytest.param("skull_ascii.ply", False, id="slicer-mesh-space-tag-ply-ascii"),
    pytest.param("skull.stl", True, id="slicer-mesh-space-tag-stl"),
    pytest.param("skull_ascii.stl", False, id="slicer-mesh-space-tag-stl-ascii"),
    pytest.param("skull.obj", False, id="slicer-mesh-space-tag-obj"),
    pytest.param("skull.vtk", True, id="slicer-mesh-space-tag-vtk"),
    pytest.param("skull.vtp", True, id="slicer-mesh-space-tag-vtp"),
    pytest.param("skull_ascii.vtp", False, id="slicer-mesh-space-tag-vtp-base64"),
]


@pytest.mark.parametrize("name,binary", MESH_CASES)
@pytest.mark.parametrize("system", ["RAS", "LPS"])
def test_landmarks_overlay_the_skull_in_slicer(tmp_path: Path, name, binary, system) -> None:
    """Mesh and markups written as `workbench reconstruct` writes them, loaded with Slicer's
    defaults: every landmark within 2 mm of the skull (before: 131-180 mm away)."""
    mesh, marks = _skull_and_points()
    skull = write_mesh(tmp_path / name, mesh, binary=binary)
    write_mrk_json(tmp_path / "skull.mrk.json", marks, coordinate_system=system)
    tree = cKDTree(_slicer_mesh_ras(skull))
    points = _slicer_mrk_json_ras(tmp_path / "skull.mrk.json")
    assert set(points) == {lm.code for lm in marks if lm.is_defined}  # "op" is not shown
    far = {code: float(tree.query(p)[0]) for code, p in points.items()}
    assert max(far.values()) <= 2.0, far
    # the test sees the fault: the same numbers read as LPS (an untagged file) land far off
    untagged = cKDTree(_vtk_mesh(skull)[0] * LPS_FLIP)
    assert min(float(untagged.query(p)[0]) for p in points.values()) > 50.0
    # and the workbench reads its own file back unchanged
    back = read_mesh(skull, units="mm")
    assert back.space == "RAS"
    assert np.abs(np.sort(back.mesh.vertices, axis=0) - np.sort(mesh.vertices, axis=0)).max() < 1e-4


def test_fcsv_points_overlay_the_skull_in_slicer(tmp_path: Path) -> None:
    mesh, marks = _skull_and_points()
    skull = write_mesh(tmp_path / "skull.ply", mesh)
    write_fcsv(tmp_path / "skull.fcsv", marks)
    system, rows = _slicer_fcsv_rows(tmp_path / "skull.fcsv")
    tree = cKDTree(_slicer_mesh_ras(skull))
    flip = LPS_FLIP if system == "LPS" else np.ones(3)
    shown = [r for r in rows if r["positionStatus"] == 2]
    assert len(shown) == len(rows) - 1
    assert max(float(tree.query(r["xyz"] * flip)[0]) for r in shown) <= 2.0


def _slicer_vtp(path: Path, points: np.ndarray, space: str) -> None:
    """A .vtp as Slicer saves a model: zlib-compressed appended data, SPACE string field."""
    from vtkmodules.util.numpy_support import numpy_to_vtk
    from vtkmodules.vtkCommonCore import vtkPoints, vtkStringArray
    from vtkmodules.vtkCommonDataModel import vtkCellArray, vtkPolyData
    from vtkmodules.vtkIOXML import vtkXMLPolyDataWriter

    poly = vtkPolyData()
    pts = vtkPoints()
    pts.SetData(numpy_to_vtk(points, deep=True))
    poly.SetPoints(pts)
    cells = vtkCellArray()
    for tri in ([0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]):
        cells.InsertNextCell(3, tri)
    poly.SetPolys(cells)
    tag = vtkStringArray()
    tag.SetName("SPACE")
    tag.InsertNextValue(space)
    poly.GetFieldData().AddArray(tag)
    writer = vtkXMLPolyDataWriter()
    writer.SetFileName(str(path))
    writer.SetInputData(poly)
    writer.SetCompressorTypeToZLib()
    writer.SetDataModeToAppended()
    writer.Write()


def _slicer_text_file(path: Path, points: np.ndarray, space: str) -> None:
    """STL / OBJ / VTK / PLY text as Slicer's storage node heads them."""
    tris = [[0, 1, 2], [0, 2, 3], [0, 3, 1], [1, 3, 2]]
    ext = path.suffix
    if ext == ".stl":
        body = "".join(
            " facet normal 0 0 0\n  outer loop\n"
            + "".join(f"   vertex {x!r} {y!r} {z!r}\n" for x, y, z in points[t].tolist())
            + "  endloop\n endfacet\n"
            for t in tris
        )
        text = f"solid 3D Slicer output. SPACE={space}\n{body}endsolid\n"
    elif ext == ".obj":
        text = f"# 3D Slicer output. SPACE={space}\n\nmtllib skull.mtl\n\n"
        text += "".join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in points.tolist())
        text += "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in tris)
    elif ext == ".vtk":
        text = f"# vtk DataFile Version 4.2\n3D Slicer output. SPACE={space}\nASCII\n"
        text += f"DATASET POLYDATA\nPOINTS {len(points)} double\n"
        text += "".join(f"{x!r} {y!r} {z!r}\n" for x, y, z in points.tolist())
        text += "POLYGONS 4 16\n" + "".join(f"3 {a} {b} {c}\n" for a, b, c in tris)
    else:
        text = "ply\nformat ascii 1.0\ncomment VTK generated PLY File\n"
        text += f"comment SPACE={space}\nobj_info vtkPolyData points and polygons: vtk4.0\n"
        text += f"element vertex {len(points)}\nproperty double x\nproperty double y\n"
        text += "property double z\nelement face 4\nproperty list uchar int vertex_indices\n"
        text += "end_header\n" + "".join(f"{x!r} {y!r} {z!r}\n" for x, y, z in points.tolist())
        text += "".join(f"3 {a} {b} {c}\n" for a, b, c in tris)
    path.write_text(text, encoding="ascii")


@pytest.mark.parametrize(
    "ext", [".vtp", ".stl", ".obj", ".vtk", ".ply"], ids=lambda e: f"slicer-mesh-lps-read-{e[1:]}"
)
@pytest.mark.parametrize("space", ["LPS", "RAS"])
def test_a_slicer_saved_mesh_is_read_in_its_space(tmp_path: Path, ext, space) -> None:
    """Slicer saves models in LPS (tagged): the workbench reads them into RAS, like Slicer."""
    stored = np.array([[10.0, 20.0, 30.0], [60.0, 20.0, 30.0], [10.0, 90.0, 30.0], [10, 20, 95]])
    path = tmp_path / f"model{ext}"
    (_slicer_vtp if ext == ".vtp" else _slicer_text_file)(path, stored, space)
    read = read_mesh(path, units="mm", kind="skull")
    assert read.space == space
    want = stored * (LPS_FLIP if space == "LPS" else 1.0)
    got = read.mesh.vertices
    assert np.abs(np.sort(got, axis=0) - np.sort(want, axis=0)).max() < 1e-9
    assert np.allclose(np.sort(_slicer_mesh_ras(path), axis=0), np.sort(want, axis=0))
    assert any("SPACE=LPS" in m for m in read.messages) == (space == "LPS")


# ------------------------------------------------------------------ .fcsv
def _statuses() -> LandmarkSet:
    return LandmarkSet(
        "skull",
        (
            Landmark("n", [1.5, 80.25, 10.0]),
            Landmark("g", [0.5, 85.0, 25.125], "suggested", 0.965, "from the template, check"),
            Landmark("go_l", NAN3, "absent", description="mandible broken"),
            Landmark("go_r", NAN3, "missing"),
            Landmark("zy_l", [-60.0, 40.0, 5.0], "placed", 0.5, 'a "quoted", text'),
        ),
    )


@pytest.mark.parametrize(
    "system", ["LPS", "RAS"], ids=["fcsv-round-trip-lps", "fcsv-round-trip-ras"]
)
def test_fcsv_round_trip_and_slicer_5_fields(tmp_path: Path, system) -> None:
    marks = _statuses()
    path = tmp_path / "skull.fcsv"
    write_fcsv(path, marks, coordinate_system=system)
    back = read_fcsv(path, "skull", allow_undefined=True)
    assert back.landmarks.equals(marks), back.landmarks
    assert back.undefined == ("go_l", "go_r")
    lines = path.read_text(encoding="utf-8").splitlines()
    assert lines[0].startswith("# Markups fiducial file version = 5.")
    assert lines[1] == f"# CoordinateSystem = {system}"
    assert lines[2] == (
        "# columns = id,x,y,z,ow,ox,oy,oz,vis,sel,lock,label,desc,associatedNodeID,"
        "positionStatus,autoCreated"
    )
    # Slicer 5 parses every integer field (the old file had 'suggested' / '0.965' there)
    _, rows = _slicer_fcsv_rows(path)
    states = {r["label"]: r["positionStatus"] for r in rows}
    assert states == {"n": 2, "g": 2, "go_l": 3, "go_r": 3, "zy_l": 2}
    assert {r["autoCreated"] for r in rows} == {0}
    desc = {r["label"]: r["desc"] for r in rows}
    assert desc["g"] == "from the template, check [workbench: suggested; confidence 0.965]"
    assert desc["go_r"] == "[workbench: missing; confidence 1.0]"


def test_a_slicer_5_fcsv_with_a_missing_point_reads_it_as_missing(tmp_path: Path) -> None:
    """Slicer 5 names 14 columns but writes 16 fields; a missing point is never (0, 0, 0)."""
    path = tmp_path / "slicer.fcsv"
    path.write_text(
        "# Markups fiducial file version = 5.6\n# CoordinateSystem = LPS\n"
        "# columns = id,x,y,z,ow,ox,oy,oz,vis,sel,lock,label,desc,associatedNodeID\n"
        "1,-1.5,-80.25,10,0,0,0,1,1,1,0,n,,,2,0\n"
        "2,0,0,0,0,0,0,1,1,1,0,gn,,,3,0\n"
        "3,0,0,0,0,0,0,1,1,1,0,pr,,,0,0\n"
        "4,-2,-70,-5,0,0,0,1,1,1,0,g,,,1,0\n",
        encoding="utf-8",
    )
    kept = read_fcsv(path, "skull", allow_undefined=True)
    lms = kept.landmarks
    assert lms["n"].status == "placed" and lms["n"].position.tolist() == [1.5, 80.25, 10.0]
    assert lms["gn"].status == "missing" and np.isnan(lms["gn"].position).all()
    assert lms["pr"].status == "missing" and np.isnan(lms["pr"].position).all()
    assert lms["g"].status == "suggested" and lms["g"].position.tolist() == [2.0, 70.0, -5.0]
    assert kept.undefined == ("gn", "pr", "g")
    plain = read_fcsv(path, "skull")
    assert plain.landmarks.codes == ("n",)  # nothing at the origin
    # a placed point keeps Slicer's word over an old note in its description
    path.write_text(
        "# CoordinateSystem = RAS\n3,5,6,7,0,0,0,1,1,1,0,pr,[workbench: missing; confidence 1.0],,2,0\n",
        encoding="utf-8",
    )
    pr = read_fcsv(path, "skull").landmarks["pr"]
    assert (
        pr.status == "placed" and pr.position.tolist() == [5.0, 6.0, 7.0] and pr.description == ""
    )


def test_a_bad_position_status_is_named(tmp_path: Path) -> None:
    path = tmp_path / "bad.fcsv"
    path.write_text("# CoordinateSystem = LPS\n1,1,2,3,0,0,0,1,1,1,0,n,,,suggested,0\n", "utf-8")
    with pytest.raises(InputError, match="positionStatus 'suggested'") as err:
        read_fcsv(path, "skull")
    assert str(path) in str(err.value)


def test_a_slicer_mrk_json_with_missing_points(tmp_path: Path) -> None:
    """Slicer writes "position": "" for points without one; they come in as missing."""
    doc = {
        "markups": [
            {
                "type": "Fiducial",
                "coordinateSystem": "LPS",
                "controlPoints": [
                    {"label": "n", "position": [-1.0, -80.0, 10.0], "positionStatus": "defined"},
                    {"label": "gn", "position": "", "positionStatus": "missing"},
                    {"label": "pr", "position": [0, 0, 0], "positionStatus": "undefined"},
                    {
                        "label": "g",
                        "position": [-2.0, -85.0, 20.0],
                        "positionStatus": "defined",
                        "description": "[workbench: suggested; confidence 0.5]",
                    },
                ],
            }
        ]
    }
    path = tmp_path / "s.mrk.json"
    path.write_text(json.dumps(doc), encoding="utf-8")
    lms = read_landmarks(path, "skull", allow_undefined=True).landmarks
    assert lms["n"].position.tolist() == [1.0, 80.0, 10.0]
    assert lms["gn"].status == "missing" and np.isnan(lms["gn"].position).all()
    assert lms["pr"].status == "missing" and np.isnan(lms["pr"].position).all()
    assert (lms["g"].status, lms["g"].confidence, lms["g"].description) == ("suggested", 0.5, "")


@pytest.mark.parametrize("ext", [".mrk.json", ".json"], ids=["deep-json-mrk", "deep-json-plain"])
def test_a_deeply_nested_landmark_file_is_an_input_error(tmp_path: Path, capsys, ext) -> None:
    path = tmp_path / f"deep{ext}"
    path.write_text("[" * 100_000 + "]" * 100_000, encoding="utf-8")
    with pytest.raises(InputError, match="nests"):
        read_landmarks(path, "skull")
    assert main(["landmarks", "check", str(path), "--surface", "skull"]) == 2
    err = capsys.readouterr().err
    assert "nests 100000 levels" in err and "Traceback" not in err


# ------------------------------------------------------------------ glTF
def test_glb_vertices_are_the_ply_frame_in_metres(tmp_path: Path, monkeypatch) -> None:
    """export_head_glb writes the head's own frame (that of its PLYs), not the head frame.

    A stand-in Animator keeps this fast: it works in a mirrored "head frame" and
    hands back its results in the stored frame, as the real one does for a
    reconstruction of a mirrored skull file.
    """
    from workbench.io.template_pack import FILES
    from workbench.services.animation import gltf as gltf_animation

    mesh, _ = _skull_and_points()
    mirror = np.diag([-1.0, 1.0, 1.0])  # stored -> head frame (a reflection)
    shift = np.array([3.0, -4.0, 5.0])

    class Head:
        meshes = {
            "skin": mesh,
            "mandible": Mesh(mesh.vertices[:40] * 0.5, np.array([[0, 1, 2], [1, 2, 3]])),
        }
        tmj_axis = (np.zeros(3), np.array([1.0, 0.0, 0.0]))

    class FakeAnimator:
        def __init__(self, head) -> None:
            self.head = Head()
            self.head.meshes = {
                k: Mesh(m.vertices @ mirror.T, m.faces[:, ::-1]) for k, m in head.meshes.items()
            }
            self.jaw_deg, self.protrusion_mm = 0.0, 0.0

        def set_expression(self, pose) -> None:
            self.jaw_deg = 10.0

        def settle(self) -> int:
            return 1

        def skin_in_head_frame(self) -> np.ndarray:
            return self.head.meshes["skin"].vertices + shift

        def skin(self) -> Mesh:
            return Mesh(self.skin_in_head_frame() @ mirror.T, Head.meshes["skin"].faces)

        def meshes(self) -> dict[str, Mesh]:
            m = self.head.meshes["mandible"]
            return {"skin": self.skin(), "mandible": Mesh((m.vertices + 1.0) @ mirror.T, m.faces)}

    monkeypatch.setattr(gltf_animation, "Animator", FakeAnimator)
    head = Head()
    ply = write_mesh(tmp_path / "skin.ply", head.meshes["skin"])  # as head/skin.ply is written
    assert "skin.ply" in FILES
    out, settled, _ = gltf_animation.export_head_glb(
        head, tmp_path / "head.glb", ["smile"], frame="the skull file's frame"
    )
    gltf = pygltflib.GLTF2().load(str(out))
    assert gltf.asset.extras["units"] == "m" and gltf.asset.extras["mm_per_unit"] == 1000
    assert gltf.asset.extras["frame"] == "the skull file's frame"
    blob = gltf.binary_blob()

    def read(index: int) -> np.ndarray:
        acc = gltf.accessors[index]
        view = gltf.bufferViews[acc.bufferView]
        data = np.frombuffer(blob, "<f4", acc.count * 3, view.byteOffset + (acc.byteOffset or 0))
        return data.reshape(-1, 3).astype(float)

    by_name = {n.name: n for n in gltf.nodes}
    root = gltf.nodes[gltf.scenes[gltf.scene].nodes[0]]
    scale = np.asarray(root.scale or [1.0, 1.0, 1.0])
    assert all(n.matrix is None and n.rotation is None for n in gltf.nodes)
    prim = gltf.meshes[by_name["skin"].mesh].primitives[0]
    rest = read(prim.attributes.POSITION) * scale * 1000.0
    ply_vertices = read_mesh(ply, units="mm").mesh.vertices
    assert np.abs(rest - ply_vertices).max() < 0.01  # the glTF and the PLY share a frame
    faces = np.frombuffer(
        blob,
        "<u4",
        gltf.accessors[prim.indices].count,
        gltf.bufferViews[gltf.accessors[prim.indices].bufferView].byteOffset,
    ).reshape(-1, 3)
    assert np.array_equal(faces, head.meshes["skin"].faces)  # the stored winding
    smiled = rest + read(prim.targets[0]["POSITION"]) * scale * 1000.0
    assert np.abs(smiled - (ply_vertices + shift * [-1, 1, 1])).max() < 0.01
    mand = gltf.meshes[by_name["mandible"].mesh].primitives[0]
    moved = read(mand.targets[0]["POSITION"]) * 1000.0
    assert np.abs(moved - [-1.0, 1.0, 1.0]).max() < 0.01
    assert settled.skin["smile"].shape == settled.stored_skin["smile"].shape


def test_landmark_csv_description_guarded_and_read_back(tmp_path: Path) -> None:
    """A landmark description that would start a spreadsheet formula is written guarded
    (leading apostrophe) in the plain CSV, and read back as the user typed it."""
    from workbench.core.landmarks import Landmark, LandmarkSet
    from workbench.io.markups import read_landmarks, write_landmarks

    text = '=HYPERLINK("http://x")'
    lms = LandmarkSet("skull", [Landmark("g", np.array([1.0, 2.0, 3.0]), description=text)])
    path = tmp_path / "lm.csv"
    write_landmarks(path, lms)
    assert "'=HYPERLINK" in path.read_text(encoding="utf-8")
    (back,) = list(read_landmarks(path, "skull").landmarks)
    assert back.description == text


@pytest.mark.parametrize("ext", [".ply", ".stl", ".obj", ".vtk", ".vtp"])
def test_directions_given_for_an_lps_file_turn_with_it(tmp_path: Path, ext) -> None:
    """``--anterior``/``--superior`` are in the file's own numbers: for a mesh tagged
    SPACE=LPS (read with x and y negated) they are negated the same way."""
    import argparse

    from workbench.cli.reconstruct_cmd import orientation_of
    from workbench.io.meshes import file_space, write_mesh

    skull, _ = _skull_and_points()
    for space, sign in (("LPS", -1.0), ("RAS", 1.0)):
        path = write_mesh(tmp_path / f"bone_{space}{ext}", skull, space=space)
        assert file_space(path) == space
        args = argparse.Namespace(anterior=(0.0, -1.0, 0.0), superior=(0.0, 0.0, 1.0), left=None)
        anterior, superior = orientation_of(args, str(path))
        assert anterior == (0.0, -1.0 * sign, 0.0) and superior == (0.0, 0.0, 1.0)


def test_meshlab_points_on_an_lps_mesh_turn_with_it(tmp_path: Path) -> None:
    """A MeshLab ``.pp`` holds the mesh file's own numbers: on an LPS-tagged skull they are
    turned with the mesh, so the case's landmarks stay on the bone."""
    from workbench.io.markups import write_pp
    from workbench.io.meshes import write_mesh
    from workbench.services.case.case_setup import start_case_from_skull

    skull, points = _skull_and_points()
    raw = Mesh(skull.vertices * [-1.0, -1.0, 1.0], skull.faces)  # LPS numbers of the skull
    path = write_mesh(tmp_path / "bone.ply", raw, space="LPS")
    pp = tmp_path / "points.pp"
    write_pp(pp, points.transformed(np.diag([-1.0, -1.0, 1.0, 1.0])))  # placed in MeshLab
    opened = start_case_from_skull(path, units="mm", landmarks_path=pp)
    got = opened.case.landmarks["skull"].as_dict()
    want = points.as_dict()
    assert max(float(np.linalg.norm(got[c] - want[c])) for c in want) < 1e-9


def test_validate_directions_turn_with_an_lps_skull(tmp_path: Path) -> None:
    """A validate manifest's directions follow the skull file the same way (a CT keeps its
    volume's numbers, so its directions stay as given)."""
    from workbench.io.meshes import write_mesh
    from workbench.services.validation.run import ValidationCase, in_read_frame

    skull, _ = _skull_and_points()
    lps = write_mesh(tmp_path / "bone.ply", skull, space="LPS")
    ras = write_mesh(tmp_path / "bone_ras.ply", skull)
    given = ((0.0, -1.0, 0.0), (0.0, 0.0, 1.0))
    turned = in_read_frame(ValidationCase("c", lps, ras, orientation=given)).orientation
    assert turned == ((0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    kept = in_read_frame(ValidationCase("c", ras, lps, orientation=given)).orientation
    assert kept == given
    ct = tmp_path / "head.nii.gz"
    assert in_read_frame(ValidationCase("c", ct, ras, orientation=given)).orientation == given
