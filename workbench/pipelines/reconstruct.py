"""Skull → face, as a finished folder: the reconstruction job's meshes, pictures and report.

:func:`reconstruct_to_folder` is ``workbench reconstruct``: open the skull as a
case, fit the reference head (:func:`workbench.services.reconstruction.job.run_reconstruction`)
and write the folder.  :func:`export_fit` is the window's *Export…*: the
same folder from a fit the window already holds.  Both end in
:func:`write_reconstruction`, so the command line, the window and a batch
row write the same files for the same case.

The folder (all in the skull file's frame; mm unless the skull file is in
other units, which ``face.ply`` then states in its header): ``face.ply``
(with the 95 % band as the vertex property ``band_mm``), the three build
faces and ``face_builds.glb``, ``head/`` (the fitted head as a template
pack; its ``head.obj`` in the colours chosen for the case's face when it has
some, an artistic choice), ``skull_landmarks.mrk.json``, ``case.fcase``, ``report.json``,
``report.pdf`` and its ``pictures/``.  The window adds the meshes in its
other formats (``face.obj``, ``head/skin.stl`` ...).
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from workbench.pipelines.outcome import Say, quiet
from workbench.pipelines.pictures import PicturesAside, draw_scene, job_skull, picture_scene

if TYPE_CHECKING:
    from workbench.model.case import Case
    from workbench.services.reconstruction.job import JobResult, JobSettings
    from workbench.services.reconstruction.service import FitResult

#: the fit's key figures (in the report's ``fit`` section): printed, and a batch row's columns
FIT_FIGURES = (
    "max_tip_error_mm",
    "min_tissue_mm",
    "penetrating_vertices",
    "refits",
    "suggested_landmarks",
    "absent_landmarks",
)
#: draws the report's pictures: ``draw(out, result, note) -> {name: path relative to out}``;
#: the window wraps it to run on its GUI thread (VTK never runs on a worker)
Draw = Callable[[Path, "JobResult", Say], dict[str, str]]


@dataclass
class ReconstructionFolder:
    """What a reconstruction pipeline wrote: the job's result, its files and its report."""

    result: JobResult
    files: dict[str, Path]
    notes: list[str] = field(default_factory=list)

    @property
    def report(self) -> dict[str, Any]:
        return self.result.report

    def figures(self) -> dict[str, Any]:
        """The job's key figures as values (what the command line prints as JSON)."""
        return summary_figures(self.report)


def summary_figures(report: dict[str, Any]) -> dict[str, Any]:
    """Key figures of a reconstruction report: tips, tissue, the self-check, jaw, validation."""
    fit = report["fit"]
    summary: dict[str, Any] = {k: fit.get(k) for k in FIT_FIGURES}
    summary["seconds"] = report.get("_seconds")
    check = report.get("self_check") or {}
    if check:
        summary["self_check"] = check.get("outcome")
    jaw = (report.get("registration") or {}).get("jaw") or {}
    if jaw.get("present"):
        occ = jaw.get("occlusion")
        summary["jaw"] = {
            "opening_in_scan_deg": jaw.get("opening_deg"),
            "for_the_face": f"occlusion ({occ['method']})" if occ else "as scanned",
        }
    if report.get("ensemble"):
        summary["ensemble_spread_mm"] = report["ensemble"]["spread_mm"]
    if report.get("validation"):
        summary["validation"] = {
            k: report["validation"][k]
            for k in ("mean_abs_mm", "pct_within_2_5mm", "pct_within_5mm")
        }
    return summary


