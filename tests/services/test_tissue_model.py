"""Tissue model settings: eye placement rules (no fit needed)."""

import pytest

from workbench.core.errors import InputError


def test_eye_placement_follows_the_tissue_model_unless_given():
    from workbench.services.tissue_model import TissueSettings

    assert TissueSettings().eye_rule == "stephan2009"
    assert TissueSettings(model="reference").eye_rule == "reference"
    assert TissueSettings(model="reference", eyes="stephan2009").eye_rule == "stephan2009"
    assert TissueSettings(eyes="reference").eye_rule == "reference"
    with pytest.raises(InputError, match="eye placement"):
        TissueSettings(eyes="glass")
