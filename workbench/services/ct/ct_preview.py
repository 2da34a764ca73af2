"""Live threshold preview of a CT volume before the full-resolution surface extraction.

Load the volume once (:meth:`CtPreview.load`), then ask for coarse preview
surfaces at any iso level (:meth:`CtPreview.surface`) and for a summary of
what that level selects (:meth:`CtPreview.summary`).  The full-resolution
surface is still made by :func:`workbench.services.ct.ct_mesh.mesh_from_ct`.

Units and frames
----------------
* Voxel values and iso levels are in the volume's units (``volume.units``:
  "HU" for CT rescaled to Hounsfield units, otherwise the file's raw
  numbers, e.g. VTK's headsq 0..~4000 CT numbers).
* Geometry is in millimetres in the volume's physical frame
  (``volume.frame``, LPS or RAS), exactly as for ``mesh_from_ct``, so a
  preview surface overlays the full-resolution one.

Downsampling
------------
The preview volume is the block mean of the full volume over blocks of
``strides = (si, sj, sk)`` voxels (one stride per index axis), chosen so that
the preview has at most ``max_voxels`` voxels (default 3·10^6) and its
voxels are as close to isotropic as the strides allow (a thick-slice CT is
thinned in-plane first).  A block mean is what a coarser scanner would
measure; it keeps the physical position of each block: the preview's voxel
(0, 0, 0) sits at the centre of the first block, its spacing is the block
size in mm and its direction is unchanged.  The last block along an axis may
be partial (fewer voxels); its centre is then off by up to (s - 1)/2 full
voxels, and preview vertices are clamped to the full volume's extent.
Volumes already below ``max_voxels`` are used as they are (strides 1, the
preview is the full-resolution surface).

Thin structures (orbit walls, nasal bones) lose contrast in a block mean, so
at coarse strides the preview shows fewer thin bones than the final surface.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace
from os import PathLike
from time import perf_counter
from typing import Any

import numpy as np

from workbench.core.cancel import CancelToken, checking
from workbench.core.errors import InputError
from workbench.core.isosurface import (
    TISSUES,
    IsoChoice,
    choose_iso,
    extract_isosurface,
    face_component_labels,
)
from workbench.core.mesh import Mesh
from workbench.core.volume import Volume
from workbench.io.volumes import read_volume

Progress = Callable[[str, float], None]

DEFAULT_MAX_VOXELS = 3_000_000
PERCENTILES = (1.0, 5.0, 25.0, 50.0, 75.0, 95.0, 99.0, 99.9)


# ---------------------------------------------------------------- downsampling
def preview_strides(
    shape_ijk: tuple[int, int, int] | np.ndarray,
    spacing_mm: np.ndarray,
    max_voxels: int = DEFAULT_MAX_VOXELS,
) -> tuple[int, int, int]:
    """Block strides ``(si, sj, sk)`` giving at most ``max_voxels`` preview voxels.

    The smallest target voxel size ``h`` (mm) is found among the multiples of
    the spacings; each axis then gets ``floor(h / spacing)`` (at least 1), so
    coarse axes (thick slices) are thinned last.
    """
    shape = np.asarray(shape_ijk, np.int64).reshape(3)
    spacing = np.asarray(spacing_mm, np.float64).reshape(3)
    max_voxels = max(1, int(max_voxels))
    if int(np.prod(shape)) <= max_voxels:
        return (1, 1, 1)
    top = int(np.max(shape))
    candidates = np.unique((spacing[:, None] * np.arange(1, top + 1)[None, :]).ravel())
    strides = np.maximum(1, np.floor(candidates[:, None] / spacing[None, :] + 1e-9)).astype(
        np.int64
    )
    strides = np.minimum(strides, shape[None, :])
    counts = np.prod(-(-shape[None, :] // strides), axis=1)  # ceil division
    fits = np.flatnonzero(counts <= max_voxels)
    best = strides[fits[0]] if len(fits) else shape
    return int(best[0]), int(best[1]), int(best[2])


def block_mean(
    volume: Volume, strides: tuple[int, int, int], cancel: CancelToken | None = None
) -> Volume:
    """Block-mean downsampling of ``volume`` by ``strides`` (i, j, k); see the module docstring.

    Returns a float32 :class:`Volume` in the same frame and units whose
    voxel centres are the block centres (mm).  ``volume`` itself is
    returned for strides (1, 1, 1).
    """
    si, sj, sk = (int(s) for s in strides)
    if (si, sj, sk) == (1, 1, 1):
        return volume
    data = volume.data
    nk, nj, ni = data.shape
    out_shape = (-(-nk // sk), -(-nj // sj), -(-ni // si))
    acc = np.zeros(out_shape, np.float32)
    for a in range(sk):
        if cancel is not None:
            cancel.check()
        for b in range(sj):
            for c in range(si):
                part = data[a::sk, b::sj, c::si]
                if part.size:
                    view = acc[: part.shape[0], : part.shape[1], : part.shape[2]]
                    np.add(view, part, out=view, casting="unsafe")
    counts = [
        np.minimum(s, n - s * np.arange(m)).astype(np.float32)
        for s, n, m in ((sk, nk, out_shape[0]), (sj, nj, out_shape[1]), (si, ni, out_shape[2]))
    ]
    acc /= counts[0][:, None, None] * counts[1][None, :, None] * counts[2][None, None, :]
    centre = volume.index_to_physical(np.array([(si - 1) / 2, (sj - 1) / 2, (sk - 1) / 2]))
    metadata = dict(volume.metadata)
    metadata["preview_strides"] = (si, sj, sk)
    return replace(
        volume,
        data=acc,
        spacing_mm=volume.spacing_mm * (si, sj, sk),
        origin_mm=centre,
        metadata=metadata,
    )


# ---------------------------------------------------------------- results
@dataclass(frozen=True)
class ThresholdSummary:
    """What an iso level selects in the full-resolution volume.

    Attributes
    ----------
    iso : float
        The level, in ``units``.
    units : str
        The volume's units ("HU" or the file's, e.g. "unknown").
    voxels_above : int
        Full-resolution voxels with value >= ``iso``.
    fraction_above : float
        ``voxels_above`` / all voxels (0..1).
    volume_above_ml : float
        ``voxels_above`` times the voxel volume, in millilitres (cm³).
    percentile : float
        Percentile rank of ``iso`` among the voxel values (0..100).
    value_range : tuple of float
        ``(min, max)`` voxel value, in ``units``.
    exact : bool
        False for non-integer data, where the counts are exact only to one
        histogram bin (1/1024 of the value range).
    """

    iso: float
    units: str
    voxels_above: int
    fraction_above: float
    volume_above_ml: float
    percentile: float
    value_range: tuple[float, float]
    exact: bool = True

    def text(self) -> str:
        """One line for a status bar or a label."""
        return (
            f"{self.voxels_above:,} voxels ≥ {self.iso:g} {self.units} "
            f"({100 * self.fraction_above:.2f} %, {self.volume_above_ml:.0f} ml)"
        )


@dataclass(frozen=True)
class PreviewSurface:
    """A coarse iso-surface (mm, the volume's frame) for the threshold preview.

    Attributes
    ----------
    iso : float
        Level in the volume's units.
    mesh : Mesh
        The piece the full extraction keeps (largest connected component)
        when ``largest_component`` was asked, else every piece.
    debris : Mesh
        The other pieces (dropped by the full extraction); empty when
        ``largest_component`` is False.
    n_components : int
        Number of connected pieces at this level in the preview.
    strides : tuple of int
        Block strides (i, j, k) of the preview volume.
    seconds : float
        Wall time of the surface extraction.
    summary : ThresholdSummary
        Full-resolution voxel counts at ``iso``.
    note : str
        Empty, or why there is no surface (level outside the data, ...).
    """

    iso: float
    mesh: Mesh
    debris: Mesh
    n_components: int
    strides: tuple[int, int, int]
    seconds: float
    summary: ThresholdSummary
    note: str = ""

    @property
    def empty(self) -> bool:
        return self.mesh.n_faces == 0


def _submesh(vertices: np.ndarray, faces: np.ndarray) -> Mesh:
    used = np.zeros(len(vertices), bool)
    used[faces.ravel()] = True
    index = np.cumsum(used) - 1
    return Mesh(vertices[used], index[faces])


# ---------------------------------------------------------------- the preview
@dataclass(eq=False)
class CtPreview:
    """A loaded CT with its preview volume, histogram and tissue presets.

    Build with :meth:`load` (path) or :meth:`from_volume`.  Thread-safe for
    concurrent :meth:`surface` calls (nothing is mutated after construction).

    Attributes
    ----------
    volume : Volume
        The full-resolution volume (values in ``volume.units``, mm geometry).
    preview_volume : Volume
        Block-mean volume the previews are extracted from (same frame).
    strides : tuple of int
        Block strides (i, j, k); (1, 1, 1) when the volume is small enough.
    presets : dict
        ``{"bone": IsoChoice, "skin": IsoChoice}`` from
        :func:`workbench.core.isosurface.choose_iso`.
    timings_s : dict
        Wall time of the loading steps in s.
    """

    volume: Volume
    preview_volume: Volume
    strides: tuple[int, int, int]
    presets: dict[str, IsoChoice]
    _values: np.ndarray = field(repr=False)
    _above: np.ndarray = field(repr=False)  # voxels with value >= _values[n]
    timings_s: dict[str, float] = field(default_factory=dict)
    source: str = ""

    @classmethod
    def load(
        cls,
        path: str | PathLike[str],
        *,
        max_voxels: int = DEFAULT_MAX_VOXELS,
        progress: Progress | None = None,
        cancel: CancelToken | None = None,
    ) -> CtPreview:
        """Read a DICOM folder / NRRD / MetaImage / NIfTI file and prepare the preview."""
        report = checking(cancel, progress)
        report("reading volume", 0.0)
        start = perf_counter()
        volume = read_volume(path)
        read_s = perf_counter() - start
        preview = cls.from_volume(
            volume,
            max_voxels=max_voxels,
            cancel=cancel,
            progress=lambda s, f: report(s, 0.5 + 0.5 * f),
        )
        preview.timings_s["read"] = round(read_s, 4)
        preview.source = str(path)
        return preview

    @classmethod
    def from_volume(
        cls,
        volume: Volume,
        *,
        max_voxels: int = DEFAULT_MAX_VOXELS,
        progress: Progress | None = None,
        cancel: CancelToken | None = None,
    ) -> CtPreview:
        """Prepare the preview of an already loaded volume."""
        report = checking(cancel, progress)
        timings: dict[str, float] = {}
        t0 = perf_counter()
        report("downsampling", 0.0)
        strides = preview_strides(volume.shape_ijk, volume.spacing_mm, max_voxels)
        preview_volume = block_mean(volume, strides, cancel)
        timings["downsample"] = round(perf_counter() - t0, 4)
        report("histogram", 0.4)
        t0 = perf_counter()
        counts, values = volume.histogram()
        above = np.concatenate([np.cumsum(counts[::-1])[::-1], [0]]).astype(np.int64)
        timings["histogram"] = round(perf_counter() - t0, 4)
        report("tissue presets", 0.7)
        t0 = perf_counter()
        presets = {tissue: choose_iso(volume, tissue) for tissue in TISSUES}
        timings["presets"] = round(perf_counter() - t0, 4)
        report("ready", 1.0)
        return cls(volume, preview_volume, strides, presets, values, above, timings, volume.source)

    # ------------------------------------------------------------ figures
    @property
    def units(self) -> str:
        return self.volume.units

    @property
    def value_range(self) -> tuple[float, float]:
        """``(min, max)`` voxel value of the full volume (``units``)."""
        return float(self._values[0]), float(self._values[-1])

    @property
    def n_voxels(self) -> int:
        return int(self._above[0])

    @property
    def integer_values(self) -> bool:
        return self.volume.data.dtype.kind in "iu"

    def voxels_above(self, iso: float) -> int:
        """Full-resolution voxels with value >= ``iso`` (from the histogram, no data pass)."""
        return int(self._above[np.searchsorted(self._values, float(iso), side="left")])

    def percentiles(self, q: tuple[float, ...] = PERCENTILES) -> dict[float, float]:
        """Voxel value (``units``) at each percentile in ``q`` (0..100)."""
        cumulative = (self.n_voxels - self._above[1:]) / max(self.n_voxels, 1)  # <= _values[n]
        index = np.searchsorted(cumulative, np.asarray(q, np.float64) / 100.0, side="left")
        index = np.minimum(index, len(self._values) - 1)
        return {float(p): float(self._values[i]) for p, i in zip(q, index, strict=True)}

    def summary(self, iso: float) -> ThresholdSummary:
        """What ``iso`` selects in the full-resolution volume (counts from the histogram)."""
        n = self.voxels_above(iso)
        total = max(self.n_voxels, 1)
        voxel_ml = float(np.prod(self.volume.spacing_mm)) / 1000.0
        return ThresholdSummary(
            iso=float(iso),
            units=self.units,
            voxels_above=n,
            fraction_above=n / total,
            volume_above_ml=n * voxel_ml,
            percentile=100.0 * (1.0 - n / total),
            value_range=self.value_range,
            exact=self.integer_values,
        )

    def histogram(self, n_bins: int = 128) -> tuple[np.ndarray, np.ndarray]:
        """``(counts, edges)`` of the voxel values over ``n_bins`` equal bins (for display)."""
        lo, hi = self.value_range
        edges = np.linspace(lo, hi if hi > lo else lo + 1.0, int(n_bins) + 1)
        per_value = self._above[:-1] - self._above[1:]
        bins = np.clip(np.searchsorted(edges, self._values, side="right") - 1, 0, n_bins - 1)
        return np.bincount(bins, weights=per_value, minlength=n_bins).astype(np.int64), edges

    def nearest_tissue(self, iso: float) -> str:
        """The tissue whose preset level is closest to ``iso``."""
        return min(TISSUES, key=lambda t: abs(self.presets[t].iso - float(iso)))

    def describe(self) -> dict[str, Any]:
        """Sizes for display: voxels (i, j, k), spacing and extent in mm, preview strides."""
        return {
            "shape_ijk": self.volume.shape_ijk,
            "spacing_mm": tuple(float(s) for s in self.volume.spacing_mm),
            "extent_mm": tuple(float(e) for e in self.volume.extent_mm),
            "frame": self.volume.frame,
            "units": self.units,
            "value_range": self.value_range,
            "preview_shape_ijk": self.preview_volume.shape_ijk,
            "preview_spacing_mm": tuple(float(s) for s in self.preview_volume.spacing_mm),
            "strides": self.strides,
        }

    # ------------------------------------------------------------ surfaces
    def surface(
        self, iso: float, *, largest_component: bool = True, cancel: CancelToken | None = None
    ) -> PreviewSurface:
        """Coarse iso-surface at ``iso`` (volume units), in mm in the volume's frame.

        Never raises for a level without a surface: the result is then empty
        and ``note`` says why.  Raises :class:`~workbench.core.errors.Cancelled`
        when ``cancel`` is set during the extraction.
        """
        iso = float(iso)
        start = perf_counter()
        summary = self.summary(iso)
        empty = Mesh(np.zeros((0, 3)))
        try:
            result = extract_isosurface(
                self.preview_volume, iso, largest_component=False, progress=checking(cancel)
            )
        except InputError as exc:
            return PreviewSurface(
                iso,
                empty,
                empty,
                0,
                self.strides,
                perf_counter() - start,
                summary,
                note=exc.problem,
            )
        vertices, faces = self._clamped(result.mesh.vertices), result.mesh.faces
        labels = face_component_labels(faces, len(vertices))
        n_components = int(labels.max()) + 1 if len(labels) else 0
        if largest_component and n_components > 1:
            keep = labels == int(np.argmax(np.bincount(labels)))
            mesh, debris = _submesh(vertices, faces[keep]), _submesh(vertices, faces[~keep])
        else:
            mesh, debris = result.mesh, empty
        return PreviewSurface(
            iso, mesh, debris, n_components, self.strides, perf_counter() - start, summary
        )

    def _clamped(self, vertices: np.ndarray) -> np.ndarray:
        """Pull vertices of partial edge blocks back inside the full volume's extent (mm)."""
        if self.strides == (1, 1, 1):
            return vertices
        ijk = self.volume.physical_to_index(vertices)
        top = np.asarray(self.volume.shape_ijk, np.float64) - 1.0
        return self.volume.index_to_physical(np.clip(ijk, 0.0, top))
