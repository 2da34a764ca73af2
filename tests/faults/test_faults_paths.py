"""Fault corpus (issue 29): hostile paths, ids and output targets for ``validate``, ``batch``
and the output rules, run through the CLI in this process.

Every entry is one problem.  It checks the exit status, that the message names the file or
option and the problem, that no traceback or "unexpected error" is printed, that the input
files are unchanged (SHA-256) and that nothing is written outside ``--out``.  Meshes are
small synthetic spheres (mm); batch rows run a stand-in for the reconstruct job where the
problem is the batch's own (interrupts, closed streams), so the file stays fast.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
import os
import re
import shutil
import socket
import stat
import sys
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest
from badinput._files import skull_mesh, sphere

from workbench.cli.main import main as real_main
from workbench.core.mesh import Mesh
from workbench.io.meshes import write_mesh

# ----------------------------------------------------------------------------- helpers


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _snapshot(root: Path, skip: Path) -> dict[str, str]:
    """Every entry below ``root`` except ``skip`` (the --out): regular files by SHA-256."""
    found = {}
    for dirpath, dirnames, filenames in os.walk(root):
        here = Path(dirpath)
        dirnames[:] = [d for d in dirnames if here / d != skip]
        for name in dirnames + filenames:
            p = here / name
            if p == skip:
                continue
            mode = os.lstat(p).st_mode
            found[str(p.relative_to(root))] = _sha(p) if stat.S_ISREG(mode) else oct(mode)
    return found


def _cli(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str]:
    try:
        status = real_main(argv)
    except SystemExit as exc:  # argparse
        status = exc.code if isinstance(exc.code, int) else 2
    out = capsys.readouterr()
    return status, out.out + out.err


@dataclass
class Case:
    """What a fault entry runs: argv built in ``tmp`` and the words its message must hold."""

    argv: list[str]
    out: Path
    words: tuple[str, ...]
    status: int = 2
    absent: tuple[str, ...] = ()
    inputs: list[Path] = field(default_factory=list)
    check: Callable[[Path], None] | None = None
    #: stands in for the reconstruct job in batch rows
    entry: Callable[[argparse.Namespace], int] | None = None
    #: stdout and stderr are pipes whose reader went away
    closed_streams: bool = False


def _meshes(folder: Path) -> tuple[Path, Path]:
    """A stand-in skull (ellipsoid, mm) and a skin 8 mm outside it."""
    bone = skull_mesh()
    centre = bone.vertices.mean(axis=0)
    skin = Mesh(centre + (bone.vertices - centre) * 1.09, bone.faces)
    return write_mesh(folder / "bone.ply", bone), write_mesh(folder / "skin.ply", skin)


def _validate(tmp: Path, rows: str, header: str = "id,skull,truth,units") -> Case:
    """A validate manifest four folders deep (an escaping id would land inside ``tmp``)."""
    deep = tmp / "a" / "b" / "c" / "d"
    deep.mkdir(parents=True)
    bone, skin = _meshes(deep)
    m = deep / "m.csv"
    m.write_text(f"{header}\n{rows}", encoding="utf-8")
    out = deep / "V"
    return Case(
        ["validate", str(m), "--out", str(out), "--no-pictures"], out, (), 2, (), [m, bone, skin]
    )


def validate_id(cell: str, *words: str) -> Callable[[Path], Case]:
    def build(tmp: Path) -> Case:
        case = _validate(tmp, f"{cell},bone.ply,skin.ply,mm\n")
        case.words = ("m.csv", "row 2", "id", "not a usable folder name", *words)
        case.check = lambda _t: None if case.out.exists() is False else pytest.fail("out made")
        return case

    return build


def validate_rows(rows: str, *words: str, header: str = "id,skull,truth,units") -> Callable:
    def build(tmp: Path) -> Case:
        case = _validate(tmp, rows, header)
        case.words = words
        return case

    return build


def truth_same_bytes(tmp: Path) -> Case:
    case = _validate(tmp, "c1,bone.ply,bone_copy.ply,mm\n")
    deep = case.inputs[0].parent
    shutil.copyfile(deep / "bone.ply", deep / "bone_copy.ply")
    case.inputs.append(deep / "bone_copy.ply")
    case.words = ("m.csv row 2 column truth", "bone_copy.ply is the skull bone.ply", "bytes")
    return case


def truth_on_bone(tmp: Path) -> Case:
    """A truth 0.3 mm outside the bone (another file, other bytes): the case fails."""
    case = _validate(tmp, "c1,bone.ply,onbone.ply,mm\n")
    deep = case.inputs[0].parent
    bone = skull_mesh()
    normals = (bone.vertices - bone.vertices.mean(axis=0)) / np.linalg.norm(
        bone.vertices - bone.vertices.mean(axis=0), axis=1, keepdims=True
    )
    write_mesh(deep / "onbone.ply", Mesh(bone.vertices + 0.3 * normals, bone.faces))
    case.inputs.append(deep / "onbone.ply")
    case.words = ("c1 [reconstruction]: failed", "onbone.ply", "lies on the skull")

    def check(_t: Path) -> None:
        with (case.out / "results.csv").open(encoding="utf-8", newline="") as fh:
            (row,) = list(csv.DictReader(fh))
        assert row["case"] == "c1" and row["status"] == "failed"

    case.check = check
    return case


def truth_other_frame(tmp: Path) -> Case:
    """The truth skin tagged SPACE=LPS beside an RAS skull: read turned 180 degrees about z, it
    no longer covers the skull, and the case fails naming the frames (not a garbage score)."""
    case = _validate(tmp, "c1,bone.ply,lps_skin.ply,mm\n")
    deep = case.inputs[0].parent
    bone = skull_mesh()
    centre = bone.vertices.mean(axis=0)
    skin = Mesh(centre + 1.1 * (bone.vertices - centre), bone.faces)
    write_mesh(deep / "lps_skin.ply", skin, space="LPS")  # numbers RAS, tag says LPS
    case.inputs.append(deep / "lps_skin.ply")
    case.words = ("c1 [reconstruction]: failed", "lps_skin.ply", "not in the same frame")
    return case


# ----------------------------------------------------------------------------- batch


def _batch(tmp: Path, rows: str, *extra: str, header: str = "id,job,input") -> Case:
    m = tmp / "m.csv"
    m.write_text(f"{header}\n{rows}", encoding="utf-8")
    out = tmp / "B"
    return Case(["batch", str(m), "--out", str(out), "--workers", "0", *extra], out, (), 2, (), [m])


def batch_id(cell: str, *words: str) -> Callable[[Path], Case]:
    def build(tmp: Path) -> Case:
        case = _batch(tmp, f"{cell},animate,reference:male\n")
        case.words = ("m.csv", "line 2", "not a usable folder name", "nothing was run", *words)
        case.check = lambda _t: None if not case.out.exists() else pytest.fail("out made")
        return case

    return build


def batch_duplicate_casefold(tmp: Path) -> Case:
    case = _batch(tmp, "Case1,animate,reference:male\ncase1,animate,reference:male\n")
    case.words = ("m.csv", "line 3", "used twice", "letter case")
    return case


def batch_out_column(tmp: Path) -> Case:
    case = _batch(tmp, "a,animate,reference:male,../../x.ply\n", header="id,job,input,out")
    case.words = ("m.csv", "line 2", "column out must be a bare file name", "../../x.ply")
    return case


def _fake_job(
    seen: list[str], interrupt_on: str | None = None
) -> Callable[[argparse.Namespace], int]:
    """Stands in for the reconstruct job in batch rows: writes the row's folder, or "presses
    Ctrl-C" on the row ``interrupt_on`` (it returns 130, as a command that saw Ctrl-C does)."""

    def entry(args: argparse.Namespace) -> int:
        out = Path(args.out)
        seen.append(out.name)
        if out.name == interrupt_on:
            out.mkdir(parents=True, exist_ok=True)
            (out / "half.txt").write_text("half", encoding="utf-8")
            return 130
        out.mkdir(parents=True, exist_ok=True)
        (out / "report.json").write_text("{}", encoding="utf-8")
        print("done")
        return 0

    return entry


