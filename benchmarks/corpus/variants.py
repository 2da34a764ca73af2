"""Seeded variant specs of the robustness corpus and the builder of their meshes.

Units mm.  A spec (:class:`VariantSpec`) is pure data drawn from a fixed seed
(no CT needed to draw it); :func:`build_variant` turns it into a PLY file
and a truth record.  Frames: the base's **input frame** (the CT's physical
frame), the **head frame** of the base's anchor (x to the subject's left, y
up, z toward the face, Frankfort at y = 0; :mod:`benchmarks.corpus.truth`),
and the variant's **file frame** (input frame mapped by the spec's rigid
transform ``X``: a rotation about the bone's centre, a mirror, a shift; the
file holds ``X(p)`` in mm, or ``0.1 * X(p)`` for a "cm" file).

Build steps (voxels in the base CT's own units, then the surface):

1. C-spine and hyoid removed: their voxels (label "extra") are set to the
   base's soft-tissue value.
2. Mandible: missing (voxels set to soft tissue); opened / pushed (its voxels,
   with a one-voxel shell of partial-volume values, are moved by a rigid map
   about the anchor's condylar axis, resampled with
   ``scipy.ndimage.affine_transform`` order 1 in a box and composed with the
   rest as ``max`` — where it overlaps the cranium it is just bone, as in a
   real CT); detached (its voxels within :data:`DETACH_GAP_MM` of any other
   bone removed, so it is a piece of its own at every level).
3. Frontal defect: a cylinder above one orbit
   (:func:`benchmarks.cases.cut_skull.hole_voxels`) set to soft tissue.
4. Apparatus, drawn with soft (one voxel) edges: head-holder pins (metal,
   3000 HU) pressing on the temporal/parietal bone; a tube (a hollow
   cylinder, 1500 HU) leaving the mouth forward-down; a head holder (a
   curved shell behind the occiput, 1200 HU); the CT table (a plate under the
   head along the scanner's posterior direction, 1200 HU).
5. Iso-surface with the project's :func:`~workbench.services.ct.ct_mesh.mesh_from_ct`
   (every component), the vault cut (:func:`benchmarks.cases.cut_skull.clip_by_plane`,
   parallel to the anchor's Frankfort plane), the component choice (largest /
   every component over 5 % of the triangles / everything), Taubin smoothing
   and quadric decimation (the project's ``taubin_smooth`` and ``decimate``).
6. The file transform and units; PLY written with the spec id, the units and
   (Visible Human data) the NLM credit in its header.

The truth of a variant (:func:`variant_truth`) is the base truth mapped by
``X``: the six landmarks, the condylar axis, whether the file is mirrored
(the base's own handedness times the spec's mirror), whether the mesh holds
a mandible (measured on the built mesh), and the jaw opening (base opening +
applied opening).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from scipy import ndimage as ndi

from benchmarks.corpus.bases import (
    BASES,
    CRANIUM,
    EXTRA,
    ISO_LEVELS,
    MANDIBLE,
    OTHER,
    Base,
    index_matrix,
    iso_level,
    load_volume,
    voxel_points,
    with_data,
)
from benchmarks.corpus.common import (
    apply,
    apply_dir,
    homogeneous,
    jsonable,
    read_json,
    results_dir,
    rotation_about,
    rotation_matrix,
    unit,
    write_json,
)
from benchmarks.corpus.truth import (
    EVAL_SEX,
    SIX,
    Anchor,
    load_anchor,
    load_segmentation,
    load_truth,
)
from workbench.core.mesh import Mesh
from workbench.core.volume import Volume

GENERATOR_VERSION = 1
SEED = 28_2028
#: variants per base (about 40 % VHP female, 35 % VHP male, 25 % headsq) and how many of
#: them are "cut" cases (no mandible, a frontal defect and the vault cut, like cut_skull.py)
COUNTS = {"vhp_female": 92, "vhp_male": 80, "headsq": 58}
CUT_COUNTS = {"vhp_female": 10, "vhp_male": 8, "headsq": 0}

ISO = ISO_LEVELS
COMPONENTS = ("largest", "over5", "all")
SMOOTH = ("none", "taubin")
TRIANGLES = (50_000, 100_000, 200_000, 0)  # 0: full resolution
MANDIBLE_CASES = ("as_scanned", "opened", "forward", "sideways", "detached", "missing")
CSPINE = ("kept", "removed")
APPARATUS = ("none", "pins", "tube", "holder", "table")
CUTS = ("none", "vault", "defect")
AXES = ("own", "prone", "permuted", "turned", "random")
UNITS = ("mm", "cm")
#: every dimension a spec varies, with its values (the "cut" group adds cut = vault+defect)
DIMENSIONS: dict[str, tuple] = {
    "iso": ISO,
    "components": COMPONENTS,
    "smooth": SMOOTH,
    "triangles": TRIANGLES,
    "mandible": MANDIBLE_CASES,
    "cspine": CSPINE,
    "apparatus": APPARATUS,
    "cut": CUTS,
    "axes": AXES,
    "mirrored": (False, True),
    "units": UNITS,
}

#: material values (HU; mapped into a base's own units by Base.value)
PIN_HU, TUBE_HU, HOLDER_HU, TABLE_HU = 3000.0, 1500.0, 1200.0, 1200.0
#: mandible voxels this close to any other bone are removed to detach it (mm; >= 1.5 voxels)
DETACH_GAP_MM = 3.0
#: a mandible sample point within this distance of the mesh is "on" it (mm; >= 1.5 voxels)
PRESENT_DISTANCE_MM = 3.0
#: a variant has a mandible when this fraction of its surface samples lies on the mesh
PRESENT_FRACTION = 0.5
MAX_TRANSLATION_MM = 500.0


# ---------------------------------------------------------------- specs
@dataclass(frozen=True)
class VariantSpec:
    """One variant, fully specified (JSON-serialisable; see the module docstring).

    Lengths in mm, angles in degrees; ``rotation`` is the 3 x 3 file-axes
    rotation (about the bone's centre), ``mirror_axis`` the file axis flipped
    after it (-1: none), ``translation`` the shift after both.
    """

    base: str
    index: int
    group: str  # "plain" | "cut"
    iso: str
    components: str
    smooth: str
    smooth_iterations: int
    triangles: int
    mandible: str
    opening_deg: float
    forward_mm: float
    lateral_mm: float  # + toward the subject's left
    cspine: str
    apparatus: str
    cut: str  # none | vault | defect | vault+defect
    vault_above_mm: float
    defect_radius_mm: float
    defect_side: str  # "l" | "r"
    axes: str
    rotation: tuple[tuple[float, float, float], ...]
    mirror_axis: int
    translation: tuple[float, float, float]
    units: str
    params: dict[str, Any] = field(default_factory=dict)  # apparatus sizes and places

    @property
    def mirrored(self) -> bool:
        return self.mirror_axis >= 0

    def to_dict(self) -> dict[str, Any]:
        return jsonable(dataclasses.asdict(self), 9)

    @property
    def id(self) -> str:
        blob = json.dumps(self.to_dict(), sort_keys=True) + f"|v{GENERATOR_VERSION}"
        return f"{self.base}-{self.index:03d}-{hashlib.sha256(blob.encode()).hexdigest()[:6]}"

    @staticmethod
    def from_dict(d: dict[str, Any]) -> VariantSpec:
        d = dict(d)
        d["rotation"] = tuple(tuple(float(x) for x in row) for row in d["rotation"])
        d["translation"] = tuple(float(x) for x in d["translation"])
        return VariantSpec(**d)

    def dimension(self, name: str) -> Any:
        """The value of one of :data:`DIMENSIONS` (plus "group" and "base")."""
        return getattr(self, name)


def _balanced(values: tuple, n: int, rng: np.random.Generator) -> list:
    """``n`` values with every value equally often (± 1), in a shuffled order."""
    reps = [values[i % len(values)] for i in range(n)]
    order = rng.permutation(n)
    return [reps[i] for i in order]


def _uniform_rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def _proper_permutations() -> list[np.ndarray]:
    """The 24 proper signed permutation matrices, identity first."""
    out = []
    for perm in ((0, 1, 2), (1, 2, 0), (2, 0, 1), (0, 2, 1), (2, 1, 0), (1, 0, 2)):
        for signs in np.ndindex(2, 2, 2):
            m = np.zeros((3, 3))
            for r, c in enumerate(perm):
                m[r, c] = 1.0 if signs[r] == 0 else -1.0
            if np.linalg.det(m) > 0:
                out.append(m)
    out.sort(key=lambda m: (not np.allclose(m, np.eye(3)), m.ravel().tolist()))
    return out


def _file_rotation(base: Base, axes: str, rng: np.random.Generator) -> np.ndarray:
    superior = np.asarray(base.hint[1], np.float64)
    prone = rotation_matrix(superior, 180.0)
    if axes == "own":
        return np.eye(3)
    if axes == "prone":
        return prone
    if axes == "permuted":
        perms = _proper_permutations()[1:]
        return perms[int(rng.integers(len(perms)))]
    if axes == "turned":
        start = prone if rng.random() < 0.5 else np.eye(3)
        axis = unit(rng.normal(size=3))
        return rotation_matrix(axis, float(rng.uniform(10.0, 60.0))) @ start
    if axes == "random":
        return _uniform_rotation(rng)
    raise ValueError(axes)


def _apparatus_params(base: Base, apparatus: str, rng: np.random.Generator) -> dict[str, Any]:
    if apparatus == "pins":
        n = int(rng.integers(2, 4))
        first = 1 if rng.random() < 0.5 else -1
        sides = [first, -first, -first][:n]  # one pin on one side, one or two on the other
        lo, hi = (8.0, 30.0) if base.vault_already_cut else (20.0, 60.0)
        return {
            "pins": [
                {
                    "side": s,  # +1: the subject's left (head +x)
                    "height_mm": float(rng.uniform(lo, hi)),
                    "z_mm": float(rng.uniform(-55.0, 5.0)),
                    "diameter_mm": float(rng.uniform(3.0, 4.0)),
                    "length_mm": float(rng.uniform(30.0, 50.0)),
                    "tilt_deg": float(rng.uniform(-15.0, 15.0)),
                }
                for s in sides
            ]
        }
    if apparatus == "tube":
        return {
            "diameter_mm": float(rng.uniform(8.0, 10.0)),
            "length_mm": 80.0,
            "down_deg": float(rng.uniform(15.0, 35.0)),
        }
    if apparatus == "holder":
        return {"gap_mm": float(rng.uniform(10.0, 25.0)), "thickness_mm": 4.0}
    if apparatus == "table":
        return {"gap_mm": float(rng.uniform(15.0, 40.0)), "thickness_mm": 6.0}
    return {}


def plain_spec(base: str, **changes: Any) -> VariantSpec:
    """A variant of ``base`` with nothing done to it but ``changes``, for tests and one-off
    checks: 300 HU, every piece, no smoothing or decimation, the jaw as scanned, the C-spine
    kept, no apparatus and no cut, the file axes of the corpus's first plain variant of that
    base.  An apparatus without ``params`` gets them drawn from ``index`` (default 900)."""
    first = next(s for s in generate_specs() if s.base == base and s.group == "plain")
    spec: dict[str, Any] = dict(
        index=900,
        iso="300",
        components="all",
        smooth="none",
        smooth_iterations=0,
        triangles=0,
        mandible="as_scanned",
        opening_deg=0.0,
        forward_mm=0.0,
        lateral_mm=0.0,
        cspine="kept",
        apparatus="none",
        cut="none",
        params={},
    )
    spec |= changes
    if "params" not in changes:
        rng = np.random.default_rng(int(spec["index"]))
        spec["params"] = _apparatus_params(BASES[base], str(spec["apparatus"]), rng)
    return dataclasses.replace(first, **spec)


def generate_specs(seed: int = SEED) -> list[VariantSpec]:
    """The corpus: :data:`COUNTS` variants per base, every dimension value covered per base."""
    specs: list[VariantSpec] = []
    for b_index, name in enumerate(COUNTS):
        base = BASES[name]
        rng = np.random.default_rng([seed, b_index])
        n, n_cut = COUNTS[name], CUT_COUNTS[name]
        cuts = ("none",) if base.vault_already_cut else CUTS
        draws = {
            "iso": _balanced(ISO, n, rng),
            "components": _balanced(COMPONENTS, n, rng),
            "smooth": _balanced(SMOOTH, n, rng),
            "triangles": _balanced(TRIANGLES, n, rng),
            "mandible": _balanced(MANDIBLE_CASES, n - n_cut, rng),
            "cspine": _balanced(CSPINE, n, rng),
            "apparatus": _balanced(APPARATUS, n, rng),
            "cut": _balanced(cuts, n - n_cut, rng),
            "axes": _balanced(AXES, n, rng),
            "mirrored": _balanced((False, True), n, rng),
            "units": _balanced(UNITS, n, rng),
        }
        for i in range(n):
            group = "cut" if i >= n - n_cut else "plain"
            mandible = "missing" if group == "cut" else draws["mandible"][i]
            cut = "vault+defect" if group == "cut" else draws["cut"][i]
            components = draws["components"][i]
            if mandible == "detached" and components == "largest":
                components = "over5" if rng.random() < 0.5 else "all"
            apparatus = draws["apparatus"][i]
            if mandible == "detached" and apparatus == "tube":
                apparatus = "pins"  # a tube between the teeth would join the jaws again
            opening = forward = lateral = 0.0
            if mandible == "opened":
                opening = float(rng.uniform(5.0, base.max_opening_deg))
            elif mandible in ("forward", "sideways"):
                if rng.random() < 0.5:
                    opening = float(rng.uniform(5.0, base.max_opening_deg))
                if mandible == "forward":
                    forward = float(rng.uniform(2.0, 6.0))
                else:
                    lateral = float(rng.uniform(2.0, 5.0)) * (1 if rng.random() < 0.5 else -1)
            rotation = _file_rotation(base, draws["axes"][i], rng)
            mirror_axis = int(rng.integers(3)) if draws["mirrored"][i] else -1
            shift = unit(rng.normal(size=3)) * float(rng.uniform(0.0, MAX_TRANSLATION_MM))
            smooth = draws["smooth"][i]
            spec = VariantSpec(
                base=name,
                index=i,
                group=group,
                iso=draws["iso"][i],
                components=components,
                smooth=smooth,
                smooth_iterations=int(rng.integers(10, 21)) if smooth == "taubin" else 0,
                triangles=int(draws["triangles"][i]),
                mandible=mandible,
                opening_deg=round(opening, 3),
                forward_mm=round(forward, 3),
                lateral_mm=round(lateral, 3),
                cspine=draws["cspine"][i],
                apparatus=apparatus,
                cut=cut,
                vault_above_mm=round(float(rng.uniform(35.0, 60.0)), 2),
                defect_radius_mm=round(float(rng.uniform(15.0, 20.0)), 2),
                defect_side="l" if rng.random() < 0.5 else "r",
                axes=draws["axes"][i],
                rotation=tuple(tuple(float(x) for x in row) for row in rotation),
                mirror_axis=mirror_axis,
                translation=tuple(float(x) for x in shift),
                units=draws["units"][i],
                params=_apparatus_params(base, apparatus, rng),
            )
            specs.append(VariantSpec.from_dict(spec.to_dict()))  # exactly as stored
    return specs


def quick_ids(specs: list[VariantSpec]) -> list[str]:
    """A fixed 12-variant subset: per base the first spec of each of four kinds."""
    kinds = (
        lambda s: s.axes == "own" and not s.mirrored and s.mandible == "as_scanned",
        lambda s: s.axes == "random" and not s.mirrored,
        lambda s: s.mirrored and s.units == "cm",
        lambda s: s.mandible in ("opened", "missing", "detached") or s.group == "cut",
    )
    chosen: list[str] = []
    for name in COUNTS:
        mine = [s for s in specs if s.base == name]
        for kind in kinds:
            pick = next((s for s in mine if kind(s) and s.id not in chosen), None)
            if pick is None:
                pick = next(s for s in mine if s.id not in chosen)
            chosen.append(pick.id)
    return chosen


# ---------------------------------------------------------------- transforms of a spec
def file_transform(spec: VariantSpec, anchor: Anchor) -> np.ndarray:
    """4 x 4 map from the base input frame (mm) to the variant's file frame (mm)."""
    c = np.asarray(anchor.bone_centre, np.float64)
    lin = np.asarray(spec.rotation, np.float64)
    if spec.mirrored:
        flip = np.ones(3)
        flip[spec.mirror_axis] = -1.0
        lin = np.diag(flip) @ lin
    return homogeneous(lin, c + np.asarray(spec.translation) - lin @ c)


def units_factor(spec: VariantSpec) -> float:
    """File number per mm."""
    return 0.1 if spec.units == "cm" else 1.0


def mandible_motion(spec: VariantSpec, anchor: Anchor) -> np.ndarray:
    """4 x 4 rigid map of the mandible in the input frame (identity when not moved):
    the opening about the anchor's condylar axis, then the push (head frame)."""
    if spec.mandible not in ("opened", "forward", "sideways"):
        return np.eye(4)
    h = anchor.input_to_head
    point_h = apply(h, anchor.tmj_point)
    axis_h = unit(apply_dir(h, anchor.tmj_direction))
    if axis_h[0] < 0:
        axis_h = -axis_h  # positive opening turns the chin down and back: about +x
    a_h = homogeneous(t=[spec.lateral_mm, 0.0, spec.forward_mm]) @ rotation_about(
        point_h, axis_h, spec.opening_deg
    )
    return np.linalg.inv(h) @ a_h @ h


# ---------------------------------------------------------------- voxel edits
def _box_of(mask: np.ndarray, grow: int = 0) -> tuple[slice, ...]:
    idx = np.nonzero(mask)
    return tuple(
        slice(max(int(a.min()) - grow, 0), min(int(a.max()) + grow + 1, n))
        for a, n in zip(idx, mask.shape, strict=True)
    )


def move_mandible(
    data: np.ndarray, labels: np.ndarray, volume: Volume, motion: np.ndarray, fill: float
) -> dict[str, Any]:
    """Move the mandible's voxels by ``motion`` (input frame) in place; overlap = max."""
    mand = labels == MANDIBLE
    src_box = _box_of(mand, grow=2)
    src_lo = np.array([s.start for s in src_box])
    sub_mand = mand[src_box]
    others = np.isin(labels[src_box], (CRANIUM, EXTRA, OTHER))
    carry = ndi.binary_dilation(sub_mand, ndi.generate_binary_structure(3, 3)) & ~others
    src = np.where(carry, data[src_box], fill).astype(np.float32)
    data[mand] = fill
    k = index_matrix(volume)
    a_idx = np.linalg.inv(k) @ motion @ k  # source kji -> destination kji
    corners = (
        np.array(
            [
                [a, b, c]
                for a in (0, sub_mand.shape[0])
                for b in (0, sub_mand.shape[1])
                for c in (0, sub_mand.shape[2])
            ],
            np.float64,
        )
        + src_lo
    )
    moved = apply(a_idx, corners)
    dst_lo = np.maximum(np.floor(moved.min(axis=0)).astype(int) - 2, 0)
    dst_hi = np.minimum(np.ceil(moved.max(axis=0)).astype(int) + 3, data.shape)
    inv = np.linalg.inv(a_idx)
    out = ndi.affine_transform(
        src,
        inv[:3, :3],
        offset=inv[:3, :3] @ dst_lo + inv[:3, 3] - src_lo,
        output_shape=tuple(int(x) for x in dst_hi - dst_lo),
        order=1,
        cval=float(fill),
    )
    dst = tuple(slice(int(a), int(b)) for a, b in zip(dst_lo, dst_hi, strict=True))
    data[dst] = np.maximum(data[dst], np.rint(out).astype(data.dtype))
    return {"box_voxels": int(np.prod(dst_hi - dst_lo)), "voxels_moved": int(sub_mand.sum())}


def detach_mandible(
    data: np.ndarray, labels: np.ndarray, volume: Volume, fill: float
) -> dict[str, Any]:
    """Remove the mandible voxels within the detach gap of any other bone (in place)."""
    gap = max(DETACH_GAP_MM, 1.5 * float(np.max(volume.spacing_mm)))
    mand = labels == MANDIBLE
    grow = int(math.ceil(gap / float(np.min(volume.spacing_mm)))) + 2
    box = _box_of(mand, grow=grow)
    other = np.isin(labels[box], (CRANIUM, EXTRA, OTHER))
    dist = ndi.distance_transform_edt(~other, sampling=np.asarray(volume.spacing_mm)[::-1])
    cut = mand[box] & (dist <= gap)
    sub = data[box]
    sub[cut] = fill
    return {"gap_mm": gap, "voxels_removed": int(cut.sum())}


def _head_grid(volume: Volume, anchor: Anchor, lo_h: np.ndarray, hi_h: np.ndarray):
    """Voxel index box covering the head-frame box [lo_h, hi_h] and its voxel centres
    in the head frame."""
    corners_h = np.array(
        [
            [x, y, z]
            for x in (lo_h[0], hi_h[0])
            for y in (lo_h[1], hi_h[1])
            for z in (lo_h[2], hi_h[2])
        ]
    )
    kji = apply(np.linalg.inv(index_matrix(volume)), apply(anchor.head_to_input, corners_h))
    shape = np.array(volume.data.shape)
    lo = np.clip(np.floor(kji.min(axis=0)).astype(int) - 1, 0, shape)
    hi = np.clip(np.ceil(kji.max(axis=0)).astype(int) + 2, 0, shape)
    if np.any(hi <= lo):
        return None, None
    grid = np.stack(
        np.meshgrid(*(np.arange(a, b) for a, b in zip(lo, hi, strict=True)), indexing="ij"), -1
    ).reshape(-1, 3)
    pts_h = apply(anchor.input_to_head, voxel_points(volume, grid))
    box = tuple(slice(int(a), int(b)) for a, b in zip(lo, hi, strict=True))
    return box, pts_h


def _paint(
    data: np.ndarray,
    volume: Volume,
    anchor: Anchor,
    lo_h: np.ndarray,
    hi_h: np.ndarray,
    signed_distance,
    value: float,
) -> int:
    """Add a solid given by its signed distance (head frame, mm; < 0 inside) with a
    one-voxel soft edge, composed by ``max``; returns the voxels it raised."""
    box, pts_h = _head_grid(volume, anchor, lo_h, hi_h)
    if box is None:
        return 0
    h = float(np.mean(volume.spacing_mm))
    occ = np.clip(0.5 - signed_distance(pts_h) / h, 0.0, 1.0).reshape(data[box].shape)
    return _blend(data, box, occ, value)


def _blend(data: np.ndarray, box: tuple[slice, ...], occ: np.ndarray, value: float) -> int:
    """Partial volume of a solid of ``value`` covering the fraction ``occ`` of each voxel
    in ``data[box]``: ``cur + occ * (value - cur)`` where that is higher (in place)."""
    sub = data[box]
    cur = sub.astype(np.float32)
    new = cur + occ.astype(np.float32) * np.maximum(np.float32(value) - cur, 0.0)
    raised = np.rint(new).astype(sub.dtype)
    changed = int(np.count_nonzero(raised != sub))
    sub[...] = raised
    return changed


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, ...]:
    ab = b - a
    t = np.clip((p - a) @ ab / (ab @ ab), 0.0, 1.0)
    radial = np.linalg.norm(p - (a + t[:, None] * ab), axis=1)
    return radial, t