def reconstruct_to_folder(
    skull_path: Path,
    settings: JobSettings,
    out: Path,
    *,
    truth: Path | None = None,
    pictures: bool = True,
    force: bool = False,
    staged: bool = False,
    progress: Say | None = None,
    notify: Say | None = None,
) -> ReconstructionFolder:
    """Reconstruct the face over the skull at ``skull_path`` and write every output into ``out``.

    ``out`` is checked before the fit (which takes a while) and written as a
    whole (:func:`workbench.io.outputs.staged_folder`): it may not hold an
    input, an existing folder is replaced only with ``force`` (kept as
    ``DIR.1``), and a failure leaves it as it was.  ``staged=True``: ``out`` is
    a fresh folder the caller staged (``workbench demo``), written straight
    into.  ``truth``: a true skin to score the face against (VALIDATION.md).
    ``progress`` hears the fit's steps; ``notify`` where a replaced folder was
    kept and why a picture is missing.
    """
    from workbench.io.outputs import check_output_folder, relocate, staged_folder
    from workbench.services.reconstruction.job import job_inputs, run_reconstruction

    say = notify or quiet
    inputs = job_inputs(skull_path, settings, truth)
    if not staged:
        check_output_folder(out, inputs, force)
    aside = PicturesAside() if pictures else None  # drawn in the helper process meanwhile
    result = run_reconstruction(skull_path, settings, progress=progress)
    notes: list[str] = []

    def note(message: str) -> None:
        notes.append(message)
        say(f"  note: {message}")

    if staged:
        files = write_reconstruction(
            result, out, truth=truth, pictures=pictures, note=note, aside=aside
        )
    else:
        with staged_folder(out, force, inputs, notify=notify) as temp:
            files = write_reconstruction(
                result, temp, truth=truth, pictures=pictures, note=note, aside=aside
            )
        files = relocate(files, temp, Path(os.path.abspath(out)))
        result.opened.case.source_path = files["case"]
    result.report["_seconds"] = {k: round(v, 2) for k, v in result.seconds.items()}
    return ReconstructionFolder(result, files, notes)


def write_reconstruction(
    result: JobResult,
    out: Path,
    *,
    truth: Path | None = None,
    pictures: bool = True,
    formats: tuple[str, ...] = (),
    draw: Draw | None = None,
    note: Say = quiet,
    aside: PicturesAside | None = None,
) -> dict[str, Path]:
    """The job's files, validation figures, pictures and report, all into the folder ``out``.

    ``out`` exists and is the caller's (a staged folder).  ``formats``: the
    face, the build faces and the head's parts again in these mesh formats
    besides PLY (``"obj"``, ``"stl"``).  ``draw`` replaces the picture drawer
    (:func:`reconstruction_pictures`), e.g. to run it on another thread.
    ``aside`` (without ``draw``): draw the pictures in the helper process while
    the other files are written (:mod:`workbench.pipelines.pictures`).
    """
    from workbench.reporting.report import write_report_json, write_report_pdf
    from workbench.services.reconstruction.job import write_outputs

    aside = aside if pictures and draw is None else None
    if aside is not None:
        aside.start(out / "pictures", result)
    try:
        files = write_outputs(result, out, staged=True)
        files.update(_coloured_head(result, out))
        files.update(_other_formats(result, out, formats))
    except BaseException:
        if aside is not None:  # the folder is removed on the way out: let the helper finish
            aside.wait()
        raise
    report = result.report
    section = appearance_section(result)
    if section is not None:
        report["appearance"] = section
    if truth is not None:
        report["validation"] = validation_figures(truth, result.settings.scale, result)
    if aside is not None:
        report["pictures"] = _with_portraits(out, result, *aside.finish(), note)
    elif pictures:
        report["pictures"] = (draw or reconstruction_pictures)(out, result, note)
    files["report"] = write_report_json(report, out / "report.json")
    files["report_pdf"] = write_report_pdf(report, out / "report.pdf", base_dir=out)
    return files


def _coloured_head(result: JobResult, out: Path) -> dict[str, Path]:
    """``head/head.obj`` again in the colours chosen for the case's face, if it has some.

    The case's :class:`~workbench.model.appearance.Appearance` (artistic, not
    evidence): the skin's colours (computed on the fitted head in its head
    frame) baked into ``head/skin_colours.png``, the eyes in its iris colour,
    and the hair, brows, beard and moustache it chose as objects of their own
    after the head's parts (artistic additions; grown on the fitted head and
    mapped into the skull file's frame with it), each with its material in
    ``head.mtl``.  Nothing is written for a case without chosen colours
    (``head.obj`` keeps the default materials).
    """
    appearance = result.opened.case.appearance
    if appearance is None:
        return {}
    from workbench.io.template_pack import write_head_obj
    from workbench.services.appearance import atlas_skin_look, skin_colours
    from workbench.services.grooming import hair_look
    from workbench.services.reconstruction.job import (
        FITTED_HEAD_FRAME_TEXT,
        hair_in_input_frame,
        head_in_input_frame,
    )

    colours = skin_colours(result.recon.head, appearance)
    head = head_in_input_frame(result.recon)
    look = atlas_skin_look(head.skin, colours, appearance)
    hair = {
        piece.kind: (piece.mesh, hair_look(piece, appearance))
        for piece in hair_in_input_frame(result.recon, appearance)
    }
    written = write_head_obj(
        head,
        out / "head",
        frame=FITTED_HEAD_FRAME_TEXT,
        iris=appearance.iris,
        looks={"skin": look},
        extra=hair,
    )
    return {f"head/{p.name}": p for p in written if p.suffix == ".png"}


