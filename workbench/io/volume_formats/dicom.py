"""DICOM series reader (a folder of single-frame CT/MR slices) via pydicom.

Steps
-----
1. Read every file's header under the folder (recursively); files that are
   not DICOM, or DICOM objects without image geometry, are skipped.
2. Group by ``SeriesInstanceUID``; take the series with the most slices (or
   the series of the file given) and report the others.
3. Check that all slices agree on rows/columns, ``PixelSpacing`` and
   ``ImageOrientationPatient`` (IOP).
4. Sort by the projection of ``ImagePositionPatient`` (IPP) on the slice
   normal ``n = row_cosine x column_cosine``; derive the slice spacing from
   the positions, refuse missing slices (gap > 1.5 x median) and duplicate
   positions, warn about small irregularities.
5. Apply ``RescaleSlope``/``RescaleIntercept`` per slice (CT: Hounsfield
   units), int16 when every value fits, else float32.

Geometry (frame LPS, mm): ``direction[:, 0]`` = IOP row cosine (increasing
column i), ``direction[:, 1]`` = IOP column cosine (increasing row j),
``direction[:, 2]`` = unit vector from the first to the last slice position.
``PixelSpacing`` is (row spacing, column spacing) = (j, i) spacing.
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from workbench.core.errors import InputError
from workbench.core.volume import Volume

if TYPE_CHECKING:
    from pydicom.dataset import Dataset

_GEOMETRY_TAGS = (
    "ImagePositionPatient",
    "ImageOrientationPatient",
    "PixelSpacing",
    "Rows",
    "Columns",
)


def _scan(folder: Path) -> tuple[list[tuple[Path, Dataset]], list[str], int]:
    """Headers of all DICOM image files below ``folder``; also skipped-file notes."""
    import pydicom
    from pydicom.errors import InvalidDicomError

    files = sorted(p for p in folder.rglob("*") if p.is_file() and p.name.upper() != "DICOMDIR")
    headers: list[tuple[Path, Dataset]] = []
    skipped: list[str] = []
    for f in files:
        try:
            ds = pydicom.dcmread(f, stop_before_pixels=True, force=f.suffix.lower() == ".dcm")
        except (InvalidDicomError, EOFError, OSError, ValueError, KeyError, TypeError):
            continue  # not a DICOM file
        missing = [t for t in _GEOMETRY_TAGS if t not in ds]
        if missing or "SeriesInstanceUID" not in ds:
            skipped.append(f"{f.name}: no {', '.join(missing) or 'SeriesInstanceUID'}")
            continue
        headers.append((f, ds))
    return headers, skipped, len(files)


def _float_list(ds, tag: str, n: int, path: Path) -> np.ndarray:
    try:
        values = np.array([float(v) for v in ds[tag].value], dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(path, f"{tag} is not numeric") from None
    if values.shape != (n,):
        raise InputError(path, f"{tag} should have {n} values, got {len(values)}")
    return values


def _pick_series(
    folder: Path, headers: list[tuple[Path, Dataset]], wanted: str | None
) -> tuple[str, list[tuple[Path, Dataset]], list[dict[str, Any]]]:
    groups: dict[str, list[tuple[Path, Dataset]]] = defaultdict(list)
    for f, ds in headers:
        groups[str(ds.SeriesInstanceUID)].append((f, ds))
    uid = wanted or max(groups, key=lambda u: len(groups[u]))
    if uid not in groups:
        raise InputError(folder, "the given file is not part of an image series with geometry")
    others = [
        {
            "series_uid": u,
            "n_files": len(g),
            "description": str(g[0][1].get("SeriesDescription", "")),
            "modality": str(g[0][1].get("Modality", "")),
        }
        for u, g in groups.items()
        if u != uid
    ]
    return uid, groups[uid], others


def _check_consistent(series) -> tuple[np.ndarray, np.ndarray, int, int]:
    f0, ds0 = series[0]
    rows, cols = int(ds0.Rows), int(ds0.Columns)
    iop0 = _float_list(ds0, "ImageOrientationPatient", 6, f0)
    ps0 = _float_list(ds0, "PixelSpacing", 2, f0)
    for f, ds in series[1:]:
        if (int(ds.Rows), int(ds.Columns)) != (rows, cols):
            raise InputError(
                f, f"inconsistent image size {ds.Rows}x{ds.Columns}; {f0.name} is {rows}x{cols}"
            )
        if np.abs(_float_list(ds, "ImageOrientationPatient", 6, f) - iop0).max() > 1e-4:
            raise InputError(
                f, f"slice orientation differs from {f0.name} (mixed orientations in one series)"
            )
        if np.abs(_float_list(ds, "PixelSpacing", 2, f) - ps0).max() > 1e-4:
            raise InputError(f, f"pixel spacing differs from {f0.name}")
        if int(ds.get("NumberOfFrames", 1) or 1) > 1:
            raise InputError(f, "multi-frame (enhanced) DICOM objects are not supported")
    if int(ds0.get("NumberOfFrames", 1) or 1) > 1:
        raise InputError(f0, "multi-frame (enhanced) DICOM objects are not supported")
    return iop0, ps0, rows, cols


def _slice_axis(folder, series, iop, warnings):
    """Sort slices; return (sorted series, origin, k direction, k spacing)."""
    row, col = iop[:3], iop[3:]
    normal = np.cross(row, col)
    if np.linalg.norm(normal) < 0.5:
        raise InputError(series[0][0], f"ImageOrientationPatient {iop.tolist()} is degenerate")
    normal /= np.linalg.norm(normal)
    positions = np.array([_float_list(ds, "ImagePositionPatient", 3, f) for f, ds in series])
    proj = positions @ normal
    order = np.argsort(proj, kind="stable")
    series = [series[n] for n in order]
    positions, proj = positions[order], proj[order]
    if len(series) < 2:
        raise InputError(folder, "the series has a single slice; a volume needs at least 2")
    gaps = np.diff(proj)
    median = float(np.median(gaps))
    if gaps.min() < 1e-3 * max(median, 1e-3):
        n = int(np.argmin(gaps))
        raise InputError(
            series[n + 1][0],
            f"same slice position as {series[n][0].name} ({proj[n]:.3f} mm along the normal)",
            hint="the folder mixes acquisitions, echoes or phases; put one series per folder",
        )
    if gaps.max() > 1.5 * median:
        n = int(np.argmax(gaps))
        missing = int(round(gaps[n] / median)) - 1
        raise InputError(
            folder,
            f"missing slice(s): gap of {gaps[n]:.3f} mm between {series[n][0].name} and "
            f"{series[n + 1][0].name} where the series spacing is {median:.3f} mm "
            f"(about {max(missing, 1)} slice(s) missing)",
        )
    if gaps.max() - gaps.min() > max(0.01 * median, 1e-3):
        warnings.append(
            f"irregular slice spacing {gaps.min():.4f}..{gaps.max():.4f} mm; "
            f"using the mean {(proj[-1] - proj[0]) / (len(proj) - 1):.4f} mm"
        )
    step = (positions[-1] - positions[0]) / (len(series) - 1)
    spacing_k = float(np.linalg.norm(step))
    k_dir = step / spacing_k
    tilt = np.degrees(np.arccos(np.clip(k_dir @ normal, -1.0, 1.0)))
    if tilt > 0.5:
        warnings.append(
            f"slice stack is sheared by {tilt:.2f} deg (gantry tilt); "
            "geometry follows the positions"
        )
    return series, positions[0], k_dir, spacing_k


def _pixels(series) -> tuple[list[np.ndarray], list[float], list[float]]:
    import pydicom

    arrays, slopes, intercepts = [], [], []
    for f, _ in series:
        try:
            ds = pydicom.dcmread(f)
            arr = ds.pixel_array
        except Exception as exc:  # noqa: BLE001 - pydicom raises many types for undecodable data
            raise InputError(
                f,
                f"cannot decode the pixel data: {exc}",
                hint="compressed transfer syntaxes need pylibjpeg or gdcm installed",
            ) from None
        if arr.shape != (int(ds.Rows), int(ds.Columns)):
            raise InputError(f, f"pixel data shape {arr.shape} does not match Rows x Columns")
        arrays.append(arr)
        slopes.append(float(ds.get("RescaleSlope", 1.0) or 1.0))
        intercepts.append(float(ds.get("RescaleIntercept", 0.0) or 0.0))
    return arrays, slopes, intercepts


def _rescale(arrays, slopes, intercepts) -> np.ndarray:
    triples = list(zip(arrays, slopes, intercepts, strict=True))
    integral = all(float(s).is_integer() and float(b).is_integer() for _, s, b in triples)
    dtype: type[np.generic] = np.float32
    if integral:
        lo = min(min(a.min() * s, a.max() * s) + b for a, s, b in triples)
        hi = max(max(a.min() * s, a.max() * s) + b for a, s, b in triples)
        info = np.iinfo(np.int16)
        if info.min <= lo and hi <= info.max:
            dtype = np.int16
    out = np.empty((len(arrays),) + arrays[0].shape, dtype=dtype)
    for n, (a, s, b) in enumerate(triples):
        if dtype == np.int16:
            out[n] = a.astype(np.int32) * int(s) + int(b)
        else:
            out[n] = a.astype(np.float64) * s + b
    return out


def read_dicom_series(path: Path) -> Volume:
    """Read a DICOM series from a folder (or the series of one file in it)."""
    path = Path(path)
    if not path.exists():
        raise InputError(path, "folder not found")
    folder = path if path.is_dir() else path.parent
    headers, skipped, n_files = _scan(folder)
    wanted = None
    if path.is_file():
        match = [ds for f, ds in headers if f == path]
        if not match:
            raise InputError(path, "not a DICOM image slice with position and orientation")
        wanted = str(match[0].SeriesInstanceUID)
    if not headers:
        raise InputError(
            folder,
            f"no DICOM image slices found ({n_files} files looked at"
            + (f"; e.g. {skipped[0]}" if skipped else "")
            + ")",
        )
    warnings: list[str] = []
    uid, series, others = _pick_series(folder, headers, wanted)
    if others:
        warnings.append(
            f"{len(others)} other series in the folder were ignored: "
            + "; ".join(f"{o['n_files']} files {o['description']!r}" for o in others)
        )
    iop, pixel_spacing, _, _ = _check_consistent(series)
    series, origin, k_dir, spacing_k = _slice_axis(folder, series, iop, warnings)
    arrays, slopes, intercepts = _pixels(series)
    data = _rescale(arrays, slopes, intercepts)
    del arrays
    ds0 = series[0][1]
    modality = str(ds0.get("Modality", "unknown")) or "unknown"
    rescale_type = str(ds0.get("RescaleType", "HU") or "HU").upper()
    has_rescale = "RescaleIntercept" in ds0
    units = "HU" if modality == "CT" and has_rescale and rescale_type in ("HU", "") else "unknown"
    if str(ds0.get("PhotometricInterpretation", "")) == "MONOCHROME1":
        warnings.append("MONOCHROME1 images: values are kept as stored (high = dark)")
    row_cos, col_cos = iop[:3] / np.linalg.norm(iop[:3]), iop[3:] / np.linalg.norm(iop[3:])
    direction = np.column_stack([row_cos, col_cos, k_dir])
    spacing = np.array([pixel_spacing[1], pixel_spacing[0], spacing_k])
    metadata = {
        "format": "DICOM",
        "series_uid": uid,
        "series_description": str(ds0.get("SeriesDescription", "")),
        "patient_position": str(ds0.get("PatientPosition", "")),
        "n_slices": len(series),
        "files": [str(f) for f, _ in series],
        "rescale_slope": sorted(set(slopes)),
        "rescale_intercept": sorted(set(intercepts)),
        "slice_thickness": float(ds0.get("SliceThickness", 0) or 0) or None,
        "other_series": others,
        "skipped_files": skipped,
        "warnings": warnings,
    }
    return Volume(data, spacing, origin, direction, "LPS", modality, units, str(path), metadata)