def _cranium_points_h(labels: np.ndarray, volume: Volume, anchor: Anchor) -> np.ndarray:
    kji = np.argwhere(labels == CRANIUM)
    return apply(anchor.input_to_head, voxel_points(volume, kji))


def add_apparatus(
    spec: VariantSpec,
    base: Base,
    data: np.ndarray,
    labels: np.ndarray,
    volume: Volume,
    anchor: Anchor,
) -> dict[str, Any]:
    """Paint the spec's apparatus into ``data`` (in place); returns where it went."""
    h = float(np.max(volume.spacing_mm))
    record: dict[str, Any] = {"kind": spec.apparatus}
    if spec.apparatus == "pins":
        cran = _cranium_points_h(labels, volume, anchor)
        placed = []
        for pin in spec.params["pins"]:
            y, z, side = pin["height_mm"], pin["z_mm"], pin["side"]
            near = (np.abs(cran[:, 1] - y) < 2.5) & (np.abs(cran[:, 2] - z) < 2.5)
            near &= np.sign(cran[:, 0]) == side
            if not near.any():
                placed.append({"skipped": "no bone at this place"})
                continue
            surf = cran[near][np.argmax(side * cran[near][:, 0])]
            tilt = np.radians(pin["tilt_deg"])
            direction = unit([side * np.cos(tilt), np.sin(tilt), 0.0])
            tip = surf - 1.0 * direction  # pressing 1 mm into the bone
            end = tip + pin["length_mm"] * direction
            r = max(pin["diameter_mm"], h) / 2.0

            def sd(p, a=tip, b=end, r=r):
                return _segment_distance(p, a, b)[0] - r

            lo = np.minimum(tip, end) - r - 2 * h
            hi = np.maximum(tip, end) + r + 2 * h
            n = _paint(data, volume, anchor, lo, hi, sd, base.value(PIN_HU))
            placed.append({"tip_h": tip, "direction_h": direction, "radius_mm": r, "voxels": n})
        record["pins"] = placed
    elif spec.apparatus == "tube":
        lms = anchor.landmarks
        mouth = apply(anchor.input_to_head, 0.5 * (lms["pr"] + lms["id"]))
        down = np.radians(spec.params["down_deg"])
        direction = np.array([0.0, -np.sin(down), np.cos(down)])
        start = mouth - 25.0 * direction
        end = start + spec.params["length_mm"] * direction
        r_out = spec.params["diameter_mm"] / 2.0
        wall = max(1.5, h)

        def sd(p):
            radial, t = _segment_distance(p, start, end)
            ring = np.abs(radial - (r_out - wall / 2.0)) - wall / 2.0
            along = np.abs(t - 0.5) * spec.params["length_mm"] - spec.params["length_mm"] / 2
            return np.maximum(ring, along)

        lo = np.minimum(start, end) - r_out - 2 * h
        hi = np.maximum(start, end) + r_out + 2 * h
        n = _paint(data, volume, anchor, lo, hi, sd, base.value(TUBE_HU))
        record.update(start_h=start, end_h=end, wall_mm=wall, voxels=n)
    elif spec.apparatus == "holder":
        cran = _cranium_points_h(labels, volume, anchor)
        back = cran[(np.abs(cran[:, 0]) < 20.0) & (cran[:, 1] > -10.0)]
        occiput = back[np.argmin(back[:, 2])]
        radius = 90.0
        gap, thick = spec.params["gap_mm"], max(spec.params["thickness_mm"], h)
        centre = occiput + np.array([0.0, 0.0, radius])

        def sd(p):
            d = p - centre
            dist = np.linalg.norm(d, axis=1)
            shell = np.abs(dist - (radius + gap + thick / 2.0)) - thick / 2.0
            cap = (-d[:, 2]) - np.cos(np.radians(55.0)) * dist  # > 0 within 55 deg of -z
            return np.maximum.reduce([shell, -cap, np.abs(d[:, 0]) - 70.0])

        outer = radius + gap + thick
        span = np.array([70.0, outer * np.sin(np.radians(55.0)), 0.0]) + 2 * h
        lo = centre + np.array([-span[0], -span[1], -outer - 2 * h])
        hi = centre + np.array([span[0], span[1], -(radius + gap) * np.cos(np.radians(55.0))])
        hi = hi + 2 * h
        n = _paint(data, volume, anchor, lo, hi, sd, base.value(HOLDER_HU))
        record.update(occiput_h=occiput, voxels=n)
    elif spec.apparatus == "table":
        # a plate under the head in the scanner's frame: along the input frame's posterior
        kji = np.argwhere(np.isin(labels, (CRANIUM, MANDIBLE, EXTRA)))
        pts = voxel_points(volume, kji)
        post = -unit(base.hint[0])
        lowest = float(np.max(pts @ post))
        gap, thick = spec.params["gap_mm"], max(spec.params["thickness_mm"], h)
        left = unit(base.hint[2])
        mid = float(np.median(pts @ left))
        # the whole volume in the input frame (coordinates are linear in k, j, i)
        m = index_matrix(volume)
        shape = volume.data.shape
        corners = np.array(
            [
                [a, b, c]
                for a in (0, shape[0] - 1)
                for b in (0, shape[1] - 1)
                for c in (0, shape[2] - 1)
            ],
            np.float64,
        )
        room = float(np.max(apply(m, corners) @ post)) - lowest
        if room < thick + 2.0:
            record.update(skipped="no room for a table in the field of view", room_mm=room)
            return record
        gap = min(gap, room - thick - 1.0)
        axes = [np.arange(n, dtype=np.float32) for n in shape]

        def linear(d: np.ndarray, offset: float) -> np.ndarray:
            c = d @ m[:3, :3]
            return (
                np.float32(d @ m[:3, 3] - offset)
                + np.float32(c[0]) * axes[0][:, None, None]
                + np.float32(c[1]) * axes[1][None, :, None]
                + np.float32(c[2]) * axes[2][None, None, :]
            )

        depth = linear(post, lowest + gap)
        lateral = linear(left, mid)
        sd = np.maximum(np.abs(depth - thick / 2.0) - thick / 2.0, np.abs(lateral) - 80.0)
        del depth, lateral
        occ = np.clip(0.5 - sd / np.float32(np.mean(volume.spacing_mm)), 0.0, 1.0)
        del sd
        rows = np.flatnonzero(occ.reshape(shape[0], -1).max(axis=1) > 0)
        if len(rows):
            box = (slice(int(rows.min()), int(rows.max()) + 1),)
            n = _blend(data, box, occ[box], base.value(TABLE_HU))
        else:
            n = 0
        record.update(plane_offset_mm=lowest + gap, voxels=n)
    return record


