"""User tissue-depth tables: every problem is reported with the file, the line and a way out."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from workbench.core.errors import InputError
from workbench.io.tables import load_depth_table

HEADER = "landmark_code,skin_code,group,sex,build,mean_mm,sd_mm,n,source\n"


def _table(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "user_depths.csv"
    path.write_text(text, encoding="utf-8")
    return path


def _error(path: Path) -> str:
    with pytest.raises(InputError) as info:
        load_depth_table(path)
    assert info.value.source == str(path)
    return str(info.value)


def test_a_valid_user_table_loads_with_sex_build_and_partners(tmp_path: Path) -> None:
    path = _table(
        tmp_path,
        "# my own study\n"
        + HEADER
        + "g,,men/slim,M,slender,4,1,20,me2024\n"
        + "zyL,,men/slim,m,slender,6.5,,,me2024\n"
        + " pr , ls ,women,F,, 11 ,2.5,12, me2024\n",
    )
    table = load_depth_table(path)
    assert table.table_id == "user_depths"
    assert table.codes == ("g", "zy_l", "pr")
    assert table.skin_codes == ("g", "zy_l", "ls")  # empty skin_code = the catalogue partner
    assert table.group_sex("men/slim") == "male" and table.group_build("men/slim") == "slender"
    assert table.group_sex("women") == "female" and table.group_build("women") == ""
    assert table.lookup("women") == {"pr": (11.0, 2.5)}
    assert np.isnan(table.sd_mm[1]) and table.n[0] == 20
    assert table.citation("me2024") == "me2024"  # no metadata file: the key is all there is


def test_missing_columns_name_the_header_line(tmp_path: Path) -> None:
    path = _table(tmp_path, "# comment\nlandmark_code,group,depth,source\ng,a,3,x\n")
    msg = _error(path)
    assert "line 2: missing columns: mean_mm" in msg and "expected columns: landmark_code" in msg


@pytest.mark.parametrize(
    ("rows", "problem"),
    [
        ("g,,a,,,abc,,,x\n", "line 3: mean_mm is not a number ('abc')"),
        ("g,,a,,,0,,,x\n", "line 3: mean_mm must be a positive number of mm, got 0"),
        ("g,,a,,,-4,,,x\n", "line 3: mean_mm must be a positive number of mm, got -4"),
        ("g,,a,,,4,-1,,x\n", "line 3: sd_mm must be a non-negative number of mm, got -1"),
        ("g,,a,,,4,1,-2,x\n", "line 3: n must be a non-negative number, got -2"),
        ("g,,a,,,4,nan,,x\n", "line 3: sd_mm must be a non-negative number of mm, got nan"),
        ("g,,a,,,4,1,,\n", "line 3: source is empty"),
        (",,a,,,4,1,,x\n", "line 3: landmark_code is empty"),
        ("g,,a\n", "line 3: mean_mm is empty"),
        ("g,,a,,,4,1,,x,surplus\n", "line 3: more values than columns (9)"),
        ("g,gg,a,,,4,1,,x\n", "line 3: unknown skin landmark code 'gg'"),
        ("g,,a,females,,4,1,,x\n", "line 3: unknown sex 'females'"),
        ("g,,a,,chubby,4,1,,x\n", "line 3: unknown build 'chubby'"),
    ],
)
def test_row_problems_name_the_line(tmp_path: Path, rows: str, problem: str) -> None:
    # the comment line counts: errors point at the line in the file, not in the data
    assert problem in _error(_table(tmp_path, "# comment\n" + HEADER + rows))


def test_unknown_codes_are_listed_with_lines_and_suggestions(tmp_path: Path) -> None:
    path = _table(
        tmp_path,
        HEADER + "pg,,a,,,11,,,x\npgn,,a,,,11,,,x\ngnathoin,,a,,,7,,,x\n"
        "prn,,a,,,3,,,x\nqqq,,a,,,3,,,x\n",
    )
    msg = _error(path)
    assert "unknown skull landmark codes: pgn, gnathoin, prn, qqq" in msg
    assert "line 3: 'pgn', did you mean pg" in msg
    assert "line 4: 'gnathoin', did you mean gn?" in msg
    assert "line 5: 'prn' is a skin landmark" in msg
    assert "line 6: 'qqq');" not in msg and "line 6: 'qqq')" in msg  # no guess for nonsense


def test_duplicate_rows_are_refused(tmp_path: Path) -> None:
    path = _table(
        tmp_path, HEADER + "zy_l,,a,,,7,,,x\ng,,a,,,5,,,x\n\nzyL,,a,,,8,,,x\nzy_l,,b,,,8,,,x\n"
    )
    msg = _error(path)
    assert "line 5: duplicate row for zy_l in group 'a' (first given on line 2)" in msg


def test_a_group_has_one_sex_and_build(tmp_path: Path) -> None:
    path = _table(tmp_path, HEADER + "g,,a,female,normal,5,,,x\npg,,a,male,normal,11,,,x\n")
    assert "line 3: group 'a' is male/normal here but female/normal on line 2" in _error(path)


def test_empty_table_and_bad_encoding(tmp_path: Path) -> None:
    assert "the table has no rows" in _error(_table(tmp_path, "# nothing\n" + HEADER))
    path = tmp_path / "latin1.csv"
    path.write_bytes(HEADER.encode() + "g,,K\xe4hler,,,5,,,x\n".encode("latin-1"))
    assert "cannot be read as UTF-8 text" in _error(path)
