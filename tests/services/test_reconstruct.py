"""Skull → face fit (services.reconstruct): accuracy on known pairs, frames, incomplete skulls."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.core.errors import LandmarkError
from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh
from workbench.services.compare import compare_surfaces, face_regions
from workbench.services.reconstruct import ensemble_spread, reconstruct
from workbench.services.reference_parts import skull_surface


def _rigid(deg: float, t) -> np.ndarray:  # noqa: ANN001
    a = np.radians(deg)
    m = np.eye(4)
    m[:3, :3] = [[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]]
    m[:3, 3] = t
    return m


@pytest.fixture(scope="module")
def female_case(head_female, head_male):  # noqa: ANN001
    """The female skull reconstructed with the male reference head (truth: the female skin)."""
    skull = skull_surface(head_female)
    return skull, reconstruct(skull, head_female.skull_landmarks, head_male)


def test_female_face_from_female_skull_with_the_male_head(female_case, head_female, head_male):
    _, recon = female_case
    c = compare_surfaces(recon.face, head_female.skin, recon_regions=face_regions(head_male))
    assert c.figures["pct_within_2_5mm"] > 90.0
    assert c.figures["mean_abs_mm"] < 1.5
    assert recon.figures["penetrating_vertices"] == 0
    assert recon.figures["max_tip_error_mm"] < 2.0
    # the muscles ride on the fitted skin: same grids, new positions
    assert [m.code for m in recon.head.muscles] == [m.code for m in head_male.muscles]


def test_result_is_in_the_input_frame(female_case, head_female, head_male):
    skull, recon = female_case
    m = _rigid(35.0, [100.0, -40.0, 900.0])
    moved_skull = skull.transformed(m)
    moved = reconstruct(moved_skull, head_female.skull_landmarks.transformed(m), head_male)
    expected = recon.face.vertices @ m[:3, :3].T + m[:3, 3]
    np.testing.assert_allclose(moved.face.vertices, expected, atol=1e-6)
    assert not moved.mirrored_input


def test_mirrored_input_is_detected_and_mapped_back(female_case, head_female, head_male):
    skull, recon = female_case
    flip = np.diag([-1.0, 1.0, 1.0, 1.0])   # a file with its x axis flipped, labels unchanged
    mirrored = Mesh(skull.vertices * [-1, 1, 1], skull.faces[:, ::-1])
    result = reconstruct(mirrored, head_female.skull_landmarks.transformed(flip), head_male)
    assert result.mirrored_input
    np.testing.assert_allclose(result.face.vertices, recon.face.vertices * [-1, 1, 1], atol=1e-6)
    assert result.face.volume * recon.face.volume > 0   # outward winding kept


def test_missing_mandible_still_gives_a_face_and_says_so(head_female, head_male):
    cranium = head_female.meshes["cranium"]
    parts = head_female.skull_landmark_part
    lms = LandmarkSet("skull", tuple(
        lm if parts.get(lm.code) == "cranium" else lm.moved(lm.position, "absent")
        for lm in head_female.skull_landmarks))
    recon = reconstruct(cranium, lms, head_male)
    assert recon.face.n_vertices == head_male.skin.n_vertices
    assert any("absent" in w or "mandib" in w for w in recon.warnings)
    assert np.isfinite(recon.face.vertices).all()


def test_too_few_landmarks_is_a_clear_error(head_female, head_male):
    keep = ("po_l", "po_r", "or_l", "n")
    lms = LandmarkSet("skull", tuple(head_female.skull_landmarks[c] for c in keep))
    with pytest.raises(LandmarkError, match="dowels"):
        reconstruct(skull_surface(head_female), lms, head_male)


def test_ensemble_spread_follows_the_table_sds(female_case, head_male):
    skull, recon = female_case
    skull_h = skull.transformed(recon.input_to_head)
    spread = ensemble_spread(recon, head_male, skull_h, 8, seed=3)
    assert spread.shape == (head_male.skin.n_vertices,)
    face = np.asarray(head_male.regions["face"])
    # T-Table SDs are 1-6 mm: the face moves by millimetres between members
    assert 0.3 < np.median(spread[face]) < 6.0
    again = ensemble_spread(recon, head_male, skull_h, 8, seed=3)
    np.testing.assert_array_equal(spread, again)