def frontal_defect(
    spec: VariantSpec, labels: np.ndarray, volume: Volume, anchor: Anchor
) -> dict[str, Any] | None:
    """The defect cylinder (cut_skull's hole dict, input frame) above the spec's orbit."""
    lms = anchor.landmarks
    side = spec.defect_side
    h = anchor.input_to_head
    orbit_h = apply(h, lms[f"or_{side}"])
    rim_h = apply(h, lms[f"mso_{side}"])
    r = spec.defect_radius_mm
    centre_xy = np.array([orbit_h[0], rim_h[1] + r + 4.0])
    cran = _cranium_points_h(labels, volume, anchor)
    disc = np.linalg.norm(cran[:, :2] - centre_xy, axis=1) <= r + 2.0
    disc &= cran[:, 2] > 0.0  # the front half of the head
    if not disc.any():
        return None
    pts = cran[disc]
    # outer surface: the front-most voxel per 2 mm column
    keys = np.floor(pts[:, :2] / 2.0).astype(np.int64)
    order = np.lexsort((-pts[:, 2], keys[:, 1], keys[:, 0]))
    _, first = np.unique(keys[order], axis=0, return_index=True)
    surf = pts[order][first]
    mean = surf.mean(axis=0)
    axis = np.linalg.svd(surf - mean)[2][-1]
    if axis[2] < 0:
        axis = -axis
    col = np.linalg.norm(surf[:, :2] - centre_xy, axis=1)
    centre_h = surf[np.argmin(col)]
    return {
        "side": side,
        "centre_mm": apply(anchor.head_to_input, centre_h),
        "axis": unit(apply_dir(anchor.head_to_input, axis)),
        "radius_mm": r,
        "depth_in_mm": 15.0,
        "depth_out_mm": 15.0,
        "centre_h": centre_h,
    }


