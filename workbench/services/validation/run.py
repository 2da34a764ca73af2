"""Validation on real skull/skin pairs: ``workbench validate MANIFEST.csv --out DIR``.

Units mm; every case in its own input frame (a CT's physical frame).  Each
case of a manifest is reconstructed from its skull by the same job as
``workbench reconstruct``, and scored with the project's metric
(:mod:`workbench.core.face_metric`, ``VALIDATION.md``) beside the uniform
6 mm offset of the same bone (:mod:`workbench.core.offset_surface`) on the
*same* truth points.

Manifest (read by :func:`workbench.services.validation.manifest.read_manifest`;
CSV, one row per case; paths relative to the manifest; any path
may be ``sample:NAME``):

========== ============================================================
column     meaning
========== ============================================================
id         case id (required, unique also without letter case): the name of
           the case's folder in DIR, so letters A-Z a-z, digits, ``-``,
           ``_``, ``.`` and spaces only, starting with a letter or digit
           (:mod:`workbench.core.safe_names`)
skull      skull mesh, or a CT volume (DICOM folder, NIfTI, NRRD, MetaImage)
truth      true skin mesh, or a CT volume (often the same CT as ``skull``)
units      units of mesh files (``mm``, ``cm``, ``m``, ``auto``); default auto
mask       ``none`` | ``clip_patch:MM`` | ``behind_clip:MM`` (see ScoreMask)
anterior   ``x,y,z`` in the file frame (the metric's anterior, and the
           orientation hint); ``superior`` and ``left`` likewise
orient     ``hint`` (default: the reconstruction is told the directions) or
           ``auto`` (it orients the skull from the bone alone; the
           directions only pick the metric's points)
sex        ``female`` | ``male`` (depth table group, built-in head)
build      ``normal`` (= ``average``) | ``slender`` | ``heavy`` (= ``obese``) |
           ``bmi:X`` | k (mean + k SD); the main face, the other two
           build faces are scored beside it
tissue     ``table`` | ``reference`` (see tissue_model)
template   a template pack instead of the built-in head
bone_iso   CT level of the bone surface (default: the preset for the data)
skin_iso   CT level of the skin surface
subject    who the case is (default: its id); cases of one subject (a skull
           and a cut copy of it) never serve as each other's references;
           it names the subject's reference pack folder (the id's rules)
truth_landmarks
           the true skin's soft-tissue landmarks (prn, al, ch, ls, sto, li,
           en, ex ...; any landmark file format, in the truth surface's frame,
           absent ones not in view): adds the per-feature errors of
           :mod:`workbench.services.validation.features` for the face, for the
           same reconstruction without guides (run as the method
           ``no_guides``) and for every guide rule on its own
========== ============================================================

With ``leave_one_out`` a reference pack is built from every subject's skin
and bone (``workbench template build``; cached under ``DIR/references``)
and each case is reconstructed with the packs of *all other* subjects,
their per-vertex median being the face (the consensus), with the tissue
model ``reference`` (the references' own, real tissue) — the case scored is
never among its references.  ``identity`` adds the identity test: the
subject's own pack, tissue model ``reference``, no guides (it isolates the
registration from the tissue model).

The faces scored keep the jaw where the scan has it (``jaw`` ``as-scanned``):
the true skin is the scanned face, mouth open or not, so a face fitted over
the articulated skull would be scored against another pose of the chin.

A truth that is the skull itself (the same mesh file, a file with the same
bytes, or a surface lying within :data:`TRUTH_ON_BONE_MM` of the bone
almost everywhere) would score a reconstruction against bone: the
manifest is refused (same file or bytes) or the case fails (geometry).
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from workbench.core.errors import WorkbenchError
from workbench.core.face_metric import (
    ScoreMask,
    region_labels,
    score,
    scored_vertices,
    unit,
)
from workbench.core.mesh import Mesh
from workbench.core.safe_names import child_path
from workbench.services.validation.manifest import (
    ValidationCase,
    input_digest,
    is_volume,
)
from workbench.services.validation.manifest import (
    read_manifest as read_manifest,  # re-exported: callers import it from here
)

Progress = Callable[[str], None]
OFFSET_MM = 6.0
#: a truth surface with this share of its vertices within TRUTH_ON_BONE_MM of the bone is
#: the bone, not a skin (real soft tissue is 2 mm or more nearly everywhere)
TRUTH_ON_BONE_MM = 1.0
TRUTH_ON_BONE_SHARE = 0.95
#: the skull's box must lie inside the true skin's box (grown by this margin, mm) for at
#: least this share of its volume: a skull outside the skin is in another frame (an LPS
#: file read beside an RAS one turns it 180 degrees about z) or another person's
FRAME_MARGIN_MM = 10.0
FRAME_OVERLAP_SHARE = 0.8


def truth_on_bone(truth: Mesh, bone: Mesh, sample: int = 5000) -> float:
    """Share (0-1) of the true skin's vertices within TRUTH_ON_BONE_MM of the bone (mm)."""
    from workbench.core.spatial import MeshIndex

    points = truth.vertices
    if len(points) > sample:
        points = points[np.linspace(0, len(points) - 1, sample).astype(int)]
    distances = MeshIndex.shared(bone).closest_points(points).distances
    return float(np.mean(distances <= TRUTH_ON_BONE_MM))


