"""Benchmark: geometry core budgets (landmark warp, ray casting, closest points).

Run ``python benchmarks/bench_geometry.py`` from the repository root (the
real test data must sit in ``../shared/data`` or ``$WORKBENCH_SHARED_DATA``).
Every figure is the best of three runs (``--repeat``): on the 2-core
reference machine run-to-run noise is up to ~2x.

Budgets
-------
* warp: fit 500 landmarks + apply to 250 000 points < 0.3 s;
* 10⁵ rays (first hit) on a ≥ 250k-triangle mesh < 0.5 s (BVH build apart);
* 10⁵ exact closest-point queries near the surface (surface points plus
  N(0, 2 mm) per axis) on the same mesh < 0.5 s (index build apart).

Meshes
------
``head``
    The headsq CT skin iso-surface, midpoint-subdivided once (220k
    triangles), with the real skull (100k triangles) scaled into it: a
    real-ish, two-sheet surface of 320k triangles.
``sphere``
    A UV sphere of radius 90 mm with 250k triangles.

Closest-point queries are also reported 5-15 mm off the surface and
uniform in the bounding box (no budget: far points need many candidates).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from workbench.core.mesh import Mesh  # noqa: E402
from workbench.core.raycast import RayCaster  # noqa: E402
from workbench.core.spatial import MeshIndex, winding_numbers  # noqa: E402
from workbench.core.tps import fit_warp  # noqa: E402
from workbench.core.unique import unique_ints  # noqa: E402

DATA = Path(os.environ.get("WORKBENCH_SHARED_DATA", ROOT.parent / "shared" / "data"))
N_QUERIES = 100_000


def best_of(fn: Callable[[], object], repeat: int) -> tuple[float, float]:
    """Best wall-clock and best process CPU time (all threads) over ``repeat`` runs."""
    wall = cpu = np.inf
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall = min(wall, time.perf_counter() - t0)
        cpu = min(cpu, time.process_time() - c0)
    return wall, cpu


def subdivide(mesh: Mesh) -> Mesh:
    """Split every triangle into four at its edge midpoints."""
    f = mesh.faces
    edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    key = edges[:, 0] * np.int64(mesh.n_vertices) + edges[:, 1]
    uniq, inv = np.unique(key, return_inverse=True)
    a_idx, b_idx = uniq // mesh.n_vertices, uniq % mesh.n_vertices
    v = np.vstack([mesh.vertices, 0.5 * (mesh.vertices[a_idx] + mesh.vertices[b_idx])])
    ab, bc, ca = mesh.n_vertices + inv.reshape(3, -1)
    a, b, c = f.T
    faces = np.concatenate(
        [np.stack(t, 1) for t in ([a, ab, ca], [ab, b, bc], [ca, bc, c], [ab, bc, ca])]
    )
    return Mesh(v, faces)


def uv_sphere(radius: float, n_faces: int) -> Mesh:
    """Closed UV sphere with about ``n_faces`` triangles, outward winding."""
    rings = int(np.sqrt(n_faces / 4))
    segs = 2 * rings
    theta = np.linspace(0, np.pi, rings + 1)[1:-1]
    phi = np.linspace(0, 2 * np.pi, segs, endpoint=False)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    body = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1).reshape(-1, 3)
    v = np.vstack([[0, 0, 1], body, [0, 0, -1]]) * radius
    idx = 1 + np.arange((rings - 1) * segs).reshape(rings - 1, segs)
    nxt = np.roll(idx, -1, axis=1)
    faces = [np.stack([np.zeros(segs, int), idx[0], nxt[0]], 1)]
    for r in range(rings - 2):
        faces.append(np.stack([idx[r], idx[r + 1], nxt[r + 1]], 1))
        faces.append(np.stack([idx[r], nxt[r + 1], nxt[r]], 1))
    south = len(v) - 1
    faces.append(np.stack([np.full(segs, south), nxt[-1], idx[-1]], 1))
    return Mesh(v, np.concatenate(faces))


def head_mesh() -> Mesh:
    from workbench.io.meshes import read_mesh
    from workbench.services.ct.ct_mesh import mesh_from_ct

    skin = subdivide(
        mesh_from_ct(DATA / "vtk_headsq_quarter_ct" / "headsq" / "quarter.nhdr", tissue="skin").mesh
    )
    skull = read_mesh(DATA / "skull_mesh_yahoojapan" / "skull.obj", units="cm").mesh
    s_lo, s_hi = skin.bounds
    k_lo, k_hi = skull.bounds
    scale = 0.8 * float(np.min((s_hi - s_lo) / (k_hi - k_lo)))
    placed = (skull.vertices - 0.5 * (k_lo + k_hi)) * scale + 0.5 * (s_lo + s_hi)
    return Mesh(
        np.vstack([skin.vertices, placed]), np.vstack([skin.faces, skull.faces + skin.n_vertices])
    )


def surface_points(mesh: Mesh, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    f = rng.integers(0, mesh.n_faces, n)
    w = rng.dirichlet(np.ones(3), n)
    return np.einsum("ij,ijk->ik", w, mesh.triangles[f]), mesh.face_normals[f]


def rays(mesh: Mesh, n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Half from a surrounding sphere toward the bounding box, half inward from 5 mm out."""
    lo, hi = mesh.bounds
    u = rng.normal(size=(n // 2, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    o1 = 0.5 * (lo + hi) + u * np.linalg.norm(hi - lo)
    d1 = rng.uniform(lo, hi, (n // 2, 3)) - o1
    p, nrm = surface_points(mesh, n - n // 2, rng)
    return np.vstack([o1, p + 5.0 * nrm]), np.vstack([d1, -nrm + 0.2 * rng.normal(size=nrm.shape)])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    rep = args.repeat
    rng = np.random.default_rng(0)
    rows: list[tuple[str, float, float, float | None]] = []

    def row(name: str, times: tuple[float, float], budget: float | None = None) -> None:
        seconds, cpu = times
        rows.append((name, seconds, cpu, budget))
        ratio = f"{seconds / budget:5.2f}" if budget else "    -"
        print(f"  {name:<52s} {seconds:8.3f} s  {ratio}", flush=True)

    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(
        f"geometry benchmark, {os.cpu_count()} cores, load average {load:.2f} "
        f"(other processes competing for the cores inflate wall times), best of {rep}"
    )
    # ------------------------------------------------------------ warp
    for n_lm in (60, 500):
        src = rng.uniform(-80, 80, (n_lm, 3))
        dst = src + 4.0 * np.sin(src / 30.0) + rng.normal(0, 1.0, src.shape)
        row(f"warp: fit {n_lm} landmarks", best_of(lambda: fit_warp(src, dst), rep))
        for n_pts in (100_000, 250_000, 1_000_000):
            pts = rng.uniform(-100, 100, (n_pts, 3))
            budget = 0.3 if (n_lm, n_pts) == (500, 250_000) else None
            row(
                f"warp: fit {n_lm} + apply to {n_pts:,} points",
                best_of(lambda: fit_warp(src, dst)(pts), rep),
                budget,
            )

    # ------------------------------------------------------------ meshes
    t0 = time.perf_counter()
    meshes = {"head": head_mesh(), "sphere": uv_sphere(90.0, 250_000)}
    print(
        f"  (meshes built in {time.perf_counter() - t0:.1f} s: "
        + ", ".join(f"{k} {m.n_faces:,} triangles" for k, m in meshes.items())
        + ")"
    )
    for name, mesh in meshes.items():
        _ = mesh.triangles, mesh.face_cross
        # the edge table (every mesh check needs it): one sort against np.unique
        e = mesh.edges_sorted
        key = e[:, 0] * np.int64(mesh.n_vertices) + e[:, 1]
        t_np = best_of(lambda: np.unique(key, return_inverse=True, return_counts=True), rep)
        t_ours = best_of(lambda: unique_ints(key), rep)
        row(f"edge table: np.unique with inverse, {name}", t_np)
        row(f"edge table: unique_ints ({t_np[0] / t_ours[0]:.1f}x faster), {name}", t_ours)
        # rays
        row(f"rays: Embree BVH build, {name}", best_of(lambda: RayCaster(mesh, "embree"), rep))
        caster = RayCaster(mesh, "embree")
        o, d = rays(mesh, N_QUERIES, rng)
        row(f"rays: 10^5 first hits, {name}", best_of(lambda: caster.first_hits(o, d), rep), 0.5)
        row(
            f"rays: 10^5 first hits, back faces culled, {name}",
            best_of(lambda: caster.first_hits(o, d, cull_backfaces=True), rep),
        )
        numpy_caster = RayCaster(mesh, "numpy")
        row(
            f"rays: 10^4 first hits, numpy backend, {name}",
            best_of(lambda: numpy_caster.first_hits(o[:10_000], d[:10_000]), 1),
        )
        # closest points
        row(f"closest: index build, {name}", best_of(lambda: MeshIndex(mesh), rep))
        index = MeshIndex(mesh)
        p, nrm = surface_points(mesh, N_QUERIES, rng)
        lo, hi = mesh.bounds
        direction = rng.normal(size=(N_QUERIES, 3))
        direction /= np.linalg.norm(direction, axis=1, keepdims=True)
        queries = {
            "near (N(0, 2 mm))": (p + rng.normal(0, 2.0, p.shape), 0.5),
            "5-15 mm off": (p + direction * rng.uniform(5, 15, (N_QUERIES, 1)), None),
            "uniform in bbox": (rng.uniform(lo, hi, (N_QUERIES, 3)), None),
        }
        for label, (q, budget) in queries.items():
            row(
                f"closest: 10^5 {label}, {name}",
                best_of(lambda q=q: index.closest_points(q), rep),
                budget,
            )
        near = queries["near (N(0, 2 mm))"][0]
        row(
            f"signed distance: 10^5 near (closest + sign), {name}",
            best_of(lambda: index.signed_distance(near), rep),
        )
        winding_numbers(mesh, near[:1])  # compile / load the kernel outside the timing
        row(
            f"winding number: 100 points (fold fallback), {name}",
            best_of(lambda: winding_numbers(mesh, near[:100]), rep),
        )

    print()
    print(f"{'figure':<54s} {'wall s':>8s} {'cpu s':>7s} {'budget':>7s} {'ratio':>6s}")
    for name, seconds, cpu, budget in rows:
        b = f"{budget:7.2f}" if budget else f"{'-':>7s}"
        r = f"{seconds / budget:6.2f}" if budget else f"{'-':>6s}"
        print(f"{name:<54s} {seconds:8.3f} {cpu:7.3f} {b} {r}")
    print(
        "(wall: best wall-clock time, the budgeted figure; cpu: best process CPU time, "
        "summed over threads)"
    )
    over = [name for name, s, _, b in rows if b and s > b]
    print("\nall budgets met" if not over else f"\nover budget: {', '.join(over)}")


if __name__ == "__main__":
    main()
