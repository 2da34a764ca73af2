"""Ground-truth soft-tissue landmarks on the true skins of the three real CT cases.

Frame and units
---------------
Every point is in millimetres in the frame of the skin mesh that ``workbench
validate`` scores against: :func:`workbench.services.ct.ct_mesh.mesh_from_ct`
(``tissue="skin"``) on the sample volume, at the case's skin level of
``benchmarks/bench_validation.py`` (headsq 500, raw VTK CT numbers; Visible
Human female and male -400 HU), i.e. the CT's physical frame as the extractor
returns it (LPS for the headsq NRRD, RAS for the Visible Human NIfTI files).
The ``.mrk.json`` files are written with ``coordinateSystem: "RAS"`` so the
numbers in them are these mesh coordinates unchanged (the project's
convention: mesh coordinates = Slicer RAS world).

Method
------
1. First guess: ``workbench fit-scan`` on the skin mesh with the case's
   orientation hints; the fitted reference head's skin landmarks are taken
   back into the scan frame (``fit_report.json`` ``input_to_head``) and
   snapped to the skin.
2. Geometric refinement in a face frame (x = subject's left, y = up,
   z = anterior; the fit's Frankfort head frame with its midsagittal plane
   re-estimated as the symmetry plane of the visible face, mirror + nearest
   neighbours): midline points on the skin's midsagittal section (most
   anterior points, deepest points under chords), bilateral points on a
   frontal depth image z(x, y) of the skin (grooves = ridges of d2z/dx2 or
   d2z/dy2 tracked from a seed until they fade).
3. Explicit overrides after looking at the pictures (:data:`OVERRIDES`),
   each with its reason.

A point whose neighbourhood touches the clipped field of view (a skin vertex
within one voxel of the volume's box) is written ``absent`` with the reason,
never guessed.

Run ``python benchmarks/truth_landmarks/place.py [--out DIR] [--cases ...]``
with ``WORKBENCH_SAMPLE_MIRRORS`` pointing at the shared data.  It writes per
case ``<case>_skin.ply``, ``<case>.mrk.json``, ``<case>_table.csv`` and
pictures (frontal/lateral close-ups, depth image) into ``--out``.

Visible Human data: Courtesy of the U.S. National Library of Medicine; the
copy used may not be the most current NLM data.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))
os.environ.setdefault("WORKBENCH_SAMPLE_MIRRORS", str(ROOT.parent / "shared" / "data"))

CREDIT = (
    "Visible Human data: Courtesy of the U.S. National Library of Medicine; "
    "the copy used may not be the most current NLM data."
)


@dataclass(frozen=True)
class Case:
    """One CT case: sample name, skin level (volume units) and file axes."""

    name: str
    skin_iso: float
    anterior: tuple[float, float, float]
    superior: tuple[float, float, float]
    left: tuple[float, float, float]
    smooth_mm: float  # Gaussian sigma of the depth image before derivatives
    clipped: bool  # the validation mask is a field-of-view clip (clip_patch / behind_clip)


#: skin levels and axes as in benchmarks/bench_validation.py
CASES = {
    "headsq": Case("headsq", 500.0, (0, -1, 0), (0, 0, -1), (1, 0, 0), 2.0, False),
    "vhp_female": Case("vhp_female", -400.0, (0, 1, 0), (0, 0, 1), (-1, 0, 0), 1.0, True),
    "vhp_male": Case("vhp_male", -400.0, (0, 1, 0), (0, 0, 1), (-1, 0, 0), 1.0, True),
}

MIDLINE = ("se", "prn", "sn", "ls", "sto", "li", "sl", "pg")
BILATERAL = ("al", "ac", "sbal", "ch", "en", "ex")
CODES = (*MIDLINE, *(f"{b}_{s}" for b in BILATERAL for s in ("l", "r")))

#: depth-image grid step (mm)
STEP = 0.5
#: a landmark within this distance (mm) of a clipped (field-of-view) skin vertex is not in view
CLIP_RADIUS = 3.0

FIT = "fit"  # in OVERRIDES: the fit-scan guess's own (x, y)

#: Manual corrections after looking at the pictures, in the face frame of the case
#: (x = left, y = up, z = anterior, mm): ``{case: {code: (x, y, reason)}}`` moves the
#: point to the frontal depth image's skin point at (x, y); ``(None, None, reason)``
#: marks it absent with that reason.
OVERRIDES: dict[str, dict[str, tuple[float | str | None, float | str | None, str]]] = {
    "vhp_female": {
        # the crease tracker ran from the left eye's centre past the inner canthus to the
        # nasal midline (x = 2 mm); the medial end of the left fissure crease is seen on the
        # depth image at x = 14 mm, mirror of en_r (x = -12 mm)
        "en_l": (14.0, 12.5, "crease tracker overshot to the nasal midline"),
        # the lateral crease ran up into a crow's-foot wrinkle at (55, 20); the fissure's
        # lateral end is taken at the fit-scan guess (52, 11), on the crease's line
        "ex_l": (52.0, 11.0, "crease tracker followed a wrinkle above the canthus"),
    },
    "headsq": {
        # both lateral crease ends ran 10 mm past the canthi into the temple wrinkles
        # (3.2 mm voxels); the fit-scan guesses sit on the crease's line at the canthi
        "ex_l": (FIT, FIT, "crease tracker overshot into temple wrinkles; fit-scan guess kept"),
        "ex_r": (FIT, FIT, "crease tracker overshot into temple wrinkles; fit-scan guess kept"),
        # an airway tube leaves the open mouth and lies on the chin just right of the
        # midline (x = -3..-10 mm, y = -70..-95 mm): the midsagittal profile below the lower
        # lip runs along the tube's edge, so the chin groove and the chin point there are
        # not the subject's skin
        "sl": (
            None,
            None,
            "not in view: the midline below the lower lip is the edge of an "
            "airway tube lying on the chin",
        ),
        "pg": (
            None,
            None,
            "not in view: the midline chin is the edge of an airway tube lying on the chin",
        ),
    },
    "vhp_male": {
        # the depth image shows the face cut flat by the field of view over a strip
        # |x| < 12 mm from the brow to the nose base and a ragged band y = -25..-65 mm over
        # the mouth and chin (|x| < 40 mm): no midline point, ala or mouth corner is real skin
        **{
            c: (None, None, "not in view: in the skin cut flat/ragged by the CT's field of view")
            for c in ("se", "prn", "sn", "ls", "sto", "li", "sl", "pg")
            + ("al_l", "al_r", "ch_l", "ch_r")
        },
        # eyes are in view, but the crease tracker overshot (medially to x = 35 mm on the
        # left, laterally past the canthi); the fit-scan guesses sit on the creases
        "en_l": (FIT, FIT, "crease tracker overshot; fit-scan guess kept (on the crease)"),
        "en_r": (FIT, FIT, "crease tracker overshot; fit-scan guess kept (on the crease)"),
        "ex_l": (FIT, FIT, "crease tracker overshot; fit-scan guess kept (on the crease)"),
        "ex_r": (FIT, FIT, "crease tracker overshot; fit-scan guess kept (on the crease)"),
    },
}

#: The validation mask of each case (benchmarks/bench_validation.py): within this many mm
#: of the clipping plane (male) or of the clipped patch (female) a point is not in view.
BEHIND_CLIP_MM = {"vhp_male": 3.0}

#: Points the rules could not separate from al (the alar groove rule returns one point for
#: al, ac and sbal on these 0.5-1 mm depth images): left "missing" (not placed), never
#: guessed.
NOT_PLACED = ("ac_l", "ac_r", "sbal_l", "sbal_r")


# ----------------------------------------------------------------------- extraction
def extract(case: Case, out: Path):
    """The true skin exactly as ``workbench validate`` extracts it; written as PLY."""
    from workbench.io.meshes import write_mesh
    from workbench.io.samples import fetch
    from workbench.services.ct.ct_mesh import mesh_from_ct

    path = fetch(case.name)
    result = mesh_from_ct(path, tissue="skin", iso=case.skin_iso)
    ply = out / f"{case.name}_skin.ply"
    write_mesh(ply, result.mesh)
    return result, ply


def clipped_vertices(mesh, case: Case) -> np.ndarray:
    """The flat patch where the field of view cut the skin (the rule of ``ScoreMask``).

    Anterior-facing vertices (normal . anterior > 0.9) within ``CLIP_FLAT_MM`` of the
    skin's most anterior extent, as :class:`workbench.core.face_metric.ScoreMask` finds
    the clip; only for the cases whose validation mask is a clip (the two VHP heads).
    """
    from workbench.core.face_metric import CLIP_FLAT_MM, vertex_normals

    if not case.clipped:
        return np.zeros(mesh.n_vertices, bool)
    a = np.asarray(case.anterior, float)
    depth = mesh.vertices @ a
    return (depth >= depth.max() - CLIP_FLAT_MM) & (vertex_normals(mesh) @ a > 0.9)


# ----------------------------------------------------------------------- first guess
def first_guess(case: Case, ply: Path, out: Path, reuse: bool) -> tuple[dict, np.ndarray]:
    """Skin landmarks of ``workbench fit-scan`` in the scan frame, and scan->head 4x4."""
    from workbench.io.markups import read_landmarks

    pack = out / f"fit_{case.name}"
    if not (reuse and (pack / "fit_report.json").is_file()):
        exe = Path(sys.executable).with_name("workbench")
        vec = {k: ",".join(f"{v:g}" for v in getattr(case, k)) for k in ("anterior", "superior")}
        left = ",".join(f"{v:g}" for v in case.left)
        cmd = [str(exe), "fit-scan", str(ply), "--units", "mm", "--no-detail", "--force"]
        cmd += ["--anterior", vec["anterior"], "--superior", vec["superior"], f"--left={left}"]
        cmd += ["--out", str(pack)]
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
    report = json.loads((pack / "fit_report.json").read_text(encoding="utf-8"))
    to_head = np.asarray(report["input_to_head"], dtype=float)
    lms = read_landmarks(pack / "skin.mrk.json", "skin", allow_undefined=True).landmarks
    back = np.linalg.inv(to_head)
    guess = {lm.code: back[:3, :3] @ lm.position + back[:3, 3] for lm in lms if lm.is_defined}
    return guess, to_head


# ----------------------------------------------------------------------- face frame
class Frame:
    """Scan <-> face frame (x left, y up, z anterior; may be improper for mirrored files)."""

    def __init__(self, rot: np.ndarray, origin_scan: np.ndarray):
        self.rot = np.asarray(rot, dtype=float)  # rows = face axes in scan coordinates
        self.origin = np.asarray(origin_scan, dtype=float)

    def to_face(self, p: np.ndarray) -> np.ndarray:
        return (np.asarray(p, dtype=float) - self.origin) @ self.rot.T

    def to_scan(self, q: np.ndarray) -> np.ndarray:
        return np.asarray(q, dtype=float) @ self.rot + self.origin

    def dir_to_scan(self, d: np.ndarray) -> np.ndarray:
        return np.asarray(d, dtype=float) @ self.rot


def head_frame(to_head: np.ndarray) -> Frame:
    """The fit's Frankfort head frame, orthonormalised."""
    r = to_head[:3, :3]
    u, _, vt = np.linalg.svd(r)
    r = u @ vt
    origin = -np.linalg.solve(r, to_head[:3, 3])  # head origin in scan coordinates
    return Frame(r, origin)


