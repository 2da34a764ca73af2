"""Where tissue-depth dowels start, which way they point, and which depth group applies.

Units and frame: millimetres, head frame (x to the subject's left, x = 0
midsagittal; y up; z toward the face; Frankfort Horizontal at y = 0).  The
skull mesh must be wound with outward normals.

Dowel directions
    The skull normal averaged over a ball (Kähler 2003, §8.6.8: single-face
    normals of a scanned skull are "too local"), with the rules of the
    reference head (:mod:`workbench.services.templates.template`): midline dowels lie in
    the midsagittal plane, and the mouth-region dowels of
    :data:`~workbench.services.templates.template.HORIZONTAL_DOWELS` run parallel to
    the Frankfort plane.

Interpolated dowel sites (Kähler 2003, §8.6.5)
    Kähler added landmark pairs "by interpolation between existing ones" on
    the upper and back cranium and on the mandible, with interpolated
    thickness, only where thickness is near-constant and never in the
    mid-face; he does not give the pattern.  Ours is :data:`SITE_PATTERN`:
    fixed weights over two skull landmarks each,

    * the midline vault: vertex–glabella and vertex–opisthocranion at 1/4, 1/2
      and 3/4 (T-Table depths 5–6 mm);
    * the frontal vault on each side: vertex–mid-supraorbital at 1/3 and 2/3;
    * the parietal vault on each side: opisthocranion–mid-supraorbital at 1/4,
      1/2 and 3/4 (the line square to this chord, away from the frame origin,
      rises to the parietal boss, well above the temporal fossa);
    * the temple on each side: zygion–vertex at 1/3 and 2/3 (the line square
      to this chord meets the temporal squama and the side of the frontal
      bone above the temporal line; depths 6.7 and 5.8 mm from the T-Table);
    * the mandibular body on each side: gonion–pogonion at 1/3 and 2/3, and the
      lower border halfway gonion–mid-mandibular border and mid-mandibular
      border–pogonion.

    A site is the weighted position of its parents pushed onto the bone along a
    line square to the parents' chord (so that the sites spread evenly),
    pointing away from the head-frame origin (between the porions) on the
    cranium, and along the parents' averaged dowel directions on the
    mandible.  A ray is cast back along that line from outside the bone, and
    the first outward-facing surface it meets is the
    site.  The site is dropped, with a reason, when a parent is undefined or
    off the bone, when no bone is found within reach of the parents' chord
    (damaged vault, missing mandible), or when the bone found there faces
    away from the ray.  The pattern depends on the landmark codes only, so
    the same call on the template's skull and on a target skull yields
    corresponding sites (matched by code).

Depth group
    :func:`choose_depth_group` picks the table group for a sex and a build:
    a slender/normal/obese group where the table has one (Rhine's tables, as
    Kähler 2003 §8.6.1 used them), otherwise mean + k·SD, labelled as such.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from workbench.core.errors import InputError
from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh
from workbench.core.normals import normals_within_radius
from workbench.core.raycast import RayCaster
from workbench.core.spatial import MeshIndex
from workbench.io.tables import DepthTable
from workbench.services.templates.template import DOWEL_RADIUS_MM, HORIZONTAL_DOWELS

BUILDS = ("slender", "normal", "obese")
#: A landmark farther than this from the skull surface is "off the bone" (mm).
#: The reference head's own landmarks lie up to ~2.3 mm off its bone meshes
#: (orbitale, after the skull warp), so the bound is not tighter.
OFF_BONE_MM = 3.0
#: A site is accepted only if the averaged bone normal there makes less than
#: 60 degrees with the ray direction (cosine bound).
MIN_OUTWARD_COS = 0.5


@dataclass(frozen=True)
class SiteRule:
    """One interpolated site: fixed weights over skull landmark codes."""

    parents: tuple[str, ...]
    weights: tuple[float, ...]
    region: str  # "cranium" | "mandible"
    #: the tissue model calibrates at this site by default (see :data:`CALIBRATED_SITES`)
    calibrate: bool = False

    @property
    def code(self) -> str:
        """``i:a-b:t`` (t = weight of b) for pairs; ``i:a-b-c:wb,wc`` otherwise."""
        return f"i:{'-'.join(self.parents)}:{','.join(f'{w:.2f}' for w in self.weights[1:])}"

    @property
    def midline(self) -> bool:
        return not any(is_bilateral(c) for c in self.parents)

    def mirrored(self) -> SiteRule:
        return SiteRule(
            tuple(mirror_code(c) for c in self.parents), self.weights, self.region, self.calibrate
        )


def is_bilateral(code: str) -> bool:
    return code.endswith(("_l", "_r"))


def mirror_code(code: str) -> str:
    if code.endswith("_l"):
        return code[:-2] + "_r"
    if code.endswith("_r"):
        return code[:-2] + "_l"
    return code


def _pair(a: str, b: str, t: float, region: str, calibrate: bool = False) -> SiteRule:
    return SiteRule((a, b), (1.0 - t, t), region, calibrate)


def _pattern() -> tuple[SiteRule, ...]:
    # pair (a, b, t): weights (1 - t, t); "cranium" sites are cast away from the frame origin
    midline = [_pair("v", "g", t, "cranium") for t in (0.25, 0.5, 0.75)]
    midline += [_pair("v", "op", t, "cranium") for t in (0.25, 0.5, 0.75)]
    left = [_pair("v", "mso_l", t, "cranium") for t in (1 / 3, 2 / 3)]
    left += [_pair("op", "mso_l", t, "cranium") for t in (0.25, 0.5, 0.75)]
    # the temple: no table has a landmark over the temporal fossa, where the built-in
    # reference's skin lies 3.5-4 mm farther from the bone than on both Visible Human
    # heads (median of the scored points there, benchmarks/); calibrated by default
    left += [_pair("zy_l", "v", t, "cranium", calibrate=True) for t in (1 / 3, 2 / 3)]
    left += [_pair("go_l", "pg", t, "mandible") for t in (1 / 3, 2 / 3)]
    left += [_pair("go_l", "mmb_l", 0.5, "mandible"), _pair("mmb_l", "pg", 0.5, "mandible")]
    return (*midline, *left, *(r.mirrored() for r in left))


#: The interpolated sites, in a fixed order (see the module docstring).
SITE_PATTERN: tuple[SiteRule, ...] = _pattern()
#: codes of the interpolated sites the tissue model calibrates at even when the others
#: are off (:class:`workbench.services.tissue.tissue_model.TissueSettings`): the temples
CALIBRATED_SITES: frozenset[str] = frozenset(r.code for r in SITE_PATTERN if r.calibrate)


def dowel_directions_at(
    skull: Mesh,
    points: np.ndarray,
    midline: np.ndarray,
    horizontal: np.ndarray,
    radius_mm: float = DOWEL_RADIUS_MM,
    *,
    tree: cKDTree | None = None,
) -> np.ndarray:
    """``(k, 3)`` unit dowel directions at ``points`` on ``skull``.

    Parameters
    ----------
    skull : Mesh
        Bone surface, mm, head frame, outward winding.
    points : (k, 3)
        Dowel origins (mm).
    midline, horizontal : (k,) bool
        Dowels kept in the plane x = 0, and dowels made parallel to the
        Frankfort plane (y component removed; straight forward (+z) where
        the averaged normal is almost vertical).
    radius_mm : float
        Averaging radius of the skull normal.
    """
    pts = np.asarray(points, float).reshape(-1, 3)
    n = normals_within_radius(skull, pts, radius_mm, tree=tree)
    midline = np.asarray(midline, bool)
    if midline.any():
        n[midline, 0] = 0.0
    horizontal = np.asarray(horizontal, bool)
    if horizontal.any():
        h = n[horizontal].copy()
        h[:, 1] = 0.0
        length = np.linalg.norm(h, axis=1, keepdims=True)
        n[horizontal] = np.where(length > 0.2, h, [0.0, 0.0, 1.0])
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return np.where(length > 1e-9, n / np.maximum(length, 1e-12), [0.0, 0.0, 1.0])


def codes_directions(
    skull: Mesh,
    points: np.ndarray,
    codes: list[str],
    radius_mm: float = DOWEL_RADIUS_MM,
    *,
    tree: cKDTree | None = None,
) -> np.ndarray:
    """:func:`dowel_directions_at` for skull landmark codes (side and mouth rules by code)."""
    return dowel_directions_at(
        skull,
        points,
        np.array([not is_bilateral(c) for c in codes]),
        np.array([c in HORIZONTAL_DOWELS for c in codes]),
        radius_mm,
        tree=tree,
    )


def interpolated_sites(
    skull: Mesh,
    landmarks: LandmarkSet,
    *,
    radius_mm: float = DOWEL_RADIUS_MM,
    skipped: list[str] | None = None,
    index: MeshIndex | None = None,
    caster: RayCaster | None = None,
) -> list[tuple[str, np.ndarray, tuple[tuple[str, float], ...]]]:
    """The sites of :data:`SITE_PATTERN` that can be placed on ``skull``.

    Parameters
    ----------
    skull : Mesh
        Bone surface (cranium and mandible as one mesh, or whatever is
        there), mm, head frame, outward winding.
    landmarks : LandmarkSet
        Skull landmarks; only placed or suggested ones are used.
    radius_mm : float
        Normal-averaging radius of the parent dowel directions.
    skipped : list, optional
        Receives one line per dropped site, saying why.
    index, caster : optional
        Prebuilt :class:`MeshIndex` / :class:`RayCaster` of ``skull``.

    Returns
    -------
    list of ``(code, position (3,) mm on the bone, ((parent code, weight), ...))``
    """
    index = index or MeshIndex(skull)
    defined = landmarks.as_dict()
    needed = sorted({c for r in SITE_PATTERN for c in r.parents if c in defined})
    pos = {c: defined[c] for c in needed}
    on_bone: dict[str, bool] = {}
    normal: dict[str, np.ndarray] = {}
    if needed:
        pts = np.stack([pos[c] for c in needed])
        dist = index.closest_points(pts).distances
        dirs = codes_directions(skull, pts, needed, radius_mm, tree=index.centroid_tree)
        on_bone = {c: bool(d <= OFF_BONE_MM) for c, d in zip(needed, dist, strict=True)}
        normal = dict(zip(needed, dirs, strict=True))
    rules, origins, directions, centres, reach = [], [], [], [], []
    for rule in SITE_PATTERN:
        bad = [c for c in rule.parents if c not in defined]
        off = [c for c in rule.parents if c in defined and not on_bone[c]]
        if bad or off:
            why = (
                (f"{', '.join(bad)} not placed" if bad else "")
                + ("; " if bad and off else "")
                + (f"{', '.join(off)} off the bone" if off else "")
            )
            _note(skipped, rule, why)
            continue
        w = np.asarray(rule.weights)
        p = np.einsum("i,ij->j", w, np.stack([pos[c] for c in rule.parents]))
        if rule.region == "cranium":  # away from the head-frame origin, between the porions
            d = p.copy()
        else:
            d = np.einsum("i,ij->j", w, np.stack([normal[c] for c in rule.parents]))
        chord = max(np.linalg.norm(pos[a] - pos[b]) for a in rule.parents for b in rule.parents)
        if len(rule.parents) == 2 and chord > 0:  # cast square to the chord: even spacing
            u = (pos[rule.parents[1]] - pos[rule.parents[0]]) / chord
            d -= (d @ u) * u
        if rule.midline:
            d[0] = 0.0
        if np.linalg.norm(d) < 0.2:
            _note(skipped, rule, "no outward direction square to the parents' chord")
            continue
        d /= np.linalg.norm(d)
        out = 0.5 * chord + 10.0  # reach outward from the chord (the bone bulges out of it)
        rules.append(rule)
        centres.append(p)
        directions.append(d)
        origins.append(p + out * d)
        reach.append((out, 0.25 * chord))
    sites = []
    if rules:
        caster = caster or RayCaster.shared(skull)
        o, d = np.asarray(origins), np.asarray(directions)
        limit = np.array([a + b for a, b in reach])
        hits = caster.first_hits(o, -d, max_distance=float(limit.max()), cull_backfaces=True)
        ok = hits.hit & (hits.distance <= limit)
        facing = np.zeros(len(rules))
        if ok.any():
            n_hit = dowel_directions_at(
                skull,
                hits.points[ok],
                np.zeros(ok.sum(), bool),
                np.zeros(ok.sum(), bool),
                radius_mm,
                tree=index.centroid_tree,
            )
            facing[ok] = np.einsum("ij,ij->i", n_hit, d[ok])
        for i, rule in enumerate(rules):
            if not ok[i]:
                _note(
                    skipped, rule, f"no bone on its dowel line (missing or damaged {rule.region}?)"
                )
            elif facing[i] < MIN_OUTWARD_COS:
                _note(
                    skipped,
                    rule,
                    f"the bone there faces away from the dowel line "
                    f"(missing or damaged {rule.region}?)",
                )
            else:
                sites.append(
                    (
                        rule.code,
                        hits.points[i].copy(),
                        tuple(zip(rule.parents, rule.weights, strict=True)),
                    )
                )
    return sites


_POOLED = ("", "pooled")


def choose_depth_group(
    table: DepthTable,
    group: str | None = None,
    sex: str | None = None,
    build: str | float = "normal",
) -> tuple[str, float, str, list[str]]:
    """Which group of a depth table to use, and the build variant.

    A named build picks the table's group of that build (and ``sex``, where
    the groups are sex-specific; a sexes-pooled group is used, with a note,
    when there is none for ``sex``).  A number k asks for mean + k·SD of the
    normal-build (or pooled) group and needs SDs.

    Returns
    -------
    group, k, label (e.g. "adult pooled, mean + 1 SD"), notes for the user

    Raises
    ------
    InputError
        The table has no such group, sex or build, or no SDs for k ≠ 0.
    """
    notes: list[str] = []
    names = table.group_names()
    listing = f"groups of {table.table_id}: {', '.join(names)}"
    k, build = _parse_build(build)
    sex = (sex or "").strip().lower() or None
    if sex not in (None, "female", "male"):
        raise InputError("sex", f"unknown sex {sex!r}", "use female, male or leave it unset")
    if group is not None:
        if group not in names:
            raise InputError(table.table_id, f"no group {group!r}", listing)
        g_build, g_sex = table.group_build(group), table.group_sex(group)
        if build != "normal" and g_build != build:
            raise InputError(table.table_id, f"group {group!r} is not of {build} build", listing)
        if sex and g_sex not in (sex, *_POOLED):
            raise InputError(table.table_id, f"group {group!r} is {g_sex}, not {sex}", listing)
        cand = [group]
    else:
        cand = list(names)
        if sex:
            exact = [g for g in cand if table.group_sex(g) == sex]
            pooled = [g for g in cand if table.group_sex(g) in _POOLED]
            if not exact and not pooled:
                raise InputError(table.table_id, f"no depths for {sex}s", listing)
            if not exact:
                notes.append(
                    f"table {table.table_id} has no {sex}-specific depths: using sexes pooled"
                )
            cand = exact or pooled
        named = [g for g in cand if table.group_build(g) == build]
        if named:
            cand = named
        elif build == "normal":
            cand = [g for g in cand if table.group_build(g) in _POOLED] or cand
        else:
            have = sorted({table.group_build(g) for g in names} - set(_POOLED))
            raise InputError(
                table.table_id,
                f"no {build} build group" + (f" (builds: {', '.join(have)})" if have else ""),
                "use a mean + k SD variant instead, e.g. build = -1 or 1",
            )
        if len(cand) > 1:
            notes.append(
                f"several groups fit ({', '.join(cand)}): using {cand[0]}; choose one with group="
            )
    group = cand[0]
    if k:
        sds = [sd for sd, g in zip(table.sd_mm, table.groups, strict=True) if g == group]
        if np.isnan(sds).all():
            raise InputError(
                table.table_id,
                f"has no standard deviations, so 'mean {signed_k(k)} SD' cannot be computed",
                "choose a table with SDs (e.g. ttable_2023) or a named build group",
            )
    parts = [group]
    for extra in (table.group_sex(group), table.group_build(group)):
        if extra and all(extra not in p for p in parts):
            parts.append(extra)
    variant = "mean" if not k else f"mean {signed_k(k)} SD"
    return group, k, f"{' '.join(parts)}, {variant}", notes


def _parse_build(build: str | float) -> tuple[float, str]:
    """``(k, build name)``: a number is mean + k SD of the normal-build group."""
    if isinstance(build, (int, float)) and not isinstance(build, bool):
        k = float(build)
    else:
        text = str(build).strip().lower()
        if text in BUILDS:
            return 0.0, text
        try:
            k = float(text.removesuffix("sd").strip())
        except ValueError:
            raise InputError(
                "build",
                f"unknown build {build!r}",
                "use slender, normal, obese, or a number k for mean + k SD",
            ) from None
    if not np.isfinite(k):
        raise InputError("build", f"k must be a finite number, got {build!r}")
    return k, "normal"


def signed_k(k: float) -> str:
    return f"{'+' if k >= 0 else '-'} {abs(k):g}"


def site_label(code: str) -> str:
    """An interpolated site's code in words (``i:v-g:0.25`` → "between v and g, 25 % of the
    way to g"); any other code as it is."""
    if not code.startswith("i:"):
        return code
    _, parents, weights = (code.split(":") + ["", ""])[:3]
    names = parents.split("-")
    if len(names) == 2:
        try:
            share = float(weights)
        except ValueError:
            return f"between {names[0]} and {names[1]}"
        return f"between {names[0]} and {names[1]}, {share:.0%} of the way to {names[1]}"
    return "between " + ", ".join(names[:-1]) + f" and {names[-1]}"


def _note(skipped: list[str] | None, rule: SiteRule, why: str) -> None:
    if skipped is not None:
        skipped.append(f"no dowel {site_label(rule.code)}: {why}")
