"""Blender imports the workbench's ``.glb`` and ``head.obj`` with their materials and colours.

The check runs real Blender: ``tools/blender_import_check.py`` under a Python
that has the ``bpy`` module (Blender as a Python module, ``pip install
bpy==4.2.0`` into a separate virtual environment on Python 3.11; never into the
workbench's own).  Point ``WORKBENCH_BPY_PYTHON`` at that interpreter, for
example::

    WORKBENCH_BPY_PYTHON=/path/to/bpyenv/bin/python pytest tests/io/test_blender_import.py

Without it (and without ``bpy`` importable here) the tests are skipped, saying
so; a ``WORKBENCH_BPY_PYTHON`` that cannot import ``bpy`` fails them.

The female reference head is exported here (glTF with morph targets: the
reference colours, and a made-up skin atlas with per-vertex eyes; the pack's
``head.obj``: preset colours, and the atlas) and imported by Blender's own
importers.  What Blender shows is compared with what the exporter wrote and
with the workbench's presets: every material by name with its base colour, the
textures loaded (and mapped the right way up: the atlas's texels where its
colours were painted, the pupil at the front of each eye), the skin's
per-vertex colours, the shape keys, and the size (glTF metres: a position x
1000 is the mm of the head's meshes; OBJ mm: Blender's importer takes them as
units, Blender's default 1 m each).
"""

from __future__ import annotations

import importlib.util
import io
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pygltflib
import pytest

from workbench.core import appearance as ap
from workbench.core.mesh import Mesh

REPO = Path(__file__).resolve().parents[2]
TOOL = REPO / "tools" / "blender_import_check.py"

#: the texel of a made-up atlas colour may differ this much (0-255) from the painted one
TEXEL_TOLERANCE = 8.0

#: an interpreter with Blender's ``bpy`` module, if one is named
BPY_PYTHON = os.environ.get("WORKBENCH_BPY_PYTHON", "")

# skipped at collection, before the reference head is built for nothing
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(
        not BPY_PYTHON and importlib.util.find_spec("bpy") is None,
        reason="Blender's bpy module is not available: set WORKBENCH_BPY_PYTHON to a Python "
        "with bpy (pip install bpy==4.2.0 into a separate venv, Python 3.11)",
    ),
]


