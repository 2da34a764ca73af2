"""No command writes over an input or an existing output, and a job folder holds one run.

Issue 12 ("evidence is sacred").  Every refused command must leave the bytes
of its inputs (and of the old outputs) as they were.  One real reconstruction
runs per module; the reruns reuse its job result (monkeypatched fit) because
only the output plumbing is under test.
"""

from __future__ import annotations

import copy
import hashlib
import shutil
from dataclasses import replace
from pathlib import Path

import pytest

import workbench.services.reconstruction.job as job_module
from workbench.cli.main import main
from workbench.core.errors import InputError
from workbench.core.headgen.eyes import icosphere
from workbench.core.landmarks import LandmarkSet
from workbench.io.case_file import load_case
from workbench.io.markups import write_landmarks, write_mrk_json
from workbench.io.meshes import read_mesh, write_mesh
from workbench.reporting.report import read_report_json
from workbench.services.templates.reference_parts import skull_surface


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _tree(folder: Path) -> dict[str, str]:
    """Relative path -> SHA-256 of every file below ``folder``."""
    return {str(p.relative_to(folder)): _sha(p) for p in sorted(folder.rglob("*")) if p.is_file()}


def _no_partials(parent: Path) -> None:
    assert not [p.name for p in parent.iterdir() if ".partial-" in p.name]


