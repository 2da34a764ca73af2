"""The whole skull → face job as one scriptable call (used by ``workbench reconstruct``).

Units mm.  Inputs are in the skull file's frame; outputs (face, head,
landmarks) are mapped back into that frame so they overlay the evidence.

Steps: open the skull as a case (evidence kept, units checked), record the
job's settings on the case as typed, undoable commands (dowel settings,
orientation, a guides file), run the one reconstruction pipeline
(:func:`workbench.services.reconstruction.service.run_fit`, the same the
window runs), push the landmark set the fit used and the provenance of the
result, and assemble the report data with :func:`build_report` (the one
report builder of the command line and the window; pictures are added by
the caller, which may render).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from workbench import __version__
from workbench.commands.case_edits import SetParameter
from workbench.commands.landmarks import ReplaceLandmarkSet
from workbench.commands.reconstruction_setup import SetDowelSettings, SetGuides, SetOrientation
from workbench.commands.stack import CommandStack
from workbench.core.data_paths import DEFAULT_DEPTH_TABLE
from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh
from workbench.core.units import UNIT_SCALES
from workbench.io.case_file import save_case
from workbench.io.catalogue import load_catalogue
from workbench.io.markups import OUTPUT_FRAME, OUTPUT_SYSTEM, write_mrk_json
from workbench.io.mesh_formats import ply
from workbench.io.meshes import write_mesh
from workbench.io.outputs import relocate, staged_folder
from workbench.io.template_pack import export_template
from workbench.model.appearance import Appearance
from workbench.model.case import Case
from workbench.model.reconstruction_setup import GuideList, Orientation
from workbench.model.template import TemplateHead
from workbench.services.case.case_setup import OpenedCase, start_case_from_skull
from workbench.services.grooming import HairMesh, hair_look, hair_meshes
from workbench.services.guides.classic import guides_from_json, guides_to_json
from workbench.services.guides.fit_guides import MAX_NORM_SD, plausible_guides
from workbench.services.landmarks.transfer import TransferResult
from workbench.services.reconstruction.build_faces import BuildFaces
from workbench.services.reconstruction.reconstruct import (
    FitSettings,
    Reconstruction,
    articulated_skull,
)
from workbench.services.reconstruction.service import (
    MAX_WORKING_TRIANGLES,
    WORKING_TRIANGLES,
    FitInputs,
    FitResult,
    prefetch_working_skull,
    run_fit,
)
from workbench.services.registration.result import SkullRegistration
from workbench.services.tissue.tissue_model import TissueSettings

__all__ = [
    "FITTED_HEAD_FRAME_TEXT",
    "MAX_NORM_SD",
    "MAX_WORKING_TRIANGLES",
    "MIN_CONFIDENCE",
    "WORKING_TRIANGLES",
    "JobResult",
    "JobSettings",
    "build_report",
    "hair_in_input_frame",
    "head_in_input_frame",
    "job_inputs",
    "plausible_guides",
    "run_reconstruction",
    "write_outputs",
]

Progress = Callable[[str], None]
MIN_CONFIDENCE = FitSettings().min_confidence


@dataclass(frozen=True)
class JobSettings:
    """Everything ``workbench reconstruct`` takes besides the skull file."""

    units: str = "auto"
    scale: float | None = None
    landmarks: str | PathLike[str] | None = None
    table: str = DEFAULT_DEPTH_TABLE
    sex: str = "male"
    build: str | float = "normal"
    guides: str | PathLike[str] = "default"  # "default" | "none" | JSON file
    rules: tuple[str, ...] = ()  # published rules replacing classic guides
    ensemble: int = 0
    template: str | PathLike[str] | None = None
    #: two or more reference packs: one fit each, the face their per-vertex median
    templates: tuple = ()
    orientation: tuple | None = None  # (anterior, superior[, left]) in file coords
    excluded: frozenset[str] = frozenset()
    overrides: dict = field(default_factory=dict)
    examiner: str = ""
    #: ``model`` and ``region_factors`` become the case's dowel settings; the
    #: other fields are fit internals passed on as they are
    tissue: TissueSettings = field(default_factory=TissueSettings)
    #: "occlusion" (the jaw closed for the face) or "as-scanned"
    jaw: str = "occlusion"

    @property
    def guides_file(self) -> Path | None:
        """The guides JSON file, or None for ``"default"`` / ``"none"``."""
        return None if str(self.guides) in ("default", "none") else Path(self.guides)


@dataclass
class JobResult:
    opened: OpenedCase
    template: TemplateHead
    recon: Reconstruction
    skull_h: Mesh
    suggestion: TransferResult | None
    guides: list
    spread: np.ndarray | None
    report: dict[str, Any]
    seconds: dict[str, float]
    settings: JobSettings = field(default_factory=JobSettings)
    fit: FitResult | None = None

    @classmethod
    def of_fit(
        cls,
        opened: OpenedCase,
        fit: FitResult,
        report: dict[str, Any],
        seconds: dict[str, float],
        settings: JobSettings,
    ) -> JobResult:
        """The result of a fit of ``opened``'s case, with its report and timings."""
        return cls(
            opened,
            fit.head,
            fit.recon,
            fit.skull_h,
            None,
            list(fit.guides),
            fit.spread_map,
            report,
            seconds,
            settings,
            fit,
        )

    @property
    def file_units_per_mm(self) -> float:
        """1 / (mm per unit of the skull file): to write results in the file's own units."""
        mm_per_unit = self.settings.scale or UNIT_SCALES.get(self.settings.units, 1.0)
        return 1.0 / mm_per_unit

    @property
    def file_units_label(self) -> str:
        """The skull file's units as ``face.ply`` states them: "mm", "cm", or
        "file units (1 unit = 15 mm)" for a ``--scale``."""
        if self.settings.scale:
            return f"file units (1 unit = {self.settings.scale:g} mm)"
        return self.settings.units if self.settings.units in UNIT_SCALES else "mm"


