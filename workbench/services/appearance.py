"""The colours chosen for a face (:class:`~workbench.model.appearance.Appearance`) on a fitted head.

Kähler (2003, §8.6.6) paints the finished head over a neutral base: one skin
tone everywhere and a few regions tinted on top.  Here the base is the
appearance's skin tone (a Monk Skin Tone preset, or an HSV colour set by
hand) and the regions are painted over it in this order, each blended in
by a smooth per-vertex weight 0..1:

``cheeks``
    Round the cheek prominence: full within :data:`CHEEK_MM` [0] of the
    short segment from ``chk`` (cheekbone point) 30 % of the way toward
    ``zy`` (zygion), fading to nothing at :data:`CHEEK_MM` [1].
``eyes``
    The skin around the eyes: the template's ``orbit_*`` and ``eyelid_*``
    regions, fading over :data:`EYES_FEATHER_MM` outside them.
``brows``
    A band above each orbit along a line through a medial point (above
    ``en``, at the height of ``mso``), ``sci`` and ``scl`` lowered by half
    the brow's height (half the height of ``sci`` over ``mso``, 2.5-6 mm)
    and a tail beyond ``scl``; its half-width narrows from that half-height
    medially to 55 % of it at the tail, with a :data:`BROW_FEATHER_MM` edge,
    then averaged over each vertex's neighbours :data:`BROW_SMOOTHING` times
    and restored to full strength by a smoothstep over :data:`BROW_LEVELS`
    (the skin's triangles are a few mm across; a band that narrow would
    otherwise show their zigzag).
``lips``
    The template's ``upper_lip`` and ``lower_lip`` regions, fading over
    :data:`LIPS_FEATHER_MM` outside them.

The weights are computed from the head's own skin, regions and skin
landmarks (the fitted head's, in its head frame: x to the subject's left,
y up, z toward the face, mm); nothing of the cached template changes.  The
landmark-guided points are snapped to their nearest skin vertex, and
distances are straight-line (mm).  Colours are blended in linear light
(:func:`~workbench.core.appearance.srgb_to_linear`).

A region without a colour set by hand follows the base by a hand-picked
rule (:data:`RULES`, HSV factors; the lips by
:data:`~workbench.core.appearance.LIPS_RULE`), so an appearance with only a
tone still shows soft lips, brows, cheeks and eye surrounds.

For exports, :func:`skin_look` gives the skin per-vertex colours (glTF
``COLOR_0``) over a skin and a lips material, :func:`atlas_skin_look` bakes
them into a texture atlas for OBJ, and :func:`appearance_looks` is every
part's look (the eyes in the chosen iris); each material's source says where
its colour comes from.

**Every colour here is an artistic choice, not evidence**
(:data:`~workbench.model.appearance.ARTISTIC_NOTE`).
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
from scipy import sparse
from scipy.spatial import cKDTree

from workbench.core.appearance import (
    HAIR,
    LIPS_RULE,
    ROUGHNESS,
    SRGB,
    Look,
    Material,
    head_looks,
    hsv_to_rgb,
    linear_to_srgb,
    lip_srgb,
    rgb_to_hsv,
    skin_tone,
    srgb_to_linear,
)
from workbench.core.mesh import Mesh
from workbench.model.appearance import ARTISTIC_NOTE, REGIONS, Appearance, Hsv
from workbench.model.template import TemplateHead

#: region -> (hue shift in turns, saturation factor, value factor, where it comes from):
#: the colour of a region not set by hand, from the base (the lips use LIPS_RULE)
RULES: dict[str, tuple[float, float, float, str]] = {
    "cheeks": (-0.012, 1.18, 0.97, "hand-picked rule: a faint warm flush over the base"),
    "eyes": (0.0, 1.06, 0.9, "hand-picked rule: the base a little darker round the eyes"),
    "brows": (0.0, 1.2, 0.55, "hand-picked rule: the base darkened (brow hair seen from afar)"),
}
#: cheeks: full weight within the first distance (mm) of their core, none beyond the second
CHEEK_MM = (5.0, 20.0)
#: fading edges (mm) of the eyes, brows and lips regions
EYES_FEATHER_MM = 6.0
BROW_FEATHER_MM = 3.5
#: rounds of neighbour averaging of the brows' weight, and the averaged weights taken
#: back to 0 and 1 (a smoothstep between them restores the band's full strength)
BROW_SMOOTHING = 2
BROW_LEVELS = (0.12, 0.55)
LIPS_FEATHER_MM = 2.0
#: the brow's half-height (mm) is half the height of sci over mso, clipped to this range
BROW_HALF_MM = (2.5, 6.0)
#: the regions painted over the base, in order (later ones cover earlier ones); the
#: ``hair`` colour is painted where the chosen hair and beard grow
#: (:func:`workbench.services.grooming.hair_cover`), not over a fixed region
PAINTED = tuple(r for r in REGIONS if r not in ("skin", "hair"))
_SIDES = ("l", "r")


# ------------------------------------------------------------------ colours per region
def _hsv_of(srgb: SRGB | tuple[int, ...]) -> Hsv:
    h, s, v = (float(x) for x in rgb_to_hsv(np.asarray(srgb, float) / 255.0))
    return Hsv(h, min(s, 1.0), min(v, 1.0))


def hsv_srgb(colour: Hsv) -> SRGB:
    """``colour`` as sRGB 0-255."""
    r, g, b = (int(x) for x in np.clip(np.rint(hsv_to_rgb(colour.to_state()) * 255.0), 0, 255))
    return (r, g, b)


def region_colour(appearance: Appearance | None, region: str) -> Hsv:
    """The colour ``region`` is painted with: set by hand, else the rule from the base.

    ``None`` stands for the default appearance (the default preset, no region set).
    """
    look = appearance if appearance is not None else Appearance()
    own = look.colour(region)
    if own is not None:
        return own
    base = look.colour("skin") or _hsv_of(skin_tone(look.tone).srgb)
    if region == "skin":
        return base
    if region == "lips":
        return _hsv_of(lip_srgb(hsv_srgb(base)))
    if region == "hair":
        from workbench.services.grooming import hair_colour

        return hair_colour(look)
    dh, fs, fv, _ = RULES[region]
    return Hsv((base.h + dh) % 1.0, min(1.0, base.s * fs), min(1.0, base.v * fv))


def region_source(appearance: Appearance | None, region: str) -> str:
    """Where ``region``'s colour comes from, in words (for exported materials)."""
    look = appearance if appearance is not None else Appearance()
    if look.colour(region) is not None:
        return f"{region}: set by hand in the Appearance dock"
    if region == "skin":
        return f"skin: {skin_tone(look.tone).source}"
    if region == "lips":
        return f"lips: {LIPS_RULE}"
    if region == "hair":
        return f"hair: {HAIR.source}"
    return f"{region}: {RULES[region][3]}"


