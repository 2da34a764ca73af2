"""Proportions of a head and how smooth its forehead is: the age change's plausibility checks.

Units mm and degrees; every head in its Frankfort frame (x to the subject's
left, x = 0 midsagittal, y up, z toward the face).  Measured on the meshes
and skin landmarks as they are:

* **eye** -- the eyeball's diameter (the globe's extent across, x, averaged
  over both eyes; the corneal bulge is in front, along z, and not counted);
* **face width** zy-zy and **face height** n-gn (straight distances), and
  n-me (the face height of anthropometry with Martin's gnathion, the lowest
  chin point);
* **vault height** -- the vertex's height over the porions (Frankfort y, the
  head-ear height) and over the nasion (v-n);
* **neck** -- the skin's perimeter around the neck (convex hull of the
  horizontal section) halfway between menton and the neck's cut, and its
  ratio to the head circumference;
* **forehead crease** -- the largest change of the angle between
  neighbouring skin triangles on the forehead from one head to another with
  the same triangles (a ridge or dent made by a warp shows as a jump there;
  a change of size alone changes no angle).

The published values beside them (:func:`published_proportions`) come from
the growth tables: eyeball axial length (Gordon & Donzis 1985; Fledelius &
Christensen 1996) over the facial norms' face width and height (Weinberg et
al. 2016), and the head-ear height over the face height of the same
children (Dezső 1967).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from scipy.spatial import ConvexHull, QhullError

from workbench.core.head_measure import plane_section_points
from workbench.core.mesh import Mesh
from workbench.model.template import TemplateHead
from workbench.services.age.eyes import eye_owner
from workbench.services.age.targets import measure_circumference

#: the forehead: skin from this far above the nasion ... (mm)
FOREHEAD_ABOVE_NASION_MM = 10.0
#: ... to this far below the vertex (mm), in front of the frontotemporale points less this (mm)
FOREHEAD_BELOW_VERTEX_MM = 25.0
FOREHEAD_BEHIND_FT_MM = 15.0


def eyeball_diameter(head: TemplateHead) -> float:
    """The eyeballs' diameter across (x extent of each globe, mean of both; mm), NaN without."""
    eyes = head.meshes["eyes"].vertices
    if not len(eyes):
        return float("nan")
    own = eye_owner(head.eye_centres, eyes)
    spans = [float(np.ptp(eyes[own == k][:, 0])) for k in range(2) if (own == k).any()]
    return float(np.mean(spans))


def neck_circumference(head: TemplateHead) -> float:
    """Perimeter (mm) of the neck's horizontal section halfway between menton and the neck cut.

    The convex hull of the section (a tape bridges hollows); NaN when the
    head has no menton or no neck opening.
    """
    lm = head.skin_landmarks.as_dict()
    rim = head.openings.get("neck")
    if "me" not in lm or rim is None or not len(rim):
        return float("nan")
    level = 0.5 * (lm["me"][1] + float(head.skin.vertices[np.asarray(rim), 1].mean()))
    pts = plane_section_points(head.skin, np.array([0.0, level, 0.0]), np.array([0.0, 1.0, 0.0]))
    if len(pts) < 3:
        return float("nan")
    try:
        return float(ConvexHull(pts[:, [0, 2]]).area)  # in 2-D, "area" is the perimeter
    except QhullError:
        return float("nan")


def measure_proportions(head: TemplateHead) -> dict[str, float]:
    """The head's proportions (mm and ratios; see the module).  Missing landmarks give NaN."""
    lm = head.skin_landmarks.as_dict()
    nan = float("nan")

    def dist(a: str, b: str) -> float:
        return float(np.linalg.norm(lm[a] - lm[b])) if a in lm and b in lm else nan

    po = [lm[c] for c in ("po_l", "po_r") if c in lm]
    vault = float(lm["v"][1] - np.mean([q[1] for q in po])) if "v" in lm and po else nan
    v_n = float(lm["v"][1] - lm["n"][1]) if "v" in lm and "n" in lm else nan
    eye = eyeball_diameter(head)
    zy, n_gn, n_me = dist("zy_l", "zy_r"), dist("n", "gn"), dist("n", "me")
    neck, hc = neck_circumference(head), measure_circumference(head)
    return {
        "eyeball_mm": eye,
        "face_width_zy_zy_mm": zy,
        "face_height_n_gn_mm": n_gn,
        "face_height_n_me_mm": n_me,
        "vault_height_v_po_mm": vault,
        "vault_height_v_n_mm": v_n,
        "neck_circumference_mm": neck,
        "head_circumference_mm": hc,
        "eye_to_face_width": eye / zy,
        "eye_to_face_height": eye / n_gn,
        "vault_to_face_height": vault / n_me,
        "v_n_to_n_gn": v_n / n_gn,
        "neck_to_head_circumference": neck / hc,
    }