def case_surfaces(
    case: ValidationCase, work: Path, progress: Progress | None = None
) -> tuple[Path, Path]:
    """Bone and true-skin mesh files of a case (extracted from CT volumes when needed).

    Extracted surfaces are cached in ``work`` under the volume's SHA-256 and
    level, so a rerun does not extract them again.
    """
    from workbench.io.meshes import write_mesh
    from workbench.services.ct.ct_mesh import mesh_from_ct

    say = progress or (lambda _m: None)
    work.mkdir(parents=True, exist_ok=True)
    out = []
    for path, tissue, iso in (
        (case.skull, "bone", case.bone_iso),
        (case.truth, "skin", case.skin_iso),
    ):
        if not is_volume(path):
            out.append(path)
            continue
        key = hashlib.sha256(f"{input_digest(path)}:{tissue}:{iso}".encode()).hexdigest()[:16]
        target = work / f"{tissue}-{key}.ply"
        if not target.is_file():
            say(f"extracting the {tissue} surface of {path.name} ...")
            result = mesh_from_ct(path, tissue=tissue, iso=iso)
            tmp = target.with_name(target.name + ".part.ply")
            write_mesh(tmp, result.mesh)
            tmp.replace(target)
        out.append(target)
    return out[0], out[1]


@dataclass
class MethodScore:
    """Figures of one surface on a case's scored truth points."""

    name: str
    figures: dict[str, Any]
    regions: dict[str, dict[str, Any]]
    signed_mm: np.ndarray


@dataclass
class CaseResult:
    """Everything ``validate`` measured on one case."""

    case_id: str
    status: str = "ok"
    error: str = ""
    n_points: int = 0
    scores: list[MethodScore] = field(default_factory=list)
    seconds: dict[str, float] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    files: dict[str, Path] = field(default_factory=dict)
    anterior: np.ndarray | None = None
    superior: np.ndarray | None = None
    truth_ids: np.ndarray | None = None
    notes: dict[str, Any] = field(default_factory=dict)

    def score_of(self, name: str) -> MethodScore | None:
        return next((s for s in self.scores if s.name == name), None)


def box_inside_share(inner: Mesh, outer: Mesh, margin_mm: float) -> float:
    """The share of ``inner``'s bounding-box volume inside ``outer``'s box grown by ``margin_mm``."""
    a_lo, a_hi = inner.vertices.min(axis=0), inner.vertices.max(axis=0)
    b_lo, b_hi = outer.vertices.min(axis=0) - margin_mm, outer.vertices.max(axis=0) + margin_mm
    common = np.clip(np.minimum(a_hi, b_hi) - np.maximum(a_lo, b_lo), 0.0, None)
    own = np.maximum(a_hi - a_lo, 1e-9)
    return float(np.prod(common / own))


def _load(path: Path, units: str) -> Mesh:
    from workbench.io.meshes import read_mesh

    return read_mesh(path, units=units if units != "auto" else "auto", kind="skull").mesh


def consensus_face(faces: Sequence[Mesh]) -> tuple[Mesh, np.ndarray]:
    """Per-vertex median of faces of one topology, and the spread between them (mm).

    The spread is the median distance of the members from the median face.
    """
    if not faces:
        raise WorkbenchError("no reconstructions to combine")
    n = faces[0].n_vertices
    if any(f.n_vertices != n or f.n_faces != faces[0].n_faces for f in faces):
        raise WorkbenchError(
            "the reference heads do not share one skin topology (they must "
            "all be built from the same base head): no consensus possible"
        )
    stack = np.stack([f.vertices for f in faces])
    med = np.median(stack, axis=0)
    spread = np.median(np.linalg.norm(stack - med, axis=2), axis=0)
    return Mesh(med, faces[0].faces), spread


