"""workbench batch, the service: manifest rows -> argv, manifest errors, the in-process run,
resume and the output-folder rules (real animate jobs on the reference head)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from workbench.cli.batch_cmd import commands
from workbench.cli.main import main
from workbench.core.errors import InputError
from workbench.pipelines.batch.manifest import read_batch_manifest
from workbench.pipelines.batch.run import (
    MARKER,
    error_line,
    file_digest,
    read_marker,
    run_batch,
)


@pytest.fixture(scope="module")
def parsers():
    return {k: v for k, v in commands().items() if k != "batch"}


def _write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def test_rows_become_the_single_commands_argv(tmp_path, parsers):
    (tmp_path / "skull.ply").write_text("not read here", encoding="utf-8")
    (tmp_path / "lm.mrk.json").write_text("{}", encoding="utf-8")
    m = _write(
        tmp_path / "m.csv",
        "id,job,input,sex,no_pictures,template,landmarks,ensemble,expression,jaw,out,#notes\n"
        ",,,,,,,,,,,\n"
        "# a comment line\n"
        "r1,reconstruct,skull.ply,male,true,a;b,lm.mrk.json,3,,,,my own note\n"
        "r2,reconstruct,sample:skull,,false,,,,,,,\n"
        "a1,animate,reference:male,,,,,,smile,5,,\n"
        "a2,animate,reference:female,,,,,,,,open.glb,\n",
    )
    out = tmp_path / "out"
    rows = {r.row_id: r for r in read_batch_manifest(m, out, parsers)}
    skull, lm = str((tmp_path / "skull.ply").resolve()), str((tmp_path / "lm.mrk.json").resolve())
    assert rows["r1"].line == 4 and rows["r1"].error is None
    assert rows["r1"].argv == [
        "reconstruct", skull, "--sex", "male", "--no-pictures", "--template", str((tmp_path / "a").resolve()),
        "--template", str((tmp_path / "b").resolve()), "--landmarks", lm, "--ensemble", "3", "--out", str(out / "r1"),
    ]  # fmt: skip
    assert rows["r2"].argv == ["reconstruct", "sample:skull", "--out", str(out / "r2")]
    assert rows["a1"].argv == [
        "animate", "reference:male", "--expression", "smile", "--jaw", "5",
        "--out", str(out / "a1" / "skin.ply"),
    ]  # fmt: skip
    assert rows["a2"].argv[-1] == str(out / "a2" / "open.glb")


def test_manifest_errors_name_every_line_before_anything_runs(tmp_path, parsers):
    m = _write(
        tmp_path / "m.csv",
        "id,job,input,colour,out,force,no-pictures\n"
        "a,animate,reference:male,,,,\n"
        "a,animate,reference:male,,,,\n"
        "b,paint,x.ply,,,,\n"
        "c,reconstruct,x.ply,red,,,\n"
        "d,reconstruct,x.ply,,elsewhere,,\n"
        "e,reconstruct,x.ply,,,true,\n"
        "f,reconstruct,,,,,\n"
        "../g,reconstruct,x.ply,,,,\n"
        "h,animate,reference:male,,sub/x.ply,,\n"
        "i,reconstruct,x.ply,,,,maybe\n",
    )
    with pytest.raises(InputError) as err:
        read_batch_manifest(m, tmp_path / "out", parsers)
    text = str(err.value)
    for expected in (
        "line 1: column colour is no option of any job",
        "line 3: id a is used twice (first on line 2)",
        "line 4: job 'paint' is not one of",
        "line 5: reconstruct has no option --colour",
        "line 6: column out is set by the batch",
        "line 7: column force is set by the batch",
        "line 8: no input",
        "line 9: id '../g' is not a usable folder name",
        "line 10: column out must be a bare file name",
        "line 11: column no-pictures is a flag",
    ):
        assert expected in text
    assert not (tmp_path / "out").exists()
    with pytest.raises(InputError, match="no column job"):
        read_batch_manifest(_write(tmp_path / "h.csv", "id,input\n"), tmp_path / "o", parsers)
    # a value argparse refuses is kept with its row, which is recorded as failed, not run
    bad = _write(tmp_path / "v.csv", "id,job,input,sex\nx,reconstruct,a.ply,fmale\n")
    (row,) = read_batch_manifest(bad, tmp_path / "o", parsers)
    assert "invalid choice: 'fmale'" in (row.error or "")


def test_error_line_is_the_commands_own_message():
    err = "    loading ...\nworkbench animate: error: x: bad\n"
    assert error_line(err, 2) == "workbench animate: error: x: bad"
    assert error_line("", 2, "  c1 [reconstruction]: failed: no bone\n") == (
        "c1 [reconstruction]: failed: no bone"
    )
    assert error_line("", 3) == "exit status 3"


def test_folder_digest_changes_with_any_file(tmp_path):
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "a.txt").write_text("a", encoding="utf-8")
    before = file_digest(tmp_path / "d")
    (tmp_path / "d" / "b.txt").write_text("", encoding="utf-8")
    assert file_digest(tmp_path / "d") != before


def _run(manifest: Path, out: Path, parsers, resume: bool = False, lines: list | None = None):
    return run_batch(
        manifest,
        out,
        commands=parsers,
        workers=0,
        resume=resume,
        notify=(lines.append if lines is not None else None),
    )


@pytest.mark.slow
def test_in_process_rows_equal_single_runs_and_bad_rows_go_on(tmp_path, parsers, head_male):
    m = _write(
        tmp_path / "m.csv",
        "id,job,input,expression,muscle,units\n"
        "smile,animate,reference:male,smile,,\n"
        "absurd,animate,reference:male,,mentalis=7,\n"
        "missing,reconstruct,no_such_skull.ply,,,mm\n",
    )
    out = tmp_path / "out"
    lines: list[str] = []
    results = _run(m, out, parsers, lines=lines)
    by = {r.row.row_id: r for r in results}
    assert [r.row.row_id for r in results] == ["smile", "absurd", "missing"]
    assert by["smile"].status == "ok" and by["smile"].figures["vertices"] > 1000
    assert by["smile"].figures["largest_movement_mm"] > 1.0
    assert by["absurd"].status == "failed" and by["absurd"].exit_status == 2
    assert "mentalis" in by["absurd"].message and "between 0" in by["absurd"].message
    assert by["missing"].status == "failed" and "no_such_skull.ply" in by["missing"].message
    assert len(lines) == 3 and all("/3 " in ln for ln in lines)
    # the batch row's file is byte for byte the single command's
    single = tmp_path / "single.ply"
    assert main(["animate", "reference:male", "--expression", "smile", "--out", str(single)]) == 0
    assert (out / "smile" / "skin.ply").read_bytes() == single.read_bytes()
    marker = read_marker(out / "smile")
    assert marker is not None and marker["status"] == "ok" and marker["argv"][0] == "animate"
    assert marker["figures"] == by["smile"].figures
    failed = json.loads((out / "missing" / MARKER).read_text(encoding="utf-8"))
    assert failed["status"] == "failed" and failed["exit_status"] == 2
    assert "no_such_skull.ply" in (out / "logs" / "missing.log").read_text(encoding="utf-8")


@pytest.mark.slow
def test_resume_skips_finished_rows_and_reruns_changed_inputs(tmp_path, parsers, head_male):
    from workbench.io.template_pack import export_template

    pack = tmp_path / "pack"
    export_template(head_male, pack)
    m = _write(
        tmp_path / "m.csv",
        f"id,job,input,jaw,muscle\nopen,animate,{pack},8,\nbad,animate,reference:male,,mentalis=2\n",
    )
    out = tmp_path / "out"
    first = _run(m, out, parsers)
    assert [r.status for r in first] == ["ok", "failed"]
    digest = first[0].inputs[str(pack)]
    assert digest == file_digest(pack)
    with pytest.raises(InputError, match="not empty.*--resume"):
        _run(m, out, parsers)
    lines: list[str] = []
    again = _run(m, out, parsers, resume=True, lines=lines)
    assert again[0].resumed and again[0].figures == first[0].figures
    assert not again[1].resumed and again[1].status == "failed"  # a failed row runs again
    assert any("open (animate): ok (resumed)" in ln for ln in lines)
    # an input changed: that row runs again, its old folder is kept as DIR/<id>.1
    (pack / "notes.txt").write_text("changed", encoding="utf-8")
    third = _run(m, out, parsers, resume=True)
    assert not third[0].resumed and third[0].status == "ok"
    assert third[0].inputs[str(pack)] != digest
    assert (out / "open.1" / "skin.ply").is_file() and (out / "open" / "skin.ply").is_file()
    # a folder the batch did not make is never written over
    (out / "bad").rename(tmp_path / "elsewhere")
    (out / "bad").mkdir()
    (out / "bad" / "mine.txt").write_text("user's", encoding="utf-8")
    with pytest.raises(InputError, match="not a batch row's folder"):
        _run(m, out, parsers, resume=True)
    assert (out / "bad" / "mine.txt").read_text(encoding="utf-8") == "user's"


def test_inputs_inside_the_batch_folder_are_refused(tmp_path, parsers):
    out = tmp_path / "out"
    (out / "in").mkdir(parents=True)
    skull = out / "in" / "skull.ply"
    skull.write_text("x", encoding="utf-8")
    m = _write(tmp_path / "m.csv", f"id,job,input\nr,reconstruct,{skull}\n")
    with pytest.raises(InputError, match="reads .*skull.ply inside it"):
        _run(m, out, parsers, resume=True)
    assert skull.read_text(encoding="utf-8") == "x" and not (out / "r").exists()


@pytest.mark.slow
def test_age_rows_give_growth_figures_and_curves(tmp_path, parsers, head_male):
    from workbench.pipelines.batch.run import summary_record
    from workbench.reporting.batch_report import write_summary

    age = {"age": parsers["age"]}
    m = _write(
        tmp_path / "m.csv",
        'id,job,input,sex,from,ages,no-pdf\ngrow,age,reference:male,male,30,"8,16",true\n'
        "old,age,reference:male,male,30,200,true\n",
    )
    out = tmp_path / "out"
    grow, old = run_batch(m, out, commands=age, workers=0)
    assert old.status == "failed" and "200" in old.message
    assert grow.status == "ok", grow.message
    f = grow.figures
    assert f["head_circumference_mm_after_8y"] < f["head_circumference_mm_after_16y"]
    assert f["head_circumference_mm_after_16y"] < f["head_circumference_mm_before"] + 1.0
    assert {"head_circumference_mm_target_8y", "z_change_max_16y"} <= set(f)
    written = write_summary([summary_record(grow), summary_record(old)], out, {"manifest": "m"})
    assert out / "plots" / "age_growth.png" in written


def test_a_row_whose_registration_asks_for_a_check_is_done_but_flagged(
    tmp_path, parsers, monkeypatch
):
    """Exit status 3 (outputs written, the skull registration in doubt): the row is "check",
    its CHECK reason is its message, a resumed batch does not run it again, the summary
    lists it apart from failures and the batch command exits 3 (issue 28)."""
    import workbench.cli.reconstruct_cmd as cmd
    from workbench.pipelines.batch.run import summary_record
    from workbench.reporting.batch_report import counts, markdown

    reason = "only 62 % of the reference's facial skeleton lies on bone"
    ran: list[Path] = []

    def fake_execute(skull, settings, out, **_kw):
        ran.append(out)
        out.mkdir(parents=True, exist_ok=True)
        cmd.print_self_check({"outcome": "check", "reasons": [reason]})
        return {"self_check": {"outcome": "check", "reasons": [reason]}}

    monkeypatch.setattr(cmd, "execute", fake_execute)
    skull = _write(tmp_path / "skull.ply", "not read: execute is replaced\n")
    m = _write(tmp_path / "m.csv", f"id,job,input,units\ndoubt,reconstruct,{skull},mm\n")
    out = tmp_path / "out"
    (row,) = _run(m, out, parsers)
    assert row.status == "check" and row.exit_status == 3
    assert row.message == f"CHECK: {reason}"
    assert read_marker(out / "doubt")["status"] == "check"
    (again,) = _run(m, out, parsers, resume=True)
    assert again.resumed and again.status == "check" and len(ran) == 1
    records = [summary_record(row)]
    assert counts(records) == {"rows": 1, "ok": 0, "check": 1, "failed": 0, "resumed": 0}
    text = markdown(records, {"manifest": str(m)})
    assert "1 to check" in text and "## Rows to check" in text and "## Failed rows" not in text
    code = main(["batch", str(m), "--out", str(tmp_path / "out2"), "--workers", "0"])
    assert code == 3 and len(ran) == 2
