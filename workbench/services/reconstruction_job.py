"""The whole skull → face job as one scriptable call (used by ``workbench reconstruct``).

Units mm.  Inputs are in the skull file's frame; outputs (face, head,
landmarks) are mapped back into that frame so they overlay the evidence.

Steps: open the skull as a case (evidence kept, units checked), suggest
landmarks when none are given, fit the reference head
(:mod:`workbench.services.reconstruct`) with the dowel plan and the nose /
mouth guides, optionally an uncertainty ensemble, and assemble the report
data (pictures are added by the caller, which may render).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from workbench import __version__
from workbench.commands.case_edits import SetParameter
from workbench.commands.landmarks import ReplaceLandmarkSet
from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh
from workbench.io.catalogue import load_catalogue
from workbench.io.case_file import save_case
from workbench.io.markups import write_mrk_json
from workbench.io.meshes import write_mesh
from workbench.io.template_pack import export_template
from workbench.model.template import TemplateHead
from workbench.services.case_setup import OpenedCase, start_case_from_skull
from workbench.services.dowels import DepthSettings
from workbench.core.errors import WorkbenchError
from workbench.core.frame import apply_transform
from workbench.core.units import UNIT_SCALES
from workbench.core.isosurface import decimate
from workbench.services.guide_rules import published_predictions
from workbench.services.guides import (
    apply_guides, check_guides, classic_guides, guides_from_json, guides_from_prediction,
    guides_to_json,
)
from workbench.services.landmark_transfer import TransferResult, transfer_landmarks
from workbench.services.reconstruct import (
    FitSettings, Reconstruction, ensemble_spread, outward, reconstruct,
)
from workbench.services.reference_parts import skull_surface
from workbench.services.template_cache import reference_head
from workbench.services.tissue_model import TissueSettings

Progress = Callable[[str], None]
#: skulls larger than this are decimated to WORKING_TRIANGLES for the fit
MAX_WORKING_TRIANGLES = 250_000
WORKING_TRIANGLES = 200_000


@dataclass(frozen=True)
class JobSettings:
    """Everything ``workbench reconstruct`` takes besides the skull file."""

    units: str = "auto"
    scale: float | None = None
    landmarks: str | PathLike[str] | None = None
    table: str = "ttable_2023"
    sex: str = "male"
    build: str | float = "normal"
    guides: str | PathLike[str] = "default"      # "default" | "none" | JSON file
    rules: tuple[str, ...] = ()                  # published rules replacing classic guides
    ensemble: int = 0
    template: str | PathLike[str] | None = None
    #: two or more reference packs: one fit each, the face their per-vertex median
    templates: tuple = ()
    orientation: tuple | None = None             # (anterior, superior[, left]) in file coords
    excluded: frozenset[str] = frozenset()
    overrides: dict = field(default_factory=dict)
    examiner: str = ""
    tissue: TissueSettings = field(default_factory=TissueSettings)


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

    @property
    def file_units_per_mm(self) -> float:
        """1 / (mm per unit of the skull file): to write results in the file's own units."""
        mm_per_unit = self.settings.scale or UNIT_SCALES.get(self.settings.units, 1.0)
        return 1.0 / mm_per_unit


def _skull_h(skull: Mesh, to_head: np.ndarray) -> Mesh:
    faces = skull.faces if np.linalg.det(to_head[:3, :3]) > 0 else skull.faces[:, ::-1]
    return outward(Mesh(apply_transform(to_head, skull.vertices), faces))


