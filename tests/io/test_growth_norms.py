"""Growth norms (issue 15): the shipped tables, interpolation, source choice, user CSVs, LMS; mm."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import pytest

from workbench.core.data_paths import data_tables_dir
from workbench.core.errors import InputError
from workbench.io.catalogue import load_catalogue
from workbench.io.growth_norms import (
    HC_SWITCH_AGE_YEARS,
    NormMeasurement,
    growth_dir,
    list_growth_norms,
    load_growth_norms,
    load_head_circumference,
)

HEADER = "measurement_id,name,kind,a,b,ethnicity,sex,age_years,mean_mm,sd_mm,n,source\n"


def _shipped_rows(name: str) -> list[dict[str, str]]:
    lines = (growth_dir() / name).read_text(encoding="utf-8").splitlines()
    return list(csv.DictReader(ln for ln in lines if not ln.startswith("#")))


# ---------------------------------------------------------------- shipped tables
def test_shipped_norms_load_with_every_code_in_the_catalogue() -> None:
    assert list_growth_norms() == ["facial_norms"]
    norms = load_growth_norms()
    assert norms.norms_id == "facial_norms" and norms.meta["units"] == "mm"
    assert len(norms.measurements) == 27
    assert norms.ethnicities()[0] == "European" and len(norms.ethnicities()) == 7
    catalogue = load_catalogue()
    for m in norms.measurements:
        assert m.kind == "euclidean"
        for code in (m.a, m.b):
            assert catalogue.get(code, "skin") is not None, (m.measurement_id, code)
    assert norms.measurement("outercanthal_width") == NormMeasurement(
        "outercanthal_width", "Outercanthal Width", "euclidean", "ex_l", "ex_r", "pair"
    )
    assert norms.measurement("facial_height").side == "midline"


def test_every_shipped_source_key_has_a_primary_citation() -> None:
    for name in ("facial_norms", "head_circumference_lms"):
        meta = json.loads((growth_dir() / f"{name}.meta.json").read_text(encoding="utf-8"))
        assert meta["units"].startswith("mm") and meta["caveats"], name
        keys = {k for r in _shipped_rows(f"{name}.csv") for k in r["source"].split(";")}
        assert keys and keys <= set(meta["sources"]), (name, keys - set(meta["sources"]))
        assert all(len(meta["sources"][k]) > 40 for k in keys), name
    norms = load_growth_norms()
    assert norms.citation("weinberg2016").startswith("Weinberg SM, Raffensperger ZD")
    both = norms.citation("laestadius1969;feingold_bossert1974")
    assert "Laestadius ND" in both and "Feingold M" in both


def test_the_norms_are_the_cliniface_distance_rows_unchanged(shared_data: Path) -> None:
    src = shared_data / "facial_norms_cliniface" / "cliniface_facial_norms_by_age.csv"
    source = [r for r in csv.DictReader(src.open(encoding="utf-8")) if r["category"] == "Distance"]
    bilateral = sum(r["bilateral"] == "True" for r in source)
    shipped = _shipped_rows("facial_norms.csv")
    assert len(shipped) == len(source) + bilateral  # each bilateral row once per side
    catalogue = load_catalogue()
    by_key = {(r["a"], r["b"], r["ethnicity"], r["sex"], float(r["age_years"])): r for r in shipped}
    sexes = {"F": "female", "M": "male", "M F": "pooled"}
    for r in source:
        a, b = (catalogue.normalise(x, "skin") for x in r["landmarks"].split())
        got = by_key[(a, b, r["ethnicity"], sexes[r["sexes"]], float(r["age_years"]))]
        assert (float(got["mean_mm"]), float(got["sd_mm"])) == (float(r["mean"]), float(r["sd"]))


def test_an_exact_tabulated_value_equals_the_csv() -> None:
    norms = load_growth_norms()
    row = next(
        r
        for r in _shipped_rows("facial_norms.csv")
        if r["measurement_id"] == "nasal_width"
        and r["sex"] == "male"
        and r["ethnicity"] == "European"
        and r["age_years"] == "7"
    )
    assert norms.at("nasal_width", "male", 7) == (float(row["mean_mm"]), float(row["sd_mm"]))
    assert norms.source_of("nasal_width", "male") == row["source"] == "weinberg2016"


def test_halfway_between_tabulated_ages_is_the_average() -> None:
    norms = load_growth_norms()
    m10, s10 = norms.at("bizygomatic_width", "female", 10)
    m11, s11 = norms.at("bizygomatic_width", "female", 11)
    m, s = norms.at("bizygomatic_width", "female", 10.5)
    assert m == pytest.approx((m10 + m11) / 2, abs=1e-12) and m10 < m < m11
    assert s == pytest.approx((s10 + s11) / 2, abs=1e-12)
    m25, _ = norms.at("bizygomatic_width", "female", 10.25)
    assert m25 == pytest.approx(m10 + 0.25 * (m11 - m10), abs=1e-12)


def test_bilateral_metrics_are_one_measurement_per_side_with_the_same_norms() -> None:
    norms = load_growth_norms()
    left = norms.measurement("palpebral_fissure_length_l")
    right = norms.measurement("palpebral_fissure_length_r")
    assert (left.a, left.b, left.side) == ("ex_l", "en_l", "left")
    assert (right.a, right.b, right.side) == ("ex_r", "en_r", "right")
    assert norms.measurement("nasal_ala_length_r").a == "ac_r"
    for age in (3, 7.5, 16):
        for eth in ("European", "Puerto Rican", "Northern European"):
            assert norms.at(left.measurement_id, "female", age, eth) == norms.at(
                right.measurement_id, "female", age, eth
            )


def test_pooled_rows_are_used_when_a_sex_has_none() -> None:
    norms = load_growth_norms()
    # Caucasian innercanthal width is pooled only (Laestadius 1969; Feingold & Bossert 1974)
    pooled = norms.at("innercanthal_width", "pooled", 8, "Caucasian")
    assert norms.at("innercanthal_width", "female", 8, "caucasian") == pooled
    assert norms.at("innercanthal_width", "male", 8, "Caucasian") == pooled
    assert norms.source_of("innercanthal_width", "male", "Caucasian").startswith("laestadius")
    # European has sex-specific Weinberg rows: they win over the pooled Farkas compilation
    assert norms.source_of("palpebral_fissure_length_l", "female") == "weinberg2016"
    assert norms.age_range("palpebral_fissure_length_l", "female") == (3.0, 40.0)
    farkas = norms.sources("palpebral_fissure_length_l", "pooled")[0]
    assert farkas.startswith("farkas1981")
    assert norms.age_range("palpebral_fissure_length_l", "female", source=farkas) == (0.0, 16.0)
    assert norms.at("palpebral_fissure_length_l", "female", 1, source=farkas) == norms.at(
        "palpebral_fissure_length_l", "pooled", 1
    )
    assert norms.has("nasal_root_width", "male", "Australian Aboriginal")
    assert not norms.has("nasal_root_width", "male")  # European: none
    assert not norms.has("no_such_measurement", "male")


def test_out_of_range_age_and_unknown_ethnicity_are_named() -> None:
    norms = load_growth_norms()
    with pytest.raises(InputError, match=r"outercanthal_width: age 45 y .*range 0-39 y"):
        norms.at("outercanthal_width", "male", 45)
    with pytest.raises(InputError, match=r"palpebral_fissure_length_l: age 1 y .*3-40 y"):
        norms.at("palpebral_fissure_length_l", "female", 1)
    with pytest.raises(InputError, match=r"unknown ethnicity 'Martian'.*European.*Puerto Rican"):
        norms.at("outercanthal_width", "male", 5, "Martian")
    with pytest.raises(InputError, match=r"no norms for nasal_root_width.*Australian Aboriginal"):
        norms.at("nasal_root_width", "male", 5)
    with pytest.raises(InputError, match=r"no measurement 'nasal_widht'.*nasal_width"):
        norms.at("nasal_widht", "male", 5)
    with pytest.raises(InputError, match="unknown sex"):
        norms.at("nasal_width", "child", 5)


# ---------------------------------------------------------------- user tables
def _write(tmp_path: Path, text: str, name: str = "my_norms.csv") -> Path:
    path = tmp_path / name
    path.write_text(text, encoding="utf-8")
    return path


def test_user_csv_round_trip(tmp_path: Path) -> None:
    norms = load_growth_norms()
    rows = [
        r
        for r in _shipped_rows("facial_norms.csv")
        if r["measurement_id"] in ("nasal_height", "palpebral_fissure_length_r")
        and r["ethnicity"] in ("European", "Puerto Rican")
    ]
    path = tmp_path / "copy.csv"
    with path.open("w", encoding="utf-8", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    mine = load_growth_norms(path)
    assert mine.norms_id == "copy" and mine.ethnicities() == ("European", "Puerto Rican")
    for mid, sex, eth, age in [
        ("nasal_height", "female", "European", 12.3),
        ("palpebral_fissure_length_r", "male", "Puerto Rican", 4.5),
        ("palpebral_fissure_length_r", "male", "European", 3),
    ]:
        assert mine.at(mid, sex, age, eth) == norms.at(mid, sex, age, eth)
        assert mine.source_of(mid, sex, eth) == norms.source_of(mid, sex, eth)
    # no sidecar: the source text is its own citation
    assert mine.citation("weinberg2016") == "weinberg2016"


def test_user_csv_with_cliniface_spellings_and_defaults(tmp_path: Path) -> None:
    path = _write(
        tmp_path,
        "# my clinic\nmeasurement_id,a,b,sex,age_years,mean_mm,sd_mm,source\n"
        "icw,Len,Ren,F,5,25,2,Clinic study 2025\n"
        "icw,Len,Ren,F,7,27,2.2,Clinic study 2025\n",
    )
    mine = load_growth_norms(path)
    m = mine.measurement("icw")
    assert (m.a, m.b, m.kind, m.side, m.name) == ("en_l", "en_r", "euclidean", "pair", "icw")
    assert mine.ethnicities() == ("unspecified",)
    assert mine.at("icw", "female", 6) == pytest.approx((26.0, 2.1))  # the only ethnicity
    assert mine.citation(mine.source_of("icw", "female")) == "Clinic study 2025"
    with pytest.raises(InputError, match=r"my_norms.csv.*age 8 y .*5-7 y"):
        mine.at("icw", "female", 8)


def test_user_sidecar_must_define_the_cited_keys(tmp_path: Path) -> None:
    path = _write(tmp_path, HEADER + "w,W,euclidean,al_l,al_r,X,male,5,30,2,,me2025\n")
    path.with_suffix(".meta.json").write_text(json.dumps({"sources": {"you2024": "You (2024)"}}))
    with pytest.raises(InputError, match=r"my_norms.csv.*not defined in the metadata: me2025"):
        load_growth_norms(path)
    path.with_suffix(".meta.json").write_text(json.dumps({"sources": {"me2025": "Me (2025) J"}}))
    assert load_growth_norms(path).citation("me2025") == "Me (2025) J"


GOOD = "w,Width,euclidean,al_l,al_r,European,male,5,30,2,10,me\n"


@pytest.mark.parametrize(
    ("text", "problem"),
    [
        ("measurement_id,a,b,sex,age_years,mean_mm,source\n" + "w,al_l,al_r,male,5,30,me\n",
         r"line 1: missing columns: sd_mm"),
        (HEADER + GOOD + "w,Width,euclidean,al_l,al_r,European,male,6,31,,10,me\n",
         r"line 3: sd_mm is missing"),
        (HEADER + "w,Width,euclidean,al_l,al_r,European,male,6,31,0,10,me\n",
         r"line 2: sd_mm must be a positive number of mm, got 0"),
        (HEADER + "w,Width,euclidean,al_l,al_r,European,male,6,31,-1.5,10,me\n",
         r"line 2: sd_mm must be a positive number of mm, got -1.5"),
        (HEADER + "w,Width,euclidean,al_l,al_r,European,male,6,31,40,10,me\n",
         r"line 2: sd_mm 40 mm is larger than the mean 31 mm"),
        (HEADER + "w,Width,euclidean,al_l,al_r,European,male,6,3100,40,10,me\n",
         r"line 2: mean_mm 3100 is implausible .*1-400 mm"),
        (HEADER + "w,Width,euclidean,al_l,al_r,European,male,6,0.3,0.1,10,me\n",
         r"line 2: mean_mm 0.3 is implausible"),
        (HEADER + "w,Width,euclidean,al_l,al_r,European,male,six,31,2,10,me\n",
         r"line 2: age_years is not a number \('six'\)"),
        (HEADER + "w,Width,euclidean,al_l,al_r,European,male,-2,31,2,10,me\n",
         r"line 2: age_years -2 is not an age"),
        (HEADER + GOOD + "w,Width,euclidean,al_l,al_r,European,male,5.0,31,2,10,me\n",
         r"line 3: age 5 y of w \(male, European, me\) is given twice \(also on line 2\)"),
        (HEADER + "w,Width,euclidean,alx_l,al_r,European,male,5,30,2,10,me\n"
         + "v,V,euclidean,zorg,n,European,male,5,30,2,10,me\n",
         r"unknown skin landmark codes: alx_l, zorg \(line 2: 'alx_l', did you mean al_l"),
        (HEADER + "w,Width,euclidean,go_l,n,European,male,5,30,2,10,me\n"
         + "v,V,euclidean,pr,n,European,male,5,30,2,10,me\n",
         r"'pr' is a skull landmark; its skin partner is ls"),
        (HEADER + GOOD + "w,Width,euclidean,ch_l,ch_r,European,male,6,30,2,10,me\n",
         r"line 3: measurement w is euclidean ch_l-ch_r 'Width' here but euclidean al_l-al_r"),
        (HEADER + "w,Width,curved,al_l,al_r,European,male,5,30,2,10,me\n",
         r"line 2: unknown kind 'curved'"),
        (HEADER + "w,Width,euclidean,al_l,al_r,European,boys,5,30,2,10,me\n",
         r"line 2: unknown sex 'boys'"),
        (HEADER + "w,Width,euclidean,al_l,al_r,European,male,5,30,2,10,\n",
         r"line 2: source is empty"),
        (HEADER + "w,Width,euclidean,al_l,al_r,European,male,5,30,2,-4,me\n",
         r"line 2: n must be a non-negative count"),
        (HEADER + "w,Width,euclidean,al_l,Lal,European,male,5,30,2,10,me\n",
         r"line 2: w measures al_l to itself"),
        (HEADER, r"the table has no rows"),
    ],
    ids=[
        "missing-sd-column", "empty-sd", "zero-sd", "negative-sd", "sd-above-mean",
        "mean-3100", "mean-0.3", "text-age", "negative-age", "duplicate-age", "unknown-code",
        "skull-code", "one-id-two-pairs", "unknown-kind", "unknown-sex", "no-source",
        "negative-n", "same-point", "no-rows",
    ],
)  # fmt: skip
def test_bad_user_tables_name_the_file_and_the_problem(
    tmp_path: Path, text: str, problem: str
) -> None:
    path = _write(tmp_path, text)
    with pytest.raises(InputError, match=problem) as info:
        load_growth_norms(path)
    assert info.value.source == str(path) and "my_norms.csv" in str(info.value)


def test_unknown_shipped_id_and_missing_file() -> None:
    with pytest.raises(
        InputError, match=r"no_such_norms: unknown growth norms table.*facial_norms"
    ):
        load_growth_norms("no_such_norms")
    with pytest.raises(InputError, match="unknown growth norms table"):
        load_growth_norms("head_circumference_lms")  # an LMS table, not facial norms
    with pytest.raises(InputError, match="not found"):
        load_growth_norms("/nonexistent/mine.csv")


# ---------------------------------------------------------------- head circumference
def test_head_circumference_reads_who_then_uk90_in_mm(shared_data: Path) -> None:
    hc = load_head_circumference()
    assert hc.age_range("male") == (0.0, 18.0) and hc.age_range("female") == (0.0, 17.0)
    who = shared_data / "head_circumference_growth_refs"
    who_rows = list(
        csv.DictReader((who / "who2006_hcfa_zscores_0_60mo_pygrowup_zhcage.csv").open())
    )
    boys_12 = next(r for r in who_rows if r["Gender"] == "1" and r["Month"] == "12")
    assert hc.median_mm("male", 1.0) == pytest.approx(float(boys_12["M"]) * 10, abs=1e-9)
    assert hc.sd_mm("male", 1.0) == pytest.approx(float(boys_12["M"]) * 10 * float(boys_12["S"]))
    # the WHO table's own SD column (cm) agrees with M*S
    assert hc.sd_mm("male", 1.0) == pytest.approx(float(boys_12["SD"]) * 10, abs=0.01)
    uk = list(csv.DictReader((who / "ofc_lms_rcpchgrowth.csv").open()))
    girls_10 = next(
        r
        for r in uk
        if r["reference"] == "UK90_child_from_4y"
        and r["sex"] == "female"
        and r["interval_value"] == "120"
    )
    assert hc.median_mm("female", 10.0) == pytest.approx(float(girls_10["M_cm"]) * 10, abs=1e-9)
    assert hc.reference_for(HC_SWITCH_AGE_YEARS - 1e-6) == "WHO2006"
    assert hc.reference_for(HC_SWITCH_AGE_YEARS) == "UK90"
    assert "Cole TJ" in hc.citation("UK90") and "WHO Multicentre" in hc.citation("WHO2006")


def test_lms_z_of_the_median_is_zero_and_value_at_inverts_z() -> None:
    hc = load_head_circumference()
    for sex in ("female", "male"):
        for age in (0.0, 0.5, 2.25, 3.99, 4.0, 9.6, 16.0, 17.0):
            median = hc.median_mm(sex, age)
            assert hc.z(sex, age, median) == pytest.approx(0.0, abs=1e-12)
            for value in (median * 0.9, median + 7.3):
                z = hc.z(sex, age, value)
                assert hc.value_at(sex, age, z) == pytest.approx(value, abs=1e-9)
            assert hc.value_at(sex, age, 1.0) - median == pytest.approx(hc.sd_mm(sex, age))
    # a general L (not 1): value_at and z still invert, sd is half the +-1 z spread
    from workbench.io.growth_norms import _lms_value

    L, M, S = -0.7, 500.0, 0.03
    v = _lms_value(L, M, S, 1.7)
    assert ((v / M) ** L - 1) / (L * S) == pytest.approx(1.7)
    assert _lms_value(0.0, M, S, 1.0) == pytest.approx(M * math.exp(S))


def test_head_circumference_outside_the_references_is_refused() -> None:
    hc = load_head_circumference()
    with pytest.raises(InputError, match=r"age 17.5 y is outside .*0-17 y \(female\)"):
        hc.median_mm("female", 17.5)
    with pytest.raises(InputError, match=r"age 30 y is outside .*0-18 y \(male\)"):
        hc.z("male", 30, 560)
    with pytest.raises(InputError, match=r"age -1 y"):
        hc.sd_mm("male", -1)
    with pytest.raises(InputError, match="female or male"):
        hc.median_mm("pooled", 5)
    with pytest.raises(InputError, match="positive"):
        hc.z("male", 5, -3)


def test_a_head_circumference_table_in_cm_is_refused(tmp_path: Path) -> None:
    src = (growth_dir() / "head_circumference_lms.csv").read_text(encoding="utf-8").splitlines()
    bad = [ln.replace(",344.618,", ",34.4618,") for ln in src]
    path = tmp_path / "hc.csv"
    path.write_text("\n".join(bad) + "\n", encoding="utf-8")
    with pytest.raises(
        InputError, match=r"hc.csv: line 6: M_mm 34.4618 is not a head circumference"
    ):
        load_head_circumference(path)


# ---------------------------------------------------------------- Table 8.2
def test_table82_codes_kinds_and_norm_links() -> None:
    rows = _shipped_rows("table82.csv")
    assert len(rows) == 70
    kinds = [r["kind"] for r in rows]
    assert (kinds.count("vertical"), kinds.count("horizontal"), kinds.count("depth")) == (24, 9, 8)
    assert (kinds.count("euclidean"), kinds.count("arc")) == (23, 6)
    catalogue = load_catalogue()
    norms = load_growth_norms()
    linked = 0
    for r in rows:
        assert catalogue.get(r["a"], "skin") and catalogue.get(r["b"], "skin"), r
        assert r["mid"] == "" or catalogue.get(r["mid"], "skin")
        if r["norm_measurement_id"]:
            linked += 1
            m = norms.measurement(r["norm_measurement_id"])
            # the norm joins the same points, or stomion superius/inferius for stomion
            same = {m.a, m.b} == {r["a"], r["b"]}
            lips = {m.a, m.b} - {r["a"], r["b"]} <= {"sts", "sti"}
            assert same or lips, (r["measurement"], m)
    assert linked == 17
    assert len({r["measurement"] for r in rows}) == 70
    assert data_tables_dir() / "growth" == growth_dir()
