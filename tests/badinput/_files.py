"""Bad input files for the bad-input corpus, written into a folder (all lengths mm).

``make_bad_files(folder)`` returns ``{name: path}``.  The good pieces are
small: an ellipsoid "skull" of 180 x 150 x 200 mm (1,280 triangles), its
surface landmarks, a two-row depth table.  Every bad file differs from a
good one by one problem, so each corpus entry fails for one reason.
"""

from __future__ import annotations

import gzip
import json
from pathlib import Path

import numpy as np

from workbench.core.landmarks import Landmark, LandmarkSet
from workbench.core.mesh import Mesh

#: half-axes (mm) of the stand-in skull: x left, y up, z toward the face
SKULL_HALF_AXES_MM = (75.0, 90.0, 100.0)
#: its centre, off the origin so that negating x and y (LPS <-> RAS) moves points off it
SKULL_CENTRE_MM = (40.0, 60.0, 0.0)


def sphere(levels: int = 3) -> Mesh:
    """Unit icosphere-like sphere (subdivided octahedron), outward winding."""
    v = [[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]]
    f = [[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]]
    verts = [np.array(p, float) for p in v]
    faces = [tuple(t) for t in f]
    for _ in range(levels):
        cache: dict[tuple[int, int], int] = {}

        def mid(a: int, b: int, cache: dict[tuple[int, int], int] = cache) -> int:
            key = (min(a, b), max(a, b))
            if key not in cache:
                p = verts[a] + verts[b]
                verts.append(p / np.linalg.norm(p))
                cache[key] = len(verts) - 1
            return cache[key]

        new = []
        for a, b, c in faces:
            ab, bc, ca = mid(a, b), mid(b, c), mid(c, a)
            new += [(a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca)]
        faces = new
    return Mesh(np.array(verts), np.array(faces))


def skull_mesh() -> Mesh:
    s = sphere(4)
    return Mesh(s.vertices * np.array(SKULL_HALF_AXES_MM) + SKULL_CENTRE_MM, s.faces)


def _ply(path: Path, vertices: np.ndarray, faces: np.ndarray) -> Path:
    """ASCII PLY written by hand, so non-finite numbers reach the file as they are."""
    lines = [
        "ply",
        "format ascii 1.0",
        f"element vertex {len(vertices)}",
        "property float x",
        "property float y",
        "property float z",
        f"element face {len(faces)}",
        "property list uchar int vertex_indices",
        "end_header",
    ]
    lines += [" ".join(repr(float(c)) for c in p) for p in vertices]
    lines += ["3 " + " ".join(str(int(i)) for i in t) for t in faces]
    path.write_text("\n".join(lines) + "\n", encoding="ascii")
    return path


#: skull codes placed on the stand-in skull: (code, direction in the skull frame)
_SKULL_POINTS = {
    "g": (0.0, 0.35, 1.0),
    "n": (0.0, 0.25, 1.0),
    "po_l": (1.0, 0.05, 0.0),
    "po_r": (-1.0, 0.05, 0.0),
    "or_l": (0.35, 0.1, 0.9),
    "or_r": (-0.35, 0.1, 0.9),
    "pr": (0.0, -0.35, 1.0),
    "gn": (0.0, -0.8, 0.7),
}


def surface_point(direction: tuple[float, float, float], offset_mm: float = 0.0) -> np.ndarray:
    """Where the ray from the centre along ``direction`` meets the ellipsoid, pushed out."""
    d = np.asarray(direction, float)
    d = d / np.linalg.norm(d)
    t = 1.0 / np.sqrt(np.sum((d / np.array(SKULL_HALF_AXES_MM)) ** 2))
    return d * (t + offset_mm) + SKULL_CENTRE_MM


def _landmarks(
    offset_mm: float = 0.0, flip: bool = False, points: dict | None = None
) -> LandmarkSet:
    out = []
    for code, d in (points or _SKULL_POINTS).items():
        p = surface_point(d, offset_mm)
        if flip:  # RAS numbers in a file that says LPS
            p = p * np.array([-1.0, -1.0, 1.0])
        out.append(Landmark(code, p, status="placed"))
    return LandmarkSet("skull", out)


