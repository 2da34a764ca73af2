"""CT threshold preview service and cooperative cancellation (real headsq CT; mm, raw values)."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from workbench.core.cancel import Cancelled, CancelToken, checking
from workbench.core.errors import WorkbenchError
from workbench.core.volume import Volume
from workbench.io.volumes import read_volume
from workbench.services.ct.ct_mesh import mesh_from_ct
from workbench.services.ct.ct_preview import CtPreview, block_mean, preview_strides


@pytest.fixture(scope="module")
def headsq(headsq_nhdr) -> Volume:
    return read_volume(headsq_nhdr)


@pytest.fixture(scope="module")
def full_bone(headsq):
    return mesh_from_ct(headsq, "bone")


# ------------------------------------------------------------------ downsampling
@pytest.mark.parametrize(
    ("shape", "spacing", "limit"),
    [
        ((512, 512, 300), (0.5, 0.5, 0.6), 3_000_000),
        ((512, 512, 60), (0.45, 0.45, 3.0), 3_000_000),
        ((64, 64, 93), (3.2, 3.2, 1.5), 1_000),
        ((64, 64, 93), (3.2, 3.2, 1.5), 10**9),
    ],
)
def test_strides_keep_the_preview_under_the_limit(shape, spacing, limit) -> None:
    strides = preview_strides(shape, np.array(spacing), limit)
    n = np.prod([-(-a // s) for a, s in zip(shape, strides, strict=True)])
    assert n <= limit
    if np.prod(shape) <= limit:
        assert strides == (1, 1, 1)
    else:
        assert n > limit / 8  # not needlessly coarse


def test_thick_slices_are_thinned_in_plane_first() -> None:
    assert preview_strides((512, 512, 60), np.array([0.45, 0.45, 3.0]), 3_000_000) == (3, 3, 1)


def test_block_mean_keeps_the_physical_frame() -> None:
    """A field linear in mm is reproduced at the preview voxel centres (blocks are centred)."""
    rng = np.random.default_rng(3)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    shape_kji = (13, 10, 17)
    k, j, i = np.indices(shape_kji)
    vol = Volume(
        np.zeros(shape_kji),
        spacing_mm=(0.7, 0.9, 2.0),
        origin_mm=(5.0, -3.0, 40.0),
        direction=q,
        frame="RAS",
        units="HU",
    )
    xyz = vol.index_to_physical(np.stack([i, j, k], axis=-1).reshape(-1, 3))
    field_ = (xyz @ np.array([0.3, -1.2, 2.5])).reshape(shape_kji)
    vol = Volume(field_, vol.spacing_mm, vol.origin_mm, vol.direction, "RAS", units="HU")
    small = block_mean(vol, (4, 3, 2))
    assert small.frame == "RAS" and small.units == "HU" and small.data.dtype == np.float32
    assert small.shape_ijk == (5, 4, 7)
    np.testing.assert_allclose(small.spacing_mm, [2.8, 2.7, 4.0])
    np.testing.assert_allclose(small.direction, vol.direction)
    # full blocks only (the last block of each axis is partial here)
    kk, jj, ii = np.indices((6, 3, 4))
    centres = small.index_to_physical(np.stack([ii, jj, kk], -1).reshape(-1, 3))
    expected = centres @ np.array([0.3, -1.2, 2.5])
    np.testing.assert_allclose(small.data[:6, :3, :4].ravel(), expected, atol=1e-3)
    assert block_mean(vol, (1, 1, 1)) is vol


# ------------------------------------------------------------------ headsq previews
def test_small_volume_preview_is_the_full_resolution_surface(headsq, full_bone) -> None:
    ct = CtPreview.from_volume(headsq)
    assert ct.strides == (1, 1, 1)
    assert ct.presets["bone"].iso == 1150.0 and ct.presets["skin"].iso == 500.0
    surface = ct.surface(ct.presets["bone"].iso)
    assert surface.mesh.n_faces == full_bone.mesh.n_faces
    np.testing.assert_allclose(surface.mesh.bounds, full_bone.mesh.bounds)
    assert surface.n_components > 1 and surface.debris.n_faces > 0


def test_preview_is_fast(headsq) -> None:
    ct = CtPreview.from_volume(headsq)
    seconds = []
    for iso in (1150.0, 900.0, 1400.0):
        start = time.perf_counter()
        ct.surface(iso)
        seconds.append(time.perf_counter() - start)
    assert min(seconds) < 0.5, seconds


def test_downsampled_preview_overlays_the_full_extraction(headsq, full_bone) -> None:
    ct = CtPreview.from_volume(headsq, max_voxels=100_000)
    assert ct.strides != (1, 1, 1)
    assert ct.preview_volume.data.size <= 100_000
    surface = ct.surface(1150.0)
    # within two full-resolution voxels ((i, j, k) = (x, y, z) here: identity direction)
    error = np.abs(surface.mesh.bounds - full_bone.mesh.bounds)
    assert np.all(error < 2.0 * headsq.spacing_mm[None, :]), error
    assert surface.mesh.n_faces < full_bone.mesh.n_faces / 2
    # inside the volume's extent even with partial edge blocks
    lo, hi = headsq.origin_mm, headsq.origin_mm + headsq.extent_mm
    assert np.all(surface.mesh.bounds[0] >= lo - 1e-9) and np.all(surface.mesh.bounds[1] <= hi)


def test_iso_changes_the_surface_and_the_counts(headsq) -> None:
    ct = CtPreview.from_volume(headsq)
    low, high = ct.surface(900.0), ct.surface(2000.0)
    assert low.iso == 900.0 and high.iso == 2000.0
    assert low.mesh.n_faces != high.mesh.n_faces
    assert not np.allclose(low.mesh.bounds, high.mesh.bounds)
    for iso, summary in ((900.0, low.summary), (2000.0, high.summary)):
        assert summary.voxels_above == np.count_nonzero(headsq.data >= iso)
        assert summary.fraction_above == pytest.approx(summary.voxels_above / headsq.data.size)
        assert summary.exact and summary.value_range == (0.0, 3926.0)
    assert low.summary.voxels_above > high.summary.voxels_above
    assert "voxels ≥ 900" in low.summary.text()


def test_percentiles_and_histogram_match_numpy(headsq) -> None:
    ct = CtPreview.from_volume(headsq)
    q = (1.0, 25.0, 50.0, 95.0, 99.9)
    got = ct.percentiles(q)
    want = np.percentile(headsq.data, q, method="inverted_cdf")
    np.testing.assert_allclose([got[p] for p in q], want)
    counts, edges = ct.histogram(64)
    assert counts.sum() == headsq.data.size and len(edges) == 65
    np.testing.assert_array_equal(counts[:-1], np.histogram(headsq.data, edges)[0][:-1])


def test_a_level_without_surface_gives_an_empty_preview(headsq) -> None:
    ct = CtPreview.from_volume(headsq)
    surface = ct.surface(10_000.0)
    assert surface.empty and surface.summary.voxels_above == 0
    assert "outside the data range" in surface.note


def test_load_reports_progress_and_describes_the_volume(headsq_nhdr) -> None:
    steps: list[tuple[str, float]] = []
    ct = CtPreview.load(headsq_nhdr, progress=lambda s, f: steps.append((s, f)))
    fractions = [f for _, f in steps]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0
    info = ct.describe()
    assert info["shape_ijk"] == (64, 64, 93) and info["spacing_mm"] == (3.2, 3.2, 1.5)
    assert info["units"] == "unknown" and ct.source == str(headsq_nhdr)


# ------------------------------------------------------------------ cancellation
def test_cancel_token_basics() -> None:
    token = CancelToken()
    token.check()
    assert not token.cancelled
    token.cancel("stop please")
    assert token.cancelled and token.wait(0)
    with pytest.raises(Cancelled, match="stop please"):
        token.check()
    assert issubclass(Cancelled, WorkbenchError)


def test_cancel_stops_mesh_from_ct_at_its_next_progress_check(headsq) -> None:
    token = CancelToken()
    steps: list[str] = []

    def report(step: str, fraction: float) -> None:
        steps.append(step)
        if step == "marching cubes":
            token.cancel()

    with pytest.raises(Cancelled):
        mesh_from_ct(headsq, "bone", progress=checking(token, report))
    assert steps[-1] == "marching cubes"
    assert "validating" not in steps and "done" not in steps


def test_cancel_from_another_thread_stops_the_worker(headsq) -> None:
    token, outcome = CancelToken(), {}
    started = threading.Event()

    def slow_report(step: str, fraction: float) -> None:
        started.set()
        time.sleep(0.05)  # a long step between two checks

    def work() -> None:
        try:
            mesh_from_ct(headsq, "bone", progress=checking(token, slow_report))
            outcome["result"] = "finished"
        except Cancelled:
            outcome["result"] = "cancelled"

    thread = threading.Thread(target=work)
    thread.start()
    assert started.wait(10)
    token.cancel()
    thread.join(10)
    assert outcome == {"result": "cancelled"}


def test_a_cancelled_preview_raises(headsq) -> None:
    ct = CtPreview.from_volume(headsq)
    token = CancelToken()
    token.cancel()
    with pytest.raises(Cancelled):
        ct.surface(1150.0, cancel=token)
    with pytest.raises(Cancelled):
        CtPreview.from_volume(headsq, cancel=token)
