"""Targets of the age change: the measurements with norms, the head scale and the vault.

Units mm, ages years; the head is in its Frankfort frame (x to the subject's
left, y up, z toward the face), where axis-aligned measurements are read
(horizontal = x, vertical = y, depth = z).  Split from
:mod:`workbench.services.age.change`, which runs the steps; here are the
targets they solve for:

* the facial norms' measurements, each keeping its z-score (Kähler §8.5.4);
* the head circumference's change at a kept z-score (the global scale s) and
  Kähler's Table 8.2 measurements without norms, which follow it;
* the vault height (head-ear height, vertex over porion) from its own norms
  (:mod:`workbench.services.age.growth_tables`), so that the neurocranium
  does not shrink with the face.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from workbench.core.errors import InputError
from workbench.core.growth_solve import Constraint, SoftPair, nearby_pairs
from workbench.core.head_measure import head_circumference_mm
from workbench.model.template import TemplateHead

#: Table 8.2's head-size measurements: with no norms here they are *hard* constraints at
#: the head-circumference scale s, since the circumference chart is the norm of the head's
#: size (as soft pairs the face's norms pulled the vault along: 0.7 % below the chart)
HEAD_SIZE = ("depth:g-op", "horizontal:t_l-t_r", "vertical:v-t_l", "vertical:v-t_r")
#: landmark pairs of the facial norms that measure the vault, not the face: the forehead
#: width (frontotemporale, on the frontal bone's temporal crests) is one of Farkas et al.'s
#: (1992) five head measurements, which mature by about 15 y; the 3D Facial Norms' curve
#: still rises 7 mm from 18 to 40 y (men) while the head circumference is held, and the
#: frontotemporale points alone pushed out 3.7 mm left a bulge and a crease on the forehead
VAULT_PAIRS = ({"ft_l", "ft_r"},)
#: the head-size measurements that are heights of the vault: with vault norms at both ages
#: the head-ear height (v-po) holds the vault's height instead and these follow softly
VAULT_HEIGHTS = ("vertical:v-t_l", "vertical:v-t_r")


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
            "before_mm": rounded(self.before_mm),
            "target_mm": rounded(self.target_mm),
            "after_mm": rounded(self.after_mm),
            "residual_mm": rounded(self.residual_mm),
        }
        if self.constraint == "norms":
            out |= {
                "norm_from": {"mean_mm": rounded(self.mean_from), "sd_mm": rounded(self.sd_from)},
                "norm_to": {"mean_mm": rounded(self.mean_to), "sd_mm": rounded(self.sd_to)},
                "z_before": rounded(self.z_before, 3),
                "z_after": rounded(self.z_after, 3),
                "source": self.source,
            }
        if self.note:
            out["note"] = self.note
        return out


def missing_row(
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


def rounded(value: float, digits: int = 2) -> float | None:
    return None if not np.isfinite(value) else round(float(value), digits)


def measure_circumference(head: TemplateHead) -> float:
    """Head circumference (mm) over glabella and opisthocranion, or NaN if either is absent."""
    pts = head.skin_landmarks.as_dict()
    if "g" not in pts or "op" not in pts:
        return float("nan")
    return head_circumference_mm(head.skin, pts["g"], pts["op"])


def hc_age(hc: Any, sex: str, age: float, notes: list[str]) -> float:
    lo, hi = hc.age_range(sex)
    if age > hi:
        notes.append(
            f"head circumference at {age:g} y read at the chart's last age {hi:g} y "
            "(the head hardly grows after it)"
        )
        return float(hi)
    return max(float(lo), age)


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


def norm_targets(
    table: Any,
    sex: str,
    eth: str,
    a0: float,
    a1: float,
    p: np.ndarray,
    index: Mapping[str, int],
    vault_age_cap: float | None = None,
) -> tuple[list[MeasurementRow], list[Constraint]]:
    """Rows of the measurements with norms and the hard constraints they give (§8.5.4).

    ``p`` holds the head's landmarks (mm, Frankfort frame) in the order of
    ``index``.  Each measurement with norms at both ages keeps its z-score,
    d_t = μ_t + (σ_t/σ_c)(d_c − μ_c); one whose norms do not cover both ages
    follows the head scale, one the head's landmarks do not allow is listed
    as unconstrained.  A measurement of the vault (:data:`VAULT_PAIRS`: the
    forehead width ft-ft) is read at ages no later than ``vault_age_cap``
    (the head-circumference chart's last age), like the head circumference
    itself.  Raises :class:`InputError` when an age lies outside every
    measurement's norms or when no hard constraint is left.
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
            rows.append(missing_row(m.measurement_id, m.name, m.kind, m.a, m.b, index))
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
        r0, r1, note = a0, a1, ""
        if vault_age_cap is not None and {m.a, m.b} in VAULT_PAIRS and max(a0, a1) > vault_age_cap:
            r0, r1 = min(a0, vault_age_cap), min(a1, vault_age_cap)
            note = (
                f"a head measurement: read at {r0:g} and {r1:g} y (the head-circumference chart's "
                "last age at most; the forehead width matures with the head)"
            )
        mu_c, sd_c = table.at(m.measurement_id, sex, r0, eth)
        mu_t, sd_t = table.at(m.measurement_id, sex, r1, eth)
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
                note=note,
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
class HeadSize:
    """The head circumference before and at the target age, and the global scale s."""

    hc_c: float  # measured on the source head (mm)
    h0: float  # the chart's ages read for the source and target ages (years)
    h1: float
    z_hc: float  # the source's z-score on the chart
    scale: float  # s: the circumference's change at a kept z-score
    hc_t: float  # target circumference, s · hc_c (mm)


def head_size(
    head: TemplateHead, hc_ref: Any, sex: str, a0: float, a1: float, notes: list[str]
) -> HeadSize:
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
    h0 = hc_age(hc_ref, sex, a0, notes)
    h1 = hc_age(hc_ref, sex, a1, notes)
    z_hc = hc_ref.z(sex, h0, hc_c)
    scale = hc_scale(hc_ref, sex, h0, h1, z_hc)
    return HeadSize(hc_c, h0, h1, z_hc, scale, scale * hc_c)


def scale_targets(
    p: np.ndarray,
    index: Mapping[str, int],
    scale: float,
    rows: list[MeasurementRow],
    hard: list[Constraint],
    head_size: Sequence[str] = HEAD_SIZE,
) -> tuple[list[SoftPair], list[Any]]:
    """Kähler's Table 8.2 measurements without norms here, at the head scale ``scale``.

    Appends their rows to ``rows`` and the head-size measurements
    ``head_size`` (as hard constraints, mm along their axis) to ``hard``;
    returns the soft pairs (each landmark's nearby pairs, then the table's
    other measurements) and the table's arcs, which are met after the solve.
    A measurement whose landmark pair already has a hard constraint (norms,
    the vault height) is left to it.
    """
    from workbench.io.growth_table82 import AXIS_OF, load_table82

    soft: list[SoftPair] = [SoftPair(a, b, (0, 1, 2), "nearby") for a, b in nearby_pairs(p)]
    hard_pairs = {(c.a, c.b) for c in hard} | {(c.b, c.a) for c in hard}
    arcs = []
    for t in load_table82():
        if t.a not in index or t.b not in index:
            rows.append(missing_row(t.measurement, t.measurement, t.kind, t.a, t.b, index))
            continue
        ia, ib = index[t.a], index[t.b]
        if t.kind == "arc":
            arcs.append(t)
            continue
        if (ia, ib) in hard_pairs:
            continue  # covered by its norms
        axes = (0, 1, 2) if t.kind == "euclidean" else (AXIS_OF[t.kind],)
        before = (
            float(np.linalg.norm(p[ia] - p[ib]))
            if t.kind == "euclidean"
            else float(abs(p[ia, axes[0]] - p[ib, axes[0]]))
        )
        if t.measurement in head_size and t.kind in AXIS_OF:
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
                    if t.measurement in head_size
                    else "follows the head scale"
                ),
            )
        )
    return soft, arcs