def depth_image(caster, frame: Frame, xr, yr, z0: float, step: float = STEP):
    """First skin hit of rays along -z (face frame) on a grid: z, scan points, face ids."""
    xs = np.arange(xr[0], xr[1] + step / 2, step)
    ys = np.arange(yr[0], yr[1] + step / 2, step)
    gx, gy = np.meshgrid(xs, ys)
    origins = np.stack([gx.ravel(), gy.ravel(), np.full(gx.size, z0)], axis=1)
    hits = caster.first_hits(
        frame.to_scan(origins),
        np.repeat(frame.dir_to_scan(np.array([[0.0, 0.0, -1.0]])), gx.size, axis=0),
    )
    pts = hits.points.reshape(gx.shape + (3,))
    z = np.where(hits.hit, z0 - hits.distance, np.nan).reshape(gx.shape)
    return xs, ys, z, pts, hits.face_ids.reshape(gx.shape)


def symmetry_frame(caster, frame: Frame, clipped_pts: np.ndarray, guess_face: dict) -> Frame:
    """Re-estimate the midsagittal plane as the symmetry plane of the visible face."""
    from scipy.spatial import cKDTree

    ys = [p[1] for c, p in guess_face.items() if c in ("pg", "se", "g", "en_l", "en_r", "sn")]
    y_lo, y_hi = min(ys) - 10, max(ys) + 25
    xs, yv, z, pts, _ = depth_image(caster, frame, (-65, 65), (y_lo, y_hi), 250.0, 1.0)
    ok = np.isfinite(z)
    cloud_scan = pts[ok]
    if len(clipped_pts):
        d, _ = cKDTree(clipped_pts).query(cloud_scan)
        cloud_scan = cloud_scan[d > 4.0]
    cloud = frame.to_face(cloud_scan)
    # keep the front of the face (drop ears, hair and the sides)
    front = cloud[:, 2] > np.percentile(cloud[:, 2], 35)
    cloud = cloud[front]
    tree = cKDTree(cloud)
    n, d0 = np.array([1.0, 0.0, 0.0]), 0.0
    for _ in range(15):
        mirrored = cloud - 2.0 * (cloud @ n - d0)[:, None] * n
        dist, idx = tree.query(mirrored)
        good = dist < max(3.0, np.percentile(dist, 70))
        p, q = cloud[good], cloud[idx[good]]
        diff = p - q
        big = np.linalg.norm(diff, axis=1) > 5.0
        diff = diff[big] * np.sign(diff[big] @ n)[:, None]
        n_new = diff.mean(axis=0)
        n_new /= np.linalg.norm(n_new)
        d_new = float(np.median(((p + q) / 2.0) @ n_new))
        if np.linalg.norm(n_new - n) < 1e-5 and abs(d_new - d0) < 1e-3:
            n, d0 = n_new, d_new
            break
        n, d0 = n_new, d_new
    # new axes: x = plane normal, y = old up made orthogonal, z completes the old handedness
    y_old = np.array([0.0, 1.0, 0.0])
    y_new = y_old - (y_old @ n) * n
    y_new /= np.linalg.norm(y_new)
    z_new = np.cross(n, y_new)
    rot_face = np.stack([n, y_new, z_new])  # in old face coordinates
    origin_face = n * d0
    return Frame(rot_face @ frame.rot, frame.to_scan(origin_face))


