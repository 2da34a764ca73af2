#!/usr/bin/env python
"""Incomplete real skull: the Visible Human Female head CT's bone without mandible, holed and cut.

A test case for skull-to-face reconstruction whose ground truth is real: the
bone surface of one CT, made incomplete the way real cases are, and the true
skin of the *same* CT.  Run from the repository root::

    python benchmarks/cases/cut_skull.py \
        --ct ../shared/data/vhp_female_head_ct/vhf_head_ct_1mm.nii.gz --out DIR

or call :func:`make_cut_skull` (cheap when ``DIR`` already holds the outputs
for the same CT file).  ``DIR`` is a cache folder: meshes derived from the CT
are never committed to the repository.

Outputs (mm, in the volume's physical frame -- RAS for NIfTI, the frame
:func:`workbench.services.ct.ct_mesh.mesh_from_ct` returns)
---------------------------------------------------------------------------
``full_bone.ply``
    The complete bone surface, iso 300 HU, largest component (cranium,
    facial skeleton, mandible with teeth, C1-C6: at 300 HU they are one piece).
``skin.ply``
    The true skin, iso -400 HU, largest component (the ground truth).
``cut_skull.ply``
    The incomplete bone surface: (a) no mandible, (b) a frontal defect above
    one orbit, (c) the vault cut off by a plane parallel to the Frankfort
    plane, with an open rim.  One connected mesh.
``cut_skull.json``
    What was removed and how (parameters, landmarks, vertex/area counts before
    and after), the SHA-256 of the CT file and the NLM credit line.

Method
------
Directions come from the volume's frame (RAS: +x right, +y anterior, +z
superior; LPS handled too); the volume must be axis aligned.  For the
landmark maps the bone mask is viewed as an array ``[S, A, R]`` (superior,
anterior, right).  No registration landmarks of the project are used; every
landmark below is derived from the bone mask's geometry.

1. **Mandible** (on voxels).  At 300 HU the mandible touches the cranium:
   on this CT only at the two temporomandibular joints (the condyles sit on
   the articular eminences -- the mouth is open, the teeth are apart; 14 and
   4 touching voxels at 1 mm, see ``contacts_at_bone_level`` in the record).
   The bone mask is labelled (6-connectivity) at increasing thresholds (300,
   350, ... HU) until one component other than the largest is mandible-like:
   at least 10 cm^3, at least 80 mm wide (left-right), U-shaped (its centroid
   lies outside its own axial projection, in the hollow of the U), below the
   largest component's centroid, with its front within 30 mm of the front of
   the largest component.  (The C-spine, which separates at a higher
   threshold, is narrow and posterior.)  That component (the mandible) and the
   largest one (cranium) seed a watershed of the inverted CT values inside the
   300 HU mask, in a box around the mandible, so every 300 HU voxel goes to the
   bone it is connected to through the densest path and the split falls in
   the low-density joint spaces.  The mandible's voxels are set to -1000 HU in
   a copy of the volume.  The C-spine is *kept* (it stays joined to the
   occipital condyles at 300 HU; realistic extra anatomy).
2. **Orbits** (front depth map: distance from the front to the first bone
   voxel, per (S, R) column).  An orbit's opening is a vertical "pocket": a
   pixel at least 12 mm deeper than the shallowest bone within 50 mm above
   *and* within 50 mm below it.  The orbits are the largest such region on
   each side of the midline (15-60 mm lateral, at least 300 mm^2).  The upper
   rim (supraorbital margin) is the highest point of the opening within 10 mm
   of its centre column; orbitale the lowest point of the opening.
3. **Porion** (lateral depth maps from the right and from the left).  The
   external acoustic meatus is a pit: a pixel at least 4 mm deeper than the
   shallowest bone within 12 mm in each of the four directions; porion is the
   top of the largest pit 50-120 mm behind the orbits' front and within 30 mm
   of orbitale's height.
4. **Frankfort plane**: least-squares plane through both orbitale and both
   porion points (on this CT 1.1 degrees from the axial plane).  **Vault
   cut**: the plane parallel to it, 45 mm above the mean of the two upper
   orbital rims; bone above it is removed by clipping
   the extracted surface exactly along the plane (triangles split, no cap),
   so the rim is open like a CT field of view that ends there.  (Removing the
   voxels instead would close the surface over the cut.)
5. **Frontal defect** (on voxels): a cylinder of radius 20 mm whose axis is
   the outward normal of the frontal bone (plane fit to the front surface
   within the radius) at the point of the outer surface straight above the
   centre of the patient's right orbit, midway (22.5 mm) between its upper
   rim and the cut plane; the voxels from 15 mm inside to 15 mm outside of
   that point along the axis are set to -1000 HU.  That is the full thickness
   of the frontal squama (its inner table lies within 14 mm of the centre's
   tangent plane over the whole disc) but not the orbital roof behind the
   brow, and the defect keeps bone margins.  The radius is the largest that
   leaves a bony bridge (about 3-4 mm) both to the brow and to the cut: the
   band between rim and cut is 45 mm high, so a 25 mm radius defect (50 mm
   across) would open into the cut rim (``--hole-radius 25`` builds that).
6. Marching cubes of the edited copy at 300 HU (the project's
   ``mesh_from_ct``), clip by the vault plane, keep the largest connected
   piece (which holds the cranium, face, maxilla with the upper teeth and the
   C-spine; the rest is debris, the hyoid, calcifications and wrap lines).
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import os
import secrets
import shutil
import sys
from dataclasses import dataclass
from pathlib import Path
from time import perf_counter
from typing import Any

import numpy as np
from scipy import ndimage as ndi

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from skimage.segmentation import watershed  # noqa: E402

from workbench.core.isosurface import face_component_labels  # noqa: E402
from workbench.core.mesh import Mesh, boundary_loops  # noqa: E402
from workbench.core.volume import Volume  # noqa: E402
from workbench.io.meshes import write_mesh  # noqa: E402
from workbench.io.volumes import read_volume  # noqa: E402
from workbench.services.ct.ct_mesh import mesh_from_ct  # noqa: E402

GENERATOR_VERSION = 1
CUT_SKULL = "cut_skull.ply"
SKIN = "skin.ply"
FULL_BONE = "full_bone.ply"
RECORD = "cut_skull.json"
OUTPUTS = (CUT_SKULL, SKIN, FULL_BONE)

CREDIT = "Courtesy of the U.S. National Library of Medicine"
FROZEN_COPY_NOTE = (
    "This copy is a frozen snapshot and may not reflect the most current or accurate data "
    "available from NLM. NLM does not endorse this project."
)
SOURCE = (
    "Visible Human Project® (U.S. National Library of Medicine), Visible Human Female head CT "
    "resampled to 1 mm; see PROVENANCE.md beside the CT file"
)


@dataclass(frozen=True)
class CutParams:
    """Parameters of the case (mm and HU).  Recorded in ``cut_skull.json``."""

    bone_iso_hu: float = 300.0
    skin_iso_hu: float = -400.0
    removed_hu: float = -1000.0
    # mandible separation
    separation_start_hu: float = 300.0
    separation_step_hu: float = 50.0
    separation_max_hu: float = 1500.0
    mandible_min_volume_cm3: float = 10.0
    mandible_min_width_mm: float = 80.0
    mandible_front_tolerance_mm: float = 30.0
    watershed_margin_mm: float = 15.0
    # orbits and porion
    orbit_pocket_depth_mm: float = 12.0
    orbit_pocket_reach_mm: float = 50.0
    orbit_min_area_mm2: float = 300.0
    orbit_lateral_range_mm: tuple[float, float] = (15.0, 60.0)
    porion_pit_depth_mm: float = 4.0
    porion_pit_reach_mm: float = 12.0
    # vault cut
    vault_cut_above_rim_mm: float = 45.0
    # frontal defect
    hole_side: str = "right"  # the patient's right
    hole_radius_mm: float = 20.0
    hole_centre_above_rim_mm: float | None = None  # None: midway between the rim and the cut
    hole_depth_in_mm: float = 15.0
    hole_depth_out_mm: float = 15.0


# ---------------------------------------------------------------- small helpers
def sha256_file(path: str | os.PathLike[str], chunk: int = 1 << 20) -> str:
    """Hex SHA-256 of a file."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        while block := handle.read(chunk):
            digest.update(block)
    return digest.hexdigest()


