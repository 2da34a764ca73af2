"""NIfTI-1/2 reader (``.nii``, ``.nii.gz``) through nibabel.

The voxel-to-world affine (sform when set, else qform, as chosen by
nibabel) maps (i, j, k) to RAS+ millimetres; it is split into origin,
spacing (column norms) and direction (normalised columns).  ``scl_slope`` /
``scl_inter`` are applied by nibabel; the native dtype is kept when they are
identity.  A 4-D image is accepted only when its 4th axis has length 1.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from workbench.core.errors import InputError
from workbench.core.volume import Volume

_SPACE_UNITS_TO_MM = {"mm": 1.0, "meter": 1000.0, "micron": 1e-3, "unknown": 1.0}


def _header_text(header, key: str) -> str:
    try:
        value = np.asarray(header[key]).item()
    except Exception:  # noqa: BLE001 - a header field nibabel cannot give: shown as empty
        return ""
    return value.decode("latin-1").strip("\x00 ") if isinstance(value, bytes) else str(value)


def _scaled(raw: np.ndarray, slope: float, inter: float) -> np.ndarray:
    """``raw * slope + inter`` as a C-contiguous native array: raw dtype when identity,
    int16 when exact and in range, float32 otherwise (never a float64 volume)."""
    if slope == 1.0 and inter == 0.0:
        return np.ascontiguousarray(raw, dtype=raw.dtype.newbyteorder("="))
    exact = raw.dtype.kind in "iu" and slope.is_integer() and inter.is_integer()
    ends = (float(raw.min()) * slope + inter, float(raw.max()) * slope + inter)
    info = np.iinfo(np.int16)
    dtype = np.int16 if exact and info.min <= min(ends) and max(ends) <= info.max else np.float32
    out = np.empty(raw.shape, dtype)
    for k in range(raw.shape[0]):  # slice by slice: no full-size temporary
        if dtype == np.int16:
            out[k] = raw[k].astype(np.int32) * int(slope) + int(inter)
        else:
            out[k] = raw[k].astype(np.float64) * slope + inter
    return out


#: what to do about a header that gives no voxel size (shown with the refusal)
NO_VOXEL_SIZE_HINT = (
    "the voxel size cannot be guessed (reading it as 1 mm would silently change every "
    "length); write the true voxel size into the header (nibabel: "
    "img.header.set_zooms((dx, dy, dz)); FSL: fslchpixdim FILE dx dy dz) or convert the "
    "original DICOM series again"
)


def header_voxel_size(path: Path) -> tuple[tuple[float, float, float], bool] | None:
    """``(pixdim[1:4], has_qform_or_sform)`` from the raw NIfTI-1/-2 header, else None.

    Read from the bytes because nibabel replaces a zero ``pixdim`` with 1 while
    loading (with a log message only), which would make a scan of unknown
    voxel size look like 1 mm voxels.  None when the file is not NIfTI (the
    loader reports that).
    """
    import gzip
    import struct

    try:
        opener = gzip.open if path.name.lower().endswith(".gz") else open
        with opener(path, "rb") as handle:
            raw = handle.read(540)
    except (OSError, EOFError):
        return None
    for order in "<>":
        size = struct.unpack(order + "i", raw[:4])[0] if len(raw) >= 4 else 0
        if size == 348 and len(raw) >= 348 and raw[344:347] in (b"n+1", b"ni1"):
            pixdim = struct.unpack(order + "3f", raw[80:92])
            codes = struct.unpack(order + "2h", raw[252:256])
            break
        if size == 540 and len(raw) >= 540 and raw[4:7] in (b"n+2", b"ni2"):
            pixdim = struct.unpack(order + "3d", raw[112:136])
            codes = struct.unpack(order + "2i", raw[344:352])
            break
    else:
        return None
    return (float(pixdim[0]), float(pixdim[1]), float(pixdim[2])), any(c > 0 for c in codes)


def read_nifti(path: Path) -> Volume:
    """Read a 3-D scalar NIfTI image; physical frame RAS, mm."""
    import nibabel as nib  # local import: nibabel is slow to import
    from nibabel.nifti1 import Nifti1Header
    from nibabel.spatialimages import SpatialImage

    path = Path(path)
    if not path.exists():
        raise InputError(path, "file not found")
    found = header_voxel_size(path)
    if found is not None and not found[1] and not all(v > 0 for v in found[0]):
        shown = " x ".join(f"{v:g}" for v in found[0])
        raise InputError(
            path,
            f"the voxel size in the header is {shown} mm (pixdim; neither a qform nor an "
            "sform is set): the header gives no voxel size",
            NO_VOXEL_SIZE_HINT,
        )
    try:
        img = nib.load(str(path))
    except Exception as exc:  # noqa: BLE001 - nibabel raises many types for bad files
        raise InputError(path, f"cannot read NIfTI file: {exc}") from None
    if not isinstance(img, SpatialImage):
        raise InputError(path, f"not a volume image ({type(img).__name__})")
    shape = img.shape
    if len(shape) == 4 and shape[3] == 1:
        shape = shape[:3]
    if len(shape) != 3:
        raise InputError(path, f"only 3-D NIfTI images are supported, got shape {img.shape}")
    if shape[2] < 2:
        raise InputError(path, "the image has a single slice; an iso-surface needs at least 2")
    proxy = img.dataobj
    slope = float(getattr(proxy, "slope", 1.0))
    inter = float(getattr(proxy, "inter", 0.0))
    try:
        raw = np.asarray(proxy.get_unscaled() if hasattr(proxy, "get_unscaled") else proxy)
    except Exception as exc:  # noqa: BLE001 - damaged data: any nibabel/numpy error
        raise InputError(path, f"cannot read the NIfTI voxel data: {exc}") from None
    if raw.dtype.kind not in "iuf":
        raise InputError(path, f"unsupported NIfTI voxel type {raw.dtype}")
    # nibabel is (i, j, k); ours is (k, j, i); scaling as in DICOM (int16 when exact)
    data = _scaled(raw.reshape(shape).transpose(2, 1, 0), slope, inter)

    warnings: list[str] = []
    header = img.header
    factor = 1.0
    if isinstance(header, Nifti1Header):  # NIfTI-1 and -2; others have no units API
        space_unit = header.get_xyzt_units()[0]
        factor = _SPACE_UNITS_TO_MM.get(space_unit, 1.0)
        if space_unit == "unknown":
            warnings.append("NIfTI spatial units are unset; assuming mm")
    affine = np.asarray(img.affine, dtype=np.float64)
    axes = affine[:3, :3] * factor
    spacing = np.linalg.norm(axes, axis=0)
    if np.any(spacing == 0):
        shown = " x ".join(f"{v:g}" for v in spacing)
        raise InputError(
            path,
            f"the header gives no voxel size along one axis (the voxel-to-world matrix "
            f"gives {shown} mm)",
            NO_VOXEL_SIZE_HINT,
        )
    direction = axes / spacing
    origin = affine[:3, 3] * factor
    codes = {}
    if isinstance(header, Nifti1Header):
        try:
            codes = {
                "sform_code": int(header["sform_code"]),
                "qform_code": int(header["qform_code"]),
            }
        except Exception:  # noqa: BLE001 # pragma: no cover - NIfTI-2 headers without codes
            pass
    metadata = {
        "format": "NIfTI",
        "affine": affine.tolist(),
        "description": _header_text(header, "descrip"),
        "scl_slope": slope,
        "scl_inter": inter,
        **codes,
        "warnings": warnings,
    }
    return Volume(
        data, spacing, origin, direction, "RAS", "unknown", "unknown", str(path), metadata
    )