def record_settings(opened: OpenedCase, settings: JobSettings) -> None:
    """The job's settings as typed commands on the case (each one undo step, audited)."""
    stack = opened.stack
    stack.push(
        SetDowelSettings(
            table=settings.table,
            sex=settings.sex,
            build=settings.build,
            overrides={k: float(v) for k, v in settings.overrides.items()},
            excluded=tuple(settings.excluded),
            tissue_model=settings.tissue.model,
            region_factors=dict(settings.tissue.region_factors),
            jaw=settings.jaw,
            label="Dowel settings of the job",
        )
    )
    if settings.orientation is not None:
        stack.push(
            SetOrientation(
                Orientation.from_hint(settings.orientation), label="Orientation of the skull file"
            )
        )
    if settings.guides_file is not None:
        guides = guides_from_json(settings.guides_file)  # checked, names the file
        stack.push(
            SetGuides(
                GuideList(tuple(guides_to_json(guides))),
                label=f"Guides from {settings.guides_file.name}",
            )
        )


def record_fit(stack: CommandStack, fit: FitResult) -> None:
    """What a fit leaves in its case, as commands on ``stack`` (each one undo step, audited):
    the skull landmarks it was fitted with (input frame, mm), the reference head's id and
    hash, the depth table's group.  ``workbench reconstruct`` and the window's export both
    record these before the report is built from the case."""
    if fit.recon.landmarks is not None:  # None only when the fit kept no landmark set
        stack.push(
            ReplaceLandmarkSet(
                surface="skull",
                new_set=fit.recon.landmarks,
                label="Skull landmarks from the dense registration",
            )
        )
    for key, value in (
        ("template_id", fit.head.template_id),
        ("template_hash", fit.head.content_hash),
        ("depth_group", fit.recon.plan.group_label),
    ):
        stack.push(SetParameter(key=key, value=value))


def run_reconstruction(
    skull_path: str | PathLike[str],
    settings: JobSettings = JobSettings(),
    progress: Progress | None = None,
) -> JobResult:
    """Open the skull as a case and reconstruct the face (see the module docstring)."""
    say = progress or (lambda _msg: None)
    times: dict[str, float] = {}
    t = time.perf_counter()
    opened = start_case_from_skull(
        skull_path,
        units=settings.units,
        scale=settings.scale,
        examiner=settings.examiner,
        landmarks_path=settings.landmarks,
        on_read=prefetch_working_skull,
    )
    case, stack = opened.case, opened.stack
    record_settings(opened, settings)
    inputs = FitInputs.from_case(
        case,
        template=settings.template,
        templates=settings.templates,
        rules=settings.rules,
        use_guides=str(settings.guides) != "none",
        ensemble=settings.ensemble,
        tissue=settings.tissue,
    )
    times["open"] = time.perf_counter() - t
    fit = run_fit(inputs, progress=say)
    times.update(fit.seconds)
    record_fit(stack, fit)
    report = build_report(case, fit, notes=opened.notes, guides_file=settings.guides_file)
    return JobResult.of_fit(opened, fit, report, times, settings)


