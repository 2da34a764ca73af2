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
   hardly grows after 18: the digest's 2–4 % after 20).
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
5. **Deform the whole head** (§8.3.2): a thin-plate spline from the
   current landmarks (and arc middles) to the solved ones moves skin,
   skull, teeth, tongue and eyes; the eyeballs move with their centres and
   scale by the warp's local size change; each skull landmark is then put
   back at its source tissue depth below its skin partner (no depth table
   by age is shipped: the source head's depths are kept, not scaled with
   the head) by a second, smooth warp of the inner parts; the result is
   settled in the Frankfort frame of its skull landmarks.  Muscles are skin
   triangles with barycentric weights, so they ride on the new skin.

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
    nearby_pairs,
    solve_landmarks,
)
from workbench.core.head_measure import head_circumference_mm, head_section, section_perimeter
from workbench.core.mesh import Mesh
from workbench.core.spatial import MeshIndex
from workbench.model.template import TemplateHead
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
#: Table 8.2's head-size measurements: with no norms here they are *hard* constraints at
#: the head-circumference scale s, since the circumference chart is the norm of the head's
#: size (as soft pairs the face's norms pulled the vault along: 0.7 % below the chart)
HEAD_SIZE = ("depth:g-op", "horizontal:t_l-t_r", "vertical:v-t_l", "vertical:v-t_r")
#: rounds of the head-size correction (the tape predicted from the warp, a secant step)
HEAD_SIZE_ROUNDS = 4


@dataclass(frozen=True)
class MeasurementRow:
    """One measurement before and after (mm; z-scores against the norms of the sex)."""

    measurement_id: str
    name: str
    kind: str
    a: str
    b: str
    constraint: str  # "norms" (hard), "scale" (follows s), "unconstrained"
    before_mm: float
    after_mm: float = float("nan")
    target_mm: float = float("nan")
    mean_from: float = float("nan")
    sd_from: float = float("nan")
    mean_to: float = float("nan")
    sd_to: float = float("nan")
    source: str = ""
    note: str = ""

    @property
    def z_before(self) -> float:
        return (self.before_mm - self.mean_from) / self.sd_from

    @property
    def z_after(self) -> float:
        return (self.after_mm - self.mean_to) / self.sd_to

    @property
    def residual_mm(self) -> float:
        return self.after_mm - self.target_mm

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "measurement_id": self.measurement_id,
            "name": self.name,
            "kind": self.kind,
            "landmarks": [self.a, self.b],
            "constraint": self.constraint,
            "before_mm": _r(self.before_mm),
            "target_mm": _r(self.target_mm),
            "after_mm": _r(self.after_mm),
            "residual_mm": _r(self.residual_mm),
        }
        if self.constraint == "norms":
            out |= {
                "norm_from": {"mean_mm": _r(self.mean_from), "sd_mm": _r(self.sd_from)},
                "norm_to": {"mean_mm": _r(self.mean_to), "sd_mm": _r(self.sd_to)},
                "z_before": _r(self.z_before, 3),
                "z_after": _r(self.z_after, 3),
                "source": self.source,
            }
        if self.note:
            out["note"] = self.note
        return out


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


def _missing_row(
    measurement_id: str, name: str, kind: str, a: str, b: str, index: Mapping[str, int]
) -> MeasurementRow:
    """The row of a measurement the head's landmarks do not allow (named in its note)."""
    gone = " and ".join(c for c in (a, b) if c not in index)
    return MeasurementRow(
        measurement_id,
        name,
        kind,
        a,
        b,
        "unconstrained",
        float("nan"),
        note=f"landmark {gone} missing on the head",
    )


def _r(value: float, digits: int = 2) -> float | None:
    return None if not np.isfinite(value) else round(float(value), digits)


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


def measure_circumference(head: TemplateHead) -> float:
    """Head circumference (mm) over glabella and opisthocranion, or NaN if either is absent."""
    pts = head.skin_landmarks.as_dict()
    if "g" not in pts or "op" not in pts:
        return float("nan")
    return head_circumference_mm(head.skin, pts["g"], pts["op"])


def _check_age(value: float, what: str) -> float:
    age = float(value)
    if not np.isfinite(age) or not AGE_LIMITS[0] <= age <= AGE_LIMITS[1]:
        raise InputError(
            what, f"age {value} is not an age in years", f"give {AGE_LIMITS[0]:g}-{AGE_LIMITS[1]:g}"
        )
    return age


