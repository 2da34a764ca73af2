#!/usr/bin/env python
"""Benchmark: the whole ``workbench reconstruct`` job as a process (issue 28 budget).

Budget: the job on an 800k-triangle CT bone — reading, checks, decimation, the
automatic registration, the fit, the pictures and the PDF report — in at most
15 s on the 2-core machine, median of the runs, wall clock of the whole process.

The bone is the Visible Human female's as other programs export it (VTK flying
edges at 300 HU on the 1 mm CT, the largest piece, nothing else: about 0.85 M
triangles), built once into ``benchmarks/results/reconstruct_job/`` (git-ignored;
meshes made from the CTs are never committed); ``--bone`` takes another.  No
orientation, no landmarks.  ``--vs REV`` runs a git revision of this checkout
(exported, as the robustness corpus does) in turn with the working tree, A B A B,
and prints the ratio pair by pair so a drift of the machine's speed cancels.
Each run's own stage times (the job's ``seconds``) are printed beside the wall
clock.  Run from the repository root::

    WORKBENCH_SAMPLE_MIRRORS=../shared/data .venv/bin/python \\
        benchmarks/bench_reconstruct_job.py --runs 3 --vs HEAD~5

Visible Human data: Courtesy of the U.S. National Library of Medicine.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("WORKBENCH_SAMPLE_MIRRORS", str(ROOT.parent / "shared" / "data"))

BUDGET_S = 15.0


def default_bone(folder: Path) -> Path:
    """The VHP female's plain marching-cubes bone (300 HU, largest piece), made once."""
    from benchmarks.bench_validation import plain_bone
    from workbench.io.samples import fetch

    return plain_bone(fetch("vhp_female"), 300.0, folder / "vhp_female_plain_300.ply")


def run_once(code: Path | None, bone: Path, extra: list[str]) -> tuple[float, dict, int]:
    """One whole ``workbench reconstruct`` process; (wall s, the job's stage seconds, exit)."""
    env = dict(os.environ)
    if code is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(code.resolve()), env.get("PYTHONPATH", "")])
    with tempfile.TemporaryDirectory(prefix="recon_job_") as tmp:
        out = Path(tmp) / "case"
        cmd = [sys.executable, "-m", "workbench", "reconstruct", str(bone), "--out", str(out)]
        t = time.perf_counter()
        done = subprocess.run(
            cmd + extra, env=env, cwd=tmp, capture_output=True, text=True, check=False
        )
        wall = time.perf_counter() - t
    stages: dict = {}
    text = done.stdout
    start = text.rfind("\n{")
    if start >= 0:
        try:
            stages = json.loads(text[start:]).get("seconds", {})
        except json.JSONDecodeError:
            stages = {}
    if done.returncode != 0:
        sys.stderr.write(done.stdout[-2000:] + done.stderr[-2000:])
    return wall, stages, done.returncode


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--runs", type=int, default=3, help="counted runs of each build")
    parser.add_argument("--bone", type=Path, help="another bone mesh (default: VHP female)")
    parser.add_argument("--vs", help="a git revision to run in turn with the working tree")
    parser.add_argument("--no-pictures", action="store_true", help="the job without pictures")
    args = parser.parse_args()
    folder = ROOT / "benchmarks" / "results" / "reconstruct_job"
    bone = args.bone or default_bone(folder)
    from workbench.io.meshes import read_mesh

    n_faces = read_mesh(bone).mesh.n_faces
    extra = ["--no-pictures"] if args.no_pictures else []
    builds: list[tuple[str, Path | None]] = [("working tree", None)]
    if args.vs:
        from benchmarks.bench_robustness import export_revision

        builds.append((args.vs, export_revision(args.vs)))
    print(f"bone {bone} ({n_faces:,} triangles), {args.runs} runs each after one warm-up")
    walls: dict[str, list[float]] = {name: [] for name, _ in builds}
    for _name, code in builds:  # warm-up: disk caches and the reference head's cache
        run_once(code, bone, extra)
    for i in range(args.runs):
        for name, code in builds:
            wall, stages, rc = run_once(code, bone, extra)
            walls[name].append(wall)
            figures = ", ".join(f"{k} {v:.1f}" for k, v in stages.items())
            print(f"  run {i + 1} {name}: {wall:.1f} s, exit {rc} ({figures})")
    for name, _ in builds:
        med = statistics.median(walls[name])
        print(
            f"{name}: median {med:.1f} s (min {min(walls[name]):.1f}, max "
            f"{max(walls[name]):.1f}); budget {BUDGET_S:.0f} s: "
            f"{'within' if med <= BUDGET_S else 'OVER'}"
        )
    if args.vs:
        ratios = [a / b for a, b in zip(walls["working tree"], walls[args.vs], strict=True)]
        print(
            f"ratio working tree / {args.vs}: median {statistics.median(ratios):.2f} "
            f"(pairs {', '.join(f'{r:.2f}' for r in ratios)})"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
