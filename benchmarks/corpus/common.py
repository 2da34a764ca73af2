"""Shared helpers of the robustness corpus: paths, hashing, JSON, rigid transforms.

Units mm.  Transforms are 4 x 4 homogeneous matrices acting on row-stacked
points (``p @ M[:3, :3].T + M[:3, 3]``), the project's convention
(:func:`workbench.core.frame.apply_transform`).
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[2]

#: every generated file of the corpus lives below this folder (git-ignored)
RESULTS = ROOT / "benchmarks" / "results" / "corpus"

CREDIT = "Courtesy of the U.S. National Library of Medicine"
CREDIT_NOTE = (
    "Visible Human Project data; this copy is a frozen snapshot and may not reflect the most "
    "current or accurate data available from NLM. NLM does not endorse this project."
)

#: the registration code whose change invalidates the cached truth
#: packages whose change invalidates a scored result (the whole path a variant goes through)
SCORED_PACKAGES = ("workbench/core", "workbench/model", "workbench/services", "workbench/io")


def results_dir(*parts: str, root: Path | None = None) -> Path:
    """A folder below the corpus results folder (created)."""
    path = (root or RESULTS).joinpath(*parts)
    path.mkdir(parents=True, exist_ok=True)
    return path


def data_root() -> Path:
    """The folder of the shared real data (``../shared/data`` beside the repository).

    ``WORKBENCH_SHARED_DATA`` wins, then the first ``WORKBENCH_SAMPLE_MIRRORS``
    entry that exists.
    """
    env = os.environ.get("WORKBENCH_SHARED_DATA")
    if env:
        return Path(env)
    for entry in os.environ.get("WORKBENCH_SAMPLE_MIRRORS", "").split(os.pathsep):
        if entry and Path(entry).is_dir():
            return Path(entry)
    return ROOT.parent / "shared" / "data"


def code_root() -> Path:
    """The folder holding the ``workbench`` package this interpreter imports (the checkout,
    or an exported revision: ``bench_robustness.py --code``)."""
    import workbench

    return Path(workbench.__file__).resolve().parents[1]


def files_hash(paths: Iterable[Path], root: Path) -> str:
    """First 16 hex digits of the SHA-256 over the paths' names (relative to ``root``) and
    contents."""
    h = hashlib.sha256()
    for path in sorted(Path(p) for p in paths):
        h.update(path.relative_to(root).as_posix().encode())
        h.update(path.read_bytes())
    return h.hexdigest()[:16]


#: the layout of a truth record (a change recomputes the truths)
TRUTH_VERSION = 4  # 3: the snapped landmarks; 4: medians over the variants' bone levels


def registration_hash() -> str:
    """Hash of the truth's code: every imported file a registration can run through (the
    orientation, the jaw, the self-check live in several modules) and :data:`TRUTH_VERSION`."""
    return f"{scored_code_hash()[:12]}v{TRUTH_VERSION}"


#: data tables the scored landmarks depend on (the snap rules move the delivered landmarks)
SCORED_TABLES = ("data_tables/landmarks/*.csv",)


def scored_code_hash() -> str:
    """Hash of every imported Python file a variant's automatic registration can run through,
    and of the landmark tables (:data:`SCORED_TABLES`)."""
    root = code_root()
    files = [p for pkg in SCORED_PACKAGES for p in (root / pkg).rglob("*.py")]
    files += [p for pattern in SCORED_TABLES for p in root.glob(pattern)]
    return files_hash(files, root)


def jsonable(x: Any, nd: int = 4) -> Any:
    """Numpy values and arrays as plain JSON values (floats rounded to ``nd`` decimals)."""
    if isinstance(x, dict):
        return {str(k): jsonable(v, nd) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return [jsonable(v, nd) for v in x]
    if isinstance(x, np.ndarray):
        return jsonable(x.tolist(), nd)
    if isinstance(x, bool | np.bool_):
        return bool(x)
    if isinstance(x, int | np.integer):
        return int(x)
    if isinstance(x, float | np.floating):
        v = float(x)
        return round(v, nd) if np.isfinite(v) else None
    return x


def write_json(path: Path, data: Any) -> Path:
    """Write ``data`` as indented JSON atomically."""
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    tmp.write_text(json.dumps(jsonable(data, 9), indent=1) + "\n", encoding="utf-8")
    tmp.replace(path)
    return path


def read_json(path: Path) -> Any:
    return json.loads(Path(path).read_text(encoding="utf-8"))


# ---------------------------------------------------------------- rigid transforms
def apply(m: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``points`` ``(n, 3)`` (or ``(3,)``) mapped by the 4 x 4 ``m``."""
    p = np.asarray(points, np.float64)
    return p @ np.asarray(m)[:3, :3].T + np.asarray(m)[:3, 3]


def apply_dir(m: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """Directions mapped by the linear part of ``m`` (not renormalised)."""
    return np.asarray(dirs, np.float64) @ np.asarray(m)[:3, :3].T


def homogeneous(r: np.ndarray | None = None, t: np.ndarray | None = None) -> np.ndarray:
    m = np.eye(4)
    if r is not None:
        m[:3, :3] = r
    if t is not None:
        m[:3, 3] = t
    return m


def rotation_matrix(axis: np.ndarray, deg: float) -> np.ndarray:
    """3 x 3 right-handed rotation by ``deg`` about the unit ``axis``."""
    a = np.asarray(axis, np.float64)
    a = a / np.linalg.norm(a)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    th = np.radians(deg)
    return np.eye(3) + np.sin(th) * k + (1 - np.cos(th)) * k @ k


def rotation_about(point: np.ndarray, axis: np.ndarray, deg: float) -> np.ndarray:
    """4 x 4 rotation by ``deg`` about the line through ``point`` along ``axis``."""
    r = rotation_matrix(axis, deg)
    p = np.asarray(point, np.float64)
    return homogeneous(r, p - r @ p)


def procrustes(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares proper rotation ``R`` and shift ``t`` with ``dst ≈ src @ R.T + t``."""
    a = np.asarray(src, np.float64)
    b = np.asarray(dst, np.float64)
    ca, cb = a.mean(axis=0), b.mean(axis=0)
    u, _, vt = np.linalg.svd((a - ca).T @ (b - cb))
    d = np.sign(np.linalg.det(vt.T @ u.T))
    r = vt.T @ np.diag([1.0, 1.0, d]) @ u.T
    return r, cb - r @ ca


def unit(v: np.ndarray) -> np.ndarray:
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v)
