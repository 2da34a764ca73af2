"""Tissue-depth dowels on a skull: the skin targets of a reconstruction (Kähler 2003, §8.6.4-5).

Units and frame: millimetres, head frame (x to the subject's left, x = 0
midsagittal; y up; z toward the face; Frankfort Horizontal at y = 0).  The
caller aligns the skull to this frame first.

A dowel starts at a skull landmark, points outward (the skull normal averaged
over a radius, or a direction set by the user; see
:mod:`workbench.services.tissue.dowel_sites`) and is as long as the tissue depth:
the table value of the chosen group (default the 2023 T-Table, Hona & Stephan
2024), a build variant of it (a slender/normal/obese group where the table
has one, otherwise mean + k·SD), or the user's override.  Its tip is where
the paired skin landmark of the reference head is sent.  Dowels can be
switched off one by one: Kähler (2003, §8.6.8) had to exclude the cheek
landmarks spm2 and sbm2 (our ectomolare codes ``ecm2s_*`` / ``ecm2i_*``, see
:data:`KAEHLER_CHEEK_EXCLUSIONS`) because their Rhine depths gave hollow
cheeks.  Interpolated dowels on the vault and the mandibular body
(§8.6.5), and ours on the temples, take the weighted depths of their parent
landmarks.

Nothing is dropped silently: landmarks that are absent, not placed, off the
bone or without a depth value, and interpolated sites that cannot be placed,
are listed in :attr:`DowelPlan.warnings`.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from workbench.core.data_paths import DEFAULT_DEPTH_TABLE
from workbench.core.errors import InputError
from workbench.core.landmarks import LandmarkSet
from workbench.core.limits import check_tissue_depth
from workbench.core.mesh import Mesh
from workbench.core.spatial import MeshIndex
from workbench.io.build_model import (
    BUILD_ALIASES,
    BUILD_FACES,
    BuildModel,
    load_build_model,
)
from workbench.io.catalogue import LandmarkCatalogue, load_catalogue
from workbench.io.tables import DepthTable, load_depth_table
from workbench.model.reconstruction_setup import parse_bmi_build
from workbench.services.templates.template import DOWEL_RADIUS_MM
from workbench.services.tissue.dowel_sites import (
    OFF_BONE_MM,
    SITE_PATTERN,
    choose_depth_group,
    codes_directions,
    dowel_directions_at,
    interpolated_sites,
    signed_k,
)

#: Kähler's spm2 / sbm2 (supra / sub second molar), excluded in his reconstructions (§8.6.8).
KAEHLER_CHEEK_EXCLUSIONS = frozenset({"ecm2s_l", "ecm2s_r", "ecm2i_l", "ecm2i_r"})
#: Smallest dowel depth (mm): mean − k·SD variants are floored here (with a warning) and the
#: depth draws of the uncertainty ensemble are truncated below it.
MIN_SAMPLE_DEPTH_MM = 0.5


@dataclass(frozen=True)
class DepthSettings:
    """How to turn skull landmarks into dowels.

    Attributes
    ----------
    table : str
        Shipped table id or path to a user CSV (:func:`workbench.io.tables.load_depth_table`).
    group : str or None
        Table group; None = the group matching ``sex`` and ``build`` (or the only one).
    sex : "female" | "male" | None
    build : "slender" | "average" | "heavy" | "normal" | "obese" | "bmi:X" or float k
        A named build picks the table's group of that build where it has
        one; otherwise slender / average / heavy (obese = heavy, normal =
        the means) and ``bmi:X`` are the build model's
        (:func:`build_score`: depths ``mean + r·SD·z``, by region).  A
        number k means mean + k·SD everywhere (uniform, the older
        variant; needs SDs).
    overrides : {skull code: depth mm}
        Depths set by the user (also for codes the table lacks, and for
        interpolated ``i:`` codes).
    excluded : set of codes
        Dowels switched off (kept in the plan, flagged ``excluded``).
    directions : {code: (3,) vector}
        User-set dowel directions (normalised here).
    normal_radius_mm : float
        Radius over which the skull normal is averaged.
    interpolate : bool
        Add the interpolated vault and mandible dowels.
    """

    table: str = DEFAULT_DEPTH_TABLE
    group: str | None = None
    sex: str | None = None
    build: str | float = "normal"
    overrides: Mapping[str, float] = field(default_factory=dict)
    excluded: frozenset[str] = frozenset()
    directions: Mapping[str, tuple[float, float, float]] = field(default_factory=dict)
    normal_radius_mm: float = DOWEL_RADIUS_MM
    interpolate: bool = True
    #: a user's build model CSV (:func:`workbench.io.build_model.load_build_model`);
    #: None: the shipped one
    build_model: str | None = None


@dataclass(frozen=True, eq=False)
class Dowel:
    """One dowel: ``tip = origin + depth_mm * direction`` (mm, head frame).

    ``source`` is "table", "override" or "interpolated"; ``sd_mm`` is None
    where the depth has no spread (overrides, tables without SDs);
    ``table_depth_mm`` is the table mean (None if the table has no value);
    ``parents`` holds ``((code, weight), ...)`` for interpolated dowels.
    ``skin_code`` is the paired skin landmark (None for interpolated dowels).
    """

    code: str
    skin_code: str | None
    origin: np.ndarray
    direction: np.ndarray
    depth_mm: float
    sd_mm: float | None
    table_depth_mm: float | None
    source: str
    excluded: bool = False
    parents: tuple[tuple[str, float], ...] = ()
    #: depth change (mm) per unit of the build score z (:mod:`workbench.io.build_model`):
    #: r·SD for a table depth with an SD, the parents' weighted sum for an interpolated
    #: one, 0 for overrides and depths without an SD
    per_z_mm: float = 0.0

    @property
    def tip(self) -> np.ndarray:
        return self.origin + self.depth_mm * self.direction


@dataclass(frozen=True, eq=False)
class DowelPlan:
    """All dowels of one skull, with where the depths came from."""

    dowels: tuple[Dowel, ...]
    table_id: str
    table_title: str
    citation: str
    group_label: str
    warnings: tuple[str, ...] = ()
    #: the build score the depths are at (0: the table means or a mean + k SD variant), and
    #: whether the build model can vary them (False: numeric k, a build group, no SDs)
    build_z: float = 0.0
    build_model: bool = False

    def active(self) -> tuple[Dowel, ...]:
        return tuple(d for d in self.dowels if not d.excluded)

    def __getitem__(self, code: str) -> Dowel:
        for d in self.dowels:
            if d.code == code:
                return d
        raise KeyError(f"no dowel {code!r}")

    @property
    def codes(self) -> tuple[str, ...]:
        return tuple(d.code for d in self.dowels)


def plan_dowels(
    skull: Mesh,
    landmarks: LandmarkSet,
    settings: DepthSettings = DepthSettings(),
    *,
    catalogue: LandmarkCatalogue | None = None,
) -> DowelPlan:
    """Dowels for every placed or suggested skull landmark with a depth.

    Parameters
    ----------
    skull : Mesh
        The whole bone surface as one mesh (cranium and mandible, if
        present), mm, head frame, outward winding.
    landmarks : LandmarkSet
        Skull landmarks in the same frame.
    settings : DepthSettings
    catalogue : LandmarkCatalogue, optional

    Raises
    ------
    InputError
        Unknown table, group, sex or build the table cannot provide, unknown
        codes in the settings, non-positive overrides, zero directions.
    """
    catalogue = catalogue or load_catalogue()
    table = load_depth_table(settings.table, catalogue)
    model, z, build_label = build_score(table, settings.build, settings.build_model)
    group, k, label, warnings = choose_depth_group(
        table, settings.group, settings.sex, "normal" if build_label else settings.build
    )
    if build_label:
        label = f"{label.removesuffix(', mean')}, {build_label}"
    rows = {
        c: i for i, (c, g) in enumerate(zip(table.codes, table.groups, strict=True)) if g == group
    }
    overrides, excluded, user_dirs = setting_codes(settings, catalogue)

    index = MeshIndex(skull)
    status = {lm.code: lm.status for lm in landmarks}
    defined = landmarks.as_dict()
    want = [c for c in landmarks.codes if c in defined and (c in rows or c in overrides)]
    off_bone: list[str] = []
    if want:
        dist = index.closest_points(np.stack([defined[c] for c in want])).distances
        off_bone = [f"{c} ({d:.1f} mm)" for c, d in zip(want, dist, strict=True) if d > OFF_BONE_MM]
        want = [c for c, d in zip(want, dist, strict=True) if d <= OFF_BONE_MM]
    _report_skipped(warnings, table, landmarks, rows, overrides, status, off_bone, catalogue)

    dowels: list[Dowel] = []
    if want:
        origins = np.stack([defined[c] for c in want])
        dirs = codes_directions(
            skull, origins, want, settings.normal_radius_mm, tree=index.centroid_tree
        )
        no_sd, floored = [], []
        for c, o, d in zip(want, origins, dirs, strict=True):
            mean = float(table.mean_mm[rows[c]]) if c in rows else None
            sd = float(table.sd_mm[rows[c]]) if c in rows else np.nan
            sd_or_none = None if np.isnan(sd) else sd
            skin = (table.skin_codes[rows[c]] if c in rows else "") or catalogue.partner(c, "skull")
            per_z = 0.0
            if c in overrides:
                depth, source, sd_or_none = overrides[c], "override", None
            else:
                if mean is None:  # ``want`` keeps only codes with a table row or an override
                    raise RuntimeError(f"no table row for {c}")
                if k and sd_or_none is None:
                    no_sd.append(c)
                depth, source = mean + (k * sd_or_none if k and sd_or_none else 0.0), "table"
                if model is not None and sd_or_none:
                    per_z = model.loading(c) * sd_or_none
                    depth += per_z * z
                if depth < MIN_SAMPLE_DEPTH_MM:
                    floored.append(f"{c} ({depth:.1f} mm)")
                    depth = MIN_SAMPLE_DEPTH_MM
            dowels.append(
                Dowel(
                    c,
                    skin or None,
                    _ro(o),
                    _ro(user_dirs.get(c, d)),
                    float(depth),
                    sd_or_none,
                    mean,
                    source,
                    c in excluded,
                    per_z_mm=per_z,
                )
            )
        if floored:
            warnings.append(
                f"{build_label or f'mean {signed_k(k)} SD'} is below {MIN_SAMPLE_DEPTH_MM:g} mm for "
                f"{', '.join(floored)}: set to {MIN_SAMPLE_DEPTH_MM:g} mm"
            )
        if no_sd:
            warnings.append(
                f"no SD in the table for {', '.join(no_sd)}: their depths are the "
                f"plain means, not mean {signed_k(k)} SD"
            )
    if settings.interpolate:
        dowels += _interpolated(
            skull, landmarks, index, dowels, settings, overrides, excluded, user_dirs, warnings
        )
    unused = sorted(set(overrides) - {d.code for d in dowels})
    if unused:
        warnings.append(f"overrides not used (no placed landmark or site): {', '.join(unused)}")
    from_table = [d for d in dowels if d.source == "table"]
    if from_table and all(d.sd_mm is None for d in from_table):
        warnings.append(
            f"table {table.table_id} has no SDs: the uncertainty ensemble keeps these depths fixed"
        )
    _check_outward(dowels, warnings)
    used = [
        p
        for d in dowels
        if d.source != "override"
        for p in ([d.code] if not d.parents else [c for c, _ in d.parents])
    ]
    keys = list(
        dict.fromkeys(table.sources[rows[p]] for p in used if p in rows and p not in overrides)
    )
    return DowelPlan(
        tuple(dowels),
        table.table_id,
        str(table.meta.get("title", table.table_id)),
        "\n".join(table.citation(key) for key in keys),
        label,
        tuple(warnings),
        z,
        model is not None,
    )


@lru_cache(maxsize=4)
def build_model_for(path: str | None = None) -> BuildModel:
    """The build model at ``path`` (None: the shipped one), read once."""
    return load_build_model(path)


def build_score(
    table: DepthTable, build: str | float, model_path: str | None = None
) -> tuple[BuildModel | None, float, str]:
    """``(build model, z, label)`` for the build asked of ``table``.

    The model is None where the depths cannot vary with build: a number k
    (mean + k SD, uniform), a named build the table has a group of, or a
    table without SDs asked for its means.  ``label`` is empty for the
    table's means ("normal"), else e.g. "heavy build (BMI 34, build model)".

    Raises
    ------
    InputError
        A slender/heavy/BMI build of a table without SDs, a bad BMI, a bad
        user build model.
    """
    if not isinstance(build, str):
        return None, 0.0, ""
    text = build.strip().lower()
    bmi = parse_bmi_build(text)
    if bmi is None:
        if text not in (*BUILD_FACES, *BUILD_ALIASES):
            return None, 0.0, ""  # choose_depth_group names the problem
        if text in {table.group_build(g) for g in table.group_names()}:
            return None, 0.0, ""  # the table's own group of that build
    if np.isnan(table.sd_mm).all():
        if text in ("normal", "average"):
            return None, 0.0, ""
        raise InputError(
            table.table_id,
            f"has no standard deviations, so the build model cannot make the {text} face",
            "choose a table with SDs (e.g. ttable_2023) or one with a group of that build",
        )
    model = build_model_for(model_path)
    if bmi is not None:
        z = model.z_of_bmi(bmi)
        return model, z, f"BMI {bmi:g} (build model, z {z:+.2f})"
    name = BUILD_ALIASES.get(text, text)
    if text == "normal":
        return model, 0.0, ""
    return model, model.z(name), f"{name} build (BMI {model.bmi(name):g}, build model)"


def depth_samples(plan: DowelPlan, rng: np.random.Generator) -> np.ndarray:
    """One random draw of every dowel's depth (mm), in the order of ``plan.dowels``.

    Table depths are drawn from a normal distribution (mean = the plan's
    depth, SD = the table SD) truncated below :data:`MIN_SAMPLE_DEPTH_MM`;
    overrides and depths without an SD stay fixed; interpolated dowels take
    the same weights over their parents' draws.
    """
    n = len(plan.dowels)
    mean = np.array([d.depth_mm for d in plan.dowels])
    sd = np.array(
        [d.sd_mm if d.sd_mm is not None and d.source == "table" else 0.0 for d in plan.dowels]
    )
    draw = mean + sd * rng.standard_normal(n)
    for _ in range(100):
        low = (draw < MIN_SAMPLE_DEPTH_MM) & (sd > 0)
        if not low.any():
            break
        draw[low] = mean[low] + sd[low] * rng.standard_normal(int(low.sum()))
    draw = np.where(sd > 0, np.maximum(draw, MIN_SAMPLE_DEPTH_MM), mean)
    where = {d.code: i for i, d in enumerate(plan.dowels)}
    for i, d in enumerate(plan.dowels):
        if d.source == "interpolated" and all(c in where for c, _ in d.parents):
            draw[i] = sum(w * draw[where[c]] for c, w in d.parents)
    return draw


# ---------------------------------------------------------------- settings codes
def setting_codes(
    settings: DepthSettings, catalogue: LandmarkCatalogue | None = None
) -> tuple[dict[str, float], set[str], dict[str, np.ndarray]]:
    """The settings' depth overrides (mm), exclusions and dowel directions by catalogue code.

    Raises :class:`InputError` for a code the catalogue does not know (a
    side-less bilateral label stands for both sides), a non-positive depth or
    a zero direction: cheap, so a job checks them before any long work.
    """
    catalogue = catalogue or load_catalogue()
    site_codes = {r.code for r in SITE_PATTERN}
    overrides = {
        _code(c, catalogue, site_codes, "overrides"): _depth(c, v)
        for c, v in settings.overrides.items()
    }
    excluded = {
        c for label_ in settings.excluded for c in _codes(label_, catalogue, site_codes, "excluded")
    }
    user_dirs = {
        _code(c, catalogue, site_codes, "directions"): _unit(c, v)
        for c, v in settings.directions.items()
    }
    return overrides, excluded, user_dirs


def _codes(label: str, catalogue: LandmarkCatalogue, sites: set[str], what: str) -> list[str]:
    """Catalogue codes for a settings label; a side-less bilateral label gives both sides."""
    if label in sites or label.startswith("i:"):
        if label not in sites:
            raise InputError(
                what, f"unknown interpolated site {label!r}", f"sites: {', '.join(sorted(sites))}"
            )
        return [label]
    try:
        return [catalogue.normalise(label, "skull")]
    except Exception:  # noqa: BLE001 - LandmarkError; try both sides below
        pass
    both = []
    for side in ("L", "R"):
        try:
            both.append(catalogue.normalise(f"{label} {side}", "skull"))
        except Exception:  # noqa: BLE001
            break
    if len(both) == 2:
        return both
    raise InputError(
        what,
        f"unknown skull landmark {label!r}",
        "use the skull codes of data_tables/landmarks/catalogue.csv",
    )


def _code(label: str, catalogue: LandmarkCatalogue, sites: set[str], what: str) -> str:
    codes = _codes(label, catalogue, sites, what)
    if len(codes) != 1:
        raise InputError(
            what,
            f"{label!r} names both sides ({', '.join(codes)})",
            "give the side, e.g. " + codes[0],
        )
    return codes[0]


def _depth(code: str, value: float) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise InputError("overrides", f"{code}: depth is not a number ({value!r})") from None
    if not np.isfinite(v) or v <= 0:
        raise InputError("overrides", f"{code}: depth must be a positive number of mm, got {value}")
    return check_tissue_depth(v, f"overrides: {code}")


def _unit(code: str, value: tuple[float, float, float]) -> np.ndarray:
    v = np.asarray(value, dtype=float).reshape(-1)
    length = float(np.linalg.norm(v)) if v.shape == (3,) else 0.0
    if v.shape != (3,) or not np.isfinite(v).all() or length < 1e-9:
        raise InputError(
            "directions", f"{code}: a direction must be a non-zero 3-vector, got {value!r}"
        )
    return v / length


def _ro(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=np.float64)
    a.setflags(write=False)
    return a


# ---------------------------------------------------------------- helpers
def _report_skipped(
    warnings: list[str],
    table: DepthTable,
    landmarks: LandmarkSet,
    rows: dict[str, int],
    overrides: dict[str, float],
    status: dict[str, str],
    off_bone: list[str],
    catalogue: LandmarkCatalogue,
) -> None:
    """Warnings for every landmark or table code that gets no dowel, grouped by reason."""
    dowel_codes = set(rows) | set(overrides)
    for st, why in (("absent", "marked absent"), ("missing", "not placed yet")):
        codes = [c for c in landmarks.codes if status[c] == st and c in dowel_codes]
        if codes:
            warnings.append(f"no dowel for {', '.join(codes)}: {why}")
    gone = [c for c in rows if c not in status]
    if gone:
        warnings.append(f"no dowel for {', '.join(gone)}: not in the landmark set")
    if off_bone:
        warnings.append(
            f"no dowel for {', '.join(off_bone)}: farther than {OFF_BONE_MM:g} mm "
            "from the skull surface (missing bone, or a misplaced landmark?)"
        )
    no_value = [
        c
        for c in landmarks.codes
        if status[c] in ("placed", "suggested")
        and c not in dowel_codes
        and (e := catalogue.get(c, "skull")) is not None
        and e.partner
    ]
    if no_value:
        warnings.append(
            f"no depth in table {table.table_id} for {', '.join(no_value)}: "
            "no dowels there (set an override to add one)"
        )


def _interpolated(
    skull: Mesh,
    landmarks: LandmarkSet,
    index: MeshIndex,
    dowels: list[Dowel],
    settings: DepthSettings,
    overrides: dict[str, float],
    excluded: set[str],
    user_dirs: dict[str, np.ndarray],
    warnings: list[str],
) -> list[Dowel]:
    skipped: list[str] = []
    sites = interpolated_sites(
        skull, landmarks, radius_mm=settings.normal_radius_mm, skipped=skipped, index=index
    )
    by_code = {d.code: d for d in dowels}
    placed = []
    for code, pos, parents in sites:
        missing = [c for c, _ in parents if c not in by_code]
        if missing:
            skipped.append(f"{code}: no dowel at {', '.join(missing)}")
            continue
        placed.append((code, pos, parents))
    if skipped:
        warnings.append("interpolated dowels skipped: " + "; ".join(skipped))
    if not placed:
        return []
    pts = np.stack([p for _, p, _ in placed])
    midline = np.array([not any(c.endswith(("_l", "_r")) for c, _ in par) for _, _, par in placed])
    dirs = dowel_directions_at(
        skull,
        pts,
        midline,
        np.zeros(len(placed), bool),
        settings.normal_radius_mm,
        tree=index.centroid_tree,
    )
    out, followed = [], []
    for (code, pos, parents), d in zip(placed, dirs, strict=True):
        ps = [by_code[c] for c, _ in parents]
        w = np.array([wt for _, wt in parents])
        depth = float(w @ [p.depth_mm for p in ps])
        table = (
            [p.table_depth_mm for p in ps]
            if all(p.table_depth_mm is not None for p in ps)
            else None
        )
        sds = [0.0 if p.source == "override" else p.sd_mm for p in ps]
        sd = None if any(s is None for s in sds) else float(np.sqrt(np.sum((w * sds) ** 2)))
        per_z = float(w @ [p.per_z_mm for p in ps])
        source = "interpolated"
        if code in overrides:
            depth, source, sd, per_z = overrides[code], "override", None, 0.0
        off = code in excluded or any(p.excluded for p in ps)
        if off and code not in excluded:
            followed.append(code)
        out.append(
            Dowel(
                code,
                None,
                _ro(pos),
                _ro(user_dirs.get(code, d)),
                depth,
                sd,
                None if table is None else float(w @ table),
                source,
                off,
                parents,
                per_z_mm=per_z,
            )
        )
    if followed:
        warnings.append(f"interpolated dowels excluded with a parent: {', '.join(followed)}")
    return out


def _check_outward(dowels: list[Dowel], warnings: list[str]) -> None:
    """Flag a skull whose dowels mostly point inward (faces wound the wrong way?)."""
    if len(dowels) < 4:
        return
    o = np.stack([d.origin for d in dowels])
    n = np.stack([d.direction for d in dowels])
    out = np.einsum("ij,ij->i", o - o.mean(axis=0), n) > 0
    if out.mean() < 0.5:
        warnings.append(
            f"{int((~out).sum())} of {len(dowels)} dowels point into the skull: "
            "are the mesh's faces wound inward?"
        )