def _mrk(path: Path, points: list[tuple[str, list[float]]], system: str = "LPS") -> Path:
    doc = {
        "@schema": "https://raw.githubusercontent.com/slicer/slicer/master/Modules/Loadable/"
        "Markups/Resources/Schema/markups-schema-v1.0.3.json#",
        "markups": [
            {
                "type": "Fiducial",
                "coordinateSystem": system,
                "controlPoints": [{"label": c, "position": p} for c, p in points],
            }
        ],
    }
    path.write_text(json.dumps(doc), encoding="utf-8")
    return path


def _nifti(
    path: Path,
    data: np.ndarray,
    zooms: tuple[float, float, float],
    sform_row_y: tuple[float, float, float, float] | None = None,
) -> Path:
    """NIfTI-1 with the voxel sizes patched into the header bytes as given (even 0 or NaN).

    qform and sform codes are 0, so readers take the affine from ``pixdim``;
    ``sform_row_y`` sets sform code 1 with that second row instead.
    """
    import struct

    import nibabel as nib

    img = nib.Nifti1Image(data, np.eye(4))
    img.header.set_xyzt_units("mm")
    img.header.set_qform(None, code=0)
    img.header.set_sform(None, code=0)
    nib.save(img, str(path))
    raw = bytearray(path.read_bytes())
    raw[80:92] = struct.pack("<3f", *zooms)
    raw[252:256] = struct.pack("<2h", 0, 0)
    if sform_row_y is not None:
        raw[254:256] = struct.pack("<h", 1)
        raw[280:296] = struct.pack("<4f", zooms[0], 0, 0, 0)
        raw[296:312] = struct.pack("<4f", *sform_row_y)
        raw[312:328] = struct.pack("<4f", 0, 0, zooms[2], 0)
    path.write_bytes(bytes(raw))
    return path


def _table(
    path: Path,
    rows: list[str],
    header: str = "landmark_code,skin_code,group,sex,build,mean_mm,sd_mm,n,source",
) -> Path:
    path.write_text("\n".join([header, *rows]) + "\n", encoding="utf-8")
    return path


