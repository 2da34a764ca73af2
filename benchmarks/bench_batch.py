"""Benchmark: ``workbench batch`` on Dask, 2 local workers vs one job after another (issue 16).

Run ``python benchmarks/bench_batch.py [--jobs 8]`` from the repository root
with ``../shared/data`` beside the checkout (or WORKBENCH_SAMPLE_MIRRORS set).

The jobs are ``workbench demo``'s built-in case: the female reference skull
reconstructed with the male reference head (``--sex male``, head frame
orientation, ``--truth`` the female reference skin, no pictures), ``--jobs``
rows, each skull a copy with its own 1e-6 mm vertex noise: identical files
would let the one-process run reuse the first job's content-keyed caches
(4 identical rows: 12.6 s, then 3.7 s a job), which a real study of
different skulls does not get.  Prints (no budgets, no assertions):

* seconds for all jobs one after another in this process (``--workers 0``),
  and on a Dask LocalCluster of 2 worker processes x 1 thread (cluster start
  included, and apart), and their ratio;
* the mean seconds of one job in each mode (from the rows' batch_row.json);
* the scheduler overhead per job: a trivial command (``workbench samples
  list``) as a task on the warm cluster (submit -> result) minus the same
  call made directly, averaged over ``--trivial`` calls.

The load average at the start is printed: on a shared machine other work
slows both modes, the 2-worker mode more.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "data"
os.environ.setdefault("WORKBENCH_SAMPLE_MIRRORS", str(SHARED))
sys.path.insert(0, str(ROOT))

from workbench.cli.batch_cmd import commands  # noqa: E402
from workbench.pipelines.batch.run import dask_client, run_batch, run_row_task  # noqa: E402

TRIVIAL = ["samples", "list"]


def _trivial_options():
    """``workbench samples list`` as a batch row's parsed options (the cheapest job there is)."""
    options = commands()["samples"].parse_args(TRIVIAL[1:])
    options.command, options.debug = TRIVIAL[0], False
    return options


def _case(folder: Path, jobs: int) -> tuple[list[Path], Path]:
    """The built-in demo case: the female reference skull (one copy per job, each with its own
    1e-6 mm vertex noise so no job reuses another's content-keyed caches) and skin (mm)."""
    import numpy as np

    from workbench.core.mesh import Mesh
    from workbench.io.meshes import write_mesh
    from workbench.services.templates.cache import reference_head
    from workbench.services.templates.reference_parts import skull_surface

    female = reference_head("female")
    reference_head("male")  # built and cached before any timing
    bone = skull_surface(female)
    skulls = []
    for i in range(jobs):
        noise = np.random.default_rng(i).normal(0.0, 1e-6, bone.vertices.shape)
        skulls.append(
            write_mesh(folder / f"skull{i + 1}.ply", Mesh(bone.vertices + noise, bone.faces))
        )
    truth = write_mesh(folder / "truth_skin.ply", female.skin)
    return skulls, truth


def _manifest(folder: Path, skulls: list[Path], truth: Path) -> Path:
    rows = [
        f'r{i + 1},reconstruct,{skull},male,"0,0,1","0,1,0",{truth},true'
        for i, skull in enumerate(skulls)
    ]
    path = folder / "manifest.csv"
    path.write_text(
        "id,job,input,sex,anterior,superior,truth,no-pictures\n" + "\n".join(rows) + "\n",
        encoding="utf-8",
    )
    return path


def _batch(manifest: Path, out: Path, workers: int) -> tuple[float, list]:
    t0 = time.perf_counter()
    results = run_batch(
        manifest,
        out,
        commands={k: v for k, v in commands().items() if k != "batch"},
        workers=workers,
        notify=lambda m: print(f"    {m}", flush=True),
    )
    return time.perf_counter() - t0, results


def _overhead(n: int) -> tuple[float, float, float]:
    """(cluster start s, direct call s, task round trip s) for the trivial command."""
    trivial = _trivial_options()
    direct = []
    for _ in range(n):
        t = time.perf_counter()
        run_row_task(trivial)
        direct.append(time.perf_counter() - t)
    t0 = time.perf_counter()
    with dask_client(2, None) as client:
        start = time.perf_counter() - t0
        client.submit(run_row_task, trivial, pure=False).result()  # warm both imports
        client.submit(run_row_task, trivial, pure=False).result()
        trips = []
        for _ in range(n):
            t = time.perf_counter()
            client.submit(run_row_task, trivial, pure=False).result()
            trips.append(time.perf_counter() - t)
    return start, sum(direct) / n, sum(trips) / n


def main_bench() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=8)
    ap.add_argument("--trivial", type=int, default=20, help="trivial calls for the overhead")
    args = ap.parse_args()
    load = os.getloadavg()
    print(
        f"load average at start: {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} ({os.cpu_count()} cores)"
    )
    with tempfile.TemporaryDirectory(prefix="bench_batch_") as tmp:
        folder = Path(tmp)
        skulls, truth = _case(folder, args.jobs)
        manifest = _manifest(folder, skulls, truth)
        print(f"{args.jobs} reconstructions one after another in this process:")
        serial, res0 = _batch(manifest, folder / "serial", 0)
        print(f"{args.jobs} reconstructions on a LocalCluster of 2 workers:")
        parallel, res2 = _batch(manifest, folder / "cluster", 2)
        bad = [r.row.row_id for r in (*res0, *res2) if r.status != "ok"]
        if bad:
            print(f"note: rows failed: {', '.join(bad)}")
        start, direct, trip = _overhead(args.trivial)
    job0 = sum(r.seconds or 0.0 for r in res0) / len(res0)
    job2 = sum(r.seconds or 0.0 for r in res2) / len(res2)
    print()
    print(f"one after another:     {serial:7.1f} s  (mean job {job0:.1f} s)")
    print(f"2 workers (Dask):      {parallel:7.1f} s  (mean job {job2:.1f} s)")
    print(f"a LocalCluster of 2 workers starts in {start:.1f} s (measured apart)")
    rest = max(parallel - start, 1e-9)
    print(f"ratio serial / 2 workers: {serial / parallel:.2f} ({serial / rest:.2f} less a start)")
    print(
        f"scheduler overhead per job: {1000 * (trip - direct):.0f} ms "
        f"(trivial task round trip {1000 * trip:.0f} ms, direct call {1000 * direct:.0f} ms, "
        f"mean of {args.trivial})"
    )


if __name__ == "__main__":
    main_bench()
