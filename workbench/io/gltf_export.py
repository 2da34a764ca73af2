"""glTF 2.0 binary (``.glb``) export of a head with morph targets (shape keys) and a clip.

The file holds one scene with a root node ``head`` and, below it, the skin
node (one mesh: ``POSITION``, ``NORMAL``, ``indices``) with one morph target
per expression, and a node per inner part (eyes, upper and lower teeth,
tongue, mandible, cranium ...).

Materials
---------
Every primitive has a PBR metallic-roughness material (metallic 0), given
per node as a :class:`workbench.core.appearance.Look`; without one a node
gets the plain preset of its name (:func:`workbench.core.appearance.plain_look`;
the skin node the skin preset).  Per-vertex colours are ``COLOR_0`` (linear
RGB) on one primitive with the look's first material: the skin carries its
tone with the lips blended in that way, rather than split triangle by
triangle.  A look with several materials and no per-vertex colours is one
mesh with a primitive per material, sharing the vertex and morph-target
accessors.  A texture (PNG, embedded) comes with ``TEXCOORD_0``; glTF's
texture origin is the image's top-left, so ``v`` is ``1 - v`` of the look's
(OBJ-style) coordinates.  Where the texture coordinates differ between the
corners that meet at a vertex (the skin atlas gives every triangle its own
patch), that vertex is written once per coordinate, with its normal and
morph displacements copied.  ``baseColorFactor`` is the linear value of the
preset's sRGB colour (white under a texture or ``COLOR_0``).  The colours
are artistic defaults, not evidence; ``asset.extras`` says so.

Units and axes
--------------
glTF is metres.  The vertices are the caller's meshes in the caller's frame,
**converted to metres** (× 0.001, float32), with no rotation and every node
at the identity transform: a glTF position × 1000 is the mm coordinate of
the same vertex in the workbench's PLY files of that head (same axes, same
handedness, same origin).  The asset's ``extras`` say so (``units``,
``mm_per_unit``, ``frame``, ``note``, ``axes``, ``materials``).  The PLY
files are in mm and declare no up axis; glTF declares metres and +Y up.  For
the head frame (x to the subject's left, y up, z toward the face) this is
glTF's own convention (+Y up, +Z the asset's front); a head in a skull
file's frame keeps that frame's axes.  Blender's glTF importer turns glTF's
+Y up into Blender's +Z up, its PLY importer turns nothing: import the PLY
with Forward Axis -Z, Up Axis Y and Scale 0.001 and the two overlay.

Morph targets
-------------
Each target stores ``POSITION`` displacements (target − rest, metres, with
the accessor ``min``/``max`` the specification requires), its name in
``mesh.extras.targetNames`` (Blender's importer makes these the shape-key
names; three.js uses them for ``morphTargetDictionary``) and a default
weight of 0 (or the ``weights`` given).  A rendered frame with weights
``w`` is ``rest + Σ w_i Δ_i``.  Parts that follow the jaw (mandible, lower
teeth, tongue) may carry the same targets (``node_targets``) so that an
expression that opens the jaw moves them with the skin; their weights are
animated with the skin's.

Optional ``names_arkit`` adds a second set of targets, each a weighted sum
of the first set's displacements (``{"jawOpen": {"au26": 1.0}, ...}``),
appended after them with their own names.

The optional animation clip is a ``weights`` channel per morphed node
(LINEAR interpolation, times in seconds).

Hair and other ribbons
----------------------
A node may be shaded otherwise (:class:`Shading`): hair, brows, beards and
moustaches (:mod:`workbench.services.grooming`, artistic additions) are thin
open ribbons, written with their own shading normals (the skin's normal under
each strand, leaning to the ribbon's edges) rather than those of their
triangles, materials with ``doubleSided`` true, and their colours split into
``baseColorFactor`` (the per-channel maximum of the vertex colours: the
colour of the lightest strands) times ``COLOR_0`` (each vertex relative to it,
0..1), so a viewer that ignores ``COLOR_0`` still shows the hair's hue.
Their morph targets are **sparse** accessors (only the vertices that move;
displacements shorter than the node's ``min_displacement_mm`` are written as
0): most of a head's hair does not move when the face smiles.
"""

from __future__ import annotations

import io
import struct
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from os import PathLike
from pathlib import Path

