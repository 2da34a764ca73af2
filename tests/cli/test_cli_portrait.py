"""``workbench portrait``: the pictures (PNG and TIFF at 300 dpi, their metadata), portrait.json,
the folder written as a whole, and clear refusals of bad input.  Small pictures (256-300 px)
of the male reference head keep it quick."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import workbench
from workbench.cli import portrait_cmd
from workbench.cli.main import main
from workbench.render import portrait

pytestmark = pytest.mark.render


def test_portrait_writes_every_view_with_its_metadata(tmp_path: Path, head_male, capsys) -> None:
    out = tmp_path / "portrait"
    assert main(["portrait", "reference:male", "--out", str(out), "--size", "300"]) == 0
    assert "wrote" in capsys.readouterr().out
    names = sorted(p.name for p in out.iterdir())
    assert names == sorted(
        ["portrait.json"] + [f"portrait_{v}.{e}" for v in portrait.VIEWS for e in ("png", "tif")]
    )
    for view in portrait.VIEWS:
        png = Image.open(out / f"portrait_{view}.png")
        assert png.size == (300, 300) and png.mode == "RGB"
        assert png.info["dpi"] == pytest.approx((300, 300), abs=0.01)
        text = png.text  # type: ignore[attr-defined]
        assert text["Description"] == portrait.DISCLAIMER
        assert head_male.template_id in text["Source"]
        assert text["Software"] == f"workbench {workbench.__version__}"
        tif = Image.open(out / f"portrait_{view}.tif")
        assert tif.size == (300, 300) and tif.info["dpi"] == (300, 300)
        description = tif.tag_v2[270]  # type: ignore[attr-defined]
        assert portrait.DISCLAIMER in description and head_male.template_id in description
        assert tif.tag_v2[305] == f"workbench {workbench.__version__}"  # type: ignore[attr-defined]
        assert np.array_equal(np.asarray(png), np.asarray(tif))  # the same picture
    summary = json.loads((out / "portrait.json").read_text())
    assert summary["disclaimer"] == portrait.DISCLAIMER
    assert summary["views"] == list(portrait.VIEWS) and summary["size_px"] == [300, 300]
    assert summary["lens"]["focal_length_mm"] == 85.0 and summary["colour"] is True
    assert set(summary["cameras"]) == set(portrait.VIEWS)
    assert {"key", "fill", "rim", "bounce"} == {light["name"] for light in summary["lights"]}
    assert summary["seconds"]["render"] > 0 and summary["template_id"] == head_male.template_id
    assert summary["files"]["front"] == ["portrait_front.png", "portrait_front.tif"]


def test_portrait_of_a_pack_without_colour_one_view(tmp_path: Path, head_male) -> None:
    from workbench.io.template_pack import export_template

    pack = tmp_path / "pack"
    export_template(head_male, pack)
    out = tmp_path / "clay"
    args = ["portrait", str(pack), "--out", str(out), "--size", "256", "--views", "profile"]
    assert main([*args, "--no-colour"]) == 0
    assert sorted(p.name for p in out.iterdir()) == [
        "portrait.json",
        "portrait_profile.png",
        "portrait_profile.tif",
    ]
    summary = json.loads((out / "portrait.json").read_text())
    assert summary["colour"] is False and summary["iris"] is None
    image = np.asarray(Image.open(out / "portrait_profile.png")).astype(int)
    assert (image.max(axis=2) - image.min(axis=2)).max() <= 3  # no hue


def test_an_existing_folder_is_kept_unless_forced(tmp_path: Path, head_male, capsys) -> None:
    out = tmp_path / "p"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    args = ["portrait", "reference:male", "--out", str(out), "--size", "256", "--views", "front"]
    assert main(args) == 2
    assert "already exists" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == ["notes.txt"]  # untouched
    assert main([*args, "--force"]) == 0
    assert (tmp_path / "p.1" / "notes.txt").read_text() == "mine"  # kept aside
    assert (out / "portrait_front.png").is_file() and not (out / "notes.txt").exists()


@pytest.mark.parametrize(
    ("extra", "message"),
    [
        (["--views", "front,back"], "back: is not a portrait view .*front, three_quarter"),
        (["--views", ","], "names no view"),
        (["--size", "100"], "from 256 to 8000 pixels"),
        (["--size", "9000"], "from 256 to 8000 pixels"),
    ],
)
def test_bad_input_is_refused(tmp_path: Path, capsys, extra, message) -> None:
    out = tmp_path / "p"
    assert main(["portrait", "reference:male", "--out", str(out), *extra]) == 2
    assert re.search(message, capsys.readouterr().err)
    assert not out.exists()


def test_a_missing_head_is_named(tmp_path: Path, capsys) -> None:
    missing = tmp_path / "nowhere"
    assert main(["portrait", str(missing), "--out", str(tmp_path / "p")]) == 2
    assert "nowhere: is not a folder" in capsys.readouterr().err
    assert main(["portrait", "reference:cat", "--out", str(tmp_path / "p")]) == 2
    assert "unknown reference head" in capsys.readouterr().err
    with pytest.raises(SystemExit):  # argparse: the choices are listed
        main(["portrait", "reference:male", "--out", str(tmp_path / "p"), "--iris", "red"])
    assert not (tmp_path / "p").exists()


def test_the_command_knows_the_renderers_views_and_limits() -> None:
    assert portrait_cmd.VIEWS == portrait.VIEWS
    assert portrait_cmd.SIZE_LIMITS == portrait.SIZE_LIMITS


def test_hair_options_and_the_case_appearance(tmp_path: Path, head_female, capsys) -> None:
    """``--hair``/``--brows`` draw pieces of the library, said to be artistic additions; a
    folder whose case.fcase keeps an appearance is drawn in it, the options changing it."""
    out = tmp_path / "groomed"
    args = ["portrait", "reference:female", "--out", str(out), "--size", "256"]
    assert main([*args, "--views", "profile", "--hair", "long", "--brows", "thin"]) == 0
    said = capsys.readouterr().out
    assert "hair long, brows thin: artistic additions, not evidence" in said
    summary = json.loads((out / "portrait.json").read_text())
    assert summary["artistic_additions"]["hair_and_brows"] == {"hair": "long", "brows": "thin"}
    assert "not evidence" in summary["artistic_additions"]["note"]
    text = Image.open(out / "portrait_profile.png").text  # type: ignore[attr-defined]
    assert "hair long" in text["Comment"] and "not evidence" in text["Comment"]
    # a reconstruction folder's case keeps an appearance: it is used, options change it
    from argparse import Namespace

    from workbench.io.case_file import save_case
    from workbench.model.appearance import Appearance
    from workbench.model.case import Case

    folder = tmp_path / "recon"
    folder.mkdir()
    kept = Appearance(tone="mst9", iris="green", grooming={"beard": "full"})
    save_case(Case(appearance=kept), folder / "case.fcase")
    none = {k: None for k in ("hair", "brows", "beard", "moustache")}
    options = Namespace(head=str(folder), skin_tone=None, iris=None, **none)
    assert portrait_cmd.chosen_appearance(options) == kept
    options.iris, options.beard, options.hair = "blue", "none", "buzz"
    changed = portrait_cmd.chosen_appearance(options)
    assert changed is not None and changed.iris == "blue" and changed.tone == "mst9"
    assert dict(changed.grooming) == {"hair": "buzz"}
    plain = Namespace(head="reference:male", skin_tone="mst2", iris=None, **none)
    assert portrait_cmd.chosen_appearance(plain) is None
    with pytest.raises(SystemExit) as stopped:
        main([*args, "--hair", "mohawk"])
    assert stopped.value.code == 2 and "invalid choice: 'mohawk'" in capsys.readouterr().err