def vault_plane(spec: VariantSpec, anchor: Anchor) -> tuple[np.ndarray, np.ndarray]:
    """Point and normal (input frame) of the vault cut: parallel to Frankfort, the spec's
    height above the supraorbital rims (the mean of mso_l and mso_r)."""
    h = anchor.input_to_head
    rims = 0.5 * (apply(h, anchor.landmarks["mso_l"]) + apply(h, anchor.landmarks["mso_r"]))
    point_h = np.array([0.0, rims[1] + spec.vault_above_mm, rims[2]])
    return apply(anchor.head_to_input, point_h), unit(apply_dir(anchor.head_to_input, [0, 1, 0]))


# ---------------------------------------------------------------- surface
def keep_components(mesh: Mesh, how: str) -> tuple[Mesh, dict[str, Any]]:
    """Largest / every component over 5 % of the triangles / everything."""
    from workbench.core.isosurface import face_component_labels

    labels = face_component_labels(np.asarray(mesh.faces), mesh.n_vertices)
    counts = np.bincount(labels)
    if how == "largest":
        keep = [int(np.argmax(counts))]
    elif how == "over5":
        keep = np.flatnonzero(counts > 0.05 * mesh.n_faces).tolist()
    elif how == "all":
        keep = list(range(len(counts)))
    else:
        raise ValueError(how)
    faces = np.asarray(mesh.faces)[np.isin(labels, keep)]
    used = np.unique(faces)
    remap = np.full(mesh.n_vertices, -1)
    remap[used] = np.arange(len(used))
    out = Mesh(mesh.vertices[used], remap[faces])
    return out, {"n_components": len(counts), "kept": len(keep)}


