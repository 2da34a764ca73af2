"""The reconstruct dock's build slider (issue 31), measured under Xvfb.

What it does: opens the window, fits the face to the real skull
(``skull.obj`` × 15 mm, the reference head's suggested landmarks, the
window's own fit), brings the Reconstruct dock to the front and moves the
build slider ``--moves`` times back and forth between slender and heavy
(faces and blends in between).  Each move morphs the face in place
(``BuildFaces.vertices_at`` → input frame → the drawn points and normals,
no new actor) and the view paints it.  It prints, per colouring ("skin" and
"band"):

* the GUI-thread time of one slider move until the view painted it
  (points moved + render), median and max, in ms per redraw;
* the part of it spent before the render (the slider's handler: blend,
  frame mapping, normals), median;
* the same with the face alone in the view (every other layer hidden: the
  skin's own cost), and one full-quality redraw of the view at rest;
* the skin's vertex and triangle count.

The budget is < 50 ms per redraw on the reference skin.  With
``--screenshots DIR`` it also saves the window with the slider at slender,
average and heavy (``slider_<build>.png``) and the band colouring at heavy
(``slider_band_heavy.png``).

Run (needs an X server; Xvfb is enough)::

    QT_QPA_PLATFORM=xcb xvfb-run -a -s "-screen 0 1600x1000x24" \\
        python benchmarks/bench_build_slider.py [--moves 30] [--screenshots DIR]

Figures, not assertions.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("QT_API", "pyside6")

REPO = Path(__file__).resolve().parents[1]
DEFAULT_SKULL = REPO.parent / "shared" / "data" / "skull_mesh_yahoojapan" / "skull.obj"


def _wait(app, window, timeout: float = 300.0) -> None:
    end = time.monotonic() + timeout
    while window.busy and time.monotonic() < end:
        app.processEvents()
        time.sleep(0.002)
    for _ in range(5):
        app.processEvents()


def _painted(app, window, timeout: float = 2.0) -> None:
    """Spin the event loop until the view has painted the render asked for."""
    start = time.perf_counter()
    while window.scene.render_queued and time.perf_counter() - start < timeout:
        app.processEvents()


def _positions(panel, moves: int) -> list[int]:
    """Slider positions slender → heavy → slender …, faces and blends, never twice in a row."""
    top = panel.build_slider.maximum()
    sweep = [round(v) for v in np.linspace(0, top, 11)]
    path = sweep + sweep[-2:0:-1]
    out = [path[(i + 1) % len(path)] for i in range(moves)]  # the first move leaves average
    return out


def _moves(app, window, positions: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """(seconds until painted, seconds of the slider's handler) per move, the slider held
    down as in a mouse drag (released at the end: one full-quality render follows)."""
    slider = window.reconstruct_panel.build_slider
    painted, handler = [], []
    slider.setSliderDown(True)
    for value in positions:
        _painted(app, window)
        start = time.perf_counter()
        slider.setValue(value)  # the window moves the face's points, asks for one render
        handler.append(time.perf_counter() - start)
        _painted(app, window)
        painted.append(time.perf_counter() - start)
    slider.setSliderDown(False)
    _rest(app, window)
    return np.array(painted), np.array(handler)


def _rest(app, window) -> None:
    """Wait until the slider's rest timer has put the skull back in full and it painted."""
    end = time.perf_counter() + 2.0
    while (window.detail.active or window.scene.render_queued) and time.perf_counter() < end:
        app.processEvents()
        time.sleep(0.002)


def _full_redraws(app, window, n: int = 10) -> np.ndarray:
    """Seconds of a full-quality render of the view (what one redraw costs at rest)."""
    out = []
    for _ in range(n):
        _painted(app, window)
        start = time.perf_counter()
        window.scene.request_render()
        _painted(app, window)
        out.append(time.perf_counter() - start)
    return np.array(out)


def _grab(app, window, path: Path) -> None:
    window.scene.request_render()
    _painted(app, window)
    for _ in range(3):
        app.processEvents()
    window.grab().save(str(path))
    print(f"  wrote {path}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("skull", nargs="?", default=str(DEFAULT_SKULL))
    parser.add_argument("--scale", type=float, default=15.0)
    parser.add_argument("--moves", type=int, default=30, help="slider moves per colouring")
    parser.add_argument("--screenshots", type=Path, default=None, help="folder for PNGs")
    args = parser.parse_args(argv)

    from workbench.qt.app import ensure_app

    app = ensure_app()
    from workbench.qt.main_window import MainWindow

    window = MainWindow(auto_update=False, interactive=False)
    window.resize(1400, 900)
    window.show()
    app.processEvents()
    t0 = time.perf_counter()
    window.open_skull(args.skull, scale=args.scale)
    _wait(app, window)
    window.suggest_landmarks()
    _wait(app, window)
    window.reconstruct()
    _wait(app, window)
    fit = window.fit
    if window.errors or fit is None:
        print("failed:", window.errors, file=sys.stderr)
        return 1
    if fit.builds is None:
        print("this fit has no build faces (nothing to slide)", file=sys.stderr)
        return 1
    print(f"fit ready in {time.perf_counter() - t0:.1f} s (open, suggest, fit)")
    window.docks["reconstruct"].raise_()
    panel = window.reconstruct_panel
    _wait(app, window)
    _painted(app, window)
    skin = fit.recon.head.skin
    print(
        f"skin: {skin.n_vertices} vertices, {skin.n_faces} triangles; "
        f"skull drawn: {window.document.case.specimen.mesh.n_faces} triangles; "
        f"GL: {window.scene.gl_renderer}"
    )
    b = fit.builds
    print(
        "builds: "
        + ", ".join(f"{n} BMI {b.bmi[n]:g} (z {b.z[n]:+.2f})" for n in b.names)
        + f"; main {b.main}"
    )

    positions = _positions(panel, args.moves)
    for colouring in ("skin", "band"):
        panel.colouring.setCurrentText(colouring)
        panel.set_build(b.main if b.main in b.names else b.names[0])
        _wait(app, window)
        _painted(app, window)
        _moves(app, window, positions[:3])  # warm-up (first paints of the new actor)
        painted, handler = _moves(app, window, positions)
        ms, hms = 1000 * painted, 1000 * handler
        print(
            f"{colouring:>5} colouring, {len(ms)} slider moves (held, light skull): "
            f"median {np.median(ms):.1f} ms, max {ms.max():.1f} ms per redraw "
            f"(handler before the render: median {np.median(hms):.2f} ms)"
        )
    # the face alone (every other layer hidden): what the skin itself costs a redraw
    panel.colouring.setCurrentText("skin")
    _wait(app, window)
    others = [k for k, on in window.scene.visible.items() if on and k != "face"]
    for layer in others:
        window.scene.set_visible(layer, False)
    _moves(app, window, positions[:3])
    painted, _ = _moves(app, window, positions)
    for layer in others:
        window.scene.set_visible(layer, True)
    ms = 1000 * painted
    print(
        f" face alone (skull, dowels, landmarks, guides hidden), {len(ms)} moves: "
        f"median {np.median(ms):.1f} ms, max {ms.max():.1f} ms per redraw"
    )
    full = 1000 * _full_redraws(app, window)
    print(
        f"a full-quality redraw of the view at rest (full skull, for comparison): "
        f"median {np.median(full):.1f} ms, max {full.max():.1f} ms"
    )
    print("budget: < 50 ms per redraw")

    if args.screenshots is not None:
        args.screenshots.mkdir(parents=True, exist_ok=True)
        panel.colouring.setCurrentText("skin")
        _wait(app, window)
        for name in b.names:
            panel.set_build(name)
            _rest(app, window)
            _grab(app, window, args.screenshots / f"slider_{name}.png")
        panel.colouring.setCurrentText("band")
        _wait(app, window)
        _grab(app, window, args.screenshots / "slider_band_heavy.png")
        panel.set_build(b.main if b.main in b.names else b.names[0])
        _painted(app, window)

    window.runner.shutdown()
    window.plotter.close()
    window.close()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
