"""Pieces of a bone mesh that are not bone: a table plate and a head-holder shell."""

from __future__ import annotations

import numpy as np

from workbench.core.bone_pieces import apparatus_faces, judge_pieces
from workbench.core.mesh import Mesh, concatenate


def _box(lo, hi) -> Mesh:
    """A closed box (12 triangles, outward), subdivided so it samples evenly."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    v = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    v = lo + v * (hi - lo)
    f = np.array(
        [
            [0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
            [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3],
        ]
    )  # fmt: skip
    return Mesh(v, f).outward()


def _shell(radius: float, thickness: float) -> Mesh:
    """A cradle: the back half of a spherical shell of one thickness, from voxels by marching
    cubes (one closed surface, as a CT gives it)."""
    from workbench.core.isosurface import extract_isosurface
    from workbench.core.volume import Volume

    n = int(2 * radius + 8)
    g = np.mgrid[:n, :n, :n].astype(float) - n / 2
    r = np.sqrt((g**2).sum(axis=0))
    solid = (r <= radius) & (r >= radius - thickness) & (g[0] < -radius * 0.2)
    return extract_isosurface(Volume(solid.astype(np.float32), (1.0, 1.0, 1.0)), 0.5).mesh


def test_a_table_plate_and_a_holder_shell_are_not_bone_and_the_skull_stays(head_female):
    skull = concatenate([head_female.meshes[p] for p in ("cranium", "upper_teeth")])
    table = _box([-90.0, -160.0, -140.0], [90.0, -155.0, 120.0])
    holder = _shell(60.0, 4.0)
    holder = Mesh(holder.vertices + [0.0, 20.0, -200.0], holder.faces)
    mesh = concatenate([skull, table, holder])
    pieces = judge_pieces(mesh)
    assert len(pieces) >= 3
    kinds = sorted((p.apparatus, round(p.share, 2)) for p in pieces)
    skull_piece = max(pieces, key=lambda p: p.share if not p.apparatus else -1)
    assert not skull_piece.apparatus and skull_piece.uniform < 0.8, kinds
    flagged = [p for p in pieces if p.apparatus]
    assert len(flagged) == 2, kinds
    assert any("flat plate" in p.describe() for p in flagged)
    shell = next(p for p in flagged if "one thickness" in p.describe())
    assert abs(shell.thickness_mm - 4.0) < 1.0
    gone = apparatus_faces(mesh, pieces)
    assert gone.sum() == table.n_faces + holder.n_faces
    assert not gone[: skull.n_faces].any()


def test_one_piece_or_bone_only_pieces_are_left_alone(head_female):
    skull = concatenate([head_female.meshes[p] for p in ("cranium", "upper_teeth")])
    assert judge_pieces(skull) == [] or not any(p.apparatus for p in judge_pieces(skull))
    jaw = concatenate([head_female.meshes["mandible"], head_female.meshes["lower_teeth"]])
    moved = Mesh(jaw.vertices + [0.0, -30.0, 0.0], jaw.faces)  # a detached jaw
    assert not any(p.apparatus for p in judge_pieces(concatenate([skull, moved])))