def vault_targets(
    sex: str,
    a0: float,
    a1: float,
    p: np.ndarray,
    index: Mapping[str, int],
    notes: list[str],
) -> tuple[list[MeasurementRow], list[Constraint]]:
    """The vault's height from its own norms: rows and hard constraints (mm, along y).

    Each head-ear height (vertex over the left / right porion, Frankfort y)
    keeps its z-score between the ages as the facial norms do,
    d_t = mu_t + (sd_t/sd_c)(d_c - mu_c), read in the vault table
    (:mod:`workbench.services.age.growth_tables`; ages past its last one at
    it).  ``p`` holds the landmarks in the order of ``index``.  Nothing when
    either age lies below the table (the vault then follows the
    head-circumference scale, as said in ``notes``) or a landmark is missing.
    """
    from workbench.services.age.growth_tables import VAULT_HEIGHT, load_vault_norms, vault_ages

    table = load_vault_norms()
    eth = table.ethnicities()[0]
    read = vault_ages(table, sex, (a0, a1))
    lo, hi = table.age_range(VAULT_HEIGHT[0], sex, eth)
    if read is None:
        notes.append(
            f"vault height: no head-ear height norms below {lo:g} y (Dezső 1967): the vault "
            "follows the head-circumference scale"
        )
        return [], []
    rows: list[MeasurementRow] = []
    hard: list[Constraint] = []
    for mid in VAULT_HEIGHT:
        m = table.measurement(mid)
        if m.a not in index or m.b not in index:
            continue  # Table 8.2's v-po row says which landmark is missing
        ia, ib = index[m.a], index[m.b]
        d_c = float(p[ia, 1] - p[ib, 1])
        mu_c, sd_c = table.at(mid, sex, read[0], eth)
        mu_t, sd_t = table.at(mid, sex, read[1], eth)
        d_t = mu_t + (sd_t / sd_c) * (d_c - mu_c)
        hard.append(Constraint(ia, ib, d_t, 1, mid))
        note = "" if max(a0, a1) <= hi else f"adult ages read at the table's last age {hi:g} y"
        rows.append(
            MeasurementRow(
                mid,
                m.name,
                m.kind,
                m.a,
                m.b,
                "norms",
                abs(d_c),
                target_mm=d_t,
                mean_from=mu_c,
                sd_from=sd_c,
                mean_to=mu_t,
                sd_to=sd_t,
                source=table.source_of(mid, sex, eth),
                note=note,
            )
        )
    return rows, hard
