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

Hash chain
----------
Records written by a case file also carry two chain fields (added when they
are first written, see :meth:`AuditLog.encode`; :attr:`AuditLog.records`
leaves them out):

seq : int
    The record's position in the log, from 0.
prev : str
    SHA-256 (hex) of the previous record's canonical encoding
    (:func:`encode_record`: the JSON line with keys sorted, chain fields
    included, and its newline).  The first chained record's ``prev`` is
    :func:`genesis`: SHA-256 of ``"forensic-workbench audit chain v1"``,
    the case id and the canonical lines of any records that predate the
    chain (logs written before the chain existed), so a log is bound to its
    case and an older prefix is sealed as one block.

The case file anchors the head (:func:`chain_anchor`: hash of the last
record, record count, count of records that predate the chain) in
``case.json``; :func:`verify_chain` checks a log against it and names the
first bad record.  The chain shows edits made without recomputing it; it is
not a signature (whoever knows this scheme can rebuild a consistent log).

Content seal
------------
The last record of every write (the ``save`` record of a save, the last new
record of an autosave snapshot) also carries

content_sha256 : str
    :func:`content_digest` of the ``case.json`` written with it: SHA-256 of
    the document's canonical JSON (keys sorted, no spaces, ASCII) without
    its ``audit_chain`` anchor.  The anchor is the only part left out: it
    holds the hash of this very record, so it cannot be inside it; it is
    checked by the chain instead.  Nothing else in ``case.json`` changes
    without a write, so everything else is sealed (``meta.modified`` and
    ``software`` are set before the digest is taken).

Because the seal is inside the chained record, and the anchor pins that
record, editing ``case.json`` by hand (a landmark moved, the examiner
renamed) shows at open (:func:`verify_content`) unless the editor also
rewrites the record and the anchor.  Logs written before the seal existed
end in a record without it: their content is "not sealed", which is not an
integrity failure but is not "verified" either.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from workbench.core.json_limits import MAX_JSON_DEPTH, nesting_depth
from workbench.model.meta import now_iso

ACTIONS = ("do", "undo", "redo", "abort", "save")
SEAL_FIELD = "content_sha256"
CHAIN_FIELDS = (SEAL_FIELD, "prev", "seq")
GENESIS_TAG = b"forensic-workbench audit chain v1"
#: the ``case.json`` key left out of :func:`content_digest` (it pins the sealing record)
ANCHOR_KEY = "audit_chain"
#: nesting accepted in one audit line (records are 3 deep; user parameters add some)
MAX_RECORD_DEPTH = MAX_JSON_DEPTH


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
        if (
            line.count(b"[") + line.count(b"{") > MAX_RECORD_DEPTH
            and nesting_depth(line) > MAX_RECORD_DEPTH
        ):
            raise ValueError(
                f"audit line {number} nests more than {MAX_RECORD_DEPTH} levels deep "
                "(no workbench record does)"
            )
        try:
            record = json.loads(line.decode("utf-8"))
        except (UnicodeDecodeError, json.JSONDecodeError, RecursionError) as error:
            raise ValueError(f"audit line {number} is not valid JSON: {error}") from None
        if not isinstance(record, dict):
            raise ValueError(f"audit line {number} is not a JSON object")
        records.append(record)
    return records


def record_hash(record: Mapping[str, Any]) -> str:
    """SHA-256 (hex) of ``record``'s canonical encoding (:func:`encode_record`)."""
    return hashlib.sha256(encode_record(record)).hexdigest()


def content_digest(doc: Mapping[str, Any]) -> str:
    """SHA-256 (hex) of a ``case.json`` document's canonical JSON, without its anchor.

    Canonical: keys sorted, no whitespace, non-ASCII escaped, so the digest
    depends on the content only, not on how the file was indented.  ``doc``
    must be what :func:`json.loads` gives for the stored text (lists, not
    tuples; string keys), before any migration.

    Raises
    ------
    ValueError
        ``doc`` holds NaN or infinity, or a value JSON cannot hold.
    """
    body = {key: value for key, value in doc.items() if key != ANCHOR_KEY}
    try:
        text = json.dumps(body, sort_keys=True, separators=(",", ":"), allow_nan=False)
    except TypeError as error:
        raise ValueError(f"case.json content is not plain JSON ({error})") from None
    return hashlib.sha256(text.encode("ascii")).hexdigest()


