"""``workbench compare RECON TRUTH``: validate a reconstruction against the true skin.

Both meshes in mm (``--units``/``--truth-units`` convert) and in the same
frame.  Prints the figures as JSON; ``--out DIR`` also writes
``DIR/compare.json`` and ``DIR/heatmap.png`` (the true skin coloured by the
signed distance: red = reconstruction outside, blue = inside).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from workbench.cli.common import add_force_option, add_units_options, load_mesh, write_json
from workbench.core.errors import InputError
from workbench.core.units import UNIT_SCALES
from workbench.services.templates.regions import REGION_NAMES


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "compare",
        help="validate a reconstruction against the true skin (signed distances, JSON)",
        description="For every vertex of the true skin (e.g. the CT skin of the same person) the "
        "signed distance to the reconstruction (mm; positive = reconstruction outside "
        "the true skin): mean absolute, RMS, signed mean and SD, % within 2.5 and "
        "5 mm, overall and per face region. Both meshes must be in the same frame.",
    )
    p.add_argument("recon", help="reconstructed skin (e.g. face.ply from workbench reconstruct)")
    p.add_argument("truth", help="true skin surface (mesh file or sample:NAME)")
    add_units_options(p)
    p.add_argument(
        "--truth-units",
        choices=["auto", *UNIT_SCALES],
        default="auto",
        help="units of the truth mesh file (default: auto, as --units)",
    )
    p.add_argument(
        "--truth-scale",
        type=float,
        default=None,
        metavar="FACTOR",
        help="explicit factor from truth file units to mm",
    )
    p.add_argument(
        "--region",
        default="face",
        help="face (default: the six face regions), all (every truth vertex near the "
        f"reconstruction) or one of: {', '.join(REGION_NAMES)}",
    )
    tpl = p.add_mutually_exclusive_group()
    tpl.add_argument(
        "--template",
        type=Path,
        default=None,
        metavar="PACK",
        help="template pack folder (workbench template export) the reconstruction "
        "was made from; it defines the face regions",
    )
    tpl.add_argument(
        "--sex",
        choices=["female", "male"],
        default=None,
        help="built-in reference head the reconstruction was made from (default male)",
    )
    p.add_argument(
        "--max-distance",
        type=float,
        default=25.0,
        metavar="MM",
        help="truth vertices farther from the reconstruction are not used (default 25)",
    )
    p.add_argument(
        "--clim",
        type=float,
        default=10.0,
        metavar="MM",
        help="heat-map colour range ±MM (default 10)",
    )
    p.add_argument(
        "--frame",
        choices=["auto", "HEAD", "LPS", "RAS"],
        default="auto",
        help="frame of the meshes, to aim the heat-map views (auto: from the template "
        "fit when the reconstruction has its topology, else HEAD)",
    )
    p.add_argument(
        "--out",
        type=Path,
        default=None,
        help="write compare.json and heatmap.png into this folder (a new one; it "
        "must not hold an input)",
    )
    add_force_option(p, folder=True)
    p.set_defaults(handler=run)


def _template_skin(args: argparse.Namespace):
    """The template skin, its labelled regions and skin landmarks (head frame, mm)."""
    if args.template is None:
        from workbench.core.headgen.skin import build_skin

        sex = args.sex or "male"
        skin = build_skin(sex)  # the skin of build_reference_head(sex), without the skull fit
        return f"built-in reference head ({sex})", skin.mesh, skin.regions, skin.landmarks
    from workbench.io.template_pack import load_template_pack

    pack = args.template
    head = load_template_pack(pack)
    mesh, regions, landmarks = head.skin, dict(head.regions), head.skin_landmarks
    info = {"template_id": head.template_id}
    return f"template pack {pack} ({info.get('template_id', '?')})", mesh, regions, landmarks


def run(args: argparse.Namespace) -> int:
    from workbench.services.templates.regions import skin_face_regions
    from workbench.services.validation.compare import compare_surfaces, template_orientation

    if not args.clim > 0:
        raise InputError("--clim", f"must be positive, got {args.clim}")
    if not args.max_distance > 0:
        raise InputError(
            "--max-distance", f"must be a positive number of mm, got {args.max_distance}"
        )
    if args.region not in ("face", "all", *REGION_NAMES):
        raise InputError(
            "--region",
            f"unknown region {args.region!r}",
            f"use face, all or one of: {', '.join(REGION_NAMES)}",
        )
    if args.out is not None:
        from workbench.cli.common import input_paths
        from workbench.io.outputs import check_output_folder

        check_output_folder(
            args.out, input_paths(args.recon, args.truth, args.template), args.force
        )
    recon_read = load_mesh(args.recon, args, kind="head")
    truth_args = argparse.Namespace(units=args.truth_units, scale=args.truth_scale)
    truth_read = load_mesh(
        args.truth, truth_args, kind="face", options=("--truth-units", "--truth-scale")
    )
    recon, truth = recon_read.mesh, truth_read.mesh

    name, skin, skin_regions, landmarks = _template_skin(args)
    same = recon.n_vertices == skin.n_vertices and np.array_equal(recon.faces, skin.faces)
    regions = skin_face_regions(skin, skin_regions, landmarks) if same else None
    if not same and args.region != "all":
        raise InputError(
            args.recon,
            f"region {args.region!r} needs the template skin's topology, but the mesh has "
            f"{recon.n_vertices} vertices / {recon.n_faces} triangles and the {name} skin "
            f"{skin.n_vertices} / {skin.n_faces} (or different triangles)",
            "use --region all, or compare the face.ply written by workbench reconstruct "
            "(PLY, OBJ or VTP keep the vertex order; STL does not)",
        )
    result = compare_surfaces(
        recon,
        truth,
        recon_regions=regions,
        region=args.region,
        max_distance_mm=args.max_distance,
        truth_name=str(truth_read.source_path),
    )

    data = {
        "reconstruction": str(recon_read.source_path),
        "truth": str(truth_read.source_path),
        "template": name if same else None,
        **result.to_json(),
    }
    data["notes"] = [*recon_read.messages, *truth_read.messages, *data["notes"]]
    from workbench.io.samples import credits_for

    credits = credits_for([recon_read.source_path, truth_read.source_path])
    if credits:  # a truth skin from the Visible Human CTs carries NLM's credit line
        data["credits"] = credits
    if args.out is not None:
        from workbench.render.heatmap import render_heatmap

        if args.frame != "auto":
            frame = args.frame
        elif same:
            frame = template_orientation(recon, skin)
        else:
            frame = "HEAD"
        from workbench.io.outputs import staged_folder

        inputs = [recon_read.source_path, truth_read.source_path, args.template]
        data["files"] = {
            "json": str(args.out / "compare.json"),
            "heatmap": str(args.out / "heatmap.png"),
        }
        with staged_folder(args.out, args.force, inputs, notify=print) as folder:
            render_heatmap(
                truth,
                result.truth_vertex_values(),
                folder / "heatmap.png",
                clim=(-args.clim, args.clim),
                frame=frame,
            )
            write_json(data, folder / "compare.json")
    write_json(data, None)
    return 0
