"""The bad-input corpus through the ``workbench`` command line, in-process (issue 12).

Each entry of :data:`badinput.corpus.ENTRIES` must end with exit status != 0,
a message holding the entry's key phrases and the file or option at fault,
no traceback, no "unexpected error", and its input files unchanged
(SHA-256).  Lengths are mm.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from badinput.conftest import sha256_of
from badinput.corpus import ENTRIES, Entry, by_family
from workbench.cli.main import main

FAMILIES = {
    "A": "absurd values reported as success",
    "B": "'unexpected error' paths",
    "C": "misleading messages",
    "D": "units",
    "O": "other bad files",
}


def _argv(entry: Entry, files: dict[str, Path], out: Path) -> tuple[list[str], list[Path]]:
    used = [files[k] for a in entry.argv for k in re.findall(r"\{(\w+)\}", a) if k in files]
    argv = [a.format(out=out, **{k: str(v) for k, v in files.items()}) for a in entry.argv]
    return argv, used


@pytest.mark.parametrize("entry", ENTRIES, ids=[f"{e.family}-{e.id}" for e in ENTRIES])
def test_bad_input_gets_a_clear_message(
    entry: Entry, bad_files: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv, used = _argv(entry, bad_files, tmp_path / "out")
    before = {p: sha256_of(p) for p in used}
    try:
        status = main(argv)
    except SystemExit as exc:  # argparse refusing a value (status 2)
        status = exc.code
    captured = capsys.readouterr()
    text = captured.err + captured.out
    assert status not in (0, None), f"exit status {status}; output:\n{text}"
    assert "Traceback" not in text and "unexpected error" not in text, text
    for phrase in entry.expect:
        assert phrase.lower() in captured.err.lower(), f"{phrase!r} not in:\n{captured.err}"
    assert entry.names in captured.err, f"{entry.names!r} not named in:\n{captured.err}"
    assert {p: sha256_of(p) for p in used} == before, "an input file was changed"
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


def test_corpus_size_per_family(capsys: pytest.CaptureFixture[str]) -> None:
    counts = by_family()
    with capsys.disabled():
        print(
            "\nbad-input corpus: "
            + ", ".join(f"{f} ({FAMILIES[f]}) {n}" for f, n in sorted(counts.items()))
            + f"; total {sum(counts.values())}"
        )
    assert set(counts) <= set(FAMILIES)
    assert sum(counts.values()) >= 60
    assert all(counts.get(f, 0) >= 5 for f in "ABCD")
    assert len({e.id for e in ENTRIES}) == len(ENTRIES), "entry ids must be unique"