@dataclass(frozen=True)
class ContentSeal:
    """Result of :func:`verify_content`: does ``case.json`` hold what the workbench sealed?

    Attributes
    ----------
    state : str
        ``"verified"``, ``"unsealed"`` (written by a version without the seal)
        or ``"changed"`` (edited outside the workbench after its last write).
    sealed_at : str
        Time of the record carrying the seal (``""`` when unsealed).
    problem : str
        What is wrong, one sentence (``"changed"`` only).
    sealed, found : str
        The sealed digest and the digest of the ``case.json`` found.
    """

    state: str
    sealed_at: str = ""
    problem: str = ""
    sealed: str = ""
    found: str = ""

    @property
    def ok(self) -> bool:
        """Not changed (unsealed content is unverifiable, not a failure)."""
        return self.state != "changed"

    def summary(self) -> str:
        if self.state == "verified":
            return f"verified (case.json is as the workbench wrote it at {self.sealed_at})"
        if self.state == "unsealed":
            return "content not sealed (written by an older version)"
        return f"NOT VERIFIED: {self.problem}"

    def to_json(self) -> dict[str, Any]:
        return {
            "status": self.summary(),
            "state": self.state,
            "sealed_at": self.sealed_at or None,
            "sealed_sha256": self.sealed or None,
            "found_sha256": self.found or None,
        }


def _write_label(record: Mapping[str, Any]) -> str:
    time = record.get("time", "an unknown time")
    if record.get("action") == "save":
        return f"the last recorded save at {time}"
    what = " ".join(str(record.get(k)) for k in ("action", "operation") if record.get(k))
    return f"the workbench last wrote it (autosave after '{what or 'an edit'}' at {time})"


def verify_content(
    records: Sequence[Mapping[str, Any]], digest: str, migrated: str = ""
) -> ContentSeal:
    """Check the :func:`content_digest` of a case's ``case.json`` against its log's seal.

    ``records`` is the parsed ``audit.jsonl`` (chain fields included).  The
    seal is the :data:`SEAL_FIELD` of the last record.  ``digest`` is the
    digest of the document as stored; ``migrated`` (optional) that of the
    document upgraded to the current format, which is accepted as well: a
    document rewritten in an older layout whose upgrade gives exactly the
    sealed content holds the same case (any other change shows in both).
    """
    if not records or SEAL_FIELD not in records[-1]:
        return ContentSeal("unsealed", found=digest)
    last = records[-1]
    seal = last[SEAL_FIELD]
    when = str(last.get("time", ""))
    if isinstance(seal, str) and seal in (digest, migrated):
        return ContentSeal("verified", when, sealed=seal, found=seal)
    return ContentSeal(
        "changed",
        when,
        f"case.json was changed outside the workbench after {_write_label(last)} "
        f"(sealed sha256 {str(seal)[:12]}…, found {digest[:12]}…)",
        sealed=str(seal),
        found=digest,
    )


def genesis(case_id: str, older: Sequence[Mapping[str, Any]] = ()) -> str:
    """The ``prev`` of a case's first chained record.

    SHA-256 of the tag, the case id and the canonical lines of the ``older``
    records (those written before the chain existed, which carry no ``prev``).
    """
    digest = hashlib.sha256(GENESIS_TAG + b"\0" + case_id.encode("utf-8") + b"\0")
    for record in older:
        digest.update(encode_record(record))
    return digest.hexdigest()


def chain_anchor(records: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    """What ``case.json`` stores to pin a log: head hash, record count, unchained prefix."""
    older = next((i for i, r in enumerate(records) if "prev" in r), len(records))
    head = record_hash(records[-1]) if records else ""
    return {"head": head, "records": len(records), "unchained": older}


@dataclass(frozen=True)
class ChainStatus:
    """Result of :func:`verify_chain`.

    Attributes
    ----------
    state : str
        ``"verified"``, ``"unchained"`` (the log predates the hash chain and
        cannot be checked) or ``"broken"``.
    records : int
        Records in the log.
    unchained : int
        Leading records that predate the chain (checked only as one block).
    index : int or None
        First bad record (``"broken"`` only; may equal ``records`` for a
        record missing at the end).
    problem : str
        What is wrong, one sentence (``"broken"`` only).
    content : ContentSeal or None
        The content seal's check (:func:`verify_content`), when the case file
        made it; reported with the chain, not part of :meth:`summary`.
    """

    state: str
    records: int
    unchained: int = 0
    index: int | None = None
    problem: str = ""
    content: ContentSeal | None = None

    @property
    def ok(self) -> bool:
        """Not broken (a log that predates the chain is not an integrity failure)."""
        return self.state != "broken"

    def summary(self) -> str:
        if self.state == "unchained":
            return "audit log predates the hash chain (not verifiable)"
        if self.state == "broken":
            return f"NOT VERIFIED: {self.problem}"
        older = (
            f"; the first {self.unchained} predate the hash chain and are sealed as one block"
            if self.unchained
            else ""
        )
        return f"verified ({self.records} records{older})"

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "status": self.summary(),
            "state": self.state,
            "records": self.records,
            "unchained": self.unchained,
            "first_bad_record": self.index,
        }
        if self.content is not None:
            out["content"] = self.content.to_json()
        return out


