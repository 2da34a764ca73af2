"""Volume readers: real headsq NRRD, and DICOM / NRRD / MetaImage / NIfTI written here."""

from __future__ import annotations

import gzip
import shutil
import zlib
from pathlib import Path

import numpy as np
import pytest

from workbench.core.errors import InputError
from workbench.core.volume import Volume
from workbench.io.volumes import read_volume

HEADSQ_SHAPE = (93, 64, 64)


@pytest.fixture(scope="module")
def headsq_reference(headsq_nhdr: Path) -> np.ndarray:
    folder = headsq_nhdr.parent
    return np.stack(
        [np.fromfile(folder / f"quarter.{i}", "<i2").reshape(64, 64) for i in range(1, 94)]
    )


def _rotation(a: float, b: float, c: float) -> np.ndarray:
    ca, sa, cb, sb, cc, sc = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(c), np.sin(c)
    rz = np.array([[ca, -sa, 0], [sa, ca, 0], [0, 0, 1]])
    ry = np.array([[cb, 0, sb], [0, 1, 0], [-sb, 0, cb]])
    rx = np.array([[1, 0, 0], [0, cc, -sc], [0, sc, cc]])
    return rz @ ry @ rx


# ---------------------------------------------------------------- headsq NRRD
def test_headsq_loads_with_documented_geometry(headsq_nhdr, headsq_reference):
    vol = read_volume(headsq_nhdr)
    assert vol.data.shape == HEADSQ_SHAPE
    assert vol.shape_ijk == (64, 64, 93)
    assert vol.data.dtype == np.int16
    np.testing.assert_allclose(vol.spacing_mm, [3.2, 3.2, 1.5])
    np.testing.assert_array_equal(vol.origin_mm, 0.0)
    np.testing.assert_array_equal(vol.direction, np.eye(3))
    assert vol.value_range() == (0.0, 3926.0)
    np.testing.assert_array_equal(vol.data, headsq_reference)
    assert vol.frame == "LPS" and vol.metadata["frame_assumed"] is True
    assert any("3D-left-handed" in w for w in vol.metadata["warnings"])
    assert len(vol.metadata["data_files"]) == 93
    # physical extent 201.6 x 201.6 x 138 mm (PROVENANCE.md) between outer voxel centres + 1 voxel
    np.testing.assert_allclose(vol.extent_mm + vol.spacing_mm, [204.8, 204.8, 139.5])
    np.testing.assert_allclose(vol.index_to_physical([[63, 63, 92]]), [[201.6, 201.6, 138.0]])


def _write(path: Path, header: str, payload: bytes = b"") -> Path:
    path.write_bytes(header.encode("latin-1") + payload)
    return path


def test_nrrd_attached_gzip_big_endian_with_space_directions(tmp_path, headsq_reference):
    rot = _rotation(0.3, -0.2, 0.1)
    spacing = np.array([0.8, 0.9, 2.5])
    axes = rot * spacing
    dirs = " ".join("(" + ",".join(f"{x:.17g}" for x in axes[:, n]) + ")" for n in range(3))
    header = (
        "NRRD0005\n# a comment\ntype: int16\ndimension: 3\nsizes: 64 64 93\n"
        "space: right-anterior-superior\n"
        f"space directions: {dirs}\nspace origin: (-10.5,20,33.25)\n"
        "kinds: domain domain domain\nendian: big\nencoding: gzip\nmodality:=CT\n\n"
    )
    path = _write(
        tmp_path / "a.nrrd", header, gzip.compress(headsq_reference.astype(">i2").tobytes())
    )
    vol = read_volume(path)
    np.testing.assert_array_equal(vol.data, headsq_reference)
    assert vol.frame == "RAS" and vol.metadata["frame_assumed"] is False
    np.testing.assert_allclose(vol.spacing_mm, spacing)
    np.testing.assert_allclose(vol.direction, rot, atol=1e-12)
    np.testing.assert_allclose(vol.origin_mm, [-10.5, 20, 33.25])
    ijk = np.array([[0, 0, 0], [3, 5, 7], [63, 1, 92]], float)
    np.testing.assert_allclose(vol.index_to_physical(ijk), ijk @ axes.T + [-10.5, 20, 33.25])
    assert vol.modality == "CT"


