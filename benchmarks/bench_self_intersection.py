"""Benchmark: self-intersection check (issue 13: no self-intersections in the fitted skin).

Run ``python benchmarks/bench_self_intersection.py`` from the repository root
with ``../shared/data`` beside the checkout (or WORKBENCH_SAMPLE_MIRRORS set;
the reference head is built once, ~10 s, and cached in the user data folder).

Meshes (mm):

* ``reference skin``: the built-in male reference head's skin;
* ``icosphere 327k``: an icosahedron midpoint-subdivided 7 times onto a
  90 mm sphere (327 680 triangles, closed, no crossings);
* ``two icospheres 2 x 82k``: two 6-times subdivided icospheres of 90 mm
  overlapping by half a radius (many crossings along one circle).

Prints per mesh: triangles, candidate pairs tested exactly, intersecting
pairs, best wall seconds of ``--repeat`` runs, the tracemalloc peak of one
traced run (numpy and Python allocations in the check) and the process's
peak RSS so far.  No budgets, no assertions.
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import time
import tracemalloc
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data"
os.environ.setdefault("WORKBENCH_SAMPLE_MIRRORS", str(SHARED))
sys.path.insert(0, str(ROOT))

from workbench.core.mesh import Mesh, concatenate  # noqa: E402
from workbench.core.self_intersection import self_intersections  # noqa: E402


def icosphere(levels: int, radius: float) -> Mesh:
    """Closed icosphere: 20 * 4**levels triangles, outward winding."""
    t = (1.0 + 5.0**0.5) / 2.0
    v = np.array(
        [[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t]]
        + [[0, -1, -t], [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]],
        float,
    )
    f = np.array(
        [[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4]]
        + [[11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8]]
        + [[3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]]
    )
    for _ in range(levels):
        edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        key = edges[:, 0] * np.int64(len(v)) + edges[:, 1]
        uniq, inv = np.unique(key, return_inverse=True)
        mid = len(v) + inv.reshape(3, -1)
        v = np.vstack([v, 0.5 * (v[uniq // len(v)] + v[uniq % len(v)])])
        a, b, c = f.T
        ab, bc, ca = mid
        f = np.concatenate(
            [np.stack(x, 1) for x in ([a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca])]
        )
    return Mesh(radius * v / np.linalg.norm(v, axis=1, keepdims=True), f)


def meshes() -> dict[str, Mesh]:
    from workbench.services.templates.cache import reference_head

    sphere = icosphere(6, 90.0)
    return {
        "reference skin": reference_head("male").skin,
        "icosphere 327k": icosphere(7, 90.0),
        "two icospheres 2 x 82k": concatenate(
            [sphere, Mesh(sphere.vertices + [45.0, 3.0, 2.0], sphere.faces)]
        ),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(
        f"self-intersection benchmark, {os.cpu_count()} cores, load average {load:.2f}, "
        f"best of {args.repeat}"
    )
    t0 = time.perf_counter()
    cases = meshes()
    print(f"  (meshes built in {time.perf_counter() - t0:.1f} s)")
    print(
        f"  {'mesh':<24s} {'triangles':>10s} {'candidates':>11s} {'pairs':>6s} "
        f"{'seconds':>8s} {'traced MB':>10s} {'peak RSS MB':>12s}"
    )
    for name, mesh in cases.items():
        _ = mesh.triangles
        best = np.inf
        for _ in range(args.repeat):
            t = time.perf_counter()
            result = self_intersections(mesh)
            best = min(best, time.perf_counter() - t)
        tracemalloc.start()
        self_intersections(mesh)
        traced = tracemalloc.get_traced_memory()[1] / 2**20
        tracemalloc.stop()
        rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
        print(
            f"  {name:<24s} {mesh.n_faces:>10,d} {result.candidates:>11,d} {result.count:>6d} "
            f"{best:>8.3f} {traced:>10.0f} {rss:>12.0f}",
            flush=True,
        )
        if result.count and name == "reference skin":
            print(f"    intersecting faces: {result.faces.tolist()}")


if __name__ == "__main__":
    main()
