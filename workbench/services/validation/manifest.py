"""The validation manifest (:mod:`workbench.services.validation.run` describes its columns).

One CSV row per case; paths relative to the manifest (or ``sample:NAME``).
Reading it checks every row and names the file, row and column of a problem;
a truth that is the skull's own file or bytes is refused here.
"""

from __future__ import annotations

import csv
import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from workbench.core.errors import InputError
from workbench.core.face_metric import ScoreMask
from workbench.core.safe_names import name_problem, safe_id

COLUMNS = (
    "id",
    "skull",
    "truth",
    "units",
    "mask",
    "anterior",
    "superior",
    "left",
    "orient",
    "sex",
    "build",
    "tissue",
    "template",
    "bone_iso",
    "skin_iso",
    "subject",
    "truth_landmarks",
)
VOLUME_SUFFIXES = (".nii", ".nii.gz", ".nrrd", ".nhdr", ".mhd", ".mha", ".dcm")
#: names ``validate`` writes in DIR itself (no case id may take them)
RESERVED = ("references", "results.csv", "results.md", "results.pdf", "features.csv")


@dataclass(frozen=True)
class ValidationCase:
    """One manifest row (paths resolved)."""

    case_id: str
    skull: Path
    truth: Path
    units: str = "auto"
    mask: ScoreMask = field(default_factory=ScoreMask)
    orientation: tuple | None = None
    sex: str = "male"
    build: str | float = "normal"
    tissue: str = "table"
    template: Path | None = None
    bone_iso: float | None = None
    skin_iso: float | None = None
    subject: str = ""
    orient: str = "hint"
    truth_landmarks: Path | None = None

    @property
    def who(self) -> str:
        return self.subject or self.case_id


def _vector(text: str, where: str) -> tuple[float, float, float] | None:
    text = (text or "").strip()
    if not text:
        return None
    try:
        v = tuple(float(t) for t in text.replace(";", ",").split(","))
    except ValueError:
        v = ()
    if len(v) != 3 or not np.isfinite(v).all() or not np.linalg.norm(v) > 0:
        raise InputError(where, f"{text!r} is not a direction x,y,z")
    return v


def _resolve(text: str, base: Path, where: str) -> Path:
    from workbench.io.samples import resolve_input

    text = text.strip()
    if not text:
        raise InputError(where, "is empty")
    if text.startswith("sample:"):
        return resolve_input(text)
    p = Path(text).expanduser()
    p = p if p.is_absolute() else base / p
    if not p.exists():
        raise InputError(where, f"no such file or folder: {p}")
    return p


