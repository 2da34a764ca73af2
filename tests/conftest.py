"""Shared fixtures.

Real data comes from ``../shared/data`` beside the repository (always present
in CI).  A test that needs it and cannot find it fails loudly instead of
skipping.  Nothing here touches the network: the sample cache is seeded from
that folder (see ``workbench.samples``).
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import settings

os.environ.setdefault("QT_API", "pyside6")

# Property tests draw the same examples on every run, so a CI result can be
# reproduced exactly; set HYPOTHESIS_PROFILE=explore to search new examples.
settings.register_profile("ci", derandomize=True, print_blob=True)
settings.register_profile("explore", derandomize=False, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = Path(os.environ.get("WORKBENCH_SHARED_DATA", REPO.parent / "shared" / "data"))


def _require(path: Path) -> Path:
    if not path.exists():
        pytest.fail(
            f"real test data not found: {path} (the ../shared/data folder must sit beside "
            "the repository; set WORKBENCH_SHARED_DATA to point elsewhere)",
            pytrace=False,
        )
    return path


@pytest.fixture(scope="session")
def shared_data() -> Path:
    return _require(SHARED_DATA)


@pytest.fixture(scope="session")
def headsq_nhdr(shared_data: Path) -> Path:
    """The VTK headsq quarter CT: NRRD header with 93 detached raw slices."""
    return _require(shared_data / "vtk_headsq_quarter_ct" / "headsq" / "quarter.nhdr")


@pytest.fixture(scope="session")
def skull_obj(shared_data: Path) -> Path:
    """Watertight 100k-triangle skull with mandible (unitless, +y up, face +z)."""
    return _require(shared_data / "skull_mesh_yahoojapan" / "skull.obj")


@pytest.fixture(scope="session")
def fsaverage_ply(shared_data: Path) -> Path:
    """Average adult head surface in mm (MNE fsaverage)."""
    return _require(shared_data / "fsaverage_head_mne" / "fsaverage-head_mm.ply")


@pytest.fixture(scope="session", autouse=True)
def _sample_cache(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Point the sample cache at a temporary folder seeded from ../shared/data.

    Downloads are disabled: a test that would need the network fails.
    """
    cache = tmp_path_factory.mktemp("sample-cache")
    os.environ["WORKBENCH_DATA_DIR"] = str(cache)
    os.environ["WORKBENCH_SAMPLE_MIRRORS"] = str(SHARED_DATA)
    os.environ["WORKBENCH_OFFLINE"] = "1"
    return cache


# ------------------------------------------------------------------ shared heavy fixtures
# The built-in reference head takes ~10 s to build; reference_head() caches it
# as a template pack in the session's temporary data folder, so each sex is
# built once per test session.


@pytest.fixture(scope="session")
def head_male(_sample_cache: Path):
    from workbench.services.templates.cache import reference_head

    return reference_head("male")


@pytest.fixture(scope="session")
def head_female(_sample_cache: Path):
    from workbench.services.templates.cache import reference_head

    return reference_head("female")


@pytest.fixture(scope="session")
def skull_obj_suggested(skull_obj: Path, head_male):
    """``(mesh, landmarks)``: ``skull.obj`` × 15 (mm, its own frame: +y up, face +z) and the
    male reference head's skull landmarks suggested on it (same frame, mm; ~2 s after the
    reference head).  Treat both as read-only: the landmark set and mesh are shared."""
    from workbench.io.meshes import read_mesh
    from workbench.services.landmarks.transfer import transfer_landmarks
    from workbench.services.templates.reference_parts import skull_surface

    mesh = read_mesh(skull_obj, scale=15.0, kind="skull").mesh
    result = transfer_landmarks(
        mesh,
        skull_surface(head_male),
        head_male.skull_landmarks,
        orientation=((0.0, 0.0, 1.0), (0.0, 1.0, 0.0)),
    )
    return mesh, result.landmarks


@pytest.fixture(scope="session")
def headsq_surfaces(headsq_nhdr: Path) -> dict:
    """Bone and skin surfaces of the headsq CT (its physical frame, mm)."""
    from workbench.services.ct.ct_mesh import mesh_from_ct

    return {t: mesh_from_ct(headsq_nhdr, t).mesh for t in ("bone", "skin")}


#: headsq anatomy (sample registry): face toward -y, superior -z, subject's left +x
HEADSQ_ORIENTATION = ((0.0, -1.0, 0.0), (0.0, 0.0, -1.0), (1.0, 0.0, 0.0))


@pytest.fixture(scope="session")
def headsq_orientation() -> tuple:
    return HEADSQ_ORIENTATION