import numpy as np
import pygltflib as g

from workbench.core.appearance import Look, Material, plain_look, srgb_to_linear
from workbench.core.mesh import Mesh
from workbench.core.normals import vertex_normals
from workbench.io.atomic import write_with_atomic

#: metres per millimetre (glTF is metres, the workbench mm)
MM_TO_M = 0.001

Keyframes = Sequence[tuple[float, Mapping[str, float]]]

#: what ``asset.extras.axes`` says: glTF's +Y up holds for the head frame, not for every frame
AXES_NOTE = (
    "no rotation is applied: in the head frame (x to the subject's left, y up, z toward the "
    "face) +Y is up and +Z the front, as glTF expects; a head in a skull file's frame keeps "
    "that file's axes (the PLY files, in mm, declare no up axis)"
)

#: what ``asset.extras.materials`` says about the colours
MATERIALS_NOTE = (
    "PBR metallic-roughness, metallic 0; colours are artistic defaults "
    "(workbench.core.appearance presets) or the scan's own colours, not evidence about the person"
)

__all__ = [
    "AXES_NOTE",
    "MATERIALS_NOTE",
    "MM_TO_M",
    "Shading",
    "png_bytes",
    "split_corners",
    "write_glb",
]


@dataclass(frozen=True, eq=False)
class Shading:
    """How a node is shaded when it is not a closed surface (hair ribbons).

    ``normals`` ``(n, 3)``: unit shading normals per vertex of the node's mesh
    (None: the normals of its triangles); ``double_sided``: its materials are
    ``doubleSided`` (seen from behind too); ``tinted``: its per-vertex colours
    are split into ``baseColorFactor`` (their per-channel maximum) times
    ``COLOR_0`` (0..1); ``min_displacement_mm``: morph targets are sparse
    accessors holding only the vertices that move at least this far (None:
    dense, every vertex, as the skin's).
    """

    normals: np.ndarray | None = None
    double_sided: bool = False
    tinted: bool = False
    min_displacement_mm: float | None = None


def png_bytes(image: np.ndarray) -> bytes:
    """An ``(h, w, 3)`` uint8 sRGB image as PNG bytes (Pillow)."""
    from PIL import Image

    buffer = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(image, dtype=np.uint8), "RGB").save(buffer, format="PNG")
    return buffer.getvalue()


