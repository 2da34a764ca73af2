"""Snap skull landmarks to their features on a real skull (services.landmark_snap).

``skull.obj`` × 15 mm with the reference head's landmarks suggested on it
(session fixture ``skull_obj_suggested``).  Checks are made in the head
frame, independently of the service's own candidate search where possible.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

from workbench.commands.stack import CommandStack
from workbench.core.errors import LandmarkError
from workbench.core.landmarks import LandmarkSet
from workbench.core.spatial import MeshIndex
from workbench.io.snap_rules import load_snap_rules
from workbench.model.case import Case
from workbench.model.specimen import Specimen
from workbench.services.landmarks.placement import SurfacePlacement
from workbench.services.landmarks.snap import snap_frame, snap_index, snap_landmark


@pytest.fixture(scope="module")
def skull(skull_obj_suggested):
    mesh, landmarks = skull_obj_suggested
    to_head = snap_frame(landmarks)
    return mesh, landmarks, to_head, MeshIndex(mesh)


def _head(to_head: np.ndarray, p: np.ndarray) -> np.ndarray:
    return to_head[:3, :3] @ np.asarray(p, float) + to_head[:3, 3]


def _input(to_head: np.ndarray, h: np.ndarray) -> np.ndarray:
    return np.linalg.solve(to_head[:3, :3], np.asarray(h, float) - to_head[:3, 3])


def _with(landmarks: LandmarkSet, code: str, position: np.ndarray) -> LandmarkSet:
    return landmarks.with_landmark(landmarks[code].moved(position, "placed"))


def _editor(mesh, landmarks: LandmarkSet) -> SurfacePlacement:
    case = Case(
        specimen=Specimen(mesh, "mm"), landmarks={"skull": landmarks, "skin": LandmarkSet("skin")}
    )
    return SurfacePlacement(mesh, CommandStack(case))


def test_perturbed_glabella_snaps_back_to_the_most_anterior_midline_point(skull):
    mesh, lms, to_head, index = skull
    feature = snap_landmark(mesh, lms, "g").position
    # 4 mm up the forehead and 1 mm back (head frame), onto the surface: behind the brow
    off = _input(to_head, _head(to_head, feature) + [0.0, 4.0, -1.0])
    perturbed = index.closest_points(off[None]).points[0]
    moved = _with(lms, "g", perturbed)
    result = snap_landmark(mesh, moved, "g")
    frame = snap_frame(moved)  # g is a midline landmark: the frame moves with it
    s, p = _head(frame, result.position), _head(frame, perturbed)

    assert result.rule is not None and result.feature == "most anterior midline point"
    assert s[2] > p[2] + 0.5  # more anterior than where it was put
    assert abs(s[0]) <= 1.5  # on the midsagittal plane (exactly, here)
    assert index.closest_points(result.position[None]).distances[0] < 1e-6  # on the surface
    # more anterior than the nearby outer surface near the midline (independent check on
    # raw vertices within the 8 mm radius, |x| <= 1.5 mm, facing forward; ties of 0.25 mm)
    heads = mesh.vertices @ frame[:3, :3].T + frame[:3, 3]
    facing = snap_index(mesh).normals @ frame[:3, :3].T
    near = (
        (np.linalg.norm(heads - s, axis=1) < 8.0)
        & (np.abs(heads[:, 0]) <= 1.5)
        & (facing[:, 2] > 0)
    )
    assert near.sum() > 10
    assert heads[near, 2].max() <= s[2] + 0.5
    assert np.linalg.norm(result.position - feature) < 2.5  # back to the same feature
    assert result.moved_mm == pytest.approx(np.linalg.norm(result.position - perturbed))
    assert result.explanation.startswith("g → most anterior midline point within 8 mm: moved")


def test_glabella_on_the_flat_of_the_brow_stays_put(skull):
    # this brow is within 0.5 mm of its most anterior point over ~10 mm of height: 4 mm
    # down is still on it, and the snap keeps the user's choice (near-ties of 0.25 mm)
    mesh, lms, to_head, index = skull
    feature = snap_landmark(mesh, lms, "g").position
    off = _input(to_head, _head(to_head, feature) + [0.0, -4.0, -1.0])
    perturbed = index.closest_points(off[None]).points[0]
    moved = _with(lms, "g", perturbed)
    result = snap_landmark(mesh, moved, "g")
    assert result.moved_mm < 1.5
    assert abs(_head(snap_frame(moved), result.position)[0]) < 1e-6  # on the midline


def test_snapping_is_idempotent_for_every_rule(skull):
    mesh, lms, _, index = skull
    rules = load_snap_rules()
    codes = [c for c in rules if c in lms and lms[c].is_defined]
    assert {"g", "pg", "me", "v", "op", "zy_l", "zy_r", "ss", "sm"} <= set(codes)
    for code in codes:
        first = snap_landmark(mesh, lms, code)
        assert first.settled, first.explanation
        assert index.closest_points(first.position[None]).distances[0] < 1e-6, code
        again = snap_landmark(mesh, _with(lms, code, first.position), code)
        assert again.moved_mm < 0.5, (code, first.explanation, again.explanation)


def test_snap_result_is_a_fixed_point_from_perturbed_starts(skull):
    """Whatever the start near the feature, snapping the result again keeps it (< 0.5 mm)."""
    mesh, lms, _, index = skull
    rng = np.random.default_rng(7)
    for code in ("sm", "ss", "g", "pg"):
        for offset in rng.normal(0.0, 2.0, (4, 3)):
            start = index.closest_points((lms[code].position + offset)[None]).points[0]
            first = snap_landmark(mesh, lms, code, start)
            if not first.settled or first.moved_mm == 0.0 and first.rule is None:
                continue
            again = snap_landmark(mesh, _with(lms, code, first.position), code)
            assert again.moved_mm < 0.5, (code, offset, first.explanation, again.explanation)


def test_lateral_and_deepest_rules_follow_the_head_frame(skull):
    mesh, lms, to_head, _ = skull
    for code, sign in (("zy_l", 1.0), ("zy_r", -1.0)):
        r = snap_landmark(mesh, lms, code)
        assert sign * _head(to_head, r.position)[0] >= sign * _head(to_head, r.start)[0]
        assert r.feature == "most lateral point"
    ss = snap_landmark(mesh, lms, "ss")
    assert ss.feature == "deepest point of the midline concavity"
    s = _head(to_head, ss.position)
    ans, pr = (_head(to_head, lms[c].position) for c in ("ans", "pr"))
    assert pr[1] < s[1] < ans[1]  # between its bounds, as defined
    assert s[2] < min(ans[2], pr[2]) - 0.3  # and behind both: a concavity


def test_snap_is_one_undo_step_that_does_not_merge_with_a_drag(skull):
    mesh, lms, to_head, index = skull
    editor = _editor(mesh, lms)
    before = editor.landmark("g").position.copy()
    dragged = editor.move("g", _input(to_head, _head(to_head, before) + [0, -4.0, 0])).position
    result = editor.snap_to_feature("g")
    assert result.moves
    assert editor.stack.undo_text == "Snap g to most anterior midline point"
    np.testing.assert_allclose(editor.landmark("g").position, result.position)
    assert editor.landmark("g").status == "placed"
    editor.stack.undo()
    np.testing.assert_allclose(editor.landmark("g").position, dragged)  # the drag stays
    editor.stack.undo()
    np.testing.assert_allclose(editor.landmark("g").position, before)
    editor.stack.redo()
    editor.stack.redo()
    np.testing.assert_allclose(editor.landmark("g").position, result.position)


def test_snap_all_is_one_step(skull):
    mesh, lms, _, _ = skull
    editor = _editor(mesh, lms)
    n_steps = len(editor.stack)
    results = editor.snap_all_to_features()
    moved = [r for r in results if r.moves]
    assert len(moved) >= 5 and all(r.rule is not None for r in results)
    assert len(editor.stack) == n_steps + 1
    editor.stack.undo()
    assert editor.stack.case.landmarks["skull"].equals(lms)


def test_landmarks_without_a_rule(skull):
    mesh, lms, to_head, index = skull
    assert "n" not in load_snap_rules()
    # nasion pushed 2 mm to the side (on the surface): it only comes back onto the midline
    off = index.closest_points(
        _input(to_head, _head(to_head, lms["n"].position) + [2.0, 0, 0])[None]
    ).points[0]
    moved = _with(lms, "n", off)
    r = snap_landmark(mesh, moved, "n")
    assert r.rule is None and r.feature == "the midsagittal plane"
    frame = snap_frame(moved)
    h, h0 = _head(frame, r.position), _head(frame, off)
    assert abs(h[0]) < 1e-6 and abs(h0[0]) > 1.0
    assert np.hypot(*(h - h0)[1:]) < 1.5  # height and depth about kept
    assert index.closest_points(r.position[None]).distances[0] < 1e-6
    # a bilateral landmark without a rule does not move, and needs no frame
    fe = snap_landmark(mesh, lms.without("po_l"), "fe_l")
    assert fe.moved_mm == 0.0 and not fe.moves and "no snap rule" in fe.explanation


def test_missing_frame_landmarks_are_named(skull):
    mesh, lms, _, _ = skull
    with pytest.raises(LandmarkError, match=r"porions.*po_l"):
        snap_landmark(mesh, lms.without("po_l"), "g")
    with pytest.raises(LandmarkError, match="or_l or or_r"):
        snap_landmark(
            mesh, lms.without("or_l").without("or_r") if "or_r" in lms else lms.without("or_l"), "g"
        )
    with pytest.raises(LandmarkError, match="place it before snapping"):
        snap_landmark(mesh, lms.without("g"), "g")


def test_a_warm_snap_is_fast(skull):
    mesh, lms, _, _ = skull
    snap_landmark(mesh, lms, "g")  # index built and cached for this mesh
    snap_landmark(mesh, lms, "sm")  # and the ray caster of the deepest rules
    costs = []
    for code in ("g", "v", "op", "zy_l", "sm"):
        t = time.perf_counter()
        snap_landmark(mesh, lms, code)
        costs.append(time.perf_counter() - t)
    assert max(costs) < 0.1, costs  # measured 2-20 ms on 100k triangles


def test_the_index_cache_lets_a_mesh_go(skull):
    import gc
    import weakref

    from workbench.core.mesh import Mesh

    copy = Mesh(skull[0].vertices, skull[0].faces)
    assert snap_index(copy).warm() is snap_index(copy)
    gone = weakref.ref(copy)
    del copy
    gc.collect()
    assert gone() is None


def test_suggested_landmarks_are_snapped_placed_ones_stay(head_female):
    from workbench.core.landmarks import LandmarkSet
    from workbench.services.landmarks.snap import snap_suggested
    from workbench.services.templates.reference_parts import skull_surface

    skull = skull_surface(head_female)
    lms = head_female.skull_landmarks
    # glabella suggested 6 mm too low, nasion placed 4 mm off: only glabella moves
    g, n = lms["g"], lms["n"]
    moved = LandmarkSet(
        "skull",
        tuple(
            g.moved(g.position + [0.0, -6.0, -1.0], "suggested")
            if lm.code == "g"
            else n.moved(n.position + [0.0, 0.0, 4.0], "placed")
            if lm.code == "n"
            else lm
            for lm in lms
        ),
    )
    out, notes = snap_suggested(skull, moved)
    assert any(note.startswith("g ") for note in notes)
    assert np.linalg.norm(out["g"].position - g.position) < 3.0
    np.testing.assert_array_equal(out["n"].position, moved["n"].position)
    assert out["g"].status == "suggested"


def test_a_suggested_midline_landmark_without_a_rule_goes_onto_the_midline(skull):
    """The dense registration may leave nasion beside the midline: snap_suggested puts a
    suggested one on the midsagittal plane (a placed one is the user's and stays)."""
    from workbench.services.landmarks.snap import snap_suggested

    mesh, lms, to_head, index = skull
    off = index.closest_points(
        _input(to_head, _head(to_head, lms["n"].position) + [3.0, 0, 0])[None]
    ).points[0]
    suggested = lms.with_landmark(lms["n"].moved(off, "suggested"))
    out, notes = snap_suggested(mesh, suggested)
    frame = snap_frame(suggested)
    assert abs(_head(frame, out["n"].position)[0]) < 1e-6
    assert abs(_head(frame, off)[0]) > 2.0
    assert out["n"].status == "suggested"
    assert any(note.startswith("n has no snap rule") and "midsagittal" in note for note in notes)
    placed = lms.with_landmark(lms["n"].moved(off, "placed"))
    kept, _ = snap_suggested(mesh, placed)
    np.testing.assert_array_equal(kept["n"].position, off)


def test_without_porions_the_registration_frame_is_used(skull):
    """The registration marks a porion absent where it saw too little bone; the suggested
    landmarks are then snapped in the registration's own head frame, not left where the
    dense fit put them."""
    from workbench.services.landmarks.snap import snap_suggested

    mesh, lms, to_head, index = skull
    feature = snap_landmark(mesh, lms, "g").position
    # 4 mm up the forehead and 1 mm back, onto the surface: behind the brow
    low = index.closest_points(_input(to_head, _head(to_head, feature) + [0, 4.0, -1.0])[None])
    moved = lms.with_landmark(lms["g"].moved(low.points[0], "suggested"))
    moved = moved.with_landmark(moved["po_l"].moved(np.full(3, np.nan), "absent"))
    unchanged, notes = snap_suggested(mesh, moved)
    np.testing.assert_array_equal(unchanged["g"].position, low.points[0])
    assert notes and "not snapped" in notes[0]
    out, notes = snap_suggested(mesh, moved, fallback_frame=to_head)
    assert any(note.startswith("g ") for note in notes)
    assert np.linalg.norm(out["g"].position - feature) < 2.5
