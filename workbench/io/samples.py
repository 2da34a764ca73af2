"""Registry of real public sample data, fetched on demand into the user's cache.

Each sample is one or more files with a SHA-256 and (usually) a download
URL; the registry lives in ``sample_registry.json`` beside this module.
Files are downloaded with pooch into the cache folder (``WORKBENCH_DATA_DIR``
if set, else the platform's user cache, e.g.
``~/.cache/forensic-workbench/samples``) and verified by hash before use.
A sample's ``main`` is the path handed to readers: one of its files, or the
folder that holds them (a DICOM series).  Coordinates in a sample's
``anatomy`` hint are in the file's own physical frame (mm): RAS for NIfTI,
LPS for DICOM, as :mod:`workbench.io.volumes` reports it.

Mirror-only files
-----------------
A file without a ``url`` (e.g. a frozen NIfTI copy made from a public DICOM
series) can only come from a local mirror or the cache; :func:`fetch` says so
when it is missing and names the sample it was made from (``derived_from``),
which can be downloaded instead.

Credit
------
Some data must carry a credit line wherever they are shown (the NLM Visible
Human data: "Courtesy of the U.S. National Library of Medicine" plus a note
that the copy is a frozen snapshot).  ``Sample.credit`` holds it;
:func:`credit_for` finds it for a local file or DICOM folder by SHA-256, and
:func:`credit_for_mesh_file` reads it back from the ``comment credit: ...``
header line that ``workbench mesh-from-ct`` writes into PLY meshes.

Local mirrors
-------------
Before downloading, the folders listed in ``WORKBENCH_SAMPLE_MIRRORS``
(separated by ``os.pathsep``) are searched for a copy at the file's
``mirror`` path; a copy whose hash matches is copied into the cache.  The
test suite seeds the cache this way from the project's shared data folder,
so tests never touch the network (they also set ``WORKBENCH_OFFLINE=1``,
which turns any download attempt into an error).
"""

from __future__ import annotations

import json
import os
import shutil
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

from workbench.core.errors import InputError, WorkbenchError
from workbench.model.evidence import file_sha256

_REGISTRY_PATH = Path(__file__).with_name("sample_registry.json")
SAMPLE_PREFIX = "sample:"


#: PLY header comment key under which derived meshes carry a sample's credit
CREDIT_COMMENT_KEY = "credit:"


@dataclass(frozen=True)
class SampleFile:
    """One registered file.

    ``path`` is relative to the cache folder; ``url`` is None for a file with
    no public download (mirror or cache only); ``mirror`` is the path relative
    to a mirror folder (e.g. the shared data folder), None if no mirror holds it.
    """

    path: str
    sha256: str
    url: str | None = None
    mirror: str | None = None

    @property
    def mirror_only(self) -> bool:
        """True when the file cannot be downloaded (no public URL)."""
        return not self.url


@dataclass(frozen=True)
class Sample:
    """A registered sample.

    ``extra_files`` are other files of the same data (e.g. a 2 mm resample)
    that :func:`fetch` does not need; they are known by hash so that meshes
    made from them carry the sample's ``credit``.  ``derived_from`` names the
    sample this one was made from (the one to download when a mirror-only
    file is missing).
    """

    name: str
    main: str
    kind: str
    description: str
    licence: str
    files: tuple[SampleFile, ...]
    anatomy: dict | None = None
    credit: str | None = None
    extra_files: tuple[SampleFile, ...] = ()
    derived_from: str | None = None

    @property
    def mirror_only_files(self) -> tuple[SampleFile, ...]:
        """Files of ``files`` that have no public URL."""
        return tuple(f for f in self.files if f.mirror_only)


def registry() -> dict[str, Sample]:
    """All registered samples by name."""
    raw = json.loads(_REGISTRY_PATH.read_text(encoding="utf-8"))
    return {
        name: Sample(
            name,
            s["main"],
            s["kind"],
            s["description"],
            s["licence"],
            tuple(SampleFile(**f) for f in s["files"]),
            s.get("anatomy"),
            s.get("credit"),
            tuple(SampleFile(**f) for f in s.get("extra_files", ())),
            s.get("derived_from"),
        )
        for name, s in raw["samples"].items()
    }


