"""The project's accuracy metric for a reconstructed face against a true skin.

Units: mm; every mesh and the anterior direction in one frame (the CT's
physical frame for a CT pair).  This is the definition of
``../shared/design/VALIDATION.md``, used by ``workbench validate``, the
benchmarks and the demo so that every printed figure compares with the
literature and with itself over time.

Scored points
-------------
The vertices ``p`` of the true skin that are all of

1. on the *outermost* skin: a ray from ``p + 0.3 a`` toward the anterior
   direction ``a`` meets no other part of the skin (a CT skin iso-surface
   also holds the airway, sinuses and the inside of lips and lids, which no
   reconstruction should match);
2. facing anterior: vertex normal · ``a`` > 0.3;
3. in front of the bone's bounding-box centre along ``a``;
4. within 35 mm of the true bone surface;

and not removed by a mask (:class:`ScoreMask`: the part of the skin a
scanner's field of view flattened).  For each, the distance to the
reconstructed surface (closest point on its triangles) and its sign,
positive where the reconstruction lies *outside* the true skin.

Figures: mean |d|, RMS, signed mean ± SD, % within 1, 2.5 and 5 mm, p95,
over all scored points and per face region (labels supplied by the caller).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from workbench.core.mesh import Mesh
from workbench.core.normals import vertex_normals
from workbench.core.raycast import RayCaster
from workbench.core.spatial import MeshIndex

#: the metric's constants (VALIDATION.md); changing one makes figures incomparable
RAY_START_MM = 0.3
MIN_ANTERIOR_DOT = 0.3
MAX_BONE_DISTANCE_MM = 35.0
#: the tolerances of the "% within" figures
TOLERANCES_MM = (1.0, 2.5, 5.0)
#: a vertex this close to the most anterior extent (mm) lies on a field-of-view clip
CLIP_FLAT_MM = 0.6


@dataclass(frozen=True)
class ScoreMask:
    """Skin a scanner's field of view flattened, taken out of the score.

    ``kind``:

    * ``"none"``;
    * ``"clip_patch"``: drop vertices within ``mm`` of the flat patch where
      the field of view cut the skin (VHP female: the nose tip);
    * ``"behind_clip"``: keep only vertices at least ``mm`` behind the
      clipping plane (VHP male: the face is clipped flat in front; only
      cheeks, jaw and chin are scored).

    The clip is found on the truth itself: the anterior-facing vertices
    within :data:`CLIP_FLAT_MM` of the skin's most anterior extent.
    """

    kind: str = "none"
    mm: float = 0.0

    @classmethod
    def parse(cls, text: str | None) -> ScoreMask:
        """``""``/``"none"``, ``"clip_patch:10"`` or ``"behind_clip:3"``."""
        text = (text or "").strip()
        if text in ("", "none"):
            return cls()
        kind, _, value = text.partition(":")
        if kind not in ("clip_patch", "behind_clip"):
            raise ValueError(f"unknown mask {text!r}: use none, clip_patch:MM or behind_clip:MM")
        try:
            mm = float(value)
        except ValueError:
            raise ValueError(f"mask {text!r} needs a distance in mm after the colon") from None
        if not 0.0 <= mm <= 100.0:
            raise ValueError(f"mask {text!r}: the distance must be 0-100 mm")
        return cls(kind, mm)

    def __str__(self) -> str:
        return "none" if self.kind == "none" else f"{self.kind}:{self.mm:g}"

    def keep(self, truth: Mesh, anterior: np.ndarray) -> np.ndarray:
        """``(n_vertices,)`` bool: truth vertices the mask leaves in."""
        n = truth.n_vertices
        if self.kind == "none":
            return np.ones(n, dtype=bool)
        depth = truth.vertices @ anterior
        front = float(depth.max())
        flat = (depth >= front - CLIP_FLAT_MM) & (vertex_normals(truth) @ anterior > 0.9)
        if self.kind == "behind_clip":
            return depth <= front - self.mm
        if not flat.any():
            return np.ones(n, dtype=bool)
        from scipy.spatial import cKDTree

        d, _ = cKDTree(truth.vertices[flat]).query(truth.vertices, distance_upper_bound=self.mm)
        return ~np.isfinite(d)


def unit(v: Sequence[float] | np.ndarray) -> np.ndarray:
    a = np.asarray(v, dtype=float).reshape(3)
    n = float(np.linalg.norm(a))
    if not np.isfinite(n) or n == 0:
        raise ValueError("the anterior direction must be a finite, non-zero vector")
    return a / n


def scored_vertices(
    truth: Mesh, bone: Mesh, anterior: Sequence[float] | np.ndarray, mask: ScoreMask = ScoreMask()
) -> np.ndarray:
    """Ids of the truth-skin vertices the metric scores (see the module docstring)."""
    a = unit(anterior)
    v = truth.vertices
    facing = vertex_normals(truth) @ a > MIN_ANTERIOR_DOT
    centre = bone.bounds.mean(axis=0)
    ahead = (v - centre) @ a > 0
    keep = facing & ahead & mask.keep(truth, a)
    ids = np.flatnonzero(keep)
    if len(ids) == 0:
        return ids
    d = MeshIndex(bone).closest_points(v[ids]).distances
    ids = ids[d <= MAX_BONE_DISTANCE_MM]
    if len(ids) == 0:
        return ids
    hits = RayCaster(truth).first_hits(v[ids] + RAY_START_MM * a, np.tile(a, (len(ids), 1)))
    return ids[~hits.hit]


def signed_errors(points: np.ndarray, recon: Mesh, index: MeshIndex | None = None) -> np.ndarray:
    """Distance of ``points`` (true skin) to ``recon``; positive where ``recon`` lies outside.

    ``recon`` must be wound outward (normals away from the head).
    """
    index = index or MeshIndex(recon)
    return -index.signed_distance(points)


def summarize(signed: np.ndarray) -> dict[str, float | int | None]:
    """Figures of one set of signed errors (mm; percentages 0-100)."""
    s = np.asarray(signed, dtype=float)
    if len(s) == 0:
        return {
            "n": 0,
            "mean_abs_mm": None,
            "rms_mm": None,
            "signed_mean_mm": None,
            "signed_sd_mm": None,
            "p95_mm": None,
            **{_pct_key(t): None for t in TOLERANCES_MM},
        }
    a = np.abs(s)
    out: dict[str, float | int | None] = {
        "n": int(len(s)),
        "mean_abs_mm": round(float(a.mean()), 3),
        "rms_mm": round(float(np.sqrt((s**2).mean())), 3),
        "signed_mean_mm": round(float(s.mean()), 3),
        "signed_sd_mm": round(float(s.std(ddof=1)) if len(s) > 1 else 0.0, 3),
        "p95_mm": round(float(np.percentile(a, 95)), 3),
    }
    for t in TOLERANCES_MM:
        out[_pct_key(t)] = round(100.0 * float((a <= t).mean()), 2)
    return out


def _pct_key(t: float) -> str:
    return f"pct_within_{t:g}mm".replace(".", "_")


def score(
    recon: Mesh,
    truth: Mesh,
    ids: np.ndarray,
    *,
    labels: np.ndarray | None = None,
    region_names: Sequence[str] = (),
) -> dict:
    """Figures of ``recon`` on the truth vertices ``ids``, overall and per region.

    ``labels`` (one per id, an index into ``region_names``, −1 for none)
    split the figures by face region.
    """
    signed = signed_errors(truth.vertices[ids], recon)
    regions: dict[str, dict[str, float | int | None]] = {}
    out: dict[str, Any] = {"all": summarize(signed), "regions": regions}
    if labels is not None:
        for k, name in enumerate(region_names):
            regions[name] = summarize(signed[labels == k])
    out["signed_mm"] = signed
    return out


def region_labels(
    truth_points: np.ndarray,
    recon: Mesh,
    vertex_regions: Mapping[str, np.ndarray],
    names: Sequence[str],
) -> np.ndarray:
    """Region index per truth point: the region of the reconstruction vertex nearest it."""
    lab = np.full(recon.n_vertices, -1, dtype=np.int64)
    for k, name in enumerate(names):
        ids = vertex_regions.get(name)
        if ids is not None:
            lab[np.asarray(ids, dtype=np.int64)] = k
    from scipy.spatial import cKDTree

    _, j = cKDTree(recon.vertices).query(truth_points)
    return lab[j]
