"""Landmark editing on a real CT bone surface (services.landmark_placement)."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.core.errors import LandmarkError
from workbench.core.spatial import MeshIndex
from workbench.services.case.case_setup import start_case_from_skull
from workbench.services.landmarks.placement import SurfacePlacement


@pytest.fixture()
def editor(headsq_surfaces, tmp_path):
    from workbench.io.meshes import write_mesh

    path = write_mesh(tmp_path / "bone.ply", headsq_surfaces["bone"])
    opened = start_case_from_skull(path)
    return SurfacePlacement(opened.case.specimen.mesh, opened.stack)


def test_place_snaps_to_the_bone_and_undoes(editor):
    bone = editor.mesh
    off = bone.vertices[1000] + [3.0, 0.0, 0.0]
    lm = editor.place("Nasion", off)
    assert lm.code == "n" and lm.status == "placed"
    d = MeshIndex(bone).closest_points(lm.position[None]).distances[0]
    assert d < 1e-9
    editor.stack.undo()
    assert editor.landmark("n") is None
    editor.stack.redo()
    np.testing.assert_allclose(editor.landmark("n").position, lm.position)


def test_slide_stays_on_the_surface_and_is_one_step(editor):
    start = editor.place("g", editor.mesh.vertices[2000]).position
    moved = editor.slide("g", [0.0, 0.0, -8.0])
    assert MeshIndex(editor.mesh).closest_points(moved.position[None]).distances[0] < 1e-9
    assert 2.0 < np.linalg.norm(moved.position - start) < 16.0
    editor.move("g", moved.position + [0.5, 0, 0])  # a drag continues: merges
    editor.stack.undo()
    np.testing.assert_allclose(editor.landmark("g").position, start)


def test_absent_confirm_delete_and_bad_input(editor):
    assert editor.mark_absent("v").status == "absent"
    assert not editor.landmark("v").is_defined
    editor.place("po_l", editor.mesh.vertices[5])
    assert editor.confirm("po_l").confidence == 1.0
    editor.delete("po_l")
    assert editor.landmark("po_l") is None
    with pytest.raises(LandmarkError, match="unknown"):
        editor.place("not-a-landmark", editor.mesh.vertices[0])
    with pytest.raises(LandmarkError, match="mm from the skull"):
        editor.place("n", editor.mesh.vertices[0] + [500.0, 0, 0])
    with pytest.raises(LandmarkError, match="place it first"):
        editor.slide("zy_l", [1.0, 0, 0])
