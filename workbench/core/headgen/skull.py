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
from pathlib import Path

import numpy as np

import workbench
from workbench.core.headgen import sdf as S
from workbench.core.headgen.eyes import corneal_apex_offset, eyeball_mesh
from workbench.core.headgen.teeth import Tooth, dental_arches, teeth_mesh, tongue_mesh
from workbench.core.landmarks import Landmark, LandmarkSet
from workbench.core.mesh import Mesh
from workbench.core.normals import normals_within_radius
from workbench.core.raycast import RayCaster
from workbench.core.spatial import MeshIndex

SEXES = ("male", "female")


def _data_tables() -> Path:
    packaged = Path(workbench.__file__).resolve().parent / "_data" / "data_tables"
    return packaged if packaged.exists() else Path(workbench.__file__).resolve().parents[1] / "data_tables"


@cache
def _raw_parameters() -> dict:
    with open(_data_tables() / "template" / "skull_parameters.json", encoding="utf-8") as fh:
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
        p["occipital_protuberance"]["radii"] = (np.asarray(p["occipital_protuberance"]["radii"])
                                                * f["occipital_protuberance"]).tolist()
        p["vault_frontal"]["centre"][1] += f["forehead_up_mm"]
        p["vault_frontal"]["centre"][2] += f["forehead_forward_mm"]
        m = p["mandible"]
        m["chin"]["radii"] = (np.asarray(m["chin"]["radii"]) * f["chin"]).tolist()
        m["mental_tubercle"]["radii"] = (np.asarray(m["mental_tubercle"]["radii"]) * f["chin"]).tolist()
        m["ramus"]["roll_deg"] += f["ramus_roll_deg"]  # less everted angles
        arch = p["zygomatic_arch"]
        arch["radii"] = (np.asarray(arch["radii"]) * f["zygomatic_arch"]).tolist()
    return p


def measurement_targets(sex: str = "male") -> dict:
    """Target ranges ``{name: [low, high]}`` (mm) of the skull measurements for ``sex``."""
    return dict(_raw_parameters()["targets"][sex])


# ------------------------------------------------------------------ helpers
def _rot(deg) -> np.ndarray:
    """Rows of the rotation by Euler angles (x, y, z) in degrees, applied x first."""
    ax, ay, az = np.radians(np.asarray(deg, float))
    cx, sx, cy, sy, cz, sz = np.cos(ax), np.sin(ax), np.cos(ay), np.sin(ay), np.cos(az), np.sin(az)
    rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return (rz @ ry @ rx).T


def _ell(d: dict) -> S.Ellipsoid:
    return S.Ellipsoid(d["centre"], d["radii"], _rot(d["rot_deg"]) if "rot_deg" in d else None)


def _sweep(curve, radii, up=(0.0, 1.0, 0.0), closed=False, exponent=2.0) -> S.Sweep:
    """Sweep through control points; ``up`` is one vector or one per control point."""
    up = np.asarray(up, float)
    per_point = up.ndim == 2
    values = np.hstack([np.asarray(radii, float), up]) if per_point else radii
    pts, tang, val = S.resample(curve, values, step=0.5, closed=closed)
    if per_point:
        up = val[:, 2:5] / np.linalg.norm(val[:, 2:5], axis=1, keepdims=True)
    return S.Sweep(pts, tang, val[:, :2], up=up, closed=closed, exponent=exponent)


def orbit_frame(p: dict) -> tuple[np.ndarray, np.ndarray]:
    """Centre and rows (lateral, up, outward normal) of the left orbital opening."""
    o = p["orbit"]
    return np.asarray(o["centre"], float), S.rotation_to(o["normal"])


def orbit_outline(p: dict, scale: float = 1.0, n: int = 72) -> np.ndarray:
    """``(n, 2)`` rounded-rectangle outline of the orbital opening in the orbit frame (mm)."""
    o = p["orbit"]
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    e = 2.0 / o["exponent"]
    u = o["half_width"] * np.sign(np.cos(t)) * np.abs(np.cos(t)) ** e
    v = o["half_height"] * np.sign(np.sin(t)) * np.abs(np.sin(t)) ** e
    a = np.radians(o["tilt_deg"])
    return scale * np.column_stack([u * np.cos(a) - v * np.sin(a), u * np.sin(a) + v * np.cos(a)])


