"""Case metadata: who examined what, when, with which software."""

from __future__ import annotations

import uuid
from dataclasses import asdict, dataclass, fields, replace
from datetime import UTC, datetime
from typing import Any

import workbench


def now_iso() -> str:
    """Current UTC time as ISO 8601 with milliseconds, e.g. ``2025-01-31T12:00:00.000+00:00``."""
    return datetime.now(UTC).isoformat(timespec="milliseconds")


@dataclass(frozen=True)
class CaseMeta:
    """Identity and bookkeeping of one case.

    Parameters
    ----------
    case_id : str
        Random UUID (version 4) string; never changes for the life of a case.
    examiner : str
        Name of the person responsible for the case.
    created, modified : str
        ISO 8601 times (UTC).  ``modified`` is updated when the case is saved.
    software_version : str
        ``workbench.__version__`` of the software that created the case.
    notes : str
        Free text.
    """

    case_id: str
    examiner: str = ""
    created: str = ""
    modified: str = ""
    software_version: str = ""
    notes: str = ""

    def __post_init__(self) -> None:
        for f in fields(self):
            if not isinstance(getattr(self, f.name), str):
                raise TypeError(f"case meta field {f.name!r} must be a string")
        try:
            uuid.UUID(self.case_id)
        except ValueError:
            raise ValueError(f"case_id {self.case_id!r} is not a UUID") from None

    @classmethod
    def new(cls, examiner: str = "", notes: str = "") -> CaseMeta:
        """Fresh metadata: new uuid4, created = modified = now, current version."""
        now = now_iso()
        return cls(
            case_id=str(uuid.uuid4()),
            examiner=examiner,
            created=now,
            modified=now,
            software_version=workbench.__version__,
            notes=notes,
        )

    def with_examiner(self, examiner: str) -> CaseMeta:
        return replace(self, examiner=examiner)

    def touched(self, when: str | None = None) -> CaseMeta:
        """Copy with ``modified`` set to ``when`` (default: now)."""
        return replace(self, modified=when or now_iso())

    def to_state(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_state(cls, state: dict[str, Any]) -> CaseMeta:
        names = [f.name for f in fields(cls)]
        unknown = sorted(set(state) - set(names))
        if unknown:
            raise ValueError(f"unknown case meta fields: {', '.join(unknown)}")
        return cls(**{name: state[name] for name in names if name in state})

    def equals(self, other: CaseMeta) -> bool:
        return self == other
