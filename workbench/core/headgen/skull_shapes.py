"""Signed-distance construction of the reference skull's cranium and mandible.

Shapes are placed from the parameter dictionary of
:func:`workbench.core.headgen.skull.skull_parameters` (mm, head frame: x to
the subject's left, y up, z forward).  Split out of
:mod:`workbench.core.headgen.skull`.
"""

from __future__ import annotations

from typing import overload

import numpy as np

from workbench.core.headgen import sdf as S  # noqa: N812 - S.sphere(...) reads as the SDF algebra
from workbench.core.headgen.teeth import Tooth


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
    ring = np.column_stack(
        [np.asarray(r["outline"], float) - [org[2], org[1]], np.zeros(len(r["outline"]))]
    )
    outline = S.resample(ring, step=1.0, closed=True)[0][:, :2]  # rounded corners
    ramus = S.Extrusion(
        S.Profile2D(outline),
        org,
        frame,
        (r["half_thickness"], r["half_thickness"]),
        round_mm=r["round"],
    )
    g.union(ramus)
    ridge = r[
        "posterior_ridge"
    ]  # the thick, rounded posterior border and angle, in the plate's plane
    zy = np.asarray(ridge["curve_zy"], float)
    curve = np.array(
        [
            org + a * fwd + b * up
            for a, b in np.linalg.solve(
                np.stack([fwd[[2, 1]], up[[2, 1]]], axis=1), (zy - org[[2, 1]]).T
            ).T
        ]
    )
    g.union(_sweep(curve, ridge["radii"], up=frame[2]), k=2.0)
    g.union(_ell(m["condyle"]), k=3.0)
    c = m["condyle"]["centre"]
    g.union(
        S.RoundCone((c[0] - 2, c[1] - 3, c[2] - 1), (org[0] + 1.0, c[1] - 16, c[2] - 3), 4.5, 4.0),
        k=3.0,
    )
    # body: a band lofted between the alveolar crest (top) and the lower border (bottom)
    b = m["body"]
    lower = sorted((t for t in teeth if t.jaw == "L" and t.side == "l"), key=lambda t: -t.tip[2])
    tops = [t.cej + b["crest_below_cej"] * t.axis for t in lower]
    tops = (
        [np.array([0.0, tops[0][1], tops[0][2]])] + tops + [np.asarray(q, float) for q in b["rear"]]
    )
    border = np.asarray(b["lower_border"], float)[::-1]
    centres, ups, radii = [], [], []
    for top, a, flare, lean in zip(tops, b["half_thickness"], b["flare"], b["lean"], strict=False):
        bottom = np.array(
            [top[0] + flare, np.interp(top[2], border[:, 0], border[:, 1]), top[2] - lean]
        )
        centres.append(0.5 * (top + bottom))
        ups.append((top - bottom) / np.linalg.norm(top - bottom))
        radii.append([a, 0.5 * np.linalg.norm(top - bottom)])
    g.union(
        _sweep(
            *_symmetric(np.array(centres), np.array(radii), np.array(ups)), exponent=b["exponent"]
        ),
        k=9.0,
    )
    # keep the crowns clear: nothing of the body above the alveolar crest
    crest_z = np.array([q[2] for q in tops[1:9]])[::-1]
    crest_y = np.array([q[1] for q in tops[1:9]])[::-1]

    def above_crest(x, y, z):
        return np.maximum(
            np.maximum(np.interp(z, crest_z, crest_y) - y, np.abs(x) - 34.0), crest_z[0] - 4.0 - z
        )

    g.subtract(S.Function(above_crest, (-34, -70, crest_z[0] - 4), (34, 0, 110)), k=1.0)
    g.union(_ell(m["chin"]), k=4.0)
    g.union(_ell(m["mental_tubercle"]), k=3.0, bilateral=True)
    return g


