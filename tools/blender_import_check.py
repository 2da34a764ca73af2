"""Import the workbench's exported meshes with real Blender and report what Blender shows.

Runs under a Python that has the ``bpy`` module (Blender as a Python module,
``pip install bpy==4.2.0`` into a separate virtual environment; Python 3.11),
not under the workbench's own environment, and imports only ``bpy``, the
standard library and numpy::

    /path/to/bpyenv/bin/python tools/blender_import_check.py FILE.glb|FILE.obj [...] \\
        [--json report.json] [--png out.png] [--view front|three-quarter|left|right] \\
        [--zoom 3] [--shape-key au26=1] [--hide skin] [--obj-scale 0.001]

For each file, Blender is reset to an empty scene and the file is imported with
Blender's own importer (``bpy.ops.import_scene.gltf`` for ``.glb``/``.gltf``,
``bpy.ops.wm.obj_import`` for ``.obj``, its default axes: forward -Z, up Y).
The report (JSON on stdout, or ``--json FILE``; a list with one entry per
file) holds:

* ``objects``: every object, its parent, vertex and polygon counts, material
  slots and polygons per material, UV layers, colour attributes (``Color
  Attribute`` layers, with their mean/min/max sRGB 0-255) and shape keys
  (glTF morph targets);
* ``materials``: each material's Principled BSDF base colour: the constant
  factor (linear RGBA, and as sRGB 0-255) and what feeds the input (an image
  texture, a Color Attribute / vertex-colour node, a constant);
* ``images``: the image textures, their size, whether the pixels loaded, and
  their mean stored (sRGB) colour and share of dark pixels (a pupil);
* ``expected``: what the file itself says (glTF materials, ``baseColorFactor``,
  textures, ``COLOR_0``, morph-target names; the OBJ's ``usemtl`` names and its
  ``.mtl``'s ``Kd``/``map_Kd``), and ``problems``: where Blender differs;
* ``bbox``: the bounding box of all meshes in Blender units (BU, world space,
  Blender's +Z up) and in mm taking 1 BU = ``scene.unit_settings.scale_length``
  metres (Blender's default: 1 BU = 1 m).

Units: the workbench's ``.glb`` files are metres (a coordinate x 1000 is the
mm of its PLY files), so a head with its neck imports about 0.3 BU = 300 mm
tall.  Its OBJ files are mm without a unit in the file, so Blender (1 BU = 1 m)
shows that head 300 BU = 300 m tall unless the import scale is 0.001 (``--obj-scale 0.001``,
Blender's *Scale* field); the report's ``notes`` say so.

The exit status is 1 (with a ``PROBLEM:`` line on stderr for each) when a
material named by the file is missing in Blender, a material has no Principled
BSDF, a base colour differs from the file's, a texture the file names is not
connected or its image did not load, a ``COLOR_0`` did not become a colour
attribute feeding the material, a mesh has no material (or polygons on an empty
slot), or the shape keys differ from the morph targets; 2 for a file that
cannot be read or imported (or any other error); else 0.  The process leaves
with ``os._exit``: bpy 4.2 as a module crashes in its own exit handlers
(SIGSEGV) once the glTF importer has run.

``--texels DIR`` writes, per textured object, each polygon's centroid (BU),
UV and the texel Blender maps there (``DIR/<file stem>__<object>.npz``), so a
caller can check a texture's orientation against what it painted.

``--png OUT.png`` renders each file (Cycles on the CPU, ``--samples`` samples,
``--size`` pixels square, the *Standard* view transform so colours are shown
as stored) with a camera framing all meshes; with several files each picture
is ``OUT_<file stem>.png``.  ``--view`` picks the side: ``front`` looks along
Blender's +Y (the face of a head in the head frame, y up and z toward the face,
imported from glTF or OBJ with default axes).  ``--shape-key NAME=W`` sets a
shape key (its clip is removed so the weight holds), ``--hide NAME`` hides an
object (``--hide skin`` shows teeth, bone and eyes).
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import os
import struct
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import bpy
import numpy as np
from mathutils import Vector

#: base colours within this of the file's (linear, per channel) agree
FACTOR_TOLERANCE = 2e-3

#: stored value below which an image pixel counts as dark (pupil, limbal ring)
DARK = 0.12


# ----------------------------------------------------------------------------- helpers


@contextlib.contextmanager
def _stdout_to_stderr() -> Iterator[None]:
    """Send Blender's own printing (C and Python) to stderr, so stdout stays JSON."""
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        os.dup2(2, 1)
        yield
    finally:
        sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)


