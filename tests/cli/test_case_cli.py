"""``workbench case``: a case file made from the real skull, inspected, and tamper-checked."""

from __future__ import annotations

import hashlib
import json
import zipfile
from pathlib import Path

import numpy as np
import pytest

from workbench.cli.main import main
from workbench.core.landmarks import LandmarkSet
from workbench.io.case_file import load_case
from workbench.io.markups import write_landmarks


def test_case_new_info_evidence(
    tmp_path: Path, skull_obj: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    landmarks = tmp_path / "skull.mrk.json"
    write_landmarks(
        landmarks, LandmarkSet.from_points("skull", {"n": (0.1, 9.5, 5.9), "pr": (0.0, 6.1, 6.2)})
    )
    case_file = tmp_path / "case.fcase"
    assert (
        main(
            [
                "case",
                "new",
                str(skull_obj),
                "--units",
                "cm",
                "--examiner",
                "A. Artist",
                "--landmarks",
                str(landmarks),
                "--out",
                str(case_file),
            ]
        )
        == 0
    )
    capsys.readouterr()

    loaded = load_case(case_file)
    case = loaded.case
    assert case.specimen.mesh.n_faces == 100_002
    assert case.specimen.mesh.extent.max() == pytest.approx(139.0, abs=0.5)  # cm -> mm
    # landmarks were given in the file's units and follow the same conversion
    assert np.allclose(case.landmarks["skull"]["n"].position, [1.0, 95.0, 59.0])

    assert main(["case", "info", str(case_file)]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["examiner"] == "A. Artist" and not info["tampered"]
    skull = next(e for e in info["evidence"] if e["role"] == "skull_mesh")
    assert skull["sha256"] == hashlib.sha256(skull_obj.read_bytes()).hexdigest()
    assert skull["status"] == "ok"
    assert info["landmarks"]["skull"]["defined"] == ["n", "pr"]
    assert [r["operation"] for r in info["audit"]][-1] == "Save case"

    out = tmp_path / "original.obj"
    assert main(["case", "evidence", str(case_file), "skull.obj", "--out", str(out)]) == 0
    assert out.read_bytes() == skull_obj.read_bytes()


def test_tampered_case_is_refused_then_reported(
    tmp_path: Path, skull_obj: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    case_file = tmp_path / "case.fcase"
    assert main(["case", "new", str(skull_obj), "--units", "cm", "--out", str(case_file)]) == 0
    tampered = tmp_path / "tampered.fcase"
    with zipfile.ZipFile(case_file) as src, zipfile.ZipFile(tampered, "w") as dst:
        for item in src.infolist():
            data = src.read(item.filename)
            if item.filename == "evidence/skull.obj":
                data = data.replace(b"v ", b"v  ", 1)
            dst.writestr(item, data)
    before = tampered.read_bytes()
    capsys.readouterr()
    assert main(["case", "info", str(tampered)]) == 2
    assert "skull.obj" in capsys.readouterr().err
    assert main(["case", "info", str(tampered), "--allow-tampered"]) == 0
    assert json.loads(capsys.readouterr().out)["tampered"] is True
    assert tampered.read_bytes() == before  # inspection never rewrites a case


def test_case_new_refuses_unclear_units(
    tmp_path: Path, skull_obj: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "case.fcase"
    assert main(["case", "new", str(skull_obj), "--out", str(out)]) == 2
    assert "--units cm" in capsys.readouterr().err
    assert not out.exists()
