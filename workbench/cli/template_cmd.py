"""``workbench template export|build`` and ``workbench render template``.

``template build`` adapts the built-in head to a person's skin and skull
surfaces (:mod:`workbench.services.templates.build`) and writes a template
pack that ``--template PACK`` accepts everywhere; ``export`` and ``render``
take a pack too.  Units mm, head frame (Frankfort Horizontal).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from workbench.cli.common import (
    add_force_option,
    add_units_options,
    print_self_check,
    self_check_status,
    write_json,
)


def register(sub: argparse._SubParsersAction) -> None:
    from workbench.cli.reconstruct_cmd import add_orientation_options

    p = sub.add_parser(
        "template",
        help="the reference head: export it, or build one for a person",
        description="The anatomical reference head (skin, skull, mandible, teeth, "
        "eyes, tongue, landmarks) built from the project's own data; "
        "mm, head frame (Frankfort Horizontal, x = 0 midsagittal).",
    )
    tsub = p.add_subparsers(dest="template_command", metavar="ACTION", required=True)
    ex = tsub.add_parser("export", help="write the template's meshes and landmarks to a folder")
    ex.add_argument("--sex", choices=["female", "male"], default="male")
    ex.add_argument(
        "--template",
        type=Path,
        default=None,
        metavar="PACK",
        help="export this template pack again instead of the built-in head",
    )
    ex.add_argument("--out", type=Path, required=True)
    add_force_option(ex, folder=True)
    ex.set_defaults(handler=run_export)

    b = tsub.add_parser(
        "build",
        help="adapt the reference head to a person's skin and skull surfaces",
        description="Warp the built-in head onto a person's skin and skull (suggested or given "
        "landmarks plus dense surface matches), project it onto both surfaces where "
        "they are reliable, and write a template pack in the person's own Frankfort "
        "head frame (mm). Both meshes (and landmark files) must share one frame, "
        "e.g. the skin and bone surfaces of one CT.",
    )
    b.add_argument(
        "--skin",
        required=True,
        metavar="SKIN_MESH",
        help="skin surface (PLY/STL/OBJ/VTK/VTP) or sample:NAME",
    )
    b.add_argument(
        "--skull",
        required=True,
        metavar="SKULL_MESH",
        help="skull/bone surface in the same frame and units",
    )
    b.add_argument(
        "--landmarks-skin",
        type=Path,
        default=None,
        metavar="FILE",
        help="skin landmarks placed by hand (kept as they are)",
    )
    b.add_argument(
        "--landmarks-skull",
        type=Path,
        default=None,
        metavar="FILE",
        help="skull landmarks placed by hand (kept as they are)",
    )
    add_units_options(b)
    add_orientation_options(b)
    b.add_argument(
        "--sex",
        choices=["female", "male"],
        default="male",
        help="which built-in head to start from",
    )
    b.add_argument("--out", type=Path, required=True, metavar="PACK")
    add_force_option(b, folder=True)
    b.set_defaults(handler=run_build)

    r = sub.add_parser("render", help="pictures of built-in assets")
    rsub = r.add_subparsers(dest="render_command", metavar="WHAT", required=True)
    rt = rsub.add_parser("template", help="front, side and three-quarter PNGs of the template")
    rt.add_argument("--sex", choices=["female", "male"], default="male")
    rt.add_argument(
        "--template",
        type=Path,
        default=None,
        metavar="PACK",
        help="render this template pack instead of the built-in head",
    )
    rt.add_argument("--out", type=Path, required=True)
    add_force_option(rt, folder=True)
    rt.set_defaults(handler=run_render)


def _head(args: argparse.Namespace):
    from workbench.services.templates.cache import reference_head

    pack = getattr(args, "template", None)
    print(
        f"reading template pack {pack} ..."
        if pack
        else f"building the {args.sex} reference head ..."
    )
    return reference_head(args.sex, pack)


def run_export(args: argparse.Namespace) -> int:
    from workbench.io.outputs import check_output_folder, write_folder
    from workbench.io.template_pack import export_template

    check_output_folder(args.out, [args.template], args.force)
    head = _head(args)
    files = write_folder(
        args.out,
        lambda folder: export_template(head, folder),
        force=args.force,
        inputs=[args.template],
        notify=print,
    )
    for path in files:
        print(f"wrote {path}")
    print(f"template {head.template_id} (content hash {head.content_hash[:16]}...)")
    return 0


def run_render(args: argparse.Namespace) -> int:
    from workbench.io.outputs import check_output_folder, write_folder
    from workbench.render.template import render_template

    check_output_folder(args.out, [args.template], args.force)
    head = _head(args)
    files = write_folder(
        args.out,
        lambda folder: render_template(head, folder),
        force=args.force,
        inputs=[args.template],
        notify=print,
    )
    for path in files:
        print(f"wrote {path}")
    return 0


def run_build(args: argparse.Namespace) -> int:
    from workbench.cli.reconstruct_cmd import orientation_of
    from workbench.io.samples import resolve_input
    from workbench.services.templates.build import build_template_pack

    orientation = orientation_of(args, args.skull)
    if orientation is None:
        orientation = orientation_of(args, args.skin)
    result, files = build_template_pack(
        resolve_input(args.skin),
        resolve_input(args.skull),
        args.out,
        sex=args.sex,
        units=args.units,
        scale=args.scale,
        skin_landmarks=args.landmarks_skin,
        skull_landmarks=args.landmarks_skull,
        orientation=orientation,
        progress=lambda m: print(f"  {m}", file=sys.stderr),  # stdout opens with CHECK lines
        force=args.force,
    )
    print_self_check(result.registration.figures.get("self_check"))
    for path in files:
        print(f"wrote {path}")
    for w in result.warnings:
        print(f"  note: {w}")
    head = result.head
    write_json(
        {
            "template_id": head.template_id,
            "content_hash": head.content_hash,
            "mirrored_input": result.mirrored_input,
            "absent_landmarks": head.provenance["absent_landmarks"],
            **result.figures,
        },
        None,
    )
    return self_check_status("template build", result.registration.figures.get("self_check"))
