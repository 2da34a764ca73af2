"""Assemble the half-head control mesh (x >= 0) from ring systems + Delaunay fill."""
from __future__ import annotations

import numpy as np
from matplotlib.path import Path
from scipy.spatial import Delaunay, cKDTree

import geom
import headsdf as H
import layout


def smoothstep(e0, e1, x):
    t = np.clip((x - e0) / (e1 - e0), 0.0, 1.0)
    return t * t * (3 - 2 * t)


def sizing(p):
    """Target control-mesh edge length (mm)."""
    p = np.atleast_2d(p)
    x, y, z = np.abs(p[:, 0]), p[:, 1], p[:, 2]
    face = smoothstep(15, 45, z) * smoothstep(-118, -100, y) * (1 - smoothstep(48, 66, y)) * (1 - smoothstep(50, 66, x))
    fore = smoothstep(10, 40, z) * (1 - smoothstep(70, 100, y))
    h = 20.0 - 7.0 * fore
    h = h * (1 - face) + 7.2 * face
    # nose base, alae and columella: finer
    u = ((x - 10.0) / 16.0) ** 2 + ((y + 22.0) / 10.0) ** 2 + ((z - 92.0) / 14.0) ** 2
    h = np.where(u < 1.0, np.minimum(h, 4.6 + 2.6 * u), h)
    # neck and below-ear region medium
    return h


class Builder:
    def __init__(self):
        self.P = []        # positions
        self.V = []        # chart-virtual positions (for Delaunay); None -> same as P
        self.names = {}    # name -> vertex id
        self.kind = []     # 'sdf' | 'explicit' | 'midline'
        self.region = []
        self.faces = []
        self.systems = []  # (outer ring ids, hole polygon in chart)
        self.labels = []   # region label per structured face

    def add(self, p, kind, region, virt=None, name=None):
        i = len(self.P)
        self.P.append(np.asarray(p, float))
        self.V.append(np.asarray(virt if virt is not None else p, float))
        self.kind.append(kind)
        self.region.append(region)
        if name:
            self.names[name] = i
        return i

    def add_ring(self, pts, kind, region, virt=None):
        ids = []
        for j, p in enumerate(pts):
            ids.append(self.add(p, kind, region, None if virt is None else virt[j]))
        return np.array(ids)

    # strips ------------------------------------------------------------------
    def strip(self, a, b, closed, label="face"):
        """Triangulate between rings a and b (vertex id arrays) by zipper on normalised parameter."""
        A = np.asarray(a)
        B = np.asarray(b)
        if closed:
            A = np.append(A, A[0])
            B = np.append(B, B[0])
        ta = np.linspace(0, 1, len(A))
        tb = np.linspace(0, 1, len(B))
        i = j = 0
        tris = []
        while i < len(A) - 1 or j < len(B) - 1:
            if i == len(A) - 1:
                adv_a = False
            elif j == len(B) - 1:
                adv_a = True
            else:
                adv_a = ta[i + 1] <= tb[j + 1] if abs(ta[i + 1] - tb[j + 1]) > 1e-9 else (i <= j)
            if adv_a:
                tris.append((A[i], A[i + 1], B[j]))
                i += 1
            else:
                tris.append((A[i], B[j + 1], B[j]))
                j += 1
        self.faces.extend(tris)
        self.labels.extend([label] * len(tris))

    def fan(self, ring, c, label="face"):
        r = list(ring) + [ring[0]]
        for k in range(len(ring)):
            self.faces.append((r[k], r[k + 1], c))
            self.labels.append(label)


def hole_polygon_closed(chart_pts):
    return Path(np.vstack([chart_pts, chart_pts[:1]]))