def cache_dir() -> Path:
    env = os.environ.get("WORKBENCH_DATA_DIR")
    if env:
        return Path(env).expanduser()
    import platformdirs

    return Path(platformdirs.user_cache_dir("forensic-workbench")) / "samples"


def _mirrors() -> list[Path]:
    raw = os.environ.get("WORKBENCH_SAMPLE_MIRRORS", "")
    return [Path(p).expanduser() for p in raw.split(os.pathsep) if p]


def seed_from_mirror(mirror: Path, names: list[str] | None = None) -> int:
    """Copy every registered file found (with the right hash) under ``mirror`` into the cache.

    Returns the number of files now present in the cache from this call.
    """
    count = 0
    for sample in registry().values():
        if names and sample.name not in names:
            continue
        for f in sample.files:
            if _from_mirror(f, [mirror]) is not None:
                count += 1
    return count


def _from_mirror(entry: SampleFile, mirrors: list[Path]) -> Path | None:
    target = cache_dir() / entry.path
    if target.exists() and file_sha256(target) == entry.sha256:
        return target
    if entry.mirror is None:
        return None
    for mirror in mirrors:
        candidate = mirror / entry.mirror
        if candidate.is_file() and file_sha256(candidate) == entry.sha256:
            target.parent.mkdir(parents=True, exist_ok=True)
            tmp = target.with_name(target.name + ".part")
            shutil.copyfile(candidate, tmp)
            os.replace(tmp, target)
            return target
    return None


def fetch(name: str, *, progress: bool = False) -> Path:
    """Local path of sample ``name``'s main file, downloading it if needed.

    Raises
    ------
    WorkbenchError
        Unknown sample; a mirror-only file (no public URL) that is neither in
        the cache nor in a mirror (the message names the sample to download
        instead); or the download failed (the message says which file and
        how to seed the cache by hand).
    """
    samples = registry()
    if name not in samples:
        raise WorkbenchError(f"unknown sample {name!r}; available: {', '.join(sorted(samples))}")
    sample = samples[name]
    mirrors = _mirrors()
    missing = [f for f in sample.files if _from_mirror(f, mirrors) is None]
    unreachable = [f for f in missing if f.mirror_only]
    if unreachable:
        raise WorkbenchError(_mirror_only_message(sample, unreachable, mirrors))
    if missing:
        _download(missing, progress)
    return cache_dir() / sample.main


def _mirror_only_message(sample: Sample, files: list[SampleFile], mirrors: list[Path]) -> str:
    root = cache_dir()
    names = ", ".join(f.path for f in files)
    where = ", ".join(str(m) for m in mirrors) or "none set"
    message = (
        f"sample {sample.name!r}: {names} has no public download URL (it can only come from "
        f"a local mirror or the cache) and was not found in the cache ({root}) or in the "
        f"mirrors of WORKBENCH_SAMPLE_MIRRORS ({where}). Point "
        "WORKBENCH_SAMPLE_MIRRORS at a folder that holds it"
    )
    if files[0].mirror:
        message += f" as {files[0].mirror}"
    if sample.derived_from:
        message += (
            f", or download the original data it was made from instead: "
            f"workbench samples fetch {sample.derived_from} (sample:{sample.derived_from})"
        )
    return message + "."


def _download(files: list[SampleFile], progress: bool) -> None:
    if os.environ.get("WORKBENCH_OFFLINE"):
        names = ", ".join(f.path for f in files)
        raise WorkbenchError(
            f"sample files not in the cache and downloads are off (WORKBENCH_OFFLINE): {names}"
        )
    import pooch

    root = cache_dir()
    fetcher = pooch.create(
        path=root,
        base_url="",
        registry={f.path: f"sha256:{f.sha256}" for f in files},
        urls={f.path: f.url for f in files},
    )
    for f in files:
        try:
            fetcher.fetch(f.path, progressbar=progress)
        except Exception as exc:  # network errors come in many types
            raise WorkbenchError(
                f"could not download sample file {f.path} from {f.url}: {exc}. "
                f"Copy it by hand into {root / f.path}, or point WORKBENCH_SAMPLE_MIRRORS "
                "at a folder that holds it."
            ) from exc


