"""Visual speech: viseme table, Cohen-Massaro coarticulation, and lip closure on the reference head."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial import cKDTree

from workbench.core.errors import InputError
from workbench.services.animation.speech import (
    JAW,
    SILENCE,
    Segment,
    builtin_viseme_table,
    coarticulate,
    dominance,
    load_visemes,
)

ARPABET = (
    "AA AE AH AO AW AY B CH D DH EH ER EY F G HH IH IY JH K L M N NG OW OY P R S SH T TH UH UW "
    "V W Y Z ZH"
).split()
TIMIT = (
    "aa ae ah ao aw ax ax-h axr ay b bcl ch d dcl dh dx eh el em en eng epi er ey f g gcl h# hh "
    "hv ih ix iy jh k kcl l m n ng nx ow oy p pau pcl q r s sh t tcl th uh uw ux v w y z zh"
).split()
PROT = "protrusion.orbicularis_oris_upper"


def segs(labels: str, dur: float, t0: float = 0.3) -> list[Segment]:
    tab = load_visemes()
    out = []
    for i, label in enumerate(labels.split()):
        canon = tab.canonical(label)
        assert canon is not None, label
        out.append(Segment(canon, t0 + i * dur, t0 + (i + 1) * dur))
    return out


def at_centres(segments: list[Segment]) -> np.ndarray:
    return np.array([s.centre for s in segments])


def test_table_reads_every_arpabet_and_timit_label() -> None:
    tab = load_visemes()
    assert set(ARPABET) | {SILENCE} == set(tab.phonemes)
    for label in TIMIT:
        assert tab.canonical(label) is not None, label
    assert tab.canonical("bcl") == "B" and tab.canonical("h#") == SILENCE
    assert tab.canonical("ax-h") == "AH" and tab.canonical("AH0") == "AH"
    assert tab.canonical("OW1") == "OW" and tab.canonical("xx") is None
    # columns are the project's muscle codes, their protrusions and the jaw
    from workbench.services.templates.muscles import read_table71

    codes = {r["code"] for r in read_table71()}
    for col in tab.columns:
        assert col == JAW or col in codes or col.removeprefix("protrusion.") in codes, col
    assert {"orbicularis_oris_upper", "orbicularis_oris_lower", PROT, JAW} <= set(tab.columns)
    sil = tab.targets[tab.index(SILENCE)]
    assert np.all(sil == 0.0)
    # the sidecar cites the dominance form and says the numbers are the project's
    meta = json.loads(builtin_viseme_table().with_suffix(".meta.json").read_text("utf-8"))
    assert "Cohen" in meta["sources"]["cohen_massaro1993"]
    assert "14496-2" in meta["sources"]["mpeg4_fap"]
    assert "own choice" in meta["what_comes_from_where"]["targets and dominance values"]


def test_dominance_is_cohen_massaro() -> None:
    tau = np.array([0.1, -0.1, 0.0])
    d = dominance(tau, 2.0, 10.0, 40.0, 1.5)
    assert d[0] == pytest.approx(2.0 * np.exp(-10.0 * 0.1**1.5))  # before the centre
    assert d[1] == pytest.approx(2.0 * np.exp(-40.0 * 0.1**1.5))  # after it
    assert d[2] == pytest.approx(2.0)


def test_track_is_the_dominance_weighted_average() -> None:
    tab = load_visemes()
    s = segs("AA IY", 0.1)
    t = np.array([0.33, 0.4, 0.47])
    got = coarticulate(s, t, tab, reach=30)
    # by hand over every segment, silences included: the lead-in from 0 - 0.2 s to the first
    # phoneme and the tail from the last to the last frame + 0.2 s, in pieces of <= 0.2 s
    jaw = tab.columns.index(JAW)
    sil = tab.index(SILENCE)
    lead = np.linspace(-0.2, 0.3, 4)
    tail = np.linspace(0.5, 0.7, 2)
    items = [((a + b) / 2, sil) for a, b in zip(lead[:-1], lead[1:], strict=True)]
    items += [(x.centre, tab.index(x.phoneme)) for x in s]
    items += [((tail[0] + tail[1]) / 2, sil)]
    for i, ti in enumerate(t):
        d = np.array(
            [
                dominance(c - ti, tab.alpha[r], tab.theta_before[r], tab.theta_after[r], tab.c[r])
                for c, r in items
            ]
        )
        want = (d * np.array([tab.targets[r, jaw] for _, r in items])).sum() / d.sum()
        assert got.jaw_deg[i] == pytest.approx(want, rel=1e-9)
    total = sum(got.weights.values())
    assert np.allclose(total, 1.0)


def test_rounding_reaches_into_the_neighbouring_consonant() -> None:
    for consonant in ("L", "T", "D", "HH"):
        rounded = coarticulate(segs(f"{consonant} OW", 0.08), [0.34])
        spread = coarticulate(segs(f"{consonant} IY", 0.08), [0.34])
        assert rounded.column(PROT)[0] > 0.15, consonant
        assert spread.column(PROT)[0] < 0.01, consonant
        assert spread.column("risorius_l")[0] > rounded.column("risorius_l")[0] + 0.05
    # in "hello world" the /l/ before /ow/ is already rounded
    hw = segs("HH AH L OW W ER L D", 0.08)
    f = coarticulate(hw, at_centres(hw))
    assert f.column(PROT)[2] > 0.15  # L (before OW)
    assert f.column(PROT)[1] < f.column(PROT)[2]  # AH less


def test_bilabials_dominate_their_segment_and_fast_speech_overlaps_more() -> None:
    slow = segs("AA M AA", 0.12)
    fast = segs("AA M AA", 0.05)
    fs = coarticulate(slow, at_centres(slow))
    ff = coarticulate(fast, at_centres(fast))
    assert fs.weights["M"][1] > 0.85 and fs.jaw_deg[1] < 1.2
    assert fs.column("orbicularis_oris_upper")[1] > 0.25
    # fast: the M is reached less and the vowels open less
    assert ff.weights["M"][1] < fs.weights["M"][1]
    assert ff.jaw_deg[0] < fs.jaw_deg[0] - 1.0
    assert ff.weights["M"][0] > fs.weights["M"][0] + 0.1
    # and the targets are never fully reached between neighbours
    assert fs.jaw_deg[0] < load_visemes().targets[load_visemes().index("AA"), 0]


def test_silence_is_neutral() -> None:
    s = segs("HH AH L OW", 0.08, t0=0.5)
    t = np.arange(0.0, 2.0, 1 / 30)
    f = coarticulate(s, t)
    far = (t < s[0].start - 0.3) | (t > s[-1].end + 0.3)
    assert far.sum() > 10
    assert np.abs(f.values[far]).max() < 0.02
    near = (t > s[0].start) & (t < s[-1].end)
    assert f.jaw_deg[near].max() > 2.0
    # a long pause inside speech comes back to neutral too
    s2 = [*s, *segs("AA", 0.1, t0=s[-1].end + 1.5)]
    f2 = coarticulate(s2, [s[-1].end + 0.75])
    assert np.abs(f2.values).max() < 0.02
    # no phonemes at all: neutral everywhere
    assert np.abs(coarticulate([], t).values).max() == 0.0


def test_influence_is_cut_beyond_seven_segments() -> None:
    s = segs("UW " + "T " * 8, 0.05)
    t = [s[8].centre]
    assert coarticulate(s, t, reach=7).weights["UW"][0] == 0.0
    assert coarticulate(s, t, reach=9).weights["UW"][0] > 0.0
    assert coarticulate(s, [s[7].centre], reach=7).weights["UW"][0] > 0.0


def test_a_bad_table_names_the_file_and_line(tmp_path: Path) -> None:
    text = builtin_viseme_table().read_text("utf-8")
    bad = tmp_path / "v.csv"
    bad.write_text(text.replace(",mentalis,", ",mentalist,"), "utf-8")
    with pytest.raises(InputError, match="mentalist"):
        load_visemes(bad)
    rows = text.splitlines()
    i = next(k for k, r in enumerate(rows) if r.startswith("AA,"))
    rows[i] = rows[i].replace(",6,", ",60,", 1)
    bad2 = tmp_path / "v2.csv"
    bad2.write_text("\n".join(rows), "utf-8")
    with pytest.raises(InputError, match=rf"v2.csv: line {i + 1} \(AA\): jaw_deg = 60"):
        load_visemes(bad2)


# ---------------------------------------------------------------------- on the reference head
@pytest.fixture(scope="module")
def lips(head_male):
    tree = cKDTree(head_male.skin.vertices)
    lm = head_male.skin_landmarks.as_dict()
    return int(tree.query(lm["sts"])[1]), int(tree.query(lm["sti"])[1])


def _lip_gaps(head, lips, labels: str, dur: float = 0.08):
    from workbench.services.animation.animator import Animator
    from workbench.services.animation.track import parse_track, run_track

    t0 = 0.2
    ph = [
        {"p": p, "start": t0 + i * dur, "end": t0 + (i + 1) * dur}
        for i, p in enumerate(labels.split())
    ]
    gaps: list[float] = []

    def measure(_: int, anim) -> None:
        x = anim.skin_in_head_frame()
        gaps.append(float(np.linalg.norm(x[lips[0]] - x[lips[1]])))

    anim = Animator(head)
    frames = run_track(anim, parse_track({"fps": 30, "phonemes": ph}), measure)
    return np.array(gaps), frames.times, ph, anim


def test_lips_close_only_for_bilabials(head_male, lips) -> None:
    """'hello world' never shuts the lips while speaking; 'hello my world' does at the /m/."""
    gap, t, ph, anim = _lip_gaps(head_male, lips, "HH AH L OW W ER L D")
    rest = float(np.linalg.norm(anim.sim.rest[lips[0]] - anim.sim.rest[lips[1]]))
    inner = (t >= ph[1]["start"]) & (t < ph[-2]["end"])
    print(f"rest gap {rest:.2f} mm; hello world inner min {gap[inner].min():.2f} mm")
    assert gap[inner].min() > rest + 3.0
    assert abs(gap[-1] - rest) < 0.1  # silence after the words: back to rest

    gap2, t2, ph2, _ = _lip_gaps(head_male, lips, "HH AH L OW M AY W ER L D")
    m = next(p for p in ph2 if p["p"] == "M")
    during = (t2 >= m["start"]) & (t2 <= m["end"] + 1e-9)
    print(f"hello my world: gap at the m {gap2[during].min():.2f} mm")
    assert gap2[during].min() < rest + 0.8
    # the vowels beside it open
    ay = next(p for p in ph2 if p["p"] == "AY")
    assert gap2[(t2 >= ay["start"]) & (t2 < ay["end"])].max() > rest + 5.0
