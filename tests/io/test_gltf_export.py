"""glTF export: morph targets, names, jaw-part nodes and the weights clip, read back with pygltflib."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pygltflib
import pytest

from workbench.core.mesh import Mesh
from workbench.io.gltf_export import MM_TO_M, write_glb


def _accessor(gltf: pygltflib.GLTF2, index: int) -> np.ndarray:
    acc = gltf.accessors[index]
    view = gltf.bufferViews[acc.bufferView]
    blob = gltf.binary_blob()
    dtype = {pygltflib.FLOAT: "<f4", pygltflib.UNSIGNED_INT: "<u4"}[acc.componentType]
    width = {"SCALAR": 1, "VEC3": 3}[acc.type]
    start = view.byteOffset + (acc.byteOffset or 0)
    data = np.frombuffer(blob, dtype=dtype, count=acc.count * width, offset=start)
    return data.reshape(acc.count, width) if width > 1 else data


def _tetra(shift: float = 0.0) -> Mesh:
    v = np.array([[0, 0, 0], [40, 0, 0], [0, 40, 0], [0, 0, 40]], float) + shift
    return Mesh(v, [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


@pytest.fixture
def scene() -> tuple[Mesh, dict[str, np.ndarray], dict[str, Mesh]]:
    skin = Mesh(
        np.array([[-50, -80, 0], [50, -80, 0], [50, 60, 20], [-50, 60, 20], [0, 0, 95]], float),
        [[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]],
    )
    rng = np.random.default_rng(3)
    targets = {
        name: skin.vertices + rng.normal(0, 3, skin.vertices.shape)
        for name in ("smile", "au26", "eye_closure")
    }
    parts = {
        "eyes": _tetra(10),
        "upper_teeth": _tetra(20),
        "lower_teeth": _tetra(-20),
        "tongue": _tetra(-30),
        "mandible": _tetra(-40),
    }
    return skin, targets, parts


def test_glb_structure_and_frame(tmp_path: Path, scene) -> None:
    skin, targets, parts = scene
    jaw = {"mandible": {"au26": parts["mandible"].vertices + [0.0, -5.0, 1.0]}}
    out = write_glb(
        tmp_path / "head.glb",
        skin,
        targets,
        extra_nodes=parts,
        node_targets=jaw,
        weights={"smile": 1.0},
        animation=[(0.0, {}), (1.0, {"smile": 1.0})],
    )
    assert list(tmp_path.iterdir()) == [out]  # no temporary file left
    gltf = pygltflib.GLTF2().load(str(out))
    assert gltf.asset.version == "2.0"
    by_name = {n.name: n for n in gltf.nodes}
    assert {"skin", "eyes", "upper_teeth", "lower_teeth", "tongue", "mandible"} <= set(by_name)
    skin_mesh = gltf.meshes[by_name["skin"].mesh]
    assert len([m for m in gltf.meshes if m.name == "skin"]) == 1
    (prim,) = skin_mesh.primitives
    assert skin_mesh.extras["targetNames"] == list(targets)
    assert len(prim.targets) == len(targets)
    assert skin_mesh.weights == [1.0, 0.0, 0.0]
    assert prim.attributes.NORMAL is not None and prim.indices is not None
    rest = _accessor(gltf, prim.attributes.POSITION).astype(float)
    assert np.allclose(rest / MM_TO_M, skin.vertices, atol=1e-4)
    faces = _accessor(gltf, prim.indices).reshape(-1, 3)
    assert np.array_equal(faces, skin.faces)
    for k, pos in enumerate(targets.values()):
        acc = gltf.accessors[prim.targets[k]["POSITION"]]
        assert acc.count == skin.n_vertices
        assert acc.min is not None and acc.max is not None
        delta = _accessor(gltf, prim.targets[k]["POSITION"]).astype(float)
        assert np.allclose(acc.min, delta.min(axis=0)) and np.allclose(acc.max, delta.max(axis=0))
        # a frame with weight 1 on this target = the target's positions (mm) within 0.01 mm
        frame = (rest + 1.0 * delta) / MM_TO_M
        assert np.abs(frame - pos).max() < 0.01
    # the jaw part follows au26 through the same target list
    mand = gltf.meshes[by_name["mandible"].mesh]
    assert mand.extras["targetNames"] == list(targets)
    mp = mand.primitives[0]
    d = _accessor(gltf, mp.targets[1]["POSITION"]) / MM_TO_M
    assert np.allclose(d, [0.0, -5.0, 1.0], atol=1e-3)
    assert gltf.meshes[by_name["eyes"].mesh].primitives[0].targets in (None, [])
    # the clip: weights channels, LINEAR, times in s
    (clip,) = gltf.animations
    nodes = [gltf.nodes.index(by_name["skin"]), gltf.nodes.index(by_name["mandible"])]
    assert sorted(c.target.node for c in clip.channels) == sorted(nodes)
    assert all(c.target.path == "weights" for c in clip.channels)
    sampler = clip.samplers[clip.channels[0].sampler]
    assert sampler.interpolation == "LINEAR"
    assert list(_accessor(gltf, sampler.input)) == [0.0, 1.0]
    w = _accessor(gltf, sampler.output).reshape(2, len(targets))
    assert w.tolist() == [[0, 0, 0], [1, 0, 0]]
    # the scene holds one root with every node below it
    (root,) = gltf.scenes[gltf.scene].nodes
    assert len(gltf.nodes[root].children) == 1 + len(parts)


def test_glb_arkit_names_and_bad_input(tmp_path: Path, scene) -> None:
    skin, targets, _ = scene
    out = write_glb(
        tmp_path / "a.glb", skin, targets, names_arkit={"jawOpen": {"au26": 1.0, "smile": 0.5}}
    )
    gltf = pygltflib.GLTF2().load(str(out))
    mesh = gltf.meshes[0]
    assert mesh.extras["targetNames"] == [*targets, "jawOpen"]
    d = _accessor(gltf, mesh.primitives[0].targets[3]["POSITION"]) / MM_TO_M
    want = (targets["au26"] - skin.vertices) + 0.5 * (targets["smile"] - skin.vertices)
    assert np.abs(d - want).max() < 0.01
    with pytest.raises(ValueError, match="unknown target"):
        write_glb(tmp_path / "b.glb", skin, targets, weights={"frown": 1.0})
    with pytest.raises(ValueError, match="expected"):
        write_glb(tmp_path / "b.glb", skin, {"x": skin.vertices[:3]})
    with pytest.raises(ValueError, match="increasing"):
        write_glb(tmp_path / "b.glb", skin, targets, animation=[(1.0, {}), (0.5, {})])
    assert not (tmp_path / "b.glb").exists()