def colour_summary(appearance: Appearance | None) -> str:
    """One line naming the base, the regions set by hand and the iris, with the note."""
    look = appearance if appearance is not None else Appearance()
    base = "a base set by hand (HSV)" if look.custom_base else f"skin tone {look.tone}"
    own = [r for r, _ in look.regions if r != "skin"]
    regions = f"; set by hand: {', '.join(own)}" if own else ""
    styles = ", ".join(f"{k} {v.replace('_', ' ')}" for k, v in look.grooming)
    groomed = f"; {styles} (artistic additions, not evidence)" if styles else ""
    return f"{base}{regions}; iris {look.iris}{groomed}. {ARTISTIC_NOTE}"


# ------------------------------------------------------------------ region weights
def _smoothstep(x: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """0 up to ``lo``, 1 from ``hi``, smooth (3t² - 2t³) between."""
    t = np.clip((x - lo) / max(hi - lo, 1e-9), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _smooth_fall(d: np.ndarray, inner: float, outer: float) -> np.ndarray:
    """1 up to ``inner``, 0 from ``outer``, smooth between."""
    return 1.0 - _smoothstep(d, inner, outer)


def _ids(head: TemplateHead, names: tuple[str, ...]) -> np.ndarray:
    found = [np.asarray(head.regions[n], np.int64) for n in names if n in head.regions]
    return np.unique(np.concatenate(found)) if found else np.zeros(0, np.int64)


def _near_set(v: np.ndarray, ids: np.ndarray, feather: float) -> np.ndarray:
    """Weight of every vertex from its distance to the vertices ``ids`` (1 on them)."""
    if not len(ids):
        return np.zeros(len(v))
    d, _ = cKDTree(v[ids]).query(v, distance_upper_bound=feather + 1.0)
    return _smooth_fall(np.where(np.isfinite(d), d, np.inf), 0.0, feather)


def _polyline(points: np.ndarray, step: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """Samples every ``step`` mm along a polyline and their position 0..1 along it."""
    seg = np.diff(points, axis=0)
    lengths = np.linalg.norm(seg, axis=1)
    total = float(lengths.sum())
    if total <= 0.0:
        return points[:1], np.zeros(1)
    samples, where = [points[:1]], [np.zeros(1)]
    run = 0.0
    for a, d, n in zip(points[:-1], seg, lengths, strict=True):
        k = max(1, int(np.ceil(n / step)))
        t = np.arange(1, k + 1) / k
        samples.append(a + t[:, None] * d)
        where.append((run + t * n) / total)
        run += float(n)
    return np.vstack(samples), np.concatenate(where)


def _near_line(v: np.ndarray, line: np.ndarray, inner: np.ndarray, feather: float) -> np.ndarray:
    """Weight from the distance to a polyline, full within a half-width that varies along it
    (``inner`` gives it at the line's ends, 0..1 interpolated)."""
    samples, where = _polyline(line)
    d, i = cKDTree(samples).query(v)
    half = inner[0] + (inner[1] - inner[0]) * where[i]
    return _smooth_fall(d - half, 0.0, feather)


def _averaged(w: np.ndarray, faces: np.ndarray, rounds: int) -> np.ndarray:
    """``w`` averaged with its edge neighbours (itself counted once) ``rounds`` times."""
    f = np.asarray(faces, np.int64)
    i = np.concatenate([f[:, 0], f[:, 1], f[:, 2], f[:, 1], f[:, 2], f[:, 0]])
    j = np.concatenate([f[:, 1], f[:, 2], f[:, 0], f[:, 0], f[:, 1], f[:, 2]])
    n = len(w)
    adjacency = sparse.coo_matrix((np.ones(len(i)), (i, j)), shape=(n, n)).tocsr()
    adjacency.data[:] = 1.0  # an edge shared by two triangles counts once
    step = adjacency + sparse.identity(n, format="csr")
    degree = np.asarray(step.sum(axis=1)).ravel()
    for _ in range(rounds):
        w = (step @ w) / degree
    return w


def _snap(v: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Each point moved onto its nearest skin vertex."""
    _, i = cKDTree(v).query(points)
    return v[i]


def _brow(v: np.ndarray, lm: Mapping[str, np.ndarray], side: str) -> np.ndarray:
    codes = [f"{c}_{side}" for c in ("sci", "scl", "mso", "en", "ex")]
    if not all(c in lm for c in codes):
        return np.zeros(len(v))
    sci, scl, mso, en, ex = (np.asarray(lm[c], float) for c in codes)
    half = float(np.clip((sci[1] - mso[1]) / 2.0, *BROW_HALF_MM))
    down = np.array([0.0, half, 0.0])
    lateral = np.sign(ex[0] - en[0]) or 1.0  # along x (head frame)
    width = abs(ex[0] - en[0])
    medial = np.array([en[0], mso[1] + half, sci[2]])
    tail = scl - down + np.array([lateral * 0.35 * width, -2.0, -0.18 * width])
    line = _snap(v, np.vstack([medial, sci - down, scl - down, tail]))
    return _near_line(v, line, np.array([half, 0.55 * half]), BROW_FEATHER_MM)


def _cheek(v: np.ndarray, lm: Mapping[str, np.ndarray], side: str) -> np.ndarray:
    chk, zy = lm.get(f"chk_{side}"), lm.get(f"zy_{side}")
    if chk is None or zy is None:
        return np.zeros(len(v))
    chk = np.asarray(chk, float)
    line = _snap(v, np.vstack([chk, chk + 0.3 * (np.asarray(zy, float) - chk)]))
    return _near_line(v, line, np.array([CHEEK_MM[0], CHEEK_MM[0]]), CHEEK_MM[1] - CHEEK_MM[0])


def region_weights(head: TemplateHead) -> dict[str, np.ndarray]:
    """``{region: (n_skin,) weight 0..1}`` for the painted regions (:data:`PAINTED`).

    A region whose template regions or landmarks the head lacks has weight 0
    everywhere (the base shows there).
    """
    v = np.asarray(head.skin.vertices, float)
    lm = head.skin_landmarks.as_dict()
    around = tuple(f"{p}_{s}" for p in ("orbit", "eyelid_upper", "eyelid_lower") for s in _SIDES)
    brows = np.maximum(*(_brow(v, lm, s) for s in _SIDES))
    brows = _averaged(brows, head.skin.faces, BROW_SMOOTHING)
    return {
        "cheeks": np.maximum(*(_cheek(v, lm, s) for s in _SIDES)),
        "eyes": _near_set(v, _ids(head, around), EYES_FEATHER_MM),
        "brows": _smoothstep(brows, *BROW_LEVELS),
        "lips": _near_set(v, _ids(head, ("upper_lip", "lower_lip")), LIPS_FEATHER_MM),
    }


# ------------------------------------------------------------------ colours per vertex
def skin_colours(
    head: TemplateHead,
    appearance: Appearance | None,
    weights: Mapping[str, np.ndarray] | None = None,
) -> np.ndarray:
    """``(n_skin, 3)`` uint8 sRGB per skin vertex: the base with the regions painted over it.

    ``weights``: :func:`region_weights` of ``head`` already computed (they
    depend on the head only, not on the colours).
    """
    w = region_weights(head) if weights is None else weights
    n = head.skin.n_vertices
    out = np.tile(srgb_to_linear(hsv_srgb(region_colour(appearance, "skin"))), (n, 1))
    for region in PAINTED:
        colour = srgb_to_linear(hsv_srgb(region_colour(appearance, region)))
        a = np.clip(np.asarray(w[region], float), 0.0, 1.0)[:, None]
        out = out * (1.0 - a) + colour * a
    if appearance is not None and appearance.grooming:
        from workbench.services.grooming import hair_cover

        cover = hair_cover(head, appearance)
        if cover is not None and cover.any():
            colour = srgb_to_linear(hsv_srgb(region_colour(appearance, "hair")))
            a = cover[:, None]
            out = out * (1.0 - a) + colour * a
    return linear_to_srgb(out)


def skin_look(
    head: TemplateHead, appearance: Appearance | None, colours: np.ndarray | None = None
) -> Look:
    """The skin's :class:`~workbench.core.appearance.Look` with these colours.

    Per-vertex colours (glTF ``COLOR_0``, every region smooth) over two
    materials, skin and lips (by triangle, for a format without vertex
    colours such as OBJ); each material's source names where its colour
    comes from and that it is an artistic choice.
    """
    rgb = skin_colours(head, appearance) if colours is None else np.asarray(colours, np.uint8)
    materials = tuple(
        Material(
            name,
            hsv_srgb(region_colour(appearance, region)),
            ROUGHNESS[name],
            f"{region_source(appearance, region)}; {ARTISTIC_NOTE}",
        )
        for name, region in (("skin", "skin"), ("lips", "lips"))
    )
    lips = _ids(head, ("upper_lip", "lower_lip"))
    if not len(lips):
        return Look(materials[:1], vertex_srgb=rgb)
    on_lip = np.zeros(head.skin.n_vertices, bool)
    on_lip[lips] = True
    face_material = (on_lip[head.skin.faces].sum(axis=1) >= 2).astype(np.int64)
    return Look(materials, face_material=face_material, vertex_srgb=rgb)


#: the image the OBJ's skin material names when it carries the chosen colours
ATLAS_FILE = "skin_colours.png"


def atlas_skin_look(
    skin: Mesh, colours: np.ndarray, appearance: Appearance | None, *, atlas_size: int = 1024
) -> Look:
    """The skin's look for a format without per-vertex colours (OBJ): ``colours`` (per
    vertex of ``skin``, from :func:`skin_colours`) baked into a texture atlas, one patch
    per triangle (:func:`workbench.io.skin_colour_export.texture_atlas`), written as
    :data:`ATLAS_FILE`.  ``skin`` may be the head's skin in another frame (the same
    vertices and triangles, winding kept or reversed)."""
    from workbench.core.colour_transfer import SkinColours
    from workbench.io.skin_colour_export import texture_atlas

    rgb = np.asarray(colours, np.uint8)
    if rgb.shape != (skin.n_vertices, 3):
        raise ValueError(f"{len(rgb)} colours for {skin.n_vertices} skin vertices")
    n = skin.n_vertices
    painted = SkinColours(rgb, np.zeros(n, bool), np.full(n, np.nan), "vertex")
    image, uv = texture_atlas(skin, painted, atlas_size=atlas_size)
    material = Material(
        "skin_coloured",
        (255, 255, 255),
        ROUGHNESS["skin"],
        f"the colours chosen for the face, baked into a texture: {colour_summary(appearance)}",
        texture=image,
        texture_file=ATLAS_FILE,
    )
    return Look((material,), corner_uv=uv)


def appearance_looks(
    head: TemplateHead,
    appearance: Appearance | None,
    *,
    eyes: str = "texture",
    texture_px: int = 512,
) -> dict[str, Look]:
    """A :class:`~workbench.core.appearance.Look` per part of ``head`` for an export:
    :func:`skin_look` for the skin, the appearance's iris for the eyes, the presets
    of :func:`~workbench.core.appearance.head_looks` for the rest."""
    look = appearance if appearance is not None else Appearance()
    out = head_looks(
        head.meshes,
        head.eye_centres,
        regions=head.regions,
        tone=look.tone,
        iris=look.iris,
        eyes=eyes,
        texture_px=texture_px,
    )
    out["skin"] = skin_look(head, appearance)
    return out


__all__ = [
    "ATLAS_FILE",
    "PAINTED",
    "RULES",
    "appearance_looks",
    "atlas_skin_look",
    "colour_summary",
    "hsv_srgb",
    "region_colour",
    "region_source",
    "region_weights",
    "skin_colours",
    "skin_look",
]
