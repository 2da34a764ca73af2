"""Hair, brows, beard and moustache in the exports' writers (issue 34): extra OBJ objects with
their materials in ``head.mtl`` (io.template_pack.write_head_obj), smooth-shaded OBJ objects
(io.mesh_formats.obj), and glTF nodes shaded as ribbons: their own normals, two-sided
materials, the colour split into ``baseColorFactor`` x ``COLOR_0``, sparse morph targets
(io.gltf_export.Shading)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pygltflib
import pytest

from workbench.core import appearance as ap
from workbench.core.mesh import Mesh
from workbench.io.gltf_export import MM_TO_M, Shading, write_glb
from workbench.io.mesh_formats import obj
from workbench.io.template_pack import (
    EXTRA_DECIMALS,
    FILES,
    HEAD_MTL,
    HEAD_OBJ,
    export_template,
    write_head_obj,
)

HAIR_SRGB = (90, 60, 40)


def _ribbons(k: int = 3, m: int = 4) -> tuple[Mesh, np.ndarray]:
    """``k`` flat ribbons of ``m`` steps (mm) and their shading normals (leaning sideways)."""
    verts, faces = [], []
    for s in range(k):
        for i in range(m):
            for side in (-0.5, 0.5):
                verts.append([10.0 * s + side, 100.0 + 3.0 * i + 1 / 3, 20.0])
    for s in range(k):
        for i in range(m - 1):
            a = 2 * (s * m + i)
            faces += [[a, a + 1, a + 3], [a, a + 3, a + 2]]
    v = np.array(verts)
    normals = np.tile([0.6, 0.0, 0.8], (len(v), 1))
    return Mesh(v, np.array(faces)), normals


def _hair_look(n: int) -> ap.Look:
    srgb = np.tile(np.array(HAIR_SRGB, np.uint8), (n, 1))
    srgb[::2] = (120, 80, 50)  # lighter strands: the factor is the lightest
    material = ap.Material("hair", HAIR_SRGB, 0.6, "hair: an artistic addition, not evidence")
    return ap.Look((material,), vertex_srgb=srgb)


def _accessor(gltf: pygltflib.GLTF2, index: int) -> np.ndarray:
    """An accessor's values (dense or sparse, float32 or uint32) as floats."""
    acc = gltf.accessors[index]
    width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3}[acc.type]
    dtype = {pygltflib.FLOAT: "<f4", pygltflib.UNSIGNED_INT: "<u4"}[acc.componentType]
    blob = gltf.binary_blob()

    def read(view_index: int, dt: str, count: int, offset: int = 0) -> np.ndarray:
        view = gltf.bufferViews[view_index]
        return np.frombuffer(blob, dtype=dt, count=count, offset=view.byteOffset + offset)

    if acc.bufferView is None:
        out = np.zeros(acc.count * width)
    else:
        out = read(acc.bufferView, dtype, acc.count * width, acc.byteOffset or 0).astype(float)
    out = out.reshape(acc.count, width)
    if acc.sparse is not None:
        n = acc.sparse.count
        assert acc.sparse.indices.componentType == pygltflib.UNSIGNED_INT
        idx = read(acc.sparse.indices.bufferView, "<u4", n)
        assert np.all(np.diff(idx.astype(np.int64)) > 0)  # strictly increasing, as required
        out[idx] = read(acc.sparse.values.bufferView, dtype, n * width).reshape(n, width)
    return out


# ----------------------------------------------------------------------------- OBJ


def test_every_obj_object_is_smooth_shaded(tmp_path: Path, head_female) -> None:
    """``s 1`` in each object before its faces: Blender imports head.obj smooth, not faceted."""
    tri = np.array([[0, 1, 2]])
    groups = [
        obj.ObjGroup("a", np.eye(3), tri, ["m"]),
        obj.ObjGroup("b", np.eye(3) * 2, tri, ["m"]),
    ]
    text = obj.encode_groups(groups, mtllib="x.mtl").decode()
    for name in ("a", "b"):
        block = re.search(rf"^o {name}\n(.*?)(?=^o |\Z)", text, re.MULTILINE | re.DOTALL)
        assert block is not None
        lines = block.group(1).splitlines()
        assert "s 1" in lines and lines.index("s 1") < lines.index("usemtl m")
    export_template(head_female, tmp_path / "pack")
    pack_obj = (tmp_path / "pack" / HEAD_OBJ).read_text(encoding="utf-8")
    assert pack_obj.count("\ns 1\n") == len(re.findall(r"^o ", pack_obj, re.MULTILINE))


