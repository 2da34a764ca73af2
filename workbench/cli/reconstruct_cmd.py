"""``workbench reconstruct``: skull → face with dowels, guides, ensemble and report.

Outputs (in ``--out DIR``, all in the skull file's frame and mm):
``face.ply``, ``head/`` (skin, skull parts, landmarks, muscles as a template
pack), ``skull_landmarks.mrk.json``, ``case.fcase``, ``report.json``,
``report.pdf`` and the report pictures in ``pictures/``.
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from workbench.cli.common import (
    add_force_option,
    add_units_options,
    print_self_check,
    self_check_status,
    write_json,
)
from workbench.core.data_paths import DEFAULT_DEPTH_TABLE
from workbench.core.errors import InputError
from workbench.core.limits import MAX_BUILD_SD, MAX_ENSEMBLE, check_count, check_tissue_depth
from workbench.pipelines.outcome import JobOutcome


def _build(value: str) -> str | float:
    from workbench.model.reconstruction_setup import BUILDS, SetupError, parse_build

    if value in BUILDS:
        return value
    if value.strip().lower().startswith("bmi"):
        try:
            return parse_build(value)
        except SetupError as exc:
            raise argparse.ArgumentTypeError(f"--build {value}: {exc.problem}") from None
    try:
        k = float(value.replace("SD", "").replace("sd", "").strip())
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"--build must be slender, average, heavy (or normal, obese), bmi:X (a BMI) or a "
            f"number of SDs (e.g. 1 or -1.5), not {value!r}"
        ) from None
    if not math.isfinite(k) or abs(k) > MAX_BUILD_SD:
        raise argparse.ArgumentTypeError(
            f"--build {value}: k must be a finite number of SDs within ±{MAX_BUILD_SD:g} SD "
            "(mean + k SD of the table group)"
        )
    return k


def _vector(text: str) -> tuple[float, float, float]:
    try:
        v = tuple(float(t) for t in text.split(","))
    except ValueError:
        v = ()
    if len(v) != 3:
        raise argparse.ArgumentTypeError(f"expected three comma-separated numbers, got {text!r}")
    return v


def add_orientation_options(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--anterior",
        type=_vector,
        default=None,
        metavar="X,Y,Z",
        help="direction the face looks in the file's coordinates (helps the "
        "automatic landmark suggestion; sample files know theirs)",
    )
    p.add_argument(
        "--superior",
        type=_vector,
        default=None,
        metavar="X,Y,Z",
        help="the head's up direction in the file's coordinates",
    )
    p.add_argument(
        "--left",
        type=_vector,
        default=None,
        metavar="X,Y,Z",
        help="the subject's left in the file's coordinates (only for mirrored files)",
    )


def _check_directions(args: argparse.Namespace) -> None:
    """Zero, non-finite or parallel ``--anterior/--superior/--left`` are refused by name."""
    from workbench.model.reconstruction_setup import MAX_AXIS_COS

    given = {f"--{k}": getattr(args, k, None) for k in ("anterior", "superior", "left")}
    for option, v in given.items():
        if v is not None and not (all(math.isfinite(c) for c in v) and any(v)):
            raise InputError(
                option,
                f"{','.join(f'{c:g}' for c in v)} is not a direction (zero or non-finite vector)",
                "give three numbers, e.g. 0,0,1",
            )
    a, s = given["--anterior"], given["--superior"]
    if a is not None and s is not None:
        cos = sum(x * y for x, y in zip(a, s, strict=True)) / (math.hypot(*a) * math.hypot(*s))
        if abs(cos) > MAX_AXIS_COS:
            raise InputError(
                "--anterior/--superior",
                "the two directions are (nearly) parallel "
                f"(angle {math.degrees(math.acos(min(1.0, abs(cos)))):.1f} degrees)",
                "anterior (face) and superior (up) must be about 90 degrees apart",
            )


def orientation_of(args: argparse.Namespace, argument: str) -> tuple | None:
    """``(anterior, superior[, left])`` from the options (in the file's own numbers), or the
    sample's known anatomy; None when not given.

    A mesh file tagged ``SPACE=LPS`` is read with x and y negated
    (:func:`workbench.io.meshes.read_mesh`), so the directions given for it are
    turned the same way here.
    """
    _check_directions(args)
    if args.anterior is not None and args.superior is not None:
        from workbench.io.meshes import file_space, to_read_frame

        given = (args.anterior, args.superior) + ((args.left,) if args.left else ())
        space = None if argument.startswith("sample:") else file_space(argument)
        return tuple(tuple(to_read_frame(v, space).tolist()) for v in given)
    if argument.startswith("sample:"):
        from workbench.io.samples import registry

        sample = registry().get(argument.split(":", 1)[1])
        if sample is not None and sample.anatomy:
            a = sample.anatomy
            return (a["anterior"], a["superior"]) + ((a["left"],) if "left" in a else ())
    if (args.anterior is None) != (args.superior is None):
        raise InputError("--anterior/--superior", "give both directions or neither")
    return None


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "reconstruct",
        help="reconstruct a face over a skull (dowels, guides, report)",
        description="Fit the reference head over a skull: tissue-depth dowels from a published "
        "table, Kähler's nose and mouth guides, non-penetration refits; optional "
        "uncertainty ensemble. Without --landmarks the skull landmarks are suggested "
        "automatically. Outputs are in the skull file's frame and mm.",
    )
    p.add_argument("skull", help="skull mesh (PLY/STL/OBJ/VTK/VTP) or sample:NAME")
    add_units_options(p)
    p.add_argument("--landmarks", type=Path, default=None, help="skull landmarks (.mrk.json …)")
    p.add_argument("--table", default=DEFAULT_DEPTH_TABLE, help="depth table id or CSV file")
    p.add_argument("--sex", choices=["female", "male"], default="male")
    p.add_argument(
        "--build",
        type=_build,
        default="normal",
        help="the main face.ply's build: slender | average (default; = normal, the table "
        "means) | heavy (= obese), bmi:X for a known BMI (the build model, by region), or k "
        "for a uniform mean + k SD; with a table that has SDs the three faces "
        "face_slender/average/heavy.ply and the uncertainty band are written beside it",
    )
    p.add_argument("--guides", default="default", help="default | none | guides JSON file")
    p.add_argument(
        "--rule",
        action="append",
        default=[],
        metavar="RULE_ID",
        help="use a published prediction rule instead of the classic guide for its "
        "feature (repeatable), e.g. nose_rynn2010_prn, mouth_75pct_rule, "
        "eye_guyomarch2012_globe; ids in data_tables/guides/guide_rules.csv",
    )
    p.add_argument(
        "--exclude",
        action="append",
        default=[],
        metavar="CODE",
        help="switch a landmark's dowel off (repeatable; e.g. ecm2s for Kähler's cheeks)",
    )
    p.add_argument(
        "--override",
        action="append",
        default=[],
        metavar="CODE=MM",
        help="set a landmark's depth by hand (repeatable)",
    )
    p.add_argument(
        "--ensemble",
        type=int,
        default=0,
        metavar="N",
        help="N fits drawing depths from mean ± SD: a per-vertex spread map",
    )
    p.add_argument(
        "--template",
        type=Path,
        action="append",
        default=None,
        metavar="PACK",
        help="template pack (workbench template build/export) instead of the built-in "
        "head; repeat it for a library: one fit per pack, the face their "
        "per-vertex median, the spread between them in the report",
    )
    p.add_argument(
        "--tissue",
        choices=["table", "reference"],
        default="table",
        help="table: the reference's thickness calibrated to the depth table "
        "(default); reference: the reference head's own thickness (a pack "
        "built from a real CT)",
    )
    p.add_argument(
        "--jaw",
        choices=["occlusion", "as-scanned"],
        default="occlusion",
        help="occlusion: the mandible brought into occlusion for the face, teeth together and "
        "condyles in the fossae (default; a toothless jaw keeps the reference's vertical "
        "dimension), the articulated skull written as skull_articulated.ply; as-scanned: "
        "the jaw where the scan has it",
    )
    p.add_argument(
        "--truth",
        default=None,
        metavar="SKIN_MESH",
        help="true skin surface (same frame and units as the skull): adds validation figures",
    )
    p.add_argument("--examiner", default="")
    p.add_argument("--no-pictures", action="store_true", help="skip the rendered pictures")
    add_orientation_options(p)
    p.add_argument(
        "--out",
        type=Path,
        required=True,
        help="output folder; it must not hold any input (it is replaced as a whole)",
    )
    add_force_option(p, folder=True)
    p.set_defaults(handler=run)


def _overrides(items: list[str]) -> dict[str, float]:
    out = {}
    for item in items:
        code, _, value = item.partition("=")
        try:
            depth = float(value)
        except ValueError:
            raise InputError("--override", f"{item!r} is not CODE=MM") from None
        out[code.strip()] = check_tissue_depth(depth, f"--override {item}")
    return out


def run(args: argparse.Namespace) -> JobOutcome:
    """The reconstruction folder; exit status 3 when the registration asks for a check."""
    from workbench.io.samples import resolve_input
    from workbench.pipelines.batch.figures import reconstruct_figures
    from workbench.services.reconstruction.job import JobSettings
    from workbench.services.tissue.tissue_model import TissueSettings

    check_count(
        args.ensemble,
        "--ensemble",
        0,
        MAX_ENSEMBLE,
        why=f"the spread map settles by ~50 fits; more than {MAX_ENSEMBLE} only takes longer",
    )
    settings = JobSettings(
        units=args.units,
        scale=args.scale,
        landmarks=args.landmarks,
        table=args.table,
        sex=args.sex,
        build=args.build,
        guides=args.guides,
        rules=tuple(args.rule),
        ensemble=args.ensemble,
        template=args.template[0] if args.template else None,
        templates=tuple(args.template or ()),
        tissue=TissueSettings(model=args.tissue),
        orientation=orientation_of(args, args.skull),
        excluded=frozenset(args.exclude),
        overrides=_overrides(args.override),
        examiner=args.examiner,
        jaw=args.jaw,
    )
    truth = None if args.truth is None else resolve_input(args.truth)
    report = execute(
        resolve_input(args.skull),
        settings,
        args.out,
        truth=truth,
        pictures=not args.no_pictures,
        force=args.force,
    )
    check = report.get("self_check") or {}
    return JobOutcome(
        self_check_status("reconstruct", check),
        reconstruct_figures(report),
        list(check.get("reasons", ())) if check.get("outcome") == "check" else [],
    )


def execute(
    skull_path: Path,
    settings,
    out: Path,
    *,
    truth: Path | None = None,
    pictures: bool = True,
    quiet: bool = False,
    force: bool = False,
    staged: bool = False,
) -> dict:
    """Run the job (:func:`workbench.pipelines.reconstruct.reconstruct_to_folder`), print
    what it wrote and its figures; returns the report dict.

    ``staged=True``: ``out`` is a fresh folder the caller staged (``workbench demo``).
    """
    from workbench.pipelines.reconstruct import reconstruct_to_folder, summary_figures

    # progress on stderr: stdout opens with the self-check's CHECK lines, then the results
    done = reconstruct_to_folder(
        skull_path,
        settings,
        out,
        truth=truth,
        pictures=pictures,
        force=force,
        staged=staged,
        progress=None if quiet else (lambda m: print(f"  {m}", file=sys.stderr)),
        notify=None if quiet else print,
    )
    report = done.report
    if quiet:
        return report
    print_self_check(report.get("self_check"))  # the self-check's doubt first, apart from the notes
    for name, path in done.files.items():
        print(f"wrote {name}: {path}")
    for w in report["warnings"]:
        print(f"  note: {w}")
    write_json(summary_figures(report), None)
    return report
