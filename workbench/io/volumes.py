"""Read 3-D medical volumes (CT, MR) into :class:`workbench.core.volume.Volume`.

Formats (chosen from the path):

=====================  =======================================  ======
path                   format                                   frame
=====================  =======================================  ======
folder / ``*.dcm``     DICOM series (pydicom)                   LPS
``.nrrd``, ``.nhdr``   NRRD, attached or detached data          LPS/RAS
``.mhd``, ``.mha``     MetaImage                                LPS
``.nii``, ``.nii.gz``  NIfTI-1/2 (nibabel)                      RAS
=====================  =======================================  ======

A file without a known extension is sniffed (NRRD magic, MetaImage
``key = value`` header, DICOM preamble).  Every problem is raised as
:class:`workbench.core.errors.InputError` naming the file at fault.  Reader
warnings (ignored series, irregular spacing, assumed frames) are collected in
``volume.metadata["warnings"]``.
"""

from __future__ import annotations

from os import PathLike
from pathlib import Path

import numpy as np

from workbench.core.errors import InputError
from workbench.core.limits import check_voxel_size
from workbench.core.volume import Volume
from workbench.io.volume_formats.dicom import read_dicom_series
from workbench.io.volume_formats.metaimage import read_metaimage
from workbench.io.volume_formats.nifti import read_nifti
from workbench.io.volume_formats.nrrd import read_nrrd

__all__ = ["Volume", "read_volume", "volume_format", "SUPPORTED_SUFFIXES"]

SUPPORTED_SUFFIXES = (".dcm", ".nrrd", ".nhdr", ".mhd", ".mha", ".nii", ".nii.gz")


def volume_format(path: str | PathLike[str]) -> str:
    """Name of the reader for ``path``: "dicom", "nrrd", "metaimage" or "nifti"."""
    path = Path(path)
    if not path.exists():
        raise InputError(path, "file or folder not found")
    if path.is_dir():
        return "dicom"
    name = path.name.lower()
    if name.endswith((".nii", ".nii.gz")):
        return "nifti"
    suffix = path.suffix.lower()
    if suffix in (".nrrd", ".nhdr"):
        return "nrrd"
    if suffix in (".mhd", ".mha"):
        return "metaimage"
    if suffix in (".dcm", ".ima"):
        return "dicom"
    try:
        with open(path, "rb") as fh:
            head = fh.read(256)
    except OSError as exc:
        raise InputError(path, f"cannot read: {exc.strerror or exc}") from None
    if head.startswith(b"NRRD000"):
        return "nrrd"
    if len(head) >= 132 and head[128:132] == b"DICM":
        return "dicom"
    text = head.decode("latin-1", "replace").lstrip()
    if text.startswith(("ObjectType", "NDims")):
        return "metaimage"
    raise InputError(
        path,
        "unrecognised volume format",
        hint="expected a DICOM folder, .nrrd/.nhdr, .mhd/.mha or .nii/.nii.gz",
    )


def read_volume(path: str | PathLike[str]) -> Volume:
    """Read a CT/MR volume from a DICOM folder or a NRRD/MetaImage/NIfTI file.

    Parameters
    ----------
    path : path-like
        A DICOM series folder (or one slice file of it), or a volume file.

    Returns
    -------
    Volume
        ``data`` indexed (k, j, i) in the file's native dtype (DICOM CT:
        Hounsfield units, int16 when they fit); spacing/origin in mm;
        ``frame`` LPS (DICOM, NRRD, MetaImage) or RAS (NIfTI).

    Raises
    ------
    InputError
        Missing/unreadable files, inconsistent sizes, missing slices, etc.
    """
    path = Path(path)
    kind = volume_format(path)
    reader = {
        "dicom": read_dicom_series,
        "nrrd": read_nrrd,
        "metaimage": read_metaimage,
        "nifti": read_nifti,
    }[kind]
    try:
        volume = reader(path)
    except ValueError as exc:  # the Volume's own checks (spacing, direction) on header values
        raise InputError(path, f"the header describes no valid volume: {exc}") from None
    if kind == "nifti":
        _check_nifti_pixdim(path)
    check_voxel_size(volume.spacing_mm, path)
    _check_finite_voxels(volume, path)
    return volume


def _check_nifti_pixdim(path: Path) -> None:
    """Refuse a NIfTI-1 whose affine comes from ``pixdim`` with a zero or negative voxel size.

    nibabel replaces such sizes with 1 (with a warning only), which would
    make a scan of unknown voxel size look like 1 mm voxels; so the raw
    header bytes are read here (``pixdim`` at byte 76, ``qform_code`` and
    ``sform_code`` at 252 and 254).
    """
    import gzip
    import struct

    try:
        opener = gzip.open if path.name.lower().endswith(".gz") else open
        with opener(path, "rb") as handle:
            raw = handle.read(348)
    except OSError:
        return  # the reader already read it; nothing more to learn here
    if len(raw) < 348:
        return
    for order in "<>":
        if struct.unpack(order + "i", raw[:4])[0] == 348:  # NIfTI-1 (NIfTI-2 has 540)
            break
    else:
        return
    pixdim = struct.unpack(order + "3f", raw[80:92])
    codes = struct.unpack(order + "2h", raw[252:256])
    if codes == (0, 0) and not all(v > 0 for v in pixdim):
        shown = " x ".join(f"{v:g}" for v in pixdim)
        raise InputError(
            path,
            f"the voxel size in the header is {shown} mm (pixdim, no qform or sform)",
            "the scan's voxel size is unset and cannot be "
            "guessed (1 mm would be a silent assumption); fix the header",
        )


def _check_finite_voxels(volume: Volume, path: Path) -> None:
    """Refuse NaN or infinite voxel values (floating-point data only), with their count."""
    data = volume.data
    if data.dtype.kind != "f":
        return
    bad = 0
    for k in range(data.shape[0]):  # slice by slice: no full-size temporary
        bad += int((~np.isfinite(data[k])).sum())
    if bad:
        raise InputError(
            path,
            f"{bad} voxels of {data.size} are NaN or infinite",
            "the volume is damaged, or NaN marks 'no data'; fill them (e.g. with "
            "the air value) before extracting a surface",
        )