def _hc_age(hc: Any, sex: str, age: float, notes: list[str]) -> float:
    lo, hi = hc.age_range(sex)
    if age > hi:
        notes.append(
            f"head circumference at {age:g} y read at the chart's last age {hi:g} y "
            "(the head hardly grows after it)"
        )
        return float(hi)
    return max(float(lo), age)


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


def hc_scale(hc: Any, sex: str, a0: float, a1: float, z: float) -> float:
    """Factor by which a head circumference at z-score ``z`` changes from age a0 to a1.

    Within one chart: value_at(a1, z) / value_at(a0, z).  Across the WHO →
    UK90 switch at 4 y the two charts disagree in level (the UK90 median at
    4 y is 20 mm, 1.4 SD, above the WHO one for boys), so the z-score read in
    one chart is not the same head in the other: the change is chained at the
    switch age, each chart giving only its own ratio at the same relative
    position z.
    """
    switch = 4.0
    lo, hi = sorted((a0, a1))
    if hi < switch or lo >= switch:
        return float(hc.value_at(sex, a1, z) / hc.value_at(sex, a0, z))
    below = hc.value_at(sex, switch - 1e-9, z) / hc.value_at(sex, lo, z)
    above = hc.value_at(sex, hi, z) / hc.value_at(sex, switch, z)
    growth = float(below * above)
    return growth if a1 > a0 else 1.0 / growth


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
    rows, hard = _norm_targets(table, sex, eth, a0, a1, p, index)
    size = _head_size(head, hc_ref, sex, a0, a1, notes)
    soft, arcs = _scale_targets(p, index, size.scale, rows, hard)
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
    aged = deform(head, solved.warp)
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


def _norm_targets(
    table: Any,
    sex: str,
    eth: str,
    a0: float,
    a1: float,
    p: np.ndarray,
    index: Mapping[str, int],
) -> tuple[list[MeasurementRow], list[Constraint]]:
    """Rows of the measurements with norms and the hard constraints they give (§8.5.4).

    ``p`` holds the head's landmarks (mm, Frankfort frame) in the order of
    ``index``.  Each measurement with norms at both ages keeps its z-score,
    d_t = μ_t + (σ_t/σ_c)(d_c − μ_c); one whose norms do not cover both ages
    follows the head scale, one the head's landmarks do not allow is listed
    as unconstrained.  Raises :class:`InputError` when an age lies outside
    every measurement's norms or when no hard constraint is left.
    """
    rows: list[MeasurementRow] = []
    hard: list[Constraint] = []
    usable_ages: list[tuple[float, float]] = []
    for m in table.measurements:
        if not table.has(m.measurement_id, sex, eth):
            continue
        lo, hi = table.age_range(m.measurement_id, sex, eth)
        usable_ages.append((lo, hi))
        if m.a not in index or m.b not in index:
            rows.append(_missing_row(m.measurement_id, m.name, m.kind, m.a, m.b, index))
            continue
        d_c = float(np.linalg.norm(p[index[m.a]] - p[index[m.b]]))
        if not (lo <= a0 <= hi and lo <= a1 <= hi):
            rows.append(
                MeasurementRow(
                    m.measurement_id,
                    m.name,
                    m.kind,
                    m.a,
                    m.b,
                    "scale",
                    d_c,
                    note=f"norms cover {lo:g}-{hi:g} y only: follows the head scale",
                )
            )
            continue
        mu_c, sd_c = table.at(m.measurement_id, sex, a0, eth)
        mu_t, sd_t = table.at(m.measurement_id, sex, a1, eth)
        d_t = mu_t + (sd_t / sd_c) * (d_c - mu_c)  # Kähler §8.5.4
        hard.append(Constraint(index[m.a], index[m.b], d_t, None, m.measurement_id))
        rows.append(
            MeasurementRow(
                m.measurement_id,
                m.name,
                m.kind,
                m.a,
                m.b,
                "norms",
                d_c,
                target_mm=d_t,
                mean_from=mu_c,
                sd_from=sd_c,
                mean_to=mu_t,
                sd_to=sd_t,
                source=table.source_of(m.measurement_id, sex, eth),
            )
        )
    if usable_ages:
        lo_all = min(a for a, _ in usable_ages)
        hi_all = max(b for _, b in usable_ages)
        for age, what in ((a0, "--from"), (a1, "--to")):
            if not lo_all <= age <= hi_all:
                raise InputError(
                    what,
                    f"age {age:g} y is outside the norms' range {lo_all:g}-{hi_all:g} y "
                    f"({table.norms_id}, {sex}, {eth})",
                    "choose an age the norms cover, or import a norms table that covers it "
                    "(--norms FILE.csv)",
                )
    if not hard:
        raise InputError(
            "--norms",
            f"{table.norms_id} gives no measurement with norms at both {a0:g} and {a1:g} y "
            f"for {sex}, {eth} that the head's landmarks allow",
        )
    return rows, hard