def score_surfaces(
    truth: Mesh,
    bone: Mesh,
    surfaces: Sequence[tuple[str, Mesh]],
    anterior: np.ndarray,
    mask: ScoreMask,
    *,
    labels_from: Mesh | None = None,
    vertex_regions: dict | None = None,
    region_names: Sequence[str] = (),
) -> tuple[np.ndarray, list[MethodScore]]:
    """Score every surface on the same truth points (the metric's selection)."""
    ids = scored_vertices(truth, bone, anterior, mask)
    if len(ids) == 0:
        raise WorkbenchError(
            "no truth-skin vertex passes the metric's selection (check the "
            "anterior direction, the frame and the mask)"
        )
    labels = None
    if labels_from is not None and vertex_regions:
        labels = region_labels(truth.vertices[ids], labels_from, vertex_regions, region_names)
    out = []
    for name, surf in surfaces:
        s = score(surf, truth, ids, labels=labels, region_names=region_names)
        out.append(MethodScore(name, s["all"], s["regions"], s["signed_mm"]))
    return ids, out


def in_read_frame(case: ValidationCase) -> ValidationCase:
    """``case`` with its directions (given in the skull file's numbers) turned as the skull
    is read: x and y negated for a mesh tagged ``SPACE=LPS`` (a CT's surface keeps the
    volume's numbers, so its directions stay as given)."""
    from workbench.io.meshes import file_space, to_read_frame

    if case.orientation is None or is_volume(case.skull):
        return case
    space = file_space(case.skull)
    if space != "LPS":
        return case
    turned = tuple(tuple(to_read_frame(v, space).tolist()) for v in case.orientation)
    return replace(case, orientation=turned)