def _input_record(ev: Any) -> dict[str, Any]:
    return {
        "role": "skull" if ev.role == "skull_mesh" else "landmarks",
        "path": ev.name,
        "sha256": ev.sha256,
        "units": ev.units_note or "mm",
    }


def _file_record(role: str, path: str | PathLike[str]) -> dict[str, Any]:
    from workbench.io.tables import tables_dir
    from workbench.model.evidence import file_sha256

    shown = Path(path)
    try:  # built-in tables by their place in the project, not this machine's path
        shown = Path("data_tables") / shown.resolve().relative_to(tables_dir().parent.resolve())
    except ValueError:
        pass
    return {"role": role, "path": str(shown), "sha256": file_sha256(path), "units": "mm"}


def _table_file(table: str) -> Path:
    from workbench.io.tables import tables_dir

    p = Path(table)
    return p if p.suffix == ".csv" and p.is_file() else tables_dir() / f"{table}.csv"


def _dir_in(recon: Reconstruction, direction: np.ndarray) -> list[float]:
    """A head-frame direction in the input frame (unit length)."""
    v = np.linalg.inv(recon.input_to_head)[:3, :3] @ np.asarray(direction, float)
    return [float(x) for x in v / np.linalg.norm(v)]


def build_report(
    case: Case,
    fit: FitResult,
    *,
    notes: Sequence[str] = (),
    guides_file: str | PathLike[str] | None = None,
    suggestion: TransferResult | None = None,
) -> dict[str, Any]:
    """The report dict (``reconstruction-report-v1``) of one fit, without pictures.

    The one report builder of ``workbench reconstruct`` and the window's
    export.  ``case`` gives the identity and the evidence; ``fit`` (with the
    :class:`FitInputs` it ran with) everything else.  Landmark rows are those
    the fit used (input frame, mm).  ``notes`` are the caller's (opening the
    skull...); ``guides_file`` is recorded (with its SHA-256) as an input.
    """
    from workbench.reporting.report import utc_now

    inputs = fit.inputs if fit.inputs is not None else FitInputs.from_case(case)
    head, recon, spread = fit.head, fit.recon, fit.spread
    landmarks = recon.landmarks or inputs.landmarks or LandmarkSet("skull")
    plan = recon.plan
    rows = _landmark_rows(landmarks, recon)
    figures = {k: v for k, v in recon.figures.items() if k != "registration"}
    figures["suggested_landmarks"] = sum(lm.status == "suggested" for lm in landmarks)
    figures["placed_landmarks"] = sum(lm.status == "placed" for lm in landmarks)
    figures["absent_landmarks"] = sum(not lm.is_defined for lm in landmarks)
    if suggestion is not None:
        figures["suggestion_residual_mm"] = round(suggestion.warp_residual_mm, 3)
    warnings = list(notes) + list(fit.warnings)
    if suggestion is not None:
        warnings += list(suggestion.warnings)
    reg = recon.registration
    registration = None if reg is None else _registration_record(reg)
    dowels = inputs.dowels
    report = {
        "@schema": "reconstruction-report-v1",
        "case_id": case.meta.case_id,
        "created": utc_now(),
        "examiner": case.meta.examiner or inputs.examiner or None,  # the case's, if set now
        "software": {"name": "workbench", "version": __version__},
        "template": {"id": head.template_id, "content_hash": head.content_hash},
        # the frame of the landmark files too (one frame, said alike in both)
        "frame": f"{OUTPUT_FRAME}; the fit ran in the Frankfort head frame"
        + (
            " (mirrored input: the skull file is a mirror image of the subject, the head "
            "frame includes a reflection; views and pictures show the subject unmirrored)"
            if recon.mirrored_input
            else ""
        ),
        "units": "mm",
        "inputs": [_input_record(ev) for ev in case.evidence]
        + [_file_record("table", _table_file(dowels.table))]
        + ([_file_record("guides", guides_file)] if guides_file is not None else [])
        + [
            _file_record("template", Path(p) / "template.json")
            for p in (inputs.templates or ([inputs.template] if inputs.template else []))
        ],
        "table": {
            "id": plan.table_id,
            "title": plan.table_title,
            "citation": plan.citation,
            "group": plan.group_label,
            "build": dowels.build_text,
        },
        "parameters": _run_parameters(inputs),
        "landmarks": rows,
        "guides": guides_to_json(fit.guides),
        "predictions": [
            {
                "rule_id": p.rule_id,
                "label": p.label,
                "value_mm": float(p.value_mm),
                "citation": p.citation,
            }
            for p in fit.predictions
            if np.isfinite(p.value_mm)
        ],
        "fit": figures,
        "registration": registration,
        "self_check": None if reg is None else self_check_record(reg.figures),
        "tissue": None if recon.tissue is None else recon.tissue.to_json(),
        "inferred": None
        if recon.observed is None
        else {
            "face_observed_fraction": recon.figures.get("face_observed_fraction"),
            "note": "skin over bone the registration did not find (missing mandible, defects, a "
            "cut vault) takes the reference head's shape; it is marked inferred per "
            "vertex (head/observed.npy, the pictures and the uncertainty map)",
        },
        "ensemble": None
        if spread is None
        else {
            "n": inputs.ensemble,
            "spread_mm": {
                "median": float(np.median(spread)),
                "p90": float(np.percentile(spread, 90)),
                "max": float(spread.max()),
            },
        },
        "validation": None,
        "pictures": {},
        "warnings": warnings,
    }
    _add_credits_builds_references(report, case, fit)
    return report


