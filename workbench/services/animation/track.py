"""Keyframe tracks: expressions, muscles, jaw, gaze and lids over time, plus speech; frames.

A track (``workbench animate HEAD --track FILE.json``, or :func:`parse_track`
for scripts) is JSON::

    {"fps": 30,
     "keys": [{"t": 0.0, "expression": "neutral"},
              {"t": 0.5, "expression": "smile", "weight": 0.8},
              {"t": 0.9, "expressions": {"smile": 0.5, "surprise": 0.5}},
              {"t": 1.0, "muscles": {"mentalis": 0.4}, "jaw_deg": 8,
               "gaze": [10, -5], "lids": 0.5}],
     "phonemes": [{"p": "HH", "start": 1.2, "end": 1.3}, ...],
     "duration": 2.0}

Units: seconds, degrees (jaw positive opens; gaze ``[yaw toward the
subject's left, pitch up]``), contractions and weights 0..1, lids 0 (open)
.. 1 (closed).  ``fps`` defaults to 30, ``duration`` to the last key or the
last phoneme's end plus :data:`TAIL_S` (so the mouth returns to rest).

Each key is a **full pose** (Kähler's expression snapshots, seeds digest
13.2): the weighted sum of its expressions' activation vectors (clamped to
0..1, :func:`workbench.services.animation.animator.mix`), then its ``muscles``
replace those muscles' contractions, ``jaw_deg`` and ``lids`` replace the
mix's, ``gaze`` is ``[0, 0]`` unless given.  A key with none of these is
neutral.

Between two keys every parameter follows **smoothstep** (the cubic Hermite
curve with zero tangents at both keys, ``s = 3u² − 2u³``): the pose is the
convex combination ``(1 − s) P_k + s P_k+1``, so contractions stay within
0..1 and the jaw within its range without clipping, and the blend is exactly
a morph-target blend of the key poses (how the ``.glb`` clip is built).  The
motion eases in and out of every key (zero velocity at a key); before the
first key the first pose holds, after the last the last.

Speech (:mod:`workbench.services.animation.speech`, Cohen-Massaro coarticulation)
adds its mouth-muscle contractions, lip protrusions and jaw angle to the
keys' (sums clamped to 0..1, -1..1 and the jaw's range); silence adds
nothing, so without keys silence is the neutral face.

:func:`evaluate_track` is vectorised over all frames; :func:`play_track`
then runs the skin simulation frame by frame: the first frame is settled,
every later one is ``round(1 / (fps * time_step_s))`` simulation steps of
the :class:`~workbench.services.animation.animator.Animator` (20 steps of 1/600 s at
30 fps), so the skin moves with its own dynamics between frames.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from workbench.core.errors import InputError
from workbench.core.json_limits import read_json
from workbench.services.animation.animator import (
    EXPRESSIONS,
    GAZE_RANGE_DEG,
    JAW_RANGE_DEG,
    Animator,
    Expression,
    mix,
)
from workbench.services.animation.speech import (
    JAW,
    PROTRUSION,
    SILENCE,
    Segment,
    SpeechFrames,
    VisemeTable,
    coarticulate,
    load_visemes,
)

__all__ = [
    "DEFAULT_FPS",
    "TAIL_S",
    "Key",
    "Track",
    "TrackFrames",
    "evaluate_track",
    "glb_clip",
    "key_pose",
    "load_track",
    "parse_track",
    "play_track",
    "smoothstep",
]

DEFAULT_FPS = 30.0
#: frames per second accepted
FPS_RANGE = (1.0, 240.0)
#: seconds of silence after the last phoneme when the track gives no duration
TAIL_S = 0.3
#: longest track (seconds)
MAX_DURATION_S = 600.0
#: largest track file read (bytes): ten minutes at 60 fps with 60 channels is ~30 MB
MAX_TRACK_BYTES = 32 * 1024 * 1024
_TRACK_FIELDS = ("fps", "keys", "phonemes", "duration")
_KEY_FIELDS = ("t", "expression", "weight", "expressions", "muscles", "jaw_deg", "gaze", "lids")
_PHONEME_FIELDS = ("p", "start", "end")


def _muscle_codes() -> tuple[str, ...]:
    from workbench.services.templates.muscles import read_table71

    return tuple(row["code"] for row in read_table71())


@dataclass(frozen=True)
class Key:
    """One pose at time ``t`` (seconds); see the module docstring."""

    t: float
    expressions: Mapping[str, float] = field(default_factory=dict)
    muscles: Mapping[str, float] = field(default_factory=dict)
    jaw_deg: float | None = None
    gaze: tuple[float, float] = (0.0, 0.0)
    lids: float | None = None

    @property
    def is_mix(self) -> bool:
        """True when the pose is only a weighted sum of palette expressions (gaze aside)."""
        return not self.muscles and self.jaw_deg is None and self.lids is None


@dataclass(frozen=True)
class Track:
    """A validated track (times in seconds)."""

    fps: float
    keys: tuple[Key, ...]
    phonemes: tuple[Segment, ...]
    duration: float
    source: str = "track"

    @property
    def n_frames(self) -> int:
        return int(math.floor(self.duration * self.fps + 1e-9)) + 1

    def times(self) -> np.ndarray:
        """``(n_frames,)`` frame times in seconds, from 0 to the duration."""
        return np.arange(self.n_frames) / self.fps


def key_pose(key: Key) -> Expression:
    """The key's pose as an :class:`Expression` (gaze is not part of it)."""
    base = mix(dict(key.expressions)) if key.expressions else EXPRESSIONS["neutral"]
    muscles = {**base.muscles, **key.muscles}
    return Expression(
        muscles,
        dict(base.protrusion),
        base.jaw_deg if key.jaw_deg is None else key.jaw_deg,
        "key",
        base.lids if key.lids is None else key.lids,
    )


