"""``workbench landmarks check|convert``: landmark files in the catalogue's codes."""

from __future__ import annotations

import argparse
from pathlib import Path

from workbench.cli.common import (
    add_force_option,
    add_units_options,
    input_paths,
    load_mesh,
    output_path,
    print_self_check,
    self_check_status,
    write_json,
)
from workbench.core.errors import LandmarkError
from workbench.io.catalogue import load_catalogue
from workbench.io.markups import read_landmarks, write_landmarks


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "landmarks",
        help="check and convert landmark files",
        description="Landmark files: 3D Slicer .mrk.json and .fcsv, MeshLab .pp, plain .csv. "
        "Labels are matched against the landmark catalogue (Farkas skin codes, "
        "craniometric / Caple & Stephan skull codes).",
    )
    lsub = p.add_subparsers(dest="landmarks_command", metavar="ACTION", required=True)
    for name, helptext, handler in (
        ("check", "list recognised, unknown, duplicate and undefined points", run_check),
        ("convert", "convert between formats (exact)", run_convert),
    ):
        q = lsub.add_parser(name, help=helptext)
        q.add_argument("file", type=Path)
        if name == "convert":
            q.add_argument("out", type=Path)
            q.add_argument(
                "--coordinate-system",
                choices=["LPS", "RAS"],
                default="LPS",
                help="for .mrk.json/.fcsv output (default LPS, as Slicer writes)",
            )
            add_force_option(q)
        q.add_argument("--surface", choices=["skull", "skin"], required=True)
        q.add_argument(
            "--strict", action="store_true", help="fail on unknown, duplicate or undefined points"
        )
        q.set_defaults(handler=handler)

    fr = lsub.add_parser(
        "frame",
        help="Frankfort Horizontal head frame from porions, orbitales and midline points",
        description="Compute the head frame (x to the subject's left, x = 0 midsagittal, y up, "
        "z toward the face; mm) from a landmark file. Prints the 4x4 transform from "
        "the file's frame. With --apply, also writes a copy of a mesh in the head "
        "frame (the input mesh is not changed).",
    )
    fr.add_argument("file", type=Path)
    fr.add_argument("--surface", choices=["skull", "skin"], required=True)
    fr.add_argument(
        "--apply",
        default=None,
        metavar="MESH",
        help="mesh in the same frame and units as the landmarks",
    )
    add_units_options(fr)
    fr.add_argument("--out", type=Path, default=None, help="where to write the aligned mesh")
    add_force_option(fr)
    fr.set_defaults(handler=run_frame, strict=False)

    sg = lsub.add_parser(
        "suggest",
        help="suggest the whole skull (or skin) landmark set on a mesh",
        description="Transfer the reference head's landmarks onto a skull or skin mesh: coarse "
        "alignment (from --seed points, an orientation, or a search), a regularised "
        "landmark warp, then projection onto the surface. Landmarks on missing parts "
        "come out 'absent'; each suggestion carries a confidence (0-1).",
    )
    sg.add_argument("mesh", help="skull or skin mesh, or sample:NAME")
    add_units_options(sg)
    sg.add_argument("--surface", choices=["skull", "skin"], default="skull")
    sg.add_argument(
        "--seed",
        type=Path,
        default=None,
        metavar="FILE",
        help="landmarks you placed (kept as they are; 3+ fix the alignment)",
    )
    sg.add_argument("--sex", choices=["female", "male"], default="male")
    sg.add_argument("--template", type=Path, default=None, metavar="PACK")
    from workbench.cli.reconstruct_cmd import add_orientation_options

    add_orientation_options(sg)
    sg.add_argument("--out", type=Path, required=True, help="output .mrk.json (or .fcsv/.csv/.pp)")
    add_force_option(sg)
    sg.set_defaults(handler=run_suggest, strict=False)

    sn = lsub.add_parser(
        "snap",
        help="snap skull landmarks of a case to the features their definitions name",
        description="Move skull landmarks of a case file to the anatomical feature their "
        "catalogue definition names, near where they are (e.g. glabella to the most "
        "anterior midline point within 8 mm), using data_tables/landmarks/"
        "snap_rules.csv. Needs both porions and an orbitale (the head frame). "
        "Snapped landmarks become 'placed'. The case is saved atomically.",
    )
    sn.add_argument("case", type=Path, help="case file (.fcase)")
    which = sn.add_mutually_exclusive_group(required=True)
    which.add_argument(
        "--code",
        action="append",
        default=None,
        metavar="CODE",
        help="landmark to snap (repeatable); one without a rule is only moved "
        "onto the midsagittal plane if it is a midline landmark",
    )
    which.add_argument(
        "--all",
        action="store_true",
        help="every placed or suggested skull landmark that has a snap rule",
    )
    sn.add_argument(
        "--out",
        type=Path,
        default=None,
        help="write the result to this case file instead of over CASE (an existing "
        "file only with --force)",
    )
    add_force_option(sn)
    sn.add_argument("--dry-run", action="store_true", help="print what would move; save nothing")
    sn.set_defaults(handler=run_snap, strict=False)


