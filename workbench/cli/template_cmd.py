"""``workbench template export`` and ``workbench render template``."""

from __future__ import annotations

import argparse
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("template", help="the built-in reference head",
                       description="The anatomical reference head (skin, skull, mandible, teeth, "
                                   "eyes, tongue, landmarks) built from the project's own data; mm, "
                                   "head frame (Frankfort Horizontal, x = 0 midsagittal).")
    tsub = p.add_subparsers(dest="template_command", metavar="ACTION", required=True)
    ex = tsub.add_parser("export", help="write the template's meshes and landmarks to a folder")
    ex.add_argument("--sex", choices=["female", "male"], default="male")
    ex.add_argument("--out", type=Path, required=True)
    ex.set_defaults(handler=run_export)

    r = sub.add_parser("render", help="pictures of built-in assets")
    rsub = r.add_subparsers(dest="render_command", metavar="WHAT", required=True)
    rt = rsub.add_parser("template", help="front, side and three-quarter PNGs of the template")
    rt.add_argument("--sex", choices=["female", "male"], default="male")
    rt.add_argument("--out", type=Path, required=True)
    rt.set_defaults(handler=run_render)


def _head(sex: str):  # noqa: ANN202
    from workbench.services.template import build_reference_head

    print(f"building the {sex} reference head ...")
    return build_reference_head(sex)


def run_export(args: argparse.Namespace) -> int:
    from workbench.io.template_pack import export_template

    head = _head(args.sex)
    for path in export_template(head, args.out):
        print(f"wrote {path}")
    print(f"template {head.template_id} (content hash {head.content_hash[:16]}...)")
    return 0


def run_render(args: argparse.Namespace) -> int:
    from workbench.render.template import render_template

    head = _head(args.sex)
    for path in render_template(head, args.out):
        print(f"wrote {path}")
    return 0