def _linear_to_srgb(c: np.ndarray) -> np.ndarray:
    c = np.clip(np.asarray(c, float), 0.0, 1.0)
    return np.where(c <= 0.0031308, 12.92 * c, 1.055 * np.power(c, 1 / 2.4) - 0.055)


def _srgb255(linear_rgb: Any) -> list[int]:
    return [int(round(v)) for v in 255 * _linear_to_srgb(np.asarray(linear_rgb, float)[:3])]


def _rounded(values: Any, digits: int = 6) -> list[float]:
    return [round(float(v), digits) for v in values]


# ----------------------------------------------------------------------------- what the file says


def _glb_json(path: Path) -> dict:
    """The JSON chunk of a ``.glb`` (or a ``.gltf``'s JSON)."""
    data = path.read_bytes()
    if path.suffix.lower() == ".gltf":
        return json.loads(data)
    magic, version, length = struct.unpack("<4sII", data[:12])
    if magic != b"glTF" or version != 2 or length != len(data):
        raise ValueError(f"{path}: not a glTF 2.0 binary")
    chunk_length, chunk_type = struct.unpack("<II", data[12:20])
    if chunk_type != 0x4E4F534A:  # "JSON"
        raise ValueError(f"{path}: first chunk is not JSON")
    return json.loads(data[20 : 20 + chunk_length])


def _expected_gltf(path: Path) -> dict:
    """Materials, textures, colours and morph targets as the glTF file states them."""
    doc = _glb_json(path)
    materials = doc.get("materials", [])
    meshes = doc.get("meshes", [])
    used: dict[str, dict] = {}
    for mesh in meshes:
        for prim in mesh.get("primitives", []):
            if "material" not in prim:
                continue
            mat = materials[prim["material"]]
            pbr = mat.get("pbrMetallicRoughness", {})
            entry = used.setdefault(
                mat.get("name", f"material_{prim['material']}"),
                {
                    "base_color_factor": pbr.get("baseColorFactor", [1.0, 1.0, 1.0, 1.0]),
                    "texture": "baseColorTexture" in pbr,
                    "vertex_colours": False,
                    "srgb": (mat.get("extras") or {}).get("srgb"),
                    "meshes": [],
                },
            )
            entry["vertex_colours"] |= "COLOR_0" in prim.get("attributes", {})
            if mesh.get("name") not in entry["meshes"]:
                entry["meshes"].append(mesh.get("name"))
    nodes = {}
    for node in doc.get("nodes", []):
        if "mesh" not in node:
            continue
        mesh = meshes[node["mesh"]]
        prims = mesh.get("primitives", [])
        nodes[node.get("name", mesh.get("name"))] = {
            "mesh": mesh.get("name"),
            "morph_targets": (mesh.get("extras") or {}).get("targetNames")
            or [f"target_{i}" for i in range(len(prims[0].get("targets", [])) if prims else 0)],
            "vertex_colours": any("COLOR_0" in p.get("attributes", {}) for p in prims),
            "texcoords": any("TEXCOORD_0" in p.get("attributes", {}) for p in prims),
        }
    return {
        "materials": used,
        "nodes": nodes,
        "images": len(doc.get("images", [])),
        "asset_extras": (doc.get("asset") or {}).get("extras"),
    }


