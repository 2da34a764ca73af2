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

from workbench.core.errors import InputError
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
    return reader(path)
