"""The library of brow shapes, hair styles, beards and moustaches, and :func:`groom`.

**Artistic additions, not evidence.**  A skull does not say whether a person
had hair, how they wore it, or what their brows looked like; a style chosen
here is the artist's choice, and the window and the report say so
(:data:`ARTISTIC_NOTE`).  Every number below (lengths, densities, heights of
the hairline and beard line) is a default picked by eye on the reference
heads so the styles read as what their names say; none is a measurement.

Each piece is a set of strands (:mod:`workbench.core.grooming.strands`)
rooted on the skin and tied to it (:class:`~workbench.core.grooming.shell.ShellPoints`),
so the brows, hair and beard follow the face through build variants, age
change and expressions: :meth:`Grooming.meshes` rebuilds them on any skin
with the head's triangles.

Units: millimetres; densities in strands per mm² of skin.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field

import numpy as np

from workbench.core.grooming.placement import (
    GroomingError,
    Landmarks,
    Marks,
    azimuth_deg,
    check_landmarks,
    hairline_height,
    marks,
    near_any,
    smooth_above,
)
from workbench.core.grooming.shell import ShellPoints, _unit
from workbench.core.grooming.strands import grow_strands, ribbons
from workbench.core.mesh import Mesh

#: the kinds of piece, in the order they are drawn
KINDS = ("hair", "brows", "beard", "moustache")
NONE = "none"
ARTISTIC_NOTE = (
    "Hair, brows and beard are artistic additions, not evidence: a skull does not "
    "show whether the person had them or how they were worn."
)


@dataclass(frozen=True)
class Style:
    """One entry of the library: how its strands are rooted and grown.

    ``density`` strands per mm²; ``length``, ``lift`` (the layer height
    strands settle at, the volume) and ``width`` (of a ribbon at its root) in
    mm; ``gravity`` in 1/mm; ``comb`` the first direction as weights
    (down, back, away from the parting); ``shape`` style-specific numbers.
    """

    kind: str
    name: str
    title: str
    density: float
    length: tuple[float, float]
    lift: tuple[float, float]
    width: float
    gravity: float = 0.0
    segments: int = 6
    comb: tuple[float, float, float] = (1.0, 0.0, 0.0)
    tip_width: float = 0.3
    shape: Mapping[str, float] = field(default_factory=dict)
    hug: float = np.inf


def _styles(*styles: Style) -> dict[str, Style]:
    return {s.name: s for s in styles}


HAIR = _styles(
    Style("hair", "buzz", "Buzz cut", 0.35, (3.0, 5.0), (0.3, 0.9), 0.55, segments=2,
          comb=(0.6, 1.0, 0.0), hug=0.3),
    Style("hair", "short", "Short", 0.2, (18.0, 32.0), (1.0, 5.0), 1.6, gravity=0.004,
          segments=6, comb=(0.5, 1.0, 0.4), shape={"part": 25.0, "taper": 0.45}, hug=1.0),
    Style("hair", "medium", "Medium (over the ears)", 0.12, (70.0, 120.0), (2.0, 9.0), 1.7,
          gravity=0.012, segments=10, comb=(0.8, 0.6, 0.5), shape={"part": 25.0, "taper": 0.8,
          "hang_gravity": 0.06, "back": 0.8}, hug=2.0),
    Style("hair", "long", "Long (to the shoulders)", 0.08, (150.0, 260.0), (2.0, 10.0), 1.7,
          gravity=0.02, segments=14, comb=(0.9, 0.5, 0.4), shape={"part": 0.0,
          "hang_gravity": 0.06, "back": 0.8}, hug=2.5),
    Style("hair", "bald_pattern", "Bald pattern (horseshoe)", 0.3, (10.0, 18.0), (0.8, 3.0),
          1.1, gravity=0.004, segments=6, comb=(1.0, 0.6, 0.0), shape={"crown": 0.42},
          hug=0.8),
)  # fmt: skip
BROWS = _styles(
    Style("brows", "straight", "Straight", 3.0, (5.0, 8.0), (0.2, 0.6), 0.2, segments=4,
          shape={"arch": 0.0, "thick": 1.0, "tail": 0.0}, hug=0.3),
    Style("brows", "soft_arch", "Soft arch", 3.0, (5.0, 8.0), (0.2, 0.6), 0.2, segments=4,
          shape={"arch": 2.5, "thick": 1.0, "tail": 2.0}, hug=0.3),
    Style("brows", "high_arch", "High arch", 3.0, (4.0, 7.0), (0.2, 0.5), 0.18, segments=4,
          shape={"arch": 5.0, "thick": 0.8, "tail": 4.0}, hug=0.3),
    Style("brows", "thick", "Thick, low", 3.5, (6.0, 10.0), (0.3, 0.9), 0.22, segments=4,
          shape={"arch": 0.5, "thick": 1.5, "tail": 0.5}, hug=0.4),
    Style("brows", "thin", "Thin", 3.0, (4.0, 6.0), (0.2, 0.4), 0.16, segments=4,
          shape={"arch": 2.0, "thick": 0.55, "tail": 2.5}, hug=0.2),
)  # fmt: skip
BEARDS = _styles(
    Style("beard", "stubble", "Stubble", 1.1, (0.8, 1.8), (0.05, 0.2), 0.14, segments=2,
          comb=(1.0, 0.0, 0.0), tip_width=0.6, hug=0.2),
    Style("beard", "short", "Short beard", 0.55, (5.0, 9.0), (0.4, 2.0), 0.42, segments=3,
          comb=(1.0, 0.0, 0.0), hug=1.0),
    Style("beard", "full", "Full beard", 0.45, (16.0, 28.0), (1.0, 6.0), 0.7, gravity=0.01,
          segments=6, comb=(1.0, -0.2, 0.0), hug=4.0),
    Style("beard", "goatee", "Goatee", 0.8, (6.0, 12.0), (0.5, 2.5), 0.35, segments=4,
          comb=(1.0, 0.0, 0.0), shape={"goatee": 1.0}, hug=1.5),
)  # fmt: skip
MOUSTACHES = _styles(
    Style("moustache", "short", "Short moustache", 1.2, (4.0, 8.0), (0.3, 1.5), 0.3,
          segments=4, comb=(1.0, 0.0, 0.35), hug=0.8),
    Style("moustache", "full", "Full moustache", 1.2, (9.0, 14.0), (0.6, 3.0), 0.35,
          gravity=0.01, segments=5, comb=(1.0, -0.1, 0.45), hug=2.5),
)  # fmt: skip
LIBRARY: Mapping[str, Mapping[str, Style]] = {
    "hair": HAIR,
    "brows": BROWS,
    "beard": BEARDS,
    "moustache": MOUSTACHES,
}


def style_names(kind: str) -> tuple[str, ...]:
    """``("none", ...)`` the choices for ``kind``."""
    return (NONE, *LIBRARY[kind])


def check_style(kind: str, name: str) -> str:
    if kind not in LIBRARY:
        raise GroomingError("style", f"unknown kind {kind!r}", f"use {', '.join(KINDS)}")
    if name != NONE and name not in LIBRARY[kind]:
        raise GroomingError(
            f"{kind} style", f"unknown {name!r}", f"use one of {', '.join(style_names(kind))}"
        )
    return name


# ------------------------------------------------------------------ regions
Region = Callable[[np.ndarray, np.ndarray], np.ndarray]  # (points, coords) -> weight 0..1


@dataclass(frozen=True)
class HeadParts:
    """What placement needs of a head besides its skin: landmarks and vertex regions."""

    landmarks: Landmarks
    regions: Mapping[str, np.ndarray]


def _region_points(skin: Mesh, parts: HeadParts, names: tuple[str, ...]) -> np.ndarray:
    ids = [np.asarray(parts.regions[n], np.int64) for n in names if n in parts.regions]
    return skin.vertices[np.concatenate(ids)] if ids else np.zeros((0, 3))


def _scalp_region(style: Style, m: Marks, skin: Mesh, parts: HeadParts) -> Region:
    ears = _region_points(skin, parts, ("ear_l", "ear_r"))
    crown = style.shape.get("crown")
    t, v = m.y("t"), m.y("v")

    def weight(p: np.ndarray, c: np.ndarray) -> np.ndarray:
        az = azimuth_deg(c)
        w = smooth_above(c[:, 1], hairline_height(m, az), 2.0)
        if crown is not None:  # a horseshoe: sides and back below the crown, nothing in front
            top = t + crown * (v - t) + 12.0 * np.clip((az - 100.0) / 80.0, 0.0, 1.0)
            w *= 1.0 - smooth_above(c[:, 1], top, 4.0)
            w *= smooth_above(az, 72.0, 6.0)
        w[near_any(p, ears, 5.0)] = 0.0
        return w

    return weight


def _beard_region(style: Style, m: Marks, skin: Mesh, parts: HeadParts) -> Region:
    lips = _region_points(skin, parts, ("upper_lip", "lower_lip"))
    ears = _region_points(skin, parts, ("ear_l", "ear_r"))
    sn, ch, li, gn, sba = m.y("sn"), m.y("ch"), m.y("li"), m.y("gn"), m.y("sba")
    go = m.y("go") if "go" in m.at else gn + 0.4 * (sba - gn)
    chk = m.y("chk") if "chk" in m.at else ch + 20.0
    az_ch, az_sba = m.az("ch"), m.az("sba")
    az_chk = m.az("chk") if "chk" in m.at else 0.5 * (az_ch + az_sba)
    goatee = style.shape.get("goatee")
    x_ch = m.x("ch")

    def weight(p: np.ndarray, c: np.ndarray) -> np.ndarray:
        az = azimuth_deg(c)
        upper = np.interp(
            az, [0.0, az_ch, az_chk, az_sba], [sn - 3.0, ch + 12.0, ch + 0.45 * (chk - ch), sba]
        )
        lower = np.interp(az, [0.0, az_ch, az_sba], [gn - 38.0, gn - 30.0, go - 18.0])
        w = (1.0 - smooth_above(c[:, 1], upper, 2.0)) * smooth_above(c[:, 1], lower, 3.0)
        w *= 1.0 - smooth_above(az, az_sba + 4.0, 3.0)
        # only the skin in front of the neck's side: not behind the jaw's angle
        w *= smooth_above(c[:, 2], m.at["sba"][2] - 4.0, 3.0)
        if goatee is not None:
            w *= 1.0 - smooth_above(np.abs(c[:, 0]), 0.85 * x_ch, 2.0)
            w *= 1.0 - smooth_above(c[:, 1], li, 2.0)
        w[near_any(p, lips, 1.5)] = 0.0
        w[near_any(p, ears, 4.0)] = 0.0
        return w

    return weight


def _moustache_region(style: Style, m: Marks, skin: Mesh, parts: HeadParts) -> Region:
    lips = _region_points(skin, parts, ("upper_lip", "lower_lip"))
    sn, ls, x_ch = m.y("sn"), m.y("ls"), m.x("ch")
    # the nostril sills: no hair within 2.5 mm of subnasale (sn is one of NEEDED)
    nose = np.asarray(parts.landmarks["sn"], float).reshape(1, 3)
    x_al = m.x("al") if "al" in m.at else 0.6 * x_ch

    def weight(p: np.ndarray, c: np.ndarray) -> np.ndarray:
        w = smooth_above(c[:, 1], ls + 0.5, 1.0) * (1.0 - smooth_above(c[:, 1], sn - 1.5, 1.0))
        # the top edge follows the nostrils out to the alae, then drops towards the corners
        w *= 1.0 - smooth_above(np.abs(c[:, 0]), x_ch + 2.0, 1.5)
        w *= smooth_above(c[:, 2], m.at["ch"][2] - 8.0, 2.0)
        wide = np.abs(c[:, 0]) > x_al
        w[wide] *= 1.0 - smooth_above(
            c[wide, 1], sn - 4.0 - 4.0 * (np.abs(c[wide, 0]) - x_al) / max(x_ch - x_al, 1.0), 1.0
        )
        w[near_any(p, lips, 1.0)] = 0.0
        w[near_any(p, nose, 2.5)] = 0.0
        return w

    return weight


# ------------------------------------------------------------------ sampling
def _sample(skin: Mesh, density: float, region: Region, m: Marks, rng: np.random.Generator
            ) -> np.ndarray:  # fmt: skip
    """Roots ``(k, 3)``: area-uniform points on the skin kept with the region's weight."""
    v = skin.vertices
    vertex_w = region(v, m.axes.coords(v))
    faces = skin.faces[vertex_w[skin.faces].max(axis=1) > 0.0]
    if len(faces) == 0:
        return np.zeros((0, 3))
    tri = v[faces]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    n = int(rng.poisson(density * area.sum()))
    pick = rng.choice(len(faces), size=n, p=area / area.sum())
    r1, r2 = rng.random(n), rng.random(n)
    s = np.sqrt(r1)
    b = np.stack([1.0 - s, s * (1.0 - r2), s * r2], axis=1)
    pts = np.einsum("kj,kjd->kd", b, tri[pick])
    keep = rng.random(n) < region(pts, m.axes.coords(pts))
    return pts[keep]