def _surface_samples(mask: np.ndarray, volume: Volume, n: int = 6000) -> np.ndarray:
    """Input-frame centres of up to ``n`` boundary voxels of ``mask`` (evenly spread)."""
    edge = mask & ~ndi.binary_erosion(mask)
    kji = np.argwhere(edge)
    if len(kji) > n:
        kji = kji[np.linspace(0, len(kji) - 1, n).astype(int)]
    return voxel_points(volume, kji)


def build_mesh(
    spec: VariantSpec, anchor: Anchor | None = None, root: Path | None = None
) -> tuple[Mesh, dict[str, Any], str | None]:
    """The variant's bone mesh in the **base input frame** (mm), its build record and the
    credit line of the data (or None)."""
    from benchmarks.cases.cut_skull import clip_by_plane, hole_voxels
    from workbench.core.isosurface import decimate, taubin_smooth
    from workbench.services.ct.ct_mesh import mesh_from_ct

    base = BASES[spec.base]
    anchor = anchor or load_anchor(spec.base, root)
    volume = load_volume(spec.base)
    labels = load_segmentation(spec.base, root).labels
    data = np.array(volume.data)  # a writable copy, native dtype
    record: dict[str, Any] = {}
    timings: dict[str, float] = {}
    t = time.perf_counter()
    if spec.cspine == "removed":
        data[labels == EXTRA] = base.fill
    motion = mandible_motion(spec, anchor)
    mand_samples = _surface_samples(labels == MANDIBLE, volume)
    if spec.mandible == "missing":
        data[labels == MANDIBLE] = base.fill
    elif spec.mandible == "detached":
        record["detach"] = detach_mandible(data, labels, volume, base.fill)
    elif spec.mandible in ("opened", "forward", "sideways"):
        record["motion"] = move_mandible(data, labels, volume, motion, base.fill)
    if "defect" in spec.cut:
        hole = frontal_defect(spec, labels, volume, anchor)
        if hole is not None:
            mask = hole_voxels(volume, hole) & (labels == CRANIUM)
            data[mask] = base.fill
            record["defect"] = {**hole, "voxels_removed": int(mask.sum())}
    if spec.apparatus != "none":
        record["apparatus"] = add_apparatus(spec, base, data, labels, volume, anchor)
    timings["voxels"] = time.perf_counter() - t
    t = time.perf_counter()
    edited = with_data(volume, data)
    level, rule = iso_level(base, spec.iso, edited)
    result = mesh_from_ct(edited, "bone", iso=level, largest_component=False)
    mesh = result.mesh
    record["iso"] = {"level": level, "rule": rule, "n_faces_extracted": mesh.n_faces}
    timings["extract"] = time.perf_counter() - t
    t = time.perf_counter()
    if "vault" in spec.cut:
        point, normal = vault_plane(spec, anchor)
        mesh = clip_by_plane(mesh, point, normal)
        record["vault_cut"] = {"point_mm": point, "normal": normal}
    mesh, record["components"] = keep_components(mesh, spec.components)
    if spec.smooth_iterations:
        mesh = Mesh(taubin_smooth(mesh.vertices, mesh.faces, spec.smooth_iterations), mesh.faces)
    if spec.triangles and spec.triangles < mesh.n_faces:
        mesh = Mesh(*decimate(mesh.vertices, mesh.faces, spec.triangles))
        if spec.components == "largest":
            mesh, _ = keep_components(mesh, "largest")
    timings["surface"] = time.perf_counter() - t
    # does the mesh hold a mandible (moved as the voxels were)?
    from workbench.core.spatial import MeshIndex

    index = MeshIndex(mesh)
    on = index.closest_points(apply(motion, mand_samples)).distances
    reach = max(PRESENT_DISTANCE_MM, 1.5 * float(np.max(volume.spacing_mm)))
    fraction = float(np.mean(on <= reach))
    record["mandible_on_mesh_fraction"] = fraction
    if spec.mandible == "detached":
        record["detach"]["separate_piece"] = _separate(
            mesh, apply(motion, mand_samples), labels, volume, reach
        )
    record["timings_s"] = {k: round(v, 3) for k, v in timings.items()}
    record["n_faces"], record["n_vertices"] = mesh.n_faces, mesh.n_vertices
    return mesh, record, result.credit