def _expected_obj(path: Path) -> dict:
    """``usemtl`` names per ``o`` object, and the material library's ``Kd``/``map_Kd``."""
    libs: list[str] = []
    objects: dict[str, dict[str, Any]] = {}
    current: dict[str, Any] = {"materials": [], "vertices": 0}
    objects[path.stem] = current
    with path.open(encoding="utf-8", errors="replace") as fh:
        for line in fh:
            if line.startswith("v "):
                current["vertices"] += 1
            elif line.startswith("o "):  # Blender splits by object, not by group
                current = {"materials": [], "vertices": 0}
                objects[line[2:].strip()] = current
            elif line.startswith("usemtl "):
                name = line[7:].strip()
                if name not in current["materials"]:
                    current["materials"].append(name)
            elif line.startswith("mtllib "):
                libs.extend(line[7:].split())
    objects = {k: v for k, v in objects.items() if v["vertices"] or v["materials"]}
    materials: dict[str, dict] = {}
    missing_libs = []
    for lib in libs:
        lib_path = path.parent / lib
        if not lib_path.is_file():
            missing_libs.append(lib)
            continue
        mat: dict | None = None
        for raw in lib_path.read_text(encoding="utf-8", errors="replace").splitlines():
            words = raw.split("#")[0].split()
            if not words:
                continue
            if words[0] == "newmtl":
                mat = materials[" ".join(words[1:])] = {
                    "kd": [1.0, 1.0, 1.0],
                    "map_kd": None,
                    "map_kd_exists": None,
                }
            elif mat is not None and words[0] == "Kd":
                mat["kd"] = [float(w) for w in words[1:4]]
            elif mat is not None and words[0] == "map_Kd":
                mat["map_kd"] = words[-1]
                mat["map_kd_exists"] = (lib_path.parent / words[-1]).is_file()
    used = {m for o in objects.values() for m in o["materials"]}
    return {
        "mtllib": libs,
        "missing_mtllib": missing_libs,
        "objects": objects,
        "materials": {k: v for k, v in materials.items() if k in used},
        "undefined_materials": sorted(used - set(materials)),
    }


# ----------------------------------------------------------------------------- what Blender shows


def _trace(socket: Any, depth: int = 0) -> list[dict]:
    """The leaves feeding ``socket``: constants, image textures, colour attributes."""
    if not socket.is_linked:
        value = socket.default_value
        if hasattr(value, "__len__") and len(value) >= 3:
            return [{"constant": _rounded(value)}]
        return [{"constant": [round(float(value), 6)] * 3 + [1.0]}]
    if depth > 16:
        return [{"node": "too deep"}]
    node = socket.links[0].from_node
    kind = node.type
    if kind == "TEX_IMAGE":
        return [{"texture": node.image.name if node.image else None}]
    if kind == "VERTEX_COLOR":
        return [{"vertex_colour": node.layer_name or "(active)"}]
    if kind == "ATTRIBUTE":
        return [{"attribute": node.attribute_name}]
    if kind == "RGB":
        return [{"constant": _rounded(node.outputs[0].default_value)}]
    if kind in ("MIX", "MIX_RGB"):
        blend = getattr(node, "blend_type", "MIX")
        pairs = (
            [s for s in node.inputs if s.identifier in ("A_Color", "B_Color")]
            if kind == "MIX"
            else [s for s in node.inputs if s.name in ("Color1", "Color2")]
        )
        out: list[dict] = [{"mix": blend}]
        for s in pairs:
            out += _trace(s, depth + 1)
        return out
    out = [{"node": kind}]
    for s in node.inputs:
        if s.is_linked:
            out += _trace(s, depth + 1)
    return out


