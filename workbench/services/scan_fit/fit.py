"""Fit the built-in reference head to a range scan of a living face (issue 13, Kähler §8.4).

A scan (structured light, photogrammetry, a CT's skin surface) shows skin
only, with holes (hair, under the chin, the ears, nostrils), noise and
anatomy that is not the head (shoulders, a head holder).  We adapt the
reference head to it and keep its topology, landmarks, muscles and inner
parts, so the result is a template pack like ``workbench template build``
writes:

1. **Orientation and size** (:func:`workbench.core.rigid_search.search_pose`)
   of the reference *skin* on the scan: from an orientation hint, from three
   or more skin landmarks the user placed (input frame; their handedness
   decides a mirrored scan), or by the multi-start search.  The search scores
   scan samples against the reference robustly (a missing part costs nothing,
   shoulders and hair saturate).  On a bust most of the scan is not a face
   (a crown, shoulders, a plinth), so without landmarks the reference *face*
   is then laid on the scan from that pose
   (:func:`workbench.core.face_pose.place_face`: face → scan, exact closest
   points), and a scan on which it finds too little of its shape is refused.
   The head frame keeps the person's size: the reference is scaled, not the
   scan.  A *partial* face (a CT that ends at the upper teeth) is laid with
   the part the scan covers alone (the rest lies beyond its rim:
   :func:`_uncovered`), and accepted when that part is at least
   :data:`~workbench.core.limits.MIN_SCAN_FACE_COVERAGE` of the face with the
   nose and its tip, matching well; the skin over no scan is inferred from
   the reference and marked (the pack's region ``inferred``,
   ``figures["inferred"]``).  A ``--bone`` away from the scan or on its skin,
   and two surfaces through each other, are refused before the fit; a fit
   with fold-overs asks for a check (``figures["self_check"]``, exit 3).
2. **Skin** (:func:`workbench.services.templates.build.fit_skin`): the scaled
   reference skin registered onto the scan, per-part affine stage then coarse
   to fine (:data:`SCAN_LEVELS`); hole and field-of-view rims fade out, thin
   sheets lying over more of the scan (a cord or strap over the face, hair:
   :func:`_sheets_over_scan`) are not matched, skin over no scan keeps the
   reference's shape (membrane, no jumps), the ears
   follow the scan's; crossings and fold-overs the fit leaves are smoothed
   away locally toward the reference's shape
   (:func:`workbench.core.untangle.untangle`).  Skin landmarks ride on the
   skin (same triangle, same barycentric weights); those over no scan are
   marked absent.
3. **The inside follows** (Kähler §8.3.2): at each paired skin/skull landmark
   of the depth table (chosen sex and build) the skull landmark's target is
   the fitted skin landmark moved *inward* along the skin normal by the
   table depth.  A regularised thin-plate spline
   (:func:`workbench.core.tps.fit_warp`) from the carried skull landmarks to
   these targets moves cranium, mandible, teeth, tongue and eyes (the eyes
   rigidly with their centres, then behind the fitted lids); the skin stays
   as fitted.  Muscles are skin triangles + barycentric weights, so they
   ride on the fitted skin without change.
4. **Frame**: the result is settled in the Frankfort frame of its estimated
   skull landmarks (porions, orbitales), like a built template.
5. **Fine detail** (:mod:`workbench.core.detail_layer`, optional): the
   animatable skin's ~4 mm edges cannot hold lid creases, lip borders or
   nostril rims, so the scan's detail is kept as a displaced subdivision
   surface (Lee, Moreton & Hoppe 2000) over the fitted skin Loop-subdivided
   twice (77 358 vertices): one scalar per fine vertex along its normal,
   fading to zero over holes and kept off the ears.  The same layer
   re-details the skin after it is animated or aged.

Units mm; head frame of the *fitted person* (x to the subject's left,
x = 0 midsagittal, y up, z toward the face, Frankfort Horizontal at y = 0).
``ScanFit.input_to_head`` maps the scan file's coordinates (after units)
into it.
"""

from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from os import PathLike
from pathlib import Path
from typing import TYPE_CHECKING, TypeVar

import numpy as np
from scipy.spatial import cKDTree

from workbench.core.data_paths import DEFAULT_DEPTH_TABLE
from workbench.core.detail_layer import DetailLayer, build_detail
from workbench.core.errors import InputError, WorkbenchError
from workbench.core.face_pose import FacePlacement, place_face
from workbench.core.frame import apply_transform
from workbench.core.landmarks import LandmarkSet
from workbench.core.limits import MIN_SCAN_FACE_COVERAGE, MIN_SCAN_NOSE_COVERAGE
from workbench.core.mesh import Mesh, boundary_loops, concatenate
from workbench.core.nonrigid import AFFINE_ROUNDS, Level, smoothstep
from workbench.core.normals import normals_within_radius
from workbench.core.raycast import RayCaster
from workbench.core.rigid_search import PoseResult
from workbench.core.self_intersection import self_intersections
from workbench.core.spatial import MeshIndex
from workbench.core.threads import worker_count
from workbench.core.tps import fit_warp
from workbench.core.untangle import untangle
from workbench.core.visibility import field_of_view_caps, seen_from_outside
from workbench.model.template import TemplateHead

Progress = Callable[[str], None]

#: fewer triangles than this is not a scan of a face
MIN_SCAN_TRIANGLES = 1000
#: largest side of a face, head or head-and-shoulders (bust) scan, mm
SCAN_EXTENT_MM = (60.0, 700.0)
#: the skin registration's levels on a scan: the template build's, then finer
SCAN_LEVELS = (
    Level(24.0, 1.0, 8.0, 6),
    Level(14.0, 0.6, 5.0, 6),
    Level(8.0, 0.4, 3.0, 6),
    Level(5.0, 0.3, 2.0, 6),
    Level(3.5, 0.25, 1.5, 6),
    Level(2.5, 0.2, 1.0, 6),
)
#: radius over which the skin normal at a landmark is averaged (mm)
NORMAL_RADIUS_MM = 6.0
#: regulariser of the inner parts' thin-plate spline
INNER_SMOOTHING = 2.0
#: scan vertices this close to a hole or field-of-view rim are not counted (mm)
RIM_EXCLUDE_MM = 4.0
#: a scan vertex counts as "the head" in the report when its belief exceeds this
HEAD_WEIGHT = 0.5
#: a fitted skin vertex is "on the scan" when the scan surface is this close (mm) ...
#: (a miss of the fit, e.g. a sharper nose tip than a coarse scan's, is not a hole:
#: holes are told by the rim-faded belief of the closest point)
ON_SCAN_MM = 5.0
#: ... at a point of belief above HEAD_WEIGHT facing the same side (creases at the mouth
#: corners and canthi turn the normals of a coarse scan by up to ~90°)
ON_SCAN_COS = 0.0
#: a second connected piece this large (area fraction of the largest) and this far away
#: (mm, between centroids) is a second head or body, not a stray fragment
SECOND_PIECE = (0.4, 150.0)
#: below this fraction of the reference face supported by the scan, it is not a face
MIN_FACE_SUPPORT = 0.6
#: ... nor below this fraction of the rigidly placed reference face within 5 mm of it
#: (:func:`workbench.core.face_pose.place_face`), or of its nose while the face's is weak
MIN_PLACED_FACE = 0.5
MIN_PLACED_NOSE = 0.45
#: ... the nose's share decides only while the face's is below this
NOSE_DOUBT_FACE = 0.6
#: a reference face vertex whose closest scan point lies beyond the scan's rim (an open
#: edge, a field-of-view lid) farther than this (mm) is not covered by the scan: part of a
#: partial face the scan does not show, not a mismatch of its shape
COVER_MM = 5.0
#: a scan covering at least this share of the reference face is a whole face: the face
#: placement's verdict on it stands (a ball, a hand: no rim to end the face at)
WHOLE_FACE_COVERAGE = 0.9
#: a partial face is laid on the scan from this many of the search's poses
PARTIAL_STARTS = 3
#: ... each scored by its face loss over the covered vertices and this cost for each
#: uncovered one (below a mismatch's 1: a pose sliding the face off the scan gains nothing)
UNCOVERED_COST = 0.5
#: a fit with more fold-overs (outside the reference's mouth-corner seam) or new
#: self-crossings than this asks for a check (exit 3); real scans give 0
MAX_FOLD_OVERS = 4
MAX_NEW_CROSSINGS = 4
#: a partial face (WHOLE_FACE_COVERAGE) must match over more of the part it shows than a
#: whole face over all of it (MIN_FACE_SUPPORT): less of it fixes the pose (the headsq
#: skin cut below the nose or at the teeth 0.78-0.83; cut at the orbits, the face laid a
#: nose lower, 0.64)
MIN_PARTIAL_SUPPORT = 0.7
#: the skin landmark a partial face must show
NOSE_TIP = "prn"
#: a partial face's inferred share is noted above this
INFERRED_NOTE_SHARE = 0.05
#: an ear with more than this share of its vertices beyond the scan's rim is cut by it,
#: and held to the reference's shape instead of following the scan's
EAR_REGIONS = ("ear_l", "ear_r")
CUT_EAR_SHARE = 0.1
#: the scan crossing itself in this many triangle pairs, spread over this length (mm), is
#: two surfaces through each other (two heads, a head merged twice); real scans give 0
SHELL_CROSSINGS = (40, 60.0)
#: --bone must overlap the scan: at least this share of it within BONE_BOX_MARGIN_MM of the
#: scan's bounding box (a partial face scan leaves the jaw's bone below it)
BONE_IN_BOX = 0.25
BONE_BOX_MARGIN_MM = 20.0
#: ... and lie under the skin, not on it: a --bone with this share of its vertices within
#: BONE_ON_SKIN_MM of the scan is the skin itself (real bone: the thinnest facial tissue
#: is ~3 mm)
BONE_ON_SKIN = 0.5
BONE_ON_SKIN_MM = 1.0
#: a placed face with a loss below this sits well (the test skins 0.02-0.13; real scans
#: 0.25-0.45, a wrong pose's 0.45-0.65): the search's runners-up are then not tried
CLEAR_FACE_LOSS = 0.2
#: texture atlas side (texels) of a coloured scan's fitted skin: each texel samples the
#: scan (2048 took ~21-28 s on a 300k-triangle scan, 1024 ~4 s)
COLOUR_ATLAS_SIZE = 1024
INNER_PARTS = ("cranium", "mandible", "upper_teeth", "lower_teeth", "tongue", "eyes")
BONE_PARTS = ("cranium", "mandible")
#: recorded in the provenance; 2: the fine detail layer over the subdivided skin
FIT_VERSION = 2
#: a note when this share of the counted face scan vertices lies over the skin's openings
OPENINGS_WARN_SHARE = 0.004
#: a scan sheet at most this thick (mm, along its inward normal to where the ray leaves
#: it) is not the face's skin (a cord or strap over the face, a hair strand, a segmentation
#: fin; the VHP female and male CTs have a ~5 mm cord around the face, lifted ~4 mm off
#: the female's forehead, its top ~9 mm out) when, before the fit, more of the scan lies
#: beneath it within SHEET_GAP_MM (the skin under the cord; not where the reference has
#: its own thin parts over air: SHEET_PARTS), or when, after it, it lies wholly
#: SHEET_OUTSIDE_MM outside the fitted skin (at both of its sides: a fin).  Chosen on the
#: VHP female skin, judged on the other cases
SHEET_MAX_MM = 6.0
SHEET_GAP_MM = 12.0
SHEET_OUTSIDE_MM = 1.0
#: the reference's regions whose skin is a thin sheet over air (the alae over the
#: nostrils, the lips at their slit, the lids, the ears' folds)
SHEET_PARTS = (
    "nose",
    "upper_lip",
    "lower_lip",
    "eyelid_upper_l",
    "eyelid_upper_r",
    "eyelid_lower_l",
    "eyelid_lower_r",
    "ear_l",
    "ear_r",
)
#: a note when this share of the face scan vertices are such sheets
SHEET_WARN_SHARE = 0.002