def batch_interrupted(tmp: Path) -> Case:
    case = _batch(tmp, "r1,reconstruct,s.ply\nr2,reconstruct,s.ply\nr3,reconstruct,s.ply\n")
    (tmp / "s.ply").write_text("not read by the stand-in", encoding="utf-8")
    case.inputs.append(tmp / "s.ply")
    case.status = 130
    case.words = ("interrupted: 1 of 3 rows done", "rerun with --resume")
    case.absent = ("nothing was run",)
    seen: list[str] = []
    case.entry = _fake_job(seen, interrupt_on="r2")

    def check(_t: Path) -> None:
        assert seen == ["r1", "r2"]
        assert json.loads((case.out / "r1" / "batch_row.json").read_text())["status"] == "ok"
        assert not (case.out / "r2" / "batch_row.json").exists()
        # --resume: r1 is done, r2's unfinished folder is the batch's own (kept as r2.1)
        import workbench.cli.reconstruct_cmd as job

        again: list[str] = []
        with pytest.MonkeyPatch.context() as mp:
            mp.setattr(job, "run", _fake_job(again))
            assert real_main([*case.argv, "--resume"]) == 0
        assert again == ["r2", "r3"]
        assert (case.out / "r2.1" / "half.txt").is_file()
        assert (case.out / "summary.csv").is_file()

    case.check = check
    return case