def _separate(
    mesh: Mesh, mand_pts: np.ndarray, labels: np.ndarray, volume: Volume, reach: float
) -> bool:
    """Whether the mesh piece holding most of the mandible is not the one holding most of
    the cranium (each sample votes for the piece of its nearest vertex)."""
    from scipy.spatial import cKDTree

    from workbench.core.isosurface import face_component_labels

    faces = np.asarray(mesh.faces)
    comp = face_component_labels(faces, mesh.n_vertices)
    vcomp = np.empty(mesh.n_vertices, np.int64)
    vcomp[faces.ravel()] = np.repeat(comp, 3)
    tree = cKDTree(mesh.vertices)
    cran = _surface_samples(labels == CRANIUM, volume)
    d_m, i_m = tree.query(mand_pts)
    d_c, i_c = tree.query(cran)
    votes_m = vcomp[i_m[d_m <= reach]]
    votes_c = vcomp[i_c[d_c <= reach]]
    if not len(votes_m) or not len(votes_c):
        return bool(len(votes_m))
    return bool(np.bincount(votes_m).argmax() != np.bincount(votes_c).argmax())


# ---------------------------------------------------------------- truth of a variant
def variant_truth(
    spec: VariantSpec, truth: dict[str, Any], anchor: Anchor, mandible_present: bool
) -> dict[str, Any]:
    """The spec's truth in its file frame (mm) from the base ``truth`` (see module docstring)."""
    x = file_transform(spec, anchor)
    lms = {c: apply(x, np.asarray(truth["landmarks"][c])) for c in SIX}
    motion = mandible_motion(spec, anchor)
    h = np.asarray(truth["input_to_head"], np.float64)
    point_in = np.asarray(truth["tmj_axis"]["point"], np.float64)
    jaw = truth["jaw_by_reference"]
    present = bool(mandible_present)
    # the jaw pose the registration should find: the base's, then the applied motion about
    # the truth's condyle point (head frame)
    a_h = h @ motion @ np.linalg.inv(h)
    point_h = apply(h, point_in)
    opening_applied = spec.opening_deg
    expected = {}
    for sex, j in jaw.items():
        base_shift = np.asarray(j["shift_h"], np.float64)
        moved = apply(a_h, point_h + base_shift) - point_h
        expected[sex] = {
            "opening_deg": j["opening_deg"] + opening_applied,
            "protrusion_mm": float(moved[2]),
            "lateral_mm": float(moved[0]),
        }
    return {
        "landmarks": lms,
        "tmj_axis": {
            "point": apply(x, point_in),
            "direction": unit(apply_dir(x, truth["tmj_axis"]["direction"])),
        },
        "file_transform": x,
        "units_factor": units_factor(spec),
        "mirrored_file": bool(truth["mirrored"]) != bool(np.linalg.det(x[:3, :3]) < 0),
        "mandible_present": present,
        "mandible_motion_input": motion,
        "applied": {
            "opening_deg": opening_applied,
            "forward_mm": spec.forward_mm,
            "lateral_mm": spec.lateral_mm,
        },
        "jaw_expected": expected if present else None,
        "opening_deg": expected[EVAL_SEX]["opening_deg"] if present else None,
        "truth_registration_hash": truth["registration_hash"],
    }


