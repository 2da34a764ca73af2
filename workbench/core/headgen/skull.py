"""Procedural skull, mandible, teeth, eyeballs and tongue of the reference head.

Units and frame
---------------
Millimetres in the HEAD FRAME: x toward the subject's left (x = 0
midsagittal), y up, z forward; the Frankfort Horizontal through porion
(``po_l``/``po_r``, top of the ear-canal opening) and orbitale
(``or_l``/``or_r``) is ``y = 0``; the origin is the porion midpoint.

Construction
------------
Signed distance fields (:mod:`workbench.core.headgen.sdf`): smooth unions
and subtractions of ellipsoids, round cones, swept elliptic sections and
extruded outlines, placed from the numbers in
``data_tables/template/skull_parameters.json`` (male geometry; the female
variant scales it per axis after softening the robust features, following
the sex traits of Buikstra & Ubelaker 1994 and White & Folkens 2005).  The
mandible is modelled first; its field dilated by a clearance is cut from the
cranium, which hollows the glenoid fossae and keeps the two meshes apart.
Surfaces come from marching cubes, Taubin smoothing and quadric decimation.
The finished parts are finally turned by a small rigid motion so that the
measured porion and orbitale points lie exactly on the Frankfort plane.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from functools import cache

import numpy as np

from workbench.core.data_paths import data_tables_dir
from workbench.core.headgen import sdf as S  # noqa: N812 - S.sphere(...) reads as the SDF algebra
from workbench.core.headgen.eyes import corneal_apex_offset, eyeball_mesh
from workbench.core.headgen.skull_landmarks import (
    _X,
    _Y,
    _Z,
    _orbit_edge,
    _place_left,
    _Rays,
    _scan,
)
from workbench.core.headgen.skull_shapes import cranium_grid, mandible_grid, orbit_frame
from workbench.core.headgen.teeth import Tooth, dental_arches, teeth_mesh, tongue_mesh
from workbench.core.landmarks import Landmark, LandmarkSet
from workbench.core.mesh import Mesh
from workbench.core.normals import normals_within_radius
from workbench.core.spatial import MeshIndex

SEXES = ("male", "female")


@cache
def _raw_parameters() -> dict:
    with open(data_tables_dir() / "template" / "skull_parameters.json", encoding="utf-8") as fh:
        return json.load(fh)


def skull_parameters(sex: str = "male") -> dict:
    """Geometry parameters for ``sex`` (a fresh deep copy; male coordinates, mm).

    For ``"female"`` the robust features are softened here; the size
    factors (x, z, and y blending from ``y_face`` below FH to ``y_vault``
    above the orbits) are returned under ``"_scale"`` and applied to the
    finished meshes.
    """
    if sex not in SEXES:
        raise ValueError(f"sex must be one of {SEXES}, got {sex!r}")
    raw = _raw_parameters()
    p = json.loads(json.dumps(raw["male"]))
    p["_scale"] = {"x": 1.0, "z": 1.0, "y_face": 1.0, "y_vault": 1.0}
    p["_sex"] = sex
    if sex == "female":
        f = raw["female"]
        p["_scale"] = dict(f["scale"])
        p["brow"]["radii"] = (np.asarray(p["brow"]["radii"]) * f["brow"]).tolist()
        p["glabella"]["radii"] = (np.asarray(p["glabella"]["radii"]) * f["glabella"]).tolist()
        p["glabella"]["centre"][2] -= f["glabella_back_mm"]
        for key in ("ra", "rb"):
            p["mastoid"][key] *= f["mastoid"]
        p["mastoid"]["b"][1] *= 0.5 + 0.5 * f["mastoid"]  # shorter process
        p["occipital_protuberance"]["radii"] = (
            np.asarray(p["occipital_protuberance"]["radii"]) * f["occipital_protuberance"]
        ).tolist()
        p["vault_frontal"]["centre"][1] += f["forehead_up_mm"]
        p["vault_frontal"]["centre"][2] += f["forehead_forward_mm"]
        m = p["mandible"]
        m["chin"]["radii"] = (np.asarray(m["chin"]["radii"]) * f["chin"]).tolist()
        m["mental_tubercle"]["radii"] = (
            np.asarray(m["mental_tubercle"]["radii"]) * f["chin"]
        ).tolist()
        m["ramus"]["roll_deg"] += f["ramus_roll_deg"]  # less everted angles
        arch = p["zygomatic_arch"]
        arch["radii"] = (np.asarray(arch["radii"]) * f["zygomatic_arch"]).tolist()
    return p


def measurement_targets(sex: str = "male") -> dict:
    """Target ranges ``{name: [low, high]}`` (mm) of the skull measurements for ``sex``."""
    return dict(_raw_parameters()["targets"][sex])


# ------------------------------------------------------------------ result
@dataclass(frozen=True)
class SkullTemplate:
    """The bony and dental parts of the reference head (mm, head frame).

    Attributes
    ----------
    cranium, mandible : Mesh
        Closed, outward-wound surfaces; the mandible in the rest pose (teeth
        in occlusion).
    upper_teeth, lower_teeth : Mesh
        16 closed tooth solids each (one component per tooth).
    eyes : Mesh
        Both globes (two components); ``eye_centres`` ``(2, 3)`` (left, right)
        and ``eye_radius`` (mm) describe them.
    tongue : Mesh
    teeth : tuple of Tooth
        Per-tooth axes, tips and cemento-enamel junctions (guides for the lips).
    landmarks : LandmarkSet
        Every representable skull landmark of the catalogue, on its mesh.
    landmark_part : dict
        code -> "cranium" | "mandible" | "teeth".
    landmark_normals : dict
        code -> ``(3,)`` outward unit normal averaged over 5 mm.
    not_representable : dict
        code -> reason, for catalogue skull codes that could not be placed.
    tmj_axis : tuple
        ``(point (3,), direction (3,))``: the line through both condyle
        centres (the mandible's rotation axis), direction toward +x.
    condyle_centres : (2, 3)
        Left and right condyle centres (mm).
    parameters : dict
        The parameters used (see :func:`skull_parameters`) plus the measured
        dimensions under ``"measurements"`` and the frame correction.
    """

    sex: str
    cranium: Mesh
    mandible: Mesh
    upper_teeth: Mesh
    lower_teeth: Mesh
    eyes: Mesh
    eye_centres: np.ndarray
    eye_radius: float
    tongue: Mesh
    teeth: tuple
    landmarks: LandmarkSet
    landmark_part: dict
    landmark_normals: dict
    tmj_axis: tuple
    condyle_centres: np.ndarray
    parameters: dict
    not_representable: dict = field(default_factory=dict)


# ------------------------------------------------------------------ assembly
def _unit(v) -> np.ndarray:
    v = np.asarray(v, float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


class _Map:
    """Point map from the modelling frame to the head frame: a rigid motion, then a sex scaling.

    The scaling multiplies x and z by constants and y by ``s(y)``, blending
    from ``face`` (below FH) to ``vault`` (above the orbits), so that a
    female face is scaled a little more than her vault (relative face
    heights of Howells' 1973 female vs male means); it keeps y = 0 fixed.
    """

    def __init__(
        self,
        rigid: np.ndarray,
        scale_xz=(1.0, 1.0),
        y_face: float = 1.0,
        y_vault: float = 1.0,
        y_range=(-20.0, 40.0),
    ):
        self.A, self.sxz = np.asarray(rigid, float), np.asarray(scale_xz, float)
        self.yf, self.yv, self.yr = float(y_face), float(y_vault), y_range

    @property
    def affine(self) -> bool:
        return self.yf == self.yv

    def __call__(self, points) -> np.ndarray:
        q = np.asarray(points, float) @ self.A[:3, :3].T + self.A[:3, 3]
        t = np.clip((q[..., 1] - self.yr[0]) / (self.yr[1] - self.yr[0]), 0.0, 1.0)
        sy = self.yf + (self.yv - self.yf) * t * t * (3.0 - 2.0 * t)
        return np.stack([q[..., 0] * self.sxz[0], q[..., 1] * sy, q[..., 2] * self.sxz[1]], axis=-1)

    def matrix(self) -> np.ndarray:
        """The 4x4 matrix of the map (only when it is affine)."""
        return np.diag([self.sxz[0], self.yv, self.sxz[1], 1.0]) @ self.A

    def mesh(self, m: Mesh) -> Mesh:
        return Mesh(self(m.vertices), m.faces)  # orientation-preserving (positive Jacobian)

    def length(self, at, direction, length: float) -> float:
        at = np.asarray(at, float)
        return float(np.linalg.norm(self(at + length * np.asarray(direction)) - self(at)))

    def direction(self, at, direction) -> np.ndarray:
        at = np.asarray(at, float)
        return _unit(self(at + np.asarray(direction, float)) - self(at))


def _move_tooth(t: Tooth, f: _Map) -> Tooth:
    return Tooth(
        t.code,
        t.jaw,
        t.name,
        t.side,
        f(t.tip),
        f.direction(t.tip, t.axis),
        f.direction(t.tip, t.mesial),
        f.direction(t.tip, t.buccal),
        f.length(t.tip, t.axis, t.crown),
        f.length(t.cej, t.axis, t.root),
        f.length(t.tip, t.mesial, t.md),
        f.length(t.cej, t.mesial, t.md_cervix),
        f.length(t.tip, t.buccal, t.ll),
        f.length(t.cej, t.buccal, t.ll_cervix),
    )


def _hints(p: dict, teeth: dict, f: _Map) -> dict:
    """Construction hints (orbit frame, tooth positions, ...) mapped into the head frame."""
    oc, rows = orbit_frame(p)
    e3 = f.direction(oc, rows[2])
    e2 = _unit(f.direction(oc, rows[1]) - (f.direction(oc, rows[1]) @ e3) * e3)
    ec, fm = p["ear_canal"], p["foramen_magnum"]
    fmc = f(fm["centre"])
    canal_c = (0.0, ec["centre_y"], ec["centre_z"])
    canal = f(canal_c)
    ui, li = teeth["U_I1_l"], teeth["L_I1_l"]
    tp = p["teeth"]
    z_ramus = np.mean(np.asarray(p["mandible"]["ramus"]["outline"])[:, 0])
    y_occ = tp["occlusal_y_incisor"] + (tp["occlusal_z_incisor"] - z_ramus) * np.tan(
        np.radians(tp["occlusal_plane_deg"])
    )
    return {
        "glabella": f(p["glabella"]["centre"]),
        "rhinion_y": f((0, max(q[1] for q in p["nasal_aperture"]["outline"]), 90))[1],
        "ans_y": f(p["ans"]["b"])[1],
        "upper_crest_y": (ui.cej + p["upper_alveolus"]["crest_above_cej"] * ui.axis)[1],
        "lower_crest_y": (li.cej + p["mandible"]["body"]["crest_below_cej"] * li.axis)[1],
        "foramen_magnum": (
            fmc[1],
            fmc[2],
            f.length(fm["centre"], _Z, fm["radii"][2]),
            f.length(fm["centre"], _Y, fm["radii"][1]),
        ),
        "orbit_centre": f(oc),
        "orbit_frame": np.stack([np.cross(e2, e3), e2, e3]),
        "canal": (canal[1], canal[2], f.length(canal_c, _Y, ec["radius"])),
        "aperture_z": f((0, 0, p["piriform_rim"]["z"]))[2],
        "teeth": teeth,
        "ramus_x": f(p["mandible"]["ramus"]["origin"])[0],
        "ramus_occlusal_y": f((0, y_occ, z_ramus))[1],
    }


def _frankfort_correction(rays: _Rays, p: dict, teeth: dict) -> np.ndarray:
    """Rigid 4x4 motion putting the measured porion and orbitale on y = 0 (porion midpoint at 0).

    The model is built with both points designed onto y = 0, so the motion
    is tiny (well under a degree and a millimetre); one step suffices.
    """
    h = _hints(p, teeth, _Map(np.eye(4)))
    xs = rays.one((300, h["canal"][0] + h["canal"][2] + 3.0, h["canal"][1]), -_X, "po")[0]
    po = rays.one((xs - 2.0, h["canal"][0], h["canal"][1]), _Y, "po")
    oc, frame = h["orbit_centre"], h["orbit_frame"]
    orb = min(
        (_orbit_edge(rays, oc, frame, u, -1.0) for u in np.arange(-14.0, 14.5, 0.5)),
        key=lambda q: q[1],
    )
    theta = np.arctan2(orb[1] - po[1], orb[2] - po[2])
    c, s = np.cos(theta), np.sin(theta)
    step = np.eye(4)
    step[:3, :3] = [[1, 0, 0], [0, c, -s], [0, s, c]]  # turns the po->or direction to +z
    step[:3, 3] = -step[:3, :3] @ np.array([0.0, po[1], po[2]])
    return step


def _mirror_landmark(rays: _Rays, mesh: Mesh, q: np.ndarray, n: np.ndarray) -> np.ndarray:
    """The surface point mirroring ``q`` (normal ``n``) across x = 0: a short ray along the mirrored normal."""
    m = np.array([-1.0, 1.0, 1.0])
    target, normal = q * m, n * m
    hit = rays(target + 1.5 * normal, -normal)[0]
    if np.isfinite(hit).all() and np.linalg.norm(hit - target) < 0.5:
        return hit
    return MeshIndex(mesh).closest_points(target[None]).points[0]


def build_skull(sex: str = "male") -> SkullTemplate:
    """Build the reference skull, mandible, teeth, eyes and tongue for ``sex``.

    Deterministic (no randomness, nothing cached on disk); about 5 s.
    """
    p = skull_parameters(sex)
    teeth = dental_arches(p)
    mgrid = mandible_grid(p, teeth)
    cgrid = cranium_grid(p, teeth, mgrid)
    cr = S.mesh_from_field(
        *cgrid.full(), cgrid.h, smooth=6, target=p["triangles"]["cranium"], blur=0.6
    )
    md = S.mesh_from_field(
        *mgrid.full(), mgrid.h, smooth=6, target=p["triangles"]["mandible"], blur=0.6
    )
    upper, lower = teeth_mesh(teeth, "U"), teeth_mesh(teeth, "L")
    tongue = tongue_mesh(teeth, avoid=mgrid.sample)
    tooth_map = {t.code: t for t in teeth}
    casters = {"cranium": _Rays(cr), "mandible": _Rays(md)}
    sc = p["_scale"]
    fmap = _Map(
        _frankfort_correction(casters["cranium"], p, tooth_map),
        (sc["x"], sc["z"]),
        sc["y_face"],
        sc["y_vault"],
    )
    cr, md, upper, lower, tongue = (fmap.mesh(m) for m in (cr, md, upper, lower, tongue))
    tooth_map = {k: _move_tooth(t, fmap) for k, t in tooth_map.items()}
    h = _hints(p, tooth_map, fmap)
    # landmarks: construct the midline and the left side, mirror to the right
    meshes = {"cranium": cr, "mandible": md}
    if fmap.affine:  # reuse the acceleration structures built before the map
        rays = {k: c.mapped(fmap.matrix()) for k, c in casters.items()}
    else:
        rays = {k: _Rays(m) for k, m in meshes.items()}
    left = _place_left(rays["cranium"], rays["mandible"], h)
    placed = dict(left)
    normals: dict[str, np.ndarray] = {}
    for part, mesh in meshes.items():
        codes = [c for c in left if left[c][1] == part]
        normals.update(
            zip(
                codes,
                normals_within_radius(mesh, np.array([left[c][0] for c in codes]), 5.0),
                strict=False,
            )
        )
    for code, (q, part, how) in left.items():
        if code.endswith("_l"):
            right = _mirror_landmark(rays[part], meshes[part], q, normals[code])
            placed[code[:-2] + "_r"] = (right, part, how + " (mirror of the left point)")
    for part, mesh in meshes.items():
        codes = [c for c in placed if c.endswith("_r") and placed[c][1] == part]
        normals.update(
            zip(
                codes,
                normals_within_radius(mesh, np.array([placed[c][0] for c in codes]), 5.0),
                strict=False,
            )
        )
    catalogue = _skull_codes()
    not_rep = {c: "no geometric construction for this code" for c in catalogue if c not in placed}
    order = [c for c in catalogue if c in placed] + sorted(c for c in placed if c not in catalogue)
    landmarks = LandmarkSet(
        "skull",
        tuple(
            Landmark(c, placed[c][0], "placed", 1.0, f"{placed[c][1]}: {placed[c][2]}")
            for c in order
        ),
    )
    # eyes: centred on the orbital opening; corneal apex `tangent_offset` mm in front of the
    # mso-mio tangent (Stephan 2002: the tangent rule under-predicts projection by ~4 mm)
    e = p["eye"]
    med = rays["cranium"].one(h["orbit_centre"], -h["orbit_frame"][0], "medial orbital margin")
    ec, mso, mio = placed["ec_l"][0], placed["mso_l"][0], placed["mio_l"][0]
    apex_z = 0.5 * (mso[2] + mio[2]) + e["tangent_offset_mm"]
    centre_l = np.array(
        [
            0.5 * (med[0] + ec[0]),
            0.5 * (mso[1] + mio[1]),
            apex_z - corneal_apex_offset(e["radius"], e["cornea_radius"], e["limbus_radius"]),
        ]
    )
    centres = np.array([centre_l, centre_l * [-1.0, 1.0, 1.0]])
    globes = [
        eyeball_mesh(c, e["radius"], (0.0, 0.0, 1.0), e["cornea_radius"], e["limbus_radius"])
        for c in centres
    ]
    eyes = Mesh(
        np.vstack([g.vertices for g in globes]),
        np.vstack([globes[0].faces, globes[1].faces + globes[0].n_vertices]),
    )
    cond = fmap(
        np.array(
            [
                p["mandible"]["condyle"]["centre"],
                np.multiply(p["mandible"]["condyle"]["centre"], [-1, 1, 1]),
            ]
        )
    )
    tmj = (0.5 * (cond[0] + cond[1]), _unit(cond[0] - cond[1]))
    params = json.loads(json.dumps(p))
    params["frame_correction"] = fmap.A.tolist()
    params["eye_rule"] = (
        f"globe (radius {e['radius']:.1f} mm) centred on the orbital opening: x midway between "
        "the medial orbital margin and ectoconchion, y midway between mso and mio; corneal apex "
        f"{e['tangent_offset_mm']:.1f} mm anterior to the mso-mio tangent (Stephan 2002 found the "
        "tangent rule under-predicts globe projection by 4 mm on average); this puts the apex "
        f"{apex_z - ec[2]:.1f} mm in front of ectoconchion"
    )
    params["corneal_apex_anterior_to_ec_mm"] = float(apex_z - ec[2])
    template = SkullTemplate(
        sex,
        cr,
        md,
        upper,
        lower,
        eyes,
        centres,
        float(e["radius"]),
        tongue,
        tuple(tooth_map[k] for k in sorted(tooth_map)),
        landmarks,
        {c: placed[c][1] for c in order},
        {c: normals[c] for c in order},
        tmj,
        cond,
        params,
        not_rep,
    )
    params["measurements"] = measure(template, rays["cranium"])
    return template


def _skull_codes() -> list[str]:
    import csv

    with open(
        data_tables_dir() / "landmarks" / "catalogue.csv", encoding="utf-8", newline=""
    ) as fh:
        return [row["code"] for row in csv.DictReader(fh) if row["surface"] == "skull"]


def measure(t: SkullTemplate, rays: _Rays | None = None) -> dict:
    """Standard craniometric distances (mm) measured on a built template."""
    L = {lm.code: lm.position for lm in t.landmarks}
    dist = lambda a, b: float(np.linalg.norm(L[a] - L[b]))  # noqa: E731
    v = t.cranium.vertices
    upper = v[v[:, 1] > 10.0]
    mid = 0.5 * (t.eye_centres[0] + t.eye_centres[1])
    rays = _Rays(t.cranium) if rays is None else rays
    y0 = L["ss"][1]
    floor = _scan(rays, (5.0, y0, 400.0), (0.0, 0.1, 0.0), 300, -_Z)  # upward from subspinale
    front = np.isfinite(floor[:, 2]) & (floor[:, 2] > L["ss"][2] - 12.0)
    sill = y0 + 0.1 * (int(np.argmax(~front)) - 1)  # lower margin of the aperture
    return {
        "g_op": dist("g", "op"),
        "eu_eu": float(upper[:, 0].max() - upper[:, 0].min()),
        "ba_b": dist("ba", "b"),
        "n_pr": dist("n", "pr"),
        "n_me": dist("n", "me"),
        "zy_zy": dist("zy_l", "zy_r"),
        "go_go": dist("go_l", "go_r"),
        "orbit_centre_distance": float(np.linalg.norm(t.eye_centres[0] - t.eye_centres[1])),
        "orbit_width": dist("d_l", "ec_l"),
        "orbit_height": dist("mso_l", "mio_l"),
        "aperture_width": dist("apl_l", "apl_r"),
        "aperture_height": float(L["rhi"][1] - sill),
        "porion_below_orbit_centre": float(mid[1] - L["po_l"][1]),
    }