# ---------------------------------------------------------------------- parsing
class _Checker:
    def __init__(self, source: str) -> None:
        self.source = source

    def fail(self, where: str, problem: str, hint: str | None = None) -> InputError:
        return InputError(self.source, f"{where}: {problem}" if where else problem, hint)

    def number(self, value: Any, where: str, what: str, lo: float, hi: float) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise self.fail(where, f"{what} must be a number, not {json.dumps(value)}")
        v = float(value)
        if not math.isfinite(v) or not lo <= v <= hi:
            raise self.fail(where, f"{what} {v:g} is outside {lo:g}..{hi:g}")
        return v

    def fields(self, item: Any, where: str, allowed: Sequence[str]) -> Mapping[str, Any]:
        if not isinstance(item, Mapping):
            raise self.fail(where, f"must be an object, not {json.dumps(item)[:40]}")
        unknown = [k for k in item if k not in allowed]
        if unknown:
            raise self.fail(
                where,
                f"unknown field {', '.join(map(str, unknown))}",
                "fields: " + ", ".join(allowed),
            )
        return item


def _parse_key(ck: _Checker, item: Any, where: str, codes: Sequence[str]) -> Key:
    d = ck.fields(item, where, _KEY_FIELDS)
    if "t" not in d:
        raise ck.fail(where, "has no time t (seconds)")
    t = ck.number(d["t"], where, "time t", 0.0, MAX_DURATION_S)
    weights: dict[str, float] = {}
    raw_mix = d.get("expressions") or {}
    if not isinstance(raw_mix, Mapping):
        raise ck.fail(where, "expressions must be an object {NAME: weight}")
    pairs = list(raw_mix.items())
    if "expression" in d:
        pairs.append((d["expression"], d.get("weight", 1.0)))
    elif "weight" in d:
        raise ck.fail(where, "has a weight but no expression")
    for name, w in pairs:
        if not isinstance(name, str) or name not in EXPRESSIONS:
            raise ck.fail(
                where, f"{name!r} is not an expression", "valid names: " + ", ".join(EXPRESSIONS)
            )
        weights[name] = weights.get(name, 0.0) + ck.number(w, where, f"weight of {name}", 0.0, 1.0)
    muscles: dict[str, float] = {}
    raw = d.get("muscles") or {}
    if not isinstance(raw, Mapping):
        raise ck.fail(where, "muscles must be an object {NAME: contraction}")
    for code, c in raw.items():
        if code not in codes:
            raise ck.fail(where, f"{code!r} is not a muscle", "valid names: " + ", ".join(codes))
        muscles[code] = ck.number(c, where, f"contraction of {code}", 0.0, 1.0)
    jaw = None
    if d.get("jaw_deg") is not None:
        lo, hi = JAW_RANGE_DEG
        jaw = ck.number(d["jaw_deg"], where, "jaw_deg (degrees, positive opens)", lo, hi)
    gaze = (0.0, 0.0)
    if d.get("gaze") is not None:
        g = d["gaze"]
        if not isinstance(g, list | tuple) or len(g) != 2:
            raise ck.fail(where, "gaze must be [yaw_deg, pitch_deg]")
        gaze = (
            ck.number(g[0], where, "gaze yaw (degrees)", -GAZE_RANGE_DEG, GAZE_RANGE_DEG),
            ck.number(g[1], where, "gaze pitch (degrees)", -GAZE_RANGE_DEG, GAZE_RANGE_DEG),
        )
    lids = None
    if d.get("lids") is not None:
        lids = ck.number(d["lids"], where, "lids (0 open .. 1 closed)", 0.0, 1.0)
    return Key(t, weights, muscles, jaw, gaze, lids)


