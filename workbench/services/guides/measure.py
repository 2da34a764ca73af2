"""Skull measurements for the nose, mouth and eye guides, and the guide tables' constants.

Units and frame: millimetres, head frame (x to the subject's left with x = 0
the midsagittal plane, y up, z toward the face, Frankfort Horizontal at y = 0).

:func:`measure_skull` derives what the guide rules need from the skull
landmarks and, where a landmark cannot give it (the widest nasal aperture, the
incisal edge, the canine–premolar junction, the base of the nasal spine), from
the skull mesh: rays cast backward in the frontal view and a horizontal section
through the upper tooth crowns.  Without a mesh, cited typical values stand in
(``data_tables/guides/guide_constants.csv``: crown length and width after
Nelson & Ash 2010, crest-to-CEJ distance after Hausmann et al. 1991, incisor
display after Vig & Brundo 1978).  Every measurement says how it was obtained.
"""

from __future__ import annotations

import json
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np
from scipy import sparse
from scipy.sparse.csgraph import connected_components

from workbench.core.data_paths import DEFAULT_DEPTH_TABLE, data_tables_dir
from workbench.core.errors import InputError
from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh
from workbench.core.raycast import RayCaster
from workbench.io.csv_rows import read_csv_rows
from workbench.io.tables import load_depth_table

CONSTANT_COLUMNS = ("name", "sex", "value", "unit", "source", "notes")
SIDES = (("l", 1.0), ("r", -1.0))
#: Implementation choices (not published numbers): rays and sections used on the mesh.
APERTURE_RIM_DEPTH_MM = 4.0  # a frontal ray hitting within this of the row's front is bone
SECTION_BELOW_CREST_MM = 3.0  # tooth section this far below prosthion (cervical third of crowns)
#: levels below prosthion of the horizontal rays that trace the outer dental arch (upper
#: crowns between the cemento-enamel junction and the contact areas)
ARCH_LEVELS_BELOW_CREST_MM = (2.5, 3.5, 4.5, 5.5)
ARCH_CENTRE_BEHIND_PR_MM = 25.0  # the rays aim at a point this far behind prosthion
ARCH_MAX_STEP_MM = 6.0  # a longer step between neighbouring rays is a gap (a missing tooth)
#: the arch's midline point may lie this far from where a crown below prosthion would be
MIN_CROWN_MM = 5.0
#: the labial face must go on this far below prosthion for upper incisor crowns to count
#: as present (the crest-to-CEJ 1.5 mm and 2 mm of crown: enough for a worn incisor or a
#: prosthion placed on the crown by a blurred CT, not for a bare alveolar ridge)
CROWN_CHECK_MM = 3.5


def guides_dir() -> Path:
    """Folder of the guide tables (``data_tables/guides``)."""
    return data_tables_dir() / "guides"


def read_table_csv(path: Path, columns: tuple[str, ...]) -> list[tuple[int, dict[str, str]]]:
    """``(line number, row)`` pairs; InputError naming the file for missing columns or ragged rows."""
    rows = read_csv_rows(path, columns, what="guide table", short_rows=False)
    return [(line, {k: v or "" for k, v in row.items()}) for line, row in rows]


def parse_number(path: Path, line: int, col: str, text: str, default: float | None = None) -> float:
    """``float(text)`` (``default`` when empty), else InputError naming file, line and column."""
    if not text and default is not None:
        return default
    try:
        return float(text)
    except ValueError:
        raise InputError(path, f"line {line}: {col} {text!r} is not a number") from None


@lru_cache(maxsize=1)
def guides_meta() -> dict:
    """``guides.meta.json`` (sources, where_read, predictor definitions)."""
    path = guides_dir() / "guides.meta.json"
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError) as exc:
        raise InputError(path, f"guide table metadata is not readable JSON ({exc})") from None


def citation(keys: str) -> str:
    """Full reference(s) for ``;``-separated source keys of the guide tables."""
    sources = guides_meta()["sources"]
    return "; ".join(sources.get(k, k) for k in keys.split(";") if k)


@lru_cache(maxsize=1)
def load_constants() -> dict[tuple[str, str], tuple[float, str]]:
    """``{(name, sex): (value, citation)}`` from ``guide_constants.csv``."""
    path = guides_dir() / "guide_constants.csv"
    return {
        (r["name"], r["sex"]): (
            parse_number(path, line, "value", r["value"]),
            citation(r["source"]),
        )
        for line, r in read_table_csv(path, CONSTANT_COLUMNS)
    }


