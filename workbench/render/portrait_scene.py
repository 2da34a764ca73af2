"""What a portrait draws: the parts of a head with their colours, refined and shaded.

:func:`portrait_parts` turns a head (head frame, mm) into the meshes
:mod:`workbench.render.portrait` draws, each with unit normals per vertex, a
roughness and either colours per vertex (sRGB) or a texture (a fit-scan
skin atlas, with texture coordinates per triangle corner):

* the skin, refined twice by :func:`refine` (Phong tessellation: the
  reconstruction's vertices stay where they are, the new ones lie on the
  smooth surface their normals describe), so its outline is round at print
  size; with colour, the Look's skin tone and lips
  (:func:`workbench.core.appearance.head_looks`);
* the eyes, as finer globes (:func:`workbench.core.appearance.fine_eyes`,
  level :data:`EYE_SUBDIVISIONS`) painted per vertex with iris, limbal ring
  and pupil (:func:`workbench.core.appearance.eyes_colours`);
* the teeth and the tongue (what a parted mouth shows); the skull and the
  mandible lie under the skin and are not drawn.

Without colour every part is one neutral clay (:data:`CLAY_SRGB`), the eyes
blank as on a sculpted bust.  Every part coloured per vertex is darkened by
its ambient occlusion among all the parts (:func:`occlusion`: rays cast with
:class:`workbench.core.raycast.RayCaster`), which gives the soft shading of
the creases without a shadow pass; a scan's skin texture is left as it is
(it holds the scan's own shading).  :func:`add_parts` hands the parts to a
pyvista plotter as PBR actors (metallic 0).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from workbench.core.appearance import (
    OTHER,
    ROUGHNESS,
    Look,
    SkinTexture,
    eye_gazes,
    eyes_colours,
    fine_eyes,
    head_looks,
    linear_to_srgb,
    srgb_to_linear,
)
from workbench.core.mesh import Mesh

if TYPE_CHECKING:
    from workbench.model.appearance import Appearance
    from workbench.model.template import TemplateHead

#: the no-colour version: one neutral clay (sRGB, no hue) and its roughness
CLAY_SRGB, CLAY_ROUGHNESS = (178, 178, 178), 0.6
#: the parts drawn (the skull and the mandible lie under the skin)
PARTS = ("skin", "eyes", "upper_teeth", "lower_teeth", "tongue")
#: the parts inside the mouth: fully shaded by their occlusion and at least this rough (the
#: glint of wet teeth in the shade of the lips would read as metal in a slightly open mouth)
MOUTH, MOUTH_ROUGHNESS = ("upper_teeth", "lower_teeth", "tongue"), 0.7
#: refinement levels of the skin (each splits every triangle in four) and the eyes' icosphere
#: level (6: 40962 vertices a globe, ~0.23 mm apart: a crisp pupil in vertex colours)
SKIN_LEVELS, EYE_SUBDIVISIONS = 2, 6
#: ambient occlusion baked into the vertex colours: rays per vertex, how far a wall
#: shades (mm), and the share of the light it may take away (0..1)
OCCLUSION_RAYS, OCCLUSION_REACH_MM, OCCLUSION_STRENGTH = 24, 25.0, 0.8


def refine(
    mesh: Mesh,
    normals: np.ndarray,
    colours: np.ndarray | None = None,
    corner_uv: np.ndarray | None = None,
    alpha: float = 0.75,
) -> tuple[Mesh, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """One level of Phong tessellation (Boubekeur & Alexa 2008): every triangle split in four.

    The old vertices stay; each edge gets a vertex at its midpoint moved
    toward the curved surface the two end normals describe (the midpoint's
    projections onto the two tangent planes, averaged, blended with the flat
    midpoint by ``alpha``).  ``normals`` ``(n, 3)`` unit, per vertex; the new
    vertices get the normalised mean of their edge's.  ``colours`` ``(n, k)``
    per vertex are averaged along the edges; ``corner_uv`` ``(m, 3, 2)`` per
    triangle corner are split with each triangle.  Same frame and units as
    ``mesh``.
    """
    v, f = mesh.vertices, np.asarray(mesh.faces, np.int64)
    pairs = f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2)
    keys = np.sort(pairs, axis=1)
    edges, which = np.unique(keys, axis=0, return_inverse=True)
    which = which.reshape(-1, 3)  # edge of (v0 v1), (v1 v2), (v2 v0) per triangle
    a, b = edges[:, 0], edges[:, 1]
    mid = 0.5 * (v[a] + v[b])
    na, nb = normals[a], normals[b]
    proj_a = mid - np.sum((mid - v[a]) * na, axis=1)[:, None] * na
    proj_b = mid - np.sum((mid - v[b]) * nb, axis=1)[:, None] * nb
    new_v = (1.0 - alpha) * mid + alpha * 0.5 * (proj_a + proj_b)
    new_n = na + nb
    lengths = np.linalg.norm(new_n, axis=1, keepdims=True)
    new_n = np.where(lengths > 1e-12, new_n / np.maximum(lengths, 1e-12), na)
    n = len(v)
    m01, m12, m20 = (n + which[:, i] for i in range(3))
    faces = np.concatenate(
        [
            np.column_stack([f[:, 0], m01, m20]),
            np.column_stack([f[:, 1], m12, m01]),
            np.column_stack([f[:, 2], m20, m12]),
            np.column_stack([m01, m12, m20]),
        ]
    )
    out_colours = None
    if colours is not None:
        c = np.asarray(colours, float)
        out_colours = np.vstack([c, 0.5 * (c[a] + c[b])])
    out_uv = None
    if corner_uv is not None:
        uv = np.asarray(corner_uv, float)
        u01, u12, u20 = (0.5 * (uv[:, i] + uv[:, (i + 1) % 3]) for i in range(3))
        out_uv = np.concatenate(
            [
                np.stack([uv[:, 0], u01, u20], axis=1),
                np.stack([uv[:, 1], u12, u01], axis=1),
                np.stack([uv[:, 2], u20, u12], axis=1),
                np.stack([u01, u12, u20], axis=1),
            ]
        )
    return Mesh(np.vstack([v, new_v]), faces), np.vstack([normals, new_n]), out_colours, out_uv


@dataclass(frozen=True, eq=False)
class DrawnPart:
    """One part ready to draw: geometry (mm, head frame), unit normals per vertex, the
    roughness, and either per-vertex colours (sRGB uint8) or a texture with corner UVs."""

    name: str
    mesh: Mesh
    normals: np.ndarray
    roughness: float
    vertex_srgb: np.ndarray | None = None
    texture: np.ndarray | None = None
    corner_uv: np.ndarray | None = None


def _hemisphere(k: int) -> np.ndarray:
    """``(k, 3)`` cosine-weighted directions about +z (a fixed, even spiral: no noise)."""
    u = (np.arange(k) + 0.5) / k
    phi = 2.0 * np.pi * ((np.arange(k) * 0.6180339887) % 1.0)
    r = np.sqrt(u)
    return np.column_stack([r * np.cos(phi), r * np.sin(phi), np.sqrt(1.0 - u)])


def occlusion(
    points: np.ndarray,
    normals: np.ndarray,
    caster: Any,
    *,
    rays: int = OCCLUSION_RAYS,
    reach_mm: float = OCCLUSION_REACH_MM,
) -> np.ndarray:
    """``(n,)`` ambient occlusion 0 (closed in) .. 1 (open sky) of surface points (mm).

    ``rays`` cosine-weighted directions about each unit normal are cast
    against ``caster`` (a :class:`workbench.core.raycast.RayCaster` of the whole
    head); a hit at distance ``t`` blocks ``1 - t / reach_mm`` of its ray, so
    near walls (the inside of a nostril, the lid over the eyeball) darken
    most and walls farther than ``reach_mm`` not at all.
    """
    p = np.asarray(points, float).reshape(-1, 3)
    n = np.asarray(normals, float).reshape(-1, 3)
    if len(p) == 0:
        return np.ones(0)
    helper = np.where(np.abs(n[:, [0]]) > 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
    t1 = np.cross(n, helper)
    t1 /= np.maximum(np.linalg.norm(t1, axis=1, keepdims=True), 1e-12)
    t2 = np.cross(n, t1)
    local = _hemisphere(rays)
    directions = (
        local[None, :, 0, None] * t1[:, None]
        + local[None, :, 1, None] * t2[:, None]
        + local[None, :, 2, None] * n[:, None]
    ).reshape(-1, 3)
    origins = np.repeat(p + 0.05 * n, rays, axis=0)
    hits = caster.first_hits(origins, directions, max_distance=reach_mm)
    blocked = np.where(hits.hit, np.clip(1.0 - hits.distance / reach_mm, 0.0, 1.0), 0.0)
    return 1.0 - blocked.reshape(-1, rays).mean(axis=1)


def _darken(srgb: np.ndarray, ao: np.ndarray, strength: float) -> np.ndarray:
    """sRGB colours (uint8) with their linear light scaled down by ``strength`` (0..1)
    of the occlusion ``1 - ao``."""
    factor = 1.0 - strength * (1.0 - np.clip(ao, 0.0, 1.0))
    return linear_to_srgb(srgb_to_linear(srgb) * factor[:, None])


def _solid(srgb: Sequence[int], n: int) -> np.ndarray:
    return np.tile(np.asarray(srgb, np.uint8), (n, 1))


def portrait_parts(
    head: TemplateHead,
    *,
    colour: bool,
    skin_tone: str,
    iris: str,
    skin_texture: SkinTexture | None,
    appearance: Appearance | None = None,
) -> list[DrawnPart]:
    """The parts to draw (head frame, mm) with their colours: the Looks, or clay.

    The skin is refined once, every part's vertices are darkened by their
    ambient occlusion (:func:`occlusion`; not a skin that carries a scan's
    texture, whose colours hold the scan's own shading), and the skin is
    refined once more.  The eyes are finer globes with painted vertices.
    With an ``appearance`` (a case's colours) its tone, painted regions and
    iris replace ``skin_tone`` and ``iris``, and its hair, brows, beard and
    moustache are drawn as ribbons (:func:`workbench.services.grooming.hair_meshes`;
    in clay too, as on a sculpted bust), after the occlusion: hair is not
    shaded by it but darkens towards its roots.
    """
    if appearance is not None:
        skin_tone, iris = appearance.tone, appearance.iris
    meshes = {p: head.meshes[p] for p in PARTS if p in head.meshes}
    centres = np.asarray(head.eye_centres, float).reshape(-1, 3)
    gazes = None
    if "eyes" in meshes and len(centres):
        gazes = eye_gazes(meshes["eyes"].vertices, centres)
        meshes["eyes"] = fine_eyes(
            centres, gazes, float(head.eye_radius), subdivisions=EYE_SUBDIVISIONS
        )
    looks: dict[str, Look] = {}
    if colour:
        others = {k: m for k, m in meshes.items() if k != "eyes"}
        looks = head_looks(
            others, None, regions=head.regions, tone=skin_tone, skin_texture=skin_texture
        )
        if appearance is not None and skin_texture is None and "skin" in looks:
            from workbench.services.appearance import skin_colours

            looks["skin"] = replace(looks["skin"], vertex_srgb=skin_colours(head, appearance))
    drawn: dict[str, DrawnPart] = {}
    for name, mesh in meshes.items():
        normals = np.asarray(mesh.vertex_normals, float)
        look = looks.get(name)
        if not colour:
            part = DrawnPart(
                name, mesh, normals, CLAY_ROUGHNESS, _solid(CLAY_SRGB, mesh.n_vertices)
            )
        elif name == "eyes" and gazes is not None:
            painted = eyes_colours(
                mesh.vertices, centres, gazes, iris=iris, radius=float(head.eye_radius)
            )
            part = DrawnPart(name, mesh, normals, ROUGHNESS["eye"], painted)
        elif look is not None:
            material = look.materials[0]
            srgb = look.vertex_srgb
            if srgb is None and material.texture is None:
                srgb = _solid(material.srgb, mesh.n_vertices)
            rough = (
                max(material.roughness, MOUTH_ROUGHNESS) if name in MOUTH else material.roughness
            )
            part = DrawnPart(name, mesh, normals, rough, srgb, material.texture, look.corner_uv)
        else:
            part = DrawnPart(
                name, mesh, normals, ROUGHNESS["other"], _solid(OTHER.srgb, mesh.n_vertices)
            )
        if name == "skin" and SKIN_LEVELS:
            part = _refined(part)
        drawn[name] = part
    _occlude(drawn, head.meshes.get("eyes"))
    if "skin" in drawn:
        for _ in range(SKIN_LEVELS - 1):
            drawn["skin"] = _refined(drawn["skin"])
    if appearance is not None and appearance.grooming:
        from workbench.services.grooming import hair_meshes

        for hair in hair_meshes(head, appearance):
            n = hair.mesh.n_vertices
            drawn[hair.kind] = DrawnPart(
                hair.kind,
                hair.mesh,
                hair.normals,
                hair.roughness if colour else CLAY_ROUGHNESS,
                hair.srgb if colour else _solid(CLAY_SRGB, n),
            )
    return list(drawn.values())


def _refined(part: DrawnPart) -> DrawnPart:
    mesh, normals, srgb, uv = refine(part.mesh, part.normals, part.vertex_srgb, part.corner_uv)
    rgb = None if srgb is None else np.clip(np.rint(srgb), 0, 255).astype(np.uint8)
    return replace(part, mesh=mesh, normals=normals, vertex_srgb=rgb, corner_uv=uv)


def _occlude(drawn: dict[str, DrawnPart], coarse_eyes: Mesh | None) -> None:
    """Darken every vertex-coloured part by its occlusion among all the parts (in place).

    The fine eyeballs are stood in for by the head's own coarser globes
    (``coarse_eyes``, the same spheres): their occlusion is cast from the
    coarse vertices and spread to the fine ones from the nearest four.
    """
    from scipy.spatial import cKDTree

    from workbench.core.raycast import RayCaster

    stand_in = {
        k: (d.mesh if k != "eyes" or coarse_eyes is None else coarse_eyes) for k, d in drawn.items()
    }
    meshes = list(stand_in.values())
    offsets = np.cumsum([0] + [m.n_vertices for m in meshes])
    caster = RayCaster(
        Mesh(
            np.vstack([m.vertices for m in meshes]),
            np.vstack([np.asarray(m.faces, np.int64) + offsets[i] for i, m in enumerate(meshes)]),
        )
    )
    for name, d in list(drawn.items()):
        if d.vertex_srgb is None or d.corner_uv is not None:
            continue
        rays = OCCLUSION_RAYS if name in ("skin", "eyes") else OCCLUSION_RAYS // 2
        mesh = stand_in[name]
        ao = occlusion(mesh.vertices, mesh.vertex_normals, caster, rays=rays)
        if mesh is not d.mesh:
            dist, near = cKDTree(mesh.vertices).query(d.mesh.vertices, k=4)
            weight = 1.0 / np.maximum(dist, 1e-6)
            ao = (ao[near] * weight).sum(axis=1) / weight.sum(axis=1)
        strength = 1.0 if name in MOUTH else OCCLUSION_STRENGTH
        drawn[name] = replace(d, vertex_srgb=_darken(d.vertex_srgb, ao, strength))


def _polydata(part: DrawnPart) -> Any:
    """``pyvista.PolyData`` of a part: shared vertices with their colours, or one vertex
    per triangle corner when the part carries texture coordinates per corner."""
    import pyvista as pv

    f = np.asarray(part.mesh.faces, np.int64)
    if part.corner_uv is not None:
        poly = pv.PolyData.from_regular_faces(
            part.mesh.vertices[f].reshape(-1, 3),
            np.arange(f.size, dtype=np.int64).reshape(-1, 3),  # type: ignore[arg-type]
        )
        poly.point_data["Normals"] = part.normals[f].reshape(-1, 3)
        poly.active_texture_coordinates = np.asarray(part.corner_uv, float).reshape(-1, 2)
    else:
        poly = pv.PolyData.from_regular_faces(
            np.array(part.mesh.vertices, float),
            f,  # type: ignore[arg-type]
        )
        poly.point_data["Normals"] = part.normals
        if part.vertex_srgb is not None:
            poly.point_data["srgb"] = part.vertex_srgb
    poly.point_data.active_normals_name = "Normals"
    return poly


def _texture(image: np.ndarray) -> Any:
    """A VTK texture of an sRGB image (row 0 at the top), marked sRGB for PBR."""
    import pyvista as pv

    tex = pv.Texture(np.ascontiguousarray(np.asarray(image, np.uint8)[::-1]))
    tex.UseSRGBColorSpaceOn()
    tex.InterpolateOn()
    tex.MipmapOn()
    return tex


def add_parts(plotter: Any, parts: Sequence[DrawnPart]) -> None:
    """PBR actors (metallic 0) for the parts: colours per vertex, or a base-colour texture."""
    for part in parts:
        common = {
            "pbr": True,
            "metallic": 0.0,
            "roughness": part.roughness,
            "smooth_shading": True,
            "name": part.name,
        }
        poly = _polydata(part)
        if part.texture is not None and part.corner_uv is not None:
            actor = plotter.add_mesh(poly, color="white", **common)
            actor.GetProperty().SetBaseColorTexture(_texture(part.texture))
        else:
            plotter.add_mesh(poly, scalars="srgb", rgb=True, **common)


__all__ = [
    "CLAY_SRGB",
    "PARTS",
    "DrawnPart",
    "add_parts",
    "occlusion",
    "portrait_parts",
    "refine",
]
