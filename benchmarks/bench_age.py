"""Benchmark: growth and age change (issue 15), figures and seconds.

Run ``python benchmarks/bench_age.py [RECONSTRUCTION_DIR ...]`` from the
repository root.  Cases: both built-in reference heads (taken as 18-year-olds)
aged 18 → 3, 18 → 8, 18 → 15, then the 3-year-old back to 18 and the
8-year-old to 15 (so 3 → 18 and 8 → 15 start from a child head); each
reconstruction folder given (e.g. ``demo_out/headsq/`` from ``workbench
demo``: a face reconstructed over the headsq CT's bone) aged 18 → 3 and
18 → 8 with the male norms, then 3 → 18 and 8 → 15 from those.  Last, a
10-age sequence (3..12 y) of the male head.

Prints per case: hard constraints met (median / max residual, mm), the
largest change of a z-score, the head circumference before / after with its
z-score and the chart's target, skin inside the skull (face region; before
→ after), fold-overs, the solve's seconds and the whole step's seconds;
then the sequence's seconds and the ratios to the issue's budgets
(< 1 s per step, < 50 ms per solve, < 10 s per 10-age sequence).  Units mm.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

from workbench.services.age.change import AgeResult, age_head
from workbench.services.age.job import age_series
from workbench.services.templates.cache import reference_head


def _line(name: str, r: AgeResult, seconds: float) -> dict:
    f = r.figures
    hc = f["head_circumference_mm"]
    inside = f["face_skin_inside_skull_vertices"]
    print(
        f"{name:28s} hard {f['hard_constraints']:2d} res med {f['hard_residual_mm']['median']:.3f}"
        f" max {f['hard_residual_mm']['max']:.3f} mm | dz max {f['z_change_max']:.4f} | "
        f"HC {hc['before']:.1f} -> {hc['after']:.1f} (target {hc['target']:.1f}, "
        f"z {hc['z_before']:+.2f} -> {hc['z_after']:+.2f}) | inside {inside['before']}->"
        f"{inside['after']} | folds {f['fold_overs']} | solve {f['solve']['seconds'] * 1000:.1f} ms"
        f" | step {seconds:.2f} s"
    )
    return {"case": name, "seconds": round(seconds, 3), **f}


def _timed(head, sex: str, a0: float, a1: float) -> tuple[AgeResult, float]:
    t = time.perf_counter()
    r = age_head(head, sex=sex, from_age=a0, to_age=a1)
    return r, time.perf_counter() - t


def main(argv: list[str]) -> int:
    rows = []
    steps = []
    solves = []
    for sex in ("male", "female"):
        head = reference_head(sex)
        age_head(head, sex=sex, from_age=18, to_age=17)  # warm caches (tables, numba)
        kids = {}
        for a1 in (3, 8, 15):
            r, s = _timed(head, sex, 18, a1)
            kids[a1] = r.head
            rows.append(_line(f"{sex} reference 18->{a1}", r, s))
            steps.append(s)
            solves.append(r.figures["solve"]["seconds"])
        for a0, a1 in ((3, 18), (8, 15)):
            r, s = _timed(kids[a0], sex, a0, a1)
            rows.append(_line(f"{sex} reference 18->{a0}->{a1}", r, s))
            steps.append(s)
            solves.append(r.figures["solve"]["seconds"])
        back = age_head(kids[3], sex=sex, from_age=3, to_age=18).head
        d = np.linalg.norm(back.skin.vertices - head.skin.vertices, axis=1)
        print(
            f"{'':28s} 18->3->18 vs the start: skin median {np.median(d):.2f} mm, "
            f"p95 {np.percentile(d, 95):.2f} mm, max {d.max():.2f} mm"
        )
    for folder in argv:
        from workbench.cli.animate_cmd import load_head

        head, _, _ = load_head(folder)
        young = {}
        for a1 in (3, 8):
            r, s = _timed(head, "male", 18, a1)
            young[a1] = r.head
            rows.append(_line(f"{Path(folder).name} 18->{a1}", r, s))
            steps.append(s)
            solves.append(r.figures["solve"]["seconds"])
        for a0, a1 in ((3, 18), (8, 15)):
            r, s = _timed(young[a0], "male", a0, a1)
            rows.append(_line(f"{Path(folder).name} 18->{a0}->{a1}", r, s))
            steps.append(s)
            solves.append(r.figures["solve"]["seconds"])
    head = reference_head("male")
    t = time.perf_counter()
    age_series(head, [float(a) for a in range(3, 13)], sex="male", from_age=18)
    seq = time.perf_counter() - t
    print(
        f"\nper step: median {np.median(steps):.2f} s, max {max(steps):.2f} s "
        f"(budget 1 s: ratio {max(steps) / 1.0:.2f}); solve median "
        f"{np.median(solves) * 1000:.1f} ms, max {max(solves) * 1000:.1f} ms (budget 50 ms: "
        f"ratio {max(solves) / 0.05:.2f}); 10-age sequence {seq:.2f} s (budget 10 s: ratio "
        f"{seq / 10:.2f})"
    )
    print(json.dumps(rows, indent=1, default=str)[:2000] + "\n...")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