def _refused(argv: list[str], capsys: pytest.CaptureFixture[str], *words: str) -> str:
    code = main(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    assert "Traceback" not in err
    for word in words:
        assert word in err, err
    return err


@pytest.fixture
def ball(tmp_path: Path) -> Path:
    """A 160 mm ball standing in for a skull (a real mesh file, mm)."""
    return write_mesh(tmp_path / "ball.ply", icosphere(2).scaled(80.0))


@pytest.fixture
def no_fit(monkeypatch: pytest.MonkeyPatch) -> None:
    """The fit must not start: the clash is found before it."""

    def fail(*_a, **_k):
        raise AssertionError("the reconstruction ran although its output was refused")

    monkeypatch.setattr(job_module, "run_reconstruction", fail)


# ------------------------------------------------------------------ reconstruct
@pytest.fixture(scope="module")
def first_run(tmp_path_factory: pytest.TempPathFactory, head_female) -> dict:
    """One real ``workbench reconstruct`` into ``out`` (no pictures); its job result kept."""
    folder = tmp_path_factory.mktemp("outputs-recon")
    skull = write_mesh(folder / "skull.ply", skull_surface(head_female))
    landmarks = folder / "skull.mrk.json"
    write_mrk_json(landmarks, head_female.skull_landmarks)
    out = folder / "runs" / "recon"
    kept: list = []
    real = job_module.run_reconstruction

    def keep(*args, **kwargs):
        result = real(*args, **kwargs)
        kept.append((result, copy.deepcopy(result.report)))
        return result

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(job_module, "run_reconstruction", keep)
        assert (
            main(
                [
                    "reconstruct",
                    str(skull),
                    "--landmarks",
                    str(landmarks),
                    "--sex",
                    "male",
                    "--no-pictures",
                    "--out",
                    str(out),
                ]
            )
            == 0
        )
    result, report = kept[0]
    return {"skull": skull, "landmarks": landmarks, "out": out, "result": result, "report": report}


@pytest.fixture
def cached_fit(first_run: dict, monkeypatch: pytest.MonkeyPatch) -> None:
    """Reruns reuse the first run's job result (a fresh copy of its report)."""

    def again(*_a, **_k):
        return replace(first_run["result"], report=copy.deepcopy(first_run["report"]))

    monkeypatch.setattr(job_module, "run_reconstruction", again)


@pytest.fixture
def old_run(first_run: dict, tmp_path: Path) -> Path:
    """A private copy of the first run's folder, to rerun into."""
    out = tmp_path / "recon"
    shutil.copytree(first_run["out"], out)
    return out


def test_first_run_is_complete_and_alone(first_run: dict) -> None:
    out = first_run["out"]
    for name in (
        "face.ply",
        "head/template.json",
        "skull_landmarks.mrk.json",
        "case.fcase",
        "report.json",
        "report.pdf",
    ):
        assert (out / name).is_file(), name
    assert sorted(p.name for p in out.parent.iterdir()) == ["recon"]
    assert load_case(out / "case.fcase").case.specimen.mesh is not None


def test_reconstruct_refuses_a_skull_inside_its_output_folder(
    first_run: dict, tmp_path: Path, no_fit: None, capsys
) -> None:
    out = tmp_path / "DIR"
    out.mkdir()
    skull = out / "face.ply"
    shutil.copyfile(first_run["skull"], skull)
    before = _sha(skull)
    for extra in ([], ["--force"]):
        _refused(
            ["reconstruct", str(skull), "--out", str(out), *extra],
            capsys,
            "face.ply, an input of this command",
            "pick another --out",
        )
        assert _sha(skull) == before
        assert sorted(p.name for p in out.iterdir()) == ["face.ply"]
    _no_partials(tmp_path)


def test_rerun_with_landmarks_from_the_output_folder_is_refused(
    old_run: Path, first_run: dict, no_fit: None, capsys
) -> None:
    old = _tree(old_run)
    skull_sha = _sha(first_run["skull"])
    landmarks = old_run / "skull_landmarks.mrk.json"
    for extra in ([], ["--force"]):
        _refused(
            [
                "reconstruct",
                str(first_run["skull"]),
                "--landmarks",
                str(landmarks),
                "--out",
                str(old_run),
                *extra,
            ],
            capsys,
            "skull_landmarks.mrk.json, an input of this command",
            "pick another --out",
        )
        assert _tree(old_run) == old
    assert _sha(first_run["skull"]) == skull_sha
    _no_partials(old_run.parent)


def test_rerun_into_an_existing_folder_needs_force_and_keeps_the_old_run(
    old_run: Path, first_run: dict, cached_fit: None, capsys
) -> None:
    old = _tree(old_run)
    skull_sha = _sha(first_run["skull"])
    _refused(
        ["reconstruct", str(first_run["skull"]), "--out", str(old_run)],
        capsys,
        "already exists",
        "use --force to replace it",
        "recon.1",
    )
    assert _tree(old_run) == old
    assert (
        main(
            [
                "reconstruct",
                str(first_run["skull"]),
                "--landmarks",
                str(first_run["landmarks"]),
                "--no-pictures",
                "--out",
                str(old_run),
                "--force",
            ]
        )
        == 0
    )
    printed = capsys.readouterr().out
    assert "kept the previous recon as" in printed
    assert _tree(old_run.with_name("recon.1")) == old  # the old run, byte for byte
    new = _tree(old_run)
    assert set(new) == set(old)  # one complete run, nothing mixed
    for name in new:  # every file written anew
        assert (old_run / name).stat().st_ino != (
            old_run.with_name("recon.1") / name
        ).stat().st_ino, name
    report = read_report_json(old_run / "report.json")
    assert report["case_id"]
    assert load_case(old_run / "case.fcase").case.specimen.mesh is not None
    assert _sha(first_run["skull"]) == skull_sha
    assert sorted(p.name for p in old_run.parent.iterdir()) == ["recon", "recon.1"]


@pytest.mark.parametrize(
    "error, code", [(RuntimeError("disk on fire"), 1), (KeyboardInterrupt(), 130)]
)
def test_failure_mid_job_leaves_the_old_folder_and_no_partial(
    old_run: Path,
    first_run: dict,
    cached_fit: None,
    monkeypatch: pytest.MonkeyPatch,
    error: BaseException,
    code: int,
    capsys,
) -> None:
    old = _tree(old_run)

    def broken(*_a, **_k):
        raise error

    monkeypatch.setattr(job_module, "export_template", broken)
    assert (
        main(
            [
                "reconstruct",
                str(first_run["skull"]),
                "--no-pictures",
                "--out",
                str(old_run),
                "--force",
            ]
        )
        == code
    )
    capsys.readouterr()
    assert _tree(old_run) == old
    assert sorted(p.name for p in old_run.parent.iterdir()) == ["recon"]


def test_python_api_write_outputs_has_the_same_protection(first_run: dict, old_run: Path) -> None:
    result = replace(first_run["result"], report=copy.deepcopy(first_run["report"]))
    old = _tree(old_run)
    with pytest.raises(InputError, match="use --force"):
        job_module.write_outputs(result, old_run)
    assert _tree(old_run) == old
    fresh = old_run.with_name("scripted")
    files = job_module.write_outputs(result, fresh)
    assert files["face"] == fresh / "face.ply" and files["face"].is_file()
    assert result.opened.case.source_path == fresh / "case.fcase"
    _no_partials(fresh.parent)


# ------------------------------------------------------------------ single files
def test_case_new_never_turns_its_skull_into_a_case(ball: Path, capsys) -> None:
    before = _sha(ball)
    for extra in ([], ["--force"]):
        _refused(
            ["case", "new", str(ball), "--units", "mm", "--out", str(ball), *extra],
            capsys,
            "is an input of this command",
        )
        assert _sha(ball) == before
    assert read_mesh(ball, units="mm").mesh.n_vertices == icosphere(2).n_vertices


def test_case_new_over_an_existing_case_needs_force(ball: Path, tmp_path: Path, capsys) -> None:
    case = tmp_path / "EXISTING.fcase"
    assert main(["case", "new", str(ball), "--units", "mm", "--out", str(case)]) == 0
    first = _sha(case)
    skull_sha = _sha(ball)
    _refused(
        ["case", "new", str(ball), "--units", "mm", "--out", str(case)],
        capsys,
        "already exists",
        "use --force to replace it",
        "EXISTING.1.fcase",
    )
    assert _sha(case) == first and not (tmp_path / "EXISTING.1.fcase").exists()
    assert main(["case", "new", str(ball), "--units", "mm", "--out", str(case), "--force"]) == 0
    assert _sha(tmp_path / "EXISTING.1.fcase") == first
    assert (
        load_case(case).case.meta.case_id
        != load_case(tmp_path / "EXISTING.1.fcase").case.meta.case_id
    )
    assert _sha(ball) == skull_sha


def test_case_evidence_refuses_an_existing_file(ball: Path, tmp_path: Path, capsys) -> None:
    case = tmp_path / "c.fcase"
    assert main(["case", "new", str(ball), "--units", "mm", "--out", str(case)]) == 0
    out = tmp_path / "copy.ply"
    out.write_bytes(b"mine")
    _refused(["case", "evidence", str(case), "ball.ply", "--out", str(out)], capsys, "use --force")
    assert out.read_bytes() == b"mine"
    assert main(["case", "evidence", str(case), "ball.ply", "--out", str(out), "--force"]) == 0
    assert _sha(out) == _sha(ball) and (tmp_path / "copy.1.ply").read_bytes() == b"mine"


def test_landmarks_snap_out_refuses_an_existing_case_and_its_input(
    ball: Path, tmp_path: Path, capsys
) -> None:
    a = tmp_path / "A.fcase"
    b = tmp_path / "B.fcase"
    assert main(["case", "new", str(ball), "--units", "mm", "--out", str(a)]) == 0
    assert main(["case", "new", str(ball), "--units", "mm", "--out", str(b)]) == 0
    shas = (_sha(a), _sha(b))
    _refused(
        ["landmarks", "snap", str(a), "--all", "--out", str(b)],
        capsys,
        "already exists",
        "B.1.fcase",
    )
    _refused(
        ["landmarks", "snap", str(a), "--all", "--out", str(a), "--force"],
        capsys,
        "is the case being snapped",
    )
    assert (_sha(a), _sha(b)) == shas


def test_landmark_files_are_never_rewritten(tmp_path: Path, capsys) -> None:
    src = tmp_path / "skull.fcsv"
    write_landmarks(src, LandmarkSet.from_points("skull", {"n": (0.5, 85.0, -34.0)}))
    dst = tmp_path / "skull.mrk.json"
    dst.write_text("the user's own file")
    before = _sha(src)
    _refused(
        ["landmarks", "convert", str(src), str(src), "--surface", "skull", "--force"],
        capsys,
        "is an input of this command",
    )
    _refused(
        ["landmarks", "convert", str(src), str(dst), "--surface", "skull"],
        capsys,
        "already exists",
        "skull.1.mrk.json",
    )
    assert dst.read_text() == "the user's own file" and _sha(src) == before
    assert main(["landmarks", "convert", str(src), str(dst), "--surface", "skull", "--force"]) == 0
    assert (tmp_path / "skull.1.mrk.json").read_text() == "the user's own file"
    assert _sha(src) == before


def test_landmarks_suggest_and_frame_refuse_before_working(
    ball: Path, tmp_path: Path, capsys
) -> None:
    existing = tmp_path / "mine.mrk.json"
    existing.write_text("keep")
    before = _sha(ball)
    _refused(
        ["landmarks", "suggest", str(ball), "--units", "mm", "--out", str(existing)],
        capsys,
        "use --force",
    )
    _refused(
        ["landmarks", "suggest", str(ball), "--units", "mm", "--out", str(ball), "--force"],
        capsys,
        "is an input of this command",
    )
    lm = tmp_path / "fh.csv"
    write_landmarks(lm, LandmarkSet.from_points("skull", {"n": (0.0, 9.2, 7.9)}))
    _refused(
        [
            "landmarks",
            "frame",
            str(lm),
            "--surface",
            "skull",
            "--apply",
            str(ball),
            "--out",
            str(ball),
            "--force",
        ],
        capsys,
        "is an input of this command",
    )
    assert existing.read_text() == "keep" and _sha(ball) == before


def test_mesh_convert_and_info_refuse_inputs_and_existing_files(
    ball: Path, tmp_path: Path, capsys
) -> None:
    before = _sha(ball)
    link = tmp_path / "alias.ply"
    link.symlink_to(ball)
    _refused(
        ["mesh", "convert", str(ball), str(link), "--units", "mm", "--force"],
        capsys,
        "is an input of this command",
    )
    out = tmp_path / "ball.stl"
    assert main(["mesh", "convert", str(ball), str(out), "--units", "mm"]) == 0
    first = _sha(out)
    _refused(["mesh", "convert", str(ball), str(out), "--units", "mm"], capsys, "ball.1.stl")
    assert _sha(out) == first
    assert main(["mesh", "convert", str(ball), str(out), "--units", "mm", "--force"]) == 0
    assert _sha(tmp_path / "ball.1.stl") == first
    _refused(["mesh", "info", str(ball), "--out", str(ball)], capsys, "is an input")
    assert _sha(ball) == before


def test_mesh_from_ct_refuses_to_write_over_the_volume(
    headsq_nhdr: Path, tmp_path: Path, capsys
) -> None:
    before = _sha(headsq_nhdr)
    _refused(
        ["mesh-from-ct", str(headsq_nhdr), "--out", str(headsq_nhdr), "--force"],
        capsys,
        "is an input of this command",
    )
    existing = tmp_path / "bone.ply"
    existing.write_bytes(b"old")
    _refused(["mesh-from-ct", str(headsq_nhdr), "--out", str(existing)], capsys, "bone.1.ply")
    assert _sha(headsq_nhdr) == before and existing.read_bytes() == b"old"


# ------------------------------------------------------------------ other output folders
def test_folder_commands_refuse_a_folder_holding_an_input(
    ball: Path, tmp_path: Path, capsys
) -> None:
    before = _sha(ball)
    folder = ball.parent
    _refused(
        [
            "compare",
            str(ball),
            str(ball),
            "--units",
            "mm",
            "--truth-units",
            "mm",
            "--region",
            "all",
            "--out",
            str(folder),
            "--force",
        ],
        capsys,
        "an input of this command",
    )
    manifest = tmp_path / "manifest.csv"
    skin = write_mesh(tmp_path / "skin.ply", icosphere(2).scaled(90.0))  # not the skull itself
    manifest.write_text(f"id,skull,truth,units\nc1,{ball},{skin},mm\n")
    _refused(
        ["validate", str(manifest), "--out", str(tmp_path), "--force"],
        capsys,
        "an input of this command",
        "pick another --out",
    )
    pack = tmp_path / "pack"
    pack.mkdir()
    (pack / "template.json").write_text("{}")
    _refused(
        ["template", "export", "--template", str(pack), "--out", str(pack), "--force"],
        capsys,
        "an input of this command",
    )
    _refused(
        [
            "template",
            "build",
            "--skin",
            str(ball),
            "--skull",
            str(ball),
            "--units",
            "mm",
            "--out",
            str(folder),
            "--force",
        ],
        capsys,
        "an input of this command",
    )
    assert _sha(ball) == before and (pack / "template.json").read_text() == "{}"
    _no_partials(tmp_path)


def test_template_export_replaces_an_existing_folder_only_with_force(
    tmp_path: Path, head_male, capsys
) -> None:
    out = tmp_path / "pack"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    _refused(["template", "export", "--out", str(out)], capsys, "use --force", "pack.1")
    assert _tree(out) == {"notes.txt": _sha(out / "notes.txt")}
    assert main(["template", "export", "--out", str(out), "--force"]) == 0
    assert (tmp_path / "pack.1" / "notes.txt").read_text() == "mine"
    assert (out / "template.json").is_file() and not (out / "notes.txt").exists()
    _no_partials(tmp_path)


def test_demo_refuses_a_folder_that_is_not_a_previous_demo(tmp_path: Path, capsys) -> None:
    out = tmp_path / "results"
    out.mkdir()
    (out / "thesis.docx").write_bytes(b"years of work")
    _refused(["demo", "--out", str(out)], capsys, "use --force", "results.1")
    assert (out / "thesis.docx").read_bytes() == b"years of work"
    from workbench.cli.demo_cmd import DEMO_MARK, _is_demo_output

    assert not _is_demo_output(out)
    (out / DEMO_MARK).write_text("")
    assert _is_demo_output(out)


def test_services_called_from_scripts_refuse_the_same_clashes(ball: Path, tmp_path: Path) -> None:
    from workbench.services.templates.build import build_template_pack
    from workbench.services.validation.run import ValidationCase, run_validation

    before = _sha(ball)
    existing = tmp_path / "pack"
    existing.mkdir()
    (existing / "mine.txt").write_text("keep")
    with pytest.raises(InputError, match="use --force"):
        build_template_pack(ball, ball, existing, units="mm")
    with pytest.raises(InputError, match="an input of this command"):
        build_template_pack(ball, ball, tmp_path, units="mm", force=True)
    with pytest.raises(InputError, match="an input of this command"):
        run_validation([ValidationCase("c1", ball, ball, units="mm")], tmp_path, force=True)
    assert _sha(ball) == before and (existing / "mine.txt").read_text() == "keep"
    _no_partials(tmp_path)