@dataclass(frozen=True)
class ScanFit:
    """The reference head fitted to a scan.

    Attributes
    ----------
    head : TemplateHead
        In the fitted person's head frame, mm.
    input_to_head : (4, 4)
        Scan coordinates (mm) → head frame (a reflection when ``mirrored_input``).
    skin_on_scan : (n_skin,) bool
        Skin vertices the scan supports (the rest keep the reference's shape).
    figures : dict
        The fit report (distances mm, fractions, seconds).
    scan : Mesh, optional
        The scan in the head frame (mm), for pictures and colour transfer.
    scan_distance : (n_scan,) float, optional
        Each scan vertex's distance to the fitted skin (mm); NaN where it is
        not counted in the face-region figures (outside the face, near a
        hole or field-of-view rim, or not the head).
    detail : DetailLayer, optional
        The scan's fine detail over the Loop-subdivided fitted skin
        (:mod:`workbench.core.detail_layer`); ``detail.apply(head.skin.vertices)``
        is the detailed skin, and re-details an animated or aged skin too.
    """

    head: TemplateHead
    input_to_head: np.ndarray
    mirrored_input: bool
    skin_on_scan: np.ndarray
    figures: dict
    warnings: tuple[str, ...] = ()
    scan: Mesh | None = None
    scan_distance: np.ndarray | None = None
    detail: DetailLayer | None = None

    def to_input(self, points: np.ndarray) -> np.ndarray:
        """Head-frame points back in the scan's coordinates."""
        return apply_transform(np.linalg.inv(self.input_to_head), np.reshape(points, (-1, 3)))


@dataclass(frozen=True)
class PreparedScan:
    """A scan file's mesh made ready to fit (:func:`prepare_scan`; the file's frame, mm).

    Attributes
    ----------
    mesh : Mesh
        The working scan: coincident vertices welded, zero-area and repeated
        triangles dropped, distant stray pieces left out, each piece wound
        consistently and outward, simplified to at most
        :data:`~workbench.core.limits.SCAN_WORK_TRIANGLES`.
    vertex_of : (n_file_vertices,) int, optional
        The working vertex of each vertex of the file's mesh (-1: left out);
        None when the scan was simplified (its vertices are new).
    face_source : (n_faces,) int, optional
        The file's triangle of each working triangle (its corners possibly in
        reverse order); None when simplified.
    notes : tuple of str
        What the user is told (pieces left out, simplification).
    repairs : tuple of str
        Harmless repairs made silently (for the report).
    file_triangles : int
        Triangles in the file's mesh.
    """

    mesh: Mesh
    vertex_of: np.ndarray | None
    face_source: np.ndarray | None
    notes: tuple[str, ...]
    repairs: tuple[str, ...]
    file_triangles: int

    @property
    def figures(self) -> dict:
        """The preparation for ``fit_report.json``."""
        return {
            "file_triangles": self.file_triangles,
            "working_triangles": int(self.mesh.n_faces),
            "simplified": self.vertex_of is None,
            "repairs": list(self.repairs),
            "notes": list(self.notes),
        }


def check_scan_mesh(mesh: Mesh, source: str | PathLike[str]) -> None:
    """Refuse a point cloud, a few triangles, non-finite vertices, two bodies or a size not a
    head's (:func:`prepare_scan`, its result not kept)."""
    prepare_scan(mesh, source)


def _refuse_not_a_scan(mesh: Mesh, source: str | PathLike[str]) -> None:
    from workbench.core.limits import SCAN_MAX_TRIANGLES

    if mesh.n_faces == 0:
        raise InputError(
            source,
            f"is a point cloud ({mesh.n_vertices} points, no triangles); a scan must be a "
            "triangle surface",
            "mesh it first (e.g. Poisson surface reconstruction in MeshLab or CloudCompare)",
        )
    if mesh.n_faces < MIN_SCAN_TRIANGLES:
        raise InputError(
            source,
            f"has only {mesh.n_faces} triangles; a face scan has thousands "
            f"(at least {MIN_SCAN_TRIANGLES})",
            "is this the right file?",
        )
    if mesh.n_faces > SCAN_MAX_TRIANGLES:
        raise InputError(
            source,
            f"has {mesh.n_faces:,} triangles, more than the {SCAN_MAX_TRIANGLES:,} the "
            "workbench reads from a scan",
            "simplify it first (e.g. 'workbench mesh decimate', or Quadric Edge Collapse "
            "Decimation in MeshLab) to a few million triangles or fewer",
        )
    bad = int((~np.isfinite(mesh.vertices)).any(axis=1).sum())
    if bad:
        raise InputError(source, f"{bad} vertices have NaN or infinite coordinates")


def prepare_scan(
    mesh: Mesh, source: str | PathLike[str], progress: Progress | None = None
) -> PreparedScan:
    """The scan made ready to fit, or an :class:`InputError` naming ``source``.

    Refused: a point cloud, too few or too many triangles
    (:data:`~workbench.core.limits.SCAN_MAX_TRIANGLES`), non-finite vertices,
    two bodies (a second piece of similar size far away), or a size not a
    head's (:data:`SCAN_EXTENT_MM`, measured on what is kept).  Repaired
    silently (vectorised, no pairwise distances; a 5 M-triangle soup in a few
    seconds):

    * coincident vertices welded (:func:`~workbench.core.repair.weld_coincident_vertices`
      on a grid of :data:`~workbench.core.limits.SCAN_WELD_FRACTION` of the
      diagonal): a triangle soup becomes a surface again;
    * triangles with a repeated corner, zero area
      (:data:`~workbench.core.limits.SCAN_SLIVER_AREA_FRACTION`) or repeating
      another's corners dropped: their normals are noise;
    * each piece wound consistently and outward
      (:func:`~workbench.core.repair.consistent_outward_winding`).

    Said (``notes``): a scan with more than
    :data:`~workbench.core.limits.SCAN_WORK_TRIANGLES` triangles is simplified
    to that many (quadric decimation, ``fast_simplification``); pieces more
    than :data:`~workbench.core.limits.SCAN_STRAY_PIECE_MM` from the largest are
    left out.
    """
    from workbench.core.limits import (
        SCAN_SLIVER_AREA_FRACTION,
        SCAN_STRAY_PIECE_MM,
        SCAN_WELD_FRACTION,
        SCAN_WORK_TRIANGLES,
    )
    from workbench.core.mesh import degenerate_face_mask, duplicate_face_mask
    from workbench.core.repair import consistent_outward_winding, weld_coincident_vertices

    say = progress or (lambda _m: None)
    _refuse_not_a_scan(mesh, source)
    n_file = mesh.n_faces
    if n_file > SCAN_WORK_TRIANGLES:
        say(f"preparing the scan's {n_file:,} triangles ...")
    used = np.bincount(mesh.faces.ravel(), minlength=mesh.n_vertices) > 0
    diag = float(np.linalg.norm(np.ptp(mesh.vertices[used], axis=0)))
    repairs: list[str] = []
    notes: list[str] = []
    welded, vertex_of_opt = weld_coincident_vertices(mesh, SCAN_WELD_FRACTION * max(diag, 1e-9))
    vertex_of: np.ndarray | None = vertex_of_opt
    work = welded.mesh
    if welded.changed:
        repairs.append(welded.message)
    face_source: np.ndarray | None = np.arange(work.n_faces)
    if work.n_faces > SCAN_WORK_TRIANGLES:
        # (its slivers and repeats go with the simplification's own)
        say(f"simplifying the scan from {work.n_faces:,} to {SCAN_WORK_TRIANGLES:,} triangles ...")
        work = _simplified(work, SCAN_WORK_TRIANGLES, SCAN_SLIVER_AREA_FRACTION * diag**2)
        vertex_of = face_source = None
        notes.append(
            f"the scan's {n_file:,} triangles were simplified to {work.n_faces:,} for the fit "
            "(quadric decimation, ~{:.1f} mm edges)".format(_mean_edge(work))
        )
    else:
        bad = degenerate_face_mask(work, SCAN_SLIVER_AREA_FRACTION * diag**2)
        bad |= duplicate_face_mask(work)
        if bad.any():
            repairs.append(
                f"dropped {int(bad.sum())} triangles of zero area, with a repeated corner or "
                "repeating another's corners"
            )
            work, vertex_of, face_source = _keep_triangles(work, ~bad, vertex_of, face_source)
    if work.n_faces < MIN_SCAN_TRIANGLES:
        raise InputError(
            source,
            f"has only {work.n_faces} triangles of non-zero area; a face scan has thousands "
            f"(at least {MIN_SCAN_TRIANGLES})",
            "is this the right file?",
        )
    keep, said = _one_body(work, source, SCAN_STRAY_PIECE_MM)
    if said:
        notes.append(said)
        work, vertex_of, face_source = _keep_triangles(work, keep, vertex_of, face_source)
    wound, _ = consistent_outward_winding(work)
    if wound.changed:
        repairs.append(wound.message)
        work = wound.mesh
    extent = np.ptp(work.vertices, axis=0)
    lo, hi = SCAN_EXTENT_MM
    largest = float(extent.max())
    if not lo <= largest <= hi:
        raise InputError(
            source,
            f"is {' x '.join(f'{v:.4g}' for v in extent)} mm (largest side {largest:.4g} mm); "
            f"a face, head or bust scan is {lo:.0f}-{hi:.0f} mm",
            "check --units / --scale: the file's numbers are not in the units given",
        )
    return PreparedScan(work, vertex_of, face_source, tuple(notes), tuple(repairs), n_file)


