"""Dense skull registration: parts found or missing, extra anatomy, frames, landmarks, stability."""

from __future__ import annotations

import numpy as np
import pytest

from tests.core._shapes import subdivided_octahedron
from workbench.core.mesh import Mesh, concatenate
from workbench.core.spatial import MeshIndex
from workbench.services.registration.skull_registration import (
    carry_head,
    mirror_from_landmarks,
    register_skull,
)
from workbench.services.templates.reference_parts import skull_surface

HINT = ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0))


def _rot_x(deg: float, about: np.ndarray) -> np.ndarray:
    a = np.radians(deg)
    m = np.eye(4)
    m[:3, :3] = [[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]]
    m[:3, 3] = about - m[:3, :3] @ about
    return m


@pytest.fixture(scope="module")
def female_on_male(head_female, head_male):
    return register_skull(skull_surface(head_female), head_male, hint=HINT)


def test_registered_reference_lies_on_the_target(female_on_male, head_female):
    reg = female_on_male
    bone = MeshIndex(reg.target_h)
    d = bone.closest_points(reg.meshes["cranium"].vertices).distances
    assert np.median(d[reg.observed["cranium"] > 0.5]) < 0.6
    assert all(p.present for p in reg.parts)
    assert reg.part("cranium").observed_fraction > 0.8
    # landmarks carried onto the bone, in the input frame
    found, truth = reg.landmarks.as_dict(), head_female.skull_landmarks.as_dict()
    err = [np.linalg.norm(found[c] - truth[c]) for c in ("g", "n", "pr", "pg", "zy_l", "go_r")]
    assert np.median(err) < 2.0


def test_an_open_jaw_gets_its_own_pose(head_female, head_male):
    jaw = concatenate([head_female.meshes["mandible"], head_female.meshes["lower_teeth"]])
    axis = head_female.tmj_axis[0]
    opened = Mesh(
        jaw.vertices @ _rot_x(18.0, axis)[:3, :3].T + _rot_x(18.0, axis)[:3, 3], jaw.faces
    )
    skull = concatenate([head_female.meshes["cranium"], head_female.meshes["upper_teeth"], opened])
    reg = register_skull(skull, head_male, hint=HINT)
    assert reg.part("mandible").present
    d = (
        MeshIndex(opened.transformed(reg.input_to_head))
        .closest_points(reg.meshes["mandible"].vertices)
        .distances
    )
    assert np.median(d) < 1.0


def test_missing_mandible_and_a_cut_vault(head_female, head_male):
    cranium = concatenate([head_female.meshes["cranium"], head_female.meshes["upper_teeth"]])
    keep = cranium.triangles.mean(axis=1)[:, 1] < 60.0  # vault cut 60 mm above FH
    cut = Mesh(cranium.vertices, cranium.faces[keep])
    reg = register_skull(cut, head_male, hint=HINT)
    assert not reg.part("mandible").present
    assert any("mandible" in w for w in reg.warnings)
    v = reg.meshes["cranium"].vertices
    top = v[:, 1] > 80.0
    assert (reg.observed["cranium"][top] < 0.3).mean() > 0.9  # inferred, not observed
    # the missing vault keeps a skull shape: no collapse onto the cut rim
    assert v[top, 1].max() > 100.0
    absent = {lm.code for lm in reg.landmarks if not lm.is_defined}
    assert {"v", "me", "pg"} <= absent
    assert "po_l" not in absent


def test_extra_anatomy_is_reported_and_ignored(head_female, head_male):
    s = subdivided_octahedron(3)
    spine = Mesh(s.vertices * [12.0, 40.0, 12.0] + [0.0, -115.0, -40.0], s.faces)
    reg = register_skull(concatenate([skull_surface(head_female), spine]), head_male, hint=HINT)
    assert reg.figures["target_extra_area_fraction"] > 0.01
    d = MeshIndex(reg.target_h).closest_points(reg.meshes["mandible"].vertices).distances
    assert np.median(d) < 1.0


def test_units_and_tiny_noise_do_not_change_the_face(head_female, head_male):
    skull = skull_surface(head_female)
    a = carry_head(head_male, register_skull(skull, head_male, hint=HINT)).skin.vertices
    rng = np.random.default_rng(5)
    noisy = Mesh(skull.vertices + 1e-9 * rng.standard_normal(skull.vertices.shape), skull.faces)
    b = carry_head(head_male, register_skull(noisy, head_male, hint=HINT)).skin.vertices
    assert np.abs(a - b).max() < 0.1
    # the same skull read in cm and scaled back to mm
    cm = Mesh((skull.vertices / 10.0) * 10.0, skull.faces)
    c = carry_head(head_male, register_skull(cm, head_male, hint=HINT)).skin.vertices
    assert np.abs(a - c).max() < 0.1


def test_handedness_from_labelled_landmarks(head_female):
    lms = head_female.skull_landmarks
    assert mirror_from_landmarks(lms) == "no"
    flip = np.diag([-1.0, 1.0, 1.0, 1.0])
    assert mirror_from_landmarks(lms.transformed(flip)) == "yes"
    assert mirror_from_landmarks(None) == "auto"