def test_head_obj_takes_hair_parts_with_their_materials(tmp_path: Path, head_female) -> None:
    ribbons, _ = _ribbons()
    brows = ribbons.with_vertices(ribbons.vertices + [0.0, -30.0, 5.0])
    brow_material = ap.Material("brows", (50, 35, 25), 0.7, "brows: artistic addition")
    extra = {
        "hair": (ribbons, _hair_look(ribbons.n_vertices)),
        "brows": (brows, ap.Look((brow_material,))),
    }
    written = write_head_obj(head_female, tmp_path, extra=extra)
    assert {tmp_path / HEAD_OBJ, tmp_path / HEAD_MTL} <= set(written)
    text = (tmp_path / HEAD_OBJ).read_text(encoding="utf-8")
    parts = [p for names in FILES.values() for p in names]
    assert re.findall(r"^o (\S+)$", text, re.MULTILINE) == [*parts, "hair", "brows"]
    assert "artistic additions" in text.split("mtllib")[0]  # the header says so
    hair_block = text.split("o hair\n")[1].split("o brows\n")[0]
    assert "usemtl hair\n" in hair_block and "s 1\n" in hair_block
    # the head's vertices are exact, the hair's to EXTRA_DECIMALS decimals, after them
    parsed = obj.read(tmp_path / HEAD_OBJ, text.encode())
    n_head = sum(head_female.meshes[p].n_vertices for p in parts)
    hair_v = parsed.vertices[n_head : n_head + ribbons.n_vertices]
    assert np.array_equal(hair_v, np.round(ribbons.vertices, EXTRA_DECIMALS))
    assert not np.array_equal(hair_v, ribbons.vertices)  # 1/3 mm is rounded
    assert len(parsed.faces) == sum(m.n_faces for m in head_female.meshes.values()) + 2 * (
        ribbons.n_faces
    )
    # head.mtl: a material each, Kd the linear value of the colour, the source in a comment
    mtl = (tmp_path / HEAD_MTL).read_text(encoding="utf-8")
    for name, srgb in (("hair", HAIR_SRGB), ("brows", (50, 35, 25))):
        entry = re.search(rf"^newmtl {name}\n(.*?)(?=^newmtl |\Z)", mtl, re.MULTILINE | re.DOTALL)
        assert entry is not None
        kd = np.array(re.findall(r"^Kd (\S+) (\S+) (\S+)$", entry.group(1), re.MULTILINE)[0], float)
        assert np.allclose(kd, ap.srgb_to_linear(srgb), atol=1e-6)
        assert "artistic addition" in entry.group(1)
    assert "hair, brows: artistic additions, not evidence" in mtl
    with pytest.raises(ValueError, match="head's own"):
        write_head_obj(head_female, tmp_path, extra={"skin": extra["hair"]})
    clash = ap.Look((ap.Material("skin", (1, 2, 3), 0.5, "x"),))
    with pytest.raises(ValueError, match="already defined"):
        write_head_obj(head_female, tmp_path, extra={"hair": (ribbons, clash)})


# ----------------------------------------------------------------------------- glTF


def _hair_glb(tmp_path: Path, head, moved: np.ndarray, floor: float | None) -> pygltflib.GLTF2:
    ribbons, normals = _ribbons()
    skin = head.skin
    out = write_glb(
        tmp_path / "hair.glb",
        skin,
        {"lift": skin.vertices + [0.0, 1.0, 0.0], "still": skin.vertices},
        extra_nodes={"hair": ribbons},
        node_targets={"hair": {"lift": moved, "still": ribbons.vertices.astype(np.float32)}},
        looks={"hair": _hair_look(ribbons.n_vertices)},
        shading={
            "hair": Shading(normals, double_sided=True, tinted=True, min_displacement_mm=floor)
        },
    )
    return pygltflib.GLTF2().load(str(out))


