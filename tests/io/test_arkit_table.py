"""The ARKit-52 table: Apple's 52 names, recipes of existing AU targets, clear errors."""

from __future__ import annotations

import csv
from pathlib import Path

import pytest

from workbench.core.errors import InputError
from workbench.io.arkit_table import ARKIT_COLUMNS, builtin_arkit_table, read_arkit_table

#: ARFaceAnchor.BlendShapeLocation, as Apple spells them
ARKIT_52 = {
    *(f"eye{k}{s}" for k in ("Blink", "LookDown", "LookIn", "LookOut", "LookUp", "Squint", "Wide")
      for s in ("Left", "Right")),
    "jawForward", "jawLeft", "jawRight", "jawOpen",
    "mouthClose", "mouthFunnel", "mouthPucker", "mouthLeft", "mouthRight",
    *(f"mouth{k}{s}" for k in ("Smile", "Frown", "Dimple", "Stretch", "Press", "LowerDown",
                               "UpperUp") for s in ("Left", "Right")),
    "mouthRollLower", "mouthRollUpper", "mouthShrugLower", "mouthShrugUpper",
    "browDownLeft", "browDownRight", "browInnerUp", "browOuterUpLeft", "browOuterUpRight",
    "cheekPuff", "cheekSquintLeft", "cheekSquintRight",
    "noseSneerLeft", "noseSneerRight", "tongueOut",
}  # fmt: skip


def test_builtin_table_has_the_52_names_and_valid_recipes() -> None:
    from workbench.services.animation.animator import EXPRESSIONS

    assert len(ARKIT_52) == 52
    with builtin_arkit_table().open(encoding="utf-8") as f:
        rows = list(csv.DictReader(f))
    assert tuple(rows[0]) == ARKIT_COLUMNS
    names = [r["arkit_name"] for r in rows]
    assert len(names) == 52 and set(names) == ARKIT_52
    for r in rows:
        assert "Apple ARKit" in r["source"], r
        assert r["notes"], r
        if r["recipe"]:
            assert "Ekman, Friesen & Hager 2002" in r["source"], r
            assert "approximation" in r["notes"], r
    table = read_arkit_table(valid=EXPRESSIONS)
    assert list(table) == names
    assert table["jawOpen"] == {"au26": 1.0}
    assert table["mouthSmileLeft"] == {"au12": 1.0}
    assert table["tongueOut"] == {}
    for mix in table.values():
        assert set(mix) <= set(EXPRESSIONS)


def test_user_table_errors(tmp_path: Path) -> None:
    good = tmp_path / "mine.csv"
    good.write_text(
        "# my table\narkit_name,recipe,source,notes\njawOpen,au26:0.5;au27:0.5,me,\n",
        encoding="utf-8",
    )
    assert read_arkit_table(good, valid=["au26", "au27"]) == {"jawOpen": {"au26": 0.5, "au27": 0.5}}
    bad = tmp_path / "bad.csv"
    bad.write_text(
        "arkit_name,recipe,source,notes\njawOpen,au26:1;grin:0.5,me,\n", encoding="utf-8"
    )
    with pytest.raises(InputError) as err:
        read_arkit_table(bad, valid=["au26", "au27"])
    message = str(err.value)
    assert "bad.csv" in message and "line 2" in message and "grin" in message
    assert "valid names: au26, au27" in message
    for text, problem in [
        ("arkit_name,recipe\njawOpen,au26\n", "TARGET:WEIGHT"),
        ("arkit_name,recipe\njawOpen,au26:x\n", "TARGET:WEIGHT"),
        ("arkit_name,recipe\njawOpen,\njawOpen,\n", "twice"),
        ("name,recipe\njawOpen,\n", "no column arkit_name"),
    ]:
        bad.write_text(text, encoding="utf-8")
        with pytest.raises(InputError, match=problem):
            read_arkit_table(bad, valid=["au26"])
    with pytest.raises(InputError, match="cannot be read"):
        read_arkit_table(tmp_path / "missing.csv")
