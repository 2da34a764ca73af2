"""Colours for showing and exporting a head: presets, HSV helpers and painted eyes.

Every colour here is an **artistic default** for display and export (a viewer,
Blender, a game engine).  None of it is evidence about the person: a face
built on a skull says nothing about skin, eye, lip or hair colour, and a
picture shown with these colours must not be read as if it did.  Each preset
says where its value comes from; "hand-picked" means a value chosen by eye
for a plausible look, not a measurement.

Colours are sRGB, 0-255 (``uint8`` arrays or int triples), the encoding of
images and of most colour pickers.  glTF wants linear RGB for
``baseColorFactor`` and ``COLOR_0``: :func:`srgb_to_linear`.

Units and frames: millimetres.  The eye functions work in any frame, given
the eyeball's centre and its gaze (a unit vector in the same frame); in the
head frame (x to the subject's left, y up, z forward) the reference head's
eyes look along +z.  A frame that is mirrored (a reconstruction written in a
mirrored skull file's frame) only mirrors the iris pattern, which is radial.

Eyes
----
A point of the globe is placed by its angle ``theta`` from the gaze axis and
its angle ``phi`` about it.  With the globe radius ``R``, the distance of the
point from the axis is ``R sin(theta)``; in front of the centre
(``theta < 90°``) it is pupil inside :data:`PUPIL_DIAMETER_MM` / 2, iris
inside :data:`IRIS_DIAMETER_MM` / 2 (the limbus) and sclera outside, and
behind the centre it is sclera.  A vertex of the corneal bulge is coloured by
its angle, i.e. by the iris it lies over.  The eyeball texture uses a Lambert
azimuthal equal-area projection about the gaze axis, centred in the image::

    u = 0.5 + 0.5 sin(theta / 2) cos(phi),  v = 0.5 + 0.5 sin(theta / 2) sin(phi)

(``u`` right, ``v`` up, OBJ's convention; glTF flips ``v``), so the corneal
pole is the image centre, the equator a circle of radius 0.35 and the back
pole the inscribed circle; the image outside that circle is sclera.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from workbench.core.mesh import Mesh

SRGB = tuple[int, int, int]


@dataclass(frozen=True)
class Preset:
    """A named sRGB colour (0-255) and where the value comes from."""

    srgb: SRGB
    source: str

    @property
    def hex(self) -> str:
        return "#" + "".join(f"{c:02x}" for c in self.srgb)


def _hex(text: str) -> SRGB:
    value = text.lstrip("#")
    return (int(value[0:2], 16), int(value[2:4], 16), int(value[4:6], 16))


# ------------------------------------------------------------------ skin
#: The ten swatches of the Monk Skin Tone (MST) scale, lightest to darkest: E. Monk,
#: developed 2019 and published by Google in 2022 with these sRGB values
#: (skintone.google).  They are swatches of skin as it looks in photographs, made for
#: annotating images across the whole range of human skin tones; they are not
#: measured reflectance.  (The Fitzpatrick types I-VI describe how skin reacts to the
#: sun, not its colour, so they give no sRGB value to take.)
MONK_SCALE = (
    "#f6ede4",
    "#f3e7db",
    "#f7ead0",
    "#eadaba",
    "#d7bd96",
    "#a07e56",
    "#825c43",
    "#604134",
    "#3a312a",
    "#292420",
)
_MONK = "Monk Skin Tone scale (Monk 2019; sRGB swatches published by Google, 2022), MST {k}"

#: skin tones: ``mst1`` ... ``mst10`` and three names for orbs of that scale (our choice:
#: one from its light, middle and dark parts)
SKIN_TONES: dict[str, Preset] = {
    f"mst{k}": Preset(_hex(code), _MONK.format(k=k)) for k, code in enumerate(MONK_SCALE, 1)
}
SKIN_TONES["light"] = SKIN_TONES["mst3"]
SKIN_TONES["medium"] = SKIN_TONES["mst6"]
SKIN_TONES["dark"] = SKIN_TONES["mst9"]
DEFAULT_SKIN_TONE = "medium"

# ------------------------------------------------------------------ eyes
#: Iris colours by the category names of eye-colour grading (blue, grey, green, hazel,
#: brown; reviewed by Mackey, Wilkinson, Kearns & Hewitt 2011, Clin Exp Ophthalmol
#: 39:462-471).  Each has the colour near the pupil and the colour of the outer iris;
#: the sRGB values are hand-picked to read as the category, not measured.
IRIS_COLOURS: dict[str, tuple[Preset, Preset]] = {
    "brown": (
        Preset(_hex("#3d2414"), "hand-picked: dark brown near the pupil"),
        Preset(_hex("#6a4124"), "hand-picked: brown outer iris"),
    ),
    "hazel": (
        Preset(_hex("#7a4f22"), "hand-picked: amber-brown ring near the pupil"),
        Preset(_hex("#77773f"), "hand-picked: green-olive outer iris"),
    ),
    "green": (
        Preset(_hex("#8a7b3c"), "hand-picked: yellowish ring near the pupil"),
        Preset(_hex("#587a48"), "hand-picked: green outer iris"),
    ),
    "blue": (
        Preset(_hex("#93aec4"), "hand-picked: light blue near the pupil"),
        Preset(_hex("#4c729a"), "hand-picked: blue outer iris"),
    ),
    "grey": (
        Preset(_hex("#a6acb0"), "hand-picked: light grey near the pupil"),
        Preset(_hex("#76828b"), "hand-picked: blue-grey outer iris"),
    ),
}
DEFAULT_IRIS = "brown"
PUPIL = Preset(_hex("#0b0a0a"), "hand-picked: near black (the pupil returns little light)")
SCLERA = Preset(_hex("#ebe5dc"), "hand-picked: a slightly warm off-white, not pure white")

#: pupil diameter (mm): a light-adapted adult pupil is about 3-4 mm over ordinary indoor
#: to daylight luminance (Watson & Yellott 2012, "A unified formula for light-adapted
#: pupil size", J Vision 12(10):12); the middle is taken
PUPIL_DIAMETER_MM = 3.5
#: iris (visible, "white-to-white") diameter (mm): 11.71 +/- 0.42 mm in healthy adults
#: (Rüfer, Schröder & Erb 2005, Cornea 24:259-261); the reference globes put their
#: limbus at the same 11.7 mm (:mod:`workbench.core.headgen.eyes`)
IRIS_DIAMETER_MM = 11.7
#: width (mm) of the darker limbal ring at the iris edge (the ring described by Peshek,
#: Semmaknejad, Hoffman & Foley 2011, Evol Psychol 9:137-146); the width is hand-picked
LIMBAL_RING_MM = 0.6
#: globe radius (mm) when none is given: the reference head's (axial length ~24 mm)
EYE_RADIUS_MM = 12.0

# ------------------------------------------------------------------ other parts
TEETH = Preset(
    _hex("#e9dfc8"), "hand-picked: off-white near the VITA classical A2 tab (not measured)"
)
LIPS_RULE = (
    "derived from the skin tone (hand-picked rule): hue 0.03 toward red, "
    "saturation x 1.35, value x 0.82"
)
EYEBROWS = Preset(_hex("#3b2a1e"), "hand-picked: dark brown")
HAIR = Preset(_hex("#3b2a1e"), "hand-picked: dark brown (hair, beard and moustache by default)")
BONE = Preset(_hex("#e3d9c3"), "hand-picked: ivory of dry bone")
TONGUE = Preset(_hex("#b9656a"), "hand-picked: pink-red")
OTHER = Preset(_hex("#b4b4b4"), "hand-picked: neutral grey for a part without a preset")

#: roughness per material (glTF metallic-roughness, 0 mirror .. 1 matte): hand-picked,
#: glossy where the surface is wet (cornea, tongue, lips), matte for dry bone
ROUGHNESS = {
    "skin": 0.5,
    "lips": 0.4,
    "eye": 0.08,
    "teeth": 0.3,
    "bone": 0.8,
    "tongue": 0.35,
    "brows": 0.7,
    "hair": 0.6,
    "other": 0.6,
}

#: head part -> (material name, preset); the skin and the eyes are made separately
PART_MATERIALS: dict[str, tuple[str, Preset]] = {
    "cranium": ("bone", BONE),
    "mandible": ("bone", BONE),
    "upper_teeth": ("teeth", TEETH),
    "lower_teeth": ("teeth", TEETH),
    "teeth": ("teeth", TEETH),
    "tongue": ("tongue", TONGUE),
    "brows": ("brows", EYEBROWS),
    "eyebrows": ("brows", EYEBROWS),
    "hair": ("hair", HAIR),
    "beard": ("hair", HAIR),
    "moustache": ("hair", HAIR),
}


# ------------------------------------------------------------------ colour helpers
def srgb_to_linear(srgb: np.ndarray | Sequence[float]) -> np.ndarray:
    """sRGB 0-255 → linear RGB 0-1 (IEC 61966-2-1 transfer function)."""
    c = np.asarray(srgb, dtype=np.float64) / 255.0
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(linear: np.ndarray | Sequence[float]) -> np.ndarray:
    """Linear RGB 0-1 → sRGB 0-255 as uint8 (the inverse of :func:`srgb_to_linear`)."""
    c = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    s = np.where(c <= 0.0031308, 12.92 * c, 1.055 * c ** (1 / 2.4) - 0.055)
    return np.clip(np.rint(s * 255.0), 0, 255).astype(np.uint8)


def rgb_to_hsv(rgb: np.ndarray | Sequence[float]) -> np.ndarray:
    """RGB 0-1 ``(..., 3)`` → HSV 0-1 ``(..., 3)`` (hue as a fraction of a turn)."""
    c = np.asarray(rgb, dtype=np.float64)
    r, g, b = c[..., 0], c[..., 1], c[..., 2]
    top = c.max(axis=-1)
    span = top - c.min(axis=-1)
    safe = np.where(span > 0, span, 1.0)
    hue = np.where(
        top == r,
        ((g - b) / safe) % 6.0,
        np.where(top == g, (b - r) / safe + 2.0, (r - g) / safe + 4.0),
    )
    hue = np.where(span > 0, hue / 6.0, 0.0)
    sat = np.where(top > 0, span / np.where(top > 0, top, 1.0), 0.0)
    return np.stack([hue % 1.0, sat, top], axis=-1)


def hsv_to_rgb(hsv: np.ndarray | Sequence[float]) -> np.ndarray:
    """HSV 0-1 ``(..., 3)`` → RGB 0-1 ``(..., 3)`` (the inverse of :func:`rgb_to_hsv`)."""
    c = np.asarray(hsv, dtype=np.float64)
    h, s, v = c[..., 0] % 1.0, np.clip(c[..., 1], 0, 1), c[..., 2]
    k = (np.array([5.0, 3.0, 1.0]) + 6.0 * h[..., None]) % 6.0
    return v[..., None] - v[..., None] * s[..., None] * np.clip(np.minimum(k, 4.0 - k), 0.0, 1.0)


def lip_srgb(skin: SRGB | Sequence[int]) -> SRGB:
    """A lip colour for a skin colour (sRGB 0-255), by the hand-picked rule :data:`LIPS_RULE`."""
    h, s, v = rgb_to_hsv(np.asarray(skin, float) / 255.0)
    rgb = hsv_to_rgb([(h - 0.03) % 1.0, min(1.0, s * 1.35), v * 0.82])
    r, g, b = (int(x) for x in np.clip(np.rint(rgb * 255.0), 0, 255))
    return (r, g, b)


def skin_tone(name: str) -> Preset:
    """The :data:`SKIN_TONES` preset ``name`` (``ValueError`` naming the choices)."""
    if name not in SKIN_TONES:
        raise ValueError(f"unknown skin tone {name!r}; choose one of {', '.join(SKIN_TONES)}")
    return SKIN_TONES[name]


def iris_colours(name: str) -> tuple[Preset, Preset]:
    """The :data:`IRIS_COLOURS` pair ``name`` (``ValueError`` naming the choices)."""
    if name not in IRIS_COLOURS:
        raise ValueError(f"unknown iris colour {name!r}; choose one of {', '.join(IRIS_COLOURS)}")
    return IRIS_COLOURS[name]


# ------------------------------------------------------------------ eye geometry
def _unit(v: np.ndarray | Sequence[float]) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64).reshape(3)
    n = float(np.linalg.norm(a))
    if n == 0.0:
        raise ValueError("the gaze direction is the zero vector")
    return a / n


def _gaze_frame(gaze: np.ndarray | Sequence[float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Unit gaze and two unit vectors across it (the first as close to +y as possible)."""
    g = _unit(gaze)
    for ref in (np.array([0.0, 1.0, 0.0]), np.array([1.0, 0.0, 0.0])):
        e1 = ref - (ref @ g) * g
        if np.linalg.norm(e1) > 0.1:
            e1 /= np.linalg.norm(e1)
            return g, e1, np.cross(g, e1)
    raise AssertionError("unreachable: +y and +x cannot both be parallel to the gaze")


