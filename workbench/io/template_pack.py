"""Write a reference head as a folder of standard files (a "template pack").

Layout (all meshes PLY, millimetres, head frame: x to the subject's left,
x = 0 midsagittal, y up, z toward the face, Frankfort Horizontal at y = 0)::

    skin.ply  skull.ply  mandible.ply  teeth.ply  eyes.ply  tongue.ply
    skin.mrk.json  skull.mrk.json     (3D Slicer markups; RAS = head frame axes as stored)
    muscles.json                      (24 grids of Kähler's Table 7.1 as skin triangles + barycentric
                                       weights + depth, and their positions on this skin in mm)
    template.json                     (id, content hash, sex, provenance, regions, openings)
    head.obj  head.mtl  eye_<iris>.png  (every part in one OBJ with a material each, for
                                         Blender and other tools: see write_head_obj)

The PLY files hold the geometry; ``head.obj`` holds the same vertices (mm, the
pack's frame) for tools that read materials, and may hold hair, brows, beard
and moustache after them (a reconstruction whose case chose some: artistic
additions, not evidence, and not in the PLY files).  Its colours are
artistic defaults (:mod:`workbench.core.appearance`), not evidence.  Like
the PLY files it is in mm: Blender takes an OBJ's numbers as metres, so
import it with Scale 0.001 to lay it over the glTF files (metres).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from workbench.core.appearance import (
    DEFAULT_IRIS,
    DEFAULT_SKIN_TONE,
    Look,
    SkinTexture,
    head_looks,
    srgb_to_linear,
)
from workbench.core.errors import InputError
from workbench.core.json_limits import read_json
from workbench.core.mesh import Mesh, concatenate
from workbench.io.atomic import write_bytes_atomic
from workbench.io.markups import read_mrk_json, write_mrk_json
from workbench.io.mesh_formats import obj
from workbench.io.meshes import read_mesh, write_mesh
from workbench.model.muscles import MuscleGrid
from workbench.model.template import PARTS, TemplateHead

#: largest template.json / muscles.json read: a pack's are ~60-80 KB
MAX_PACK_JSON_BYTES = 16 * 1024 * 1024

FILES = {
    "skin.ply": ("skin",),
    "skull.ply": ("cranium",),
    "mandible.ply": ("mandible",),
    "teeth.ply": ("upper_teeth", "lower_teeth"),
    "eyes.ply": ("eyes",),
    "tongue.ply": ("tongue",),
}


def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value


def _pairs(head: TemplateHead) -> dict[str, Any]:
    from workbench.io.catalogue import load_catalogue

    catalogue = load_catalogue()
    skin = head.skin_landmarks.as_dict()
    out = {}
    for code, position in head.skull_landmarks.as_dict().items():
        partner = catalogue.partner(code, "skull")
        if partner and partner in skin:
            out[code] = {"skin": partner, "offset_mm": skin[partner] - position}
    return out


#: how ``template.json`` names the frame of a pack written in the head frame
HEAD_FRAME_TEXT = (
    "head frame: x to the subject's left (x = 0 midsagittal), y up, z toward "
    "the face; Frankfort Horizontal at y = 0; origin between the porions"
)


#: the pack's OBJ of every part with its materials, and its material library
HEAD_OBJ = "head.obj"
HEAD_MTL = "head.mtl"
#: decimals (mm) of the vertices of extra parts in ``head.obj`` (hair: 1 µm, a smaller file)
EXTRA_DECIMALS = 3


def write_head_obj(
    head: TemplateHead,
    folder: str | PathLike[str],
    *,
    frame: str = HEAD_FRAME_TEXT,
    skin_tone: str = DEFAULT_SKIN_TONE,
    iris: str = DEFAULT_IRIS,
    skin_texture: SkinTexture | None = None,
    looks: Mapping[str, Look] | None = None,
    extra: Mapping[str, tuple[Mesh, Look]] | None = None,
) -> list[Path]:
    """``head.obj`` (every part an ``o`` object, its triangles under ``usemtl``),
    ``head.mtl`` and the textures it names, into ``folder``; returns the files written.

    Vertices are the head's, in mm and its frame (``frame`` says which, in a
    comment): the same numbers as the pack's PLY files, in the same part
    order.  Materials (:func:`workbench.core.appearance.head_looks`): skin
    and lips from ``skin_tone``, or the skin's colour atlas -- ``skin_texture``,
    else the pack's own ``skin_texture.png`` when ``folder`` holds one made
    for this skin (``fit-scan``); the eyes the ``iris`` texture
    (``eye_<iris>.png``, equal-area map about the gaze); teeth, bone and tongue
    their presets.  ``Kd`` is linear RGB, as Blender reads and writes it.
    ``looks`` replaces those of the parts it names (a case's chosen colours,
    :func:`workbench.services.appearance.skin_look`).

    ``extra`` adds parts after the head's own, ``{name: (mesh, look)}`` in the
    same frame and mm (the hair, brows, beard and moustache a case chose:
    artistic additions, which their materials' comments say), their vertices
    to :data:`EXTRA_DECIMALS` decimals.  Names must not be those of the head's
    parts; a material name used twice must have one colour.
    """
    from workbench.io.gltf_export import png_bytes
    from workbench.io.skin_colour_export import read_skin_texture

    out = Path(folder)
    if skin_texture is None:
        skin_texture = read_skin_texture(out, head.skin)
    looks = head_looks(
        head.meshes,
        head.eye_centres,
        regions=head.regions,
        tone=skin_tone,
        iris=iris,
        skin_texture=skin_texture,
    ) | dict(looks or {})
    # the pack's own atlas is referenced where it is; other textures are written
    kept = {skin_texture.file} if skin_texture is not None and skin_texture.file else set()
    own = [p for parts in FILES.values() for p in parts]
    extra = dict(extra or {})
    clash = sorted(set(extra) & set(own))
    if clash:
        raise ValueError(f"extra parts named as the head's own: {', '.join(clash)}")
    parts: list[tuple[str, Mesh, Look]] = [(p, head.meshes[p], looks[p]) for p in own]
    for name, (mesh, look) in extra.items():
        parts.append((name, mesh.with_vertices(np.round(mesh.vertices, EXTRA_DECIMALS)), look))
    groups: list[obj.ObjGroup] = []
    materials: dict[str, obj.MtlMaterial] = {}
    written: list[Path] = []
    for part, mesh, look in parts:
        groups.append(
            obj.ObjGroup(
                part,
                mesh.vertices,
                mesh.faces,
                [m.name for m in look.materials],
                look.face_material,
                look.corner_uv,
            )
        )
        for m in look.materials:
            if m.texture is not None and not (
                m.texture_file in kept and (out / m.texture_file).is_file()
            ):
                written.append(write_bytes_atomic(out / m.texture_file, png_bytes(m.texture)))
            kd = srgb_to_linear(m.srgb)
            if part in extra and m.name in materials and materials[m.name].kd != tuple(kd):
                raise ValueError(f"extra part {part!r}: material {m.name!r} is already defined")
            materials[m.name] = obj.MtlMaterial(
                m.name,
                (float(kd[0]), float(kd[1]), float(kd[2])),
                m.roughness,
                m.texture_file if m.texture is not None else "",
                m.metallic,
                f"sRGB {m.srgb[0]} {m.srgb[1]} {m.srgb[2]}; {m.source}",
            )
    notes = ["colours are artistic defaults, not evidence about the person"]
    comments = [f"frame: {frame}", "every part of the head; same vertices as the pack's PLY files"]
    if extra:
        names = ", ".join(extra)
        notes.append(f"{names}: artistic additions, not evidence about the person")
        comments.append(
            f"then {names}: artistic additions (not evidence), not in the PLY files; mm"
        )
    written.append(
        write_bytes_atomic(out / HEAD_MTL, obj.encode_mtl(list(materials.values()), notes))
    )
    written.append(
        write_bytes_atomic(
            out / HEAD_OBJ, obj.encode_groups(groups, mtllib=HEAD_MTL, comments=comments)
        )
    )
    return written


def export_template(
    head: TemplateHead, folder: str | PathLike[str], *, frame: str = HEAD_FRAME_TEXT
) -> list[Path]:
    """Write ``head`` into ``folder`` (created if needed); returns the files written.

    ``frame`` is recorded in ``template.json``: pass another description when
    the head was mapped out of the head frame first (a fitted head exported in
    the skull file's frame, for instance).  Units are always mm.  Besides the
    PLY files, ``head.obj`` holds every part with a material
    (:func:`write_head_obj`, default colours).
    """
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for name, parts in FILES.items():
        written.append(write_mesh(out / name, concatenate([head.meshes[p] for p in parts])))
    for name, lmset in (
        ("skin.mrk.json", head.skin_landmarks),
        ("skull.mrk.json", head.skull_landmarks),
    ):
        write_mrk_json(out / name, lmset, coordinate_system="RAS")
        written.append(out / name)
    muscles = {
        "@schema": "muscle-grids-v1",
        "units": "mm",
        "note": "points are stored on skin.ply as (triangle, barycentric weights, depth below the "
        "skin along the interpolated vertex normal); 'positions_mm' evaluates them on this skin",
        "muscles": [
            m.to_state()
            | {
                "positions_mm": m.points.evaluate(head.skin),
                "axis_positions_mm": None if m.axis is None else m.axis.evaluate(head.skin),
            }
            for m in head.muscles
        ],
    }
    path = out / "muscles.json"
    path.write_text(json.dumps(_jsonable(muscles), indent=1) + "\n", encoding="utf-8")
    written.append(path)
    written += write_head_obj(head, out, frame=frame)
    info = {
        "@schema": "template-pack-v1",
        "template_id": head.template_id,
        "content_hash": head.content_hash,
        "sex": head.sex,
        "units": "mm",
        "frame": frame,
        "files": {name: list(parts) for name, parts in FILES.items()},
        # per-part sizes so a reader can split the combined files again
        "part_sizes": {p: [head.meshes[p].n_vertices, head.meshes[p].n_faces] for p in PARTS},
        "skull_landmark_part": dict(head.skull_landmark_part),
        # Kähler §8.3.2: each skull landmark is tied to its skin partner by an
        # offset vector (skin - skull, mm); rescaling it changes tissue depth
        "pairs": _pairs(head),
        "eye_centres_mm": head.eye_centres,
        "eye_radius_mm": head.eye_radius,
        "tmj_axis": {"point_mm": head.tmj_axis[0], "direction": head.tmj_axis[1]},
        "regions": {k: np.asarray(v, dtype=int) for k, v in head.regions.items()},
        "openings": {k: np.asarray(v, dtype=int) for k, v in head.openings.items()},
        "provenance": dict(head.provenance),
    }
    path = out / "template.json"
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(_jsonable(info), indent=1) + "\n", encoding="utf-8")
    tmp.replace(path)
    written.append(path)
    return written


def _split(
    mesh: Mesh, parts: list[str], sizes: dict[str, list[int]], path: Path
) -> dict[str, Mesh]:
    out, v0, f0 = {}, 0, 0
    for part in parts:
        nv, nf = sizes[part]
        faces = mesh.faces[f0 : f0 + nf] - v0
        if len(faces) != nf or (nf and (faces.min() < 0 or faces.max() >= nv)):
            raise InputError(
                path,
                f"part {part!r} does not match the sizes in template.json",
                hint="the pack was edited or is incomplete; export it again",
            )
        out[part] = Mesh(mesh.vertices[v0 : v0 + nv], faces)
        v0, f0 = v0 + nv, f0 + nf
    if v0 != mesh.n_vertices or f0 != mesh.n_faces:
        raise InputError(
            path,
            "holds more geometry than template.json lists",
            hint="the pack was edited; export it again",
        )
    return out


def load_template_pack(folder: str | PathLike[str]) -> TemplateHead:
    """Read a folder written by :func:`export_template` back into a :class:`TemplateHead`.

    The content hash is recomputed and must equal the one recorded in
    ``template.json``; a pack whose files were changed by hand is refused,
    because cases record the hash to name exactly which head they used.
    """
    root = Path(folder)
    info_path = root / "template.json"
    if not info_path.is_file():
        raise InputError(
            root,
            "is not a template pack (no template.json)",
            hint="write one with 'workbench template export' or 'workbench template build'",
        )
    info = read_json(info_path, max_bytes=MAX_PACK_JSON_BYTES, what="template description")
    if (
        not isinstance(info, dict)
        or info.get("@schema") != "template-pack-v1"
        or "part_sizes" not in info
    ):
        raise InputError(
            info_path,
            "is not a template-pack-v1 description (or predates part sizes)",
            hint="export the pack again with this version of the workbench",
        )
    meshes: dict[str, Mesh] = {}
    for name, parts in info["files"].items():
        path = root / name
        if not path.is_file():
            raise InputError(path, "is missing from the template pack")
        meshes.update(
            _split(read_mesh(path, units="mm").mesh, list(parts), info["part_sizes"], path)
        )
    marks = {
        s: read_mrk_json(root / f"{s}.mrk.json", s, allow_undefined=True).landmarks
        for s in ("skin", "skull")
    }
    muscles_doc = read_json(
        root / "muscles.json", max_bytes=MAX_PACK_JSON_BYTES, what="muscle description"
    )
    head = TemplateHead(
        template_id=str(info["template_id"]),
        sex=str(info["sex"]),
        meshes={p: meshes[p] for p in PARTS},
        skin_landmarks=marks["skin"],
        skull_landmarks=marks["skull"],
        skull_landmark_part=dict(info["skull_landmark_part"]),
        muscles=tuple(MuscleGrid.from_state(m) for m in muscles_doc["muscles"]),
        regions={k: np.asarray(v, dtype=np.int64) for k, v in info["regions"].items()},
        openings={k: np.asarray(v, dtype=np.int64) for k, v in info["openings"].items()},
        eye_centres=np.asarray(info["eye_centres_mm"], dtype=float),
        eye_radius=float(info["eye_radius_mm"]),
        tmj_axis=np.vstack([info["tmj_axis"]["point_mm"], info["tmj_axis"]["direction"]]),
        provenance=dict(info.get("provenance", {})),
    )
    if head.content_hash != info["content_hash"]:
        raise InputError(
            root,
            "content does not match the hash recorded in template.json",
            hint="a file in the pack was changed; export or build the pack again",
        )
    return head