def _keep_triangles(
    mesh: Mesh, keep: np.ndarray, vertex_of: np.ndarray | None, face_source: np.ndarray | None
) -> tuple[Mesh, np.ndarray | None, np.ndarray | None]:
    """``mesh`` with only the triangles ``keep`` and the vertices they use; the file maps
    carried along."""
    faces = mesh.faces[keep]
    used = np.zeros(mesh.n_vertices, bool)
    used[faces.ravel()] = True
    new = np.cumsum(used) - 1
    out = Mesh(mesh.vertices[used], new[faces])
    if vertex_of is not None:
        ok = vertex_of >= 0
        ok[ok] = used[vertex_of[ok]]
        vertex_of = np.where(ok, new[np.maximum(vertex_of, 0)], -1)
    if face_source is not None:
        face_source = face_source[keep]
    return out, vertex_of, face_source


def _simplified(mesh: Mesh, target: int, sliver_mm2: float) -> Mesh:
    """``mesh`` decimated to about ``target`` triangles, without zero-area (below
    ``sliver_mm2``) or repeated triangles.

    Quadric decimation (``fast_simplification``) costs ~0.2 s per 100k input
    triangles and more on millions, so a scan over :data:`_CLUSTER_ABOVE` times
    ``target`` is first clustered on a grid (its vertices in one cell merged to
    their mean: one ``np.unique``) to about that many, and decimated from there.
    Triangles the simplification made cross others are dropped.
    """
    import fast_simplification

    from workbench.core.mesh import degenerate_face_mask, duplicate_face_mask
    from workbench.core.repair import weld_coincident_vertices

    if mesh.n_faces > _CLUSTER_ABOVE * target:
        # a grid cell of side h holds ~one vertex of a surface of area A meshed with
        # A / h² vertices, ~2 A / h² triangles
        cell = float(np.sqrt(2.0 * mesh.area / (_CLUSTER_ABOVE * target)))
        clustered, vertex_of = weld_coincident_vertices(mesh, cell)
        if clustered.changed:
            count = np.bincount(vertex_of, minlength=clustered.mesh.n_vertices)[:, None]
            mean = np.stack(
                [np.bincount(vertex_of, mesh.vertices[:, i], len(count)) for i in range(3)], 1
            )
            mesh = Mesh(mean / np.maximum(count, 1), clustered.mesh.faces)
    bad = degenerate_face_mask(mesh, sliver_mm2) | duplicate_face_mask(mesh)
    if bad.any():
        mesh = _keep_triangles(mesh, ~bad, None, None)[0]
    if mesh.n_faces > target:
        points, faces = fast_simplification.simplify(
            mesh.vertices.astype(np.float32),
            mesh.faces.astype(np.int32),
            target_reduction=1.0 - target / mesh.n_faces,
        )
        mesh = Mesh(np.asarray(points, np.float64), np.asarray(faces, np.int64))
    bad = degenerate_face_mask(mesh, sliver_mm2) | duplicate_face_mask(mesh)
    mesh = _keep_triangles(mesh, ~bad, None, None)[0]
    # the collapses can push a few triangles through others (VHF skin, 5.3 M → 300k: ~80
    # crossing pairs, none in the file): they are dropped, small holes the fit skips, so
    # the simplification's own crossings are not taken for two surfaces through each other
    crossing = self_intersections(mesh).faces
    if len(crossing):
        keep = np.ones(mesh.n_faces, bool)
        keep[crossing] = False
        mesh = _keep_triangles(mesh, keep, None, None)[0]
    return mesh


#: a scan over this many times the working size is clustered on a grid before the
#: quadric decimation (which took ~250 s for 5.3 M triangles, ~1 s for 0.6 M)
_CLUSTER_ABOVE = 3


def _mean_edge(mesh: Mesh) -> float:
    e = mesh.edges_unique
    return float(np.linalg.norm(mesh.vertices[e[:, 0]] - mesh.vertices[e[:, 1]], axis=1).mean())


def _one_body(mesh: Mesh, source: str | PathLike[str], stray_mm: float) -> tuple[np.ndarray, str]:
    """The triangles to keep and what was left out: refuse a file holding two (or more)
    heads or bodies (a piece of at least :data:`SECOND_PIECE` ``[0]`` of the largest's
    area, its centre farther than ``SECOND_PIECE[1]`` from the largest's); pieces farther
    than ``stray_mm`` from the largest piece's surface are left out (a stray blob, a marker:
    kept, it would make the scan look like metres, not a head).  Per piece, vectorised; the
    gaps from one KD-tree of the largest piece's vertices."""
    labels = mesh.face_components
    keep = np.ones(mesh.n_faces, bool)
    k = int(labels.max()) + 1
    if k < 2:
        return keep, ""
    areas = np.bincount(labels, weights=mesh.face_areas, minlength=k)
    main = int(areas.argmax())
    # (each piece's centre: the mean of its triangles' centres)
    centres = mesh.triangles.mean(axis=1)
    sums = np.stack([np.bincount(labels, centres[:, i], k) for i in range(3)], axis=1)
    cent = sums / np.bincount(labels, minlength=k)[:, None]
    apart = np.linalg.norm(cent - cent[main], axis=1)
    big = (areas >= SECOND_PIECE[0] * areas[main]) & (np.arange(k) != main)
    second = big & (apart > SECOND_PIECE[1])
    if second.any():
        far = int(np.flatnonzero(second)[apart[second].argmax()])
        raise InputError(
            source,
            f"holds {int(second.sum()) + 1} separate surfaces of similar size "
            f"{apart[far]:.0f} mm apart (a second piece of {areas[far]:.0f} mm², the largest "
            f"{areas[main]:.0f} mm²: two heads, or a head and another body, in one file)",
            "keep one head in the file (e.g. delete the other pieces in MeshLab or Blender)",
        )
    # surface gap of every other piece to the largest: its corners' nearest largest-piece
    # vertex, the smallest per piece
    main_faces = labels == main
    tree = cKDTree(mesh.vertices[np.unique(mesh.faces[main_faces])])
    others = np.flatnonzero(~main_faces)
    corner = mesh.faces[others].ravel()
    ids, back = np.unique(corner, return_inverse=True)
    d, _ = tree.query(mesh.vertices[ids], workers=worker_count())
    gap = np.full(k, np.inf)
    np.minimum.at(gap, np.repeat(labels[others], 3), d[back.ravel()])
    gap[main] = 0.0
    stray = gap > stray_mm
    if not stray.any():
        return keep, ""
    keep = ~stray[labels]
    n = int(stray.sum())
    return keep, (
        f"left out {n} piece{'s' if n > 1 else ''} of the scan lying "
        f"{gap[stray].min():.0f}"
        + (f"-{gap[stray].max():.0f}" if n > 1 else "")
        + f" mm away from the head ({int((~keep).sum())} triangles, "
        f"{100 * areas[stray].sum() / areas.sum():.1f} % of the surface): not part of it"
    )


def check_landmarks_on_scan(
    landmarks: LandmarkSet,
    scan: Mesh,
    source: str | PathLike[str],
    scan_name: str,
    reference: Mapping[str, np.ndarray] | None = None,
) -> None:
    """Refuse a landmark file (``source``) that does not belong to ``scan`` (the file's
    frame, mm), naming what is wrong: landmarks that coincide (within
    :data:`~workbench.core.limits.COINCIDENT_MM`, where the ``reference`` skin
    landmarks lie more than :data:`LANDMARKS_APART_MM` apart: the stomion points of
    closed lips may coincide), or that lie off the scan's
    surface (further than :data:`~workbench.core.limits.SCAN_LANDMARK_OFF_MM`), and then
    whether they land on it in the other of the LPS and RAS frames (x and y negated) or
    in other units.  A wrong landmark file otherwise misleads the orientation and the
    refusal blames the scan."""
    from workbench.core.limits import COINCIDENT_MM, SCAN_LANDMARK_OFF_MM

    codes = [lm.code for lm in landmarks if lm.is_defined]
    if not codes:
        return
    pts = landmarks.positions_of(codes)
    pairs = cKDTree(pts).query_pairs(COINCIDENT_MM, output_type="ndarray")
    ref = reference or {}
    pairs = np.array(
        [
            (i, j)
            for i, j in pairs.tolist()
            if codes[i] in ref
            and codes[j] in ref
            and np.linalg.norm(ref[codes[i]] - ref[codes[j]]) > LANDMARKS_APART_MM
        ],
        dtype=np.int64,
    ).reshape(-1, 2)
    if len(pairs):
        shown = ", ".join(f"{codes[i]} and {codes[j]}" for i, j in pairs[:4].tolist())
        raise InputError(
            source,
            f"{len(pairs)} pair{'s' if len(pairs) > 1 else ''} of landmarks lie at the same "
            f"point (closer than {COINCIDENT_MM:g} mm): {shown}"
            + (" ..." if len(pairs) > 4 else ""),
            "place each landmark at its own point on the scan (the file may repeat one "
            "point, or hold unset landmarks at 0,0,0)",
        )
    index = MeshIndex.shared(scan)
    d = index.closest_points(pts).distances
    off = d > SCAN_LANDMARK_OFF_MM
    if not off.any():
        return
    worst = np.argsort(-d)[:3]
    shown = ", ".join(f"{codes[i]} {d[i]:.0f} mm" for i in worst if off[i])
    where = (
        f"{int(off.sum())} of {len(codes)} landmarks lie off the scan {scan_name} "
        f"({shown}; a landmark on the scan is within {SCAN_LANDMARK_OFF_MM:g} mm of it)"
    )
    lps_ras = np.diag([-1.0, -1.0, 1.0])
    if (index.closest_points(pts @ lps_ras).distances <= SCAN_LANDMARK_OFF_MM).all():
        raise InputError(
            source,
            f"{where}, but all lie on it with x and y negated: the landmarks are in the "
            "other frame (RAS vs LPS) than the scan",
            "export the landmarks in the scan's frame (3D Slicer writes LPS or RAS as "
            "chosen; the scan file's frame decides), or negate their x and y",
        )
    for factor in (1000.0, 100.0, 25.4, 10.0, 0.1, 0.01, 0.001):
        if (index.closest_points(pts * factor).distances <= SCAN_LANDMARK_OFF_MM).all():
            raise InputError(
                source,
                f"{where}, but all lie on it when multiplied by {factor:g}: the landmarks "
                "are in other units than the scan",
                "export the landmarks in the scan's units (--units / --scale apply to both)",
            )
    raise InputError(
        source,
        where,
        "were they placed on this scan, in its frame and units? (a landmark over a hole "
        "may float, but not this far)",
    )


