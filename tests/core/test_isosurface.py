"""Iso-surface extraction: orientation, welding, slabs, smoothing, decimation, presets."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from workbench.core.errors import InputError
from workbench.core.isosurface import (
    choose_iso,
    extract_isosurface,
    looks_like_hu,
    taubin_smooth,
    thin_bone_loss,
)
from workbench.core.mesh import validate
from workbench.core.volume import Volume
from workbench.io.volumes import read_volume


def _rotation(a: float, b: float) -> np.ndarray:
    ca, sa, cb, sb = np.cos(a), np.sin(a), np.cos(b), np.sin(b)
    return np.array([[ca, -sa, 0], [sa, ca, 0], [0, 0, 1]]) @ np.array(
        [[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]]
    )


def _ball(
    shape_kji, spacing, centre_mm, radius_mm, *, inside=1000.0, outside=-1000.0, dtype=np.float32
):
    """Smooth ball (linear ramp over ~2 voxels) in index-space mm, values inside > outside."""
    nk, nj, ni = shape_kji
    k, j, i = np.meshgrid(np.arange(nk), np.arange(nj), np.arange(ni), indexing="ij")
    r = np.sqrt(
        ((i * spacing[0]) - centre_mm[0]) ** 2
        + ((j * spacing[1]) - centre_mm[1]) ** 2
        + ((k * spacing[2]) - centre_mm[2]) ** 2
    )
    ramp = np.clip((radius_mm - r) / (2 * min(spacing)) + 0.5, 0.0, 1.0)
    return (outside + (inside - outside) * ramp).astype(dtype)


@pytest.fixture(scope="module")
def headsq(headsq_nhdr):
    return read_volume(headsq_nhdr)


@pytest.mark.parametrize(
    "direction",
    [
        np.eye(3),
        _rotation(0.5, -0.3),
        np.diag([-1.0, 1.0, 1.0]),
        _rotation(1.0, 0.2) @ np.diag([1, -1, 1]),
    ],
    ids=["identity", "oblique", "mirrored", "oblique-mirrored"],
)
def test_closed_ball_has_outward_normals_and_right_volume(direction):
    spacing = np.array([0.9, 1.1, 1.4])
    radius = 12.0
    data = _ball((26, 30, 34), spacing, (15.0, 16.0, 17.0), radius)
    vol = Volume(data, spacing, origin_mm=(5.0, -7.0, 11.0), direction=direction, units="HU")
    result = extract_isosurface(vol, 0.0)
    mesh = result.mesh
    report = validate(mesh)
    assert report.is_watertight and report.is_clean and report.n_components == 1
    assert report.inconsistent_orientation_edges == 0
    true_volume = 4 / 3 * np.pi * radius**3
    assert mesh.volume > 0  # outward
    assert abs(mesh.volume - true_volume) / true_volume < 0.02
    centre = vol.index_to_physical(np.array([15.0, 16.0, 17.0]) / spacing)
    np.testing.assert_allclose(mesh.vertices.mean(axis=0), centre, atol=0.1)
    assert result.frame == "LPS" and result.rule == "explicit level"


def test_low_valued_object_faces_point_out_of_the_high_region():
    # a hole (air bubble) inside bone: the surface encloses the *low* region, so
    # normals point into the bubble and the signed volume is negative
    data = -_ball((24, 24, 24), (1, 1, 1), (12, 12, 12), 7.0)
    mesh = extract_isosurface(Volume(data, (1, 1, 1)), 0.0).mesh
    assert mesh.volume < 0


def test_integer_levels_hit_exactly_do_not_create_cracks():
    # many voxels equal the level exactly (integer data, integer iso)
    data = (
        np.round(_ball((20, 20, 20), (1, 1, 1), (10, 10, 10), 6.0, inside=600, outside=0) / 100)
        * 100
    )
    assert (data == 300).sum() > 100
    mesh = extract_isosurface(Volume(data.astype(np.int16), (1, 1, 1)), 300).mesh
    report = validate(mesh)
    assert report.is_watertight and report.is_clean and mesh.volume > 0
    assert len(np.unique(mesh.vertices, axis=0)) == mesh.n_vertices  # no coincident vertices


def test_slabs_give_the_same_surface_as_one_pass(headsq):
    one = extract_isosurface(headsq, 1150.0, slab_slices=1000)
    assert one.stats["n_slabs"] == 1
    for slab in (2, 7, 16):
        sliced = extract_isosurface(headsq, 1150.0, slab_slices=slab)
        assert sliced.stats["n_slabs"] > 1 and sliced.stats["n_vertices_welded"] > 0
        assert sliced.mesh.n_vertices == one.mesh.n_vertices
        assert sliced.mesh.n_faces == one.mesh.n_faces
        assert abs(sliced.mesh.area - one.mesh.area) <= 1e-3 * one.mesh.area
        # same vertices (marching cubes returns float32 slab-local coordinates: ~1e-5 mm)
        distance, _ = cKDTree(one.mesh.vertices).query(sliced.mesh.vertices)
        assert distance.max() < 1e-4
        report = validate(sliced.mesh)
        assert report.nonmanifold_edges == 0 and report.inconsistent_orientation_edges == 0


def test_matches_pyvista_contour_triangle_counts(headsq):
    pv = pytest.importorskip("pyvista")
    grid = pv.ImageData(dimensions=headsq.shape_ijk, spacing=tuple(headsq.spacing_mm))
    grid.point_data["ct"] = headsq.data.ravel()  # (k, j, i) C order = VTK x-fastest order
    for level in (500.0, 1150.0):
        ours = extract_isosurface(headsq, level).mesh
        theirs = grid.contour([level], scalars="ct").connectivity("largest")
        assert abs(ours.n_faces - theirs.n_cells) <= 0.10 * theirs.n_cells
        np.testing.assert_allclose(
            ours.bounds.ravel(), np.asarray(theirs.bounds).reshape(3, 2).T.ravel(), atol=0.5
        )


def test_decimation_hits_target_and_keeps_orientation(headsq):
    full = extract_isosurface(headsq, "skin")
    result = extract_isosurface(headsq, "skin", target_triangles=12000)
    assert abs(result.mesh.n_faces - 12000) <= 0.05 * 12000
    assert full.mesh.n_faces > 50000
    report = validate(result.mesh)
    assert report.n_components == 1 and report.inconsistent_orientation_edges == 0
    # the volume cut (open boundary) survives; the surface keeps its size
    np.testing.assert_allclose(result.mesh.extent, full.mesh.extent, atol=2.0)


def test_taubin_smoothing_preserves_volume_and_reduces_roughness():
    spacing = (1.0, 1.0, 1.0)
    rng = np.random.default_rng(0)
    data = _ball((30, 30, 30), spacing, (15, 15, 15), 10.0) + rng.normal(
        0, 150, (30, 30, 30)
    ).astype(np.float32)
    raw = extract_isosurface(Volume(data, spacing), 0.0)
    smooth = extract_isosurface(Volume(data, spacing), 0.0, smooth_iterations=10)
    assert raw.mesh.n_faces == smooth.mesh.n_faces
    assert abs(smooth.mesh.volume - raw.mesh.volume) / raw.mesh.volume < 0.02
    radius = lambda m: np.linalg.norm(m.vertices - m.vertices.mean(axis=0), axis=1)  # noqa: E731
    assert radius(smooth.mesh).std() < 0.7 * radius(raw.mesh).std()
    assert smooth.mesh.area < raw.mesh.area
    # boundary vertices are fixed on open meshes
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0.5]], float)
    f = np.array([[0, 1, 2], [1, 3, 2]])
    np.testing.assert_array_equal(taubin_smooth(v, f, 5), v)


def test_largest_component_option():
    data = np.maximum(
        _ball((24, 24, 40), (1, 1, 1), (10, 12, 12), 6.0),
        _ball((24, 24, 40), (1, 1, 1), (30, 12, 12), 4.0),
    )
    vol = Volume(data, (1, 1, 1))
    both = extract_isosurface(vol, 0.0, largest_component=False)
    big = extract_isosurface(vol, 0.0)
    assert validate(both.mesh).n_components == 2 and big.stats["n_components"] == 2
    assert validate(big.mesh).n_components == 1
    np.testing.assert_allclose(big.mesh.volume, 4 / 3 * np.pi * 6.0**3, rtol=0.03)


def test_presets_and_rules(headsq):
    hu = Volume(np.array([[[-1000, 40], [1200, 0]]] * 2, np.int16), (1, 1, 1), units="HU")
    assert choose_iso(hu, "bone").iso == 300.0 and choose_iso(hu, "skin").iso == -300.0
    assert "HU preset" in choose_iso(hu, "bone").rule
    assert choose_iso(headsq, "skin").iso == 500.0 and choose_iso(headsq, "bone").iso == 1150.0
    assert "VTK" in choose_iso(headsq, "bone").rule
    # not HU, not headsq-like (float, shifted): multi-Otsu separates three classes
    rng = np.random.default_rng(0)
    labels = rng.choice(3, size=(20, 20, 20), p=[0.5, 0.35, 0.15])
    data = np.array([0.1, 0.45, 0.9])[labels] + rng.normal(0, 0.03, labels.shape)
    vol = Volume(data.astype(np.float32), (1, 1, 1))
    skin, bone = choose_iso(vol, "skin"), choose_iso(vol, "bone")
    assert "multi-Otsu" in bone.rule
    assert 0.15 < skin.iso < 0.4 and 0.5 < bone.iso < 0.85
    with pytest.raises(ValueError, match="tissue"):
        choose_iso(vol, "muscle")


def test_bad_levels_and_progress(headsq):
    with pytest.raises(InputError, match="outside the data range"):
        extract_isosurface(headsq, 5000.0)
    calls = []
    extract_isosurface(
        headsq,
        "bone",
        smooth_iterations=2,
        target_triangles=20000,
        progress=lambda step, f: calls.append((step, f)),
    )
    fractions = [f for _, f in calls]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0
    assert {"crop", "marching cubes", "smoothing", "decimation"} <= {s for s, _ in calls}


def test_unstated_units_that_look_like_hounsfield_get_the_hu_presets():
    """A CT NIfTI rarely states HU: air at -1024, soft tissue near 40 and bone above 1000
    read as HU (300 HU for bone), not as three anonymous classes."""
    data = np.full((20, 20, 20), -1024, np.int16)
    data[4:16, 4:16, 4:16] = 40
    data[8:12, 8:12, 8:12] = 1400
    vol = Volume(data, (1, 1, 1))
    assert vol.units != "HU" and looks_like_hu(vol)
    bone = choose_iso(vol, "bone")
    assert bone.iso == 300.0 and "look like Hounsfield" in bone.rule
    # the same shapes shifted to 0..2400 (CT numbers, not HU) are not taken for HU
    assert not looks_like_hu(Volume((data.astype(np.int32) + 1024).astype(np.int16), (1, 1, 1)))


def test_a_high_bone_level_reports_the_thin_bone_it_leaves_out():
    data = np.full((30, 30, 30), -1000, np.int16)
    data[5:25, 5:25, 5:15] = 1200  # a thick block
    data[5:25, 5:25, 20] = 450  # a one-voxel plate, partial volume lowers it
    vol = Volume(data, (1, 1, 1), units="HU")
    loss = thin_bone_loss(vol, 600.0, 300.0)
    assert loss is not None and loss["thin_lost"] > 0.95
    plate = 20 * 20
    assert loss["lost"] == pytest.approx(plate / (plate + 20 * 20 * 10), abs=1e-6)
    assert thin_bone_loss(vol, 300.0, 300.0) is None