def constant(name: str, sex: str | None = None) -> float:
    """A constant for ``sex`` ("M"/"F"); the pooled row, else the mean of the sexes."""
    table = load_constants()
    for key in ((name, sex or ""), (name, "pooled")):
        if key in table:
            return table[key][0]
    values = [v for (n, _), (v, _) in table.items() if n == name]
    if not values:
        raise KeyError(f"no guide constant {name!r}")
    return float(np.mean(values))


def sex_code(sex: str | None) -> str | None:
    """``"male"``/``"m"`` → ``"M"``, ``"female"``/``"f"`` → ``"F"``, None/"" → None."""
    if sex is None or str(sex).strip() == "":
        return None
    key = str(sex).strip().lower()
    if key in ("m", "male"):
        return "M"
    if key in ("f", "female"):
        return "F"
    raise InputError("sex", f"unknown sex {sex!r}", "use female, male or leave it out")


# ------------------------------------------------------------------ measurements
@dataclass(frozen=True)
class Measure:
    """A skull measurement (mm) and how it was obtained."""

    value: float
    how: str
    #: where it was taken (head frame, mm), to be shown on the skull; None: not a place
    at: tuple[float, float, float] | None = None


@dataclass
class SkullMeasures:
    """Named measurements; ``missing`` says why the others could not be taken."""

    values: dict[str, Measure] = field(default_factory=dict)
    missing: dict[str, str] = field(default_factory=dict)

    def __contains__(self, name: object) -> bool:
        return name in self.values

    def __getitem__(self, name: str) -> float:
        return self.values[name].value

    def put(
        self,
        name: str,
        value: float | None,
        how: str,
        why_missing: str = "",
        at: np.ndarray | tuple[float, float, float] | None = None,
    ) -> None:
        if value is None or not np.isfinite(value):
            self.missing[name] = why_missing or how
        else:
            where = None if at is None else (float(at[0]), float(at[1]), float(at[2]))
            self.values[name] = Measure(float(value), how, where)

    def numbers(self) -> dict[str, float]:
        return {k: m.value for k, m in self.values.items()}


def _pos(lms: LandmarkSet, code: str) -> np.ndarray | None:
    lm = lms.get(code)
    return lm.position if lm is not None and lm.is_defined else None


def _front_z(caster: RayCaster, xs: np.ndarray, ys: np.ndarray, z0: float) -> np.ndarray:
    """z of the first hit of rays cast backward (−z) from ``z0``.

    Shape ``(len(ys), len(xs))``; NaN where a ray misses.
    """
    gx, gy = np.meshgrid(xs, ys)
    origins = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, z0)])
    hits = caster.first_hits(origins, np.tile([0.0, 0.0, -1.0], (gx.size, 1)))
    return np.where(hits.hit, hits.points[:, 2], np.nan).reshape(gx.shape)


def _aperture_width(
    caster: RayCaster, z0: float, ys: np.ndarray, side: float
) -> tuple[float, np.ndarray] | None:
    """|x| of the widest aperture point on one side, seen from the front, and that
    point on the rim (head frame).

    Per row, rays step outward from 2 mm beside the midline; the aperture ends at
    the first ray that hits within :data:`APERTURE_RIM_DEPTH_MM` of the row's most
    anterior bone (the rim), while rays inside it pass deep into the nasal cavity.
    """
    xs = side * np.arange(2.0, 25.01, 0.5)
    best: tuple[float, np.ndarray] | None = None
    with np.errstate(invalid="ignore"):
        for y, row in zip(ys, _front_z(caster, xs, ys, z0), strict=True):
            if np.isnan(row).all():
                continue
            closed = row >= np.nanmax(row) - APERTURE_RIM_DEPTH_MM
            if closed[0] or not closed.any():
                continue
            k = int(np.argmax(closed))
            half = abs(xs[k]) - 0.25
            if best is None or half > best[0]:
                best = (half, np.array([side * half, y, row[k]]))
    return best


