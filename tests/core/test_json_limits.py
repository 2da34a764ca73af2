"""The one limited JSON reader: size, nesting and non-finite numbers refused with the source named."""

from __future__ import annotations

from pathlib import Path

import pytest

from workbench.core.errors import InputError
from workbench.core.json_limits import loads_limited, nesting_depth, read_json


def test_depth_ignores_brackets_in_strings() -> None:
    assert nesting_depth(b'{"a": [1, {"b": "[[[[{{"}]}') == 3
    assert nesting_depth(b'"\\"[[["') == 0
    assert nesting_depth(b"12") == 0


def test_deep_nesting_refused_without_recursion_error() -> None:
    with pytest.raises(InputError, match="nests 100000 levels") as info:
        loads_limited("[" * 100_000 + "]" * 100_000, "deep.json")
    assert "deep.json" in str(info.value)


def test_size_limit_and_padding(tmp_path: Path) -> None:
    big = tmp_path / "padded.json"
    big.write_bytes(b"{" + b" " * 2000 + b"}")
    with pytest.raises(InputError, match="padded.json: the case file is 0.0 MB"):
        read_json(big, max_bytes=1000, what="case file")
    assert read_json(big) == {}


def test_nan_and_garbage_refused() -> None:
    with pytest.raises(InputError, match="NaN is not a number"):
        loads_limited('{"x": NaN}', "lm.json")
    with pytest.raises(InputError, match="not valid JSON"):
        loads_limited("{", "lm.json")
    with pytest.raises(InputError, match="not UTF-8"):
        loads_limited(b'{"a": "\xff"}', "lm.json")
    assert loads_limited('\ufeff{"a": [1, 2]}', "x") == {"a": [1, 2]}