def _material_report(mat: Any) -> dict:
    entry: dict[str, Any] = {"name": mat.name, "users": mat.users, "principled": False}
    if not mat.use_nodes or mat.node_tree is None:
        entry["base_colour"] = {"factor": _rounded(mat.diffuse_color), "linked": False}
        return entry
    principled = [n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED"]
    if not principled:
        return entry
    bsdf = principled[0]
    entry["principled"] = True
    base = bsdf.inputs["Base Color"]
    leaves = _trace(base)
    constants = [np.asarray(x["constant"], float) for x in leaves if "constant" in x]
    textures = [x["texture"] for x in leaves if "texture" in x]
    vertex = [x.get("vertex_colour") or x.get("attribute") for x in leaves]
    vertex = [v for v in vertex if v]
    if base.is_linked:
        # under a texture or colour attribute the constants along the chain multiply it
        factor = np.prod(constants, axis=0) if constants else np.ones(4)
    else:
        factor = np.asarray(base.default_value, float)
    if textures:
        source = "texture"
    elif vertex:
        source = "vertex colour"
    elif base.is_linked:
        source = "node"
    else:
        source = "factor"
    entry["base_colour"] = {
        "factor": _rounded(factor),
        "factor_srgb255": _srgb255(factor),
        "linked": base.is_linked,
        "source": source,
        "textures": textures,
        "colour_attributes": vertex,
        "chain": leaves,
    }
    entry["roughness"] = round(float(bsdf.inputs["Roughness"].default_value), 4)
    entry["metallic"] = round(float(bsdf.inputs["Metallic"].default_value), 4)
    return entry


def _image_report(img: Any) -> dict:
    w, h = (int(v) for v in img.size)
    # a file that failed to load becomes a 0 x 0 placeholder (type UV_TEST: Blender's
    # OBJ importer) that still says has_data
    loaded = bool(img.has_data) and w > 0 and h > 0 and img.type == "IMAGE"
    entry: dict[str, Any] = {
        "type": img.type,
        "name": img.name,
        "source": img.source,
        "filepath": bpy.path.abspath(img.filepath) if img.filepath else "",
        "packed": img.packed_file is not None,
        "size": [w, h],
        "loaded": loaded,
        "colorspace": img.colorspace_settings.name,
    }
    if loaded:
        rgb = _image_array(img).reshape(-1, 3)
        entry["mean_stored_255"] = [int(round(v)) for v in 255 * rgb.mean(axis=0)]
        entry["dark_fraction"] = round(float((rgb.max(axis=1) < DARK).mean()), 4)
    return entry


def _colour_attribute_report(attr: Any) -> dict:
    n = len(attr.data)
    entry: dict[str, Any] = {
        "name": attr.name,
        "domain": attr.domain,
        "data_type": attr.data_type,
        "count": n,
    }
    if n:
        c = np.empty(n * 4, np.float32)
        attr.data.foreach_get("color_srgb", c)
        rgb = 255 * c.reshape(-1, 4)[:, :3]
        entry["mean_srgb255"] = [int(round(v)) for v in rgb.mean(axis=0)]
        entry["min_srgb255"] = [int(round(v)) for v in rgb.min(axis=0)]
        entry["max_srgb255"] = [int(round(v)) for v in rgb.max(axis=0)]
        entry["distinct_colours"] = int(len(np.unique(np.round(rgb).astype(np.int32), axis=0)))
    return entry


def _object_report(obj: Any) -> dict:
    entry: dict[str, Any] = {
        "name": obj.name,
        "type": obj.type,
        "parent": obj.parent.name if obj.parent else None,
    }
    if obj.type != "MESH":
        return entry
    me = obj.data
    slots = [s.material.name if s.material else None for s in obj.material_slots]
    index = np.empty(len(me.polygons), np.int32)
    me.polygons.foreach_get("material_index", index)
    per: dict[str, int] = {}
    for k, count in zip(*np.unique(index, return_counts=True), strict=True):
        name = slots[k] if k < len(slots) and slots[k] else f"(empty slot {k})"
        per[name] = per.get(name, 0) + int(count)
    keys = me.shape_keys.key_blocks if me.shape_keys else []
    entry.update(
        vertices=len(me.vertices),
        polygons=len(me.polygons),
        materials=slots,
        polygons_per_material=per,
        uv_layers=[u.name for u in me.uv_layers],
        colour_attributes=[_colour_attribute_report(a) for a in me.color_attributes],
        shape_keys=[k.name for k in keys][1:],
        shape_key_count=max(len(keys) - 1, 0),
    )
    return entry


def _image_array(img: Any) -> np.ndarray:
    """``(h, w, 3)`` stored values 0-1 (sRGB for 8-bit images); row 0 is the bottom."""
    w, h = (int(v) for v in img.size)
    px = np.empty(w * h * img.channels, np.float32)
    img.pixels.foreach_get(px)
    return px.reshape(h, w, img.channels)[..., :3]


def texel_samples(obj: Any) -> dict[str, np.ndarray] | None:
    """Per textured polygon: world centroid (BU), centroid UV and the texel there (sRGB 0-255).

    The image is the one feeding the base colour of the polygon's material, read
    at the active UV map (nearest texel), as Blender maps it: this checks the
    texture's orientation end to end, not only that it loaded.
    """
    me = obj.data
    if obj.type != "MESH" or me.uv_layers.active is None:
        return None
    images = []
    for slot in obj.material_slots:
        tex = None
        if slot.material is not None and slot.material.use_nodes:
            for node in slot.material.node_tree.nodes:
                if node.type == "BSDF_PRINCIPLED":
                    names = [x.get("texture") for x in _trace(node.inputs["Base Color"])]
                    names = [n for n in names if n and n in bpy.data.images]
                    tex = bpy.data.images[names[0]] if names else None
                    break
        usable = tex is not None and tex.has_data and tex.type == "IMAGE" and tex.size[0] > 0
        images.append(tex if usable else None)
    n_loops = len(me.loops)
    flat_uv = np.empty(n_loops * 2, np.float64)
    me.uv_layers.active.data.foreach_get("uv", flat_uv)
    uv = flat_uv.reshape(-1, 2)
    co = np.empty(len(me.vertices) * 3, np.float64)
    me.vertices.foreach_get("co", co)
    loop_vertex = np.empty(n_loops, np.int64)
    me.loops.foreach_get("vertex_index", loop_vertex)
    start = np.empty(len(me.polygons), np.int64)
    total = np.empty(len(me.polygons), np.int64)
    which = np.empty(len(me.polygons), np.int64)
    me.polygons.foreach_get("loop_start", start)
    me.polygons.foreach_get("loop_total", total)
    me.polygons.foreach_get("material_index", which)
    m = np.array(obj.matrix_world)
    world = co.reshape(-1, 3)[loop_vertex] @ m[:3, :3].T + m[:3, 3]
    centre_uv = np.add.reduceat(uv, start, axis=0) / total[:, None]
    centre_co = np.add.reduceat(world, start, axis=0) / total[:, None]
    srgb = np.full((len(start), 3), np.nan)
    for k, img in enumerate(images):
        sel = which == k
        if img is None or not sel.any():
            continue
        pixels = _image_array(img)
        h, w = pixels.shape[:2]
        ix = np.clip(np.floor(centre_uv[sel, 0] % 1.0 * w).astype(np.int64), 0, w - 1)
        iy = np.clip(np.floor(centre_uv[sel, 1] % 1.0 * h).astype(np.int64), 0, h - 1)
        srgb[sel] = 255.0 * pixels[iy, ix]
    keep = ~np.isnan(srgb[:, 0])
    if not keep.any():
        return None
    return {"co": centre_co[keep], "uv": centre_uv[keep], "srgb": srgb[keep]}


def _mesh_points(objects: list[Any]) -> np.ndarray:
    pts = []
    for obj in objects:
        me = obj.data
        co = np.empty(len(me.vertices) * 3, np.float64)
        me.vertices.foreach_get("co", co)
        m = np.array(obj.matrix_world)
        pts.append(co.reshape(-1, 3) @ m[:3, :3].T + m[:3, 3])
    return np.concatenate(pts) if pts else np.zeros((0, 3))


def _bbox(objects: list[Any]) -> dict:
    pts = _mesh_points(objects)
    if not len(pts):
        return {}
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    scale = bpy.context.scene.unit_settings.scale_length
    return {
        "min_bu": _rounded(lo),
        "max_bu": _rounded(hi),
        "size_bu": _rounded(hi - lo),
        "size_mm": _rounded((hi - lo) * scale * 1000.0, 3),
        "bu_in_m": scale,
        "unit_system": bpy.context.scene.unit_settings.system,
    }


# ----------------------------------------------------------------------------- comparison


def _close(a: Any, b: Any) -> bool:
    return bool(
        np.allclose(np.asarray(a, float)[:3], np.asarray(b, float)[:3], atol=FACTOR_TOLERANCE)
    )


def _blender_material(mats: dict[str, dict], name: str) -> dict | None:
    """The Blender material of a file's name (Blender may add ``.001`` on a clash)."""
    if name in mats:
        return mats[name]
    for key, value in mats.items():
        if key.rsplit(".", 1)[0] == name:
            return value
    return None


def _check_common(report: dict) -> list[str]:
    problems = []
    for obj in report["objects"]:
        if obj["type"] != "MESH":
            continue
        if not obj["materials"] or all(m is None for m in obj["materials"]):
            problems.append(f"mesh {obj['name']!r} has no material")
        for name in obj["polygons_per_material"]:
            if name.startswith("(empty slot"):
                problems.append(f"mesh {obj['name']!r}: polygons on {name}")
    for mat in report["materials"]:
        if not mat["principled"]:
            problems.append(f"material {mat['name']!r} has no Principled BSDF")
    images = {i["name"]: i for i in report["images"]}
    for img in report["images"]:
        if not img["loaded"]:
            problems.append(
                f"image {img['name']!r} did not load ({img['filepath'] or 'packed'}; "
                f"size {img['size']})"
            )
    for mat in report["materials"]:
        for tex in (mat.get("base_colour") or {}).get("textures", []):
            if tex is None:
                problems.append(f"material {mat['name']!r}: image texture node without image")
            elif tex in images and not images[tex]["loaded"]:
                problems.append(f"material {mat['name']!r}: its texture {tex!r} did not load")
    return problems


def _check_gltf(report: dict, expected: dict) -> list[str]:
    problems = []
    mats = {m["name"]: m for m in report["materials"]}
    objects = {o["name"]: o for o in report["objects"]}
    for name, want in expected["materials"].items():
        got = _blender_material(mats, name)
        if got is None:
            problems.append(f"glTF material {name!r} is missing in Blender")
            continue
        base = got.get("base_colour") or {}
        if not _close(base.get("factor", [0, 0, 0]), want["base_color_factor"]):
            problems.append(
                f"material {name!r}: base colour {base.get('factor')} in Blender, "
                f"{want['base_color_factor']} in the file"
            )
        if want["texture"] and not base.get("textures"):
            problems.append(f"material {name!r}: the file's baseColorTexture is not connected")
        if want["vertex_colours"] and not want["texture"] and not base.get("colour_attributes"):
            problems.append(
                f"material {name!r}: the file's COLOR_0 does not feed the base colour "
                "(the mesh would show the plain factor)"
            )
    for name, want in expected["nodes"].items():
        obj = objects.get(name)
        if obj is None:
            problems.append(f"glTF node {name!r} is not a Blender object")
            continue
        if want["vertex_colours"] and not obj.get("colour_attributes"):
            problems.append(f"object {name!r}: the file's COLOR_0 is not a colour attribute")
        if want["texcoords"] and not obj.get("uv_layers"):
            problems.append(f"object {name!r}: the file's TEXCOORD_0 is not a UV map")
        if obj.get("shape_keys", []) != list(want["morph_targets"]):
            problems.append(
                f"object {name!r}: shape keys {obj.get('shape_keys')} in Blender, morph "
                f"targets {want['morph_targets']} in the file"
            )
    return problems


def _check_obj(report: dict, expected: dict) -> list[str]:
    problems = [f"material library {lib!r} not found" for lib in expected["missing_mtllib"]]
    problems += [f"usemtl {m!r} is in no material library" for m in expected["undefined_materials"]]
    mats = {m["name"]: m for m in report["materials"]}
    objects = {o["name"]: o for o in report["objects"]}
    for name, want in expected["materials"].items():
        got = _blender_material(mats, name)
        if got is None:
            problems.append(f"OBJ material {name!r} is missing in Blender")
            continue
        base = got.get("base_colour") or {}
        if want["map_kd"]:
            if not want["map_kd_exists"]:
                problems.append(f"material {name!r}: map_Kd {want['map_kd']!r} not found")
            if not base.get("textures"):
                problems.append(f"material {name!r}: map_Kd {want['map_kd']!r} is not connected")
        elif not _close(base.get("factor", [0, 0, 0]), want["kd"]):
            problems.append(
                f"material {name!r}: base colour {base.get('factor')} in Blender, "
                f"Kd {want['kd']} in the file"
            )
    for name, want in expected["objects"].items():
        obj = objects.get(name)
        if obj is None:
            problems.append(f"OBJ object {name!r} is not a Blender object")
            continue
        slots = [m.rsplit(".", 1)[0] if m else None for m in obj.get("materials", [])]
        for m in want["materials"]:
            if m not in slots:
                problems.append(f"object {name!r}: material {m!r} not in its slots {slots}")
    return problems


# ----------------------------------------------------------------------------- import, report


def _reset() -> None:
    bpy.ops.wm.read_factory_settings(use_empty=True)


def import_file(path: Path, obj_scale: float) -> str:
    """Import ``path`` into the (empty) scene; returns the importer used."""
    suffix = path.suffix.lower()
    if suffix in (".glb", ".gltf"):
        result = bpy.ops.import_scene.gltf(filepath=str(path))
        importer = "import_scene.gltf"
    elif suffix == ".obj":
        result = bpy.ops.wm.obj_import(filepath=str(path), global_scale=obj_scale)
        importer = f"wm.obj_import (global_scale {obj_scale})"
    else:
        raise ValueError(f"{path}: not .glb, .gltf or .obj")
    if "FINISHED" not in result:
        raise RuntimeError(f"{path}: the importer returned {sorted(result)}")
    return importer


def check_file(path: Path, obj_scale: float = 1.0) -> dict:
    """Import ``path`` into an empty scene and report what Blender shows (see the module)."""
    _reset()
    suffix = path.suffix.lower()
    expected = _expected_obj(path) if suffix == ".obj" else _expected_gltf(path)
    with _stdout_to_stderr():
        importer = import_file(path, obj_scale)
    meshes = [o for o in bpy.context.scene.objects if o.type == "MESH"]
    report: dict[str, Any] = {
        "file": str(path),
        "blender": bpy.app.version_string,
        "importer": importer,
        "objects": [
            _object_report(o) for o in sorted(bpy.context.scene.objects, key=lambda o: o.name)
        ],
        "materials": [
            _material_report(m) for m in sorted(bpy.data.materials, key=lambda m: m.name)
        ],
        "images": [
            _image_report(i)
            for i in sorted(bpy.data.images, key=lambda i: i.name)
            if i.type not in ("RENDER_RESULT", "COMPOSITING")
        ],
        "shape_keys_total": sum(
            len(o.data.shape_keys.key_blocks) - 1 for o in meshes if o.data.shape_keys
        ),
        "bbox": _bbox(meshes),
        "expected": expected,
    }
    problems = _check_common(report)
    problems += _check_obj(report, expected) if suffix == ".obj" else _check_gltf(report, expected)
    report["problems"] = problems
    notes = []
    size_m = (
        max(report["bbox"].get("size_bu", [0.0])) * bpy.context.scene.unit_settings.scale_length
    )
    if size_m > 2.0:
        notes.append(
            f"the largest extent is {size_m:g} m in Blender (1 BU = 1 m): a head is about "
            "0.2-0.3 m; OBJ vertices are mm, import with Scale 0.001 (--obj-scale 0.001)"
        )
    elif 0 < size_m < 0.02:
        notes.append(f"the largest extent is {size_m:g} m in Blender: too small for a head")
    report["notes"] = notes
    return report


# ----------------------------------------------------------------------------- picture

VIEWS = {"front": 0.0, "three-quarter": 35.0, "left": 90.0, "right": -90.0}


def render(
    png: Path, view: str, size: int, samples: int, elevation: float, zoom: float = 1.0
) -> None:
    """Render the imported scene to ``png`` (Cycles CPU), all meshes framed (``zoom`` > 1:
    the camera that much closer to their centre)."""
    scene = bpy.context.scene
    meshes = [o for o in scene.objects if o.type == "MESH" and not o.hide_render]
    pts = _mesh_points(meshes)
    if not len(pts):
        raise RuntimeError("nothing to render")
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    centre = Vector(((lo + hi) / 2).tolist())
    radius = float(np.linalg.norm(hi - lo) / 2)
    # front: the camera on Blender's -Y looking along +Y; turn about +Z by the view's angle
    az, el = math.radians(VIEWS[view]), math.radians(elevation)
    direction = Vector((math.sin(az) * math.cos(el), -math.cos(az) * math.cos(el), math.sin(el)))
    cam_data = bpy.data.cameras.new("check_camera")
    cam_data.lens_unit = "FOV"
    cam_data.angle = math.radians(30.0)
    distance = radius / math.sin(cam_data.angle / 2) * 1.02 / zoom
    cam_data.clip_start = distance * 0.01
    cam_data.clip_end = distance * 10
    cam = bpy.data.objects.new("check_camera", cam_data)
    scene.collection.objects.link(cam)
    cam.location = centre + direction * distance
    cam.rotation_euler = (-direction).to_track_quat("-Z", "Y").to_euler()
    scene.camera = cam
    sun_data = bpy.data.lights.new("check_sun", "SUN")
    sun_data.energy = 3.0
    sun_data.angle = math.radians(12.0)  # soft shadow edges
    sun = bpy.data.objects.new("check_sun", sun_data)
    scene.collection.objects.link(sun)
    key = Vector((math.sin(az + 0.6), -math.cos(az + 0.6), 0.8)).normalized()
    sun.rotation_euler = (-key).to_track_quat("-Z", "Y").to_euler()
    world = bpy.data.worlds.new("check_world")
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (0.55, 0.55, 0.55, 1.0)
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 1.0
    scene.world = world
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = samples
    scene.cycles.use_denoising = False
    scene.render.resolution_x = scene.render.resolution_y = size
    scene.render.resolution_percentage = 100
    scene.render.image_settings.file_format = "PNG"
    scene.view_settings.view_transform = "Standard"
    scene.render.filepath = str(png)
    png.parent.mkdir(parents=True, exist_ok=True)
    with _stdout_to_stderr():
        bpy.ops.render.render(write_still=True)


def _apply_scene_options(shape_keys: list[str], hide: list[str]) -> None:
    for text in shape_keys:
        name, _, weight = text.partition("=")
        found = False
        for obj in bpy.context.scene.objects:
            keys = obj.data.shape_keys if obj.type == "MESH" else None
            if keys is not None and name in keys.key_blocks:
                keys.animation_data_clear()  # the imported clip would override the weight
                keys.key_blocks[name].value = float(weight or 1.0)
                found = True
        if not found:
            print(f"note: no shape key {name!r}", file=sys.stderr)
    for name in hide:
        obj = bpy.context.scene.objects.get(name)
        if obj is None:
            print(f"note: no object {name!r} to hide", file=sys.stderr)
        else:
            obj.hide_render = True


# ----------------------------------------------------------------------------- main


def _write_texels(folder: Path, path: Path) -> dict[str, str]:
    folder.mkdir(parents=True, exist_ok=True)
    written = {}
    for obj in bpy.context.scene.objects:
        samples = texel_samples(obj) if obj.type == "MESH" else None
        if samples is not None:
            out = folder / f"{path.stem}__{obj.name}.npz"
            np.savez(out, co=samples["co"], uv=samples["uv"], srgb=samples["srgb"])
            written[obj.name] = str(out)
    return written


def _png_for(png: Path, path: Path, several: bool) -> Path:
    return png.with_name(f"{png.stem}_{path.stem}{png.suffix}") if several else png


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("files", nargs="+", type=Path, help=".glb, .gltf or .obj files")
    p.add_argument("--json", type=Path, help="write the report here instead of stdout")
    p.add_argument("--png", type=Path, help="render a picture (several files: OUT_<stem>.png)")
    p.add_argument("--view", choices=sorted(VIEWS), default="front")
    p.add_argument("--elevation", type=float, default=10.0, help="camera elevation, degrees")
    p.add_argument("--size", type=int, default=800, help="picture size in pixels (square)")
    p.add_argument("--samples", type=int, default=24, help="Cycles samples")
    p.add_argument("--zoom", type=float, default=1.0, help="> 1: the camera closer")
    p.add_argument("--shape-key", action="append", default=[], metavar="NAME=W")
    p.add_argument("--hide", action="append", default=[], metavar="OBJECT")
    p.add_argument(
        "--texels",
        type=Path,
        metavar="DIR",
        help="write DIR/<file stem>__<object>.npz per textured object: polygon centroids "
        "(co, BU), their UV and the texel there (srgb, 0-255)",
    )
    p.add_argument(
        "--obj-scale", type=float, default=1.0, help="OBJ import scale (Blender's default 1)"
    )
    args = p.parse_args(argv)
    reports, status = [], 0
    for path in args.files:
        path = path.resolve()
        try:
            report = check_file(path, args.obj_scale)
        except (OSError, ValueError, RuntimeError) as exc:
            print(f"ERROR: {path}: {exc}", file=sys.stderr)
            reports.append({"file": str(path), "error": str(exc)})
            status = max(status, 2)
            continue
        for problem in report["problems"]:
            print(f"PROBLEM: {path.name}: {problem}", file=sys.stderr)
        for note in report["notes"]:
            print(f"note: {path.name}: {note}", file=sys.stderr)
        if report["problems"]:
            status = max(status, 1)
        if args.texels:
            report["texels"] = _write_texels(args.texels, path)
        if args.png:
            out = _png_for(args.png, path, len(args.files) > 1).resolve()
            _apply_scene_options(args.shape_key, args.hide)
            render(out, args.view, args.size, args.samples, args.elevation, args.zoom)
            report["png"] = str(out)
            print(f"rendered {out}", file=sys.stderr)
        reports.append(report)
    text = json.dumps(reports, indent=1)
    if args.json:
        args.json.write_text(text + "\n", encoding="utf-8")
    else:
        print(text)
    return status


if __name__ == "__main__":
    argv = sys.argv[1:] if "--" not in sys.argv else sys.argv[sys.argv.index("--") + 1 :]
    try:
        code = main(argv)
    except SystemExit as exc:  # argparse: --help, bad arguments
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 2)
    except BaseException:  # noqa: BLE001 -- whatever fails must still reach os._exit below
        import traceback

        traceback.print_exc()
        code = 2
    sys.stdout.flush()
    sys.stderr.flush()
    # bpy 4.2 as a module crashes in its exit handlers once the glTF add-on has run
    # (SpaceType destructors call into an already finalised Python): leave without them
    os._exit(code)
