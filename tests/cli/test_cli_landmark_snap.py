"""``workbench landmarks snap``: snap landmarks of a saved case, save it atomically."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from workbench.cli.main import main
from workbench.io.case_file import load_case
from workbench.io.markups import write_landmarks


@pytest.fixture
def case_file(tmp_path: Path, skull_obj: Path, skull_obj_suggested) -> Path:
    """A case of ``skull.obj`` (× 15 mm) with the suggested skull landmarks imported."""
    _, landmarks = skull_obj_suggested
    to_file = np.diag([1 / 15, 1 / 15, 1 / 15, 1.0])  # landmark files are in file units
    lm_path = tmp_path / "skull.mrk.json"
    write_landmarks(lm_path, landmarks.transformed(to_file), coordinate_system="RAS")
    out = tmp_path / "case.fcase"
    assert (
        main(
            [
                "case",
                "new",
                str(skull_obj),
                "--scale",
                "15",
                "--landmarks",
                str(lm_path),
                "--out",
                str(out),
            ]
        )
        == 0
    )
    return out


def test_snap_one_landmark_and_save(case_file: Path, capsys: pytest.CaptureFixture[str]) -> None:
    before = load_case(case_file).case.landmarks["skull"]
    capsys.readouterr()
    assert main(["landmarks", "snap", str(case_file), "--code", "g"]) == 0
    printed = capsys.readouterr().out
    assert "g → most anterior midline point within 8 mm: moved" in printed
    assert "saved" in printed
    loaded = load_case(case_file)  # hashes checked: a valid case file
    after = loaded.case.landmarks["skull"]
    assert np.linalg.norm(after["g"].position - before["g"].position) > 0.5
    assert after["g"].status == "placed"
    for lm in before:  # nothing else changed
        if lm.code != "g":
            assert after[lm.code].equals(lm), lm.code
    ops = [r["operation"] for r in loaded.audit_records]
    assert "Snap g to most anterior midline point" in ops


def test_snap_all_dry_run_and_out(
    case_file: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    original = case_file.read_bytes()
    capsys.readouterr()
    assert main(["landmarks", "snap", str(case_file), "--all", "--dry-run"]) == 0
    printed = capsys.readouterr().out
    assert "zy_l → most lateral point" in printed and "nothing saved" in printed
    assert case_file.read_bytes() == original
    out = tmp_path / "snapped.fcase"
    assert main(["landmarks", "snap", str(case_file), "--all", "--out", str(out)]) == 0
    assert case_file.read_bytes() == original
    before = load_case(case_file).case.landmarks["skull"]
    after = load_case(out).case.landmarks["skull"]
    changed = {lm.code for lm in after if not lm.equals(before[lm.code])}
    assert {"g", "zy_l", "zy_r"} <= changed and not changed & {"n", "po_l", "fe_l"}


def test_snap_needs_the_frame_landmarks(
    tmp_path: Path, skull_obj: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    lm_path = tmp_path / "g.csv"
    lm_path.write_text("label,x,y,z\ng,0.0,2.6,5.6\n", encoding="utf-8")
    out = tmp_path / "case.fcase"
    assert (
        main(
            [
                "case",
                "new",
                str(skull_obj),
                "--scale",
                "15",
                "--landmarks",
                str(lm_path),
                "--out",
                str(out),
            ]
        )
        == 0
    )
    capsys.readouterr()
    assert main(["landmarks", "snap", str(out), "--code", "g"]) == 2
    assert "po_l" in capsys.readouterr().err
