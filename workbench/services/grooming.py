"""Hair, brows, beard and moustache on a head, in the colours of its appearance.

The styles a case chose (:attr:`workbench.model.appearance.Appearance.grooming`)
are grown on the head's skin from its own skin landmarks
(:func:`workbench.core.grooming.groom`) and tied to the skin, so the same
strands are rebuilt on any skin with the head's triangles: a build variant,
the aged head, a frame of an animation (:func:`hair_meshes` with
``vertices``).  Growing takes 0.5-2 s for one head, so the grown pieces are
kept for the last few heads and choices (:data:`CACHE_SIZE`).

Colours: the hair, beard and moustache take the ``hair`` region's colour,
the brows the ``brows`` region's when it is set by hand, else the hair's a
little darker (:data:`BROW_VALUE`); each strand's brightness varies a
little, darkens towards its root and lightens towards its tip
(:data:`ROOT_SHADE`, :data:`TIP_LIGHTER`).  The skin under
the hair and beard is painted in the hair's colour (:func:`hair_cover`), as
an artist paints the scalp under a wig, so the ribbons' gaps do not show
skin.  **All of it is an artistic addition, not evidence**
(:data:`~workbench.core.grooming.ARTISTIC_NOTE`).

Units: mm, in the head's own frame (the frame of its skin).
"""

from __future__ import annotations

import hashlib
import threading
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from workbench.core.appearance import (
    HAIR,
    ROUGHNESS,
    Look,
    Material,
    hsv_to_rgb,
    linear_to_srgb,
    rgb_to_hsv,
    srgb_to_linear,
)
from workbench.core.grooming import ARTISTIC_NOTE, Grooming, HeadParts, groom
from workbench.core.mesh import Mesh
from workbench.model.appearance import Appearance, Hsv
from workbench.model.template import TemplateHead

#: grown pieces kept (per head and choice)
CACHE_SIZE = 6
#: how strongly the skin under hair (cover 1) takes the hair's colour, per kind
PAINT = {"hair": 0.85, "beard": 0.55, "moustache": 0.55, "brows": 0.0}
#: a beard drawn as stubble is mostly its painted shadow
STUBBLE_PAINT = 0.4
#: the brows' value (brightness) as a fraction of the hair's, unless set by hand
BROW_VALUE = 0.8
#: how much lighter a strand's tip is, and how much darker its root (in the shade of the
#: hair over it), than the colour (fractions, linear light)
TIP_LIGHTER, ROOT_SHADE = 0.2, 0.35
#: material of each kind (names of :data:`workbench.core.appearance.ROUGHNESS`)
MATERIAL = {"hair": "hair", "beard": "hair", "moustache": "hair", "brows": "brows"}

_CACHE: OrderedDict[tuple[str, tuple[tuple[str, str], ...]], Grooming] = OrderedDict()
_LOCK = threading.Lock()


def _head_key(head: TemplateHead) -> str:
    h = hashlib.sha1()
    h.update(np.ascontiguousarray(head.skin.vertices).tobytes())
    h.update(np.ascontiguousarray(head.skin.faces).tobytes())
    for code, point in sorted(head.skin_landmarks.as_dict().items()):
        h.update(code.encode())
        h.update(np.asarray(point, float).tobytes())
    return h.hexdigest()


def head_grooming(head: TemplateHead, appearance: Appearance | None) -> Grooming:
    """The chosen pieces grown on ``head`` (kept for the last :data:`CACHE_SIZE` heads).

    Raises :class:`~workbench.core.grooming.GroomingError` when the head lacks
    the landmarks a piece is placed from.
    """
    choice = appearance.grooming if appearance is not None else ()
    if not choice:
        return Grooming({}, ())
    key = (_head_key(head), tuple(choice))
    with _LOCK:
        found = _CACHE.get(key)
        if found is not None:
            _CACHE.move_to_end(key)
            return found
    grown = groom(head.skin, HeadParts(head.skin_landmarks.as_dict(), head.regions), dict(choice))
    with _LOCK:
        _CACHE[key] = grown
        while len(_CACHE) > CACHE_SIZE:
            _CACHE.popitem(last=False)
    return grown


def grooming_ready(head: TemplateHead, appearance: Appearance | None) -> bool:
    """The chosen pieces of ``appearance`` are grown on ``head`` already (no wait)."""
    choice = appearance.grooming if appearance is not None else ()
    if not choice:
        return True
    with _LOCK:
        return (_head_key(head), tuple(choice)) in _CACHE