def run_case(
    case: ValidationCase,
    out: Path,
    *,
    templates: Sequence[Path] = (),
    tissue: str | None = None,
    guides: str = "default",
    label: str = "reconstruction",
    progress: Progress | None = None,
) -> tuple[CaseResult, Any]:
    """Reconstruct one case and score it beside the uniform offset (``out``: its folder).

    ``templates`` (two or more): one reconstruction per reference pack and
    their per-vertex median scored.  Returns the result and the job result
    of the (first) reconstruction (for pictures), or None when it failed.
    """
    from workbench.core.offset_surface import uniform_offset
    from workbench.io.meshes import write_mesh
    from workbench.services.templates.regions import REGION_NAMES, face_regions

    case = in_read_frame(case)
    from workbench.services.reconstruction.job import JobSettings, run_reconstruction, write_outputs
    from workbench.services.tissue.tissue_model import TissueSettings

    say = progress or (lambda _m: None)
    res = CaseResult(case.case_id)
    t0 = time.perf_counter()
    try:
        bone_path, truth_path = case_surfaces(case, out / "inputs", say)
        units = "mm" if is_volume(case.skull) else case.units
        bone = _load(bone_path, units)
        truth = _load(truth_path, "mm" if is_volume(case.truth) else case.units)
        inside = box_inside_share(bone, truth, FRAME_MARGIN_MM)
        if inside < FRAME_OVERLAP_SHARE:
            raise WorkbenchError(
                f"the skull ({case.skull.name}) and the true skin ({case.truth.name}) are not in "
                f"the same frame: only {100 * inside:.0f} % of the skull's box lies inside the "
                "skin's, so the skull is not under that skin (a mesh tagged SPACE=LPS, as 3D "
                "Slicer and mesh-from-ct of a DICOM or NRRD CT write it, is read turned into "
                "RAS: give both as CT volumes, or both as meshes tagged alike)"
            )
        on_bone = truth_on_bone(truth, bone)
        if on_bone >= TRUTH_ON_BONE_SHARE:
            raise WorkbenchError(
                f"the true skin ({case.truth.name}) lies on the skull: {100 * on_bone:.0f} % of "
                f"its points are within {TRUTH_ON_BONE_MM:g} mm of the bone, so it is the bone "
                "surface, not a skin (check the truth column, or skin_iso for a CT)"
            )
        res.seconds["surfaces"] = time.perf_counter() - t0
        packs: list[Path | None] = [*templates] or [case.template or None]
        settings = JobSettings(
            units=units,
            sex=case.sex,
            build=case.build,
            orientation=case.orientation if case.orient == "hint" else None,
            tissue=TissueSettings(model=tissue or case.tissue),
            guides=guides,
            # the true skin has the jaw where the scan has it: so does the face scored on it
            jaw="as-scanned",
        )
        faces, first = [], None
        t = time.perf_counter()
        for i, pack in enumerate(packs):
            say(
                f"{case.case_id}: reconstructing"
                + (f" with reference {i + 1}/{len(packs)}" if len(packs) > 1 else "")
                + " ..."
            )
            job = run_reconstruction(bone_path, replace(settings, template=pack))
            folder = child_path(out, label if len(packs) == 1 else f"{label}-ref{i + 1}")
            write_outputs(job, folder)
            faces.append(job.recon.face)  # mm, the skull file's frame
            first = first or job
            res.warnings += [f"{label}: {w}" for w in job.report["warnings"]]
        res.seconds[label] = time.perf_counter() - t
        face = faces[0]
        if len(faces) > 1:
            face, spread = consensus_face(faces)
            write_mesh(out / f"{label}_consensus.ply", face)
            np.save(out / f"{label}_reference_spread.npy", spread)
            res.notes["reference_spread_mm"] = {
                "median": float(np.median(spread)),
                "p90": float(np.percentile(spread, 90)),
            }
        res.files[label] = (
            out / label / "face.ply" if len(faces) == 1 else out / f"{label}_consensus.ply"
        )
        if first is None:  # packs is never empty
            raise RuntimeError(f"{case.case_id}: no reconstruction ran")
        recon = first.recon
        if case.orientation is not None:
            ant = unit(case.orientation[0])
            sup = unit(case.orientation[1])
        else:
            back = np.linalg.inv(recon.input_to_head)[:3, :3]
            ant, sup = unit(back @ [0.0, 0.0, 1.0]), unit(back @ [0.0, 1.0, 0.0])
            res.notes["anterior"] = "from the reconstruction's head frame (no anterior given)"
        res.anterior, res.superior = ant, sup
        t = time.perf_counter()
        offset_file = out / "inputs" / f"offset{OFFSET_MM:g}-{input_digest(bone_path)[:16]}.ply"
        if offset_file.is_file():
            offset = _load(offset_file, "mm")
        else:
            say(f"{case.case_id}: uniform {OFFSET_MM:g} mm offset of the bone ...")
            offset = uniform_offset(bone, OFFSET_MM)
            write_mesh(offset_file, offset)
        res.seconds["offset"] = time.perf_counter() - t
        builds = first.fit.builds if first.fit is not None and len(faces) == 1 else None
        build_surfaces = (
            [(f"{label}_{n}", builds.face(n, recon)) for n in builds.names if n != builds.main]
            if builds is not None
            else []
        )
        regions_v = face_regions(first.template)
        ids, scores = score_surfaces(
            truth,
            bone,
            [(label, face), *build_surfaces, (f"uniform_{OFFSET_MM:g}mm_offset", offset)],
            ant,
            case.mask,
            labels_from=face,
            vertex_regions=regions_v,
            region_names=REGION_NAMES,
        )
        res.truth_ids, res.n_points, res.scores = ids, len(ids), scores
        if builds is not None:
            res.notes["band"] = _band_notes(builds, face, truth.vertices[ids], regions_v)
        res.files["truth"], res.files["bone"] = truth_path, bone_path
        if case.truth_landmarks is not None:
            _feature_notes(res, case, first, label, with_rules=guides != "none")
        res.notes["observed_face_fraction"] = recon.figures.get("face_observed_fraction")
        res.notes["registration"] = {
            k: recon.figures.get("registration", {}).get(k)
            for k in ("orientation", "observed_fraction")
        }
        return res, first
    except WorkbenchError as exc:
        res.status, res.error = "failed", str(exc)
        return res, None
    finally:
        res.seconds["total"] = time.perf_counter() - t0


def _band_notes(builds: Any, face: Mesh, points: np.ndarray, regions_v: dict) -> dict[str, Any]:
    """Coverage of the uncertainty band on the scored true-skin points: the unknown-build
    band, and each build's own band (its face ± what a known build leaves)."""
    from workbench.core.face_metric import region_labels
    from workbench.services.reconstruction.build_faces import band_coverage
    from workbench.services.templates.regions import REGION_NAMES

    labels = region_labels(points, face, regions_v, REGION_NAMES)
    out: dict[str, Any] = {"main": builds.main}
    for name in (None, *builds.names):
        lower, upper = builds.band(name)
        out[name or "unknown"] = band_coverage(face, lower, upper, points, labels, REGION_NAMES)
    return out


