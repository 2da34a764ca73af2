"""``workbench portrait HEAD --out DIR``: front, three-quarter and profile pictures of a head.

HEAD is a template pack folder, a reconstruction folder (its ``head/`` pack,
in the skull file's frame: the portrait moves it into its Frankfort head
frame first) or ``reference:male`` / ``reference:female``.  DIR receives
``portrait_<view>.png`` and ``portrait_<view>.tif`` (``size`` x ``size``
pixels, 300 dpi) per view and ``portrait.json`` (views, cameras in the head
frame in mm, lens, lights, sizes, timings and the disclaimer); it is written
as a whole and refused when it exists and is not empty unless ``--force``
(the old one then kept as ``DIR.1``).

The pictures are an artistic presentation (:mod:`workbench.render.portrait`):
the skin tone and the iris are defaults the user picks, not evidence, and
``--no-colour`` draws the head in a neutral clay that claims no colour.  A
fit-scan pack's own skin texture (its colour atlas) is used for the skin when
HEAD holds one, unless ``--no-colour``.

A reconstruction folder whose ``case.fcase`` keeps an appearance (colours,
iris, hair and brows chosen in the window's Appearance dock) is drawn in it;
``--skin-tone``, ``--iris``, ``--hair``, ``--brows``, ``--beard`` and
``--moustache`` change single choices (``none`` removes a piece).  Hair,
brows and beard are artistic additions, not evidence, and ``portrait.json``
and each picture's metadata say so.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import TYPE_CHECKING

from workbench.cli.common import add_force_option, add_style_options, chosen_appearance
from workbench.core.appearance import DEFAULT_IRIS, DEFAULT_SKIN_TONE, IRIS_COLOURS, SKIN_TONES
from workbench.pipelines.outcome import JobOutcome

if TYPE_CHECKING:
    from workbench.core.appearance import SkinTexture
    from workbench.model.template import TemplateHead

#: the views and the size limits (also in :mod:`workbench.render.portrait`, which the
#: command imports only when it runs: VTK takes a while to load)
VIEWS = ("front", "three_quarter", "profile")
SIZE_LIMITS = (256, 8000)


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "portrait",
        help="front, three-quarter and profile pictures of a head (PNG and TIFF, 300 dpi)",
        description="Render portraits of a head for an appeal: an 85 mm lens on 35 mm film "
        "(16.1 deg vertical), the camera at eye level, the head filling 80 % of the frame "
        "height, studio lights and physically based shading, on a neutral grey. The front "
        "view shows the subject's right on the viewer's left; three_quarter is turned 45 deg "
        "toward the subject's right; profile is the right profile. An artistic presentation, "
        "not a photograph: the colours are defaults, not evidence.",
    )
    p.add_argument(
        "head",
        help="template pack folder, reconstruction folder (with head/), or reference:male | "
        "reference:female",
    )
    p.add_argument("--out", type=Path, required=True, metavar="DIR", help="output folder")
    p.add_argument(
        "--size",
        type=int,
        default=2000,
        metavar="PX",
        help=f"side of each square picture in pixels, {SIZE_LIMITS[0]}..{SIZE_LIMITS[1]} "
        "(default: %(default)s; 2000 px is 6.7 in at 300 dpi)",
    )
    p.add_argument(
        "--no-colour",
        "--no-color",
        dest="colour",
        action="store_false",
        help="draw every part in one neutral clay (no colour claimed)",
    )
    p.add_argument(
        "--skin-tone",
        choices=list(SKIN_TONES),
        default=None,
        help="the skin's colour, a Monk Skin Tone swatch (mst1-mst10; light, medium and dark "
        "are mst3, mst6, mst9); an artistic default, not evidence (default: the case's, else "
        f"{DEFAULT_SKIN_TONE})",
    )
    p.add_argument(
        "--iris",
        choices=list(IRIS_COLOURS),
        default=None,
        help=f"the iris colour painted on the eyes (default: the case's, else {DEFAULT_IRIS})",
    )
    add_style_options(p)
    p.add_argument(
        "--views",
        default=",".join(VIEWS),
        metavar="A,B,...",
        help=f"the views to render, comma-separated, from {', '.join(VIEWS)} (default: all three)",
    )
    add_force_option(p, folder=True)
    p.set_defaults(handler=run)


def _skin_texture(spec: str, head: TemplateHead) -> SkinTexture | None:
    """A fit-scan pack's own skin atlas, when HEAD (or its ``head/``) holds one."""
    if spec.startswith("reference:"):
        return None
    from workbench.io.skin_colour_export import read_skin_texture

    root = Path(spec)
    for folder in (root, root / "head"):
        texture = read_skin_texture(folder, head.skin) if folder.is_dir() else None
        if texture is not None:
            return texture
    return None


def run(args: argparse.Namespace) -> JobOutcome:
    """Render and write the portrait folder; its key figures as values."""
    from workbench.cli.animate_cmd import load_head
    from workbench.io.outputs import check_output_folder
    from workbench.render.portrait import check_size, check_views, save_portrait

    views = check_views(str(args.views).split(","))
    size = check_size(args.size)
    t0 = time.perf_counter()
    head, _frame, inputs = load_head(args.head)
    check_output_folder(args.out, inputs, args.force)  # before the rendering
    texture = _skin_texture(str(args.head), head) if args.colour else None
    appearance = chosen_appearance(args)
    skin_tone = args.skin_tone or DEFAULT_SKIN_TONE
    iris = args.iris or DEFAULT_IRIS
    if appearance is not None:
        skin_tone, iris = appearance.tone, appearance.iris
    loaded = time.perf_counter() - t0
    saved = save_portrait(
        head,
        args.out,
        force=args.force,
        inputs=inputs,
        notify=print,
        views=views,
        size=size,
        colour=args.colour,
        skin_tone=skin_tone,
        iris=iris,
        skin_texture=texture,
        appearance=appearance,
    )
    seconds = saved.summary["seconds"]
    look = (
        "clay, no colour"
        if not args.colour
        else ("the scan's skin texture" if texture is not None else f"{skin_tone} skin")
        + f", {iris} iris"
    )
    if appearance is not None and appearance.grooming:
        styles = ", ".join(f"{k} {v.replace('_', ' ')}" for k, v in appearance.grooming)
        look += f"; {styles}: artistic additions, not evidence"
    print(
        f"wrote {args.out}: {len(views)} views ({', '.join(views)}) at {size} x {size} px, "
        f"PNG and TIFF, 300 dpi ({look}); rendered in {seconds.get('render', 0.0):.1f} s. "
        "An artistic presentation, not a photograph: the colours are defaults, not evidence."
    )
    return JobOutcome(
        0,
        {
            "views": len(views),
            "size_px": size,
            "colour": bool(args.colour),
            "hair_and_brows": ", ".join(f"{k} {v}" for k, v in appearance.grooming)
            if appearance is not None
            else "",
            "load_s": round(loaded, 2),
            "render_s": round(float(seconds.get("render", 0.0)), 2),
            "write_s": round(float(seconds.get("write", 0.0)), 2),
        },
    )
