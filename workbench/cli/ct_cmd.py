"""``workbench mesh-from-ct``: bone or skin surface of a CT volume.

The mesh is written in the volume's physical frame (LPS or RAS) in mm, and the
file's header says which (3D Slicer's ``SPACE=`` tag).  When
the volume is registered sample data that must carry a credit line (the NLM
Visible Human CTs), the credit is printed (also with ``--quiet``), goes into
the JSON report, and into a PLY output's header as ``comment credit: ...``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from workbench.cli.common import add_force_option, output_path, progress_printer, write_json
from workbench.io.mesh_formats import ply
from workbench.io.meshes import write_mesh
from workbench.io.samples import credit_comment, resolve_input
from workbench.services.ct.ct_mesh import mesh_from_ct


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "mesh-from-ct",
        help="extract the bone or skin surface of a CT volume",
        description=(
            "Extract an iso-surface (bone or skin) from a CT or other volume: a DICOM series "
            "folder, NRRD/NHDR, MetaImage (.mhd/.mha) or NIfTI file, or sample:headsq. The mesh "
            "is written in the volume's physical frame (LPS or RAS, as the file says) in mm."
        ),
    )
    p.add_argument("volume", help="volume file or DICOM folder, or sample:NAME")
    p.add_argument("--tissue", choices=["bone", "skin"], default="bone")
    p.add_argument(
        "--iso",
        type=float,
        default=None,
        help="iso level in the volume's units (HU for CT); default: the tissue preset",
    )
    p.add_argument(
        "--target-triangles",
        type=int,
        default=None,
        metavar="N",
        help="decimate to about N triangles (quadric error)",
    )
    p.add_argument(
        "--smooth",
        type=int,
        default=0,
        metavar="ITER",
        help="Taubin smoothing iterations (default 0: unsmoothed, best for measuring)",
    )
    p.add_argument(
        "--all-components",
        action="store_true",
        help="keep every piece instead of the largest connected one",
    )
    p.add_argument("--out", required=True, type=Path, help="output mesh (.ply .stl .obj .vtk .vtp)")
    p.add_argument(
        "--report",
        type=Path,
        default=None,
        help="also write a JSON report (iso rule, timings, validation)",
    )
    p.add_argument("--quiet", action="store_true")
    add_force_option(p)
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> int:
    from workbench.core.errors import InputError
    from workbench.io.outputs import check_output_file, same_file
    from workbench.services.ct.ct_mesh import check_extraction_settings

    check_extraction_settings(args.iso, args.target_triangles, args.smooth)
    source = resolve_input(args.volume)
    check_output_file(args.out, [source], args.force)  # before the extraction
    if args.report is not None:
        if same_file(args.report, args.out):
            raise InputError(args.report, "is also the --out mesh", "give the report its own name")
        check_output_file(args.report, [source], args.force)
    result = mesh_from_ct(
        source,
        tissue=args.tissue,
        iso=args.iso,
        target_triangles=args.target_triangles,
        smooth_iterations=args.smooth,
        largest_component=not args.all_components,
        progress=progress_printer(not args.quiet),
    )
    # the volume's own frame, tagged (SPACE=LPS or RAS) so 3D Slicer lays the mesh on the CT;
    # the workbench reads an LPS-tagged mesh turned into RAS, as it reads LPS landmark files
    with output_path(args.out, args, source) as out:
        if result.credit and out.suffix.lower() == ".ply":
            ply.write(
                out, result.mesh, comments=[credit_comment(result.credit)], space=result.frame
            )
        else:
            write_mesh(out, result.mesh, space=result.frame)
    if args.report:
        with output_path(args.report, args, source) as report:
            write_json(result.to_dict(), report)
    if result.credit:
        print(f"credit: {result.credit}")
        if args.out.suffix.lower() != ".ply":
            print(
                f"  note: {args.out.suffix} files have no header comments to carry this credit; "
                "keep it with the mesh (a .ply output or the --report JSON records it)"
            )
    if not args.quiet:
        print(f"{args.tissue} surface at iso {result.iso:g} ({result.rule})")
        if result.iso_note:
            print(f"  note: {result.iso_note}")
        print(f"  {result.summary}")
        lo, hi = result.mesh.bounds
        print(f"  extent {(hi - lo).round(1).tolist()} mm in the volume's {result.frame} frame")
        for w in result.warnings:
            print(f"  note: {w}")
        print(f"  wrote {args.out}")
    return 0