def test_glb_hair_node_is_shaded_as_ribbons(tmp_path: Path, head_female) -> None:
    ribbons, normals = _ribbons()
    moved = ribbons.vertices.copy()
    moved[:4] += [0.0, 2.0, 0.0]  # the first strand's root moves
    moved[4] += [0.0, 0.004, 0.0]  # below the floor: written as 0
    gltf = _hair_glb(tmp_path, head_female, moved, 0.01)
    nodes = {n.name: n for n in gltf.nodes}
    skin = gltf.meshes[nodes["skin"].mesh]
    hair = gltf.meshes[nodes["hair"].mesh]
    assert hair.extras["targetNames"] == skin.extras["targetNames"] == ["lift", "still"]
    (prim,) = hair.primitives
    # the normals given, not those of the flat ribbons' triangles
    assert np.allclose(_accessor(gltf, prim.attributes.NORMAL), normals, atol=1e-6)
    material = gltf.materials[prim.material]
    assert material.name == "hair" and material.doubleSided is True
    assert gltf.materials[skin.primitives[0].material].doubleSided is False
    # baseColorFactor x COLOR_0 is each vertex's colour; the factor is the lightest's
    factor = np.array(material.pbrMetallicRoughness.baseColorFactor[:3])
    colour = _accessor(gltf, prim.attributes.COLOR_0)
    assert colour.max() <= 1.0 and np.allclose(colour.max(axis=0), 1.0)
    want = ap.srgb_to_linear(_hair_look(ribbons.n_vertices).vertex_srgb)
    assert np.allclose(colour * factor, want, atol=1e-6)
    assert np.allclose(factor, ap.srgb_to_linear((120, 80, 50)), atol=1e-6)
    # sparse targets: only the vertices that move; one that moves too little is 0
    lift = gltf.accessors[prim.targets[0]["POSITION"]]
    assert lift.bufferView is None and lift.sparse is not None and lift.sparse.count == 4
    delta = _accessor(gltf, prim.targets[0]["POSITION"]) / MM_TO_M
    assert np.allclose(delta[:4], [0.0, 2.0, 0.0], atol=1e-5)
    assert np.abs(delta[4:]).max() == 0.0
    # min and max (required for POSITION targets) over every vertex, the zeros included
    assert np.allclose(np.array(lift.min) / MM_TO_M, [0.0, 0.0, 0.0])
    assert np.allclose(np.array(lift.max) / MM_TO_M, [0.0, 2.0, 0.0], atol=1e-5)
    still = gltf.accessors[prim.targets[1]["POSITION"]]
    assert still.sparse is not None and still.sparse.count == 1  # never empty
    # the skin's own targets stay dense and exact
    (skin_prim,) = skin.primitives
    assert gltf.accessors[skin_prim.targets[0]["POSITION"]].sparse is None


def test_glb_hair_targets_are_dense_when_most_vertices_move(tmp_path: Path, head_female) -> None:
    ribbons, _ = _ribbons()
    moved = ribbons.vertices + [0.0, 0.0, 1.5]
    gltf = _hair_glb(tmp_path, head_female, moved, 0.01)
    hair = gltf.meshes[next(n.mesh for n in gltf.nodes if n.name == "hair")]
    acc = gltf.accessors[hair.primitives[0].targets[0]["POSITION"]]
    assert acc.sparse is None and acc.bufferView is not None  # smaller dense
    delta = _accessor(gltf, hair.primitives[0].targets[0]["POSITION"]) / MM_TO_M
    assert np.allclose(delta, [0.0, 0.0, 1.5], atol=1e-5)
    # without a floor (None) every target is dense, as the skin's
    dense = _hair_glb(tmp_path, head_female, ribbons.vertices, None)
    hair = dense.meshes[next(n.mesh for n in dense.nodes if n.name == "hair")]
    assert all(dense.accessors[t["POSITION"]].sparse is None for t in hair.primitives[0].targets)


def test_glb_shading_normals_must_fit_the_mesh(tmp_path: Path, head_female) -> None:
    ribbons, normals = _ribbons()
    with pytest.raises(ValueError, match="normals for"):
        write_glb(
            tmp_path / "bad.glb",
            head_female.skin,
            {},
            extra_nodes={"hair": ribbons},
            shading={"hair": Shading(normals[:-1])},
        )