def eye_angles(
    vertices: np.ndarray, centre: np.ndarray | Sequence[float], gaze: np.ndarray | Sequence[float]
) -> tuple[np.ndarray, np.ndarray]:
    """``(theta, phi)`` of each vertex (radians): from the gaze axis (0..pi) and about it
    (-pi..pi, 0 toward the head's up direction)."""
    g, e1, e2 = _gaze_frame(gaze)
    d = np.asarray(vertices, dtype=np.float64).reshape(-1, 3) - np.asarray(centre, float)
    along = d @ g
    across = np.linalg.norm(d - along[:, None] * g, axis=1)
    return np.arctan2(across, along), np.arctan2(d @ e2, d @ e1)


def gaze_from_cornea(
    vertices: np.ndarray, centre: np.ndarray | Sequence[float], bulge_mm: float = 0.3
) -> np.ndarray | None:
    """The direction from ``centre`` to the corneal apex of a globe (unit), or None.

    The cornea bulges about 1.1 mm beyond the globe on the reference head, so
    the vertices farthest from the centre mark the gaze in whatever frame the
    mesh is in.  None when the farthest vertex stands less than ``bulge_mm``
    above the median radius (a plain sphere: no cornea to read).
    """
    d = np.asarray(vertices, dtype=np.float64).reshape(-1, 3) - np.asarray(centre, float)
    r = np.linalg.norm(d, axis=1)
    if len(r) == 0 or r.max() - np.median(r) < bulge_mm:
        return None
    apex = d[r >= r.max() - 0.05].mean(axis=0)
    return apex / np.linalg.norm(apex)


