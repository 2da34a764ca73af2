"""Scalar volume value type (CT, MR, ...) with its index-to-physical mapping.

Index order and frames
----------------------
``Volume.data`` is indexed ``data[k, j, i]`` = (slice, row, column), which
is the natural order of a stack of 2-D images.  All geometric quantities are
given for the *index axes in (i, j, k) order*:

* ``spacing_mm[0]`` is the distance between columns (i), ``[1]`` between
  rows (j) and ``[2]`` between slices (k), all in millimetres;
* ``direction[:, 0]`` is the unit physical direction of increasing i, and so
  on for j and k (columns of the matrix);
* ``origin_mm`` is the physical position of the centre of voxel (0, 0, 0).

A voxel index ``(i, j, k)`` therefore maps to the physical point::

    p = origin_mm + direction @ (spacing_mm * (i, j, k))

``frame`` names the physical frame of ``origin_mm``/``direction``: ``"LPS"``
(x to the patient's left, y posterior, z superior; DICOM, NRRD, MetaImage)
or ``"RAS"`` (x right, y anterior, z superior; NIfTI).  The two differ by
negating x and y; :meth:`Volume.in_frame` converts.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

FRAMES = ("LPS", "RAS")
_LPS_RAS = np.diag([-1.0, -1.0, 1.0])


def _frozen(array: np.ndarray) -> np.ndarray:
    array.setflags(write=False)
    return array


@dataclass(frozen=True, eq=False)
class Volume:
    """A 3-D scalar image with its voxel-to-millimetre geometry.

    Parameters
    ----------
    data : (nk, nj, ni) array
        Voxel values indexed (slice, row, column); the native dtype is kept
        (e.g. int16 for CT in Hounsfield units).
    spacing_mm : (3,) float
        Voxel size along the i, j, k index axes in mm (all > 0).
    origin_mm : (3,) float
        Physical position of voxel (0, 0, 0) in mm, in ``frame``.
    direction : (3, 3) float
        Columns are the unit physical directions of the i, j, k axes.
    frame : {"LPS", "RAS"}
        Physical frame of ``origin_mm`` and ``direction``.
    modality : str
        "CT", "MR", ... or "unknown".
    units : str
        "HU" for rescaled CT, otherwise "unknown" (or what the file states).
    source : str
        Where the volume came from (path or description).
    metadata : dict
        Format-specific details and reader warnings (``metadata["warnings"]``).
    """

    data: np.ndarray
    spacing_mm: np.ndarray
    origin_mm: np.ndarray = field(default_factory=lambda: np.zeros(3))
    direction: np.ndarray = field(default_factory=lambda: np.eye(3))
    frame: str = "LPS"
    modality: str = "unknown"
    units: str = "unknown"
    source: str = ""
    metadata: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        data = np.asarray(self.data).view()  # read-only view; no copy of big volumes
        if data.ndim != 3:
            raise ValueError(f"volume data must be 3-D (k, j, i), got shape {data.shape}")
        spacing = np.array(self.spacing_mm, dtype=np.float64).reshape(3)
        if not np.all(np.isfinite(spacing)) or np.any(spacing <= 0):
            raise ValueError(f"voxel spacing must be positive and finite, got {spacing}")
        origin = np.array(self.origin_mm, dtype=np.float64).reshape(3)
        direction = np.array(self.direction, dtype=np.float64).reshape(3, 3)
        if abs(np.linalg.det(direction)) < 1e-6:
            raise ValueError(f"direction matrix is singular: {direction.tolist()}")
        if self.frame not in FRAMES:
            raise ValueError(f"frame must be one of {FRAMES}, got {self.frame!r}")
        data.setflags(write=False)
        object.__setattr__(self, "data", data)
        object.__setattr__(self, "spacing_mm", _frozen(spacing))
        object.__setattr__(self, "origin_mm", _frozen(origin))
        object.__setattr__(self, "direction", _frozen(direction))

    # ------------------------------------------------------------ basics
    @property
    def shape_ijk(self) -> tuple[int, int, int]:
        """Number of voxels along (i, j, k)."""
        nk, nj, ni = self.data.shape
        return int(ni), int(nj), int(nk)

    @property
    def affine(self) -> np.ndarray:
        """``(4, 4)`` homogeneous map from (i, j, k, 1) to physical mm in ``frame``."""
        out = np.eye(4)
        out[:3, :3] = self.direction * self.spacing_mm[None, :]
        out[:3, 3] = self.origin_mm
        return out

    @property
    def extent_mm(self) -> np.ndarray:
        """``(3,)`` physical size along i, j, k between first and last voxel centres."""
        return (np.asarray(self.shape_ijk) - 1) * self.spacing_mm

    def __repr__(self) -> str:
        return (
            f"Volume(shape_ijk={self.shape_ijk}, dtype={self.data.dtype}, "
            f"spacing_mm={tuple(round(float(s), 4) for s in self.spacing_mm)}, "
            f"frame={self.frame!r}, "
            f"modality={self.modality!r}, units={self.units!r})"
        )

    # ------------------------------------------------------------ geometry
    def index_to_physical(self, ijk: np.ndarray) -> np.ndarray:
        """Map voxel indices ``(n, 3)`` in (i, j, k) order to physical mm in ``frame``.

        Fractional indices are allowed (voxel centres sit at integers).
        """
        ijk = np.asarray(ijk, dtype=np.float64)
        flat = ijk.reshape(-1, 3)
        out = flat @ (self.direction * self.spacing_mm[None, :]).T + self.origin_mm
        return out.reshape(ijk.shape)

    def physical_to_index(self, points: np.ndarray) -> np.ndarray:
        """Inverse of :meth:`index_to_physical`: mm in ``frame`` to fractional (i, j, k)."""
        points = np.asarray(points, dtype=np.float64)
        flat = points.reshape(-1, 3) - self.origin_mm
        inv = np.linalg.inv(self.direction * self.spacing_mm[None, :])
        return (flat @ inv.T).reshape(points.shape)

    def in_frame(self, frame: str) -> Volume:
        """The same voxels with origin/direction expressed in ``frame`` ("LPS" or "RAS")."""
        if frame not in FRAMES:
            raise ValueError(f"frame must be one of {FRAMES}, got {frame!r}")
        if frame == self.frame:
            return self
        return replace(
            self,
            origin_mm=_LPS_RAS @ self.origin_mm,
            direction=_LPS_RAS @ self.direction,
            frame=frame,
        )

    def value_range(self) -> tuple[float, float]:
        """``(min, max)`` of the voxel values (native units)."""
        return float(self.data.min()), float(self.data.max())

    def histogram(self, n_bins: int = 1024) -> tuple[np.ndarray, np.ndarray]:
        """Voxel-value histogram ``(counts, bin centres)`` of the non-empty bins.

        Integer data spanning fewer than 65536 values get one bin per value;
        otherwise ``n_bins`` equal bins.  Built slab by slab (no full-size copy).
        """
        data = self.data
        lo, hi = self.value_range()
        integer = data.dtype.kind in "iu" and hi - lo < 65536
        n = int(hi - lo) + 1 if integer else int(n_bins)
        counts = np.zeros(n, np.int64)
        step = max(1, (32 * 2**20) // max(1, data[0].size * 8))
        for k0 in range(0, data.shape[0], step):
            chunk = data[k0 : k0 + step].ravel()
            if integer:
                counts += np.bincount(chunk.astype(np.int64) - int(lo), minlength=n)
            else:
                counts += np.histogram(chunk, bins=n, range=(lo, hi))[0]
        if integer:
            centres = np.arange(n, dtype=np.float64) + lo
        else:
            edges = np.linspace(lo, hi, n + 1)
            centres = 0.5 * (edges[1:] + edges[:-1])
        keep = counts > 0
        return counts[keep], centres[keep]
