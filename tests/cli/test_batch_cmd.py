"""``workbench batch``: a LocalCluster of two worker processes, the summary files, a validate
row's figures and plots, and the command's own refusals."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from workbench.cli.main import main


def _rows(path: Path) -> dict[str, dict[str, str]]:
    with path.open(encoding="utf-8", newline="") as fh:
        return {r["id"]: r for r in csv.DictReader(fh)}


def test_batch_refusals_are_one_line_errors(tmp_path, capsys):
    m = tmp_path / "m.csv"
    m.write_text("id,job,input,colour\na,animate,reference:male,red\n", encoding="utf-8")
    out = tmp_path / "out"
    assert main(["batch", str(m), "--out", str(out), "--workers", "0"]) == 2
    err = capsys.readouterr().err
    assert "line 2: animate has no option --colour" in err and "nothing was run" in err
    assert not out.exists()
    args = ["batch", str(m), "--out", str(out)]
    assert main([*args, "--scheduler", "tcp://127.0.0.1:8786", "--workers", "2"]) == 2
    assert "--workers and --memory-limit are for the local cluster" in capsys.readouterr().err
    assert main([*args, "--memory-limit", "lots"]) == 2
    assert "is not a size" in capsys.readouterr().err
    assert main([*args, "--memory-limit", "10MB"]) == 2
    assert "too small" in capsys.readouterr().err


def test_a_failing_validate_row_is_recorded_and_summarised(tmp_path, capsys):
    cases = tmp_path / "cases.csv"
    cases.write_text("id,skull,truth\nc1,gone.ply,gone.ply\n", encoding="utf-8")
    m = tmp_path / "m.csv"
    m.write_text("id,job,input,no-pictures\nv,validate,cases.csv,true\n", encoding="utf-8")
    out = tmp_path / "out"
    assert main(["batch", str(m), "--out", str(out), "--workers", "0"]) == 2
    row = _rows(out / "summary.csv")["v"]
    assert row["status"] == "failed" and row["exit_status"] == "2" and row["line"] == "2"
    assert "gone.ply" in row["message"] and "workbench validate: error:" in row["message"]
    assert "1/1 v (validate): failed" in capsys.readouterr().err
    md = (out / "summary.md").read_text(encoding="utf-8")
    assert "## Failed rows" in md and "line 2, v (validate)" in md
    assert (out / "summary.pdf").read_bytes()[:5] == b"%PDF-"


@pytest.mark.slow
def test_local_cluster_rows_equal_single_runs(tmp_path, skull_obj, head_male, capsys):
    from pypdf import PdfReader

    m = tmp_path / "manifest.csv"
    m.write_text(
        "id,job,input,scale,anterior,superior,no-pictures,expression,muscle,units\n"
        f'rec,reconstruct,{skull_obj},15,"0,0,1","0,1,0",true,,,\n'
        "smile,animate,reference:male,,,,,smile,,\n"
        "absurd,animate,reference:male,,,,,,mentalis=7,\n"
        "missing,reconstruct,nothing.ply,,,,,,,mm\n",
        encoding="utf-8",
    )
    out = tmp_path / "out"
    import os

    threads_before = {k: os.environ.get(k) for k in ("OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    assert main(["batch", str(m), "--out", str(out), "--workers", "2"]) == 2
    # the workers' one-thread environment stays theirs (distributed's nanny writes it into
    # the parent's os.environ: this process's own loops would drop to one thread)
    assert {k: os.environ.get(k) for k in threads_before} == threads_before
    err = capsys.readouterr().err
    assert "4/4" in err and "smile (animate): ok" in err and "absurd (animate): failed" in err
    rows = _rows(out / "summary.csv")
    assert [rows[k]["status"] for k in ("rec", "smile", "absurd", "missing")] == [
        "ok",
        "ok",
        "failed",
        "failed",
    ]
    assert "between 0" in rows["absurd"]["message"]
    # the same command run alone, in this process
    single = tmp_path / "single"
    argv = ["reconstruct", str(skull_obj), "--scale", "15", "--anterior", "0,0,1"]
    assert main([*argv, "--superior", "0,1,0", "--no-pictures", "--out", str(single)]) == 0
    alone = tmp_path / "smile.ply"
    assert main(["animate", "reference:male", "--expression", "smile", "--out", str(alone)]) == 0
    assert (out / "smile" / "skin.ply").read_bytes() == alone.read_bytes()
    files = [p.relative_to(single) for p in single.rglob("*") if p.is_file()]
    assert len(files) > 10
    from workbench.io.meshes import read_mesh

    for rel in files:
        if rel.name in ("report.json", "report.pdf", "case.fcase"):  # they hold the time
            continue
        if rel.suffix == ".ply":
            # a worker runs with one thread, this process with several: BLAS may sum in
            # another order, so meshes agree to the last few bits, not byte for byte
            a = read_mesh(out / "rec" / rel, units="mm").mesh
            b = read_mesh(single / rel, units="mm").mesh
            assert np.array_equal(a.faces, b.faces), rel
            assert np.abs(a.vertices - b.vertices).max() < 1e-9, rel
            continue
        if rel.suffix == ".json":  # numbers to the last bits; the meshes' hashes differ then
            ja = json.loads((out / "rec" / rel).read_text(encoding="utf-8"))
            jb = json.loads((single / rel).read_text(encoding="utf-8"))
            assert _same(ja, jb), rel
            continue
        assert (out / "rec" / rel).read_bytes() == (single / rel).read_bytes(), rel
    from workbench.pipelines.batch.figures import reconstruct_figures

    figures = reconstruct_figures(json.loads((single / "report.json").read_text(encoding="utf-8")))
    assert figures["max_tip_error_mm"] > 0
    for key, value in figures.items():
        assert float(rows["rec"][key]) == pytest.approx(value), key
    text = "".join(page.extract_text() for page in PdfReader(out / "summary.pdf").pages)
    assert "Batch study" in text and "Dask LocalCluster" in text and "absurd" in text
    assert (out / "plots" / "seconds.png").is_file()


@pytest.mark.slow
def test_validate_row_figures_and_plots(tmp_path, head_female):
    from workbench.io.meshes import write_mesh
    from workbench.services.templates.reference_parts import skull_surface

    write_mesh(tmp_path / "skull.ply", skull_surface(head_female))
    write_mesh(tmp_path / "skin.ply", head_female.skin)
    (tmp_path / "cases.csv").write_text(
        'id,skull,truth,units,anterior,superior,sex\nf,skull.ply,skin.ply,mm,"0,0,1","0,1,0",male\n',
        encoding="utf-8",
    )
    m = tmp_path / "m.csv"
    m.write_text("id,job,input,no-pictures\nval,validate,cases.csv,true\n", encoding="utf-8")
    out = tmp_path / "out"
    assert main(["batch", str(m), "--out", str(out), "--workers", "0"]) == 0
    with (out / "val" / "results.csv").open(encoding="utf-8", newline="") as fh:
        results = {r["method"]: r for r in csv.DictReader(fh)}
    row = _rows(out / "summary.csv")["val"]
    for method in ("reconstruction", "uniform_6mm_offset"):
        for key in ("pct_within_2_5mm", "mean_abs_mm"):
            assert float(row[f"{method}_{key}"]) == pytest.approx(float(results[method][key]))
    assert float(row["reconstruction_pct_within_2_5mm"]) > float(
        row["uniform_6mm_offset_pct_within_2_5mm"]
    )
    for name in ("seconds", "validate_error_distribution", "validate_regions"):
        assert (out / "plots" / f"{name}.png").stat().st_size > 1000
    assert "validate_regions.png" in (out / "summary.md").read_text(encoding="utf-8")


@pytest.mark.slow
def test_a_job_over_the_memory_limit_is_a_failed_row(tmp_path, skull_obj, capsys):
    m = tmp_path / "m.csv"
    m.write_text(
        "id,job,input,scale,anterior,superior,no-pictures\n"
        f'big,reconstruct,{skull_obj},15,"0,0,1","0,1,0",true\n',
        encoding="utf-8",
    )
    out = tmp_path / "out"
    args = ["batch", str(m), "--out", str(out), "--workers", "1", "--memory-limit", "300MB"]
    assert main(args) == 2
    row = _rows(out / "summary.csv")["big"]
    assert row["status"] == "failed" and row["exit_status"] == ""
    assert "the worker running it died (over its memory limit of 300MB" in row["message"]
    assert "KilledWorker" in (out / "logs" / "big.log").read_text(encoding="utf-8")
    assert "1/1 big (reconstruct): failed" in capsys.readouterr().err


def _same(a, b) -> bool:
    """JSON values equal, floats within 1e-9, content hashes (sha256 hex) not compared."""
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(
            "hash" in k or "sha256" in k or _same(a[k], b[k]) for k in a
        )
    if isinstance(a, list) and isinstance(b, list):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) or isinstance(b, float):
        return abs(float(a) - float(b)) < 1e-9
    return a == b


def test_fit_scan_row_figures_take_the_skull_and_baseline_scalars():
    """A fit-scan case's row: its report's scalars, skull vs bone and the uniform baseline."""
    from workbench.pipelines.batch.figures import fit_scan_figures

    report = {
        "face_within_1mm_fraction": 0.97,
        "skull_vs_bone": {
            "mean_abs_mm": 6.6,
            "within_2_5mm_fraction": 0.275,
            "uniform_offset_baseline": {"depth_mm": 6.0, "mean_abs_mm": 11.8},
        },
    }
    row = fit_scan_figures(report)
    assert row["skull_vs_bone_mean_abs_mm"] == 6.6
    assert row["skull_vs_bone_baseline_mean_abs_mm"] == 11.8
    assert row["skull_vs_bone_baseline_depth_mm"] == 6.0