@pytest.mark.parametrize("form", ["list", "single", "pattern-gzip"])
def test_nrrd_detached_data_file_forms(tmp_path, headsq_reference, form):
    base = (
        "NRRD0004\ntype: short\ndimension: 3\nsizes: 64 64 93\n"
        "spacings: 3.2 3.2 1.5\nendian: little\n"
    )
    if form == "list":
        names = [f"s{n:03d}.raw" for n in range(93)]
        for name, sl in zip(names, headsq_reference, strict=True):
            (tmp_path / name).write_bytes(sl.astype("<i2").tobytes())
        header = (
            base
            + "encoding: raw\nspace: left-posterior-superior\ndata file: LIST\n"
            + "\n".join(names)
            + "\n"
        )
    elif form == "single":
        (tmp_path / "d.raw").write_bytes(b"JUNKHEADER" + headsq_reference.astype("<i2").tobytes())
        header = base + "encoding: raw\nbyte skip: 10\ndata file: d.raw\n"
    else:
        for n, sl in enumerate(headsq_reference):
            (tmp_path / f"img{2 * n + 5:04d}.gz").write_bytes(
                gzip.compress(sl.astype("<i2").tobytes())
            )
        header = base + "encoding: gzip\ndata file: img%04d.gz 5 189 2\n"
    vol = read_volume(_write(tmp_path / "h.nhdr", header))
    np.testing.assert_array_equal(vol.data, headsq_reference)
    np.testing.assert_allclose(vol.spacing_mm, [3.2, 3.2, 1.5])


def test_nrrd_problems_are_input_errors(tmp_path, headsq_nhdr):
    folder = tmp_path / "headsq"
    shutil.copytree(headsq_nhdr.parent, folder)
    (folder / "quarter.47").unlink()
    with pytest.raises(InputError, match=r"quarter\.47: data file not found"):
        read_volume(folder / "quarter.nhdr")
    (folder / "quarter.47").write_bytes(b"\0" * 100)
    with pytest.raises(InputError, match="found only 50"):
        read_volume(folder / "quarter.nhdr")
    bad = _write(
        tmp_path / "bad.nrrd",
        "NRRD0004\ntype: block\ndimension: 3\nsizes: 2 2 2\nencoding: raw\n\n",
    )
    with pytest.raises(InputError, match="unsupported type 'block'"):
        read_volume(bad)
    with pytest.raises(InputError, match="not a NRRD file"):
        read_volume(_write(tmp_path / "x.nrrd", "hello\n"))
    with pytest.raises(InputError, match="not found"):
        read_volume(tmp_path / "nothing.nrrd")


# ---------------------------------------------------------------- DICOM
def _write_dicom_series(
    folder: Path,
    raw: np.ndarray,
    *,
    rot,
    spacing_ijk,
    origin,
    slope,
    intercept,
    series_uid=None,
    rng=None,
    description="axial",
):
    """Write raw[k, j, i] (uint16) as CT slices in shuffled file and instance order."""
    from pydicom.dataset import Dataset, FileMetaDataset
    from pydicom.uid import CTImageStorage, ExplicitVRLittleEndian, generate_uid

    folder.mkdir(parents=True, exist_ok=True)
    rng = rng or np.random.default_rng(0)
    series_uid = series_uid or generate_uid()
    nk, nj, ni = raw.shape
    order = rng.permutation(nk)
    for n, k in enumerate(order):
        meta = FileMetaDataset()
        meta.MediaStorageSOPClassUID = CTImageStorage
        meta.MediaStorageSOPInstanceUID = generate_uid()
        meta.TransferSyntaxUID = ExplicitVRLittleEndian
        ds = Dataset()
        ds.file_meta = meta
        ds.SOPClassUID = CTImageStorage
        ds.SOPInstanceUID = meta.MediaStorageSOPInstanceUID
        ds.Modality = "CT"
        ds.SeriesInstanceUID = series_uid
        ds.SeriesDescription = description
        ds.InstanceNumber = n + 1
        ipp = origin + k * spacing_ijk[2] * rot[:, 2]
        ds.ImagePositionPatient = [round(float(x), 6) for x in ipp]
        ds.ImageOrientationPatient = [round(float(x), 8) for x in np.r_[rot[:, 0], rot[:, 1]]]
        ds.PixelSpacing = [spacing_ijk[1], spacing_ijk[0]]  # (row spacing, column spacing)
        ds.SliceThickness = spacing_ijk[2]
        ds.Rows, ds.Columns = nj, ni
        ds.SamplesPerPixel = 1
        ds.PhotometricInterpretation = "MONOCHROME2"
        ds.BitsAllocated, ds.BitsStored, ds.HighBit, ds.PixelRepresentation = 16, 16, 15, 0
        ds.RescaleSlope, ds.RescaleIntercept = slope, intercept
        ds.PixelData = raw[k].astype("<u2").tobytes()
        ds.save_as(folder / f"IM{rng.integers(1e9):09d}.dcm", enforce_file_format=True)
    return series_uid


DICOM_ROT = _rotation(0.4, 0.25, -0.15)
DICOM_SPACING = np.array([0.7, 0.9, 2.5])  # i (column), j (row), k (slice)
DICOM_ORIGIN = np.array([-120.0, 35.5, 80.25])


