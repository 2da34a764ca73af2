"""Fixtures for the io tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from workbench.core.mesh import Mesh
from workbench.io.meshes import read_mesh


@pytest.fixture(scope="module")
def head_mesh(fsaverage_ply: Path) -> Mesh:
    """Real head in mm with coordinates that are not float32-exact after a shift."""
    mesh = read_mesh(fsaverage_ply).mesh
    return mesh.with_vertices(mesh.vertices + np.array([0.1, 1 / 3, -np.pi]))