@pytest.fixture(scope="session")
def bpy_python() -> str:
    """An interpreter that imports ``bpy`` (``WORKBENCH_BPY_PYTHON``, or this one)."""
    named = BPY_PYTHON
    if not named:
        return sys.executable
    exe = shutil.which(named)
    if exe is None:
        pytest.fail(f"WORKBENCH_BPY_PYTHON={named} is not an executable", pytrace=False)
    done = subprocess.run(
        [exe, "-c", "import bpy; print(bpy.app.version_string)"],
        capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    if done.returncode != 0:
        pytest.fail(
            f"WORKBENCH_BPY_PYTHON={named} cannot import bpy: {done.stderr.strip()[-400:]}",
            pytrace=False,
        )
    return exe


def _atlas_colour(x: np.ndarray, z: np.ndarray) -> np.ndarray:
    """The made-up skin colour (sRGB 0-255) at head-frame mm ``x``, ``z``: stripes
    across the face and a ramp front to back, so a texture upside down or mirrored
    shows the wrong colours."""
    rgb = np.column_stack([180 + 40 * np.sin(x / 15), 140 + 0 * x, 110 + z / 5])
    return np.clip(rgb, 0, 255)


def _skin_atlas(skin: Mesh) -> ap.SkinTexture:
    from workbench.core.colour_transfer import SkinColours
    from workbench.io.skin_colour_export import texture_atlas

    v = skin.vertices
    n = skin.n_vertices
    rgb = _atlas_colour(v[:, 0], v[:, 2]).astype(np.uint8)
    colours = SkinColours(rgb, np.ones(n, bool), np.zeros(n), "vertex")
    image, uv = texture_atlas(skin, colours, atlas_size=1024)
    return ap.SkinTexture(image, uv)


def _run_check(python: str, files: list[Path], out: Path) -> tuple[int, str, list[dict]]:
    """Run the Blender check; ``(exit status, stderr, reports)``."""
    report = out / "report.json"
    done = subprocess.run(
        [python, str(TOOL), *map(str, files), "--json", str(report), "--texels", str(out / "texels")],
        capture_output=True, text=True, timeout=600, check=False,
    )  # fmt: skip
    if not report.is_file():
        pytest.fail(
            f"the Blender check wrote no report (exit {done.returncode}): {done.stderr[-2000:]}"
        )
    return done.returncode, done.stderr, json.loads(report.read_text(encoding="utf-8"))


@pytest.fixture(scope="module")
def imported(bpy_python: str, tmp_path_factory: pytest.TempPathFactory, head_female) -> dict:
    """The female head exported four ways, and what Blender shows of each."""
    from workbench.io.template_pack import write_head_obj
    from workbench.services.animation.gltf import export_head_glb

    out = tmp_path_factory.mktemp("blender")
    atlas = _skin_atlas(head_female.skin)
    files = {
        "reference.glb": out / "reference.glb",
        "atlas.glb": out / "atlas.glb",
        "pack": out / "pack" / "head.obj",
        "atlas_pack": out / "atlas_pack" / "head.obj",
    }
    export_head_glb(head_female, files["reference.glb"], ["au26"])
    export_head_glb(
        head_female, files["atlas.glb"], ["au26"], skin_texture=atlas, eyes="vertex", iris="blue"
    )
    for name, texture in (("pack", None), ("atlas_pack", atlas)):
        files[name].parent.mkdir()
        write_head_obj(
            head_female, files[name].parent, skin_tone="dark", iris="green", skin_texture=texture
        )
    status, stderr, reports = _run_check(bpy_python, list(files.values()), out)
    assert status == 0, stderr[-3000:]
    by_file = {r["file"]: r for r in reports}
    return {
        "out": out,
        "files": files,
        "reports": {k: by_file[str(p.resolve())] for k, p in files.items()},
    }


# ----------------------------------------------------------------------------- helpers


def _materials(report: dict) -> dict[str, dict]:
    return {m["name"]: m for m in report["materials"]}


def _objects(report: dict) -> dict[str, dict]:
    return {o["name"]: o for o in report["objects"]}


def _images(report: dict) -> dict[str, dict]:
    return {i["name"]: i for i in report["images"]}


def _srgb_to_blender_linear(srgb: Any) -> np.ndarray:
    return np.asarray(ap.srgb_to_linear(np.asarray(srgb, float)), float)[:3]


def _extent_blender(vertices_mm: np.ndarray) -> np.ndarray:
    """The size of a head-frame mm box as Blender lays it (x, -z, y: +Z up)."""
    size = vertices_mm.max(axis=0) - vertices_mm.min(axis=0)
    return np.array([size[0], size[2], size[1]])


def _texels(imported: dict, file_key: str, obj: str) -> dict[str, np.ndarray]:
    path = imported["reports"][file_key]["texels"][obj]
    with np.load(path) as data:
        return {k: data[k] for k in data.files}


def _head_frame_mm(co_blender: np.ndarray, bu_per_mm: float) -> np.ndarray:
    """Blender's (X, Y, Z) back to the head frame's (x, y, z) in mm (glTF/OBJ +Y up)."""
    x, y, z = (co_blender / bu_per_mm).T
    return np.column_stack([x, z, -y])


def _png_size(gltf: pygltflib.GLTF2, image: int) -> tuple[int, int]:
    from PIL import Image

    view = gltf.bufferViews[gltf.images[image].bufferView]
    data = gltf.binary_blob()[view.byteOffset : view.byteOffset + view.byteLength]
    with Image.open(io.BytesIO(data)) as im:
        return im.size


def _assert_front_of_each_eye_is_the_pupil(co_mm: np.ndarray, srgb: np.ndarray) -> None:
    for side in (co_mm[:, 0] > 0, co_mm[:, 0] < 0):
        front = np.argsort(-co_mm[side, 2])[:3]  # z toward the face
        assert np.abs(srgb[side][front] - ap.PUPIL.srgb).max() <= 3, srgb[side][front]


# ----------------------------------------------------------------------------- glTF


@pytest.mark.parametrize("file_key", ["reference.glb", "atlas.glb"])
def test_blender_shows_the_glb_materials_as_written(imported: dict, file_key: str) -> None:
    report = imported["reports"][file_key]
    assert report["problems"] == []
    gltf = pygltflib.GLTF2().load(str(imported["files"][file_key]))
    mats, objects, images = _materials(report), _objects(report), _images(report)
    assert set(mats) == {m.name for m in gltf.materials}
    for mesh in gltf.meshes:
        obj = objects[mesh.name]
        names = [gltf.materials[p.material].name for p in mesh.primitives]
        assert obj["materials"] == names and None not in obj["materials"]
        assert obj["shape_keys"] == (mesh.extras or {}).get("targetNames", [])
        colour_0 = mesh.primitives[0].attributes.COLOR_0 is not None
        assert bool(obj["colour_attributes"]) == colour_0, mesh.name
    for material in gltf.materials:
        got = mats[material.name]
        base = got["base_colour"]
        pbr = material.pbrMetallicRoughness
        assert got["principled"]
        assert np.allclose(base["factor"], pbr.baseColorFactor, atol=1e-4), material.name
        assert got["roughness"] == pytest.approx(pbr.roughnessFactor, abs=1e-4)
        if pbr.baseColorTexture is not None:
            (tex,) = base["textures"]
            source = gltf.textures[pbr.baseColorTexture.index].source
            assert images[tex]["loaded"] and images[tex]["packed"]
            assert tuple(images[tex]["size"]) == _png_size(gltf, source)
        elif base["linked"]:
            assert base["source"] == "vertex colour" and base["colour_attributes"]
        else:  # a plain preset: the colour the workbench chose, as Blender holds it
            srgb = material.extras["srgb"]
            assert np.allclose(base["factor"][:3], _srgb_to_blender_linear(srgb), atol=1e-4)
    assert report["shape_keys_total"] == sum(
        len((m.extras or {}).get("targetNames", [])) for m in gltf.meshes
    )


def test_blender_shows_the_reference_glb_colours(imported: dict, head_female) -> None:
    """Preset colours: skin and lips per vertex, ivory bone, textured brown eyes."""
    report = imported["reports"]["reference.glb"]
    mats, objects = _materials(report), _objects(report)
    looks = ap.head_looks(head_female.meshes, head_female.eye_centres, regions=head_female.regions)
    want = looks["skin"].vertex_srgb
    assert want is not None
    (colours,) = objects["skin"]["colour_attributes"]
    # byte colours: Blender keeps COLOR_0 as 8-bit sRGB, within 1 of the tone
    assert np.abs(np.subtract(colours["mean_srgb255"], want.mean(axis=0))).max() <= 1.5
    assert np.abs(np.subtract(colours["min_srgb255"], want.min(axis=0))).max() <= 1
    assert np.abs(np.subtract(colours["max_srgb255"], want.max(axis=0))).max() <= 1
    assert mats["skin"]["base_colour"]["source"] == "vertex colour"
    bone = mats["bone"]["base_colour"]
    assert bone["source"] == "factor" and bone["factor_srgb255"] == list(ap.BONE.srgb)
    assert mats["teeth"]["base_colour"]["factor_srgb255"] == list(ap.TEETH.srgb)
    assert mats["tongue"]["base_colour"]["factor_srgb255"] == list(ap.TONGUE.srgb)
    assert objects["upper_teeth"]["materials"] == ["teeth"]
    assert objects["cranium"]["materials"] == objects["mandible"]["materials"] == ["bone"]
    eye = mats["eye_brown"]["base_colour"]
    assert eye["source"] == "texture"
    tex = _texels(imported, "reference.glb", "eyes")
    _assert_front_of_each_eye_is_the_pupil(_head_frame_mm(tex["co"], 1e-3), tex["srgb"])


def test_blender_shows_the_atlas_glb_colours(imported: dict) -> None:
    """The skin atlas's texels where they were painted; per-vertex blue eyes."""
    report = imported["reports"]["atlas.glb"]
    mats, objects = _materials(report), _objects(report)
    assert mats["skin"]["base_colour"]["source"] == "texture"
    assert objects["skin"]["uv_layers"] and not objects["skin"]["colour_attributes"]
    tex = _texels(imported, "atlas.glb", "skin")
    co = _head_frame_mm(tex["co"], 1e-3)
    error = np.abs(tex["srgb"] - _atlas_colour(co[:, 0], co[:, 2])).max(axis=1)
    assert len(error) == objects["skin"]["polygons"]
    assert np.percentile(error, 95) < 3 and error.max() < TEXEL_TOLERANCE, error.max()
    eyes = mats["eye_blue"]["base_colour"]
    assert eyes["source"] == "vertex colour"
    (colours,) = objects["eyes"]["colour_attributes"]
    assert colours["distinct_colours"] > 100  # iris fibres, limbal ring, pupil, sclera
    assert max(colours["min_srgb255"]) <= max(ap.PUPIL.srgb) + 2
    assert colours["max_srgb255"][2] > colours["max_srgb255"][0]  # a blue iris


def test_blender_glb_size_is_the_heads_mm_over_1000(imported: dict, head_female) -> None:
    """glTF is metres: Blender's box x 1000 is the head's box in mm, +Y up made +Z up."""
    report = imported["reports"]["reference.glb"]
    bbox = report["bbox"]
    assert bbox["bu_in_m"] == 1.0 and bbox["unit_system"] == "METRIC"
    every = np.concatenate([m.vertices for m in head_female.meshes.values()])
    assert np.allclose(bbox["size_mm"], _extent_blender(every), atol=0.01)
    assert np.allclose(np.asarray(bbox["size_bu"]) * 1000, _extent_blender(every), atol=0.01)
    assert 150 < max(bbox["size_mm"]) < 400  # a head, neither mm read as m nor m as mm
    assert report["notes"] == []


# ----------------------------------------------------------------------------- OBJ


@pytest.mark.parametrize("file_key", ["pack", "atlas_pack"])
def test_blender_shows_the_obj_materials_as_written(
    imported: dict, head_female, file_key: str
) -> None:
    report = imported["reports"][file_key]
    assert report["problems"] == []
    folder = imported["files"][file_key].parent
    atlas = _skin_atlas(head_female.skin) if file_key == "atlas_pack" else None
    looks = ap.head_looks(
        head_female.meshes,
        head_female.eye_centres,
        regions=head_female.regions,
        tone="dark",
        iris="green",
        skin_texture=atlas,
    )
    mats, objects, images = _materials(report), _objects(report), _images(report)
    written = {m.name: m for look in looks.values() for m in look.materials}
    assert set(mats) == set(written)
    for part, look in looks.items():
        obj = objects[part]
        assert obj["vertices"] == head_female.meshes[part].n_vertices
        counts = np.bincount(look.faces_of(obj["polygons"]), minlength=len(look.materials))
        want = {m.name: int(n) for m, n in zip(look.materials, counts, strict=True) if n}
        assert obj["polygons_per_material"] == want, part
    for name, material in written.items():
        base = mats[name]["base_colour"]
        if material.texture is None:
            assert base["source"] == "factor", name
            assert np.allclose(
                base["factor"][:3], _srgb_to_blender_linear(material.srgb), atol=2e-6
            )
            continue
        (tex,) = base["textures"]
        image = images[tex]
        assert image["loaded"] and not image["packed"]
        assert Path(image["filepath"]).resolve() == (folder / material.texture_file).resolve()
        assert tuple(image["size"]) == material.texture.shape[1::-1]
    tone = ap.skin_tone("dark").srgb
    if atlas is None:
        assert mats["skin"]["base_colour"]["factor_srgb255"] == list(tone)
        assert mats["lips"]["base_colour"]["factor_srgb255"] == list(ap.lip_srgb(tone))
    tex = _texels(imported, file_key, "eyes")
    _assert_front_of_each_eye_is_the_pupil(_head_frame_mm(tex["co"], 1.0), tex["srgb"])


def test_blender_shows_the_obj_atlas_where_it_was_painted(imported: dict) -> None:
    tex = _texels(imported, "atlas_pack", "skin")
    co = _head_frame_mm(tex["co"], 1.0)
    error = np.abs(tex["srgb"] - _atlas_colour(co[:, 0], co[:, 2])).max(axis=1)
    assert np.percentile(error, 95) < 3 and error.max() < TEXEL_TOLERANCE, error.max()


def test_blender_obj_is_the_heads_mm_one_unit_each(imported: dict, head_female) -> None:
    """OBJ has no unit: Blender takes the mm numbers as units (1 m each by default), so
    the head is ~0.3 km tall unless imported with Scale 0.001; the check says so."""
    report = imported["reports"]["pack"]
    every = np.concatenate([m.vertices for m in head_female.meshes.values()])
    assert np.allclose(report["bbox"]["size_bu"], _extent_blender(every), atol=1e-4)
    assert any("Scale 0.001" in note for note in report["notes"])


# ----------------------------------------------------------------------------- the check fails


def test_the_check_fails_when_a_texture_is_missing(
    imported: dict, bpy_python: str, tmp_path: Path
) -> None:
    pack = tmp_path / "pack"
    shutil.copytree(imported["files"]["pack"].parent, pack)
    (pack / "eye_green.png").unlink()
    status, stderr, (report,) = _run_check(bpy_python, [pack / "head.obj"], tmp_path)
    assert status == 1
    assert "PROBLEM: head.obj: image 'eye_green.png' did not load" in stderr
    assert any("map_Kd 'eye_green.png' not found" in p for p in report["problems"])