def _read(args: argparse.Namespace):
    return read_landmarks(
        args.file,
        args.surface,
        catalogue=load_catalogue(),
        allow_undefined=True,
        strict=args.strict,
    )


def run_check(args: argparse.Namespace) -> int:
    result = _read(args)
    catalogue = load_catalogue()
    expected = set(catalogue.codes(args.surface))
    present = {lm.code for lm in result.landmarks}
    write_json(
        {
            "file": str(args.file),
            "surface": args.surface,
            "coordinate_system": result.coordinate_system,
            "defined": [lm.code for lm in result.landmarks if lm.is_defined],
            "unknown": list(result.unknown),
            "duplicates": list(result.duplicates),
            "undefined": list(result.undefined),
            "not_in_file": sorted(expected - present),
            "messages": list(result.messages),
        },
        None,
    )
    return 0


def run_convert(args: argparse.Namespace) -> int:
    from workbench.io.outputs import check_output_file

    check_output_file(args.out, [args.file], args.force)
    result = _read(args)
    if not len(result.landmarks):
        raise LandmarkError(f"{args.file}: no recognised landmarks to write")
    kwargs = {}
    if args.out.suffix.lower() in (".json", ".fcsv") or args.out.name.endswith(".mrk.json"):
        kwargs["coordinate_system"] = args.coordinate_system
    with output_path(args.out, args, args.file) as out:
        write_landmarks(out, result.landmarks, **kwargs)
    for message in result.messages:
        print(f"note: {message}")
    print(f"wrote {len(result.landmarks)} landmarks to {args.out}")
    return 0


def run_frame(args: argparse.Namespace) -> int:
    from workbench.io.meshes import write_mesh
    from workbench.services.landmarks.frame import head_frame_from_landmarks

    if args.apply and args.out is not None:
        from workbench.io.outputs import check_output_file

        check_output_file(args.out, input_paths(args.file, args.apply), args.force)
    from workbench.services.case.input_checks import check_landmark_geometry

    result = _read(args)
    check_landmark_geometry(result.landmarks, args.file)
    frame = head_frame_from_landmarks(result.landmarks)
    head = result.landmarks.transformed(frame.input_to_head)
    write_json(
        {
            "file": str(args.file),
            "input_to_head": frame.input_to_head.round(12).tolist(),
            "fh_residual_mm": frame.fh_residual_mm,
            "mirrored_input": frame.mirrored_input,
            "landmarks_in_head_frame_mm": {
                lm.code: lm.position.round(4).tolist() for lm in head if lm.is_defined
            },
        },
        None,
    )
    if frame.mirrored_input:
        print(
            "warning: the landmarks imply a mirrored input (left and right swapped, or a "
            "mesh exported with one axis flipped); check the left/right labels"
        )
    if args.apply:
        if args.out is None:
            raise LandmarkError("--apply needs --out for the aligned copy")
        read = load_mesh(args.apply, args, kind="skull")
        with output_path(args.out, args, args.file, read.source_path) as out:
            write_mesh(out, read.mesh.transformed(frame.input_to_head))
        print(f"wrote {args.out} (head frame, mm)")
    return 0


def run_suggest(args: argparse.Namespace) -> int:
    from workbench.cli.reconstruct_cmd import orientation_of
    from workbench.io.outputs import check_output_file
    from workbench.services.landmarks.transfer import transfer_landmarks
    from workbench.services.templates.cache import reference_head

    check_output_file(args.out, input_paths(args.mesh, args.seed, args.template), args.force)
    read = load_mesh(
        args.mesh,
        args,
        kind="skull" if args.surface == "skull" else "head",
        check_skull=args.surface == "skull",
    )
    head = reference_head(args.sex, args.template)
    seeds = None
    if args.seed is not None:
        seeds = read_landmarks(args.seed, args.surface, catalogue=load_catalogue()).landmarks
        if read.scale_applied != 1.0:
            import numpy as np

            m = np.eye(4)
            m[:3, :3] *= read.scale_applied
            seeds = seeds.transformed(m)
    if args.surface == "skull":
        return _suggest_skull(args, read, head, seeds)
    result = transfer_landmarks(
        read.mesh,
        head.skin,
        head.skin_landmarks,
        seeds=seeds,
        orientation=orientation_of(args, args.mesh),
    )
    lms = result.landmarks
    if read.scale_applied != 1.0:  # back to the file's units
        import numpy as np

        m = np.eye(4)
        m[:3, :3] /= read.scale_applied
        lms = lms.transformed(m)
    _write_suggested(args, read, lms)
    for w in result.warnings:
        print(f"note: {w}")
    write_json(
        {
            "file": str(args.out),
            "surface": args.surface,
            "template": head.template_id,
            "placed": [lm.code for lm in lms if lm.status == "placed"],
            "suggested": {
                lm.code: round(lm.confidence, 2) for lm in lms if lm.status == "suggested"
            },
            "absent": list(result.absent),
            "alignment": {
                "method": result.alignment.method,
                "rms_mm": round(result.alignment.rms_mm, 2),
                "scale": round(result.alignment.scale, 4),
            },
            "warp_residual_mm": round(result.warp_residual_mm, 3),
            "matches": result.matches,
        },
        None,
    )
    return 0


