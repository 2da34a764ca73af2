"""The ``.fcase`` case file: one zip holding a whole case.

Layout
------
``case.json``
    Small state (see ``data_tables/schemas/case.schema.json``); arrays are
    referenced by the sha256 of their ``.npy`` bytes.
``arrays/<sha256>.npy``
    Arrays (specimen vertices and faces...), ``np.save(allow_pickle=False)``.
``evidence/<name>``
    Original evidence files, byte-for-byte (stored, not compressed).
``derived`` (in ``case.json``)
    Optional results computed from the case (the fitted face), as plain
    state with their arrays under ``arrays/`` like the parts' (see
    :attr:`workbench.model.case.Case.derived`).  Not evidence; a state
    records the digest of the inputs it came from.
Optional parts (in ``case.json``)
    A part registered as optional (:attr:`workbench.model.case.PartCodec.optional`,
    e.g. ``appearance``, the colours chosen for the face) is left out while it
    holds its default (``None``) and read as the default when absent, so
    files written before it existed open unchanged and need no migration.
``audit.jsonl``
    Append-only audit log (see :mod:`workbench.model.audit`), hash-chained;
    ``case.json`` ``audit_chain`` anchors its head and length.

Guarantees
----------
- Saving is atomic: a temporary file in the same folder is written, fsynced
  and moved over the target with :func:`os.replace`; a failed save leaves the
  previous file as it was.
- Evidence bytes are never re-encoded: a save copies them from the previous
  case file or from the original file, re-hashing them on the way.
- The audit log only grows: a save over the same case writes the old log
  byte-identical and appends.
- :func:`write_case_snapshot` (autosave) writes the same format, atomically,
  with no side effect on the case (no ``save`` record, meta and
  ``source_path`` unchanged).
- Loading runs the data-only migrations, validates against the schema, builds
  objects through :data:`workbench.model.case.PARTS` only (no class named in
  the file is ever instantiated, nothing is unpickled) and re-hashes every
  array and evidence file, and checks the audit log's hash chain against its
  anchor.  A mismatch (or an edited, deleted, reordered or added audit
  record) is refused unless ``allow_tampered=True``, which loads and reports
  it in ``evidence_status`` (the log under ``audit.jsonl``) and
  ``audit_chain``.  A log written before the chain existed loads as
  ``audit_chain.state == "unchained"`` (not verifiable, not an error); the
  next save chains the new records onto it.
- Every write seals ``case.json``: the last audit record written carries the
  :func:`~workbench.model.audit.content_digest` of the document (all of it
  but the ``audit_chain`` anchor, which pins that record).  Loading
  recomputes the digest of the document as stored and as migrated to the
  current format (the same case in an older layout still verifies); a
  mismatch (``case.json`` edited by hand, a landmark moved, the examiner
  renamed) is reported under ``case.json`` in ``evidence_status`` and in
  ``audit_chain.content``, and refused unless ``allow_tampered=True``.  A
  case loaded that way is never sealed again: :func:`save_case` and
  :func:`write_case_snapshot` refuse it.  A file whose last record has no
  seal (written by an older version) loads as "content not sealed".
- Members are read through :mod:`workbench.io.zip_limits`: the archive's
  directory is checked before any member is read (duplicate names, unsafe
  names, encryption, compression method, size per kind of member,
  compression ratio) and no member is decompressed past its limit, whatever
  its header says.  ``case.json`` and ``audit.jsonl`` then go through the
  JSON size and depth limits of :mod:`workbench.core.json_limits`.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import os
import time
import uuid
import zipfile
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from functools import lru_cache
from os import PathLike
from pathlib import Path
from types import MappingProxyType
from typing import Any, Protocol

import jsonschema
import numpy as np

import workbench
from workbench.core.data_paths import data_tables_dir
from workbench.core.errors import InputError
from workbench.core.json_limits import loads_limited
from workbench.io.case_archive import (
    AUDIT,
    CASE_JSON,
    CaseArchive,
    CaseFileError,
    array_limit,
    open_case_zip,
    open_previous,
    read_stored_json,
)
from workbench.io.case_archive import MAX_ARRAY_BYTES as MAX_ARRAY_BYTES
from workbench.io.case_archive import MAX_AUDIT_BYTES as MAX_AUDIT_BYTES
from workbench.io.case_archive import MAX_CASE_JSON_BYTES as MAX_CASE_JSON_BYTES
from workbench.io.case_archive import MAX_EVIDENCE_BYTES as MAX_EVIDENCE_BYTES
from workbench.io.case_archive import MAX_OTHER_BYTES as MAX_OTHER_BYTES
from workbench.io.case_archive import member_limit as member_limit
from workbench.io.case_archive import sized_in_case as sized_in_case
from workbench.io.migrations import CURRENT_VERSION, SCHEMA_ID, MigrationError, migrate
from workbench.io.zip_limits import (
    MEMBER_ERRORS,
    MemberTooLarge,
    ZipLimitError,
)
from workbench.model.audit import (
    ANCHOR_KEY,
    AuditLog,
    ChainStatus,
    ContentSeal,
    chain_anchor,
    content_digest,
    make_record,
    parse_records,
    verify_chain,
    verify_content,
)
from workbench.model.case import PARTS, Case
from workbench.model.evidence import (
    EvidenceFile,
    Opener,
    copy_hashed,
    find_verified_copy,
    hash_chunks,
    read_chunks,
)
from workbench.model.state import ARRAY_KEY, array_from_npy, join_arrays, split_arrays

OK = "ok"

PathArg = str | PathLike[str]


@dataclass(frozen=True)
class LoadedCase:
    """Result of :func:`load_case`.

    Attributes
    ----------
    case : Case
    audit_records : tuple of dict
        The stored audit log, oldest first.
    evidence_status : mapping
        ``{member: "ok" or what is wrong}`` for every ``evidence/...`` and
        ``arrays/...`` member the case refers to, and ``audit.jsonl`` (its
        hash chain) when the file has a log.
    audit_chain : ChainStatus
        The audit log's hash-chain check (``.summary()`` for people).
    """

    case: Case
    audit_records: tuple[dict[str, Any], ...]
    evidence_status: Mapping[str, str]
    audit_chain: ChainStatus = ChainStatus("unchained", 0)

    @property
    def tampered(self) -> bool:
        return any(status != OK for status in self.evidence_status.values())

    @property
    def content_seal(self) -> ContentSeal:
        """Whether ``case.json`` is as the workbench last wrote it (see the module docstring)."""
        return self.audit_chain.content or ContentSeal("unsealed")


# ---------------------------------------------------------------- schema
def schema_dir() -> Path:
    """Folder of the JSON schemas: the wheel's ``_data`` copy first, else the source tree."""
    folder = data_tables_dir() / "schemas"
    if not (folder / "case.schema.json").is_file():
        raise FileNotFoundError(f"case.schema.json not found in {folder}")
    return folder