def read_manifest(path: str | Path) -> list[ValidationCase]:
    """The cases of a manifest CSV; clear errors name the file, row and column."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "no such manifest file")
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(path, f"cannot be read as UTF-8 text ({exc})") from None
    reader = csv.DictReader(line for line in text.splitlines() if not line.startswith("#"))
    header = [h.strip() for h in (reader.fieldnames or [])]
    unknown = sorted(set(header) - set(COLUMNS))
    if unknown:
        raise InputError(
            path, f"unknown columns {', '.join(unknown)}", f"columns: {', '.join(COLUMNS)}"
        )
    for need in ("id", "skull", "truth"):
        if need not in header:
            raise InputError(path, f"has no {need!r} column")
    rows = list(reader)
    if not rows:
        raise InputError(path, "has no cases (a header row and one row per case are needed)")
    cases: list[ValidationCase] = []
    seen: dict[str, str] = {}
    for i, row in enumerate(rows, start=2):
        where = f"{path.name} row {i}"
        cid = (row.get("id") or "").strip()
        if not cid:
            raise InputError(where, "has no id")
        cid = safe_id(cid, path, i, seen=seen, reserved=RESERVED)
        subject = (row.get("subject") or "").strip()
        problem = name_problem(subject) if subject else None
        if problem is not None:
            raise InputError(
                f"{where} column subject",
                f"{subject!r} cannot name the subject's reference folder: {problem}",
                "a subject follows the rules of an id",
            )
        vec = {
            k: _vector(row.get(k) or "", f"{where} column {k}")
            for k in ("anterior", "superior", "left")
        }
        orientation = None
        if vec["anterior"] is not None or vec["superior"] is not None:
            if vec["anterior"] is None or vec["superior"] is None:
                raise InputError(where, "give both anterior and superior, or neither")
            orientation = (vec["anterior"], vec["superior"]) + (
                (vec["left"],) if vec["left"] is not None else ()
            )
        try:
            mask = ScoreMask.parse(row.get("mask"))
        except ValueError as exc:
            raise InputError(f"{where} column mask", str(exc)) from None
        isos = {}
        for k in ("bone_iso", "skin_iso"):
            t = (row.get(k) or "").strip()
            try:
                isos[k] = float(t) if t else None
            except ValueError:
                raise InputError(f"{where} column {k}", f"{t!r} is not a number") from None
        build_text = (row.get("build") or "normal").strip() or "normal"
        build: str | float = build_text
        if build_text not in ("slender", "normal", "obese"):
            try:
                build = float(build_text)
            except ValueError:
                raise InputError(f"{where} column build", f"unknown build {build_text!r}") from None
        template = (row.get("template") or "").strip()
        orient = (row.get("orient") or "hint").strip() or "hint"
        if orient not in ("hint", "auto"):
            raise InputError(f"{where} column orient", f"{orient!r} is not hint or auto")
        skull = _resolve(row["skull"], path.parent, f"{where} column skull")
        truth = _resolve(row["truth"], path.parent, f"{where} column truth")
        _refuse_truth_is_skull(skull, truth, f"{where} column truth")
        marks = (row.get("truth_landmarks") or "").strip()
        cases.append(
            ValidationCase(
                cid,
                skull,
                truth,
                (row.get("units") or "auto").strip() or "auto",
                mask,
                orientation,
                (row.get("sex") or "male").strip() or "male",
                build,
                (row.get("tissue") or "table").strip() or "table",
                _resolve(template, path.parent, f"{where} column template") if template else None,
                isos["bone_iso"],
                isos["skin_iso"],
                subject,
                orient,
                _resolve(marks, path.parent, f"{where} column truth_landmarks") if marks else None,
            )
        )
    return cases


def _refuse_truth_is_skull(skull: Path, truth: Path, where: str) -> None:
    """Refuse a truth mesh that is the skull's file, or a file with the skull's bytes.

    A CT volume may be both (its bone and skin levels give the two surfaces).
    """
    from workbench.io.outputs import same_file

    if is_volume(skull) or is_volume(truth):
        return
    same = same_file(skull, truth)
    if not same:
        try:
            same = skull.stat().st_size == truth.stat().st_size and input_digest(
                skull
            ) == input_digest(truth)
        except OSError:
            same = False
    if same:
        raise InputError(
            where,
            f"the true skin {truth.name} is the skull {skull.name} itself (the same "
            + ("file" if same_file(skull, truth) else "bytes")
            + "); a reconstruction scored against bone measures nothing",
            "give the case's skin surface as its truth",
        )


def is_volume(path: Path) -> bool:
    """Whether ``path`` is a CT volume (a DICOM folder or a volume file), not a mesh."""
    name = path.name.lower()
    return path.is_dir() or any(name.endswith(s) for s in VOLUME_SUFFIXES)


def input_digest(path: Path) -> str:
    """SHA-256 of a file, or of a folder's files (names and contents, sorted)."""
    from workbench.model.evidence import sha256_file

    if path.is_dir():
        h = hashlib.sha256()
        for f in sorted(p for p in path.iterdir() if p.is_file()):
            h.update(f.name.encode())
            h.update(sha256_file(f)[0].encode())
        return h.hexdigest()
    return sha256_file(path)[0]