def _name(records: Sequence[Mapping[str, Any]], index: int) -> str:
    if not 0 <= index < len(records):
        return f"record {index}"
    r = records[index]
    what = " ".join(str(r.get(k, "?")) for k in ("action", "operation") if r.get(k))
    return f"record {index} ({r.get('time', 'no time')}, {what or 'no action'})"


def _has_chain_fields(record: Mapping[str, Any]) -> bool:
    seq = record.get("seq")
    return (
        isinstance(record.get("prev"), str) and isinstance(seq, int) and not isinstance(seq, bool)
    )


def _broken(
    records: Sequence[Mapping[str, Any]], older: int, index: int, problem: str
) -> ChainStatus:
    return ChainStatus("broken", len(records), older, index, problem)


def verify_chain(
    records: Sequence[Mapping[str, Any]], case_id: str, anchor: Mapping[str, Any] | None
) -> ChainStatus:
    """Check ``records`` (parsed ``audit.jsonl``) against the chain and its ``anchor``.

    ``anchor`` is the ``case.json`` entry written by :func:`chain_anchor`, or
    ``None`` for a file written before the chain existed.
    """
    n = len(records)
    if anchor is None:
        chained = next((i for i, r in enumerate(records) if "prev" in r), None)
        if chained is None:
            return ChainStatus("unchained", n, n)
        return _broken(
            records,
            chained,
            chained,
            f"{_name(records, chained)} carries a chain "
            "hash but case.json has no audit chain anchor (it was removed)",
        )
    older = int(anchor["unchained"])
    for i in range(min(older, n)):
        if "prev" in records[i]:
            return _broken(
                records,
                older,
                i,
                f"{_name(records, i)} carries a chain hash but "
                f"the anchor says the first {older} records predate the chain",
            )
    links = [genesis(case_id, records[:older]) if n >= older else ""]
    links += [record_hash(r) for r in records[older:]]
    for i in range(older, n):
        record = records[i]
        if not _has_chain_fields(record):
            return _broken(
                records,
                older,
                i,
                f"{_name(records, i)} has no valid chain fields (edited or inserted)",
            )
        seq = record["seq"]
        if seq != i:
            return _broken(records, older, i, _order_problem(records, i, seq))
        if record["prev"] != links[i - older]:
            return _broken(records, older, *_edit_problem(records, older, i, links, anchor))
    expected = int(anchor["records"])
    if n < expected:
        last = f"; the log ends with {_name(records, n - 1)}" if n else ""
        return _broken(
            records,
            older,
            n,
            f"record {n} is missing: the anchor counts {expected} "
            f"records, the log has {n} (deleted at the end){last}",
        )
    if n > expected:
        return _broken(
            records,
            older,
            expected,
            f"{_name(records, expected)} was added after "
            f"the last save: the anchor counts {expected} records, the log has {n}",
        )
    if n and links[-1] != anchor["head"]:
        return _broken(
            records,
            older,
            n - 1,
            f"{_name(records, n - 1)} was edited, or the "
            "anchor in case.json was: the last record's hash does not match it",
        )
    return ChainStatus("verified", n, older)


def _order_problem(records: Sequence[Mapping[str, Any]], i: int, seq: int) -> str:
    """Why the record at position ``i`` carries sequence number ``seq``."""
    if seq < i:
        return (
            f"{_name(records, i)} was inserted or duplicated: it claims the position of "
            f"record {seq}"
        )
    later = next((j for j in range(i + 1, len(records)) if records[j].get("seq") == i), None)
    if later is not None:
        return (
            f"records reordered: {_name(records, i)} was written as record {seq}, and "
            f"the one written as record {i} is now at position {later}"
        )
    return (
        f"record {i} is missing (deleted): position {i} holds "
        f"{_name(records, i)}, written as record {seq}"
    )


