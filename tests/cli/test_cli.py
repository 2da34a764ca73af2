"""The ``workbench`` command line, end to end on real data."""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import workbench
from workbench.cli.main import main
from workbench.core.landmarks import LandmarkSet
from workbench.io.markups import read_landmarks, write_landmarks
from workbench.io.meshes import read_mesh


def test_version_and_help(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert workbench.__version__ in capsys.readouterr().out
    assert main([]) == 0
    out = capsys.readouterr().out
    for command in ("demo", "mesh-from-ct", "mesh", "landmarks", "samples"):
        assert command in out


def test_python_dash_m_runs_the_cli() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "workbench", "--version"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert done.returncode == 0
    assert workbench.__version__ in done.stdout


def test_mesh_from_ct_on_headsq(tmp_path: Path, headsq_nhdr: Path) -> None:
    out = tmp_path / "bone.ply"
    report = tmp_path / "bone.json"
    assert (
        main(
            [
                "mesh-from-ct",
                str(headsq_nhdr),
                "--tissue",
                "bone",
                "--out",
                str(out),
                "--report",
                str(report),
                "--quiet",
            ]
        )
        == 0
    )
    mesh = read_mesh(out).mesh
    extent = mesh.extent
    # bone of an adult head, cut by the field of view: ~15 cm wide, 13.8 cm of slices
    assert (
        130 < extent[0] < 175 and 130 < extent[1] < 200 and extent[2] == pytest.approx(138, abs=2)
    )
    data = json.loads(report.read_text())
    assert data["tissue"] == "bone" and data["iso"] == pytest.approx(1150, abs=1)
    assert data["n_faces"] == mesh.n_faces


def test_mesh_from_ct_decimates_and_accepts_sample_names(tmp_path: Path) -> None:
    out = tmp_path / "skin.stl"
    assert (
        main(
            [
                "mesh-from-ct",
                "sample:headsq",
                "--tissue",
                "skin",
                "--target-triangles",
                "20000",
                "--out",
                str(out),
                "--quiet",
            ]
        )
        == 0
    )
    mesh = read_mesh(out).mesh
    assert abs(mesh.n_faces - 20000) < 0.05 * 20000


def test_units_are_never_guessed_silently(
    tmp_path: Path, skull_obj: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "skull.ply"
    assert main(["mesh", "convert", str(skull_obj), str(out), "--kind", "skull"]) == 2
    err = capsys.readouterr().err
    assert "skull.obj" in err and "--units" in err
    assert not out.exists()
    assert (
        main(["mesh", "convert", str(skull_obj), str(out), "--kind", "skull", "--units", "cm"]) == 0
    )
    mesh = read_mesh(out).mesh
    assert mesh.extent.max() == pytest.approx(139.0, abs=0.5)


def test_mesh_info_reports_problems(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], headsq_nhdr: Path
) -> None:
    out = tmp_path / "skin.ply"
    main(["mesh-from-ct", str(headsq_nhdr), "--tissue", "skin", "--out", str(out), "--quiet"])
    capsys.readouterr()
    assert main(["mesh", "info", str(out)]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["units"]["looks_like_mm"] is True
    # the CT field of view cuts the head: open at the top and bottom
    assert info["validation"]["holes"] >= 2
    assert any("holes" in p for p in info["validation"]["problems"])


def test_bad_input_gives_one_clear_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    broken = tmp_path / "broken.ply"
    broken.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 10\n")
    assert main(["mesh", "info", str(broken)]) == 2
    err = capsys.readouterr().err
    assert "broken.ply" in err and "Traceback" not in err
    assert (
        main(["mesh-from-ct", str(tmp_path / "nothing.nrrd"), "--out", str(tmp_path / "x.ply")])
        == 2
    )
    assert "nothing.nrrd" in capsys.readouterr().err


def test_landmark_convert_round_trip(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    points = {"n": (0.5, 85.0, -34.0), "po_l": (70.0, -10.0, -40.0), "po_r": (-70.0, -10.0, -40.0)}
    src = tmp_path / "skull.fcsv"
    write_landmarks(src, LandmarkSet.from_points("skull", points))
    dst = tmp_path / "skull.mrk.json"
    assert main(["landmarks", "convert", str(src), str(dst), "--surface", "skull"]) == 0
    back = read_landmarks(dst, "skull").landmarks
    for code, p in points.items():
        assert np.array_equal(back[code].position, np.asarray(p))
    assert main(["landmarks", "check", str(dst), "--surface", "skull"]) == 0
    report = json.loads(capsys.readouterr().out.split("\n", 1)[1])
    assert set(report["defined"]) == set(points)
    assert "g" in report["not_in_file"]


def test_samples_list_and_offline_fetch(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["samples", "list"]) == 0
    assert "headsq" in capsys.readouterr().out
    assert main(["samples", "fetch", "skull"]) == 0
    path = Path(capsys.readouterr().out.strip())
    assert path.name == "skull.obj" and path.stat().st_size == 3_421_857
    assert main(["samples", "fetch", "no-such-sample"]) == 2


def test_landmarks_frame_aligns_a_copy(
    tmp_path: Path, skull_obj: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    # FH landmarks on the unitless skull (+y up, face +z), with the head tilted 12 degrees
    # about x; the frame undoes the tilt and an aligned copy of the mesh is written
    tilt = np.deg2rad(12.0)
    rot = np.array([[1, 0, 0], [0, np.cos(tilt), -np.sin(tilt)], [0, np.sin(tilt), np.cos(tilt)]])
    fh = {
        "po_l": (6.2, 7.0, -0.5),
        "po_r": (-6.2, 7.0, -0.5),
        "or_l": (3.3, 7.0, 6.7),
        "or_r": (-3.3, 7.0, 6.7),
        "n": (0.0, 9.2, 7.9),
        "me": (0.0, -0.5, 6.5),
    }
    tilted = {c: rot @ np.asarray(p) for c, p in fh.items()}
    lm = tmp_path / "fh.csv"
    write_landmarks(lm, LandmarkSet.from_points("skull", tilted))
    out = tmp_path / "aligned.ply"
    args = [
        "landmarks",
        "frame",
        str(lm),
        "--surface",
        "skull",
        "--apply",
        str(skull_obj),
        "--out",
        str(out),
    ]
    assert main(args) == 2  # the mesh's units are unclear: refused, nothing written
    assert not out.exists()
    capsys.readouterr()
    assert main([*args, "--units", "mm"]) == 0
    printed = capsys.readouterr().out
    report = json.loads(printed[: printed.rindex("}") + 1])
    matrix = np.asarray(report["input_to_head"])
    head = {c: matrix[:3, :3] @ p + matrix[:3, 3] for c, p in tilted.items()}
    assert np.allclose(head["po_l"], [6.2, 0, 0], atol=1e-9)
    assert np.allclose(head["or_l"][1], 0, atol=1e-9) and head["or_l"][2] > 0
    assert report["mirrored_input"] is False
    aligned = read_mesh(out, units="mm").mesh
    original = read_mesh(skull_obj, units="mm").mesh
    assert np.allclose(aligned.vertices, original.vertices @ matrix[:3, :3].T + matrix[:3, 3])


def test_mesh_from_ct_says_what_a_high_bone_level_leaves_out(tmp_path: Path, capsys) -> None:
    """A bone level above 300 HU on HU data (stated or evident) is followed by a note: how
    much of the thin bone it drops, and the usual level."""
    import nibabel as nib

    data = np.full((30, 30, 30), -1024, np.int16)
    data[3:27, 3:27, 3:27] = 40
    data[6:24, 6:24, 6:14] = 1300  # thick bone
    data[6:24, 6:24, 18] = 420  # a thin plate
    path = tmp_path / "ct.nii.gz"
    nib.save(nib.Nifti1Image(data, np.eye(4)), str(path))
    assert main(["mesh-from-ct", str(path), "--iso", "600", "--out", str(tmp_path / "b.ply")]) == 0
    text = capsys.readouterr().out
    assert "note: at 600 HU, 100 % of the thin bone" in text and "--iso 300" in text
    assert main(["mesh-from-ct", str(path), "--out", str(tmp_path / "c.ply")]) == 0
    text = capsys.readouterr().out
    assert "bone surface at iso 300" in text and "look like Hounsfield" in text
    assert "left out" not in text


def test_a_command_imports_only_its_own_module() -> None:
    """``workbench reconstruct`` does not pay for importing the other commands (~0.4 s);
    help, typos and ``batch``'s column checks still see every command."""
    code = (
        "import sys\n"
        "from workbench.cli.main import build_parser\n"
        "p = build_parser(['--debug', 'reconstruct', 'x.ply'], every=False)\n"
        "loaded = sorted(m for m in sys.modules if m.startswith('workbench.cli.') and "
        "m.endswith('_cmd'))\n"
        "print(' '.join(loaded))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["workbench.cli.reconstruct_cmd"]
    from workbench.cli.batch_cmd import commands
    from workbench.cli.main import COMMANDS, build_parser

    names = {c for _, cs in COMMANDS for c in cs}
    assert set(commands()) == names
    assert set(_choices(build_parser(["reconstrct"], every=False))) == names
    assert set(_choices(build_parser(["render", "template"], every=False))) == {
        "template",
        "render",
    }


def _choices(parser) -> dict:
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def test_finaliser_errors_after_an_interrupt_are_not_printed():
    """A Ctrl-C inside a constructor leaves a half-built object whose ``__del__``
    may fail (pyvista's Renderer reading an attribute never set); once the
    interrupt is seen that report is dropped, before it the hook found is used."""
    import types

    from workbench.cli import main as cli_main

    reported = []
    saved = sys.unraisablehook
    sys.unraisablehook = reported.append
    try:
        watch = cli_main._Interrupts()
        try:
            failure = types.SimpleNamespace(exc_type=AttributeError, exc_value=None)
            sys.unraisablehook(failure)
            assert reported == [failure]  # no interrupt yet: reported as usual
            watch.seen = True
            sys.unraisablehook(failure)
            assert reported == [failure]  # after the interrupt: dropped
        finally:
            watch.restore()
        assert sys.unraisablehook == reported.append
    finally:
        sys.unraisablehook = saved


def test_an_interrupt_printed_by_compiled_code_is_raised_again(capsys):
    """Compiled code that prints an exception and goes on (numpy's ``import_array`` when
    Ctrl-C lands in the import it makes) calls ``sys.excepthook``: no traceback is shown,
    the interrupt is raised again a moment later, and the hook found is put back."""
    import ctypes

    from workbench.cli import main as cli_main

    saved = sys.excepthook
    reported: list = []
    sys.excepthook = lambda *exc: reported.append(exc[0])
    try:
        watch = cli_main._Interrupts()
        try:
            with pytest.raises(KeyboardInterrupt):
                ctypes.pythonapi.PyErr_SetNone(ctypes.py_object(KeyboardInterrupt))
                ctypes.pythonapi.PyErr_Print()  # what numpy's import_array does on failure
                assert watch.seen and not reported
                for _ in range(500):  # raised again within ~10 ms, by a timer thread
                    time.sleep(0.01)
            sys.excepthook(ValueError, ValueError("other"), None)  # others: as before
        finally:
            watch.restore()
        assert reported == [ValueError]
        assert sys.excepthook is not watch._printed
    finally:
        sys.excepthook = saved
    assert "KeyboardInterrupt" not in capsys.readouterr().err
