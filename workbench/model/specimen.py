"""The specimen: the working skull mesh and its placement in the head frame."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from workbench.core.mesh import Mesh
from workbench.model.state import readonly_array


def _check_transform(matrix: Any) -> np.ndarray:
    m = readonly_array(matrix, np.float64, (4, 4))
    if not np.isfinite(m).all():
        raise ValueError("input_to_head must be finite")
    if not np.array_equal(m[3], [0.0, 0.0, 0.0, 1.0]):
        raise ValueError("input_to_head must be affine (last row 0, 0, 0, 1)")
    return m


@dataclass(frozen=True, eq=False)
class Specimen:
    """The working skull mesh of a case.

    Parameters
    ----------
    mesh : Mesh or None
        Working mesh, vertices in the specimen's input frame, in ``units``.
        Derived geometry: the original scan stays untouched as evidence.
    units : str
        Length unit of ``mesh`` (``"mm"`` once scaled).
    input_to_head : (4, 4) float64 or None
        Homogeneous transform from the input frame to the head frame (mm), or
        ``None`` until the head frame has been set.
    """

    mesh: Mesh | None = None
    units: str = "mm"
    input_to_head: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.mesh is not None and not isinstance(self.mesh, Mesh):
            raise TypeError(f"specimen mesh must be a Mesh, got {type(self.mesh).__name__}")
        if not isinstance(self.units, str) or not self.units:
            raise ValueError("specimen units must be a non-empty string")
        if self.input_to_head is not None:
            object.__setattr__(self, "input_to_head", _check_transform(self.input_to_head))

    @property
    def head_mesh(self) -> Mesh | None:
        """The mesh mapped into the head frame, or ``None`` if either is missing."""
        if self.mesh is None or self.input_to_head is None:
            return None
        return self.mesh.transformed(self.input_to_head)

    def to_state(self) -> dict[str, Any]:
        mesh = None
        if self.mesh is not None:
            mesh = {"vertices": self.mesh.vertices, "faces": self.mesh.faces}
        transform = None if self.input_to_head is None else self.input_to_head.tolist()
        return {"mesh": mesh, "units": self.units, "input_to_head": transform}

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> Specimen:
        mesh_state = state["mesh"]
        mesh = None
        if mesh_state is not None:
            mesh = Mesh(mesh_state["vertices"], mesh_state["faces"])
        return cls(mesh, state["units"], state["input_to_head"])

    def equals(self, other: Specimen) -> bool:
        if self.units != other.units:
            return False
        if (self.mesh is None) != (other.mesh is None):
            return False
        if self.mesh is not None and other.mesh is not None and not self.mesh.equals(other.mesh):
            return False
        if self.input_to_head is None or other.input_to_head is None:
            return self.input_to_head is None and other.input_to_head is None
        return bool(np.array_equal(self.input_to_head, other.input_to_head))
