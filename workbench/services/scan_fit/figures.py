"""The scan fit's report: its figures (``fit_report.json``), notes and self-check.

How far the counted face scan vertices lie from the fitted skin (and, the
other way, the fitted face skin from the scan), what of the face was fitted
and what inferred from the reference, fold-overs and crossings of the fitted
skin (the self-check: :func:`_fit_check`), the fine detail layer's figures,
the landmarks' distances to the scan and to the user's, the tissue depths
reached against the table's, the orientation found, and the estimated skull
against a true bone (:func:`_skull_vs_bone`).  Each ``_…_figures`` function
returns its part of the figures in the report's order.

Units mm; the head frame of the fitted person, settled in the Frankfort frame
of its estimated skull (x to the subject's left, y up, z toward the face,
Frankfort Horizontal at y = 0), except where a docstring says otherwise.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial import cKDTree

from workbench.core.detail_layer import DetailLayer
from workbench.core.face_pose import FacePlacement
from workbench.core.frame import apply_transform
from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh, boundary_loops, concatenate
from workbench.core.rigid_search import PoseResult
from workbench.core.self_intersection import SelfIntersections, self_intersections
from workbench.core.spatial import MeshIndex
from workbench.core.threads import worker_count
from workbench.core.untangle import Untangled
from workbench.model.template import TemplateHead
from workbench.services.scan_fit.placement import _beyond_rim
from workbench.services.scan_fit.settings import (
    BASELINE_DEPTH_MM,
    BONE_PARTS,
    HEAD_WEIGHT,
    INFERRED_NOTE_SHARE,
    MAX_FOLD_OVERS,
    MAX_NEW_CROSSINGS,
    OPENINGS_WARN_SHARE,
    RIM_EXCLUDE_MM,
    SHEET_OUTSIDE_MM,
    SHEET_WARN_SHARE,
    PreparedScan,
)
from workbench.services.scan_fit.sheets import _sheets_outside

if TYPE_CHECKING:
    from workbench.services.templates.build import SkinFit


def _scan_figures(
    scan_h: Mesh,
    fitted: Mesh,
    face: np.ndarray,
    seen: np.ndarray,
    layered: np.ndarray,
    cap_d: np.ndarray,
    target_weights: np.ndarray,
    caps: np.ndarray,
    prepared: PreparedScan,
    warnings: list[str],
) -> tuple[dict, np.ndarray, np.ndarray]:
    """The scan → fitted skin figures: ``(figures, counted, scan_distance)``.

    Counted are the face scan vertices (nearest fitted skin vertex in ``face``)
    away from a hole or field-of-view rim (:data:`RIM_EXCLUDE_MM`, ``cap_d``),
    believed to be the head (``target_weights``), ``seen`` by a scanner and not
    on a thin sheet (``layered`` before the fit, or wholly outside the fitted
    skin: :func:`_sheets_outside`); ``scan_distance`` is each counted vertex's
    distance to the ``fitted`` skin (NaN elsewhere).  A note on sheets goes to
    ``warnings``.
    """
    fig: dict = {}
    _, nearest = cKDTree(fitted.vertices).query(scan_h.vertices, workers=worker_count())
    rim_d = np.full(scan_h.n_vertices, np.inf)
    loops = boundary_loops(scan_h)
    if loops:
        rim_d, _ = cKDTree(scan_h.vertices[np.concatenate(loops)]).query(
            scan_h.vertices, workers=worker_count()
        )
    rim_d = np.minimum(rim_d, cap_d)
    in_face = face[nearest] & (rim_d > RIM_EXCLUDE_MM)
    counted = in_face & (target_weights > HEAD_WEIGHT)
    hidden = in_face & ~seen
    counted &= seen
    fitted_index = MeshIndex(fitted)
    sheet = in_face & seen & layered
    ids = np.flatnonzero(counted & ~sheet)
    d = fitted_index.closest_points(scan_h.vertices[ids]).distances
    # (only a vertex farther than SHEET_OUTSIDE_MM can lie that far outside)
    far = ids[d > SHEET_OUTSIDE_MM]
    sheet[far[_sheets_outside(scan_h, far, fitted_index)]] = True
    d = d[~sheet[ids]]
    counted &= ~sheet
    scan_distance = np.full(scan_h.n_vertices, np.nan)
    scan_distance[counted] = d
    fig["scan_vertices"] = int(scan_h.n_vertices)
    fig["scan_triangles"] = int(scan_h.n_faces)
    fig["scan_preparation"] = prepared.figures
    fig["face_region_vertices"] = int(counted.sum())
    fig["face_region_not_head_vertices"] = int((in_face & ~hidden & ~counted & ~sheet).sum())
    fig["face_region_hidden_vertices"] = int(hidden.sum())
    # (thin sheets over the skin, found before the fit, or wholly outside the fitted skin,
    # found now: a cord, a strap, hair, a fin; not counted)
    fig["face_region_sheet_vertices"] = int(sheet.sum())
    if sheet.sum() > SHEET_WARN_SHARE * max(int(counted.sum()), 1):
        warnings.append(
            f"{int(sheet.sum())} face scan vertices belong to thin sheets over the skin (a "
            "cord or strap over the face, hair, a segmentation fin): the skin was fitted "
            "beneath them and they are not counted in the figures"
        )
    fig["field_of_view_cap_vertices"] = int(caps.sum())
    fig["face_within_1mm_fraction"] = float((d <= 1.0).mean()) if len(d) else 0.0
    fig["face_within_2_5mm_fraction"] = float((d <= 2.5).mean()) if len(d) else 0.0
    fig["face_mean_distance_mm"] = float(d.mean()) if len(d) else None
    fig["face_median_distance_mm"] = float(np.median(d)) if len(d) else None
    return fig, counted, scan_distance


def _skin_figures(
    to_scan: np.ndarray,
    face: np.ndarray,
    facing: np.ndarray,
    on_scan: np.ndarray,
    shown_share: float,
    partial: bool,
    warnings: list[str],
) -> dict:
    """The fitted skin → scan figures and the fitted and inferred shares of the face
    (``figures["inferred"]``); a note on a partial face's inferred part goes to
    ``warnings``."""
    fig: dict = {}
    # the other direction: fitted face skin over believed scan → the scan (a nose longer than
    # the scan's passes the scan → skin test, every scan point lying near its sides)
    back = to_scan[face & facing]
    fig["face_skin_to_scan_mm"] = {
        "n": len(back),
        "mean": float(back.mean()) if len(back) else None,
        "p95": float(np.percentile(back, 95)) if len(back) else None,
        "max": float(back.max()) if len(back) else None,
        "within_2_5mm_fraction": float((back <= 2.5).mean()) if len(back) else 0.0,
    }
    fig["skin_on_scan_fraction"] = float(on_scan.mean())
    fig["face_on_scan_fraction"] = float(on_scan[face].mean())
    # skin over no scan (holes, beyond a partial scan's rim) keeps the reference's shape:
    # inferred, marked per vertex (the pack's region "inferred")
    inferred_share = 1.0 - fig["face_on_scan_fraction"]
    fig["inferred"] = {
        "face_fitted_fraction": round(fig["face_on_scan_fraction"], 4),
        "face_inferred_fraction": round(inferred_share, 4),
        "face_shown_by_scan_fraction": round(shown_share, 4),
        "partial_face": partial,
        "skin_inferred_vertices": int((~on_scan).sum()),
        "marked_as": "region 'inferred' of the pack (template.json): skin vertices over no "
        "scan, whose shape is the reference head's",
    }
    if partial and inferred_share > INFERRED_NOTE_SHARE:
        warnings.append(
            f"the scan shows {100 * shown_share:.0f} % of the face: "
            f"{_fitted_vs_inferred(fig['inferred'])}; the inferred part is the reference "
            "head's shape, not the person's"
        )
    return fig


def _fold_figures(
    fitted: Mesh,
    ref_settled: TemplateHead,
    ref_cross: SelfIntersections,
    untangled: Untangled,
    head: TemplateHead,
) -> dict:
    """Fold-overs and new crossings of the ``fitted`` skin against the reference's
    (``ref_settled``, its own crossings ``ref_cross``), what untangling did, and the
    self-check (:func:`_fit_check`) naming the regions of ``head`` folded over."""
    fig: dict = {}
    ref_n, fit_n = ref_settled.skin.face_normals, fitted.face_normals
    folded = (ref_n * fit_n).sum(axis=1) < 0
    fig["fold_overs"] = int(folded.sum())
    # the reference skin itself has a few crossing sliver triangles at the mouth corners
    # (the lips' seam, 0.02-0.07 mm², ≤ 0.6 mm deep): they turn over easily; the fit must
    # add no fold-over or crossing elsewhere
    seam = np.zeros(fitted.n_faces, bool)
    seam[ref_cross.faces] = True
    fig["fold_overs_outside_mouth_corner_seam"] = int((folded & ~seam).sum())
    fig["untangled"] = {
        "vertices_moved": int(untangled.moved.sum()),
        "rounds": untangled.rounds,
        "crossings_before": untangled.crossings_before,
        "fold_overs_before": untangled.folds_before,
    }
    fitted_x = self_intersections(fitted).pairs
    ref_x = {tuple(p) for p in ref_cross.pairs.tolist()}
    fig["self_intersections"] = {
        "pairs": len(fitted_x),
        "reference_pairs": len(ref_x),
        "new_pairs": sum(tuple(p) not in ref_x for p in fitted_x.tolist()),
    }
    fig["self_check"] = _fit_check(fig, _regions_of(head.regions, fitted.faces[folded & ~seam]))
    return fig


def _detail_section(
    layer: DetailLayer | None,
    fitted: Mesh,
    scan_h: Mesh,
    counted: np.ndarray,
    face: np.ndarray,
    warnings: list[str],
) -> dict:
    """``{"detail": ...}`` of a fit with a detail layer (:func:`_detail_figures`), empty
    without one; a note on scan vertices over the skin's openings goes to ``warnings``."""
    fig: dict = {}
    if layer is not None:
        fig["detail"] = _detail_figures(layer, fitted, scan_h.vertices[counted], face)
        beyond = fig["detail"]["face_over_skin_openings_vertices"]
        if beyond > OPENINGS_WARN_SHARE * max(int(counted.sum()), 1):
            warnings.append(
                f"{beyond} face scan vertices lie over the fitted skin's eye, mouth or nostril "
                "openings, more than 1 mm from it: the scan has a surface there (closed eyes "
                "or lips, a bust's carved eyes) where the reference's lids and lips stay parted"
            )
    return fig