def _unit(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v)


def _r(x: Any, nd: int = 3) -> Any:
    """Round floats (or arrays of them) for the JSON record."""
    arr = np.asarray(x, dtype=np.float64)
    if arr.ndim == 0:
        return round(float(arr), nd)
    return np.round(arr, nd).tolist()


def mesh_summary(mesh: Mesh) -> dict[str, Any]:
    """Counts, area and bounds of a mesh (mm)."""
    return {
        "n_vertices": int(mesh.n_vertices),
        "n_faces": int(mesh.n_faces),
        "area_mm2": _r(mesh.area, 1),
        "bounds_mm": _r(mesh.bounds, 2),
    }


def anatomical_directions(frame: str) -> dict[str, np.ndarray]:
    """Unit vectors "right", "anterior", "superior" in a physical frame (RAS or LPS)."""
    s = 1.0 if frame == "RAS" else -1.0
    return {
        "right": np.array([s, 0.0, 0.0]),
        "anterior": np.array([0.0, s, 0.0]),
        "superior": np.array([0.0, 0.0, 1.0]),
    }


class _Canon:
    """View of ``data[k, j, i]`` arrays in anatomical order ``[S, A, R]``.

    Index increases toward superior, anterior and the patient's right; the
    volume must be axis aligned (any permutation/flip of the index axes).
    """

    def __init__(self, volume: Volume) -> None:
        d = np.asarray(volume.direction, np.float64)
        if volume.frame == "LPS":
            d = np.diag([-1.0, -1.0, 1.0]) @ d  # columns in RAS
        ras_of_index = np.argmax(np.abs(d), axis=0)
        if (
            sorted(ras_of_index.tolist()) != [0, 1, 2]
            or np.min(np.abs(d[ras_of_index, [0, 1, 2]])) < 0.999
        ):
            raise ValueError(f"the volume must be axis aligned, direction = {d.tolist()}")
        # index axis (i=0, j=1, k=2) along S, A, R (= RAS axes 2, 1, 0)
        self.index_axis = [int(np.flatnonzero(ras_of_index == ras)[0]) for ras in (2, 1, 0)]
        self.flip = [
            bool(d[ras, a] < 0) for ras, a in zip((2, 1, 0), self.index_axis, strict=False)
        ]
        self.data_axes = [2 - a for a in self.index_axis]
        self.shape_ijk = volume.shape_ijk
        self.spacing = np.asarray(volume.spacing_mm, np.float64)[self.index_axis]
        self.volume = volume

    def view(self, array: np.ndarray) -> np.ndarray:
        out = np.transpose(array, self.data_axes)
        for axis, flipped in enumerate(self.flip):
            if flipped:
                out = np.flip(out, axis=axis)
        return out

    def to_ijk(self, sar: np.ndarray) -> np.ndarray:
        sar = np.atleast_2d(np.asarray(sar, np.float64))
        ijk = np.zeros_like(sar)
        for c in range(3):
            a = self.index_axis[c]
            n = self.shape_ijk[a]
            ijk[:, a] = (n - 1 - sar[:, c]) if self.flip[c] else sar[:, c]
        return ijk

    def to_physical(self, sar: np.ndarray) -> np.ndarray:
        return self.volume.index_to_physical(self.to_ijk(sar))

    def from_physical(self, points: np.ndarray) -> np.ndarray:
        ijk = np.atleast_2d(self.volume.physical_to_index(np.atleast_2d(points)))
        sar = np.zeros_like(ijk)
        for c in range(3):
            a = self.index_axis[c]
            n = self.shape_ijk[a]
            sar[:, c] = (n - 1 - ijk[:, a]) if self.flip[c] else ijk[:, a]
        return sar


# ---------------------------------------------------------------- mandible
_STRUCT6 = ndi.generate_binary_structure(3, 1)
_NO_BONE = 1e4  # depth-map value (mm) of a ray that meets no bone


def _component_geometry(canon: _Canon, mask_sar: np.ndarray, offset: np.ndarray) -> dict:
    """Centroid, extents (mm) and U-shape test of a component given as a cropped mask."""
    s, a, r = np.nonzero(mask_sar)
    pts = np.c_[s, a, r] + offset
    mm = pts * canon.spacing
    lo, hi = mm.min(axis=0), mm.max(axis=0)
    centre = mm.mean(axis=0)
    proj = mask_sar.any(axis=0)  # (A, R)
    ca, cr = np.round(pts.mean(axis=0)[1:] - offset[1:]).astype(int)
    win = proj[max(ca - 2, 0) : ca + 3, max(cr - 2, 0) : cr + 3]
    return {
        "centre_sar_mm": centre,
        "lo_sar_mm": lo,
        "hi_sar_mm": hi,
        "width_mm": float(hi[2] - lo[2]),
        "centroid_in_axial_projection": bool(win.any()),
    }


