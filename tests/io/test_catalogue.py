"""The landmark catalogue: every code system we meet resolves, and the table is consistent."""

from __future__ import annotations

import csv
import json
import re
import shutil
from pathlib import Path

import pytest

import workbench
from workbench.core.errors import InputError, LandmarkError
from workbench.io.catalogue import COLUMNS, default_catalogue_path, load_catalogue, split_side

TABLE = (
    Path(workbench.__file__).resolve().parents[1] / "data_tables" / "landmarks" / "catalogue.csv"
)
META = TABLE.with_name("catalogue.meta.json")

# Kähler (2003) Table 8.3: (id, skull code, skin code); bilateral ids get a side.
KAHLER_83_MIDLINE = [
    ("tr", "sg", "tr"),
    ("g", "g", "g"),
    ("n", "n", "n"),
    ("na", "rhi", "rhi"),
    ("a", "mp", "mp"),
    ("sd", "pr", "ls"),
    ("id", "id", "li"),
    ("b", "b", "sl"),
    ("pog", "pg", "pg"),
    ("me", "me", "me"),
]
KAHLER_83_BILATERAL = [
    ("fe*", "fe", "fe"),
    ("sci", "mso", "sci"),
    ("or", "or", "or"),
    ("en", "d", "en"),
    ("ex", "ec", "ex"),
    ("im", "im", "im"),
    ("lo", "lo", "lo"),
    ("zy", "zy", "zy"),
    ("sg", "sgl", "sgl"),
    ("go", "go", "go"),
    ("spm2*", "ecm2s", "sM2"),
    ("ol", "ol", "ol"),
    ("sbm2*", "ecm2i", "iM2"),
    ("mp*", "ms", "ms"),
]
# Documented departures from Kähler's "same id on skull and skin" (README): skin tr/sci are
# Farkas' trichion/superciliare, skull b is bregma, skull n pairs with skin se (T-Table).
KAHLER_NOT_PARTNERS = {"tr", "n", "b", "sci"}
KAHLER_82 = "v n gn po t g op sto sn sl zy go or sci en ex se obs al prn ls li ch sa sba obi pra pa"
RHINE_EXPECTED = {
    "sg": "sg",
    "g": "g",
    "n": "n",
    "rhi": "rhi",
    "mp": "mp",
    "pr": "pr",
    "id": "id",
    "sm": "sm",
    "pg": "pg",
    "me": "me",
    "fe": "fe",
    "mso": "mso",
    "or": "or",
    "im": "im",
    "lo": "lo",
    "zy": "zy",
    "sgl": "sgl",
    "go": "go",
    "ecm2_sup": "ecm2s",
    "mm": "ol",
    "ecm2_inf": "ecm2i",
}


@pytest.fixture(scope="module")
def cat():
    return load_catalogue()


def _rows(path: Path) -> list[dict]:
    with open(path, newline="", encoding="utf-8") as fh:
        return list(csv.DictReader(fh))


def test_table_columns_and_sources():
    with open(TABLE, newline="", encoding="utf-8") as fh:
        assert tuple(next(csv.reader(fh))) == COLUMNS
    meta = json.loads(META.read_text(encoding="utf-8"))
    assert meta["@schema"] == "landmark-catalogue-v1"
    assert meta["frame"] and meta["notes"]
    for row in _rows(TABLE):
        keys = [k for k in row["source"].split(";") if k]
        assert keys, f"{row['surface']} {row['code']} cites nothing"
        assert all(k in meta["sources"] for k in keys), (row["code"], keys)
        assert row["definition"].strip().endswith("."), row["code"]


def test_default_path_is_the_checkout(cat):
    assert default_catalogue_path() == TABLE
    assert len(cat.codes("skin")) > 80 and len(cat.codes("skull")) > 50


