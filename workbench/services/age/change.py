"""Growth and age change of a head from anthropometric norms (issue 15; Kähler 2003 §8.5).

Units mm; the head is in its Frankfort frame (x to the subject's left,
x = 0 midsagittal, y up, z toward the face), where the axis-aligned
measurements (horizontal = x, vertical = y, depth = z) are read.

1. **Measure** every measurement with norms for the sex and ethnicity at
   both ages (:mod:`workbench.io.growth_norms`: straight-line distances
   between skin landmarks; pupils from the eyeballs) and the head
   circumference (:func:`workbench.core.head_measure.head_circumference_mm`).
2. **Targets** (§8.5.4): each measurement keeps its z-score,
   d_t = μ_t + (σ_t/σ_c)(d_c − μ_c).  The global factor s is the head
   circumference's change at a kept z-score (WHO 2006 below 4 y, UK90 from
   4 y; ages past the chart's end are read at its last age, since the head
   hardly grows after 18: the digest's 2–4 % after 20).  The vault's height
   (vertex over the porions) keeps its z-score in its own norms (Dezső 1967,
   7-17 y), not the face's, where they cover both ages
   (:mod:`workbench.services.age.targets`).
3. **Solve** (§8.5.3, :func:`workbench.core.growth_solve.solve_landmarks`):
   the measurements with norms are hard constraints; Kähler's Table 8.2
   measurements without norms here and each landmark's nearby pairs are
   soft constraints scaled by s; the tragia's midpoint (the head frame's
   origin lies between the porions) anchors the translation.
4. **Arcs** after the solve (§8.5.3): for each arc of Table 8.2 a middle
   point on the skin (the skin point over the chord's middle) is moved
   along the skin normal so that the circle segment through it has the
   target arc length (s times the current one, plus the optional young-child
   increase of up to 10 %, §8.5.5).
5. **Deform the whole head** (§8.3.2): a landmark spline from the current
   landmarks (and arc middles) to the solved ones (Kähler's, with a rounded
   kernel that leaves no crease at a landmark:
   :mod:`workbench.services.age.smooth_warp`) moves skin, skull, teeth,
   tongue and eyes; each skull landmark is then put back at
   its source tissue depth below its skin partner (no depth table by age is
   shipped: the source head's depths are kept, not scaled with the head) by
   a second, smooth warp of the inner parts; the eyeballs are scaled about
   their centres by their own growth (axial length by age) and seated in
   the lids (:mod:`workbench.services.age.eyes`); the result is settled in
   the Frankfort frame of its skull landmarks.  Muscles are skin triangles
   with barycentric weights, so they ride on the new skin.

The warp steps (4-5) are in :mod:`workbench.services.age.warp_steps`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from workbench.core.errors import InputError, WorkbenchError
from workbench.core.growth_solve import (
    CONDITION_NUMBER,
    Constraint,
    SoftPair,
    arc_length,
    solve_landmarks,
)
from workbench.core.head_measure import head_section, section_perimeter
from workbench.core.mesh import Mesh
from workbench.core.spatial import MeshIndex
from workbench.model.template import TemplateHead
from workbench.services.age.growth_tables import load_eyeball_growth
from workbench.services.age.proportions import proportion_figures
from workbench.services.age.targets import (
    HEAD_SIZE,
    VAULT_HEIGHTS,
    HeadSize,
    MeasurementRow,
    head_size,
    norm_targets,
    scale_targets,
    vault_targets,
)
from workbench.services.age.targets import (  # re-exported: callers import them from here
    hc_scale as hc_scale,
)
from workbench.services.age.targets import (
    measure_circumference as measure_circumference,
)
from workbench.services.age.targets import rounded as _r
from workbench.services.age.warp_steps import (
    SLIVER_MM2,
    arc_middles,
    deform,
    inside_before,
    skin_out_of_skull,
    skin_warp,
    warp_points,
)
from workbench.services.age.warp_steps import (
    unfold as unfold,  # re-exported: callers import it from here
)

Progress = Callable[[str], None]

#: youngest and oldest age (years) a request may name at all (the tables decide within)
AGE_LIMITS = (0.0, 100.0)
#: the young-child arc-length increase is capped at Kähler's 10 % (§8.5.5)
MAX_ARC_INCREASE = 0.10
#: nearest landmarks each landmark is softly tied to
SOFT_NEIGHBOURS = 4
#: rounds of the head-size correction (the tape predicted from the warp, a secant step)
HEAD_SIZE_ROUNDS = 4


@dataclass(frozen=True)
class AgeResult:
    """A head aged from ``from_age`` to ``to_age`` and how every measurement came out."""

    head: TemplateHead
    from_age: float
    to_age: float
    sex: str
    rows: tuple[MeasurementRow, ...]
    figures: Mapping[str, Any]
    warnings: tuple[str, ...] = ()
    landmarks_before: Mapping[str, np.ndarray] = field(default_factory=dict)
    landmarks_after: Mapping[str, np.ndarray] = field(default_factory=dict)


def in_frankfort_frame(head: TemplateHead) -> tuple[TemplateHead, bool]:
    """``head`` moved into the Frankfort frame of its skull landmarks, and whether it moved.

    Axis-aligned measurements and the head circumference's plane are read in
    this frame; a head already in it (a template pack) is returned as is.
    """
    from workbench.services.landmarks.frame import input_frame
    from workbench.services.registration.skull_registration import head_transformed

    try:
        settle, mirrored = input_frame(head.skull_landmarks)
    except WorkbenchError:
        return head, False
    # a pack already in its frame (to within 0.05 mm and 0.01°: the frame re-measured on
    # its own landmarks) stays as it is
    if np.allclose(settle[:3, :3], np.eye(3), atol=2e-4) and np.abs(settle[:3, 3]).max() < 0.05:
        return head, False
    moved = head_transformed(head, settle)
    if mirrored:
        # a reconstruction of a mirrored skull file is stored mirrored, with its triangles
        # wound the other way to keep the normals outward; the reflection back restores the
        # reference's own winding (the muscles' triangles and morph targets rely on it)
        moved = replace(
            moved, meshes={k: Mesh(m.vertices, m.faces[:, ::-1]) for k, m in moved.meshes.items()}
        )
    return moved, True


def head_points(head: TemplateHead) -> dict[str, np.ndarray]:
    """Skin landmarks of ``head`` (mm) plus the pupils (corneal apex of each eyeball, gaze +z)."""
    pts = dict(head.skin_landmarks.as_dict())
    for c in head.eye_centres:
        code = "p_l" if c[0] > 0 else "p_r"
        pts.setdefault(code, c + np.array([0.0, 0.0, head.eye_radius]))
    return pts


def _check_age(value: float, what: str) -> float:
    age = float(value)
    if not np.isfinite(age) or not AGE_LIMITS[0] <= age <= AGE_LIMITS[1]:
        raise InputError(
            what, f"age {value} is not an age in years", f"give {AGE_LIMITS[0]:g}-{AGE_LIMITS[1]:g}"
        )
    return age


_NORMS: dict[tuple[str, int], Any] = {}


def _cached_norms(norms: str, load: Callable[[str], Any]) -> Any:
    """A norms table loaded once per file version (tables are immutable values)."""
    from workbench.io.growth_norms import growth_dir

    path = Path(norms) if str(norms).lower().endswith(".csv") else growth_dir() / f"{norms}.csv"
    try:
        key = (str(path.resolve()), path.stat().st_mtime_ns)
    except OSError:
        return load(norms)  # let the loader say what is wrong with it
    if key not in _NORMS:
        _NORMS[key] = load(norms)
    return _NORMS[key]


def age_head(
    head: TemplateHead,
    *,
    sex: str,
    from_age: float,
    to_age: float,
    norms: str = "facial_norms",
    ethnicity: str | None = None,
    arc_increase: float = 0.0,
    progress: Progress | None = None,
) -> AgeResult:
    """``head`` (aged ``from_age``, head frame, mm) changed to ``to_age`` years.

    Raises
    ------
    InputError
        An age outside what the norms cover, an unknown ethnicity or norms
        table, a head without the landmarks the method needs, an arc
        increase outside 0–10 %.
    """
    from workbench.io.growth_norms import load_head_circumference

    say = progress or (lambda _m: None)
    t0 = time.perf_counter()
    a0, a1, table, eth = _checked_request(sex, from_age, to_age, norms, ethnicity, arc_increase)
    hc_ref = load_head_circumference()
    notes: list[str] = []

    head, reframed = in_frankfort_frame(head)
    if reframed:
        notes.append(
            "the head was not in its Frankfort frame (a reconstruction is stored in the skull "
            "file's frame): measured and aged in the frame of its porions and orbitales"
        )
    pts = head_points(head)
    codes = list(pts)
    index = {c: i for i, c in enumerate(codes)}
    p = np.array([pts[c] for c in codes])

    # 1-2. measure and set the targets
    say("measuring the head ...")
    rows, hard = norm_targets(table, sex, eth, a0, a1, p, index, hc_ref.age_range(sex)[1])
    vault_rows, vault_hard = vault_targets(sex, a0, a1, p, index, notes)
    rows += vault_rows
    hard += vault_hard
    size = head_size(head, hc_ref, sex, a0, a1, notes)
    held = [h for h in HEAD_SIZE if not (vault_hard and h in VAULT_HEIGHTS)]
    soft, arcs = scale_targets(p, index, size.scale, rows, hard, held)
    anchor = [index[c] for c in ("t_l", "t_r") if c in index] or [
        index[c] for c in ("po_l", "po_r") if c in index
    ]
    if not anchor:
        raise InputError("HEAD", "has neither tragia nor porions: the growth solve has no anchor")

    # 3-4. solve, then the arcs
    say("solving the landmark constraints ...")
    solved = _solve_to_head_size(head, pts, p, hard, soft, arcs, index, size, arc_increase, anchor)

    # 5. deform the whole head
    say("warping the head ...")
    eye_scale = load_eyeball_growth().scale(a0, a1)
    aged = deform(head, solved.warp, eye_scale)
    aged, pushed, skull = skin_out_of_skull(
        aged, head.skin.face_normals, keep=head.skin.face_areas < SLIVER_MM2
    )
    seconds = time.perf_counter() - t0

    # the report: measure the aged head as it came out
    after = head_points(aged)
    out_rows = _rows_after(rows, after, size.scale)
    out_rows += _arc_rows_after(aged, after, solved.arc_rows, arc_increase)
    figures: dict[str, Any] = {
        "from_age": a0,
        "to_age": a1,
        "sex": sex,
        "ethnicity": eth,
        "norms": table.norms_id,
        "hard_constraints": len(solved.hard),
        "soft_constraints": len(soft),
        **_outcome_figures(head, aged, skull, out_rows, hc_ref, sex, size, solved),
        "skin_vertices_moved_out_of_skull": pushed,
        **_fold_figures(head, aged),
        "vault_height": "head-ear height norms (Dezső 1967)"
        if vault_hard
        else "head-circumference scale",
        **proportion_figures(head, aged, eye_scale),
        "seconds": round(seconds, 3),
        "unconstrained": [r.measurement_id for r in out_rows if r.constraint == "unconstrained"],
    }
    warnings = tuple(dict.fromkeys(notes))
    before_lm = {c: p[i] for i, c in enumerate(codes)}
    return AgeResult(
        aged,
        a0,
        a1,
        sex,
        tuple(out_rows),
        figures,
        warnings,
        before_lm,
        {c: after[c] for c in codes if c in after},
    )


def _checked_request(
    sex: str,
    from_age: float,
    to_age: float,
    norms: str,
    ethnicity: str | None,
    arc_increase: float,
) -> tuple[float, float, Any, str]:
    """The request's ages (years), its norms table and ethnicity, after checking them.

    Raises :class:`InputError` for an age outside :data:`AGE_LIMITS`, a sex
    other than female or male, an arc increase outside 0–10 % and an
    ethnicity the norms table does not have (in that order).
    """
    from workbench.io.growth_norms import load_growth_norms

    a0 = _check_age(from_age, "--from")
    a1 = _check_age(to_age, "--to")
    if sex not in ("female", "male"):
        raise InputError("--sex", f"'{sex}' is not female or male")
    if not 0.0 <= arc_increase <= MAX_ARC_INCREASE:
        raise InputError(
            "--arc-increase",
            f"{arc_increase:g} is outside 0-{MAX_ARC_INCREASE:g} (Kähler's young-child arc "
            "increase is at most 10 %)",
        )
    table = _cached_norms(norms, load_growth_norms)
    known = table.ethnicities()
    eth = ethnicity or ("European" if "European" in known else known[0])
    eth = next((k for k in known if k.lower() == eth.lower()), eth)
    if eth not in known:
        raise InputError(
            "--ethnicity", f"'{eth}' has no norms in {table.norms_id}", "known: " + ", ".join(known)
        )
    return a0, a1, table, eth


@dataclass(frozen=True)
class _Solved:
    """The landmark solve after the head-size correction and the skin warp it gives."""

    hard: list[Constraint]  # the hard constraints of the last round (head-size targets corrected)
    sol: Any  # the last round's solve (workbench.core.growth_solve)
    warp: Any  # the skin's thin-plate spline, source head frame -> aged (mm)
    arc_rows: list[tuple[Any, float, float]]  # (arc, current length, target length), mm
    landmark_solve_s: list[float]  # seconds of each round's landmark solve
    solve_s: float  # seconds of the whole loop with its warps


def _solve_to_head_size(
    head: TemplateHead,
    pts: Mapping[str, np.ndarray],
    p: np.ndarray,
    hard: list[Constraint],
    soft: list[SoftPair],
    arcs: list[Any],
    index: Mapping[str, int],
    size: HeadSize,
    arc_increase: float,
    anchor: list[int],
) -> _Solved:
    """Solve the landmarks (§8.5.3), then the arcs, correcting the head-size targets.

    Each round scales the head-size targets by k until the skin's tape
    around the head (its g-op section moved by the round's warp, mm) meets
    the chart's target circumference (a secant step, at most
    :data:`HEAD_SIZE_ROUNDS` rounds).
    """
    t_solve = time.perf_counter()
    section = head_section(head.skin, pts["g"], pts["op"])
    size_rows = [i for i, c in enumerate(hard) if c.label in HEAD_SIZE]
    skin_index = MeshIndex(head.skin) if arcs else None
    k_size = 1.0
    landmark_solve_s: list[float] = []
    for _round in range(HEAD_SIZE_ROUNDS):
        hard_k = [
            replace(c, target=c.target * k_size) if i in size_rows else c
            for i, c in enumerate(hard)
        ]
        t_ls = time.perf_counter()
        sol = solve_landmarks(p, hard_k, soft, size.scale, anchor)
        landmark_solve_s.append(time.perf_counter() - t_ls)
        q = sol.points
        src, dst, lam, arc_rows = warp_points(
            head, p, q, hard_k, arcs, index, size.scale, arc_increase, skin_index
        )
        warp = skin_warp(src, dst, lam)
        moved = warp(np.vstack([section, pts["g"], pts["op"]]))
        predicted = section_perimeter(moved[:-2], moved[-2], moved[-1])
        if not np.isfinite(predicted) or abs(predicted / size.hc_t - 1.0) < 1e-3:
            break
        k_size *= size.hc_t / predicted
    solve_s = time.perf_counter() - t_solve
    return _Solved(hard_k, sol, warp, arc_rows, landmark_solve_s, solve_s)


def _rows_after(
    rows: Sequence[MeasurementRow], after: Mapping[str, np.ndarray], scale: float
) -> list[MeasurementRow]:
    """``rows`` measured again on the aged head's landmarks ``after`` (mm), with targets."""
    from workbench.io.growth_table82 import AXIS_OF

    out_rows = []
    for row in rows:
        if row.constraint == "unconstrained":
            out_rows.append(row)
            continue
        a, b = after.get(row.a), after.get(row.b)
        if a is None or b is None:
            out_rows.append(replace(row, note=(row.note + "; landmark lost").strip("; ")))
            continue
        if row.kind in AXIS_OF:
            ax = AXIS_OF[row.kind]
            value = float(abs(a[ax] - b[ax]))
        else:
            value = float(np.linalg.norm(a - b))
        target = row.target_mm if row.constraint == "norms" else scale * row.before_mm
        out_rows.append(replace(row, after_mm=value, target_mm=target))
    return out_rows


