"""glTF 2.0 binary (``.glb``) export of a head with morph targets (shape keys) and a clip.

The file holds one scene with a root node ``head`` and, below it, the skin
node (one mesh, one primitive: ``POSITION``, ``NORMAL``, ``indices``) with
one morph target per expression, and a node per inner part (eyes, upper and
lower teeth, tongue, mandible, cranium ...).

Units and axes
--------------
glTF is metres.  The vertices are the caller's meshes in the caller's frame,
**converted to metres** (× 0.001, float32), with no rotation and every node
at the identity transform: a glTF position × 1000 is the mm coordinate of
the same vertex in the workbench's PLY files of that head (same axes, same
handedness, same origin).  The asset's ``extras`` say so (``units``,
``mm_per_unit``, ``frame``).  For the head frame (x to the subject's left,
y up, z toward the face) this is glTF's own convention (+Y up, +Z the
asset's front); a head in a skull file's frame keeps that frame's axes.
Blender's glTF importer turns glTF's +Y up into Blender's +Z up, its PLY
importer turns nothing: import the PLY with Forward Axis -Z, Up Axis Y
and Scale 0.001 and the two overlay.

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
"""

from __future__ import annotations

import struct
from collections.abc import Mapping, Sequence
from os import PathLike
from pathlib import Path

import numpy as np
import pygltflib as g

from workbench.core.mesh import Mesh
from workbench.core.normals import vertex_normals
from workbench.io.atomic import write_bytes_atomic

#: metres per millimetre (glTF is metres, the workbench mm)
MM_TO_M = 0.001

Keyframes = Sequence[tuple[float, Mapping[str, float]]]

__all__ = ["MM_TO_M", "write_glb"]


class _Builder:
    """Accumulates one binary buffer and its bufferViews/accessors."""

    def __init__(self) -> None:
        self.gltf = g.GLTF2(asset=g.Asset(version="2.0", generator="workbench"))
        self.blob = bytearray()

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

    def mesh(
        self,
        name: str,
        mesh: Mesh,
        targets: Mapping[str, np.ndarray] | None = None,
        weights: Sequence[float] | None = None,
    ) -> int:
        v = mesh.vertices * MM_TO_M
        normals = vertex_normals(mesh)
        attributes = g.Attributes(
            POSITION=self.accessor(v, g.VEC3, min_max=True),
            NORMAL=self.accessor(normals, g.VEC3),
        )
        prim = g.Primitive(
            attributes=attributes,
            indices=self.accessor(
                mesh.faces.reshape(-1).astype(np.uint32),
                g.SCALAR,
                target=g.ELEMENT_ARRAY_BUFFER,
            ),
            mode=g.TRIANGLES,
        )
        out = g.Mesh(name=name, primitives=[prim])
        if targets:
            prim.targets = [
                g.Attributes(POSITION=self.accessor(d * MM_TO_M, g.VEC3, min_max=True))
                for d in targets.values()
            ]
            out.weights = [float(w) for w in (weights or [0.0] * len(targets))]
            out.extras = {"targetNames": list(targets)}
        self.gltf.meshes.append(out)
        return len(self.gltf.meshes) - 1

    def node(self, name: str, mesh: int | None = None) -> int:
        self.gltf.nodes.append(g.Node(name=name, mesh=mesh))
        return len(self.gltf.nodes) - 1

    def to_bytes(self) -> bytes:
        self.gltf.buffers = [g.Buffer(byteLength=len(self.blob))]
        self.gltf.set_binary_blob(bytes(self.blob))
        return b"".join(self.gltf.save_to_bytes())


def _displacements(
    rest: Mesh, targets: Mapping[str, np.ndarray], what: str
) -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    for name, pos in targets.items():
        p = np.asarray(pos, dtype=np.float64)
        if p.shape != rest.vertices.shape:
            raise ValueError(
                f"{what} target {name!r}: expected {rest.vertices.shape} positions, got {p.shape}"
            )
        out[name] = p - rest.vertices
    return out


def _with_arkit(
    deltas: dict[str, np.ndarray], names_arkit: Mapping[str, Mapping[str, float]] | None
) -> dict[str, np.ndarray]:
    if not names_arkit:
        return deltas
    out = dict(deltas)
    for arkit, mix in names_arkit.items():
        if arkit in deltas:
            raise ValueError(f"ARKit target name {arkit!r} is already a target name")
        total = np.zeros_like(next(iter(deltas.values())))
        for name, w in mix.items():
            if name not in deltas:
                raise ValueError(f"ARKit target {arkit!r} uses unknown target {name!r}")
            total += float(w) * deltas[name]
        out[arkit] = total
    return out


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
    """
    path = Path(path)
    extra_nodes = dict(extra_nodes or {})
    node_targets = dict(node_targets or {})
    deltas = _with_arkit(_displacements(skin, targets, skin_name), names_arkit)
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
    }
    morphed: list[int] = []
    skin_node = b.node(skin_name, b.mesh(skin_name, skin, deltas, default))
    morphed.append(skin_node)
    children = [skin_node]
    for name, mesh in extra_nodes.items():
        part = node_targets.get(name)
        if part:
            unknown = set(part) - set(targets)
            if unknown:
                raise ValueError(f"node {name!r}: unknown targets {sorted(unknown)}")
            d = _displacements(mesh, part, name)
            zero = np.zeros_like(mesh.vertices)
            # the same target list (and order) as the skin, so one set of weights drives both
            part_deltas = {n: d.get(n, zero) for n in targets}
            part_deltas = _with_arkit(part_deltas, names_arkit)
            node = b.node(name, b.mesh(name, mesh, part_deltas, default))
            morphed.append(node)
        else:
            node = b.node(name, b.mesh(name, mesh))
        children.append(node)
    root = b.node("head")
    b.gltf.nodes[root].children = children
    b.gltf.scenes = [g.Scene(name="head", nodes=[root])]
    b.gltf.scene = 0

    if animation:
        times = np.array([float(t) for t, _ in animation])
        if np.any(np.diff(times) <= 0) or times[0] < 0:
            raise ValueError("animation key times must be >= 0 and strictly increasing")
        values = np.array([[float(frame.get(n, 0.0)) for n in names] for _, frame in animation])
        t_acc = b.accessor(times, g.SCALAR, target=None, min_max=True)
        w_acc = b.accessor(values.reshape(-1), g.SCALAR, target=None)
        clip = g.Animation(name=clip_name)
        for node in morphed:
            clip.samplers.append(
                g.AnimationSampler(input=t_acc, output=w_acc, interpolation="LINEAR")
            )
            clip.channels.append(
                g.AnimationChannel(
                    sampler=len(clip.samplers) - 1,
                    target=g.AnimationChannelTarget(node=node, path="weights"),
                )
            )
        b.gltf.animations = [clip]

    payload = b.to_bytes()
    if payload[:4] != b"glTF" or struct.unpack("<I", payload[8:12])[0] != len(payload):
        raise RuntimeError("internal error: malformed GLB")
    write_bytes_atomic(path, payload)
    return path
