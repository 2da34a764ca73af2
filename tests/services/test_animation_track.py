"""Keyframe tracks: parsing and its errors, smoothstep keys, mixing, speech on top, frames, clip."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from workbench.core.errors import InputError
from workbench.services.animation.animator import EXPRESSIONS, Animator, mix
from workbench.services.animation.track import (
    TAIL_S,
    evaluate_track,
    glb_clip,
    key_weights,
    load_track,
    parse_track,
    play_track,
    smoothstep,
    steps_per_frame,
)

ZYG = "zygomaticus_major_l"


def test_parse_defaults_and_times() -> None:
    tr = parse_track(
        {
            "keys": [{"t": 0.0}, {"t": 0.5, "expression": "smile", "weight": 0.8}],
            "phonemes": [
                {"p": "hh", "start": 0.6, "end": 0.7},
                {"p": "AH0", "start": 0.7, "end": 0.8},
            ],
        }
    )
    assert tr.fps == 30.0
    assert tr.duration == pytest.approx(0.8 + TAIL_S)
    assert tr.n_frames == 34 and tr.times()[-1] == pytest.approx(1.1)
    assert [p.phoneme for p in tr.phonemes] == ["HH", "AH"]
    assert tr.keys[1].expressions == {"smile": 0.8}
    assert parse_track({"fps": 24, "keys": [{"t": 0}], "duration": 2}).n_frames == 49


def test_smoothstep_between_keys() -> None:
    w = key_weights(np.array([0.0, 1.0, 3.0]), np.array([-1.0, 0.0, 0.25, 0.5, 1.0, 2.0, 3.0, 9.0]))
    assert np.allclose(w.sum(axis=1), 1.0)
    assert np.allclose(w[:, 0], [1, 1, 1 - smoothstep(0.25), 0.5, 0, 0, 0, 0])
    assert np.allclose(w[:, 2], [0, 0, 0, 0, 0, 0.5, 1, 1])
    # zero slope at a key (ease in/out), the cubic 3u^2 - 2u^3 between
    assert smoothstep(np.array(1e-3)) < 1e-5
    assert smoothstep(np.array(0.25)) == pytest.approx(3 * 0.25**2 - 2 * 0.25**3)


def test_keys_mix_override_and_interpolate() -> None:
    tr = parse_track(
        {
            "fps": 10,
            "keys": [
                {"t": 0.0, "expressions": {"smile": 0.5, "surprise": 0.5}},
                {"t": 1.0, "expression": "smile", "muscles": {ZYG: 0.1, "mentalis": 0.4}},
                {"t": 2.0, "jaw_deg": 8, "gaze": [10, -5], "lids": 0.5},
            ],
        }
    )
    f = evaluate_track(tr)
    col = {c: i for i, c in enumerate(f.codes)}
    m = mix({"smile": 0.5, "surprise": 0.5})
    assert f.contraction[0, col[ZYG]] == pytest.approx(m.muscles[ZYG])
    assert f.jaw_deg[0] == pytest.approx(m.jaw_deg)
    # key 1: the smile with the muscles replaced (left zygomaticus) or added (mentalis)
    assert f.contraction[10, col[ZYG]] == pytest.approx(0.1)
    assert f.contraction[10, col["zygomaticus_major_r"]] == pytest.approx(
        EXPRESSIONS["smile"].muscles["zygomaticus_major_r"]
    )
    assert f.contraction[10, col["mentalis"]] == pytest.approx(0.4)
    # half way from key 1 to key 2 (t = 1.5): the mean of the two poses
    assert f.contraction[15, col["mentalis"]] == pytest.approx(0.2)
    assert f.jaw_deg[15] == pytest.approx(4.0)
    assert np.allclose(f.gaze[15], [5.0, -2.5]) and np.allclose(f.gaze[20], [10.0, -5.0])
    assert f.lids[20] == pytest.approx(0.5)
    # key 2 names no expression: everything else relaxed there
    assert f.contraction[20, col[ZYG]] == 0.0
    # a quarter of the way the smoothstep weight, not the linear one
    s = smoothstep(np.array(0.3))
    want = (1 - s) * m.muscles["frontalis_inner_l"]
    assert f.contraction[3, col["frontalis_inner_l"]] == pytest.approx(want)


def test_mixing_is_clamped() -> None:
    tr = parse_track(
        {"keys": [{"t": 0, "expressions": {"smile": 1.0, "happiness": 1.0, "au12": 1.0}}]}
    )
    f = evaluate_track(tr)
    assert f.contraction.max() <= 1.0
    assert f.contraction[0, f.codes.index(ZYG)] == pytest.approx(1.0)


def test_speech_adds_to_the_keys() -> None:
    keys = [{"t": 0.0, "expression": "smile"}]
    ph = [{"p": "UW", "start": 0.2, "end": 0.4}]
    both = evaluate_track(parse_track({"keys": keys, "phonemes": ph}))
    keys_only = evaluate_track(parse_track({"keys": keys, "duration": both.times[-1]}))
    speech_only = evaluate_track(parse_track({"phonemes": ph}))
    assert both.speech is not None and keys_only.speech is None
    want = np.clip(keys_only.contraction + speech_only.contraction, 0, 1)
    assert np.allclose(both.contraction, want)
    assert np.allclose(both.jaw_deg, keys_only.jaw_deg + speech_only.jaw_deg)
    oo = both.codes.index("orbicularis_oris_upper")
    assert both.protrusion[9, oo] > 0.5  # the /uw/ rounds the smiling lips
    assert np.abs(speech_only.contraction[-1]).max() < 0.02  # silence after it: neutral


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"keys": [{"t": 0}, {"t": 1, "expression": "joy"}]}, r"key 1: 'joy' is not an expression"),
        (
            {"keys": [{"t": 0, "muscles": {"zygomatic": 0.3}}]},
            r"key 0: 'zygomatic' is not a muscle",
        ),
        ({"keys": [{"t": 0}, {"t": 2}, {"t": 1}]}, r"key 2: time 1 s is not after key 1"),
        ({"keys": [{"t": 0, "expression": "smile", "weight": 1.5}]}, r"key 0: weight of smile 1.5"),
        ({"keys": [{"t": 0, "jaw_deg": 90}]}, r"key 0: jaw_deg .* 90 is outside -5..35"),
        ({"keys": [{"t": 0, "lids": -1}]}, r"key 0: lids"),
        ({"keys": [{"t": 0, "gaze": [80, 0]}]}, r"key 0: gaze yaw"),
        ({"keys": [{"t": 0, "jaw": 5}]}, r"key 0: unknown field jaw .*jaw_deg"),
        ({"keys": [{"t": "soon"}]}, r"key 0: time t must be a number"),
        ({"keys": [{"t": 0, "expressions": ["smile"]}]}, r"key 0: expressions must be an object"),
        ({"keys": [{"t": 0, "expression": ["smile"]}]}, r"key 0: \['smile'\] is not an expression"),
        ({"keys": [{"t": 0, "weight": 0.5}]}, r"key 0: has a weight but no expression"),
        ([{"t": 0}], r"must be an object"),
        (
            {"phonemes": [{"p": "XX", "start": 0, "end": 0.1}]},
            r"phoneme 0: \"XX\" is not an ARPAbet",
        ),
        (
            {
                "phonemes": [
                    {"p": "M", "start": 0, "end": 0.2},
                    {"p": "AA", "start": 0.1, "end": 0.3},
                ]
            },
            r"phoneme 1: starts at 0.1 s, before phoneme 0 ends",
        ),
        ({"phonemes": [{"p": "M", "start": 0.3, "end": 0.2}]}, r"phoneme 0: ends"),
        ({"fps": 0, "keys": [{"t": 0}]}, r"fps 0 is outside"),
        ({}, r"neither keys nor phonemes"),
    ],
)
def test_bad_tracks_name_the_file_and_entry(tmp_path: Path, data, message) -> None:
    path = tmp_path / "speech.json"
    path.write_text(json.dumps(data), "utf-8")
    with pytest.raises(InputError, match=message) as err:
        load_track(path)
    assert str(path) in str(err.value)


def test_unreadable_track(tmp_path: Path) -> None:
    path = tmp_path / "t.json"
    path.write_text("{keys: [", "utf-8")
    with pytest.raises(InputError, match="is not valid JSON"):
        load_track(path)
    with pytest.raises(InputError, match="cannot be read"):
        load_track(tmp_path / "missing.json")


def test_clip_weights_follow_the_track() -> None:
    tr = parse_track(
        {
            "fps": 10,
            "keys": [
                {"t": 0, "expression": "neutral"},
                {"t": 1, "expression": "smile", "weight": 0.6},
                {"t": 2, "muscles": {"mentalis": 0.5}},
            ],
            "phonemes": [
                {"p": "M", "start": 0.4, "end": 0.5},
                {"p": "AA", "start": 0.5, "end": 0.6},
            ],
        }
    )
    f = evaluate_track(tr)
    poses, keyframes = glb_clip(tr, f, ["smile"])
    assert set(poses) == {"key_2", "viseme_M", "viseme_AA"}
    assert poses["key_2"].muscles == {"mentalis": 0.5}
    assert poses["viseme_AA"].jaw_deg > 3.0 and poses["viseme_M"].jaw_deg == 0.0
    times = [t for t, _ in keyframes]
    assert np.allclose(times, f.times)
    smile = np.array([w["smile"] for _, w in keyframes])
    assert np.allclose(smile, 0.6 * f.key_weights[:, 1])
    assert smile[5] == pytest.approx(0.3)
    m = np.array([w["viseme_M"] for _, w in keyframes])
    assert m.argmax() in (4, 5) and m.max() > 0.5
    assert "neutral" not in keyframes[0][1]


# ---------------------------------------------------------------------- frames on the reference head
def test_frames_step_the_animator(head_male) -> None:
    """Frame 0 is the settled pose; later frames are the animator's steps, 20 at 30 fps."""
    anim = Animator(head_male)
    assert steps_per_frame(anim, 30.0) == 20 and steps_per_frame(anim, 60.0) == 10
    tr = parse_track(
        {"fps": 30, "keys": [{"t": 0, "expression": "smile"}, {"t": 0.1, "jaw_deg": 10}]}
    )
    f = evaluate_track(tr, anim.muscle_codes)
    ref = Animator(head_male)
    ref.set_expression("smile")
    ref.settle()
    want0 = ref.skin_in_head_frame()
    poses = []
    for i in play_track(anim, f, tr.fps):
        poses.append(anim.skin_in_head_frame())
        if i == 1:  # one frame = 20 steps of the same dynamics from the same state
            ref.set_muscles(dict(zip(f.codes, f.contraction[1], strict=True)), reset=True)
            ref.set_jaw(float(f.jaw_deg[1]))
            ref.step(20)
            assert np.abs(poses[1] - ref.skin_in_head_frame()).max() < 1e-6
    assert len(poses) == 4
    assert np.abs(poses[0] - want0).max() < 1e-6
    chin = head_male.skin.vertices[:, 1] < -80
    assert (poses[0][chin, 1] - poses[-1][chin, 1]).max() > 5.0  # the jaw opened meanwhile
    assert anim.jaw_deg == pytest.approx(10.0)


def test_the_example_track_parses() -> None:
    example = Path(__file__).resolve().parents[2] / "examples" / "hello_world_track.json"
    tr = load_track(example)
    assert [p.phoneme for p in tr.phonemes][:4] == ["HH", "AH", "L", "OW"]
    f = evaluate_track(tr)
    assert f.n_frames == 61 and f.lids.max() == pytest.approx(1.0)
