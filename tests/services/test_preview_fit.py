"""The interactive preview re-solves the last fit's warp with moved targets (mm)."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.core.tps import fit_warp
from workbench.services.guides.classic import Guide
from workbench.services.reconstruction.preview_fit import PreviewFit
from workbench.services.reconstruction.reconstruct import SMOOTHING, reconstruct
from workbench.services.templates.reference_parts import skull_surface


@pytest.fixture(scope="module")
def fitted(head_female, head_male):
    """The female skull with the male head, shifted so input and head frames differ."""
    m = np.eye(4)
    m[:3, 3] = [40.0, -25.0, 300.0]
    skull = skull_surface(head_female).transformed(m)
    lms = head_female.skull_landmarks.transformed(m)
    guide_targets = {"prn": head_male.skin_landmarks["prn"].position + [0.0, 0.0, 3.0]}
    return skull, lms, reconstruct(skull, lms, head_male, guide_targets=guide_targets)


def test_labels_describe_every_correspondence(fitted):
    _, _, recon = fitted
    assert len(recon.labels) == len(recon.sources) == len(recon.targets)
    kinds = {label.split(":")[0] for label in recon.labels}
    assert {"dowel", "guide", "anchor"} <= kinds <= {"dowel", "guide", "clearance", "anchor", "eye"}
    assert "guide:prn" in recon.labels
    assert recon.labels.count("clearance") == recon.figures["extra_correspondences"]
    # anchors hold the modelled skin: their targets are their sources
    rows = [i for i, lab in enumerate(recon.labels) if lab == "anchor"]
    np.testing.assert_array_equal(recon.sources[rows], recon.targets[rows])


def test_an_unchanged_preview_is_the_fit(fitted, head_male):
    _, _, recon = fitted
    preview = PreviewFit.from_fit(recon, head_male)
    np.testing.assert_allclose(preview.skin(), recon.face.vertices, atol=1e-8)


def test_moving_a_landmark_moves_its_dowel_tip_and_the_face_near_it(fitted, head_male):
    _, lms, recon = fitted
    preview = PreviewFit.from_fit(recon, head_male)
    g = lms["g"].position
    assert preview.move_landmark("g", g + [0.0, 4.0, 0.0])  # 4 mm up (input = head axes here)
    moved = preview.skin()
    shift = np.linalg.norm(moved - recon.face.vertices, axis=1)
    row = recon.labels.index("dowel:g")
    skin_g = recon.sources[row]
    base = recon.base_skin
    near = np.linalg.norm(base - skin_g, axis=1) < 6.0
    far = np.linalg.norm(base - skin_g, axis=1) > 80.0
    assert shift[near].mean() > 1.5
    assert shift[far].max() < shift[near].mean() / 2
    # the same as solving the warp from scratch with that one tip moved and the anchors
    # around it let go
    targets = recon.targets.copy()
    targets[row] += recon.input_to_head[:3, :3] @ [0.0, 4.0, 0.0]
    from workbench.services.reconstruction.lids import lids_on_globes
    from workbench.services.reconstruction.reconstruct import ANCHOR_CLEARANCE_MM

    anchor = np.array([lab == "anchor" for lab in recon.labels])
    keep = ~(anchor & (np.linalg.norm(recon.sources - skin_g, axis=1) < ANCHOR_CLEARANCE_MM))
    # (anchors near moving points hold loosely: the fit's own λ per correspondence)
    assert recon.smoothing is not None and len(recon.smoothing) == len(recon.sources)
    assert recon.smoothing.min() == SMOOTHING
    warp = fit_warp(recon.sources[keep], targets[keep], smoothing=recon.smoothing[keep])
    # (then the lids rested on the fit's eyeballs, as the fit rests them)
    rested, _ = lids_on_globes(warp(base), recon.head.meshes["eyes"])
    np.testing.assert_allclose(preview.skin_head(), rested, atol=1e-8)
    assert not preview.move_landmark("no_such_code", g)


def test_moving_a_guide_sets_the_coordinate_it_fixes(fitted, head_male):
    _, _, recon = fitted
    preview = PreviewFit.from_fit(recon, head_male)
    row = recon.labels.index("guide:prn")
    y = float(recon.targets[row, 1]) + 5.0
    guide = Guide(
        id="nose_tip_y",
        label="nose tip height",
        kind="hline",
        view="frontal",
        value=(y,),
        affects=("prn",),
        rule_id="test",
        citation="test",
    )
    assert preview.move_guide(guide)
    assert preview.targets[row, 1] == pytest.approx(y)
    np.testing.assert_allclose(preview.targets[row, [0, 2]], recon.targets[row, [0, 2]])
    prn = recon.sources[row]
    i = int(np.argmin(np.linalg.norm(recon.base_skin - prn, axis=1)))
    assert preview.skin_head()[i, 1] - recon.head.skin.vertices[i, 1] > 3.0
    off = Guide(
        id="x",
        label="x",
        kind="vline",
        view="frontal",
        value=(1.0,),
        affects=("no_code",),
        rule_id="t",
        citation="t",
    )
    assert not preview.move_guide(off)