# ------------------------------------------------------------------ mandible
def mandible_grid(p: dict, teeth: list[Tooth]) -> S.Grid:
    """Half (x >= 0) distance field of the mandible, rest pose (mouth closed)."""
    m = p["mandible"]
    h = m["grid_mm"]
    g = S.Grid((-70, -112, -8), (70, 8, 104), h, half=True)
    r = m["ramus"]
    yaw, roll = np.radians(r["yaw_deg"]), np.radians(r["roll_deg"])
    fwd = np.array([np.sin(yaw), 0.0, np.cos(yaw)])
    up = np.array([np.sin(roll), np.cos(roll), 0.0])
    up -= (up @ fwd) * fwd
    up /= np.linalg.norm(up)
    frame = np.stack([fwd, up, np.cross(fwd, up)])  # in-plane (forward, up), then the plate normal
    org = np.asarray(r["origin"], float)
    ring = np.column_stack([np.asarray(r["outline"], float) - [org[2], org[1]], np.zeros(len(r["outline"]))])
    outline = S.resample(ring, step=1.0, closed=True)[0][:, :2]  # rounded corners
    ramus = S.Extrusion(S.Profile2D(outline), org, frame,
                        (r["half_thickness"], r["half_thickness"]), round_mm=r["round"])
    g.union(ramus)
    ridge = r["posterior_ridge"]  # the thick, rounded posterior border and angle, in the plate's plane
    zy = np.asarray(ridge["curve_zy"], float)
    curve = np.array([org + a * fwd + b * up for a, b in
                      np.linalg.solve(np.stack([fwd[[2, 1]], up[[2, 1]]], axis=1), (zy - org[[2, 1]]).T).T])
    g.union(_sweep(curve, ridge["radii"], up=frame[2]), k=2.0)
    g.union(_ell(m["condyle"]), k=3.0)
    c = m["condyle"]["centre"]
    g.union(S.RoundCone((c[0] - 2, c[1] - 3, c[2] - 1), (org[0] + 1.0, c[1] - 16, c[2] - 3), 4.5, 4.0), k=3.0)
    # body: a band lofted between the alveolar crest (top) and the lower border (bottom)
    b = m["body"]
    lower = sorted((t for t in teeth if t.jaw == "L" and t.side == "l"), key=lambda t: -t.tip[2])
    tops = [t.cej + b["crest_below_cej"] * t.axis for t in lower]
    tops = [np.array([0.0, tops[0][1], tops[0][2]])] + tops + [np.asarray(q, float) for q in b["rear"]]
    border = np.asarray(b["lower_border"], float)[::-1]
    centres, ups, radii = [], [], []
    for top, a, flare, lean in zip(tops, b["half_thickness"], b["flare"], b["lean"]):
        bottom = np.array([top[0] + flare, np.interp(top[2], border[:, 0], border[:, 1]), top[2] - lean])
        centres.append(0.5 * (top + bottom))
        ups.append((top - bottom) / np.linalg.norm(top - bottom))
        radii.append([a, 0.5 * np.linalg.norm(top - bottom)])
    g.union(_sweep(*_symmetric(np.array(centres), np.array(radii), np.array(ups)), exponent=b["exponent"]), k=9.0)
    # keep the crowns clear: nothing of the body above the alveolar crest
    crest_z = np.array([q[2] for q in tops[1:9]])[::-1]
    crest_y = np.array([q[1] for q in tops[1:9]])[::-1]

    def above_crest(x, y, z):
        return np.maximum(np.maximum(np.interp(z, crest_z, crest_y) - y, np.abs(x) - 34.0), crest_z[0] - 4.0 - z)

    g.subtract(S.Function(above_crest, (-34, -70, crest_z[0] - 4), (34, 0, 110)), k=1.0)
    g.union(_ell(m["chin"]), k=4.0)
    g.union(_ell(m["mental_tubercle"]), k=3.0, bilateral=True)
    return g