def batch_stdout_closed(tmp: Path) -> Case:
    case = _batch(tmp, "r1,reconstruct,s.ply\nr2,reconstruct,s.ply\n")
    (tmp / "s.ply").write_text("x", encoding="utf-8")
    case.inputs.append(tmp / "s.ply")
    case.status = 0
    case.words = ()
    case.entry = _fake_job([])
    case.closed_streams = True

    def check(_t: Path) -> None:
        with (case.out / "summary.csv").open(encoding="utf-8", newline="") as fh:
            assert [r["status"] for r in csv.DictReader(fh)] == ["ok", "ok"]

    case.check = check
    return case


def batch_lock_held(tmp: Path) -> Case:
    import fcntl

    case = _batch(tmp, "r1,animate,reference:male\n")
    case.out.mkdir()
    lock = case.out / ".batch.lock"
    fd = os.open(lock, os.O_RDWR | os.O_CREAT)
    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    os.write(fd, json.dumps({"pid": 424242, "host": "elsewhere"}).encode())
    case.words = (str(case.out), "another batch is writing into this folder", "424242")

    def check(_t: Path) -> None:
        os.close(fd)
        assert sorted(p.name for p in case.out.iterdir()) == [".batch.lock"]

    case.check = check
    return case


def batch_lock_stale(tmp: Path) -> Case:
    """A lock file left by a process that died (no flock held): taken over, the batch runs."""
    case = _batch(tmp, "r1,reconstruct,s.ply\n")
    (tmp / "s.ply").write_text("x", encoding="utf-8")
    case.inputs.append(tmp / "s.ply")
    case.out.mkdir()
    stale = {"pid": 999_999_999, "host": socket.gethostname()}
    (case.out / ".batch.lock").write_text(json.dumps(stale), encoding="utf-8")
    case.status = 0
    case.argv.append("--resume")
    case.entry = _fake_job([])

    def check(_t: Path) -> None:
        assert (case.out / "summary.csv").is_file()
        assert not (case.out / ".batch.lock").exists()  # released

    case.check = check
    return case


