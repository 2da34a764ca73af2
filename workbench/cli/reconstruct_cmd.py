"""``workbench reconstruct``: skull → face with dowels, guides, ensemble and report.

Outputs (in ``--out DIR``, all in the skull file's frame and mm):
``face.ply``, ``head/`` (skin, skull parts, landmarks, muscles as a template
pack), ``skull_landmarks.mrk.json``, ``case.fcase``, ``report.json``,
``report.pdf`` and the report pictures in ``pictures/``.
"""

from __future__ import annotations

import argparse
import math
import os
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


def run(args: argparse.Namespace) -> int:
    from workbench.io.samples import resolve_input
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
    return self_check_status("reconstruct", report.get("self_check"))


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
    """Run the job, write every output into ``out``; returns the report dict.

    ``out`` is checked before the fit and written as a whole
    (:func:`workbench.io.outputs.staged_folder`): it may not hold an input,
    an existing folder is replaced only with ``force`` (kept as ``DIR.1``),
    and a failure leaves it as it was.  ``staged=True``: ``out`` is a fresh
    folder the caller staged (``workbench demo``), written straight into.
    """
    from workbench.io.outputs import check_output_folder, relocate, staged_folder
    from workbench.services.reconstruction.job import job_inputs, run_reconstruction

    # progress on stderr: stdout opens with the self-check's CHECK lines, then the results
    say = (lambda _m: None) if quiet else (lambda m: print(f"  {m}", file=sys.stderr))
    inputs = job_inputs(skull_path, settings, truth)
    if not staged:
        check_output_folder(out, inputs, force)  # before the fit, which takes a while
    result = run_reconstruction(skull_path, settings, progress=say)
    if staged:
        files = _write_all(result, out, truth, settings, pictures)
    else:
        with staged_folder(out, force, inputs, notify=None if quiet else print) as temp:
            files = _write_all(result, temp, truth, settings, pictures)
        files = relocate(files, temp, Path(os.path.abspath(out)))
        result.opened.case.source_path = files["case"]
    report = result.report
    report["_seconds"] = {k: round(v, 2) for k, v in result.seconds.items()}
    if quiet:
        return report
    check = report.get("self_check") or {}
    print_self_check(check)  # the self-check's doubt first, apart from the notes
    for name, path in files.items():
        print(f"wrote {name}: {path}")
    fit = report["fit"]
    summary = {
        k: fit.get(k)
        for k in (
            "max_tip_error_mm",
            "min_tissue_mm",
            "penetrating_vertices",
            "refits",
            "suggested_landmarks",
            "absent_landmarks",
        )
    }
    summary["seconds"] = report["_seconds"]
    if check:
        summary["self_check"] = check.get("outcome")
    jaw = (report.get("registration") or {}).get("jaw") or {}
    if jaw.get("present"):
        occ = jaw.get("occlusion")
        summary["jaw"] = {
            "opening_in_scan_deg": jaw.get("opening_deg"),
            "for_the_face": f"occlusion ({occ['method']})" if occ else "as scanned",
        }
    if report["ensemble"]:
        summary["ensemble_spread_mm"] = report["ensemble"]["spread_mm"]
    if report["validation"]:
        summary["validation"] = {
            k: report["validation"][k]
            for k in ("mean_abs_mm", "pct_within_2_5mm", "pct_within_5mm")
        }
    for w in report["warnings"]:
        print(f"  note: {w}")
    write_json(summary, None)
    return report


def _write_all(result, out: Path, truth: Path | None, settings, pictures: bool) -> dict[str, Path]:
    """The job's files, validation figures, pictures and report, all into ``out``."""
    from workbench.reporting.report import write_report_json, write_report_pdf
    from workbench.services.reconstruction.job import write_outputs

    files = write_outputs(result, out, staged=True)
    report = result.report
    if truth is not None:
        report["validation"] = _validate(truth, settings.scale, result)
    if pictures:
        report["pictures"] = _pictures(out, result)
    files["report"] = write_report_json(report, out / "report.json")
    files["report_pdf"] = write_report_pdf(report, out / "report.pdf", base_dir=out)
    return files


def _validate(truth_path: Path, scale: float | None, result) -> dict:
    """The project's metric (VALIDATION.md) on the true skin, beside a uniform 6 mm offset.

    The anterior direction is the fitted head frame's (no other is known
    here); ``workbench validate`` takes it from its manifest.
    """
    import numpy as np

    from workbench.core.face_metric import ScoreMask, unit
    from workbench.core.offset_surface import uniform_offset
    from workbench.io.meshes import read_mesh
    from workbench.services.templates.regions import REGION_NAMES, face_regions
    from workbench.services.validation.run import score_surfaces

    truth = read_mesh(truth_path, units="mm" if scale is None else "auto", scale=scale).mesh
    recon = result.recon
    bone = result.opened.case.specimen.mesh
    anterior = unit(np.linalg.inv(recon.input_to_head)[:3, :3] @ [0.0, 0.0, 1.0])
    _, (mine, base) = score_surfaces(
        truth,
        bone,
        [("reconstruction", recon.face), ("uniform_6mm_offset", uniform_offset(bone))],
        anterior,
        ScoreMask(),
        labels_from=recon.face,
        vertex_regions=face_regions(result.template),
        region_names=REGION_NAMES,
    )
    return {
        **mine.figures,
        "regions": mine.regions,
        "truth": str(truth_path),
        "region": "face (VALIDATION.md metric)",
        "metric": "VALIDATION.md: outermost, anterior-facing true-skin vertices in front of "
        "the bone centre and within 35 mm of the bone; distance to the "
        "reconstruction (positive: outside)",
        "baseline": {"method": "uniform 6 mm offset of the bone", **base.figures},
    }


def _pictures(out: Path, result) -> dict[str, str]:
    import numpy as np

    from workbench.render.reconstruction import render_builds, render_reconstruction
    from workbench.services.reconstruction.reconstruct import articulated_skull

    recon = result.recon
    active = recon.plan.active()
    origins = recon.to_input(np.array([d.origin for d in active]))
    tips = recon.to_input(np.array([d.tip for d in active]))
    skull = result.opened.case.specimen.mesh
    if recon.registration is not None and recon.registration.occlusion is not None:
        skull = articulated_skull(recon.registration)  # the skull the face was fitted over
    eyes = recon.mesh_to_input(recon.head.meshes["eyes"])
    try:
        paths = render_reconstruction(
            skull,
            recon.face,
            (origins, tips),
            out / "pictures",
            frame=recon.input_to_head,
            eyes=eyes,
            spread=result.spread,
            inferred=recon.inferred,
        )
    except (RuntimeError, OSError, ValueError) as exc:
        print(f"  note: no pictures (off-screen rendering failed: {exc})")
        return {}
    builds = result.fit.builds if result.fit is not None else None
    if builds is not None:
        # the three build faces side by side and the band map: a failure here loses only
        # these pictures, never the job
        try:
            paths |= render_builds(
                {name: builds.face(name, recon) for name in builds.names},
                out / "pictures",
                frame=recon.input_to_head,
                bmi=builds.bmi,
                main=builds.main,
                eyes=eyes,
                skull=skull,
                band_face=recon.face,
                band_mm=builds.half_width_mm,
            )
        except (RuntimeError, OSError, ValueError, InputError) as exc:
            print(f"  note: no build pictures (rendering failed: {exc})")
    return {k: str(Path(p).relative_to(out)) for k, p in paths.items()}