def hair_cover(head: TemplateHead, appearance: Appearance | None) -> np.ndarray | None:
    """``(n_skin,)`` 0..1: how strongly each skin vertex is painted in the hair's colour."""
    grown = head_grooming(head, appearance)
    if grown.empty:
        return None
    cover = np.zeros(head.skin.n_vertices)
    for piece in grown.pieces:
        strength = STUBBLE_PAINT if piece.style == "stubble" else PAINT[piece.kind]
        cover = np.maximum(cover, strength * piece.cover)
    return cover


def _srgb(colour: Hsv) -> np.ndarray:
    """sRGB 0-255 of an HSV colour (as :func:`workbench.services.appearance.hsv_srgb`)."""
    return np.clip(np.rint(hsv_to_rgb(colour.to_state()) * 255.0), 0, 255)


def _hsv(srgb: tuple[int, int, int]) -> Hsv:
    h, s, v = (float(x) for x in rgb_to_hsv(np.asarray(srgb, float) / 255.0))
    return Hsv(h, min(s, 1.0), min(v, 1.0))


def hair_colour(appearance: Appearance | None) -> Hsv:
    """The hair's colour: set by hand (the ``hair`` region), else :data:`~workbench.core.appearance.HAIR`."""
    own = appearance.colour("hair") if appearance is not None else None
    return own if own is not None else _hsv(HAIR.srgb)


def piece_colour(appearance: Appearance, kind: str) -> Hsv:
    """The colour of ``kind``'s strands (see the module notes)."""
    hair = hair_colour(appearance)
    if kind != "brows":
        return hair
    own = appearance.colour("brows")
    return own if own is not None else Hsv(hair.h, hair.s, hair.v * BROW_VALUE)


def hair_look(piece: HairMesh, appearance: Appearance) -> Look:
    """An export's :class:`~workbench.core.appearance.Look` of one piece: one material named
    after its kind in the piece's colour (the case's hair colour, or its brows'), the
    strands' own colours per vertex; the source says it is an artistic addition."""
    srgb = _srgb(piece_colour(appearance, piece.kind))
    colour = (int(srgb[0]), int(srgb[1]), int(srgb[2]))
    material = Material(piece.kind, colour, piece.roughness, piece.source)
    return Look((material,), vertex_srgb=piece.srgb)


@dataclass(frozen=True, eq=False)
class HairMesh:
    """One piece ready to draw or export: ribbons, sRGB per vertex, the skin normal under
    each vertex (unit), material and roughness."""

    kind: str
    style: str
    mesh: Mesh
    srgb: np.ndarray
    normals: np.ndarray
    material: str
    roughness: float
    source: str


def hair_meshes(
    head: TemplateHead,
    appearance: Appearance | None,
    vertices: np.ndarray | None = None,
    *,
    stride: int = 1,
) -> list[HairMesh]:
    """The chosen pieces as meshes on ``vertices`` (a skin with ``head``'s triangles, mm;
    default the head's own skin), coloured; empty when nothing is chosen.  ``stride``
    > 1 keeps every so many strands of the scalp hair (a lighter view)."""
    grown = head_grooming(head, appearance)
    if grown.empty or appearance is None:
        return []
    skin_v = head.skin.vertices if vertices is None else np.asarray(vertices, float)
    if skin_v.shape != head.skin.vertices.shape:
        raise ValueError(
            f"{len(skin_v)} skin vertices given for a head with {head.skin.n_vertices}"
        )
    out = []
    for kind, drawn in grown.meshes(skin_v, head.skin.faces, stride=stride).items():
        base = srgb_to_linear(_srgb(piece_colour(appearance, kind)))
        light = drawn.shade * (1.0 - ROOT_SHADE * (1.0 - drawn.along) + TIP_LIGHTER * drawn.along)
        rgb = base[None, :] * light[:, None]
        style = appearance.style(kind)
        out.append(
            HairMesh(
                kind,
                style,
                drawn.mesh,
                linear_to_srgb(np.clip(rgb, 0.0, 1.0)),
                drawn.normals,
                MATERIAL[kind],
                ROUGHNESS[MATERIAL[kind]],
                f"{kind}: style {style!r} of the workbench's library; {ARTISTIC_NOTE}",
            )
        )
    return out


__all__ = [
    "ARTISTIC_NOTE",
    "CACHE_SIZE",
    "HairMesh",
    "hair_cover",
    "hair_meshes",
    "grooming_ready",
    "hair_colour",
    "hair_look",
    "head_grooming",
    "piece_colour",
]