# ------------------------------------------------------------------ cranium
def cranium_grid(p: dict, teeth: list[Tooth], mandible: S.Grid) -> S.Grid:
    """Half (x >= 0) distance field of the cranium (skull without the mandible)."""
    h = p["grid_mm"]
    g = S.Grid((-80, -62, -100), (80, 128, 118), h, half=True)
    vp, vf, tp = p["vault_parietal"], p["vault_frontal"], p["vault_taper"]
    par = S.SuperEllipsoid(vp["centre"], vp["radii"], vp.get("exponent", 2.0))

    def ramp(t, w=10.0):  # smooth max(t, 0): no crease on the vault
        return w * np.logaddexp(0.0, t / w)

    def vault(x, y, z):  # parietal vault narrowed toward the front and toward the base
        taper = 1.0 + tp["per_mm"] * ramp(z - tp["z0"]) + tp["low_per_mm"] * ramp(tp["low_y"] - y)
        return par(x * taper, y, z)

    g.union(S.Function(vault, par.lo, par.hi))
    g.union(_ell(vf), k=vf["blend"])
    g.intersect(S.Function(lambda x, y, z: p["base_floor_y"] - y + 0 * x + 0 * z,
                           (-99, -99, -99), (99, 99, 99)), k=6.0)
    g.union(_ell(p["base_block"]), k=8.0)
    g.union(_ell(p["sphenoid_block"]), k=8.0)
    g.union(_ell(p["occipital_protuberance"]), k=4.0)
    # face: orbit surroundings, nasal root, maxillae, zygomas
    oc, orot = orbit_frame(p)
    g.union(S.Ellipsoid(oc + np.array([0.0, -1.0, -16.0]), (24, 22, 16), orot), k=6.0, bilateral=True)
    g.union(_ell(p["glabella"]), k=6.0)
    g.union(_ell(p["nasal_root"]), k=6.0)
    g.union(S.RoundCone(**_cone(p["frontal_process"])), k=4.0, bilateral=True)
    g.union(_ell(p["maxilla"]), k=8.0, bilateral=True)
    g.union(_ell(p["midface"]), k=8.0)
    g.union(_ell(p["premaxilla"]), k=6.0)
    g.union(S.RoundCone(**_cone(p["canine_eminence"])), k=4.0, bilateral=True)
    g.subtract(_ell(p["canine_fossa"]), k=p["canine_fossa"]["blend"], bilateral=True)
    g.union(_ell(p["zygoma"]), k=6.0, bilateral=True)
    g.union(S.RoundCone(**_cone(p["zygomatic_buttress"])), k=6.0, bilateral=True)
    g.union(S.RoundCone(**_cone(p["orbital_pillar"])), k=4.0, bilateral=True)
    br = p["brow"]
    g.union(_sweep(br["curve"], br["radii"]), k=br["blend"], bilateral=True)
    # orbital rims, then the orbital cavities
    o = p["orbit"]
    rim3 = np.array([oc + u * orot[0] + v * orot[1] - o["rim_back"] * orot[2]
                     for u, v in orbit_outline(p, o["rim_scale"], 48)])
    g.union(_sweep(rim3, [[o["rim_radius"]] * 2] * len(rim3), up=orot[2], closed=True), k=2.5,
            bilateral=True)
    prof = S.Profile2D(orbit_outline(p))
    g.subtract(S.Extrusion(prof, oc, orot, (20.0, 10.0)), k=1.5, bilateral=True)
    g.subtract(S.Extrusion(S.Profile2D(orbit_outline(p, 1.04)), oc - 6.0 * orot[2], orot,
                           (0.0, o["depth"] - 6.0), taper=o["taper"]), k=3.0, bilateral=True)
    # temporal fossa, then the zygomatic arches across it
    tf = p["temporal_fossa"]
    g.subtract(_ell(tf), k=tf["blend"], bilateral=True)
    za = p["zygomatic_arch"]
    g.union(_sweep(za["curve"], za["radii"]), k=za["blend"], bilateral=True)
    # temporal bone: ear region, mastoid, glenoid fossa
    g.union(_ell(p["temporal_block"]), k=5.0, bilateral=True)
    g.union(_ell(p["articular_eminence"]), k=4.0, bilateral=True)
    g.union(_ell(p["glenoid_roof"]), k=4.0, bilateral=True)
    g.union(S.RoundCone(**_cone(p["mastoid"])), k=5.0, bilateral=True)
    ec = p["ear_canal"]
    g.subtract(S.RoundCone((80, ec["centre_y"], ec["centre_z"]), (ec["x_in"], ec["centre_y"], ec["centre_z"]),
                           ec["radius"]), k=1.0, bilateral=True)
    g.union(_ell(p["occipital_condyle"]), k=3.0, bilateral=True)
    g.subtract(_ell(p["foramen_magnum"]), k=2.0)
    # upper alveolar process and palate
    upper = sorted((t for t in teeth if t.jaw == "U" and t.side == "l"), key=lambda t: -t.tip[2])
    ua = p["upper_alveolus"]
    crest = np.array([t.cej + ua["crest_above_cej"] * t.axis for t in upper])
    alv = np.array([t.cej + 0.5 * t.root * t.axis for t in upper])
    pts = np.vstack([[0.0, alv[0, 1], alv[0, 2]], alv, alv[-1] + [1.0, 2.0, -8.0]])  # + tuberosity
    extra = np.interp(np.arange(len(upper) + 2), [0, 2, 4], [ua["bone_over_incisors"]] * 2 + [ua["bone_over_root"]])
    half_ll = np.array([0.5 * upper[0].ll_cervix] + [0.5 * t.ll_cervix for t in upper] + [3.0]) + extra
    ref = np.vstack([[0.0, crest[0, 1], crest[0, 2]], crest, crest[-1] + [1.0, 4.0, -8.0]])
    half_h = np.linalg.norm(pts - ref, axis=1)
    alveolus = _sweep(*_symmetric(pts, np.column_stack([half_ll, half_h])), exponent=3.0)
    g.union(alveolus, k=4.0)
    g.union(_ell(p["palate"]), k=6.0)
    g.subtract(_ell(p["palatal_vault"]), k=4.0)
    cz, cy = crest[::-1, 2], crest[::-1, 1]
    # near the teeth the maxilla is only alveolar process and palate: trim the other bulk
    env_h, env_m = ua["envelope_height"], ua["envelope_margin"]
    palate = _ell(p["palate"])

    def envelope(x, y, z):
        inside = np.minimum(alveolus(x, y, z) - env_m, palate(x, y, z))
        above = np.interp(z, cz, cy) + env_h - y
        return np.maximum(-np.minimum(inside, above), cz[0] - 4.0 - z)

    g.subtract(S.Function(envelope, (-45, -75, cz[0] - 4.0), (45, cy.max() + env_h + 6, 115)), k=3.0)
    g.union(alveolus, k=4.0)  # fillet the crease the trim leaves above the alveolar process
    # keep the crowns clear: nothing of the maxilla below the alveolar crest

    def below_crest(x, y, z):
        return np.maximum(y - np.interp(z, cz, cy) + 0 * x, cz[0] - 6.0 - z)

    g.subtract(S.Function(below_crest, (-45, -75, cz[0] - 6.0), (45, cy.max() + 1, 115)), k=1.0)
    # nasal aperture and cavity, then septum, conchae and anterior nasal spine
    na = p["nasal_aperture"]
    half = np.asarray(na["outline"], float)
    outline = np.vstack([half, half[-2:0:-1] * [-1, 1]])
    nb = p["nasal_bones"]
    g.union(_sweep(nb["curve"], nb["radii"], up=(0.0, 0.0, 1.0)), k=4.0)
    pr = p["piriform_rim"]
    rim = np.column_stack([outline * pr["scale"], pr["z"] + pr["tilt"] * (outline[:, 1] + 14.0)])
    g.union(_sweep(rim[::2], [[pr["radius"]] * 2] * len(rim[::2]), up=(0.0, 0.0, 1.0), closed=True),
            k=pr["blend"])
    g.subtract(S.Extrusion(S.Profile2D(outline), (0, 0, na["origin_z"]), np.eye(3),
                           (20.0, na["depth"]), taper=na["taper"], round_mm=na["round"]), k=1.5)
    g.subtract(_ell(p["nasal_cavity"]), k=3.0)
    g.union(S.Box(p["septum"]["centre"], p["septum"]["half"], round_mm=0.8), k=1.0)
    g.union(_ell(p["concha"]), k=2.0, bilateral=True)
    g.union(S.RoundCone(**_cone(p["ans"])), k=2.0)
    # keep clear of the mandible (this hollows the glenoid fossae)
    _subtract_grid(g, mandible, p["mandible"]["clearance_mm"], k=1.0)
    return g