def hole_polygon_midline(chart_pts, through_angle=None):
    """Open half-loop with both ends on the unit circle: close it along the circle.

    through_angle: chart angle the closing arc must pass (chooses the arc direction)."""
    a0 = np.arctan2(chart_pts[-1, 1], chart_pts[-1, 0])
    a1 = np.arctan2(chart_pts[0, 1], chart_pts[0, 0])
    # two candidate arcs from a0 to a1
    def arc(a_start, a_end, ccw):
        if ccw:
            while a_end < a_start:
                a_end += 2 * np.pi
        else:
            while a_end > a_start:
                a_end -= 2 * np.pi
        t = np.linspace(a_start, a_end, 60)
        return np.stack([np.cos(t), np.sin(t)], 1) * 1.02, t
    arc1, t1 = arc(a0, a1, True)
    arc2, t2 = arc(a0, a1, False)
    if through_angle is None:
        use = arc1 if abs(t1[-1] - t1[0]) < abs(t2[-1] - t2[0]) else arc2
    else:
        def passes(t):
            tt = np.mod(t - through_angle + np.pi, 2 * np.pi) - np.pi
            return np.any(np.abs(tt) < 0.05)
        use = arc1 if passes(t1) else arc2
    return Path(np.vstack([chart_pts, use, chart_pts[:1]]))


# ---------------------------------------------------------------------------- landmarks
def profile_landmarks(prof):
    y, z = prof[:, 1], prof[:, 2]

    def pick(mask, arr, fn):
        i = np.nonzero(mask)[0]
        return int(i[fn(arr[i])])
    L = {}
    L["v"] = pick(np.ones(len(y), bool), y, np.argmax)
    L["op"] = pick((y > -40) & (z < 0), z, np.argmin)
    L["g"] = pick((y > 32) & (y < 60) & (z > 0), z, np.argmax)
    L["se"] = pick((y > 12) & (y < 38) & (z > 0), z, np.argmin)
    L["prn"] = pick((y > -30) & (y < 10) & (z > 0), z, np.argmax)
    L["pg"] = pick((y > -95) & (y < -72) & (z > 0), z, np.argmax)
    L["me"] = pick((z > y[L["pg"]] * 0 + z[L["pg"]] - 24) & (y < y[L["pg"]]), y, np.argmin)
    # sl: deepest point between the lower lip and pg
    L["sl"] = pick((y > -75) & (y < -60) & (z > 0), z, np.argmin)
    # sn: deepest point behind the line prn - upper lip (y -40)
    ip = L["prn"]
    lip = pick((y > -44) & (y < -36) & (z > 0), z, np.argmax)
    a, b = prof[ip], prof[lip]
    idx = np.arange(min(ip, lip), max(ip, lip) + 1)
    ab = (b - a) / np.linalg.norm(b - a)
    rel = prof[idx] - a
    dist = np.abs(rel[:, 1] * ab[2] - rel[:, 2] * ab[1])
    L["sn"] = int(idx[np.argmax(dist)])
    # c: most convex point of the lobule/columella outline between prn and sn
    a, b = prof[L["prn"]], prof[L["sn"]]
    idx = np.arange(min(L["prn"], L["sn"]), max(L["prn"], L["sn"]) + 1)
    ab = (b - a) / np.linalg.norm(b - a)
    rel = prof[idx] - a
    dist = rel[:, 1] * ab[2] - rel[:, 2] * ab[1]
    L["c"] = int(idx[np.argmax(np.abs(dist))])
    pos = {k: prof[i].copy() for k, i in L.items()}
    idx_of = dict(L)
    # arc-defined points
    seg = np.linalg.norm(np.diff(prof, axis=0), axis=1)
    cum = np.concatenate([[0], np.cumsum(seg)])

    def at_arc(i0, delta):
        s = cum[i0] + delta
        j = int(np.clip(np.searchsorted(cum, s), 1, len(prof) - 1))
        return j
    # profile runs with increasing angle: from the chin (bottom front) up the face to the top and back
    direction_up = 1 if prof[L["g"], 1] > prof[L["prn"], 1] and L["g"] > L["prn"] else -1
    j = at_arc(L["se"], 3.0 * direction_up)
    pos["n"] = prof[j].copy()
    idx_of["n"] = j
    j = at_arc(L["g"], 14.0 * direction_up)
    pos["sg"] = prof[j].copy()
    idx_of["sg"] = j
    # rhinion ~ 21 mm below n along the dorsum, midnasale halfway
    j = at_arc(idx_of["n"], -21.0 * direction_up)
    pos["rhi"] = prof[j].copy()
    idx_of["rhi"] = j
    j = at_arc(idx_of["n"], -10.5 * direction_up)
    pos["mn"] = prof[j].copy()
    idx_of["mn"] = j
    # trichion: forehead height n-tr 62 mm (typical adult male; no hair line on a bald template)
    cand = np.nonzero((prof[:, 1] > pos["n"][1] + 55) & (prof[:, 2] > 0))[0]
    j = int(cand[np.argmin(np.abs(prof[cand, 1] - (pos["n"][1] + 62.0)))])
    pos["tr"] = prof[j].copy()
    idx_of["tr"] = j
    # gn: halfway (arc) between pg and me
    half = 0.5 * (cum[L["pg"]] + cum[L["me"]])
    j = int(np.argmin(np.abs(cum - half)))
    pos["gn"] = prof[j].copy()
    idx_of["gn"] = j
    return pos, idx_of


