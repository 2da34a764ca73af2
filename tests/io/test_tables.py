"""Tissue-depth tables: shipped tables agree with the published copies; user tables are checked."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pytest

from workbench.core.errors import InputError
from workbench.io.catalogue import load_catalogue
from workbench.io.tables import list_tables, load_depth_table


def test_shipped_tables_are_listed_with_the_ttable_first() -> None:
    ids = list_tables()
    assert ids[0] == "ttable_2023"
    assert "rhine_1983_sw_native_american" in ids


def test_ttable_matches_the_source_values(shared_data: Path) -> None:
    table = load_depth_table("ttable_2023")
    got = table.lookup("adult")
    catalogue = load_catalogue()
    src = shared_data / "fstt_ttable_2023_stephan" / "fstt_ttable_2023_adult_esomjai.csv"
    rows = list(csv.DictReader(src.open()))
    assert len(got) == len(rows) == 36
    for r in rows:
        code = catalogue.normalise(r["hard_tissue_landmark"], "skull")
        assert got[code] == (float(r["mean_mm"]), float(r["sd_mm"]))
        skin = table.skin_codes[table.codes.index(code)]
        assert skin == catalogue.normalise(r["soft_tissue_landmark"], "skin")
    assert all(table.citation(s).startswith("Hona") for s in table.sources)


def test_rhine_table_has_means_only(shared_data: Path) -> None:
    table = load_depth_table("rhine_1983_sw_native_american")
    assert np.isnan(table.sd_mm).all()
    depths = table.lookup()
    assert depths["pg"][0] == 13.0 and depths["zy_l"][0] == depths["zy_r"][0] == 7.0
    assert len(depths) == 10 + 2 * 11


def test_every_table_code_is_in_the_catalogue() -> None:
    catalogue = load_catalogue()
    for table_id in list_tables():
        table = load_depth_table(table_id)
        assert (table.mean_mm > 0).all()
        for code in table.codes:
            assert catalogue.get(code, "skull") is not None, (table_id, code)


def test_user_table_errors_name_the_problem(tmp_path: Path) -> None:
    path = tmp_path / "mine.csv"
    path.write_text(
        "landmark_code,group,mean_mm,source\npg,adult,11,me\nxyz,adult,5,me\nfoo,adult,5,me\n"
    )
    with pytest.raises(InputError, match=r"mine.csv.*unknown skull landmark codes: xyz, foo"):
        load_depth_table(path)
    path.write_text("landmark_code,group,mean_mm,source\npg,adult,-3,me\n")
    with pytest.raises(InputError, match="line 2: mean_mm must be a positive"):
        load_depth_table(path)
    path.write_text("code,depth\npg,11\n")
    with pytest.raises(InputError, match="missing columns"):
        load_depth_table(path)
    path.write_text("landmark_code,group,mean_mm,source\npgL,adult,11,me\n")
    with pytest.raises(InputError):
        load_depth_table(path)  # 'pgL' is not a skull landmark: pogonion is midline
    path.write_text("landmark_code,group,mean_mm,sd_mm,source\nzyL,adult,7,2,me\n")
    assert load_depth_table(path).lookup() == {"zy_l": (7.0, 2.0)}