def run_reconstruction(skull_path: str | PathLike[str], settings: JobSettings = JobSettings(),
                       progress: Progress | None = None) -> JobResult:
    say = progress or (lambda _msg: None)
    times: dict[str, float] = {}
    t = time.perf_counter()
    opened = start_case_from_skull(skull_path, units=settings.units, scale=settings.scale,
                                   examiner=settings.examiner, landmarks_path=settings.landmarks)
    case, stack = opened.case, opened.stack
    skull = case.specimen.mesh
    head = reference_head(settings.sex, settings.template)
    times["open"] = time.perf_counter() - t
    work = skull
    if skull.n_faces > MAX_WORKING_TRIANGLES:
        # Kähler §8.6.4: a 50-250k-triangle working mesh keeps the editor
        # responsive; the original stays in the case as evidence
        say(f"decimating the working skull {skull.n_faces} -> {WORKING_TRIANGLES} triangles ...")
        v, f = decimate(skull.vertices, skull.faces, WORKING_TRIANGLES)
        work = Mesh(v, f)
        opened.notes.append(f"working skull decimated from {skull.n_faces} to {work.n_faces} "
                            "triangles (the original file is kept as evidence)")
    suggestion = None
    given = case.landmarks.get("skull")
    if given is not None and not len(given):
        given = None
    depth = DepthSettings(table=settings.table, sex=settings.sex, build=settings.build,
                          overrides=dict(settings.overrides), excluded=frozenset(settings.excluded))
    fit = FitSettings(depth=depth, tissue=settings.tissue)
    say("registering the reference skull and fitting the head ...")
    t = time.perf_counter()
    chosen: list = []
    rejected: list[str] = []

    def guide_fn(skull_h: Mesh, lms_h: LandmarkSet, plan):  # noqa: ANN001, ANN202
        if str(settings.guides) == "none":
            return None
        if str(settings.guides) == "default":
            tips = {d.code: d.tip for d in plan.active()}
            table = settings.table if not str(settings.table).endswith(".csv") else "ttable_2023"
            chosen.extend(classic_guides(lms_h, skull_h, dowel_tips=tips, sex=settings.sex,
                                         table_id=table))
        else:
            import json

            chosen.extend(guides_from_json(
                json.loads(Path(settings.guides).read_text("utf-8")), settings.guides))
        if settings.rules:
            tips = {d.code: d.tip for d in plan.active()}
            why: list[str] = []
            preds = published_predictions(lms_h, settings.sex, rules=settings.rules,
                                          skull=skull_h, dowel_tips=tips, problems=why)
            for pred in preds:
                if pred.target:
                    chosen[:] = guides_from_prediction(pred, chosen)
            found = {p.rule_id for p in preds}
            rejected.extend(f"published rule {r} not applied: "
                            f"{'; '.join(why) or 'no prediction for this skull'}"
                            for r in settings.rules if r not in found)
        return lambda skin: plausible_guides(chosen, skin, skull_h, lms_h, rejected)

    recon = reconstruct(work, given, head, settings=fit, guides=guide_fn,
                        hint=settings.orientation, progress=say)
    references = None
    if len(settings.templates) > 1:
        recon, references = _consensus(recon, work, given, settings, fit, say)
    landmarks = recon.landmarks
    stack.push(ReplaceLandmarkSet(surface="skull", new_set=landmarks,
                                  label="Skull landmarks from the dense registration"))
    guides = chosen
    skull_h = _skull_h(work, recon.input_to_head)
    lms_h = landmarks.transformed(recon.input_to_head)
    problems = check_guides([g for g in guides if g.enabled], skull_h, lms_h) if guides else []
    recon = replace(recon, warnings=recon.warnings + tuple(rejected)
                    + tuple(f"guide: {p}" for p in problems))
    try:
        predictions = published_predictions(lms_h, settings.sex, skull=skull_h)
    except WorkbenchError as exc:  # informative only: a missing measurement must not stop the job
        predictions = []
        opened.notes.append(f"published guide predictions unavailable: {exc}")
    times["fit"] = time.perf_counter() - t
    spread = None
    if settings.ensemble > 0:
        say(f"ensemble of {settings.ensemble} fits ...")
        t = time.perf_counter()
        spread = ensemble_spread(recon, head, skull_h, settings.ensemble, settings=fit)
        times["ensemble"] = time.perf_counter() - t
    for key, value in (("template_id", head.template_id), ("template_hash", head.content_hash),
                       ("depth_table", recon.plan.table_id), ("depth_group", recon.plan.group_label),
                       ("sex", settings.sex), ("build", str(settings.build)),
                       ("guides", guides_to_json(guides)),
                       ("excluded_landmarks", sorted(settings.excluded)),
                       ("depth_overrides", {k: float(v) for k, v in settings.overrides.items()})):
        stack.push(SetParameter(key=key, value=value))
    report = build_report(opened, head, recon, landmarks, guides, spread, suggestion, settings)
    if references is not None and spread is None:
        spread = references["spread"]   # the pictures' spread map: between the references
    if references is not None:
        report["references"] = {
            "method": "one fit per reference head, the face their per-vertex median (input frame)",
            "heads": references["heads"],
            "spread_between_mm": {"median": float(np.median(references["spread"])),
                                  "p90": float(np.percentile(references["spread"], 90))}}
    report["predictions"] = [
        {"rule_id": p.rule_id, "label": p.label, "value_mm": float(p.value_mm),
         "citation": p.citation} for p in predictions if np.isfinite(p.value_mm)]
    return JobResult(opened, head, recon, skull_h, suggestion, guides, spread, report, times,
                     settings)


