"""Skin detail files of a scan-fit pack (workbench.io.skin_detail_export)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.core.test_detail_layer import _coarse, _scan
from workbench.core.detail_layer import build_detail
from workbench.core.errors import InputError
from workbench.core.headgen.eyes import icosphere
from workbench.io.meshes import read_mesh
from workbench.io.skin_detail_export import NPZ_NAME, PLY_NAME, read_skin_detail, write_skin_detail


def test_round_trip_and_re_detailing(tmp_path) -> None:
    coarse, scan = _coarse(), _scan()
    detail = build_detail(coarse, scan, np.ones(scan.n_vertices))
    files = write_skin_detail(tmp_path, detail, coarse)
    assert [f.name for f in files] == [PLY_NAME, NPZ_NAME]
    mesh = read_mesh(tmp_path / PLY_NAME).mesh
    np.testing.assert_allclose(mesh.vertices, detail.apply(coarse.vertices).vertices, atol=1e-4)
    back = read_skin_detail(tmp_path / NPZ_NAME, coarse)
    assert back.levels == detail.levels
    np.testing.assert_array_equal(back.observed, detail.observed)
    # an animated skin of the same topology gets the same detail along its own normals
    moved = coarse.vertices * [1.0, 1.1, 0.9]
    np.testing.assert_allclose(back.apply(moved).vertices, detail.apply(moved).vertices, atol=1e-4)


def test_bad_files_are_refused(tmp_path) -> None:
    coarse, scan = _coarse(), _scan()
    detail = build_detail(coarse, scan, np.ones(scan.n_vertices))
    write_skin_detail(tmp_path, detail, coarse)
    other = icosphere(2)
    with pytest.raises(InputError, match="other connectivity"):
        read_skin_detail(tmp_path / NPZ_NAME, other)
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip file at all")
    with pytest.raises(InputError, match="not a skin detail file"):
        read_skin_detail(bad, coarse)
    with pytest.raises(InputError, match="not found"):
        read_skin_detail(tmp_path / "missing.npz", coarse)
    np.savez(
        tmp_path / "short.npz",
        levels=2,
        displacement=np.zeros(5),
        observed=np.zeros(5, bool),
        coarse_faces=coarse.faces,
    )
    with pytest.raises(InputError, match="5 displacements"):
        read_skin_detail(tmp_path / "short.npz", coarse)
