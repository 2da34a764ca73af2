"""Benchmark: mass-spring skin and muscle update (issue 14 speed targets).

Run ``python benchmarks/bench_animation.py`` from the repository root with
``../shared/data`` beside the checkout (or WORKBENCH_SAMPLE_MIRRORS set; the
reference head is built once, ~10 s, and cached).

Prints (no budgets, no assertions; targets from issue 14 in brackets):

* numba JIT compile time of the three kernels, from an empty cache and from
  the on-disk cache, each in a fresh process;
* simulation steps per second (one projective-dynamics local/global step of
  1/600 s) on a ~1k-vertex skin [>= 2000] and on the male reference head's
  skin [>= 300], compiled and numpy-only;
* one muscle update (24 muscles -> skin spring targets) in ms [< 1 ms];
* quasi-static settle of a smile on the reference head (iterations, s);
* keyframe track + speech evaluation (``--only-track`` runs just this):
  a 60 s track with keys every 0.5 s and ~600 phonemes at 30 fps, all
  frames at once (ms, µs a frame), against one simulated frame of the
  reference head (20 steps of 1/600 s plus setting the frame's parameters).

The ~1k-vertex skin is the reference skin decimated with fast-simplification
(its face side, z > -30 mm, simulated; the rest kinematic) over the cranium.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data"
os.environ.setdefault("WORKBENCH_SAMPLE_MIRRORS", str(SHARED))
sys.path.insert(0, str(ROOT))

from workbench.core.mass_spring import SkinSimulation  # noqa: E402
from workbench.core.spatial import MeshIndex  # noqa: E402
from workbench.services.animation.animator import Animator  # noqa: E402
from workbench.services.templates.cache import reference_head  # noqa: E402

_COMPILE_SNIPPET = """
import time, numpy as np
t0 = time.perf_counter()
from workbench.core import mass_spring as ms
t1 = time.perf_counter()
s = np.random.rand(50, 3); out = np.zeros_like(s)
i = np.arange(49, dtype=np.int64); j = i + 1
ms._springs_jit(s, i, j, np.ones(49), np.ones(49), out)
bn = np.array([0], np.int64); ptr = np.array([0, 1], np.int64); ring = np.array([0], np.int64)
faces = np.array([[0, 1, 2]], np.int64); v3 = np.zeros((1, 3)); w = np.ones(1)
ms._bone_jit(s, bn, ptr, ring, faces, np.ones(50), v3, np.ones(50), v3, v3, w, w, 2.0, out)
p = np.arange(3, dtype=np.int64); x = np.ones(3)
ms._lu_jit(p, np.arange(2, dtype=np.int64), x, p, np.arange(2, dtype=np.int64), x,
           np.arange(2, dtype=np.int64), np.arange(2, dtype=np.int64), np.ones((2, 3)),
           np.zeros((2, 3)), np.zeros((2, 3)))
