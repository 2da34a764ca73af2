"""The base CTs of the corpus and their voxel label volumes.

Units mm; every position is in the base's **input frame** (the CT's physical
frame: LPS for the NRRD ``headsq``, RAS for the NIfTI VHP volumes), the frame
:func:`workbench.services.ct.ct_mesh.mesh_from_ct` gives the bone surface in.
Voxel values are in each volume's own units: HU for the VHP CTs (the reader
says "unknown", but they are HU), raw 0..3926 CT numbers for ``headsq``
(roughly HU + 1024; soft tissue ~1050, the VTK bone level 1150).

Labels (``uint8``, ``data``-shaped, ``data[k, j, i]``), given to every voxel
at or above the base's :attr:`Base.label_floor` (the lowest iso level any
variant uses):

* 1 **cranium** — with the maxilla and the upper teeth;
* 2 **mandible** — with the lower teeth;
* 3 **extra** — below the skull base: C-spine, hyoid;
* 4 **other** — anything else (CT table, calcifications, debris): never edited.

Method (:func:`segment`), using the *anchor* (the base's first clean hinted
registration, :mod:`benchmarks.corpus.truth`: the registered reference
cranium and mandible surfaces in the head frame):

1. Seeds.  Bone voxels within :data:`SEED_MM` of the registered mandible and
   farther than ``SEED_MM + SEED_GAP_MM`` from the registered cranium seed the
   mandible; the converse seeds the cranium.  Bone voxels farther than
   :data:`EXTRA_MM` from both and below the Frankfort plane seed "extra".
   For the VHP CTs the mandible found by
   :func:`benchmarks.cases.cut_skull.find_mandible` (thresholds + watershed,
   no registration) replaces the registration's mandible seed when the two
   agree (:data:`FIND_MANDIBLE_AGREEMENT`).
2. A watershed of the negated CT values inside the bone mask grows the seeds,
   so two touching bones split along their low-density joint spaces (the
   temporomandibular joints, the occipital condyles on the atlas).  "Extra"
   grown above the extra seed region (into a skull base the seeds left bare)
   goes to the nearer registered part.
3. Bone not reached (separate pieces): a piece whose median distance to the
   registered mandible (cranium) is under :data:`PIECE_MM` joins it; a piece
   mostly in the "extra" seed region is extra (the hyoid); anything else is
   "other".

The label volume is cached (``bases/<base>_labels_v<N>.npz``) together with a
check image of orthogonal maximum-intensity projections coloured by label.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from scipy import ndimage as ndi

from benchmarks.corpus.common import apply, data_root
from workbench.core.mesh import Mesh
from workbench.core.spatial import MeshIndex
from workbench.core.volume import Volume
from workbench.io.volumes import read_volume

SEGMENTATION_VERSION = 1
NONE, CRANIUM, MANDIBLE, EXTRA, OTHER = 0, 1, 2, 3, 4
LABEL_NAMES = {CRANIUM: "cranium", MANDIBLE: "mandible", EXTRA: "extra", OTHER: "other"}
#: seed distance to a registered part (mm; at least one voxel)
SEED_MM = 3.0
#: a seed must be this much farther from the other part (mm)
SEED_GAP_MM = 3.0
#: bone farther than this from the registered skull and below Frankfort is extra anatomy (mm)
EXTRA_MM = 12.0
#: ... and lies this far below the Frankfort plane, this close to the midline (mm)
EXTRA_BELOW_FH_MM = 20.0
EXTRA_HALF_WIDTH_MM = 40.0
#: a separate bone piece this close (median) to a registered part belongs to it (mm)
PIECE_MM = 5.0
#: find_mandible's mask is used when it holds this fraction of the registration's mandible
#: seed and at most FIND_MANDIBLE_LEAK of its cranium seed (on the VHP male, whose teeth are
#: in occlusion, it takes the maxilla and the upper teeth too)
FIND_MANDIBLE_AGREEMENT = 0.7
FIND_MANDIBLE_LEAK = 0.01


@dataclass(frozen=True)
class Base:
    """One base CT and how it is read (values in the volume's own units)."""

    name: str
    relpath: str
    sex: str  # the reference head of the truth registration
    raw: bool  # raw CT numbers (headsq) rather than HU
    truth_iso: float
    hint: tuple[tuple[float, float, float], ...]  # anterior, superior, left (input frame)
    hu_offset: float  # value = HU + hu_offset
    fill: float  # soft-tissue value written where bone is removed
    label_floor: float  # lowest level any variant uses
    vault_already_cut: bool
    credited: bool  # Visible Human data: the NLM credit goes into every output header
    # the largest applied jaw opening (degrees): base opening + applied <= 40 degrees, the
    # largest opening a real jaw makes (MAX_TOTAL_OPENING_DEG); measured base openings below
    max_opening_deg: float = 35.0

    @property
    def path(self) -> Path:
        return data_root() / self.relpath

    def value(self, hu: float) -> float:
        """A level or a material value given in HU, in this volume's units (clipped)."""
        lo, hi = VALUE_RANGES[self.name]
        return float(np.clip(hu + self.hu_offset, lo, hi))


#: the largest total opening (base + applied) a variant gets (degrees)
MAX_TOTAL_OPENING_DEG = 40.0
VALUE_RANGES = {
    "headsq": (0.0, 3926.0),
    "vhp_female": (-1024.0, 3063.0),
    "vhp_male": (-1024.0, 3617.0),
}

_VHP_HINT = ((0.0, 1.0, 0.0), (0.0, 0.0, 1.0), (-1.0, 0.0, 0.0))
BASES: dict[str, Base] = {
    "headsq": Base(
        name="headsq",
        relpath="vtk_headsq_quarter_ct/headsq/quarter.nhdr",
        sex="male",
        raw=True,
        truth_iso=1150.0,
        hint=((0.0, -1.0, 0.0), (0.0, 0.0, -1.0), (1.0, 0.0, 0.0)),
        hu_offset=1024.0,
        fill=1040.0,
        label_floor=1150.0,
        vault_already_cut=True,
        credited=False,
        max_opening_deg=20.0,  # its base opening is ~20 degrees (mouth open in the scan)
    ),
    "vhp_female": Base(
        name="vhp_female",
        relpath="vhp_female_head_ct/vhf_head_ct_1mm.nii.gz",
        sex="female",
        raw=False,
        truth_iso=300.0,
        hint=_VHP_HINT,
        hu_offset=0.0,
        fill=40.0,
        label_floor=250.0,
        vault_already_cut=False,
        credited=True,
        max_opening_deg=30.0,
    ),
    "vhp_male": Base(
        name="vhp_male",
        relpath="vhp_male_head_ct/vhm_head_ct_1mm.nii.gz",
        sex="male",
        raw=False,
        truth_iso=300.0,
        hint=_VHP_HINT,
        hu_offset=0.0,
        fill=40.0,
        label_floor=250.0,
        vault_already_cut=False,
        credited=True,
        max_opening_deg=35.0,
    ),
}


@functools.lru_cache(maxsize=3)
def load_volume(name: str) -> Volume:
    """The base CT (read once per process)."""
    base = BASES[name]
    if not base.path.is_file():
        raise FileNotFoundError(f"base CT {name!r} not found: {base.path}")
    return read_volume(base.path)


#: the bone levels the variants are extracted at (HU, or multi-Otsu)
ISO_LEVELS = ("250", "300", "400", "500", "700", "otsu")


def iso_level(base: Base, iso: str, volume: Volume) -> tuple[float, str]:
    """The level of a spec's ``iso`` in the base's units, and the rule."""
    if iso == "otsu":
        from skimage.filters import threshold_multiotsu

        _, t_high = threshold_multiotsu(classes=3, hist=volume.histogram())
        return float(t_high), "multi-Otsu (3 classes) of the edited volume"
    hu = float(iso)
    if base.raw:
        # raw CT numbers ~ HU + 1024; never below the VTK bone level (1150)
        return max(base.value(hu), 1150.0), f"{hu:g} HU as raw HU + 1024 (at least 1150)"
    return hu, f"{hu:g} HU"


def with_data(volume: Volume, data: np.ndarray) -> Volume:
    """``volume`` with other voxel values (same geometry, source and units)."""
    return dataclasses.replace(volume, data=data)


def index_matrix(volume: Volume) -> np.ndarray:
    """4 x 4 map from array indices ``(k, j, i)`` to input-frame mm."""
    m = np.eye(4)
    m[:3, :3] = (volume.direction * volume.spacing_mm[None, :])[:, ::-1]
    m[:3, 3] = volume.origin_mm
    return m


def voxel_points(volume: Volume, kji: np.ndarray) -> np.ndarray:
    """Input-frame mm of voxel indices ``(n, 3)`` in ``(k, j, i)`` order."""
    return volume.index_to_physical(np.asarray(kji, np.float64)[:, ::-1])


# ---------------------------------------------------------------- segmentation
@dataclass(frozen=True)
class Segmentation:
    labels: np.ndarray  # uint8, data-shaped
    report: dict[str, Any]


def _distances(points_h: np.ndarray, mesh_h: Mesh) -> np.ndarray:
    return MeshIndex(mesh_h).closest_points(points_h).distances


def segment(
    base: Base,
    volume: Volume,
    input_to_head: np.ndarray,
    cranium_h: Mesh,
    mandible_h: Mesh,
) -> Segmentation:
    """Label the bone voxels of ``volume`` (see the module docstring)."""
    from skimage.segmentation import watershed

    data = np.asarray(volume.data)
    bone = data >= base.label_floor
    box = tuple(
        slice(max(int(a.min()) - 2, 0), int(a.max()) + 3) for a in np.nonzero(bone)
    )  # bounding box of the bone, grown by 2
    sub = data[box]
    sub_bone = bone[box]
    kji = np.argwhere(sub_bone) + [b.start for b in box]
    pts_h = apply(input_to_head, voxel_points(volume, kji))
    d_cr = _distances(pts_h, cranium_h)
    d_md = _distances(pts_h, mandible_h)
    seed_mm = max(SEED_MM, float(np.max(volume.spacing_mm)))
    # extra anatomy: the C-spine and the hyoid lie near the midline, below the skull base
    neck = (pts_h[:, 1] < -EXTRA_BELOW_FH_MM) & (np.abs(pts_h[:, 0]) < EXTRA_HALF_WIDTH_MM)
    far = np.minimum(d_cr, d_md) > EXTRA_MM
    seeds = np.zeros(len(kji), np.int32)
    seeds[(d_cr <= seed_mm) & (d_md > seed_mm + SEED_GAP_MM)] = CRANIUM
    seeds[(d_md <= seed_mm) & (d_cr > seed_mm + SEED_GAP_MM)] = MANDIBLE
    seeds[far & neck] = EXTRA
    report: dict[str, Any] = {
        "version": SEGMENTATION_VERSION,
        "label_floor": base.label_floor,
        "n_bone_voxels": len(kji),
        "seed_mm": seed_mm,
        "seed_voxels": {LABEL_NAMES[k]: int(np.sum(seeds == k)) for k in (1, 2, 3)},
    }
    markers = np.zeros(sub.shape, np.int32)
    local = tuple((kji - [b.start for b in box]).T)
    markers[local] = seeds
    if not base.raw:
        fm = _find_mandible(base, volume, box)
        if fm is not None:
            in_fm = fm[local]
            seed_in_fm = float(np.mean(in_fm[seeds == MANDIBLE]))
            cranium_in_fm = float(np.mean(in_fm[seeds == CRANIUM]))
            report["find_mandible"] = {
                "fraction_of_registration_mandible_seed": round(seed_in_fm, 4),
                "fraction_of_registration_cranium_seed": round(cranium_in_fm, 4),
                "volume_cm3": round(float(fm.sum() * np.prod(volume.spacing_mm)) / 1000, 2),
            }
            if seed_in_fm >= FIND_MANDIBLE_AGREEMENT and cranium_in_fm <= FIND_MANDIBLE_LEAK:
                markers[(markers == MANDIBLE) & ~fm] = 0
                markers[fm & sub_bone] = MANDIBLE
                report["mandible_seed"] = "find_mandible (cut_skull.py)"
        if "mandible_seed" not in report:
            report["mandible_seed"] = "registration (find_mandible disagreed or failed)"
    else:
        report["mandible_seed"] = "registration"
    grown = watershed(-sub.astype(np.float32), markers, mask=sub_bone)
    lab = grown[local].astype(np.uint8)
    # the watershed can climb from the atlas into a skull base the seeds left bare: nothing
    # above the extra seed region is extra
    high = (lab == EXTRA) & (pts_h[:, 1] >= -EXTRA_BELOW_FH_MM)
    lab[high] = np.where(d_md[high] < d_cr[high], MANDIBLE, CRANIUM)
    report["extra_relabelled_above_seed_region"] = int(high.sum())
    # separate pieces the watershed did not reach
    pieces, n_pieces = ndi.label(sub_bone & (grown == 0), ndi.generate_binary_structure(3, 3))
    piece_of = pieces[local]
    assigned = {"mandible": 0, "cranium": 0, "extra": 0, "other": 0}
    for idx in range(1, n_pieces + 1):
        sel = piece_of == idx
        if not sel.any():
            continue
        if np.median(d_md[sel]) < PIECE_MM and np.median(d_md[sel]) <= np.median(d_cr[sel]):
            value = MANDIBLE
        elif np.median(d_cr[sel]) < PIECE_MM:
            value = CRANIUM
        elif np.mean(far[sel] & neck[sel]) > 0.5:
            value = EXTRA
        else:
            value = OTHER
        lab[sel] = value
        assigned[LABEL_NAMES[value]] += int(sel.sum())
    labels = np.zeros(data.shape, np.uint8)
    labels[tuple(kji.T)] = lab
    vox_cm3 = float(np.prod(volume.spacing_mm)) / 1000.0
    report["unreached_pieces"] = {"n": int(n_pieces), "voxels_assigned": assigned}
    report["volumes_cm3"] = {
        LABEL_NAMES[k]: round(float(np.sum(lab == k)) * vox_cm3, 2) for k in LABEL_NAMES
    }
    mand_pts = pts_h[lab == MANDIBLE]
    if len(mand_pts):
        report["mandible_extent_head_mm"] = np.ptp(mand_pts, axis=0).round(1).tolist()
    return Segmentation(labels, report)


def _find_mandible(base: Base, volume: Volume, box: tuple[slice, ...]) -> np.ndarray | None:
    """cut_skull.find_mandible's mask (cropped to ``box``), or None when it finds none."""
    from benchmarks.cases.cut_skull import CutParams, find_mandible

    try:
        mask, _ = find_mandible(volume, CutParams(bone_iso_hu=base.label_floor))
    except RuntimeError:
        return None
    return mask[box]


# ---------------------------------------------------------------- check image
def anatomical_view(volume: Volume, input_to_head: np.ndarray, array: np.ndarray) -> np.ndarray:
    """``array`` (data-shaped) permuted/flipped so its axes run along head x, y, z.

    Uses the index axis closest to each head axis (the CTs are scanned nearly
    aligned with the head; good enough for a picture).
    """
    dirs = apply_dir_rows(input_to_head, index_matrix(volume)[:3, :3].T)  # (3 kji, 3 head)
    out_axes, flips = [], []
    for h in range(3):
        a = int(np.argmax(np.abs(dirs[:, h])))
        out_axes.append(a)
        flips.append(dirs[a, h] < 0)
    view = np.transpose(array, out_axes)
    for ax, f in enumerate(flips):
        if f:
            view = np.flip(view, axis=ax)
    return view


def anatomical_spacing(volume: Volume, input_to_head: np.ndarray) -> np.ndarray:
    """Voxel size (mm) along the axes of :func:`anatomical_view`."""
    dirs = apply_dir_rows(input_to_head, index_matrix(volume)[:3, :3].T)
    spacing_kji = np.asarray(volume.spacing_mm, np.float64)[::-1]
    return np.array([spacing_kji[int(np.argmax(np.abs(dirs[:, h])))] for h in range(3)])


def apply_dir_rows(m: np.ndarray, rows: np.ndarray) -> np.ndarray:
    return np.asarray(rows, np.float64) @ np.asarray(m)[:3, :3].T


def label_picture(
    volume: Volume, labels: np.ndarray, input_to_head: np.ndarray, path: Path, title: str
) -> Path:
    """Maximum-intensity projections along head x, z and y, coloured by the label of the
    brightest voxel on each ray (cranium grey-blue, mandible orange, extra green, other red)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = anatomical_view(volume, input_to_head, np.asarray(volume.data, np.float32))
    spacing = anatomical_spacing(volume, input_to_head)
    lab = anatomical_view(volume, input_to_head, labels)
    colours = np.array(
        [[0, 0, 0], [0.55, 0.65, 0.85], [1.0, 0.55, 0.1], [0.2, 0.8, 0.3], [0.9, 0.15, 0.15]]
    )
    lo = float(np.min(volume.data))
    fig, axes = plt.subplots(1, 4, figsize=(20, 5.6))
    # (projection axis, image rows axis, image columns axis, title)
    for ax, (proj, name) in zip(
        axes[:3], ((0, "sagittal: face right"), (2, "coronal"), (1, "axial: face up")), strict=True
    ):
        masked = np.where(lab > 0, data, lo)
        idx = np.argmax(masked, axis=proj)
        mip = np.take_along_axis(masked, np.expand_dims(idx, proj), axis=proj).squeeze(proj)
        lbl = np.take_along_axis(lab, np.expand_dims(idx, proj), axis=proj).squeeze(proj)
        shade = np.clip((mip - lo) / (np.percentile(mip[lbl > 0], 99) - lo + 1e-9), 0.25, 1.0)
        rgb = colours[lbl] * shade[..., None]
        if proj == 0:  # (y, z): rows y up, columns z (face right)
            img, rows, cols = rgb, 1, 2
        elif proj == 2:  # (x, y): rows y, columns x; viewer faces the subject -> left on the right
            img, rows, cols = np.transpose(rgb, (1, 0, 2)), 1, 0
        else:  # (x, z): rows z (face up), columns x
            img, rows, cols = np.transpose(rgb, (1, 0, 2)), 2, 0
        aspect = spacing[rows] / spacing[cols]
        ax.imshow(img, origin="lower", interpolation="nearest", aspect=aspect)
        ax.set_title(name)
        ax.set_xticks([])
        ax.set_yticks([])
    # a para-sagittal slice through the molars and the ramus (a quarter into the mandible)
    xs = np.nonzero((lab == MANDIBLE).any(axis=(1, 2)))[0]
    if len(xs):
        xi = int(xs.min() + 0.25 * (xs.max() - xs.min()))
        sl_lab, sl_data = lab[xi], data[xi]
        shade = np.clip((sl_data - lo) / (np.percentile(sl_data, 99.5) - lo + 1e-9), 0.1, 1.0)
        grey = np.where(sl_lab[..., None] > 0, colours[sl_lab], 0.35) * shade[..., None]
        axes[3].imshow(
            grey, origin="lower", interpolation="nearest", aspect=spacing[1] / spacing[2]
        )
        axes[3].set_title(f"slice {xi} along x (through the molars)")
        axes[3].set_xticks([])
        axes[3].set_yticks([])
    fig.suptitle(f"{title}: labels (grey-blue cranium, orange mandible, green extra, red other)")
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path
