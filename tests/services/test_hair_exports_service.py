"""Hair, brows, beard and moustache in the exports (issue 34): the animation's ``.glb``
(a node per piece with a morph target per expression, grown on each settled skin), a
reconstruction's ``face_builds.glb`` (a morph target per build) and its ``head/head.obj``
(an object per piece with its material), all in the frame of the head's PLY files; a
mirrored input turns the ribbons' triangles over as it does the head's."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pygltflib
import pytest

from workbench.core.appearance import srgb_to_linear
from workbench.io.gltf_export import MM_TO_M
from workbench.model.appearance import Appearance, Hsv
from workbench.model.case import Case
from workbench.services.grooming import hair_meshes

LOOK = Appearance(
    tone="mst5",
    regions={"hair": Hsv(0.08, 0.6, 0.4)},
    grooming={"hair": "buzz", "brows": "straight", "beard": "short", "moustache": "short"},
)
KINDS = ("hair", "brows", "beard", "moustache")


def _read(gltf: pygltflib.GLTF2, index: int) -> np.ndarray:
    """A float VEC3 accessor's values, dense or sparse (mm when a position)."""
    acc = gltf.accessors[index]
    blob = gltf.binary_blob()

    def view(i: int, dtype: str, count: int) -> np.ndarray:
        return np.frombuffer(blob, dtype, count, gltf.bufferViews[i].byteOffset)

    out = np.zeros((acc.count, 3))
    if acc.bufferView is not None:
        out = view(acc.bufferView, "<f4", 3 * acc.count).reshape(-1, 3).astype(float)
    if acc.sparse is not None:
        idx = view(acc.sparse.indices.bufferView, "<u4", acc.sparse.count)
        out[idx] = view(acc.sparse.values.bufferView, "<f4", 3 * acc.sparse.count).reshape(-1, 3)
    return out


def _node_mesh(gltf: pygltflib.GLTF2, name: str) -> pygltflib.Mesh:
    return gltf.meshes[next(n.mesh for n in gltf.nodes if n.name == name)]


def _faces(gltf: pygltflib.GLTF2, prim: pygltflib.Primitive) -> np.ndarray:
    acc = gltf.accessors[prim.indices]
    offset = gltf.bufferViews[acc.bufferView].byteOffset
    return np.frombuffer(gltf.binary_blob(), "<u4", acc.count, offset).reshape(-1, 3)


@pytest.fixture(scope="module")
def mirrored(head_male):
    """The male reference head standing in for a fit, in a mirrored made-up input frame."""
    from workbench.services.reconstruction.reconstruct import Reconstruction

    flip = np.diag([-1.0, 1.0, 1.0, 1.0])
    flip[:3, 3] = [5.0, -2.0, 30.0]
    return Reconstruction(head_male, flip, True, None, np.zeros((0, 3)), np.zeros((0, 3)), {})  # type: ignore[arg-type]


def _builds(head):
    from workbench.services.reconstruction.build_faces import BuildFaces

    n = head.skin.n_vertices
    names = ("lean", "average", "heavy")
    return BuildFaces(
        names=names,
        bmi={"lean": 19.0, "average": 24.0, "heavy": 32.0},
        z={"lean": -1.0, "average": 0.0, "heavy": 1.5},
        main="average",
        main_z=0.0,
        per_z_mm=np.ones(n),
        offsets={"lean": np.full(n, -2.0), "average": np.zeros(n), "heavy": np.full(n, 3.0)},
        lower_mm=np.full(n, -2.0),
        upper_mm=np.full(n, 3.0),
        normals=head.skin.vertex_normals,
        base=head.skin.vertices,
        model_id="test",
    )


@pytest.mark.slow
def test_animation_glb_hair_follows_each_expression(tmp_path: Path, head_male) -> None:
    from workbench.services.animation.gltf import HAIR_MIN_MM, export_head_glb

    out, settled, _ = export_head_glb(
        head_male, tmp_path / "head.glb", ["au1", "au26"], appearance=LOOK
    )
    gltf = pygltflib.GLTF2().load(str(out))
    names = _node_mesh(gltf, "skin").extras["targetNames"]
    assert names == ["au1", "au26"]
    rest = {p.kind: p for p in hair_meshes(head_male, LOOK)}
    assert set(rest) == set(KINDS)
    moved: dict[str, dict[str, np.ndarray]] = {}
    for kind in KINDS:
        mesh = _node_mesh(gltf, kind)
        assert mesh.extras["targetNames"] == names  # one set of weights drives them all
        (prim,) = mesh.primitives
        position = _read(gltf, prim.attributes.POSITION) / MM_TO_M
        assert np.abs(position - rest[kind].mesh.vertices).max() < 1e-3  # every strand
        assert gltf.materials[prim.material].name == kind
        for k, name in enumerate(names):
            frame = position + _read(gltf, prim.targets[k]["POSITION"]) / MM_TO_M
            want = {p.kind: p for p in hair_meshes(head_male, LOOK, settled.stored_skin[name])}
            # weight 1 is the piece grown on the settled skin (small moves written as 0)
            assert np.abs(frame - want[kind].mesh.vertices).max() < HAIR_MIN_MM + 1e-3
            moved.setdefault(kind, {})[name] = frame - position
    # the brows rise with au1 (inner brow raiser), the beard goes down with au26 (jaw drop)
    assert np.median(moved["brows"]["au1"][:, 1]) > 0.3
    assert moved["beard"]["au26"][:, 1].min() < -5.0
    assert np.abs(moved["beard"]["au1"]).max() < 0.5
    assert np.percentile(np.abs(moved["hair"]["au26"][:, 1]), 50) < 0.05  # the scalp keeps still