def eye_owner(vertices: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """For each vertex of a mesh of several globes, the index of the nearest centre."""
    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    c = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
    return np.linalg.norm(v[:, None] - c[None], axis=2).argmin(axis=1)


def eye_gazes(
    vertices: np.ndarray,
    centres: np.ndarray,
    default: np.ndarray | Sequence[float] = (0.0, 0.0, 1.0),
) -> np.ndarray:
    """``(k, 3)`` gaze per globe: read from its cornea, else ``default``."""
    owner = eye_owner(vertices, centres)
    c = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    out = []
    for i in range(len(c)):
        found = gaze_from_cornea(v[owner == i], c[i])
        out.append(_unit(default) if found is None else found)
    return np.array(out).reshape(-1, 3)


def vertices_near_pole(
    vertices: np.ndarray,
    centre: np.ndarray | Sequence[float],
    gaze: np.ndarray | Sequence[float],
    within_mm: float = 2.0,
) -> int:
    """How many vertices of a globe lie within ``within_mm`` of its front pole.

    The pole is the globe's foremost point along ``gaze``.  A 3.5 mm pupil needs
    a few rings of vertices inside it to show as a disc in vertex colours.
    """
    g = _unit(gaze)
    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    c = np.asarray(centre, dtype=np.float64)
    pole = c + g * float(((v - c) @ g).max())
    return int((np.linalg.norm(v - pole, axis=1) < within_mm).sum())


def fine_eyes(
    centres: np.ndarray,
    gazes: np.ndarray,
    radius: float = EYE_RADIUS_MM,
    subdivisions: int = 6,
) -> Mesh:
    """Finer replacement globes (for vertex-coloured display or export), one per centre.

    Each is the reference globe (:func:`workbench.core.headgen.eyes.eyeball_mesh`:
    sphere of ``radius`` with the same corneal bulge) at ``subdivisions``
    icosphere levels, its cornea along the gaze.  Level 6 has 40962 vertices per
    globe (edges ~0.23 mm, ~240 vertices within 2 mm of the pole); the
    reference's level 4 has 2562 (edges ~0.9 mm, 15 within 2 mm), which shows a
    pupil only as a blur in vertex colours.  The template is not changed.
    """
    from workbench.core.headgen.eyes import eyeball_mesh

    c = np.asarray(centres, dtype=np.float64).reshape(-1, 3)
    g = np.asarray(gazes, dtype=np.float64).reshape(-1, 3)
    globes = [
        eyeball_mesh(c[i], radius, _unit(g[i]), subdivisions=subdivisions) for i in range(len(c))
    ]
    offsets = np.cumsum([0] + [m.n_vertices for m in globes])
    return Mesh(
        np.vstack([m.vertices for m in globes]),
        np.vstack([m.faces + offsets[i] for i, m in enumerate(globes)]),
    )


# ------------------------------------------------------------------ eye colour
def _smoothstep(edge0: float, edge1: float, x: np.ndarray) -> np.ndarray:
    t = np.clip((x - edge0) / (edge1 - edge0), 0.0, 1.0)
    return t * t * (3.0 - 2.0 * t)


def _fibres(phi: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Radial streaks in -1..1: a few integer harmonics of phi (seamless at +/-pi),
    twisted slightly with the position ``t`` across the iris."""
    a = phi + 0.25 * t
    return (
        0.45 * np.sin(29 * a + 1.3)
        + 0.3 * np.sin(47 * a + 0.7 + 2.0 * t)
        + 0.25 * np.sin(83 * a + 2.1 - 3.0 * t)
    )


def _eye_rgb(
    theta: np.ndarray,
    phi: np.ndarray,
    iris: str,
    radius: float,
    pupil_mm: float,
    iris_mm: float,
) -> np.ndarray:
    """The eye's colour (sRGB 0-1, ``(k, 3)``) at angles ``theta``, ``phi`` (radians)."""
    inner, outer = (np.asarray(p.srgb, float) / 255.0 for p in iris_colours(iris))
    rho = radius * np.sin(np.clip(theta, 0.0, np.pi))  # mm from the gaze axis
    front = theta < np.pi / 2
    r_pupil, r_iris = pupil_mm / 2.0, iris_mm / 2.0
    t = np.clip((rho - r_pupil) / (r_iris - r_pupil), 0.0, 1.0)
    mix = _smoothstep(0.1, 0.8, t)[:, None]
    hsv = rgb_to_hsv(inner * (1.0 - mix) + outer * mix)
    shade = 1.0 + 0.16 * _fibres(phi, t)
    shade += 0.12 * np.exp(-(((t - 0.3) / 0.07) ** 2))  # the lighter collarette
    shade *= 1.0 - 0.6 * (1.0 - _smoothstep(0.0, LIMBAL_RING_MM, r_iris - rho))  # limbal ring
    hsv[:, 2] = np.clip(hsv[:, 2] * shade, 0.0, 1.0)
    hsv[:, 1] = np.clip(hsv[:, 1] * (1.0 + 0.1 * _fibres(phi + 0.5, t)), 0.0, 1.0)
    rgb = hsv_to_rgb(hsv)
    pupil = np.asarray(PUPIL.srgb, float) / 255.0
    sclera = np.asarray(SCLERA.srgb, float) / 255.0
    in_pupil = (1.0 - _smoothstep(r_pupil - 0.06, r_pupil + 0.06, rho)) * front
    in_iris = (1.0 - _smoothstep(r_iris - 0.08, r_iris + 0.08, rho)) * front
    out = rgb * in_iris[:, None] + sclera * (1.0 - in_iris[:, None])
    return out * (1.0 - in_pupil[:, None]) + pupil * in_pupil[:, None]


def _to_uint8(rgb01: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(rgb01 * 255.0), 0, 255).astype(np.uint8)


def eye_colours(
    vertices: np.ndarray,
    centre: np.ndarray | Sequence[float],
    gaze: np.ndarray | Sequence[float] = (0.0, 0.0, 1.0),
    *,
    iris: str = DEFAULT_IRIS,
    radius: float = EYE_RADIUS_MM,
    pupil_mm: float = PUPIL_DIAMETER_MM,
    iris_mm: float = IRIS_DIAMETER_MM,
) -> np.ndarray:
    """``(n, 3)`` uint8 sRGB per vertex of one globe: pupil, iris or sclera by angle.

    ``gaze`` is the unit direction the eye looks along (head frame: +z for the
    reference head).  The iris has a darker limbal ring, a lighter collarette
    and radial streaks; the colours come from :data:`IRIS_COLOURS`,
    :data:`PUPIL` and :data:`SCLERA`.
    """
    theta, phi = eye_angles(vertices, centre, gaze)
    return _to_uint8(_eye_rgb(theta, phi, iris, radius, pupil_mm, iris_mm))


def eyes_colours(
    vertices: np.ndarray,
    centres: np.ndarray,
    gazes: np.ndarray,
    *,
    iris: str = DEFAULT_IRIS,
    radius: float = EYE_RADIUS_MM,
) -> np.ndarray:
    """:func:`eye_colours` for a mesh of several globes (each vertex by its nearest centre)."""
    v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    owner = eye_owner(v, centres)
    out = np.empty((len(v), 3), np.uint8)
    for i, (c, g) in enumerate(zip(np.asarray(centres), np.asarray(gazes), strict=True)):
        sel = owner == i
        out[sel] = eye_colours(v[sel], c, g, iris=iris, radius=radius)
    return out


def eye_texture(
    size: int = 512,
    *,
    iris: str = DEFAULT_IRIS,
    radius: float = EYE_RADIUS_MM,
    pupil_mm: float = PUPIL_DIAMETER_MM,
    iris_mm: float = IRIS_DIAMETER_MM,
) -> np.ndarray:
    """The eyeball texture ``(size, size, 3)`` uint8 sRGB, row 0 at the top (``v`` = 1).

    Mapped by the equal-area projection of the module docstring (see
    :func:`eye_uv`): the pupil in the middle, the iris around it, sclera
    elsewhere.  At 512 px the iris is ~130 px across.
    """
    centres = (np.arange(size) + 0.5) / size
    u, v = np.meshgrid(centres, 1.0 - centres)  # row 0 is the top of the image: v = 1
    dx, dy = u - 0.5, v - 0.5
    s = np.minimum(2.0 * np.hypot(dx, dy), 1.0)
    theta = 2.0 * np.arcsin(s).ravel()
    phi = np.arctan2(dy, dx).ravel()
    rgb = _eye_rgb(theta, phi, iris, radius, pupil_mm, iris_mm)
    return _to_uint8(rgb).reshape(size, size, 3)


def eye_uv(
    vertices: np.ndarray, centre: np.ndarray | Sequence[float], gaze: np.ndarray | Sequence[float]
) -> np.ndarray:
    """``(n, 2)`` texture coordinates of a globe's vertices (u right, v up) for :func:`eye_texture`."""
    theta, phi = eye_angles(vertices, centre, gaze)
    r = 0.5 * np.sin(theta / 2.0)
    return np.column_stack([0.5 + r * np.cos(phi), 0.5 + r * np.sin(phi)])


#: where the few triangles around a globe's back pole take their colour: a corner of
#: the texture, outside the projected disc, which is sclera
BACK_UV = (0.01, 0.01)


def eyes_corner_uv(mesh: Mesh, centres: np.ndarray, gazes: np.ndarray) -> np.ndarray:
    """``(m, 3, 2)`` texture coordinates per triangle corner of a mesh of globes.

    Corners take :func:`eye_uv` of their vertex, except in the triangles around
    a back pole, whose corners spread around the image's rim: drawn from
    those, a triangle would cut across the image and pick up the iris, so
    these take :data:`BACK_UV` (sclera) at every corner.
    """
    v = mesh.vertices
    owner = eye_owner(v, centres)
    uv = np.empty((len(v), 2))
    theta = np.empty(len(v))
    phi = np.empty(len(v))
    for i, (c, g) in enumerate(zip(np.asarray(centres), np.asarray(gazes), strict=True)):
        sel = owner == i
        theta[sel], phi[sel] = eye_angles(v[sel], c, g)
        uv[sel] = eye_uv(v[sel], c, g)
    corners = uv[mesh.faces]
    p = phi[mesh.faces]
    spread = np.zeros(len(p))
    for a, b in ((0, 1), (1, 2), (2, 0)):
        d = np.abs((p[:, a] - p[:, b] + np.pi) % (2 * np.pi) - np.pi)
        spread = np.maximum(spread, d)
    back = (theta[mesh.faces] > np.pi / 2).all(axis=1) & (spread > np.pi / 2)
    corners[back] = BACK_UV
    return corners


# ------------------------------------------------------------------ looks of a head
@dataclass(frozen=True, eq=False)
class Material:
    """One material: a base colour, or a texture (sRGB, row 0 at the top), and roughness.

    ``texture_file`` names the image beside an OBJ (``map_Kd``).  Metallic is 0:
    nothing of a head is metal.
    """

    name: str
    srgb: SRGB
    roughness: float
    source: str
    texture: np.ndarray | None = None
    texture_file: str = ""
    metallic: float = 0.0


@dataclass(frozen=True, eq=False)
class Look:
    """How one part of a head is drawn and exported.

    ``face_material`` gives each triangle an index into ``materials`` (None: all
    the first); ``corner_uv`` ``(m, 3, 2)`` are texture coordinates per triangle
    corner (u right, v up: OBJ's convention); ``vertex_srgb`` ``(n, 3)`` uint8
    per-vertex colours, which a format that has them (glTF ``COLOR_0``) uses
    with the first material *instead of* the per-triangle materials (a smooth
    lip border rather than a triangle-wise one), while OBJ keeps the materials;
    ``mesh`` replaces the part's mesh for display and export (finer eyes), its
    arrays then applying to it.
    """

    materials: tuple[Material, ...]
    face_material: np.ndarray | None = None
    corner_uv: np.ndarray | None = None
    vertex_srgb: np.ndarray | None = None
    mesh: Mesh | None = None

    def faces_of(self, n_faces: int) -> np.ndarray:
        """``(n_faces,)`` material index per triangle."""
        if self.face_material is None:
            return np.zeros(n_faces, np.int64)
        return np.asarray(self.face_material, np.int64)


@dataclass(frozen=True, eq=False)
class SkinTexture:
    """A colour atlas of the skin: image (sRGB, row 0 at the top) and ``(m, 3, 2)``
    texture coordinates per triangle corner (u right, v up); ``file``: the image's
    name when it was read from a file beside the skin's OBJ."""

    image: np.ndarray
    corner_uv: np.ndarray
    file: str = ""


def plain_look(part: str, tone: str = DEFAULT_SKIN_TONE) -> Look:
    """One plain material for ``part`` by its name (skin, eyes, teeth, bone ...)."""
    if part == "skin":
        preset = skin_tone(tone)
        return Look((Material("skin", preset.srgb, ROUGHNESS["skin"], preset.source),))
    if part == "eyes":
        return Look((Material("eye", SCLERA.srgb, ROUGHNESS["eye"], SCLERA.source),))
    name, preset = PART_MATERIALS.get(part, ("other", OTHER))
    return Look((Material(name, preset.srgb, ROUGHNESS[name], preset.source),))


def _skin_look(mesh: Mesh, regions: Mapping[str, np.ndarray], tone: str) -> Look:
    """Skin and lips: per triangle (at least two corners in the lip regions) and per vertex."""
    preset = skin_tone(tone)
    skin = Material("skin", preset.srgb, ROUGHNESS["skin"], preset.source)
    lips = Material("lips", lip_srgb(preset.srgb), ROUGHNESS["lips"], f"{LIPS_RULE}; skin {tone}")
    ids = [np.asarray(regions[r], np.int64) for r in ("upper_lip", "lower_lip") if r in regions]
    if not ids:
        return Look((skin,))
    on_lip = np.zeros(mesh.n_vertices, bool)
    on_lip[np.concatenate(ids)] = True
    face_material = (on_lip[mesh.faces].sum(axis=1) >= 2).astype(np.int64)
    colours = np.where(on_lip[:, None], np.asarray(lips.srgb), np.asarray(skin.srgb))
    return Look((skin, lips), face_material=face_material, vertex_srgb=colours.astype(np.uint8))


def _eye_look(mesh: Mesh, centres: np.ndarray, iris: str, style: str, texture_px: int) -> Look:
    gazes = eye_gazes(mesh.vertices, centres)
    source = (
        f"painted eye: iris {iris} ({IRIS_DIAMETER_MM} mm), pupil ({PUPIL_DIAMETER_MM} mm) "
        "and sclera colours hand-picked (workbench.core.appearance)"
    )
    if style == "vertex":
        fine = fine_eyes(centres, gazes)
        colours = eyes_colours(fine.vertices, centres, gazes, iris=iris)
        material = Material(f"eye_{iris}", (255, 255, 255), ROUGHNESS["eye"], source)
        return Look((material,), vertex_srgb=colours, mesh=fine)
    if style != "texture":
        raise ValueError(f"eye style {style!r}: use 'texture' or 'vertex'")
    material = Material(
        f"eye_{iris}",
        SCLERA.srgb,
        ROUGHNESS["eye"],
        source,
        texture=eye_texture(texture_px, iris=iris),
        texture_file=f"eye_{iris}.png",
    )
    return Look((material,), corner_uv=eyes_corner_uv(mesh, centres, gazes))


def head_looks(
    meshes: Mapping[str, Mesh],
    eye_centres: np.ndarray | None = None,
    *,
    regions: Mapping[str, np.ndarray] | None = None,
    tone: str = DEFAULT_SKIN_TONE,
    iris: str = DEFAULT_IRIS,
    skin_texture: SkinTexture | None = None,
    eyes: str = "texture",
    texture_px: int = 512,
) -> dict[str, Look]:
    """A :class:`Look` per part of a head (any frame, mm).

    The skin takes ``skin_texture`` when given and made for this skin (one
    corner UV per triangle), else the ``tone`` preset with the lips (regions
    ``upper_lip``/``lower_lip``) in their own material.  The eyes (a mesh of
    globes around ``eye_centres``, gaze read from each cornea) take the iris
    texture (``eyes="texture"``) or, with ``eyes="vertex"``, finer globes with
    per-vertex colours.  Other parts take :data:`PART_MATERIALS` by name.
    """
    out: dict[str, Look] = {}
    for part, mesh in meshes.items():
        if part == "skin" and skin_texture is not None:
            if skin_texture.corner_uv.shape != (mesh.n_faces, 3, 2):
                raise ValueError(
                    f"the skin texture has UVs for {len(skin_texture.corner_uv)} triangles, "
                    f"the skin has {mesh.n_faces}"
                )
            material = Material(
                "skin",
                (255, 255, 255),
                ROUGHNESS["skin"],
                "the scan's own colours carried onto the fitted skin (a texture atlas)",
                texture=skin_texture.image,
                texture_file=skin_texture.file or "skin_atlas.png",
            )
            out[part] = Look((material,), corner_uv=skin_texture.corner_uv)
        elif part == "skin":
            out[part] = _skin_look(mesh, regions or {}, tone)
        elif part == "eyes" and eye_centres is not None and len(eye_centres):
            out[part] = _eye_look(mesh, np.asarray(eye_centres, float), iris, eyes, texture_px)
        else:
            out[part] = plain_look(part, tone)
    return out


__all__ = [
    "DEFAULT_IRIS",
    "DEFAULT_SKIN_TONE",
    "IRIS_COLOURS",
    "IRIS_DIAMETER_MM",
    "PUPIL_DIAMETER_MM",
    "SKIN_TONES",
    "Look",
    "Material",
    "Preset",
    "SkinTexture",
    "eye_angles",
    "eye_colours",
    "eye_texture",
    "eye_uv",
    "eyes_colours",
    "eyes_corner_uv",
    "fine_eyes",
    "gaze_from_cornea",
    "head_looks",
    "hsv_to_rgb",
    "lip_srgb",
    "linear_to_srgb",
    "plain_look",
    "rgb_to_hsv",
    "srgb_to_linear",
    "vertices_near_pole",
]
