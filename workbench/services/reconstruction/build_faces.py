"""Three faces for an unknown body build, and the face's 95 % uncertainty band.

Units mm.  Vertex arrays are per skin vertex of the fitted head (head frame:
x to the subject's left, y up, z toward the face, Frankfort Horizontal at
y = 0); :meth:`BuildFaces.face` gives a face in the skull file's frame.

The skull cannot tell how heavy the person was.  The build model
(:mod:`workbench.io.build_model`) moves every tissue-depth site by
``r·SD·z`` for a build score ``z``; the tissue model spreads site changes
over the skin linearly (its influence matrix ``E``,
:mod:`workbench.services.tissue.tissue_model`), so a build changes the fitted skin
by ``u(v)·Δz`` along the normal, ``u = E · (r·SD)``.  Only depths change
between builds, so the three faces (slender, average, heavy) are the
fitted face moved along its normals — no second registration or fit — and
any build between them is a blend (the window's build slider).  Where a
thinner build would take the skin closer to the bone than the fit's
minimum tissue, it stops there.  Thin parts move as one piece (the nose,
the lips together, each ear: along their mean normal, blended into the
normals around them), and the lids, which rest on the eyeball, keep their
place with the build's change fading in around them (:data:`LID_FADE_MM`).

The band: per vertex, inner and outer offsets (mm along the outward normal
of the main face) that hold the true skin with ~95 % probability when the
build is unknown.  It is the *envelope* of the builds the model spans
(``band_builds``, slender to heavy), widened by 1.96 σ where σ² adds

* what a known build leaves of the table's spread, ``SD·√(1 − r²)``,
  spread by ``|E|`` (neighbouring sites taken as fully correlated: the
  independent draws of the ensemble average out and made the old spread
  map far too narrow);
* the reconstruction's own shape error where bone is observed,
  :data:`MODEL_SD_MM`;
* over inferred skin (no bone beneath), the reference's prior,
  :data:`~workbench.services.reconstruction.reconstruct.PRIOR_SD_MM`.

The inner edge never enters the bone.  ``half_width`` is half the band's
width (the band is not centred on the face: a heavier build lies further
out than a slender one lies in).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from workbench.core.mesh import Mesh
from workbench.core.spatial import MeshIndex
from workbench.core.thickness import adjacency, smooth_field
from workbench.io.build_model import BUILD_FACES, BuildModel
from workbench.model.template import TemplateHead
from workbench.services.reconstruction.reconstruct import (
    BONE_SEARCH_MM,
    PRIOR_SD_MM,
    Reconstruction,
)

#: the band's two-sided 95 % normal quantile
BAND_Z = 1.96
#: skin regions that move as one piece between builds (each along its mean normal, blended
#: into the vertex normals around it): a thin part moved along its own vertex normals
#: would swell (an ear) or part (the lips)
RIGID_PARTS: tuple[tuple[str, ...], ...] = (
    ("nose",),
    ("upper_lip", "lower_lip"),
    ("ear_l",),
    ("ear_r",),
)
#: the lids rest on the eyeball, which sits on the bone whatever the build: they keep their
#: place, and the build's change fades in over this distance around them (mm)
LIDS = ("eyelid_upper_l", "eyelid_upper_r", "eyelid_lower_l", "eyelid_lower_r")
LID_FADE_MM = 5.0
#: smoothing passes blending a rigid part's direction into the normals around it
BLEND_PASSES = 4
#: the fitted shape's own error where the bone is observed (σ, mm): set on headsq (the lean
#: living CT the method was tuned on) as the smallest whole millimetre giving it ≥ 95 %
#: coverage at the table's means; judged on the two Visible Human cadavers
#: (docs/validation.md)
MODEL_SD_MM = 1.0


@dataclass(frozen=True, eq=False)
class BuildFaces:
    """The three build faces of one reconstruction and its band (see the module docstring).

    Attributes
    ----------
    names : the builds, thinnest first (:data:`~workbench.io.build_model.BUILD_FACES`)
    bmi, z : {name: BMI kg/m²}, {name: build score}
    main : the build of the main face (``face.ply``): a name of ``names``, else e.g.
        "BMI 27.5" (a BMI between them) — its offsets are all zero
    main_z : its build score
    per_z_mm : (n_skin,) mm of skin movement per unit build score
    offsets : {name: (n_skin,)} mm along the main face's outward normal
    lower_mm, upper_mm : (n_skin,) the band's edges relative to the main face
    model_id : the build model used
    """

    names: tuple[str, ...]
    bmi: dict[str, float]
    z: dict[str, float]
    main: str
    main_z: float
    per_z_mm: np.ndarray
    offsets: dict[str, np.ndarray]
    lower_mm: np.ndarray
    upper_mm: np.ndarray
    normals: np.ndarray
    base: np.ndarray
    model_id: str
    sigma_mm: np.ndarray | None = None
    floor_mm: np.ndarray | None = None

    @property
    def half_width_mm(self) -> np.ndarray:
        """``(n_skin,)`` half the band's width (mm)."""
        return 0.5 * (self.upper_mm - self.lower_mm)

    def band(self, build: str | None = None) -> tuple[np.ndarray, np.ndarray]:
        """``(lower, upper)`` offsets (mm, from the main face): the unknown-build band, or the
        band of a known ``build`` (its face ± 1.96 σ: the spread a known build leaves)."""
        if build is None or self.sigma_mm is None:
            return self.lower_mm, self.upper_mm
        lower = self.offsets[build] - BAND_Z * self.sigma_mm
        if self.floor_mm is not None:
            lower = np.maximum(lower, self.floor_mm)
        return lower, self.offsets[build] + BAND_Z * self.sigma_mm

    def vertices_at(self, z: float) -> np.ndarray:
        """Skin vertices (head frame) at build score ``z``: the main face moved along its
        normals, the faces' own floors kept (a blend of the two nearest faces)."""
        zs = np.array([self.z[n] for n in self.names])
        offs = np.stack([self.offsets[n] for n in self.names])
        if z <= zs[0]:
            off = offs[0]
        elif z >= zs[-1]:
            off = offs[-1]
        else:
            i = int(np.searchsorted(zs, z)) - 1
            t = (z - zs[i]) / (zs[i + 1] - zs[i])
            off = (1.0 - t) * offs[i] + t * offs[i + 1]
        return self.base + off[:, None] * self.normals

    def vertices(self, name: str) -> np.ndarray:
        return self.base + self.offsets[name][:, None] * self.normals

    def face(self, name: str, recon: Reconstruction) -> Mesh:
        """Build ``name``'s face in the skull file's frame (mm)."""
        return recon.mesh_to_input(recon.head.skin.with_vertices(self.vertices(name)))

    def summary(self) -> dict:
        """Figures for the report (mm)."""
        hw = self.half_width_mm
        return {
            "model": self.model_id,
            "main": self.main,
            "builds": {
                n: {
                    "bmi": round(self.bmi[n], 1),
                    "z": round(self.z[n], 2),
                    "offset_mm": {
                        "p5": round(float(np.percentile(self.offsets[n], 5)), 2),
                        "median": round(float(np.median(self.offsets[n])), 2),
                        "p95": round(float(np.percentile(self.offsets[n], 95)), 2),
                    },
                }
                for n in self.names
            },
            "band_half_width_mm": {
                "median": round(float(np.median(hw)), 2),
                "p90": round(float(np.percentile(hw, 90)), 2),
            },
        }


