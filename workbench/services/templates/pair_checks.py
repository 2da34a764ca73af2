"""Checks of a skin and skull pair before a template build (one input frame, mm).

Refused in seconds rather than after the (long) build: one file given as both
surfaces, skin and skull swapped, a skin that cannot be the skull's person's,
surfaces not in one frame (:func:`check_skin_fits_skull`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from os import PathLike
from pathlib import Path

import numpy as np

from workbench.core.errors import InputError
from workbench.core.mesh import Mesh, boundary_loops
from workbench.core.spatial import MeshIndex
from workbench.model.evidence import file_sha256

#: input checks before a build (:func:`check_skin_fits_skull`), on up to PAIR_SAMPLES
#: skull vertices.  The skin of one CT encloses its bone: measured on headsq and both
#: Visible Human heads, the median skull-to-skin distance is 11-18 mm (vault and face
#: 3-15 mm, the inner table, sinuses and C-spine deeper) and no skull point lies more than
#: 2 mm outside the skin (0-0.05 %); headsq's skin centred on a Visible Human skull lets
#: 27 % of it through, its own skin moved by 10 mm 4 %, by 20 mm 1.6 %.  A skin of a
#: similar head placed just so over the skull passes (the Visible Human skins centred on
#: each other's skull: 0-1.3 %): geometry alone cannot tell two such people apart
PAIR_SAMPLES = 6000
#: the skull lying farther than this (mm, median) from the skin: not one scan, or two frames
PAIR_FAR_MM = 50.0
#: a median tissue thinner than this (mm): the "skin" hugs the bone (a second bone surface)
PAIR_MIN_MEDIAN_TISSUE_MM = 2.0
#: a median tissue thicker than this (mm): the skin is far too large for the skull
PAIR_MAX_MEDIAN_TISSUE_MM = 35.0
#: skull points more than PAIR_OUTSIDE_MM outside the skin: at most this fraction
PAIR_OUTSIDE_MM = 2.0
PAIR_MAX_OUTSIDE_FRACTION = 0.01


def vertex_mask(n: int, groups: Sequence) -> np.ndarray:
    """Boolean mask of ``n`` vertices, True at every index in any of ``groups``."""
    m = np.zeros(n, dtype=bool)
    for ids in groups:
        m[np.asarray(ids, dtype=np.int64)] = True
    return m


def _pair_source(skin_source: object, skull_source: object) -> str:
    return f"--skin {skin_source} and --skull {skull_source}"


def check_distinct_inputs(
    skin_path: str | PathLike[str],
    skull_path: str | PathLike[str],
    hashes: tuple[str, str] | None = None,
) -> None:
    """Refuse one file given as both surfaces (same path, or same content: ``hashes`` are
    the two files' SHA-256 when the caller has them)."""
    skin_path, skull_path = Path(skin_path), Path(skull_path)
    same = False
    try:
        same = skin_path.samefile(skull_path)
    except OSError:
        same = skin_path.absolute() == skull_path.absolute()
    if same:
        raise InputError(
            _pair_source(skin_path, skull_path),
            "are the same file",
            "give the skin surface as --skin and the bone surface as --skull (e.g. both "
            "extracted from one CT with workbench mesh-from-ct --tissue skin / --tissue bone)",
        )
    if hashes is None:
        hashes = (file_sha256(skin_path), file_sha256(skull_path))
    if hashes[0] == hashes[1]:
        raise InputError(
            _pair_source(skin_path, skull_path),
            f"have the same content (SHA-256 {hashes[0][:16]}...): one surface given twice",
            "give the skin surface as --skin and the bone surface as --skull",
        )


@dataclass(frozen=True)
class PairMeasure:
    """Skull vertices measured against the skin (:func:`measure_pair`; mm, one frame).

    ``distance`` (unsigned) for every sampled skull vertex; ``depth`` (signed,
    outside > 0) for those the skin covers (closest skin point not on a hole's
    or the field of view's rim); mean distances of skull and skin vertices from
    the skull's centroid.
    """

    n_points: int
    distance: np.ndarray
    depth: np.ndarray
    radius_skull: float
    radius_skin: float

    @property
    def figures(self) -> dict[str, float]:
        depth = self.depth
        return {
            "skull_points": float(self.n_points),
            "covered_fraction": len(depth) / max(self.n_points, 1),
            "median_distance_mm": float(np.median(self.distance)),
            "outside_fraction": float((depth > 0).mean()) if len(depth) else 0.0,
            "through_fraction": float((depth > PAIR_OUTSIDE_MM).mean()) if len(depth) else 0.0,
            "median_tissue_mm": float(np.median(-depth)) if len(depth) else float("nan"),
            "mean_radius_skull_mm": self.radius_skull,
            "mean_radius_skin_mm": self.radius_skin,
        }


def measure_pair(skin: Mesh, skull: Mesh) -> PairMeasure | None:
    """Up to :data:`PAIR_SAMPLES` skull vertices measured against ``skin`` (None when
    either mesh has too few triangles to judge: left to the other checks)."""
    if skin.n_faces < 4 or skull.n_faces < 4:
        return None
    step = max(1, skull.n_vertices // PAIR_SAMPLES)
    points = skull.vertices[::step]
    outward_skin = skin.outward()
    cp, signed = MeshIndex(outward_skin).signed_closest_points(points)
    rim = np.zeros(skin.n_faces, dtype=bool)
    loops = boundary_loops(outward_skin)
    if loops:
        rim = vertex_mask(skin.n_vertices, loops)[skin.faces].any(axis=1)
    covered = ~rim[cp.face_ids]
    centre = skull.vertices.mean(axis=0)
    return PairMeasure(
        len(points),
        cp.distances,
        signed[covered],
        float(np.linalg.norm(skull.vertices - centre, axis=1).mean()),
        float(np.linalg.norm(skin.vertices - centre, axis=1).mean()),
    )


def check_not_swapped(
    measure: PairMeasure | None, skin_source: object = "skin", skull_source: object = "skull"
) -> None:
    """Refuse a skull surface that encloses the skin surface (any units: no lengths used).

    Swapped when the two overlap (median distance under half the skull's mean
    radius), most of the skull the skin covers lies outside it, and the
    skull's vertices lie farther from its centre than the skin's.
    """
    if measure is None or len(measure.depth) < 0.2 * measure.n_points:
        return
    f = measure.figures
    overlap = f["median_distance_mm"] < 0.5 * measure.radius_skull
    if overlap and f["outside_fraction"] > 0.5 and measure.radius_skull > measure.radius_skin:
        raise InputError(
            _pair_source(skin_source, skull_source),
            f"the skull surface encloses the skin surface ({100 * f['outside_fraction']:.0f} % "
            "of the skull lies outside the skin, and the skull is the larger of the two: "
            f"{measure.radius_skull / max(measure.radius_skin, 1e-12):.2f} x the skin's mean "
            "radius): skin and skull look swapped",
            "give the skin surface as --skin and the bone surface as --skull",
        )


def check_skin_fits_skull(
    skin: Mesh | PairMeasure | None,
    skull: Mesh | None = None,
    skin_source: object = "skin",
    skull_source: object = "skull",
) -> dict[str, float]:
    """Refuse a skin and a skull (mm, one frame) that cannot be one person's, before the
    (long) build; ``skin`` may be a :class:`PairMeasure` already taken (then no ``skull``).

    On up to :data:`PAIR_SAMPLES` skull vertices (:func:`measure_pair`):

    - the skull far from the skin (median > :data:`PAIR_FAR_MM`): not in one frame;
    - swapped (:func:`check_not_swapped`);
    - more than :data:`PAIR_MAX_OUTSIDE_FRACTION` of the skull the skin covers more
      than :data:`PAIR_OUTSIDE_MM` outside it: the skin does not fit that skull
      (another person's, or moved);
    - a median tissue outside :data:`PAIR_MIN_MEDIAN_TISSUE_MM` -
      :data:`PAIR_MAX_MEDIAN_TISSUE_MM`: a second bone surface, or a skin far too large.

    Returns the figures (fractions, mm; empty when the meshes are too small to judge).
    """
    if isinstance(skin, PairMeasure) or skin is None:
        measure = skin
    else:
        if skull is None:
            raise TypeError("check_skin_fits_skull needs the skull with a skin mesh")
        measure = measure_pair(skin, skull)
    if measure is None:
        return {}
    source = _pair_source(skin_source, skull_source)
    f = measure.figures
    median = f["median_distance_mm"]
    if median > PAIR_FAR_MM:
        raise InputError(
            source,
            f"the skull lies {median:.0f} mm (median) from the skin: the two surfaces are "
            "not in one frame (another scan, another person, or moved)",
            "give the skin and bone surfaces of one CT, both in the scan's own coordinates",
        )
    if len(measure.depth) < 0.2 * measure.n_points:  # the skin covers too little to judge
        return f
    check_not_swapped(measure, skin_source, skull_source)
    depth = measure.depth
    if f["through_fraction"] > PAIR_MAX_OUTSIDE_FRACTION:
        worst = float(np.quantile(depth, 0.99))
        raise InputError(
            source,
            f"{100 * f['through_fraction']:.1f} % of the skull lies more than "
            f"{PAIR_OUTSIDE_MM:g} mm outside the skin (1 % by {worst:.0f} mm or more; one "
            f"person's skin keeps the bone inside, at most "
            f"{100 * PAIR_MAX_OUTSIDE_FRACTION:g} % may poke through): the skin does not fit "
            "this skull",
            "another person's skin, or the two surfaces are not in one frame; give the skin "
            "and bone surfaces of one CT",
        )
    tissue = f["median_tissue_mm"]
    if not PAIR_MIN_MEDIAN_TISSUE_MM <= tissue <= PAIR_MAX_MEDIAN_TISSUE_MM:
        thin = tissue < PAIR_MIN_MEDIAN_TISSUE_MM
        raise InputError(
            source,
            f"the skin lies {tissue:.1f} mm (median) from the skull, outside the "
            f"{PAIR_MIN_MEDIAN_TISSUE_MM:g}-{PAIR_MAX_MEDIAN_TISSUE_MM:g} mm of soft tissue "
            "of one person's head: "
            + (
                "the skin hugs the bone (is --skin a second bone surface?)"
                if thin
                else "the skin is far too large for this skull (another person's skin?)"
            ),
            "give the skin and bone surfaces of one CT (workbench mesh-from-ct --tissue skin "
            "/ --tissue bone)",
        )
    return f