def test_dicom_series_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    raw = rng.integers(0, 2000, size=(12, 10, 14)).astype(np.uint16)
    folder = tmp_path / "series"
    _write_dicom_series(
        folder,
        raw,
        rot=DICOM_ROT,
        spacing_ijk=DICOM_SPACING,
        origin=DICOM_ORIGIN,
        slope=2,
        intercept=-1024,
        rng=rng,
    )
    _write_dicom_series(
        folder,
        raw[:3],
        rot=np.eye(3),
        spacing_ijk=DICOM_SPACING,
        origin=DICOM_ORIGIN,
        slope=1,
        intercept=0,
        rng=rng,
        description="scout",
    )
    (folder / "notes.txt").write_text("not a DICOM file")
    vol = read_volume(folder)
    assert vol.data.shape == (12, 10, 14) and vol.data.dtype == np.int16
    np.testing.assert_array_equal(vol.data, raw.astype(np.int32) * 2 - 1024)
    assert (vol.units, vol.modality, vol.frame) == ("HU", "CT", "LPS")
    np.testing.assert_allclose(vol.spacing_mm, DICOM_SPACING, atol=1e-6)
    np.testing.assert_allclose(vol.direction, DICOM_ROT, atol=1e-6)
    np.testing.assert_allclose(vol.origin_mm, DICOM_ORIGIN, atol=1e-5)
    # voxel (i, j, k) centre = IPP_k + i * column spacing * row cosine
    #                                + j * row spacing * column cosine
    i, j, k = 13, 9, 7
    expected = (
        DICOM_ORIGIN
        + k * 2.5 * DICOM_ROT[:, 2]
        + i * 0.7 * DICOM_ROT[:, 0]
        + j * 0.9 * DICOM_ROT[:, 1]
    )
    np.testing.assert_allclose(vol.index_to_physical(np.array([[i, j, k]])), [expected], atol=1e-5)
    assert vol.metadata["n_slices"] == 12
    assert len(vol.metadata["other_series"]) == 1
    assert any("scout" in w for w in vol.metadata["warnings"])
    # a single slice file selects its own series
    scout_file = next(f for f in folder.glob("*.dcm") if _description(f) == "scout")
    assert read_volume(scout_file).data.shape == (3, 10, 14)


def _description(path: Path) -> str:
    import pydicom

    return str(pydicom.dcmread(path, stop_before_pixels=True).SeriesDescription)


def test_dicom_fractional_rescale_gives_float32(tmp_path):
    raw = np.arange(4 * 5 * 6, dtype=np.uint16).reshape(4, 5, 6)
    _write_dicom_series(
        tmp_path,
        raw,
        rot=np.eye(3),
        spacing_ijk=np.array([1.0, 1.0, 1.25]),
        origin=np.zeros(3),
        slope=0.5,
        intercept=-100.25,
    )
    vol = read_volume(tmp_path)
    assert vol.data.dtype == np.float32
    np.testing.assert_allclose(vol.data, raw * 0.5 - 100.25)
    np.testing.assert_allclose(vol.spacing_mm, [1.0, 1.0, 1.25])


def test_dicom_problems_are_input_errors(tmp_path):
    raw = np.zeros((6, 4, 4), np.uint16)
    folder = tmp_path / "gap"
    _write_dicom_series(
        folder,
        raw,
        rot=DICOM_ROT,
        spacing_ijk=DICOM_SPACING,
        origin=DICOM_ORIGIN,
        slope=1,
        intercept=-1024,
    )
    import pydicom

    files = sorted(
        folder.glob("*.dcm"),
        key=lambda f: float(np.dot(pydicom.dcmread(f).ImagePositionPatient, DICOM_ROT[:, 2])),
    )
    files[3].unlink()
    with pytest.raises(InputError, match=r"missing slice\(s\).*about 1 slice"):
        read_volume(folder)
    ds = pydicom.dcmread(files[1])
    ds.Rows, ds.Columns = 2, 8
    ds.save_as(files[1])
    with pytest.raises(InputError, match="inconsistent image size"):
        read_volume(folder)
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "readme.txt").write_text("nothing here")
    with pytest.raises(InputError, match=r"no DICOM image slices found \(1 files"):
        read_volume(empty)