def build_faces(
    recon: Reconstruction,
    model: BuildModel,
    *,
    main: str | None = None,
    min_tissue_mm: float = 2.0,
    bone: Mesh | None = None,
) -> BuildFaces | None:
    """The three build faces and the band of ``recon`` (None when its depths cannot vary with
    build: a uniform mean + k SD, a table's build group, no SDs, the reference's own tissue).

    ``main``: the build ``recon`` was fitted at (its plan's ``build_z`` otherwise);
    ``bone``: the bone the skin must stay off (head frame; default the registration's).
    """
    field_ = recon.tissue
    plan = recon.plan
    if field_ is None or not plan.build_model or not field_.sites:
        return None
    if field_.settings.model != "table":
        return None
    per_site = np.array([s.per_z_mm for s in field_.sites])
    if not np.any(per_site):
        return None
    skin = recon.head.skin
    base = skin.vertices
    normals, keep = _directions(recon.head)
    u_band = field_.influence @ per_site
    u = u_band * keep  # the faces: the lids stay on the eyeball
    z_main = float(plan.build_z)
    zs = {n: model.z(n) for n in BUILD_FACES}
    bmis = {n: model.bmi(n) for n in BUILD_FACES}
    if main is None:
        main = next((n for n in BUILD_FACES if abs(zs[n] - z_main) < 1e-9), "")
        main = main or f"BMI {model.bmi_centre + z_main * model.bmi_sd:.1f}"
    # how far the skin may come in: the fit's minimum tissue over the bone
    target = (
        bone if bone is not None else (recon.registration.target_h if recon.registration else None)
    )
    room = np.full(len(base), np.inf)
    if target is not None:
        d = MeshIndex(target).signed_distance(base)
        near = np.abs(d) < BONE_SEARCH_MM
        room[near] = np.maximum(d[near] - min_tissue_mm, 0.0)
    offsets = {n: np.maximum(u * (zs[n] - z_main), -room) for n in BUILD_FACES}
    # the band: the envelope of the spanned builds, widened by 1.96 σ
    # (the band keeps the lids' own spread: where they rest is still uncertain)
    lo_b, hi_b = (np.maximum(u_band * (zs[b] - z_main), -room) for b in model.band_builds)
    lo = np.minimum(np.minimum(lo_b, hi_b), 0.0)
    hi = np.maximum(np.maximum(lo_b, hi_b), 0.0)
    sd = np.array([s.sd_mm or 0.0 for s in field_.sites])
    with np.errstate(divide="ignore", invalid="ignore"):
        r = np.where(sd > 0, np.clip(per_site / sd, 0.0, 1.0), 0.0)
    resid = np.abs(field_.influence) @ (sd * np.sqrt(1.0 - r**2))
    var = resid**2 + MODEL_SD_MM**2
    if recon.observed is not None:
        var = var + (PRIOR_SD_MM * (1.0 - recon.observed)) ** 2
    sigma = np.sqrt(var)
    floor = np.where(np.isfinite(room), -(room + min_tissue_mm), -np.inf)
    lower = np.maximum(lo - BAND_Z * sigma, floor)
    upper = hi + BAND_Z * sigma
    return BuildFaces(
        BUILD_FACES,
        bmis,
        zs,
        main,
        z_main,
        u,
        offsets,
        lower,
        upper,
        normals,
        base,
        model.model_id,
        sigma,
        floor,
    )


