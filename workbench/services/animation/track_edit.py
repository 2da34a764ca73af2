"""Author keyframe tracks: a track back to JSON, keys added or replaced, saved atomically.

The counterpart of :mod:`workbench.services.animation.track` (which reads
and evaluates tracks) for the window's timeline and for scripts::

    track = new_track(duration=2.0)
    track = with_key(track, Key(0.5, {"smile": 0.8}))
    save_track(track, "smile.json")

Every edit returns a new :class:`Track` that went through
:func:`~workbench.services.animation.track.parse_track` again, so an edited
track is always one ``workbench animate --track`` accepts.  Units as there:
seconds, degrees, contractions 0..1.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from os import PathLike
from pathlib import Path
from typing import Any

from workbench.io.atomic import write_bytes_atomic
from workbench.io.outputs import output_file
from workbench.services.animation.track import DEFAULT_FPS, Key, Track, parse_track

__all__ = ["key_to_json", "new_track", "save_track", "track_to_json", "with_duration", "with_key"]


def key_to_json(key: Key) -> dict[str, Any]:
    """One key as the track format's object (fields left out when they are the default)."""
    out: dict[str, Any] = {"t": round(float(key.t), 6)}
    if key.expressions:
        out["expressions"] = {k: float(v) for k, v in key.expressions.items()}
    if key.muscles:
        out["muscles"] = {k: round(float(v), 6) for k, v in key.muscles.items()}
    if key.jaw_deg is not None:
        out["jaw_deg"] = round(float(key.jaw_deg), 6)
    if tuple(key.gaze) != (0.0, 0.0):
        out["gaze"] = [round(float(key.gaze[0]), 6), round(float(key.gaze[1]), 6)]
    if key.lids is not None:
        out["lids"] = round(float(key.lids), 6)
    return out


def track_to_json(track: Track) -> dict[str, Any]:
    """The track as the JSON object :func:`parse_track` reads (duration always written)."""
    return {
        "fps": float(track.fps),
        "duration": round(float(track.duration), 6),
        "keys": [key_to_json(k) for k in track.keys],
        "phonemes": [
            {"p": p.phoneme, "start": float(p.start), "end": float(p.end)} for p in track.phonemes
        ],
    }


def _reparsed(data: dict[str, Any], source: str) -> Track:
    return parse_track(data, source)


def new_track(duration: float = 2.0, fps: float = DEFAULT_FPS, source: str = "new track") -> Track:
    """A neutral track (one neutral key at 0 s) of ``duration`` seconds at ``fps``."""
    return _reparsed(
        {"fps": fps, "duration": duration, "keys": [{"t": 0.0, "expression": "neutral"}]}, source
    )


def with_key(track: Track, key: Key, *, tolerance_s: float | None = None) -> Track:
    """``track`` with ``key`` added in time order; a key within ``tolerance_s`` (default
    half a frame) of ``key.t`` is replaced.  The duration grows to ``key.t`` if needed."""
    tol = 0.5 / track.fps if tolerance_s is None else tolerance_s
    keys = [k for k in track.keys if abs(k.t - key.t) > tol]
    keys.append(key)
    keys.sort(key=lambda k: k.t)
    data = track_to_json(track)
    data["keys"] = [key_to_json(k) for k in keys]
    data["duration"] = max(float(track.duration), round(float(key.t), 6))
    return _reparsed(data, track.source)


def with_duration(track: Track, duration: float) -> Track:
    """``track`` lasting ``duration`` seconds (keys after it are kept but never reached)."""
    data = track_to_json(track)
    data["duration"] = float(duration)
    return _reparsed(data, track.source)


def save_track(
    track: Track,
    path: str | PathLike[str],
    inputs: Iterable[str | PathLike[str] | None] = (),
    *,
    force: bool = False,
) -> Path:
    """Write ``track`` as JSON to ``path`` atomically (temporary file beside it, then renamed).

    ``inputs`` (e.g. the track file it was opened from) are never replaced,
    not even with ``force``; an existing file is replaced only with ``force``
    and then kept as a numbered backup (:func:`workbench.io.outputs.output_file`).
    """
    text = json.dumps(track_to_json(track), indent=2) + "\n"
    with output_file(path, inputs, force) as out:
        write_bytes_atomic(out, text.encode("utf-8"))
    return Path(path)
