"""Tissue-depth dowels on the reference head's skull (cranium + mandible as one scan-like mesh)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from workbench.core.errors import InputError
from workbench.core.landmarks import Landmark, LandmarkSet
from workbench.core.mesh import Mesh, concatenate
from workbench.core.spatial import MeshIndex
from workbench.io.tables import load_depth_table
from workbench.services.tissue.dowel_sites import SITE_PATTERN, interpolated_sites, site_label
from workbench.services.tissue.dowels import (
    KAEHLER_CHEEK_EXCLUSIONS,
    MIN_SAMPLE_DEPTH_MM,
    DepthSettings,
    depth_samples,
    plan_dowels,
)

MANDIBLE_CODES = {
    "id",
    "sm",
    "pg",
    "gn",
    "me",
    "iC_l",
    "iC_r",
    "ecm2i_l",
    "ecm2i_r",
    "mr_l",
    "mr_r",
    "go_l",
    "go_r",
    "mmb_l",
    "mmb_r",
}


def _combine(*meshes: Mesh) -> Mesh:
    return concatenate(list(meshes))


@pytest.fixture(scope="module")
def head(head_male):
    return head_male


@pytest.fixture(scope="module")
def skull(head) -> Mesh:
    return _combine(head.meshes["cranium"], head.meshes["mandible"])


@pytest.fixture(scope="module")
def plan(head, skull):
    return plan_dowels(skull, head.skull_landmarks)


def _with_status(lms: LandmarkSet, **status: str) -> LandmarkSet:
    for code, st in status.items():
        lm = lms[code]
        lms = lms.with_landmark(Landmark(code, lm.position, st))
    return lms


def test_template_dowel_tips_reach_the_paired_skin_landmarks(head, plan) -> None:
    table = load_depth_table("ttable_2023")
    rows = [d for d in plan.dowels if d.source == "table"]
    assert {d.code for d in rows} == set(table.codes)  # all 36 T-Table sites are on the template
    errors = {
        d.code: float(np.linalg.norm(d.tip - head.skin_landmarks[d.skin_code].position))
        for d in rows
    }
    # the template skull was fitted so these agree; measured worst 0.21 mm (ecm2s)
    assert max(errors.values()) < 0.5, errors
    for d in rows:
        assert d.skin_code == table.skin_codes[table.codes.index(d.code)]
        assert d.depth_mm == d.table_depth_mm and d.sd_mm is not None
        assert np.isclose(np.linalg.norm(d.direction), 1.0)
        if not d.code.endswith(("_l", "_r")):
            assert d.direction[0] == 0.0  # midline dowels stay in the midsagittal plane
    assert plan["pr"].direction[1] == 0.0  # mouth-region dowels are parallel to FH
    assert plan.group_label == "adult pooled, mean"
    assert plan.citation.startswith("Hona, T. W. P. T. and Stephan, C. N. (2024)")
    assert plan.table_id == "ttable_2023" and "T-Table" in plan.table_title
    assert len(plan.active()) == len(plan.dowels)
    # landmarks with a skin partner but no T-Table value are named, not silently dropped
    no_value = next(w for w in plan.warnings if w.startswith("no depth in table"))
    assert "fe_l" in no_value and "sgl_r" in no_value


def test_build_variant_adds_k_sd_exactly(head, skull, plan) -> None:
    plus = plan_dowels(skull, head.skull_landmarks, DepthSettings(build=1.5))
    minus = plan_dowels(skull, head.skull_landmarks, DepthSettings(build="-1 SD"))
    assert plus.group_label == "adult pooled, mean + 1.5 SD"
    assert minus.group_label == "adult pooled, mean - 1 SD"
    for base, d in zip(plan.dowels, plus.dowels, strict=True):
        assert d.code == base.code
        if d.source == "table":
            assert d.depth_mm == pytest.approx(base.depth_mm + 1.5 * d.sd_mm, abs=1e-12)
            assert d.table_depth_mm == base.depth_mm
            np.testing.assert_array_equal(d.tip, d.origin + d.depth_mm * d.direction)
        else:  # interpolated: the same weights over the shifted parents
            shift = sum(w * 1.5 * plan[c].sd_mm for c, w in d.parents)
            assert d.depth_mm == pytest.approx(base.depth_mm + shift, abs=1e-12)
    assert minus["go_l"].depth_mm == pytest.approx(12.5 - 6.0)
    # mean - 3 SD would put gonion (12.5 +- 6 mm) inside the bone: floored, and said so
    thin = plan_dowels(skull, head.skull_landmarks, DepthSettings(build=-3))
    assert thin["go_l"].depth_mm == MIN_SAMPLE_DEPTH_MM
    assert any(
        w.startswith("mean - 3 SD is below 0.5 mm for") and "go_l (-5.5 mm)" in w
        for w in thin.warnings
    )


def test_named_builds_and_impossible_requests(head, skull, tmp_path: Path) -> None:
    lms = head.skull_landmarks
    # a table without build groups: "obese" is the build model's heavy face
    obese = plan_dowels(skull, lms, DepthSettings(build="obese"))
    assert obese.group_label.endswith("heavy build (BMI 34, build model)")
    rhine = "rhine_1983_sw_native_american"
    with pytest.raises(InputError, match="no standard deviations, so the build model cannot"):
        plan_dowels(skull, lms, DepthSettings(table=rhine, sex="female", build="obese"))
    with pytest.raises(InputError, match="has no standard deviations, so 'mean \\+ 1 SD'"):
        plan_dowels(skull, lms, DepthSettings(table=rhine, build=1.0))
    with pytest.raises(InputError, match="no depths for males"):
        plan_dowels(skull, lms, DepthSettings(table=rhine, sex="male"))
    with pytest.raises(InputError, match="unknown build 'chubby'"):
        plan_dowels(skull, lms, DepthSettings(build="chubby"))
    with pytest.raises(InputError, match="no group 'teen'"):
        plan_dowels(skull, lms, DepthSettings(group="teen"))
    with pytest.raises(InputError, match="group 'female/normal' is female, not male"):
        plan_dowels(skull, lms, DepthSettings(table=rhine, group="female/normal", sex="male"))
    female = plan_dowels(skull, lms, DepthSettings(table=rhine, sex="female"))
    assert female.group_label == "female/normal, mean" and female["pg"].depth_mm == 13.0
    assert female["pg"].sd_mm is None
    assert any("has no SDs" in w for w in female.warnings)
    # a user table with build groups (values invented for the test): the named build is used
    path = tmp_path / "builds.csv"
    path.write_text(
        "landmark_code,group,sex,build,mean_mm,sd_mm,source\n"
        + "".join(
            f"{c},m/{b},male,{b},{d},1,test\n{c},f/{b},female,{b},{d + 1},1,test\n"
            for c in ("g", "pg", "go_l")
            for b, d in (("slender", 3.0), ("normal", 5.0), ("obese", 8.0))
        )
    )
    obese = plan_dowels(skull, lms, DepthSettings(table=str(path), sex="male", build="obese"))
    assert obese.group_label == "m/obese male, mean"
    assert {d.code: d.depth_mm for d in obese.dowels if d.source == "table"} == {
        "g": 8.0,
        "pg": 8.0,
        "go_l": 8.0,
    }
    slim = plan_dowels(skull, lms, DepthSettings(table=str(path), sex="female", build="slender"))
    assert slim["g"].depth_mm == 4.0 and slim.citation == "test"
    k = plan_dowels(skull, lms, DepthSettings(table=str(path), sex="female", build=-1))
    assert k["g"].depth_mm == 5.0 and k.group_label == "f/normal female, mean - 1 SD"


def test_overrides_and_exclusions(head, skull, plan) -> None:
    settings = DepthSettings(
        overrides={"pg": 15.0, "sgl_l": 8.0}, excluded=frozenset({"spm2", "sbm2", "go_r"})
    )
    p = plan_dowels(skull, head.skull_landmarks, settings)
    pg = p["pg"]
    assert (pg.source, pg.depth_mm, pg.table_depth_mm, pg.sd_mm) == ("override", 15.0, 11.0, None)
    sgl = p["sgl_l"]  # no T-Table value: the override adds a dowel
    assert (sgl.source, sgl.table_depth_mm, sgl.skin_code) == ("override", None, "sgl_l")
    # Kähler's spm2 / sbm2 are the ectomolare codes, both sides
    off = {d.code for d in p.dowels if d.excluded}
    assert KAEHLER_CHEEK_EXCLUSIONS | {"go_r"} <= off
    assert not off & {d.code for d in p.active()}
    # interpolated dowels follow an excluded parent and use an overridden one
    assert all(p[r.code].excluded for r in SITE_PATTERN if "go_r" in r.parents)
    assert any("excluded with a parent" in w for w in p.warnings)
    site = p["i:go_l-pg:0.67"]
    assert site.depth_mm == pytest.approx(plan["go_l"].depth_mm / 3 + 2 * 15.0 / 3)
    with pytest.raises(InputError, match="unknown skull landmark 'xyz'"):
        plan_dowels(skull, head.skull_landmarks, DepthSettings(overrides={"xyz": 3.0}))
    with pytest.raises(InputError, match="pg: depth must be a positive number"):
        plan_dowels(skull, head.skull_landmarks, DepthSettings(overrides={"pg": -2.0}))


def test_user_direction_overrides_the_normal(head, skull) -> None:
    p = plan_dowels(
        skull,
        head.skull_landmarks,
        DepthSettings(directions={"g": (0.0, 0.0, 2.0), "i:v-g:0.50": (0, 1, 1)}),
    )
    np.testing.assert_allclose(p["g"].direction, [0.0, 0.0, 1.0])
    np.testing.assert_allclose(p["g"].tip, p["g"].origin + [0.0, 0.0, 5.5])
    np.testing.assert_allclose(p["i:v-g:0.50"].direction, [0.0, 2**-0.5, 2**-0.5])
    with pytest.raises(InputError, match="g: a direction must be a non-zero 3-vector"):
        plan_dowels(skull, head.skull_landmarks, DepthSettings(directions={"g": (0, 0, 0)}))


def test_absent_and_missing_landmarks_are_skipped_with_warnings(head, skull) -> None:
    lms = _with_status(head.skull_landmarks, pg="absent", v="missing")
    p = plan_dowels(skull, lms)
    assert "pg" not in p.codes and "v" not in p.codes
    assert "no dowel for pg: marked absent" in p.warnings
    assert "no dowel for v: not placed yet" in p.warnings
    skipped = next(w for w in p.warnings if w.startswith("interpolated dowels skipped"))
    for r in SITE_PATTERN:
        assert (r.code in p.codes) == (not {"pg", "v"} & set(r.parents))
        if {"pg", "v"} & set(r.parents):
            assert site_label(r.code) in skipped


def test_missing_mandible_drops_its_dowels_and_sites(head, plan) -> None:
    cranium = head.meshes["cranium"]
    p = plan_dowels(cranium, head.skull_landmarks)
    assert not MANDIBLE_CODES & set(p.codes)
    off = next(w for w in p.warnings if "from the skull surface" in w)
    assert all(f"{c} (" in off for c in MANDIBLE_CODES)
    mandibular = {r.code for r in SITE_PATTERN if r.region == "mandible"}
    assert not mandibular & set(p.codes)
    assert {r.code for r in SITE_PATTERN if r.region == "cranium"} <= set(p.codes)
    assert all(
        site_label(c) in next(w for w in p.warnings if "interpolated" in w) for c in mandibular
    )
    # the cranial dowels do not change when the mandible is missing
    for d in p.dowels:
        np.testing.assert_allclose(d.tip, plan[d.code].tip, atol=1e-9)


def test_interpolated_sites_lie_on_the_bone_between_their_parents(head, skull, plan) -> None:
    sites = interpolated_sites(skull, head.skull_landmarks)
    assert [c for c, _, _ in sites] == [r.code for r in SITE_PATTERN]
    pos = np.stack([p for _, p, _ in sites])
    assert MeshIndex(skull).closest_points(pos).distances.max() < 0.1
    for code, p, parents in sites:
        d = plan[code]
        np.testing.assert_array_equal(d.origin, p)
        assert d.source == "interpolated" and d.skin_code is None and d.parents == parents
        depths = [plan[c].depth_mm for c, _ in parents]
        assert min(depths) <= d.depth_mm <= max(depths)
        assert d.depth_mm == pytest.approx(sum(w * plan[c].depth_mm for c, w in parents))
        assert np.dot(d.direction, p - np.mean([plan[c].origin for c, _ in parents], axis=0)) > 0
        if code.count("_l") == 0 and code.count("_r") == 0:
            assert abs(p[0]) < 1e-6  # midline sites stay on the midline
        if "_l" in code:  # left and right sites are mirror images on the symmetric template
            right = dict((c, q) for c, q, _ in sites)[code.replace("_l", "_r")]
            np.testing.assert_allclose(right, p * [-1, 1, 1], atol=0.5)


def test_sites_correspond_on_a_scaled_skull_and_vanish_in_a_hole(head, skull) -> None:
    base = dict((c, p) for c, p, _ in interpolated_sites(skull, head.skull_landmarks))
    big = interpolated_sites(
        skull.scaled(1.1), head.skull_landmarks.transformed(np.diag([1.1] * 3 + [1]))
    )
    assert [c for c, _, _ in big] == list(base)
    worst = max(np.linalg.norm(p - 1.1 * base[c]) for c, p, _ in big)
    assert worst < 1.0  # measured 0.26 mm (the normal radius does not scale)
    # a damaged vault: a 12 mm hole where one site would be
    centre = base["i:v-op:0.50"]
    keep = np.linalg.norm(skull.triangles.mean(axis=1) - centre, axis=1) > 12.0
    skipped: list[str] = []
    holed = interpolated_sites(
        Mesh(skull.vertices, skull.faces[keep]), head.skull_landmarks, skipped=skipped
    )
    assert [c for c, _, _ in holed] == [c for c in base if c != "i:v-op:0.50"]
    assert skipped == [
        "no dowel between v and op, 50% of the way to op: no bone on its dowel line "
        "(missing or damaged cranium?)"
    ]


def test_depth_samples_follow_mean_and_sd(head, skull) -> None:
    p = plan_dowels(skull, head.skull_landmarks, DepthSettings(overrides={"g": 6.0}))
    rng = np.random.default_rng(7)
    draws = np.stack([depth_samples(p, rng) for _ in range(4000)])
    assert draws.shape == (4000, len(p.dowels)) and draws.min() >= MIN_SAMPLE_DEPTH_MM
    index = {c: i for i, c in enumerate(p.codes)}
    for i, d in enumerate(p.dowels):
        col = draws[:, i]
        if d.source == "override":
            assert (col == d.depth_mm).all()
        elif d.source == "table":  # a normal truncated at 0.5 mm (go: 12.5 ± 6 loses 2 %)
            a = (MIN_SAMPLE_DEPTH_MM - d.depth_mm) / d.sd_mm
            mean, var = stats.truncnorm.stats(a, np.inf, loc=d.depth_mm, scale=d.sd_mm)
            se = d.sd_mm / np.sqrt(len(col))
            assert abs(col.mean() - mean) < 4 * se, d.code
            assert abs(col.std() - np.sqrt(var)) < 0.05 * d.sd_mm, d.code
        else:
            expect = sum(w * draws[:, index[c]] for c, w in d.parents)
            np.testing.assert_allclose(col, expect)
    assert np.corrcoef(draws[:, index["v"]], draws[:, index["i:v-op:0.25"]])[0, 1] > 0.5


def test_inward_wound_skull_is_flagged(head, skull) -> None:
    flipped = Mesh(skull.vertices, skull.faces[:, ::-1])
    p = plan_dowels(flipped, head.skull_landmarks, DepthSettings(interpolate=False))
    assert any("point into the skull" in w for w in p.warnings)
