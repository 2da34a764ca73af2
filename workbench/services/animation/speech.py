"""Visual speech: a timed phoneme track -> mouth-muscle, lip-protrusion and jaw tracks per frame.

Coarticulation after Cohen & Massaro (1993), as MEDUSA does it (seeds
digest section 13.4): every phoneme segment ``s`` has a *target* ``T_sp``
for every parameter ``p`` (a muscle contraction, a lip protrusion, the jaw
angle) and a *dominance function* over time

    D_s(t) = alpha_s * exp(-theta_s * |tau|^c_s),   tau = centre_s - t (seconds),

with ``theta_s = theta_before`` while ``t`` is before the segment's centre
(``tau > 0``) and ``theta_after`` after it.  The track of a parameter is the
dominance-weighted average of the targets,

    F_p(t) = sum_s D_s(t) T_sp / sum_s D_s(t),

over the segments at most :data:`REACH` (7) segments away from the one that
holds ``t`` (farther ones are cut: the seeds say influences reach up to 7
segments).  Targets are rarely reached: a consonant of low dominance
(t, d, n, l, k, g, hh) between two vowels takes much of their lip shape, so
a rounded vowel's protrusion reaches into its neighbours, while a bilabial's
large, narrow dominance shuts the lips during its own segment only.  When
segments are short (fast speech) the centres are closer and the functions
overlap more, so every target is reached less.

Gaps between segments, the time before the first and the time after the
last are silence (``sil``: every parameter neutral), cut into pieces of at
most :data:`SILENCE_PIECE_S` so that a long pause returns to neutral near
its edges, not only at its middle.

Targets and dominance parameters per phoneme are in
``data_tables/animation/visemes.csv`` (their sources and which numbers are
the project's own choice in ``visemes.meta.json``).  Labels are ARPAbet
(``AA`` ... ``ZH``, stress digits ``AH0`` ignored) or TIMIT (``aa``, ``bcl``,
``ax-h``, ``h#`` ...), case-insensitive; there is no text-to-phoneme step.

Everything is vectorised over frames (numpy; each frame looks at a window
of ``2 * REACH + 1`` segments), so evaluating a track costs far less than
simulating its skin (see ``benchmarks/bench_animation.py``).
"""

from __future__ import annotations

import csv
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from functools import lru_cache
from os import PathLike
from pathlib import Path

import numpy as np

from workbench.core.data_paths import data_tables_dir
from workbench.core.errors import InputError
from workbench.services.animation.animator import JAW_RANGE_DEG

__all__ = [
    "JAW",
    "REACH",
    "SILENCE",
    "SILENCE_PIECE_S",
    "Segment",
    "SpeechFrames",
    "VisemeTable",
    "builtin_viseme_table",
    "coarticulate",
    "dominance",
    "load_visemes",
]

#: label of the pause phoneme (every parameter neutral)
SILENCE = "sil"
#: segments farther than this (counted in segments, silences included) have no influence
REACH = 7
#: silences are cut into pieces no longer than this (seconds)
SILENCE_PIECE_S = 0.2
#: column of the jaw angle (degrees, positive opens)
JAW = "jaw_deg"
#: prefix of the sphincter protrusion columns (``protrusion.orbicularis_oris_upper``)
PROTRUSION = "protrusion."
_DOMINANCE = ("alpha", "theta_before", "theta_after", "c")
_TEXT = ("phoneme", "timit", "class", "mpeg4_viseme", "notes")


def builtin_viseme_table() -> Path:
    """Path of the shipped viseme table."""
    return data_tables_dir() / "animation" / "visemes.csv"


@dataclass(frozen=True)
class VisemeTable:
    """Per-phoneme targets and dominance parameters (rows = :attr:`phonemes`)."""

    source: str
    phonemes: tuple[str, ...]  #: canonical labels (ARPAbet upper case, ``sil``)
    classes: tuple[str, ...]  #: viseme class of each phoneme
    columns: tuple[str, ...]  #: muscle codes, ``protrusion.<code>``, ``jaw_deg``
    targets: np.ndarray  #: ``(n_phonemes, n_columns)``
    alpha: np.ndarray
    theta_before: np.ndarray  #: 1/s^c
    theta_after: np.ndarray  #: 1/s^c
    c: np.ndarray
    aliases: Mapping[str, str] = field(default_factory=dict)  #: lower-case label -> phoneme

    def canonical(self, label: str) -> str | None:
        """The table's phoneme for an ARPAbet or TIMIT label (None: unknown)."""
        text = str(label).strip().lower()
        found = self.aliases.get(text)
        if found is None:  # ARPAbet with a stress digit: AH0, OW1
            found = self.aliases.get(re.sub(r"(?<=[a-z])[012]$", "", text))
        return found

    def index(self, phoneme: str) -> int:
        return self.phonemes.index(phoneme)

    @property
    def labels(self) -> list[str]:
        """Every label the table accepts (ARPAbet phonemes, then TIMIT-only labels)."""
        extra = [a for a in self.aliases if a.upper() not in self.phonemes and a != SILENCE]
        return [*self.phonemes, *sorted(extra)]