def test_ttable_pairs_are_partners(cat, shared_data):
    rows = _rows(shared_data / "fstt_ttable_2023_stephan" / "fstt_ttable_2023_adult_esomjai.csv")
    assert len(rows) == 36
    for row in rows:
        skull = cat.normalise(row["hard_tissue_landmark"], "skull")
        skin = cat.normalise(row["soft_tissue_landmark"], "skin")
        assert cat.partner(skull, "skull") == skin, row["landmark_pair"]
        assert cat.partner(skin, "skin") == skull, row["landmark_pair"]
        assert cat.entry(skull, "skull").side == row["side"]
        assert cat.entry(skin, "skin").side == row["side"]
    assert cat.normalise("ecm2(s)L", "skull") == "ecm2s_l"
    assert cat.normalise("ecm2(i)R", "skull") == "ecm2i_r"
    assert cat.partner("n", "skull") == "se" and cat.normalise("sm'", "skin") == "sl"


def test_rhine_codes_resolve(cat, shared_data):
    rows = _rows(
        shared_data
        / "fstt_rhine1983_sw_native_american"
        / "fstt_rhine1983_sw_native_american_normal_female.csv"
    )
    assert {r["code"] for r in rows} == set(RHINE_EXPECTED)
    for row in rows:
        want = RHINE_EXPECTED[row["code"]]
        if row["bilateral"] == "yes":
            for spelled, side in ((f"{row['code']}_l", "l"), (f"{row['code']}R", "r")):
                assert cat.normalise(spelled, "skull") == f"{want}_{side}", spelled
        else:
            assert cat.normalise(row["code"], "skull") == want
        assert cat.partner(
            cat.normalise(row["code"] + ("_l" if row["bilateral"] == "yes" else ""), "skull"),
            "skull",
        ), row["code"]


def test_cliniface_codes_resolve(cat, shared_data):
    rows = _rows(shared_data / "facial_norms_cliniface" / "cliniface_metrics.csv")
    tokens = {re.sub(r"^\d+", "", t) for r in rows for t in r["landmarks"].split()}
    assert len(tokens) > 40
    for token in sorted(tokens):
        code = cat.normalise(token, "skin")
        side = cat.entry(code, "skin").side
        expected = {"L": "left", "R": "right"}.get(token[0], "midline")
        assert side == expected, (token, code)
        assert token in cat.entry(code, "skin").aliases or token == code or side == "midline"
    assert cat.normalise("Lex", "skin") == "ex_l" and cat.normalise("Rsbal", "skin") == "sbal_r"


@pytest.mark.parametrize("kid,skull,skin", KAHLER_83_MIDLINE)
def test_kahler_table_83_midline(cat, kid, skull, skin):
    assert cat.normalise(kid, "skull") == skull
    assert cat.normalise(kid, "skin") == skin
    if kid not in KAHLER_NOT_PARTNERS:
        assert cat.partner(skull, "skull") == skin


@pytest.mark.parametrize("kid,skull,skin", KAHLER_83_BILATERAL)
@pytest.mark.parametrize("side", ["l", "r"])
def test_kahler_table_83_bilateral(cat, kid, skull, skin, side):
    word = "left" if side == "l" else "right"
    for spelled in (f"{kid}_{side}", f"{kid}{side.upper()}", f"{kid} ({word})"):
        assert cat.normalise(spelled, "skull") == f"{skull}_{side}", spelled
        assert cat.normalise(spelled, "skin") == f"{skin}_{side}", spelled
    if kid not in KAHLER_NOT_PARTNERS:
        assert cat.partner(f"{skull}_{side}", "skull") == f"{skin}_{side}"
    assert "kahler2003" in cat.entry(f"{skull}_{side}", "skull").sources


def test_kahler_table_82_skin_points_exist(cat):
    for base in KAHLER_82.split():
        if cat.get(base, "skin") is None:
            assert cat.get(f"{base}_l", "skin") and cat.get(f"{base}_r", "skin"), base
        assert "kahler2003" in (cat.get(base, "skin") or cat.get(f"{base}_l", "skin")).sources


def test_mastoid_and_supraglenoid_collisions(cat):
    assert cat.normalise("mp", "skull") == "mp"  # mid-philtrum (T-Table, Rhine)
    assert cat.normalise("mp*_l", "skull") == "ms_l"  # Kähler's mastoid process
    assert "mp*" in cat.entry("ms_r", "skull").aliases
    assert cat.normalise("sg", "skull") == "sg"  # Rhine's supraglabella
    assert cat.normalise("sg_r", "skull") == "sgl_r"  # Kähler's supraglenoid