# ------------------------------------------------------------------ pieces
@dataclass(frozen=True)
class HairPiece:
    """One piece (hair, brows, beard or moustache) as strands tied to the skin.

    ``shell`` holds ``strands * points`` points, strand by strand;
    ``widths`` and ``shade`` (a brightness factor near 1) are per strand;
    ``cover`` (per skin vertex, 0-1) is how much of the skin the piece grows
    from, for painting the skin under it in the hair's colour.
    """

    kind: str
    style: str
    shell: ShellPoints
    strands: int
    points: int
    widths: np.ndarray
    shade: np.ndarray
    tip_width: float
    cover: np.ndarray
    tilt: np.ndarray | None = None

    def mesh(
        self,
        vertices: np.ndarray,
        faces: np.ndarray,
        normals: np.ndarray | None = None,
        stride: int = 1,
    ) -> Ribbons:
        """The piece's ribbons on the skin ``vertices`` (same triangles as when grown);
        ``stride`` > 1 keeps every so many strands (a lighter preview)."""
        keep = np.arange(0, self.strands, max(1, int(stride)))
        rows = (keep[:, None] * self.points + np.arange(self.points)[None, :]).ravel()
        shell = self.shell if len(keep) == self.strands else self.shell.subset(rows)
        pts, nrm = shell.evaluate(vertices, faces, normals)
        shape = (len(keep), self.points, 3)
        tilt = None if self.tilt is None else self.tilt[keep]
        verts, tris, along, shading = ribbons(
            pts.reshape(shape), nrm.reshape(shape), self.widths[keep], self.tip_width, tilt
        )
        shade = np.repeat(self.shade[keep], self.points * 2)
        return Ribbons(Mesh(verts, tris), along, shade, shading)


