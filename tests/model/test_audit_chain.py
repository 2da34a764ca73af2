"""The audit log's hash chain: encoding, anchor and the diagnosis of each kind of tamper."""

from __future__ import annotations

import json
import uuid

import pytest

from workbench.model.audit import (
    AuditLog,
    chain_anchor,
    content_digest,
    encode_record,
    genesis,
    make_record,
    parse_records,
    record_hash,
    verify_chain,
    verify_content,
)

CASE_ID = str(uuid.UUID(int=7))
OTHER_ID = str(uuid.UUID(int=8))


def _log(n: int = 6, case_id: str = CASE_ID) -> AuditLog:
    log = AuditLog(case_id=case_id)
    for i in range(n):
        log.append(make_record("do", f"Step {i}", "A. Examiner", {"i": i}))
    return log


def _chained(n: int = 6) -> list[dict]:
    return parse_records(_log(n).encode())


def test_records_are_chained_in_order_from_the_genesis() -> None:
    data = _log().encode()
    records = parse_records(data)
    assert [r["seq"] for r in records] == list(range(6))
    assert records[0]["prev"] == genesis(CASE_ID)
    for before, after in zip(records, records[1:], strict=False):
        assert after["prev"] == record_hash(before)
    # canonical: the stored line is the record's encode_record bytes
    assert data.splitlines(keepends=True)[2] == encode_record(records[2])
    anchor = chain_anchor(records)
    assert anchor == {"head": record_hash(records[-1]), "records": 6, "unchained": 0}
    status = verify_chain(records, CASE_ID, anchor)
    assert status.state == "verified" and status.ok and status.index is None
    assert status.summary() == "verified (6 records)"


def test_in_memory_records_hide_the_chain_fields_and_encoding_is_stable() -> None:
    log = _log(3)
    data = log.encode()
    assert log.encode() == data  # deterministic: a snapshot then a save write the same lines
    log.mark_persisted(data)
    assert all("prev" not in r and "seq" not in r for r in log.records)
    log.append(make_record("undo", "Step 2", "A. Examiner"))
    more = log.encode()
    assert more.startswith(data)
    records = parse_records(more)
    assert records[3]["seq"] == 3 and records[3]["prev"] == record_hash(records[2])
    assert verify_chain(records, CASE_ID, chain_anchor(records)).state == "verified"


def test_mark_persisted_with_extra_and_a_later_append() -> None:
    log = _log(2)
    save = make_record("save", "Save case", "A. Examiner")
    data = log.encode([save])
    log.append(make_record("do", "Late", "A. Examiner"))  # between encode and the write
    log.mark_persisted(data, [save])
    assert [r["operation"] for r in log.records] == ["Step 0", "Step 1", "Save case", "Late"]
    assert [r["operation"] for r in log.pending] == ["Late"]
    assert log.persisted_bytes == data


def _check(records: list[dict], anchor: dict, index: int, *words: str) -> str:
    status = verify_chain(records, CASE_ID, anchor)
    assert status.state == "broken" and not status.ok
    assert status.index == index, status.problem
    for word in words:
        assert word in status.problem, status.problem
    assert status.summary().startswith("NOT VERIFIED: ")
    return status.problem


def test_each_kind_of_tamper_names_the_first_bad_record() -> None:
    records = _chained()
    anchor = chain_anchor(records)

    edited = [dict(r) for r in records]
    edited[2]["operation"] = "Something else"
    _check(edited, anchor, 2, "record 2", "Something else", "edited")

    prev_edited = [dict(r) for r in records]
    prev_edited[3]["prev"] = "0" * 64
    _check(prev_edited, anchor, 3, "record 3", "edited")

    _check(records[:2] + records[3:], anchor, 2, "record 2 is missing", "deleted")
    _check(records[:-1], anchor, 5, "record 5 is missing", "at the end")
    swapped = [*records[:1], records[2], records[1], *records[3:]]
    _check(swapped, anchor, 1, "reordered", "position 2")

    forged = make_record("do", "Forged", "Mallory")
    forged.update(prev=record_hash(records[-1]), seq=6)
    _check([*records, forged], anchor, 6, "record 6", "Forged", "added after the last save")
    unchained = [*records[:3], make_record("do", "Inserted", "Mallory"), *records[3:]]
    _check(unchained, anchor, 3, "Inserted", "no valid chain fields")
    copy = dict(records[2])
    _check([*records[:3], copy, *records[3:]], anchor, 3, "inserted or duplicated")

    _check(records, {**anchor, "head": "f" * 64}, 5, "record 5", "anchor")
    _check(records, {**anchor, "records": 7}, 6, "record 6 is missing")
    last = [dict(r) for r in records]
    last[-1]["examiner"] = "Mallory"
    _check(last, anchor, 5, "record 5", "edited")


def test_the_chain_is_bound_to_its_case() -> None:
    records = parse_records(_log(3, OTHER_ID).encode())
    _check(records, chain_anchor(records), 0, "record 0", "another case")


