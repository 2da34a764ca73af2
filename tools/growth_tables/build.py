"""One-off authoring script: re-enter the growth norms into ``data_tables/growth/``.

Reads the copies in ``../shared/data`` (see their PROVENANCE.md) and writes

* ``facial_norms.csv``   -- the Cliniface "Distance" metrics by age, sex, ethnicity and source,
  landmarks as catalogue skin codes, bilateral metrics expanded to a left and a right row set;
* ``head_circumference_lms.csv`` -- WHO 2006 (0-60 months) and UK90 (4-18 y) LMS rows, cm -> mm.

Run from the checkout:  ``python tools/growth_tables/build.py [SHARED_DATA]``.
Values are copied unchanged (means/SDs with up to 10 significant digits, M x 10).
and ``table82.csv`` (Kähler's Table 8.2 rebuilt with catalogue codes).
The meta files and the README are written by hand.
"""

from __future__ import annotations

import csv
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
OUT = ROOT / "data_tables" / "growth"
sys.path.insert(0, str(ROOT))

from workbench.io.catalogue import load_catalogue  # noqa: E402

#: Cliniface source text -> citation keys of the primary publications
SOURCE_KEYS = {
    "Weinberg et al. (2016)": "weinberg2016",
    "Weinberg et al. (2016).": "weinberg2016",
    "Cliniface (2020).": "cliniface2020",
    "Farkas (1981).": "farkas1981",
    "Farkas (1981), Chouke (1929), Laestadius et al. (1969), and Thomas et al. (1987).": (
        "farkas1981;chouke1929;laestadius1969;thomas1987"
    ),
    "Farkas (1981), Chouke (1929), Laestadius et al. (1969), Thomas et al. (1987), and Fox (1966).": (
        "farkas1981;chouke1929;laestadius1969;thomas1987;fox1966"
    ),
    "Laestadius et al. (1969) and Feingold and Bossert (1974).": "laestadius1969;feingold_bossert1974",
    "Feingold and Bossert (1974), and Farkas (1981).": "feingold_bossert1974;farkas1981",
    "Feingold and Bossert (1974).": "feingold_bossert1974",
    "Goodman and Gorlin (1977), Farkas (1981), and Saksena et al. (1987).": (
        "goodman_gorlin1977;farkas1981;saksena1987"
    ),
    "Iosub S, Fuchs M, Bingol N, et al. (1985).": "iosub1985",
    "Clarren et al. (2010).": "clarren2010",
    "Stromland et al. (1999).": "stromland1999",
}
SEXES = {"F": "female", "M": "male", "M F": "pooled"}


def _id(name: str) -> str:
    return re.sub(r"[^a-z0-9]+", "_", name.lower()).strip("_")


def _num(text: str) -> str:
    """The number as written in the source, without float noise."""
    float(text)  # a number, or fail loudly
    return text.removesuffix(".0")


def facial_norms(shared: Path) -> None:
    cat = load_catalogue()
    src = shared / "facial_norms_cliniface" / "cliniface_facial_norms_by_age.csv"
    rows = [r for r in csv.DictReader(src.open(encoding="utf-8")) if r["category"] == "Distance"]
    out = []
    for r in rows:
        labels = r["landmarks"].split()
        assert len(labels) == 2, r
        codes = [cat.normalise(label, "skin") for label in labels]
        sides = [("", codes)]
        if r["bilateral"] == "True":
            right = [cat.mirror(c, "skin") for c in codes]
            sides = [("_l", codes), ("_r", right)]
        for suffix, (a, b) in sides:
            word = {"_l": " (left)", "_r": " (right)"}.get(suffix, "")
            n = int(r["n_samples"])
            out.append(
                {
                    "measurement_id": _id(r["metric_name"]) + suffix,
                    "name": r["metric_name"] + word,
                    "kind": "euclidean",
                    "a": a,
                    "b": b,
                    "ethnicity": r["ethnicity"],
                    "sex": SEXES[r["sexes"]],
                    "age_years": _num(r["age_years"]),
                    "mean_mm": r["mean"],
                    "sd_mm": r["sd"],
                    "n": str(n) if n > 0 else "",
                    "source": SOURCE_KEYS[r["source"]],
                }
            )
    order = {m: i for i, m in reversed(list(enumerate(r["measurement_id"] for r in out)))}
    out.sort(key=lambda r: order[r["measurement_id"]])  # stable: each measurement's rows together
    header = [
        "# Facial anthropometric norms by age, sex and ethnicity: mean and SD in mm of straight-line (Euclidean, 3D)",
        "# distances between two skin landmarks (catalogue skin codes; _l/_r = the subject's left/right). Euclidean",
        "# distances do not depend on the head frame. age_years in years; n = the study's sample size over all ages",
        "# (empty where the source gives none). Re-entered unchanged from the Cliniface norms copy in",
        "# ../shared/data/facial_norms_cliniface; citations of the primary publications in facial_norms.meta.json.",
    ]
    _write(OUT / "facial_norms.csv", header, out)
    print(f"facial_norms.csv: {len(out)} rows from {len(rows)} source rows")