@lru_cache(maxsize=1)
def case_validator() -> jsonschema.Draft202012Validator:
    """The checked validator of ``case.schema.json`` (built once: ~75 ms)."""
    schema = json.loads((schema_dir() / "case.schema.json").read_text(encoding="utf-8"))
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


def validate_case_json(doc: Any, source: PathArg) -> None:
    """Raise :class:`CaseFileError` naming the first schema violation in ``doc``."""
    error = jsonschema.exceptions.best_match(case_validator().iter_errors(doc))
    if error is not None:
        message = error.message if len(error.message) < 300 else error.message[:300] + "..."
        raise CaseFileError(
            source, f"case.json does not match {SCHEMA_ID} at {error.json_path}: {message}"
        )


# ---------------------------------------------------------------- reading
def _current(stored: Mapping[str, Any], path: Path) -> dict[str, Any]:
    """A stored ``case.json`` migrated to the current format and validated."""
    try:
        doc, _ = migrate(stored)
    except MigrationError as error:
        raise CaseFileError(path, str(error)) from None
    validate_case_json(doc, path)
    return doc


def _read_document(archive: CaseArchive) -> dict[str, Any]:
    """``case.json``, migrated to the current format and validated."""
    return _current(read_stored_json(archive), archive.path)


def _load_array(archive: CaseArchive, status: dict[str, str], ref: Mapping[str, Any]) -> np.ndarray:
    member = f"arrays/{ref[ARRAY_KEY]}.npy"
    limit = array_limit(ref)
    try:
        data = archive.read(member, limit)
    except MemberTooLarge:
        raise CaseFileError(
            archive.path,
            f"{member}: holds more than {limit} bytes, case.json expects "
            f"{ref['dtype']}{list(ref['shape'])}",
        ) from None
    found = hashlib.sha256(data).hexdigest()
    status[member] = OK if found == ref[ARRAY_KEY] else f"sha256 mismatch (hashes to {found})"
    try:
        return array_from_npy(data, ref)
    except ValueError as error:
        raise CaseFileError(archive.path, f"{member}: {error}") from None


