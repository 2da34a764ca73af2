"""Interactive budgets of the workbench window (issue 5), measured under Xvfb.

Budgets: dragging a landmark or a guide updates the preview fit at >= 10 Hz
on a 100k-triangle skull; nothing blocks the event loop for more than 200 ms.

What it does, on the public 100k-triangle skull (``skull.obj`` × 15 mm):
opens it, suggests landmarks, fits the face, then drags the glabella along
the skull (30 mouse moves), then again with the muscles shown (15 moves)
and a horizontal guide in the guide view (20 moves), and prints

* the time per drawn preview (re-solved face + render) and the rate it allows;
* the longest gap of a 10 ms heartbeat timer (the longest time the event
  loop was blocked) during opening, suggesting, fitting, the drags, undo,
  redo, saving, exporting (meshes and the PDF report) and comparing;
* the worker times of the jobs.

Run (needs an X server; Xvfb is enough)::

    QT_QPA_PLATFORM=xcb xvfb-run -a -s "-screen 0 1600x1000x24" \\
        python benchmarks/bench_gui.py [SKULL.obj] [--scale 15] [--cold]

``--cold`` starts from an empty cache, as a first run does: the reference
head (~12 s of work that holds the GIL in long stretches) is then built in
the helper process during "suggest".

Figures, not assertions: the budgets are printed with the ratio measured/budget.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("QT_API", "pyside6")
DEFAULT_SKULL = Path(__file__).resolve().parents[2] / "shared/data/skull_mesh_yahoojapan/skull.obj"


class Heartbeat:
    """A 10 ms timer; the longest gap between its ticks is the longest event-loop block."""

    def __init__(self) -> None:
        from PySide6.QtCore import QTimer

        self.timer = QTimer()
        self.timer.setInterval(10)
        self.timer.timeout.connect(self._tick)
        self.last = time.perf_counter()
        self.gaps: list[float] = []

    def _tick(self) -> None:
        now = time.perf_counter()
        self.gaps.append(now - self.last)
        self.last = now

    def start(self) -> None:
        self.gaps.clear()
        self.last = time.perf_counter()
        self.timer.start()

    def stop(self) -> float:
        self.timer.stop()
        return max(self.gaps, default=0.0)


def _wait(app, window, timeout: float = 300.0) -> None:
    end = time.monotonic() + timeout
    while window.busy and time.monotonic() < end:
        app.processEvents()
        time.sleep(0.002)
    for _ in range(5):
        app.processEvents()


def _settle(app, beat: Heartbeat) -> None:
    """Spin the event loop until the heartbeat has ticked once (at most 0.5 s).

    Synthetic input is sent from this script, outside the event loop; a
    user's input arrives through it, with timers running in between.  So
    that two synthetic events in a row do not count as one block, the loop
    gets its turn between them.
    """
    n, end = len(beat.gaps), time.monotonic() + 0.5
    while len(beat.gaps) == n and time.monotonic() < end:
        app.processEvents()
        time.sleep(0.001)


def _drag(app, widget, start, offsets, beat: Heartbeat) -> np.ndarray:
    """Press, move, release; returns the seconds from each move to its drawn frame."""
    from PySide6.QtCore import QPoint, Qt
    from PySide6.QtTest import QTest

    QTest.mousePress(widget, Qt.MouseButton.LeftButton, Qt.KeyboardModifier.NoModifier, start)
    frames = []
    for dx, dy in offsets:
        _settle(app, beat)
        t0 = time.perf_counter()
        QTest.mouseMove(widget, start + QPoint(dx, dy))
        app.processEvents()  # the coalesced preview, then the paint (one render per view)
        app.processEvents()
        frames.append(time.perf_counter() - t0)
    _settle(app, beat)
    QTest.mouseRelease(
        widget,
        Qt.MouseButton.LeftButton,
        Qt.KeyboardModifier.NoModifier,
        start + QPoint(*offsets[-1]),
    )
    app.processEvents()
    return np.array(frames)


def _qt_pos(plotter, xy):
    from PySide6.QtCore import QPoint

    ratio = plotter.devicePixelRatioF()
    h = plotter.render_window.GetSize()[1]
    return QPoint(int(round(xy[0] / ratio)), int(round((h - xy[1]) / ratio)))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("skull", nargs="?", default=str(DEFAULT_SKULL))
    parser.add_argument("--scale", type=float, default=15.0)
    parser.add_argument(
        "--cold",
        action="store_true",
        help="start from an empty cache folder, as on a first run "
        "(the reference head is built during 'suggest')",
    )
    args = parser.parse_args(argv)
    if args.cold:
        import tempfile

        os.environ["WORKBENCH_DATA_DIR"] = tempfile.mkdtemp(prefix="bench-gui-cold-")

    from workbench.qt.app import ensure_app

    app = ensure_app()
    from workbench.qt.main_window import MainWindow

    window = MainWindow(auto_update=False, interactive=False)
    window.resize(1400, 900)
    window.show()
    app.processEvents()
    beat = Heartbeat()
    blocks: dict[str, float] = {}

    def step(name: str, fn) -> None:
        beat.start()
        fn()
        _wait(app, window)
        blocks[name] = beat.stop()

    step("open", lambda: window.open_skull(args.skull, scale=args.scale))
    step("suggest", window.suggest_landmarks)
    step("fit", window.reconstruct)
    if window.errors or window.fit is None:
        print("failed:", window.errors, file=sys.stderr)
        return 1
    n_tri = window.document.case.specimen.mesh.n_faces
    render_ms = {}
    for mode in ("full", "light"):
        if mode == "light":
            window.detail.begin()
        times = []
        for _ in range(6):
            t0 = time.perf_counter()
            window.plotter.render()
            times.append(time.perf_counter() - t0)
        render_ms[mode] = float(np.median(times[1:])) * 1e3
    window.detail.end()
    app.processEvents()

    def landmark_drag(name: str, offsets) -> tuple[np.ndarray, np.ndarray]:
        """Drag the glabella; (move → frame seconds, preview seconds); the block in ``blocks``."""
        window.landmarks_panel.select("g")
        window.scene.render_now()
        _wait(app, window)
        g = window.document.case.landmarks["skull"]["g"].position
        start = _qt_pos(window.plotter, window.picker.display_position(g))
        window.drag_timings.clear()
        beat.start()
        frames = _drag(app, window.plotter, start, offsets, beat)
        blocks[name] = beat.stop()
        return frames, np.array(window.drag_timings)

    lm_frames, lm_times = landmark_drag("landmark drag", [(0, -k) for k in range(1, 31)])
    step("re-fit after the drag", lambda: None)
    # the same with the muscles layer shown (they follow the preview too)
    window.scene.set_visible("muscles", True)
    mu_frames, mu_times = landmark_drag(
        "landmark drag, muscles shown", [(0, k) for k in range(1, 16)]
    )
    step("re-fit after it", lambda: None)
    window.scene.set_visible("muscles", False)

    # a guide drag in the guide view
    gv = window.guide_view
    gv.refresh(reset_camera=True)
    guides = window.reconstruct_panel.guides
    row = next(i for i, g in enumerate(guides) if g.kind == "hline" and g.enabled)
    seg = gv._segment(guides[row])
    start = _qt_pos(gv.plotter, gv._display((seg[0] + seg[1]) / 2))
    window.drag_timings.clear()
    beat.start()
    guide_frames = _drag(app, gv.plotter, start, [(0, -k) for k in range(1, 21)], beat)
    blocks["guide drag"] = beat.stop()
    guide_times = np.array(window.drag_timings)
    step("re-fit after the guide", lambda: None)

    # the rest of a session: undo/redo (each re-fits), save, export, compare
    import tempfile

    from workbench.io.meshes import write_mesh

    out = Path(tempfile.mkdtemp(prefix="bench-gui-"))
    truth = write_mesh(out / "truth.ply", window.fit.recon.face)  # any skin will do
    step("undo", window.undo)
    step("redo", window.redo)
    step("save", lambda: window.save_to(out / "case.fcase"))
    step("export", lambda: window.export_to(out / "export"))
    step("compare", lambda: window.load_truth(truth))
    if window.errors or window.comparison is None:
        print("failed:", window.errors, file=sys.stderr)
        return 1

    print(
        f"skull: {n_tri} triangles; window 1400x900; "
        f"renderer: {window.scene.gl_renderer}; FXAA "
        f"{'on' if window.plotter.renderer.GetUseFXAA() else 'off (software renderer)'}"
    )
    print(
        f"one render of the main view: full quality {render_ms['full']:.0f} ms, "
        f"interactive (light skull, no edge smoothing) {render_ms['light']:.0f} ms"
    )
    for name, times, frames in (
        ("landmark drag", lm_times, lm_frames),
        ("landmark drag, muscles shown", mu_times, mu_frames),
        ("guide drag", guide_times, guide_frames),
    ):
        med = float(np.median(frames))
        print(
            f"{name}: {len(frames)} moves, move → drawn frame median {med * 1e3:.0f} ms, "
            f"max {frames.max() * 1e3:.0f} ms -> {1 / med:.1f} Hz "
            f"(budget >= 10 Hz: ratio {(1 / med) / 10:.2f}); preview computation median "
            f"{np.median(times) * 1e3:.1f} ms"
        )
    for name, gap in blocks.items():
        print(
            f"longest event-loop block during {name}: {gap * 1e3:.0f} ms "
            f"(budget 200 ms: ratio {gap / 0.2:.2f})"
        )
    print("worker times: " + ", ".join(f"{k} {v:.2f} s" for k, v in window.runner.timings.items()))
    window.runner.shutdown()
    window.guide_view.close_view()
    window.plotter.close()
    window.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