def _number(text: str, where: str, path: Path) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not np.isfinite(value):
        raise InputError(path, f"{where}: {text!r} is not a number")
    return value


def _muscle_codes() -> list[str]:
    from workbench.services.templates.muscles import read_table71

    return [row["code"] for row in read_table71()]


def load_visemes(path: str | PathLike[str] | None = None) -> VisemeTable:
    """Read a viseme table (default: the built-in one); bad rows are :class:`InputError`."""
    p = builtin_viseme_table() if path is None else Path(path)
    return _load(str(p))


@lru_cache(maxsize=8)
def _load(path_text: str) -> VisemeTable:
    p = Path(path_text)
    try:
        text = p.read_text(encoding="utf-8-sig")
    except OSError as exc:
        raise InputError(p, f"cannot be read ({exc.strerror or exc})") from None
    numbered = [
        (i, ln)
        for i, ln in enumerate(text.splitlines(), start=1)
        if ln.strip() and not ln.lstrip().startswith("#")
    ]
    rows = list(csv.reader([ln for _, ln in numbered]))
    if not rows:
        raise InputError(p, "is empty", "a viseme table has a header row and one row per phoneme")
    header = [h.strip() for h in rows[0]]
    missing = [h for h in ("phoneme", *_DOMINANCE, JAW) if h not in header]
    if missing:
        raise InputError(p, f"has no column {', '.join(missing)}")
    codes = set(_muscle_codes())
    columns = [h for h in header if h not in _TEXT and h not in _DOMINANCE]
    bad = [
        h
        for h in columns
        if h != JAW
        and h not in codes
        and not (h.startswith(PROTRUSION) and h[len(PROTRUSION) :] in codes)
    ]
    if bad:
        raise InputError(
            p,
            f"column {', '.join(bad)} is neither a muscle, protrusion.<muscle> nor {JAW}",
            "muscle codes: " + ", ".join(sorted(codes)),
        )
    phonemes: list[str] = []
    classes: list[str] = []
    aliases: dict[str, str] = {}
    targets, dom = [], []
    for (line_no, _), cells in zip(numbered[1:], rows[1:], strict=True):
        row = dict(zip(header, cells, strict=False))
        where = f"line {line_no}"
        ph = (row.get("phoneme") or "").strip()
        if not ph:
            raise InputError(p, f"{where}: the phoneme is empty")
        canon = SILENCE if ph.lower() == SILENCE else ph.upper()
        if canon in phonemes:
            raise InputError(p, f"{where}: {ph} is listed twice")
        names = [canon.lower(), *[a.strip().lower() for a in (row.get("timit") or "").split(";")]]
        for name in filter(None, names):
            if aliases.get(name, canon) != canon:
                raise InputError(p, f"{where}: label {name} already belongs to {aliases[name]}")
            aliases[name] = canon
        values = [_number(row.get(h) or "", f"{where} ({ph}) {h}", p) for h in columns]
        d = [_number(row.get(h) or "", f"{where} ({ph}) {h}", p) for h in _DOMINANCE]
        if d[0] <= 0 or d[1] < 0 or d[2] < 0 or d[3] <= 0:
            raise InputError(p, f"{where} ({ph}): alpha and c must be > 0, theta >= 0")
        for h, v in zip(columns, values, strict=True):
            lo, hi = (
                JAW_RANGE_DEG if h == JAW else (-1.0, 1.0) if h.startswith(PROTRUSION) else (0, 1)
            )
            if not lo <= v <= hi:
                raise InputError(p, f"{where} ({ph}): {h} = {v:g} is outside {lo:g}..{hi:g}")
        phonemes.append(canon)
        classes.append((row.get("class") or "").strip())
        targets.append(values)
        dom.append(d)
    if SILENCE not in phonemes:
        raise InputError(p, f"has no {SILENCE} row", "silence needs its (neutral) targets")
    d_arr = np.asarray(dom, float).reshape(-1, 4)
    return VisemeTable(
        source=str(p),
        phonemes=tuple(phonemes),
        classes=tuple(classes),
        columns=tuple(columns),
        targets=np.asarray(targets, float).reshape(len(phonemes), len(columns)),
        alpha=d_arr[:, 0],
        theta_before=d_arr[:, 1],
        theta_after=d_arr[:, 2],
        c=d_arr[:, 3],
        aliases=aliases,
    )


@dataclass(frozen=True)
class Segment:
    """One phoneme from ``start`` to ``end`` (seconds); ``phoneme`` is the table's label."""

    phoneme: str
    start: float
    end: float

    @property
    def centre(self) -> float:
        return 0.5 * (self.start + self.end)