def _evidence_status(archive: CaseArchive, item: EvidenceFile) -> str:
    member = f"evidence/{item.name}"
    if not archive.has(member):
        return "missing from the case file"
    try:
        with archive.open(member, item.size) as stream:
            sha, size = hash_chunks(read_chunks(stream))
    except MemberTooLarge:
        return f"larger than its recorded {item.size} bytes"
    except ZipLimitError as error:
        return error.problem
    except MEMBER_ERRORS as error:
        return f"unreadable ({error})"
    if (sha, size) != (item.sha256, item.size):
        return f"sha256 mismatch (recorded {item.sha256}, found {sha}, {size} bytes)"
    return OK


def _evidence_store(doc: Mapping[str, Any], path: Path) -> tuple[EvidenceFile, ...]:
    store = {e["name"]: EvidenceFile.from_state(e) for e in doc["evidence_store"]}
    if len(store) != len(doc["evidence_store"]):
        raise CaseFileError(path, "the evidence store lists a file name twice")
    for entry in doc["evidence"]:
        if store.get(entry["name"]) != EvidenceFile.from_state(entry):
            raise CaseFileError(path, f"evidence {entry['name']!r} is not in the evidence store")
    return tuple(store.values())


def _part_state(
    doc: Mapping[str, Any], name: str, load: Callable[[Mapping[str, Any]], np.ndarray]
) -> Any:
    codec = PARTS[name]
    if codec.optional and name not in doc:
        return codec.to_state(codec.default())  # left out of the file while unused
    return join_arrays(doc[name], load) if codec.has_arrays else doc[name]


def _build_case(
    doc: Mapping[str, Any], load: Callable[[Mapping[str, Any]], np.ndarray], path: Path
) -> Case:
    state = {name: _part_state(doc, name, load) for name in PARTS}
    try:
        return Case.from_state(state)
    except (ValueError, TypeError, KeyError) as error:
        raise CaseFileError(path, f"invalid case content: {error}") from None


def _digest(stored: Mapping[str, Any], path: Path) -> str:
    try:
        return content_digest(stored)
    except ValueError as error:
        raise CaseFileError(path, str(error)) from None


