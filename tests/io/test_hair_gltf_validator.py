"""The Khronos glTF-Validator on glTF files with hair, brows, beard and moustache (issue 34):
the animation's ``.glb`` and a reconstruction's ``face_builds.glb`` report 0 errors and 0
warnings with the pieces' sparse morph targets, two-sided materials and tinted colours.

The validator is installed and run as in ``test_gltf_materials.py`` (its fixture)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pygltflib
import pytest
from test_gltf_materials import VALIDATOR_VERSION, _validate, gltf_validator  # noqa: F401

from workbench.model.appearance import Appearance, Hsv

pytestmark = pytest.mark.slow

LOOK = Appearance(
    tone="mst4",
    regions={"hair": Hsv(0.07, 0.55, 0.35)},
    grooming={"hair": "short", "brows": "soft_arch", "beard": "short", "moustache": "full"},
)
KINDS = {"hair", "brows", "beard", "moustache"}


def _clean(report: dict) -> dict:
    issues = report["issues"]
    assert report["validatorVersion"] == VALIDATOR_VERSION
    assert (issues["numErrors"], issues["numWarnings"]) == (0, 0), issues["messages"][:10]
    return report["info"]


def test_animation_glb_with_hair_is_valid(tmp_path: Path, head_male, gltf_validator) -> None:  # noqa: F811
    from workbench.services.animation.gltf import export_head_glb, ramp_keyframes

    out, _, _ = export_head_glb(
        head_male, tmp_path / "head.glb", ["au1", "au26"], ramp_keyframes("au26"), appearance=LOOK
    )
    info = _clean(_validate(gltf_validator, out))
    assert info["hasMorphTargets"] and info["animationCount"] == 1
    gltf = pygltflib.GLTF2().load(str(out))
    assert KINDS <= {n.name for n in gltf.nodes}
    sparse = [a for a in gltf.accessors if a.sparse is not None]
    assert sparse  # the hair's targets are sparse, and valid
    assert all(m.doubleSided for m in gltf.materials if m.name in KINDS)


def test_face_builds_glb_with_hair_is_valid(tmp_path: Path, head_male, gltf_validator) -> None:  # noqa: F811
    """A mirrored input frame (a reflection: the ribbons' triangles turned over)."""
    from workbench.services.reconstruction.build_faces import BuildFaces
    from workbench.services.reconstruction.job import write_build_files
    from workbench.services.reconstruction.reconstruct import Reconstruction

    flip = np.diag([-1.0, 1.0, 1.0, 1.0])
    flip[:3, 3] = [5.0, -2.0, 30.0]
    recon = Reconstruction(head_male, flip, True, None, np.zeros((0, 3)), np.zeros((0, 3)), {})  # type: ignore[arg-type]
    n = head_male.skin.n_vertices
    names = ("lean", "average", "heavy")
    builds = BuildFaces(
        names=names,
        bmi={"lean": 19.0, "average": 24.0, "heavy": 32.0},
        z={"lean": -1.0, "average": 0.0, "heavy": 1.5},
        main="average",
        main_z=0.0,
        per_z_mm=np.ones(n),
        offsets={"lean": np.full(n, -2.0), "average": np.zeros(n), "heavy": np.full(n, 3.0)},
        lower_mm=np.full(n, -2.0),
        upper_mm=np.full(n, 3.0),
        normals=head_male.skin.vertex_normals,
        base=head_male.skin.vertices,
        model_id="test",
    )
    files = write_build_files(recon, builds, tmp_path, appearance=LOOK)
    info = _clean(_validate(gltf_validator, files["builds_glb"]))
    assert info["hasMorphTargets"]
    gltf = pygltflib.GLTF2().load(str(files["builds_glb"]))
    assert KINDS <= {n.name for n in gltf.nodes}