def find_mandible(volume: Volume, params: CutParams) -> tuple[np.ndarray, dict[str, Any]]:
    """Boolean ``data``-shaped mask of the mandible's voxels at ``bone_iso_hu``, and a report."""
    canon = _Canon(volume)
    data = np.asarray(volume.data)
    data_sar = canon.view(data)
    vox_mm3 = float(np.prod(volume.spacing_mm))
    tried: list[dict[str, Any]] = []
    thresholds = np.arange(
        params.separation_start_hu, params.separation_max_hu + 1e-9, params.separation_step_hu
    )
    found = None
    for thr in thresholds:
        labels, _ = ndi.label(data_sar >= thr, _STRUCT6)
        sizes = np.bincount(labels.ravel())
        sizes[0] = 0
        big = int(np.argmax(sizes))
        objects = ndi.find_objects(labels)
        sl = objects[big - 1]
        cranium = _component_geometry(canon, labels[sl] == big, np.array([s.start for s in sl]))
        entry: dict[str, Any] = {"threshold_hu": float(thr), "candidates": []}
        for label in np.argsort(sizes)[::-1][1:9]:
            if sizes[label] * vox_mm3 < params.mandible_min_volume_cm3 * 1000.0:
                break
            sl = objects[label - 1]
            geo = _component_geometry(canon, labels[sl] == label, np.array([s.start for s in sl]))
            checks = {
                "wide": geo["width_mm"] >= params.mandible_min_width_mm,
                "u_shaped": not geo["centroid_in_axial_projection"],
                "below_cranium_centroid": geo["centre_sar_mm"][0] < cranium["centre_sar_mm"][0],
                "front_near_face": geo["hi_sar_mm"][1]
                >= cranium["hi_sar_mm"][1] - params.mandible_front_tolerance_mm,
            }
            entry["candidates"].append(
                {
                    "volume_cm3": _r(sizes[label] * vox_mm3 / 1000.0, 2),
                    "width_mm": _r(geo["width_mm"], 1),
                    "checks": checks,
                }
            )
            if all(checks.values()):
                found = (float(thr), labels, big, int(label), sl, geo)
                break
        tried.append(entry)
        if found is not None:
            break
    if found is None:
        raise RuntimeError(
            "no mandible-like component separated from the cranium between "
            f"{thresholds[0]:g} and {thresholds[-1]:g} HU: {tried}"
        )
    thr, labels, big, label, sl, geo = found
    n_seed = int(np.count_nonzero(labels[sl] == label))

    # grow both seeds back into the bone_iso mask (watershed of -HU), in a box around the mandible
    margin = np.ceil(params.watershed_margin_mm / canon.spacing).astype(int)
    box = tuple(
        slice(max(s.start - m, 0), min(s.stop + m, n))
        for s, m, n in zip(sl, margin, data_sar.shape, strict=False)
    )
    sub = data_sar[box]
    markers = np.zeros(sub.shape, np.int32)
    markers[labels[box] == big] = 1
    markers[labels[box] == label] = 2
    bone = sub >= params.bone_iso_hu
    grown = watershed(-sub.astype(np.float32), markers, mask=bone)
    mandible_sar = np.zeros(data_sar.shape, bool)
    mandible_sar[box] = grown == 2
    # where does the removed mandible touch the remaining bone at the bone level?
    rest = (sub >= params.bone_iso_hu) & (grown != 2)
    touch = ndi.binary_dilation(grown == 2, _STRUCT6) & rest
    touch_lab, n_touch = ndi.label(touch, np.ones((3, 3, 3), bool))
    contacts = []
    for idx, obj in enumerate(ndi.find_objects(touch_lab), start=1):
        pts = np.argwhere(touch_lab[obj] == idx) + [o.start for o in obj] + [b.start for b in box]
        contacts.append(
            {
                "n_voxels": int(len(pts)),
                "centre_mm": _r(canon.to_physical(pts.mean(axis=0))[0], 1),
            }
        )
    contacts.sort(key=lambda c: -c["n_voxels"])

    # back to data[k, j, i] order
    mask = np.zeros(data.shape, bool)
    canon.view(mask)[...] = mandible_sar
    kji = np.argwhere(mask)
    pts = volume.index_to_physical(kji[:, ::-1].astype(np.float64))
    report = {
        "method": (
            "6-connected components of the CT at increasing thresholds until a mandible-like "
            "component separates (>= min volume, >= min width, U-shaped, below the largest "
            "component's centroid, front near the face); watershed of -HU from that component "
            "and the largest one inside the bone-level mask assigns the joining voxels"
        ),
        "separation_threshold_hu": thr,
        "thresholds_tried": tried,
        "n_voxels_at_separation": n_seed,
        "volume_at_separation_cm3": _r(n_seed * vox_mm3 / 1000.0, 2),
        "n_voxels_removed": int(len(kji)),
        "volume_removed_cm3": _r(len(kji) * vox_mm3 / 1000.0, 2),
        "width_mm": _r(geo["width_mm"], 1),
        "bounds_mm": _r([pts.min(axis=0), pts.max(axis=0)], 1),
        "contacts_at_bone_level": contacts[:10],
        "n_contacts_at_bone_level": int(n_touch),
        "c_spine": "kept (joined to the occipital condyles at the bone level)",
    }
    return mask, report


# ---------------------------------------------------------------- landmarks
def _first_hit(mask: np.ndarray, axis: int, from_high: bool) -> tuple[np.ndarray, np.ndarray]:
    """Index of the first True along ``axis`` (from its high or low end) and a hit flag."""
    m = np.flip(mask, axis=axis) if from_high else mask
    first = np.argmax(m, axis=axis)
    hit = m.any(axis=axis)
    if from_high:
        first = mask.shape[axis] - 1 - first
    return first, hit


def _shallowest_beyond(depth: np.ndarray, n: int, axis: int, ahead: bool) -> np.ndarray:
    """Smallest ``depth`` over the ``n`` pixels after (``ahead``) or before each pixel along
    ``axis`` (the pixel itself excluded; beyond the map counts as no bone, i.e. very deep)."""
    moved = np.moveaxis(depth, axis, 0)
    out = np.full(moved.shape, _NO_BONE)
    for step in range(1, n + 1):
        if ahead:
            out[:-step] = np.minimum(out[:-step], moved[step:])
        else:
            out[step:] = np.minimum(out[step:], moved[:-step])
    return np.moveaxis(out, 0, axis)


