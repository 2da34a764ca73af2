"""Reference head assembly: the procedural skull fitted under the authored skin (issue 3, in progress)."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.io.tables import load_depth_table
from workbench.model.template import PARTS
from workbench.services.templates.template import build_reference_head


@pytest.fixture(scope="module", params=["female", "male"])
def head(request: pytest.FixtureRequest):
    # the session's head: built by build_reference_head in this session's
    # empty cache (tests/conftest.py), so these tests check a fresh build
    return request.getfixturevalue(f"head_{request.param}")


def test_every_ttable_pair_is_fitted(head) -> None:
    table = load_depth_table("ttable_2023")
    errors = head.provenance["depth_error_mm"]
    assert set(errors) == set(table.codes)  # all 36 T-Table landmark pairs take part
    values = np.array(list(errors.values()))
    # the skin landmark lies at the dowel tip: skull landmark + table depth along the dowel
    assert np.median(values) < 0.1
    # Issue 3: every pair within 1 mm (with the skull's Frankfort landmarks held
    # on FH).  Achieved: about 0.2 mm at worst for both sexes.
    assert values.max() < 1.0


def test_parts_are_present_and_the_bone_is_under_the_skin(head) -> None:
    assert set(PARTS) <= set(head.meshes)
    # Away from the openings bone stays under the skin (issue 3: > 0 mm).
    # Achieved: 0.75 mm (male), 1.7 mm (female) at worst.
    assert head.provenance["min_clearance_mm"] > 0.0
    # the skull keeps its own Frankfort landmarks on the FH plane
    fh = head.skull_landmarks.positions_of(["po_l", "po_r", "or_l", "or_r"])
    assert np.abs(fh[:, 1]).max() < 0.05
    # the fitted skull is mirror-symmetric: left/right landmark pairs mirror each other
    lms = head.skull_landmarks.as_dict()
    for code, pos in lms.items():
        if code.endswith("_l") and code[:-2] + "_r" in lms and np.isfinite(pos).all():
            assert np.linalg.norm(pos * [-1, 1, 1] - lms[code[:-2] + "_r"]) < 0.5, code
    skin = head.meshes["skin"]
    for part in ("cranium", "mandible"):
        lo, hi = head.meshes[part].bounds
        assert (lo > skin.bounds[0] - 1).all() and (hi < skin.bounds[1] + 1).all()


def test_template_identity(head) -> None:
    assert head.template_id.endswith(head.sex)
    assert len(head.content_hash) == 64
    again = build_reference_head(head.sex)
    assert again.content_hash == head.content_hash  # deterministic
