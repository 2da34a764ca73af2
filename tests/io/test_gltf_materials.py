"""glTF materials and textures (io.gltf_export, services.animation.gltf), and the Khronos
glTF-Validator's verdict on a whole head: 0 errors and 0 warnings.

The validator is the npm package ``gltf-validator`` at :data:`VALIDATOR_VERSION`,
installed on first use into a cache folder outside the repository
(``WORKBENCH_TOOLS_DIR``, default ``<user cache>/forensic-workbench/tools``) and
driven by ``tests/io/gltf_validate.js``.  The test is skipped, saying why, only
when node or npm is missing, or when the package is not installed and cannot be
(no network).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import pygltflib
import pytest

from workbench.core import appearance as ap
from workbench.core.mesh import Mesh
from workbench.io.gltf_export import MM_TO_M, split_corners, write_glb

VALIDATOR_VERSION = "2.0.0-dev.3.10"
SCRIPT = Path(__file__).with_name("gltf_validate.js")


def _tools_dir() -> Path:
    env = os.environ.get("WORKBENCH_TOOLS_DIR")
    if env:
        return Path(env)
    import platformdirs

    return Path(platformdirs.user_cache_dir("forensic-workbench")) / "tools"


@pytest.fixture(scope="session")
def gltf_validator() -> tuple[str, Path]:
    """``(node executable, folder of the gltf-validator package)``, installed if needed."""
    node, npm = shutil.which("node"), shutil.which("npm")
    if node is None:
        pytest.skip("node is not installed: cannot run the Khronos glTF-Validator")
    prefix = _tools_dir() / f"gltf-validator-{VALIDATOR_VERSION}"
    package = prefix / "node_modules" / "gltf-validator"
    if not (package / "package.json").is_file():
        if npm is None:
            pytest.skip("npm is not installed and gltf-validator is not in " + str(prefix))
        prefix.parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=".gltf-validator-", dir=prefix.parent))
        done = subprocess.run(
            [npm, "install", "--prefix", str(staging), "--no-audit", "--no-fund",
             f"gltf-validator@{VALIDATOR_VERSION}"],
            capture_output=True, text=True, timeout=600, check=False,
        )  # fmt: skip
        if done.returncode != 0:
            shutil.rmtree(staging, ignore_errors=True)
            pytest.skip(
                f"gltf-validator@{VALIDATOR_VERSION} is not installed in {prefix} and npm "
                f"could not install it (no network?): {done.stderr.strip()[-300:]}"
            )
        try:
            staging.rename(prefix)  # atomic: a concurrent session may have won the race
        except OSError:
            shutil.rmtree(staging, ignore_errors=True)
    installed = json.loads((package / "package.json").read_text(encoding="utf-8"))["version"]
    assert installed == VALIDATOR_VERSION, installed
    return node, package


def _validate(validator: tuple[str, Path], glb: Path) -> dict:
    node, package = validator
    done = subprocess.run(
        [node, str(SCRIPT), str(package), str(glb)],
        capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def _accessor(gltf: pygltflib.GLTF2, index: int) -> np.ndarray:
    acc = gltf.accessors[index]
    view = gltf.bufferViews[acc.bufferView]
    dtype = {pygltflib.FLOAT: "<f4", pygltflib.UNSIGNED_INT: "<u4"}[acc.componentType]
    width = {"SCALAR": 1, "VEC2": 2, "VEC3": 3}[acc.type]
    start = view.byteOffset + (acc.byteOffset or 0)
    data = np.frombuffer(gltf.binary_blob(), dtype=dtype, count=acc.count * width, offset=start)
    return data.reshape(acc.count, width).astype(float)


def _skin_atlas(head) -> ap.SkinTexture:
    """An atlas for the skin made from smooth made-up vertex colours."""
    from workbench.core.colour_transfer import SkinColours
    from workbench.io.skin_colour_export import texture_atlas

    v = head.skin.vertices
    rgb = np.column_stack([180 + 40 * np.sin(v[:, 0] / 15), 140 + 0 * v[:, 1], 110 + v[:, 2] / 5])
    n = head.skin.n_vertices
    colours = SkinColours(
        np.clip(rgb, 0, 255).astype(np.uint8), np.ones(n, bool), np.zeros(n), "vertex"
    )
    image, uv = texture_atlas(head.skin, colours, atlas_size=512)
    return ap.SkinTexture(image, uv)


def test_split_corners_copies_vertices_only_where_uvs_differ() -> None:
    faces = np.array([[0, 1, 2], [2, 1, 3]])
    uv = np.array([[[0, 0], [1, 0], [0, 1]], [[0, 1], [1, 0.5], [1, 1]]], float)
    source, new_faces, new_uv = split_corners(faces, uv)
    assert sorted(source.tolist()) == [0, 1, 1, 2, 3]  # vertex 1 has two coordinates
    assert np.array_equal(source[new_faces], faces)
    assert np.array_equal(new_uv[new_faces], uv)


def test_a_look_with_two_materials_is_two_primitives_sharing_vertices(tmp_path: Path) -> None:
    v = np.array([[0, 0, 0], [40, 0, 0], [0, 40, 0], [0, 0, 40]], float)
    skin = Mesh(v, np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]))
    red = ap.Material("red", (200, 30, 30), 0.4, "test")
    blue = ap.Material("blue", (30, 30, 200), 0.6, "test")
    look = ap.Look((red, blue), face_material=np.array([0, 1, 1, 0]))
    out = write_glb(tmp_path / "two.glb", skin, {"up": v + [0.0, 2.0, 0.0]}, looks={"skin": look})
    gltf = pygltflib.GLTF2().load(str(out))
    first, second = gltf.meshes[0].primitives
    assert first.attributes.POSITION == second.attributes.POSITION
    assert first.targets == second.targets and len(first.targets) == 1
    assert [gltf.materials[p.material].name for p in (first, second)] == ["red", "blue"]
    faces = [_accessor(gltf, p.indices).astype(int).reshape(-1, 3) for p in (first, second)]
    assert np.array_equal(faces[0], skin.faces[[0, 3]]) and np.array_equal(
        faces[1], skin.faces[[1, 2]]
    )
    factor = gltf.materials[first.material].pbrMetallicRoughness.baseColorFactor
    assert np.allclose(factor[:3], ap.srgb_to_linear(red.srgb)) and factor[3] == 1.0
    assert gltf.materials[first.material].extras["srgb"] == [200, 30, 30]


def test_glb_materials_default_and_given(tmp_path: Path, head_female) -> None:
    skin = head_female.skin
    smile = skin.vertices + np.array([0.0, 1.0, 0.5])
    parts = {k: head_female.meshes[k] for k in ("eyes", "upper_teeth", "cranium")}
    parts["extra"] = Mesh(np.eye(3) * 10, np.array([[0, 1, 2]]))
    plain = pygltflib.GLTF2().load(
        str(write_glb(tmp_path / "plain.glb", skin, {"smile": smile}, extra_nodes=parts))
    )
    names = {m.name for m in plain.materials}
    assert names == {"skin", "eye", "teeth", "bone", "other"}
    for mesh in plain.meshes:
        for prim in mesh.primitives:
            pbr = plain.materials[prim.material].pbrMetallicRoughness
            assert pbr.metallicFactor == 0.0 and 0.0 < pbr.roughnessFactor <= 1.0
    assert "artistic defaults" in plain.asset.extras["materials"]
    assert plain.asset.extras["units"] == "m" and plain.asset.extras["mm_per_unit"] == 1000
    assert "+Y is up" in plain.asset.extras["axes"]

    looks = ap.head_looks(
        {"skin": skin, **parts}, head_female.eye_centres, regions=head_female.regions,
        skin_texture=_skin_atlas(head_female), iris="hazel",
    )  # fmt: skip
    out = write_glb(tmp_path / "looks.glb", skin, {"smile": smile}, extra_nodes=parts, looks=looks)
    gltf = pygltflib.GLTF2().load(str(out))
    by_name = {n.name: n for n in gltf.nodes}
    (prim,) = gltf.meshes[by_name["skin"].mesh].primitives
    assert gltf.materials[prim.material].pbrMetallicRoughness.baseColorTexture is not None
    rest = _accessor(gltf, prim.attributes.POSITION) / MM_TO_M
    delta = _accessor(gltf, prim.targets[0]["POSITION"]) / MM_TO_M
    assert len(rest) == 3 * skin.n_faces  # the atlas gives every triangle its own patch
    faces = _accessor(gltf, prim.indices).astype(int).reshape(-1, 3)
    # every written triangle lies on the skin's, and the target moves every copy alike
    assert np.abs(rest[faces] - skin.vertices[skin.faces]).max() < 1e-3
    assert np.abs(delta - [0.0, 1.0, 0.5]).max() < 1e-4
    uv = _accessor(gltf, prim.attributes.TEXCOORD_0)
    want = looks["skin"].corner_uv
    assert want is not None
    assert np.abs(uv[faces] - np.stack([want[..., 0], 1.0 - want[..., 1]], -1)).max() < 1e-6
    (eye,) = gltf.meshes[by_name["eyes"].mesh].primitives
    assert eye.attributes.TEXCOORD_0 is not None
    assert gltf.materials[eye.material].name == "eye_hazel"
    assert len(gltf.images) == 2 and all(i.mimeType == "image/png" for i in gltf.images)


@pytest.mark.slow
@pytest.mark.parametrize("variant", ["reference", "atlas_and_vertex_eyes"])
def test_khronos_validator_finds_no_error_or_warning(
    tmp_path: Path, head_female, gltf_validator, variant
) -> None:
    """A whole head with expressions, jaw targets, a clip, materials and textures."""
    from workbench.services.animation.gltf import export_head_glb, ramp_keyframes

    options: dict = {}
    if variant != "reference":
        options = {
            "skin_texture": _skin_atlas(head_female),
            "eyes": "vertex",
            "iris": "blue",
            "skin_tone": "dark",
        }
    out, _, _ = export_head_glb(
        head_female, tmp_path / "head.glb", ["smile", "au26"], ramp_keyframes("au26"), **options
    )
    report = _validate(gltf_validator, out)
    issues = report["issues"]
    assert report["validatorVersion"] == VALIDATOR_VERSION
    assert (issues["numErrors"], issues["numWarnings"]) == (0, 0), issues["messages"][:10]
    info = report["info"]
    assert info["hasMorphTargets"] and info["animationCount"] == 1
    assert info["hasTextures"] and info["materialCount"] >= 5
    gltf = pygltflib.GLTF2().load(str(out))
    skin = next(m for m in gltf.meshes if m.name == "skin")
    attrs = skin.primitives[0].attributes
    if variant == "reference":  # skin tone with the lips blended in per vertex
        assert attrs.COLOR_0 is not None and attrs.TEXCOORD_0 is None
    else:
        assert attrs.TEXCOORD_0 is not None
        eyes = next(m for m in gltf.meshes if m.name == "eyes")
        assert eyes.primitives[0].attributes.COLOR_0 is not None
