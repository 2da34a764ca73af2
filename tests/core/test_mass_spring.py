"""Mass-spring skin (core.mass_spring) and fibre muscles (core.muscle_model) on small shapes.

A 'head' here is an icosphere of radius 60 mm (skin) over a 52 mm sphere (bone), mm and s.
"""

from __future__ import annotations

import numpy as np
import pytest

from workbench.core.headgen.eyes import icosphere
from workbench.core.mass_spring import JAW, NONE, SKULL, SkinSimulation, edge_topology
from workbench.core.mesh import Mesh
from workbench.core.muscle_model import MuscleRig, MuscleSpec
from workbench.core.spatial import MeshIndex


def _ball(radius: float, subdivisions: int) -> Mesh:
    m = icosphere(subdivisions)
    return Mesh(m.vertices * radius, m.faces)


@pytest.fixture(scope="module")
def bone() -> MeshIndex:
    return MeshIndex(_ball(52.0, 4))


@pytest.fixture(scope="module")
def skin() -> Mesh:
    return _ball(60.0, 3)


def test_edge_topology_of_a_closed_mesh(skin: Mesh) -> None:
    edges, bend, bend_edge, edge_face = edge_topology(skin.faces, skin.n_vertices)
    assert len(edges) == 3 * skin.n_faces // 2  # closed: every edge has two faces
    assert len(bend) == len(edges)  # one bending pair per interior edge
    assert len(edge_face) == 3 * skin.n_faces
    # a bending pair's two vertices are not joined by the edge it crosses
    crossed = edges[bend_edge]
    assert not np.any((crossed == bend[:, :1]) | (crossed == bend[:, 1:]))


def test_rest_is_an_equilibrium_and_masses_follow_area(skin: Mesh, bone: MeshIndex) -> None:
    sim = SkinSimulation(skin.vertices, skin.faces, cranium=bone)
    assert np.all(sim.attachment == SKULL)  # 8 mm above bone everywhere
    total = 4 * np.pi * 60.0**2 * 2.0 * 1.1e-3  # area x 2 mm x density, g
    assert sim.mass.sum() == pytest.approx(total, rel=0.02)
    sim.step(50)
    assert np.abs(sim.x - sim.rest).max() < 1e-8


def _pulled(skin: Mesh, bone: MeshIndex, target_shift: np.ndarray, **kw):
    top = np.nonzero(skin.vertices[:, 1] > 55.0)[0]
    sim = SkinSimulation(
        skin.vertices,
        skin.faces,
        cranium=bone,
        muscle_nodes=top,
        muscle_weights=np.ones(len(top)),
        **kw,
    )
    sim.set_muscle_targets(skin.vertices[top] + target_shift)
    return sim, top


def test_muscle_pull_moves_skin_locally_and_relaxes_back(skin: Mesh, bone: MeshIndex) -> None:
    sim, top = _pulled(skin, bone, np.array([8.0, 0.0, 0.0]))
    sim.settle(tol_mm=1e-5)
    move = np.linalg.norm(sim.x - sim.rest, axis=1)
    assert move[top].mean() > 3.0
    far = skin.vertices[:, 1] < -30.0
    assert move[far].max() < 0.05  # the bone springs hold the rest of the ball
    sim.set_muscle_targets(skin.vertices[top])
    sim.settle(tol_mm=1e-6)
    assert np.abs(sim.x - sim.rest).max() < 0.01


def test_dynamics_are_stable_for_a_violent_pull(skin: Mesh, bone: MeshIndex) -> None:
    sim, top = _pulled(skin, bone, np.array([0.0, 0.0, 40.0]))
    sim.step(400)
    assert np.all(np.isfinite(sim.x))
    sim.set_muscle_targets(skin.vertices[top])
    sim.step(2000)
    assert np.abs(sim.x - sim.rest).max() < 0.05


def test_skin_is_not_pushed_into_the_bone(skin: Mesh, bone: MeshIndex) -> None:
    # targets 30 mm inward: deep inside the 52 mm bone
    sim, top = _pulled(skin, bone, np.zeros(3))
    sim.set_muscle_targets(skin.vertices[top] * 0.5)
    sim.settle(tol_mm=1e-4)
    assert np.linalg.norm(sim.x, axis=1).min() > 52.0
    moved = sim.push_out_of_bone([(bone, None)])
    assert moved == 0
    assert np.all(bone.signed_distance(sim.x) > 0)


