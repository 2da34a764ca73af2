"""The Case document: the root of everything a user edits and saves.

A :class:`Case` is a small set of named *parts*, each an immutable value:

=========== ==================================================================
part        value
=========== ==================================================================
meta        :class:`~workbench.model.meta.CaseMeta`
evidence    tuple of :class:`~workbench.model.evidence.EvidenceFile` (visible)
specimen    :class:`~workbench.model.specimen.Specimen`
landmarks   read-only ``{surface: LandmarkSet}`` for ``"skull"`` and ``"skin"``
dowels      :class:`~workbench.model.reconstruction_setup.DowelSettings` (depth
            table, sex, build, overrides, exclusions, tissue model)
orientation :class:`~workbench.model.reconstruction_setup.Orientation` of the
            skull file, or ``None`` (found from the bone)
guides      :class:`~workbench.model.reconstruction_setup.GuideList` set by the
            user, or ``None`` (computed from the skull)
age_study   :class:`~workbench.model.age_study.AgeStudy` kept from the Age
            progression dock, or ``None`` (no study)
appearance  :class:`~workbench.model.appearance.Appearance`: the colours chosen
            for the face (artistic, not evidence), or ``None`` (none chosen);
            optional in the file (absent when ``None``)
parameters  read-only ``{str: JSON value}``: other settings and provenance of
            results (template id and hash, depth group)
=========== ==================================================================

Parts are replaced, never mutated in place (:meth:`Case.replace`), so a
command can keep the previous value by reference for undo and views can
compare by identity.  Every replacement emits ``case.events.changed(part)``.

Each part has ``to_state`` / ``from_state`` through the explicit registry
:data:`PARTS`; ``Case.from_state(case.to_state())`` equals the case.  New
features add a registry entry (a typed part with its own commands) or, for
loose values, a ``parameters`` key; never a class name in the file.

Three things travel with a case but are *not* part of its undoable state:
``audit`` (the append-only :class:`~workbench.model.audit.AuditLog`),
``retained_evidence`` (every evidence file ever added, so its bytes stay in
the case file even after ``AddEvidence`` is undone) and ``derived``: results
computed from the parts (the fitted face), ``{name: plain state}`` with
arrays, kept so a reopened case shows them at once.  A derived state records
the digest of the inputs it was computed from, so a reader can tell whether
it still belongs to the parts (see
:mod:`workbench.services.reconstruction.stored_fit`); it is never evidence and
never edited by a command.

Notes
-----
Units and frames are fixed here, once:

- Lengths are millimetres.  Angles are radians inside :mod:`workbench.core`
  and degrees only at the UI.
- Landmark positions are stored in the specimen's **input frame**, the frame
  of the working mesh as imported.
- The **head frame** has x toward the subject's left (x = 0 on the
  midsagittal plane), y up and z toward the face, with the Frankfort
  Horizontal plane horizontal.  It is stored once, as the 4x4 homogeneous
  transform ``specimen.input_to_head`` from the input frame (``None`` until
  set); head-frame positions are derived, never stored twice.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

from psygnal import Signal

from workbench.core.errors import WorkbenchError
from workbench.core.landmarks import LandmarkSet
from workbench.model.age_study import AgeStudy, age_study_from_state, age_study_to_state
from workbench.model.appearance import Appearance, appearance_from_state, appearance_to_state
from workbench.model.audit import AuditLog
from workbench.model.evidence import (
    EvidenceFile,
    coerce_evidence,
    evidence_from_state,
    evidence_to_state,
)
from workbench.model.landmarks import (
    coerce_landmarks,
    empty_landmarks,
    landmarks_from_state,
    landmarks_to_state,
)
from workbench.model.meta import CaseMeta
from workbench.model.reconstruction_setup import (
    DowelSettings,
    GuideList,
    Orientation,
    guides_from_state,
    optional_to_state,
    orientation_from_state,
)
from workbench.model.specimen import Specimen
from workbench.model.state import freeze_json, states_equal, thaw_json


class EvidenceConflictError(WorkbenchError):
    """Two different evidence files would share one name in the case file."""


def _check_type(cls: type) -> Callable[[Any], Any]:
    def check(value: Any) -> Any:
        if not isinstance(value, cls):
            raise TypeError(f"expected {cls.__name__}, got {type(value).__name__}")
        return value

    return check


def _check_optional(cls: type) -> Callable[[Any], Any]:
    check = _check_type(cls)
    return lambda value: None if value is None else check(value)


@dataclass(frozen=True)
class PartCodec:
    """How one part is validated, defaulted and turned into state and back.

    ``has_arrays`` tells the case file that the state may hold numpy arrays.
    ``optional``: the case file leaves the part out while it holds its default
    and reads a file without it as the default (a part added without a new
    format version, so files written before it still open, and files that
    never use it still open in the versions before it).
    """

    coerce: Callable[[Any], Any]
    to_state: Callable[[Any], Any]
    from_state: Callable[[Any], Any]
    default: Callable[[], Any]
    has_arrays: bool = False
    optional: bool = False


#: The explicit registry of parts.  Order is the order of ``to_state()``.
PARTS: Mapping[str, PartCodec] = MappingProxyType(
    {
        "meta": PartCodec(
            _check_type(CaseMeta), CaseMeta.to_state, CaseMeta.from_state, CaseMeta.new
        ),
        "evidence": PartCodec(coerce_evidence, evidence_to_state, evidence_from_state, tuple),
        "specimen": PartCodec(
            _check_type(Specimen), Specimen.to_state, Specimen.from_state, Specimen, True
        ),
        "landmarks": PartCodec(
            coerce_landmarks, landmarks_to_state, landmarks_from_state, empty_landmarks
        ),
        "dowels": PartCodec(
            _check_type(DowelSettings),
            DowelSettings.to_state,
            DowelSettings.from_state,
            DowelSettings,
        ),
        "orientation": PartCodec(
            _check_optional(Orientation), optional_to_state, orientation_from_state, lambda: None
        ),
        "guides": PartCodec(
            _check_optional(GuideList), optional_to_state, guides_from_state, lambda: None
        ),
        "age_study": PartCodec(
            _check_optional(AgeStudy), age_study_to_state, age_study_from_state, lambda: None
        ),
        "appearance": PartCodec(
            _check_optional(Appearance),
            appearance_to_state,
            appearance_from_state,
            lambda: None,
            optional=True,
        ),
        "parameters": PartCodec(
            lambda v: freeze_json(v, "parameters"),
            thaw_json,
            lambda s: freeze_json(s, "parameters"),
            lambda: MappingProxyType({}),
        ),
    }
)


class CaseEvents:
    """Signals of a case.  ``changed(part_name)`` fires after a part is replaced."""

    changed = Signal(str)


class Case:
    """The root document; see the module docstring.

    Parameters
    ----------
    **parts
        Initial part values by name (see :data:`PARTS`); missing parts get
        their defaults (a fresh :class:`CaseMeta`, no evidence, empty
        specimen, empty landmark sets, default dowel settings, automatic
        orientation, computed guides, no age study, no colours, no
        parameters).
    """

    def __init__(self, **parts: Any) -> None:
        unknown = sorted(set(parts) - set(PARTS))
        if unknown:
            raise TypeError(f"unknown case parts: {', '.join(unknown)}")
        self.events = CaseEvents()
        self.audit = AuditLog()
        self.source_path: Path | None = None
        #: derived results kept with the case (see the module docstring): name → plain state
        self.derived: dict[str, Mapping[str, Any]] = {}
        self._parts: dict[str, Any] = {}
        self._retained: dict[str, EvidenceFile] = {}
        for name, codec in PARTS.items():
            value = parts[name] if name in parts else codec.default()
            self._parts[name] = codec.coerce(value)
        for item in self._parts["evidence"]:
            self.retain_evidence(item)

    # ------------------------------------------------------------ parts
    @property
    def meta(self) -> CaseMeta:
        return self._parts["meta"]

    @property
    def evidence(self) -> tuple[EvidenceFile, ...]:
        return self._parts["evidence"]

    @property
    def specimen(self) -> Specimen:
        return self._parts["specimen"]

    @property
    def landmarks(self) -> Mapping[str, LandmarkSet]:
        return self._parts["landmarks"]

    @property
    def dowels(self) -> DowelSettings:
        return self._parts["dowels"]

    @property
    def orientation(self) -> Orientation | None:
        return self._parts["orientation"]

    @property
    def guides(self) -> GuideList | None:
        return self._parts["guides"]

    @property
    def age_study(self) -> AgeStudy | None:
        return self._parts["age_study"]

    @property
    def appearance(self) -> Appearance | None:
        return self._parts["appearance"]

    @property
    def parameters(self) -> Mapping[str, Any]:
        return self._parts["parameters"]

    def part(self, name: str) -> Any:
        """The current value of part ``name``."""
        if name not in PARTS:
            raise KeyError(f"no case part {name!r}")
        return self._parts[name]

    def replace(self, name: str, value: Any) -> None:
        """Replace part ``name`` by ``value`` (validated) and emit ``changed(name)``."""
        if name not in PARTS:
            raise KeyError(f"no case part {name!r}")
        value = PARTS[name].coerce(value)
        if name == "evidence":
            for item in value:
                self._check_name_free(item)
            for item in value:
                self.retain_evidence(item)
        self._parts[name] = value
        self.events.changed.emit(name)

    def set_landmark_set(self, landmarks: LandmarkSet) -> None:
        """Replace the landmark set of ``landmarks.surface``."""
        self.replace("landmarks", {**self.landmarks, landmarks.surface: landmarks})

    # ------------------------------------------------------------ evidence store
    @property
    def retained_evidence(self) -> Mapping[str, EvidenceFile]:
        """Every evidence file ever referenced, by name (append-only)."""
        return MappingProxyType(dict(self._retained))

    def retain_evidence(self, item: EvidenceFile) -> None:
        """Remember ``item`` so its bytes stay in the case file for good.

        Raises
        ------
        EvidenceConflictError
            If a different file with the same name was retained before.
        """
        self._check_name_free(item)
        self._retained.setdefault(item.name, item)

    def _check_name_free(self, item: EvidenceFile) -> None:
        known = self._retained.get(item.name)
        if known is not None and (known.sha256, known.size) != (item.sha256, item.size):
            raise EvidenceConflictError(
                f"evidence name {item.name!r} is already used by a different file "
                f"(sha256 {known.sha256[:12]}...); choose another name"
            )

    def unused_evidence_name(self, name: str) -> str:
        """``name``, or ``stem-2.ext``, ``stem-3.ext``... if it is already retained."""
        candidate, stem, suffix, n = name, Path(name).stem, Path(name).suffix, 1
        while candidate in self._retained:
            n += 1
            candidate = f"{stem}-{n}{suffix}"
        return candidate

    # ------------------------------------------------------------ state
    def to_state(self) -> dict[str, Any]:
        """``{part: state}``; arrays appear as read-only numpy arrays."""
        return {name: codec.to_state(self._parts[name]) for name, codec in PARTS.items()}

    @classmethod
    def from_state(cls, state: Mapping[str, Any]) -> Case:
        """Build a case from :meth:`to_state` output (every part required)."""
        missing = [name for name in PARTS if name not in state]
        unknown = sorted(set(state) - set(PARTS))
        if missing or unknown:
            raise ValueError(
                f"case state: missing parts {missing or 'none'}, unknown parts {unknown or 'none'}"
            )
        return cls(**{name: codec.from_state(state[name]) for name, codec in PARTS.items()})

    def equals(self, other: Case) -> bool:
        """Same state in every part (audit log and retained evidence not compared)."""
        return states_equal(self.to_state(), other.to_state())

    def __repr__(self) -> str:
        n_lm = {s: len(v) for s, v in self.landmarks.items()}
        return (
            f"Case(id={self.meta.case_id[:8]}, examiner={self.meta.examiner!r}, "
            f"evidence={len(self.evidence)}, landmarks={n_lm})"
        )