def _pocket(depth: np.ndarray, reach: dict[int, int]) -> np.ndarray:
    """How much deeper each pixel is than its surroundings on every side.

    ``depth`` minus the largest, over the axes in ``reach`` and both directions,
    of the shallowest depth within ``reach[axis]`` pixels: positive only where
    shallower bone lies within reach on every side (a pocket or pit).
    """
    bound = np.full(depth.shape, -np.inf)
    for axis, n in reach.items():
        for ahead in (True, False):
            bound = np.maximum(bound, _shallowest_beyond(depth, n, axis, ahead))
    return depth - bound


def find_landmarks(volume: Volume, bone_kji: np.ndarray, params: CutParams) -> dict[str, Any]:
    """Orbits, porions, midline and the Frankfort plane from a bone mask (mandible removed)."""
    canon = _Canon(volume)
    sp_s, sp_a, sp_r = canon.spacing
    bone = canon.view(bone_kji)
    ns, na, nr = bone.shape
    dirs = anatomical_directions(volume.frame)

    # midline: median R of the bone voxels
    counts_r = bone.sum(axis=(0, 1)).astype(np.float64)
    cdf = np.cumsum(counts_r) / counts_r.sum()
    r_mid = float(np.searchsorted(cdf, 0.5))

    # ---- orbits: front depth map (S, R)
    first_a, hit = _first_hit(bone, axis=1, from_high=True)
    depth = np.where(hit, (na - 1 - first_a) * sp_a, _NO_BONE)
    pocket = _pocket(depth, {0: int(round(params.orbit_pocket_reach_mm / sp_s))})
    deep = (pocket >= params.orbit_pocket_depth_mm) & hit
    lab2, n2 = ndi.label(deep)
    orbits: dict[str, dict[str, Any]] = {}
    best: dict[str, tuple[float, int]] = {}
    lo_lat, hi_lat = params.orbit_lateral_range_mm
    for idx in range(1, n2 + 1):
        ss, rr = np.nonzero(lab2 == idx)
        area = len(ss) * sp_s * sp_r
        if area < params.orbit_min_area_mm2:
            continue
        lateral = (rr.mean() - r_mid) * sp_r
        if not lo_lat <= abs(lateral) <= hi_lat:
            continue
        side = "right" if lateral > 0 else "left"
        if side not in best or area > best[side][0]:
            best[side] = (area, idx)
    if set(best) != {"right", "left"}:
        raise RuntimeError(
            f"could not find both orbits in the front depth map (found {sorted(best)})"
        )
    for side, (area, idx) in best.items():
        ss, rr = np.nonzero(lab2 == idx)
        rc = rr.mean()
        near = np.abs(rr - rc) * sp_r <= 10.0
        s_top = int(ss[near].max())
        r_top = int(np.round(np.median(rr[near & (ss == s_top)])))
        s_bot = int(ss.min())
        r_bot = int(np.round(np.median(rr[ss == s_bot])))
        # the rim points on the bone surface: one voxel outside the opening
        rim_top = canon.to_physical([s_top + 1, first_a[s_top + 1, r_top], r_top])[0]
        orbitale = canon.to_physical([s_bot - 1, first_a[s_bot - 1, r_bot], r_bot])[0]
        # centre of the opening (S, R) at the depth of the front of its upper rim
        centre = canon.to_physical([ss.mean(), first_a[s_top + 1, r_top], rc])[0]
        orbits[side] = {
            "opening_area_mm2": _r(area, 0),
            "width_mm": _r((rr.max() - rr.min() + 1) * sp_r, 1),
            "height_mm": _r((ss.max() - ss.min() + 1) * sp_s, 1),
            "centre_mm": centre,
            "upper_rim_mm": rim_top,
            "orbitale_mm": orbitale,
        }

    # ---- porions: lateral depth maps (S, A) from each side
    orbit_front_a = max(
        canon.from_physical(orbits[s]["upper_rim_mm"])[0, 1] for s in ("right", "left")
    )
    orbitale_s = np.mean([canon.from_physical(orbits[s]["orbitale_mm"])[0, 0] for s in orbits])
    porions: dict[str, Any] = {}
    for side, from_high in (("right", True), ("left", False)):
        first_r, hit_r = _first_hit(bone, axis=2, from_high=from_high)
        lat = np.where(hit_r, ((nr - 1 - first_r) if from_high else first_r) * sp_r, _NO_BONE)
        reach_mm = params.porion_pit_reach_mm
        pit = _pocket(lat, {0: int(round(reach_mm / sp_s)), 1: int(round(reach_mm / sp_a))})
        ok = (pit >= params.porion_pit_depth_mm) & hit_r
        s_idx = np.arange(ns)[:, None] * np.ones((1, na))
        a_idx = np.ones((ns, 1)) * np.arange(na)[None, :]
        window = (
            (np.abs(s_idx - orbitale_s) * sp_s <= 30.0)
            & ((orbit_front_a - a_idx) * sp_a >= 50.0)
            & ((orbit_front_a - a_idx) * sp_a <= 120.0)
        )
        lab, n_pits = ndi.label(ok & window)
        if n_pits == 0:
            raise RuntimeError(f"no external acoustic meatus found on the {side}")
        sizes = np.bincount(lab.ravel())
        sizes[0] = 0
        k = int(np.argmax(sizes))
        ss, aa = np.nonzero(lab == k)
        s_top = int(ss.max())
        a_top = int(np.round(np.median(aa[ss == s_top])))
        s_rim = min(s_top + 1, ns - 1)
        point = canon.to_physical([s_rim, a_top, first_r[s_rim, a_top]])[0]
        porions[side] = {
            "porion_mm": point,
            "pit_area_mm2": _r(len(ss) * sp_s * sp_a, 0),
            "pit_depth_mm": _r(float(pit[ss, aa].max()), 1),
        }

    pts = np.array(
        [orbits[s]["orbitale_mm"] for s in ("right", "left")]
        + [porions[s]["porion_mm"] for s in ("right", "left")]
    )
    centre = pts.mean(axis=0)
    normal = np.linalg.svd(pts - centre)[2][-1]
    if normal @ dirs["superior"] < 0:
        normal = -normal
    tilt = float(np.degrees(np.arccos(np.clip(normal @ dirs["superior"], -1, 1))))
    pitch = float(np.degrees(np.arctan2(normal @ dirs["anterior"], normal @ dirs["superior"])))
    roll = float(np.degrees(np.arctan2(normal @ dirs["right"], normal @ dirs["superior"])))
    return {
        "midline_mm": float(canon.to_physical([0, 0, r_mid])[0] @ dirs["right"]),
        "_r_mid": r_mid,
        "orbits": orbits,
        "porions": porions,
        "frankfort": {
            "point_mm": centre,
            "normal": normal,
            "tilt_from_axial_deg": tilt,
            "pitch_deg": pitch,  # + = normal leans anterior: orbitale below porion (chin down)
            "roll_deg": roll,  # + = normal leans to the right: the right side lower
            "residual_mm": float(np.abs((pts - centre) @ normal).max()),
        },
        "_front_first_a": first_a,
        "_front_hit": hit,
    }


