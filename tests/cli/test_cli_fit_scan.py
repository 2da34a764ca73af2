"""``workbench fit-scan`` end to end: a damaged skin in cm, bad scans, an existing pack."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tests.services._scans import damaged_skin
from workbench.cli.main import main
from workbench.core.mesh import Mesh
from workbench.io.meshes import write_mesh
from workbench.io.template_pack import load_template_pack


@pytest.fixture(scope="module")
def scan_cm(tmp_path_factory: pytest.TempPathFactory, head_female) -> Path:
    scan, _ = damaged_skin(head_female)
    folder = tmp_path_factory.mktemp("cli-fit-scan")
    return write_mesh(folder / "face_cm.ply", Mesh(scan.vertices / 10.0, scan.faces))


@pytest.fixture(scope="module")
def fitted(scan_cm: Path, head_male) -> tuple[int, Path]:
    out = scan_cm.parent / "pack"
    code = main(["fit-scan", str(scan_cm), "--units", "cm", "--sex", "male", "--out", str(out)])
    return code, out


def test_fit_scan_writes_a_pack_and_its_report(fitted, head_male):
    code, out = fitted
    assert code == 0
    report = json.loads((out / "fit_report.json").read_text())
    assert report["face_within_1mm_fraction"] >= 0.95
    assert report["fold_overs"] == 0
    assert report["tissue_depths"]["mean_abs_diff_mm"] < 1.0
    head = load_template_pack(out)
    assert head.skin.n_vertices == head_male.skin.n_vertices
    assert len(head.muscles) == len(head_male.muscles)
    assert head.provenance["built_from"][0]["file"] == "face_cm.ply"
    # the person's size in mm (the female skin, not the male reference, not cm)
    assert 150 < float(np.ptp(head.skin.vertices[:, 1])) < 320
    # the fine detail over the subdivided skin, in the same frame
    assert report["detail"]["new_crossings"] == 0 and report["detail"]["fold_overs"] == 0
    from workbench.io.meshes import read_mesh
    from workbench.io.skin_detail_export import read_skin_detail

    detailed = read_mesh(out / "skin_detailed.ply", units="mm").mesh
    layer = read_skin_detail(out / "skin_detail.npz", head.skin)
    np.testing.assert_allclose(
        detailed.vertices, layer.apply(head.skin.vertices).vertices, atol=1e-3
    )


def test_existing_pack_is_refused_without_force(fitted, scan_cm, capsys):
    _, out = fitted
    before = (out / "fit_report.json").read_bytes()
    code = main(["fit-scan", str(scan_cm), "--units", "cm", "--out", str(out)])
    assert code != 0
    assert str(out.name) in capsys.readouterr().err
    assert (out / "fit_report.json").read_bytes() == before


def test_cm_scan_without_units_is_refused(scan_cm, capsys):
    code = main(["fit-scan", str(scan_cm), "--out", str(scan_cm.parent / "other")])
    assert code != 0
    assert "face_cm.ply" in capsys.readouterr().err


def test_point_cloud_and_few_triangles_are_refused_by_name(tmp_path: Path, capsys):
    rng = np.random.default_rng(0)
    cloud = tmp_path / "cloud.ply"
    write_mesh(cloud, Mesh(rng.random((2000, 3)) * 180.0))
    few = tmp_path / "few.ply"
    write_mesh(few, Mesh(rng.random((300, 3)) * 180.0, np.arange(600).reshape(200, 3) % 300))
    for path, words in ((cloud, "cloud.ply"), (few, "few.ply")):
        code = main(["fit-scan", str(path), "--out", str(tmp_path / f"out_{path.stem}")])
        err = capsys.readouterr().err
        assert code != 0
        assert words in err, err
    assert "200 triangles" in err


def test_fit_scan_writes_the_pdf_with_its_distance_maps(fitted):
    import pypdf

    code, out = fitted
    assert code == 0
    pdf = out / "fit_report.pdf"
    assert pdf.read_bytes().startswith(b"%PDF")
    for name in ("scan_distance.png", "scan_signed_distance.png", "distance_histogram.png"):
        assert (out / "pictures" / name).stat().st_size > 10_000, name
    reader = pypdf.PdfReader(pdf)
    text = " ".join(" ".join(page.extract_text().split()) for page in reader.pages)
    report = json.loads((out / "fit_report.json").read_text())
    assert "face_cm.ply" in text
    assert f"{100 * report['face_within_1mm_fraction']:.1f} %" in text
    assert report["tissue_depths"]["table"] in text
    assert sum(len(page.images) for page in reader.pages) == 3


def test_fit_scan_pdf_without_opengl_has_no_pictures(scan_cm, monkeypatch, capsys):
    from workbench.render import scan_fit_pictures

    def no_gl(*_a, **_k):
        raise RuntimeError("no OpenGL context")

    monkeypatch.setattr(scan_fit_pictures, "render_distance_views", no_gl)
    out = scan_cm.parent / "pack_no_gl"
    code = main(["fit-scan", str(scan_cm), "--units", "cm", "--no-detail", "--out", str(out)])
    assert code == 0
    assert not (out / "skin_detailed.ply").exists()  # --no-detail
    assert "detail" not in json.loads((out / "fit_report.json").read_text())
    printed = capsys.readouterr().out
    assert "no distance picture (no OpenGL context)" in printed
    assert f"wrote {out / 'fit_report.pdf'}" in printed
    assert (out / "pictures" / "distance_histogram.png").is_file()
    assert not (out / "pictures" / "scan_distance.png").exists()
    import pypdf

    text = " ".join(p.extract_text() for p in pypdf.PdfReader(out / "fit_report.pdf").pages)
    assert "no OpenGL context" in text


def test_texture_without_uvs_is_refused_before_the_fit(scan_cm, tmp_path: Path, capsys):
    from PIL import Image

    image = tmp_path / "skin.png"
    Image.new("RGB", (8, 8), (200, 150, 120)).save(image)
    code = main(
        [
            "fit-scan",
            str(scan_cm),
            "--units",
            "cm",
            "--texture",
            str(image),
            "--out",
            str(tmp_path / "pack"),
        ]
    )
    err = capsys.readouterr().err
    assert code != 0
    assert scan_cm.name in err and "texture coordinates" in err and "Traceback" not in err
    assert not (tmp_path / "pack").exists()