# ------------------------------------------------------------------ cranium
def cranium_grid(p: dict, teeth: list[Tooth], mandible: S.Grid) -> S.Grid:
    """Half (x >= 0) distance field of the cranium (skull without the mandible).

    Built in a fixed order of smooth unions and subtractions (the order
    matters: each blend sees the field built so far); grid step ``p["grid_mm"]``.
    """
    h = p["grid_mm"]
    g = S.Grid((-80, -62, -100), (80, 128, 118), h, half=True)
    _add_vault_and_base(g, p)
    _add_face_blocks(g, p)
    _add_orbits(g, p)
    _add_temporal_region(g, p)
    _add_upper_alveolus(g, p, teeth)
    _add_nasal_region(g, p)
    # keep clear of the mandible (this hollows the glenoid fossae)
    _subtract_grid(g, mandible, p["mandible"]["clearance_mm"], k=1.0)
    return g


def _add_vault_and_base(g: S.Grid, p: dict) -> None:
    """The braincase: tapered parietal vault, frontal bulge, flat base and its blocks (mm)."""
    vp, vf, tp = p["vault_parietal"], p["vault_frontal"], p["vault_taper"]
    par = S.SuperEllipsoid(vp["centre"], vp["radii"], vp.get("exponent", 2.0))

    def ramp(t, w=10.0):  # smooth max(t, 0): no crease on the vault
        return w * np.logaddexp(0.0, t / w)

    def vault(x, y, z):  # parietal vault narrowed toward the front and toward the base
        taper = 1.0 + tp["per_mm"] * ramp(z - tp["z0"]) + tp["low_per_mm"] * ramp(tp["low_y"] - y)
        return par(x * taper, y, z)

    g.union(S.Function(vault, par.lo, par.hi))
    g.union(_ell(vf), k=vf["blend"])
    g.intersect(
        S.Function(
            lambda x, y, z: p["base_floor_y"] - y + 0 * x + 0 * z, (-99, -99, -99), (99, 99, 99)
        ),
        k=6.0,
    )
    g.union(_ell(p["base_block"]), k=8.0)
    g.union(_ell(p["sphenoid_block"]), k=8.0)
    g.union(_ell(p["occipital_protuberance"]), k=4.0)


def _add_face_blocks(g: S.Grid, p: dict) -> None:
    """Bulk of the face: orbit surroundings, nasal root, maxillae, zygomas and brows (mm)."""
    oc, orot = orbit_frame(p)
    g.union(
        S.Ellipsoid(oc + np.array([0.0, -1.0, -16.0]), (24, 22, 16), orot), k=6.0, bilateral=True
    )
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


def _add_orbits(g: S.Grid, p: dict) -> None:
    """Orbital rims, then the orbital openings and cavities cut along the orbit frame's normal."""
    oc, orot = orbit_frame(p)
    o = p["orbit"]
    rim3 = np.array(
        [
            oc + u * orot[0] + v * orot[1] - o["rim_back"] * orot[2]
            for u, v in orbit_outline(p, o["rim_scale"], 48)
        ]
    )
    g.union(
        _sweep(rim3, [[o["rim_radius"]] * 2] * len(rim3), up=orot[2], closed=True),
        k=2.5,
        bilateral=True,
    )
    prof = S.Profile2D(orbit_outline(p))
    g.subtract(S.Extrusion(prof, oc, orot, (20.0, 10.0)), k=1.5, bilateral=True)
    g.subtract(
        S.Extrusion(
            S.Profile2D(orbit_outline(p, 1.04)),
            oc - 6.0 * orot[2],
            orot,
            (0.0, o["depth"] - 6.0),
            taper=o["taper"],
        ),
        k=3.0,
        bilateral=True,
    )


def _add_temporal_region(g: S.Grid, p: dict) -> None:
    """Temporal fossa and zygomatic arch, then the temporal bone: ear canal, mastoid, glenoid."""
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
    g.subtract(
        S.RoundCone(
            (80, ec["centre_y"], ec["centre_z"]),
            (ec["x_in"], ec["centre_y"], ec["centre_z"]),
            ec["radius"],
        ),
        k=1.0,
        bilateral=True,
    )
    g.union(_ell(p["occipital_condyle"]), k=3.0, bilateral=True)
    g.subtract(_ell(p["foramen_magnum"]), k=2.0)


