"""Blender imports hair, brows, beard and moustache from the workbench's ``.glb`` and
``head.obj`` (issue 34): each piece an object with its material and colours, the glTF
pieces with a shape key per expression (from sparse morph targets), and every OBJ object
shaded smooth (``s 1``).

Runs real Blender as ``test_blender_import.py`` does (``WORKBENCH_BPY_PYTHON``, a Python
with ``bpy``); skipped without it."""

from __future__ import annotations

import importlib.util
import json
import subprocess

import numpy as np
import pytest
from test_blender_import import BPY_PYTHON, _run_check, bpy_python  # noqa: F401

from workbench.core import appearance as ap
from workbench.model.appearance import Appearance, Hsv

pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(
        not BPY_PYTHON and importlib.util.find_spec("bpy") is None,
        reason="Blender's bpy module is not available: set WORKBENCH_BPY_PYTHON to a Python "
        "with bpy (pip install bpy==4.2.0 into a separate venv, Python 3.11)",
    ),
]

LOOK = Appearance(
    regions={"hair": Hsv(0.09, 0.5, 0.45)},
    grooming={"hair": "buzz", "brows": "straight", "beard": "short", "moustache": "short"},
)
KINDS = ("hair", "brows", "beard", "moustache")
TARGETS = ["au1", "au26"]

#: imports head.obj and prints, per mesh object, whether every polygon is shaded smooth
SMOOTH_SCRIPT = """
import json, os, sys
import bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.wm.obj_import(filepath=sys.argv[-1])
out = {o.name: all(p.use_smooth for p in o.data.polygons)
       for o in bpy.context.scene.objects if o.type == "MESH"}
print("SMOOTH " + json.dumps(out), flush=True)
os._exit(0)
"""


@pytest.fixture(scope="module")
def checked(bpy_python: str, tmp_path_factory: pytest.TempPathFactory, head_male) -> dict:  # noqa: F811
    from workbench.io.template_pack import write_head_obj
    from workbench.services.animation.gltf import export_head_glb
    from workbench.services.grooming import hair_meshes
    from workbench.services.reconstruction.job import hair_look

    out = tmp_path_factory.mktemp("blender_hair")
    glb = out / "hair.glb"
    export_head_glb(head_male, glb, TARGETS, appearance=LOOK)
    pack = out / "pack"
    pack.mkdir()
    pieces = hair_meshes(head_male, LOOK)
    write_head_obj(head_male, pack, extra={p.kind: (p.mesh, hair_look(p, LOOK)) for p in pieces})
    status, stderr, reports = _run_check(bpy_python, [glb, pack / "head.obj"], out)
    assert status == 0, stderr[-3000:]
    done = subprocess.run(
        [bpy_python, "-c", SMOOTH_SCRIPT, str(pack / "head.obj")],
        capture_output=True, text=True, timeout=600, check=False,
    )  # fmt: skip
    line = next((s for s in done.stdout.splitlines() if s.startswith("SMOOTH ")), None)
    assert line is not None, done.stderr[-2000:]
    return {
        "glb": reports[0],
        "obj": reports[1],
        "smooth": json.loads(line[len("SMOOTH ") :]),
        "pieces": {p.kind: p for p in pieces},
    }


def test_blender_shows_the_glb_hair_with_shape_keys(checked: dict) -> None:
    report = checked["glb"]
    assert report["problems"] == []
    objects = {o["name"]: o for o in report["objects"]}
    materials = {m["name"]: m for m in report["materials"]}
    for kind in KINDS:
        obj = objects[kind]
        assert obj["vertices"] == checked["pieces"][kind].mesh.n_vertices
        assert obj["shape_keys"] == TARGETS  # Blender read the sparse targets
        assert obj["colour_attributes"] and obj["materials"] == [kind]
        chain = materials[kind]["base_colour"]["chain"]
        assert {"mix": "MULTIPLY"} in chain and any("vertex_colour" in c for c in chain)


def test_blender_shows_the_obj_hair_smooth_in_its_colours(checked: dict) -> None:
    from workbench.services.appearance import hsv_srgb
    from workbench.services.grooming import piece_colour

    report = checked["obj"]
    assert report["problems"] == []
    objects = {o["name"]: o for o in report["objects"]}
    materials = {m["name"]: m for m in report["materials"]}
    for kind in KINDS:
        assert objects[kind]["polygons_per_material"] == {
            kind: checked["pieces"][kind].mesh.n_faces
        }
        factor = materials[kind]["base_colour"]["factor"][:3]
        want = ap.srgb_to_linear(hsv_srgb(piece_colour(LOOK, kind)))
        assert np.allclose(factor, want, atol=2e-6), kind
    # s 1: Blender shades every object smooth (before, the head came in faceted)
    assert set(checked["smooth"]) >= {"skin", "eyes", *KINDS}
    assert all(checked["smooth"].values()), checked["smooth"]