def _parse_phoneme(ck: _Checker, item: Any, where: str, table: VisemeTable) -> Segment:
    d = ck.fields(item, where, _PHONEME_FIELDS)
    for name in _PHONEME_FIELDS:
        if name not in d:
            raise ck.fail(where, f"has no {name}")
    label = d["p"]
    canon = table.canonical(label) if isinstance(label, str) else None
    if canon is None:
        raise ck.fail(
            where,
            f"{json.dumps(label)} is not an ARPAbet or TIMIT phoneme label",
            "labels: " + " ".join(table.labels),
        )
    start = ck.number(d["start"], where, "start", 0.0, MAX_DURATION_S)
    end = ck.number(d["end"], where, "end", 0.0, MAX_DURATION_S)
    if end <= start:
        raise ck.fail(where, f"ends ({end:g} s) before it starts ({start:g} s)")
    return Segment(canon, start, end)


def parse_track(
    data: Any, source: str | PathLike[str] = "track", table: VisemeTable | None = None
) -> Track:
    """A :class:`Track` from parsed JSON; every problem is an :class:`InputError` naming
    ``source`` and the key or phoneme index."""
    ck = _Checker(str(source))
    d = ck.fields(data, "", _TRACK_FIELDS)
    fps = DEFAULT_FPS if d.get("fps") is None else ck.number(d["fps"], "", "fps", *FPS_RANGE)
    raw_keys = d.get("keys") or []
    raw_ph = d.get("phonemes") or []
    if not isinstance(raw_keys, list) or not isinstance(raw_ph, list):
        raise ck.fail("", "keys and phonemes must be lists")
    if not raw_keys and not raw_ph:
        raise ck.fail("", "has neither keys nor phonemes", "see `workbench animate --help`")
    codes = _muscle_codes()
    keys = [_parse_key(ck, item, f"key {i}", codes) for i, item in enumerate(raw_keys)]
    for i in range(1, len(keys)):
        if keys[i].t <= keys[i - 1].t:
            raise ck.fail(
                f"key {i}",
                f"time {keys[i].t:g} s is not after key {i - 1}'s {keys[i - 1].t:g} s",
                "key times must increase",
            )
    table = table or load_visemes()
    phonemes = [_parse_phoneme(ck, item, f"phoneme {i}", table) for i, item in enumerate(raw_ph)]
    for i in range(1, len(phonemes)):
        if phonemes[i].start < phonemes[i - 1].end - 1e-9:
            raise ck.fail(
                f"phoneme {i}",
                f"starts at {phonemes[i].start:g} s, before phoneme {i - 1} ends "
                f"({phonemes[i - 1].end:g} s)",
                "phonemes must be in time order and must not overlap",
            )
    last = max([k.t for k in keys] + [p.end + TAIL_S for p in phonemes])
    if d.get("duration") is not None:
        duration = ck.number(d["duration"], "", "duration (seconds)", 0.0, MAX_DURATION_S)
    else:
        duration = min(last, MAX_DURATION_S)
    return Track(fps, tuple(keys), tuple(phonemes), duration, str(source))


def load_track(path: str | PathLike[str]) -> Track:
    """Read and validate a track JSON file.

    Read with :func:`workbench.core.json_limits.read_json`: a track over
    :data:`MAX_TRACK_BYTES` or nested deeper than the JSON limit is refused
    before it is decoded.
    """
    p = Path(path)
    if not p.is_file():
        reason = "is a folder, not a track file" if p.is_dir() else "does not exist"
        raise InputError(p, f"cannot be read ({reason})")
    data = read_json(p, max_bytes=MAX_TRACK_BYTES, what="track file")
    return parse_track(data, p)


