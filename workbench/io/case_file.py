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
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import time
import uuid
import zipfile
import zlib
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from functools import lru_cache, partial
from os import PathLike
from pathlib import Path
from types import MappingProxyType
from typing import Any, Protocol

import jsonschema
import numpy as np

import workbench
from workbench.core.data_paths import data_tables_dir
from workbench.core.errors import InputError
from workbench.io.migrations import CURRENT_VERSION, SCHEMA_ID, MigrationError, migrate
from workbench.model.audit import (
    AuditLog,
    ChainStatus,
    chain_anchor,
    make_record,
    parse_records,
    verify_chain,
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

CASE_JSON = "case.json"
AUDIT = "audit.jsonl"
OK = "ok"
_ZIP_ERRORS = (zipfile.BadZipFile, zlib.error, EOFError, NotImplementedError)

PathArg = str | PathLike[str]


class CaseFileError(InputError):
    """A case file that cannot be read or written; names the file and the problem."""


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
@contextlib.contextmanager
def _open_zip(path: Path) -> Iterator[zipfile.ZipFile]:
    if not path.is_file():
        raise CaseFileError(path, "no such case file")
    try:
        with zipfile.ZipFile(path, "r") as archive:
            yield archive
    except _ZIP_ERRORS as error:
        raise CaseFileError(
            path, f"the file is damaged or truncated ({error})", "restore it from a backup"
        ) from None
    except OSError as error:
        raise CaseFileError(path, f"cannot read the file ({error})") from None


def _read_member(archive: zipfile.ZipFile, name: str, path: Path) -> bytes:
    try:
        return archive.read(name)
    except KeyError:
        raise CaseFileError(path, f"{name} is missing from the case file") from None


def _read_document(archive: zipfile.ZipFile, path: Path) -> dict[str, Any]:
    """``case.json``, migrated to the current format and validated."""
    raw = _read_member(archive, CASE_JSON, path)
    try:
        doc = json.loads(raw.decode("utf-8"), parse_constant=_reject_constant)
    except (UnicodeDecodeError, ValueError) as error:
        raise CaseFileError(path, f"case.json is not valid JSON ({error})") from None
    if not isinstance(doc, dict):
        raise CaseFileError(path, "case.json is not a JSON object")
    try:
        doc, _ = migrate(doc)
    except MigrationError as error:
        raise CaseFileError(path, str(error)) from None
    validate_case_json(doc, path)
    return doc


def _reject_constant(name: str) -> None:
    raise ValueError(f"{name} is not allowed")


def _load_array(
    archive: zipfile.ZipFile, path: Path, status: dict[str, str], ref: Mapping[str, Any]
) -> np.ndarray:
    member = f"arrays/{ref[ARRAY_KEY]}.npy"
    data = _read_member(archive, member, path)
    found = hashlib.sha256(data).hexdigest()
    status[member] = OK if found == ref[ARRAY_KEY] else f"sha256 mismatch (hashes to {found})"
    try:
        return array_from_npy(data, ref)
    except ValueError as error:
        raise CaseFileError(path, f"{member}: {error}") from None


def _evidence_status(archive: zipfile.ZipFile, item: EvidenceFile) -> str:
    try:
        with archive.open(f"evidence/{item.name}") as stream:
            sha, size = hash_chunks(read_chunks(stream))
    except KeyError:
        return "missing from the case file"
    except _ZIP_ERRORS as error:
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


def _build_case(
    doc: Mapping[str, Any], load: Callable[[Mapping[str, Any]], np.ndarray], path: Path
) -> Case:
    state = {
        name: join_arrays(doc[name], load) if codec.has_arrays else doc[name]
        for name, codec in PARTS.items()
    }
    try:
        return Case.from_state(state)
    except (ValueError, TypeError, KeyError) as error:
        raise CaseFileError(path, f"invalid case content: {error}") from None


def load_case(path: PathArg, *, allow_tampered: bool = False) -> LoadedCase:
    """Open a ``.fcase`` file (read-only; the file is never modified).

    Raises
    ------
    CaseFileError
        Not a zip, truncated, invalid JSON, schema violation, missing member,
        or (unless ``allow_tampered``) an array or evidence hash mismatch or a
        broken audit chain (naming the first bad record).
    """
    path = Path(path)
    status: dict[str, str] = {}
    with _open_zip(path) as archive:
        doc = _read_document(archive, path)
        store = _evidence_store(doc, path)
        case = _build_case(doc, lambda ref: _load_array(archive, path, status, ref), path)
        for item in store:
            status[f"evidence/{item.name}"] = _evidence_status(archive, item)
        has_log = AUDIT in archive.namelist()
        audit_bytes = archive.read(AUDIT) if has_log else b""
    chain, damaged = _check_chain(audit_bytes, case, doc.get("audit_chain"))
    if not chain.ok or (has_log and damaged is None):
        status[AUDIT] = OK if chain.ok else chain.problem
    bad = {member: s for member, s in status.items() if s != OK}
    if bad and not allow_tampered:
        listing = "; ".join(f"{member}: {s}" for member, s in bad.items())
        raise CaseFileError(
            path,
            f"integrity check failed, refusing to open: {listing}",
            "it was modified or damaged outside the workbench; "
            "load with allow_tampered=True to inspect it",
        )
    if damaged is not None:
        raise CaseFileError(path, f"the audit log is damaged ({damaged})")
    case.audit = AuditLog(audit_bytes, case.meta.case_id)
    for item in store:
        case.retain_evidence(item)
    case.source_path = path.resolve()
    return LoadedCase(case, case.audit.records, MappingProxyType(status), chain)


def _check_chain(
    audit_bytes: bytes, case: Case, anchor: Mapping[str, Any] | None
) -> tuple[ChainStatus, ValueError | None]:
    """The audit log's chain status, or the parse error of a log that is not JSON lines."""
    try:
        records = parse_records(audit_bytes)
    except ValueError as error:
        return ChainStatus("unchained", 0), error
    return verify_chain(records, case.meta.case_id, anchor), None


def evidence_bytes(path: PathArg, name: str, *, allow_tampered: bool = False) -> bytes:
    """The original bytes of evidence file ``name``, checked against its recorded sha256."""
    path = Path(path)
    with _open_zip(path) as archive:
        store = {e.name: e for e in _evidence_store(_read_document(archive, path), path)}
        if name not in store:
            raise CaseFileError(path, f"the case has no evidence file named {name!r}")
        data = _read_member(archive, f"evidence/{name}", path)
    found = hashlib.sha256(data).hexdigest()
    if found != store[name].sha256 and not allow_tampered:
        raise CaseFileError(path, f"evidence/{name} does not match its recorded sha256")
    return data


# ---------------------------------------------------------------- writing
def _encode(
    case: Case, meta_state: dict[str, Any], audit: bytes
) -> tuple[dict[str, Any], dict[str, bytes]]:
    """``case.json`` document and ``{sha256: npy bytes}`` for ``case`` with log ``audit``."""
    doc: dict[str, Any] = {
        "@schema": SCHEMA_ID,
        "format_version": CURRENT_VERSION,
        "software": f"forensic-workbench {workbench.__version__}",
    }
    blobs: dict[str, bytes] = {}
    for name, state in case.to_state().items():
        if name == "meta":
            state = meta_state
        if PARTS[name].has_arrays:
            state, part_blobs = split_arrays(state)
            blobs.update(part_blobs)
        doc[name] = state
        if name == "evidence":
            doc["evidence_store"] = [e.to_state() for e in case.retained_evidence.values()]
    doc["audit_chain"] = chain_anchor(parse_records(audit))
    return doc, blobs


def _bound_log(case: Case) -> AuditLog:
    """``case.audit``, told its case id (the chain's genesis) before it is encoded."""
    case.audit.case_id = case.meta.case_id
    return case.audit


def _sources(path: Path, case: Case, stack: contextlib.ExitStack) -> list[zipfile.ZipFile]:
    """Readable previous case files (target first, then where the case came from)."""
    found = []
    for candidate in dict.fromkeys(p for p in (path, case.source_path) if p is not None):
        with contextlib.suppress(OSError, *_ZIP_ERRORS):
            found.append(stack.enter_context(zipfile.ZipFile(candidate, "r")))
    return found


def _check_audit_prefix(
    path: Path, case: Case, sources: list[zipfile.ZipFile], new_audit: bytes
) -> None:
    """Refuse to overwrite this case's file if its log is not a prefix of ``new_audit``."""
    if not sources or Path(sources[0].filename or "") != path:
        return  # nothing to overwrite
    try:
        doc, _ = migrate(json.loads(sources[0].read(CASE_JSON)))
        same_case = doc["meta"]["case_id"] == case.meta.case_id
        old_audit = sources[0].read(AUDIT)
    except (KeyError, ValueError, TypeError, *_ZIP_ERRORS):
        return  # not a case file, or no log yet
    if same_case and not new_audit.startswith(old_audit):
        raise CaseFileError(
            path,
            "the audit log in this file has records this session does "
            "not know (another session saved it)",
            "save under a new name",
        )


def _evidence_source(item: EvidenceFile, sources: list[zipfile.ZipFile]) -> Opener:
    """An opener for a copy of ``item`` whose bytes hash to its recorded sha256."""
    member = f"evidence/{item.name}"
    openers = [partial(a.open, member) for a in sources if member in a.namelist()]
    if item.original_path:
        openers.append(partial(open, item.original_path, "rb"))
    found = find_verified_copy(item, openers, (OSError, *_ZIP_ERRORS))
    if found is None:
        raise CaseFileError(
            item.original_path or item.name,
            f"no copy of evidence {item.name!r} with sha256 {item.sha256} was "
            "found in the previous case file or at its original path",
        )
    return found


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
    text = json.dumps(doc, indent=1, ensure_ascii=False, allow_nan=False)
    archive.writestr(_zip_info(CASE_JSON, zipfile.ZIP_DEFLATED), text.encode("utf-8"))
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
    meta = case.meta.touched()
    record = make_record(
        "save", "Save case", meta.examiner, {"file": path.name, "format_version": CURRENT_VERSION}
    )
    audit = _bound_log(case).encode([record])
    doc, blobs = _encode(case, meta.to_state(), audit)
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
    the audit log is carried as its encoded bytes, with the retained evidence
    and ``source_path``.  The copy has no listeners.
    """
    copy = Case()
    for item in case.retained_evidence.values():
        copy.retain_evidence(item)
    for name in PARTS:
        copy.replace(name, case.part(name))
    copy.audit = AuditLog(_bound_log(case).encode(), case.meta.case_id)
    copy.source_path = case.source_path
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
    audit = _bound_log(case).encode()
    doc, blobs = _encode(case, case.meta.to_state(), audit)
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
    with _open_zip(path) as archive:
        return _read_document(archive, path)
