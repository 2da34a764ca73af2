"""Start the desktop window (``workbench gui``, ``python -m workbench``).

:func:`run` opens the window, optionally loads a case or a skull and a face
scan, runs the requested steps (suggest landmarks, reconstruct, compare, fit
the scan) and either enters
the event loop or, with ``screenshot``, waits for the work to finish, saves
a picture of the whole window (3D view included; needs a real X display or
Xvfb with ``QT_QPA_PLATFORM=xcb``) and exits.  Units mm throughout.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

os.environ.setdefault("QT_API", "pyside6")


@dataclass
class LaunchOptions:
    """What to open and do before showing (or photographing) the window."""

    case: Path | None = None
    skull: Path | None = None
    ct: Path | None = None
    units: str = "auto"
    scale: float | None = None
    suggest: bool = False
    reconstruct: bool = False
    truth: Path | None = None
    #: a face scan for the Fit scan tool (``units`` / ``scale`` apply to it too), and
    #: whether to fit it
    scan: Path | None = None
    fit_scan: bool = False
    tool: str = "landmarks"
    #: the Animate tool's preset and its intensity (0..1); the tool is "animate" then
    expression: str | None = None
    intensity: float = 1.0
    #: a keyframe/phoneme track for the Animate tool's timeline, and the frame to show
    track: Path | None = None
    track_frame: int = 0
    #: the Age progression tool's ``{"to_age", "from_age", "sex", "view"}`` (None: not asked)
    age: dict | None = None
    screenshot: Path | None = None
    size: tuple[int, int] = (1400, 900)
    steps: list[str] = field(default_factory=list)


def ensure_app(argv: Sequence[str] | None = None):
    from PySide6.QtWidgets import QApplication

    app = QApplication.instance()
    if app is None:
        app = QApplication(list(argv or sys.argv[:1]))
        app.setApplicationName("Forensic workbench")
        icon = Path(__file__).resolve().parent.parent / "resources" / "forensic-workbench.png"
        if icon.is_file():
            from qtpy.QtGui import QIcon

            app.setWindowIcon(QIcon(str(icon)))
        app.setOrganizationName("workbench")
    return app


def prepare(window, options: LaunchOptions) -> list[str]:
    """Load and run what ``options`` ask for, waiting for each step; returns errors."""
    if options.case is not None:
        window.open_case(options.case)
    elif options.skull is not None:
        window.open_skull(options.skull, units=options.units, scale=options.scale)
    elif options.ct is not None:
        window.open_ct(options.ct)
    window.wait_idle()
    if options.suggest:
        window.suggest_landmarks()
        window.wait_idle()
    if options.reconstruct:
        window.reconstruct()
        window.wait_idle()
    if options.truth is not None:
        window.load_truth(options.truth)
        window.wait_idle()
        window.wait_idle()
    if options.scan is not None:
        window.open_scan(options.scan, units=options.units, scale=options.scale)
        window.wait_idle()
        if options.fit_scan:
            window.fit_scan()
            window.wait_idle(timeout_s=600.0)
    tool = options.tool.replace("-", "_")  # "fit-scan" → the "fit_scan" dock
    if tool == "animate" or options.expression is not None or options.track is not None:
        window.show_animate(options.expression, options.intensity)
        window.wait_idle()  # the head loads in the worker
        if options.track is not None:
            if window.animate.open_track(options.track):
                window.animate.show_frame_now(options.track_frame)
        elif options.screenshot is not None:  # the face moved to its pose before the picture
            window.animate.settle_now()
    elif tool == "age":
        age = options.age or {}
        if age.get("view"):
            window.age_panel.mode_buttons[age["view"]].setChecked(True)
        if options.screenshot is not None:
            window.age.prefetch_years = 0  # the picture needs the target age only
        window.show_age(  # with --reconstruct: the reconstructed head is aged
            age.get("to_age"),
            age.get("from_age"),
            age.get("sex"),
            reconstructed=options.reconstruct,
        )
        window.wait_idle(timeout_s=300.0)  # the head loads, then the ages are computed
    elif tool in window.docks:
        window.docks[tool].raise_()
    return list(window.errors)


def run(options: LaunchOptions) -> int:
    """Open the window; with ``options.screenshot`` save a picture and return."""
    app = ensure_app()
    from workbench.qt.main_window import MainWindow

    screenshot = options.screenshot
    shot = screenshot is not None
    window = MainWindow(auto_update=not shot, interactive=not shot)
    window.resize(*options.size)
    window.show()
    app.processEvents()
    errors = prepare(window, options)
    if screenshot is None:
        from PySide6.QtCore import QTimer

        from workbench.qt.autosave import offer_recovery

        QTimer.singleShot(0, lambda: offer_recovery(window))  # unsaved work of a crash
        return int(app.exec())
    window.reset_view()
    window.wait_idle()
    path = window.save_screenshot(screenshot)
    window.close()
    for text in errors:
        print(
            f"workbench gui: {text.splitlines()[0]} {' '.join(text.splitlines()[1:])}",
            file=sys.stderr,
        )
    print(f"wrote {path}")
    return 2 if errors else 0