def _landmark_figures(
    skin_lms: LandmarkSet,
    absent_skin: Sequence[str],
    scan_index: MeshIndex,
    landmarks: LandmarkSet | None,
    to_head: np.ndarray,
    head: TemplateHead,
) -> dict:
    """The fitted skin landmarks' distances to the scan (``skin_lms`` before the settling
    move, ``scan_index`` the scan's in that frame) and to the user's ``landmarks`` (scan
    frame, mapped by ``to_head`` onto the settled ``head``)."""
    fig: dict = {}
    present = [c for c in skin_lms.as_dict() if c not in absent_skin]
    # before the settling move (rigid: same distances), with the index built above
    lm_d = scan_index.closest_points(skin_lms.positions_of(present)).distances
    fig["skin_landmark_to_scan_mm"] = {
        "mean": float(lm_d.mean()) if len(lm_d) else None,
        "max": float(lm_d.max()) if len(lm_d) else None,
        "n": len(present),
        "absent": list(absent_skin),
    }
    if landmarks is not None:
        placed = {lm.code: lm.position for lm in landmarks if lm.is_defined}
        common = [c for c in placed if c in skin_lms.as_dict()]
        if common:
            user = apply_transform(to_head, np.array([placed[c] for c in common]))
            gap = np.linalg.norm(user - head.skin_landmarks.positions_of(common), axis=1)
            fig["skin_landmark_to_user_mm"] = {
                "mean": float(gap.mean()),
                "max": float(gap.max()),
                "per_landmark": {c: round(float(g), 2) for c, g in zip(common, gap, strict=True)},
            }
    return fig


