"""Benchmark: bone surface from a 512 x 512 x 400 int16 head CT (budget 20 s, 3 GB).

Run ``python benchmarks/bench_ct.py`` from the repository root.  The script

1. builds a synthetic head CT in Hounsfield units (512 x 512 x 400 int16,
   0.5 x 0.5 x 0.625 mm): air -1000 HU, an ellipsoidal head of soft tissue
   (40 HU) with a neck, a skull shell of 1200 HU whose thickness varies
   between 5 and 8 mm, a cranial base plate with a foramen magnum, a
   mandible-like arc joined to the base by two rami, and Gaussian noise
   (sigma 20 HU);
2. runs each case in a fresh child process (so peak RSS is per case and
   includes the 200 MB volume): the core extraction without and with
   ``target_triangles=200000`` and the full service (with validation);
3. prints wall time, peak RSS (``resource.getrusage``), the tracemalloc peak
   of numpy/Python allocations during the extraction (separate traced run),
   triangle counts and the ratio to the 20 s / 3 GB budgets.

Options: ``--no-tracemalloc`` skips the traced runs; ``--keep DIR`` keeps the
phantom as ``DIR/phantom.npy``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SHAPE = (400, 512, 512)  # (k, j, i)
SPACING = (0.5, 0.5, 0.625)  # (i, j, k) mm
TIME_BUDGET_S = 20.0
RSS_BUDGET_MB = 3 * 1024.0
CASES = {
    "core, no decimation": {"service": False, "target": None},
    "core, target 200k": {"service": False, "target": 200_000},
    "service (read+extract+validate), target 200k": {"service": True, "target": 200_000},
}


def synthetic_head_ct(seed: int = 0) -> np.ndarray:
    """``(400, 512, 512)`` int16 head phantom in HU, built slice by slice (x = i, y = j, z = k).

    Head frame (mm, origin at the head centre): x left-right, y posterior
    (the face is at -y), z superior.
    """
    nk, nj, ni = SHAPE
    rng = np.random.default_rng(seed)
    x = (np.arange(ni) - ni / 2 + 0.5) * SPACING[0]
    y = (np.arange(nj) - nj / 2 + 0.5) * SPACING[1]
    X, Y = np.meshgrid(x, y)  # (j, i)
    a, b, c = 75.0, 95.0, 115.0  # head semi-axes (mm)
    angle = np.arctan2(Y, X)
    thickness = 6.5 + 1.5 * np.cos(3 * angle)  # skull 5-8 mm
    outer = 1.0 - 6.0 / a  # 6 mm of scalp
    inner = outer - thickness / a
    # mandible arc in the axial plane: x = 45 cos t, y = 10 - 60 sin t, t in [0.15 pi, 0.85 pi]
    t = np.linspace(0.15 * np.pi, 0.85 * np.pi, 200)
    arc = np.stack([45 * np.cos(t), 10 - 60 * np.sin(t)], axis=1)
    rami = arc[[0, -1]]
    out = np.empty(SHAPE, np.int16)
    for k in range(nk):
        z = (k - nk / 2 + 0.5) * SPACING[2]
        sl = np.full((nj, ni), -1000.0, np.float32)
        r = np.sqrt((X / a) ** 2 + (Y / b) ** 2 + (z / c) ** 2)
        sl[r < 1.0] = 40.0
        if z < -40:  # neck
            sl[(X / 55) ** 2 + ((Y - 15) / 60) ** 2 < 1.0] = 40.0
        bone = (r < outer) & (r > inner) & (z > -35)
        if -38 < z < -30:  # cranial base with a foramen magnum
            base = (r < outer) & ~((X / 15) ** 2 + ((Y - 25) / 18) ** 2 < 1.0)
            bone |= base
        if -78 < z < -52:  # mandible body
            d = np.full(X.shape, np.inf, np.float32)
            for px, py in arc[::4]:
                d = np.minimum(d, (X - px) ** 2 + (Y - py) ** 2)
            bone |= d < 6.0**2
        if -78 < z < -32:  # rami up to the base
            for px, py in rami:
                bone |= (X - px) ** 2 + (Y - py) ** 2 < 5.0**2
        sl[bone] = 1200.0
        sl += rng.normal(0.0, 20.0, sl.shape).astype(np.float32)
        out[k] = np.clip(sl, -1024, 3071).astype(np.int16)
    return out


def _child(volume_path: str, case: str, traced: bool) -> dict:
    """Run one case in this (fresh) process and return its figures."""
    sys.path.insert(0, str(ROOT))
    from workbench.core.isosurface import extract_isosurface
    from workbench.core.volume import Volume
    from workbench.services.ct.ct_mesh import mesh_from_ct

    data = np.load(volume_path)
    volume = Volume(data, SPACING, modality="CT", units="HU", source="synthetic head CT")
    spec = CASES[case]
    if traced:
        import tracemalloc

        tracemalloc.start()
    start = time.perf_counter()
    if spec["service"]:
        res = mesh_from_ct(volume, "bone", target_triangles=spec["target"])
        mesh, extra = res.mesh, {"validation": res.summary, "timings": res.timings_s}
    else:
        res = extract_isosurface(volume, "bone", target_triangles=spec["target"])
        mesh, extra = (
            res.mesh,
            {"timings": res.stats["timings_s"], "faces_mc": res.stats["n_faces_marching_cubes"]},
        )
    wall = time.perf_counter() - start
    figures = {"wall_s": wall, "n_faces": mesh.n_faces, "n_vertices": mesh.n_vertices, **extra}
    if traced:
        figures["tracemalloc_peak_mb"] = tracemalloc.get_traced_memory()[1] / 2**20
    figures["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    return figures


def _run_child(volume_path: Path, case: str, traced: bool) -> dict:
    cmd = [sys.executable, __file__, "--child", str(volume_path), "--case", case]
    if traced:
        cmd.append("--traced")
    done = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"case {case!r} failed:\n{done.stderr}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--child", help=argparse.SUPPRESS)
    parser.add_argument("--case", help=argparse.SUPPRESS)
    parser.add_argument("--traced", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--no-tracemalloc", action="store_true", help="skip the traced runs")
    parser.add_argument("--keep", type=Path, help="folder to keep the phantom in")
    args = parser.parse_args(argv)
    if args.child:
        print(json.dumps(_child(args.child, args.case, args.traced)))
        return 0

    with tempfile.TemporaryDirectory() as tmp:
        folder = args.keep or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / "phantom.npy"
        t0 = time.perf_counter()
        data = synthetic_head_ct()
        np.save(path, data)
        print(
            f"phantom {data.shape[::-1]} (i, j, k) {data.dtype}, spacing {SPACING} mm, "
            f"{data.nbytes / 2**20:.0f} MB, built in {time.perf_counter() - t0:.1f} s"
        )
        del data
        budgets = f"{TIME_BUDGET_S:.0f} s and {RSS_BUDGET_MB / 1024:.0f} GB"
        print(f"CPUs: {os.cpu_count()}; budgets {budgets}\n")
        ok = True
        for case in CASES:
            f = _run_child(path, case, traced=False)
            traced = None if args.no_tracemalloc else _run_child(path, case, traced=True)
            ok &= f["wall_s"] < TIME_BUDGET_S and f["peak_rss_mb"] < RSS_BUDGET_MB
            print(f"{case}:")
            wall, rss = f["wall_s"], f["peak_rss_mb"]
            print(f"  wall time      {wall:7.2f} s   ({wall / TIME_BUDGET_S:5.1%} of budget)")
            print(
                f"  peak RSS       {rss:7.0f} MB  ({rss / RSS_BUDGET_MB:5.1%} of budget, "
                "includes the 200 MB volume)"
            )
            if traced:
                peak = traced["tracemalloc_peak_mb"]
                print(
                    f"  tracemalloc    {peak:7.0f} MB  (numpy/Python allocations in the extraction)"
                )
            print(f"  triangles      {f['n_faces']:>9,d}   vertices {f['n_vertices']:,d}")
            if "faces_mc" in f:
                print(f"  marching cubes {f['faces_mc']:>9,d} triangles before clean-up")
            print(f"  steps (s)      {f['timings']}")
            if "validation" in f:
                print(f"  validation     {f['validation']}")
        print("\nwithin budget" if ok else "\nOVER BUDGET")
        return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
