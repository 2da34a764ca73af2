"""The case's landmarks part: one :class:`LandmarkSet` per surface.

The value types live in :mod:`workbench.core.landmarks`; this module gives the
part its state codec.  Positions are in mm in the specimen's input frame (the
frame of the mesh they were placed on); undefined points have no position.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any

import numpy as np

from workbench.core.landmarks import SURFACES, Landmark, LandmarkSet

Landmarks = Mapping[str, LandmarkSet]


def empty_landmarks() -> Landmarks:
    """``{surface: empty LandmarkSet}`` for every surface."""
    return MappingProxyType({s: LandmarkSet(s) for s in SURFACES})


def coerce_landmarks(value: Mapping[str, LandmarkSet]) -> Landmarks:
    """Validate a landmarks mapping; missing surfaces get empty sets."""
    out: dict[str, LandmarkSet] = {}
    for surface in SURFACES:
        item = value.get(surface, LandmarkSet(surface))
        if not isinstance(item, LandmarkSet):
            raise TypeError(f"landmarks[{surface!r}] must be a LandmarkSet")
        if item.surface != surface:
            raise ValueError(f"landmarks[{surface!r}] holds a {item.surface} set")
        out[surface] = item
    unknown = sorted(set(value) - set(SURFACES))
    if unknown:
        raise ValueError(f"unknown landmark surfaces: {', '.join(unknown)}")
    return MappingProxyType(out)


def landmark_to_state(landmark: Landmark) -> dict[str, Any]:
    """``{code, position (mm, or None if undefined), status, confidence, description}``."""
    position = [float(x) for x in landmark.position] if landmark.is_defined else None
    return {
        "code": landmark.code,
        "position": position,
        "status": landmark.status,
        "confidence": float(landmark.confidence),
        "description": landmark.description,
    }


def landmark_from_state(state: Mapping[str, Any]) -> Landmark:
    """Inverse of :func:`landmark_to_state`."""
    position = state["position"]
    if position is None:
        position = [math.nan] * 3
    return Landmark(
        code=state["code"],
        position=np.asarray(position, dtype=np.float64),
        status=state["status"],
        confidence=state["confidence"],
        description=state["description"],
    )


def landmark_set_to_state(landmarks: LandmarkSet) -> dict[str, Any]:
    """``{surface, landmarks: [landmark state, ...]}`` in set order."""
    return {
        "surface": landmarks.surface,
        "landmarks": [landmark_to_state(lm) for lm in landmarks],
    }


def landmark_set_from_state(state: Mapping[str, Any]) -> LandmarkSet:
    """Inverse of :func:`landmark_set_to_state`."""
    return LandmarkSet(
        state["surface"], tuple(landmark_from_state(item) for item in state["landmarks"])
    )


def landmarks_to_state(landmarks: Landmarks) -> dict[str, Any]:
    """State of the landmarks part: ``{surface: set state}`` for every surface."""
    return {surface: landmark_set_to_state(landmarks[surface]) for surface in SURFACES}


def landmarks_from_state(state: Mapping[str, Any]) -> Landmarks:
    """Inverse of :func:`landmarks_to_state` (validated)."""
    return coerce_landmarks(
        {surface: landmark_set_from_state(item) for surface, item in state.items()}
    )


def landmarks_equal(a: Landmarks, b: Landmarks) -> bool:
    """Same surfaces with equal sets (NaN positions compare equal)."""
    return a.keys() == b.keys() and all(a[s].equals(b[s]) for s in a)