def _searched(*matrices: np.ndarray) -> object:
    """A bone-only search result whose candidates are ``matrices``, best first."""
    from workbench.core.skull_pose import Candidate, SkullPoseResult

    return SkullPoseResult(
        tuple(Candidate(m, 0.5 + 0.01 * i, 0.5, 0.5) for i, m in enumerate(matrices)),
        False,
        symmetry_normal=np.array([1.0, 0.0, 0.0]),
        symmetry_loss=0.1,
    )


def _turned_about_vertical(centre: np.ndarray) -> np.ndarray:
    """Half a turn about the superior (y) axis through ``centre``: face where the occiput was."""
    m = np.diag([-1.0, 1.0, -1.0, 1.0])
    m[:3, 3] = centre - m[:3, :3] @ centre
    return m


def test_a_wrong_bone_only_pose_is_doubted_and_a_runner_up_that_passes_is_taken(
    head_female, head_male, monkeypatch
):
    """Oriented from the bone alone, a winner whose registration leaves the reference's face
    skeleton off the bone is registered again from the search's runner-up, which passes the
    self-check and is used; the user is told."""
    import workbench.core.skull_pose as sp
    import workbench.services.registration.skull_registration as sr

    skull = skull_surface(head_female)
    wrong = _turned_about_vertical(skull.vertices.mean(axis=0))
    monkeypatch.setattr(sr, "_CACHE", {})  # no result from (or for) another test
    monkeypatch.setattr(sp, "search_skull_pose", lambda *a, **k: _searched(wrong, np.eye(4)))
    reg = register_skull(skull, head_male)
    assert np.allclose(reg.pose.matrix, np.eye(4))
    assert reg.figures["self_check"]["outcome"] == "confident"
    assert reg.part("mandible").present
    assert any("did not pass the self-check" in w for w in reg.warnings)
    found, truth = reg.landmarks.as_dict(), head_female.skull_landmarks.as_dict()
    assert np.median([np.linalg.norm(found[c] - truth[c]) for c in ("g", "n", "pg")]) < 3.0


def test_a_wrong_bone_only_pose_with_no_better_runner_up_is_refused(
    head_female, head_male, monkeypatch
):
    """No face with a wrong orientation leaves as a result: the registration raises, naming
    what to give."""
    import workbench.core.skull_pose as sp
    import workbench.services.registration.skull_registration as sr
    from workbench.services.registration.skull_check import OrientationRefused

    skull = skull_surface(head_female)
    wrong = _turned_about_vertical(skull.vertices.mean(axis=0))
    monkeypatch.setattr(sr, "_CACHE", {})
    search = sp.search_skull_pose
    monkeypatch.setattr(sp, "search_skull_pose", lambda *a, **k: _searched(wrong))
    with pytest.raises(OrientationRefused) as err:
        register_skull(skull, head_male)
    assert "--anterior" in str(err.value) and "landmarks" in str(err.value)
    assert "facial skeleton" in str(err.value)
    # with the orientation given, the same skull registers (and is never refused)
    monkeypatch.setattr(sp, "search_skull_pose", search)
    reg = register_skull(skull, head_male, hint=HINT)
    assert reg.figures["self_check"]["outcome"] == "confident"


def test_an_open_jaw_is_articulated_into_occlusion(head_female, head_male):
    """The female skull with her jaw opened 20° (a CT with the mouth open): articulated,
    the jaw's bone lies back where her closed jaw is, the registered mandible and its
    landmarks with it, and the opening found in the scan is reported."""
    from workbench.services.registration.jaw import axis_rotation
    from workbench.services.registration.skull_registration import articulate

    jaw = concatenate([head_female.meshes["mandible"], head_female.meshes["lower_teeth"]])
    cranium = concatenate([head_female.meshes["cranium"], head_female.meshes["upper_teeth"]])
    point, direction = head_female.tmj_axis
    opened = jaw.transformed(axis_rotation(point, direction, np.radians(20.0)))
    reg = register_skull(concatenate([cranium, opened]), head_male, hint=HINT)
    assert reg.jaw is not None and reg.jaw.present and reg.occlusion is None
    art = articulate(reg, head_male)
    assert art.occlusion is not None and art.jaw_bone is not None
    occ = art.figures["jaw"]["occlusion"]
    assert occ["opening_in_ct_deg"] > 12.0  # the female jaw on the male reference
    # the jaw's bone, articulated, lies on her closed jaw (head frame)
    closed = MeshIndex(jaw.transformed(reg.input_to_head))
    moved = art.target_h.vertices[art.jaw_bone]
    assert np.median(closed.closest_points(moved).distances) < 2.0
    before = np.median(closed.closest_points(reg.target_h.vertices[art.jaw_bone]).distances)
    assert before > 5.0
    # the mandible's landmarks moved with it (input frame), the cranium's did not
    a, b = reg.landmarks.as_dict(), art.landmarks.as_dict()
    truth = head_female.skull_landmarks.as_dict()
    assert np.linalg.norm(b["pg"] - truth["pg"]) < np.linalg.norm(a["pg"] - truth["pg"]) - 5.0
    assert np.allclose(a["n"], b["n"])
    assert articulate(register_skull(cranium, head_male, hint=HINT), head_male).occlusion is None
