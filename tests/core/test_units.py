"""Unit detection and explicit scaling on the real skull and head meshes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from workbench.core.errors import InputError, UnitsError
from workbench.core.mesh import Mesh
from workbench.core.units import (
    UNIT_SCALES,
    detect_units,
    detect_units_from_extent,
    reference_scale_factor,
    resolve_units,
    scale_to_reference_length,
    unit_scale,
)
from workbench.io.meshes import read_mesh


@pytest.fixture(scope="module")
def skull_raw(skull_obj: Path) -> Mesh:
    """The unitless skull exactly as stored (extent 8.7 x 13.9 x 12.1)."""
    return read_mesh(skull_obj).mesh


@pytest.fixture(scope="module")
def head_mm(fsaverage_ply: Path) -> Mesh:
    return read_mesh(fsaverage_ply).mesh


def _box(size: float) -> Mesh:
    """Tetrahedron whose largest extent is ``size`` (file units)."""
    v = np.array([[0, 0, 0], [size, 0, 0], [0, size / 2, 0], [0, 0, size / 3]], float)
    return Mesh(v, [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def test_real_skull_is_not_mm_and_looks_like_cm(skull_raw):
    np.testing.assert_allclose(skull_raw.extent, [8.69, 13.90, 12.11], atol=0.01)
    report = detect_units(skull_raw, kind="skull")
    assert report.guess == "cm"
    assert report.scale_to_mm == 10.0
    assert not report.plausible_in_mm
    assert report.needs_confirmation
    assert report.largest_extent == pytest.approx(13.9027, abs=1e-3)
    msg = report.message
    assert "13.9" in msg and "far too small for a skull" in msg
    assert "as centimetres it would be 139 mm" in msg
    assert "--units cm" in msg
    # inch is considered but 13.9 in = 353 mm is out of range for a skull
    assert dict(report.candidates)["in"] == pytest.approx(353.1, abs=0.1)


def test_real_head_is_plausible_mm(head_mm):
    report = detect_units(head_mm, kind="head")
    assert report.guess == "mm" and report.scale_to_mm == 1.0
    assert report.plausible_in_mm and not report.needs_confirmation
    assert "plausible as millimetres" in report.message


@pytest.mark.parametrize("unit", ["cm", "m", "in"])
def test_real_head_converted_to_other_units_is_recognised(head_mm, unit):
    in_unit = head_mm.scaled(1.0 / UNIT_SCALES[unit])
    report = detect_units(in_unit, kind="head")
    assert report.guess == unit
    assert report.needs_confirmation
    assert report.scale_to_mm == pytest.approx(UNIT_SCALES[unit])


def test_far_too_large_and_impossible_sizes():
    report = detect_units(_box(5000.0), kind="head")  # 5 m: not mm, no unit fits
    assert report.guess == "unknown" and report.scale_to_mm is None
    assert "far too large" in report.message and "--scale" in report.message
    tiny = detect_units(_box(1e-6))
    assert tiny.guess == "unknown" and tiny.needs_confirmation


def test_face_scan_accepts_smaller_extent():
    assert detect_units_from_extent(80.0, "face").plausible_in_mm
    assert not detect_units_from_extent(80.0, "head").plausible_in_mm
    with pytest.raises(InputError, match="unknown object kind"):
        detect_units_from_extent(80.0, "torso")


def test_ambiguous_cm_or_inch_prefers_closest_to_typical():
    # 12 units: 120 mm as cm and 305 mm as inches are both possible for a head
    report = detect_units_from_extent(12.0, "skull")
    assert report.guess == "cm"
    assert "as centimetres it would be 120 mm" in report.message
    assert "as inches it would be 305 mm" in report.message
    # 9 units: 90 mm is too small for a head, 229 mm as inches fits
    assert detect_units_from_extent(9.0, "head").guess == "in"


def test_empty_or_nonfinite_geometry_is_unknown():
    assert detect_units(np.zeros((0, 3))).guess == "unknown"
    assert detect_units(np.array([[np.nan, 0, 0], [1, 1, 1]])).guess == "unknown"  # one point left


def test_resolve_units(skull_raw, head_mm):
    skull_report = detect_units(skull_raw, kind="skull")
    with pytest.raises(UnitsError) as info:
        resolve_units(skull_report, "auto", source="skull.obj")
    assert "skull.obj" in str(info.value) and "--units cm" in str(info.value)
    assert resolve_units(skull_report, "cm") == 10.0
    assert resolve_units(skull_report, "in") == 25.4
    assert resolve_units(skull_report.confirm("--units cm"), "auto") == 1.0
    assert resolve_units(detect_units(head_mm), None) == 1.0
    assert unit_scale("Inches") == 25.4
    with pytest.raises(InputError, match="unknown unit"):
        resolve_units(skull_report, "furlong")


def test_scale_to_reference_length_skull(skull_raw):
    # adult skull with mandible: ~185 mm glabella-opisthocranion; the skull's length is z
    scaled = scale_to_reference_length(skull_raw, 185.0, axis="z")
    assert scaled.extent[2] == pytest.approx(185.0, rel=1e-12)
    factor = 185.0 / skull_raw.extent[2]
    np.testing.assert_allclose(scaled.vertices, skull_raw.vertices * factor, rtol=1e-12)
    np.testing.assert_allclose(scaled.extent, [132.8, 212.4, 185.0], atol=0.2)
    assert np.array_equal(scaled.faces, skull_raw.faces)
    report = detect_units(scaled, kind="skull")
    assert report.plausible_in_mm and report.guess == "mm"
    assert reference_scale_factor(skull_raw, 185.0, axis=2) == pytest.approx(factor)
    largest = scale_to_reference_length(skull_raw, 200.0)
    assert largest.extent.max() == pytest.approx(200.0)
    assert largest.extent.argmax() == 1


def test_scale_to_reference_length_rejects_bad_input(skull_raw):
    with pytest.raises(InputError, match="positive"):
        scale_to_reference_length(skull_raw, -5.0)
    with pytest.raises(InputError, match="unknown axis"):
        scale_to_reference_length(skull_raw, 185.0, axis="w")
    flat = Mesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float), [[0, 1, 2]])
    with pytest.raises(InputError, match="no extent"):
        scale_to_reference_length(flat, 185.0, axis="z")
