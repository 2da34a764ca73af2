"""``workbench gui [CASE]``: open the desktop window (``python -m workbench`` does too).

``--screenshot FILE.png`` opens, loads, runs the asked-for steps, renders,
saves a picture of the whole window and exits (for tests and documentation;
headless it needs Xvfb and ``QT_QPA_PLATFORM=xcb``).  Units mm.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from workbench.core.errors import InputError

TOOLS = ("landmarks", "dowels", "reconstruct", "compare", "fit-scan", "animate", "age")


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "gui",
        help="open the desktop window",
        description="The workbench window: skull landmarks, dowels, guides, "
        "reconstruction, comparison and export.",
    )
    add_arguments(p)
    p.set_defaults(handler=run)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "case",
        nargs="?",
        default=None,
        help="case file (.fcase) or skull mesh (.ply .stl .obj .vtk .vtp) to open, or sample:NAME",
    )
    p.add_argument(
        "--ct",
        default=None,
        help="CT volume or DICOM folder to open, or sample:NAME (e.g. sample:headsq)",
    )
    p.add_argument(
        "--units",
        choices=["auto", "mm", "cm", "m", "in"],
        default="auto",
        help="units of a skull mesh or a --scan (default: judged from its size)",
    )
    p.add_argument(
        "--scale",
        type=float,
        default=None,
        metavar="MM_PER_UNIT",
        help="millimetres per file unit of a skull mesh or a --scan",
    )
    p.add_argument("--suggest", action="store_true", help="suggest the skull landmarks")
    p.add_argument("--reconstruct", action="store_true", help="reconstruct the face")
    p.add_argument(
        "--truth",
        default=None,
        help="true skin surface to compare with (same frame, mm), or sample:NAME",
    )
    p.add_argument(
        "--scan",
        default=None,
        metavar="SCAN_MESH",
        help="face scan to open in the Fit scan tool (--units/--scale apply to it), or sample:NAME",
    )
    p.add_argument(
        "--fit-scan",
        action="store_true",
        help="fit the reference head to the --scan (as workbench fit-scan does)",
    )
    p.add_argument("--tool", choices=TOOLS, default="landmarks", help="dock shown in front")
    p.add_argument(
        "--expression",
        default=None,
        metavar="NAME",
        help="Animate tool: show the reference head with this preset (e.g. smile; "
        "implies --tool animate)",
    )
    p.add_argument(
        "--intensity",
        type=float,
        default=1.0,
        metavar="0..1",
        help="intensity of the --expression (default 1)",
    )
    p.add_argument(
        "--track",
        type=Path,
        default=None,
        metavar="FILE.json",
        help="Animate tool: open this keyframe/phoneme track on the timeline (the format of "
        "workbench animate --track; implies --tool animate)",
    )
    p.add_argument(
        "--frame",
        type=int,
        default=0,
        metavar="N",
        help="with --track: the frame shown (simulated up to it)",
    )
    p.add_argument(
        "--age-to",
        type=float,
        default=None,
        metavar="AGE",
        help="Age progression tool: show the head aged to AGE years (implies --tool age); "
        "the reference head, or with --reconstruct the reconstructed one",
    )
    p.add_argument(
        "--age-from",
        type=float,
        default=None,
        metavar="AGE",
        help="Age progression tool: the head's age now (default 18, the reference heads)",
    )
    p.add_argument(
        "--sex",
        choices=["female", "male"],
        default=None,
        help="Age progression tool: the reference head and norms of this sex (default male)",
    )
    p.add_argument(
        "--age-view",
        choices=["side", "overlay"],
        default=None,
        help="Age progression tool: before/after side by side or overlaid with a distance "
        "colour map (default side)",
    )
    p.add_argument(
        "--screenshot",
        type=Path,
        default=None,
        metavar="FILE.png",
        help="save a picture of the window after loading, then exit",
    )
    p.add_argument("--size", default="1400x900", help="window size WxH (default 1400x900)")


def options_from(args: argparse.Namespace):
    from workbench.qt.app import LaunchOptions

    try:
        w, h = (int(v) for v in str(args.size).lower().split("x"))
    except ValueError:
        raise InputError("--size", f"expected WxH, e.g. 1400x900, got {args.size!r}") from None
    from workbench.io.samples import resolve_input

    case = skull = None
    if args.case is not None:
        path = resolve_input(str(args.case))
        if path.suffix.lower() == ".fcase":
            case = path
        else:
            skull = path
    ct = None if args.ct is None else resolve_input(str(args.ct))
    truth = None if args.truth is None else resolve_input(str(args.truth))
    scan = None if args.scan is None else resolve_input(str(args.scan))
    if args.fit_scan and scan is None:
        raise InputError("--fit-scan", "needs a scan to fit", "give it with --scan FILE")
    tool = args.tool
    if args.expression is not None:
        from workbench.services.animation.animator import EXPRESSIONS

        if args.expression not in EXPRESSIONS:
            raise InputError(
                args.expression,
                "is not an expression",
                "valid names: " + ", ".join(sorted(EXPRESSIONS)),
            )
        if not 0.0 <= args.intensity <= 1.0:
            raise InputError("--intensity", f"must be between 0 and 1, got {args.intensity}")
        tool = "animate"
    if args.track is not None:
        if not args.track.is_file():
            raise InputError(args.track, "does not exist (a track .json was expected)")
        if args.frame < 0:
            raise InputError("--frame", f"must be 0 or more, got {args.frame}")
        tool = "animate"
    age_asked = any(v is not None for v in (args.age_to, args.age_from, args.sex, args.age_view))
    if age_asked:
        tool = "age"
    if args.screenshot is not None and args.screenshot.suffix.lower() != ".png":
        raise InputError(args.screenshot, "the screenshot must be a .png file")
    return LaunchOptions(
        case=case,
        skull=skull,
        ct=ct,
        units=args.units,
        scale=args.scale,
        suggest=args.suggest,
        reconstruct=args.reconstruct,
        truth=truth,
        scan=scan,
        fit_scan=args.fit_scan,
        tool=tool,
        expression=args.expression,
        intensity=args.intensity,
        track=args.track,
        track_frame=args.frame,
        age=(
            {
                "to_age": args.age_to,
                "from_age": args.age_from,
                "sex": args.sex,
                "view": args.age_view,
            }
            if age_asked or tool == "age"
            else None
        ),
        screenshot=args.screenshot,
        size=(w, h),
    )


def run(args: argparse.Namespace) -> int:
    from workbench.qt.app import run as run_window

    return run_window(options_from(args))


def launch(argv: list[str] | None = None) -> int:
    """``python -m workbench`` without arguments: parse ``argv`` as ``workbench gui`` does."""
    parser = argparse.ArgumentParser(prog="workbench gui")
    add_arguments(parser)
    return run(parser.parse_args(argv or []))
