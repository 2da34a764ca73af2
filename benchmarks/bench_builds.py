"""Benchmark: what the three build faces and the band add to a reconstruction (issue 31).

Run ``python benchmarks/bench_builds.py [SKULL]`` from the repository root
(``WORKBENCH_SAMPLE_MIRRORS`` or ``../shared/data`` beside the checkout).
Default skull: headsq's plain marching-cubes bone
(``benchmarks/results/plain_bones/headsq_plain.ply``, made by
``bench_validation.py --unseen``), else the built-in generated skull.

It runs one reconstruction job in this process, then times, each over
several repeats (median, min, max in seconds):

* ``build_faces``: the three faces and the band from the fitted head;
* ``write_build_files``: ``face_<build>.ply`` ×3, the band arrays and
  ``face_builds.glb``;
* ``render_builds`` (when the render module has it): the report's build
  and band pictures, off-screen;

and prints their sum beside the job's own fit time, with the budget
(three faces add < 3 s).  The whole-process cost is measured by timing
``workbench reconstruct`` itself against the previous build (see the
docs/reconstruction.md).  Units: seconds; skin vertex count printed.
"""

from __future__ import annotations

import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

BUDGET_S = 3.0
REPEATS = 5


def _times(fn: Callable[[], object], repeats: int = REPEATS) -> list[float]:
    out = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t)
    return out


def _row(name: str, times: list[float]) -> str:
    return (
        f"{name:<20} median {statistics.median(times):7.3f} s   "
        f"min {min(times):7.3f}   max {max(times):7.3f}   (n = {len(times)})"
    )


def main() -> int:
    from workbench.services.reconstruction.build_faces import build_faces
    from workbench.services.reconstruction.job import (
        JobSettings,
        run_reconstruction,
        write_build_files,
    )
    from workbench.services.tissue.dowels import build_model_for

    default = ROOT / "benchmarks" / "results" / "plain_bones" / "headsq_plain.ply"
    skull = Path(sys.argv[1]) if len(sys.argv) > 1 else default
    if not skull.is_file():
        from workbench.io.meshes import write_mesh
        from workbench.services.templates.cache import reference_head
        from workbench.services.templates.reference_parts import skull_surface

        tmp = Path(tempfile.mkdtemp())
        skull = write_mesh(tmp / "generated_skull.ply", skull_surface(reference_head("female")))
        print(f"(no {default.name}: the built-in generated skull instead)")
    t = time.perf_counter()
    job = run_reconstruction(skull, JobSettings(sex="male"))
    job_s = time.perf_counter() - t
    fit = job.fit
    assert fit is not None and fit.builds is not None, "no build faces: a table without SDs?"
    recon, model = fit.recon, build_model_for()
    print(
        f"skull {skull.name}: job {job_s:.1f} s (fit {fit.seconds.get('fit', 0):.1f} s); "
        f"skin {recon.head.skin.n_vertices} vertices"
    )
    rows = {
        "build_faces": _times(
            lambda: build_faces(recon, model, min_tissue_mm=2.0, bone=fit.skull_h)
        ),
    }
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder)
        rows["write_build_files"] = _times(lambda: write_build_files(recon, fit.builds, out))
        try:
            from workbench.render import reconstruction as render
        except ImportError:  # pragma: no cover - render is part of the package
            render = None
        draw = getattr(render, "render_builds", None)
        if draw is not None:
            faces = {n: fit.builds.face(n, recon) for n in fit.builds.names}

            def pictures() -> object:
                return draw(
                    faces,
                    out / "pictures",
                    frame=recon.input_to_head,
                    band_face=recon.face,
                    band_mm=fit.builds.half_width_mm,
                )

            rows["render_builds"] = _times(pictures, 3)
    for name, times in rows.items():
        print(_row(name, times))
    total = sum(statistics.median(t) for t in rows.values())
    print(
        f"added by the three faces: {total:.2f} s (median sum) — budget < {BUDGET_S:g} s, "
        f"ratio {total / BUDGET_S:.2f}; {100 * total / job_s:.0f} % of this job's {job_s:.1f} s"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