def _consensus(first: Reconstruction, work: Mesh, given: LandmarkSet | None,
               settings: JobSettings, fit: FitSettings, say: Progress
               ) -> tuple[Reconstruction, dict]:
    """Fit every reference pack of ``settings.templates``; the face is their per-vertex median.

    All packs must share the first one's skin topology (packs built from the
    same base head do).  The spread between them (median distance of the
    members from the median face, mm) comes back with the head list.
    """
    faces = [first.face]
    heads = [{"id": first.head.template_id, "path": str(settings.templates[0])}]
    for i, pack in enumerate(settings.templates[1:], start=2):
        say(f"reference {i}/{len(settings.templates)} ...")
        other = reconstruct(work, given, reference_head(settings.sex, pack), settings=fit,
                            hint=settings.orientation)
        if other.head.skin.n_vertices != first.head.skin.n_vertices or \
                other.head.skin.n_faces != first.head.skin.n_faces:
            raise WorkbenchError(f"reference {pack} does not share the skin topology of "
                                 f"{settings.templates[0]} (packs must be built from one base head)")
        faces.append(other.face)
        heads.append({"id": other.head.template_id, "path": str(pack)})
    stack = np.stack([f.vertices for f in faces])
    median = np.median(stack, axis=0)
    spread = np.median(np.linalg.norm(stack - median, axis=2), axis=0)
    skin_h = apply_transform(first.input_to_head, median)
    head = replace(first.head, meshes={**first.head.meshes,
                                       "skin": first.head.skin.with_vertices(skin_h)})
    recon = replace(first, head=head, warnings=first.warnings + (
        f"face = per-vertex median of {len(faces)} reference heads (spread between them: median "
        f"{np.median(spread):.1f} mm)",))
    return recon, {"heads": heads, "spread": spread}


#: a computed guide that would move its skin landmark farther than this from
#: the tissue-depth fit is taken as a failed skull measurement and switched off
MAX_GUIDE_SHIFT_MM = 8.0
MIN_CONFIDENCE = FitSettings().min_confidence


def plausible_guides(guides: list, skin: dict[str, np.ndarray], skull_h: Mesh,
                      lms_h: LandmarkSet, rejected: list[str]) -> dict[str, np.ndarray]:
    """Guide targets, leaving out computed guides that fail their checks.

    A guide set by the user is always applied.  A computed one is switched
    off (and the reason recorded in ``rejected``) when ``check_guides`` finds
    it outside the skull or anatomically impossible, or when it would move
    its landmark more than :data:`MAX_GUIDE_SHIFT_MM` from the tissue-depth
    fit — never a silently distorted face.
    """
    for i, g in enumerate(guides):
        if not g.enabled or g.source == "user":
            continue
        problems = check_guides([g], skull_h, lms_h)
        shift = max((float(np.linalg.norm(p - skin[c])) for c, p in apply_guides([g], skin).items()),
                    default=0.0)
        if problems or shift > MAX_GUIDE_SHIFT_MM:
            why = problems[0] if problems else f"it would move {', '.join(g.affects)} by {shift:.1f} mm"
            rejected.append(f"guide {g.id} switched off ({why}); check the skull there or set "
                            "the guide by hand")
            guides[i] = replace(g, enabled=False)
    return apply_guides(guides, skin)