def _depth_figures(
    head: TemplateHead,
    pairs: Mapping[str, tuple[str, float]],
    codes: Sequence[str],
    depth: np.ndarray,
    table: str,
    depth_label: str,
    fitted: Mesh,
    face: np.ndarray,
    eye_shift: Mapping[int, np.ndarray],
) -> dict:
    """Skin–skull distances at the paired landmarks ``codes`` against the table's
    ``depth``, face skin vertices inside the skull, and the eyes' moves."""
    fig: dict = {}
    # skin–skull distances at the paired landmarks vs the table
    skull = concatenate([head.meshes[p] for p in ("cranium", "mandible")])
    new_skin_pts = head.skin_landmarks.positions_of([pairs[c][0] for c in codes])
    new_skull_pts = head.skull_landmarks.positions_of(codes)
    dowel = np.linalg.norm(new_skin_pts - new_skull_pts, axis=1)
    to_bone = MeshIndex(skull).closest_points(new_skin_pts).distances
    fig["tissue_depths"] = {
        "table": table,
        "group": depth_label,
        "pairs": len(codes),
        "mean_abs_diff_mm": float(np.abs(dowel - depth).mean()),
        "max_abs_diff_mm": float(np.abs(dowel - depth).max()),
        "mean_abs_diff_to_skull_surface_mm": float(np.abs(to_bone - depth).mean()),
        "per_landmark": {
            c: {"table_mm": round(float(t_), 2), "fitted_mm": round(float(f_), 2)}
            for c, t_, f_ in zip(codes, depth, dowel, strict=True)
        },
    }
    signed = MeshIndex(skull).signed_distance(fitted.vertices[face])
    fig["face_skin_inside_skull_vertices"] = int((signed < 0).sum())
    fig["eye_shift_mm"] = {str(i): round(float(m[2]), 2) for i, m in eye_shift.items()}
    return fig