def batch_foreign_folder(tmp: Path) -> Case:
    """A row folder the batch never started (no marker, no unfinished log) stays refused."""
    case = _batch(tmp, "r1,reconstruct,s.ply\n", "--resume")
    (tmp / "s.ply").write_text("x", encoding="utf-8")
    (case.out / "r1").mkdir(parents=True)
    mine = case.out / "r1" / "mine.txt"
    mine.write_text("the user's", encoding="utf-8")
    case.inputs += [tmp / "s.ply", mine]
    case.words = ("line 2", "is not a batch row's folder", "nothing was run")
    return case


# ----------------------------------------------------------------------------- outputs


def _fit_scan(tmp: Path, target: Path | str, *words: str) -> Case:
    s = sphere(3)
    skin = write_mesh(tmp / "skin.ply", Mesh(s.vertices * np.array([80.0, 100.0, 95.0]), s.faces))
    return Case(
        ["fit-scan", str(skin), "--units", "mm", "--force", "--out", str(target)],
        Path(target),
        (str(target), *words),
        2,
        ("use --force", "Traceback"),
        [skin],
    )


def out_fifo(tmp: Path) -> Case:
    os.mkfifo(tmp / "fifo")
    case = _fit_scan(tmp, tmp / "fifo", "FIFO", "not a regular file or folder")
    case.check = lambda t: None if stat.S_ISFIFO(os.lstat(t / "fifo").st_mode) else pytest.fail()
    return case


def out_link_to_fifo(tmp: Path) -> Case:
    os.mkfifo(tmp / "fifo")
    (tmp / "link").symlink_to(tmp / "fifo")
    return _fit_scan(tmp, tmp / "link", "a link to a FIFO")


def out_devnull(tmp: Path) -> Case:
    return _fit_scan(tmp, "/dev/null", "character device")


def out_mknod(tmp: Path) -> Case:
    try:
        os.mknod(tmp / "fakenull", 0o666 | stat.S_IFCHR, os.makedev(1, 3))
    except PermissionError:
        pytest.skip("mknod needs root (the FIFO entries cover the same rule)")
    case = _fit_scan(tmp, tmp / "fakenull", "character device")
    case.check = lambda t: None if stat.S_ISCHR(os.lstat(t / "fakenull").st_mode) else pytest.fail()
    return case


def out_inside_fifo(tmp: Path) -> Case:
    os.mkfifo(tmp / "fifo")
    return _fit_scan(tmp, tmp / "fifo" / "pack", "FIFO (named pipe), not a folder")


# ----------------------------------------------------------------------------- the corpus