t2 = time.perf_counter()
print(f"{t2 - t1:.3f}")
"""


def compile_seconds(cache_dir: str) -> float:
    env = dict(os.environ, NUMBA_CACHE_DIR=cache_dir)
    done = subprocess.run(
        [sys.executable, "-c", _COMPILE_SNIPPET],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    return float(done.stdout.strip().splitlines()[-1])


def steps_per_second(sim: SkinSimulation, seconds: float) -> float:
    sim.step(5)  # warm-up (and JIT load)
    n = 0
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        sim.step(20)
        n += 20
    return n / (time.perf_counter() - t0)


def decimated_skin(head, target_vertices: int = 1000):
    import fast_simplification

    v, f = head.skin.vertices, head.skin.faces
    reduction = 1.0 - target_vertices / len(v)
    pts, tris = fast_simplification.simplify(v.astype(np.float32), f.astype(np.int32), reduction)
    return np.asarray(pts, np.float64), np.asarray(tris, np.int64)


def track_evaluation(head, seconds: float = 60.0, reps: int = 5) -> None:
    """Print the cost of evaluating a long keyframe + phoneme track against the physics."""
    from workbench.services.animation.speech import load_visemes
    from workbench.services.animation.track import (
        apply_frame,
        evaluate_track,
        parse_track,
        steps_per_frame,
    )

    rng = np.random.default_rng(1)
    labels = [p for p in load_visemes().phonemes if p != "sil"]
    names = ["smile", "happiness", "surprise", "sadness", "au26", "neutral"]
    keys = [
        {"t": float(t), "expression": names[k % len(names)], "weight": float(rng.uniform(0.3, 1))}
        for k, t in enumerate(np.arange(0.0, seconds, 0.5))
    ]
    phonemes, t = [], 0.1
    while t < seconds - 0.5:
        d = float(rng.uniform(0.05, 0.11))
        phonemes.append({"p": str(rng.choice(labels)), "start": t, "end": t + d})
        t += d + (0.3 if rng.random() < 0.05 else 0.0)  # a pause now and then
    track = parse_track({"fps": 30, "keys": keys, "phonemes": phonemes})
    anim = Animator(head)
    evaluate_track(track, anim.muscle_codes)  # warm-up
    t0 = time.perf_counter()
    for _ in range(reps):
        frames = evaluate_track(track, anim.muscle_codes)
    ms = (time.perf_counter() - t0) / reps * 1e3
    n = frames.n_frames
    steps = steps_per_frame(anim, track.fps)
    apply_frame(anim, frames, 0)
    anim.step(steps)  # warm-up
    k = 30
    t0 = time.perf_counter()
    for i in range(1, k + 1):
        apply_frame(anim, frames, i)
        anim.step(steps)
    frame_ms = (time.perf_counter() - t0) / k * 1e3
    print(
        f"track evaluation: {n} frames ({track.duration:.1f} s at 30 fps), {len(keys)} keys, "
        f"{len(phonemes)} phonemes: {ms:.1f} ms for all frames, {ms / n * 1e3:.1f} us a frame; "
        f"one simulated frame of the reference head ({steps} steps + parameters): "
        f"{frame_ms:.1f} ms, {frame_ms / (ms / n):,.0f}x the track's share"
    )


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=3.0, help="wall time per steps/s figure")
    ap.add_argument("--only-track", action="store_true", help="only the track-evaluation figure")
    args = ap.parse_args()
    if args.only_track:
        track_evaluation(reference_head("male"))
        return 0

    with tempfile.TemporaryDirectory() as cache:
        cold = compile_seconds(cache)
        warm = compile_seconds(cache)
    print(
        f"numba JIT compile of the kernels: {cold:.2f} s from an empty cache, "
        f"{warm:.3f} s from the cache"
    )

    head = reference_head("male")
    cranium = MeshIndex(head.meshes["cranium"])
    v, f = decimated_skin(head)
    face_side = v[:, 2] > -30.0
    for compiled in (True, False):
        sim = SkinSimulation(v, f, cranium=cranium, simulated=face_side, compiled=compiled)
        sim.set_muscle_targets(np.zeros((0, 3)))
        rate = steps_per_second(sim, args.seconds)
        label = "numba" if compiled else "numpy"
        print(
            f"~1k skin ({len(v)} vertices, {int(face_side.sum())} simulated, "
            f"{len(sim.spring_i)} springs), {label}: {rate:,.0f} steps/s  [target >= 2000]"
        )

    for compiled in (True, False):
        anim = Animator(head, compiled=compiled)
        anim.set_expression("smile")
        anim.update_muscles()
        rate = steps_per_second(anim.sim, args.seconds)
        label = "numba" if compiled else "numpy"
        print(
            f"reference skin ({head.skin.n_vertices} vertices, {len(anim.sim.free)} simulated, "
            f"{len(anim.sim.spring_i)} springs), {label}: {rate:,.0f} steps/s  [target >= 300]"
        )

    anim = Animator(head)
    rng = np.random.default_rng(0)
    reps = 300
    t0 = time.perf_counter()
    for _ in range(reps):
        anim.contraction[:] = rng.uniform(0.0, 0.6, len(anim.contraction))
        anim.update_muscles()
    ms = (time.perf_counter() - t0) / reps * 1e3
    print(
        f"muscle update, {len(anim.muscle_codes)} muscles -> {len(anim.rig.nodes)} skin "
        f"targets: {ms:.3f} ms  [target < 1 ms]"
    )
    t0 = time.perf_counter()
    for k in range(reps):
        anim.set_jaw(10.0 * (k % 2))
        anim.update_muscles()
    ms = (time.perf_counter() - t0) / reps * 1e3
    print(f"muscle update with a new jaw angle (bone anchors moved too): {ms:.3f} ms")

    anim.relax()
    anim.set_expression("smile")
    t0 = time.perf_counter()
    n = anim.settle()
    print(f"settle a smile on the reference head: {n} iterations, {time.perf_counter() - t0:.2f} s")
    track_evaluation(head)
    return 0


if __name__ == "__main__":
    sys.exit(main())
