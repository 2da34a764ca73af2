"""Reference head assembly: the procedural skull fitted under the authored skin (issue 3, in progress)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.core._shapes import subdivided_octahedron
from workbench.core.headgen.skin import build_skin
from workbench.core.mesh import Mesh, boundary_loops
from workbench.core.spatial import MeshIndex
from workbench.io.tables import load_depth_table
from workbench.model.template import PARTS
from workbench.services.templates.template import (
    MIN_CLEARANCE_MM,
    build_reference_head,
    closed_openings,
)


@pytest.fixture(scope="module", params=["female", "male"])
def head(request: pytest.FixtureRequest):
    # the session's head: built by build_reference_head in this session's
    # empty cache (tests/conftest.py), so these tests check a fresh build
    return request.getfixturevalue(f"head_{request.param}")


def test_every_ttable_pair_is_fitted(head) -> None:
    table = load_depth_table("ttable_2023")
    errors = head.provenance["depth_error_mm"]
    assert set(errors) == set(table.codes)  # all 36 T-Table landmark pairs take part
    values = np.array(list(errors.values()))
    # the skin landmark lies at the dowel tip: skull landmark + table depth along the dowel
    assert np.median(values) < 0.1
    # Issue 3: every pair within 1 mm (with the skull's Frankfort landmarks held
    # on FH).  Achieved: about 0.2 mm at worst for both sexes.
    assert values.max() < 1.0


def test_parts_are_present_and_the_bone_is_under_the_skin(head) -> None:
    assert set(PARTS) <= set(head.meshes)
    # Away from the openings bone stays under the skin (issue 3: > 0 mm).
    # Achieved: 0.83 mm (male), 1.5 mm (female) at worst.
    assert head.provenance["min_clearance_mm"] > 0.0
    # the skull keeps its own Frankfort landmarks on the FH plane
    fh = head.skull_landmarks.positions_of(["po_l", "po_r", "or_l", "or_r"])
    assert np.abs(fh[:, 1]).max() < 0.05
    # the fitted skull is mirror-symmetric: left/right landmark pairs mirror each other
    lms = head.skull_landmarks.as_dict()
    for code, pos in lms.items():
        if code.endswith("_l") and code[:-2] + "_r" in lms and np.isfinite(pos).all():
            assert np.linalg.norm(pos * [-1, 1, 1] - lms[code[:-2] + "_r"]) < 0.5, code
    skin = head.meshes["skin"]
    for part in ("cranium", "mandible"):
        lo, hi = head.meshes[part].bounds
        assert (lo > skin.bounds[0] - 1).all() and (hi < skin.bounds[1] + 1).all()


def test_template_identity(head) -> None:
    assert head.template_id.endswith(head.sex)
    assert len(head.content_hash) == 64
    again = build_reference_head(head.sex)
    assert again.content_hash == head.content_hash  # deterministic


def test_the_skin_stays_off_the_bone_at_the_outer_eye_corners(head) -> None:
    # The lateral orbital rims lie a few mm from the eye openings: before the skull fit
    # closed those openings for its skin-over-bone test, the female rim came out through
    # the skin beside the outer eye corners (31 skin vertices inside the cranium, 0.6 mm
    # deep; the male rim 0.3 mm under the skin).
    skin = head.meshes["skin"].vertices
    for part in ("cranium", "mandible"):
        assert not MeshIndex(head.meshes[part]).contains(skin).any(), part
    lms = head.skin_landmarks.as_dict()
    corner = np.zeros(len(skin), bool)
    for code in ("ex_l", "ex_r"):
        corner |= np.linalg.norm(skin - lms[code], axis=1) < 12.0
    tissue = MeshIndex(head.meshes["cranium"]).signed_distance(skin[corner])
    # Achieved: all but 1 (female) and 4 (male) of ~190 vertices at 2 mm or more; the
    # thinnest 1.95 mm (female) and 1.7 mm (male), at or next to the lateral-orbit
    # landmark lo, which the last step (lifting thin skin) leaves where it is.
    assert (tissue >= MIN_CLEARANCE_MM - 0.01).mean() > 0.95
    assert tissue.min() > 1.5
    lift = head.provenance["skin_lift_mm"]
    assert 0 < lift["vertices"] < 300 and lift["max"] < 1.5  # 120 / 150 vertices, 1.0 / 0.8 mm


def test_the_skin_landmarks_are_the_authored_skins(head) -> None:
    # lifting thin skin off the bone does not move a landmark: the measurements, the
    # Frankfort plane and the tissue depths of the skull fit are taken at them
    authored = build_skin(head.sex).landmarks
    assert head.skin_landmarks.codes == authored.codes
    np.testing.assert_array_equal(head.skin_landmarks.positions, authored.positions)


def test_closed_openings_caps_the_given_holes_facing_outward() -> None:
    sphere = subdivided_octahedron(3)
    v, f = sphere.vertices * 50.0, sphere.faces
    keep = v[f].mean(axis=1)[:, 2] < 40.0  # a hole around the top (+z)
    open_sphere = Mesh(v, f[keep])
    (loop,) = boundary_loops(open_sphere)
    closed = closed_openings(open_sphere, [loop])
    assert closed.n_vertices == open_sphere.n_vertices + 1
    assert np.array_equal(closed.vertices[: open_sphere.n_vertices], open_sphere.vertices)
    assert boundary_loops(closed) == ()
    cap = closed.face_normals[open_sphere.n_faces :]
    assert (cap[:, 2] > 0.9).all()  # the fan faces out of the hole, like the sphere
    # the closed surface has an inside: just under the cap is in, just over it is out
    top = closed.vertices[-1, 2]
    signed = MeshIndex(closed).signed_distance(np.array([[0.0, 0.0, top - 1.0], [0, 0, top + 1.0]]))
    assert signed[0] < 0.0 < signed[1]