def _landmark_rows(landmarks: LandmarkSet, recon: Reconstruction) -> list[dict[str, Any]]:
    """The report's landmark rows (input frame, mm): every landmark with its dowel (or
    none, with the reason), then the interpolated dowel sites."""
    catalogue = load_catalogue()
    plan = recon.plan
    by_code = {d.code: d for d in plan.dowels}
    rows = []
    for lm in landmarks:
        d = by_code.get(lm.code)
        entry = catalogue.get(lm.code, "skull")
        rows.append(
            {
                "code": lm.code,
                "name": entry.name if entry else lm.code,
                "status": lm.status,
                "confidence": float(lm.confidence) if lm.is_defined else None,
                "position_mm": None if not lm.is_defined else [float(v) for v in lm.position],
                "skin_code": None if d is None else d.skin_code,
                "table_depth_mm": None if d is None else d.table_depth_mm,
                "sd_mm": None if d is None else d.sd_mm,
                "depth_mm": None if d is None or d.excluded else float(d.depth_mm),
                "source": "none" if d is None else ("excluded" if d.excluded else d.source),
                "direction": None if d is None else _dir_in(recon, d.direction),
                "note": (
                    f"suggested with confidence {lm.confidence:.2f} < {MIN_CONFIDENCE:g}: "
                    "no dowel until confirmed or moved"
                )
                if lm.status == "suggested" and d is None and lm.confidence < MIN_CONFIDENCE
                else None,
            }
        )
    for d in plan.dowels:
        if d.source == "interpolated":
            rows.append(
                {
                    "code": d.code,
                    "name": "interpolated site",
                    "status": "suggested",
                    "position_mm": [float(v) for v in recon.to_input(d.origin[None])[0]],
                    "skin_code": None,
                    "table_depth_mm": None,
                    "sd_mm": d.sd_mm,
                    "depth_mm": None if d.excluded else float(d.depth_mm),
                    "source": "excluded" if d.excluded else "interpolated",
                    "direction": _dir_in(recon, d.direction),
                }
            )
    return rows


def _registration_record(reg: SkullRegistration) -> dict[str, Any]:
    """The skull registration as the report records it: method, figures, parts."""
    return {
        "method": "dense registration of the reference skull onto the bone (orientation search, "
        "per-part coarse-to-fine non-rigid), soft tissue carried by the skull's "
        "displacement field",
        **reg.figures,
        "parts": [
            {
                "name": p.name,
                "present": p.present,
                "observed_fraction": p.observed_fraction,
                "note": p.note,
            }
            for p in reg.parts
        ],
    }


