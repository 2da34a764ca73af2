"""The window's background jobs: plain functions over the services, no Qt, no VTK.

The window runs these in a worker thread (:mod:`workbench.qt.workers`) and
applies their results on the GUI thread through undoable commands.  They
read the case's parameters with the same keys ``workbench reconstruct``
writes (:func:`workbench.services.reconstruction_job.run_reconstruction`):

=================== ==========================================================
key                 value
=================== ==========================================================
depth_table         table id (``workbench.io.tables.list_tables``)
sex                 "female" | "male" (depth group and reference head)
build               "slender" | "normal" | "obese" or a number k (mean + k SD)
depth_overrides     ``{skull code: depth mm}``
excluded_landmarks  list of skull codes whose dowels are off
guides              list of guide dicts (``guides_to_json``); absent = computed
orientation         ``{"anterior": [x,y,z], "superior": [x,y,z]}`` of the file
=================== ==========================================================

Units mm.  Landmarks, dowels and the face are returned in the **input frame**
(the skull file's frame) so they overlay the specimen; the fit itself runs in
the head frame (x to the subject's left, y up, z forward, Frankfort
Horizontal at y = 0).
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from workbench.core.errors import WorkbenchError
from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh
from workbench.model.case import Case
from workbench.model.evidence import sha256_file
from workbench.model.template import TemplateHead
from workbench.services.dowels import DepthSettings, DowelPlan, plan_dowels
from workbench.services.guides import (
    Guide, classic_guides, guides_from_json, guides_to_json,
)
from workbench.services.guide_rules import published_predictions
from workbench.services.skull_registration import (
    SkullRegistration, mirror_from_landmarks, register_skull,
)
from workbench.services.reconstruct import (
    FitSettings, Reconstruction, ensemble_spread, input_frame, outward, reconstruct,
)
from workbench.services.reconstruction_job import plausible_guides
from workbench.services.reference_parts import skull_surface
from workbench.services.template_cache import reference_head

DEFAULTS: dict[str, Any] = {"depth_table": "ttable_2023", "sex": "male", "build": "normal",
                            "depth_overrides": {}, "excluded_landmarks": []}


def param(case: Case, key: str) -> Any:
    """``case.parameters[key]`` or the window's default for it."""
    return case.parameters.get(key, DEFAULTS.get(key))


def build_value(text: Any) -> str | float:
    """``"normal"`` stays a word; ``"1.5"`` becomes k = 1.5 SD."""
    text = str(text)
    if text in ("slender", "normal", "obese"):
        return text
    return float(text)


def depth_settings(case: Case) -> DepthSettings:
    """The dowel settings the case's parameters describe."""
    return DepthSettings(
        table=str(param(case, "depth_table")), sex=str(param(case, "sex")),
        build=build_value(param(case, "build")),
        overrides={str(k): float(v) for k, v in dict(param(case, "depth_overrides")).items()},
        excluded=frozenset(str(c) for c in param(case, "excluded_landmarks")))


def orientation(case: Case) -> tuple | None:
    """``(anterior, superior)`` in file coordinates, or None (automatic)."""
    value = case.parameters.get("orientation")
    if not value:
        return None
    out = (tuple(value["anterior"]), tuple(value["superior"]))
    return out + ((tuple(value["left"]),) if "left" in value else ())


def sample_orientation(path: str | Path) -> dict[str, list[float]] | None:
    """The known anatomy directions of a public sample file, matched by SHA-256.

    ``{"anterior": [...], "superior": [...] (, "left": [...])}`` in the
    file's coordinates, or None for any other file.
    """

    from workbench.io.samples import registry

    path = Path(path)
    if not path.is_file():
        return None
    digest = sha256_file(path)[0]
    for sample in registry().values():
        main = [f for f in sample.files if f.path == sample.main]
        if sample.anatomy and main and main[0].sha256 == digest:
            return {k: [float(v) for v in sample.anatomy[k]]
                    for k in ("anterior", "superior", "left") if k in sample.anatomy}
    return None