def test_an_anchor_removed_from_a_chained_log_is_reported() -> None:
    _check(_chained(), None, 0, "no audit chain anchor")


def test_a_log_that_predates_the_chain_is_unverifiable_then_sealed() -> None:
    old = b"".join(encode_record(make_record("do", f"Old {i}", "X")) for i in range(3))
    status = verify_chain(parse_records(old), CASE_ID, None)
    assert status.state == "unchained" and status.ok and status.index is None
    assert status.summary() == "audit log predates the hash chain (not verifiable)"
    assert verify_chain([], CASE_ID, None).state == "unchained"

    log = AuditLog(old, CASE_ID)
    log.append(make_record("do", "New", "X"))
    data = log.encode([make_record("save", "Save case", "X")])
    assert data.startswith(old)
    records = parse_records(data)
    assert records[3]["prev"] == genesis(CASE_ID, records[:3]) and records[3]["seq"] == 3
    anchor = chain_anchor(records)
    assert anchor["unchained"] == 3 and anchor["records"] == 5
    status = verify_chain(records, CASE_ID, anchor)
    assert status.state == "verified" and status.unchained == 3
    assert "the first 3 predate the hash chain" in status.summary()

    older_edit = [dict(r) for r in records]
    older_edit[1]["operation"] = "Rewritten"
    _check(older_edit, anchor, 2, "predate the chain", "edited")
    stripped = [dict(r) for r in records]
    del stripped[3]["prev"]
    _check(stripped, anchor, 3, "no valid chain fields")
    _check(records[1:], anchor, 2, "carries a chain hash")


def test_chain_fields_given_by_a_caller_are_replaced() -> None:
    log = AuditLog(case_id=CASE_ID)
    log.append({**make_record("do", "A", "X"), "prev": "bogus", "seq": 99})
    records = parse_records(log.encode())
    assert records[0]["prev"] == genesis(CASE_ID) and records[0]["seq"] == 0
    assert json.loads(json.dumps(log.records[0])) == log.records[0]
    with pytest.raises(ValueError, match="JSON compliant"):
        log.append({"x": float("nan")})


# ---------------------------------------------------------------- content seal
def test_content_digest_ignores_the_anchor_and_the_layout_only() -> None:
    doc = {"meta": {"examiner": "A. Examiner"}, "landmarks": [1.5, 2.0], "audit_chain": {"x": 1}}
    digest = content_digest(doc)
    assert content_digest({**doc, "audit_chain": {"head": "other"}}) == digest
    assert content_digest(json.loads(json.dumps(doc, indent=4))) == digest
    assert content_digest({**doc, "meta": {"examiner": "B. Examiner"}}) != digest
    assert content_digest({**doc, "landmarks": [11.5, 2.0]}) != digest
    with pytest.raises(ValueError, match="NaN|not JSON compliant"):
        content_digest({"x": float("nan")})


def test_encode_seals_only_the_last_new_record() -> None:
    log = _log(3)
    records = parse_records(log.encode(content="c" * 64))
    assert [r.get("content_sha256") for r in records] == [None, None, "c" * 64]
    assert all("content_sha256" not in r for r in log.records)  # not part of the record
    log.mark_persisted(log.encode(content="c" * 64))
    assert log.encode(content="d" * 64) == log.persisted_bytes  # nothing new to seal
    log.append(make_record("do", "Later", "A. Examiner"))
    later = parse_records(log.encode(content="d" * 64))
    assert [r.get("content_sha256") for r in later[-2:]] == ["c" * 64, "d" * 64]
    assert verify_chain(later, CASE_ID, chain_anchor(later)).state == "verified"


def test_verify_content_states() -> None:
    records = parse_records(_log(2).encode(content="a" * 64))
    assert verify_content(records, "a" * 64).state == "verified"
    assert verify_content(records, "b" * 64, "a" * 64).state == "verified"  # as migrated
    changed = verify_content(records, "b" * 64)
    assert changed.state == "changed" and not changed.ok
    assert changed.problem.startswith(
        "case.json was changed outside the workbench after the workbench last wrote it"
    )
    unsealed = verify_content(_chained(2), "b" * 64)
    assert unsealed.ok and unsealed.summary() == "content not sealed (written by an older version)"
    assert verify_content([], "b" * 64).state == "unsealed"


def test_copy_keeps_pending_records_pending() -> None:
    log = _log(2)
    log.mark_persisted(log.encode())
    log.append(make_record("do", "Pending", "A. Examiner"))
    log.content_problem = "edited"
    copy = log.copy()
    assert copy.encode(content="e" * 64) == log.encode(content="e" * 64)
    assert copy.pending == log.pending and copy.content_problem == "edited"
    copy.append(make_record("do", "Only in the copy", "A. Examiner"))
    assert len(copy) == len(log) + 1


def test_a_deep_audit_line_is_a_damaged_log_not_a_recursion_error() -> None:
    deep = b"[" * 100_000 + b"]" * 100_000 + b"\n"
    with pytest.raises(ValueError, match="audit line 2 nests more than 64 levels deep"):
        parse_records(_log(1).encode() + deep)
