"""Validation of a reconstruction against the true skin (issue 4, "Validation").

Real data: the built-in reference head's skin as reconstruction, and copies
of it moved along the vertex normals, cut in half or labelled, as truth.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from workbench.core.errors import InputError
from workbench.core.mesh import Mesh
from workbench.core.normals import vertex_normals
from workbench.services.templates.regions import REGION_NAMES, face_regions
from workbench.services.validation.compare import (
    FIGURE_KEYS,
    compare_surfaces,
    template_orientation,
)


@pytest.fixture(scope="module")
def head(head_male):
    return head_male


@pytest.fixture(scope="module")
def regions(head) -> dict[str, np.ndarray]:
    return face_regions(head)


@pytest.fixture(scope="module")
def displaced(head) -> Mesh:
    """The template skin moved 3 mm outward along its vertex normals."""
    skin = head.skin
    normals = vertex_normals(skin)
    # the normals point out of the head (precondition for the sign below)
    outward = np.einsum("ij,ij->i", normals, skin.vertices - skin.vertices.mean(axis=0))
    assert (outward > 0).mean() > 0.85
    return skin.with_vertices(skin.vertices + 3.0 * normals)


def test_face_regions_partition_the_face(head, regions) -> None:
    assert tuple(regions) == REGION_NAMES
    ids = np.concatenate(list(regions.values()))
    assert len(ids) == len(np.unique(ids))  # disjoint
    assert set(ids.tolist()) == set(np.asarray(head.regions["face"]).tolist())  # union = face
    v = head.skin.vertices
    lm = head.skin_landmarks.as_dict()
    # each region holds its anatomy: pronasale in the nose, glabella on the
    # forehead, the mouth corners in the mouth, gnathion on the chin, zygion on the cheeks
    nearest = {
        code: int(np.linalg.norm(v - lm[code], axis=1).argmin())
        for code in ("prn", "g", "ch_l", "ch_r", "pg", "zy_l", "zy_r", "ex_l")
    }
    assert nearest["prn"] in regions["nose"]
    assert nearest["g"] in regions["forehead"]
    assert nearest["ch_l"] in regions["mouth"] and nearest["ch_r"] in regions["mouth"]
    assert nearest["pg"] in regions["chin"]
    assert nearest["zy_l"] in regions["cheeks"] and nearest["zy_r"] in regions["cheeks"]
    assert nearest["ex_l"] in regions["orbits"]
    # symmetric: as many vertices left as right in every region
    for name, idx in regions.items():
        x = v[idx, 0]
        assert abs(int((x > 1e-6).sum()) - int((x < -1e-6).sum())) <= 2, name
    # every region is a real patch of skin
    assert min(len(idx) for idx in regions.values()) > 100


def test_identical_surfaces_agree_everywhere(head, regions) -> None:
    result = compare_surfaces(head.skin, head.skin, recon_regions=regions)
    fig = result.figures
    assert set(fig) == set(FIGURE_KEYS)
    assert fig["mean_abs_mm"] < 1e-9 and fig["rms_mm"] < 1e-9
    assert fig["pct_within_2_5mm"] == 100.0 and fig["pct_within_5mm"] == 100.0
    assert fig["n_vertices"] == len(head.regions["face"])
    assert fig["coverage"] == pytest.approx(1.0)
    assert set(result.regions) == set(REGION_NAMES)
    for name, figures in result.regions.items():
        assert figures["n_vertices"] == len(regions[name]) and figures["coverage"] == pytest.approx(
            1.0
        )


def test_a_thicker_true_skin_gives_negative_distances(head, regions, displaced) -> None:
    # the truth lies 3 mm outside the reconstruction: the reconstruction is inside (too thin)
    result = compare_surfaces(head.skin, displaced, recon_regions=regions)
    fig = result.figures
    assert fig["signed_mean_mm"] == pytest.approx(-3.0, abs=0.35)
    assert fig["mean_abs_mm"] == pytest.approx(3.0, abs=0.25)
    # closer than 3 mm only where the offset surface folds toward the skin
    # (mouth slit, alar and eyelid creases)
    assert fig["pct_within_2_5mm"] < 12.0
    assert fig["pct_within_5mm"] == 100.0
    # on the smooth forehead and chin the offset is exactly 3 mm
    for name in ("forehead", "chin"):
        assert result.regions[name]["signed_mean_mm"] == pytest.approx(-3.0, abs=0.05), name
        assert result.regions[name]["pct_within_2_5mm"] == 0.0, name
    # swapping the roles flips the sign: now the reconstruction is outside (too
    # thick); the offset surface folds over itself in the creases of nose and
    # mouth, so only the smooth regions give exactly +3 mm
    swapped = compare_surfaces(displaced, head.skin, recon_regions=regions)
    assert swapped.figures["signed_mean_mm"] > 2.0
    for name in ("forehead", "chin"):
        assert swapped.regions[name]["signed_mean_mm"] == pytest.approx(3.0, abs=0.05), name
    # the per-vertex values land on the truth mesh, NaN where not compared
    values = result.truth_vertex_values()
    assert values.shape == (displaced.n_vertices,)
    assert np.isnan(values[head.regions["scalp"]]).mean() > 0.5
    assert np.isfinite(values[regions["nose"]]).all()


def test_a_partial_truth_lowers_the_coverage(head, regions, displaced) -> None:
    # a scan of the left half of the face only
    keep = displaced.triangles.mean(axis=1)[:, 0] > 0
    half = Mesh(displaced.vertices, displaced.faces[keep])
    full = compare_surfaces(head.skin, displaced, recon_regions=regions)
    part = compare_surfaces(head.skin, half, recon_regions=regions)
    assert full.figures["coverage"] > 0.98
    assert 0.45 < part.figures["coverage"] < 0.65
    for name in ("forehead", "cheeks", "orbits"):
        assert part.regions[name]["coverage"] < 0.65, name
    # only the scanned half is used, and its figures do not change
    assert part.figures["n_vertices"] < 0.6 * full.figures["n_vertices"]
    assert (head.skin.vertices[part.truth_vertex_ids, 0] > -3.0).all()
    assert part.regions["forehead"]["signed_mean_mm"] == pytest.approx(-3.0, abs=0.05)


def test_regions_all_and_single(head, regions, displaced) -> None:
    whole = compare_surfaces(head.skin, displaced, region="all")  # needs no labels
    assert whole.figures["n_vertices"] > 0.95 * displaced.n_vertices
    assert whole.regions == {} and (whole.region_of == -1).all()
    nose = compare_surfaces(head.skin, displaced, recon_regions=regions, region="nose")
    assert list(nose.regions) == ["nose"]
    assert nose.figures["n_vertices"] == nose.regions["nose"]["n_vertices"] > 250
    # the JSON form is plain data, without NaN
    text = json.dumps(nose.to_json(), allow_nan=False)
    data = json.loads(text)
    assert data["figures"]["n_vertices"] == nose.figures["n_vertices"]
    assert data["published"]["pct_within_2_5mm"][0]["range_pct"] == [63, 74]
    with pytest.raises(InputError, match="needs region labels"):
        compare_surfaces(head.skin, displaced, region="face")
    with pytest.raises(InputError, match="unknown region 'ears'"):
        compare_surfaces(head.skin, displaced, recon_regions=regions, region="ears")


def test_max_distance_and_inward_winding(head, regions, displaced) -> None:
    skin = head.skin
    # truth vertices farther than max_distance_mm are other anatomy, not compared
    near = compare_surfaces(skin, displaced, recon_regions=regions, max_distance_mm=2.0)
    assert near.figures["n_vertices"] < 0.12 * len(head.regions["face"])
    assert np.abs(near.signed_mm).max() <= 2.0
    assert near.figures["coverage"] < 0.1  # and the truth does not cover the face
    # a reconstruction wound inside out keeps the sign convention, and says so
    flipped = Mesh(skin.vertices, skin.faces[:, ::-1])
    normals = vertex_normals(skin)
    truth = skin.with_vertices(skin.vertices - 2.0 * normals)  # 2 mm inside: recon too thick
    result = compare_surfaces(flipped, truth, recon_regions=regions)
    assert result.regions["forehead"]["signed_mean_mm"] == pytest.approx(2.0, abs=0.05)
    assert result.notes and "inward" in result.notes[0]


def test_orientation_from_the_template(head) -> None:
    # a reconstruction in a CT's LPS frame: head frame (x left, y up, z face) -> LPS
    to_lps = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])  # x->L, y up->S, z face->-P
    recon = head.skin.with_vertices(head.skin.vertices @ to_lps.T + [5.0, -80.0, 20.0])
    anterior, superior = template_orientation(recon, head.skin)
    assert anterior == pytest.approx([0.0, -1.0, 0.0], abs=1e-9)
    assert superior == pytest.approx([0.0, 0.0, 1.0], abs=1e-9)


@pytest.mark.render
def test_heatmap_is_not_blank(tmp_path: Path, head, regions, displaced) -> None:
    from PIL import Image

    from workbench.render.heatmap import render_heatmap

    # left half too thin, right half too thick
    skin = head.skin
    normals = vertex_normals(skin)
    truth = skin.with_vertices(skin.vertices + normals * (skin.vertices[:, [0]] / 10.0))
    result = compare_surfaces(skin, truth, recon_regions=regions)
    path = render_heatmap(
        truth, result.truth_vertex_values(), tmp_path / "heat.png", views=("front", "side")
    )
    image = np.asarray(Image.open(path).convert("RGB")).astype(int)
    assert image.shape[1] > image.shape[0]  # panels side by side
    assert image.std() > 20
    red = (image[..., 0] > image[..., 2] + 60).mean()
    blue = (image[..., 2] > image[..., 0] + 60).mean()
    assert red > 0.005 and blue > 0.005  # both signs show
    with pytest.raises(ValueError, match="one value per vertex"):
        render_heatmap(truth, result.signed_mm, tmp_path / "bad.png")