# ---------------------------------------------------------------- the corpus on disk
def corpus_dir(root: Path | None = None) -> Path:
    return results_dir("meshes", root=root)


def mesh_path(spec: VariantSpec, root: Path | None = None) -> Path:
    return corpus_dir(root) / f"{spec.id}.ply"


def build_variant(
    spec: VariantSpec, root: Path | None = None, force: bool = False
) -> dict[str, Any]:
    """Build (or reuse) the variant's PLY and return its manifest entry (truth included)."""
    from workbench.io.mesh_formats import ply
    from workbench.io.samples import credit_comment

    path = mesh_path(spec, root)
    meta_path = path.with_suffix(".json")
    anchor = load_anchor(spec.base, root)
    truth = load_truth(spec.base, root)
    if not force and path.is_file() and meta_path.is_file():
        entry = read_json(meta_path)
        if entry.get("generator_version") == GENERATOR_VERSION:
            if entry["truth"]["truth_registration_hash"] != truth["registration_hash"]:
                entry["truth"] = jsonable(
                    variant_truth(spec, truth, anchor, entry["truth"]["mandible_present"]), 6
                )
                write_json(meta_path, entry)
            entry["cached"] = True
            return entry
    t0 = time.perf_counter()
    mesh, record, credit = build_mesh(spec, anchor, root)
    present = spec.mandible != "missing" and record["mandible_on_mesh_fraction"] >= (
        PRESENT_FRACTION
    )
    vt = variant_truth(spec, truth, anchor, present)
    x = vt["file_transform"]
    k = units_factor(spec)
    out = mesh.transformed(x)
    if k != 1.0:
        out = Mesh(out.vertices * k, out.faces)
    comments = [f"robustness corpus variant {spec.id} (generator v{GENERATOR_VERSION})"]
    if credit:
        comments.append(credit_comment(credit))
    ply.write(path, out, comments=comments, units=spec.units)
    entry = {
        "id": spec.id,
        "generator_version": GENERATOR_VERSION,
        "file": path.name,
        "units": spec.units,
        "spec": spec.to_dict(),
        "truth": vt,
        "build": record,
        "credit": credit,
        "build_seconds": round(time.perf_counter() - t0, 2),
    }
    write_json(meta_path, entry)
    entry = read_json(meta_path)
    entry["cached"] = False
    return entry


