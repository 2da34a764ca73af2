"""Get a reference head quickly: from a template pack, a cached build, or a fresh build.

Building the built-in head (authored skin, procedural skull fitted at
T-Table depths, 24 muscle grids) takes several seconds, so the result is
kept as a template pack (see :mod:`workbench.io.template_pack`) in the user
cache folder, keyed by a hash of every source file and data table that goes
into it.  Editing any of them gives a new key, so a stale head is never
used.  Units and frame: mm, head frame (x to the subject's left, y up,
z forward, Frankfort Horizontal at y = 0).
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import shutil
import tempfile
from os import PathLike
from pathlib import Path

from workbench.core import helper_process
from workbench.core.data_paths import DEFAULT_DEPTH_TABLE, data_tables_dir
from workbench.core.errors import InputError, WorkbenchError
from workbench.io.template_pack import export_template, load_template_pack
from workbench.model.template import TemplateHead

#: the workbench package (this file is workbench/services/templates/cache.py)
_PACKAGE = Path(__file__).resolve().parents[2]
#: sources whose content decides the built-in head
_SOURCE_GLOBS = (
    "core/headgen/*.py",
    "services/templates/template.py",
    "services/templates/muscles.py",
    "model/template.py",
    "model/muscles.py",
    "core/tps.py",
    "core/normals.py",
    # the geometry the build queries (closest points and signs, rays, iso-surfaces)
    "core/mesh.py",
    "core/spatial.py",
    "core/bvh.py",
    "core/raycast.py",
    "core/isosurface.py",
)
_TABLE_GLOBS = (
    "template/*",
    f"tissue_depth/{DEFAULT_DEPTH_TABLE}.*",
    "muscles/*",
    "landmarks/catalogue.csv",
)
SEXES = ("female", "male")


def _tables_root() -> Path:
    return data_tables_dir()


def source_key() -> str:
    """Hash of every file the built-in head is made from (first 16 hex digits)."""
    h = hashlib.sha256()
    roots = [(_PACKAGE, _SOURCE_GLOBS), (_tables_root(), _TABLE_GLOBS)]
    for root, globs in roots:
        for pattern in globs:
            for path in sorted(root.glob(pattern)):
                h.update(path.relative_to(root).as_posix().encode())
                h.update(path.read_bytes())
    return h.hexdigest()[:16]


def cache_root() -> Path:
    env = os.environ.get("WORKBENCH_DATA_DIR")
    if env:
        return Path(env) / "templates"
    import platformdirs

    return Path(platformdirs.user_cache_dir("forensic-workbench")) / "templates"


def cached_folder(sex: str, root: Path | None = None) -> Path:
    """Where the up-to-date built-in head for ``sex`` is (or will be) cached."""
    return (root or cache_root()) / f"{sex}-{source_key()}"


@helper_process.runnable
def build_cached(sex: str, root: str) -> bool:
    """Make sure the built-in head for ``sex`` is cached under ``root``; True if it is now.

    The build keeps the GIL for long stretches (MINPACK least squares, mesh
    decimation: up to ~0.5 s each), so the desktop window's workers have it
    run in the helper process and then read the cached pack.  ``root`` is
    passed along because the helper's environment is the one it started
    with.
    """
    folder = cached_folder(sex, Path(root))
    _cached_head(sex, folder)
    return (folder / "template.json").is_file()


def reference_head(
    sex: str = "male", pack: str | PathLike[str] | None = None, *, use_cache: bool = True
) -> TemplateHead:
    """The head to work with: ``pack`` if given, else the built-in head for ``sex``.

    A pack is read as it is (its own sex wins; ``sex`` is ignored).  The
    built-in head comes from the cache when an up-to-date copy is there and
    is built (and cached) otherwise.  A damaged cache entry is rebuilt.
    On a thread that offloads to the helper process (the window's workers,
    :func:`workbench.core.helper_process.offload_here`) the build runs there.
    """
    if pack is not None:
        return load_template_pack(pack)
    if sex not in SEXES:
        raise InputError("--sex", f"unknown sex {sex!r}", hint="use female or male")
    if not use_cache:
        from workbench.services.templates.template import build_reference_head

        return build_reference_head(sex)
    root = cache_root()
    folder = cached_folder(sex, root)
    if helper_process.offloading() and not (folder / "template.json").is_file():
        with contextlib.suppress(RuntimeError, WorkbenchError, OSError):
            helper_process.call("workbench.services.templates.cache:build_cached", sex, str(root))
            # (if that failed, the head is built below, in this process)
    return _cached_head(sex, folder)


def _cached_head(sex: str, folder: Path) -> TemplateHead:
    """The head cached in ``folder``, built and published there if missing or damaged."""
    from workbench.services.templates.template import build_reference_head

    if (folder / "template.json").is_file():
        try:
            return load_template_pack(folder)
        except (WorkbenchError, OSError, KeyError, ValueError):
            shutil.rmtree(folder, ignore_errors=True)
    head = build_reference_head(sex)
    try:
        folder.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{sex}-", dir=folder.parent))
        export_template(head, tmp)
        try:
            tmp.rename(folder)  # atomic publish; a concurrent builder may have won
        except OSError:
            shutil.rmtree(tmp, ignore_errors=True)
    except OSError:
        pass  # a read-only cache only costs time
    return head
