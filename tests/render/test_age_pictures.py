"""Pictures of an age change: source and aged head at one scale, and the growth map.

Real data: the built-in male head aged 18 -> 3 y with the shipped norms
(each head in its Frankfort frame, mm).  Pictures are small to keep the
module fast; panels are cut out of the PNG by their known pixel width.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from workbench.render.age_pictures import (
    colour_limit,
    growth_distance,
    render_age_pictures,
    render_compare,
    render_growth_map,
)
from workbench.services.age.change import AgeResult, age_head

SIZE = (180, 210)
#: rows at the top of a panel that hold its label text
LABEL_ROWS = 28


@pytest.fixture(scope="module")
def aged(head_male) -> AgeResult:
    return age_head(head_male, sex="male", from_age=18.0, to_age=3.0)


def pixels(path: Path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGB"), float)


def panels(image: np.ndarray, width: int) -> list[np.ndarray]:
    return [image[:, i : i + width] for i in range(0, image.shape[1], width)]


def drawn(panel: np.ndarray) -> int:
    """Pixels of the panel below its label that are not the white background."""
    body = panel[LABEL_ROWS:]
    return int((np.abs(body - 255.0).sum(axis=2) > 30).sum())


def test_growth_distance_is_negative_where_the_head_shrank(head_male) -> None:
    skin = head_male.skin
    smaller = skin.with_vertices(skin.vertices * 0.9)  # about the Frankfort origin
    d = growth_distance(skin, smaller)
    assert d.shape == (skin.n_vertices,)
    assert np.median(d) < -5.0  # a tenth of a head's half-width, and more
    assert np.mean(d < 0) > 0.85  # inward-facing skin (ear backs, nostrils) reads +
    bigger = growth_distance(skin, skin.with_vertices(skin.vertices * 1.1))
    assert np.median(bigger) > 5.0
    assert np.allclose(growth_distance(skin, skin), 0.0, atol=1e-6)


@pytest.mark.parametrize(
    ("values", "limit"),
    [([0.2, -0.4], 1.0), ([-7.3, 2.0], 8.0), ([18.0, -3.0], 18.0), ([-23.0], 25.0)],
)
def test_colour_limit_is_a_round_number_covering_the_values(values, limit) -> None:
    assert colour_limit(np.array(values)) == limit


@pytest.mark.render
def test_side_by_side_shows_the_child_head_smaller_at_the_same_scale(
    aged: AgeResult, head_male, tmp_path: Path
) -> None:
    path = render_compare(head_male, aged.head, tmp_path / "compare.png", size=SIZE)
    image = pixels(path)
    assert image.shape == (SIZE[1], 4 * SIZE[0], 3)
    src_front, aged_front, src_side, aged_side = panels(image, SIZE[0])
    for panel in (src_front, aged_front, src_side, aged_side):
        assert panel[LABEL_ROWS:].std() > 20.0  # a head, not a blank panel
    # 18 -> 3 y: the head circumference scale is about 0.9, so about 0.8 of the area
    for source, child in ((src_front, aged_front), (src_side, aged_side)):
        assert drawn(child) < 0.92 * drawn(source)
        assert drawn(child) > 0.5 * drawn(source)
    # the same head twice at the same scale covers the same pixels
    twin = pixels(render_compare(head_male, head_male, tmp_path / "twin.png", size=SIZE))
    a, b = panels(twin, SIZE[0])[2:]  # the side views (the front one has the 100 mm bar)
    assert abs(drawn(a) - drawn(b)) <= 0.01 * drawn(a)


@pytest.mark.render
def test_growth_map_is_mostly_blue_when_the_head_shrinks(
    aged: AgeResult, head_male, tmp_path: Path
) -> None:
    path, limit = render_growth_map(head_male, aged.head, tmp_path / "growth.png", size=SIZE)
    d = growth_distance(head_male.skin, aged.head.skin)
    assert limit == colour_limit(d) and limit >= float(np.percentile(np.abs(d), 99))
    image = pixels(path)
    assert image.shape == (SIZE[1], 2 * SIZE[0], 3)
    assert image.std() > 20.0
    r, g, b = image[..., 0], image[..., 1], image[..., 2]
    blue = int(((b > r + 25) & (b > g)).sum())
    red = int(((r > b + 40) & (r > g + 20)).sum())
    assert blue > 1000
    assert blue > 5 * red
    with pytest.raises(ValueError, match="one value per aged skin vertex"):
        render_growth_map(head_male, aged.head, tmp_path / "x.png", values=np.zeros(3))


@pytest.mark.render
def test_every_age_gets_both_pictures(aged: AgeResult, head_male, tmp_path: Path) -> None:
    other = replace(aged, to_age=7.5)
    out, notes = render_age_pictures(head_male, [aged, other], tmp_path / "pics", size=SIZE)
    assert notes == []
    assert list(out) == ["compare_3y", "growth_3y", "compare_7.5y", "growth_7.5y"]
    for key, path in out.items():
        assert path == tmp_path / "pics" / f"{key}.png"
        assert pixels(path).std() > 20.0


@pytest.mark.render
def test_age_command_writes_the_pdf_with_its_pictures(tmp_path: Path, head_male, capsys) -> None:
    import pypdf

    from workbench.cli.main import main

    out = tmp_path / "aged"
    argv = ["age", "reference:male", "--sex", "male", "--from", "18", "--to", "3"]
    assert main([*argv, "--out", str(out)]) == 0
    for name in ("compare_3y.png", "growth_3y.png"):
        assert pixels(out / "pictures" / name).std() > 20.0
    reader = pypdf.PdfReader(out / "report.pdf")
    assert sum(len(page.images) for page in reader.pages) == 2
    text = " ".join(" ".join(page.extract_text() for page in reader.pages).split())
    assert "Nasal Width" in text and "Weinberg SM" in text and "Cole TJ" in text
    assert "National Library of Medicine" not in text  # the reference head is not a VHP sample
    assert f"wrote {out.resolve() / 'report.pdf'}" in capsys.readouterr().out


@pytest.mark.render
def test_a_head_built_from_the_visible_human_ct_carries_the_nlm_credit(
    aged: AgeResult, head_male, tmp_path: Path
) -> None:
    import pypdf

    from workbench.pipelines.age import write_age_report_pdf

    built = {"built_from": [{"role": "skin", "file": "vhm_head_ct_1mm.nii.gz", "sha256": "0" * 64}]}
    source = replace(head_male, provenance=built)
    files = write_age_report_pdf(tmp_path, source, [aged])
    assert tmp_path / "report.pdf" in files
    assert {p.name for p in files} == {"compare_3y.png", "growth_3y.png", "report.pdf"}
    reader = pypdf.PdfReader(tmp_path / "report.pdf")
    text = " ".join(" ".join(page.extract_text() for page in reader.pages).split())
    assert "Courtesy of the U.S. National Library of Medicine" in text