def split_corners(
    faces: np.ndarray, corner_uv: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Vertices split where their corners' texture coordinates differ.

    Returns ``(source, new_faces, uv)``: for each new vertex the index of the
    vertex it copies, the triangles over the new vertices, and one ``(u, v)``
    per new vertex.  A vertex whose corners all share one coordinate stays one
    vertex.
    """
    f = np.asarray(faces, np.int64).reshape(-1)
    uv = np.asarray(corner_uv, np.float64).reshape(-1, 2)
    keys = np.column_stack([f.astype(np.float64), uv])
    unique, inverse = np.unique(keys, axis=0, return_inverse=True)
    return unique[:, 0].astype(np.int64), inverse.reshape(-1, 3), unique[:, 1:]


class _Builder:
    """Accumulates one binary buffer and its bufferViews/accessors, materials and images."""

    def __init__(self) -> None:
        self.gltf = g.GLTF2(asset=g.Asset(version="2.0", generator="workbench"))
        self.blob = bytearray()
        self._materials: dict[str, int] = {}
        self._images: dict[int, int] = {}

    def _view(self, data: bytes, target: int | None) -> int:
        pad = -len(self.blob) % 4
        self.blob.extend(b"\0" * pad)
        view = g.BufferView(buffer=0, byteOffset=len(self.blob), byteLength=len(data))
        if target is not None:
            view.target = target
        self.blob.extend(data)
        self.gltf.bufferViews.append(view)
        return len(self.gltf.bufferViews) - 1

    def accessor(
        self,
        array: np.ndarray,
        kind: str,
        *,
        target: int | None = g.ARRAY_BUFFER,
        min_max: bool = False,
    ) -> int:
        if array.dtype.kind == "u":
            array = np.ascontiguousarray(array, dtype="<u4")
            component = g.UNSIGNED_INT
        else:
            array = np.ascontiguousarray(array, dtype="<f4")
            component = g.FLOAT
        count = int(array.shape[0]) if array.ndim else 1
        acc = g.Accessor(
            bufferView=self._view(array.tobytes(), target),
            componentType=component,
            count=count,
            type=kind,
        )
        if min_max:
            flat = array.reshape(count, -1)
            acc.min = [float(v) for v in flat.min(axis=0)]
            acc.max = [float(v) for v in flat.max(axis=0)]
        self.gltf.accessors.append(acc)
        return len(self.gltf.accessors) - 1

    def _texture(self, image: np.ndarray) -> int:
        """The texture index of ``image`` (embedded once however many materials use it)."""
        key = id(image)
        if key not in self._images:
            if not self.gltf.samplers:
                self.gltf.samplers.append(
                    g.Sampler(
                        magFilter=g.LINEAR,
                        minFilter=g.LINEAR,
                        wrapS=g.CLAMP_TO_EDGE,
                        wrapT=g.CLAMP_TO_EDGE,
                    )
                )
            view = self._view(png_bytes(image), None)
            self.gltf.images.append(g.Image(bufferView=view, mimeType="image/png"))
            self.gltf.textures.append(g.Texture(sampler=0, source=len(self.gltf.images) - 1))
            self._images[key] = len(self.gltf.textures) - 1
        return self._images[key]

    def material(
        self,
        material: Material,
        vertex_colours: bool,
        *,
        double_sided: bool = False,
        factor: np.ndarray | None = None,
    ) -> int:
        """The index of ``material`` (one glTF material per name, colouring and sides);
        ``factor``: the linear base colour under ``COLOR_0`` (default white)."""
        tint = None if factor is None else tuple(round(float(c), 7) for c in factor)
        key = f"{material.name}|{vertex_colours}|{double_sided}|{tint}"
        if key in self._materials:
            return self._materials[key]
        pbr = g.PbrMetallicRoughness(
            baseColorFactor=[1.0, 1.0, 1.0, 1.0],
            metallicFactor=float(material.metallic),
            roughnessFactor=float(material.roughness),
        )
        if material.texture is not None:
            pbr.baseColorTexture = g.TextureInfo(index=self._texture(material.texture))
        elif not vertex_colours:
            pbr.baseColorFactor = [*(float(c) for c in srgb_to_linear(material.srgb)), 1.0]
        elif tint is not None:
            pbr.baseColorFactor = [*tint, 1.0]
        self.gltf.materials.append(
            g.Material(
                name=material.name,
                pbrMetallicRoughness=pbr,
                doubleSided=bool(double_sided),
                extras={"srgb": list(material.srgb), "source": material.source},
            )
        )
        self._materials[key] = len(self.gltf.materials) - 1
        return self._materials[key]

    def target(self, delta_m: np.ndarray, min_m: float | None) -> int:
        """A morph target's ``POSITION`` accessor (metres): dense, or with ``min_m``
        sparse (displacements shorter than ``min_m`` written as 0)."""
        d = np.ascontiguousarray(delta_m, dtype="<f4")
        if min_m is None:
            return self.accessor(d, g.VEC3, min_max=True)
        if min_m > 0.0:
            d = d.copy()
            d[np.einsum("ij,ij->i", d, d) < np.float32(min_m) ** 2] = 0.0
        moved = np.flatnonzero(np.any(d != 0.0, axis=1))
        if 16 * len(moved) >= 12 * len(d):  # index + value per vertex: dense is smaller
            return self.accessor(d, g.VEC3, min_max=True)
        if not len(moved):  # a sparse accessor holds at least one value
            moved = np.zeros(1, np.int64)
        acc = g.Accessor(
            byteOffset=None,
            componentType=g.FLOAT,
            count=len(d),
            type=g.VEC3,
            min=[float(v) for v in d.min(axis=0)],
            max=[float(v) for v in d.max(axis=0)],
            sparse=g.Sparse(
                count=len(moved),
                indices=g.AccessorSparseIndices(
                    bufferView=self._view(moved.astype("<u4").tobytes(), None),
                    componentType=g.UNSIGNED_INT,
                ),
                values=g.AccessorSparseValues(bufferView=self._view(d[moved].tobytes(), None)),
            ),
        )
        self.gltf.accessors.append(acc)
        return len(self.gltf.accessors) - 1

    def mesh(
        self,
        name: str,
        mesh: Mesh,
        look: Look,
        targets: Mapping[str, np.ndarray] | None = None,
        weights: Sequence[float] | None = None,
        shading: Shading | None = None,
    ) -> int:
        """A mesh with a primitive per material of ``look``; ``targets``: displacements (mm)."""
        shading = shading or Shading()
        faces = mesh.faces
        positions = mesh.vertices * MM_TO_M
        if shading.normals is not None:
            normals = np.asarray(shading.normals, float)
            if normals.shape != mesh.vertices.shape:
                raise ValueError(f"{name}: {len(normals)} normals for {mesh.n_vertices} vertices")
        else:
            normals = vertex_normals(mesh)
        colours = None if look.vertex_srgb is None else srgb_to_linear(look.vertex_srgb)
        factor = None
        if colours is not None and shading.tinted:
            factor = colours.max(axis=0)
            colours = np.divide(colours, factor, out=np.zeros_like(colours), where=factor > 0)
            colours = np.clip(colours, 0.0, 1.0)
        uv = source = None
        if look.corner_uv is not None:
            source, faces, uv = split_corners(faces, look.corner_uv)
            uv = np.column_stack([uv[:, 0], 1.0 - uv[:, 1]])  # glTF: origin at the top-left
            positions, normals = positions[source], normals[source]
            colours = None if colours is None else colours[source]
        attributes = {
            "POSITION": self.accessor(positions, g.VEC3, min_max=True),
            "NORMAL": self.accessor(normals, g.VEC3),
        }
        if uv is not None:
            attributes["TEXCOORD_0"] = self.accessor(uv, g.VEC2)
        if colours is not None:
            attributes["COLOR_0"] = self.accessor(colours, g.VEC3)
        floor = shading.min_displacement_mm
        floor_m = None if floor is None else floor * MM_TO_M
        morphs = []
        for delta in (targets or {}).values():  # one at a time: hair has many vertices
            d = np.asarray(delta, np.float64) * MM_TO_M
            morphs.append(self.target(d if source is None else d[source], floor_m))
        # per-vertex colours replace the per-triangle materials (the first one carries them)
        which = np.zeros(len(faces), np.int64) if colours is not None else look.faces_of(len(faces))
        out = g.Mesh(name=name, primitives=[])
        for k, material in enumerate(look.materials):
            rows = faces[which == k]
            if not len(rows):
                continue
            prim = g.Primitive(
                attributes=g.Attributes(**attributes),
                indices=self.accessor(
                    rows.reshape(-1).astype(np.uint32), g.SCALAR, target=g.ELEMENT_ARRAY_BUFFER
                ),
                material=self.material(
                    material,
                    colours is not None,
                    double_sided=shading.double_sided,
                    factor=factor,
                ),
                mode=g.TRIANGLES,
            )
            if morphs:
                prim.targets = [g.Attributes(POSITION=m) for m in morphs]
            out.primitives.append(prim)
        if targets:
            out.weights = [float(w) for w in (weights or [0.0] * len(targets))]
            out.extras = {"targetNames": list(targets)}
        self.gltf.meshes.append(out)
        return len(self.gltf.meshes) - 1

    def node(self, name: str, mesh: int | None = None) -> int:
        self.gltf.nodes.append(g.Node(name=name, mesh=mesh))
        return len(self.gltf.nodes) - 1

    def chunks(self) -> list[bytes | bytearray]:
        """The GLB: header, JSON chunk and binary chunk (the buffer itself, not a copy:
        a head with hair holds tens of MB)."""
        self.blob.extend(b"\0" * (-len(self.blob) % 4))
        self.gltf.buffers = [g.Buffer(byteLength=len(self.blob))]
        text = self.gltf.gltf_to_json(separators=(",", ":"), indent=None).encode("utf-8")
        text += b" " * (-len(text) % 4)
        total = 12 + 8 + len(text) + 8 + len(self.blob)
        return [
            struct.pack("<4sII", b"glTF", 2, total),
            struct.pack("<I4s", len(text), b"JSON"),
            text,
            struct.pack("<I4s", len(self.blob), b"BIN\0"),
            self.blob,
        ]


class _Deltas(Mapping[str, np.ndarray]):
    """A node's morph displacements (mm), each computed when read: ``positions - rest``
    (0 for a target the node does not move), and the ARKit targets as weighted sums of
    those, so a node with many vertices and targets (hair) never holds them all at once.
    The names and shapes are checked at once."""

    def __init__(
        self,
        rest: Mesh,
        positions: Mapping[str, np.ndarray],
        names: Sequence[str],
        arkit: Mapping[str, Mapping[str, float]] | None,
        what: str,
    ) -> None:
        self._rest = rest.vertices
        self._positions = dict(positions)
        self._arkit = dict(arkit or {})
        for name, pos in self._positions.items():
            if np.shape(pos) != self._rest.shape:
                raise ValueError(
                    f"{what} target {name!r}: expected {self._rest.shape} positions, "
                    f"got {np.shape(pos)}"
                )
        for name, mix in self._arkit.items():
            if name in names:
                raise ValueError(f"ARKit target name {name!r} is already a target name")
            for used in mix:
                if used not in names:
                    raise ValueError(f"ARKit target {name!r} uses unknown target {used!r}")
        self._names = [*names, *self._arkit]

    def _base(self, name: str) -> np.ndarray:
        pos = self._positions.get(name)
        if pos is None:
            return np.zeros_like(self._rest, dtype=np.float64)
        return np.asarray(pos, np.float64) - self._rest

    def __getitem__(self, name: str) -> np.ndarray:
        mix = self._arkit.get(name)
        if mix is None:
            if name not in self._names:
                raise KeyError(name)
            return self._base(name)
        total = np.zeros_like(self._rest, dtype=np.float64)
        for used, w in mix.items():
            total += float(w) * self._base(used)
        return total

    def __contains__(self, name: object) -> bool:
        return name in self._names

    def __iter__(self) -> Iterator[str]:
        return iter(self._names)

    def __len__(self) -> int:
        return len(self._names)


def _look_for(
    name: str, mesh: Mesh, looks: Mapping[str, Look], default: str, has_targets: bool
) -> tuple[Mesh, Look]:
    """The look of a node and the mesh to write (a look's replacement mesh only without
    morph targets, whose displacements belong to the given mesh)."""
    look = looks.get(name) or plain_look(default)
    if look.mesh is not None and has_targets:
        look = plain_look(default)
    mesh = look.mesh if look.mesh is not None else mesh
    n, m = mesh.n_vertices, mesh.n_faces
    if look.corner_uv is not None and np.shape(look.corner_uv) != (m, 3, 2):
        raise ValueError(f"{name}: texture coordinates for {len(look.corner_uv)} of {m} triangles")
    if look.vertex_srgb is not None and len(look.vertex_srgb) != n:
        raise ValueError(f"{name}: colours for {len(look.vertex_srgb)} of {n} vertices")
    if look.face_material is not None and len(look.face_material) != m:
        raise ValueError(f"{name}: materials for {len(look.face_material)} of {m} triangles")
    return mesh, look


def write_glb(
    path: str | PathLike[str],
    skin: Mesh,
    targets: Mapping[str, np.ndarray],
    *,
    extra_nodes: Mapping[str, Mesh] | None = None,
    node_targets: Mapping[str, Mapping[str, np.ndarray]] | None = None,
    weights: Mapping[str, float] | None = None,
    animation: Keyframes | None = None,
    names_arkit: Mapping[str, Mapping[str, float]] | None = None,
    skin_name: str = "skin",
    clip_name: str = "expression",
    frame: str = "",
    looks: Mapping[str, Look] | None = None,
    shading: Mapping[str, Shading] | None = None,
) -> Path:
    """Write a ``.glb``: the skin with morph targets, inner parts as nodes, an optional clip.

    Parameters
    ----------
    path : output file (written atomically: a temporary file beside it, then renamed)
    skin : rest skin (mm, head frame)
    targets : ``{name: (n, 3) positions in mm}``, one morph target each (in this order)
    extra_nodes : ``{name: mesh (mm)}`` for eyes, teeth, tongue, mandible ... (no targets)
    node_targets : ``{extra node name: {target name: positions (mm)}}``: morph targets
        of an extra node (a jaw part); names must be among ``targets``, missing ones are 0
    weights : default morph weights ``{target name: w}`` (others 0)
    animation : ``[(time_s, {target name: weight}), ...]``: a clip animating the
        weights (LINEAR); targets not named in a keyframe have weight 0 there
    names_arkit : ``{ARKit name: {target name: weight}}``: extra targets made of the others
    frame : what the meshes' frame is (the frame of the head's PLY files), for ``extras``
    looks : ``{node name: Look}`` (materials, textures, colours; see
        :func:`workbench.core.appearance.head_looks`); a node without one gets the
        plain preset of its name, the skin node the skin preset
    shading : ``{node name: Shading}`` for nodes that are not closed surfaces (hair
        ribbons: their own normals, two-sided materials, tinted colours, sparse targets)
    """
    path = Path(path)
    shading = dict(shading or {})
    extra_nodes = dict(extra_nodes or {})
    node_targets = dict(node_targets or {})
    looks = dict(looks or {})
    deltas = _Deltas(skin, targets, list(targets), names_arkit, skin_name)
    names = list(deltas)
    for key in [*(weights or {})] + [k for _, frame in (animation or []) for k in frame]:
        if key not in deltas:
            raise ValueError(f"weight for unknown target {key!r}")
    default = [float((weights or {}).get(n, 0.0)) for n in names]

    b = _Builder()
    b.gltf.asset.extras = {
        "units": "m",
        "mm_per_unit": 1000,
        "frame": frame or "the frame of the meshes given (the head's PLY files), axes unchanged",
        "note": "a position x 1000 is the vertex in mm in the head's PLY files",
        "axes": AXES_NOTE,
        "materials": MATERIALS_NOTE,
    }
    morphed: list[int] = []
    skin_mesh, skin_look = _look_for(skin_name, skin, looks, "skin", True)
    skin_node = b.node(
        skin_name,
        b.mesh(skin_name, skin_mesh, skin_look, deltas, default, shading.get(skin_name)),
    )
    morphed.append(skin_node)
    children = [skin_node]
    for name, mesh in extra_nodes.items():
        part = node_targets.get(name)
        if part:
            unknown = set(part) - set(targets)
            if unknown:
                raise ValueError(f"node {name!r}: unknown targets {sorted(unknown)}")
            # the same target list (and order) as the skin, so one set of weights drives both
            part_deltas = _Deltas(mesh, part, list(targets), names_arkit, name)
            mesh, look = _look_for(name, mesh, looks, name, True)
            node = b.node(name, b.mesh(name, mesh, look, part_deltas, default, shading.get(name)))
            morphed.append(node)
        else:
            mesh, look = _look_for(name, mesh, looks, name, False)
            node = b.node(name, b.mesh(name, mesh, look, shading=shading.get(name)))
        children.append(node)
    root = b.node("head")
    b.gltf.nodes[root].children = children
    b.gltf.scenes = [g.Scene(name="head", nodes=[root])]
    b.gltf.scene = 0
    if animation:
        _clip(b, animation, names, morphed, clip_name)

    chunks = b.chunks()
    if struct.unpack("<I", chunks[0][8:12])[0] != sum(len(c) for c in chunks):
        raise RuntimeError("internal error: malformed GLB")

    def write(tmp: Path) -> None:
        with open(tmp, "wb") as handle:
            for chunk in chunks:
                handle.write(chunk)

    write_with_atomic(path, write)
    return path


def _clip(
    b: _Builder, animation: Keyframes, names: list[str], morphed: list[int], clip_name: str
) -> None:
    """The weights clip: one LINEAR ``weights`` channel per morphed node."""
    times = np.array([float(t) for t, _ in animation])
    if np.any(np.diff(times) <= 0) or times[0] < 0:
        raise ValueError("animation key times must be >= 0 and strictly increasing")
    values = np.array([[float(frame.get(n, 0.0)) for n in names] for _, frame in animation])
    t_acc = b.accessor(times, g.SCALAR, target=None, min_max=True)
    w_acc = b.accessor(values.reshape(-1), g.SCALAR, target=None)
    clip = g.Animation(name=clip_name)
    for node in morphed:
        clip.samplers.append(g.AnimationSampler(input=t_acc, output=w_acc, interpolation="LINEAR"))
        clip.channels.append(
            g.AnimationChannel(
                sampler=len(clip.samplers) - 1,
                target=g.AnimationChannelTarget(node=node, path="weights"),
            )
        )
    b.gltf.animations = [clip]