def test_face_builds_glb_hair_per_build_in_the_input_frame(
    tmp_path: Path, head_male, mirrored
) -> None:
    from workbench.services.reconstruction.job import write_build_files

    builds = _builds(head_male)
    files = write_build_files(mirrored, builds, tmp_path, appearance=LOOK)
    gltf = pygltflib.GLTF2().load(str(files["builds_glb"]))
    skin = _node_mesh(gltf, "face_average")
    assert skin.extras["targetNames"] == ["lean", "heavy"]
    rest = {p.kind: p for p in hair_meshes(head_male, LOOK)}
    heavy = {p.kind: p for p in hair_meshes(head_male, LOOK, builds.vertices("heavy"))}
    for kind in KINDS:
        mesh = _node_mesh(gltf, kind)
        assert mesh.extras["targetNames"] == ["lean", "heavy"]
        (prim,) = mesh.primitives
        position = _read(gltf, prim.attributes.POSITION) / MM_TO_M
        assert np.abs(position - mirrored.to_input(rest[kind].mesh.vertices)).max() < 1e-3
        frame = position + _read(gltf, prim.targets[1]["POSITION"]) / MM_TO_M
        assert np.abs(frame - mirrored.to_input(heavy[kind].mesh.vertices)).max() < 0.012
        # mirrored: triangles turned over, normals mirrored with the points
        assert np.array_equal(_faces(gltf, prim), rest[kind].mesh.faces[:, ::-1])
        normals = _read(gltf, prim.attributes.NORMAL)
        assert np.allclose(normals, rest[kind].normals * [-1.0, 1.0, 1.0], atol=1e-5)
        material = gltf.materials[prim.material]
        assert material.doubleSided and "not evidence" in material.extras["source"]
        assert material.pbrMetallicRoughness.baseColorFactor[3] == 1.0
    # no hair chosen: the file holds the face alone, as before
    (tmp_path / "plain").mkdir()
    plain = write_build_files(mirrored, builds, tmp_path / "plain", appearance=Appearance())
    names = {n.name for n in pygltflib.GLTF2().load(str(plain["builds_glb"])).nodes}
    assert names == {"face_average", "head"}


def test_reconstruction_head_obj_holds_the_chosen_hair(tmp_path: Path, head_male, mirrored) -> None:
    import re

    from workbench.io.mesh_formats import obj
    from workbench.io.template_pack import EXTRA_DECIMALS
    from workbench.pipelines.reconstruct import _coloured_head
    from workbench.services.appearance import hsv_srgb
    from workbench.services.grooming import piece_colour

    out = tmp_path / "folder"
    (out / "head").mkdir(parents=True)
    result = SimpleNamespace(recon=mirrored, opened=SimpleNamespace(case=Case(appearance=LOOK)))
    _coloured_head(result, out)  # type: ignore[arg-type]
    text = (out / "head" / "head.obj").read_text(encoding="utf-8")
    objects = re.findall(r"^o (\S+)$", text, re.MULTILINE)
    assert objects[-4:] == list(KINDS) and len(objects) == len(head_male.meshes) + 4
    assert text.count("\ns 1\n") == len(objects)
    parsed = obj.read(out / "head" / "head.obj", text.encode())
    start = sum(m.n_vertices for m in head_male.meshes.values())
    first_face = sum(m.n_faces for m in head_male.meshes.values())
    for piece in hair_meshes(head_male, LOOK):
        n, m = piece.mesh.n_vertices, piece.mesh.n_faces
        want = np.round(mirrored.to_input(piece.mesh.vertices), EXTRA_DECIMALS)
        assert np.array_equal(parsed.vertices[start : start + n], want), piece.kind
        # mirrored input: winding reversed, so the ribbons face out as the skin does
        faces = parsed.faces[first_face : first_face + m] - start
        assert np.array_equal(faces, piece.mesh.faces[:, ::-1]), piece.kind
        start, first_face = start + n, first_face + m
    mtl = (out / "head" / "head.mtl").read_text(encoding="utf-8")
    for kind in KINDS:
        entry = re.search(rf"^newmtl {kind}\n(.*?)(?=^newmtl |\Z)", mtl, re.MULTILINE | re.DOTALL)
        assert entry is not None, kind
        kd = np.array(re.findall(r"^Kd (\S+) (\S+) (\S+)$", entry.group(1), re.MULTILINE)[0], float)
        colour = srgb_to_linear(hsv_srgb(piece_colour(LOOK, kind)))
        assert np.allclose(kd, colour, atol=1e-6), kind
        assert "artistic addition" in entry.group(1) and "not evidence" in entry.group(1)
    assert len(parsed.vertices) == start  # nothing after the pieces