# ---------------------------------------------------------------------- evaluation
def smoothstep(u: np.ndarray) -> np.ndarray:
    """``3u² − 2u³`` on [0, 1] (clamped): the cubic Hermite curve with zero end tangents."""
    u = np.clip(u, 0.0, 1.0)
    return u * u * (3.0 - 2.0 * u)


def key_weights(key_times: np.ndarray, times: np.ndarray) -> np.ndarray:
    """``(n_frames, n_keys)`` interpolation weights (rows sum to 1; two nonzero at most)."""
    kt = np.asarray(key_times, float)
    t = np.asarray(times, float)
    w = np.zeros((len(t), len(kt)))
    if len(kt) == 0:
        return w
    j = np.clip(np.searchsorted(kt, t, side="right") - 1, 0, len(kt) - 1)
    nxt = np.minimum(j + 1, len(kt) - 1)
    span = np.where(nxt > j, kt[nxt] - kt[j], 1.0)
    s = np.where(nxt > j, smoothstep((t - kt[j]) / span), 0.0)
    s = np.where(t < kt[0], 0.0, s)
    rows = np.arange(len(t))
    w[rows, j] += 1.0 - s
    w[rows, nxt] += s
    return w


@dataclass
class TrackFrames:
    """Per-frame parameters of a track, ready to drive an :class:`Animator`."""

    times: np.ndarray  #: ``(n,)`` seconds
    codes: tuple[str, ...]  #: muscle order of the columns
    contraction: np.ndarray  #: ``(n, n_muscles)`` 0..1
    protrusion: np.ndarray  #: ``(n, n_muscles)`` -1..1
    jaw_deg: np.ndarray  #: ``(n,)`` degrees, positive opens
    gaze: np.ndarray  #: ``(n, 2)`` degrees (yaw to the subject's left, pitch up)
    lids: np.ndarray  #: ``(n,)`` 0 open .. 1 closed
    key_weights: np.ndarray  #: ``(n, n_keys)`` smoothstep weights of the keys' poses
    speech: SpeechFrames | None = None

    @property
    def n_frames(self) -> int:
        return len(self.times)


def evaluate_track(
    track: Track, codes: Sequence[str] | None = None, table: VisemeTable | None = None
) -> TrackFrames:
    """Every frame's parameters at once (numpy over frames); ``codes``: the muscle order."""
    codes = tuple(codes) if codes is not None else _muscle_codes()
    t = track.times()
    n, m = len(t), len(codes)
    poses = [key_pose(k) for k in track.keys]
    # key poses as rows: contraction, protrusion, jaw, gaze (2), lids
    p = np.zeros((len(poses), 2 * m + 4))
    col = {c: i for i, c in enumerate(codes)}
    for r, (key, pose) in enumerate(zip(track.keys, poses, strict=True)):
        for c, value in pose.muscles.items():
            if c in col:
                p[r, col[c]] = value
        for c, value in pose.protrusion.items():
            if c in col:
                p[r, m + col[c]] = value
        p[r, 2 * m :] = [pose.jaw_deg, *key.gaze, pose.lids]
    w = key_weights(np.array([k.t for k in track.keys]), t)
    v = w @ p if len(poses) else np.zeros((n, 2 * m + 4))
    contraction, protrusion = v[:, :m], v[:, m : 2 * m]
    jaw = v[:, 2 * m]
    speech = None
    if track.phonemes:
        speech = coarticulate(track.phonemes, t, table)
        contraction = contraction + speech.muscles(codes)
        protrusion = protrusion + speech.protrusion(codes)
        jaw = jaw + speech.jaw_deg
    return TrackFrames(
        times=t,
        codes=codes,
        contraction=np.clip(contraction, 0.0, 1.0),
        protrusion=np.clip(protrusion, -1.0, 1.0),
        jaw_deg=np.clip(jaw, *JAW_RANGE_DEG),
        gaze=v[:, 2 * m + 1 : 2 * m + 3].copy(),
        lids=np.clip(v[:, 2 * m + 3], 0.0, 1.0),
        key_weights=w,
        speech=speech,
    )


# ---------------------------------------------------------------------- simulation
def steps_per_frame(anim: Animator, fps: float) -> int:
    """Simulation steps of the animator's time step in one frame (at least 1)."""
    return max(1, round(1.0 / (fps * anim.sim.params.time_step_s)))