def _edit_problem(
    records: Sequence[Mapping[str, Any]],
    older: int,
    i: int,
    links: Sequence[str],
    anchor: Mapping[str, Any],
) -> tuple[int, str]:
    """The record at ``i`` does not follow its predecessor: which one changed."""
    if i + 1 < len(records):
        next_ok = records[i + 1].get("prev") == links[i + 1 - older]
    else:
        next_ok = links[-1] == anchor["head"]
    if not next_ok:
        return i, f"{_name(records, i)} was edited (its chain hash does not match)"
    if i == 0:
        return i, (
            f"{_name(records, i)} does not start this case's chain (the log was "
            "copied from another case, or the case id was changed)"
        )
    if i == older:
        return i - 1, (
            f"the first {older} records, which predate the chain, were edited, "
            f"reordered or deleted (up to {_name(records, i - 1)})"
        )
    return i - 1, (
        f"{_name(records, i - 1)} was edited: its hash does not match the next record's prev"
    )


class AuditLog:
    """Append-only list of audit records.

    Parameters
    ----------
    persisted : bytes
        ``audit.jsonl`` bytes already stored in a case file.
    case_id : str, optional
        The case the log belongs to; it sets the chain's :func:`genesis`.  The
        case file sets it before writing (a log with no chained record yet
        cannot be encoded for a file without it).

    Attributes
    ----------
    content_problem : str
        Why the case's content failed its seal when it was opened (empty if
        it did not); the case file refuses to seal such a case again.
    """

    def __init__(self, persisted: bytes = b"", case_id: str | None = None) -> None:
        self._persisted_bytes = bytes(persisted)
        self._records = parse_records(self._persisted_bytes)
        self._n_persisted = len(self._records)
        self.case_id = case_id
        #: set by the case file when the case's ``case.json`` failed its content seal
        #: (:func:`verify_content`); a log carrying it is never sealed again
        self.content_problem = ""

    def __len__(self) -> int:
        return len(self._records)

    @property
    def records(self) -> tuple[dict[str, Any], ...]:
        """Every record, oldest first (copies, without the chain fields)."""
        return tuple(
            json.loads(json.dumps({k: v for k, v in r.items() if k not in CHAIN_FIELDS}))
            for r in self._records
        )

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

    def copy(self) -> AuditLog:
        """An independent log: the same saved bytes, pending records still pending.

        Records are never changed in place, so they are shared, not copied.
        """
        other = AuditLog(case_id=self.case_id)
        other._persisted_bytes = self._persisted_bytes
        other._records = list(self._records)
        other._n_persisted = self._n_persisted
        other.content_problem = self.content_problem
        return other

    def _last_link(self) -> str:
        """The ``prev`` of the next record written after the persisted ones."""
        persisted = self._records[: self._n_persisted]
        if persisted and "prev" in persisted[-1]:
            return record_hash(persisted[-1])
        return genesis(self.case_id or "", persisted)

    def encode(self, extra: Sequence[Mapping[str, Any]] = (), content: str | None = None) -> bytes:
        """Persisted bytes + pending records + ``extra``, as ``audit.jsonl`` bytes.

        Pending and extra records are chained here (``seq`` and ``prev``, see
        the module docstring); the persisted bytes are kept as they are.
        ``content`` (a :func:`content_digest`) seals the last new record; with
        no new record the last persisted one keeps the seal it was written with.
        """
        link, lines = self._last_link(), []
        tail = [*self._records[self._n_persisted :], *extra]
        last = self._n_persisted + len(tail) - 1
        for seq, record in enumerate(tail, start=self._n_persisted):
            chained = {k: v for k, v in record.items() if k not in CHAIN_FIELDS}
            if content is not None and seq == last:
                chained[SEAL_FIELD] = content
            line = encode_record({**chained, "prev": link, "seq": seq})
            link = hashlib.sha256(line).hexdigest()
            lines.append(line)
        return self._persisted_bytes + b"".join(lines)

    def mark_persisted(self, data: bytes, extra: Sequence[Mapping[str, Any]] = ()) -> None:
        """Record that ``data`` (from :meth:`encode` with ``extra``) is now on disk."""
        written = parse_records(data)
        n_pending = len(written) - len(extra) - self._n_persisted
        later = self._records[self._n_persisted + n_pending :]
        self._records = [*written, *later]
        self._persisted_bytes = bytes(data)
        self._n_persisted = len(written)