def _orientation_figures(
    pose: PoseResult,
    mirrored: bool,
    s: float,
    placement: FacePlacement | None,
    fit: SkinFit,
    cut_ears: list[str],
) -> dict:
    """The orientation found (``pose``, scale ``s`` of the scan on the reference, the face
    ``placement``), the scan's share that is not the head and the ears held to the
    reference's shape."""
    fig: dict = {}
    fig["orientation"] = {
        "method": pose.method,
        "handedness": pose.handedness,
        "mirrored": mirrored,
        "reference_scale": round(1 / s, 4),
        # the search's robust cost and scan samples within 2 mm, or after a face placement
        # its face loss and face vertices within 2.5 mm
        "matched_fraction": round(pose.matched_fraction, 3),
        "cost": round(pose.cost, 4),
    }
    if placement is not None:
        fig["orientation"]["face_placement"] = {
            "loss_before": round(placement.start_loss, 4),
            "loss_after": round(min(placement.loss, placement.start_loss), 4),
            "moved": bool(placement.loss < placement.start_loss),
            "face_within_2_5mm_fraction": round(placement.matched_fraction, 3),
            "face_within_5mm_fraction": round(placement.near_fraction, 3),
            "within_5mm_fraction_by_region": {
                k: round(v, 3) for k, v in placement.near_by_group.items()
            },
        }
    fig["scan_not_head_area_fraction"] = round(fit.not_head, 4)
    fig["ears_cut_by_the_scan_rim"] = cut_ears  # held to the reference's shape
    return fig


def _fitted_vs_inferred(inferred: Mapping) -> str:
    """``"62 % of the face fitted to the scan, 38 % inferred from the reference head
    (marked)"`` from ``figures["inferred"]``."""
    return (
        f"{100 * inferred['face_fitted_fraction']:.0f} % of the face fitted to the scan, "
        f"{100 * inferred['face_inferred_fraction']:.0f} % inferred from the reference head "
        "(marked)"
    )


def fitted_vs_inferred(figures: Mapping) -> str | None:
    """The fit's one line on what of the face was fitted and what inferred (None for
    figures of a fit before the inferred part was recorded)."""
    inferred = figures.get("inferred")
    return None if not inferred else _fitted_vs_inferred(inferred)


def _fit_check(fig: Mapping, folded_at: str = "") -> dict:
    """The fit's self-check: ``{"outcome": "confident" | "check", "reasons": [...]}``.

    Fold-overs outside the reference's mouth-corner seam or new crossings of the
    fitted skin (:data:`MAX_FOLD_OVERS`, :data:`MAX_NEW_CROSSINGS`; real scans
    give none) mean the skin was pulled onto something that is not one face
    (two heads through each other, a wrong pose) or folded where it is (an
    ear): the pack is written, but the command exits with ``EXIT_CHECK``.
    ``folded_at`` names the regions where the fold-overs are.
    """
    reasons = []
    folds = int(fig["fold_overs_outside_mouth_corner_seam"])
    if folds > MAX_FOLD_OVERS:
        where = f" ({folded_at})" if folded_at else ""
        reasons.append(
            f"{folds} triangles of the fitted skin are turned over against the "
            f"reference's{where}: a fit onto one face gives none; look at the skin there "
            "(many, all over, mean the skin was pulled onto surfaces that are not one "
            "face: two heads, a wrong pose)"
        )
    crossings = int(fig["self_intersections"]["new_pairs"])
    if crossings > MAX_NEW_CROSSINGS:
        reasons.append(
            f"the fitted skin crosses itself in {crossings} triangle pairs the reference "
            f"does not (a fit onto one face gives none; over {MAX_NEW_CROSSINGS} means a "
            "skin pulled through itself)"
        )
    return {"outcome": "check" if reasons else "confident", "reasons": reasons}