def _directions(head: TemplateHead) -> tuple[np.ndarray, np.ndarray]:
    """``(directions, weights)`` per skin vertex: the outward normals with the rigid parts'
    mean normals blended in, and 0 on the lids fading to 1 over :data:`LID_FADE_MM`."""
    from scipy.spatial import cKDTree

    skin = head.skin
    normals = skin.vertex_normals.copy()
    adj = adjacency(skin)
    for names in RIGID_PARTS:
        ids = np.concatenate(
            [np.asarray(head.regions[n], dtype=np.int64) for n in names if n in head.regions]
            or [np.zeros(0, np.int64)]
        )
        if not len(ids):
            continue
        mean = normals[ids].mean(axis=0)
        if np.linalg.norm(mean) < 1e-6:
            continue
        ind = np.zeros(skin.n_vertices)
        ind[ids] = 1.0
        b = np.clip(smooth_field(adj, ind, BLEND_PASSES), 0.0, 1.0)
        b[ids] = 1.0
        normals = (1.0 - b)[:, None] * normals + b[:, None] * (mean / np.linalg.norm(mean))
    normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    keep = np.ones(skin.n_vertices)
    lids = [np.asarray(head.regions[n], dtype=np.int64) for n in LIDS if n in head.regions]
    if lids:
        lid = np.concatenate(lids)
        dist = cKDTree(skin.vertices[lid]).query(skin.vertices)[0]
        keep = np.clip(dist / LID_FADE_MM, 0.0, 1.0)
    return normals, keep


def band_coverage(
    face: Mesh,
    lower: np.ndarray,
    upper: np.ndarray,
    points: np.ndarray,
    labels: np.ndarray | None = None,
    region_names: tuple[str, ...] | list[str] = (),
) -> dict:
    """How many of the true-skin ``points`` lie inside a band (same frame as ``face``, mm).

    Each point's offset from the face along the face's outward side (its signed distance:
    positive outside) is compared with the band's edges interpolated at its closest point.
    Returns ``{"coverage", "half_width_median_mm", "n", "regions": {name: {...}}}``.
    """
    index = MeshIndex(face)
    cp, signed = index.signed_closest_points(points)
    tri = face.faces[cp.face_ids]
    lo = np.einsum("ij,ij->i", cp.barycentric, lower[tri])
    hi = np.einsum("ij,ij->i", cp.barycentric, upper[tri])
    inside = (signed >= lo) & (signed <= hi)
    half = 0.5 * (hi - lo)

    def figures(mask: np.ndarray) -> dict:
        n = int(mask.sum())
        return {
            "n": n,
            "coverage": round(float(inside[mask].mean()), 4) if n else None,
            "half_width_median_mm": round(float(np.median(half[mask])), 2) if n else None,
        }

    out = figures(np.ones(len(points), bool))
    if labels is not None:
        out["regions"] = {
            name: figures(np.asarray(labels) == i) for i, name in enumerate(region_names)
        }
    return out