ENTRIES = [
    pytest.param(validate_id("../../../../escaped", "path separator"), id="row1-id-dotdot"),
    pytest.param(validate_id("a/b", "path separator"), id="row1-id-slash"),
    pytest.param(validate_id("a\\b", "path separator"), id="row1-id-backslash"),
    pytest.param(validate_id("/tmp/abs", "absolute path"), id="row1-id-absolute"),
    pytest.param(validate_id(".", "names a folder"), id="row1-id-dot"),
    pytest.param(validate_id("..", "names a folder"), id="row1-id-dotdot-bare"),
    pytest.param(
        validate_id(".hidden", "start with a letter or a digit"), id="row1-id-leading-dot"
    ),
    pytest.param(validate_id('"a\x01b"', "control character"), id="row1-id-control-char"),
    pytest.param(validate_id('"a\tb"', "control character"), id="row1-id-tab"),
    pytest.param(validate_id("CON", "reserved by Windows"), id="row1-id-windows-con"),
    pytest.param(validate_id("nul.txt", "reserved by Windows"), id="row1-id-windows-nul-ext"),
    pytest.param(validate_id("a" * 101, "101 characters"), id="row1-id-too-long"),
    pytest.param(validate_id("case.", "ends with a dot"), id="row1-id-trailing-dot"),
    pytest.param(validate_id("\"=cmd|' /C calc'!A0\"", "'='"), id="row1-id-formula"),
    pytest.param(validate_id("results.csv", "writes a file or folder"), id="row1-id-reserved"),
    pytest.param(validate_id("Résumé", "'é'"), id="row1-id-non-ascii"),
    pytest.param(
        validate_rows(",bone.ply,skin.ply,mm\n", "m.csv row 2", "has no id"), id="row1-id-empty"
    ),
    pytest.param(
        validate_rows(
            "Case1,bone.ply,skin.ply,mm\ncase1,bone.ply,skin.ply,mm\n",
            "m.csv",
            "row 3",
            "used twice",
            "letter case",
        ),
        id="row2-id-casefold-duplicate",
    ),
    pytest.param(
        validate_rows(
            "c1,bone.ply,skin.ply,mm,../../x\n",
            "m.csv row 2 column subject",
            "../../x",
            "path separator",
            header="id,skull,truth,units,subject",
        ),
        id="row1-subject-dotdot",
    ),
    pytest.param(
        validate_rows(
            "c1,bone.ply,bone.ply,mm\n", "m.csv row 2 column truth", "is the skull", "same file"
        ),
        id="row1-truth-is-skull-file",
    ),
    pytest.param(truth_same_bytes, id="row1-truth-is-skull-bytes"),
    pytest.param(truth_on_bone, id="row1-truth-on-bone"),
    pytest.param(truth_other_frame, id="slicer-truth-skin-in-other-frame"),
    pytest.param(batch_id("../../escaped", "path separator"), id="batch-row1-id-dotdot"),
    pytest.param(batch_id("a/b", "path separator"), id="batch-row1-id-slash"),
    pytest.param(batch_id("\"=cmd|' /C calc'!A0\"", "'='"), id="batch-row1-id-formula"),
    pytest.param(batch_id("aux", "reserved by Windows"), id="batch-row1-id-windows-aux"),
    pytest.param(batch_id("logs", "writes a file or folder"), id="batch-row1-id-reserved"),
    pytest.param(batch_duplicate_casefold, id="batch-row2-id-casefold-duplicate"),
    pytest.param(batch_out_column, id="batch-row1-out-column-dotdot"),
    pytest.param(batch_foreign_folder, id="batch-resume-foreign-folder"),
    pytest.param(batch_interrupted, id="batch-interrupt-resume"),
    pytest.param(batch_stdout_closed, id="batch-streams-closed"),
    pytest.param(batch_lock_held, id="batch-lock-held"),
    pytest.param(batch_lock_stale, id="batch-lock-stale"),
    pytest.param(out_fifo, id="out-fifo-force"),
    pytest.param(out_link_to_fifo, id="out-link-to-fifo"),
    pytest.param(out_devnull, id="out-dev-null"),
    pytest.param(out_mknod, id="out-char-device-force"),
    pytest.param(out_inside_fifo, id="out-under-fifo"),
]


class _Closed:
    """A stream whose reader went away."""

    def write(self, _text: str) -> int:
        raise BrokenPipeError(32, "Broken pipe")

    def flush(self) -> None:
        raise BrokenPipeError(32, "Broken pipe")

    def fileno(self) -> int:
        raise ValueError("no descriptor")


@pytest.mark.parametrize("build", ENTRIES)
def test_fault(build, tmp_path, capsys, monkeypatch):
    case = build(tmp_path)
    if case.entry is not None:  # the batch's rows run this instead of the reconstruct job
        import workbench.cli.reconstruct_cmd as job

        monkeypatch.setattr(job, "run", case.entry)
    if case.closed_streams:
        monkeypatch.setattr(sys, "stdout", _Closed())
        monkeypatch.setattr(sys, "stderr", _Closed())
    before = {p: _sha(p) for p in case.inputs}
    around = _snapshot(tmp_path, case.out)
    status, text = _cli(case.argv, capsys)
    assert status == case.status, text
    for word in case.words:
        assert word in text, (word, text)
    for word in ("Traceback", "unexpected error", *case.absent):
        assert word not in text, text
    assert {p: _sha(p) for p in case.inputs} == before
    assert _snapshot(tmp_path, case.out) == around, "written outside --out"
    if case.check is not None:
        case.check(tmp_path)