# ---------------------------------------------------------------- frontal defect
def plan_frontal_hole(
    volume: Volume, landmarks: dict[str, Any], plane_normal: np.ndarray, params: CutParams
) -> dict[str, Any]:
    """Centre (on the outer frontal surface), outward axis and extent of the defect cylinder."""
    if params.hole_side not in ("right", "left"):
        raise ValueError(f"hole_side must be 'right' or 'left', got {params.hole_side!r}")
    canon = _Canon(volume)
    sp = canon.spacing
    first_a, hit = landmarks["_front_first_a"], landmarks["_front_hit"]
    orbit = landmarks["orbits"][params.hole_side]
    dirs = anatomical_directions(volume.frame)
    # straight above the orbit's centre column, hole_centre_above_rim_mm above its upper rim
    above = params.hole_centre_above_rim_mm
    if above is None:
        above = params.vault_cut_above_rim_mm / 2.0
    target = orbit["upper_rim_mm"] + above * plane_normal
    target = target + ((orbit["centre_mm"] - target) @ dirs["right"]) * dirs["right"]
    s_c, _, r_c = canon.from_physical(target)[0]
    s_i, r_i = int(round(s_c)), int(round(r_c))
    if not hit[s_i, r_i]:
        raise RuntimeError("no frontal bone in front of the planned defect centre")
    centre = canon.to_physical([s_i, first_a[s_i, r_i], r_i])[0]
    # outward axis: normal of the plane fitted to the front surface within the radius
    ss, rr = np.mgrid[0 : first_a.shape[0], 0 : first_a.shape[1]]
    near = hit & (np.hypot((ss - s_i) * sp[0], (rr - r_i) * sp[2]) <= params.hole_radius_mm)
    surf = canon.to_physical(np.c_[ss[near], first_a[near], rr[near]])
    mean = surf.mean(axis=0)
    axis = np.linalg.svd(surf - mean)[2][-1]
    if axis @ dirs["anterior"] < 0:
        axis = -axis
    return {
        "side": params.hole_side,
        "centre_above_upper_rim_mm": float(above),
        "centre_mm": centre,
        "axis": axis,
        "radius_mm": params.hole_radius_mm,
        "depth_in_mm": params.hole_depth_in_mm,
        "depth_out_mm": params.hole_depth_out_mm,
        "axis_from_anterior_deg": float(
            np.degrees(np.arccos(np.clip(axis @ dirs["anterior"], -1, 1)))
        ),
    }


def in_hole(points: np.ndarray, hole: dict[str, Any], shrink_mm: float = 0.0) -> np.ndarray:
    """Points inside the defect cylinder (optionally shrunk by ``shrink_mm`` on every side)."""
    d = np.asarray(points, np.float64) - np.asarray(hole["centre_mm"])
    axis = _unit(hole["axis"])
    t = d @ axis
    radial = np.linalg.norm(d - t[:, None] * axis, axis=1)
    return (
        (radial <= hole["radius_mm"] - shrink_mm)
        & (t >= -hole["depth_in_mm"] + shrink_mm)
        & (t <= hole["depth_out_mm"] - shrink_mm)
    )


