"""The incomplete real skull case (``benchmarks/cases/cut_skull.py``) on the 2 mm VHF CT.

The generator runs once into a temporary cache folder; the checks below
recompute every region from the recorded parameters and the written meshes
(never from the generator's own check results).
"""

from __future__ import annotations

import hashlib
import json
import sys
from pathlib import Path

import numpy as np
import pytest

from workbench.core.mesh import Mesh, boundary_loops
from workbench.io.meshes import read_mesh
from workbench.services.ct.ct_mesh import mesh_from_ct

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from benchmarks.cases import cut_skull  # noqa: E402

OUTPUTS = ("cut_skull.ply", "skin.ply", "full_bone.ply", "cut_skull.json")


@pytest.fixture(scope="module")
def vhf_2mm(shared_data: Path) -> Path:
    path = shared_data / "vhp_female_head_ct" / "vhf_head_ct_2mm.nii.gz"
    if not path.is_file():
        pytest.fail(f"real test data not found: {path}", pytrace=False)
    return path


@pytest.fixture(scope="module")
def case(vhf_2mm: Path, tmp_path_factory: pytest.TempPathFactory) -> dict:
    out = tmp_path_factory.mktemp("cut_skull") / "case"
    record = cut_skull.make_cut_skull(vhf_2mm, out)
    meshes = {name: read_mesh(out / name).mesh for name in OUTPUTS[:3]}
    return {"out": out, "record": record, "meshes": meshes, "spacing": 2.0}


def _unit(v) -> np.ndarray:
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v)


def test_outputs_and_record(case: dict, vhf_2mm: Path) -> None:
    out, record = case["out"], case["record"]
    assert not record["cached"]
    for name in OUTPUTS:
        assert (out / name).is_file(), name
    assert not [p.name for p in out.parent.iterdir() if ".tmp-" in p.name]  # temp folder gone
    on_disk = json.loads((out / "cut_skull.json").read_text(encoding="utf-8"))
    assert on_disk == {k: v for k, v in record.items() if k not in ("cached", "out_dir")}
    assert on_disk["ct"]["sha256"] == hashlib.sha256(vhf_2mm.read_bytes()).hexdigest()
    assert on_disk["credit"] == "Courtesy of the U.S. National Library of Medicine"
    assert "frozen snapshot and may not reflect the most current" in on_disk["credit_note"]
    assert on_disk["frame"] == "RAS" and on_disk["units"] == "mm"
    for name, mesh in case["meshes"].items():
        assert on_disk["outputs"][name]["n_faces"] == mesh.n_faces
        assert on_disk["outputs"][name]["bytes"] == (out / name).stat().st_size


def test_cut_skull_is_one_nonempty_mesh_smaller_than_the_full_bone(case: dict) -> None:
    cut, full = case["meshes"]["cut_skull.ply"], case["meshes"]["full_bone.ply"]
    assert cut.n_faces > 50_000
    assert len(np.unique(cut.face_components)) == 1
    assert cut.area < full.area
    # mandible (~45 cm^3 of bone), the vault and the defect: a quarter of the surface goes
    assert cut.area < 0.85 * full.area


def test_same_frame_as_mesh_from_ct(case: dict, vhf_2mm: Path) -> None:
    full = case["meshes"]["full_bone.ply"]
    direct = mesh_from_ct(vhf_2mm, "bone", iso=300).mesh
    assert full.n_faces == direct.n_faces
    np.testing.assert_allclose(full.vertices, direct.vertices, atol=1e-9)
    skin = case["meshes"]["skin.ply"]
    lo, hi = skin.bounds
    assert np.all(case["meshes"]["cut_skull.ply"].bounds[0] >= lo - 1e-6)
    assert np.all(case["meshes"]["cut_skull.ply"].bounds[1] <= hi + 1e-6)


def test_nothing_above_the_vault_cut_and_the_rim_is_open(case: dict) -> None:
    cut_plane = case["record"]["removed"]["vault_cut"]
    point, normal = np.asarray(cut_plane["plane_point_mm"]), _unit(cut_plane["plane_normal"])
    cut, full = case["meshes"]["cut_skull.ply"], case["meshes"]["full_bone.ply"]
    height = (cut.vertices - point) @ normal
    assert height.max() <= 1e-6
    assert np.count_nonzero((full.vertices - point) @ normal > 0) > 1000  # the vault was there
    # open rim: boundary vertices lie on the plane, and no triangle caps it
    on_plane = np.abs(height) < 1e-6
    border = np.unique(np.concatenate(boundary_loops(cut)))
    assert np.count_nonzero(on_plane[border]) > 200
    assert not on_plane[np.asarray(cut.faces)].all(axis=1).any()
    # the plane is roughly parallel to the axial (here, Frankfort) plane, above the orbits
    assert normal[2] > np.cos(np.radians(10))
    rims = case["record"]["landmarks"]["orbits"]
    for side in ("right", "left"):
        above = (point - np.asarray(rims[side]["upper_rim_mm"])) @ normal
        assert 35.0 <= above <= 50.0