def published_proportions(sex: str, age: float, ethnicity: str = "European") -> dict[str, Any]:
    """Published counterparts of :func:`measure_proportions`' ratios at ``age`` years.

    ``eye_to_face_width`` / ``eye_to_face_height``: the mean eyeball axial
    length over the facial norms' mean zy-zy / n-gn (ages past the norms'
    last one, 39 y, read at it), with the range when the face is taken ±2 SD;
    ``vault_to_face_height``: Dezső's head-ear height over his n-me of the
    same children, with its ±2 SD band (None below 7 y); a ``neck`` norm is
    not shipped (None).  Each entry is ``{"value", "band", "source"}``.
    """
    from workbench.io.growth_norms import load_growth_norms
    from workbench.services.age.growth_tables import load_eyeball_growth, published_vault_face

    eyeball = load_eyeball_growth()
    axial = eyeball.axial_mm(age)
    norms = load_growth_norms()
    out: dict[str, Any] = {"eyeball_axial_mm": axial}
    for key, mid in (
        ("eye_to_face_width", "bizygomatic_width"),
        ("eye_to_face_height", "facial_height"),
    ):
        lo, hi = norms.age_range(mid, sex, ethnicity)
        a = min(float(age), hi)
        if a < lo:
            out[key] = None
            continue
        mu, sd = norms.at(mid, sex, a, ethnicity)
        out[key] = {
            "value": axial / mu,
            "band": (axial / (mu + 2 * sd), axial / (mu - 2 * sd)),
            "source": f"{eyeball.source_at(age)}; {norms.source_of(mid, sex, ethnicity)}",
        }
    vault = published_vault_face(sex, age)
    out["vault_to_face_height"] = (
        None
        if vault is None
        else {"value": vault["ratio"], "band": vault["band"], "source": vault["source"]}
    )
    out["neck_to_head_circumference"] = None
    return out


# ------------------------------------------------------------------ forehead smoothness
def forehead_faces(head: TemplateHead) -> np.ndarray:
    """Skin triangles of the forehead (indices; see the module's bounds), from the head's
    landmarks n, v and ft; empty when one is missing."""
    lm = head.skin_landmarks.as_dict()
    ft = [lm[c] for c in ("ft_l", "ft_r") if c in lm]
    if "n" not in lm or "v" not in lm or not ft:
        return np.zeros(0, dtype=np.int64)
    v = head.skin.vertices
    z_min = min(q[2] for q in ft) - FOREHEAD_BEHIND_FT_MM
    inside = (
        (v[:, 1] >= lm["n"][1] + FOREHEAD_ABOVE_NASION_MM)
        & (v[:, 1] <= lm["v"][1] - FOREHEAD_BELOW_VERTEX_MM)
        & (v[:, 2] >= z_min)
    )
    return np.flatnonzero(inside[head.skin.faces].all(axis=1))


def _face_pairs(mesh: Mesh, faces: np.ndarray) -> np.ndarray:
    """(k, 2) pairs of triangles among ``faces`` that share an edge."""
    f = mesh.faces[faces]
    edges = np.sort(np.vstack([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
    owner = np.tile(faces, 3)
    order = np.lexsort((edges[:, 1], edges[:, 0]))
    e, o = edges[order], owner[order]
    same = (e[1:] == e[:-1]).all(axis=1)
    return np.column_stack([o[:-1][same], o[1:][same]])


def dihedral_degrees(mesh: Mesh, pairs: np.ndarray) -> np.ndarray:
    """Angle (degrees) between the normals of each pair of triangles of ``mesh``."""
    n = mesh.face_normals
    cos = np.clip((n[pairs[:, 0]] * n[pairs[:, 1]]).sum(axis=1), -1.0, 1.0)
    return np.degrees(np.arccos(cos))


def forehead_crease(source: TemplateHead, aged: TemplateHead) -> dict[str, float]:
    """How much sharper or flatter the forehead's skin folds became from ``source`` to ``aged``.

    ``aged`` is ``source`` moved (same skin triangles).  Over the edges between
    forehead triangles (:func:`forehead_faces` of the source): the largest and
    the 99th-percentile change of the angle between the two triangles'
    normals (degrees), and each head's largest angle there.
    """
    faces = forehead_faces(source)
    if not len(faces) or source.skin.n_faces != aged.skin.n_faces:
        return {}
    pairs = _face_pairs(source.skin, faces)
    before = dihedral_degrees(source.skin, pairs)
    after = dihedral_degrees(aged.skin, pairs)
    change = np.abs(after - before)
    return {
        "max_change_deg": float(change.max()),
        "p99_change_deg": float(np.percentile(change, 99.0)),
        "max_angle_before_deg": float(before.max()),
        "max_angle_after_deg": float(after.max()),
    }


def proportion_figures(
    source: TemplateHead, aged: TemplateHead, eye_scale: float
) -> dict[str, Any]:
    """The report's figures of the eyes, the proportions and the forehead (mm, degrees)."""
    from workbench.services.age.eyes import lid_gaps, rim_gap

    def rims(head: TemplateHead) -> float:
        return float(np.mean([rim_gap(head, k) for k in range(len(head.eye_centres))]))

    def rounded(values: Mapping[str, float], digits: int = 4) -> dict[str, float | None]:
        return {k: (round(v, digits) if np.isfinite(v) else None) for k, v in values.items()}

    return {
        "eyes": {
            "scale": round(float(eye_scale), 5),
            "radius_mm": {
                "before": round(float(source.eye_radius), 3),
                "after": round(float(aged.eye_radius), 3),
            },
            "lid_gap_mm": {
                "before": rounded({**lid_gaps(source), "margin_median": rims(source)}, 3),
                "after": rounded({**lid_gaps(aged), "margin_median": rims(aged)}, 3),
            },
        },
        "proportions": {
            "before": rounded(measure_proportions(source)),
            "after": rounded(measure_proportions(aged)),
        },
        "forehead_crease_deg": rounded(forehead_crease(source, aged), 3),
    }