@dataclass(frozen=True, eq=False)
class Ribbons:
    """A piece drawn: the ribbon mesh (mm), each vertex's place along its strand (0
    root, 1 tip), its strand's shade (brightness factor) and its shading normal (the
    skin normal under it, leant towards the ribbon's edge so it is lit as a round
    strand: :func:`~workbench.core.grooming.strands.ribbons`)."""

    mesh: Mesh
    along: np.ndarray
    shade: np.ndarray
    normals: np.ndarray


@dataclass(frozen=True)
class Grooming:
    """The pieces chosen for one head (empty when every choice is ``none``)."""

    choice: Mapping[str, str]
    pieces: tuple[HairPiece, ...]

    def meshes(
        self, vertices: np.ndarray, faces: np.ndarray, *, stride: int = 1
    ) -> dict[str, Ribbons]:
        """``{kind: ribbons}`` on the skin ``vertices`` (see :meth:`HairPiece.mesh`);
        ``stride`` thins the scalp hair only (brows and beards are small)."""
        from workbench.core.grooming.shell import vertex_normals_of

        normals = vertex_normals_of(vertices, faces)
        return {
            p.kind: p.mesh(vertices, faces, normals, stride if p.kind == "hair" else 1)
            for p in self.pieces
            if p.strands
        }

    @property
    def empty(self) -> bool:
        return not any(p.strands for p in self.pieces)


