"""Colours chosen for a face on the fitted head (issue 34, colouring; Kähler 2003 §8.6.6):
smooth region weights from the head's own regions and landmarks, the base and region
colours, and the looks an export takes (the reference head stands in for a fitted one)."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pygltflib
import pytest

from workbench.core.appearance import SKIN_TONES, lip_srgb
from workbench.io.gltf_export import write_glb
from workbench.model.appearance import ARTISTIC_NOTE, Appearance, Hsv
from workbench.model.case import Case
from workbench.services import appearance as colouring


@pytest.fixture(scope="module")
def weights(head_male):
    return colouring.region_weights(head_male)


def test_region_weights_are_smooth_fractions_where_the_regions_are(head_male, weights) -> None:
    v = head_male.skin.vertices
    lm = head_male.skin_landmarks.as_dict()
    assert set(weights) == set(colouring.PAINTED) == {"cheeks", "eyes", "brows", "lips"}
    for name, w in weights.items():
        assert w.shape == (head_male.skin.n_vertices,)
        assert 0.0 <= w.min() and w.max() <= 1.0 and w.max() > 0.99, name
        # soft edges: vertices between in and out (the lips keep the vermilion border's
        # edge: their 2 mm fade is shorter than the skin's edges there)
        assert name == "lips" or ((w > 0.05) & (w < 0.95)).any(), name
    lips = np.concatenate([head_male.regions["upper_lip"], head_male.regions["lower_lip"]])
    assert np.all(weights["lips"][lips] == 1.0)
    assert weights["lips"][head_male.regions["scalp"]].max() == 0.0
    eyelids = head_male.regions["eyelid_upper_l"]
    assert np.all(weights["eyes"][eyelids] == 1.0)
    # brows: above the upper lids and under superciliare, on both sides, not on the midline
    brow = weights["brows"] > 0.5
    for side in ("l", "r"):
        mine = brow & (np.sign(v[:, 0]) == np.sign(lm[f"sci_{side}"][0]))
        assert mine.sum() > 10
        assert v[mine, 1].min() > lm[f"ps_{side}"][1]
        assert v[mine, 1].max() < lm[f"sci_{side}"][1] + 6.0
    assert weights["brows"][np.abs(v[:, 0]) < 3.0].max() < 0.5
    # cheeks: around the cheekbone point, nothing on the lips or the forehead
    near = np.linalg.norm(v - lm["chk_l"], axis=1).argmin()
    assert weights["cheeks"][near] == 1.0
    assert weights["cheeks"][lips].max() < 0.2
    assert weights["cheeks"][v[:, 1] > lm["sci_l"][1]].max() == 0.0


def test_region_colours_follow_the_base_unless_set_by_hand() -> None:
    medium = SKIN_TONES["medium"].srgb
    assert colouring.hsv_srgb(colouring.region_colour(None, "skin")) == medium
    assert colouring.hsv_srgb(colouring.region_colour(None, "lips")) == lip_srgb(medium)
    base = colouring.region_colour(None, "skin")
    brows = colouring.region_colour(None, "brows")
    assert brows.v < base.v and abs(brows.h - base.h) < 1e-9
    dark = Appearance(tone="dark")
    assert colouring.region_colour(dark, "cheeks").v < colouring.region_colour(None, "cheeks").v
    own = Appearance(regions={"skin": (0.6, 0.2, 0.7), "lips": (0.95, 0.6, 0.5)})
    assert colouring.region_colour(own, "skin") == Hsv(0.6, 0.2, 0.7)
    assert colouring.region_colour(own, "lips") == Hsv(0.95, 0.6, 0.5)
    # a rule follows the base set by hand
    assert abs(colouring.region_colour(own, "eyes").h - 0.6) < 1e-9
    assert "set by hand" in colouring.region_source(own, "lips")
    assert "Monk" in colouring.region_source(None, "skin")
    assert ARTISTIC_NOTE in colouring.colour_summary(own)


def test_skin_colours_paint_each_region(head_male, weights) -> None:
    look = Appearance(tone="mst2", regions={"lips": (0.98, 0.7, 0.6), "brows": (0.08, 0.5, 0.2)})
    rgb = colouring.skin_colours(head_male, look, weights)
    assert rgb.shape == (head_male.skin.n_vertices, 3) and rgb.dtype == np.uint8
    scalp = head_male.regions["scalp"]
    assert np.all(rgb[scalp] == SKIN_TONES["mst2"].srgb)
    on_lip = weights["lips"] == 1.0
    assert np.all(rgb[on_lip] == colouring.hsv_srgb(Hsv(0.98, 0.7, 0.6)))
    brow = weights["brows"] > 0.99
    assert np.allclose(rgb[brow], colouring.hsv_srgb(Hsv(0.08, 0.5, 0.2)), atol=3)
    # between regions the colour changes smoothly: no edge jumps more than the region's contrast
    f = head_male.skin.faces
    jump = np.abs(rgb[f[:, 0]].astype(int) - rgb[f[:, 1]].astype(int)).max()
    assert jump <= np.abs(np.subtract(SKIN_TONES["mst2"].srgb, (51, 36, 20))).max() + 2
    assert np.array_equal(colouring.skin_colours(head_male, look), rgb)  # weights optional


def test_looks_for_an_export(head_male, tmp_path: Path) -> None:
    look = Appearance(tone="mst8", regions={"cheeks": (0.0, 0.6, 0.4)}, iris="green")
    looks = colouring.appearance_looks(head_male, look)
    skin = looks["skin"]
    assert skin.vertex_srgb is not None and len(skin.vertex_srgb) == head_male.skin.n_vertices
    assert [m.name for m in skin.materials] == ["skin", "lips"]
    assert skin.materials[0].srgb == SKIN_TONES["mst8"].srgb
    assert all(ARTISTIC_NOTE in m.source for m in skin.materials)
    assert looks["eyes"].materials[0].name == "eye_green"
    path = write_glb(
        tmp_path / "head.glb",
        head_male.skin,
        {},
        extra_nodes={"eyes": head_male.meshes["eyes"]},
        looks=looks,
    )
    gltf = pygltflib.GLTF2().load(str(path))
    skin_mesh = next(m for m in gltf.meshes if m.name == "skin")
    assert skin_mesh.primitives[0].attributes.COLOR_0 is not None
    sources = [m.extras["source"] for m in gltf.materials]
    assert any("artistic choice" in s for s in sources)


def test_the_atlas_look_carries_the_colours_into_an_obj(head_male, tmp_path: Path) -> None:
    look = Appearance(tone="mst5", regions={"lips": (0.97, 0.65, 0.55)})
    rgb = colouring.skin_colours(head_male, look)
    atlas = colouring.atlas_skin_look(head_male.skin, rgb, look)
    material = atlas.materials[0]
    assert material.texture_file == colouring.ATLAS_FILE and material.texture is not None
    assert atlas.corner_uv.shape == (head_male.skin.n_faces, 3, 2)
    # a triangle inside the lips is that colour in the atlas at its corners' centre
    lips = np.flatnonzero((rgb[head_male.skin.faces] == rgb[head_male.regions["upper_lip"][0]])
                          .all(axis=(1, 2)))  # fmt: skip
    image = material.texture
    u, v = atlas.corner_uv[lips[0]].mean(axis=0)
    px = image[int((1.0 - v) * image.shape[0]), int(u * image.shape[1])]
    assert np.abs(px.astype(int) - colouring.hsv_srgb(Hsv(0.97, 0.65, 0.55))).max() <= 2
    with pytest.raises(ValueError, match="colours for"):
        colouring.atlas_skin_look(head_male.skin, rgb[:10], look)


def test_the_reconstruction_folder_carries_the_case_colours(head_male, tmp_path: Path) -> None:
    """``write_reconstruction``'s step: ``head/head.obj`` again with the colours baked in
    (the reference head, mirrored into a made-up input frame, stands in for a fit)."""
    from workbench.io.mesh_formats import obj
    from workbench.pipelines.reconstruct import _coloured_head
    from workbench.services.reconstruction.reconstruct import Reconstruction

    flip = np.diag([-1.0, 1.0, 1.0, 1.0])
    flip[:3, 3] = [5.0, -2.0, 30.0]
    recon = Reconstruction(head_male, flip, True, None, np.zeros((0, 3)), np.zeros((0, 3)), {})  # type: ignore[arg-type]
    look = Appearance(tone="mst7", iris="blue")
    out = tmp_path / "folder"
    (out / "head").mkdir(parents=True)
    plain = SimpleNamespace(recon=recon, opened=SimpleNamespace(case=Case()))
    assert _coloured_head(plain, out) == {}  # type: ignore[arg-type]
    assert not (out / "head" / "head.obj").exists()
    coloured = SimpleNamespace(recon=recon, opened=SimpleNamespace(case=Case(appearance=look)))
    files = _coloured_head(coloured, out)  # type: ignore[arg-type]
    assert (out / "head" / colouring.ATLAS_FILE) in files.values()
    assert (out / "head" / "eye_blue.png").is_file()
    mtl = (out / "head" / "head.mtl").read_text()
    assert f"map_Kd {colouring.ATLAS_FILE}" in mtl and "artistic choice" in mtl
    text = (out / "head" / "head.obj").read_text()
    assert "usemtl skin_coloured" in text
    assert text.count("\nvt ") >= 3 * head_male.skin.n_faces  # a patch per triangle
    parsed = obj.read(out / "head" / "head.obj", text.encode())
    assert len(parsed.vertices) == sum(m.n_vertices for m in head_male.meshes.values())
    assert json.dumps(colouring.colour_summary(look))  # the summary is plain text