def _arc_rows_after(
    aged: TemplateHead,
    after: Mapping[str, np.ndarray],
    arc_rows: Sequence[tuple[Any, float, float]],
    arc_increase: float,
) -> list[MeasurementRow]:
    """The rows of the arcs, measured over the aged skin (circle segment through the skin
    point over the chord's middle, mm)."""
    out_rows = []
    if arc_rows:
        mids_new, normals_new = arc_middles(
            aged.skin,
            MeshIndex(aged.skin),
            np.array([after[t.a] for t, _, _ in arc_rows]),
            np.array([after[t.b] for t, _, _ in arc_rows]),
        )
    for k, (t, arc_c, arc_t) in enumerate(arc_rows):
        mid_new, normal = mids_new[k], normals_new[k]
        chord = float(np.linalg.norm(after[t.a] - after[t.b]))
        h = max(0.0, float((mid_new - (after[t.a] + after[t.b]) / 2) @ normal))
        out_rows.append(
            MeasurementRow(
                t.measurement,
                t.measurement,
                "arc",
                t.a,
                t.b,
                "scale",
                arc_c,
                after_mm=arc_length(chord, h),
                target_mm=arc_t,
                note="arc over the skin (circle segment through the middle point); "
                f"head scale{' + young-child increase' if arc_increase else ''}",
            )
        )
    return out_rows


