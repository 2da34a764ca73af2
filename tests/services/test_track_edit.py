"""Authoring tracks: JSON round trip, keys added/replaced, atomic save never over an input."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from workbench.core.errors import InputError
from workbench.services.animation.track import Key, load_track, parse_track
from workbench.services.animation.track_edit import (
    new_track,
    save_track,
    track_to_json,
    with_duration,
    with_key,
)

EXAMPLE = Path(__file__).resolve().parents[2] / "examples" / "hello_world_track.json"


def test_the_example_track_round_trips_through_json():
    track = load_track(EXAMPLE)
    again = parse_track(json.loads(json.dumps(track_to_json(track))), "again")
    assert again.fps == track.fps and again.duration == track.duration
    assert again.keys == track.keys
    assert again.phonemes == track.phonemes


def test_keys_are_added_in_time_order_and_replaced_within_half_a_frame():
    track = new_track(1.0)
    track = with_key(track, Key(0.5, muscles={"mentalis": 0.4}, jaw_deg=6.0, gaze=(5.0, -2.0)))
    track = with_key(track, Key(0.25, {"smile": 0.7}, lids=0.3))
    assert [k.t for k in track.keys] == [0.0, 0.25, 0.5]
    track = with_key(track, Key(0.51, {"surprise": 1.0}))  # 0.01 s < 1/60 s: replaces 0.5
    assert [k.t for k in track.keys] == [0.0, 0.25, 0.51]
    assert dict(track.keys[2].expressions) == {"surprise": 1.0}
    track = with_key(track, Key(1.5))
    assert track.duration == 1.5  # grows to the new key
    assert with_duration(track, 3.0).duration == 3.0
    with pytest.raises(InputError, match="mentalis_x"):
        with_key(track, Key(0.7, muscles={"mentalis_x": 0.2}))


def test_save_is_atomic_and_never_replaces_an_input(tmp_path):
    track = with_key(new_track(1.0), Key(1.0, {"smile": 1.0}))
    out = save_track(track, tmp_path / "t.json")
    assert load_track(out).keys == track.keys
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.json"]  # no temporary left
    with pytest.raises(InputError, match="already exists"):
        save_track(track, out)
    save_track(with_duration(track, 2.0), out, force=True)
    assert load_track(out).duration == 2.0
    assert (tmp_path / "t.1.json").is_file()  # the replaced one kept
    before = out.read_bytes()
    with pytest.raises(InputError, match="input"):
        save_track(track, out, [out], force=True)
    assert out.read_bytes() == before