def _add_upper_alveolus(g: S.Grid, p: dict, teeth: list[Tooth]) -> None:
    """Upper alveolar process around the left upper teeth and the palate, trimmed to the crowns.

    The process is swept through points half a root length above each tooth's
    cemento-enamel junction and continued through its mirror image (mm).
    """
    upper = sorted((t for t in teeth if t.jaw == "U" and t.side == "l"), key=lambda t: -t.tip[2])
    ua = p["upper_alveolus"]
    crest = np.array([t.cej + ua["crest_above_cej"] * t.axis for t in upper])
    alv = np.array([t.cej + 0.5 * t.root * t.axis for t in upper])
    pts = np.vstack([[0.0, alv[0, 1], alv[0, 2]], alv, alv[-1] + [1.0, 2.0, -8.0]])  # + tuberosity
    extra = np.interp(
        np.arange(len(upper) + 2),
        [0, 2, 4],
        [ua["bone_over_incisors"]] * 2 + [ua["bone_over_root"]],
    )
    half_ll = (
        np.array([0.5 * upper[0].ll_cervix] + [0.5 * t.ll_cervix for t in upper] + [3.0]) + extra
    )
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

    g.subtract(
        S.Function(envelope, (-45, -75, cz[0] - 4.0), (45, cy.max() + env_h + 6, 115)), k=3.0
    )
    g.union(alveolus, k=4.0)  # fillet the crease the trim leaves above the alveolar process
    # keep the crowns clear: nothing of the maxilla below the alveolar crest

    def below_crest(x, y, z):
        return np.maximum(y - np.interp(z, cz, cy) + 0 * x, cz[0] - 6.0 - z)

    g.subtract(S.Function(below_crest, (-45, -75, cz[0] - 6.0), (45, cy.max() + 1, 115)), k=1.0)


def _add_nasal_region(g: S.Grid, p: dict) -> None:
    """Nasal bones, piriform rim and aperture, nasal cavity, septum, conchae and spine (mm)."""
    na = p["nasal_aperture"]
    half = np.asarray(na["outline"], float)
    outline = np.vstack([half, half[-2:0:-1] * [-1, 1]])
    nb = p["nasal_bones"]
    g.union(_sweep(nb["curve"], nb["radii"], up=(0.0, 0.0, 1.0)), k=4.0)
    pr = p["piriform_rim"]
    rim = np.column_stack([outline * pr["scale"], pr["z"] + pr["tilt"] * (outline[:, 1] + 14.0)])
    g.union(
        _sweep(rim[::2], [[pr["radius"]] * 2] * len(rim[::2]), up=(0.0, 0.0, 1.0), closed=True),
        k=pr["blend"],
    )
    g.subtract(
        S.Extrusion(
            S.Profile2D(outline),
            (0, 0, na["origin_z"]),
            np.eye(3),
            (20.0, na["depth"]),
            taper=na["taper"],
            round_mm=na["round"],
        ),
        k=1.5,
    )
    g.subtract(_ell(p["nasal_cavity"]), k=3.0)
    g.union(S.Box(p["septum"]["centre"], p["septum"]["half"], round_mm=0.8), k=1.0)
    g.union(_ell(p["concha"]), k=2.0, bilateral=True)
    g.union(S.RoundCone(**_cone(p["ans"])), k=2.0)


@overload
def _symmetric(points: np.ndarray, radii: np.ndarray) -> tuple[np.ndarray, np.ndarray]: ...
@overload
def _symmetric(
    points: np.ndarray, radii: np.ndarray, ups: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]: ...
def _symmetric(
    points: np.ndarray, radii: np.ndarray, ups: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray] | tuple[np.ndarray, np.ndarray, np.ndarray]:
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
    hi = np.minimum(
        g.origin + g.h * (np.array(g.shape) - 1),
        other.origin + other.h * (np.array(other.shape) - 1),
    )
    if g.half:
        lo[0] = max(lo[0], 0.0)
    i0 = np.ceil((lo - g.origin) / g.h - 1e-6).astype(int)
    i1 = np.floor((hi - g.origin) / g.h + 1e-6).astype(int) + 1
    axes = [g.origin[d] + g.h * np.arange(i0[d], i1[d]) for d in range(3)]
    pts = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    d = other.sample(pts).reshape([len(a) for a in axes]) - clearance
    sl = tuple(slice(a, b) for a, b in zip(i0, i1, strict=False))
    g.field[sl] = S.smax(g.field[sl], -d.astype(np.float32), k)