def _symmetric(points: np.ndarray, radii: np.ndarray, ups: np.ndarray | None = None):
    """Control points of a left half-arch starting on the midline, continued through its mirror image.

    A sweep that merely started at ``x = 0`` would end in a flat cap there,
    and the mirrored field would show a seam along the midline.
    """
    m = np.array([-1.0, 1.0, 1.0])
    pts = np.vstack([points[:0:-1] * m, points])
    rad = np.vstack([radii[:0:-1], radii])
    if ups is None:
        return pts, rad
    return pts, rad, np.vstack([ups[:0:-1] * m, ups])


def _cone(d: dict) -> dict:
    ra = d.get("ra", d.get("r"))
    return {"a": d["a"], "b": d["b"], "ra": ra, "rb": d.get("rb", ra)}


def _subtract_grid(g: S.Grid, other: S.Grid, clearance: float, k: float) -> None:
    """``g -= (other dilated by clearance)``, evaluated on the nodes of ``g`` inside ``other``'s box."""
    lo = np.maximum(g.origin, other.origin)
    hi = np.minimum(g.origin + g.h * (np.array(g.shape) - 1),
                    other.origin + other.h * (np.array(other.shape) - 1))
    if g.half:
        lo[0] = max(lo[0], 0.0)
    i0 = np.ceil((lo - g.origin) / g.h - 1e-6).astype(int)
    i1 = np.floor((hi - g.origin) / g.h + 1e-6).astype(int) + 1
    axes = [g.origin[d] + g.h * np.arange(i0[d], i1[d]) for d in range(3)]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    d = other.sample(pts).reshape([len(a) for a in axes]) - clearance
    sl = tuple(slice(a, b) for a, b in zip(i0, i1))
    g.field[sl] = S.smax(g.field[sl], -d.astype(np.float32), k)


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


# ------------------------------------------------------------------ landmarks
class _Rays:
    """First hits of rays on one mesh; misses are NaN rows.

    ``affine`` (4x4, an invertible affine map) lets the caster built on the
    untransformed mesh answer queries about the mesh mapped by it: rays are
    pulled back, hits pushed forward (affine maps keep lines and their order
    of intersections), so one acceleration structure serves the whole build.
    """

    def __init__(self, mesh_or_caster, affine: np.ndarray | None = None):
        self.caster = mesh_or_caster if isinstance(mesh_or_caster, RayCaster) else RayCaster(mesh_or_caster)
        self.A = np.eye(4) if affine is None else np.asarray(affine, float)
        self.inv = np.linalg.inv(self.A)

    def mapped(self, affine: np.ndarray) -> _Rays:
        return _Rays(self.caster, affine)

    def __call__(self, origins, directions) -> np.ndarray:
        o = np.atleast_2d(np.asarray(origins, float))
        d = np.atleast_2d(np.asarray(directions, float))
        if len(d) == 1 and len(o) > 1:
            d = np.repeat(d, len(o), axis=0)
        o = o @ self.inv[:3, :3].T + self.inv[:3, 3]
        d = d @ self.inv[:3, :3].T
        hits = self.caster.first_hits(o, d).points
        return hits @ self.A[:3, :3].T + self.A[:3, 3]

    def one(self, origin, direction, what: str) -> np.ndarray:
        hit = self(origin, direction)[0]
        if not np.isfinite(hit).all():
            raise RuntimeError(f"landmark construction failed: no surface hit for {what}")
        return hit


_X, _Y, _Z = np.eye(3)


def _scan(rays: _Rays, start, step, n: int, direction) -> np.ndarray:
    """Hits of ``n`` parallel rays whose origins step from ``start`` by ``step``."""
    origins = np.asarray(start, float) + np.arange(n)[:, None] * np.asarray(step, float)
    return rays(origins, direction)


def _pick(hits: np.ndarray, key, what: str, mask=None) -> np.ndarray:
    ok = np.isfinite(hits).all(axis=1) if mask is None else np.isfinite(hits).all(axis=1) & mask
    if not ok.any():
        raise RuntimeError(f"landmark construction failed: no surface hit for {what}")
    idx = np.flatnonzero(ok)
    return hits[idx[int(np.argmax(key(hits[idx])))]]


def _profile(rays: _Rays, y0: float, y1: float, x: float = 0.0, step: float = 0.1) -> np.ndarray:
    """Hits of rays along -z (from the front) at heights ``y0 .. y1``."""
    n = int(abs(y1 - y0) / step) + 1
    return _scan(rays, (x, y0, 400.0), (0.0, np.sign(y1 - y0) * step, 0.0), n, -_Z)


