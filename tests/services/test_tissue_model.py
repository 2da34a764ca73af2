"""Tissue model settings: eye placement rules (no fit needed)."""

import pytest

from workbench.core.errors import InputError


def test_eye_placement_follows_the_tissue_model_unless_given():
    from workbench.services.tissue.tissue_model import TissueSettings

    assert TissueSettings().eye_rule == "stephan2009"
    assert TissueSettings(model="reference").eye_rule == "reference"
    assert TissueSettings(model="reference", eyes="stephan2009").eye_rule == "stephan2009"
    assert TissueSettings(eyes="reference").eye_rule == "reference"
    with pytest.raises(InputError, match="eye placement"):
        TissueSettings(eyes="glass")


def test_the_temples_are_calibrated_and_the_other_interpolated_sites_only_on_request(head_male):
    """No table landmark lies over the temporal fossa: the zygion-vertex sites calibrate it."""
    from workbench.services.tissue.dowel_sites import CALIBRATED_SITES, SITE_PATTERN
    from workbench.services.tissue.dowels import DepthSettings
    from workbench.services.tissue.tissue_model import TissueSettings, tissue_field

    assert CALIBRATED_SITES == {
        r.code for r in SITE_PATTERN if "zy_l" in r.parents or "zy_r" in r.parents
    }
    assert len(CALIBRATED_SITES) == 4
    depth = DepthSettings(sex="male")
    default = {s.code: s for s in tissue_field(head_male, depth).sites}
    interpolated = {c for c in default if c.startswith("i:")}
    assert interpolated == CALIBRATED_SITES  # all four placed, no other interpolated site
    # the table's blend of zygion and vertex (6.7 / 5.8 mm) is thinner than the reference there
    assert all(default[c].delta_mm < 0 for c in CALIBRATED_SITES)
    every = tissue_field(head_male, depth, TissueSettings(interpolated_sites=True)).sites
    assert CALIBRATED_SITES < {s.code for s in every if s.code.startswith("i:")}
    off = tissue_field(head_male, depth, TissueSettings(temple_sites=False)).sites
    assert not any(s.code.startswith("i:") for s in off)
