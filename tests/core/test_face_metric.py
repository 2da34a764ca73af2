"""The validation metric (VALIDATION.md) and the uniform-offset baseline on known shapes."""

from __future__ import annotations

import numpy as np
import pytest

from tests.core._shapes import subdivided_octahedron
from workbench.core.face_metric import ScoreMask, score, scored_vertices, summarize
from workbench.core.mesh import Mesh, concatenate
from workbench.core.offset_surface import uniform_offset


def _sphere(r: float, centre=(0.0, 0.0, 0.0), levels: int = 4) -> Mesh:
    s = subdivided_octahedron(levels)
    return Mesh(s.vertices * r + np.asarray(centre, float), s.faces)


def test_selection_keeps_the_front_outer_skin_near_the_bone():
    bone = _sphere(60.0)
    skin = _sphere(70.0)
    inner = _sphere(40.0)  # an "airway": skin surface inside the head
    truth = concatenate([skin, Mesh(inner.vertices, inner.faces[:, ::-1])])
    ids = scored_vertices(truth, bone, (0, 0, 1))
    v = truth.vertices[ids]
    assert len(ids) > 50
    assert (ids < skin.n_vertices).all()  # the inner surface is never scored
    normals = v / np.linalg.norm(v, axis=1, keepdims=True)
    assert (normals[:, 2] > 0.3).all()  # facing anterior
    # the anterior cap of a 70 mm sphere with n·a > 0.3: every such vertex is kept
    cap = (skin.vertices[:, 2] / 70.0) > 0.3 + 1e-6
    assert set(np.flatnonzero(cap)) <= set(ids) | set(np.flatnonzero(~cap))
    assert len(ids) == int(cap.sum())
    # farther than 35 mm from the bone: nothing
    assert len(scored_vertices(_sphere(100.0), bone, (0, 0, 1))) == 0


def test_signed_errors_and_figures():
    bone = _sphere(60.0)
    truth = _sphere(70.0)
    ids = scored_vertices(truth, bone, (0, 0, 1))
    too_thick = _sphere(73.0, levels=5)
    s = score(too_thick, truth, ids)["all"]
    assert s["signed_mean_mm"] == pytest.approx(3.0, abs=0.1)  # outside: positive
    assert s["pct_within_2_5mm"] == 0.0 and s["pct_within_5mm"] == 100.0
    thin = score(_sphere(69.3, levels=5), truth, ids)["all"]
    assert thin["signed_mean_mm"] == pytest.approx(-0.7, abs=0.1)
    assert thin["pct_within_1mm"] > 95.0
    assert summarize(np.array([]))["n"] == 0


def test_masks_drop_a_flattened_front():
    bone = _sphere(60.0)
    truth = _sphere(70.0, levels=5)
    # flatten the front like a field-of-view clip at z = 66
    v = truth.vertices.copy()
    v[:, 2] = np.minimum(v[:, 2], 66.0)
    clipped = Mesh(v, truth.faces)
    all_ids = scored_vertices(clipped, bone, (0, 0, 1))
    behind = scored_vertices(clipped, bone, (0, 0, 1), ScoreMask.parse("behind_clip:3"))
    patch = scored_vertices(clipped, bone, (0, 0, 1), ScoreMask.parse("clip_patch:5"))
    assert (clipped.vertices[behind, 2] <= 63.0 + 1e-9).all()
    assert len(behind) < len(patch) < len(all_ids)
    flat = clipped.vertices[:, 2] >= 66.0 - 1e-9
    assert not np.isin(np.flatnonzero(flat), patch).any()
    for bad in ("clip_patch", "clip_patch:x", "ring:3", "behind_clip:-1"):
        with pytest.raises(ValueError):
            ScoreMask.parse(bad)


def test_uniform_offset_is_6mm_out_and_closed():
    bone = _sphere(50.0)
    off = uniform_offset(bone, 6.0, 1.0)
    r = np.linalg.norm(off.vertices, axis=1)
    assert np.median(r) == pytest.approx(56.0, abs=0.3)
    assert off.volume > 0
    # a hollow shell (two walls) gives only the outer offset: the cavity is filled
    shell = concatenate([_sphere(50.0), Mesh(_sphere(45.0).vertices, _sphere(45.0).faces[:, ::-1])])
    outer = uniform_offset(shell, 6.0, 1.0)
    assert np.linalg.norm(outer.vertices, axis=1).min() > 54.0
