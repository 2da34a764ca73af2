"""``workbench mesh info|convert``: inspect and convert mesh files."""

from __future__ import annotations

import argparse
from pathlib import Path

from workbench.cli.common import (
    add_force_option,
    add_units_options,
    load_mesh,
    mesh_summary,
    output_path,
    write_json,
)
from workbench.core.mesh import validate
from workbench.core.repair import clean, fill_small_holes, keep_largest_component
from workbench.io.meshes import write_mesh


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "mesh",
        help="inspect, check and convert mesh files",
        description="Inspect, check and convert mesh files (PLY, STL, OBJ, VTK, VTP).",
    )
    msub = p.add_subparsers(dest="mesh_command", metavar="ACTION", required=True)

    info = msub.add_parser("info", help="size, units judgement and validation report (JSON)")
    info.add_argument("mesh", help="mesh file or sample:NAME")
    info.add_argument(
        "--kind",
        choices=["head", "skull", "face"],
        default="head",
        help="what the mesh shows (sets the plausible size range for units)",
    )
    info.add_argument("--units", choices=["auto", "mm", "cm", "m", "in"], default="auto")
    info.add_argument("--scale", type=float, default=None, metavar="FACTOR")
    info.add_argument(
        "--out", type=Path, default=None, help="write the JSON here instead of stdout"
    )
    add_force_option(info)
    info.set_defaults(handler=run_info)

    conv = msub.add_parser("convert", help="convert to another format (and to mm)")
    conv.add_argument("mesh", help="mesh file or sample:NAME")
    conv.add_argument("out", type=Path, help="output file; the extension picks the format")
    add_units_options(conv)
    conv.add_argument("--kind", choices=["head", "skull", "face"], default="head")
    conv.add_argument(
        "--clean",
        action="store_true",
        help="remove NaN vertices, degenerate/duplicate triangles, unused vertices",
    )
    conv.add_argument(
        "--largest-component", action="store_true", help="keep only the largest piece"
    )
    conv.add_argument(
        "--fill-holes",
        type=int,
        default=0,
        metavar="MAX_EDGES",
        help="close holes bounded by at most this many edges",
    )
    conv.add_argument("--ascii", action="store_true", help="text encoding where the format has one")
    add_force_option(conv)
    conv.set_defaults(handler=run_convert)


def run_info(args: argparse.Namespace) -> int:
    from workbench.io.meshes import read_mesh
    from workbench.io.samples import resolve_input

    path = resolve_input(args.mesh)
    # units and scale go in as given (both at once are refused); a damaged file is
    # inspected, not refused: its NaN vertices are counted in the validation report
    result = read_mesh(
        path, units=args.units, scale=args.scale, kind=args.kind, allow_nonfinite=True
    )
    report = validate(result.mesh)
    data = {
        "file": str(path),
        "format": result.format,
        "scale_applied": result.scale_applied,
        "units": {
            "guess": result.units.guess,
            "looks_like_mm": bool(result.units.plausible_in_mm),
            "needs_confirmation": bool(result.units.needs_confirmation),
            "message": result.units.message,
        },
        **mesh_summary(result.mesh),
        "validation": report.to_dict() | {"problems": report.problems()},
        "messages": list(result.messages),
    }
    if args.out is None:
        write_json(data, None)
    else:
        with output_path(args.out, args, path) as out:
            write_json(data, out)
    return 0


def run_convert(args: argparse.Namespace) -> int:
    from workbench.cli.common import input_paths
    from workbench.io.outputs import check_output_file

    check_output_file(args.out, input_paths(args.mesh), args.force)
    result = load_mesh(args.mesh, args, kind=args.kind)
    mesh = result.mesh
    notes: list[str] = []
    if args.clean:
        mesh, done = clean(mesh)
        notes += done
    if args.fill_holes:
        step = fill_small_holes(mesh, args.fill_holes)
        mesh = step.mesh
        notes += [step.message] if step.changed else []
    if args.largest_component:
        step = keep_largest_component(mesh)
        mesh = step.mesh
        notes += [step.message] if step.changed else []
    with output_path(args.out, args, result.source_path) as out:
        write_mesh(out, mesh, binary=not args.ascii)
    for note in [*result.messages, *notes]:
        print(f"note: {note}")
    print(f"wrote {args.out}: {mesh.n_vertices} vertices, {mesh.n_faces} triangles (mm)")
    return 0