def _feature_notes(
    res: CaseResult, case: ValidationCase, job: Any, label: str, *, with_rules: bool
) -> None:
    """Per-feature errors against the true landmarks (``res.notes["features"]``):
    the face's own landmarks and, ``with_rules``, every guide rule on its own."""
    from workbench.services.validation.features import (
        feature_errors,
        read_truth_landmarks,
        rule_landmarks,
    )

    assert case.truth_landmarks is not None
    truth = read_truth_landmarks(case.truth_landmarks)
    recon = job.recon
    truth_h = truth.landmarks.transformed(recon.input_to_head).as_dict()
    feats = {label: feature_errors(recon.head.skin_landmarks.as_dict(), truth_h)}
    if with_rules:
        tips = {d.code: d.tip for d in recon.plan.active()}
        lms_h = recon.landmarks.transformed(recon.input_to_head)
        predicted, why = rule_landmarks(job.skull_h, lms_h, case.sex, tips)
        for rule_id, pts in sorted(predicted.items()):
            errs = feature_errors(pts, truth_h)
            if errs:
                feats[f"rule {rule_id}"] = errs
        res.notes["feature_rules_not_computed"] = why or None
    res.notes["features"] = feats
    res.notes["truth_not_in_view"] = truth.absent or None


def build_references(
    cases: Sequence[ValidationCase], out: Path, *, progress: Progress | None = None
) -> dict[str, Path | str]:
    """A reference pack per subject from its first case's skin and bone (cached).

    The pack is oriented the way the cases that use it are: with the
    manifest's directions for ``orient = hint`` cases, from the bone alone for
    ``orient = auto`` ones (a mirrored file read in its own handedness, as the
    automatic reconstruction reads it; a pack built with the hint's reflection
    would be the subject's mirror image there).  Returns :func:`pack_key` →
    pack folder, or the reason there is none.
    """
    from workbench.services.templates.build import BUILD_VERSION, build_template_pack

    say = progress or (lambda _m: None)
    packs: dict[str, Path | str] = {}
    first_of: dict[str, ValidationCase] = {}
    for case in cases:
        first_of.setdefault(pack_key(case), case)
    out.mkdir(parents=True, exist_ok=True)
    for who, case in first_of.items():
        folder = child_path(out, who)
        stamp = folder / "built_from.json"
        try:
            bone, skin = case_surfaces(case, child_path(out.parent, case.case_id) / "inputs", say)
            key = {
                "skin": input_digest(skin),
                "skull": input_digest(bone),
                "sex": case.sex,
                "build_version": BUILD_VERSION,
                "orient": case.orient,
            }
            if stamp.is_file() and json.loads(stamp.read_text("utf-8")) == key:
                packs[who] = folder
                continue
            say(f"{who}: building a reference head from its own skin and bone ...")
            tmp = child_path(out, f".{who}.part")
            if tmp.exists():  # left by an interrupted run: this cache is ours to rebuild
                import shutil

                shutil.rmtree(tmp)
            units = "mm" if is_volume(case.skull) else case.units
            build_template_pack(
                skin,
                bone,
                tmp,
                sex=case.sex,
                units=units,
                orientation=in_read_frame(case).orientation if case.orient == "hint" else None,
                staged=True,
            )
            (tmp / "built_from.json").write_text(json.dumps(key), "utf-8")
            if folder.exists():
                import shutil

                shutil.rmtree(folder)
            tmp.rename(folder)
            packs[who] = folder
        except WorkbenchError as exc:
            packs[who] = f"no reference pack: {exc}"
    return packs


def pack_key(case: ValidationCase) -> str:
    """The reference pack a case uses: its subject's, oriented the way the case is."""
    return case.who if case.orient == "hint" else f"{case.who}@auto"


def validation_inputs(cases: Sequence[ValidationCase]) -> list[Path]:
    """Every file or folder the cases read (skulls, truths, template packs)."""
    return [p for c in cases for p in (c.skull, c.truth, c.template) if p is not None]


