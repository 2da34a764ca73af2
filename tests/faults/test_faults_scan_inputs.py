"""Fault corpus, issue 29: scans that ran out of memory or time, and misleading refusals.

Every entry runs ``workbench fit-scan`` in-process on a damaged copy of a
reference skin (mm) and checks the exit status, that the message names the
file and the real problem (no traceback, no "unexpected error"), and that the
inputs are left as they were.  The 5 M-triangle scan is measured by
``benchmarks/bench_scan_limits.py``, not here.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

from tests.services._scans import damaged_skin
from workbench.cli.main import main
from workbench.core.mesh import Mesh, concatenate
from workbench.io.meshes import write_mesh


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _ball(radius: float, centre, n: int = 12) -> Mesh:
    from scipy.spatial import ConvexHull

    t, p = np.meshgrid(np.linspace(0.1, np.pi - 0.1, n), np.linspace(0, 2 * np.pi, 2 * n))
    pts = radius * np.c_[
        (np.sin(t) * np.cos(p)).ravel(), (np.sin(t) * np.sin(p)).ravel(), np.cos(t).ravel()
    ] + np.asarray(centre)
    return Mesh(pts, ConvexHull(pts).simplices)


def _write_obj(path: Path, mesh: Mesh, materials: int, image_names: list[str]) -> None:
    """An OBJ with per-vertex texture coordinates and ``materials`` materials (one
    ``map_Kd`` image each, ``image_names`` cycled), the triangles split among them."""
    v = mesh.vertices
    uv = (v[:, :2] - v[:, :2].min(0)) / np.ptp(v[:, :2], axis=0)
    lines = [f"mtllib {path.stem}.mtl"]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in v]
    lines += [f"vt {a:.6f} {b:.6f}" for a, b in uv]
    for k, chunk in enumerate(np.array_split(mesh.faces + 1, materials)):
        lines.append(f"usemtl m{k}")
        lines += [f"f {a}/{a} {b}/{b} {c}/{c}" for a, b, c in chunk]
    path.write_text("\n".join(lines) + "\n")
    mtl = [f"newmtl m{k}\nmap_Kd {image_names[k % len(image_names)]}" for k in range(materials)]
    (path.parent / f"{path.stem}.mtl").write_text("\n".join(mtl) + "\n")


@dataclass
class Case:
    """A damaged input: ``make(folder, scan, landmarks)`` writes it and returns the argv
    after ``fit-scan``; ``code`` the exit status; ``words`` must be in the message (or,
    on success, in the report's notes and repairs)."""

    make: Callable
    code: int
    words: tuple[str, ...]
    names: tuple[str, ...] = ()
    extra: dict = field(default_factory=dict)


def _scan_file(folder: Path, mesh: Mesh, name: str = "scan.ply") -> Path:
    return write_mesh(folder / name, mesh)


def _soup(folder, scan, lms):
    """Each triangle its own three vertices (an STL-style export)."""
    soup = Mesh(
        scan.vertices[scan.faces].reshape(-1, 3), np.arange(3 * scan.n_faces).reshape(-1, 3)
    )
    return [str(_scan_file(folder, soup, "soup.ply"))]


def _slivers(folder, scan, lms):
    """Zero-area triangles: repeated corners, and corners that are copies of one point."""
    rng = np.random.default_rng(1)
    pick = rng.choice(scan.n_faces, scan.n_faces // 20, replace=False)
    a, b = scan.faces[pick, 0], scan.faces[pick, 1]
    copies = np.arange(scan.n_vertices, scan.n_vertices + len(pick))
    v = np.vstack([scan.vertices, scan.vertices[a]])
    faces = np.vstack([scan.faces, np.c_[a, a, b], np.c_[a, copies, b]])
    return [str(_scan_file(folder, Mesh(v, faces), "slivers.ply"))]


def _reversed(folder, scan, lms):
    """Every triangle wound inward, and a third of them turned again (mixed winding)."""
    faces = scan.faces[:, ::-1].copy()
    turn = np.random.default_rng(2).random(len(faces)) < 0.3
    faces[turn] = faces[turn][:, ::-1]
    return [str(_scan_file(folder, Mesh(scan.vertices, faces), "reversed.ply"))]


def _blob(folder, scan, lms):
    """A head and a small blob 400 mm away (a marker, a crumb on the turntable)."""
    far = scan.vertices.mean(0) + (400.0, 0.0, 0.0)
    return [str(_scan_file(folder, concatenate([scan, _ball(12.0, far)]), "blob.ply"))]


def _second_head(folder, scan, lms):
    two = concatenate([scan, scan.with_vertices(scan.vertices + (300.0, 0.0, 0.0))])
    return [str(_scan_file(folder, two, "two_heads.ply"))]


def _landmarks(folder, scan, lms, change, name):
    from workbench.io.markups import write_landmarks

    path = folder / name
    write_landmarks(path, change(lms), coordinate_system="RAS")
    return [str(_scan_file(folder, scan)), "--landmarks", str(path)]


def _coincident(folder, scan, lms):
    from workbench.core.landmarks import Landmark, LandmarkSet

    first = next(lm for lm in lms if lm.is_defined)
    moved = [
        Landmark(lm.code, first.position, lm.status, lm.confidence, lm.description)
        if lm.code in ("prn", "sn")
        else lm
        for lm in lms
    ]
    return _landmarks(
        folder, scan, lms, lambda _: LandmarkSet(lms.surface, tuple(moved)), "coincident.mrk.json"
    )


def _far(folder, scan, lms):
    return _landmarks(folder, scan, lms, lambda s: s.transformed(_shift(10_000.0)), "far.mrk.json")


def _flipped(folder, scan, lms):
    lps = np.diag([-1.0, -1.0, 1.0, 1.0])
    return _landmarks(folder, scan, lms, lambda s: s.transformed(lps), "flipped.mrk.json")


def _shift(mm: float) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = (mm, 0.0, 0.0)
    return m


def _many_textures(folder, scan, lms):
    from PIL import Image

    Image.new("RGB", (8, 8), (200, 150, 120)).save(folder / "skin.png")
    names = []
    for k in range(70):
        name = f"t{k}.png"
        (folder / name).write_bytes((folder / "skin.png").read_bytes())
        names.append(name)
    _write_obj(folder / "many.obj", scan, 70, names)
    return [str(folder / "many.obj")]


CASES = {
    "row6-unwelded-scan": Case(_soup, 0, ("welded",)),
    "row6-too-many-textures": Case(_many_textures, 2, ("70 texture images", "more than")),
    "row9-zero-area-slivers": Case(_slivers, 0, ("zero area",)),
    "row9-reversed-winding": Case(_reversed, 0, ("wound", "outward")),
    "row9-distant-blob": Case(_blob, 0, ("left out 1 piece", "mm away")),
    "row9-second-head-named": Case(_second_head, 2, ("two_heads.ply", "a second piece")),
    "row9-landmarks-coincident": Case(
        _coincident, 2, ("coincident.mrk.json", "same point", "prn", "sn")
    ),
    "row9-landmarks-10m-away": Case(_far, 2, ("far.mrk.json", "off the scan", "scan.ply")),
    "row9-landmarks-lps-ras-flipped": Case(
        _flipped, 2, ("flipped.mrk.json", "x and y negated", "RAS vs LPS")
    ),
}


@pytest.mark.parametrize("row", list(CASES), ids=list(CASES))
def test_scan_input_fault(row, tmp_path, head_female, capsys):
    case = CASES[row]
    scan, lms = damaged_skin(head_female)
    argv = case.make(tmp_path, scan, lms)
    inputs = {p: _sha(p) for p in tmp_path.iterdir() if p.is_file()}
    out = tmp_path / "pack"
    try:
        code = main(["fit-scan", *argv, "--no-detail", "--out", str(out)])
    except SystemExit as exc:  # argparse
        code = exc.code
    captured = capsys.readouterr()
    text = captured.out + captured.err
    assert "Traceback" not in text and "unexpected error" not in text, text
    assert code == case.code, text
    assert {p: _sha(p) for p in inputs} == inputs  # inputs unchanged
    if code == 0:
        report = json.loads((out / "fit_report.json").read_text())
        told = " ".join(report["scan_preparation"]["repairs"] + report["warnings"])
        for word in case.words:
            assert word in told, told
        assert report["face_within_1mm_fraction"] >= 0.9
    else:
        assert not out.exists()
        assert Path(argv[-1] if "--landmarks" in argv else argv[0]).name in captured.err
        for word in case.words:
            assert word in captured.err, captured.err


def test_row9_texture_of_16384_squared_is_read(tmp_path, head_female):
    """The stated limit is 16384 x 16384; Pillow's own bomb guard (~179 M pixels) must not
    refuse it first.  Kept as uint8 at the working resolution."""
    from PIL import Image

    from workbench.core.limits import SCAN_TEXTURE_WORK_PIXELS
    from workbench.io.scan_colours import read_scan_colours

    scan, _ = damaged_skin(head_female)
    Image.new("L", (16384, 16384), 128).save(tmp_path / "big.png")
    _write_obj(tmp_path / "scan.obj", scan, 1, ["big.png"])
    colours = read_scan_colours(tmp_path / "scan.obj")
    assert colours is not None and colours.image is not None
    assert colours.image.dtype == np.uint8
    assert colours.image.shape[0] * colours.image.shape[1] <= SCAN_TEXTURE_WORK_PIXELS
    assert colours.image.shape[0] == 4096 and (colours.image == 128).all()


def test_row6_textures_over_the_stated_limits_are_refused_from_their_headers(tmp_path):
    """Beyond 16384 x 16384 one image, or the total over the stated count x pixels, is
    refused before anything is decoded, naming the file."""
    from PIL import Image

    from workbench.core.errors import InputError
    from workbench.io import scan_colours

    Image.new("L", (16385, 16384), 0).save(tmp_path / "huge.png")
    with pytest.raises(InputError, match=r"huge.png.*16385 x 16384 pixels"):
        scan_colours.read_textures([tmp_path / "huge.png"], "texture image")
    Image.new("L", (8192, 8192), 0).save(tmp_path / "t.png")
    paths = [tmp_path / "t.png"] * 33  # 33 x 8192²: over the stated 32 x 8192²
    with pytest.raises(InputError, match=r"t.png.*33 texture images hold 2,215 M pixels"):
        scan_colours.read_textures(paths, "texture image")


def test_row6_many_textures_are_shrunk_to_the_working_budget(tmp_path):
    """Twelve textures are kept as uint8 at a working resolution (together within the
    stated budget), not as one float32 atlas of them all."""
    from PIL import Image

    from workbench.core.limits import SCAN_TEXTURE_WORK_PIXELS
    from workbench.io.scan_colours import read_textures

    Image.new("RGB", (2048, 2048), (10, 20, 30)).save(tmp_path / "t.png")
    images = read_textures([tmp_path / "t.png"] * 12, "texture image")
    assert sum(i.shape[0] * i.shape[1] for i in images) <= SCAN_TEXTURE_WORK_PIXELS
    assert all(i.dtype == np.uint8 and i.shape == (1024, 1024, 3) for i in images)
