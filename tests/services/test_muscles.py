"""Kähler's 24 muscles (Table 7.1) laid out as grids on the template skin."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.core.headgen.skin import build_skin
from workbench.core.mesh import Mesh
from workbench.core.spatial import MeshIndex
from workbench.core.tps import fit_warp
from workbench.model.muscles import MuscleGrid, SurfacePoints
from workbench.services.templates.muscles import GRID_DEPTH_MM, layout_muscles, read_table71

MIRROR = np.array([-1.0, 1.0, 1.0])


@pytest.fixture(scope="module", params=["male", "female"])
def layout(request: pytest.FixtureRequest):
    skin = build_skin(request.param)
    return skin, {m.code: m for m in layout_muscles(skin)}


def _on_skin(sp: SurfacePoints, mesh: Mesh) -> np.ndarray:
    return SurfacePoints(sp.faces, sp.barycentric).evaluate(mesh)


def _lm(skin, code: str) -> np.ndarray:
    return np.asarray(skin.landmarks[code].position, float)


def test_table71_codes_kinds_attachments_sides(layout) -> None:
    _, muscles = layout
    table = read_table71()
    assert len(table) == 24 and len(muscles) == 24
    for row in table:
        m = muscles[row["code"]]
        assert isinstance(m, MuscleGrid)
        assert (m.name, m.kind, m.attachment, m.side) == (
            row["name"],
            row["kind"],
            row["attachment"],
            row["side"],
        )
        # grid sizes close to Kähler's control-grid point counts
        n = len(m.points)
        assert abs(n - int(row["n_points"])) <= 1, (row["code"], n)
        assert np.allclose(m.points.depth_mm, GRID_DEPTH_MM)
        assert (m.axis is not None) == (m.kind == "sphincter")


def test_grid_points_lie_on_the_skin(layout) -> None:
    skin, muscles = layout
    index = MeshIndex(skin.mesh)
    for m in muscles.values():
        sp = m.points
        assert np.all(sp.barycentric >= -1e-12) and np.allclose(sp.barycentric.sum(1), 1.0)
        d = index.closest_points(_on_skin(sp, skin.mesh)).distances
        assert d.max() < 1e-6, m.code
        # the stored depth puts the points 4 mm below the skin
        deep = sp.evaluate(skin.mesh)
        assert np.allclose(np.linalg.norm(deep - _on_skin(sp, skin.mesh), axis=1), GRID_DEPTH_MM)


def test_points_are_not_stray(layout) -> None:
    """Neighbouring grid points stay close: no ray landed on another part of the head."""
    skin, muscles = layout
    for m in muscles.values():
        for row in m.rows(skin.mesh):
            if len(row) > 1:
                assert np.linalg.norm(np.diff(row, axis=0), axis=1).max() < 30.0, m.code


def test_left_right_mirror(layout) -> None:
    skin, muscles = layout
    for code, m in muscles.items():
        if not code.endswith("_l"):
            continue
        r = muscles[code[:-2] + "_r"]
        assert r.row_lengths == m.row_lengths
        assert (
            np.abs(_on_skin(m.points, skin.mesh) * MIRROR - _on_skin(r.points, skin.mesh)).max()
            < 0.5
        )
        assert np.all(_on_skin(m.points, skin.mesh)[:, 0] > 0)
        if m.axis is not None:
            assert (
                np.abs(m.axis.evaluate(skin.mesh) * MIRROR - r.axis.evaluate(skin.mesh)).max() < 0.5
            )


def test_midline_muscles_are_symmetric(layout) -> None:
    skin, muscles = layout
    for m in muscles.values():
        if m.side != "midline":
            continue
        for row in m.rows(skin.mesh):
            assert np.abs(row * MIRROR - row[::-1]).max() < 0.5, m.code
        if m.axis is not None:
            assert np.abs(m.axis.evaluate(skin.mesh)[:, 0]).max() < 1e-6


@pytest.mark.parametrize(
    "code, fixed, free",
    [
        ("zygomaticus_major_l", "zy_l", "ch_l"),
        ("risorius_l", "go_l", "ch_l"),
        ("triangularis_l", "mmb_l", "ch_l"),
        ("quadratus_labii_l", "gn", "li"),
        ("levator_labii_l", "or_l", "ls"),
        ("mentalis", "pg", "sl"),
        ("frontalis_inner_l", "tr", "en_l"),
        ("frontalis_outer_l", "tr", "ex_l"),
        ("corrugator_l", "g", "sci_l"),
        ("mylohyoideus", "me", "me"),
    ],
)
def test_linear_rows_run_from_bone_to_free_end(layout, code: str, fixed: str, free: str) -> None:
    skin, muscles = layout
    rows = muscles[code].rows(skin.mesh)
    first, last = rows[0].mean(0), rows[-1].mean(0)
    a = _lm(skin, fixed)
    assert np.linalg.norm(first - a) < np.linalg.norm(last - a)
    if free != fixed:
        b = _lm(skin, free)
        assert np.linalg.norm(last - b) < np.linalg.norm(first - b)


def test_orbicularis_oris_above_and_below_the_mouth(layout) -> None:
    skin, muscles = layout
    loop = skin.mesh.vertices[skin.openings["mouth"]]
    top, bottom = loop[:, 1].max(), loop[:, 1].min()
    upper = np.vstack(muscles["orbicularis_oris_upper"].rows(skin.mesh))
    lower = np.vstack(muscles["orbicularis_oris_lower"].rows(skin.mesh))
    assert upper.shape[0] >= 50 and lower.shape[0] == 21
    # each point is above (below) the loop where the loop has that x
    for pts, sign in ((upper, 1.0), (lower, -1.0)):
        inside = np.abs(pts[:, 0]) < np.abs(loop[:, 0]).max() - 3.0
        for p in pts[inside]:
            near = loop[np.abs(loop[:, 0] - p[0]) < 3.0, 1]
            assert sign * (p[1] - (near.max() if sign > 0 else near.min())) > 0
    assert upper[:, 1].mean() > top and lower[:, 1].mean() < bottom
    # each axis points into the mouth (backwards) from its lip
    for code in ("orbicularis_oris_upper", "orbicularis_oris_lower"):
        a0, a1 = muscles[code].axis.evaluate(skin.mesh)
        assert a1[2] < a0[2] and np.linalg.norm(a1 - a0) == pytest.approx(10.0, abs=1e-6)


def test_eye_rings_surround_the_eye(layout) -> None:
    skin, muscles = layout
    for side in ("l", "r"):
        c = skin.mesh.vertices[skin.openings[f"eye_{side}"]].mean(0)
        orb = np.vstack(muscles[f"orbicularis_oculi_orbital_{side}"].rows(skin.mesh))
        pal = np.vstack(muscles[f"orbicularis_oculi_palpebral_{side}"].rows(skin.mesh))
        d_orb = np.linalg.norm(orb[:, :2] - c[:2], axis=1)
        d_pal = np.linalg.norm(pal[:, :2] - c[:2], axis=1)
        assert d_pal.mean() < d_orb.mean() and d_orb.max() < 45.0
        assert orb[:, 1].max() > c[1] + 10 and orb[:, 1].min() < c[1] - 10


def test_grids_follow_a_warp_of_the_skin(layout) -> None:
    skin, muscles = layout
    v = skin.mesh.vertices
    rng = np.random.default_rng(3)
    src = v[rng.choice(len(v), 12, replace=False)]
    warp = fit_warp(src, src + rng.normal(0.0, 4.0, src.shape))
    warped = Mesh(warp(v), skin.mesh.faces)
    for m in muscles.values():
        sp = m.points
        got = _on_skin(sp, warped)
        corners = warped.vertices[warped.faces[sp.faces]]
        assert np.allclose(got, np.einsum("ij,ijk->ik", sp.barycentric, corners), atol=1e-9)
        assert not np.allclose(got, _on_skin(sp, skin.mesh))
        # state round trip
        again = MuscleGrid.from_state(m.to_state())
        assert np.allclose(again.points.evaluate(warped), sp.evaluate(warped))