def reuse_caches(previous: Path, fresh: Path) -> None:
    """Copy the extracted surfaces (``CASE/inputs``) and reference packs of a previous run.

    They are keyed by the SHA-256 of their sources, so a rerun does not
    extract or build them again; everything else is made anew.
    """
    import shutil

    if not previous.is_dir():
        return
    folders = [(previous / "references", fresh / "references")]
    folders += [
        (d / "inputs", fresh / d.name / "inputs")
        for d in previous.iterdir()
        if d.is_dir() and not d.name.startswith(".")
    ]
    for source, target in folders:
        if source.is_dir() and not target.exists():
            shutil.copytree(source, target, ignore=shutil.ignore_patterns(".*"))


def run_validation(
    cases: Sequence[ValidationCase],
    out: Path,
    *,
    leave_one_out: bool = False,
    identity: bool = False,
    progress: Progress | None = None,
    on_case: Callable[[CaseResult, Any, str], None] | None = None,
    force: bool = False,
    staged: bool = False,
) -> list[tuple[CaseResult, str]]:
    """Every case with the built-in head, and with the reference library when asked.

    Returns ``(result, method label)`` pairs; ``on_case`` is called after each
    (for pictures) with the job result of the reconstruction.

    ``out`` is written as a whole (:func:`workbench.io.outputs.staged_folder`):
    a folder holding an input is refused, an existing one is replaced only
    with ``force`` (kept as ``DIR.1``; its cached surfaces and reference packs
    are reused) and a failure leaves it as it was.  ``staged=True``: ``out``
    is a fresh folder the caller staged (``workbench validate`` adds its
    tables), written straight into.
    """
    if staged:
        return _run_validation(
            cases,
            Path(out),
            leave_one_out=leave_one_out,
            identity=identity,
            progress=progress,
            on_case=on_case,
        )
    from workbench.io.outputs import relocate, staged_folder

    final = Path(os.path.abspath(out))
    with staged_folder(final, force, validation_inputs(cases)) as temp:
        reuse_caches(final, temp)
        results = _run_validation(
            cases,
            temp,
            leave_one_out=leave_one_out,
            identity=identity,
            progress=progress,
            on_case=on_case,
        )
    for res, _ in results:
        res.files = relocate(res.files, temp, final)
    return results


def _run_validation(
    cases: Sequence[ValidationCase],
    out: Path,
    *,
    leave_one_out: bool,
    identity: bool,
    progress: Progress | None,
    on_case: Callable[[CaseResult, Any, str], None] | None,
) -> list[tuple[CaseResult, str]]:
    out.mkdir(parents=True, exist_ok=True)
    results: list[tuple[CaseResult, str]] = []

    def done(res: CaseResult, job: Any, label: str) -> None:
        results.append((res, label))
        if on_case is not None:
            on_case(res, job, label)

    folders = {c.case_id: child_path(out, c.case_id) for c in cases}
    for case in cases:
        res, job = run_case(case, folders[case.case_id], progress=progress)
        done(res, job, "reconstruction")
        if case.truth_landmarks is not None:  # the guides' effect: the same fit without them
            res, job = run_case(
                case, folders[case.case_id], guides="none", label="no_guides", progress=progress
            )
            done(res, job, "no_guides")
    if leave_one_out or identity:
        packs = build_references(cases, out / "references", progress=progress)
        first_case: dict[str, ValidationCase] = {}
        for c in cases:
            first_case.setdefault(pack_key(c), c)
        for case in cases:
            mine = pack_key(case)
            if leave_one_out:
                others = [
                    p
                    for key, p in packs.items()
                    if isinstance(p, Path) and key != mine and first_case[key].orient == case.orient
                ]
                if others:
                    # the references are real people: their own tissue, not the table's
                    res, job = run_case(
                        case,
                        folders[case.case_id],
                        templates=others,
                        tissue="reference",
                        label="library_loo",
                        progress=progress,
                    )
                    res.notes["references"] = [p.name for p in others]
                else:
                    res = CaseResult(case.case_id, "failed", "no other reference pack")
                    job = None
                done(res, job, "library_loo")
            own = packs.get(mine)
            if identity:
                if isinstance(own, Path):
                    # the identity test isolates the registration: no tissue model, no guides
                    res, job = run_case(
                        case,
                        folders[case.case_id],
                        templates=[own],
                        tissue="reference",
                        guides="none",
                        label="identity",
                        progress=progress,
                    )
                else:
                    res, job = CaseResult(case.case_id, "failed", str(own)), None
                done(res, job, "identity")
    return results
