"""Animation service on the male reference head: the issue-14 physics sanity checks (mm, head frame)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from workbench.core.errors import InputError
from workbench.services.animation.animator import ACTION_UNITS, EXPRESSIONS, Animator, mix


@pytest.fixture(scope="module")
def anim(head_male) -> Animator:
    return Animator(head_male)


@pytest.fixture(scope="module")
def marks(head_male) -> dict[str, int]:
    """Skin landmark code -> nearest skin vertex."""
    tree = cKDTree(head_male.skin.vertices)
    return {c: int(tree.query(p)[1]) for c, p in head_male.skin_landmarks.as_dict().items()}


@pytest.fixture(scope="module")
def mirror(head_male) -> np.ndarray:
    v = head_male.skin.vertices
    d, idx = cKDTree(v).query(v * [-1.0, 1.0, 1.0])
    assert d.max() < 1e-6  # the reference skin is exactly symmetric
    return idx


@pytest.fixture(scope="module")
def smiled(anim: Animator) -> np.ndarray:
    anim.set_expression("smile")
    anim.settle()
    x = anim.skin_in_head_frame()
    anim.relax()
    return x


def test_smile_moves_the_mouth_corners(smiled, anim: Animator, marks) -> None:
    rest = anim.sim.rest
    for code in ("ch_l", "ch_r"):
        move = np.linalg.norm(smiled[marks[code]] - rest[marks[code]])
        print(f"{code} moves {move:.2f} mm")
        assert move >= 3.0
    # a smile pulls the corners up and out
    assert smiled[marks["ch_l"], 1] > rest[marks["ch_l"], 1] + 1.0
    assert smiled[marks["ch_l"], 0] > rest[marks["ch_l"], 0]


def test_smile_leaves_forehead_and_back_of_head(smiled, anim: Animator, head_male, marks) -> None:
    rest = anim.sim.rest
    move = np.linalg.norm(smiled - rest, axis=1)
    g_y = rest[marks["g"], 1]
    forehead = (rest[:, 1] > g_y + 10.0) & (rest[:, 2] > 0)
    back = rest[:, 2] < -20.0
    print(f"forehead {move[forehead].max():.3f} mm, back {move[back].max():.3f} mm")
    assert move[forehead].max() < 0.3
    assert move[back].max() < 0.3


def test_symmetric_expression_is_symmetric(smiled, anim: Animator, mirror) -> None:
    mirrored = smiled[mirror] * [-1.0, 1.0, 1.0]
    asym = np.linalg.norm(mirrored - smiled, axis=1).max()
    print(f"asymmetry {asym:.3f} mm")
    assert asym < 0.5


def test_relaxing_returns_to_rest(smiled, anim: Animator) -> None:
    # the smiled fixture relaxed the head after measuring
    err = np.linalg.norm(anim.skin_in_head_frame() - anim.sim.rest, axis=1).max()
    print(f"after relax {err:.4f} mm")
    assert err < 0.1
    assert np.linalg.norm(smiled - anim.sim.rest, axis=1).max() > 3.0  # it did move


def test_no_skin_inside_the_skull(anim: Animator, head_male) -> None:
    from workbench.core.spatial import MeshIndex

    cranium = MeshIndex(head_male.meshes["cranium"])
    mandible = MeshIndex(head_male.meshes["mandible"])
    for name in ("anger", "au9", "au27"):
        anim.set_expression(name)
        anim.settle()
        x = anim.skin_in_head_frame()
        assert np.all(cranium.signed_distance(x) > 0), name
        jaw = anim.meshes()["mandible"]
        assert np.all(MeshIndex(jaw).signed_distance(x) > 0), name
        assert np.all(mandible.signed_distance(anim.sim.rest) > 0)
    anim.relax()


def test_jaw_opening_opens_the_lips(anim: Animator, marks, head_male) -> None:
    rest = anim.sim.rest
    gap0 = np.linalg.norm(rest[marks["ls"]] - rest[marks["li"]])
    anim.set_jaw(10.0)
    anim.settle()
    x = anim.skin_in_head_frame()
    gap = np.linalg.norm(x[marks["ls"]] - x[marks["li"]])
    print(f"lip gap {gap0:.1f} -> {gap:.1f} mm")
    assert gap > gap0 + 5.0
    # the chin goes down with the jaw, the nasion stays
    assert x[marks["pg"], 1] < rest[marks["pg"], 1] - 8.0
    assert np.linalg.norm(x[marks["n"]] - rest[marks["n"]]) < 0.3
    # the mandible and lower teeth moved, the cranium did not
    parts = anim.meshes()
    assert np.abs(parts["mandible"].vertices - head_male.meshes["mandible"].vertices).max() > 5.0
    assert np.allclose(parts["cranium"].vertices, head_male.meshes["cranium"].vertices, atol=1e-9)
    anim.relax()


def test_palette_and_bad_input(anim: Animator) -> None:
    for name in (
        "neutral",
        "happiness",
        "sadness",
        "surprise",
        "fear",
        "anger",
        "disgust",
        "eye_closure",
    ):
        assert name in EXPRESSIONS
    codes = set(anim.muscle_codes)
    assert len(codes) == 24
    for au in ACTION_UNITS.values():
        assert set(au.muscles) <= codes
    # every muscle but the structural mylohyoideus is in some AU except none
    used = {c for au in ACTION_UNITS.values() for c in au.muscles}
    assert used == codes
    m = mix({"smile": 0.5, "surprise": 0.5})
    assert m.muscles["zygomaticus_major_l"] == pytest.approx(
        0.5 * EXPRESSIONS["smile"].muscles["zygomaticus_major_l"]
    )
    assert m.jaw_deg == pytest.approx(0.5 * EXPRESSIONS["surprise"].jaw_deg)
    with pytest.raises(InputError, match="valid names: .*zygomaticus_major_l"):
        anim.set_muscles({"zygomatic": 0.3})
    with pytest.raises(InputError, match="between 0"):
        anim.set_muscles({"mentalis": 1.5})
    with pytest.raises(InputError, match="range"):
        anim.set_jaw(80.0)
    with pytest.raises(InputError, match="valid names: .*happiness"):
        anim.set_expression("joy")
    with pytest.raises(InputError):
        mix({"joy": 1.0})


def test_gaze_turns_the_eyes(anim: Animator, head_male) -> None:
    anim.set_gaze(20.0, 0.0)
    eyes = anim.meshes()["eyes"].vertices
    rest = head_male.meshes["eyes"].vertices
    front = rest[:, 2] > rest[:, 2].max() - 1.0  # the corneas
    assert np.mean(eyes[front, 0] - rest[front, 0]) > 2.0  # toward the subject's left
    anim.set_gaze(0.0, 0.0)
    with pytest.raises(InputError):
        anim.set_gaze(90.0, 0.0)


def test_a_head_in_another_frame_animates_the_same(smiled, anim: Animator, head_male) -> None:
    """A reconstruction's head/ pack is in the skull file's frame: the pose must not depend on it."""
    from workbench.services.registration.jaw import axis_rotation

    m = axis_rotation(np.array([5.0, -20.0, 30.0]), np.array([0.3, 1.0, 0.2]), np.radians(25.0))
    m[:3, 3] += [40.0, -15.0, 120.0]

    def move(p: np.ndarray) -> np.ndarray:
        return np.asarray(p) @ m[:3, :3].T + m[:3, 3]

    moved = Animator(head_male.warped(move))
    moved.set_expression("smile")
    moved.settle()
    assert np.abs(moved.skin_in_head_frame() - smiled).max() < 1e-3
    # and the written skin is in the moved head's own frame
    expect = move(
        smiled if anim._back is None else smiled @ anim._back[:3, :3].T + anim._back[:3, 3]
    )
    assert np.abs(moved.skin().vertices - expect).max() < 1e-3


def test_eye_closure_closes_the_lids(anim: Animator, marks) -> None:
    rest = anim.sim.rest
    anim.set_expression("eye_closure")
    anim.settle()
    x = anim.skin_in_head_frame()
    for side in ("l", "r"):
        up, low = marks[f"ps_{side}"], marks[f"pi_{side}"]
        gap0 = np.linalg.norm(rest[up] - rest[low])
        gap = np.linalg.norm(x[up] - x[low])
        print(f"lids {side}: {gap0:.1f} -> {gap:.1f} mm")
        assert gap < 0.4 * gap0
    # the lids stay outside the eyeball
    eyes = anim.head.eye_centres
    for region, k in (("eyelid_upper_l", 0), ("eyelid_upper_r", 1)):
        nodes = anim.head.regions[region]
        assert np.linalg.norm(x[nodes] - eyes[k], axis=1).min() > anim.head.eye_radius
    anim.relax()
    with pytest.raises(InputError):
        anim.set_lids(1.5)


def test_a_head_stored_mirrored_animates_like_the_head(head_male, smiled) -> None:
    """A reconstruction of a mirrored skull file is stored mirrored with reversed winding."""
    from dataclasses import replace

    from workbench.core.frame import apply_transform
    from workbench.core.mesh import Mesh
    from workbench.services.registration.skull_registration import head_transformed

    c, s = np.cos(0.5), np.sin(0.5)
    m = np.array([[-1.0, 0, 0, 70], [0, c, -s, 10], [0, s, c, -40], [0, 0, 0, 1]])
    stored = head_transformed(head_male, m)
    stored = replace(
        stored, meshes={k: Mesh(v.vertices, v.faces[:, ::-1]) for k, v in stored.meshes.items()}
    )
    other = Animator(stored)
    other.set_expression("smile")
    other.settle()
    out = other.skin()
    assert np.array_equal(out.faces, stored.skin.faces)  # the stored winding comes back
    back = apply_transform(np.linalg.inv(m), out.vertices)
    assert np.abs(back - smiled).max() < 0.05


def test_lids_close_without_the_cornea_showing_through(head_male) -> None:
    from scipy.spatial import cKDTree

    lm = head_male.skin_landmarks.as_dict()
    tree = cKDTree(head_male.skin.vertices)
    ps, pi = (int(tree.query(lm[c])[1]) for c in ("ps_l", "pi_l"))
    rest_gap = np.linalg.norm(head_male.skin.vertices[ps] - head_male.skin.vertices[pi])
    anim = Animator(head_male)
    anim.set_lids(1.0)
    anim.settle()
    x = anim.skin_in_head_frame()
    assert np.linalg.norm(x[ps] - x[pi]) < 0.2 * rest_gap  # closed to a slit
    assert x[ps, 1] > x[pi, 1]  # the upper margin stays above the lower one
    eyes = anim.meshes()["eyes"].vertices
    centre = head_male.eye_centres[0]
    apex = np.linalg.norm(eyes - centre, axis=1)
    apex = apex[np.linalg.norm(eyes - centre, axis=1) < 20].max()
    lid = np.asarray(head_male.regions["eyelid_upper_l"])
    r = np.linalg.norm(x[lid] - centre, axis=1)
    ahead = (x[lid] - centre)[:, 2] / r > np.cos(np.deg2rad(35.0))
    assert (r[ahead] > apex).all()  # no lid skin inside the cornea