def build_corpus(
    specs: list[VariantSpec], root: Path | None = None, force: bool = False, say=print
) -> list[dict[str, Any]]:
    """Build every spec (cached) and write ``manifest.json`` beside the meshes."""
    entries = []
    for i, spec in enumerate(specs):
        entry = build_variant(spec, root, force)
        if not entry["cached"]:
            say(
                f"  [{i + 1}/{len(specs)}] built {spec.id}: {entry['build']['n_faces']} faces, "
                f"{entry['build_seconds']} s"
            )
        entries.append(entry)
    manifest = {
        "generator_version": GENERATOR_VERSION,
        "seed": SEED,
        "units": "mm (file numbers x units_factor)",
        "n": len(entries),
        "variants": [{k: v for k, v in e.items() if k != "cached"} for e in entries],
    }
    write_json(corpus_dir(root).parent / "manifest.json", manifest)
    return entries


# ---------------------------------------------------------------- check image
def variant_picture(entry: dict[str, Any], path: Path, root: Path | None = None) -> Path:
    """Side, front and top views of a built variant mapped back into the anchor's head frame
    (the file transform undone), with its truth landmarks: a check that the mesh and its
    truth travelled together."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from workbench.io.meshes import read_mesh

    spec = VariantSpec.from_dict(entry["spec"])
    anchor = load_anchor(spec.base, root)
    mesh = read_mesh(corpus_dir(root) / entry["file"], units=entry["units"]).mesh
    to_h = anchor.input_to_head @ np.linalg.inv(np.asarray(entry["truth"]["file_transform"]))
    v = apply(to_h, mesh.vertices)
    lms = {c: apply(to_h, np.asarray(p)) for c, p in entry["truth"]["landmarks"].items()}
    step = max(1, len(v) // 60000)
    v = v[::step]
    fig, axes = plt.subplots(1, 3, figsize=(16, 6))
    for ax, (a, b, name) in zip(
        axes, ((2, 1, "side (z, y)"), (0, 1, "front (x, y)"), (0, 2, "top (x, z)")), strict=True
    ):
        ax.scatter(v[:, a], v[:, b], s=0.2, c="0.3", alpha=0.3)
        for c, p in lms.items():
            ax.plot(p[a], p[b], "r+", ms=12)
            ax.annotate(c, (p[a], p[b]), color="r", fontsize=8)
        ax.set_aspect("equal")
        ax.set_title(name)
    fig.suptitle(
        f"{spec.id}: mandible {spec.mandible}, apparatus {spec.apparatus}, cut {spec.cut}, "
        f"iso {spec.iso}, {spec.components}, {entry['build']['n_faces']} faces "
        "(head frame of the anchor)"
    )
    fig.tight_layout()
    fig.savefig(path, dpi=70)
    plt.close(fig)
    return path
