"""The Age progression dock's live preview (issue 15), measured under Xvfb.

What it does: opens the window, brings the Age progression dock to the
front with the reference male head (18 y) aimed at 10 y, lets the worker
compute 10 y and the whole years around it (``--prefetch`` years each side),
then scrubs the slider back and forth over the computed ages (each move
draws the nearest computed head: the aged skin's points moved in place, then
a render).  It prints

* the worker time of each age step (the service's own figure and the job's
  wall time, queueing included);
* the GUI-thread time of one slider move over computed ages (points moved +
  table refilled + render), median and max;
* the longest gap of a 10 ms heartbeat timer while the ages were computed
  (the longest time the event loop was blocked: the view stays responsive
  while the worker ages the head).

Run (needs an X server; Xvfb is enough)::

    QT_QPA_PLATFORM=xcb xvfb-run -a -s "-screen 0 1600x1000x24" \\
        python benchmarks/bench_age_dock.py [--prefetch 2] [--moves 40]

Figures, not assertions.
"""

from __future__ import annotations

import argparse
import os
import time

import numpy as np

os.environ.setdefault("QT_API", "pyside6")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--prefetch", type=int, default=2, help="whole years each side of 10 y")
    parser.add_argument("--moves", type=int, default=40, help="slider moves over computed ages")
    args = parser.parse_args(argv)

    from PySide6.QtCore import QTimer

    from workbench.qt.app import ensure_app
    from workbench.qt.main_window import MainWindow
    from workbench.services.templates.cache import reference_head

    app = ensure_app()
    reference_head("male")  # built (or read from the cache) before the clock starts
    window = MainWindow(auto_update=False, interactive=False)
    window.resize(1400, 900)
    window.show()
    app.processEvents()
    tool = window.age
    tool.prefetch_years = args.prefetch

    gaps: list[float] = []
    last = [time.perf_counter()]

    shown_at: list[tuple[float, str]] = []

    def tick() -> None:
        now = time.perf_counter()
        gaps.append(now - last[0])
        shown_at.append((now - last[0], window.age_panel.status.text()[:60]))
        last[0] = now

    beat = QTimer()
    beat.setInterval(10)
    beat.timeout.connect(tick)

    worker_s: dict[int, float] = {}
    t0 = time.perf_counter()
    window.show_age(10, 18, "male")
    last[0] = time.perf_counter()
    beat.start()
    want = {10 + k for k in range(-args.prefetch, args.prefetch + 1)}
    seen_jobs = 0
    while not want <= set(tool.cache) and time.perf_counter() - t0 < 600:
        app.processEvents()
        time.sleep(0.002)
        if len(tool.cache) != seen_jobs:
            seen_jobs = len(tool.cache)
            newest = list(tool.cache)[-1]  # dicts keep insertion order
            worker_s[newest] = window.runner.timings.get("age", float("nan"))
    beat.stop()
    total = time.perf_counter() - t0
    blocked = max(gaps) if gaps else float("nan")

    ages = sorted(tool.cache)
    moves = []
    slider = window.age_panel.target
    for i in range(args.moves):
        age = ages[i % len(ages)] if (i // len(ages)) % 2 == 0 else ages[-1 - i % len(ages)]
        start = time.perf_counter()
        slider.setValue(age)  # the tool asks for one render: wait until the view painted it
        while window.scene.render_queued and time.perf_counter() - start < 2.0:
            app.processEvents()
        moves.append(time.perf_counter() - start)

    print(f"ages computed: {ages} in {total:.1f} s (load + {len(ages)} steps)")
    for age in ages:
        step = tool.cache[age]
        print(
            f"  {age:>2} y: service {step.result.figures['seconds']:.2f} s, "
            f"job {worker_s.get(age, float('nan')):.2f} s, "
            f"hard residual max {step.result.figures['hard_residual_mm']['max']} mm"
        )
    ms = 1000 * np.array(moves)
    print(
        f"slider move over computed ages (GUI thread, until the view painted): "
        f"median {np.median(ms):.1f} ms, max {ms.max():.1f} ms ({len(ms)} moves)"
    )
    repaints = []
    for _ in range(10):
        start = time.perf_counter()
        window.scene.request_render()
        while window.scene.render_queued and time.perf_counter() - start < 2.0:
            app.processEvents()
        repaints.append(time.perf_counter() - start)
    print(f"a repaint of the view alone: median {1000 * np.median(repaints):.1f} ms")
    print(f"longest event-loop block while computing: {1000 * blocked:.0f} ms")
    for gap, what in sorted(shown_at, reverse=True)[:4]:
        print(f"  {1000 * gap:.0f} ms, then: {what}")
    window.runner.shutdown()
    window.plotter.close()
    window.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