# ---------------------------------------------------------------- MetaImage
def test_metaimage_detached_and_local_compressed(tmp_path, headsq_reference):
    rot = _rotation(-0.3, 0.1, 0.2)
    tm = " ".join(f"{x:.17g}" for x in rot.T.ravel())  # n-th triple = direction of axis n
    common = (
        f"ObjectType = Image\nNDims = 3\nDimSize = 64 64 93\nElementSpacing = 3.2 3.2 1.5\n"
        f"Offset = 1 -2 3.5\nTransformMatrix = {tm}\nAnatomicalOrientation = RAI\n"
    )
    (tmp_path / "v.raw").write_bytes(headsq_reference.astype(">i2").tobytes())
    mhd = _write(
        tmp_path / "v.mhd",
        common + "ElementType = MET_SHORT\nBinaryDataByteOrderMSB = True\n"
        "Modality = MET_MOD_CT\nElementDataFile = v.raw\n",
    )
    vol = read_volume(mhd)
    np.testing.assert_array_equal(vol.data, headsq_reference)
    np.testing.assert_allclose(vol.direction, rot, atol=1e-12)
    np.testing.assert_allclose(vol.origin_mm, [1, -2, 3.5])
    np.testing.assert_allclose(vol.spacing_mm, [3.2, 3.2, 1.5])
    assert (vol.frame, vol.modality) == ("LPS", "CT")

    values = headsq_reference.astype("<f4") * 0.25
    mha = _write(
        tmp_path / "v.mha",
        common + "ElementType = MET_FLOAT\nCompressedData = True\nElementDataFile = LOCAL\n",
        zlib.compress(values.tobytes()),
    )
    vol = read_volume(mha)
    assert vol.data.dtype == np.float32
    np.testing.assert_array_equal(vol.data, values)

    with pytest.raises(InputError, match="found only"):
        read_volume(
            _write(
                tmp_path / "short.mha",
                common + "ElementType = MET_USHORT\nElementDataFile = LOCAL\n",
                b"\0" * 1000,
            )
        )


# ---------------------------------------------------------------- NIfTI
def test_nifti_round_trip(tmp_path):
    import nibabel as nib

    rng = np.random.default_rng(3)
    data_ijk = rng.integers(-1024, 3000, size=(9, 7, 5)).astype(np.int16)
    affine = np.eye(4)
    affine[:3, :3] = _rotation(0.2, 0.1, -0.4) * [0.6, 0.75, 2.0]
    affine[:3, 3] = [-90.0, 12.0, -40.0]
    nib.save(nib.Nifti1Image(data_ijk, affine), tmp_path / "ct.nii.gz")
    vol = read_volume(tmp_path / "ct.nii.gz")
    assert vol.frame == "RAS" and vol.data.dtype == np.int16
    np.testing.assert_array_equal(vol.data, data_ijk.transpose(2, 1, 0))
    np.testing.assert_allclose(vol.affine, affine, atol=1e-5)  # NIfTI stores float32
    # same voxel, same physical point, both conventions
    i, j, k = 4, 6, 3
    np.testing.assert_allclose(
        vol.index_to_physical(np.array([i, j, k])), (affine @ [i, j, k, 1])[:3], atol=1e-4
    )
    lps = vol.in_frame("LPS")
    np.testing.assert_allclose(
        lps.index_to_physical(np.array([i, j, k])),
        (affine @ [i, j, k, 1])[:3] * [-1, -1, 1],
        atol=1e-4,
    )

    img = nib.Nifti1Image(data_ijk, affine)
    img.header.set_slope_inter(0.5, 10.0)
    nib.save(img, tmp_path / "scaled.nii")
    scaled = read_volume(tmp_path / "scaled.nii")
    assert scaled.data.dtype == np.float32  # never a float64 volume
    np.testing.assert_allclose(scaled.data, data_ijk.transpose(2, 1, 0) * 0.5 + 10.0)
    img = nib.Nifti1Image(data_ijk // 2, affine)
    img.header.set_slope_inter(2.0, -1024.0)  # CT stored with an integer rescale
    nib.save(img, tmp_path / "ct_rescaled.nii")
    rescaled = read_volume(tmp_path / "ct_rescaled.nii")
    assert rescaled.data.dtype == np.int16
    np.testing.assert_array_equal(rescaled.data, (data_ijk // 2).transpose(2, 1, 0) * 2 - 1024)


def test_volume_value_type_checks():
    with pytest.raises(ValueError, match="3-D"):
        Volume(np.zeros((4, 4)), (1, 1, 1))
    with pytest.raises(ValueError, match="positive"):
        Volume(np.zeros((2, 2, 2)), (1, 0, 1))
    data = np.zeros((2, 3, 4), np.int16)
    vol = Volume(data, (1, 2, 3))
    assert data.flags.writeable and not vol.data.flags.writeable
    pts = np.random.default_rng(0).uniform(0, 3, size=(10, 3))
    np.testing.assert_allclose(vol.physical_to_index(vol.index_to_physical(pts)), pts)


def test_unknown_format_is_an_input_error(tmp_path):
    with pytest.raises(InputError, match="unrecognised volume format"):
        read_volume(_write(tmp_path / "x.bin", "just bytes"))
