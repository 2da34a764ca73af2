"""Outputs never replace inputs or old outputs silently (workbench.io.outputs, issue 12)."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

import pytest

from workbench.core.errors import InputError
from workbench.io.outputs import (
    backup_existing,
    backup_name,
    check_output_file,
    check_output_folder,
    output_file,
    same_file,
    staged_folder,
    write_folder,
)


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _tree(folder: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()
    }


def test_same_file_sees_through_symlinks_and_hard_links(tmp_path: Path) -> None:
    a = tmp_path / "a.ply"
    a.write_bytes(b"bone")
    (tmp_path / "link.ply").symlink_to(a)
    os.link(a, tmp_path / "hard.ply")
    assert same_file(a, tmp_path / "link.ply") and same_file(a, tmp_path / "hard.ply")
    assert same_file(tmp_path / "x" / ".." / "missing.ply", tmp_path / "missing.ply")
    assert not same_file(a, tmp_path / "b.ply")


def test_output_file_that_is_an_input_is_refused_even_with_force(tmp_path: Path) -> None:
    skull = tmp_path / "skull.ply"
    skull.write_bytes(b"evidence")
    before = _sha(skull)
    (tmp_path / "alias.ply").symlink_to(skull)
    for target in (skull, tmp_path / "alias.ply", tmp_path / "." / "skull.ply"):
        for force in (False, True):
            with pytest.raises(InputError, match="is an input of this command"):
                check_output_file(target, [skull], force)
    assert _sha(skull) == before


def test_output_file_inside_an_input_folder_is_refused(tmp_path: Path) -> None:
    dicom = tmp_path / "series"
    dicom.mkdir()
    with pytest.raises(InputError, match="inside the input folder"):
        check_output_file(dicom / "bone.ply", [dicom], force=True)


def test_existing_output_file_needs_force_and_is_kept_as_numbered_backup(tmp_path: Path) -> None:
    out = tmp_path / "skull_landmarks.mrk.json"
    out.write_text("first")
    with pytest.raises(InputError) as info:
        check_output_file(out, [], force=False)
    assert "use --force to replace it" in str(info.value)
    assert "skull_landmarks.1.mrk.json" in str(info.value)
    assert out.read_text() == "first"
    notes: list[str] = []
    with output_file(out, [], force=True, notify=notes.append) as path:
        tmp = path.with_name(".new")
        tmp.write_text("second")
        os.replace(tmp, path)  # what the atomic writers do
    assert out.read_text() == "second"
    assert (tmp_path / "skull_landmarks.1.mrk.json").read_text() == "first"
    assert notes and "skull_landmarks.1.mrk.json" in notes[0]
    with output_file(out, [], force=True) as path:
        tmp = path.with_name(".new")
        tmp.write_text("third")
        os.replace(tmp, path)
    assert (tmp_path / "skull_landmarks.2.mrk.json").read_text() == "second"
    assert (tmp_path / "skull_landmarks.1.mrk.json").read_text() == "first"


def test_failed_write_leaves_the_old_file_and_no_backup(tmp_path: Path) -> None:
    out = tmp_path / "case.fcase"
    out.write_bytes(b"old case")
    with pytest.raises(RuntimeError), output_file(out, [], force=True):
        raise RuntimeError("writer failed")
    assert out.read_bytes() == b"old case"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["case.fcase"]


def test_backup_names_never_overwrite_a_backup(tmp_path: Path) -> None:
    f = tmp_path / "face.ply"
    f.write_text("now")
    (tmp_path / "face.1.ply").write_text("older")
    assert backup_name(f).name == "face.2.ply"
    assert backup_existing(f).name == "face.2.ply"
    assert not f.exists() and (tmp_path / "face.1.ply").read_text() == "older"
    d = tmp_path / "recon"
    d.mkdir()
    (tmp_path / "recon.1").mkdir()
    (tmp_path / "recon.1" / "keep").write_text("x")
    assert backup_existing(d).name == "recon.2"
    assert (tmp_path / "recon.1" / "keep").read_text() == "x"
    plain = tmp_path / "README"
    plain.write_text("r")
    assert backup_name(plain).name == "README.1"


def test_output_folder_holding_an_input_is_refused_even_with_force(tmp_path: Path) -> None:
    out = tmp_path / "recon"
    out.mkdir()
    skull = out / "face.ply"
    skull.write_bytes(b"bone")
    for force in (False, True):
        with pytest.raises(InputError, match=r"face\.ply, an input of this command"):
            check_output_folder(out, [skull], force)
        with pytest.raises(InputError, match="pick another --out"):
            with staged_folder(out, force, [skull]):
                pytest.fail("must not start")
    pack = tmp_path / "pack"
    pack.mkdir()
    with pytest.raises(InputError, match="inside the input folder"):
        check_output_folder(pack / "out", [pack], True)
    assert skull.read_bytes() == b"bone"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pack", "recon"]


def test_staged_folder_refuses_then_keeps_the_old_run(tmp_path: Path) -> None:
    out = tmp_path / "recon"
    out.mkdir()
    (out / "face.ply").write_text("run 1")
    old = _tree(out)
    with pytest.raises(InputError, match="use --force to replace it") as info:
        with staged_folder(out, False, []):
            pytest.fail("must not start")
    assert "recon.1" in str(info.value)
    with staged_folder(out, True, []) as temp:
        assert temp.parent == out.parent and temp.name.startswith(".recon.partial-")
        assert _tree(out) == old  # untouched while the job runs
        (temp / "face.ply").write_text("run 2")
        (temp / "report.json").write_text("{}")
    assert _tree(out) == {"face.ply": b"run 2", "report.json": b"{}"}
    assert _tree(tmp_path / "recon.1") == old
    assert sorted(p.name for p in tmp_path.iterdir()) == ["recon", "recon.1"]


def test_failure_mid_job_leaves_the_old_folder_and_no_partial(tmp_path: Path) -> None:
    out = tmp_path / "recon"
    out.mkdir()
    (out / "face.ply").write_text("run 1")
    for error in (RuntimeError("fit failed"), KeyboardInterrupt()):
        with pytest.raises(type(error)):
            with staged_folder(out, True, []) as temp:
                (temp / "face.ply").write_text("half")
                raise error
        assert _tree(out) == {"face.ply": b"run 1"}
        assert sorted(p.name for p in tmp_path.iterdir()) == ["recon"]


def test_new_or_empty_folder_needs_no_force_and_stale_partials_go(tmp_path: Path) -> None:
    out = tmp_path / "deep" / "recon"
    stale = tmp_path / "deep" / ".recon.partial-999999999"
    stale.mkdir(parents=True)
    (stale / "face.ply").write_text("killed run")
    files = write_folder(out, lambda d: [d / "a.txt"] if (d / "a.txt").write_text("a") else [])
    assert files == [out / "a.txt"] and (out / "a.txt").read_text() == "a"
    assert not stale.exists()
    empty = tmp_path / "empty"
    empty.mkdir()
    with staged_folder(empty, False, []) as temp:
        (temp / "b").write_text("b")
    assert _tree(empty) == {"b": b"b"}
    assert not (tmp_path / "empty.1").exists()


def test_discard_existing_replaces_without_backup(tmp_path: Path) -> None:
    out = tmp_path / "demo_out"
    out.mkdir()
    (out / "summary.json").write_text("old")
    with staged_folder(out, True, [], discard_existing=True) as temp:
        (temp / "summary.json").write_text("new")
    assert _tree(out) == {"summary.json": b"new"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demo_out"]
