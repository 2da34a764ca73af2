"""Hair, brows, beard and moustache grown on a head (workbench.core.grooming), mm.

On the built-in male reference head: where each piece grows (landmark tests), that strands
stay outside the skin, that the result does not depend on the file's axes, and that the pieces
follow the skin when it deforms (a build, an expression) because they are tied to it.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from workbench.core.grooming import GroomingError, HeadParts, groom, style_names
from workbench.core.grooming.placement import head_axes
from workbench.core.grooming.shell import ShellPoints, surface_frames, vertex_normals_of
from workbench.core.mesh import Mesh

CHOICE = {"hair": "short", "brows": "soft_arch", "beard": "short", "moustache": "full"}


@pytest.fixture(scope="module")
def grown(head_male):
    return groom(head_male.skin, _parts(head_male), CHOICE)


def _parts(head, landmarks=None) -> HeadParts:
    return HeadParts(landmarks or head.skin_landmarks.as_dict(), head.regions)


def _roots(grown, kind: str, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    piece = next(p for p in grown.pieces if p.kind == kind)
    pts, _ = piece.shell.evaluate(vertices, faces)
    return pts.reshape(piece.strands, piece.points, 3)


def _height(skin: Mesh, points: np.ndarray) -> np.ndarray:
    """Signed height (mm) of ``points`` over the skin, along the interpolated normal."""
    from workbench.core.spatial import MeshIndex

    found = MeshIndex.shared(skin).closest_points(points)
    base, frame = surface_frames(
        skin.vertices, skin.faces, found.face_ids, found.barycentric, skin.vertex_normals
    )
    return np.einsum("kd,kd->k", points - base, frame[:, 2])


def test_shell_points_come_back_exactly_and_move_rigidly(head_male) -> None:
    skin = head_male.skin
    rng = np.random.default_rng(1)
    pts = skin.vertices[rng.choice(skin.n_vertices, 500)] + rng.normal(0, 3.0, (500, 3))
    shell = ShellPoints.attach(skin, pts)
    back, _ = shell.evaluate(skin.vertices, skin.faces)
    assert np.abs(back - pts).max() < 1e-9
    angle = np.radians(37.0)
    rot = np.array(
        [[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]]
    )
    moved, _ = shell.evaluate(skin.vertices @ rot.T + [10.0, -5.0, 3.0], skin.faces)
    assert np.abs(moved - (pts @ rot.T + [10.0, -5.0, 3.0])).max() < 1e-9


def test_heights_over_the_skin_are_kept_when_it_swells(head_male) -> None:
    skin = head_male.skin
    rng = np.random.default_rng(2)
    ids = rng.choice(skin.n_vertices, 300)
    normals = vertex_normals_of(skin.vertices, skin.faces)
    pts = skin.vertices[ids] + 4.0 * normals[ids]
    shell = ShellPoints.attach(skin, pts)
    swollen = skin.vertices + 3.0 * normals  # a heavier build: the skin 3 mm further out
    moved, _ = shell.evaluate(swollen, skin.faces)
    h = _height(Mesh(swollen, skin.faces), moved)
    assert np.median(np.abs(h - 4.0)) < 0.3


def test_where_each_piece_grows(head_male, grown) -> None:
    skin, lm = head_male.skin, head_male.skin_landmarks.as_dict()
    axes = head_axes(lm)
    c = {k: axes.coords(np.asarray(v, float))[0] for k, v in lm.items()}
    counts = {p.kind: p.strands for p in grown.pieces}
    assert counts["hair"] > 5000 and counts["brows"] > 300 and counts["beard"] > 2000
    assert counts["moustache"] > 100
    hair = axes.coords(_roots(grown, "hair", skin.vertices, skin.faces)[:, 0])
    brow = axes.coords(_roots(grown, "brows", skin.vertices, skin.faces)[:, 0])
    beard = axes.coords(_roots(grown, "beard", skin.vertices, skin.faces)[:, 0])
    tache = axes.coords(_roots(grown, "moustache", skin.vertices, skin.faces)[:, 0])
    # scalp hair: nothing on the forehead below the trichion (within 30 deg of straight ahead)
    front = np.degrees(np.arctan2(np.abs(hair[:, 0]), hair[:, 2])) < 30.0
    assert front.sum() > 200 and (hair[front, 1] > c["tr"][1] - 8.0).all()
    # brows: above the eyes' corners, below the hairline, beside the midline
    assert (brow[:, 1] > max(c["en_l"][1], c["ex_l"][1])).all()
    assert (brow[:, 1] < c["tr"][1]).all()
    assert np.abs(brow[:, 0]).min() > 3.0
    # both brows, one per side
    assert (brow[:, 0] > 0).sum() > 100 and (brow[:, 0] < 0).sum() > 100
    # beard below the nose, moustache between the nose and the upper lip
    # (the beard rises to the sideburns at the sides: in front it stays below the nose)
    ahead = np.degrees(np.arctan2(np.abs(beard[:, 0]), beard[:, 2])) < 25.0
    assert ahead.sum() > 500 and (beard[ahead, 1] < c["sn"][1]).all()
    assert (beard[:, 1] < c["sba_l"][1] + 3.0).all()
    assert (tache[:, 1] < c["sn"][1]).all() and (tache[:, 1] > c["ls"][1]).all()
    # none rooted on the lips or the ears
    lips = skin.vertices[np.concatenate([head_male.regions[r] for r in ("upper_lip", "lower_lip")])]
    ears = skin.vertices[np.concatenate([head_male.regions[r] for r in ("ear_l", "ear_r")])]
    for kind in ("beard", "moustache"):
        roots = _roots(grown, kind, skin.vertices, skin.faces)[:, 0]
        assert cKDTree(lips).query(roots)[0].min() > 0.9
    roots = _roots(grown, "hair", skin.vertices, skin.faces)[:, 0]
    assert cKDTree(ears).query(roots)[0].min() > 4.5


def test_strands_stay_outside_the_skin(head_male, grown) -> None:
    skin = head_male.skin
    for piece in grown.pieces:
        pts, _ = piece.shell.evaluate(skin.vertices, skin.faces)
        h = _height(skin, pts)
        assert np.quantile(h, 0.001) > -0.05, piece.kind


def test_the_same_in_any_file_axes(head_male, grown) -> None:
    """A head written turned and moved grows the same strands, turned and moved."""
    angle = np.radians(70.0)
    rot = np.array(
        [[1, 0, 0], [0, np.cos(angle), -np.sin(angle)], [0, np.sin(angle), np.cos(angle)]]
    )
    shift = np.array([40.0, -300.0, 12.0])
    skin = head_male.skin
    turned = Mesh(skin.vertices @ rot.T + shift, skin.faces)
    lm = {
        k: np.asarray(v, float) @ rot.T + shift
        for k, v in head_male.skin_landmarks.as_dict().items()
    }
    again = groom(turned, _parts(head_male, lm), CHOICE)
    for a, b in zip(grown.pieces, again.pieces, strict=True):
        assert a.strands == b.strands
        pa, _ = a.shell.evaluate(skin.vertices, skin.faces)
        pb, _ = b.shell.evaluate(turned.vertices, turned.faces)
        assert np.abs(pa @ rot.T + shift - pb).max() < 1e-4, a.kind


def test_pieces_follow_the_skin(head_male, grown) -> None:
    """The chin moved 6 mm down (an open jaw): the beard there moves with it, the scalp
    hair stays where it was."""
    skin = head_male.skin
    lm = head_male.skin_landmarks.as_dict()
    axes = head_axes(lm)
    c = axes.coords(skin.vertices)
    gn = axes.coords(np.asarray(lm["gn"], float))[0]
    chin = c[:, 1] < gn[1] + 15.0
    moved = skin.vertices.copy()
    moved[chin] -= 6.0 * axes.up
    beard_before = _roots(grown, "beard", skin.vertices, skin.faces)
    beard_after = _roots(grown, "beard", moved, skin.faces)
    low = axes.coords(beard_before[:, 0])[:, 1] < gn[1]
    shift = (beard_before - beard_after)[low] @ axes.up
    assert np.median(shift) == pytest.approx(6.0, abs=0.3)
    hair_before = _roots(grown, "hair", skin.vertices, skin.faces)
    hair_after = _roots(grown, "hair", moved, skin.faces)
    assert np.abs(hair_after - hair_before).max() < 1e-9


def test_same_choice_same_strands_and_none_is_empty(head_male, grown) -> None:
    again = groom(head_male.skin, _parts(head_male), CHOICE)
    for a, b in zip(grown.pieces, again.pieces, strict=True):
        assert np.array_equal(a.shell.local, b.shell.local)
    assert groom(head_male.skin, _parts(head_male), {}).empty
    assert "none" in style_names("hair") and "long" in style_names("hair")


def test_bad_choices_and_missing_landmarks_are_named(head_male) -> None:
    with pytest.raises(GroomingError, match="unknown 'mohawk'"):
        groom(head_male.skin, _parts(head_male), {"hair": "mohawk"})
    lm = dict(head_male.skin_landmarks.as_dict())
    del lm["tr"], lm["sci_l"]
    with pytest.raises(GroomingError, match="tr"):
        groom(head_male.skin, _parts(head_male, lm), {"hair": "short"})
    lm = dict(head_male.skin_landmarks.as_dict())
    del lm["sci_l"]
    with pytest.raises(GroomingError, match="sci_l"):
        groom(head_male.skin, _parts(head_male, lm), {"brows": "thin"})


@pytest.mark.parametrize("style", ["buzz", "medium", "long", "bald_pattern"])
def test_every_hair_style_grows_outside_the_skin(head_female, style) -> None:
    skin = head_female.skin
    g = groom(skin, _parts(head_female), {"hair": style})
    (piece,) = g.pieces
    pts, _ = piece.shell.evaluate(skin.vertices, skin.faces)
    assert piece.strands > 1000
    assert np.quantile(_height(skin, pts), 0.001) > -0.05
    drawn = g.meshes(skin.vertices, skin.faces)["hair"]
    assert drawn.mesh.n_faces == piece.strands * (piece.points - 1) * 2
    assert np.allclose(np.linalg.norm(drawn.normals, axis=1), 1.0)