def max_search(points, key):
    points = points[~np.isnan(points).any(1)]
    return points[np.argmax(key(points))]


def lateral_landmarks():
    L = {}
    # zygion: most lateral point over the arch
    yy, zz = np.meshgrid(np.linspace(-8, 3, 12), np.linspace(18, 35, 18))
    o = np.stack([np.zeros(yy.size), yy.ravel(), zz.ravel()], 1)
    L["zy"] = max_search(geom.rays_hit(o, [[1, 0, 0]], t_max=110, step=0.3), lambda p: p[:, 0])
    # alare: most lateral point of the ala
    yy, zz = np.meshgrid(np.linspace(-25, -15, 11), np.linspace(82, 96, 15))
    o = np.stack([np.zeros(yy.size), yy.ravel(), zz.ravel()], 1)
    hits = geom.rays_hit(o, [[1, 0, 0]], t_max=40, step=0.1, f=H.nose)
    L["al"] = geom.project(max_search(hits, lambda p: p[:, 0]))[0]
    L["go"] = geom.rays_hit([[0, -77.0, 11.0]], [[1, 0, 0]], t_max=110, step=0.3)[0]
    L["ft"] = geom.rays_hit([[0, 50.0, 62.0]], [[1, 0, 0]], t_max=110, step=0.3)[0]
    L["lt"] = geom.rays_hit([[0, 35.0, 20.0]], [[1, 0, 0]], t_max=110, step=0.3)[0]
    L["sgl"] = geom.rays_hit([[0, 14.0, 14.0]], [[1, 0, 0]], t_max=110, step=0.3)[0]
    L["ms"] = geom.rays_hit([[0, -24.0, -21.0]], [[1, 0, 0]], t_max=110, step=0.3)[0]
    L["sM2"] = geom.rays_hit([[0, -40.0, 42.0]], [[1, 0, 0]], t_max=110, step=0.3)[0]
    L["iM2"] = geom.rays_hit([[0, -57.0, 42.0]], [[1, 0, 0]], t_max=110, step=0.3)[0]
    L["ol"] = geom.rays_hit([[0, -47.0, 24.0]], [[1, 0, 0]], t_max=110, step=0.3)[0]
    L["mr"] = geom.rays_hit([[0, -38.0, 12.0]], [[1, 0, 0]], t_max=110, step=0.3)[0]
    L["fe"] = geom.zray(27.0, 68.0)
    L["sci"] = geom.zray(27.0, 40.0)
    L["scl"] = geom.zray(44.4, 37.0)
    L["chk"] = geom.zray(40.0, -13.0)
    L["im"] = geom.zray(46.0, -23.0)
    L["ac"] = geom.zray(15.8, -23.3)
    ys = np.linspace(-21.0, -33.0, 49)
    pz = np.array([geom.zray(9.6, yv) for yv in ys])
    a, b = pz[0], pz[-1]
    ab = (b - a) / np.linalg.norm(b - a)
    rel = pz - a
    dist = rel[:, 1] * ab[2] - rel[:, 2] * ab[1]
    L["sbal"] = pz[np.argmax(np.abs(dist))]
    d = np.array([0.5, -0.83, 0.25])
    L["mmb"] = geom.rays_hit([[22.0, -72.0, 46.0]], [d], t_max=60, step=0.2)[0]
    return {k: np.asarray(v, float) for k, v in L.items()}