def _add_credits_builds_references(report: dict[str, Any], case: Case, fit: FitResult) -> None:
    """The report's optional sections: credit lines the input data need, the build faces
    and the per-reference-head fits (``report`` is changed in place)."""
    # data that must carry a credit line (the Visible Human CTs, and meshes made from them)
    from workbench.io.samples import credits_for

    credits = credits_for(
        [ev.original_path for ev in case.evidence if getattr(ev, "original_path", "")],
        [ev.sha256 for ev in case.evidence],
    )
    if credits:
        report["credits"] = credits
    if fit.builds is not None:
        report["builds"] = {
            **fit.builds.summary(),
            "files": [f"face_{n}.ply" for n in fit.builds.names]
            + ["face_builds.glb", "face_band_mm.npy", "face_band_edges_mm.npy"],
            "note": "the skull cannot tell the build: three faces at the build model's BMIs "
            "(depths mean + r SD z by region; a stated model, see data_tables/build), and a "
            "95 % band over the slender-heavy range, the spread a known build leaves, the "
            "fit's own error and the inferred skin (face.ply vertex band_mm)",
        }
    if fit.references is not None:
        between = fit.references["spread"]
        report["references"] = {
            "method": "one fit per reference head, the face their per-vertex median (input frame)",
            "heads": fit.references["heads"],
            "spread_between_mm": {
                "median": float(np.median(between)),
                "p90": float(np.percentile(between, 90)),
            },
        }


def self_check_record(figures: Mapping[str, Any]) -> dict[str, Any] | None:
    """The registration's self-check as the report records it (None when it has none)."""
    check = figures.get("self_check")
    if check is None:
        return None
    return {**check, "measures": dict(figures.get("check_measures") or {})}


def _run_parameters(inputs: FitInputs) -> dict[str, Any]:
    """The settings of the run as the report records them (the case's typed parts)."""
    guides = (
        "none"
        if not inputs.use_guides
        else ("computed from the skull" if inputs.guides is None else "set in the case")
    )
    return {
        "dowels": inputs.dowels.to_state(),
        "orientation": None if inputs.orientation is None else inputs.orientation.to_state(),
        "guides": guides,
        "rules": list(inputs.rules),
        "ensemble": inputs.ensemble,
        "tissue_model": inputs.dowels.tissue_model,
    }


#: the frame ``template.json`` records for a fitted head written by the jobs
FITTED_HEAD_FRAME_TEXT = (
    "the skull file's frame (input frame of the evidence), mm; the fit "
    "ran in the Frankfort head frame and was mapped back"
)


def head_in_input_frame(recon: Reconstruction) -> TemplateHead:
    """The fitted head with every part mapped into the skull file's frame.

    Skin vertices over bone the registration did not find are the region
    ``inferred`` (their shape is the reference's prior).
    """
    h = recon.head
    if recon.observed is not None:
        # the skin over missing bone, as a region of the pack (template.json)
        h = replace(h, regions={**h.regions, "inferred": np.flatnonzero(recon.inferred)})
    inv = np.linalg.inv(recon.input_to_head)
    axis_pts = recon.to_input(np.vstack([h.tmj_axis[0], h.tmj_axis[0] + h.tmj_axis[1]]))
    return replace(
        h,
        meshes={k: recon.mesh_to_input(m) for k, m in h.meshes.items()},
        skin_landmarks=h.skin_landmarks.transformed(inv),
        skull_landmarks=h.skull_landmarks.transformed(inv),
        eye_centres=recon.to_input(h.eye_centres),
        tmj_axis=np.vstack(
            [axis_pts[0], (axis_pts[1] - axis_pts[0]) / np.linalg.norm(axis_pts[1] - axis_pts[0])]
        ),
    )


def hair_in_input_frame(
    recon: Reconstruction,
    appearance: Appearance | None,
    vertices: np.ndarray | None = None,
    *,
    stride: int = 1,
) -> list[HairMesh]:
    """The case's chosen hair, brows, beard and moustache (artistic additions) grown on the
    fitted head's skin, or on ``vertices`` (a build's skin, head frame), and mapped into the
    skull file's frame as :func:`head_in_input_frame` maps the head: triangles turned over
    for a mirrored input, normals turned with the frame.  Empty when none was chosen."""
    pieces = hair_meshes(recon.head, appearance, vertices, stride=stride)
    # normals map by the inverse transpose of the points' linear map (input -> head)
    turn = np.asarray(recon.input_to_head, float)[:3, :3]
    out = []
    for piece in pieces:
        n = piece.normals @ turn
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
        out.append(replace(piece, mesh=recon.mesh_to_input(piece.mesh), normals=n))
    return out