def _outcome_figures(
    head: TemplateHead,
    aged: TemplateHead,
    skull: MeshIndex,
    out_rows: Sequence[MeasurementRow],
    hc_ref: Any,
    sex: str,
    size: HeadSize,
    solved: _Solved,
) -> dict[str, Any]:
    """The report's figures of the residuals, the circumference, the solve and the face
    skin inside the skull (source ``head`` and ``aged`` head, mm)."""
    hc_after = measure_circumference(aged)
    normed = [r for r in out_rows if r.constraint == "norms"]
    res = np.array([abs(r.residual_mm) for r in normed])
    dz = np.array([abs(r.z_after - r.z_before) for r in normed])
    face = np.unique(np.concatenate([np.asarray(v) for k, v in aged.regions.items()]))
    inside = int((skull.signed_distance(aged.skin.vertices[face]) < 0).sum())
    inside0 = inside_before(head, face)
    sol = solved.sol
    h0, h1 = size.h0, size.h1
    return {
        "hard_residual_mm": {
            "median": _r(float(np.median(res)), 3),
            "max": _r(float(res.max()), 3),
        },
        "z_change_max": _r(float(dz.max()), 4),
        "global_scale": round(float(size.scale), 5),
        "head_circumference_mm": {
            "before": _r(size.hc_c, 1),
            "after": _r(hc_after, 1),
            "target": _r(size.hc_t, 1),
            "z_before": _r(size.z_hc, 3),
            "z_after": _r(hc_ref.z(sex, h1, hc_after), 3),
            "chart": f"{hc_ref.reference_for(h0)} at {h0:g} y, {hc_ref.reference_for(h1)} at {h1:g} y",
        },
        "solve": {
            # the landmark solve (per head-size round) and the whole loop with its warps
            "seconds": round(max(solved.landmark_solve_s), 4),
            "head_size_rounds": len(solved.landmark_solve_s),
            "with_head_size_correction_seconds": round(solved.solve_s, 4),
            "rounds": sol.rounds,
            "condition_number_limit": CONDITION_NUMBER,
            "condition": [round(c, 1) for c in sol.condition],
            "dropped_singular_values": list(sol.dropped_singular_values),
        },
        # the reference heads have a few orbit vertices a fraction of a mm inside the bone
        "face_skin_inside_skull_vertices": {"after": inside, "before": inside0},
    }


def _fold_figures(head: TemplateHead, aged: TemplateHead) -> dict[str, int]:
    """Skin triangles the age change turned over (against the source head's normals)."""
    folded = (head.skin.face_normals * aged.skin.face_normals).sum(axis=1) < 0
    sliver = head.skin.face_areas < SLIVER_MM2
    return {
        # turned-over skin triangles, apart from the reference's own slivers at the mouth
        # corners (< 0.05 mm², the lips' seam), which are counted on their own
        "fold_overs": int((folded & ~sliver).sum()),
        "fold_overs_mouth_corner_slivers": int((folded & sliver).sum()),
    }


def aged_template_id(head: TemplateHead, from_age: float, to_age: float) -> str:
    return f"{head.template_id}/age/{from_age:g}-{to_age:g}"