def _other_formats(result: JobResult, out: Path, formats: tuple[str, ...]) -> dict[str, Path]:
    """``face.<ext>``, ``face_<build>.<ext>`` and ``head/<part>.<ext>`` for each extra format."""
    from workbench.core.mesh import concatenate
    from workbench.io.meshes import write_mesh
    from workbench.io.template_pack import FILES
    from workbench.services.reconstruction.job import head_in_input_frame

    others = [e for e in formats if e != "ply"]  # the folder already holds the PLY files
    if not others:
        return {}
    from workbench.io.markups import OUTPUT_SYSTEM, write_fcsv

    files: dict[str, Path] = {}
    lms = result.opened.case.landmarks["skull"]
    if len(lms):  # Slicer's older markups format beside the .mrk.json
        write_fcsv(out / "skull_landmarks.fcsv", lms, coordinate_system=OUTPUT_SYSTEM)
        files["landmarks_fcsv"] = out / "skull_landmarks.fcsv"
    recon, builds = result.recon, result.fit.builds if result.fit is not None else None
    for ext in others:
        files[f"face_{ext}"] = write_mesh(out / f"face.{ext}", recon.face)
        if builds is None:
            continue
        for name in builds.names:
            files[f"face_{name}_{ext}"] = write_mesh(
                out / f"face_{name}.{ext}", builds.face(name, recon)
            )
    head = head_in_input_frame(recon)
    for name, parts in FILES.items():
        stem, mesh = Path(name).stem, concatenate([head.meshes[p] for p in parts])
        for ext in others:
            files[f"head/{stem}.{ext}"] = write_mesh(out / "head" / f"{stem}.{ext}", mesh)
    return files


def validation_figures(truth_path: Path, scale: float | None, result: JobResult) -> dict:
    """The project's metric (VALIDATION.md) on the true skin, beside a uniform 6 mm offset.

    The anterior direction is the fitted head frame's (no other is known
    here); ``workbench validate`` takes it from its manifest.
    """
    from workbench.core.face_metric import ScoreMask, unit
    from workbench.core.offset_surface import uniform_offset
    from workbench.io.meshes import read_mesh
    from workbench.services.templates.regions import REGION_NAMES, face_regions
    from workbench.services.validation.run import score_surfaces

    truth = read_mesh(truth_path, units="mm" if scale is None else "auto", scale=scale).mesh
    recon = result.recon
    bone = job_skull(result)
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


#: the side (px) of the report's portraits in the case's appearance (a third of the page
#: width is about 60 mm: 900 px prints it at ~380 dpi)
REPORT_PORTRAIT_PX = 900


def appearance_section(result: JobResult) -> dict[str, Any] | None:
    """The report's ``appearance``: what the case chose for the face (colours, iris, hair)
    and that it is an artistic presentation, not evidence; None when it chose nothing."""
    appearance = result.opened.case.appearance
    if appearance is None:
        return None
    from workbench.core.grooming import ARTISTIC_NOTE as GROOMING_NOTE
    from workbench.model.appearance import ARTISTIC_NOTE
    from workbench.services.appearance import colour_summary

    summary = colour_summary(appearance).removesuffix(ARTISTIC_NOTE).strip()
    additions = (
        {"hair_and_brows": dict(appearance.grooming), "note": GROOMING_NOTE}
        if appearance.grooming
        else None
    )
    return {"summary": summary, "note": ARTISTIC_NOTE, "artistic_additions": additions}


