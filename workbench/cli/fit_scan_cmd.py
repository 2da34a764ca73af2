"""``workbench fit-scan``: the reference head fitted to a range scan (a template pack).

See :mod:`workbench.services.scan_fit.fit`.  The pack (skin, skull parts,
teeth, eyes, tongue, muscles, skin and skull landmarks) is in the fitted
person's Frankfort head frame, mm; ``fit_report.json`` beside it holds the
figures of the fit, ``fit_report.pdf`` the same with the scan's distance maps
(``pictures/``, see :mod:`workbench.render.scan_fit_pictures`).

Skin over no scan (holes, the part of a partial face the scan does not show)
keeps the reference's shape: it is the pack's region ``inferred`` and the
command says how much of the face was fitted and how much inferred.  A fit
whose skin came out folded or crossed (two heads through each other, a wrong
pose) is written but exits 3 (check before use), like ``reconstruct``.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from workbench.cli.common import add_force_option, add_units_options, write_json
from workbench.core.data_paths import DEFAULT_DEPTH_TABLE
from workbench.pipelines.outcome import JobOutcome


def register(sub: argparse._SubParsersAction) -> None:
    from workbench.cli.reconstruct_cmd import _build, add_orientation_options

    p = sub.add_parser(
        "fit-scan",
        help="fit the reference head to a surface scan of a face (a template pack)",
        description="Adapt the built-in head to a range scan of a living face (structured "
        "light, photogrammetry, a CT's skin surface; holes and noise are fine): the skin "
        "registered onto the scan, the skull, teeth, eyes and tongue placed at the depth "
        "table's tissue depths under it. Writes a template pack (mm, the person's "
        "Frankfort head frame) with fit_report.json and fit_report.pdf (distance maps); "
        "a scan's vertex colours or texture are carried onto the fitted skin.",
    )
    p.add_argument("scan", help="scan mesh (PLY/STL/OBJ/VTK/VTP) or sample:NAME")
    add_units_options(p)
    p.add_argument(
        "--landmarks",
        type=Path,
        default=None,
        metavar="FILE",
        help="skin landmarks placed on the scan (3+ orient it; all are compared in the report)",
    )
    p.add_argument("--sex", choices=["female", "male"], default="male")
    p.add_argument("--table", default=DEFAULT_DEPTH_TABLE, help="depth table id or CSV file")
    p.add_argument(
        "--build",
        type=_build,
        default="normal",
        help="slender|normal|obese where the table has them, else k for mean + k SD",
    )
    p.add_argument(
        "--bone",
        default=None,
        metavar="BONE_MESH",
        help="the true bone surface in the scan's frame and units (a CT): the estimated "
        "skull is compared with it in the report",
    )
    p.add_argument(
        "--texture",
        type=Path,
        default=None,
        metavar="IMAGE",
        help="the texture image the scan's UVs refer to (instead of its OBJ material); "
        "vertex colours or a texture are carried onto the fitted skin",
    )
    p.add_argument(
        "--no-detail",
        dest="detail",
        action="store_false",
        help="skip the fine detail layer (skin_detailed.ply, skin_detail.npz: the scan's "
        "creases and borders over the subdivided skin; ~2-3 s)",
    )
    add_orientation_options(p)
    p.add_argument("--out", type=Path, required=True, metavar="PACK")
    add_force_option(p, folder=True)
    p.set_defaults(handler=run)


def run(args: argparse.Namespace) -> JobOutcome:
    """The fitted pack with its report; exit status 3 when the fit asks for a check."""
    from workbench.cli.common import print_self_check, self_check_status
    from workbench.cli.reconstruct_cmd import orientation_of
    from workbench.io.samples import resolve_input
    from workbench.pipelines.batch.figures import fit_scan_figures
    from workbench.pipelines.scan_fit import fit_scan_to_folder
    from workbench.services.scan_fit.figures import fitted_vs_inferred

    orientation = orientation_of(args, args.scan)
    result, files = fit_scan_to_folder(
        resolve_input(args.scan),
        args.out,
        units=args.units,
        scale=args.scale,
        landmarks=args.landmarks,
        sex=args.sex,
        table=args.table,
        build=args.build,
        orientation=orientation,
        bone_path=None if args.bone is None else resolve_input(args.bone),
        texture=args.texture,
        force=args.force,
        progress=lambda m: print(f"  {m}"),
        note=lambda m: print(f"  note: {m}"),
        detail=args.detail,
    )
    fig = result.figures
    print_self_check(fig.get("self_check"))  # the fit's doubt first, apart from the notes
    for path in files:
        print(f"wrote {path}")
    line = fitted_vs_inferred(fig)
    if line:  # the inferred skin is the pack's region "inferred"
        print(line)
    for w in result.warnings:
        print(f"  note: {w}")
    write_json(
        {
            "template_id": result.head.template_id,
            "mirrored_input": result.mirrored_input,
            **{
                k: fig[k]
                for k in (
                    "face_region_vertices",
                    "face_within_1mm_fraction",
                    "face_within_2_5mm_fraction",
                    "face_mean_distance_mm",
                    "fold_overs",
                    "seconds",
                )
            },
            "tissue_depth_mean_abs_diff_mm": fig["tissue_depths"]["mean_abs_diff_mm"],
            **({"inferred": fig["inferred"]} if "inferred" in fig else {}),
            **({"self_check": fig["self_check"]} if "self_check" in fig else {}),
            **({"skull_vs_bone": fig["skull_vs_bone"]} if "skull_vs_bone" in fig else {}),
            **({"detail": fig["detail"]} if "detail" in fig else {}),
        },
        None,
    )
    # written, but a fit that asks for a check is not a plain success (exit 3)
    check = fig.get("self_check") or {}
    return JobOutcome(
        self_check_status("fit-scan", check),
        fit_scan_figures(fig),
        list(check.get("reasons", ())) if check.get("outcome") == "check" else [],
    )