def head_circumference(shared: Path) -> None:
    base = shared / "head_circumference_growth_refs"
    out = []
    who = base / "who2006_hcfa_zscores_0_60mo_pygrowup_zhcage.csv"
    for r in csv.DictReader(who.open(encoding="utf-8")):
        sex = {"1": "male", "2": "female"}[r["Gender"]]
        out.append(
            {
                "reference": "WHO2006",
                "sex": sex,
                "age_years": f"{int(r['Month']) / 12:.6f}",
                "L": r["L"],
                "M_mm": f"{float(r['M']) * 10:.4f}".rstrip("0").rstrip("."),
                "S": r["S"],
                "source": "who2007_hc",
            }
        )
    uk = base / "ofc_lms_rcpchgrowth.csv"
    for r in csv.DictReader(uk.open(encoding="utf-8")):
        if r["reference"] != "UK90_child_from_4y":
            continue
        out.append(
            {
                "reference": "UK90",
                "sex": r["sex"],
                "age_years": f"{int(r['interval_value']) / 12:.6f}",
                "L": r["L"],
                "M_mm": f"{float(r['M_cm']) * 10:.4f}".rstrip("0").rstrip("."),
                "S": r["S"],
                "source": "cole1998",
            }
        )
    header = [
        "# Head circumference (occipito-frontal, OFC) growth references as LMS tables, by sex and age (years).",
        "# M_mm = median in mm (the sources give cm; multiplied by 10 here); L (Box-Cox power) and S (coefficient of",
        "# variation) are unitless and unchanged. WHO2006: 0-60 months, monthly; UK90: 4-18 y (girls 4-17 y), monthly.",
        "# z = ((x/M)^L - 1)/(L S) for L != 0; value at z: M (1 + L S z)^(1/L). Citations in head_circumference_lms.meta.json.",
    ]
    _write(OUT / "head_circumference_lms.csv", header, out)
    print(f"head_circumference_lms.csv: {len(out)} rows")