def _portraits(out: Path, result: JobResult, note: Say) -> dict[str, Path]:
    """Front, three-quarter and profile portraits in the case's appearance (with its hair)
    into ``out/pictures`` for the report; none when the case chose no appearance."""
    appearance = result.opened.case.appearance
    if appearance is None:
        return {}
    from workbench.core.errors import WorkbenchError
    from workbench.render.portrait import make_portrait, write_portrait

    try:
        portrait = make_portrait(result.recon.head, size=REPORT_PORTRAIT_PX, appearance=appearance)
        written = write_portrait(portrait, out / "pictures", formats=("png",))
    except (RuntimeError, OSError, ValueError, WorkbenchError) as exc:
        note(f"no portraits in the report (rendering failed: {exc})")
        return {}
    return {f"portrait_{view}": paths[0] for view, paths in written.items()}


def reconstruction_pictures(out: Path, result: JobResult, note: Say = quiet) -> dict[str, str]:
    """The report's pictures into ``out/pictures``: {name: path relative to ``out``}.

    Without off-screen rendering the job goes on without pictures, and
    ``note`` says why; the three build faces and the band map are drawn apart,
    so a failure there loses only those pictures
    (:func:`workbench.pipelines.pictures.draw_scene`).
    """
    return _with_portraits(
        out, result, *draw_scene(str(out / "pictures"), picture_scene(result)), note
    )


def _with_portraits(
    out: Path, result: JobResult, paths: dict[str, Path], notes: list[str], note: Say
) -> dict[str, str]:
    """``paths`` and the portraits in the case's appearance, relative to ``out``; ``notes`` said."""
    for message in notes:
        note(message)
    paths = paths | _portraits(out, result, note)
    return {k: str(Path(p).relative_to(out)) for k, p in paths.items()}


def job_result_of(case: Case, fit: FitResult, notes: list[str] | None = None) -> JobResult:
    """A fit the window holds, as the job result :func:`write_reconstruction` writes (mm).

    The window's case is not touched: the folder's case is a copy
    (:func:`~workbench.io.case_file.detached_copy`) with a stack of its own, on
    which the fit is recorded as ``workbench reconstruct`` records it
    (:func:`~workbench.services.reconstruction.job.record_fit`: the landmarks it
    was fitted with, the reference head, the table group) before the report is
    built from it; saving it into the folder then marks only the copy saved.
    The window's skull is in mm (read in mm or converted on opening), so the
    folder is in mm.
    """
    from workbench.commands.stack import CommandStack
    from workbench.io.case_file import detached_copy
    from workbench.services.case.case_setup import OpenedCase
    from workbench.services.reconstruction.job import (
        JobResult,
        JobSettings,
        build_report,
        record_fit,
    )

    own = detached_copy(case)
    opened = OpenedCase(own, CommandStack(own), list(notes or []))
    record_fit(opened.stack, fit)
    report = build_report(own, fit, notes=list(notes or []))
    return JobResult.of_fit(opened, fit, report, dict(fit.seconds), JobSettings(units="mm"))


def export_fit(
    case: Case,
    fit: FitResult,
    out: Path,
    *,
    notes: list[str] | None = None,
    formats: tuple[str, ...] = (),
    pictures: bool = True,
    draw: Draw | None = None,
    force: bool = False,
    notify: Say | None = None,
) -> ReconstructionFolder:
    """The window's *Export…*: the reconstruction folder of a fit already made, staged as a whole.

    The same files as :func:`reconstruct_to_folder` for the same case, plus
    the meshes in ``formats``; an existing non-empty ``out`` is replaced only
    with ``force`` (kept as ``DIR.1``).  The case saved in the folder is a
    copy: the window's own case file is not touched.
    """
    from workbench.io.outputs import relocate, staged_folder

    result = job_result_of(case, fit, notes)
    inputs = [Path(ev.original_path) for ev in case.evidence if getattr(ev, "original_path", None)]
    written: list[str] = []

    def note(message: str) -> None:
        written.append(message)
        if notify is not None:
            notify(message)

    with staged_folder(out, force, inputs, notify=notify) as temp:
        files = write_reconstruction(
            result, temp, pictures=pictures, formats=formats, draw=draw, note=note
        )
    return ReconstructionFolder(result, relocate(files, temp, Path(os.path.abspath(out))), written)
