"""Per-feature errors of ``workbench validate`` against true soft-tissue landmarks,
and the truth landmark files of ``tests/data/soft_tissue_truth``."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from tests.services.test_guide_defaults import _skull
from workbench.services.validation.features import (
    feature_errors,
    read_truth_landmarks,
    rule_landmarks,
)

TRUTH = Path(__file__).resolve().parents[1] / "data" / "soft_tissue_truth"


@pytest.fixture(scope="module")
def head(head_male):
    return head_male


def test_feature_errors_widths_heights_points_and_handedness():
    truth = {
        "prn": np.array([0.0, -20.0, 110.0]),
        "al_l": np.array([18.0, -25.0, 95.0]),
        "al_r": np.array([-18.0, -25.0, 95.0]),
        "ch_l": np.array([25.0, -50.0, 85.0]),
        "ch_r": np.array([-25.0, -50.0, 85.0]),
        "ls": np.array([0.0, -42.0, 100.0]),
        "en_l": np.array([15.0, 0.0, 80.0]),
        "en_r": np.array([-15.0, 0.0, 80.0]),
    }
    pred = {
        "prn": np.array([0.0, -23.0, 106.0]),
        "al_l": np.array([16.0, np.nan, np.nan]),  # a vertical guide line fixes x only
        "al_r": np.array([-16.0, np.nan, np.nan]),
        "ch_l": np.array([28.0, -50.0, 85.0]),
        "ch_r": np.array([-28.0, -50.0, 85.0]),
        "ls": np.array([0.0, -40.0, np.nan]),
        "en_l": np.array([15.0, 0.0, 84.0]),
        "en_r": np.array([-15.0, 3.0, 80.0]),
    }
    e = feature_errors(pred, truth)
    assert e["prn_mm"] == pytest.approx(5.0) and e["prn_projection_mm"] == pytest.approx(-4.0)
    assert e["alar_width_mm"] == pytest.approx(-4.0) and e["mouth_width_mm"] == pytest.approx(6.0)
    assert e["ls_height_mm"] == pytest.approx(2.0) and e["en_mm"] == pytest.approx(3.5)
    assert "sto_height_mm" not in e and "ex_mm" not in e  # not in the truth
    # a registration that read the file's left as the head's right: the same errors
    mirrored = {
        (c[:-2] + {"_l": "_r", "_r": "_l"}[c[-2:]] if c[-2:] in ("_l", "_r") else c): v
        for c, v in truth.items()
    }
    assert feature_errors(pred, mirrored) == pytest.approx(e)


def test_rule_landmarks_give_each_rule_its_own_prediction(head):
    tips = {"mp": np.array([0.0, -34.0, 90.0])}
    pred, why = rule_landmarks(_skull(head), head.skull_landmarks, "male", tips)
    assert {"kaehler_nose_width", "nose_purkait2024_alar_width", "mouth_75pct_rule"} <= set(pred)
    width = pred["nose_purkait2024_alar_width"]
    assert np.isnan(width["al_l"][1:]).all() and width["al_l"][0] > 0 > width["al_r"][0]
    assert isinstance(why, dict)


@pytest.mark.parametrize("case", ["headsq", "vhp_female", "vhp_male"])
def test_truth_landmark_files_read_with_what_is_not_in_view(case):
    truth = read_truth_landmarks(TRUTH / f"{case}.mrk.json")
    assert {"en_l", "en_r", "ex_l", "ex_r"} <= set(truth.positions)
    if case == "vhp_male":  # the face is cut flat in front: no nose, no mouth
        assert {"prn", "al_l", "ch_l", "ls"} <= set(truth.absent)
        assert "field of view" in truth.absent["prn"]
    else:
        assert {"al_l", "al_r", "ch_l", "ch_r", "sn", "ls"} <= set(truth.positions)
    assert ("prn" in truth.positions) == (case == "headsq")


def test_headsq_truth_landmarks_lie_on_the_skin_validate_scores(headsq_nhdr):
    """The frame check: the skin validate extracts at iso 500 holds the placed points."""
    from workbench.core.spatial import MeshIndex
    from workbench.services.ct.ct_mesh import mesh_from_ct

    skin = mesh_from_ct(headsq_nhdr, tissue="skin", iso=500).mesh
    truth = read_truth_landmarks(TRUTH / "headsq.mrk.json")
    on_skin = {c: p for c, p in truth.positions.items() if c != "sto"}  # sto: the open mouth
    d = MeshIndex(skin).closest_points(np.array(list(on_skin.values()))).distances
    assert d.max() < 0.5, dict(zip(on_skin, d.round(2), strict=True))


def test_the_validation_manifest_takes_truth_landmarks(tmp_path, headsq_nhdr):
    from workbench.core.errors import InputError
    from workbench.services.validation.run import read_manifest

    ct = str(headsq_nhdr)
    head = "id,skull,truth,truth_landmarks\n"
    m = tmp_path / "m.csv"
    m.write_text(head + f"h,{ct},{ct},{TRUTH / 'headsq.mrk.json'}\n", encoding="utf-8")
    assert read_manifest(m)[0].truth_landmarks == TRUTH / "headsq.mrk.json"
    m.write_text(head + f"h,{ct},{ct},nowhere.mrk.json\n", encoding="utf-8")
    with pytest.raises(InputError, match="column truth_landmarks"):
        read_manifest(m)
    m.write_text(head + f"h,{ct},{ct},\n", encoding="utf-8")
    assert replace(read_manifest(m)[0]).truth_landmarks is None