#: two skin landmarks this far apart (mm) on the reference cannot share a point on a scan
LANDMARKS_APART_MM = 5.0


def _working_colours(
    colours: ScanColours | None, file_mesh: Mesh, prepared: PreparedScan
) -> ScanColours | None:
    """The file's colours made to fit the working scan (:func:`prepare_scan`)."""
    from workbench.io.scan_colours import colours_on_working_scan

    if colours is None:
        return None
    return colours_on_working_scan(
        colours, file_mesh.vertices, prepared.mesh, prepared.vertex_of, prepared.face_source
    )


if TYPE_CHECKING:
    from workbench.core.colour_transfer import ScanColours


def _check_one_shell(scan: Mesh, source: str | PathLike[str]) -> None:
    """Refuse a scan that cuts through itself along a long curve: two surfaces through
    each other (two overlapping heads, a head merged twice out of register), which
    :func:`_check_one_body` does not see when they touch (:data:`SHELL_CROSSINGS`)."""
    crossing = self_intersections(scan)
    if crossing.count < SHELL_CROSSINGS[0]:
        return
    centres = scan.vertices[scan.faces[crossing.faces]].mean(axis=1)
    spread = float(np.linalg.norm(centres.max(axis=0) - centres.min(axis=0)))
    if spread >= SHELL_CROSSINGS[1]:
        raise InputError(
            source,
            f"cuts through itself: {crossing.count} pairs of its triangles cross each other "
            f"over {spread:.0f} mm (two heads through each other, or one head merged twice "
            "out of register); one face cannot be fitted to two surfaces",
            "keep one head in the file (delete the other surface in MeshLab or Blender), "
            "or register the scans onto each other before merging them",
        )


