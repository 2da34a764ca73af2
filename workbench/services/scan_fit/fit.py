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
   :func:`~workbench.services.scan_fit.placement._uncovered`), and accepted when that part is at least
   :data:`~workbench.core.limits.MIN_SCAN_FACE_COVERAGE` of the face with the
   nose and its tip, matching well; the skin over no scan is inferred from
   the reference and marked (the pack's region ``inferred``,
   ``figures["inferred"]``).  A ``--bone`` away from the scan or on its skin,
   and two surfaces through each other, are refused before the fit; a fit
   with fold-overs asks for a check (``figures["self_check"]``, exit 3).
2. **Skin** (:func:`workbench.services.templates.build.fit_skin`): the scaled
   reference skin registered onto the scan, per-part affine stage then coarse
   to fine (:data:`~workbench.services.scan_fit.settings.SCAN_LEVELS`); hole and field-of-view rims fade out, thin
   sheets lying over more of the scan (a cord or strap over the face, hair:
   :func:`~workbench.services.scan_fit.sheets._sheets_over_scan`) are not matched, skin over no scan keeps the
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

:func:`fit_scan` runs the steps in this order (:func:`_orient`,
:func:`_fit_skin_to_scan`, :func:`~workbench.services.scan_fit.inside._place_inside`,
:func:`_settle`, :func:`_detail_layer`, :func:`_measure`, :func:`_with_provenance`);
the constants are in :mod:`~workbench.services.scan_fit.settings`.
"""

from __future__ import annotations

import hashlib
import json
import time
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, replace
from typing import TypeVar

import numpy as np
from scipy.spatial import cKDTree

from workbench.core.data_paths import DEFAULT_DEPTH_TABLE
from workbench.core.detail_layer import DetailLayer, build_detail
from workbench.core.errors import WorkbenchError
from workbench.core.face_pose import FacePlacement
from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh
from workbench.core.nonrigid import smoothstep
from workbench.core.rigid_search import PoseResult
from workbench.core.spatial import MeshIndex
from workbench.core.threads import worker_count
from workbench.core.visibility import field_of_view_caps, seen_from_outside
from workbench.model.template import TemplateHead
from workbench.services.scan_fit.checks import _check_bone, _check_one_shell, prepare_scan
from workbench.services.scan_fit.figures import (
    _depth_figures,
    _detail_section,
    _fold_figures,
    _landmark_figures,
    _orientation_figures,
    _scan_figures,
    _skin_figures,
    _skull_vs_bone,
)
from workbench.services.scan_fit.inside import _depth_pairs, _Inside, _place_inside
from workbench.services.scan_fit.placement import _place_face, _seed_pairs
from workbench.services.scan_fit.settings import (
    FIT_VERSION,
    RIM_EXCLUDE_MM,
    SHEET_PARTS,
    PreparedScan,
    Progress,
    ScanFit,
)
from workbench.services.scan_fit.sheets import _sheets_over_scan
from workbench.services.scan_fit.skin import _fit_skin_to_scan, _mask, _Skin

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


@dataclass(frozen=True)
class _Oriented:
    """Step 1's result (:func:`_orient`): the pose of the reference on the scan, the
    reference scaled to the person and the scan in its head frame (mm).

    Attributes
    ----------
    pose : PoseResult
        Scan (file frame) → reference head frame, with the reference's scale.
    placement : FacePlacement, optional
        The reference face laid on the scan (None when landmarks seeded the pose).
    scale : float
        ``pose.scale``: the scan's scale on the reference (the reference is scaled
        ``1 / scale``).
    rigid : (4, 4)
        Scan (file frame) → the person's head frame, without the scale.
    mirrored : bool
        ``rigid`` is a reflection (a mirrored scan).
    rest : TemplateHead
        The reference scaled to the person.
    scan_h : Mesh
        The scan in the head frame, wound outward.
    caps, cap_d : (n_scan,)
        Field-of-view lid vertices, and each vertex's distance to one (mm; inf
        without lids).
    seen : (n_scan,)
        Vertices a scanner could see (not the airway's, mouth's, nostrils' walls).
    layered : (n_scan,) bool
        Vertices on thin sheets over more of the scan (:func:`_sheets_over_scan`).
    belief : (n_scan,) float
        The skin registration's per-vertex belief in the scan.
    face_ids : (k,) int
        The reference skin's face-region vertices.
    """

    pose: PoseResult
    placement: FacePlacement | None
    scale: float
    rigid: np.ndarray
    mirrored: bool
    rest: TemplateHead
    scan_h: Mesh
    caps: np.ndarray
    cap_d: np.ndarray
    seen: np.ndarray
    layered: np.ndarray
    belief: np.ndarray
    face_ids: np.ndarray


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
    from workbench.services.templates.cache import reference_head

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
    o = _orient(scan, base, landmarks, orientation, source, warnings)
    seconds["orientation"] = time.perf_counter() - t0

    # 2. skin
    t = time.perf_counter()
    say("registering the reference skin onto the scan ...")
    sk = _fit_skin_to_scan(
        o.rest, o.scan_h, o.caps, o.belief, o.rigid, o.face_ids, base, landmarks, source, warnings
    )
    seconds["skin"] = time.perf_counter() - t

    # 3. the inside follows the skin at the table's depths
    t = time.perf_counter()
    say("placing skull, teeth, eyes and tongue at the table's tissue depths ...")
    inside = _place_inside(o.rest, sk.skin, sk.landmarks, sk.on_scan, pairs, table)
    seconds["inside"] = time.perf_counter() - t

    # 4. settle in the Frankfort frame of the estimated skull
    head, to_head, scan_h, ref_settled = _settle(inside.head, o.rigid, o.scan_h, o.rest)

    # 5. the scan's fine detail over the subdivided skin (the animatable skin keeps the
    # reference's 4 890 vertices; its ~4 mm edges cannot hold lid creases or lip borders)
    layer = None
    if detail:
        t = time.perf_counter()
        say("carrying the scan's fine detail onto the subdivided skin ...")
        layer = _detail_layer(head, scan_h, sk.fit.target_weights * o.seen, sk.skin, base)
        seconds["detail"] = time.perf_counter() - t

    # figures
    say("measuring the fit ...")
    t = time.perf_counter()
    fig, scan_distance = _measure(
        o,
        sk,
        inside,
        head,
        to_head,
        scan_h,
        ref_settled,
        layer,
        prepared,
        landmarks,
        pairs,
        table,
        depth_label,
        warnings,
    )
    seconds["figures"] = time.perf_counter() - t
    if bone is not None:  # the check against a true bone, not part of the fit
        t = time.perf_counter()
        fig["skull_vs_bone"] = _skull_vs_bone(head, bone, to_head, sk.face)
        seconds["skull_vs_bone"] = time.perf_counter() - t
    seconds["total"] = time.perf_counter() - t0
    fig["seconds"] = {k: round(v, 2) for k, v in seconds.items()}

    head = _with_provenance(
        head, base, inputs, table, sex, build, depth_label, to_head, o.mirrored, sk, fig, warnings
    )
    return ScanFit(
        head, to_head, o.mirrored, sk.on_scan, fig, tuple(warnings), scan_h, scan_distance, layer
    )


def _orient(
    scan: Mesh,
    base: TemplateHead,
    landmarks: LandmarkSet | None,
    orientation: tuple | None,
    source: str,
    warnings: list[str],
) -> _Oriented:
    """Step 1, orientation and size: the reference's pose on the (prepared) ``scan``, from
    the user's ``landmarks``, the ``orientation`` hint or the search with the face laid
    on the scan (:func:`_search`); the reference scaled to the person, the scan moved
    into its head frame, and the scan's belief for the skin registration (rims and
    field-of-view lids faded out, thin sheets over more of the scan left out).  A note on
    a size search stopped at its limit goes to ``warnings``."""
    from workbench.core.rigid_search import SCALE_RANGE
    from workbench.services.registration.skull_registration import head_transformed
    from workbench.services.templates.build import scan_in_frame
    from workbench.services.templates.regions import face_regions

    seeds = _seed_pairs(landmarks, base)
    regions = face_regions(base)
    face_ids = np.concatenate(list(regions.values()))
    # lids where a CT's volume ended (below the chin, a cut vault): not skin, and their
    # edges are rims like a hole's (found in the file's own axes, where the volume's
    # sides are)
    caps = field_of_view_caps(scan)
    pose, searched_scale, placement, seen = _search(
        scan, base, seeds, orientation, regions, source, caps
    )
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
    return _Oriented(
        pose,
        placement,
        s,
        rigid,
        mirrored,
        rest,
        scan_h,
        caps,
        cap_d,
        seen,
        layered,
        belief,
        face_ids,
    )


def _search(
    scan: Mesh,
    base: TemplateHead,
    seeds: tuple[np.ndarray, np.ndarray] | None,
    orientation: tuple | None,
    regions: Mapping[str, np.ndarray],
    source: str,
    caps: np.ndarray,
) -> tuple[PoseResult, float, FacePlacement | None, np.ndarray]:
    """The pose search (:func:`workbench.core.rigid_search.search_pose`) and, without
    ``seeds``, the reference face laid on the scan (:func:`_place_face`), with the scan's
    closest-point index, the one-shell check and the seen vertices found beside it.
    Returns the pose, the search's own scale, the face placement (or None) and the
    scan's seen vertices (the file's frame)."""
    from workbench.core.rigid_search import search_pose

    placement = None
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
            pose, placement, _ = _place_face(scan, base, pose, regions, source, caps)
        seen = seen_job()
    return pose, searched_scale, placement, seen


def _settle(
    head: TemplateHead, rigid: np.ndarray, scan_h: Mesh, rest: TemplateHead
) -> tuple[TemplateHead, np.ndarray, Mesh, TemplateHead]:
    """Step 4: ``head`` settled in the Frankfort frame of its estimated skull landmarks
    (unmoved when they do not give one).  Returns the head, the scan file → head frame
    transform, and the scan and the scaled reference ``rest`` moved with it."""
    from workbench.services.landmarks.frame import head_frame_from_landmarks
    from workbench.services.registration.skull_registration import head_transformed

    try:
        settle = head_frame_from_landmarks(head.skull_landmarks).input_to_head
    except WorkbenchError:
        settle = np.eye(4)
    head = head_transformed(head, settle)
    to_head = settle @ rigid
    scan_h = scan_h.transformed(settle)  # rigid: keeps borrowing the scan's index
    ref_settled = head_transformed(rest, settle)
    return head, to_head, scan_h, ref_settled


def _detail_layer(
    head: TemplateHead, scan_h: Mesh, believed: np.ndarray, skin: Mesh, base: TemplateHead
) -> DetailLayer:
    """Step 5: the scan's fine detail over the subdivided skin of the settled ``head``
    (:func:`workbench.core.detail_layer.build_detail`), ``believed`` per scan vertex, the
    ears (of ``base``, on the fitted ``skin``) held fixed."""
    # not the ears: their helix, antihelix and concha fold within millimetres of each
    # other at every angle, and a displacement there crosses a neighbouring fold (the
    # headsq fit gained ~110 new crossings at the ears, none elsewhere after the limits
    # of build_detail)
    ears = _mask(
        skin.n_vertices, [base.regions[r] for r in ("ear_l", "ear_r") if r in base.regions]
    )
    return build_detail(head.skin, scan_h, believed, fixed=ears)


def _measure(
    o: _Oriented,
    sk: _Skin,
    inside: _Inside,
    head: TemplateHead,
    to_head: np.ndarray,
    scan_h: Mesh,
    ref_settled: TemplateHead,
    layer: DetailLayer | None,
    prepared: PreparedScan,
    landmarks: LandmarkSet | None,
    pairs: Mapping[str, tuple[str, float]],
    table: str,
    depth_label: str,
    warnings: list[str],
) -> tuple[dict, np.ndarray]:
    """The fit's figures (:mod:`~workbench.services.scan_fit.figures`, in the report's
    order) and each scan vertex's distance to the fitted skin (NaN where not counted);
    the notes go to ``warnings``."""
    fitted = head.skin
    fig, counted, scan_distance = _scan_figures(
        scan_h,
        fitted,
        sk.face,
        o.seen,
        o.layered,
        o.cap_d,
        sk.fit.target_weights,
        o.caps,
        prepared,
        warnings,
    )
    fig.update(
        _skin_figures(
            sk.to_scan, sk.face, sk.facing, sk.on_scan, sk.shown_share, sk.partial, warnings
        )
    )
    fig.update(_fold_figures(fitted, ref_settled, sk.ref_cross, sk.untangled, head))
    fig.update(_detail_section(layer, fitted, scan_h, counted, sk.face, warnings))
    fig.update(_landmark_figures(sk.landmarks, sk.absent, sk.index, landmarks, to_head, head))
    fig.update(
        _depth_figures(
            head,
            pairs,
            inside.codes,
            inside.depth,
            table,
            depth_label,
            fitted,
            sk.face,
            inside.eye_shift,
        )
    )
    fig.update(_orientation_figures(o.pose, o.mirrored, o.scale, o.placement, sk.fit, sk.cut_ears))
    return fig, scan_distance


def _with_provenance(
    head: TemplateHead,
    base: TemplateHead,
    inputs: Sequence[Mapping],
    table: str,
    sex: str,
    build: str | float,
    depth_label: str,
    to_head: np.ndarray,
    mirrored: bool,
    sk: _Skin,
    fig: dict,
    warnings: list[str],
) -> TemplateHead:
    """The fitted ``head`` with its id (``base``'s, the inputs' and the table's digest), its
    provenance (inputs, method, frame, figures, notes) and the region ``inferred`` (the
    skin over no scan)."""
    absent_skin, on_scan = sk.absent, sk.on_scan
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
    return replace(
        head,
        template_id=f"{base.template_id}/scan/{digest}",
        provenance=provenance,
        # the skin the scan does not support: the reference's shape (see figures["inferred"])
        regions={**head.regions, "inferred": np.flatnonzero(~on_scan)},
    )
