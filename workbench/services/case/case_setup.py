"""Start a case from a skull (mesh file or CT surface) and report on saved cases.

Opening a skull is one undoable step: the original file becomes evidence
(bytes kept, SHA-256 recorded) and a working copy in millimetres becomes the
specimen.  The original is never modified; unit conversion applies only to
the working copy, and the evidence record notes it.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from os import PathLike
from pathlib import Path
from typing import Any

import numpy as np

from workbench.commands.case_edits import AddEvidence, SetSpecimen
from workbench.commands.landmarks import ReplaceLandmarkSet
from workbench.commands.stack import CommandStack
from workbench.core.errors import InputError
from workbench.core.mesh import Mesh, validate
from workbench.core.units import check_units_choice, resolve_units
from workbench.io.case_file import load_case
from workbench.io.catalogue import load_catalogue
from workbench.io.markups import read_landmarks
from workbench.io.meshes import read_mesh
from workbench.model.case import Case
from workbench.model.evidence import EvidenceFile
from workbench.model.meta import CaseMeta
from workbench.model.state import thaw_json
from workbench.services.case.input_checks import (
    check_landmark_geometry,
    check_landmarks_on_skull,
    check_skull_mesh,
)


@dataclass
class OpenedCase:
    """A new case with its command stack and notes for the user."""

    case: Case
    stack: CommandStack
    notes: list[str] = field(default_factory=list)


def start_case_from_skull(
    skull_path: str | PathLike[str],
    *,
    units: str = "auto",
    scale: float | None = None,
    examiner: str = "",
    landmarks_path: str | PathLike[str] | None = None,
    on_read: Callable[[Mesh], None] | None = None,
) -> OpenedCase:
    """New case whose specimen is the skull mesh at ``skull_path``.

    Parameters
    ----------
    skull_path : path
        Skull surface (PLY, STL, OBJ, VTK, VTP); kept byte-for-byte as evidence.
    units, scale
        Units of the file (see :func:`workbench.io.meshes.read_mesh`); with
        ``"auto"`` a file whose size does not look like mm is refused with an
        explanation (``UnitsError``).
    examiner : str
        Name recorded in the case and the audit log.
    landmarks_path : path, optional
        Skull landmarks to import (``.mrk.json``, ``.fcsv``, ``.pp``, ``.csv``),
        in the same frame and units as the skull file.
    on_read : callable, optional
        Called with the skull mesh (mm) once it is read and its units and shape are
        accepted, before the slower checks and the case set-up: the reconstruction
        job starts its working skull's decimation there.
    """
    path = Path(skull_path)
    check_units_choice(units, scale)
    read = read_mesh(path, units=units if scale is None else "auto", scale=scale, kind="skull")
    if scale is None and units == "auto":
        resolve_units(read.units, "auto", source=str(path))
    check_skull_mesh(read.mesh, path, units_note=read.units.confirmed)
    if on_read is not None:
        on_read(read.mesh)
    factor = read.scale_applied
    units_note = "millimetres" if factor == 1.0 else f"file units x {factor:g} = mm"
    case = Case(meta=CaseMeta.new(examiner=examiner))
    stack = CommandStack(case)
    notes = list(read.messages)
    report = validate(read.mesh)
    notes += [f"skull mesh: {p}" for p in report.problems()]
    with stack.group(f"Open skull {path.name}"):
        stack.push(
            AddEvidence(evidence=EvidenceFile.from_path(path, "skull_mesh", units_note=units_note))
        )
        stack.push(SetSpecimen(mesh=read.mesh, units="mm"))
        if landmarks_path is not None:
            result = read_landmarks(landmarks_path, "skull", catalogue=load_catalogue())
            _refuse_unusable_points(result, landmarks_path)
            landmarks = result.landmarks
            if read.space == "LPS" and str(landmarks_path).lower().endswith(".pp"):
                # MeshLab's points are the mesh file's own numbers; the mesh was read turned
                # from LPS into RAS, and so are they (Slicer's files say their own system)
                landmarks = landmarks.transformed(np.diag([-1.0, -1.0, 1.0, 1.0]))
                notes.append(f"{Path(landmarks_path).name}: turned with the mesh (SPACE=LPS)")
            if factor != 1.0:
                landmarks = landmarks.transformed(_scale_matrix(factor))
            check_landmark_geometry(landmarks, landmarks_path)
            check_landmarks_on_skull(read.mesh, landmarks, landmarks_path)
            notes += list(result.messages)
            stack.push(
                AddEvidence(evidence=EvidenceFile.from_path(landmarks_path, "skull_landmarks"))
            )
            stack.push(
                ReplaceLandmarkSet(
                    surface="skull",
                    new_set=landmarks,
                    label=f"Import landmarks {Path(landmarks_path).name}",
                )
            )
    stack.set_clean()
    return OpenedCase(case, stack, notes)


def _refuse_unusable_points(result: Any, path: str | PathLike[str]) -> None:
    """Unknown or repeated codes in a landmark file given for a case are refused.

    The reader skips them with a note; for evidence imported into a case a
    skipped point is a silent loss, so the user fixes the file first.
    """
    problems = []
    if result.unknown:
        problems.append(f"unknown skull landmark codes: {', '.join(result.unknown)}")
    if result.duplicates:
        problems.append(f"duplicate codes: {', '.join(result.duplicates)} (given twice)")
    if problems:
        raise InputError(
            path,
            "; ".join(problems),
            "use the codes of data_tables/landmarks/catalogue.csv, one point per "
            "code ('workbench landmarks check' lists them)",
        )


def _scale_matrix(factor: float) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] *= factor
    return m


def describe_case(path: str | PathLike[str], *, allow_tampered: bool = False) -> dict[str, Any]:
    """JSON-able summary of a saved case: meta, evidence check, specimen, landmarks, audit.

    ``audit_chain["status"]`` is ``"verified (N records)"``, ``"NOT VERIFIED: ..."``
    (naming the first bad record; only with ``allow_tampered``, else loading
    refuses) or ``"audit log predates the hash chain (not verifiable)"``.
    """
    loaded = load_case(path, allow_tampered=allow_tampered)
    case = loaded.case
    specimen = case.specimen
    landmarks = {
        surface: {
            "defined": [lm.code for lm in lmset if lm.is_defined],
            "absent": [lm.code for lm in lmset if lm.status == "absent"],
        }
        for surface, lmset in case.landmarks.items()
    }
    return {
        "file": str(path),
        "case_id": case.meta.case_id,
        "examiner": case.meta.examiner,
        "created": case.meta.created,
        "modified": case.meta.modified,
        "software_version": case.meta.software_version,
        "evidence": [
            {
                "name": e.name,
                "role": e.role,
                "sha256": e.sha256,
                "size": e.size,
                "units_note": e.units_note,
                "status": loaded.evidence_status.get(f"evidence/{e.name}", "?"),
            }
            for e in case.evidence
        ],
        "tampered": loaded.tampered,
        "audit_chain": loaded.audit_chain.to_json(),
        "specimen": None
        if specimen.mesh is None
        else {
            "n_vertices": specimen.mesh.n_vertices,
            "n_faces": specimen.mesh.n_faces,
            "units": specimen.units,
            "extent_mm": specimen.mesh.extent.tolist(),
            "head_frame_set": specimen.input_to_head is not None,
        },
        "landmarks": landmarks,
        "dowels": case.dowels.to_state(),
        "orientation": None if case.orientation is None else case.orientation.to_state(),
        "guides": None if case.guides is None else list(case.guides.ids),
        "parameters": thaw_json(case.parameters),  # nested values are frozen mappings
        "audit": [
            {k: r.get(k) for k in ("time", "action", "operation", "examiner") if k in r}
            for r in loaded.audit_records
        ],
    }