# ----------------------------------------------------------------------- midline
def midsagittal_profile(caster, frame: Frame, y_lo: float, y_hi: float, step: float = 0.2):
    """Anterior skin profile in the plane x = 0: first hits of rays along -z, (k, 3) face mm."""
    ys = np.arange(y_lo, y_hi, step)
    origins = np.stack([np.zeros_like(ys), ys, np.full_like(ys, 300.0)], axis=1)
    hits = caster.first_hits(
        frame.to_scan(origins),
        np.repeat(frame.dir_to_scan(np.array([[0.0, 0.0, -1.0]])), len(ys), axis=0),
    )
    prof = frame.to_face(hits.points[hits.hit])
    return prof


def deepest_under_chord(env: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Point of the profile between a and b farthest behind the chord a-b (y-z plane)."""
    lo, hi = sorted((a[1], b[1]))
    seg = env[(env[:, 1] > lo) & (env[:, 1] < hi)]
    if not len(seg):
        return (a + b) / 2
    d = b[1:] - a[1:]
    normal = np.array([d[1], -d[0]]) / np.linalg.norm(d)  # perpendicular in (y, z)
    if normal[1] > 0:  # point it backwards (-z)
        normal = -normal
    depth = (seg[:, 1:] - a[1:]) @ normal
    return seg[int(np.argmax(depth))]


def most_anterior(env: np.ndarray, y_lo: float, y_hi: float) -> np.ndarray:
    seg = env[(env[:, 1] >= y_lo) & (env[:, 1] <= y_hi)]
    return seg[int(np.argmax(seg[:, 2]))]


def lip_line_row(dep: Depth, y_lo: float, y_hi: float) -> float:
    """Height of the mouth line: the row whose lip groove (z_yy ridge) is strongest over |x| < 12."""
    cols = np.abs(dep.xs) < 12.0
    best, y_best = -np.inf, (y_lo + y_hi) / 2
    for i, y in enumerate(dep.ys):
        if y_lo <= y <= y_hi:
            v = float(np.mean(np.clip(dep.zyy[i, cols], 0, None)))
            if v > best:
                best, y_best = v, float(y)
    return y_best


def prominent_before_chord(env: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Point of the profile between a and b farthest in front of the chord a-b."""
    lo, hi = sorted((a[1], b[1]))
    seg = env[(env[:, 1] > lo) & (env[:, 1] < hi)]
    d = b[1:] - a[1:]
    normal = np.array([d[1], -d[0]]) / np.linalg.norm(d)
    if normal[1] < 0:  # forwards (+z)
        normal = -normal
    return seg[int(np.argmax((seg[:, 1:] - a[1:]) @ normal))]


def midline_points(env: np.ndarray, g: dict, dep: Depth) -> tuple[dict, dict, bool]:
    """Midline landmarks on the profile, seeded by the first guess ``g`` (face frame)."""
    how: dict[str, str] = {}
    p: dict[str, np.ndarray] = {}
    y_sn, y_se = g["sn"][1], g["se"][1]
    p["prn"] = most_anterior(env, y_sn, y_se)
    how["prn"] = "most anterior point of the midsagittal profile between the guessed sn and se"
    # se: deepest point behind the chord glabella-prn when a glabella bulge is in view,
    # else (forehead cut off) the most concave point of the nasal root
    above = env[env[:, 1] > y_se + 5.0]
    top = above[:, 1].max() if len(above) else y_se
    glab = most_anterior(env, y_se + 5.0, min(y_se + 30.0, top))
    cand = deepest_under_chord(env, glab, p["prn"])
    if glab[1] < top - 3.0 and cand[1] > p["prn"][1] + 10.0:
        p["se"] = cand
        how["se"] = "deepest profile point behind the chord from the glabella bulge to prn"
    else:
        from scipy.ndimage import gaussian_filter1d

        seg = env[(env[:, 1] > y_se - 10.0) & (env[:, 1] < top - 3.0)]
        zz = gaussian_filter1d(seg[:, 2], 15.0, order=2)  # 15 samples = 3 mm
        p["se"] = seg[int(np.argmax(zz))]
        how["se"] = (
            "no glabella in view (vault cut): most concave point of the nasal-root profile "
            "(max d2z/dy2, 3 mm smoothing)"
        )
    # mouth line from the frontal lip groove, then the lips around it
    y_line = lip_line_row(dep, p["prn"][1] - 60.0, p["prn"][1] - 15.0)
    near = env[np.abs(env[:, 1] - y_line) <= 4.0]
    p["sto"] = near[int(np.argmin(near[:, 2]))]
    how["sto"] = (
        "deepest profile point within 4 mm of the mouth line (the row of the strongest "
        "lip groove in the frontal depth image)"
    )
    p["ls"] = most_anterior(env, p["sto"][1] + 1.0, p["sto"][1] + 12.0)
    how["ls"] = "most anterior point of the upper lip within 12 mm above the mouth line"
    p["li"] = most_anterior(env, p["sto"][1] - 12.0, p["sto"][1] - 1.0)
    how["li"] = "most anterior point of the lower lip within 12 mm below the mouth line"
    gapped = p["sto"][2] < min(p["ls"][2], p["li"][2]) - 6.0
    p["sn"] = deepest_under_chord(env, p["prn"], p["ls"])
    how["sn"] = "deepest profile point behind the chord prn-ls (columella-lip junction)"
    # menton end of the chin: last profile point before the profile drops under the jaw
    below = env[(env[:, 1] < p["li"][1]) & (env[:, 1] > p["li"][1] - 50.0)][::-1]
    jump = np.nonzero((np.abs(np.diff(below[:, 2])) > 6.0) | (below[1:, 2] < p["li"][2] - 30))[0]
    end = below[jump[0]] if len(jump) else below[-1]
    p["pg"] = prominent_before_chord(env, p["li"], end)
    how["pg"] = (
        "most prominent profile point in front of the chord from li to the lower end of the "
        "chin profile"
    )
    p["sl"] = deepest_under_chord(env, p["li"], p["pg"])
    how["sl"] = "deepest profile point behind the chord li-pg"
    return p, how, gapped


def gap_middle(env: np.ndarray, mid: dict) -> np.ndarray:
    """Open mouth: middle of the gap between the lips' free edges on the profile (in air).

    The free edge of a lip is where the profile, followed from ls (li) towards the
    mouth, first falls 3 mm behind the lip's most anterior point.
    """
    ls, li = mid["ls"], mid["li"]
    seg = env[(env[:, 1] < ls[1]) & (env[:, 1] > li[1])]
    upper = seg[::-1]  # from ls downwards
    k_up = int(np.argmax(upper[:, 2] < ls[2] - 3.0))
    k_lo = int(np.argmax(seg[:, 2] < li[2] - 3.0))
    a, b = upper[k_up], seg[k_lo]
    return (a + b) / 2


# ----------------------------------------------------------------------- depth-image grooves
class Depth:
    """Frontal depth image of the face with smoothed second derivatives."""

    def __init__(self, caster, frame: Frame, xr, yr, sigma_mm: float):
        from scipy.ndimage import gaussian_filter

        self.xs, self.ys, self.z, self.pts, self.fid = depth_image(caster, frame, xr, yr, 300.0)
        z = self.z.copy()
        fill = np.nanmin(z) if np.isfinite(z).any() else 0.0
        z[~np.isfinite(z)] = fill
        s = sigma_mm / STEP
        self.zs = gaussian_filter(z, s)
        self.zyy = gaussian_filter(z, s, order=(2, 0)) / STEP**2  # rows = y
        self.zxx = gaussian_filter(z, s, order=(0, 2)) / STEP**2
        self.zx = gaussian_filter(z, s, order=(0, 1)) / STEP

    def ij(self, x: float, y: float) -> tuple[int, int]:
        i = int(np.clip(round((y - self.ys[0]) / STEP), 0, len(self.ys) - 1))
        j = int(np.clip(round((x - self.xs[0]) / STEP), 0, len(self.xs) - 1))
        return i, j

    def face_point(self, x: float, y: float) -> np.ndarray:
        i, j = self.ij(x, y)
        return np.array([self.xs[j], self.ys[i], self.z[i, j]])


def track_groove_x(dep: Depth, x0: float, y0: float, sign: int, window: float, stop_frac: float):
    """Follow a roughly horizontal groove (ridge of z_yy) from (x0, y0) towards ``sign`` x.

    Returns the list of (x, y, strength) and the index where the strength fell below
    ``stop_frac`` of the groove's strength near the seed (the groove's end).
    """
    i, j = dep.ij(x0, y0)
    w = int(round(window / STEP))
    track = []
    while 0 <= j < len(dep.xs):
        lo, hi = max(i - w, 0), min(i + w + 1, len(dep.ys))
        col = dep.zyy[lo:hi, j]
        k = int(np.argmax(col))
        i = lo + k
        track.append((dep.xs[j], dep.ys[i], col[k]))
        j += sign
        if abs(dep.xs[min(max(j, 0), len(dep.xs) - 1)] - x0) > 45:
            break
    arr = np.array(track)
    ref = np.percentile(arr[: int(round(20.0 / STEP)), 2], 75)
    weak = arr[:, 2] < stop_frac * ref
    run = int(round(2.0 / STEP))  # the groove has faded when it stays weak for 2 mm
    end = len(arr) - 1
    for k in range(len(arr) - run):
        if weak[k : k + run].all():
            end = k - 1
            break
    return arr, max(end, 0)


def alar_groove(dep: Depth, y_lo: float, y_hi: float, sign: int):
    """Per row: the alar-facial groove (strongest z_xx ridge at 8-32 mm from the midline)."""
    rows = []
    for i, y in enumerate(dep.ys):
        if not (y_lo <= y <= y_hi):
            continue
        sel = (sign * dep.xs >= 8.0) & (sign * dep.xs <= 32.0)
        js = np.nonzero(sel)[0]
        k = js[int(np.argmax(dep.zxx[i, js]))]
        rows.append((dep.xs[k], y, dep.zxx[i, k], dep.z[i, k]))
    return np.array(rows)


# ----------------------------------------------------------------------- the case
def place_case(case: Case, out: Path, reuse: bool) -> dict:
    from scipy.spatial import cKDTree

    from workbench.core.landmarks import Landmark, LandmarkSet
    from workbench.core.raycast import RayCaster
    from workbench.io.markups import write_landmarks

    result, ply = extract(case, out)
    mesh = result.mesh
    clipped = clipped_vertices(mesh, case)
    clip_pts = mesh.vertices[clipped]
    clip_tree = cKDTree(clip_pts) if len(clip_pts) else None
    caster = RayCaster(mesh)
    guess_scan, to_head = first_guess(case, ply, out, reuse)
    frame0 = head_frame(to_head)
    guess0 = {c: frame0.to_face(p) for c, p in guess_scan.items()}
    frame = symmetry_frame(caster, frame0, clip_pts, guess0)
    g = {c: frame.to_face(p) for c, p in guess_scan.items()}

    y_lo = g["pg"][1] - 30.0
    y_hi = g["se"][1] + 40.0
    env = midsagittal_profile(caster, frame, y_lo, y_hi)
    dep = Depth(caster, frame, (-70.0, 70.0), (y_lo, y_hi), case.smooth_mm)
    mid, how, gapped = midline_points(env, g, dep)
    pts: dict[str, np.ndarray] = dict(mid)
    for side, sign in (("l", 1), ("r", -1)):
        # alar groove, al, ac, sbal
        grooves = alar_groove(dep, mid["sn"][1] - 3.0, mid["sn"][1] + 22.0, sign)
        strong = grooves[grooves[:, 2] > 0.35 * grooves[:, 2].max()]
        k = int(np.argmax(sign * strong[:, 0]))
        pts[f"al_{side}"] = dep.face_point(strong[k, 0], strong[k, 1])
        how[f"al_{side}"] = (
            "alar-facial groove point (z_xx ridge) farthest from the midline in the frontal "
            "depth image, over the height of the ala"
        )
        below = strong[strong[:, 1] <= strong[k, 1]]
        kac = int(np.argmax(sign * below[:, 0] - below[:, 3]))
        pts[f"ac_{side}"] = dep.face_point(below[kac, 0], below[kac, 1])
        how[f"ac_{side}"] = (
            "most posterolateral point (max |x| - z) of the alar-facial groove at or below al"
        )
        low = strong[int(np.argmin(strong[:, 1]))]
        pts[f"sbal_{side}"] = dep.face_point(low[0], low[1])
        how[f"sbal_{side}"] = "lowest point of the alar-facial groove, where it meets the lip"
        # cheilion: the lip contact groove followed from stomion
        seed_y = mid["sto"][1]
        arr, end = track_groove_x(dep, 0.0, seed_y, sign, 1.5, 0.3)
        pts[f"ch_{side}"] = dep.face_point(arr[end, 0], arr[end, 1])
        how[f"ch_{side}"] = (
            "lateral end of the lip contact groove (z_yy ridge) followed from sto until its "
            "strength falls below 30 % of that at the midline"
        )
        # eye fissure: crease through the guessed eye centre, followed both ways
        en_g, ex_g = g.get(f"en_{side}"), g.get(f"ex_{side}")
        if en_g is not None and ex_g is not None:
            cx, cy = (en_g[0] + ex_g[0]) / 2, (en_g[1] + ex_g[1]) / 2
        elif en_g is not None:
            cx, cy = en_g[0] + sign * 15.0, en_g[1]
        else:
            cx, cy = sign * 32.0, mid["se"][1] - 8.0
        i, j = dep.ij(cx, cy)
        w = int(round(5.0 / STEP))
        cy = dep.ys[max(i - w, 0) + int(np.argmax(dep.zyy[max(i - w, 0) : i + w + 1, j]))]
        lat, e_lat = track_groove_x(dep, cx, cy, sign, 1.0, 0.25)
        med, e_med = track_groove_x(dep, cx, cy, -sign, 1.0, 0.25)
        pts[f"ex_{side}"] = dep.face_point(lat[e_lat, 0], lat[e_lat, 1])
        pts[f"en_{side}"] = dep.face_point(med[e_med, 0], med[e_med, 1])
        how[f"ex_{side}"] = (
            "lateral end of the closed-eyelid crease (z_yy ridge) followed from the eye's "
            "centre until it fades"
        )
        how[f"en_{side}"] = (
            "medial end of the closed-eyelid crease (z_yy ridge) followed from the eye's "
            "centre until it fades"
        )

    absent: dict[str, str] = {}
    for code, (x, y, reason) in OVERRIDES.get(case.name, {}).items():
        if x is None or y is None:
            absent[code] = reason
            continue
        if x == FIT:
            x, y = float(g[code][0]), float(g[code][1])
        pts[code] = dep.face_point(float(x), float(y))
        how[code] += f"; moved by hand after looking at the pictures: {reason}"

    # to the scan frame, onto the skin; field-of-view check
    rows = []
    landmarks = []
    for code in CODES:
        method = how.get(code, "")
        first = guess_scan.get(code)
        first_txt = (
            "first guess from workbench fit-scan (reference head's landmark carried onto the scan)"
            if first is not None
            else "no fit-scan guess"
        )
        if code in NOT_PLACED:
            reason = (
                "not placed: the automatic alar-groove rule did not separate it from al; "
                "needs placement by hand"
            )
            landmarks.append(Landmark(code, np.full(3, np.nan), "missing", 0.0, reason))
            rows.append((code, None, "missing", reason))
            continue
        if code in absent:
            landmarks.append(Landmark(code, np.full(3, np.nan), "absent", 1.0, absent[code]))
            rows.append((code, None, "absent", absent[code]))
            continue
        q = pts[code]
        if code == "sto" and gapped:
            # the middle of the lips' gap on the profile (not on the skin)
            p_scan = frame.to_scan(gap_middle(env, mid))
            method = "mouth open: middle of the lip gap on the midsagittal profile (in air)"
        else:
            p_scan = frame.to_scan(q)  # a skin point already (section or ray hit)
        if clip_tree is not None and clip_tree.query(p_scan)[0] < CLIP_RADIUS:
            reason = (
                "not in view: the skin here is the flat cut of the CT's field of view "
                f"(clipped skin within {CLIP_RADIUS:g} mm)"
            )
            landmarks.append(Landmark(code, np.full(3, np.nan), "absent", 1.0, reason))
            rows.append((code, None, "absent", reason))
            continue
        if case.name in BEHIND_CLIP_MM:
            a = np.asarray(case.anterior, float)
            front = float((mesh.vertices @ a).max())
            if p_scan @ a > front - BEHIND_CLIP_MM[case.name]:
                reason = (
                    "not in view: the face is clipped flat by the CT's field of view here "
                    f"(within {BEHIND_CLIP_MM[case.name]:g} mm of the clipping plane, the "
                    "validation mask behind_clip)"
                )
                landmarks.append(Landmark(code, np.full(3, np.nan), "absent", 1.0, reason))
                rows.append((code, None, "absent", reason))
                continue
        desc = f"{first_txt}; refined: {method}; checked by eye on frontal/lateral pictures"
        landmarks.append(Landmark(code, p_scan, "placed", 1.0, desc))
        rows.append((code, p_scan, "placed", method))
    lmset = LandmarkSet("skin", tuple(landmarks))
    write_landmarks(out / f"{case.name}.mrk.json", lmset, coordinate_system="RAS")
    with open(out / f"{case.name}_table.csv", "w", encoding="utf-8") as fh:
        fh.write("code,x_mm,y_mm,z_mm,status,method\n")
        for code, p, status, m in rows:
            xyz = ",".join(f"{v:.2f}" for v in p) if p is not None else ",,"
            fh.write(f'{code},{xyz},{status},"{m}"\n')
    info = {
        "case": case.name,
        "iso": result.iso,
        "frame": result.frame,
        "n_vertices": mesh.n_vertices,
        "n_faces": mesh.n_faces,
        "bounds_mm": mesh.bounds.tolist(),
        "face_frame_rot": frame.rot.tolist(),
        "face_frame_origin": frame.origin.tolist(),
        "mouth_open": bool(gapped),
        "credit": result.credit,
    }
    (out / f"{case.name}_info.json").write_text(json.dumps(info, indent=2), encoding="utf-8")
    pictures(case, mesh, frame, lmset, dep, env, out, guess_scan)
    return info


# ----------------------------------------------------------------------- pictures
COLOURS = {
    "se": "yellow",
    "prn": "red",
    "sn": "orange",
    "ls": "magenta",
    "sto": "cyan",
    "li": "purple",
    "sl": "blue",
    "pg": "green",
    "al": "red",
    "ac": "orange",
    "sbal": "yellow",
    "ch": "magenta",
    "en": "cyan",
    "ex": "blue",
}


def pictures(case, mesh, frame, lmset, dep, env, out: Path, guess_scan: dict) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import pyvista as pv

    pv.OFF_SCREEN = True
    face_v = frame.to_face(mesh.vertices)
    poly = pv.PolyData(face_v, np.hstack([np.full((mesh.n_faces, 1), 3), mesh.faces]).ravel())
    defined = {lm.code: frame.to_face(lm.position) for lm in lmset if lm.is_defined}
    ys = [p[1] for p in defined.values()]
    cy = (min(ys) + max(ys)) / 2 if ys else 0.0
    zf = max((p[2] for p in defined.values()), default=face_v[:, 2].max())
    box = poly.clip_box([-80, 80, cy - 75, cy + 75, zf - 70, zf + 20], invert=False)
    for view, pos, up in (
        ("frontal", (0, cy, zf + 400), (0, 1, 0)),
        ("lateral_l", (400, cy, zf - 30), (0, 1, 0)),
        ("lateral_r", (-400, cy, zf - 30), (0, 1, 0)),
        ("oblique", (250, cy - 60, zf + 300), (0, 1, 0)),
    ):
        pl = pv.Plotter(off_screen=True, window_size=(1100, 1300))
        pl.add_mesh(box, color="wheat", smooth_shading=True, specular=0.2)
        for code, p in defined.items():
            base = code.split("_")[0]
            pl.add_mesh(pv.Sphere(radius=1.3, center=p), color=COLOURS.get(base, "white"))
        if defined:
            pl.add_point_labels(
                np.array(list(defined.values())),
                list(defined.keys()),
                font_size=12,
                point_size=1,
                shape_opacity=0.4,
                always_visible=True,
            )
        pl.camera.position = pos
        pl.camera.focal_point = (0, cy, zf - 30)
        pl.camera.up = up
        pl.camera.parallel_projection = True
        pl.camera.parallel_scale = 70
        pl.add_text(f"{case.name} {view}", font_size=10)
        if case.name.startswith("vhp"):
            pl.add_text(
                "Courtesy of the U.S. National Library of Medicine",
                position="lower_left",
                font_size=8,
            )
        pl.screenshot(str(out / f"{case.name}_{view}.png"))
        pl.close()
    # depth image and profile
    fig, axes = plt.subplots(1, 2, figsize=(16, 9))
    ext = [dep.xs[0], dep.xs[-1], dep.ys[0], dep.ys[-1]]
    axes[0].imshow(
        dep.zyy + dep.zxx, origin="lower", extent=ext, cmap="gray_r", vmin=-0.3, vmax=0.3
    )
    for code, p in defined.items():
        axes[0].plot(p[0], p[1], "o", ms=4, color="red")
        axes[0].annotate(code, (p[0], p[1]), color="red", fontsize=8)
    for code, p in guess_scan.items():
        if code in CODES:
            q = frame.to_face(p)
            axes[0].plot(q[0], q[1], "x", ms=4, color="blue")
    axes[0].set_title(f"{case.name}: Laplacian of the frontal depth (red: final, blue x: fit-scan)")
    axes[0].set_xlim(-60, 60)
    axes[0].invert_xaxis()  # subject's left on the image right, as in a frontal photo
    axes[1].plot(env[:, 2], env[:, 1], "-", lw=0.8)
    for code, p in defined.items():
        if code in MIDLINE:
            axes[1].plot(p[2], p[1], "o", color="red")
            axes[1].annotate(code, (p[2], p[1]))
    axes[1].set_aspect("equal")
    axes[1].set_title("midsagittal profile (z anterior, y up, mm)")
    fig.tight_layout()
    fig.savefig(out / f"{case.name}_depth.png", dpi=90)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=Path("/work/scratch/truth_lm/out"))
    ap.add_argument("--cases", nargs="*", default=list(CASES))
    ap.add_argument("--reuse-fit", action="store_true", help="reuse fit-scan packs in --out")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    for name in args.cases:
        info = place_case(CASES[name], args.out, args.reuse_fit)
        print(json.dumps({k: info[k] for k in ("case", "iso", "n_vertices", "mouth_open")}))
    print(CREDIT)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