def _behind(q: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """How far the midline points ``q`` lie behind the profile chord ``a``-``b`` (mm)."""
    d = (b - a)[1:] / np.linalg.norm((b - a)[1:])
    rel = q[:, 1:] - a[1:]
    return -(rel[:, 1] * d[0] - rel[:, 0] * d[1]) * np.sign(d[0])


def _orbit_edge(rays: _Rays, oc, frame, u: float, sign: float) -> np.ndarray:
    """Margin point of the orbital opening above (sign +1) or below (-1) the centre at offset ``u``."""
    e1, e2, e3 = frame
    hits = _scan(rays, oc + u * e1 + 8.0 * e3, sign * 0.1 * e2, 320, -e3)
    depth = (hits - oc) @ e3
    shallow = np.isfinite(depth) & (depth > -6.0)
    first = int(np.argmax(shallow)) if shallow.any() else None
    if first is None or first == 0:
        raise RuntimeError("landmark construction failed: orbital margin not found")
    return hits[first]


def _place_left(cr: _Rays, md: _Rays, h: dict) -> dict:
    """Midline and left-side landmarks: code -> (position, part, construction)."""
    out: dict = {}
    put = lambda code, q, part, how: out.__setitem__(code, (np.asarray(q, float), part, how))  # noqa: E731
    # --- midline profile of the cranium
    gl = h["glabella"]
    g = _pick(_profile(cr, gl[1] - 10, gl[1] + 15), lambda q: q[:, 2], "g")
    put("g", g, "cranium", "most anterior point of the midline profile between the brows")
    put("sg", cr.one((0, g[1] + 10, 400), -_Z, "sg"), "cranium", "midline profile 10 mm above glabella")
    prof = _profile(cr, g[1], g[1] - 45)
    z = prof[:, 2]
    deep = ~np.isfinite(z) | (np.r_[z[0], z[:-1]] - z > 6.0)  # the profile drops into the aperture
    i_rhi = int(np.argmax(deep)) - 1
    rhi = prof[i_rhi]
    n = _pick(prof[: i_rhi + 1], lambda q: _behind(q, g, rhi), "n")
    put("n", n, "cranium", "deepest point of the midline profile behind the chord glabella-rhinion")
    put("rhi", rhi, "cranium", "lowest midline point of the nasal bones (profile drops into the aperture)")
    put("mn", cr.one((0, 0.5 * (n[1] + rhi[1]), 400), -_Z, "mn"), "cranium", "midline profile halfway between n and rhi")
    ans = _pick(_profile(cr, h["ans_y"] - 5, h["ans_y"] + 5), lambda q: q[:, 2], "ans")
    put("ans", ans, "cranium", "most anterior point of the anterior nasal spine")
    low = _profile(cr, ans[1] - 2, h["upper_crest_y"] - 6)
    front = np.isfinite(low).all(axis=1) & (low[:, 2] > ans[2] - 25)
    pr = low[np.flatnonzero(front)[-1]]
    ss = _pick(low[: np.flatnonzero(front)[-1]], lambda q: _behind(q, ans, pr), "ss")
    put("ss", ss, "cranium", "deepest midline point of the profile behind the line ans-pr")
    put("pr", pr, "cranium", "lowest point of the midline alveolar profile (between the upper central incisors)")
    put("mp", cr.one((0, 0.5 * (ss[1] + pr[1]), 400), -_Z, "mp"), "cranium", "midline profile halfway between ss and pr")
    v = _pick(_scan(cr, (0, 400, -60), (0, 0, 0.25), 480, -_Y), lambda q: q[:, 1], "v")
    put("v", v, "cranium", "highest midline point of the vault (FH orientation)")
    tilt = np.radians(10.0)
    put("b", cr.one((0, 0, 0), (0, np.cos(tilt), np.sin(tilt)), "b"), "cranium",
        "midline vault point 10 deg forward of vertical from the porion midpoint (no sutures modelled)")
    ang = np.radians(np.arange(-60.0, 60.0, 0.25))
    back = cr((0.0, 30.0, -20.0), np.column_stack([0 * ang, np.sin(ang), -np.cos(ang)]))
    op = _pick(back, lambda q: np.linalg.norm(q - g, axis=1), "op")
    put("op", op, "cranium", "midline point farthest from glabella")
    fm = h["foramen_magnum"]
    col = _scan(cr, (0, -300, fm[1]), (0, 0, 0.1), int((fm[2] + 8) / 0.1), _Y)
    outside = np.isfinite(col[:, 1]) & (col[:, 1] < fm[0] + 0.5 * fm[3])
    put("ba", col[int(np.argmax(outside))], "cranium", "anterior rim of the foramen magnum in the midline")
    # --- midline of the mandible
    id_ = _pick(_profile(md, h["lower_crest_y"] + 6, h["lower_crest_y"] - 8),
                lambda q: np.where(q[:, 2] > 60, q[:, 1], -1e9), "id")
    put("id", id_, "mandible", "highest point of the midline lower alveolar profile")
    me = _pick(_scan(md, (0, -300, 50), (0, 0, 0.2), 250, _Y), lambda q: -q[:, 1], "me")
    put("me", me, "mandible", "lowest midline point of the symphysis")
    pg = _pick(_profile(md, me[1] + 3, id_[1] - 10), lambda q: q[:, 2], "pg")
    put("pg", pg, "mandible", "most anterior midline point of the chin")
    alv = _pick(_profile(md, id_[1] - 14, id_[1] - 1), lambda q: q[:, 2], "sm")  # alveolar convexity
    put("sm", _pick(_profile(md, pg[1], alv[1]), lambda q: _behind(q, alv, pg), "sm"), "mandible",
        "deepest midline point of the concavity between the alveolar convexity below id and pg")
    put("gn", md.one((0, pg[1], me[2]), (0, -1, 1), "gn"), "mandible",
        "chin outline on the bisector between the facial profile and the lower border")
    # --- orbit
    oc, frame = h["orbit_centre"], h["orbit_frame"]
    e1, e2, e3 = frame
    put("mso_l", _orbit_edge(cr, oc, frame, 0.0, 1.0), "cranium", "upper orbital margin on the orbit's vertical bisector")
    put("mio_l", _orbit_edge(cr, oc, frame, 0.0, -1.0), "cranium", "lower orbital margin on the orbit's vertical bisector")
    lows = np.array([_orbit_edge(cr, oc, frame, u, -1.0) for u in np.arange(-14.0, 14.5, 0.5)])
    put("or_l", lows[np.argmin(lows[:, 1])], "cranium", "lowest point of the lower orbital margin")
    ec = cr.one(oc, e1, "ec")
    put("ec_l", ec, "cranium", "lateral orbital margin on the orbit's horizontal bisector")
    put("d_l", cr.one(oc - 5 * e3 + 6 * e2, -e1, "d"), "cranium", "medial orbital wall, 5 mm inside the opening, 6 mm above its centre")
    put("lo_l", cr.one(ec + (30, -10, 30), (-1, 0, -1), "lo"), "cranium", "zygomatic bone 10 mm below ec")
    put("im_l", cr.one((ec[0] - 10, out["or_l"][0][1] - 22, 400), -_Z, "im"), "cranium",
        "front of the zygomaxillary junction, 22 mm below orbitale")
    put("fe_l", cr.one((28.0, g[1] + 32, 400), -_Z, "fe"), "cranium", "frontal bone 28 mm lateral, 32 mm above glabella")
    # --- lateral face and temporal bone
    yy, zz = np.meshgrid(np.arange(-12.0, 6.0, 0.5), np.arange(10.0, 55.0, 0.5), indexing="ij")
    grid = np.column_stack([np.full(yy.size, 300.0), yy.ravel(), zz.ravel()])
    put("zy_l", _pick(cr(grid, -_X), lambda q: q[:, 0], "zy"), "cranium", "most lateral point of the zygomatic arch")
    yy, zz = np.meshgrid(np.arange(-26.0, -10.0, 0.5), np.arange(-25.0, 0.0, 0.5), indexing="ij")
    grid = np.column_stack([np.full(yy.size, 300.0), yy.ravel(), zz.ravel()])
    put("ms_l", _pick(cr(grid, -_X), lambda q: q[:, 0], "ms"), "cranium", "most lateral point of the mastoid process")
    put("sgl_l", cr.one((300, 6.0, 10.0), -_X, "sgl"), "cranium", "zygomatic root 6 mm above and 10 mm in front of porion")
    xs = cr.one((300, h["canal"][0] + h["canal"][2] + 3.0, h["canal"][1]), -_X, "po")[0]
    put("po_l", cr.one((xs - 2.0, h["canal"][0], h["canal"][1]), _Y, "po"), "cranium",
        "roof of the ear canal 2 mm inside its opening")
    # --- nasal aperture and alveolar processes
    y0, y1 = h["ans_y"] + 3.0, h["rhinion_y"] - 3.0
    aps = _scan(cr, (1.5, y0, h["aperture_z"]), (0, 0.25, 0), int((y1 - y0) / 0.25), _X)
    apl = _pick(aps, lambda q: q[:, 0], "apl", mask=aps[:, 0] < 25)
    put("apl_l", apl, "cranium", "most lateral point of the piriform aperture margin")
    put("ac_l", cr.one((apl[0] + 5, apl[1], 400), -_Z, "ac"), "cranium", "maxilla 5 mm lateral of apl")
    t = h["teeth"]
    uc, lc, um2, lm2 = t["U_C_l"], t["L_C_l"], t["U_M2_l"], t["L_M2_l"]
    put("sC_l", cr.one(uc.cej + 4 * uc.axis + 25 * uc.buccal, -uc.buccal, "sC"), "cranium",
        "alveolar bone over the upper canine root, 4 mm above its CEJ")
    put("iC_l", md.one(lc.cej + 4 * lc.axis + 25 * lc.buccal, -lc.buccal, "iC"), "mandible",
        "alveolar bone over the lower canine root, 4 mm below its CEJ")
    put("ecm2s_l", cr.one((300, um2.cej[1] + 2.5, um2.cej[2]), -_X, "ecm2s"), "cranium",
        "buccal alveolar margin at the upper second molar")
    put("ecm2i_l", md.one((300, lm2.cej[1] - 2.5, lm2.cej[2]), -_X, "ecm2i"), "mandible",
        "buccal alveolar margin at the lower second molar")
    _place_ramus(md, h, put, out)
    return out


def _place_ramus(md: _Rays, h: dict, put, out: dict) -> None:
    """Ramus, angle and lower-border landmarks of the left side."""

    def breadth(y):  # rearmost contiguous run of lateral hits = the ramus at height y
        hits = _scan(md, (300, y, -10.0), (0, 0, 0.25), 240, -_X)
        idx = np.flatnonzero(np.isfinite(hits[:, 0]) & (hits[:, 0] > h["ramus_x"] - 6.0))
        gaps = np.flatnonzero(np.diff(idx) > 1)
        return hits[idx[0]], hits[idx[gaps[0]] if len(gaps) else idx[-1]]

    ys = np.arange(-50.0, -30.0, 1.0)
    spans = [breadth(y) for y in ys]
    widths = [b[2] - a[2] for a, b in spans]
    a, b = spans[int(np.argmin(widths))]
    y_mr = a[1]
    put("mr_l", md.one((300, y_mr, 0.5 * (a[2] + b[2])), -_X, "mr"), "mandible",
        "middle of the narrowest ramus breadth")
    a, b = breadth(h["ramus_occlusal_y"])
    put("ol_l", md.one((300, a[1], 0.5 * (a[2] + b[2])), -_X, "ol"), "mandible",
        "middle of the ramus breadth at the occlusal plane")
    # lower border profile (lowest points) and posterior border profile (rearmost points)
    zs = np.arange(-5.0, 70.0, 0.5)
    xs = np.arange(0.0, 56.0, 1.0)
    xx, zz = np.meshgrid(xs, zs, indexing="ij")
    low = md(np.column_stack([xx.ravel(), np.full(xx.size, -300.0), zz.ravel()]), _Y).reshape(len(xs), len(zs), 3)
    lowy = np.where(np.isfinite(low[..., 1]), low[..., 1], np.inf)
    border = low[np.argmin(lowy, axis=0), np.arange(len(zs))]
    yb = np.arange(-62.0, -20.0, 0.5)
    xx, yy = np.meshgrid(np.arange(36.0, 56.0, 1.0), yb, indexing="ij")
    rear = md(np.column_stack([xx.ravel(), yy.ravel(), np.full(xx.size, -300.0)]), _Z).reshape(xx.shape + (3,))
    rearz = np.where(np.isfinite(rear[..., 2]), rear[..., 2], np.inf)
    post = rear[np.argmin(rearz, axis=0), np.arange(len(yb))]
    me = out["me"][0]
    top = post[-1]
    ok = np.isfinite(border).all(axis=1) & (border[:, 2] < np.nanmin(post[:, 2]) + 15.0)
    tb = border[np.flatnonzero(ok)[np.argmin(border[ok, 1])]]  # lowest point of the angle region
    ok = np.isfinite(post).all(axis=1) & (post[:, 1] < -40.0)
    s2 = (post[:, 2] - top[2]) / np.maximum(top[1] - post[:, 1], 1e-6)
    tr = post[np.flatnonzero(ok)[np.argmin(s2[ok])]]  # tangent point of the ramus line
    d1 = (me - tb)[1:] / np.linalg.norm((me - tb)[1:])  # (y, z) along the lower border, forward
    d2 = (top - tr)[1:] / np.linalg.norm((top - tr)[1:])  # up the ramus
    mat = np.column_stack([d1, -d2])
    s = np.linalg.solve(mat, (tr - tb)[1:])
    vertex = tb[1:] + s[0] * d1
    bis = d1 + d2
    edge = md.one((tb[0], vertex[0], vertex[1]), (0, bis[0], bis[1]), "go")
    inward = 2.5 * bis / np.linalg.norm(bis)
    go = md.one((300.0, edge[1] + inward[0], edge[2] + inward[1]), -_X, "go")
    put("go_l", go, "mandible", "lateral surface of the angle, 2.5 mm inside the point where the bisector "
        "of the ramus line and the mandibular line (menton to the lowest point of the angle) meets the border")
    pg = out["pg"][0]
    zm = 0.5 * (go[2] + pg[2])
    put("mmb_l", border[int(np.argmin(np.abs(zs - zm)))], "mandible",
        "lowest point of the lower border halfway between gonion and pogonion")


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

    def __init__(self, rigid: np.ndarray, scale_xz=(1.0, 1.0), y_face: float = 1.0, y_vault: float = 1.0,
                 y_range=(-20.0, 40.0)):
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
    return Tooth(t.code, t.jaw, t.name, t.side, f(t.tip), f.direction(t.tip, t.axis),
                 f.direction(t.tip, t.mesial), f.direction(t.tip, t.buccal),
                 f.length(t.tip, t.axis, t.crown), f.length(t.cej, t.axis, t.root),
                 f.length(t.tip, t.mesial, t.md), f.length(t.cej, t.mesial, t.md_cervix),
                 f.length(t.tip, t.buccal, t.ll), f.length(t.cej, t.buccal, t.ll_cervix))


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
    y_occ = tp["occlusal_y_incisor"] + (tp["occlusal_z_incisor"] - z_ramus) * np.tan(np.radians(tp["occlusal_plane_deg"]))
    return {
        "glabella": f(p["glabella"]["centre"]),
        "rhinion_y": f((0, max(q[1] for q in p["nasal_aperture"]["outline"]), 90))[1],
        "ans_y": f(p["ans"]["b"])[1],
        "upper_crest_y": (ui.cej + p["upper_alveolus"]["crest_above_cej"] * ui.axis)[1],
        "lower_crest_y": (li.cej + p["mandible"]["body"]["crest_below_cej"] * li.axis)[1],
        "foramen_magnum": (fmc[1], fmc[2], f.length(fm["centre"], _Z, fm["radii"][2]),
                           f.length(fm["centre"], _Y, fm["radii"][1])),
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
    orb = min((_orbit_edge(rays, oc, frame, u, -1.0) for u in np.arange(-14.0, 14.5, 0.5)),
              key=lambda q: q[1])
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
    cr = S.mesh_from_field(*cgrid.full(), cgrid.h, smooth=6, target=p["triangles"]["cranium"], blur=0.6)
    md = S.mesh_from_field(*mgrid.full(), mgrid.h, smooth=6, target=p["triangles"]["mandible"], blur=0.6)
    upper, lower = teeth_mesh(teeth, "U"), teeth_mesh(teeth, "L")
    tongue = tongue_mesh(teeth, avoid=mgrid.sample)
    tooth_map = {t.code: t for t in teeth}
    casters = {"cranium": _Rays(cr), "mandible": _Rays(md)}
    sc = p["_scale"]
    fmap = _Map(_frankfort_correction(casters["cranium"], p, tooth_map), (sc["x"], sc["z"]),
                sc["y_face"], sc["y_vault"])
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
    placed, normals = dict(left), {}
    for part, mesh in meshes.items():
        codes = [c for c in left if left[c][1] == part]
        normals.update(zip(codes, normals_within_radius(mesh, np.array([left[c][0] for c in codes]), 5.0)))
    for code, (q, part, how) in left.items():
        if code.endswith("_l"):
            right = _mirror_landmark(rays[part], meshes[part], q, normals[code])
            placed[code[:-2] + "_r"] = (right, part, how + " (mirror of the left point)")
    for part, mesh in meshes.items():
        codes = [c for c in placed if c.endswith("_r") and placed[c][1] == part]
        normals.update(zip(codes, normals_within_radius(mesh, np.array([placed[c][0] for c in codes]), 5.0)))
    catalogue = _skull_codes()
    not_rep = {c: "no geometric construction for this code" for c in catalogue if c not in placed}
    order = [c for c in catalogue if c in placed] + sorted(c for c in placed if c not in catalogue)
    landmarks = LandmarkSet("skull", tuple(Landmark(c, placed[c][0], "placed", 1.0, f"{placed[c][1]}: {placed[c][2]}")
                                           for c in order))
    # eyes: centred on the orbital opening; corneal apex `tangent_offset` mm in front of the
    # mso-mio tangent (Stephan 2002: the tangent rule under-predicts projection by ~4 mm)
    e = p["eye"]
    med = rays["cranium"].one(h["orbit_centre"], -h["orbit_frame"][0], "medial orbital margin")
    ec, mso, mio = placed["ec_l"][0], placed["mso_l"][0], placed["mio_l"][0]
    apex_z = 0.5 * (mso[2] + mio[2]) + e["tangent_offset_mm"]
    centre_l = np.array([0.5 * (med[0] + ec[0]), 0.5 * (mso[1] + mio[1]),
                         apex_z - corneal_apex_offset(e["radius"], e["cornea_radius"], e["limbus_radius"])])
    centres = np.array([centre_l, centre_l * [-1.0, 1.0, 1.0]])
    globes = [eyeball_mesh(c, e["radius"], (0.0, 0.0, 1.0), e["cornea_radius"], e["limbus_radius"]) for c in centres]
    eyes = Mesh(np.vstack([g.vertices for g in globes]),
                np.vstack([globes[0].faces, globes[1].faces + globes[0].n_vertices]))
    cond = fmap(np.array([p["mandible"]["condyle"]["centre"], np.multiply(p["mandible"]["condyle"]["centre"], [-1, 1, 1])]))
    tmj = (0.5 * (cond[0] + cond[1]), _unit(cond[0] - cond[1]))
    params = json.loads(json.dumps(p))
    params["frame_correction"] = fmap.A.tolist()
    params["eye_rule"] = (
        "globe (radius %.1f mm) centred on the orbital opening: x midway between the medial orbital "
        "margin and ectoconchion, y midway between mso and mio; corneal apex %.1f mm anterior to the "
        "mso-mio tangent (Stephan 2002 found the tangent rule under-predicts globe projection by 4 mm "
        "on average); this puts the apex %.1f mm in front of ectoconchion"
        % (e["radius"], e["tangent_offset_mm"], apex_z - ec[2]))
    params["corneal_apex_anterior_to_ec_mm"] = float(apex_z - ec[2])
    template = SkullTemplate(sex, cr, md, upper, lower, eyes, centres, float(e["radius"]), tongue,
                             tuple(tooth_map[k] for k in sorted(tooth_map)), landmarks,
                             {c: placed[c][1] for c in order}, {c: normals[c] for c in order}, tmj, cond,
                             params, not_rep)
    params["measurements"] = measure(template, rays["cranium"])
    return template


def _skull_codes() -> list[str]:
    import csv

    with open(_data_tables() / "landmarks" / "catalogue.csv", encoding="utf-8", newline="") as fh:
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
        "g_op": dist("g", "op"), "eu_eu": float(upper[:, 0].max() - upper[:, 0].min()),
        "ba_b": dist("ba", "b"), "n_pr": dist("n", "pr"), "n_me": dist("n", "me"),
        "zy_zy": dist("zy_l", "zy_r"), "go_go": dist("go_l", "go_r"),
        "orbit_centre_distance": float(np.linalg.norm(t.eye_centres[0] - t.eye_centres[1])),
        "orbit_width": dist("d_l", "ec_l"), "orbit_height": dist("mso_l", "mio_l"),
        "aperture_width": dist("apl_l", "apl_r"), "aperture_height": float(L["rhi"][1] - sill),
        "porion_below_orbit_centre": float(mid[1] - L["po_l"][1]),
    }