def make_bad_files(folder: Path) -> dict[str, Path]:
    from workbench.io.markups import write_landmarks
    from workbench.io.meshes import write_mesh

    folder.mkdir(parents=True, exist_ok=True)
    f: dict[str, Path] = {}
    skull = skull_mesh()
    v, t = skull.vertices, skull.faces
    f["skull"] = write_mesh(folder / "skull.ply", skull)
    f["skull_cm"] = write_mesh(folder / "skull_cm.ply", skull.scaled(0.1))
    bad = v.copy()
    bad[[3, 10, 20]] = np.nan
    f["nan_skull"] = _ply(folder / "nan_skull.ply", bad, t)
    bad = v.copy()
    bad[5, 1] = np.inf
    f["inf_skull"] = _ply(folder / "inf_skull.ply", bad, t)
    f["empty_ply"] = folder / "empty.ply"
    f["empty_ply"].write_bytes(b"")
    f["garbage_ply"] = folder / "garbage.ply"
    f["garbage_ply"].write_bytes(np.random.default_rng(1).bytes(4096))
    f["header_only_ply"] = folder / "header_only.ply"
    f["header_only_ply"].write_text(
        "ply\nformat ascii 1.0\nelement vertex 3\n"
        "property float x\nproperty float y\nproperty float z\n"
        "element face 1\nproperty list uchar int vertex_indices\n"
        "end_header\n0 0 0\n",
        encoding="ascii",
    )
    f["bad_index_ply"] = _ply(folder / "bad_index.ply", v[:3], np.array([[0, 1, 7]]))
    f["wrong_ext"] = folder / "skull.txt"
    f["wrong_ext"].write_bytes(f["skull"].read_bytes())
    f["folder_ply"] = folder / "folder.ply"
    f["folder_ply"].mkdir()
    f["missing"] = folder / "does_not_exist.ply"
    f["missing_landmarks"] = folder / "does_not_exist.mrk.json"
    # two triangles the size of a skull
    tri = np.array([[-80.0, -90, 0], [80, -90, 0], [80, 90, 0], [-80, 90, 0]])
    f["two_triangles"] = write_mesh(
        folder / "two_triangles.ply", Mesh(tri, np.array([[0, 1, 2], [0, 2, 3]]))
    )
    # a flat (coplanar) skull: the ellipsoid squashed to 0.5 mm deep
    centre = np.array(SKULL_CENTRE_MM)
    flat = (v - centre) * np.array([1.0, 1.0, 0.005]) + centre
    f["flat_skull"] = write_mesh(folder / "flat_skull.ply", Mesh(flat, t))
    # a line-like (collinear) skull: everything within 0.5 mm of the y axis
    line = (v - centre) * np.array([0.005, 1.0, 0.005]) + centre
    f["line_skull"] = write_mesh(folder / "line_skull.ply", Mesh(line, t))
    # non-manifold: three copies of one triangle fan sharing edges
    nm_faces = np.vstack([t, t[:40, [0, 2, 1]], t[:40]])
    f["nonmanifold"] = _ply(folder / "nonmanifold.ply", v, nm_faces)
    skin = (v - centre) * 1.08 + centre
    f["skin"] = write_mesh(folder / "skin.ply", Mesh(skin, t))
    # far away: the other surface 1 m off (no overlap for compare)
    f["far_skin"] = write_mesh(
        folder / "far_skin.ply", Mesh(skin + np.array([0.0, 0.0, 1000.0]), t)
    )
    bad = skin.copy()
    bad[7] = np.nan
    f["nan_skin"] = _ply(folder / "nan_skin.ply", bad, t)
    # scans for fit-scan: two heads in one file, a point cloud (vertices, no faces)
    f["two_heads"] = write_mesh(
        folder / "two_heads.ply",
        Mesh(np.vstack([skin, skin + np.array([300.0, 0.0, 0.0])]), np.vstack([t, t + len(skin)])),
    )
    cloud = folder / "point_cloud.ply"
    cloud.write_text(
        f"ply\nformat ascii 1.0\nelement vertex {len(skin)}\nproperty float x\nproperty float y\n"
        "property float z\nend_header\n"
        + "\n".join(" ".join(f"{c:.3f}" for c in p) for p in skin)
        + "\n",
        encoding="ascii",
    )
    f["point_cloud"] = cloud
    f["not_a_file_out"] = folder / "regular_file"
    f["not_a_file_out"].write_text("I am a file, not a folder\n", encoding="utf-8")
    # landmarks
    write_landmarks(folder / "skull.mrk.json", _landmarks(), coordinate_system="LPS")
    f["landmarks"] = folder / "skull.mrk.json"
    write_landmarks(folder / "off50.mrk.json", _landmarks(offset_mm=50.0), coordinate_system="LPS")
    f["landmarks_off50"] = folder / "off50.mrk.json"
    # RAS numbers in a file declared LPS: the reader negates x and y, the points leave the skull
    f["landmarks_flipped"] = _mrk(
        folder / "flipped.mrk.json",
        [(c, [float(x) for x in surface_point(d)]) for c, d in _SKULL_POINTS.items()],
        system="LPS",
    )
    f["landmarks_unknown"] = _mrk(
        folder / "unknown.mrk.json", [("g", [0, 31, 95]), ("zz_not_a_code", [1, 2, 3])]
    )
    f["landmarks_duplicate"] = _mrk(
        folder / "duplicate.mrk.json", [("g", [0, 31, 95]), ("g", [0, 30, 95])]
    )
    f["landmarks_partial_nan"] = folder / "partial_nan.csv"
    f["landmarks_partial_nan"].write_text(
        "code,x_mm,y_mm,z_mm\ng,nan,91,95\nn,40,85,98\n", encoding="utf-8"
    )
    f["landmarks_empty"] = folder / "empty.mrk.json"
    f["landmarks_empty"].write_bytes(b"")
    f["landmarks_garbage"] = folder / "garbage.mrk.json"
    f["landmarks_garbage"].write_text("{this is not json", encoding="utf-8")
    f["landmarks_wrong_ext"] = folder / "points.docx"
    f["landmarks_wrong_ext"].write_text("g,0,0,0\n", encoding="utf-8")
    porion = surface_point(_SKULL_POINTS["po_l"])
    f["porions_same"] = _mrk(
        folder / "porions_same.mrk.json",
        [
            (c, [float(x) for x in (porion if c.startswith("po") else surface_point(d))])
            for c, d in _SKULL_POINTS.items()
        ],
        system="RAS",
    )
    f["landmarks_collinear"] = _mrk(
        folder / "collinear.mrk.json",
        [(c, [40.0, 60.0 + i * 5.0, 100.0]) for i, c in enumerate(_SKULL_POINTS)],
        system="RAS",
    )
    # depth tables
    good_rows = ["g,g',adult,pooled,pooled,5.5,1.2,40,t", "n,n',adult,pooled,pooled,6.5,1.4,40,t"]
    f["table_5500"] = _table(
        folder / "table_5500.csv", ["g,g',adult,pooled,pooled,5500,1.2,40,t", good_rows[1]]
    )
    f["table_zero"] = _table(
        folder / "table_zero.csv", ["g,g',adult,pooled,pooled,0,1.2,40,t", good_rows[1]]
    )
    f["table_negative_sd"] = _table(
        folder / "table_negative_sd.csv", ["g,g',adult,pooled,pooled,5.5,-1.2,40,t", good_rows[1]]
    )
    f["table_huge_sd"] = _table(
        folder / "table_huge_sd.csv", ["g,g',adult,pooled,pooled,5.5,900,40,t", good_rows[1]]
    )
    f["table_missing_columns"] = _table(
        folder / "table_missing.csv", ["g,5.5", "n,6.5"], header="landmark_code,mean_mm"
    )
    f["table_unknown_code"] = _table(
        folder / "table_unknown.csv", ["zorg,,adult,pooled,pooled,5.5,1.2,40,t", good_rows[1]]
    )
    f["table_duplicate"] = _table(folder / "table_duplicate.csv", [good_rows[0]] * 2)
    f["table_text_depth"] = _table(
        folder / "table_text.csv", ["g,g',adult,pooled,pooled,five,1.2,40,t", good_rows[1]]
    )
    f["table_empty"] = folder / "table_empty.csv"
    f["table_empty"].write_text("", encoding="utf-8")
    f["table_nan"] = _table(
        folder / "table_nan.csv", ["g,g',adult,pooled,pooled,nan,1.2,40,t", good_rows[1]]
    )
    # guides
    f["guides_garbage"] = folder / "guides.json"
    f["guides_garbage"].write_text("[1, 2, 3", encoding="utf-8")
    # volumes (a 24^3 block with a bright ball)
    zz, yy, xx = np.mgrid[:24, :24, :24]
    r = np.sqrt((xx - 12.0) ** 2 + (yy - 12.0) ** 2 + (zz - 12.0) ** 2)
    ball = (np.clip(1.0 - r / 10.0, 0.0, 1.0) * 1500.0 - 1000.0).astype(np.float32)
    f["ct_good"] = _nifti(folder / "ct_good.nii", ball.astype(np.int16), (8.0, 8.0, 8.0))
    f["ct_voxel0"] = _nifti(folder / "ct_voxel0.nii", ball.astype(np.int16), (0.0, 0.0, 0.0))
    f["ct_km"] = _nifti(
        folder / "ct_km.nii", ball.astype(np.int16), (3200000.0, 3200000.0, 3200000.0)
    )
    nan_ball = ball.copy()
    nan_ball[3:6, 3:6, 3:6] = np.nan
    f["ct_nan_voxels"] = _nifti(folder / "ct_nan_voxels.nii", nan_ball, (8.0, 8.0, 8.0))
    f["ct_nan_spacing"] = _nifti(
        folder / "ct_nan_spacing.nii",
        ball.astype(np.int16),
        (8.0, 8.0, 8.0),
        sform_row_y=(0.0, np.nan, 0.0, 0.0),
    )
    f["ct_garbage"] = folder / "ct_garbage.nii.gz"
    f["ct_garbage"].write_bytes(gzip.compress(b"not a nifti" * 40))
    f["ct_empty"] = folder / "ct_empty.nrrd"
    f["ct_empty"].write_bytes(b"")
    # a growth norms table whose SD column is empty (issue 15)
    f["norms_no_sd"] = folder / "norms_no_sd.csv"
    f["norms_no_sd"].write_text(
        "measurement_id,name,kind,a,b,ethnicity,sex,age_years,mean_mm,sd_mm,n,source\n"
        "nasal_width,Nasal Width,euclidean,al_l,al_r,European,male,3,28.1,,,mine\n"
        "nasal_width,Nasal Width,euclidean,al_l,al_r,European,male,18,36.0,,,mine\n",
        encoding="utf-8",
    )
    return f
