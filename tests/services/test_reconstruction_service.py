"""The one reconstruction pipeline: FitInputs snapshots, and CLI job == window job."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from workbench.commands.reconstruction_setup import (
    SetDepthOverride,
    SetDowelExclusion,
    SetDowelSettings,
    SetGuides,
    SetOrientation,
)
from workbench.commands.stack import CommandStack
from workbench.core.errors import InputError
from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh
from workbench.model.case import Case
from workbench.model.reconstruction_setup import DowelSettings, Orientation
from workbench.model.specimen import Specimen
from workbench.services.reconstruction.service import FitInputs, depth_settings, tissue_settings
from workbench.services.tissue.tissue_model import TissueSettings

ORIENT = ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0))  # the generated skull: face +z, up +y


def tetra() -> Mesh:
    v = np.array([[0, 0, 0], [10, 0, 0], [0, 10, 0], [0, 0, 10]], float)
    return Mesh(v, [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])


def small_case() -> tuple[Case, CommandStack]:
    case = Case(specimen=Specimen(tetra()))
    stack = CommandStack(case)
    stack.push(
        SetDowelSettings(
            sex="female", build=1.0, tissue_model="reference", region_factors={"nose": 1.2}
        )
    )
    stack.push(SetDepthOverride("g", 6.5))
    stack.push(SetDowelExclusion("ecm2s_l", True))
    stack.push(SetOrientation(ORIENT + ((1.0, 0.0, 0.0),)))
    return case, stack


# ---------------------------------------------------------------- snapshots
def test_fit_inputs_are_a_snapshot_of_the_case() -> None:
    case, stack = small_case()
    inputs = FitInputs.from_case(
        case, rules=["nose_rynn2010_prn"], ensemble=3, tissue=TissueSettings(min_tissue_mm=1.5)
    )
    assert inputs.skull is case.specimen.mesh and inputs.landmarks is None  # no landmarks yet
    assert inputs.dowels is case.dowels and inputs.orientation is case.orientation
    assert inputs.guides is None and inputs.use_guides and inputs.ensemble == 3
    assert inputs.rules == ("nose_rynn2010_prn",) and inputs.template is None
    assert inputs.hint == ORIENT + ((1.0, 0.0, 0.0),)
    fit = inputs.fit_settings
    assert fit.depth.sex == "female" and fit.depth.build == 1.0
    assert dict(fit.depth.overrides) == {"g": 6.5} and fit.depth.excluded == {"ecm2s_l"}
    assert fit.tissue.model == "reference" and dict(fit.tissue.region_factors) == {"nose": 1.2}
    assert fit.tissue.min_tissue_mm == 1.5
    # later edits of the case do not reach the snapshot (a worker may be fitting it)
    before = inputs.dowels
    stack.push(SetDowelSettings(sex="male"))
    stack.push(SetOrientation(None))
    assert inputs.dowels == before and inputs.dowels.sex == "female"
    assert inputs.orientation == Orientation(*ORIENT, (1.0, 0.0, 0.0))
    with pytest.raises(AttributeError):
        inputs.ensemble = 5  # type: ignore[misc]


def test_fit_inputs_keep_landmarks_packs_and_guides() -> None:
    case, stack = small_case()
    case.set_landmark_set(LandmarkSet.from_points("skull", {"n": (0.0, 5.0, 9.0)}))
    guide = {
        "id": "nose_tip",
        "label": "Nose tip",
        "kind": "point",
        "view": "lateral",
        "value": [-20.0, 95.0],
        "affects": ["prn"],
        "rule_id": "r",
        "citation": "c",
        "source": "user",
    }
    stack.push(SetGuides([guide]))
    inputs = FitInputs.from_case(case, templates=["a", "b"], use_guides=False)
    assert inputs.landmarks is case.landmarks["skull"] and inputs.guides is case.guides
    assert inputs.template == Path("a") and inputs.templates == (Path("a"), Path("b"))
    assert not inputs.use_guides


def test_fit_inputs_refuse_what_cannot_be_fitted() -> None:
    with pytest.raises(InputError, match="no skull"):
        FitInputs.from_case(Case())
    case, stack = small_case()
    stack.push(SetGuides([{"id": "nose_tip", "value": [1.0], "kind": "circle"}]))
    with pytest.raises(InputError, match="case guides"):
        FitInputs.from_case(case)
    with pytest.raises(InputError, match="ensemble"):
        FitInputs(tetra(), None, ensemble=-1)


def test_settings_conversions() -> None:
    d = DowelSettings(
        table="rhine_1983_sw_native_american",
        sex="female",
        build="obese",
        overrides={"g": 4.0},
        excluded=("n",),
        tissue_model="reference",
        region_factors={"chin": 0.8},
    )
    depth = depth_settings(d)
    assert (depth.table, depth.sex, depth.build) == (
        "rhine_1983_sw_native_american",
        "female",
        "obese",
    )
    assert depth.overrides == {"g": 4.0} and depth.excluded == frozenset({"n"})
    tissue = tissue_settings(d, TissueSettings(pin_dowels=True))
    assert tissue.model == "reference" and tissue.region_factors == {"chin": 0.8}
    assert tissue.pin_dowels


# ---------------------------------------------------------------- one pipeline
@pytest.fixture(scope="module")
def skull_file(tmp_path_factory: pytest.TempPathFactory, head_female) -> Path:
    from workbench.io.meshes import write_mesh
    from workbench.services.templates.reference_parts import skull_surface

    return write_mesh(
        tmp_path_factory.mktemp("one-pipeline") / "skull.ply", skull_surface(head_female)
    )


@pytest.mark.slow
def test_the_cli_job_and_the_window_job_give_the_same_face(
    skull_file: Path, tmp_path: Path, head_male
) -> None:
    from workbench.services.case.case_setup import start_case_from_skull
    from workbench.services.reconstruction import case_steps as jobs
    from workbench.services.reconstruction.job import JobSettings, run_reconstruction

    settings = JobSettings(
        sex="male",
        orientation=ORIENT,
        overrides={"g": 6.5},
        excluded=frozenset({"ecm2s_l", "ecm2s_r"}),
    )
    cli = run_reconstruction(skull_file, settings)

    # the window: open the skull, set the same things with the panels' commands, fit
    opened = start_case_from_skull(skull_file)
    case, stack = opened.case, opened.stack
    stack.push(SetOrientation(Orientation(*ORIENT)))
    stack.push(SetDepthOverride("g", 6.5))
    for code in ("ecm2s_l", "ecm2s_r"):
        stack.push(SetDowelExclusion(code, True))
    inputs = jobs.fit_inputs(case, use_guides=True, ensemble=0)
    assert inputs.dowels == cli.opened.case.dowels
    assert inputs.orientation == cli.opened.case.orientation
    window = jobs.fit_face(inputs)

    assert window.head.content_hash == cli.template.content_hash == head_male.content_hash
    np.testing.assert_allclose(window.recon.face.vertices, cli.recon.face.vertices, atol=1e-6)
    np.testing.assert_allclose(window.recon.input_to_head, cli.recon.input_to_head, atol=1e-9)
    assert [g.id for g in window.guides] == [g.id for g in cli.guides]
    assert [g.enabled for g in window.guides] == [g.enabled for g in cli.guides]
    assert window.recon.warnings == cli.recon.warnings
    assert window.preview.codes == cli.fit.preview.codes
    assert "ecm2s_l" not in window.preview.codes and window.recon.plan["g"].depth_mm == 6.5

    # one report builder: the window's export writes the job's report
    from workbench.pipelines.reconstruct import export_fit

    files = export_fit(case, window, tmp_path / "export", pictures=False).files
    report = json.loads(files["report"].read_text(encoding="utf-8"))
    mine = cli.report
    for key in (
        "template",
        "table",
        "landmarks",
        "guides",
        "predictions",
        "parameters",
        "frame",
        "ensemble",
    ):
        assert report[key] == json.loads(json.dumps(mine[key])), key
    assert report["case_id"] == case.meta.case_id != mine["case_id"]


# ---------------------------------------------------------------- the working skull
def _big_sphere() -> Mesh:
    """A closed sphere of ~300k triangles (over MAX_WORKING_TRIANGLES), radius 80 mm."""
    import pyvista as pv

    s = pv.Sphere(radius=80.0, theta_resolution=390, phi_resolution=390).triangulate()
    return Mesh(np.asarray(s.points, float), s.faces.reshape(-1, 4)[:, 1:])


def test_a_prefetched_working_skull_is_the_one_decimated_in_place(monkeypatch) -> None:
    from workbench.core import helper_process
    from workbench.services.reconstruction import service as rs

    big = _big_sphere()
    assert big.n_faces > rs.MAX_WORKING_TRIANGLES
    direct, notes = rs.working_skull(big)
    assert direct.n_faces <= rs.WORKING_TRIANGLES * 1.01 and "decimated" in notes[0]
    calls: list[int] = []
    real = helper_process.call
    monkeypatch.setattr(
        helper_process, "call", lambda name, *a: calls.append(len(a[1])) or real(name, *a)
    )
    rs.prefetch_working_skull(big)
    # the same surface read again (another object, equal arrays) takes the prefetched result
    again = Mesh(big.vertices.copy(), big.faces.copy())
    work, _ = rs.working_skull(again)
    assert calls == [big.n_faces]
    assert np.array_equal(work.vertices, direct.vertices)
    assert np.array_equal(work.faces, direct.faces)
    # taken once: a second fit of the same skull decimates it itself, and another skull
    # never takes a prefetched result
    rs.prefetch_working_skull(big)
    other = Mesh(big.vertices * 1.01, big.faces)
    assert rs.working_skull(other)[0].n_faces <= rs.WORKING_TRIANGLES * 1.01
    assert len(calls) == 2 and rs._prefetched(big) is not None
    # a small skull is used as it is and starts nothing
    rs.prefetch_working_skull(tetra())
    assert len(calls) == 2 and rs.working_skull(tetra())[0].n_faces == 4