# ---------------------------------------------------------------------------- assembly
def nearest_idx(pts, target, mask=None):
    d = np.linalg.norm(pts[:, :2] - np.asarray(target)[:2], axis=1)
    if mask is not None:
        d = np.where(mask, d, np.inf)
    return int(np.argmin(d))


def snap(pts, i, new):
    pts = pts.copy()
    pts[i] = new
    return pts


def assemble(seed=0, n_candidates=60000, relax=3, verbose=True):
    rng = np.random.default_rng(seed)
    B = Builder()
    LM = {}  # landmark code -> vertex id
    ang, prof = geom.midline_profile_fast(3000)
    ppos, pidx = profile_landmarks(prof)
    lat = lateral_landmarks()

    # ---- eye system
    er = layout.eye_rings()
    rings = {n: p.copy() for n, p, k in er}
    kinds = {n: k for n, p, k in er}
    r0 = rings["eye_r0"]
    LM["en"] = ("eye_r0", 0)
    LM["ex"] = ("eye_r0", 8)
    up = np.arange(1, 8)
    lo = np.arange(9, 16)
    LM["ps"] = ("eye_r0", int(up[np.argmax(r0[up, 1])]))
    LM["pi"] = ("eye_r0", int(lo[np.argmin(r0[lo, 1])]))
    r4 = rings["eye_r4"]
    bottom = r4[:, 1] < 8
    i_or = nearest_idx(r4, (36.0, 0.0), bottom)
    r4 = snap(r4, i_or, geom.zray(36.0, 0.0))
    i_mio = nearest_idx(r4, (31.0, 0.5), bottom & (np.arange(len(r4)) != i_or))
    r4 = snap(r4, i_mio, geom.zray(31.0, 0.5))
    top = r4[:, 1] > 20
    i_mso = nearest_idx(r4, (32.5, 33.0), top)
    r4 = snap(r4, i_mso, geom.zray(32.5, r4[i_mso, 1]))
    i_lo = nearest_idx(r4, (50.0, 10.0))
    r4 = snap(r4, i_lo, geom.zray(50.0, 10.0))
    i_mf = nearest_idx(r4, (9.5, 21.0))
    r4 = snap(r4, i_mf, geom.zray(9.5, 21.0))
    rings["eye_r4"] = r4
    LM.update({"or": ("eye_r4", i_or), "mio": ("eye_r4", i_mio), "mso": ("eye_r4", i_mso),
               "lo": ("eye_r4", i_lo), "mf": ("eye_r4", i_mf)})
    ids = {}
    for n in ["eye_r0", "eye_r1", "eye_r2", "eye_r3", "eye_r4"]:
        ids[n] = B.add_ring(rings[n], kinds[n], "eye")
    names = ["eye_r0", "eye_r1", "eye_r2", "eye_r3", "eye_r4"]
    for k, (a, b) in enumerate(zip(names[:-1], names[1:])):
        B.strip(ids[a], ids[b], True, "eyelid" if k < 2 else "orbit")

    # ---- mouth system
    mr = layout.mouth_rings()
    mrings = {n: p.copy() for n, p, k in mr}
    mkinds = {n: k for n, p, k in mr}
    for n in mrings:
        mrings[n][0, 0] = 0.0
        mrings[n][-1, 0] = 0.0
    # snaps on the midline / lateral
    m6 = mrings["mouth_m6"]
    m6[0] = ppos["sn"]
    m5 = mrings["mouth_m5"]
    m5[-1] = ppos["sl"]
    mp = 0.5 * (ppos["sn"] + mrings["mouth_m3"][0])
    m5[0] = geom.zray(0.0, mp[1])
    m5[0, 0] = 0.0
    i_sc = nearest_idx(m5[:8], (17.0, -37.0))
    i_ic = 9 + nearest_idx(m5[9:], (16.0, -64.0))
    m1 = mrings["mouth_m1"]
    i_mlfs = nearest_idx(m1[:6], (12.5, -49.0))
    m3 = mrings["mouth_m3"]
    i_mvs = nearest_idx(m3[:6], (0.5 * (6.5 + 25.0), -44.0))
    LM.update({"sn": ("mouth_m6", 0), "mp": ("mouth_m5", 0), "sl": ("mouth_m5", len(m5) - 1),
               "ls": ("mouth_m3", 0), "li": ("mouth_m3", len(m3) - 1), "cph": ("mouth_m3", 2),
               "mvs": ("mouth_m3", i_mvs), "sts": ("mouth_m1", 0), "sti": ("mouth_m1", len(m1) - 1),
               "ch": ("mouth_m1", 6), "mlfs": ("mouth_m1", i_mlfs), "sC": ("mouth_m5", i_sc),
               "iC": ("mouth_m5", i_ic)})
    mnames = ["mouth_m0", "mouth_m1", "mouth_m2", "mouth_m3", "mouth_m4", "mouth_m5", "mouth_m6"]
    for n in mnames:
        kind = mkinds[n]
        ids[n] = B.add_ring(mrings[n], kind, "mouth")
    for k, (a, b) in enumerate(zip(mnames[:-1], mnames[1:])):
        B.strip(ids[a], ids[b], False, "lip" if k < 3 else "perioral")

    # ---- nostrils
    nr, virt, cpos, cfoot = layout.nostril_rings()
    ids["nostril_rim"] = B.add_ring(nr[0][1], "sdf", "nose", virt[0])
    ids["nostril_in"] = B.add_ring(nr[1][1], "explicit", "nose", virt[1])
    c_id = B.add(cpos, "explicit", "nose", cfoot)
    ids["nostril_c"] = np.array([c_id])
    B.strip(ids["nostril_rim"], ids["nostril_in"], True, "nose")
    B.fan(ids["nostril_in"], c_id, "nose")

    # ---- ear
    erg, ecen = layout.ear_rings()
    enames = [n for n, p, k in erg]
    for n, p, k in erg:
        ids[n] = B.add_ring(p, k, "ear")
    for a, b in zip(enames[:-1], enames[1:]):
        B.strip(ids[a], ids[b], True, "ear")
    e_c = B.add(ecen, "explicit", "ear")
    ids["ear_c"] = np.array([e_c])
    B.fan(ids[enames[-1]], e_c, "ear")

    # ---- neck
    nk = layout.neck_rings()
    nnames = [n for n, p, k in nk]
    for n, p, k in nk:
        ids[n] = B.add_ring(p, k, "neck")
    for a, b in zip(nnames[:-1], nnames[1:]):
        B.strip(ids[a], ids[b], False, "neck")

    structured_n = len(B.P)
    outer = {"eye": ids["eye_r4"], "mouth": ids["mouth_m6"], "nostril": ids["nostril_rim"],
             "ear": ids["ear_att"], "neck": ids["neck_n0"]}

    # ---- feature points (free landmarks) and midline samples
    fixed_pts = []  # (code, position, kind, region)
    for code in ["v", "op", "tr", "sg", "g", "n", "se", "mn", "rhi", "prn", "c", "pg", "gn", "me"]:
        p = ppos[code].copy()
        p[0] = 0.0
        fixed_pts.append((code, p, "midline"))
    for code, p in lat.items():
        fixed_pts.append((code, p, "sdf"))

    # exclusion ranges on the midline
    m6p = mrings["mouth_m6"]
    y_mouth_top, y_mouth_bot = m6p[0, 1], m6p[-1, 1]
    n0 = layout.neck_rings()[0][1]
    y_neck_front, y_neck_back = n0[0, 1], n0[-1, 1]
    fixed_mid = np.array([p for c, p, k in fixed_pts if k == "midline"])

    def mid_ok(p):
        y, z = p[1], p[2]
        if z > 40 and y_mouth_bot - 0.3 <= y <= y_mouth_top + 0.3:
            return False
        if z > -20 and y < y_neck_front + 0.5 and z < 60:
            return False
        if z <= -20 and y < y_neck_back + 0.5:
            return False
        if z > 0 and y < y_neck_front + 0.5:
            return False
        return True
    seg = np.linalg.norm(np.diff(prof, axis=0), axis=1)
    cum = np.concatenate([[0], np.cumsum(seg)])
    mid_samples = []
    s = 0.0
    while s < cum[-1]:
        j = int(np.searchsorted(cum, s))
        p = prof[min(j, len(prof) - 1)]
        h = sizing(p)[0]
        if mid_ok(p):
            if np.min(np.linalg.norm(fixed_mid - p, axis=1)) > 0.6 * h:
                mid_samples.append(p.copy())
        s += h
    # also drop samples too close to structured midline ring ends
    struct_mid = np.array([q for q in B.P if abs(q[0]) < 1e-9])
    ms = []
    for p in mid_samples:
        h = sizing(p)[0]
        if len(struct_mid) and np.min(np.linalg.norm(struct_mid - p, axis=1)) < 0.6 * h:
            continue
        ms.append(p)
    mid_samples = ms

    for code, p, k in fixed_pts:
        region = "midline" if k == "midline" else "face"
        vid = B.add(p, "sdf", region)
        LM[code] = ("vertex", vid)
    for p in mid_samples:
        p = p.copy()
        p[0] = 0.0
        B.add(p, "sdf", "midline")

    # ---- hole polygons in the chart
    def chart_of(vids):
        return geom.chart(np.array([B.V[i] for i in vids]))
    holes = [
        hole_polygon_closed(chart_of(outer["eye"])),
        hole_polygon_midline(chart_of(outer["mouth"])),
        hole_polygon_closed(chart_of(outer["nostril"])),
        hole_polygon_closed(chart_of(outer["ear"])),
        hole_polygon_midline(chart_of(outer["neck"]), through_angle=-np.pi / 2),
    ]

    # ---- free points: Poisson disk on the surface
    dirs = rng.normal(size=(n_candidates, 3))
    dirs[:, 0] = np.abs(dirs[:, 0])
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    cand = geom.rays_hit(geom.CENTER, dirs, t_max=320, step=0.8)
    cand = cand[~np.isnan(cand).any(1)]
    hc = sizing(cand)
    cand = cand[cand[:, 0] > 0.5 * hc]
    hc = sizing(cand)
    ch = geom.chart(cand)
    inside = np.zeros(len(cand), bool)
    for hp in holes:
        inside |= hp.contains_points(ch)
    cand, hc = cand[~inside], hc[~inside]
    existing = np.array(B.P)
    tree = cKDTree(existing)
    dmin, _ = tree.query(cand)
    keep = dmin > 0.75 * hc
    cand, hc = cand[keep], hc[keep]
    order = rng.permutation(len(cand))
    accepted = []
    grid = {}
    cell = 4.0

    def key(p):
        return tuple((p // cell).astype(int))
    for i in order:
        p = cand[i]
        h = hc[i]
        r = 0.9 * h
        k0 = key(p)
        rr = int(np.ceil(r / cell))
        ok = True
        for dx in range(-rr, rr + 1):
            for dy in range(-rr, rr + 1):
                for dz in range(-rr, rr + 1):
                    for q in grid.get((k0[0] + dx, k0[1] + dy, k0[2] + dz), ()):
                        if np.sum((q - p) ** 2) < r * r:
                            ok = False
                            break
                    if not ok:
                        break
                if not ok:
                    break
            if not ok:
                break
        if ok:
            accepted.append(p)
            grid.setdefault(k0, []).append(p)
    free0 = len(B.P)
    for p in accepted:
        B.add(p, "sdf", "free")
    if verbose:
        print(f"structured {structured_n}, fixed+mid {free0 - structured_n}, free {len(accepted)}")
    B.ids = ids
    B.LM = LM
    B.outer = outer
    B.holes = holes
    B.free0 = free0
    B.structured_n = structured_n
    return B


def triangulate(B, verbose=True):
    """Delaunay in the chart for the free region, remove holes, add to structured faces."""
    P = np.array(B.P)
    V = np.array(B.V)
    # Delaunay point set: everything except interior structured vertices
    struct_ids = np.arange(B.structured_n)
    outer_ids = np.concatenate(list(B.outer.values()))
    use = np.concatenate([outer_ids, np.arange(B.structured_n, len(P))])
    C = geom.chart(V[use])
    # midline points exactly on the unit circle
    onmid = np.abs(P[use, 0]) < 1e-9
    C[onmid] /= np.linalg.norm(C[onmid], axis=1, keepdims=True)
    tri = Delaunay(C)
    S = tri.simplices
    # constraint edges: outer rings (local indices into `use`)
    loc = {g: i for i, g in enumerate(use)}
    cons = []
    for name, ring in B.outer.items():
        closed = name in ("eye", "nostril", "ear")
        rr = list(ring) + ([ring[0]] if closed else [])
        cons += [(loc[a], loc[b]) for a, b in zip(rr[:-1], rr[1:])]
    S, failed = recover_edges(S, C, cons)
    if verbose and failed:
        print("could not recover", failed)
    T = use[S]
    cent = C[S].mean(1)
    bad = np.zeros(len(T), bool)
    for hp in B.holes:
        bad |= hp.contains_points(cent)
    T = T[~bad]
    # required outer ring edges
    have = set()
    for a, b, c in T:
        for u, v in ((a, b), (b, c), (c, a)):
            have.add((min(u, v), max(u, v)))
    missing = []
    for name, ring in B.outer.items():
        closed = name in ("eye", "nostril", "ear")
        rr = list(ring) + ([ring[0]] if closed else [])
        for u, v in zip(rr[:-1], rr[1:]):
            if (min(u, v), max(u, v)) not in have:
                missing.append((name, u, v))
    if verbose:
        print("delaunay faces", len(T), "missing ring edges", missing)
    faces = np.vstack([np.array(B.faces), T])
    return faces, missing


def orient(faces, P, seed_face=None):
    """Make the winding consistent (BFS over edge neighbours), then outward (positive volume)."""
    faces = faces.copy()
    m = len(faces)
    from collections import defaultdict, deque
    e2f = defaultdict(list)
    for fi, (a, b, c) in enumerate(faces):
        for u, v in ((a, b), (b, c), (c, a)):
            e2f[(min(u, v), max(u, v))].append(fi)
    seen = np.zeros(m, bool)
    for start in range(m):
        if seen[start]:
            continue
        seen[start] = True
        dq = deque([start])
        while dq:
            f = dq.popleft()
            a, b, c = faces[f]
            for u, v in ((a, b), (b, c), (c, a)):
                for g in e2f[(min(u, v), max(u, v))]:
                    if g == f or seen[g]:
                        continue
                    # neighbour must traverse (v, u)
                    ga, gb, gc = faces[g]
                    dirs = {(ga, gb), (gb, gc), (gc, ga)}
                    if (u, v) in dirs:
                        faces[g] = faces[g][::-1]
                    seen[g] = True
                    dq.append(g)
    return faces


def _seg_cross(p1, p2, p3, p4):
    def orient2(a, b, c):
        return (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
    d1 = orient2(p3, p4, p1)
    d2 = orient2(p3, p4, p2)
    d3 = orient2(p1, p2, p3)
    d4 = orient2(p1, p2, p4)
    return (d1 * d2 < 0) and (d3 * d4 < 0)


def recover_edges(T, C, constraints, max_iter=200):
    """Sloan-style edge flipping so that every (u, v) in constraints is an edge of T (indices into C)."""
    T = [tuple(t) for t in T]
    failed = []
    for (u, v) in constraints:
        for it in range(max_iter):
            e2t = {}
            for ti, (a, b, c) in enumerate(T):
                for x, y in ((a, b), (b, c), (c, a)):
                    e2t.setdefault((min(x, y), max(x, y)), []).append(ti)
            if (min(u, v), max(u, v)) in e2t:
                break
            flipped = False
            for (a, b), tl in list(e2t.items()):
                if len(tl) != 2 or a in (u, v) or b in (u, v):
                    continue
                if not _seg_cross(C[u], C[v], C[a], C[b]):
                    continue
                t1, t2 = T[tl[0]], T[tl[1]]
                c = [x for x in t1 if x not in (a, b)][0]
                d = [x for x in t2 if x not in (a, b)][0]
                # convex quad a c b d  <=> segment c-d crosses a-b
                if not _seg_cross(C[c], C[d], C[a], C[b]):
                    continue

                def ccw(tri):
                    p, q, r = C[tri[0]], C[tri[1]], C[tri[2]]
                    return (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0]) > 0
                n1 = (c, d, a) if ccw((c, d, a)) else (d, c, a)
                n2 = (c, d, b) if ccw((c, d, b)) else (d, c, b)
                T[tl[0]] = n1
                T[tl[1]] = n2
                flipped = True
                break
            if not flipped:
                failed.append((u, v))
                break
    return np.array(T), failed