def _input_record(ev: Any) -> dict[str, Any]:
    return {"role": "skull" if ev.role == "skull_mesh" else "landmarks", "path": ev.name,
            "sha256": ev.sha256, "units": ev.units_note or "mm"}


def _file_record(role: str, path: str | PathLike[str]) -> dict[str, Any]:
    from workbench.io.tables import tables_dir
    from workbench.reporting.report import sha256_file

    shown = Path(path)
    try:  # built-in tables by their place in the project, not this machine's path
        shown = Path("data_tables") / shown.resolve().relative_to(tables_dir().parent.resolve())
    except ValueError:
        pass
    return {"role": role, "path": str(shown), "sha256": sha256_file(path), "units": "mm"}


def _table_file(table: str) -> Path:
    from workbench.io.tables import tables_dir

    p = Path(table)
    return p if p.suffix == ".csv" and p.is_file() else tables_dir() / f"{table}.csv"


def _dir_in(recon: Reconstruction, direction: np.ndarray) -> list[float]:
    """A head-frame direction in the input frame (unit length)."""
    v = np.linalg.inv(recon.input_to_head)[:3, :3] @ np.asarray(direction, float)
    return [float(x) for x in v / np.linalg.norm(v)]


def build_report(opened: OpenedCase, head: TemplateHead, recon: Reconstruction,
                 landmarks: LandmarkSet, guides: list, spread: np.ndarray | None,
                 suggestion: TransferResult | None, settings: JobSettings) -> dict[str, Any]:
    """The report dict (``reconstruction-report-v1``) without pictures."""
    from workbench.reporting.report import utc_now

    catalogue = load_catalogue()
    plan = recon.plan
    by_code = {d.code: d for d in plan.dowels}
    rows = []
    for lm in landmarks:
        d = by_code.get(lm.code)
        entry = catalogue.get(lm.code, "skull")
        rows.append({
            "code": lm.code, "name": entry.name if entry else lm.code, "status": lm.status,
            "confidence": float(lm.confidence) if lm.is_defined else None,
            "position_mm": None if not lm.is_defined else [float(v) for v in lm.position],
            "skin_code": None if d is None else d.skin_code,
            "table_depth_mm": None if d is None else d.table_depth_mm,
            "sd_mm": None if d is None else d.sd_mm,
            "depth_mm": None if d is None or d.excluded else float(d.depth_mm),
            "source": "none" if d is None else ("excluded" if d.excluded else d.source),
            "direction": None if d is None else _dir_in(recon, d.direction),
            "note": (f"suggested with confidence {lm.confidence:.2f} < {MIN_CONFIDENCE:g}: no dowel "
                     "until confirmed or moved") if lm.status == "suggested" and d is None
            and lm.confidence < MIN_CONFIDENCE else None,
        })
    for d in plan.dowels:
        if d.source == "interpolated":
            rows.append({"code": d.code, "name": "interpolated site", "status": "suggested",
                         "position_mm": [float(v) for v in recon.to_input(d.origin[None])[0]],
                         "skin_code": None, "table_depth_mm": None, "sd_mm": d.sd_mm,
                         "depth_mm": None if d.excluded else float(d.depth_mm),
                         "source": "excluded" if d.excluded else "interpolated",
                         "direction": _dir_in(recon, d.direction)})
    fit = {k: v for k, v in recon.figures.items() if k != "registration"}
    fit["suggested_landmarks"] = sum(lm.status == "suggested" for lm in landmarks)
    fit["placed_landmarks"] = sum(lm.status == "placed" for lm in landmarks)
    fit["absent_landmarks"] = sum(not lm.is_defined for lm in landmarks)
    if suggestion is not None:
        fit["suggestion_residual_mm"] = round(suggestion.warp_residual_mm, 3)
    warnings = list(opened.notes) + list(recon.warnings)
    if suggestion is not None:
        warnings += list(suggestion.warnings)
    reg = recon.registration
    registration = None if reg is None else {
        "method": "dense registration of the reference skull onto the bone (orientation search, "
                  "per-part coarse-to-fine non-rigid), soft tissue carried by the skull's "
                  "displacement field",
        **reg.figures,
        "parts": [{"name": p.name, "present": p.present, "observed_fraction": p.observed_fraction,
                   "note": p.note} for p in reg.parts],
    }
    return {
        "@schema": "reconstruction-report-v1",
        "case_id": opened.case.meta.case_id,
        "created": utc_now(),
        "examiner": settings.examiner or None,
        "software": {"name": "workbench", "version": __version__},
        "template": {"id": head.template_id, "content_hash": head.content_hash},
        "frame": "input frame of the skull file (mm); the fit ran in the Frankfort head frame"
                 + (" (mirrored input: reflection included)" if recon.mirrored_input else ""),
        "units": "mm",
        "inputs": [_input_record(ev) for ev in opened.case.evidence]
        + [_file_record("table", _table_file(settings.table))]
        + ([_file_record("guides", settings.guides)]
           if str(settings.guides) not in ("default", "none") else [])
        + ([_file_record("template", Path(settings.template) / "template.json")]
           if settings.template is not None else []),
        "table": {"id": plan.table_id, "title": plan.table_title, "citation": plan.citation,
                  "group": plan.group_label, "build": str(settings.build)},
        "landmarks": rows,
        "guides": guides_to_json(guides),
        "predictions": [],
        "fit": fit,
        "registration": registration,
        "tissue": None if recon.tissue is None else recon.tissue.to_json(),
        "inferred": None if recon.observed is None else {
            "face_observed_fraction": recon.figures.get("face_observed_fraction"),
            "note": "skin over bone the registration did not find (missing mandible, defects, a "
                    "cut vault) takes the reference head's shape; it is marked inferred per "
                    "vertex (head/observed.npy, the pictures and the uncertainty map)"},
        "ensemble": None if spread is None else {
            "n": settings.ensemble,
            "spread_mm": {"median": float(np.median(spread)),
                          "p90": float(np.percentile(spread, 90)), "max": float(spread.max())}},
        "validation": None,
        "pictures": {},
        "warnings": warnings,
    }


