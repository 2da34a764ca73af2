"""Checks of a scan fit's inputs, before the fit: refusals that name what is wrong.

* :func:`prepare_scan` (and :func:`check_scan_mesh`, which keeps nothing):
  a point cloud, too few or too many triangles, non-finite vertices, two
  bodies in one file or a size not a head's are refused; coincident vertices
  are welded, degenerate and repeated triangles dropped, stray pieces left
  out, the winding made outward, and a very large scan simplified.
* :func:`check_landmarks_on_scan`: a landmark file that does not belong to
  the scan (coincident points, points off the scan, another frame or unit).
* :func:`_check_one_shell`: two surfaces through each other.
* :func:`_check_bone`: a ``--bone`` that does not lie beneath the scan's skin.

Units mm; everything here is in the scan file's frame (after ``--units`` /
``--scale``), before the scan is oriented.
"""

from __future__ import annotations

from collections.abc import Mapping
from os import PathLike

import numpy as np
from scipy.spatial import cKDTree

from workbench.core.errors import InputError
from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh
from workbench.core.self_intersection import self_intersections
from workbench.core.spatial import MeshIndex
from workbench.core.threads import worker_count
from workbench.services.scan_fit.settings import (
    BONE_BOX_MARGIN_MM,
    BONE_IN_BOX,
    BONE_ON_SKIN,
    BONE_ON_SKIN_MM,
    LANDMARKS_APART_MM,
    MIN_SCAN_TRIANGLES,
    SCAN_EXTENT_MM,
    SECOND_PIECE,
    SHELL_CROSSINGS,
    PreparedScan,
    Progress,
)


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


def _check_one_shell(scan: Mesh, source: str | PathLike[str]) -> None:
    """Refuse a scan that cuts through itself along a long curve: two surfaces through
    each other (two overlapping heads, a head merged twice out of register), which
    :func:`_one_body` does not see when they touch (:data:`SHELL_CROSSINGS`)."""
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
