"""The reference head template: skin, skull parts, landmarks and muscles as one value.

Units and frame: millimetres in the head frame (x to the subject's left,
x = 0 midsagittal; y up; z toward the face; Frankfort Horizontal at y = 0).

A template is built by :mod:`workbench.services.templates.template` from the
project's own data and code (never downloaded) and identified by
``template_id`` plus a content hash over every array, which cases record so a
reconstruction can name exactly which head it started from.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Any

import numpy as np

from workbench.core.landmarks import LandmarkSet
from workbench.core.mesh import Mesh
from workbench.model.muscles import MuscleGrid

#: mesh parts of a template, in export order
PARTS = ("skin", "cranium", "mandible", "upper_teeth", "lower_teeth", "eyes", "tongue")


@dataclass(frozen=True, eq=False)
class TemplateHead:
    """An anatomical reference head (Kähler 2003, §5.1).

    Attributes
    ----------
    template_id : str
        E.g. ``"workbench-reference-head/1/male"``.
    sex : str
    meshes : mapping
        ``{part: Mesh}`` for :data:`PARTS`.
    skin_landmarks, skull_landmarks : LandmarkSet
    skull_landmark_part : mapping
        Skull code → "cranium" | "mandible" | "teeth".
    muscles : tuple of MuscleGrid
        Grids painted on the skin (empty until muscles are laid out).
    regions : mapping
        Skin vertex ids per named region (face, scalp, lips, eyelids ...).
    openings : mapping
        Ordered skin boundary loops (eyes, mouth, neck).
    eye_centres : (2, 3)
        Left and right globe centres; ``eye_radius`` in mm.
    tmj_axis : (2, 3)
        A point on the temporomandibular rotation axis and its unit direction.
    provenance : mapping
        How it was built (depth table, fit residuals, build parameters).
    """

    template_id: str
    sex: str
    meshes: Mapping[str, Mesh]
    skin_landmarks: LandmarkSet
    skull_landmarks: LandmarkSet
    skull_landmark_part: Mapping[str, str]
    muscles: tuple[MuscleGrid, ...] = ()
    regions: Mapping[str, np.ndarray] = field(default_factory=dict)
    openings: Mapping[str, np.ndarray] = field(default_factory=dict)
    eye_centres: np.ndarray = field(default_factory=lambda: np.zeros((2, 3)))
    eye_radius: float = 12.0
    tmj_axis: np.ndarray = field(default_factory=lambda: np.array([[0.0, 0, 0], [1.0, 0, 0]]))
    provenance: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        missing = [p for p in PARTS if p not in self.meshes]
        if missing:
            raise ValueError(f"template is missing parts: {', '.join(missing)}")

    @property
    def skin(self) -> Mesh:
        return self.meshes["skin"]

    def _eye_owner(self) -> np.ndarray:
        eyes = self.meshes["eyes"].vertices
        return np.linalg.norm(eyes[:, None] - self.eye_centres[None], axis=2).argmin(axis=1)

    def warped(self, warp: Callable[[np.ndarray], np.ndarray]) -> TemplateHead:
        """Every part moved by ``warp`` (``(k, 3) → (k, 3)`` mm); the eyeballs rigidly with
        their centres (Kähler 2003, §8.3.2), the jaw axis through its warped points."""
        meshes = {name: m.with_vertices(warp(m.vertices)) for name, m in self.meshes.items()}
        centres = warp(self.eye_centres)
        eyes = self.meshes["eyes"].vertices
        shift = (centres - self.eye_centres)[self._eye_owner()]
        meshes["eyes"] = self.meshes["eyes"].with_vertices(eyes + shift)
        axis_pts = warp(np.vstack([self.tmj_axis[0], self.tmj_axis[0] + 10 * self.tmj_axis[1]]))
        direction = axis_pts[1] - axis_pts[0]
        return replace(
            self,
            meshes=meshes,
            skin_landmarks=self.skin_landmarks.warped(warp),
            skull_landmarks=self.skull_landmarks.warped(warp),
            eye_centres=centres,
            tmj_axis=np.vstack([axis_pts[0], direction / np.linalg.norm(direction)]),
        )

    def with_eyes_moved(self, moves: Mapping[int, np.ndarray]) -> TemplateHead:
        """The eyeballs translated by ``moves`` (eye index → (3,) mm); the skin unchanged."""
        if not moves:
            return self
        shift = np.zeros_like(self.eye_centres)
        for i, m in moves.items():
            shift[i] = m
        eyes = self.meshes["eyes"].vertices
        meshes = {
            **self.meshes,
            "eyes": self.meshes["eyes"].with_vertices(eyes + shift[self._eye_owner()]),
        }
        return replace(self, meshes=meshes, eye_centres=self.eye_centres + shift)

    @cached_property
    def content_hash(self) -> str:
        """SHA-256 over every mesh, landmark, muscle and region array (hex)."""
        h = hashlib.sha256()
        h.update(self.template_id.encode())
        for part in PARTS:
            mesh = self.meshes[part]
            h.update(part.encode())
            h.update(np.ascontiguousarray(mesh.vertices).tobytes())
            h.update(np.ascontiguousarray(mesh.faces).tobytes())
        for lmset in (self.skin_landmarks, self.skull_landmarks):
            for lm in lmset:
                h.update(lm.code.encode())
                h.update(np.ascontiguousarray(lm.position).tobytes())
        h.update(json.dumps([m.to_state() for m in self.muscles], sort_keys=True).encode())
        for name in sorted(self.regions):
            h.update(name.encode())
            h.update(np.ascontiguousarray(self.regions[name], dtype=np.int64).tobytes())
        return h.hexdigest()