#: the frame ``template.json`` records for a fitted head written by the jobs
FITTED_HEAD_FRAME_TEXT = ("the skull file's frame (input frame of the evidence), mm; the fit "
                          "ran in the Frankfort head frame and was mapped back")


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
        tmj_axis=np.vstack([axis_pts[0], (axis_pts[1] - axis_pts[0])
                            / np.linalg.norm(axis_pts[1] - axis_pts[0])]),
    )


def write_outputs(result: JobResult, out: str | PathLike[str]) -> dict[str, Path]:
    """Outputs in the skull file's frame (no report files).

    ``face.ply`` is also in the skull file's **units**, so it overlays the
    evidence in any viewer; when those are not mm, ``face_mm.ply`` is the
    same surface in mm.  ``head/`` (a template pack: skin, skull parts,
    muscles, landmarks) and the landmark file are in mm, as the pack format
    and the case require.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    face = result.recon.face
    k = result.file_units_per_mm
    files = {"face": write_mesh(out / "face.ply", face if k == 1.0 else face.scaled(k))}
    if k != 1.0:
        files["face_mm"] = write_mesh(out / "face_mm.ply", face)
    head_in = head_in_input_frame(result.recon)
    export_template(head_in, out / "head", frame=FITTED_HEAD_FRAME_TEXT)
    files["head"] = out / "head"
    write_mrk_json(out / "skull_landmarks.mrk.json", result.opened.case.landmarks["skull"],
                   coordinate_system="RAS")
    files["landmarks"] = out / "skull_landmarks.mrk.json"
    files["case"] = save_case(result.opened.case, out / "case.fcase", result.opened.stack)
    return files

