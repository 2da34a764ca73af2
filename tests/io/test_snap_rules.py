"""The snap rule table: every row restates a catalogue definition and cites its sources."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from workbench.core.errors import InputError
from workbench.io.catalogue import load_catalogue
from workbench.io.snap_rules import COLUMNS, default_snap_rules_path, load_snap_rules

#: the words of a definition that make it an extremum, and the direction they mean
WORDS = {
    r"most (forward-projecting|anterior)": "+z",
    r"most posterior": "-z",
    r"highest": "+y",
    r"lowest": "-y",
    r"most lateral": "lateral",
    r"deepest": "+z",
}


def test_rules_encode_the_catalogue_definitions_and_cite_them() -> None:
    catalogue = load_catalogue()
    rules = load_snap_rules()
    assert {"g", "v", "op", "pg", "me", "ans", "ss", "sm", "zy_l", "zy_r"} <= set(rules)
    for code, rule in rules.items():
        entry = catalogue.entry(code, "skull")
        assert rule.sources and set(rule.sources) <= set(entry.sources), code
        assert rule.midline == (entry.side == "midline")
        wanted = [d for pattern, d in WORDS.items() if re.search(pattern, entry.definition.lower())]
        assert rule.direction in wanted, (code, entry.definition)
        assert (rule.rule == "deepest") == ("deepest" in entry.definition.lower())
        assert np.isclose(np.linalg.norm(rule.axis), 1.0)
    assert rules["zy_l"].axis[0] == 1.0 and rules["zy_r"].axis[0] == -1.0
    assert rules["ss"].between == ("ans", "pr")
    # the frame landmarks and suture points have no rule
    assert not {"po_l", "po_r", "or_l", "or_r", "n", "b", "mn"} & set(rules)


def test_meta_file_describes_every_column() -> None:
    path = default_snap_rules_path()
    meta = json.loads(path.with_name("snap_rules.meta.json").read_text(encoding="utf-8"))
    assert meta["@schema"] == "landmark-snap-rules-v1" and meta["table"] == path.name
    assert tuple(meta["columns"]) == COLUMNS


@pytest.mark.parametrize(
    ("row", "message"),
    [
        ("g,extremum,lateral,8,yes,,kahler2003,", "sideways"),
        ("zy_l,extremum,lateral,8,yes,,kahler2003,", "midline must be"),
        ("g,extremum,+z,-3,yes,,kahler2003,", "radius_mm"),
        ("g,extremum,up,8,yes,,kahler2003,", "direction must be"),
        ("g,extremum,+z,8,yes,,,", "cites no source"),
        ("g,extremum,+z,8,yes,,nobody2020,", "nobody2020"),
        ("gg,extremum,+z,8,yes,,kahler2003,", "not a skull landmark"),
        ("g,extremum,+z,8,yes,ans;pr,kahler2003,", "between"),
        ("zy_l,deepest,+z,8,no,,kahler2003,", "deepest"),
    ],
)
def test_bad_rows_are_refused_with_the_line(tmp_path: Path, row: str, message: str) -> None:
    path = tmp_path / "rules.csv"
    path.write_text(",".join(COLUMNS) + "\n" + row + "\n", encoding="utf-8")
    with pytest.raises(InputError, match=f"line 2: .*{message}"):
        load_snap_rules(path, load_catalogue())