def view_axes(case: Case) -> tuple[np.ndarray, np.ndarray] | None:
    """``(anterior, superior)`` unit vectors in the input frame for the camera.

    From the head frame of the skull landmarks when they define one, else
    from the ``orientation`` parameter, else None.
    """
    try:
        to_head, _ = input_frame(case.landmarks["skull"])
    except (WorkbenchError, ValueError, KeyError, np.linalg.LinAlgError):
        orient = orientation(case)
        return None if orient is None else (np.array(orient[0], float),
                                            np.array(orient[1], float))
    back = np.linalg.inv(to_head)[:3, :3]
    a, s = back @ [0.0, 0.0, 1.0], back @ [0.0, 1.0, 0.0]
    return a / np.linalg.norm(a), s / np.linalg.norm(s)


def user_guides(case: Case) -> list[Guide] | None:
    """Guides stored in the case (edited by the user), or None (compute them)."""
    value = case.parameters.get("guides")
    if value is None:
        return None
    return guides_from_json(json.loads(json.dumps(_thaw(value))), "case guides")


def _thaw(value: Any) -> Any:
    if isinstance(value, Mapping):
        return {k: _thaw(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_thaw(v) for v in value]
    return value


# ------------------------------------------------------------------ suggest
def suggest_landmarks(skull: Mesh, current: LandmarkSet, sex: str,
                      orient: tuple | None) -> tuple[LandmarkSet, SkullRegistration]:
    """Suggest the skull landmarks not placed yet (input frame, mm), by the dense registration.

    Landmarks the user placed are seeds (and hard constraints) and stay as
    they are; landmarks the user marked absent stay absent.  Returns the new
    set and the registration (figures, warnings; reused by the fit).
    """
    head = reference_head(sex)
    placed = LandmarkSet("skull", tuple(lm for lm in current if lm.status == "placed"))
    reg = register_skull(skull, head, hint=orient, seeds=placed if len(placed) else None,
                         mirror=mirror_from_landmarks(current))
    # marked absent by a person (SetLandmarkStatus gives confidence 1; the registration 0)
    user_absent = {lm.code: lm for lm in current if lm.status == "absent" and lm.confidence > 0.5}
    merged = [user_absent.get(lm.code, lm) for lm in reg.landmarks]
    extra = [lm for lm in current if lm.code not in reg.landmarks]
    return LandmarkSet("skull", tuple(merged + extra)), reg


# ------------------------------------------------------------------ dowels
@dataclass(frozen=True)
class DowelPreview:
    """A dowel plan with origins and tips mapped into the input frame."""

    plan: DowelPlan
    origins: np.ndarray   # (n, 3) input frame mm, active dowels
    tips: np.ndarray      # (n, 3)
    codes: tuple[str, ...]


def _to(m: np.ndarray, p: np.ndarray) -> np.ndarray:
    return np.asarray(p, float).reshape(-1, 3) @ m[:3, :3].T + m[:3, 3]


def preview_dowels(skull: Mesh, landmarks: LandmarkSet, settings: DepthSettings,
                   orient: tuple | None = None) -> DowelPreview:
    """Plan the dowels (head frame) and map them back for display.

    The head frame comes from the landmarks' porions and orbitales, or —
    when they do not define one — from the dense registration of the skull.
    """
    try:
        to_head, _ = input_frame(landmarks)
    except (WorkbenchError, ValueError):
        head = reference_head(str(settings.sex or "male"))
        placed = LandmarkSet("skull", tuple(lm for lm in landmarks if lm.status == "placed"))
        to_head = register_skull(skull, head, hint=orient,
                                 seeds=placed if len(placed) else None,
                                 mirror=mirror_from_landmarks(landmarks)).input_to_head
    skull_h = outward(skull.transformed(to_head))
    plan = plan_dowels(skull_h, landmarks.transformed(to_head), settings)
    active = plan.active()
    back = np.linalg.inv(to_head)
    origins = _to(back, np.array([d.origin for d in active])) if active else np.zeros((0, 3))
    tips = _to(back, np.array([d.tip for d in active])) if active else np.zeros((0, 3))
    return DowelPreview(plan, origins, tips, tuple(d.code for d in active))


# ------------------------------------------------------------------ fit
@dataclass(frozen=True)
class FitResult:
    """A reconstruction with the guides it used and, optionally, its spread."""

    recon: Reconstruction
    head: TemplateHead
    skull_h: Mesh
    guides: tuple[Guide, ...]
    spread: np.ndarray | None   # (n_skin_vertices,) mm or None
    preview: DowelPreview
    predictions: tuple = ()     # published-rule predictions (guide_rules.Prediction)


def fit_face(skull: Mesh, landmarks: LandmarkSet, settings: DepthSettings,
             guides: list[Guide] | None, *, use_guides: bool = True,
             ensemble: int = 0, orient: tuple | None = None) -> FitResult:
    """Reconstruct the face as ``workbench reconstruct`` does (guides: the second warp).

    ``guides`` None computes Kähler's classic guides from the skull; a list
    uses the stored guides.  Computed guides that fail their plausibility
    checks are switched off with a warning, as in the command-line job.
    """
    head = reference_head(str(settings.sex or "male"))
    fit = FitSettings(depth=settings)
    chosen: list[Guide] = []
    rejected: list[str] = []

    def guide_fn(skull_h: Mesh, lms_h: LandmarkSet, plan: DowelPlan):  # noqa: ANN202
        if not use_guides:
            return None
        if guides is None:
            tips = {d.code: d.tip for d in plan.active()}
            table = settings.table if not str(settings.table).endswith(".csv") else "ttable_2023"
            chosen.extend(classic_guides(lms_h, skull_h, dowel_tips=tips, sex=settings.sex,
                                         table_id=table))
        else:
            chosen.extend(guides)
        return lambda skin: _guide_targets(chosen, skin, skull_h, lms_h, rejected)

    recon = reconstruct(skull, landmarks, head, settings=fit, guides=guide_fn, hint=orient)
    recon = replace(recon, warnings=recon.warnings + tuple(rejected))
    skull_h = outward(skull.transformed(recon.input_to_head))
    spread = ensemble_spread(recon, head, skull_h, ensemble, settings=fit) if ensemble else None
    try:
        predictions = published_predictions(
            landmarks.transformed(recon.input_to_head), settings.sex, skull=skull_h,
            dowel_tips={d.code: d.tip for d in recon.plan.active()}, problems=[])
    except WorkbenchError:
        predictions = []   # informative only
    active = recon.plan.active()
    preview = DowelPreview(recon.plan, recon.to_input(np.array([d.origin for d in active])),
                           recon.to_input(np.array([d.tip for d in active])),
                           tuple(d.code for d in active))
    for mesh in (recon.face, recon.head.skin):   # drawn smooth-shaded: normals here, not in
        _ = mesh.vertex_normals                   # the GUI thread
    return FitResult(recon, head, skull_h, tuple(chosen), spread, preview, tuple(predictions))


def _guide_targets(guides: list[Guide], skin: dict[str, np.ndarray], skull_h: Mesh,
                   lms_h: LandmarkSet, rejected: list[str]) -> dict[str, np.ndarray]:
    """Guide targets through the job's plausibility filter (the CLI applies the same)."""
    return plausible_guides(guides, skin, skull_h, lms_h, rejected)


def guide_geometry(fit: FitResult) -> tuple[list[tuple[np.ndarray, np.ndarray]], np.ndarray]:
    """Enabled guides as drawable segments and points in the input frame (mm).

    A vertical line (x = value) and a horizontal line (y = value) are drawn
    in the frontal plane just in front of the fitted face (head frame, z =
    the face's front + 5 mm); a lateral point (y, z) sits on the midline.
    """
    skin = fit.recon.head.skin.vertices
    z_front = float(skin[:, 2].max()) + 5.0
    segments, points = [], []
    for g in fit.guides:
        if not g.enabled:
            continue
        if g.kind == "vline":
            a, b = [g.value[0], -75.0, z_front], [g.value[0], 5.0, z_front]
        elif g.kind == "hline":
            a, b = [-35.0, g.value[0], z_front], [35.0, g.value[0], z_front]
        else:
            points.append([0.0, g.value[0], g.value[1]])
            continue
        ends = fit.recon.to_input(np.array([a, b], float))
        segments.append((ends[0], ends[1]))
    pts = fit.recon.to_input(np.array(points, float)) if points else np.zeros((0, 3))
    return segments, pts


def guides_state(guides: list[Guide] | tuple[Guide, ...]) -> list[dict[str, Any]]:
    """Guides as the JSON value stored under the ``guides`` parameter."""
    return guides_to_json(guides)


# ------------------------------------------------------------------ export
def export_results(folder: str | Path, case: Case, fit: FitResult | None, *,
                   formats: tuple[str, ...] = ("ply", "obj", "stl"),
                   report: bool = True, notes: list[str] | None = None) -> dict[str, Path]:
    """Face and head meshes, landmarks (.mrk.json, .fcsv) and the PDF report into ``folder``.

    All in the skull file's frame, mm.  ``face.<ext>`` is the fitted skin's
    face region; ``head/`` holds the whole fitted head: a template pack
    (PLY parts, landmarks, muscles, ``template.json``; readable by
    ``workbench template``) plus every part again in the other formats
    (``head/skull.obj``, ``head/teeth.stl`` ...).  The report is the one
    ``workbench reconstruct`` writes (``reconstruction-report-v1``), without
    pictures.
    """
    from workbench.core.mesh import concatenate
    from workbench.io.markups import write_fcsv, write_mrk_json
    from workbench.io.meshes import write_mesh
    from workbench.io.template_pack import FILES, export_template
    from workbench.services.reconstruction_job import (
        FITTED_HEAD_FRAME_TEXT, head_in_input_frame,
    )

    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    files: dict[str, Path] = {}
    lms = case.landmarks["skull"]
    if len(lms):
        write_mrk_json(out / "skull_landmarks.mrk.json", lms, coordinate_system="RAS")
        write_fcsv(out / "skull_landmarks.fcsv", lms, coordinate_system="RAS")
        files["landmarks_mrk"] = out / "skull_landmarks.mrk.json"
        files["landmarks_fcsv"] = out / "skull_landmarks.fcsv"
    if fit is None:
        return files
    for ext in formats:
        files[f"face_{ext}"] = write_mesh(out / f"face.{ext}", fit.recon.face)
    head = head_in_input_frame(fit.recon)
    for path in export_template(head, out / "head", frame=FITTED_HEAD_FRAME_TEXT):
        files[f"head/{path.name}"] = path
    others = [e for e in formats if e != "ply"]   # the pack already wrote the PLY files
    for name, parts in FILES.items():
        stem, mesh = Path(name).stem, concatenate([head.meshes[p] for p in parts])
        for ext in others:
            files[f"head/{stem}.{ext}"] = write_mesh(out / "head" / f"{stem}.{ext}", mesh)
    if report:
        files.update(_report(out, case, fit, notes or []))
    return files


def _report(out: Path, case: Case, fit: FitResult, notes: list[str]) -> dict[str, Path]:
    from workbench.commands.stack import CommandStack
    from workbench.reporting.report import write_report_json, write_report_pdf
    from workbench.services.case_setup import OpenedCase
    from workbench.services.reconstruction_job import JobSettings, build_report

    s = depth_settings(case)
    settings = JobSettings(table=s.table, sex=str(s.sex), build=s.build,
                           excluded=s.excluded, overrides=dict(s.overrides),
                           examiner=case.meta.examiner)
    opened = OpenedCase(case, CommandStack(case, audit=lambda _r: None), list(notes))
    report = build_report(opened, fit.head, fit.recon, case.landmarks["skull"],
                          list(fit.guides), fit.spread, None, settings)
    return {"report_json": write_report_json(report, out / "report.json"),
            "report_pdf": write_report_pdf(report, out / "report.pdf", base_dir=out)}