def _spine_base_z(caster: RayCaster, z0: float, ans: np.ndarray) -> float | None:
    """z of the lower aperture margin 4 mm either side of the spine (where it leaves the maxilla)."""
    ys = np.arange(ans[1] + 4.0, ans[1] - 12.0, -0.25)
    out = []
    with np.errstate(invalid="ignore"):
        for col in _front_z(caster, np.array([-4.0, 4.0]), ys, z0).T:
            front = col >= ans[2] - 15.0
            if not front[0] and front.any():  # open aperture above, bone below
                out.append(col[int(np.argmax(front))])
    return float(np.mean(out)) if out else None


def _incisal_edge_y(caster: RayCaster, z0: float, pr: np.ndarray) -> float | None:
    """y of the upper incisal edge: going down the labial face 2.5 mm either side of the
    midline, where the profile steps back by more than 1 mm (onto the lower incisors) or ends."""
    step = 0.2
    ys = np.arange(pr[1] - 2.0, pr[1] - 20.0, -step)
    edges = []
    with np.errstate(invalid="ignore"):
        for col in _front_z(caster, np.array([-2.5, 2.5]), ys, z0).T:
            if not np.isfinite(col[0]) or col[0] < pr[2] - 10.0:
                continue
            drop = np.flatnonzero(~(col[1:] >= col[:-1] - 1.0))
            if len(drop):
                edges.append(ys[drop[0]] - 0.5 * step)
    return float(np.mean(edges)) if edges else None


def _crowns_below(caster: RayCaster, z0: float, pr: np.ndarray) -> bool:
    """Whether the labial face goes on below prosthion without a gap for
    :data:`CROWN_CHECK_MM`: frontal rays 2.5 mm either side of the midline meet bone or
    tooth within 5 mm of prosthion's depth on 80 % of the rows.  Where the upper
    incisors are missing the maxilla ends within a millimetre or two of prosthion, and
    lower incisors standing below it (a closed edentulous mouth) are separated from it
    by a gap."""
    ys = np.arange(pr[1] - 0.5, pr[1] - CROWN_CHECK_MM - 0.01, -0.5)
    with np.errstate(invalid="ignore"):
        z = _front_z(caster, np.array([-2.5, 2.5]), ys, z0)
        return bool(np.mean(np.abs(z - pr[2]) <= 5.0) >= 0.8)