def load_case(path: PathArg, *, allow_tampered: bool = False) -> LoadedCase:
    """Open a ``.fcase`` file (read-only; the file is never modified).

    Raises
    ------
    CaseFileError
        Not a zip, truncated, over a size or ratio limit, a member listed
        twice or encrypted, invalid JSON, schema violation, missing member,
        or (unless ``allow_tampered``) an array or evidence hash mismatch, a
        broken audit chain (naming the first bad record) or a ``case.json``
        changed after its last write.
    """
    path = Path(path)
    status: dict[str, str] = {}
    with open_case_zip(path) as archive:
        stored = read_stored_json(archive)
        doc = _current(stored, path)
        digests = (_digest(stored, path), _digest(doc, path))
        store = _evidence_store(doc, path)
        case = _build_case(doc, lambda ref: _load_array(archive, status, ref), path)
        case.derived = {
            name: join_arrays(state, lambda ref: _load_array(archive, status, ref))
            for name, state in (doc.get("derived") or {}).items()
        }
        for item in store:
            status[f"evidence/{item.name}"] = _evidence_status(archive, item)
        has_log = archive.has(AUDIT)
        audit_bytes = archive.read(AUDIT) if has_log else b""
    chain, damaged = _check_chain(audit_bytes, case, doc.get(ANCHOR_KEY), digests)
    if not chain.ok or (has_log and damaged is None):
        status[AUDIT] = OK if chain.ok else chain.problem
    seal = chain.content
    if seal is not None and seal.state != "unsealed":
        status[CASE_JSON] = OK if seal.ok else seal.problem
    bad = {member: s for member, s in status.items() if s != OK}
    if bad and not allow_tampered:
        listing = "; ".join(f"{member}: {s}" for member, s in bad.items())
        raise CaseFileError(
            path,
            f"integrity check failed, refusing to open: {listing}",
            "it was modified or damaged outside the workbench; inspect it with "
            "'workbench case info --allow-tampered' (load_case(..., allow_tampered=True))",
        )
    if damaged is not None:
        raise CaseFileError(path, f"the audit log is damaged ({AUDIT}: {damaged})")
    case.audit = AuditLog(audit_bytes, case.meta.case_id)
    if seal is not None and not seal.ok:
        case.audit.content_problem = seal.problem
    for item in store:
        case.retain_evidence(item)
    case.source_path = path.resolve()
    return LoadedCase(case, case.audit.records, MappingProxyType(status), chain)


def _check_chain(
    audit_bytes: bytes,
    case: Case,
    anchor: Mapping[str, Any] | None,
    digests: tuple[str, str],
) -> tuple[ChainStatus, ValueError | None]:
    """The audit log's chain and content-seal status, or the parse error of a damaged log.

    ``digests``: the content digests of ``case.json`` as stored and as migrated.
    """
    try:
        records = parse_records(audit_bytes)
    except ValueError as error:
        return ChainStatus("unchained", 0), error
    chain = verify_chain(records, case.meta.case_id, anchor)
    return dataclasses.replace(chain, content=verify_content(records, *digests)), None


def evidence_bytes(path: PathArg, name: str, *, allow_tampered: bool = False) -> bytes:
    """The original bytes of evidence file ``name``, checked against its recorded sha256.

    The recorded sha256 is trusted only if ``case.json`` still matches its
    content seal (unless ``allow_tampered``).
    """
    path = Path(path)
    with open_case_zip(path) as archive:
        stored = read_stored_json(archive)
        current = _current(stored, path)
        store = {e.name: e for e in _evidence_store(current, path)}
        if name not in store:
            raise CaseFileError(path, f"the case has no evidence file named {name!r}")
        seal = ContentSeal("unsealed")
        if archive.has(AUDIT):
            digests = (_digest(stored, path), _digest(current, path))
            with contextlib.suppress(ValueError):
                seal = verify_content(parse_records(archive.read(AUDIT)), *digests)
        if not seal.ok and not allow_tampered:
            raise CaseFileError(
                path,
                f"{seal.problem}; its recorded sha256 of evidence/{name} cannot be trusted",
                "inspect it with 'workbench case info --allow-tampered'",
            )
        item = store[name]
        member = f"evidence/{name}"
        try:
            data = archive.read(member, item.size)
        except MemberTooLarge:
            if not allow_tampered:
                raise CaseFileError(
                    path, f"{member} is larger than its recorded {item.size} bytes"
                ) from None
            data = archive.read(member)
    found = hashlib.sha256(data).hexdigest()
    if found != item.sha256 and not allow_tampered:
        raise CaseFileError(path, f"evidence/{name} does not match its recorded sha256")
    return data


