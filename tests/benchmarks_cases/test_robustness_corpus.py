"""The robustness corpus (``benchmarks/corpus``): its generator, truth bookkeeping and the
jaw-opening measure.

These check the measuring instrument, not the registration under test: no
test here asks the automatic registration to succeed.  The headsq variant is
built into a temporary cache folder from the real CT (units mm; truths in
each file's own frame).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from workbench.core.spatial import MeshIndex
from workbench.io.meshes import read_mesh

REPO = Path(__file__).resolve().parents[2]
if str(REPO) not in sys.path:
    sys.path.insert(0, str(REPO))

from benchmarks.corpus import common, truth, variants  # noqa: E402
from benchmarks.corpus.bases import BASES  # noqa: E402


# ---------------------------------------------------------------- (a) the spec generator
def test_specs_are_deterministic_and_cover_every_value() -> None:
    specs = variants.generate_specs()
    again = variants.generate_specs()
    assert [s.id for s in specs] == [s.id for s in again]
    assert [s.to_dict() for s in specs] == [s.to_dict() for s in again]
    assert len({s.id for s in specs}) == len(specs) >= 220
    by_base = {b: [s for s in specs if s.base == b] for b in variants.COUNTS}
    shares = {b: len(v) / len(specs) for b, v in by_base.items()}
    assert shares["vhp_female"] == pytest.approx(0.40, abs=0.03)
    assert shares["vhp_male"] == pytest.approx(0.35, abs=0.03)
    assert shares["headsq"] == pytest.approx(0.25, abs=0.03)
    assert any(s.group == "cut" for s in specs)
    for base, mine in by_base.items():
        for dim, values in variants.DIMENSIONS.items():
            if dim == "cut" and BASES[base].vault_already_cut:
                values = ("none",)
            seen = {s.dimension(dim) for s in mine}
            assert set(values) <= seen, (base, dim, set(values) - seen)
    # another seed gives another corpus; a spec survives its JSON form with its id
    assert [s.id for s in variants.generate_specs(seed=1)] != [s.id for s in specs]
    for s in specs[::17]:
        back = variants.VariantSpec.from_dict(json.loads(json.dumps(s.to_dict())))
        assert back == s and back.id == s.id


def test_spec_values_are_in_range() -> None:
    for s in variants.generate_specs():
        r = np.asarray(s.rotation)
        assert np.allclose(r @ r.T, np.eye(3), atol=1e-8) and np.linalg.det(r) > 0
        assert np.linalg.norm(s.translation) <= variants.MAX_TRANSLATION_MM + 1e-6
        if s.mandible == "opened":
            assert 5.0 <= s.opening_deg <= BASES[s.base].max_opening_deg
        if s.mandible == "forward":
            assert 2.0 <= s.forward_mm <= 6.0 and s.lateral_mm == 0.0
        if s.mandible == "sideways":
            assert 2.0 <= abs(s.lateral_mm) <= 5.0 and s.forward_mm == 0.0
        if s.mandible == "detached":
            assert s.components != "largest" and s.apparatus != "tube"
        if s.axes == "turned":
            assert 10.0 - 1e-6 <= _angle_from_own_or_prone(s) <= 60.0 + 1e-6
        if s.group == "cut":
            assert s.mandible == "missing" and s.cut == "vault+defect"
        assert 35.0 <= s.vault_above_mm <= 60.0 and 15.0 <= s.defect_radius_mm <= 20.0
    assert len(variants.quick_ids(variants.generate_specs())) == 12


def _angle_from_own_or_prone(s: variants.VariantSpec) -> float:
    r = np.asarray(s.rotation)
    prone = common.rotation_matrix(BASES[s.base].hint[1], 180.0)
    angles = [
        np.degrees(np.arccos(np.clip((np.trace(r @ start.T) - 1) / 2, -1, 1)))
        for start in (np.eye(3), prone)
    ]
    return float(min(angles))


# ---------------------------------------------------------------- (c) the jaw-opening measure
@pytest.mark.parametrize("deg", [-8.0, 0.0, 12.5, 30.0])
def test_jaw_opening_returns_the_applied_rotation(deg: float) -> None:
    rng = np.random.default_rng(3)
    cranium = rng.normal(scale=40.0, size=(400, 3))
    condyle = np.array([0.0, -14.0, 6.0])
    # a mandible-like cloud below and in front of the condyles
    mandible = condyle + rng.normal(scale=15.0, size=(300, 3)) + [0.0, -50.0, 45.0]
    opening = common.rotation_about(condyle, [1.0, 0.0, 0.0], deg)
    # the whole head also sits somewhere else: the measure is relative to the cranium
    pose = common.homogeneous(common.rotation_matrix([0.3, 1.0, -0.2], 25.0), [5.0, -7.0, 9.0])
    noise = rng.normal(scale=0.05, size=mandible.shape)
    reg = SimpleNamespace(
        rest={
            "cranium": SimpleNamespace(vertices=cranium),
            "mandible": SimpleNamespace(vertices=mandible),
        },
        meshes={
            "cranium": SimpleNamespace(vertices=common.apply(pose, cranium)),
            "mandible": SimpleNamespace(vertices=common.apply(pose @ opening, mandible) + noise),
        },
    )
    assert truth.jaw_opening_deg(reg) == pytest.approx(deg, abs=0.05)
    jp = truth.jaw_pose(reg, condyle)
    assert abs(jp.protrusion_mm) < 0.1 and abs(jp.lateral_mm) < 0.1  # turned about the condyle
    # positive opening: the chin goes down and back
    chin = condyle + [0.0, -90.0, 70.0]
    moved = common.apply(opening, chin)
    if deg > 0:
        assert moved[1] < chin[1] and moved[2] < chin[2]


def test_jaw_pose_reports_a_forward_push() -> None:
    rng = np.random.default_rng(4)
    cranium = rng.normal(scale=40.0, size=(200, 3))
    mandible = rng.normal(scale=20.0, size=(200, 3)) + [0.0, -60.0, 40.0]
    push = common.homogeneous(t=[-2.0, 0.0, 4.0])
    reg = SimpleNamespace(
        rest={
            "cranium": SimpleNamespace(vertices=cranium),
            "mandible": SimpleNamespace(vertices=mandible),
        },
        meshes={
            "cranium": SimpleNamespace(vertices=cranium),
            "mandible": SimpleNamespace(vertices=common.apply(push, mandible)),
        },
    )
    jp = truth.jaw_pose(reg, np.array([50.0, -10.0, 0.0]))
    assert jp.opening_deg == pytest.approx(0.0, abs=1e-6)
    assert jp.protrusion_mm == pytest.approx(4.0) and jp.lateral_mm == pytest.approx(-2.0)


# ---------------------------------------------------------------- (b) a headsq variant


def _headsq_spec(**changes) -> variants.VariantSpec:
    return variants.plain_spec("headsq", **changes)


@pytest.mark.slow
def test_truth_landmarks_travel_with_a_mirrored_cm_rotated_file(corpus_root: Path) -> None:
    rot = common.rotation_matrix([0.4, -0.7, 0.2], 137.0)
    spec = _headsq_spec(
        axes="random",
        rotation=tuple(tuple(row) for row in rot),
        mirror_axis=1,
        translation=(180.0, -320.0, 95.0),
        units="cm",
    )
    entry = variants.build_variant(spec, corpus_root)
    path = variants.corpus_dir(corpus_root) / entry["file"]
    assert path.is_file() and entry["id"] == spec.id
    in_cm = read_mesh(path, units="mm").mesh  # the file's own numbers
    mesh = read_mesh(path, units="cm").mesh
    np.testing.assert_allclose(mesh.vertices, 10.0 * in_cm.vertices)
    base_truth = truth.load_truth("headsq", corpus_root)
    vt = entry["truth"]
    x = np.asarray(vt["file_transform"])
    assert np.linalg.det(x[:3, :3]) == pytest.approx(-1.0)
    # headsq is itself a mirrored file; mirrored once more it is proper
    assert base_truth["mirrored"] and not vt["mirrored_file"]
    back = np.linalg.inv(x)
    base_mesh, _, _ = variants.build_mesh(spec, root=corpus_root)
    base_index, file_index = MeshIndex(base_mesh), MeshIndex(mesh)
    for code in truth.SIX:
        lm_file = np.asarray(vt["landmarks"][code])
        lm_base = np.asarray(base_truth["landmarks"][code])
        np.testing.assert_allclose(common.apply(back, lm_file), lm_base, atol=1e-6)
        d_file = file_index.closest_points(lm_file[None]).distances[0]
        d_base = base_index.closest_points(lm_base[None]).distances[0]
        assert d_file == pytest.approx(d_base, abs=1e-4), code
        # on the bone; the thin orbital floor is partly lost at headsq's 3.2 mm voxels
        assert d_file < (6.0 if code.startswith("or_") else 3.0), code
    axis = vt["tmj_axis"]
    np.testing.assert_allclose(
        common.apply(back, np.asarray(axis["point"])), base_truth["tmj_axis"]["point"], atol=1e-6
    )
    # the file carries its id and units
    from workbench.io.mesh_formats import ply

    header = ply.header_comments(path)
    assert any(spec.id in c for c in header) and any("units: cm" in c for c in header)


@pytest.mark.slow
def test_an_opened_jaw_moves_its_voxels_as_recorded(corpus_root: Path) -> None:
    anchor = truth.load_anchor("headsq", corpus_root)
    spec = _headsq_spec(
        index=901,
        mandible="opened",
        opening_deg=15.0,
        axes="own",
        rotation=((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)),
        mirror_axis=-1,
        translation=(0.0, 0.0, 0.0),
        units="mm",
    )
    motion = variants.mandible_motion(spec, anchor)
    in_head = anchor.input_to_head @ motion @ np.linalg.inv(anchor.input_to_head)
    assert truth.opening_about_x(in_head[:3, :3]) == pytest.approx(15.0, abs=0.2)
    entry = variants.build_variant(spec, corpus_root)
    # the moved mandible's surface samples (moved analytically) lie on the built mesh
    assert entry["build"]["mandible_on_mesh_fraction"] > 0.9
    assert entry["truth"]["mandible_present"]
    base_truth = truth.load_truth("headsq", corpus_root)
    expected = base_truth["jaw_by_reference"][truth.EVAL_SEX]["opening_deg"] + 15.0
    assert entry["truth"]["opening_deg"] == pytest.approx(expected)
    # a missing mandible is recorded as missing, whatever the mesh
    gone = variants.build_variant(_headsq_spec(index=902, mandible="missing"), corpus_root)
    assert not gone["truth"]["mandible_present"]
    assert gone["build"]["mandible_on_mesh_fraction"] < 0.2
    # a detached one is a piece of its own
    alone = variants.build_variant(_headsq_spec(index=903, mandible="detached"), corpus_root)
    assert alone["build"]["detach"]["separate_piece"]


def test_the_truth_is_the_median_over_the_bone_levels() -> None:
    """The truth's landmarks and openings are medians over one hinted registration per
    bone level, coordinate by coordinate; a landmark a level left undefined does not count,
    and the mandible is present when most levels found it."""
    nan = np.full(3, np.nan)

    def record(shift: float, opening: float, snapped_g=None, present=True) -> dict:
        lms = {c: np.array([shift, 2 * shift, 0.0]) for c in truth.SIX}
        snapped = dict(lms, g=nan if snapped_g is None else snapped_g)
        return {
            "landmarks": lms,
            "landmarks_snapped": snapped,
            "jaw": {"opening_deg": opening, "reported_opening_deg": opening + 1, "x": shift},
            "mandible_present": present,
        }

    records = [
        record(0.0, 5.0, np.array([1.0, 1.0, 1.0])),
        record(1.0, 9.0, present=False),
        record(10.0, 6.0, np.array([3.0, 3.0, 3.0])),
    ]
    out = truth._median_record(records)
    np.testing.assert_allclose(out["landmarks"]["n"], [1.0, 2.0, 0.0])  # not the 10 mm one
    np.testing.assert_allclose(out["landmarks_snapped"]["g"], [2.0, 2.0, 2.0])  # NaN left out
    assert out["jaw"]["opening_deg"] == 6.0 and out["jaw"]["reported_opening_deg"] == 7.0
    assert out["jaw"]["x"] == 0.0  # other jaw figures: the first level's
    assert out["mandible_present"]
    assert truth.ISO_LEVELS == variants.ISO  # taken at the variants' own levels
