"""Crossings and fold-overs a fit left are smoothed away locally, toward the template's shape."""

from __future__ import annotations

import numpy as np

from tests.core._shapes import subdivided_octahedron
from workbench.core.mesh import Mesh
from workbench.core.self_intersection import self_intersections
from workbench.core.untangle import untangle


def _sphere() -> Mesh:
    s = subdivided_octahedron(4)
    return Mesh(s.vertices * 50.0, s.faces)


def _spiked(sphere: Mesh, vid: int) -> Mesh:
    """One vertex pushed through the centre and out of the far side: its fan crosses the
    far side's faces (18 pairs) and turns over."""
    v = sphere.vertices.copy()
    v[vid] *= -1.2
    return sphere.with_vertices(v)


def test_a_spike_is_smoothed_until_nothing_crosses_and_the_rest_stays():
    sphere = _sphere()
    bad = _spiked(sphere, 100)
    assert len(self_intersections(bad).pairs) > 0
    out = untangle(bad, reference=sphere)
    assert out.crossings_before > 0 and out.folds_before > 0
    assert out.crossings_after == 0 and out.folds_after == 0
    assert len(self_intersections(out.mesh).pairs) == 0
    assert ((out.mesh.face_normals * sphere.face_normals).sum(axis=1) > 0).all()
    # only the two neighbourhoods moved (where the spike starts and where it comes out)
    assert 0 < out.moved.sum() < 0.06 * sphere.n_vertices
    far = (np.linalg.norm(sphere.vertices - sphere.vertices[100], axis=1) > 30.0) & (
        np.linalg.norm(sphere.vertices - bad.vertices[100], axis=1) > 30.0
    )
    assert far.sum() > 0.5 * sphere.n_vertices
    assert np.array_equal(out.mesh.vertices[far], bad.vertices[far])


def test_allowed_crossings_and_fixed_vertices_are_left_alone():
    sphere = _sphere()
    bad = _spiked(sphere, 100)
    pairs = self_intersections(bad).pairs
    out = untangle(bad, reference=sphere, allowed=map(tuple, pairs.tolist()))
    # the crossings are declared the template's own: only the fold-overs are treated
    assert out.crossings_before == 0
    fixed = np.zeros(sphere.n_vertices, bool)
    fixed[100] = True
    held = untangle(bad, reference=sphere, fixed=fixed)
    assert np.array_equal(held.mesh.vertices[100], bad.vertices[100])


def test_a_clean_mesh_is_returned_unchanged():
    sphere = _sphere()
    out = untangle(sphere, reference=sphere)
    assert out.rounds == 0 and not out.moved.any()
    assert np.array_equal(out.mesh.vertices, sphere.vertices)