# ----------------------------------------------------------------------------- the writers


@pytest.mark.parametrize(
    ("cell", "expected"),
    [
        pytest.param("=cmd|' /C calc'!A0", "'=cmd|' /C calc'!A0", id="csv-cell-equals"),
        pytest.param("+1+2", "'+1+2", id="csv-cell-plus-formula"),
        pytest.param("-2+3", "'-2+3", id="csv-cell-minus-formula"),
        pytest.param("@SUM(A1)", "'@SUM(A1)", id="csv-cell-at"),
        pytest.param("\tx", "'\tx", id="csv-cell-tab"),
        pytest.param("\rx", "'\rx", id="csv-cell-cr"),
        pytest.param("-1.5", "-1.5", id="csv-cell-negative-number-text"),
        pytest.param(-1.5, -1.5, id="csv-cell-negative-float"),
        pytest.param(-3, -3, id="csv-cell-negative-int"),
        pytest.param("case 1", "case 1", id="csv-cell-plain"),
        pytest.param("", "", id="csv-cell-empty"),
        pytest.param(None, None, id="csv-cell-none"),
    ],
)
def test_csv_cell(cell, expected):
    from workbench.core.table_cells import csv_cell, csv_row

    assert csv_cell(cell) == expected
    assert csv_row({"a": cell}) == {"a": expected}


@pytest.mark.parametrize(
    ("cell", "expected"),
    [
        pytest.param("a|b", "a\\|b", id="md-cell-pipe"),
        pytest.param("a\nb\r\nc", "a b c", id="md-cell-newlines"),
        pytest.param(None, "", id="md-cell-none"),
    ],
)
def test_md_cell(cell, expected):
    from workbench.core.table_cells import md_cell

    assert md_cell(cell) == expected


def test_validate_tables_guard_user_text(tmp_path):
    """The validate table writers guard every cell themselves (a failed case's message can
    hold user text at its start)."""
    from workbench.reporting.validation_report import markdown, rows, write_csv
    from workbench.services.validation.run import CaseResult

    res = CaseResult("c1", "failed", "=HYPERLINK(x)|row\nbreak")
    write_csv(rows([(res, "reconstruction")], ()), tmp_path / "r.csv")
    with (tmp_path / "r.csv").open(encoding="utf-8", newline="") as fh:
        (row,) = list(csv.DictReader(fh))
    assert row["error"].startswith("'=")
    md = markdown([(res, "reconstruction")], ())
    line = next(ln for ln in md.splitlines() if ln.startswith("| c1 |"))
    assert "\\|row break" in line
    assert len(re.findall(r"(?<!\\)\|", line)) == 11  # the table's 10 columns, unbroken


def test_batch_summary_guards_user_text(tmp_path):
    """The batch summary writers guard ids and messages themselves (CSV formulas, Markdown rows)."""
    from workbench.reporting.batch_report import markdown, write_csv

    rec = {
        "id": "r1",
        "job": "reconstruct",
        "line": 2,
        "status": "failed",
        "resumed": False,
        "exit_status": 1,
        "seconds": 1.0,
        "message": "@SUM(A1)|x\nnext",
        "figures": {},
    }
    write_csv([rec], tmp_path / "s.csv")
    with (tmp_path / "s.csv").open(encoding="utf-8", newline="") as fh:
        (row,) = list(csv.DictReader(fh))
    assert row["message"].startswith("'@")
    md = markdown([rec], {"manifest": "m.csv"})
    (item,) = [ln for ln in md.splitlines() if ln.startswith("- line 2")]
    assert item.endswith("@SUM(A1)\\|x next")
