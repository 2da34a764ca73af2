"""Hair on a head in its case's colours (workbench.services.grooming), issue 34."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.core.appearance import rgb_to_hsv
from workbench.model.appearance import Appearance, Hsv
from workbench.services import grooming
from workbench.services.appearance import skin_colours

LOOK = Appearance(
    tone="mst3",
    regions={"hair": (0.08, 0.6, 0.5)},
    grooming={"hair": "short", "brows": "straight", "beard": "stubble"},
)


def test_pieces_in_the_chosen_colours(head_male) -> None:
    pieces = {p.kind: p for p in grooming.hair_meshes(head_male, LOOK)}
    assert set(pieces) == {"hair", "brows", "beard"}
    for piece in pieces.values():
        assert piece.srgb.shape == (piece.mesh.n_vertices, 3) and piece.srgb.dtype == np.uint8
        assert piece.normals.shape == (piece.mesh.n_vertices, 3)
        assert "not evidence" in piece.source
    hue = rgb_to_hsv(pieces["hair"].srgb.astype(float) / 255.0)[:, 0]
    assert np.median(hue) == pytest.approx(0.08, abs=0.02)
    # the brows follow the hair, a little darker, unless set by hand
    v_hair = np.median(pieces["hair"].srgb.max(axis=1))
    v_brow = np.median(pieces["brows"].srgb.max(axis=1))
    assert v_brow < v_hair
    own = LOOK.with_colour("brows", Hsv(0.6, 0.5, 0.4))
    brows = next(p for p in grooming.hair_meshes(head_male, own) if p.kind == "brows")
    assert np.median(rgb_to_hsv(brows.srgb.astype(float) / 255.0)[:, 0]) == pytest.approx(
        0.6, abs=0.02
    )


def test_the_scalp_under_the_hair_is_painted(head_male) -> None:
    plain = skin_colours(head_male, LOOK.replaced(grooming=())).astype(float)
    groomed = skin_colours(head_male, LOOK).astype(float)
    scalp = head_male.regions["scalp"]
    nose = head_male.regions["nose"]
    assert groomed[scalp].mean() < plain[scalp].mean() - 40.0
    assert np.array_equal(groomed[nose], plain[nose])


def test_lighter_view_and_another_skin(head_male) -> None:
    full = {p.kind: p for p in grooming.hair_meshes(head_male, LOOK)}
    light = {p.kind: p for p in grooming.hair_meshes(head_male, LOOK, stride=2)}
    assert light["hair"].mesh.n_faces < 0.55 * full["hair"].mesh.n_faces
    assert light["brows"].mesh.n_faces == full["brows"].mesh.n_faces
    moved = head_male.skin.vertices + [0.0, 5.0, 0.0]
    shifted = {p.kind: p for p in grooming.hair_meshes(head_male, LOOK, moved)}
    assert np.allclose(shifted["hair"].mesh.vertices - full["hair"].mesh.vertices, [0, 5, 0])
    assert grooming.grooming_ready(head_male, LOOK)
    with pytest.raises(ValueError, match="skin vertices"):
        grooming.hair_meshes(head_male, LOOK, moved[:-1])
    assert grooming.hair_meshes(head_male, None) == []
    assert grooming.hair_cover(head_male, Appearance()) is None
