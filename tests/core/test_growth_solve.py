"""The growth constraint solve (Kähler §8.5.3) on synthetic landmark sets (mm)."""

from __future__ import annotations

import numpy as np
import pytest

from workbench.core.growth_solve import (
    Constraint,
    SoftPair,
    arc_length,
    arc_sagitta,
    nearby_pairs,
    solve_landmarks,
)


def _cloud(n: int = 40, seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return rng.normal(scale=60.0, size=(n, 3))


def test_soft_pairs_alone_scale_the_set_about_the_anchor() -> None:
    p = _cloud()
    soft = [SoftPair(a, b) for a, b in nearby_pairs(p)]
    sol = solve_landmarks(p, [], soft, 1.2, anchor=[0, 1])
    centre = p[[0, 1]].mean(axis=0)
    assert np.allclose(sol.points, centre + 1.2 * (p - centre), atol=1e-6)
    assert np.allclose([f for *_, f in sol.soft_factors], 1.2)


def test_feasible_euclidean_and_axis_targets_are_met() -> None:
    p = _cloud()
    # the targets come from a known smooth change of the set: a stretch in y and a bend
    q = p * np.array([1.05, 1.25, 1.1]) + 0.002 * p[:, [0]] ** 2 * np.array([0, 1, 0])
    rng = np.random.default_rng(1)
    pairs = rng.choice(len(p), size=(25, 2))
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    hard = [Constraint(int(a), int(b), float(np.linalg.norm(q[a] - q[b]))) for a, b in pairs[:15]]
    hard += [Constraint(int(a), int(b), float(q[a, 1] - q[b, 1]), axis=1) for a, b in pairs[15:]]
    soft = [SoftPair(a, b) for a, b in nearby_pairs(p)]
    sol = solve_landmarks(p, hard, soft, 1.1, anchor=[0])
    assert np.abs(sol.hard_residuals).max() < 0.2
    assert np.allclose(sol.points[0], p[0], atol=1e-6)  # the anchor stays
    assert sol.rounds > 1  # the Euclidean rows were re-linearised


def test_anchor_fixes_the_translation() -> None:
    p = _cloud(12)
    hard = [Constraint(0, 1, 2 * float(np.linalg.norm(p[0] - p[1])))]
    soft = [SoftPair(a, b) for a, b in nearby_pairs(p)]
    sol = solve_landmarks(p, hard, soft, 1.0, anchor=[3, 4, 5])
    assert np.allclose(sol.points[[3, 4, 5]].mean(axis=0), p[[3, 4, 5]].mean(axis=0), atol=1e-6)


def test_midline_pairs_stay_on_the_midline() -> None:
    p = _cloud(30)
    p[:10, 0] = 0.0  # ten midline landmarks
    hard = [Constraint(10, 11, 1.3 * float(np.linalg.norm(p[10] - p[11])))]
    soft = [SoftPair(a, b) for a, b in nearby_pairs(p)]
    soft += [SoftPair(a, a + 1, axes=(0,)) for a in range(9)]
    sol = solve_landmarks(p, hard, soft, 1.0, anchor=[0])
    assert np.abs(sol.points[:10, 0]).max() < 0.01


def test_bad_constraints_are_refused() -> None:
    p = _cloud(5)
    with pytest.raises(ValueError):
        solve_landmarks(p, [Constraint(0, 0, 3.0)], [], 1.0, anchor=[0])
    with pytest.raises(ValueError):
        solve_landmarks(p, [Constraint(0, 1, -3.0)], [], 1.0, anchor=[0])
    with pytest.raises(ValueError):
        solve_landmarks(p, [], [], 1.0, anchor=[])


@pytest.mark.parametrize("chord,arc", [(40.0, 41.0), (60.0, 80.0), (30.0, 30.0 * np.pi / 2)])
def test_arc_sagitta_inverts_arc_length(chord: float, arc: float) -> None:
    h = arc_sagitta(chord, arc)
    assert h > 0
    assert arc_length(chord, h) == pytest.approx(arc, rel=1e-9)


def test_semicircle_and_flat_arcs() -> None:
    assert arc_sagitta(20.0, 10 * np.pi) == pytest.approx(10.0, rel=1e-6)
    assert arc_sagitta(20.0, 19.0) == 0.0
    assert arc_length(20.0, 0.0) == 20.0
