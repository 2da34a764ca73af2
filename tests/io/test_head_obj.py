"""The pack's OBJ with materials (io.template_pack.write_head_obj, io.mesh_formats.obj):
every ``usemtl`` names a material of the MTL, every ``map_Kd`` file exists, the vertices
are the PLY files' and the PLY files are unchanged."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from workbench.core.mesh import concatenate
from workbench.io.mesh_formats import obj
from workbench.io.meshes import read_mesh
from workbench.io.template_pack import FILES, HEAD_MTL, HEAD_OBJ, export_template, write_head_obj


def _materials(folder: Path) -> tuple[set[str], set[str], dict[str, str]]:
    """``(usemtl names, newmtl names, material -> map_Kd)`` of the pack's OBJ and MTL."""
    text = (folder / HEAD_OBJ).read_text(encoding="utf-8")
    assert re.findall(r"^mtllib (.+)$", text, re.MULTILINE) == [HEAD_MTL]
    used = set(re.findall(r"^usemtl (\S+)$", text, re.MULTILINE))
    library = (folder / HEAD_MTL).read_text(encoding="utf-8")
    defined, maps, current = set(), {}, ""
    for line in library.splitlines():
        if line.startswith("newmtl "):
            current = line.split(None, 1)[1]
            defined.add(current)
        elif line.startswith("map_Kd "):
            maps[current] = line.split(None, 1)[1]
    return used, defined, maps


def test_pack_obj_materials_and_textures(tmp_path: Path, head_female) -> None:
    pack = tmp_path / "pack"
    written = export_template(head_female, pack)
    assert {pack / HEAD_OBJ, pack / HEAD_MTL, pack / "eye_brown.png"} <= set(written)
    used, defined, maps = _materials(pack)
    assert used == defined == {"skin", "lips", "bone", "teeth", "eye_brown", "tongue"}
    assert maps == {"eye_brown": "eye_brown.png"}
    assert all((pack / name).is_file() for name in maps.values())
    text = (pack / HEAD_OBJ).read_text(encoding="utf-8")
    parts = [p for parts in FILES.values() for p in parts]
    assert re.findall(r"^o (\S+)$", text, re.MULTILINE) == parts
    assert "# units: mm" in text and "# SPACE=RAS" in text
    # the same vertices and triangles as the PLY files, part by part
    parsed = obj.read(pack / HEAD_OBJ, (pack / HEAD_OBJ).read_bytes())
    whole = concatenate([head_female.meshes[p] for p in parts])
    assert np.array_equal(parsed.vertices, whole.vertices)
    # (the triangles of a part are grouped by material, so compare them as sets)
    assert sorted(map(tuple, parsed.faces.tolist())) == sorted(map(tuple, whole.faces.tolist()))
    for name in FILES:
        ply = read_mesh(pack / name, units="mm").mesh
        assert np.array_equal(
            ply.vertices, concatenate([head_female.meshes[p] for p in FILES[name]]).vertices
        )
    # the eyes carry texture coordinates, one per corner, inside the image
    eye_faces = re.search(r"^o eyes$(.*?)^o ", text, re.MULTILINE | re.DOTALL)
    assert eye_faces is not None and re.search(r"^f \d+/\d+ ", eye_faces.group(1), re.MULTILINE)
    uv = np.array(re.findall(r"^vt (\S+) (\S+)$", text, re.MULTILINE), float)
    assert len(uv) and uv.min() >= 0.0 and uv.max() <= 1.0


def test_pack_obj_takes_the_fits_skin_atlas(tmp_path: Path, head_female) -> None:
    """A fit-scan pack: once the atlas is written beside, head.obj maps the skin with it."""
    from workbench.core.colour_transfer import SkinColours
    from workbench.io.skin_colour_export import (
        PNG_NAME,
        read_skin_texture,
        write_coloured_skin,
    )

    pack = tmp_path / "pack"
    export_template(head_female, pack)
    n = head_female.skin.n_vertices
    rgb = np.tile(np.array([[200, 150, 120]], np.uint8), (n, 1))
    write_coloured_skin(
        pack, head_female.skin, SkinColours(rgb, np.ones(n, bool), np.zeros(n), "vertex"),
        atlas_size=256,
    )  # fmt: skip
    atlas = read_skin_texture(pack, head_female.skin)
    assert atlas is not None and atlas.file == PNG_NAME
    assert atlas.corner_uv.shape == (head_female.skin.n_faces, 3, 2)
    before = (pack / PNG_NAME).read_bytes()
    written = write_head_obj(head_female, pack, iris="grey", skin_tone="light")
    assert pack / PNG_NAME not in written and (pack / PNG_NAME).read_bytes() == before
    used, defined, maps = _materials(pack)
    assert used <= defined and maps == {"skin": PNG_NAME, "eye_grey": "eye_grey.png"}
    assert "lips" not in used  # the atlas holds the lips' own colour
    assert all((pack / name).is_file() for name in maps.values())
    # an atlas made for another skin is not taken
    assert read_skin_texture(pack, head_female.meshes["tongue"]) is None
    assert read_skin_texture(tmp_path, head_female.skin) is None
