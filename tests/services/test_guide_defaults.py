"""Guides measured on real bone and chosen by validation.

The dental arch traced by rays (teeth fused on a CT surface), the
missing-teeth refusals, the default rules of ``guide_defaults.csv`` and the
width check against the facial norms (instead of the reference head).
"""

from __future__ import annotations

import numpy as np
import pytest

from workbench.core.mesh import Mesh
from workbench.core.raycast import RayCaster
from workbench.services.guides import measure as gm
from workbench.services.guides.classic import Guide, classic_guides
from workbench.services.guides.fit_guides import width_problem
from workbench.services.guides.rules import effective_rules, load_guide_defaults, load_rules


@pytest.fixture(scope="module")
def head(head_male):
    return head_male


def _skull(head, drop_incisors: bool = False) -> Mesh:
    teeth = head.meshes["upper_teeth"]
    if drop_incisors:  # the four upper incisors lost: crowns whose centre is within 9 mm of x = 0
        keep = np.abs(teeth.vertices[teeth.faces].mean(axis=1)[:, 0]) > 9.0
        teeth = Mesh(teeth.vertices, teeth.faces[keep])
    parts = [head.meshes["cranium"], head.meshes["mandible"], teeth, head.meshes["lower_teeth"]]
    offsets = np.cumsum([0] + [p.n_vertices for p in parts])
    return Mesh(
        np.vstack([p.vertices for p in parts]),
        np.vstack([p.faces + o for p, o in zip(parts, offsets, strict=False)]),
    )


def test_the_arch_traced_by_rays_finds_the_canines_the_crown_section_finds(head):
    skull = _skull(head)
    pr = head.skull_landmarks["pr"].position
    section = gm._canines(skull, pr)
    arch = gm.dental_arch(RayCaster(skull), pr)
    assert section is not None and arch is not None
    traced = gm._arch_canines(arch)
    assert traced is not None
    for side in ("l", "r"):
        # the arch counts crown widths from the midline, the section counts crowns
        assert abs(traced[side][0] - section[side][0]) < 2.5
        assert np.sign(traced[side][0]) == (1 if side == "l" else -1)


def test_missing_upper_incisors_are_said_and_the_nose_guides_still_apply(head):
    problems: list[str] = []
    guides = classic_guides(
        head.skull_landmarks, _skull(head, drop_incisors=True), sex="male", problems=problems
    )
    ids = {g.id for g in guides}
    assert {"nose_width_l", "nose_width_r", "nose_tip"} <= ids
    assert not {"mouth_width_l", "lip_upper_margin", "lip_parting"} & ids
    text = " ".join(problems)
    assert "teeth missing" in text and "mouth width" in text and "lip parting" in text


def test_defaults_replace_the_classic_guides_unless_the_user_chooses(head):
    defaults = {d.rule_id: d.replaces for d in load_guide_defaults()}
    assert defaults["mouth_75pct_rule"] == "kaehler_mouth_width"
    assert defaults["nose_purkait2024_alar_width"] == "kaehler_nose_width"
    asked, applied = effective_rules(())
    assert asked == [] and {d.rule_id for d in applied} == set(defaults)
    # asking for the classic rule keeps Kähler's guide for those landmarks
    asked, applied = effective_rules(["kaehler_mouth_width"])
    assert asked == [] and "mouth_75pct_rule" not in {d.rule_id for d in applied}
    # another published rule for the same landmarks replaces the default
    asked, applied = effective_rules(["mouth_stephan2003_57pct"])
    assert asked == ["mouth_stephan2003_57pct"]
    assert {d.rule_id for d in applied} == {"nose_purkait2024_alar_width"}
    assert load_rules()["nose_purkait2024_alar_width"].sex == "M"  # stated, not hidden


def _vline(gid: str, x: float) -> Guide:
    return Guide(gid, gid, "vline", "frontal", (x,), ("ch_l" if x > 0 else "ch_r",), "r", "c")


def test_a_width_guide_is_refused_by_the_norms_never_by_the_reference():
    narrow = {g.id: g for g in (_vline("mouth_width_l", 15.0), _vline("mouth_width_r", -15.0))}
    why = width_problem(narrow["mouth_width_l"], narrow, "male")
    assert "labial fissure width of 30.0 mm" in why and "SD below" in why
    usual = {g.id: g for g in (_vline("mouth_width_l", 25.0), _vline("mouth_width_r", -24.0))}
    assert width_problem(usual["mouth_width_l"], usual, None) == ""
    # one line alone: twice its distance from the midline
    assert width_problem(_vline("mouth_width_l", 26.0), {}, "female") == ""
    other = Guide("lip_parting", "l", "hline", "frontal", (-50.0,), ("sto",), "r", "c")
    assert width_problem(other, {}, None) == ""


def test_a_broken_spine_and_missing_nasal_bones_leave_the_other_guides(head):
    """Bad input: without the anterior nasal spine the nose tip says why it is not
    derived; without the nasal bones (rhinion) nothing else is lost."""
    lms = head.skull_landmarks.without("ans").without("rhi")
    problems: list[str] = []
    guides = {g.id for g in classic_guides(lms, _skull(head), sex="male", problems=problems)}
    assert "nose_tip" not in guides and any("nose tip" in p and "ans" in p for p in problems)
    assert {"nose_width_l", "nose_width_r", "mouth_width_l", "lip_parting"} <= guides