def dental_arch(caster: RayCaster, pr: np.ndarray) -> dict[str, np.ndarray] | None:
    """The outer (labial and buccal) outline of the upper dental arch, per side.

    Horizontal rays aimed at a point :data:`ARCH_CENTRE_BEHIND_PR_MM` behind
    prosthion, one per degree from straight ahead to 100 degrees either side, at
    the crown levels :data:`ARCH_LEVELS_BELOW_CREST_MM`; at each angle the outermost
    hit of the levels (gaps between crowns let single rays through), median-filtered
    over 5 degrees.  This works where the teeth of a CT surface are fused into one
    outline, which a section cannot split into crowns.  Per side ``"l"``/``"r"``:
    ``(k, 2)`` (x, z) points from the midline outward, ending at the first gap of
    more than :data:`ARCH_MAX_STEP_MM`; None when no crown stands at the midline
    (upper incisors missing).
    """
    angles = np.radians(np.arange(-100.0, 100.01, 1.0))
    d = np.column_stack([np.sin(angles), np.zeros_like(angles), np.cos(angles)])
    centre = np.array([0.0, 0.0, pr[2] - ARCH_CENTRE_BEHIND_PR_MM])
    radii = []
    for below in ARCH_LEVELS_BELOW_CREST_MM:
        c = centre + [0.0, pr[1] - below, 0.0]
        hits = caster.first_hits(c + 3.0 * ARCH_CENTRE_BEHIND_PR_MM * d, -d)
        # signed: a ray through a gap meets the far side of the arch behind the centre
        radii.append(np.where(hits.hit, np.einsum("ij,ij->i", hits.points - c, d), np.nan))
    with np.errstate(invalid="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # angles no level hit
        r = np.nanmax(np.array(radii), axis=0)
        r[~(r > 0.6 * ARCH_CENTRE_BEHIND_PR_MM)] = np.nan  # behind or well inside the arch
        # median over 5 degrees, kept where at least 3 of the 5 rays met a crown (a ray
        # between two crowns, as between the central incisors, takes its neighbours')
        window = np.lib.stride_tricks.sliding_window_view(np.pad(r, 2, mode="edge"), 5)
        ok = np.isfinite(window).sum(axis=1) >= 3
        r = np.where(ok, np.nanmedian(window, axis=1), np.nan)
    mid = len(angles) // 2
    if not ok[mid] or abs(r[mid] - ARCH_CENTRE_BEHIND_PR_MM) > MIN_CROWN_MM:
        return None
    pts = np.column_stack([r * np.sin(angles), centre[2] + r * np.cos(angles)])
    out = {}
    for side, step in (("l", 1), ("r", -1)):
        run = [pts[mid]]
        for k in range(mid + step, len(angles) if step > 0 else -1, step):
            if not ok[k]:
                continue
            if np.linalg.norm(pts[k] - run[-1]) > ARCH_MAX_STEP_MM:
                break
            run.append(pts[k])
        out[side] = np.array(run)
    return out


def _arch_canines(
    arch: Mapping[str, np.ndarray],
) -> dict[str, tuple[float, float, np.ndarray, np.ndarray]] | None:
    """Per side (x of the canine's lateral aspect, x of the canine–premolar junction)
    along the arch outline, by the crowns' mesiodistal widths (Nelson & Ash 2010):
    the canine spans the arch length from central + lateral incisor to central +
    lateral incisor + canine, measured from the midline; its lateral aspect is the
    outline's widest point over that span, the junction the point at its end; then
    both points (x, z) on the outline.  None when the outline ends before it (a gap:
    missing teeth)."""
    w1, w2, w3 = (
        constant(f"upper_{t}_crown_md") for t in ("central_incisor", "lateral_incisor", "canine")
    )
    out = {}
    for side, run in arch.items():
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(run, axis=0), axis=1))])
        if s[-1] < w1 + w2 + w3:
            return None
        span = (s >= w1 + w2) & (s <= w1 + w2 + w3)
        sign = 1.0 if side == "l" else -1.0
        widest = np.flatnonzero(span)[int(np.argmax(sign * run[span, 0]))]
        at_junction = np.array(
            [np.interp(w1 + w2 + w3, s, run[:, 0]), np.interp(w1 + w2 + w3, s, run[:, 1])]
        )
        out[side] = (float(run[widest, 0]), float(at_junction[0]), run[widest], at_junction)
    return out


