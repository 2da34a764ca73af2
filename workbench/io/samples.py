"""Registry of real public sample data, fetched on demand into the user's cache.

Each sample is one or more files with a download URL and a SHA-256; the
registry lives in ``sample_registry.json`` beside this module.  Files are
downloaded with pooch into the cache folder (``WORKBENCH_DATA_DIR`` if set,
else the platform's user cache, e.g. ``~/.cache/forensic-workbench/samples``)
and verified by hash before use.

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
from dataclasses import dataclass
from pathlib import Path

from workbench.core.errors import InputError, WorkbenchError
from workbench.model.evidence import sha256_file

_REGISTRY_PATH = Path(__file__).with_name("sample_registry.json")
SAMPLE_PREFIX = "sample:"


@dataclass(frozen=True)
class SampleFile:
    path: str
    sha256: str
    url: str
    mirror: str


@dataclass(frozen=True)
class Sample:
    name: str
    main: str
    kind: str
    description: str
    licence: str
    files: tuple[SampleFile, ...]
    anatomy: dict | None = None


def registry() -> dict[str, Sample]:
    """All registered samples by name."""
    raw = json.loads(_REGISTRY_PATH.read_text(encoding="utf-8"))
    return {
        name: Sample(name, s["main"], s["kind"], s["description"], s["licence"],
                     tuple(SampleFile(**f) for f in s["files"]), s.get("anatomy"))
        for name, s in raw["samples"].items()
    }


def cache_dir() -> Path:
    env = os.environ.get("WORKBENCH_DATA_DIR")
    if env:
        return Path(env).expanduser()
    import platformdirs

    return Path(platformdirs.user_cache_dir("forensic-workbench")) / "samples"


def _sha256(path: Path) -> str:
    return sha256_file(path)[0]


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
    if target.exists() and _sha256(target) == entry.sha256:
        return target
    for mirror in mirrors:
        candidate = mirror / entry.mirror
        if candidate.is_file() and _sha256(candidate) == entry.sha256:
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
        Unknown sample, or the download failed (the message says which file
        and how to seed the cache by hand).
    """
    samples = registry()
    if name not in samples:
        raise WorkbenchError(f"unknown sample {name!r}; available: {', '.join(sorted(samples))}")
    sample = samples[name]
    mirrors = _mirrors()
    missing = [f for f in sample.files if _from_mirror(f, mirrors) is None]
    if missing:
        _download(missing, progress)
    return cache_dir() / sample.main


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


def resolve_input(argument: str) -> Path:
    """Turn a CLI argument into a path: ``sample:NAME`` fetches a sample.

    Raises :class:`InputError` if a plain path does not exist.
    """
    if argument.startswith(SAMPLE_PREFIX):
        return fetch(argument[len(SAMPLE_PREFIX):])
    path = Path(argument).expanduser()
    if not path.exists():
        raise InputError(path, "no such file or folder",
                         f"samples can be named as {SAMPLE_PREFIX}NAME, e.g. {SAMPLE_PREFIX}headsq")
    return path