def _brow_piece(style: Style, skin: Mesh, parts: HeadParts, m: Marks, rng: np.random.Generator
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """Roots, first directions and lengths of both brows."""
    lm = parts.landmarks
    ax = m.axes
    arch, thick, tail_drop = (style.shape[k] for k in ("arch", "thick", "tail"))
    roots, dirs, lengths = [], [], []
    for side in ("l", "r"):
        codes = [f"{c}_{side}" for c in ("sci", "scl", "mso", "en", "ex")]
        check_landmarks(lm, tuple(codes), "brows")
        sci, scl, mso, en, ex = (ax.coords(np.asarray(lm[c], float))[0] for c in codes)
        half = float(np.clip((sci[1] - mso[1]) / 2.0, 2.5, 6.0))
        width = abs(ex[0] - en[0])
        sign = 1.0 if ex[0] >= en[0] else -1.0
        medial = np.array([en[0] - sign * 1.0, mso[1] + half, sci[2]])
        peak = scl - np.array([0.0, half - arch, 0.0])
        tail = scl + np.array([sign * 0.35 * width, -half - 2.0 - tail_drop, -0.18 * width])
        knots = np.vstack([medial, sci - np.array([0.0, half, 0.0]), peak, tail])
        seg = np.linalg.norm(np.diff(knots, axis=0), axis=1)
        s_knots = np.concatenate([[0.0], np.cumsum(seg)])
        total = float(s_knots[-1])
        n = int(rng.poisson(style.density * total * 2.0 * half * thick))
        u = rng.random(n) ** 1.15  # a little denser at the head of the brow
        centre = np.stack([np.interp(u * total, s_knots, knots[:, j]) for j in range(3)], axis=1)
        profile = half * thick * (1.0 - 0.65 * u) + 0.4
        v = rng.uniform(-1.0, 1.0, n)
        c = centre + np.outer(v * profile, [0.0, 1.0, 0.0])
        tangent = np.stack([np.interp(u * total, s_knots[1:], np.diff(knots[:, j]) / seg)
                            for j in range(3)], axis=1)  # fmt: skip
        tangent = _unit(tangent)
        angle = np.radians(np.interp(u, [0.0, 0.15, 0.4, 1.0], [75.0, 40.0, 8.0, -12.0]) - 18.0 * v)
        d = np.cos(angle)[:, None] * tangent + np.sin(angle)[:, None] * np.array([0.0, 1.0, 0.0])
        roots.append(ax.vector(c[:, 0], c[:, 1], c[:, 2]) + ax.origin)
        dirs.append(ax.vector(d[:, 0], d[:, 1], d[:, 2]))
        lo, hi = style.length
        lengths.append(rng.uniform(lo, hi, n) * (1.0 - 0.35 * u))
    r = np.concatenate(roots)
    # onto the skin
    from workbench.core.spatial import MeshIndex

    r = MeshIndex.shared(skin).closest_points(r).points
    return r, np.concatenate(dirs), np.concatenate(lengths)


def _piece(style: Style, skin: Mesh, parts: HeadParts, m: Marks, seed: int) -> HairPiece:
    rng = np.random.default_rng(seed)
    ax = m.axes
    if style.kind == "brows":
        roots, dirs, lengths = _brow_piece(style, skin, parts, m, rng)
        cover = np.zeros(skin.n_vertices)
    else:
        make = {"hair": _scalp_region, "beard": _beard_region, "moustache": _moustache_region}
        region = make[style.kind](style, m, skin, parts)
        roots = _sample(skin, style.density, region, m, rng)
        cover = region(skin.vertices, ax.coords(skin.vertices))
        c = ax.coords(roots)
        down, back, side = style.comb
        lo, hi = style.length
        lengths = rng.uniform(lo, hi, len(roots))
        if style.kind == "hair":
            # combed back over the top: in front of the crown the comb also points up, so
            # hair at the hairline goes over the head instead of down the forehead; the
            # parting runs from the hairline to the crown only
            crown_z = m.at["v"][2] - 15.0
            ahead = np.clip((c[:, 2] - crown_z) / 40.0, 0.0, 1.0)
            lat = side * np.sign(c[:, 0] - style.shape.get("part", 0.0)) * ahead
            upward = -down + 1.4 * back * ahead
            # hair at the temples and sides goes back over the ears, not down the cheeks
            side_back = style.shape.get("back", 0.0) * np.clip((azimuth_deg(c) - 30.0) / 40.0, 0, 1)
            back = back + side_back * (1.0 - ahead)
            # shorter at the sides and the nape (a tapered cut)
            taper = style.shape.get("taper", 1.0)
            t_y = m.y("t")
            lengths *= np.interp(c[:, 1], [t_y - 20.0, t_y + 35.0], [taper, 1.0])
        else:
            lat = side * np.sign(c[:, 0]) if style.kind == "moustache" else 0.0 * c[:, 0]
            upward = -down * np.ones(len(c))
        dirs = ax.vector(lat, upward, -back * np.ones(len(c)))
    k = len(roots)
    if k:
        from workbench.core.spatial import MeshIndex

        found = MeshIndex.shared(skin).closest_points(roots)
        from workbench.core.grooming.shell import surface_frames

        _, frame = surface_frames(
            skin.vertices, skin.faces, found.face_ids, found.barycentric, skin.vertex_normals
        )
        n = frame[:, 2]
        dirs = _unit(dirs - np.einsum("kd,kd->k", dirs, n)[:, None] * n) + 0.25 * n
    lift = rng.uniform(*style.lift, k)
    gravity = np.full(k, style.gravity)
    hug = np.full(k, style.hug) if np.isfinite(style.hug) else None
    # long hair hangs free below the widest part of the head (a little above the tragion)
    hang = float(ax.origin @ ax.up) + m.y("t") + 15.0 if style.kind == "hair" else -np.inf
    strands = grow_strands(
        skin,
        roots,
        dirs,
        lengths,
        lift,
        gravity,
        ax.up,
        style.segments,
        hug,
        hang,
        style.shape.get("hang_gravity", 0.0),
        (ax.forward, float(ax.origin @ ax.forward) + m.at["ex"][2] - 8.0)
        if style.kind == "hair" and "ex" in m.at
        else None,
    )
    shell = ShellPoints.attach(skin, strands.reshape(-1, 3))
    widths = style.width * rng.uniform(0.7, 1.3, k)
    shade = rng.normal(1.0, 0.12, k).clip(0.7, 1.3)
    tilt = rng.normal(0.0, 0.3, k)
    return HairPiece(
        style.kind,
        style.name,
        shell,
        k,
        style.segments + 1,
        widths,
        shade,
        style.tip_width,
        np.clip(cover, 0.0, 1.0),
        tilt,
    )


def groom(skin: Mesh, parts: HeadParts, choice: Mapping[str, str], seed: int = 0) -> Grooming:
    """The pieces of ``choice`` (``{kind: style name or "none"}``) grown on ``skin``.

    Placed from ``parts.landmarks`` (skin landmarks, the skin's frame, mm);
    the same choice and seed give the same strands on the same head.
    Raises :class:`GroomingError` for an unknown style or missing landmarks.
    """
    chosen = {k: check_style(k, choice.get(k, NONE)) for k in KINDS}
    wanted = [k for k in KINDS if chosen[k] != NONE]
    if not wanted:
        return Grooming(chosen, ())
    m = marks(parts.landmarks)
    pieces = tuple(
        _piece(LIBRARY[k][chosen[k]], skin, parts, m, seed + 1009 * i) for i, k in enumerate(wanted)
    )
    return Grooming(chosen, pieces)


__all__ = [
    "ARTISTIC_NOTE",
    "BEARDS",
    "BROWS",
    "HAIR",
    "KINDS",
    "LIBRARY",
    "MOUSTACHES",
    "NONE",
    "Grooming",
    "HairPiece",
    "HeadParts",
    "Ribbons",
    "Style",
    "check_style",
    "groom",
    "style_names",
]