# ---------------------------------------------------------------- writing
def _encode(case: Case, meta_state: dict[str, Any]) -> tuple[dict[str, Any], dict[str, bytes]]:
    """``case.json`` document (no anchor yet) and ``{sha256: npy bytes}`` for ``case``."""
    doc: dict[str, Any] = {
        "@schema": SCHEMA_ID,
        "format_version": CURRENT_VERSION,
        "software": f"forensic-workbench {workbench.__version__}",
    }
    blobs: dict[str, bytes] = {}
    for name, state in case.to_state().items():
        if PARTS[name].optional and state is None:
            continue  # left out while unused (see PartCodec.optional)
        if name == "meta":
            state = meta_state
        if PARTS[name].has_arrays:
            state, part_blobs = split_arrays(state)
            blobs.update(part_blobs)
        doc[name] = state
        if name == "evidence":
            doc["evidence_store"] = [e.to_state() for e in case.retained_evidence.values()]
    if case.derived:
        derived: dict[str, Any] = {}
        for name, state in case.derived.items():
            derived[name], part_blobs = split_arrays(state)
            blobs.update(part_blobs)
        doc["derived"] = derived
    return doc, blobs


def _case_text(doc: Mapping[str, Any]) -> bytes:
    """The ``case.json`` bytes written for ``doc``."""
    return json.dumps(doc, indent=1, ensure_ascii=False, allow_nan=False).encode("utf-8")


def _refuse_tampered(case: Case, path: Path) -> None:
    """Refuse to write a case whose content failed its seal when it was opened."""
    problem = case.audit.content_problem
    if problem:
        raise CaseFileError(
            path,
            f"not saved: this case was opened although {problem}; the workbench does not "
            "seal content it did not write",
            "start a new case from the original evidence, or restore the case file from a backup",
        )


def _seal(case: Case, doc: dict[str, Any], extra: list[dict[str, Any]]) -> bytes:
    """The log's bytes with ``extra`` appended and ``doc`` sealed; anchors the log in ``doc``.

    The last record written carries the :func:`content_digest` of ``doc`` as it
    will be read back (the anchor, added here afterwards, is not part of it).
    """
    digest = content_digest(json.loads(_case_text(doc)))
    audit = _bound_log(case).encode(extra, content=digest)
    doc[ANCHOR_KEY] = chain_anchor(parse_records(audit))
    return audit


def _bound_log(case: Case) -> AuditLog:
    """``case.audit``, told its case id (the chain's genesis) before it is encoded."""
    case.audit.case_id = case.meta.case_id
    return case.audit


def _sources(path: Path, case: Case, stack: contextlib.ExitStack) -> list[CaseArchive]:
    """Readable previous case files (target first, then where the case came from)."""
    found = []
    for candidate in dict.fromkeys(p for p in (path, case.source_path) if p is not None):
        source = open_previous(Path(candidate), stack)
        if source is not None:
            found.append(source)
    return found


def _check_audit_prefix(
    path: Path, case: Case, sources: list[CaseArchive], new_audit: bytes
) -> None:
    """Refuse to overwrite this case's file if its log is not a prefix of ``new_audit``."""
    if not sources or sources[0].path != path:
        return  # nothing to overwrite
    try:
        doc, _ = migrate(
            loads_limited(sources[0].read(CASE_JSON), path, max_bytes=MAX_CASE_JSON_BYTES)
        )
        same_case = doc["meta"]["case_id"] == case.meta.case_id
        old_audit = sources[0].read(AUDIT)
    except (KeyError, ValueError, TypeError, AttributeError, InputError, *MEMBER_ERRORS):
        return  # not a case file, or no log yet
    if same_case and not new_audit.startswith(old_audit):
        raise CaseFileError(
            path,
            "the audit log in this file has records this session does "
            "not know (another session saved it)",
            "save under a new name",
        )