def _regions_of(regions: Mapping[str, np.ndarray], faces: np.ndarray) -> str:
    """``"ear_r 5, upper_lip 2"``: the named regions (not the whole face) holding all
    three corners of ``faces``, with counts, most first."""
    counts: dict[str, int] = {}
    for name, ids in regions.items():
        if name in ("face", "inferred") or not len(faces):
            continue
        inside = np.zeros(int(max(faces.max(), np.max(ids, initial=0))) + 1, bool)
        inside[np.asarray(ids, dtype=np.int64)] = True
        n = int(inside[faces].all(axis=1).sum())
        if n:
            counts[name] = n
    return ", ".join(f"{k} {n}" for k, n in sorted(counts.items(), key=lambda kv: -kv[1]))


def _detail_figures(
    detail: DetailLayer, fitted: Mesh, counted: np.ndarray, face: np.ndarray
) -> dict:
    """The detail layer's figures: the same scan vertices' distances to the detailed skin,
    turned triangles and crossings it added to the undisplaced subdivided skin."""
    smooth = detail.smooth_surface(fitted.vertices)
    detailed = detail.apply(fitted.vertices)
    closest = MeshIndex(detailed).closest_points(counted)
    d = closest.distances
    beyond = _beyond_rim(detailed, closest.face_ids, closest.barycentric) & (d > 1.0)
    turned = (detailed.face_normals * smooth.face_normals).sum(axis=1) <= 0.0
    # the fine vertices over the face: most of their subdivision weight on coarse face
    # vertices (one sparse product; a row-wise argmax took ~0.35 s)
    on_face = np.asarray(detail.matrix @ face.astype(float)).ravel() > 0.5
    disp = np.abs(detail.displacement[on_face])
    return {
        "levels": detail.levels,
        "fine_vertices": int(detailed.n_vertices),
        "fine_triangles": int(detailed.n_faces),
        "face_within_1mm_fraction": float((d <= 1.0).mean()) if len(d) else 0.0,
        "face_within_2_5mm_fraction": float((d <= 2.5).mean()) if len(d) else 0.0,
        "face_mean_distance_mm": float(d.mean()) if len(d) else None,
        # scan vertices over the skin's own openings (the palpebral fissures, the mouth
        # slit, nostrils): closed eyes on a CT have no skin to meet, and the figures
        # without them say how well the skin there is fitted
        "face_over_skin_openings_vertices": int(beyond.sum()),
        "face_within_2_5mm_fraction_off_openings": (
            float((d[~beyond] <= 2.5).mean()) if (~beyond).any() else 0.0
        ),
        "face_observed_fraction": float(detail.observed[on_face].mean()),
        "face_displacement_mm": {
            "mean_abs": float(disp.mean()),
            "p95_abs": float(np.percentile(disp, 95)),
            "max_abs": float(disp.max()),
        },
        "fold_overs": int(turned.sum()),
        # checked on the whole detailed skin by build_detail's last round
        "new_crossings": detail.new_crossings,
    }


def _skull_vs_bone(head: TemplateHead, bone: Mesh, to_head: np.ndarray, face: np.ndarray) -> dict:
    """Estimated skull (face region) vs the true bone: mean |d| and % within 2.5 mm, and the
    same for the uniform baseline (head frame, mm).

    The face-region skull vertices: cranium and mandible vertices whose
    nearest fitted-skin vertex lies in the face region.  The baseline is the
    face → skull counterpart of VALIDATION.md's uniform offset: the fitted
    face skin moved :data:`BASELINE_DEPTH_MM` inward along its normals, its
    vertices scored against the same bone (other points than the skull's:
    the nose and lips count against it).
    """
    est = concatenate([head.meshes[p] for p in BONE_PARTS])
    bone_h = Mesh(apply_transform(to_head, bone.vertices), bone.faces)
    _, nearest = cKDTree(head.skin.vertices).query(est.vertices)
    sel = face[nearest]
    index = MeshIndex(bone_h)
    d = index.closest_points(est.vertices[sel]).distances
    skin = head.skin
    inner = skin.vertices[face] - BASELINE_DEPTH_MM * skin.vertex_normals[face]
    d0 = index.closest_points(inner).distances
    return {
        "face_skull_vertices": int(sel.sum()),
        "mean_abs_mm": float(d.mean()) if len(d) else None,
        "median_abs_mm": float(np.median(d)) if len(d) else None,
        "within_2_5mm_fraction": float((d <= 2.5).mean()) if len(d) else 0.0,
        "uniform_offset_baseline": {
            "depth_mm": BASELINE_DEPTH_MM,
            "face_skin_vertices": int(len(d0)),
            "mean_abs_mm": float(d0.mean()) if len(d0) else None,
            "within_2_5mm_fraction": float((d0 <= 2.5).mean()) if len(d0) else 0.0,
        },
    }