def test_no_vertex_in_the_frontal_hole(case: dict) -> None:
    hole = case["record"]["removed"]["frontal_hole"]
    centre, axis = np.asarray(hole["centre_mm"]), _unit(hole["axis"])
    margin = case["spacing"]  # marching-cubes vertices sit within one voxel of kept voxels

    def inside(mesh: Mesh) -> np.ndarray:
        d = mesh.vertices - centre
        t = d @ axis
        radial = np.linalg.norm(d - t[:, None] * axis, axis=1)
        return (
            (radial <= hole["radius_mm"] - margin)
            & (t >= -hole["depth_in_mm"] + margin)
            & (t <= hole["depth_out_mm"] - margin)
        )

    assert np.count_nonzero(inside(case["meshes"]["full_bone.ply"])) > 200  # there was bone
    assert np.count_nonzero(inside(case["meshes"]["cut_skull.ply"])) == 0
    # off the midline, above the orbit of its side, in the frontal bone (front of the skull)
    lm = case["record"]["landmarks"]
    orbit = lm["orbits"][hole["side"]]
    assert abs(centre[0] - lm["midline_mm"]) > 15.0
    assert abs(centre[0] - orbit["centre_mm"][0]) < 10.0
    assert centre[2] > orbit["upper_rim_mm"][2] + 10.0
    assert axis[1] > 0.5  # faces forward (+y anterior)


def _anterior_columns(mesh: Mesh, landmarks: dict) -> tuple[np.ndarray, np.ndarray]:
    """Vertices within 30 mm of the midline, at most 40 mm behind the orbital rims' front;
    and every vertex's height relative to orbitale (mm, +z superior)."""
    orbits = landmarks["orbits"]
    z_orbitale = np.mean([orbits[s]["orbitale_mm"][2] for s in orbits])
    y_front = max(orbits[s]["upper_rim_mm"][1] for s in orbits)
    v = mesh.vertices
    columns = (np.abs(v[:, 0] - landmarks["midline_mm"]) <= 30.0) & (v[:, 1] >= y_front - 40.0)
    return columns, v[:, 2] - z_orbitale


def test_no_mandible_and_the_maxilla_is_intact(case: dict) -> None:
    landmarks = case["record"]["landmarks"]
    full, cut = case["meshes"]["full_bone.ply"], case["meshes"]["cut_skull.ply"]
    # the chin: the front of the face more than 45 mm below orbitale holds the mandible's
    # symphysis and lower teeth; the maxilla with the upper teeth ends above that
    f_cols, f_h = _anterior_columns(full, landmarks)
    c_cols, c_h = _anterior_columns(cut, landmarks)
    assert np.count_nonzero(f_cols & (f_h < -45.0)) > 500  # fails if the mandible were kept
    assert np.count_nonzero(c_cols & (c_h < -45.0)) == 0
    assert f_h[f_cols].min() < -75.0  # the chin of the full bone is far lower

    # the maxilla and the upper teeth (10-45 mm below orbitale) are untouched
    def area(mesh: Mesh, vmask: np.ndarray) -> float:
        return float(mesh.face_areas[vmask[np.asarray(mesh.faces)].all(axis=1)].sum())

    full_maxilla = area(full, f_cols & (f_h >= -45.0) & (f_h <= -10.0))
    cut_maxilla = area(cut, c_cols & (c_h >= -45.0) & (c_h <= -10.0))
    assert full_maxilla > 2000.0
    assert cut_maxilla == pytest.approx(full_maxilla, rel=0.01)
    assert c_h[c_cols].min() < -25.0  # upper teeth / alveolar process present
    # the removed bone is a mandible-sized piece, below the orbits and U-wide
    mandible = case["record"]["removed"]["mandible"]
    assert 25.0 < mandible["volume_removed_cm3"] < 80.0
    assert mandible["width_mm"] > 80.0
    assert mandible["bounds_mm"][1][2] < min(
        landmarks["orbits"][s]["orbitale_mm"][2] for s in ("right", "left")
    )


def test_second_call_is_a_no_op(case: dict, vhf_2mm: Path) -> None:
    out = case["out"]
    before = {name: (out / name).stat().st_mtime_ns for name in OUTPUTS}
    again = cut_skull.make_cut_skull(vhf_2mm, out)
    assert again["cached"]
    assert {name: (out / name).stat().st_mtime_ns for name in OUTPUTS} == before
    assert again["ct"]["sha256"] == case["record"]["ct"]["sha256"]


def test_clip_by_plane_is_exact_and_open() -> None:
    # a closed unit-ish box surface (12 triangles), clipped by an oblique plane
    v = np.array([[x, y, z] for x in (0, 10) for y in (0, 10) for z in (0, 10)], float)
    f = np.array(
        [
            [0, 1, 3],
            [0, 3, 2],
            [4, 6, 7],
            [4, 7, 5],
            [0, 4, 5],
            [0, 5, 1],
            [2, 3, 7],
            [2, 7, 6],
            [0, 2, 6],
            [0, 6, 4],
            [1, 5, 7],
            [1, 7, 3],
        ]
    )
    box = Mesh(v, f)
    point, normal = np.array([5.0, 5.0, 6.0]), _unit([0.1, -0.2, 1.0])
    clipped = cut_skull.clip_by_plane(box, point, normal)
    h = (clipped.vertices - point) @ normal
    assert h.max() <= 1e-9 and h.min() < -5.0
    loops = boundary_loops(clipped)
    assert len(loops) == 1 and np.all(np.abs(h[loops[0]]) < 1e-9)  # one open rim on the plane
    assert np.all(clipped.edge_face_counts <= 2)
    # area below the plane: the four walls' parts and the floor
    heights = 6.0 - (np.array([0.1, -0.2]) @ (np.array([[0, 0], [10, 0], [0, 10], [10, 10]]).T - 5))
    assert clipped.area == pytest.approx(100.0 + 10 * heights.sum(), rel=1e-9)