def _evidence_source(item: EvidenceFile, sources: list[CaseArchive]) -> Opener:
    """An opener for a copy of ``item`` whose bytes hash to its recorded sha256."""
    member = f"evidence/{item.name}"
    openers: list[Opener] = [_member_opener(a, member, item.size) for a in sources if a.has(member)]
    if item.original_path:
        openers.append(lambda: open(item.original_path, "rb"))
    found = find_verified_copy(item, openers, (OSError, ZipLimitError, *MEMBER_ERRORS))
    if found is None:
        raise CaseFileError(
            item.original_path or item.name,
            f"no copy of evidence {item.name!r} with sha256 {item.sha256} was "
            "found in the previous case file or at its original path",
        )
    return found


def _member_opener(archive: CaseArchive, member: str, size: int) -> Opener:
    """Opens ``member`` of ``archive`` read at most ``size`` bytes (more is an error)."""
    return lambda: archive.open(member, size)


def _zip_info(name: str, compress: int, size: int = 0) -> zipfile.ZipInfo:
    info = zipfile.ZipInfo(name, date_time=time.localtime()[:6])
    info.compress_type = compress
    info.file_size = size
    return info


def _write_members(
    archive: zipfile.ZipFile,
    doc: dict[str, Any],
    blobs: dict[str, bytes],
    audit: bytes,
    openers: dict[EvidenceFile, Opener],
) -> None:
    archive.writestr(_zip_info(CASE_JSON, zipfile.ZIP_DEFLATED), _case_text(doc))
    for sha, data in blobs.items():
        # fastest deflate level: a 100k-triangle mesh's arrays compress in
        # ~55 ms instead of ~210 ms (the default, 6), 4% larger; the window
        # saves on its GUI thread
        archive.writestr(
            _zip_info(f"arrays/{sha}.npy", zipfile.ZIP_DEFLATED), data, compresslevel=1
        )
    for item, opener in openers.items():
        info = _zip_info(f"evidence/{item.name}", zipfile.ZIP_STORED, item.size)
        with opener() as source, archive.open(info, "w") as target:
            copied = copy_hashed(source, target)
        if copied != (item.sha256, item.size):
            raise CaseFileError(item.name, "evidence changed while it was being copied")
    archive.writestr(_zip_info(AUDIT, zipfile.ZIP_DEFLATED), audit)


@contextlib.contextmanager
def _cleanup_on_error(path: Path, temp: Path) -> Iterator[None]:
    """Remove ``temp`` if the block fails; report OS errors as :class:`CaseFileError`."""
    try:
        yield
    except BaseException as error:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(temp)
        if isinstance(error, OSError):
            raise CaseFileError(path, f"could not save ({error})") from error
        raise


def _write_temp(path: Path, write: Callable[[zipfile.ZipFile], None]) -> Path:
    """Write a complete, fsynced zip next to ``path`` and return its name."""
    temp = path.with_name(f".{path.name}.{uuid.uuid4().hex[:8]}.tmp")
    with _cleanup_on_error(path, temp):
        fd = os.open(temp, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o666)
        with os.fdopen(fd, "wb") as stream:
            with zipfile.ZipFile(stream, "w") as archive:
                write(archive)
            stream.flush()
            os.fsync(stream.fileno())
    return temp


def _replace(temp: Path, path: Path) -> None:
    """Move ``temp`` over ``path`` (atomic on one file system) and sync the folder."""
    with _cleanup_on_error(path, temp):
        os.replace(temp, path)
    with contextlib.suppress(OSError):  # make the rename durable where supported
        dir_fd = os.open(path.parent, os.O_RDONLY)
        try:
            os.fsync(dir_fd)
        finally:
            os.close(dir_fd)