def dominance(
    tau: np.ndarray,
    alpha: np.ndarray,
    theta_before: np.ndarray,
    theta_after: np.ndarray,
    c: np.ndarray,
) -> np.ndarray:
    """Cohen & Massaro's ``alpha * exp(-theta * |tau|^c)``, ``tau = centre - t`` in seconds.

    ``theta_before`` applies where ``tau >= 0`` (``t`` before the centre),
    ``theta_after`` where ``tau < 0``; arrays broadcast.
    """
    tau = np.asarray(tau, float)
    theta = np.where(tau >= 0, theta_before, theta_after)
    return np.asarray(alpha) * np.exp(-theta * np.abs(tau) ** np.asarray(c))


@dataclass
class SpeechFrames:
    """Per-frame speech parameters (the table's columns) and each phoneme's share of them."""

    times: np.ndarray  #: ``(n,)`` seconds
    columns: tuple[str, ...]
    values: np.ndarray  #: ``(n, n_columns)``
    #: phoneme -> ``(n,)`` normalised dominance summed over its segments (rows sum to 1)
    weights: dict[str, np.ndarray]

    def column(self, name: str) -> np.ndarray:
        """``(n,)`` track of one column (zeros if the table has no such column)."""
        if name in self.columns:
            return self.values[:, self.columns.index(name)]
        return np.zeros(len(self.times))

    def muscles(self, codes: Sequence[str]) -> np.ndarray:
        """``(n, len(codes))`` contractions 0..1 in the order of ``codes``."""
        return np.stack([self.column(c) for c in codes], axis=1)

    def protrusion(self, codes: Sequence[str]) -> np.ndarray:
        """``(n, len(codes))`` sphincter protrusions -1..1 (0 for muscles without one)."""
        return np.stack([self.column(PROTRUSION + c) for c in codes], axis=1)

    @property
    def jaw_deg(self) -> np.ndarray:
        return self.column(JAW)


def _with_silences(segments: Sequence[Segment], t0: float, t1: float) -> list[Segment]:
    """The segments with every gap, the lead-in and the tail filled by silence pieces."""

    def pieces(a: float, b: float) -> list[Segment]:
        if b - a <= 1e-9:
            return []
        n = int(np.ceil((b - a) / SILENCE_PIECE_S - 1e-9))
        edges = np.linspace(a, b, n + 1)
        return [
            Segment(SILENCE, float(u), float(v)) for u, v in zip(edges[:-1], edges[1:], strict=True)
        ]

    if not segments:
        return pieces(min(t0, 0.0) - SILENCE_PIECE_S, t1 + SILENCE_PIECE_S)
    out = pieces(min(t0, segments[0].start) - SILENCE_PIECE_S, segments[0].start)
    for k, s in enumerate(segments):
        out.append(s)
        nxt = segments[k + 1].start if k + 1 < len(segments) else max(t1, s.end) + SILENCE_PIECE_S
        out.extend(pieces(s.end, nxt))
    return out


def coarticulate(
    segments: Iterable[Segment],
    times: np.ndarray,
    table: VisemeTable | None = None,
    reach: int = REACH,
) -> SpeechFrames:
    """Parameter tracks at ``times`` (seconds) for phoneme segments (in order, not overlapping).

    Segment phonemes must be labels of ``table`` (its :meth:`VisemeTable.canonical`
    form; the track parser checks them and names the file and entry).
    """
    table = table or load_visemes()
    t = np.asarray(times, float).reshape(-1)
    given = list(segments)
    segs = _with_silences(given, float(t.min(initial=0.0)), float(t.max(initial=0.0)))
    row = np.array([table.index(s.phoneme) for s in segs], np.int64)
    start = np.array([s.start for s in segs])
    centre = np.array([s.centre for s in segs])
    n_seg = len(segs)
    # the segment that holds each frame, and its window of neighbours
    k = np.clip(np.searchsorted(start, t, side="right") - 1, 0, n_seg - 1)
    idx = k[:, None] + np.arange(-reach, reach + 1)[None, :]
    valid = (idx >= 0) & (idx < n_seg)
    idx = np.clip(idx, 0, n_seg - 1)
    r = row[idx]
    tau = centre[idx] - t[:, None]
    theta = np.where(tau >= 0, table.theta_before[r], table.theta_after[r])
    # in logs, shifted per frame: no underflow however long a segment is
    log_d = np.log(table.alpha[r]) - theta * np.abs(tau) ** table.c[r]
    log_d = np.where(valid, log_d, -np.inf)
    d = np.exp(log_d - log_d.max(axis=1, keepdims=True))
    w = d / d.sum(axis=1, keepdims=True)
    values = np.einsum("fk,fkc->fc", w, table.targets[r])
    weights = {}
    for ph in dict.fromkeys(s.phoneme for s in segs):
        weights[ph] = np.where(r == table.index(ph), w, 0.0).sum(axis=1)
    return SpeechFrames(times=t, columns=table.columns, values=values, weights=weights)
