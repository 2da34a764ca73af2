"""Muscle grids painted on the skin (Kähler 2003, §7.4 and Table 7.1).

A muscle is stored the way the dissertation paints it: a coarse grid of
points *on the skin surface*, row by row from the fixed (bone) end to the
free end.  Each point is kept as a triangle of the skin mesh plus
barycentric weights, so the grid follows any deformation of the skin
exactly (§8.3.2: "apply the deformation function to the grid vertices and
re-compute the shape").  Sphincters also carry an axis (two points, each a
skin point pushed inward by a depth in mm along the local normal).

Units: mm; positions are evaluated on whatever skin mesh (same topology) the
grid is attached to.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from workbench.core.mesh import Mesh
from workbench.core.normals import vertex_normals

KINDS = ("linear", "sphincter")
ATTACHMENTS = ("skull", "jaw")


@dataclass(frozen=True, eq=False)
class SurfacePoints:
    """Points on a mesh as (face id, barycentric weights), optionally pushed inward.

    Attributes
    ----------
    faces : (k,) int64
    barycentric : (k, 3) float64
    depth_mm : (k,) float64
        Distance below the surface along the interpolated vertex normal.
    """

    faces: np.ndarray
    barycentric: np.ndarray
    depth_mm: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def __post_init__(self) -> None:
        f = np.asarray(self.faces, dtype=np.int64).reshape(-1)
        b = np.asarray(self.barycentric, dtype=np.float64).reshape(-1, 3)
        d = np.asarray(self.depth_mm, dtype=np.float64).reshape(-1)
        if len(d) == 0:
            d = np.zeros(len(f))
        if not (len(f) == len(b) == len(d)):
            raise ValueError("faces, barycentric and depth_mm must have the same length")
        for a in (f, b, d):
            a.setflags(write=False)
        object.__setattr__(self, "faces", f)
        object.__setattr__(self, "barycentric", b)
        object.__setattr__(self, "depth_mm", d)

    def __len__(self) -> int:
        return len(self.faces)

    def evaluate(self, mesh: Mesh, normals: np.ndarray | None = None) -> np.ndarray:
        """``(k, 3)`` positions on (or below) ``mesh`` in mm."""
        corners = mesh.faces[self.faces]
        p = np.einsum("ij,ijk->ik", self.barycentric, mesh.vertices[corners])
        if np.any(self.depth_mm):
            n = vertex_normals(mesh) if normals is None else normals
            nn = np.einsum("ij,ijk->ik", self.barycentric, n[corners])
            nn /= np.maximum(np.linalg.norm(nn, axis=1, keepdims=True), 1e-12)
            p = p - nn * self.depth_mm[:, None]
        return p

    def to_state(self) -> dict[str, Any]:
        return {
            "faces": self.faces.tolist(),
            "barycentric": self.barycentric.tolist(),
            "depth_mm": self.depth_mm.tolist(),
        }

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> SurfacePoints:
        return cls(
            np.asarray(state["faces"]),
            np.asarray(state["barycentric"]),
            np.asarray(state.get("depth_mm", [])),
        )


@dataclass(frozen=True, eq=False)
class MuscleGrid:
    """One muscle of the reference set.

    Attributes
    ----------
    code : str
        Identifier from ``data_tables/muscles/table71.csv`` (e.g. ``zygomatic_major_l``).
    name : str
    kind : "linear" or "sphincter"
    attachment : "skull" or "jaw"
    side : "left", "right" or "midline"
    row_lengths : tuple of int
        Points per grid row; rows run from the fixed end to the free end
        (linear) or from the outer to the inner ring (sphincter).
    points : SurfacePoints
        All grid points, row after row.
    axis : SurfacePoints or None
        Two points (sphincters only): the contraction axis ends.
    """

    code: str
    name: str
    kind: str
    attachment: str
    side: str
    row_lengths: tuple[int, ...]
    points: SurfacePoints
    axis: SurfacePoints | None = None

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ValueError(f"muscle {self.code}: kind must be one of {KINDS}")
        if self.attachment not in ATTACHMENTS:
            raise ValueError(f"muscle {self.code}: attachment must be one of {ATTACHMENTS}")
        if sum(self.row_lengths) != len(self.points):
            raise ValueError(f"muscle {self.code}: row lengths do not add up to the point count")
        if self.kind == "sphincter" and (self.axis is None or len(self.axis) != 2):
            raise ValueError(f"muscle {self.code}: a sphincter needs a two-point axis")

    def rows(self, mesh: Mesh) -> list[np.ndarray]:
        """Grid rows as ``(n_i, 3)`` arrays of positions on ``mesh``."""
        pts = self.points.evaluate(mesh)
        bounds = np.cumsum((0, *self.row_lengths))
        return [pts[a:b] for a, b in zip(bounds[:-1], bounds[1:], strict=True)]

    def to_state(self) -> dict[str, Any]:
        return {
            "code": self.code,
            "name": self.name,
            "kind": self.kind,
            "attachment": self.attachment,
            "side": self.side,
            "row_lengths": list(self.row_lengths),
            "points": self.points.to_state(),
            "axis": None if self.axis is None else self.axis.to_state(),
        }

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> MuscleGrid:
        axis = state.get("axis")
        return cls(
            state["code"],
            state["name"],
            state["kind"],
            state["attachment"],
            state["side"],
            tuple(int(n) for n in state["row_lengths"]),
            SurfacePoints.from_state(state["points"]),
            None if axis is None else SurfacePoints.from_state(axis),
        )