def _write_case(
    path: Path,
    case: Case,
    doc: dict[str, Any],
    blobs: dict[str, bytes],
    audit: bytes,
    *,
    guard_audit: bool,
) -> None:
    """Write a complete case file to ``path`` atomically; evidence copied from a verified copy.

    ``guard_audit``: refuse to overwrite a file of the same case whose audit log is not a
    prefix of ``audit`` (see :func:`_check_audit_prefix`).
    """
    with contextlib.ExitStack() as stack_of_files:
        sources = _sources(path, case, stack_of_files)
        if guard_audit:
            _check_audit_prefix(path, case, sources, audit)
        openers = {
            item: _evidence_source(item, sources) for item in case.retained_evidence.values()
        }
        temp = _write_temp(path, lambda zf: _write_members(zf, doc, blobs, audit, openers))
    _replace(temp, path)  # after the previous file is closed (needed on Windows)


class _Cleanable(Protocol):
    def set_clean(self) -> None: ...


def save_case(case: Case, path: PathArg, stack: _Cleanable | None = None) -> Path:
    """Write ``case`` to ``path`` atomically; see the module docstring.

    Parameters
    ----------
    case : Case
    path : path
        Target ``.fcase`` file; its folder must exist.
    stack : CommandStack, optional
        Marked clean after a successful save.

    Returns
    -------
    Path
        ``path``.  On success ``case.meta.modified`` is updated, the audit
        log (with one ``save`` record added) is marked persisted and
        ``case.source_path`` becomes ``path``.
    """
    path = Path(path).resolve()
    _refuse_tampered(case, path)
    meta = case.meta.touched()
    record = make_record(
        "save", "Save case", meta.examiner, {"file": path.name, "format_version": CURRENT_VERSION}
    )
    doc, blobs = _encode(case, meta.to_state())
    audit = _seal(case, doc, [record])
    validate_case_json(doc, path)
    _write_case(path, case, doc, blobs, audit, guard_audit=True)
    case.audit.mark_persisted(audit, [record])
    case.replace("meta", meta)
    case.source_path = path
    if stack is not None:
        stack.set_clean()
    return path


# ---------------------------------------------------------------- snapshots (autosave)
def detached_copy(case: Case) -> Case:
    """A copy of ``case`` that later edits of ``case`` cannot reach.

    For writing a snapshot in a worker thread while the user goes on editing.
    Cheap: parts are immutable values and are shared (no array is copied);
    the audit log is copied with its records not yet saved still pending (a
    snapshot seals the last of them), with the retained evidence and
    ``source_path``.  The copy has no listeners.
    """
    copy = Case()
    for item in case.retained_evidence.values():
        copy.retain_evidence(item)
    for name in PARTS:
        copy.replace(name, case.part(name))
    copy.audit = _bound_log(case).copy()
    copy.source_path = case.source_path
    copy.derived = dict(case.derived)
    return copy


def write_case_snapshot(case: Case, path: PathArg) -> Path:
    """Write ``case`` to ``path`` as a complete ``.fcase``, changing nothing about ``case``.

    The file loads with :func:`load_case` like a saved case, but unlike
    :func:`save_case` this adds no ``save`` audit record (records not yet
    saved are written and stay pending in ``case.audit``), leaves
    ``case.meta``, ``case.source_path`` and any command stack alone, and does
    not check ``path`` against another session's log (a snapshot file belongs
    to its writer).  Evidence bytes are copied exactly as by :func:`save_case`
    (from the previous file at ``path``, the case's source file or the
    original path, re-hashed), so a snapshot of a case never saved still holds
    its evidence.  Atomic; thread-safe on a :func:`detached_copy`.

    Returns
    -------
    Path
        ``path``, resolved.
    """
    path = Path(path).resolve()
    _refuse_tampered(case, path)
    doc, blobs = _encode(case, case.meta.to_state())
    audit = _seal(case, doc, [])
    validate_case_json(doc, path)
    _write_case(path, case, doc, blobs, audit, guard_audit=False)
    return path


def read_case_json(path: PathArg) -> dict[str, Any]:
    """The migrated, schema-checked ``case.json`` of a case file.

    A quick check that ``path`` is a readable case file: arrays and evidence
    are neither read nor hashed (:func:`load_case` does that).

    Raises
    ------
    CaseFileError
    """
    path = Path(path)
    with open_case_zip(path) as archive:
        return _read_document(archive)