def hole_voxels(volume: Volume, hole: dict[str, Any]) -> np.ndarray:
    """``data``-shaped mask of the voxels whose centres lie in the defect cylinder."""
    ext = hole["radius_mm"] + max(hole["depth_in_mm"], hole["depth_out_mm"])
    corners = np.asarray(hole["centre_mm"]) + ext * np.array(
        [[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], np.float64
    )
    ijk = volume.physical_to_index(corners)
    lo = np.maximum(np.floor(ijk.min(axis=0)).astype(int), 0)
    hi = np.minimum(np.ceil(ijk.max(axis=0)).astype(int) + 1, volume.shape_ijk)
    mask = np.zeros(volume.data.shape, bool)
    if np.any(hi <= lo):
        return mask
    grid = np.stack(
        np.meshgrid(*(np.arange(a, b) for a, b in zip(lo, hi, strict=False)), indexing="ij"),
        axis=-1,
    )  # (ni, nj, nk, 3) in (i, j, k)
    inside = in_hole(volume.index_to_physical(grid.reshape(-1, 3)), hole).reshape(grid.shape[:3])
    mask[lo[2] : hi[2], lo[1] : hi[1], lo[0] : hi[0]] = inside.transpose(2, 1, 0)
    return mask


# ---------------------------------------------------------------- mesh operations
def clip_by_plane(mesh: Mesh, point: np.ndarray, normal: np.ndarray) -> Mesh:
    """Keep the part of ``mesh`` on the negative side of the plane, splitting crossing triangles.

    The result ends exactly on the plane with an open border (no cap); new
    vertices on a cut edge are shared by the two triangles of that edge.
    """
    normal = _unit(normal)
    v = mesh.vertices
    f = np.asarray(mesh.faces)
    point = np.asarray(point, np.float64)
    s = (v - point) @ normal
    while np.any(np.abs(s) < 1e-7):  # no vertex on the plane: lower it by a nanometre or so
        point = point - 1e-6 * normal
        s = (v - point) @ normal
    inside = s < 0
    n_in = inside[f].sum(axis=1)
    keep = f[n_in == 3]
    cross = f[(n_in == 1) | (n_in == 2)]
    if len(cross) == 0:
        used = np.unique(keep)
        remap = np.full(len(v), -1)
        remap[used] = np.arange(len(used))
        return Mesh(v[used], remap[keep])
    cin = inside[cross]
    odd = np.where(cin.sum(axis=1) == 1, np.argmax(cin, axis=1), np.argmin(cin, axis=1))
    rot = np.stack([cross[np.arange(len(cross)), (odd + k) % 3] for k in range(3)], axis=1)
    a, b, c = rot[:, 0], rot[:, 1], rot[:, 2]
    # one new vertex per crossing edge (a-b and a-c), shared between neighbours
    edges = np.concatenate([np.c_[a, b], np.c_[a, c]])
    lo, hi = edges.min(axis=1), edges.max(axis=1)
    keys, inverse = np.unique(lo * np.int64(len(v)) + hi, return_inverse=True)
    eu, ew = keys // len(v), keys % len(v)
    t = s[eu] / (s[eu] - s[ew])
    new_v = v[eu] + t[:, None] * (v[ew] - v[eu])
    new_id = len(v) + inverse.ravel()
    p_ab, p_ac = new_id[: len(a)], new_id[len(a) :]
    one_in = inside[a]
    tri = [np.c_[a, p_ab, p_ac][one_in]]
    two = ~one_in
    tri += [np.c_[p_ab, b, c][two], np.c_[p_ab, c, p_ac][two]]
    faces = np.concatenate([keep] + tri)
    verts = np.concatenate([v, new_v])
    used = np.unique(faces)
    remap = np.full(len(verts), -1)
    remap[used] = np.arange(len(used))
    return Mesh(verts[used], remap[faces])


def component_areas(mesh: Mesh) -> tuple[np.ndarray, np.ndarray]:
    """Face component labels and the area (mm^2) of each component."""
    labels = face_component_labels(np.asarray(mesh.faces), mesh.n_vertices)
    return labels, np.bincount(labels, weights=mesh.face_areas)


def keep_faces(mesh: Mesh, keep: np.ndarray) -> Mesh:
    faces = np.asarray(mesh.faces)[keep]
    used = np.unique(faces)
    remap = np.full(mesh.n_vertices, -1)
    remap[used] = np.arange(len(used))
    return Mesh(mesh.vertices[used], remap[faces])


# ---------------------------------------------------------------- checks recorded with the case
def region_checks(full: Mesh, cut: Mesh, landmarks: dict[str, Any], frame: str) -> dict[str, Any]:
    """Vertex counts / areas of the full and cut bone in two anterior boxes (mm, frame axes).

    ``chin_box``: within 30 mm of the midline, at most 40 mm behind the front of
    the upper orbital rims and more than 45 mm below orbitale -- the mandible's
    symphysis and lower teeth (the maxilla with the upper teeth ends higher).
    ``maxilla_box``: same columns, 10-45 mm below orbitale -- the maxilla and
    the upper teeth, which the mandible's removal must leave as they are.
    """
    dirs = anatomical_directions(frame)
    orbits = landmarks["orbits"]
    z_orbitale = np.mean([orbits[s]["orbitale_mm"] @ dirs["superior"] for s in orbits])
    y_front = max(orbits[s]["upper_rim_mm"] @ dirs["anterior"] for s in orbits)
    x_mid = landmarks["midline_mm"]

    def boxes(mesh: Mesh) -> dict[str, np.ndarray]:
        v = mesh.vertices
        col = (np.abs(v @ dirs["right"] - x_mid) <= 30.0) & (v @ dirs["anterior"] >= y_front - 40.0)
        h = v @ dirs["superior"] - z_orbitale
        return {"chin_box": col & (h < -45.0), "maxilla_box": col & (h >= -45.0) & (h <= -10.0)}

    def area(mesh: Mesh, vmask: np.ndarray) -> float:
        return float(mesh.face_areas[vmask[np.asarray(mesh.faces)].all(axis=1)].sum())

    out: dict[str, Any] = {
        "definition": (
            "columns within 30 mm of the midline and at most 40 mm behind the front of the "
            "upper orbital rims; chin_box: more than 45 mm below orbitale; "
            "maxilla_box: 10-45 mm below orbitale"
        ),
    }
    fb, cb = boxes(full), boxes(cut)
    for name in ("chin_box", "maxilla_box"):
        out[name] = {
            "full_bone_vertices": int(fb[name].sum()),
            "cut_skull_vertices": int(cb[name].sum()),
            "full_bone_area_mm2": _r(area(full, fb[name]), 1),
            "cut_skull_area_mm2": _r(area(cut, cb[name]), 1),
        }
    h_cut = cut.vertices @ dirs["superior"] - z_orbitale
    col = (np.abs(cut.vertices @ dirs["right"] - x_mid) <= 30.0) & (
        cut.vertices @ dirs["anterior"] >= y_front - 40.0
    )
    out["cut_skull_lowest_anterior_below_orbitale_mm"] = _r(-h_cut[col].min(), 1)
    return out


def _jsonable(obj: Any) -> Any:
    if isinstance(obj, dict):
        return {k: _jsonable(v) for k, v in obj.items() if not str(k).startswith("_")}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _r(obj, 6)
    if isinstance(obj, (np.bool_, bool)):
        return bool(obj)
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return _r(obj, 6)
    return obj


# ---------------------------------------------------------------- the case
def build_case(
    ct_path: str | os.PathLike[str], params: CutParams = CutParams()
) -> tuple[dict[str, Mesh], dict[str, Any]]:
    """Build the meshes (name -> Mesh) and the record (JSON-ready dict) without writing."""
    timings: dict[str, float] = {}
    clock = perf_counter()
    start = clock

    def lap(name: str) -> None:
        nonlocal clock
        now = perf_counter()
        timings[name] = round(now - clock, 3)
        clock = now

    ct_path = Path(ct_path)
    sha = sha256_file(ct_path)
    lap("sha256")
    volume = read_volume(ct_path)
    lo_hu, hi_hu = volume.value_range()
    if not (-1100 <= lo_hu <= -900 and hi_hu >= 1000):
        raise ValueError(
            f"{ct_path}: values {lo_hu:g}..{hi_hu:g} do not look like Hounsfield units "
            "(air near -1000 HU, bone above 1000 HU expected)"
        )
    dirs = anatomical_directions(volume.frame)
    lap("read")

    full = mesh_from_ct(volume, "bone", iso=params.bone_iso_hu)
    lap("full_bone")
    skin = mesh_from_ct(volume, "skin", iso=params.skin_iso_hu)
    lap("skin")

    mandible, mandible_report = find_mandible(volume, params)
    lap("mandible")
    data = np.asarray(volume.data)
    bone = (data >= params.bone_iso_hu) & ~mandible
    labels, _ = ndi.label(bone, _STRUCT6)
    sizes = np.bincount(labels.ravel())
    sizes[0] = 0
    bone = labels == int(np.argmax(sizes))
    del labels
    landmarks = find_landmarks(volume, bone, params)
    del bone
    # the geometry used is exactly the geometry recorded (rounded to 1e-6 first)
    normal = np.round(landmarks["frankfort"]["normal"], 6)
    rim = np.mean([landmarks["orbits"][s]["upper_rim_mm"] for s in ("right", "left")], axis=0)
    plane_point = np.round(rim + params.vault_cut_above_rim_mm * _unit(normal), 6)
    hole = plan_frontal_hole(volume, landmarks, _unit(normal), params)
    hole["centre_mm"] = np.round(hole["centre_mm"], 6)
    hole["axis"] = np.round(hole["axis"], 6)
    hole_mask = hole_voxels(volume, hole)
    lap("landmarks")

    edited = np.array(data, copy=True)
    edited[mandible] = params.removed_hu
    no_mandible = mesh_from_ct(
        dataclasses.replace(volume, data=edited), "bone", iso=params.bone_iso_hu
    )
    n_hole_bone = int(np.count_nonzero(hole_mask & (edited >= params.bone_iso_hu)))
    edited[hole_mask] = params.removed_hu
    holed = mesh_from_ct(
        dataclasses.replace(volume, data=edited),
        "bone",
        iso=params.bone_iso_hu,
        largest_component=False,
    )
    del edited
    lap("edited_bone")

    hole_comp, hole_areas = component_areas(holed.mesh)
    holed_largest = keep_faces(holed.mesh, hole_comp == int(np.argmax(hole_areas)))
    clipped = clip_by_plane(holed.mesh, plane_point, normal)
    comp, areas = component_areas(clipped)
    biggest = int(np.argmax(areas))
    cut = keep_faces(clipped, comp == biggest)
    lap("vault_cut")

    # checks
    spacing = float(np.max(volume.spacing_mm))
    height = (cut.vertices - plane_point) @ normal
    full_height = (full.mesh.vertices - plane_point) @ normal
    in_defect_full = in_hole(full.mesh.vertices, hole)
    loops = boundary_loops(cut)
    border = np.unique(np.concatenate(loops)) if loops else np.zeros(0, np.int64)
    near_hole_border = in_hole(
        cut.vertices[border], {**hole, "radius_mm": hole["radius_mm"] + spacing}
    )
    rim_height = (full.mesh.vertices[in_defect_full] - rim) @ normal
    checks = {
        "max_height_above_cut_plane_mm": float(height.max()),
        "n_vertices_in_hole_shrunk_by_one_voxel": int(
            in_hole(cut.vertices, hole, shrink_mm=spacing).sum()
        ),
        "n_boundary_loops": len(loops),
        "boundary_loop_sizes": sorted((len(lp) for lp in loops), reverse=True)[:10],
        "hole_isolated_from_cut_rim": bool(not near_hole_border.any()),
        "hole_bone_margin_below_cut_mm": _r(-full_height[in_defect_full].max(), 1),
        "hole_lowest_above_upper_rim_mm": _r(rim_height.min(), 1),
        "mandible_regions": region_checks(full.mesh, cut, landmarks, volume.frame),
    }
    lap("checks")
    timings["total"] = round(perf_counter() - start, 3)

    vox_mm3 = float(np.prod(volume.spacing_mm))
    kept = cut.area
    record: dict[str, Any] = {
        "case": "vhf_cut_skull",
        "description": (
            "Incomplete real skull for skull-to-face validation: the bone surface (300 HU) of the "
            "Visible Human Female head CT without mandible, with a frontal defect above one orbit "
            "and the vault cut off by a plane parallel to the Frankfort plane (open rim); the "
            "skin (-400 HU) of the same CT is the ground truth."
        ),
        "generator": "benchmarks/cases/cut_skull.py",
        "generator_version": GENERATOR_VERSION,
        "credit": CREDIT,
        "credit_note": FROZEN_COPY_NOTE,
        "source": SOURCE,
        "ct": {
            "file": ct_path.name,
            "path": str(ct_path),
            "sha256": sha,
            "bytes": ct_path.stat().st_size,
            "shape_ijk": list(volume.shape_ijk),
            "spacing_mm": _r(volume.spacing_mm, 4),
            "affine": _r(volume.affine, 4),
            "frame": volume.frame,
            "value_range": [float(lo_hu), float(hi_hu)],
        },
        "frame": volume.frame,
        "units": "mm",
        "frame_note": (
            f"vertices in mm in the volume's physical frame ({volume.frame}), the frame "
            "workbench.services.ct.ct_mesh.mesh_from_ct returns; "
            f"anterior = {dirs['anterior'].tolist()}, superior = {dirs['superior'].tolist()}, "
            f"patient's right = {dirs['right'].tolist()}"
        ),
        "params": dataclasses.asdict(params),
        "landmarks": landmarks,
        "removed": {
            "mandible": mandible_report,
            "frontal_hole": {
                **hole,
                "n_voxels_set_to_removed_hu": int(hole_mask.sum()),
                "n_bone_voxels_removed": n_hole_bone,
                "bone_volume_removed_cm3": _r(n_hole_bone * vox_mm3 / 1000.0, 2),
                "method": (
                    "voxels whose centres lie in the cylinder (radius about the outward axis, "
                    "from depth_in inside to depth_out outside the centre on the outer frontal "
                    "surface) set to removed_hu before surface extraction; the defect has bone "
                    "margins"
                ),
            },
            "vault_cut": {
                "plane_point_mm": plane_point,
                "plane_normal": normal,
                "above_upper_orbital_rims_mm": params.vault_cut_above_rim_mm,
                "upper_orbital_rims_mean_mm": rim,
                "method": (
                    "the surface is clipped exactly along the plane (crossing triangles split), "
                    "kept below it (signed distance < 0 along the normal); open rim, no cap"
                ),
            },
            "components_dropped_after_cut": {
                "n": int(len(areas) - 1),
                "area_mm2": _r(areas.sum() - areas[biggest], 1),
                "largest_dropped_area_mm2": _r(np.sort(areas)[-2] if len(areas) > 1 else 0.0, 1),
                "note": "debris, the hyoid, calcifications and wrap lines (not skull)",
            },
        },
        "counts": {
            "full_bone": mesh_summary(full.mesh),
            "without_mandible": mesh_summary(no_mandible.mesh),
            "without_mandible_and_hole": mesh_summary(holed_largest),
            "cut_skull": mesh_summary(cut),
            "skin": mesh_summary(skin.mesh),
            "cut_skull_area_fraction_of_full_bone": _r(kept / full.mesh.area, 4),
        },
        "checks": checks,
        "outputs": {
            CUT_SKULL: {"iso_hu": params.bone_iso_hu, "what": "incomplete bone surface"},
            SKIN: {
                "iso_hu": params.skin_iso_hu,
                "what": "true skin (ground truth), largest component",
            },
            FULL_BONE: {"iso_hu": params.bone_iso_hu, "what": "complete bone, largest component"},
        },
        "timings_s": timings,
    }
    meshes = {CUT_SKULL: cut, SKIN: skin.mesh, FULL_BONE: full.mesh}
    return meshes, _jsonable(record)


def _cached_record(out_dir: Path, sha: str, params: CutParams) -> dict[str, Any] | None:
    """The recorded case in ``out_dir`` if it is complete and made from this CT and params."""
    try:
        record = json.loads((out_dir / RECORD).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if (
        record.get("ct", {}).get("sha256") != sha
        or record.get("generator_version") != GENERATOR_VERSION
        or record.get("params") != _jsonable(dataclasses.asdict(params))
    ):
        return None
    for name in OUTPUTS:
        path = out_dir / name
        expected = record.get("outputs", {}).get(name, {}).get("bytes")
        if not path.is_file() or path.stat().st_size != expected:
            return None
    return record


def make_cut_skull(
    ct_path: str | os.PathLike[str],
    out_dir: str | os.PathLike[str],
    *,
    force: bool = False,
    params: CutParams = CutParams(),
) -> dict[str, Any]:
    """Write the case into ``out_dir`` (unless it is already there) and return its record.

    Skips the work when ``out_dir`` holds ``cut_skull.json`` with the same CT
    SHA-256, generator version and parameters and the three meshes with the
    recorded sizes (``force`` rebuilds).  The returned dict is the JSON record
    plus ``"cached"`` (True when nothing was rebuilt) and ``"out_dir"``.

    Writing is atomic: a new ``out_dir`` is built as a temporary sibling folder
    and renamed into place; an existing one has its record removed first, then
    each file is renamed in from a temporary folder inside it, the record last,
    so an interrupted run never leaves a record that matches stale meshes.
    """
    ct_path = Path(ct_path)
    out_dir = Path(out_dir)
    sha = sha256_file(ct_path)
    if not force:
        record = _cached_record(out_dir, sha, params)
        if record is not None:
            return {**record, "cached": True, "out_dir": str(out_dir)}
    meshes, record = build_case(ct_path, params)
    if record["ct"]["sha256"] != sha:
        raise RuntimeError(f"{ct_path} changed while the case was being built")

    out_dir.parent.mkdir(parents=True, exist_ok=True)
    fresh = not out_dir.exists()
    tmp = (out_dir.parent if fresh else out_dir) / f".{out_dir.name}.tmp-{secrets.token_hex(6)}"
    tmp.mkdir()
    try:
        t0 = perf_counter()
        for name, mesh in meshes.items():
            path = write_mesh(tmp / name, mesh)
            record["outputs"][name].update(
                bytes=path.stat().st_size, sha256=sha256_file(path), **mesh_summary(mesh)
            )
        record["timings_s"]["write"] = round(perf_counter() - t0, 3)
        (tmp / RECORD).write_text(json.dumps(record, indent=1) + "\n", encoding="utf-8")
        if fresh:
            try:
                os.rename(tmp, out_dir)
            except OSError:  # created meanwhile by someone else: fall through to file moves
                fresh = False
        if not fresh:
            (out_dir / RECORD).unlink(missing_ok=True)
            for name in (*OUTPUTS, RECORD):
                os.replace(tmp / name, out_dir / name)
    finally:
        if tmp.exists():
            shutil.rmtree(tmp, ignore_errors=True)
    return {**record, "cached": False, "out_dir": str(out_dir)}


# ---------------------------------------------------------------- command line
def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--ct", required=True, help="head CT (NIfTI/NRRD/DICOM) in HU")
    parser.add_argument("--out", required=True, help="cache folder for the outputs")
    parser.add_argument("--force", action="store_true", help="rebuild even if up to date")
    parser.add_argument(
        "--cut-above-rim",
        type=float,
        default=CutParams.vault_cut_above_rim_mm,
        help="vault cut height above the upper orbital rims (mm)",
    )
    parser.add_argument(
        "--hole-radius",
        type=float,
        default=CutParams.hole_radius_mm,
        help="frontal defect radius (mm)",
    )
    parser.add_argument("--hole-side", choices=("right", "left"), default=CutParams.hole_side)
    args = parser.parse_args(argv)
    params = CutParams(
        vault_cut_above_rim_mm=args.cut_above_rim,
        hole_radius_mm=args.hole_radius,
        hole_side=args.hole_side,
    )
    t0 = perf_counter()
    record = make_cut_skull(args.ct, args.out, force=args.force, params=params)
    wall = perf_counter() - t0
    state = "up to date (nothing rebuilt)" if record["cached"] else "built"
    print(f"{record['out_dir']}: {state} in {wall:.1f} s; CT sha256 {record['ct']['sha256'][:16]}…")
    for name in OUTPUTS:
        o = record["outputs"][name]
        print(
            f"  {name:14s} {o['n_vertices']:>8d} vertices {o['n_faces']:>8d} faces "
            f"{o['area_mm2'] / 100:>9.1f} cm²  {o['bytes'] / 2**20:6.1f} MiB"
        )
    m = record["removed"]["mandible"]
    h = record["removed"]["frontal_hole"]
    v = record["removed"]["vault_cut"]
    f = record["landmarks"]["frankfort"]
    c = record["checks"]
    mr = c["mandible_regions"]
    print(
        f"  mandible: separates at {m['separation_threshold_hu']:g} HU, "
        f"{m['volume_removed_cm3']} cm³ removed, {m['n_contacts_at_bone_level']} contact(s) at "
        f"{record['params']['bone_iso_hu']:g} HU: "
        + "; ".join(f"{k['n_voxels']} vox at {k['centre_mm']}" for k in m["contacts_at_bone_level"])
    )
    print(
        f"  Frankfort: tilt {f['tilt_from_axial_deg']:.2f}° from axial (pitch "
        f"{f['pitch_deg']:.2f}°, roll {f['roll_deg']:.2f}°); cut plane point "
        f"{v['plane_point_mm']} normal {v['plane_normal']}"
    )
    print(
        f"  hole ({h['side']}): centre {h['centre_mm']} axis {h['axis']} radius "
        f"{h['radius_mm']} mm; isolated from the cut rim: {c['hole_isolated_from_cut_rim']}"
    )
    print(
        f"  area kept {record['counts']['cut_skull_area_fraction_of_full_bone']:.1%} of the full "
        f"bone; chin box vertices full/cut {mr['chin_box']['full_bone_vertices']}/"
        f"{mr['chin_box']['cut_skull_vertices']}; maxilla box area full/cut "
        f"{mr['maxilla_box']['full_bone_area_mm2']}/{mr['maxilla_box']['cut_skull_area_mm2']} mm²"
    )
    if not record["cached"]:
        print("  timings (s): " + ", ".join(f"{k} {t}" for k, t in record["timings_s"].items()))
    print(f"  {CREDIT} (Visible Human Project®). {FROZEN_COPY_NOTE}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