def _check_bone(scan: Mesh, bone: Mesh, source: str) -> None:
    """Refuse a ``--bone`` that is not the bone beneath this scan's skin (both in the scan's
    frame, mm): one lying away from the scan (another frame or unit, another file) or one
    lying on the skin (the skin surface given as the bone)."""
    hint = (
        "give the bone surface of the same CT as the scan, in the same frame and units "
        "(workbench mesh-from-ct CT --tissue bone)"
    )
    if bone.n_faces == 0:
        raise InputError(source, "(--bone) has no triangles: it is not a bone surface", hint)
    used = bone.vertices[np.unique(bone.faces)]
    on_scan = scan.vertices[np.unique(scan.faces)]
    lo = on_scan.min(axis=0) - BONE_BOX_MARGIN_MM
    hi = on_scan.max(axis=0) + BONE_BOX_MARGIN_MM
    inside = float(((used >= lo) & (used <= hi)).all(axis=1).mean())
    if inside < BONE_IN_BOX:
        gap = float(np.linalg.norm(used.mean(axis=0) - on_scan.mean(axis=0)))
        raise InputError(
            source,
            f"(--bone) does not lie under the scan: {100 * inside:.0f} % of it is within "
            f"{BONE_BOX_MARGIN_MM:.0f} mm of the scan's bounding box (its centre is "
            f"{gap:.0f} mm from the scan's); the bone of the scanned head lies inside it",
            hint,
        )
    sample = used[:: max(1, len(used) // 5000)]
    near = MeshIndex.shared(scan).closest_points(sample).distances <= BONE_ON_SKIN_MM
    if near.mean() >= BONE_ON_SKIN:
        raise InputError(
            source,
            f"(--bone) lies on the scan's skin: {100 * near.mean():.0f} % of it is within "
            f"{BONE_ON_SKIN_MM:g} mm of the scan's surface, where bone lies millimetres "
            "beneath the skin everywhere; is it the skin surface (or the scan) itself?",
            hint,
        )


_R = TypeVar("_R")


def _seen_in_file_axes(scan: Mesh) -> np.ndarray:
    """:func:`seen_from_outside` of ``scan`` in its file's axes, along the normals pointing
    away from it (as :func:`outward` winds it in the head frame): the rays are the head
    frame's, moved rigidly."""
    from workbench.core.normals import vertex_normals

    normals = vertex_normals(scan)
    return seen_from_outside(scan, normals=normals if scan.outward() is scan else -normals)


class _Beside:
    """Jobs run on a thread beside the caller's work (in line when one thread is allowed);
    leaving the block waits for them."""

    def __enter__(self) -> _Beside:
        self._pool = ThreadPoolExecutor(max_workers=2) if worker_count() > 1 else None
        return self

    def run(self, fn: Callable[..., _R], *args: object) -> Callable[[], _R]:
        """Start ``fn(*args)``; returns a function that waits for its result (or raises)."""
        if self._pool is None:
            value = fn(*args)
            return lambda: value
        return self._pool.submit(fn, *args).result

    def __exit__(self, *exc: object) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True)


def _placed_on(landmarks: LandmarkSet | None, ref: Mapping[str, np.ndarray]) -> dict:
    """``{code: position}`` of the user's defined landmarks the reference also has."""
    if landmarks is None:
        return {}
    return {lm.code: lm.position for lm in landmarks if lm.is_defined and lm.code in ref}


def _seed_pairs(
    landmarks: LandmarkSet | None, base: TemplateHead
) -> tuple[np.ndarray, np.ndarray] | None:
    ref = base.skin_landmarks.as_dict()
    placed = _placed_on(landmarks, ref)
    if len(placed) < 3:
        return None
    codes = sorted(placed)
    return np.array([placed[c] for c in codes], float), np.array([ref[c] for c in codes])


#: a first-guess landmark's confidence falls to 1/e at this distance from the scan (mm)
CONFIDENCE_MM = 1.5
#: ... and is at most this over a hole (its position is the reference's, not measured)
HOLE_CONFIDENCE = 0.2


def _with_confidences(
    lms: LandmarkSet, absent: Sequence[str], scan_index: MeshIndex, placed: LandmarkSet | None
) -> LandmarkSet:
    """The fitted skin landmarks as a first guess with confidences (head frame, mm).

    Those the user placed stay ``placed`` with confidence 1; the others are
    ``suggested`` with ``exp(-d / CONFIDENCE_MM)`` for their distance ``d`` to
    the scan, capped at :data:`HOLE_CONFIDENCE` over a hole (in empty space:
    their description says so).
    """
    from workbench.core.landmarks import Landmark

    user = set() if placed is None else {lm.code for lm in placed if lm.is_defined}
    codes = [lm.code for lm in lms if lm.is_defined]
    if not codes:
        return lms
    dist = scan_index.closest_points(lms.positions_of(codes)).distances
    d = dict(zip(codes, dist, strict=True))
    out = []
    for lm in lms:
        if not lm.is_defined:
            out.append(lm)
            continue
        if lm.code in user:
            out.append(Landmark(lm.code, lm.position, "placed", 1.0, lm.description))
            continue
        conf = float(np.exp(-d[lm.code] / CONFIDENCE_MM))
        if lm.code in absent:
            conf = min(conf, HOLE_CONFIDENCE)
        out.append(Landmark(lm.code, lm.position, "suggested", round(conf, 3), lm.description))
    return LandmarkSet(lms.surface, tuple(out))


def _user_constraints(
    landmarks: LandmarkSet | None, rest: TemplateHead, to_head: np.ndarray
) -> tuple[np.ndarray, np.ndarray] | None:
    """Skin landmarks the user placed as hard constraints of the skin fit.

    Each placed landmark (scan frame) is mapped into the head frame; the three
    vertices of the reference skin triangle holding that landmark are pulled to
    where the triangle would sit with the landmark on the user's point (the
    triangle moved by the landmark's offset), so the fitted landmark lands on
    it whether or not the scan has surface there ("in empty space").
    """
    ref = rest.skin_landmarks.as_dict()
    placed = _placed_on(landmarks, ref)
    if not placed:
        return None
    codes = sorted(placed)
    user = apply_transform(to_head, np.array([placed[c] for c in codes]))
    at = np.array([ref[c] for c in codes])
    tri = rest.skin.faces[MeshIndex(rest.skin).closest_points(at).face_ids]  # (k, 3)
    targets = rest.skin.vertices[tri] + (user - at)[:, None, :]
    ids, first = np.unique(tri.ravel(), return_index=True)  # a vertex shared: first wins
    return ids, targets.reshape(-1, 3)[first]


def _mask(n: int, groups: Sequence) -> np.ndarray:
    m = np.zeros(n, dtype=bool)
    for ids in groups:
        m[np.asarray(ids, dtype=np.int64)] = True
    return m


def _depth_pairs(
    head: TemplateHead, table: str, sex: str, build: str | float
) -> tuple[dict[str, tuple[str, float]], str, list[str]]:
    from workbench.io.tables import load_depth_table
    from workbench.services.templates.template import paired_depths
    from workbench.services.tissue.dowel_sites import choose_depth_group
    from workbench.services.tissue.dowels import build_score

    tab = load_depth_table(table)
    model, z, by_model = build_score(tab, build)
    group, k, label, notes = choose_depth_group(tab, None, sex, "normal" if by_model else build)
    pairs = paired_depths(
        set(head.skull_landmarks.as_dict()), set(head.skin_landmarks.as_dict()), table, group, k
    )
    if model is not None and z:
        # the build model's regional depths (mean + r SD z) for a named build or a BMI
        sds = {c: sd for c, (_, sd) in tab.lookup(group).items()}
        pairs = {
            c: (skin, d + model.loading(c) * sds[c] * z if np.isfinite(sds[c]) else d)
            for c, (skin, d) in pairs.items()
        }
        label = f"{label.removesuffix(', mean')}, {by_model}"
    return pairs, label, notes


def _inward_normals(skin: Mesh, points: np.ndarray, codes: Sequence[str]) -> np.ndarray:
    """Inward unit skin normals at ``points`` (midline landmarks kept in the midsagittal plane)."""
    n = normals_within_radius(skin, points, NORMAL_RADIUS_MM)
    mid = np.array([not c.endswith(("_l", "_r")) for c in codes])
    if mid.any():
        n[mid, 0] = 0.0
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    return -n


def _uncovered(index: MeshIndex, caps: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Per point (the scan's frame, mm): does the scan end before it?

    Its closest scan point lies on an open rim (the edge of a hole or of the
    scanned field) or on a field-of-view lid (``caps``: per scan vertex), more
    than :data:`COVER_MM` away: the scan does not show that part (a partial
    face), which is not a mismatch of its shape.  A closed surface (a ball)
    covers every point.
    """
    cp = index.closest_points(points)
    scan = index.mesh
    ended = _beyond_rim(scan, cp.face_ids, cp.barycentric)
    if caps.any():
        ended |= caps[scan.faces[cp.face_ids]].any(axis=1)
    return ended & (cp.distances > COVER_MM)


def _place_partial(
    index: MeshIndex,
    caps: np.ndarray,
    base: TemplateHead,
    face_ids: np.ndarray,
    groups: Mapping[str, np.ndarray],
    starts: Sequence[PoseResult],
) -> tuple[FacePlacement, np.ndarray] | None:
    """The reference face laid on a scan that shows only part of it, or None when the
    scan covers (nearly) all of the face under every start.

    From each start the face vertices the scan covers (:func:`_uncovered`) are
    laid on it alone (:func:`~workbench.core.face_pose.place_face`: the missing
    part neither pulls nor costs), and the coverage is found again at the pose
    reached.  The pose whose covered loss plus :data:`UNCOVERED_COST` per
    uncovered vertex is lowest wins.  Returns its placement (fractions and
    ``near_by_group`` over the covered vertices) and the covered mask (per face
    vertex, at that pose).
    """
    from workbench.core.rigid_search import SCALE_RANGE

    pts = base.skin.vertices[face_ids]
    nrm = base.skin.vertex_normals[face_ids]
    best: tuple[float, FacePlacement, np.ndarray] | None = None
    for start in starts[:PARTIAL_STARTS]:
        matrix = start.matrix
        covered = ~_uncovered(index, caps, apply_transform(np.linalg.inv(matrix), pts))
        if covered.mean() >= WHOLE_FACE_COVERAGE or covered.mean() < 0.5 * MIN_SCAN_FACE_COVERAGE:
            continue
        slot = np.cumsum(covered) - 1
        sub = {k: slot[np.asarray(g)[covered[g]]] for k, g in groups.items()}
        placed = place_face(
            index, pts[covered], nrm[covered], matrix, scale_range=SCALE_RANGE, groups=sub
        )
        now = ~_uncovered(index, caps, apply_transform(np.linalg.inv(placed.matrix), pts))
        score = (placed.loss * covered.sum() + UNCOVERED_COST * (~covered).sum()) / len(pts)
        if best is None or score < best[0]:
            best = (score, placed, now)
    return None if best is None else (best[1], best[2])


def _place_face(
    scan: Mesh,
    base: TemplateHead,
    pose: PoseResult,
    regions: Mapping[str, np.ndarray],
    source: str,
    caps: np.ndarray,
) -> tuple[PoseResult, FacePlacement, np.ndarray | None]:
    """The search's pose improved by laying the reference face on the scan; refuse a
    scan the face does not find its shape on (:func:`workbench.core.face_pose.place_face`).

    The search scores the whole scan; on a bust the crown, hair and shoulders outweigh
    the face.  The face is laid from the search's winner and from its next-best
    distinct poses (a crown or shoulders can tilt the winner: Nefertiti without a hint
    came out nodded by 24°, a runner-up by 11°); the lowest face loss wins.
    """
    from workbench.core.rigid_search import SCALE_RANGE

    face_ids = np.concatenate(list(regions.values()))
    offsets = np.cumsum([0] + [len(v) for v in regions.values()])
    groups = {
        k: np.arange(a, b) for k, a, b in zip(regions, offsets[:-1], offsets[1:], strict=True)
    }
    index = MeshIndex.shared(scan)  # the head-frame copy of the scan borrows it
    searched = (pose, *pose.alternatives)
    placements: list[FacePlacement] = []
    for start in searched:
        if placements and placements[0].loss < CLEAR_FACE_LOSS:
            break  # the winner's face sits well: the runners-up need not be tried
        placements.append(
            place_face(
                index,
                base.skin.vertices[face_ids],
                base.skin.vertex_normals[face_ids],
                start.matrix,
                scale_range=SCALE_RANGE,
                groups=groups,
            )
        )
    placement = min(placements, key=lambda p: p.loss)
    placement = replace(placement, start_loss=placements[0].start_loss)
    if placement.loss < placement.start_loss:
        # the search's cost and matched fraction described the pose left behind
        pose = replace(
            pose,
            matrix=placement.matrix,
            scale=placement.scale,
            method=f"{pose.method} + face placement",
            cost=placement.loss,
            matched_fraction=placement.matched_fraction,
        )
    nose = placement.near_by_group.get("nose", 1.0)
    if _face_like(placement.near_fraction, nose):
        return pose, placement, None
    # a part of a face (a CT that ends at the upper teeth, a scan without its chin): the
    # reference face beyond the scan's rim finds nothing there, and laid whole it slides
    # up or down to cover more (the headsq skin cut at the upper teeth: its mouth on the
    # scan's nose, 46 % of the face within 5 mm); laid with the covered part alone
    partial = _place_partial(index, caps, base, face_ids, groups, searched)
    shown = ""
    if partial is not None:
        part, covered = partial
        share = float(covered.mean())
        nose_share = float(covered[groups["nose"]].mean()) if "nose" in groups else 1.0
        part_nose = part.near_by_group.get("nose", 1.0)
        if (
            share >= MIN_SCAN_FACE_COVERAGE
            and nose_share >= MIN_SCAN_NOSE_COVERAGE
            and _face_like(part.near_fraction, part_nose)
        ):
            pose = replace(
                searched[0],
                matrix=part.matrix,
                scale=part.scale,
                method=f"{searched[0].method} + partial face placement",
                cost=part.loss,
                matched_fraction=part.matched_fraction,
            )
            return pose, replace(part, start_loss=placement.start_loss), covered
        shown = (
            f"; the scan shows {100 * share:.0f} % of the face and {100 * nose_share:.0f} % "
            f"of its nose, of which {100 * part.near_fraction:.0f} and "
            f"{100 * part_nose:.0f} % find their shape (a partial face needs "
            f"{100 * MIN_SCAN_FACE_COVERAGE:.0f} % of the face shown with "
            f"{100 * MIN_SCAN_NOSE_COVERAGE:.0f} % of the nose, and the shares above)"
        )
    # a ball, a hand, a smooth crown: convex enough for forehead and cheeks, but the
    # nose finds nothing of its shape (ball 42 % of the face / 29 % of the nose, a
    # cylinder 54 / 32 %; real scans 64-99 / 61-100 %: the VHP female's nose tip is
    # cut off by the CT's field of view).  A face placed well but turned ~10° (Nefertiti
    # with its axes searched: 72 / 37 %) misses with its nose alone: not refused
    raise InputError(
        source,
        "does not look like a face: laid on it as well as it goes, "
        f"{100 * placement.near_fraction:.0f} % of the reference face and "
        f"{100 * nose:.0f} % of its nose find scan surface of their shape within 5 mm "
        f"(a face scan gives over {100 * MIN_PLACED_FACE:.0f} and "
        f"{100 * MIN_PLACED_NOSE:.0f} %){shown}",
        "is this a scan of a face? check the orientation (--anterior/--superior or "
        "3+ --landmarks) and the units",
    )


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


def _face_like(face: float, nose: float) -> bool:
    """Does a placed face with these shares within 5 mm (of the face, of its nose) find
    a face's shape (:data:`MIN_PLACED_FACE`, :data:`MIN_PLACED_NOSE`)?"""
    weak_nose = nose < MIN_PLACED_NOSE and face < NOSE_DOUBT_FACE
    return face >= MIN_PLACED_FACE and not weak_nose


def fit_scan(
    scan: Mesh,
    *,
    landmarks: LandmarkSet | None = None,
    sex: str = "male",
    table: str = DEFAULT_DEPTH_TABLE,
    build: str | float = "normal",
    orientation: tuple | None = None,
    bone: Mesh | None = None,
    base: TemplateHead | None = None,
    source: str = "scan",
    inputs: Sequence[Mapping] = (),
    progress: Progress | None = None,
    detail: bool = True,
    bone_source: str = "bone",
) -> ScanFit:
    """Adapt the reference head of ``sex`` (or ``base``) to ``scan`` (input frame, mm).

    Parameters
    ----------
    landmarks : LandmarkSet, optional
        Skin landmarks placed on the scan (input frame, mm): three or more
        orient it (and decide its handedness); all are compared with the
        fitted ones in the report.
    table, sex, build : the depth table, its group and variant (mean + k SD)
        giving the skin–skull distances the inner parts are placed at.
    orientation : (anterior, superior[, left]) in the scan's coordinates, optional
    bone : Mesh, optional
        The true bone surface in the scan's frame (a CT): the estimated skull
        is compared with it in the report.  Refused when it does not lie
        under the scan, or lies on its skin (:func:`_check_bone`).
    source, bone_source : str
        Names of the scan and the bone in error messages (their files).
    detail : bool
        Also carry the scan's fine detail onto the subdivided skin
        (:attr:`ScanFit.detail`, ``figures["detail"]``; ~2-3 s); False for
        batches that need only the animatable head.
    """
    from workbench.core.rigid_search import SCALE_RANGE, search_pose
    from workbench.services.landmarks.frame import head_frame_from_landmarks
    from workbench.services.registration.skull_registration import head_transformed
    from workbench.services.templates.build import (
        carry_skin_landmarks,
        eyes_behind_lids,
        fit_skin,
        scan_in_frame,
    )
    from workbench.services.templates.cache import reference_head
    from workbench.services.templates.regions import face_regions

    say = progress or (lambda _m: None)
    t0 = time.perf_counter()
    seconds: dict[str, float] = {}
    prepared = prepare_scan(scan, source, say)  # welded, repaired, simplified (the same
    scan = prepared.mesh  # mesh again when fit_scan_pack prepared it)
    if bone is not None:  # a bone that is not under this skin makes the comparison garbage
        _check_bone(scan, bone, bone_source)
    base = base or reference_head(sex)
    pairs, depth_label, warnings = _depth_pairs(base, table, sex, build)
    warnings += list(prepared.notes)

    # 1. orientation and size
    say("orienting the scan ...")
    seeds = _seed_pairs(landmarks, base)
    regions = face_regions(base)
    face_ids = np.concatenate(list(regions.values()))
    placement = None
    covered = None  # per face vertex, when the scan shows only part of the face
    # lids where a CT's volume ended (below the chin, a cut vault): not skin, and their
    # edges are rims like a hole's (found in the file's own axes, where the volume's
    # sides are)
    caps = field_of_view_caps(scan)
    # the scan's closest-point index and which of its vertices a scanner could see do not
    # depend on the pose: they are found beside the pose search (their compiled loops and
    # Embree's casts run without the GIL; ~0.5 s of a 300k-triangle fit)
    with _Beside() as beside:
        beside.run(MeshIndex.shared, scan)
        # two heads through each other: refused before a face is laid on either
        one_shell = beside.run(_check_one_shell, scan, source)
        # walls of the airway, mouth and nostrils (a CT's skin surface, parted lips): no
        # scanner sees them and the reference has no surface for them
        seen_job = beside.run(_seen_in_file_axes, scan)
        pose = search_pose(scan, base.skin, hint=orientation, seeds=seeds, mirror="auto")
        searched_scale = pose.scale
        one_shell()
        if seeds is None:
            pose, placement, covered = _place_face(scan, base, pose, regions, source, caps)
        seen = seen_job()
    s = pose.scale
    rigid = pose.matrix.copy()
    rigid[:3] /= s
    rigid[3] = (0.0, 0.0, 0.0, 1.0)
    mirrored = bool(np.linalg.det(rigid[:3, :3]) < 0)
    at_limit = [np.isclose(1 / x, SCALE_RANGE, rtol=0.02).any() for x in (searched_scale, s)]
    if seeds is None and any(at_limit):
        # the whole-scan search at its limit is said even when the face alone then found
        # a size inside the range: a face laid on part of a head 1.6 times life size
        # looks like a fit (most of such a scan is then "not the head")
        laid = "" if at_limit[1] else f"; the face alone was then laid at {1 / s:.2f}"
        warnings.append(
            f"the size search stopped at its limit (reference scaled "
            f"{1 / searched_scale:.2f}{laid}): the scan may not be in the units given, or "
            "parts that are not a face (a crown, hair, shoulders) misled it; check the "
            "result, or place 3 or more skin landmarks (--landmarks) to set the size"
        )
    rest = head_transformed(base, np.diag([1 / s, 1 / s, 1 / s, 1.0]))
    scan_h = scan_in_frame(scan, rigid, mirrored)
    cap_d = np.full(scan.n_vertices, np.inf)
    if caps.any():
        cap_d, _ = cKDTree(scan_h.vertices[caps]).query(scan_h.vertices, workers=worker_count())
    # sheets over more of the scan (a cord, a strap, hair): no correspondence there, the
    # skin beneath them is fitted like a hole's
    thin = _mask(rest.skin.n_vertices, [rest.regions[r] for r in SHEET_PARTS if r in rest.regions])
    layered = _sheets_over_scan(scan_h, seen > 0, rest.skin, thin)
    belief = seen * smoothstep(cap_d / RIM_EXCLUDE_MM) * ~layered
    seconds["orientation"] = time.perf_counter() - t0

    # 2. skin
    t = time.perf_counter()
    say("registering the reference skin onto the scan ...")
    scan_index = MeshIndex.shared(scan_h)  # the file-frame scan's, when the placement built it
    hard = _user_constraints(landmarks, rest, rigid)
    # an ear the scan's rim cuts through (a CT that ends below the nose) is held to the
    # reference's shape: half an ear pulled onto the scan's and half inferred folds over
    # (the headsq skin cut at the subnasale: 7 fold-overs at the right ear)
    ears_at = {r: rest.skin.vertices[base.regions[r]] for r in EAR_REGIONS if r in base.regions}
    cut_ears = [
        r for r, at in ears_at.items() if _uncovered(scan_index, caps, at).mean() > CUT_EAR_SHARE
    ]
    fit = fit_skin(
        rest.skin,
        scan_h,
        # (held passive: the regions fit_skin holds when its ears do not follow the scan)
        {k: v for k, v in base.regions.items() if k not in EAR_REGIONS or k in cut_ears},
        levels=SCAN_LEVELS,
        affine_rounds=AFFINE_ROUNDS,
        source=source,
        near="the reference head placed on it",
        hint="check the orientation (--anterior/--superior or 3+ --landmarks) and the units",
        belief=belief,
        hard=hard,
        # the ears look for the scan's too: held passive they stay the reference's, a few
        # mm to a centimetre beside the scan's, whose vertices then counted as misses of the
        # cheek; following, 1 mm figures rise 0.3-4 points on every case, no fold-over added
        ears=not cut_ears,
        index=scan_index,
    )
    warnings += list(fit.warnings)
    # the reference skin's own crossings (sliver triangles of the lips' seam at the mouth
    # corners) are its design; any other the fit made is smoothed away where it is
    ref_cross = self_intersections(rest.skin)
    untangled = untangle(
        rest.skin.with_vertices(fit.registration.vertices),
        reference=rest.skin,
        allowed=map(tuple, ref_cross.pairs.tolist()),
        fixed=None if hard is None else _mask(rest.skin.n_vertices, [hard[0]]),
    )
    skin = untangled.mesh
    facing, to_scan = _scan_support(
        skin.vertices, rest.skin.faces, scan_h, fit.target_weights, scan_index
    )
    on_scan = facing & (to_scan <= ON_SCAN_MM)
    face = _mask(rest.skin.n_vertices, [face_ids])
    # the face the scan shows: on a partial face (a CT that ends at the upper teeth) the
    # skin beyond the scan's rim follows the reference's shape and is inferred, not missed
    shown = face & ~_uncovered(scan_index, caps, skin.vertices)
    shown_share = float(shown.sum() / max(int(face.sum()), 1))
    partial = shown_share < WHOLE_FACE_COVERAGE
    support = float(on_scan[shown if partial else face].mean()) if shown.any() else 0.0
    need = MIN_PARTIAL_SUPPORT if partial else MIN_FACE_SUPPORT
    if shown_share < MIN_SCAN_FACE_COVERAGE or support < need:
        # a hand, an object, the back of a head: the skin was bent onto it, but most of
        # the face found no surface of its shape near it; that is not a fitted face
        of_it = (
            f" of the {100 * shown_share:.0f} % of the reference face the scan shows"
            if partial
            else " of the reference face"
        )
        raise InputError(
            source,
            f"does not look like a face: only {100 * support:.0f} %{of_it} found scan "
            f"surface of its shape near it (a face scan gives over "
            f"{100 * MIN_FACE_SUPPORT:.0f} %, a part of a face over {100 * MIN_PARTIAL_SUPPORT:.0f} "
            f"% of at least {100 * MIN_SCAN_FACE_COVERAGE:.0f} % of the face)",
            "is this a scan of a face? check the orientation (--anterior/--superior or 3+ "
            "--landmarks) and the units",
        )
    skin_lms, absent_skin = carry_skin_landmarks(rest.skin, skin, rest.skin_landmarks, on_scan)
    tip = skin_lms.as_dict().get(NOSE_TIP)
    if partial and tip is not None and _uncovered(scan_index, caps, tip[None])[0]:
        # a band of brow and orbits can take the reference's nose and mouth (the headsq
        # skin cut 40 mm below the vault's top: the face laid 75 mm low, its nose tip
        # beyond the scan's rim); a part of a face fixes the pose only with its nose tip
        # over the scan
        raise InputError(
            source,
            f"shows too little of the face to fit it: {100 * shown_share:.0f} % of the "
            "reference face lies over the scan, but not the nose tip (pronasale); a "
            "partial face scan must show the nose with the eyes or the mouth",
            "give a scan that shows the middle of the face, or place 3+ skin landmarks "
            "(--landmarks)",
        )
    skin_lms = _with_confidences(skin_lms, absent_skin, scan_index, landmarks)
    seconds["skin"] = time.perf_counter() - t

    # 3. the inside follows the skin at the table's depths
    t = time.perf_counter()
    say("placing skull, teeth, eyes and tongue at the table's tissue depths ...")
    skin_at = skin_lms.as_dict()
    skull_at = rest.skull_landmarks.as_dict()
    codes = [c for c in pairs if c in skull_at and pairs[c][0] in skin_at]
    if len(codes) < 4:
        raise InputError(
            table, f"only {len(codes)} skin/skull landmark pairs: the skull cannot be placed"
        )
    skin_pts = np.array([skin_at[pairs[c][0]] for c in codes])
    depth = np.array([pairs[c][1] for c in codes])
    inward = _inward_normals(skin, skin_pts, codes)
    targets = skin_pts + depth[:, None] * inward
    src = np.array([skull_at[c] for c in codes])
    warp = fit_warp(src, targets, smoothing=INNER_SMOOTHING)
    warped = rest.warped(warp)
    meshes = dict(warped.meshes)
    meshes.update(_bone_under_skin(meshes, skin, np.asarray(rest.regions["face"])))
    meshes["skin"] = skin
    eye_shift = eyes_behind_lids(warped, skin.vertices, on_scan)
    head = replace(warped, meshes=meshes, skin_landmarks=skin_lms).with_eyes_moved(eye_shift)
    seconds["inside"] = time.perf_counter() - t

    # 4. settle in the Frankfort frame of the estimated skull
    try:
        settle = head_frame_from_landmarks(head.skull_landmarks).input_to_head
    except WorkbenchError:
        settle = np.eye(4)
    head = head_transformed(head, settle)
    to_head = settle @ rigid
    scan_h = scan_h.transformed(settle)  # rigid: keeps borrowing the scan's index
    ref_settled = head_transformed(rest, settle)

    # 5. the scan's fine detail over the subdivided skin (the animatable skin keeps the
    # reference's 4 890 vertices; its ~4 mm edges cannot hold lid creases or lip borders)
    layer = None
    if detail:
        t = time.perf_counter()
        say("carrying the scan's fine detail onto the subdivided skin ...")
        believed = fit.target_weights * seen
        # not the ears: their helix, antihelix and concha fold within millimetres of each
        # other at every angle, and a displacement there crosses a neighbouring fold (the
        # headsq fit gained ~110 new crossings at the ears, none elsewhere after the limits
        # of build_detail)
        ears = _mask(
            skin.n_vertices, [base.regions[r] for r in ("ear_l", "ear_r") if r in base.regions]
        )
        layer = build_detail(head.skin, scan_h, believed, fixed=ears)
        seconds["detail"] = time.perf_counter() - t

    # figures
    say("measuring the fit ...")
    t = time.perf_counter()
    fig: dict = {}
    fitted = head.skin
    _, nearest = cKDTree(fitted.vertices).query(scan_h.vertices, workers=worker_count())
    rim_d = np.full(scan_h.n_vertices, np.inf)
    loops = boundary_loops(scan_h)
    if loops:
        rim_d, _ = cKDTree(scan_h.vertices[np.concatenate(loops)]).query(
            scan_h.vertices, workers=worker_count()
        )
    rim_d = np.minimum(rim_d, cap_d)
    in_face = face[nearest] & (rim_d > RIM_EXCLUDE_MM)
    counted = in_face & (fit.target_weights > HEAD_WEIGHT)
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
    if layer is not None:
        fig["detail"] = _detail_figures(layer, fitted, scan_h.vertices[counted], face)
        beyond = fig["detail"]["face_over_skin_openings_vertices"]
        if beyond > OPENINGS_WARN_SHARE * max(int(counted.sum()), 1):
            warnings.append(
                f"{beyond} face scan vertices lie over the fitted skin's eye, mouth or nostril "
                "openings, more than 1 mm from it: the scan has a surface there (closed eyes "
                "or lips, a bust's carved eyes) where the reference's lids and lips stay parted"
            )
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
    seconds["figures"] = time.perf_counter() - t
    if bone is not None:  # the check against a true bone, not part of the fit
        t = time.perf_counter()
        fig["skull_vs_bone"] = _skull_vs_bone(head, bone, to_head, face)
        seconds["skull_vs_bone"] = time.perf_counter() - t
    seconds["total"] = time.perf_counter() - t0
    fig["seconds"] = {k: round(v, 2) for k, v in seconds.items()}

    digest = hashlib.sha256(
        "".join(str(i.get("sha256", "")) for i in inputs).encode()
        + base.content_hash.encode()
        + json.dumps([table, sex, str(build)]).encode()
    ).hexdigest()[:12]
    provenance = {
        "built_from": [dict(i) for i in inputs],
        "base_template": {"template_id": base.template_id, "content_hash": base.content_hash},
        "method": "reference skin oriented on the scan (rigid multi-start search or landmarks), "
        "registered onto it (affine then coarse to fine, rims and non-head parts faded "
        "out, the reference's shape over holes); skull, teeth, tongue and eyes warped "
        "(thin-plate spline) so the paired skull landmarks lie at the table depths "
        "inward along the skin normal (Kähler 2003 §8.3.2)",
        "frame": "the fitted person's head frame (Frankfort Horizontal from the estimated "
        "skull's porions and orbitales), mm",
        "input_to_head": to_head,
        "mirrored_input": mirrored,
        "absent_landmarks": {"skin": list(absent_skin), "skull": []},
        "depth_table": {"table": table, "group": depth_label, "sex": sex, "build": str(build)},
        "figures": fig,
        "warnings": list(warnings),
        "fit_version": FIT_VERSION,
    }
    head = replace(
        head,
        template_id=f"{base.template_id}/scan/{digest}",
        provenance=provenance,
        # the skin the scan does not support: the reference's shape (see figures["inferred"])
        regions={**head.regions, "inferred": np.flatnonzero(~on_scan)},
    )
    return ScanFit(
        head, to_head, mirrored, on_scan, fig, tuple(warnings), scan_h, scan_distance, layer
    )


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


def _beyond_rim(mesh: Mesh, face_ids: np.ndarray, bary: np.ndarray) -> np.ndarray:
    """Closest points (face, barycentric) that lie on a boundary edge of ``mesh``: the
    query point is beyond the rim of one of its openings, not over its surface."""
    # edge h of a face (0: corners 0-1, 1: 1-2, 2: 2-0) holds the points whose weight on
    # the opposite corner is zero
    on_edge = np.asarray(bary)[:, [2, 0, 1]] < 1e-6
    return (mesh.open_face_edges[face_ids] & on_edge).any(axis=1)


#: bone that reaches through the fitted face skin is moved back under it to this depth (mm)
BONE_CLEARANCE_MM = 0.5
#: ... with a Gaussian falloff of this radius around each skin vertex it reached (mm)
BONE_PUSH_RADIUS_MM = 5.0


def _bone_under_skin(
    meshes: Mapping[str, Mesh], skin: Mesh, face: np.ndarray, rounds: int = 6
) -> dict[str, Mesh]:
    """Cranium and mandible moved back under ``face`` skin vertices they reach through (mm).

    The skin is the scan's and the skull only an estimate placed by a smooth
    warp at the paired landmarks, so between the pairs (the thin skin of the
    lateral orbit rims, the nasal dorsum) bone can come through: there
    the bone is pushed in along the skin's normal, with a Gaussian falloff
    (:data:`BONE_PUSH_RADIUS_MM`), until the skin is at least
    :data:`BONE_CLEARANCE_MM` outside it.  Returns the moved parts; the skull
    landmarks are not moved.
    """
    parts = {p: meshes[p] for p in ("cranium", "mandible") if p in meshes}
    if len(parts) < 2:
        return {}
    normals = skin.vertex_normals
    for _ in range(rounds):
        bone = MeshIndex(concatenate(list(parts.values())))
        signed = bone.signed_distance(skin.vertices[face])
        hit = signed < 0
        if not hit.any():
            break
        where = skin.vertices[face[hit]]
        need = BONE_CLEARANCE_MM - signed[hit]
        push = need[:, None] * normals[face[hit]]
        tree = cKDTree(where)
        for name, mesh in parts.items():
            v = mesh.vertices
            dist, j = tree.query(v, distance_upper_bound=3.0 * BONE_PUSH_RADIUS_MM)
            near = np.isfinite(dist)
            w = np.exp(-((dist[near] / BONE_PUSH_RADIUS_MM) ** 2))
            moved = v.copy()
            moved[near] -= w[:, None] * push[j[near]]
            parts[name] = mesh.with_vertices(moved)
    return parts


def _scan_support(
    skin_v: np.ndarray,
    faces: np.ndarray,
    scan_h: Mesh,
    scan_weights: np.ndarray,
    index: MeshIndex,
) -> tuple[np.ndarray, np.ndarray]:
    """Per fitted skin vertex: is its closest scan point believed (not a hole rim, not a
    cavity wall, not the shoulders) and facing the same side; and its distance (mm).

    Measured to the scan's *surface* (not its vertices), so a coarse scan (5 mm
    edges) supports the skin as well as a dense one.  A vertex is on the scan
    when supported within :data:`ON_SCAN_MM`.  ``index`` is ``scan_h``'s.
    """
    from workbench.core.normals import vertex_normals

    cp = index.closest_points(skin_v)
    w = np.einsum("ij,ij->i", cp.barycentric, scan_weights[scan_h.faces[cp.face_ids]])
    n = vertex_normals(Mesh(skin_v, faces))
    # (the closest feature's normal: a face's would depend on which face a tie returned)
    cos = np.einsum("ij,ij->i", n, index.pseudo_normals(cp.face_ids, cp.barycentric))
    return (w > HEAD_WEIGHT) & (cos > ON_SCAN_COS), cp.distances


def _leave_inward(scan_h: Mesh, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Of scan vertices ``rows``, those whose ray along the inward normal leaves the scan's
    inside (meets a back-facing triangle) within :data:`SHEET_MAX_MM`: a thin sheet.
    Returns their places in ``rows``, their inward directions and the exit points (head
    frame, mm; the scan wound outward)."""
    normals = scan_h.vertex_normals[rows]
    # (a vertex of no triangle, or of degenerate ones only, has no normal to follow)
    places = np.flatnonzero(np.abs(normals).sum(axis=1) > 0.5)
    inward = -normals[places]
    if not len(places):
        return places, inward, np.empty((0, 3))
    # (started a hair past the surface, so a ray does not meet the triangles it left)
    hits = RayCaster.shared(scan_h).first_hits(
        scan_h.vertices[rows[places]] + 0.05 * inward, inward, max_distance=SHEET_MAX_MM
    )
    facing = np.einsum("ij,ij->i", scan_h.face_normals[np.maximum(hits.face_ids, 0)], inward)
    leaves = hits.hit & (facing > 0)
    return places[leaves], inward[leaves], hits.points[leaves]


def _sheets_over_scan(
    scan_h: Mesh, candidates: np.ndarray, reference: Mesh, thin: np.ndarray
) -> np.ndarray:
    """Per scan vertex: does it lie on a thin sheet with more of the scan beneath it (head
    frame, mm; the scan wound outward, the ``reference`` skin placed on it)?

    Seeds: a ray from the vertex along its inward normal leaves the scan's inside
    within :data:`SHEET_MAX_MM` (:func:`_leave_inward`) and then enters it again
    within :data:`SHEET_GAP_MM`: a cord, strap or strand of hair over the skin.
    The whole sheet then goes with its seeds: every thin vertex joined to one by
    thin vertices (the cord's sides, whose rays run across it with nothing
    beneath).  Only among ``candidates``, and not where the nearest reference
    vertex is ``thin`` (its own thin parts, the alae over the nostrils:
    :data:`SHEET_PARTS`).
    """
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    out = np.zeros(scan_h.n_vertices, bool)
    rows = np.flatnonzero(candidates)
    places, inward, exits = _leave_inward(scan_h, rows)
    rows = rows[places]
    if len(rows) and thin.any():
        _, nearest = cKDTree(reference.vertices).query(scan_h.vertices[rows])
        keep = ~thin[nearest]
        rows, inward, exits = rows[keep], inward[keep], exits[keep]
    if not len(rows):
        return out
    hits = RayCaster.shared(scan_h).first_hits(
        exits + 0.05 * inward, inward, max_distance=SHEET_GAP_MM
    )
    facing = np.einsum("ij,ij->i", scan_h.face_normals[np.maximum(hits.face_ids, 0)], inward)
    seeds = hits.hit & (facing < 0)
    if not seeds.any():
        return out
    # the thin vertices' own graph: its pieces holding a seed
    slot = np.full(scan_h.n_vertices, -1)
    slot[rows] = np.arange(len(rows))
    e = slot[scan_h.edges_unique]
    e = e[(e >= 0).all(axis=1)]
    graph = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(len(rows), len(rows)))
    _, piece = connected_components(graph, directed=False)
    out[rows[np.isin(piece, piece[seeds])]] = True
    return out


def _sheets_outside(scan_h: Mesh, ids: np.ndarray, skin: MeshIndex) -> np.ndarray:
    """Per scan vertex ``ids``: does it lie on a thin sheet of the scan wholly outside the
    fitted skin (head frame, mm; the scan wound outward)?

    The vertex's inward ray leaves the scan within :data:`SHEET_MAX_MM`
    (:func:`_leave_inward`), and both the vertex and that exit point lie more
    than :data:`SHEET_OUTSIDE_MM` outside the fitted skin (signed by the
    closest feature's pseudo-normal): a fin, or a cord with nothing beneath
    it.  The alae and the lips at their slit are thin too, but their inner side
    lies inside the fitted skin.
    """
    out = np.zeros(len(ids), bool)
    if not len(ids):
        return out
    outside = np.flatnonzero(skin.signed_distance(scan_h.vertices[ids]) > SHEET_OUTSIDE_MM)
    places, _, exits = _leave_inward(scan_h, ids[outside])
    if len(places):
        out[outside[places]] = skin.signed_distance(exits) > SHEET_OUTSIDE_MM
    return out


#: the uniform tissue depth of the baseline the estimated skull must beat (VALIDATION.md: 6 mm)
BASELINE_DEPTH_MM = 6.0


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


def fit_scan_pack(
    scan_path: str | PathLike[str],
    out: str | PathLike[str],
    *,
    units: str = "auto",
    scale: float | None = None,
    landmarks: str | PathLike[str] | None = None,
    sex: str = "male",
    table: str = DEFAULT_DEPTH_TABLE,
    build: str | float = "normal",
    orientation: tuple | None = None,
    bone_path: str | PathLike[str] | None = None,
    texture: str | PathLike[str] | None = None,
    force: bool = False,
    progress: Progress | None = None,
    extra: Callable[[Path, ScanFit], list[Path]] | None = None,
    detail: bool = True,
) -> tuple[ScanFit, list[Path]]:
    """Read the scan (and landmarks, bone), :func:`fit_scan`, write the pack and
    ``fit_report.json`` to ``out``.

    The scan, its landmark file and the bone share one frame and one unit
    (``units`` or ``scale`` converts them to mm).  ``out`` is written as a
    whole (:func:`workbench.io.outputs.staged_folder`): an existing pack is
    replaced only with ``force`` and a failure leaves it as it was.
    Where the scan carries vertex colours or a UV texture (or ``texture``
    names the image its UVs refer to), the colour is carried onto the fitted
    skin (Lee, Terzopoulos & Waters 1993 did this with their scanner's
    reflectance image): ``skin_colour.ply`` (vertex colours) and
    ``skin_textured.obj`` + ``.mtl`` + ``skin_texture.png`` (an atlas) in
    the pack; skin away from the scan gets colour diffused from around.
    The scan's fine detail over the subdivided skin is written as
    ``skin_detailed.ply`` (the mesh) and ``skin_detail.npz`` (the layer, to
    re-detail an animated or aged skin: :mod:`workbench.io.skin_detail_export`),
    unless ``detail`` is False.
    ``extra(folder, result)`` writes further files into the staged pack (the
    CLI's PDF report, which needs the render layer) and returns their paths.
    """
    from workbench.core.colour_transfer import transfer_colours
    from workbench.core.units import check_units_choice, detect_units, resolve_units
    from workbench.io.catalogue import load_catalogue
    from workbench.io.markups import read_landmarks
    from workbench.io.meshes import read_mesh
    from workbench.io.outputs import check_output_folder, write_folder
    from workbench.io.scan_colours import read_scan_colours
    from workbench.io.skin_colour_export import write_coloured_skin
    from workbench.io.skin_detail_export import write_skin_detail
    from workbench.io.template_pack import export_template
    from workbench.model.evidence import file_sha256

    check_units_choice(units, scale)
    sources = [scan_path, landmarks, bone_path, texture]
    check_output_folder(out, sources, force)  # before the fit, which takes a while
    path = Path(scan_path)
    read = read_mesh(path, units=units if scale is None else "auto", scale=scale, kind="face")
    prepared = prepare_scan(read.mesh, path, progress)
    colours = _working_colours(read_scan_colours(path, texture=texture), read.mesh, prepared)
    if scale is None and units == "auto":  # judged on what is kept (not a stray blob)
        resolve_units(detect_units(prepared.mesh, "face"), "auto", source=str(path))
    factor = read.scale_applied
    inputs = [{"role": "scan", "file": path.name, "sha256": file_sha256(path)}]
    if texture is not None:
        inputs.append(
            {"role": "texture", "file": Path(texture).name, "sha256": file_sha256(Path(texture))}
        )
    lms = None
    if landmarks is not None:
        lms = read_landmarks(
            landmarks, "skin", catalogue=load_catalogue(), allow_undefined=True
        ).landmarks.transformed(np.diag([factor, factor, factor, 1.0]))
        inputs.append(
            {
                "role": "skin_landmarks",
                "file": Path(landmarks).name,
                "sha256": file_sha256(Path(landmarks)),
            }
        )
        from workbench.services.templates.cache import reference_head

        known = reference_head(sex).skin_landmarks.as_dict()
        check_landmarks_on_scan(lms, prepared.mesh, landmarks, path.name, known)
    bone = None
    if bone_path is not None:
        bone_sha = file_sha256(Path(bone_path))
        if bone_sha == inputs[0]["sha256"]:
            raise InputError(
                bone_path,
                f"(--bone) is the scan itself (the same content as {path.name}): the skin "
                "cannot be its own bone",
                "give the bone surface of the same CT (workbench mesh-from-ct CT --tissue "
                "bone), or leave --bone out",
            )
        bone = read_mesh(bone_path, scale=factor, kind="skull").mesh
        inputs.append({"role": "bone", "file": Path(bone_path).name, "sha256": bone_sha})
    result = fit_scan(
        prepared.mesh,
        landmarks=lms,
        sex=sex,
        table=table,
        build=build,
        orientation=orientation,
        bone=bone,
        source=str(path),
        inputs=inputs,
        progress=progress,
        detail=detail,
        bone_source=str(bone_path),
    )
    # (fit_scan prepared the prepared mesh again, finding nothing to do: the file's story)
    result = replace(result, warnings=(*prepared.notes, *result.warnings))
    result.figures["scan_preparation"] = prepared.figures

    from workbench.io.samples import credits_for

    credits = credits_for([path, bone_path])
    if credits:  # a CT's skin from the Visible Human data carries NLM's credit line
        result.figures["credits"] = credits

    def write(folder: Path) -> list[Path]:
        files = export_template(result.head, folder)
        if result.detail is not None:
            files += write_skin_detail(folder, result.detail, result.head.skin)
        if colours is not None and result.scan is not None:
            say = progress or (lambda _m: None)
            say("carrying the scan's colour onto the fitted skin ...")
            index = MeshIndex.shared(result.scan)
            skin_rgb = transfer_colours(result.head.skin, result.scan, colours, index=index)
            files += write_coloured_skin(
                folder,
                result.head.skin,
                skin_rgb,
                atlas_size=COLOUR_ATLAS_SIZE,
                scan=result.scan,
                scan_colours=colours,
                index=index,
            )
            result.figures["colour"] = {
                "kind": skin_rgb.kind,
                "observed_fraction": round(float(skin_rgb.observed_fraction), 4),
                "atlas_size": COLOUR_ATLAS_SIZE,
            }
        report = folder / "fit_report.json"
        report.write_text(
            json.dumps(
                {
                    "template_id": result.head.template_id,
                    "scan": path.name,
                    "mirrored_input": result.mirrored_input,
                    "input_to_head": result.input_to_head.tolist(),
                    "warnings": list(result.warnings),
                    **result.figures,
                },
                indent=2,
                default=_json_default,
            )
        )
        more = [] if extra is None else extra(folder, result)
        return [*files, report, *more]

    return result, write_folder(out, write, force=force, inputs=sources)


def _json_default(value: object) -> object:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, np.integer)):
        return value.item()
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")