def section_loops(mesh: Mesh, y: float) -> list[np.ndarray]:
    """Connected pieces of the section of ``mesh`` with the plane ``y``: ``(k, 2)`` (x, z) each."""
    s = mesh.vertices[:, 1] - y
    s[s == 0.0] = 1e-9
    sf = s[mesh.faces]
    faces = mesh.faces[(sf.min(axis=1) < 0) & (sf.max(axis=1) > 0)]
    if not len(faces):
        return []
    edges = np.stack([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]], axis=1)
    crossing = (s[edges[..., 0]] < 0) != (s[edges[..., 1]] < 0)  # two per face
    pairs = np.sort(edges[crossing].reshape(-1, 2), axis=1)
    uniq, inv = np.unique(pairs, axis=0, return_inverse=True)
    inv = inv.ravel()
    a, b = uniq[:, 0], uniq[:, 1]
    t = s[a] / (s[a] - s[b])
    pts = mesh.vertices[a] + t[:, None] * (mesh.vertices[b] - mesh.vertices[a])
    n = len(uniq)
    graph = sparse.coo_matrix((np.ones(len(inv) // 2), (inv[0::2], inv[1::2])), shape=(n, n))
    _, label = connected_components(graph, directed=False)
    return [pts[label == k][:, [0, 2]] for k in np.unique(label)]


def _canines(mesh: Mesh, pr: np.ndarray) -> dict[str, tuple[float, float]] | None:
    """Per side: (x of the canine's lateral aspect, x of the canine–first-premolar junction).

    The tooth crowns are cut :data:`SECTION_BELOW_CREST_MM` below prosthion, where
    neighbouring crowns (narrower at the cervix than at their contacts) are separate
    outlines.  Outlines of tooth size in front of the arch are ordered by their angle
    around a point 30 mm behind prosthion: the third on each side is the canine (a
    single outline across the midline counts as both central incisors).
    """
    centre_z = pr[2] - 30.0
    teeth = []
    for loop in section_loops(mesh, pr[1] - SECTION_BELOW_CREST_MM):
        c = loop.mean(axis=0)
        size = float(np.linalg.norm(loop.max(axis=0) - loop.min(axis=0)))
        if 2.5 <= size <= 15.0 and c[1] > pr[2] - 35.0 and abs(c[0]) < 35.0:
            teeth.append((float(np.arctan2(c[0], c[1] - centre_z)), loop))
    out = {}
    for side, sign in SIDES:
        row = sorted(
            (
                (abs(a), lp)
                for a, lp in teeth
                if sign * lp[:, 0].mean() > 0 or (lp[:, 0].min() < -1 and lp[:, 0].max() > 1)
            ),
            key=lambda item: item[0],
        )
        if len(row) < 3:
            return None
        canine = row[2][1]
        lateral = float(sign * (sign * canine[:, 0]).max())
        junction = lateral
        if len(row) > 3:  # the middle of the closest pair of canine and premolar points
            d = np.linalg.norm(canine[:, None, :] - row[3][1][None, :, :], axis=2)
            i, j = np.unravel_index(int(np.argmin(d)), d.shape)
            junction = float(0.5 * (canine[i, 0] + row[3][1][j, 0]))
        out[side] = (lateral, junction)
    return out


#: measurements shown on the skull (the guide view): name -> short label
MARKED = {
    "aperture_x_l": "widest aperture",
    "aperture_x_r": "widest aperture",
    "spine_projection": "nasal spine",
    "canine_x_l": "canine",
    "canine_x_r": "canine",
    "cp_junction_x_l": "canine-premolar",
    "cp_junction_x_r": "canine-premolar",
    "upper_cej_y": "upper CEJ",
    "incisal_edge_y": "incisal edge",
    "lower_cej_y": "lower CEJ",
}


def measurement_marks(m: SkullMeasures) -> list[tuple[str, np.ndarray, str]]:
    """(label, point in the head frame, how it was taken) for every measurement of
    :data:`MARKED` that has a place: what the guide view draws on the skull."""
    return [
        (MARKED[name], np.array(m.values[name].at), m.values[name].how)
        for name in MARKED
        if name in m.values and m.values[name].at is not None
    ]


def marks_for_view(
    lms_h: LandmarkSet, skull_h: Mesh, sex: str | None = None
) -> tuple[list[tuple[str, np.ndarray, str]], list[str]]:
    """What the guide view shows of the skull measurements: the marks of
    :func:`measurement_marks`, and one line per guide measurement that could not be
    taken, with why (head frame, mm)."""
    m = measure_skull(lms_h, skull_h, sex=sex)
    wanted = (*MARKED, "intercanine_width")
    seen: set[str] = set()
    missing = []
    for name in wanted:
        why = m.missing.get(name)
        if why and why not in seen:  # one line per reason (left and right share theirs)
            seen.add(why)
            missing.append(f"{MARKED.get(name, name.replace('_', ' '))}: {why}")
    return measurement_marks(m), missing


def measure_skull(
    lms: LandmarkSet,
    skull: Mesh | None = None,
    *,
    dowel_tips: Mapping[str, np.ndarray] | None = None,
    sex: str | None = None,
    table_id: str = DEFAULT_DEPTH_TABLE,
) -> SkullMeasures:
    """Everything the guide rules need, from landmarks, the mesh (optional) and cited constants."""
    sex = sex_code(sex)
    m = SkullMeasures()
    p: dict[str, np.ndarray] = {}
    for c in lms.codes:
        pos = _pos(lms, c)
        if pos is not None:
            p[c] = pos
    caster: RayCaster | None = None
    z0 = 0.0
    if skull is not None and skull.n_faces:
        caster = RayCaster.shared(skull)
        z0 = float(skull.vertices[:, 2].max() + 5.0)

    _measure_nose_width(m, p, caster, z0)
    _measure_spine_and_philtrum(m, p, caster, z0, dowel_tips, table_id)
    # teeth: CEJ lines from the alveolar crests, incisal edge, canines
    arch, upper_teeth, no_upper = _measure_incisors(m, p, caster, z0, sex)
    _measure_canines(m, p, skull, caster, arch, upper_teeth, no_upper)
    _measure_rynn_distances(m, p)
    _measure_orbits(m, p)
    return m


def _measure_nose_width(
    m: SkullMeasures, p: Mapping[str, np.ndarray], caster: RayCaster | None, z0: float
) -> None:
    """The widest nasal aperture (head frame x, mm): frontal rays on the mesh from ``z0``
    in front of it, else the bony alare apl_l/apl_r."""
    ys = None
    if caster is not None and ("ans" in p or "apl_l" in p or "apl_r" in p):
        lo = p["ans"][1] if "ans" in p else min(p[c][1] for c in ("apl_l", "apl_r") if c in p) - 15
        hi = p["rhi"][1] if "rhi" in p else lo + 40.0
        ys = np.arange(lo, hi, 0.5)
    for side, sign in SIDES:
        got = (
            _aperture_width(caster, z0, ys, sign) if caster is not None and ys is not None else None
        )
        if got is not None:
            m.put(
                f"aperture_x_{side}",
                sign * got[0],
                "widest nasal aperture in the frontal view (rays on the skull mesh)",
                at=got[1],
            )
        elif f"apl_{side}" in p:
            m.put(
                f"aperture_x_{side}",
                p[f"apl_{side}"][0],
                f"bony alare apl_{side} (most lateral aperture point)",
            )
        else:
            m.put(f"aperture_x_{side}", None, "", f"no skull mesh aperture and no apl_{side}")

    if "aperture_x_l" in m and "aperture_x_r" in m:
        m.put(
            "aperture_width",
            m["aperture_x_l"] - m["aperture_x_r"],
            "widest nasal aperture, left minus right",
        )
    else:
        m.missing["aperture_width"] = m.missing.get(
            "aperture_x_l", m.missing.get("aperture_x_r", "no aperture width")
        )


def _measure_spine_and_philtrum(
    m: SkullMeasures,
    p: Mapping[str, np.ndarray],
    caster: RayCaster | None,
    z0: float,
    dowel_tips: Mapping[str, np.ndarray] | None,
    table_id: str,
) -> None:
    """The anterior nasal spine (tip = ans, base = front of the maxilla beneath it) and
    the mid-philtrum dowel tip's depth z (given, else skull mp plus the table's mean
    depth parallel to FH), mm."""
    if "ans" in p:
        m.put("ans_y", p["ans"][1], "anterior nasal spine tip ans")
        m.put("ans_z", p["ans"][2], "anterior nasal spine tip ans")
        base = _spine_base_z(caster, z0, p["ans"]) if caster is not None else None
        how = "lower aperture margin beside the spine (rays on the skull mesh)"
        if base is None and "ss" in p:
            base, how = p["ss"][2], "depth of subspinale ss (no mesh margin found)"
        m.put(
            "spine_projection",
            None if base is None else p["ans"][2] - base,
            f"ans z minus the spine base z; base from the {how}",
            "no spine base (mesh or ss)",
            at=p["ans"],
        )
    else:
        m.missing["spine_projection"] = "no anterior nasal spine ans"
    if dowel_tips is not None and "mp" in dowel_tips:
        m.put(
            "mp_dowel_z",
            float(np.asarray(dowel_tips["mp"], float)[2]),
            "mid-philtrum dowel tip (given)",
        )
    elif "mp" in p:
        depth = load_depth_table(table_id).lookup(None).get("mp")
        m.put(
            "mp_dowel_z",
            None if depth is None else p["mp"][2] + depth[0],
            f"skull mp + {depth[0] if depth else '?'} mm ({table_id} mean) parallel to FH",
            f"table {table_id} has no mp depth",
        )
    else:
        m.missing["mp_dowel_z"] = "no mid-philtrum landmark mp and no dowel tip"


def _measure_incisors(
    m: SkullMeasures,
    p: Mapping[str, np.ndarray],
    caster: RayCaster | None,
    z0: float,
    sex: str | None,
) -> tuple[dict[str, np.ndarray] | None, bool, str]:
    """The CEJ lines from the alveolar crests, the upper incisal edge and the incisor
    display (y, mm).

    Returns the upper dental arch traced on the mesh (None without one),
    whether upper teeth are there (always assumed without a mesh) and the
    reason given when they are not.
    """
    crest = constant("cej_below_alveolar_crest")
    no_upper = (
        "no upper incisor crowns on the skull mesh (the labial face ends within "
        f"{CROWN_CHECK_MM} mm below prosthion pr, or the dental arch has no tooth at the "
        "midline: teeth missing?)"
    )
    arch = (
        dental_arch(caster, p["pr"])
        if caster is not None and "pr" in p and _crowns_below(caster, z0, p["pr"])
        else None
    )
    upper_teeth = caster is None or arch is not None
    if "pr" in p:
        edge = _incisal_edge_y(caster, z0, p["pr"]) if upper_teeth and caster is not None else None
        crown = constant("upper_central_incisor_crown_length")
        m.put(
            "upper_cej_y",
            p["pr"][1] - crest if upper_teeth else None,
            f"prosthion pr − {crest} mm (crest to CEJ)",
            no_upper,
            at=p["pr"] - [0.0, crest, 0.0],
        )
        m.put(
            "incisal_edge_y",
            edge if edge is not None else p["pr"][1] - crest - crown if caster is None else None,
            "incisal edge of the upper central incisors (rays on the skull mesh)"
            if edge is not None
            else f"upper CEJ − {crown} mm crown length (no skull mesh)",
            no_upper,
            at=None if edge is None else (p["pr"][0], edge, p["pr"][2]),
        )
    else:
        for k in ("upper_cej_y", "incisal_edge_y"):
            m.missing[k] = "no prosthion pr (upper alveolar crest)"
    if "id" in p:
        m.put(
            "lower_cej_y",
            p["id"][1] + crest,
            f"infradentale id + {crest} mm (crest to CEJ)",
            at=p["id"] + [0.0, crest, 0.0],
        )
    else:
        m.missing["lower_cej_y"] = "no infradentale id (mandible missing?)"
    m.put(
        "incisor_display",
        constant("incisor_display_at_rest", sex),
        f"incisor display at rest ({sex or 'sex unknown: mean of men and women'})",
    )
    return arch, upper_teeth, no_upper


def _measure_canines(
    m: SkullMeasures,
    p: Mapping[str, np.ndarray],
    skull: Mesh | None,
    caster: RayCaster | None,
    arch: dict[str, np.ndarray] | None,
    upper_teeth: bool,
    no_upper: str,
) -> None:
    """The upper canines' lateral aspects and the canine–premolar junctions (x, mm) and
    the widths between them: from the mesh's crown section, else the traced arch, else
    (without a mesh) the supracanine landmarks sC plus half a canine crown."""
    # crowns are counted from the midline: without the incisors the third is a premolar
    found: dict[str, tuple[float, float]] | None = (
        _canines(skull, p["pr"]) if skull is not None and "pr" in p and upper_teeth else None
    )
    where = "crown section of the mesh"
    traced = _arch_canines(arch) if arch is not None else None
    if found is None and traced is not None:
        found = {side: (t[0], t[1]) for side, t in traced.items()}
        where = "outer dental arch traced by rays, crown widths after Nelson & Ash 2010"
    level = p["pr"][1] - float(np.mean(ARCH_LEVELS_BELOW_CREST_MM)) if "pr" in p else 0.0

    def on_arch(side: str, k: int) -> tuple[float, float, float] | None:
        """Where the arch puts a canine point (x as measured, level, z), shown on the skull."""
        if traced is None or found is None:
            return None
        xz = traced[side][3] if k else traced[side][2]
        return (found[side][k], level, float(xz[1]))

    half_md = 0.5 * constant("upper_canine_crown_md")
    for side, sign in SIDES:
        if found is not None:
            m.put(
                f"canine_x_{side}",
                found[side][0],
                f"lateral aspect of the upper canine ({where})",
                at=on_arch(side, 0),
            )
            m.put(
                f"cp_junction_x_{side}",
                found[side][1],
                f"canine–first-premolar junction ({where})",
                at=on_arch(side, 1),
            )
        elif caster is not None and "pr" in p:
            why = (
                no_upper
                if not upper_teeth
                else "the upper dental arch has a gap before the canine (teeth missing?)"
            )
            for k in ("canine_x", "cp_junction_x"):
                m.missing[f"{k}_{side}"] = why
        elif f"sC_{side}" in p:
            at_x = _canine_from_supracanine(p, side, sign, half_md)
            how = (
                f"supracanine sC_{side} + half the canine crown width ({half_md} mm) along the arch"
            )
            m.put(f"canine_x_{side}", at_x, how)
            m.put(f"cp_junction_x_{side}", at_x, how)
        else:
            for k in ("canine_x", "cp_junction_x"):
                m.missing[f"{k}_{side}"] = f"no tooth crowns on a mesh and no sC_{side}"
    for side, _ in SIDES:
        for width, x in (("intercanine_width", "canine_x"), ("cp_junction_width", "cp_junction_x")):
            if f"{x}_{side}" not in m and width not in m.missing:
                m.missing[width] = m.missing.get(f"{x}_{side}", f"no {x}_{side}")
    if "canine_x_l" in m and "canine_x_r" in m:
        m.put(
            "intercanine_width", m["canine_x_l"] - m["canine_x_r"], "lateral aspects of the canines"
        )
        m.put(
            "cp_junction_width",
            m["cp_junction_x_l"] - m["cp_junction_x_r"],
            "canine–premolar junctions",
        )


def _canine_from_supracanine(
    p: Mapping[str, np.ndarray], side: str, sign: float, half_md: float
) -> float:
    """The canine's lateral aspect x (mm) from supracanine sC: half a canine crown
    (``half_md``) along the arch, whose direction at the canine is taken from
    pr → sC → ecm2s when those are placed (else straight lateral)."""
    sc = p[f"sC_{side}"][[0, 2]]
    lateral = 1.0
    if "pr" in p and f"ecm2s_{side}" in p:
        d1 = sc - p["pr"][[0, 2]]
        d2 = p[f"ecm2s_{side}"][[0, 2]] - sc
        t = d1 / np.linalg.norm(d1) + d2 / np.linalg.norm(d2)
        lateral = abs(t[0]) / np.linalg.norm(t)
    return sc[0] + sign * half_md * lateral


def _measure_rynn_distances(m: SkullMeasures, p: Mapping[str, np.ndarray]) -> None:
    """Rynn et al. 2010's distances X (n–ans), Y (rhi–ss), Z (n–ss) and the heights and
    depths of n, pr and ss they are laid off from (mm)."""
    for name, (a, b) in {"X": ("n", "ans"), "Y": ("rhi", "ss"), "Z": ("n", "ss")}.items():
        if a in p and b in p:
            m.put(name, float(np.linalg.norm(p[a] - p[b])), f"distance {a}–{b}")
        else:
            m.missing[name] = f"needs {a} and {b}"
    if "n" in p and "pr" in p:
        for code in ("n", "pr"):
            m.put(f"{code}_y", p[code][1], f"{code} landmark")
            m.put(f"{code}_z", p[code][2], f"{code} landmark")
    if "ss" in p:
        m.put("ss_z", p["ss"][2], "subspinale ss")


def _measure_orbits(m: SkullMeasures, p: Mapping[str, np.ndarray]) -> None:
    """Orbit heights and breadths, centres and the mso–or tangent per side (mm;
    supraconchion ≈ mso, dlom ≈ ec, see guides.meta.json)."""
    for side, _ in SIDES:
        need = [f"{c}_{side}" for c in ("mso", "or", "d", "ec")]
        if not all(c in p for c in need):
            m.missing[f"OBH_{side}"] = f"needs {', '.join(need)}"
            continue
        mso, orb, d, ec = (p[c] for c in need)
        m.put(f"OBH_{side}", mso[1] - orb[1], f"y of mso_{side} − y of or_{side}")
        m.put(f"OBB_{side}", float(np.linalg.norm(ec - d)), f"distance d_{side}–ec_{side}")
        m.put(f"sk_y_{side}", mso[1], f"mso_{side} for supraconchion")
        m.put(f"d_x_{side}", d[0], f"dacryon d_{side}")
        m.put(f"dlom_z_{side}", ec[2], f"ectoconchion ec_{side} for dlom")
        cy = 0.5 * (mso[1] + orb[1])
        m.put(f"orbit_cx_{side}", 0.5 * (d[0] + ec[0]), "middle of d and ec")
        m.put(f"orbit_cy_{side}", cy, "middle of mso and or")
        m.put(
            f"tangent_z_{side}",
            orb[2] + (cy - orb[1]) * (mso[2] - orb[2]) / (mso[1] - orb[1]),
            "mso–or tangent at mid-orbit height",
        )