def test_frankfort_and_guide_points_exist(cat):
    for code in ("po_l", "po_r", "or_l", "or_r", "ans", "apl_l", "apl_r", "ba", "b"):
        assert cat.get(code, "skull") is not None, code


def test_bilateral_pairs_symmetric_and_mirror_involution(cat):
    for e in cat.entries:
        if e.side == "midline":
            assert e.bilateral_pair == "" and cat.mirror(e.code, e.surface) == e.code
            continue
        pair = cat.entry(e.bilateral_pair, e.surface)
        assert pair.bilateral_pair == e.code and {e.side, pair.side} == {"left", "right"}
        assert e.code.endswith("_l" if e.side == "left" else "_r")
        assert cat.mirror(cat.mirror(e.code, e.surface), e.surface) == e.code
        assert cat.mirror(e.code) == pair.code
        if e.partner:
            assert cat.entry(e.partner, "skin" if e.surface == "skull" else "skull").side == e.side


def test_partners_point_back(cat):
    other = {"skin": "skull", "skull": "skin"}
    for e in cat.entries:
        if e.partner:
            assert cat.partner(e.partner, other[e.surface]) == e.code, e.code


def test_every_alias_resolves_to_its_row(cat):
    for e in cat.entries:
        for alias in e.aliases:
            if e.side != "midline" and not any(s == e.side for _, s in split_side(alias)):
                alias = f"{alias}_{e.code[-1]}"
            assert cat.normalise(alias, e.surface) == e.code, (e.surface, alias)


@pytest.mark.parametrize(
    "label",
    [
        "exL",
        "ex_L",
        "Lex",
        "L ex",
        "ex-l",
        "ex (left)",
        "ex'L",
        "ex_l",
        "Exocanthion (left)",
        "left exocanthion",
        "ex left",
    ],
)
def test_side_spellings(cat, label):
    assert cat.normalise(label, "skin") == "ex_l"


def test_unknown_label_is_named(cat):
    with pytest.raises(LandmarkError, match="LPA"):
        cat.normalise("LPA", "skin")
    with pytest.raises(LandmarkError, match="'n_l'"):
        cat.normalise("n_l", "skull")
    with pytest.raises(LandmarkError, match="'A'"):  # point A is ss elsewhere; no guessing
        cat.normalise("A", "skull")
    with pytest.raises(LandmarkError):
        cat.mirror("nope")
    assert cat.get("nope", "skin") is None


def _broken_copy(tmp_path: Path, edit) -> Path:
    target = tmp_path / "catalogue.csv"
    shutil.copy(META, tmp_path / "catalogue.meta.json")
    target.write_text(edit(TABLE.read_text(encoding="utf-8")), encoding="utf-8")
    return target


@pytest.mark.parametrize(
    "edit,problem",
    [
        (lambda t: t.replace("surface,code", "surf,code", 1), "columns"),
        (
            lambda t: t.replace(
                "skin,ex_r,Exocanthion,right,ex_l", "skin,ex_r,Exocanthion,right,en_l"
            ),
            "pair",
        ),
        (
            lambda t: t.replace(
                "skull,ec_l,Ectoconchion,left,ec_r,ex_l", "skull,ec_l,Ectoconchion,left,ec_r,en_l"
            ),
            "partner",
        ),
        (lambda t: t.replace("farkas1994", "farkas1994x", 1), "undefined source"),
    ],
)
def test_broken_tables_are_rejected(tmp_path, edit, problem):
    with pytest.raises(InputError, match=problem):
        load_catalogue(_broken_copy(tmp_path, edit))


def test_wheel_data_is_preferred(tmp_path, monkeypatch):
    fake = tmp_path / "site" / "workbench"
    (fake / "_data" / "data_tables" / "landmarks").mkdir(parents=True)
    shutil.copy(TABLE, fake / "_data" / "data_tables" / "landmarks" / "catalogue.csv")
    monkeypatch.setattr(workbench, "__file__", str(fake / "__init__.py"))
    assert (
        default_catalogue_path() == fake / "_data" / "data_tables" / "landmarks" / "catalogue.csv"
    )
    assert load_catalogue().codes("skin") == load_catalogue(TABLE).codes("skin")
