"""The append-only audit log of a case.

Every ``do``, ``undo`` and ``redo`` of a command, and every save, appends one
record.  On disk the log is ``audit.jsonl``: one JSON object per line, UTF-8,
keys sorted.  Records already written to a case file are kept as their exact
bytes, so a later save writes them back byte-identical and only appends.

The log is not part of the undoable case state: undoing a command appends an
``undo`` record, it never removes the ``do`` record.

Record fields
-------------
time : str
    ISO 8601 UTC time.
examiner : str
    ``case.meta.examiner`` at the time.
action : str
    ``"do"``, ``"undo"``, ``"redo"``, ``"abort"`` or ``"save"``.
operation : str
    The command's label (what the user saw in the Edit menu).
command : str
    The command's class name (informative only; never used to build objects).
parameters : dict
    JSON parameters of the command (positions in mm, input frame).
table_ids : list of str
    Ids of data tables the operation used.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from workbench.model.meta import now_iso

ACTIONS = ("do", "undo", "redo", "abort", "save")


def make_record(
    action: str,
    operation: str,
    examiner: str,
    parameters: Mapping[str, Any] | None = None,
    table_ids: Iterable[str] = (),
    command: str = "",
) -> dict[str, Any]:
    """Build one audit record (see the module docstring for the fields)."""
    if action not in ACTIONS:
        raise ValueError(f"unknown audit action {action!r}")
    return {
        "time": now_iso(),
        "examiner": examiner,
        "action": action,
        "operation": operation,
        "command": command,
        "parameters": dict(parameters or {}),
        "table_ids": [str(t) for t in table_ids],
    }


def encode_record(record: Mapping[str, Any]) -> bytes:
    """One ``audit.jsonl`` line (with its newline) for ``record``."""
    text = json.dumps(record, sort_keys=True, ensure_ascii=False, allow_nan=False)
    return (text + "\n").encode("utf-8")


def parse_records(data: bytes) -> list[dict[str, Any]]:
    """Parse ``audit.jsonl`` bytes.

    Raises
    ------
    ValueError
        Naming the first bad line (not UTF-8, not JSON, not an object, or no
        final newline).
    """
    if data and not data.endswith(b"\n"):
        raise ValueError("the last audit record is cut off (no final newline)")
    records = []
    for number, line in enumerate(data.splitlines(), start=1):
        try:
            record = json.loads(line.decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError) as error:
            raise ValueError(f"audit line {number} is not valid JSON: {error}") from None
        if not isinstance(record, dict):
            raise ValueError(f"audit line {number} is not a JSON object")
        records.append(record)
    return records


class AuditLog:
    """Append-only list of audit records.

    Parameters
    ----------
    persisted : bytes
        ``audit.jsonl`` bytes already stored in a case file.
    """

    def __init__(self, persisted: bytes = b"") -> None:
        self._persisted_bytes = bytes(persisted)
        self._records = parse_records(self._persisted_bytes)
        self._n_persisted = len(self._records)

    def __len__(self) -> int:
        return len(self._records)

    @property
    def records(self) -> tuple[dict[str, Any], ...]:
        """Every record, oldest first (copies)."""
        return tuple(json.loads(json.dumps(r)) for r in self._records)

    @property
    def pending(self) -> tuple[dict[str, Any], ...]:
        """Records not yet written to a case file."""
        return self.records[self._n_persisted :]

    @property
    def persisted_bytes(self) -> bytes:
        """The exact ``audit.jsonl`` bytes of the records already saved."""
        return self._persisted_bytes

    def append(self, record: Mapping[str, Any]) -> None:
        """Append a record; it must be JSON-able (checked now, not at save time)."""
        line = encode_record(record)
        self._records.append(json.loads(line))

    def __call__(self, record: Mapping[str, Any]) -> None:
        self.append(record)

    def encode(self, extra: Sequence[Mapping[str, Any]] = ()) -> bytes:
        """Persisted bytes + pending records + ``extra``, as ``audit.jsonl`` bytes."""
        tail = [*self._records[self._n_persisted :], *extra]
        return self._persisted_bytes + b"".join(encode_record(r) for r in tail)

    def mark_persisted(self, data: bytes, extra: Sequence[Mapping[str, Any]] = ()) -> None:
        """Record that ``data`` (from :meth:`encode` with ``extra``) is now on disk."""
        for record in extra:
            self.append(record)
        self._persisted_bytes = bytes(data)
        self._n_persisted = len(self._records)
