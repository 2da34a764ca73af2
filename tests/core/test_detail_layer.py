"""Detail layer over a fitted skin (workbench.core.detail_layer): displaced subdivision."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.core.detail_layer import DetailLayer, build_detail, subdivision_of
from workbench.core.headgen.eyes import icosphere
from workbench.core.mesh import Mesh
from workbench.core.self_intersection import self_intersections
from workbench.core.spatial import MeshIndex

R = 40.0
APEX = np.array([0.0, 0.0, R])


def _coarse() -> Mesh:
    """A control mesh with ~5.5 mm edges (642 vertices)."""
    ico = icosphere(3)
    return ico.with_vertices(R * ico.vertices)


def _scan(bump_mm: float = 2.0, width_mm: float = 4.0, noise_mm: float = 0.0) -> Mesh:
    """A fine sphere (~0.7 mm edges) of radius R with a Gaussian bump at the apex."""
    ico = icosphere(6)
    u = ico.vertices
    p = R * u
    r = R + bump_mm * np.exp(-((p - APEX) ** 2).sum(axis=1) / (2 * width_mm**2))
    if noise_mm:
        r = r + np.random.default_rng(3).uniform(-noise_mm, noise_mm, len(r))
    return ico.with_vertices(r[:, None] * u)


def _radius_of(mesh: Mesh) -> np.ndarray:
    return np.linalg.norm(mesh.vertices, axis=1)


@pytest.fixture(scope="module")
def bump_fit() -> tuple[Mesh, Mesh, DetailLayer]:
    coarse, scan = _coarse(), _scan()
    return coarse, scan, build_detail(coarse, scan, np.ones(scan.n_vertices))


def test_subdivision_sizes() -> None:
    coarse = _coarse()
    matrix, faces = subdivision_of(coarse, 2)
    assert matrix.shape == (10242, 642) and faces.shape == (16 * coarse.n_faces, 3)
    # the control vertices come first; rows are affine combinations
    np.testing.assert_allclose(np.asarray(matrix.sum(axis=1)).ravel(), 1.0)


def test_detail_recovers_a_bump(bump_fit) -> None:
    coarse, scan, detail = bump_fit
    smooth = detail.smooth_surface(coarse.vertices)
    detailed = detail.apply(coarse.vertices)
    near = np.linalg.norm(scan.vertices - APEX, axis=1) < 10.0
    d_smooth = MeshIndex(smooth).closest_points(scan.vertices[near]).distances
    d_detail = MeshIndex(detailed).closest_points(scan.vertices[near]).distances
    # the smooth skin misses the 2 mm bump (and Loop shrinks the sphere a little)
    assert d_smooth.max() > 1.5
    assert d_detail.max() < 0.25 and d_detail.mean() < 0.08
    # everywhere else too: the shrinkage is taken back
    d_all = MeshIndex(detailed).closest_points(scan.vertices).distances
    assert np.percentile(d_all, 99) < 0.15
    apex = int(np.argmax(smooth.vertices[:, 2]))
    assert detail.observed.all()
    assert detail.displacement[apex] == pytest.approx(R + 2.0 - smooth.vertices[apex, 2], abs=0.15)
    assert detail.new_crossings == 0


def test_the_layer_rides_on_a_moved_skin(bump_fit) -> None:
    """The same layer re-details a rotated, translated or deformed control mesh."""
    coarse, _scan_mesh, detail = bump_fit
    rot = np.linalg.qr(np.random.default_rng(1).normal(size=(3, 3)))[0]
    rot *= np.sign(np.linalg.det(rot))
    moved = coarse.vertices @ rot.T + [5.0, -3.0, 12.0]
    np.testing.assert_allclose(
        detail.apply(moved).vertices,
        detail.apply(coarse.vertices).vertices @ rot.T + [5.0, -3.0, 12.0],
        atol=1e-9,
    )
    # a squashed skin keeps the bump's height along its own normals
    squashed = coarse.vertices * [1.0, 1.0, 0.8]
    smooth = detail.smooth_surface(squashed)
    apex = int(np.argmax(smooth.vertices[:, 2]))
    lifted = detail.apply(squashed).vertices[apex] - smooth.vertices[apex]
    assert lifted[2] == pytest.approx(detail.displacement[apex], abs=1e-6)


def test_holes_fade_to_the_fitted_skin() -> None:
    """Where the scan has no data or is not believed, the layer goes smoothly to zero."""
    coarse = _coarse()
    scan = _scan(bump_mm=0.0)
    kept = scan.vertices[scan.faces].mean(axis=1)[:, 2] > -25.0  # the bottom cap cut away
    holed = Mesh(scan.vertices, scan.faces[kept])
    # and a patch on the side that is there but not believed
    weights = np.where(holed.vertices[:, 0] > 30.0, 0.0, 1.0)
    detail = build_detail(coarse, holed, weights)
    fine = detail.smooth_surface(coarse.vertices)
    v = fine.vertices
    observed_d = detail.displacement[detail.observed]
    assert observed_d.mean() > 0.2  # the shrinkage taken back where the scan is
    for deep in (v[:, 2] < -36.0, v[:, 0] > 37.0):
        assert deep.sum() > 20 and not detail.observed[deep].any()
        assert np.abs(detail.displacement[deep]).max() < 0.05 * observed_d.mean()
    # smoothly: no step between neighbouring fine vertices bigger than the observed spread
    e = np.concatenate([detail.faces[:, [0, 1]], detail.faces[:, [1, 2]]])
    step = np.abs(detail.displacement[e[:, 0]] - detail.displacement[e[:, 1]])
    assert step.max() < 0.1


def test_fixed_skin_keeps_no_detail(bump_fit) -> None:
    coarse, scan, _ = bump_fit
    fixed = coarse.vertices[:, 2] > 30.0  # the bump's cap
    detail = build_detail(coarse, scan, np.ones(scan.n_vertices), fixed=fixed)
    smooth = detail.smooth_surface(coarse.vertices)
    cap = smooth.vertices[:, 2] > 36.0
    assert cap.any() and np.abs(detail.displacement[cap]).max() < 0.05


def test_noisy_scan_gives_no_folds_or_crossings() -> None:
    """A rough scan (±1.5 mm per vertex, finer than the layer) and a sharp narrow spike:
    the detailed skin has no turned-over triangle and no crossing."""
    coarse = _coarse()
    scan = _scan(bump_mm=5.0, width_mm=1.0, noise_mm=1.5)
    detail = build_detail(coarse, scan, np.ones(scan.n_vertices))
    smooth = detail.smooth_surface(coarse.vertices)
    detailed = detail.apply(coarse.vertices)
    turned = (detailed.face_normals * smooth.face_normals).sum(axis=1) <= 0.0
    assert not turned.any()
    assert self_intersections(detailed).count == 0
    assert detail.new_crossings == 0
    # the spike is followed (the smooth skin stops ~5 mm short of its tip), the noise,
    # finer than the layer's ~1.4 mm edges, is averaged, not made worse
    assert detailed.vertices[:, 2].max() > smooth.vertices[:, 2].max() + 3.5
    d_s = MeshIndex(smooth).closest_points(scan.vertices).distances
    d_d = MeshIndex(detailed).closest_points(scan.vertices).distances
    assert d_d.mean() < d_s.mean()


def _plane(z: float, n: int = 81, half: float = 40.0) -> Mesh:
    """A square grid at height ``z`` facing +z (1 mm spacing)."""
    g = np.linspace(-half, half, n)
    x, y = np.meshgrid(g, g, indexing="ij")
    v = np.column_stack([x.ravel(), y.ravel(), np.full(n * n, z)])
    i = (np.arange(n - 1)[:, None] * n + np.arange(n - 1)[None, :]).ravel()
    f = np.concatenate(
        [np.column_stack([i, i + n, i + n + 1]), np.column_stack([i, i + n + 1, i + 1])]
    )
    return Mesh(v, f)


def test_two_sheets_facing_each_other_do_not_meet() -> None:
    """Lips in contact: a 4 mm thin slab whose scan (facing up) lies 1 mm below its lower
    side.  The upper sheet, pulled 5 mm down onto it, would pass through the lower one
    (hundreds of crossings the repair rounds cannot undo); the clearance limit stops it
    short of the lower sheet."""
    coarse = _coarse()
    slab = coarse.with_vertices(coarse.vertices * [1.0, 1.0, 0.05])
    scan = _plane(-3.0)
    detail = build_detail(slab, scan, np.ones(scan.n_vertices))
    detailed = detail.apply(slab.vertices)
    assert self_intersections(detailed).count == 0 and detail.new_crossings == 0
    smooth = detail.smooth_surface(slab.vertices).vertices
    centre = np.abs(smooth[:, :2]).max(axis=1) < 10
    top, bottom = centre & (smooth[:, 2] > 0), centre & (smooth[:, 2] < 0)
    # the upper sheet moved toward the scan, but stays above the lower one
    assert detailed.vertices[top, 2].max() < smooth[top, 2].min() - 1.0
    assert detailed.vertices[top, 2].min() > detailed.vertices[bottom, 2].max() + 1.0