def _credited_files() -> dict[str, str]:
    """SHA-256 -> credit of every registered file (main and extra) of a sample with a credit."""
    table: dict[str, str] = {}
    for sample in registry().values():
        if sample.credit:
            for f in sample.files + sample.extra_files:
                table.setdefault(f.sha256, sample.credit)
    return table


def credit_for(path: str | os.PathLike[str]) -> str | None:
    """The credit line of the sample a local file or DICOM folder came from, or None.

    A file matches when its SHA-256 is that of any registered file (main or
    extra) of a sample with a credit, wherever the file lives and whatever it
    is called.  A folder matches when it is a sample's ``main`` folder in the
    cache, or when a file in it (searched recursively, as the DICOM reader
    does) named like a registered file of a credited sample has that file's
    SHA-256 (only such files are hashed, so a large unrelated series costs
    nothing).  Anything else, or a missing path, gives None.
    """
    path = Path(path).expanduser()
    samples = [s for s in registry().values() if s.credit]
    if not samples:
        return None
    if path.is_file():
        return _credited_files().get(file_sha256(path))
    if not path.is_dir():
        return None
    root = cache_dir()
    resolved = path.resolve()
    for sample in samples:
        if (root / sample.main).resolve() == resolved:
            return sample.credit
    by_name: dict[str, dict[str, str]] = {}
    for sample in samples:
        for f in sample.files + sample.extra_files:
            by_name.setdefault(Path(f.path).name, {})[f.sha256] = sample.credit or ""
    for candidate in sorted(path.rglob("*")):
        table = by_name.get(candidate.name)
        if table and candidate.is_file():
            credit = table.get(file_sha256(candidate))
            if credit:
                return credit
    return None


def credit_for_mesh_file(path: str | os.PathLike[str]) -> str | None:
    """The credit a mesh file carries in its header (PLY ``comment credit: ...``), or None.

    Only PLY headers are read (other formats have no header comments); a
    missing or unreadable file gives None.  Several credit comments are
    joined with a space.
    """
    from workbench.io.mesh_formats import ply

    path = Path(path).expanduser()
    if path.suffix.lower() != ".ply" or not path.is_file():
        return None
    try:
        comments = ply.header_comments(path)
    except (OSError, WorkbenchError):
        return None
    credits = [
        c[len(CREDIT_COMMENT_KEY) :].strip() for c in comments if c.startswith(CREDIT_COMMENT_KEY)
    ]
    credits = [c for c in credits if c]
    return " ".join(credits) if credits else None


def credits_for(
    paths: Iterable[str | os.PathLike[str] | None], sha256s: Iterable[str] = ()
) -> list[str]:
    """The distinct credit lines the inputs ``paths`` (and files with ``sha256s``) ask for.

    A path's credit comes from the sample registry (:func:`credit_for`) or from
    the mesh file's own header (:func:`credit_for_mesh_file`, a mesh extracted
    from a credited CT); a SHA-256 matches any registered credited file.  Reports
    that used such data show these lines (the NLM Visible Human credit).
    """
    out: list[str] = []
    table = _credited_files() if any(s.credit for s in registry().values()) else {}
    for sha in sha256s:
        found = table.get(sha)
        if found and found not in out:
            out.append(found)
    for p in paths:
        if p is None:
            continue
        try:
            found = credit_for(p) or credit_for_mesh_file(p)
        except (OSError, ValueError, WorkbenchError):
            found = None
        if found and found not in out:
            out.append(found)
    return out


def credit_comment(credit: str) -> str:
    """The PLY header comment (without ``comment``) that carries ``credit``."""
    return f"{CREDIT_COMMENT_KEY} {' '.join(credit.split())}"


def resolve_input(argument: str) -> Path:
    """Turn a CLI argument into a path: ``sample:NAME`` fetches a sample.

    Raises :class:`InputError` if a plain path does not exist.
    """
    if argument.startswith(SAMPLE_PREFIX):
        return fetch(argument[len(SAMPLE_PREFIX) :])
    path = Path(argument).expanduser()
    if not path.exists():
        raise InputError(
            path,
            "no such file or folder",
            f"samples can be named as {SAMPLE_PREFIX}NAME, e.g. {SAMPLE_PREFIX}headsq",
        )
    return path