def job_inputs(
    skull_path: str | PathLike[str] | None,
    settings: JobSettings,
    *extra: str | PathLike[str] | None,
) -> list[Path]:
    """Every file or folder a job reads: skull, landmarks, guides, table CSV, packs, ``extra``.

    Outputs are checked against these (:mod:`workbench.io.outputs`): none may
    be replaced, and none may lie inside the output folder.
    """
    found = [
        skull_path,
        settings.landmarks,
        settings.guides_file,
        settings.template,
        *settings.templates,
        *extra,
    ]
    table = Path(settings.table)
    if table.suffix == ".csv" and table.is_file():
        found.append(table)
    return [Path(p) for p in found if p is not None]


def _result_inputs(result: JobResult) -> list[Path]:
    originals = [
        ev.original_path for ev in result.opened.case.evidence if getattr(ev, "original_path", None)
    ]
    return job_inputs(None, result.settings, *originals)


def write_outputs(
    result: JobResult, out: str | PathLike[str], *, force: bool = False, staged: bool = False
) -> dict[str, Path]:
    """Outputs in the skull file's frame (no report files).

    ``face.ply`` is also in the skull file's **units**, so it overlays the
    evidence in any viewer, and its ``comment units:`` header line names
    them (e.g. ``units: cm``); when those are not mm, ``face_mm.ply`` is the
    same surface in mm.  ``head/`` (a template pack: skin, skull parts,
    muscles, landmarks) and the landmark file are in mm, as the pack format
    and the case require.

    ``out`` is written as a whole (:func:`workbench.io.outputs.staged_folder`):
    a folder holding one of the job's inputs is refused, an existing one
    only replaced with ``force`` (kept as ``DIR.1``), and a failure leaves it
    as it was.  ``staged=True``: ``out`` is a fresh folder the caller staged
    itself (``workbench reconstruct`` adds the report to it); it is written
    straight into.
    """
    if staged:
        return _write_into(result, Path(out))
    final = Path(os.path.abspath(out))
    with staged_folder(final, force, _result_inputs(result)) as temp:
        files = _write_into(result, temp)
    result.opened.case.source_path = final / "case.fcase"
    return relocate(files, temp, final)


#: hair displacements (mm) below this are written as 0 in a glTF's sparse morph targets
HAIR_MIN_MM = 0.01

#: the band's files beside face.ply
BAND_FILES = "face_band_mm.npy; inner/outer edges in face_band_edges_mm.npy"