def test_compressed_skin_bulges(skin: Mesh, bone: MeshIndex) -> None:
    """Slide a ring toward the pole: with the volume term the compressed cap inside stands higher.

    (The stiff membrane, λ = 12 mm, flattens a bump this narrow: about 0.2 mm here.)"""
    v = skin.vertices
    polar = np.degrees(np.arccos(np.clip(v[:, 1] / 60.0, -1, 1)))
    ring = np.nonzero((polar > 18) & (polar < 24))[0]
    inside = np.nonzero(polar < 10)[0]
    # ring targets slid along the sphere toward the pole: polar angle x 0.6
    az = np.arctan2(v[ring, 2], v[ring, 0])
    pol = np.radians(polar[ring] * 0.6)
    shrink = 60.0 * np.stack([np.sin(pol) * np.cos(az), np.cos(pol), np.sin(pol) * np.sin(az)], 1)
    results = []
    for thickness in (2.0, 1e-6):  # with and (practically) without the volume term
        from workbench.core.mass_spring import SkinParameters

        sim = SkinSimulation(
            v,
            skin.faces,
            cranium=bone,
            muscle_nodes=ring,
            muscle_weights=np.ones(len(ring)),
            params=SkinParameters(
                thickness_mm=thickness, density_g_per_mm3=1.1e-3 * 2.0 / thickness
            ),
        )
        sim.set_muscle_targets(shrink)
        sim.settle(tol_mm=1e-5)
        results.append(np.linalg.norm(sim.x[inside], axis=1).mean() - 60.0)
    with_volume, without = results
    assert with_volume > without + 0.1


def test_jaw_nodes_follow_the_jaw(skin: Mesh, bone: MeshIndex) -> None:
    lower_bone = MeshIndex(Mesh(_ball(51.0, 3).vertices + [0, -3.0, 0], _ball(51.0, 3).faces))
    low = skin.vertices[:, 1] < -20.0
    sim = SkinSimulation(
        skin.vertices, skin.faces, cranium=bone, mandible=lower_bone, lower_face=low
    )
    jaw = sim.attachment == JAW
    assert jaw.any() and not jaw[~low].any()
    assert not np.any(sim.attachment == NONE)
    sim.set_jaw(np.eye(3), np.array([0.0, -3.0, 0.0]))
    sim.settle(tol_mm=1e-5)
    dy = sim.x[:, 1] - sim.rest[:, 1]
    assert dy[jaw].mean() < -2.0
    assert np.abs(dy[skin.vertices[:, 1] > 30]).max() < 0.3


def test_linear_muscle_shortens_along_its_polygon_and_sphincter_shrinks() -> None:
    x = np.array([[0.0, 0, 0], [10.0, 0, 0], [30.0, 0, 0], [0, 0, 0]]) + [0, 0, 4.0]
    rows = (
        np.array([[0.0, -1, 0], [0.0, 1, 0]]),
        np.array([[10.0, -1, 0], [10, 1, 0]]),
        np.array([[30.0, -1, 0], [30, 1, 0]]),
    )
    ring = (
        np.array([[-10.0, 0, 0], [0, 10, 0], [10, 0, 0]]),
        np.array([[-5.0, 0, 0], [0, 5, 0], [5, 0, 0]]),
    )
    specs = [
        MuscleSpec("lin", "linear", "skull", rows),
        MuscleSpec("sph", "sphincter", "jaw", ring, axis=np.array([[0.0, 0, 0], [0, 0, -10.0]])),
    ]
    normals = np.tile([0.0, 0, 1], (len(x), 1))
    rig = MuscleRig(specs, x, normals)
    q = rig.control_points(np.array([0.5, 0.5]))
    lin = q[:6].reshape(3, 2, 3)
    assert np.allclose(lin[0], rows[0])  # the fixed end stays
    assert np.allclose(lin[2, :, 0], 15.0)  # free end at half the arc length
    assert np.allclose(lin[1, :, 0], 5.0)
    sph = q[6:].reshape(2, 3, 3)
    assert np.allclose(sph[0], ring[0] * 0.5)  # towards the axis (the z axis)
    assert rig.bulge(np.array([0.2, 0.0]))[0] == pytest.approx(2.0)  # 1 + 5 (1 - 0.8)
    assert rig.bulge(np.array([1.0, 0.0]))[0] == pytest.approx(3.0)  # clamped
    # jaw muscles move rigidly with the jaw
    rot = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
    qj = rig.control_points(np.zeros(2), jaw=(rot, np.zeros(3)))
    assert np.allclose(qj[6:], rig.rest_points[6:] @ rot.T)
    assert np.allclose(qj[:6], rig.rest_points[:6])
    # skin nodes over the linear muscle follow it
    t = rig.targets(np.array([0.5, 0.0]))
    k = list(rig.nodes).index(2)  # the node above the free end
    assert t[k][0] < 30.0 - 10.0


def test_numba_kernels_match_the_numpy_path(skin: Mesh, bone: MeshIndex) -> None:
    pytest.importorskip("numba")
    runs = []
    for compiled in (True, False):
        sim, top = _pulled(skin, bone, np.array([5.0, 3.0, 0.0]), compiled=compiled)
        assert sim.compiled is compiled
        sim.step(30)
        sim.settle(tol_mm=1e-4, max_steps=200)
        runs.append(sim.x.copy())
    assert np.abs(runs[0] - runs[1]).max() < 1e-8
    assert np.abs(runs[0] - skin.vertices).max() > 1.0