def _write(path: Path, header: list[str], rows: list[dict[str, str]]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", encoding="utf-8", newline="") as fh:
        fh.write("\n".join(header) + "\n")
        w = csv.DictWriter(fh, fieldnames=list(rows[0]), lineterminator="\n")
        w.writeheader()
        w.writerows(rows)


def table82() -> None:
    """Kähler's Table 8.2 (digest Part 2 §A.5) with catalogue codes, left/right duplicated."""
    cat = load_catalogue()
    BI = {"po","t","zy","go","or","sci","en","ex","obs","al","ch","sa","sba","obi","pra","pa"}
    # (region, kind, a, b) in the printed order; duplicates merged below
    T = [
     ("Head","vertical","v","n"),("Head","vertical","v","gn"),("Head","vertical","v","po"),("Head","vertical","v","t"),
     ("Head","horizontal","t","t"),("Head","depth","g","op"),
     ("Face","vertical","n","gn"),("Face","vertical","n","sto"),("Face","vertical","sn","gn"),("Face","vertical","sto","gn"),("Face","vertical","sl","gn"),
     ("Face","horizontal","zy","zy"),("Face","horizontal","go","go"),
     ("Face","euclidean","t","g"),("Face","euclidean","n","t"),("Face","euclidean","sn","t"),("Face","euclidean","gn","t"),("Face","euclidean","go","gn"),
     ("Face","arc","sn","t"),("Face","arc","gn","t"),
     ("Orbits","vertical","or","sci"),("Orbits","horizontal","en","en"),("Orbits","horizontal","ex","ex"),("Orbits","horizontal","ex","en"),
     ("Orbits","depth","en","se"),("Orbits","euclidean","en","se"),("Orbits","euclidean","ex","obs"),("Orbits","euclidean","ex","t"),("Orbits","euclidean","ex","go"),
     ("Nose","vertical","n","sn"),("Nose","vertical","sn","sto"),("Nose","horizontal","al","al"),("Nose","depth","sn","prn"),("Nose","depth","en","se"),("Nose","euclidean","n","prn"),
     ("Lips and mouth","vertical","sn","sto"),("Lips and mouth","vertical","sn","ls"),("Lips and mouth","vertical","ls","sto"),("Lips and mouth","vertical","sto","li"),("Lips and mouth","vertical","li","sl"),("Lips and mouth","vertical","sto","sl"),
     ("Lips and mouth","horizontal","ch","ch"),("Lips and mouth","euclidean","ch","t"),("Lips and mouth","arc","ch","t"),
     ("Ears","vertical","sa","sba"),("Ears","vertical","obs","obi"),("Ears","depth","pra","pa"),("Ears","depth","op","po"),("Ears","euclidean","n","obs"),
    ]
    # Table 8.2 measurement -> facial_norms measurement (and what differs)
    NORM = {
     ("vertical","n","gn"): ("facial_height", "norm is the Euclidean n-gn distance, not its vertical component"),
     ("horizontal","en","en"): ("innercanthal_width", "norm is Euclidean (en_l-en_r lie nearly level)"),
     ("horizontal","ex","ex"): ("outercanthal_width", "norm is Euclidean (ex_l-ex_r lie nearly level)"),
     ("horizontal","ex","en"): ("palpebral_fissure_length", "norm is the Euclidean fissure length (the fissure is inclined)"),
     ("horizontal","zy","zy"): ("bizygomatic_width", "norm is Euclidean"),
     ("horizontal","go","go"): ("mandibular_width", "norm is Euclidean"),
     ("horizontal","al","al"): ("nasal_width", "norm is Euclidean"),
     ("horizontal","ch","ch"): ("labial_fissure_width", "norm is Euclidean"),
     ("vertical","n","sn"): ("nasal_height", "norm is the Euclidean n-sn distance"),
     ("vertical","sn","sto"): ("upper_lip_height", "norm is Euclidean sn-sts (stomion superius); sto and sts coincide with closed lips"),
     ("vertical","sn","ls"): ("philtral_length", "norm is the Euclidean sn-ls distance"),
     ("vertical","ls","sto"): ("upper_vermilion_height", "norm is Euclidean ls-sts (stomion superius)"),
     ("vertical","sto","li"): ("lower_vermilion_height", "norm is Euclidean sti-li (stomion inferius)"),
     ("vertical","li","sl"): ("cutaneous_lower_lip_height", "norm is the Euclidean li-sl distance"),
     ("depth","sn","prn"): ("nasal_protrusion", "norm is the Euclidean sn-prn distance, not its depth component"),
     ("euclidean","n","prn"): ("nasal_bridge_length", ""),
    }
    GN = "Farkas' gn is the lowest chin point (catalogue me); gn (halfway pg-me) is used, as in the norms"
    rows, seen = [], {}
    for region, kind, a, b in T:
        key = (kind, a, b)
        if key in seen:
            seen[key]["region"] += "; " + region
            continue
        pairs = []
        if a == b:  # t-t, zy-zy ...: one left-right pair
            pairs = [(a + "_l", b + "_r", "")]
        elif a in BI or b in BI:
            for s in ("_l", "_r"):
                pairs.append((a + s if a in BI else a, b + s if b in BI else b, s))
        else:
            pairs = [(a, b, "")]
        for ca, cb, s in pairs:
            for c in (ca, cb):
                assert cat.get(c, "skin") is not None, c
            norm, note = NORM.get(key, ("", ""))
            if norm == "palpebral_fissure_length":
                norm += s
            notes = [note] if note else []
            if "gn" in (a, b):
                notes.append(GN)
            if kind == "arc":
                notes.append(f"Kähler's middle point of the {a}-{b} arc is not in the catalogue: placed on the skin by the solver")
            r = {"measurement": f"{kind}:{ca}-{cb}", "kind": kind, "a": ca, "b": cb, "mid": "", "region": region,
                 "norm_measurement_id": norm, "note": "; ".join(notes)}
            rows.append(r)
            seen.setdefault(key, r)
    # merged regions apply to both sides
    for r in rows:
        k = (r["kind"],) + tuple(x.removesuffix("_l").removesuffix("_r") for x in (r["a"], r["b"]))
        r["region"] = seen[k]["region"]
    with open(OUT / 'table82.csv', 'w', newline='', encoding='utf-8') as fh:
        fh.write("# Kähler (2003) Table 8.2: the measurements driving age changes, rebuilt with the catalogue's skin codes\n"
                 "# (Farkas 1994 landmark names; _l/_r = the subject's left/right), one row per measurement after left/right\n"
                 "# duplication. kind: vertical (y), horizontal (x), depth (z) of the Frankfort frame, euclidean (3D), arc\n"
                 "# (along the skin). Pairs printed twice in Table 8.2 (vertical sn-sto, depth en-se) are one row with both\n"
                 "# regions. norm_measurement_id: the facial_norms.csv measurement that covers it (empty: no norms here).\n")
        w = csv.DictWriter(fh, fieldnames=list(rows[0]), lineterminator="\n")
        w.writeheader(); w.writerows(rows)
    print(f"table82.csv: {len(rows)} rows, {sum(1 for r in rows if r['norm_measurement_id'])} with norms")


if __name__ == "__main__":
    shared = Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT.parent / "shared" / "data"
    facial_norms(shared)
    head_circumference(shared)
    table82()