def write_build_files(
    recon: Reconstruction,
    builds: BuildFaces,
    out: Path,
    *,
    units_per_mm: float = 1.0,
    units_label: str = "mm",
    appearance: Appearance | None = None,
) -> dict[str, Path]:
    """``face_<build>.ply`` per build (the skull file's frame and units, as ``face.ply``),
    the band (``face_band_mm.npy``: half-width mm per vertex of ``face.ply``;
    ``face_band_edges_mm.npy``: (n, 2) inner and outer edge, mm along the face's outward
    normal) and ``face_builds.glb`` (the main face with one morph target per other build,
    the skull file's frame, mm ÷ 1000), its skin coloured as the case's ``appearance``
    says (an artistic choice; None: the default tone), with the hair, brows, beard and
    moustache it chose (artistic additions, every strand) as nodes of their own whose
    morph targets follow the builds (grown on each build's skin)."""
    from workbench.io.gltf_export import Shading, write_glb
    from workbench.services.appearance import skin_look

    files: dict[str, Path] = {}
    for name in builds.names:
        files[f"face_{name}"] = ply.write(
            out / f"face_{name}.ply",
            builds.face(name, recon).scaled(units_per_mm),
            units=units_label,
            comments=[
                f"build {name}: BMI {builds.bmi[name]:g} kg/m2 (build model {builds.model_id})"
            ],
        )
    np.save(out / "face_band_mm.npy", builds.half_width_mm.astype(np.float32))
    edges = np.column_stack([builds.lower_mm, builds.upper_mm]).astype(np.float32)
    np.save(out / "face_band_edges_mm.npy", edges)
    files["band"] = out / "face_band_mm.npy"
    files["band_edges"] = out / "face_band_edges_mm.npy"
    skin_name = f"face_{builds.main}".replace(" ", "_")
    others = [n for n in builds.names if n != builds.main]
    # recon.face is the fitted head's skin vertex for vertex: its colours apply as they are
    looks = {skin_name: skin_look(recon.head, appearance)}
    extra: dict[str, Mesh] = {}
    extra_targets: dict[str, dict[str, np.ndarray]] = {}
    shading: dict[str, Shading] = {}
    if appearance is not None:
        for piece in hair_in_input_frame(recon, appearance):
            extra[piece.kind] = piece.mesh
            looks[piece.kind] = hair_look(piece, appearance)
            shading[piece.kind] = Shading(
                piece.normals, double_sided=True, tinted=True, min_displacement_mm=HAIR_MIN_MM
            )
    for name in others if extra else ():  # float32: the hair has many vertices
        for piece in hair_in_input_frame(recon, appearance, builds.vertices(name)):
            extra_targets.setdefault(piece.kind, {})[name] = piece.mesh.vertices.astype(np.float32)
    files["builds_glb"] = write_glb(
        out / "face_builds.glb",
        recon.face,
        {n: recon.to_input(builds.vertices(n)) for n in others},
        extra_nodes=extra,
        node_targets=extra_targets,
        skin_name=skin_name,
        frame=FITTED_HEAD_FRAME_TEXT,
        looks=looks,
        shading=shading,
    )
    return files


def _write_into(result: JobResult, out: Path) -> dict[str, Path]:
    out.mkdir(parents=True, exist_ok=True)
    face = result.recon.face
    k = result.file_units_per_mm
    builds = result.fit.builds if result.fit is not None else None
    band = {"band_mm": builds.half_width_mm} if builds is not None else None
    band_note = (
        [f"vertex band_mm: half-width (mm) of the 95 % band, build unknown ({BAND_FILES})"]
        if builds is not None
        else []
    )
    if k == 1.0:
        files = {"face": ply.write(out / "face.ply", face, vertex_scalars=band, comments=band_note)}
    else:  # the skull file's units, and the header says so (not "mm")
        files = {
            "face": ply.write(
                out / "face.ply",
                face.scaled(k),
                units=result.file_units_label,
                comments=["same surface in mm: face_mm.ply", *band_note],
                vertex_scalars=band,
            )
        }
    if k != 1.0:
        files["face_mm"] = write_mesh(out / "face_mm.ply", face)
    if builds is not None:
        files.update(
            write_build_files(
                result.recon,
                builds,
                out,
                units_per_mm=k,
                units_label=result.file_units_label,
                appearance=result.opened.case.appearance,
            )
        )
    reg = result.recon.registration
    if reg is not None and reg.occlusion is not None:
        # the face was fitted over the skull with its jaw in occlusion: that skull beside it
        # (the working skull, in the skull file's frame and units)
        files["skull_articulated"] = ply.write(
            out / "skull_articulated.ply",
            articulated_skull(reg).scaled(k),
            units=result.file_units_label,
            comments=[
                "the skull with its mandible brought into occlusion for the face "
                f"({reg.occlusion.method}; opened {reg.jaw.opening_deg:.1f} deg in the scan)"
                if reg.jaw is not None
                else "the skull with its mandible brought into occlusion for the face"
            ],
        )
    head_in = head_in_input_frame(result.recon)
    export_template(head_in, out / "head", frame=FITTED_HEAD_FRAME_TEXT)
    files["head"] = out / "head"
    write_mrk_json(
        out / "skull_landmarks.mrk.json",
        result.opened.case.landmarks["skull"],
        coordinate_system=OUTPUT_SYSTEM,
    )
    files["landmarks"] = out / "skull_landmarks.mrk.json"
    if result.fit is not None:  # the face kept with the case: reopened, it is shown at once
        from workbench.services.reconstruction.stored_fit import KEY, fit_to_state

        result.opened.case.derived[KEY] = fit_to_state(result.fit, result.opened.case)
    files["case"] = save_case(result.opened.case, out / "case.fcase", result.opened.stack)
    return files
