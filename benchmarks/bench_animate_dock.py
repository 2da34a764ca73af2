"""Frame times of the Animate dock's timeline (issue 14), measured in the window under Xvfb.

Opens the window, loads the reference head in the Animate dock, opens a
track (default: examples/hello_world_track.json) and prints medians of

* playing it the first time (each frame simulated: ``steps_per_frame`` steps
  of the skin + moving the drawn points), and the time from one played frame
  to the next with the 3D view's render and the event loop included;
* playing it again (every frame restored from its checkpoint);
* scrubbing backwards (restore + exact skin + drawing), one scrub at a time;
* one render of the 3D view at the window's size;
* the live slider timer's frames (a smile preset settling).

Run (needs an X server; Xvfb is enough)::

    DISPLAY=:99 QT_QPA_PLATFORM=xcb QT_API=pyside6 \\
        python benchmarks/bench_animate_dock.py [TRACK.json] [--size 1400x1000] \\
        [--screenshot anim.png --frame 33]

Figures, not assertions; the machine's load (``os.getloadavg``) is printed
with them, since the 3D view renders in software (llvmpipe) on shared cores.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("QT_API", "pyside6")
EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "hello_world_track.json"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("track", nargs="?", type=Path, default=EXAMPLE)
    ap.add_argument("--size", default="1400x1000")
    ap.add_argument("--screenshot", type=Path, default=None)
    ap.add_argument("--frame", type=int, default=33, help="frame shown in the screenshot")
    args = ap.parse_args()
    width, height = (int(v) for v in args.size.split("x"))

    from PySide6.QtWidgets import QApplication

    app = QApplication.instance() or QApplication(sys.argv[:1])
    from workbench.qt.main_window import MainWindow

    w = MainWindow(auto_update=False, interactive=False)
    w.resize(width, height)
    w.show()

    def wait(cond, timeout_s: float = 300.0) -> None:
        t = time.perf_counter()
        while not cond() and time.perf_counter() - t < timeout_s:
            app.processEvents()
            time.sleep(0.001)

    try:
        t0 = time.perf_counter()
        w.show_animate()
        wait(lambda: w.animate.animator is not None)
        tool = w.animate
        print(f"head loaded in {time.perf_counter() - t0:.1f} s; load {os.getloadavg()[0]:.1f}")
        if not tool.open_track(args.track):
            print(tool.panel.track_message.text())
            return 2
        wait(lambda: tool.frame == 0 and tool._target is None)
        n = tool.frames.n_frames
        print(f"{args.track.name}: {n} frames at {tool.track.fps:g} fps")

        def play(label: str) -> None:
            tool.seek(0)
            wait(lambda: tool._target is None)
            tool.play()
            wait(lambda: not tool.playing)
            print(
                f"{label}: {np.median(tool.play_ms):.1f} ms median frame, a frame every "
                f"{np.median(tool.play_interval_ms):.1f} ms with the render "
                f"(budget {1000 / tool.track.fps:.1f} ms)"
            )

        play("play, frames simulated")
        play("play again, frames restored")
        times = []
        for frame in range(n - 1, 0, -max(1, n // 10)):
            t = time.perf_counter()
            tool.show_frame_now(frame)
            times.append(1000 * (time.perf_counter() - t))
        print(f"scrub backwards: {np.median(times):.1f} ms median ({len(times)} scrubs)")
        t = time.perf_counter()
        for _ in range(5):
            w.plotter.render()
        print(f"render of the 3D view: {1000 * (time.perf_counter() - t) / 5:.1f} ms")
        if args.screenshot is not None:
            tool.show_frame_now(args.frame)
            for _ in range(20):
                app.processEvents()
                time.sleep(0.02)
            w.grab().save(str(args.screenshot))
            print(f"screenshot: {args.screenshot} (frame {args.frame})")
        tool.frame_ms.clear()
        w.animate_panel.expression.setCurrentText("smile")
        wait(lambda: not tool.running, 120.0)
        print(f"live sliders (smile settling): {np.median(tool.frame_ms):.1f} ms median frame")
        print(f"load {os.getloadavg()[0]:.1f}")
    finally:
        w.runner.shutdown()
        w.plotter.close()
        w.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