def apply_frame(anim: Animator, frames: TrackFrames, i: int) -> None:
    """Set the animator's muscles, protrusions, jaw, gaze and lids to frame ``i``."""
    if tuple(frames.codes) != tuple(anim.muscle_codes):
        raise ValueError("the frames' muscle order is not the animator's")
    anim.set_muscles(
        dict(zip(frames.codes, frames.contraction[i].tolist(), strict=True)), reset=True
    )
    anim.set_protrusion(dict(zip(frames.codes, frames.protrusion[i].tolist(), strict=True)))
    anim.set_jaw(float(frames.jaw_deg[i]), anim.protrusion_mm)
    anim.set_gaze(float(frames.gaze[i, 0]), float(frames.gaze[i, 1]))
    anim.set_lids(float(frames.lids[i]))


def play_track(
    anim: Animator,
    frames: TrackFrames,
    fps: float,
    *,
    settle_first: bool = True,
) -> Iterator[int]:
    """Simulate the frames one by one; yields each frame's index once the skin is there.

    The caller reads the pose in between (``anim.skin()``, ``anim.meshes()``).
    Frame 0 is settled to rest in its pose (``settle_first``); every later
    frame is :func:`steps_per_frame` steps of the animator's own time step.
    """
    n_steps = steps_per_frame(anim, fps)
    for i in range(frames.n_frames):
        apply_frame(anim, frames, i)
        if i == 0 and settle_first:
            anim.settle()
        else:
            anim.step(n_steps)
        yield i


def run_track(
    anim: Animator,
    track: Track,
    on_frame: Callable[[int, Animator], None] | None = None,
    *,
    settle_first: bool = True,
) -> TrackFrames:
    """Evaluate ``track`` and simulate every frame, calling ``on_frame(i, anim)`` after each."""
    frames = evaluate_track(track, anim.muscle_codes)
    for i in play_track(anim, frames, track.fps, settle_first=settle_first):
        if on_frame is not None:
            on_frame(i, anim)
    return frames


# ---------------------------------------------------------------------- glTF clip
def glb_clip(
    track: Track, frames: TrackFrames, expression_targets: Sequence[str] = ()
) -> tuple[dict[str, Expression], list[tuple[float, dict[str, float]]]]:
    """Morph targets a track needs beyond the palette, and its clip as per-frame weights.

    Returns ``(poses, keyframes)``: ``poses`` are the extra targets to settle
    (``key_<i>`` for a key that is not a plain mix of ``expression_targets``,
    ``viseme_<PHONEME>`` for each spoken phoneme but silence); ``keyframes``
    are ``[(t, {target: weight})]`` at every frame: a mix key's smoothstep
    weight times its expression weights, a key pose's weight, and each
    phoneme's share of the Cohen-Massaro average.  A glTF frame is
    ``rest + Σ w Δ`` (linear blend of settled targets), an approximation of
    the simulated frame wherever several targets mix.  Gaze is not in it.
    """
    available = set(expression_targets)
    poses: dict[str, Expression] = {}
    columns: list[tuple[str, np.ndarray]] = []
    for i, key in enumerate(track.keys):
        w = frames.key_weights[:, i]
        # "neutral" is the rest shape: no target, no weight
        mixed = {n: k for n, k in key.expressions.items() if n != "neutral"}
        if key.is_mix and set(mixed) <= available:
            columns.extend((name, k * w) for name, k in mixed.items())
        else:
            poses[f"key_{i}"] = key_pose(key)
            columns.append((f"key_{i}", w))
    if frames.speech is not None:
        sp = frames.speech
        table = load_visemes()
        for ph, share in sp.weights.items():
            if ph == SILENCE or not np.any(share > 0):
                continue
            row = table.targets[table.index(ph)]
            values = dict(zip(table.columns, row.tolist(), strict=True))
            poses[f"viseme_{ph}"] = Expression(
                {c: v for c, v in values.items() if c != JAW and not c.startswith(PROTRUSION)},
                {c[len(PROTRUSION) :]: v for c, v in values.items() if c.startswith(PROTRUSION)},
                values.get(JAW, 0.0),
                f"viseme {ph}",
            )
            columns.append((f"viseme_{ph}", share))
    names = list(dict.fromkeys(name for name, _ in columns))
    total = {name: np.zeros(frames.n_frames) for name in names}
    for name, w in columns:
        total[name] += w
    keyframes = [
        (float(t), {name: float(total[name][i]) for name in names})
        for i, t in enumerate(frames.times)
    ]
    return poses, keyframes