def _write_suggested(args: argparse.Namespace, read, lms) -> None:
    options = {"coordinate_system": "RAS"} if args.out.suffix in (".json", ".fcsv") else {}
    with output_path(args.out, args, read.source_path, args.seed, args.template) as out:
        write_landmarks(out, lms, **options)


def _suggest_skull(args: argparse.Namespace, read, head, seeds) -> int:
    """Skull landmarks from the dense registration of the reference skull (issue 11)."""
    import numpy as np

    from workbench.cli.reconstruct_cmd import orientation_of
    from workbench.core.landmarks import LandmarkSet
    from workbench.services.reconstruction.case_steps import suggest_landmarks

    # the seeds stay as the user placed them (the window's Suggest does the same)
    given = seeds if seeds is not None else LandmarkSet("skull", ())
    lms, reg = suggest_landmarks(read.mesh, given, head, orientation_of(args, args.mesh))
    print_self_check(reg.figures.get("self_check"))
    if read.scale_applied != 1.0:  # back to the file's units
        m = np.eye(4)
        m[:3, :3] /= read.scale_applied
        lms = lms.transformed(m)
    _write_suggested(args, read, lms)
    for w in reg.warnings:
        print(f"note: {w}")
    o = reg.figures["orientation"]
    write_json(
        {
            "file": str(args.out),
            "surface": "skull",
            "template": head.template_id,
            "method": "dense registration of the reference skull",
            "placed": [lm.code for lm in lms if lm.status == "placed"],
            "suggested": {
                lm.code: round(lm.confidence, 2) for lm in lms if lm.status == "suggested"
            },
            "absent": [lm.code for lm in lms if not lm.is_defined],
            "parts": {
                p.name: {"present": p.present, "observed_fraction": p.observed_fraction}
                for p in reg.parts
            },
            "alignment": {
                "method": o["method"],
                "handedness": o["handedness"],
                "mirrored": o["mirrored"],
                "scale": round(1.0 / o["reference_scale"], 4),
            },
            "median_bone_distance_mm": reg.figures["median_observed_distance_mm"],
            "self_check": (reg.figures.get("self_check") or {}).get("outcome"),
        },
        None,
    )
    return self_check_status("landmarks suggest", reg.figures.get("self_check"))


def run_snap(args: argparse.Namespace) -> int:
    from workbench.commands.stack import CommandStack
    from workbench.core.errors import InputError
    from workbench.io.case_file import load_case, save_case
    from workbench.io.outputs import check_output_file, same_file
    from workbench.services.landmarks.placement import SurfacePlacement

    if args.out is not None:
        if same_file(args.out, args.case):
            raise InputError(
                args.out,
                "is the case being snapped",
                "leave --out away to update the case in place",
            )
        check_output_file(args.out, [args.case], args.force)
    case = load_case(args.case).case
    if case.specimen.mesh is None:
        raise LandmarkError(f"{args.case}: the case has no skull mesh to snap on")
    stack = CommandStack(case)
    placement = SurfacePlacement(case.specimen.mesh, stack, "skull")
    results = placement.snap_all_to_features(None if args.all else args.code)
    for r in results:
        print(r.explanation)
    moved = sum(r.moves for r in results)
    if args.dry_run or not moved:
        print(
            f"{moved} landmark(s) would move; nothing saved"
            if args.dry_run
            else "nothing moved; case not saved"
        )
        return 0
    if args.out is None:  # the case itself, in place: an atomic save with its audit log
        out = save_case(case, args.case, stack)
    else:
        with output_path(args.out, args, args.case) as target:
            out = save_case(case, target, stack)
    print(f"saved {out} ({moved} landmark(s) moved)")
    return 0
