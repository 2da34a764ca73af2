"""The result of the dense skull registration (:mod:`workbench.services.registration.skull_registration`).

Units mm; head frame: x to the subject's left, x = 0 midsagittal, y up,
z toward the face, Frankfort Horizontal at y = 0.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field

import numpy as np

from workbench.core.frame import apply_transform
from workbench.core.jaw_pose import JawPose, Occlusion
from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh, concatenate
from workbench.core.rigid_search import PoseResult

#: a vertex is "observed" when its final match weight exceeds this
OBSERVED_WEIGHT = 0.3

PART_OF = {"cranium": 0, "upper_teeth": 0, "mandible": 1, "lower_teeth": 1}


def apply_points(m: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Points ``p`` (any shape holding 3-vectors, mm) mapped by the 4 x 4 matrix ``m``, as (n, 3)."""
    return apply_transform(m, np.reshape(p, (-1, 3)))


@dataclass(frozen=True)
class PartReport:
    """What the registration found for one part of the reference skull."""

    name: str
    present: bool
    observed_fraction: float
    note: str = ""


@dataclass(frozen=True)
class SkullRegistration:
    """The reference skull on a target skull (see the module docstring).

    Attributes
    ----------
    input_to_head : (4, 4)
        Rigid map of input coordinates into the target's head frame (mm); a
        reflection included when ``mirrored``.
    mirrored : bool
    reference_scale : float
        Uniform scale applied to the reference head before the non-rigid step.
    meshes : mapping
        Registered reference parts (head frame, mm): ``cranium``,
        ``upper_teeth``, ``mandible``, ``lower_teeth`` — the registration
        resolution (teeth decimated).
    rest : mapping
        The same parts as laid out in the (scaled) reference, before the
        mandible pose and the non-rigid step: the field ``rest → meshes``
        carries the rest of the head (:func:`~workbench.services.registration.skull_registration.carry_head`).
    observed : mapping
        Per part, per vertex weight 0..1 of the final match to real bone.
    landmarks : LandmarkSet
        Skull landmarks in the **input frame**: suggested (observed) or absent.
    inferred : mapping
        Code → head-frame position carried by the registration, for every
        reference landmark (observed or not).
    target_h : Mesh
        The target bone in the head frame (outward).
    target_weight : (n_target_vertices,)
    parts : tuple of PartReport
    pose : PoseResult
    settle : (4, 4)
        Rigid correction from the oriented reference's frame to the target's
        own Frankfort frame (the last step of ``input_to_head``).
    figures : dict
    warnings : tuple of str
    jaw : JawPose or None
        The mandible's pose found on the bone (head frame; ``jaw.present``
        False when none was found); None for registrations made without it.
    jaw_axis : (2, 3)
        The condylar axis (point, unit direction) of the rest layout, head frame.
    occlusion : Occlusion or None
        Set by :func:`~workbench.services.registration.articulation.articulate`: how the jaw was brought into occlusion
        (``meshes``, ``target_h``, ``inferred`` and ``landmarks`` then show the
        jaw closed); None: the jaw as scanned.
    jaw_bone : (n_target_vertices,) bool or None
        Set by :func:`~workbench.services.registration.articulation.articulate`: the target vertices that belong to the jaw.
    """

    input_to_head: np.ndarray
    mirrored: bool
    reference_scale: float
    meshes: Mapping[str, Mesh]
    rest: Mapping[str, Mesh]
    observed: Mapping[str, np.ndarray]
    landmarks: LandmarkSet
    inferred: Mapping[str, np.ndarray]
    target_h: Mesh
    target_weight: np.ndarray
    parts: tuple[PartReport, ...]
    pose: PoseResult
    settle: np.ndarray = field(default_factory=lambda: np.eye(4))
    figures: dict = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    jaw: JawPose | None = None
    jaw_axis: np.ndarray = field(default_factory=lambda: np.array([[0.0, 0, 0], [1.0, 0, 0]]))
    occlusion: Occlusion | None = None
    jaw_bone: np.ndarray | None = None

    def part(self, name: str) -> PartReport:
        return next(p for p in self.parts if p.name == name)

    def displacement_samples(self, spacing_mm: float = 8.0) -> tuple[np.ndarray, np.ndarray]:
        """A spread subset of (rest, registered) vertex pairs of every part (head frame)."""
        rest = concatenate([self.rest[p] for p in PART_OF]).vertices
        moved = concatenate([self.meshes[p] for p in PART_OF]).vertices
        _, first = np.unique(
            np.floor(rest / spacing_mm).astype(np.int64), axis=0, return_index=True
        )
        pick = np.sort(first)
        return rest[pick], moved[pick]