@dataclass(frozen=True)
class _HeadSize:
    """The head circumference before and at the target age, and the global scale s."""

    hc_c: float  # measured on the source head (mm)
    h0: float  # the chart's ages read for the source and target ages (years)
    h1: float
    z_hc: float  # the source's z-score on the chart
    scale: float  # s: the circumference's change at a kept z-score
    hc_t: float  # target circumference, s · hc_c (mm)


def _head_size(
    head: TemplateHead, hc_ref: Any, sex: str, a0: float, a1: float, notes: list[str]
) -> _HeadSize:
    """The head circumference's change from ``a0`` to ``a1`` years at a kept z-score.

    Raises :class:`InputError` when the circumference cannot be measured;
    chart notes (ages read at the chart's end) are added to ``notes``.
    """
    hc_c = measure_circumference(head)
    if not np.isfinite(hc_c):
        raise InputError(
            "HEAD",
            "the head circumference cannot be measured (glabella or opisthocranion missing, or "
            "no closed section of the skin through them)",
            "the global scale of measurements without norms comes from it",
        )
    h0 = _hc_age(hc_ref, sex, a0, notes)
    h1 = _hc_age(hc_ref, sex, a1, notes)
    z_hc = hc_ref.z(sex, h0, hc_c)
    scale = hc_scale(hc_ref, sex, h0, h1, z_hc)
    return _HeadSize(hc_c, h0, h1, z_hc, scale, scale * hc_c)


def _scale_targets(
    p: np.ndarray,
    index: Mapping[str, int],
    scale: float,
    rows: list[MeasurementRow],
    hard: list[Constraint],
) -> tuple[list[SoftPair], list[Any]]:
    """Kähler's Table 8.2 measurements without norms here, at the head scale ``scale``.

    Appends their rows to ``rows`` and the head-size measurements (as hard
    constraints, mm along their axis) to ``hard``; returns the soft pairs
    (each landmark's nearby pairs, then the table's other measurements) and
    the table's arcs, which are met after the solve.
    """
    from workbench.io.growth_table82 import AXIS_OF, load_table82

    soft: list[SoftPair] = [SoftPair(a, b, (0, 1, 2), "nearby") for a, b in nearby_pairs(p)]
    hard_pairs = {(c.a, c.b) for c in hard} | {(c.b, c.a) for c in hard}
    arcs = []
    for t in load_table82():
        if t.a not in index or t.b not in index:
            rows.append(_missing_row(t.measurement, t.measurement, t.kind, t.a, t.b, index))
            continue
        ia, ib = index[t.a], index[t.b]
        if t.kind == "arc":
            arcs.append(t)
            continue
        if t.norm_measurement_id and (ia, ib) in hard_pairs:
            continue  # covered by its norms
        axes = (0, 1, 2) if t.kind == "euclidean" else (AXIS_OF[t.kind],)
        before = (
            float(np.linalg.norm(p[ia] - p[ib]))
            if t.kind == "euclidean"
            else float(abs(p[ia, axes[0]] - p[ib, axes[0]]))
        )
        if t.measurement in HEAD_SIZE and t.kind in AXIS_OF:
            ax = AXIS_OF[t.kind]
            hard.append(Constraint(ia, ib, scale * float(p[ia, ax] - p[ib, ax]), ax, t.measurement))
        else:
            soft.append(SoftPair(ia, ib, axes, t.measurement))
        rows.append(
            MeasurementRow(
                t.measurement,
                t.measurement,
                t.kind,
                t.a,
                t.b,
                "scale",
                before,
                target_mm=scale * before,
                note="no norms here (Kähler Table 8.2): "
                + (
                    "held at the head-circumference scale"
                    if t.measurement in HEAD_SIZE
                    else "follows the head scale"
                ),
            )
        )
    return soft, arcs


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
    size: _HeadSize,
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
    size: _HeadSize,
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
