"""mesh_from_ct on the real headsq CT (anatomy checks) and on a DICOM series in HU."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from workbench.core.mesh import Mesh, validate
from workbench.io.volumes import read_volume
from workbench.services.ct.ct_mesh import CTMeshResult, mesh_from_ct

# PROVENANCE.md (pyvista/VTK, largest component).  VTK's NRRD reader flips the
# row (y) axis; we follow the NRRD spec (row 0 first), so y_ours = 201.6 - y_vtk.
FOV_Y = 201.6
SKIN_VTK = {"x": (4.9, 193.5), "y": (1.5, 186.1), "z": (0.0, 138.0), "faces": 55016}
BONE_VTK = {"x": (26.0, 175.1), "y": (13.5, 181.9), "z": (0.0, 138.0), "faces": 75190}


@pytest.fixture(scope="module")
def skin(headsq_nhdr) -> CTMeshResult:
    return mesh_from_ct(headsq_nhdr, tissue="skin")


@pytest.fixture(scope="module")
def bone(headsq_nhdr) -> CTMeshResult:
    return mesh_from_ct(headsq_nhdr, tissue="bone")


def _check_against_provenance(mesh: Mesh, ref: dict) -> None:
    (x0, y0, z0), (x1, y1, z1) = mesh.bounds
    np.testing.assert_allclose([x0, x1], ref["x"], atol=0.6)
    np.testing.assert_allclose([y0, y1], [FOV_Y - ref["y"][1], FOV_Y - ref["y"][0]], atol=0.6)
    np.testing.assert_allclose([z0, z1], ref["z"], atol=0.01)
    assert abs(mesh.n_faces - ref["faces"]) <= 0.10 * ref["faces"]


def test_headsq_skin_has_head_dimensions(skin):
    assert skin.iso == 500.0 and "VTK" in skin.rule and skin.units == "unknown"
    assert skin.frame == "LPS" and skin.warnings  # frame assumed for '3D-left-handed'
    np.testing.assert_allclose(skin.mesh.extent, [190, 185, 138], atol=3.0)
    _check_against_provenance(skin.mesh, SKIN_VTK)
    assert set(skin.timings_s) == {"read", "extract", "validate", "total"}
    assert skin.summary.startswith(f"{skin.mesh.n_vertices} vertices")
    assert skin.to_dict()["validation"]["n_faces"] == skin.mesh.n_faces


def test_headsq_bone_dimensions(bone):
    assert bone.iso == 1150.0
    _check_against_provenance(bone.mesh, BONE_VTK)


def _boundary_on_volume_cut(result: CTMeshResult, headsq) -> None:
    report = result.validation
    assert report.nonmanifold_edges == 0 and report.inconsistent_orientation_edges == 0
    assert report.n_components == 1 and report.degenerate_faces == 0
    upper = np.array(headsq.shape_ijk) - 1
    for loop in report.boundary_loops:
        ijk = headsq.physical_to_index(result.mesh.vertices[loop])
        on_cut = np.isclose(ijk, 0, atol=1e-6) | np.isclose(ijk, upper, atol=1e-6)
        assert on_cut.any(axis=1).all(), "a hole that is not at the edge of the scanned volume"


def _capped_volume(mesh: Mesh) -> float:
    """Enclosed volume with the z = const cuts closed: flux of (x, y, 0) / 2 (caps add 0)."""
    t = mesh.triangles
    centroid = t.mean(axis=1)
    cross = mesh.face_cross  # 2 x area-weighted normal
    return float(0.25 * (centroid[:, 0] * cross[:, 0] + centroid[:, 1] * cross[:, 1]).sum())


def test_surfaces_are_closed_except_at_the_volume_cut_and_face_outward(skin, bone, headsq_nhdr):
    headsq = read_volume(headsq_nhdr)
    for result in (skin, bone):
        _boundary_on_volume_cut(result, headsq)
        assert _capped_volume(result.mesh) > 0
    # skin encloses the head: 1.5-3.5 litres between the brow and the neck cuts
    assert 1.5e6 < _capped_volume(skin.mesh) < 3.5e6
    # at the most anterior skin point (lowest y: the face looks towards -y) normals point anteriorly
    mesh = skin.mesh
    tip = int(np.argmin(mesh.vertices[:, 1]))
    around = np.flatnonzero((mesh.faces == tip).any(axis=1))
    assert mesh.face_normals[around].mean(axis=0)[1] < -0.5


def _protrusion(v: np.ndarray, mid_x: float, z: float, dx: float) -> float:
    """How far the midline at height z lies in front of the skin dx mm to either side (mm)."""
    level = v[np.abs(v[:, 2] - z) < 2.0]
    front = lambda x: level[np.abs(level[:, 0] - x) < 2.5][:, 1].min()  # noqa: E731 (-y = anterior)
    return 0.5 * (front(mid_x - dx) + front(mid_x + dx)) - front(mid_x)


def test_face_has_a_nose_on_the_midline(skin):
    v = skin.mesh.vertices
    mid_x = skin.mesh.bounds[:, 0].mean()
    tip = v[np.argmin(v[:, 1])]  # most anterior skin point
    assert abs(tip[0] - mid_x) < 10.0  # on the midline
    assert 25.0 < tip[2] < 70.0  # below the brow (z = 0 is the top slice), above the mouth
    # at the tip's height the midline stands well proud of the cheeks; the forehead is flat
    assert _protrusion(v, mid_x, tip[2], 25.0) > 10.0
    assert _protrusion(v, mid_x, tip[2], 15.0) > 3.0
    assert _protrusion(v, mid_x, 5.0, 25.0) < 6.0
    assert _protrusion(v, mid_x, 5.0, 15.0) < 1.5


def test_mandible_and_chin_present_below_the_teeth(bone):
    v = bone.mesh.vertices
    mid_x = bone.mesh.bounds[:, 0].mean()
    # below the teeth (~z 90 mm), front half of the head: the mandibular arch
    arch = v[(v[:, 2] > 100) & (v[:, 2] < 125) & (v[:, 1] < 75)]
    assert len(arch) > 200
    assert np.ptp(arch[:, 0]) > 60.0  # spans both sides of the jaw
    chin = arch[np.abs(arch[:, 0] - mid_x) < 10.0]
    assert len(chin) and chin[:, 1].min() < 60.0  # symphysis in front, on the midline
    # the arch opens backwards: its sides lie behind its midline front
    sides = arch[np.abs(arch[:, 0] - mid_x) > 30.0]
    assert sides[:, 1].min() > chin[:, 1].min() + 10.0


def test_matches_pyvista_largest_component_counts(skin, bone, headsq_nhdr):
    pv = pytest.importorskip("pyvista")
    headsq = read_volume(headsq_nhdr)
    grid = pv.ImageData(dimensions=headsq.shape_ijk, spacing=tuple(headsq.spacing_mm))
    grid.point_data["ct"] = headsq.data.ravel()
    for result in (skin, bone):
        ref = grid.contour([result.iso], scalars="ct").connectivity("largest")
        assert abs(result.mesh.n_faces - ref.n_cells) <= 0.10 * ref.n_cells
        np.testing.assert_allclose(result.mesh.area, ref.area, rtol=0.02)


def test_decimated_smoothed_surface(headsq_nhdr):
    calls: list[tuple[str, float]] = []
    result = mesh_from_ct(
        headsq_nhdr,
        "bone",
        target_triangles=20000,
        smooth_iterations=5,
        progress=lambda s, f: calls.append((s, f)),
    )
    assert abs(result.mesh.n_faces - 20000) <= 1000
    assert result.validation.n_components == 1
    assert result.validation.inconsistent_orientation_edges == 0
    assert _capped_volume(result.mesh) > 0
    fractions = [f for _, f in calls]
    assert fractions == sorted(fractions) and fractions[0] == 0.0 and fractions[-1] == 1.0
    assert calls[0][0] == "reading volume" and calls[-1][0] == "done"


def _write_ct_series(folder: Path, hu: np.ndarray, spacing: tuple[float, float, float]) -> None:
    from pydicom.dataset import Dataset, FileMetaDataset
    from pydicom.uid import CTImageStorage, ExplicitVRLittleEndian, generate_uid

    folder.mkdir()
    series = generate_uid()
    for k in np.random.default_rng(0).permutation(len(hu)):
        ds = Dataset()
        ds.file_meta = FileMetaDataset()
        ds.file_meta.MediaStorageSOPClassUID = CTImageStorage
        ds.file_meta.MediaStorageSOPInstanceUID = ds.SOPInstanceUID = generate_uid()
        ds.file_meta.TransferSyntaxUID = ExplicitVRLittleEndian
        ds.SOPClassUID, ds.Modality, ds.SeriesInstanceUID = CTImageStorage, "CT", series
        ds.ImagePositionPatient = [-50.0, -60.0, 100.0 - k * spacing[2]]  # feet-first order
        ds.ImageOrientationPatient = [1, 0, 0, 0, 1, 0]
        ds.PixelSpacing = [spacing[1], spacing[0]]
        ds.Rows, ds.Columns = hu.shape[1:]
        ds.SamplesPerPixel, ds.PhotometricInterpretation = 1, "MONOCHROME2"
        ds.BitsAllocated, ds.BitsStored, ds.HighBit, ds.PixelRepresentation = 16, 12, 11, 0
        ds.RescaleSlope, ds.RescaleIntercept = 1, -1024
        ds.PixelData = (hu[k] + 1024).astype("<u2").tobytes()
        ds.save_as(folder / f"{generate_uid()}.dcm", enforce_file_format=True)


def test_dicom_ct_in_hu_end_to_end(tmp_path):
    spacing = (0.8, 0.8, 1.25)
    nk, nj, ni = 40, 48, 48
    k, j, i = np.meshgrid(np.arange(nk), np.arange(nj), np.arange(ni), indexing="ij")
    r = np.sqrt((i * 0.8 - 19.2) ** 2 + (j * 0.8 - 19.2) ** 2 + (k * 1.25 - 25.0) ** 2)
    hu = np.where(r < 15, 40, -1000) + np.where(
        (r < 12) & (r > 9), 1160, 0
    )  # skin ball, bone shell
    hu = hu + np.random.default_rng(1).normal(0, 10, hu.shape)
    _write_ct_series(tmp_path / "ct", np.clip(np.round(hu), -1024, 3071).astype(np.int16), spacing)
    bone = mesh_from_ct(tmp_path / "ct", "bone")
    skin = mesh_from_ct(tmp_path / "ct", "skin")
    assert (bone.iso, bone.units, skin.iso) == (300.0, "HU", -300.0)
    assert "HU preset" in bone.rule and bone.frame == "LPS"
    assert bone.validation.is_watertight and skin.validation.is_watertight
    assert bone.mesh.volume > 0 and skin.mesh.volume > 0
    np.testing.assert_allclose(skin.mesh.volume, 4 / 3 * np.pi * 15**3, rtol=0.03)
    # a closed shell has two separate surfaces: the largest (outer) one is kept by default
    assert bone.stats["n_components"] == 2
    np.testing.assert_allclose(bone.mesh.volume, 4 / 3 * np.pi * 12**3, rtol=0.08)
    both = mesh_from_ct(tmp_path / "ct", "bone", largest_component=False)
    assert both.validation.n_components == 2 and both.validation.is_watertight
    # the inner surface faces inwards (into the non-bone core), so its volume subtracts;
    # (the sharp 40 -> 1200 HU step puts the 300 HU surface ~0.3 voxel into the soft side)
    inner = bone.mesh.volume - both.mesh.volume
    np.testing.assert_allclose(inner, 4 / 3 * np.pi * 9**3, rtol=0.12)
    # centre in LPS: x = -50 + 19.2, y = -60 + 19.2, z = 100 - 25 (slices stored feet-first)
    np.testing.assert_allclose(skin.mesh.vertices.mean(axis=0), [-30.8, -40.8, 75.0], atol=0.3)
    assert validate(skin.mesh).n_components == 1
